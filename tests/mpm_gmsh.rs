//! MPM bodies and boundary conditions from gmsh meshes (tests/meshes, written by gmsh itself with
//! tests/meshes/make_meshes.py): `load_mesh`, `fill_mesh`, and `fix` on a mesh group.

use crate::common;
use common::*;

fn mesh(name: &str) -> String {
    root().join("tests/meshes").join(name).display().to_string()
}

/// The corners make_meshes.py gives gmsh.
const FOUNDATION: [(f64, f64); 6] = [(0.0, 0.0), (10.0, 0.0), (10.0, 2.0), (7.0, 2.0), (3.0, 2.0), (0.0, 2.0)];
const EMBANKMENT: [(f64, f64); 4] = [(3.0, 2.0), (7.0, 2.0), (5.5, 3.5), (4.5, 3.5)];

fn polygon(corners: &[(f64, f64)]) -> (f64, f64) {
    let n = corners.len();
    let (mut area, mut perimeter) = (0.0, 0.0);
    for i in 0..n {
        let ((x0, y0), (x1, y1)) = (corners[i], corners[(i + 1) % n]);
        area += 0.5 * (x0 * y1 - x1 * y0);
        perimeter += ((x1 - x0).powi(2) + (y1 - y0).powi(2)).sqrt();
    }
    (area.abs(), perimeter)
}

#[test]
fn a_mesh_group_fills_and_fixes_exactly_as_the_box_and_faces_it_covers() {
    // The foundation is the rectangle [0, 10] x [0, 2]; its "base" is y = 0 and its "sides" are
    // x = 0 and x = 10. Filled and held from the mesh, a settling layer must go bit for bit as
    // the same layer filled with fill_box and held by the grid's faces.
    let source = format!(
        r#"
        let file = load_mesh("{}");
        fn layer(from_mesh, file) {{
            let sim = mpm(#{{ dim: 2, origin: [0.0, 0.0], cell: 0.25, cells: [40, 8] }});
            let soil = sim.material("linear_elastic", #{{ density: 2000.0, young: 5e7, poisson: 0.3 }});
            if from_mesh {{
                sim.fill_mesh(soil, file, "foundation", #{{ per_cell: 2 }});
                sim.fix(file, "sides", "x");
                sim.fix(file, "base", "x");
                sim.fix(file, "base", "y", 0.0);
            }} else {{
                sim.fill_box(soil, [0.0, 0.0], [10.0, 2.0], #{{ per_cell: 2 }});
                sim.fix("x-", "x");
                sim.fix("x+", "x");
                sim.fix("y-", "x");
                sim.fix("y-", "y", 0.0);
            }}
            sim.gravity([0.0, -9.81]);
            sim.damping(0.05);
            sim.dt(0.2 * sim.critical_dt());
            sim.run_steps(200);
            sim
        }}
        let a = layer(false, file);
        let b = layer(true, file);
        summary("points_box", a.points);
        summary("points_mesh", b.points);
        let differ = 0;
        for i in 0..a.points {{
            if a.point_position(i) != b.point_position(i) || a.point_stress(i) != b.point_stress(i) {{
                differ += 1;
            }}
        }}
        summary("differ", differ);
        summary("settled_y", a.point_position(0)[1]);
        "#,
        mesh("embankment_v22_binary.msh")
    );
    let out = run_text("gmsh_equivalence", &source);
    let summary: serde_json::Value = common::summary_of(&out);
    let points = summary["points_box"].as_i64().unwrap();
    // 40 x 8 cells of 2 x 2 points.
    assert_eq!(points, 40 * 8 * 4);
    assert_eq!(summary["points_mesh"].as_i64(), Some(points));
    assert_eq!(summary["differ"].as_i64(), Some(0), "points differ between the two layers");
    // The layer did move (the comparison compares something): it sank under its weight.
    let first_point_y = 0.25 * 0.5 * (1.0 - 1.0 / 3f64.sqrt());
    assert!(summary["settled_y"].as_f64().unwrap() < first_point_y);
}

#[test]
fn friction_on_a_mesh_curve_is_friction_on_the_grid_face_it_lies_on() {
    // A layer sliding down a tilted gravity on a rough base: friction on the mesh's "base" and on
    // the grid face y- must give the same run, bit for bit.
    let source = format!(
        r#"
        let file = load_mesh("{}");
        fn slide(from_mesh, file) {{
            let sim = mpm(#{{ dim: 2, origin: [0.0, 0.0], cell: 0.25, cells: [48, 8] }});
            let soil = sim.material("linear_elastic", #{{ density: 2000.0, young: 5e7, poisson: 0.3 }});
            sim.fill_mesh(soil, file, "foundation", #{{ per_cell: 2 }});
            sim.fix("y-", "y");
            if from_mesh {{ sim.friction(file, "base", 0.3); }} else {{ sim.friction("y-", 0.3); }}
            sim.gravity([4.0, -9.0]);
            sim.dt(0.2 * sim.critical_dt());
            sim.run_steps(200);
            sim
        }}
        let a = slide(false, file);
        let b = slide(true, file);
        let differ = 0;
        for i in 0..a.points {{
            if a.point_position(i) != b.point_position(i) || a.point_velocity(i) != b.point_velocity(i) {{
                differ += 1;
            }}
        }}
        summary("differ", differ);
        summary("vx", a.point_velocity(0)[0]);
        summary("time", a.time);
        "#,
        mesh("embankment_v41_binary.msh")
    );
    let out = run_text("gmsh_friction", &source);
    let summary: serde_json::Value = common::summary_of(&out);
    assert_eq!(summary["differ"].as_i64(), Some(0));
    // Sliding, and slower than frictionless: a = g_x - mu g_y at most.
    let (vx, t) = (summary["vx"].as_f64().unwrap(), summary["time"].as_f64().unwrap());
    assert!(vx > 0.0 && vx < 4.0 * t, "vx = {vx} after {t} s");
}

#[test]
fn a_traction_on_a_mesh_curve_pushes_with_traction_times_length() {
    // A free layer, without gravity, pushed by a traction on its base: its momentum grows by
    // the traction times the base's length each second (Newton's second law).
    let q = [250.0, 1000.0];
    let source = format!(
        r#"
        let file = load_mesh("{}");
        let sim = mpm(#{{ dim: 2, origin: [0.0, 0.0], cell: 0.25, cells: [48, 12] }});
        let soil = sim.material("linear_elastic", #{{ density: 2000.0, young: 5e7, poisson: 0.3 }});
        sim.fill_mesh(soil, file, "foundation", #{{ per_cell: 2 }});
        sim.traction(file, "base", [{}, {}]);
        sim.dt(0.2 * sim.critical_dt());
        sim.run_steps(50);
        let d = sim.diagnostics();
        summary("px", d.momentum_x);
        summary("py", d.momentum_y);
        summary("time", sim.time);
        summary("length", file.measure("base"));
        "#,
        mesh("embankment_v22_ascii.msh"),
        q[0],
        q[1]
    );
    let out = run_text("gmsh_traction", &source);
    let summary: serde_json::Value = common::summary_of(&out);
    let get = |k: &str| summary[k].as_f64().unwrap();
    let impulse = |t: f64| get("length") * t * get("time");
    for (k, t) in [("px", q[0]), ("py", q[1])] {
        assert!((get(k) - impulse(t)).abs() <= 1e-9 * impulse(t), "{k} = {} against {}", get(k), impulse(t));
    }
}

#[test]
fn an_embankment_filled_from_gmsh_has_its_area_and_stays_within_its_slopes() {
    let (cell, per_cell) = (0.25, 2.0);
    let source = format!(
        r#"
        let file = load_mesh("{}");
        let sim = mpm(#{{ dim: 2, origin: [0.0, 0.0], cell: {cell}, cells: [40, 16] }});
        let soil = sim.material("linear_elastic", #{{ name: "foundation", density: 2000.0, young: 5e7, poisson: 0.3 }});
        let fill = sim.material("linear_elastic", #{{ name: "embankment", density: 1800.0, young: 2e7, poisson: 0.3 }});
        sim.fill_mesh(soil, file, "foundation", #{{ per_cell: {per_cell} }});
        sim.fill_mesh(fill, file, "embankment", #{{ per_cell: {per_cell} }});
        sim.write_points("points.csv");
        "#,
        mesh("embankment_v41_ascii.msh")
    );
    let out = run_text("gmsh_embankment", &source);
    let (h, rows) = read_csv(&out.join("points.csv"));
    let (material, x, y, volume) = (column(&h, "material"), column(&h, "x"), column(&h, "y"), column(&h, "volume"));
    // Points stand on a lattice of spacing d; each carries a d x d square. The squares of the
    // points inside a polygon cover it but for a strip along its boundary at most d/2 wide.
    let d = cell / per_cell;
    for (m, corners) in [(0.0, &FOUNDATION[..]), (1.0, &EMBANKMENT[..])] {
        let (area, perimeter) = polygon(corners);
        let filled: f64 = rows.iter().filter(|r| r[material] == m).map(|r| r[volume]).sum();
        assert!((filled - area).abs() <= 0.5 * d * perimeter, "material {m}: {filled} m^2 of {area}");
    }
    for r in rows.iter().filter(|r| r[material] == 1.0) {
        let (px, py) = (r[x], r[y]);
        // Above the foundation, under the crest, within both slopes (1:1). Points on a slope
        // belong to the group; they sit on it to rounding.
        let on = 1e-12;
        assert!((2.0..=3.5).contains(&py), "({px}, {py})");
        assert!(py - 2.0 <= px - 3.0 + on && py - 2.0 <= 7.0 - px + on, "({px}, {py}) outside the slopes");
    }
    for r in rows.iter().filter(|r| r[material] == 0.0) {
        assert!(r[y] <= 2.0, "a foundation point at y = {}", r[y]);
    }
}

#[test]
fn a_volume_group_fills_its_solid() {
    let (cell, per_cell) = (0.05, 2.0);
    let source = format!(
        r#"
        let file = load_mesh("{}");
        let sim = mpm(#{{ dim: 3, origin: [0.0, 0.0, 0.0], cell: {cell}, cells: [20, 20, 10] }});
        let soil = sim.material("linear_elastic", #{{ density: 2000.0, young: 5e7, poisson: 0.3 }});
        let n = sim.fill_mesh(soil, file, "block", #{{ per_cell: {per_cell} }});
        summary("points", n);
        summary("volume", file.measure("block"));
        "#,
        mesh("wedge_block.msh")
    );
    let out = run_text("gmsh_volume", &source);
    let summary: serde_json::Value = common::summary_of(&out);
    let d = cell / per_cell;
    let filled = summary["points"].as_f64().unwrap() * d * d * d;
    // A unit square base under a top from 0.5 (x = 0) down to 0.25 (x = 1).
    let (h0, h1) = (0.5, 0.25);
    let volume = 0.5 * (h0 + h1);
    assert!((summary["volume"].as_f64().unwrap() - volume).abs() < 1e-12);
    let top = (1.0f64 + (h0 - h1) * (h0 - h1)).sqrt();
    let surface = 1.0 + top + 2.0 * volume + h0 + h1;
    assert!((filled - volume).abs() <= 0.5 * d * surface, "{filled} m^3 of {volume}");
}

#[test]
fn mesh_groups_of_the_wrong_kind_or_name_are_refused_naming_them() {
    let file = mesh("embankment_v41_binary.msh");
    let setup = r#"let sim = mpm(#{ dim: 2, origin: [0.0, 0.0], cell: 0.25, cells: [40, 16] });
        let soil = sim.material("linear_elastic", #{ density: 2000.0, young: 5e7, poisson: 0.3 });"#;
    let e = run_text_err(
        "gmsh_curve_fill",
        &format!("{setup}\nlet m = load_mesh(\"{file}\");\nsim.fill_mesh(soil, m, \"slope\");"),
    );
    assert!(e.contains("\"slope\"") && e.contains("curves") && e.contains("surfaces"), "{e}");
    let e =
        run_text_err("gmsh_no_group", &format!("{setup}\nlet m = load_mesh(\"{file}\");\nsim.fix(m, \"toe\", \"x\");"));
    assert!(e.contains("\"toe\"") && e.contains("\"embankment\" (2D)"), "{e}");
    let e = run_text_err(
        "gmsh_surface_fix",
        &format!("{setup}\nlet m = load_mesh(\"{file}\");\nsim.fix(m, \"embankment\", \"x\");"),
    );
    assert!(e.contains("surfaces") && e.contains("curves"), "{e}");
    let e = run_text_err(
        "gmsh_slope_friction",
        &format!("{setup}\nlet m = load_mesh(\"{file}\");\nsim.friction(m, \"slope\", 0.3);"),
    );
    assert!(e.contains("not a straight boundary"), "{e}");
    let e = run_text_err("gmsh_missing", "let m = load_mesh(\"no_such_mesh.msh\");");
    assert!(e.contains("no_such_mesh.msh") && e.contains("line 1"), "{e}");
}
