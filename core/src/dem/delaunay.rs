//! 3D Delaunay tetrahedralisation (Bowyer-Watson with exact orientation and in-sphere
//! predicates), used by the tetrahedron method of void ratio (thesis 2.12-2.16).
//!
//! Points are jittered by a tiny relative amount first, so that the co-spherical points of regular
//! packings do not create degenerate cavities; the method only needs tetrahedra that tile the
//! convex hull of the centres.

use crate::math::Vec3;
use robust::{insphere, orient3d, Coord3D};
use std::collections::HashMap;

const NONE: u32 = u32::MAX;

fn c(p: &Vec3) -> Coord3D<f64> {
    Coord3D { x: p[0], y: p[1], z: p[2] }
}

struct Mesh {
    pts: Vec<Vec3>,
    tets: Vec<[u32; 4]>,
    /// Neighbour across the face opposite each vertex.
    nbr: Vec<[u32; 4]>,
    alive: Vec<bool>,
}

impl Mesh {
    /// Positive when the tetrahedron `a b c d` is positively oriented (Shewchuk's convention:
    /// d below the plane of a, b, c seen counter-clockwise from above).
    fn orient(&self, t: [u32; 4]) -> f64 {
        orient3d(
            c(&self.pts[t[0] as usize]),
            c(&self.pts[t[1] as usize]),
            c(&self.pts[t[2] as usize]),
            c(&self.pts[t[3] as usize]),
        )
    }

    fn in_sphere(&self, t: usize, p: usize) -> bool {
        let v = self.tets[t];
        insphere(
            c(&self.pts[v[0] as usize]),
            c(&self.pts[v[1] as usize]),
            c(&self.pts[v[2] as usize]),
            c(&self.pts[v[3] as usize]),
            c(&self.pts[p]),
        ) > 0.0
    }

    /// Walks from `start` towards the tetrahedron containing point `p`.
    fn locate(&self, start: usize, p: usize) -> usize {
        let mut t = start;
        let mut guard = 0;
        'walk: loop {
            guard += 1;
            if guard > 10 * self.tets.len() + 100 {
                break;
            }
            let v = self.tets[t];
            for k in 0..4 {
                // Replace vertex k by p: a negative orientation means p is beyond face k.
                let mut w = v;
                w[k] = p as u32;
                if self.orient(w) < 0.0 {
                    let n = self.nbr[t][k];
                    if n != NONE {
                        t = n as usize;
                        continue 'walk;
                    }
                }
            }
            return t;
        }
        // Fallback (should not happen with exact predicates): any live tetrahedron whose
        // circumsphere contains p.
        (0..self.tets.len()).find(|&t| self.alive[t] && self.in_sphere(t, p)).unwrap_or(start)
    }

    fn insert(&mut self, p: usize, start: usize) -> usize {
        let t0 = self.locate(start, p);
        // Cavity: connected tetrahedra whose circumsphere contains p.
        let mut cavity = vec![t0];
        let mut in_cavity: HashMap<usize, ()> = HashMap::new();
        in_cavity.insert(t0, ());
        let mut k = 0;
        while k < cavity.len() {
            let t = cavity[k];
            k += 1;
            for f in 0..4 {
                let n = self.nbr[t][f];
                if n == NONE || in_cavity.contains_key(&(n as usize)) {
                    continue;
                }
                if self.in_sphere(n as usize, p) {
                    in_cavity.insert(n as usize, ());
                    cavity.push(n as usize);
                }
            }
        }
        // Boundary faces of the cavity become tetrahedra with p.
        let mut created = Vec::new();
        let mut edge_to_face: HashMap<(u32, u32), (usize, usize)> = HashMap::new();
        for &t in &cavity {
            for f in 0..4 {
                let n = self.nbr[t][f];
                if n != NONE && in_cavity.contains_key(&(n as usize)) {
                    continue;
                }
                let mut v = self.tets[t];
                v[f] = p as u32;
                let new = self.tets.len();
                self.tets.push(v);
                self.nbr.push([NONE; 4]);
                self.alive.push(true);
                // Across the old face (opposite p, index f): the outside neighbour.
                self.nbr[new][f] = n;
                if n != NONE {
                    let back = self.nbr[n as usize].iter().position(|&x| x as usize == t).unwrap_or(0);
                    self.nbr[n as usize][back] = new as u32;
                }
                // The three faces through p pair up by the edge they do not contain.
                for g in 0..4 {
                    if g == f {
                        continue;
                    }
                    let others: Vec<u32> = (0..4).filter(|&h| h != f && h != g).map(|h| v[h]).collect();
                    let key = (others[0].min(others[1]), others[0].max(others[1]));
                    if let Some((other, og)) = edge_to_face.remove(&key) {
                        self.nbr[new][g] = other as u32;
                        self.nbr[other][og] = new as u32;
                    } else {
                        edge_to_face.insert(key, (new, g));
                    }
                }
                created.push(new);
            }
        }
        for &t in &cavity {
            self.alive[t] = false;
        }
        *created.last().unwrap_or(&t0)
    }
}

/// Tetrahedra (indices into `points`) of a Delaunay tetrahedralisation of the points.
pub fn tetrahedralize(points: &[Vec3]) -> Vec<[usize; 4]> {
    let n = points.len();
    if n < 4 {
        return Vec::new();
    }
    let (lo, hi) = crate::math::point_bounds(points);
    let size = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    let centre = [0, 1, 2].map(|a| 0.5 * (lo[a] + hi[a]));
    // Deterministic tiny jitter against co-spherical degeneracies.
    let mut pts: Vec<Vec3> = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            [0, 1, 2].map(|a| p[a] + 1e-9 * size * (crate::ext::contact::uniform(0x5EED, (3 * i + a) as u64) - 0.5))
        })
        .collect();
    // A super-tetrahedron far around everything.
    let big = 1e3 * size;
    let s = [
        [centre[0] - big, centre[1] - big, centre[2] - big],
        [centre[0] + 3.0 * big, centre[1] - big, centre[2] - big],
        [centre[0] - big, centre[1] + 3.0 * big, centre[2] - big],
        [centre[0] - big, centre[1] - big, centre[2] + 3.0 * big],
    ];
    pts.extend_from_slice(&s);
    let sv = [n as u32, n as u32 + 1, n as u32 + 2, n as u32 + 3];
    let mut mesh = Mesh { pts, tets: vec![sv], nbr: vec![[NONE; 4]], alive: vec![true] };
    if mesh.orient(sv) < 0.0 {
        mesh.tets[0] = [sv[0], sv[2], sv[1], sv[3]];
    }
    // Insert in a spatially coherent order (cells of a coarse grid) so walks stay short.
    let cells = (n as f64).cbrt().ceil().max(1.0);
    let key = |p: &Vec3| -> (u64, u64, u64) {
        let f = |a: usize| (((p[a] - lo[a]) / size * cells).floor().max(0.0)) as u64;
        (f(2), f(1), f(0))
    };
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| key(&points[i]));
    let mut last = 0;
    for &i in &order {
        last = mesh.insert(i, last);
        if !mesh.alive[last] {
            last = mesh.alive.iter().rposition(|&a| a).unwrap_or(0);
        }
    }
    mesh.tets
        .iter()
        .zip(&mesh.alive)
        .filter(|(t, &a)| a && t.iter().all(|&v| (v as usize) < n))
        .map(|(t, _)| [t[0] as usize, t[1] as usize, t[2] as usize, t[3] as usize])
        .collect()
}

/// Volume of a tetrahedron.
pub fn tet_volume(a: Vec3, b: Vec3, c: Vec3, d: Vec3) -> f64 {
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let w = [d[0] - a[0], d[1] - a[1], d[2] - a[2]];
    (u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) + u[2] * (v[0] * w[1] - v[1] * w[0])).abs()
        / 6.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lattice_tets_tile_the_hull() {
        let mut pts = Vec::new();
        for i in 0..5 {
            for j in 0..4 {
                for k in 0..6 {
                    pts.push([i as f64, j as f64 * 0.5, k as f64 * 0.7]);
                }
            }
        }
        let tets = tetrahedralize(&pts);
        let vol: f64 = tets.iter().map(|t| tet_volume(pts[t[0]], pts[t[1]], pts[t[2]], pts[t[3]])).sum();
        let hull = 4.0 * 1.5 * 3.5;
        assert!((vol - hull).abs() < 1e-6 * hull, "tets cover {vol}, hull {hull}");
    }

    #[test]
    fn random_points_give_a_delaunay_tiling() {
        let pts: Vec<Vec3> = (0..300).map(|i| [0, 1, 2].map(|a| crate::ext::contact::uniform(9, 3 * i + a))).collect();
        let tets = tetrahedralize(&pts);
        // Empty circumspheres: no point strictly inside any tetrahedron's circumsphere.
        for t in tets.iter().take(200) {
            let (a, b, c2, d) = (pts[t[0]], pts[t[1]], pts[t[2]], pts[t[3]]);
            let o = orient3d(c(&a), c(&b), c(&c2), c(&d));
            for (i, p) in pts.iter().enumerate() {
                if t.contains(&i) {
                    continue;
                }
                let s = insphere(c(&a), c(&b), c(&c2), c(&d), c(p)) * o.signum();
                assert!(s <= 1e-9, "point {i} inside a circumsphere");
            }
        }
    }
}
