//! `granite repl`: reads inputs from a terminal (line editing, history) or from standard input,
//! and evaluates them in one session. Ctrl-C pauses a running simulation instead of quitting.

use granite_core::error::Result;
use granite_script::repl::{Outcome, ReplSession};
use granite_script::RunOptions;
use std::io::{BufRead, IsTerminal};
use std::path::{Path, PathBuf};

const HELP: &str = "granite repl: the script API one input at a time (variables and functions are kept).
  sim.run(), sim.run(n)   run in the background (until paused, or n steps); the prompt stays usable
  sim.pause(), sim.wait(), sim.running, sim.step()   pause, wait for the end, ask, one step
  sim.run_steps(n), sim.run_until(t)   run at the prompt; Ctrl-C pauses any run, state kept,
                          and stops the input being evaluated (a loop of runs, an endless loop)
  sim.diagnostics(), sim.time, sim.step   inspect (between two steps, also while running)
  sim.gravity([..]), sim.damping(d), sim.vtk_every(n) ...   change (between two steps, also while running)
  a line ending inside { ( [ continues on the next line; an empty line ends it
  Tab completes functions, a variable's methods (sim.gra<Tab>) and option keys (#{ co<Tab>)
  :help NAME  a call's forms with argument names, option keys and what it does, e.g. :help sphere
  :api [text] every call whose name, form or description holds text, e.g. :api wall
  :help this text, :quit or Ctrl-D leaves; history is kept in ~/.granite_history ($GRANITE_HISTORY)";

/// Runs the session; returns the number of inputs that failed when the inputs came from a pipe
/// (a session driven by a file should fail when its inputs did), zero after an interactive one
/// (a mistyped line at the prompt was answered there).
pub fn run(script: Option<&Path>, options: RunOptions) -> Result<usize> {
    let mut session = ReplSession::new(crate::registry(), options)?;
    if let Err(e) = ctrlc::set_handler(session.pause_handle()) {
        granite_core::errln!("granite: Ctrl-C will not pause runs ({e})");
    }
    let mut failures = 0;
    if let Some(path) = script {
        let source = std::fs::read_to_string(path).map_err(|e| granite_core::error::GraniteError::io(path, e))?;
        match session.eval(&source, false) {
            Outcome::Error(e) => {
                granite_core::errln!("{}: {e}", path.display());
                failures += 1;
            }
            Outcome::Interrupted(e) => granite_core::errln!("{}: {e}", path.display()),
            _ => {}
        }
    }
    let interactive = std::io::stdin().is_terminal();
    let mut reader = Input::new(interactive, Box::new(session.pause_handle()));
    reader.load_history();
    if interactive {
        granite_core::outln!("{HELP}");
    }
    let mut pending = String::new();
    loop {
        let prompt = if pending.is_empty() { "granite> " } else { "     ... " };
        reader.know(session.variables());
        // At the end of the input, what is pending is evaluated as it stands.
        let line = match reader.read(prompt) {
            Some(Ok(line)) => line,
            Some(Err(why)) => {
                // The input goes on: one bad line (a file in another encoding) is not the end.
                failures += 1;
                granite_core::errln!("error: {why}; the line was skipped");
                continue;
            }
            None if !pending.is_empty() => String::new(),
            None => break,
        };
        let trimmed = line.trim();
        if pending.is_empty() && trimmed.starts_with(':') {
            reader.remember(trimmed);
        }
        if pending.is_empty() {
            match trimmed {
                "" => continue,
                ":quit" | ":q" | "exit" | "quit" => break,
                ":help" | "help" => {
                    granite_core::outln!("{HELP}");
                    continue;
                }
                _ if trimmed.starts_with(":help ") => {
                    granite_core::out!("{}", ensure_newline(session.help(trimmed[":help".len()..].trim())));
                    continue;
                }
                _ if trimmed == ":api" || trimmed.starts_with(":api ") => {
                    let filter = trimmed[":api".len()..].trim();
                    let found = session.api(filter);
                    if found.is_empty() {
                        granite_core::outln!("no call of the API matches `{filter}`");
                    }
                    for line in found {
                        granite_core::outln!("  {line}");
                    }
                    continue;
                }
                _ if trimmed.starts_with(':') => {
                    // No Rhai input starts with a colon: a mistyped command.
                    failures += 1;
                    granite_core::errln!(
                        "error: unknown command `{trimmed}`; the commands are :help [NAME], :api [text] and :quit"
                    );
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
            Outcome::Value(Some(v)) => granite_core::outln!("{v}"),
            Outcome::Value(None) => {}
            Outcome::Error(e) => {
                failures += 1;
                granite_core::errln!("error: {e}");
            }
            Outcome::Interrupted(e) => granite_core::errln!("{e}"),
        }
        reader.remember(pending.trim_end());
        pending.clear();
    }
    session.finish();
    Ok(if interactive { 0 } else { failures })
}

fn ensure_newline(text: String) -> String {
    if text.ends_with('\n') {
        text
    } else {
        text + "\n"
    }
}

/// Where the history is kept between sessions: `$GRANITE_HISTORY`, else `~/.granite_history`.
fn history_path() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("GRANITE_HISTORY") {
        return Some(PathBuf::from(p));
    }
    std::env::var_os("HOME").map(|home| PathBuf::from(home).join(".granite_history"))
}

/// Completion from the API table and the session's variables (see `api_doc::complete`).
#[derive(Default)]
struct Completion {
    variables: Vec<(String, String)>,
}

impl rustyline::completion::Completer for Completion {
    type Candidate = String;
    fn complete(&self, line: &str, pos: usize, _: &rustyline::Context<'_>) -> rustyline::Result<(usize, Vec<String>)> {
        Ok(granite_script::api_doc::complete(line, pos, &self.variables))
    }
}

impl rustyline::hint::Hinter for Completion {
    type Hint = String;
}
impl rustyline::highlight::Highlighter for Completion {}
impl rustyline::validate::Validator for Completion {}
impl rustyline::Helper for Completion {}

type Editor = rustyline::Editor<Completion, rustyline::history::DefaultHistory>;

/// A terminal with line editing, completion and history, or plain lines from a pipe.
enum Input {
    /// The editor, and what Ctrl-C at its prompt does (the terminal then sends no signal).
    Editor(Box<Editor>, Box<dyn Fn()>),
    Plain(std::io::StdinLock<'static>),
}

impl Input {
    fn new(interactive: bool, on_ctrl_c: Box<dyn Fn()>) -> Input {
        if interactive {
            // Tab completes what all candidates share, a second Tab lists them (as bash and
            // IPython do), instead of cycling through them one at a time.
            let config = rustyline::Config::builder().completion_type(rustyline::CompletionType::List).build();
            if let Ok(mut editor) = Editor::with_config(config) {
                editor.set_helper(Some(Completion::default()));
                return Input::Editor(Box::new(editor), on_ctrl_c);
            }
        }
        Input::Plain(std::io::stdin().lock())
    }

    fn load_history(&mut self) {
        if let (Input::Editor(editor, _), Some(path)) = (self, history_path()) {
            let _ = editor.load_history(&path);
        }
    }

    /// The variables completion offers, and their types (for their methods).
    fn know(&mut self, variables: Vec<(String, String)>) {
        if let Input::Editor(editor, _) = self {
            if let Some(helper) = editor.helper_mut() {
                helper.variables = variables;
            }
        }
    }

    /// The next line; an error for a line that is not text (invalid UTF-8); None at the end.
    fn read(&mut self, prompt: &str) -> Option<std::result::Result<String, String>> {
        match self {
            Input::Editor(editor, on_ctrl_c) => loop {
                match editor.readline(prompt) {
                    Ok(line) => return Some(Ok(line)),
                    Err(rustyline::error::ReadlineError::Interrupted) => {
                        on_ctrl_c();
                        granite_core::outln!("(Ctrl-C pauses background runs; :quit or Ctrl-D leaves)");
                    }
                    Err(rustyline::error::ReadlineError::Io(e)) if e.kind() == std::io::ErrorKind::InvalidData => {
                        return Some(Err(format!("the input is not valid UTF-8 text ({e})")))
                    }
                    Err(_) => return None,
                }
            },
            Input::Plain(stdin) => {
                let mut bytes = Vec::new();
                match stdin.read_until(b'\n', &mut bytes) {
                    Ok(0) | Err(_) => None,
                    Ok(_) => Some(match String::from_utf8(bytes) {
                        Ok(line) => Ok(line.trim_end_matches(['\n', '\r']).to_string()),
                        Err(e) => Err(format!(
                            "the input line is not valid UTF-8 text (byte {} is not); granite reads scripts as UTF-8",
                            e.utf8_error().valid_up_to() + 1
                        )),
                    }),
                }
            }
        }
    }

    /// Adds an input to the history, and to the history file at once (a session that ends
    /// badly keeps what was typed).
    fn remember(&mut self, entry: &str) {
        if let Input::Editor(editor, _) = self {
            let _ = editor.add_history_entry(entry);
            if let Some(path) = history_path() {
                let _ = editor.append_history(&path);
            }
        }
    }
}
