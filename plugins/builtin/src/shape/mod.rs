//! Grain shapes: a sphere, the 4-sphere tetrahedral clump of the JGS round robin (thesis 2.2.1,
//! table 2.3); and two body kinds of their own: potential particles (`potential/`: the rounded
//! tetrahedron fitted to that clump, thesis 2.2.2.2, table 2.2, rounded boxes, the thesis's
//! container parts, and planes of the user's own) and capsules (`capsule.rs`), which meet one
//! another (`capsule_potential.rs`).

use granite_core::dem::clump::tetrahedral_members;
use granite_core::ext::{BodyPairGeometry, ShapeModel, ShapeModelFactory};
use granite_core::math::Vec3;
use granite_core::params::{ParamSpec, Params};
use granite_core::{Registry, Result};
use std::sync::Arc;

pub mod capsule;
pub mod capsule_potential;
pub mod potential;

pub fn register(registry: &mut Registry) {
    registry.add_body_kind(Arc::new(capsule::CapsuleKind));
    registry.add_shape(Arc::new(SphereFactory));
    registry.add_shape(Arc::new(TetraFactory));
    registry.add_body_kind(Arc::new(potential::PotentialTetraKind));
    registry.add_body_kind(Arc::new(potential::PotentialBoxKind));
    registry.add_body_kind(Arc::new(potential::PotentialPlanesKind));
    for geometry in body_pair_geometries() {
        registry.add_body_pair_geometry(geometry);
    }
}

/// The geometries of pairs of the body families above: capsules with potential particles.
pub fn body_pair_geometries() -> Vec<Arc<dyn BodyPairGeometry>> {
    vec![Arc::new(capsule_potential::CapsulePotential)]
}

struct Shape {
    name: &'static str,
    params: Params,
    members: Vec<(Vec3, f64)>,
}

impl ShapeModel for Shape {
    fn name(&self) -> &str {
        self.name
    }
    fn params(&self) -> &Params {
        &self.params
    }
    fn members(&self) -> Vec<(Vec3, f64)> {
        self.members.clone()
    }
}

pub struct SphereFactory;

const SPHERE: &[ParamSpec] = &[ParamSpec::required("radius", "sphere radius in m, > 0")];

impl ShapeModelFactory for SphereFactory {
    fn name(&self) -> &str {
        "sphere"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        SPHERE
    }
    fn description(&self) -> &str {
        "a single sphere"
    }
    fn build(&self, params: Params) -> Result<Box<dyn ShapeModel>> {
        let r = params.positive("radius")?;
        Ok(Box::new(Shape { name: "sphere", members: vec![([0.0; 3], r)], params }))
    }
}

pub struct TetraFactory;

const TETRA: &[ParamSpec] = &[
    ParamSpec::optional("r_sphere", 0.3101e-2, "member radius r_s in m (table 2.3: 3.101 mm)"),
    ParamSpec::optional("r_clump", 0.5e-2, "radius of the sphere the clump is inscribed in (table 2.3: 5 mm)"),
];

impl ShapeModelFactory for TetraFactory {
    fn name(&self) -> &str {
        "tetra"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        TETRA
    }
    fn description(&self) -> &str {
        "4 spheres at the vertices of a regular tetrahedron (JGS round robin)"
    }
    fn build(&self, params: Params) -> Result<Box<dyn ShapeModel>> {
        let members = tetrahedral_members([0.0; 3], params.positive("r_sphere")?, params.positive("r_clump")?)?;
        Ok(Box::new(Shape { name: "tetra", members, params }))
    }
}

/// The least of `g` on `[lo, hi]` by a golden-section search of `steps` steps (the bracket
/// shrinks by 0.618 a step), for a function with one least there: `(t, g(t))`.
pub(crate) fn golden_least(g: &impl Fn(f64) -> f64, (mut lo, mut hi): (f64, f64), steps: usize) -> (f64, f64) {
    let ratio = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (hi - ratio * (hi - lo), lo + ratio * (hi - lo));
    let (mut ga, mut gb) = (g(a), g(b));
    for _ in 0..steps {
        if ga <= gb {
            (hi, b, gb) = (b, a, ga);
            a = hi - ratio * (hi - lo);
            ga = g(a);
        } else {
            (lo, a, ga) = (a, b, gb);
            b = lo + ratio * (hi - lo);
            gb = g(b);
        }
    }
    if ga <= gb {
        (a, ga)
    } else {
        (b, gb)
    }
}
