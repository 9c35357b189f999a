//! The incremental tangential spring with a Coulomb slider, shared by the laws.

use granite_core::math::Vec3;

#[inline(always)]
pub fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Removes the normal part of `u` and restores its length: the spring turns with the contact
/// plane instead of leaking into the normal direction.
#[inline(always)]
pub fn rotate_into_plane(u: Vec3, n: Vec3) -> Vec3 {
    let len2 = dot(u, u);
    if len2 == 0.0 {
        return u;
    }
    let un = dot(u, n);
    let t = minus_along(u, un, n);
    let t2 = dot(t, t);
    if t2 == 0.0 {
        return [0.0; 3];
    }
    let s = (len2 / t2).sqrt();
    [t[0] * s, t[1] * s, t[2] * s]
}

/// Tangential force on particle 1 from the spring displacement `u` (of 2 relative to 1), updated
/// with the tangential relative velocity over `dt`, limited to `mu * fn` (Coulomb, eq. 2.3).
/// Returns the force; `u` is left consistent with it (slip shortens the spring).
#[inline(always)]
pub fn spring_slider(u: &mut Vec3, n: Vec3, rel_velocity: Vec3, dt: f64, kt: f64, mu: f64, fn_: f64) -> Vec3 {
    let r = rotate_into_plane(*u, n);
    let vn = dot(rel_velocity, n);
    let vt = minus_along(rel_velocity, vn, n);
    let mut s = [r[0] + vt[0] * dt, r[1] + vt[1] * dt, r[2] + vt[2] * dt];
    let mut f = [kt * s[0], kt * s[1], kt * s[2]];
    if let Some(scale) = beyond_limit(f, mu * fn_) {
        f = scaled(f, scale);
        // The spring shortened by the same factor keeps f = kt s (no division by kt).
        s = scaled(s, scale);
    }
    *u = s;
    f
}

/// The factor that brings `v` back to length `limit` when it is longer (a slider slips), None
/// otherwise. Most contacts stick: the test compares squares, the root is taken only on slip.
#[inline(always)]
pub fn beyond_limit(v: Vec3, limit: f64) -> Option<f64> {
    let norm2 = dot(v, v);
    if norm2 > limit * limit {
        let norm = norm2.sqrt();
        Some(if norm > 0.0 { limit / norm } else { 0.0 })
    } else {
        None
    }
}

/// `a - s n`: `a` less `s` along the unit normal `n` (its tangential part when `s` is its normal
/// component; the force on particle 1 from the tangential force and the normal one).
#[inline(always)]
pub fn minus_along(a: Vec3, s: f64, n: Vec3) -> Vec3 {
    [a[0] - s * n[0], a[1] - s * n[1], a[2] - s * n[2]]
}

#[inline(always)]
pub fn scaled(v: Vec3, s: f64) -> Vec3 {
    [v[0] * s, v[1] * s, v[2] * s]
}

/// Elastic-perfectly plastic resistance to a relative rotation: the rotation `theta` grows with
/// `omega dt`, the moment `k theta` is capped at `limit` (and `theta` shortened to match).
#[inline(always)]
pub fn rotational_spring(theta: &mut Vec3, omega: Vec3, dt: f64, k: f64, limit: f64) -> Vec3 {
    let mut t = [theta[0] + omega[0] * dt, theta[1] + omega[1] * dt, theta[2] + omega[2] * dt];
    let mut m = [k * t[0], k * t[1], k * t[2]];
    if let Some(scale) = beyond_limit(m, limit) {
        m = scaled(m, scale);
        t = scaled(t, scale);
    }
    *theta = t;
    m
}

/// Energy an incremental tangential spring lost to slip in one step: the spring went from `before`
/// (turned into the contact plane) to `after` by `v_t dt` less the slip `trial - after`, `trial`
/// being `before + v_t dt`. Over the step its force is the mean of its two ends (the trapezoid
/// rule, exact for a linear spring), so the slip took `kt (before + after)/2 . slip`.
pub fn spring_slip_work(before: &[f64], after: &[f64], n: Vec3, rel_velocity: Vec3, dt: f64, kt: f64) -> f64 {
    let r = rotate_into_plane([before[0], before[1], before[2]], n);
    let vn = dot(rel_velocity, n);
    let vt = minus_along(rel_velocity, vn, n);
    let kept = [after[0], after[1], after[2]];
    let slip = [r[0] + vt[0] * dt - kept[0], r[1] + vt[1] * dt - kept[1], r[2] + vt[2] * dt - kept[2]];
    let mean = [0.5 * (r[0] + kept[0]), 0.5 * (r[1] + kept[1]), 0.5 * (r[2] + kept[2])];
    kt * dot(mean, slip)
}

/// Viscous work of a normal dashpot over one step: the normal force beyond the elastic one
/// (`fn - f_elastic`, the dashpot's share after the clamp at zero) times the overlap's change
/// `-v_n dt` (`rel_velocity` the step's mean relative velocity).
pub fn dashpot_work(force: Vec3, n: Vec3, elastic: f64, rel_velocity: Vec3, dt: f64) -> f64 {
    // The force on particle 1 is -fn n + ft.
    let fn_ = -dot(force, n);
    (fn_ - elastic) * -dot(rel_velocity, n) * dt
}
