//! The angle-of-repose scene of thesis 2.2 end to end, both set-ups at their small defaults.
//! The thesis's clump model gives 35.95 ± 0.88° (PP-CLP series), the same within about 1 % in
//! both set-ups with its measuring method (2.4.2). Small heaps scatter more: the 300-clump
//! plane-strain heap gives 42.3°, 35.6° and 29.7° for seeds 1 to 3, so its test takes their
//! mean; the 800-clump cylinder scatters less. Hence ±5° on one cylinder run and on the mean of
//! three plane-strain runs.
//! Long (about 2.5 and 1.5 min on two cores): `cargo test --release --test integration dem_repose_scripts:: -- --ignored`.

use crate::common;

const THESIS_CLUMP_AOR_DEG: f64 = 35.95;
const SMALL_HEAP_TOLERANCE_DEG: f64 = 5.0;

/// Angle of repose of one run, checking that grains left the device when it opened.
fn heap(setup: &str, seed: &str) -> f64 {
    let name = format!("repose_{setup}_{seed}");
    let report = common::run("dem/angle_of_repose.rhai", &name, &[("setup", setup), ("seed", seed)], 2)
        .unwrap_or_else(|e| panic!("{setup}: {e}"));
    let lost = common::summary_f64(&report, "lost_particles");
    assert!(lost > 0.0, "{setup}: grains leave the device when it opens");
    common::summary_f64(&report, "angle_of_repose_deg")
}

fn assert_near_thesis(setup: &str, angle: f64) {
    assert!(
        (angle - THESIS_CLUMP_AOR_DEG).abs() < SMALL_HEAP_TOLERANCE_DEG,
        "{setup}: angle of repose {angle}°, thesis {THESIS_CLUMP_AOR_DEG}°"
    );
}

#[test]
#[ignore]
fn plane_strain_heap() {
    let angles: Vec<f64> = ["1", "2", "3"].iter().map(|seed| heap("plane_strain", seed)).collect();
    assert_near_thesis("plane_strain (mean of seeds 1-3)", angles.iter().sum::<f64>() / angles.len() as f64);
}

#[test]
#[ignore]
fn axisymmetric_heap() {
    assert_near_thesis("axisymmetric", heap("axisymmetric", "1"));
}
