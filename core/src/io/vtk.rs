//! ParaView output: one `.vtu` (XML unstructured grid of vertices) per frame and a `.pvd` index.

use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// A named per-point field with 1, 3, 6 or 9 components.
pub struct Field {
    pub name: String,
    pub components: usize,
    pub values: Vec<f64>,
}

pub struct VtkWriter {
    dir: PathBuf,
    stem: String,
    frames: Vec<(f64, String)>,
}

impl VtkWriter {
    pub fn new(dir: &Path, stem: &str) -> Result<VtkWriter> {
        std::fs::create_dir_all(dir).map_err(|e| GraniteError::io(dir, e))?;
        Ok(VtkWriter { dir: dir.to_path_buf(), stem: stem.into(), frames: Vec::new() })
    }

    pub fn frames(&self) -> usize {
        self.frames.len()
    }

    /// Writes one frame and rewrites the `.pvd` index.
    pub fn write_frame(&mut self, time: f64, positions: &[Vec3], fields: &[Field]) -> Result<PathBuf> {
        let name = format!("{}_{:06}.vtu", self.stem, self.frames.len());
        let path = self.dir.join(&name);
        let text = vtu_text(positions, fields);
        std::fs::write(&path, text).map_err(|e| GraniteError::io(&path, e))?;
        self.frames.push((time, name));
        let mut pvd =
            String::from("<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n");
        for (t, file) in &self.frames {
            let _ = writeln!(pvd, "<DataSet timestep=\"{t}\" part=\"0\" file=\"{file}\"/>");
        }
        pvd.push_str("</Collection>\n</VTKFile>\n");
        let pvd_path = self.dir.join(format!("{}.pvd", self.stem));
        std::fs::write(&pvd_path, pvd).map_err(|e| GraniteError::io(&pvd_path, e))?;
        Ok(path)
    }
}

/// Writes one stand-alone `.vtu` file.
pub fn write_vtu(path: &Path, positions: &[Vec3], fields: &[Field]) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| GraniteError::io(dir, e))?;
    }
    std::fs::write(path, vtu_text(positions, fields)).map_err(|e| GraniteError::io(path, e))
}

fn vtu_text(positions: &[Vec3], fields: &[Field]) -> String {
    let n = positions.len();
    let mut s = String::with_capacity(64 * n * (1 + fields.len()));
    let _ = write!(
        s,
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n\
         <UnstructuredGrid>\n<Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{n}\">\n<PointData>\n"
    );
    for f in fields {
        let _ = writeln!(
            s,
            "<DataArray type=\"Float64\" Name=\"{}\" NumberOfComponents=\"{}\" format=\"ascii\">",
            f.name, f.components
        );
        for chunk in f.values.chunks(f.components.max(1)) {
            for v in chunk {
                let _ = write!(s, "{v} ");
            }
            s.push('\n');
        }
        s.push_str("</DataArray>\n");
    }
    s.push_str("</PointData>\n<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n");
    for x in positions {
        let _ = writeln!(s, "{} {} {}", x[0], x[1], x[2]);
    }
    s.push_str("</DataArray>\n</Points>\n<Cells>\n<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n");
    for i in 0..n {
        let _ = write!(s, "{i} ");
    }
    s.push_str("\n</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n");
    for i in 0..n {
        let _ = write!(s, "{} ", i + 1);
    }
    s.push_str("\n</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
    for _ in 0..n {
        s.push_str("1 ");
    }
    s.push_str("\n</DataArray>\n</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");
    s
}
