//! Potential particles from scripts: the `potential` family of body kinds (`potential_tetra`,
//! `potential_box`, and `potential` of planes of the user's own) under the names their users
//! know: `sim.potential(...)`, `potential_velocity`, `potential_body`, `potential_ids` and
//! `sim.potentials`. Clouds of them come from `clump_cloud` with a potential kind's name.

use super::convert::{err, finite, get, numbers, only_keys, param_map, string, vector, RhaiResult};
use super::dem_api::{DemHandle, DemMaterialHandle};
use granite_core::params::ParamMap;
use rhai::{Dynamic, Engine, Map};

/// The family of the potential kinds.
const FAMILY: &str = "potential";
/// Keys of `sim.potential` that are not a shape's parameters.
const OWN_KEYS: [&str; 6] = ["shape", "planes", "rotation", "velocity", "fixed", "spin"];

/// The kind and parameters `opts` asks for: `planes` with `r`, `R`, `k` (kind `potential`), or a
/// potential kind by name (`shape`, default `potential_tetra`) with its parameters.
fn kind_and_params(s: &DemHandle, opts: &Map) -> RhaiResult<(String, ParamMap)> {
    if let Some(planes) = get(opts, "planes") {
        let mut allowed = OWN_KEYS.to_vec();
        allowed.extend(["r", "R", "k"]);
        only_keys(opts, &allowed, "sim.potential(...) with `planes`")?;
        let rows = planes
            .clone()
            .into_array()
            .or_else(|_| err("`planes` must be an array of [a, b, c, d] (a x + b y + c z = d)"))?;
        let mut given = ParamMap::new();
        for key in ["r", "R", "k"] {
            match get(opts, key) {
                Some(d) => given.insert(key.into(), finite(d, key)?),
                None => return err(format!("a potential particle from `planes` needs `{key}`")),
            };
        }
        for (i, row) in rows.iter().enumerate() {
            let v = numbers(row, "plane")?;
            if v.len() != 4 {
                return err(format!(
                    "plane {} must be [a, b, c, d] (a x + b y + c z = d, the normal outwards), got {} numbers",
                    i + 1,
                    v.len()
                ));
            }
            for (c, value) in ["a", "b", "c", "d"].iter().zip(v) {
                given.insert(format!("{c}{}", i + 1), value);
            }
        }
        return Ok(("potential".into(), given));
    }
    let name = get(opts, "shape").map(|d| string(d, "shape")).transpose()?.unwrap_or_else(|| "potential_tetra".into());
    let registry = s.lock().ctx.registry().clone();
    match registry.body_kind(&name) {
        Ok(kind) if kind.family() == FAMILY => Ok((name.clone(), param_map(opts, &OWN_KEYS, &name)?)),
        _ => {
            let potentials: Vec<String> = registry
                .body_kind_names()
                .into_iter()
                .filter(|n| registry.body_kind(n).is_ok_and(|k| k.family() == FAMILY))
                .collect();
            err(format!(
                "`shape` of sim.potential is a potential particle's kind ({}), got `{name}`; grains of spheres come \
                 from sim.clump or sim.clump_cloud",
                potentials.join(", ")
            ))
        }
    }
}

/// The index of the potential particle with `id`.
fn index_of(s: &DemHandle, id: i64) -> RhaiResult<usize> {
    match super::body_api::index_of(s, id) {
        Ok(i) if s.lock().sim.dem.world.kinds.family_name(i) == FAMILY => Ok(i),
        _ => err(format!("no potential particle with id {id}")),
    }
}

pub(super) fn register(engine: &mut Engine) {
    engine.register_fn("potential", |s: &mut DemHandle, m: DemMaterialHandle, centre: Dynamic, opts: Map| {
        let (kind, given) = kind_and_params(s, &opts)?;
        super::body_api::add_with(s, &kind, &given, &m, &centre, &opts)
    });
    engine.register_fn("potential_velocity", |s: &mut DemHandle, id: i64, v: Dynamic| {
        let v = vector(&v, 3, "velocity")?;
        let i = index_of(s, id)?;
        s.lock().sim.dem.world.kinds.v[i] = v;
        Ok::<_, Box<rhai::EvalAltResult>>(())
    });
    engine.register_fn("potential_body", |s: &mut DemHandle, id: i64| {
        index_of(s, id)?;
        super::body_api::state(s, id)
    });
    engine.register_fn("potential_ids", |s: &mut DemHandle| {
        let st = s.lock();
        let k = &st.sim.dem.world.kinds;
        let ids = (0..k.len()).filter(|&i| k.family_name(i) == FAMILY).map(|i| k.id[i]);
        ids.map(|i| Dynamic::from(i as i64)).collect::<rhai::Array>()
    });
    engine.register_get("potentials", |s: &mut DemHandle| {
        let st = s.lock();
        let k = &st.sim.dem.world.kinds;
        (0..k.len()).filter(|&i| k.family_name(i) == FAMILY).count() as i64
    });
}
