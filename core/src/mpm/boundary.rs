//! Boundary conditions on grid nodes: velocity constraints (eqs. 3.19-3.20), Coulomb friction on a
//! boundary (CB-Geo's friction constraint) and nodal forces (eq. 3.21-3.22); and loads carried by
//! material points (CB-Geo's particle tractions), which follow the material.

use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use crate::mpm::mesh::Mesh;
use crate::region::Simplices;

/// A value that may change with time.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum TimeFunction {
    Constant(f64),
    /// Piecewise-linear table of (time, value), constant beyond its ends.
    Table(Vec<(f64, f64)>),
    /// Set from outside before each step (e.g. by a script function evaluated once per step).
    Driven(f64),
}

impl TimeFunction {
    pub fn table(points: Vec<(f64, f64)>) -> Result<TimeFunction> {
        if points.is_empty() {
            return Err(GraniteError::param("table", "[]", "needs at least one (time, value) pair"));
        }
        if points.iter().any(|(t, v)| !(t.is_finite() && v.is_finite())) {
            return Err(GraniteError::param("table", format!("{points:?}"), "times and values must be finite"));
        }
        if points.windows(2).any(|w| w[1].0 <= w[0].0) {
            return Err(GraniteError::param("table", "times", "times must increase strictly"));
        }
        Ok(TimeFunction::Table(points))
    }

    pub fn at(&self, t: f64) -> f64 {
        match self {
            TimeFunction::Constant(v) | TimeFunction::Driven(v) => *v,
            TimeFunction::Table(pts) => {
                if t <= pts[0].0 {
                    return pts[0].1;
                }
                for w in pts.windows(2) {
                    let ((t0, v0), (t1, v1)) = (w[0], w[1]);
                    if t <= t1 {
                        return v0 + (v1 - v0) * (t - t0) / (t1 - t0);
                    }
                }
                pts[pts.len() - 1].1
            }
        }
    }
}

/// A face of the mesh box: axis and side (`x-` is axis 0, lower side).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Face {
    pub axis: usize,
    pub upper: bool,
}

impl Face {
    pub fn parse(name: &str, dim: usize) -> Result<Face> {
        let allowed = if dim == 2 { "x-, x+, y-, y+" } else { "x-, x+, y-, y+, z-, z+" };
        let b = name.as_bytes();
        let axis = match b.first() {
            Some(b'x') => 0,
            Some(b'y') => 1,
            Some(b'z') if dim == 3 => 2,
            _ => return Err(GraniteError::param("face", name, &format!("must be one of {allowed}"))),
        };
        let upper = match &b[1..] {
            b"-" => false,
            b"+" => true,
            _ => return Err(GraniteError::param("face", name, &format!("must be one of {allowed}"))),
        };
        Ok(Face { axis, upper })
    }

    /// Nodes on this face of the mesh, in index order.
    pub fn nodes(&self, mesh: &Mesh) -> Vec<u32> {
        let n = mesh.nodes_per_axis();
        let fixed = if self.upper { n[self.axis] - 1 } else { 0 };
        (0..mesh.node_count()).filter(|&i| mesh.node_ijk(i)[self.axis] == fixed).map(|i| i as u32).collect()
    }

    /// Unit outward normal component along `axis`: +1 on an upper face, -1 on a lower one.
    pub fn outward_sign(&self) -> f64 {
        if self.upper {
            1.0
        } else {
            -1.0
        }
    }
}

/// `V_axis = value(t)` on a set of nodes, and zero acceleration along `axis` there.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct VelocityConstraint {
    pub nodes: Vec<u32>,
    pub axis: usize,
    pub value: TimeFunction,
}

/// Coulomb friction with a planar boundary of outward normal `sign * e_axis`: while a node moves
/// into the boundary, its normal velocity is removed and its tangential speed reduced by at most
/// `mu` times the removed normal speed (the impulse ratio of Coulomb's law).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct FrictionConstraint {
    pub nodes: Vec<u32>,
    pub axis: usize,
    pub sign: f64,
    pub mu: f64,
}

/// A force on each node of a set (N in 3D, N/m in 2D plane strain), scaled by `factor(t)`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct NodalForce {
    pub nodes: Vec<u32>,
    /// Force per node at factor 1 (one entry per node: tractions give unequal nodal shares).
    pub force: Vec<Vec3>,
    pub factor: TimeFunction,
}

/// A load carried by material points: a force on each point (a traction times the point's share
/// of the loaded surface; N in 3D, N/m in 2D plane strain), scaled by `factor(t)` and mapped to the
/// nodes by the point's shape functions at every step, as gravity is (the surface term of eq.
/// 3.21 lumped on the points next to the surface, CB-Geo's particle traction). Where the
/// material goes, the load goes: a footing that settles by cells stays loaded. The forces keep
/// the size and direction they were given (a dead load per reference area, the nominal traction).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct PointLoad {
    /// What was loaded, for messages (`group "footing"`).
    pub name: String,
    /// The loaded points by id (ids survive deletions and reordering).
    pub ids: Vec<u64>,
    /// Force on each point at factor 1.
    pub force: Vec<Vec3>,
    pub factor: TimeFunction,
    /// Each point's index among the points, as last found.
    #[serde(skip)]
    pub(crate) at: Vec<usize>,
}

impl PointLoad {
    pub fn new(name: String, ids: Vec<u64>, force: Vec<Vec3>, factor: TimeFunction) -> PointLoad {
        PointLoad { name, ids, force, factor, at: Vec::new() }
    }

    /// Finds the loaded points among `ids` (every point's id, in storage order) where they moved
    /// (deletions, insertions); points no longer there are dropped, their force with them.
    /// Returns how many were dropped and the force they carried.
    pub(crate) fn locate(&mut self, ids: &[u64]) -> (usize, Vec3) {
        let current =
            self.at.len() == self.ids.len() && self.at.iter().zip(&self.ids).all(|(&i, &id)| ids.get(i) == Some(&id));
        if current {
            return (0, [0.0; 3]);
        }
        let index: std::collections::HashMap<u64, usize> = ids.iter().enumerate().map(|(i, &id)| (id, i)).collect();
        let (mut lost, mut carried) = (0, [0.0; 3]);
        let mut kept = (Vec::new(), Vec::new(), Vec::new());
        for (&id, f) in self.ids.iter().zip(&self.force) {
            match index.get(&id) {
                Some(&i) => {
                    kept.0.push(id);
                    kept.1.push(*f);
                    kept.2.push(i);
                }
                None => {
                    lost += 1;
                    carried = [0, 1, 2].map(|a| carried[a] + f[a]);
                }
            }
        }
        (self.ids, self.force, self.at) = kept;
        (lost, carried)
    }
}

/// A material point's share of a surface it lies under: its size `V^(1/d)` to the power `d - 1`
/// (a length per unit thickness in 2D, an area in 3D), exact for the square or cubic points of a
/// regular fill (`per_cell` points a cell side).
pub fn surface_share(volume: f64, dim: usize) -> f64 {
    volume.powf((dim as f64 - 1.0) / dim as f64)
}

/// The size of a point of `volume`: the side of a square (2D) or cube (3D) of that volume.
pub fn point_size(volume: f64, dim: usize) -> f64 {
    volume.powf(1.0 / dim as f64)
}

/// All boundary conditions of a simulation. Those on nodes refer to node indices of one mesh and
/// are cleared when the mesh is replaced; point loads stay with their points.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Boundary {
    pub velocity: Vec<VelocityConstraint>,
    pub friction: Vec<FrictionConstraint>,
    pub forces: Vec<NodalForce>,
    #[serde(default)]
    pub point_loads: Vec<PointLoad>,
}

impl Boundary {
    /// Clears the conditions on nodes (the mesh is replaced); point loads stay.
    pub fn clear(&mut self) {
        self.velocity.clear();
        self.friction.clear();
        self.forces.clear();
    }

    /// Whether no condition holds the nodes (point loads aside).
    pub fn is_empty(&self) -> bool {
        self.velocity.is_empty() && self.friction.is_empty() && self.forces.is_empty()
    }

    /// Nodal forces equivalent to a uniform traction on a mesh face (eq. 3.22 with linear shape
    /// functions: each node carries the face area it is closest to).
    pub fn traction_on_face(mesh: &Mesh, face: Face, traction: Vec3) -> (Vec<u32>, Vec<Vec3>) {
        let nodes = face.nodes(mesh);
        let n = mesh.nodes_per_axis();
        let forces = nodes
            .iter()
            .map(|&i| {
                let ijk = mesh.node_ijk(i as usize);
                let mut area = 1.0;
                for a in 0..mesh.dim {
                    if a == face.axis {
                        continue;
                    }
                    let share = if ijk[a] == 0 || ijk[a] == n[a] - 1 { 0.5 } else { 1.0 };
                    area *= share * mesh.cell[a];
                }
                [traction[0] * area, traction[1] * area, traction[2] * area]
            })
            .collect();
        (nodes, forces)
    }
}

/// The grid nodes within `reach` of a group of mesh elements (its curves or surfaces).
pub fn nodes_near(mesh: &Mesh, group: &Simplices, reach: f64) -> Vec<u32> {
    (0..mesh.node_count())
        .filter(|&i| group.distance_within(mesh.node_position(i), reach).is_some())
        .map(|i| i as u32)
        .collect()
}

/// The grid nodes of cell `base` (its lowest corner's node coordinates) and their linear shape
/// functions at `x`.
fn cell_weights(mesh: &Mesh, base: [usize; 3], x: Vec3) -> impl Iterator<Item = (usize, f64)> + '_ {
    let frac: Vec3 =
        [0, 1, 2].map(|a| if a < mesh.dim { (x[a] - mesh.origin[a]) / mesh.cell[a] - base[a] as f64 } else { 0.0 });
    (0..1usize << mesh.dim).map(move |c| {
        let mut ijk = base;
        let mut w = 1.0;
        for a in 0..mesh.dim {
            let up = (c >> a) & 1;
            ijk[a] += up;
            w *= if up == 1 { frac[a] } else { 1.0 - frac[a] };
        }
        (mesh.node_index(ijk), w)
    })
}

/// Clips a convex polygon to the half-space `x[axis] <= value` (`below`) or `>= value`.
fn clip(polygon: &[Vec3], axis: usize, value: f64, below: bool) -> Vec<Vec3> {
    let inside = |p: &Vec3| if below { p[axis] <= value } else { p[axis] >= value };
    let mut out = Vec::with_capacity(polygon.len() + 2);
    for (k, p) in polygon.iter().enumerate() {
        let q = &polygon[(k + 1) % polygon.len()];
        if inside(p) {
            out.push(*p);
        }
        if inside(p) != inside(q) {
            let s = (value - p[axis]) / (q[axis] - p[axis]);
            out.push([0, 1, 2].map(|a| if a == axis { value } else { p[a] + s * (q[a] - p[a]) }));
        }
    }
    out
}

/// Nodal forces of a uniform traction on a curve (plane strain, per unit thickness) or a surface
/// (3D) given as segments or triangles: eq. 3.22, `f_I = integral of N_I t over the boundary`
/// with the grid's linear shape functions. Each segment or triangle is cut at the cells' faces;
/// on a piece inside one cell `N_I` is a polynomial of degree 2 (plane) or 3 (3D), integrated
/// exactly by Gauss' two points on a segment and Strang and Fix's four points on a triangle. The
/// forces sum to the traction times the length or area. Refused where the boundary leaves the
/// mesh.
pub fn traction_on_simplices(mesh: &Mesh, boundary: &Simplices, traction: Vec3) -> Result<(Vec<u32>, Vec<Vec3>)> {
    if boundary.dim + 1 != mesh.dim {
        return Err(GraniteError::Setup(format!(
            "a traction in {}D acts on {} (a group of dimension {}), not on a group of dimension {}",
            mesh.dim,
            if mesh.dim == 2 { "curves" } else { "surfaces" },
            mesh.dim - 1,
            boundary.dim
        )));
    }
    let mut share: std::collections::BTreeMap<usize, f64> = Default::default();
    let n = boundary.dim + 1;
    for c in &boundary.corners {
        let corners = &c[..n];
        for x in corners {
            if mesh.locate(*x).is_none() {
                return Err(GraniteError::Setup(format!("the boundary reaches {x:?}, outside the background mesh")));
            }
        }
        // The cells the element's bounding box spans.
        let mut range = [(0usize, 0usize); 3];
        for a in 0..mesh.dim {
            let t = |x: &Vec3| (x[a] - mesh.origin[a]) / mesh.cell[a];
            let lo = corners.iter().map(t).fold(f64::INFINITY, f64::min).floor().max(0.0) as usize;
            let hi = corners.iter().map(t).fold(f64::NEG_INFINITY, f64::max).floor() as usize;
            range[a] = (lo.min(mesh.cells[a] - 1), hi.min(mesh.cells[a] - 1));
        }
        for k in range[2].0..=range[2].1 {
            for j in range[1].0..=range[1].1 {
                for i in range[0].0..=range[0].1 {
                    let base = [i, j, k];
                    let mut piece: Vec<Vec3> = corners.to_vec();
                    for a in 0..mesh.dim {
                        let lo = mesh.origin[a] + base[a] as f64 * mesh.cell[a];
                        piece = clip(&piece, a, lo, false);
                        piece = clip(&piece, a, lo + mesh.cell[a], true);
                    }
                    let mut add = |x: Vec3, measure: f64| {
                        // A node the boundary only passes at the far side of its cell gets no share.
                        for (node, w) in cell_weights(mesh, base, x).filter(|&(_, w)| w != 0.0) {
                            *share.entry(node).or_insert(0.0) += w * measure;
                        }
                    };
                    if boundary.dim == 1 {
                        // A clipped segment comes back as its two ends (and their copies).
                        if piece.len() < 2 {
                            continue;
                        }
                        let (p, q) = (piece[0], piece[1]);
                        let length = crate::math::norm3(crate::math::sub3(q, p));
                        let g = 0.5 / 3f64.sqrt();
                        for s in [0.5 - g, 0.5 + g] {
                            add([0, 1, 2].map(|a| p[a] + s * (q[a] - p[a])), 0.5 * length);
                        }
                    } else {
                        for t in 1..piece.len().saturating_sub(1) {
                            let (p, q, r) = (piece[0], piece[t], piece[t + 1]);
                            let area = 0.5
                                * crate::math::norm3(crate::math::cross3(
                                    crate::math::sub3(q, p),
                                    crate::math::sub3(r, p),
                                ));
                            let at = |l: [f64; 3]| [0, 1, 2].map(|a| l[0] * p[a] + l[1] * q[a] + l[2] * r[a]);
                            add(at([1.0 / 3.0; 3]), -27.0 / 48.0 * area);
                            for l in [[0.6, 0.2, 0.2], [0.2, 0.6, 0.2], [0.2, 0.2, 0.6]] {
                                add(at(l), 25.0 / 48.0 * area);
                            }
                        }
                    }
                }
            }
        }
    }
    let nodes = share.keys().map(|&n| n as u32).collect();
    let forces = share.values().map(|&a| traction.map(|t| t * a)).collect();
    Ok((nodes, forces))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_interpolates_and_clamps() {
        let f = TimeFunction::table(vec![(0.0, 0.0), (1.0, 2.0), (3.0, 2.0)]).unwrap();
        assert_eq!(f.at(-1.0), 0.0);
        assert!((f.at(0.25) - 0.5).abs() < 1e-15);
        assert_eq!(f.at(10.0), 2.0);
        assert!(TimeFunction::table(vec![(1.0, 0.0), (1.0, 1.0)]).is_err());
    }

    #[test]
    fn face_traction_sums_to_traction_times_area() {
        let mesh = Mesh::new(3, [0.0; 3], [0.5, 0.25, 1.0], [2, 4, 3]).unwrap();
        let (nodes, forces) = Boundary::traction_on_face(&mesh, Face::parse("x+", 3).unwrap(), [-100.0, 0.0, 0.0]);
        assert_eq!(nodes.len(), 5 * 4);
        let total: f64 = forces.iter().map(|f| f[0]).sum();
        assert!((total - (-100.0 * 1.0 * 3.0)).abs() < 1e-9);
    }

    /// The face x+ of `mesh` as two triangles.
    fn face_as_triangles(mesh: &Mesh) -> Simplices {
        let (lo, hi) = (mesh.origin, mesh.upper());
        let p = |y: f64, z: f64| [hi[0], y, z];
        Simplices::from_corners(
            2,
            vec![
                [p(lo[1], lo[2]), p(hi[1], lo[2]), p(hi[1], hi[2]), [0.0; 3]],
                [p(lo[1], lo[2]), p(hi[1], hi[2]), p(lo[1], hi[2]), [0.0; 3]],
            ],
        )
    }

    #[test]
    fn a_traction_on_triangles_over_a_face_gives_the_face_s_nodal_forces() {
        let mesh = Mesh::new(3, [0.0; 3], [0.5, 0.25, 1.0], [2, 4, 3]).unwrap();
        let t = [-100.0, 20.0, 0.0];
        let (face_nodes, face_forces) = Boundary::traction_on_face(&mesh, Face::parse("x+", 3).unwrap(), t);
        let (nodes, forces) = traction_on_simplices(&mesh, &face_as_triangles(&mesh), t).unwrap();
        let mut expected: Vec<(u32, Vec3)> = face_nodes.into_iter().zip(face_forces).collect();
        expected.sort_by_key(|e| e.0);
        assert_eq!(nodes, expected.iter().map(|e| e.0).collect::<Vec<_>>());
        for ((n, f), g) in expected.iter().zip(&forces) {
            // Exact integration: the same forces but for rounding.
            assert!((0..3).all(|a| (f[a] - g[a]).abs() < 1e-12 * 100.0), "node {n}: {f:?} against {g:?}");
        }
    }

    #[test]
    fn a_traction_on_a_slanted_segment_sums_to_traction_times_length() {
        let mesh = Mesh::new(2, [0.0; 3], [0.3, 0.2, 1.0], [10, 10, 1]).unwrap();
        let (a, b) = ([0.1, 0.15, 0.0], [2.7, 1.85, 0.0]);
        let segment = Simplices::from_corners(1, vec![[a, b, [0.0; 3], [0.0; 3]]]);
        let t = [3.0, -4.0, 0.0];
        let (_, forces) = traction_on_simplices(&mesh, &segment, t).unwrap();
        let length = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
        for k in 0..2 {
            let total: f64 = forces.iter().map(|f| f[k]).sum();
            assert!((total - t[k] * length).abs() < 1e-12 * length * 5.0, "{total}");
        }
        // Nodes within half a cell of the segment: those of the cells it crosses, nearest first.
        let near = nodes_near(&mesh, &segment, 0.5 * mesh.min_cell());
        assert!(near.iter().all(|&n| segment.distance_within(mesh.node_position(n as usize), 0.1).is_some()));
        assert!(!near.is_empty());
    }
}
