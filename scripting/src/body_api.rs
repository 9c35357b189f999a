//! Bodies of plugin kinds from scripts (`ext::body`: capsules, ...): one body of a registered kind
//! (`sim.add_body(kind, ...)`, `sim.capsule(...)`), clouds of them (`clump_cloud` with a kind's name,
//! in dem_api), and reading one back.

use super::convert::{err, get, only_keys, param_map, vector, OrRhai, RhaiResult};
use super::dem_api::{DemHandle, DemMaterialHandle};
use granite_core::dem::kinds::NewBody;
use granite_core::math::Vec3;
use nalgebra::{UnitQuaternion, Vector3};
use rhai::{Dynamic, Engine, Map};

/// Keys of `sim.body` that are not the shape's parameters.
const OWN_KEYS: [&str; 5] = ["axis", "rotation", "velocity", "spin", "fixed"];

/// The orientation `opts` asks for: `axis` (where the body's z axis points: a capsule's axis), or
/// a rotation vector `rotation` (axis times angle, rad); none: the body frame.
fn orientation(opts: &Map) -> RhaiResult<UnitQuaternion<f64>> {
    match (get(opts, "axis"), get(opts, "rotation")) {
        (Some(_), Some(_)) => err("give `axis` or `rotation`, not both"),
        (Some(a), None) => {
            let a = vector(a, 3, "axis")?;
            let a = Vector3::new(a[0], a[1], a[2]);
            if !(a.norm() > 0.0) {
                return err("`axis` must be a non-zero vector");
            }
            // Turned the shortest way; the opposite of z turns about x.
            Ok(UnitQuaternion::rotation_between(&Vector3::z(), &a)
                .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)))
        }
        (None, Some(r)) => {
            let r = vector(r, 3, "rotation")?;
            Ok(UnitQuaternion::from_scaled_axis(Vector3::new(r[0], r[1], r[2])))
        }
        (None, None) => Ok(UnitQuaternion::identity()),
    }
}

fn vector_or_zero(opts: &Map, key: &str) -> RhaiResult<Vec3> {
    get(opts, key).map(|d| vector(d, 3, key)).transpose().map(|v| v.unwrap_or([0.0; 3]))
}

/// Adds one body of `kind`; its id.
fn add(s: &DemHandle, kind: &str, m: &DemMaterialHandle, centre: &Dynamic, opts: &Map) -> RhaiResult<i64> {
    let given = param_map(opts, &OWN_KEYS, kind)?;
    let registry = s.lock().ctx.registry().clone();
    let factory = registry.body_kind(kind).or_rhai()?;
    let known: Vec<&str> = factory.param_specs().iter().map(|p| p.name).chain(OWN_KEYS).collect();
    // A kind whose shapes take a list of values (the planes of a potential particle: a1, b1, ...)
    // names them itself: what it builds from is allowed.
    if let Err(e) = only_keys(opts, &known, &format!("sim.add_body(\"{kind}\", ...)")) {
        if factory.build_from(&given).is_err() {
            return Err(e);
        }
    }
    add_with(s, kind, &given, m, centre, opts)
}

/// Adds one body of `kind` from its shape's parameters `given`, placed and set moving as `opts`
/// says (`axis` or `rotation`, `velocity`, `spin`, `fixed`); its id.
pub(super) fn add_with(
    s: &DemHandle,
    kind: &str,
    given: &granite_core::params::ParamMap,
    m: &DemMaterialHandle,
    centre: &Dynamic,
    opts: &Map,
) -> RhaiResult<i64> {
    let centre = vector(centre, 3, "centre")?;
    let registry = s.lock().ctx.registry().clone();
    let factory = registry.body_kind(kind).or_rhai()?;
    let shape = factory.build_from(given).or_rhai()?;
    let fixed = match get(opts, "fixed") {
        Some(d) => d.as_bool().or_else(|_| err("`fixed` is true or false"))?,
        None => false,
    };
    let meetings = registry.body_pair_geometries();
    let body = NewBody {
        kind: factory.as_ref(),
        meetings: &meetings,
        shape,
        material: m.index_in(s)?,
        x: centre,
        q: orientation(opts)?,
        v: vector_or_zero(opts, "velocity")?,
        w: vector_or_zero(opts, "spin")?,
        fixed,
    };
    let mut st = s.lock();
    let dem = &mut st.sim.dem;
    let i = dem.world.add_body(body).or_rhai()?;
    Ok(dem.world.kinds.id[i] as i64)
}

/// The index of the body with `id`.
pub(super) fn index_of(s: &DemHandle, id: i64) -> RhaiResult<usize> {
    let st = s.lock();
    let k = &st.sim.dem.world.kinds;
    match k.id.iter().position(|&i| i as i64 == id) {
        Some(i) => Ok(i),
        None => err(format!("no body with id {id} ({} bodies)", k.len())),
    }
}

pub(super) fn register(engine: &mut Engine) {
    engine.register_fn(
        "add_body",
        |s: &mut DemHandle, kind: &str, m: DemMaterialHandle, centre: Dynamic, opts: Map| {
            add(s, kind, &m, &centre, &opts)
        },
    );
    engine.register_fn("capsule", |s: &mut DemHandle, m: DemMaterialHandle, centre: Dynamic, opts: Map| {
        add(s, "capsule", &m, &centre, &opts)
    });
    engine.register_fn("body_state", state);
    register_motion(engine);
}

/// A body's state as a map.
pub(super) fn state(s: &mut DemHandle, id: i64) -> RhaiResult<Map> {
    let i = index_of(s, id)?;
    let st = s.lock();
    let k = &st.sim.dem.world.kinds;
    let array = |v: Vec3| Dynamic::from(v.iter().map(|c| Dynamic::from(*c)).collect::<rhai::Array>());
    let q = k.q[i].scaled_axis();
    let axis = k.q[i] * Vector3::z();
    let mut map = Map::new();
    map.insert("id".into(), Dynamic::from(k.id[i] as i64));
    map.insert("kind".into(), Dynamic::from(k.family_name(i).to_string()));
    map.insert("position".into(), array(k.x[i]));
    map.insert("rotation".into(), array([q[0], q[1], q[2]]));
    map.insert("axis".into(), array([axis[0], axis[1], axis[2]]));
    map.insert("velocity".into(), array(k.v[i]));
    map.insert("spin".into(), array(k.w[i]));
    map.insert("force".into(), array(k.force[i]));
    map.insert("torque".into(), array(k.torque[i]));
    map.insert("mass".into(), Dynamic::from(k.mass[i]));
    map.insert("volume".into(), Dynamic::from(k.shapes[k.shape[i] as usize].volume()));
    map.insert("fixed".into(), Dynamic::from(k.fixed[i]));
    Ok(map)
}

fn register_motion(engine: &mut Engine) {
    engine.register_fn("body_velocity", |s: &mut DemHandle, id: i64, v: Dynamic| {
        let v = vector(&v, 3, "velocity")?;
        let i = index_of(s, id)?;
        s.lock().sim.dem.world.kinds.v[i] = v;
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("body_spin", |s: &mut DemHandle, id: i64, w: Dynamic| {
        let w = vector(&w, 3, "spin")?;
        let i = index_of(s, id)?;
        s.lock().sim.dem.world.kinds.w[i] = w;
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("body_ids", |s: &mut DemHandle| {
        s.lock().sim.dem.world.kinds.id.iter().map(|&i| Dynamic::from(i as i64)).collect::<rhai::Array>()
    });
    engine.register_get("bodies", |s: &mut DemHandle| s.lock().sim.dem.world.kinds.len() as i64);
    engine.register_fn("body_contacts", |s: &mut DemHandle, id: i64| contacts(s, id));
}

/// A body's touching contacts as maps, seen from it: what it touches (`with`, `id`, `kind`) and
/// the contact as `sim.contacts()` shows it (force on this body).
fn contacts(s: &mut DemHandle, id: i64) -> RhaiResult<rhai::Array> {
    use granite_core::dem::inspect::Member;
    let i = index_of(s, id)?;
    let st = s.lock();
    let dem = &st.sim.dem;
    let world = &dem.world;
    let list = world.body_contacts_of(i).into_iter().map(|c| {
        let mut map = super::dem_console::contact_map(dem, &c);
        let (with, other, kind) = match c.other {
            Member::Body(j) => ("body", world.kinds.id[j] as i64, world.kinds.kind_name(j).to_string()),
            Member::Wall(w) => ("wall", w as i64, world.walls[w].name.clone()),
            Member::Sphere(j) => ("sphere", world.spheres.id[j] as i64, "sphere".to_string()),
        };
        map.insert("with".into(), Dynamic::from(with.to_string()));
        map.insert("id".into(), Dynamic::from(other));
        map.insert("kind".into(), Dynamic::from(kind));
        Dynamic::from(map)
    });
    Ok(list.collect())
}

/// Whether `name` is a registered body kind.
pub(super) fn is_kind(s: &DemHandle, name: &str) -> bool {
    s.lock().ctx.registry().body_kind(name).is_ok()
}

/// The bounding radius of a body of `kind` with the parameters of `opts` (skipping `skip`).
pub(super) fn bounding_radius(s: &DemHandle, kind: &str, opts: &Map, skip: &[&str]) -> RhaiResult<f64> {
    let given = param_map(opts, skip, kind)?;
    let shape = s.lock().ctx.registry().build_body_shape(kind, &given).or_rhai()?;
    Ok(shape.bounding_radius())
}

/// Adds bodies of `kind` at `centres`, each turned by a uniformly random rotation drawn from
/// `seed` (Shoemake's method, as clumps are). Returns how many.
pub(super) fn add_cloud(
    s: &DemHandle,
    kind: &str,
    m: &DemMaterialHandle,
    (opts, skip): (&Map, &[&str]),
    centres: &[Vec3],
    seed: u64,
) -> RhaiResult<i64> {
    let given = param_map(opts, skip, kind)?;
    let registry = s.lock().ctx.registry().clone();
    let factory = registry.body_kind(kind).or_rhai()?;
    let shape = registry.build_body_shape(kind, &given).or_rhai()?;
    let material = m.index_in(s)?;
    let meetings = registry.body_pair_geometries();
    let mut st = s.lock();
    for (k, c) in centres.iter().enumerate() {
        let u = [0, 1, 2].map(|j| granite_core::ext::contact::uniform(seed ^ 0xC1u64, (3 * k + j) as u64));
        let (_, q) = granite_core::dem::clump::place_template(&[], *c, u);
        let body = NewBody {
            kind: factory.as_ref(),
            meetings: &meetings,
            shape: shape.clone(),
            material,
            x: *c,
            q,
            v: [0.0; 3],
            w: [0.0; 3],
            fixed: false,
        };
        st.sim.dem.world.add_body(body).or_rhai()?;
    }
    Ok(centres.len() as i64)
}
