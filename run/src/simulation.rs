//! What an engine gives a run driver: a step, the rows and frames of its output contract, a state
//! to fall back on, and a checkpoint.

use granite_core::comm::Comm;
use granite_core::error::Result;
use granite_core::io::vtk::{Field, PolyData};
use granite_core::math::Vec3;
use std::path::Path;

/// Who runs a simulation and where its results go.
#[derive(Clone, Default)]
pub struct RunContext {
    /// The program and version recorded in checkpoints and provenance.
    pub program: String,
    /// The processes stepping this simulation together (an MPI run); None: this process alone.
    pub comm: Option<Comm>,
    /// No progress lines or reports on standard error.
    pub quiet: bool,
    /// Where the runs' progress is also told (an observer on another thread).
    pub progress: Option<std::sync::Arc<crate::runner::ProgressProbe>>,
}

impl RunContext {
    /// Whether this process writes the files (the first of an MPI run; the others step the same
    /// simulation and write nothing).
    pub fn writes_files(&self) -> bool {
        self.comm.as_ref().is_none_or(|c| c.rank() == 0)
    }
}

/// What a simulation reports when a run ends.
#[derive(Default)]
pub struct RunEnd {
    /// Entries for summary.json.
    pub summary: Vec<(String, serde_json::Value)>,
    /// Lines for the user (standard error unless quiet).
    pub notes: Vec<String>,
}

/// An engine as a run driver steps it: a Rhai script (granite-script) or a Rust program
/// ([`crate::Runner`]).
pub trait Simulation: Send + 'static {
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
    fn vtk_poly(&self) -> Vec<(&'static str, PolyData)> {
        Vec::new()
    }
    /// A CSV table of every point or particle.
    fn write_points(&self, path: &Path) -> Result<()>;
    /// Global measures by name.
    fn diagnostics(&self) -> Vec<(&'static str, f64)>;
    fn snapshot(&self) -> Self::Snapshot;
    fn restore(&mut self, snapshot: Self::Snapshot);
    /// Messages for the user since the last call (deletions, mesh changes...).
    fn drain_events(&mut self) -> Vec<String>;
    /// Sets the value of driven boundary condition `target` (a function of time evaluated by the
    /// driver once per step).
    fn set_driven(&mut self, target: usize, value: f64);
    /// What the set-up should tell the user before its first run (bodies overlapping deeply);
    /// called before every run, it says each thing once.
    fn setup_warnings(&mut self) -> Vec<String> {
        Vec::new()
    }
    /// Writes a checkpoint of the whole state that the engine's loader resumes from. Every
    /// process of an MPI run calls it; the first writes.
    fn save_state(&self, path: &Path, run: &RunContext) -> Result<()>;
    /// A run ended: what the engine reports of it (the processes' share of the work in a run over
    /// MPI). Every process calls it at the same point.
    fn run_ended(&mut self) -> Result<RunEnd> {
        Ok(RunEnd::default())
    }
}

/// Diagnostics that count things (steps, points, contacts...): whole numbers, which summary.json
/// and scripts get as integers rather than as `248.0`.
pub const COUNTS: &[&str] = &[
    "step",
    "points",
    "deleted_points",
    "contacts",
    "wall_contacts",
    "rattlers",
    "particles",
    "rve_active",
    "rve_sphere_steps",
];

/// A diagnostic as JSON: a count as an integer, anything else as the number it is.
pub fn diagnostic_json(name: &str, value: f64) -> serde_json::Value {
    match whole_count(name, value) {
        Some(n) => serde_json::Value::from(n),
        None => serde_json::Value::from(value),
    }
}

/// `value` as an integer when `name` is a count and the value is whole.
pub fn whole_count(name: &str, value: f64) -> Option<i64> {
    (COUNTS.contains(&name) && value.fract() == 0.0 && value.abs() < 9.0e15).then_some(value as i64)
}
