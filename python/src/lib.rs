//! `granite._native`: the engine behind the `granite` Python package. It runs a script as
//! `granite run` does and hands back where its outputs went and its summary; the Python half
//! (python/granite/) reads those into numpy and pandas.

use granite_script::repl::ReplSession;
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use rhai::{Array, Dynamic, Map};
use std::path::PathBuf;
use std::sync::atomic::{AtomicI32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

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

/// Where runs tell how far they have got, read from Python while they go on.
#[pyclass(frozen)]
#[derive(Default)]
struct Progress(Arc<granite_run::ProgressProbe>);

#[pymethods]
impl Progress {
    #[new]
    fn new() -> Progress {
        Progress::default()
    }

    /// (run calls started, steps of the current one done, asked (0: no end of its own), its
    /// simulated time).
    fn read(&self) -> (u64, u64, u64, f64) {
        let r = self.0.read();
        (r.calls, r.done, r.total, r.time)
    }
}

/// Runs `script` with `--set` overrides into `out` (None: out/<script stem>/) on `threads`
/// threads (None: every core), without holding the GIL. Returns the output folder and the
/// summary as JSON text.
#[pyfunction]
#[pyo3(signature = (script, overrides, out=None, threads=None, quiet=true, progress=None))]
fn run(
    py: Python<'_>,
    script: PathBuf,
    overrides: Vec<(String, String)>,
    out: Option<PathBuf>,
    threads: Option<usize>,
    quiet: bool,
    progress: Option<PyRef<'_, Progress>>,
) -> PyResult<(String, String)> {
    STOP.store(0, Ordering::SeqCst);
    let request = granite::RunRequest {
        overrides,
        out_dir: out,
        quiet,
        threads,
        stop_signal: Some(&STOP),
        progress: progress.map(|p| p.0.clone()),
        ..Default::default()
    };
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

/// A declared parameter: name, value as text, its type, what its limits allow, the comment of
/// its line.
type Declaration = (String, String, String, String, String);

/// The parameters a script declares before its first simulation, values from `overrides`
/// checked as a run checks them.
#[pyfunction]
#[pyo3(signature = (script, overrides=Vec::new()))]
fn params(script: PathBuf, overrides: Vec<(String, String)>) -> PyResult<Vec<Declaration>> {
    let options = granite_script::RunOptions { overrides, quiet: true, ..Default::default() };
    let declared = granite_script::list_params(&script, granite::registry(), options)
        .map_err(|e| GraniteError::new_err(e.to_string()))?;
    Ok(declared
        .into_iter()
        .map(|d| (d.name, d.value.to_string(), d.value.type_name().to_string(), d.allowed, d.comment))
        .collect())
}

/// A value of a session that Python holds by name: a simulation, a material, a wall... kept in
/// the session as the variable `variable` and handed back to calls by it.
#[pyclass(frozen)]
struct Stored {
    #[pyo3(get)]
    variable: String,
    #[pyo3(get)]
    kind: String,
}

/// The live scene of `granite.load`: a script's variables and simulations kept between calls, as in
/// `granite repl`.
#[pyclass(frozen)]
struct Session {
    inner: Mutex<ReplSession>,
    /// Pauses the session's runs at their next step (Ctrl-C), without its lock.
    pause: Box<dyn Fn() + Send + Sync>,
    pool: rayon::ThreadPool,
    /// Numbers the values stored for Python.
    stored: AtomicU64,
}

#[pymethods]
impl Session {
    #[new]
    #[pyo3(signature = (overrides, out, threads=None, quiet=true, progress=None, script_dir=None))]
    fn new(
        overrides: Vec<(String, String)>,
        out: PathBuf,
        threads: Option<usize>,
        quiet: bool,
        progress: Option<PyRef<'_, Progress>>,
        script_dir: Option<PathBuf>,
    ) -> PyResult<Session> {
        let options = granite_script::RunOptions {
            program: format!("granite {} (Python)", env!("CARGO_PKG_VERSION")),
            out_dir: out,
            overrides,
            quiet,
            stop_signal: Some(&STOP),
            progress: progress.map(|p| p.0.clone()),
            script_dir,
            ..Default::default()
        };
        let session =
            ReplSession::new(granite::registry(), options).map_err(|e| GraniteError::new_err(e.to_string()))?;
        let pause = session.pause_handle();
        let mut pool = rayon::ThreadPoolBuilder::new();
        if let Some(n) = threads {
            pool = pool.num_threads(n);
        }
        let pool = pool.build().map_err(|e| GraniteError::new_err(format!("thread pool: {e}")))?;
        Ok(Session { inner: Mutex::new(session), pause: Box::new(pause), pool, stored: AtomicU64::new(0) })
    }

    /// Evaluates script code in the session without holding the GIL; returns its value (plain
    /// values converted, others stored and returned as `Stored`).
    fn eval(&self, py: Python<'_>, code: &str) -> PyResult<Py<PyAny>> {
        STOP.store(0, Ordering::SeqCst);
        let value = py.detach(|| self.pool.install(|| self.lock().eval_value(code))).map_err(GraniteError::new_err)?;
        self.to_python(py, value)
    }

    /// Sets a variable of the session to a Python value.
    fn set(&self, name: &str, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let dynamic = self.to_dynamic(value)?;
        self.with_session(value.py(), |s| s.set_variable(name, dynamic));
        Ok(())
    }

    /// One array of the simulation held in `variable`: its values as bytes (f64, native order)
    /// and its number of columns.
    fn array(&self, py: Python<'_>, variable: &str, name: &str) -> PyResult<(Py<PyBytes>, usize)> {
        let sim = self.variable(py, variable)?;
        let table = py
            .detach(|| granite_script::arrays::array(&sim, name))
            .map_err(|e| GraniteError::new_err(e.to_string()))?;
        let bytes: Vec<u8> = table.values.iter().flat_map(|v| v.to_ne_bytes()).collect();
        Ok((PyBytes::new(py, &bytes).unbind(), table.columns))
    }

    /// Sets one array of the simulation held in `variable` from f64 values (native order) in rows
    /// of `columns`, with the checks of the script calls that change them.
    fn set_array(&self, py: Python<'_>, variable: &str, name: &str, values: &[u8], columns: usize) -> PyResult<()> {
        let sim = self.variable(py, variable)?;
        let values = values.chunks_exact(8).map(|b| f64::from_ne_bytes(b.try_into().unwrap_or([0; 8]))).collect();
        let table = granite_script::arrays::Table { values, columns };
        py.detach(|| granite_script::arrays::set_array(&sim, name, &table))
            .map_err(|e| GraniteError::new_err(e.to_string()))
    }

    /// The arrays the value in `variable` offers (None: not a simulation).
    fn array_names(&self, py: Python<'_>, variable: &str) -> PyResult<Option<Vec<String>>> {
        let sim = self.variable(py, variable)?;
        Ok(py.detach(|| granite_script::arrays::names(&sim)))
    }

    /// The session's variables and their types.
    fn variables(&self, py: Python<'_>) -> Vec<(String, String)> {
        self.with_session(py, |s| s.variables())
    }

    /// Refuses parameters given that no `param(...)` declared.
    fn check_overrides(&self, py: Python<'_>) -> PyResult<()> {
        self.with_session(py, |s| s.check_overrides()).map_err(GraniteError::new_err)
    }

    /// Pauses every run of the session at its next step and stops the code being evaluated
    /// (Ctrl-C); the state is kept.
    fn interrupt(&self) {
        (self.pause)();
    }

    /// Pauses the runs still going in the background and waits for them.
    fn finish(&self, py: Python<'_>) {
        self.with_session(py, |s| s.finish());
    }
}

impl Session {
    fn lock(&self) -> std::sync::MutexGuard<'_, ReplSession> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// `f` on the session, waiting for it (another thread's input may hold it for a whole run)
    /// without the GIL, which that input needs to end.
    fn with_session<R: Send>(&self, py: Python<'_>, f: impl FnOnce(&mut ReplSession) -> R + Send) -> R {
        py.detach(|| f(&mut self.lock()))
    }

    fn variable(&self, py: Python<'_>, name: &str) -> PyResult<Dynamic> {
        self.with_session(py, |s| s.variable(name))
            .ok_or_else(|| GraniteError::new_err(format!("the session has no variable `{name}`")))
    }

    fn to_python(&self, py: Python<'_>, value: Dynamic) -> PyResult<Py<PyAny>> {
        if value.is_unit() {
            return Ok(py.None());
        }
        if let Some(b) = value.clone().try_cast::<bool>() {
            return Ok(PyBool::new(py, b).to_owned().into_any().unbind());
        }
        if let Some(i) = value.clone().try_cast::<rhai::INT>() {
            return Ok(i.into_pyobject(py)?.into_any().unbind());
        }
        if let Some(f) = value.clone().try_cast::<rhai::FLOAT>() {
            return Ok(PyFloat::new(py, f).into_any().unbind());
        }
        if value.is_string() {
            return Ok(PyString::new(py, &value.to_string()).into_any().unbind());
        }
        if value.is_array() {
            let items =
                value.cast::<Array>().into_iter().map(|v| self.to_python(py, v)).collect::<PyResult<Vec<_>>>()?;
            return Ok(PyList::new(py, items)?.into_any().unbind());
        }
        if value.is_map() {
            let dict = PyDict::new(py);
            for (k, v) in value.cast::<Map>() {
                dict.set_item(k.as_str(), self.to_python(py, v)?)?;
            }
            return Ok(dict.into_any().unbind());
        }
        let variable = format!("__python_{}", self.stored.fetch_add(1, Ordering::SeqCst));
        let kind = self.with_session(py, |s| {
            let kind = s.type_name(&value);
            s.set_variable(&variable, value);
            kind
        });
        Ok(Py::new(py, Stored { variable, kind })?.into_any())
    }

    fn to_dynamic(&self, value: &Bound<'_, PyAny>) -> PyResult<Dynamic> {
        if value.is_none() {
            return Ok(Dynamic::UNIT);
        }
        if let Ok(stored) = value.extract::<PyRef<'_, Stored>>() {
            return self.variable(value.py(), &stored.variable);
        }
        if value.is_instance_of::<PyBool>() {
            return Ok(Dynamic::from(value.extract::<bool>()?));
        }
        if value.is_instance_of::<PyInt>() {
            return Ok(Dynamic::from(value.extract::<rhai::INT>()?));
        }
        if value.is_instance_of::<PyFloat>() {
            return Ok(Dynamic::from(value.extract::<rhai::FLOAT>()?));
        }
        if value.is_instance_of::<PyString>() {
            return Ok(Dynamic::from(value.extract::<String>()?));
        }
        if let Ok(dict) = value.cast::<PyDict>() {
            let mut map = Map::new();
            for (k, v) in dict.iter() {
                map.insert(k.str()?.to_string().into(), self.to_dynamic(&v)?);
            }
            return Ok(Dynamic::from_map(map));
        }
        if value.is_instance_of::<PyList>() || value.is_instance_of::<PyTuple>() {
            let items = value.try_iter()?.map(|v| self.to_dynamic(&v?)).collect::<PyResult<Array>>()?;
            return Ok(Dynamic::from_array(items));
        }
        // numpy arrays and scalars: as their lists and Python numbers.
        if value.hasattr("tolist")? {
            return self.to_dynamic(&value.call_method0("tolist")?);
        }
        Err(GraniteError::new_err(format!(
            "a {} cannot go into a script: numbers, booleans, strings, lists, dicts, numpy arrays and values of the session can",
            value.get_type().name()?
        )))
    }
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_class::<Session>()?;
    m.add_class::<Progress>()?;
    m.add_class::<Stored>()?;
    m.add_function(wrap_pyfunction!(request_stop, m)?)?;
    m.add_function(wrap_pyfunction!(params, m)?)?;
    m.add("GraniteError", m.py().get_type::<GraniteError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
