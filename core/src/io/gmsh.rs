//! gmsh meshes (MSH 4.1 and 2.2, ASCII and binary) with their physical groups: the nodes, the
//! elements and the named groups they belong to. The geometry of a group (inside, distance,
//! measure) is in `mesh_region.rs`.
//!
//! Format references: the gmsh reference manual, "MSH file format" (version 4.1) and "Legacy
//! formats" (version 2.2). Elements of higher order keep all their nodes; the corner nodes come
//! first, so the geometry reads those.

use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use std::collections::HashMap;
use std::path::Path;

/// The shape of an element, whatever its order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ElementShape {
    Point,
    Line,
    Triangle,
    Quadrangle,
    Tetrahedron,
    Hexahedron,
    Prism,
    Pyramid,
}

impl ElementShape {
    /// Dimension of the element (0 for a point, 3 for a solid).
    pub fn dim(self) -> u8 {
        match self {
            ElementShape::Point => 0,
            ElementShape::Line => 1,
            ElementShape::Triangle | ElementShape::Quadrangle => 2,
            _ => 3,
        }
    }

    /// Number of corner nodes (the element's first nodes).
    pub fn corners(self) -> usize {
        match self {
            ElementShape::Point => 1,
            ElementShape::Line => 2,
            ElementShape::Triangle => 3,
            ElementShape::Quadrangle | ElementShape::Tetrahedron => 4,
            ElementShape::Hexahedron => 8,
            ElementShape::Prism => 6,
            ElementShape::Pyramid => 5,
        }
    }
}

/// gmsh's element type number: its shape and node count.
fn element_type(code: i64) -> Option<(ElementShape, usize)> {
    use ElementShape::*;
    Some(match code {
        15 => (Point, 1),
        1 => (Line, 2),
        8 => (Line, 3),
        26 => (Line, 4),
        27 => (Line, 5),
        28 => (Line, 6),
        2 => (Triangle, 3),
        9 => (Triangle, 6),
        20 => (Triangle, 9),
        21 => (Triangle, 10),
        22 => (Triangle, 12),
        23 => (Triangle, 15),
        3 => (Quadrangle, 4),
        16 => (Quadrangle, 8),
        10 => (Quadrangle, 9),
        4 => (Tetrahedron, 4),
        11 => (Tetrahedron, 10),
        29 => (Tetrahedron, 20),
        5 => (Hexahedron, 8),
        17 => (Hexahedron, 20),
        12 => (Hexahedron, 27),
        6 => (Prism, 6),
        18 => (Prism, 15),
        13 => (Prism, 18),
        7 => (Pyramid, 5),
        19 => (Pyramid, 13),
        14 => (Pyramid, 14),
        _ => return None,
    })
}

/// One element: its shape, its nodes (indices into [`GmshMesh::nodes`], corners first) and the
/// physical groups it belongs to (indices into [`GmshMesh::groups`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Element {
    pub shape: ElementShape,
    pub nodes: Vec<u32>,
    pub groups: Vec<u32>,
}

/// A physical group: its dimension, gmsh's tag and its name (`"tag N"` when the file names it
/// not).
#[derive(Debug, Clone, PartialEq)]
pub struct PhysicalGroup {
    pub dim: u8,
    pub tag: i32,
    pub name: String,
}

/// A mesh read from a gmsh file.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GmshMesh {
    pub nodes: Vec<Vec3>,
    pub elements: Vec<Element>,
    pub groups: Vec<PhysicalGroup>,
}

impl GmshMesh {
    /// Reads a `.msh` file of version 4.1 or 2.2, ASCII or binary.
    pub fn read(path: &Path) -> Result<GmshMesh> {
        let data =
            super::read_input(path).map_err(|e| GraniteError::Setup(format!("cannot read the mesh file: {e}")))?;
        GmshMesh::parse(&data).map_err(|why| GraniteError::Setup(format!("mesh file {}: {why}", path.display())))
    }

    /// Parses the bytes of a `.msh` file.
    pub fn parse(data: &[u8]) -> std::result::Result<GmshMesh, String> {
        Reader::new(data).read()
    }

    /// The index of the group called `name`, or an error naming the groups there are.
    pub fn group(&self, name: &str) -> Result<usize> {
        self.groups.iter().position(|g| g.name == name).ok_or_else(|| {
            let names: Vec<String> = self.groups.iter().map(|g| format!("\"{}\" ({}D)", g.name, g.dim)).collect();
            GraniteError::Setup(format!(
                "the mesh has no physical group \"{name}\"; its groups are {}",
                if names.is_empty() { "none (name them in gmsh with Physical ...)".into() } else { names.join(", ") }
            ))
        })
    }

    /// The elements of group `g`.
    pub fn elements_of(&self, g: usize) -> impl Iterator<Item = &Element> {
        self.elements.iter().filter(move |e| e.groups.contains(&(g as u32)))
    }

    /// The corner positions of an element.
    pub fn corners(&self, e: &Element) -> Vec<Vec3> {
        e.nodes[..e.shape.corners()].iter().map(|&n| self.nodes[n as usize]).collect()
    }
}

/// Reads a file section by section; numbers are text in an ASCII file, little- or big-endian
/// values in a binary one (`int` 4 bytes, `size_t` as the header says, `double` 8).
struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
    binary: bool,
    swap: bool,
    size_t: usize,
    version: u8,
    /// Node tag → index.
    node_index: HashMap<u64, u32>,
    /// Physical tags of each entity `(dim, tag)` (version 4.1).
    entity_groups: HashMap<(u8, i32), Vec<i32>>,
    /// Physical `(dim, tag)` → group index.
    group_index: HashMap<(u8, i32), u32>,
    mesh: GmshMesh,
}

type Parsed<T> = std::result::Result<T, String>;

impl<'a> Reader<'a> {
    fn new(data: &'a [u8]) -> Reader<'a> {
        Reader {
            data,
            pos: 0,
            binary: false,
            swap: false,
            size_t: 8,
            version: 0,
            node_index: HashMap::new(),
            entity_groups: HashMap::new(),
            group_index: HashMap::new(),
            mesh: GmshMesh::default(),
        }
    }

    fn read(mut self) -> Parsed<GmshMesh> {
        while let Some(section) = self.next_section()? {
            match section.as_str() {
                "MeshFormat" => self.format()?,
                "PhysicalNames" => self.physical_names()?,
                "Entities" if self.version == 4 => self.entities()?,
                "Nodes" => {
                    if self.version == 4 {
                        self.nodes_41()?
                    } else {
                        self.nodes_22()?
                    }
                }
                "Elements" => {
                    if self.version == 4 {
                        self.elements_41()?
                    } else {
                        self.elements_22()?
                    }
                }
                _ => {}
            }
            if self.version == 0 {
                return Err("not a gmsh mesh: it does not begin with $MeshFormat".into());
            }
            self.end_section(&section)?;
        }
        if self.mesh.nodes.is_empty() {
            return Err("no $Nodes section".into());
        }
        Ok(self.mesh)
    }

    /// The name of the next `$Section`, or None at the end of the file.
    fn next_section(&mut self) -> Parsed<Option<String>> {
        self.skip_space();
        if self.pos >= self.data.len() {
            return Ok(None);
        }
        if self.data[self.pos] != b'$' {
            return Err(format!("expected a $Section at byte {}", self.pos));
        }
        let line = self.line();
        Ok(Some(line[1..].trim().to_string()))
    }

    /// Moves past `$End<section>` (skipping what a section not read holds).
    fn end_section(&mut self, section: &str) -> Parsed<()> {
        let marker = format!("$End{section}");
        let rest = &self.data[self.pos..];
        let at = rest
            .windows(marker.len())
            .position(|w| w == marker.as_bytes())
            .ok_or_else(|| format!("section ${section} has no {marker}"))?;
        let between = &rest[..at];
        // A section that was read must end where its contents do.
        if matches!(section, "MeshFormat" | "PhysicalNames" | "Nodes" | "Elements" | "Entities")
            && !between.iter().all(|b| b.is_ascii_whitespace())
            && !(section == "Entities" && self.version != 4)
        {
            return Err(format!("section ${section} holds more than its counts say"));
        }
        self.pos += at + marker.len();
        Ok(())
    }

    /// Moves past the end of the current line (where a binary block follows a text count).
    fn skip_line_end(&mut self) {
        while self.pos < self.data.len() && self.data[self.pos] != b'\n' {
            self.pos += 1;
        }
        self.pos = (self.pos + 1).min(self.data.len());
    }

    /// Where the reader is, for messages: a line of a text file, a byte of a binary one.
    fn place(&self, at: usize) -> String {
        if self.binary {
            format!("at byte {at}")
        } else {
            let line = 1 + self.data[..at.min(self.data.len())].iter().filter(|&&b| b == b'\n').count();
            format!("on line {line}")
        }
    }

    /// A physical or entity dimension: 0 to 3.
    fn dimension(value: i64) -> Parsed<u8> {
        u8::try_from(value)
            .ok()
            .filter(|&d| d <= 3)
            .ok_or_else(|| format!("a dimension of {value} (a physical group or entity is of dimension 0, 1, 2 or 3)"))
    }

    /// In a text file, moves to the next token (so that its line is the one a message names).
    fn skip_space_if_text(&mut self) {
        if !self.binary {
            self.skip_space();
        }
    }

    fn skip_space(&mut self) {
        while self.pos < self.data.len() && self.data[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
    }

    /// The rest of the current line, without its end.
    fn line(&mut self) -> String {
        let start = self.pos;
        while self.pos < self.data.len() && self.data[self.pos] != b'\n' {
            self.pos += 1;
        }
        let s = String::from_utf8_lossy(&self.data[start..self.pos]).trim_end_matches('\r').to_string();
        if self.pos < self.data.len() {
            self.pos += 1;
        }
        s
    }

    fn token(&mut self) -> Parsed<&'a str> {
        self.skip_space();
        let start = self.pos;
        while self.pos < self.data.len() && !self.data[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        if start == self.pos {
            return Err("the file ends in the middle of a section".into());
        }
        std::str::from_utf8(&self.data[start..self.pos]).map_err(|_| format!("unreadable text at byte {start}"))
    }

    fn text_int(&mut self) -> Parsed<i64> {
        let t = self.token()?;
        t.parse().map_err(|_| format!("expected an integer, found \"{t}\""))
    }

    fn text_f64(&mut self) -> Parsed<f64> {
        let t = self.token()?;
        t.parse().map_err(|_| format!("expected a number, found \"{t}\""))
    }

    fn bytes(&mut self, n: usize) -> Parsed<&'a [u8]> {
        if self.pos + n > self.data.len() {
            return Err("the file ends in the middle of binary data".into());
        }
        let b = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(b)
    }

    fn raw<const N: usize>(&mut self) -> Parsed<[u8; N]> {
        let mut b: [u8; N] = self.bytes(N)?.try_into().expect("N bytes");
        if self.swap {
            b.reverse();
        }
        Ok(b)
    }

    /// An `int`: text, or 4 binary bytes.
    fn int(&mut self) -> Parsed<i64> {
        if self.binary {
            Ok(i32::from_le_bytes(self.raw::<4>()?) as i64)
        } else {
            self.text_int()
        }
    }

    /// A `size_t` (a count or a tag in version 4.1).
    fn size(&mut self) -> Parsed<u64> {
        if !self.binary {
            let v = self.text_int()?;
            return u64::try_from(v).map_err(|_| format!("expected a count >= 0, found {v}"));
        }
        Ok(match self.size_t {
            4 => u32::from_le_bytes(self.raw::<4>()?) as u64,
            _ => u64::from_le_bytes(self.raw::<8>()?),
        })
    }

    fn real(&mut self) -> Parsed<f64> {
        if self.binary {
            Ok(f64::from_le_bytes(self.raw::<8>()?))
        } else {
            self.text_f64()
        }
    }

    /// A count, refused when it could not fit in what is left of the file (a damaged header).
    fn count(&mut self, bytes_each: usize) -> Parsed<usize> {
        let n = self.size()?;
        let left = (self.data.len() - self.pos) as u64;
        if n.saturating_mul(bytes_each.max(1) as u64) > left {
            return Err(format!("a count of {n} is larger than the rest of the file"));
        }
        Ok(n as usize)
    }

    fn format(&mut self) -> Parsed<()> {
        let version = self.token()?.to_string();
        let file_type = self.text_int()?;
        let size = self.text_int()?;
        self.version = match version.as_str() {
            "4.1" => 4,
            "2.2" | "2.1" | "2" | "2.0" => 2,
            v => return Err(format!("MSH version {v} is not read: save the mesh as version 4.1 or 2.2")),
        };
        self.size_t = match size {
            4 | 8 => size as usize,
            s => return Err(format!("data size {s} (expected 4 or 8)")),
        };
        self.binary = file_type == 1;
        if self.binary {
            // One `int` 1 tells the byte order.
            self.skip_line_end();
            let one = self.bytes(4)?;
            self.swap = match one {
                [1, 0, 0, 0] => false,
                [0, 0, 0, 1] => true,
                _ => return Err("binary file without its byte-order mark".into()),
            };
        }
        Ok(())
    }

    fn physical_names(&mut self) -> Parsed<()> {
        // Always text, in binary files too.
        let n = self.text_int()?;
        for _ in 0..n {
            let dim = Self::dimension(self.text_int()?)?;
            let tag = Self::tag(self.text_int()?)?;
            self.skip_space();
            let line = self.line();
            let name = line.trim().trim_matches('"').to_string();
            self.add_group(dim, tag, Some(name));
        }
        Ok(())
    }

    fn add_group(&mut self, dim: u8, tag: i32, name: Option<String>) -> u32 {
        if let Some(&g) = self.group_index.get(&(dim, tag)) {
            if let Some(name) = name {
                self.mesh.groups[g as usize].name = name;
            }
            return g;
        }
        let g = self.mesh.groups.len() as u32;
        self.mesh.groups.push(PhysicalGroup { dim, tag, name: name.unwrap_or_else(|| format!("tag {tag}")) });
        self.group_index.insert((dim, tag), g);
        g
    }

    fn entities(&mut self) -> Parsed<()> {
        let counts = [self.size()?, self.size()?, self.size()?, self.size()?];
        for (dim, &n) in counts.iter().enumerate() {
            for _ in 0..n {
                let tag = Self::tag(self.int()?)?;
                for _ in 0..if dim == 0 { 3 } else { 6 } {
                    self.real()?;
                }
                let physical = self.count(4)?;
                let tags = (0..physical).map(|_| self.int().and_then(Self::tag)).collect::<Parsed<Vec<i32>>>()?;
                if dim > 0 {
                    let bounding = self.count(4)?;
                    for _ in 0..bounding {
                        self.int()?;
                    }
                }
                self.entity_groups.insert((dim as u8, tag), tags);
            }
        }
        Ok(())
    }

    /// A physical or entity tag, which gmsh writes as an `int`.
    fn tag(value: i64) -> Parsed<i32> {
        i32::try_from(value).map_err(|_| format!("a tag of {value} (gmsh's tags fit a 32-bit integer)"))
    }

    /// Stores node `tag`, read from `at`; a corner at NaN or infinity is refused there.
    fn push_node(&mut self, tag: u64, x: Vec3, at: usize) -> Parsed<()> {
        if let Some(bad) = x.iter().find(|v| !v.is_finite()) {
            return Err(format!(
                "node {tag} {} is at ({}, {}, {}): a node's coordinates must be finite numbers, not {bad}",
                self.place(at),
                x[0],
                x[1],
                x[2]
            ));
        }
        let index = self.mesh.nodes.len() as u32;
        if self.node_index.insert(tag, index).is_some() {
            return Err(format!("node {tag} is given twice"));
        }
        self.mesh.nodes.push(x);
        Ok(())
    }

    fn nodes_41(&mut self) -> Parsed<()> {
        let blocks = self.size()?;
        let total = self.count(8)?;
        self.size()?;
        self.size()?;
        self.mesh.nodes.reserve(total);
        for _ in 0..blocks {
            let dim = self.int()?;
            self.int()?;
            let parametric = self.int()? != 0;
            let n = self.count(8)?;
            let tags = (0..n).map(|_| self.size()).collect::<Parsed<Vec<u64>>>()?;
            let extra = if parametric { dim.max(0) as usize } else { 0 };
            for tag in tags {
                self.skip_space_if_text();
                let at = self.pos;
                let x = [self.real()?, self.real()?, self.real()?];
                for _ in 0..extra {
                    self.real()?;
                }
                self.push_node(tag, x, at)?;
            }
        }
        Ok(())
    }

    fn nodes_22(&mut self) -> Parsed<()> {
        // The count is text in binary files too.
        let n = self.text_int()?;
        if n < 0 {
            return Err(format!("a count of {n} nodes"));
        }
        if self.binary {
            self.skip_line_end();
        }
        for _ in 0..n {
            self.skip_space_if_text();
            let at = self.pos;
            let tag = self.int()?;
            let tag =
                u64::try_from(tag).map_err(|_| format!("node tag {tag} {} (tags are positive)", self.place(at)))?;
            let x = [self.real()?, self.real()?, self.real()?];
            self.push_node(tag, x, at)?;
        }
        Ok(())
    }

    fn node(&self, tag: u64) -> Parsed<u32> {
        self.node_index.get(&tag).copied().ok_or_else(|| format!("an element names node {tag}, which is not given"))
    }

    fn shape_of(code: i64) -> Parsed<(ElementShape, usize)> {
        element_type(code).ok_or_else(|| format!("element type {code} is not read"))
    }

    fn elements_41(&mut self) -> Parsed<()> {
        let blocks = self.size()?;
        let total = self.count(8)?;
        self.size()?;
        self.size()?;
        self.mesh.elements.reserve(total);
        for _ in 0..blocks {
            let dim = Self::dimension(self.int()?)?;
            let entity = Self::tag(self.int()?)?;
            let (shape, count) = Self::shape_of(self.int()?)?;
            let n = self.count(8)?;
            let physical = self.entity_groups.get(&(dim, entity)).cloned().unwrap_or_default();
            let groups: Vec<u32> = physical.iter().map(|&t| self.add_group(dim, t.saturating_abs(), None)).collect();
            for _ in 0..n {
                self.size()?;
                let nodes = (0..count).map(|_| self.size().and_then(|t| self.node(t))).collect::<Parsed<Vec<u32>>>()?;
                self.mesh.elements.push(Element { shape, nodes, groups: groups.clone() });
            }
        }
        Ok(())
    }

    fn elements_22(&mut self) -> Parsed<()> {
        let total = self.text_int()?;
        if !self.binary {
            for _ in 0..total {
                self.text_int()?;
                let (shape, count) = Self::shape_of(self.text_int()?)?;
                let tags = (0..self.text_int()?).map(|_| self.text_int()).collect::<Parsed<Vec<i64>>>()?;
                let nodes = (0..count)
                    .map(|_| self.text_int().and_then(|t| self.node(t as u64)))
                    .collect::<Parsed<Vec<u32>>>()?;
                self.push_element_22(shape, nodes, &tags)?;
            }
            return Ok(());
        }
        if total < 0 {
            return Err(format!("a count of {total} elements"));
        }
        self.skip_line_end();
        let mut read = 0;
        while read < total {
            let (shape, count) = Self::shape_of(self.int()?)?;
            let following = self.int()?;
            let tag_count = self.int()?;
            if following <= 0 || tag_count < 0 {
                return Err("a damaged block of binary elements".into());
            }
            for _ in 0..following {
                self.int()?;
                let tags = (0..tag_count).map(|_| self.int()).collect::<Parsed<Vec<i64>>>()?;
                let nodes =
                    (0..count).map(|_| self.int().and_then(|t| self.node(t as u64))).collect::<Parsed<Vec<u32>>>()?;
                self.push_element_22(shape, nodes, &tags)?;
            }
            read += following;
        }
        Ok(())
    }

    /// Version 2.2: the first tag is the physical group (0: none).
    fn push_element_22(&mut self, shape: ElementShape, nodes: Vec<u32>, tags: &[i64]) -> Parsed<()> {
        let groups = match tags.first() {
            Some(&t) if t != 0 => vec![self.add_group(shape.dim(), Self::tag(t)?, None)],
            _ => Vec::new(),
        };
        self.mesh.elements.push(Element { shape, nodes, groups });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::region::Simplices;

    fn mesh(name: &str) -> GmshMesh {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/meshes").join(name);
        GmshMesh::read(&path).unwrap()
    }

    /// Shoelace area of a polygon.
    fn polygon_area(corners: &[(f64, f64)]) -> f64 {
        let n = corners.len();
        0.5 * (0..n)
            .map(|i| {
                let ((x0, y0), (x1, y1)) = (corners[i], corners[(i + 1) % n]);
                x0 * y1 - x1 * y0
            })
            .sum::<f64>()
            .abs()
    }

    fn measure(m: &GmshMesh, group: &str) -> f64 {
        Simplices::of_group(m, m.group(group).unwrap(), 2).unwrap().measure()
    }

    #[test]
    fn the_four_encodings_give_one_mesh_with_its_named_groups() {
        // The corners make_meshes.py gives gmsh.
        let foundation = [(0.0, 0.0), (10.0, 0.0), (10.0, 2.0), (7.0, 2.0), (3.0, 2.0), (0.0, 2.0)];
        let embankment = [(3.0, 2.0), (7.0, 2.0), (5.5, 3.5), (4.5, 3.5)];
        let slope = 2.0 * (1.5f64 * 1.5 + 1.5 * 1.5).sqrt() + 1.0;
        let first = mesh("embankment_v41_ascii.msh");
        for name in [
            "embankment_v41_ascii.msh",
            "embankment_v41_binary.msh",
            "embankment_v22_ascii.msh",
            "embankment_v22_binary.msh",
        ] {
            let m = mesh(name);
            let names: Vec<(&str, u8)> = m.groups.iter().map(|g| (g.name.as_str(), g.dim)).collect();
            assert_eq!(
                names,
                [("base", 1), ("sides", 1), ("slope", 1), ("foundation", 2), ("embankment", 2)],
                "{name}"
            );
            assert_eq!(m.nodes.len(), first.nodes.len(), "{name}");
            assert_eq!(m.elements.len(), first.elements.len(), "{name}");
            // ASCII files carry 16 significant digits: positions up to 10 m agree to 1e-14 m.
            let sorted = |m: &GmshMesh| {
                let mut x = m.nodes.clone();
                x.sort_by(|a, b| {
                    a.iter()
                        .zip(b)
                        .map(|(p, q)| p.total_cmp(q))
                        .find(|o| o.is_ne())
                        .unwrap_or(std::cmp::Ordering::Equal)
                });
                x
            };
            for (p, q) in sorted(&m).iter().zip(sorted(&first)) {
                assert!((0..3).all(|a| (p[a] - q[a]).abs() < 1e-14), "{name}: node at {p:?} against {q:?}");
            }
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b;
            assert!(close(measure(&m, "foundation"), polygon_area(&foundation)), "{name}");
            assert!(close(measure(&m, "embankment"), polygon_area(&embankment)), "{name}");
            assert!(close(measure(&m, "base"), 10.0) && close(measure(&m, "sides"), 4.0), "{name}");
            assert!(close(measure(&m, "slope"), slope), "{name}");
        }
    }

    #[test]
    fn second_order_elements_are_read_by_their_corners() {
        let m = mesh("embankment_order2.msh");
        assert!(m.elements.iter().any(|e| e.shape == ElementShape::Triangle && e.nodes.len() == 6));
        let first = mesh("embankment_v41_ascii.msh");
        for group in ["foundation", "embankment", "slope"] {
            assert!((measure(&m, group) - measure(&first, group)).abs() < 1e-12 * measure(&first, group), "{group}");
        }
    }

    #[test]
    fn a_volume_group_of_tetrahedra_has_the_volume_of_its_solid() {
        let m = mesh("wedge_block.msh");
        let block = Simplices::of_group(&m, m.group("block").unwrap(), 3).unwrap();
        // A unit square base under a top plane from 0.5 (x = 0) to 0.25 (x = 1): mean height 0.375.
        let heights = [0.5, 0.25];
        let volume = 0.5 * (heights[0] + heights[1]);
        assert!((block.measure() - volume).abs() < 1e-12, "{}", block.measure());
        assert!(block.contains([0.5, 0.5, 0.37]) && !block.contains([0.5, 0.5, 0.38]));
        let bottom = Simplices::of_group(&m, m.group("bottom").unwrap(), 3).unwrap();
        assert!((bottom.measure() - 1.0).abs() < 1e-12);
        assert!((bottom.distance_within([0.3, 0.6, 0.1], 0.2).unwrap() - 0.1).abs() < 1e-15);
        assert_eq!(bottom.distance_within([0.3, 0.6, 0.3], 0.2), None);
    }

    #[test]
    fn nodes_at_nan_or_infinity_are_refused_naming_the_node_and_its_line() {
        let text = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/meshes/embankment_v22_ascii.msh"),
        )
        .unwrap();
        let lines: Vec<&str> = text.lines().collect();
        let nodes = lines.iter().position(|l| *l == "$Nodes").unwrap();
        // `$Nodes` is on line nodes + 1 (counted from 1), its count on the next: the third node
        // is on line nodes + 5.
        let third = nodes + 5;
        let tag = lines[third - 1].split_whitespace().next().unwrap().to_string();
        for bad in ["nan", "inf", "-inf"] {
            let mut damaged = lines.clone();
            let fields: Vec<&str> = lines[third - 1].split_whitespace().collect();
            let line = format!("{} {} {bad} {}", fields[0], fields[1], fields[3]);
            damaged[third - 1] = &line;
            let e = GmshMesh::parse(damaged.join("\n").as_bytes()).unwrap_err();
            assert!(e.contains(&format!("node {tag} on line {third}")) && e.contains("finite"), "{bad}: {e}");
        }
    }

    #[test]
    fn damaged_files_and_unknown_groups_are_refused_with_a_reason() {
        let text =
            std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/meshes/embankment_v41_ascii.msh"))
                .unwrap();
        let cut = GmshMesh::parse(&text[..text.len() / 2]).unwrap_err();
        assert!(cut.contains("ends") || cut.contains("has no"), "{cut}");
        let v3 = GmshMesh::parse(b"$MeshFormat\n3.0 0 8\n$EndMeshFormat\n").unwrap_err();
        assert!(v3.contains("version 3.0 is not read"), "{v3}");
        assert!(GmshMesh::parse(b"solid x\nendsolid\n").unwrap_err().contains("$Section"));
        // A binary file cut right after an empty count: an error, not a read past its end.
        let binary_head = [b"$MeshFormat\n2.2 1 8\n".as_slice(), &[1, 0, 0, 0], b"\n$EndMeshFormat\n"].concat();
        for tail in [b"$Nodes\n0".as_slice(), b"$Nodes\n0\n$EndNodes\n$Elements\n0"] {
            let e = GmshMesh::parse(&[binary_head.as_slice(), tail].concat()).unwrap_err();
            assert!(e.contains("has no $End") || e.contains("ends"), "{e}");
        }
        let dim =
            GmshMesh::parse(b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n1\n-7 1 \"x\"\n").unwrap_err();
        assert!(dim.contains("dimension of -7"), "{dim}");
        let m = mesh("embankment_v22_ascii.msh");
        let e = m.group("dam").unwrap_err().to_string();
        assert!(e.contains("\"dam\"") && e.contains("\"slope\" (1D)"), "{e}");
    }
}
