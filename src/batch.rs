//! `granite batch SCRIPT --params FILE.toml [--jobs N]`: one script over many parameter sets,
//! each run in its own process and output folder, N at a time; failures do not stop the others.
//!
//! The TOML file holds `[grid]` (every combination of the listed values) and/or `[[set]]`
//! entries (explicit sets); with both, each set is combined with every grid point, and a name
//! may not be in both (one of the two values would be silently dropped). Every set is checked
//! against the script's `param` declarations before the first run starts; each run keeps its
//! `stdout.log` and `stderr.log` in its folder.

use granite_core::{GraniteError, Result};
use std::path::{Path, PathBuf};
use std::process::Command;

/// One run: its index, its `NAME=VALUE` overrides and its output folder.
#[derive(Debug, Clone)]
pub struct Job {
    pub index: usize,
    pub overrides: Vec<(String, String)>,
    pub out_dir: PathBuf,
}

/// How one run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    Ok,
    Failed,
    /// Stopped by a signal the batch passed on (SIGINT, SIGTERM).
    Interrupted,
    /// Ran past `--run-timeout` and was stopped.
    TimedOut,
    /// Never started: the batch was stopped first.
    NotRun,
}

impl Status {
    pub fn name(self) -> &'static str {
        match self {
            Status::Ok => "ok",
            Status::Failed => "failed",
            Status::Interrupted => "interrupted",
            Status::TimedOut => "timed out",
            Status::NotRun => "not run",
        }
    }
}

/// The outcome of one run.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub job: Job,
    pub status: Status,
    pub exit_code: Option<i32>,
    pub summary: Option<serde_json::Value>,
    /// The run's error message, whole (from its summary.json, else its stderr).
    pub error: String,
}

fn value_text(v: &toml::Value) -> Result<String> {
    Ok(match v {
        toml::Value::String(s) => s.clone(),
        toml::Value::Integer(i) => i.to_string(),
        toml::Value::Float(f) => format!("{f:?}"),
        toml::Value::Boolean(b) => b.to_string(),
        other => {
            return Err(GraniteError::Setup(format!(
                "parameter values must be strings, numbers or booleans, got {other}"
            )))
        }
    })
}
/// All parameter sets of a batch file.
pub fn parameter_sets(text: &str, file: &Path) -> Result<Vec<Vec<(String, String)>>> {
    let doc: toml::Table = text.parse().map_err(|e| GraniteError::Setup(format!("{}: {e}", file.display())))?;
    for key in doc.keys() {
        if key != "grid" && key != "set" {
            return Err(GraniteError::Unknown {
                kind: format!("section of {}", file.display()),
                name: key.clone(),
                known: "grid, set".into(),
            });
        }
    }
    let mut grid: Vec<Vec<(String, String)>> = vec![Vec::new()];
    if let Some(g) = doc.get("grid") {
        let table =
            g.as_table().ok_or_else(|| GraniteError::Setup("[grid] must be a table of NAME = [values]".into()))?;
        for (name, values) in table {
            let list = match values {
                toml::Value::Array(a) => a.iter().map(value_text).collect::<Result<Vec<_>>>()?,
                v => vec![value_text(v)?],
            };
            if list.is_empty() {
                return Err(GraniteError::Setup(format!("[grid] {name} has no value")));
            }
            grid = grid
                .into_iter()
                .flat_map(|base| {
                    list.iter().map(move |v| {
                        let mut s = base.clone();
                        s.push((name.clone(), v.clone()));
                        s
                    })
                })
                .collect();
        }
    }
    let sets: Vec<Vec<(String, String)>> = match doc.get("set") {
        None => vec![Vec::new()],
        Some(toml::Value::Array(a)) => a
            .iter()
            .map(|t| {
                let t = t.as_table().ok_or_else(|| GraniteError::Setup("each [[set]] is a table".into()))?;
                t.iter().map(|(k, v)| Ok((k.clone(), value_text(v)?))).collect::<Result<Vec<_>>>()
            })
            .collect::<Result<_>>()?,
        Some(_) => return Err(GraniteError::Setup("use [[set]] for explicit parameter sets".into())),
    };
    if let (Some(first_grid), true) = (grid.first(), doc.contains_key("set")) {
        for (k, set) in sets.iter().enumerate() {
            if let Some((name, _)) = set.iter().find(|(name, _)| first_grid.iter().any(|(g, _)| g == name)) {
                return Err(GraniteError::Setup(format!(
                    "{}: `{name}` is given both in [grid] and in [[set]] number {}: give each parameter in one \
                     place (a set's value would replace the grid's, or the reverse, and the summary would not say)",
                    file.display(),
                    k + 1
                )));
            }
        }
    }
    Ok(sets.iter().flat_map(|s| grid.iter().map(move |g| s.iter().chain(g).cloned().collect())).collect())
}

/// Checks every set's values against the script's `param(...)` declarations (names, types,
/// limits) before anything runs: a batch whose tenth run has a misspelt name fails at once.
pub fn check_sets(script: &Path, sets: &[Vec<(String, String)>]) -> Result<()> {
    for (k, set) in sets.iter().enumerate() {
        let refused = |e: String| {
            let params: Vec<String> = set.iter().map(|(k, v)| format!("{k}={v}")).collect();
            GraniteError::Setup(format!("run {k} [{}] would fail before it starts: {e}", params.join(" ")))
        };
        let options = granite_script::RunOptions { overrides: set.clone(), quiet: true, ..Default::default() };
        let declared =
            granite_script::list_params(script, crate::registry(), options).map_err(|e| refused(e.to_string()))?;
        // Parameters are declared before a script's first simulation: a name not among them is
        // a misspelling the run would refuse there.
        if let Some((name, _)) = set.iter().find(|(name, _)| !declared.iter().any(|d| &d.name == name)) {
            let names: Vec<&str> = declared.iter().map(|d| d.name.as_str()).collect();
            let near = granite_script::api_doc::closest(name, names.iter().copied());
            let hint = near.first().map(|n| format!(" (did you mean `{n}`?)")).unwrap_or_default();
            return Err(refused(format!(
                "{} declares no parameter `{name}`{hint}; declared: {}",
                script.display(),
                names.join(", ")
            )));
        }
    }
    Ok(())
}

/// How a batch is run besides its script and parameter sets.
#[derive(Debug, Clone)]
pub struct BatchOptions {
    /// Runs at a time.
    pub jobs: usize,
    pub quiet: bool,
    /// A run still going after this long is stopped (SIGTERM, then SIGKILL after
    /// [`KILL_GRACE`]) and reported `timed out`.
    pub run_timeout: Option<std::time::Duration>,
    /// Set by a signal handler to the signal that asks the batch to stop (see `signals`).
    pub stop: Option<&'static std::sync::atomic::AtomicI32>,
}

/// How long a run stopped by a signal or its time limit has to write its outputs before it is
/// killed.
pub const KILL_GRACE: std::time::Duration = std::time::Duration::from_secs(30);

/// A run going on: its process, when it started, and the signal sent to it, when.
struct Running {
    job: Job,
    child: std::process::Child,
    started: std::time::Instant,
    signalled: Option<(i32, std::time::Instant)>,
    timed_out: bool,
}

/// Runs every set with the `granite` executable `exe`, `jobs` at a time, and writes
/// `OUT/batch_summary.csv`, also when a signal stops the batch: the signal is passed on to the
/// runs, which stop cleanly, and the sets not started are listed `not run`. Returns the outcomes
/// in set order.
pub fn run(exe: &Path, script: &Path, params_file: &Path, out: &Path, options: &BatchOptions) -> Result<Vec<Outcome>> {
    let text = std::fs::read_to_string(params_file).map_err(|e| GraniteError::io(params_file, e))?;
    let sets = parameter_sets(&text, params_file)?;
    check_sets(script, &sets)?;
    std::fs::create_dir_all(out).map_err(|e| GraniteError::io(out, e))?;
    let mut queue = sets.into_iter().enumerate().map(|(index, overrides)| Job {
        index,
        overrides,
        out_dir: out.join(format!("run_{index:03}")),
    });
    let stop_requested = || options.stop.map(|s| s.load(std::sync::atomic::Ordering::SeqCst)).filter(|&s| s != 0);
    let mut running: Vec<Running> = Vec::new();
    let mut outcomes = Vec::new();
    loop {
        let stopping = stop_requested();
        while stopping.is_none() && running.len() < options.jobs.max(1) {
            let Some(job) = queue.next() else { break };
            match start(exe, script, &job) {
                Ok(child) => running.push(Running {
                    job,
                    child,
                    started: std::time::Instant::now(),
                    signalled: None,
                    timed_out: false,
                }),
                Err(error) => outcomes.push(report(
                    Outcome { job, status: Status::Failed, exit_code: None, summary: None, error },
                    options.quiet,
                )),
            }
        }
        let mut k = 0;
        while k < running.len() {
            let run = &mut running[k];
            if let Ok(Some(exit)) = run.child.try_wait() {
                let run = running.swap_remove(k);
                outcomes.push(report(finished(run, exit), options.quiet));
                continue;
            }
            let over_time = options.run_timeout.is_some_and(|limit| run.started.elapsed() > limit);
            match (run.signalled, stopping) {
                (None, Some(signal)) => send(run, signal),
                (None, None) if over_time => {
                    run.timed_out = true;
                    send(run, SIGTERM);
                }
                (Some((_, when)), _) if when.elapsed() > KILL_GRACE => {
                    let _ = run.child.kill();
                }
                _ => {}
            }
            k += 1;
        }
        if running.is_empty() && (stopping.is_some() || queue.len() == 0) {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    for job in queue {
        let error = "the batch was stopped before this run started".to_string();
        outcomes.push(Outcome { job, status: Status::NotRun, exit_code: None, summary: None, error });
    }
    outcomes.sort_by_key(|o| o.job.index);
    write_summary(out, &outcomes)?;
    Ok(outcomes)
}

const SIGTERM: i32 = 15;

/// Passes `signal` on to a run.
fn send(run: &mut Running, signal: i32) {
    #[cfg(unix)]
    // SAFETY: kill(2) on a child this process started and has not reaped yet.
    unsafe {
        libc::kill(run.child.id() as libc::pid_t, signal);
    }
    #[cfg(not(unix))]
    let _ = run.child.kill();
    run.signalled = Some((signal, std::time::Instant::now()));
}

/// Starts one run, its standard output and error going to `stdout.log` and `stderr.log` in its
/// folder (a failed run's folder then says why, and a batch that stops reading cannot block it).
fn start(exe: &Path, script: &Path, job: &Job) -> std::result::Result<std::process::Child, String> {
    std::fs::create_dir_all(&job.out_dir).map_err(|e| format!("{}: {e}", job.out_dir.display()))?;
    // A summary left by an earlier batch in this folder must not be taken for this run's.
    let _ = std::fs::remove_file(job.out_dir.join("summary.json"));
    let log = |name: &str| {
        let path = job.out_dir.join(name);
        std::fs::File::create(&path).map_err(|e| format!("{}: {e}", path.display()))
    };
    let mut cmd = Command::new(exe);
    cmd.arg("run").arg(script).arg("--quiet").arg("--threads").arg("1").arg("--out").arg(&job.out_dir);
    for (k, v) in &job.overrides {
        cmd.arg("--set").arg(format!("{k}={v}"));
    }
    cmd.stdin(std::process::Stdio::null()).stdout(log("stdout.log")?).stderr(log("stderr.log")?);
    // A batch killed outright (SIGKILL, a lost session) takes its runs with it: each is sent
    // SIGTERM, stops at its next step and writes its outputs, instead of going on orphaned.
    #[cfg(target_os = "linux")]
    // SAFETY: prctl is async-signal-safe and only sets this child's own death signal.
    unsafe {
        use std::os::unix::process::CommandExt;
        cmd.pre_exec(|| {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
            Ok(())
        });
    }
    cmd.spawn().map_err(|e| format!("could not start {}: {e}", exe.display()))
}

/// The outcome of a run that ended with `exit`.
fn finished(run: Running, exit: std::process::ExitStatus) -> Outcome {
    let summary: Option<serde_json::Value> =
        std::fs::read_to_string(run.job.out_dir.join("summary.json")).ok().and_then(|t| serde_json::from_str(&t).ok());
    let code = exit.code();
    let status = match (code, run.timed_out, run.signalled) {
        (Some(0), _, _) => Status::Ok,
        (_, true, _) => Status::TimedOut,
        (_, _, Some(_)) => Status::Interrupted,
        _ => Status::Failed,
    };
    let stderr = std::fs::read_to_string(run.job.out_dir.join("stderr.log")).unwrap_or_default();
    let mut error = summary.as_ref().and_then(|s| s.get("error")).and_then(|e| e.as_str()).map(str::to_string);
    if error.is_none() && status != Status::Ok {
        // The error a run printed runs from its `granite: error:` line to the end.
        let from = stderr.find("granite: error: ").or_else(|| stderr.trim_end().rfind('\n').map(|i| i + 1));
        error = Some(stderr[from.unwrap_or(0)..].trim().to_string());
    }
    let mut error = error.unwrap_or_default();
    if status == Status::TimedOut {
        error = format!("stopped after the batch's --run-timeout of {:.0?}; {error}", run.started.elapsed());
    }
    Outcome { job: run.job, status, exit_code: code, summary, error }
}

/// Says how a run ended (unless quiet); the outcome.
fn report(outcome: Outcome, quiet: bool) -> Outcome {
    if !quiet {
        let status = match outcome.status {
            Status::Ok => "ok".to_string(),
            other => format!("{}: {}", other.name().to_uppercase(), outcome.error.lines().next().unwrap_or("")),
        };
        let params: Vec<String> = outcome.job.overrides.iter().map(|(k, v)| format!("{k}={v}")).collect();
        granite_core::errln!("granite batch: run {} [{}] {status}", outcome.job.index, params.join(" "));
    }
    outcome
}

/// `batch_summary.csv`: one row per run with its status, exit code, parameters, summary values
/// and error message. A summary value named like a parameter or a fixed column is written as
/// `summary_NAME` (one header, one meaning).
fn write_summary(out: &Path, outcomes: &[Outcome]) -> Result<()> {
    let fixed = ["run", "status", "exit_code", "error"];
    let mut params: Vec<String> = Vec::new();
    let mut keys: Vec<String> = Vec::new();
    for o in outcomes {
        for (k, _) in &o.job.overrides {
            if !params.contains(k) {
                params.push(k.clone());
            }
        }
        if let Some(serde_json::Value::Object(m)) = &o.summary {
            for k in m.keys() {
                if !keys.contains(k) && k != "error" && k != "status" {
                    keys.push(k.clone());
                }
            }
        }
    }
    // Always a warnings column: an empty one says no run warned.
    if !keys.iter().any(|k| k == "warnings") {
        keys.push("warnings".into());
    }
    let column = |k: &String| {
        if params.contains(k) || fixed.contains(&k.as_str()) {
            format!("summary_{k}")
        } else {
            k.clone()
        }
    };
    let mut header = vec!["run".to_string(), "status".to_string(), "exit_code".to_string()];
    header.extend(params.iter().cloned());
    header.extend(keys.iter().map(column));
    header.push("error".into());
    let mut w = csv::Writer::from_writer(Vec::new());
    let csv_error = |e: csv::Error| GraniteError::Other(format!("batch_summary.csv: {e}"));
    w.write_record(&header).map_err(csv_error)?;
    for o in outcomes {
        let mut row = vec![
            o.job.index.to_string(),
            o.status.name().to_string(),
            o.exit_code.map_or("none".into(), |c| c.to_string()),
        ];
        for p in &params {
            row.push(o.job.overrides.iter().find(|(k, _)| k == p).map(|(_, v)| v.clone()).unwrap_or_default());
        }
        for k in &keys {
            let v = o.summary.as_ref().and_then(|s| s.get(k)).map(|v| match v {
                serde_json::Value::String(s) => s.clone(),
                // A list of texts (the warnings), one cell.
                serde_json::Value::Array(items) if items.iter().all(|i| i.is_string()) => {
                    items.iter().filter_map(|i| i.as_str()).collect::<Vec<_>>().join(" | ")
                }
                other => other.to_string(),
            });
            row.push(v.unwrap_or_default());
        }
        row.push(o.error.clone());
        w.write_record(&row).map_err(csv_error)?;
    }
    let bytes = w.into_inner().map_err(|e| GraniteError::Other(format!("batch_summary.csv: {e}")))?;
    granite_core::io::durable::replace(&out.join("batch_summary.csv"), &bytes, granite_core::io::durable::Flush::ToDisk)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_and_sets_combine() {
        let text = "[grid]\nscheme = [\"USF\", \"USL\"]\nduration = 0.1\n[[set]]\nupdate = \"PIC\"\n[[set]]\nupdate = \"FLIP\"\n";
        let sets = parameter_sets(text, Path::new("x.toml")).unwrap();
        assert_eq!(sets.len(), 4);
        assert!(sets.iter().all(|s| s.iter().any(|(k, _)| k == "duration")));
        // Grid names come in the table's (sorted) order.
        assert_eq!(
            sets[0],
            vec![("update".into(), "PIC".into()), ("duration".into(), "0.1".into()), ("scheme".into(), "USF".into())]
        );
    }

    #[test]
    fn a_name_in_both_grid_and_set_is_refused() {
        let text = "[grid]\nupdate = [\"PIC\", \"FLIP\"]\n[[set]]\nscheme = \"USL\"\n[[set]]\nupdate = \"APIC\"\n";
        let e = parameter_sets(text, Path::new("x.toml")).unwrap_err().to_string();
        assert!(e.contains("`update` is given both in [grid] and in [[set]] number 2"), "{e}");
    }
}
