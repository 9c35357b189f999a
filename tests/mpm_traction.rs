//! A traction on the top face of a column is carried down unchanged: sigma_yy = t_y everywhere.

use crate::common;

#[test]
fn top_traction_gives_uniform_vertical_stress() {
    let traction = -2000.0;
    let src = format!(
        r#"
let sim = mpm(#{{ dim: 2, cell: 0.05, cells: [4, 10] }});
let m = sim.material("linear_elastic", #{{ density: 1000.0, young: 1e7, poisson: 0.3 }});
sim.fill_box(m, [0.0, 0.0], [0.2, 0.5], #{{ per_cell: 2 }});
sim.fix("x-", "x");
sim.fix("x+", "x");
sim.fix("y-", "y");
sim.traction("y+", [0.0, {traction}]);
sim.damping(0.3);
sim.dt(0.3 * sim.critical_dt());
sim.run_until(0.3);
sim.write_points("points.csv");
"#
    );
    let out = common::run_text("traction", &src);
    let (h, rows) = common::read_csv(&out.join("points.csv"));
    let (syy, sxx) = (common::column(&h, "syy"), common::column(&h, "sxx"));
    // Oedometric: lateral strain is zero, so sigma_xx = nu/(1-nu) sigma_yy.
    let k0 = 0.3 / 0.7;
    for r in &rows {
        assert!((r[syy] - traction).abs() < 0.02 * traction.abs(), "sigma_yy = {}", r[syy]);
        assert!((r[sxx] - k0 * traction).abs() < 0.02 * traction.abs(), "sigma_xx = {}", r[sxx]);
    }
}
