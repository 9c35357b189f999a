//! `granite repl` on a real terminal (a pseudo-terminal): Tab completes a variable's methods and
//! the keys of an open options map, the history is kept in a file between sessions, and an
//! interactive session with a failed input still exits 0.

use std::process::Command;

/// Starts the REPL on a pseudo-terminal with its history in `history`; None where the machine
/// gives no pseudo-terminal (said on stderr: the test then checks nothing).
fn start(history: &std::path::Path, out: &std::path::Path) -> Option<rexpect::session::PtySession> {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_granite"));
    cmd.args(["repl", "--quiet", "--out"]).arg(out).env("GRANITE_HISTORY", history).env("TERM", "xterm");
    let mut p = match rexpect::session::spawn_command(cmd, Some(30_000)) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("no pseudo-terminal on this machine ({e}): the terminal test is not run");
            return None;
        }
    };
    p.exp_string("granite> ").expect("a prompt");
    Some(p)
}

/// Keys typed as they are, without a newline.
fn type_in(p: &mut rexpect::session::PtySession, keys: &str) {
    p.send(keys).unwrap();
    p.flush().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(100));
}

#[test]
fn tab_completes_and_history_is_kept() {
    let dir = std::env::temp_dir().join(format!("granite_repl_terminal_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let history = dir.join("history");
    let Some(mut p) = start(&history, &dir.join("out")) else { return };
    p.send_line("let sim = dem();").unwrap();
    p.exp_string("granite> ").unwrap();
    // `sim.gra` + Tab becomes `sim.gravity`: the only DemSim method starting so.
    type_in(&mut p, "sim.gra");
    type_in(&mut p, "\t");
    type_in(&mut p, "([0.0, 0.0, -9.81]); print_line(`g = ${sim.diagnostics().particles}`);");
    type_in(&mut p, "\r");
    p.exp_string("g = 0").expect("the completed call ran");
    // Several candidates: a second Tab lists them all at once (`sim.run` + Tab, Tab lists
    // run, run_steps, run_until), instead of inserting one.
    type_in(&mut p, "sim.dt(1e-6); sim.run_");
    type_in(&mut p, "\t");
    type_in(&mut p, "\t");
    p.exp_string("run_steps").expect("the candidates listed");
    p.exp_string("run_until").expect("the candidates listed");
    // The line is still as typed (cycling would have made it `sim.run_until`): finish it.
    type_in(&mut p, "steps(0); print_line(`kept ${40 + 2}`);");
    type_in(&mut p, "\r");
    p.exp_string("kept 42").expect("the line was left as typed");
    // An option key of the open map: `#{ dens` + Tab becomes `#{ density`.
    type_in(&mut p, "let m = sim.material(#{ dens");
    type_in(&mut p, "\t");
    type_in(&mut p, ": 2500.0 }); print_line(`made ${m}`);");
    type_in(&mut p, "\r");
    p.exp_string("made DemMaterial(").expect("the completed key was accepted");
    // A failed input, then leave: still exit 0.
    p.send_line("sim.no_such_call();").unwrap();
    p.exp_string("Function not found").unwrap();
    p.send_line(":quit").unwrap();
    p.exp_eof().unwrap();
    let saved = std::fs::read_to_string(&history).expect("the history file is written");
    assert!(saved.contains("sim.gravity([0.0, 0.0, -9.81])"), "{saved}");
    assert!(saved.contains("#{ density: 2500.0 }"), "{saved}");
    // A new session starts with that history: Up recalls the last input.
    let mut p = start(&history, &dir.join("out2")).expect("a second terminal");
    type_in(&mut p, "\x1b[A");
    type_in(&mut p, "\r");
    p.exp_string(":quit").expect("the last input recalled");
    p.exp_eof().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// Lines typed while a run goes on at the prompt are kept and evaluated in order once it ends.
#[test]
fn lines_typed_during_a_run_are_kept() {
    let dir = std::env::temp_dir().join(format!("granite_repl_typeahead_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let Some(mut p) = start(&dir.join("history"), &dir.join("out")) else { return };
    p.send_line(
        "let sim = mpm(#{ dim: 2, cell: 0.1, cells: [10, 10] }); \
         let m = sim.material(\"linear_elastic\", #{ density: 1000.0, young: 1e6, poisson: 0.3 }); \
         sim.fill_box(m, [0.0, 0.0], [1.0, 0.5]); sim.gravity([0.0, -9.81]); sim.dt(1e-5);",
    )
    .unwrap();
    p.exp_string("granite> ").unwrap();
    // A run of a second or more at the prompt, and two lines typed meanwhile.
    p.send_line("let t0 = timestamp(); sim.run_steps(300000); print_line(`ran ${sim.step} for ${t0.elapsed > 0.5}`);")
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(300));
    type_in(&mut p, "print_line(`first ${1 + 1}`);\r");
    type_in(&mut p, "print_line(`second ${2 + 2}`);\r");
    // The run outlasted the typing (else the test would prove nothing).
    p.exp_string("ran 300000 for true").expect("the run ended, after more than 0.5 s");
    p.exp_string("first 2").expect("the first line typed during the run");
    p.exp_string("second 4").expect("the second line typed during the run");
    p.send_line(":quit").unwrap();
    p.exp_eof().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}
