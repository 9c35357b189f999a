//! The files one simulation writes into its output folder: `series.csv` rows and VTK frames,
//! whatever the engine.

use granite_core::error::Result;
use granite_core::io::vtk::{Field, PolyData, VtkFormat};
use granite_core::io::{SeriesWriter, VtkWriter};
use granite_core::math::Vec3;
use std::path::PathBuf;

pub struct Output {
    pub dir: PathBuf,
    /// The output folder the run was given (`--out`): `dir` or a `simN/` folder in it. It may be
    /// a link; folders granite makes below it may not.
    pub root: PathBuf,
    /// False in the processes of an MPI run other than the first: they run the same simulation
    /// and write nothing.
    pub writes: bool,
    series: Option<SeriesWriter>,
    vtk: Option<VtkWriter>,
    /// Poly-data series beside the points (DEM walls, contact network), by name.
    poly: Vec<(String, VtkWriter)>,
    /// Every frame in one file, when the script asks for VTKHDF.
    #[cfg(feature = "vtkhdf")]
    hdf: Option<granite_core::io::vtkhdf::VtkHdfWriter>,
    /// Where frames go: XML files (binary arrays unless the script asks for ASCII) or VTKHDF.
    pub vtk_format: VtkFormat,
    /// Steps between series rows / VTK frames; None = chosen per run call.
    pub series_every: Option<u64>,
    pub vtk_every: Option<u64>,
    pub last_series_step: Option<u64>,
    pub last_vtk_step: Option<u64>,
    /// The step and time a simulation loaded from a checkpoint starts at: its series continue
    /// the files of the run it resumes, and the VTK series keeps that run's earlier frames.
    pub resumes_at: Option<(u64, f64)>,
    /// The folder was made (and found not to be a link) for the first file written.
    folder_made: bool,
}

impl Output {
    pub fn new(dir: PathBuf) -> Output {
        Output {
            root: dir.clone(),
            dir,
            writes: true,
            series: None,
            vtk: None,
            poly: Vec::new(),
            #[cfg(feature = "vtkhdf")]
            hdf: None,
            vtk_format: VtkFormat::default(),
            series_every: None,
            vtk_every: None,
            last_series_step: None,
            last_vtk_step: None,
            resumes_at: None,
            folder_made: false,
        }
    }

    /// Makes this simulation's folder before its first file: a `simN/` folder that is a link
    /// (a reused or shared output folder) is refused, naming it.
    fn make_folder(&mut self) -> Result<()> {
        if !self.folder_made {
            granite_core::io::output_folder(&self.root, &self.dir)?;
            self.folder_made = true;
        }
        Ok(())
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
            self.make_folder()?;
            let columns: Vec<String> = cols.iter().map(|s| s.to_string()).collect();
            let first = self.series.is_none();
            let resumed = if first { self.resumed_series(&columns)? } else { None };
            self.series = match resumed {
                Some(resumed) => Some(resumed),
                None => {
                    // A resumed run whose columns match no earlier file leaves series.csv alone.
                    let taken = self.resumes_at.is_some() && self.dir.join("series.csv").exists();
                    let name = if first && !taken { "series.csv".to_string() } else { format!("series_{tag}.csv") };
                    Some(SeriesWriter::create(&self.dir.join(name), columns)?)
                }
            };
        }
        if let Some(w) = self.series.as_mut() {
            w.write(vals)?;
        }
        self.last_series_step = Some(step);
        Ok(())
    }

    /// For a resumed simulation, the earlier series file with these columns (`series.csv`, then
    /// `series_*.csv`), continued from the step it resumes at.
    fn resumed_series(&self, columns: &[String]) -> Result<Option<SeriesWriter>> {
        let Some((step, _)) = self.resumes_at else { return Ok(None) };
        let mut files = vec![self.dir.join("series.csv")];
        if let Ok(entries) = std::fs::read_dir(&self.dir) {
            let mut more: Vec<_> = entries
                .flatten()
                .map(|e| e.path())
                .filter(|p| p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("series_")))
                .filter(|p| p.extension().is_some_and(|e| e == "csv"))
                .collect();
            more.sort();
            files.extend(more);
        }
        for file in files {
            if let Some(series) = SeriesWriter::resume(&file, columns, step)? {
                return Ok(Some(series));
            }
        }
        Ok(None)
    }

    /// A VTK series of this simulation: a new one, or for a resumed simulation the earlier run's,
    /// continued after its frames before the resumed time.
    fn vtk_series(&self, dir: &std::path::Path, stem: &str) -> Result<VtkWriter> {
        match self.resumes_at {
            Some((_, time)) => VtkWriter::resume(dir, stem, time),
            None => VtkWriter::new(dir, stem),
        }
    }

    /// One frame: the points, and each poly-data series (`vtk/<name>_N.vtp`, its own `.pvd`) at
    /// the same time; or all of them as blocks of one frame of `vtk/run.vtkhdf`.
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
        self.make_folder()?;
        let dir = self.dir.join("vtk");
        let encoding = match self.vtk_format {
            VtkFormat::Xml(encoding) => encoding,
            VtkFormat::VtkHdf => {
                self.write_vtkhdf(&dir, time, positions, fields, poly)?;
                self.last_vtk_step = Some(step);
                return Ok(());
            }
        };
        if self.vtk.is_none() {
            self.vtk = Some(self.vtk_series(&dir, "points")?);
        }
        if let Some(w) = self.vtk.as_mut() {
            w.encoding = encoding;
            w.write_frame(time, positions, fields)?;
        }
        for (name, data) in poly {
            let k = match self.poly.iter().position(|(n, _)| n == name) {
                Some(k) => k,
                None => {
                    let series = self.vtk_series(&dir, name)?;
                    self.poly.push((name.to_string(), series));
                    self.poly.len() - 1
                }
            };
            let writer = &mut self.poly[k].1;
            writer.encoding = encoding;
            writer.write_poly_frame(time, data)?;
        }
        self.last_vtk_step = Some(step);
        Ok(())
    }
}

impl Output {
    /// A frame of `vtk/run.vtkhdf`: the points as block `points`, each poly-data picture as a
    /// block of its name. A resumed simulation continues the file after its frames before the
    /// resumed time. (Without the `vtkhdf` feature `VtkFormat::parse` refuses the format.)
    fn write_vtkhdf(
        &mut self,
        dir: &std::path::Path,
        time: f64,
        positions: &[Vec3],
        fields: &[Field],
        poly: &[(&str, PolyData)],
    ) -> Result<()> {
        #[cfg(feature = "vtkhdf")]
        {
            use granite_core::io::vtkhdf::{BlockFrame, VtkHdfWriter};
            let writer = match &mut self.hdf {
                Some(writer) => writer,
                None => {
                    let path = dir.join("run.vtkhdf");
                    let writer = self.hdf.insert(match self.resumes_at {
                        Some((_, resumed)) => VtkHdfWriter::resume(&path, resumed)?,
                        None => VtkHdfWriter::create(&path)?,
                    });
                    if let Some(note) = writer.take_note() {
                        granite_core::errln!("granite: warning: {note}");
                    }
                    writer
                }
            };
            let mut blocks = vec![("points", BlockFrame::points(positions, fields))];
            blocks.extend(poly.iter().map(|(name, data)| (*name, BlockFrame::poly(data))));
            writer.write_frame(time, &blocks)
        }
        #[cfg(not(feature = "vtkhdf"))]
        {
            let _ = (dir, time, positions, fields, poly);
            Err(granite_core::error::GraniteError::Other("this granite was built without `--features vtkhdf`".into()))
        }
    }
}

/// Writes a CSV table: `header` (comma-separated names), then one line of `rows` a row, each value
/// as Rust prints an f64 (the shortest text that reads back the same).
pub fn write_table(path: &std::path::Path, header: &str, rows: impl Iterator<Item = Vec<f64>>) -> Result<()> {
    use granite_core::error::GraniteError;
    use std::io::Write;
    let io = |e| GraniteError::io(path, e);
    let mut w = std::io::BufWriter::new(granite_core::io::create_in_folder(path).map_err(io)?);
    writeln!(w, "{header}").map_err(io)?;
    for row in rows {
        let line = row.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(",");
        writeln!(w, "{line}").map_err(io)?;
    }
    w.flush().map_err(io)
}
