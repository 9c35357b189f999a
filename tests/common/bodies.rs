//! A DEM scene of bodies of plugin kinds built from Rust, for the capsule and body-family tests.

use granite_core::dem::kinds::NewBody;
use granite_core::dem::DemSim;
use granite_core::ext::BodyShape;
use granite_core::math::Vec3;
use granite_core::registry::{ParamMap, Registry};
use granite_plugins::shape::potential::planes_params;
use granite_plugins::shape::potential::shape::box_planes;
use nalgebra::{UnitQuaternion, Vector3};
use std::sync::Arc;

pub fn params(pairs: &[(&str, f64)]) -> ParamMap {
    pairs.iter().map(|(k, v)| (k.to_string(), *v)).collect()
}

pub struct Scene {
    pub registry: Registry,
    pub sim: DemSim,
    pub material: u16,
}

/// A scene with one material of `density` and the linear law of `law` parameters.
pub fn scene(density: f64, law: &[(&str, f64)]) -> Scene {
    let registry = granite_plugins::default_registry();
    let mut sim = DemSim::new();
    let material = sim.world.add_material("grains", density).unwrap();
    sim.world.set_contact_law(registry.build_contact_law("linear", &params(law)).unwrap(), None).unwrap();
    Scene { registry, sim, material }
}

impl Scene {
    pub fn capsule(&self, radius: f64, length: f64) -> Arc<dyn BodyShape> {
        self.registry.build_body_shape("capsule", &params(&[("radius", radius), ("length", length)])).unwrap()
    }

    /// A rounded box (a potential particle) of half sides `half`, rounding `r`, shadow sphere
    /// `big_r` and weight `k` (`k = 1`: a sphere of radius `big_r`).
    pub fn rounded_box(&self, half: [f64; 3], r: f64, big_r: f64, k: f64) -> Arc<dyn BodyShape> {
        let kind = self.registry.body_kind("potential").unwrap();
        kind.build_from(&planes_params(&box_planes(half), r, big_r, k)).unwrap()
    }

    /// Adds a body of `shape` moving at `[v, w]` (fixed: driven at them); its index.
    pub fn add_as(
        &mut self,
        shape: &Arc<dyn BodyShape>,
        x: Vec3,
        q: UnitQuaternion<f64>,
        [v, w]: [Vec3; 2],
        fixed: bool,
    ) -> usize {
        let kind = self.registry.body_kind(shape.kind()).unwrap().clone();
        let meetings = self.registry.body_pair_geometries();
        let (material, shape) = (self.material, shape.clone());
        let body = NewBody { kind: kind.as_ref(), meetings: &meetings, shape, material, x, q, v, w, fixed };
        self.sim.world.add_body(body).unwrap()
    }

    /// Adds a free body at rest.
    pub fn add(&mut self, shape: &Arc<dyn BodyShape>, x: Vec3, q: UnitQuaternion<f64>) -> usize {
        self.add_as(shape, x, q, [[0.0; 3]; 2], false)
    }

    /// Adds a free body moving at `v`, spinning at `w`.
    pub fn add_moving(
        &mut self,
        shape: &Arc<dyn BodyShape>,
        x: Vec3,
        q: UnitQuaternion<f64>,
        v: Vec3,
        w: Vec3,
    ) -> usize {
        self.add_as(shape, x, q, [v, w], false)
    }
}

/// The rotation taking the body's z axis to `axis`.
pub fn along(axis: [f64; 3]) -> UnitQuaternion<f64> {
    UnitQuaternion::rotation_between(&Vector3::z(), &Vector3::from(axis)).unwrap()
}

/// Grains of a body kind (`cloud`: the options of `clump_cloud` after `count`) poured into a
/// cylinder standing on a disk, and into the silo of scripts/dem/silo_outlet_15mm.stl (a wall
/// mesh: four sides and a floor with a 15 mm hole, closed by a rectangle just under it), let
/// settle for `time` s: for each container its name and summary, with `weight` (the grains'),
/// `carried` (by the walls), `lowest` (the lowest centre) and `wall_contacts`.
pub fn poured_into_containers(what: &str, cloud: &str, time: f64) -> Vec<(&'static str, serde_json::Value)> {
    let stl = super::script("dem/silo_outlet_15mm.stl");
    let cases = [
        (
            "disk",
            "let walls = [sim.wall_disk(m, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 0.05)];
        walls.push(sim.wall_cylinder(m, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 0.05, 0.3));"
                .to_string(),
            ([-0.03, -0.03], [0.03, 0.03]),
        ),
        (
            "silo",
            format!(
                "let walls = sim.wall_mesh(m, \"{}\", #{{ scale: 0.001 }});
        walls.push(sim.wall_rect(m, [0.03, 0.03, -0.0001], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.03, 0.03]));",
                stl.display()
            ),
            ([0.008, 0.008], [0.052, 0.052]),
        ),
    ];
    let mut out = Vec::new();
    for (name, walls, (lo, hi)) in cases {
        let source = format!(
            r#"
        let sim = dem(#{{ seed: 5 }});
        let m = sim.material(#{{ density: 2500.0 }});
        sim.contact_law("linear", #{{ kn: 2e4, kt_ratio: 0.5, friction: 25.0 }});
        sim.gravity([0.0, 0.0, -9.81]);
        {walls}
        sim.clump_cloud(m, [{}, {}, 0.01], [{}, {}, 0.13], #{{ {cloud} }});
        sim.damping(0.4);
        sim.dt(0.2 * sim.critical_dt());
        sim.run_until({time});
        let weight = 0.0;
        let lowest = 1.0;
        for id in sim.body_ids() {{
            let b = sim.body_state(id);
            weight += 9.81 * b.mass;
            lowest = min(lowest, b.position[2]);
        }}
        summary("weight", weight);
        summary("carried", -sim.wall_force(walls)[2]);
        summary("lowest", lowest);
        summary("wall_contacts", sim.contacts().filter(|c| c.kind1 != "sphere" && "wall" in c).len());
        "#,
            lo[0], lo[1], hi[0], hi[1]
        );
        let dir = super::run_text(&format!("{what}_in_{name}"), &source);
        let s = super::summary_of(&dir);
        eprintln!("{what} in the {name}: {s}");
        out.push((name, s));
    }
    out
}
