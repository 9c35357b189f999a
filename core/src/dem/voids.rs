//! Void ratio of granular assemblies of any shape (thesis 2.3.3): the tetrahedron method on a
//! Delaunay tetrahedralisation of the centres (2.12-2.16), the sub-volume method (2.17-2.31), the
//! bounding-box reference (2.34-2.36) and the void ratio without rattlers (2.44).

use crate::dem::delaunay::{tet_volume, tetrahedralize};
use crate::dem::particles::FREE;
use crate::dem::sim::DemSim;
use crate::ext::contact::uniform;
use crate::ext::BodyShape;
use crate::math::Vec3;
use nalgebra::UnitQuaternion;
use rayon::prelude::*;
use std::sync::Arc;

/// A particle as the void-ratio methods see it: its spheres (one, or a clump's members) and the
/// volume of their union; for a body of a plugin kind, its bounding sphere (centre and reach) and
/// its shape where it is, which decides what lies inside it.
#[derive(Debug, Clone)]
pub struct Grain {
    pub spheres: Vec<(Vec3, f64)>,
    pub volume: f64,
    pub body: Option<PlacedShape>,
}

/// A body's shape at its pose.
#[derive(Debug, Clone)]
pub struct PlacedShape {
    pub shape: Arc<dyn BodyShape>,
    pub x: Vec3,
    pub q: UnitQuaternion<f64>,
}

impl Grain {
    fn contains(&self, p: Vec3) -> bool {
        if let Some(b) = &self.body {
            let local = b.q.inverse() * nalgebra::Vector3::new(p[0] - b.x[0], p[1] - b.x[1], p[2] - b.x[2]);
            return b.shape.contains([local[0], local[1], local[2]]);
        }
        self.spheres.iter().any(|(c, r)| (p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2) <= r * r)
    }

    fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for (c, r) in &self.spheres {
            for a in 0..3 {
                lo[a] = lo[a].min(c[a] - r);
                hi[a] = hi[a].max(c[a] + r);
            }
        }
        (lo, hi)
    }
}

/// The grains of a simulation: free spheres, clumps and bodies of plugin kinds (fixed ones, the
/// container's parts, left out).
pub fn grains(sim: &DemSim) -> Vec<Grain> {
    let s = &sim.world.spheres;
    let mut out: Vec<Grain> = (0..s.len())
        .filter(|&i| s.clump[i] == FREE)
        .map(|i| Grain {
            spheres: vec![(s.x[i], s.radius[i])],
            volume: 4.0 / 3.0 * std::f64::consts::PI * s.radius[i].powi(3),
            body: None,
        })
        .collect();
    for c in 0..sim.world.clumps.len() {
        let spheres = sim.world.clumps.members_of(c).map(|m| {
            let i = sim.world.clumps.members[m] as usize;
            (s.x[i], s.radius[i])
        });
        out.push(Grain { spheres: spheres.collect(), volume: sim.world.clumps.volume[c], body: None });
    }
    let k = &sim.world.kinds;
    for i in (0..k.len()).filter(|&i| !k.fixed[i]) {
        let shape = k.shapes[k.shape[i] as usize].clone();
        out.push(Grain {
            spheres: vec![(k.x[i], shape.bounding_radius())],
            volume: shape.volume(),
            body: Some(PlacedShape { shape, x: k.x[i], q: k.q[i] }),
        });
    }
    out
}

/// Axis-aligned bounding box of the grains.
pub fn bounding_box(grains: &[Grain]) -> (Vec3, Vec3) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for g in grains {
        let (l, h) = g.bounds();
        for a in 0..3 {
            lo[a] = lo[a].min(l[a]);
            hi[a] = hi[a].max(h[a]);
        }
    }
    (lo, hi)
}

/// Reference void ratio on the bounding box (eqs. 2.34-2.36).
pub fn void_ratio_bounding_box(grains: &[Grain]) -> f64 {
    let (lo, hi) = bounding_box(grains);
    let v: f64 = (0..3).map(|a| hi[a] - lo[a]).product();
    let vp: f64 = grains.iter().map(|g| g.volume).sum();
    (v - vp) / vp
}

/// A sub-volume for the sub-volume method.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SubVolume {
    Box {
        lo: Vec3,
        hi: Vec3,
    },
    /// A cone of axis z: base radius `radius` at `z_min`, apex at `z_max`, axis through `centre`.
    Cone {
        centre: [f64; 2],
        radius: f64,
        z_min: f64,
        z_max: f64,
    },
}

impl SubVolume {
    /// The homothetic box of the sample's bounding box for parameter C in ]0.5, 1] (2.17-2.18).
    pub fn homothetic_box(grains: &[Grain], c: f64) -> SubVolume {
        let (lo, hi) = bounding_box(grains);
        SubVolume::Box {
            lo: [0, 1, 2].map(|a| (1.0 - c) * (hi[a] - lo[a]) + lo[a]),
            hi: [0, 1, 2].map(|a| c * (hi[a] - lo[a]) + lo[a]),
        }
    }

    /// The homothetic cone of an axisymmetric heap for parameter C (2.19-2.22).
    pub fn homothetic_cone(grains: &[Grain], c: f64) -> SubVolume {
        let (lo, hi) = bounding_box(grains);
        SubVolume::Cone {
            centre: [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])],
            radius: (2.0 * c - 1.0) * (hi[0] - lo[0] + hi[1] - lo[1]) / 4.0,
            z_min: (1.0 - c) * (hi[2] - lo[2]) + lo[2],
            z_max: c * (hi[2] - lo[2]) + lo[2],
        }
    }

    pub fn contains(&self, p: Vec3) -> bool {
        match *self {
            SubVolume::Box { lo, hi } => (0..3).all(|a| p[a] >= lo[a] && p[a] <= hi[a]),
            SubVolume::Cone { centre, radius, z_min, z_max } => {
                if p[2] < z_min || p[2] > z_max {
                    return false;
                }
                let r = radius * (z_max - p[2]) / (z_max - z_min);
                (p[0] - centre[0]).powi(2) + (p[1] - centre[1]).powi(2) <= r * r
            }
        }
    }

    pub fn volume(&self) -> f64 {
        match *self {
            SubVolume::Box { lo, hi } => (0..3).map(|a| (hi[a] - lo[a]).max(0.0)).product(),
            SubVolume::Cone { radius, z_min, z_max, .. } => {
                std::f64::consts::PI * radius * radius * (z_max - z_min) / 3.0
            }
        }
    }
}

/// Sub-volume method (2.24-2.29): grains whose bounding box lies inside count whole, those cut by
/// the boundary by Monte Carlo with `n_mc` points in their bounding box.
pub fn void_ratio_sub_volume(grains: &[Grain], sub: &SubVolume, n_mc: usize, seed: u64) -> f64 {
    let parts: Vec<f64> = grains
        .par_iter()
        .enumerate()
        .map(|(k, g)| {
            let (lo, hi) = g.bounds();
            let corners_in = (0..8)
                .filter(|&m| sub.contains([0, 1, 2].map(|a| if m >> a & 1 == 1 { hi[a] } else { lo[a] })))
                .count();
            match corners_in {
                8 => g.volume,
                0 if !g.spheres.iter().any(|(c, _)| sub.contains(*c)) => 0.0,
                _ => {
                    let bb: f64 = (0..3).map(|a| hi[a] - lo[a]).product();
                    let mut inside = 0usize;
                    for i in 0..n_mc {
                        let p =
                            [0, 1, 2].map(|a| lo[a] + (hi[a] - lo[a]) * uniform(seed ^ k as u64, (3 * i + a) as u64));
                        if sub.contains(p) && g.contains(p) {
                            inside += 1;
                        }
                    }
                    // V^p_in = fraction of the particle's own volume (its share of the bounding box).
                    let in_both = inside as f64 / n_mc as f64 * bb;
                    in_both.min(g.volume)
                }
            }
        })
        .collect();
    let vp: f64 = parts.iter().sum();
    (sub.volume() - vp) / vp
}

/// Tetrahedron method (2.12-2.16): Delaunay tetrahedra of the sphere centres, `n_mc` points per
/// tetrahedron tested against the grains that may cut it. Returns the void ratio, the volume
/// covered and the solid volume in it.
pub fn void_ratio_tetrahedra(grains: &[Grain], n_mc: usize, seed: u64) -> (f64, f64, f64) {
    let mut centres = Vec::new();
    let mut owner = Vec::new();
    for (k, g) in grains.iter().enumerate() {
        for (c, _) in &g.spheres {
            centres.push(*c);
            owner.push(k);
        }
    }
    let tets = tetrahedralize(&centres);
    // Grains on a grid of their bounding boxes, to find those that may cut a tetrahedron.
    let (lo, hi) = bounding_box(grains);
    let r_max = grains.iter().flat_map(|g| g.spheres.iter().map(|s| s.1)).fold(0.0, f64::max);
    let h = (2.0 * r_max).max(f64::MIN_POSITIVE);
    let dims = [0, 1, 2].map(|a| (((hi[a] - lo[a]) / h).ceil() as usize).max(1));
    let cell = |p: Vec3| [0, 1, 2].map(|a| (((p[a] - lo[a]) / h).floor().max(0.0) as usize).min(dims[a] - 1));
    let mut grid: Vec<Vec<u32>> = vec![Vec::new(); dims[0] * dims[1] * dims[2]];
    for (k, g) in grains.iter().enumerate() {
        let (l, u) = g.bounds();
        let (cl, cu) = (cell(l), cell(u));
        for z in cl[2]..=cu[2] {
            for y in cl[1]..=cu[1] {
                for x in cl[0]..=cu[0] {
                    grid[x + dims[0] * (y + dims[1] * z)].push(k as u32);
                }
            }
        }
    }
    let per_tet: Vec<(f64, f64)> = tets
        .par_iter()
        .enumerate()
        .map(|(t, v)| {
            let p = [centres[v[0]], centres[v[1]], centres[v[2]], centres[v[3]]];
            let vol = tet_volume(p[0], p[1], p[2], p[3]);
            let mut tlo = [f64::INFINITY; 3];
            let mut thi = [f64::NEG_INFINITY; 3];
            for q in &p {
                for a in 0..3 {
                    tlo[a] = tlo[a].min(q[a]);
                    thi[a] = thi[a].max(q[a]);
                }
            }
            let (cl, cu) = (cell(tlo), cell(thi));
            let mut cut: Vec<u32> = Vec::new();
            for z in cl[2]..=cu[2] {
                for y in cl[1]..=cu[1] {
                    for x in cl[0]..=cu[0] {
                        cut.extend_from_slice(&grid[x + dims[0] * (y + dims[1] * z)]);
                    }
                }
            }
            cut.sort_unstable();
            cut.dedup();
            let mut inside = 0usize;
            for i in 0..n_mc {
                let u = [0, 1, 2].map(|a| uniform(seed ^ (t as u64).wrapping_mul(0x9E37_79B9), (3 * i + a) as u64));
                let x = point_in_tet(&p, u);
                if cut.iter().any(|&k| grains[k as usize].contains(x)) {
                    inside += 1;
                }
            }
            (vol, inside as f64 / n_mc as f64 * vol)
        })
        .collect();
    let v_tot: f64 = per_tet.iter().map(|t| t.0).sum();
    let v_part: f64 = per_tet.iter().map(|t| t.1).sum();
    let _ = owner;
    ((v_tot - v_part) / v_part, v_tot, v_part)
}

/// A uniform point in a tetrahedron from three uniform numbers (Rocchini & Cignoni 2000).
fn point_in_tet(p: &[Vec3; 4], u: [f64; 3]) -> Vec3 {
    let (mut s, mut t, mut w) = (u[0], u[1], u[2]);
    if s + t > 1.0 {
        s = 1.0 - s;
        t = 1.0 - t;
    }
    if t + w > 1.0 {
        let tmp = w;
        w = 1.0 - s - t;
        t = 1.0 - tmp;
    } else if s + t + w > 1.0 {
        let tmp = w;
        w = s + t + w - 1.0;
        s = 1.0 - t - tmp;
    }
    [0, 1, 2].map(|a| p[0][a] + s * (p[1][a] - p[0][a]) + t * (p[2][a] - p[0][a]) + w * (p[3][a] - p[0][a]))
}

/// Void ratio without rattlers (2.44): rattlers' volume counted as void.
pub fn void_ratio_without_rattlers(v_void: f64, v_part: f64, rattler_volume: f64) -> f64 {
    (v_void + rattler_volume) / (v_part - rattler_volume)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tet_points_are_uniform() {
        // The mean of uniform points is the centroid.
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]];
        let mut m = [0.0; 3];
        let n = 200_000;
        for i in 0..n {
            let x = point_in_tet(&p, [0, 1, 2].map(|a| uniform(1, 3 * i + a)));
            for a in 0..3 {
                m[a] += x[a] / n as f64;
            }
        }
        let c = [0.25, 0.5, 0.75];
        for a in 0..3 {
            assert!((m[a] - c[a]).abs() < 0.01 * c[a].max(0.25));
        }
    }
}
