//! Sparing RVE work in MPMxDEM (`dem_rve`): exact sharing of bitwise-equal RVEs gives the bits
//! of stepping every RVE, and adaptive RVEs (points following an active point) coarsen where
//! points deform alike, step again where they part, keep the stress close to the run that steps
//! every RVE, and do not depend on the thread count or on a checkpoint in the middle.

use crate::common;
use common::prescribe_node_velocities;
use granite_core::dem::DemSim;
use granite_core::ext::constitutive::ObjectMap;
use granite_core::math::Voigt;
use granite_core::mpm::{Mesh, MpmSim, StressScheme};
use granite_core::registry::ParamMap;
use std::sync::{Arc, OnceLock};

fn rve() -> &'static DemSim {
    static RVE: OnceLock<DemSim> = OnceLock::new();
    RVE.get_or_init(|| granite::bench::periodic_rve(150, 1e5).unwrap())
}

/// Compression along x of the right cell only (the left one at rest), at 2 /s.
fn right_cell_compressed(x: [f64; 3]) -> [f64; 3] {
    [-2.0 * (x[0] - 1.0).max(0.0), 0.0, 0.0]
}

/// Compression along x of both cells alike, at 2 /s.
fn both_compressed(x: [f64; 3]) -> [f64; 3] {
    [-2.0 * x[0], 0.0, 0.0]
}

/// Two 1 m cells along x, four points in each (the left cell's first), every one with a copy
/// of the RVE, under the law parameters `given`.
fn two_cells(given: &[(&str, f64)]) -> MpmSim {
    let reg = granite::registry();
    let mesh = Mesh::new(3, [0.0; 3], [1.0; 3], [2, 1, 1]).unwrap();
    let mut sim = MpmSim::new(mesh, reg.build_velocity_update("PIC", &ParamMap::new()).unwrap());
    let given: ParamMap = given.iter().map(|(k, v)| (k.to_string(), *v)).collect();
    let mut objects = ObjectMap::new();
    objects.insert("rve".into(), Arc::new(rve().clone()));
    let law = reg.build_law_with("dem_rve", &given, &objects).unwrap();
    let m = sim.add_material("rve", 1600.0, law).unwrap();
    let mut xs = Vec::new();
    for cell in [0.0, 1.0] {
        for (y, z) in [(0.3, 0.3), (0.7, 0.3), (0.3, 0.7), (0.7, 0.7)] {
            xs.push([cell + 0.5, y, z]);
        }
    }
    let stress = rve().world.love_weber_stress(rve().world.cell_volume().unwrap());
    sim.add_points(m, &xs, &[0.25; 8], [0.0; 3], stress).unwrap();
    sim.scheme = StressScheme::Usl;
    sim.set_dt(2e-5).unwrap();
    sim
}

fn drive(sim: &mut MpmSim, field: fn([f64; 3]) -> [f64; 3], steps: usize) {
    sim.boundary.velocity.clear();
    prescribe_node_velocities(sim, field);
    for _ in 0..steps {
        sim.step().unwrap();
    }
}

/// The number series.csv gives under `name` for this simulation's laws.
fn series(sim: &MpmSim, name: &str) -> f64 {
    sim.law_series().into_iter().find(|(n, _)| *n == name).map(|(_, v)| v).unwrap()
}

/// The sphere-steps exact sharing spared the simulation's RVE material.
fn spared(sim: &MpmSim) -> f64 {
    sim.materials[0].law.point_objects().unwrap().process_savings()
}

fn pressure(s: &Voigt) -> f64 {
    -(s[0] + s[1] + s[2]) / 3.0
}

fn norm(s: &Voigt) -> f64 {
    (s[0] * s[0] + s[1] * s[1] + s[2] * s[2] + 2.0 * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5])).sqrt()
}

#[test]
fn exact_sharing_gives_the_bits_of_stepping_every_rve_and_spares_the_copies_at_rest() {
    let run = |share: f64| {
        let mut sim = two_cells(&[("share", share)]);
        drive(&mut sim, right_cell_compressed, 6);
        let spared = spared(&sim);
        (sim.points.stress.clone(), sim.materials[0].state.clone(), spared)
    };
    let (stress_on, state_on, spared_on) = run(1.0);
    let (stress_off, state_off, spared_off) = run(0.0);
    assert_eq!(stress_on, stress_off);
    assert_eq!(state_on, state_off);
    // The left cell's four points take bitwise-zero increments: three of them ride on the
    // first one's RVE, which takes one DEM step a call (eq. 4.5 with no strain), 6 calls of
    // 150 spheres each.
    assert_eq!(spared_off, 0.0);
    assert!(spared_on >= 3.0 * 6.0 * 150.0, "exact sharing spared {spared_on} sphere-steps");
    // The compressed cell's points did work, the resting ones stayed at the prepared stress.
    let p0 = pressure(&stress_on[0]);
    assert!(pressure(&stress_on[4]) > p0 * 1.01, "compressed {} vs resting {p0}", pressure(&stress_on[4]));
}

#[test]
fn equal_rves_of_a_checkpoint_share_again_on_resuming() {
    let sim = two_cells(&[]);
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/test-out/mpmxdem_share_checkpoint");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("checkpoint.json");
    sim.save(&path).unwrap();
    let mut resumed = MpmSim::load(&path, &granite::registry()).unwrap();
    let mut sim = sim;
    drive(&mut sim, right_cell_compressed, 6);
    drive(&mut resumed, right_cell_compressed, 6);
    assert_eq!(sim.points.stress, resumed.points.stress);
    assert_eq!(sim.materials[0].state, resumed.materials[0].state);
    // The eight saved copies of the prepared sample share again: the resting cell's spare as much
    // as in the run that was never saved.
    let (spared, spared_resumed) = (spared(&sim), spared(&resumed));
    assert!(spared > 0.0);
    assert_eq!(spared_resumed, spared);
}

/// Both cells compressed alike for 20 steps, then only the right one for 20.
fn two_phases(given: &[(&str, f64)]) -> (MpmSim, f64, f64) {
    let mut sim = two_cells(given);
    drive(&mut sim, both_compressed, 20);
    let active_alike = series(&sim, "rve_active");
    drive(&mut sim, right_cell_compressed, 20);
    let active_parted = series(&sim, "rve_active");
    (sim, active_alike, active_parted)
}

const ADAPTIVE: [(&str, f64); 4] =
    [("adaptive", 1.0), ("adaptive_coarsen", 0.02), ("adaptive_refine", 0.05), ("adaptive_every", 5.0)];

#[test]
fn alike_points_follow_one_rve_and_parting_points_step_their_own_again() {
    let (adaptive, alike, parted) = two_phases(&ADAPTIVE);
    let (reference, all, _) = two_phases(&[]);
    assert_eq!(all, 8.0, "without `adaptive` every point steps its own RVE");
    // Under one homogeneous compression the eight points deform alike: one RVE steps.
    assert_eq!(alike, 1.0, "points stepping their own RVE while all deform alike");
    // Once only the right cell is compressed, its points part from the resting leader.
    assert!(parted >= 2.0, "{parted} points step their own RVE once the cells part");
    // Followers carry the stress error the tolerances allow: the distance estimates it as a
    // fraction of the mean pressure, and a follower restarts past `refine`; twice `refine`
    // leaves room for the estimate's secant stiffness.
    let p_mean = reference.points.stress.iter().map(pressure).sum::<f64>() / 8.0;
    for (i, (a, r)) in adaptive.points.stress.iter().zip(&reference.points.stress).enumerate() {
        let gap: Voigt = std::array::from_fn(|k| a[k] - r[k]);
        let error = norm(&gap) / p_mean;
        assert!(error < 2.0 * 0.05, "point {i}: stress off by {:.1} % of the mean pressure", 100.0 * error);
    }
    // And the run did less DEM work.
    let work = |sim: &MpmSim| sim.materials[0].state.chunks(8).map(|s| s[7]).sum::<f64>();
    assert!(work(&adaptive) < 0.7 * work(&reference), "{} vs {} sphere-steps", work(&adaptive), work(&reference));
}

#[test]
fn adaptive_rves_do_not_depend_on_the_thread_count() {
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let (sim, _, _) = two_phases(&ADAPTIVE);
            (sim.points.stress.clone(), sim.materials[0].state.clone())
        })
    };
    assert_eq!(run(1), run(2));
}

#[test]
fn an_adaptive_run_resumes_from_a_checkpoint_bit_for_bit() {
    let mut sim = two_cells(&ADAPTIVE);
    drive(&mut sim, both_compressed, 12);
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/test-out/mpmxdem_adaptive_checkpoint");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("checkpoint.json");
    sim.save(&path).unwrap();
    let mut resumed = MpmSim::load(&path, &granite::registry()).unwrap();
    assert_eq!(series(&resumed, "rve_active"), series(&sim, "rve_active"));
    for s in [&mut sim, &mut resumed] {
        drive(s, both_compressed, 8);
        drive(s, right_cell_compressed, 20);
    }
    assert_eq!(sim.points.stress, resumed.points.stress);
    assert_eq!(sim.materials[0].state, resumed.materials[0].state);
    assert_eq!(series(&sim, "rve_active"), series(&resumed, "rve_active"));
}
