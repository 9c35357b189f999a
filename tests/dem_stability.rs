#![allow(clippy::needless_range_loop)]
//! The time-step limit of a packing (`stable_dt`) against the integrator's real limit, and a
//! sphere too fast for its time step stopping the run instead of passing through a wall.

use granite_core::dem::cell::PeriodicCell;
use granite_core::dem::{DemSim, Wall, WallShape};
use granite_core::registry::ParamMap;
use granite_core::GraniteError;

use crate::common;

fn params(pairs: &[(&str, f64)]) -> ParamMap {
    pairs.iter().map(|(k, v)| (k.to_string(), *v)).collect()
}

const DENSITY: f64 = 2500.0;
const KN: f64 = 1e4;
/// Radius of every sphere, and how much neighbours overlap, as a fraction of it.
const RADIUS: f64 = 0.01;
const OVERLAP: f64 = 0.01;

/// A simple cubic packing of 4 x 4 x 4 equal spheres of `RADIUS`, overlapping by `OVERLAP` of it,
/// in a periodic cube, with a linear law of tangential stiffness `kt_ratio` k_n and friction
/// angle `friction`; no gravity, no damping. Neighbours along x are given opposite x velocities
/// (the frictionless lattice's fastest mode).
fn lattice_with(kt_ratio: f64, friction: f64) -> DemSim {
    let mut sim = DemSim::new();
    let m = sim.world.add_material("m", DENSITY).unwrap();
    let law = granite::registry()
        .build_contact_law("linear", &params(&[("kn", KN), ("kt_ratio", kt_ratio), ("friction", friction)]))
        .unwrap();
    sim.world.set_contact_law(law, None).unwrap();
    let (n, r) = (4, RADIUS);
    let d = 2.0 * r - OVERLAP * r;
    sim.world.set_cell(Some(PeriodicCell::new_box([n as f64 * d; 3])));
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let v = if i % 2 == 0 { 1e-4 } else { -1e-4 };
                let x = [(i as f64 + 0.5) * d, (j as f64 + 0.5) * d, (k as f64 + 0.5) * d];
                sim.world.add_sphere(m, x, r, [v, 0.0, 0.0]).unwrap();
            }
        }
    }
    sim.skin = 0.1 * r;
    sim.world.set_dt(1e-6).unwrap();
    // One step builds the lists and finds the contacts.
    sim.step().unwrap();
    sim
}

fn lattice(kt_ratio: f64) -> DemSim {
    lattice_with(kt_ratio, 0.0)
}

/// Mass of one sphere of `RADIUS`.
fn sphere_mass() -> f64 {
    DENSITY * 4.0 / 3.0 * std::f64::consts::PI * RADIUS.powi(3)
}

#[test]
fn stable_dt_of_a_cubic_lattice_is_exact_without_friction_and_safe_with_it() {
    // Six contacts per sphere. Frictionless, rotations are free and the fastest mode has
    // neighbours in opposition along an axis: omega^2 = 4 k_n / m, stable up to sqrt(m / k_n),
    // which Gershgorin's bound gives exactly.
    let sim = lattice(0.0);
    let m = sphere_mass();
    let limit = sim.world.stable_dt().expect("a packing in contact has a limit");
    let expected = (m / KN).sqrt();
    assert!((limit.dt / expected - 1.0).abs() < 1e-9, "{} s, expected {expected} s", limit.dt);
    assert_eq!(limit.contacts, 6);
    // With tangential springs two modes are known exactly: the same opposition plus shear,
    // omega^2 = (4 k_n + 8 k_t) / m, and every sphere turning the same way about an axis, each
    // of the four contacts around it sheared by 2 l theta (l = r - overlap/2, I = 2/5 m r^2):
    // omega^2 = 8 k_t l^2 / I. A safe limit lies below both.
    let kt = 0.5 * KN;
    let sim = lattice(0.5);
    let (r, l) = (RADIUS, RADIUS * (1.0 - 0.5 * OVERLAP));
    let shear = 2.0 / ((4.0 * KN + 8.0 * kt) / m).sqrt();
    let turning = 2.0 / (8.0 * kt * l * l / (0.4 * m * r * r)).sqrt();
    let limit = sim.world.stable_dt().unwrap().dt;
    assert!(limit <= shear.min(turning), "{limit} s above an exact mode's limit ({shear} s, {turning} s)");
    // Without contacts there is no limit.
    let mut sim = DemSim::new();
    let m = sim.world.add_material("m", DENSITY).unwrap();
    sim.world.add_sphere(m, [0.0; 3], RADIUS, [0.0; 3]).unwrap();
    assert!(sim.world.stable_dt().is_none());
}

/// The kinetic energy after each of up to `steps` steps at `factor` times the lattice's
/// stable_dt, the error that stopped the run if one did, and the events it gave.
fn run_at(sim: &mut DemSim, factor: f64, steps: usize) -> (Vec<f64>, Option<GraniteError>) {
    let limit = sim.world.stable_dt().unwrap().dt;
    sim.world.set_dt(factor * limit).unwrap();
    let mut energy = Vec::with_capacity(steps);
    for _ in 0..steps {
        if let Err(e) = sim.step() {
            return (energy, Some(e));
        }
        energy.push(sim.world.diagnostics().kinetic_energy);
    }
    (energy, None)
}

fn largest(values: &[f64]) -> f64 {
    values.iter().cloned().fold(0.0, f64::max)
}

#[test]
fn leapfrog_is_stable_just_below_stable_dt_and_blows_up_just_above() {
    // Just below: the fastest mode keeps its amplitude (leapfrog conserves a modified energy),
    // so the second half of the run peaks no higher than the first.
    let mut sim = lattice(0.0);
    let (energy, error) = run_at(&mut sim, 0.98, 3000);
    assert!(error.is_none(), "stable below the limit: {error:?}");
    let (first, second) = (largest(&energy[..1500]), largest(&energy[1500..]));
    assert!(second <= 1.05 * first, "energy grew below the limit: peaks {first:e} J, then {second:e} J");
    assert!(sim.world.events.is_empty(), "no warning below the limit: {:?}", sim.world.events);
    // Just above, with the stop turned off: that mode's amplitude is multiplied by about -1.5
    // each step. Within 40 steps its energy passes a thousand times that of the first three (the
    // contacts, overlapping by 1 % of a radius, stay closed up to amplitudes 2000 times the
    // start's). Once they open the growth slows down; a run that then stops must stop on a
    // sphere too fast for its step.
    let mut sim = lattice(0.0);
    sim.stop_on_unstable_dt = false;
    let (energy, error) = run_at(&mut sim, 1.02, 3000);
    let (start, later) = (largest(&energy[..3]), largest(&energy[..40]));
    assert!(later > 1e3 * start, "no blow-up above the limit: {start:e} J -> {later:e} J");
    if let Some(e) = error {
        assert!(e.to_string().contains("more than half the skin"), "{e}");
    }
    assert!(sim.world.events.iter().any(|e| e.contains("above the stability bound")), "warned: {:?}", sim.world.events);
    // By default the first step proves the mode too fast (omega dt = 2.04) and stops the run.
    let mut sim = lattice(0.0);
    match run_at(&mut sim, 1.02, 3000) {
        (energy, Some(GraniteError::Unstable { reason, .. })) => {
            assert!(energy.is_empty(), "stopped at the first step");
            assert!(reason.contains("above the stability limit") && reason.contains("multiplies"), "{reason}");
        }
        (_, other) => panic!("expected the run to stop: {other:?}"),
    }
}

#[test]
fn a_lattice_with_friction_and_spins_is_stable_just_below_stable_dt() {
    // Tangential springs (friction high enough that no contact slides) couple translations and
    // rotations. Stir both and check that the bound is safe: with no damping, the total energy
    // (kinetic plus elastic) departs from its start only by leapfrog's oscillation about the
    // energy it conserves, of the order of the stirring's energy (0.8 of it here; at 1.2 times
    // the bound the departure reaches 2e8 of it), and that departure does not grow.
    let mut sim = lattice_with(0.5, 80.0);
    for i in 0..sim.world.spheres.len() {
        let u = |k: u64| 2.0 * granite_core::ext::contact::uniform(7, 6 * i as u64 + k) - 1.0;
        sim.world.spheres.v[i] = [1e-4 * u(0), 1e-4 * u(1), 1e-4 * u(2)];
        sim.world.spheres.w[i] = [1e-2 * u(3), 1e-2 * u(4), 1e-2 * u(5)];
    }
    let total = |sim: &DemSim| {
        let d = sim.world.diagnostics();
        d.kinetic_energy + d.elastic_energy
    };
    let limit = sim.world.stable_dt().unwrap().dt;
    sim.world.set_dt(0.98 * limit).unwrap();
    let (start, stirring) = (total(&sim), sim.world.diagnostics().kinetic_energy);
    let mut departure = Vec::with_capacity(3000);
    for _ in 0..3000 {
        sim.step().expect("stable below the bound");
        departure.push((total(&sim) - start).abs());
    }
    let (first, second) = (largest(&departure[..1500]), largest(&departure[1500..]));
    assert!(first < 10.0 * stirring, "the energy departed by {first:e} J, {stirring:e} J stirred in");
    assert!(second <= 1.05 * first, "the departure grew below the bound: {first:e} J, then {second:e} J");
    assert!(sim.world.events.is_empty(), "no warning below the bound: {:?}", sim.world.events);
}

/// Time step of the shot below, and where its wall stands (the sphere starts at the origin).
const SHOT_DT: f64 = 2e-4;
const WALL_X: f64 = 0.06;

/// A sphere of `RADIUS` shot at a wall, at `radii_per_step` radii per step.
fn shot_at_a_wall(radii_per_step: f64) -> (DemSim, Result<(), GraniteError>) {
    let mut sim = DemSim::new();
    let m = sim.world.add_material("m", DENSITY).unwrap();
    let law = granite::registry()
        .build_contact_law("linear", &params(&[("kn", 1e5), ("kt_ratio", 0.3), ("friction", 30.0)]))
        .unwrap();
    sim.world.set_contact_law(law, None).unwrap();
    sim.world.add_wall(Wall::new("wall", WallShape::Plane { normal: [-1.0, 0.0, 0.0] }, [WALL_X, 0.0, 0.0], m));
    sim.world.add_sphere(m, [0.0; 3], RADIUS, [radii_per_step * RADIUS / SHOT_DT, 0.0, 0.0]).unwrap();
    sim.skin = 0.5 * RADIUS;
    sim.world.set_dt(SHOT_DT).unwrap();
    let run = (0..100).try_for_each(|_| sim.step());
    (sim, run)
}

#[test]
fn a_sphere_too_fast_for_its_time_step_stops_the_run_instead_of_passing_through_a_wall() {
    // Half a radius per step: the contact is seen and the sphere comes back, clear of the wall.
    let (sim, run) = shot_at_a_wall(0.5);
    run.expect("a resolved impact runs on");
    assert!(sim.world.spheres.v[0][0] < 0.0 && sim.world.spheres.x[0][0] < WALL_X - RADIUS, "the sphere bounced back");
    // Two radii per step: it would skip over the contact; the first step says so.
    let (sim, run) = shot_at_a_wall(2.0);
    match run {
        Err(GraniteError::Unstable { step, reason, .. }) => {
            assert_eq!(step, 1);
            let speed = format!("{:.4e} m/s", 2.0 * RADIUS / SHOT_DT);
            assert!(
                reason.contains(&speed) && reason.contains(&format!("smallest radius ({RADIUS:.4e} m)")),
                "{reason}"
            );
        }
        other => panic!("expected the run to stop, got {other:?}"),
    }
    assert!(sim.world.spheres.x[0][0] < WALL_X, "it never got past the wall");
}

/// Runs a script given as text with one parameter set, quietly, into its own output folder.
fn run_script(
    name: &str,
    source: &str,
    (param, value): (&str, &str),
) -> granite_core::Result<granite_script::RunReport> {
    let options = granite_script::RunOptions {
        out_dir: common::out_dir(&format!("{name}_{value}")),
        overrides: common::sets(&[(param, value)]),
        quiet: true,
        ..Default::default()
    };
    granite_script::run_source(&format!("{name}.rhai"), source, granite::registry(), options)
}

#[test]
fn a_script_reads_the_limit_of_two_spheres_in_contact() {
    // Two equal spheres pressed together, one spring between them: its normal vibration has
    // omega^2 = 2 k_n / m; its tangential one, sliding and turning both spheres, omega^2 =
    // k_t (2 / m + 2 l^2 / I) with l = r - overlap/2 and I = 2/5 m r^2. Leapfrog is stable up to
    // 2 / omega of the faster. Frictionless, the bound is exactly the normal one; with k_t it
    // must stay below the exact limit. critical_dt is sqrt(m / (2 k_n)).
    let (r, overlap) = (RADIUS, OVERLAP * RADIUS);
    let src = format!(
        "let kt = param(\"kt_ratio\", 0.0, #{{ min: 0.0 }});\n\
         let sim = dem(#{{ seed: 1 }});\n\
         let m = sim.material(#{{ name: \"glass\", density: {DENSITY:?} }});\n\
         sim.contact_law(\"linear\", #{{ kn: {KN:?}, kt_ratio: kt, friction: 30.0 }});\n\
         sim.sphere(m, [0.0, 0.0, 0.0], {r:?}, #{{}});\n\
         sim.sphere(m, [{:?}, 0.0, 0.0], {r:?}, #{{}});\n\
         sim.dt(1e-5);\n\
         sim.run_steps(1);\n\
         summary(\"stable_dt\", sim.stable_dt());\n\
         summary(\"critical_dt\", sim.critical_dt());\n",
        2.0 * r - overlap
    );
    let run = |kt_ratio: &str| {
        let report = run_script("two_sphere_limit", &src, ("kt_ratio", kt_ratio)).unwrap();
        (common::summary_f64(&report, "stable_dt"), common::summary_f64(&report, "critical_dt"))
    };
    let m = sphere_mass();
    let (stable, critical) = run("0.0");
    let expected = 2.0 / (2.0 * KN / m).sqrt();
    assert!((stable / expected - 1.0).abs() < 1e-9, "stable_dt {stable} s, expected {expected} s");
    assert!((critical / (m / (2.0 * KN)).sqrt() - 1.0).abs() < 1e-9, "critical_dt {critical} s");
    let (stable, _) = run("0.3");
    let (kt, l, inertia) = (0.3 * KN, r - 0.5 * overlap, 0.4 * m * r * r);
    let omega2 = (2.0 * KN / m).max(kt * (2.0 / m + 2.0 * l * l / inertia));
    let exact = 2.0 / omega2.sqrt();
    assert!(stable <= exact, "stable_dt {stable} s above the exact limit {exact} s");
}

#[test]
fn a_script_is_stopped_below_critical_dt_when_the_packing_cannot_follow_and_may_go_on_if_it_asks() {
    // A simple cubic lattice with k_t = k_n and no sliding: every sphere turning the same way
    // shears its four contacts around the axis by 2 l theta, omega^2 = 8 k_t l^2 / I, about
    // 20 k_n / m: leapfrog needs dt < 0.45 sqrt(m/k_n), below critical_dt = 0.71 sqrt(m/k_n).
    let src = format!(
        "let stop = param(\"stop\", true);\n\
         let sim = dem(#{{ seed: 1 }});\n\
         let m = sim.material(#{{ name: \"glass\", density: {DENSITY:?} }});\n\
         sim.contact_law(\"linear\", #{{ kn: {KN:?}, kt_ratio: 1.0, friction: 80.0 }});\n\
         let r = {RADIUS:?}; let d = 2.0 * r - {OVERLAP:?} * r;\n\
         sim.periodic([4.0 * d, 4.0 * d, 4.0 * d]);\n\
         for i in 0..4 {{ for j in 0..4 {{ for k in 0..4 {{\n\
             sim.sphere(m, [(i.to_float() + 0.5) * d, (j.to_float() + 0.5) * d, (k.to_float() + 0.5) * d], r, #{{}});\n\
         }} }} }}\n\
         sim.stop_on_unstable_dt(stop);\n\
         sim.dt(0.9 * sim.critical_dt());\n\
         sim.run_steps(10);\n"
    );
    let run_line = src.lines().position(|l| l.contains("run_steps")).unwrap() + 1;
    let run = |stop: &str| run_script("turning_lattice", &src, ("stop", stop));
    let e = run("true").expect_err("the run must stop").to_string();
    let at = format!("line {run_line}");
    assert!(e.contains(&at) && e.contains("above the stability limit of the present contacts"), "{e}");
    run("false").expect("asked to go on, it goes on");
}
