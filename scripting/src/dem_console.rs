//! Script calls on single bodies and contacts of a DEM simulation (YADE's `O.bodies`,
//! `O.interactions`, `O.forces`), and live changes of contact laws and materials that keep the
//! contacts' history. Every call acts between two steps, also on a run going in the background.

use super::convert::elastic_from;
use super::convert::{api_options, err, finite, get, integer, number, string, vector, OrRhai, RhaiResult};
use super::dem_api::{DemHandle, DemMaterialHandle};
use granite_core::dem::bodies::{dofs_name, parse_dofs, SphereEdit};
use granite_core::dem::inspect::{ContactView, Member};
use granite_core::dem::particles::FREE;
use granite_core::dem::DemSim;
use granite_core::error::GraniteError;
use granite_core::math::Vec3;
use granite_core::registry::ParamMap;
use rhai::{Array, Dynamic, Engine, Map};

fn vec3(v: Vec3) -> Dynamic {
    Dynamic::from(v.iter().map(|&c| Dynamic::from(c)).collect::<Array>())
}

fn id_of(id: i64) -> RhaiResult<u64> {
    if id < 0 {
        return err(format!("a sphere id is >= 0, got {id}"));
    }
    Ok(id as u64)
}

/// Everything about one sphere, by index.
fn body_map(dem: &DemSim, i: usize) -> Map {
    let s = &dem.world.spheres;
    let id = s.id[i];
    let (external_force, external_torque) = dem.world.external_load(id);
    let mut m = Map::new();
    m.insert("id".into(), Dynamic::from(id as i64));
    m.insert("position".into(), vec3(s.x[i]));
    m.insert("velocity".into(), vec3(s.v[i]));
    m.insert("spin".into(), vec3(s.w[i]));
    m.insert("force".into(), vec3(s.force[i]));
    m.insert("torque".into(), vec3(s.torque[i]));
    m.insert("external_force".into(), vec3(external_force));
    m.insert("external_torque".into(), vec3(external_torque));
    m.insert("radius".into(), Dynamic::from(s.radius[i]));
    m.insert("mass".into(), Dynamic::from(s.mass[i]));
    m.insert("inertia".into(), Dynamic::from(s.inertia[i]));
    let material = dem.world.materials.get(s.material[i] as usize).map_or(String::new(), |m| m.name.clone());
    m.insert("material".into(), Dynamic::from(material));
    let clump = s.clump[i];
    m.insert("clump".into(), if clump == FREE { Dynamic::UNIT } else { Dynamic::from(clump as i64) });
    m.insert("fixed".into(), Dynamic::from(dofs_name(s.blocked[i])));
    m
}

/// A contact as scripts see it: the first member's id and kind (`id1`, `kind1`: "sphere" or a
/// body's kind), the other's (`id2`, `kind2`) or its wall's index (`wall`), which of a body's
/// contact points with it this is (`part`), and the contact.
pub(crate) fn contact_map(dem: &DemSim, c: &ContactView) -> Map {
    let mut m = Map::new();
    let w = &dem.world;
    let grain = |member: Member| match member {
        Member::Sphere(i) => Some((w.spheres.id[i] as i64, "sphere".to_string())),
        Member::Body(i) => Some((w.kinds.id[i] as i64, w.kinds.kind_name(i).to_string())),
        Member::Wall(_) => None,
    };
    for (member, id, kind) in [(c.first, "id1", "kind1"), (c.other, "id2", "kind2")] {
        if let Some((number, name)) = grain(member) {
            m.insert(id.into(), Dynamic::from(number));
            m.insert(kind.into(), Dynamic::from(name));
        }
    }
    if let Member::Wall(index) = c.other {
        m.insert("wall".into(), Dynamic::from(index as i64));
    }
    if let Member::Body(_) = c.first {
        m.insert("part".into(), Dynamic::from(c.part as i64));
    }
    if c.shift != [0; 3] {
        m.insert("image".into(), Dynamic::from(c.shift.iter().map(|&s| Dynamic::from(s as i64)).collect::<Array>()));
    }
    m.insert("point".into(), vec3(c.point));
    m.insert("normal".into(), vec3(c.normal));
    m.insert("overlap".into(), Dynamic::from(c.overlap));
    m.insert("force".into(), vec3(c.force));
    m.insert("normal_force".into(), Dynamic::from(c.normal_force));
    m.insert("shear_force".into(), vec3(c.shear_force));
    if let Some(law) = dem.world.contacts.laws.get(c.law as usize) {
        m.insert("law".into(), Dynamic::from(law.name().to_string()));
        let names = law.pair_param_names();
        let mut params = Map::new();
        for (k, v) in c.params.iter().enumerate() {
            let name = names.get(k).map_or_else(|| format!("p{k}"), |n| n.to_string());
            params.insert(name.into(), Dynamic::from(*v));
        }
        m.insert("params".into(), Dynamic::from(params));
    }
    m
}

/// Reads the changes of `sim.set_body` from its options.
fn sphere_edit(opts: &Map, material: Option<u16>) -> RhaiResult<SphereEdit> {
    api_options(opts, "DemSim", "set_body")?;
    let v3 = |k: &str| get(opts, k).map(|d| vector(d, 3, k)).transpose();
    let fixed = match get(opts, "fixed") {
        None => None,
        Some(d) if d.is_bool() => {
            Some(if d.as_bool().unwrap_or(false) { granite_core::dem::particles::dof::ALL } else { 0 })
        }
        Some(d) => Some(parse_dofs(&string(d, "fixed")?).or_rhai()?),
    };
    let radius = get(opts, "radius").map(|d| finite(d, "radius")).transpose()?;
    let mass = get(opts, "mass").map(|d| finite(d, "mass")).transpose()?;
    Ok(SphereEdit {
        position: v3("position")?,
        velocity: v3("velocity")?,
        spin: v3("spin")?,
        radius,
        material,
        mass,
        blocked: fixed,
        force: v3("force")?,
        torque: v3("torque")?,
    })
}

impl DemHandle {
    fn with_body<T>(&self, id: i64, f: impl FnOnce(&mut DemSim, usize) -> RhaiResult<T>) -> RhaiResult<T> {
        let id = id_of(id)?;
        let mut st = self.lock();
        let dem = &mut st.sim.dem;
        let i = dem.world.sphere_index_or_err(id).or_rhai()?;
        f(dem, i)
    }

    /// The parameters of the law that a key (a material pair, or the default law) uses now.
    fn law_params(&self, pair: Option<(u16, u16)>) -> RhaiResult<(String, ParamMap)> {
        let st = self.lock();
        let dem = &st.sim.dem;
        let Some(idx) = dem.world.law_index(pair) else {
            return err(match pair {
                Some(_) => {
                    "no contact law for this pair of materials (and no default law): call contact_law(...) first"
                }
                None => "no default contact law: call contact_law(\"name\", #{ ... }) first",
            });
        };
        let law = &dem.world.contacts.laws[idx as usize];
        let params = law.params().iter().filter(|(_, v)| !v.is_nan()).map(|(k, v)| (k.to_string(), v)).collect();
        Ok((law.name().to_string(), params))
    }

    /// Changes some parameters of the law a key uses (the others keep their values), from the
    /// next step on, keeping every contact and its history.
    fn set_contact_params(&mut self, pair: Option<(u16, u16)>, changes: Map) -> RhaiResult<()> {
        let (name, mut params) = self.law_params(pair)?;
        for (k, v) in &changes {
            params.insert(k.to_string(), number(v, &format!("{k}` of `{name}"))?);
        }
        let mut st = self.lock();
        let law = st.ctx.registry().build_contact_law(&name, &params).or_rhai()?;
        st.sim.dem.world.set_contact_law(law, pair).or_rhai()
    }
}

fn law_map(name: String, params: ParamMap) -> Map {
    let mut m = Map::new();
    m.insert("law".into(), Dynamic::from(name));
    for (k, v) in params {
        m.insert(k.into(), Dynamic::from(v));
    }
    m
}

pub(super) fn register(engine: &mut Engine) {
    register_bodies(engine);
    register_contacts(engine);
    register_live_changes(engine);
    register_energy(engine);
}

fn register_bodies(engine: &mut Engine) {
    engine.register_fn("body", |s: &mut DemHandle, id: i64| s.with_body(id, |dem, i| Ok(body_map(dem, i))));
    engine.register_fn("set_body", |s: &mut DemHandle, id: i64, opts: Map| {
        let material = match get(&opts, "material") {
            Some(m) => Some(
                m.clone()
                    .try_cast::<DemMaterialHandle>()
                    .ok_or_else(|| {
                        super::convert::to_rhai(GraniteError::Setup(
                            "`material` of set_body is a material made by sim.material(...)".into(),
                        ))
                    })?
                    .index_in(s)?,
            ),
            None => None,
        };
        s.with_body(id, |dem, i| {
            let edit = sphere_edit(&opts, material)?;
            dem.world.edit_sphere(i, &edit).or_rhai()
        })
    });
    fn erase(s: &mut DemHandle, ids: Vec<u64>) -> RhaiResult<i64> {
        let mut st = s.lock();
        st.sim.dem.world.erase_spheres(&ids).map(|n| n as i64).or_rhai()
    }
    engine.register_fn("erase", |s: &mut DemHandle, id: i64| erase(s, vec![id_of(id)?]));
    engine.register_fn("erase", |s: &mut DemHandle, ids: Array| {
        let ids = ids.iter().map(|d| id_of(integer(d, "id")?)).collect::<RhaiResult<Vec<u64>>>()?;
        erase(s, ids)
    });
    // Bulk arrays, in the order of `ids()`: one call for all spheres instead of one per sphere.
    engine.register_fn("ids", |s: &mut DemHandle| {
        s.lock().sim.dem.world.spheres.id.iter().map(|&i| Dynamic::from(i as i64)).collect::<Array>()
    });
    fn rows(v: &[Vec3]) -> Array {
        v.iter().map(|x| vec3(*x)).collect()
    }
    engine.register_fn("positions", |s: &mut DemHandle| rows(&s.lock().sim.dem.world.spheres.x));
    engine.register_fn("velocities", |s: &mut DemHandle| rows(&s.lock().sim.dem.world.spheres.v));
    engine.register_fn("spins", |s: &mut DemHandle| rows(&s.lock().sim.dem.world.spheres.w));
    engine.register_fn("forces", |s: &mut DemHandle| rows(&s.lock().sim.dem.world.spheres.force));
    engine.register_fn("torques", |s: &mut DemHandle| rows(&s.lock().sim.dem.world.spheres.torque));
    engine.register_fn("radii", |s: &mut DemHandle| {
        s.lock().sim.dem.world.spheres.radius.iter().map(|&r| Dynamic::from(r)).collect::<Array>()
    });
    engine.register_fn("contact_counts", |s: &mut DemHandle| {
        s.lock().sim.dem.world.contact_counts().iter().map(|&c| Dynamic::from(c as i64)).collect::<Array>()
    });
}

fn register_contacts(engine: &mut Engine) {
    engine.register_fn("contacts", |s: &mut DemHandle| {
        let st = s.lock();
        let dem = &st.sim.dem;
        dem.world.touching_contacts().iter().map(|c| Dynamic::from(contact_map(dem, c))).collect::<Array>()
    });
    engine.register_fn("contact", |s: &mut DemHandle, id1: i64, id2: i64| {
        let (a, b) = (id_of(id1)?, id_of(id2)?);
        let st = s.lock();
        let dem = &st.sim.dem;
        let (i, j) = (dem.world.sphere_index_or_err(a).or_rhai()?, dem.world.sphere_index_or_err(b).or_rhai()?);
        Ok::<_, Box<rhai::EvalAltResult>>(
            dem.world.contact_between(i, j).map_or(Dynamic::UNIT, |c| Dynamic::from(contact_map(dem, &c))),
        )
    });
    engine.register_fn("wall_contact", |s: &mut DemHandle, id: i64, wall: i64| {
        let id = id_of(id)?;
        let st = s.lock();
        let dem = &st.sim.dem;
        let i = dem.world.sphere_index_or_err(id).or_rhai()?;
        if wall < 0 || wall as usize >= dem.world.walls.len() {
            return err(format!("wall index {wall} out of range 0..{}", dem.world.walls.len()));
        }
        Ok(dem.world.wall_contact_of(i, wall as usize).map_or(Dynamic::UNIT, |c| Dynamic::from(contact_map(dem, &c))))
    });
    engine.register_fn("fabric", |s: &mut DemHandle| {
        let f = s.lock().sim.dem.world.fabric_tensor();
        f.iter().map(|row| vec3(*row)).collect::<Array>()
    });
}

fn register_energy(engine: &mut Engine) {
    engine.register_fn("track_energy", |s: &mut DemHandle, on: bool| s.lock().sim.dem.track_energy(on).or_rhai());
    engine.register_fn("energy", |s: &mut DemHandle| {
        let st = s.lock();
        let Some(e) = st.sim.dem.energy.as_ref() else {
            return err("energy(): call sim.track_energy(true) first (from the next step on)");
        };
        let mut m = Map::new();
        for (k, v) in e.entries() {
            m.insert(k.into(), Dynamic::from(v));
        }
        Ok(m)
    });
}

fn register_live_changes(engine: &mut Engine) {
    engine.register_fn("contact_law_params", |s: &mut DemHandle| {
        let (name, params) = s.law_params(None)?;
        Ok::<_, Box<rhai::EvalAltResult>>(law_map(name, params))
    });
    engine.register_fn("contact_law_params", |s: &mut DemHandle, a: DemMaterialHandle, b: DemMaterialHandle| {
        let (name, params) = s.law_params(Some((a.index_in(s)?, b.index_in(s)?)))?;
        Ok::<_, Box<rhai::EvalAltResult>>(law_map(name, params))
    });
    engine.register_fn("set_contact_params", |s: &mut DemHandle, changes: Map| s.set_contact_params(None, changes));
    // Every pair of materials that one material is in (walls' materials included).
    engine.register_fn("set_contact_params", |s: &mut DemHandle, m: DemMaterialHandle, changes: Map| {
        let count = s.lock().sim.dem.world.materials.len() as u16;
        for other in 0..count {
            let pair = Some((m.index_in(s)?, other));
            if s.lock().sim.dem.world.law_index(pair).is_some() {
                s.set_contact_params(pair, changes.clone())?;
            }
        }
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn(
        "set_contact_params",
        |s: &mut DemHandle, a: DemMaterialHandle, b: DemMaterialHandle, changes: Map| {
            let pair = (a.index_in(s)?, b.index_in(s)?);
            s.set_contact_params(Some(pair), changes)
        },
    );
    engine.register_fn("set_material", |s: &mut DemHandle, m: DemMaterialHandle, opts: Map| {
        api_options(&opts, "DemSim", "set_material")?;
        let elastic = elastic_from(&opts, &format!("material \"{}\"", m.name()))?;
        if elastic.is_none() {
            return err("set_material: give `young` and `poisson`, or `rigid: true`");
        }
        let index = m.index_in(s)?;
        s.lock().sim.dem.world.set_material_elastic(index, elastic).or_rhai()
    });
}
