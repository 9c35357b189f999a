//! Time series as CSV: a header row fixed by the first record, one row per record.

use crate::error::{GraniteError, Result};
use std::fs::File;
use std::path::{Path, PathBuf};

pub struct SeriesWriter {
    path: PathBuf,
    writer: csv::Writer<File>,
    columns: Vec<String>,
}

impl SeriesWriter {
    pub fn create(path: &Path, columns: Vec<String>) -> Result<SeriesWriter> {
        let file = File::create(path).map_err(|e| GraniteError::io(path, e))?;
        let mut writer = csv::Writer::from_writer(file);
        writer.write_record(&columns).map_err(|e| GraniteError::Other(format!("{}: {e}", path.display())))?;
        Ok(SeriesWriter { path: path.to_path_buf(), writer, columns })
    }

    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    pub fn write(&mut self, values: &[f64]) -> Result<()> {
        debug_assert_eq!(values.len(), self.columns.len());
        // `{:e}`-free formatting keeps full f64 precision and stays readable by any CSV reader.
        self.writer
            .write_record(values.iter().map(|v| format!("{v}")))
            .map_err(|e| GraniteError::Other(format!("{}: {e}", self.path.display())))?;
        self.writer.flush().map_err(|e| GraniteError::io(&self.path, e))
    }
}
