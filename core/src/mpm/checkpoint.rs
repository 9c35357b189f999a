//! Checkpoints of a whole MPM simulation (points, laws with their state and objects, mesh,
//! boundary conditions, clock), so a resumed run continues exactly as an uninterrupted one.

use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use crate::mpm::boundary::{Boundary, TimeFunction};
use crate::mpm::mesh::Mesh;
use crate::mpm::points::Points;
use crate::mpm::sim::{Material, MpmSim, OutOfMeshPolicy, ShapeFunctions, StressRate, StressScheme, VolumetricStrain};
use crate::registry::{ParamMap, Registry};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

const FORMAT: &str = "granite-mpm-checkpoint";
/// 4: loads carried by points (`Boundary::point_loads`; none in older files).
/// 3: the shape functions and the stress rate are part of the state.
/// 2: the file is an envelope (`io::checkpoint_file`: writer, CRC-32) around the state of 1.
/// Bump it whenever `MpmState` changes, and read the older ones through an upgrade path.
const VERSION: u32 = 4;
/// The oldest version read: 1, whose state is 3's without the shape functions and stress rate
/// (read as the linear functions and plain rate that granite then had).
const OLDEST: u32 = 1;

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
    #[serde(default)]
    stress_rate: StressRate,
    #[serde(default)]
    volumetric_strain: VolumetricStrain,
    #[serde(default)]
    shape: ShapeFunctions,
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
    /// Writes a checkpoint as JSON (f64 values round-trip exactly). In a run over several
    /// processes every process calls it: the objects of spread materials are gathered to the
    /// first process, which writes the file, and every process returns its outcome.
    pub fn save(&self, path: &Path) -> Result<()> {
        self.save_as(path, &crate::io::checkpoint_file::default_writer())
    }

    /// [`MpmSim::save`], recording `written_by` (the program and its commit) in the file.
    pub fn save_as(&self, path: &Path, written_by: &str) -> Result<()> {
        crate::comm::agree(self.comm.as_ref(), 0, self.write_checkpoint(path, written_by))
    }

    fn write_checkpoint(&self, path: &Path, written_by: &str) -> Result<()> {
        let mut materials = Vec::new();
        for m in &self.materials {
            let objects = match (m.law.point_objects(), &m.spread) {
                (None, _) => None,
                (Some(objects), Some(spread)) => match spread.gather_objects(objects)? {
                    Some(points) => objects.save_objects_from(points)?,
                    None => None,
                },
                (Some(objects), None) => objects.save_objects()?,
            };
            materials.push(MaterialRecord {
                name: m.name.clone(),
                density: m.density,
                law: m.law.name().to_string(),
                params: m.law.params().iter().filter(|(_, v)| !v.is_nan()).map(|(k, v)| (k.to_string(), v)).collect(),
                state: m.state.clone(),
                count: m.count,
                objects,
            });
        }
        if !self.writes_files() {
            return Ok(());
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
            stress_rate: self.stress_rate,
            volumetric_strain: self.volumetric_strain,
            shape: self.shape,
            velocity_update: self.velocity_update.name().to_string(),
            velocity_update_params: self.velocity_update.params(),
            dt: self.dt,
            time: self.time,
            step: self.step,
            out_of_mesh: self.out_of_mesh,
            deleted_points: self.deleted_points,
            next_id: self.next_id(),
        };
        let state =
            serde_json::to_string(&state).map_err(|e| GraniteError::Other(format!("{}: {e}", path.display())))?;
        let text = crate::io::checkpoint_file::seal(FORMAT, VERSION, written_by, &state);
        crate::io::durable::replace_keeping_previous(path, text.as_bytes())
    }

    /// Reads a checkpoint; laws and velocity updates are rebuilt from `registry`, laws with
    /// objects (an RVE per point) get them back from the checkpoint.
    pub fn load(path: &Path, registry: &Registry) -> Result<MpmSim> {
        let text = std::fs::read_to_string(path).map_err(|e| GraniteError::io(path, e))?;
        Self::from_checkpoint_text(path, &text, registry)
    }

    /// [`MpmSim::load`] of the newest whole checkpoint: `path`, or the one written before it
    /// (`ck.prev.json`) when `path` is missing, cut or damaged; then also why the older one was
    /// taken, and the file read.
    pub fn load_newest(path: &Path, registry: &Registry) -> Result<(MpmSim, PathBuf, Option<String>)> {
        Self::load_newest_until(path, registry, &|| false)
    }

    /// [`MpmSim::load_newest`] that gives up reading once `stop()` says so.
    pub fn load_newest_until(
        path: &Path,
        registry: &Registry,
        stop: &dyn Fn() -> bool,
    ) -> Result<(MpmSim, PathBuf, Option<String>)> {
        let whole =
            |p: &Path, text: &str| crate::io::checkpoint_file::open(p, text, FORMAT, VERSION, OLDEST).map(|_| ());
        let (read, text, note) = crate::io::durable::read_newest(path, whole, stop)?;
        Ok((Self::from_checkpoint_text(&read, &text, registry)?, read, note))
    }

    fn from_checkpoint_text(path: &Path, text: &str, registry: &Registry) -> Result<MpmSim> {
        let opened = crate::io::checkpoint_file::open(path, text, FORMAT, VERSION, OLDEST)?;
        let st: MpmState = serde_json::from_str(opened.state)
            .map_err(|e| GraniteError::Other(format!("{} is not a granite MPM checkpoint: {e}", path.display())))?;
        if st.format != FORMAT || !(OLDEST..=VERSION).contains(&st.version) {
            return Err(GraniteError::Other(format!(
                "{}: format {} version {} (this granite reads {FORMAT} versions {OLDEST} to {VERSION})",
                path.display(),
                st.format,
                st.version
            )));
        }
        let update = registry.build_velocity_update(&st.velocity_update, &st.velocity_update_params)?;
        let not_usable =
            |e: String| GraniteError::Other(format!("{}: not a usable MPM checkpoint: {e}", path.display()));
        // Mesh::new checks what deserializing skipped.
        let mesh = Mesh::new(st.mesh.dim, st.mesh.origin, st.mesh.cell, st.mesh.cells)
            .map_err(|e| not_usable(format!("mesh: {e}")))?;
        let mut sim = MpmSim::new(mesh, update);
        for m in st.materials {
            let law = match m.objects {
                None => registry.build_law(&m.law, &m.params)?,
                Some(objects) => {
                    let law = registry.law_factory(&m.law)?.restore(&m.params, objects, registry)?;
                    law
                }
            };
            sim.materials.push(Material {
                name: m.name,
                density: m.density,
                law,
                state: m.state,
                count: m.count,
                spread: None,
            });
        }
        sim.points = st.points;
        sim.boundary = st.boundary;
        sim.gravity = st.gravity;
        sim.damping = st.damping;
        sim.scheme = st.scheme;
        sim.stress_rate = st.stress_rate;
        sim.volumetric_strain = st.volumetric_strain;
        sim.shape = st.shape;
        sim.dt = st.dt;
        sim.time = st.time;
        sim.step = st.step;
        sim.out_of_mesh = st.out_of_mesh;
        sim.deleted_points = st.deleted_points;
        sim.set_next_id(st.next_id);
        check_consistent(&sim).map_err(not_usable)?;
        Ok(sim)
    }
}

/// What a step relies on in a checkpoint read from a file (edited by hand, truncated, or from
/// another program): array lengths that agree, points grouped by material as the counts say,
/// node indices in the mesh, values a step can use. A file breaking one is refused with what is
/// wrong, instead of panicking or running on garbage.
fn check_consistent(sim: &MpmSim) -> std::result::Result<(), String> {
    let p = &sim.points;
    let n = p.len();
    let lengths = [
        ("id", p.id.len()),
        ("material", p.material.len()),
        ("mass", p.mass.len()),
        ("volume", p.volume.len()),
        ("v", p.v.len()),
        ("stress", p.stress.len()),
        ("strain", p.strain.len()),
        ("dstrain", p.dstrain.len()),
        ("affine", p.affine.len()),
    ];
    crate::loaded::same_length("points", "x", n, &lengths)?;
    crate::loaded::unique_ids("points", &p.id)?;
    crate::loaded::step_and_time(sim.step, sim.time, sim.dt)?;
    crate::loaded::next_id("points", sim.next_id(), &p.id)?;
    let positive = |x: f64| x.is_finite() && x > 0.0;
    for i in 0..n {
        let id = p.id[i];
        if !(positive(p.mass[i]) && positive(p.volume[i])) {
            return Err(format!(
                "point id {id}: mass {}, volume {} (each must be finite and > 0)",
                p.mass[i], p.volume[i]
            ));
        }
        let values = p.x[i].iter().chain(&p.v[i]).chain(&p.stress[i]).chain(&p.strain[i]);
        if !values.into_iter().all(|c| c.is_finite()) {
            return Err(format!("point id {id}: a non-finite position, velocity, stress or strain"));
        }
    }
    // Points are stored material by material, `count` of each, in material order.
    let mut first = 0;
    for (m, material) in sim.materials.iter().enumerate() {
        let block = first..first + material.count;
        if block.end > n || p.material[block.clone()].iter().any(|&k| k as usize != m) {
            return Err(format!(
                "material {m} (\"{}\") counts {} points that are not its own",
                material.name, material.count
            ));
        }
        let per_point = material.law.state_names().len();
        if material.state.len() != material.count * per_point {
            return Err(format!(
                "material {m}: {} state values for {} points of {per_point}",
                material.state.len(),
                material.count
            ));
        }
        if !positive(material.density) {
            return Err(format!("material {m}: density {}", material.density));
        }
        first = block.end;
    }
    if first != n {
        return Err(format!("{n} points, {first} counted by the materials"));
    }
    let (nodes, dim) = (sim.mesh.node_count(), sim.mesh.dim);
    let b = &sim.boundary;
    let sets = b.velocity.iter().map(|c| (&c.nodes, c.axis)).chain(b.friction.iter().map(|c| (&c.nodes, c.axis)));
    for (set, axis) in sets {
        if axis >= dim {
            return Err(format!("a boundary condition on axis {axis} of a {dim}D mesh"));
        }
        if let Some(k) = set.iter().find(|&&k| k as usize >= nodes) {
            return Err(format!("a boundary condition on node {k} of the mesh's {nodes}"));
        }
    }
    for f in &b.forces {
        if f.force.len() != f.nodes.len() || f.nodes.iter().any(|&k| k as usize >= nodes) {
            return Err(format!(
                "a nodal force of {} nodes, {} forces, or a node beyond {nodes}",
                f.nodes.len(),
                f.force.len()
            ));
        }
    }
    for load in &b.point_loads {
        if load.force.len() != load.ids.len() || load.force.iter().flatten().any(|f| !f.is_finite()) {
            return Err(format!(
                "{}: {} points and {} forces, or a force that is not finite",
                load.name,
                load.ids.len(),
                load.force.len()
            ));
        }
    }
    let functions = b
        .velocity
        .iter()
        .map(|c| &c.value)
        .chain(b.forces.iter().map(|f| &f.factor))
        .chain(b.point_loads.iter().map(|l| &l.factor));
    for function in functions {
        if let TimeFunction::Table(points) = function {
            TimeFunction::table(points.clone()).map_err(|e| format!("a boundary table: {e}"))?;
        }
    }
    if !(sim.dt.is_finite() && sim.dt >= 0.0 && sim.time.is_finite() && (0.0..1.0).contains(&sim.damping)) {
        return Err(format!("time step {}, time {}, damping {}", sim.dt, sim.time, sim.damping));
    }
    Ok(())
}
