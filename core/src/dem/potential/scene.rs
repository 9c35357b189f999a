//! Adding potential particles to a simulation.

use super::shape::PotentialShape;
use crate::dem::sim::{DemSim, MIXED_SHAPES};
use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use nalgebra::UnitQuaternion;
use std::sync::Arc;

impl DemSim {
    /// Adds a potential particle of `shape` and `material` with its centre of mass at `x`, turned
    /// by `q` from its body frame, moving at `v`; a `fixed` one moves only with its own velocity
    /// (a wall). Returns its index.
    pub fn add_potential(
        &mut self,
        material: u16,
        shape: &Arc<PotentialShape>,
        x: Vec3,
        q: UnitQuaternion<f64>,
        v: Vec3,
        fixed: bool,
    ) -> Result<usize> {
        if !self.spheres.is_empty() {
            return Err(GraniteError::Setup(MIXED_SHAPES.into()));
        }
        if self.energy.is_some() {
            return Err(GraniteError::Setup(
                "the energy tracker covers spheres and clumps: turn it off (track_energy(false)) before adding potential particles"
                    .into(),
            ));
        }
        let density = self
            .materials
            .get(material as usize)
            .ok_or_else(|| GraniteError::Setup(format!("no material with index {material}")))?
            .density;
        let i = self.potentials.push(self.next_id, shape, material, density, x, q, v, fixed)?;
        self.next_id += 1;
        self.needs_rebuild = true;
        Ok(i)
    }

    /// Removes the potential particles whose flag is false; the pairs of those that stay keep
    /// their history.
    pub fn remove_potentials(&mut self, keep: &[bool]) {
        self.potentials.retain(keep);
        self.potential_pairs.retain_spheres(keep, true);
        self.potential_wall_pairs.retain_spheres(keep, false);
        let mut k = keep.iter();
        self.potential_x_at_build.retain(|_| *k.next().unwrap_or(&true));
        self.needs_rebuild = true;
    }
}
