//! Grain shapes: a sphere, the 4-sphere tetrahedral clump of the JGS round robin (thesis 2.2.1,
//! table 2.3), and potential particles: the rounded tetrahedron fitted to that clump (thesis
//! 2.2.2.2, table 2.2) and rounded boxes (the thesis's container parts); and capsules, a body
//! kind of their own (`capsule.rs`).

use granite_core::dem::clump::tetrahedral_members;
use granite_core::dem::potential::shape::{box_planes, PotentialShape, MASS_RESOLUTION};
use granite_core::ext::{ShapeModel, ShapeModelFactory};
use granite_core::math::Vec3;
use granite_core::params::{ParamSpec, Params};
use granite_core::{Registry, Result};
use std::sync::Arc;

pub mod capsule;

pub fn register(registry: &mut Registry) {
    registry.add_body_kind(Arc::new(capsule::CapsuleKind));
    registry.add_shape(Arc::new(SphereFactory));
    registry.add_shape(Arc::new(TetraFactory));
    registry.add_shape(Arc::new(PotentialTetraFactory));
    registry.add_shape(Arc::new(PotentialBoxFactory));
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

/// A potential particle of a registered shape.
struct Potential {
    name: &'static str,
    params: Params,
    shape: Arc<PotentialShape>,
}

impl ShapeModel for Potential {
    fn name(&self) -> &str {
        self.name
    }
    fn params(&self) -> &Params {
        &self.params
    }
    fn members(&self) -> Vec<(Vec3, f64)> {
        Vec::new()
    }
    fn potential(&self) -> Option<Arc<PotentialShape>> {
        Some(self.shape.clone())
    }
}

pub struct PotentialTetraFactory;

const POTENTIAL_TETRA: &[ParamSpec] = &[
    ParamSpec::optional("r_sphere", 0.3101e-2, "radius r_s of the clump's spheres in m; the rounding radius r = r_s"),
    ParamSpec::optional("r_clump", 0.5e-2, "radius of the sphere the clump is inscribed in, in m"),
    ParamSpec::optional("k", 0.65, "sphericity, in (0, 1] (table 2.2's fit: 0.65)"),
    ParamSpec::unset("R", "shadow sphere's radius in m (default sqrt(2) r_s, the thesis's)"),
];

impl ShapeModelFactory for PotentialTetraFactory {
    fn name(&self) -> &str {
        "potential_tetra"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        POTENTIAL_TETRA
    }
    fn description(&self) -> &str {
        "potential particle: the rounded tetrahedron of thesis table 2.2, faces through the tetra clump's sphere centres"
    }
    fn build(&self, params: Params) -> Result<Box<dyn ShapeModel>> {
        let (r_s, r_clump) = (params.positive("r_sphere")?, params.positive("r_clump")?);
        let big_r = if params.is_set("R") { params.positive("R")? } else { 2f64.sqrt() * r_s };
        let shape = PotentialShape::rounded_tetrahedron(r_s, r_clump, big_r, params.get("k"))?;
        Ok(Box::new(Potential { name: "potential_tetra", params, shape: Arc::new(shape) }))
    }
}

pub struct PotentialBoxFactory;

const POTENTIAL_BOX: &[ParamSpec] = &[
    ParamSpec::required("hx", "half-size along x in m (the flat part; the rounding adds r)"),
    ParamSpec::required("hy", "half-size along y in m"),
    ParamSpec::required("hz", "half-size along z in m"),
    ParamSpec::unset("r", "rounding radius in m (default a tenth of the smallest half-size)"),
    ParamSpec::optional("k", 0.05, "sphericity, in (0, 1]: small keeps the faces flat (they bow by about k r / 8)"),
];

impl ShapeModelFactory for PotentialBoxFactory {
    fn name(&self) -> &str {
        "potential_box"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        POTENTIAL_BOX
    }
    fn description(&self) -> &str {
        "potential particle: a rounded box (container parts, as the thesis builds its devices)"
    }
    fn build(&self, params: Params) -> Result<Box<dyn ShapeModel>> {
        let half = [params.positive("hx")?, params.positive("hy")?, params.positive("hz")?];
        let smallest = half.iter().copied().fold(f64::INFINITY, f64::min);
        let r = if params.is_set("r") { params.positive("r")? } else { 0.1 * smallest };
        // The shadow sphere twice the box's half-diagonal: between a face's middle and its
        // corners the sphere term changes by 3/4 k, which moves the face by about k r / 8.
        let big_r = 2.0 * (half[0] * half[0] + half[1] * half[1] + half[2] * half[2]).sqrt();
        let shape = PotentialShape::new(&box_planes(half), r, big_r, params.get("k"), MASS_RESOLUTION)?;
        Ok(Box::new(Potential { name: "potential_box", params, shape: Arc::new(shape) }))
    }
}
