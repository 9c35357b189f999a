//! A constitutive law written as a script function gives the built-in law's results.

use crate::common;

#[test]
fn script_hooke_matches_linear_elastic() {
    let src = r#"
let e = 1.0e7;
let nu = 0.25;
let lambda = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
let g = e / (2.0 * (1.0 + nu));
fn make(kind, e, nu, lambda, g) {
    let sim = mpm(#{ dim: 2, cell: 0.1, cells: [4, 6] });
    let m = if kind == "builtin" {
        sim.material("linear_elastic", #{ density: 2000.0, young: e, poisson: nu })
    } else {
        // Hooke's law as a script: engineering shear in the strain, plain shear in the stress;
        // `calls` counts the updates in a state variable.
        sim.script_material("hooke", |s, de, st| {
            let tr = de[0] + de[1] + de[2];
            #{ stress: [s[0] + lambda * tr + 2.0 * g * de[0], s[1] + lambda * tr + 2.0 * g * de[1],
                        s[2] + lambda * tr + 2.0 * g * de[2], s[3] + g * de[3], s[4] + g * de[4], s[5] + g * de[5]],
               state: [st[0] + 1.0] }
        }, #{ density: 2000.0, state: ["calls"] })
    };
    sim.fill_box(m, [0.0, 0.0], [0.4, 0.4], #{ per_cell: 2 });
    sim.fix("y-", "y");
    sim.gravity([0.0, -9.81]);
    sim.dt(1e-4);
    sim
}
let a = make("builtin", e, nu, lambda, g);
let b = make("script", e, nu, lambda, g);
a.run_steps(200);
let t0 = timestamp();
b.run_steps(200);
let script_time = t0.elapsed;
let worst = 0.0;
let scale = 0.0;
for i in 0..a.points {
    let sa = a.point_stress(i);
    let sb = b.point_stress(i);
    for c in 0..6 { worst = worst.max(abs(sa[c] - sb[c])); scale = scale.max(abs(sa[c])); }
}
summary("worst_difference", worst);
summary("stress_scale", scale);
summary("calls", b.point_state(0, "calls"));
summary("script_seconds_per_call", script_time / (200.0 * b.points.to_float()));
"#;
    let out = common::run_text("script_law", src);
    let s: serde_json::Value = common::summary_of(&out);
    let worst = s["worst_difference"].as_f64().unwrap();
    let scale = s["stress_scale"].as_f64().unwrap();
    assert!(scale > 100.0, "the block must be loaded by its weight (stress scale {scale})");
    assert!(worst <= 1e-9 * scale, "script and built-in laws differ by {worst} Pa");
    assert_eq!(s["calls"].as_f64().unwrap(), 200.0, "one call per step per point");
}
