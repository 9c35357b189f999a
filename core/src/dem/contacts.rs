//! Candidate contact pairs with their per-pair parameters and history, kept across rebuilds of
//! the candidate list.

use crate::math::Vec3;

/// A list of pairs `(a, b)` sorted by `(a, b)`: sphere-sphere (b a sphere) or sphere-wall (b a wall).
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct PairList {
    pub a: Vec<u32>,
    pub b: Vec<u32>,
    /// Periodic image of `b` this pair involves (`x_b + h shift`); zero without a periodic cell.
    pub shift: Vec<[i32; 3]>,
    /// Contact law of the pair (index into the simulation's law table).
    pub law: Vec<u16>,
    pub param_stride: usize,
    pub history_stride: usize,
    pub params: Vec<f64>,
    pub history: Vec<f64>,
    pub touching: Vec<bool>,
    /// Force on `a` (b gets the opposite).
    pub force: Vec<Vec3>,
}

impl PairList {
    pub fn len(&self) -> usize {
        self.a.len()
    }

    pub fn is_empty(&self) -> bool {
        self.a.is_empty()
    }

    /// Re-sorts the pairs by `(a, b, shift)` after their shifts changed (wrapping, flipping).
    pub fn resort(&mut self) {
        let n = self.len();
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by_key(|&k| (self.a[k], self.b[k], self.shift[k]));
        if order.iter().enumerate().all(|(i, &k)| i == k) {
            return;
        }
        let (ps, hs) = (self.param_stride, self.history_stride);
        let pick = |v: &Vec<f64>, stride: usize| -> Vec<f64> {
            order.iter().flat_map(|&k| v[k * stride..(k + 1) * stride].iter().copied()).collect()
        };
        let params = pick(&self.params, ps);
        let history = pick(&self.history, hs);
        fn permute<T: Copy>(v: &[T], order: &[usize]) -> Vec<T> {
            order.iter().map(|&k| v[k]).collect()
        }
        self.a = permute(&self.a, &order);
        self.b = permute(&self.b, &order);
        self.shift = permute(&self.shift, &order);
        self.law = permute(&self.law, &order);
        self.touching = permute(&self.touching, &order);
        self.force = permute(&self.force, &order);
        self.params = params;
        self.history = history;
    }

    /// Gives back storage beyond the pairs held (rebuilds grow it by doubling).
    pub fn shrink_to_fit(&mut self) {
        self.a.shrink_to_fit();
        self.b.shrink_to_fit();
        self.shift.shrink_to_fit();
        self.law.shrink_to_fit();
        self.params.shrink_to_fit();
        self.history.shrink_to_fit();
        self.touching.shrink_to_fit();
        self.force.shrink_to_fit();
    }

    pub fn touching_count(&self) -> usize {
        self.touching.iter().filter(|t| **t).count()
    }

    /// Replaces the candidates by `pairs` (sorted), keeping parameters and history of pairs present
    /// in both, and calling `init(a, b, law_out, params_out)` for new ones. The new list is built
    /// in `spare`'s storage, which gets the old list's (a simulation that rebuilds often then
    /// reuses memory instead of faulting in fresh pages every time).
    pub fn merge(
        &mut self,
        spare: &mut PairList,
        pairs: &[(u32, u32, [i32; 3])],
        (param_stride, history_stride): (usize, usize),
        mut init: impl FnMut(u32, u32, &mut u16, &mut [f64]),
    ) {
        let n = pairs.len();
        let next = spare;
        /// Empties `v` for `len` values, keeping its storage.
        fn reuse<T>(v: &mut Vec<T>, len: usize) {
            v.clear();
            v.reserve(len);
        }
        reuse(&mut next.a, n);
        reuse(&mut next.b, n);
        reuse(&mut next.shift, n);
        reuse(&mut next.law, n);
        reuse(&mut next.params, n * param_stride);
        reuse(&mut next.history, n * history_stride);
        reuse(&mut next.touching, n);
        (next.param_stride, next.history_stride) = (param_stride, history_stride);
        // Forces are recomputed every step.
        next.force.clear();
        next.force.resize(n, [0.0; 3]);
        let same_layout = self.param_stride == param_stride && self.history_stride == history_stride;
        let mut old = 0;
        let mut scratch = vec![0.0; param_stride];
        for &(a, b, shift) in pairs {
            while old < self.a.len() && (self.a[old], self.b[old], self.shift[old]) < (a, b, shift) {
                old += 1;
            }
            next.a.push(a);
            next.b.push(b);
            next.shift.push(shift);
            if same_layout && old < self.a.len() && (self.a[old], self.b[old], self.shift[old]) == (a, b, shift) {
                next.law.push(self.law[old]);
                next.params.extend_from_slice(&self.params[old * param_stride..(old + 1) * param_stride]);
                next.history.extend_from_slice(&self.history[old * history_stride..(old + 1) * history_stride]);
                next.touching.push(self.touching[old]);
            } else {
                let mut law = 0;
                scratch.iter_mut().for_each(|v| *v = 0.0);
                init(a, b, &mut law, &mut scratch);
                next.law.push(law);
                next.params.extend_from_slice(&scratch);
                next.history.extend(std::iter::repeat_n(0.0, history_stride));
                next.touching.push(false);
            }
        }
        std::mem::swap(self, next);
    }
}
