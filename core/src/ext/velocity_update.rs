//! Velocity-update strategies (thesis table 3.1): how a point's new velocity and its displacement
//! velocity are built from grid quantities interpolated at the point.

use crate::error::Result;
use crate::math::{Vec3, Voigt};
use crate::params::{ParamSpec, Params};

/// Interpolated grid quantities for a chunk of points, and the outputs the strategy writes.
pub struct G2pBatch<'a> {
    /// Point velocity at the start of the step.
    pub v_old: &'a [Vec3],
    /// `sum_i V~_i N_i` (eq. 3.28): the updated grid velocity interpolated at the point.
    pub v_pic: &'a [Vec3],
    /// `sum_i a_i N_i dt` (eq. 3.30): the grid velocity increment interpolated at the point, with
    /// `a_i = (V~_i - V_i)/dt` as applied (constraints included), so `v_pic - dv_grid` is the
    /// grid velocity before this step's forces, interpolated at the point.
    pub dv_grid: &'a [Vec3],
    /// Accumulated strain of each point (tension positive): its volumetric part tells a dilated
    /// point from a compressed one (ASFLIP's separation test).
    pub strain: &'a [Voigt],
    /// Velocity the point carries into the next step.
    pub v_new: &'a mut [Vec3],
    /// Velocity that moves the point this step: `x += v_move dt`.
    pub v_move: &'a mut [Vec3],
}

pub trait VelocityUpdate: Send + Sync {
    fn name(&self) -> &str;
    /// When true the engine keeps a per-point affine velocity matrix `C_p = sum_i V~_i (grad N_i)^T`
    /// and adds `m_p N_i C_p (x_i - x_p)` to the nodal momentum (APIC, Jiang et al. 2015).
    fn affine(&self) -> bool {
        false
    }
    fn update(&self, batch: G2pBatch<'_>);
    /// The parameters it was built with (to rebuild it from the registry, e.g. on restart).
    fn params(&self) -> crate::registry::ParamMap {
        crate::registry::ParamMap::new()
    }
}

pub trait VelocityUpdateFactory: Send + Sync {
    fn name(&self) -> &str;
    fn param_specs(&self) -> &[ParamSpec] {
        &[]
    }
    fn build(&self, params: Params) -> Result<Box<dyn VelocityUpdate>>;
    fn description(&self) -> &str {
        ""
    }
}
