//! MPMxDEM over MPI processes (`cargo test --features mpi --test integration mpi::`, Open MPI's `mpirun` on
//! the PATH): the same script gives byte-identical results on 1, 2 and 3 processes and without
//! MPI, a checkpoint written on 2 processes continues on 3 and without MPI bit for bit, and an
//! RVE failing on rank 1, or a checkpoint the first process cannot write, stops every process
//! with the cause named.
#![cfg(feature = "mpi")]

use crate::common;
use common::*;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// A small RVE (100 spheres at 1 kPa), prepared once for every test of this file.
fn rve() -> &'static Path {
    static RVE: OnceLock<PathBuf> = OnceLock::new();
    RVE.get_or_init(|| {
        let prep = run(
            "mpmxdem/prepare_rve.rhai",
            "mpi_rve",
            &[("count", "100"), ("p_init", "1000"), ("vertical_axis", "1")],
            2,
        )
        .expect("preparing the RVE");
        prep.out_dir.join("rve.json")
    })
}

fn test_script(name: &str) -> PathBuf {
    root().join("tests").join("mpi").join(name)
}

/// `mpirun -np N granite run SCRIPT --set ...` into a fresh folder; (exit code, stderr, folder).
fn mpirun(np: usize, script: &str, name: &str, sets: &[(&str, &str)]) -> (i32, String, PathBuf) {
    let out = out_dir(name);
    let (code, stderr) = mpirun_granite(np, &test_script(script), &out, sets);
    (code, stderr, out)
}

/// The same script without MPI, in this process.
fn alone(script: &str, name: &str, sets_: &[(&str, &str)]) -> granite_core::Result<PathBuf> {
    granite::run(&test_script(script), sets(sets_), Some(out_dir(name)), true, Some(1)).map(|r| r.out_dir)
}

fn bytes(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// summary.json without what differs from run to run (times) and what depends on how the
/// points are spread over processes (their share of the work, what exact sharing of RVEs
/// within a process spared).
fn results(dir: &Path) -> serde_json::Map<String, serde_json::Value> {
    let text = std::fs::read_to_string(dir.join("summary.json")).unwrap();
    let serde_json::Value::Object(mut map) = serde_json::from_str(&text).unwrap() else { panic!("summary.json") };
    for key in [
        "wall_time_s",
        "processes",
        "rank_busy_fraction",
        "rank_imbalance",
        "rank_points",
        "objects_moved",
        "rve_sphere_steps_shared",
        "rve_sphere_steps_computed",
    ] {
        map.remove(key);
    }
    map
}

#[test]
fn one_two_and_three_processes_write_the_same_bytes_as_a_run_without_mpi() {
    let rve = rve().to_str().unwrap();
    let sets = [("rve", rve), ("steps", "60"), ("balance_every", "10")];
    let reference = alone("spread_column.rhai", "mpi_alone", &sets).unwrap();
    for np in [1, 2, 3] {
        let (code, stderr, out) = mpirun(np, "spread_column.rhai", &format!("mpi_np{np}"), &sets);
        assert_eq!(code, 0, "{np} processes: {stderr}");
        for file in ["series.csv", "half.json", "rve_point5.vtu"] {
            assert!(bytes(&reference.join(file)) == bytes(&out.join(file)), "{np} processes: {file} differs");
        }
        assert_eq!(results(&reference), results(&out), "{np} processes: summary.json differs");
        let summary: serde_json::Value = common::summary_of(&out);
        if np > 1 {
            // Every process reports its share, and the RVEs are all somewhere.
            let points: Vec<u64> =
                summary["rank_points"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
            assert_eq!(points.len(), np);
            let (header, rows) = read_csv(&reference.join("series.csv"));
            let count = rows.last().unwrap()[column(&header, "points")] as u64;
            assert_eq!(points.iter().sum::<u64>(), count, "{count} material points over {np} processes: {points:?}");
            let busy = summary["rank_busy_fraction"].as_array().unwrap();
            assert!(busy.iter().all(|b| b.as_f64().is_some_and(|b| (0.0..=1.0).contains(&b))), "{busy:?}");
        }
    }
}

#[test]
fn adaptive_rves_decide_the_same_on_one_two_and_three_processes() {
    let rve = rve().to_str().unwrap();
    let sets = [("rve", rve), ("steps", "60"), ("balance_every", "10"), ("adaptive", "true")];
    let reference = alone("spread_column.rhai", "mpi_adaptive_alone", &sets).unwrap();
    let summary = results(&reference);
    let followed = summary["rve_point_steps_followed"].as_f64().unwrap();
    assert!(followed > 0.0, "no point followed another: the test would not test the activation");
    for np in [2, 3] {
        let (code, stderr, out) = mpirun(np, "spread_column.rhai", &format!("mpi_adaptive_np{np}"), &sets);
        assert_eq!(code, 0, "{np} processes: {stderr}");
        for file in ["series.csv", "half.json", "rve_point5.vtu"] {
            assert!(bytes(&reference.join(file)) == bytes(&out.join(file)), "{np} processes: {file} differs");
        }
        assert_eq!(summary, results(&out), "{np} processes: summary.json differs");
    }
}

#[test]
fn a_run_saved_on_two_processes_continues_on_three_and_without_mpi_bit_for_bit() {
    let rve = rve().to_str().unwrap();
    let sets = [("rve", rve), ("steps", "60"), ("balance_every", "10")];
    let (code, stderr, saved) = mpirun(2, "spread_column.rhai", "mpi_saved_on_2", &sets);
    assert_eq!(code, 0, "{stderr}");
    let checkpoint = saved.join("half.json");
    let checkpoint = checkpoint.to_str().unwrap();
    let resume = [("resume", checkpoint), ("steps", "60"), ("balance_every", "7")];
    let (code, stderr, on3) = mpirun(3, "spread_column.rhai", "mpi_resumed_on_3", &resume);
    assert_eq!(code, 0, "{stderr}");
    let without = alone("spread_column.rhai", "mpi_resumed_alone", &resume).unwrap();
    // The resumed series starts at the checkpoint's step (30) and must be the saved run's rows from there.
    let full = String::from_utf8(bytes(&saved.join("series.csv"))).unwrap();
    let from_half: Vec<&str> = full.lines().skip_while(|l| !l.starts_with("30,")).collect();
    assert!(from_half.len() > 5, "the full run's series reaches past step 30");
    for resumed in [&on3, &without] {
        let text = String::from_utf8(bytes(&resumed.join("series.csv"))).unwrap();
        let rows: Vec<&str> = text.lines().skip(1).collect();
        assert_eq!(rows, from_half, "{}: the resumed run departs from the uninterrupted one", resumed.display());
        assert_eq!(results(resumed), results(&saved), "{}: summary.json", resumed.display());
    }
}

#[test]
fn an_rve_failing_on_rank_1_stops_every_process_naming_the_point_and_the_rank() {
    let rve = rve().to_str().unwrap();
    let started = std::time::Instant::now();
    let (code, stderr, out) = mpirun(2, "failing_rve.rhai", "mpi_failing", &[("rve", rve)]);
    assert_ne!(code, 0, "the run must fail: {stderr}");
    assert!(
        started.elapsed().as_secs() < granite::END_GRACE_S,
        "both processes stop together, without waiting for the grace period of a lone failure"
    );
    let summary: serde_json::Value = common::summary_of(&out);
    assert_eq!(summary["status"], "failed");
    let error = summary["error"].as_str().unwrap();
    assert!(error.contains("RVE of point 1") && error.contains("rank 1 of 2"), "{error}");
    assert!(error.contains("max_dem_steps"), "says what to change: {error}");
    assert!(out.join("last_good_points.csv").is_file(), "the last good state is written");
    assert!(stderr.contains("rank 1 of 2"), "the error reaches the terminal: {stderr}");
    // Without MPI the same point fails with the same message, less the rank.
    let alone = alone("failing_rve.rhai", "mpi_failing_alone", &[("rve", rve)]).unwrap_err().to_string();
    assert!(alone.contains("RVE of point 1") && !alone.contains("rank"), "{alone}");
}

#[test]
fn a_checkpoint_the_first_process_cannot_write_stops_every_process() {
    let rve = rve().to_str().unwrap();
    let started = std::time::Instant::now();
    // series.csv is a file: no folder can be made under it.
    let sets = [("rve", rve), ("steps", "10"), ("checkpoint", "series.csv/half.json")];
    let (code, stderr, out) = mpirun(2, "spread_column.rhai", "mpi_cannot_write", &sets);
    assert_ne!(code, 0, "the run must fail: {stderr}");
    assert!(started.elapsed().as_secs() < granite::END_GRACE_S, "both processes stop together");
    let summary: serde_json::Value = common::summary_of(&out);
    assert_eq!(summary["status"], "failed");
    let error = summary["error"].as_str().unwrap();
    assert!(error.contains("half.json") && error.contains("line"), "names the file and the script line: {error}");
}

/// `mpirun -np N granite run spread_column.rhai` stepping without end into `out`, with
/// `--mpi-timeout timeout_s`; returned once it steps, with the granite processes' ids (their
/// command lines name the folder, as mpirun's does).
fn endless_run(np: usize, timeout_s: &str, out: &Path) -> (std::process::Child, Vec<i32>) {
    let rve = rve().to_str().unwrap();
    let mut cmd = Command::new("mpirun");
    let version = Command::new("mpirun").arg("--version").output().expect("mpirun on the PATH (Open MPI)");
    if String::from_utf8_lossy(&version.stdout).contains("Open MPI") {
        cmd.args(["--allow-run-as-root", "--oversubscribe"]);
        cmd.env("OMPI_MCA_mpi_yield_when_idle", "1");
    }
    cmd.args(["-np", &np.to_string(), env!("CARGO_BIN_EXE_granite"), "run"]).arg(test_script("spread_column.rhai"));
    cmd.args(["--quiet", "--threads", "1", "--mpi-timeout", timeout_s, "--out"]).arg(out);
    cmd.args(["--set", &format!("rve={rve}"), "--set", "steps=1000000"]);
    let child = cmd.stderr(std::process::Stdio::piped()).spawn().expect("running mpirun");
    // Every process steps once series.csv has rows past its first.
    common::wait_until_running(out, std::time::Duration::from_secs(120));
    let listed = Command::new("pgrep").args(["-f", &format!("granite run .*{}", out.display())]).output().unwrap();
    let pids: Vec<i32> = String::from_utf8_lossy(&listed.stdout)
        .lines()
        .filter_map(|l| l.trim().parse().ok())
        .filter(|&pid| pid != child.id() as i32)
        .collect();
    assert_eq!(pids.len(), np, "{pids:?}");
    (child, pids)
}

/// Whether process `pid` has ended (a zombie counts as ended).
fn gone(pid: i32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .map_or(true, |s| s.rsplit(')').next().and_then(|r| r.split_whitespace().next()) == Some("Z"))
}

/// A process that stops answering (here frozen by SIGSTOP) ends the run on every process once
/// another has waited `--mpi-timeout` seconds for it, with status failed and the cause named,
/// instead of leaving them waiting without limit.
#[test]
fn a_frozen_process_ends_the_run_on_every_process_after_the_timeout() {
    let out = out_dir("mpi_frozen");
    let (child, pids) = endless_run(2, "3", &out);
    assert_eq!(unsafe { libc::kill(pids[1], libc::SIGSTOP) }, 0);
    let frozen = std::time::Instant::now();
    let finished = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&finished.stderr);
    assert_ne!(finished.status.code(), Some(0), "{stderr}");
    assert!(frozen.elapsed() < std::time::Duration::from_secs(60), "{:?} after the freeze", frozen.elapsed());
    assert!(stderr.contains("stopped answering") && stderr.contains("--mpi-timeout 3 s"), "{stderr}");
    let summary: serde_json::Value = common::summary_of(&out);
    assert_eq!(summary["status"], "failed", "{summary}");
    assert!(summary["error"].as_str().unwrap().contains("stopped answering"), "{summary}");
    // The launcher ends the frozen one too (a moment after it returns).
    let waited = std::time::Instant::now();
    while !pids.iter().all(|&pid| gone(pid)) {
        assert!(waited.elapsed() < std::time::Duration::from_secs(30), "a process of the run is still there: {pids:?}");
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
}

/// No process outlives its job. Of three processes, one is frozen (SIGSTOP) and the launcher is
/// killed (SIGKILL: it can pass nothing on): the two left waiting for the frozen one in an
/// exchange end within seconds, as does the frozen one once it runs again, instead of waiting
/// out `--mpi-timeout` or for good. (Open MPI 4.1 ends them itself when its launcher goes; the
/// watch's check of the parent process ends them with launchers that do not.)
#[test]
fn no_process_outlives_a_launcher_that_returned() {
    let out = out_dir("mpi_orphans");
    let (child, pids) = endless_run(3, "600", &out);
    assert_eq!(unsafe { libc::kill(pids[2], libc::SIGSTOP) }, 0);
    std::thread::sleep(std::time::Duration::from_millis(500));
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGKILL) }, 0);
    let _ = child.wait_with_output().unwrap();
    let returned = std::time::Instant::now();
    // The frozen one runs again: it finds its launcher gone too.
    unsafe { libc::kill(pids[2], libc::SIGCONT) };
    while !pids.iter().all(|&pid| gone(pid)) {
        assert!(
            returned.elapsed() < std::time::Duration::from_secs(15),
            "processes of the run outlive the launcher: {:?}",
            pids.iter().filter(|&&p| !gone(p)).collect::<Vec<_>>()
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
}
