//! Contact physics of a pair (YADE's `Ip2` functors): which contact law a pair of materials gets,
//! the per-pair values it is laid out for, the pair's `PairInfo` (radii, masses, elastic moduli, a
//! seed drawn from the two ids) its law sets its parameters from, and new candidate pairs merged
//! into a list with their law and parameters. Geometry (`contact_stage.rs`, a body kind's) and the
//! laws themselves (`ext::ContactLaw`) are apart from it.

use crate::dem::contact_set::{MemberKind, Pairing};
use crate::dem::contacts::{PairKey, PairList};
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
    /// Values per pair (parameters, history) the pair lists are laid out for (see
    /// [`ContactSet::pair_strides`]).
    pub fn pair_strides(&self) -> (usize, usize) {
        self.contacts.pair_strides()
    }

    /// The law index a key uses: a material pair's own law or, with None, the default law.
    pub fn law_index(&self, pair: Option<(u16, u16)>) -> Option<u16> {
        match pair {
            Some((a, b)) => self.law_for(a, b),
            None => self.contacts.default_law,
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
        let mut lists = self.contacts.take_lists();
        let mut lost = false;
        for (list, pairing) in lists.iter_mut().zip(Pairing::ALL) {
            // Body lists keep their geometry's warm starts after the law's values.
            let warm = if pairing.first() == MemberKind::Body { warm } else { 0 };
            if list.is_empty() {
                list.param_stride = ps;
                list.history_stride = hs + warm;
                continue;
            }
            list.relayout_with_warm(ps, hs, warm);
            let hs_list = list.history_stride;
            for p in 0..list.len() {
                let (a, b) = (list.a[p] as usize, list.b[p] as usize);
                let (ma, mb) = self.pair_materials(pairing, a, b);
                let Some(law) = self.law_for(ma, mb) else {
                    // No law for this pair any more: the next rebuild says so.
                    lost = true;
                    continue;
                };
                let same_kind = old_laws.get(list.law[p] as usize).is_some_and(|old| {
                    let new = &self.contacts.laws[law as usize];
                    old.name() == new.name() && old.history_count() == new.history_count()
                });
                list.law[p] = law;
                let info = self.pairing_info(pairing, a, b);
                let params = &mut list.params[p * ps..(p + 1) * ps];
                params.fill(0.0);
                self.contacts.laws[law as usize].init_pair(&info, params);
                if !same_kind {
                    list.history[p * hs_list..p * hs_list + hs].fill(0.0);
                    list.touching[p] = false;
                }
            }
        }
        self.contacts.put_lists(lists);
        // The spare list is storage for the next rebuild: its layout is set there.
        self.needs_rebuild |= lost;
    }

    /// The materials of the two members of pair `(a, b)` of a list of `pairing`.
    pub(crate) fn pair_materials(&self, pairing: Pairing, a: usize, b: usize) -> (u16, u16) {
        let of = |kind: MemberKind, i: usize| match kind {
            MemberKind::Sphere => self.spheres.material[i],
            MemberKind::Wall => self.walls[i].material,
            MemberKind::Body => self.kinds.material[i],
        };
        (of(pairing.first(), a), of(pairing.second(), b))
    }

    /// What the law of pair `(a, b)` of a list of `pairing` sets its parameters from.
    pub(crate) fn pairing_info(&self, pairing: Pairing, a: usize, b: usize) -> PairInfo {
        match pairing {
            Pairing::SphereSphere => self.info_for(a, b, false),
            Pairing::SphereWall => self.info_for(a, b, true),
            Pairing::BodyBody => self.kind_info(a, b, Other::Same),
            Pairing::BodyWall => self.kind_info(a, b, Other::Walls),
            Pairing::BodySphere => self.kind_info(a, b, Other::Of(&self.spheres.material)),
        }
    }

    /// The law of a pair of materials: its own, else the default one.
    pub fn law_for(&self, a: u16, b: u16) -> Option<u16> {
        self.contacts.law_for(a, b)
    }

    /// [`PairList::merge`] with each new pair given the law of its bodies' materials and its
    /// parameters from `info`; returns a pair of materials without a contact law, if it met one.
    pub(crate) fn merge_with_laws<K: PairKey>(
        &self,
        list: &mut PairList,
        spare: &mut PairList,
        pieces: &[&[K]],
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
            self.contacts.laws[l as usize].init_pair(&info(a, b), params);
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
