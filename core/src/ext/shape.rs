//! Grain shape models: a grain is a rigid set of spheres (one sphere, or the members of a clump),
//! given around its reference point. Generators place and orient them; the engine integrates
//! multi-sphere grains as clumps. Grains of other shapes (potential particles, capsules) are body
//! kinds (`ext::body`).

use crate::error::Result;
use crate::math::Vec3;
use crate::params::{ParamSpec, Params};

pub trait ShapeModel: Send + Sync {
    fn name(&self) -> &str;
    fn params(&self) -> &Params;
    /// Member spheres `(centre relative to the reference point, radius)`.
    fn members(&self) -> Vec<(Vec3, f64)>;
    /// Radius of the sphere around the reference point that holds every member.
    fn bounding_radius(&self) -> f64 {
        self.members().iter().map(|(c, r)| (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt() + r).fold(0.0, f64::max)
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
