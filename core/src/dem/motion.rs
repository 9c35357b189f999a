//! The gather of each sphere's loads with the integration: leapfrog with gravity and Cundall
//! damping, the affine field of a periodic cell, and clumps as rigid bodies.

use crate::dem::cell::CellUpdate;
use crate::dem::clump::Clumps;
use crate::dem::contact_stage::Handover;
use crate::dem::particles::{dof, Spheres, FREE};
use crate::math::{add3 as add, cross3 as cross, mat_vec, sub3 as sub, Vec3};
use crate::simd::{self, add4, mat_vec4, mul4, narrow, scale4, sub4, widen, Lanes};
use nalgebra::Matrix3;

/// One parallel piece of the force gather with the integration: consecutive spheres from
/// `first` (piece number `part`), their state (`moving`), what stays fixed over the step and the
/// handovers of the pieces after this one.
pub(super) struct GatherJob<'j> {
    pub(super) first: usize,
    pub(super) part: usize,
    pub(super) moving: PieceState<'j>,
    pub(super) fixed: SphereConstants<'j>,
    pub(super) later: &'j [&'j Handover],
    pub(super) motion: &'j Motion,
}

/// The state a piece's spheres change in a step (their run of each array).
pub(super) struct PieceState<'j> {
    pub(super) x: &'j mut [Vec3],
    pub(super) v: &'j mut [Vec3],
    pub(super) w: &'j mut [Vec3],
    pub(super) force: &'j mut [Vec3],
    pub(super) torque: &'j mut [Vec3],
}

/// What a step reads of every sphere and leaves as it is.
pub(super) struct SphereConstants<'j> {
    pub(super) mass: &'j [f64],
    pub(super) inertia: &'j [f64],
    pub(super) blocked: &'j [u8],
    pub(super) clump: &'j [u32],
    pub(super) x_at_build: &'j [Vec3],
}

/// Adds the loads handed over to a piece's spheres, then moves them.
pub(super) fn gather_piece(job: GatherJob<'_>) -> f64 {
    let GatherJob { first, part, moving, fixed, later, motion } = job;
    // The last terms of `write_back`'s order: piece after piece, each in pair order.
    for h in later {
        for &(i, f, t) in h.to(part) {
            let k = i as usize - first;
            moving.force[k] = sub(moving.force[k], f);
            moving.torque[k] = add(moving.torque[k], t);
        }
    }
    move_run_wide((first, moving, &fixed, motion))
}

/// Whether none of these spheres has a blocked degree of freedom or belongs to a clump: their
/// integration then needs no per-sphere test (most scenes; one pass over two small arrays).
#[inline(always)]
fn all_free(blocked: &[u8], clump: &[u32]) -> bool {
    blocked.iter().fold(0, |any, &b| any | b) == 0 && clump.iter().all(|&c| c == FREE)
}

/// The larger of two displacements, NaN if either is (`f64::max` would drop a NaN, and with it
/// the news that some state stopped being finite).
pub(super) fn farther(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// Leapfrog integration with gravity and Cundall damping, on the calling thread. In a periodic
/// cell (`affine` = `(L, F)`) velocities are fluctuations and positions also follow the affine
/// field `L x`. Returns the largest displacement since the candidate lists were built, not
/// counting the affine part `F x_build` (NaN if a sphere's state stopped being finite).
pub(super) fn integrate(sp: &mut Spheres, x_at_build: &[Vec3], motion: &Motion) -> f64 {
    let Spheres { x, v, w, mass, inertia, force, torque, blocked, clump, .. } = sp;
    let moving = PieceState { x, v, w, force, torque };
    let fixed = SphereConstants { mass, inertia, blocked, clump, x_at_build };
    move_run_wide((0, moving, &fixed, motion))
}

/// Moves the spheres of a run that starts at sphere `first` (see [`integrate_run`]) and returns
/// the largest displacement (see [`integrate`]).
#[inline(always)]
fn move_run((first, moving, fixed, motion): (usize, PieceState<'_>, &SphereConstants<'_>, &Motion)) -> f64 {
    let range = first..first + moving.x.len();
    if all_free(&fixed.blocked[range.clone()], &fixed.clump[range]) {
        integrate_run::<true>(first, moving, fixed, motion).largest()
    } else {
        integrate_run::<false>(first, moving, fixed, motion).largest()
    }
}

// The kernel returns a number, not the running record (`Travel`): the parallel gather's kernel
// returned the record, and there the compiler split every four-lane operation of the loop in two
// (184 instructions a sphere against 155, callgrind).
crate::wide_kernel!(fn move_run_wide(job: (usize, PieceState<'_>, &SphereConstants<'_>, &Motion)) -> f64 => move_run);

/// Moves the spheres of a run that starts at sphere `first`, under the loads in its `force` and
/// `torque`.
#[inline(always)]
fn integrate_run<const ALL_FREE: bool>(
    first: usize,
    PieceState { x, v, w, force, torque }: PieceState<'_>,
    fixed: &SphereConstants<'_>,
    motion: &Motion,
) -> Travel {
    let n = x.len();
    let range = first..first + n;
    let (v, w, force, torque) = (&mut v[..n], &mut w[..n], &force[..n], &torque[..n]);
    let (mass, inertia) = (&fixed.mass[range.clone()], &fixed.inertia[range.clone()]);
    let (blocked, clump, x_at_build) =
        (&fixed.blocked[range.clone()], &fixed.clump[range.clone()], &fixed.x_at_build[range]);
    let mut travel = Travel::default();
    for i in 0..n {
        let (moved2, state) = motion.advance_as::<ALL_FREE>(
            (&mut x[i], &mut v[i], &mut w[i]),
            (mass[i], inertia[i], blocked[i], clump[i]),
            (widen(force[i]), widen(torque[i])),
            &x_at_build[i],
        );
        travel.record(moved2, state);
    }
    travel
}

/// What moves every free sphere in one step.
pub(super) struct Motion {
    gravity: Vec3,
    damping: f64,
    dt: f64,
    affine: Option<(Matrix3<f64>, Matrix3<f64>)>,
    /// How the fluctuations follow the cell's field.
    update: CellUpdate,
    /// `gravity` and the columns of `affine`'s `(L, F, L dt)` as lanes.
    gravity_lanes: Lanes,
    affine_columns: Option<([Lanes; 3], [Lanes; 3], [Lanes; 3])>,
}

impl Motion {
    pub(super) fn new(rigid: &RigidMotion) -> Motion {
        let RigidMotion { gravity, damping, dt, affine, update } = *rigid;
        let affine_columns =
            affine.as_ref().map(|(l, f)| (simd::columns(l), simd::columns(f), simd::columns(&(l * dt))));
        Motion { gravity, damping, dt, affine, update, gravity_lanes: simd::widen(gravity), affine_columns }
    }

    /// [`Motion::advance`], or [`Motion::advance_free`] when the caller knows `ALL_FREE` spheres
    /// (not blocked, not clumped).
    #[inline(always)]
    fn advance_as<const ALL_FREE: bool>(
        &self,
        sphere: (&mut Vec3, &mut Vec3, &mut Vec3),
        (m, inertia, blocked, clump): (f64, f64, u8, u32),
        loads: (Lanes, Lanes),
        x0: &Vec3,
    ) -> (f64, Lanes) {
        if ALL_FREE {
            self.advance_free(sphere, (m, inertia), loads, x0)
        } else {
            self.advance(sphere, (m, inertia, blocked, clump), loads, x0)
        }
    }

    /// Moves one sphere. Returns what [`Travel::record`] takes: its squared displacement since
    /// the build and its state to check. Returned rather than recorded through a reference, so
    /// that the running record stays in registers from one sphere to the next.
    #[inline(always)]
    fn advance(
        &self,
        (x, v, w): (&mut Vec3, &mut Vec3, &mut Vec3),
        (m, inertia, blocked, clump): (f64, f64, u8, u32),
        (f, t): (Lanes, Lanes),
        x0: &Vec3,
    ) -> (f64, Lanes) {
        if clump != FREE {
            // Clump members move with their clump (see integrate_clumps).
            return (0.0, [0.0; 4]);
        }
        if blocked != 0 {
            return self.advance_blocked((x, v, w), (m, inertia, blocked), (f, t), x0);
        }
        self.advance_free((x, v, w), (m, inertia), (f, t), x0)
    }

    /// [`Motion::advance`] of a sphere with every degree of freedom free, outside any clump.
    #[inline(always)]
    fn advance_free(
        &self,
        (x, v, w): (&mut Vec3, &mut Vec3, &mut Vec3),
        (m, inertia): (f64, f64),
        (f, t): (Lanes, Lanes),
        x0: &Vec3,
    ) -> (f64, Lanes) {
        let (damping, dt) = (self.damping, self.dt);
        // The three components side by side in lanes: one vector instruction where the
        // component-wise form took three.
        let (x4, v4, w4) = (widen(*x), widen(*v), widen(*w));
        let (lx, reference) = match &self.affine_columns {
            Some((l, f, _)) => (mat_vec4(l, x4), mat_vec4(f, widen(*x0))),
            None => ([0.0; 4], widen(*x0)),
        };
        // One packed division instead of six scalar ones: the divider is the slowest unit here.
        let (inv_m, inv_i) = simd::reciprocals(m, inertia);
        let acc = add4(scale4(f, inv_m), self.gravity_lanes);
        let v4 = add4(v4, scale4(cundall4(acc, v4, damping, dt), dt));
        let moving = add4(v4, lx);
        let x4 = add4(x4, scale4(moving, dt));
        // The field's part of the fluctuation's change (`CellUpdate`): SLLOD's `L v dt` by
        // default, the same for a sphere and its images.
        let v4 = match (&self.affine_columns, self.update) {
            (Some((_, _, l_dt)), CellUpdate::Sllod) => sub4(v4, mat_vec4(l_dt, v4)),
            (Some((_, _, l_dt)), CellUpdate::Newton) => sub4(v4, mat_vec4(l_dt, moving)),
            _ => v4,
        };
        let w4 = add4(w4, scale4(cundall4(scale4(t, inv_i), w4, damping, dt), dt));
        (*x, *v, *w) = (narrow(x4), narrow(v4), narrow(w4));
        let d2 = mul4(sub4(x4, reference), sub4(x4, reference));
        (d2[0] + d2[1] + d2[2], add4(d2, add4(v4, w4)))
    }

    /// [`Motion::advance`] of a sphere with blocked degrees of freedom, component by component.
    fn advance_blocked(
        &self,
        (x, v, w): (&mut Vec3, &mut Vec3, &mut Vec3),
        (m, inertia, blocked): (f64, f64, u8),
        (f, t): (Lanes, Lanes),
        x0: &Vec3,
    ) -> (f64, Lanes) {
        let Motion { gravity, damping, dt, affine, update, .. } = self;
        let (damping, dt) = (*damping, *dt);
        let (lx, reference) = match affine {
            Some((l, f)) => (mat_vec(l, *x), mat_vec(f, *x0)),
            None => ([0.0; 3], *x0),
        };
        let damp = |acc: f64, vel: f64| cundall(acc, vel, damping, dt);
        let (inv_m, inv_i) = simd::reciprocals(m, inertia);
        for a in 0..3 {
            if blocked & (dof::X << a) == 0 {
                v[a] += damp(f[a] * inv_m + gravity[a], v[a]) * dt;
            }
            if blocked & (dof::RX << a) == 0 {
                w[a] += damp(t[a] * inv_i, w[a]) * dt;
            }
        }
        let moving = add(*v, lx);
        for a in 0..3 {
            x[a] += moving[a] * dt;
        }
        if let Some((l, _)) = affine {
            // As in `advance_free`; a blocked component keeps its prescribed fluctuation.
            if let Some(w) = update.field_velocity(*v, moving) {
                let field_change = mat_vec(l, w);
                for a in 0..3 {
                    if blocked & (dof::X << a) == 0 {
                        v[a] -= field_change[a] * dt;
                    }
                }
            }
        }
        let d = sub(*x, reference);
        let d2 = [d[0] * d[0], d[1] * d[1], d[2] * d[2]];
        (d2[0] + d2[1] + d2[2], add4(widen(d2), add4(widen(*v), widen(*w))))
    }
}

/// YADE's Cundall damping of an acceleration: reduced by `damping` against the sign of the
/// power at mid-step (`damping` >= 0, so copysign is damping times that sign).
#[inline(always)]
fn cundall(acc: f64, vel: f64, damping: f64, dt: f64) -> f64 {
    acc * (1.0 - damping.copysign(acc * (vel + 0.5 * dt * acc)))
}

/// [`cundall`] on each lane.
#[inline(always)]
fn cundall4(acc: Lanes, vel: Lanes, damping: f64, dt: f64) -> Lanes {
    // Spelled out: `array::map` is not inlined for certain, and this must be.
    [
        cundall(acc[0], vel[0], damping, dt),
        cundall(acc[1], vel[1], damping, dt),
        cundall(acc[2], vel[2], damping, dt),
        cundall(acc[3], vel[3], damping, dt),
    ]
}

/// How far the spheres of a run went since the candidate lists were built, and whether all
/// their states stayed finite.
#[derive(Clone, Copy, Default)]
struct Travel {
    worst2: f64,
    /// Sums of every displacement and velocity, lane by lane: finite only if every term is (no
    /// finite state is large enough to overflow them), so one test at the end replaces one per
    /// sphere.
    check: Lanes,
}

impl Travel {
    /// A sphere that moved `moved2` squared; `state` holds its squared displacements plus its
    /// velocities (only finiteness matters).
    #[inline(always)]
    fn record(&mut self, moved2: f64, state: Lanes) {
        // Not f64::max: its NaN handling lengthens the chain from one sphere to the next, and a
        // NaN shows in `check` anyway.
        if moved2 > self.worst2 {
            self.worst2 = moved2;
        }
        self.check = add4(self.check, state);
    }

    /// The largest displacement, NaN if some state stopped being finite.
    fn largest(self) -> f64 {
        if self.check.iter().all(|c| c.is_finite()) {
            self.worst2.sqrt()
        } else {
            f64::NAN
        }
    }
}

/// Rigid-body integration of the clumps (forces and torques gathered from their members), then
/// members placed and given the clump's velocity field. Returns the largest member displacement
/// since the candidate lists were built (affine part excluded).
pub(super) fn integrate_clumps(cl: &mut Clumps, sp: &mut Spheres, x_at_build: &[Vec3], motion: &RigidMotion) -> f64 {
    use nalgebra::Vector3;
    let affine = motion.affine;
    let mut moved: f64 = 0.0;
    for c in 0..cl.len() {
        let xc = cl.x[c];
        let (mut f, mut t) = ([0.0; 3], [0.0; 3]);
        for m in cl.members_of(c) {
            let i = cl.members[m] as usize;
            f = add(f, sp.force[i]);
            t = add(add(t, sp.torque[i]), cross(sub(sp.x[i], xc), sp.force[i]));
        }
        cl.force[c] = f;
        cl.torque[c] = t;
        let body = RigidBody { x: &mut cl.x[c], v: &mut cl.v[c], w: &mut cl.w[c], q: &mut cl.q[c] };
        body.advance((cl.mass[c], cl.inertia[c]), (f, t), motion);
        let xc = cl.x[c];
        for m in cl.members_of(c) {
            let i = cl.members[m] as usize;
            let l = cl.local[m];
            let arm = cl.q[c] * Vector3::new(l[0], l[1], l[2]);
            let arm = [arm[0], arm[1], arm[2]];
            sp.x[i] = add(xc, arm);
            // A member's fluctuation: the clump's rigid motion less the field's change across the arm.
            let field_across_arm = match &affine {
                Some((l, _)) => mat_vec(l, arm),
                None => [0.0; 3],
            };
            sp.v[i] = sub(add(cl.v[c], cross(cl.w[c], arm)), field_across_arm);
            sp.w[i] = cl.w[c];
            let reference = match &affine {
                Some((_, fm)) => mat_vec(fm, x_at_build[i]),
                None => x_at_build[i],
            };
            let d = sub(sp.x[i], reference);
            let dist = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if !dist.is_finite() {
                return f64::NAN;
            }
            moved = moved.max(dist);
        }
    }
    moved
}

/// What moves every free rigid body (clump or body of a plugin kind) in a step.
pub(crate) struct RigidMotion {
    pub gravity: Vec3,
    pub damping: f64,
    pub dt: f64,
    /// The periodic cell's `(L, F)`: velocities are fluctuations around `L x`.
    pub affine: Option<(Matrix3<f64>, Matrix3<f64>)>,
    /// How the fluctuations follow the field.
    pub update: CellUpdate,
}

/// The state of one rigid body a step changes: centre, velocity, angular velocity (world frame)
/// and orientation (body principal frame to world).
pub(crate) struct RigidBody<'a> {
    pub x: &'a mut Vec3,
    pub v: &'a mut Vec3,
    pub w: &'a mut Vec3,
    pub q: &'a mut nalgebra::UnitQuaternion<f64>,
}

impl RigidBody<'_> {
    /// One leapfrog step of a body of `(mass, principal moments)` under force and torque `(f, t)`,
    /// gravity and Cundall damping: Newton's law for the centre, Euler's equations in the world
    /// frame for the rotation, the orientation turned by the new angular velocity.
    pub(crate) fn advance(self, (mass, inertia): (f64, Vec3), (f, t): (Vec3, Vec3), m: &RigidMotion) {
        use nalgebra::{UnitQuaternion, Vector3};
        let RigidMotion { gravity, damping, dt, ref affine, update } = *m;
        let damp = |acc: f64, vel: f64| cundall(acc, vel, damping, dt);
        let xc = *self.x;
        let lx = match affine {
            Some((l, _)) => mat_vec(l, xc),
            None => [0.0; 3],
        };
        for a in 0..3 {
            let acc = damp(f[a] / mass + gravity[a], self.v[a]);
            self.v[a] += acc * dt;
        }
        let moving = add(*self.v, lx);
        for a in 0..3 {
            self.x[a] += moving[a] * dt;
        }
        if let Some((l, _)) = affine {
            // As for a sphere (`Motion::advance_free`).
            if let Some(w) = update.field_velocity(*self.v, moving) {
                let field_change = mat_vec(l, w);
                for a in 0..3 {
                    self.v[a] -= field_change[a] * dt;
                }
            }
        }
        // Euler's equations in the world frame: I w' = T - w x (I w).
        let rot = self.q.to_rotation_matrix();
        let i_body = Matrix3::from_diagonal(&Vector3::new(inertia[0], inertia[1], inertia[2]));
        let i_world = rot.matrix() * i_body * rot.matrix().transpose();
        let w = Vector3::new(self.w[0], self.w[1], self.w[2]);
        let rhs = Vector3::new(t[0], t[1], t[2]) - w.cross(&(i_world * w));
        let alpha = i_world.try_inverse().map(|inv| inv * rhs).unwrap_or_else(Vector3::zeros);
        for a in 0..3 {
            self.w[a] += damp(alpha[a], self.w[a]) * dt;
        }
        let wn = Vector3::new(self.w[0], self.w[1], self.w[2]);
        *self.q = UnitQuaternion::from_scaled_axis(wn * dt) * *self.q;
    }
}
