//! What every scripted simulation shares: the handle scripts hold, the run loop (boundary
//! functions once per step, callbacks every N steps, output, progress, falling back on the last
//! good state), and the script methods built on it.

use super::convert::{err, finite, number, OrRhai, RhaiResult};
use super::output::Output;
use super::ScriptContext;
use granite_core::error::{GraniteError, Result};
use granite_core::io::vtk::Field;
use granite_core::math::Vec3;
use rhai::{Dynamic, Engine, FnPtr, Map, NativeCallContext};
use std::io::IsTerminal;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// An engine as scripts drive it.
pub trait ScriptSim: Send + 'static {
    type Snapshot: Send;
    /// Checks the set-up before a run.
    fn validate(&self) -> Result<()>;
    /// One time step.
    fn advance(&mut self) -> Result<()>;
    fn time(&self) -> f64;
    fn steps(&self) -> u64;
    fn dt(&self) -> f64;
    /// Column names and values of one `series.csv` row.
    fn series_row(&self) -> (Vec<&'static str>, Vec<f64>);
    /// Names the file that continues the series when its columns change.
    fn series_tag(&self) -> &'static str {
        "more"
    }
    /// Positions and per-point fields of one VTK frame.
    fn vtk_frame(&self) -> (Vec<Vec3>, Vec<Field>);
    /// Poly data written beside each frame, by series name (DEM walls and contact network).
    fn vtk_poly(&self) -> Vec<(&'static str, granite_core::io::vtk::PolyData)> {
        Vec::new()
    }
    /// A CSV table of every point or particle.
    fn write_points(&self, path: &Path) -> Result<()>;
    /// Global measures by name, for `sim.diagnostics()`.
    fn diagnostics(&self) -> Vec<(&'static str, f64)>;
    fn snapshot(&self) -> Self::Snapshot;
    fn restore(&mut self, snapshot: Self::Snapshot);
    /// Messages for the user since the last call (deletions, mesh changes...).
    fn drain_events(&mut self) -> Vec<String>;
    /// Sets the value of boundary condition `target` from a script function (see `Handle::drive`).
    fn set_driven(&mut self, target: usize, value: f64);
    /// What the set-up should tell the user before its first run (bodies overlapping deeply);
    /// called before every run, it says each thing once.
    fn setup_warnings(&mut self) -> Vec<String> {
        Vec::new()
    }
    /// Writes a checkpoint of the whole state (every process of an MPI run calls it; the first
    /// writes) that `mpm_load` / `dem_load` resume from.
    fn save_state(&self, path: &Path, ctx: &ScriptContext) -> Result<()>;
    /// A run call ended: what the engine reports of it (the processes' share of the work in a run
    /// over MPI). Every process calls it at the same point.
    fn run_ended(&mut self, _ctx: &ScriptContext) -> Result<()> {
        Ok(())
    }
}

pub struct State<S: ScriptSim> {
    pub sim: S,
    pub ctx: Arc<ScriptContext>,
    pub output: Output,
    callbacks: Vec<(u64, FnPtr)>,
    driven: Vec<(usize, FnPtr)>,
    /// Extra series columns computed by script functions.
    columns: Vec<(String, FnPtr)>,
    output_claimed: bool,
    last_good: Option<S::Snapshot>,
    /// `sim.checkpoint_every(n, file)`: a checkpoint every n steps, and when a signal stops the run.
    checkpoint: Option<(u64, String)>,
    background: Option<Background>,
}

impl<S: ScriptSim> State<S> {
    /// Claims this simulation's output folder on its first write: the first simulation of a
    /// script that writes gets the run's folder itself (series.csv, vtk/...), the N-th one
    /// `simN/` in it; in a REPL session every simulation gets its own `simN/`.
    fn claim_output(&mut self) {
        if !self.output_claimed {
            let index = self.ctx.next_sim_index();
            if index > 1 || self.ctx.options.folder_per_simulation {
                self.output.dir = self.output.dir.join(format!("sim{index}"));
            }
            // A simulation first writes before its first step: one that has steps behind it was
            // loaded from a checkpoint, and continues the outputs of the run that wrote it.
            if self.sim.steps() > 0 {
                self.output.resumes_at = Some((self.sim.steps(), self.sim.time()));
            }
            self.output_claimed = true;
        }
    }

    /// Writes a series row with the engine's columns and already computed extra values.
    fn write_series_row(&mut self, extra: &[f64]) -> Result<()> {
        self.claim_output();
        let (mut all, mut vals) = self.sim.series_row();
        all.extend(self.columns.iter().map(|(n, _)| n.as_str()));
        vals.extend_from_slice(extra);
        let tag = self.sim.series_tag();
        let written = self.output.write_series(self.sim.steps(), &all, &vals, tag);
        written.map_err(|e| self.output_failed(e))
    }

    fn write_vtk(&mut self) -> Result<()> {
        self.claim_output();
        let (x, fields) = self.sim.vtk_frame();
        let poly = self.sim.vtk_poly();
        let written = self.output.write_vtk(self.sim.steps(), self.sim.time(), &x, &fields, &poly);
        written.map_err(|e| self.output_failed(e))
    }

    /// An output that could not be written (a full disk, a lost folder): the run stops with the
    /// step it was at, the file and the cause; what was written before stays as it was.
    fn output_failed(&self, e: GraniteError) -> GraniteError {
        GraniteError::Other(format!(
            "at step {} (t = {:.6e} s) an output could not be written: {e}; the outputs written before are kept",
            self.sim.steps(),
            self.sim.time()
        ))
    }

    /// Where a file the script names is written: relative paths in this simulation's output
    /// folder (made if missing).
    pub fn points_path(&mut self, file: &str) -> std::path::PathBuf {
        self.claim_output();
        let path = self.output.dir.join(file);
        if let Some(dir) = path.parent() {
            let _ = std::fs::create_dir_all(dir);
        }
        path
    }

    /// [`State::points_path`] of a file the script names for something it writes, checked by
    /// [`super::output::check_script_file`].
    pub fn script_file_path(&mut self, call: &str, file: &str) -> RhaiResult<std::path::PathBuf> {
        super::output::check_script_file(call, file).or_else(err)?;
        Ok(self.points_path(file))
    }

    /// Writes the checkpoint the script asked for, if it asked; its path.
    fn write_checkpoint(&mut self) -> Result<Option<std::path::PathBuf>> {
        let Some((_, file)) = self.checkpoint.clone() else { return Ok(None) };
        let path = self.points_path(&file);
        self.sim.save_state(&path, &self.ctx).map_err(|e| self.output_failed(e))?;
        Ok(Some(path))
    }

    /// A signal asked the run to stop: the state as it is after the last whole step is written
    /// (series row, VTK frame, the script's checkpoint), and the script ends with where it stopped
    /// and how to resume.
    fn stop_on_signal(&mut self, signal: i32) -> Box<rhai::EvalAltResult> {
        let (step, time) = (self.sim.steps(), self.sim.time());
        let mut msg = format!(
            "stopped by {} at step {step} (t = {time:.6e} s); the outputs hold the state up to there",
            super::signal_name(signal)
        );
        self.output.last_vtk_step = None;
        if let Err(e) = self.write_vtk() {
            msg.push_str(&format!(" (the last VTK frame could not be written: {e})"));
        }
        msg.push_str(&match self.write_checkpoint() {
            Ok(Some(path)) => format!("; checkpoint {}: resume from it with mpm_load / dem_load", path.display()),
            Ok(None) => {
                "; no checkpoint was asked for (sim.checkpoint_every(n, file) writes one, also on a signal)".into()
            }
            Err(e) => format!("; the checkpoint could not be written: {e}"),
        });
        super::convert::to_rhai(GraniteError::Other(msg))
    }

    /// Restores the last good state, writes it out, and turns the failure into a script error.
    fn fail(&mut self, e: GraniteError) -> Box<rhai::EvalAltResult> {
        let failed_step = self.sim.steps();
        let mut msg = e.to_string();
        if let Some(snap) = self.last_good.take() {
            self.sim.restore(snap);
            self.output.last_vtk_step = None;
            let path = self.points_path("last_good_points.csv");
            let writes = self.output.writes;
            let written = self.write_vtk().and_then(|_| if writes { self.sim.write_points(&path) } else { Ok(()) });
            msg = match written {
                Ok(()) => format!(
                    "{msg}\nthe last good state (step {}, t = {:.6e} s) is kept and written to {} and vtk/",
                    self.sim.steps(),
                    self.sim.time(),
                    path.display()
                ),
                Err(w) => format!("{msg}\n(could not write the last good state: {w})"),
            };
        }
        self.ctx.set_summary("failed_at_step", serde_json::Value::from(failed_step));
        super::convert::to_rhai(GraniteError::Other(msg))
    }

    /// Clears script functions driving boundary values (their targets are gone).
    pub fn clear_driven(&mut self) {
        self.driven.clear();
    }
}

/// A script's handle on one simulation (shared: closures, callbacks and a background run may
/// hold it too).
pub struct Handle<S: ScriptSim>(Arc<Shared<S>>);

pub struct Shared<S: ScriptSim> {
    /// Which simulation of the session this is (1, 2, ...): the handles of its materials carry it.
    serial: u64,
    state: Mutex<State<S>>,
    /// Threads other than a background run's waiting for the state: the run lets them in
    /// between two steps (a plain mutex may hand it straight back to the running loop).
    waiting: AtomicUsize,
}

impl<S: ScriptSim> Clone for Handle<S> {
    fn clone(&self) -> Self {
        Handle(self.0.clone())
    }
}

/// Calls script functions during a run: from inside a script call, or from a background thread
/// with the session's engine and latest compiled functions.
enum Caller<'a, 'b> {
    Within(&'a NativeCallContext<'b>),
    Detached { engine: Arc<Engine>, ctx: Arc<ScriptContext> },
}

impl Caller<'_, '_> {
    fn call(&self, f: &FnPtr, args: impl rhai::FuncArgs) -> RhaiResult<Dynamic> {
        match self {
            Caller::Within(ctx) => f.call_within_context::<Dynamic>(ctx, args),
            Caller::Detached { engine, ctx } => {
                let ast = ctx.ast.lock().unwrap().clone().unwrap_or_else(|| Arc::new(rhai::AST::empty()));
                f.call::<Dynamic>(engine, &ast, args)
            }
        }
    }
}

/// How one run goes: how long, what it writes, what stops it.
struct Plan {
    /// None: until paused.
    steps: Option<u64>,
    series_every: u64,
    vtk_every: u64,
    progress: bool,
    /// Set by `sim.pause()` for a background run.
    stop: Option<Arc<AtomicBool>>,
    /// Ctrl-C requests made before the run: a later one pauses it.
    pauses_at_start: u64,
}

/// A run going on in a thread of its own while the script or the REPL goes on.
#[derive(Clone)]
struct Background {
    stop: Arc<AtomicBool>,
    done: Arc<(Mutex<Ending>, Condvar)>,
}

#[derive(Default)]
struct Ending {
    ended: bool,
    /// The run's result until someone collects it.
    result: Option<RhaiResult<()>>,
}

impl Background {
    fn finished(&self) -> bool {
        self.done.0.lock().unwrap_or_else(|p| p.into_inner()).ended
    }

    /// Waits for the end; the run's result for the first caller, Ok after.
    fn join(&self) -> RhaiResult<()> {
        let (slot, cv) = &*self.done;
        let mut guard = slot.lock().unwrap_or_else(|p| p.into_inner());
        while !guard.ended {
            guard = cv.wait(guard).unwrap_or_else(|p| p.into_inner());
        }
        guard.result.take().unwrap_or(Ok(()))
    }
}

impl<S: ScriptSim> Handle<S> {
    pub fn new(sim: S, ctx: Arc<ScriptContext>) -> Handle<S> {
        // The output folder is chosen when the simulation first writes: a simulation that only
        // serves as a template (e.g. a loaded RVE) does not take the run's folder.
        let mut output = Output::new(ctx.options.out_dir.clone());
        output.writes = ctx.writes_files();
        let state = State {
            sim,
            ctx,
            output,
            callbacks: Vec::new(),
            driven: Vec::new(),
            columns: Vec::new(),
            output_claimed: false,
            last_good: None,
            checkpoint: None,
            background: None,
        };
        let serial = state.ctx.next_simulation_serial();
        Handle(Arc::new(Shared { serial, state: Mutex::new(state), waiting: AtomicUsize::new(0) }))
    }

    /// Which simulation of the session this is (1, 2, ...).
    pub fn serial(&self) -> u64 {
        self.0.serial
    }

    /// Checks that a handle made by simulation `owner` (a material) is used with this one.
    pub fn owns(&self, owner: u64, what: &str) -> RhaiResult<()> {
        if owner == self.serial() {
            return Ok(());
        }
        err(format!(
            "{what} belongs to simulation #{owner}, not to this one (#{}): a material is used by the simulation \
             that made it; make one for this simulation with its own material(...)",
            self.serial()
        ))
    }

    /// The state; while blocked here a thread counts as waiting, so a background run lets it in
    /// before its next step (the run's own locks are released by then and count for nothing).
    pub fn lock(&self) -> MutexGuard<'_, State<S>> {
        self.0.waiting.fetch_add(1, Ordering::SeqCst);
        let guard = self.0.state.lock().unwrap_or_else(|p| p.into_inner());
        self.0.waiting.fetch_sub(1, Ordering::SeqCst);
        guard
    }

    /// Registers a script function of time that sets boundary value `target` once per step.
    pub fn drive(&self, target: usize, f: FnPtr) {
        self.lock().driven.push((target, f));
    }

    /// Writes a series row now: extra columns are script functions, called without the lock held
    /// (they may use the simulation).
    pub fn write_series(&self, ctx: &NativeCallContext) -> RhaiResult<()> {
        self.write_series_with(&Caller::Within(ctx))
    }

    fn write_series_with(&self, caller: &Caller) -> RhaiResult<()> {
        let columns: Vec<FnPtr> = self.lock().columns.iter().map(|(_, f)| f.clone()).collect();
        let mut extra = Vec::with_capacity(columns.len());
        for f in columns {
            let v = caller.call(&f, (self.clone(),))?;
            extra.push(number(&v, "series column value")?);
        }
        self.lock().write_series_row(&extra).or_rhai()
    }

    /// Checks that no background run is going (collecting one that ended), then the set-up; writes
    /// the first frame and keeps the state to fall back on. `steps` of None: open-ended.
    fn begin(&self, steps: Option<u64>, stop: Option<Arc<AtomicBool>>) -> RhaiResult<Plan> {
        self.collect_finished()?;
        let mut guard = self.lock();
        let st = &mut *guard;
        if st.background.is_some() {
            return err(format!(
                "the simulation is running in the background (step {}): sim.pause() or sim.wait() first",
                st.sim.steps()
            ));
        }
        st.ctx.check_overrides()?;
        st.sim.validate().or_rhai()?;
        for w in st.sim.setup_warnings() {
            st.ctx.warn(&w);
        }
        // Unless the script set them, output intervals follow the run's length up to this call's
        // end: a short first call (common in the REPL) must not fix every-step output for later
        // long ones, and a script looping over short calls (`loop { sim.run_steps(500); ... }`)
        // must not write 20 frames and 500 rows per call; it gets about 20 frames and 500 rows
        // each time its step count doubles.
        let (series_every, vtk_every) = match steps {
            Some(n) => {
                let end = st.sim.steps().saturating_add(n);
                ((end / 500).max(1), (end / 20).max(1))
            }
            None => (OPEN_RUN_SERIES_EVERY, OPEN_RUN_VTK_EVERY),
        };
        let plan = Plan {
            steps,
            series_every: st.output.series_every.unwrap_or(series_every),
            vtk_every: st.output.vtk_every.unwrap_or(vtk_every),
            progress: !st.ctx.options.quiet && stop.is_none(),
            stop,
            pauses_at_start: st.ctx.pause_requests(),
        };
        if st.output.last_vtk_step.is_none() {
            st.write_vtk().or_rhai()?;
        }
        st.last_good = Some(st.sim.snapshot());
        Ok(plan)
    }

    /// Runs `steps` steps now, returning when they are done or Ctrl-C pauses the run.
    pub fn run(&self, ctx: &NativeCallContext, steps: u64) -> RhaiResult<()> {
        let plan = self.begin(Some(steps), None)?;
        self.run_plan(&Caller::Within(ctx), plan)
    }

    /// One step, with its boundary functions, callbacks and due output.
    pub fn step(&self, ctx: &NativeCallContext) -> RhaiResult<()> {
        let mut plan = self.begin(Some(1), None)?;
        let st = self.lock();
        // A single step writes a frame only on the run's own frame interval.
        plan.vtk_every = st.output.vtk_every.unwrap_or(u64::MAX);
        drop(st);
        self.run_plan(&Caller::Within(ctx), plan)
    }

    fn run_plan(&self, caller: &Caller, plan: Plan) -> RhaiResult<()> {
        self.write_series_with(caller)?;
        let progress = Progress::new(!plan.progress, plan.steps);
        let background = plan.stop.is_some();
        let mut k = 0u64;
        while plan.steps.is_none_or(|n| k < n) {
            if background {
                // Someone (the prompt) waits for the state: let it in before the next step.
                while self.0.waiting.load(Ordering::SeqCst) > 0 {
                    std::thread::yield_now();
                }
            }
            let (t, driven, paused, signal) = {
                let st = self.lock();
                let stopped = plan.stop.as_ref().is_some_and(|s| s.load(Ordering::SeqCst));
                let interrupted = st.ctx.pause_requests() != plan.pauses_at_start;
                if interrupted && !stopped {
                    granite_core::errln!("granite: paused at step {} (t = {:.6e} s)", st.sim.steps(), st.sim.time());
                }
                (st.sim.time(), st.driven.clone(), stopped || interrupted, st.ctx.stop_requested())
            };
            if let Some(signal) = signal {
                progress.finish();
                self.write_series_with(caller)?;
                return Err(self.lock().stop_on_signal(signal));
            }
            if paused {
                progress.finish();
                // The series ends on the paused state, whatever the interval.
                return self.write_series_with(caller);
            }
            let mut values = Vec::with_capacity(driven.len());
            for (_, f) in &driven {
                let v = caller.call(f, (t,))?;
                values.push(number(&v, "boundary function value")?);
            }
            let (due, series_due): (Vec<FnPtr>, bool) = {
                let mut guard = self.lock();
                let st = &mut *guard;
                for ((target, _), v) in driven.iter().zip(values) {
                    st.sim.set_driven(*target, v);
                }
                // A script law runs inside the step: a Ctrl-C at the prompt pauses the run after
                // the step (and stops the input then), never halfway through it.
                let interruptible = super::INTERRUPTIBLE_SINCE.take();
                let advanced = st.sim.advance();
                super::INTERRUPTIBLE_SINCE.set(interruptible);
                if let Err(e) = advanced {
                    return Err(st.fail(e));
                }
                for ev in st.sim.drain_events() {
                    st.ctx.warn(&ev);
                }
                k += 1;
                let step = st.sim.steps();
                let last = plan.steps == Some(k);
                let series_due = step.is_multiple_of(plan.series_every) || last;
                if series_due {
                    st.last_good = Some(st.sim.snapshot());
                }
                // A call's last state is written when the call spans a frame interval (short calls
                // in a script loop would otherwise flood vtk/).
                if step.is_multiple_of(plan.vtk_every) || (last && k >= plan.vtk_every) {
                    st.write_vtk().or_rhai()?;
                }
                if st.checkpoint.as_ref().is_some_and(|(every, _)| step.is_multiple_of(*every)) {
                    st.write_checkpoint().or_rhai()?;
                }
                progress.tick(k, st.sim.time());
                let due =
                    st.callbacks.iter().filter(|(n, _)| step.is_multiple_of(*n)).map(|(_, f)| f.clone()).collect();
                (due, series_due)
            };
            if series_due {
                self.write_series_with(caller)?;
            }
            for f in due {
                let _ = caller.call(&f, (self.clone(),))?;
            }
        }
        progress.finish();
        let mut st = self.lock();
        let ctx = st.ctx.clone();
        st.sim.run_ended(&ctx).or_rhai()
    }

    pub fn run_until(&self, ctx: &NativeCallContext, t_end: Dynamic) -> RhaiResult<()> {
        let t_end = finite(&t_end, "time")?;
        let steps = {
            let st = self.lock();
            st.sim.validate().or_rhai()?;
            let remaining = t_end - st.sim.time();
            // Half a step of slack: a script reaching its end times by sums of steps lands there
            // within rounding.
            if remaining < -0.5 * st.sim.dt() {
                return err(format!(
                    "run_until({t_end:e}): the simulation is already at t = {:e} s, past that time; nothing would run",
                    st.sim.time()
                ));
            }
            if remaining <= 0.0 {
                return Ok(());
            }
            (remaining / st.sim.dt() - 1e-9).ceil() as u64
        };
        self.run(ctx, steps)
    }

    /// Starts a run in a thread of its own and returns at once: `steps` steps, or until paused.
    /// Script functions (boundary values, callbacks) are called with the session's engine.
    pub fn start(&self, steps: Option<u64>) -> RhaiResult<()> {
        let ctx = self.lock().ctx.clone();
        let Some(engine) = ctx.engine() else {
            return err("background runs need a script session (granite run or granite repl)");
        };
        if let Some(comm) = ctx.comm() {
            return err(format!(
                "sim.run() goes on in the background, which a run over {} MPI processes cannot do (they must \
                 step together): use sim.run_steps(n) or sim.run_until(t)",
                comm.size()
            ));
        }
        let stop = Arc::new(AtomicBool::new(false));
        // A run without an end of its own is stopped, not waited for, when the script ends.
        let open_ended = steps.is_none().then(|| stop.clone());
        let plan = self.begin(steps, Some(stop.clone()))?;
        let done = Arc::new((Mutex::new(Ending::default()), Condvar::new()));
        self.lock().background = Some(Background { stop, done: done.clone() });
        let handle = self.clone();
        let caller_ctx = ctx.clone();
        let thread = std::thread::spawn(move || {
            IN_BACKGROUND_RUN.set(true);
            let caller = Caller::Detached { engine: engine.clone(), ctx: caller_ctx };
            let result = handle.run_plan(&caller, plan);
            let report = match &result {
                Ok(()) => None,
                Err(e) => Some(super::describe(e, &engine)),
            };
            if let Some(e) = &report {
                granite_core::errln!("granite: the background run stopped: {e}");
            }
            let (slot, cv) = &*done;
            *slot.lock().unwrap_or_else(|p| p.into_inner()) = Ending { ended: true, result: Some(result) };
            cv.notify_all();
            report
        });
        ctx.add_background(super::BackgroundThread { thread, open_ended });
        Ok(())
    }

    /// Takes the background run out once it has ended, passing on its error.
    fn collect_finished(&self) -> RhaiResult<()> {
        let run = self.lock().background.clone();
        match run {
            Some(run) if run.finished() => self.collect(&run),
            _ => Ok(()),
        }
    }

    /// Waits for `run` to end and forgets it.
    fn collect(&self, run: &Background) -> RhaiResult<()> {
        let result = run.join();
        let mut st = self.lock();
        if st.background.as_ref().is_some_and(|b| Arc::ptr_eq(&b.done, &run.done)) {
            st.background = None;
        }
        result
    }

    /// Waits for the background run to end (Ctrl-C pauses it); its error, if it failed.
    pub fn wait(&self) -> RhaiResult<()> {
        if IN_BACKGROUND_RUN.get() {
            return err("sim.wait() in a callback of a background run would wait for itself");
        }
        let run = self.lock().background.clone();
        run.map_or(Ok(()), |run| self.collect(&run))
    }

    /// Stops the background run after the step under way; the state stays as it is then.
    /// From a callback of that run, it only asks it to stop once the callback returns.
    pub fn pause(&self) -> RhaiResult<()> {
        let Some(run) = self.lock().background.clone() else {
            return Ok(());
        };
        run.stop.store(true, Ordering::SeqCst);
        if IN_BACKGROUND_RUN.get() {
            return Ok(());
        }
        self.collect(&run)
    }

    pub fn running(&self) -> bool {
        self.lock().background.as_ref().is_some_and(|b| !b.finished())
    }
}

thread_local! {
    /// Whether this thread runs a background run (its callbacks must not wait for it).
    static IN_BACKGROUND_RUN: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Output intervals of an open-ended run (`sim.run()`) unless the script set them.
const OPEN_RUN_SERIES_EVERY: u64 = 100;
const OPEN_RUN_VTK_EVERY: u64 = 2000;

/// Progress of a run on stderr: a bar on a terminal, a plain status line every 10 s otherwise.
struct Progress {
    bar: Option<indicatif::ProgressBar>,
    /// Not on a terminal: when the last status line went out.
    plain: Option<std::cell::Cell<Instant>>,
    total: u64,
    start: Instant,
}

impl Progress {
    fn new(quiet: bool, total: Option<u64>) -> Progress {
        let now = Instant::now();
        let mut progress = Progress { bar: None, plain: None, total: total.unwrap_or(0), start: now };
        let Some(total) = total.filter(|_| !quiet) else {
            return progress;
        };
        if std::io::stderr().is_terminal() {
            let bar = indicatif::ProgressBar::new(total);
            let style =
                indicatif::ProgressStyle::with_template("{bar:30.cyan/blue} {pos}/{len} steps  {msg}  ETA {eta}")
                    .map(|s| s.progress_chars("=> "));
            if let Ok(style) = style {
                bar.set_style(style);
            }
            // Small runs finish before the first redraw and leave nothing behind.
            bar.set_draw_target(indicatif::ProgressDrawTarget::stderr_with_hz(4));
            progress.bar = Some(bar);
        } else {
            progress.plain = Some(std::cell::Cell::new(now));
        }
        progress
    }

    fn tick(&self, done: u64, time: f64) {
        if let Some(bar) = &self.bar {
            bar.set_position(done);
            if done.is_multiple_of(64) {
                let rate = done as f64 / self.start.elapsed().as_secs_f64().max(1e-9);
                bar.set_message(format!("t = {time:.4e} s  {rate:.0} steps/s"));
            }
        } else if let Some(last) = &self.plain {
            if last.get().elapsed() < Duration::from_secs(10) {
                return;
            }
            last.set(Instant::now());
            let rate = done as f64 / self.start.elapsed().as_secs_f64().max(1e-9);
            let eta = (self.total - done) as f64 / rate.max(1e-9);
            granite_core::errln!(
                "step {done}/{} ({:.0}%)  t = {time:.4e} s  {rate:.0} steps/s  ETA {eta:.0} s",
                self.total,
                100.0 * done as f64 / self.total as f64
            );
        }
    }

    fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

/// Script methods every simulation type has.
pub fn register_common<S: ScriptSim>(engine: &mut Engine) {
    engine.register_fn("run_until", |ctx: NativeCallContext, s: &mut Handle<S>, t: Dynamic| s.run_until(&ctx, t));
    engine.register_fn("run_steps", |ctx: NativeCallContext, s: &mut Handle<S>, n: i64| {
        if n < 0 {
            return err(format!("run_steps needs n >= 0, got {n}"));
        }
        s.run(&ctx, n as u64)
    });
    engine.register_fn("run", |s: &mut Handle<S>| s.start(None));
    engine.register_fn("run", |s: &mut Handle<S>, n: i64| {
        if n < 0 {
            return err(format!("run(n) needs n >= 0, got {n}"));
        }
        s.start(Some(n as u64))
    });
    engine.register_fn("step", |ctx: NativeCallContext, s: &mut Handle<S>| s.step(&ctx));
    engine.register_fn("pause", |s: &mut Handle<S>| s.pause());
    engine.register_fn("wait", |s: &mut Handle<S>| s.wait());
    engine.register_get("running", |s: &mut Handle<S>| s.running());
    engine.register_fn("every", |s: &mut Handle<S>, n: i64, f: FnPtr| {
        if n < 1 {
            return err(format!("every(n, f) needs n >= 1, got {n}"));
        }
        s.lock().callbacks.push((n as u64, f));
        Ok(())
    });
    engine.register_fn("series_every", |s: &mut Handle<S>, n: i64| {
        if n < 1 {
            return err(format!("series_every needs a step count >= 1, got {n}"));
        }
        s.lock().output.series_every = Some(n as u64);
        Ok(())
    });
    engine.register_fn("vtk_every", |s: &mut Handle<S>, n: i64| {
        if n < 1 {
            return err(format!("vtk_every needs a step count >= 1, got {n}"));
        }
        s.lock().output.vtk_every = Some(n as u64);
        Ok(())
    });
    engine.register_fn("diagnostics", |s: &mut Handle<S>| {
        let st = s.lock();
        let mut m = Map::new();
        for (k, v) in st.sim.diagnostics() {
            m.insert(k.into(), Dynamic::from(v));
        }
        m
    });
    engine.register_fn("write_points", |s: &mut Handle<S>, file: &str| {
        let mut st = s.lock();
        let path = st.script_file_path("write_points", file)?;
        let written = if st.output.writes { st.sim.write_points(&path) } else { Ok(()) };
        granite_core::comm::agree(st.ctx.comm(), 0, written).map(|_| path.display().to_string()).or_rhai()
    });
    engine.register_fn("write_series", |ctx: NativeCallContext, s: &mut Handle<S>| s.write_series(&ctx));
    engine.register_fn("series_column", |s: &mut Handle<S>, name: &str, f: FnPtr| {
        let mut st = s.lock();
        if st.output.last_series_step.is_some() {
            return err(format!("series_column(\"{name}\", ...) must come before the first run: the columns of series.csv are fixed by its first row"));
        }
        // Two columns of one name would be read as one, whichever a reader takes.
        let (engine_columns, _) = st.sim.series_row();
        if engine_columns.contains(&name) || st.columns.iter().any(|(n, _)| n == name) {
            return err(format!(
                "series_column(\"{name}\", ...): series.csv already has a column `{name}`; give this one another name"
            ));
        }
        st.columns.push((name.to_string(), f));
        Ok(())
    });
    engine.register_fn("write_vtk", |s: &mut Handle<S>| s.lock().write_vtk().or_rhai());
    engine.register_fn("checkpoint_every", |s: &mut Handle<S>, n: i64, file: &str| {
        if n < 1 {
            return err(format!("checkpoint_every(n, file) needs n >= 1 steps, got {n}"));
        }
        super::output::check_script_file("checkpoint_every", file).or_else(err)?;
        s.lock().checkpoint = Some((n as u64, file.to_string()));
        Ok(())
    });
    engine.register_fn("vtk_format", |s: &mut Handle<S>, format: &str| {
        let encoding = granite_core::io::vtk::Encoding::parse(format).or_rhai()?;
        s.lock().output.vtk_encoding = encoding;
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_get("time", |s: &mut Handle<S>| s.lock().sim.time());
    engine.register_get("step", |s: &mut Handle<S>| s.lock().sim.steps() as i64);
    engine.register_get("dt", |s: &mut Handle<S>| s.lock().sim.dt());
}
