//! Body kinds: rigid bodies of a shape a plugin brings (capsules, potential particles, ...),
//! beside the engine's own spheres and clumps. A kind registers a factory that builds its shapes
//! from parameters and the contact geometry of its pairs: with one another, with plane walls and
//! with spheres, each called once per pair list (YADE's `Ig2` functors, without a virtual call per
//! contact; a kind may also meet walls of bounded shapes). The engine keeps the bodies (pose, velocity, mass properties), finds candidate pairs
//! from their bounding spheres, runs the registered contact laws on what the geometry found, sums
//! the loads in pair order and moves the bodies (`dem::kinds`).
//!
//! Once a step the geometry places the bodies where they are ([`BodyGeometry::place`]: a
//! potential particle moves its planes into the world frame there); the three pair lists are then
//! handed to what it placed. A geometry whose solve starts from the last step's solution keeps
//! values per pair ([`BodyGeometry::warm_values`]) that the engine stores with the pair.
//!
//! Bodies of two families meet where a plugin registers the geometry of their pair
//! ([`BodyPairGeometry`], `Registry::add_body_pair_geometry`): a scene holding several families
//! calls each family's geometry, and each pair geometry, once a step on its share of a list.

use crate::error::Result;
use crate::math::Vec3;
use crate::params::{ParamMap, ParamSpec, Params};
use nalgebra::UnitQuaternion;
use rayon::prelude::*;
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
    /// Whether point `p` (body frame) lies in the body: what the void ratio's sub-volume method
    /// asks.
    fn contains(&self, p: Vec3) -> bool;
    /// Points (body frame) the heap measures follow the body by; its centre of mass unless the
    /// kind says better.
    fn monitor_points(&self) -> Vec<Vec3> {
        vec![[0.0; 3]]
    }
    /// The shape as its own type, for its kind's geometry to read once a step (never per
    /// contact).
    fn as_any(&self) -> &dyn std::any::Any;
}

/// A body kind as the registry holds it.
pub trait BodyKindFactory: Send + Sync {
    fn name(&self) -> &str;
    fn description(&self) -> &str {
        ""
    }
    /// The geometry family the kind's bodies belong to: kinds of one family share a geometry and
    /// meet in one simulation (a rounded tetrahedron and a rounded box are both potential
    /// particles). The kind's own name unless it says otherwise.
    fn family(&self) -> &str {
        self.name()
    }
    fn param_specs(&self) -> &[ParamSpec];
    /// A shape of this kind from resolved parameters.
    fn build(&self, params: Params) -> Result<Arc<dyn BodyShape>>;
    /// A shape from parameters as a user or a saved state gives them ([`BodyShape::params`]):
    /// checked against [`BodyKindFactory::param_specs`], then built. A kind whose shapes take a
    /// list of values (the planes of a potential particle) reads them here itself.
    fn build_from(&self, given: &ParamMap) -> Result<Arc<dyn BodyShape>> {
        self.build(Params::resolve(&format!("{} body", self.name()), self.param_specs(), given)?)
    }
    /// Values each shape gives its geometry ([`BodyShape::values`]).
    fn values_per_shape(&self) -> usize;
    /// The contact geometry of this kind's pairs.
    fn geometry(&self) -> Arc<dyn BodyGeometry>;
}

/// The bodies of a simulation as a family's geometry reads them, at the start of a step: centres
/// of mass, orientations (body frame to world), each body's shape values (`stride` a body: the
/// most any family in the scene gives, a family's own first), each body's shape among the
/// distinct `shapes`, and each body's family. A geometry is handed pairs of its `own` family's
/// bodies only; where several families meet, the arrays hold the others' bodies too.
#[derive(Clone, Copy)]
pub struct KindBodies<'a> {
    pub x: &'a [Vec3],
    pub q: &'a [UnitQuaternion<f64>],
    pub values: &'a [f64],
    pub stride: usize,
    pub shape: &'a [u32],
    pub shapes: &'a [Arc<dyn BodyShape>],
    pub family: &'a [u16],
    pub own: u16,
}

impl KindBodies<'_> {
    /// The shape values of body `i`.
    pub fn values_of(&self, i: usize) -> &[f64] {
        &self.values[i * self.stride..(i + 1) * self.stride]
    }

    /// Whether body `i` is of this view's own family.
    pub fn owns(&self, i: usize) -> bool {
        self.family[i] == self.own
    }

    /// The shape of body `i`.
    pub fn shape_of(&self, i: usize) -> &dyn BodyShape {
        self.shapes[self.shape[i] as usize].as_ref()
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
/// the bodies live on; `part`: which of the geometry's contact points with a wall this pair is
/// (`0..BodyGeometry::wall_points()`).
#[derive(Debug, Clone, Copy)]
pub struct Plane {
    pub point: Vec3,
    pub normal: Vec3,
    pub part: u8,
}

/// A sphere as a geometry meets it.
#[derive(Debug, Clone, Copy)]
pub struct Ball {
    pub centre: Vec3,
    pub radius: f64,
}

/// The values a geometry keeps per pair of a list from one step to the next (its warm starts),
/// `count` a pair: they sit in the pair's history after its law's (`stride` values a pair from
/// `offset`). They start at zero for a new pair and stay while the pair is a candidate.
pub struct WarmStarts<'a> {
    history: &'a mut [f64],
    stride: usize,
    offset: usize,
    count: usize,
}

impl<'a> WarmStarts<'a> {
    /// The warm starts of a list whose history holds `stride` values a pair, the geometry's
    /// `count` from `offset`.
    pub fn new(history: &'a mut [f64], stride: usize, offset: usize, count: usize) -> WarmStarts<'a> {
        assert!(offset + count <= stride || count == 0, "warm starts beyond a pair's history");
        WarmStarts { history, stride, offset, count }
    }

    pub fn count(&self) -> usize {
        self.count
    }

    /// Each pair's values, in pair order (empty slices when the geometry keeps none).
    pub fn per_pair(&mut self) -> Vec<&mut [f64]> {
        let (offset, count) = (self.offset, self.count);
        if count == 0 {
            return Vec::new();
        }
        self.history.chunks_mut(self.stride).map(|c| &mut c[offset..offset + count]).collect()
    }

    /// Each pair's values for a parallel pass, in pair order (`count` must be > 0).
    pub fn par_per_pair(&mut self) -> impl IndexedParallelIterator<Item = &mut [f64]> + '_ {
        let (offset, count) = (self.offset, self.count);
        self.history.par_chunks_mut(self.stride.max(1)).map(move |c| &mut c[offset..offset + count])
    }
}

/// A contact a geometry could not settle: the pair (its index in the list) and why.
#[derive(Debug, Clone, PartialEq)]
pub struct PairFailure {
    pub pair: usize,
    pub reason: String,
}

/// The contact geometry of bodies of two families (a capsule and a potential particle), which a
/// plugin knowing both registers (`Registry::add_body_pair_geometry`): the geometry of a pair of
/// shapes, as YADE's `Ig2` functors, called once per pair list.
pub trait BodyPairGeometry: Send + Sync {
    /// The two families, in the order of the pairs' bodies.
    fn families(&self) -> [&str; 2];
    /// Its name in listings: the families joined, `capsule_potential`.
    fn name(&self) -> String {
        let [a, b] = self.families();
        format!("{a}_{b}")
    }
    fn description(&self) -> &str {
        ""
    }
    /// Values each pair keeps for the geometry from one step to the next ([`WarmStarts`]).
    fn warm_values(&self) -> usize {
        0
    }
    /// Pairs `(i, j)`, `i` of the first family (`first.own`), `j` of the second; the normal points
    /// from `i` to `j`. Fills `out` (as long as the list) with a touch, or None where the two are
    /// apart.
    fn pairs(
        &self,
        first: KindBodies<'_>,
        second: KindBodies<'_>,
        pairs: &[(u32, u32)],
        warm: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure>;
}

/// The contact geometry of a body kind: the bodies placed once a step, then the pair lists.
pub trait BodyGeometry: Send + Sync {
    /// Values each pair keeps for the geometry from one step to the next ([`WarmStarts`]).
    fn warm_values(&self) -> usize {
        0
    }
    /// Contact points a body of the kind may have with one wall (a capsule lying on a plane
    /// bears on both ends): each body-wall candidate is that many pairs, `part` 0, 1, ..., each
    /// with its own force and history (a contact manifold). One unless the kind says more.
    fn wall_points(&self) -> usize {
        1
    }
    /// Contact points a body of the kind may have with another of its family (two capsules
    /// side by side bear at both ends of their overlap): each candidate pair of them is that many
    /// pairs, `part` 0, 1, ..., each with its own force and history. One unless the kind says
    /// more; a pair of two families (a `BodyPairGeometry`) has one.
    fn body_points(&self) -> usize {
        1
    }
    /// Whether its bodies meet walls of bounded shapes ([`PlacedBodies::bounded_walls`]);
    /// otherwise plane walls only, and a scene with another wall is refused before its first step.
    fn meets_bounded_walls(&self) -> bool {
        false
    }
    /// The bodies where they are at this step's start, ready for the pair lists.
    fn place<'a>(&'a self, bodies: KindBodies<'a>) -> Result<Box<dyn PlacedBodies + 'a>>;
}

/// A kind's bodies placed for a step. Each call takes a whole pair list and fills `out` (as long
/// as the list): a touch, or None where the two are apart; `warm` holds the list's warm starts.
pub trait PlacedBodies: Sync {
    /// Pairs of bodies of this kind, `(i, j, part)`; the normal points from `i` to `j`; `part`
    /// is which of the kind's [`BodyGeometry::body_points`] the pair is.
    fn pairs(
        &self,
        pairs: &[(u32, u32, u8)],
        warm: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure>;
    /// Bodies against plane walls, `(i, plane)`; the normal points from the body into the wall.
    fn planes(
        &self,
        pairs: &[(u32, Plane)],
        warm: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure>;
    /// Bodies against walls of bounded shapes (rectangles, disks, cylinders, the triangles of a
    /// wall mesh: `Wall::contact` gives a sphere's contact with any of them), `(i, wall)`; the
    /// normal points from the body into the wall. Called only for a kind whose geometry says it
    /// meets them ([`BodyGeometry::meets_bounded_walls`]); the third of a pair is its `part`, as
    /// [`Plane::part`].
    fn bounded_walls(
        &self,
        pairs: &[(u32, &crate::dem::walls::Wall, u8)],
        warm: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure> {
        let _ = (warm, out);
        Err(PairFailure {
            pair: 0,
            reason: format!("{} bounded walls met by a kind that meets planes only", pairs.len()),
        })
    }
    /// Bodies against spheres, `(i, sphere)`; the normal points from the body to the sphere.
    fn spheres(
        &self,
        pairs: &[(u32, Ball)],
        warm: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure>;
}
