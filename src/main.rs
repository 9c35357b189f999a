use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

/// granite: multi-scale simulation of granular materials (MPM, DEM, MPMxDEM) driven by Rhai scripts.
#[derive(Parser)]
#[command(name = "granite", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a simulation script.
    Run {
        /// The Rhai script.
        script: PathBuf,
        /// Override a script parameter declared with param("NAME", default).
        #[arg(long = "set", value_name = "NAME=VALUE", value_parser = granite::parse_override)]
        set: Vec<(String, String)>,
        /// Output folder (default: out/<script stem>/).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Worker threads (default: all cores).
        #[arg(long, value_parser = granite::parse_threads)]
        threads: Option<usize>,
        /// No progress lines.
        #[arg(long)]
        quiet: bool,
        /// Load a native constitutive-law plugin (a granite-plugin-abi cdylib) first; repeatable.
        #[arg(long = "plugin", value_name = "LIBRARY")]
        plugins: Vec<PathBuf>,
        /// List the script's parameters (value, limits, comment) instead of running it.
        #[arg(long)]
        list_params: bool,
        /// Under mpirun: end the run on every process when one waits this many seconds for the
        /// others (one of them frozen or lost), with status failed.
        #[arg(long, value_name = "SECONDS", value_parser = granite::parse_seconds)]
        mpi_timeout: Option<std::time::Duration>,
    },
    /// Interactive session: the script API one input at a time; Ctrl-C pauses a run.
    Repl {
        /// A script to run first (its variables stay available).
        script: Option<PathBuf>,
        /// Output folder (default: out/repl/).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Override a parameter declared with param("NAME", default) in the script.
        #[arg(long = "set", value_name = "NAME=VALUE", value_parser = granite::parse_override)]
        set: Vec<(String, String)>,
        /// Load a native constitutive-law plugin first; repeatable.
        #[arg(long = "plugin", value_name = "LIBRARY")]
        plugins: Vec<PathBuf>,
        /// No progress lines.
        #[arg(long)]
        quiet: bool,
    },
    /// Print performance figures.
    Bench {
        /// Which benchmark: mpm, dem, mpmxdem, triaxial, potential; or adapter (the GPU's limits).
        which: String,
        /// Material points in the 3D block (about).
        #[arg(long, default_value_t = 100_000, value_parser = granite::parse_at_least::<10>)]
        points: usize,
        /// Steps to time.
        #[arg(long, default_value_t = 50, value_parser = granite::parse_at_least::<1>)]
        steps: usize,
        /// DEM: particle counts, comma separated (dem: 10000,50000; potential: 512 grains).
        #[arg(long, value_delimiter = ',', value_parser = granite::parse_at_least::<1>)]
        particles: Option<Vec<usize>>,
        /// dem, potential: timed steps (after 200 of warm-up; 2000). mpmxdem --device: DEM steps
        /// per call, comma separated, one measurement each (51).
        #[arg(long, value_delimiter = ',', value_parser = granite::parse_at_least::<1>)]
        dem_steps: Vec<usize>,
        /// Thread counts to measure, comma separated.
        #[arg(long, default_value = "1,2", value_delimiter = ',', value_parser = granite::parse_threads)]
        threads: Vec<usize>,
        /// triaxial: axial strain to reach.
        #[arg(long, default_value_t = 0.1, value_parser = granite::parse_strain)]
        axial_strain: f64,
        /// dem, mpmxdem: runs of each measurement; the fastest is reported (a shared machine's
        /// slow spells only ever slow a run down).
        #[arg(long, default_value_t = 3, value_parser = granite::parse_at_least::<1>)]
        repeat: usize,
        /// mpmxdem: where the RVEs run, "cpu" or "gpu" (against all CPU threads on the same RVEs).
        #[arg(long, default_value = "cpu")]
        device: String,
        /// mpmxdem --device gpu: "oedometric" (16 x 125-sphere RVEs) or "column" (the thesis
        /// column's 400 x 2000-sphere RVEs).
        #[arg(long, default_value = "oedometric")]
        scene: String,
        /// mpmxdem --device: RVEs in the batch (the scene's count by default).
        #[arg(long, value_parser = granite::parse_at_least::<1>)]
        copies: Option<usize>,
        /// mpmxdem --device: RVEs that differ (each sheared at its own rate after its own number
        /// of steps), so that their candidate searches fall at different steps.
        #[arg(long)]
        perturb: bool,
        /// mpmxdem --device: rebuild the candidate lists before every DEM step (device and CPU).
        #[arg(long)]
        force_rebuild: bool,
        /// mpmxdem --device gpu: invocations per workgroup (64 to 1024; chosen from the RVEs' size
        /// by default).
        #[arg(long)]
        workgroup: Option<u32>,
        /// mpmxdem --device: write the figures to this JSON file (one object per DEM-steps value;
        /// a list when there are several).
        #[arg(long, value_name = "FILE")]
        json: Option<PathBuf>,
        /// mpmxdem --device: append one markdown table row per measurement to this file.
        #[arg(long, value_name = "FILE")]
        table: Option<PathBuf>,
    },
    /// List the registered plugins (constitutive laws, contact laws, shapes, velocity updates)
    /// and their parameters, with the laws of native plugin libraries given with --plugin.
    Plugins {
        /// A native constitutive-law plugin (a granite-plugin-abi cdylib) to list; repeatable.
        #[arg(long = "plugin", value_name = "LIBRARY")]
        plugins: Vec<PathBuf>,
    },
    /// Print the script API reference (Markdown; docs/api.md is this output), or one call's help.
    Api {
        /// A function or property name (`sphere`, `DemSim.sphere`): its help only.
        name: Option<String>,
    },
    /// Run a script over many parameter sets (a TOML file of [grid] lists and/or [[set]] tables).
    Batch {
        script: PathBuf,
        /// The parameter file.
        #[arg(long)]
        params: PathBuf,
        /// Runs at a time.
        #[arg(long, default_value_t = 1, value_parser = granite::parse_at_least::<1>)]
        jobs: usize,
        /// Output folder (default: out/<script stem>_batch/).
        #[arg(long)]
        out: Option<PathBuf>,
        #[arg(long)]
        quiet: bool,
        /// Stop a run still going after this many seconds (SIGTERM: it writes its outputs and
        /// checkpoint), reported `timed out`.
        #[arg(long, value_name = "SECONDS", value_parser = granite::parse_seconds)]
        run_timeout: Option<std::time::Duration>,
    },
    /// Plot series.csv columns against another column, as SVG or PNG (by the output file's extension; text drawn with a built-in font).
    Plot {
        /// The CSV file (e.g. out/column_collapse/series.csv).
        csv: PathBuf,
        /// Column on the horizontal axis.
        #[arg(long, default_value = "time")]
        x: String,
        /// Columns to plot, comma separated.
        #[arg(long, value_delimiter = ',', required = true)]
        y: Vec<String>,
        /// Output file, .svg or .png (default: plot_<columns>.svg next to the CSV).
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

/// Counts the bytes the process holds, so that a script's own data is stopped with an error before
/// it takes all the memory (see `granite_core::memory::CountingAllocator`).
#[global_allocator]
static ALLOCATOR: granite_core::memory::CountingAllocator = granite_core::memory::CountingAllocator;

fn main() -> ExitCode {
    granite_core::memory::CountingAllocator::installed();
    let cli = Cli::parse();
    match cli.command {
        Command::Run { script, set, list_params: true, plugins, .. } => {
            match granite::describe_params(&script, set, plugins) {
                Ok(table) => {
                    granite_core::out!("{table}");
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    granite_core::errln!("granite: error: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        Command::Run { script, set, out, threads, quiet, plugins, mpi_timeout, .. } => {
            // MPI starts only under a launcher: a plain `granite run` of an MPI build is a plain run.
            #[cfg(feature = "mpi")]
            let mpi = || {
                let timeout =
                    mpi_timeout.unwrap_or(std::time::Duration::from_secs_f64(granite::mpi_comm::DEFAULT_TIMEOUT_S));
                let out_dir = out.clone().unwrap_or_else(|| granite::default_out_dir(&script));
                granite::mpi_comm::start(timeout, Some(&out_dir))
            };
            #[cfg(not(feature = "mpi"))]
            let _ = mpi_timeout;
            #[cfg(feature = "mpi")]
            let (_universe, comm) = match granite::launched_by_mpirun().then(mpi).transpose() {
                Ok(Some((universe, comm))) => (Some(universe), (comm.size() > 1).then_some(comm)),
                Ok(None) => (None, None),
                Err(e) => {
                    granite_core::errln!("granite: error: MPI: {e}");
                    return ExitCode::FAILURE;
                }
            };
            #[cfg(not(feature = "mpi"))]
            let comm = None;
            #[cfg(not(feature = "mpi"))]
            if let Some(n) = granite::launched_processes().filter(|&n| n > 1) {
                granite_core::errln!(
                    "granite: error: started as one of {n} MPI processes, but this granite was built without MPI: \
                     each process would run the whole simulation and write the same files. Build it with \
                     `cargo build --release --features mpi` (see README, Over MPI)"
                );
                return ExitCode::FAILURE;
            }
            let first = comm.as_ref().is_none_or(|c: &granite_core::comm::Comm| c.rank() == 0);
            // Alone, a signal stops the run cleanly; the processes of an MPI run would stop at
            // different steps and wait for each other, so there the launcher's signal ends them.
            let stop_signal = match &comm {
                Some(_) => None,
                None => match granite::signals::install() {
                    Ok(flag) => Some(flag),
                    Err(e) => {
                        granite_core::errln!("granite: error: {e}");
                        return ExitCode::FAILURE;
                    }
                },
            };
            let request = granite::RunRequest {
                overrides: set,
                out_dir: out,
                quiet,
                threads,
                plugins,
                comm: comm.clone(),
                stop_signal,
                progress: None,
            };
            let result = granite::run_request(&script, request);
            if let (Some(signal), Err(e)) = (granite::signals::received(), &result) {
                granite_core::errln!("granite: {e}");
                return ExitCode::from((128 + signal).clamp(0, 255) as u8);
            }
            let code = match &result {
                Ok(report) => {
                    if !quiet && first {
                        granite_core::outln!("granite: done; outputs in {}", report.out_dir.display());
                        for (k, v) in &report.summary {
                            granite_core::outln!("  {k} = {}", granite::shown::shown(v));
                        }
                    }
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    if first {
                        granite_core::errln!("granite: error: {e}");
                    }
                    ExitCode::FAILURE
                }
            };
            if let Some(comm) = &comm {
                granite::end_among(comm, result.as_ref().err());
            }
            code
        }
        Command::Bench {
            which,
            points,
            steps,
            particles,
            dem_steps,
            threads,
            axial_strain,
            repeat,
            device,
            scene,
            copies,
            perturb,
            force_rebuild,
            workgroup,
            json,
            table,
        } => {
            let timed_steps = dem_steps.first().copied().unwrap_or(2000);
            #[cfg(feature = "mpi")]
            if which == "mpmxdem" && granite::launched_by_mpirun() {
                let timeout = std::time::Duration::from_secs_f64(granite::mpi_comm::DEFAULT_TIMEOUT_S);
                let (_universe, comm) = match granite::mpi_comm::start(timeout, None) {
                    Ok(started) => started,
                    Err(e) => {
                        granite_core::errln!("granite: error: MPI: {e}");
                        return ExitCode::FAILURE;
                    }
                };
                return match granite::bench::mpmxdem_mpi(comm, repeat) {
                    Ok(()) => ExitCode::SUCCESS,
                    Err(e) => {
                        granite_core::errln!("granite: bench failed: {e}");
                        ExitCode::FAILURE
                    }
                };
            }
            let result = match which.as_str() {
                "mpm" => granite::bench::mpm(points, steps, &threads),
                "dem" => granite::bench::dem(
                    &particles.unwrap_or_else(|| vec![10_000, 50_000]),
                    timed_steps,
                    &threads,
                    repeat,
                ),
                "mpmxdem" if device != "cpu" => granite::bench::mpmxdem_on_device(&granite::bench::DeviceBench {
                    device,
                    scene,
                    repeat,
                    copies,
                    dem_steps: dem_steps.iter().map(|&s| s as u64).collect(),
                    perturb,
                    force_rebuild,
                    workgroup,
                    json,
                    table,
                }),
                "adapter" => granite::bench::adapter(),
                "mpmxdem" => granite::bench::mpmxdem(&threads, repeat),
                "triaxial" => granite::bench::triaxial(&threads, axial_strain),
                "potential" => {
                    let count = particles.and_then(|p| p.first().copied()).unwrap_or(512);
                    granite::bench::potential(count, timed_steps, repeat)
                }
                other => {
                    granite_core::errln!(
                        "granite: unknown benchmark `{other}`; available: mpm, dem, mpmxdem, triaxial, potential, adapter"
                    );
                    return ExitCode::from(2);
                }
            };
            match result {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    granite_core::errln!("granite: bench failed: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        Command::Batch { script, params, jobs, out, quiet, run_timeout } => {
            let out = out.unwrap_or_else(|| {
                let stem = script.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_else(|| "run".into());
                PathBuf::from("out").join(format!("{stem}_batch"))
            });
            let exe = match std::env::current_exe() {
                Ok(e) => e,
                Err(e) => {
                    granite_core::errln!("granite: cannot find the granite executable: {e}");
                    return ExitCode::FAILURE;
                }
            };
            // SIGINT and SIGTERM stop the batch: passed on to its runs, which stop cleanly.
            let stop = match granite::signals::install() {
                Ok(flag) => Some(flag),
                Err(e) => {
                    granite_core::errln!("granite: error: {e}");
                    return ExitCode::FAILURE;
                }
            };
            let options = granite::batch::BatchOptions { jobs, quiet, run_timeout, stop };
            match granite::batch::run(&exe, &script, &params, &out, &options) {
                Ok(outcomes) => {
                    use granite::batch::Status;
                    let count = |s: Status| outcomes.iter().filter(|o| o.status == s).count();
                    let ok = count(Status::Ok);
                    let mut counts = format!("{ok} ok, {} failed", count(Status::Failed));
                    for s in [Status::Interrupted, Status::TimedOut, Status::NotRun] {
                        if count(s) > 0 {
                            counts.push_str(&format!(", {} {}", count(s), s.name()));
                        }
                    }
                    granite_core::outln!(
                        "granite batch: {} runs, {counts}; summary in {}",
                        outcomes.len(),
                        out.join("batch_summary.csv").display()
                    );
                    if let Some(signal) = granite::signals::received() {
                        granite_core::errln!("granite batch: stopped by {}", granite_script::signal_name(signal));
                        ExitCode::from((128 + signal).clamp(0, 255) as u8)
                    } else if ok < outcomes.len() {
                        ExitCode::FAILURE
                    } else {
                        ExitCode::SUCCESS
                    }
                }
                Err(e) => {
                    granite_core::errln!("granite: error: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        Command::Plot { csv, x, y, out } => match granite_script::plot::plot(&csv, &x, &y, out) {
            Ok(path) => {
                granite_core::outln!("granite: wrote {}", path.display());
                ExitCode::SUCCESS
            }
            Err(e) => {
                granite_core::errln!("granite: error: {e}");
                ExitCode::FAILURE
            }
        },
        Command::Repl { script, out, set, plugins, quiet } => {
            let program = format!("granite {} ({})", env!("CARGO_PKG_VERSION"), env!("GRANITE_GIT_COMMIT"));
            let out_dir = out.unwrap_or_else(|| PathBuf::from("out").join("repl"));
            let options =
                granite_script::RunOptions { program, out_dir, overrides: set, quiet, plugins, ..Default::default() };
            match granite::repl::run(script.as_deref(), options) {
                Ok(0) => ExitCode::SUCCESS,
                Ok(failed) => {
                    granite_core::errln!("granite: {failed} input(s) failed");
                    ExitCode::FAILURE
                }
                Err(e) => {
                    granite_core::errln!("granite: error: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        Command::Api { name: None } => {
            granite_core::out!("{}", granite_script::api_doc::markdown());
            ExitCode::SUCCESS
        }
        Command::Api { name: Some(name) } => {
            let found = granite_script::api_doc::lookup(&name);
            if found.is_empty() {
                let word = name.rsplit('.').next().unwrap_or(&name);
                granite_core::errln!(
                    "granite: no function or property `{name}` in the API{}",
                    granite_script::api_doc::did_you_mean(word)
                );
                return ExitCode::FAILURE;
            }
            for d in found {
                granite_core::out!("{}", granite_script::api_doc::help_text(d));
            }
            ExitCode::SUCCESS
        }
        Command::Plugins { plugins } => match granite::plugin_listing(&plugins) {
            Ok(listing) => {
                granite_core::out!("{listing}");
                ExitCode::SUCCESS
            }
            Err(e) => {
                granite_core::errln!("granite: error: {e}");
                ExitCode::FAILURE
            }
        },
    }
}
