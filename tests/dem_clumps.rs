#![allow(clippy::needless_range_loop)]
//! Clumps: rigid aggregates of spheres. Free rotation keeps the angular momentum; collisions keep
//! the linear momentum; a clump dropped on a floor comes to rest on it.

use granite_core::dem::clump::tetrahedral_members;
use granite_core::dem::walls::{Wall, WallShape};
use granite_core::dem::DemSim;
use granite_core::registry::ParamMap;
use nalgebra::{Matrix3, Vector3};

fn sim(law: &str, pairs: &[(&str, f64)]) -> (DemSim, u16) {
    let mut s = DemSim::new();
    let m = s.world.add_material("resin", 1111.0).unwrap();
    let p: ParamMap = pairs.iter().map(|(k, v)| (k.to_string(), *v)).collect();
    s.world.set_contact_law(granite::registry().build_contact_law(law, &p).unwrap(), None).unwrap();
    s.skin = 1e-3;
    (s, m)
}

fn angular_momentum(s: &DemSim, c: usize) -> Vector3<f64> {
    let cl = &s.world.clumps;
    let rot = cl.q[c].to_rotation_matrix();
    let ib = Matrix3::from_diagonal(&Vector3::new(cl.inertia[c][0], cl.inertia[c][1], cl.inertia[c][2]));
    let iw = rot.matrix() * ib * rot.matrix().transpose();
    iw * Vector3::new(cl.w[c][0], cl.w[c][1], cl.w[c][2])
}

#[test]
fn free_asymmetric_clump_keeps_its_angular_momentum() {
    let (mut s, m) = sim("linear", &[("kn", 1e4)]);
    // Three unequal, partly overlapping spheres: three different principal moments.
    let members = [([0.0, 0.0, 0.0], 0.01), ([0.012, 0.0, 0.0], 0.007), ([0.0, 0.009, 0.004], 0.005)];
    let c = s.world.add_clump(m, &members, [0.0; 3], 128).unwrap();
    s.world.clumps.w[c] = [3.0, -2.0, 5.0];
    let l0 = angular_momentum(&s, c);
    s.world.set_dt(1e-5).unwrap();
    for _ in 0..20_000 {
        s.step().unwrap();
    }
    let l1 = angular_momentum(&s, c);
    assert!((l1 - l0).norm() < 1e-3 * l0.norm(), "L went from {l0:?} to {l1:?}");
    // Members stay rigidly attached: their mutual distances do not change.
    let d = |a: usize, b: usize| {
        let (xa, xb) = (s.world.spheres.x[a], s.world.spheres.x[b]);
        ((xa[0] - xb[0]).powi(2) + (xa[1] - xb[1]).powi(2) + (xa[2] - xb[2]).powi(2)).sqrt()
    };
    assert!((d(0, 1) - 0.012).abs() < 1e-12 && (d(0, 2) - (0.009f64.hypot(0.004))).abs() < 1e-12);
}

#[test]
fn clump_collision_conserves_linear_momentum() {
    let (mut s, m) = sim("linear", &[("kn", 1e4), ("kt_ratio", 0.5), ("friction", 20.0)]);
    let a = tetrahedral_members([0.0, 0.0, 0.0], 0.003101, 0.005).unwrap();
    let b = tetrahedral_members([0.0125, 0.002, 0.001], 0.003101, 0.005).unwrap();
    s.world.add_clump(m, &a, [0.5, 0.0, 0.0], 128).unwrap();
    s.world.add_clump(m, &b, [-0.3, 0.05, 0.0], 128).unwrap();
    let p = |s: &DemSim| {
        let mut p = [0.0; 3];
        for c in 0..s.world.clumps.len() {
            for k in 0..3 {
                p[k] += s.world.clumps.mass[c] * s.world.clumps.v[c][k];
            }
        }
        p
    };
    let p0 = p(&s);
    s.world.set_dt(2e-6).unwrap();
    let mut touched = false;
    for _ in 0..20_000 {
        s.step().unwrap();
        touched |= s.world.contacts.spheres.touching_count() > 0;
    }
    assert!(touched, "the clumps must collide");
    let p1 = p(&s);
    let scale = p0.iter().map(|c| c.abs()).fold(0.0, f64::max);
    for k in 0..3 {
        assert!((p1[k] - p0[k]).abs() < 1e-10 * scale, "momentum {p0:?} -> {p1:?}");
    }
}

#[test]
fn clump_settles_on_a_floor() {
    let (mut s, m) = sim("visco_elastic", &[("kn", 1e4), ("kt_ratio", 0.5), ("friction", 30.0), ("restitution", 0.3)]);
    let members = tetrahedral_members([0.0, 0.0, 0.02], 0.003101, 0.005).unwrap();
    s.world.add_clump(m, &members, [0.0; 3], 128).unwrap();
    s.world.add_wall(Wall::new("floor", WallShape::Plane { normal: [0.0, 0.0, 1.0] }, [0.0; 3], m));
    s.world.gravity = [0.0, 0.0, -9.81];
    s.world.set_dt(1e-5).unwrap();
    for _ in 0..100_000 {
        s.step().unwrap();
    }
    let d = s.world.diagnostics();
    assert!(d.kinetic_energy < 1e-9, "still moving: Ek = {}", d.kinetic_energy);
    // At rest the floor carries the clump's weight (within the static overlap).
    let weight = s.world.clumps.mass[0] * 9.81;
    let floor = s.world.wall_force(0)[2];
    assert!((-floor - weight).abs() < 1e-3 * weight, "floor force {floor} vs weight {weight}");
    // The lowest member touches the floor with a small overlap.
    let lowest = (0..4).map(|i| s.world.spheres.x[i][2] - s.world.spheres.radius[i]).fold(f64::INFINITY, f64::min);
    assert!(lowest < 0.0 && lowest > -1e-3, "lowest point at {lowest}");
}

/// A clump refused for one member (here a radius whose mass underflows to zero next to a
/// normal one, so the union's mass is fine) leaves no loose member spheres behind.
#[test]
fn a_refused_clump_adds_no_spheres() {
    let mut sim = DemSim::new();
    let m = sim.world.add_material("grains", 2650.0).unwrap();
    let members = [([0.0, 0.0, 0.0], 1e-2), ([0.1, 0.0, 0.0], 1e-110)];
    let e = sim.world.add_clump(m, &members, [0.0; 3], 64).expect_err("refused").to_string();
    assert!(e.contains("`radius` = 1e-110") && e.contains("mass of 0e0 kg"), "{e}");
    assert_eq!((sim.world.spheres.len(), sim.world.clumps.len()), (0, 0));
}
