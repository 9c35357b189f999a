//! Nodal fields and the deterministic parallel particle-to-grid scatter.
//!
//! A point talks to a window of `span` node planes along the last axis (2 for linear shape
//! functions, 3 or 4 for GIMP and B-splines). Points are bucketed by slab, the first plane of
//! their window; slabs `span` apart touch disjoint node planes, so slabs of one colour (their
//! index modulo `span`) scatter in parallel, one colour after the other. Every node therefore
//! sums its contributions in the same order whatever the thread count: results are
//! bit-identical for 1 or N threads, without f64 atomics.

use crate::math::Vec3;
use crate::mpm::mesh::Mesh;
use crate::mpm::shape::Weights;
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
    /// Node planes of a window.
    pub span: usize,
}

impl SlabIndex {
    /// Counting sort of the points by slab (stable, so deterministic); `span` node planes per window.
    pub fn build(&mut self, mesh: &Mesh, span: usize, points: usize, slab_of: impl Fn(usize) -> usize) {
        let slabs = mesh.cells[mesh.slab_axis()] + 2 - span;
        self.span = span;
        self.start.clear();
        self.start.resize(slabs + 1, 0);
        for p in 0..points {
            self.start[slab_of(p) + 1] += 1;
        }
        for s in 0..slabs {
            self.start[s + 1] += self.start[s];
        }
        let mut next = self.start.clone();
        self.order.clear();
        self.order.resize(points, 0);
        for p in 0..points {
            let s = slab_of(p);
            self.order[next[s]] = p as u32;
            next[s] += 1;
        }
    }

    pub fn slab(&self, s: usize) -> &[u32] {
        &self.order[self.start[s]..self.start[s + 1]]
    }

    pub fn slab_count(&self) -> usize {
        self.start.len().saturating_sub(1)
    }
}

/// Runs `add(point, window, window_first_node, scratch)` for every point, where `window` is the
/// slice of nodal sums covering the node planes of the point's slab, and `scratch` weights to
/// reuse (one per task: they are large for the wider shape functions).
pub fn scatter<F>(sums: &mut [NodeSums], mesh: &Mesh, slabs: &SlabIndex, add: F)
where
    F: Fn(usize, &mut [NodeSums], usize, &mut Weights) + Sync,
{
    let plane = mesh.nodes_per_plane();
    let (nslabs, span) = (slabs.slab_count(), slabs.span);
    // Enough slabs per task that a task has a few thousand points to scatter.
    let per_slab = slabs.order.len() / nslabs.max(1);
    let min_windows = (4096 / per_slab.max(1)).max(1);
    for colour in 0..span.min(nslabs) {
        let body = &mut sums[colour * plane..];
        body.par_chunks_mut(span * plane).enumerate().with_min_len(min_windows).for_each(|(j, window)| {
            let s = span * j + colour;
            if s < nslabs {
                let first = s * plane;
                let mut scratch = Weights::default();
                for &p in slabs.slab(s) {
                    add(p as usize, window, first, &mut scratch);
                }
            }
        });
    }
}
