//! The time-step limit of the explicit integration for the contacts a packing has now.
//!
//! `critical_dt` looks at one contact at a time (`sqrt(m/k_n)`); a sphere held by many contacts
//! oscillates faster, and a time step below `critical_dt` can still make a dense packing gain
//! energy step after step. The limit here takes every contact of every sphere into account.

use crate::dem::particles::{dof, FREE};
use crate::dem::sim::DemSim;
use crate::math::Vec3;

/// The stability limit of the present contacts and the sphere whose contacts set it.
#[derive(Debug, Clone, Copy)]
pub struct StableStep {
    /// The largest stable time step (s).
    pub dt: f64,
    /// Id of the sphere (a member, for a clump) whose contacts give the limit.
    pub sphere: u64,
    /// Its touching contacts (all members', for a clump).
    pub contacts: u32,
}

/// One body's share of the linearised stiffness: its diagonal block (the sum of its contacts'
/// stiffness matrices) and, per axis, the absolute row sums of its couplings to other bodies
/// already divided by `sqrt(m_i m_j)`.
#[derive(Clone, Copy, Default)]
struct Row {
    diagonal: [[f64; 3]; 3],
    coupling: [f64; 3],
    contacts: u32,
}

/// Stiffness matrix of one contact: `k_t I + (k_n - k_t) n n^T`.
fn contact_matrix(kn: f64, kt: f64, n: Vec3) -> [[f64; 3]; 3] {
    let mut k = [[0.0; 3]; 3];
    for (a, row) in k.iter_mut().enumerate() {
        for (b, value) in row.iter_mut().enumerate() {
            *value = (kn - kt) * n[a] * n[b] + if a == b { kt } else { 0.0 };
        }
    }
    k
}

fn add_matrix(into: &mut [[f64; 3]; 3], k: &[[f64; 3]; 3]) {
    for a in 0..3 {
        for b in 0..3 {
            into[a][b] += k[a][b];
        }
    }
}

fn abs_row_sums(k: &[[f64; 3]; 3]) -> Vec3 {
    k.map(|row| row.iter().map(|v| v.abs()).sum())
}

impl DemSim {
    /// The largest time step for which the leapfrog integration of the bodies' translations,
    /// linearised about the present contacts, stays stable: `2 / omega_max`, where `omega_max^2`,
    /// the largest eigenvalue of `M^-1/2 K M^-1/2`, is bounded row by row (body i, axis a) by
    /// Gershgorin's theorem: `sum_b |D_i[a][b]| / m_i + sum_c sum_b |K_c[a][b]| / sqrt(m_i m_j)`,
    /// with `K_c = k_t I + (k_n - k_t) n n^T` the tangent stiffness of contact c (as its law gives
    /// it at the present overlap) and `D_i` the sum of body i's. For a chain or a simple cubic
    /// lattice of equal frictionless spheres this is exact: `sqrt(m/k_n)`. Rotations and viscous
    /// damping are left out; both lower the true limit somewhat. Bodies whose three translations
    /// are blocked count as infinitely heavy. None without touching contacts.
    pub fn stable_dt(&self) -> Option<StableStep> {
        let s = &self.spheres;
        let n = s.len();
        let body = |i: usize| if s.clump[i] == FREE { i } else { n + s.clump[i] as usize };
        let mass = |b: usize| if b < n { s.mass[b] } else { self.clumps.mass[b - n] };
        let all_translations = dof::X | dof::Y | dof::Z;
        let held = |b: usize| b < n && s.blocked[b] & all_translations == all_translations;
        let mut rows = vec![Row::default(); n + self.clumps.mass.len()];
        let p = &self.pairs;
        for c in 0..p.len() {
            if !p.touching[c] {
                continue;
            }
            let (i, j) = (p.a[c] as usize, p.b[c] as usize);
            let image = self.cell.as_ref().map(|cell| cell.shift_vector(p.shift[c])).unwrap_or([0.0; 3]);
            let l: Vec3 = std::array::from_fn(|a| s.x[j][a] + image[a] - s.x[i][a]);
            let distance = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
            if !(distance > 0.0) {
                continue;
            }
            let normal = l.map(|v| v / distance);
            let params = &p.params[c * p.param_stride..(c + 1) * p.param_stride];
            let overlap = s.radius[i] + s.radius[j] - distance;
            let (kn, kt) = self.laws[p.law[c] as usize].tangent_stiffness(overlap, params);
            if !(kn > 0.0) {
                continue;
            }
            let k = contact_matrix(kn, kt.max(0.0), normal);
            let sums = abs_row_sums(&k);
            let (bi, bj) = (body(i), body(j));
            for (me, other) in [(bi, bj), (bj, bi)] {
                let row = &mut rows[me];
                add_matrix(&mut row.diagonal, &k);
                row.contacts += 1;
                if !held(other) {
                    let scale = 1.0 / (mass(me) * mass(other)).sqrt();
                    for a in 0..3 {
                        row.coupling[a] += sums[a] * scale;
                    }
                }
            }
        }
        let w = &self.wall_pairs;
        for c in 0..w.len() {
            if !w.touching[c] {
                continue;
            }
            let i = w.a[c] as usize;
            let Some(contact) = self.walls[w.b[c] as usize].contact(s.x[i], s.radius[i], f64::INFINITY) else {
                continue;
            };
            let params = &w.params[c * w.param_stride..(c + 1) * w.param_stride];
            let (kn, kt) = self.laws[w.law[c] as usize].tangent_stiffness(-contact.gap, params);
            if !(kn > 0.0) {
                continue;
            }
            let row = &mut rows[body(i)];
            add_matrix(&mut row.diagonal, &contact_matrix(kn, kt.max(0.0), contact.normal));
            row.contacts += 1;
        }
        let mut worst: Option<(f64, usize)> = None;
        for (b, row) in rows.iter().enumerate() {
            if row.contacts == 0 || held(b) {
                continue;
            }
            let own = abs_row_sums(&row.diagonal);
            let bound = (0..3).map(|a| own[a] / mass(b) + row.coupling[a]).fold(0.0, f64::max);
            if worst.is_none_or(|(w, _)| bound > w) {
                worst = Some((bound, b));
            }
        }
        let (omega2, b) = worst?;
        let sphere = if b < n { b } else { (0..n).find(|&i| body(i) == b).unwrap_or(0) };
        Some(StableStep { dt: 2.0 / omega2.sqrt(), sphere: s.id[sphere], contacts: rows[b].contacts })
    }

    /// Says once (in `events`) that the time step is above the present contacts' stability
    /// limit: such a packing gains energy it should not have, slowly at first.
    pub(crate) fn warn_if_above_stable_dt(&mut self) {
        let Some(limit) = self.stable_dt() else { return };
        if self.dt > limit.dt {
            self.stability_warned = true;
            self.events.push(format!(
                "step {} (t = {:.6e} s): the time step {:.4e} s is above the stability limit {:.4e} s of the present \
                 contacts (sphere {} with {} contacts; stable_dt()): the packing can gain energy it should not have; \
                 lower dt below that limit",
                self.step, self.time, self.dt, limit.dt, limit.sphere, limit.contacts
            ));
        }
    }
}
