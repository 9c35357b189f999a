//! Where a script's files go and come from, and values checked where they are given.

use granite_script::{run_source, RunOptions};

use crate::common;

fn run(name: &str, out: &std::path::Path, source: &str) -> granite_core::Result<granite_script::RunReport> {
    let options = RunOptions { out_dir: out.to_path_buf(), quiet: true, ..Default::default() };
    run_source(&format!("{name}.rhai"), source, granite::registry(), options)
}

const ONE_SPHERE: &str = r#"
let sim = dem();
let m = sim.material(#{ density: 1000.0 });
sim.contact_law("linear", #{ kn: 1.0 });
sim.sphere(m, [0.0, 0.0, 0.0], 0.1);
sim.dt(1e-3);
"#;

/// Each simulation of a REPL session writes into its own folder; `sim.save(name)` writes into it
/// and `dem_load(name)` finds the file there.
#[test]
fn repl_simulations_have_their_own_folders() {
    let out = common::out_dir("outputs_repl");
    let mut session = granite_script::repl::ReplSession::new(
        granite::registry(),
        RunOptions { out_dir: out.clone(), quiet: true, ..Default::default() },
    )
    .unwrap();
    use granite_script::repl::Outcome;
    let ok = |o: Outcome| assert!(matches!(o, Outcome::Value(_)), "{o:?}");
    ok(session.eval(&format!("{ONE_SPHERE} sim.run_steps(10); sim.save(\"state.json\");"), false));
    ok(session.eval("let again = dem_load(\"state.json\"); again.run_steps(5);", false));
    session.finish();
    assert!(out.join("sim1/series.csv").is_file() && out.join("sim1/state.json").is_file());
    assert!(out.join("sim2/series.csv").is_file() && out.join("sim2/vtk/points.pvd").is_file());
    assert!(!out.join("series.csv").exists());
}

/// In a script the first simulation that writes uses the run's folder; a second one `sim2/`.
/// A run into a folder that holds more frames of an earlier run leaves none of them.
#[test]
fn script_simulations_and_stale_frames() {
    let out = common::out_dir("outputs_script");
    let long = format!("{ONE_SPHERE} sim.vtk_every(1); sim.run_steps(30);");
    run("long", &out, &long).unwrap();
    let frames = |dir: &std::path::Path| {
        std::fs::read_dir(dir)
            .unwrap()
            .filter(|e| e.as_ref().is_ok_and(|e| e.file_name().to_string_lossy().starts_with("points_")))
            .count()
    };
    assert_eq!(frames(&out.join("vtk")), 31);
    let short = format!("{ONE_SPHERE} sim.vtk_every(1); sim.run_steps(3);\nlet other = dem(); other.write_vtk();");
    run("short", &out, &short).unwrap();
    assert_eq!(frames(&out.join("vtk")), 4, "the earlier run's frames 4 to 30 are gone");
    assert!(out.join("sim2/vtk/points.pvd").is_file());
}

/// A time step above the stability limit is refused where it is set, not at the next run.
#[test]
fn a_time_step_is_checked_where_it_is_set() {
    let out = common::out_dir("outputs_dt");
    let dem = format!("{ONE_SPHERE}\nsim.dt(100.0);\n");
    let e = run("dem_dt", &out, &dem).unwrap_err().to_string();
    assert!(e.contains("line 8") && e.contains("`dt` = 1e2") && e.contains("must not exceed"), "{e}");
    let mpm = r#"
let sim = mpm(#{ dim: 2, origin: [0.0, 0.0], cell: 0.1, cells: [4, 4] });
let m = sim.material("linear_elastic", #{ density: 1000.0, young: 1e6, poisson: 0.3 });
sim.fill_box(m, [0.0, 0.0], [0.2, 0.2]);
sim.dt(1.0);
"#;
    let e = run("mpm_dt", &out, mpm).unwrap_err().to_string();
    assert!(e.contains("line 5") && e.contains("stability limit"), "{e}");
}

/// `unbalanced_force` (mean resultant on the free spheres over the mean contact force) has no
/// value before a contact touches: that row's cell is empty, not NaN. A sphere resting on a floor
/// under its weight, with its spring's overlap at equilibrium, is balanced: near 0 once damped.
#[test]
fn unbalanced_force_is_empty_until_a_contact_carries_a_force() {
    let out = common::out_dir("outputs_unbalanced");
    let (kn, mass) = (1e4, 1000.0 * 4.0 / 3.0 * std::f64::consts::PI * 0.01f64.powi(3));
    let rest = 0.01 - mass * 9.81 / kn;
    let source = format!(
        "let sim = dem();\nlet m = sim.material(#{{ density: 1000.0 }});\n\
         sim.contact_law(\"linear\", #{{ kn: {kn} }});\nsim.wall_plane(m, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]);\n\
         sim.sphere(m, [0.0, 0.0, {rest}], 0.01);\nsim.gravity([0.0, 0.0, -9.81]);\nsim.damping(0.2);\n\
         sim.dt(0.1 * sim.critical_dt());\nsim.series_every(100);\nsim.run_steps(1000);\n"
    );
    run("unbalanced", &out, &source).unwrap();
    let text = std::fs::read_to_string(out.join("series.csv")).unwrap();
    let mut lines = text.lines();
    let column = lines.next().unwrap().split(',').position(|c| c == "unbalanced_force").unwrap();
    let cells: Vec<String> = lines.map(|l| l.split(',').nth(column).unwrap().to_string()).collect();
    assert_eq!(cells[0], "", "step 0: no contact yet");
    let last: f64 = cells.last().unwrap().parse().unwrap();
    assert!(last.abs() < 1e-3, "at rest on the floor: {text}");
}
