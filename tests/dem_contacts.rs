//! Binary collisions against their analytic solutions (thesis 2.2.3, Schwager & Pöschel 2007;
//! Hertz's elastic impact).

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
    let m = sim.world.add_material("glass", 2500.0).unwrap();
    sim.world.set_contact_law(reg.build_contact_law(law, &params(law_params)).unwrap(), None).unwrap();
    let r = 0.01;
    sim.world.add_sphere(m, [0.0, 0.0, 0.0], r, [speed, 0.0, 0.0]).unwrap();
    if against_wall {
        sim.world.add_wall(Wall::new("wall", WallShape::Plane { normal: [-1.0, 0.0, 0.0] }, [r + 1e-4, 0.0, 0.0], m));
    } else {
        sim.world.add_sphere(m, [2.0 * r + 1e-4, 0.0, 0.0], r, [-speed, 0.0, 0.0]).unwrap();
    }
    let m1 = sim.world.spheres.mass[0];
    let m_eff = if against_wall { m1 } else { 0.5 * m1 };
    let kn = sim.world.contacts.laws[0].max_normal_stiffness(&granite_core::ext::PairInfo {
        radius: [r, if against_wall { f64::INFINITY } else { r }],
        mass: [m1, if against_wall { f64::INFINITY } else { m1 }],
        seed: 0,
        elastic: [None; 2],
    });
    let w0 = (kn / m_eff).sqrt();
    sim.skin = 0.5 * r;
    sim.world.set_dt(dt_fraction / w0).unwrap();
    let kinetic = |s: &DemSim| s.world.diagnostics().kinetic_energy;
    let before = kinetic(&sim);
    let rel_before = if against_wall { speed } else { 2.0 * speed };
    let mut in_contact = 0u64;
    let mut started = false;
    for _ in 0..2_000_000 {
        sim.step().unwrap();
        let touching = if against_wall {
            sim.world.contacts.sphere_walls.force.iter().any(|f| f[0] != 0.0)
        } else {
            sim.world.contacts.spheres.force.iter().any(|f| f[0] != 0.0)
        };
        if touching {
            started = true;
            in_contact += 1;
        } else if started {
            break;
        }
    }
    let v = &sim.world.spheres.v;
    let rel_after = if against_wall { -v[0][0] } else { v[1][0] - v[0][0] };
    let out = Outcome {
        restitution: rel_after / rel_before,
        contact_time: in_contact as f64 * sim.world.dt,
        kinetic_before: before,
        kinetic_after: kinetic(&sim),
    };
    (out, w0)
}

/// Given as a damping ratio (YADE's KnKsPhys `betan`, thesis table 2.7's 0.071), the dashpot
/// gives the restitution Schwager & Pöschel's solution of the clamped linear spring-dashpot
/// predicts for that ratio, within 1 %.
#[test]
fn a_damping_ratio_gives_its_restitution() {
    let beta: f64 = 0.071;
    let predicted = (-beta * duration(beta)).exp();
    for wall in [false, true] {
        let (o, _) = collide("visco_elastic", &[("kn", 1e5), ("beta_n", beta)], wall, 0.5, 2e-3);
        assert!(
            (o.restitution - predicted).abs() < 0.01 * predicted,
            "wall {wall}: e = {} for {predicted}",
            o.restitution
        );
    }
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

/// Hertz's impact: `t_c = 2 I δ_max / v` with `δ_max = (15 m* v² / (16 E* sqrt(R*)))^(2/5)` and
/// `I = ∫0^1 (1 − x^(5/2))^(-1/2) dx`, integrated here (x = 1 − s² removes the end singularity).
fn hertz_contact_time(m_eff: f64, r_eff: f64, e_eff: f64, v: f64) -> f64 {
    let f = |s: f64| {
        let x = 1.0 - s * s;
        let g = 1.0 - x.powf(2.5);
        if s == 0.0 {
            2.0 / 2.5f64.sqrt()
        } else {
            2.0 * s / g.sqrt()
        }
    };
    let n = 20_000;
    let h = 1.0 / n as f64;
    let simpson: f64 = (0..=n)
        .map(|k| {
            let w = if k == 0 || k == n {
                1.0
            } else if k % 2 == 1 {
                4.0
            } else {
                2.0
            };
            w * f(k as f64 * h)
        })
        .sum::<f64>()
        * h
        / 3.0;
    let delta_max = (15.0 * m_eff * v * v / (16.0 * e_eff * r_eff.sqrt())).powf(0.4);
    2.0 * simpson * delta_max / v
}

#[test]
fn hertz_impact_is_elastic_and_lasts_the_analytic_time() {
    let (young, poisson, r, rho, speed) = (1e9, 0.3, 0.01, 2500.0, 0.5);
    let e_eff = young / (2.0 * (1.0 - poisson * poisson));
    let m = rho * 4.0 / 3.0 * std::f64::consts::PI * r * r * r;
    for wall in [false, true] {
        let (o, _) = collide("hertz_mindlin", &[("young", young), ("poisson", poisson)], wall, speed, 2e-3);
        let (m_eff, r_eff, v) = if wall { (m, r, speed) } else { (0.5 * m, 0.5 * r, 2.0 * speed) };
        let tc = hertz_contact_time(m_eff, r_eff, e_eff, v);
        assert!(
            (o.contact_time - tc).abs() < 0.01 * tc,
            "wall {wall}: contact lasted {} s, Hertz gives {tc} s",
            o.contact_time
        );
        assert!((o.restitution - 1.0).abs() < 1e-3, "wall {wall}: e = {}", o.restitution);
        let rel = (o.kinetic_after - o.kinetic_before).abs() / o.kinetic_before;
        assert!(rel < 1e-4, "wall {wall}: kinetic energy changed by {rel}");
    }
}

/// A sphere resting on a floor under gravity settles at Hertz's overlap
/// `δ = (3 F_n / (4 E* sqrt(R)))^(2/3)`; tilting gravity then shifts it by `F_t / k_t` with
/// Mindlin's `k_t = 8 G* sqrt(R δ)` (rotations blocked, friction far from sliding).
#[test]
fn hertz_overlap_and_mindlin_shear_stiffness_of_a_resting_sphere() {
    use granite_core::dem::particles::dof;
    let (young, poisson, r, rho, g) = (1e7, 0.3, 0.01, 2500.0, 9.81);
    let reg = granite::registry();
    let mut sim = DemSim::new();
    let m = sim.world.add_material("grain", rho).unwrap();
    let law =
        reg.build_contact_law("hertz_mindlin", &params(&[("young", young), ("poisson", poisson), ("friction", 60.0)]));
    sim.world.set_contact_law(law.unwrap(), None).unwrap();
    sim.world.add_sphere(m, [0.0, 0.0, r], r, [0.0; 3]).unwrap();
    sim.world.spheres.blocked[0] = dof::RX | dof::RY | dof::RZ;
    sim.world.add_wall(Wall::new("floor", WallShape::Plane { normal: [0.0, 0.0, 1.0] }, [0.0; 3], m));
    sim.skin = 0.1 * r;
    sim.world.damping = 0.4;
    sim.world.gravity = [0.0, 0.0, -g];
    sim.world.set_dt(0.2 * sim.world.critical_dt().unwrap()).unwrap();
    for _ in 0..20_000 {
        sim.step().unwrap();
    }
    let mass = sim.world.spheres.mass[0];
    let e_eff = young / (2.0 * (1.0 - poisson * poisson));
    let g_eff = young / (2.0 * (1.0 + poisson)) / (2.0 * (2.0 - poisson));
    let delta = (3.0 * mass * g / (4.0 * e_eff * r.sqrt())).powf(2.0 / 3.0);
    let settled = sim.world.spheres.x[0];
    assert!((r - settled[2] - delta).abs() < 0.01 * delta, "overlap {} m, Hertz gives {delta} m", r - settled[2]);

    let tilt = 0.3;
    sim.world.gravity = [tilt * g, 0.0, -g];
    for _ in 0..20_000 {
        sim.step().unwrap();
    }
    let kt = 8.0 * g_eff * (r * delta).sqrt();
    let expected = tilt * mass * g / kt;
    let shift = sim.world.spheres.x[0][0] - settled[0];
    assert!((shift - expected).abs() < 0.01 * expected, "tangential shift {shift} m, Mindlin gives {expected} m");
}

/// Six head-on collisions in one scene, alternately of two materials each with its own law (an
/// elastic `linear` spring with 3 values per contact, and `visco_elastic` at e = 0.8 with 4):
/// their contacts share a chunk, so each law runs on its compacted subset of several contacts,
/// laid out with its own count of values; each collision rebounds as its own law says.
#[test]
fn different_laws_in_one_chunk_keep_their_own_restitution() {
    let reg = granite::registry();
    let mut sim = DemSim::new();
    let elastic = sim.world.add_material("elastic", 2500.0).unwrap();
    let damped = sim.world.add_material("damped", 2500.0).unwrap();
    let laws = [(elastic, "linear", 1.0), (damped, "visco_elastic", 0.8)];
    for (m, law, e) in laws {
        let mut p = params(&[("kn", 1e5)]);
        if e < 1.0 {
            p.insert("restitution".into(), e);
        }
        sim.world.set_contact_law(reg.build_contact_law(law, &p).unwrap(), Some((m, m))).unwrap();
    }
    let (r, speed) = (0.01, 0.5);
    for k in 0..6 {
        let (m, _, _) = laws[k % 2];
        let y = 0.1 * k as f64;
        sim.world.add_sphere(m, [0.0, y, 0.0], r, [speed, 0.0, 0.0]).unwrap();
        sim.world.add_sphere(m, [2.0 * r + 1e-4, y, 0.0], r, [-speed, 0.0, 0.0]).unwrap();
    }
    sim.skin = 0.5 * r;
    let m_eff = 0.5 * sim.world.spheres.mass[0];
    sim.world.set_dt(2e-3 / (1e5 / m_eff).sqrt()).unwrap();
    // Until both contacts have started and ended.
    let mut touched = false;
    for _ in 0..2_000_000 {
        sim.step().unwrap();
        let touching = sim.world.contacts.spheres.touching.iter().any(|&t| t);
        touched |= touching;
        if touched && !touching {
            break;
        }
    }
    let v = &sim.world.spheres.v;
    for k in 0..6 {
        let (_, law, e) = laws[k % 2];
        let rebound = (v[2 * k + 1][0] - v[2 * k][0]) / (2.0 * speed);
        assert!((rebound - e).abs() < 0.01 * e, "{law} pair: e = {rebound}, expected {e}");
    }
}

/// A frictionless sphere at rest in the corner of a floor and a side wall, under a gravity that
/// leans towards the side wall: each wall carries the weight's component along its own normal
/// (frictionless contacts push along normals only), and a third wall, out of reach, carries none.
#[test]
fn each_wall_carries_the_weight_along_its_normal() {
    let mut sim = DemSim::new();
    let m = sim.world.add_material("glass", 2500.0).unwrap();
    sim.world
        .set_contact_law(granite::registry().build_contact_law("linear", &params(&[("kn", 1e4)])).unwrap(), None)
        .unwrap();
    let r = 0.01;
    sim.world.add_sphere(m, [r, 0.0, r], r, [0.0; 3]).unwrap();
    sim.world.add_wall(Wall::new("far", WallShape::Plane { normal: [0.0, -1.0, 0.0] }, [0.0, 0.5, 0.0], m));
    sim.world.add_wall(Wall::new("floor", WallShape::Plane { normal: [0.0, 0.0, 1.0] }, [0.0; 3], m));
    sim.world.add_wall(Wall::new("side", WallShape::Plane { normal: [1.0, 0.0, 0.0] }, [0.0; 3], m));
    let g = [-3.0, 0.0, -9.81];
    sim.world.gravity = g;
    sim.world.damping = 0.4;
    sim.skin = 0.5 * r;
    sim.world.set_dt(0.1 * (sim.world.spheres.mass[0] / 1e4).sqrt()).unwrap();
    for _ in 0..20_000 {
        sim.step().unwrap();
    }
    assert!(
        sim.world.diagnostics().kinetic_energy < 1e-18,
        "not at rest: Ek = {}",
        sim.world.diagnostics().kinetic_energy
    );
    let weight = g.map(|c| sim.world.spheres.mass[0] * c);
    // What the sphere exerts on each wall.
    assert_eq!(sim.world.wall_force(0), [0.0; 3]);
    let (floor, side) = (sim.world.wall_force(1), sim.world.wall_force(2));
    let tolerance = 1e-9 * weight[2].abs();
    assert!(
        (floor[2] - weight[2]).abs() < tolerance && floor[0] == 0.0 && floor[1] == 0.0,
        "floor {floor:?}, weight {weight:?}"
    );
    assert!(
        (side[0] - weight[0]).abs() < tolerance && side[1] == 0.0 && side[2] == 0.0,
        "side {side:?}, weight {weight:?}"
    );
    // Out of range: nothing.
    assert_eq!(sim.world.wall_force(3), [0.0; 3]);
}
