//! Named scalar parameters of a plugin, checked against the plugin's declared list.

use crate::error::{GraniteError, Result};
use indexmap::IndexMap;

/// User-given parameter values by name, in the order given.
pub type ParamMap = indexmap::IndexMap<String, f64>;

/// A time step as a user gives it: finite and > 0.
pub fn time_step(dt: f64) -> Result<f64> {
    if dt > 0.0 && dt.is_finite() {
        Ok(dt)
    } else {
        Err(GraniteError::param("dt", dt, "must be > 0"))
    }
}

/// Refuses a time step above a stability `limit` (None: nothing limits it yet); `limit_is` says
/// what the limit is, for the message.
pub fn time_step_within(dt: f64, limit: Option<f64>, limit_is: &str) -> Result<()> {
    match limit {
        Some(crit) if dt > crit => {
            Err(GraniteError::param("dt", format!("{dt:e}"), &format!("must not exceed {limit_is} = {crit:.4e} s")))
        }
        _ => Ok(()),
    }
}

/// The time step a run needs: none set yet (zero) is an error that says what to call.
pub fn require_time_step(dt: f64) -> Result<()> {
    if dt > 0.0 {
        Ok(())
    } else {
        Err(GraniteError::Setup("no time step: call dt(...) before running".into()))
    }
}

/// A parameter a plugin accepts: its name, a default (None = required) and a line of documentation.
#[derive(Debug, Clone, Copy)]
pub struct ParamSpec {
    pub name: &'static str,
    pub default: Option<f64>,
    pub doc: &'static str,
}

impl ParamSpec {
    pub const fn required(name: &'static str, doc: &'static str) -> Self {
        ParamSpec { name, default: None, doc }
    }
    pub const fn optional(name: &'static str, default: f64, doc: &'static str) -> Self {
        ParamSpec { name, default: Some(default), doc }
    }
    /// Optional with no default: reads as NaN until given; test with [`Params::is_set`].
    pub const fn unset(name: &'static str, doc: &'static str) -> Self {
        ParamSpec { name, default: Some(f64::NAN), doc }
    }
}

/// Values given by the user, resolved against a list of specs: every spec has a value afterwards.
#[derive(Debug, Clone, Default)]
pub struct Params {
    owner: String,
    values: IndexMap<String, f64>,
}

impl Params {
    /// Checks `given` against `specs`: unknown names and missing required values are errors that name
    /// the owner (e.g. `material "mohr_coulomb"`) and list what is allowed.
    pub fn resolve(owner: &str, specs: &[ParamSpec], given: &IndexMap<String, f64>) -> Result<Params> {
        let known = || specs.iter().map(|s| s.name).collect::<Vec<_>>().join(", ");
        for name in given.keys() {
            if !specs.iter().any(|s| s.name == name) {
                return Err(GraniteError::Unknown {
                    kind: format!("parameter of {owner}"),
                    name: name.clone(),
                    known: known(),
                });
            }
        }
        let mut values = IndexMap::new();
        for spec in specs {
            let value = match (given.get(spec.name), spec.default) {
                (Some(v), _) => *v,
                (None, Some(d)) => d,
                (None, None) => {
                    return Err(GraniteError::MissingParameter {
                        name: spec.name.into(),
                        context: owner.into(),
                        expected: spec.doc.into(),
                    })
                }
            };
            let unset_default = given.get(spec.name).is_none() && value.is_nan();
            if !value.is_finite() && !unset_default {
                return Err(GraniteError::param_in(
                    format!("`{}` of {owner}", spec.name),
                    value,
                    "must be a finite number",
                ));
            }
            values.insert(spec.name.to_string(), value);
        }
        Ok(Params { owner: owner.into(), values })
    }

    pub fn owner(&self) -> &str {
        &self.owner
    }

    /// The value of a declared parameter (declared names always resolve).
    pub fn get(&self, name: &str) -> f64 {
        self.values.get(name).copied().unwrap_or(f64::NAN)
    }

    /// Whether an optional parameter declared with [`ParamSpec::unset`] was given.
    pub fn is_set(&self, name: &str) -> bool {
        !self.get(name).is_nan()
    }

    pub fn set(&mut self, name: &str, value: f64) -> Result<()> {
        match self.values.get_mut(name) {
            Some(v) => {
                *v = value;
                Ok(())
            }
            None => Err(GraniteError::Unknown {
                kind: format!("parameter of {}", self.owner),
                name: name.into(),
                known: self.values.keys().cloned().collect::<Vec<_>>().join(", "),
            }),
        }
    }

    pub fn iter(&self) -> impl Iterator<Item = (&str, f64)> {
        self.values.iter().map(|(k, v)| (k.as_str(), *v))
    }

    /// `value > 0`, or an error naming the parameter.
    pub fn positive(&self, name: &str) -> Result<f64> {
        let v = self.get(name);
        if v > 0.0 {
            Ok(v)
        } else {
            Err(GraniteError::param_in(self.qualified(name), v, "must be > 0"))
        }
    }

    /// A whole number >= 1 (a count of steps), or an error naming the parameter.
    pub fn count(&self, name: &str) -> Result<u64> {
        let v = self.get(name);
        if v >= 1.0 && v.fract() == 0.0 && v < u64::MAX as f64 {
            Ok(v as u64)
        } else {
            Err(GraniteError::param_in(self.qualified(name), v, "must be a whole number >= 1"))
        }
    }

    /// A switch: `true` or `false` in a script (1 or 0 as a number), or an error naming the
    /// parameter; 2.5 is neither.
    pub fn flag(&self, name: &str) -> Result<bool> {
        match self.get(name) {
            0.0 => Ok(false),
            1.0 => Ok(true),
            v => Err(GraniteError::param_in(self.qualified(name), v, "must be true or false (or 1 or 0)")),
        }
    }

    /// `value >= 0`, or an error naming the parameter.
    pub fn non_negative(&self, name: &str) -> Result<f64> {
        let v = self.get(name);
        if v >= 0.0 {
            Ok(v)
        } else {
            Err(GraniteError::param_in(self.qualified(name), v, "must be >= 0"))
        }
    }

    /// `lo <= value < hi` (or `<= hi` when `hi_inclusive`), or an error naming the parameter.
    pub fn in_range(&self, name: &str, lo: f64, hi: f64, hi_inclusive: bool) -> Result<f64> {
        let v = self.get(name);
        let ok = v >= lo && if hi_inclusive { v <= hi } else { v < hi };
        if ok {
            Ok(v)
        } else {
            let bracket = if hi_inclusive { "]" } else { ")" };
            Err(GraniteError::param_in(self.qualified(name), v, &format!("must be in [{lo}, {hi}{bracket}")))
        }
    }

    fn qualified(&self, name: &str) -> String {
        format!("`{name}` of {}", self.owner)
    }
}
