//! The MPMxDEM scripts end to end at a tiny size: prepare an RVE, run the one-cell triaxial.

mod common;
use common::*;

#[test]
fn prepare_and_run_the_one_cell_triaxial() {
    let prep = run("mpmxdem/prepare_rve.rhai", "mpmxdem_prepare", &[("count", "150")], 2).unwrap();
    let e0 = summary_f64(&prep, "void_ratio");
    assert!(e0 > 0.4 && e0 < 0.8, "a dense RVE of spheres: e0 = {e0}");
    let p = summary_f64(&prep, "mean_stress");
    assert!((p + 1e5).abs() < 0.02e5, "prepared at 100 kPa, got {p}");
    let rve = prep.out_dir.join("rve.json");
    let tri = run(
        "mpmxdem/triaxial_one_cell.rhai",
        "mpmxdem_triaxial",
        &[("rve", rve.to_str().unwrap()), ("axial_strain", "0.002"), ("dt", "1e-3"), ("dump_every", "500")],
        2,
    )
    .unwrap();
    let (h, rows) = read_csv(&tri.out_dir.join("series.csv"));
    let (q, axial, p_col) = (column(&h, "q"), column(&h, "axial_strain"), column(&h, "p"));
    // The points start at the RVE's stress as it was saved: a loaded sample reports its contact
    // forces before any step.
    let p0 = rows[0][p_col];
    assert!((p0 + p).abs() < 1e-9 * p.abs(), "step 0: p = {p0} for an RVE saved at {}", -p);
    let last = rows.last().unwrap();
    assert!(last[axial] > 0.0019, "axial strain reached {}", last[axial]);
    // Compression at constant lateral stress: q grows and p = sigma_lat + q / 3.
    assert!(last[q] > 1e4, "q = {}", last[q]);
    assert!((last[p_col] - (1e5 + last[q] / 3.0)).abs() < 0.05 * last[p_col], "p = {}, q = {}", last[p_col], last[q]);
    for k in 0..8 {
        column(&h, &format!("q_{k}"));
    }
    let dumps = std::fs::read_dir(tri.out_dir.join("rve_point0")).unwrap().count();
    assert!(dumps >= 1, "RVE particle dumps of point 0");
}
