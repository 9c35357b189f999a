//! Constitutive laws written as script functions (the counterpart of the thesis's `PythonModel`):
//! `|stress, dstrain, state| #{ stress: [...], state: [...] }`, called once per point and step.
//! Meant for trying ideas on small problems: a call costs microseconds where a built-in law
//! costs nanoseconds (see docs/scripting.md for the measured figures).

use super::convert::{api_options, get, number, string, OrRhai, RhaiResult};
use super::driver::Handle;
use super::ScriptContext;
use granite_core::error::{GraniteError, Result};
use granite_core::ext::{ConstitutiveLaw, LawBatch};
use granite_core::params::Params;
use granite_run::MpmScene;
use rhai::{Array, Dynamic, Engine, FnPtr, Map};
use std::sync::Arc;

pub struct ScriptLaw {
    name: String,
    params: Params,
    function: FnPtr,
    engine: Engine,
    ast: Arc<rhai::AST>,
    state_names: Vec<&'static str>,
}

fn voigt(d: &Dynamic, what: &str) -> Result<[f64; 6]> {
    let arr =
        d.clone().into_array().map_err(|_| GraniteError::Other(format!("{what} must be an array of 6 numbers")))?;
    if arr.len() != 6 {
        return Err(GraniteError::Other(format!("{what} must have 6 components, got {}", arr.len())));
    }
    let mut v = [0.0; 6];
    for (k, x) in arr.iter().enumerate() {
        v[k] = x
            .as_float()
            .or_else(|_| x.as_int().map(|i| i as f64))
            .map_err(|_| GraniteError::Other(format!("{what}[{k}] is not a number")))?;
    }
    Ok(v)
}

fn array(v: &[f64]) -> Array {
    v.iter().map(|&x| Dynamic::from(x)).collect()
}

impl ConstitutiveLaw for ScriptLaw {
    fn name(&self) -> &str {
        &self.name
    }
    fn params(&self) -> &Params {
        &self.params
    }
    fn state_names(&self) -> &[&'static str] {
        &self.state_names
    }
    fn update(&self, batch: LawBatch<'_>) -> Result<()> {
        let stride = self.state_names.len();
        for k in 0..batch.len() {
            let state = &mut batch.state[k * stride..(k + 1) * stride];
            let args = (array(&batch.stress[k]), array(&batch.dstrain[k]), array(state));
            let out: Dynamic = self.function.call(&self.engine, &self.ast, args).map_err(|e| {
                GraniteError::Other(format!("script law \"{}\" at point {}: {e}", self.name, batch.first + k))
            })?;
            let map = out.try_cast::<Map>().ok_or_else(|| {
                GraniteError::Other(format!(
                    "script law \"{}\" must return #{{ stress: [6 numbers], state: [...] }}",
                    self.name
                ))
            })?;
            let stress = map
                .get("stress")
                .ok_or_else(|| GraniteError::Other(format!("script law \"{}\" returned no `stress`", self.name)))?;
            batch.stress[k] = voigt(stress, "the returned stress")?;
            if stride > 0 {
                let st = map
                    .get("state")
                    .ok_or_else(|| GraniteError::Other(format!("script law \"{}\" returned no `state`", self.name)))?;
                let st = st
                    .clone()
                    .into_array()
                    .map_err(|_| GraniteError::Other("the returned state must be an array".into()))?;
                if st.len() != stride {
                    return Err(GraniteError::Other(format!(
                        "script law \"{}\" returned {} state values, declared {stride}",
                        self.name,
                        st.len()
                    )));
                }
                for (i, v) in st.iter().enumerate() {
                    state[i] = v
                        .as_float()
                        .or_else(|_| v.as_int().map(|x| x as f64))
                        .map_err(|_| GraniteError::Other("state values must be numbers".into()))?;
                }
            }
        }
        Ok(())
    }
}

pub(super) fn register(engine: &mut Engine, ctx: &Arc<ScriptContext>) {
    let c = ctx.clone();
    engine.register_fn(
        "script_material",
        move |s: &mut Handle<MpmScene>,
              name: &str,
              f: FnPtr,
              opts: Map|
              -> RhaiResult<super::mpm_api::MaterialHandle> {
            api_options(&opts, "MpmSim", "script_material")?;
            let density = number(get(&opts, "density").unwrap_or(&Dynamic::UNIT), "density")?;
            let names: Vec<String> = match get(&opts, "state") {
                Some(d) => d
                    .clone()
                    .into_array()
                    .unwrap_or_default()
                    .iter()
                    .map(|v| string(v, "state name"))
                    .collect::<RhaiResult<_>>()?,
                None => Vec::new(),
            };
            let ast = c
                .ast
                .lock()
                .unwrap()
                .clone()
                .ok_or_else(|| super::convert::to_rhai(GraniteError::Setup("no script".into())))?;
            // State names live as long as the law: leak the few strings once per material.
            let state_names: Vec<&'static str> = names.into_iter().map(|n| &*Box::leak(n.into_boxed_str())).collect();
            let law = ScriptLaw {
                name: name.to_string(),
                params: Params::default(),
                function: f,
                engine: Engine::new(),
                ast,
                state_names,
            };
            let mut st = s.lock();
            let index = st.sim.mpm.add_material(name, density, Box::new(law)).or_rhai()?;
            Ok(super::mpm_api::MaterialHandle::new(index, name.to_string(), s.serial()))
        },
    );
}
