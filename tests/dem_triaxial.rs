//! The periodic triaxial of thesis 2.9 (`scripts/dem/triaxial_periodic.rhai`): the stress servo
//! holds the confining stress while the sample is sheared, at a low and a usual confining
//! pressure and with grains 20 times stiffer than the script's default.

use crate::common;
use common::*;

/// Shears 1000 spheres to 5 % axial strain at the script's quasi-static inertial number (2e-4)
/// and returns its summary.
fn triaxial(name: &str, confining: &str, young: &str) -> granite_script::RunReport {
    let pairs = [("confining", confining), ("young", young), ("axial_strain", "0.05")];
    run("dem/triaxial_periodic.rhai", name, &pairs, 2).unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn assert_lateral_stress_held(name: &str, report: &granite_script::RunReport) {
    let mean = summary_f64(report, "mean_lateral_stress_error");
    let smoothed = summary_f64(report, "max_lateral_stress_error_2500_steps");
    let single = summary_f64(report, "max_lateral_stress_error");
    // The servo's integral part leaves no steady error (0.01-0.1 % measured over a shear); the
    // mean of 5 samples 500 steps apart stays within 1 % (0.2-0.7 % measured). A single sample
    // can catch a force chain giving way: up to 3.2 % measured, at 5 kPa and with stiff grains.
    assert!(mean.abs() < 2e-3, "{name}: mean lateral stress off by {mean}");
    assert!(smoothed < 0.01, "{name}: lateral stress off by {smoothed} over 2500 steps");
    assert!(single < 0.05, "{name}: lateral stress off by {single} in one sample");
    // And the sample was sheared: a peak stress ratio of a dense packing.
    let ratio = summary_f64(report, "final_q") / summary_f64(report, "final_p");
    assert!(ratio > 0.5, "{name}: q/p = {ratio} at 5 % axial strain");
}

#[test]
fn the_servo_holds_the_confining_stress_at_100_kpa() {
    let report = triaxial("triaxial_100kpa", "1e5", "1e8");
    assert_lateral_stress_held("100 kPa", &report);
}

#[test]
fn the_servo_holds_the_confining_stress_at_5_kpa() {
    let report = triaxial("triaxial_5kpa", "5e3", "1e8");
    assert_lateral_stress_held("5 kPa", &report);
}

#[test]
fn the_servo_holds_the_confining_stress_with_grains_20_times_stiffer() {
    let report = triaxial("triaxial_stiff", "1e5", "2e9");
    assert_lateral_stress_held("E = 2 GPa", &report);
}

/// Capsules of aspect ratio 2 (total length over diameter) against spheres of the same volume,
/// the same law, compaction and shear (150 grains to 10 % axial strain): elongated grains
/// interlock and resist rolling, so their peak friction angle is higher (by several degrees in
/// published simulations of elongated grains). Measured here: 31.9-33.7° for spheres, 43.8-44.2°
/// for capsules over seeds 1 and 2 (docs/dem.md).
#[test]
fn capsules_reach_a_higher_peak_friction_angle_than_spheres() {
    let shear = |kind: &str| {
        let pairs = [("kind", kind), ("count", "150"), ("axial_strain", "0.1"), ("inertial_number", "1e-3")];
        run("dem/triaxial_periodic.rhai", &format!("triaxial_{kind}"), &pairs, 2)
            .unwrap_or_else(|e| panic!("{kind}: {e}"))
    };
    let (spheres, capsules) = (shear("sphere"), shear("capsule"));
    assert_lateral_stress_held("capsules", &capsules);
    let (a, b) = (summary_f64(&spheres, "peak_friction_angle"), summary_f64(&capsules, "peak_friction_angle"));
    assert!(a > 20.0 && a < 40.0, "spheres: peak friction angle {a}°");
    assert!(b > a + 5.0, "capsules: peak friction angle {b}°, spheres {a}°");
    // Elongated grains pack denser (random close packing peaks near aspect ratio 1.5-2).
    let (ea, eb) = (summary_f64(&spheres, "initial_void_ratio"), summary_f64(&capsules, "initial_void_ratio"));
    assert!(eb < ea, "initial void ratio: capsules {eb}, spheres {ea}");
}
