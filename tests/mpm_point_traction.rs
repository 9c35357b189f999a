//! Loads carried by material points (`sim.point_traction`, `sim.point_pressure`): the points under
//! a surface carry a traction that follows them, mapped to the grid through their shape functions
//! at every step as their weight is.

use crate::common;

fn mesh(name: &str) -> String {
    common::root().join("tests/meshes").join(name).to_string_lossy().into_owned()
}

/// A free layer without gravity, its base loaded through its points: its momentum grows by the
/// traction times the base's length each second (Newton's second law), to rounding, since the
/// nodal shares of a point's force sum to it. A pressure on the embankment's slopes and crest
/// pushes it down by the pressure times the width they cover (4 m) and not sideways: each piece
/// of the surface pushes along its normal with the pressure times its length.
#[test]
fn a_point_traction_pushes_with_traction_times_length_and_a_pressure_along_the_normals() {
    let q = [250.0, 1000.0];
    let pressure = 2000.0;
    let source = format!(
        r#"
        let file = load_mesh("{}");
        let sim = mpm(#{{ dim: 2, origin: [0.0, 0.0], cell: 0.25, cells: [48, 24] }});
        let soil = sim.material("linear_elastic", #{{ density: 2000.0, young: 5e7, poisson: 0.3 }});
        sim.fill_mesh(soil, file, "foundation", #{{ per_cell: 2 }});
        sim.point_traction(file, "base", [{}, {}]);
        sim.dt(0.2 * sim.critical_dt());
        sim.run_steps(50);
        let d = sim.diagnostics();
        summary("px", d.momentum_x);
        summary("py", d.momentum_y);
        summary("time", sim.time);
        summary("length", file.measure("base"));
        let dam = mpm(#{{ dim: 2, origin: [0.0, 0.0], cell: 0.25, cells: [48, 24] }});
        let fill = dam.material("linear_elastic", #{{ density: 2000.0, young: 5e7, poisson: 0.3 }});
        dam.fill_mesh(fill, file, "embankment", #{{ per_cell: 2 }});
        dam.point_pressure(file, "slope", {pressure});
        dam.dt(0.2 * dam.critical_dt());
        dam.run_steps(50);
        let e = dam.diagnostics();
        summary("dam_px", e.momentum_x);
        summary("dam_py", e.momentum_y);
        summary("dam_time", dam.time);
        "#,
        mesh("embankment_v22_ascii.msh"),
        q[0],
        q[1]
    );
    let out = common::run_text("point_traction_push", &source);
    let s = common::summary_of(&out);
    let get = |k: &str| s[k].as_f64().unwrap();
    let impulse = |t: f64| get("length") * t * get("time");
    for (k, t) in [("px", q[0]), ("py", q[1])] {
        assert!((get(k) - impulse(t)).abs() <= 1e-9 * impulse(t), "{k} = {} against {}", get(k), impulse(t));
    }
    // The slopes (1.5 m over 1.5 m each side) and the crest cover the embankment's 4 m base.
    // Each piece of the surface hands its length to the points nearest to it: exact to rounding.
    let down = -pressure * 4.0 * get("dam_time");
    assert!((get("dam_py") - down).abs() < 1e-9 * down.abs(), "py = {} against {down}", get("dam_py"));
    assert!(get("dam_px").abs() < 1e-9 * down.abs(), "px = {}", get("dam_px"));
}

/// A soft column in an oedometer (sides on rollers, base fixed), loaded on its top through the
/// layer of points under it, settles by more than a cell to the settlement of its law: a
/// hypoelastic law integrates the rate `dσ = M dε` with `dε = dh / h`, so at rest
/// `h = H exp(t / M)` (M the constrained modulus, E at ν = 0) and σ_yy = t. The load follows the
/// surface down through the cells. The same load on the grid's top nodes stays where the surface
/// was: once the material has left those nodes the run says so, and again when it flings points.
#[test]
fn a_column_under_a_point_traction_settles_by_cells_to_the_settlement_of_its_law() {
    let (young, traction, height, cell): (f64, f64, f64, f64) = (1e5, -1.5e4, 1.0, 0.1);
    let column = |cells: usize, load: &str| {
        format!(
            r#"
            let sim = mpm(#{{ dim: 2, origin: [0.0, 0.0], cell: {cell}, cells: [2, {cells}] }});
            let soil = sim.material("linear_elastic", #{{ density: 1000.0, young: {young}, poisson: 0.0 }});
            sim.fill_box(soil, [0.0, 0.0], [0.2, {height}], #{{ per_cell: 2 }});
            sim.shape_functions("bspline2");
            sim.fix("x-", "x"); sim.fix("x+", "x"); sim.fix("y-", "y");
            {load}
            sim.damping(0.3);
            sim.dt(0.3 * sim.critical_dt());
            sim.run_until(8.0);
            sim.write_points("points.csv");
            let d = sim.diagnostics();
            summary("kinetic", d.kinetic_energy);
            summary("elastic", d.elastic_energy);
            "#
        )
    };
    // The layer of points under the top (2 x 2 points a cell: their centres 0.025 m below it).
    let top_layer = format!("sim.point_traction([0.0, {}], [0.2, {height}], [0.0, {traction}]);", height - 0.05);
    let out = common::run_text("point_traction_column", &column(12, &top_layer));
    let (h, rows) = common::read_csv(&out.join("points.csv"));
    let (y, syy) = (common::column(&h, "y"), common::column(&h, "syy"));
    let squeeze = (traction / young).exp();
    assert!(height * (1.0 - squeeze) > cell, "the test settles by more than a cell");
    // Uniform strain: a point first at height Y is at Y squeeze. The top layer started at 0.975.
    let top = rows.iter().map(|r| r[y]).fold(f64::MIN, f64::max);
    let expected = (height - 0.025) * squeeze;
    assert!((top - expected).abs() < 0.01 * height, "top layer at {top} m, the law gives {expected} m");
    let mean = rows.iter().map(|r| r[syy]).sum::<f64>() / rows.len() as f64;
    assert!((mean - traction).abs() < 0.02 * traction.abs(), "mean sigma_yy = {mean}");
    let s = common::summary_of(&out);
    let (kinetic, elastic) = (s["kinetic"].as_f64().unwrap(), s["elastic"].as_f64().unwrap());
    assert!(kinetic < 0.01 * elastic, "at rest: kinetic {kinetic} J against elastic {elastic} J");
    assert!(s.get("warnings").is_none(), "{s}");
    // On the grid's top nodes (the grid as high as the column): said once the material has left.
    let out = common::run_text(
        "point_traction_column_nodal",
        &column(10, &format!("sim.traction(\"y+\", [0.0, {traction}]);")),
    );
    let warnings = common::summary_of(&out)["warnings"].to_string();
    assert!(warnings.contains("no material left under them") && warnings.contains("point_traction"), "{warnings}");
    // Points left with little mass under a loaded node are thrown faster than the material's
    // P waves (10 m/s here): said too.
    assert!(warnings.contains("faster than their material's P-wave speed"), "{warnings}");
}

/// A load carried by points is part of the checkpoint, its factor table too: a run saved halfway
/// and resumed ends where a run straight through does, bit for bit.
#[test]
fn a_point_load_resumes_from_a_checkpoint_bit_for_bit() {
    let head = r#"
        let resume = param("resume", false);
        let sim = if resume { mpm_load("half.json") } else {
            let s = mpm(#{ dim: 2, origin: [0.0, 0.0], cell: 0.1, cells: [4, 6] });
            let soil = s.material("linear_elastic", #{ density: 1000.0, young: 1e6, poisson: 0.3 });
            s.fill_box(soil, [0.1, 0.0], [0.3, 0.4], #{ per_cell: 2 });
            s.fix("y-", "y");
            s.point_traction([0.1, 0.35], [0.3, 0.4], [2e3, -1e4], [[0.0, 0.0], [0.01, 1.0]]);
            s.dt(0.2 * s.critical_dt());
            s
        };
    "#;
    let straight =
        common::run_text("point_load_straight", &format!("{head}sim.run_steps(200);\nsim.write_points(\"end.csv\");"));
    let dir = common::out_dir("point_load_resumed");
    let source = format!(
        "{head}if resume {{ sim.run_steps(100); sim.write_points(\"end.csv\"); }} else {{ sim.run_steps(100); sim.save(\"half.json\"); }}"
    );
    common::run_source_in(&dir, "resume.rhai", &source, &[]);
    common::run_source_in(&dir, "resume.rhai", &source, &[("resume", "true")]);
    let read = |d: &std::path::Path| std::fs::read_to_string(d.join("end.csv")).unwrap();
    assert_eq!(read(&straight), read(&dir));
}

/// In 3D, on a surface group of triangles: a wedge of tetrahedra pushed through the points over
/// its unit-square base gains momentum at traction × area, and a pressure on that base pushes it
/// up (along the inward normal) at pressure × area, to rounding.
#[test]
fn a_point_traction_and_a_pressure_on_a_surface_group_push_with_their_area() {
    let (t, pressure) = ([300.0, -200.0, 1000.0], 500.0);
    let source = format!(
        r#"
        let file = load_mesh("{}");
        for load in ["traction", "pressure"] {{
            let sim = mpm(#{{ dim: 3, origin: [0.0, 0.0, 0.0], cell: 0.1, cells: [10, 10, 6] }});
            let soil = sim.material("linear_elastic", #{{ density: 2000.0, young: 5e7, poisson: 0.3 }});
            sim.fill_mesh(soil, file, "block", #{{ per_cell: 2 }});
            if load == "traction" {{ sim.point_traction(file, "bottom", [{}, {}, {}]); }}
            else {{ sim.point_pressure(file, "bottom", {pressure}); }}
            sim.dt(0.2 * sim.critical_dt());
            sim.run_steps(5);
            let d = sim.diagnostics();
            summary(`${{load}}_p`, [d.momentum_x, d.momentum_y, d.momentum_z]);
            summary(`${{load}}_time`, sim.time);
        }}
        summary("area", file.measure("bottom"));
        "#,
        mesh("wedge_block.msh"),
        t[0],
        t[1],
        t[2]
    );
    let out = common::run_text("point_traction_3d", &source);
    let s = common::summary_of(&out);
    let area = s["area"].as_f64().unwrap();
    assert!((area - 1.0).abs() < 1e-12);
    let momentum = |k: &str| -> Vec<f64> { s[k].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect() };
    let impulse = area * s["traction_time"].as_f64().unwrap();
    let size = t.iter().map(|c| c * c).sum::<f64>().sqrt();
    for (a, p) in momentum("traction_p").iter().enumerate() {
        assert!((p - t[a] * impulse).abs() <= 1e-9 * size * impulse, "axis {a}: {p} against {}", t[a] * impulse);
    }
    let up = pressure * area * s["pressure_time"].as_f64().unwrap();
    let p = momentum("pressure_p");
    assert!((p[2] - up).abs() <= 1e-9 * up && p[0].abs() <= 1e-9 * up && p[1].abs() <= 1e-9 * up, "{p:?} against {up}");
}

/// A strip footing loaded through the points under it (scripts/mpm/strip_footing.rhai) on a
/// weightless Tresca soil: Prandtl's collapse load `(2 + π) c` bounds what it carries. At 0.95 of
/// it the footing settles to rest; at 1.15 of it the soil flows and the footing keeps sinking
/// (0.1 m cells under a 1 m footing: the collapse load of the discretisation lies between).
#[test]
fn a_strip_footing_carries_up_to_prandtl_s_load() {
    let below = common::run("mpm/strip_footing.rhai", "footing_below", &[("q_factor", "0.95")], 2).unwrap();
    let above = common::run("mpm/strip_footing.rhai", "footing_above", &[("q_factor", "1.15")], 2).unwrap();
    let rate = |r: &granite_script::RunReport| common::summary_f64(r, "settling_rate");
    let settled = common::summary_f64(&below, "settlement");
    assert!(
        rate(&below).abs() < 1e-5 && settled > 0.0 && settled < 0.05,
        "0.95 q_u: {settled} m, {} m/s",
        rate(&below)
    );
    assert!(rate(&above) > 1e-3, "1.15 q_u: still {} m/s", rate(&above));
    assert!(common::summary_f64(&above, "settlement") > 2.0 * settled);
}
