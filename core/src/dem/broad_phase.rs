//! Broad phase: candidate sphere pairs from a cell list, with a Verlet skin so the list stays
//! valid until some sphere has moved more than half the skin.

use crate::dem::cell::PeriodicCell;
use crate::dem::walls::{Wall, WallShape};
use crate::math::dot3;
use crate::math::Vec3;
use rayon::prelude::*;

/// Particles per parallel block of the search.
const BLOCK: usize = 256;

/// Counting sort of items by cell: `items[start[c]..start[c + 1]]` are the items of cell `c`,
/// in increasing index.
fn bucket(cells: &[usize], ncells: usize) -> (Vec<u32>, Vec<u32>) {
    let mut start = vec![0u32; ncells + 1];
    for &c in cells {
        start[c + 1] += 1;
    }
    for c in 0..ncells {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut items = vec![0u32; cells.len()];
    for (i, &c) in cells.iter().enumerate() {
        items[fill[c] as usize] = i as u32;
        fill[c] += 1;
    }
    (start, items)
}

/// The 13 neighbour-cell offsets `[dx, dy, dz]` that come after `[0, 0, 0]` in `(dz, dy, dx)`
/// order: with the cell itself, they meet every pair of neighbouring cells once.
const FORWARD: [[i64; 3]; 13] = [
    [1, 0, 0],
    [-1, 1, 0],
    [0, 1, 0],
    [1, 1, 0],
    [-1, -1, 1],
    [0, -1, 1],
    [1, -1, 1],
    [-1, 0, 1],
    [0, 0, 1],
    [1, 0, 1],
    [-1, 1, 1],
    [0, 1, 1],
    [1, 1, 1],
];

/// Candidates found in any order (each once, `a > b`), sorted by `(a, b, shift)` as
/// [`candidates_by_particle`] returns them: counted out by first particle, then each particle's
/// few sorted.
fn sorted_by_first(n: usize, blocks: Vec<Vec<Candidate>>) -> Vec<Candidate> {
    let mut start = vec![0usize; n + 1];
    for &(a, _, _) in blocks.iter().flatten() {
        start[a as usize + 1] += 1;
    }
    for a in 0..n {
        start[a + 1] += start[a];
    }
    let mut fill = start.clone();
    let mut out = vec![(0, 0, [0; 3]); start[n]];
    for &c in blocks.iter().flatten() {
        out[fill[c.0 as usize]] = c;
        fill[c.0 as usize] += 1;
    }
    for a in 0..n {
        out[start[a]..start[a + 1]].sort_unstable();
    }
    out
}

/// A candidate pair: `(a, b, shift of b's image)`.
pub type Candidate = (u32, u32, [i32; 3]);

/// Candidates in consecutive blocks: one after the other, they are the sorted list. A search
/// hands over the lists its parallel blocks filled (joined on one thread, they took 0.1-0.2 ms of
/// a 10k-sphere rebuild), and the merge into the pair list takes them block by block.
pub type Blocks = Vec<Vec<Candidate>>;

/// The candidates of every particle, particle by particle: `search(i, out)` appends those of
/// particle `i` (in any order; each particle's are then sorted and deduplicated). Blocks of
/// particles run in parallel, each filling one list; the lists, in order, are the candidates.
fn candidates_by_particle(n: usize, search: impl Fn(usize, &mut Vec<Candidate>) + Sync) -> Blocks {
    by_blocks(n, |i, found| {
        let first = found.len();
        search(i, found);
        found[first..].sort_unstable();
        let mut kept = first;
        for k in first..found.len() {
            if k == first || found[k] != found[kept - 1] {
                found[kept] = found[k];
                kept += 1;
            }
        }
        found.truncate(kept);
    })
}

/// `search(i, out)` for every particle, blocks of particles in parallel, one list per block (in
/// block order).
fn by_blocks(n: usize, search: impl Fn(usize, &mut Vec<Candidate>) + Sync) -> Vec<Vec<Candidate>> {
    (0..n.div_ceil(BLOCK))
        .into_par_iter()
        .map(|b| {
            let mut found = Vec::new();
            for i in b * BLOCK..((b + 1) * BLOCK).min(n) {
                search(i, &mut found);
            }
            found
        })
        .collect()
}

/// Candidate pairs `(a, b)`, `a > b`, whose gap is below `skin`; sorted by `(a, b)`. The first
/// sphere is the larger index: the step's force sums rely on it (see `step::write_back`).
pub fn sphere_pairs(x: &[Vec3], radius: &[f64], skin: f64) -> Blocks {
    let n = x.len();
    if n < 2 {
        return Vec::new();
    }
    let r_max = radius.iter().cloned().fold(0.0, f64::max);
    let (lo, hi) = crate::math::point_bounds(x);
    // Cells at least as large as the longest possible interaction, and not more than ~2 per sphere.
    let mut size = (2.0 * r_max + skin).max(f64::MIN_POSITIVE);
    let cells_for = |size: f64| -> [usize; 3] {
        let mut d = [1usize; 3];
        for a in 0..3 {
            d[a] = (((hi[a] - lo[a]) / size).floor() as usize + 1).max(1);
        }
        d
    };
    let mut dims = cells_for(size);
    while (dims[0] as u128 * dims[1] as u128 * dims[2] as u128) > (2 * n as u128).max(64) {
        size *= 1.26;
        dims = cells_for(size);
    }
    let cell_of = |p: &Vec3| -> [usize; 3] {
        let mut c = [0usize; 3];
        for a in 0..3 {
            c[a] = (((p[a] - lo[a]) / size) as usize).min(dims[a] - 1);
        }
        c
    };
    let index = |c: [usize; 3]| c[0] + dims[0] * (c[1] + dims[1] * c[2]);
    // In parallel where the pool has workers: serial, these passes were a tenth of a rebuild.
    let coords: Vec<[usize; 3]> = x.par_iter().with_min_len(BLOCK).map(cell_of).collect();
    let cells: Vec<usize> = coords.par_iter().with_min_len(BLOCK).map(|&c| index(c)).collect();
    let (start, items) = bucket(&cells, dims[0] * dims[1] * dims[2]);
    // Positions and radii in bucket order, so that a run of cells is read in one sweep.
    let by_cell: Vec<(Vec3, f64)> =
        items.par_iter().with_min_len(BLOCK).map(|&j| (x[j as usize], radius[j as usize])).collect();
    candidates_by_particle(n, |i, found| {
        let c = coords[i];
        let (xi, ri) = (x[i], radius[i]);
        // The up to three neighbour cells along x of one (y, z) row are consecutive cells, so
        // their particles are one run of `items`: nine runs instead of 27 cells.
        let (x_lo, x_hi) = (c[0].saturating_sub(1), (c[0] + 1).min(dims[0] - 1));
        for qz in c[2].saturating_sub(1)..=(c[2] + 1).min(dims[2] - 1) {
            for qy in c[1].saturating_sub(1)..=(c[1] + 1).min(dims[1] - 1) {
                let (first, last) = (index([x_lo, qy, qz]), index([x_hi, qy, qz]));
                let run = start[first] as usize..start[last + 1] as usize;
                for (&j, &(xj, rj)) in items[run.clone()].iter().zip(&by_cell[run]) {
                    let d = [xj[0] - xi[0], xj[1] - xi[1], xj[2] - xi[2]];
                    let reach = ri + rj + skin;
                    // One branch, rarely taken (`&`, not `&&`): a test of `j < i` first would
                    // be mispredicted about every other particle.
                    if (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] < reach * reach) & ((j as usize) < i) {
                        found.push((i as u32, j, [0; 3]));
                    }
                }
            }
        }
    })
}

/// Candidate pairs in a periodic cell. Positions must lie in the cell (reduced coordinates in
/// [0, 1)). Each image is found through the neighbour cell it lies in, which gives its shift
/// directly. A cell thinner than twice the interaction reach (an RVE flattened by a large
/// stretch) holds several images of a particle near another, and images of a particle near
/// itself: the search then reaches over as many cells as the reach spans, and a pair of one
/// particle with its own image is kept once, under the shift whose first non-zero component is
/// positive (the opposite shift is the same contact seen from the image).
pub fn periodic_sphere_pairs(x: &[Vec3], radius: &[f64], skin: f64, cell: &PeriodicCell) -> Blocks {
    periodic_pairs(x, radius, (skin, cell), true)
}

/// [`periodic_sphere_pairs`], through half of the neighbour cells when there are three cells or
/// more on every axis and `half` allows it (the whole stencil otherwise: the two agree).
fn periodic_pairs(x: &[Vec3], radius: &[f64], (skin, cell): (f64, &PeriodicCell), half: bool) -> Blocks {
    let n = x.len();
    if n == 0 {
        return Vec::new();
    }
    let r_max = radius.iter().cloned().fold(0.0, f64::max);
    let reach = (2.0 * r_max + skin).max(f64::MIN_POSITIVE);
    let widths = cell.widths();
    let mut dims = [1usize; 3];
    for a in 0..3 {
        dims[a] = ((widths[a] / reach).floor() as usize).clamp(1, 1 << 10);
    }
    while dims[0] * dims[1] * dims[2] > (2 * n).max(27) {
        let a = (0..3).max_by_key(|&a| dims[a]).unwrap_or(0);
        dims[a] = (dims[a] / 2).max(1);
    }
    let inv = cell.inverse();
    // Cell coordinates of every particle, once (`rem_euclid` is a library call).
    let coords: Vec<[usize; 3]> = x
        .iter()
        .map(|p| {
            let s = cell.reduced(&inv, *p);
            [0, 1, 2].map(|a| ((s[a].rem_euclid(1.0) * dims[a] as f64) as usize).min(dims[a] - 1))
        })
        .collect();
    let index = |c: [usize; 3]| c[0] + dims[0] * (c[1] + dims[1] * c[2]);
    let cells: Vec<usize> = coords.iter().map(|&c| index(c)).collect();
    let (start, items) = bucket(&cells, dims[0] * dims[1] * dims[2]);
    // Positions and radii in bucket order: a cell's particles are then read one after another,
    // not each from wherever its index points.
    let by_cell: Vec<(Vec3, f64)> = items.iter().map(|&j| (x[j as usize], radius[j as usize])).collect();
    // A neighbour coordinate `c + d` (d in -1..=1) lies in -1..=dims: wrapped by a comparison,
    // not by a division (27 neighbour cells of 3 axes per particle).
    let wrap = |raw: i64, dim: usize| -> (usize, i32) {
        if raw < 0 {
            (dim - 1, -1)
        } else if raw as usize >= dim {
            (raw as usize - dim, 1)
        } else {
            (raw as usize, 0)
        }
    };
    // The 27 images a neighbour cell can hold (shifts of -1, 0 or 1 cell on each axis).
    let images: [Vec3; 27] =
        std::array::from_fn(|k| cell.shift_vector([k % 3, k / 3 % 3, k / 9].map(|s| s as i32 - 1)));
    let image_of = |w: [i32; 3]| images[(w[0] + 1 + 3 * (w[1] + 1) + 9 * (w[2] + 1)) as usize];
    if half && dims.iter().all(|&d| d >= 3) {
        // Three cells or more on every axis: neighbour cells are distinct, so each pair is met
        // once from the cell that comes first in the stencil order (half of the 26 neighbours),
        // and checked as the whole-stencil search checks it, from its first particle.
        let blocks = by_blocks(n, |i, found| {
            let c = coords[i];
            let own = start[index(c)] as usize..start[index(c) + 1] as usize;
            for (&j, &(xj, rj)) in items[own.clone()].iter().zip(&by_cell[own]) {
                let j = j as usize;
                let dv = [xj[0] - x[i][0], xj[1] - x[i][1], xj[2] - x[i][2]];
                let r = radius[i] + rj + skin;
                if (dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2] < r * r) & (j < i) {
                    found.push((i as u32, j as u32, [0; 3]));
                }
            }
            for d in FORWARD {
                let mut q = [0usize; 3];
                let mut w = [0i32; 3];
                for a in 0..3 {
                    (q[a], w[a]) = wrap(c[a] as i64 + d[a], dims[a]);
                }
                let back = [-w[0], -w[1], -w[2]];
                let (ahead, behind) = (image_of(w), image_of(back));
                let run = start[index(q)] as usize..start[index(q) + 1] as usize;
                for (&j, &(xj, rj)) in items[run.clone()].iter().zip(&by_cell[run]) {
                    let j = j as usize;
                    // From the first particle: j's image w seen from i, or i's image -w
                    // seen from j.
                    let (from, to, image) = if j < i { (x[i], xj, ahead) } else { (xj, x[i], behind) };
                    let dv = [to[0] + image[0] - from[0], to[1] + image[1] - from[1], to[2] + image[2] - from[2]];
                    let r = radius[i] + rj + skin;
                    if dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2] < r * r {
                        found.push(if j < i { (i as u32, j as u32, w) } else { (j as u32, i as u32, back) });
                    }
                }
            }
        });
        return vec![sorted_by_first(n, blocks)];
    }
    // Cells to reach on each side along each axis: one when a cell is at least the reach thick,
    // more in a cell thinner than the reach.
    let reach_cells: [i64; 3] = [0, 1, 2].map(|a| (reach * dims[a] as f64 / widths[a]).ceil().max(1.0) as i64);
    candidates_by_particle(n, |i, found| {
        let c = coords[i];
        let [mx, my, mz] = reach_cells;
        for dz in -mz..=mz {
            for dy in -my..=my {
                for dx in -mx..=mx {
                    let d = [dx, dy, dz];
                    let mut q = [0usize; 3];
                    let mut w = [0i32; 3];
                    for a in 0..3 {
                        let raw = c[a] as i64 + d[a];
                        (q[a], w[a]) = (raw.rem_euclid(dims[a] as i64) as usize, raw.div_euclid(dims[a] as i64) as i32);
                    }
                    // Each offset is a different (cell, image): dims of 1 or 2, or a reach over
                    // several cells, meet one cell through several offsets, each its own image.
                    let k = index(q);
                    let image = if w == [0; 3] { [0.0; 3] } else { cell.shift_vector(w) };
                    // One particle and its own image: once, under the positive shift.
                    let own_image = w.iter().find(|&&s| s != 0).is_some_and(|&s| s > 0);
                    let run = start[k] as usize..start[k + 1] as usize;
                    for (&j, &(xj, rj)) in items[run.clone()].iter().zip(&by_cell[run]) {
                        let j = j as usize;
                        let dv = [xj[0] + image[0] - x[i][0], xj[1] + image[1] - x[i][1], xj[2] + image[2] - x[i][2]];
                        let r = radius[i] + rj + skin;
                        // One branch, rarely taken (`&`, not `&&`; see `sphere_pairs`).
                        let first_above = (j < i) | ((j == i) & own_image);
                        if (dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2] < r * r) & first_above {
                            found.push((i as u32, j as u32, w));
                        }
                    }
                }
            }
        }
    })
}

/// Fewest triangles of wall meshes found through a grid rather than one by one.
const TRIANGLES_IN_A_GRID: usize = 16;

/// The triangles of wall meshes binned by their bounds grown by `reach`: a sphere's candidates
/// are those of the cube its centre lies in.
fn triangle_bins(walls: &[Wall], triangles: &[usize], reach: f64) -> crate::box_bins::BoxBins {
    let boxes: Vec<(Vec3, Vec3)> = triangles
        .iter()
        .map(|&w| {
            let wall = &walls[w];
            let WallShape::Triangle { b, c, .. } = &wall.shape else { unreachable!("triangles only") };
            let p = wall.position;
            let corners = [p, [0, 1, 2].map(|k| p[k] + b[k]), [0, 1, 2].map(|k| p[k] + c[k])];
            let lo = [0, 1, 2].map(|k| corners.iter().map(|v| v[k]).fold(f64::INFINITY, f64::min) - reach);
            let hi = [0, 1, 2].map(|k| corners.iter().map(|v| v[k]).fold(f64::NEG_INFINITY, f64::max) + reach);
            (lo, hi)
        })
        .collect();
    crate::box_bins::BoxBins::new(&boxes)
}

/// Whether a sphere centred at `p` comes within `reach` of a triangle wall: by distance alone. A
/// triangle that leaves a shared edge or corner to a neighbour is still a candidate near it: the
/// sphere may move onto its face before the next rebuild.
fn triangle_near(w: &Wall, p: Vec3, reach: f64) -> bool {
    let WallShape::Triangle { b, c, .. } = &w.shape else { return false };
    let x = w.position;
    let d = [p[0] - x[0], p[1] - x[1], p[2] - x[2]];
    let (q, _) = crate::dem::mesh_walls::closest_on_triangle(d, [0.0; 3], *b, *c);
    let e = [d[0] - q[0], d[1] - q[1], d[2] - q[2]];
    dot3(e, e) <= reach * reach
}

/// Candidate sphere-wall pairs `(sphere, wall)` within `skin`, sorted by sphere then wall. The
/// triangles of wall meshes are looked up on a grid when there are many.
pub fn wall_pairs(x: &[Vec3], radius: &[f64], walls: &[Wall], skin: f64) -> Blocks {
    if walls.is_empty() {
        return Vec::new();
    }
    // A plane's normal and position side by side, tested in line with the sphere's centre kept in
    // registers, by the same arithmetic as `Wall::contact`. (Through `Wall::contact`, whose other
    // shapes take a call, the centre went to the stack and back for every wall, and each test
    // waited on that store: a third of a rebuild of a 10k-sphere deposition in a box.)
    let planes: Vec<Option<(Vec3, Vec3)>> = walls
        .iter()
        .map(|w| match w.shape {
            WallShape::Plane { normal } => Some((normal, w.position)),
            _ => None,
        })
        .collect();
    let triangles: Vec<usize> =
        (0..walls.len()).filter(|&w| matches!(walls[w].shape, WallShape::Triangle { .. })).collect();
    let reach = radius.iter().copied().fold(0.0, f64::max) + skin;
    let grid = (triangles.len() >= TRIANGLES_IN_A_GRID).then(|| triangle_bins(walls, &triangles, reach));
    candidates_by_particle(x.len(), |i, found| {
        let (p, r) = (x[i], radius[i]);
        for (k, (w, plane)) in walls.iter().zip(&planes).enumerate() {
            let near = match plane {
                Some((normal, at)) => !(dot3([p[0] - at[0], p[1] - at[1], p[2] - at[2]], *normal) - r > skin),
                None if matches!(w.shape, WallShape::Triangle { .. }) => {
                    grid.is_none() && triangle_near(w, p, r + skin)
                }
                None => w.contact(p, r, skin).is_some(),
            };
            if near {
                found.push((i as u32, k as u32, [0; 3]));
            }
        }
        if let Some(grid) = &grid {
            for &t in grid.at(p) {
                let k = triangles[t as usize];
                if triangle_near(&walls[k], p, r + skin) {
                    found.push((i as u32, k as u32, [0; 3]));
                }
            }
        }
    })
}

/// Reproducible uniform numbers in [0, 1) for the tests (a 64-bit linear congruential generator).
#[cfg(test)]
fn uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed;
    move || {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cell_list_finds_the_same_pairs_as_brute_force() {
        let mut x = Vec::new();
        let mut r = Vec::new();
        let mut next = uniform(12345);
        for _ in 0..600 {
            x.push([next(), next() * 0.5, next() * 2.0]);
            r.push(0.02 + 0.02 * next());
        }
        let skin = 0.01;
        let fast = sphere_pairs(&x, &r, skin).concat();
        let mut brute = Vec::new();
        for i in 0..x.len() {
            for j in 0..i {
                let d: f64 = (0..3).map(|a| (x[j][a] - x[i][a]).powi(2)).sum::<f64>().sqrt();
                if d < r[i] + r[j] + skin {
                    brute.push((i as u32, j as u32, [0; 3]));
                }
            }
        }
        assert!(!brute.is_empty());
        assert_eq!(fast, brute);
    }

    #[test]
    fn triangles_found_on_the_grid_are_those_within_reach() {
        // A wavy surface of 2 x 20 x 20 triangles over [0, 1]^2, spheres scattered about it.
        let n = 20;
        let height = |i: usize, j: usize| 0.05 * ((i as f64 * 0.7).sin() + (j as f64 * 0.4).cos());
        let at = |i: usize, j: usize| [i as f64 / n as f64, j as f64 / n as f64, height(i, j)];
        let mut triangles = Vec::new();
        for i in 0..n {
            for j in 0..n {
                triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        let walls = crate::dem::mesh_walls::mesh_walls(&triangles, "wavy", 0).unwrap();
        let mut u = uniform(7);
        let x: Vec<Vec3> = (0..2000).map(|_| [1.2 * u() - 0.1, 1.2 * u() - 0.1, 0.3 * u() - 0.15]).collect();
        let r: Vec<f64> = (0..x.len()).map(|_| 0.01 + 0.02 * u()).collect();
        let skin = 0.005;
        let found = wall_pairs(&x, &r, &walls, skin).concat();
        let mut expected = Vec::new();
        for i in 0..x.len() {
            for (k, w) in walls.iter().enumerate() {
                if triangle_near(w, x[i], r[i] + skin) {
                    expected.push((i as u32, k as u32, [0; 3]));
                }
            }
        }
        assert!(expected.len() > 500, "{} pairs", expected.len());
        assert_eq!(found, expected);
    }

    #[test]
    fn wall_candidates_are_the_spheres_within_the_skin_of_each_wall() {
        let mut next = uniform(777);
        let x: Vec<Vec3> = (0..2000).map(|_| [2.4 * next() - 1.2, 2.4 * next() - 1.2, 2.4 * next() - 0.2]).collect();
        let r: Vec<f64> = (0..x.len()).map(|_| 0.02 + 0.03 * next()).collect();
        let plane = |normal: Vec3, at: Vec3| Wall::new("", WallShape::Plane { normal }, at, 0);
        let s3 = 0.5f64.sqrt();
        let walls = [
            plane([0.0, 0.0, 1.0], [0.0; 3]),
            plane([s3, 0.0, -s3], [0.3, 0.0, 1.0]),
            Wall::new("", WallShape::Cylinder { axis: [0.0, 0.0, 1.0], radius: 1.0, length: 2.0 }, [0.0, 0.0, 1.0], 0),
            Wall::new(
                "",
                WallShape::Rect { u: [1.0, 0.0, 0.0], v: [0.0, 0.0, 1.0], half: [0.5, 0.5] },
                [0.0, 0.4, 0.5],
                0,
            ),
        ];
        let skin = 0.01;
        let found = wall_pairs(&x, &r, &walls, skin).concat();
        let mut expected = Vec::new();
        for i in 0..x.len() {
            for (k, w) in walls.iter().enumerate() {
                // The definition: the wall's own contact geometry, with the skin as its reach.
                if w.contact(x[i], r[i], skin).is_some() {
                    expected.push((i as u32, k as u32, [0; 3]));
                }
            }
        }
        for k in 0..walls.len() as u32 {
            assert!(expected.iter().any(|c| c.1 == k), "no sphere near wall {k}: the test checks nothing there");
        }
        assert_eq!(found, expected);
    }
}
#[cfg(test)]
mod periodic_tests {
    use super::*;

    #[test]
    fn half_stencil_finds_exactly_the_whole_stencils_pairs() {
        // A dense random packing in a sheared, compressed cell, with cells enough for the half
        // stencil on every axis.
        let mut next = uniform(12345);
        let mut cell = PeriodicCell::new_box([0.2, 0.25, 0.3]);
        cell.h[(0, 1)] = 0.07;
        cell.h[(2, 0)] = -0.04;
        let (mut x, mut r) = (Vec::new(), Vec::new());
        for _ in 0..1500 {
            let s = nalgebra::Vector3::new(next(), next(), next());
            let p = cell.h * s;
            x.push([p[0], p[1], p[2]]);
            r.push(0.006 + 0.006 * next());
        }
        let skin = 0.002;
        let whole = periodic_pairs(&x, &r, (skin, &cell), false).concat();
        let half = periodic_pairs(&x, &r, (skin, &cell), true).concat();
        assert!(whole.len() > 2000, "{} pairs", whole.len());
        assert_eq!(half, whole);
    }

    #[test]
    fn sheared_cubic_lattice_has_all_its_neighbours() {
        let (n, d, r) = (4usize, 0.0199, 0.01);
        let l = n as f64 * d;
        for shear in [0.0, 0.3, -0.5, 0.5] {
            let mut cell = PeriodicCell::new_box([l; 3]);
            cell.h[(0, 2)] = shear * l;
            let mut x = Vec::new();
            for i in 0..n {
                for j in 0..n {
                    for k in 0..n {
                        // Lattice sites sheared with the cell, wrapped into it.
                        let s = [(i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64, (k as f64 + 0.5) / n as f64];
                        let p = cell.h * nalgebra::Vector3::new(s[0], s[1], s[2]);
                        x.push([p[0], p[1], p[2]]);
                    }
                }
            }
            // Sheared lattice: neighbours along z are d apart only through the sheared base vector,
            // so count pairs closer than 2r + skin for the sheared geometry by brute force.
            let radius = vec![r; x.len()];
            let skin = 0.001;
            let found = periodic_sphere_pairs(&x, &radius, skin, &cell).concat();
            let mut brute = 0;
            for a in 0..x.len() {
                for b in a + 1..x.len() {
                    for sx in -2..=2 {
                        for sy in -2..=2 {
                            for sz in -2..=2 {
                                let im = cell.shift_vector([sx, sy, sz]);
                                let dv: f64 = (0..3).map(|q| (x[b][q] + im[q] - x[a][q]).powi(2)).sum::<f64>().sqrt();
                                if dv < 2.0 * r + skin {
                                    brute += 1;
                                }
                            }
                        }
                    }
                }
            }
            assert_eq!(found.len(), brute, "shear {shear}");
        }
    }

    /// Every pair within reach over every image, by brute force: `(a, b, n)` with `a > b`, or
    /// `a == b` under the shift whose first non-zero component is positive.
    fn brute_force_over_images(x: &[Vec3], r: &[f64], skin: f64, cell: &PeriodicCell, span: i32) -> Vec<Candidate> {
        let mut found = Vec::new();
        for a in 0..x.len() {
            for b in 0..=a {
                for sz in -span..=span {
                    for sy in -span..=span {
                        for sx in -span..=span {
                            let n = [sx, sy, sz];
                            let positive = n.iter().find(|&&s| s != 0).is_some_and(|&s| s > 0);
                            if b == a && !positive {
                                continue;
                            }
                            let im = cell.shift_vector(n);
                            let d2: f64 = (0..3).map(|q| (x[b][q] + im[q] - x[a][q]).powi(2)).sum();
                            if d2 < (r[a] + r[b] + skin).powi(2) {
                                found.push((a as u32, b as u32, n));
                            }
                        }
                    }
                }
            }
        }
        found.sort_unstable();
        found
    }

    #[test]
    fn a_cell_thinner_than_the_reach_has_every_image_within_it() {
        // A flattened, sheared cell: 0.3 of the reach thick along y, 1.4 along z, so a sphere
        // meets several images of each other sphere and of itself.
        let mut next = uniform(4242);
        let (r_max, skin) = (0.01, 0.002);
        let reach = 2.0 * r_max + skin;
        let mut cell = PeriodicCell::new_box([0.12, 0.3 * reach, 1.4 * reach]);
        cell.h[(0, 1)] = 0.2 * 0.3 * reach;
        cell.h[(1, 2)] = 0.1 * reach;
        let (mut x, mut r) = (Vec::new(), Vec::new());
        for _ in 0..40 {
            let p = cell.h * nalgebra::Vector3::new(next(), next(), next());
            x.push([p[0], p[1], p[2]]);
            r.push(r_max * (0.5 + 0.5 * next()));
        }
        let found = periodic_sphere_pairs(&x, &r, skin, &cell).concat();
        let brute = brute_force_over_images(&x, &r, skin, &cell, 8);
        assert!(brute.iter().any(|c| c.0 == c.1), "no sphere meets its own image: the test checks nothing there");
        let images_of_one_pair = |c: &Candidate| brute.iter().filter(|d| (d.0, d.1) == (c.0, c.1)).count();
        assert!(brute.iter().any(|c| c.0 != c.1 && images_of_one_pair(c) > 2), "no pair met through several images");
        assert_eq!(found, brute);
    }
}
