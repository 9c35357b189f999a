//! The `granite` command as a user runs it.

use crate::common;
use std::process::Command;

fn granite() -> Command {
    Command::new(env!("CARGO_BIN_EXE_granite"))
}

#[test]
fn version_and_help() {
    let out = granite().arg("--version").output().unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains(env!("CARGO_PKG_VERSION")));
    let out = granite().args(["run", "--help"]).output().unwrap();
    assert!(String::from_utf8_lossy(&out.stdout).contains("--set"));
}

#[test]
fn run_writes_the_output_contract() {
    let dir = common::out_dir("cli_cube");
    let out = granite()
        .args(["run", "scripts/mpm/bouncing_cube.rhai", "--quiet", "--threads", "1", "--set", "duration=0.1", "--out"])
        .arg(&dir)
        .current_dir(common::root())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (header, rows) = common::read_csv(&dir.join("series.csv"));
    for col in ["step", "time", "kinetic_energy", "elastic_energy", "gravitational_energy", "max_height"] {
        common::column(&header, col);
    }
    assert!(rows.len() > 10);
    let summary: serde_json::Value = common::summary_of(&dir);
    assert_eq!(summary["status"], "ok");
    let pvd = std::fs::read_to_string(dir.join("vtk/points.pvd")).unwrap();
    assert!(pvd.contains("points_000000.vtu"));
    // Binary appended data after the XML header: read as bytes.
    let vtu = String::from_utf8_lossy(&std::fs::read(dir.join("vtk/points_000000.vtu")).unwrap()).to_string();
    assert!(vtu.contains("NumberOfPoints=\"27\"") && vtu.contains("Name=\"stress\""));
    let prov: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("provenance.json")).unwrap()).unwrap();
    assert!(prov["program"].as_str().unwrap().contains(env!("CARGO_PKG_VERSION")));
    assert_eq!(prov["parameters"]["duration"], 0.1);
    assert_eq!(prov["threads"], 1);
    assert!(prov["script_hash"].as_str().unwrap().starts_with("fnv1a64:"));
    assert!(prov["plugins"]["constitutive_laws"].as_array().unwrap().iter().any(|l| l == "mohr_coulomb"));
}

#[test]
fn unknown_parameter_fails_with_the_declared_list() {
    let dir = common::out_dir("cli_unknown");
    let out = granite()
        .args(["run", "scripts/mpm/bouncing_cube.rhai", "--quiet", "--set", "sceme=USL", "--out"])
        .arg(&dir)
        .current_dir(common::root())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("sceme") && err.contains("scheme, update, flip_ratio, duration"), "{err}");
    // Said at the line of the script's first simulation (bouncing_cube.rhai line 18: `mpm(...)`),
    // where its parameters are all declared, with the closest name.
    assert!(err.contains("line 18: --set sceme") && err.contains("did you mean `scheme`?"), "{err}");
}

#[test]
fn params_lists_values_limits_and_comments_without_running() {
    let list = |sets: &[&str]| {
        let mut cmd = granite();
        cmd.args(["run", "scripts/dem/triaxial_periodic.rhai", "--list-params"]).current_dir(common::root());
        for s in sets {
            cmd.args(["--set", s]);
        }
        cmd.output().unwrap()
    };
    let out = list(&["friction=20"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().find(|l| l.trim_start().starts_with("friction ")).expect("a friction line");
    assert!(
        line.contains("20.0 (default 30.0)") && line.contains(">= 0 and < 90") && line.contains("inter-particle"),
        "{line}"
    );
    assert!(text.contains("confining") && text.contains("> 0") && text.contains("P_c, Pa"), "{text}");
    // The listing stops before the first simulation: no compaction, no run.
    assert!(!text.contains("compacted") && !text.contains("granite: done"), "{text}");
    // Values are checked as a run checks them.
    let out = list(&["friction=95"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    let source = std::fs::read_to_string(common::root().join("scripts/dem/triaxial_periodic.rhai")).unwrap();
    let line = 1 + source.lines().position(|l| l.contains("param(\"friction\"")).expect("a friction parameter");
    assert!(err.contains(&format!("line {line}:")) && err.contains("`friction` must be >= 0 and < 90"), "{err}");
}

#[test]
fn plot_writes_an_svg() {
    let dir = common::out_dir("cli_plot");
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("series.csv");
    std::fs::write(&csv, "step,time,kinetic_energy,runout\n0,0,1.0,0\n1,0.1,0.5,0.2\n2,0.2,0.25,0.3\n").unwrap();
    let out =
        granite().args(["plot"]).arg(&csv).args(["--x", "time", "--y", "kinetic_energy,runout"]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let svg = std::fs::read_to_string(dir.join("plot_kinetic_energy_runout.svg")).unwrap();
    assert!(svg.len() > 1000 && svg.contains("<svg") && svg.contains("polyline"), "an SVG with lines");
    // Energy and length on axes of their own, each labelled with its unit.
    assert!(svg.matches("<polyline").count() >= 2);
    assert!(
        svg.contains("time [s]") && svg.contains("runout [m]") && svg.contains("kinetic_energy [J"),
        "axes with units"
    );
    let bad = granite().args(["plot"]).arg(&csv).args(["--y", "nope"]).output().unwrap();
    assert!(!bad.status.success() && String::from_utf8_lossy(&bad.stderr).contains("time, kinetic_energy, runout"));
}

/// A plot named .png is a bitmap drawn with the font built into granite: its lines in their
/// colours and its text (the title band holds dark pixels) without any font on the machine.
#[test]
fn plot_writes_a_png_with_its_text() {
    let dir = common::out_dir("cli_plot_png");
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("series.csv");
    std::fs::write(&csv, "step,time,kinetic_energy,runout\n0,0,1.0,0\n1,0.1,0.5,0.2\n2,0.2,0.25,0.3\n").unwrap();
    let png = dir.join("energy.png");
    let out = granite()
        .args(["plot"])
        .arg(&csv)
        .args(["--x", "time", "--y", "kinetic_energy,runout", "--out"])
        .arg(&png)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut pixels = vec![0; reader.output_buffer_size()];
    let frame = reader.next_frame(&mut pixels).unwrap();
    assert_eq!(frame.color_type, png::ColorType::Rgb);
    let (width, height) = (frame.width as usize, frame.height as usize);
    // Two panels (J and m): 2 x (120 + 2 x 380) pixels high, 1800 wide.
    assert_eq!((width, height), (1800, 2 * (120 + 2 * 380)));
    let rgb = |i: usize| (pixels[3 * i], pixels[3 * i + 1], pixels[3 * i + 2]);
    let count =
        |from: usize, to: usize, want: &dyn Fn((u8, u8, u8)) -> bool| (from..to).filter(|&i| want(rgb(i))).count();
    let all = width * height;
    assert!(count(0, all, &|c| c == (0, 0, 255)) > 500, "the first series' blue line");
    assert!(count(0, all, &|c| c == (255, 0, 0)) > 500, "the second series' red line");
    let title_band = 40 * width;
    assert!(count(0, title_band, &|(r, g, b)| r < 100 && g < 100 && b < 100) > 200, "the title's letters");
    let bad =
        granite().args(["plot"]).arg(&csv).args(["--y", "runout", "--out"]).arg(dir.join("x.jpg")).output().unwrap();
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success() && err.contains("`.jpg`") && err.contains(".svg or .png"), "{err}");
}

/// `granite batch` of bouncing_cube.rhai over the parameter file `toml`, two jobs at a time,
/// into `DIR/runs` of a fresh folder named `name`; the folder and the command's output.
fn batch(name: &str, toml: &str) -> (std::path::PathBuf, std::process::Output) {
    let dir = common::out_dir(name);
    std::fs::create_dir_all(&dir).unwrap();
    let params = dir.join("params.toml");
    std::fs::write(&params, toml).unwrap();
    let out = granite()
        .args(["batch", "scripts/mpm/bouncing_cube.rhai", "--jobs", "2", "--quiet", "--params"])
        .arg(&params)
        .arg("--out")
        .arg(dir.join("runs"))
        .current_dir(common::root())
        .output()
        .unwrap();
    (dir, out)
}

#[test]
fn batch_runs_every_set_and_reports_a_failure() {
    // Three runs; the last asks for a velocity update that does not exist (the script declares
    // no limits for it, so the run itself finds out).
    let (dir, out) = batch(
        "cli_batch",
        "[grid]\nduration = 0.02\n[[set]]\nupdate = \"FLIP\"\n[[set]]\nupdate = \"PIC\"\n[[set]]\nupdate = \"XYZ\"\n",
    );
    assert!(!out.status.success(), "a failed run makes the batch fail");
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("3 runs, 2 ok, 1 failed"),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let (h, rows) = common::read_csv(&dir.join("runs/batch_summary.csv"));
    assert_eq!(rows.len(), 3);
    let exit = common::column(&h, "exit_code");
    assert_eq!((rows[0][exit], rows[1][exit]), (0.0, 0.0));
    assert_ne!(rows[2][exit], 0.0);
    common::column(&h, "final_total_energy");
    for k in 0..3 {
        assert!(dir.join(format!("runs/run_{k:03}/summary.json")).exists());
        assert!(dir.join(format!("runs/run_{k:03}/stdout.log")).exists());
    }
    let log = std::fs::read_to_string(dir.join("runs/run_002/stderr.log")).unwrap();
    assert!(log.contains("XYZ"), "the failed run's stderr.log says why: {log}");
}

/// A value outside a parameter's declared limits is found before any run starts, naming the run.
#[test]
fn batch_checks_every_set_before_running() {
    let (dir, out) =
        batch("cli_batch_check", "[grid]\nduration = 0.02\n[[set]]\nscheme = \"USF\"\n[[set]]\nscheme = \"XYZ\"\n");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("run 1 [scheme=XYZ duration=0.02] would fail before it starts"), "{err}");
    assert!(!dir.join("runs/run_000").exists(), "no run started");
}

#[test]
fn counts_out_of_range_are_refused_by_the_command_line() {
    // Each would have run something meaningless (no threads, 100 000 threads being created,
    // a benchmark of zero runs printing NaN speed-ups) instead of saying what is allowed.
    let threads = format!("thread count from 1 to {}", granite::MAX_THREADS);
    let too_many = (granite::MAX_THREADS + 1).to_string();
    for (args, says) in [
        (&["run", "scripts/mpm/bouncing_cube.rhai", "--threads", "0"][..], threads.as_str()),
        (&["run", "scripts/mpm/bouncing_cube.rhai", "--threads", &too_many][..], threads.as_str()),
        (&["bench", "dem", "--repeat", "0"][..], "whole number >= 1"),
        (&["bench", "mpm", "--threads", "1,0"][..], threads.as_str()),
        (&["bench", "triaxial", "--axial-strain", "nan"][..], "strain in (0, 1)"),
    ] {
        let out = granite().current_dir(common::root()).args(args).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
}

/// Default output intervals follow the run's length up to each call's end: a loop of short calls
/// (the YADE way of running until a condition holds) writes about 20 frames and 500 series rows
/// each time its step count doubles, not 20 frames and 500 rows per call.
#[test]
fn a_loop_of_short_runs_does_not_flood_the_output() {
    let (calls, steps) = (64u32, 100u64);
    let src = format!(
        "let sim = dem(#{{ seed: 1 }});\n\
         let m = sim.material(#{{ name: \"glass\", density: 2500.0 }});\n\
         sim.contact_law(\"linear\", #{{ kn: 1.0e4, kt_ratio: 0.5, friction: 30.0 }});\n\
         sim.sphere(m, [0.0, 0.0, 0.0], 0.01, #{{ velocity: [0.1, 0.0, 0.0] }});\n\
         sim.dt(1.0e-4);\n\
         for k in 0..{calls} {{ sim.run_steps({steps}); }}\n"
    );
    let out = common::run_text("loop_output", &src);
    let frames = std::fs::read_dir(out.join("vtk"))
        .unwrap()
        .filter(|e| e.as_ref().is_ok_and(|e| e.path().extension().is_some_and(|x| x == "vtu")));
    let (_, rows) = common::read_csv(&out.join("series.csv"));
    // log2(64) = 6 doublings after the first call's 20 frames and 500 rows.
    let doublings = (calls as f64).log2() + 1.0;
    let frames = frames.count() as f64;
    assert!(frames <= 20.0 * (doublings + 1.0), "{frames} frames for {calls} calls");
    assert!(rows.len() as f64 <= 500.0 * (doublings + 1.0), "{} rows for {calls} calls", rows.len());
    // Still a full run's worth: every doubling writes some.
    assert!(frames >= 20.0 * doublings / 2.0, "only {frames} frames");
}

/// docs/api.md is what `granite api` prints: the reference and the REPL's `:help` come from one
/// table, so the reference cannot go stale without this test failing.
#[test]
fn the_api_reference_is_generated_from_the_table() {
    let out = granite().arg("api").output().unwrap();
    assert!(out.status.success());
    let written = std::fs::read_to_string(common::root().join("docs/api.md")).unwrap();
    assert!(
        written == String::from_utf8_lossy(&out.stdout),
        "docs/api.md differs from `granite api`: regenerate it with `granite api > docs/api.md`"
    );
    let help = granite().args(["api", "sim.gravty"]).output().unwrap();
    assert!(String::from_utf8_lossy(&help.stderr).contains("did you mean `gravity`?"));
}

/// Started by `mpirun -np 2` without the `mpi` feature, each process would run the whole
/// simulation and write the same files: refused, saying how to build for MPI.
#[cfg(not(feature = "mpi"))]
#[test]
fn a_build_without_mpi_refuses_to_run_as_one_of_several_mpi_processes() {
    let dir = common::out_dir("cli_not_mpi");
    let out = granite()
        .args(["run", "scripts/mpm/bouncing_cube.rhai", "--quiet", "--out"])
        .arg(&dir)
        .current_dir(common::root())
        .env("OMPI_COMM_WORLD_SIZE", "2")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("2 MPI processes") && stderr.contains("--features mpi"), "{stderr}");
    assert!(!dir.join("summary.json").exists(), "nothing written");
}

/// A point thrown out of the mesh is deleted with a warning (speed 0: none).
const LEAVES_THE_MESH: &str = "let speed = param(\"speed\", 5.0);\n\
    let sim = mpm(#{ dim: 2, origin: [0.0, 0.0], cell: 0.1, cells: [4, 4] });\n\
    let s = sim.material(\"linear_elastic\", #{ name: \"s\", density: 1000.0, young: 1e5, poisson: 0.3 });\n\
    sim.fill_box(s, [0.3, 0.0], [0.4, 0.1], #{ per_cell: 1, velocity: [speed, 0.0] });\n\
    sim.dt(1e-3);\nsim.run_steps(50);\n";

/// `--quiet` hides progress, not warnings; warnings go to summary.json and batch_summary.csv too.
#[test]
fn warnings_reach_stderr_under_quiet_summary_json_and_the_batch_summary() {
    let dir = common::out_dir("cli_warnings");
    std::fs::create_dir_all(&dir).unwrap();
    let script = dir.join("leaves.rhai");
    std::fs::write(&script, LEAVES_THE_MESH).unwrap();
    let out = granite().args(["run", "--quiet", "--out"]).arg(dir.join("run")).arg(&script).output().unwrap();
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("left the mesh"), "the warning under --quiet: {stderr}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("run/summary.json")).unwrap()).unwrap();
    let warnings = summary["warnings"].as_array().expect("summary.json lists the warnings");
    assert!(warnings.iter().any(|w| w.as_str().unwrap().contains("left the mesh")), "{warnings:?}");
    let params = dir.join("params.toml");
    std::fs::write(&params, "[[set]]\nspeed = 5.0\n[[set]]\nspeed = 0.0\n").unwrap();
    let out = granite()
        .args(["batch"])
        .arg(&script)
        .arg("--params")
        .arg(&params)
        .arg("--out")
        .arg(dir.join("batch"))
        .args(["--quiet"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mut csv = csv::Reader::from_path(dir.join("batch/batch_summary.csv")).unwrap();
    let header = csv.headers().unwrap().clone();
    let column = header.iter().position(|h| h == "warnings").expect("a warnings column");
    let rows: Vec<csv::StringRecord> = csv.records().map(|r| r.unwrap()).collect();
    assert!(rows[0][column].contains("left the mesh"), "{:?}", &rows[0]);
    assert_eq!(&rows[1][column], "", "the run at rest has none");
}

/// A batch stopped by SIGTERM passes the signal on to its runs, which stop cleanly, lists the
/// runs it did not start, writes batch_summary.csv and exits 143; a run past --run-timeout is
/// stopped and reported; a summary value named like a parameter gets a column of its own; the
/// error column holds a run's whole error message.
#[cfg(unix)]
#[test]
fn a_batch_passes_signals_on_limits_run_time_and_keeps_one_header_per_column() {
    let dir = common::out_dir("cli_batch_signal");
    std::fs::create_dir_all(&dir).unwrap();
    let script = dir.join("endless.rhai");
    std::fs::write(
        &script,
        r#"let k = param("k", 1);
let steps = param("steps", 100000000);
let sim = mpm(#{ dim: 2, origin: [0.0, 0.0], cell: 0.1, cells: [10, 10] });
let soil = sim.material("linear_elastic", #{ density: 1800.0, young: 1e6, poisson: 0.3 });
sim.fill_box(soil, [0.0, 0.0], [0.5, 0.5], #{ per_cell: 2 });
sim.fix("y-", "y");
sim.gravity([0.0, -9.81]);
sim.dt(1e-5);
sim.series_every(100);
summary("k", k);
if k == 3 { throw "a first line\nand a second line"; }
sim.run_steps(steps);
"#,
    )
    .unwrap();
    let params = dir.join("params.toml");
    std::fs::write(&params, "[grid]\nk = [1, 2, 3, 4]\n").unwrap();
    let batch = |out: &str, extra: &[&str]| {
        let mut cmd = granite();
        cmd.args(["batch", "--quiet", "--jobs", "2", "--params"]).arg(&params).arg("--out").arg(dir.join(out));
        cmd.args(extra).arg(&script);
        cmd
    };
    let mut child = batch("stopped", &[]).stdout(std::process::Stdio::null()).spawn().unwrap();
    let started = std::time::Instant::now();
    while !(1..=2).all(|k| dir.join(format!("stopped/run_{:03}/series.csv", k - 1)).exists()) {
        assert!(started.elapsed() < std::time::Duration::from_secs(60), "the runs did not start");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGTERM) }, 0);
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(143));
    let mut csv = csv::Reader::from_path(dir.join("stopped/batch_summary.csv")).unwrap();
    let header: Vec<String> = csv.headers().unwrap().iter().map(String::from).collect();
    let mut unique = header.clone();
    unique.sort();
    unique.dedup();
    assert_eq!(unique.len(), header.len(), "a column twice: {header:?}");
    assert!(header.contains(&"k".to_string()) && header.contains(&"summary_k".to_string()), "{header:?}");
    let rows: Vec<csv::StringRecord> = csv.records().map(|r| r.unwrap()).collect();
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let statuses: Vec<&str> = rows.iter().map(|r| &r[col("status")]).collect();
    assert_eq!(statuses, ["interrupted", "interrupted", "not run", "not run"]);
    for k in 0..2 {
        let summary: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join(format!("stopped/run_{k:03}/summary.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!((summary["status"].as_str(), summary["signal"].as_str()), (Some("interrupted"), Some("SIGTERM")));
    }
    // A time limit, and a run failing with an error of two lines.
    let out = batch("limited", &["--run-timeout", "1"]).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let mut csv = csv::Reader::from_path(dir.join("limited/batch_summary.csv")).unwrap();
    let header: Vec<String> = csv.headers().unwrap().iter().map(String::from).collect();
    let rows: Vec<csv::StringRecord> = csv.records().map(|r| r.unwrap()).collect();
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let statuses: Vec<&str> = rows.iter().map(|r| &r[col("status")]).collect();
    assert_eq!(statuses, ["timed out", "timed out", "failed", "timed out"]);
    let error = &rows[2][col("error")];
    assert!(error.contains("a first line\nand a second line"), "{error}");
    assert!(rows[0][col("error")].contains("--run-timeout"), "{}", &rows[0][col("error")]);
}

/// A misspelt parameter name in a batch file is refused before any run starts.
#[test]
fn batch_refuses_a_misspelt_parameter_before_any_run() {
    let (dir, out) = batch("cli_batch_misspelt", "[grid]\nduraton = [0.02, 0.04]\n");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("declares no parameter `duraton` (did you mean `duration`?)"), "{err}");
    assert!(!dir.join("runs/run_000").exists(), "no run started");
}

/// The end of a run prints its summary for a person: long arrays by their ends and length,
/// numbers to six significant digits, counts as integers; summary.json keeps them whole.
#[test]
fn the_end_of_a_run_prints_short_values() {
    let dir = common::out_dir("cli_shown");
    std::fs::create_dir_all(&dir).unwrap();
    let script = dir.join("shown.rhai");
    std::fs::write(
        &script,
        "let sim = dem();\nlet m = sim.material(#{ density: 1000.0 });\nsim.contact_law(\"linear\", #{ kn: 1e4 });\n\
         sim.sphere(m, [0.0, 0.0, 0.0], 0.01);\nsim.sphere(m, [0.0, 0.0, 0.0199], 0.01);\nsim.dt(1e-5);\nsim.run_steps(3);\n\
         let d = sim.diagnostics();\nsummary(\"contacts\", d.contacts);\nsummary(\"ratio\", 1.1749999999999998);\n\
         let times = [];\nfor k in 0..1200 { times.push(k.to_float() * 0.5); }\nsummary(\"times\", times);\n",
    )
    .unwrap();
    let out = granite().args(["run", "--threads", "1", "--out"]).arg(&dir).arg(&script).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("  contacts = 1\n"), "{stdout}");
    assert!(stdout.contains("  ratio = 1.175\n"), "{stdout}");
    assert!(stdout.contains("  times = [0, 0.5, 1, ..., 599.5] (1200 values)\n"), "{stdout}");
    let summary: serde_json::Value = common::summary_of(&dir);
    assert_eq!(summary["times"].as_array().unwrap().len(), 1200);
    assert_eq!(summary["ratio"], 1.1749999999999998);
    assert!(summary["contacts"].is_i64());
}

/// `--list-params` works on every script of scripts/ from the repository root, as README shows
/// it: files a script reads before its first simulation (a mesh) are found in its folder.
#[test]
fn every_script_lists_its_parameters_from_the_repository_root() {
    let mut scripts: Vec<std::path::PathBuf> = ["mpm", "dem", "mpmxdem"]
        .iter()
        .flat_map(|d| std::fs::read_dir(common::root().join("scripts").join(d)).unwrap().flatten().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "rhai"))
        .collect();
    scripts.sort();
    assert!(scripts.len() > 10);
    for script in scripts {
        let relative = script.strip_prefix(common::root()).unwrap();
        let out = granite().arg("run").arg(relative).arg("--list-params").current_dir(common::root()).output().unwrap();
        assert!(out.status.success(), "{}: {}", relative.display(), String::from_utf8_lossy(&out.stderr));
        assert!(String::from_utf8_lossy(&out.stdout).contains("parameter(s) declared"), "{}", relative.display());
    }
}
