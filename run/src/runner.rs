//! The run loop shared by every driver: steps an engine, writes series rows, VTK frames and
//! checkpoints on their intervals, keeps the last good state, and turns a failed step (NaN, a
//! blow-up, a lost point) into a stop that restores and writes that state.

use crate::output::Output;
use crate::simulation::{RunContext, RunEnd, Simulation};
use granite_core::error::{GraniteError, Result};
use indexmap::IndexMap;
use serde_json::Value;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Output intervals of a run with no end of its own, unless the driver set them.
pub const OPEN_RUN_SERIES_EVERY: u64 = 100;
pub const OPEN_RUN_VTK_EVERY: u64 = 2000;

/// Steps between series rows and between VTK frames during one run call.
#[derive(Debug, Clone, Copy)]
pub struct Cadence {
    pub series_every: u64,
    pub vtk_every: u64,
}

/// What a step left due.
#[derive(Debug, Default)]
pub struct StepDone {
    /// Messages of the engine for the user (deletions, mesh changes...).
    pub events: Vec<String>,
    /// A series row is due now (the last good state was kept with it).
    pub series_due: bool,
}

/// Chooses a simulation's output folder on its first write, from the folder it was given.
pub type FolderChoice = Box<dyn FnOnce(&Path) -> PathBuf + Send>;

/// A simulation with its outputs: what a driver steps.
pub struct Runner<S: Simulation> {
    pub sim: S,
    pub output: Output,
    pub run: RunContext,
    /// A checkpoint every n steps (and when a signal stops the run), into this file of the output
    /// folder.
    pub checkpoint: Option<(u64, String)>,
    /// Entries of summary.json ([`Runner::write_summary`]).
    pub summary: IndexMap<String, Value>,
    /// The step a failed step was at, until the driver takes it.
    pub failed_at_step: Option<u64>,
    last_good: Option<S::Snapshot>,
    folder_choice: Option<FolderChoice>,
    claimed: bool,
}

impl<S: Simulation> Runner<S> {
    /// A simulation writing into `out_dir` (made when first written to).
    pub fn new(sim: S, out_dir: impl Into<PathBuf>, run: RunContext) -> Runner<S> {
        let mut output = Output::new(out_dir.into());
        output.writes = run.writes_files();
        Runner {
            sim,
            output,
            run,
            checkpoint: None,
            summary: IndexMap::new(),
            failed_at_step: None,
            last_good: None,
            folder_choice: None,
            claimed: false,
        }
    }

    /// The output folder is chosen by `choice` when the simulation first writes (a simulation
    /// that only serves as a template, e.g. a loaded RVE, takes no folder).
    pub fn choose_folder_on_first_write(&mut self, choice: FolderChoice) {
        self.folder_choice = Some(choice);
    }

    /// Fixes the output folder on the first write. A simulation that has steps behind it then was
    /// loaded from a checkpoint, and continues the outputs of the run that wrote it.
    pub fn claim_output(&mut self) {
        if self.claimed {
            return;
        }
        if let Some(choice) = self.folder_choice.take() {
            self.output.dir = choice(&self.output.dir);
        }
        if self.sim.steps() > 0 {
            self.output.resumes_at = Some((self.sim.steps(), self.sim.time()));
        }
        self.claimed = true;
    }

    /// Whether this simulation has written anything (it then has outputs to close on a signal).
    pub fn has_written(&self) -> bool {
        self.claimed
    }

    /// Where a file of this simulation's output folder goes (its folder made if missing; a
    /// folder on the way that is a symbolic link is refused, naming it).
    pub fn output_path(&mut self, file: &str) -> Result<PathBuf> {
        self.claim_output();
        let path = self.output.dir.join(file);
        if let Some(dir) = path.parent() {
            granite_core::io::output_folder(&self.output.root, dir)
                .map_err(|e| GraniteError::Other(format!("cannot write {}: {e}", path.display())))?;
        }
        Ok(path)
    }

    /// A series row: the engine's columns, then `extra` (names and values).
    pub fn write_series_row(&mut self, extra_names: &[&str], extra: &[f64]) -> Result<()> {
        self.claim_output();
        let (mut names, mut values) = self.sim.series_row();
        names.extend_from_slice(extra_names);
        values.extend_from_slice(extra);
        let tag = self.sim.series_tag();
        let written = self.output.write_series(self.sim.steps(), &names, &values, tag);
        written.map_err(|e| self.output_failed(e))
    }

    pub fn write_vtk(&mut self) -> Result<()> {
        self.claim_output();
        let (x, fields) = self.sim.vtk_frame();
        let poly = self.sim.vtk_poly();
        let written = self.output.write_vtk(self.sim.steps(), self.sim.time(), &x, &fields, &poly);
        written.map_err(|e| self.output_failed(e))
    }

    /// An output that could not be written (a full disk, a lost folder): the run stops with the
    /// step it was at, the file and the cause; what was written before stays as it was.
    pub fn output_failed(&self, e: GraniteError) -> GraniteError {
        GraniteError::Other(format!(
            "at step {} (t = {:.6e} s) an output could not be written: {e}; the outputs written before are kept",
            self.sim.steps(),
            self.sim.time()
        ))
    }

    /// Writes the checkpoint asked for, if one was; its path.
    pub fn write_checkpoint(&mut self) -> Result<Option<PathBuf>> {
        let Some((_, file)) = self.checkpoint.clone() else { return Ok(None) };
        let path = self.output_path(&file).map_err(|e| self.output_failed(e))?;
        self.sim.save_state(&path, &self.run).map_err(|e| self.output_failed(e))?;
        Ok(Some(path))
    }

    /// A signal (named `signal`) asked the run to stop: the state after the last whole step is
    /// written (VTK frame, checkpoint); what to tell the user.
    pub fn stop_on_signal(&mut self, signal: &str) -> String {
        let (step, time) = (self.sim.steps(), self.sim.time());
        let mut msg =
            format!("stopped by {signal} at step {step} (t = {time:.6e} s); the outputs hold the state up to there");
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
        msg
    }

    /// A step failed: the last good state is restored and written out, and the error says so.
    pub fn fail(&mut self, e: GraniteError) -> GraniteError {
        let failed_step = self.sim.steps();
        let mut msg = e.to_string();
        if let Some(snap) = self.last_good.take() {
            self.sim.restore(snap);
            self.output.last_vtk_step = None;
            let writes = self.output.writes;
            let written = self.write_vtk().and_then(|()| self.output_path("last_good_points.csv")).and_then(|path| {
                if writes {
                    self.sim.write_points(&path)?;
                }
                Ok(path)
            });
            msg = match written {
                Ok(path) => format!(
                    "{msg}\nthe last good state (step {}, t = {:.6e} s) is kept and written to {} and vtk/",
                    self.sim.steps(),
                    self.sim.time(),
                    path.display()
                ),
                Err(w) => format!("{msg}\n(could not write the last good state: {w})"),
            };
        }
        self.failed_at_step = Some(failed_step);
        GraniteError::Other(msg)
    }

    /// The output intervals of a run call of `steps` steps (None: until stopped), unless set.
    /// They follow the run's length up to the call's end: a short first call (common in a REPL)
    /// must not fix every-step output for later long ones, and a loop over short calls must not
    /// write 20 frames and 500 rows per call; it gets about 20 frames and 500 rows each time its
    /// step count doubles.
    pub fn cadence(&self, steps: Option<u64>) -> Cadence {
        let (series_every, vtk_every) = match steps {
            Some(n) => {
                let end = self.sim.steps().saturating_add(n);
                ((end / 500).max(1), (end / 20).max(1))
            }
            None => (OPEN_RUN_SERIES_EVERY, OPEN_RUN_VTK_EVERY),
        };
        Cadence {
            series_every: self.output.series_every.unwrap_or(series_every),
            vtk_every: self.output.vtk_every.unwrap_or(vtk_every),
        }
    }

    /// Checks the set-up; what it should tell the user first.
    pub fn prepare(&mut self) -> Result<Vec<String>> {
        self.sim.validate()?;
        Ok(self.sim.setup_warnings())
    }

    /// The start of a run call of `cadence`: the first frame (unless written), and the state to
    /// fall back on. A simulation resumed from a checkpoint continues the frames of the run that
    /// wrote it: its first state gets a frame only where that run's frame interval put one, so
    /// that the resumed series is the one a run without a stop writes.
    pub fn open(&mut self, cadence: Cadence) -> Result<()> {
        if self.output.last_vtk_step.is_none() {
            self.claim_output();
            let step = self.sim.steps();
            let resumed_between_frames =
                self.output.resumes_at.is_some_and(|(at, _)| at == step) && !step.is_multiple_of(cadence.vtk_every);
            if resumed_between_frames {
                // No frame here: the earlier run's frames before this step stay as they are.
                self.output.last_vtk_step = Some(step);
            } else {
                self.write_vtk()?;
            }
        }
        self.keep_good();
        Ok(())
    }

    /// Keeps the present state to fall back on.
    pub fn keep_good(&mut self) {
        self.last_good = Some(self.sim.snapshot());
    }

    /// Step `k` (from 1) of a run call, `last` its last: the step, then the frame and checkpoint
    /// due. A failed step restores the last good state ([`Runner::fail`]).
    pub fn step(&mut self, cadence: Cadence, k: u64, last: bool) -> Result<StepDone> {
        if let Err(e) = self.sim.advance() {
            return Err(self.fail(e));
        }
        let events = self.sim.drain_events();
        let step = self.sim.steps();
        let series_due = step.is_multiple_of(cadence.series_every) || last;
        if series_due {
            self.keep_good();
        }
        // A call's last state is written when the call spans a frame interval (short calls in a
        // loop would otherwise flood vtk/).
        if step.is_multiple_of(cadence.vtk_every) || (last && k >= cadence.vtk_every) {
            self.write_vtk()?;
        }
        if self.checkpoint.as_ref().is_some_and(|(every, _)| step.is_multiple_of(*every)) {
            self.write_checkpoint()?;
        }
        Ok(StepDone { events, series_due })
    }

    /// The run call ended: the engine's report, its summary entries kept and its notes said
    /// (this process writing, not quiet).
    pub fn end(&mut self) -> Result<RunEnd> {
        let end = self.sim.run_ended()?;
        if self.run.writes_files() {
            if !self.run.quiet {
                for note in &end.notes {
                    granite_core::errln!("granite: {note}");
                }
            }
            self.summary.extend(end.summary.iter().cloned());
        }
        Ok(end)
    }

    /// Runs `steps` steps with the outputs on their intervals: what a Rust program calls.
    pub fn run_steps(&mut self, steps: u64) -> Result<()> {
        for warning in self.prepare()? {
            if !self.run.quiet {
                granite_core::errln!("granite: {warning}");
            }
        }
        let cadence = self.cadence(Some(steps));
        self.open(cadence)?;
        self.write_series_row(&[], &[])?;
        let progress = Progress::new(self.run.quiet, Some(steps), self.run.progress.clone());
        for k in 1..=steps {
            let done = match self.step(cadence, k, k == steps) {
                Ok(done) => done,
                Err(e) => {
                    progress.finish();
                    if let Some(step) = self.failed_at_step {
                        self.summary.insert("failed_at_step".into(), Value::from(step));
                    }
                    return Err(e);
                }
            };
            if !self.run.quiet {
                for event in done.events {
                    granite_core::errln!("granite: {event}");
                }
            }
            if done.series_due {
                self.write_series_row(&[], &[])?;
            }
            progress.tick(k, self.sim.time());
        }
        progress.finish();
        self.end().map(|_| ())
    }

    /// Runs until time `t_end` (within half a step).
    pub fn run_until(&mut self, t_end: f64) -> Result<()> {
        let remaining = t_end - self.sim.time();
        if remaining <= 0.0 {
            return Ok(());
        }
        self.run_steps((remaining / self.sim.dt() - 1e-9).ceil() as u64)
    }

    /// Writes `summary.json`: the entries kept so far, then the engine's measures now.
    pub fn write_summary(&mut self) -> Result<()> {
        if !self.output.writes {
            return Ok(());
        }
        let mut values = self.summary.clone();
        for (name, value) in self.sim.diagnostics() {
            values.entry(name.to_string()).or_insert(crate::simulation::diagnostic_json(name, value));
        }
        let path = self.output_path("summary.json")?;
        granite_core::io::write_summary(&path, &values)
    }
}

/// How far the runs of a script have got, for an observer on another thread (the Python
/// package's progress bar): the run calls started so far, the steps of the current one done and
/// asked (0: no end of its own), and its simulated time.
#[derive(Debug, Default)]
pub struct ProgressProbe {
    calls: AtomicU64,
    done: AtomicU64,
    total: AtomicU64,
    time: AtomicU64,
}

/// What a [`ProgressProbe`] says at one moment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProgressReading {
    pub calls: u64,
    pub done: u64,
    pub total: u64,
    pub time: f64,
}

impl ProgressProbe {
    pub fn read(&self) -> ProgressReading {
        ProgressReading {
            calls: self.calls.load(Ordering::Relaxed),
            done: self.done.load(Ordering::Relaxed),
            total: self.total.load(Ordering::Relaxed),
            time: f64::from_bits(self.time.load(Ordering::Relaxed)),
        }
    }

    fn start(&self, total: Option<u64>) {
        self.done.store(0, Ordering::Relaxed);
        self.total.store(total.unwrap_or(0), Ordering::Relaxed);
        self.calls.fetch_add(1, Ordering::Relaxed);
    }

    fn tick(&self, done: u64, time: f64) {
        self.done.store(done, Ordering::Relaxed);
        self.time.store(time.to_bits(), Ordering::Relaxed);
    }
}

/// Progress of a run on standard error: a bar on a terminal, a plain status line every 10 s
/// otherwise; and on a probe, if the run has one.
pub struct Progress {
    bar: Option<indicatif::ProgressBar>,
    /// Not on a terminal: when the last status line went out.
    plain: Option<std::cell::Cell<Instant>>,
    total: u64,
    start: Instant,
    probe: Option<Arc<ProgressProbe>>,
}

impl Progress {
    /// Nothing on standard error when `quiet` or the run has no end of its own.
    pub fn new(quiet: bool, total: Option<u64>, probe: Option<Arc<ProgressProbe>>) -> Progress {
        let now = Instant::now();
        if let Some(probe) = &probe {
            probe.start(total);
        }
        let mut progress = Progress { bar: None, plain: None, total: total.unwrap_or(0), start: now, probe };
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

    pub fn tick(&self, done: u64, time: f64) {
        if let Some(probe) = &self.probe {
            probe.tick(done, time);
        }
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

    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
