//! Potential particles from scripts: one particle of a registered shape or of planes of its own,
//! clouds of them (`clump_cloud` with a potential shape, in dem_api), and the velocity of fixed
//! ones (moving container parts).

use super::convert::{err, finite, get, numbers, param_map, string, vector, OrRhai, RhaiResult};
use super::dem_api::{DemHandle, DemMaterialHandle};
use granite_core::dem::potential::shape::{PotentialShape, MASS_RESOLUTION};
use granite_core::math::Vec3;
use nalgebra::{UnitQuaternion, Vector3};
use rhai::{Dynamic, Engine, Map};
use std::sync::Arc;

/// Keys of `sim.potential` that are not a shape's parameters.
const OWN_KEYS: [&str; 9] = ["shape", "planes", "r", "R", "k", "rotation", "velocity", "fixed", "spin"];

/// The shape `opts` asks for: `planes` with `r`, `R`, `k`, or a registered shape by name
/// (`shape`, default `potential_tetra`) with its parameters.
fn shape_from(s: &DemHandle, opts: &Map) -> RhaiResult<Arc<PotentialShape>> {
    if let Some(planes) = get(opts, "planes") {
        super::convert::only_keys(opts, &OWN_KEYS, "sim.potential(...) with `planes`")?;
        let rows = planes
            .clone()
            .into_array()
            .or_else(|_| err("`planes` must be an array of [a, b, c, d] (a x + b y + c z = d)"))?;
        let mut list = Vec::with_capacity(rows.len());
        for (i, row) in rows.iter().enumerate() {
            let v = numbers(row, "plane")?;
            if v.len() != 4 {
                return err(format!(
                    "plane {} must be [a, b, c, d] (a x + b y + c z = d, the normal outwards), got {} numbers",
                    i + 1,
                    v.len()
                ));
            }
            list.push(([v[0], v[1], v[2]], v[3]));
        }
        let need = |key: &str| match get(opts, key) {
            Some(d) => finite(d, key),
            None => err(format!("a potential particle from `planes` needs `{key}`")),
        };
        let shape = PotentialShape::new(&list, need("r")?, need("R")?, need("k")?, MASS_RESOLUTION).or_rhai()?;
        return Ok(Arc::new(shape));
    }
    let name = get(opts, "shape").map(|d| string(d, "shape")).transpose()?.unwrap_or_else(|| "potential_tetra".into());
    let skip: Vec<&str> = OWN_KEYS.iter().copied().filter(|k| !matches!(*k, "r" | "R" | "k")).collect();
    let given = param_map(opts, &skip, &name)?;
    let model = s.lock().ctx.registry().build_shape(&name, &given).or_rhai()?;
    match model.potential() {
        Some(p) => Ok(p),
        None => err(format!("shape `{name}` is made of spheres: use sim.clump or sim.clump_cloud for it")),
    }
}

/// A rotation from a rotation vector `[rx, ry, rz]` (axis times angle in radians).
fn rotation_from(opts: &Map) -> RhaiResult<UnitQuaternion<f64>> {
    match get(opts, "rotation") {
        Some(d) => {
            let r = vector(d, 3, "rotation")?;
            Ok(UnitQuaternion::from_scaled_axis(Vector3::new(r[0], r[1], r[2])))
        }
        None => Ok(UnitQuaternion::identity()),
    }
}

fn vector_or_zero(opts: &Map, key: &str) -> RhaiResult<Vec3> {
    get(opts, key).map(|d| vector(d, 3, key)).transpose().map(|v| v.unwrap_or([0.0; 3]))
}

/// The index of the potential particle with `id`.
fn index_of(s: &DemHandle, id: i64) -> RhaiResult<usize> {
    let st = s.lock();
    let p = &st.sim.dem.potentials;
    match p.id.iter().position(|&i| i as i64 == id) {
        Some(i) => Ok(i),
        None => err(format!("no potential particle with id {id} ({} potential particles)", p.len())),
    }
}

pub(super) fn register(engine: &mut Engine) {
    engine.register_fn("potential", |s: &mut DemHandle, m: DemMaterialHandle, centre: Dynamic, opts: Map| {
        let centre = vector(&centre, 3, "centre")?;
        let shape = shape_from(s, &opts)?;
        let (q, v, spin) = (rotation_from(&opts)?, vector_or_zero(&opts, "velocity")?, vector_or_zero(&opts, "spin")?);
        let fixed = match get(&opts, "fixed") {
            Some(d) => d.as_bool().or_else(|_| err("`fixed` is true or false"))?,
            None => false,
        };
        let mut st = s.lock();
        let dem = &mut st.sim.dem;
        let i = dem.add_potential(m.index_in(s)?, &shape, centre, q, v, fixed).or_rhai()?;
        dem.potentials.w[i] = spin;
        Ok::<_, Box<rhai::EvalAltResult>>(dem.potentials.id[i] as i64)
    });
    engine.register_fn("potential_velocity", |s: &mut DemHandle, id: i64, v: Dynamic| {
        let v = vector(&v, 3, "velocity")?;
        let i = index_of(s, id)?;
        s.lock().sim.dem.potentials.v[i] = v;
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("potential_body", |s: &mut DemHandle, id: i64| {
        let i = index_of(s, id)?;
        let st = s.lock();
        let p = &st.sim.dem.potentials;
        let array = |v: Vec3| Dynamic::from(v.iter().map(|c| Dynamic::from(*c)).collect::<rhai::Array>());
        let q = p.q[i].scaled_axis();
        let mut map = Map::new();
        map.insert("id".into(), Dynamic::from(p.id[i] as i64));
        map.insert("position".into(), array(p.x[i]));
        map.insert("rotation".into(), array([q[0], q[1], q[2]]));
        map.insert("velocity".into(), array(p.v[i]));
        map.insert("spin".into(), array(p.w[i]));
        map.insert("force".into(), array(p.force[i]));
        map.insert("torque".into(), array(p.torque[i]));
        map.insert("mass".into(), Dynamic::from(p.mass[i]));
        map.insert("volume".into(), Dynamic::from(p.shape_of(i).volume));
        map.insert("fixed".into(), Dynamic::from(p.fixed[i]));
        Ok::<_, Box<rhai::EvalAltResult>>(map)
    });
    engine.register_fn("potential_ids", |s: &mut DemHandle| {
        s.lock().sim.dem.potentials.id.iter().map(|&i| Dynamic::from(i as i64)).collect::<rhai::Array>()
    });
    engine.register_get("potentials", |s: &mut DemHandle| s.lock().sim.dem.potentials.len() as i64);
}

/// Adds potential particles of `shape` at `centres`, each turned by a uniformly random rotation
/// drawn from `seed` (Shoemake's method, as clumps are). Returns how many.
pub(super) fn add_cloud(
    s: &DemHandle,
    m: &DemMaterialHandle,
    shape: &Arc<PotentialShape>,
    centres: &[Vec3],
    seed: u64,
) -> RhaiResult<i64> {
    let mut st = s.lock();
    for (k, c) in centres.iter().enumerate() {
        let u = [0, 1, 2].map(|j| granite_core::ext::contact::uniform(seed ^ 0xC1u64, (3 * k + j) as u64));
        let (_, q) = granite_core::dem::clump::place_template(&[], *c, u);
        st.sim.dem.add_potential(m.index_in(s)?, shape, *c, q, [0.0; 3], false).or_rhai()?;
    }
    Ok(centres.len() as i64)
}
