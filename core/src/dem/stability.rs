//! The time-step limit of the explicit integration for the contacts a packing has now.
//!
//! `critical_dt` looks at one contact at a time (`sqrt(m/k_n)`); a body held by many contacts
//! vibrates faster, and a time step below `critical_dt` can still make a dense packing gain
//! energy step after step. Here every contact of every body counts, rotations included: the
//! contacts' tangent stiffnesses make a linear system `M q'' = -K q` (six degrees of freedom a
//! body), and leapfrog follows it only while `omega dt <= 2` for its fastest vibration.

use crate::dem::particles::{dof, FREE};
use crate::dem::sim::DemWorld;
use crate::ext::contact::uniform;
use nalgebra::{DMatrix, Matrix3, Matrix6, SMatrix, Vector3};

/// The stability limit of the present contacts and the sphere whose contacts set it.
#[derive(Debug, Clone, Copy)]
pub struct StableStep {
    /// A time step on the safe side of the stability limit (s).
    pub dt: f64,
    /// Id of the sphere (a member, for a clump) whose contacts give the limit.
    pub sphere: u64,
    /// Its touching contacts (all members', for a clump).
    pub contacts: u32,
}

/// Lanczos steps when testing whether a time step is above the true limit.
const PROBE_STEPS: usize = 100;
/// Fewest steps between two checks of the time step (made at rebuilds of the candidate lists,
/// and at once after the time step is set): the contact network changes slowly.
pub const CHECK_EVERY: u64 = 1000;
/// `Spring::j` of a wall.
const WALL: u32 = u32::MAX;

/// One contact, linearised: bodies `i` and `j`, tangent stiffness `k` (`k_t I + (k_n - k_t) n n^T`)
/// and the contact point seen from each body's centre.
struct Spring {
    i: u32,
    j: u32,
    k: Matrix3<f64>,
    arm_i: Vector3<f64>,
    arm_j: Vector3<f64>,
}

/// The bodies' six degrees of freedom and their contacts: `A = M^-1/2 K M^-1/2`.
struct Linearised {
    /// `1 / sqrt(m)` and `1 / sqrt(I)` of every body (0 for blocked motion: it does not move, as
    /// if infinitely heavy). A clump's `I` is its smallest principal moment.
    inv_sqrt_mass: Vec<f64>,
    inv_sqrt_inertia: Vec<f64>,
    springs: Vec<Spring>,
    /// A sphere of each body, to name it.
    sphere_of: Vec<usize>,
}

fn skew(a: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0)
}

impl Linearised {
    /// How body `b`'s scaled motion moves the contact point: relative displacement
    /// `d = u_j - u_i + a_i x theta_i - a_j x theta_j` (rotations turn the arms `a`).
    fn map(&self, b: u32, arm: &Vector3<f64>, sign: f64) -> SMatrix<f64, 3, 6> {
        let mut m = SMatrix::<f64, 3, 6>::zeros();
        let b = b as usize;
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&(Matrix3::identity() * (sign * self.inv_sqrt_mass[b])));
        m.fixed_view_mut::<3, 3>(0, 3).copy_from(&(skew(arm) * (-sign * self.inv_sqrt_inertia[b])));
        m
    }

    /// Gershgorin's bound on the largest eigenvalue of `A`: row by row, the absolute sum of the
    /// body's own block (exact sum of its springs) and of its couplings to other bodies. The
    /// body whose row gives it and its contacts; None without contacts.
    fn gershgorin(&self) -> Option<(f64, usize, u32)> {
        let bodies = self.inv_sqrt_mass.len();
        let mut own = vec![Matrix6::<f64>::zeros(); bodies];
        let mut coupling = vec![[0.0; 6]; bodies];
        let mut contacts = vec![0u32; bodies];
        for s in &self.springs {
            let bi = self.map(s.i, &s.arm_i, -1.0);
            own[s.i as usize] += bi.transpose() * s.k * bi;
            contacts[s.i as usize] += 1;
            if s.j != WALL {
                let bj = self.map(s.j, &s.arm_j, 1.0);
                own[s.j as usize] += bj.transpose() * s.k * bj;
                contacts[s.j as usize] += 1;
                let cross = bi.transpose() * s.k * bj;
                for r in 0..6 {
                    coupling[s.i as usize][r] += cross.row(r).abs().sum();
                    coupling[s.j as usize][r] += cross.column(r).abs().sum();
                }
            }
        }
        let mut worst: Option<(f64, usize, u32)> = None;
        for b in 0..bodies {
            if contacts[b] == 0 {
                continue;
            }
            let bound = (0..6).map(|r| own[b].row(r).abs().sum() + coupling[b][r]).fold(0.0, f64::max);
            if worst.is_none_or(|(w, _, _)| bound > w) {
                worst = Some((bound, b, contacts[b]));
            }
        }
        worst
    }

    /// `y = A x`, six values per body.
    fn apply(&self, x: &[f64], y: &mut [f64]) {
        y.iter_mut().for_each(|v| *v = 0.0);
        let scaled = |b: u32| -> (Vector3<f64>, Vector3<f64>) {
            if b == WALL {
                return (Vector3::zeros(), Vector3::zeros());
            }
            let (o, b) = (6 * b as usize, b as usize);
            (
                Vector3::new(x[o], x[o + 1], x[o + 2]) * self.inv_sqrt_mass[b],
                Vector3::new(x[o + 3], x[o + 4], x[o + 5]) * self.inv_sqrt_inertia[b],
            )
        };
        for s in &self.springs {
            let ((ui, ti), (uj, tj)) = (scaled(s.i), scaled(s.j));
            let d = uj - ui + s.arm_i.cross(&ti) - s.arm_j.cross(&tj);
            let f = s.k * d;
            // The gradient of the spring's energy d.K d / 2 with respect to each motion.
            for (b, arm, sign) in [(s.i, &s.arm_i, -1.0), (s.j, &s.arm_j, 1.0)] {
                if b == WALL {
                    continue;
                }
                let (o, b) = (6 * b as usize, b as usize);
                let force = f * sign * self.inv_sqrt_mass[b];
                let torque = arm.cross(&f) * (sign * self.inv_sqrt_inertia[b]);
                for a in 0..3 {
                    y[o + a] += force[a];
                    y[o + 3 + a] += torque[a];
                }
            }
        }
    }

    /// The largest Ritz value of `A` after `PROBE_STEPS` Lanczos steps from a fixed
    /// pseudo-random start: the largest eigenvalue of the tridiagonal matrix the three-term
    /// recurrence builds. Ritz values lie within `A`'s spectrum (without reorthogonalisation, to
    /// within rounding of `|A|`: Paige), so this is a lower bound of `A`'s largest eigenvalue,
    /// found with two vectors of memory whatever the size of the packing.
    fn largest_ritz_value(&self) -> f64 {
        let len = 6 * self.inv_sqrt_mass.len();
        let mut v: Vec<f64> = (0..len).map(|k| 2.0 * uniform(0x5eed, k as u64) - 1.0).collect();
        let mut previous = vec![0.0; len];
        let mut w = vec![0.0; len];
        let (mut alpha, mut beta) = (Vec::new(), Vec::new());
        let mut norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        for _ in 0..PROBE_STEPS.min(len) {
            if !(norm > 1e-300) {
                break;
            }
            v.iter_mut().for_each(|x| *x /= norm);
            self.apply(&v, &mut w);
            let b = beta.last().copied().unwrap_or(0.0);
            w.iter_mut().zip(&previous).for_each(|(x, p)| *x -= b * p);
            let a: f64 = w.iter().zip(&v).map(|(x, y)| x * y).sum();
            w.iter_mut().zip(&v).for_each(|(x, y)| *x -= a * y);
            alpha.push(a);
            norm = w.iter().map(|x| x * x).sum::<f64>().sqrt();
            beta.push(norm);
            std::mem::swap(&mut previous, &mut v);
            std::mem::swap(&mut v, &mut w);
        }
        let k = alpha.len();
        if k == 0 {
            return 0.0;
        }
        let t = DMatrix::from_fn(k, k, |r, c| match r.abs_diff(c) {
            0 => alpha[r],
            1 => beta[r.min(c)],
            _ => 0.0,
        });
        t.symmetric_eigenvalues().iter().cloned().fold(0.0, f64::max)
    }
}

/// Growth of leapfrog's fastest mode per step when `omega dt > 2` (the larger root's size of
/// `l^2 - (2 - (omega dt)^2) l + 1 = 0`).
fn growth_per_step(omega_dt: f64) -> f64 {
    let b = omega_dt * omega_dt - 2.0;
    (b + (b * b - 4.0).max(0.0).sqrt()) / 2.0
}

impl DemWorld {
    fn linearise(&self) -> Linearised {
        let s = &self.spheres;
        let n = s.len();
        let body = |i: usize| if s.clump[i] == FREE { i } else { n + s.clump[i] as usize };
        let bodies = n + self.clumps.mass.len();
        let (mut inv_sqrt_mass, mut inv_sqrt_inertia) = (vec![0.0; bodies], vec![0.0; bodies]);
        let mut sphere_of = vec![0; bodies];
        let inv_sqrt = |v: f64| if v > 0.0 { 1.0 / v.sqrt() } else { 0.0 };
        for i in (0..n).rev() {
            let b = body(i);
            sphere_of[b] = i;
            if b < n {
                let blocked = s.blocked[b];
                let all = |first: u8| blocked & (first * 7) == first * 7;
                inv_sqrt_mass[b] = if all(dof::X) { 0.0 } else { inv_sqrt(s.mass[b]) };
                inv_sqrt_inertia[b] = if all(dof::RX) { 0.0 } else { inv_sqrt(s.inertia[b]) };
            } else {
                let c = b - n;
                let smallest = self.clumps.inertia[c].iter().cloned().fold(f64::INFINITY, f64::min);
                inv_sqrt_mass[b] = inv_sqrt(self.clumps.mass[c]);
                inv_sqrt_inertia[b] = inv_sqrt(smallest);
            }
        }
        // A clump's arms start at its centre of mass, a sphere's at its own centre.
        let centre = |i: usize| -> Vector3<f64> {
            let x = if s.clump[i] == FREE { s.x[i] } else { self.clumps.x[s.clump[i] as usize] };
            Vector3::from(x)
        };
        let mut springs = Vec::new();
        let p = &self.contacts.spheres;
        for c in 0..p.len() {
            if !p.touching[c] {
                continue;
            }
            let (i, j) = (p.a[c] as usize, p.b[c] as usize);
            let image = Vector3::from(self.cell.as_ref().map(|cell| cell.shift_vector(p.shift[c])).unwrap_or([0.0; 3]));
            let l = Vector3::from(s.x[j]) + image - Vector3::from(s.x[i]);
            let distance = l.norm();
            if !(distance > 0.0) {
                continue;
            }
            let normal = l / distance;
            let params = &p.params[c * p.param_stride..(c + 1) * p.param_stride];
            let overlap = s.radius[i] + s.radius[j] - distance;
            let (kn, kt) = self.contacts.laws[p.law[c] as usize].tangent_stiffness(overlap, params);
            if !(kn > 0.0) {
                continue;
            }
            // The contact point: in the middle of the overlap, as the contact stage puts it.
            let point = Vector3::from(s.x[i]) + normal * (s.radius[i] - 0.5 * overlap);
            springs.push(Spring {
                i: body(i) as u32,
                j: body(j) as u32,
                k: contact_matrix(kn, kt.max(0.0), &normal),
                arm_i: point - centre(i),
                arm_j: point - image - centre(j),
            });
        }
        let w = &self.contacts.sphere_walls;
        for c in 0..w.len() {
            if !w.touching[c] {
                continue;
            }
            let i = w.a[c] as usize;
            let Some(contact) = self.walls[w.b[c] as usize].contact(s.x[i], s.radius[i], f64::INFINITY) else {
                continue;
            };
            let params = &w.params[c * w.param_stride..(c + 1) * w.param_stride];
            let (kn, kt) = self.contacts.laws[w.law[c] as usize].tangent_stiffness(-contact.gap, params);
            if kn > 0.0 {
                springs.push(Spring {
                    i: body(i) as u32,
                    j: WALL,
                    k: contact_matrix(kn, kt.max(0.0), &Vector3::from(contact.normal)),
                    arm_i: Vector3::from(contact.point) - centre(i),
                    arm_j: Vector3::zeros(),
                });
            }
        }
        Linearised { inv_sqrt_mass, inv_sqrt_inertia, springs, sphere_of }
    }

    /// A time step on the safe side of the limit below which the leapfrog integration of the
    /// bodies' motions, linearised about the present contacts, is stable: `2 / omega_max`, with
    /// `omega_max^2`, the largest eigenvalue of `M^-1/2 K M^-1/2`, bounded by Gershgorin's
    /// theorem row by row (six degrees of freedom a body). `K` comes from each contact's tangent
    /// stiffness `k_t I + (k_n - k_t) n n^T` (as its law gives it at the present overlap) acting
    /// on the relative displacement of the contact point. Cundall damping `D` multiplies a force
    /// that opposes the motion by up to `1 + D`, so the bound is too. Exact for an undamped
    /// simple cubic lattice of equal frictionless spheres (`sqrt(m/k_n)`); viscous damping, left
    /// out, lowers the true limit. Blocked motions count as infinitely heavy. None without
    /// touching contacts.
    pub fn stable_dt(&self) -> Option<StableStep> {
        let lin = self.linearise();
        let (bound, b, contacts) = lin.gershgorin()?;
        Some(StableStep { dt: self.dt_of_bound(bound), sphere: self.spheres.id[lin.sphere_of[b]], contacts })
    }

    /// `2 / omega` for `omega^2` = `bound` raised by Cundall damping (see [`DemWorld::stable_dt`]).
    fn dt_of_bound(&self, bound: f64) -> f64 {
        2.0 / (bound * (1.0 + self.damping.max(0.0))).sqrt()
    }

    /// After a rebuild or a new time step: a time step above `stable_dt` is said once in
    /// `events`; if Lanczos iteration then proves that the present contacts, undamped, vibrate
    /// faster than leapfrog can follow (`omega dt > 2`), the run stops, since the packing would
    /// gain energy from nowhere step after step (unless `stop` is false, or there are clumps,
    /// whose rotational inertia is only bounded here). The proof is for the undamped system;
    /// Cundall damping lowers the real limit (measured on an RVE), so the stop errs on the side of
    /// running.
    pub fn check_time_step(&mut self, stop: bool) -> crate::Result<()> {
        self.time_step_check.last = Some(self.step);
        let lin = self.linearise();
        let Some((bound, b, contacts)) = lin.gershgorin() else { return Ok(()) };
        let limit = self.dt_of_bound(bound);
        if self.dt <= limit {
            return Ok(());
        }
        let sphere = self.spheres.id[lin.sphere_of[b]];
        if !self.time_step_check.warned {
            self.time_step_check.warned = true;
            let said = time_step_warning(self.step, self.time, self.dt, limit, sphere, contacts);
            self.events.push(said);
        }
        if !stop || !self.clumps.mass.is_empty() {
            return Ok(());
        }
        let omega2 = lin.largest_ritz_value();
        if omega2 * self.dt * self.dt <= 4.0 * (1.0 + 1e-9) {
            return Ok(());
        }
        let omega = omega2.sqrt();
        Err(crate::GraniteError::Unstable {
            step: self.step,
            time: self.time,
            reason: format!(
                "the time step {:.4e} s is above the stability limit of the present contacts: they vibrate at \
                 {omega:.4e} rad/s or faster, so leapfrog multiplies that vibration by {:.3} or more each step and the \
                 packing gains energy from nowhere. Stable only below 2/omega = {:.4e} s; stable_dt() = {limit:.4e} s \
                 is on the safe side",
                self.dt,
                growth_per_step(omega * self.dt),
                2.0 / omega
            ),
        })
    }
}

/// What a check says of a time step `dt` above the bound `limit` of the contacts at `step` (time
/// `time`), set by sphere `sphere` (its id) with `contacts` contacts.
pub fn time_step_warning(step: u64, time: f64, dt: f64, limit: f64, sphere: u64, contacts: u32) -> String {
    format!(
        "step {step} (t = {time:.6e} s): the time step {dt:.4e} s is above the stability bound {limit:.4e} s of the \
         present contacts (sphere {sphere} with {contacts} contacts; stable_dt()): the packing can gain energy it \
         should not have; lower dt below that bound"
    )
}

/// Stiffness matrix of one contact: `k_t I + (k_n - k_t) n n^T`.
fn contact_matrix(kn: f64, kt: f64, n: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::identity() * kt + n * n.transpose() * (kn - kt)
}
