//! `element_test(law, #{ parameters }, #{ path })`: a law on one material point, without a mesh
//! (see `granite_core::element_test`).

use super::convert::{api_options, err, finite, get, integer, numbers, OrRhai, RhaiResult};
use super::ScriptContext;
use granite_core::element_test::{run, Path};
use rhai::{Array, Dynamic, Engine, Map};
use std::sync::Arc;

const COMPONENTS: [&str; 6] = ["xx", "yy", "zz", "xy", "yz", "xz"];

fn voigt(d: Option<&Dynamic>, name: &str) -> RhaiResult<[f64; 6]> {
    let Some(d) = d else { return Ok([0.0; 6]) };
    let v = numbers(d, name)?;
    if v.len() != 6 {
        return err(format!("`{name}` has 6 components [xx, yy, zz, xy, yz, xz], got {}", v.len()));
    }
    Ok([v[0], v[1], v[2], v[3], v[4], v[5]])
}

fn rows(v: &[[f64; 6]]) -> Array {
    v.iter().map(|r| Dynamic::from(r.iter().map(|&c| Dynamic::from(c)).collect::<Array>())).collect()
}

fn element_test(ctx: &ScriptContext, law: &str, params: Map, path: Map) -> RhaiResult<Map> {
    api_options(&path, "", "element_test")?;
    let steps = integer(get(&path, "steps").unwrap_or(&Dynamic::from(1000_i64)), "steps")?;
    if !(1..=10_000_000).contains(&steps) {
        return err(format!("`steps` of element_test must be from 1 to 10000000, got {steps}"));
    }
    let mut hold = [None; 6];
    if let Some(h) = get(&path, "hold") {
        let h = h.clone().try_cast::<Map>().ok_or_else(|| {
            super::convert::to_rhai(granite_core::GraniteError::Setup(
                "`hold` of element_test is a map of components and stresses, e.g. #{ xx: -1e5, yy: -1e5 }".into(),
            ))
        })?;
        super::convert::only_keys(&h, &COMPONENTS, "`hold` of element_test")?;
        for (k, v) in &h {
            let c = COMPONENTS.iter().position(|n| *n == k.as_str()).unwrap_or(0);
            hold[c] = Some(finite(v, &format!("hold.{k}"))?);
        }
    }
    let path = Path {
        initial_stress: voigt(get(&path, "stress"), "stress")?,
        strain: voigt(get(&path, "strain"), "strain")?,
        hold,
        steps: steps as usize,
    };
    let registry = ctx.registry();
    let (given, objects) = super::mpm_api::law_inputs(&params, law, &registry)?;
    let law_obj = registry.build_law_with(law, &given, &objects).or_rhai()?;
    if let Some(objects) = law_obj.point_objects() {
        objects.points_added(&[true]).or_rhai()?;
    }
    let record = run(law_obj.as_ref(), &path).or_rhai()?;
    let mut out = Map::new();
    out.insert("stress".into(), Dynamic::from(rows(&record.stress)));
    out.insert("strain".into(), Dynamic::from(rows(&record.strain)));
    let (p, q): (Array, Array) = record
        .stress
        .iter()
        .map(|s| {
            let (p, q) = granite_core::math::p_q(s);
            (Dynamic::from(-p), Dynamic::from(q))
        })
        .unzip();
    out.insert("p".into(), Dynamic::from(p));
    out.insert("q".into(), Dynamic::from(q));
    let mut state = Map::new();
    for (k, name) in law_obj.state_names().iter().enumerate() {
        let column: Array = record.state.iter().map(|row| Dynamic::from(row[k])).collect();
        state.insert((*name).into(), Dynamic::from(column));
    }
    out.insert("state".into(), Dynamic::from(state));
    Ok(out)
}

pub(super) fn register(engine: &mut Engine, ctx: &Arc<ScriptContext>) {
    let c = ctx.clone();
    engine.register_fn("element_test", move |law: &str, params: Map, path: Map| element_test(&c, law, params, path));
}
