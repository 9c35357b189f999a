//! Saving and loading a whole DEM state (particles, walls, cell, contacts with their history), so
//! a prepared sample can be reused (thesis 2.2.4, 5.2.4) and a run resumed exactly.

use crate::dem::cell::{CellControl, PeriodicCell};
use crate::dem::clump::Clumps;
use crate::dem::contacts::{Adjacency, PairList};
use crate::dem::particles::Spheres;
use crate::dem::sim::{DemMaterial, DemSim};
use crate::dem::walls::Wall;
use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use crate::registry::{ParamMap, Registry};
use serde::{Deserialize, Serialize};
use std::path::Path;

const FORMAT: &str = "granite-dem-state";
const VERSION: u32 = 1;

/// A contact law by registry name and parameters (rebuilt from the registry on load).
#[derive(Serialize, Deserialize)]
struct LawRecord {
    name: String,
    params: ParamMap,
}

#[derive(Serialize, Deserialize)]
pub(crate) struct DemState {
    format: String,
    version: u32,
    spheres: Spheres,
    clumps: Clumps,
    walls: Vec<Wall>,
    materials: Vec<DemMaterial>,
    laws: Vec<LawRecord>,
    law_of: Vec<((u16, u16), u16)>,
    default_law: Option<u16>,
    gravity: Vec3,
    cell: Option<PeriodicCell>,
    cell_control: Option<CellControl>,
    cell_reference: Option<nalgebra::Matrix3<f64>>,
    damping: f64,
    dt: f64,
    time: f64,
    step: u64,
    skin: f64,
    seed: u64,
    pairs: PairList,
    wall_pairs: PairList,
    adjacency: Adjacency,
    wall_adjacency: Adjacency,
    x_at_build: Vec<Vec3>,
    walls_at_build: Vec<Vec3>,
    h_at_build: Option<nalgebra::Matrix3<f64>>,
    needs_rebuild: bool,
    rebuilds: u64,
}

impl DemSim {
    fn to_state(&self) -> DemState {
        let mut law_of: Vec<((u16, u16), u16)> = self.law_of.iter().map(|(k, v)| (*k, *v)).collect();
        law_of.sort();
        DemState {
            format: FORMAT.into(),
            version: VERSION,
            spheres: self.spheres.clone(),
            clumps: self.clumps.clone(),
            walls: self.walls.clone(),
            materials: self.materials.clone(),
            laws: self
                .laws
                .iter()
                .map(|l| LawRecord {
                    name: l.name().to_string(),
                    params: l.params().iter().filter(|(_, v)| !v.is_nan()).map(|(k, v)| (k.to_string(), v)).collect(),
                })
                .collect(),
            law_of,
            default_law: self.default_law,
            gravity: self.gravity,
            cell: self.cell.clone(),
            cell_control: self.cell_control.clone(),
            cell_reference: self.cell_reference,
            damping: self.damping,
            dt: self.dt,
            time: self.time,
            step: self.step,
            skin: self.skin,
            seed: self.seed,
            pairs: self.pairs.clone(),
            wall_pairs: self.wall_pairs.clone(),
            adjacency: self.adjacency.clone(),
            wall_adjacency: self.wall_adjacency.clone(),
            x_at_build: self.x_at_build.clone(),
            walls_at_build: self.walls_at_build.clone(),
            h_at_build: self.h_at_build,
            needs_rebuild: self.needs_rebuild,
            rebuilds: self.rebuilds,
        }
    }

    /// The whole state as a JSON value (for checkpoints that embed DEM samples).
    pub fn to_json(&self) -> Result<serde_json::Value> {
        serde_json::to_value(self.to_state()).map_err(|e| GraniteError::Other(format!("DEM state: {e}")))
    }

    /// A state from [`DemSim::to_json`]; contact laws are rebuilt from `registry`.
    pub fn from_json(value: serde_json::Value, registry: &Registry) -> Result<DemSim> {
        let st: DemState = serde_json::from_value(value).map_err(|e| GraniteError::Other(format!("DEM state: {e}")))?;
        Self::from_state(st, registry, "checkpoint")
    }

    /// Writes the whole state as JSON (f64 values round-trip exactly).
    pub fn save(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string(&self.to_state())
            .map_err(|e| GraniteError::Other(format!("{}: {e}", path.display())))?;
        std::fs::write(path, text).map_err(|e| GraniteError::io(path, e))
    }

    /// Reads a state written by [`DemSim::save`]; contact laws are rebuilt from `registry`.
    pub fn load(path: &Path, registry: &Registry) -> Result<DemSim> {
        let text = std::fs::read_to_string(path).map_err(|e| GraniteError::io(path, e))?;
        let st: DemState = serde_json::from_str(&text)
            .map_err(|e| GraniteError::Other(format!("{} is not a granite DEM state: {e}", path.display())))?;
        Self::from_state(st, registry, &path.display().to_string())
    }

    fn from_state(st: DemState, registry: &Registry, source: &str) -> Result<DemSim> {
        if st.format != FORMAT || st.version != VERSION {
            return Err(GraniteError::Other(format!(
                "{source}: format {} version {} (this granite reads {FORMAT} version {VERSION})",
                st.format, st.version
            )));
        }
        let mut sim = DemSim::new();
        for law in &st.laws {
            let built = registry.build_contact_law(&law.name, &law.params)?;
            sim.laws.push(std::sync::Arc::from(built));
        }
        sim.spheres = st.spheres;
        sim.clumps = st.clumps;
        sim.walls = st.walls;
        sim.materials = st.materials;
        sim.law_of = st.law_of.into_iter().collect();
        sim.default_law = st.default_law;
        sim.gravity = st.gravity;
        sim.cell = st.cell;
        sim.cell_control = st.cell_control;
        sim.cell_reference = st.cell_reference;
        sim.damping = st.damping;
        sim.dt = st.dt;
        sim.time = st.time;
        sim.step = st.step;
        sim.skin = st.skin;
        sim.seed = st.seed;
        sim.pairs = st.pairs;
        sim.wall_pairs = st.wall_pairs;
        sim.adjacency = st.adjacency;
        sim.wall_adjacency = st.wall_adjacency;
        sim.x_at_build = st.x_at_build;
        sim.walls_at_build = st.walls_at_build;
        sim.h_at_build = st.h_at_build;
        sim.radius_max_at_build = sim.spheres.largest_radius();
        sim.radius_min_at_build = sim.spheres.smallest_radius();
        sim.needs_rebuild = st.needs_rebuild;
        sim.rebuilds = st.rebuilds;
        // Reading grows arrays by doubling; copies hold just their contents (a loaded RVE is the
        // template of every material point's copy, so its reported memory should be theirs).
        sim.spheres = sim.spheres.clone();
        sim.pairs = sim.pairs.clone();
        sim.wall_pairs = sim.wall_pairs.clone();
        sim.x_at_build = sim.x_at_build.clone();
        Ok(sim)
    }
}
