//! Items with bounding boxes binned on a uniform grid of cubes, for finding those near a point
//! (the triangles of wall meshes near a sphere, the elements of a mesh group near a point). Each
//! item is listed in every cube its box overlaps; cubes are about as wide as the mean box, and
//! there are at most ~8 of them per item.

use crate::math::Vec3;

#[derive(Debug, Clone)]
pub struct BoxBins {
    lo: Vec3,
    cube: f64,
    counts: [usize; 3],
    /// The items of each cube (CSR).
    start: Vec<u32>,
    items: Vec<u32>,
}

impl BoxBins {
    /// Bins of items `0..boxes.len()` with the boxes `(lower, upper)` (at least one).
    pub fn new(boxes: &[(Vec3, Vec3)]) -> BoxBins {
        let lo = [0, 1, 2].map(|k| boxes.iter().map(|b| b.0[k]).fold(f64::INFINITY, f64::min));
        let hi = [0, 1, 2].map(|k| boxes.iter().map(|b| b.1[k]).fold(f64::NEG_INFINITY, f64::max));
        let span = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
        let mean = boxes.iter().map(|(a, b)| (0..3).map(|k| b[k] - a[k]).fold(0.0, f64::max)).sum::<f64>()
            / boxes.len().max(1) as f64;
        let mut cube = mean.max(1e-9 * span).max(f64::MIN_POSITIVE);
        let counts_of = |cube: f64| [0, 1, 2].map(|k| (((hi[k] - lo[k]) / cube) as usize + 1).min(1 << 20));
        while counts_of(cube).iter().product::<usize>() > 8 * boxes.len() + 64 {
            cube *= 1.5;
        }
        let counts = counts_of(cube);
        let index = |x: f64, k: usize| (((x - lo[k]) / cube).max(0.0) as usize).min(counts[k] - 1);
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); counts.iter().product()];
        for (item, (a, b)) in boxes.iter().enumerate() {
            for z in index(a[2], 2)..=index(b[2], 2) {
                for y in index(a[1], 1)..=index(b[1], 1) {
                    for x in index(a[0], 0)..=index(b[0], 0) {
                        lists[(z * counts[1] + y) * counts[0] + x].push(item as u32);
                    }
                }
            }
        }
        let mut start = vec![0u32];
        let mut items = Vec::new();
        for l in lists {
            items.extend(l);
            start.push(items.len() as u32);
        }
        BoxBins { lo, cube, counts, start, items }
    }

    fn cell(&self, ijk: [usize; 3]) -> &[u32] {
        let c = (ijk[2] * self.counts[1] + ijk[1]) * self.counts[0] + ijk[0];
        &self.items[self.start[c] as usize..self.start[c + 1] as usize]
    }

    /// The items whose boxes may hold `x`: those of its cube (none outside the bins).
    pub fn at(&self, x: Vec3) -> &[u32] {
        let mut ijk = [0usize; 3];
        for k in 0..3 {
            let t = (x[k] - self.lo[k]) / self.cube;
            if !(t >= 0.0 && t < self.counts[k] as f64) {
                return &[];
            }
            ijk[k] = t as usize;
        }
        self.cell(ijk)
    }

    /// The items whose boxes may come within `reach` of `x`, each once, in increasing order.
    pub fn near(&self, x: Vec3, reach: f64) -> Vec<u32> {
        let mut range = [(0usize, 0usize); 3];
        for k in 0..3 {
            let lo = ((x[k] - reach - self.lo[k]) / self.cube).floor();
            let hi = ((x[k] + reach - self.lo[k]) / self.cube).floor();
            let top = self.counts[k] as f64 - 1.0;
            if !(hi >= 0.0 && lo <= top) {
                return Vec::new();
            }
            range[k] = (lo.max(0.0) as usize, hi.min(top) as usize);
        }
        let mut found = Vec::new();
        for z in range[2].0..=range[2].1 {
            for y in range[1].0..=range[1].1 {
                for xb in range[0].0..=range[0].1 {
                    found.extend_from_slice(self.cell([xb, y, z]));
                }
            }
        }
        found.sort_unstable();
        found.dedup();
        found
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_items_near_a_point_are_those_whose_boxes_come_within_reach() {
        // 200 small boxes along a helix.
        let boxes: Vec<(Vec3, Vec3)> = (0..200)
            .map(|i| {
                let t = i as f64 * 0.1;
                let c = [t.cos(), t.sin(), 0.05 * t];
                ([c[0] - 0.05, c[1] - 0.05, c[2] - 0.02], [c[0] + 0.05, c[1] + 0.05, c[2] + 0.02])
            })
            .collect();
        let bins = BoxBins::new(&boxes);
        let gap = |x: Vec3, (a, b): &(Vec3, Vec3)| {
            (0..3).map(|k| (a[k] - x[k]).max(x[k] - b[k]).max(0.0).powi(2)).sum::<f64>().sqrt()
        };
        for q in 0..100 {
            let s = q as f64 * 0.19;
            let x = [1.1 * s.cos(), 0.9 * s.sin(), 0.04 * s];
            let reach = 0.1;
            let found = bins.near(x, reach);
            for (i, b) in boxes.iter().enumerate() {
                if gap(x, b) <= reach {
                    assert!(found.contains(&(i as u32)), "box {i} within reach of {x:?} not found");
                }
                if gap(x, b) == 0.0 {
                    assert!(bins.at(x).contains(&(i as u32)), "box {i} holding {x:?} not at it");
                }
            }
        }
    }
}
