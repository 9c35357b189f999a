//! Nodal fields and the deterministic parallel particle-to-grid scatter.
//!
//! Points are bucketed by slab (layer of cells along the last axis, see [`Mesh`]). Slabs of equal
//! parity touch disjoint node planes, so all even slabs scatter in parallel, then all odd ones.
//! Every node therefore sums its contributions in the same order whatever the thread count:
//! results are bit-identical for 1 or N threads, without f64 atomics.

use crate::math::Vec3;
use crate::mpm::mesh::{Location, Mesh};
use rayon::prelude::*;

/// What points scatter to a node.
#[derive(Debug, Clone, Copy, Default)]
pub struct NodeSums {
    pub mass: f64,
    pub momentum: Vec3,
    /// Internal plus gravity force (eqs. 3.21, 3.23); nodal forces are added at the grid update.
    pub force: Vec3,
}

#[derive(Debug, Clone, Default)]
pub struct Grid {
    pub sums: Vec<NodeSums>,
    /// V^i (eq. 3.18 then 3.19).
    pub velocity: Vec<Vec3>,
    /// V~^i (eq. 3.27, after constraints).
    pub velocity_new: Vec<Vec3>,
    /// a^i = (V~^i - V^i)/dt: the acceleration actually applied, constraints included.
    pub accel: Vec<Vec3>,
}

impl Grid {
    pub fn resize(&mut self, nodes: usize) {
        self.sums.resize(nodes, NodeSums::default());
        self.velocity.resize(nodes, [0.0; 3]);
        self.velocity_new.resize(nodes, [0.0; 3]);
        self.accel.resize(nodes, [0.0; 3]);
    }
}

/// Point indices grouped by slab, each group in increasing point index.
#[derive(Debug, Clone, Default)]
pub struct SlabIndex {
    pub order: Vec<u32>,
    /// `order[start[s]..start[s + 1]]` are the points in slab `s`.
    pub start: Vec<usize>,
}

impl SlabIndex {
    /// Counting sort of the points by slab (stable, so deterministic).
    pub fn build(&mut self, mesh: &Mesh, loc: &[Location]) {
        let slabs = mesh.slab_count();
        self.start.clear();
        self.start.resize(slabs + 1, 0);
        let stride = mesh.cells[0] * if mesh.dim == 3 { mesh.cells[1] } else { 1 };
        for l in loc {
            self.start[l.cell as usize / stride + 1] += 1;
        }
        for s in 0..slabs {
            self.start[s + 1] += self.start[s];
        }
        let mut next = self.start.clone();
        self.order.clear();
        self.order.resize(loc.len(), 0);
        for (p, l) in loc.iter().enumerate() {
            let s = l.cell as usize / stride;
            self.order[next[s]] = p as u32;
            next[s] += 1;
        }
    }

    pub fn slab(&self, s: usize) -> &[u32] {
        &self.order[self.start[s]..self.start[s + 1]]
    }
}

/// Runs `add(point, window, window_first_node)` for every point, where `window` is the slice of
/// nodal sums covering the two node planes of the point's slab.
pub fn scatter<F>(sums: &mut [NodeSums], mesh: &Mesh, slabs: &SlabIndex, add: F)
where
    F: Fn(usize, &mut [NodeSums], usize) + Sync,
{
    let plane = mesh.nodes_per_plane();
    let nslabs = mesh.slab_count();
    // Enough slabs per task that a task has a few thousand points to scatter.
    let per_slab = slabs.order.len() / nslabs.max(1);
    let min_windows = (4096 / per_slab.max(1)).max(1);
    for parity in 0..2 {
        let body = &mut sums[parity * plane..];
        body.par_chunks_mut(2 * plane).enumerate().with_min_len(min_windows).for_each(|(j, window)| {
            let s = 2 * j + parity;
            if s < nslabs {
                let first = s * plane;
                for &p in slabs.slab(s) {
                    add(p as usize, window, first);
                }
            }
        });
    }
}
