#![allow(clippy::needless_range_loop)]
//! The time-step limit of a packing (`stable_dt`) against the integrator's real limit, and a
//! sphere too fast for its time step stopping the run instead of passing through a wall.

use granite_core::dem::cell::PeriodicCell;
use granite_core::dem::{DemSim, Wall, WallShape};
use granite_core::registry::ParamMap;
use granite_core::GraniteError;

mod common;

fn params(pairs: &[(&str, f64)]) -> ParamMap {
    pairs.iter().map(|(k, v)| (k.to_string(), *v)).collect()
}

const DENSITY: f64 = 2500.0;
const KN: f64 = 1e4;

/// A simple cubic packing of 4 x 4 x 4 equal spheres of radius `r`, overlapping by 1 % of `r`,
/// in a periodic cube, with a frictionless linear law of tangential stiffness `kt_ratio` k_n; no
/// gravity, no damping. Neighbours along x are given opposite x velocities (the lattice's
/// fastest mode).
fn lattice(kt_ratio: f64) -> DemSim {
    let mut sim = DemSim::new();
    let m = sim.add_material("m", DENSITY).unwrap();
    let law = granite::registry()
        .build_contact_law("linear", &params(&[("kn", KN), ("kt_ratio", kt_ratio), ("friction", 0.0)]))
        .unwrap();
    sim.set_contact_law(law, None).unwrap();
    let (n, r) = (4, 0.01);
    let d = 2.0 * r - 0.01 * r;
    sim.set_cell(Some(PeriodicCell::new_box([n as f64 * d; 3])));
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let v = if i % 2 == 0 { 1e-4 } else { -1e-4 };
                let x = [(i as f64 + 0.5) * d, (j as f64 + 0.5) * d, (k as f64 + 0.5) * d];
                sim.add_sphere(m, x, r, [v, 0.0, 0.0]).unwrap();
            }
        }
    }
    sim.skin = 0.1 * r;
    sim.set_dt(1e-6).unwrap();
    // One step builds the lists and finds the contacts.
    sim.step().unwrap();
    sim
}

fn sphere_mass(sim: &DemSim) -> f64 {
    DENSITY * 4.0 / 3.0 * std::f64::consts::PI * sim.spheres.radius[0].powi(3)
}

#[test]
fn stable_dt_of_a_cubic_lattice_is_its_fastest_modes_limit() {
    // Six contacts per sphere. The x rows: two normal springs along x and, from the four
    // contacts across, tangential ones; the fastest mode (neighbours in opposition) has
    // omega^2 = (4 k_n + 8 k_t) / m, so leapfrog is stable up to 2 / omega = sqrt(m / (k_n + 2 k_t)).
    for kt_ratio in [0.0, 0.5] {
        let sim = lattice(kt_ratio);
        let m = sphere_mass(&sim);
        let expected = (m / (KN + 2.0 * kt_ratio * KN)).sqrt();
        let limit = sim.stable_dt().expect("a packing in contact has a limit");
        assert!((limit.dt / expected - 1.0).abs() < 1e-9, "kt/kn {kt_ratio}: {} s, expected {expected} s", limit.dt);
        assert_eq!(limit.contacts, 6);
    }
    // Without contacts there is no limit.
    let mut sim = DemSim::new();
    let m = sim.add_material("m", DENSITY).unwrap();
    sim.add_sphere(m, [0.0; 3], 0.01, [0.0; 3]).unwrap();
    assert!(sim.stable_dt().is_none());
}

/// The kinetic energy after each of up to `steps` steps at `factor` times the lattice's
/// stable_dt, the error that stopped the run if one did, and the events it gave.
fn run_at(factor: f64, steps: usize) -> (Vec<f64>, Option<GraniteError>, Vec<String>) {
    let mut sim = lattice(0.0);
    let limit = sim.stable_dt().unwrap().dt;
    sim.set_dt(factor * limit).unwrap();
    let mut energy = Vec::with_capacity(steps);
    for _ in 0..steps {
        if let Err(e) = sim.step() {
            return (energy, Some(e), sim.events.clone());
        }
        energy.push(sim.diagnostics().kinetic_energy);
    }
    (energy, None, sim.events.clone())
}

fn largest(values: &[f64]) -> f64 {
    values.iter().cloned().fold(0.0, f64::max)
}

#[test]
fn leapfrog_is_stable_just_below_stable_dt_and_blows_up_just_above() {
    // Just below: the fastest mode keeps its amplitude (leapfrog conserves a modified energy),
    // so the second half of the run peaks no higher than the first.
    let (energy, error, events) = run_at(0.98, 3000);
    assert!(error.is_none(), "stable below the limit: {error:?}");
    let (first, second) = (largest(&energy[..1500]), largest(&energy[1500..]));
    assert!(second <= 1.05 * first, "energy grew below the limit: peaks {first:e} J, then {second:e} J");
    assert!(events.is_empty(), "no warning below the limit: {events:?}");
    // Just above: that mode's amplitude is multiplied by about -1.5 each step. Within 40 steps
    // its energy passes a thousand times that of the first three (the contacts, overlapping by
    // 1 % of a radius, stay closed up to amplitudes 2000 times the start's). Once they open, the
    // growth slows down; a run that then stops must stop on a sphere too fast for its step.
    let (energy, error, events) = run_at(1.02, 3000);
    let (start, later) = (largest(&energy[..3]), largest(&energy[..40]));
    assert!(later > 1e3 * start, "no blow-up above the limit: {start:e} J -> {later:e} J");
    if let Some(e) = error {
        assert!(e.to_string().contains("more than the smallest radius"), "{e}");
    }
    assert!(
        events.iter().any(|e| e.contains("above the stability limit")),
        "the time step above the limit is reported: {events:?}"
    );
}

/// A sphere of radius 1 cm shot at a wall 5 cm away, at `radii_per_step` radii per step.
fn shot_at_a_wall(radii_per_step: f64) -> (DemSim, Result<(), GraniteError>) {
    let mut sim = DemSim::new();
    let m = sim.add_material("m", DENSITY).unwrap();
    let law = granite::registry()
        .build_contact_law("linear", &params(&[("kn", 1e5), ("kt_ratio", 0.3), ("friction", 30.0)]))
        .unwrap();
    sim.set_contact_law(law, None).unwrap();
    let (r, dt) = (0.01, 2e-4);
    sim.add_wall(Wall::new("wall", WallShape::Plane { normal: [-1.0, 0.0, 0.0] }, [0.06, 0.0, 0.0], m));
    sim.add_sphere(m, [0.0; 3], r, [radii_per_step * r / dt, 0.0, 0.0]).unwrap();
    sim.skin = 0.5 * r;
    sim.set_dt(dt).unwrap();
    let run = (0..100).try_for_each(|_| sim.step());
    (sim, run)
}

#[test]
fn a_sphere_too_fast_for_its_time_step_stops_the_run_instead_of_passing_through_a_wall() {
    // Half a radius per step: the contact is seen and the sphere comes back.
    let (sim, run) = shot_at_a_wall(0.5);
    run.expect("a resolved impact runs on");
    assert!(sim.spheres.v[0][0] < 0.0 && sim.spheres.x[0][0] < 0.05, "the sphere bounced back");
    // Two radii per step: it would skip over the contact; the first step says so.
    let (sim, run) = shot_at_a_wall(2.0);
    match run {
        Err(GraniteError::Unstable { step, reason, .. }) => {
            assert_eq!(step, 1);
            assert!(reason.contains("1.0000e2 m/s") && reason.contains("smallest radius 1.0000e-2 m"), "{reason}");
        }
        other => panic!("expected the run to stop, got {other:?}"),
    }
    assert!(sim.spheres.x[0][0] < 0.06, "it never got past the wall");
}

#[test]
fn a_script_reads_the_limit_of_two_spheres_in_contact() {
    // Two equal spheres pressed together: omega^2 = k_n / (m / 2), so leapfrog is stable up to
    // 2 / omega = sqrt(2 m / k_n), which the bound gives exactly; critical_dt is sqrt(m / (2 k_n)).
    let src = "let sim = dem(#{ seed: 1 });\n\
               let m = sim.material(#{ name: \"glass\", density: 2500.0 });\n\
               sim.contact_law(\"linear\", #{ kn: 1e4, kt_ratio: 0.3, friction: 30.0 });\n\
               sim.sphere(m, [0.0, 0.0, 0.0], 0.01, #{});\n\
               sim.sphere(m, [0.0199, 0.0, 0.0], 0.01, #{});\n\
               sim.dt(1e-5);\n\
               sim.run_steps(1);\n\
               summary(\"stable_dt\", sim.stable_dt());\n\
               summary(\"critical_dt\", sim.critical_dt());\n";
    let options = granite_core::script::RunOptions {
        out_dir: common::out_dir("two_sphere_limit"),
        quiet: true,
        ..Default::default()
    };
    let report = granite_core::script::run_source("two_sphere_limit.rhai", src, granite::registry(), options).unwrap();
    let m = DENSITY * 4.0 / 3.0 * std::f64::consts::PI * 0.01f64.powi(3);
    let expected = (2.0 * m / KN).sqrt();
    let (stable, critical) = (common::summary_f64(&report, "stable_dt"), common::summary_f64(&report, "critical_dt"));
    assert!((stable / expected - 1.0).abs() < 1e-9, "stable_dt {stable} s, expected {expected} s");
    assert!((critical / (m / (2.0 * KN)).sqrt() - 1.0).abs() < 1e-9, "critical_dt {critical} s");
}
