//! The `dem(...)` simulation object of scripts and its methods.

use super::convert::{
    api_options, err, finite, get, integer, number, numbers, only_keys, param_map, string, vector, OrRhai, RhaiResult,
};
use super::driver::{register_common, Handle};
use super::ScriptContext;
use granite_core::dem::generate::{cloud, lattice, Psd};
use granite_core::dem::particles::dof;
use granite_core::dem::walls::{Wall, WallShape};
use granite_core::dem::DemSim;
use granite_core::error::GraniteError;
use granite_core::math::Vec3;
use granite_run::{DemScene, Simulation};
use rhai::{Array, Dynamic, Engine, FnPtr, Map};
use std::sync::Arc;

pub type DemHandle = Handle<DemScene>;

/// A DEM material created by `sim.material(...)`.
#[derive(Clone)]
pub struct DemMaterialHandle {
    index: u16,
    name: String,
    /// The simulation that made it (`Handle::serial`).
    sim: u64,
}

impl DemMaterialHandle {
    /// Its index in `s`'s materials; an error when it is another simulation's material.
    pub(super) fn index_in(&self, s: &DemHandle) -> RhaiResult<u16> {
        s.owns(
            self.sim,
            &format!("material \"{}\"", self.name),
            "make one for this simulation with its own material(...)",
        )?;
        Ok(self.index)
    }
    pub(super) fn name(&self) -> &str {
        &self.name
    }
}

/// A wall made by `wall_plane`, `box_walls`, `wall_mesh` and the like: its index among the
/// simulation's walls and the simulation that made it, so that another simulation refuses it
/// instead of moving its own wall of that index.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct DemWallHandle {
    index: usize,
    sim: u64,
}

impl DemWallHandle {
    fn to_text(self) -> String {
        format!("DemWall({})", self.index)
    }
}

/// `clump_cloud` of a body kind: random non-overlapping bodies (by their bounding spheres, and
/// clear of the spheres and bodies already there), randomly turned.
fn body_cloud(
    s: &DemHandle,
    m: &DemMaterialHandle,
    (lo, hi): (Vec3, Vec3),
    count: usize,
    kind: &str,
    opts: &Map,
) -> RhaiResult<i64> {
    const SKIP: [&str; 3] = ["count", "shape", "seed"];
    let bound = super::body_api::bounding_radius(s, kind, opts, &SKIP)?;
    let (seed, existing) = {
        let st = s.lock();
        let seed = match get(opts, "seed") {
            Some(v) => integer(v, "seed")? as u64,
            None => st.sim.dem.world.seed,
        };
        let (sp, k) = (&st.sim.dem.world.spheres, &st.sim.dem.world.kinds);
        let mut existing: Vec<(Vec3, f64)> = sp.x.iter().copied().zip(sp.radius.iter().copied()).collect();
        existing.extend((0..k.len()).map(|i| (k.x[i], k.bounding_radius(i))));
        (seed, existing)
    };
    let ctx = s.lock().ctx.clone();
    let psd = Psd::Uniform { min: bound, max: bound };
    let centres = cloud(lo, hi, count, &psd, seed, &existing, &|| ctx.interrupted()).or_rhai()?;
    let centres: Vec<Vec3> = centres.iter().map(|(c, _)| *c).collect();
    super::body_api::add_cloud(s, kind, m, (opts, &SKIP), &centres, seed)
}

/// Voxels per axis for the mass properties of overlapping clumps (0.1 % on table 2.3's clump).
const CLUMP_VOXELS: usize = 400;

fn unit(v: Vec3, name: &str) -> RhaiResult<Vec3> {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if !(n > 0.0) {
        return err(format!("`{name}` must be a non-zero vector"));
    }
    Ok([v[0] / n, v[1] / n, v[2] / n])
}

fn psd_from(opts: &Map) -> RhaiResult<Psd> {
    if let Some(p) = get(opts, "psd") {
        let m = p.clone().try_cast::<Map>().ok_or_else(|| {
            super::convert::to_rhai(GraniteError::Setup(
                "`psd` must be a map #{ diameters: [...], passing: [...] }".into(),
            ))
        })?;
        let diameters = numbers(get(&m, "diameters").unwrap_or(&Dynamic::UNIT), "psd.diameters")?;
        let passing = numbers(get(&m, "passing").unwrap_or(&Dynamic::UNIT), "psd.passing")?;
        let psd = Psd::Table { diameters, passing };
        psd.validate().or_rhai()?;
        return Ok(psd);
    }
    match get(opts, "radius") {
        Some(r) if r.is_array() => {
            let v = numbers(r, "radius")?;
            if v.len() != 2 {
                return err("`radius` is a number or a [min, max] pair");
            }
            let psd = Psd::Uniform { min: v[0], max: v[1] };
            psd.validate().or_rhai()?;
            Ok(psd)
        }
        Some(r) => {
            let r = finite(r, "radius")?;
            let psd = Psd::Uniform { min: r, max: r };
            psd.validate().or_rhai()?;
            Ok(psd)
        }
        None => err("give the particle sizes: `radius` (number or [min, max]) or `psd`"),
    }
}

impl Handle<DemScene> {
    /// `DemSim(1500 spheres, 5 walls, t = 0.12 s, step 4000, paused)`: what printing a simulation shows.
    pub fn describe(&self) -> String {
        let running = if self.running() { "running" } else { "paused" };
        let st = self.lock();
        let d = &st.sim.dem;
        let count = |n: usize, what: &str| format!("{n} {what}{}", if n == 1 { "" } else { "s" });
        let clumps = if d.world.clumps.is_empty() {
            String::new()
        } else {
            format!(" in {}", count(d.world.clumps.len(), "clump"))
        };
        let cell = if d.world.cell.is_some() { ", periodic" } else { "" };
        format!(
            "DemSim({}{clumps}, {}{cell}, t = {:.6} s, step {}, {running})",
            count(d.world.spheres.len(), "sphere"),
            count(d.world.walls.len(), "wall"),
            d.world.time,
            d.world.step
        )
    }

    fn create(ctx: Arc<ScriptContext>, opts: Map) -> RhaiResult<DemHandle> {
        ctx.before_simulation()?;
        api_options(&opts, "", "dem")?;
        let mut dem = DemSim::new();
        if let Some(s) = get(&opts, "seed") {
            dem.world.seed = integer(s, "seed")? as u64;
        }
        let auto_skin = match get(&opts, "skin") {
            Some(s) => {
                dem.skin = finite(s, "skin")?;
                if !(dem.skin >= 0.0) {
                    return err(format!("`skin` must be >= 0, got {}", dem.skin));
                }
                false
            }
            None => true,
        };
        Ok(Handle::new(DemScene::new(dem, auto_skin), ctx))
    }

    fn material(&mut self, opts: Map) -> RhaiResult<DemMaterialHandle> {
        api_options(&opts, "DemSim", "material")?;
        let mut st = self.lock();
        let density = number(get(&opts, "density").unwrap_or(&Dynamic::UNIT), "density")?;
        let name = match get(&opts, "name") {
            Some(n) => string(n, "name")?,
            None => format!("material_{}", st.sim.dem.world.materials.len() + 1),
        };
        let elastic = super::convert::elastic_from(&opts, &format!("material \"{name}\""))?;
        let index = st.sim.dem.world.add_material(&name, density).or_rhai()?;
        st.sim.dem.world.set_material_elastic(index, elastic).or_rhai()?;
        Ok(DemMaterialHandle { index, name, sim: self.serial() })
    }

    fn contact_law(&mut self, law: &str, pair: Option<(u16, u16)>, opts: Map) -> RhaiResult<()> {
        let mut st = self.lock();
        let params = param_map(&opts, &[], law)?;
        let law = st.ctx.registry().build_contact_law(law, &params).or_rhai()?;
        st.sim.dem.world.set_contact_law(law, pair).or_rhai()
    }

    fn add_generated(&mut self, m: &DemMaterialHandle, spheres: Vec<(Vec3, f64)>) -> RhaiResult<i64> {
        let index = m.index_in(self)?;
        let mut st = self.lock();
        for (x, r) in &spheres {
            st.sim.dem.world.add_sphere(index, *x, *r, [0.0; 3]).or_rhai()?;
        }
        Ok(spheres.len() as i64)
    }

    fn add_wall(
        &mut self,
        mat: &DemMaterialHandle,
        name: String,
        shape: WallShape,
        position: Vec3,
    ) -> RhaiResult<DemWallHandle> {
        let wall = Wall::new(&name, shape, position, mat.index_in(self)?);
        let mut st = self.lock();
        let twin = st.sim.dem.world.walls.iter().position(|w| w.same_surface(&wall));
        let index = st.sim.dem.world.add_wall(wall);
        if let Some(twin) = twin {
            st.ctx.warn(&format!(
                "wall {index} (\"{name}\") is the same surface as wall {twin} (\"{}\"): a sphere touches both, \
                 with twice the stiffness; add it once",
                st.sim.dem.world.walls[twin].name
            ));
        }
        Ok(DemWallHandle { index, sim: self.serial() })
    }

    /// The six walls of a box (or five, open at the top), lower corner `lo`, upper `hi`.
    fn box_walls(&mut self, m: &DemMaterialHandle, lo: &Dynamic, hi: &Dynamic, open_top: bool) -> RhaiResult<Array> {
        let (lo, hi) = (vector(lo, 3, "lower corner")?, vector(hi, 3, "upper corner")?);
        if let Some(a) = (0..3).find(|&a| !(lo[a] < hi[a])) {
            return err(format!(
                "box_walls: the lower corner {lo:?} must be below the upper corner {hi:?} on every axis (not on {})",
                ["x", "y", "z"][a]
            ));
        }
        let mut out = Array::new();
        for a in 0..3 {
            for (upper, point) in [(false, lo), (true, hi)] {
                if upper && a == 2 && open_top {
                    continue;
                }
                let mut n = [0.0; 3];
                n[a] = if upper { -1.0 } else { 1.0 };
                let name = format!("{}{}", ["x", "y", "z"][a], if upper { "+" } else { "-" });
                out.push(Dynamic::from(self.add_wall(m, name, WallShape::Plane { normal: n }, point)?));
            }
        }
        Ok(out)
    }

    fn wall_index(&self, w: i64) -> RhaiResult<usize> {
        let n = self.lock().sim.dem.world.walls.len();
        if w < 0 || w as usize >= n {
            return err(format!("wall index {w} out of range 0..{n}"));
        }
        Ok(w as usize)
    }

    /// One wall a script names: a wall this simulation made, or its index among this
    /// simulation's walls.
    fn wall_of(&self, w: &Dynamic) -> Option<RhaiResult<usize>> {
        if let Ok(i) = w.as_int() {
            return Some(self.wall_index(i));
        }
        let wall = w.clone().try_cast::<DemWallHandle>()?;
        Some(
            self.owns(
                wall.sim,
                &format!("wall {}", wall.index),
                "name this simulation's walls by what its own wall_plane, box_walls or wall_mesh returned",
            )
            .map(|()| wall.index),
        )
    }

    /// The walls a script names: a wall, or an array of them (what `wall_mesh` and `box_walls`
    /// return); a wall is what made it returned, or its index.
    fn walls_of(&self, w: &Dynamic) -> RhaiResult<Vec<usize>> {
        if let Some(one) = self.wall_of(w) {
            return Ok(vec![one?]);
        }
        let Some(list) = w.clone().try_cast::<Array>() else {
            return err(format!("a wall is a wall, an index or an array of them, got {}", w.type_name()));
        };
        if list.is_empty() {
            return err("an empty array of walls");
        }
        list.iter()
            .map(|d| {
                self.wall_of(d).unwrap_or_else(|| {
                    err(format!(
                        "a wall is a wall, an index or an array of them, got an array holding {}",
                        d.type_name()
                    ))
                })
            })
            .collect()
    }

    /// The triangles of an STL file, a gmsh file's surface group or a loaded mesh's, as walls.
    fn wall_mesh(&mut self, m: &DemMaterialHandle, source: Dynamic, opts: Map) -> RhaiResult<Array> {
        api_options(&opts, "DemSim", "wall_mesh")?;
        let group = get(&opts, "group").map(|g| super::convert::string(g, "group")).transpose()?;
        let script = self.lock().ctx.clone();
        let (name, triangles) = super::mesh_api::surface_triangles(&script, source, group.as_deref())?;
        let scale = match get(&opts, "scale") {
            Some(d) => finite(d, "scale")?,
            None => 1.0,
        };
        if !(scale > 0.0) {
            return err(format!("`scale` of wall_mesh must be > 0, got {scale}"));
        }
        let translate = get(&opts, "translate").map(|d| vector(d, 3, "translate")).transpose()?.unwrap_or([0.0; 3]);
        let rotate = get(&opts, "rotate").map(|d| vector(d, 3, "rotate")).transpose()?.unwrap_or([0.0; 3]);
        let rotation = nalgebra::Rotation3::new(nalgebra::Vector3::from(rotate));
        let place = |v: Vec3| {
            let r = rotation * nalgebra::Vector3::new(scale * v[0], scale * v[1], scale * v[2]);
            [r[0] + translate[0], r[1] + translate[1], r[2] + translate[2]]
        };
        let placed: Vec<[Vec3; 3]> = triangles.iter().map(|t| t.map(place)).collect();
        let material = m.index_in(self)?;
        let walls = granite_core::dem::mesh_walls::mesh_walls(&placed, &name, material).or_rhai()?;
        let sim = self.serial();
        let mut st = self.lock();
        let first = st.sim.dem.world.walls.len();
        for w in walls {
            st.sim.dem.world.add_wall(w);
        }
        Ok((first..st.sim.dem.world.walls.len()).map(|index| Dynamic::from(DemWallHandle { index, sim })).collect())
    }
}

pub(super) fn register(engine: &mut Engine, ctx: &Arc<ScriptContext>) {
    engine.register_type_with_name::<DemHandle>("DemSim");
    engine.register_type_with_name::<DemMaterialHandle>("DemMaterial");
    engine.register_type_with_name::<DemWallHandle>("DemWall");
    engine.register_fn("to_string", |w: &mut DemWallHandle| w.to_text());
    engine.register_fn("to_debug", |w: &mut DemWallHandle| w.to_text());
    engine.register_get("index", |w: &mut DemWallHandle| w.index as i64);
    engine.register_fn("==", |a: DemWallHandle, b: DemWallHandle| a == b);
    engine.register_fn("!=", |a: DemWallHandle, b: DemWallHandle| a != b);
    engine.register_fn("to_string", |s: &mut DemHandle| s.describe());
    engine.register_fn("to_debug", |s: &mut DemHandle| s.describe());
    engine.register_fn("to_string", |m: &mut DemMaterialHandle| format!("DemMaterial(\"{}\")", m.name));
    engine.register_fn("to_debug", |m: &mut DemMaterialHandle| format!("DemMaterial(\"{}\")", m.name));
    register_common::<DemScene>(engine);
    engine.register_get("name", |m: &mut DemMaterialHandle| m.name.clone());
    let c = ctx.clone();
    engine.register_fn("dem", move |opts: Map| DemHandle::create(c.clone(), opts));
    let c = ctx.clone();
    engine.register_fn("dem", move || DemHandle::create(c.clone(), Map::new()));
    engine.register_fn("material", |s: &mut DemHandle, opts: Map| s.material(opts));
    engine.register_fn("save", |s: &mut DemHandle, file: &str| {
        let mut st = s.lock();
        let path = st.script_file_path("save", file)?;
        let ctx = st.ctx.clone();
        st.sim.save_state(&path, &ctx.run_context()).map(|_| path.display().to_string()).or_rhai()
    });
    let c = ctx.clone();
    engine.register_fn("dem_load", move |file: &str| {
        c.before_simulation()?;
        let path = c.input_path(file).map_err(|why| {
            super::convert::to_rhai(GraniteError::Setup(format!(
                "dem_load: {why}; `sim.save(file)` writes a state into a run's output folder (a prepared \
                 RVE: `granite run scripts/mpmxdem/prepare_rve.rhai` writes out/prepare_rve/rve.json)"
            )))
        })?;
        let stop = || c.stop_requested().is_some();
        let (dem, read, fallback) = DemSim::load_newest_until(&path, &*c.registry(), &stop).or_rhai()?;
        c.record_load(&read, dem.world.step, fallback);
        Ok::<_, Box<rhai::EvalAltResult>>(Handle::new(DemScene::new(dem, false), c.clone()))
    });
    engine.register_fn("contact_law", |s: &mut DemHandle, law: &str, opts: Map| s.contact_law(law, None, opts));
    engine.register_fn(
        "contact_law",
        |s: &mut DemHandle, law: &str, a: DemMaterialHandle, b: DemMaterialHandle, opts: Map| {
            let pair = (a.index_in(s)?, b.index_in(s)?);
            s.contact_law(law, Some(pair), opts)
        },
    );
    fn sphere(s: &mut DemHandle, m: DemMaterialHandle, x: Dynamic, r: Dynamic, opts: Map) -> RhaiResult<i64> {
        api_options(&opts, "DemSim", "sphere")?;
        let x = vector(&x, 3, "position")?;
        let r = finite(&r, "radius")?;
        let v = match get(&opts, "velocity") {
            Some(v) => vector(v, 3, "velocity")?,
            None => [0.0; 3],
        };
        let index = m.index_in(s)?;
        let mut st = s.lock();
        let i = st.sim.dem.world.add_sphere(index, x, r, v).or_rhai()?;
        if let Some(f) = get(&opts, "fixed") {
            st.sim.dem.world.spheres.blocked[i] = if f.is_bool() {
                if f.as_bool().unwrap_or(false) {
                    dof::ALL
                } else {
                    0
                }
            } else {
                granite_core::dem::bodies::parse_dofs(&string(f, "fixed")?).or_rhai()?
            };
        }
        Ok(st.sim.dem.world.spheres.id[i] as i64)
    }
    engine.register_fn("sphere", sphere);
    engine.register_fn("sphere", |s: &mut DemHandle, m: DemMaterialHandle, x: Dynamic, r: Dynamic| {
        sphere(s, m, x, r, Map::new())
    });
    engine.register_fn("cloud", |s: &mut DemHandle, m: DemMaterialHandle, lo: Dynamic, hi: Dynamic, opts: Map| {
        api_options(&opts, "DemSim", "cloud")?;
        let (lo, hi) = (vector(&lo, 3, "lower corner")?, vector(&hi, 3, "upper corner")?);
        let count = integer(get(&opts, "count").unwrap_or(&Dynamic::UNIT), "count")?;
        if count < 0 {
            return err(format!("`count` must be >= 0, got {count}"));
        }
        let psd = psd_from(&opts)?;
        let (seed, existing, ctx) = {
            let st = s.lock();
            let seed = match get(&opts, "seed") {
                Some(v) => integer(v, "seed")? as u64,
                None => st.sim.dem.world.seed,
            };
            let sp = &st.sim.dem.world.spheres;
            (seed, sp.x.iter().copied().zip(sp.radius.iter().copied()).collect::<Vec<_>>(), st.ctx.clone())
        };
        let made = cloud(lo, hi, count as usize, &psd, seed, &existing, &|| ctx.interrupted()).or_rhai()?;
        s.add_generated(&m, made)
    });
    engine.register_fn("clump", |s: &mut DemHandle, m: DemMaterialHandle, members: Array| {
        let mut list = Vec::new();
        for (k, row) in members.iter().enumerate() {
            let v = numbers(row, "clump member")?;
            if v.len() != 4 || !(v[3] > 0.0) {
                return err(format!("clump member {k} must be [x, y, z, radius] with radius > 0"));
            }
            list.push(([v[0], v[1], v[2]], v[3]));
        }
        let index = m.index_in(s)?;
        s.lock().sim.dem.world.add_clump(index, &list, [0.0; 3], CLUMP_VOXELS).map(|c| c as i64).or_rhai()
    });
    engine.register_fn(
        "tetra_clump",
        |s: &mut DemHandle, m: DemMaterialHandle, centre: Dynamic, r_sphere: Dynamic, r_clump: Dynamic| {
            let c = vector(&centre, 3, "centre")?;
            let members = granite_core::dem::clump::tetrahedral_members(
                c,
                finite(&r_sphere, "r_sphere")?,
                finite(&r_clump, "r_clump")?,
            )
            .or_rhai()?;
            let index = m.index_in(s)?;
            s.lock().sim.dem.world.add_clump(index, &members, [0.0; 3], CLUMP_VOXELS).map(|c| c as i64).or_rhai()
        },
    );
    engine.register_fn(
        "clump_cloud",
        |s: &mut DemHandle, m: DemMaterialHandle, lo: Dynamic, hi: Dynamic, opts: Map| {
            let (lo, hi) = (vector(&lo, 3, "lower corner")?, vector(&hi, 3, "upper corner")?);
            let count = integer(get(&opts, "count").unwrap_or(&Dynamic::UNIT), "count")?;
            if count < 0 {
                return err(format!("`count` must be >= 0, got {count}"));
            }
            let count = count as usize;
            let shape_name =
                get(&opts, "shape").map(|t| string(t, "shape")).transpose()?.unwrap_or_else(|| "tetra".into());
            if super::body_api::is_kind(s, &shape_name) {
                return body_cloud(s, &m, (lo, hi), count, &shape_name, &opts);
            }
            let shape_params = param_map(&opts, &["count", "shape", "seed"], &shape_name)?;
            let (seed, existing, shape) = {
                let st = s.lock();
                let seed = match get(&opts, "seed") {
                    Some(v) => integer(v, "seed")? as u64,
                    None => st.sim.dem.world.seed,
                };
                let sp = &st.sim.dem.world.spheres;
                let shape = st.ctx.registry().build_shape(&shape_name, &shape_params).or_rhai()?;
                (seed, sp.x.iter().copied().zip(sp.radius.iter().copied()).collect::<Vec<_>>(), shape)
            };
            let template = shape.members();
            let bound = shape.bounding_radius();
            // Reference points kept apart by the grains' bounding spheres; orientations uniformly random.
            let ctx = s.lock().ctx.clone();
            let psd = Psd::Uniform { min: bound, max: bound };
            let centres = cloud(lo, hi, count, &psd, seed, &existing, &|| ctx.interrupted()).or_rhai()?;
            let index = m.index_in(s)?;
            let density = s.lock().sim.dem.world.materials[index as usize].density;
            let props = granite_core::dem::clump::mass_properties(&template, density, CLUMP_VOXELS).or_rhai()?;
            let mut st = s.lock();
            for (k, (c, _)) in centres.iter().enumerate() {
                let u = [0, 1, 2].map(|j| granite_core::ext::contact::uniform(seed ^ 0xC1u64, (3 * k + j) as u64));
                let (members, q) = granite_core::dem::clump::place_template(&template, *c, u);
                if members.len() == 1 {
                    st.sim.dem.world.add_sphere(index, members[0].0, members[0].1, [0.0; 3]).or_rhai()?;
                } else {
                    st.sim.dem.world.add_clump_with(index, &members, &props.transformed(&q, *c)).or_rhai()?;
                }
            }
            Ok::<_, Box<rhai::EvalAltResult>>(count as i64)
        },
    );
    engine.register_fn("lattice", |s: &mut DemHandle, m: DemMaterialHandle, lo: Dynamic, hi: Dynamic, opts: Map| {
        api_options(&opts, "DemSim", "lattice")?;
        let (lo, hi) = (vector(&lo, 3, "lower corner")?, vector(&hi, 3, "upper corner")?);
        let spacing = finite(get(&opts, "spacing").unwrap_or(&Dynamic::UNIT), "spacing")?;
        let radius = finite(get(&opts, "radius").unwrap_or(&Dynamic::UNIT), "radius")?;
        let jitter = match get(&opts, "jitter") {
            Some(j) => finite(j, "jitter")?,
            None => 0.0,
        };
        let seed = match get(&opts, "seed") {
            Some(v) => integer(v, "seed")? as u64,
            None => s.lock().sim.dem.world.seed,
        };
        let made = lattice(lo, hi, spacing, radius, jitter, seed).or_rhai()?;
        s.add_generated(&m, made)
    });
    engine.register_fn("wall_plane", |s: &mut DemHandle, m: DemMaterialHandle, point: Dynamic, normal: Dynamic| {
        let (p, n) = (vector(&point, 3, "point")?, unit(vector(&normal, 3, "normal")?, "normal")?);
        s.add_wall(&m, "plane".into(), WallShape::Plane { normal: n }, p)
    });
    engine.register_fn(
        "wall_rect",
        |s: &mut DemHandle, m: DemMaterialHandle, centre: Dynamic, u: Dynamic, v: Dynamic, half: Dynamic| {
            let c = vector(&centre, 3, "centre")?;
            let u = unit(vector(&u, 3, "u")?, "u")?;
            let v = unit(vector(&v, 3, "v")?, "v")?;
            let h = numbers(&half, "half sizes")?;
            if h.len() != 2 || !(h[0] > 0.0 && h[1] > 0.0) {
                return err("`half sizes` must be [half_u, half_v] > 0");
            }
            if (u[0] * v[0] + u[1] * v[1] + u[2] * v[2]).abs() > 1e-9 {
                return err("rectangle sides `u` and `v` must be orthogonal");
            }
            s.add_wall(&m, "rect".into(), WallShape::Rect { u, v, half: [h[0], h[1]] }, c)
        },
    );
    engine.register_fn(
        "wall_disk",
        |s: &mut DemHandle, m: DemMaterialHandle, centre: Dynamic, normal: Dynamic, radius: Dynamic| {
            let c = vector(&centre, 3, "centre")?;
            let n = unit(vector(&normal, 3, "normal")?, "normal")?;
            let r = finite(&radius, "radius")?;
            if !(r > 0.0) {
                return err("disk radius must be > 0");
            }
            s.add_wall(&m, "disk".into(), WallShape::Disk { normal: n, radius: r }, c)
        },
    );
    engine.register_fn(
        "wall_cylinder",
        |s: &mut DemHandle, m: DemMaterialHandle, base: Dynamic, axis: Dynamic, radius: Dynamic, length: Dynamic| {
            let b = vector(&base, 3, "base")?;
            let a = unit(vector(&axis, 3, "axis")?, "axis")?;
            let (r, l) = (finite(&radius, "radius")?, finite(&length, "length")?);
            if !(r > 0.0 && l > 0.0) {
                return err("cylinder radius and length must be > 0");
            }
            s.add_wall(&m, "cylinder".into(), WallShape::Cylinder { axis: a, radius: r, length: l }, b)
        },
    );
    engine.register_fn("box_walls", |s: &mut DemHandle, m: DemMaterialHandle, lo: Dynamic, hi: Dynamic, opts: Map| {
        api_options(&opts, "DemSim", "box_walls")?;
        let open_top = get(&opts, "open_top").and_then(|d| d.as_bool().ok()).unwrap_or(false);
        s.box_walls(&m, &lo, &hi, open_top)
    });
    engine.register_fn("box_walls", |s: &mut DemHandle, m: DemMaterialHandle, lo: Dynamic, hi: Dynamic| {
        s.box_walls(&m, &lo, &hi, false)
    });
    // A wall is an index, or an array of them moving as one (the triangles of `wall_mesh`).
    engine.register_fn("wall_velocity", |s: &mut DemHandle, w: Dynamic, v: Dynamic| {
        let walls = s.walls_of(&w)?;
        let v = vector(&v, 3, "velocity")?;
        let mut st = s.lock();
        for w in walls {
            st.sim.dem.world.walls[w].velocity = v;
        }
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("wall_velocity", |s: &mut DemHandle, w: Dynamic, axis: &str, f: FnPtr| {
        let walls = s.walls_of(&w)?;
        let axis = super::convert::axis_index(axis, 3)?;
        let target = {
            let mut st = s.lock();
            st.sim.driven.push((walls, axis));
            st.sim.driven.len() - 1
        };
        s.drive(target, f);
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("wall_spin", |s: &mut DemHandle, w: Dynamic, spin: Dynamic, pivot: Dynamic| {
        let walls = s.walls_of(&w)?;
        let spin = vector(&spin, 3, "spin")?;
        let pivot = vector(&pivot, 3, "pivot")?;
        let mut st = s.lock();
        let world = &mut st.sim.dem.world;
        if let Some(&k) = walls.iter().find(|&&k| !matches!(world.walls[k].shape, WallShape::Triangle { .. })) {
            return err(format!(
                "wall_spin: wall {k} (\"{}\") is not a triangle of a wall mesh: walls made by wall_mesh spin, the others translate",
                world.walls[k].name
            ));
        }
        if spin != [0.0; 3] && st.sim.dem.energy.is_some() {
            return err("wall_spin: energy tracking covers walls that translate: turn it off first (track_energy(false))");
        }
        let world = &mut st.sim.dem.world;
        for k in walls {
            world.walls[k].spin = spin;
            world.walls[k].pivot = pivot;
        }
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("wall_force", |s: &mut DemHandle, w: Dynamic| {
        let walls = s.walls_of(&w)?;
        let forces = s.lock().sim.dem.world.wall_forces();
        let f = walls.iter().fold([0.0; 3], |sum, &w| [0, 1, 2].map(|k| sum[k] + forces[w][k]));
        Ok::<_, Box<rhai::EvalAltResult>>(f.iter().map(|&c| Dynamic::from(c)).collect::<Array>())
    });
    engine.register_fn("wall_torque", |s: &mut DemHandle, w: Dynamic, about: Dynamic| {
        let walls = s.walls_of(&w)?;
        let about = vector(&about, 3, "point")?;
        let t = s.lock().sim.dem.world.wall_torque(&walls, about);
        Ok::<_, Box<rhai::EvalAltResult>>(t.iter().map(|&c| Dynamic::from(c)).collect::<Array>())
    });
    engine.register_fn("wall_position", |s: &mut DemHandle, w: Dynamic| {
        let walls = s.walls_of(&w)?;
        let p = s.lock().sim.dem.world.walls[walls[0]].position;
        Ok::<_, Box<rhai::EvalAltResult>>(p.iter().map(|&c| Dynamic::from(c)).collect::<Array>())
    });
    engine.register_fn("wall_mesh", |s: &mut DemHandle, m: DemMaterialHandle, source: Dynamic, opts: Map| {
        s.wall_mesh(&m, source, opts)
    });
    engine.register_fn("wall_mesh", |s: &mut DemHandle, m: DemMaterialHandle, source: Dynamic| {
        s.wall_mesh(&m, source, Map::new())
    });
    engine.register_fn("gravity", |s: &mut DemHandle, g: Dynamic| {
        s.lock().sim.dem.world.gravity = vector(&g, 3, "gravity")?;
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("damping", |s: &mut DemHandle, d: Dynamic| {
        let d = number(&d, "damping")?;
        s.lock().sim.dem.world.set_damping(d).or_rhai()
    });
    engine.register_fn("dt", |s: &mut DemHandle, dt: Dynamic| {
        let dt = number(&dt, "dt")?;
        let mut st = s.lock();
        st.sim.dem.world.check_dt(dt).or_rhai()?;
        st.sim.dem.world.set_dt(dt).or_rhai()
    });
    engine.register_fn("critical_dt", |s: &mut DemHandle| -> RhaiResult<f64> {
        let st = s.lock();
        let dem = &st.sim.dem;
        // No limit means nothing to compute it from: say what is missing (a dt of inf would be
        // refused later with no word of the cause).
        dem.world.critical_dt().ok_or(()).or_else(|_| {
            err(if dem.world.spheres.is_empty() {
                "critical_dt(): no spheres yet: the limit comes from their masses and their contacts' stiffness"
                    .to_string()
            } else if dem.world.contacts.laws.is_empty() {
                "critical_dt(): no contact law yet: call sim.contact_law(name, #{ ... }) first".to_string()
            } else {
                "critical_dt(): the contact laws give the spheres' materials no stiffness (set_contact_law between \
                 them?)"
                    .to_string()
            })
        })
    });
    engine.register_fn("stable_dt", |s: &mut DemHandle| {
        s.lock().sim.dem.world.stable_dt().map(|limit| limit.dt).unwrap_or(f64::INFINITY)
    });
    engine.register_fn("allow_overlaps", |s: &mut DemHandle, allow: bool| {
        s.lock().sim.check_overlaps = !allow;
    });
    engine.register_fn("stop_on_unstable_dt", |s: &mut DemHandle, on: bool| {
        s.lock().sim.dem.stop_on_unstable_dt = on;
    });
    engine.register_fn("erase_outside", |s: &mut DemHandle, lo: Dynamic, hi: Dynamic| {
        let (lo, hi) = (vector(&lo, 3, "lower corner")?, vector(&hi, 3, "upper corner")?);
        if let Some(a) = (0..3).find(|&a| !(lo[a] <= hi[a])) {
            return err(format!(
                "erase_outside: the lower corner {lo:?} must not be above the upper corner {hi:?} on any axis (it is \
                 on {}): every sphere would be erased",
                ["x", "y", "z"][a]
            ));
        }
        let mut st = s.lock();
        let inside = |x: &Vec3| (0..3).all(|a| x[a] >= lo[a] && x[a] <= hi[a]);
        let keep: Vec<bool> = st.sim.dem.world.spheres.x.iter().map(inside).collect();
        let mut lost = keep.iter().filter(|k| !**k).count();
        if lost > 0 {
            st.sim.dem.world.remove_spheres(&keep);
        }
        // Bodies of plugin kinds by their centres; fixed ones are container parts and stay.
        let k = &st.sim.dem.world.kinds;
        let keep: Vec<bool> = (0..k.len()).map(|i| k.fixed[i] || inside(&k.x[i])).collect();
        let gone = keep.iter().filter(|k| !**k).count();
        if gone > 0 {
            st.sim.dem.world.remove_bodies(&keep);
            lost += gone;
        }
        Ok::<_, Box<rhai::EvalAltResult>>(lost as i64)
    });
    engine.register_fn("love_weber_stress", |s: &mut DemHandle, volume: Dynamic| {
        let v = finite(&volume, "volume")?;
        if !(v > 0.0) {
            return err("volume must be > 0");
        }
        Ok(s.lock().sim.dem.world.love_weber_stress(v).iter().map(|&c| Dynamic::from(c)).collect::<Array>())
    });
    engine.register_get("particles", |s: &mut DemHandle| s.lock().sim.dem.world.spheres.len() as i64);
    engine.register_get("memory_bytes", |s: &mut DemHandle| s.lock().sim.dem.memory_bytes() as i64);
    engine.register_fn("skin", |s: &mut DemHandle, skin: Dynamic| -> RhaiResult<()> {
        let skin = finite(&skin, "skin")?;
        let mut st = s.lock();
        st.sim.dem.set_skin(skin).or_rhai()?;
        st.sim.auto_skin = false;
        Ok(())
    });
    engine.register_get("skin", |s: &mut DemHandle| s.lock().sim.dem.skin);
    engine.register_get("clumps", |s: &mut DemHandle| s.lock().sim.dem.world.clumps.len() as i64);
    register_cell(engine);
    register_measures(engine);
}

fn cell_axis(name: &str) -> Option<usize> {
    match name {
        "x" => Some(0),
        "y" => Some(1),
        "z" => Some(2),
        _ => None,
    }
}

fn voigt_array(v: &granite_core::math::Voigt) -> Array {
    v.iter().map(|&c| Dynamic::from(c)).collect()
}

/// Periodic cell methods (thesis 1.1.4; YADE's Cell and PeriTriaxController).
fn register_cell(engine: &mut Engine) {
    use granite_core::dem::cell::{AxisGoal, CellControl, PeriodicCell};
    engine.register_fn("periodic", |s: &mut DemHandle, size: Dynamic| {
        let size = vector(&size, 3, "cell size")?;
        if size.iter().any(|&l| !(l > 0.0)) {
            return err("periodic cell sizes must be > 0");
        }
        s.lock().sim.dem.world.set_cell(Some(PeriodicCell::new_box(size)));
        Ok(())
    });
    fn cell_of(s: &DemHandle) -> RhaiResult<granite_core::dem::cell::PeriodicCell> {
        s.lock().sim.dem.world.cell.clone().ok_or_else(|| {
            super::convert::to_rhai(GraniteError::Setup(
                "this simulation has no periodic cell: call periodic([lx, ly, lz]) first".into(),
            ))
        })
    }
    engine.register_fn("cell_velocity_gradient", |s: &mut DemHandle, l: Array| {
        cell_of(s)?;
        if l.len() != 3 {
            return err("the velocity gradient is a 3 x 3 array of rows [[Lxx, Lxy, Lxz], ...]");
        }
        let mut m = nalgebra::Matrix3::zeros();
        for (i, row) in l.iter().enumerate() {
            let r = numbers(row, "velocity gradient row")?;
            if r.len() != 3 {
                return err("each velocity gradient row has 3 entries");
            }
            for j in 0..3 {
                m[(i, j)] = r[j];
            }
        }
        let mut st = s.lock();
        st.sim.dem.world.cell_control = None;
        if let Some(c) = st.sim.dem.world.cell.as_mut() {
            c.velocity_gradient = m;
        }
        Ok(())
    });
    engine.register_fn("cell_update", |s: &mut DemHandle, name: &str| -> RhaiResult<()> {
        cell_of(s)?;
        let update = granite_core::dem::cell::CellUpdate::named(name).or_else(err)?;
        if let Some(c) = s.lock().sim.dem.world.cell.as_mut() {
            c.update = update;
        }
        Ok(())
    });
    engine.register_fn("cell_update", |s: &mut DemHandle| -> RhaiResult<String> {
        Ok(cell_of(s)?.update.name().to_string())
    });
    engine.register_fn("cell_control", |s: &mut DemHandle, opts: Map| {
        cell_of(s)?;
        api_options(&opts, "DemSim", "cell_control")?;
        let mut axes = [AxisGoal::Rate(0.0); 3];
        let mut shear = Vec::new();
        let mut relax_steps = 200.0;
        for (k, v) in &opts {
            if k == "relax_steps" {
                relax_steps = finite(v, "relax_steps")?;
                if !(relax_steps >= 1.0) {
                    return err("`relax_steps` must be >= 1");
                }
                continue;
            }
            if k.len() == 2 {
                let (i, j) = (cell_axis(&k[0..1]).unwrap_or(0), cell_axis(&k[1..2]).unwrap_or(0));
                shear.push((i, j, finite(v, k)?));
                continue;
            }
            let a = cell_axis(k).unwrap_or(0);
            let m = v.clone().try_cast::<Map>().ok_or_else(|| {
                super::convert::to_rhai(GraniteError::Setup(format!(
                    "cell_control `{k}` takes #{{ rate: 1/s }} or #{{ stress: Pa, max_rate: 1/s }}"
                )))
            })?;
            only_keys(&m, &["rate", "stress", "max_rate"], &format!("cell_control `{k}`"))?;
            axes[a] = match (get(&m, "rate"), get(&m, "stress")) {
                (Some(r), None) => AxisGoal::Rate(finite(r, "rate")?),
                (None, Some(t)) => {
                    let max_rate = number(get(&m, "max_rate").unwrap_or(&Dynamic::from(1.0)), "max_rate")?;
                    if !(max_rate > 0.0) {
                        return err("`max_rate` must be > 0");
                    }
                    AxisGoal::Stress { target: finite(t, "stress")?, max_rate }
                }
                _ => return err(format!("cell_control `{k}`: give exactly one of `rate` and `stress`")),
            };
        }
        s.lock().sim.dem.world.cell_control = Some(CellControl::new(axes, shear, relax_steps));
        Ok(())
    });
    engine.register_fn("cell_stress", |s: &mut DemHandle| {
        let cell = cell_of(s)?;
        Ok::<_, Box<rhai::EvalAltResult>>(voigt_array(&s.lock().sim.dem.world.love_weber_stress(cell.volume())))
    });
    engine.register_fn("stress_reached", |s: &mut DemHandle, tolerance: Dynamic| {
        let cell = cell_of(s)?;
        let tol = number(&tolerance, "tolerance")?;
        let st = s.lock();
        let stress = st.sim.dem.world.love_weber_stress(cell.volume());
        Ok::<_, Box<rhai::EvalAltResult>>(
            st.sim.dem.world.cell_control.as_ref().is_some_and(|c| c.stress_reached(&stress, tol)),
        )
    });
    engine.register_fn("cell_size", |s: &mut DemHandle| {
        let cell = cell_of(s)?;
        Ok::<_, Box<rhai::EvalAltResult>>((0..3).map(|a| Dynamic::from(cell.h.column(a).norm())).collect::<Array>())
    });
    engine.register_fn("cell_volume", |s: &mut DemHandle| Ok::<_, Box<rhai::EvalAltResult>>(cell_of(s)?.volume()));
    engine.register_fn("cell_strain", |s: &mut DemHandle| {
        cell_of(s)?;
        let (axial, vol) = s.lock().sim.dem.world.cell_strain().unwrap_or(([0.0; 3], 0.0));
        let mut m = Map::new();
        for (k, v) in ["x", "y", "z"].iter().zip(axial) {
            m.insert((*k).into(), Dynamic::from(v));
        }
        m.insert("volumetric".into(), Dynamic::from(vol));
        Ok::<_, Box<rhai::EvalAltResult>>(m)
    });
    engine.register_fn("reset_cell_strain", |s: &mut DemHandle| {
        let cell = cell_of(s)?;
        s.lock().sim.dem.world.cell_reference = Some(cell.h);
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("void_ratio", |s: &mut DemHandle| {
        cell_of(s)?;
        Ok::<_, Box<rhai::EvalAltResult>>(s.lock().sim.dem.world.void_ratio().unwrap_or(f64::NAN))
    });
}

fn range2(d: Option<&Dynamic>, name: &str) -> RhaiResult<[f64; 2]> {
    let v = numbers(d.unwrap_or(&Dynamic::UNIT), name)?;
    if v.len() != 2 || !(v[1] > v[0]) {
        return err(format!("`{name}` must be [min, max] with min < max"));
    }
    Ok([v[0], v[1]])
}

/// Heap and packing measures (thesis 2.3.2-2.3.3, appendix A).
fn register_measures(engine: &mut Engine) {
    use granite_core::dem::repose::{measure, Heap};
    use granite_core::dem::voids::{
        grains, void_ratio_bounding_box, void_ratio_sub_volume, void_ratio_tetrahedra, SubVolume,
    };
    engine.register_fn("angle_of_repose", |s: &mut DemHandle, opts: Map| {
        api_options(&opts, "DemSim", "angle_of_repose")?;
        let kind = string(get(&opts, "heap").unwrap_or(&Dynamic::from("plane_strain")), "heap")?;
        let d = finite(get(&opts, "d").unwrap_or(&Dynamic::UNIT), "d (grain diameter)")?;
        let heap = match kind.as_str() {
            "plane_strain" => Heap::PlaneStrain {
                x_range: range2(get(&opts, "x_range"), "x_range")?,
                y_range: range2(get(&opts, "y_range"), "y_range")?,
                open_x: finite(get(&opts, "open_x").unwrap_or(&Dynamic::UNIT), "open_x")?,
            },
            "axisymmetric" => {
                let c = numbers(get(&opts, "centre").unwrap_or(&Dynamic::UNIT), "centre")?;
                if c.len() != 2 {
                    return err("`centre` is [x, y] of the heap's axis");
                }
                Heap::Axisymmetric {
                    centre: [c[0], c[1]],
                    radius: finite(get(&opts, "radius").unwrap_or(&Dynamic::UNIT), "radius")?,
                    z_range: range2(get(&opts, "z_range"), "z_range")?,
                }
            }
            other => return err(format!("`heap` is \"plane_strain\" or \"axisymmetric\", got \"{other}\"")),
        };
        let x_min = number(get(&opts, "x_min").unwrap_or(&Dynamic::from(0.32 * d)), "x_min")?;
        let x_max = number(get(&opts, "x_max").unwrap_or(&Dynamic::from(f64::INFINITY)), "x_max")?;
        let positions = {
            let st = s.lock();
            let dem = &st.sim.dem;
            // Spheres (clump members) and the free bodies' monitor points.
            let mut positions = dem.world.spheres.x.clone();
            positions.extend(dem.world.kinds.monitor_positions());
            positions
        };
        let r = measure(&positions, &heap, d, x_min, x_max).or_rhai()?;
        let mut m = Map::new();
        m.insert("angle_deg".into(), Dynamic::from(r.angle_deg));
        m.insert("std_deg".into(), Dynamic::from(r.std_deg));
        m.insert("slope".into(), Dynamic::from(r.linear[0]));
        m.insert("quadratic".into(), Dynamic::from(r.quadratic.iter().map(|&c| Dynamic::from(c)).collect::<Array>()));
        m.insert("surface_points".into(), Dynamic::from(r.points.len() as i64));
        Ok(m)
    });
    engine.register_fn("void_ratio_sub_volume", |s: &mut DemHandle, opts: Map| {
        api_options(&opts, "DemSim", "void_ratio_sub_volume")?;
        let c = finite(get(&opts, "c").unwrap_or(&Dynamic::from(0.8)), "c")?;
        if !(c > 0.5 && c <= 1.0) {
            return err(format!("`c` must be in ]0.5, 1], got {c}"));
        }
        let n_mc = integer(get(&opts, "n_mc").unwrap_or(&Dynamic::from(100_i64)), "n_mc")?.max(1) as usize;
        let seed = integer(get(&opts, "seed").unwrap_or(&Dynamic::from(1_i64)), "seed")? as u64;
        let shape = string(get(&opts, "shape").unwrap_or(&Dynamic::from("box")), "shape")?;
        let g = grains(&s.lock().sim.dem);
        if g.is_empty() {
            return err("no particles to measure");
        }
        let sub = match shape.as_str() {
            "box" => SubVolume::homothetic_box(&g, c),
            "cone" => SubVolume::homothetic_cone(&g, c),
            other => return err(format!("`shape` is \"box\" or \"cone\", got \"{other}\"")),
        };
        Ok(void_ratio_sub_volume(&g, &sub, n_mc, seed))
    });
    engine.register_fn("void_ratio_tetrahedra", |s: &mut DemHandle, opts: Map| {
        api_options(&opts, "DemSim", "void_ratio_tetrahedra")?;
        let n_mc = integer(get(&opts, "n_mc").unwrap_or(&Dynamic::from(100_i64)), "n_mc")?.max(1) as usize;
        let seed = integer(get(&opts, "seed").unwrap_or(&Dynamic::from(1_i64)), "seed")? as u64;
        let g = grains(&s.lock().sim.dem);
        if g.len() < 4 {
            return err("the tetrahedron method needs at least 4 particles");
        }
        Ok::<_, Box<rhai::EvalAltResult>>(void_ratio_tetrahedra(&g, n_mc, seed).0)
    });
    engine.register_fn("void_ratio_bounding_box", |s: &mut DemHandle| {
        let g = grains(&s.lock().sim.dem);
        if g.is_empty() {
            return err("no particles to measure");
        }
        Ok(void_ratio_bounding_box(&g))
    });
    engine.register_fn("global_stress", |s: &mut DemHandle, volume: Dynamic| {
        let v = finite(&volume, "volume")?;
        if !(v > 0.0) {
            return err("volume must be > 0");
        }
        Ok(voigt_array(&s.lock().sim.dem.world.global_stress_with_gravity(v)))
    });
}
