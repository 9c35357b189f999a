//! granite against YADE 2023.02a on the same scenes (the scripts in tests/yade/): a periodic
//! packing under a constant-volume compression and a simple shear (linear, rolling-resistance and
//! Hertz-Mindlin laws), and a deposition into a box.
//! YADE runs from granite's saved state with its standard engines (ScGeom, FrictPhys and
//! CundallStrack, or CohFrictPhys with the incremental moment law, or MindlinPhys;
//! NewtonIntegrator): same grains, velocities, law, damping and time step.
//!
//! Two granular runs that differ in the last bits drift apart (the packing is chaotic), so the
//! comparison has two parts. Until the runs drift, the stresses agree to what the two codes'
//! details allow. Afterwards each code is compared with itself: "twins" of a run, whose damping
//! differs by a few 1e-9 (physically the same run), drift from it too, and granite and YADE must
//! not differ from each other much more than each differs from its own twins.
//!
//! Needs YADE on the PATH (`apt-get install yade`); ignored by default:
//! `cargo test --release --test integration yade_comparison:: -- --ignored`.

use crate::common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Stress samples up to this many steps come before the runs drift apart (the drift shows after
/// about 1500 steps in both periodic scenes).
const BEFORE_DRIFT: f64 = 1000.0;
/// Largest stress difference before the drift, relative to the largest stress component. What the
/// codes do differently there is YADE's start: it gives the grains the cell's velocity field one
/// step late (about 1e-4 of the stress here). A wrong law parameter shows far above it: 2 degrees
/// of friction, 10 % of kt or 5 % of kn give 2e-3 to 5e-2 within these steps.
const SAME_LAW: f64 = 1e-3;
/// Relative damping offsets of a run (0) and its twins.
const TWINS: [f64; 3] = [0.0, 1e-9, 2e-9];
/// How much further granite and YADE may drift from each other than each drifts from its twins
/// (the two codes start drifting from about 1e-4, see `SAME_LAW`, instead of 1e-9: earlier), or
/// than `SAME_LAW` where the runs hardly drift.
const DRIFT_MARGIN: f64 = 2.0;

fn yade_script(name: &str) -> PathBuf {
    common::root().join("tests").join("yade").join(name)
}

/// Runs a tests/yade script with granite on one thread; returns its output folder.
fn granite(script: &str, name: &str, sets: &[(&str, String)]) -> PathBuf {
    let out = common::out_dir(name);
    let pairs: Vec<(String, String)> = sets.iter().map(|(k, v)| (k.to_string(), v.clone())).collect();
    granite::run(&yade_script(script), pairs, Some(out.clone()), true, Some(1))
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    out
}

/// Runs tests/yade/yade_run.py on a saved granite state; returns the CSV it writes.
fn yade(state: &Path, name: &str, options: &[(&str, String)]) -> PathBuf {
    let out = common::out_dir(name);
    std::fs::create_dir_all(&out).unwrap();
    let csv = out.join("yade.csv");
    let mut command = std::process::Command::new("yade");
    command.arg("-n").arg("-x").arg(yade_script("yade_run.py")).arg(state).arg(&csv);
    command.args(options.iter().map(|(k, v)| format!("{k}={v}")));
    let output = command.output().unwrap_or_else(|e| panic!("cannot start `yade` ({e}): apt-get install yade"));
    assert!(
        output.status.success() && csv.is_file(),
        "{name}: yade failed:\n{}\n{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    csv
}

/// The packing of tests/yade/prepare.rhai, made once for the tests of this file.
fn packing() -> &'static Path {
    static PACKING: OnceLock<PathBuf> = OnceLock::new();
    PACKING.get_or_init(|| granite("prepare.rhai", "yade_packing", &[]).join("packing.json"))
}

struct Series {
    header: Vec<String>,
    rows: Vec<Vec<f64>>,
}

impl Series {
    fn read(path: &Path) -> Series {
        let (header, rows) = common::read_csv(path);
        Series { header, rows }
    }
    fn get(&self, row: usize, name: &str) -> f64 {
        self.rows[row][common::column(&self.header, name)]
    }
    /// The row written `steps` steps after the first one (granite counts steps from the saved
    /// state's, YADE from 0).
    fn row_after(&self, steps: f64) -> Option<usize> {
        let first = self.get(0, "step");
        (0..self.rows.len()).find(|&i| self.get(i, "step") - first == steps)
    }
}

const STRESS: [&str; 4] = ["sxx", "syy", "szz", "sxz"];

/// Steps after the start and largest stress difference of `a` from `base` there, relative to
/// `base`'s largest component, at every sample both runs wrote after the start.
fn stress_gaps(base: &Series, a: &Series) -> Vec<(f64, f64)> {
    let first = base.get(0, "step");
    let gaps: Vec<(f64, f64)> = (1..base.rows.len())
        .filter_map(|i| {
            let after = base.get(i, "step") - first;
            let j = a.row_after(after)?;
            let scale = STRESS.iter().map(|k| base.get(i, k).abs()).fold(0.0, f64::max);
            let gap = STRESS.iter().map(|k| (a.get(j, k) - base.get(i, k)).abs()).fold(0.0, f64::max) / scale;
            Some((after, gap))
        })
        .collect();
    assert!(gaps.len() >= 20, "the runs share only {} samples", gaps.len());
    gaps
}

/// Root mean square of the gaps.
fn rms(gaps: &[(f64, f64)]) -> f64 {
    (gaps.iter().map(|(_, g)| g * g).sum::<f64>() / gaps.len() as f64).sqrt()
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// The periodic comparison: the packing under a constant cell velocity gradient. granite writes
/// its rows at multiples of `every` counted from step 0 and the packing stops at a multiple of
/// 500 steps (prepare.rhai), so `every` divides 500 for both codes to sample the same steps.
fn periodic_case(name: &str, steps: usize, every: usize, options: &[(&str, &str)]) {
    assert_eq!(500 % every, 0);
    let state = packing();
    let damping = 0.2;
    let sets = |offset: f64| {
        let mut sets = vec![
            ("steps", steps.to_string()),
            ("every", every.to_string()),
            ("friction", "30.0".to_string()),
            ("damping", format!("{:.12}", damping * (1.0 + offset))),
        ];
        sets.extend(options.iter().map(|(k, v)| (*k, v.to_string())));
        sets
    };
    let mut granite_runs = Vec::new();
    let mut yade_runs = Vec::new();
    for (k, &offset) in TWINS.iter().enumerate() {
        let mut granite_sets = sets(offset);
        granite_sets.push(("state", state.display().to_string()));
        let dir = granite("granite_run.rhai", &format!("{name}_granite{k}"), &granite_sets);
        granite_runs.push(Series::read(&dir.join("series.csv")));
        yade_runs.push(Series::read(&yade(state, &format!("{name}_yade{k}"), &sets(offset))));
    }

    let (granite0, yade0) = (&granite_runs[0], &yade_runs[0]);
    let gaps = stress_gaps(granite0, yade0);
    let early: Vec<f64> = gaps.iter().filter(|(after, _)| *after <= BEFORE_DRIFT).map(|(_, g)| *g).collect();
    assert!(!early.is_empty());
    let early_max = early.iter().cloned().fold(0.0, f64::max);
    assert!(early_max < SAME_LAW, "{name}: before the drift, YADE's stress is {early_max:.2e} away from granite's");

    let across = mean(&granite_runs.iter().zip(&yade_runs).map(|(g, y)| rms(&stress_gaps(g, y))).collect::<Vec<_>>());
    let within = |runs: &[Series]| mean(&runs[1..].iter().map(|t| rms(&stress_gaps(&runs[0], t))).collect::<Vec<_>>());
    let (within_granite, within_yade) = (within(&granite_runs), within(&yade_runs));
    println!(
        "{name}: before the drift {early_max:.2e}; drift (rms of the stress gaps) granite-YADE {across:.4}, \
         granite-granite {within_granite:.4}, YADE-YADE {within_yade:.4}"
    );
    // A packing that hardly drifts (rolling resistance calms its rearrangements) keeps the codes'
    // own difference instead, which may grow with the strain as much.
    let allowed = DRIFT_MARGIN * within_granite.max(within_yade).max(SAME_LAW);
    assert!(across <= allowed, "{name}: granite and YADE drift {across:.4} apart, more than {allowed:.4}");
}

#[test]
#[ignore = "needs YADE (apt-get install yade); about a minute in release"]
fn constant_volume_compression_matches_yade() {
    // Compression along z at 2 /s, x and y stretched to keep the volume: about 9 % axial strain.
    periodic_case("yade_compression", 20_000, 250, &[("l_xx", "1.0"), ("l_yy", "1.0"), ("l_zz", "-2.0")]);
}

#[test]
#[ignore = "needs YADE (apt-get install yade); about a minute in release"]
fn simple_shear_matches_yade() {
    // Shear rate 4 /s in the xz plane at constant volume: a shear strain of about 0.19.
    periodic_case("yade_shear", 20_000, 500, &[("l_xz", "4.0")]);
}

#[test]
#[ignore = "needs YADE (apt-get install yade); about a minute in release"]
fn simple_shear_with_rolling_resistance_matches_yade() {
    // The Camargue sand law of the coupling (table 5.2's alpha_r, alpha_t, eta_r), against YADE's
    // CohFrictPhys without cohesion and its incremental moment law.
    periodic_case("yade_rolling", 20_000, 500, &[("l_xz", "4.0"), ("law", "rolling_resistance")]);
}

#[test]
#[ignore = "needs YADE (apt-get install yade); about a minute in release"]
fn simple_shear_with_hertz_mindlin_matches_yade() {
    // Hertz's normal force and Mindlin's tangential stiffness against YADE's MindlinPhys; a modulus
    // that gives the packing's contacts about the stiffness of the linear law it was made with.
    periodic_case(
        "yade_hertz",
        20_000,
        500,
        &[("l_xz", "4.0"), ("law", "hertz_mindlin"), ("young", "1e9"), ("poisson", "0.25")],
    );
}

fn mean_and_sd(values: &[f64]) -> (f64, f64) {
    let m = mean(values);
    let var = values.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (values.len() as f64 - 1.0);
    (m, var.sqrt())
}

#[test]
#[ignore = "needs YADE (apt-get install yade); about two minutes in release"]
fn deposition_settles_as_in_yade() {
    let (steps, every) = (60_000usize, 200usize);
    let sets = |damping: f64| {
        vec![("steps", steps.to_string()), ("every", every.to_string()), ("damping", format!("{damping:.12}"))]
    };
    // A run and four twins: the spread of what a settled packing carries.
    let dirs: Vec<PathBuf> = (0..5)
        .map(|k| granite("deposition.rhai", &format!("yade_deposition{k}"), &sets(0.4 * (1.0 + k as f64 * 1e-9))))
        .collect();
    let runs: Vec<Series> = dirs.iter().map(|d| Series::read(&d.join("series.csv"))).collect();
    let yade = Series::read(&yade(&dirs[0].join("initial.json"), "yade_deposition_yade", &sets(0.4)[..2]));
    let base = &runs[0];

    // Free fall and the first touches of the walls, before grains meet grains: the same motion,
    // apart from rounding (1.6e-9 at step 400 when measured).
    for i in 1..base.rows.len() {
        if base.get(i, "contacts") > 0.0 {
            break;
        }
        let (g, y) = (base.get(i, "kinetic_energy"), yade.get(i, "kinetic_energy"));
        assert!((g - y).abs() <= 1e-6 * y, "step {}: kinetic energy {g} in granite, {y} in YADE", i * every);
    }

    // Settled: the kinetic energy is a vanishing part of the weight times the height fallen.
    let last = base.rows.len() - 1;
    let weight = -base.get(last, "floor_force");
    assert!(weight > 0.0);
    for (who, ke) in [("granite", base.get(last, "kinetic_energy")), ("YADE", yade.get(last, "kinetic_energy"))] {
        assert!(ke < 1e-6 * weight * base.get(0, "max_height"), "{who} has not settled: kinetic energy {ke} J");
    }

    // What the floor carries (the side walls' friction holds the rest, Janssen's effect) and the
    // contacts of the settled packing depend on the grains' chaotic paths: YADE's must lie
    // among granite's twins, within three of their standard deviations.
    let checks = [
        ("floor force (N)", runs.iter().map(|r| r.get(last, "floor_force")).collect::<Vec<_>>(), {
            yade.get(last, "wall_force_z")
        }),
        (
            "contacts",
            runs.iter().map(|r| r.get(last, "contacts") + r.get(last, "wall_contacts")).collect(),
            yade.get(last, "contacts"),
        ),
    ];
    for (what, granite_values, yade_value) in checks {
        let (mean, sd) = mean_and_sd(&granite_values);
        println!("deposition {what}: granite {granite_values:?} (mean {mean:.3}, sd {sd:.3}), YADE {yade_value}");
        assert!(
            (yade_value - mean).abs() <= 3.0 * sd,
            "deposition {what}: YADE {yade_value}, granite's runs {granite_values:?}"
        );
    }
}
