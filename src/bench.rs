//! `granite bench mpm`: material-point updates per second (one update = one point through one
//! whole MPM step: P2G, grid update, G2P, strain and stress).

use granite_core::mpm::boundary::VelocityConstraint;
use granite_core::mpm::fill::{cell_points, Layout};
use granite_core::mpm::TimeFunction;
use granite_core::mpm::{Face, Mesh, MpmSim, StressScheme};
use granite_core::registry::ParamMap;
use granite_core::{GraniteError, Result};
use std::time::Instant;

fn pool(threads: usize) -> Result<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| GraniteError::Other(format!("thread pool: {e}")))
}

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
        let pool = pool(n)?;
        let (secs, points) = pool.install(|| -> Result<(f64, usize)> {
            let mut sim = build()?;
            let points = sim.points.len();
            Ok((time_steps(&mut sim, steps)?, points))
        })?;
        let rate = points as f64 * steps as f64 / secs;
        let speedup = speedup_over(&mut base, rate);
        granite_core::outln!(
            "{label:<34} threads {n}  points {points:>7}  steps {steps:>4}  {:>8.3} s  {:>7.2} M point-updates/s  {:>6.2} M/s per thread  speed-up {speedup:.2}x",
            secs,
            rate / 1e6,
            rate / 1e6 / n as f64
        );
    }
    Ok(())
}

pub fn mpm(points: usize, steps: usize, threads: &[usize]) -> Result<()> {
    granite_core::outln!("granite bench mpm (USF + FLIP, linear shape functions)");
    measure("3D linear-elastic block", threads, steps, &|| elastic_block(points))?;
    let cell = (2.0 / (points as f64 / 4.0)).sqrt();
    measure("2D Mohr-Coulomb column (table 5.1)", threads, steps, &|| mohr_coulomb_column(cell))?;
    Ok(())
}

/// The gravity-deposition scene of the DEM benchmark (see scripts/dem/gravity_deposition.rhai).
pub fn gravity_deposition(count: usize) -> Result<granite_core::dem::DemSim> {
    use granite_core::dem::generate::lattice;
    use granite_core::dem::walls::{Wall, WallShape};
    let reg = crate::registry();
    let (r, rho, young) = (0.01, 2600.0, 1.0e7);
    let spacing = 2.2 * r;
    let side = ((count as f64 / 2.0).cbrt().ceil() as usize).max(1);
    let lx = side as f64 * spacing;
    let lz = (count as f64 / (side * side) as f64).ceil() * spacing;
    let mut sim = granite_core::dem::DemSim::new();
    sim.world.seed = 1;
    sim.skin = 0.5 * r;
    let m = sim.world.add_material("glass", rho)?;
    sim.world.set_contact_law(
        reg.build_contact_law("linear", &params(&[("young", young), ("kt_ratio", 0.3), ("friction", 30.0)]))?,
        None,
    )?;
    let top = lz + 2.0 * spacing;
    for (a, upper) in [(0, false), (0, true), (1, false), (1, true), (2, false)] {
        let mut n = [0.0; 3];
        n[a] = if upper { -1.0 } else { 1.0 };
        let position = if upper { [lx, lx, top] } else { [0.0; 3] };
        sim.world.add_wall(Wall::new("", WallShape::Plane { normal: n }, position, m));
    }
    for (x, radius) in lattice([0.0; 3], [lx, lx, lz], spacing, r, 0.05 * r, 1)? {
        sim.world.add_sphere(m, x, radius, [0.0; 3])?;
    }
    sim.world.gravity = [0.0, 0.0, -9.81];
    sim.world.damping = 0.4;
    sim.world.set_dt(0.5 * r * (rho / young).sqrt())?;
    Ok(sim)
}

/// A periodic RVE of `count` spheres (radius 1.5 mm +- 30 %) compacted to `pressure` (Pa) with a
/// friction of 5 degrees, then given 30 degrees; left at rest with no cell control.
pub fn periodic_rve(count: usize, pressure: f64) -> Result<granite_core::dem::DemSim> {
    use granite_core::dem::cell::{AxisGoal, CellControl, PeriodicCell};
    use granite_core::dem::generate::{cloud, Psd};
    let reg = crate::registry();
    let (r, rho): (f64, f64) = (1.5e-3, 2650.0);
    let solid = count as f64 * 4.0 / 3.0 * std::f64::consts::PI * r.powi(3) * 1.1;
    let side = (solid / 0.15).cbrt();
    let mut sim = granite_core::dem::DemSim::new();
    sim.world.seed = 1;
    sim.skin = 0.5 * 0.7 * r;
    let m = sim.world.add_material("grains", rho)?;
    let law =
        |phi: f64| reg.build_contact_law("linear", &params(&[("young", 1e8), ("kt_ratio", 0.5), ("friction", phi)]));
    sim.world.set_contact_law(law(5.0)?, None)?;
    sim.world.set_cell(Some(PeriodicCell::new_box([side; 3])));
    for (x, radius) in
        cloud([0.0; 3], [side; 3], count, &Psd::Uniform { min: 0.7 * r, max: 1.3 * r }, 1, &[], &|| None)?
    {
        sim.world.add_sphere(m, x, radius, [0.0; 3])?;
    }
    sim.world.damping = 0.4;
    sim.world.set_dt(0.3 * sim.world.critical_dt().unwrap_or(1e-6))?;
    let goal = AxisGoal::Stress { target: -pressure, max_rate: 5.0 };
    sim.world.cell_control = Some(CellControl::new([goal; 3], vec![], 200.0));
    for round in 0.. {
        for _ in 0..500 {
            sim.step()?;
        }
        let volume = sim.world.cell_volume().unwrap_or(1.0);
        let stress = sim.world.love_weber_stress(volume);
        let reached = sim.world.cell_control.as_ref().is_some_and(|c| c.stress_reached(&stress, 0.01));
        if (reached && sim.world.diagnostics().unbalanced_force < 0.01) || round > 400 {
            break;
        }
    }
    sim.world.set_contact_law(law(30.0)?, None)?;
    sim.world.cell_control = None;
    // Let the contacts' tangential springs build up again under the new friction.
    for _ in 0..500 {
        sim.step()?;
    }
    Ok(sim)
}

/// One timed run per thread count, `repeat` rounds, rounds interleaved (a slow spell of a shared
/// machine then hits every thread count alike); for each thread count, the fastest run (seconds
/// and what it returned) and the slowest time.
struct Timed<T> {
    threads: usize,
    best: f64,
    worst: f64,
    out: T,
}

fn best_of<T: Send>(
    threads: &[usize],
    repeat: usize,
    run: impl Fn() -> Result<(f64, T)> + Sync,
) -> Result<Vec<Timed<T>>> {
    let pools = threads.iter().map(|&n| pool(n)).collect::<Result<Vec<_>>>()?;
    let mut timed: Vec<Option<Timed<T>>> = threads.iter().map(|_| None).collect();
    for _ in 0..repeat.max(1) {
        for ((slot, pool), &n) in timed.iter_mut().zip(&pools).zip(threads) {
            let (secs, out) = pool.install(&run)?;
            *slot = Some(match slot.take() {
                None => Timed { threads: n, best: secs, worst: secs, out },
                Some(t) if secs < t.best => Timed { threads: n, best: secs, worst: t.worst.max(secs), out },
                Some(t) => Timed { worst: t.worst.max(secs), ..t },
            });
        }
    }
    Ok(timed.into_iter().flatten().collect())
}

/// What two threads can gain on this machine at best: the same work on every thread, each on its
/// own data (no communication), timed on 1 and on `threads` threads. `arithmetic` chains square
/// roots on a small array; `cache-bound` reads and writes a 512 kB array in a scattered order, as
/// a contact loop does. DEM stages cannot scale better than the second.
pub fn machine_reference(threads: &[usize], repeat: usize) -> Result<()> {
    fn arithmetic(data: &mut [f64]) {
        for _ in 0..2000 {
            for x in data.iter_mut() {
                *x = (*x * 1.000_000_1 + 1e-9).sqrt();
            }
        }
    }
    fn cache_bound(data: &mut [f64]) {
        let n = data.len();
        for _ in 0..40 {
            for i in 0..n {
                let j = (i * 7919) % n;
                data[i] = data[i] * 0.999_999 + data[j] * 1e-7;
            }
        }
    }
    granite_core::outln!(
        "machine reference: the same work on every thread, each on its own data (ideal speed-up = threads)"
    );
    for (name, len, work) in [("arithmetic", 1000, arithmetic as fn(&mut [f64])), ("cache-bound", 65_536, cache_bound)]
    {
        let timed = best_of(threads, repeat, || -> Result<(f64, ())> {
            let mut data = vec![vec![1.0f64; len]; rayon::current_num_threads()];
            let t = Instant::now();
            rayon::scope(|s| {
                for d in data.iter_mut() {
                    s.spawn(move |_| work(d));
                }
            });
            Ok((t.elapsed().as_secs_f64(), ()))
        })?;
        for (t, speedup) in timed.iter().zip(same_work_per_thread_speedups(&timed)) {
            granite_core::outln!("  {name:<11}  threads {}  {:>7.2} ms{speedup}", t.threads, t.best * 1e3);
        }
    }
    Ok(())
}

/// `granite bench dem`: particle-steps per second of gravity deposition (2000 timed steps after
/// 200 of warm-up, as in the protocol) and time per step of a sheared periodic RVE; each
/// the fastest of `repeat` runs, with the slowest in brackets (this machine is shared). Each is
/// also timed in interleaved windows against the ceiling of the moment (see [`windows`]).
pub fn dem(counts: &[usize], steps: usize, threads: &[usize], repeat: usize) -> Result<()> {
    machine_reference(threads, repeat)?;
    granite_core::outln!(
        "granite bench dem: gravity deposition (linear law, Cundall 0.4, skin 0.5 r), best of {repeat}"
    );
    for &count in counts {
        let timed = best_of(threads, repeat, || -> Result<(f64, (usize, u64, usize))> {
            let mut sim = gravity_deposition(count)?;
            for _ in 0..200 {
                sim.step()?;
            }
            let before = sim.rebuilds;
            let t = Instant::now();
            for _ in 0..steps {
                sim.step()?;
            }
            Ok((
                t.elapsed().as_secs_f64(),
                (sim.world.spheres.len(), sim.rebuilds - before, sim.world.contacts.spheres.touching_count()),
            ))
        })?;
        let mut base = None;
        for Timed { threads: n, best, worst, out: (particles, rebuilds, contacts) } in timed {
            let rate = particles as f64 * steps as f64 / best;
            let speedup = speedup_over(&mut base, rate);
            granite_core::outln!(
                "N = {particles:>6}  threads {n}  {steps} steps  {best:>7.3} s ({worst:.3})  {:>7.2} M particle-steps/s  {:>6.2} M/s per thread  speed-up {speedup:.2}x  ({rebuilds} list rebuilds, {contacts} contacts at the end)",
                rate / 1e6,
                rate / 1e6 / n as f64
            );
        }
        if threads.iter().any(|&n| n > 1) {
            let mut state = gravity_deposition(count)?;
            pool(1)?.install(|| (0..200).try_for_each(|_| state.step()))?;
            print_windows(&format!("N = {:>6}  ", state.world.spheres.len()), &state, threads, repeat)?;
        }
    }
    granite_core::outln!(
        "granite bench dem: 1500-sphere periodic RVE at 100 kPa, constant-volume simple shear, best of {repeat}"
    );
    let mut rve = periodic_rve(1500, 1e5)?;
    rve.world.cell_control = Some(granite_core::dem::cell::CellControl::new(
        [granite_core::dem::cell::AxisGoal::Rate(0.0); 3],
        vec![(0, 2, 1.0)],
        200.0,
    ));
    let timed = best_of(threads, repeat, || -> Result<(f64, usize)> {
        let mut sim = rve.clone();
        let t = Instant::now();
        for _ in 0..steps {
            sim.step()?;
        }
        Ok((t.elapsed().as_secs_f64(), sim.world.contacts.spheres.touching_count()))
    })?;
    let mut base = None;
    for Timed { threads: n, best, worst, out: contacts } in timed {
        let per_step = best / steps as f64;
        let speedup = speedup_over(&mut base, 1.0 / per_step);
        granite_core::outln!(
            "N = {:>6}  threads {n}  {steps} steps  {:>7.4} ms per step ({:.4})  {:>6.2} M particle-steps/s  speed-up {speedup:.2}x  ({contacts} contacts)",
            rve.world.spheres.len(),
            per_step * 1e3,
            worst / steps as f64 * 1e3,
            rve.world.spheres.len() as f64 / per_step / 1e6
        );
    }
    // The ceiling of the parallel figures above on this machine: every thread steps its own copy
    // (sequentially, nothing shared, no synchronisation); the speed-up is n t1 / tn.
    let timed = best_of(threads, repeat, || -> Result<(f64, ())> {
        let t = Instant::now();
        rayon::broadcast(|_| -> Result<()> {
            let mut sim = rve.clone();
            sim.set_sequential(true);
            for _ in 0..steps {
                sim.step()?;
            }
            Ok(())
        })
        .into_iter()
        .collect::<Result<Vec<()>>>()?;
        Ok((t.elapsed().as_secs_f64(), ()))
    })?;
    for (t, speedup) in timed.iter().zip(same_work_per_thread_speedups(&timed)) {
        granite_core::outln!(
            "the same RVE, one copy per thread (nothing shared)  threads {}  {:>7.4} ms per step{speedup}",
            t.threads,
            t.best / steps as f64 * 1e3
        );
    }
    print_windows("", &rve, threads, repeat)
}

/// Prints the speed-ups that [`windows`] measures from `state` on each thread count above one.
fn print_windows(label: &str, state: &granite_core::dem::DemSim, threads: &[usize], repeat: usize) -> Result<()> {
    for &n in threads.iter().filter(|&&n| n > 1) {
        let w = windows(state, n, WINDOWS, repeat)?;
        granite_core::outln!(
            "{label}interleaved windows ({WINDOWS} x {WINDOW_STEPS} steps)  threads {n}  speed-up {:.2}x, one copy per thread {:.2}x: the parallel step gets {:.0} % of what this machine gives independent copies",
            w.speedup,
            w.ceiling,
            100.0 * w.speedup / w.ceiling
        );
    }
    Ok(())
}

/// Windows timed by [`windows`], and steps in each.
const WINDOWS: usize = 10;
const WINDOW_STEPS: usize = 100;

/// What [`windows`] measured: the speed-up of the parallel step, and that of one copy per
/// thread (the ceiling), both against one thread.
struct Windows {
    speedup: f64,
    ceiling: f64,
}

/// The speed-up of a simulation on `n` threads, set against the ceiling of the moment: from state
/// `from`, the same window of steps is timed on one thread, on `n`, and as `n` copies at once
/// (each the fastest of `repeat`), one right after the other, so that a slow spell of this shared
/// machine slows all three; the state then moves on by a window, `count` times. Speed-ups are
/// ratios of summed times.
fn windows(from: &granite_core::dem::DemSim, n: usize, count: usize, repeat: usize) -> Result<Windows> {
    let (one, many) = (pool(1)?, pool(n)?);
    let window = |sim: &mut granite_core::dem::DemSim| -> Result<f64> {
        // The first step of a copy touches its fresh memory: not timed.
        sim.step()?;
        let t = Instant::now();
        for _ in 1..WINDOW_STEPS {
            sim.step()?;
        }
        Ok(t.elapsed().as_secs_f64())
    };
    let mut state = from.clone();
    let mut sums = [0.0; 3];
    for _ in 0..count {
        let mut best = [f64::INFINITY; 3];
        for _ in 0..repeat.max(1) {
            best[0] = best[0].min(one.install(|| window(&mut state.clone()))?);
            best[1] = best[1].min(many.install(|| window(&mut state.clone()))?);
            let copies = many.broadcast(|_| {
                let mut copy = state.clone();
                copy.set_sequential(true);
                window(&mut copy)
            });
            best[2] = best[2].min(copies.into_iter().collect::<Result<Vec<f64>>>()?.into_iter().fold(0.0, f64::max));
        }
        sums.iter_mut().zip(best).for_each(|(sum, b)| *sum += b);
        one.install(|| (0..WINDOW_STEPS).try_for_each(|_| state.step()))?;
    }
    Ok(Windows { speedup: sums[0] / sums[1], ceiling: n as f64 * sums[0] / sums[2] })
}

/// Benchmark (b) of the coupling issue: MPM steps, their time step, DEM steps per MPM step, and
/// the oedometric loading: the top of a mesh of 2 x 2 cells of `CELL` pushed down at `TOP_SPEED`.
const MPM_STEPS: usize = 200;
const MPM_DT: f64 = 1e-5;
const DEM_STEPS: usize = 51;
const TOP_SPEED: f64 = 1e-2;
const CELL: f64 = 0.5;

/// Seconds to step `copies` copies of `rve` as the coupled run of [`mpmxdem`] steps its RVEs, in
/// the current pool: per MPM step, each copy takes its DEM steps at the oedometric strain rate
/// (one copy per task, in parallel over copies), with nothing else around. Also the seconds
/// spent inside the tasks, summed over tasks: against the wall time times the threads, what
/// the threads waited; against the same sum on one thread, how much slower the same work ran.
fn rves_alone(rve: &granite_core::dem::DemSim, copies: usize) -> Result<RvesAlone> {
    use rayon::prelude::*;
    let mut sims: Vec<_> = (0..copies).map(|_| (rve.clone(), 0.0)).collect();
    for (sim, _) in sims.iter_mut() {
        sim.set_sequential(true);
        // One MPM step's strain increment spread over its DEM steps, as the dem_rve law does.
        let rate = TOP_SPEED / (2.0 * CELL) * MPM_DT / (DEM_STEPS as f64 * sim.world.dt);
        if let Some(c) = sim.world.cell.as_mut() {
            c.velocity_gradient[(1, 1)] = -rate;
        }
    }
    let t = Instant::now();
    for _ in 0..MPM_STEPS {
        sims.par_iter_mut().try_for_each(|(sim, busy)| {
            let started = Instant::now();
            let done = (0..DEM_STEPS).try_for_each(|_| sim.step());
            *busy += started.elapsed().as_secs_f64();
            done
        })?;
    }
    Ok(RvesAlone { wall: t.elapsed().as_secs_f64(), busy: sims.iter().map(|(_, busy)| busy).sum() })
}

/// What [`rves_alone`] measured: wall seconds, and seconds inside the RVE tasks over all threads.
#[derive(Clone, Copy)]
struct RvesAlone {
    wall: f64,
    busy: f64,
}

/// `granite bench mpmxdem`: an oedometric scene of 16 material points, each with a 125-sphere
/// periodic RVE, 200 MPM steps of 1e-5 s with 51 DEM steps each (the peer's protocol).
/// The scene of `granite bench mpmxdem`: 2 x 2 cells, 2 x 2 points each, every point a copy of
/// `rve` stepped `DEM_STEPS` times per MPM step, compressed oedometrically from the top. Over the
/// processes of `comm` when given. Returns it with the memory of one RVE.
fn oedometric_rves(rve: &granite_core::dem::DemSim, comm: Option<granite_core::comm::Comm>) -> Result<(MpmSim, usize)> {
    use granite_core::mpm::boundary::{TimeFunction, VelocityConstraint};
    use granite_core::mpm::fill::{cell_points, Layout};
    use granite_core::mpm::Face;
    use std::sync::Arc;
    let reg = crate::registry();
    let mesh = Mesh::new(2, [0.0; 3], [CELL, CELL, 1.0], [2, 2, 1])?;
    let mut sim = MpmSim::new(mesh.clone(), reg.build_velocity_update("PIC", &ParamMap::new())?);
    if let Some(comm) = comm {
        sim.set_communicator(comm);
    }
    let mut objects = granite_core::ext::constitutive::ObjectMap::new();
    objects.insert("rve".into(), Arc::new(rve.clone()));
    // Every RVE steps (no exact sharing of points whose increments agree): the peer's work.
    let law = reg.build_law_with("dem_rve", &params(&[("dem_steps", DEM_STEPS as f64), ("share", 0.0)]), &objects)?;
    let bytes = law.point_objects().map(|o| o.bytes_per_point()).unwrap_or(0);
    let m = sim.add_material("sand", 1700.0, law)?;
    let (xs, vols) = cell_points(&mesh, Layout::Gauss, 2, |_| Ok(true))?;
    let volume = rve.world.cell_volume().unwrap_or(1.0);
    sim.add_points(m, &xs, &vols, [0.0; 3], rve.world.love_weber_stress(volume))?;
    for (face, axis, v) in [("x-", 0, 0.0), ("x+", 0, 0.0), ("y-", 1, 0.0), ("y+", 1, -TOP_SPEED)] {
        let f = Face::parse(face, 2)?;
        sim.boundary.velocity.push(VelocityConstraint {
            nodes: f.nodes(&mesh),
            axis,
            value: TimeFunction::Constant(v),
        });
    }
    sim.set_dt(MPM_DT)?;
    Ok((sim, bytes))
}

/// The RVE of `granite bench mpmxdem`: 125 spheres at 100 kPa with a script's default skin.
fn bench_rve() -> Result<granite_core::dem::DemSim> {
    let mut rve = periodic_rve(125, 1e5)?;
    // The Verlet skin scripts/mpmxdem/prepare_rve.rhai gives an RVE by default (0.05 smallest
    // radii): an RVE deforms slowly, so a thin skin means fewer candidate pairs and few rebuilds.
    let r_min = rve.world.spheres.smallest_radius();
    rve.set_skin(0.05 * r_min)?;
    Ok(rve)
}

/// `mpirun -np N granite bench mpmxdem`: the benchmark scene over N processes of one thread
/// each, against the same scene in rank 0 alone on N threads (the others wait without using
/// their core), alternating, `repeat` rounds; fastest and slowest of each printed, with per MPM
/// step the time in RVEs, in the all-gather, and its bytes.
pub fn mpmxdem_mpi(comm: granite_core::comm::Comm, repeat: usize) -> Result<()> {
    let (rank, size) = (comm.rank(), comm.size());
    let rve = bench_rve()?;
    let first = rank == 0;
    if first {
        granite_core::outln!(
            "granite bench mpmxdem over MPI: 16 points x {}-sphere RVEs, {MPM_STEPS} MPM steps x {DEM_STEPS} DEM steps, \
             {size} processes of 1 thread against 1 process of {size} threads",
            rve.world.spheres.len()
        );
    }
    let threads_pool = pool(size)?;
    let one_pool = pool(1)?;
    let wait = std::time::Duration::from_secs(3600);
    let (mut threaded, mut spread): (Vec<f64>, Vec<f64>) = (Vec::new(), Vec::new());
    let mut last_report = None;
    for _ in 0..repeat.max(1) {
        if first {
            threaded.push(threads_pool.install(|| -> Result<f64> {
                let (mut sim, _) = oedometric_rves(&rve, None)?;
                let t = Instant::now();
                for _ in 0..MPM_STEPS {
                    sim.step()?;
                }
                Ok(t.elapsed().as_secs_f64())
            })?);
        }
        if !comm.meet(wait) {
            comm.abort(1);
        }
        let (secs, report) =
            one_pool.install(|| -> Result<(f64, Option<granite_core::mpm::spread::SpreadReport>)> {
                let (mut sim, _) = oedometric_rves(&rve, Some(comm.clone()))?;
                let t = Instant::now();
                for _ in 0..MPM_STEPS {
                    sim.step()?;
                }
                let secs = t.elapsed().as_secs_f64();
                // One process keeps every RVE itself: nothing is spread, nothing communicated.
                let report = sim.materials[0].spread.as_ref().map(|s| s.report()).transpose()?;
                Ok((secs, report))
            })?;
        spread.push(secs);
        last_report = report;
    }
    if !first {
        return Ok(());
    }
    let fastest = |v: &[f64]| v.iter().cloned().fold(f64::INFINITY, f64::min);
    let slowest = |v: &[f64]| v.iter().cloned().fold(0.0, f64::max);
    let sphere_steps = (16 * rve.world.spheres.len() * DEM_STEPS * MPM_STEPS) as f64;
    let per_step = |s: f64| 1e6 * s / MPM_STEPS as f64;
    let (t_threads, t_spread) = (fastest(&threaded), fastest(&spread));
    granite_core::outln!(
        "1 process, {size} threads    {t_threads:>7.3} s ({:.3})  {:>6.2} M sphere-steps/s  {:>8.0} us per MPM step",
        slowest(&threaded),
        sphere_steps / t_threads / 1e6,
        per_step(t_threads)
    );
    granite_core::outln!(
        "{size} processes, 1 thread  {t_spread:>7.3} s ({:.3})  {:>6.2} M sphere-steps/s  {:>8.0} us per MPM step: {:.1} % of the threaded rate",
        slowest(&spread),
        sphere_steps / t_spread / 1e6,
        per_step(t_spread),
        100.0 * t_threads / t_spread
    );
    let Some(report) = last_report else {
        granite_core::outln!("  one process: all of each MPM step in its RVEs and the MPM, no communication");
        return Ok(());
    };
    let stages = report.stages.max(1) as f64;
    for r in 0..size {
        granite_core::outln!(
            "  rank {r}: {} RVEs; per MPM step {:>8.0} us in its RVEs, {:>6.0} us in the all-gather (waiting included), {:.0} bytes received",
            report.points[r],
            1e6 * report.busy_s[r] / stages,
            1e6 * report.gather_s[r] / stages,
            report.gather_bytes as f64 / stages
        );
    }
    Ok(())
}

pub fn mpmxdem(threads: &[usize], repeat: usize) -> Result<()> {
    // What a second core can give right now: the 2-thread figure below is read against it.
    machine_reference(threads, repeat)?;
    granite_core::outln!(
        "granite bench mpmxdem: 16 points x 125-sphere RVEs, {MPM_STEPS} MPM steps x {DEM_STEPS} DEM steps, oedometric"
    );
    let rve = bench_rve()?;
    // The coupling's own cost: in every round, right after the coupled run, the same DEM work
    // without the MPM around it (one slow spell of the machine then hits both alike).
    // Fastest time of that, per thread count.
    let alone_best = std::sync::Mutex::new(std::collections::BTreeMap::<usize, RvesAlone>::new());
    let timed = best_of(threads, repeat, || -> Result<(f64, (usize, usize))> {
        let (mut sim, bytes) = oedometric_rves(&rve, None)?;
        let t = Instant::now();
        for _ in 0..MPM_STEPS {
            sim.step()?;
        }
        let coupled = t.elapsed().as_secs_f64();
        let alone = rves_alone(&rve, sim.points.len())?;
        let mut best = alone_best.lock().unwrap_or_else(|e| e.into_inner());
        let entry = best.entry(rayon::current_num_threads()).or_insert(alone);
        if alone.wall < entry.wall {
            *entry = alone;
        }
        Ok((coupled, (sim.points.len(), bytes)))
    })?;
    let alone_best = alone_best.into_inner().unwrap_or_else(|e| e.into_inner());
    let mut base = None;
    for Timed { threads: n, best: secs, worst, out: (points, bytes) } in timed {
        let sphere_steps = (points * rve.world.spheres.len() * DEM_STEPS * MPM_STEPS) as f64;
        let rate = sphere_steps / secs;
        let speedup = speedup_over(&mut base, rate);
        granite_core::outln!(
            "threads {n}  {points} RVEs  {secs:>7.3} s ({worst:.3})  {:>6.2} M sphere-steps/s  {:>6.2} M/s per thread  speed-up {speedup:.2}x  memory per RVE {:.3} MB",
            rate / 1e6,
            rate / 1e6 / n as f64,
            bytes as f64 / 1e6
        );
        if let Some(&RvesAlone { wall: alone, busy }) = alone_best.get(&n) {
            granite_core::outln!(
                "           the same RVEs stepped alone (no MPM)  {alone:>7.3} s  {:>6.2} M sphere-steps/s: the coupled run does {:.1} % of that",
                sphere_steps / alone / 1e6,
                100.0 * alone / secs
            );
            // Where a second thread's time goes: waiting for work (the code's share of a
            // speed-up short of the thread count), or the same work running slower (the machine's).
            if let (true, Some(one)) = (n > 1, alone_best.get(&1)) {
                granite_core::outln!(
                    "           in that run the threads were inside RVE steps {:.1} % of the time, and the same RVE steps took {:.2}x their time on 1 thread",
                    100.0 * busy / (alone * n as f64),
                    busy / one.busy
                );
            }
        }
    }
    let mut big = periodic_rve(1000, 1e5)?;
    // As the dem_rve law holds its RVEs: stepped sequentially, without the parallel gather's lists.
    big.set_sequential(true);
    granite_core::outln!("memory of a 1000-sphere RVE: {:.3} MB", big.memory_bytes() as f64 / 1e6);
    Ok(())
}

/// `granite bench triaxial`: benchmark (a) of the coupling issue, the one-cell triaxial of thesis
/// 4.4.1 run by the scripts themselves: 8 material points, each with a copy of the RVE that
/// `scripts/mpmxdem/prepare_rve.rhai` makes with its defaults (1000 spheres), at the scripts'
/// I_n = 1e-2, to `axial_strain`. Run from the repository root (it reads `scripts/`).
pub fn triaxial(threads: &[usize], axial_strain: f64) -> Result<()> {
    let scripts = std::path::Path::new("scripts/mpmxdem");
    if !scripts.is_dir() {
        return Err(granite_core::GraniteError::Other(
            "granite bench triaxial runs scripts/mpmxdem/*.rhai: start it from the repository root".into(),
        ));
    }
    let root = std::path::PathBuf::from("out/bench_triaxial");
    granite_core::outln!(
        "granite bench triaxial: one MPM cell, 8 points x RVE of prepare_rve defaults, to {:.1} % axial strain",
        100.0 * axial_strain
    );
    let t = Instant::now();
    let prepared = crate::run(&scripts.join("prepare_rve.rhai"), vec![], Some(root.join("rve")), true, None)?;
    let rve =
        prepared.summary.get("file").and_then(|v| v.as_str()).map(std::path::PathBuf::from).ok_or_else(|| {
            granite_core::GraniteError::Other("prepare_rve.rhai did not report its saved `file`".into())
        })?;
    granite_core::outln!("RVE prepared in {:.1} s: {}", t.elapsed().as_secs_f64(), rve.display());
    let mut base = None;
    for &n in threads {
        let sets = vec![
            ("rve".to_string(), rve.display().to_string()),
            ("axial_strain".to_string(), axial_strain.to_string()),
        ];
        let t = Instant::now();
        let report = crate::run(
            &scripts.join("triaxial_one_cell.rhai"),
            sets,
            Some(root.join(format!("threads_{n}"))),
            true,
            Some(n),
        )?;
        let secs = t.elapsed().as_secs_f64();
        let number = |key: &str| report.summary.get(key).and_then(|v| v.as_f64()).unwrap_or(f64::NAN);
        let rate = number("dem_sphere_steps") / secs;
        let speedup = speedup_over(&mut base, rate);
        granite_core::outln!(
            "threads {n}  wall {secs:>8.1} s  {:>6.2} M sphere-steps/s  {:>6.2} M/s per thread  speed-up {speedup:.2}x  memory per {}-sphere RVE {:.3} MB  final q {:.4e} Pa",
            rate / 1e6,
            rate / 1e6 / n as f64,
            number("rve_particles"),
            number("rve_memory_mb"),
            number("final_q"),
        );
    }
    Ok(())
}

/// Speed-ups of runs giving every thread the same work, `n t1 / tn`, as text to print (none
/// without a 1-thread run to compare with).
fn same_work_per_thread_speedups<T>(timed: &[Timed<T>]) -> Vec<String> {
    let one = timed.iter().find(|t| t.threads == 1).map(|t| t.best);
    timed
        .iter()
        .map(|t| one.map_or(String::new(), |one| format!("  speed-up {:.2}x", t.threads as f64 * one / t.best)))
        .collect()
}

/// `rate` over the first rate measured (which `base` keeps).
fn speedup_over(base: &mut Option<f64>, rate: f64) -> f64 {
    rate / *base.get_or_insert(rate)
}

/// A heap of `count` grains of the JGS resin (thesis table 2.7: K_n 1200 N/m, K_s/K_n 0.773,
/// friction tan^-1 0.713, restitution 0.8, density 943 kg/m^3, dt 7.86e-5 s) poured into a box of
/// plane walls and settled for `settle` steps: as 4-sphere clumps (`tetra`) or as the thesis's
/// rounded tetrahedra (`potential_tetra`), from the same centres and orientations.
pub fn resin_heap(shape: &str, count: usize, settle: usize) -> Result<granite_core::dem::DemSim> {
    use granite_core::dem::kinds::NewBody;
    use granite_core::dem::walls::{Wall, WallShape};
    /// A grain of spheres (a shape model) or a body of a plugin kind.
    enum Grain {
        Clump(Box<dyn granite_core::ext::ShapeModel>),
        Body(std::sync::Arc<dyn granite_core::ext::BodyKindFactory>, std::sync::Arc<dyn granite_core::ext::BodyShape>),
    }
    let reg = crate::registry();
    let grain = match reg.body_kind(shape) {
        Ok(kind) => Grain::Body(kind.clone(), kind.build_from(&ParamMap::new())?),
        Err(_) => Grain::Clump(reg.build_shape(shape, &ParamMap::new())?),
    };
    let mut sim = granite_core::dem::DemSim::new();
    sim.world.seed = 1;
    let resin = sim.world.add_material("resin", 943.0)?;
    let friction = 0.713f64.atan().to_degrees();
    let law = params(&[("kn", 1200.0), ("kt_ratio", 0.773), ("friction", friction), ("restitution", 0.8)]);
    sim.world.set_contact_law(reg.build_contact_law("visco_elastic", &law)?, None)?;
    // Grains on a lattice of 1.1 bounding diameters, 8 across, in a box 10 across.
    let bound = match &grain {
        Grain::Clump(model) => model.bounding_radius(),
        Grain::Body(_, body) => body.bounding_radius(),
    };
    let spacing = 2.2 * bound;
    let across = 8usize;
    let width = (across + 2) as f64 * spacing;
    for (a, upper) in [(0, false), (0, true), (1, false), (1, true), (2, false)] {
        let mut n = [0.0; 3];
        n[a] = if upper { -1.0 } else { 1.0 };
        let position = if upper { [width, width, 0.0] } else { [0.0; 3] };
        sim.world.add_wall(Wall::new("", WallShape::Plane { normal: n }, position, resin));
    }
    sim.skin = 0.2 * bound;
    let template = match &grain {
        Grain::Clump(model) => model.members(),
        Grain::Body(..) => Vec::new(),
    };
    let props = match &grain {
        Grain::Clump(_) => Some(granite_core::dem::clump::mass_properties(&template, 943.0, 400)?),
        Grain::Body(..) => None,
    };
    for k in 0..count {
        let (i, j, l) = (k % across, (k / across) % across, k / (across * across));
        let c = [(1.5 + i as f64) * spacing, (1.5 + j as f64) * spacing, (0.6 + l as f64) * spacing];
        let u = [0, 1, 2].map(|a| granite_core::ext::contact::uniform(7, (3 * k + a) as u64));
        let (members, q) = granite_core::dem::clump::place_template(&template, c, u);
        match (&grain, &props) {
            (Grain::Body(kind, body), _) => {
                let shape = body.clone();
                let v = [0.0; 3];
                let new = NewBody {
                    kind: kind.as_ref(),
                    meetings: &[],
                    shape,
                    material: resin,
                    x: c,
                    q,
                    v,
                    w: v,
                    fixed: false,
                };
                sim.world.add_body(new)?
            }
            (Grain::Clump(_), Some(props)) => sim.world.add_clump_with(resin, &members, &props.transformed(&q, c))?,
            (Grain::Clump(_), None) => unreachable!("a clump's mass properties are computed above"),
        };
    }
    sim.world.gravity = [0.0, 0.0, -9.81];
    sim.world.set_damping(0.3)?;
    sim.world.set_dt(7.86e-5)?;
    for _ in 0..settle {
        sim.step()?;
    }
    Ok(sim)
}

/// Potential particles against 4-sphere clumps on the same settled heap, one thread: time per
/// grain-step (fastest and slowest of `repeat` windows, alternating), and for potential particles
/// the share of detection and of the law with the sums.
pub fn potential(count: usize, steps: usize, repeat: usize) -> Result<()> {
    granite_core::outln!("granite bench potential: a heap of {count} JGS resin grains (thesis table 2.7), settled, then {steps} steps, one thread, best of {repeat}");
    pool(1)?.install(|| -> Result<()> {
        let settle = 6000;
        let heaps = [("4-sphere clumps", resin_heap("tetra", count, settle)?), ("potential particles", resin_heap("potential_tetra", count, settle)?)];
        let mut times = [(f64::INFINITY, 0.0f64); 2];
        let mut split = [0.0; 2];
        for _ in 0..repeat.max(1) {
            for (k, (_, heap)) in heaps.iter().enumerate() {
                let mut sim = heap.clone();
                let before = sim.world.kinds.seconds;
                let t = Instant::now();
                for _ in 0..steps {
                    sim.step()?;
                }
                let secs = t.elapsed().as_secs_f64();
                if secs < times[k].0 {
                    split = if k == 1 { [sim.world.kinds.seconds[0] - before[0], sim.world.kinds.seconds[1] - before[1]] } else { split };
                }
                times[k] = (times[k].0.min(secs), times[k].1.max(secs));
            }
        }
        let per = |secs: f64| secs / (count * steps) as f64 * 1e6;
        for (k, (label, heap)) in heaps.iter().enumerate() {
            let contacts = heap.world.contacts.touching_count();
            granite_core::outln!(
                "{label:<20} {:>7.3} us a grain-step ({:.3})  {} contacts at the start, {:.2} a grain",
                per(times[k].0),
                per(times[k].1),
                contacts,
                contacts as f64 / count as f64
            );
        }
        granite_core::outln!(
            "potential particles: {:.2} times the clumps' time a grain-step (target: at most 5; YADE: about 100, thesis figure 2.8); detection {:.0} %, law and sums {:.0} % of the step",
            times[1].0 / times[0].0,
            100.0 * split[0] / times[1].0,
            100.0 * split[1] / times[1].0
        );
        Ok(())
    })
}

/// A scene of `granite bench mpmxdem --device`: copies of one RVE, each compressed along y in
/// every call as the oedometric scene's RVEs are, a fixed number of DEM steps per call.
struct DeviceScene {
    name: &'static str,
    rve: granite_core::dem::DemSim,
    copies: usize,
    calls: usize,
}

impl DeviceScene {
    fn new(scene: &str) -> Result<DeviceScene> {
        match scene {
            "oedometric" => Ok(DeviceScene { name: "oedometric", rve: bench_rve()?, copies: 16, calls: 40 }),
            // Thesis 5.4: 400 points (0.1 m cells), each a 2000-sphere RVE.
            "column" => {
                let mut rve = periodic_rve(2000, 1e5)?;
                let r_min = rve.world.spheres.smallest_radius();
                rve.set_skin(0.05 * r_min)?;
                Ok(DeviceScene { name: "column", rve, copies: 400, calls: 5 })
            }
            other => Err(granite_core::GraniteError::Setup(format!(
                "unknown scene `{other}` of granite bench mpmxdem --device: oedometric or column"
            ))),
        }
    }

    /// The velocity gradient of one call of `dem_steps` DEM steps (the oedometric scene's strain
    /// per MPM step); perturbed, copy `k` of `copies` is also sheared, each at its own rate.
    fn gradient(&self, dem_steps: u64, perturbed: Option<(usize, usize)>) -> nalgebra::Matrix3<f64> {
        let mut l = nalgebra::Matrix3::zeros();
        let rate = TOP_SPEED / (2.0 * CELL) * MPM_DT / (dem_steps as f64 * self.rve.world.dt);
        l[(1, 1)] = -rate;
        if let Some((k, copies)) = perturbed {
            l[(0, 1)] = 2.0 * rate * k as f64 / copies as f64;
        }
        l
    }
}

/// What `granite bench mpmxdem --device` measures; see [`mpmxdem_on_device`].
pub struct DeviceBench {
    pub device: String,
    pub scene: String,
    pub repeat: usize,
    /// RVEs (the scene's count when None).
    pub copies: Option<usize>,
    /// DEM steps per call, one measurement each (51 when empty).
    pub dem_steps: Vec<u64>,
    /// RVEs that differ: each sheared at its own rate, after its own number of steps.
    pub perturb: bool,
    /// Candidate lists rebuilt before every DEM step, on the device and the CPU alike.
    pub force_rebuild: bool,
    /// Invocations per workgroup on the GPU (chosen from the RVEs' size when None).
    pub workgroup: Option<u32>,
    pub json: Option<std::path::PathBuf>,
    /// Append one markdown table row per measurement to this file (a header first if it is
    /// empty or new).
    pub table: Option<std::path::PathBuf>,
}

/// One measurement of [`mpmxdem_on_device`], as `--json` writes it.
#[derive(serde::Serialize)]
struct DeviceFigures {
    adapter: String,
    scene: String,
    copies: usize,
    spheres_per_rve: usize,
    dem_steps: u64,
    perturb: bool,
    force_rebuild: bool,
    workgroup: Option<u32>,
    sphere_steps_per_s: f64,
    sphere_steps_per_s_slowest: f64,
    cpu_threads: usize,
    cpu_sphere_steps_per_s: f64,
    pair_tests_per_sphere_rebuild: Option<f64>,
    device_bytes_per_rve: f64,
    submissions_per_mpm_step: f64,
    chunks: u64,
    host_ms_per_mpm_step: f64,
    device_ms_per_mpm_step: Option<f64>,
    idle_ms_per_mpm_step: f64,
    thesis_run_hours: f64,
}

/// `granite bench mpmxdem --device gpu [--scene column]`: the same RVEs stepped on the device and
/// on all CPU threads of this machine, rounds interleaved; fastest and slowest of each printed,
/// in sphere-steps per second, with the device's name, what the device counted (distance tests
/// per sphere and search, bytes per RVE, submissions per call, buffer sets) and the projected
/// wall time of the thesis column at this rate.
pub fn mpmxdem_on_device(bench: &DeviceBench) -> Result<()> {
    let scene = DeviceScene::new(&bench.scene)?;
    let copies = bench.copies.unwrap_or(scene.copies);
    let on = device_of(bench)?;
    let steps_list = if bench.dem_steps.is_empty() { vec![DEM_STEPS as u64] } else { bench.dem_steps.clone() };
    let mut figures = Vec::new();
    for &dem_steps in &steps_list {
        figures.push(device_round(&scene, copies, dem_steps, bench, &*on)?);
    }
    if let Some(path) = &bench.table {
        append_table_rows(path, &figures)?;
    }
    if let Some(path) = &bench.json {
        let value = if figures.len() == 1 { serde_json::to_value(&figures[0]) } else { serde_json::to_value(&figures) }
            .map_err(|e| granite_core::GraniteError::Other(e.to_string()))?;
        let text =
            serde_json::to_string_pretty(&value).map_err(|e| granite_core::GraniteError::Other(e.to_string()))?;
        std::fs::write(path, text + "\n")
            .map_err(|e| granite_core::GraniteError::Other(format!("--json {}: {e}", path.display())))?;
    }
    Ok(())
}

/// The device a bench runs on: the registry's by name, or the GPU told to rebuild every step or to
/// use workgroups of a given size.
fn device_of(bench: &DeviceBench) -> Result<std::sync::Arc<dyn granite_core::ext::RveDevice>> {
    if !bench.force_rebuild && bench.workgroup.is_none() {
        return Ok(crate::registry().rve_device(&bench.device)?.clone());
    }
    #[cfg(feature = "gpu")]
    if bench.device == "gpu" {
        let mut gpu = match bench.workgroup {
            Some(size) => crate::gpu::GpuDevice::with_workgroup(size)?,
            None => crate::gpu::GpuDevice::new(),
        };
        if bench.force_rebuild {
            gpu = gpu.forcing_rebuilds();
        }
        return Ok(std::sync::Arc::new(gpu));
    }
    Err(granite_core::GraniteError::Setup(format!(
        "--force-rebuild, --workgroup: the device \"{}\" takes neither (device \"gpu\" of a build with --features gpu does)",
        bench.device
    )))
}

/// The RVEs of a device round, each after its warm-up call, with the orders of a timed call.
fn device_rves(
    scene: &DeviceScene,
    copies: usize,
    dem_steps: u64,
    perturb: bool,
) -> (Vec<granite_core::ext::RveOrder>, Vec<granite_core::ext::RveOrder>) {
    use granite_core::ext::RveOrder;
    let perturbed = |k: usize| perturb.then_some((k, copies));
    let orders: Vec<RveOrder> = (0..copies)
        .map(|k| RveOrder {
            velocity_gradient: scene.gradient(dem_steps, perturbed(k)),
            full_steps: dem_steps,
            last_step: 0.0,
        })
        .collect();
    // Perturbed, the copies' warm-up calls differ in length: their rebuilds fall out of step.
    let warm_up = orders
        .iter()
        .enumerate()
        .map(|(k, o)| RveOrder { full_steps: if perturb { 1 + (37 * k as u64) % 101 } else { dem_steps }, ..*o })
        .collect();
    (warm_up, orders)
}

/// One DEM-steps value of [`mpmxdem_on_device`]: `bench.repeat` interleaved rounds of the
/// device and the CPU threads on the same RVEs and orders.
fn device_round(
    scene: &DeviceScene,
    copies: usize,
    dem_steps: u64,
    bench: &DeviceBench,
    on: &dyn granite_core::ext::RveDevice,
) -> Result<DeviceFigures> {
    use granite_core::dem::Rve;
    use granite_core::ext::RveOrder;
    use rayon::prelude::*;
    let threads = rayon::current_num_threads();
    let rve = Rve::prepare(scene.rve.clone(), "granite bench mpmxdem")?;
    let (warm_up, orders) = device_rves(scene, copies, dem_steps, bench.perturb);
    let idle: Vec<RveOrder> = orders.iter().map(|o| RveOrder { full_steps: 0, ..*o }).collect();
    let mut adapter = String::new();
    let (mut device_times, mut cpu_times, mut idle_times) = (Vec::new(), Vec::new(), Vec::new());
    let mut counted = (granite_core::ext::BatchCounters::default(), granite_core::ext::BatchCounters::default());
    let failed = |reports: Vec<granite_core::ext::RveReport>| match reports.into_iter().find_map(|r| r.failure) {
        Some(failure) => Err(granite_core::GraniteError::Other(format!("an RVE failed on the device: {failure}"))),
        None => Ok(()),
    };
    for _ in 0..bench.repeat {
        let mut batch = on.open(vec![rve.clone(); copies])?;
        adapter = batch.device_name();
        // The warm-up call uploads the RVEs: not timed.
        failed(batch.step(&warm_up)?)?;
        let before = batch.counters();
        let t = Instant::now();
        for _ in 0..scene.calls {
            failed(batch.step(&orders)?)?;
        }
        let took = t.elapsed().as_secs_f64();
        // The counts (and the device's own time) of the fastest round, as its host time is.
        if device_times.iter().all(|&d| took < d) {
            counted = (before, batch.counters());
        }
        device_times.push(took);
        // The same calls without DEM steps: submission, the orders and reports across, the
        // stress sums (what a call costs besides its steps).
        let t = Instant::now();
        for _ in 0..scene.calls {
            batch.step(&idle)?;
        }
        idle_times.push(t.elapsed().as_secs_f64());
        drop(batch);
        // The CPU threads carry out the same orders as dem_rve does (steps, then the response).
        let mut rves: Vec<Rve> = vec![rve.clone(); copies];
        rves.par_iter_mut().zip(&warm_up).try_for_each(|(rve, o)| cpu_call(rve, o, bench.force_rebuild))?;
        let t = Instant::now();
        for _ in 0..scene.calls {
            rves.par_iter_mut().zip(&orders).try_for_each(|(rve, o)| cpu_call(rve, o, bench.force_rebuild))?;
        }
        cpu_times.push(t.elapsed().as_secs_f64());
    }
    let work = (copies * rve.sphere_count() * scene.calls) as f64 * dem_steps as f64;
    let fastest = |t: &[f64]| t.iter().cloned().fold(f64::INFINITY, f64::min);
    let slowest = |t: &[f64]| t.iter().cloned().fold(0.0, f64::max);
    let (g, c, idle_call) = (fastest(&device_times), fastest(&cpu_times), fastest(&idle_times) / scene.calls as f64);
    let (before, after) = counted;
    let calls = (after.calls - before.calls).max(1) as f64;
    let searches = after.sphere_searches - before.sphere_searches;
    let device_seconds = after.device_seconds.map(|a| a - before.device_seconds.unwrap_or(0.0));
    // Thesis 5.4 at its size: 3.5 s at dt 1.46e-6 s (2.40 M MPM steps), 400 RVEs of 2000 spheres.
    let rate = work / (g - idle_call * scene.calls as f64).max(f64::MIN_POSITIVE);
    let thesis_hours = 3.5 / 1.46e-6 * (idle_call + 400.0 * 2000.0 * dem_steps as f64 / rate) / 3600.0;
    let figures = DeviceFigures {
        adapter,
        scene: scene.name.into(),
        copies,
        spheres_per_rve: rve.sphere_count(),
        dem_steps,
        perturb: bench.perturb,
        force_rebuild: bench.force_rebuild,
        workgroup: bench.workgroup,
        sphere_steps_per_s: work / g,
        sphere_steps_per_s_slowest: work / slowest(&device_times),
        cpu_threads: threads,
        cpu_sphere_steps_per_s: work / c,
        pair_tests_per_sphere_rebuild: (searches > 0)
            .then(|| (after.pair_tests - before.pair_tests) as f64 / searches as f64),
        device_bytes_per_rve: after.device_bytes as f64 / copies as f64,
        submissions_per_mpm_step: (after.submissions - before.submissions) as f64 / calls,
        chunks: after.chunks,
        host_ms_per_mpm_step: 1e3 * g / scene.calls as f64,
        device_ms_per_mpm_step: device_seconds.map(|s| 1e3 * s / calls),
        idle_ms_per_mpm_step: 1e3 * idle_call,
        thesis_run_hours: thesis_hours,
    };
    print_device_figures(&figures, work, slowest(&cpu_times));
    Ok(figures)
}

/// One call of `order` on the CPU, as `dem_rve` makes it; with `force_rebuild`, the candidate
/// lists rebuilt before every step as the device is told to.
fn cpu_call(rve: &mut granite_core::dem::Rve, order: &granite_core::ext::RveOrder, force_rebuild: bool) -> Result<()> {
    if force_rebuild {
        rve.deform_rebuilding_every_step(order)?;
    } else {
        rve.deform(order)?;
    }
    Ok(())
}

fn print_device_figures(f: &DeviceFigures, work: f64, cpu_slowest: f64) {
    granite_core::outln!(
        "granite bench mpmxdem --device --scene {}: {} RVEs x {} spheres{}{}, {} DEM steps a call ({work:.3e} sphere-steps a round)",
        f.scene,
        f.copies,
        f.spheres_per_rve,
        if f.perturb { ", perturbed" } else { "" },
        if f.force_rebuild { ", lists rebuilt every step" } else { "" },
        f.dem_steps
    );
    granite_core::outln!(
        "device  {}: {:.4e} sphere-steps/s (slowest {:.4e}); {:.3} ms a call on the host{}",
        f.adapter,
        f.sphere_steps_per_s,
        f.sphere_steps_per_s_slowest,
        f.host_ms_per_mpm_step,
        f.device_ms_per_mpm_step.map(|d| format!(", {d:.3} ms on the device")).unwrap_or_default()
    );
    granite_core::outln!(
        "cpu     {} threads: {:.4e} sphere-steps/s (slowest {:.4e}); device over all CPU threads: {:.2}x",
        f.cpu_threads,
        f.cpu_sphere_steps_per_s,
        work / cpu_slowest,
        f.sphere_steps_per_s / f.cpu_sphere_steps_per_s
    );
    granite_core::outln!(
        "device  distance tests per sphere and search: {}; {:.3} MB per RVE in {} buffer set(s); {:.2} submissions a call; {:.3} ms a call without steps",
        f.pair_tests_per_sphere_rebuild.map(|t| format!("{t:.1}")).unwrap_or_else(|| "no search".into()),
        f.device_bytes_per_rve / 1e6,
        f.chunks,
        f.submissions_per_mpm_step,
        f.idle_ms_per_mpm_step
    );
    granite_core::outln!(
        "the thesis column (2.40e6 MPM steps, 400 x 2000-sphere RVEs, {} DEM steps each) at this rate and call cost: {:.1} h",
        f.dem_steps,
        f.thesis_run_hours
    );
}

/// The columns of `--table`: what `scripts/bench/gpu_check.sh` collects into one table.
const TABLE_HEADER: &str = "| scene | RVEs x spheres | DEM steps | perturbed | rebuilt every step | workgroup | device sphere-steps/s | CPU sphere-steps/s (threads) | device/CPU | ms a call (host / device) | tests per sphere and search | MB per RVE | buffer sets | submissions a call | thesis run (h) |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";

fn append_table_rows(path: &std::path::Path, figures: &[DeviceFigures]) -> Result<()> {
    use std::io::Write;
    let fresh = std::fs::metadata(path).map(|m| m.len() == 0).unwrap_or(true);
    let mut text = String::new();
    if fresh {
        text += TABLE_HEADER;
    }
    for f in figures {
        text += &format!(
            "| {} | {} x {} | {} | {} | {} | {} | {:.3e} | {:.3e} ({}) | {:.2} | {:.2} / {} | {} | {:.2} | {} | {:.2} | {:.1} |\n",
            f.scene,
            f.copies,
            f.spheres_per_rve,
            f.dem_steps,
            if f.perturb { "yes" } else { "no" },
            if f.force_rebuild { "yes" } else { "no" },
            f.workgroup.map(|w| w.to_string()).unwrap_or_else(|| "chosen".into()),
            f.sphere_steps_per_s,
            f.cpu_sphere_steps_per_s,
            f.cpu_threads,
            f.sphere_steps_per_s / f.cpu_sphere_steps_per_s,
            f.host_ms_per_mpm_step,
            f.device_ms_per_mpm_step.map(|d| format!("{d:.2}")).unwrap_or_else(|| "-".into()),
            f.pair_tests_per_sphere_rebuild.map(|t| format!("{t:.0}")).unwrap_or_else(|| "-".into()),
            f.device_bytes_per_rve / 1e6,
            f.chunks,
            f.submissions_per_mpm_step,
            f.thesis_run_hours
        );
    }
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map_err(|e| granite_core::GraniteError::Other(format!("--table {}: {e}", path.display())))?;
    file.write_all(text.as_bytes())
        .map_err(|e| granite_core::GraniteError::Other(format!("--table {}: {e}", path.display())))
}

/// `granite bench adapter`: the GPU adapter the RVEs would run on, its driver and the limits that
/// shape a batch.
pub fn adapter() -> Result<()> {
    #[cfg(feature = "gpu")]
    {
        for (name, value) in crate::gpu::GpuDevice::new().adapter_facts()? {
            granite_core::outln!("{name}: {value}");
        }
        Ok(())
    }
    #[cfg(not(feature = "gpu"))]
    Err(granite_core::GraniteError::Setup(
        "granite bench adapter: this build has no GPU device (cargo build --release --features gpu)".into(),
    ))
}
