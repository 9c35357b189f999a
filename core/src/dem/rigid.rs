//! What the stages of rigid bodies of plugin kinds use: the contact laws run on their touching
//! pairs in pair order, and the bodies moved by their loads.

use crate::dem::contacts::PairList;
use crate::dem::motion::{RigidBody, RigidMotion};
use crate::ext::{ContactBatch, ContactLaw};
use crate::math::{sub3, Vec3};
use nalgebra::UnitQuaternion;
use std::sync::Arc;

/// One touching contact as a law takes it: its slot in the list, normal, overlap, velocity of
/// the second body relative to the first at the contact point, and relative spin.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LawContact {
    pub slot: usize,
    pub normal: Vec3,
    pub overlap: f64,
    pub rel_velocity: Vec3,
    pub rel_spin: Vec3,
}

/// Runs each law on the touching contacts of `list` that are its own, in pair order; the force
/// and extra moment on each contact's first body, in the order of `touching`.
pub(crate) fn laws_in_pair_order(
    laws: &[Arc<dyn ContactLaw>],
    list: &mut PairList,
    touching: &[LawContact],
    dt: f64,
) -> (Vec<Vec3>, Vec<Vec3>) {
    let n = touching.len();
    let (mut force, mut moment) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
    let strides = (list.param_stride, list.history_stride);
    for (l, law) in laws.iter().enumerate() {
        let members: Vec<usize> = (0..n).filter(|&e| list.law[touching[e].slot] as usize == l).collect();
        if members.is_empty() {
            continue;
        }
        let pick = |f: &dyn Fn(&LawContact) -> Vec3| members.iter().map(|&e| f(&touching[e])).collect::<Vec<Vec3>>();
        let normal = pick(&|c| c.normal);
        let rel_velocity = pick(&|c| c.rel_velocity);
        let rel_spin = pick(&|c| c.rel_spin);
        let overlap: Vec<f64> = members.iter().map(|&e| touching[e].overlap).collect();
        let slot: Vec<u32> = members.iter().map(|&e| touching[e].slot as u32).collect();
        let (mut f, mut m) = (vec![[0.0; 3]; members.len()], vec![[0.0; 3]; members.len()]);
        law.compute(ContactBatch {
            normal: &normal,
            overlap: &overlap,
            rel_velocity: &rel_velocity,
            rel_spin: &rel_spin,
            slot: &slot,
            strides,
            params: &list.params,
            history: &mut list.history,
            force: &mut f,
            moment: &mut m,
            dt,
        });
        for (s, &e) in members.iter().enumerate() {
            force[e] = f[s];
            moment[e] = m[s];
        }
    }
    (force, moment)
}

/// A set of rigid bodies as a step moves them.
pub(crate) struct RigidSet<'a> {
    pub x: &'a mut [Vec3],
    pub v: &'a mut [Vec3],
    pub w: &'a mut [Vec3],
    pub q: &'a mut [UnitQuaternion<f64>],
    pub mass: &'a [f64],
    pub inertia: &'a [Vec3],
    pub fixed: &'a [bool],
    pub force: &'a [Vec3],
    pub torque: &'a [Vec3],
}

/// Moves every body one step: a fixed one by its own velocity and spin only, the others by their
/// loads, gravity and damping. The largest distance a centre moved from `x_at_build`, or the
/// first body whose position or velocity stopped being finite.
pub(crate) fn move_rigid_bodies(set: RigidSet<'_>, x_at_build: &[Vec3], motion: &RigidMotion) -> Result<f64, usize> {
    let RigidSet { x, v, w, q, mass, inertia, fixed, force, torque } = set;
    let dt = motion.dt;
    let mut moved: f64 = 0.0;
    for i in 0..x.len() {
        if fixed[i] {
            for a in 0..3 {
                x[i][a] += v[i][a] * dt;
            }
            let spin = nalgebra::Vector3::new(w[i][0], w[i][1], w[i][2]);
            q[i] = UnitQuaternion::from_scaled_axis(spin * dt) * q[i];
        } else {
            let body = RigidBody { x: &mut x[i], v: &mut v[i], w: &mut w[i], q: &mut q[i] };
            body.advance((mass[i], inertia[i]), (force[i], torque[i]), motion);
        }
        // In a periodic cell, measured from where the cell's field has carried the build's place.
        let built = x_at_build.get(i).copied().unwrap_or(x[i]);
        let reference = match &motion.affine {
            Some((_, deformation)) => crate::math::mat_vec(deformation, built),
            None => built,
        };
        let d = sub3(x[i], reference);
        let distance = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if !(distance.is_finite() && v[i].iter().chain(&w[i]).all(|c| c.is_finite())) {
            return Err(i);
        }
        moved = moved.max(distance);
    }
    Ok(moved)
}
