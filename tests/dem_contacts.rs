//! Binary collisions against their analytic solutions (thesis 2.2.3, Schwager & Pöschel 2007).

use granite_core::dem::walls::{Wall, WallShape};
use granite_core::dem::DemSim;
use granite_core::registry::ParamMap;

fn params(pairs: &[(&str, f64)]) -> ParamMap {
    pairs.iter().map(|(k, v)| (k.to_string(), *v)).collect()
}

/// Contact duration in units of 1/w0 for damping ratio x (formulas.md), written out here
/// independently of the plugin so the test checks the engine against the formula.
fn duration(x: f64) -> f64 {
    if x < std::f64::consts::FRAC_1_SQRT_2 {
        let w = (1.0 - x * x).sqrt();
        (std::f64::consts::PI - (2.0 * x * w / (w * w - x * x)).atan()) / w
    } else {
        let w = (1.0 - x * x).sqrt();
        (2.0 * x * w / (x * x - w * w)).atan() / w
    }
}

struct Outcome {
    restitution: f64,
    contact_time: f64,
    kinetic_before: f64,
    kinetic_after: f64,
}

/// Two spheres (or a sphere and a wall) approaching at `speed`; returns what the collision did.
fn collide(law: &str, law_params: &[(&str, f64)], against_wall: bool, speed: f64, dt_fraction: f64) -> (Outcome, f64) {
    let reg = granite::registry();
    let mut sim = DemSim::new();
    let m = sim.add_material("glass", 2500.0).unwrap();
    sim.set_contact_law(reg.build_contact_law(law, &params(law_params)).unwrap(), None).unwrap();
    let r = 0.01;
    sim.add_sphere(m, [0.0, 0.0, 0.0], r, [speed, 0.0, 0.0]).unwrap();
    if against_wall {
        sim.add_wall(Wall {
            name: "wall".into(),
            shape: WallShape::Plane { normal: [-1.0, 0.0, 0.0] },
            position: [r + 1e-4, 0.0, 0.0],
            velocity: [0.0; 3],
            material: m,
            force: [0.0; 3],
        });
    } else {
        sim.add_sphere(m, [2.0 * r + 1e-4, 0.0, 0.0], r, [-speed, 0.0, 0.0]).unwrap();
    }
    let m1 = sim.spheres.mass[0];
    let m_eff = if against_wall { m1 } else { 0.5 * m1 };
    let kn = sim.laws[0].max_normal_stiffness(&granite_core::ext::PairInfo {
        radius: [r, if against_wall { f64::INFINITY } else { r }],
        mass: [m1, if against_wall { f64::INFINITY } else { m1 }],
        seed: 0,
    });
    let w0 = (kn / m_eff).sqrt();
    sim.skin = 0.5 * r;
    sim.set_dt(dt_fraction / w0).unwrap();
    let kinetic = |s: &DemSim| s.diagnostics().kinetic_energy;
    let before = kinetic(&sim);
    let rel_before = if against_wall { speed } else { 2.0 * speed };
    let mut in_contact = 0u64;
    let mut started = false;
    for _ in 0..2_000_000 {
        sim.step().unwrap();
        let touching = if against_wall {
            sim.wall_pairs.force.iter().any(|f| f[0] != 0.0)
        } else {
            sim.pairs.force.iter().any(|f| f[0] != 0.0)
        };
        if touching {
            started = true;
            in_contact += 1;
        } else if started {
            break;
        }
    }
    let v = &sim.spheres.v;
    let rel_after = if against_wall { -v[0][0] } else { v[1][0] - v[0][0] };
    let out = Outcome {
        restitution: rel_after / rel_before,
        contact_time: in_contact as f64 * sim.dt,
        kinetic_before: before,
        kinetic_after: kinetic(&sim),
    };
    (out, w0)
}

#[test]
fn sphere_sphere_and_sphere_wall_hit_the_target_restitution() {
    for target in [0.5, 0.8] {
        for wall in [false, true] {
            let (o, w0) = collide("visco_elastic", &[("kn", 1e5), ("restitution", target)], wall, 0.5, 2e-3);
            assert!(
                (o.restitution - target).abs() < 0.01 * target,
                "wall {wall}: e = {} for target {target}",
                o.restitution
            );
            // Contact time of Schwager & Pöschel for the damping ratio that gives `target`.
            let x = {
                let (mut lo, mut hi) = (0.0f64, 0.7f64);
                for _ in 0..200 {
                    let mid = 0.5 * (lo + hi);
                    if (-mid * duration(mid)).exp() > target {
                        lo = mid
                    } else {
                        hi = mid
                    }
                }
                0.5 * (lo + hi)
            };
            let tc = duration(x) / w0;
            assert!(
                (o.contact_time - tc).abs() < 0.01 * tc,
                "wall {wall}: contact lasted {} s, analytic {tc} s",
                o.contact_time
            );
        }
    }
}

#[test]
fn elastic_frictionless_collision_conserves_energy() {
    for wall in [false, true] {
        let (o, w0) = collide("linear", &[("kn", 1e5)], wall, 0.5, 2e-3);
        let rel = (o.kinetic_after - o.kinetic_before).abs() / o.kinetic_before;
        assert!(rel < 1e-4, "wall {wall}: kinetic energy changed by {rel}");
        // A linear spring: half a period of the one-contact oscillator.
        let tc = std::f64::consts::PI / w0;
        assert!((o.contact_time - tc).abs() < 0.01 * tc);
        assert!((o.restitution - 1.0).abs() < 1e-3);
    }
}
