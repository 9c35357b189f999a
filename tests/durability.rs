//! Long runs that never lose data, tried as a user's runs meet trouble: killed (SIGKILL) while
//! checkpointing, a disk that fills up, a file-size limit, standard error closed or full, a
//! resume into the folder of the run it continues, `timeout -s INT` (a signal sent twice).
#![cfg(unix)]

use crate::common;
use granite_core::mpm::MpmSim;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn block(cells: usize, extra: &str) -> String {
    common::settling_block(cells, extra)
}

fn run_in(out: &Path, source: &str, pairs: &[(&str, &str)]) -> granite_script::RunReport {
    common::run_source_in(out, "block.rhai", source, pairs)
}

fn write_script(dir: &Path, source: &str) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let path = dir.join("block.rhai");
    std::fs::write(&path, source).unwrap();
    path
}

fn granite() -> Command {
    Command::new(env!("CARGO_BIN_EXE_granite"))
}

fn json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}: {text:?}", path.display()))
}

/// Every line of a series file is a whole row: its header's column count of numbers, each row
/// ending with a line end. The steps of its rows.
fn whole_rows(path: &Path) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.ends_with('\n'), "{} ends inside a row", path.display());
    let (header, rows) = common::read_csv(path);
    for row in &rows {
        assert!(row.len() == header.len() && row.iter().all(|v| v.is_finite()), "{}: {row:?}", path.display());
    }
    rows.iter().map(|r| r[common::column(&header, "step")]).collect()
}

#[test]
fn a_run_killed_while_checkpointing_always_leaves_a_loadable_checkpoint_and_its_earlier_rows() {
    // 1600 points: a checkpoint of about 0.5 MB, written and flushed at every step, so that most
    // kills fall inside a checkpoint's write.
    let base = common::out_dir("durability_kill");
    let script = write_script(&base, &block(40, "sim.series_every(1);\nsim.checkpoint_every(1, \"ck.json\");"));
    let out = base.join("run");
    let registry = granite::registry();
    // Kills at times spread over 0.3 s after each run's first checkpoint, the same ones every time.
    let mut lcg: u64 = 0x9e37_79b9_7f4a_7c15;
    let (trials, mut fell_back) = (100, 0);
    let ck = out.join("ck.json");
    for trial in 0..trials {
        lcg = lcg.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        let delay = Duration::from_micros((lcg >> 33) % 300_000);
        let _ = std::fs::remove_dir_all(&out);
        common::kill_after_first_checkpoint(&script, &out, &ck, delay, trial);
        // The newest checkpoint is never a cut one: it is replaced whole or not at all.
        let sim = MpmSim::load(&ck, &registry)
            .unwrap_or_else(|e| panic!("trial {trial} (killed after {delay:?}): ck.json: {e}"));
        let (newest, read, note) = MpmSim::load_newest(&ck, &registry).unwrap();
        assert_eq!(read, ck);
        fell_back += usize::from(note.is_some());
        assert_eq!(newest.step, sim.step);
        // The rows before the checkpoint's step are all there (its own row follows it).
        let steps = whole_rows_allowing_cut_end(&out.join("series.csv"));
        let expected: Vec<f64> = (0..sim.step).map(|s| s as f64).collect();
        assert!(
            steps.len() >= expected.len() && steps[..expected.len()] == expected[..],
            "trial {trial}: {} rows for a checkpoint at step {}",
            steps.len(),
            sim.step
        );
    }
    println!("{trials} runs killed while checkpointing every step: every ck.json loaded");
    assert_eq!(fell_back, 0, "ck.json itself loaded every time");
}

/// The steps of a series file's whole rows; a kill may cut its last row (a resume drops it).
fn whole_rows_allowing_cut_end(path: &Path) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let whole = &text[..text.rfind('\n').map_or(0, |i| i + 1)];
    whole.lines().skip(1).map(|l| l.split(',').next().unwrap().parse::<f64>().unwrap()).collect()
}

/// A disk that fills up mid-run (a 2 MB tmpfs in a private namespace); where no such mount is
/// allowed, the file-size-limit test covers the same path.
#[test]
fn a_full_disk_fails_the_run_with_the_file_and_step_and_keeps_a_checkpoint_and_whole_rows() {
    if !common::can_mount_tmpfs() {
        return;
    }
    // 400 points (a checkpoint of about 0.13 MB) writing a VTK frame every step into 2 MB.
    let base = common::out_dir("durability_disk_full");
    let script = write_script(
        &base,
        &block(20, "sim.series_every(1);\nsim.vtk_every(1);\nsim.checkpoint_every(5, \"ck.json\");"),
    );
    let kept = base.join("kept");
    let status = Command::new("unshare")
        .args(["-rm", "sh", "-c"])
        .arg(
            "d=$(mktemp -d) && mount -t tmpfs -o size=2m none \"$d\" && \
             \"$0\" run --quiet --threads 1 --out \"$d/out\" \"$1\" >\"$2/stdout.txt\" 2>\"$2/stderr.txt\"; \
             echo $? >\"$2/code.txt\"; cp -a \"$d/out\" \"$2/out\"",
        )
        .arg(env!("CARGO_BIN_EXE_granite"))
        .arg(&script)
        .arg(&base)
        .status()
        .unwrap();
    assert!(status.success());
    let code = std::fs::read_to_string(base.join("code.txt")).unwrap();
    let stderr = std::fs::read_to_string(base.join("stderr.txt")).unwrap();
    assert_eq!(code.trim(), "1", "{stderr}");
    // The message says which file failed first, at which step, and why.
    assert!(stderr.contains("No space left on device"), "{stderr}");
    let step = common::stopped_at_step(&stderr);
    assert!(stderr.contains("/out/"), "the file is named: {stderr}");
    let out = kept.join("out").canonicalize().unwrap_or_else(|_| base.join("out"));
    let ck = out.join("ck.json");
    let sim = MpmSim::load(&ck, &granite::registry()).unwrap_or_else(|e| panic!("{e}; {stderr}"));
    assert!(sim.step > 0 && sim.step <= step, "checkpoint at {} for a failure at {step}", sim.step);
    let rows = whole_rows(&out.join("series.csv"));
    assert!(rows.len() as u64 >= sim.step, "{} rows, checkpoint at step {}", rows.len(), sim.step);
    let summary = json(&out.join("summary.json"));
    assert_eq!(summary["status"], "failed", "{summary}");
    assert!(summary["error"].as_str().unwrap().contains("No space left on device"), "{summary}");
    // Nothing half-written is left under a real name: each frame the .pvd lists opens whole.
    let pvd = std::fs::read_to_string(out.join("vtk/points.pvd")).unwrap();
    for file in pvd.split("file=\"").skip(1).map(|s| s.split('"').next().unwrap()) {
        let frame = std::fs::read(out.join("vtk").join(file)).unwrap();
        assert!(frame.ends_with(b"</VTKFile>\n"), "{file} is cut");
    }
}

#[test]
fn a_file_size_limit_fails_the_run_naming_the_file_the_step_and_the_cause() {
    // `ulimit -f 200`: 100 kB a file; the checkpoint of 1600 points is larger.
    let base = common::out_dir("durability_fsize");
    let script = write_script(&base, &block(40, "sim.series_every(1);\nsim.checkpoint_every(20, \"ck.json\");"));
    let out = base.join("out");
    let (code, stderr) = common::run_under_limit("ulimit -f 200", &script, &out);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("at step 20 ") && stderr.contains("ck.json") && stderr.contains("File too large"),
        "{stderr}"
    );
    assert!(!out.join("ck.json").exists() && !out.join(".ck.json.partial").exists(), "no cut checkpoint is left");
    assert_eq!(whole_rows(&out.join("series.csv")), (0..20).map(|s| s as f64).collect::<Vec<_>>());
    let summary = json(&out.join("summary.json"));
    assert_eq!(summary["status"], "failed");
    assert!(summary["error"].as_str().unwrap().contains("at step 20"), "{summary}");
}

#[test]
fn a_resumed_run_continues_the_series_and_the_frames_of_the_run_it_resumes() {
    let out = common::out_dir("durability_resume");
    let outputs = "sim.series_every(10);\nsim.vtk_every(100);\nif !resume { sim.checkpoint_every(200, \"ck.json\"); }";
    let source = block(10, outputs);
    let run = |pairs: &[(&str, &str)]| run_in(&out, &source, pairs);
    run(&[("steps", "300")]);
    let first = std::fs::read_to_string(out.join("series.csv")).unwrap();
    // Resumed from the checkpoint of step 200, to step 400.
    let report = run(&[("resume", "true"), ("steps", "200")]);
    assert_eq!(report.summary["end_step"], 400);
    let steps = whole_rows(&out.join("series.csv"));
    assert_eq!(steps, (0..=40).map(|k| 10.0 * k as f64).collect::<Vec<_>>(), "one row every 10 steps, none twice");
    // The rows before step 200 are the first run's, byte for byte.
    let resumed = std::fs::read_to_string(out.join("series.csv")).unwrap();
    let before: String = first.lines().take(21).map(|l| format!("{l}\n")).collect();
    assert!(resumed.starts_with(&before));
    // Frames of steps 0 and 100 from the first run, 200 to 400 from the resumed one, in order.
    let pvd = std::fs::read_to_string(out.join("vtk/points.pvd")).unwrap();
    let times: Vec<f64> =
        pvd.split("timestep=\"").skip(1).map(|s| s.split('"').next().unwrap().parse().unwrap()).collect();
    let dt = 1e-4;
    assert_eq!(times.len(), 5, "{pvd}");
    for (k, t) in times.iter().enumerate() {
        assert!((t - 100.0 * k as f64 * dt).abs() < 1e-9, "frame {k} at t = {t}");
    }
    for k in 0..5 {
        assert!(out.join(format!("vtk/points_{k:06}.vtu")).is_file());
    }
    assert!(!out.join("vtk/points_000005.vtu").exists());
}

/// A run resumed from a checkpoint between two frames (step 250 of frames every 100) writes no
/// frame at its first step: its frames are those of a run that never stopped, again and again.
#[test]
fn a_run_resumed_between_two_frames_adds_no_frame() {
    let times = |dir: &Path| -> Vec<f64> {
        let pvd = std::fs::read_to_string(dir.join("vtk/points.pvd")).unwrap();
        pvd.split("timestep=\"").skip(1).map(|s| s.split('"').next().unwrap().parse().unwrap()).collect()
    };
    let straight = common::out_dir("durability_frames_straight");
    let outputs = "sim.series_every(10);\nsim.vtk_every(100);\nsim.checkpoint_every(250, \"ck.json\");";
    let source = block(6, outputs);
    run_in(&straight, &source, &[("steps", "800")]);
    let out = common::out_dir("durability_frames_resumed");
    run_in(&out, &source, &[("steps", "300")]);
    // Three resumes from steps 250, 500 and 750, each run a little past its next checkpoint (a
    // kill would leave the frames after it, which the resume replaces).
    for (from, to) in [(250, 550), (500, 780), (750, 800)] {
        let report = run_in(&out, &source, &[("resume", "true"), ("steps", &(to - from).to_string())]);
        assert_eq!(report.summary["end_step"], to);
    }
    assert_eq!(times(&out), times(&straight), "the frames of a run that never stopped");
    assert_eq!(times(&out).len(), 9);
}

#[test]
fn standard_error_and_output_closed_or_full_never_fail_a_run() {
    // APIC on linear shape functions warns; print_line writes to standard output.
    let base = common::out_dir("durability_stderr");
    let script = write_script(&base, &block(4, "sim.velocity_update(\"APIC\");\nprint_line(\"hello\");"));
    // Full: every write fails with "No space left on device".
    let out = base.join("full");
    let full = || std::fs::File::create("/dev/full").unwrap();
    let run = granite()
        .args(["run", "--threads", "1", "--set", "steps=50", "--out"])
        .arg(&out)
        .arg(&script)
        .stdout(full())
        .stderr(full())
        .status()
        .unwrap();
    assert_eq!(run.code(), Some(0));
    let summary = json(&out.join("summary.json"));
    assert_eq!(summary["status"], "ok");
    let warnings = summary["warnings"].as_array().unwrap();
    assert!(warnings.iter().any(|w| w.as_str().unwrap().contains("APIC")), "the warning is kept: {summary}");
    // Closed: the reader of a pipe has left.
    let out = base.join("closed");
    let mut child = granite()
        .args(["run", "--threads", "1", "--set", "steps=50", "--out"])
        .arg(&out)
        .arg(&script)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    drop(child.stderr.take());
    assert_eq!(child.wait().unwrap().code(), Some(0));
    assert_eq!(json(&out.join("summary.json"))["status"], "ok");
}

#[test]
fn timeout_s_int_which_signals_twice_still_ends_the_run_cleanly() {
    let base = common::out_dir("durability_timeout");
    let script = write_script(&base, &block(20, "sim.series_every(100);\nsim.checkpoint_every(1000000, \"ck.json\");"));
    for k in 0..3 {
        let out = base.join(format!("run{k}"));
        let started = Instant::now();
        let run = Command::new("timeout")
            .args(["--preserve-status", "-s", "INT", "2.5"])
            .arg(env!("CARGO_BIN_EXE_granite"))
            .args(["run", "--quiet", "--threads", "1", "--out"])
            .arg(&out)
            .arg(&script)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(130), "{stderr}");
        assert!(started.elapsed() < Duration::from_secs(30));
        let summary = json(&out.join("summary.json"));
        assert_eq!(summary["status"], "interrupted", "{summary}");
        assert_eq!(summary["signal"], "SIGINT");
        MpmSim::load(&out.join("ck.json"), &granite::registry()).unwrap();
    }
    // The same without a race: held stopped, the run is sent SIGINT and SIGTERM (two signals of
    // different numbers do not merge), then let go; it gets both at once and stops cleanly.
    let out = base.join("both");
    let child = common::spawn_running(&script, &out);
    for signal in [libc::SIGSTOP, libc::SIGINT, libc::SIGTERM, libc::SIGCONT] {
        assert_eq!(unsafe { libc::kill(child.id() as i32, signal) }, 0);
    }
    let done = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&done.stderr);
    assert!(!stderr.contains("a second signal"), "{stderr}");
    let summary = json(&out.join("summary.json"));
    assert_eq!(summary["status"], "interrupted", "{summary}");
    MpmSim::load(&out.join("ck.json"), &granite::registry()).unwrap();
}

#[test]
fn scripts_cannot_write_over_the_run_own_files_or_outside_its_folder() {
    let base = common::out_dir("durability_paths");
    for (extra, expected) in [
        ("sim.checkpoint_every(5, \"series.csv\");", "the run writes that file itself"),
        ("sim.checkpoint_every(5, \"vtk/points.pvd\");", "the run writes that file itself"),
        ("sim.save(\"../escaped.json\");", "relative path without `..`"),
        ("sim.write_points(\"/tmp/granite_points.csv\");", "relative path without `..`"),
        ("plot(\"series.csv\", \"time\", [\"kinetic_energy\"], \"/tmp/granite_plot.svg\");", "relative path"),
    ] {
        let e = common::run_text_err("durability_paths", &block(2, extra).replace("param(\"steps\", 100000)", "10"));
        assert!(e.contains(expected) && e.contains("line "), "{extra}: {e}");
    }
    assert!(!base.parent().unwrap().join("escaped.json").exists());
    // An error about a file that is not a series does not print its content.
    let secret = common::out_dir("durability_secret");
    std::fs::create_dir_all(&secret).unwrap();
    let file = secret.join("passwd");
    std::fs::write(&file, "root:x:0:0:hunter2:/root:/bin/bash\n").unwrap();
    let e = common::run_text_err("durability_plot", &format!("plot({:?}, \"time\", [\"x\"], \"p.svg\");", file));
    assert!(e.contains("no column") || e.contains("unknown column"), "{e}");
    assert!(!e.contains("hunter2"), "{e}");
}

/// Symbolic links left in a reused or shared output folder are never written through: a file
/// of the run's that is a link (series.csv, summary.json, a checkpoint, a frame, a partial file)
/// is replaced by the run's own file in the folder (a series a resume continues is read through
/// it, then written in the folder), and a folder the run writes into that is a link (`vtk/`, a
/// folder of `sim.save`) is refused, naming the link. The files the links point to are left as
/// they were.
#[test]
fn links_in_the_output_folder_are_not_followed() {
    let out = common::out_dir("durability_links");
    let outside = common::out_dir("durability_links_outside");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::create_dir_all(outside.join("vtk")).unwrap();
    let untouched = "not granite's\n";
    let links =
        ["series.csv", "summary.json", "ck.json", ".ck.json.partial", "vtk/points_000000.vtu", "vtk/points.pvd"];
    let link_files = |dir: &Path| {
        std::fs::create_dir_all(dir.join("vtk")).unwrap();
        for name in links {
            std::fs::write(outside.join(name), untouched).unwrap();
            std::os::unix::fs::symlink(outside.join(name), dir.join(name)).unwrap();
        }
    };
    link_files(&out);
    let source = block(2, "sim.series_every(5);\nsim.vtk_every(5);\nsim.checkpoint_every(10, \"ck.json\");");
    run_in(&out, &source, &[("steps", "20")]);
    for name in links {
        assert_eq!(std::fs::read_to_string(outside.join(name)).unwrap(), untouched, "{name} was written through");
        let meta = std::fs::symlink_metadata(out.join(name));
        assert!(meta.as_ref().map_or(true, |m| !m.file_type().is_symlink()), "{name} is still a link");
    }
    assert_eq!(whole_rows(&out.join("series.csv")), [0.0, 5.0, 10.0, 15.0, 20.0]);
    // A resume continues series.csv: a link there (to a series with the same columns) is read,
    // and replaced by the continued series in the folder.
    let series = std::fs::read_to_string(out.join("series.csv")).unwrap();
    std::fs::write(outside.join("series.csv"), &series).unwrap();
    std::fs::remove_file(out.join("series.csv")).unwrap();
    std::os::unix::fs::symlink(outside.join("series.csv"), out.join("series.csv")).unwrap();
    run_in(&out, &source, &[("resume", "true"), ("steps", "5")]);
    assert_eq!(std::fs::read_to_string(outside.join("series.csv")).unwrap(), series);
    assert!(!std::fs::symlink_metadata(out.join("series.csv")).unwrap().file_type().is_symlink());
    assert_eq!(whole_rows(&out.join("series.csv")), [0.0, 5.0, 10.0, 15.0, 20.0, 25.0]);
    // Folders: vtk/ and a folder the script saves into.
    for (folder, extra) in [("vtk", "sim.vtk_every(5);"), ("states", "sim.save(\"states/a.json\");")] {
        let fresh = common::out_dir(&format!("durability_links_{folder}"));
        std::fs::create_dir_all(&fresh).unwrap();
        std::os::unix::fs::symlink(outside.join("vtk"), fresh.join(folder)).unwrap();
        let e = common::run_source_in_err(&fresh, &block(2, extra), &[("steps", "5")]);
        assert!(e.contains(&format!("{folder} is a symbolic link")), "{folder}: {e}");
    }
    assert_eq!(std::fs::read_dir(outside.join("vtk")).unwrap().count(), 2, "nothing new outside");
}

/// A checkpoint cut after it was written (a disk that lied about its flush, a copy cut short) is
/// not resumed from: the one before it is, with a warning, and provenance.json says which file
/// and step the run continued from.
#[test]
fn a_cut_checkpoint_falls_back_on_the_one_before_and_provenance_names_it() {
    let out = common::out_dir("durability_fallback");
    let source = block(10, "if !resume { sim.checkpoint_every(200, \"ck.json\"); }");
    let run = |pairs: &[(&str, &str)]| run_in(&out, &source, pairs);
    run(&[("steps", "450")]);
    let ck = out.join("ck.json");
    let text = std::fs::read(&ck).unwrap();
    std::fs::write(&ck, &text[..text.len() / 2]).unwrap();
    let report = run(&[("resume", "true"), ("steps", "10")]);
    assert_eq!(report.summary["end_step"], 210, "resumed from the checkpoint of step 200");
    let warnings = report.summary["warnings"].as_array().unwrap();
    assert!(warnings.iter().any(|w| w.as_str().unwrap().contains("ck.prev.json was loaded instead")), "{warnings:?}");
    let provenance = json(&out.join("provenance.json"));
    let loaded = &provenance["loaded"][0];
    assert_eq!(loaded["step"], 200, "{provenance}");
    assert!(loaded["file"].as_str().unwrap().ends_with("ck.prev.json"), "{loaded}");
    assert!(loaded["fallback"].as_str().unwrap().contains("ck.json"), "{loaded}");
}
