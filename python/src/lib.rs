//! `granite._native`: the engine behind the `granite` Python package. It runs a script as
//! `granite run` does and hands back where its outputs went and its summary; the Python half
//! (python/granite/) reads those into numpy and pandas.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::atomic::{AtomicI32, Ordering};

create_exception!(
    _native,
    GraniteError,
    PyException,
    "A granite run failed: bad input, a script error, an unstable run."
);

/// Set by `request_stop` (the Python side's Ctrl-C): runs under way stop cleanly at their next
/// step, as `granite run` does on SIGINT.
static STOP: AtomicI32 = AtomicI32::new(0);

/// The signal number a run reports when stopped from Python (SIGINT).
const SIGINT: i32 = 2;

/// Runs `script` with `--set` overrides into `out` (None: out/<script stem>/) on `threads`
/// threads (None: every core), without holding the GIL. Returns the output folder and the
/// summary as JSON text.
#[pyfunction]
#[pyo3(signature = (script, overrides, out=None, threads=None, quiet=true))]
fn run(
    py: Python<'_>,
    script: PathBuf,
    overrides: Vec<(String, String)>,
    out: Option<PathBuf>,
    threads: Option<usize>,
    quiet: bool,
) -> PyResult<(String, String)> {
    STOP.store(0, Ordering::SeqCst);
    let request =
        granite::RunRequest { overrides, out_dir: out, quiet, threads, stop_signal: Some(&STOP), ..Default::default() };
    let report =
        py.detach(|| granite::run_request(&script, request)).map_err(|e| GraniteError::new_err(e.to_string()))?;
    let summary = serde_json::to_string(&report.summary).map_err(|e| GraniteError::new_err(e.to_string()))?;
    Ok((report.out_dir.to_string_lossy().into_owned(), summary))
}

/// Asks every run under way to stop cleanly at its next step (outputs and checkpoints written,
/// status `interrupted`).
#[pyfunction]
fn request_stop() {
    STOP.store(SIGINT, Ordering::SeqCst);
}

/// The parameters a script declares before its first simulation: (name, value as text, its
/// type, what its limits allow, the comment of its line), values from `overrides` checked as a
/// run checks them.
#[pyfunction]
#[pyo3(signature = (script, overrides=Vec::new()))]
fn params(
    script: PathBuf,
    overrides: Vec<(String, String)>,
) -> PyResult<Vec<(String, String, String, String, String)>> {
    let options = granite_script::RunOptions { overrides, quiet: true, ..Default::default() };
    let declared = granite_script::list_params(&script, granite::registry(), options)
        .map_err(|e| GraniteError::new_err(e.to_string()))?;
    Ok(declared
        .into_iter()
        .map(|d| (d.name, d.value.to_string(), d.value.type_name().to_string(), d.allowed, d.comment))
        .collect())
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(request_stop, m)?)?;
    m.add_function(wrap_pyfunction!(params, m)?)?;
    m.add("GraniteError", m.py().get_type::<GraniteError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
