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
    if e >= 1.0 {
        return 0.0;
    }
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    while restitution(hi) > e {
        hi *= 2.0;
        if hi > 1e6 {
            return hi;
        }
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if restitution(mid) > e {
            lo = mid;
        } else {
            hi = mid;
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
