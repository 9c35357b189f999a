//! Signals during `granite run`, sent for real: SIGINT and SIGTERM stop the run at its next step
//! with its outputs, summary.json and provenance.json written (status `interrupted`), a checkpoint
//! when the script asked for one, a line saying where it stopped, and exit code 130 or 143; a
//! second signal, a second or more after the first, ends the process at once.
#![cfg(unix)]

use crate::common;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// An MPM column that would run for hours, checkpointing every 200000 steps.
const ENDLESS: &str = r#"
let sim = mpm(#{ dim: 2, origin: [0.0, 0.0], cell: 0.1, cells: [10, 10] });
let soil = sim.material("mohr_coulomb", #{ name: "soil", density: 1800.0, young: 1e6, poisson: 0.3, friction: 30.0, cohesion: 0.0 });
sim.fill_box(soil, [0.0, 0.0], [0.5, 0.5], #{ per_cell: 2 });
sim.fix("x-", "x"); sim.fix("y-", "y");
sim.gravity([0.0, -9.81]);
sim.dt(1e-5);
sim.series_every(100);
sim.checkpoint_every(200000, "checkpoint.json");
sim.run_steps(100000000);
"#;

fn start(name: &str, source: &str) -> (Child, PathBuf) {
    let out = common::out_dir(name);
    std::fs::create_dir_all(&out).unwrap();
    let script = out.join("endless.rhai");
    std::fs::write(&script, source).unwrap();
    (common::spawn_running(&script, &out), out)
}

fn signal(child: &Child, signal: i32) {
    assert_eq!(unsafe { libc::kill(child.id() as i32, signal) }, 0, "kill");
}

fn finish(child: Child) -> (i32, String) {
    let out = child.wait_with_output().unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stderr).into_owned())
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn sigint_and_sigterm_stop_the_run_cleanly_and_it_resumes_from_its_checkpoint() {
    for (sig, name, code) in [(libc::SIGINT, "SIGINT", 130), (libc::SIGTERM, "SIGTERM", 143)] {
        let (child, out) = start(&format!("signal_{name}"), ENDLESS);
        signal(&child, sig);
        let (exit, stderr) = finish(child);
        assert_eq!(exit, code, "{name}: {stderr}");
        let summary = json(&out.join("summary.json"));
        assert_eq!(summary["status"], "interrupted", "{summary}");
        assert_eq!(summary["signal"], name);
        assert_eq!(json(&out.join("provenance.json"))["status"], "interrupted");
        // The line on stderr says where it stopped and how to resume.
        let step = common::stopped_at_step(&stderr);
        assert!(stderr.contains("checkpoint") && stderr.contains("mpm_load"), "{stderr}");
        // The series ends on that step, and the checkpoint holds it.
        let (header, rows) = common::read_csv(&out.join("series.csv"));
        assert_eq!(rows.last().unwrap()[common::column(&header, "step")], step as f64);
        let checkpoint = out.join("checkpoint.json");
        let resume = format!(
            "let sim = mpm_load({:?});\nsummary(\"step\", sim.step);\nsim.run_steps(10);\n",
            checkpoint.to_str().unwrap()
        );
        let resumed = common::out_dir(&format!("signal_{name}_resumed"));
        let options = granite_script::RunOptions { out_dir: resumed.clone(), quiet: true, ..Default::default() };
        granite_script::run_source("resume.rhai", &resume, granite::registry(), options).unwrap();
        assert_eq!(json(&resumed.join("summary.json"))["step"], step);
    }
}

#[test]
fn a_second_signal_ends_the_process_at_once() {
    // 10000 points: the way out (the last frame, a checkpoint of several MB) takes a while, and
    // the second signal comes during it. (Two signals sent back to back would merge into one.)
    let big = ENDLESS.replace("cells: [10, 10]", "cells: [100, 100]").replace("[0.5, 0.5]", "[5.0, 5.0]");
    let (child, out) = start("signal_twice", &big);
    signal(&child, libc::SIGINT);
    // The first signal was taken once the way out has begun: its VTK frame is there.
    let started = Instant::now();
    while !out.join("vtk").join("points_000001.vtu").exists() {
        assert!(started.elapsed() < Duration::from_secs(60), "the run did not stop");
        std::thread::sleep(Duration::from_millis(1));
    }
    // A signal within a second of the first repeats it (`timeout` signals twice): held there
    // until that second has passed, the process then gets a second signal of its own.
    signal(&child, libc::SIGSTOP);
    std::thread::sleep(Duration::from_millis(1100));
    signal(&child, libc::SIGINT);
    signal(&child, libc::SIGCONT);
    let (exit, stderr) = finish(child);
    assert_eq!(exit, 130, "{stderr}");
    assert!(stderr.contains("a second signal: stopped at once"), "{stderr}");
}

/// A signal is honoured within a second during a long generation call (a cloud that cannot fit
/// tries for minutes) and during script code, and the message names the signal.
#[test]
fn signals_stop_long_calls_and_script_code_naming_the_signal() {
    let cases = [
        (
            "signal_cloud",
            "let sim = dem();\nlet m = sim.material(#{ density: 2500.0 });\nprint_line(\"busy\");\n\
             sim.cloud(m, [0.0, 0.0, 0.0], [0.1, 0.1, 0.1], #{ count: 1000000, radius: 0.004 });\n",
            "while placing spheres",
        ),
        ("signal_loop", "print_line(\"busy\");\nlet x = 0;\nloop { x += 1; }\n", "line 3"),
    ];
    for (name, source, says) in cases {
        let out = common::out_dir(name);
        std::fs::create_dir_all(&out).unwrap();
        let script = out.join("busy.rhai");
        std::fs::write(&script, source).unwrap();
        let mut child = Command::new(env!("CARGO_BIN_EXE_granite"))
            .args(["run", "--quiet", "--threads", "1", "--out"])
            .arg(&out)
            .arg(&script)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // The script says when it starts the call or the loop; a moment later it is busy in it.
        let mut said = String::new();
        std::io::BufRead::read_line(&mut std::io::BufReader::new(child.stdout.take().unwrap()), &mut said).unwrap();
        assert_eq!(said.trim(), "busy");
        std::thread::sleep(Duration::from_millis(300));
        let sent = Instant::now();
        signal(&child, libc::SIGTERM);
        let (exit, stderr) = finish(child);
        let took = sent.elapsed();
        assert_eq!(exit, 143, "{name}: {stderr}");
        assert!(stderr.contains("stopped by SIGTERM") && stderr.contains(says), "{name}: {stderr}");
        assert!(!stderr.contains("Ctrl-C"), "{name}: {stderr}");
        assert!(took < Duration::from_secs(5), "{name}: {took:?} after the signal");
        assert_eq!(json(&out.join("summary.json"))["status"], "interrupted");
    }
}

/// A signal that lands in script code the run calls (a per-step callback, a series column) or in
/// plain script code between runs stops the run as at a step's end: the series ends on the state
/// after the last whole step, the checkpoint asked for holds it (written on the way out although
/// none was due yet), and stderr says where it stopped and how to resume. The script code is the
/// bulk of each step here, so the signal lands in it.
#[test]
fn a_signal_in_a_callback_a_series_column_or_between_runs_still_writes_the_checkpoint() {
    let busy = "let busy = 0; for i in 0..20000 { busy += i; }";
    let cases = [
        ("signal_in_callback", format!("sim.every(1, |s| {{ {busy} }});\nsim.run_steps(100000000);")),
        (
            "signal_in_column",
            format!(
                "sim.series_every(1);\nsim.series_column(\"busy\", |s| {{ {busy} 1.0 }});\nsim.run_steps(100000000);"
            ),
        ),
        ("signal_between_runs", format!("loop {{ sim.run_steps(10); {busy} }}")),
    ];
    for (name, tail) in cases {
        let source = ENDLESS
            .replace("sim.series_every(100);", "sim.series_every(10);")
            .replace("sim.run_steps(100000000);\n", &tail);
        let (child, out) = start(name, &source);
        std::thread::sleep(Duration::from_millis(200));
        signal(&child, libc::SIGTERM);
        let (exit, stderr) = finish(child);
        assert_eq!(exit, 143, "{name}: {stderr}");
        assert_eq!(json(&out.join("summary.json"))["status"], "interrupted");
        let step = common::stopped_at_step(&stderr);
        assert!(stderr.contains("checkpoint") && stderr.contains("mpm_load"), "{name}: {stderr}");
        let (header, rows) = common::read_csv(&out.join("series.csv"));
        assert_eq!(rows.last().unwrap()[common::column(&header, "step")], step as f64, "{name}");
        if name == "signal_in_column" {
            assert_eq!(rows.last().unwrap()[common::column(&header, "busy")], 1.0, "{name}: the column computed");
        }
        assert_eq!(json(&out.join("checkpoint.json"))["state"]["step"], step, "{name}");
    }
}
