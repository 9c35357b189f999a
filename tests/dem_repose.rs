//! The angle-of-repose measure (thesis 2.3.2) recovers the slope of synthetic heaps.

use granite_core::dem::repose::{measure, mobilised_friction_deg, Heap};

/// Grain centres (diameter d) of a heap whose outer surface is a plane (plane strain) or a cone
/// (axisymmetric) of slope `alpha`: grains lying on the surface (centres d/2 below it, +- 5 % of
/// d) over a random interior.
fn heap(alpha_deg: f64, axisymmetric: bool) -> (Vec<[f64; 3]>, Heap, f64) {
    let d: f64 = 0.01;
    let slope = alpha_deg.to_radians().tan();
    let (w, depth): (f64, f64) = (0.1, 0.06);
    let mut pts = Vec::new();
    let mut rand = crate::common::uniform_stream(7);
    let top = w * slope;
    let samples = (2.0 * w * 2.0 * w * top / (0.5 * d).powi(3)) as usize;
    for _ in 0..samples {
        {
            {
                let p = [(2.0 * rand() - 1.0) * w, (2.0 * rand() - 1.0) * w, rand() * top];
                let (inside, height) = if axisymmetric {
                    let r = p[0].hypot(p[1]);
                    (r <= w, (w - r) * slope)
                } else {
                    (p[0] >= 0.0 && p[0] <= w && p[1] >= 0.0 && p[1] <= depth, p[0] * slope)
                };
                if inside && p[2] >= 0.0 && p[2] <= height - d {
                    pts.push(p);
                }
            }
        }
    }
    // The surface layer, dense enough that every surface cell holds a surface grain.
    for _ in 0..(4.0 * w * w / (d * d)) as usize * 16 {
        let (x, y) = ((2.0 * rand() - 1.0) * w, (2.0 * rand() - 1.0) * w);
        let (inside, height) = if axisymmetric {
            let r = x.hypot(y);
            (r <= w, (w - r) * slope)
        } else {
            (x >= 0.0 && x <= w && y >= 0.0 && y <= depth, x * slope)
        };
        if inside && height > 0.5 * d {
            pts.push([x, y, height - 0.5 * d + 0.1 * d * (rand() - 0.5)]);
        }
    }
    let heap = if axisymmetric {
        Heap::Axisymmetric { centre: [0.0, 0.0], radius: w, z_range: [0.0, w * slope] }
    } else {
        Heap::PlaneStrain { x_range: [0.0, w], y_range: [0.0, depth], open_x: 0.0 }
    };
    (pts, heap, d)
}

#[test]
fn synthetic_heaps_give_back_their_slope() {
    for axisymmetric in [false, true] {
        for alpha in [25.0, 33.0, 40.0] {
            let (pts, geometry, d) = heap(alpha, axisymmetric);
            let x_max = 0.1;
            let r = measure(&pts, &geometry, d, 0.32 * d, x_max).unwrap();
            assert!(
                (r.angle_deg - alpha).abs() < 0.3,
                "axisymmetric {axisymmetric}: {} deg for a {alpha} deg heap",
                r.angle_deg
            );
            // Eq. 2.11's error estimate covers the actual error.
            assert!(
                (r.angle_deg - alpha).abs() <= 3.0 * r.std_deg,
                "error {} vs std {}",
                r.angle_deg - alpha,
                r.std_deg
            );
            // A planar heap: the quadratic fit is straight, its local angle is the slope.
            assert!((r.local_angle_deg(0.05) - alpha).abs() < 1.0);
        }
    }
}

#[test]
fn mobilised_friction_of_a_mohr_coulomb_state() {
    // sigma1/sigma3 = (1 + sin phi)/(1 - sin phi) at failure: eq. 2.37 gives back phi.
    let phi: f64 = 30.0;
    let ratio = (1.0 + phi.to_radians().sin()) / (1.0 - phi.to_radians().sin());
    assert!((mobilised_friction_deg(ratio * 1e5, 1e5) - phi).abs() < 1e-9);
}
