//! Contacts as a user inspects them between two steps (YADE's `O.interactions`): geometry of the
//! present positions, forces of the last step, the law and its values for the pair.

use crate::dem::contact_stage::branch;
use crate::dem::kind_stage::{BodyContacts, Surroundings};
use crate::dem::sim::DemWorld;
use crate::math::Vec3;

/// The other body of a contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Other {
    /// A sphere, by index.
    Sphere(usize),
    /// A wall, by index.
    Wall(usize),
}

/// One touching contact. `normal` points from the first sphere towards the other body; `force` is
/// the force on the first sphere (the other gets its opposite).
#[derive(Debug, Clone)]
pub struct ContactView {
    /// Index of the first sphere.
    pub sphere: usize,
    pub other: Other,
    /// Periodic image of the other sphere (zero without a periodic cell).
    pub shift: [i32; 3],
    pub point: Vec3,
    pub normal: Vec3,
    /// Positive when the bodies overlap.
    pub overlap: f64,
    pub force: Vec3,
    /// Normal force, positive in compression (the bodies pushed apart): `-force . normal`.
    pub normal_force: f64,
    /// Part of `force` in the contact plane.
    pub shear_force: Vec3,
    /// Index of the contact law in `DemSim::laws`.
    pub law: u16,
    /// The law's values for this pair (`ContactLaw::init_pair`).
    pub params: Vec<f64>,
}

fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl DemWorld {
    /// Every contact touching in the last step: sphere pairs in list order, then wall contacts.
    pub fn touching_contacts(&self) -> Vec<ContactView> {
        let mut out = Vec::new();
        for k in 0..self.pairs.len() {
            if self.pairs.touching[k] {
                out.push(self.sphere_contact(k));
            }
        }
        for k in 0..self.wall_pairs.len() {
            if self.wall_pairs.touching[k] {
                out.push(self.wall_contact(k));
            }
        }
        out
    }

    /// The touching contact between spheres `i` and `j` (indices), if any.
    pub fn contact_between(&self, i: usize, j: usize) -> Option<ContactView> {
        let (a, b) = (i.max(j) as u32, i.min(j) as u32);
        let p = &self.pairs;
        let start = crate::math::partition_index(0..p.len(), |k| (p.a[k], p.b[k]) < (a, b));
        (start..p.len()).take_while(|&k| (p.a[k], p.b[k]) == (a, b)).find(|&k| p.touching[k]).map(|k| {
            let mut c = self.sphere_contact(k);
            if c.sphere != i {
                // Seen from sphere i: the other side of the same contact.
                c.sphere = i;
                c.other = Other::Sphere(j);
                c.normal = c.normal.map(|n| -n);
                c.force = c.force.map(|f| -f);
                c.shear_force = c.shear_force.map(|f| -f);
            }
            c
        })
    }

    /// The touching contact between sphere `i` and wall `w`, if any.
    pub fn wall_contact_of(&self, i: usize, w: usize) -> Option<ContactView> {
        let p = &self.wall_pairs;
        (0..p.len())
            .find(|&k| p.touching[k] && p.a[k] as usize == i && p.b[k] as usize == w)
            .map(|k| self.wall_contact(k))
    }

    fn view(&self, list_is_walls: bool, k: usize, point: Vec3, normal: Vec3, overlap: f64) -> ContactView {
        let p = if list_is_walls { &self.wall_pairs } else { &self.pairs };
        let force = p.force[k];
        let fn_along = dot(force, normal);
        let shear_force = [0, 1, 2].map(|a| force[a] - fn_along * normal[a]);
        let law = p.law[k];
        let count = self.laws.get(law as usize).map_or(0, |l| l.param_count());
        let ps = p.param_stride;
        ContactView {
            sphere: p.a[k] as usize,
            other: if list_is_walls { Other::Wall(p.b[k] as usize) } else { Other::Sphere(p.b[k] as usize) },
            shift: p.shift[k],
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

    /// The geometry of sphere pair `k` at positions `x`, as the contact stage makes it: unit
    /// normal from the first sphere to the second, overlap, and the lever arms `(la, lb)` from each
    /// centre to the contact point.
    pub(crate) fn pair_geometry(&self, x: &[Vec3], k: usize) -> (Vec3, f64, f64, f64) {
        let (i, j) = (self.pairs.a[k] as usize, self.pairs.b[k] as usize);
        let r = &self.spheres.radius;
        let d = branch(x, i, j, self.pairs.shift[k], self.cell.as_ref());
        let dist = dot(d, d).sqrt();
        let n = if dist > 0.0 { d.map(|c| c / dist) } else { [0.0; 3] };
        let overlap = r[i] + r[j] - dist;
        let la = r[i] - 0.5 * overlap;
        (n, overlap, la, dist - la)
    }

    fn sphere_contact(&self, k: usize) -> ContactView {
        let x = &self.spheres.x;
        let (n, overlap, la, _) = self.pair_geometry(x, k);
        let i = self.pairs.a[k] as usize;
        let point = [0, 1, 2].map(|a| x[i][a] + la * n[a]);
        self.view(false, k, point, n, overlap)
    }

    fn wall_contact(&self, k: usize) -> ContactView {
        let (i, w) = (self.wall_pairs.a[k] as usize, self.wall_pairs.b[k] as usize);
        let s = &self.spheres;
        match self.walls[w].contact(s.x[i], s.radius[i], f64::INFINITY) {
            Some(g) => self.view(true, k, g.point, g.normal, -g.gap),
            None => self.view(true, k, s.x[i], [0.0; 3], f64::NAN),
        }
    }

    /// Pairs of spheres, bodies of plugin kinds and walls whose overlap exceeds `fraction` of the
    /// smaller radius (of the sphere's or body's, for a wall; a body's is the radius of the sphere
    /// of its volume), from the candidate lists as they are (after a rebuild): `(description,
    /// overlap / radius)`, deepest first, at most `most`. A packing made by hand with such
    /// overlaps starts with forces it was never meant to have.
    pub fn deep_overlaps(&self, fraction: f64, most: usize) -> Vec<(String, f64)> {
        let s = &self.spheres;
        let mut found: Vec<(String, f64)> = Vec::new();
        for k in 0..self.pairs.len() {
            let (i, j) = (self.pairs.a[k] as usize, self.pairs.b[k] as usize);
            let (_, overlap, _, _) = self.pair_geometry(&s.x, k);
            let depth = overlap / s.radius[i].min(s.radius[j]);
            if depth > fraction {
                found.push((format!("spheres {} and {}", s.id[i], s.id[j]), depth));
            }
        }
        for k in 0..self.wall_pairs.len() {
            let (i, w) = (self.wall_pairs.a[k] as usize, self.wall_pairs.b[k] as usize);
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
        let around = Surroundings {
            spheres: &self.spheres,
            walls: &self.walls,
            laws: &self.laws,
            cell: self.cell.as_ref(),
            law_history: self.pair_strides().1,
            dt: self.dt,
            step: self.step,
            time: self.time,
        };
        let Ok(lists) = BodyContacts::overlaps(k, &around) else { return Vec::new() };
        let body = |i: usize| format!("{} {}", k.kind_name(i), k.id[i]);
        let mut found = Vec::new();
        for (n, (list, touching)) in [&k.pairs, &k.wall_pairs, &k.sphere_pairs].into_iter().zip(lists).enumerate() {
            for (pair, overlap) in touching {
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
        for k in 0..self.pairs.len() {
            if !self.pairs.touching[k] {
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
