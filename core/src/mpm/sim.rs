//! The state of an MPM simulation and its set-up operations. The time step itself is in `step.rs`.

use crate::error::{GraniteError, Result};
use crate::ext::{ConstitutiveLaw, VelocityUpdate};
use crate::math::{Vec3, Voigt};
use crate::mpm::boundary::Boundary;
use crate::mpm::grid::{Grid, SlabIndex};
use crate::mpm::mesh::{Location, Mesh};
use crate::mpm::points::{retain_strided, NewPoint, Points};
use std::ops::Range;

/// When the stress is updated relative to the internal force (eq. 3.23).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum StressScheme {
    /// Update Stress First: strain from the mapped velocity, then forces from the new stress.
    Usf,
    /// Update Stress Last: forces from the old stress, strain from the updated grid velocity.
    Usl,
    /// Modified USL: like USL, but strain from the velocity remapped from the updated points.
    Musl,
}

impl StressScheme {
    pub fn parse(name: &str) -> Result<StressScheme> {
        match name.to_ascii_uppercase().as_str() {
            "USF" => Ok(StressScheme::Usf),
            "USL" => Ok(StressScheme::Usl),
            "MUSL" => Ok(StressScheme::Musl),
            _ => Err(GraniteError::param("scheme", name, "must be one of USF, USL, MUSL")),
        }
    }
    pub fn name(&self) -> &'static str {
        match self {
            StressScheme::Usf => "USF",
            StressScheme::Usl => "USL",
            StressScheme::Musl => "MUSL",
        }
    }
}

/// The stress rate the constitutive update integrates. The thesis (like CB-Geo) adds the law's
/// increment to the stress as it is; under large rotations that is not objective.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum StressRate {
    /// `sigma_{n+1} = sigma_n + d sigma_law` (thesis eq. 3.41).
    #[default]
    Plain,
    /// Jaumann: the stress is first turned with the point's spin `W = (L - L^T)/2`, exactly
    /// (`R = exp(W dt)`), then the law adds its increment.
    Jaumann,
}

/// Where the volumetric part of a point's strain increment comes from. With linear shape
/// functions, a flow that keeps volume (Mohr–Coulomb without dilatancy, plane strain) locks: the
/// bilinear velocity field of a cell must keep the volume at each of its points, which it can do
/// only by hardly moving, and collapse loads and factors of safety come out too high (an
/// embankment at 0.25 m cells: 1.6 for Bishop's 1.39, higher than at 0.5 m). Taking the
/// volumetric strain rate at the cell's centre for all its points (B-bar, selective reduced
/// integration of the volume) frees the deviatoric flow.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum VolumetricStrain {
    /// Each point's own velocity gradient (the thesis, CB-Geo).
    #[default]
    Point,
    /// The trace of the velocity gradient at the centre of the point's cell; the deviatoric part
    /// from the point's own. Linear shape functions only.
    CellCentre,
}

impl VolumetricStrain {
    pub fn parse(name: &str) -> Result<VolumetricStrain> {
        match name.to_ascii_lowercase().as_str() {
            "point" => Ok(VolumetricStrain::Point),
            "cell" => Ok(VolumetricStrain::CellCentre),
            _ => Err(GraniteError::param("volumetric_strain", name, "must be \"point\" or \"cell\"")),
        }
    }
}

impl StressRate {
    pub fn parse(name: &str) -> Result<StressRate> {
        match name.to_ascii_lowercase().as_str() {
            "plain" => Ok(StressRate::Plain),
            "jaumann" => Ok(StressRate::Jaumann),
            _ => Err(GraniteError::param("stress_rate", name, "must be \"plain\" or \"jaumann\"")),
        }
    }
}

/// The shape functions of the mesh (see `shape.rs`).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum ShapeFunctions {
    /// Thesis eqs. 3.11-3.16.
    #[default]
    Linear,
    /// uGIMP with points of a fixed size: `half_length` (m) is half a point's side.
    Gimp {
        half_length: f64,
    },
    QuadraticBspline,
    CubicBspline,
}

impl ShapeFunctions {
    pub const NAMES: &'static str = "\"linear\", \"gimp\", \"bspline2\" or \"bspline3\"";

    /// `half_length` is needed for GIMP only.
    pub fn parse(name: &str, half_length: Option<f64>) -> Result<ShapeFunctions> {
        match name.to_ascii_lowercase().as_str() {
            "linear" => Ok(ShapeFunctions::Linear),
            "gimp" => match half_length {
                Some(h) if h > 0.0 && h.is_finite() => Ok(ShapeFunctions::Gimp { half_length: h }),
                Some(h) => Err(GraniteError::param("point_size", 2.0 * h, "must be > 0")),
                None => Err(GraniteError::Setup(
                    "GIMP needs the size of a point: give #{ point_size } or create the points first".into(),
                )),
            },
            "bspline2" => Ok(ShapeFunctions::QuadraticBspline),
            "bspline3" => Ok(ShapeFunctions::CubicBspline),
            _ => Err(GraniteError::param("shape_functions", name, &format!("must be {}", Self::NAMES))),
        }
    }

    pub fn name(&self) -> &'static str {
        match self {
            ShapeFunctions::Linear => "linear",
            ShapeFunctions::Gimp { .. } => "gimp",
            ShapeFunctions::QuadraticBspline => "bspline2",
            ShapeFunctions::CubicBspline => "bspline3",
        }
    }

    /// APIC's `D_p = sum_i N_i d_i d_i^T` per axis where it is the same for every point (B-splines
    /// away from the mesh edges, Jiang et al. 2015: h^2/4 quadratic, h^2/3 cubic); None for bases
    /// whose `D_p` moves with the point.
    pub fn interior_moment(&self, mesh: &Mesh) -> Option<Vec3> {
        let factor = match self {
            ShapeFunctions::QuadraticBspline => 0.25,
            ShapeFunctions::CubicBspline => 1.0 / 3.0,
            ShapeFunctions::Linear | ShapeFunctions::Gimp { .. } => return None,
        };
        let mut d = [0.0; 3];
        for a in 0..mesh.dim {
            d[a] = factor * mesh.cell[a] * mesh.cell[a];
        }
        Some(d)
    }

    /// Nodes a point talks to along one axis.
    pub fn span(&self) -> usize {
        match self {
            ShapeFunctions::Linear => 2,
            ShapeFunctions::Gimp { .. } | ShapeFunctions::QuadraticBspline => 3,
            ShapeFunctions::CubicBspline => 4,
        }
    }

    /// Whether a mesh is large enough, and for GIMP whether its points fit a cell: a point
    /// larger than a cell would talk to more than three nodes per axis.
    pub fn check(&self, mesh: &Mesh) -> Result<()> {
        let fewest = (0..mesh.dim).map(|a| mesh.cells[a]).min().unwrap_or(1);
        if fewest + 1 < self.span() {
            return Err(GraniteError::Setup(format!(
                "{} shape functions need at least {} cells along every axis; this mesh has {fewest}",
                self.name(),
                self.span() - 1
            )));
        }
        if let ShapeFunctions::Gimp { half_length } = self {
            let h = mesh.min_cell();
            if 2.0 * half_length > h * (1.0 + 1e-12) {
                return Err(GraniteError::param(
                    "point_size",
                    2.0 * half_length,
                    &format!("GIMP points must not be larger than a cell ({h} m)"),
                ));
            }
        }
        Ok(())
    }

    /// Half a point's size in cells along each axis (GIMP; zero for the others).
    pub fn half_in_cells(&self, mesh: &Mesh) -> Vec3 {
        match self {
            ShapeFunctions::Gimp { half_length } => [0, 1, 2].map(|a| half_length / mesh.cell[a]),
            _ => [0.0; 3],
        }
    }
}

/// What happens to a point that leaves the mesh (thesis 3.4.6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum OutOfMeshPolicy {
    Delete,
    Stop,
}

pub struct Material {
    pub name: String,
    pub density: f64,
    pub law: Box<dyn ConstitutiveLaw>,
    /// Per-point state variables of this material's points, point-major.
    pub state: Vec<f64>,
    /// Number of points of this material (they are stored contiguously).
    pub count: usize,
    /// Where the law's per-point objects live in a run over several processes.
    pub spread: Option<crate::mpm::spread::Spread>,
}

impl Material {
    pub fn state_stride(&self) -> usize {
        self.law.state_names().len()
    }
}

/// A copy of everything a step changes, to fall back on when a step goes wrong.
#[derive(Debug, Clone)]
pub struct Snapshot {
    pub step: u64,
    pub time: f64,
    pub points: Points,
    pub states: Vec<Vec<f64>>,
    pub counts: Vec<usize>,
}

pub struct MpmSim {
    pub mesh: Mesh,
    pub points: Points,
    pub materials: Vec<Material>,
    pub boundary: Boundary,
    pub gravity: Vec3,
    /// Cundall damping coefficient D (eq. 3.26).
    pub damping: f64,
    pub scheme: StressScheme,
    pub stress_rate: StressRate,
    pub volumetric_strain: VolumetricStrain,
    pub shape: ShapeFunctions,
    pub velocity_update: Box<dyn VelocityUpdate>,
    pub dt: f64,
    pub time: f64,
    pub step: u64,
    pub out_of_mesh: OutOfMeshPolicy,
    /// Points deleted since the start because they left the mesh.
    pub deleted_points: u64,
    /// Things a user should be told about (deletions, mesh changes), drained by the driver.
    pub events: Vec<String>,
    next_id: u64,
    pub(crate) grid: Grid,
    pub(crate) slabs: SlabIndex,
    pub(crate) loc: Vec<Location>,
    /// The processes running this simulation together (None: this process alone).
    pub(crate) comm: Option<crate::comm::Comm>,
    balance_every: u64,
    /// The mesh was replaced (its boundary conditions with it) since the last run began.
    pub mesh_replaced: bool,
    /// Nodal loads already said to have lost material under some of their nodes.
    pub(crate) unloaded_said: Vec<usize>,
    /// Points faster than their material's waves were said to be flung.
    pub(crate) flung_said: bool,
}

impl MpmSim {
    pub fn new(mesh: Mesh, velocity_update: Box<dyn VelocityUpdate>) -> MpmSim {
        MpmSim {
            mesh,
            points: Points::default(),
            materials: Vec::new(),
            boundary: Boundary::default(),
            gravity: [0.0; 3],
            damping: 0.0,
            scheme: StressScheme::Usf,
            stress_rate: StressRate::Plain,
            volumetric_strain: VolumetricStrain::Point,
            shape: ShapeFunctions::Linear,
            velocity_update,
            dt: 0.0,
            time: 0.0,
            step: 0,
            out_of_mesh: OutOfMeshPolicy::Delete,
            deleted_points: 0,
            events: Vec::new(),
            next_id: 0,
            grid: Grid::default(),
            slabs: SlabIndex::default(),
            loc: Vec::new(),
            comm: None,
            balance_every: crate::mpm::spread::DEFAULT_BALANCE_EVERY,
            mesh_replaced: false,
            unloaded_said: Vec::new(),
            flung_said: false,
        }
    }

    /// Runs this simulation together with the other processes of `comm`: the per-point objects of
    /// spreadable laws (RVEs) are shared out among them, each kept by one process only.
    pub fn set_communicator(&mut self, comm: crate::comm::Comm) {
        self.comm = Some(comm);
        for k in 0..self.materials.len() {
            if self.materials[k].spread.is_some() {
                continue;
            }
            if let Some(mut spread) = self.new_spread(self.materials[k].law.as_ref()) {
                let m = &mut self.materials[k];
                let here = spread.add(m.count);
                if let Some(objects) = m.law.point_objects() {
                    objects.release_objects(&here);
                }
                m.spread = Some(spread);
            }
        }
    }

    /// Steps between two balances of the spread materials' objects over the processes (0: keep
    /// them where they are). Without other processes it changes nothing.
    pub fn set_balance_every(&mut self, steps: u64) {
        self.balance_every = steps;
        for spread in self.materials.iter_mut().filter_map(|m| m.spread.as_mut()) {
            spread.balance_every = steps;
        }
    }

    fn new_spread(&self, law: &dyn ConstitutiveLaw) -> Option<crate::mpm::spread::Spread> {
        let spreadable = law.point_objects().is_some_and(|o| o.spreadable());
        let comm = self.comm.as_ref().filter(|c| c.size() > 1 && spreadable)?;
        let mut spread = crate::mpm::spread::Spread::new(comm.clone());
        spread.balance_every = self.balance_every;
        Some(spread)
    }

    /// Whether this process writes the simulation's files (the first of a run's processes).
    pub fn writes_files(&self) -> bool {
        self.comm.as_ref().is_none_or(|c| c.rank() == 0)
    }

    /// The processes running this simulation, if more than this one.
    pub fn communicator(&self) -> Option<&crate::comm::Comm> {
        self.comm.as_ref()
    }

    pub(crate) fn next_id(&self) -> u64 {
        self.next_id
    }

    pub(crate) fn set_next_id(&mut self, id: u64) {
        self.next_id = id;
    }

    pub fn dim(&self) -> usize {
        self.mesh.dim
    }

    pub fn add_material(&mut self, name: &str, density: f64, law: Box<dyn ConstitutiveLaw>) -> Result<usize> {
        if !(density > 0.0 && density.is_finite()) {
            return Err(GraniteError::param_in(format!("`density` of material \"{name}\""), density, "must be > 0"));
        }
        let spread = self.new_spread(law.as_ref());
        self.materials.push(Material { name: name.into(), density, law, state: Vec::new(), count: 0, spread });
        Ok(self.materials.len() - 1)
    }

    pub fn material_index(&self, name: &str) -> Result<usize> {
        self.materials.iter().position(|m| m.name == name).ok_or_else(|| GraniteError::Unknown {
            kind: "material".into(),
            name: name.into(),
            known: self.materials.iter().map(|m| m.name.clone()).collect::<Vec<_>>().join(", "),
        })
    }

    /// Points `[start, end)` of material `m`.
    pub fn material_range(&self, m: usize) -> Range<usize> {
        let start: usize = self.materials[..m].iter().map(|m| m.count).sum();
        start..start + self.materials[m].count
    }

    /// Adds points of material `m` at the given positions, each with volume `volume[k]`
    /// (mass = density x volume), velocity `v` and initial stress `stress`.
    pub fn add_points(&mut self, m: usize, positions: &[Vec3], volumes: &[f64], v: Vec3, stress: Voigt) -> Result<()> {
        if m >= self.materials.len() {
            return Err(GraniteError::Setup(format!("no material with index {m}")));
        }
        for (k, x) in positions.iter().enumerate() {
            if !self.mesh.contains(*x) {
                return Err(GraniteError::Setup(format!(
                    "material point {k} at {x:?} is outside the mesh [{:?}, {:?}]",
                    self.mesh.origin,
                    self.mesh.upper()
                )));
            }
            if !(volumes[k] > 0.0) {
                return Err(GraniteError::param("volume", volumes[k], "must be > 0"));
            }
        }
        let density = self.materials[m].density;
        let new: Vec<NewPoint> = positions
            .iter()
            .zip(volumes)
            .map(|(&x, &vol)| NewPoint { x, volume: vol, mass: density * vol, v, stress })
            .collect();
        let at = self.material_range(m).end;
        self.points.insert(at, m as u32, self.next_id, &new);
        self.next_id += new.len() as u64;
        let here = match self.materials[m].spread.as_mut() {
            Some(spread) => spread.add(new.len()),
            None => vec![true; new.len()],
        };
        if let Some(objects) = self.materials[m].law.point_objects() {
            objects.points_added(&here)?;
        }
        let material = &mut self.materials[m];
        let stride = material.state_stride();
        let mut fresh = vec![0.0; stride];
        material.law.init_state(&mut fresh);
        for _ in 0..new.len() {
            material.state.extend_from_slice(&fresh);
        }
        material.count += new.len();
        Ok(())
    }

    /// Replaces the background mesh; points stay where they are (thesis 5.2.1). Boundary conditions
    /// refer to nodes of the old mesh and are cleared.
    pub fn replace_mesh(&mut self, mesh: Mesh) -> Result<()> {
        if mesh.dim != self.mesh.dim {
            return Err(GraniteError::param("dim", mesh.dim, &format!("a new mesh must keep dim = {}", self.mesh.dim)));
        }
        if let Some(p) = self.points.x.iter().position(|x| !mesh.contains(*x)) {
            return Err(GraniteError::Setup(format!(
                "the new mesh does not contain material point {} at {:?}",
                self.points.id[p], self.points.x[p]
            )));
        }
        self.mesh = mesh;
        self.boundary.clear();
        self.unloaded_said.clear();
        self.mesh_replaced = true;
        Ok(())
    }

    /// Finds the points that carry loads where they now are; a loaded point that is gone (it left
    /// the mesh) takes its share of the load with it, which the user is told.
    pub(crate) fn locate_point_loads(&mut self) {
        for load in &mut self.boundary.point_loads {
            let (lost, carried) = load.locate(&self.points.id);
            if lost > 0 {
                let carried = crate::math::norm3(carried);
                self.events.push(format!(
                    "step {} (t = {:.6e} s): {lost} point(s) loaded by {} are gone (they left the mesh), with \
                     their share of the load ({carried:.4e} N at factor 1); {} points carry the rest",
                    self.step,
                    self.time,
                    load.name,
                    load.ids.len()
                ));
            }
        }
    }

    /// Stable time step of explicit MPM: the cell crossing time of the fastest P wave.
    pub fn critical_dt(&self) -> Option<f64> {
        let h = self.mesh.min_cell();
        self.materials
            .iter()
            .filter(|m| m.count > 0)
            .filter_map(|m| m.law.wave_speed(m.density))
            .map(|c| h / c)
            .reduce(f64::min)
    }

    pub fn set_dt(&mut self, dt: f64) -> Result<()> {
        self.dt = crate::params::time_step(dt)?;
        Ok(())
    }

    /// Whether `dt` is within the stability limit of the points present (a script's `sim.dt`
    /// checks it at once; a run checks it again, as points and materials may come later).
    pub fn check_dt(&self, dt: f64) -> Result<()> {
        crate::params::time_step_within(
            dt,
            self.critical_dt(),
            "the stability limit cell/c_p of this mesh and material",
        )
    }

    /// Checks everything a run needs; called before stepping.
    pub fn validate(&self) -> Result<()> {
        crate::params::require_time_step(self.dt)?;
        self.check_dt(self.dt)?;
        self.shape.check(&self.mesh)?;
        if !(self.damping >= 0.0 && self.damping < 1.0) {
            return Err(GraniteError::param("damping", self.damping, "must be in [0, 1)"));
        }
        Ok(())
    }

    /// The laws' columns for series.csv (`ConstitutiveLaw::series`), summed over the
    /// materials that give the same name, in the order they first appear.
    pub fn law_series(&self) -> Vec<(&'static str, f64)> {
        let mut out: Vec<(&'static str, f64)> = Vec::new();
        for m in &self.materials {
            let Some(objects) = m.law.point_objects() else { continue };
            for (name, value) in objects.series(&m.state) {
                match out.iter_mut().find(|(n, _)| *n == name) {
                    Some((_, v)) => *v += value,
                    None => out.push((name, value)),
                }
            }
        }
        out
    }

    pub fn snapshot(&self) -> Snapshot {
        Snapshot {
            step: self.step,
            time: self.time,
            points: self.points.clone(),
            states: self.materials.iter().map(|m| m.state.clone()).collect(),
            counts: self.materials.iter().map(|m| m.count).collect(),
        }
    }

    pub fn restore(&mut self, snap: Snapshot) {
        self.step = snap.step;
        self.time = snap.time;
        self.points = snap.points;
        for ((m, state), count) in self.materials.iter_mut().zip(snap.states).zip(snap.counts) {
            m.state = state;
            m.count = count;
        }
    }

    /// Removes points by mask, keeping material blocks and their state aligned.
    pub(crate) fn remove_points(&mut self, keep: &[bool]) {
        let mut start = 0;
        for m in &mut self.materials {
            let mask = &keep[start..start + m.count];
            retain_strided(&mut m.state, m.law.state_names().len(), mask);
            if let Some(objects) = m.law.point_objects() {
                objects.points_removed(mask);
            }
            if let Some(spread) = m.spread.as_mut() {
                spread.retain(mask);
            }
            start += m.count;
            m.count = mask.iter().filter(|&&k| k).count();
        }
        self.points.retain(keep);
    }
}
