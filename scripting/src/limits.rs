//! Allowed values of a script parameter, declared with it: `param("dt", 1e-4, #{ above: 0.0 })`.
//! The default and any `--set` override are checked before the script goes on, so a bad value
//! stops the run at the declaration's line, with the parameter's name and what it allows,
//! instead of surfacing later as an obscure error or a run that makes no sense.

use super::convert::{err, number, only_keys, RhaiResult};
use rhai::{Dynamic, Map};

/// Bounds (numbers) and a list of allowed values (any kind); every one given must hold.
#[derive(Debug, Default)]
pub(crate) struct Limits {
    min: Option<f64>,
    max: Option<f64>,
    above: Option<f64>,
    below: Option<f64>,
    one_of: Option<Vec<Dynamic>>,
}

const KEYS: [&str; 5] = ["min", "max", "above", "below", "one_of"];

impl Limits {
    /// Reads `#{ min, max, above, below, one_of }` (`min`/`max` inclusive, `above`/`below` strict).
    pub fn parse(map: &Map, name: &str) -> RhaiResult<Limits> {
        only_keys(map, &KEYS, &format!("the limits of parameter `{name}`"))?;
        let bound = |key: &str| -> RhaiResult<Option<f64>> {
            let what = format!("{key}` of the limits of `{name}");
            match map.get(key).map(|d| number(d, &what)).transpose()? {
                Some(b) if b.is_nan() => err(format!("`{what}` must be a number, got NaN")),
                b => Ok(b),
            }
        };
        let one_of = match map.get("one_of") {
            None => None,
            Some(d) => Some(d.clone().into_array().or_else(|_| {
                err(format!("`one_of` of the limits of `{name}` must be an array of the allowed values"))
            })?),
        };
        Ok(Limits { min: bound("min")?, max: bound("max")?, above: bound("above")?, below: bound("below")?, one_of })
    }

    fn has_bounds(&self) -> bool {
        self.min.is_some() || self.max.is_some() || self.above.is_some() || self.below.is_some()
    }

    /// Whether `value` meets every limit (a NaN meets no bound).
    pub fn admits(&self, value: &Dynamic) -> bool {
        if self.has_bounds() {
            let x = match (value.as_float(), value.as_int()) {
                (Ok(f), _) => f,
                (_, Ok(i)) => i as f64,
                _ => return false,
            };
            let holds = |bound: Option<f64>, ok: fn(f64, f64) -> bool| bound.is_none_or(|b| ok(x, b));
            if !(holds(self.min, |x, b| x >= b)
                && holds(self.max, |x, b| x <= b)
                && holds(self.above, |x, b| x > b)
                && holds(self.below, |x, b| x < b))
            {
                return false;
            }
        }
        self.one_of.as_ref().is_none_or(|allowed| {
            allowed.iter().any(|a| a.type_name() == value.type_name() && a.to_string() == value.to_string())
        })
    }

    /// What the limits allow, as in "must be ...": `> 0 and <= 90`, `one of "a", "b"`.
    pub fn describe(&self) -> String {
        let mut parts: Vec<String> = [(">=", self.min), (">", self.above), ("<=", self.max), ("<", self.below)]
            .into_iter()
            .filter_map(|(op, b)| b.map(|b| format!("{op} {b}")))
            .collect();
        if let Some(allowed) = &self.one_of {
            let shown: Vec<String> =
                allowed.iter().map(|a| if a.is_string() { format!("\"{a}\"") } else { a.to_string() }).collect();
            parts.push(format!("one of {}", shown.join(", ")));
        }
        parts.join(" and ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits(pairs: &[(&str, Dynamic)]) -> Limits {
        let map: Map = pairs.iter().map(|(k, v)| ((*k).into(), v.clone())).collect();
        Limits::parse(&map, "x").unwrap()
    }

    #[test]
    fn bounds_are_inclusive_or_strict_as_named_and_refuse_nan() {
        let l = limits(&[("above", Dynamic::from(0.0)), ("max", Dynamic::from(90_i64))]);
        assert!(l.admits(&Dynamic::from(90.0)) && l.admits(&Dynamic::from(1_i64)));
        assert!(!l.admits(&Dynamic::from(0.0)) && !l.admits(&Dynamic::from(90.5)));
        assert!(!l.admits(&Dynamic::from(f64::NAN)));
        assert!(!l.admits(&Dynamic::from("5".to_string())));
        assert_eq!(l.describe(), "> 0 and <= 90");
    }

    #[test]
    fn one_of_compares_kind_and_value() {
        let l = limits(&[("one_of", Dynamic::from(vec![Dynamic::from("USF".to_string()), Dynamic::from(2_i64)]))]);
        assert!(l.admits(&Dynamic::from("USF".to_string())) && l.admits(&Dynamic::from(2_i64)));
        assert!(!l.admits(&Dynamic::from("usf".to_string())) && !l.admits(&Dynamic::from("2".to_string())));
        assert_eq!(l.describe(), "one of \"USF\", 2");
    }

    #[test]
    fn unknown_keys_are_refused_with_the_allowed_ones() {
        let map: Map = [("minimum".into(), Dynamic::from(0.0))].into_iter().collect();
        let e = Limits::parse(&map, "dt").unwrap_err().to_string();
        assert!(e.contains("minimum") && e.contains("`dt`") && e.contains("above"), "{e}");
    }
}
