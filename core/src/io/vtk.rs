//! ParaView output: one XML VTK file per frame and a `.pvd` index per series. Points (material
//! points, spheres) are `.vtu` files of vertices; walls and contact networks are `.vtp` poly data.
//!
//! Arrays are written appended and zlib-compressed by default (`header_type="UInt64"`, one
//! block per array: the header `[1, n, n, compressed size]` before the compressed bytes), or as
//! ASCII text when asked. Integer fields (ids, materials, counts) are `Int64` arrays.

use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// A named field with 1, 3, 6 or 9 components per point (or per cell of poly data).
pub struct Field {
    pub name: String,
    pub components: usize,
    pub values: Vec<f64>,
    /// Written as `Int64` (the values are whole numbers below 2^53: ids, materials, counts).
    pub integer: bool,
}

impl Field {
    pub fn float(name: &str, components: usize, values: Vec<f64>) -> Field {
        Field { name: name.into(), components, values, integer: false }
    }
    pub fn int(name: &str, values: impl IntoIterator<Item = i64>) -> Field {
        Field {
            name: name.into(),
            components: 1,
            values: values.into_iter().map(|v| v as f64).collect(),
            integer: true,
        }
    }
}

/// Lines (contacts) or polygons (walls) with data per point and per cell.
#[derive(Default)]
pub struct PolyData {
    pub points: Vec<Vec3>,
    pub lines: Vec<[u32; 2]>,
    pub polygons: Vec<Vec<u32>>,
    pub point_fields: Vec<Field>,
    /// One value per line, then one per polygon (VTK's cell order).
    pub cell_fields: Vec<Field>,
}

/// How arrays are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Encoding {
    /// Appended raw data, zlib-compressed: an MPM frame of 800 Mohr-Coulomb points takes 94 bytes
    /// a point against 490 in ASCII.
    #[default]
    Binary,
    Ascii,
}

impl Encoding {
    pub fn parse(name: &str) -> Result<Encoding> {
        match name {
            "binary" => Ok(Encoding::Binary),
            "ascii" => Ok(Encoding::Ascii),
            other => Err(GraniteError::param("vtk format", format!("\"{other}\""), "\"binary\" or \"ascii\"")),
        }
    }
}

/// Where a run's frames go: one XML file a frame (`vtk/points_N.vtu` and `.pvd` indices), or one
/// VTKHDF file holding them all (`vtk/run.vtkhdf`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VtkFormat {
    Xml(Encoding),
    VtkHdf,
}

impl Default for VtkFormat {
    fn default() -> Self {
        VtkFormat::Xml(Encoding::default())
    }
}

impl VtkFormat {
    pub fn parse(name: &str) -> Result<VtkFormat> {
        const ALLOWED: &str = "\"binary\", \"ascii\" or \"vtkhdf\"";
        match name {
            "vtkhdf" if cfg!(feature = "vtkhdf") => Ok(VtkFormat::VtkHdf),
            "vtkhdf" => Err(GraniteError::param(
                "vtk format",
                "\"vtkhdf\"",
                "\"binary\" or \"ascii\" in this build: VTKHDF needs granite built with `--features vtkhdf` \
                 (and the HDF5 library: `apt-get install libhdf5-dev`)",
            )),
            "binary" | "ascii" => Encoding::parse(name).map(VtkFormat::Xml),
            other => Err(GraniteError::param("vtk format", format!("\"{other}\""), ALLOWED)),
        }
    }
}

/// A frame series: numbered files and their `.pvd` index.
pub struct VtkWriter {
    dir: PathBuf,
    stem: String,
    frames: Vec<(f64, String)>,
    pub encoding: Encoding,
}

impl VtkWriter {
    /// A new series in `dir`. Frames of an earlier run with the same stem are removed first: a
    /// shorter new run would otherwise leave the old run's later frames beside its own.
    pub fn new(dir: &Path, stem: &str) -> Result<VtkWriter> {
        Self::keeping(dir, stem, Vec::new())
    }

    /// The series `stem` in `dir` continued by a run resumed at `time`: the frames its `.pvd`
    /// lists before that time are kept (the resumed run writes the later ones again), the others
    /// removed, and new frames numbered after the kept ones.
    pub fn resume(dir: &Path, stem: &str, time: f64) -> Result<VtkWriter> {
        let pvd = std::fs::read_to_string(dir.join(format!("{stem}.pvd"))).unwrap_or_default();
        let attribute = |line: &str, name: &str| -> Option<String> {
            let start = line.find(&format!("{name}=\""))? + name.len() + 2;
            Some(line[start..].split('"').next()?.to_string())
        };
        let mut kept = Vec::new();
        for line in pvd.lines().filter(|l| l.trim_start().starts_with("<DataSet")) {
            let (Some(t), Some(file)) = (attribute(line, "timestep"), attribute(line, "file")) else { break };
            // Frames are numbered in order: the first one missing or too late ends the run's part.
            let expected = frame_index(stem, &file) == Some(kept.len());
            match t.parse::<f64>() {
                Ok(t) if t < time && expected && dir.join(&file).is_file() => kept.push((t, file)),
                _ => break,
            }
        }
        Self::keeping(dir, stem, kept)
    }

    /// A series in `dir` whose first frames are `kept`; other frames of `stem` found there, left by
    /// an earlier run, are removed (a shorter new run would otherwise leave them beside its own).
    fn keeping(dir: &Path, stem: &str, kept: Vec<(f64, String)>) -> Result<VtkWriter> {
        // `vtk/` of an output folder: a link there would take every frame elsewhere.
        super::output_folder(dir.parent().unwrap_or(dir), dir)?;
        let entries = std::fs::read_dir(dir).map_err(|e| GraniteError::io(dir, e))?;
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().to_string();
            if frame_index(stem, &name).is_some_and(|k| k >= kept.len()) {
                let _ = std::fs::remove_file(entry.path());
            }
        }
        Ok(VtkWriter { dir: dir.to_path_buf(), stem: stem.into(), frames: kept, encoding: Encoding::default() })
    }

    pub fn frames(&self) -> usize {
        self.frames.len()
    }

    /// Writes one frame of points and rewrites the `.pvd` index.
    pub fn write_frame(&mut self, time: f64, positions: &[Vec3], fields: &[Field]) -> Result<PathBuf> {
        let bytes = vtu(positions, fields, self.encoding);
        self.write(time, "vtu", &bytes)
    }

    /// Writes one frame of poly data and rewrites the `.pvd` index.
    pub fn write_poly_frame(&mut self, time: f64, data: &PolyData) -> Result<PathBuf> {
        let bytes = vtp(data, self.encoding);
        self.write(time, "vtp", &bytes)
    }

    fn write(&mut self, time: f64, extension: &str, bytes: &[u8]) -> Result<PathBuf> {
        let name = format!("{}_{:06}.{extension}", self.stem, self.frames.len());
        let path = self.dir.join(&name);
        super::durable::replace(&path, bytes, super::durable::Flush::ToSystem)?;
        self.frames.push((time, name));
        let mut pvd =
            String::from("<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n");
        for (t, file) in &self.frames {
            let _ = writeln!(pvd, "<DataSet timestep=\"{t}\" part=\"0\" file=\"{file}\"/>");
        }
        pvd.push_str("</Collection>\n</VTKFile>\n");
        let pvd_path = self.dir.join(format!("{}.pvd", self.stem));
        super::durable::replace(&pvd_path, pvd.as_bytes(), super::durable::Flush::ToSystem)?;
        Ok(path)
    }
}

/// The number of frame file `name` of series `stem` (`points_000012.vtu` → 12).
fn frame_index(stem: &str, name: &str) -> Option<usize> {
    let rest = name.strip_prefix(stem)?.strip_prefix('_')?;
    let (digits, ext) = rest.split_once('.')?;
    let frame = digits.len() == 6 && digits.bytes().all(|b| b.is_ascii_digit()) && (ext == "vtu" || ext == "vtp");
    if frame {
        digits.parse().ok()
    } else {
        None
    }
}

/// Writes one stand-alone `.vtu` file.
pub fn write_vtu(path: &Path, positions: &[Vec3], fields: &[Field]) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| GraniteError::io(dir, e))?;
    }
    let bytes = vtu(positions, fields, Encoding::default());
    super::create_in_folder(path).and_then(|mut f| f.write_all(&bytes)).map_err(|e| GraniteError::io(path, e))
}

/// The XML text of a file, and its appended binary data.
struct Document {
    xml: String,
    appended: Vec<u8>,
    encoding: Encoding,
}

impl Document {
    fn new(kind: &str, encoding: Encoding) -> Document {
        let compressor = match encoding {
            Encoding::Binary => " header_type=\"UInt64\" compressor=\"vtkZLibDataCompressor\"",
            Encoding::Ascii => "",
        };
        let xml = format!(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"{kind}\" version=\"1.0\" byte_order=\"LittleEndian\"{compressor}>\n<{kind}>\n"
        );
        Document { xml, appended: Vec::new(), encoding }
    }

    /// One `DataArray` of `type` (`Float64`, `Int64`, `UInt8`) from its little-endian bytes and
    /// its values as text.
    fn array(
        &mut self,
        ty: &str,
        name: Option<&str>,
        components: usize,
        bytes: Vec<u8>,
        text: impl FnOnce() -> String,
    ) {
        let name = name.map(|n| format!(" Name=\"{n}\"")).unwrap_or_default();
        match self.encoding {
            Encoding::Ascii => {
                let _ = writeln!(
                    self.xml,
                    "<DataArray type=\"{ty}\"{name} NumberOfComponents=\"{components}\" format=\"ascii\">\n{}\n</DataArray>",
                    text()
                );
            }
            Encoding::Binary => {
                let _ = writeln!(
                    self.xml,
                    "<DataArray type=\"{ty}\"{name} NumberOfComponents=\"{components}\" format=\"appended\" offset=\"{}\"/>",
                    self.appended.len()
                );
                let header: [u64; 3] = [1, bytes.len() as u64, bytes.len() as u64];
                if bytes.is_empty() {
                    // No block at all.
                    self.appended.extend_from_slice(&0u64.to_le_bytes());
                    self.appended.extend_from_slice(&0u64.to_le_bytes());
                    self.appended.extend_from_slice(&0u64.to_le_bytes());
                    return;
                }
                let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
                // Writing into memory cannot fail.
                let _ = z.write_all(&bytes);
                let compressed = z.finish().unwrap_or_default();
                for h in header {
                    self.appended.extend_from_slice(&h.to_le_bytes());
                }
                self.appended.extend_from_slice(&(compressed.len() as u64).to_le_bytes());
                self.appended.extend_from_slice(&compressed);
            }
        }
    }

    fn floats(&mut self, name: Option<&str>, components: usize, values: &[f64]) {
        let bytes = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.array("Float64", name, components, bytes, || join(values.iter().map(|v| v.to_string())));
    }

    fn ints(&mut self, name: Option<&str>, components: usize, values: &[i64]) {
        let bytes = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.array("Int64", name, components, bytes, || join(values.iter().map(|v| v.to_string())));
    }

    fn bytes(&mut self, name: Option<&str>, values: &[u8]) {
        self.array("UInt8", name, 1, values.to_vec(), || join(values.iter().map(|v| v.to_string())));
    }

    fn field(&mut self, f: &Field) {
        if f.integer {
            let values: Vec<i64> = f.values.iter().map(|&v| v as i64).collect();
            self.ints(Some(&f.name), f.components, &values);
        } else {
            self.floats(Some(&f.name), f.components, &f.values);
        }
    }

    fn points(&mut self, positions: &[Vec3]) {
        self.xml.push_str("<Points>\n");
        let flat: Vec<f64> = positions.iter().flatten().copied().collect();
        self.floats(None, 3, &flat);
        self.xml.push_str("</Points>\n");
    }

    fn finish(mut self, kind: &str) -> Vec<u8> {
        let _ = writeln!(self.xml, "</{kind}>");
        let mut out = self.xml.into_bytes();
        if self.encoding == Encoding::Binary {
            out.extend_from_slice(b"<AppendedData encoding=\"raw\">\n_");
            out.extend_from_slice(&self.appended);
            out.extend_from_slice(b"\n</AppendedData>\n");
        }
        out.extend_from_slice(b"</VTKFile>\n");
        out
    }
}

fn join(items: impl Iterator<Item = String>) -> String {
    items.collect::<Vec<_>>().join(" ")
}

/// An unstructured grid of one vertex per point.
fn vtu(positions: &[Vec3], fields: &[Field], encoding: Encoding) -> Vec<u8> {
    let n = positions.len();
    let mut d = Document::new("UnstructuredGrid", encoding);
    let _ = writeln!(d.xml, "<Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{n}\">\n<PointData>");
    for f in fields {
        d.field(f);
    }
    d.xml.push_str("</PointData>\n");
    d.points(positions);
    d.xml.push_str("<Cells>\n");
    let ids: Vec<i64> = (0..n as i64).collect();
    d.ints(Some("connectivity"), 1, &ids);
    let offsets: Vec<i64> = (1..=n as i64).collect();
    d.ints(Some("offsets"), 1, &offsets);
    d.bytes(Some("types"), &vec![1u8; n]);
    d.xml.push_str("</Cells>\n</Piece>\n");
    d.finish("UnstructuredGrid")
}

/// Poly data: lines and polygons.
fn vtp(p: &PolyData, encoding: Encoding) -> Vec<u8> {
    let mut d = Document::new("PolyData", encoding);
    let _ = writeln!(
        d.xml,
        "<Piece NumberOfPoints=\"{}\" NumberOfVerts=\"0\" NumberOfLines=\"{}\" NumberOfStrips=\"0\" NumberOfPolys=\"{}\">",
        p.points.len(),
        p.lines.len(),
        p.polygons.len()
    );
    d.xml.push_str("<PointData>\n");
    for f in &p.point_fields {
        d.field(f);
    }
    d.xml.push_str("</PointData>\n<CellData>\n");
    for f in &p.cell_fields {
        d.field(f);
    }
    d.xml.push_str("</CellData>\n");
    d.points(&p.points);
    d.xml.push_str("<Lines>\n");
    let connectivity: Vec<i64> = p.lines.iter().flatten().map(|&i| i as i64).collect();
    d.ints(Some("connectivity"), 1, &connectivity);
    let offsets: Vec<i64> = (1..=p.lines.len() as i64).map(|k| 2 * k).collect();
    d.ints(Some("offsets"), 1, &offsets);
    d.xml.push_str("</Lines>\n<Polys>\n");
    let connectivity: Vec<i64> = p.polygons.iter().flatten().map(|&i| i as i64).collect();
    d.ints(Some("connectivity"), 1, &connectivity);
    let offsets: Vec<i64> = p
        .polygons
        .iter()
        .scan(0i64, |end, poly| {
            *end += poly.len() as i64;
            Some(*end)
        })
        .collect();
    d.ints(Some("offsets"), 1, &offsets);
    d.xml.push_str("</Polys>\n</Piece>\n");
    d.finish("PolyData")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;

    /// Reads back the arrays of a binary file by the layout the module doc gives.
    fn arrays(bytes: &[u8]) -> Vec<Vec<u8>> {
        let start = bytes.windows(2).position(|w| w == b"\n_").unwrap() + 2;
        let text = String::from_utf8_lossy(&bytes[..start]);
        let offsets: Vec<usize> =
            text.split("offset=\"").skip(1).map(|s| s.split('"').next().unwrap().parse().unwrap()).collect();
        offsets
            .iter()
            .map(|&o| {
                let at = start + o;
                let word =
                    |k: usize| u64::from_le_bytes(bytes[at + 8 * k..at + 8 * k + 8].try_into().unwrap()) as usize;
                if word(0) == 0 {
                    return Vec::new();
                }
                let (size, compressed) = (word(1), word(3));
                let mut out = Vec::new();
                flate2::read::ZlibDecoder::new(&bytes[at + 32..at + 32 + compressed]).read_to_end(&mut out).unwrap();
                assert_eq!(out.len(), size);
                out
            })
            .collect()
    }

    #[test]
    fn binary_arrays_read_back() {
        let fields = [Field::int("id", [7, -3]), Field::float("v", 3, vec![1.5, 2.0, -3.0, 0.25, 1e300, 0.0])];
        let bytes = vtu(&[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]], &fields, Encoding::Binary);
        let a = arrays(&bytes);
        let ints = |b: &[u8]| b.chunks(8).map(|c| i64::from_le_bytes(c.try_into().unwrap())).collect::<Vec<_>>();
        let floats = |b: &[u8]| b.chunks(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect::<Vec<_>>();
        assert_eq!(ints(&a[0]), vec![7, -3]);
        assert_eq!(floats(&a[1]), fields[1].values);
        assert_eq!(floats(&a[2]), vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(ints(&a[3]), vec![0, 1]);
        let text = String::from_utf8_lossy(&bytes);
        assert!(text.contains("type=\"Int64\" Name=\"id\""));
    }

    #[test]
    fn ascii_stays_available() {
        let bytes = vtp(
            &PolyData {
                points: vec![[0.0; 3], [1.0, 0.0, 0.0]],
                lines: vec![[0, 1]],
                cell_fields: vec![Field::float("normal_force", 1, vec![2.5])],
                ..Default::default()
            },
            Encoding::Ascii,
        );
        let text = String::from_utf8(bytes).unwrap();
        assert!(text.contains("NumberOfLines=\"1\"") && text.contains(">\n2.5\n</DataArray>"));
        assert!(!text.contains("AppendedData"));
    }
}
