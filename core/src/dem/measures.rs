//! Measures of a DEM state: energies, unbalanced force, coordination (thesis 5.14), Love-Weber
//! stress (4.7), global stress with gravity (appendix A, eq. .14).

use crate::dem::contact_set::{MemberKind, Pairing};
use crate::dem::contacts::PairList;
use crate::dem::sim::DemWorld;
use crate::math::{Vec3, Voigt};

/// Runs of consecutive pairs summed apart in the Love-Weber stress, their sums then added
/// pairwise in a fixed tree: a device sums them in the same order, each run on its own
/// invocation (`rve.wgsl`), whatever the thread count.
pub const STRESS_LANES: usize = 256;

#[derive(Debug, Clone, Default)]
pub struct DemDiagnostics {
    pub particles: usize,
    /// Touching sphere-sphere contacts.
    pub contacts: usize,
    pub wall_contacts: usize,
    /// Translational plus rotational.
    pub kinetic_energy: f64,
    /// Stored in the contact springs.
    pub elastic_energy: f64,
    /// `-sum m g . x`.
    pub gravitational_energy: f64,
    /// Mean resultant force (contacts + gravity) on free spheres over the mean contact force.
    pub unbalanced_force: f64,
    /// 2 contacts / particles, every particle counted.
    pub coordination: f64,
    /// Eq. 5.14: without rattlers (one contact) and floaters (none).
    pub coordination_no_rattlers: f64,
    pub rattlers: usize,
    pub floaters: usize,
    pub max_height: f64,
}

/// Contacts and coordination of a DEM state (thesis eq. 5.14).
#[derive(Debug, Clone, Copy, Default)]
pub struct Coordination {
    /// Touching sphere-sphere contacts.
    pub contacts: usize,
    /// 2 contacts / particles, every particle counted.
    pub coordination: f64,
    /// Eq. 5.14: without rattlers (one contact) and floaters (none).
    pub coordination_no_rattlers: f64,
    pub rattlers: usize,
    pub floaters: usize,
}

impl DemWorld {
    /// Overlap of pair `k` of `list` in the current positions (zero when apart).
    fn overlap_of(&self, list: &PairList, k: usize, wall: bool) -> f64 {
        let s = &self.spheres;
        let i = list.a[k] as usize;
        let overlap = if wall {
            self.walls[list.b[k] as usize].contact(s.x[i], s.radius[i], 0.0).map_or(0.0, |g| -g.gap)
        } else {
            let j = list.b[k] as usize;
            let d = crate::dem::contact_stage::branch(&s.x, i, j, list.shift[k], self.cell.as_ref());
            s.radius[i] + s.radius[j] - (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
        };
        overlap.max(0.0)
    }

    /// The touching pairs of a list with their overlaps: the spheres' found again where they are,
    /// the bodies' as their last step found them.
    pub(crate) fn touching_overlaps(&self, pairing: Pairing) -> Vec<(usize, f64)> {
        let list = self.contacts.list(pairing);
        let touching = (0..list.len()).filter(|&k| list.touching[k]);
        match pairing.body_list() {
            None => touching.map(|k| (k, self.overlap_of(list, k, pairing == Pairing::SphereWall))).collect(),
            Some(n) => {
                let touches = &self.contacts.body_touches[n];
                let overlap =
                    |k: usize| touches.binary_search_by_key(&k, |(c, _)| c.slot).map_or(0.0, |t| touches[t].0.overlap);
                touching.map(|k| (k, overlap(k))).collect()
            }
        }
    }

    /// Contacts per sphere (sphere-sphere and sphere-wall), in sphere order.
    pub fn contact_counts(&self) -> Vec<u32> {
        let mut count = vec![0u32; self.spheres.len()];
        for k in 0..self.contacts.spheres.len() {
            if self.contacts.spheres.touching[k] {
                count[self.contacts.spheres.a[k] as usize] += 1;
                count[self.contacts.spheres.b[k] as usize] += 1;
            }
        }
        for k in 0..self.contacts.sphere_walls.len() {
            if self.contacts.sphere_walls.touching[k] {
                count[self.contacts.sphere_walls.a[k] as usize] += 1;
            }
        }
        count
    }

    /// Touching contacts of every grain: the spheres' ([`DemWorld::contact_counts`], with those
    /// of bodies on them), then the bodies of plugin kinds' (with one another, walls and spheres).
    pub fn grain_contact_counts(&self) -> Vec<u32> {
        let mut count = self.contact_counts();
        let ns = count.len();
        count.resize(ns + self.kinds.len(), 0);
        let c = &self.contacts;
        for (list, second) in [(&c.bodies, Some(ns)), (&c.body_walls, None), (&c.body_spheres, Some(0))] {
            for c in (0..list.len()).filter(|&c| list.touching[c]) {
                count[ns + list.a[c] as usize] += 1;
                if let Some(first) = second {
                    count[first + list.b[c] as usize] += 1;
                }
            }
        }
        count
    }

    pub fn diagnostics(&self) -> DemDiagnostics {
        let s = &self.spheres;
        let n = s.len();
        let g = self.gravity;
        let mut d = DemDiagnostics { particles: n, max_height: f64::NEG_INFINITY, ..Default::default() };
        let up = {
            let gn = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            if gn > 0.0 {
                [-g[0] / gn, -g[1] / gn, -g[2] / gn]
            } else {
                [0.0, 0.0, 1.0]
            }
        };
        let mut resultant = 0.0;
        let mut free = 0usize;
        // A rigid body's (a clump's, a body's of a plugin kind) energies and resultant force.
        let mut rigid = |d: &mut DemDiagnostics,
                         m: f64,
                         (v, w, x): (Vec3, Vec3, Vec3),
                         q: &nalgebra::UnitQuaternion<f64>,
                         inertia: Vec3,
                         force: Vec3| {
            d.kinetic_energy += 0.5 * m * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
            // Rotational energy with the world-frame inertia.
            let rot = q.to_rotation_matrix();
            let ib = nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::new(inertia[0], inertia[1], inertia[2]));
            let iw = rot.matrix() * ib * rot.matrix().transpose();
            let wv = nalgebra::Vector3::new(w[0], w[1], w[2]);
            d.kinetic_energy += 0.5 * wv.dot(&(iw * wv));
            d.gravitational_energy -= m * (g[0] * x[0] + g[1] * x[1] + g[2] * x[2]);
            let f = [force[0] + m * g[0], force[1] + m * g[1], force[2] + m * g[2]];
            resultant += (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
            free += 1;
        };
        let cl = &self.clumps;
        for c in 0..cl.len() {
            rigid(&mut d, cl.mass[c], (cl.v[c], cl.w[c], cl.x[c]), &cl.q[c], cl.inertia[c], cl.force[c]);
        }
        let k = &self.kinds;
        for i in 0..k.len() {
            d.max_height = d.max_height.max(k.x[i][0] * up[0] + k.x[i][1] * up[1] + k.x[i][2] * up[2]);
            if !k.fixed[i] {
                rigid(&mut d, k.mass[i], (k.v[i], k.w[i], k.x[i]), &k.q[i], k.inertia[i], k.force[i]);
            }
        }
        d.particles += k.len();
        for i in 0..n {
            let (m, v, w, x) = (s.mass[i], s.v[i], s.w[i], s.x[i]);
            d.max_height = d.max_height.max(x[0] * up[0] + x[1] * up[1] + x[2] * up[2]);
            if s.clump[i] != crate::dem::particles::FREE {
                continue;
            }
            d.kinetic_energy += 0.5 * m * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
            d.kinetic_energy += 0.5 * s.inertia[i] * (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
            d.gravitational_energy -= m * (g[0] * x[0] + g[1] * x[1] + g[2] * x[2]);
            if s.blocked[i] & crate::dem::particles::dof::ALL == 0 {
                let f = [s.force[i][0] + m * g[0], s.force[i][1] + m * g[1], s.force[i][2] + m * g[2]];
                resultant += (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
                free += 1;
            }
        }
        let mut contact_force = 0.0;
        let mut touching = 0usize;
        for (pairing, list) in self.contacts.lists() {
            let (ps, hs) = (list.param_stride, list.history_stride);
            for (k, overlap) in self.touching_overlaps(pairing) {
                let f = list.force[k];
                contact_force += (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
                touching += 1;
                if pairing.second() == MemberKind::Wall {
                    d.wall_contacts += 1;
                } else {
                    d.contacts += 1;
                }
                let law = &self.contacts.laws[list.law[k] as usize];
                d.elastic_energy += law.elastic_energy(
                    overlap,
                    &list.params[k * ps..(k + 1) * ps],
                    &list.history[k * hs..(k + 1) * hs],
                );
            }
        }
        d.unbalanced_force = if touching > 0 && free > 0 {
            (resultant / free as f64) / (contact_force / touching as f64)
        } else {
            f64::NAN
        };
        let c = self.coordination();
        (d.coordination, d.coordination_no_rattlers, d.rattlers, d.floaters) =
            (c.coordination, c.coordination_no_rattlers, c.rattlers, c.floaters);
        d
    }

    /// Contact counts and coordination numbers alone (what an RVE reports after every call),
    /// without the energies and forces of [`DemWorld::diagnostics`].
    pub fn coordination(&self) -> Coordination {
        let k = &self.kinds;
        let n = self.spheres.len() + k.len();
        let counts = self.grain_contact_counts();
        let contacts = self
            .contacts
            .lists()
            .iter()
            .filter(|(p, _)| p.second() != MemberKind::Wall)
            .map(|(_, l)| l.touching_count())
            .sum();
        let rattlers = counts.iter().filter(|&&c| c == 1).count();
        let floaters = counts.iter().filter(|&&c| c == 0).count();
        // Eq. 5.14 with N_contacts counted per particle end: each contact has two ends.
        let ends: u64 = counts.iter().map(|&c| c as u64).sum();
        let kept = n.saturating_sub(rattlers + floaters);
        Coordination {
            contacts,
            coordination: if n > 0 { 2.0 * contacts as f64 / n as f64 } else { 0.0 },
            coordination_no_rattlers: if kept > 0 { (ends - rattlers as u64) as f64 / kept as f64 } else { 0.0 },
            rattlers,
            floaters,
        }
    }

    /// Love-Weber stress of the contacts between grains over a volume (eq. 4.7; spheres, and
    /// bodies of plugin kinds with one another and with spheres):
    /// `sigma_ij = (1/V) sum_c f_i l_j`, f the force on particle 1 and l the branch vector from 1
    /// to 2. Tension positive: a compressed packing has negative diagonal stress.
    pub fn love_weber_stress(&self, volume: f64) -> Voigt {
        // One walk over the pairs for both measures; the stiffness sums cost little beside it.
        // In parallel blocks when the spheres are enough to share: the same sums either way. (An
        // RVE inside a parallel loop over material points sums on its own thread: `Rve::stress`.)
        let parallel = crate::dem::pieces::worth_parallel(self.spheres.len());
        self.stress_and_axis_stiffness(volume, parallel).0
    }

    /// [`DemWorld::love_weber_stress`] over `volume` and, in the same pass over the pairs (the stress
    /// servo needs both every step), the stiffness of the packing along each axis,
    /// `(1/V) sum_c k_n l_a^2`: the stress increment per unit strain of an affine deformation
    /// (normal springs only).
    /// In parallel blocks if `parallel`: the same sums either way.
    pub fn stress_and_axis_stiffness(&self, volume: f64, parallel: bool) -> (Voigt, [f64; 3]) {
        // Summed run by run, and the runs' sums in a fixed tree: the same sums whatever the
        // thread count. The servo needs them every step; when the step runs in parallel, so do
        // the runs, keeping both cores busy instead of leaving one to fall asleep while the
        // other sums alone.
        let len = self.contacts.spheres.len();
        let per = len.div_ceil(STRESS_LANES).max(1);
        let lanes: Vec<std::ops::Range<usize>> =
            (0..STRESS_LANES).map(|t| (t * per).min(len)..((t + 1) * per).min(len)).collect();
        let mut sums: Vec<([f64; 9], [f64; 3])> = if parallel {
            crate::par::run_pieces(lanes, |r| self.pair_sums(r))
        } else {
            lanes.into_iter().map(|r| self.pair_sums(r)).collect()
        };
        let mut half = STRESS_LANES / 2;
        while half > 0 {
            let (low, high) = sums.split_at_mut(half);
            for ((s, k), (ps, pk)) in low.iter_mut().zip(high.iter()) {
                s.iter_mut().zip(ps).for_each(|(a, b)| *a += b);
                k.iter_mut().zip(pk).for_each(|(a, b)| *a += b);
            }
            half /= 2;
        }
        let (mut s, mut k) = sums[0];
        if !self.kinds.is_empty() {
            let (bs, bk) = self.body_pair_sums();
            s.iter_mut().zip(bs).for_each(|(a, b)| *a += b);
            k.iter_mut().zip(bk).for_each(|(a, b)| *a += b);
        }
        let sym = |a: usize, b: usize| 0.5 * (s[3 * a + b] + s[3 * b + a]) / volume;
        ([sym(0, 0), sym(1, 1), sym(2, 2), sym(0, 1), sym(1, 2), sym(0, 2)], k.map(|v| v / volume))
    }

    /// [`DemWorld::pair_sums`] over the touching contacts of the bodies of plugin kinds with one
    /// another and with spheres, the branch vector from the body's centre of mass to the other's
    /// (or its image's): the Love-Weber sum holds for grains of any shape, each in equilibrium
    /// under its contact forces.
    fn body_pair_sums(&self) -> ([f64; 9], [f64; 3]) {
        let mut s = [0.0; 9];
        let mut k = [0.0; 3];
        let (b, c) = (&self.kinds, &self.contacts);
        for (p, centres) in [(&c.bodies, &b.x), (&c.body_spheres, &self.spheres.x)] {
            let ps = p.param_stride;
            for c in (0..p.len()).filter(|&c| p.touching[c]) {
                let image = match &self.cell {
                    Some(cell) => cell.shift_vector(p.shift[c]),
                    None => [0.0; 3],
                };
                let (xi, xj) = (b.x[p.a[c] as usize], centres[p.b[c] as usize]);
                let l: Vec3 = std::array::from_fn(|a| xj[a] + image[a] - xi[a]);
                let kn = self.contacts.laws[p.law[c] as usize].normal_stiffness(&p.params[c * ps..(c + 1) * ps]);
                add_contact_sums((&mut s, &mut k), p.force[c], l, kn);
            }
        }
        (s, k)
    }

    /// `sum f_a l_b` (row-major) and `sum k_n l_a^2` over the touching pairs of `range`.
    fn pair_sums(&self, range: std::ops::Range<usize>) -> ([f64; 9], [f64; 3]) {
        let mut s = [0.0; 9];
        let mut k = [0.0; 3];
        let p = &self.contacts.spheres;
        let ps = p.param_stride;
        for c in range {
            if !p.touching[c] {
                continue;
            }
            let (i, j) = (p.a[c] as usize, p.b[c] as usize);
            let image = match &self.cell {
                Some(cell) => cell.shift_vector(p.shift[c]),
                None => [0.0; 3],
            };
            let (xi, xj) = (self.spheres.x[i], self.spheres.x[j]);
            // Spelled out: `array::map` stays a call here, once per contact.
            let l: Vec3 = [xj[0] + image[0] - xi[0], xj[1] + image[1] - xi[1], xj[2] + image[2] - xi[2]];
            // Spelled out rather than through `add_contact_sums`: the servo sums every step, and
            // the call's arguments cost this loop 2.7 % more instructions.
            let f = p.force[c];
            for a in 0..3 {
                for b in 0..3 {
                    s[3 * a + b] += f[a] * l[b];
                }
            }
            let kn = self.contacts.laws[p.law[c] as usize].normal_stiffness(&p.params[c * ps..(c + 1) * ps]);
            if kn > 0.0 {
                for a in 0..3 {
                    k[a] += kn * l[a] * l[a];
                }
            }
        }
        (s, k)
    }

    /// Global stress of a packing at rest under gravity (appendix A, eq. .14): wall contact forces
    /// on the particles at their contact points plus `m g x` of every particle, over `volume`.
    pub fn global_stress_with_gravity(&self, volume: f64) -> Voigt {
        let mut s = [0.0; 9];
        let p = &self.contacts.sphere_walls;
        for k in 0..p.len() {
            if !p.touching[k] {
                continue;
            }
            let i = p.a[k] as usize;
            let wall = &self.walls[p.b[k] as usize];
            let Some(c) = wall.contact(self.spheres.x[i], self.spheres.radius[i], 0.0) else { continue };
            let f = p.force[k];
            for a in 0..3 {
                for b in 0..3 {
                    s[3 * a + b] += f[a] * c.point[b];
                }
            }
        }
        let g = self.gravity;
        for i in 0..self.spheres.len() {
            let (m, x) = (self.spheres.mass[i], self.spheres.x[i]);
            for a in 0..3 {
                for b in 0..3 {
                    s[3 * a + b] += m * g[a] * x[b];
                }
            }
        }
        let sym = |a: usize, b: usize| 0.5 * (s[3 * a + b] + s[3 * b + a]) / volume;
        [sym(0, 0), sym(1, 1), sym(2, 2), sym(0, 1), sym(1, 2), sym(0, 2)]
    }
}

/// Adds one contact's share of the Love-Weber sum, `f_a l_b` (row-major), to `s`, and of the axis
/// stiffness, `k_n l_a^2`, to `k`.
#[inline(always)]
fn add_contact_sums((s, k): (&mut [f64; 9], &mut [f64; 3]), f: Vec3, l: Vec3, kn: f64) {
    for a in 0..3 {
        for b in 0..3 {
            s[3 * a + b] += f[a] * l[b];
        }
    }
    if kn > 0.0 {
        for a in 0..3 {
            k[a] += kn * l[a] * l[a];
        }
    }
}
