//! `granite bench mpm`: material-point updates per second (one update = one point through one
//! whole MPM step: P2G, grid update, G2P, strain and stress).

use granite_core::mpm::boundary::VelocityConstraint;
use granite_core::mpm::fill::{cell_points, Layout};
use granite_core::mpm::TimeFunction;
use granite_core::mpm::{Face, Mesh, MpmSim, StressScheme};
use granite_core::registry::ParamMap;
use granite_core::{GraniteError, Result};
use std::time::Instant;

fn params(pairs: &[(&str, f64)]) -> ParamMap {
    pairs.iter().map(|(k, v)| (k.to_string(), *v)).collect()
}

/// A 3D linear-elastic block of about `points` points (8 per cell) on a fixed floor under gravity.
pub fn elastic_block(points: usize) -> Result<MpmSim> {
    let reg = crate::registry();
    let cells_per_side = ((points as f64 / 8.0).cbrt().round() as usize).max(1);
    let h = 0.1;
    let n = cells_per_side + 2;
    let mesh = Mesh::new(3, [0.0; 3], [h; 3], [n, n, n])?;
    let mut sim = MpmSim::new(mesh.clone(), reg.build_velocity_update("FLIP", &ParamMap::new())?);
    let law = reg.build_law("linear_elastic", &params(&[("young", 1e7), ("poisson", 0.3)]))?;
    let m = sim.add_material("block", 2000.0, law)?;
    let top = h * (cells_per_side as f64 + 1.0);
    let (xs, vols) = cell_points(&mesh, Layout::Gauss, 2, |x| Ok(x.iter().all(|&c| c > h && c < top)))?;
    sim.add_points(m, &xs, &vols, [0.0; 3], [0.0; 6])?;
    sim.gravity = [0.0, 0.0, -9.81];
    sim.scheme = StressScheme::Usf;
    for face in ["x-", "x+", "y-", "y+", "z-"] {
        let f = Face::parse(face, 3)?;
        sim.boundary.velocity.push(VelocityConstraint {
            nodes: f.nodes(&mesh),
            axis: f.axis,
            value: TimeFunction::Constant(0.0),
        });
    }
    let dt = 0.2 * sim.critical_dt().unwrap_or(1e-4);
    sim.set_dt(dt)?;
    Ok(sim)
}

/// The thesis column (table 5.1 Mohr-Coulomb) at a fine resolution, settling on its narrow mesh.
pub fn mohr_coulomb_column(cell: f64) -> Result<MpmSim> {
    let reg = crate::registry();
    let (width, height) = (1.0, 2.0);
    let cells = [(width / cell).round() as usize, (height / cell).round() as usize, 1];
    let mesh = Mesh::new(2, [0.0; 3], [cell, cell, 1.0], cells)?;
    let mut sim = MpmSim::new(mesh.clone(), reg.build_velocity_update("FLIP", &ParamMap::new())?);
    let law = reg.build_law(
        "mohr_coulomb",
        &params(&[("young", 1.28e7), ("poisson", 0.16), ("friction", 33.75), ("cohesion", 1.0)]),
    )?;
    let m = sim.add_material("sand", 1748.0, law)?;
    let (xs, vols) = cell_points(&mesh, Layout::Gauss, 2, |_| Ok(true))?;
    sim.add_points(m, &xs, &vols, [0.0; 3], [-250.0, -250.0, -250.0, 0.0, 0.0, 0.0])?;
    sim.gravity = [0.0, -9.81, 0.0];
    sim.damping = 0.1;
    for (face, _) in [("x-", 0), ("x+", 0), ("y-", 1)] {
        let f = Face::parse(face, 2)?;
        sim.boundary.velocity.push(VelocityConstraint {
            nodes: f.nodes(&mesh),
            axis: f.axis,
            value: TimeFunction::Constant(0.0),
        });
    }
    sim.set_dt(0.1 * sim.critical_dt().unwrap_or(1e-5))?;
    Ok(sim)
}

fn time_steps(sim: &mut MpmSim, steps: usize) -> Result<f64> {
    for _ in 0..3 {
        sim.step()?;
    }
    let t = Instant::now();
    for _ in 0..steps {
        sim.step()?;
    }
    Ok(t.elapsed().as_secs_f64())
}

fn measure(label: &str, threads: &[usize], steps: usize, build: &(dyn Fn() -> Result<MpmSim> + Sync)) -> Result<()> {
    let mut base = None;
    for &n in threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .map_err(|e| GraniteError::Other(format!("thread pool: {e}")))?;
        let (secs, points) = pool.install(|| -> Result<(f64, usize)> {
            let mut sim = build()?;
            let points = sim.points.len();
            Ok((time_steps(&mut sim, steps)?, points))
        })?;
        let rate = points as f64 * steps as f64 / secs;
        let speedup = base.map(|b: f64| rate / b).unwrap_or(1.0);
        base.get_or_insert(rate);
        println!(
            "{label:<34} threads {n}  points {points:>7}  steps {steps:>4}  {:>8.3} s  {:>7.2} M point-updates/s  {:>6.2} M/s per thread  speed-up {speedup:.2}x",
            secs,
            rate / 1e6,
            rate / 1e6 / n as f64
        );
    }
    Ok(())
}

pub fn mpm(points: usize, steps: usize, threads: &[usize]) -> Result<()> {
    println!("granite bench mpm (USF + FLIP, linear shape functions)");
    measure("3D linear-elastic block", threads, steps, &|| elastic_block(points))?;
    let cell = (2.0 / (points as f64 / 4.0)).sqrt();
    measure("2D Mohr-Coulomb column (table 5.1)", threads, steps, &|| mohr_coulomb_column(cell))?;
    Ok(())
}
