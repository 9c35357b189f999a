//! Rhai scripting: a script builds a simulation, runs it and writes the output contract
//! (`series.csv`, `summary.json`, `vtk/`) into the run's output folder.
//!
//! Rhai is called at set-up and from callbacks every N steps, never per material point.

// As in granite-core: index loops over fixed-size arrays read better than iterator chains, and
// negated comparisons are deliberate (they also reject NaN).
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod api_doc;
pub mod arrays;
mod body_api;
pub mod convert;
mod data_memory;
mod dem_api;
mod dem_console;
pub mod driver;
mod element;
mod limits;
mod mesh_api;
mod mpm_api;
mod output;
pub mod plot;
mod potential_api;
pub mod repl;
mod script_law;

pub use mpm_api::SimHandle;

use convert::{err, RhaiResult};
use granite_core::error::{GraniteError, Result};
use granite_core::registry::Registry;
use indexmap::IndexMap;
use limits::Limits;
use rhai::{Dynamic, Engine, EvalAltResult, NativeCallContext};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// A background run's thread; `open_ended` holds the stop flag of a run with no end of its own.
pub(crate) struct BackgroundThread {
    pub thread: std::thread::JoinHandle<Option<String>>,
    pub open_ended: Option<Arc<std::sync::atomic::AtomicBool>>,
}

/// How a script is run.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Who runs it (version and commit), recorded in provenance.json.
    pub program: String,
    /// Output folder (created if missing).
    pub out_dir: PathBuf,
    /// `--set NAME=VALUE` overrides of the script's `param(...)` declarations.
    pub overrides: Vec<(String, String)>,
    /// No progress lines.
    pub quiet: bool,
    /// Native plugin libraries to load before the script runs (`--plugin`).
    pub plugins: Vec<std::path::PathBuf>,
    /// Only list the parameters (`granite run --list-params`): the script stops where it makes its
    /// first simulation, and nothing is written.
    pub list_params: bool,
    /// Every simulation writes into a folder of its own, `simN/` (a REPL session, where one
    /// simulation follows another); otherwise the first one writing uses the folder itself.
    pub folder_per_simulation: bool,
    /// The processes running this script together (`mpirun`); None: this process alone. Every
    /// process runs the whole script; the first one writes the files.
    pub comm: Option<granite_core::comm::Comm>,
    /// Set by a signal handler to the number of a signal asking the run to stop (SIGINT, SIGTERM):
    /// a run stops cleanly at its next step and the script ends `interrupted`.
    pub stop_signal: Option<&'static std::sync::atomic::AtomicI32>,
    /// The folder of the script file (set by `run_script`): files the script reads (meshes) are
    /// also looked for there.
    pub script_dir: Option<PathBuf>,
    /// Where the runs also tell their progress (the Python package's progress bar).
    pub progress: Option<Arc<granite_run::ProgressProbe>>,
}

impl ScriptContext {
    /// Whether this process writes the run's files (the first of several processes, or the only one).
    /// Who runs the script's simulations, as the run driver needs it.
    pub fn run_context(&self) -> granite_run::RunContext {
        granite_run::RunContext {
            program: self.options.program.clone(),
            comm: self.options.comm.clone(),
            quiet: self.options.quiet,
            progress: self.options.progress.clone(),
        }
    }

    pub fn writes_files(&self) -> bool {
        self.options.comm.as_ref().is_none_or(|c| c.rank() == 0)
    }

    /// Why script code (and the long calls it makes, such as `sim.cloud`) must stop now, if it
    /// must: Ctrl-C pressed while a REPL input is evaluated, or a signal asking the run to stop.
    pub fn interrupted(&self) -> Option<String> {
        match INTERRUPTIBLE_SINCE.get() {
            Some(presses) if self.pause_requests() != presses => Some(INTERRUPTED.to_string()),
            _ if self.stopping.load(std::sync::atomic::Ordering::SeqCst) > 0 => None,
            _ => self.stop_requested().map(|s| format!("stopped by {}", signal_name(s))),
        }
    }

    /// The signal that asked the run to stop, if one did.
    pub fn stop_requested(&self) -> Option<i32> {
        self.options.stop_signal.map(|s| s.load(std::sync::atomic::Ordering::SeqCst)).filter(|&s| s != 0)
    }

    /// The other processes of the run, if any.
    pub fn comm(&self) -> Option<&granite_core::comm::Comm> {
        self.options.comm.as_ref().filter(|c| c.size() > 1)
    }

    /// A file a script reads (`mpm_load`, `dem_load`, `load_mesh`): a relative path from the
    /// working directory, else from the script's folder, the output folder or one of its
    /// simulation folders (where `sim.save` wrote it).
    pub(crate) fn input_path(&self, file: &str) -> std::result::Result<PathBuf, String> {
        // A checkpoint whose newest file was lost still has the one before (`io::durable`). A
        // FIFO or a device is taken too, to be refused by name where it is read.
        let exists = |p: &Path| (p.exists() && !p.is_dir()) || granite_core::io::durable::previous_path(p).is_file();
        let given = Path::new(file);
        if exists(given) || given.is_absolute() {
            return Ok(given.to_path_buf());
        }
        let out = &self.options.out_dir;
        let mut looked: Vec<PathBuf> = self.options.script_dir.iter().map(|d| d.join(file)).collect();
        looked.push(out.join(file));
        if let Ok(entries) = std::fs::read_dir(out) {
            let mut sims: Vec<PathBuf> = entries
                .flatten()
                .map(|e| e.path())
                .filter(|p| p.is_dir() && p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("sim")))
                .collect();
            sims.sort();
            looked.extend(sims.into_iter().map(|d| d.join(file)));
        }
        looked.iter().find(|p| exists(p)).cloned().ok_or_else(|| {
            format!(
                "no file `{file}` in the working directory ({}){} nor in the output folder {} or its simulation folders",
                std::env::current_dir().map(|d| d.display().to_string()).unwrap_or_default(),
                self.options.script_dir.as_ref().map(|d| format!(", the script's folder ({})", d.display())).unwrap_or_default(),
                out.display()
            )
        })
    }
}

/// A parameter as the script declared it, for `granite run --list-params`.
#[derive(Debug, Clone)]
pub struct Declared {
    pub name: String,
    /// The value this run takes (the `--set` value if given, else the default).
    pub value: Dynamic,
    pub default: Dynamic,
    /// What the declared limits allow ("> 0 and <= 90"), empty without limits.
    pub allowed: String,
    /// Line of the declaration, and the comment that ends it, if any.
    pub line: usize,
    pub comment: String,
}

/// What a finished script leaves behind.
#[derive(Debug, Clone)]
pub struct RunReport {
    pub out_dir: PathBuf,
    pub summary: IndexMap<String, Value>,
}

/// State shared by every function a script calls.
pub struct ScriptContext {
    registry: std::sync::RwLock<Registry>,
    /// Native plugins loaded by this script: (library, law, version).
    plugins: Mutex<Vec<(String, String, String)>>,
    /// States and checkpoints the script loaded (`mpm_load`, `dem_load`): the file read, its
    /// step, and why an older file was read instead of the one named, for provenance.json.
    loaded: Mutex<Vec<Value>>,
    pub options: RunOptions,
    declared: Mutex<IndexMap<String, Declared>>,
    summary: Mutex<IndexMap<String, Value>>,
    sims: Mutex<usize>,
    /// The compiled script, for laws written as script functions.
    pub(crate) ast: Mutex<Option<Arc<rhai::AST>>>,
    /// Ctrl-C presses so far: a run pauses at its next step when this count changes.
    pauses: std::sync::atomic::AtomicU64,
    /// The engine running the script, for runs in background threads.
    engine: Mutex<std::sync::Weak<Engine>>,
    /// Background run threads (each returns its error, if it failed), with the stop flag of
    /// those that run until paused.
    background: Mutex<Vec<BackgroundThread>>,
    /// Set when a parameter listing stopped the script at its first simulation.
    listing_done: std::sync::atomic::AtomicBool,
    /// Warnings kept for summary.json, and how many there were in all.
    warnings: Mutex<(Vec<String>, usize)>,
    /// Simulations made so far (their handles' serial numbers).
    simulations: std::sync::atomic::AtomicU64,
    /// The simulations of this script (weakly: the script's variables own them), whose outputs a
    /// signal that stops the script writes out.
    alive: Mutex<Vec<std::sync::Weak<dyn StopsOnSignal>>>,
    /// While above 0, a signal does not stop script code: the outputs of a stop are being
    /// written, and they may call the script's series columns.
    stopping: std::sync::atomic::AtomicUsize,
}

/// A simulation that writes out its state when a signal stops the script (see
/// `driver::Handle::finish_on_signal`).
pub(crate) trait StopsOnSignal: Send + Sync {
    /// What was written and how to resume; None when nothing was (never written, done already).
    fn finish_on_signal(self: Arc<Self>, signal: i32) -> Option<String>;
}

/// Script code may run while it lives, whatever signal came (see `ScriptContext::stopping`).
pub(crate) struct StoppingAllowance<'a>(&'a std::sync::atomic::AtomicUsize);

impl Drop for StoppingAllowance<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, std::sync::atomic::Ordering::SeqCst);
    }
}

/// Warnings summary.json lists in full; past these it counts them.
pub const MAX_WARNINGS_KEPT: usize = 50;

impl ScriptContext {
    fn new(registry: Registry, options: RunOptions) -> ScriptContext {
        ScriptContext {
            registry: std::sync::RwLock::new(registry),
            plugins: Mutex::new(Vec::new()),
            loaded: Mutex::new(Vec::new()),
            options,
            declared: Mutex::new(IndexMap::new()),
            summary: Mutex::new(IndexMap::new()),
            sims: Mutex::new(0),
            ast: Mutex::new(None),
            pauses: std::sync::atomic::AtomicU64::new(0),
            engine: Mutex::new(std::sync::Weak::new()),
            background: Mutex::new(Vec::new()),
            listing_done: std::sync::atomic::AtomicBool::new(false),
            warnings: Mutex::new((Vec::new(), 0)),
            simulations: std::sync::atomic::AtomicU64::new(0),
            alive: Mutex::new(Vec::new()),
            stopping: std::sync::atomic::AtomicUsize::new(0),
        }
    }

    /// Keeps a new simulation in the list a stopping signal writes out.
    pub(crate) fn add_simulation(&self, sim: std::sync::Weak<dyn StopsOnSignal>) {
        let mut alive = self.alive.lock().unwrap();
        alive.retain(|s| s.strong_count() > 0);
        alive.push(sim);
    }

    /// Lets script code run until the allowance is dropped, although a signal asked to stop.
    pub(crate) fn run_script_while_stopping(&self) -> StoppingAllowance<'_> {
        self.stopping.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        StoppingAllowance(&self.stopping)
    }

    /// A signal stopped the script: every simulation that wrote outputs and was not written out
    /// by its run writes them now (series row, VTK frame, checkpoint). What each says.
    fn finish_simulations_on_signal(&self, signal: i32) -> Vec<String> {
        let alive: Vec<_> = self.alive.lock().unwrap().iter().filter_map(|s| s.upgrade()).collect();
        alive.into_iter().filter_map(|s| s.finish_on_signal(signal)).collect()
    }

    /// The serial number of a new simulation handle.
    pub(crate) fn next_simulation_serial(&self) -> u64 {
        self.simulations.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1
    }

    /// Pauses every run at its next step (Ctrl-C).
    pub fn request_pause(&self) {
        self.pauses.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
    }

    pub(crate) fn pause_requests(&self) -> u64 {
        self.pauses.load(std::sync::atomic::Ordering::SeqCst)
    }

    pub(crate) fn engine(&self) -> Option<Arc<Engine>> {
        self.engine.lock().unwrap().upgrade()
    }

    pub(crate) fn add_background(&self, thread: BackgroundThread) {
        let mut threads = self.background.lock().unwrap();
        threads.retain(|t| !t.thread.is_finished());
        threads.push(thread);
    }

    /// Waits for every background run to end, pausing them first if asked; runs without an end
    /// (`sim.run()`) are stopped in any case. The errors of those that failed.
    pub fn finish_background(&self, pause: bool) -> Vec<String> {
        if pause {
            self.request_pause();
        }
        let threads = std::mem::take(&mut *self.background.lock().unwrap());
        for t in &threads {
            if let Some(stop) = &t.open_ended {
                stop.store(true, std::sync::atomic::Ordering::SeqCst);
            }
        }
        threads
            .into_iter()
            .filter_map(|t| t.thread.join().unwrap_or_else(|_| Some("a background run panicked".into())))
            .collect()
    }

    /// The registry (read access; plugins may be added by `load_plugin`).
    pub fn registry(&self) -> std::sync::RwLockReadGuard<'_, Registry> {
        self.registry.read().unwrap_or_else(|p| p.into_inner())
    }

    /// Loads a native law plugin into this script's registry.
    pub fn load_plugin(&self, path: &Path, replace: bool) -> Result<(String, String)> {
        let mut reg = self.registry.write().unwrap_or_else(|p| p.into_inner());
        let (name, version) = granite_loader::load_plugin(path, &mut reg, replace)?;
        let entry = (path.display().to_string(), name.clone(), version.clone());
        let mut plugins = self.plugins.lock().unwrap();
        if !plugins.contains(&entry) {
            plugins.push(entry);
        }
        Ok((name, version))
    }

    /// `param(name, default)` or `param(name, default, limits)` at `line`: the override if one
    /// was given, parsed like the default; with limits, the default and the override must meet them.
    fn param(&self, name: &str, default: Dynamic, limits: Option<&rhai::Map>, line: usize) -> RhaiResult<Dynamic> {
        let limits = limits.map(|l| Limits::parse(l, name)).transpose()?;
        if let Some(l) = &limits {
            if !l.admits(&default) {
                return err(format!(
                    "param(\"{name}\"): the default {default} is outside its own limits: must be {}",
                    l.describe()
                ));
            }
        }
        let given = self.options.overrides.iter().rev().find(|(k, _)| k == name).map(|(_, v)| v.clone());
        let value = match given {
            None => default.clone(),
            Some(text) => {
                let value = parse_like(&text, &default, name)?;
                if let Some(l) = limits.as_ref().filter(|l| !l.admits(&value)) {
                    return err(format!(
                        "--set {name}={text}: `{name}` must be {} (the default is {default})",
                        l.describe()
                    ));
                }
                value
            }
        };
        let allowed = limits.map(|l| l.describe()).unwrap_or_default();
        let declared =
            Declared { name: name.to_string(), value: value.clone(), default, allowed, line, comment: String::new() };
        self.declared.lock().unwrap().insert(name.to_string(), declared);
        Ok(value)
    }

    /// Called where a script makes a simulation: when only listing parameters, stops it there.
    /// Called where a script makes a simulation. Parameters are declared before the first one
    /// (`--list-params` stops there), so a `--set` name not declared by then is reported here, at
    /// the line of the first simulation, and not at a later, unrelated call.
    pub(crate) fn before_simulation(&self) -> RhaiResult<()> {
        if self.options.list_params {
            self.listing_done.store(true, std::sync::atomic::Ordering::SeqCst);
            return err("stopped at the first simulation: listing the parameters only");
        }
        self.check_overrides_with(" before its first simulation (this line): declare parameters at the top")
    }

    /// Every `--set` name must be declared by the script.
    pub fn check_overrides(&self) -> RhaiResult<()> {
        self.check_overrides_with("")
    }

    fn check_overrides_with(&self, when: &str) -> RhaiResult<()> {
        let declared = self.declared.lock().unwrap();
        for (k, _) in &self.options.overrides {
            if !declared.contains_key(k) {
                let list = if declared.is_empty() {
                    "none".to_string()
                } else {
                    declared.keys().cloned().collect::<Vec<_>>().join(", ")
                };
                let near = api_doc::closest(k, declared.keys().map(|s| s.as_str()));
                let hint = near.first().map(|n| format!(" (did you mean `{n}`?)")).unwrap_or_default();
                return err(format!("--set {k}: the script declares no parameter `{k}`{when}{hint}; declared: {list}"));
            }
        }
        Ok(())
    }

    /// Something the user must be told (a deleted point, a time step above the stable one): on
    /// stderr whatever `--quiet` says (it hides progress, not warnings), and in summary.json's
    /// `warnings` (the first [`MAX_WARNINGS_KEPT`], then a count of the rest).
    pub fn warn(&self, text: &str) {
        if self.writes_files() {
            granite_core::errln!("granite: {text}");
        }
        let mut warnings = self.warnings.lock().unwrap();
        warnings.1 += 1;
        if warnings.0.len() < MAX_WARNINGS_KEPT {
            warnings.0.push(text.to_string());
        }
    }

    /// Records a state or checkpoint the script loaded from file `read` (see `loaded`), and warns
    /// when it is older than the one named.
    pub(crate) fn record_load(&self, read: &Path, step: u64, fallback: Option<String>) {
        if let Some(why) = &fallback {
            self.warn(why);
        }
        let mut entry = serde_json::json!({ "file": read.display().to_string(), "step": step });
        if let Some(why) = fallback {
            entry["fallback"] = Value::from(why);
        }
        self.loaded.lock().unwrap().push(entry);
    }

    pub fn set_summary(&self, name: &str, value: Value) {
        self.summary.lock().unwrap().insert(name.to_string(), value);
    }

    pub(crate) fn next_sim_index(&self) -> usize {
        let mut n = self.sims.lock().unwrap();
        *n += 1;
        *n
    }
}

fn parse_like(text: &str, default: &Dynamic, name: &str) -> RhaiResult<Dynamic> {
    let bad = |what: &str| err(format!("--set {name}={text}: expected {what} (the default is {default})"));
    if default.is_int() {
        text.trim().parse::<i64>().map(Dynamic::from).or_else(|_| bad("an integer"))
    } else if default.is_float() {
        match text.trim().parse::<f64>() {
            Ok(x) if x.is_finite() => Ok(Dynamic::from(x)),
            _ => bad("a finite number"),
        }
    } else if default.is_bool() {
        text.trim().parse::<bool>().map(Dynamic::from).or_else(|_| bad("true or false"))
    } else {
        Ok(Dynamic::from(text.to_string()))
    }
}

fn to_json(d: &Dynamic) -> Value {
    if let Ok(f) = d.as_float() {
        serde_json::Number::from_f64(f).map(Value::Number).unwrap_or(Value::Null)
    } else if let Ok(i) = d.as_int() {
        Value::from(i)
    } else if let Ok(b) = d.as_bool() {
        Value::from(b)
    } else if d.is_array() {
        Value::Array(d.clone().into_array().unwrap_or_default().iter().map(to_json).collect())
    } else {
        Value::from(d.to_string())
    }
}

thread_local! {
    /// On the thread evaluating a REPL input: the count of Ctrl-C presses when it began. A press
    /// since then stops the input (an endless loop, a loop of runs) after pausing any run; other
    /// threads (a background run's callbacks), script laws inside a step and `granite run` are
    /// not interrupted this way.
    pub(crate) static INTERRUPTIBLE_SINCE: std::cell::Cell<Option<u64>> = const { std::cell::Cell::new(None) };
}

/// What an input stopped by Ctrl-C ends with (see [`INTERRUPTIBLE_SINCE`]).
pub(crate) const INTERRUPTED: &str = "interrupted by Ctrl-C";

fn build_engine(ctx: &Arc<ScriptContext>) -> Engine {
    let mut engine = Engine::new();
    engine.set_max_expr_depths(128, 64);
    // A script's own data may not take all the memory: `pad` and `blob` are checked before they
    // allocate, and every operation checks what the process holds (see `data_memory`). No limit
    // on operations, which would cut off a legitimate long run.
    data_memory::register_sized_builtins(&mut engine);
    let c = ctx.clone();
    let budget = data_memory::DataBudget::default();
    // Checked at every operation: a loop of runs does only a few between two runs, and the
    // check outside the REPL is one thread-local read.
    // A signal stops `granite run` between steps (see the driver) and its script here, at the
    // next operation, should it be busy outside any run.
    engine.on_progress(move |operations| c.interrupted().or_else(|| budget.check(operations)).map(Dynamic::from));
    // param(name, default) and param(name, default, limits), for each kind of default.
    macro_rules! register_param {
        ($kind:ty, $to_dynamic:expr) => {
            let c = ctx.clone();
            engine.register_fn("param", move |call: NativeCallContext, name: &str, d: $kind| {
                c.param(name, $to_dynamic(d), None, call.call_position().line().unwrap_or(0))
            });
            let c = ctx.clone();
            engine.register_fn("param", move |call: NativeCallContext, name: &str, d: $kind, limits: rhai::Map| {
                c.param(name, $to_dynamic(d), Some(&limits), call.call_position().line().unwrap_or(0))
            });
        };
    }
    register_param!(f64, Dynamic::from);
    register_param!(i64, Dynamic::from);
    register_param!(&str, |d: &str| Dynamic::from(d.to_string()));
    register_param!(bool, Dynamic::from);
    let c = ctx.clone();
    engine.register_fn("summary", move |name: &str, value: Dynamic| -> RhaiResult<()> {
        // JSON has no NaN or infinity: such a value would be written as null, with status ok.
        if let Some(bad) = non_finite(&value) {
            return err(format!(
                "summary(\"{name}\", ...): {bad} is not a finite number and JSON cannot hold it; the run has gone \
                 wrong before this line, or the value needs a check"
            ));
        }
        c.set_summary(name, to_json(&value));
        Ok(())
    });
    let c = ctx.clone();
    engine.register_fn("load_plugin", move |path: &str| -> RhaiResult<String> {
        c.load_plugin(Path::new(path), false).map(|(name, _)| name).map_err(convert::to_rhai)
    });
    let c = ctx.clone();
    engine.register_fn("load_plugin", move |path: &str, opts: rhai::Map| -> RhaiResult<String> {
        convert::api_options(&opts, "", "load_plugin")?;
        let replace = match opts.get("replace") {
            None => false,
            Some(v) => v.as_bool().map_err(|_| convert::to_rhai(GraniteError::param("replace", v, "true or false")))?,
        };
        c.load_plugin(Path::new(path), replace).map(|(name, _)| name).map_err(convert::to_rhai)
    });
    let c = ctx.clone();
    engine.register_fn("out_dir", move || c.options.out_dir.display().to_string());
    if ctx.writes_files() {
        engine.register_fn("print_line", |s: &str| granite_core::outln!("{s}"));
        // Rhai's own print and debug panic on a closed standard output.
        engine.on_print(|s| granite_core::outln!("{s}"));
        engine.on_debug(|s, source, pos| match source {
            Some(source) => granite_core::errln!("{source} @ {pos:?} | {s}"),
            None => granite_core::errln!("{pos:?} | {s}"),
        });
    } else {
        // The other processes of an MPI run run the same script: one of them speaks.
        engine.register_fn("print_line", |_: &str| {});
        engine.on_print(|_| {});
        engine.on_debug(|_, _, _| {});
    }
    let c = ctx.clone();
    engine.register_fn("plot", move |csv: &str, x: &str, ys: rhai::Array, out: &str| -> RhaiResult<String> {
        output::check_script_file("plot", out).or_else(err)?;
        let dir = &c.options.out_dir;
        let ys: Vec<String> = ys.iter().map(|y| y.to_string()).collect();
        let drawn = if c.writes_files() {
            crate::plot::plot(&dir.join(csv), x, &ys, Some(dir.join(out))).map(|_| ())
        } else {
            Ok(())
        };
        granite_core::comm::agree(c.comm(), 0, drawn).map_err(convert::to_rhai)?;
        Ok(dir.join(out).display().to_string())
    });
    let c = ctx.clone();
    engine.register_fn(
        "plot_field",
        move |csv: &str, x: &str, y: &str, value: &str, out: &str| -> RhaiResult<String> {
            output::check_script_file("plot_field", out).or_else(err)?;
            output::check_read_file("plot_field", csv).or_else(err)?;
            let dir = &c.options.out_dir;
            let drawn = if c.writes_files() {
                crate::plot::plot_field(&dir.join(csv), (x, y), value, dir.join(out)).map(|_| ())
            } else {
                Ok(())
            };
            granite_core::comm::agree(c.comm(), 0, drawn).map_err(convert::to_rhai)?;
            Ok(dir.join(out).display().to_string())
        },
    );
    let c = ctx.clone();
    engine.register_fn("exists", move |file: &str| -> RhaiResult<bool> {
        output::check_read_file("exists", file).or_else(err)?;
        let path = c.options.out_dir.join(file);
        // A checkpoint whose newest copy was lost still has the one before (`durable`).
        Ok(path.is_file() || granite_core::io::durable::previous_path(&path).is_file())
    });
    let c = ctx.clone();
    engine.register_fn("read_column", move |csv: &str, column: &str| -> RhaiResult<rhai::Array> {
        output::check_read_file("read_column", csv).or_else(err)?;
        let values = crate::plot::read_column(&c.options.out_dir.join(csv), column).map_err(convert::to_rhai)?;
        Ok(values.into_iter().map(Dynamic::from).collect())
    });
    mpm_api::register(&mut engine, ctx);
    dem_api::register(&mut engine, ctx);
    dem_console::register(&mut engine);
    potential_api::register(&mut engine);
    body_api::register(&mut engine);
    element::register(&mut engine, ctx);
    mesh_api::register(&mut engine, ctx);
    script_law::register(&mut engine, ctx);
    engine
}

/// The output folder, the context with `--plugin` libraries loaded, and an engine on it.
pub(crate) fn prepare(registry: Registry, options: RunOptions) -> Result<(Arc<ScriptContext>, Arc<Engine>)> {
    let out_dir = options.out_dir.clone();
    if !options.list_params {
        std::fs::create_dir_all(&out_dir).map_err(|e| GraniteError::io(&out_dir, e))?;
    }
    let plugins = options.plugins.clone();
    let ctx = Arc::new(ScriptContext::new(registry, options));
    for p in &plugins {
        ctx.load_plugin(p, false)?;
    }
    let engine = Arc::new(build_engine(&ctx));
    *ctx.engine.lock().unwrap() = Arc::downgrade(&engine);
    Ok((ctx, engine))
}

/// The parameters a script declares before it makes its first simulation, with the values
/// `options.overrides` give them (checked as a run would check them), their limits and the
/// comment ending each declaration's line. Nothing is run or written.
pub fn list_params(path: &Path, registry: Registry, options: RunOptions) -> Result<Vec<Declared>> {
    let source = std::fs::read_to_string(path).map_err(|e| GraniteError::io(path, e))?;
    let name = path.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
    // Files the script reads before its first simulation (a mesh) are found as a run finds them.
    let script_dir = Some(path.parent().map(Path::to_path_buf).unwrap_or_default());
    let (ctx, engine) = prepare(registry, RunOptions { list_params: true, script_dir, ..options })?;
    let ast = engine.compile(&source).map_err(|e| GraniteError::Other(format!("{name}: syntax error: {e}")))?;
    if let Err(e) = engine.run_ast(&ast) {
        if !ctx.listing_done.load(std::sync::atomic::Ordering::SeqCst) {
            return Err(GraniteError::Other(format!("{name}: {}", describe(&e, &engine))));
        }
    }
    let lines: Vec<&str> = source.lines().collect();
    let mut declared: Vec<Declared> = ctx.declared.lock().unwrap().values().cloned().collect();
    for d in &mut declared {
        let text = d.line.checked_sub(1).and_then(|i| lines.get(i)).copied().unwrap_or("");
        d.comment = line_comment(text).unwrap_or_default().trim().to_string();
    }
    Ok(declared)
}

/// The `//` comment ending a line of Rhai, if any (a `//` inside a string literal is text).
fn line_comment(line: &str) -> Option<&str> {
    let mut quote: Option<char> = None;
    let mut escaped = false;
    for (i, c) in line.char_indices() {
        match (quote, c) {
            (Some(_), _) if escaped => escaped = false,
            (Some(_), '\\') => escaped = true,
            (Some(q), c) if c == q => quote = None,
            (None, '"' | '`') => quote = Some(c),
            (None, '/') if line[i + 1..].starts_with('/') => return Some(&line[i + 2..]),
            _ => {}
        }
    }
    None
}

/// Runs a script file. The output folder gets `summary.json` whatever happens; a failed run
/// records `status: "failed"` and the error there too.
pub fn run_script(path: &Path, registry: Registry, options: RunOptions) -> Result<RunReport> {
    let source = std::fs::read_to_string(path).map_err(|e| GraniteError::io(path, e))?;
    let name = path.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
    let script_dir = Some(path.parent().map(Path::to_path_buf).unwrap_or_default());
    run_source(&name, &source, registry, RunOptions { script_dir, ..options })
}

/// Runs script text; `name` is used in error messages.
pub fn run_source(name: &str, source: &str, registry: Registry, options: RunOptions) -> Result<RunReport> {
    let out_dir = options.out_dir.clone();
    let (ctx, engine) = prepare(registry, options)?;
    let started = std::time::Instant::now();
    let started_at = std::time::SystemTime::now();
    let outcome = engine
        .compile(source)
        .map_err(|e| format!("{name}: syntax error: {e}"))
        .and_then(|ast| {
            *ctx.ast.lock().unwrap() = Some(Arc::new(ast.clone()));
            // The script's variables outlive an error in a scope of this function's: a signal that
            // stopped plain script code (between runs, in a loop of its own) left the outputs of
            // the simulations they hold to close here.
            let mut scope = rhai::Scope::new();
            let ran =
                engine.run_ast_with_scope(&mut scope, &ast).map_err(|e| format!("{name}: {}", describe(&e, &engine)));
            let ran = match (ran, ctx.stop_requested()) {
                (Err(e), Some(signal)) => {
                    let written = ctx.finish_simulations_on_signal(signal);
                    Err(std::iter::once(e).chain(written).collect::<Vec<_>>().join("\n"))
                }
                (ran, _) => ran,
            };
            // Runs the script left going in the background finish before its outputs are closed.
            let failed = ctx.finish_background(false);
            ran.and_then(|_| match failed.first() {
                Some(e) => Err(format!("{name}: background run: {e}")),
                None => Ok(()),
            })
        })
        .and_then(|_| ctx.check_overrides().map_err(|e| format!("{name}: {}", describe(&e, &engine))));
    let mut summary = ctx.summary.lock().unwrap().clone();
    let status = match (&outcome, ctx.stop_requested()) {
        (_, Some(_)) => "interrupted",
        (Ok(()), None) => "ok",
        (Err(_), None) => "failed",
    };
    summary.insert("status".into(), Value::from(status));
    if let Some(signal) = ctx.stop_requested() {
        summary.insert("signal".into(), Value::from(signal_name(signal)));
    }
    let (mut warnings, count) = ctx.warnings.lock().unwrap().clone();
    if count > warnings.len() {
        warnings.push(format!("... and {} more warnings (on stderr)", count - warnings.len()));
    }
    if !warnings.is_empty() {
        summary.insert("warnings".into(), Value::from(warnings));
    }
    if let Err(e) = &outcome {
        summary.insert("error".into(), Value::from(e.clone()));
    }
    summary.insert("wall_time_s".into(), Value::from(started.elapsed().as_secs_f64()));
    if ctx.writes_files() {
        let records = granite_core::io::write_summary(&out_dir.join("summary.json"), &summary)
            .and_then(|()| write_provenance(&out_dir, name, source, &ctx, started_at, summary.get("status")));
        if let Err(e) = records {
            // The run's own error comes first: it is what failed first (a full disk fails the
            // run's outputs before its summary).
            let ended = match &outcome {
                Ok(()) => format!("the run itself ended {status}"),
                Err(run) => format!("the run had stopped: {run}"),
            };
            return Err(GraniteError::Other(format!("{ended}; then its records could not be written: {e}")));
        }
    }
    match outcome {
        Ok(()) => Ok(RunReport { out_dir, summary }),
        Err(e) => Err(GraniteError::Other(e)),
    }
}

/// The first number in `value` (an array or map searched too) that is NaN or infinite.
fn non_finite(value: &Dynamic) -> Option<f64> {
    if let Ok(x) = value.as_float() {
        return (!x.is_finite()).then_some(x);
    }
    if let Some(items) = value.read_lock::<rhai::Array>() {
        return items.iter().find_map(non_finite);
    }
    if let Some(map) = value.read_lock::<rhai::Map>() {
        return map.values().find_map(non_finite);
    }
    None
}

/// SIGINT, SIGTERM, or the number of another signal.
pub fn signal_name(signal: i32) -> String {
    match signal {
        2 => "SIGINT".into(),
        15 => "SIGTERM".into(),
        1 => "SIGHUP".into(),
        n => format!("signal {n}"),
    }
}

/// 64-bit FNV-1a of the script text: enough to tell two versions of a script apart.
fn fnv1a(text: &str) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in text.bytes() {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    format!("fnv1a64:{h:016x}")
}

/// Seconds since the Unix epoch, UTC, as ISO 8601.
fn iso8601(t: std::time::SystemTime) -> String {
    let secs = t.duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0);
    let (days, rem) = (secs / 86_400, secs % 86_400);
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + if m <= 2 { 1 } else { 0 };
    format!("{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z", rem / 3600, rem % 3600 / 60, rem % 60)
}

/// `provenance.json`: what ran, with which parameters and plugins, on how many threads, when.
fn write_provenance(
    out_dir: &Path,
    name: &str,
    source: &str,
    ctx: &ScriptContext,
    started: std::time::SystemTime,
    status: Option<&Value>,
) -> Result<()> {
    let params: IndexMap<String, Value> =
        ctx.declared.lock().unwrap().iter().map(|(k, d)| (k.clone(), to_json(&d.value))).collect();
    let plugins = serde_json::json!({
        "constitutive_laws": ctx.registry().law_names(),
        "velocity_updates": ctx.registry().velocity_update_names(),
        "contact_laws": ctx.registry().contact_law_names(),
        "shapes": ctx.registry().shape_names(),
        "body_kinds": ctx.registry().body_kind_names(),
        "loaded": ctx.plugins.lock().unwrap().iter().map(|(lib, law, version)| serde_json::json!({ "library": lib, "law": law, "version": version })).collect::<Vec<_>>(),
    });
    let mut p = IndexMap::new();
    p.insert("program".to_string(), Value::from(ctx.options.program.clone()));
    p.insert("script".to_string(), Value::from(name));
    p.insert("script_hash".to_string(), Value::from(fnv1a(source)));
    p.insert("parameters".to_string(), serde_json::to_value(params).unwrap_or(Value::Null));
    p.insert(
        "overrides".to_string(),
        Value::from(ctx.options.overrides.iter().map(|(k, v)| format!("{k}={v}")).collect::<Vec<_>>()),
    );
    p.insert("plugins".to_string(), plugins);
    p.insert("loaded".to_string(), Value::from(ctx.loaded.lock().unwrap().clone()));
    p.insert("threads".to_string(), Value::from(rayon::current_num_threads()));
    p.insert("processes".to_string(), Value::from(ctx.options.comm.as_ref().map_or(1, |c| c.size())));
    p.insert("started".to_string(), Value::from(iso8601(started)));
    p.insert("ended".to_string(), Value::from(iso8601(std::time::SystemTime::now())));
    p.insert("status".to_string(), status.cloned().unwrap_or(Value::Null));
    granite_core::io::write_summary(&out_dir.join("provenance.json"), &p)
}

/// A script error in one line: the message first, then where it happened. A call that matches
/// no function of `engine` also lists the forms the API has under that name.
pub(crate) fn describe(e: &EvalAltResult, engine: &Engine) -> String {
    let mut inner = e;
    let mut pos = e.position();
    while let EvalAltResult::ErrorInFunctionCall(_, _, next, p) = inner {
        if !p.is_none() {
            pos = *p;
        }
        inner = next;
    }
    let msg = match inner {
        EvalAltResult::ErrorRuntime(d, _) => d.to_string(),
        EvalAltResult::ErrorFunctionNotFound(call, _) => function_not_found(call, engine),
        // The token says what stopped it: Ctrl-C at the prompt, or a signal naming itself.
        EvalAltResult::ErrorTerminated(token, _) => {
            let why = token.clone().into_string().unwrap_or_else(|_| INTERRUPTED.to_string());
            format!("{why}: the input stopped here; simulations keep their state")
        }
        other => {
            let s = other.to_string();
            let s = match s.find(" (line ") {
                Some(i) => s[..i].to_string(),
                None => s,
            };
            property_hint(s)
        }
    };
    let p = if inner.position().is_none() { pos } else { inner.position() };
    match p.line() {
        Some(line) => format!("line {line}: {msg}"),
        None => msg,
    }
}

/// Rhai's "Unknown property 'tme' - a getter is not registered for type 'DemSim'" with the
/// closest names that type has.
fn property_hint(message: String) -> String {
    let quoted = |after: &str| {
        let start = message.find(after)? + after.len();
        let end = message[start..].find('\'')? + start;
        Some(message[start..end].to_string())
    };
    let (Some(name), Some(ty)) = (quoted("Unknown property '"), quoted("for type '")) else { return message };
    let names = api_doc::API.iter().filter(|d| d.on == ty || (d.on == "sim" && ty.ends_with("Sim"))).map(|d| d.name);
    let near = api_doc::closest(&name, names);
    match near.first() {
        Some(n) => format!("{message}; did you mean `{n}`?"),
        None => message,
    }
}

/// "Function not found: every (MpmSim, f64, Fn)" with the forms of `every` that exist; Rhai
/// does not turn a float into an integer, so a count or an index written `10.0` lands here.
fn function_not_found(call: &str, engine: &Engine) -> String {
    let name = call.split_once(" (").map_or(call, |(name, _)| name);
    let forms: Vec<String> = repl::api_signatures(engine)
        .into_iter()
        .filter(|form| {
            let head = form.split_once('(').map_or(form.as_str(), |(head, _)| head);
            head.rsplit('.').next() == Some(name)
        })
        .collect();
    if forms.is_empty() {
        // A script function or one of Rhai's own: its text says enough.
        let hint = api_doc::did_you_mean(name);
        return format!(
            "Function not found: {call}{hint} (`:help NAME` and `:api` in `granite repl` describe granite's functions)"
        );
    }
    // An `int` argument, not "int" inside a name such as `point_stress`.
    let takes_int =
        |form: &String| form.split_once('(').is_some_and(|(_, args)| args.split([',', ')']).any(|a| a.trim() == "int"));
    let hint = if call.contains("f64") && forms.iter().any(takes_int) {
        "; counts and indices are integers: write 10, not 10.0"
    } else {
        ""
    };
    format!("no form of `{name}` takes these arguments ({call}); the API has: {}{hint}", forms.join(", "))
}

#[cfg(test)]
mod tests {
    use super::line_comment;

    #[test]
    fn line_comments_skip_slashes_inside_strings() {
        assert_eq!(line_comment(r#"let v = param("w", 0.0); // m/s; 0: default"#), Some(" m/s; 0: default"));
        assert_eq!(line_comment(r#"let u = param("url", "http://x\"//y"); // where"#), Some(" where"));
        assert_eq!(line_comment("let s = `a // b`;"), None);
    }
}
