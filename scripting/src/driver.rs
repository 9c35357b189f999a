//! What every scripted simulation shares: the handle scripts hold, the run loop (boundary
//! functions once per step, callbacks every N steps, output, progress, falling back on the last
//! good state), and the script methods built on it.

use super::convert::{err, finite, number, OrRhai, RhaiResult};
use super::ScriptContext;
use granite_core::error::{GraniteError, Result};
use granite_run::{Cadence, Progress, Runner, Simulation};
use rhai::{Dynamic, Engine, FnPtr, Map, NativeCallContext};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};

pub struct State<S: Simulation> {
    /// The simulation with its outputs, last good state and checkpoint.
    pub run: Runner<S>,
    pub ctx: Arc<ScriptContext>,
    callbacks: Vec<(u64, FnPtr)>,
    driven: Vec<(usize, FnPtr)>,
    /// Extra series columns computed by script functions.
    columns: Vec<(String, FnPtr)>,
    background: Option<Background>,
    /// A signal's stop was written out (series row, VTK frame, checkpoint): done once.
    stopped_on_signal: bool,
}

impl<S: Simulation> std::ops::Deref for State<S> {
    type Target = Runner<S>;
    fn deref(&self) -> &Runner<S> {
        &self.run
    }
}

impl<S: Simulation> std::ops::DerefMut for State<S> {
    fn deref_mut(&mut self) -> &mut Runner<S> {
        &mut self.run
    }
}

impl<S: Simulation> State<S> {
    /// Writes a series row with the engine's columns and already computed extra values.
    fn write_series_row(&mut self, extra: &[f64]) -> Result<()> {
        let names: Vec<&str> = self.columns.iter().map(|(n, _)| n.as_str()).collect();
        self.run.write_series_row(&names, extra)
    }

    /// Where a file the script names is written: relative paths in this simulation's output
    /// folder (made if missing).
    pub fn points_path(&mut self, file: &str) -> RhaiResult<std::path::PathBuf> {
        self.run.output_path(file).or_rhai()
    }

    /// [`State::points_path`] of a file the script names for something it writes, checked by
    /// [`super::output::check_script_file`].
    pub fn script_file_path(&mut self, call: &str, file: &str) -> RhaiResult<std::path::PathBuf> {
        super::output::check_script_file(call, file).or_else(err)?;
        self.points_path(file)
    }

    /// A signal asked the run to stop: the state as it is after the last whole step is written
    /// (series row, VTK frame, the script's checkpoint), and the script ends with where it stopped
    /// and how to resume.
    fn stop_on_signal(&mut self, signal: i32) -> String {
        self.stopped_on_signal = true;
        self.run.stop_on_signal(&super::signal_name(signal))
    }

    /// A failed step (the last good state restored and written by the runner) as a script error.
    fn failed(&mut self, e: GraniteError) -> Box<rhai::EvalAltResult> {
        if let Some(step) = self.run.failed_at_step.take() {
            self.ctx.set_summary("failed_at_step", serde_json::Value::from(step));
        }
        super::convert::to_rhai(e)
    }

    /// Keeps the script functions driving boundary values whose targets stay (`keep[target]`),
    /// numbering those targets anew in order; the others' targets are gone.
    pub fn retain_driven(&mut self, keep: &[bool]) {
        let renumbered: Vec<Option<usize>> = keep
            .iter()
            .scan(0, |next, &k| {
                let at = k.then_some(*next);
                *next += usize::from(k);
                Some(at)
            })
            .collect();
        self.driven.retain_mut(|(target, _)| match renumbered.get(*target).copied().flatten() {
            Some(at) => {
                *target = at;
                true
            }
            None => false,
        });
    }
}

/// A script's handle on one simulation (shared: closures, callbacks and a background run may
/// hold it too).
pub struct Handle<S: Simulation>(Arc<Shared<S>>);

pub struct Shared<S: Simulation> {
    /// Which simulation of the session this is (1, 2, ...): the handles of its materials carry it.
    serial: u64,
    state: Mutex<State<S>>,
    /// Threads other than a background run's waiting for the state: the run lets them in
    /// between two steps (a plain mutex may hand it straight back to the running loop).
    waiting: AtomicUsize,
}

impl<S: Simulation> Clone for Handle<S> {
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
    cadence: Cadence,
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

impl<S: Simulation> Handle<S> {
    pub fn new(sim: S, ctx: Arc<ScriptContext>) -> Handle<S> {
        let mut run = Runner::new(sim, ctx.options.out_dir.clone(), ctx.run_context());
        // The output folder is chosen when the simulation first writes: a simulation that only
        // serves as a template (e.g. a loaded RVE) does not take the run's folder. The first
        // simulation of a script that writes gets the run's folder itself (series.csv, vtk/...),
        // the N-th one `simN/` in it; in a REPL session every simulation gets its own `simN/`.
        let chooser = ctx.clone();
        run.choose_folder_on_first_write(Box::new(move |dir: &std::path::Path| {
            let index = chooser.next_sim_index();
            if index > 1 || chooser.options.folder_per_simulation {
                dir.join(format!("sim{index}"))
            } else {
                dir.to_path_buf()
            }
        }));
        let state = State {
            run,
            ctx,
            callbacks: Vec::new(),
            driven: Vec::new(),
            columns: Vec::new(),
            background: None,
            stopped_on_signal: false,
        };
        let serial = state.ctx.next_simulation_serial();
        let ctx = state.ctx.clone();
        let shared = Arc::new(Shared { serial, state: Mutex::new(state), waiting: AtomicUsize::new(0) });
        let weak: std::sync::Weak<dyn super::StopsOnSignal> = Arc::downgrade(&shared) as _;
        ctx.add_simulation(weak);
        Handle(shared)
    }

    /// A signal asked the run to stop, whatever was executing (a step's end, a callback, a series
    /// column, plain script code): the outputs of the state after the last whole step are
    /// written once (series row, VTK frame, the script's checkpoint). The series row's script
    /// columns are computed while the signal is set aside (a second signal still ends the
    /// process at once); one that fails is left empty. Returns what was written and how to
    /// resume, or None for a simulation that never wrote or was written out already.
    fn finish_on_signal(&self, caller: Option<&Caller>, signal: i32) -> Option<String> {
        let (columns, ctx) = {
            let st = self.lock();
            if st.stopped_on_signal || !st.run.has_written() {
                return None;
            }
            (st.columns.iter().map(|(_, f)| f.clone()).collect::<Vec<FnPtr>>(), st.ctx.clone())
        };
        let detached = ctx.engine().map(|engine| Caller::Detached { engine, ctx: ctx.clone() });
        let extra: Vec<f64> = {
            let _allowed = ctx.run_script_while_stopping();
            columns
                .iter()
                .map(|f| {
                    let value = caller.or(detached.as_ref()).map(|c| c.call(f, (self.clone(),)));
                    match value {
                        Some(Ok(v)) => number(&v, "series column value").unwrap_or(f64::NAN),
                        _ => f64::NAN,
                    }
                })
                .collect()
        };
        let mut st = self.lock();
        let row = st.write_series_row(&extra).err();
        let mut msg = st.stop_on_signal(signal);
        if let Some(e) = row {
            msg.push_str(&format!(" (the last series row could not be written: {e})"));
        }
        Some(msg)
    }

    /// Which simulation of the session this is (1, 2, ...).
    pub fn serial(&self) -> u64 {
        self.0.serial
    }

    /// Checks that a handle made by simulation `owner` (a material, a wall) is used with this one;
    /// `remedy` says how to make one for this simulation.
    pub fn owns(&self, owner: u64, what: &str, remedy: &str) -> RhaiResult<()> {
        if owner == self.serial() {
            return Ok(());
        }
        err(format!(
            "{what} belongs to simulation #{owner}, not to this one (#{}): it is used by the simulation that made \
             it; {remedy}",
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
        for w in st.run.prepare().or_rhai()? {
            st.ctx.warn(&w);
        }
        let cadence = st.run.cadence(steps);
        let plan = Plan {
            steps,
            cadence,
            progress: !st.ctx.options.quiet && stop.is_none(),
            stop,
            pauses_at_start: st.ctx.pause_requests(),
        };
        st.run.open(cadence).or_rhai()?;
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
        plan.cadence.vtk_every = st.output.vtk_every.unwrap_or(u64::MAX);
        drop(st);
        self.run_plan(&Caller::Within(ctx), plan)
    }

    fn run_plan(&self, caller: &Caller, plan: Plan) -> RhaiResult<()> {
        let ran = self.run_steps_of(caller, &plan);
        // A signal may have stopped script code this run called (a callback, a series column, a
        // boundary function): the stop is written out as at a step's end.
        if let Err(e) = ran {
            let signal = self.lock().ctx.stop_requested();
            return Err(match signal.and_then(|s| self.finish_on_signal(Some(caller), s)) {
                Some(msg) => super::convert::to_rhai(GraniteError::Other(msg)),
                None => e,
            });
        }
        Ok(())
    }

    fn run_steps_of(&self, caller: &Caller, plan: &Plan) -> RhaiResult<()> {
        self.write_series_with(caller)?;
        let probe = self.lock().ctx.options.progress.clone();
        let progress = Progress::new(!plan.progress, plan.steps, probe);
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
                let msg = self
                    .finish_on_signal(Some(caller), signal)
                    .unwrap_or_else(|| format!("stopped by {}", super::signal_name(signal)));
                return Err(super::convert::to_rhai(GraniteError::Other(msg)));
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
                k += 1;
                let stepped = st.run.step(plan.cadence, k, plan.steps == Some(k));
                super::INTERRUPTIBLE_SINCE.set(interruptible);
                let done = match stepped {
                    Ok(done) => done,
                    Err(e) => return Err(st.failed(e)),
                };
                for ev in done.events {
                    st.ctx.warn(&ev);
                }
                let step = st.sim.steps();
                progress.tick(k, st.sim.time());
                let series_due = done.series_due;
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
        let end = st.run.end().or_rhai()?;
        let summary = std::mem::take(&mut st.run.summary);
        for (key, value) in summary {
            st.ctx.set_summary(&key, value);
        }
        drop(end);
        Ok(())
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

impl<S: Simulation> super::StopsOnSignal for Shared<S> {
    fn finish_on_signal(self: Arc<Self>, signal: i32) -> Option<String> {
        Handle(self).finish_on_signal(None, signal)
    }
}

thread_local! {
    /// Whether this thread runs a background run (its callbacks must not wait for it).
    static IN_BACKGROUND_RUN: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Script methods every simulation type has.
pub fn register_common<S: Simulation>(engine: &mut Engine) {
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
            let value = match granite_run::simulation::whole_count(k, v) {
                Some(n) => Dynamic::from(n),
                None => Dynamic::from(v),
            };
            m.insert(k.into(), value);
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
        let chosen = granite_core::io::vtk::VtkFormat::parse(format).or_rhai()?;
        s.lock().output.vtk_format = chosen;
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_get("time", |s: &mut Handle<S>| s.lock().sim.time());
    engine.register_get("step", |s: &mut Handle<S>| s.lock().sim.steps() as i64);
    engine.register_get("dt", |s: &mut Handle<S>| s.lock().sim.dt());
}
