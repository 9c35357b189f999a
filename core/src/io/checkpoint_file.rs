//! The envelope of a checkpoint file (DEM states, MPM checkpoints): what it is, which format
//! version, which granite wrote it, and a CRC-32 of its content, so that a file damaged after it
//! was written (one digit changed, a cut) is refused instead of silently resuming a different run.
//!
//! ```text
//! {"format":"granite-dem-state","version":3,"written_by":"granite 0.1.0 (1a2b3c4)","crc32":"89abcdef","state":{...}}
//! ```
//! The CRC covers the bytes of `state` exactly as they are in the file. Files of older versions
//! (the whole file is the state, no envelope) are read through each format's upgrade path.

use crate::error::{GraniteError, Result};
use serde::Deserialize;
use serde_json::value::RawValue;
use std::path::Path;

/// Who writes a file when the caller does not say (scripts pass the program with its commit).
pub fn default_writer() -> String {
    format!("granite-core {}", env!("CARGO_PKG_VERSION"))
}

/// The file text for `state` (already JSON) of `format` at `version`.
pub fn seal(format: &str, version: u32, written_by: &str, state: &str) -> String {
    let written_by = if written_by.is_empty() { default_writer() } else { written_by.to_string() };
    let quoted = |s: &str| serde_json::to_string(s).unwrap_or_else(|_| "\"?\"".into());
    format!(
        "{{\"format\":{},\"version\":{version},\"written_by\":{},\"crc32\":\"{:08x}\",\"state\":{state}}}",
        quoted(format),
        quoted(&written_by),
        crc32fast::hash(state.as_bytes())
    )
}

/// What a file says of itself.
#[derive(Deserialize)]
struct Header<'a> {
    format: String,
    version: u32,
    #[serde(default)]
    written_by: Option<String>,
    #[serde(default)]
    crc32: Option<String>,
    #[serde(borrow, default)]
    state: Option<&'a RawValue>,
}

/// A file's state text and the version it was written in.
pub struct Opened<'a> {
    pub version: u32,
    /// The state's JSON: the `state` member of an enveloped file, the whole text of an older one.
    pub state: &'a str,
}

/// Checks `text` (read from `path`) is a `format` file this build reads: the right kind, not
/// newer than `current`, and, when enveloped, whole (its CRC matches). `oldest` is the oldest
/// version an upgrade path reads.
pub fn open<'a>(path: &Path, text: &'a str, format: &str, current: u32, oldest: u32) -> Result<Opened<'a>> {
    let file = path.display();
    let header: Header = serde_json::from_str(text)
        .map_err(|e| GraniteError::Other(format!("{file} is not a granite {format} file (or is damaged: {e})")))?;
    if header.format != format {
        return Err(GraniteError::Other(format!("{file} is a `{}` file, not a `{format}` one", header.format)));
    }
    let writer = header.written_by.as_deref().unwrap_or("an older granite");
    if header.version > current {
        return Err(GraniteError::Other(format!(
            "{file} was written by {writer} in {format} version {}; this granite ({}) reads versions {oldest} to \
             {current}: load it with a granite at least as new as the one that wrote it",
            header.version,
            default_writer()
        )));
    }
    if header.version < oldest {
        return Err(GraniteError::Other(format!(
            "{file}: {format} version {} is older than this granite reads (versions {oldest} to {current})",
            header.version
        )));
    }
    let Some(state) = header.state else {
        // Before the envelope the whole file was the state; a file of this version has one.
        if header.version == current {
            return Err(GraniteError::Other(format!(
                "{file}: a {format} of version {current} without its envelope (no state, no checksum): not written by granite"
            )));
        }
        return Ok(Opened { version: header.version, state: text });
    };
    let stored = header.crc32.ok_or_else(|| GraniteError::Other(format!("{file}: no checksum (crc32) in the file")))?;
    let computed = format!("{:08x}", crc32fast::hash(state.get().as_bytes()));
    if stored != computed {
        return Err(GraniteError::Other(format!(
            "{file} is damaged: its content does not match the checksum it was written with (crc32 {stored}, \
             content {computed}); it was changed or cut after {writer} wrote it"
        )));
    }
    Ok(Opened { version: header.version, state: state.get() })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sealed_file_opens_and_one_changed_digit_is_refused() {
        let path = Path::new("x.json");
        let text = seal("granite-test", 3, "granite test", r#"{"a":[1.25,2.5]}"#);
        let opened = open(path, &text, "granite-test", 3, 2).unwrap();
        assert_eq!(opened.state, r#"{"a":[1.25,2.5]}"#);
        let damaged = text.replace("1.25", "1.35");
        let e = open(path, &damaged, "granite-test", 3, 2).err().unwrap().to_string();
        assert!(e.contains("x.json is damaged") && e.contains("crc32"), "{e}");
        let newer = seal("granite-test", 4, "granite 9.0 (abc)", "{}");
        let e = open(path, &newer, "granite-test", 3, 2).err().unwrap().to_string();
        assert!(e.contains("granite 9.0 (abc)") && e.contains("version 4") && e.contains("versions 2 to 3"), "{e}");
        let other = open(path, &text, "granite-other", 3, 2).err().unwrap().to_string();
        assert!(other.contains("not a `granite-other`"), "{other}");
        // An older file is its own state.
        let old = r#"{"format":"granite-test","version":2,"a":[1]}"#;
        assert_eq!(open(path, old, "granite-test", 3, 2).unwrap().state, old);
    }
}
