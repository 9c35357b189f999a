//! Small fixed-size linear algebra used in hot loops, and Voigt conversions.
//!
//! Points and nodes store plain arrays (`[f64; 3]`, `[f64; 6]`) so that the SoA buffers stay `Copy`
//! and cheap; nalgebra is used where a decomposition is needed (eigenvalues in plasticity).

pub type Real = f64;
pub type Vec3 = [f64; 3];
/// Voigt vector, order xx, yy, zz, xy, yz, xz.
pub type Voigt = [f64; 6];
/// Row-major 3x3 matrix.
pub type Mat3 = [f64; 9];

pub const XX: usize = 0;
pub const YY: usize = 1;
pub const ZZ: usize = 2;
pub const XY: usize = 3;
pub const YZ: usize = 4;
pub const XZ: usize = 5;

#[inline(always)]
pub fn sub3(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline(always)]
pub fn cross3(a: Vec3, b: Vec3) -> Vec3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

#[inline(always)]
pub fn add3(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[inline]
pub fn scale3(a: Vec3, s: f64) -> Vec3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

#[inline]
pub fn dot3(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
pub fn norm3(a: Vec3) -> f64 {
    dot3(a, a).sqrt()
}

/// `m x` for a 3x3 matrix (the affine field and the image shifts of a periodic cell).
#[inline(always)]
pub fn mat_vec(m: &nalgebra::Matrix3<f64>, x: Vec3) -> Vec3 {
    [0, 1, 2].map(|r| m[(r, 0)] * x[0] + m[(r, 1)] * x[1] + m[(r, 2)] * x[2])
}

/// Axis-aligned bounds `(lo, hi)` of points (infinite, lo > hi, when there are none).
pub fn point_bounds(points: &[Vec3]) -> (Vec3, Vec3) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (lo, hi)
}

/// Turns a stress by the spin of a velocity gradient over `dt`: `sigma <- R sigma R^T` with
/// `R = exp(W dt)`, `W = (L - L^T)/2`. This integrates the Jaumann rate `sigma_dot = W sigma - sigma W`
/// exactly for a constant spin, so a rigid rotation keeps the invariants to round-off.
pub fn rotate_by_spin(stress: &mut Voigt, l: &Mat3, dt: f64) {
    // Axial vector of W dt (W a = w x a): Rotation3::new turns by its length about it.
    let w = nalgebra::Vector3::new(0.5 * (l[7] - l[5]) * dt, 0.5 * (l[2] - l[6]) * dt, 0.5 * (l[3] - l[1]) * dt);
    if w == nalgebra::Vector3::zeros() {
        return;
    }
    let r = nalgebra::Rotation3::new(w).into_inner();
    *stress = stress_from_matrix(&(r * stress_matrix(stress) * r.transpose()));
}

/// Velocity gradient `L_ij = d v_i / d x_j` (row-major) to the Voigt strain rate with engineering shear
/// (thesis eq. 3.36: the off-diagonal terms are `gamma_ij = L_ij + L_ji`).
#[inline]
pub fn strain_rate_from_gradient(l: &Mat3) -> Voigt {
    [l[0], l[4], l[8], l[1] + l[3], l[5] + l[7], l[2] + l[6]]
}

/// Trace of a Voigt tensor.
#[inline]
pub fn trace(v: &Voigt) -> f64 {
    v[0] + v[1] + v[2]
}

/// `sigma : eps` for a stress and an engineering-shear strain (the tensor double contraction).
#[inline]
pub fn stress_strain_work(stress: &Voigt, strain: &Voigt) -> f64 {
    stress[0] * strain[0]
        + stress[1] * strain[1]
        + stress[2] * strain[2]
        + stress[3] * strain[3]
        + stress[4] * strain[4]
        + stress[5] * strain[5]
}

/// Frobenius norm of the deviatoric part of an engineering-shear strain (thesis eqs. 5.11-5.12).
pub fn deviatoric_strain_norm(strain: &Voigt) -> f64 {
    let mean = trace(strain) / 3.0;
    let d = [strain[0] - mean, strain[1] - mean, strain[2] - mean];
    let (gxy, gyz, gxz) = (strain[3] * 0.5, strain[4] * 0.5, strain[5] * 0.5);
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] + 2.0 * (gxy * gxy + gyz * gyz + gxz * gxz)).sqrt()
}

/// Mean stress `p = tr(sigma)/3` (negative in compression) and von Mises equivalent `q`.
pub fn p_q(stress: &Voigt) -> (f64, f64) {
    let p = trace(stress) / 3.0;
    let s = [stress[0] - p, stress[1] - p, stress[2] - p];
    let j2 = 0.5 * (s[0] * s[0] + s[1] * s[1] + s[2] * s[2])
        + stress[3] * stress[3]
        + stress[4] * stress[4]
        + stress[5] * stress[5];
    (p, (3.0 * j2).sqrt())
}

/// Symmetric 3x3 matrix of a Voigt stress (plain shear components).
pub fn stress_matrix(s: &Voigt) -> nalgebra::Matrix3<f64> {
    nalgebra::Matrix3::new(s[0], s[3], s[5], s[3], s[1], s[4], s[5], s[4], s[2])
}

/// Voigt stress of a symmetric 3x3 matrix.
pub fn stress_from_matrix(m: &nalgebra::Matrix3<f64>) -> Voigt {
    [m[(0, 0)], m[(1, 1)], m[(2, 2)], m[(0, 1)], m[(1, 2)], m[(0, 2)]]
}

/// Symmetric 3x3 matrix of an engineering-shear Voigt strain (tensor components).
pub fn strain_matrix(e: &Voigt) -> nalgebra::Matrix3<f64> {
    nalgebra::Matrix3::new(e[0], 0.5 * e[3], 0.5 * e[5], 0.5 * e[3], e[1], 0.5 * e[4], 0.5 * e[5], 0.5 * e[4], e[2])
}

pub fn all_finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// The first index of `range` where `before` turns false, by bisection: `slice::partition_point`
/// for a predicate on indices (`before` must hold on a front part of the range and nowhere after).
pub fn partition_index(range: std::ops::Range<usize>, before: impl Fn(usize) -> bool) -> usize {
    let (mut lo, mut hi) = (range.start, range.end);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if before(mid) {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quarter_turn_about_z_swaps_the_normal_stresses_in_x_and_y() {
        // v = omega x (-y, x): L_xy = -omega, L_yx = omega; a quarter turn in dt = 1.
        let omega = std::f64::consts::FRAC_PI_2;
        let l = [0.0, -omega, 0.0, omega, 0.0, 0.0, 0.0, 0.0, 0.0];
        let mut s = [-100.0, -30.0, -50.0, 0.0, 0.0, 0.0];
        rotate_by_spin(&mut s, &l, 1.0);
        let expected = [-30.0, -100.0, -50.0, 0.0, 0.0, 0.0];
        for c in 0..6 {
            assert!((s[c] - expected[c]).abs() < 1e-12, "{s:?}");
        }
        // An eighth of a turn: the shear (sxx - syy)/2 appears, with the sign of the rotation.
        let mut s = [-100.0, -30.0, -50.0, 0.0, 0.0, 0.0];
        rotate_by_spin(&mut s, &l, 0.5);
        assert!((s[XY] - (-100.0 + 30.0) / 2.0).abs() < 1e-12, "{s:?}");
    }

    #[test]
    fn partition_index_finds_where_a_slices_partition_point_does() {
        let values: Vec<u32> = (0..37).map(|k| k / 3).collect();
        for start in [0, 5, 37] {
            for target in 0..15 {
                let found = partition_index(start..values.len(), |k| values[k] < target);
                assert_eq!(
                    found,
                    start + values[start..].partition_point(|&v| v < target),
                    "from {start}, below {target}"
                );
            }
        }
    }

    #[test]
    fn pure_shear_deviatoric_norm() {
        // eps_xy = 0.01 (gamma = 0.02): the tensor has two off-diagonal entries 0.01, norm 0.01*sqrt(2).
        let e = [0.0, 0.0, 0.0, 0.02, 0.0, 0.0];
        assert!((deviatoric_strain_norm(&e) - 0.01 * 2f64.sqrt()).abs() < 1e-15);
    }

    #[test]
    fn uniaxial_q_equals_axial_stress() {
        let (p, q) = p_q(&[-3.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert!((p + 1.0).abs() < 1e-15 && (q - 3.0).abs() < 1e-14);
    }
}
