//! A velocity prescribed by a piecewise-linear table compresses an elastic column by the integral
//! of the table; the same through a script function of time.

use crate::common;

fn compress(value: &str, name: &str) -> f64 {
    let src = format!(
        r#"
let sim = mpm(#{{ dim: 2, cell: 0.05, cells: [2, 10] }});
let m = sim.material("linear_elastic", #{{ density: 1000.0, young: 1e6, poisson: 0.0 }});
sim.fill_box(m, [0.0, 0.0], [0.1, 0.5], #{{ per_cell: 2 }});
sim.fix("x-", "x");
sim.fix("x+", "x");
sim.fix("y-", "y");
sim.fix("y+", "y", {value});
sim.damping(0.2);
sim.dt(0.2 * sim.critical_dt());
sim.run_until(0.6);
sim.write_points("points.csv");
"#
    );
    let out = common::run_text(name, &src);
    let (h, rows) = common::read_csv(&out.join("points.csv"));
    let eyy = common::column(&h, "eyy");
    rows.iter().map(|r| r[eyy]).sum::<f64>() / rows.len() as f64
}

#[test]
fn table_and_function_velocities_compress_by_their_integral() {
    // v(t) ramps to -0.01 m/s over 0.1 s then holds until 0.5 s, then stops: the top moves by
    // -(0.5 * 0.1 + 0.4) * 0.01 = -4.5 mm over the 0.5 m column.
    let expected = -0.0045 / 0.5;
    let table = compress("[[0.0, 0.0], [0.1, -0.01], [0.5, -0.01], [0.5001, 0.0]]", "table_velocity");
    assert!((table - expected).abs() < 0.02 * expected.abs(), "mean strain {table}, expected {expected}");
    let function = compress("|t| if t < 0.1 { -0.1 * t } else if t < 0.5 { -0.01 } else { 0.0 }", "function_velocity");
    assert!((function - expected).abs() < 0.02 * expected.abs(), "mean strain {function}, expected {expected}");
}
