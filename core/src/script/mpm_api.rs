//! The `mpm(...)` simulation object of scripts and its methods.

use super::convert::{
    counts, err, get, integer, number, numbers, only_keys, param_map, string, vector, OrRhai, RhaiResult,
};
use super::output::{Output, Runout};
use super::ScriptContext;
use crate::error::GraniteError;
use crate::math::{Vec3, Voigt};
use crate::mpm::boundary::{Face, FrictionConstraint, NodalForce, TimeFunction, VelocityConstraint};
use crate::mpm::fill::{cell_points, Layout};
use crate::mpm::sim::Snapshot;
use crate::mpm::{Boundary, Mesh, MpmSim, OutOfMeshPolicy, StressScheme};
use crate::registry::ParamMap;
use rhai::{Array, Dynamic, Engine, FnPtr, Map, NativeCallContext};
use std::io::IsTerminal;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// A script's handle on one simulation (shared: closures and callbacks may hold it too).
#[derive(Clone)]
pub struct SimHandle(Arc<Mutex<SimState>>);

/// A material created by `sim.material(...)`.
#[derive(Clone)]
pub struct MaterialHandle {
    index: usize,
    name: String,
}

pub struct SimState {
    pub sim: MpmSim,
    ctx: Arc<ScriptContext>,
    output: Output,
    callbacks: Vec<(u64, FnPtr)>,
    /// Boundary values set by a script function of time once per step.
    driven: Vec<(Driven, FnPtr)>,
    runout: Option<Runout>,
    last_good: Option<Snapshot>,
}

#[derive(Clone, Copy)]
enum Driven {
    Velocity(usize),
    Force(usize),
}

impl SimHandle {
    pub fn lock(&self) -> MutexGuard<'_, SimState> {
        self.0.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The engine state, e.g. for tests or tools that inspect a finished script's simulation.
    pub fn with_sim<R>(&self, f: impl FnOnce(&MpmSim) -> R) -> R {
        f(&self.lock().sim)
    }
}

const MESH_KEYS: &[&str] = &["dim", "origin", "cell", "cells"];

fn parse_mesh(opts: &Map, dim_hint: Option<usize>) -> RhaiResult<Mesh> {
    only_keys(opts, MESH_KEYS, "mesh options")?;
    let dim = match (get(opts, "dim"), dim_hint) {
        (Some(d), _) => integer(d, "dim")? as usize,
        (None, Some(d)) => d,
        (None, None) => return err("mpm(#{...}) needs `dim` (2 for plane strain, 3)"),
    };
    if dim != 2 && dim != 3 {
        return err(format!("`dim` must be 2 or 3, got {dim}"));
    }
    let origin = match get(opts, "origin") {
        Some(o) => vector(o, dim, "origin")?,
        None => [0.0; 3],
    };
    let cell = match get(opts, "cell") {
        None => return err("mesh needs `cell` (cell size in m, a number or one per axis)"),
        Some(c) if c.is_array() => vector(c, dim, "cell")?,
        Some(c) => {
            let h = number(c, "cell")?;
            [h, h, h]
        }
    };
    let cells = match get(opts, "cells") {
        Some(c) => counts(c, dim, "cells")?,
        None => return err("mesh needs `cells` (cells along each axis)"),
    };
    Mesh::new(dim, origin, cell, cells).or_rhai()
}

fn axis_index(name: &str, dim: usize) -> RhaiResult<usize> {
    match name {
        "x" => Ok(0),
        "y" => Ok(1),
        "z" if dim == 3 => Ok(2),
        _ => err(format!("axis `{name}` must be one of {}", if dim == 3 { "x, y, z" } else { "x, y" })),
    }
}

fn position_array(x: Vec3, dim: usize) -> Array {
    x[..dim].iter().map(|&v| Dynamic::from(v)).collect()
}

fn stress_arg(d: &Dynamic) -> RhaiResult<Voigt> {
    let v = numbers(d, "stress")?;
    if v.len() != 6 {
        return err(format!(
            "`stress` must have 6 components (xx, yy, zz, xy, yz, xz; tension positive), got {}",
            v.len()
        ));
    }
    Ok([v[0], v[1], v[2], v[3], v[4], v[5]])
}

impl SimHandle {
    fn new(ctx: Arc<ScriptContext>, opts: Map) -> RhaiResult<SimHandle> {
        let mut opts = opts;
        let update = opts.remove("velocity_update").map(|d| string(&d, "velocity_update")).transpose()?;
        let mesh = parse_mesh(&opts, None)?;
        let strategy =
            ctx.registry.build_velocity_update(update.as_deref().unwrap_or("FLIP"), &ParamMap::new()).or_rhai()?;
        let index = ctx.next_sim_index();
        let prefix = if index == 1 { String::new() } else { format!("sim{index}_") };
        let output = Output::new(ctx.options.out_dir.clone(), prefix);
        Ok(SimHandle(Arc::new(Mutex::new(SimState {
            sim: MpmSim::new(mesh, strategy),
            ctx,
            output,
            callbacks: Vec::new(),
            driven: Vec::new(),
            runout: None,
            last_good: None,
        }))))
    }

    fn material(&mut self, law: &str, opts: Map) -> RhaiResult<MaterialHandle> {
        let mut st = self.lock();
        let density = match get(&opts, "density") {
            Some(d) => number(d, "density")?,
            None => return err(format!("material \"{law}\" needs `density` (kg/m^3)")),
        };
        let name = match get(&opts, "name") {
            Some(n) => string(n, "name")?,
            None => format!("{law}_{}", st.sim.materials.len() + 1),
        };
        let params = param_map(&opts, &["density", "name"], law)?;
        let law_obj = st.ctx.registry.build_law(law, &params).or_rhai()?;
        let index = st.sim.add_material(&name, density, law_obj).or_rhai()?;
        Ok(MaterialHandle { index, name })
    }

    fn fill(
        &mut self,
        ctx: Option<&NativeCallContext>,
        mat: &MaterialHandle,
        region: Region,
        opts: Map,
    ) -> RhaiResult<i64> {
        only_keys(&opts, &["per_cell", "layout", "velocity", "stress"], "fill options")?;
        let mut st = self.lock();
        let dim = st.sim.dim();
        let per_dir = match get(&opts, "per_cell") {
            Some(n) => integer(n, "per_cell")?,
            None => 2,
        };
        if !(1..=20).contains(&per_dir) {
            return err(format!("`per_cell` (points per cell direction) must be in [1, 20], got {per_dir}"));
        }
        let layout = match get(&opts, "layout") {
            Some(l) => Layout::parse(&string(l, "layout")?).or_rhai()?,
            None => Layout::Gauss,
        };
        let v = match get(&opts, "velocity") {
            Some(v) => vector(v, dim, "velocity")?,
            None => [0.0; 3],
        };
        let stress = match get(&opts, "stress") {
            Some(s) => stress_arg(s)?,
            None => [0.0; 6],
        };
        let mesh = st.sim.mesh.clone();
        let mut script_error = None;
        let (xs, vols) = cell_points(&mesh, layout, per_dir as usize, |x| match &region {
            Region::Box(lo, hi) => Ok((0..dim).all(|a| x[a] >= lo[a] && x[a] <= hi[a])),
            Region::Closure(f) => {
                let ctx = ctx.expect("closure regions are called with a context");
                match f.call_within_context::<bool>(ctx, (position_array(x, dim),)) {
                    Ok(b) => Ok(b),
                    Err(e) => {
                        script_error = Some(e);
                        Err(GraniteError::Setup("region closure failed".into()))
                    }
                }
            }
        })
        .map_err(|e| match script_error.take() {
            Some(se) => se,
            None => super::convert::to_rhai(e),
        })?;
        if xs.is_empty() {
            return err("the region holds no material point: check its bounds against the mesh");
        }
        st.sim.add_points(mat.index, &xs, &vols, v, stress).or_rhai()?;
        Ok(xs.len() as i64)
    }

    /// A box region that must lie inside the mesh (a box poking out would silently lose points).
    fn box_region(&self, lo: &Dynamic, hi: &Dynamic) -> RhaiResult<Region> {
        let st = self.lock();
        let dim = st.sim.dim();
        let (lo, hi) = (vector(lo, dim, "lower corner")?, vector(hi, dim, "upper corner")?);
        let (mlo, mhi) = (st.sim.mesh.origin, st.sim.mesh.upper());
        for a in 0..dim {
            if !(lo[a] < hi[a]) {
                return err(format!("box corners must satisfy lower < upper on every axis, got {lo:?} and {hi:?}"));
            }
            let eps = 1e-9 * st.sim.mesh.cell[a];
            if lo[a] < mlo[a] - eps || hi[a] > mhi[a] + eps {
                return err(format!(
                    "box [{:?}, {:?}] extends outside the mesh [{:?}, {:?}]",
                    &lo[..dim],
                    &hi[..dim],
                    &mlo[..dim],
                    &mhi[..dim]
                ));
            }
        }
        Ok(Region::Box(lo, hi))
    }

    fn select_nodes(&self, ctx: &NativeCallContext, selector: &Dynamic) -> RhaiResult<Vec<u32>> {
        let mesh = self.lock().sim.mesh.clone();
        if let Ok(face) = selector.clone().into_string() {
            return Ok(Face::parse(&face, mesh.dim).or_rhai()?.nodes(&mesh));
        }
        if let Some(f) = selector.clone().try_cast::<FnPtr>() {
            let mut nodes = Vec::new();
            for i in 0..mesh.node_count() {
                if f.call_within_context::<bool>(ctx, (position_array(mesh.node_position(i), mesh.dim),))? {
                    nodes.push(i as u32);
                }
            }
            if nodes.is_empty() {
                return err("the node selector matches no node of the mesh");
            }
            return Ok(nodes);
        }
        err(format!(
            "nodes are selected by a face name (\"x-\", \"y+\", ...) or a closure |x| ..., got {}",
            selector.type_name()
        ))
    }

    fn time_function(value: &Dynamic, name: &str) -> RhaiResult<(TimeFunction, Option<FnPtr>)> {
        if let Some(f) = value.clone().try_cast::<FnPtr>() {
            return Ok((TimeFunction::Driven(0.0), Some(f)));
        }
        if value.is_array() {
            let rows = value.clone().into_array().unwrap_or_default();
            let mut table = Vec::new();
            for r in &rows {
                let pair = numbers(r, name)?;
                if pair.len() != 2 {
                    return err(format!("`{name}` table rows must be [time, value]"));
                }
                table.push((pair[0], pair[1]));
            }
            return Ok((TimeFunction::table(table).or_rhai()?, None));
        }
        Ok((TimeFunction::Constant(number(value, name)?), None))
    }

    fn fix(&mut self, ctx: &NativeCallContext, selector: Dynamic, axis: &str, value: Dynamic) -> RhaiResult<()> {
        let nodes = self.select_nodes(ctx, &selector)?;
        let (f, driver) = Self::time_function(&value, "velocity")?;
        let mut st = self.lock();
        let axis = axis_index(axis, st.sim.dim())?;
        st.sim.boundary.velocity.push(VelocityConstraint { nodes, axis, value: f });
        let idx = st.sim.boundary.velocity.len() - 1;
        if let Some(fp) = driver {
            st.driven.push((Driven::Velocity(idx), fp));
        }
        Ok(())
    }

    fn friction(&mut self, face: &str, mu: Dynamic) -> RhaiResult<()> {
        let mu = number(&mu, "mu")?;
        if !(mu >= 0.0) {
            return err(format!("friction coefficient `mu` must be >= 0, got {mu}"));
        }
        let mut st = self.lock();
        let face = Face::parse(face, st.sim.dim()).or_rhai()?;
        let nodes = face.nodes(&st.sim.mesh);
        st.sim.boundary.friction.push(FrictionConstraint { nodes, axis: face.axis, sign: face.outward_sign(), mu });
        Ok(())
    }

    fn add_force(&mut self, nodes: Vec<u32>, force: Vec<Vec3>, factor: Dynamic) -> RhaiResult<()> {
        let (f, driver) = Self::time_function(&factor, "factor")?;
        let mut st = self.lock();
        st.sim.boundary.forces.push(NodalForce { nodes, force, factor: f });
        let idx = st.sim.boundary.forces.len() - 1;
        if let Some(fp) = driver {
            st.driven.push((Driven::Force(idx), fp));
        }
        Ok(())
    }

    fn traction(&mut self, face: &str, t: Dynamic, factor: Dynamic) -> RhaiResult<()> {
        let (nodes, forces) = {
            let st = self.lock();
            let dim = st.sim.dim();
            let face = Face::parse(face, dim).or_rhai()?;
            Boundary::traction_on_face(&st.sim.mesh, face, vector(&t, dim, "traction")?)
        };
        self.add_force(nodes, forces, factor)
    }

    fn nodal_force(
        &mut self,
        ctx: &NativeCallContext,
        selector: Dynamic,
        f: Dynamic,
        factor: Dynamic,
    ) -> RhaiResult<()> {
        let nodes = self.select_nodes(ctx, &selector)?;
        let dim = self.lock().sim.dim();
        let f = vector(&f, dim, "force")?;
        let forces = vec![f; nodes.len()];
        self.add_force(nodes, forces, factor)
    }

    /// Geostatic stress: `sigma_v = -rho |g| (surface - height)`, horizontal `K0 sigma_v`.
    fn geostatic(&mut self, surface: Dynamic, k0: Dynamic) -> RhaiResult<()> {
        let (surface, k0) = (number(&surface, "surface")?, number(&k0, "k0")?);
        if !(k0 >= 0.0) {
            return err(format!("`k0` must be >= 0, got {k0}"));
        }
        let mut st = self.lock();
        let g = crate::math::norm3(st.sim.gravity);
        if g == 0.0 {
            return err("geostatic_stress needs gravity: call gravity([...]) first");
        }
        let up = st.sim.dim() - 1;
        let densities: Vec<f64> = st.sim.materials.iter().map(|m| m.density).collect();
        let pts = &mut st.sim.points;
        for i in 0..pts.len() {
            let depth = (surface - pts.x[i][up]).max(0.0);
            let sv = -densities[pts.material[i] as usize] * g * depth;
            let mut s = [k0 * sv, k0 * sv, k0 * sv, 0.0, 0.0, 0.0];
            s[up] = sv;
            pts.stress[i] = s;
        }
        Ok(())
    }

    fn run(&mut self, ctx: &NativeCallContext, steps: u64) -> RhaiResult<()> {
        let quiet;
        {
            let mut st = self.lock();
            st.ctx.check_overrides()?;
            st.sim.validate().or_rhai()?;
            quiet = st.ctx.options.quiet;
            let series_every = st.output.series_every.unwrap_or((steps / 500).max(1));
            let vtk_every = st.output.vtk_every.unwrap_or((steps / 20).max(1));
            st.output.series_every.get_or_insert(series_every);
            st.output.vtk_every.get_or_insert(vtk_every);
            let st = &mut *st;
            st.output.write_series(&st.sim, st.runout.as_ref()).or_rhai()?;
            st.output.write_vtk(&st.sim).or_rhai()?;
            st.last_good = Some(st.sim.snapshot());
        }
        let progress = Progress::new(quiet, steps);
        for k in 0..steps {
            let (t, driven) = {
                let st = self.lock();
                (st.sim.time, st.driven.clone())
            };
            let mut values = Vec::with_capacity(driven.len());
            for (_, f) in &driven {
                values.push(
                    f.call_within_context::<Dynamic>(ctx, (t,)).and_then(|d| number(&d, "boundary function value"))?,
                );
            }
            let due: Vec<FnPtr> = {
                let mut guard = self.lock();
                let st = &mut *guard;
                for ((which, _), v) in driven.iter().zip(values) {
                    match *which {
                        Driven::Velocity(i) => st.sim.boundary.velocity[i].value = TimeFunction::Driven(v),
                        Driven::Force(i) => st.sim.boundary.forces[i].factor = TimeFunction::Driven(v),
                    }
                }
                if let Err(e) = st.sim.step() {
                    return Err(st.fail(e));
                }
                for ev in st.sim.events.drain(..) {
                    if !quiet {
                        eprintln!("granite: {ev}");
                    }
                }
                let step = st.sim.step;
                let last = k + 1 == steps;
                if step.is_multiple_of(st.output.series_every.unwrap_or(1)) || last {
                    st.output.write_series(&st.sim, st.runout.as_ref()).or_rhai()?;
                    st.last_good = Some(st.sim.snapshot());
                }
                if step.is_multiple_of(st.output.vtk_every.unwrap_or(1)) || last {
                    st.output.write_vtk(&st.sim).or_rhai()?;
                }
                progress.tick(k + 1, st.sim.time);
                st.callbacks.iter().filter(|(n, _)| step.is_multiple_of(*n)).map(|(_, f)| f.clone()).collect()
            };
            for f in due {
                let _ = f.call_within_context::<Dynamic>(ctx, (self.clone(),))?;
            }
        }
        progress.finish();
        Ok(())
    }

    fn run_until(&mut self, ctx: &NativeCallContext, t_end: Dynamic) -> RhaiResult<()> {
        let t_end = number(&t_end, "time")?;
        let steps = {
            let st = self.lock();
            st.sim.validate().or_rhai()?;
            let remaining = t_end - st.sim.time;
            if remaining <= 0.0 {
                return Ok(());
            }
            (remaining / st.sim.dt - 1e-9).ceil() as u64
        };
        self.run(ctx, steps)
    }
}

impl SimState {
    /// Restores the last good state, writes it out, and turns the failure into a script error.
    fn fail(&mut self, e: GraniteError) -> Box<rhai::EvalAltResult> {
        let failed_step = self.sim.step;
        let mut msg = e.to_string();
        if let Some(snap) = self.last_good.take() {
            self.sim.restore(snap);
            self.output.last_vtk_step = None;
            let written = self
                .output
                .write_vtk(&self.sim)
                .and_then(|_| self.output.write_points(&self.sim, "last_good_points.csv"));
            msg = match written {
                Ok(path) => format!(
                    "{msg}\nthe last good state (step {}, t = {:.6e} s) is kept and written to {} and vtk/",
                    self.sim.step,
                    self.sim.time,
                    path.display()
                ),
                Err(w) => format!("{msg}\n(could not write the last good state: {w})"),
            };
        }
        self.ctx.set_summary("failed_at_step", serde_json::Value::from(failed_step));
        super::convert::to_rhai(GraniteError::Other(msg))
    }
}

enum Region {
    Box(Vec3, Vec3),
    Closure(FnPtr),
}

/// Periodic progress on stderr: a rewritten line on a terminal, a plain line every 10 s otherwise.
struct Progress {
    enabled: bool,
    terminal: bool,
    total: u64,
    start: Instant,
    last: std::cell::Cell<Instant>,
}

impl Progress {
    fn new(quiet: bool, total: u64) -> Progress {
        let now = Instant::now();
        Progress {
            enabled: !quiet,
            terminal: std::io::stderr().is_terminal(),
            total,
            start: now,
            last: std::cell::Cell::new(now),
        }
    }

    fn tick(&self, done: u64, time: f64) {
        if !self.enabled {
            return;
        }
        let every = if self.terminal { Duration::from_millis(500) } else { Duration::from_secs(10) };
        if self.last.get().elapsed() < every {
            return;
        }
        self.last.set(Instant::now());
        let elapsed = self.start.elapsed().as_secs_f64();
        let rate = done as f64 / elapsed.max(1e-9);
        let eta = (self.total - done) as f64 / rate.max(1e-9);
        let line = format!(
            "step {done}/{} ({:.0}%)  t = {time:.4e} s  {rate:.0} steps/s  ETA {eta:.0} s",
            self.total,
            100.0 * done as f64 / self.total as f64
        );
        if self.terminal {
            eprint!("\r{line}   ");
        } else {
            eprintln!("{line}");
        }
    }

    fn finish(&self) {
        if self.enabled && self.terminal && self.start.elapsed() > Duration::from_millis(500) {
            eprintln!();
        }
    }
}

fn diag_map(st: &SimState) -> Map {
    let d = st.sim.diagnostics();
    let mut m = Map::new();
    let mut put = |k: &str, v: f64| {
        m.insert(k.into(), Dynamic::from(v));
    };
    put("time", st.sim.time);
    put("step", st.sim.step as f64);
    put("points", d.points as f64);
    put("mass", d.mass);
    put("kinetic_energy", d.kinetic_energy);
    put("elastic_energy", d.elastic_energy);
    put("gravitational_energy", d.gravitational_energy);
    put("total_energy", d.total_energy());
    put("max_height", d.max_height);
    put("max_x", d.max_x);
    put("max_deviatoric_strain", d.max_deviatoric_strain);
    put("deleted_points", st.sim.deleted_points as f64);
    if let Some(r) = &st.runout {
        let (lx, dr, ln, tn) = r.measure(&st.sim);
        put("lx", lx);
        put("runout", dr);
        put("runout_normalised", ln);
        put("time_normalised", tn);
    }
    m
}

pub(super) fn register(engine: &mut Engine, ctx: &Arc<ScriptContext>) {
    engine.register_type_with_name::<SimHandle>("MpmSim");
    engine.register_type_with_name::<MaterialHandle>("Material");
    engine.register_get("name", |m: &mut MaterialHandle| m.name.clone());
    let c = ctx.clone();
    engine.register_fn("mpm", move |opts: Map| SimHandle::new(c.clone(), opts));

    engine.register_fn("material", |s: &mut SimHandle, law: &str, opts: Map| s.material(law, opts));
    engine.register_fn("fill_box", |s: &mut SimHandle, m: MaterialHandle, lo: Dynamic, hi: Dynamic, opts: Map| {
        let region = s.box_region(&lo, &hi)?;
        s.fill(None, &m, region, opts)
    });
    engine.register_fn("fill_box", |s: &mut SimHandle, m: MaterialHandle, lo: Dynamic, hi: Dynamic| {
        let region = s.box_region(&lo, &hi)?;
        s.fill(None, &m, region, Map::new())
    });
    engine.register_fn("add_points", |s: &mut SimHandle, m: MaterialHandle, positions: Array, volume: Dynamic| {
        let volume = number(&volume, "volume")?;
        let mut st = s.lock();
        let dim = st.sim.dim();
        let xs = positions.iter().map(|p| vector(p, dim, "position")).collect::<RhaiResult<Vec<_>>>()?;
        let vols = vec![volume; xs.len()];
        st.sim.add_points(m.index, &xs, &vols, [0.0; 3], [0.0; 6]).or_rhai()
    });
    engine.register_fn(
        "fill_region",
        |ctx: NativeCallContext, s: &mut SimHandle, m: MaterialHandle, f: FnPtr, opts: Map| {
            s.fill(Some(&ctx), &m, Region::Closure(f), opts)
        },
    );
    engine.register_fn("gravity", |s: &mut SimHandle, g: Dynamic| {
        let mut st = s.lock();
        let dim = st.sim.dim();
        st.sim.gravity = vector(&g, dim, "gravity")?;
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("damping", |s: &mut SimHandle, d: Dynamic| {
        let d = number(&d, "damping")?;
        if !(0.0..1.0).contains(&d) {
            return err(format!("Cundall damping D must be in [0, 1), got {d}"));
        }
        s.lock().sim.damping = d;
        Ok(())
    });
    engine.register_fn("scheme", |s: &mut SimHandle, name: &str| {
        s.lock().sim.scheme = StressScheme::parse(name).or_rhai()?;
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    fn set_update(s: &mut SimHandle, name: &str, opts: Map) -> RhaiResult<()> {
        let mut st = s.lock();
        let params = param_map(&opts, &[], name)?;
        st.sim.velocity_update = st.ctx.registry.build_velocity_update(name, &params).or_rhai()?;
        Ok(())
    }
    engine.register_fn("velocity_update", set_update);
    engine.register_fn("velocity_update", |s: &mut SimHandle, name: &str| set_update(s, name, Map::new()));
    engine.register_fn("dt", |s: &mut SimHandle, dt: Dynamic| s.lock().sim.set_dt(number(&dt, "dt")?).or_rhai());
    engine.register_fn("critical_dt", |s: &mut SimHandle| s.lock().sim.critical_dt().unwrap_or(f64::INFINITY));
    engine.register_fn("fix", |ctx: NativeCallContext, s: &mut SimHandle, sel: Dynamic, axis: &str, v: Dynamic| {
        s.fix(&ctx, sel, axis, v)
    });
    engine.register_fn("fix", |ctx: NativeCallContext, s: &mut SimHandle, sel: Dynamic, axis: &str| {
        s.fix(&ctx, sel, axis, Dynamic::from(0.0))
    });
    engine.register_fn("friction", |s: &mut SimHandle, face: &str, mu: Dynamic| s.friction(face, mu));
    engine.register_fn("traction", |s: &mut SimHandle, face: &str, t: Dynamic| s.traction(face, t, Dynamic::from(1.0)));
    engine.register_fn("traction", |s: &mut SimHandle, face: &str, t: Dynamic, factor: Dynamic| {
        s.traction(face, t, factor)
    });
    engine.register_fn("nodal_force", |ctx: NativeCallContext, s: &mut SimHandle, sel: Dynamic, f: Dynamic| {
        s.nodal_force(&ctx, sel, f, Dynamic::from(1.0))
    });
    engine.register_fn(
        "nodal_force",
        |ctx: NativeCallContext, s: &mut SimHandle, sel: Dynamic, f: Dynamic, factor: Dynamic| {
            s.nodal_force(&ctx, sel, f, factor)
        },
    );
    engine.register_fn("geostatic_stress", |s: &mut SimHandle, surface: Dynamic, k0: Dynamic| s.geostatic(surface, k0));
    engine.register_fn("initial_stress", |s: &mut SimHandle, stress: Dynamic| {
        let v = stress_arg(&stress)?;
        s.lock().sim.points.stress.iter_mut().for_each(|p| *p = v);
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("mesh", |s: &mut SimHandle, opts: Map| {
        let mut st = s.lock();
        let dim = st.sim.dim();
        let mesh = parse_mesh(&opts, Some(dim))?;
        st.sim.replace_mesh(mesh).or_rhai()?;
        st.driven.clear();
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("on_leave", |s: &mut SimHandle, what: &str| {
        s.lock().sim.out_of_mesh = match what {
            "delete" => OutOfMeshPolicy::Delete,
            "stop" => OutOfMeshPolicy::Stop,
            _ => return err(format!("on_leave takes \"delete\" or \"stop\", got \"{what}\"")),
        };
        Ok(())
    });
    engine.register_fn("series_every", |s: &mut SimHandle, n: i64| {
        if n < 1 {
            return err(format!("series_every needs a step count >= 1, got {n}"));
        }
        s.lock().output.series_every = Some(n as u64);
        Ok(())
    });
    engine.register_fn("vtk_every", |s: &mut SimHandle, n: i64| {
        if n < 1 {
            return err(format!("vtk_every needs a step count >= 1, got {n}"));
        }
        s.lock().output.vtk_every = Some(n as u64);
        Ok(())
    });
    engine.register_fn("track_runout", |s: &mut SimHandle, width: Dynamic, height: Dynamic| {
        let (w, h) = (number(&width, "width")?, number(&height, "height")?);
        if !(w > 0.0 && h > 0.0) {
            return err("track_runout needs the initial column width and height (> 0)");
        }
        let mut st = s.lock();
        let t0 = st.sim.time;
        st.runout = Some(Runout { width0: w, height0: h, t0 });
        Ok(())
    });
    engine.register_fn("every", |s: &mut SimHandle, n: i64, f: FnPtr| {
        if n < 1 {
            return err(format!("every(n, f) needs n >= 1, got {n}"));
        }
        s.lock().callbacks.push((n as u64, f));
        Ok(())
    });
    engine.register_fn("run_until", |ctx: NativeCallContext, s: &mut SimHandle, t: Dynamic| s.run_until(&ctx, t));
    engine.register_fn("run_steps", |ctx: NativeCallContext, s: &mut SimHandle, n: i64| {
        if n < 0 {
            return err(format!("run_steps needs n >= 0, got {n}"));
        }
        s.run(&ctx, n as u64)
    });
    engine.register_fn("diagnostics", |s: &mut SimHandle| diag_map(&s.lock()));
    engine.register_fn("write_points", |s: &mut SimHandle, file: &str| {
        let st = s.lock();
        st.output.write_points(&st.sim, file).map(|p| p.display().to_string()).or_rhai()
    });
    engine.register_fn("write_series", |s: &mut SimHandle| {
        let mut guard = s.lock();
        let st = &mut *guard;
        st.output.write_series(&st.sim, st.runout.as_ref()).or_rhai()
    });
    engine.register_fn("write_vtk", |s: &mut SimHandle| {
        let mut guard = s.lock();
        let st = &mut *guard;
        st.output.write_vtk(&st.sim).or_rhai()
    });
    engine.register_get("time", |s: &mut SimHandle| s.lock().sim.time);
    engine.register_get("step", |s: &mut SimHandle| s.lock().sim.step as i64);
    engine.register_get("points", |s: &mut SimHandle| s.lock().sim.points.len() as i64);
    engine.register_get("dt", |s: &mut SimHandle| s.lock().sim.dt);
    engine.register_fn("point_stress", |s: &mut SimHandle, i: i64| -> RhaiResult<Array> {
        let st = s.lock();
        let n = st.sim.points.len();
        if i < 0 || i as usize >= n {
            return err(format!("point index {i} out of range 0..{n}"));
        }
        Ok(st.sim.points.stress[i as usize].iter().map(|&v| Dynamic::from(v)).collect())
    });
    engine.register_fn("point_position", |s: &mut SimHandle, i: i64| -> RhaiResult<Array> {
        let st = s.lock();
        let n = st.sim.points.len();
        if i < 0 || i as usize >= n {
            return err(format!("point index {i} out of range 0..{n}"));
        }
        Ok(st.sim.points.x[i as usize].iter().map(|&v| Dynamic::from(v)).collect())
    });
}
