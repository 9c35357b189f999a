//! A Rust program runs an engine with the output contract of a script run, without Rhai: the
//! physics it gets, the files it writes, a checkpoint that resumes bit for bit, a failed step that
//! falls back on the last good state.

#[path = "../examples/self_weight.rs"]
mod self_weight;

use granite_core::mpm::{MpmSim, OutOfMeshPolicy};
use granite_run::{MpmScene, RunContext, Runner};
use self_weight::Column;
use std::path::{Path, PathBuf};

fn column() -> Column {
    Column { width: 0.2, height: 1.0, cell: 0.05, density: 2000.0, young: 1e8 }
}

fn out_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn quiet() -> RunContext {
    RunContext { program: "granite-run test".into(), quiet: true, ..Default::default() }
}

fn runner(sim: MpmSim, dir: &Path) -> Runner<MpmScene> {
    let mut runner = Runner::new(MpmScene::new(sim), dir, quiet());
    runner.output.series_every = Some(50);
    runner.output.vtk_every = Some(500);
    runner
}

/// Rows of a CSV file: its header and values.
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines.map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    (header, rows)
}

#[test]
fn a_rust_program_settles_a_column_to_its_overburden_and_writes_the_output_contract() {
    let registry = granite_plugins::default_registry();
    let column = column();
    let dir = out_dir("rust_driver_settles");
    let mut runner = runner(column.build(&registry).unwrap(), &dir);
    runner.checkpoint = Some((5000, "checkpoint.json".into()));
    runner.run_until(1.0).unwrap();
    runner.write_summary().unwrap();

    // Physics: at rest sigma_yy = -rho g (H - y), cell row by cell row (linear shape functions
    // make the stress uniform in a cell; 3 % covers the rows next to the floor).
    let profile = column.stress_profile(&runner.sim.mpm);
    assert!(profile.len() >= 15, "{} rows checked", profile.len());
    for (y, s, expected) in profile {
        assert!(
            (s - expected).abs() < 0.03 * expected.abs(),
            "y = {y:.3}: sigma_yy = {s:.1} Pa, overburden {expected:.1} Pa"
        );
    }

    // The output contract: series rows on their interval to the last step, settled at the end.
    let (header, rows) = read_csv(&dir.join("series.csv"));
    let (step, kinetic) = (0, header.iter().position(|h| h == "kinetic_energy").unwrap());
    assert_eq!(header[step], "step");
    let steps = runner.sim.mpm.step as f64;
    assert_eq!(rows.last().unwrap()[step], steps);
    assert_eq!(
        rows.len(),
        1 + (runner.sim.mpm.step / 50) as usize + usize::from(!runner.sim.mpm.step.is_multiple_of(50))
    );
    assert!(rows.last().unwrap()[kinetic] < 1e-6, "kinetic energy {}", rows.last().unwrap()[kinetic]);
    let pvd = std::fs::read_to_string(dir.join("vtk/points.pvd")).unwrap();
    let frames = pvd.matches("<DataSet").count() as u64;
    // The first frame, one every 500 steps, and the call's last state.
    let last = u64::from(!runner.sim.mpm.step.is_multiple_of(500));
    assert_eq!(frames, 1 + runner.sim.mpm.step / 500 + last, "frames in points.pvd");
    let saved = MpmSim::load(&dir.join("checkpoint.json"), &registry).unwrap();
    assert_eq!(saved.step, runner.sim.mpm.step / 5000 * 5000);
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["step"].as_f64(), Some(steps));
    assert!(summary["kinetic_energy"].as_f64().unwrap() < 1e-6);
}

#[test]
fn a_checkpoint_written_by_the_runner_resumes_bit_for_bit_and_continues_the_series() {
    let registry = granite_plugins::default_registry();
    let column = column();
    let straight_dir = out_dir("rust_driver_straight");
    let mut straight = runner(column.build(&registry).unwrap(), &straight_dir);
    straight.run_steps(600).unwrap();

    let resumed_dir = out_dir("rust_driver_resumed");
    let mut first = runner(column.build(&registry).unwrap(), &resumed_dir);
    first.checkpoint = Some((300, "checkpoint.json".into()));
    first.run_steps(300).unwrap();
    drop(first);
    let loaded = MpmSim::load(&resumed_dir.join("checkpoint.json"), &registry).unwrap();
    let mut second = runner(loaded, &resumed_dir);
    second.run_steps(300).unwrap();

    let (a, b) = (&straight.sim.mpm.points, &second.sim.mpm.points);
    assert_eq!(second.sim.mpm.step, 600);
    assert!(a.x == b.x && a.v == b.v && a.stress == b.stress, "the resumed run parted from the straight one");
    // Row intervals follow each call's length (600 / 500 and 300 / 500 round to 1): set here to
    // 50 in both, the files must be the same bytes.
    let series = |dir: &Path| std::fs::read(dir.join("series.csv")).unwrap();
    assert_eq!(series(&straight_dir), series(&resumed_dir), "series.csv differs");
}

#[test]
fn a_step_that_loses_a_point_restores_the_last_good_state_and_writes_it() {
    let registry = granite_plugins::default_registry();
    let dir = out_dir("rust_driver_lost_point");
    let mut sim = column().build(&registry).unwrap();
    // Thrown upwards out of a mesh as high as the column, with a run told to stop on a lost point.
    sim.out_of_mesh = OutOfMeshPolicy::Stop;
    sim.points.v.iter_mut().for_each(|v| v[1] = 20.0);
    let mut runner = runner(sim, &dir);
    let e = runner.run_steps(2000).unwrap_err().to_string();
    let failed = runner.failed_at_step.expect("the failed step is kept");
    assert!(e.contains("the last good state"), "{e}");
    assert!(
        failed > 0 && runner.sim.mpm.step < failed,
        "state at step {} after failing at {failed}",
        runner.sim.mpm.step
    );
    let height = column().height;
    assert!(runner.sim.mpm.points.x.iter().all(|x| x[1] < height), "a point outside the mesh was kept");
    assert!(dir.join("last_good_points.csv").exists());
    assert_eq!(runner.summary["failed_at_step"].as_u64(), Some(failed));
}

/// A probe given in the run context follows the runs from another thread: the calls, the steps
/// of the last one done against those asked, and the simulated time it reached.
#[test]
fn a_progress_probe_follows_the_runs() {
    let registry = granite_plugins::default_registry();
    let dir = out_dir("rust_driver_probe");
    let probe = std::sync::Arc::new(granite_run::ProgressProbe::default());
    let context = RunContext { progress: Some(probe.clone()), ..quiet() };
    let mut runner = Runner::new(MpmScene::new(column().build(&registry).unwrap()), &dir, context);
    runner.run_steps(30).unwrap();
    runner.run_steps(20).unwrap();
    let reading = probe.read();
    assert_eq!((reading.calls, reading.done, reading.total), (2, 20, 20));
    assert_eq!(reading.time, runner.sim.mpm.time);
}
