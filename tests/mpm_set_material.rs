//! `sim.set_material` between two runs: a column squeezed at a constant rate between fixed walls
//! deforms homogeneously (every node's velocity is prescribed), so its vertical stress grows by
//! exactly the constrained modulus times the strain increment; after the change of Young's
//! modulus it grows with the new modulus from the stress already reached. A change that would
//! break the time-step limit, or touch the density, is refused and leaves the law as it was.

use crate::common;

const E1: f64 = 1e6;
const E2: f64 = 4e6;
const NU: f64 = 0.25;
const H: f64 = 0.1;
const V: f64 = 1e-3;
const STEPS: u64 = 200;

fn constrained_modulus(e: f64) -> f64 {
    e * (1.0 - NU) / ((1.0 + NU) * (1.0 - 2.0 * NU))
}

#[test]
fn a_new_modulus_acts_from_the_change_on() {
    let src = format!(
        r#"
let sim = mpm(#{{ dim: 2, cell: {H:?}, cells: [1, 1] }});
let m = sim.material("linear_elastic", #{{ density: 1000.0, young: {E1:?}, poisson: {NU:?} }});
sim.fill_box(m, [0.0, 0.0], [{H:?}, {H:?}], #{{ per_cell: 2 }});
sim.fix("x-", "x");
sim.fix("x+", "x");
sim.fix("y-", "y");
sim.fix("y+", "y", -{V:?});
sim.dt(0.25 * sim.critical_dt());
sim.run_steps({STEPS});
sim.write_points("first.csv");
sim.set_material(m, #{{ young: {E2:?} }});
sim.run_steps({STEPS});
sim.write_points("second.csv");
summary("dt", sim.dt);
let refused = [];
for change in [#{{ young: {E2:?} * 100.0 }}, #{{ density: 2000.0 }}, #{{ cohesion: 1.0 }}] {{
    try {{ sim.set_material(m, change); }} catch (e) {{ refused.push(`${{e}}`); }}
}}
summary("refused", refused);
sim.run_steps({STEPS});
sim.write_points("third.csv");
"#
    );
    let out = common::run_text("set_material", &src);
    let summary: serde_json::Value = common::summary_of(&out);
    let dt = summary["dt"].as_f64().unwrap();
    let strain_per_run = -V * dt * STEPS as f64 / H;
    let syy = |file: &str| {
        let (h, rows) = common::read_csv(&out.join(file));
        let (s, e) = (common::column(&h, "syy"), common::column(&h, "eyy"));
        for r in &rows {
            assert!((r[e] - rows[0][e]).abs() < 1e-12, "homogeneous strain");
            assert!((r[s] - rows[0][s]).abs() < 1e-9 * r[s].abs(), "homogeneous stress");
        }
        rows[0][s]
    };
    let (m1, m2) = (constrained_modulus(E1), constrained_modulus(E2));
    let first = syy("first.csv");
    let second = syy("second.csv");
    let third = syy("third.csv");
    let expect1 = m1 * strain_per_run;
    assert!((first - expect1).abs() < 1e-9 * expect1.abs(), "before the change: {first} vs {expect1}");
    let expect2 = expect1 + m2 * strain_per_run;
    assert!((second - expect2).abs() < 1e-9 * expect2.abs(), "after the change: {second} vs {expect2}");
    // The refused changes left E2 in place.
    let expect3 = expect2 + m2 * strain_per_run;
    assert!((third - expect3).abs() < 1e-9 * expect3.abs(), "after refused changes: {third} vs {expect3}");

    let refused: Vec<String> =
        summary["refused"].as_array().unwrap().iter().map(|v| v.as_str().unwrap().to_string()).collect();
    assert_eq!(refused.len(), 3, "{refused:?}");
    assert!(refused[0].contains("time step") || refused[0].contains("dt"), "{}", refused[0]);
    assert!(refused[1].contains("density"), "{}", refused[1]);
    assert!(refused[2].contains("cohesion"), "{}", refused[2]);
}
