//! Thesis 5.2: a small column collapse runs both phases and dissipates energy as it spreads.

use crate::common;
use common::*;

#[test]
fn small_column_collapses_and_dissipates_energy() {
    let report = run(
        "mpm/column_collapse.rhai",
        "column_collapse_small",
        &[("a_tau", "0.05"), ("settle_time", "0.5"), ("collapse_time", "1.0")],
        2,
    )
    .unwrap();
    let runout = summary_f64(&report, "final_normalised_runout");
    assert!(runout > 0.3, "the column should spread (L~ = {runout})");
    assert_eq!(summary_f64(&report, "deleted_points"), 0.0);
    let (h, rows) = read_csv(&report.out_dir.join("series_runout.csv"));
    let (e, lx, pts) = (column(&h, "total_energy"), column(&h, "lx"), column(&h, "points"));
    let e0 = rows[0][e];
    // No source of energy during the collapse: floor friction and plasticity only dissipate.
    let e_max = rows.iter().map(|r| r[e]).fold(f64::NEG_INFINITY, f64::max);
    assert!(e_max <= e0 + 0.01 * e0.abs(), "mechanical energy grew from {e0} to {e_max}");
    assert!(rows.last().unwrap()[e] < e0 - 0.05 * e0.abs(), "too little dissipation");
    // The voxelised width only grows in whole cells (eq. 5.6) and never shrinks below the start.
    assert!(rows.iter().all(|r| r[lx] >= rows[0][lx] - 1e-12));
    assert!(rows.iter().all(|r| r[pts] == rows[0][pts]), "material points were lost");
}
