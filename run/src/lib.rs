//! granite-run: steps an engine of granite-core and writes its output contract into a folder:
//! `series.csv` rows, VTK frames (`vtk/*.pvd`), checkpoints and `summary.json`, keeping the last
//! good state to fall back on when a step fails. The Rhai layer (granite-script) drives its runs
//! through it; a Rust program can too, without Rhai:
//!
//! ```no_run
//! use granite_run::{MpmScene, RunContext, Runner};
//! # fn sim() -> granite_core::mpm::MpmSim { unimplemented!() }
//! let mut runner = Runner::new(MpmScene::new(sim()), "out/column", RunContext::default());
//! runner.checkpoint = Some((1000, "checkpoint.json".into()));
//! runner.run_steps(5000)?;
//! runner.write_summary()?;
//! # Ok::<(), granite_core::GraniteError>(())
//! ```

// As in granite-core: index loops read better than iterator chains where several arrays share
// the index.
#![allow(clippy::needless_range_loop)]

pub mod dem_scene;
pub mod mpm_scene;
pub mod output;
pub mod runner;
pub mod simulation;

pub use dem_scene::{DemScene, DemSnapshot, DEEP_OVERLAP};
pub use mpm_scene::{Driven, MpmScene, Runout};
pub use output::Output;
pub use runner::{Cadence, Progress, ProgressProbe, ProgressReading, Runner, StepDone};
pub use simulation::{RunContext, RunEnd, Simulation};
