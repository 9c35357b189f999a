//! Grain shape models: a grain is a rigid set of spheres (one sphere, or the members of a clump),
//! given around its reference point, or a potential particle (a rounded convex polyhedron,
//! `dem::potential`). Generators place and orient them; the engine integrates multi-sphere grains
//! as clumps and potential particles as rigid bodies of their own.

use crate::error::Result;
use crate::math::Vec3;
use crate::params::{ParamSpec, Params};

pub trait ShapeModel: Send + Sync {
    fn name(&self) -> &str;
    fn params(&self) -> &Params;
    /// Member spheres `(centre relative to the reference point, radius)`; none for a potential
    /// particle.
    fn members(&self) -> Vec<(Vec3, f64)>;
    /// Radius of the sphere around the reference point that holds every member.
    fn bounding_radius(&self) -> f64 {
        if let Some(p) = self.potential() {
            return p.bounding_radius;
        }
        self.members().iter().map(|(c, r)| (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt() + r).fold(0.0, f64::max)
    }
    /// The grain as a potential particle (its reference point is its centre of mass), for shapes
    /// that are one rather than spheres.
    fn potential(&self) -> Option<std::sync::Arc<crate::dem::potential::PotentialShape>> {
        None
    }
}

pub trait ShapeModelFactory: Send + Sync {
    fn name(&self) -> &str;
    fn param_specs(&self) -> &[ParamSpec];
    fn build(&self, params: Params) -> Result<Box<dyn ShapeModel>>;
    fn description(&self) -> &str {
        ""
    }
}
