//! Exact sharing of a `dem_rve` material's RVEs in one process: points whose RVEs are bitwise
//! the same (copies of the prepared sample that have taken bitwise the same strain increments)
//! step one RVE, their *keeper's*, and take its results. When their increments part, each new
//! group gets a copy of the keeper's RVE before anything steps (copy on divergence). The
//! results are the same bits as stepping every RVE; only the work differs.

use granite_core::math::Voigt;
use std::collections::BTreeMap;

/// Which points of this process share another point's RVE.
#[derive(Debug, Clone, Default)]
pub struct Twins {
    /// Per material point: the point whose RVE object is also its RVE (its own object is stale),
    /// or None: its own object is current (or it lives in another process).
    keeper: Vec<Option<u32>>,
}

/// One step's work after sharing.
#[derive(Debug, Default, PartialEq)]
pub struct Shared {
    /// RVE copies to make before stepping: (from, to).
    pub copies: Vec<(usize, usize)>,
    /// Points whose RVE objects step, in point order.
    pub steppers: Vec<usize>,
    /// Points that step through another's RVE: (point, keeper).
    pub riders: Vec<(usize, usize)>,
}

impl Twins {
    /// Points appended; those `here` flags (all copies of the prepared sample) share the first
    /// one's RVE when `share` is on.
    pub fn add(&mut self, here: &[bool], share: bool) {
        let first = self.keeper.len();
        let mut keeper: Option<u32> = None;
        for (k, &h) in here.iter().enumerate() {
            let point = (first + k) as u32;
            match (h && share, keeper) {
                (true, Some(kp)) => self.keeper.push(Some(kp)),
                (true, None) => {
                    keeper = Some(point);
                    self.keeper.push(None);
                }
                (false, _) => self.keeper.push(None),
            }
        }
    }

    /// The sharing a checkpoint's equal RVEs give: `keeper[i]` the first point whose RVE equals
    /// point i's (None: the first of its kind). Replaces what was there.
    pub fn restore(&mut self, keeper: &[Option<usize>]) {
        self.keeper = keeper.iter().map(|k| k.map(|k| k as u32)).collect();
    }

    /// The point whose RVE object holds this point's RVE.
    pub fn object_of(&self, point: usize) -> usize {
        self.keeper.get(point).copied().flatten().map(|k| k as usize).unwrap_or(point)
    }

    /// Groups this step's work: `strain[i]` is the strain point i's RVE takes, None where it does
    /// not step here. Riders whose strain parts from their keeper's, and riders that do not step,
    /// get RVEs of their own.
    pub fn split(&mut self, strain: &[Option<Voigt>]) -> Shared {
        let mut out = Shared::default();
        // Increments that differ only in the sign of a zero make the same RVE order (`order`
        // adds 0.0 to every component), so they share.
        let bits = |e: &Voigt| e.map(|x| (x + 0.0).to_bits());
        // Per (keeper, strain bits) group: its new keeper (the keeper itself when it steps with
        // the same strain, else the group's lowest point).
        let mut groups: BTreeMap<(usize, [u64; 6]), usize> = BTreeMap::new();
        for (k, e) in strain.iter().enumerate() {
            if self.keeper.get(k).copied().flatten().is_none() {
                if let Some(e) = e {
                    groups.insert((k, bits(e)), k);
                }
            }
        }
        for point in 0..self.keeper.len().min(strain.len()) {
            let Some(keeper) = self.keeper[point].map(|k| k as usize) else { continue };
            match &strain[point] {
                None => {
                    out.copies.push((keeper, point));
                    self.keeper[point] = None;
                }
                Some(e) => {
                    let group = *groups.entry((keeper, bits(e))).or_insert(point);
                    if group == point {
                        out.copies.push((keeper, point));
                        self.keeper[point] = None;
                    } else {
                        self.keeper[point] = Some(group as u32);
                    }
                }
            }
        }
        for (point, e) in strain.iter().enumerate() {
            if e.is_none() {
                continue;
            }
            match self.keeper.get(point).copied().flatten() {
                Some(k) => out.riders.push((point, k as usize)),
                None => out.steppers.push(point),
            }
        }
        out
    }

    /// Before `point`'s own RVE object is read or stepped alone: the copy (from, to) that makes
    /// it current, if it rides.
    pub fn own(&mut self, point: usize) -> Option<(usize, usize)> {
        let keeper = self.keeper.get_mut(point)?.take()?;
        Some((keeper as usize, point))
    }

    /// Before `point`'s RVE object is replaced or dropped: its riders get a new keeper, the
    /// lowest of them, which needs a copy of the RVE (returned: from, to); a rider stops riding.
    pub fn detach(&mut self, point: usize) -> Option<(usize, usize)> {
        if point >= self.keeper.len() {
            return None;
        }
        if self.keeper[point].take().is_some() {
            return None;
        }
        let mut new_keeper: Option<usize> = None;
        for k in 0..self.keeper.len() {
            if self.keeper[k] == Some(point as u32) {
                match new_keeper {
                    None => {
                        new_keeper = Some(k);
                        self.keeper[k] = None;
                    }
                    Some(n) => self.keeper[k] = Some(n as u32),
                }
            }
        }
        new_keeper.map(|n| (point, n))
    }

    /// Points removed: keep those whose flag is true (detach the others first).
    pub fn retain(&mut self, keep: &[bool]) {
        let mut new_index = Vec::with_capacity(keep.len());
        let mut next = 0u32;
        for &k in keep {
            new_index.push(next);
            next += u32::from(k);
        }
        let mut k = keep.iter();
        self.keeper.retain(|_| *k.next().unwrap_or(&true));
        for kp in self.keeper.iter_mut().flatten() {
            *kp = new_index[*kp as usize];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const A: Voigt = [1e-6, 0.0, 0.0, 0.0, 0.0, 0.0];
    const B: Voigt = [2e-6, 0.0, 0.0, 0.0, 0.0, 0.0];

    #[test]
    fn copies_of_the_prepared_sample_step_once_until_their_strains_part() {
        let mut t = Twins::default();
        t.add(&[true, true, false, true], true);
        let same = t.split(&[Some(A), Some(A), None, Some(A)]);
        assert_eq!(same, Shared { copies: vec![], steppers: vec![0], riders: vec![(1, 0), (3, 0)] });
        // Point 3 parts: it gets a copy of point 0's RVE before anything steps.
        let parted = t.split(&[Some(A), Some(A), None, Some(B)]);
        assert_eq!(parted, Shared { copies: vec![(0, 3)], steppers: vec![0, 3], riders: vec![(1, 0)] });
        assert_eq!(t.object_of(1), 0);
        assert_eq!(t.object_of(3), 3);
    }

    #[test]
    fn a_keeper_that_does_not_step_hands_its_rve_to_its_riders() {
        let mut t = Twins::default();
        t.add(&[true, true, true], true);
        let s = t.split(&[None, Some(B), Some(B)]);
        assert_eq!(s, Shared { copies: vec![(0, 1)], steppers: vec![1], riders: vec![(2, 1)] });
        assert_eq!(t.detach(1), Some((1, 2)));
        assert_eq!((t.object_of(1), t.object_of(2)), (1, 2));
        t.add(&[true, true], true);
        assert_eq!(t.own(4), Some((3, 4)));
        assert_eq!(t.own(3), None);
    }

    #[test]
    fn without_sharing_every_point_steps_its_own() {
        let mut t = Twins::default();
        t.add(&[true, true], false);
        assert_eq!(t.split(&[Some(A), Some(A)]).steppers, vec![0, 1]);
    }

    #[test]
    fn removal_renumbers_keepers() {
        let mut t = Twins::default();
        t.add(&[true, true, true, true], true);
        t.split(&[Some(A), Some(B), Some(B), Some(A)]);
        // Point 0 is removed: it hands its RVE to point 3 first.
        assert_eq!(t.detach(0), Some((0, 3)));
        t.retain(&[false, true, true, true]);
        assert_eq!((t.object_of(0), t.object_of(1), t.object_of(2)), (0, 0, 2));
    }
}
