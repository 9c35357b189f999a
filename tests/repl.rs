//! `granite repl` driven through standard input: start a long run, pause it with Ctrl-C (SIGINT),
//! inspect, change gravity, resume, and check against free fall that the change took effect at
//! the pause and that no state was lost. A bad input is reported with its position and leaves
//! the simulation untouched. The same with a run in the background while the prompt is used.

use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

const G1: f64 = 9.81;
const G2: f64 = 2.0;
const DT: f64 = 1e-5;
const RESUMED_STEPS: u64 = 1000;

/// A block falling freely in a tall mesh, and a function of its speed; numbers from the constants.
fn falling_block() -> String {
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
"#
    )
}

/// The session piped in; its numbers come from the constants above.
fn session() -> String {
    falling_block()
        + format!(
            r#"print_line("running");
sim.run_steps(1000000000);
print_line(`paused ${{sim.step}} ${{sim.time}} ${{speed(sim)}}`);
sim.gravity([0.0, -2.0], 7);
let broken = (1 + ;
sim.gravity([0.0, -{G2:?}]);
sim.run_steps({RESUMED_STEPS});
print_line(`resumed ${{sim.step}} ${{sim.time}} ${{speed(sim)}} ${{sim.diagnostics().points - points}}`);
"#
        )
        .as_str()
}

fn numbers(line: &str, tag: &str) -> Vec<f64> {
    line.trim_start_matches(tag).split_whitespace().map(|w| w.parse().expect("a number")).collect()
}

/// A REPL process: its stdin, its stdout lines as they come, and its whole stderr at the end.
struct Repl {
    child: std::process::Child,
    stdin: Option<std::process::ChildStdin>,
    lines: mpsc::Receiver<String>,
    errors: std::thread::JoinHandle<String>,
    out: std::path::PathBuf,
}

/// `granite repl --quiet --out OUT` with its three streams piped.
fn piped_repl(out: &std::path::Path) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_granite"));
    command
        .args(["repl", "--quiet", "--out"])
        .arg(out)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    command
}

impl Repl {
    fn start(name: &str) -> Repl {
        let out = std::env::temp_dir().join(format!("granite_repl_{name}_{}", std::process::id()));
        let mut child = piped_repl(&out).spawn().expect("granite starts");
        let (tx, lines) = mpsc::channel();
        let stdout = child.stdout.take().unwrap();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
        let stderr = child.stderr.take().unwrap();
        let errors = std::thread::spawn(move || std::io::read_to_string(stderr).unwrap_or_default());
        let stdin = child.stdin.take();
        Repl { child, stdin, lines, errors, out }
    }

    fn send(&mut self, input: &str) {
        let stdin = self.stdin.as_mut().expect("stdin open");
        stdin.write_all(input.as_bytes()).unwrap();
        stdin.flush().unwrap();
    }

    fn line(&self, what: &str) -> String {
        self.lines.recv_timeout(Duration::from_secs(60)).unwrap_or_else(|_| panic!("no line: {what}"))
    }

    /// Closes stdin; the exit code and stderr.
    fn finish(mut self) -> (Option<i32>, String) {
        drop(self.stdin.take());
        let status = self.child.wait().unwrap();
        let errors = self.errors.join().unwrap();
        let _ = std::fs::remove_dir_all(&self.out);
        (status.code(), errors)
    }
}

#[test]
fn pause_change_gravity_resume() {
    let mut repl = Repl::start("ctrl_c");
    repl.send(&session());
    let (child, rx) = (&repl.child, &repl.lines);

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
    let resumed = repl.line("resumed run reports");
    let (status, errors) = repl.finish();

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
    assert_eq!(status, Some(1), "two inputs failed: {errors}");
}

/// `sim.run()` returns at once; the prompt inspects the running simulation, a blocking run is
/// refused meanwhile, `sim.pause()` stops it between two steps, `sim.step()` does one step, and a
/// gravity change followed by `sim.run(n)` and `sim.wait()` acts from the pause on.
#[test]
fn background_run_pause_change_wait() {
    let mut repl = Repl::start("background");
    repl.send(&falling_block());
    repl.send("sim.run();\nprint_line(`started ${sim.running}`);\n");
    assert_eq!(repl.line("started"), "started true");
    std::thread::sleep(Duration::from_millis(500));
    repl.send("print_line(`running ${sim.step} ${sim.running}`);\nsim.run_steps(5);\n");
    let running = numbers(&repl.line("inspected while running").replace("true", "1"), "running");
    assert!(running[0] > 0.0 && running[1] == 1.0, "the run goes on behind the prompt: {running:?}");

    repl.send("sim.pause();\nprint_line(`paused ${sim.step} ${sim.time} ${speed(sim)} ${sim.running}`);\n");
    let paused = repl.line("paused");
    assert!(paused.ends_with("false"), "{paused}");
    let p = numbers(paused.trim_end_matches("false"), "paused");
    let (step1, t1, v1) = (p[0], p[1], p[2]);
    assert!(step1 >= running[0], "{paused}");
    assert!((t1 - step1 * DT).abs() < 1e-9 * t1.max(1.0), "{paused}");
    assert!((v1 - G1 * t1).abs() < 1e-6 * G1 * t1, "speed at pause {v1}, free fall gives {}", G1 * t1);

    // Paused means paused: the state does not move until asked.
    std::thread::sleep(Duration::from_millis(200));
    repl.send("sim.step();\nprint_line(`stepped ${sim.step}`);\n");
    let stepped = numbers(&repl.line("one step"), "stepped");
    assert_eq!(stepped[0], step1 + 1.0, "sim.step() does one step after the pause");

    repl.send(&format!(
        "sim.gravity([0.0, -{G2:?}]);\nsim.run({RESUMED_STEPS});\nsim.wait();\nprint_line(`resumed ${{sim.step}} ${{sim.time}} ${{speed(sim)}} ${{sim.diagnostics().points - points}} ${{sim.running}}`);\n"
    ));
    let resumed = repl.line("resumed");
    assert!(resumed.ends_with("false"), "the run has ended after sim.wait(): {resumed}");
    let r = numbers(resumed.trim_end_matches("false"), "resumed");
    let (step2, t2, v2, lost) = (r[0], r[1], r[2], r[3]);
    assert_eq!(step2 - step1, RESUMED_STEPS as f64 + 1.0, "{resumed}");
    // One step under G1 after the pause, then G2.
    let t_step = t1 + DT;
    let expected = G1 * t_step + G2 * (t2 - t_step);
    assert!((v2 - expected).abs() < 1e-6 * expected, "speed after resume {v2}, expected {expected}");
    assert_eq!(lost, 0.0, "material points lost: {resumed}");

    let (status, errors) = repl.finish();
    assert!(errors.contains("running in the background"), "the blocking run is refused: {errors}");
    assert_eq!(status, Some(1), "one input failed: {errors}");
}

/// `:api`, `:help`, printed objects and "did you mean", as a piped session sees them. A piped
/// session with a failed input exits 1 (an interactive one exits 0).
#[test]
fn api_help_and_suggestions() {
    let mut repl = Repl::start("api");
    repl.send(concat!(
        ":api wall_\n:api no_such_function\n:apiwall\n",
        ":help sphere\n:help sim.gravty\n",
        "let sim = dem();\nsim\nlet m = sim.material(#{ name: \"glass\", density: 2500.0 });\nm\n",
        "sim.gravty([0.0, 0.0, -9.81]);\n",
        "sim.tme\n",
        "sim.sphere(m, [0.0, 0.0, 0.0], 0.01, #{ velocty: [1.0, 0.0, 0.0] });\n",
        "print_line(\"end\");\n"
    ));
    let mut lines = Vec::new();
    loop {
        let line = repl.line("api listing");
        if line == "end" {
            break;
        }
        lines.push(line);
    }
    let (status, errors) = repl.finish();
    let has = |text: &str| lines.iter().any(|l| l.contains(text));
    // A mistyped command is said to be one (not a Rhai syntax error at the colon).
    assert!(errors.contains("unknown command `:apiwall`"), "{errors}");
    assert_eq!(status, Some(1), "{errors}");
    assert!(has("sim.wall_plane(material, point, normal)"), "{lines:?}");
    assert!(has("no call of the API matches `no_such_function`"), "{lines:?}");
    // :help gives argument names and option keys.
    assert!(has("sim.sphere(material, [x, y, z], radius, #{ velocity, fixed })"), "{lines:?}");
    assert!(has("options: velocity, fixed"), "{lines:?}");
    assert!(has("no function or property `sim.gravty` in granite's API; did you mean `gravity`?"), "{lines:?}");
    // Objects print as what they hold.
    assert!(has("DemSim(0 spheres, 0 walls, t = 0.000000 s, step 0, paused)"), "{lines:?}");
    assert!(has("DemMaterial(\"glass\")"), "{lines:?}");
    // Misspelt names and keys get a suggestion.
    assert!(errors.contains("did you mean `gravity`?"), "{errors}");
    assert!(errors.contains("Unknown property 'tme'") && errors.contains("did you mean `time`?"), "{errors}");
    assert!(errors.contains("unknown option `velocty` of sim.sphere(...) (did you mean `velocity`?)"), "{errors}");
}

/// Ctrl-C stops the input being evaluated, not only a run: an endless loop, and a loop of runs
/// (whose run is paused first, then the loop stops instead of starting the next run). The
/// session goes on with its variables and its simulation, and an interruption is no failure.
#[test]
fn ctrl_c_stops_a_loop_at_the_prompt() {
    const RUN: u64 = 100_000;
    let mut repl = Repl::start("loop");
    let interrupt = |repl: &Repl| {
        std::thread::sleep(Duration::from_millis(500));
        Command::new("kill").args(["-INT", &repl.child.id().to_string()]).status().expect("kill runs");
    };
    repl.send("let turns = 0;\nprint_line(\"looping\");\nwhile true { turns += 1; }\n");
    assert_eq!(repl.line("loop starts"), "looping");
    interrupt(&repl);
    repl.send("print_line(`turns ${turns}`);\n");
    let turns = numbers(&repl.line("after the loop"), "turns");
    assert!(turns[0] > 0.0, "the loop ran and its variable is kept: {turns:?}");

    repl.send(&falling_block());
    repl.send(&format!("print_line(\"runs\");\nfor k in 0..1000 {{ sim.run_steps({RUN}); }}\n"));
    assert_eq!(repl.line("runs start"), "runs");
    interrupt(&repl);
    repl.send("print_line(`stopped ${sim.step} ${sim.time} ${speed(sim)}`);\n");
    let s = numbers(&repl.line("after the runs"), "stopped");
    let (step, t, v) = (s[0], s[1], s[2]);
    // Stopped inside the run under way (its steps are not a multiple of RUN), not at the end of
    // the loop's thousand runs; nothing lost: free fall to the step it stopped at.
    assert!(step > 0.0 && step < 1000.0 * RUN as f64 && step % RUN as f64 != 0.0, "{step}");
    assert!((t - step * DT).abs() < 1e-9 * t.max(1.0) && (v - G1 * t).abs() < 1e-6 * G1 * t, "{s:?}");

    let (status, errors) = repl.finish();
    assert_eq!(errors.matches("interrupted by Ctrl-C").count(), 2, "{errors}");
    assert_eq!(status, Some(0), "an interrupted input is not a failure: {errors}");
}

/// A line that is not UTF-8 text (a file in Latin-1 piped in) is reported and skipped; the
/// inputs after it run.
#[test]
fn a_line_of_invalid_utf8_is_reported_and_the_session_goes_on() {
    let out = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/test-out/repl_utf8");
    let mut child = piped_repl(&out).spawn().unwrap();
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all(b"print_line(\"before\");\nprint_line(\"caf\xe9\");\nprint_line(\"after\");\n").unwrap();
    drop(stdin);
    let done = child.wait_with_output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&done.stdout), String::from_utf8_lossy(&done.stderr));
    assert_eq!(stdout.lines().collect::<Vec<_>>(), ["before", "after"], "{stderr}");
    assert!(stderr.contains("not valid UTF-8") && stderr.contains("byte 16"), "{stderr}");
    assert_eq!(done.status.code(), Some(1), "a piped session with a failed input exits 1");
}

/// README's REPL example says what its simulation holds (`MpmSim(2D, N points, ...)`): the
/// inputs before that line, evaluated in a session, make a simulation of that many points.
#[test]
fn the_readme_repl_example_holds_the_points_it_shows() {
    let readme = std::fs::read_to_string(crate::common::root().join("README.md")).unwrap();
    let inputs: Vec<&str> = readme
        .lines()
        .filter_map(|l| l.strip_prefix("granite> "))
        .map(|l| l.split("  //").next().unwrap().trim())
        .collect();
    let shown = readme.lines().find(|l| l.contains("// MpmSim(2D, ")).expect("the example's last line");
    let points: i64 = shown.split("MpmSim(2D, ").nth(1).unwrap().split_whitespace().next().unwrap().parse().unwrap();
    let mut session = granite_script::repl::ReplSession::new(
        granite::registry(),
        granite_script::RunOptions {
            out_dir: crate::common::out_dir("readme_repl"),
            quiet: true,
            ..Default::default()
        },
    )
    .unwrap();
    // The set-up lines: those before the first run.
    for input in inputs.iter().take_while(|i| !i.starts_with("sim.run")) {
        let outcome = session.eval(input, false);
        assert!(matches!(outcome, granite_script::repl::Outcome::Value(_)), "{input}: {outcome:?}");
    }
    match session.eval("sim.points", false) {
        granite_script::repl::Outcome::Value(v) => {
            assert_eq!(v, Some(points.to_string()), "README shows {points} points")
        }
        other => panic!("{other:?}"),
    }
    session.finish();
}
