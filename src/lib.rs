//! The `granite` command: thin wiring between the command line, the engine and the built-in plugins.

pub mod batch;
pub mod bench;
pub mod repl;

use granite_core::script::{run_script, RunOptions, RunReport};
use granite_core::{Registry, Result};
use std::path::{Path, PathBuf};

/// The registry every run starts from: all built-in plugins.
pub fn registry() -> Registry {
    granite_plugins::default_registry()
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
    run_with_plugins(script, overrides, out_dir, quiet, threads, Vec::new())
}

/// [`run`], loading native law plugins first (`--plugin`).
pub fn run_with_plugins(
    script: &Path,
    overrides: Vec<(String, String)>,
    out_dir: Option<PathBuf>,
    quiet: bool,
    threads: Option<usize>,
    plugins: Vec<PathBuf>,
) -> Result<RunReport> {
    let out_dir = out_dir.unwrap_or_else(|| default_out_dir(script));
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        pool = pool.num_threads(n);
    }
    let pool = pool.build().map_err(|e| granite_core::GraniteError::Other(format!("thread pool: {e}")))?;
    let program = format!("granite {} ({})", env!("CARGO_PKG_VERSION"), env!("GRANITE_GIT_COMMIT"));
    pool.install(|| run_script(script, registry(), RunOptions { program, out_dir, overrides, quiet, plugins }))
}

/// Parses `NAME=VALUE`.
pub fn parse_override(s: &str) -> std::result::Result<(String, String), String> {
    match s.split_once('=') {
        Some((k, v)) if !k.trim().is_empty() => Ok((k.trim().to_string(), v.to_string())),
        _ => Err(format!("expected NAME=VALUE, got `{s}`")),
    }
}

/// Human-readable list of the registered plugins and their parameters.
pub fn plugin_listing() -> String {
    use std::fmt::Write;
    let reg = registry();
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
    out
}
