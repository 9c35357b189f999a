//! Candidate contact pairs with their per-pair parameters and history, kept across rebuilds of
//! the candidate list.

use crate::dem::broad_phase::Candidate;
use crate::math::Vec3;
use rayon::prelude::*;

/// Most per-pair parameters / history values a contact law may use.
pub const MAX_PARAMS: usize = 16;
pub const MAX_HISTORY: usize = 16;

/// What a pair of a list is known by: its two members, the periodic image of the second, and
/// which of several contact points of the two it is (a body meeting a wall or another body at
/// several points: a contact manifold).
pub trait PairKey: Copy + Send + Sync {
    /// Whether the list's pairs have contact points apart (`PairList::part`).
    const PARTED: bool;
    fn key(&self) -> (u32, u32, [i32; 3], u8);
}

impl PairKey for Candidate {
    const PARTED: bool = false;
    #[inline(always)]
    fn key(&self) -> (u32, u32, [i32; 3], u8) {
        (self.0, self.1, self.2, 0)
    }
}

/// A candidate pair and its contact point.
impl PairKey for (Candidate, u8) {
    const PARTED: bool = true;
    #[inline(always)]
    fn key(&self) -> (u32, u32, [i32; 3], u8) {
        (self.0 .0, self.0 .1, self.0 .2, self.1)
    }
}

/// One piece of a new list's entries, written by [`PairList::merge_block`].
struct Merged<'a> {
    a: &'a mut [u32],
    b: &'a mut [u32],
    shift: &'a mut [[i32; 3]],
    part: &'a mut [u8],
    law: &'a mut [u16],
    params: &'a mut [f64],
    history: &'a mut [f64],
    touching: &'a mut [bool],
    force: &'a mut [Vec3],
}

/// A list of pairs `(a, b)` sorted by `(a, b)`: sphere-sphere (b a sphere) or sphere-wall (b a wall).
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct PairList {
    pub a: Vec<u32>,
    pub b: Vec<u32>,
    /// Periodic image of `b` this pair involves (`x_b + h shift`); zero without a periodic cell.
    pub shift: Vec<[i32; 3]>,
    /// Which of the contact points of its two members a pair is, in a list whose pairs have
    /// several (a body's kind meeting walls or its own kind at several points); empty in a list
    /// of one point a pair (spheres), all of whose pairs are point 0.
    #[serde(default)]
    pub part: Vec<u8>,
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

impl<'a> Merged<'a> {
    /// Cuts the entries of the next `len` pairs off the front of `rest`.
    fn cut_front(rest: &mut Merged<'a>, len: usize, (ps, hs): (usize, usize)) -> Merged<'a> {
        fn front<'a, T>(rest: &mut &'a mut [T], len: usize) -> &'a mut [T] {
            let (head, tail) = std::mem::take(rest).split_at_mut(len);
            *rest = tail;
            head
        }
        Merged {
            a: front(&mut rest.a, len),
            b: front(&mut rest.b, len),
            shift: front(&mut rest.shift, len),
            part: {
                let parted = if rest.part.is_empty() { 0 } else { len };
                front(&mut rest.part, parted)
            },
            law: front(&mut rest.law, len),
            params: front(&mut rest.params, len * ps),
            history: front(&mut rest.history, len * hs),
            touching: front(&mut rest.touching, len),
            force: front(&mut rest.force, len),
        }
    }
}

impl PairList {
    pub fn len(&self) -> usize {
        self.a.len()
    }

    pub fn is_empty(&self) -> bool {
        self.a.is_empty()
    }

    /// The contact point pair `k` is (see `part`).
    #[inline(always)]
    pub fn part_of(&self, k: usize) -> u8 {
        self.part.get(k).copied().unwrap_or(0)
    }

    /// What pair `k` is known by: members, image, contact point.
    #[inline(always)]
    pub fn key_of(&self, k: usize) -> (u32, u32, [i32; 3], u8) {
        (self.a[k], self.b[k], self.shift[k], self.part_of(k))
    }

    /// Re-sorts the pairs by `(a, b, shift, part)` after their shifts changed (wrapping,
    /// flipping).
    pub fn resort(&mut self) {
        let n = self.len();
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by_key(|&k| self.key_of(k));
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
        if !self.part.is_empty() {
            self.part = permute(&self.part, &order);
        }
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
        self.part.shrink_to_fit();
        self.law.shrink_to_fit();
        self.params.shrink_to_fit();
        self.history.shrink_to_fit();
        self.touching.shrink_to_fit();
        self.force.shrink_to_fit();
    }

    /// Lays the per-pair values out with `ps` parameters and `hs` history values per pair,
    /// keeping each pair's leading values (the law's own; the rest is padding).
    pub fn relayout(&mut self, ps: usize, hs: usize) {
        fn restride(v: &mut Vec<f64>, from: usize, to: usize, pairs: usize) {
            if from == to {
                return;
            }
            let keep = from.min(to);
            let mut out = vec![0.0; pairs * to];
            for k in 0..pairs {
                out[k * to..k * to + keep].copy_from_slice(&v[k * from..k * from + keep]);
            }
            *v = out;
        }
        let n = self.len();
        restride(&mut self.params, self.param_stride, ps, n);
        restride(&mut self.history, self.history_stride, hs, n);
        (self.param_stride, self.history_stride) = (ps, hs);
    }

    /// [`PairList::relayout`] for a list whose history rows end with `warm` values of a body
    /// geometry's warm starts after the law's: the law's leading values and the warm starts
    /// both stay, the law's part now `hs` values.
    pub fn relayout_with_warm(&mut self, ps: usize, hs: usize, warm: usize) {
        let (from, n) = (self.history_stride, self.len());
        let own = from.saturating_sub(warm);
        if own == hs || warm == 0 {
            return self.relayout(ps, hs + warm);
        }
        let keep = own.min(hs);
        let to = hs + warm;
        let mut out = vec![0.0; n * to];
        for k in 0..n {
            let (row, old) = (&mut out[k * to..(k + 1) * to], &self.history[k * from..(k + 1) * from]);
            row[..keep].copy_from_slice(&old[..keep]);
            row[hs..].copy_from_slice(&old[own..]);
        }
        self.history = out;
        self.history_stride = to;
        self.relayout(ps, to);
    }

    /// Drops the pairs of spheres whose `keep` flag is false and renumbers the others' spheres
    /// as `Spheres::retain` does (the order of the list is kept: renumbering keeps the order).
    /// `b` is a sphere index for sphere pairs (`spheres`), a wall index otherwise.
    pub fn retain_spheres(&mut self, keep: &[bool], spheres: bool) {
        let new_index = crate::dem::particles::compacted_indices(keep);
        let (ps, hs) = (self.param_stride, self.history_stride);
        let mut kept = 0;
        for k in 0..self.len() {
            let (a, b) = (self.a[k] as usize, self.b[k] as usize);
            let stays = keep.get(a).copied().unwrap_or(false) && (!spheres || keep.get(b).copied().unwrap_or(false));
            if !stays {
                continue;
            }
            self.a[kept] = new_index[a];
            self.b[kept] = if spheres { new_index[b] } else { b as u32 };
            self.shift[kept] = self.shift[k];
            if !self.part.is_empty() {
                self.part[kept] = self.part[k];
            }
            self.law[kept] = self.law[k];
            self.touching[kept] = self.touching[k];
            self.force[kept] = self.force[k];
            self.params.copy_within(k * ps..(k + 1) * ps, kept * ps);
            self.history.copy_within(k * hs..(k + 1) * hs, kept * hs);
            kept += 1;
        }
        self.a.truncate(kept);
        self.b.truncate(kept);
        self.shift.truncate(kept);
        self.part.truncate(if self.part.is_empty() { 0 } else { kept });
        self.law.truncate(kept);
        self.touching.truncate(kept);
        self.force.truncate(kept);
        self.params.truncate(kept * ps);
        self.history.truncate(kept * hs);
    }

    pub fn touching_count(&self) -> usize {
        self.touching.iter().filter(|t| **t).count()
    }

    /// Replaces the candidates by the sorted list that `pieces` make one after the other,
    /// keeping parameters and history of pairs present in both, and calling
    /// `init(a, b, law_out, params_out)` (params zeroed) for new ones; `init` returns false where no
    /// law applies, and the first such pair is returned. The new list is built in `spare`'s
    /// storage, which gets the old list's (a simulation that rebuilds often then reuses memory
    /// instead of faulting in fresh pages every time). In `parallel`, the pieces are merged on the
    /// pool's workers: each pair's entry depends only on the pair and on the old list, so the list
    /// is the same on any number of threads and for any cut into pieces.
    pub fn merge<K: PairKey>(
        &mut self,
        spare: &mut PairList,
        pieces: &[&[K]],
        strides: (usize, usize),
        parallel: bool,
        init: impl Fn(u32, u32, &mut u16, &mut [f64]) -> bool + Sync,
    ) -> Option<(u32, u32)> {
        let n = pieces.iter().map(|p| p.len()).sum();
        let (param_stride, history_stride) = strides;
        let next = spare;
        // Every entry below `n` is written by the merge: the storage's old contents are kept (not
        // cleared and refilled), so that only growth is filled twice.
        next.a.resize(n, 0);
        next.b.resize(n, 0);
        next.shift.resize(n, [0; 3]);
        next.part.resize(if K::PARTED { n } else { 0 }, 0);
        next.law.resize(n, 0);
        next.params.resize(n * param_stride, 0.0);
        next.history.resize(n * history_stride, 0.0);
        next.touching.resize(n, false);
        next.force.resize(n, [0.0; 3]);
        (next.param_stride, next.history_stride) = strides;
        let mut rest = Merged {
            a: &mut next.a,
            b: &mut next.b,
            shift: &mut next.shift,
            part: &mut next.part,
            law: &mut next.law,
            params: &mut next.params,
            history: &mut next.history,
            touching: &mut next.touching,
            force: &mut next.force,
        };
        let outs: Vec<Merged<'_>> =
            pieces.iter().map(|piece| Merged::cut_front(&mut rest, piece.len(), strides)).collect();
        let old: &PairList = self;
        let merge = |(piece, out): (&&[K], Merged<'_>)| old.merge_block(piece, out, strides, &init);
        let missing = if parallel {
            pieces.par_iter().zip(outs).map(merge).reduce(|| None, |first, later| first.or(later))
        } else {
            pieces.iter().zip(outs).map(merge).fold(None, |first, later| first.or(later))
        };
        std::mem::swap(self, next);
        missing
    }

    /// Writes the entries of `pairs` (a run of the sorted new list) into `out`, from the old
    /// list (`self`) where a pair is in it.
    fn merge_block<K: PairKey>(
        &self,
        pairs: &[K],
        out: Merged<'_>,
        (ps, hs): (usize, usize),
        init: &impl Fn(u32, u32, &mut u16, &mut [f64]) -> bool,
    ) -> Option<(u32, u32)> {
        let same_layout = self.param_stride == ps && self.history_stride == hs;
        let key = |k: usize| self.key_of(k);
        // The first old pair not before this run's first pair.
        let mut old =
            pairs.first().map_or(0, |first| crate::math::partition_index(0..self.len(), |k| key(k) < first.key()));
        let mut missing = None;
        for (k, pair) in pairs.iter().enumerate() {
            let (a, b, shift, part) = pair.key();
            while old < self.len() && key(old) < (a, b, shift, part) {
                old += 1;
            }
            (out.a[k], out.b[k], out.shift[k]) = (a, b, shift);
            if K::PARTED {
                out.part[k] = part;
            }
            // Forces are recomputed every step; a kept pair keeps its force until then, so that
            // what is measured between two steps (the cell's stress, a saved state) does not
            // depend on whether the list was rebuilt (`sim.skin`) since the last one.
            out.force[k] = [0.0; 3];
            let (params, history) = (&mut out.params[k * ps..(k + 1) * ps], &mut out.history[k * hs..(k + 1) * hs]);
            if same_layout && old < self.len() && key(old) == (a, b, shift, part) {
                out.law[k] = self.law[old];
                params.copy_from_slice(&self.params[old * ps..(old + 1) * ps]);
                history.copy_from_slice(&self.history[old * hs..(old + 1) * hs]);
                out.touching[k] = self.touching[old];
                out.force[k] = self.force[old];
            } else {
                params.fill(0.0);
                history.fill(0.0);
                out.law[k] = 0;
                if !init(a, b, &mut out.law[k], params) && missing.is_none() {
                    missing = Some((a, b));
                }
                out.touching[k] = false;
            }
        }
        missing
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An old list of every third pair `(a, a - 1 - k)`, each with history and parameters that
    /// name it, and a new candidate list of every second one: some pairs stay, some go, some come.
    fn lists(pairs: u32) -> (PairList, Vec<Candidate>) {
        let key = |k: u32| (k / 4 + 10, k / 4 + 6 + k % 4, [0, (k % 2) as i32, 0]);
        let mut old = PairList { param_stride: 2, history_stride: 3, ..PairList::default() };
        for k in (0..pairs).step_by(3) {
            let (a, b, shift) = key(k);
            old.a.push(a);
            old.b.push(b);
            old.shift.push(shift);
            old.law.push(7);
            old.params.extend([a as f64, b as f64]);
            old.history.extend([a as f64, b as f64, shift[1] as f64 + 0.5]);
            old.touching.push(k % 9 == 0);
            old.force.push([1.0; 3]);
        }
        let new = (0..pairs).step_by(2).map(key).collect();
        (old, new)
    }

    /// A sphere without a law, in the first block of pairs and in a later one.
    fn lawless(sphere: u32) -> bool {
        sphere % 5000 == 13
    }

    /// What a new pair gets: law 3 and parameters from its spheres, none for `lawless` ones.
    fn init(a: u32, b: u32, law: &mut u16, params: &mut [f64]) -> bool {
        *law = 3;
        params[0] = -(a as f64);
        params[1] = -(b as f64);
        !lawless(a) && !lawless(b)
    }

    #[test]
    fn a_merge_keeps_the_history_of_the_pairs_that_stay_on_any_number_of_threads_and_pieces() {
        let pairs = 24_581;
        let (old, new) = lists(pairs);
        let merged = |parallel: bool, threads: usize, piece: usize, spare: &mut PairList| {
            let mut list = old.clone();
            // Pieces of `piece` pairs, and an empty one.
            let mut pieces: Vec<&[Candidate]> = new.chunks(piece).collect();
            pieces.insert(1, &[]);
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let missing = pool.install(|| list.merge(spare, &pieces, (2, 3), parallel, init));
            (list, missing)
        };
        let (sequential, missing) = merged(false, 1, new.len(), &mut PairList::default());
        // Only new pairs meet `init`: the first new pair without a law is the one reported.
        let in_old = |c: &Candidate| (0..old.len()).any(|o| (old.a[o], old.b[o], old.shift[o]) == *c);
        let lawless_pairs: Vec<_> = new.iter().filter(|c| (lawless(c.0) || lawless(c.1)) && !in_old(c)).collect();
        assert!(lawless_pairs.last().is_some_and(|c| c.0 > 5000));
        let first_missing = lawless_pairs.first().map(|c| (c.0, c.1));
        assert_eq!(missing, first_missing);
        assert_eq!(sequential.len(), new.len());
        let mut kept = 0;
        for (k, &(a, b, shift)) in new.iter().enumerate() {
            assert_eq!((sequential.a[k], sequential.b[k], sequential.shift[k]), (a, b, shift));
            let history = &sequential.history[3 * k..3 * k + 3];
            let params = &sequential.params[2 * k..2 * k + 2];
            match (0..old.len()).find(|&o| (old.a[o], old.b[o], old.shift[o]) == (a, b, shift)) {
                Some(o) => {
                    kept += 1;
                    assert_eq!((sequential.law[k], sequential.touching[k]), (7, old.touching[o]));
                    // Until the next step computes it again, a kept pair's force is the last one.
                    assert_eq!(sequential.force[k], old.force[o]);
                    assert_eq!(history, &old.history[3 * o..3 * o + 3]);
                    assert_eq!(params, &old.params[2 * o..2 * o + 2]);
                }
                None => {
                    assert_eq!((sequential.law[k], sequential.touching[k]), (3, false));
                    assert_eq!(sequential.force[k], [0.0; 3]);
                    assert_eq!(history, &[0.0; 3]);
                    assert_eq!(params, &[-(a as f64), -(b as f64)]);
                }
            }
        }
        // Every sixth pair is in both lists.
        assert_eq!(kept, new.len().div_ceil(3));
        // In parallel, into a spare list that holds stale entries of another layout.
        let (stale, _) = lists(pairs / 2 + 17);
        for (threads, piece) in [(1, 1000), (2, 1024), (2, 333), (3, 4096)] {
            let mut spare = PairList { param_stride: 1, history_stride: 1, ..stale.clone() };
            let (parallel, missing) = merged(true, threads, piece, &mut spare);
            assert_eq!(missing, first_missing);
            assert_eq!(
                (&parallel.a, &parallel.b, &parallel.shift, &parallel.law, &parallel.touching),
                (&sequential.a, &sequential.b, &sequential.shift, &sequential.law, &sequential.touching)
            );
            assert_eq!(
                (&parallel.params, &parallel.history, &parallel.force),
                (&sequential.params, &sequential.history, &sequential.force)
            );
            assert_eq!((parallel.param_stride, parallel.history_stride), (2, 3));
            // The old list's storage is the next spare.
            assert_eq!(spare.len(), old.len());
        }
    }
}
