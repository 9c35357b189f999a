//! The geometry of a group of mesh elements (a gmsh physical group): whether a point lies inside
//! its surfaces (2D) or volumes (3D), how far a point is from its curves or surfaces, and its
//! measure. Elements are split into simplices (a quadrangle into two triangles, a hexahedron into
//! six tetrahedra, a prism into three, a pyramid into two), exact for straight-sided elements;
//! higher-order elements are read by their corners. A grid of bins over the group finds the
//! simplices near a point, so a query costs the few simplices of its bin.

use crate::box_bins::BoxBins;
use crate::error::{GraniteError, Result};
use crate::io::gmsh::{ElementShape, GmshMesh};
use crate::math::{cross3 as cross, dot3 as dot, norm3 as norm, scale3 as scale, sub3 as sub, Vec3};

/// Simplices of one dimension: segments (1), triangles (2) or tetrahedra (3), as corner lists.
#[derive(Debug, Clone)]
pub struct Simplices {
    pub dim: usize,
    pub corners: Vec<[Vec3; 4]>,
    bins: BoxBins,
}

/// The simplices an element splits into, as corner index lists.
fn split(shape: ElementShape) -> &'static [&'static [usize]] {
    match shape {
        ElementShape::Point => &[&[0]],
        ElementShape::Line => &[&[0, 1]],
        ElementShape::Triangle => &[&[0, 1, 2]],
        ElementShape::Quadrangle => &[&[0, 1, 2], &[0, 2, 3]],
        ElementShape::Tetrahedron => &[&[0, 1, 2, 3]],
        // Around the diagonal 0-6.
        ElementShape::Hexahedron => {
            &[&[0, 1, 2, 6], &[0, 2, 3, 6], &[0, 3, 7, 6], &[0, 7, 4, 6], &[0, 4, 5, 6], &[0, 5, 1, 6]]
        }
        ElementShape::Prism => &[&[0, 1, 2, 5], &[0, 1, 5, 4], &[0, 4, 5, 3]],
        ElementShape::Pyramid => &[&[0, 1, 2, 4], &[0, 2, 3, 4]],
    }
}

impl Simplices {
    /// The simplices of the elements of group `g` of `mesh`, with `space` the dimension of the
    /// space the caller works in (2: a plane simulation reads x and y only).
    pub fn of_group(mesh: &GmshMesh, g: usize, space: usize) -> Result<Simplices> {
        let group = &mesh.groups[g];
        let dim = group.dim as usize;
        let mut corners = Vec::new();
        for e in mesh.elements_of(g) {
            if e.shape.dim() as usize != dim {
                continue;
            }
            let at = mesh.corners(e);
            for s in split(e.shape) {
                let mut c = [[0.0; 3]; 4];
                for (k, &i) in s.iter().enumerate() {
                    c[k] = at[i];
                    if space == 2 {
                        c[k][2] = 0.0;
                    }
                }
                corners.push(c);
            }
        }
        if corners.is_empty() {
            return Err(GraniteError::Setup(format!("physical group \"{}\" holds no element", group.name)));
        }
        Ok(Simplices::from_corners(dim, corners))
    }

    /// Simplices of dimension `dim` from their corners (the first `dim + 1` of each).
    pub fn from_corners(dim: usize, corners: Vec<[Vec3; 4]>) -> Simplices {
        let n = dim + 1;
        let boxes: Vec<(Vec3, Vec3)> = corners
            .iter()
            .map(|c| {
                let lo = [0, 1, 2].map(|k| c[..n].iter().map(|p| p[k]).fold(f64::INFINITY, f64::min));
                let hi = [0, 1, 2].map(|k| c[..n].iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max));
                (lo, hi)
            })
            .collect();
        Simplices { dim, bins: BoxBins::new(&boxes), corners }
    }

    /// The simplices whose boxes lie within `reach` of `x`.
    fn near(&self, x: Vec3, reach: f64) -> impl Iterator<Item = usize> + '_ {
        self.bins.near(x, reach).into_iter().map(|s| s as usize)
    }

    /// Whether `x` lies in a triangle (2D group) or a tetrahedron (3D group), its boundary
    /// included to a relative `1e-12`.
    pub fn contains(&self, x: Vec3) -> bool {
        // The simplices whose boxes hold `x` are all listed in its cube.
        self.bins.at(x).iter().any(|&s| {
            let c = &self.corners[s as usize];
            match self.dim {
                2 => barycentric_triangle(x, c).iter().all(|&w| w >= -1e-12),
                3 => barycentric_tetrahedron(x, c).iter().all(|&w| w >= -1e-12),
                _ => false,
            }
        })
    }

    /// The distance from `x` to the nearest segment or triangle of the group, if one lies within
    /// `reach`.
    pub fn distance_within(&self, x: Vec3, reach: f64) -> Option<f64> {
        self.near(x, reach)
            .map(|s| {
                let c = &self.corners[s];
                match self.dim {
                    0 => norm(sub(x, c[0])),
                    1 => distance_to_segment(x, c[0], c[1]),
                    _ => distance_to_triangle(x, c[0], c[1], c[2]),
                }
            })
            .filter(|&d| d <= reach)
            .min_by(f64::total_cmp)
    }

    /// The nearest segment or triangle of the group within `reach` of `x`: its index and distance.
    pub fn nearest_within(&self, x: Vec3, reach: f64) -> Option<(usize, f64)> {
        self.near(x, reach)
            .map(|s| {
                let c = &self.corners[s];
                let d = match self.dim {
                    1 => distance_to_segment(x, c[0], c[1]),
                    _ => distance_to_triangle(x, c[0], c[1], c[2]),
                };
                (s, d)
            })
            .filter(|&(_, d)| d <= reach)
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// The unit normal of segment (in the plane z = 0) or triangle `s`, in the orientation its
    /// corners give, and its length or area.
    pub fn normal_and_measure(&self, s: usize) -> (Vec3, f64) {
        let c = &self.corners[s];
        let (n, measure) = match self.dim {
            1 => {
                let t = sub(c[1], c[0]);
                ([t[1], -t[0], 0.0], norm(t))
            }
            _ => {
                let n = cross(sub(c[1], c[0]), sub(c[2], c[0]));
                (n, 0.5 * norm(n))
            }
        };
        let l = norm(n);
        (if l > 0.0 { scale(n, 1.0 / l) } else { n }, measure)
    }

    /// Where the group's simplex `s` lies: one of its corners.
    pub fn corner(&self, s: usize) -> Vec3 {
        self.corners[s][0]
    }

    /// Length, area or volume of the group.
    pub fn measure(&self) -> f64 {
        self.corners
            .iter()
            .map(|c| match self.dim {
                1 => norm(sub(c[1], c[0])),
                2 => 0.5 * norm(cross(sub(c[1], c[0]), sub(c[2], c[0]))),
                3 => dot(sub(c[1], c[0]), cross(sub(c[2], c[0]), sub(c[3], c[0]))).abs() / 6.0,
                _ => 0.0,
            })
            .sum()
    }

    /// The unit normals of the segments (in the plane z = 0) or triangles, weighted by their
    /// measure and summed with the orientation of the first: the group's mean normal direction
    /// (a curve or surface group that bounds a body along one direction).
    pub fn mean_normal(&self) -> Vec3 {
        let mut sum = [0.0; 3];
        let mut first: Option<Vec3> = None;
        for c in &self.corners {
            let n = match self.dim {
                1 => {
                    let t = sub(c[1], c[0]);
                    [t[1], -t[0], 0.0]
                }
                2 => scale(cross(sub(c[1], c[0]), sub(c[2], c[0])), 0.5),
                _ => continue,
            };
            let reference = *first.get_or_insert(n);
            let n = if dot(n, reference) < 0.0 { scale(n, -1.0) } else { n };
            sum = [sum[0] + n[0], sum[1] + n[1], sum[2] + n[2]];
        }
        let l = norm(sum);
        if l > 0.0 {
            scale(sum, 1.0 / l)
        } else {
            sum
        }
    }
}

/// Barycentric weights of `x` (its x and y) in the triangle `c[0..3]` (in the plane z = 0).
fn barycentric_triangle(x: Vec3, c: &[Vec3; 4]) -> [f64; 3] {
    let (a, b, d) = (c[0], c[1], c[2]);
    let det = (b[0] - a[0]) * (d[1] - a[1]) - (d[0] - a[0]) * (b[1] - a[1]);
    if det == 0.0 {
        return [-1.0; 3];
    }
    let l1 = ((x[0] - a[0]) * (d[1] - a[1]) - (d[0] - a[0]) * (x[1] - a[1])) / det;
    let l2 = ((b[0] - a[0]) * (x[1] - a[1]) - (x[0] - a[0]) * (b[1] - a[1])) / det;
    [1.0 - l1 - l2, l1, l2]
}

/// Barycentric weights of `x` in the tetrahedron `c`.
fn barycentric_tetrahedron(x: Vec3, c: &[Vec3; 4]) -> [f64; 4] {
    let (e1, e2, e3) = (sub(c[1], c[0]), sub(c[2], c[0]), sub(c[3], c[0]));
    let det = dot(e1, cross(e2, e3));
    if det == 0.0 {
        return [-1.0; 4];
    }
    let p = sub(x, c[0]);
    let l1 = dot(p, cross(e2, e3)) / det;
    let l2 = dot(e1, cross(p, e3)) / det;
    let l3 = dot(e1, cross(e2, p)) / det;
    [1.0 - l1 - l2 - l3, l1, l2, l3]
}

fn distance_to_segment(x: Vec3, a: Vec3, b: Vec3) -> f64 {
    let t = sub(b, a);
    let l2 = dot(t, t);
    let s = if l2 > 0.0 { (dot(sub(x, a), t) / l2).clamp(0.0, 1.0) } else { 0.0 };
    norm(sub(x, [a[0] + s * t[0], a[1] + s * t[1], a[2] + s * t[2]]))
}

/// Distance from `x` to the triangle `abc`: to its plane where the foot falls inside, else to
/// the nearest edge.
fn distance_to_triangle(x: Vec3, a: Vec3, b: Vec3, c: Vec3) -> f64 {
    let n = cross(sub(b, a), sub(c, a));
    let l = norm(n);
    if l > 0.0 {
        let n = scale(n, 1.0 / l);
        let h = dot(sub(x, a), n);
        let foot = sub(x, scale(n, h));
        let inside = [(a, b), (b, c), (c, a)].iter().all(|&(p, q)| dot(cross(sub(q, p), sub(foot, p)), n) >= 0.0);
        if inside {
            return h.abs();
        }
    }
    distance_to_segment(x, a, b).min(distance_to_segment(x, b, c)).min(distance_to_segment(x, c, a))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_square_as_two_triangles() -> Simplices {
        let z = [0.0; 3];
        Simplices::from_corners(
            2,
            vec![
                [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], z],
                [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], z],
            ],
        )
    }

    #[test]
    fn a_square_of_two_triangles_holds_its_inside_and_its_edges() {
        let s = unit_square_as_two_triangles();
        assert_eq!(s.measure(), 1.0);
        for p in [[0.5, 0.5, 0.0], [0.0, 0.0, 0.0], [1.0, 0.3, 0.0], [0.99, 0.01, 0.0]] {
            assert!(s.contains(p), "{p:?}");
        }
        for p in [[1.01, 0.5, 0.0], [-0.01, 0.5, 0.0], [0.5, 1.2, 0.0]] {
            assert!(!s.contains(p), "{p:?}");
        }
    }

    #[test]
    fn distance_to_a_triangle_is_to_its_plane_over_it_and_to_an_edge_beside_it() {
        let (a, b, c) = ([0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]);
        assert_eq!(distance_to_triangle([0.5, 0.5, 0.3], a, b, c), 0.3);
        // Beside the hypotenuse x + y = 2, at (1.5, 1.5, 0): sqrt(2)/2 from it.
        assert!((distance_to_triangle([1.5, 1.5, 0.0], a, b, c) - 0.5f64.sqrt()).abs() < 1e-15);
        assert_eq!(distance_to_triangle([-1.0, 0.0, 0.0], a, b, c), 1.0);
    }

    #[test]
    fn a_unit_cube_of_six_tetrahedra_has_unit_volume_and_holds_its_centre() {
        let corners = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
        ];
        let tets = split(ElementShape::Hexahedron)
            .iter()
            .map(|s| [corners[s[0]], corners[s[1]], corners[s[2]], corners[s[3]]])
            .collect();
        let cube = Simplices::from_corners(3, tets);
        assert!((cube.measure() - 1.0).abs() < 1e-15);
        assert!(cube.contains([0.5, 0.5, 0.5]) && cube.contains([0.1, 0.9, 0.2]));
        assert!(!cube.contains([0.5, 0.5, 1.1]));
    }
}
