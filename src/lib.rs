//! The `granite` command: thin wiring between the command line, the engine and the built-in plugins.

pub mod batch;
pub mod bench;
#[cfg(feature = "gpu")]
pub use granite_gpu as gpu;
#[cfg(feature = "mpi")]
pub mod mpi_comm;
pub mod repl;
pub mod shown;
pub mod signals;

use granite_core::{Registry, Result};
use granite_script::{run_script, RunOptions, RunReport};
use std::path::{Path, PathBuf};

/// The registry every run starts from: all built-in plugins (and, built with `--features gpu`,
/// the GPU as a device for the RVEs of `dem_rve`).
pub fn registry() -> Registry {
    #[allow(unused_mut)]
    let mut registry = granite_plugins::default_registry();
    #[cfg(feature = "gpu")]
    registry.add_rve_device(std::sync::Arc::new(gpu::GpuDevice::new()));
    registry
}

/// Default output folder of a script: `out/<script stem>/`.
pub fn default_out_dir(script: &Path) -> PathBuf {
    let stem = script.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_else(|| "run".into());
    PathBuf::from("out").join(stem)
}

/// Runs a script with `--set` overrides into `out_dir`, on `threads` worker threads (None: all
/// cores). The script itself runs on a worker of that pool, so the engine's parallel loops start
/// without handing work across threads.
pub fn run(
    script: &Path,
    overrides: Vec<(String, String)>,
    out_dir: Option<PathBuf>,
    quiet: bool,
    threads: Option<usize>,
) -> Result<RunReport> {
    run_request(script, RunRequest { overrides, out_dir, quiet, threads, ..Default::default() })
}

/// What `granite run` is given besides the script.
#[derive(Debug, Default)]
pub struct RunRequest {
    pub overrides: Vec<(String, String)>,
    /// Output folder (default: out/<script stem>/).
    pub out_dir: Option<PathBuf>,
    pub quiet: bool,
    /// Worker threads (default: all cores, or under an MPI launcher the cores over the processes).
    pub threads: Option<usize>,
    /// Native law plugins to load first (`--plugin`).
    pub plugins: Vec<PathBuf>,
    /// The processes of an MPI run this one belongs to: every process runs the script, the first
    /// one speaks and writes the files.
    pub comm: Option<granite_core::comm::Comm>,
    /// A flag a signal handler sets (see [`signals`]): the run stops cleanly at its next step.
    pub stop_signal: Option<&'static std::sync::atomic::AtomicI32>,
    /// Where the runs also tell their progress (an observer on another thread).
    pub progress: Option<std::sync::Arc<granite_run::ProgressProbe>>,
}

/// [`run`] with everything `granite run` takes.
pub fn run_request(script: &Path, request: RunRequest) -> Result<RunReport> {
    let RunRequest { overrides, out_dir, quiet, threads, plugins, comm, stop_signal, progress } = request;
    let out_dir = out_dir.unwrap_or_else(|| default_out_dir(script));
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads.or_else(threads_per_process) {
        pool = pool.num_threads(n);
    }
    let pool = pool.build().map_err(|e| granite_core::GraniteError::Other(format!("thread pool: {e}")))?;
    let program = format!("granite {} ({})", env!("CARGO_PKG_VERSION"), env!("GRANITE_GIT_COMMIT"));
    let quiet = quiet || comm.as_ref().is_some_and(|c| c.rank() > 0);
    let options =
        RunOptions { program, out_dir, overrides, quiet, plugins, comm, stop_signal, progress, ..Default::default() };
    pool.install(|| run_script(script, registry(), options))
}

/// The end of one process of an MPI run. Processes that fail together (an RVE failing in one
/// fails the step in all) meet and stop; a process that failed alone (a file only it could not
/// read) would leave the others waiting in their next step forever, so after a grace period it
/// says why and stops the whole run.
pub fn end_among(comm: &granite_core::comm::Comm, error: Option<&granite_core::GraniteError>) {
    let grace = match error {
        None => std::time::Duration::from_secs(u64::MAX / 4),
        Some(_) => std::time::Duration::from_secs(END_GRACE_S),
    };
    if !comm.meet(grace) {
        let why = error.map(|e| e.to_string()).unwrap_or_default();
        granite_core::errln!(
            "granite: error on rank {} of {}: {why}\ngranite: the other processes did not stop with it within {END_GRACE_S} s: aborting the run",
            comm.rank(),
            comm.size()
        );
        comm.abort(1);
    }
}

/// Whether an MPI launcher started this process (Open MPI, MPICH, Intel MPI or Slurm's srun).
pub fn launched_by_mpirun() -> bool {
    ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK", "MPI_LOCALNRANKS"].iter().any(|v| std::env::var_os(v).is_some())
}

/// How many processes the launcher started, where it says (Open MPI; MPICH and srun with PMI).
pub fn launched_processes() -> Option<usize> {
    ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE"].iter().find_map(|v| std::env::var(v).ok()?.trim().parse().ok())
}

/// Seconds a failed process waits for the others to stop too before aborting the run.
pub const END_GRACE_S: u64 = 60;

/// Threads per process when several processes share a machine (`mpirun -np 2` on one node):
/// the cores divided among them, from the launcher's count of local processes (Open MPI's
/// `OMPI_COMM_WORLD_LOCAL_SIZE`, MPICH's `MPI_LOCALNRANKS`). None outside a launcher.
pub fn threads_per_process() -> Option<usize> {
    let local: usize = ["OMPI_COMM_WORLD_LOCAL_SIZE", "MPI_LOCALNRANKS"]
        .iter()
        .find_map(|v| std::env::var(v).ok()?.trim().parse().ok())?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    Some((cores / local.max(1)).max(1))
}

/// `granite run SCRIPT --list-params`: the parameters the script declares before its first
/// simulation, one line each: name, value (and default when `--set` changed it), what its
/// limits allow, and the comment of its line. Values given with `--set` are checked as a run
/// checks them.
pub fn describe_params(script: &Path, overrides: Vec<(String, String)>, plugins: Vec<PathBuf>) -> Result<String> {
    let options = RunOptions { overrides: overrides.clone(), plugins, quiet: true, ..Default::default() };
    let declared = granite_script::list_params(script, registry(), options)?;
    let shown = |d: &granite_script::Declared| {
        let (value, default) = (d.value.to_string(), d.default.to_string());
        if value == default {
            value
        } else {
            format!("{value} (default {default})")
        }
    };
    let rows: Vec<[String; 4]> =
        declared.iter().map(|d| [d.name.clone(), shown(d), d.allowed.clone(), d.comment.clone()]).collect();
    let width = |c: usize| rows.iter().map(|r| r[c].chars().count()).max().unwrap_or(0);
    let (w0, w1, w2) = (width(0), width(1), width(2));
    let mut out = format!(
        "{}: {} parameter(s) declared before the first simulation; change one with --set NAME=VALUE\n",
        script.display(),
        rows.len()
    );
    for [name, value, allowed, comment] in &rows {
        let line = format!("  {name:<w0$}  {value:<w1$}  {allowed:<w2$}  {comment}");
        out.push_str(line.trim_end());
        out.push('\n');
    }
    for (name, _) in overrides.iter().filter(|(k, _)| !declared.iter().any(|d| &d.name == k)) {
        out.push_str(&format!(
            "--set {name}: not among these (a run refuses it unless the script declares it later)\n"
        ));
    }
    Ok(out)
}

/// Parses `NAME=VALUE`.
pub fn parse_override(s: &str) -> std::result::Result<(String, String), String> {
    match s.split_once('=') {
        Some((k, v)) if !k.trim().is_empty() => Ok((k.trim().to_string(), v.to_string())),
        _ => Err(format!("expected NAME=VALUE, got `{s}`")),
    }
}

/// The most worker threads the command line takes: far beyond any core count, low enough that a
/// typo (`--threads 100000`) is an error rather than minutes of thread creation.
pub const MAX_THREADS: usize = 1024;

/// A whole number of at least `MIN` (step, point and particle counts, repeats).
pub fn parse_at_least<const MIN: usize>(s: &str) -> std::result::Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n) if n >= MIN => Ok(n),
        _ => Err(format!("expected a whole number >= {MIN}, got `{s}`")),
    }
}

/// A thread count, 1 to [`MAX_THREADS`].
pub fn parse_threads(s: &str) -> std::result::Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n) if (1..=MAX_THREADS).contains(&n) => Ok(n),
        _ => Err(format!("expected a thread count from 1 to {MAX_THREADS}, got `{s}`")),
    }
}

/// A duration in seconds: a number > 0.
pub fn parse_seconds(s: &str) -> std::result::Result<std::time::Duration, String> {
    match s.trim().parse::<f64>() {
        Ok(x) if x > 0.0 && x.is_finite() && x < 1e9 => Ok(std::time::Duration::from_secs_f64(x)),
        _ => Err(format!("expected a number of seconds > 0, got `{s}`")),
    }
}

/// A strain: a number in (0, 1).
pub fn parse_strain(s: &str) -> std::result::Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(x) if x > 0.0 && x < 1.0 => Ok(x),
        _ => Err(format!("expected a strain in (0, 1), got `{s}`")),
    }
}

/// Human-readable list of the registered plugins and their parameters, with the laws of the
/// native plugin libraries `libraries` loaded first.
pub fn plugin_listing(libraries: &[PathBuf]) -> Result<String> {
    use std::fmt::Write;
    let mut reg = registry();
    for lib in libraries {
        granite_loader::load_plugin(lib, &mut reg, false)?;
    }
    let mut out = String::from("constitutive laws (sim.material(NAME, #{ density: ..., PARAMS })):\n");
    for name in reg.law_names() {
        if let Ok(f) = reg.law_factory(&name) {
            let _ = writeln!(out, "  {name}: {}", f.description());
            for s in f.param_specs() {
                let default = match s.default {
                    None => "required".to_string(),
                    Some(d) if d.is_nan() => "optional".to_string(),
                    Some(d) => format!("default {d}"),
                };
                let _ = writeln!(out, "      {:<20} {} ({default})", s.name, s.doc);
            }
        }
    }
    let specs = |out: &mut String, list: &[granite_core::params::ParamSpec]| {
        for s in list {
            let default = match s.default {
                None => "required".to_string(),
                Some(d) if d.is_nan() => "optional".to_string(),
                Some(d) => format!("default {d}"),
            };
            let _ = writeln!(out, "      {:<20} {} ({default})", s.name, s.doc);
        }
    };
    out.push_str("contact laws (sim.contact_law(NAME, #{ PARAMS }) in dem()):\n");
    for name in reg.contact_law_names() {
        if let Ok(f) = reg.contact_law_factory(&name) {
            let _ = writeln!(out, "  {name}: {}", f.description());
            specs(&mut out, f.param_specs());
        }
    }
    out.push_str("grain shapes (sim.clump_cloud(m, lo, hi, #{ shape: NAME, PARAMS })):\n");
    for name in reg.shape_names() {
        if let Ok(f) = reg.shape_factory(&name) {
            let _ = writeln!(out, "  {name}: {}", f.description());
            specs(&mut out, f.param_specs());
        }
    }
    out.push_str(
        "body kinds (sim.add_body(NAME, m, centre, #{ PARAMS }), sim.clump_cloud(m, lo, hi, #{ shape: NAME, PARAMS })):\n",
    );
    for name in reg.body_kind_names() {
        if let Ok(f) = reg.body_kind(&name) {
            let _ = writeln!(out, "  {name}: {}", f.description());
            specs(&mut out, f.param_specs());
        }
    }
    out.push_str("contacts between body families (bodies of both kinds in one simulation meet):\n");
    for g in reg.body_pair_geometries() {
        let [a, b] = g.families();
        let _ = writeln!(out, "  {}: {a} with {b}: {}", g.name(), g.description());
    }
    out.push_str("velocity updates (sim.velocity_update(NAME, #{ PARAMS })):\n");
    for name in reg.velocity_update_names() {
        if let Ok(f) = reg.velocity_update_factory(&name) {
            let params: Vec<String> =
                f.param_specs().iter().map(|s| format!("{} = {}", s.name, s.default.unwrap_or(f64::NAN))).collect();
            let _ = writeln!(
                out,
                "  {name:<7} {}{}",
                f.description(),
                if params.is_empty() { String::new() } else { format!(" [{}]", params.join(", ")) }
            );
        }
    }
    Ok(out)
}
