//! Results as the end of a run prints them: numbers to six significant digits, counts as
//! integers, long arrays cut to their ends. summary.json keeps every value whole.

use serde_json::Value;

/// Arrays longer than this are shown by their first and last values and their length.
const ARRAY_SHOWN: usize = 6;

/// One summary value for a person to read.
pub fn shown(value: &Value) -> String {
    match value {
        Value::Number(n) => match (n.as_i64(), n.as_u64(), n.as_f64()) {
            (Some(i), _, _) => i.to_string(),
            (_, Some(u), _) => u.to_string(),
            (_, _, Some(x)) => number(x),
            _ => n.to_string(),
        },
        Value::String(s) => s.clone(),
        Value::Array(items) if items.len() > ARRAY_SHOWN => {
            let first: Vec<String> = items[..3].iter().map(shown).collect();
            format!("[{}, ..., {}] ({} values)", first.join(", "), shown(&items[items.len() - 1]), items.len())
        }
        Value::Array(items) => format!("[{}]", items.iter().map(shown).collect::<Vec<_>>().join(", ")),
        Value::Object(map) if map.len() > ARRAY_SHOWN => format!("{{...}} ({} entries)", map.len()),
        Value::Object(map) => {
            format!("{{{}}}", map.iter().map(|(k, v)| format!("{k}: {}", shown(v))).collect::<Vec<_>>().join(", "))
        }
        other => other.to_string(),
    }
}

/// A float to six significant digits, without trailing zeros; an exponent outside 1e-4..1e6.
fn number(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return x.to_string();
    }
    let magnitude = x.abs();
    if (1e-4..1e6).contains(&magnitude) {
        let decimals = (5 - magnitude.log10().floor() as i32).max(0) as usize;
        let text = format!("{x:.decimals$}");
        if text.contains('.') {
            text.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            text
        }
    } else {
        let text = format!("{x:.5e}");
        let (mantissa, exponent) = text.split_once('e').unwrap_or((&text, "0"));
        let mantissa =
            if mantissa.contains('.') { mantissa.trim_end_matches('0').trim_end_matches('.') } else { mantissa };
        format!("{mantissa}e{exponent}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn values_are_shown_short() {
        assert_eq!(shown(&json!(1.1749999999999998)), "1.175");
        assert_eq!(shown(&json!(248)), "248");
        assert_eq!(shown(&json!(0.000123456789)), "0.000123457");
        assert_eq!(shown(&json!(6.02e23)), "6.02e23");
        assert_eq!(shown(&json!(-2.5e-7)), "-2.5e-7");
        assert_eq!(shown(&json!(123456.7)), "123457");
        assert_eq!(shown(&json!("ok")), "ok");
        let long: Vec<f64> = (0..1200).map(|k| k as f64 * 0.1).collect();
        assert_eq!(shown(&json!(long)), "[0, 0.1, 0.2, ..., 119.9] (1200 values)");
        assert_eq!(shown(&json!([1, 2.5])), "[1, 2.5]");
    }
}
