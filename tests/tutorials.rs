//! The tutorials of examples/ run as a user runs them (at a small size) and do what they say.

use crate::common;

fn run(script: &str, name: &str, sets: &[(&str, &str)]) -> granite_script::RunReport {
    let path = common::root().join("examples").join(script);
    granite::run(&path, common::sets(sets), Some(common::out_dir(name)), true, Some(1)).unwrap()
}

/// The elastic block thrown at 2 m/s along a floor with friction 0.3 slides as a rigid block
/// would: `v t - mu g t^2 / 2` (0.341 m in 0.2 s). Friction acts at the floor's nodes and the
/// block is elastic, so a few per cent less (3.3 % measured).
#[test]
fn the_mpm_tutorial_block_slides_as_friction_says() {
    let front = |duration: &str| {
        common::summary_f64(
            &run("tutorial_mpm.rhai", &format!("tutorial_mpm_{duration}"), &[("duration", duration)]),
            "front_position",
        )
    };
    let slid = front("0.2") - front("0.0");
    let rigid = 2.0 * 0.2 - 0.5 * 0.3 * 9.81 * 0.2f64.powi(2);
    assert!((slid / rigid - 1.0).abs() < 0.06, "slid {slid} m, a rigid block {rigid} m");
}

/// The beads come to rest, and the potential energy they lost is in friction, damping and the
/// contacts' springs: the balance holds to 1 % of it.
#[test]
fn the_dem_tutorial_beads_settle_and_keep_the_energy_balance() {
    let report =
        run("tutorial_dem.rhai", "tutorial_dem", &[("count", "200"), ("duration", "0.4"), ("repose_time", "0")]);
    let get = |k: &str| common::summary_f64(&report, k);
    let lost = get("gravitational_energy_lost");
    assert!(lost > 0.0);
    assert!(get("kinetic_energy") < 1e-3 * lost, "at rest: {} J of {lost} J", get("kinetic_energy"));
    let accounted = get("dissipated") + get("elastic_energy") + get("kinetic_energy");
    assert!((accounted / lost - 1.0).abs() < 0.01, "{accounted} J of {lost} J accounted for");
    assert!(get("energy_balance_error") < 0.01 * lost);
    assert!(get("coordination") > 2.0, "a heap in contact: {}", get("coordination"));
}

/// The batch tutorial sweeps the DEM tutorial's heap (its defaults: 500 beads, rolling
/// resistance 0.1) over the beads' friction. At 25 degrees (the tutorial's own run) and 35 the
/// heap comes to rest within its 4 s, as the tutorial says, and the angle is the resting heap's;
/// at 5 and 15 degrees the heap still drains at 4 s (summary column `heap_at_rest`). The slope
/// rises with friction (Zhou et al. 2001, Phys. Rev. E 64: 021301) by more than the measures'
/// standard deviations (eq. 2.11) from 5 to 15 and to 25 degrees (measured: 28.9 +- 1.8,
/// 46.5 +- 1.4, 54.3 +- 2.4, then 48.3 +- 4.4 at 35). Part of the beads flowed out of the box.
#[test]
fn the_batch_tutorial_finds_heaps_steeper_with_more_friction() {
    let out = common::out_dir("tutorial_batch");
    let _ = std::fs::remove_dir_all(&out);
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_granite"))
        .current_dir(common::root())
        .args([
            "batch",
            "examples/tutorial_dem.rhai",
            "--params",
            "examples/tutorial_batch.toml",
            "--jobs",
            "2",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(status.status.success(), "{}", String::from_utf8_lossy(&status.stderr));
    let (h, rows) = common::read_csv(&out.join("batch_summary.csv"));
    let col = |name: &str| common::column(&h, name);
    assert_eq!(rows.len(), 4, "one row a friction");
    // `heap_at_rest` is a word (true or false): read from the file's text.
    let text = std::fs::read_to_string(out.join("batch_summary.csv")).unwrap();
    let words: Vec<Vec<&str>> = text.lines().skip(1).map(|l| l.split(',').collect()).collect();
    let heap = |friction: f64| {
        let k =
            rows.iter().position(|r| r[col("friction")] == friction).unwrap_or_else(|| panic!("no run at {friction}"));
        let row = &rows[k];
        assert!(row[col("exit_code")] == 0.0);
        let kept = row[col("beads_in_heap")];
        assert!(kept > 0.25 * 500.0 && kept < 0.9 * 500.0, "friction {friction}: {kept} of 500 beads in the heap");
        if friction >= 25.0 {
            assert_eq!(words[k][col("heap_at_rest")], "true", "friction {friction}: the heap is not at rest");
        }
        (row[col("angle_of_repose_deg")], row[col("angle_std_deg")])
    };
    let (smooth, smooth_std) = heap(5.0);
    assert!(smooth > 0.0, "a heap, not a flat layer: {smooth} degrees");
    for friction in [15.0, 25.0] {
        let (rough, rough_std) = heap(friction);
        assert!(
            rough - smooth > rough_std + smooth_std,
            "friction {friction}: {rough} +- {rough_std} against {smooth} +- {smooth_std} degrees at 5"
        );
    }
}

/// A triaxial test at constant lateral stress follows the stress path p = sigma_lat + q / 3
/// whatever the grains do; the RVEs' sand carries a deviatoric stress once compressed.
#[test]
fn the_mpmxdem_tutorial_follows_the_triaxial_stress_path() {
    let report = run("tutorial_mpmxdem.rhai", "tutorial_mpmxdem", &[("count", "60"), ("axial_strain", "0.005")]);
    let get = |k: &str| common::summary_f64(&report, k);
    let (q, p, lateral) = (get("q"), get("p"), get("lateral_stress"));
    assert!(q > 0.1 * lateral, "the sand resists: q = {q} Pa");
    // The points' lateral stress trails the traction by the slow compression's inertia: 0.55 %
    // of p measured.
    assert!((p - (lateral + q / 3.0)).abs() < 0.01 * p, "p = {p} Pa, q = {q} Pa");
    // The MPM is the script's second simulation: its files are in sim2/.
    assert!(report.out_dir.join("sim2/rve_point0/end.vtu").is_file());
    assert!(report.out_dir.join("sim2/series.csv").is_file());
}
