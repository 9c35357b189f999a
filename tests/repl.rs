//! `granite repl` driven through standard input: start a long run, pause it with Ctrl-C (SIGINT),
//! inspect, change gravity, resume, and check against free fall that the change took effect at
//! the pause and that no state was lost. A bad input is reported with its position and leaves
//! the simulation untouched.

use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

const G1: f64 = 9.81;
const G2: f64 = 2.0;
const DT: f64 = 1e-5;
const RESUMED_STEPS: u64 = 1000;

/// The session piped in; its numbers come from the constants above.
fn session() -> String {
    format!(
        r#"let sim = mpm(#{{ dim: 2, origin: [0.0, 0.0], cell: 0.1, cells: [10, 40] }});
let soil = sim.material("linear_elastic", #{{ density: 1000.0, young: 1e6, poisson: 0.3 }});
let filled = sim.fill_box(soil, [0.3, 3.5], [0.7, 3.9], #{{ per_cell: 2 }});
sim.gravity([0.0, -{G1:?}]);
sim.dt({DT:e});
fn speed(s) {{
  let d = s.diagnostics();
  (2.0 * d.kinetic_energy / d.mass).sqrt()
}}
let points = sim.diagnostics().points;
print_line("running");
sim.run_steps(1000000000);
print_line(`paused ${{sim.step}} ${{sim.time}} ${{speed(sim)}}`);
sim.gravity([0.0, -2.0], 7);
let broken = (1 + ;
sim.gravity([0.0, -{G2:?}]);
sim.run_steps({RESUMED_STEPS});
print_line(`resumed ${{sim.step}} ${{sim.time}} ${{speed(sim)}} ${{sim.diagnostics().points - points}}`);
"#
    )
}

fn numbers(line: &str, tag: &str) -> Vec<f64> {
    line.trim_start_matches(tag).split_whitespace().map(|w| w.parse().expect("a number")).collect()
}

#[test]
fn pause_change_gravity_resume() {
    let out = std::env::temp_dir().join(format!("granite_repl_{}", std::process::id()));
    let mut child = Command::new(env!("CARGO_BIN_EXE_granite"))
        .args(["repl", "--quiet", "--out"])
        .arg(&out)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("granite starts");
    child.stdin.take().unwrap().write_all(session().as_bytes()).unwrap();
    let (tx, rx) = mpsc::channel();
    let stdout = child.stdout.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let stderr = child.stderr.take().unwrap();
    let errors = std::thread::spawn(move || std::io::read_to_string(stderr).unwrap_or_default());

    assert_eq!(rx.recv_timeout(Duration::from_secs(60)).expect("session starts"), "running");
    // Ctrl-C until the run reports back (a signal before the run began would be cleared).
    let mut paused = None;
    for _ in 0..20 {
        std::thread::sleep(Duration::from_millis(300));
        Command::new("kill").args(["-INT", &child.id().to_string()]).status().expect("kill runs");
        if let Ok(line) = rx.recv_timeout(Duration::from_secs(2)) {
            paused = Some(line);
            break;
        }
    }
    let paused = paused.expect("Ctrl-C pauses the run");
    let resumed = rx.recv_timeout(Duration::from_secs(60)).expect("resumed run reports");
    let status = child.wait().unwrap();
    let errors = errors.join().unwrap();

    let p = numbers(&paused, "paused");
    let (step1, t1, v1) = (p[0], p[1], p[2]);
    assert!(step1 > 0.0 && step1 < 1e9, "the run stopped part-way: {paused}");
    // Nothing lost at the pause: time and velocity are those of free fall after step1 steps.
    assert!((t1 - step1 * DT).abs() < 1e-9 * t1.max(1.0), "{paused}");
    assert!((v1 - G1 * t1).abs() < 1e-6 * G1 * t1, "speed at pause {v1}, free fall gives {}", G1 * t1);

    // The new gravity acts from the pause on, and the failed inputs changed nothing.
    let r = numbers(&resumed, "resumed");
    let (step2, t2, v2, lost) = (r[0], r[1], r[2], r[3]);
    assert_eq!(step2 - step1, RESUMED_STEPS as f64, "{resumed}");
    let expected = G1 * t1 + G2 * (t2 - t1);
    assert!((v2 - expected).abs() < 1e-6 * expected, "speed after resume {v2}, expected {expected}");
    assert_eq!(lost, 0.0, "material points lost: {resumed}");

    assert!(errors.contains("paused at step"), "{errors}");
    assert!(errors.contains("gravity"), "the bad call is reported: {errors}");
    assert!(errors.contains("line 1, column 19"), "the syntax error gives its position: {errors}");
    assert_eq!(status.code(), Some(1), "two inputs failed: {errors}");
    let _ = std::fs::remove_dir_all(&out);
}
