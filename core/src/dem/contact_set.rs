//! Every contact of a DEM simulation in one place: the law table (which law a pair of materials
//! gets) and the five candidate lists, one for each pairing of what meets (sphere–sphere,
//! sphere–wall, body–body, body–wall, body–sphere, a body being of a plugin kind). Law changes,
//! layout, validation, save/load, energy booking and inspection walk [`ContactSet::lists`]; the
//! spheres' contact stage keeps its own hot loop over the first two.

use crate::dem::contacts::PairList;
use crate::dem::rigid::LawContact;
use crate::ext::ContactLaw;
use crate::math::Vec3;
use std::collections::HashMap;
use std::sync::Arc;

/// What a candidate list pairs: its first members are spheres or bodies of a plugin kind, its
/// second members spheres, walls or bodies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pairing {
    SphereSphere,
    SphereWall,
    BodyBody,
    BodyWall,
    BodySphere,
}

/// What a member of a pair is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MemberKind {
    Sphere,
    Wall,
    Body,
}

impl Pairing {
    /// The lists in their order in the set (and in saved states and inspection).
    pub const ALL: [Pairing; 5] =
        [Pairing::SphereSphere, Pairing::SphereWall, Pairing::BodyBody, Pairing::BodyWall, Pairing::BodySphere];

    /// The list's name in messages.
    pub fn name(self) -> &'static str {
        match self {
            Pairing::SphereSphere => "pairs",
            Pairing::SphereWall => "wall pairs",
            Pairing::BodyBody => "body pairs",
            Pairing::BodyWall => "body-wall pairs",
            Pairing::BodySphere => "body-sphere pairs",
        }
    }

    pub fn first(self) -> MemberKind {
        match self {
            Pairing::SphereSphere | Pairing::SphereWall => MemberKind::Sphere,
            _ => MemberKind::Body,
        }
    }

    pub fn second(self) -> MemberKind {
        match self {
            Pairing::SphereSphere | Pairing::BodySphere => MemberKind::Sphere,
            Pairing::SphereWall | Pairing::BodyWall => MemberKind::Wall,
            Pairing::BodyBody => MemberKind::Body,
        }
    }

    /// Index of a body list among the three the bodies' stage fills (None for the spheres').
    pub(crate) fn body_list(self) -> Option<usize> {
        match self {
            Pairing::BodyBody => Some(0),
            Pairing::BodyWall => Some(1),
            Pairing::BodySphere => Some(2),
            _ => None,
        }
    }
}

/// The contact laws and every candidate pair with its law, parameters, history and last force.
#[derive(Clone, Default)]
pub struct ContactSet {
    /// Contact laws; `law_of` maps a material pair to one of them, `default_law` covers the rest.
    pub laws: Vec<Arc<dyn ContactLaw>>,
    pub law_of: HashMap<(u16, u16), u16>,
    pub default_law: Option<u16>,
    /// Sphere pairs, stored under the larger index first (`a > b`, or a sphere with its own image).
    pub spheres: PairList,
    pub sphere_walls: PairList,
    pub bodies: PairList,
    pub body_walls: PairList,
    pub body_spheres: PairList,
    /// The touching contacts the bodies' stage found in the last step in each body list (body
    /// pairs, walls, spheres), in pair order, with their contact points: what the energy
    /// booking and the measures read of them (a body's geometry is its plugin's, so the step's
    /// is kept rather than computed again).
    pub(crate) body_touches: [Vec<(LawContact, Vec3)>; 3],
}

impl ContactSet {
    pub fn list(&self, pairing: Pairing) -> &PairList {
        match pairing {
            Pairing::SphereSphere => &self.spheres,
            Pairing::SphereWall => &self.sphere_walls,
            Pairing::BodyBody => &self.bodies,
            Pairing::BodyWall => &self.body_walls,
            Pairing::BodySphere => &self.body_spheres,
        }
    }

    pub fn list_mut(&mut self, pairing: Pairing) -> &mut PairList {
        match pairing {
            Pairing::SphereSphere => &mut self.spheres,
            Pairing::SphereWall => &mut self.sphere_walls,
            Pairing::BodyBody => &mut self.bodies,
            Pairing::BodyWall => &mut self.body_walls,
            Pairing::BodySphere => &mut self.body_spheres,
        }
    }

    /// The five lists with what they pair, in [`Pairing::ALL`]'s order.
    pub fn lists(&self) -> [(Pairing, &PairList); 5] {
        Pairing::ALL.map(|p| (p, self.list(p)))
    }

    /// The lists taken out (left empty), to change several at once beside the rest of the set.
    pub(crate) fn take_lists(&mut self) -> [PairList; 5] {
        Pairing::ALL.map(|p| std::mem::take(self.list_mut(p)))
    }

    /// Puts back lists taken by [`ContactSet::take_lists`].
    pub(crate) fn put_lists(&mut self, lists: [PairList; 5]) {
        for (p, list) in Pairing::ALL.into_iter().zip(lists) {
            *self.list_mut(p) = list;
        }
    }

    /// The three body lists taken out, in the order the bodies' stage fills them.
    pub(crate) fn take_body_lists(&mut self) -> [PairList; 3] {
        [std::mem::take(&mut self.bodies), std::mem::take(&mut self.body_walls), std::mem::take(&mut self.body_spheres)]
    }

    pub(crate) fn put_body_lists(&mut self, [bodies, walls, spheres]: [PairList; 3]) {
        (self.bodies, self.body_walls, self.body_spheres) = (bodies, walls, spheres);
    }

    /// Each list's history: what the energy booking compares a step's with.
    pub(crate) fn histories(&self) -> [Vec<f64>; 5] {
        Pairing::ALL.map(|p| self.list(p).history.clone())
    }

    /// Contacts touching in the last step, in every list.
    pub fn touching_count(&self) -> usize {
        self.lists().iter().map(|(_, l)| l.touching_count()).sum()
    }

    /// Touching contacts of the bodies of plugin kinds (with one another, walls and spheres).
    pub fn body_touching_count(&self) -> usize {
        self.bodies.touching_count() + self.body_walls.touching_count() + self.body_spheres.touching_count()
    }

    /// The law of a pair of materials: its own, else the default one.
    pub fn law_for(&self, a: u16, b: u16) -> Option<u16> {
        self.law_of.get(&(a.min(b), a.max(b))).copied().or(self.default_law)
    }

    /// Values per pair (parameters, history) the lists are laid out for: the most any law keeps
    /// (at least one of each), so that pairs of different laws share one list.
    pub fn pair_strides(&self) -> (usize, usize) {
        let most = |count: fn(&Arc<dyn ContactLaw>) -> usize| self.laws.iter().map(count).max().unwrap_or(0).max(1);
        (most(|l| l.param_count()), most(|l| l.history_count()))
    }

    /// Bytes the lists hold.
    pub fn memory_bytes(&self) -> usize {
        self.lists().iter().map(|(_, l)| list_bytes(l)).sum()
    }

    /// What a step relies on in lists read from a file: array lengths that agree, indices within
    /// `spheres`, `walls` and `bodies`, laws of the table with their values laid out, pairs sorted
    /// without repeats, sphere pairs stored under their larger index.
    pub(crate) fn check(&self, spheres: usize, walls: usize, bodies: usize) -> std::result::Result<(), String> {
        use crate::loaded::same_length;
        let laws = self.laws.len();
        if self.default_law.is_some_and(|l| l as usize >= laws) || self.law_of.values().any(|&l| l as usize >= laws) {
            return Err(format!("a material pair uses a contact law beyond the {laws} saved"));
        }
        let count = |m: MemberKind| match m {
            MemberKind::Sphere => spheres,
            MemberKind::Wall => walls,
            MemberKind::Body => bodies,
        };
        for (pairing, list) in self.lists() {
            let name = pairing.name();
            let beyond = match pairing.first() {
                MemberKind::Sphere => format!("the {spheres} spheres or {walls} walls"),
                _ => format!("the {bodies} bodies, {spheres} spheres or {walls} walls"),
            };
            let m = list.len();
            let lengths = [
                ("b", list.b.len()),
                ("shift", list.shift.len()),
                ("law", list.law.len()),
                ("touching", list.touching.len()),
                ("force", list.force.len()),
            ];
            same_length(name, "a", m, &lengths)?;
            if !list.part.is_empty() {
                same_length(name, "a", m, &[("part", list.part.len())])?;
            }
            let (firsts, others) = (count(pairing.first()), count(pairing.second()));
            if list.a.iter().any(|&i| i as usize >= firsts) || list.b.iter().any(|&j| j as usize >= others) {
                return Err(format!("{name}: an index beyond {beyond}"));
            }
            if let Some(&l) = list.law.iter().find(|&&l| l as usize >= laws) {
                return Err(format!("{name}: contact law {l} of {laws}"));
            }
            let (ps, hs) = (list.param_stride, list.history_stride);
            let keeps_more = |&l: &u16| {
                let law = &self.laws[l as usize];
                law.param_count() > ps || law.history_count() > hs
            };
            if list.law.iter().any(keeps_more) {
                return Err(format!("{name}: {ps} parameters and {hs} history values a pair, fewer than a law keeps"));
            }
            if list.params.len() != m * ps || list.history.len() != m * hs {
                return Err(format!(
                    "{name}: {} parameters and {} history values for {m} pairs of {ps} and {hs}",
                    list.params.len(),
                    list.history.len()
                ));
            }
            if (1..m).any(|k| list.key_of(k - 1) >= list.key_of(k)) {
                return Err(format!("{name}: not sorted by (first, second, image, point) without repeats"));
            }
        }
        // The force sums' order rests on it (see `step::write_back`). A sphere meets its own image
        // in a thin cell (under a positive shift when found, under any after a flip until the
        // next rebuild).
        let p = &self.spheres;
        if let Some(k) = (0..p.len()).find(|&k| p.a[k] < p.b[k] || (p.a[k] == p.b[k] && p.shift[k] == [0; 3])) {
            return Err(format!("pairs: pair {k} has a first sphere below its second, or is a sphere with itself"));
        }
        Ok(())
    }
}

/// Bytes a pair list holds.
pub(crate) fn list_bytes(p: &PairList) -> usize {
    p.a.capacity() * (2 * 4 + 12 + 2 + 1 + 24) + (p.params.capacity() + p.history.capacity()) * 8
}
