//! The potential particles of a simulation, as arrays (one entry per particle), and their shapes.

use super::shape::PotentialShape;
use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use nalgebra::UnitQuaternion;
use std::sync::Arc;

/// Potential particles: rigid bodies of a [`PotentialShape`] each. A `fixed` particle is moved
/// only by its own velocity and spin (a wall or a container part made of a potential particle):
/// forces do not change them, and it counts as infinitely heavy in its contacts.
#[derive(Debug, Clone, Default)]
pub struct Potentials {
    /// The distinct shapes; `shape[i]` indexes them.
    pub shapes: Vec<Arc<PotentialShape>>,
    pub shape: Vec<u32>,
    pub id: Vec<u64>,
    pub material: Vec<u16>,
    /// Centre of mass, velocity and angular velocity (world frame).
    pub x: Vec<Vec3>,
    pub v: Vec<Vec3>,
    pub w: Vec<Vec3>,
    /// Orientation: body (principal) frame to world.
    pub q: Vec<UnitQuaternion<f64>>,
    pub mass: Vec<f64>,
    /// Principal moments of inertia (body frame).
    pub inertia: Vec<Vec3>,
    pub fixed: Vec<bool>,
    /// Force and torque of the last step's contacts.
    pub force: Vec<Vec3>,
    pub torque: Vec<Vec3>,
    /// Each particle's potential where it is, placed anew at every step before detection (kept
    /// for its storage).
    pub(crate) placed: Vec<super::Placed>,
}

impl Potentials {
    pub fn len(&self) -> usize {
        self.x.len()
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// The index of `shape` among the distinct shapes, added if new.
    pub fn shape_index(&mut self, shape: &Arc<PotentialShape>) -> u32 {
        match self.shapes.iter().position(|s| Arc::ptr_eq(s, shape) || **s == **shape) {
            Some(i) => i as u32,
            None => {
                self.shapes.push(shape.clone());
                (self.shapes.len() - 1) as u32
            }
        }
    }

    pub fn shape_of(&self, i: usize) -> &PotentialShape {
        &self.shapes[self.shape[i] as usize]
    }

    /// The bounding radius of each particle (their broad phase sees them as these spheres).
    pub fn bounding_radii(&self) -> Vec<f64> {
        (0..self.len()).map(|i| self.shape_of(i).bounding_radius).collect()
    }

    /// Adds a particle; its mass and inertia follow from the shape and `density`.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn push(
        &mut self,
        id: u64,
        shape: &Arc<PotentialShape>,
        material: u16,
        density: f64,
        x: Vec3,
        q: UnitQuaternion<f64>,
        v: Vec3,
        fixed: bool,
    ) -> Result<usize> {
        let mass = density * shape.volume;
        let inertia = shape.inertia_per_density.map(|m| density * m);
        let finite = |v: Vec3| v.iter().all(|c| c.is_finite());
        if !(mass > 0.0 && mass.is_finite() && finite(inertia) && finite(x) && finite(v)) {
            return Err(GraniteError::Setup(format!(
                "a potential particle at {x:?} with velocity {v:?}, mass {mass:e} kg and inertia {inertia:?}: position and \
                 velocity must be finite, mass and inertia finite and > 0"
            )));
        }
        let index = self.shape_index(shape);
        self.shape.push(index);
        self.id.push(id);
        self.material.push(material);
        self.x.push(x);
        self.v.push(v);
        self.w.push([0.0; 3]);
        self.q.push(q);
        self.mass.push(mass);
        self.inertia.push(inertia);
        self.fixed.push(fixed);
        self.force.push([0.0; 3]);
        self.torque.push([0.0; 3]);
        Ok(self.len() - 1)
    }

    /// Keeps the particles whose flag is true, in order.
    pub(crate) fn retain(&mut self, keep: &[bool]) {
        fn kept<T: Clone>(v: &mut Vec<T>, keep: &[bool]) {
            let mut k = keep.iter();
            v.retain(|_| *k.next().unwrap_or(&true));
        }
        kept(&mut self.shape, keep);
        kept(&mut self.id, keep);
        kept(&mut self.material, keep);
        kept(&mut self.x, keep);
        kept(&mut self.v, keep);
        kept(&mut self.w, keep);
        kept(&mut self.q, keep);
        kept(&mut self.mass, keep);
        kept(&mut self.inertia, keep);
        kept(&mut self.fixed, keep);
        kept(&mut self.force, keep);
        kept(&mut self.torque, keep);
        self.placed.clear();
    }

    /// The world positions of the monitor points (see [`PotentialShape::monitor_points`]) of the
    /// free particles: fixed ones are container parts, not grains of the heap.
    pub fn monitor_positions(&self) -> Vec<Vec3> {
        let mut out = Vec::new();
        for i in (0..self.len()).filter(|&i| !self.fixed[i]) {
            let rot = self.q[i].to_rotation_matrix();
            for b in &self.shape_of(i).monitor_points {
                let w = rot * nalgebra::Vector3::new(b[0], b[1], b[2]);
                out.push([self.x[i][0] + w[0], self.x[i][1] + w[1], self.x[i][2] + w[2]]);
            }
        }
        out
    }

    /// Places every particle's potential where the particle is now.
    pub(crate) fn place_all(&mut self) {
        self.placed.resize_with(self.len(), Default::default);
        for i in 0..self.len() {
            let pose = self.pose(i);
            let shape = &self.shapes[self.shape[i] as usize];
            self.placed[i].place(shape, &pose);
        }
    }

    /// The pose of particle `i` for contact detection.
    pub fn pose(&self, i: usize) -> super::Pose {
        super::Pose { position: self.x[i], rotation: *self.q[i].to_rotation_matrix().matrix() }
    }

    /// Mass as its contacts see it: infinite for a fixed particle.
    pub fn contact_mass(&self, i: usize) -> f64 {
        if self.fixed[i] {
            f64::INFINITY
        } else {
            self.mass[i]
        }
    }
}
