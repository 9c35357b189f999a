//! `granite repl`: reads inputs from a terminal (line editing, history) or from standard input,
//! and evaluates them in one session. Ctrl-C pauses a running simulation instead of quitting.

use granite_core::error::Result;
use granite_core::script::repl::{Outcome, ReplSession};
use granite_core::script::RunOptions;
use std::io::{BufRead, IsTerminal};
use std::path::Path;

const HELP: &str = "granite repl: the script API one input at a time (variables and functions are kept).
  sim.run_steps(n), sim.run_until(t)   run; Ctrl-C pauses at the next step, state kept
  sim.diagnostics(), sim.time, sim.step   inspect
  sim.gravity([..]), sim.damping(d), sim.dt(..), sim.vtk_every(n) ...   change, then run again to resume
  a line ending inside { ( [ continues on the next line; an empty line ends it
  :help this text, :quit or Ctrl-D leaves";

/// Runs the session; returns the number of inputs that failed.
pub fn run(script: Option<&Path>, options: RunOptions) -> Result<usize> {
    let mut session = ReplSession::new(crate::registry(), options)?;
    let pause = session.pause_handle();
    if let Err(e) = ctrlc::set_handler(pause) {
        eprintln!("granite: Ctrl-C will not pause runs ({e})");
    }
    let mut failures = 0;
    if let Some(path) = script {
        let source = std::fs::read_to_string(path).map_err(|e| granite_core::error::GraniteError::io(path, e))?;
        if let Outcome::Error(e) = session.eval(&source, false) {
            eprintln!("{}: {e}", path.display());
            failures += 1;
        }
    }
    let interactive = std::io::stdin().is_terminal();
    let mut reader = Input::new(interactive);
    if interactive {
        println!("{HELP}");
    }
    let mut pending = String::new();
    loop {
        let prompt = if pending.is_empty() { "granite> " } else { "     ... " };
        // At the end of the input, what is pending is evaluated as it stands.
        let line = match reader.read(prompt) {
            Some(line) => line,
            None if !pending.is_empty() => String::new(),
            None => break,
        };
        let trimmed = line.trim();
        if pending.is_empty() {
            match trimmed {
                "" => continue,
                ":quit" | ":q" | "exit" | "quit" => break,
                ":help" | "help" => {
                    println!("{HELP}");
                    continue;
                }
                _ => {}
            }
        }
        let finishing = !pending.is_empty() && trimmed.is_empty();
        pending.push_str(&line);
        pending.push('\n');
        match session.eval(&pending, !finishing) {
            Outcome::Incomplete => continue,
            Outcome::Value(Some(v)) => println!("{v}"),
            Outcome::Value(None) => {}
            Outcome::Error(e) => {
                failures += 1;
                eprintln!("error: {e}");
            }
        }
        reader.remember(pending.trim_end());
        pending.clear();
    }
    Ok(failures)
}

/// A terminal with line editing and history, or plain lines from a pipe.
enum Input {
    Editor(Box<rustyline::DefaultEditor>),
    Plain(std::io::StdinLock<'static>),
}

impl Input {
    fn new(interactive: bool) -> Input {
        if interactive {
            if let Ok(editor) = rustyline::DefaultEditor::new() {
                return Input::Editor(Box::new(editor));
            }
        }
        Input::Plain(std::io::stdin().lock())
    }

    fn read(&mut self, prompt: &str) -> Option<String> {
        match self {
            Input::Editor(editor) => loop {
                match editor.readline(prompt) {
                    Ok(line) => return Some(line),
                    Err(rustyline::error::ReadlineError::Interrupted) => {
                        println!("(Ctrl-C at the prompt does nothing; :quit or Ctrl-D leaves)");
                    }
                    Err(_) => return None,
                }
            },
            Input::Plain(stdin) => {
                let mut line = String::new();
                match stdin.read_line(&mut line) {
                    Ok(0) | Err(_) => None,
                    Ok(_) => Some(line.trim_end_matches(['\n', '\r']).to_string()),
                }
            }
        }
    }

    fn remember(&mut self, entry: &str) {
        if let Input::Editor(editor) = self {
            let _ = editor.add_history_entry(entry);
        }
    }
}
