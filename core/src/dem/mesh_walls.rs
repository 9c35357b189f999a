//! Walls of triangles (an STL file, a gmsh surface group): each triangle a wall of its own
//! (`WallShape::Triangle`), touched from either side, with the same contact laws as the other
//! walls.
//!
//! A sphere meets a triangle at the triangle's point closest to its centre: inside the face, on
//! an edge or at a corner. Neighbouring triangles share edges and corners, and a sphere near one
//! of those would meet each triangle there: the shared feature is counted once, by the triangle
//! that owns it (the lowest-numbered of those sharing it), and only where it is the closest point
//! of every triangle sharing it. Where the surface folds towards the sphere (a valley, or a flat
//! seam) a neighbour's face is closer and makes the contact; where it folds away (a ridge, a
//! corner of a box seen from outside) the feature itself is the contact. So a sphere rolling over
//! a seam or a ridge feels one contact, and one pressed into a valley or the inside corner of a
//! box feels each face it touches.

use crate::dem::walls::{Wall, WallShape};
use crate::error::{GraniteError, Result};
use crate::math::{cross3 as cross, dot3 as dot, sub3 as sub, Vec3};
use std::collections::HashMap;

/// The features of a triangle `(a, b, c)`, as bits: edges `ab`, `bc`, `ca`, corners `a`, `b`, `c`.
pub mod feature {
    pub const EDGE_AB: u8 = 1;
    pub const EDGE_BC: u8 = 2;
    pub const EDGE_CA: u8 = 4;
    pub const CORNER_A: u8 = 8;
    pub const CORNER_B: u8 = 16;
    pub const CORNER_C: u8 = 32;
}

/// The triangles around one: those sharing one of its corners, with their corners relative to
/// its first corner and which of its features each shares; and the features it owns.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, Default)]
pub struct FacetRing {
    pub others: Vec<([Vec3; 3], u8)>,
    pub owns: u8,
}

fn along(a: Vec3, d: Vec3, t: f64) -> Vec3 {
    [a[0] + t * d[0], a[1] + t * d[1], a[2] + t * d[2]]
}

/// The point of triangle `(a, b, c)` closest to `p`, and the feature it lies on (0: inside the
/// face). Found by which region of the triangle's plane `p` projects into: a corner's, an edge's
/// or the face's (strictly inside); a point on an edge's line or a corner's boundary belongs to
/// the edge or the corner.
pub fn closest_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> (Vec3, u8) {
    use feature::*;
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, CORNER_A);
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (b, CORNER_B);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return (along(a, ab, d1 / (d1 - d3)), EDGE_AB);
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (c, CORNER_C);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return (along(a, ac, d2 / (d2 - d6)), EDGE_CA);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return (along(b, sub(c, b), (d4 - d3) / ((d4 - d3) + (d5 - d6))), EDGE_BC);
    }
    let inv = 1.0 / (va + vb + vc);
    let (v, w) = (vb * inv, vc * inv);
    ([0, 1, 2].map(|k| a[k] + v * ab[k] + w * ac[k]), 0)
}

/// The contact point of a triangle (corners `0`, `b`, `c` about its first corner) with a sphere
/// centred at `p` (same frame): its closest point, unless that is a shared edge or corner another
/// triangle counts, or at which a neighbour sharing it is closer.
pub fn facet_contact_point(p: Vec3, b: Vec3, c: Vec3, ring: &FacetRing) -> Option<Vec3> {
    let (q, on) = closest_on_triangle(p, [0.0; 3], b, c);
    if on == 0 {
        return Some(q);
    }
    let shared = ring.others.iter().any(|(_, mask)| mask & on != 0);
    if !shared {
        return Some(q);
    }
    if ring.owns & on == 0 {
        return None;
    }
    let d = sub(p, q);
    let dist2 = dot(d, d);
    // Rounding: a neighbour's closest point on the very feature may come out nearer by a few
    // ulps of the triangles' size.
    let size2 = dot(b, b).max(dot(c, c));
    let slack = 1e-12 * size2;
    for (corners, mask) in &ring.others {
        if mask & on == 0 {
            continue;
        }
        let (r, _) = closest_on_triangle(p, corners[0], corners[1], corners[2]);
        let e = sub(p, r);
        if dot(e, e) < dist2 - slack {
            return None;
        }
    }
    Some(q)
}

/// The walls of a surface of triangles (world coordinates), named `name#k`, of `material`.
/// Corners closer than `1e-9` of the surface's size are one corner; triangles of no area are left
/// out. Fails when none is left.
pub fn mesh_walls(triangles: &[[Vec3; 3]], name: &str, material: u16) -> Result<Vec<Wall>> {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for t in triangles {
        for v in t {
            if v.iter().any(|c| !c.is_finite()) {
                return Err(GraniteError::Setup(format!("wall mesh \"{name}\": a corner at {v:?}")));
            }
            for k in 0..3 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
    }
    let size = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
    let tolerance = 1e-9 * size.max(f64::MIN_POSITIVE);
    // Corners welded on a lattice of the tolerance.
    let mut corner_of: HashMap<[i64; 3], u32> = HashMap::new();
    let mut corners: Vec<Vec3> = Vec::new();
    let mut faces: Vec<[u32; 3]> = Vec::new();
    for t in triangles {
        let ids = t.map(|v| {
            let key = [0, 1, 2].map(|k| ((v[k] - lo[k]) / tolerance).round() as i64);
            *corner_of.entry(key).or_insert_with(|| {
                corners.push(v);
                (corners.len() - 1) as u32
            })
        });
        let [a, b, c] = ids.map(|i| corners[i as usize]);
        let area2 = cross(sub(b, a), sub(c, a));
        if ids[0] == ids[1] || ids[1] == ids[2] || ids[0] == ids[2] || dot(area2, area2) == 0.0 {
            continue;
        }
        faces.push(ids);
    }
    if faces.is_empty() {
        return Err(GraniteError::Setup(format!("wall mesh \"{name}\": no triangle of non-zero area")));
    }
    let mut around: HashMap<u32, Vec<u32>> = HashMap::new();
    for (f, ids) in faces.iter().enumerate() {
        for &v in ids {
            around.entry(v).or_default().push(f as u32);
        }
    }
    let mut walls = Vec::with_capacity(faces.len());
    for (f, ids) in faces.iter().enumerate() {
        let mut neighbours: Vec<u32> =
            ids.iter().flat_map(|v| around[v].iter().copied()).filter(|&g| g != f as u32).collect();
        neighbours.sort_unstable();
        neighbours.dedup();
        let a = corners[ids[0] as usize];
        let rel = |v: u32| sub(corners[v as usize], a);
        let mut ring = FacetRing::default();
        let mut owner = [f as u32; 6];
        for &g in &neighbours {
            let other = faces[g as usize];
            let has = |v: u32| other.contains(&v);
            let [pa, pb, pc] = [has(ids[0]), has(ids[1]), has(ids[2])];
            let bit = |on: bool, feature: u8| if on { feature } else { 0 };
            let mask = bit(pa && pb, feature::EDGE_AB)
                | bit(pb && pc, feature::EDGE_BC)
                | bit(pc && pa, feature::EDGE_CA)
                | bit(pa, feature::CORNER_A)
                | bit(pb, feature::CORNER_B)
                | bit(pc, feature::CORNER_C);
            for (bit, o) in owner.iter_mut().enumerate() {
                if mask & (1 << bit) != 0 {
                    *o = (*o).min(g);
                }
            }
            ring.others.push((other.map(rel), mask));
        }
        ring.owns = (0..6).filter(|&bit| owner[bit] == f as u32).fold(0, |m, bit| m | (1 << bit));
        let shape = WallShape::Triangle { b: rel(ids[1]), c: rel(ids[2]), ring };
        walls.push(Wall::new(&format!("{name}#{f}"), shape, a, material));
    }
    Ok(walls)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn contacts(walls: &[Wall], x: Vec3, r: f64) -> Vec<(usize, Vec3)> {
        walls
            .iter()
            .enumerate()
            .filter_map(|(k, w)| w.contact(x, r, 0.0).filter(|c| c.gap < 0.0).map(|c| (k, c.point)))
            .collect()
    }

    /// A unit square in z = 0 as two triangles sharing the diagonal (0,0)-(1,1).
    fn square() -> Vec<[Vec3; 3]> {
        vec![[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]], [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]]]
    }

    #[test]
    fn the_closest_point_lies_in_the_region_the_centre_projects_into() {
        let (a, b, c) = ([0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]);
        assert_eq!(closest_on_triangle([0.5, 0.5, 1.0], a, b, c), ([0.5, 0.5, 0.0], 0));
        assert_eq!(closest_on_triangle([-1.0, -1.0, 0.3], a, b, c), (a, feature::CORNER_A));
        assert_eq!(closest_on_triangle([1.0, -1.0, 0.0], a, b, c), ([1.0, 0.0, 0.0], feature::EDGE_AB));
        assert_eq!(closest_on_triangle([2.0, 2.0, 0.0], a, b, c), ([1.0, 1.0, 0.0], feature::EDGE_BC));
        assert_eq!(closest_on_triangle([3.0, -0.5, 0.0], a, b, c), (b, feature::CORNER_B));
    }

    #[test]
    fn a_sphere_over_a_seam_or_a_shared_corner_meets_the_surface_once() {
        let walls = mesh_walls(&square(), "square", 0).unwrap();
        // Over the diagonal seam, and over the shared corners (0, 0) and (1, 1) from outside.
        for x in [[0.5, 0.5, 0.09], [0.3, 0.3, 0.05], [-0.05, -0.05, 0.05], [1.05, 1.05, 0.0]] {
            let found = contacts(&walls, x, 0.1);
            assert_eq!(found.len(), 1, "at {x:?}: {found:?}");
        }
        // Over one face only.
        assert_eq!(contacts(&walls, [0.8, 0.2, 0.05], 0.1).len(), 1);
        // Off the square's unshared corner (1, 0): that corner, once.
        let found = contacts(&walls, [1.05, -0.05, 0.0], 0.1);
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].1, [1.0, 0.0, 0.0]);
    }

    #[test]
    fn a_sphere_in_a_valley_meets_both_faces_and_one_on_a_ridge_meets_the_ridge() {
        // Two faces folded along the y axis at 90 degrees: z = -x for x < 0, z = x for x > 0 (a
        // valley seen from above, a ridge from below).
        let fold = vec![
            [[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 1.0]],
            [[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 0.0]],
        ];
        let walls = mesh_walls(&fold, "fold", 0).unwrap();
        // From above, in the valley: both faces, at their feet.
        let r = 0.1;
        let found = contacts(&walls, [0.0, 0.5, 0.12], r);
        assert_eq!(found.len(), 2, "{found:?}");
        // From below, under the ridge: the ridge itself, once.
        let found = contacts(&walls, [0.0, 0.5, -0.05], r);
        assert_eq!(found.len(), 1, "{found:?}");
        assert!((found[0].1[0]).abs() < 1e-15 && found[0].1[2].abs() < 1e-15);
    }
}
