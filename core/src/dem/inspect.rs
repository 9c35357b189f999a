//! Contacts as a user inspects them between two steps (YADE's `O.interactions`), of every
//! pairing in the contact set: those touching in the last step, with its forces, the law and its
//! values for the pair, and their geometry: a sphere pair's of the present positions (found again
//! from the centres), a body's as its kind's geometry found it in the last step (found again
//! where the bodies are in a state loaded before its first step).

use crate::dem::contact_set::{MemberKind, Pairing};
use crate::dem::contact_stage::branch;
use crate::dem::kind_stage::{BodyContacts, Surroundings};
use crate::dem::rigid::LawContact;
use crate::dem::sim::DemWorld;
use crate::math::Vec3;
use std::borrow::Cow;

/// A member of a contact: a sphere, a wall or a body of a plugin kind, by index.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Member {
    Sphere(usize),
    Wall(usize),
    Body(usize),
}

impl Member {
    fn of(kind: MemberKind, index: usize) -> Member {
        match kind {
            MemberKind::Sphere => Member::Sphere(index),
            MemberKind::Wall => Member::Wall(index),
            MemberKind::Body => Member::Body(index),
        }
    }
}

/// One touching contact. `normal` points from the first member towards the other; `force` is
/// the force on the first member (the other gets its opposite).
#[derive(Debug, Clone)]
pub struct ContactView {
    /// The list the contact is in.
    pub pairing: Pairing,
    /// A sphere or a body.
    pub first: Member,
    pub other: Member,
    /// Periodic image of the other member (zero without a periodic cell).
    pub shift: [i32; 3],
    /// Which of the pair's contact points this is, where its members meet at several (a
    /// capsule's two ends on a wall); 0 otherwise.
    pub part: u8,
    pub point: Vec3,
    pub normal: Vec3,
    /// Positive when the members overlap.
    pub overlap: f64,
    pub force: Vec3,
    /// Normal force, positive in compression (the members pushed apart): `-force . normal`.
    pub normal_force: f64,
    /// Part of `force` in the contact plane.
    pub shear_force: Vec3,
    /// Index of the contact law in the contact set's `laws`.
    pub law: u16,
    /// The law's values for this pair (`ContactLaw::init_pair`).
    pub params: Vec<f64>,
}

impl ContactView {
    /// The same contact seen from its other member.
    fn turned(mut self) -> ContactView {
        std::mem::swap(&mut self.first, &mut self.other);
        self.normal = self.normal.map(|n| -n);
        self.force = self.force.map(|f| -f);
        self.shear_force = self.shear_force.map(|f| -f);
        self
    }
}

fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl DemWorld {
    /// Every contact touching in the last step, list by list in [`Pairing::ALL`]'s order
    /// (sphere pairs, sphere-wall, body pairs, body-wall, body-sphere), each in pair order.
    pub fn touching_contacts(&self) -> Vec<ContactView> {
        self.touching_of(&Pairing::ALL)
    }

    /// The contacts touching in the last step of the lists of `pairings`, in their order.
    fn touching_of(&self, pairings: &[Pairing]) -> Vec<ContactView> {
        let mut out = Vec::new();
        let bodies = self.body_touches();
        for &pairing in pairings {
            let list = self.contacts.list(pairing);
            match pairing.body_list() {
                None => out.extend((0..list.len()).filter(|&k| list.touching[k]).map(|k| self.sphere_view(pairing, k))),
                Some(n) => out.extend(
                    bodies[n]
                        .iter()
                        .filter(|(c, _)| list.touching[c.slot])
                        .map(|&(c, point)| self.view(pairing, c.slot, point, c.normal, c.overlap)),
                ),
            }
        }
        out
    }

    /// The bodies' touches of the last step, or, in a state loaded before its first step (whose
    /// touches are not saved), found again by their geometries where the bodies are.
    fn body_touches(&self) -> Cow<'_, [Vec<(LawContact, Vec3)>; 3]> {
        let c = &self.contacts;
        let lists = [&c.bodies, &c.body_walls, &c.body_spheres];
        if (0..3).all(|n| c.body_touches[n].len() == lists[n].touching_count()) {
            return Cow::Borrowed(&c.body_touches);
        }
        let around = self.surroundings();
        BodyContacts::touches_now(&self.kinds, c, &around).map_or(Cow::Borrowed(&c.body_touches), Cow::Owned)
    }

    /// What the bodies' geometries read besides the bodies.
    fn surroundings(&self) -> Surroundings<'_> {
        Surroundings {
            spheres: &self.spheres,
            walls: &self.walls,
            laws: &self.contacts.laws,
            cell: self.cell.as_ref(),
            law_history: self.pair_strides().1,
            dt: self.dt,
            step: self.step,
            time: self.time,
        }
    }

    /// The touching contact between spheres `i` and `j` (indices), if any, seen from `i`.
    pub fn contact_between(&self, i: usize, j: usize) -> Option<ContactView> {
        let (a, b) = (i.max(j) as u32, i.min(j) as u32);
        let p = &self.contacts.spheres;
        let start = crate::math::partition_index(0..p.len(), |k| (p.a[k], p.b[k]) < (a, b));
        (start..p.len()).take_while(|&k| (p.a[k], p.b[k]) == (a, b)).find(|&k| p.touching[k]).map(|k| {
            let c = self.sphere_view(Pairing::SphereSphere, k);
            if c.first == Member::Sphere(i) {
                c
            } else {
                c.turned()
            }
        })
    }

    /// The touching contact between sphere `i` and wall `w`, if any.
    pub fn wall_contact_of(&self, i: usize, w: usize) -> Option<ContactView> {
        let p = &self.contacts.sphere_walls;
        (0..p.len())
            .find(|&k| p.touching[k] && p.a[k] as usize == i && p.b[k] as usize == w)
            .map(|k| self.sphere_view(Pairing::SphereWall, k))
    }

    /// The touching contacts of body `i` (with bodies, walls and spheres), each seen from it.
    pub fn body_contacts_of(&self, i: usize) -> Vec<ContactView> {
        let me = Member::Body(i);
        let lists = [Pairing::BodyBody, Pairing::BodyWall, Pairing::BodySphere];
        let contacts = self.touching_of(&lists).into_iter().filter(|c| c.first == me || c.other == me);
        contacts.map(|c| if c.first == me { c } else { c.turned() }).collect()
    }

    fn view(&self, pairing: Pairing, k: usize, point: Vec3, normal: Vec3, overlap: f64) -> ContactView {
        let p = self.contacts.list(pairing);
        let force = p.force[k];
        let fn_along = dot(force, normal);
        let shear_force = [0, 1, 2].map(|a| force[a] - fn_along * normal[a]);
        let law = p.law[k];
        let count = self.contacts.laws.get(law as usize).map_or(0, |l| l.param_count());
        let ps = p.param_stride;
        ContactView {
            pairing,
            first: Member::of(pairing.first(), p.a[k] as usize),
            other: Member::of(pairing.second(), p.b[k] as usize),
            shift: p.shift[k],
            part: p.part_of(k),
            point,
            normal,
            overlap,
            force,
            normal_force: -fn_along,
            shear_force,
            law,
            params: p.params[k * ps..k * ps + count.min(ps)].to_vec(),
        }
    }

    /// A contact of a sphere list, its geometry from where the spheres are now.
    fn sphere_view(&self, pairing: Pairing, k: usize) -> ContactView {
        let s = &self.spheres;
        if pairing == Pairing::SphereSphere {
            let (n, overlap, la, _) = self.pair_geometry(&s.x, k);
            let i = self.contacts.spheres.a[k] as usize;
            let point = [0, 1, 2].map(|a| s.x[i][a] + la * n[a]);
            return self.view(pairing, k, point, n, overlap);
        }
        let p = &self.contacts.sphere_walls;
        let (i, w) = (p.a[k] as usize, p.b[k] as usize);
        match self.walls[w].contact(s.x[i], s.radius[i], f64::INFINITY) {
            Some(g) => self.view(pairing, k, g.point, g.normal, -g.gap),
            None => self.view(pairing, k, s.x[i], [0.0; 3], f64::NAN),
        }
    }

    /// The geometry of sphere pair `k` at positions `x`, as the contact stage makes it: unit
    /// normal from the first sphere to the second, overlap, and the lever arms `(la, lb)` from each
    /// centre to the contact point.
    pub(crate) fn pair_geometry(&self, x: &[Vec3], k: usize) -> (Vec3, f64, f64, f64) {
        let (i, j) = (self.contacts.spheres.a[k] as usize, self.contacts.spheres.b[k] as usize);
        let r = &self.spheres.radius;
        let d = branch(x, i, j, self.contacts.spheres.shift[k], self.cell.as_ref());
        let dist = dot(d, d).sqrt();
        let n = if dist > 0.0 { d.map(|c| c / dist) } else { [0.0; 3] };
        let overlap = r[i] + r[j] - dist;
        let la = r[i] - 0.5 * overlap;
        (n, overlap, la, dist - la)
    }

    /// Pairs of spheres, bodies of plugin kinds and walls whose overlap exceeds `fraction` of the
    /// smaller radius (of the sphere's or body's, for a wall; a body's is the radius of the sphere
    /// of its volume), from the candidate lists as they are (after a rebuild): `(description,
    /// overlap / radius)`, deepest first, at most `most`. A packing made by hand with such
    /// overlaps starts with forces it was never meant to have.
    pub fn deep_overlaps(&self, fraction: f64, most: usize) -> Vec<(String, f64)> {
        let s = &self.spheres;
        let mut found: Vec<(String, f64)> = Vec::new();
        for k in 0..self.contacts.spheres.len() {
            let (i, j) = (self.contacts.spheres.a[k] as usize, self.contacts.spheres.b[k] as usize);
            let (_, overlap, _, _) = self.pair_geometry(&s.x, k);
            let depth = overlap / s.radius[i].min(s.radius[j]);
            if depth > fraction {
                found.push((format!("spheres {} and {}", s.id[i], s.id[j]), depth));
            }
        }
        for k in 0..self.contacts.sphere_walls.len() {
            let (i, w) = (self.contacts.sphere_walls.a[k] as usize, self.contacts.sphere_walls.b[k] as usize);
            if let Some(g) = self.walls[w].contact(s.x[i], s.radius[i], f64::INFINITY) {
                let depth = -g.gap / s.radius[i];
                if depth > fraction {
                    found.push((format!("sphere {} and wall {w} (\"{}\")", s.id[i], self.walls[w].name), depth));
                }
            }
        }
        found.extend(self.deep_body_overlaps(fraction));
        found.sort_by(|a, b| b.1.total_cmp(&a.1));
        found.truncate(most);
        found
    }

    /// [`DemWorld::deep_overlaps`] of the bodies of plugin kinds (none where their geometry fails:
    /// the step reports why).
    fn deep_body_overlaps(&self, fraction: f64) -> Vec<(String, f64)> {
        let k = &self.kinds;
        let around = self.surroundings();
        let Ok(lists) = BodyContacts::touches_now(k, &self.contacts, &around) else { return Vec::new() };
        let body = |i: usize| format!("{} {}", k.kind_name(i), k.id[i]);
        let mut found = Vec::new();
        let c = &self.contacts;
        for (n, (list, touching)) in [&c.bodies, &c.body_walls, &c.body_spheres].into_iter().zip(lists).enumerate() {
            for (contact, _) in touching {
                let (pair, overlap) = (contact.slot, contact.overlap);
                let (i, j) = (list.a[pair] as usize, list.b[pair] as usize);
                let (what, radius) = match n {
                    0 => (format!("{} and {}", body(i), body(j)), k.equivalent_radius(i).min(k.equivalent_radius(j))),
                    1 => (format!("{} and wall {j} (\"{}\")", body(i), self.walls[j].name), k.equivalent_radius(i)),
                    _ => (
                        format!("{} and sphere {}", body(i), self.spheres.id[j]),
                        k.equivalent_radius(i).min(self.spheres.radius[j]),
                    ),
                };
                if overlap / radius > fraction {
                    found.push((what, overlap / radius));
                }
            }
        }
        found
    }

    /// Fabric tensor of the sphere contacts, `(1/N) sum n n^T` over the N contacts touching in the
    /// last step (Oda 1982): symmetric, trace 1; one third of the identity for an isotropic
    /// network. Zero without contacts.
    pub fn fabric_tensor(&self) -> [[f64; 3]; 3] {
        let mut f = [[0.0; 3]; 3];
        let mut count = 0usize;
        for k in 0..self.contacts.spheres.len() {
            if !self.contacts.spheres.touching[k] {
                continue;
            }
            let n = self.pair_geometry(&self.spheres.x, k).0;
            for (a, row) in f.iter_mut().enumerate() {
                for (b, entry) in row.iter_mut().enumerate() {
                    *entry += n[a] * n[b];
                }
            }
            count += 1;
        }
        if count > 0 {
            for row in f.iter_mut() {
                for entry in row.iter_mut() {
                    *entry /= count as f64;
                }
            }
        }
        f
    }
}
