//! Body kinds: rigid bodies of a shape a plugin brings (capsules, ...), beside the engine's own
//! spheres and clumps. A kind registers a factory that builds its shapes from parameters and the
//! contact geometry of its pairs: with one another, with plane walls and with spheres, each
//! called once per pair list (YADE's `Ig2` functors, without a virtual call per contact). The
//! engine keeps the bodies (pose, velocity, mass properties), finds candidate pairs from their
//! bounding spheres, runs the registered contact laws on what the geometry found, sums the loads
//! in pair order and moves the bodies (`dem::kinds`).

use crate::error::Result;
use crate::math::Vec3;
use crate::params::{ParamSpec, Params};
use nalgebra::UnitQuaternion;
use std::sync::Arc;

/// One shape of a body kind, in its body frame: the centre of mass at the origin, principal
/// axes along the frame's axes.
pub trait BodyShape: Send + Sync + std::fmt::Debug {
    /// The kind's registered name.
    fn kind(&self) -> &str;
    /// The parameters it was built from (what a saved state rebuilds it with).
    fn params(&self) -> crate::params::ParamMap;
    /// What the kind's geometry reads of the shape (a capsule: radius and half length), as many
    /// values for every shape of the kind ([`BodyKindFactory::values_per_shape`]).
    fn values(&self) -> Vec<f64>;
    /// Radius of the sphere about the centre of mass holding the body.
    fn bounding_radius(&self) -> f64;
    /// Volume (m^3).
    fn volume(&self) -> f64;
    /// Principal moments of inertia about the centre of mass per unit density (m^5).
    fn inertia_per_density(&self) -> Vec3;
    /// A closed triangulated surface (vertices, triangles) for pictures.
    fn surface(&self) -> (Vec<Vec3>, Vec<[usize; 3]>);
}

/// A body kind as the registry holds it.
pub trait BodyKindFactory: Send + Sync {
    fn name(&self) -> &str;
    fn description(&self) -> &str {
        ""
    }
    fn param_specs(&self) -> &[ParamSpec];
    /// A shape of this kind from resolved parameters.
    fn build(&self, params: Params) -> Result<Arc<dyn BodyShape>>;
    /// Values each shape gives its geometry ([`BodyShape::values`]).
    fn values_per_shape(&self) -> usize;
    /// The contact geometry of this kind's pairs.
    fn geometry(&self) -> Arc<dyn BodyGeometry>;
}

/// Bodies of one kind as their geometry reads them, at the start of a step: centres of mass,
/// orientations (body frame to world), and each body's shape values (`stride` a body).
pub struct KindBodies<'a> {
    pub x: &'a [Vec3],
    pub q: &'a [UnitQuaternion<f64>],
    pub values: &'a [f64],
    pub stride: usize,
}

impl KindBodies<'_> {
    /// The shape values of body `i`.
    pub fn values_of(&self, i: usize) -> &[f64] {
        &self.values[i * self.stride..(i + 1) * self.stride]
    }
}

/// Where two bodies touch: the unit normal from the first body to the second, the overlap
/// (positive: they interpenetrate by that much along the normal), and the contact point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Touch {
    pub normal: Vec3,
    pub overlap: f64,
    pub point: Vec3,
}

/// A plane wall as a geometry meets it: a point on it and its unit normal, pointing to the side
/// the bodies live on.
#[derive(Debug, Clone, Copy)]
pub struct Plane {
    pub point: Vec3,
    pub normal: Vec3,
}

/// A sphere as a geometry meets it.
#[derive(Debug, Clone, Copy)]
pub struct Ball {
    pub centre: Vec3,
    pub radius: f64,
}

/// The contact geometry of a body kind. Each call takes a whole pair list and fills `out` (as
/// long as the list): a touch, or None where the two are apart.
pub trait BodyGeometry: Send + Sync {
    /// Pairs of bodies of this kind, `(i, j)`; the normal points from `i` to `j`.
    fn pairs(&self, bodies: &KindBodies<'_>, pairs: &[(u32, u32)], out: &mut [Option<Touch>]);
    /// Bodies against plane walls, `(i, plane)`; the normal points from the body into the wall.
    fn planes(&self, bodies: &KindBodies<'_>, pairs: &[(u32, Plane)], out: &mut [Option<Touch>]);
    /// Bodies against spheres, `(i, sphere)`; the normal points from the body to the sphere.
    fn spheres(&self, bodies: &KindBodies<'_>, pairs: &[(u32, Ball)], out: &mut [Option<Touch>]);
}
