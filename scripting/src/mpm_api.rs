//! The `mpm(...)` simulation object of scripts and its methods.

use super::convert::{
    api_options, axis_index, counts, err, finite, get, integer, number, numbers, param_map, string, vector, OrRhai,
    RhaiResult,
};
use super::driver::{register_common, Handle};
use super::ScriptContext;
use granite_core::error::GraniteError;
use granite_core::math::{Vec3, Voigt};
use granite_core::mpm::boundary::{Face, FrictionConstraint, NodalForce, TimeFunction, VelocityConstraint};
use granite_core::mpm::fill::{cell_points, Layout};
use granite_core::mpm::{
    Boundary, Mesh, MpmSim, OutOfMeshPolicy, ShapeFunctions, StressRate, StressScheme, VolumetricStrain,
};
use granite_core::registry::ParamMap;
use granite_run::{Driven, MpmScene, Runout, Simulation};
use rhai::{Array, Dynamic, Engine, FnPtr, Map, NativeCallContext};
use std::sync::Arc;

pub type SimHandle = Handle<MpmScene>;

/// A material created by `sim.material(...)`.
#[derive(Clone)]
pub struct MaterialHandle {
    index: usize,
    name: String,
    /// The simulation that made it (`Handle::serial`).
    sim: u64,
}

impl MaterialHandle {
    pub(super) fn name(&self) -> &str {
        &self.name
    }
    /// Its index in `s`'s materials; an error when it is another simulation's material.
    fn index_in(&self, s: &SimHandle) -> RhaiResult<usize> {
        s.owns(
            self.sim,
            &format!("material \"{}\"", self.name),
            "make one for this simulation with its own material(...)",
        )?;
        Ok(self.index)
    }

    pub(super) fn new(index: usize, name: String, sim: u64) -> MaterialHandle {
        MaterialHandle { index, name, sim }
    }
}

fn parse_mesh(opts: &Map, dim_hint: Option<usize>) -> RhaiResult<Mesh> {
    api_options(opts, "MpmSim", "mesh")?;
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
            let h = finite(c, "cell")?;
            [h, h, h]
        }
    };
    let cells = match get(opts, "cells") {
        Some(c) => counts(c, dim, "cells")?,
        None => return err("mesh needs `cells` (cells along each axis)"),
    };
    Mesh::new(dim, origin, cell, cells).or_rhai()
}

/// A point index from a script, checked.
fn point_index(sim: &MpmSim, i: i64) -> RhaiResult<usize> {
    let n = sim.points.len();
    if i < 0 || i as usize >= n {
        return err(format!("point index {i} out of range 0..{n}"));
    }
    Ok(i as usize)
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

/// A value given as a number, a `[[t, v], ...]` table, or a function of time (driven per step).
pub(super) fn time_function(value: &Dynamic, name: &str) -> RhaiResult<(TimeFunction, Option<FnPtr>)> {
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
    Ok((TimeFunction::Constant(finite(value, name)?), None))
}

/// A law's inputs from the options of `sim.material` or `element_test`: its numbers, and as
/// objects the values that are simulations (a prepared DEM sample for `dem_rve`) and the device
/// a `device` string names ("cpu", the default, is none); `density` and `name` are the
/// material's, not the law's.
pub(super) fn law_inputs(
    opts: &Map,
    law: &str,
    registry: &granite_core::registry::Registry,
) -> RhaiResult<(granite_core::registry::ParamMap, granite_core::ext::constitutive::ObjectMap)> {
    let mut objects = granite_core::ext::constitutive::ObjectMap::new();
    let mut skip = vec!["density", "name"];
    if let Some(device) = get(opts, "device") {
        let name = string(device, "device")?;
        if name != "cpu" {
            let device = registry.rve_device(&name).or_rhai()?.clone();
            objects.insert("device".into(), Arc::new(granite_core::ext::rve::RveDeviceChoice(device)));
        }
        skip.push("device");
    }
    // Switches are numbers to a law (true: 1), and an option given as a map (`adaptive: #{
    // coarsen: 0.01 }`) switches on the option and sets its parameters `adaptive_coarsen`, ...
    let mut numbers = Map::new();
    for (k, v) in opts {
        if let Some(h) = v.clone().try_cast::<super::dem_api::DemHandle>() {
            let dem = h.lock().sim.prepared();
            objects.insert(k.to_string(), Arc::new(dem));
            skip.push(k.as_str());
        } else if let Ok(on) = v.as_bool() {
            numbers.insert(k.clone(), Dynamic::from(if on { 1.0 } else { 0.0 }));
        } else if let Some(sub) = v.clone().try_cast::<Map>() {
            numbers.insert(k.clone(), Dynamic::from(1.0));
            for (s, value) in sub {
                numbers.insert(format!("{k}_{s}").into(), value);
            }
        } else {
            numbers.insert(k.clone(), v.clone());
        }
    }
    Ok((param_map(&numbers, &skip, law)?, objects))
}

pub(super) enum Region {
    Box(Vec3, Vec3),
    Closure(FnPtr),
    /// Inside the surfaces (2D) or volumes (3D) of a mesh group.
    Mesh(granite_core::region::Simplices),
}

impl Handle<MpmScene> {
    /// `MpmSim(2D, 400 points, t = 0.31 s, step 1200, running)`: what printing a simulation shows.
    pub fn describe(&self) -> String {
        let running = if self.running() { "running" } else { "paused" };
        let st = self.lock();
        let m = &st.sim.mpm;
        format!("MpmSim({}D, {} points, t = {:.6} s, step {}, {running})", m.dim(), m.points.len(), m.time, m.step)
    }

    fn create(ctx: Arc<ScriptContext>, opts: Map) -> RhaiResult<SimHandle> {
        ctx.before_simulation()?;
        api_options(&opts, "", "mpm")?;
        let mut opts = opts;
        let update = opts.remove("velocity_update").map(|d| string(&d, "velocity_update")).transpose()?;
        let mesh = parse_mesh(&opts, None)?;
        let strategy =
            ctx.registry().build_velocity_update(update.as_deref().unwrap_or("FLIP"), &ParamMap::new()).or_rhai()?;
        let mut mpm = MpmSim::new(mesh, strategy);
        if let Some(comm) = &ctx.options.comm {
            mpm.set_communicator(comm.clone());
        }
        let scene = MpmScene::new(mpm);
        Ok(Handle::new(scene, ctx))
    }

    fn material(&mut self, law: &str, opts: Map) -> RhaiResult<MaterialHandle> {
        let mut st = self.lock();
        let density = match get(&opts, "density") {
            Some(d) => number(d, "density")?,
            None => {
                // A misspelt `density` is the likelier cause: name it.
                let keys: Vec<String> = opts.keys().map(|k| k.to_string()).collect();
                let typo = keys.iter().find(|k| !super::api_doc::closest(k, ["density"]).is_empty());
                return err(match typo {
                    Some(k) => format!("unknown option `{k}` of material \"{law}\"; did you mean `density`?"),
                    None => format!("material \"{law}\" needs `density` (kg/m^3)"),
                });
            }
        };
        let name = match get(&opts, "name") {
            Some(n) => string(n, "name")?,
            None => format!("{law}_{}", st.sim.mpm.materials.len() + 1),
        };
        let law_obj = {
            let registry = st.ctx.registry();
            let (params, objects) = law_inputs(&opts, law, &registry)?;
            registry.build_law_with(law, &params, &objects).or_rhai()?
        };
        let index = st.sim.mpm.add_material(&name, density, law_obj).or_rhai()?;
        Ok(MaterialHandle { index, name, sim: self.serial() })
    }

    /// New values for some parameters of a material's law, between two steps. The law is rebuilt
    /// from its current parameters and the new ones; the points keep their stress and state.
    fn set_material(&mut self, m: &MaterialHandle, opts: Map) -> RhaiResult<()> {
        if get(&opts, "density").is_some() {
            return err(format!(
                "set_material(\"{}\"): the density cannot change (point masses are fixed when points are made)",
                m.name
            ));
        }
        let index = m.index_in(self)?;
        let mut guard = self.lock();
        let st = &mut *guard;
        let Some(material) = st.sim.mpm.materials.get(index) else {
            return err(format!("material \"{}\" does not belong to this simulation", m.name));
        };
        let law = material.law.name().to_string();
        if material.law.point_objects().is_some() {
            return err(format!(
                "set_material(\"{}\"): law \"{law}\" keeps an object per point; its parameters are fixed",
                m.name
            ));
        }
        let mut params: granite_core::registry::ParamMap =
            material.law.params().iter().filter(|(_, v)| !v.is_nan()).map(|(k, v)| (k.to_string(), v)).collect();
        params.extend(param_map(&opts, &[], &law)?);
        let rebuilt = st.ctx.registry().build_law(&law, &params).or_rhai()?;
        let old = std::mem::replace(&mut st.sim.mpm.materials[index].law, rebuilt);
        // A stiffer law may need a smaller time step: refuse the change rather than blow up.
        if let Err(e) = st.sim.mpm.validate() {
            st.sim.mpm.materials[index].law = old;
            return err(format!("set_material(\"{}\") refused: {e}", m.name));
        }
        Ok(())
    }

    /// A box region that must lie inside the mesh (a box poking out would silently lose points).
    fn box_region(&self, lo: &Dynamic, hi: &Dynamic) -> RhaiResult<Region> {
        let st = self.lock();
        let mesh = &st.sim.mpm.mesh;
        let dim = mesh.dim;
        let (lo, hi) = (vector(lo, dim, "lower corner")?, vector(hi, dim, "upper corner")?);
        let (mlo, mhi) = (mesh.origin, mesh.upper());
        for a in 0..dim {
            if !(lo[a] < hi[a]) {
                return err(format!("box corners must satisfy lower < upper on every axis, got {lo:?} and {hi:?}"));
            }
            let eps = 1e-9 * mesh.cell[a];
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

    pub(super) fn fill(
        &mut self,
        ctx: Option<&NativeCallContext>,
        mat: &MaterialHandle,
        region: Region,
        opts: Map,
    ) -> RhaiResult<i64> {
        api_options(&opts, "MpmSim", "fill_box")?;
        let material = mat.index_in(self)?;
        let mut st = self.lock();
        let dim = st.sim.mpm.dim();
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
        let mesh = st.sim.mpm.mesh.clone();
        let mut script_error = None;
        let (xs, vols) = cell_points(&mesh, layout, per_dir as usize, |x| match &region {
            Region::Box(lo, hi) => Ok((0..dim).all(|a| x[a] >= lo[a] && x[a] <= hi[a])),
            Region::Mesh(group) => Ok(group.contains(x)),
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
        st.sim.mpm.add_points(material, &xs, &vols, v, stress).or_rhai()?;
        Ok(xs.len() as i64)
    }

    fn select_nodes(&self, ctx: &NativeCallContext, selector: &Dynamic) -> RhaiResult<Vec<u32>> {
        let mesh = self.lock().sim.mpm.mesh.clone();
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

    fn fix(&mut self, ctx: &NativeCallContext, selector: Dynamic, axis: &str, value: Dynamic) -> RhaiResult<()> {
        let nodes = self.select_nodes(ctx, &selector)?;
        self.fix_nodes(nodes, axis, value)
    }

    /// Fixes the velocity of `nodes` along `axis` to `value` (a number, a table, a function of t).
    pub(super) fn fix_nodes(&mut self, nodes: Vec<u32>, axis: &str, value: Dynamic) -> RhaiResult<()> {
        let (f, driver) = time_function(&value, "velocity")?;
        let mut st = self.lock();
        let axis = axis_index(axis, st.sim.mpm.dim())?;
        st.sim.mpm.boundary.velocity.push(VelocityConstraint { nodes, axis, value: f });
        let target = Driven::Velocity(st.sim.mpm.boundary.velocity.len() - 1);
        drop(st);
        self.drive_by(target, driver);
        Ok(())
    }

    /// Has the script function `driver`, if any, set boundary value `target` once per step.
    fn drive_by(&self, target: Driven, driver: Option<FnPtr>) {
        if let Some(fp) = driver {
            let index = {
                let mut st = self.lock();
                st.sim.driven.push(target);
                st.sim.driven.len() - 1
            };
            self.drive(index, fp);
        }
    }

    fn friction(&mut self, face: &str, mu: Dynamic) -> RhaiResult<()> {
        let mu = number(&mu, "mu")?;
        if !(mu >= 0.0 && mu.is_finite()) {
            return err(format!("friction coefficient `mu` must be finite and >= 0, got {mu}"));
        }
        let mut st = self.lock();
        let face = Face::parse(face, st.sim.mpm.dim()).or_rhai()?;
        let nodes = face.nodes(&st.sim.mpm.mesh);
        st.sim.mpm.boundary.friction.push(FrictionConstraint { nodes, axis: face.axis, sign: face.outward_sign(), mu });
        Ok(())
    }

    pub(super) fn add_force(&mut self, nodes: Vec<u32>, force: Vec<Vec3>, factor: Dynamic) -> RhaiResult<()> {
        let (f, driver) = time_function(&factor, "factor")?;
        let mut st = self.lock();
        st.sim.mpm.boundary.forces.push(NodalForce { nodes, force, factor: f });
        let target = Driven::Force(st.sim.mpm.boundary.forces.len() - 1);
        drop(st);
        self.drive_by(target, driver);
        Ok(())
    }

    /// Adds a load carried by points, its factor a number, a table or a script function of time.
    pub(super) fn add_point_load(
        &mut self,
        mut load: granite_core::mpm::boundary::PointLoad,
        factor: Dynamic,
    ) -> RhaiResult<()> {
        let (f, driver) = time_function(&factor, "factor")?;
        load.factor = f;
        let mut st = self.lock();
        st.sim.mpm.boundary.point_loads.push(load);
        let target = Driven::PointLoad(st.sim.mpm.boundary.point_loads.len() - 1);
        drop(st);
        self.drive_by(target, driver);
        Ok(())
    }

    /// `sim.point_traction(lower, upper, t)`: the points inside a box carry the traction `t`, each
    /// over its surface share (`V^((d-1)/d)`): one layer of points under a surface carries `t`
    /// times that surface.
    fn point_traction_in_box(&mut self, lower: Dynamic, upper: Dynamic, t: Dynamic, factor: Dynamic) -> RhaiResult<()> {
        use granite_core::mpm::boundary::{surface_share, PointLoad, TimeFunction};
        let (ids, forces) = {
            let st = self.lock();
            let sim = &st.sim.mpm;
            let dim = sim.dim();
            let (lo, hi) = (vector(&lower, dim, "lower corner")?, vector(&upper, dim, "upper corner")?);
            let t = vector(&t, dim, "traction")?;
            let pts = &sim.points;
            let inside = |x: &Vec3| (0..dim).all(|a| x[a] >= lo[a] && x[a] <= hi[a]);
            let picked: Vec<usize> = (0..pts.len()).filter(|&p| inside(&pts.x[p])).collect();
            if picked.is_empty() {
                return err(format!(
                    "sim.point_traction({lo:?}, {hi:?}, ...): no material point lies in that box (it should hold the \
                     layer of points under the loaded surface)"
                ));
            }
            let forces = picked.iter().map(|&p| t.map(|c| c * surface_share(pts.volume[p], dim))).collect();
            (picked.iter().map(|&p| pts.id[p]).collect(), forces)
        };
        let name = "point_traction in a box".to_string();
        self.add_point_load(PointLoad::new(name, ids, forces, TimeFunction::Constant(1.0)), factor)
    }

    fn traction(&mut self, face: &str, t: Dynamic, factor: Dynamic) -> RhaiResult<()> {
        let (nodes, forces) = {
            let st = self.lock();
            let dim = st.sim.mpm.dim();
            let face = Face::parse(face, dim).or_rhai()?;
            Boundary::traction_on_face(&st.sim.mpm.mesh, face, vector(&t, dim, "traction")?)
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
        let dim = self.lock().sim.mpm.dim();
        let f = vector(&f, dim, "force")?;
        let forces = vec![f; nodes.len()];
        self.add_force(nodes, forces, factor)
    }

    /// Geostatic stress: `sigma_v = -rho |g| (surface - height)`, horizontal `K0 sigma_v`.
    fn geostatic(&mut self, surface: Dynamic, k0: Dynamic) -> RhaiResult<()> {
        let (surface, k0) = (finite(&surface, "surface")?, finite(&k0, "k0")?);
        if !(k0 >= 0.0) {
            return err(format!("`k0` must be >= 0, got {k0}"));
        }
        let mut st = self.lock();
        let sim = &mut st.sim.mpm;
        let g = granite_core::math::norm3(sim.gravity);
        if g == 0.0 {
            return err("geostatic_stress needs gravity: call gravity([...]) first");
        }
        let up = sim.dim() - 1;
        let densities: Vec<f64> = sim.materials.iter().map(|m| m.density).collect();
        let pts = &mut sim.points;
        for i in 0..pts.len() {
            let depth = (surface - pts.x[i][up]).max(0.0);
            let sv = -densities[pts.material[i] as usize] * g * depth;
            let mut s = [k0 * sv, k0 * sv, k0 * sv, 0.0, 0.0, 0.0];
            s[up] = sv;
            pts.stress[i] = s;
        }
        Ok(())
    }
}

pub(super) fn register(engine: &mut Engine, ctx: &Arc<ScriptContext>) {
    engine.register_type_with_name::<SimHandle>("MpmSim");
    engine.register_type_with_name::<MaterialHandle>("Material");
    engine.register_fn("to_string", |s: &mut SimHandle| s.describe());
    engine.register_fn("to_debug", |s: &mut SimHandle| s.describe());
    engine.register_fn("to_string", |m: &mut MaterialHandle| format!("Material(\"{}\")", m.name));
    engine.register_fn("to_debug", |m: &mut MaterialHandle| format!("Material(\"{}\")", m.name));
    register_common::<MpmScene>(engine);
    engine.register_get("name", |m: &mut MaterialHandle| m.name.clone());
    let c = ctx.clone();
    engine.register_fn("mpm", move |opts: Map| SimHandle::create(c.clone(), opts));

    engine.register_fn("material", |s: &mut SimHandle, law: &str, opts: Map| s.material(law, opts));
    engine.register_fn("set_material", |s: &mut SimHandle, m: MaterialHandle, opts: Map| s.set_material(&m, opts));
    // By name: the materials of a simulation loaded from a checkpoint have no handles in the script.
    engine.register_fn("set_material", |s: &mut SimHandle, name: &str, opts: Map| {
        let found = s.lock().sim.mpm.materials.iter().position(|m| m.name == name);
        let Some(index) = found else {
            let names: Vec<String> = s.lock().sim.mpm.materials.iter().map(|m| format!("\"{}\"", m.name)).collect();
            return err(format!(
                "set_material(\"{name}\", ...): no material of that name; there are {}",
                names.join(", ")
            ));
        };
        let handle = MaterialHandle::new(index, name.to_string(), s.serial());
        s.set_material(&handle, opts)
    });
    engine.register_fn("memory_per_point", |s: &mut SimHandle, m: MaterialHandle| -> RhaiResult<i64> {
        let index = m.index_in(s)?;
        let st = s.lock();
        match st.sim.mpm.materials.get(index) {
            Some(material) => Ok(material.law.point_objects().map(|o| o.bytes_per_point()).unwrap_or(0) as i64),
            None => err(format!("material \"{}\" does not belong to this simulation", m.name)),
        }
    });
    engine.register_fn("balance_every", |s: &mut SimHandle, n: i64| -> RhaiResult<()> {
        if n < 0 {
            return err(format!("balance_every(n) needs n >= 0 steps (0: never), got {n}"));
        }
        s.lock().sim.mpm.set_balance_every(n as u64);
        Ok(())
    });
    engine.register_fn("save", |s: &mut SimHandle, file: &str| {
        let mut st = s.lock();
        let path = st.script_file_path("save", file)?;
        let ctx = st.ctx.clone();
        st.sim.save_state(&path, &ctx.run_context()).map(|_| path.display().to_string()).or_rhai()
    });
    let c = ctx.clone();
    engine.register_fn("mpm_load", move |file: &str| {
        c.before_simulation()?;
        let path = c
            .input_path(file)
            .map_err(|why| super::convert::to_rhai(GraniteError::Setup(format!("mpm_load: {why}"))))?;
        let stop = || c.stop_requested().is_some();
        let (mut mpm, read, fallback) = MpmSim::load_newest_until(&path, &c.registry(), &stop).or_rhai()?;
        c.record_load(&read, mpm.step, fallback);
        if let Some(comm) = &c.options.comm {
            mpm.set_communicator(comm.clone());
        }
        Ok::<_, Box<rhai::EvalAltResult>>(Handle::new(MpmScene::new(mpm), c.clone()))
    });
    engine.register_fn("fill_box", |s: &mut SimHandle, m: MaterialHandle, lo: Dynamic, hi: Dynamic, opts: Map| {
        let region = s.box_region(&lo, &hi)?;
        s.fill(None, &m, region, opts)
    });
    engine.register_fn("fill_box", |s: &mut SimHandle, m: MaterialHandle, lo: Dynamic, hi: Dynamic| {
        let region = s.box_region(&lo, &hi)?;
        s.fill(None, &m, region, Map::new())
    });
    engine.register_fn("add_points", |s: &mut SimHandle, m: MaterialHandle, positions: Array, volume: Dynamic| {
        let volume = finite(&volume, "volume")?;
        let index = m.index_in(s)?;
        let mut st = s.lock();
        let dim = st.sim.mpm.dim();
        let xs = positions.iter().map(|p| vector(p, dim, "position")).collect::<RhaiResult<Vec<_>>>()?;
        let vols = vec![volume; xs.len()];
        st.sim.mpm.add_points(index, &xs, &vols, [0.0; 3], [0.0; 6]).or_rhai()
    });
    engine.register_fn(
        "fill_region",
        |ctx: NativeCallContext, s: &mut SimHandle, m: MaterialHandle, f: FnPtr, opts: Map| {
            s.fill(Some(&ctx), &m, Region::Closure(f), opts)
        },
    );
    engine.register_fn("gravity", |s: &mut SimHandle, g: Dynamic| {
        let mut st = s.lock();
        let dim = st.sim.mpm.dim();
        st.sim.mpm.gravity = vector(&g, dim, "gravity")?;
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("damping", |s: &mut SimHandle, d: Dynamic| {
        let d = number(&d, "damping")?;
        if !(0.0..1.0).contains(&d) {
            return err(format!("Cundall damping D must be in [0, 1), got {d}"));
        }
        s.lock().sim.mpm.damping = d;
        Ok(())
    });
    engine.register_fn("scheme", |s: &mut SimHandle, name: &str| {
        s.lock().sim.mpm.scheme = StressScheme::parse(name).or_rhai()?;
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    fn set_shape_functions(s: &mut SimHandle, name: &str, opts: Map) -> RhaiResult<()> {
        api_options(&opts, "MpmSim", "shape_functions")?;
        let mut st = s.lock();
        let sim = &mut st.sim.mpm;
        let half = match get(&opts, "point_size") {
            Some(size) => Some(0.5 * number(size, "point_size")?),
            // A point's side from the mean volume of the points present (uGIMP keeps it).
            None if !sim.points.is_empty() => {
                let mean = sim.points.volume.iter().sum::<f64>() / sim.points.len() as f64;
                Some(0.5 * mean.powf(1.0 / sim.mesh.dim as f64))
            }
            None => None,
        };
        let shape = ShapeFunctions::parse(name, half).or_rhai()?;
        shape.check(&sim.mesh).or_rhai()?;
        sim.shape = shape;
        Ok(())
    }
    engine.register_fn("shape_functions", set_shape_functions);
    engine.register_fn("shape_functions", |s: &mut SimHandle, name: &str| set_shape_functions(s, name, Map::new()));
    engine.register_fn("point_velocity", |s: &mut SimHandle, i: i64| -> RhaiResult<Array> {
        let st = s.lock();
        let i = point_index(&st.sim.mpm, i)?;
        Ok(st.sim.mpm.points.v[i].iter().map(|&v| Dynamic::from(v)).collect())
    });
    engine.register_fn("set_point_velocity", |s: &mut SimHandle, i: i64, v: Dynamic| -> RhaiResult<()> {
        let mut st = s.lock();
        let i = point_index(&st.sim.mpm, i)?;
        let dim = st.sim.mpm.dim();
        st.sim.mpm.points.v[i] = vector(&v, dim, "velocity")?;
        Ok(())
    });
    engine.register_fn("stress_rate", |s: &mut SimHandle, name: &str| {
        s.lock().sim.mpm.stress_rate = StressRate::parse(name).or_rhai()?;
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("volumetric_strain", |s: &mut SimHandle, name: &str| {
        let chosen = VolumetricStrain::parse(name).or_rhai()?;
        let mut st = s.lock();
        if chosen == VolumetricStrain::CellCentre && st.sim.mpm.shape != ShapeFunctions::Linear {
            return err(format!(
                "volumetric_strain(\"cell\") takes the volumetric strain at the centre of a cell of linear shape \
                 functions; this simulation uses {:?} (sim.shape_functions(\"linear\") first)",
                st.sim.mpm.shape
            ));
        }
        st.sim.mpm.volumetric_strain = chosen;
        Ok(())
    });
    fn set_update(s: &mut SimHandle, name: &str, opts: Map) -> RhaiResult<()> {
        let mut st = s.lock();
        let params = param_map(&opts, &[], name)?;
        let update = st.ctx.registry().build_velocity_update(name, &params).or_rhai()?;
        st.sim.mpm.velocity_update = update;
        Ok(())
    }
    engine.register_fn("velocity_update", set_update);
    engine.register_fn("velocity_update", |s: &mut SimHandle, name: &str| set_update(s, name, Map::new()));
    engine.register_fn("dt", |s: &mut SimHandle, dt: Dynamic| {
        let dt = number(&dt, "dt")?;
        let mut st = s.lock();
        st.sim.mpm.check_dt(dt).or_rhai()?;
        st.sim.mpm.set_dt(dt).or_rhai()
    });
    engine.register_fn("critical_dt", |s: &mut SimHandle| -> RhaiResult<f64> {
        let st = s.lock();
        let sim = &st.sim.mpm;
        if let Some(dt) = sim.critical_dt() {
            return Ok(dt);
        }
        let silent: Vec<String> = sim
            .materials
            .iter()
            .filter(|m| m.count > 0)
            .map(|m| format!("\"{}\" (law {})", m.name, m.law.name()))
            .collect();
        if silent.is_empty() {
            return err("critical_dt(): no material points yet: the limit is that of the points' materials");
        }
        err(format!(
            "critical_dt(): no material with points reports a wave speed ({}): a plugin law gives one through \
             NativeLaw::wave_speed (ABI version 2); set dt from your own estimate of cell / c_p",
            silent.join(", ")
        ))
    });
    engine.register_fn("fix", |ctx: NativeCallContext, s: &mut SimHandle, sel: Dynamic, axis: &str, v: Dynamic| {
        s.fix(&ctx, sel, axis, v)
    });
    engine.register_fn("fix", |ctx: NativeCallContext, s: &mut SimHandle, sel: Dynamic, axis: &str| {
        s.fix(&ctx, sel, axis, Dynamic::from(0.0))
    });
    engine.register_fn("friction", |s: &mut SimHandle, face: &str, mu: Dynamic| s.friction(face, mu));
    engine.register_fn("point_traction", |s: &mut SimHandle, lower: Dynamic, upper: Dynamic, t: Dynamic| {
        s.point_traction_in_box(lower, upper, t, Dynamic::from(1.0))
    });
    engine.register_fn(
        "point_traction",
        |s: &mut SimHandle, lower: Dynamic, upper: Dynamic, t: Dynamic, factor: Dynamic| {
            s.point_traction_in_box(lower, upper, t, factor)
        },
    );
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
        s.lock().sim.mpm.points.stress.iter_mut().for_each(|p| *p = v);
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("mesh", |s: &mut SimHandle, opts: Map| {
        let mut st = s.lock();
        let dim = st.sim.mpm.dim();
        let mesh = parse_mesh(&opts, Some(dim))?;
        st.sim.mpm.replace_mesh(mesh).or_rhai()?;
        // The conditions on nodes went with the old mesh; loads carried by points stay.
        let keep: Vec<bool> = st.sim.driven.iter().map(|d| matches!(d, Driven::PointLoad(_))).collect();
        st.sim.driven.retain(|d| matches!(d, Driven::PointLoad(_)));
        st.retain_driven(&keep);
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("on_leave", |s: &mut SimHandle, what: &str| {
        s.lock().sim.mpm.out_of_mesh = match what {
            "delete" => OutOfMeshPolicy::Delete,
            "stop" => OutOfMeshPolicy::Stop,
            _ => return err(format!("on_leave takes \"delete\" or \"stop\", got \"{what}\"")),
        };
        Ok(())
    });
    engine.register_fn("track_runout", |s: &mut SimHandle, width: Dynamic, height: Dynamic| {
        let (w, h) = (finite(&width, "width")?, finite(&height, "height")?);
        if !(w > 0.0 && h > 0.0) {
            return err("track_runout needs the initial column width and height (> 0)");
        }
        let mut st = s.lock();
        let t0 = st.sim.mpm.time;
        st.sim.runout = Some(Runout { width0: w, height0: h, t0 });
        Ok(())
    });
    engine.register_get("points", |s: &mut SimHandle| s.lock().sim.mpm.points.len() as i64);
    engine.register_fn("point_stress", |s: &mut SimHandle, i: i64| -> RhaiResult<Array> {
        let st = s.lock();
        let i = point_index(&st.sim.mpm, i)? as i64;
        Ok(st.sim.mpm.points.stress[i as usize].iter().map(|&v| Dynamic::from(v)).collect())
    });
    engine.register_fn("point_strain", |s: &mut SimHandle, i: i64| -> RhaiResult<Array> {
        let st = s.lock();
        let i = point_index(&st.sim.mpm, i)? as i64;
        Ok(st.sim.mpm.points.strain[i as usize].iter().map(|&v| Dynamic::from(v)).collect())
    });
    engine.register_fn("point_state", |s: &mut SimHandle, i: i64, name: &str| -> RhaiResult<f64> {
        let st = s.lock();
        let sim = &st.sim.mpm;
        let i = point_index(sim, i)? as i64;
        let m = sim.points.material[i as usize] as usize;
        let range = sim.material_range(m);
        let law = &sim.materials[m].law;
        let names = law.state_names();
        match names.iter().position(|v| *v == name) {
            Some(k) => Ok(sim.materials[m].state[(i as usize - range.start) * names.len() + k]),
            None => err(format!("law \"{}\" has no state variable `{name}`; it has: {}", law.name(), names.join(", "))),
        }
    });
    engine.register_fn("write_point_object", |s: &mut SimHandle, i: i64, file: &str| -> RhaiResult<String> {
        let mut st = s.lock();
        let sim = &st.sim.mpm;
        let i = point_index(sim, i)? as i64;
        let m = sim.points.material[i as usize] as usize;
        let local = i as usize - sim.material_range(m).start;
        // In a run over several processes, the one holding the point's object writes it.
        let (holder, here) = match &sim.materials[m].spread {
            Some(spread) => (spread.owner[local] as usize, spread.owner[local] as usize == spread.rank()),
            None => (0, sim.writes_files()),
        };
        let objects = sim.materials[m].law.point_objects();
        let frame = if here { objects.and_then(|o| o.object_frame(local)) } else { None };
        let law = sim.materials[m].law.name().to_string();
        let path = st.points_path(file)?;
        let written = match frame {
            Some((x, fields)) => granite_core::io::vtk::write_vtu(&path, &x, &fields),
            None if here => Err(GraniteError::Other(format!("law \"{law}\" keeps no per-point object to write"))),
            None => Ok(()),
        };
        granite_core::comm::agree(st.ctx.comm(), holder, written).or_rhai()?;
        Ok(path.display().to_string())
    });
    engine.register_fn("point_position", |s: &mut SimHandle, i: i64| -> RhaiResult<Array> {
        let st = s.lock();
        let i = point_index(&st.sim.mpm, i)? as i64;
        Ok(st.sim.mpm.points.x[i as usize].iter().map(|&v| Dynamic::from(v)).collect())
    });
}
