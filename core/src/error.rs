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

impl GraniteError {
    pub fn param(name: &str, value: impl std::fmt::Display, allowed: &str) -> Self {
        GraniteError::Parameter { name: format!("`{name}`"), value: value.to_string(), allowed: allowed.into() }
    }

    /// Like `param`, for a name already formatted (e.g. "`young` of material \"sand\"").
    pub fn param_in(qualified_name: String, value: impl std::fmt::Display, allowed: &str) -> Self {
        GraniteError::Parameter { name: qualified_name, value: value.to_string(), allowed: allowed.into() }
    }

    pub fn io(path: impl AsRef<std::path::Path>, source: std::io::Error) -> Self {
        GraniteError::Io { path: path.as_ref().display().to_string(), source }
    }
}
