//! Constitutive laws: pure functions of (stress, strain increment, state) -> (new stress, new state),
//! called over batches of material points so that one virtual call serves many points.

use crate::error::Result;
use crate::math::Voigt;
use crate::params::{ParamSpec, Params};

/// The points a law updates in one call. All slices have the same number of points `n`;
/// `state` holds `n * state_names().len()` values, point after point.
pub struct LawBatch<'a> {
    /// Stress at the start of the increment on entry, updated stress on return (tension positive).
    pub stress: &'a mut [Voigt],
    /// Strain increment (engineering shear) of this step.
    pub dstrain: &'a [Voigt],
    /// State variables, point-major.
    pub state: &'a mut [f64],
}

impl LawBatch<'_> {
    pub fn len(&self) -> usize {
        self.stress.len()
    }
    pub fn is_empty(&self) -> bool {
        self.stress.is_empty()
    }
}

/// A constitutive law with its parameters fixed (one per material).
pub trait ConstitutiveLaw: Send + Sync {
    /// Registry name of the law (e.g. `mohr_coulomb`).
    fn name(&self) -> &str;
    /// Parameters in force, by name.
    fn params(&self) -> &Params;
    /// Names of the per-point state variables, in storage order.
    fn state_names(&self) -> &[&'static str] {
        &[]
    }
    /// Initial state of one point (defaults to zeros).
    fn init_state(&self, state: &mut [f64]) {
        state.fill(0.0);
    }
    /// Speed of the fastest (P) wave for a given density, used to check the time step.
    fn wave_speed(&self, _density: f64) -> Option<f64> {
        None
    }
    /// Updates stress and state of a batch of points from their strain increments.
    fn update(&self, batch: LawBatch<'_>) -> Result<()>;
}

/// Builds a law from user parameters; this is what the registry stores under the law's name.
pub trait ConstitutiveLawFactory: Send + Sync {
    fn name(&self) -> &str;
    fn param_specs(&self) -> &[ParamSpec];
    /// Validates the parameters (a clear error names any bad one) and builds the law.
    fn build(&self, params: Params) -> Result<Box<dyn ConstitutiveLaw>>;
    fn description(&self) -> &str {
        ""
    }
}
