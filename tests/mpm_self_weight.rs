//! A linear-elastic column at rest under gravity carries sigma_yy = -rho g depth.

use crate::common;
use common::*;

#[test]
fn settled_column_stress_matches_overburden() {
    check_overburden(&run("mpm/self_weight_column.rhai", "self_weight", &[], 2).unwrap());
}

/// The same with the volumetric strain of each cell's centre (B-bar): the points of a cell share
/// its volumetric strain, and the column carries its weight as before.
#[test]
fn settled_column_with_cell_volumetric_strain_matches_overburden() {
    let sets = [("volumetric_strain", "cell")];
    check_overburden(&run("mpm/self_weight_column.rhai", "self_weight_bbar", &sets, 2).unwrap());
}

fn check_overburden(report: &granite_script::RunReport) {
    assert!(summary_f64(report, "final_kinetic_energy") < 1e-6, "the column has not settled");
    let (rho, height, cell) =
        (summary_f64(report, "density"), summary_f64(report, "height"), summary_f64(report, "cell_size"));
    let g = 9.81;
    let (h, rows) = read_csv(&report.out_dir.join("points.csv"));
    let (y, syy) = (column(&h, "y"), column(&h, "syy"));
    // Linear shape functions make the stress uniform in a cell, equal to the overburden at the
    // cell's centroid (thesis 5.3.2): compare cell averages, away from the top cell.
    let mut cells: std::collections::BTreeMap<i64, (f64, f64, usize)> = Default::default();
    for r in &rows {
        let e = cells.entry((r[y] / cell).floor() as i64).or_default();
        e.0 += r[y];
        e.1 += r[syy];
        e.2 += 1;
    }
    let top_cell = ((height / cell).round() as i64) - 1;
    let mut checked = 0;
    for (&c, &(ys, ss, n)) in &cells {
        if c >= top_cell {
            continue;
        }
        let (y_mean, s_mean) = (ys / n as f64, ss / n as f64);
        let expected = -rho * g * (height - y_mean);
        let err = (s_mean - expected).abs() / expected.abs();
        assert!(err < 0.03, "cell {c} (y = {y_mean:.3}): sigma_yy = {s_mean:.1} Pa, expected {expected:.1} Pa");
        checked += 1;
    }
    assert!(checked >= 10, "too few cells checked: {checked}");
}

/// A soft, nearly incompressible column standing free on its base (E = 1 MPa, ν = 0.49, its own
/// weight, light Cundall damping) with the volumetric strain of the cells' centres comes to rest:
/// the internal force is the work of the stress on the B-bar strain rate. With the force taken
/// from each point's own gradient while its strain took the centre's volumetric rate, the same
/// column gained energy, flung its points out of the mesh and never settled.
#[test]
fn a_free_standing_nearly_incompressible_column_with_cell_volumetric_strain_comes_to_rest() {
    let source = r#"
        let sim = mpm(#{ dim: 2, origin: [-0.2, 0.0], cell: 0.05, cells: [12, 24] });
        let soil = sim.material("linear_elastic", #{ name: "soil", density: 2000.0, young: 1e6, poisson: 0.49 });
        sim.fill_box(soil, [0.0, 0.0], [0.2, 1.0], #{ per_cell: 2 });
        sim.fix("y-", "x"); sim.fix("y-", "y");
        sim.gravity([0.0, -9.81]);
        sim.volumetric_strain("cell");
        sim.damping(0.05);
        sim.dt(0.2 * sim.critical_dt());
        sim.run_until(4.0);
        let d = sim.diagnostics();
        summary("kinetic", d.kinetic_energy);
        summary("elastic", d.elastic_energy);
        summary("points", d.points);
        summary("top", d.max_height);
    "#;
    let out = common::run_text("bbar_free_column", source);
    let s: serde_json::Value = common::summary_of(&out);
    let (kinetic, elastic) = (s["kinetic"].as_f64().unwrap(), s["elastic"].as_f64().unwrap());
    assert_eq!(s["points"], 320, "no point lost: {s}");
    assert!(kinetic < 1e-4 * elastic, "at rest: kinetic {kinetic} J against elastic {elastic} J");
    // Its own weight shortens it by about rho g H^2 / (2 E') ~ 1 cm (E' between E and the
    // constrained modulus): it stands, neither collapsed nor thrown up.
    let top = s["top"].as_f64().unwrap();
    assert!(top > 0.95 && top < 1.0, "the column's top at {top} m");
}
