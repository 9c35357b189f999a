//! Saving and loading a whole DEM state (particles, walls, cell, contacts with their history), so
//! a prepared sample can be reused (thesis 2.2.4, 5.2.4) and a run resumed exactly.

use crate::dem::cell::{CellControl, PeriodicCell};
use crate::dem::clump::Clumps;
use crate::dem::contact_set::ContactSet;
use crate::dem::contacts::PairList;
use crate::dem::particles::Spheres;
use crate::dem::sim::{DemMaterial, DemSim};
use crate::dem::walls::Wall;
use crate::error::{GraniteError, Result};
use crate::ext::contact::ContactLawSource;
use crate::math::Vec3;
use crate::params::ParamMap;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

const FORMAT: &str = "granite-dem-state";
/// 7: the contacts as one record (`contacts`: the law table and the five lists), in place of
///    `laws`, `law_of`, `default_law`, `pairs`, `wall_pairs` and the bodies' three lists.
/// 6: bodies of several families (their families and each body's).
/// 5: bodies of plugin kinds (capsules, ...).
/// 4: a stress-controlled cell keeps its servo's integral part.
/// 3: the file is an envelope (`io::checkpoint_file`: writer, CRC-32) around the state of 2.
/// 2: a pair of spheres is stored under its larger index (`a > b`); 1 stored it under the smaller.
/// Bump it whenever `DemState` changes, and read the older ones through an upgrade path.
const VERSION: u32 = 7;
/// The oldest version read: 2, whose state is 7's less what was added since: external loads and
/// the energy tracker (none), the servo's integral part (zero: the servo learns it again within a
/// few of its relaxation times), bodies of plugin kinds (none), their families (one); and with its
/// contacts in the fields before 7's record (see [`Legacy`]).
const OLDEST: u32 = 2;

/// A contact law by registry name and parameters (rebuilt from the registry on load).
#[derive(Serialize, Deserialize)]
struct LawRecord {
    name: String,
    params: ParamMap,
}

/// Bodies of plugin kinds: the families by a kind of each, each shape by its kind and the
/// parameters it was built from (mass properties are computed again from them and the
/// materials' densities), each body's family.
#[derive(Serialize, Deserialize)]
struct BodiesRecord {
    /// A kind of the first family.
    kind: String,
    /// A kind of each family, in the order they joined (absent in states of one family).
    #[serde(default)]
    families: Vec<String>,
    /// Each body's family (absent in states of one family: all of `kind`'s).
    #[serde(default)]
    family: Vec<u16>,
    shapes: Vec<ParamMap>,
    /// Each shape's kind (absent in states of one kind per family: `kind` then).
    #[serde(default)]
    shape_kinds: Vec<String>,
    shape: Vec<u32>,
    id: Vec<u64>,
    material: Vec<u16>,
    x: Vec<Vec3>,
    v: Vec<Vec3>,
    w: Vec<Vec3>,
    q: Vec<nalgebra::UnitQuaternion<f64>>,
    fixed: Vec<bool>,
    /// Before version 7: the bodies' lists (body pairs, walls, spheres).
    #[serde(default, skip_serializing)]
    pairs: PairList,
    #[serde(default, skip_serializing)]
    wall_pairs: PairList,
    #[serde(default, skip_serializing)]
    sphere_pairs: PairList,
    x_at_build: Vec<Vec3>,
}

/// The contact set ([`ContactSet`]): the law table, laws by registry name and parameters, and the
/// five candidate lists.
#[derive(Serialize, Deserialize)]
struct ContactsRecord {
    laws: Vec<LawRecord>,
    law_of: Vec<((u16, u16), u16)>,
    default_law: Option<u16>,
    spheres: PairList,
    sphere_walls: PairList,
    bodies: PairList,
    body_walls: PairList,
    body_spheres: PairList,
}

impl ContactsRecord {
    fn of(c: &ContactSet) -> ContactsRecord {
        let mut law_of: Vec<((u16, u16), u16)> = c.law_of.iter().map(|(k, v)| (*k, *v)).collect();
        law_of.sort();
        let laws = c
            .laws
            .iter()
            .map(|l| LawRecord {
                name: l.name().to_string(),
                params: l.params().iter().filter(|(_, v)| !v.is_nan()).map(|(k, v)| (k.to_string(), v)).collect(),
            })
            .collect();
        ContactsRecord {
            laws,
            law_of,
            default_law: c.default_law,
            spheres: c.spheres.clone(),
            sphere_walls: c.sphere_walls.clone(),
            bodies: c.bodies.clone(),
            body_walls: c.body_walls.clone(),
            body_spheres: c.body_spheres.clone(),
        }
    }

    /// The contact set of the record, its laws made by `build_law`.
    fn into_set(self, build_law: &LawBuilder) -> Result<ContactSet> {
        let laws = self.laws.iter().enumerate().map(|(k, law)| build_law(k, law)).collect::<Result<Vec<_>>>()?;
        Ok(ContactSet {
            laws,
            law_of: self.law_of.into_iter().collect(),
            default_law: self.default_law,
            spheres: self.spheres,
            sphere_walls: self.sphere_walls,
            bodies: self.bodies,
            body_walls: self.body_walls,
            body_spheres: self.body_spheres,
            body_touches: Default::default(),
        })
    }
}

#[derive(Serialize, Deserialize)]
pub(crate) struct DemState {
    format: String,
    version: u32,
    spheres: Spheres,
    clumps: Clumps,
    walls: Vec<Wall>,
    materials: Vec<DemMaterial>,
    /// From version 7; older states kept their contacts in the five fields below and the
    /// bodies' record.
    #[serde(default)]
    contacts: Option<ContactsRecord>,
    #[serde(default, skip_serializing)]
    laws: Vec<LawRecord>,
    #[serde(default, skip_serializing)]
    law_of: Vec<((u16, u16), u16)>,
    #[serde(default, skip_serializing)]
    default_law: Option<u16>,
    #[serde(default, skip_serializing)]
    pairs: PairList,
    #[serde(default, skip_serializing)]
    wall_pairs: PairList,
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
    x_at_build: Vec<Vec3>,
    walls_at_build: Vec<Vec3>,
    h_at_build: Option<nalgebra::Matrix3<f64>>,
    needs_rebuild: bool,
    rebuilds: u64,
    #[serde(default)]
    external: Vec<crate::dem::particles::ExternalLoad>,
    #[serde(default)]
    energy: Option<crate::dem::energy::EnergyTracker>,
    #[serde(default)]
    bodies: Option<BodiesRecord>,
}

impl DemSim {
    fn to_state(&self) -> DemState {
        DemState {
            format: FORMAT.into(),
            version: VERSION,
            spheres: self.world.spheres.clone(),
            clumps: self.world.clumps.clone(),
            walls: self.world.walls.clone(),
            materials: self.world.materials.clone(),
            contacts: Some(ContactsRecord::of(&self.world.contacts)),
            laws: Vec::new(),
            law_of: Vec::new(),
            default_law: None,
            pairs: PairList::default(),
            wall_pairs: PairList::default(),
            gravity: self.world.gravity,
            cell: self.world.cell.clone(),
            cell_control: self.world.cell_control.clone(),
            cell_reference: self.world.cell_reference,
            damping: self.world.damping,
            dt: self.world.dt,
            time: self.world.time,
            step: self.world.step,
            skin: self.skin,
            seed: self.world.seed,
            x_at_build: self.built.x.clone(),
            walls_at_build: self.built.walls.clone(),
            h_at_build: self.built.h,
            needs_rebuild: self.world.needs_rebuild,
            rebuilds: self.rebuilds,
            external: self.world.external.clone(),
            energy: self.energy.clone(),
            bodies: self.bodies_record(),
        }
    }

    fn bodies_record(&self) -> Option<BodiesRecord> {
        let k = &self.world.kinds;
        if k.is_empty() {
            return None;
        }
        let families: Vec<String> = k.families.iter().map(|f| f.kind.clone()).collect();
        Some(BodiesRecord {
            kind: families[0].clone(),
            families,
            family: k.family.clone(),
            shapes: k.shapes.iter().map(|s| s.params()).collect(),
            shape_kinds: k.shapes.iter().map(|s| s.kind().to_string()).collect(),
            shape: k.shape.clone(),
            id: k.id.clone(),
            material: k.material.clone(),
            x: k.x.clone(),
            v: k.v.clone(),
            w: k.w.clone(),
            q: k.q.clone(),
            fixed: k.fixed.clone(),
            pairs: PairList::default(),
            wall_pairs: PairList::default(),
            sphere_pairs: PairList::default(),
            x_at_build: k.x_at_build.clone(),
        })
    }

    /// The bodies of a saved state, their kind and shapes rebuilt from `registry`.
    fn restore_bodies(&mut self, mut record: BodiesRecord, registry: Option<&dyn ContactLawSource>) -> Result<()> {
        let Some(registry) = registry else {
            return Err(GraniteError::Other(format!("a state with {} bodies moved without a registry", record.kind)));
        };
        // A state of one kind per family names the family's kind for every shape.
        let kind_of = |s: usize| record.shape_kinds.get(s).unwrap_or(&record.kind);
        let families = if record.families.is_empty() { vec![record.kind.clone()] } else { record.families.clone() };
        let shapes = (0..record.shapes.len())
            .map(|s| registry.body_kind(kind_of(s))?.build_from(&record.shapes[s]))
            .collect::<Result<Vec<_>>>()?;
        let n = record.x.len();
        let lengths = [
            ("shape", record.shape.len()),
            ("id", record.id.len()),
            ("material", record.material.len()),
            ("v", record.v.len()),
            ("w", record.w.len()),
            ("q", record.q.len()),
            ("fixed", record.fixed.len()),
            ("x_at_build", record.x_at_build.len()),
            ("family", if record.family.is_empty() { n } else { record.family.len() }),
        ];
        crate::loaded::same_length("bodies", "x", n, &lengths).map_err(GraniteError::Other)?;
        let k = &mut self.world.kinds;
        let meetings = registry.body_pair_geometries();
        for name in &families {
            k.join_family(registry.body_kind(name)?.as_ref(), &meetings)?;
        }
        k.family = if record.family.is_empty() { vec![0; n] } else { record.family };
        if let Some(&f) = k.family.iter().find(|&&f| f as usize >= families.len()) {
            return Err(GraniteError::Other(format!("bodies: family {f} of {}", families.len())));
        }
        for i in 0..n {
            let shape = shapes.get(record.shape[i] as usize).ok_or_else(|| {
                GraniteError::Other(format!("body {i}: shape {} of {}", record.shape[i], shapes.len()))
            })?;
            let density = self
                .world
                .materials
                .get(record.material[i] as usize)
                .ok_or_else(|| GraniteError::Other(format!("body {i}: material {}", record.material[i])))?
                .density;
            let values = shape.values();
            let padding = k.stride.checked_sub(values.len()).ok_or_else(|| {
                GraniteError::Other(format!("body {i}: a {} shape gives more values than its family", shape.kind()))
            })?;
            k.values.extend(values);
            k.values.extend(std::iter::repeat_n(0.0, padding));
            k.mass.push(density * shape.volume());
            k.inertia.push(shape.inertia_per_density().map(|c| density * c));
        }
        k.shapes = shapes;
        (k.shape, k.id, k.material, k.x, k.v, k.w, k.q, k.fixed) =
            (record.shape, record.id, record.material, record.x, record.v, record.w, record.q, record.fixed);
        k.force = vec![[0.0; 3]; n];
        k.torque = vec![[0.0; 3]; n];
        k.x_at_build = record.x_at_build;
        // A state before version 7 kept the bodies' lists here.
        let c = &mut self.world.contacts;
        for (list, old) in [
            (&mut c.bodies, &mut record.pairs),
            (&mut c.body_walls, &mut record.wall_pairs),
            (&mut c.body_spheres, &mut record.sphere_pairs),
        ] {
            if !old.is_empty() {
                *list = std::mem::take(old);
            }
        }
        // Before version 7 a body-wall pair's contact point was numbered in its shift's first
        // entry (walls have no images); it is its `part` now.
        let walls = &mut c.body_walls;
        if walls.part.is_empty() && !walls.is_empty() {
            walls.part = walls.shift.iter().map(|s| s[0].clamp(0, u8::MAX as i32) as u8).collect();
            walls.shift.iter_mut().for_each(|s| *s = [0; 3]);
        }
        Ok(())
    }

    /// The whole state as a JSON value (for checkpoints that embed DEM samples).
    pub fn to_json(&self) -> Result<serde_json::Value> {
        serde_json::to_value(self.to_state()).map_err(|e| GraniteError::Other(format!("DEM state: {e}")))
    }

    /// A state from [`DemSim::to_json`]; contact laws are rebuilt from `registry`.
    pub fn from_json(value: serde_json::Value, registry: &dyn ContactLawSource) -> Result<DemSim> {
        let st: DemState = serde_json::from_value(value).map_err(|e| GraniteError::Other(format!("DEM state: {e}")))?;
        Self::from_state(st, &from_registry(registry), Some(registry), "checkpoint")
    }

    /// A state from [`DemSim::to_json`] of a copy of `like` (an RVE moved between processes):
    /// its contact laws are `like`'s, which must be the ones it was written with.
    pub fn from_json_like(value: serde_json::Value, like: &DemSim) -> Result<DemSim> {
        let st: DemState = serde_json::from_value(value).map_err(|e| GraniteError::Other(format!("DEM state: {e}")))?;
        let laws = |k: usize, record: &LawRecord| -> Result<std::sync::Arc<dyn crate::ext::ContactLaw>> {
            match like.world.contacts.laws.get(k) {
                Some(law) if law.name() == record.name => Ok(law.clone()),
                _ => Err(GraniteError::Other(format!(
                    "DEM state: contact law {k} is `{}`, not one of the sample it was copied from",
                    record.name
                ))),
            }
        };
        Self::from_state(st, &laws, None, "moved sample")
    }

    /// Writes the whole state as JSON (f64 values round-trip exactly), sealed with a checksum.
    pub fn save(&self, path: &Path) -> Result<()> {
        self.save_as(path, &crate::io::checkpoint_file::default_writer())
    }

    /// [`DemSim::save`], recording `written_by` (the program and its commit) in the file.
    pub fn save_as(&self, path: &Path, written_by: &str) -> Result<()> {
        let state = serde_json::to_string(&self.to_state())
            .map_err(|e| GraniteError::Other(format!("{}: {e}", path.display())))?;
        let text = crate::io::checkpoint_file::seal(FORMAT, VERSION, written_by, &state);
        crate::io::durable::replace_keeping_previous(path, text.as_bytes())
    }

    /// Reads a state written by [`DemSim::save`] (this version or an older one); a damaged file or
    /// one from a newer granite is refused. Contact laws are rebuilt from `registry`.
    pub fn load(path: &Path, registry: &dyn ContactLawSource) -> Result<DemSim> {
        let text = std::fs::read_to_string(path).map_err(|e| GraniteError::io(path, e))?;
        Self::from_state_text(path, &text, registry)
    }

    /// [`DemSim::load`] of the newest whole state: `path`, or the one written before it
    /// (`ck.prev.json`) when `path` is missing, cut or damaged; then also why the older one was
    /// taken, and the file read.
    pub fn load_newest(path: &Path, registry: &dyn ContactLawSource) -> Result<(DemSim, PathBuf, Option<String>)> {
        Self::load_newest_until(path, registry, &|| false)
    }

    /// [`DemSim::load_newest`] that gives up reading once `stop()` says so.
    pub fn load_newest_until(
        path: &Path,
        registry: &dyn ContactLawSource,
        stop: &dyn Fn() -> bool,
    ) -> Result<(DemSim, PathBuf, Option<String>)> {
        let whole =
            |p: &Path, text: &str| crate::io::checkpoint_file::open(p, text, FORMAT, VERSION, OLDEST).map(|_| ());
        let (read, text, note) = crate::io::durable::read_newest(path, whole, stop)?;
        Ok((Self::from_state_text(&read, &text, registry)?, read, note))
    }

    fn from_state_text(path: &Path, text: &str, registry: &dyn ContactLawSource) -> Result<DemSim> {
        let opened = crate::io::checkpoint_file::open(path, text, FORMAT, VERSION, OLDEST)?;
        let st: DemState = serde_json::from_str(opened.state)
            .map_err(|e| GraniteError::Other(format!("{} is not a granite DEM state: {e}", path.display())))?;
        Self::from_state(st, &from_registry(registry), Some(registry), &path.display().to_string())
    }

    fn from_state(
        st: DemState,
        build_law: &LawBuilder,
        kinds: Option<&dyn ContactLawSource>,
        source: &str,
    ) -> Result<DemSim> {
        if st.format != FORMAT || !(OLDEST..=VERSION).contains(&st.version) {
            return Err(GraniteError::Other(format!(
                "{source}: format {} version {} (this granite reads {FORMAT} versions {OLDEST} to {VERSION})",
                st.format, st.version
            )));
        }
        let mut sim = DemSim::new();
        sim.world.contacts = match st.contacts {
            Some(record) => record.into_set(build_law)?,
            None => {
                let record = ContactsRecord {
                    laws: st.laws,
                    law_of: st.law_of,
                    default_law: st.default_law,
                    spheres: st.pairs,
                    sphere_walls: st.wall_pairs,
                    bodies: PairList::default(),
                    body_walls: PairList::default(),
                    body_spheres: PairList::default(),
                };
                record.into_set(build_law)?
            }
        };
        sim.world.spheres = st.spheres;
        sim.world.clumps = st.clumps;
        sim.world.walls = st.walls;
        sim.world.materials = st.materials;
        sim.world.gravity = st.gravity;
        sim.world.cell = st.cell;
        sim.world.cell_control = st.cell_control;
        sim.world.cell_reference = st.cell_reference;
        sim.world.set_damping(st.damping).map_err(|e| GraniteError::Other(format!("{source}: {e}")))?;
        sim.world.dt = st.dt;
        sim.world.time = st.time;
        sim.world.step = st.step;
        sim.skin = st.skin;
        sim.world.seed = st.seed;
        sim.built.x = st.x_at_build;
        sim.built.walls = st.walls_at_build;
        sim.built.h = st.h_at_build;
        sim.built.radius_max = sim.world.spheres.largest_radius();
        sim.built.radius_min = sim.world.spheres.smallest_radius();
        // The angle a spinning wall turned since the lists were built is not saved: they are
        // built again.
        sim.world.needs_rebuild = st.needs_rebuild || sim.world.walls.iter().any(|w| w.spin != [0.0; 3]);
        sim.rebuilds = st.rebuilds;
        sim.world.external = st.external;
        sim.energy = st.energy;
        if let Some(bodies) = st.bodies {
            sim.restore_bodies(bodies, kinds).map_err(|e| GraniteError::Other(format!("{source}: {e}")))?;
        }
        sim.world.next_id =
            sim.world.spheres.id.iter().chain(&sim.world.kinds.id).max().map_or(0, |m| m.saturating_add(1));
        widen_pair_layout(&mut sim);
        check_consistent(&sim).map_err(|e| GraniteError::Other(format!("{source}: not a usable DEM state: {e}")))?;
        // A state as a step leaves it has every sphere within half the skin of where the lists
        // saw it, or asks for a rebuild; one edited since (a sphere moved in the file) has its
        // lists built again from the positions it holds, instead of stopping at the next step as
        // if that sphere had flown there.
        let moved = sim.built.farthest_moved(&sim.world.spheres.x, sim.world.cell.as_ref().map(|c| &c.h));
        if moved.is_some_and(|(_, d)| d > 0.5 * sim.skin + 0.5 * sim.built.radius_min) {
            sim.world.needs_rebuild = true;
        }
        // The parallel stages' cuts of the pair lists are found again on the first step, not saved.
        // Reading grows arrays by doubling; copies hold just their contents (a loaded RVE is the
        // template of every material point's copy, so its reported memory should be theirs).
        sim.world.spheres = sim.world.spheres.clone();
        for list in [&mut sim.world.contacts.spheres, &mut sim.world.contacts.sphere_walls] {
            *list = list.clone();
        }
        sim.built.x = sim.built.x.clone();
        Ok(sim)
    }
}

/// Makes the contact law of a state's record (its index, name and parameters).
type LawBuilder<'a> = dyn Fn(usize, &LawRecord) -> Result<std::sync::Arc<dyn crate::ext::ContactLaw>> + 'a;

fn from_registry(
    registry: &dyn ContactLawSource,
) -> impl Fn(usize, &LawRecord) -> Result<std::sync::Arc<dyn crate::ext::ContactLaw>> + '_ {
    move |_, law| Ok(std::sync::Arc::from(registry.build_contact_law(&law.name, &law.params)?))
}

/// A state written when a law kept fewer values per pair (`hertz_mindlin` before its dashpot)
/// has its pairs laid out for the laws of this build and their values set again from them,
/// keeping their history. Only a list whose arrays and indices hold together is touched; anything
/// else is left for `check_consistent` to name.
fn widen_pair_layout(sim: &mut DemSim) {
    let (ps, hs) = sim.world.pair_strides();
    let (spheres, walls, laws) = (sim.world.spheres.len(), sim.world.walls.len(), sim.world.contacts.laws.len());
    let sound = |list: &crate::dem::contacts::PairList, others: usize| {
        let m = list.len();
        [list.b.len(), list.shift.len(), list.law.len(), list.touching.len(), list.force.len()].iter().all(|&l| l == m)
            && list.params.len() == m * list.param_stride
            && list.history.len() == m * list.history_stride
            && list.history_stride <= hs
            && list.a.iter().all(|&i| (i as usize) < spheres)
            && list.b.iter().all(|&j| (j as usize) < others)
            && list.law.iter().all(|&l| (l as usize) < laws)
    };
    let narrow = |list: &crate::dem::contacts::PairList| list.param_stride < ps || list.history_stride < hs;
    if (narrow(&sim.world.contacts.spheres) || narrow(&sim.world.contacts.sphere_walls))
        && sound(&sim.world.contacts.spheres, spheres)
        && sound(&sim.world.contacts.sphere_walls, walls)
        && sim.world.spheres.material.iter().all(|&m| (m as usize) < sim.world.materials.len())
    {
        let laws = sim.world.contacts.laws.clone();
        sim.world.refresh_pair_laws(&laws);
    }
}

/// What a step relies on in a state read from a file (edited by hand, truncated, or from another
/// program): array lengths that agree, indices in range, values a step can use. A file breaking
/// one is refused with what is wrong, instead of panicking or running on garbage.
fn check_consistent(sim: &DemSim) -> std::result::Result<(), String> {
    use crate::loaded::same_length;
    let s = &sim.world.spheres;
    let n = s.len();
    let lengths = [
        ("id", s.id.len()),
        ("v", s.v.len()),
        ("w", s.w.len()),
        ("radius", s.radius.len()),
        ("mass", s.mass.len()),
        ("inertia", s.inertia.len()),
        ("material", s.material.len()),
        ("force", s.force.len()),
        ("torque", s.torque.len()),
        ("blocked", s.blocked.len()),
        ("clump", s.clump.len()),
    ];
    same_length("spheres", "x", n, &lengths)?;
    crate::loaded::unique_ids("spheres", &s.id)?;
    crate::loaded::step_and_time(sim.world.step, sim.world.time, sim.world.dt)?;
    let finite = |v: &Vec3| v.iter().all(|c| c.is_finite());
    let positive = |x: f64| x.is_finite() && x > 0.0;
    for (m, material) in sim.world.materials.iter().enumerate() {
        if !positive(material.density) {
            return Err(format!(
                "material {m} (\"{}\"): density {} (must be finite and > 0)",
                material.name, material.density
            ));
        }
    }
    for i in 0..n {
        let id = s.id[i];
        // A radius whose sphere has no finite volume (1e300 m) would overflow every measure.
        let volume = 4.0 / 3.0 * std::f64::consts::PI * s.radius[i].powi(3);
        if !(positive(s.radius[i]) && positive(volume) && positive(s.mass[i]) && positive(s.inertia[i])) {
            return Err(format!(
                "sphere id {id}: radius {}, mass {}, inertia {} (each must be > 0, with a finite volume and mass)",
                s.radius[i], s.mass[i], s.inertia[i]
            ));
        }
        if !(finite(&s.x[i]) && finite(&s.v[i]) && finite(&s.w[i])) {
            return Err(format!("sphere id {id}: non-finite position or velocity"));
        }
        if s.material[i] as usize >= sim.world.materials.len() {
            return Err(format!("sphere id {id}: material {} of {}", s.material[i], sim.world.materials.len()));
        }
        if s.clump[i] != crate::dem::particles::FREE && s.clump[i] as usize >= sim.world.clumps.len() {
            return Err(format!("sphere id {id}: clump {} of {}", s.clump[i], sim.world.clumps.len()));
        }
    }
    let c = &sim.world.clumps;
    let clumps = c.len();
    let lengths = [
        ("v", c.v.len()),
        ("w", c.w.len()),
        ("q", c.q.len()),
        ("mass", c.mass.len()),
        ("inertia", c.inertia.len()),
        ("volume", c.volume.len()),
        ("force", c.force.len()),
        ("torque", c.torque.len()),
    ];
    same_length("clumps", "x", clumps, &lengths)?;
    same_length("clumps", "members", c.members.len(), &[("local", c.local.len())])?;
    if clumps > 0 {
        let ordered = c.start.len() == clumps + 1
            && c.start.windows(2).all(|w| w[0] <= w[1])
            && c.start.last().is_some_and(|&e| e as usize == c.members.len());
        if !ordered || c.members.iter().any(|&m| m as usize >= n) {
            return Err("clump member lists do not match the spheres".into());
        }
        if c.mass.iter().any(|&m| !positive(m)) || c.inertia.iter().flatten().any(|&i| !positive(i)) {
            return Err("a clump has a mass or inertia that is not finite and > 0".into());
        }
    }
    let nb = sim.world.kinds.len();
    let mut ids = s.id.clone();
    ids.extend(&sim.world.kinds.id);
    crate::loaded::unique_ids("spheres and bodies", &ids)?;
    let walls = sim.world.walls.len();
    for (i, wall) in sim.world.walls.iter().enumerate() {
        wall.check_loaded().map_err(|e| format!("wall {i} (\"{}\"): {e}", wall.name))?;
        if wall.material as usize >= sim.world.materials.len() {
            return Err(format!(
                "wall {i} (\"{}\"): material {} of {}",
                wall.name,
                wall.material,
                sim.world.materials.len()
            ));
        }
    }
    sim.world.contacts.check(n, walls, nb)?;
    same_length("the positions at the last list build", "spheres", n, &[("x_at_build", sim.built.x.len())])?;
    same_length(
        "the wall positions at the last list build",
        "walls",
        sim.world.walls.len(),
        &[("walls_at_build", sim.built.walls.len())],
    )?;
    if let Some(cell) = &sim.world.cell {
        let det = cell.h.determinant();
        if !(det.is_finite() && det > 0.0) {
            return Err(format!("periodic cell of volume {det} (must be finite and > 0)"));
        }
    }
    if !(sim.world.dt.is_finite()
        && sim.world.dt >= 0.0
        && sim.skin.is_finite()
        && sim.skin >= 0.0
        && sim.world.time.is_finite())
    {
        return Err(format!(
            "time step {}, skin {}, time {} (finite, the first two >= 0)",
            sim.world.dt, sim.skin, sim.world.time
        ));
    }
    Ok(())
}
