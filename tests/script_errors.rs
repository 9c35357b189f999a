//! Bad input gives a clear error naming the script line and the parameter; a run that goes
//! unstable stops, keeps and writes its last good state.

use crate::common;
use granite_script::{run_source, RunOptions};

fn run_err(name: &str, source: &str, overrides: &[(&str, &str)]) -> String {
    let options = RunOptions {
        out_dir: common::out_dir(name),
        overrides: common::sets(overrides),
        quiet: true,
        ..Default::default()
    };
    match run_source(&format!("{name}.rhai"), source, granite::registry(), options) {
        Ok(_) => panic!("{name}: the script should have failed"),
        Err(e) => e.to_string(),
    }
}

const HEAD: &str = "let sim = mpm(#{ dim: 2, cell: 0.1, cells: [4, 4] });\n";

#[test]
fn negative_modulus_names_the_parameter_and_line() {
    let e = run_err(
        "neg_young",
        &format!(
            "{HEAD}\nlet m = sim.material(\"linear_elastic\", #{{ density: 1000.0, young: -5.0, poisson: 0.2 }});"
        ),
        &[],
    );
    assert!(e.contains("line 3") && e.contains("`young`") && e.contains("> 0"), "{e}");
}

#[test]
fn incompressible_poisson_ratio_is_rejected() {
    let e = run_err(
        "nu_half",
        &format!("{HEAD}let m = sim.material(\"mohr_coulomb\", #{{ density: 1e3, young: 5e6, poisson: 0.5, friction: 30.0 }});"),
        &[],
    );
    assert!(e.contains("line 2") && e.contains("`poisson`") && e.contains("0.5"), "{e}");
}

#[test]
fn points_outside_the_mesh_are_refused() {
    let make = "let m = sim.material(\"linear_elastic\", #{ density: 1e3, young: 5e6, poisson: 0.2 });\n";
    let e =
        run_err("outside_point", &format!("{HEAD}{make}sim.add_points(m, [[0.05, 0.05], [0.5, 0.1]], 0.001);"), &[]);
    assert!(e.contains("line 3") && e.contains("outside the mesh"), "{e}");
    let e = run_err("outside_box", &format!("{HEAD}{make}sim.fill_box(m, [0.0, 0.0], [1.0, 0.2]);"), &[]);
    assert!(e.contains("line 3") && e.contains("extends outside the mesh"), "{e}");
}

#[test]
fn time_step_above_the_stability_limit_is_refused() {
    let src = format!(
        "{HEAD}let m = sim.material(\"linear_elastic\", #{{ density: 1e3, young: 5e6, poisson: 0.2 }});\n\
         sim.fill_box(m, [0.0, 0.0], [0.2, 0.2]);\nsim.dt(1.0);\nsim.run_steps(10);"
    );
    // Refused where it is set, not at the run.
    let e = run_err("big_dt", &src, &[]);
    assert!(e.contains("line 4") && e.contains("`dt`") && e.contains("stability limit"), "{e}");
}

#[test]
fn unknown_override_lists_the_declared_parameters() {
    let src = "let e = param(\"young\", 5e6);\nlet n = param(\"steps\", 10);\n";
    let e = run_err("unknown_set", src, &[("yung", "3")]);
    assert!(e.contains("yung") && e.contains("young, steps"), "{e}");
    let e = run_err("bad_set_type", src, &[("steps", "ten")]);
    assert!(e.contains("steps") && e.contains("integer"), "{e}");
}

#[test]
fn overrides_outside_the_declared_limits_are_refused_at_the_declaration() {
    let src = "// a script with limits\nlet dt = param(\"dt\", 1e-3, #{ above: 0.0 });\n\
               let phi = param(\"friction\", 30.0, #{ min: 0.0, max: 90.0 });\n\
               let s = param(\"scheme\", \"USF\", #{ one_of: [\"USF\", \"USL\"] });\n";
    let e = run_err("limit_dt", src, &[("dt", "-1e-3")]);
    assert!(e.contains("line 2") && e.contains("`dt`") && e.contains("must be > 0"), "{e}");
    let e = run_err("limit_nan", src, &[("dt", "NaN")]);
    assert!(e.contains("line 2") && e.contains("finite number"), "{e}");
    let e = run_err("limit_friction", src, &[("friction", "95")]);
    assert!(e.contains("line 3") && e.contains(">= 0 and <= 90"), "{e}");
    let e = run_err("limit_scheme", src, &[("scheme", "usf")]);
    assert!(e.contains("line 4") && e.contains("one of \"USF\", \"USL\""), "{e}");
    // A default outside its own limits is the script's own mistake, reported as such.
    let e = run_err("limit_default", "let n = param(\"count\", 0, #{ min: 1 });\n", &[]);
    assert!(e.contains("line 1") && e.contains("default 0") && e.contains(">= 1"), "{e}");
}

#[test]
fn unknown_law_lists_the_registered_ones() {
    let e = run_err("typo_law", &format!("{HEAD}let m = sim.material(\"mohr_colomb\", #{{ density: 1e3 }});"), &[]);
    assert!(e.contains("mohr_colomb") && e.contains("linear_elastic, mohr_coulomb"), "{e}");
}

#[test]
fn nan_stops_the_run_and_keeps_the_last_good_state() {
    // A prescribed floor velocity that turns into NaN poisons the grid after t = 1 ms.
    let src = format!(
        "{HEAD}let m = sim.material(\"linear_elastic\", #{{ density: 1e3, young: 5e6, poisson: 0.2 }});\n\
         sim.fill_box(m, [0.0, 0.0], [0.4, 0.2]);\nsim.gravity([0.0, -9.81]);\n\
         sim.fix(\"y-\", \"y\", |t| if t > 0.001 {{ 0.0 / 0.0 }} else {{ 0.0 }});\nsim.dt(1e-4);\nsim.run_until(0.01);"
    );
    let e = run_err("nan_run", &src, &[]);
    assert!(e.contains("line 7") && e.contains("non-finite") && e.contains("last good state"), "{e}");
    let dir = common::root().join("target/test-out/nan_run");
    let (h, rows) = common::read_csv(&dir.join("last_good_points.csv"));
    assert_eq!(rows.len(), 4 * 2 * 4, "every point (4 x 2 cells, 2 x 2 per cell) of the last good state is written");
    assert!(rows.iter().all(|r| r.iter().all(|v| v.is_finite())), "the kept state is finite");
    let _ = h;
    let summary: serde_json::Value = common::summary_of(&dir);
    assert_eq!(summary["status"], "failed");
}

#[test]
fn a_point_faster_than_a_cell_per_step_stops_the_run() {
    // HEAD's cells of 0.1 m, dt = 1 ms (the elastic wave's limit is 1.34 ms): at 1.5 cells per
    // step a point breaks the CFL condition whatever the material.
    let (cell, dt) = (0.1, 1e-3);
    let src = |cells_per_step: f64| {
        format!(
            "{HEAD}let m = sim.material(\"linear_elastic\", #{{ density: 1e3, young: 5e6, poisson: 0.2 }});\n\
             sim.fill_box(m, [0.1, 0.1], [0.2, 0.2], #{{ velocity: [{:?}, 0.0] }});\n\
             sim.dt({dt:?});\nsim.run_steps(1);",
            cells_per_step * cell / dt
        )
    };
    let e = run_err("cfl_run", &src(1.5), &[]);
    let (step, limit) = (format!("{:.4e} m in one step", 1.5 * cell), format!("more than a cell ({cell:.4e} m)"));
    assert!(e.contains("line 5") && e.contains(&step) && e.contains(&limit), "{e}");
    assert!(e.contains("last good state (step 0"), "{e}");
    // Half a cell per step is a legitimate motion.
    let options = RunOptions { out_dir: common::out_dir("cfl_ok"), quiet: true, ..Default::default() };
    run_source("cfl_ok.rhai", &src(0.5), granite::registry(), options).expect("half a cell per step runs");
}

#[test]
fn a_float_where_an_integer_is_expected_lists_the_forms_that_exist() {
    // Rhai does not turn 10.0 into an integer: the call matches no function.
    let e = run_err("float_count", &format!("{HEAD}sim.every(10.0, |s| 1);"), &[]);
    assert!(e.contains("line 2") && e.contains("MpmSim.every(int, Fn)") && e.contains("write 10, not 10.0"), "{e}");
    // A script's own typo keeps Rhai's words.
    let e = run_err("no_such_fn", &format!("{HEAD}sim.explode(1);"), &[]);
    assert!(e.contains("line 2") && e.contains("Function not found: explode"), "{e}");
}

#[test]
fn non_finite_vectors_and_boundary_values_are_refused_where_they_are_given() {
    let e = run_err("nan_gravity", &format!("{HEAD}sim.gravity([0.0 / 0.0, -9.81]);"), &[]);
    assert!(e.contains("line 2") && e.contains("`gravity`") && e.contains("finite"), "{e}");
    // A velocity prescribed as infinite on a face with no material would change nothing and
    // go unnoticed until points got there.
    let e = run_err("inf_fix", &format!("{HEAD}sim.fix(\"y+\", \"y\", 1.0 / 0.0);"), &[]);
    assert!(e.contains("line 2") && e.contains("finite"), "{e}");
    let e = run_err("nan_table", &format!("{HEAD}sim.fix(\"y+\", \"y\", [[0.0, 0.0], [0.0 / 0.0, 1.0]]);"), &[]);
    assert!(e.contains("line 2") && e.contains("finite"), "{e}");
}

#[test]
fn numbers_at_the_ends_of_the_f64_range_are_shown_with_an_exponent() {
    let e = run_err("tiny_damping", &format!("{HEAD}sim.damping(-1e-320);"), &[]);
    assert!(e.contains("line 2") && e.contains("-1e-320") && e.len() < 200, "{e}");
}

const DEM_HEAD: &str = "let sim = dem(#{ seed: 1 });\nlet m = sim.material(#{ density: 2600.0 });\n";

#[test]
fn spheres_and_clumps_whose_mass_overflows_or_vanishes_are_refused_at_once() {
    // A radius of 1e308 m or 1e-320 m passes "> 0", but its mass is infinite or zero; a clump of
    // such members had an inertia whose principal axes were searched for without end.
    for (name, call, what) in [
        ("huge_sphere", "sim.sphere(m, [0.0, 0.0, 0.0], 1e308, #{})", "`radius` = 1e308"),
        ("tiny_sphere", "sim.sphere(m, [0.0, 0.0, 0.0], 1e-320, #{})", "`radius` = 1e-320"),
        ("huge_clump", "sim.clump(m, [[0.0, 0.0, 0.0, 1e308]])", "clump with volume inf"),
        ("tiny_clump", "sim.clump(m, [[0.0, 0.0, 0.0, 1e-320]])", "clump with volume 0e0"),
        ("spread_clump", "sim.tetra_clump(m, [0.0, 0.0, 0.0], 0.005, 1e308)", "inertia up to NaN"),
    ] {
        let e = run_err(name, &format!("{DEM_HEAD}{call};"), &[]);
        assert!(e.contains("line 3") && e.contains(what), "{name}: {e}");
    }
}

/// Values that cannot be right are refused where they are given, not run on or written as null.
#[test]
fn infinite_friction_a_past_end_time_and_a_nan_summary_are_refused() {
    let e = run_err("inf_friction", &format!("{HEAD}sim.friction(\"y-\", 1.0 / 0.0);\n"), &[]);
    assert!(e.contains("line 2") && e.contains("finite") && e.contains("mu"), "{e}");
    let src = format!(
        "{HEAD}let m = sim.material(\"linear_elastic\", #{{ density: 1000.0, young: 1e5, poisson: 0.2 }});\n\
         sim.fill_box(m, [0.0, 0.0], [0.2, 0.2]);\nsim.dt(1e-3);\nsim.run_until(0.01);\nsim.run_until(0.005);\n"
    );
    let e = run_err("past_end", &src, &[]);
    assert!(e.contains("line 6") && e.contains("run_until(5e-3)") && e.contains("already at t = 1"), "{e}");
    let e = run_err("nan_summary", "let x = 0.0 / 0.0;\nsummary(\"x\", x);\n", &[]);
    assert!(e.contains("line 2") && e.contains("NaN") && e.contains("summary(\"x\""), "{e}");
    let e = run_err("nan_in_list", "summary(\"xs\", [1.0, 1.0 / 0.0]);\n", &[]);
    assert!(e.contains("inf"), "{e}");
}

/// The error names the cause: the missing contact law behind an infinite critical time step,
/// the misspelt option behind a missing density.
#[test]
fn errors_name_the_missing_law_and_the_misspelt_option() {
    let e = run_err(
        "no_contact_law",
        "let sim = dem();\nlet m = sim.material(#{ name: \"g\", density: 2500.0 });\n\
         sim.sphere(m, [0.0, 0.0, 0.0], 0.01);\nsim.dt(0.3 * sim.critical_dt());\n",
        &[],
    );
    assert!(e.contains("line 4") && e.contains("no contact law") && e.contains("sim.contact_law"), "{e}");
    let e = run_err(
        "densty",
        &format!("{HEAD}let m = sim.material(\"linear_elastic\", #{{ densty: 1000.0, young: 1e5, poisson: 0.2 }});\n"),
        &[],
    );
    assert!(
        e.contains("line 2") && e.contains("unknown option `densty`") && e.contains("did you mean `density`?"),
        "{e}"
    );
}

/// Impossible geometry is refused; doubtful geometry is said once, naming the bodies.
#[test]
fn inverted_boxes_are_refused_and_twin_walls_and_deep_overlaps_are_said() {
    let head = "let sim = dem();\nlet m = sim.material(#{ name: \"g\", density: 2500.0 });\n";
    let e = run_err("inverted_box", &format!("{head}sim.box_walls(m, [0.0, 0.0, 0.0], [0.2, -0.2, 0.2]);\n"), &[]);
    assert!(e.contains("line 3") && e.contains("not on y"), "{e}");
    let e = run_err(
        "inverted_erase",
        &format!(
            "{head}sim.sphere(m, [0.1, 0.1, 0.1], 0.005);\nsim.erase_outside([0.2, 0.0, 0.0], [0.0, 0.2, 0.2]);\n"
        ),
        &[],
    );
    assert!(e.contains("line 4") && e.contains("every sphere would be erased"), "{e}");
    // The same floor twice, a sphere centred on it, two spheres 0.1 mm apart at r = 5 mm.
    let src = format!(
        "{head}sim.contact_law(\"linear\", #{{ kn: 1e4 }});\n\
         sim.wall_plane(m, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]);\n\
         sim.wall_plane(m, [0.3, 0.1, 0.0], [0.0, 0.0, 1.0]);\n\
         sim.sphere(m, [0.1, 0.1, 0.0], 0.005);\n\
         sim.sphere(m, [0.05, 0.05, 0.05], 0.005);\nsim.sphere(m, [0.0501, 0.05, 0.05], 0.005);\n\
         sim.dt(0.1 * sim.critical_dt());\nsim.run_steps(1);\n"
    );
    let out = common::out_dir("overlaps");
    let options = RunOptions { out_dir: out.clone(), quiet: true, ..Default::default() };
    run_source("overlaps.rhai", &src, granite::registry(), options).unwrap();
    let summary: serde_json::Value = common::summary_of(&out);
    let warnings: Vec<&str> = summary["warnings"].as_array().unwrap().iter().map(|w| w.as_str().unwrap()).collect();
    assert!(warnings.iter().any(|w| w.contains("wall 1") && w.contains("same surface as wall 0")), "{warnings:?}");
    let deep = warnings.iter().find(|w| w.contains("overlap by more than 10 %")).expect("the deep overlaps");
    assert!(deep.contains("spheres 2 and 1 by 198 %") && deep.contains("sphere 0 and wall 0"), "{deep}");
    // Said off: no warning.
    let allowed = src.replace("sim.dt(", "sim.allow_overlaps(true);\nsim.dt(");
    let out = common::out_dir("overlaps_allowed");
    let options = RunOptions { out_dir: out.clone(), quiet: true, ..Default::default() };
    run_source("overlaps_allowed.rhai", &allowed, granite::registry(), options).unwrap();
    let summary = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(!summary.contains("overlap by more than"), "{summary}");
}

/// Replacing the mesh clears its boundary conditions: said only when the next run starts
/// without any (a script that sets them again hears nothing).
#[test]
fn a_replaced_mesh_without_boundaries_is_said_and_one_with_them_is_not() {
    let run = |name: &str, again: &str| -> String {
        let src = format!(
            "{HEAD}let m = sim.material(\"linear_elastic\", #{{ density: 1000.0, young: 1e5, poisson: 0.2 }});\n\
             sim.fill_box(m, [0.0, 0.0], [0.2, 0.2]);\nsim.fix(\"y-\", \"y\");\nsim.gravity([0.0, -9.81]);\n\
             sim.dt(1e-3);\nsim.run_steps(2);\nsim.mesh(#{{ cell: 0.1, cells: [8, 4] }});\n{again}sim.run_steps(2);\n"
        );
        let out = common::out_dir(name);
        let options = RunOptions { out_dir: out.clone(), quiet: true, ..Default::default() };
        run_source(&format!("{name}.rhai"), &src, granite::registry(), options).unwrap();
        std::fs::read_to_string(out.join("summary.json")).unwrap()
    };
    assert!(run("mesh_bare", "").contains("none was set since"));
    assert!(!run("mesh_bounded", "sim.fix(\"y-\", \"y\");\n").contains("warnings"));
}

/// A material belongs to the simulation that made it: given to another one, it is refused,
/// naming both, instead of taking that simulation's material of the same index.
#[test]
fn a_material_of_one_simulation_is_refused_by_another() {
    let dem = "let a = dem();\nlet glass = a.material(#{ name: \"glass\", density: 2500.0 });\n\
               let b = dem();\nlet steel = b.material(#{ name: \"steel\", density: 7800.0 });\n";
    for (call, line) in [
        ("b.sphere(glass, [0.0, 0.0, 0.0], 0.01);", 5),
        ("b.clump_cloud(glass, [0.0, 0.0, 0.0], [0.1, 0.1, 0.1], #{ count: 3, r_sphere: 0.005, r_clump: 0.01 });", 5),
        ("b.wall_plane(glass, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]);", 5),
        ("b.contact_law(\"linear\", glass, steel, #{ kn: 1e5 });", 5),
    ] {
        let e = run_err("material_of_another_dem", &format!("{dem}{call}"), &[]);
        assert!(
            e.contains("material \"glass\" belongs to simulation #1, not to this one (#2)")
                && e.contains(&format!("line {line}")),
            "{call}: {e}"
        );
    }
    let mpm = "let a = mpm(#{ dim: 2, cell: 0.1, cells: [4, 4] });\n\
               let sand = a.material(\"linear_elastic\", #{ name: \"sand\", density: 1800.0, young: 1e6, poisson: 0.3 });\n\
               let b = mpm(#{ dim: 2, cell: 0.1, cells: [4, 4] });\n\
               b.fill_box(sand, [0.0, 0.0], [0.2, 0.2]);";
    let e = run_err("material_of_another_mpm", mpm, &[]);
    assert!(
        e.contains("material \"sand\" belongs to simulation #1, not to this one (#2)") && e.contains("line 4"),
        "{e}"
    );
}

/// A wall belongs to the simulation that made it, as a material does: `b.wall_velocity(a_wall,
/// ...)` is refused naming both simulations instead of moving b's wall of the same index. An
/// index names the simulation's own wall.
#[test]
fn a_wall_of_one_simulation_is_refused_by_another() {
    let dem = "let a = dem();\nlet glass = a.material(#{ name: \"glass\", density: 2500.0 });\n\
               let floor = a.wall_plane(glass, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]);\n\
               let box = a.box_walls(glass, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]);\n\
               let b = dem();\nlet steel = b.material(#{ name: \"steel\", density: 7800.0 });\n\
               let own = b.wall_plane(steel, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]);\n";
    for call in [
        "b.wall_velocity(floor, [0.0, 0.0, 1.0]);",
        "b.wall_velocity([own, floor], [0.0, 0.0, 1.0]);",
        "b.wall_force(box[0]);",
        "b.wall_position(box);",
        "b.wall_velocity(floor, \"z\", |t| 1.0);",
    ] {
        let e = run_err("wall_of_another_dem", &format!("{dem}{call}"), &[]);
        assert!(e.contains("belongs to simulation #1, not to this one (#2)") && e.contains("line 8"), "{call}: {e}");
    }
    // Its own walls, by handle or index, are taken; the handle says which wall it is.
    let out = common::out_dir("wall_of_its_own");
    let source = format!(
        "{dem}b.wall_velocity(own, [0.0, 0.0, 2.0]);\nb.wall_velocity(0, [0.0, 1.0, 2.0]);\n\
         summary(\"own\", own.index);\nsummary(\"box_last\", box[5].index);\nsummary(\"same\", box[1] == box[1] && box[0] != box[1]);\n"
    );
    let report = granite_script::run_source(
        "walls.rhai",
        &source,
        granite::registry(),
        granite_script::RunOptions { out_dir: out, quiet: true, ..Default::default() },
    )
    .unwrap();
    assert_eq!(report.summary["own"], 0);
    assert_eq!(report.summary["box_last"], 6);
    assert_eq!(report.summary["same"], true);
}

/// A script's series column may not take the name of a column granite writes (two
/// `volumetric_strain` columns of opposite signs were written before).
#[test]
fn a_series_column_with_the_name_of_one_of_granite_is_refused() {
    let e = run_err(
        "series_column_twice",
        "let sim = dem();\nsim.periodic([0.01, 0.01, 0.01]);\nsim.series_column(\"volumetric_strain\", |s| 0.0);",
        &[],
    );
    assert!(e.contains("already has a column `volumetric_strain`") && e.contains("line 3"), "{e}");
}

/// `device: "gpu"` in a granite built without the `gpu` feature says how to build one; an unknown
/// device names the known ones.
#[test]
fn an_rve_device_granite_lacks_is_refused_with_what_to_do() {
    let script = |device: &str| {
        format!(
            "let sim = mpm(#{{ dim: 3, origin: [0.0, 0.0, 0.0], cell: 1.0, cells: [1, 1, 1] }});\n\
             let rve = dem();\nrve.periodic([0.01, 0.01, 0.01]);\n\
             sim.material(\"dem_rve\", #{{ density: 1600.0, rve: rve, device: \"{device}\" }});"
        )
    };
    if cfg!(not(feature = "gpu")) {
        let e = run_err("rve_device_gpu", &script("gpu"), &[]);
        assert!(e.contains("--features gpu") && e.contains("line 4"), "{e}");
    }
    let e = run_err("rve_device_unknown", &script("tpu"), &[]);
    assert!(e.contains("no RVE device \"tpu\"") && e.contains("\"cpu\"") && e.contains("line 4"), "{e}");
}

/// `adaptive: #{ ... }` of `dem_rve`: a misspelt tolerance is named with the parameters there
/// are, and a `refine` not above `coarsen` is refused with why.
#[test]
fn adaptive_rve_tolerances_are_checked_by_name() {
    let script = |adaptive: &str| {
        format!(
            "let sim = mpm(#{{ dim: 3, origin: [0.0, 0.0, 0.0], cell: 1.0, cells: [1, 1, 1] }});\n\
             let rve = dem();\nrve.periodic([0.01, 0.01, 0.01]);\n\
             sim.material(\"dem_rve\", #{{ density: 1600.0, rve: rve, adaptive: {adaptive} }});"
        )
    };
    let e = run_err("rve_adaptive_misspelt", &script("#{ corsen: 0.01 }"), &[]);
    assert!(e.contains("adaptive_corsen") && e.contains("adaptive_coarsen") && e.contains("line 4"), "{e}");
    let e = run_err("rve_adaptive_refine", &script("#{ coarsen: 0.01, refine: 0.005 }"), &[]);
    assert!(e.contains("adaptive_refine") && e.contains("must exceed adaptive_coarsen") && e.contains("line 4"), "{e}");
    // A switch is true or false: 2.5 or 5 is neither, not "on".
    for (value, name) in [("2.5", "adaptive"), ("true, share: 5", "share")] {
        let e = run_err("rve_switch", &script(value), &[]);
        assert!(e.contains(&format!("`{name}`")) && e.contains("must be true or false") && e.contains("line 4"), "{e}");
    }
}

#[test]
fn a_bad_body_names_the_kind_the_parameter_and_the_line() {
    let head = "let sim = dem();\nlet m = sim.material(#{ density: 2500.0 });\n";
    let e = run_err(
        "capsule_radius",
        &format!("{head}sim.capsule(m, [0.0, 0.0, 0.0], #{{ radius: -0.01, length: 0.02 }});"),
        &[],
    );
    assert!(e.contains("line 3") && e.contains("`radius`") && e.contains("> 0"), "{e}");
    let e = run_err(
        "capsule_key",
        &format!("{head}sim.capsule(m, [0.0, 0.0, 0.0], #{{ radius: 0.01, lenght: 0.02 }});"),
        &[],
    );
    assert!(e.contains("line 3") && e.contains("lenght"), "{e}");
    let e = run_err("body_kind", &format!("{head}sim.add_body(\"cube\", m, [0.0, 0.0, 0.0], #{{ side: 0.01 }});"), &[]);
    assert!(e.contains("line 3") && e.contains("cube") && e.contains("capsule"), "{e}");
    let e = run_err(
        "capsule_length",
        &format!("{head}sim.periodic([0.1, 0.1, 0.1]);\nsim.capsule(m, [0.05, 0.05, 0.05], #{{ radius: 0.01, length: -0.02 }});"),
        &[],
    );
    assert!(e.contains("line 4") && e.contains("`length`") && e.contains(">= 0"), "{e}");
}

#[test]
fn a_bad_potential_particle_names_what_is_wrong_and_the_line() {
    let head = "let sim = dem();\nlet m = sim.material(#{ density: 2500.0 });\n";
    let e = run_err(
        "potential_shape",
        &format!("{head}sim.potential(m, [0.0, 0.0, 0.0], #{{ shape: \"capsule\" }});"),
        &[],
    );
    assert!(e.contains("line 3") && e.contains("potential_tetra") && e.contains("capsule"), "{e}");
    let e = run_err(
        "potential_plane",
        &format!(
            "{head}sim.potential(m, [0.0, 0.0, 0.0], #{{ planes: [[0.0, 0.0, 1.0]], r: 0.001, R: 0.004, k: 0.5 }});"
        ),
        &[],
    );
    assert!(e.contains("line 3") && e.contains("plane 1") && e.contains("[a, b, c, d]"), "{e}");
    let e = run_err(
        "potential_k",
        &format!("{head}sim.potential(m, [0.0, 0.0, 0.0], #{{ shape: \"potential_tetra\", k: 1.5 }});"),
        &[],
    );
    assert!(e.contains("line 3") && e.contains("`k`") && e.contains("(0, 1]"), "{e}");
}

/// A build without the `vtkhdf` feature refuses the format where the script asks for it, saying
/// how to get it.
#[cfg(not(feature = "vtkhdf"))]
#[test]
fn vtkhdf_in_a_build_without_it_says_how_to_build_it() {
    let e = run_err("no_vtkhdf", &format!("{HEAD}sim.vtk_format(\"vtkhdf\");"), &[]);
    assert!(e.contains("line 2") && e.contains("--features vtkhdf") && e.contains("libhdf5-dev"), "{e}");
}

/// The cell's volumetric strain is for linear shape functions: asked with others it is refused at
/// the line, and shape functions changed afterwards stop the run naming the choice.
#[test]
fn cell_volumetric_strain_needs_linear_shape_functions() {
    let body = "let m = sim.material(\"linear_elastic\", #{ density: 1e3, young: 1e6, poisson: 0.3 });\n\
                sim.fill_box(m, [0.0, 0.0], [0.2, 0.2], #{ per_cell: 2 });\n";
    let e = run_err(
        "bbar_gimp",
        &format!("{HEAD}{body}sim.shape_functions(\"gimp\");\nsim.volumetric_strain(\"cell\");"),
        &[],
    );
    assert!(e.contains("line 5") && e.contains("volumetric_strain") && e.contains("linear"), "{e}");
    let e = run_err(
        "bbar_then_gimp",
        &format!("{HEAD}{body}sim.volumetric_strain(\"cell\");\nsim.shape_functions(\"gimp\");\nsim.dt(1e-4);\nsim.run_steps(2);"),
        &[],
    );
    assert!(e.contains("volumetric_strain") && e.contains("linear shape functions only"), "{e}");
    let e = run_err("bbar_name", &format!("{HEAD}sim.volumetric_strain(\"centre\");"), &[]);
    assert!(e.contains("line 2") && e.contains("\"point\" or \"cell\""), "{e}");
}

/// A material changed by a name the simulation does not have is refused with the names it has.
#[test]
fn set_material_by_an_unknown_name_lists_the_materials() {
    let body =
        "let m = sim.material(\"linear_elastic\", #{ name: \"clay\", density: 1e3, young: 1e6, poisson: 0.3 });\n";
    let e = run_err("set_by_name", &format!("{HEAD}{body}sim.set_material(\"sand\", #{{ young: 2e6 }});"), &[]);
    assert!(e.contains("line 3") && e.contains("\"sand\"") && e.contains("\"clay\""), "{e}");
}

#[test]
fn a_negative_cloud_count_and_an_unknown_cell_update_are_refused_by_name() {
    let head = "let sim = dem();\nlet g = sim.material(#{ name: \"g\", density: 2000.0 });\n";
    for (name, call) in [
        ("cloud_count", "sim.cloud(g, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0], #{ count: -5, radius: 0.01 });"),
        (
            "clump_cloud_count",
            "sim.clump_cloud(g, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0], #{ count: -5, shape: \"tetra\" });",
        ),
    ] {
        let e = run_err(name, &format!("{head}{call}"), &[]);
        assert!(e.contains("line 3") && e.contains("`count` must be >= 0, got -5"), "{e}");
    }
    let e =
        run_err("cell_update", &format!("{head}sim.periodic([1.0, 1.0, 1.0]);\nsim.cell_update(\"lagrange\");"), &[]);
    assert!(e.contains("line 4") && e.contains("lagrange") && e.contains("sllod, newton, yade"), "{e}");
}
