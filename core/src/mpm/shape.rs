//! Shape functions on the regular mesh, as tensor products of one-dimensional bases. The engine
//! is generic over [`ShapeFunction`] so its hot loops are monomorphic.
//!
//! Along an axis a point sits at `t`, its position in cell lengths from the mesh origin (nodes at
//! the integers `0..=cells`). A basis gives the first node of the window of `SPAN` nodes the point
//! talks to, and per window node the value, the derivative in `t`, and the node's coordinate
//! relative to the point (for the affine transfer).
//!
//! - [`Linear`]: the bi/tri-linear functions of thesis eqs. 3.11-3.16 (2 nodes per axis).
//! - [`Gimp`]: uGIMP (Bardenhagen & Kober 2004), the linear functions averaged over the point's
//!   domain `[t - a, t + a]`, `a` the half length of a point in cells (3 nodes per axis). A domain
//!   reaching past the mesh edge is averaged against the edge element's functions extended
//!   linearly, which keeps partition of unity and linear completeness there.
//! - [`QuadraticBspline`], [`CubicBspline`]: B-splines of degree 2 and 3 (3 and 4 nodes per axis),
//!   the functions of `wave2.md` away from the edges. At the edges the knot vector is open (the
//!   end knot repeated degree + 1 times, as in the boundary-modified B-splines of Steffen, Kirby &
//!   Berzins 2008), so the basis keeps partition of unity and reproduces linear fields up to the
//!   mesh edge, and the edge node alone carries the edge (a velocity fixed there is met exactly).
//!   Near an edge a node's function is centred at its Greville abscissa, not at the node.

use crate::math::Vec3;
use crate::mpm::mesh::Mesh;

/// Most nodes along one axis (cubic B-spline).
pub const MAX_SPAN: usize = 4;
/// Most nodes a point talks to (cubic B-spline in 3D).
pub const MAX_NODES: usize = MAX_SPAN * MAX_SPAN * MAX_SPAN;

/// One axis of a point's weights.
#[derive(Debug, Clone, Copy)]
pub struct Axis {
    /// First node of the window.
    pub first: usize,
    pub n: [f64; MAX_SPAN],
    /// dN/dt (per cell length).
    pub dn: [f64; MAX_SPAN],
    /// Node coordinate minus the point's, in cell lengths (the Greville abscissa for B-splines).
    pub d: [f64; MAX_SPAN],
}

pub trait Basis: Send + Sync + 'static {
    const SPAN: usize;
    /// APIC's affine matrix from the moments, `C_p = B_p D_p^-1` (Jiang et al. 2015); otherwise
    /// the velocity gradient, which is what `B_p D_p^-1` reduces to for multilinear functions.
    const AFFINE_FROM_MOMENTS: bool = false;
    /// The volume update uses the velocity divergence at the cell centre (thesis eq. 3.39, for
    /// linear functions), otherwise at the point.
    const VOLUME_AT_CELL_CENTRE: bool = false;
    /// The first node of the window of a point at `t` on an axis of `cells` cells.
    fn first(t: f64, cells: usize) -> usize;
    /// Weights at `t`; `half` is the point's half length in cells (GIMP only).
    fn eval(t: f64, cells: usize, half: f64) -> Axis;
}

/// Linear functions (thesis eqs. 3.11-3.16).
pub struct Linear;
/// uGIMP with a fixed point size.
pub struct Gimp;
/// B-spline of degree `P` with an open knot vector.
pub struct Bspline<const P: usize>;
pub type QuadraticBspline = Bspline<2>;
pub type CubicBspline = Bspline<3>;

impl Basis for Linear {
    const SPAN: usize = 2;
    const VOLUME_AT_CELL_CENTRE: bool = true;
    #[inline(always)]
    fn first(t: f64, cells: usize) -> usize {
        (t as usize).min(cells - 1)
    }
    #[inline(always)]
    fn eval(t: f64, cells: usize, _half: f64) -> Axis {
        let first = Self::first(t, cells);
        let s = t - first as f64;
        Axis { first, n: [1.0 - s, s, 0.0, 0.0], dn: [-1.0, 1.0, 0.0, 0.0], d: [-s, 1.0 - s, 0.0, 0.0] }
    }
}

impl Basis for Gimp {
    const SPAN: usize = 3;
    #[inline(always)]
    fn first(t: f64, cells: usize) -> usize {
        ((t + 0.5) as usize).saturating_sub(1).min(cells - 2)
    }
    fn eval(t: f64, cells: usize, half: f64) -> Axis {
        let first = Self::first(t, cells);
        // The linear functions of the window's two elements at x, the element chosen among them
        // (the edge elements extended past the mesh); continuous, so a breakpoint may use either.
        let hats = |x: f64| -> [f64; 3] {
            let e = (x.floor().max(first as f64) as usize).min(first + 1);
            let s = x - e as f64;
            let mut v = [0.0; 3];
            v[e - first] = 1.0 - s;
            v[e - first + 1] = s;
            v
        };
        let (lo, hi) = (t - half, t + half);
        let mut n = [0.0; MAX_SPAN];
        // Exact integral over [lo, hi]: split at the integers inside, midpoint rule per piece.
        let mut a = lo;
        while a < hi {
            let b = (a.floor() + 1.0).min(hi);
            let v = hats(0.5 * (a + b));
            for k in 0..3 {
                n[k] += (b - a) * v[k];
            }
            a = b;
        }
        let (vl, vh) = (hats(lo), hats(hi));
        let mut dn = [0.0; MAX_SPAN];
        let mut d = [0.0; MAX_SPAN];
        for k in 0..3 {
            n[k] /= 2.0 * half;
            dn[k] = (vh[k] - vl[k]) / (2.0 * half);
            d[k] = (first + k) as f64 - t;
        }
        Axis { first, n, dn, d }
    }
}

/// Open-knot B-spline of degree `P` on `cells` cells, one function per node: knot `j` of
/// `0..=cells + P + 1` is 0 for `j <= P`, `cells` for `j > cells`, else `j - P - 1 + (P + 1)/2`.
struct OpenSpline<const P: usize>;

impl<const P: usize> OpenSpline<P> {
    const CENTRE: f64 = (P as f64 + 1.0) / 2.0;

    #[inline(always)]
    fn knot(j: usize, cells: usize) -> f64 {
        if j <= P {
            0.0
        } else if j > cells {
            cells as f64
        } else {
            (j - P - 1) as f64 + Self::CENTRE
        }
    }

    #[inline(always)]
    fn span(t: f64, cells: usize) -> usize {
        let k = (t - Self::CENTRE).floor() + (P + 1) as f64;
        (k.max(P as f64) as usize).min(cells)
    }

    fn greville(j: usize, cells: usize) -> f64 {
        (1..=P).map(|r| Self::knot(j + r, cells)).sum::<f64>() / P as f64
    }

    /// Values and derivatives of the `P + 1` functions not zero at `t` (Cox-de Boor).
    fn eval(t: f64, cells: usize) -> Axis {
        let mu = Self::span(t, cells);
        let first = mu - P;
        let mut n = [0.0; MAX_SPAN];
        let mut lower = [0.0; MAX_SPAN];
        let (mut left, mut right) = ([0.0; MAX_SPAN], [0.0; MAX_SPAN]);
        n[0] = 1.0;
        for j in 1..=P {
            if j == P {
                lower = n;
            }
            left[j] = t - Self::knot(mu + 1 - j, cells);
            right[j] = Self::knot(mu + j, cells) - t;
            let mut saved = 0.0;
            for r in 0..j {
                let denom = right[r + 1] + left[j - r];
                let temp = if denom > 0.0 { n[r] / denom } else { 0.0 };
                n[r] = saved + right[r + 1] * temp;
                saved = left[j - r] * temp;
            }
            n[j] = saved;
        }
        // dN_{i,P} = P (N_{i,P-1} / (t_{i+P} - t_i) - N_{i+1,P-1} / (t_{i+P+1} - t_{i+1})), with
        // `lower[r]` holding N_{first + 1 + r, P-1}.
        let ratio = |value: f64, width: f64| if width > 0.0 { value / width } else { 0.0 };
        let mut dn = [0.0; MAX_SPAN];
        let mut d = [0.0; MAX_SPAN];
        for r in 0..=P {
            let i = first + r;
            let a = if r > 0 { ratio(lower[r - 1], Self::knot(i + P, cells) - Self::knot(i, cells)) } else { 0.0 };
            let b = if r < P { ratio(lower[r], Self::knot(i + P + 1, cells) - Self::knot(i + 1, cells)) } else { 0.0 };
            dn[r] = P as f64 * (a - b);
            d[r] = Self::greville(i, cells) - t;
        }
        Axis { first, n, dn, d }
    }
}

impl<const P: usize> Basis for Bspline<P> {
    const SPAN: usize = P + 1;
    const AFFINE_FROM_MOMENTS: bool = true;
    #[inline(always)]
    fn first(t: f64, cells: usize) -> usize {
        OpenSpline::<P>::span(t, cells) - P
    }
    fn eval(t: f64, cells: usize, _half: f64) -> Axis {
        OpenSpline::<P>::eval(t, cells)
    }
}

/// A point's weights over its window of nodes (x fastest, then y, then z).
#[derive(Debug, Clone)]
pub struct Weights {
    /// First node of the window along each axis.
    pub first: [usize; 3],
    pub n: [f64; MAX_NODES],
    /// Global gradients, 1/m.
    pub dn: [Vec3; MAX_NODES],
    /// Node position minus the point's, m.
    pub d: [Vec3; MAX_NODES],
    /// Diagonal of the inertia-like matrix `D_p = sum_i N_i d_i d_i^T` (m^2); it has no
    /// off-diagonal terms for a tensor-product basis with linear completeness.
    pub moment: Vec3,
}

impl Default for Weights {
    fn default() -> Weights {
        Weights {
            first: [0; 3],
            n: [0.0; MAX_NODES],
            dn: [[0.0; 3]; MAX_NODES],
            d: [[0.0; 3]; MAX_NODES],
            moment: [0.0; 3],
        }
    }
}

pub trait ShapeFunction: Send + Sync + 'static {
    type Basis: Basis;
    const DIM: usize;
    /// Nodes along one axis of the window.
    const SPAN: usize = <Self::Basis as Basis>::SPAN;
    /// Nodes influencing one point.
    const NODES: usize;
    /// Weights of a point at cell coordinates `t`; `half` is its half length in cells per axis.
    fn eval(t: Vec3, mesh: &Mesh, half: Vec3, w: &mut Weights);
}

/// The tensor product of a basis over `DIM` axes.
pub struct Tensor<B, const DIM: usize>(std::marker::PhantomData<B>);

impl<B: Basis, const DIM: usize> ShapeFunction for Tensor<B, DIM> {
    type Basis = B;
    const DIM: usize = DIM;
    const NODES: usize = B::SPAN.pow(DIM as u32);

    #[inline(always)]
    fn eval(t: Vec3, mesh: &Mesh, half: Vec3, w: &mut Weights) {
        let span = B::SPAN;
        let mut axes = [Axis { first: 0, n: [1.0; MAX_SPAN], dn: [0.0; MAX_SPAN], d: [0.0; MAX_SPAN] }; 3];
        for a in 0..DIM {
            axes[a] = B::eval(t[a], mesh.cells[a], half[a]);
            w.first[a] = axes[a].first;
            let h = mesh.cell[a];
            w.moment[a] = (0..span).map(|k| axes[a].n[k] * (axes[a].d[k] * h).powi(2)).sum();
        }
        let h = mesh.cell;
        for k in 0..Self::NODES {
            let kx = k % span;
            let ky = (k / span) % span;
            let kz = if DIM == 3 { k / (span * span) } else { 0 };
            let (x, y, z) = (&axes[0], &axes[1], &axes[2]);
            let (nx, ny, nz) = (x.n[kx], y.n[ky], if DIM == 3 { z.n[kz] } else { 1.0 });
            w.n[k] = nx * ny * nz;
            w.dn[k] = [
                x.dn[kx] / h[0] * ny * nz,
                nx * y.dn[ky] / h[1] * nz,
                if DIM == 3 { nx * ny * z.dn[kz] / h[2] } else { 0.0 },
            ];
            w.d[k] = [x.d[kx] * h[0], y.d[ky] * h[1], if DIM == 3 { z.d[kz] * h[2] } else { 0.0 }];
        }
    }
}

/// The window's first node plane along the slab axis, for the parallel scatter.
#[inline]
pub fn first_plane<S: ShapeFunction>(mesh: &Mesh, t: Vec3) -> usize {
    let a = mesh.slab_axis();
    S::Basis::first(t[a], mesh.cells[a])
}

/// Node index offsets, relative to the window's first node, of the nodes a point talks to.
pub fn node_offsets<S: ShapeFunction>(mesh: &Mesh) -> [usize; MAX_NODES] {
    let n = mesh.nodes_per_axis();
    let span = S::SPAN;
    let mut off = [0; MAX_NODES];
    for (k, o) in off.iter_mut().enumerate().take(S::NODES) {
        let (kx, ky, kz) = (k % span, (k / span) % span, k / (span * span));
        *o = kx + n[0] * (ky + n[1] * kz);
    }
    off
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Partition of unity, linear completeness and the consistency of gradients, in one dimension
    /// (the tensor product inherits them), at many positions including both mesh edges.
    fn check_complete<B: Basis>(cells: usize, half: f64) {
        let name = std::any::type_name::<B>();
        let samples = 400;
        for s in 0..=samples {
            let t = cells as f64 * s as f64 / samples as f64;
            let ax = B::eval(t, cells, half);
            assert!(ax.first + B::SPAN <= cells + 1, "{name}: window past the mesh at t = {t}");
            let sum: f64 = ax.n[..B::SPAN].iter().sum();
            let dsum: f64 = ax.dn[..B::SPAN].iter().sum();
            let first_moment: f64 = (0..B::SPAN).map(|k| ax.n[k] * ax.d[k]).sum();
            let slope: f64 = (0..B::SPAN).map(|k| ax.dn[k] * (ax.d[k] + t)).sum();
            assert!((sum - 1.0).abs() < 1e-13, "{name} at t = {t}: sum N = {sum}");
            assert!(dsum.abs() < 1e-12, "{name} at t = {t}: sum dN = {dsum}");
            assert!(first_moment.abs() < 1e-13, "{name} at t = {t}: sum N (x_i - x) = {first_moment}");
            assert!((slope - 1.0).abs() < 1e-12, "{name} at t = {t}: sum dN x_i = {slope}");
            assert!(ax.n[..B::SPAN].iter().all(|&v| v > -1e-14), "{name} at t = {t}: {:?}", ax.n);
            // The derivative is the derivative: central difference away from breakpoints.
            let e = 1e-7;
            if t > e && t < cells as f64 - e {
                let (lo, hi) = (B::eval(t - e, cells, half), B::eval(t + e, cells, half));
                if lo.first == ax.first && hi.first == ax.first {
                    for k in 0..B::SPAN {
                        let fd = (hi.n[k] - lo.n[k]) / (2.0 * e);
                        assert!((fd - ax.dn[k]).abs() < 1e-5, "{name} at t = {t}: dN {} vs {fd}", ax.dn[k]);
                    }
                }
            }
        }
    }

    #[test]
    fn every_basis_is_a_complete_partition_of_unity_up_to_the_mesh_edges() {
        for cells in [3, 4, 9] {
            check_complete::<Linear>(cells, 0.0);
            check_complete::<Gimp>(cells, 0.25);
            check_complete::<Gimp>(cells, 0.5);
            check_complete::<QuadraticBspline>(cells, 0.0);
            check_complete::<CubicBspline>(cells, 0.0);
        }
        check_complete::<QuadraticBspline>(2, 0.0);
    }

    #[test]
    fn b_splines_away_from_the_edges_are_the_uniform_ones() {
        // wave2.md: with xi = (x_p - x_i)/h, quadratic N = 3/4 - xi^2 (|xi| < 1/2),
        // (3/2 - |xi|)^2 / 2 (1/2 <= |xi| < 3/2); cubic N = |xi|^3/2 - xi^2 + 2/3 (|xi| < 1),
        // (2 - |xi|)^3 / 6 (1 <= |xi| < 2).
        let quadratic = |xi: f64| {
            let a = xi.abs();
            if a < 0.5 {
                0.75 - a * a
            } else if a < 1.5 {
                0.5 * (1.5 - a).powi(2)
            } else {
                0.0
            }
        };
        let cubic = |xi: f64| {
            let a = xi.abs();
            if a < 1.0 {
                0.5 * a.powi(3) - a * a + 2.0 / 3.0
            } else if a < 2.0 {
                (2.0 - a).powi(3) / 6.0
            } else {
                0.0
            }
        };
        for t in [4.0, 4.3, 4.5, 4.77, 5.2] {
            let q = QuadraticBspline::eval(t, 10, 0.0);
            let c = CubicBspline::eval(t, 10, 0.0);
            for k in 0..3 {
                let xi = t - (q.first + k) as f64;
                assert!((q.n[k] - quadratic(xi)).abs() < 1e-14 && (q.d[k] + xi).abs() < 1e-14);
            }
            for k in 0..4 {
                let xi = t - (c.first + k) as f64;
                assert!((c.n[k] - cubic(xi)).abs() < 1e-14 && (c.d[k] + xi).abs() < 1e-14);
            }
            // D_p = h^2/4 (quadratic) and h^2/3 (cubic) of Jiang et al. 2015, h = 1.
            let dq: f64 = (0..3).map(|k| q.n[k] * q.d[k] * q.d[k]).sum();
            let dc: f64 = (0..4).map(|k| c.n[k] * c.d[k] * c.d[k]).sum();
            assert!((dq - 0.25).abs() < 1e-14 && (dc - 1.0 / 3.0).abs() < 1e-14, "{dq} {dc}");
        }
    }

    #[test]
    fn gimp_of_a_point_inside_one_cell_is_the_linear_function_at_its_centre() {
        // A domain inside one cell averages a linear function: the value at the domain's centre.
        let g = Gimp::eval(2.4, 6, 0.25);
        let l = Linear::eval(2.4, 6, 0.0);
        assert_eq!(g.first, 1);
        assert!(g.n[0].abs() < 1e-15 && (g.n[1] - l.n[0]).abs() < 1e-14 && (g.n[2] - l.n[1]).abs() < 1e-14);
        // Straddling a node it smooths the kink: a point at a node weighs that node 1 - a/2.
        let g = Gimp::eval(3.0, 6, 0.25);
        assert!((g.n[1] - (1.0 - 0.125)).abs() < 1e-14 && (g.n[0] - 0.0625).abs() < 1e-14, "{:?}", g.n);
        assert!(g.dn[1].abs() < 1e-14, "the kink's derivative is smoothed to zero at the node");
    }

    #[test]
    fn tensor_weights_multiply_and_offsets_address_the_window() {
        let mesh = Mesh::new(3, [0.0; 3], [0.5, 0.25, 1.0], [6, 8, 5]).unwrap();
        let mut w = Weights::default();
        let t = [2.3, 4.6, 1.1];
        Tensor::<QuadraticBspline, 3>::eval(t, &mesh, [0.0; 3], &mut w);
        type S = Tensor<QuadraticBspline, 3>;
        assert_eq!(S::NODES, 27);
        let sum: f64 = w.n[..S::NODES].iter().sum();
        assert!((sum - 1.0).abs() < 1e-14);
        let off = node_offsets::<S>(&mesh);
        let base = mesh.node_index(w.first);
        // sum N_i x_i reproduces the point's position in metres.
        for a in 0..3 {
            let x: f64 = (0..S::NODES).map(|k| w.n[k] * (w.d[k][a] + t[a] * mesh.cell[a])).sum();
            assert!((x - t[a] * mesh.cell[a]).abs() < 1e-13);
            let g: f64 = (0..S::NODES).map(|k| w.dn[k][a] * (w.d[k][a] + t[a] * mesh.cell[a])).sum();
            assert!((g - 1.0).abs() < 1e-12);
        }
        assert_eq!(mesh.node_ijk(base + off[S::NODES - 1]), [w.first[0] + 2, w.first[1] + 2, w.first[2] + 2]);
    }
}
