#![allow(clippy::needless_range_loop)]
//! Transfers conserve mass and momentum; rigid motion strains nothing; thread count changes nothing.

use granite_core::mpm::fill::{cell_points, Layout};
use granite_core::mpm::{Mesh, MpmSim, StressScheme};
use granite_core::registry::ParamMap;

fn elastic_block(dim: usize, update: &str) -> MpmSim {
    let reg = granite::registry();
    let mesh = Mesh::new(dim, [0.0; 3], [0.1, 0.125, 0.2], [8, 6, 5]).unwrap();
    let mut sim = MpmSim::new(mesh.clone(), reg.build_velocity_update(update, &ParamMap::new()).unwrap());
    let params: ParamMap = [("young".to_string(), 1e6), ("poisson".to_string(), 0.25)].into_iter().collect();
    let m = sim.add_material("block", 1500.0, reg.build_law("linear_elastic", &params).unwrap()).unwrap();
    let (xs, vols) =
        cell_points(&mesh, Layout::Gauss, 2, |x| Ok(x[0] > 0.2 && x[0] < 0.6 && x[1] > 0.25 && x[1] < 0.5)).unwrap();
    sim.add_points(m, &xs, &vols, [0.0; 3], [0.0; 6]).unwrap();
    sim.set_dt(0.1 * sim.critical_dt().unwrap()).unwrap();
    sim
}

/// A smooth but non-uniform velocity field, so that transfers have something to get wrong.
fn swirl(sim: &mut MpmSim) {
    for (v, x) in sim.points.v.iter_mut().zip(&sim.points.x) {
        *v = [0.3 + (7.0 * x[1]).sin(), -0.2 + (5.0 * x[0]).cos(), if sim.mesh.dim == 3 { 0.1 * x[0] } else { 0.0 }];
    }
}

fn total_momentum(sim: &MpmSim) -> [f64; 3] {
    let mut p = [0.0; 3];
    for (m, v) in sim.points.mass.iter().zip(&sim.points.v) {
        for a in 0..3 {
            p[a] += m * v[a];
        }
    }
    p
}

#[test]
fn p2g_conserves_mass_and_momentum() {
    for dim in [2, 3] {
        let mut sim = elastic_block(dim, "FLIP");
        swirl(&mut sim);
        let mass: f64 = sim.points.mass.iter().sum();
        let momentum = total_momentum(&sim);
        let sums = sim.map_to_grid().unwrap();
        let grid_mass: f64 = sums.iter().map(|s| s.mass).sum();
        assert!((grid_mass - mass).abs() <= 1e-13 * mass, "{dim}D mass {grid_mass} vs {mass}");
        for a in 0..3 {
            let grid_p: f64 = sums.iter().map(|s| s.momentum[a]).sum();
            assert!((grid_p - momentum[a]).abs() <= 1e-12 * mass, "{dim}D momentum[{a}] {grid_p} vs {}", momentum[a]);
        }
    }
}

#[test]
fn free_steps_conserve_momentum_for_every_strategy() {
    // No gravity, no boundary condition: internal forces cancel, so P2G -> grid -> G2P must keep
    // the total momentum to round-off, whatever the velocity update.
    for update in ["PIC", "FLIP", "NFLIP", "FLIPX", "NFLIPX", "APIC"] {
        for scheme in [StressScheme::Usf, StressScheme::Usl, StressScheme::Musl] {
            let mut sim = elastic_block(2, update);
            sim.scheme = scheme;
            swirl(&mut sim);
            let before = total_momentum(&sim);
            let mass: f64 = sim.points.mass.iter().sum();
            for _ in 0..20 {
                sim.step().unwrap();
            }
            let after = total_momentum(&sim);
            for a in 0..3 {
                assert!(
                    (after[a] - before[a]).abs() <= 1e-11 * mass,
                    "{update} {scheme:?}: momentum {after:?} vs {before:?}"
                );
            }
        }
    }
}

#[test]
fn rigid_translation_produces_no_strain() {
    for dim in [2, 3] {
        let mut sim = elastic_block(dim, "FLIP");
        let v = [0.7, -0.4, if dim == 3 { 0.25 } else { 0.0 }];
        sim.points.v.iter_mut().for_each(|p| *p = v);
        let x0 = sim.points.x.clone();
        let steps = 200;
        for _ in 0..steps {
            sim.step().unwrap();
        }
        let t = sim.time;
        for (i, (x, x_start)) in sim.points.x.iter().zip(&x0).enumerate() {
            for a in 0..3 {
                assert!((x[a] - (x_start[a] + v[a] * t)).abs() < 1e-10, "point {i} drifted");
            }
            assert!(
                sim.points.strain[i].iter().all(|e| e.abs() < 1e-12),
                "point {i} strained: {:?}",
                sim.points.strain[i]
            );
            assert!(sim.points.stress[i].iter().all(|s| s.abs() < 1e-5), "point {i} stressed");
        }
    }
}

#[test]
fn results_do_not_depend_on_thread_count() {
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let reg = granite::registry();
            let mesh = Mesh::new(2, [0.0; 3], [0.01, 0.01, 1.0], [100, 70, 1]).unwrap();
            let mut sim = MpmSim::new(mesh.clone(), reg.build_velocity_update("APIC", &ParamMap::new()).unwrap());
            let params: ParamMap = [("young", 1e6), ("poisson", 0.2), ("friction", 30.0), ("cohesion", 10.0)]
                .iter()
                .map(|(k, v)| (k.to_string(), *v))
                .collect();
            let m = sim.add_material("sand", 1800.0, reg.build_law("mohr_coulomb", &params).unwrap()).unwrap();
            let (xs, vols) = cell_points(&mesh, Layout::Gauss, 3, |x| Ok(x[0] < 0.5 && x[1] < 0.6)).unwrap();
            sim.add_points(m, &xs, &vols, [0.0; 3], [0.0; 6]).unwrap();
            sim.gravity = [0.0, -9.81, 0.0];
            for (face, axis) in [("x-", 0), ("y-", 1)] {
                let f = granite_core::mpm::Face::parse(face, 2).unwrap();
                sim.boundary.velocity.push(granite_core::mpm::boundary::VelocityConstraint {
                    nodes: f.nodes(&mesh),
                    axis,
                    value: granite_core::mpm::TimeFunction::Constant(0.0),
                });
            }
            sim.set_dt(0.2 * sim.critical_dt().unwrap()).unwrap();
            for _ in 0..150 {
                sim.step().unwrap();
            }
            (sim.points.x.clone(), sim.points.stress.clone())
        })
    };
    let (x1, s1) = run(1);
    let (x2, s2) = run(2);
    assert!(x1.len() > 20_000, "the scene must be large enough to be split across threads");
    assert!(x1 == x2 && s1 == s2, "1 and 2 threads differ");
}
