//! The one error type of the engine: every variant says what is wrong in words a user can act on.

use thiserror::Error;

#[derive(Debug, Error)]
pub enum GraniteError {
    /// A parameter has a value outside what is allowed.
    #[error("parameter {name} = {value}: {allowed}")]
    Parameter { name: String, value: String, allowed: String },
    /// A required parameter is missing.
    #[error("missing parameter `{name}` ({context}); expected: {expected}")]
    MissingParameter { name: String, context: String, expected: String },
    /// A name that no registry or list knows.
    #[error("unknown {kind} `{name}`; known: {known}")]
    Unknown { kind: String, name: String, known: String },
    /// A simulation set-up that cannot be run.
    #[error("{0}")]
    Setup(String),
    /// The run went unstable (NaN/inf, blow-up) or lost material points where it must not.
    #[error("simulation stopped at step {step} (t = {time:.6e} s): {reason}")]
    Unstable { step: u64, time: f64, reason: String },
    #[error("I/O error on {path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("{0}")]
    Other(String),
}

pub type Result<T> = std::result::Result<T, GraniteError>;

/// `text` with every number that `Display` wrote out in more than 24 digits (1e-320 or 1e300
/// have no exponent there: hundreds of digits in a message) in scientific notation instead.
pub fn compact_numbers(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(start) = rest.find(|c: char| c.is_ascii_digit()) {
        out.push_str(&rest[..start]);
        let len = rest[start..].find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(rest.len() - start);
        let run = &rest[start..start + len];
        match run.parse::<f64>() {
            Ok(number) if len > 24 => out.push_str(&format!("{number:e}")),
            _ => out.push_str(run),
        }
        rest = &rest[start + len..];
    }
    out.push_str(rest);
    out
}

fn shown(value: impl std::fmt::Display) -> String {
    compact_numbers(&value.to_string())
}

impl GraniteError {
    pub fn param(name: &str, value: impl std::fmt::Display, allowed: &str) -> Self {
        GraniteError::Parameter { name: format!("`{name}`"), value: shown(value), allowed: allowed.into() }
    }

    /// Like `param`, for a name already formatted (e.g. "`young` of material \"sand\"").
    pub fn param_in(qualified_name: String, value: impl std::fmt::Display, allowed: &str) -> Self {
        GraniteError::Parameter { name: qualified_name, value: shown(value), allowed: allowed.into() }
    }

    pub fn io(path: impl AsRef<std::path::Path>, source: std::io::Error) -> Self {
        GraniteError::Io { path: path.as_ref().display().to_string(), source }
    }
}

#[cfg(test)]
mod tests {
    use super::compact_numbers;

    #[test]
    fn numbers_written_out_in_hundreds_of_digits_get_an_exponent() {
        let tiny = format!("`spacing` = {}: must be > 0", 1e-320);
        assert_eq!(compact_numbers(&tiny), "`spacing` = 1e-320: must be > 0");
        let huge = format!("D must be in [0, 1), got -{}", 1e308);
        assert_eq!(compact_numbers(&huge), "D must be in [0, 1), got -1e308");
        // Short numbers, integers as long as an i64, versions and names stay as written.
        let plain = "step 9223372036854775807, t = 0.30000000000000004 s, granite 0.1.0, point_2";
        assert_eq!(compact_numbers(plain), plain);
    }
}
