//! Files: the output contract (`series.csv`, `summary.json`, `vtk/`) and the meshes read as input
//! (`gmsh`, `stl`).

pub mod checkpoint_file;
pub mod durable;
pub mod gmsh;
pub mod series;
pub mod stl;
pub mod vtk;
#[cfg(feature = "vtkhdf")]
pub mod vtkhdf;

pub use series::SeriesWriter;
pub use vtk::VtkWriter;

use crate::error::{GraniteError, Result};
use std::path::Path;

/// Writes `summary.json` (a flat object of named results, in insertion order), replacing the
/// file whole or not at all.
pub fn write_summary(path: &Path, values: &indexmap::IndexMap<String, serde_json::Value>) -> Result<()> {
    let text = serde_json::to_string_pretty(values).map_err(|e| GraniteError::Other(e.to_string()))?;
    durable::replace(path, (text + "\n").as_bytes(), durable::Flush::ToDisk)
}
