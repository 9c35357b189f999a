//! Contact physics of a pair (YADE's `Ip2` functors): which contact law a pair of materials gets,
//! the per-pair values it is laid out for, the pair's `PairInfo` (radii, masses, elastic moduli, a
//! seed drawn from the two ids) its law sets its parameters from, and new candidate pairs merged
//! into a list with their law and parameters. Geometry (`contact_stage.rs`, a body kind's) and the
//! laws themselves (`ext::ContactLaw`) are apart from it.

use crate::dem::broad_phase::Candidate;
use crate::dem::contacts::PairList;
use crate::dem::sim::DemWorld;
use crate::error::GraniteError;
use crate::ext::{ContactLaw, PairInfo};
use std::sync::Arc;

/// The bodies a pair list joins: the first bodies' materials, what the second bodies are, and
/// whether the merge may run in parallel.
pub(crate) struct PairBodies<'a> {
    pub material: &'a [u16],
    pub other: Other<'a>,
    pub parallel: bool,
}

/// The second bodies of a pair list.
#[derive(Clone, Copy)]
pub(crate) enum Other<'a> {
    /// Bodies of the first ones' set.
    Same,
    /// The simulation's walls.
    Walls,
    /// Bodies of another set, of these materials (spheres met by bodies of a plugin kind).
    Of(&'a [u16]),
}

impl DemWorld {
    /// Values per pair (parameters, history) the pair lists are laid out for: the most any law
    /// keeps (at least one of each), so that pairs of different laws share one list.
    pub fn pair_strides(&self) -> (usize, usize) {
        let most = |count: fn(&Arc<dyn ContactLaw>) -> usize| self.laws.iter().map(count).max().unwrap_or(0).max(1);
        (most(|l| l.param_count()), most(|l| l.history_count()))
    }

    /// The law index a key uses: a material pair's own law or, with None, the default law.
    pub fn law_index(&self, pair: Option<(u16, u16)>) -> Option<u16> {
        match pair {
            Some((a, b)) => self.law_for(a, b),
            None => self.default_law,
        }
    }

    /// Gives every candidate pair, of spheres and of bodies of plugin kinds alike, the law of its
    /// two materials now and sets its parameters again from that law. A pair whose law keeps its
    /// kind (same name and history as in `old_laws`) keeps its history (and a body geometry's warm
    /// starts, which follow the law's values); another starts its law's history afresh. The pair
    /// lists are laid out again when the laws need more values per pair.
    pub(crate) fn refresh_pair_laws(&mut self, old_laws: &[Arc<dyn ContactLaw>]) {
        let (ps, hs) = self.pair_strides();
        let warm = self.kinds.warm_values();
        let k = &mut self.kinds;
        let mut lists = [
            std::mem::take(&mut self.pairs),
            std::mem::take(&mut self.wall_pairs),
            std::mem::take(&mut k.pairs),
            std::mem::take(&mut k.wall_pairs),
            std::mem::take(&mut k.sphere_pairs),
        ];
        let (s, k) = (&self.spheres, &self.kinds);
        let sides = [
            (&s.material, Other::Of(&s.material), 0),
            (&s.material, Other::Walls, 0),
            (&k.material, Other::Same, warm),
            (&k.material, Other::Walls, warm),
            (&k.material, Other::Of(&s.material), warm),
        ];
        let mut lost = false;
        for (n, (list, &(first, other, warm))) in lists.iter_mut().zip(&sides).enumerate() {
            if list.is_empty() {
                list.param_stride = ps;
                list.history_stride = hs + warm;
                continue;
            }
            list.relayout_with_warm(ps, hs, warm);
            let hs_list = list.history_stride;
            for p in 0..list.len() {
                let (a, b) = (list.a[p] as usize, list.b[p] as usize);
                let mb = match other {
                    Other::Same => first[b],
                    Other::Walls => self.walls[b].material,
                    Other::Of(materials) => materials[b],
                };
                let Some(law) = self.law_for(first[a], mb) else {
                    // No law for this pair any more: the next rebuild says so.
                    lost = true;
                    continue;
                };
                let same_kind = old_laws.get(list.law[p] as usize).is_some_and(|old| {
                    let new = &self.laws[law as usize];
                    old.name() == new.name() && old.history_count() == new.history_count()
                });
                list.law[p] = law;
                let info = match n {
                    0 => self.info_for(a, b, false),
                    1 => self.info_for(a, b, true),
                    _ => self.kind_info(a, b, other),
                };
                let params = &mut list.params[p * ps..(p + 1) * ps];
                params.fill(0.0);
                self.laws[law as usize].init_pair(&info, params);
                if !same_kind {
                    list.history[p * hs_list..p * hs_list + hs].fill(0.0);
                    list.touching[p] = false;
                }
            }
        }
        let [spheres, walls, bodies, body_walls, body_spheres] = lists;
        (self.pairs, self.wall_pairs) = (spheres, walls);
        let k = &mut self.kinds;
        (k.pairs, k.wall_pairs, k.sphere_pairs) = (bodies, body_walls, body_spheres);
        // The spare list is storage for the next rebuild: its layout is set there.
        self.needs_rebuild |= lost;
    }

    /// The law of a pair of materials: its own, else the default one.
    pub fn law_for(&self, a: u16, b: u16) -> Option<u16> {
        self.law_of.get(&(a.min(b), a.max(b))).copied().or(self.default_law)
    }

    /// [`PairList::merge`] with each new pair given the law of its bodies' materials and its
    /// parameters from `info`; returns a pair of materials without a contact law, if it met one.
    pub(crate) fn merge_with_laws(
        &self,
        list: &mut PairList,
        spare: &mut PairList,
        pieces: &[&[Candidate]],
        strides: (usize, usize),
        bodies: PairBodies<'_>,
        info: impl Fn(usize, usize) -> crate::ext::PairInfo + Sync,
    ) -> Option<(u16, u16)> {
        let PairBodies { material, other, parallel } = bodies;
        let materials = |a: usize, b: usize| {
            let second = match other {
                Other::Same => material[b],
                Other::Walls => self.walls[b].material,
                Other::Of(materials) => materials[b],
            };
            (material[a], second)
        };
        let missing = list.merge(spare, pieces, strides, parallel, |a, b, law, params| {
            let (a, b) = (a as usize, b as usize);
            let pair = materials(a, b);
            let Some(l) = self.law_for(pair.0, pair.1) else { return false };
            *law = l;
            self.laws[l as usize].init_pair(&info(a, b), params);
            true
        });
        missing.map(|(a, b)| materials(a as usize, b as usize))
    }

    /// The error of a pair of materials without a contact law.
    pub(crate) fn missing_law(&self, (a, b): (u16, u16)) -> GraniteError {
        let name = |m: u16| self.materials.get(m as usize).map(|m| m.name.clone()).unwrap_or_default();
        GraniteError::Setup(format!(
            "no contact law for materials \"{}\" and \"{}\": give a default law or one for this pair",
            name(a),
            name(b)
        ))
    }

    /// Info for spheres `i` and `j` (None: `i` against a rigid, infinitely large body).
    pub(crate) fn pair_info(&self, i: usize, j: Option<usize>) -> PairInfo {
        let s = &self.spheres;
        let (r2, m2, id2) = match j {
            Some(j) => (s.radius[j], s.mass[j], s.id[j]),
            None => (f64::INFINITY, f64::INFINITY, u64::MAX),
        };
        let (lo, hi) = (s.id[i].min(id2), s.id[i].max(id2));
        let seed = crate::ext::contact::uniform(self.seed ^ lo.wrapping_mul(0x100_0000_01B3), hi).to_bits();
        let elastic = |m: u16| self.materials.get(m as usize).and_then(|m| m.elastic);
        let e2 = j.and_then(|j| elastic(s.material[j]));
        PairInfo { radius: [s.radius[i], r2], mass: [s.mass[i], m2], seed, elastic: [elastic(s.material[i]), e2] }
    }

    /// Info for a sphere-sphere pair or, with `wall` set, a sphere-wall pair.
    pub fn info_for(&self, i: usize, j: usize, wall: bool) -> PairInfo {
        if wall {
            let mut info = self.pair_info(i, None);
            info.seed ^= (j as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
            info.elastic[1] = self.materials.get(self.walls[j].material as usize).and_then(|m| m.elastic);
            info
        } else {
            self.pair_info(i, Some(j))
        }
    }
}
