//! Boundary conditions on grid nodes: velocity constraints (eqs. 3.19-3.20), Coulomb friction on a
//! boundary (CB-Geo's friction constraint) and nodal forces (eq. 3.21-3.22).

use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use crate::mpm::mesh::Mesh;

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

/// All boundary conditions of a simulation. They refer to node indices of one mesh and are
/// cleared when the mesh is replaced.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Boundary {
    pub velocity: Vec<VelocityConstraint>,
    pub friction: Vec<FrictionConstraint>,
    pub forces: Vec<NodalForce>,
}

impl Boundary {
    pub fn clear(&mut self) {
        *self = Boundary::default();
    }

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
}
