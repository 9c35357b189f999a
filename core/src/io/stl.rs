//! STL files (ASCII and binary): the triangles of a surface, for mesh walls. The facet normals
//! the file gives are not read: a wall's triangles are touched from either side.

use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use std::path::Path;

/// Reads the triangles of an STL file, ASCII (`solid ... facet ... vertex x y z ...`) or binary
/// (an 80-byte header, a count, 50 bytes a triangle).
pub fn read_stl(path: &Path) -> Result<Vec<[Vec3; 3]>> {
    let data = super::read_input(path).map_err(|e| GraniteError::Setup(format!("cannot read the STL file: {e}")))?;
    parse_stl(&data).map_err(|why| GraniteError::Setup(format!("STL file {}: {why}", path.display())))
}

/// The triangles of the bytes of an STL file.
pub fn parse_stl(data: &[u8]) -> std::result::Result<Vec<[Vec3; 3]>, String> {
    // A binary file may begin with "solid" too: its size tells it apart.
    if data.len() >= 84 {
        let count = u32::from_le_bytes([data[80], data[81], data[82], data[83]]) as usize;
        if count.checked_mul(50).and_then(|b| b.checked_add(84)) == Some(data.len()) {
            return Ok(binary(data, count));
        }
    }
    let text = std::str::from_utf8(data).map_err(|_| "neither ASCII STL nor binary STL of a consistent size")?;
    if !text.trim_start().starts_with("solid") {
        return Err("neither ASCII STL (it does not begin with `solid`) nor binary STL of a consistent size".into());
    }
    ascii(text)
}

fn binary(data: &[u8], count: usize) -> Vec<[Vec3; 3]> {
    let real = |at: usize| f32::from_le_bytes([data[at], data[at + 1], data[at + 2], data[at + 3]]) as f64;
    (0..count)
        .map(|t| {
            // Each record: normal (3 floats), three vertices (9 floats), a 2-byte attribute.
            let base = 84 + 50 * t + 12;
            [0, 1, 2].map(|v| [0, 1, 2].map(|c| real(base + 12 * v + 4 * c)))
        })
        .collect()
}

fn ascii(text: &str) -> std::result::Result<Vec<[Vec3; 3]>, String> {
    let mut triangles = Vec::new();
    let mut corners: Vec<Vec3> = Vec::with_capacity(3);
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("vertex") => {
                let v: Vec<f64> = words
                    .map(|w| w.parse::<f64>().map_err(|_| format!("line {}: `{w}` is not a number", n + 1)))
                    .collect::<std::result::Result<_, _>>()?;
                if v.len() != 3 {
                    return Err(format!("line {}: a vertex has three coordinates", n + 1));
                }
                corners.push([v[0], v[1], v[2]]);
            }
            Some("endloop") => {
                if corners.len() != 3 {
                    return Err(format!(
                        "line {}: a facet of {} vertices (STL facets are triangles)",
                        n + 1,
                        corners.len()
                    ));
                }
                triangles.push([corners[0], corners[1], corners[2]]);
                corners.clear();
            }
            _ => {}
        }
    }
    if triangles.is_empty() {
        return Err("no facet".into());
    }
    Ok(triangles)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TETRA: [[Vec3; 3]; 4] = [
        [[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]],
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    ];

    fn ascii_of(triangles: &[[Vec3; 3]]) -> String {
        let mut s = String::from("solid tetra\n");
        for t in triangles {
            s.push_str("  facet normal 0 0 0\n    outer loop\n");
            for v in t {
                s.push_str(&format!("      vertex {:e} {:e} {:e}\n", v[0], v[1], v[2]));
            }
            s.push_str("    endloop\n  endfacet\n");
        }
        s + "endsolid tetra\n"
    }

    fn binary_of(triangles: &[[Vec3; 3]]) -> Vec<u8> {
        // A header that begins with "solid", as some exporters write.
        let mut b = b"solid written as binary".to_vec();
        b.resize(80, b' ');
        b.extend((triangles.len() as u32).to_le_bytes());
        for t in triangles {
            b.extend([0u8; 12]);
            for v in t {
                for c in v {
                    b.extend((*c as f32).to_le_bytes());
                }
            }
            b.extend([0u8; 2]);
        }
        b
    }

    #[test]
    fn ascii_and_binary_give_the_same_triangles() {
        assert_eq!(parse_stl(ascii_of(&TETRA).as_bytes()).unwrap(), TETRA);
        assert_eq!(parse_stl(&binary_of(&TETRA)).unwrap(), TETRA);
    }

    #[test]
    fn broken_files_are_refused_with_a_reason() {
        let quad = ascii_of(&TETRA).replacen("    endloop", "      vertex 1 1 1\n    endloop", 1);
        assert!(parse_stl(quad.as_bytes()).unwrap_err().contains("4 vertices"));
        assert!(parse_stl(b"solid x\n vertex 1 2\n").unwrap_err().contains("three coordinates"));
        let mut cut = binary_of(&TETRA);
        cut.truncate(cut.len() - 10);
        assert!(parse_stl(&cut).unwrap_err().contains("neither"));
    }
}
