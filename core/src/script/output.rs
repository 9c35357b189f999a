//! The files one simulation writes: series rows and VTK frames, whatever the engine.

use crate::error::Result;
use crate::io::vtk::{Encoding, Field, PolyData};
use crate::io::{SeriesWriter, VtkWriter};
use crate::math::Vec3;
use std::path::PathBuf;

pub struct Output {
    pub dir: PathBuf,
    /// False in the processes of an MPI run other than the first: they run the same simulation
    /// and write nothing.
    pub writes: bool,
    series: Option<SeriesWriter>,
    vtk: Option<VtkWriter>,
    /// Poly-data series beside the points (DEM walls, contact network), by name.
    poly: Vec<(String, VtkWriter)>,
    /// How VTK arrays are written (binary unless the script asks for ASCII).
    pub vtk_encoding: Encoding,
    /// Steps between series rows / VTK frames; None = chosen per run call.
    pub series_every: Option<u64>,
    pub vtk_every: Option<u64>,
    pub last_series_step: Option<u64>,
    pub last_vtk_step: Option<u64>,
}

impl Output {
    pub fn new(dir: PathBuf) -> Output {
        Output {
            dir,
            writes: true,
            series: None,
            vtk: None,
            poly: Vec::new(),
            vtk_encoding: Encoding::default(),
            series_every: None,
            vtk_every: None,
            last_series_step: None,
            last_vtk_step: None,
        }
    }

    /// Appends a row; a change in the column set (e.g. runout tracking starting) continues in
    /// `<prefix>series_<tag>.csv`.
    pub fn write_series(&mut self, step: u64, cols: &[&str], vals: &[f64], tag: &str) -> Result<()> {
        if self.last_series_step == Some(step) {
            return Ok(());
        }
        if !self.writes {
            self.last_series_step = Some(step);
            return Ok(());
        }
        let needs_new = match &self.series {
            None => true,
            Some(w) => w.columns().len() != cols.len() || w.columns().iter().zip(cols).any(|(a, b)| a != b),
        };
        if needs_new {
            let name = match &self.series {
                None => "series.csv".to_string(),
                Some(_) => format!("series_{tag}.csv"),
            };
            self.series =
                Some(SeriesWriter::create(&self.dir.join(name), cols.iter().map(|s| s.to_string()).collect())?);
        }
        if let Some(w) = self.series.as_mut() {
            w.write(vals)?;
        }
        self.last_series_step = Some(step);
        Ok(())
    }

    /// One frame: the points, and each poly-data series (`vtk/<prefix><name>_N.vtp`, its own
    /// `.pvd`) at the same time.
    pub fn write_vtk(
        &mut self,
        step: u64,
        time: f64,
        positions: &[Vec3],
        fields: &[Field],
        poly: &[(&str, PolyData)],
    ) -> Result<()> {
        if self.last_vtk_step == Some(step) {
            return Ok(());
        }
        if !self.writes {
            self.last_vtk_step = Some(step);
            return Ok(());
        }
        let dir = self.dir.join("vtk");
        if self.vtk.is_none() {
            self.vtk = Some(VtkWriter::new(&dir, "points")?);
        }
        if let Some(w) = self.vtk.as_mut() {
            w.encoding = self.vtk_encoding;
            w.write_frame(time, positions, fields)?;
        }
        for (name, data) in poly {
            let k = match self.poly.iter().position(|(n, _)| n == name) {
                Some(k) => k,
                None => {
                    self.poly.push((name.to_string(), VtkWriter::new(&dir, name)?));
                    self.poly.len() - 1
                }
            };
            let writer = &mut self.poly[k].1;
            writer.encoding = self.vtk_encoding;
            writer.write_poly_frame(time, data)?;
        }
        self.last_vtk_step = Some(step);
        Ok(())
    }
}
