//! Shape functions. The engine is generic over [`ShapeFunction`] so its hot loops are monomorphic;
//! linear (bi/tri-linear) functions of thesis eqs. 3.11-3.16 are built in, and GIMP or B-splines can
//! be added as other implementations with more nodes per point.

use crate::math::Vec3;

/// Most nodes a point talks to with the shape functions built in.
pub const MAX_NODES: usize = 8;

pub trait ShapeFunction: Send + Sync + 'static {
    /// Nodes influencing one point.
    const NODES: usize;
    /// Offsets (in node steps along x, y, z) from a cell's lower-corner node to each node.
    fn offsets() -> &'static [[usize; 3]];
    /// Values and global gradients at local coordinates `xi` for cell sizes `cell`.
    fn eval(xi: Vec3, cell: Vec3, n: &mut [f64; MAX_NODES], dn: &mut [Vec3; MAX_NODES]);
}

/// 4-node quadrilateral (2D plane strain).
pub struct Linear2;
/// 8-node hexahedron, node numbering of thesis figure 3.1.
pub struct Linear3;

const OFFSETS_3D: [[usize; 3]; 8] =
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]];

impl ShapeFunction for Linear2 {
    const NODES: usize = 4;
    fn offsets() -> &'static [[usize; 3]] {
        &OFFSETS_3D[..4]
    }
    #[inline(always)]
    fn eval(xi: Vec3, cell: Vec3, n: &mut [f64; MAX_NODES], dn: &mut [Vec3; MAX_NODES]) {
        // d(xi)/dx = 2/l (thesis eq. 3.15-3.16, the Jacobian of a regular mesh is diagonal).
        let (jx, jy) = (2.0 / cell[0], 2.0 / cell[1]);
        for (k, o) in OFFSETS_3D[..4].iter().enumerate() {
            let sx = if o[0] == 1 { 1.0 } else { -1.0 };
            let sy = if o[1] == 1 { 1.0 } else { -1.0 };
            let fx = 1.0 + sx * xi[0];
            let fy = 1.0 + sy * xi[1];
            n[k] = 0.25 * fx * fy;
            dn[k] = [0.25 * sx * fy * jx, 0.25 * fx * sy * jy, 0.0];
        }
    }
}

impl ShapeFunction for Linear3 {
    const NODES: usize = 8;
    fn offsets() -> &'static [[usize; 3]] {
        &OFFSETS_3D
    }
    #[inline(always)]
    fn eval(xi: Vec3, cell: Vec3, n: &mut [f64; MAX_NODES], dn: &mut [Vec3; MAX_NODES]) {
        let (jx, jy, jz) = (2.0 / cell[0], 2.0 / cell[1], 2.0 / cell[2]);
        for (k, o) in OFFSETS_3D.iter().enumerate() {
            let sx = if o[0] == 1 { 1.0 } else { -1.0 };
            let sy = if o[1] == 1 { 1.0 } else { -1.0 };
            let sz = if o[2] == 1 { 1.0 } else { -1.0 };
            let fx = 1.0 + sx * xi[0];
            let fy = 1.0 + sy * xi[1];
            let fz = 1.0 + sz * xi[2];
            n[k] = 0.125 * fx * fy * fz;
            dn[k] = [0.125 * sx * fy * fz * jx, 0.125 * fx * sy * fz * jy, 0.125 * fx * fy * sz * jz];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check_partition_of_unity<S: ShapeFunction>() {
        let cell = [0.3, 0.7, 1.1];
        let mut n = [0.0; MAX_NODES];
        let mut dn = [[0.0; 3]; MAX_NODES];
        for xi in [[-1.0, -1.0, -1.0], [0.2, -0.7, 0.5], [1.0, 0.3, -0.1]] {
            S::eval(xi, cell, &mut n, &mut dn);
            let sum: f64 = n[..S::NODES].iter().sum();
            assert!((sum - 1.0).abs() < 1e-14);
            for a in 0..3 {
                let g: f64 = dn[..S::NODES].iter().map(|d| d[a]).sum();
                assert!(g.abs() < 1e-12, "gradients of a partition of unity sum to zero");
            }
            // Linear completeness: sum_i N_i x_i reproduces the local position, sum_i grad N_i x_i = I.
            for a in 0..2 {
                let x: f64 = (0..S::NODES).map(|k| n[k] * S::offsets()[k][a] as f64 * cell[a]).sum();
                assert!((x - (xi[a] + 1.0) * 0.5 * cell[a]).abs() < 1e-12);
                let dxdx: f64 = (0..S::NODES).map(|k| dn[k][a] * S::offsets()[k][a] as f64 * cell[a]).sum();
                assert!((dxdx - 1.0).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn linear_shape_functions_are_complete() {
        check_partition_of_unity::<Linear2>();
        check_partition_of_unity::<Linear3>();
    }
}
