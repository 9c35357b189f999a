//! Regular background mesh of 4-node quadrilaterals (2D plane strain) or 8-node hexahedra (3D).
//!
//! Nodes are numbered x fastest, then y, then z; so are cells. The "slab" axis is the last active
//! one (y in 2D, z in 3D): a slab is one layer of cells along it, and slabs two apart share no node,
//! which is what lets the particle-to-grid scatter run in parallel without atomics.

use crate::error::{GraniteError, Result};
use crate::math::Vec3;

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Mesh {
    pub dim: usize,
    pub origin: Vec3,
    /// Cell size along each axis (in 2D the z entry is the unit thickness, 1 m).
    pub cell: Vec3,
    /// Cells along each axis (in 2D the z entry is 1).
    pub cells: [usize; 3],
}

/// Where a point sits: its position in cell lengths from the origin along each axis, in
/// `[0, cells]` (nodes at the integers; 0 on the unused z axis of 2D meshes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Location {
    pub t: Vec3,
}

impl Mesh {
    pub fn new(dim: usize, origin: Vec3, cell: Vec3, cells: [usize; 3]) -> Result<Mesh> {
        if dim != 2 && dim != 3 {
            return Err(GraniteError::param("dim", dim, "must be 2 (plane strain) or 3"));
        }
        for a in 0..dim {
            if !(cell[a] > 0.0 && cell[a].is_finite()) {
                return Err(GraniteError::param("cell", cell[a], "cell sizes must be > 0"));
            }
            if cells[a] == 0 {
                return Err(GraniteError::param("cells", 0, "every axis needs at least one cell"));
            }
        }
        let mut cells = cells;
        let mut cell = cell;
        if dim == 2 {
            cells[2] = 1;
            cell[2] = 1.0;
        }
        let nodes =
            (cells[0] as f64 + 1.0) * (cells[1] as f64 + 1.0) * if dim == 3 { cells[2] as f64 + 1.0 } else { 1.0 };
        if nodes > u32::MAX as f64 / 2.0 {
            return Err(GraniteError::param("cells", nodes, "too many nodes for one mesh"));
        }
        crate::memory::check("the mesh", nodes, "nodes", crate::memory::BYTES_PER_NODE, "use fewer or larger cells")?;
        Ok(Mesh { dim, origin, cell, cells })
    }

    /// Nodes along each axis (2D: z has a single node layer).
    pub fn nodes_per_axis(&self) -> [usize; 3] {
        [self.cells[0] + 1, self.cells[1] + 1, if self.dim == 3 { self.cells[2] + 1 } else { 1 }]
    }

    pub fn node_count(&self) -> usize {
        let n = self.nodes_per_axis();
        n[0] * n[1] * n[2]
    }

    pub fn cell_count(&self) -> usize {
        self.cells[0] * self.cells[1] * self.cells[2]
    }

    pub fn slab_axis(&self) -> usize {
        self.dim - 1
    }

    /// Nodes in one node plane normal to the slab axis.
    pub fn nodes_per_plane(&self) -> usize {
        let n = self.nodes_per_axis();
        if self.dim == 3 {
            n[0] * n[1]
        } else {
            n[0]
        }
    }

    /// The smallest cell size over the active axes.
    pub fn min_cell(&self) -> f64 {
        self.cell[..self.dim].iter().copied().fold(f64::INFINITY, f64::min)
    }

    pub fn cell_volume(&self) -> f64 {
        self.cell[0] * self.cell[1] * self.cell[2]
    }

    pub fn upper(&self) -> Vec3 {
        let mut u = self.origin;
        for a in 0..self.dim {
            u[a] += self.cell[a] * self.cells[a] as f64;
        }
        u
    }

    pub fn node_index(&self, ijk: [usize; 3]) -> usize {
        let n = self.nodes_per_axis();
        ijk[0] + n[0] * (ijk[1] + n[1] * ijk[2])
    }

    pub fn node_ijk(&self, index: usize) -> [usize; 3] {
        let n = self.nodes_per_axis();
        [index % n[0], (index / n[0]) % n[1], index / (n[0] * n[1])]
    }

    pub fn node_position(&self, index: usize) -> Vec3 {
        let ijk = self.node_ijk(index);
        let mut x = self.origin;
        for a in 0..self.dim {
            x[a] += ijk[a] as f64 * self.cell[a];
        }
        x
    }

    pub fn cell_ijk(&self, cell: u32) -> [usize; 3] {
        let c = cell as usize;
        [c % self.cells[0], (c / self.cells[0]) % self.cells[1], c / (self.cells[0] * self.cells[1])]
    }

    /// Cell coordinates of a position; `None` outside the mesh (its boundary belongs to it).
    #[inline]
    pub fn locate(&self, x: Vec3) -> Option<Location> {
        let mut t = [0.0; 3];
        for a in 0..self.dim {
            t[a] = (x[a] - self.origin[a]) / self.cell[a];
            if !(t[a] >= 0.0 && t[a] <= self.cells[a] as f64) {
                return None;
            }
        }
        Some(Location { t })
    }

    pub fn contains(&self, x: Vec3) -> bool {
        self.locate(x).is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locate_gives_cell_coordinates_and_keeps_the_boundary_in_the_mesh() {
        let m = Mesh::new(2, [1.0, 2.0, 0.0], [0.5, 0.25, 1.0], [4, 8, 1]).unwrap();
        let loc = m.locate([1.5, 2.3, 0.0]).unwrap();
        assert!((loc.t[0] - 1.0).abs() < 1e-12 && (loc.t[1] - 1.2).abs() < 1e-12 && loc.t[2] == 0.0);
        let top = m.locate(m.upper()).unwrap();
        assert!((top.t[0] - 4.0).abs() < 1e-12 && (top.t[1] - 8.0).abs() < 1e-12);
        assert!(m.locate([0.99, 2.5, 0.0]).is_none());
    }
}
