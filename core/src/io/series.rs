//! Time series as CSV: a header row fixed by the first record, one row per record.
//!
//! Rows are appended and flushed one at a time; a row the disk had no room for is cut off again,
//! so the file always ends with a whole row. A run resumed from a checkpoint continues the file
//! of its columns from the checkpoint's step ([`SeriesWriter::resume`]).

use crate::error::{GraniteError, Result};
use std::fs::File;
use std::path::{Path, PathBuf};

pub struct SeriesWriter {
    path: PathBuf,
    writer: csv::Writer<File>,
    columns: Vec<String>,
    /// The file's length after its last whole row.
    whole: u64,
    /// A row could not be written: the file stays as it was before that row.
    failed: bool,
}

impl SeriesWriter {
    pub fn create(path: &Path, columns: Vec<String>) -> Result<SeriesWriter> {
        let file = super::create_in_folder(path).map_err(|e| GraniteError::io(path, e))?;
        let mut series = SeriesWriter::over(path, file, columns, 0);
        let header = series.columns.clone();
        series.append(header.iter().map(|s| s.as_str()))?;
        Ok(series)
    }

    /// Continues the series at `path` from step `from_step`: when the file's header is `columns`
    /// (its first column the step), its rows before that step are kept, those from it on dropped
    /// (the resumed run writes them again), and new rows follow. None when there is no such file.
    pub fn resume(path: &Path, columns: &[String], from_step: u64) -> Result<Option<SeriesWriter>> {
        let Ok(text) = std::fs::read_to_string(path) else { return Ok(None) };
        let mut lines = text.split_inclusive('\n');
        let Some(header) = lines.next() else { return Ok(None) };
        let same_columns = header.trim_end().split(',').eq(columns.iter().map(|c| c.as_str()));
        if !same_columns || columns.first().map(|c| c.as_str()) != Some("step") {
            return Ok(None);
        }
        let mut kept = String::from(header);
        for line in lines {
            // A row cut by a killed writer has no line end.
            let before = line.ends_with('\n')
                && line
                    .split(',')
                    .next()
                    .and_then(|s| s.trim().parse::<f64>().ok())
                    .is_some_and(|s| s < from_step as f64);
            if !before {
                break;
            }
            kept.push_str(line);
        }
        super::durable::replace(path, kept.as_bytes(), super::durable::Flush::ToDisk)?;
        let file = super::append_in_folder(path)?;
        Ok(Some(SeriesWriter::over(path, file, columns.to_vec(), kept.len() as u64)))
    }

    fn over(path: &Path, file: File, columns: Vec<String>, whole: u64) -> SeriesWriter {
        let writer = csv::WriterBuilder::new().from_writer(file);
        SeriesWriter { path: path.to_path_buf(), writer, columns, whole, failed: false }
    }

    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    pub fn write(&mut self, values: &[f64]) -> Result<()> {
        debug_assert_eq!(values.len(), self.columns.len());
        // `{:e}`-free formatting keeps full f64 precision and stays readable by any CSV reader. A
        // value not defined at this step (NaN: an unbalanced force without contacts) is an empty
        // cell, which CSV readers take as missing.
        let row: Vec<String> = values.iter().map(|v| if v.is_nan() { String::new() } else { format!("{v}") }).collect();
        self.append(row.iter().map(|s| s.as_str()))
    }

    fn append<'a>(&mut self, fields: impl IntoIterator<Item = &'a str>) -> Result<()> {
        if self.failed {
            return Err(GraniteError::Other(format!(
                "{}: no row is written after one failed (the file ends with the last whole row)",
                self.path.display()
            )));
        }
        let written = self
            .writer
            .write_record(fields)
            .map_err(|e| match e.into_kind() {
                csv::ErrorKind::Io(io) => io,
                other => std::io::Error::other(format!("{other:?}")),
            })
            .and_then(|()| self.writer.flush())
            .and_then(|()| self.writer.get_ref().metadata().map(|m| m.len()));
        match written {
            Ok(len) => {
                self.whole = len;
                Ok(())
            }
            Err(e) => {
                self.failed = true;
                let _ = self.writer.get_ref().set_len(self.whole);
                Err(GraniteError::io(&self.path, e))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_resumed_series_keeps_the_rows_before_its_step_and_drops_a_cut_row() {
        let dir = std::env::temp_dir().join(format!("granite-series-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("series.csv");
        let columns: Vec<String> = ["step", "time"].iter().map(|s| s.to_string()).collect();
        let mut w = SeriesWriter::create(&path, columns.clone()).unwrap();
        for step in [0.0, 10.0, 20.0, 30.0] {
            w.write(&[step, step * 0.1]).unwrap();
        }
        drop(w);
        let mut text = std::fs::read_to_string(&path).unwrap();
        text.push_str("40,4.0"); // a row cut by a kill
        std::fs::write(&path, &text).unwrap();
        let mut w = SeriesWriter::resume(&path, &columns, 20).unwrap().expect("same columns");
        w.write(&[20.0, 2.0]).unwrap();
        w.write(&[25.0, 2.5]).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "step,time\n0,0\n10,1\n20,2\n25,2.5\n");
        let other: Vec<String> = ["step", "energy"].iter().map(|s| s.to_string()).collect();
        assert!(SeriesWriter::resume(&path, &other, 20).unwrap().is_none(), "other columns: another series");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
