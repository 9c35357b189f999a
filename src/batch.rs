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
use std::sync::Mutex;

/// One run: its index, its `NAME=VALUE` overrides and its output folder.
#[derive(Debug, Clone)]
pub struct Job {
    pub index: usize,
    pub overrides: Vec<(String, String)>,
    pub out_dir: PathBuf,
}

/// The outcome of one run.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub job: Job,
    pub exit_code: Option<i32>,
    pub summary: Option<serde_json::Value>,
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
        crate::describe_params(script, set.clone(), Vec::new()).map_err(|e| {
            let params: Vec<String> = set.iter().map(|(k, v)| format!("{k}={v}")).collect();
            GraniteError::Setup(format!("run {k} [{}] would fail before it starts: {e}", params.join(" ")))
        })?;
    }
    Ok(())
}

/// Runs every set with the `granite` executable `exe`, `jobs` at a time, and writes
/// `OUT/batch_summary.csv`. Returns the outcomes in set order.
pub fn run(
    exe: &Path,
    script: &Path,
    params_file: &Path,
    out: &Path,
    jobs: usize,
    quiet: bool,
) -> Result<Vec<Outcome>> {
    let text = std::fs::read_to_string(params_file).map_err(|e| GraniteError::io(params_file, e))?;
    let sets = parameter_sets(&text, params_file)?;
    check_sets(script, &sets)?;
    std::fs::create_dir_all(out).map_err(|e| GraniteError::io(out, e))?;
    let queue: Vec<Job> = sets
        .into_iter()
        .enumerate()
        .map(|(index, overrides)| Job { index, overrides, out_dir: out.join(format!("run_{index:03}")) })
        .collect();
    let next = Mutex::new(0usize);
    let results = Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..jobs.max(1) {
            scope.spawn(|| loop {
                let job = {
                    let mut n = next.lock().unwrap_or_else(|p| p.into_inner());
                    if *n >= queue.len() {
                        return;
                    }
                    *n += 1;
                    queue[*n - 1].clone()
                };
                let mut cmd = Command::new(exe);
                cmd.arg("run").arg(script).arg("--quiet").arg("--threads").arg("1").arg("--out").arg(&job.out_dir);
                for (k, v) in &job.overrides {
                    cmd.arg("--set").arg(format!("{k}={v}"));
                }
                let outcome = match cmd.output() {
                    Ok(o) => {
                        // The run's own output, kept beside its results (a failed run's folder
                        // then says why).
                        let _ = std::fs::create_dir_all(&job.out_dir);
                        let _ = std::fs::write(job.out_dir.join("stdout.log"), &o.stdout);
                        let _ = std::fs::write(job.out_dir.join("stderr.log"), &o.stderr);
                        Outcome {
                            exit_code: o.status.code(),
                            summary: std::fs::read_to_string(job.out_dir.join("summary.json"))
                                .ok()
                                .and_then(|t| serde_json::from_str(&t).ok()),
                            error: String::from_utf8_lossy(&o.stderr).trim().to_string(),
                            job,
                        }
                    }
                    Err(e) => Outcome {
                        exit_code: None,
                        summary: None,
                        error: format!("could not start {}: {e}", exe.display()),
                        job,
                    },
                };
                if !quiet {
                    let status = if outcome.exit_code == Some(0) {
                        "ok".to_string()
                    } else {
                        format!("FAILED: {}", outcome.error)
                    };
                    let params: Vec<String> = outcome.job.overrides.iter().map(|(k, v)| format!("{k}={v}")).collect();
                    granite_core::errln!("granite batch: run {} [{}] {status}", outcome.job.index, params.join(" "));
                }
                results.lock().unwrap_or_else(|p| p.into_inner()).push(outcome);
            });
        }
    });
    let mut outcomes = results.into_inner().unwrap_or_else(|p| p.into_inner());
    outcomes.sort_by_key(|o| o.job.index);
    write_summary(out, &outcomes)?;
    Ok(outcomes)
}

/// `batch_summary.csv`: one row per run with its parameters, exit status and summary values.
fn write_summary(out: &Path, outcomes: &[Outcome]) -> Result<()> {
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
                if !keys.contains(k) && k != "error" {
                    keys.push(k.clone());
                }
            }
        }
    }
    // Always a warnings column: an empty one says no run warned.
    if !keys.iter().any(|k| k == "warnings") {
        keys.push("warnings".into());
    }
    let path = out.join("batch_summary.csv");
    let mut w = csv::Writer::from_path(&path).map_err(|e| GraniteError::Other(format!("{}: {e}", path.display())))?;
    let mut header = vec!["run".to_string(), "exit_code".to_string()];
    header.extend(params.iter().cloned());
    header.extend(keys.iter().cloned());
    header.push("error".into());
    w.write_record(&header).map_err(|e| GraniteError::Other(e.to_string()))?;
    for o in outcomes {
        let mut row = vec![o.job.index.to_string(), o.exit_code.map_or("none".into(), |c| c.to_string())];
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
        row.push(o.error.lines().last().unwrap_or("").to_string());
        w.write_record(&row).map_err(|e| GraniteError::Other(e.to_string()))?;
    }
    w.flush().map_err(|e| GraniteError::io(&path, e))
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
