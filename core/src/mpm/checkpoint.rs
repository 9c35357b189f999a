//! Checkpoints of a whole MPM simulation (points, laws with their state and objects, mesh,
//! boundary conditions, clock), so a resumed run continues exactly as an uninterrupted one.

use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use crate::mpm::boundary::Boundary;
use crate::mpm::mesh::Mesh;
use crate::mpm::points::Points;
use crate::mpm::sim::{Material, MpmSim, OutOfMeshPolicy, StressScheme};
use crate::registry::{ParamMap, Registry};
use serde::{Deserialize, Serialize};
use std::path::Path;

const FORMAT: &str = "granite-mpm-checkpoint";
const VERSION: u32 = 1;

#[derive(Serialize, Deserialize)]
struct MaterialRecord {
    name: String,
    density: f64,
    law: String,
    params: ParamMap,
    state: Vec<f64>,
    count: usize,
    objects: Option<serde_json::Value>,
}

#[derive(Serialize, Deserialize)]
struct MpmState {
    format: String,
    version: u32,
    mesh: Mesh,
    points: Points,
    materials: Vec<MaterialRecord>,
    boundary: Boundary,
    gravity: Vec3,
    damping: f64,
    scheme: StressScheme,
    velocity_update: String,
    velocity_update_params: ParamMap,
    dt: f64,
    time: f64,
    step: u64,
    out_of_mesh: OutOfMeshPolicy,
    deleted_points: u64,
    next_id: u64,
}

impl MpmSim {
    /// Writes a checkpoint as JSON (f64 values round-trip exactly).
    pub fn save(&self, path: &Path) -> Result<()> {
        let mut materials = Vec::new();
        for m in &self.materials {
            materials.push(MaterialRecord {
                name: m.name.clone(),
                density: m.density,
                law: m.law.name().to_string(),
                params: m.law.params().iter().filter(|(_, v)| !v.is_nan()).map(|(k, v)| (k.to_string(), v)).collect(),
                state: m.state.clone(),
                count: m.count,
                objects: m.law.save_objects()?,
            });
        }
        let state = MpmState {
            format: FORMAT.into(),
            version: VERSION,
            mesh: self.mesh.clone(),
            points: self.points.clone(),
            materials,
            boundary: self.boundary.clone(),
            gravity: self.gravity,
            damping: self.damping,
            scheme: self.scheme,
            velocity_update: self.velocity_update.name().to_string(),
            velocity_update_params: self.velocity_update.params(),
            dt: self.dt,
            time: self.time,
            step: self.step,
            out_of_mesh: self.out_of_mesh,
            deleted_points: self.deleted_points,
            next_id: self.next_id(),
        };
        let text =
            serde_json::to_string(&state).map_err(|e| GraniteError::Other(format!("{}: {e}", path.display())))?;
        std::fs::write(path, text).map_err(|e| GraniteError::io(path, e))
    }

    /// Reads a checkpoint; laws and velocity updates are rebuilt from `registry`, laws with
    /// objects (an RVE per point) get them back from the checkpoint.
    pub fn load(path: &Path, registry: &Registry) -> Result<MpmSim> {
        let text = std::fs::read_to_string(path).map_err(|e| GraniteError::io(path, e))?;
        let st: MpmState = serde_json::from_str(&text)
            .map_err(|e| GraniteError::Other(format!("{} is not a granite MPM checkpoint: {e}", path.display())))?;
        if st.format != FORMAT || st.version != VERSION {
            return Err(GraniteError::Other(format!(
                "{}: format {} version {} (this granite reads {FORMAT} version {VERSION})",
                path.display(),
                st.format,
                st.version
            )));
        }
        let update = registry.build_velocity_update(&st.velocity_update, &st.velocity_update_params)?;
        let mut sim = MpmSim::new(st.mesh, update);
        for m in st.materials {
            let law = match m.objects {
                None => registry.build_law(&m.law, &m.params)?,
                Some(objects) => {
                    let law = registry.law_factory(&m.law)?.restore(&m.params, objects, registry)?;
                    law
                }
            };
            sim.materials.push(Material { name: m.name, density: m.density, law, state: m.state, count: m.count });
        }
        sim.points = st.points;
        sim.boundary = st.boundary;
        sim.gravity = st.gravity;
        sim.damping = st.damping;
        sim.scheme = st.scheme;
        sim.dt = st.dt;
        sim.time = st.time;
        sim.step = st.step;
        sim.out_of_mesh = st.out_of_mesh;
        sim.deleted_points = st.deleted_points;
        sim.set_next_id(st.next_id);
        Ok(sim)
    }
}
