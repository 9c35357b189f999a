//! The shape of a potential particle (Houlsby 2009; Boon, Houlsby & Utili 2013; thesis eq. 2.1):
//!
//! `f(x) = (1 - k) (sum_i <n_i . x - d_i>^2 / r^2 - 1) + k (|x - s|^2 / R^2 - 1)`
//!
//! with planes `n_i . x = d_i` (unit outward normals) whose interior is a convex polytope,
//! Macaulay brackets `<v> = max(v, 0)`, rounding radius `r`, shadow-sphere radius `R` centred at
//! `s`, and sphericity `0 < k <= 1`. `f < 0` inside, `f = 0` on the surface, `f > 0` outside; `f` is
//! convex, piecewise quadratic and continuously differentiable. `k = 1` is a sphere of radius `R`;
//! `k = 0` is the polytope grown by `r` in every direction (its Minkowski sum with a ball).
//!
//! A shape is kept in its body frame: origin at its centre of mass, axes along its principal
//! axes of inertia, so that a particle's pose is a position and a rotation, and its inertia three
//! numbers.

use granite_core::error::{GraniteError, Result};
use granite_core::math::{dot3, Vec3};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};

/// A potential particle's shape in its body frame (see the module's text).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PotentialShape {
    /// Unit outward normals and distances of the planes, `n . x = d`.
    pub planes: Vec<(Vec3, f64)>,
    /// Rounding radius `r` (m).
    pub r: f64,
    /// Shadow-sphere radius `R` (m) and centre `s` (body frame).
    pub big_r: f64,
    pub sphere_centre: Vec3,
    /// Sphericity `k`, in (0, 1].
    pub k: f64,
    /// Volume (m^3) and principal moments of inertia per unit density (m^5), from
    /// [`PotentialShape::new`]'s integration.
    pub volume: f64,
    pub inertia_per_density: Vec3,
    /// A radius no point of the particle lies beyond, from its centre of mass (m).
    pub bounding_radius: f64,
    /// Points the heap measures follow the particle by (body frame): the vertices of its planes'
    /// polytope (for the thesis's tetrahedron, the centres of the clump's spheres, as in thesis
    /// 2.2.2.2), or its centre of mass when the planes bound no polytope.
    pub monitor_points: Vec<Vec3>,
}

/// Grid points per axis of the integration of a shape's volume and inertia: at 120 the
/// tetrahedral particle of thesis table 2.2 gets table 2.3's volume within 0.1 %.
pub const MASS_RESOLUTION: usize = 120;

impl PotentialShape {
    /// A shape from planes `n . x = d` (normals need not be unit: they are normalised with their
    /// distance), `r`, `R`, `k`, in the coordinates the planes are given in (shadow sphere at their
    /// origin). The shape is integrated on a grid of `resolution`^3 points for its centre of mass
    /// and inertia, then moved into its body frame.
    pub fn new(planes: &[(Vec3, f64)], r: f64, big_r: f64, k: f64, resolution: usize) -> Result<PotentialShape> {
        if !(r > 0.0 && r.is_finite()) {
            return Err(GraniteError::param("r", r, "the rounding radius must be > 0 (m)"));
        }
        if !(big_r > 0.0 && big_r.is_finite()) {
            return Err(GraniteError::param("R", big_r, "the shadow sphere's radius must be > 0 (m)"));
        }
        if !(k > 0.0 && k <= 1.0) {
            return Err(GraniteError::param("k", k, "the sphericity must be in (0, 1]"));
        }
        if planes.is_empty() && k < 1.0 {
            return Err(GraniteError::Setup("a potential particle with k < 1 needs at least one plane".into()));
        }
        let mut unit = Vec::with_capacity(planes.len());
        for (i, &(n, d)) in planes.iter().enumerate() {
            let norm = dot3(n, n).sqrt();
            if !(norm > 0.0 && norm.is_finite() && d.is_finite()) {
                return Err(GraniteError::Setup(format!(
                    "plane {} of a potential particle: normal {n:?} and distance {d} must be finite, the normal not zero",
                    i + 1
                )));
            }
            unit.push(([n[0] / norm, n[1] / norm, n[2] / norm], d / norm));
        }
        let given = PotentialShape {
            planes: unit.clone(),
            r,
            big_r,
            sphere_centre: [0.0; 3],
            k,
            volume: 0.0,
            inertia_per_density: [0.0; 3],
            bounding_radius: reach_bound(&unit, r, big_r, k, [0.0; 3]),
            monitor_points: Vec::new(),
        };
        let (volume, centroid, inertia) = given.integrate(resolution.max(8));
        if !(volume > 0.0) {
            return Err(GraniteError::Setup(format!(
                "a potential particle with r = {r}, R = {big_r}, k = {k} and these planes encloses no volume \
                 (its grid of {resolution}^3 points found none inside)"
            )));
        }
        // Axes the inertia is already diagonal in (to the integration's accuracy) are kept, so that
        // a box or a regular shape keeps the frame its planes were given in; otherwise principal
        // axes, sorted by moment, as a proper rotation from body to given coordinates.
        let off_diagonal = inertia[(0, 1)].abs() + inertia[(0, 2)].abs() + inertia[(1, 2)].abs();
        if off_diagonal <= 1e-4 * inertia.trace() {
            let moments = [inertia[(0, 0)], inertia[(1, 1)], inertia[(2, 2)]];
            return Ok(given.moved(centroid, &Matrix3::identity(), volume, moments));
        }
        let eigen = SymmetricEigen::new(inertia);
        let mut order = [0, 1, 2];
        order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
        let mut q = Matrix3::from_columns(&order.map(|i| eigen.eigenvectors.column(i).into_owned()));
        if q.determinant() < 0.0 {
            q.set_column(2, &(-q.column(2)));
        }
        Ok(given.moved(centroid, &q, volume, order.map(|i| eigen.eigenvalues[i])))
    }

    /// This shape with its centre of mass `c` as origin and the columns of `q` as axes.
    fn moved(&self, c: Vec3, q: &Matrix3<f64>, volume: f64, moments: Vec3) -> PotentialShape {
        let to_body = |v: Vec3| {
            let b = q.transpose() * Vector3::new(v[0], v[1], v[2]);
            [b[0], b[1], b[2]]
        };
        let planes: Vec<(Vec3, f64)> = self.planes.iter().map(|&(n, d)| (to_body(n), d - dot3(n, c))).collect();
        let s = self.sphere_centre;
        let sphere_centre = to_body([s[0] - c[0], s[1] - c[1], s[2] - c[2]]);
        PotentialShape {
            sphere_centre,
            volume,
            inertia_per_density: moments,
            bounding_radius: reach_bound(&planes, self.r, self.big_r, self.k, sphere_centre),
            monitor_points: polytope_vertices(&planes).unwrap_or_else(|| vec![[0.0; 3]]),
            planes,
            ..self.clone()
        }
    }

    /// The rounded tetrahedron of thesis table 2.2: faces through the centres of the 4-sphere clump
    /// of spheres `r_sphere` inscribed in `r_clump` (`dem::clump::tetrahedral_members`), rounding
    /// radius `r_sphere`, shadow sphere `big_r` (the thesis: `sqrt(2) r_sphere`), sphericity `k`.
    pub fn rounded_tetrahedron(r_sphere: f64, r_clump: f64, big_r: f64, k: f64) -> Result<PotentialShape> {
        if !(r_sphere > 0.0 && r_clump > r_sphere) {
            return Err(GraniteError::param("r_clump", r_clump, "needs r_clump > r_sphere > 0"));
        }
        PotentialShape::new(&tetrahedron_planes(r_clump - r_sphere), r_sphere, big_r, k, MASS_RESOLUTION)
    }

    /// `f(x)` (body frame).
    #[inline]
    pub fn value(&self, x: Vec3) -> f64 {
        potential::<false, false>(&self.planes, self.sphere_centre, self.weights(), x).0
    }

    /// `f(x)`, its gradient and its Hessian (constant between the planes' switches), body frame.
    pub fn value_gradient_hessian(&self, x: Vec3) -> (f64, Vec3, Matrix3<f64>) {
        potential::<true, true>(&self.planes, self.sphere_centre, self.weights(), x)
    }

    /// The weights of the plane and sphere terms, `(1 - k)/r^2` and `k/R^2`, with the constant
    /// `-(1 - k) - k = -1`.
    pub(crate) fn weights(&self) -> [f64; 2] {
        [(1.0 - self.k) / (self.r * self.r), self.k / (self.big_r * self.big_r)]
    }

    /// Volume, centroid and inertia tensor per unit density of `f <= 0`, by the midpoint rule on
    /// `n`^3 cells of the bounding cube.
    fn integrate(&self, n: usize) -> (f64, Vec3, Matrix3<f64>) {
        let (lo, hi) = self.bounds();
        // `n` cells along each axis of the bounding box: a thin plate gets as many across its
        // thickness as along its length.
        let h = [0, 1, 2].map(|a| (hi[a] - lo[a]) / n as f64);
        let at = |i: usize, a: usize| lo[a] + (i as f64 + 0.5) * h[a];
        // Sums in f64 over a fixed order: the same numbers on any machine.
        let (mut count, mut first, mut second) = (0.0, [0.0; 3], Matrix3::zeros());
        for i in 0..n {
            for j in 0..n {
                for l in 0..n {
                    let x = [at(i, 0), at(j, 1), at(l, 2)];
                    if self.value(x) <= 0.0 {
                        count += 1.0;
                        for a in 0..3 {
                            first[a] += x[a];
                            for b in 0..3 {
                                second[(a, b)] += x[a] * x[b];
                            }
                        }
                    }
                }
            }
        }
        let cell = h[0] * h[1] * h[2];
        let volume = count * cell;
        if count == 0.0 {
            return (0.0, [0.0; 3], Matrix3::zeros());
        }
        let centroid = first.map(|f| f / count);
        // Second moments about the centroid, then the inertia tensor I = tr(S) 1 - S.
        let mut s = second * cell;
        for a in 0..3 {
            for b in 0..3 {
                s[(a, b)] -= volume * centroid[a] * centroid[b];
            }
        }
        let inertia = Matrix3::identity() * s.trace() - s;
        (volume, centroid, inertia)
    }

    /// An axis-aligned box holding the particle: the bounding sphere's, narrowed to the polytope
    /// grown by the most the surface stands off a plane, `r / sqrt(1 - k)`, when that is bounded.
    fn bounds(&self) -> (Vec3, Vec3) {
        let (c, reach) = (self.sphere_centre, self.bounding_radius);
        let (mut lo, mut hi) = (c.map(|v| v - reach), c.map(|v| v + reach));
        if self.k < 1.0 {
            let grow = self.r / (1.0 - self.k).sqrt();
            let grown: Vec<(Vec3, f64)> = self.planes.iter().map(|&(n, d)| (n, d + grow)).collect();
            if let Some(vertices) = polytope_vertices(&grown) {
                for a in 0..3 {
                    let (min, max) = vertices
                        .iter()
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, u), v| (l.min(v[a]), u.max(v[a])));
                    lo[a] = lo[a].max(min);
                    hi[a] = hi[a].min(max);
                }
            }
        }
        (lo, hi)
    }

    /// A triangulated surface `f = 0` for pictures: rays from the centre of mass along the
    /// directions of a subdivided octahedron (`level` subdivisions: 8 * 4^level triangles), each
    /// cut where it meets the surface. Vertices (body frame) and triangles.
    pub fn surface(&self, level: usize) -> (Vec<Vec3>, Vec<[usize; 3]>) {
        let (mut vertices, mut triangles) = octahedron();
        for _ in 0..level {
            (vertices, triangles) = subdivided(&vertices, &triangles);
        }
        let points = vertices.iter().map(|&u| ray_to_surface(self, [0.0; 3], u, self.bounding_radius)).collect();
        (points, triangles)
    }
}

/// A radius about the origin beyond which `f > 0`, the smaller of two proven bounds:
/// - the shadow sphere: inside, `k (|x - s|^2/R^2 - 1) <= 1 - k`, so `|x - s| <= R / sqrt(k)`;
/// - the planes: inside, `(1 - k)(P(x)/r^2 - 1) <= k`, so every `<n_i . x - d_i>` is at most
///   `r / sqrt(1 - k)`: the point lies in the polytope grown by that much, whose farthest vertex
///   bounds it when that polytope is bounded.
fn reach_bound(planes: &[(Vec3, f64)], r: f64, big_r: f64, k: f64, s: Vec3) -> f64 {
    let sphere = big_r / k.sqrt() + dot3(s, s).sqrt();
    if k >= 1.0 {
        return sphere;
    }
    let grow = r / (1.0 - k).sqrt();
    let grown: Vec<(Vec3, f64)> = planes.iter().map(|&(n, d)| (n, d + grow)).collect();
    polytope_reach(&grown).map_or(sphere, |p| p.min(sphere))
}

/// The largest distance from the origin of a vertex of `{x : n_i . x <= d_i}` (unit normals), or
/// None when that set is unbounded or has no vertex.
fn polytope_reach(planes: &[(Vec3, f64)]) -> Option<f64> {
    polytope_vertices(planes)?.iter().map(|v| dot3(*v, *v).sqrt()).reduce(f64::max)
}

/// The vertices of `{x : n_i . x <= d_i}` (unit normals), or None when that set is unbounded or
/// has no vertex. It is bounded exactly when the cone `{u : n_i . u <= 0}` is `{0}`: with normals
/// spanning space that cone is pointed, and a pointed cone other than `{0}` has an edge
/// `+-(n_i x n_j)` on two of its planes. A vertex met by more than three planes is listed once.
pub fn polytope_vertices(planes: &[(Vec3, f64)]) -> Option<Vec<Vec3>> {
    let normals = Matrix3::from_fn(|i, j| planes.iter().map(|(n, _)| n[i] * n[j]).sum::<f64>());
    if planes.len() < 4 || normals.determinant().abs() < 1e-12 {
        return None;
    }
    let cross = |a: Vec3, b: Vec3| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    for (i, &(a, _)) in planes.iter().enumerate() {
        for &(b, _) in &planes[i + 1..] {
            let u = cross(a, b);
            if dot3(u, u) < 1e-24 {
                continue;
            }
            for sign in [1.0, -1.0] {
                if planes.iter().all(|(n, _)| sign * dot3(*n, u) <= 1e-12) {
                    return None;
                }
            }
        }
    }
    let scale = planes.iter().map(|(_, d)| d.abs()).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    let mut vertices: Vec<Vec3> = Vec::new();
    for i in 0..planes.len() {
        for j in i + 1..planes.len() {
            for l in j + 1..planes.len() {
                let (a, b, c) = (planes[i], planes[j], planes[l]);
                let m = Matrix3::from_rows(&[
                    Vector3::new(a.0[0], a.0[1], a.0[2]).transpose(),
                    Vector3::new(b.0[0], b.0[1], b.0[2]).transpose(),
                    Vector3::new(c.0[0], c.0[1], c.0[2]).transpose(),
                ]);
                let Some(v) = m.lu().solve(&Vector3::new(a.1, b.1, c.1)) else { continue };
                let v = [v[0], v[1], v[2]];
                let near = |w: &Vec3| (0..3).all(|k| (w[k] - v[k]).abs() <= 1e-9 * scale);
                if planes.iter().all(|(n, d)| dot3(*n, v) <= d + 1e-9 * scale) && !vertices.iter().any(near) {
                    vertices.push(v);
                }
            }
        }
    }
    (!vertices.is_empty()).then_some(vertices)
}

/// `f(x) = a sum <n_i . x - d_i>^2 + b |x - s|^2 - 1` for planes `(n_i, d_i)`, sphere centre `s`
/// and weights `[a, b]` (see [`PotentialShape::weights`]), in whatever frame the planes are given;
/// with its gradient when `GRADIENT`, and its Hessian when `HESSIAN` (zero otherwise).
#[inline(always)]
pub(crate) fn potential<const GRADIENT: bool, const HESSIAN: bool>(
    planes: &[(Vec3, f64)],
    s: Vec3,
    [a, b]: [f64; 2],
    x: Vec3,
) -> (f64, Vec3, Matrix3<f64>) {
    let y = [x[0] - s[0], x[1] - s[1], x[2] - s[2]];
    let mut sum = 0.0;
    let mut gradient = if GRADIENT { [2.0 * b * y[0], 2.0 * b * y[1], 2.0 * b * y[2]] } else { [0.0; 3] };
    let mut hessian = if HESSIAN { Matrix3::identity() * (2.0 * b) } else { Matrix3::zeros() };
    for &(n, d) in planes {
        let v = dot3(n, x) - d;
        if v > 0.0 {
            sum += v * v;
            if GRADIENT {
                for i in 0..3 {
                    gradient[i] += 2.0 * a * v * n[i];
                }
            }
            if HESSIAN {
                for i in 0..3 {
                    for j in 0..3 {
                        hessian[(i, j)] += 2.0 * a * n[i] * n[j];
                    }
                }
            }
        }
    }
    (a * sum + b * dot3(y, y) - 1.0, gradient, hessian)
}

/// The point where the ray from `from` (inside, `f < 0`) along unit `u` leaves the surface, found by
/// bisection on `[0, reach]` (`f` is convex along the ray, so it crosses zero once).
pub fn ray_to_surface(shape: &PotentialShape, from: Vec3, u: Vec3, reach: f64) -> Vec3 {
    let at = |t: f64| [from[0] + t * u[0], from[1] + t * u[1], from[2] + t * u[2]];
    let (mut lo, mut hi) = (0.0, reach);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if shape.value(at(mid)) > 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    at(0.5 * (lo + hi))
}

fn octahedron() -> (Vec<Vec3>, Vec<[usize; 3]>) {
    let v =
        vec![[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];
    let t = vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
    (v, t)
}

/// Each triangle cut into four, the new vertices pushed onto the unit sphere.
fn subdivided(vertices: &[Vec3], triangles: &[[usize; 3]]) -> (Vec<Vec3>, Vec<[usize; 3]>) {
    let mut v = vertices.to_vec();
    let mut middle = std::collections::HashMap::new();
    let mut mid = |a: usize, b: usize, v: &mut Vec<Vec3>| {
        *middle.entry((a.min(b), a.max(b))).or_insert_with(|| {
            let m = [0, 1, 2].map(|i| 0.5 * (v[a][i] + v[b][i]));
            let norm = dot3(m, m).sqrt();
            v.push(m.map(|c| c / norm));
            v.len() - 1
        })
    };
    let mut t = Vec::with_capacity(4 * triangles.len());
    for &[a, b, c] in triangles {
        let (ab, bc, ca) = (mid(a, b, &mut v), mid(b, c, &mut v), mid(c, a, &mut v));
        t.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    (v, t)
}

/// The planes of a regular tetrahedron whose vertices are those of the 4-sphere clump of thesis
/// table 2.3 (`dem::clump::tetrahedral_members`) of circumradius `circumradius`: each face lies
/// opposite a vertex `v`, with outward normal `-v / |v|`, at the inradius `circumradius / 3`.
pub fn tetrahedron_planes(circumradius: f64) -> Vec<(Vec3, f64)> {
    let s = 1.0 / 3f64.sqrt();
    [[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]]
        .iter()
        .map(|v: &Vec3| ([-v[0] * s, -v[1] * s, -v[2] * s], circumradius / 3.0))
        .collect()
}

/// The six planes of a box of half-sides `half`, axis-aligned about the origin.
pub fn box_planes(half: Vec3) -> Vec<(Vec3, f64)> {
    let mut planes = Vec::with_capacity(6);
    for a in 0..3 {
        for sign in [1.0, -1.0] {
            let mut n = [0.0; 3];
            n[a] = sign;
            planes.push((n, half[a]));
        }
    }
    planes
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn k_one_is_a_sphere_of_radius_big_r() {
        let r_big = 2e-3;
        let shape = PotentialShape::new(&box_planes([1e-3; 3]), 5e-4, r_big, 1.0, MASS_RESOLUTION).unwrap();
        let volume = 4.0 / 3.0 * PI * r_big.powi(3);
        assert!((shape.volume / volume - 1.0).abs() < 2e-3, "{} against {volume}", shape.volume);
        let moment = 0.4 * volume * r_big * r_big;
        for m in shape.inertia_per_density {
            assert!((m / moment - 1.0).abs() < 5e-3, "{m} against {moment}");
        }
        assert!(dot3(shape.sphere_centre, shape.sphere_centre).sqrt() < 1e-3 * r_big);
        assert!((shape.bounding_radius / r_big - 1.0).abs() < 2e-3);
        // The surface is the sphere: f = 0 at distance R in any direction.
        let p = ray_to_surface(&shape, shape.sphere_centre, [0.6, 0.0, 0.8], shape.bounding_radius);
        let s = shape.sphere_centre;
        let d = dot3([p[0] - s[0], p[1] - s[1], p[2] - s[2]], [p[0] - s[0], p[1] - s[1], p[2] - s[2]]).sqrt();
        assert!((d / r_big - 1.0).abs() < 1e-12);
    }

    /// With `k` near 0 a box grows by `r` in every direction: Steiner's formula for a cube of side
    /// `a` grown by `r`, `a^3 + 6 a^2 r + 3 pi a r^2 + 4/3 pi r^3`.
    #[test]
    fn a_rounded_cube_has_steiners_volume() {
        let (a, r) = (2e-3, 5e-4);
        let k = 1e-9;
        // Turned, so that no face lies along the integration grid (where counting cell centres
        // errs by up to half a cell on the whole face).
        let turn = nalgebra::Rotation3::from_euler_angles(0.3, 0.5, 0.7);
        let planes: Vec<(Vec3, f64)> = box_planes([0.5 * a; 3])
            .into_iter()
            .map(|(n, d)| {
                let m = turn * Vector3::new(n[0], n[1], n[2]);
                ([m[0], m[1], m[2]], d)
            })
            .collect();
        let shape = PotentialShape::new(&planes, r, 10.0 * a, k, 200).unwrap();
        let steiner = a.powi(3) + 6.0 * a * a * r + 3.0 * PI * a * r * r + 4.0 / 3.0 * PI * r.powi(3);
        assert!((shape.volume / steiner - 1.0).abs() < 5e-3, "{} against {steiner}", shape.volume);
        // Its moments are equal (cubic symmetry).
        let m = shape.inertia_per_density;
        assert!((m[0] / m[2] - 1.0).abs() < 1e-3, "{m:?}");
    }

    /// Thesis table 2.3: the rounded tetrahedron of table 2.2 (r = r_s, R = sqrt(2) r_s, k = 0.65,
    /// faces through the clump's sphere centres) has volume 3.9248e-7 m^3 and inertia / density
    /// 3.286e-12 m^5 about any axis.
    #[test]
    fn the_thesis_tetrahedron_has_table_2_3s_volume_and_inertia() {
        let (r_s, r_clump) = (0.3101e-2, 0.5e-2);
        // Table 2.2's distance, from the geometry.
        assert!((tetrahedron_planes(r_clump - r_s)[0].1 - 0.00063299).abs() < 1e-8);
        let shape = PotentialShape::rounded_tetrahedron(r_s, r_clump, 2f64.sqrt() * r_s, 0.65).unwrap();
        assert!((shape.volume / 3.9248e-7 - 1.0).abs() < 2e-3, "volume {}", shape.volume);
        for m in shape.inertia_per_density {
            assert!((m / 3.286e-12 - 1.0).abs() < 3e-3, "inertia / density {m}");
        }
    }

    /// The rounded tetrahedron is followed by its polytope's vertices, which are the centres of
    /// the 4-sphere clump's spheres (thesis 2.2.2.2: the planes were chosen so).
    #[test]
    fn the_tetrahedron_is_followed_by_the_clumps_sphere_centres() {
        let (r_s, r_clump) = (0.3101e-2, 0.5e-2);
        let shape = PotentialShape::rounded_tetrahedron(r_s, r_clump, 2f64.sqrt() * r_s, 0.65).unwrap();
        let centres = granite_core::dem::clump::tetrahedral_members([0.0; 3], r_s, r_clump).unwrap();
        assert_eq!(shape.monitor_points.len(), 4);
        for (c, _) in centres {
            let nearest = shape
                .monitor_points
                .iter()
                .map(|p| (0..3).map(|a| (p[a] - c[a]).powi(2)).sum::<f64>().sqrt())
                .fold(f64::INFINITY, f64::min);
            // The body frame's origin is the integrated centre of mass, a grid's error off.
            assert!(nearest < 1e-3 * r_clump, "sphere centre {c:?}: nearest vertex {nearest} m away");
        }
    }

    #[test]
    fn bad_shapes_are_refused_naming_the_parameter() {
        let planes = box_planes([1e-3; 3]);
        let e = PotentialShape::new(&planes, 1e-3, 1e-3, 0.0, 20).unwrap_err().to_string();
        assert!(e.contains("k") && e.contains("(0, 1]"), "{e}");
        let e = PotentialShape::new(&planes, -1.0, 1e-3, 0.5, 20).unwrap_err().to_string();
        assert!(e.contains("rounding radius"), "{e}");
        let e = PotentialShape::new(&[([0.0; 3], 1.0)], 1e-3, 1e-3, 0.5, 20).unwrap_err().to_string();
        assert!(e.contains("plane 1"), "{e}");
    }

    #[test]
    fn the_surface_lies_on_f_zero() {
        let shape = PotentialShape::new(&tetrahedron_planes(1.9e-3), 3.1e-3, 4.4e-3, 0.65, 60).unwrap();
        let (points, triangles) = shape.surface(2);
        assert_eq!(triangles.len(), 8 * 16);
        for p in points {
            assert!(shape.value(p).abs() < 1e-9);
        }
    }
}
