//! The DEM energy tracker (`sim.track_energy`): kinetic, gravitational and elastic energy, the
//! losses to friction, to the dashpots and to Cundall damping, and the work of moving walls add up
//! to a constant.

use granite_script::{run_source, RunOptions};

use crate::common;

/// 120 spheres dropped into a box under `law` and Cundall `damping`, then squeezed by a side wall
/// moving in at 5 cm/s, the energy tracked throughout; `series` rows every that many steps.
fn squeezed_deposition(name: &str, law: &str, damping: f64, series: u64) -> granite_script::RunReport {
    let source = format!(
        r#"
let r = 0.01; let rho = 2600.0;
let sim = dem(#{{ seed: 3, skin: 0.5 * r }});
let glass = sim.material(#{{ name: "glass", density: rho }});
sim.contact_law({law});
let walls = sim.box_walls(glass, [0.0, 0.0, 0.0], [0.1, 0.1, 0.3], #{{ open_top: true }});
sim.lattice(glass, [0.0, 0.0, 0.0], [0.1, 0.1, 0.12], #{{ spacing: 2.2 * r, radius: r, jitter: 0.1 * r }});
sim.gravity([0.0, 0.0, -9.81]);
sim.damping({damping:?});
sim.dt(0.1 * r * sqrt(rho / 1.0e7));
sim.series_every({series});
sim.track_energy(true);
sim.run_steps(15000);
sim.wall_velocity(walls[1], [-0.05, 0.0, 0.0]);
sim.run_steps(10000);
let e = sim.energy();
for k in e.keys() {{ summary(k, e[k]); }}
"#
    );
    let options = RunOptions { out_dir: common::out_dir(name), quiet: true, ..Default::default() };
    run_source("energy.rhai", &source, granite::registry(), options).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// 120 spheres dropped into a box (visco-elastic contacts with restitution 0.5, friction 30
/// degrees, Cundall damping 0.2), then squeezed by a side wall moving in at 5 cm/s. Each loss and
/// the wall's work are a sizeable share of the initial energy, and the balance holds to 1e-3 of
/// it. (Leapfrog's balance error is of order (omega dt)^2: at this time step, 0.1 r sqrt(rho/E),
/// the run ends 6e-5 off; at 0.3 r sqrt(rho/E), 5e-4.)
#[test]
fn a_damped_frictional_deposition_keeps_its_energy_balance() {
    let law = r#""visco_elastic", #{ young: 1.0e7, kt_ratio: 0.3, friction: 30.0, restitution: 0.5 }"#;
    let report = squeezed_deposition("dem_energy", law, 0.2, 1000);
    let get = |k: &str| common::summary_f64(&report, k);
    let initial = get("initial_total");
    for term in ["friction", "viscous", "damping", "boundary_work"] {
        assert!(get(term) > 0.02 * initial, "{term} = {} of {initial} J", get(term));
    }
    let drift = (get("total") - initial).abs();
    assert!(drift < 1e-3 * initial, "balance off by {drift} J of {initial} J");
    // The series has the balance's columns (empty before the first tracked step).
    let (h, rows) = common::read_csv(&report.out_dir.join("series.csv"));
    let total = common::column(&h, "energy_total");
    assert!(rows[0][total].is_nan() && rows.len() > 20);
    assert!(rows[1..].iter().all(|row| (row[total] - initial).abs() < 1e-3 * initial));
}

/// The Camargue-sand law (`rolling_resistance`, thesis table 5.2) with a low rolling limit, little
/// damping and the squeezing wall: its rolling and twisting springs slip as much as its sliding
/// ones (leaving them out of the losses puts the balance 26 % off), and the balance holds to 1e-3.
#[test]
fn rolling_and_twisting_losses_close_the_balance() {
    let law = r#""rolling_resistance", #{ young: 1.0e7, alpha_s: 0.3, alpha_r: 0.5, alpha_t: 0.5, friction: 30.0, eta_r: 0.05 }"#;
    let report = squeezed_deposition("dem_energy_rolling", law, 0.05, 1000000);
    let get = |k: &str| common::summary_f64(&report, k);
    let initial = get("initial_total");
    assert!(get("friction") > 0.2 * initial && get("boundary_work") > 0.2 * initial);
    let drift = (get("total") - initial).abs();
    assert!(drift < 1e-3 * initial, "balance off by {drift} J of {initial} J");
}

/// Tetrahedral clumps (thesis table 2.3's shape, smaller) falling into a box: translation and
/// Euler's equations for the rotation; the balance holds to 1e-3 while friction, dashpots and
/// damping take most of the energy the fall releases.
#[test]
fn clumps_keep_the_energy_balance() {
    let source = r#"
let rho = 2600.0;
let sim = dem(#{ seed: 3, skin: 0.005 });
let glass = sim.material(#{ name: "glass", density: rho });
sim.contact_law("visco_elastic", #{ young: 1.0e7, kt_ratio: 0.3, friction: 30.0, restitution: 0.5 });
sim.box_walls(glass, [0.0, 0.0, 0.0], [0.12, 0.12, 0.4], #{ open_top: true });
sim.clump_cloud(glass, [0.0, 0.0, 0.0], [0.12, 0.12, 0.3], #{ count: 60, shape: "tetra", r_sphere: 0.006, r_clump: 0.01, seed: 2 });
sim.gravity([0.0, 0.0, -9.81]);
sim.damping(0.2);
sim.dt(0.1 * 0.006 * sqrt(rho / 1.0e7));
sim.series_every(1000000);
sim.track_energy(true);
sim.run_steps(30000);
let e = sim.energy();
for k in e.keys() { summary(k, e[k]); }
summary("clumps", sim.clumps);
"#;
    let options = RunOptions { out_dir: common::out_dir("dem_energy_clumps"), quiet: true, ..Default::default() };
    let report = run_source("energy.rhai", source, granite::registry(), options).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(common::summary_f64(&report, "clumps"), 60.0);
    losses_take_most_and_the_balance_holds(&report);
}

/// Grains of a body kind and spheres (`shape` and its parameters for `clump_cloud`) falling
/// into a box of plane walls, damped and frictional, the energy tracked: the energies and losses,
/// the summary's entries.
fn bodies_and_spheres_falling(name: &str, grains: &str, sphere_radius: f64, steps: u64) -> granite_script::RunReport {
    let source = format!(
        r#"
let rho = 2600.0;
let sim = dem(#{{ seed: 3, skin: 0.003 }});
let glass = sim.material(#{{ name: "glass", density: rho }});
sim.contact_law("visco_elastic", #{{ young: 1.0e7, kt_ratio: 0.3, friction: 30.0, restitution: 0.5 }});
sim.box_walls(glass, [0.0, 0.0, 0.0], [0.1, 0.1, 0.4], #{{ open_top: true }});
sim.clump_cloud(glass, [0.0, 0.0, 0.0], [0.1, 0.1, 0.15], #{{ count: 30, seed: 2, {grains} }});
sim.cloud(glass, [0.0, 0.0, 0.15], [0.1, 0.1, 0.3], #{{ count: 40, radius: {sphere_radius:?} }});
sim.gravity([0.0, 0.0, -9.81]);
sim.damping(0.2);
sim.dt(0.1 * {sphere_radius:?} * sqrt(rho / 1.0e7));
sim.series_every(1000000);
sim.track_energy(true);
sim.run_steps({steps});
let e = sim.energy();
for k in e.keys() {{ summary(k, e[k]); }}
summary("bodies", sim.bodies);
"#
    );
    let options = RunOptions { out_dir: common::out_dir(name), quiet: true, ..Default::default() };
    run_source("energy.rhai", &source, granite::registry(), options).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Friction, dashpots and damping took more than half the energy a fall released, and the
/// balance holds to 1e-3 of the initial energy.
fn losses_take_most_and_the_balance_holds(report: &granite_script::RunReport) {
    let get = |k: &str| common::summary_f64(report, k);
    let initial = get("initial_total");
    let released = initial - get("gravitational");
    let lost = get("friction") + get("viscous") + get("damping");
    assert!(lost > 0.5 * released, "lost {lost} J of {released} J released");
    let drift = (get("total") - initial).abs();
    assert!(drift < 1e-3 * initial, "balance off by {drift} J of {initial} J");
}

/// Capsules and spheres falling into a box: the balance holds to 1e-3 while friction, dashpots
/// and damping take most of the energy the fall releases.
#[test]
fn capsules_and_spheres_keep_the_energy_balance() {
    let report = bodies_and_spheres_falling(
        "dem_energy_capsules",
        r#"shape: "capsule", radius: 0.005, length: 0.012"#,
        0.005,
        25000,
    );
    assert_eq!(common::summary_f64(&report, "bodies"), 30.0);
    losses_take_most_and_the_balance_holds(&report);
}

/// Rounded tetrahedra (potential particles, thesis table 2.2's shape) and spheres falling into a
/// box: the balance holds to 1e-3 while the losses take most of the energy the fall releases.
/// (Boon et al.'s contact geometry is not exactly conservative, tests/potential_particles.rs,
/// but its share here is far below that.)
#[test]
fn potential_particles_and_spheres_keep_the_energy_balance() {
    let report = bodies_and_spheres_falling("dem_energy_potentials", r#"shape: "potential_tetra""#, 0.004, 60000);
    assert_eq!(common::summary_f64(&report, "bodies"), 30.0);
    losses_take_most_and_the_balance_holds(&report);
}

/// A fixed capsule (a container part moved at its own velocity) pushed down into settled spheres:
/// the work it does on them is boundary work, many times the energy they had, and the balance
/// holds to 1e-3 of all the energy that went through (measured: 1.4e-4 of it).
#[test]
fn a_driven_fixed_body_books_its_work() {
    let source = r#"
let r = 0.01; let rho = 2600.0;
let sim = dem(#{ seed: 3, skin: 0.5 * r });
let glass = sim.material(#{ name: "glass", density: rho });
sim.contact_law("visco_elastic", #{ young: 1.0e7, kt_ratio: 0.3, friction: 30.0, restitution: 0.5 });
sim.box_walls(glass, [0.0, 0.0, 0.0], [0.1, 0.1, 0.3], #{ open_top: true });
sim.lattice(glass, [0.0, 0.0, 0.0], [0.1, 0.1, 0.06], #{ spacing: 2.2 * r, radius: r, jitter: 0.1 * r });
let blade = sim.capsule(glass, [0.05, 0.05, 0.07], #{ radius: 0.008, length: 0.07, axis: [1.0, 0.0, 0.0], fixed: true });
sim.gravity([0.0, 0.0, -9.81]);
sim.damping(0.2);
sim.dt(0.1 * r * sqrt(rho / 1.0e7));
sim.series_every(1000000);
sim.track_energy(true);
sim.run_steps(10000);
sim.body_velocity(blade, [0.0, 0.0, -0.2]);
sim.run_steps(12000);
let e = sim.energy();
for k in e.keys() { summary(k, e[k]); }
summary("blade_z", sim.body_state(blade).position[2]);
"#;
    let options = RunOptions { out_dir: common::out_dir("dem_energy_blade"), quiet: true, ..Default::default() };
    let report = run_source("energy.rhai", source, granite::registry(), options).unwrap_or_else(|e| panic!("{e}"));
    let get = |k: &str| common::summary_f64(&report, k);
    let initial = get("initial_total");
    assert!(get("blade_z") < 0.035, "the blade went down into the spheres: at {} m", get("blade_z"));
    let work = get("boundary_work");
    assert!(work > initial, "boundary work {work} J, initial energy {initial} J");
    let drift = (get("total") - initial).abs();
    assert!(drift < 1e-3 * (initial + work), "balance off by {drift} J of {initial} J and {work} J of work");
}

/// Periodic cells are refused by name.
#[test]
fn energy_tracking_says_what_it_does_not_cover() {
    let source = r#"
let sim = dem();
let m = sim.material(#{ density: 1000.0 });
sim.contact_law("linear", #{ kn: 1e4 });
sim.periodic([1.0, 1.0, 1.0]);
sim.track_energy(true);
"#;
    let options = RunOptions { out_dir: common::out_dir("dem_energy_refused"), quiet: true, ..Default::default() };
    let e = run_source("energy.rhai", source, granite::registry(), options).unwrap_err().to_string();
    assert!(e.contains("periodic cells"), "{e}");
}
