//! Normal damping from a restitution coefficient, after Schwager & Pöschel (2007): the contact ends
//! when the normal force `k_n d + c_n d'` returns to zero, not when the overlap does.
//! Everything here is in units of `w0 = sqrt(k_n / m*)`: `x = beta / w0`, times in `1 / w0`.

/// Contact duration (in units of 1/w0) of a linear visco-elastic contact with damping ratio `x`.
pub fn contact_time(x: f64) -> f64 {
    let s2 = std::f64::consts::FRAC_1_SQRT_2;
    if x < s2 {
        let w = (1.0 - x * x).sqrt();
        (std::f64::consts::PI - (2.0 * x * w / (w * w - x * x)).atan()) / w
    } else if x < 1.0 {
        let w = (1.0 - x * x).sqrt();
        (2.0 * x * w / (x * x - w * w)).atan() / w
    } else if x == 1.0 {
        // Limit of both neighbouring branches: t = 2 / w0.
        2.0
    } else {
        let big_w = (x * x - 1.0).sqrt();
        ((x + big_w) / (x - big_w)).ln() / big_w
    }
}

/// Restitution coefficient for damping ratio `x = beta / w0`.
pub fn restitution(x: f64) -> f64 {
    (-x * contact_time(x)).exp()
}

/// The damping ratio `beta / w0` that gives restitution `e` (0 < e <= 1), by bisection on the
/// monotonic `restitution(x)`.
pub fn damping_ratio(e: f64) -> f64 {
    bisect_decreasing(restitution, e, 200, 0.0)
}

/// The `x >= 0` where the decreasing `f` (with `f(0) = 1`) takes the value `e` in (0, 1], by
/// bisection: `iterations` at most, or until the bracket is narrower than `relative` of itself.
/// Beyond 1e6 the bracket's end is returned (a dashpot that strong stops any contact dead).
fn bisect_decreasing(f: impl Fn(f64) -> f64, e: f64, iterations: usize, relative: f64) -> f64 {
    if e >= 1.0 {
        return 0.0;
    }
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    while f(hi) > e {
        hi *= 2.0;
        if hi > 1e6 {
            return hi;
        }
    }
    for _ in 0..iterations {
        let mid = 0.5 * (lo + hi);
        if f(mid) > e {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < relative * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn published_value_for_half_restitution() {
        // formulas.md: e = 0.5 needs beta/w0 = 0.2553 (the classical formula would give 0.2155).
        assert!((damping_ratio(0.5) - 0.2553).abs() < 5e-5, "{}", damping_ratio(0.5));
        let classical = -(0.5f64).ln() / (std::f64::consts::PI.powi(2) + (0.5f64).ln().powi(2)).sqrt();
        assert!((classical - 0.2155).abs() < 5e-5);
    }

    #[test]
    fn restitution_is_continuous_and_decreasing() {
        let mut last = 1.0;
        for k in 1..400 {
            let x = k as f64 * 0.01;
            let e = restitution(x);
            assert!(e < last + 1e-12, "not decreasing at x = {x}");
            last = e;
        }
        let s2 = std::f64::consts::FRAC_1_SQRT_2;
        assert!((restitution(s2 - 1e-9) - restitution(s2 + 1e-9)).abs() < 1e-6);
        assert!((restitution(1.0 - 1e-9) - restitution(1.0 + 1e-9)).abs() < 1e-6);
        assert!((damping_ratio(restitution(0.3)) - 0.3).abs() < 1e-9);
    }
}

/// Restitution of a Hertz contact whose dashpot is `c_n = 2 beta sqrt(m* k_n(d))`, with `k_n`
/// the tangent stiffness `dF/dd = 3/2 K d^(1/2)` of `F = K d^(3/2)`, the force clamped at zero
/// (no attraction). Scaled by the approach speed `v0` and the length and time that make `m* = K
/// = v0 = 1`, the motion is `d'' = -max(0, d^(3/2) + 2 beta sqrt(3/2) d^(1/4) d')` from `d = 0,
/// d' = 1`: the restitution depends on `beta` alone. Integrated with classical Runge-Kutta over
/// 4000 steps of the undamped contact's duration (about 3.2 in these units), which puts `e` within
/// 1e-6 of the converged value.
pub fn hertz_restitution(beta: f64) -> f64 {
    let damping = 2.0 * beta * 1.5f64.sqrt();
    let acceleration = |d: f64, v: f64| {
        let d = d.max(0.0);
        -(d.powf(1.5) + damping * d.powf(0.25) * v).max(0.0)
    };
    let h = 3.22 / 4000.0;
    let (mut d, mut v) = (0.0f64, 1.0f64);
    // The contact ends when the overlap is back to zero: the acceleration is never positive, so
    // once the bodies move apart they do reach it.
    for _ in 0..4000 * 1000 {
        let (k1d, k1v) = (v, acceleration(d, v));
        let (k2d, k2v) = (v + 0.5 * h * k1v, acceleration(d + 0.5 * h * k1d, v + 0.5 * h * k1v));
        let (k3d, k3v) = (v + 0.5 * h * k2v, acceleration(d + 0.5 * h * k2d, v + 0.5 * h * k2v));
        let (k4d, k4v) = (v + h * k3v, acceleration(d + h * k3d, v + h * k3v));
        let (d_next, v_next) =
            (d + h / 6.0 * (k1d + 2.0 * k2d + 2.0 * k3d + k4d), v + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v));
        if d_next <= 0.0 {
            // Linear interpolation of the velocity at the crossing.
            return (-(v + (v_next - v) * d / (d - d_next))).max(0.0);
        }
        (d, v) = (d_next, v_next);
    }
    0.0
}

/// The `beta` of [`hertz_restitution`] that gives restitution `e` (0 < e <= 1), by bisection on
/// that decreasing function (Thornton, Cummins & Cleary (2013) fit the same relation with a
/// polynomial, within about 0.005 in e).
pub fn hertz_damping_ratio(e: f64) -> f64 {
    bisect_decreasing(hertz_restitution, e, 60, 1e-10)
}

#[cfg(test)]
mod hertz_tests {
    use super::*;

    #[test]
    fn an_undamped_hertz_contact_gives_back_its_speed() {
        assert!((hertz_restitution(0.0) - 1.0).abs() < 1e-6);
    }

    /// Thornton, Cummins & Cleary (2013)'s fit of the same relation (wave2.md): beta from e
    /// through a polynomial in e. It must agree with the bisection on the integrated contact to
    /// the fit's own accuracy.
    #[test]
    fn bisection_agrees_with_the_thornton_fit() {
        let h =
            [-6.918798, -16.41105, 146.8049, -796.4559, 2928.711, -7206.864, 11494.29, -11342.18, 6276.757, -1489.915];
        for e in [0.2, 0.4, 0.6, 0.8] {
            let alpha = e * h.iter().rev().fold(0.0, |acc, c| c + e * acc);
            let beta_fit = (1.0 / (1.0 - (1.0 + e) * (1.0 + e) * f64::exp(alpha)) - 1.0).sqrt();
            let beta = hertz_damping_ratio(e);
            assert!((hertz_restitution(beta) - e).abs() < 1e-6, "e = {e}");
            assert!(
                (hertz_restitution(beta_fit) - e).abs() < 0.01,
                "e = {e}: fit gives {}",
                hertz_restitution(beta_fit)
            );
        }
    }
}
