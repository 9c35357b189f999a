//! Conversions from Rhai values to engine values, with errors that name the parameter.

use granite_core::error::{GraniteError, Result};
use granite_core::ext::contact::Elastic;
use granite_core::math::Vec3;
use granite_core::registry::ParamMap;
use rhai::{Dynamic, EvalAltResult, Map, Position};

pub type RhaiResult<T> = std::result::Result<T, Box<EvalAltResult>>;

/// A granite error as a Rhai runtime error; Rhai adds the script position of the failing call.
pub fn to_rhai(e: GraniteError) -> Box<EvalAltResult> {
    let text = granite_core::error::compact_numbers(&e.to_string());
    Box::new(EvalAltResult::ErrorRuntime(Dynamic::from(text), Position::NONE))
}

pub fn err<T>(msg: impl Into<String>) -> RhaiResult<T> {
    Err(to_rhai(GraniteError::Setup(msg.into())))
}

pub trait OrRhai<T> {
    fn or_rhai(self) -> RhaiResult<T>;
}

impl<T> OrRhai<T> for Result<T> {
    fn or_rhai(self) -> RhaiResult<T> {
        self.map_err(to_rhai)
    }
}

/// A number given as float or integer.
pub fn number(d: &Dynamic, name: &str) -> RhaiResult<f64> {
    if let Ok(f) = d.as_float() {
        Ok(f)
    } else if let Ok(i) = d.as_int() {
        Ok(i as f64)
    } else {
        err(format!("`{name}` must be a number, got {} ({})", d, d.type_name()))
    }
}

/// A finite number (a value that enters the physics: a position, a force, a velocity).
pub fn finite(d: &Dynamic, name: &str) -> RhaiResult<f64> {
    let x = number(d, name)?;
    if !x.is_finite() {
        return err(format!("`{name}` must be a finite number, got {x}"));
    }
    Ok(x)
}

pub fn integer(d: &Dynamic, name: &str) -> RhaiResult<i64> {
    d.as_int().or_else(|_| err(format!("`{name}` must be an integer, got {} ({})", d, d.type_name())))
}

/// An array of `dim` finite numbers (2D vectors get z = 0).
pub fn vector(d: &Dynamic, dim: usize, name: &str) -> RhaiResult<Vec3> {
    let arr = d
        .clone()
        .into_array()
        .or_else(|_| err(format!("`{name}` must be an array of {dim} numbers, got {}", d.type_name())))?;
    if arr.len() != dim {
        return err(format!("`{name}` must have {dim} components (dim = {dim}), got {}", arr.len()));
    }
    let mut v = [0.0; 3];
    for (k, x) in arr.iter().enumerate() {
        v[k] = finite(x, name)?;
    }
    Ok(v)
}

/// An array of finite numbers of any length.
pub fn numbers(d: &Dynamic, name: &str) -> RhaiResult<Vec<f64>> {
    let arr = d.clone().into_array().or_else(|_| err(format!("`{name}` must be an array of numbers")))?;
    arr.iter().map(|x| finite(x, name)).collect()
}

pub fn counts(d: &Dynamic, dim: usize, name: &str) -> RhaiResult<[usize; 3]> {
    let arr = d.clone().into_array().or_else(|_| err(format!("`{name}` must be an array of {dim} integers")))?;
    if arr.len() != dim {
        return err(format!("`{name}` must have {dim} entries (dim = {dim}), got {}", arr.len()));
    }
    let mut c = [1usize; 3];
    for (k, x) in arr.iter().enumerate() {
        let n = integer(x, name)?;
        if n <= 0 {
            return err(format!("`{name}` entries must be >= 1, got {n}"));
        }
        c[k] = n as usize;
    }
    Ok(c)
}

/// The numeric entries of an options map, minus the keys the caller handles itself.
pub fn param_map(map: &Map, skip: &[&str], owner: &str) -> RhaiResult<ParamMap> {
    let mut out = ParamMap::new();
    for (k, v) in map {
        if skip.contains(&k.as_str()) {
            continue;
        }
        out.insert(k.to_string(), number(v, &format!("{k}` of `{owner}"))?);
    }
    Ok(out)
}

pub fn get<'a>(map: &'a Map, key: &str) -> Option<&'a Dynamic> {
    map.get(key)
}

/// Rejects keys of an options map that the function does not know, suggesting the closest.
pub fn only_keys(map: &Map, allowed: &[&str], function: &str) -> RhaiResult<()> {
    for k in map.keys() {
        if !allowed.contains(&k.as_str()) {
            let near = super::api_doc::closest(k, allowed.iter().copied());
            let hint = near.first().map(|n| format!(" (did you mean `{n}`?)")).unwrap_or_default();
            return err(format!("unknown option `{k}` of {function}{hint}; allowed: {}", allowed.join(", ")));
        }
    }
    Ok(())
}

/// Rejects keys of an options map that the API table (`api_doc.rs`) does not list for
/// `on.name`: the keys a function checks and those `:help` and completion show are one list.
pub fn api_options(map: &Map, on: &str, name: &str) -> RhaiResult<()> {
    let shown = if on.is_empty() { format!("{name}(...)") } else { format!("sim.{name}(...)") };
    only_keys(map, super::api_doc::options_of(on, name), &shown)
}

pub fn string(d: &Dynamic, name: &str) -> RhaiResult<String> {
    d.clone().into_string().or_else(|_| err(format!("`{name}` must be a string, got {}", d.type_name())))
}

/// Elastic constants from `#{ young, poisson }` or `#{ rigid: true }` (None when neither is given).
pub(super) fn elastic_from(opts: &Map, what: &str) -> RhaiResult<Option<Elastic>> {
    let rigid = match get(opts, "rigid") {
        Some(d) => d.as_bool().or_else(|_| err(format!("`rigid` of {what} is true or false")))?,
        None => false,
    };
    let young = get(opts, "young").map(|d| number(d, "young")).transpose()?;
    let poisson = get(opts, "poisson").map(|d| finite(d, "poisson")).transpose()?;
    match (rigid, young, poisson) {
        (true, None, p) => Ok(Some(Elastic { young: f64::INFINITY, poisson: p.unwrap_or(0.0) })),
        (true, Some(_), _) => err(format!("{what}: give `rigid: true` or `young`, not both")),
        (false, Some(young), Some(poisson)) => Ok(Some(Elastic { young, poisson })),
        (false, None, None) => Ok(None),
        _ => err(format!("{what}: give both `young` (Pa) and `poisson`, or `rigid: true`")),
    }
}

/// The index of a named axis: x, y (and z in 3D).
pub(super) fn axis_index(name: &str, dim: usize) -> RhaiResult<usize> {
    match name {
        "x" => Ok(0),
        "y" => Ok(1),
        "z" if dim == 3 => Ok(2),
        _ => err(format!("axis `{name}` must be one of {}", if dim == 3 { "x, y, z" } else { "x, y" })),
    }
}
