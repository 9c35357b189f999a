#![allow(clippy::needless_range_loop)]
//! MPMxDEM (thesis chapter 4): the `dem_rve` law against hand-checked numbers, its own RVE at
//! rest, a pure DEM run of the same strain path, and thread-count independence.

use crate::common;
use common::prescribe_node_velocities;
use granite_core::dem::cell::PeriodicCell;
use granite_core::dem::{DemSim, Rve};
use granite_core::ext::constitutive::ObjectMap;
use granite_core::ext::{ConstitutiveLaw, LawBatch, PointObjects};
use granite_core::mpm::{Mesh, MpmSim, StressScheme};
use granite_core::params::Params;
use granite_core::registry::ParamMap;
use granite_plugins::constitutive::dem_rve::{DemRve, SPECS};
use std::sync::Arc;

fn objects(rve: &DemSim) -> ObjectMap {
    let mut o = ObjectMap::new();
    o.insert("rve".into(), Arc::new(rve.clone()));
    o
}

fn params(pairs: &[(&str, f64)]) -> Params {
    let given: ParamMap = pairs.iter().map(|(k, v)| (k.to_string(), *v)).collect();
    Params::resolve("law \"dem_rve\"", SPECS, &given).unwrap()
}

/// A 4 x 4 x 4 simple cubic RVE of spheres r = 1 mm, rho = 2650, just touching, in a periodic box.
fn lattice_rve() -> DemSim {
    let mut sim = DemSim::new();
    let m = sim.world.add_material("grains", 2650.0).unwrap();
    let p: ParamMap = [("kn".to_string(), 1e5)].into_iter().collect();
    sim.world.set_contact_law(granite::registry().build_contact_law("linear", &p).unwrap(), None).unwrap();
    let (r, n) = (1e-3, 4);
    sim.world.set_cell(Some(PeriodicCell::new_box([2.0 * r * n as f64; 3])));
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                sim.world
                    .add_sphere(
                        m,
                        [(2 * i + 1) as f64 * r, (2 * j + 1) as f64 * r, (2 * k + 1) as f64 * r],
                        r,
                        [0.0; 3],
                    )
                    .unwrap();
            }
        }
    }
    sim.skin = 1e-4;
    sim.world.set_dt(1e-5).unwrap();
    sim
}

#[test]
fn p_min_and_deformation_time_follow_eqs_4_2_to_4_5() {
    let rve = lattice_rve();
    let law = DemRve::new(params(&[("inertial_number", 1e-2)]), &objects(&rve)).unwrap();
    // Hand-checked: m = 2650 * 4/3 pi (1e-3)^3 = 1.1100294e-5 kg; W = 64 m 9.81 = 6.969210e-3 N;
    // the bottom face is (8 mm)^2 = 6.4e-5 m^2, so P_min = 108.894 Pa (eq. 4.2).
    let p_min = law.p_min(&Rve::prepare(rve.clone(), "test").unwrap());
    assert!((p_min - 108.894).abs() < 1e-3, "P_min = {p_min}");
    // Eq. 4.1 with |de|max = 1e-4, I = 1e-2, rho_g = 2650, l = 2 mm, P = P_min:
    // T = 1e-2 sqrt(2650 * 4e-6 / 108.894) = 9.8662e-5 s.
    let plan = law.plan(1e-4, p_min, 1e-5);
    // Eq. 4.5: ceil(9.8661) = 10 steps of 1e-5 s.
    assert_eq!(plan.full_steps, 10);
    assert!((plan.duration - 1e-4).abs() < 1e-15);
    // Eq. 4.4: 9 steps of 1e-5 s and one of 0.8661e-5 s, T kept.
    let adjusted = DemRve::new(params(&[("inertial_number", 1e-2), ("strategy", 0.0)]), &objects(&rve)).unwrap();
    let plan = adjusted.plan(1e-4, p_min, 1e-5);
    assert_eq!(plan.full_steps, 9);
    assert!((plan.duration - 9.8662e-5).abs() < 1e-9, "T = {}", plan.duration);
    assert!((plan.last_step - 0.8662e-5).abs() < 1e-9, "last step {}", plan.last_step);
    // A zero increment still takes one DEM step.
    assert_eq!(law.plan(0.0, p_min, 1e-5).full_steps, 1);
}

#[test]
fn fixed_dem_steps_are_a_whole_number_within_the_safeguard() {
    let rve = lattice_rve();
    let law = DemRve::new(params(&[("dem_steps", 51.0)]), &objects(&rve)).unwrap();
    assert_eq!(law.plan(1e-4, 1e5, 1e-5).full_steps, 51);
    // Half a step was taken as one before; a count beyond max_dem_steps failed only at the
    // first call, naming a deformation time that fixed steps do not use.
    for (given, says) in [
        (&[("dem_steps", 0.5)][..], "whole number >= 1"),
        (&[("dem_steps", 100.0), ("max_dem_steps", 99.0)][..], "must not exceed max_dem_steps = 99"),
        (&[("max_dem_steps", 2.5)][..], "whole number >= 1"),
    ] {
        let e = DemRve::new(params(given), &objects(&rve)).err().expect("refused").to_string();
        assert!(e.contains(says), "{given:?}: {e}");
    }
}

#[test]
fn zero_increment_returns_the_prepared_stress() {
    let rve = granite::bench::periodic_rve(300, 1e5).unwrap();
    let volume = rve.world.cell_volume().unwrap();
    let before = rve.world.love_weber_stress(volume);
    let p = (before[0] + before[1] + before[2]) / 3.0;
    assert!(p < -5e4, "the prepared RVE must be compressed, p = {p}");
    let law = DemRve::new(params(&[]), &objects(&rve)).unwrap();
    law.points_added(&[true]).unwrap();
    let mut stress = [[0.0; 6]];
    let mut state = vec![0.0; law.state_names().len()];
    law.update(LawBatch { first: 0, stress: &mut stress, dstrain: &[[0.0; 6]], state: &mut state }).unwrap();
    for a in 0..3 {
        assert!((stress[0][a] - before[a]).abs() < 0.01 * p.abs(), "sigma[{a}]: {} vs {}", stress[0][a], before[a]);
    }
}

/// One 1 m hexahedron, one material point with the RVE law, every node's velocity prescribed as
/// the homogeneous field v = L x: the point sees the strain path of L. Returns the (axial strain,
/// q) curve, the simulation and the strain increments (Voigt) the point received.
type Increments = Vec<[f64; 6]>;
fn coupled_run(
    rve: &DemSim,
    l: [f64; 3],
    dt: f64,
    steps: usize,
    inertial: f64,
) -> (Vec<(f64, f64)>, MpmSim, Increments) {
    let reg = granite::registry();
    let mesh = Mesh::new(3, [0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
    let mut sim = MpmSim::new(mesh, reg.build_velocity_update("PIC", &ParamMap::new()).unwrap());
    let given: ParamMap = [("inertial_number".to_string(), inertial)].into_iter().collect();
    let law = reg.build_law_with("dem_rve", &given, &objects(rve)).unwrap();
    let m = sim.add_material("rve", 1600.0, law).unwrap();
    let volume = rve.world.cell_volume().unwrap();
    sim.add_points(m, &[[0.5; 3]], &[1.0], [0.0; 3], rve.world.love_weber_stress(volume)).unwrap();
    sim.scheme = StressScheme::Usl;
    prescribe_node_velocities(&mut sim, |x| [l[0] * x[0], l[1] * x[1], l[2] * x[2]]);
    sim.set_dt(dt).unwrap();
    let mut curve = Vec::new();
    let mut increments = Vec::new();
    let mut axial = 0.0;
    for _ in 0..steps {
        sim.step().unwrap();
        increments.push(sim.points.dstrain[0]);
        axial -= sim.points.dstrain[0][2];
        let s = sim.points.stress[0];
        curve.push((axial, s[0].max(s[1]) - s[2]));
    }
    (curve, sim, increments)
}

/// Pure DEM under a sequence of strain increments (Voigt, engineering shear), each applied as a
/// velocity gradient over the deformation time of eqs. 4.1 and 4.5, computed here from the sample
/// itself.
fn pure_dem_path(rve: &DemSim, increments: &[[f64; 6]], inertial: f64) -> Vec<(f64, f64)> {
    let mut dem = rve.clone();
    dem.set_sequential(true);
    let s = &dem.world.spheres;
    let mass: f64 = s.mass.iter().sum();
    let rho = mass / dem.world.solid_volume();
    let l = 2.0 * s.radius.iter().sum::<f64>() / s.len() as f64;
    let mut out = Vec::new();
    let mut axial = 0.0;
    for de in increments {
        let strain = granite_core::math::strain_matrix(de);
        let max = nalgebra::SymmetricEigen::new(strain).eigenvalues.amax();
        let cell = dem.world.cell.as_ref().unwrap();
        let st = dem.world.love_weber_stress(cell.volume());
        let bottom = cell.h.column(0).cross(&cell.h.column(1)).norm();
        let p = ((st[0] + st[1] + st[2]) / 3.0).abs().max(mass * 9.81 / bottom);
        let t_eps = max / inertial * (rho * l * l / p).sqrt();
        let n = (t_eps / dem.world.dt).ceil().max(1.0) as usize;
        let t = n as f64 * dem.world.dt;
        dem.world.cell.as_mut().unwrap().velocity_gradient = strain / t;
        for _ in 0..n {
            dem.step().unwrap();
        }
        axial -= de[2];
        let s = dem.world.love_weber_stress(dem.world.cell.as_ref().unwrap().volume());
        out.push((axial, s[0].max(s[1]) - s[2]));
    }
    out
}

#[test]
fn coupled_triaxial_reproduces_pure_dem() {
    let rve = granite::bench::periodic_rve(300, 1e5).unwrap();
    // Isochoric compression along z, 1e-3 per MPM step, to 4 %.
    let rate = 20.0;
    let dt = 5e-5;
    let steps = 40;
    let inertial = 1e-3;
    let (coupled, _, increments) = coupled_run(&rve, [0.5 * rate, 0.5 * rate, -rate], dt, steps, inertial);
    // The MPM applied the intended path (to round-off)...
    for de in &increments {
        let intended = [0.5 * rate * dt, 0.5 * rate * dt, -rate * dt, 0.0, 0.0, 0.0];
        assert!(de.iter().zip(intended).all(|(a, b)| (a - b).abs() < 1e-12), "increment {de:?}");
    }
    // ...and pure DEM follows the very same increments: a granular sample is chaotic, so two runs
    // whose paths differ by round-off drift apart by several percent of q within a few percent of
    // strain, which would hide what this test is after (the coupling adding nothing of its own).
    let reference = pure_dem_path(&rve, &increments, inertial);
    let peak = coupled.iter().map(|c| c.1).fold(f64::NEG_INFINITY, f64::max);
    assert!(peak > 5e4, "the sample should develop a deviatoric stress (peak {peak} Pa)");
    // Both runs take the same DEM steps under the same velocity gradients (eqs. 4.1-4.5), so the
    // whole curve agrees to round-off, far inside the 3 % of the peak up to the peak.
    for (&(e, q), &(e_ref, q_ref)) in coupled.iter().zip(&reference) {
        assert!((e - e_ref).abs() < 1e-12);
        assert!(
            (q - q_ref).abs() <= 1e-9 * peak,
            "at axial strain {e:.4}: coupled q = {q:.0} Pa, pure DEM {q_ref:.0} Pa"
        );
    }
}

#[test]
fn coupled_results_do_not_depend_on_thread_count() {
    let rve = granite::bench::periodic_rve(150, 1e5).unwrap();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let reg = granite::registry();
            let mesh = Mesh::new(3, [0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
            let mut sim = MpmSim::new(mesh, reg.build_velocity_update("PIC", &ParamMap::new()).unwrap());
            let law = reg.build_law_with("dem_rve", &ParamMap::new(), &objects(&rve)).unwrap();
            let m = sim.add_material("rve", 1600.0, law).unwrap();
            let xs = [[0.3, 0.3, 0.3], [0.7, 0.3, 0.4], [0.4, 0.7, 0.6], [0.6, 0.6, 0.7]];
            sim.add_points(m, &xs, &[0.25; 4], [0.0; 3], [0.0; 6]).unwrap();
            prescribe_node_velocities(&mut sim, |x| [10.0 * x[1], -5.0 * x[0], -20.0 * x[2]]);
            sim.set_dt(5e-5).unwrap();
            for _ in 0..10 {
                sim.step().unwrap();
            }
            sim.points.stress.clone()
        })
    };
    assert_eq!(run(1), run(2));
}

#[test]
fn coupled_checkpoint_resumes_bit_for_bit() {
    let rve = granite::bench::periodic_rve(150, 1e5).unwrap();
    let (_, mut sim, _) = coupled_run(&rve, [5.0, 5.0, -10.0], 5e-5, 4, 1e-2);
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/test-out/mpmxdem_checkpoint");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("checkpoint.json");
    sim.save(&path).unwrap();
    let mut resumed = MpmSim::load(&path, &granite::registry()).unwrap();
    for _ in 0..4 {
        sim.step().unwrap();
        resumed.step().unwrap();
    }
    assert_eq!(sim.points.stress, resumed.points.stress);
    assert_eq!(sim.points.x, resumed.points.x);
    assert_eq!(sim.materials[0].state, resumed.materials[0].state);
    assert_eq!(sim.time.to_bits(), resumed.time.to_bits());
}

#[test]
fn an_rve_time_step_above_its_contacts_bound_is_said_once_by_the_coupled_run() {
    // The RVE's own stable_dt counts all of a grain's contacts; a time step a little above it
    // (still far below what the RVE's contacts cannot follow at all) is worth a warning, which
    // the MPM passes on once for all its RVEs.
    let mut rve = granite::bench::periodic_rve(150, 1e5).unwrap();
    let limit = rve.world.stable_dt().expect("a compacted RVE has contacts").dt;
    rve.world.set_dt(1.05 * limit).unwrap();
    let (_, sim, _) = coupled_run(&rve, [0.0, 0.0, -0.01], 1e-4, 3, 1e-2);
    let said: Vec<&String> = sim.events.iter().filter(|e| e.contains("above the stability bound")).collect();
    assert_eq!(said.len(), 1, "said once: {:?}", sim.events);
    assert!(said[0].contains("material \"rve\"") && said[0].contains("RVE of material point 0"), "{}", said[0]);
}
