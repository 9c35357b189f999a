//! Constitutive laws (CB-Geo's materials as pure functions of stress, strain increment and state).

pub mod dem_rve;
pub mod dem_rve_adaptive;
mod dem_rve_device;
mod dem_rve_share;
pub mod elasticity;
pub mod linear_elastic;
pub mod mohr_coulomb;

use granite_core::Registry;
use std::sync::Arc;

pub fn register(registry: &mut Registry) {
    registry.add_law(Arc::new(linear_elastic::LinearElasticFactory));
    registry.add_law(Arc::new(mohr_coulomb::MohrCoulombFactory));
    registry.add_law(Arc::new(dem_rve::DemRveFactory));
}

/// Resolves parameters for a law's specs in unit tests.
#[cfg(test)]
pub(crate) fn test_params(
    specs: &[granite_core::params::ParamSpec],
    pairs: &[(&str, f64)],
) -> granite_core::Result<granite_core::params::Params> {
    let given = pairs.iter().map(|(k, v)| (k.to_string(), *v)).collect();
    granite_core::params::Params::resolve("law \"test\"", specs, &given)
}
