//! `dem_rve`: the MPMxDEM law (thesis chapter 4). Every material point owns a periodic DEM sample
//! (a Representative Volume Element), a copy of a prepared one. Each call deforms the RVE by the
//! point's strain increment as a velocity gradient applied over `T_DEM` (eqs. 4.1-4.6), on top of
//! the contact forces, and returns its Love-Weber stress (4.7), tension positive like the MPM.

use super::dem_rve_adaptive::{state, Activation, Restart, Role, Tolerances};
use super::dem_rve_device::DeviceRves;
use super::dem_rve_share::Twins;
use granite_core::dem::{DemSim, Rve};
use granite_core::ext::constitutive::ObjectMap;
use granite_core::ext::rve::RveDeviceChoice;
use granite_core::ext::{ConstitutiveLaw, ConstitutiveLawFactory, LawBatch, PointObjects, RveOrder, RveReport};
use granite_core::math::Voigt;
use granite_core::params::{ParamSpec, Params};
use granite_core::{GraniteError, Result};
use nalgebra::{Matrix3, SymmetricEigen};
use rayon::prelude::*;
use std::sync::{Arc, Mutex, RwLock};
use std::time::Instant;

pub struct DemRveFactory;

pub const SPECS: &[ParamSpec] = &[
    ParamSpec::optional("inertial_number", 1e-2, "I_n of eq. 4.1 (quasi-static below about 1e-2)"),
    ParamSpec::optional(
        "strategy",
        1.0,
        "1: keep dt, ceil the deformation time (eq. 4.5); 0: keep T, shorten the last step (eq. 4.4)",
    ),
    ParamSpec::optional("vertical_axis", 2.0, "RVE axis along gravity for P_min (eq. 4.2): 0, 1 or 2"),
    ParamSpec::optional("gravity", 9.81, "gravity magnitude for the RVE's weight in P_min (eq. 4.2), m/s^2"),
    ParamSpec::unset("grain_size", "characteristic grain size l of eq. 4.1 (default: mean diameter of the RVE)"),
    ParamSpec::optional("max_dem_steps", 1e7, "most DEM steps one call may take (a safeguard)"),
    ParamSpec::unset("dem_steps", "fixed DEM steps per call instead of eqs. 4.1-4.5 (benchmarks, comparisons)"),
    ParamSpec::optional(
        "share",
        1.0,
        "1: points whose RVEs and strain increments are bitwise the same step one RVE (exact); 0: each steps its own",
    ),
    ParamSpec::optional(
        "adaptive",
        0.0,
        "1: points close to an active point follow it instead of stepping their RVE (docs/mpmxdem.md)",
    ),
    ParamSpec::optional("adaptive_coarsen", 0.001, "adaptive: distance (relative stress error) under which a point follows"),
    ParamSpec::optional("adaptive_refine", 0.002, "adaptive: distance over which a follower steps its own RVE again"),
    ParamSpec::optional("adaptive_every", 10.0, "adaptive: MPM steps between two coarsening passes (the history's memory)"),
    ParamSpec::optional(
        "adaptive_restart",
        0.0,
        "adaptive: a follower steps again from 0: a copy of its leader's RVE; 1: its own, caught up with the strain it missed",
    ),
];

/// What one point's RVE carries between calls.
struct PointRve {
    rve: Rve,
    /// Love-Weber stress of `rve` as the last call left it: the next call's P (eq. 4.3) without
    /// a second pass over the contacts. None until computed (a new or reloaded RVE).
    stress: Option<Voigt>,
}

pub struct DemRve {
    params: Params,
    template: Rve,
    /// One slot per material point; empty for points whose RVE lives in another process.
    rves: RwLock<Vec<Mutex<Option<PointRve>>>>,
    inertial_number: f64,
    keep_dt: bool,
    vertical_axis: usize,
    /// Grain density rho_g and size l of eq. 4.1.
    density: f64,
    grain_size: f64,
    /// Weight of the RVE W^RVE of eq. 4.2.
    weight: f64,
    max_steps: u64,
    fixed_steps: Option<u64>,
    /// The first RVE event (e.g. a time step above its contacts' stability bound), passed on
    /// once: every RVE of the material would say the same. Of one MPM step's, the lowest point's
    /// (whatever thread updated which point).
    event: Mutex<Option<(usize, String)>>,
    event_said: std::sync::atomic::AtomicBool,
    /// Volume of the RVE's spheres (the void ratio's denominator).
    solid_volume: f64,
    /// The device the RVEs live on (`device: "gpu"`), or None: each point's RVE in `rves`,
    /// stepped by the thread that updates the point.
    device: Option<DeviceRves>,
    /// Whether the RVE's time step was checked against its contacts (a device's RVEs: once,
    /// on the prepared sample, before their first steps).
    time_step_checked: std::sync::atomic::AtomicBool,
    /// Exact sharing of bitwise-equal RVEs among this process's points (`share`).
    share: bool,
    twins: Mutex<Twins>,
    /// Sphere-steps exact sharing spared this process.
    shared_sphere_steps: Mutex<f64>,
    /// Similarity-based activation (`adaptive`), the same in every process.
    activation: Option<Mutex<Activation>>,
}

impl ConstitutiveLawFactory for DemRveFactory {
    fn name(&self) -> &str {
        "dem_rve"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        SPECS
    }
    fn description(&self) -> &str {
        "MPMxDEM: a periodic DEM sample per material point (needs `rve`, a prepared periodic dem(); `device: \"gpu\"` steps them on a GPU)"
    }
    fn build(&self, params: Params) -> Result<Box<dyn ConstitutiveLaw>> {
        self.build_with(params, &ObjectMap::new())
    }
    fn build_with(&self, params: Params, objects: &ObjectMap) -> Result<Box<dyn ConstitutiveLaw>> {
        Ok(Box::new(DemRve::new(params, objects)?))
    }
    fn restore(
        &self,
        given: &granite_core::registry::ParamMap,
        objects: serde_json::Value,
        registry: &dyn granite_core::ext::contact::ContactLawSource,
    ) -> Result<Box<dyn ConstitutiveLaw>> {
        let bad = || GraniteError::Other("dem_rve checkpoint: expected {template, rves}".into());
        let serde_json::Value::Object(mut map) = objects else { return Err(bad()) };
        let template = Rve::from_json(map.remove("template").ok_or_else(bad)?, registry)?;
        let params = Params::resolve("law \"dem_rve\"", SPECS, given)?;
        let mut objects = ObjectMap::new();
        objects.insert("rve".into(), std::sync::Arc::new(template));
        // RVEs saved from a device resume on it, or on the CPU threads where there is none.
        let mut moved_off = None;
        if let Some(serde_json::Value::String(name)) = map.remove("device") {
            match registry.rve_device(&name) {
                Ok(device) => {
                    objects.insert("device".into(), Arc::new(RveDeviceChoice(device)));
                }
                Err(e) => moved_off = Some(format!("the RVEs saved on device \"{name}\" run on the CPU threads ({e})")),
            }
        }
        let law = DemRve::new(params, &objects)?;
        if let Some(said) = moved_off {
            law.tell_once(0, said);
        }
        if let (Some(a), Some(saved)) = (&law.activation, map.remove("adaptive")) {
            a.lock()
                .unwrap_or_else(|e| e.into_inner())
                .load_json(saved)
                .map_err(|e| GraniteError::Other(format!("dem_rve checkpoint: adaptive RVEs: {e}")))?;
        }
        let serde_json::Value::Array(rves) = map.remove("rves").ok_or_else(bad)? else { return Err(bad()) };
        // Points whose saved RVEs are equal share one again (a checkpoint written before their
        // increments parted).
        let keepers = if law.share { equal_to_earlier(&rves) } else { vec![None; rves.len()] };
        law.twins.lock().unwrap_or_else(|e| e.into_inner()).restore(&keepers);
        if let Some(device) = &law.device {
            let rves = rves.into_iter().map(|v| Rve::from_json(v, registry).map(Some)).collect::<Result<Vec<_>>>()?;
            device.add(rves)?;
            return Ok(Box::new(law));
        }
        {
            let mut store = law.rves.write().map_err(|_| GraniteError::Other("RVE store poisoned".into()))?;
            for v in rves {
                store.push(Mutex::new(Some(PointRve { rve: Rve::from_json(v, registry)?, stress: None })));
            }
        }
        Ok(Box::new(law))
    }
}

impl DemRve {
    /// The law for resolved parameters and the prepared sample in `objects["rve"]`.
    pub fn new(params: Params, objects: &ObjectMap) -> Result<DemRve> {
        let share = params.flag("share")?;
        let tolerances = if params.flag("adaptive")? {
            let coarsen = params.non_negative("adaptive_coarsen")?;
            let refine = params.positive("adaptive_refine")?;
            if refine <= coarsen {
                return Err(GraniteError::param_in(
                    format!("`adaptive_refine` of {}", params.owner()),
                    refine,
                    &format!("must exceed adaptive_coarsen = {coarsen} (a follower would step again at once)"),
                ));
            }
            let every = params.count("adaptive_every")?.max(1);
            let restart = match params.get("adaptive_restart") {
                0.0 => Restart::CopyLeader,
                1.0 => Restart::OwnCaughtUp,
                other => {
                    return Err(GraniteError::param_in(
                        format!("`adaptive_restart` of {}", params.owner()),
                        other,
                        "must be 0 (from a copy of the leader's RVE) or 1 (its own RVE, caught up)",
                    ))
                }
            };
            Some(Tolerances { coarsen, refine, every, restart })
        } else {
            None
        };
        // A script hands the DEM simulation it prepared; a checkpoint, the RVE it saved.
        let given = objects.get("rve");
        let template =
            match (given.and_then(|o| o.downcast_ref::<Rve>()), given.and_then(|o| o.downcast_ref::<DemSim>())) {
                (Some(rve), _) => rve.clone(),
                (None, Some(dem)) => Rve::prepare(dem.clone(), params.owner())?,
                (None, None) => {
                    return Err(GraniteError::MissingParameter {
                        name: "rve".into(),
                        context: params.owner().into(),
                        expected: "a prepared periodic DEM sample: a dem() simulation with periodic(...)".into(),
                    })
                }
            };
        let inertial_number = params.positive("inertial_number")?;
        let strategy = params.get("strategy");
        if strategy != 0.0 && strategy != 1.0 {
            return Err(GraniteError::param_in(
                format!("`strategy` of {}", params.owner()),
                strategy,
                "must be 0 (eq. 4.4) or 1 (eq. 4.5)",
            ));
        }
        let vertical = params.get("vertical_axis");
        if ![0.0, 1.0, 2.0].contains(&vertical) {
            return Err(GraniteError::param_in(
                format!("`vertical_axis` of {}", params.owner()),
                vertical,
                "must be 0, 1 or 2",
            ));
        }
        let mass = template.mass();
        let volume = template.solid_volume();
        let mean_diameter = template.mean_diameter();
        let grain_size = if params.is_set("grain_size") { params.positive("grain_size")? } else { mean_diameter };
        let g = params.non_negative("gravity")?;
        let max_steps = params.count("max_dem_steps")?;
        let fixed_steps = if params.is_set("dem_steps") { Some(params.count("dem_steps")?) } else { None };
        if let Some(n) = fixed_steps.filter(|&n| n > max_steps) {
            return Err(GraniteError::param_in(
                format!("`dem_steps` of {}", params.owner()),
                n,
                &format!("must not exceed max_dem_steps = {max_steps}"),
            ));
        }
        let device = match objects.get("device") {
            None => None,
            Some(d) => {
                let d = d.downcast_ref::<RveDeviceChoice>().ok_or_else(|| {
                    GraniteError::Setup(format!("{}: `device` must be \"cpu\" or \"gpu\"", params.owner()))
                })?;
                Some(DeviceRves::new(d.0.clone()))
            }
        };
        let mut law = DemRve {
            weight: mass * g,
            density: mass / volume,
            grain_size,
            inertial_number,
            keep_dt: strategy == 1.0,
            vertical_axis: vertical as usize,
            max_steps,
            fixed_steps,
            rves: RwLock::new(Vec::new()),
            template,
            params,
            event: Mutex::new(None),
            event_said: std::sync::atomic::AtomicBool::new(false),
            solid_volume: volume,
            device,
            time_step_checked: std::sync::atomic::AtomicBool::new(false),
            share,
            twins: Mutex::new(Twins::default()),
            shared_sphere_steps: Mutex::new(0.0),
            activation: None,
        };
        if let Some(tolerances) = tolerances {
            // Relative distances are floored at the RVE's own weight over its base (eq. 4.2).
            law.activation = Some(Mutex::new(Activation::new(tolerances, law.p_min(&law.template))));
        }
        Ok(law)
    }
}

/// Plan of one call: DEM steps of `dt` and, with eq. 4.4, a shorter last one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeformationPlan {
    /// T^DEM: the time the increment is applied over.
    pub duration: f64,
    /// Full steps of the RVE's time step.
    pub full_steps: u64,
    /// A last step of this length (eq. 4.4), or 0.
    pub last_step: f64,
}

impl DemRve {
    /// P^min of eq. 4.2: the RVE's weight over the area of its bottom face.
    pub fn p_min(&self, rve: &Rve) -> f64 {
        self.p_min_of_cell(&rve.cell())
    }

    /// P^min of eq. 4.2 for a cell of base vectors `h` (columns).
    fn p_min_of_cell(&self, h: &Matrix3<f64>) -> f64 {
        let (i, j) = match self.vertical_axis {
            0 => (1, 2),
            1 => (2, 0),
            _ => (0, 1),
        };
        let area = h.column(i).cross(&h.column(j)).norm();
        if area > 0.0 {
            self.weight / area
        } else {
            0.0
        }
    }

    /// T^eps of eq. 4.1 and the DEM steps of eqs. 4.4/4.5 for an increment whose largest
    /// principal magnitude is `max_strain`, at mean stress `p` (already bounded below by P^min),
    /// with DEM time step `dt`. At least one step is taken.
    pub fn plan(&self, max_strain: f64, p: f64, dt: f64) -> DeformationPlan {
        if let Some(n) = self.fixed_steps {
            return DeformationPlan { duration: n as f64 * dt, full_steps: n, last_step: 0.0 };
        }
        let t_eps = max_strain / self.inertial_number * (self.density * self.grain_size * self.grain_size / p).sqrt();
        if !(t_eps > 0.0) || !t_eps.is_finite() {
            return DeformationPlan { duration: dt, full_steps: 1, last_step: 0.0 };
        }
        if self.keep_dt {
            let n = ((t_eps / dt).ceil() as u64).max(1);
            DeformationPlan { duration: n as f64 * dt, full_steps: n, last_step: 0.0 }
        } else {
            let n = (t_eps / dt).floor() as u64;
            let rest = t_eps - n as f64 * dt;
            DeformationPlan { duration: t_eps, full_steps: n, last_step: if rest > 1e-12 * dt { rest } else { 0.0 } }
        }
    }
}

/// In the order of `dem_rve_adaptive::state`'s indices.
const STATE: &[&str] = &[
    "rve_mean_stress",
    "rve_deviatoric_stress",
    "void_ratio",
    "coordination",
    "rattlers",
    "dem_steps",
    "no_contacts",
    "dem_sphere_steps",
];

impl ConstitutiveLaw for DemRve {
    fn name(&self) -> &str {
        "dem_rve"
    }
    fn params(&self) -> &Params {
        &self.params
    }
    fn state_names(&self) -> &[&'static str] {
        STATE
    }
    fn update(&self, batch: LawBatch<'_>) -> Result<()> {
        if self.whole_batch() && batch.first == 0 && batch.len() == self.points() {
            // `complete_update` follows, called by the MPM step.
            let all = vec![true; batch.len()];
            return self.update_batch(&all, batch).map(|_| ());
        }
        if self.device.is_some() || self.activation.is_some() {
            return Err(GraniteError::Other(format!(
                "dem_rve with a device or adaptive RVEs updates all {} points at once, not points {}..{}",
                self.points(),
                batch.first,
                batch.first + batch.len()
            )));
        }
        let rves = self.rves.read().map_err(|_| GraniteError::Other("RVE store poisoned".into()))?;
        for k in 0..batch.len() {
            let index = batch.first + k;
            if let Some((from, to)) = self.twins.lock().unwrap_or_else(|e| e.into_inner()).own(index) {
                copy_within(&rves, from, to)?;
            }
            let mut rve = rves
                .get(index)
                .ok_or_else(|| GraniteError::Other(format!("no RVE for material point {index}")))?
                .lock()
                .map_err(|_| GraniteError::Other(format!("RVE {index} poisoned")))?;
            let Some(rve) = &mut *rve else {
                return Err(GraniteError::Other(format!("the RVE of material point {index} is in another process")));
            };
            let report = self.step_own(index, &batch.dstrain[k], rve)?;
            self.record(
                &report,
                rve.rve.grain_count(),
                &mut batch.stress[k],
                &mut batch.state[k * STATE.len()..][..STATE.len()],
            );
        }
        Ok(())
    }
    fn point_objects(&self) -> Option<&dyn PointObjects> {
        Some(self)
    }
}

impl PointObjects for DemRve {
    fn points_added(&self, here: &[bool]) -> Result<()> {
        self.twins.lock().unwrap_or_else(|e| e.into_inner()).add(here, self.share);
        if let Some(a) = &self.activation {
            a.lock().unwrap_or_else(|e| e.into_inner()).add(here.len());
        }
        if let Some(device) = &self.device {
            return device.add(here.iter().map(|&h| h.then(|| self.template.clone())).collect());
        }
        let mut rves = self.rves.write().map_err(|_| GraniteError::Other("RVE store poisoned".into()))?;
        for &here in here {
            rves.push(Mutex::new(here.then(|| PointRve { rve: self.template.clone(), stress: None })));
        }
        Ok(())
    }
    fn spreadable(&self) -> bool {
        true
    }
    fn whole_batch(&self) -> bool {
        self.device.is_some() || self.share || self.activation.is_some()
    }
    fn update_where(&self, here: &[bool], batch: LawBatch<'_>) -> Result<Vec<f64>> {
        self.update_batch(here, batch)
    }
    fn complete_update(&self, stress: &mut [Voigt], state: &mut [f64]) -> Result<Vec<(usize, usize)>> {
        Ok(match &self.activation {
            Some(a) => a.lock().unwrap_or_else(|e| e.into_inner()).complete(stress, state, STATE.len()),
            None => Vec::new(),
        })
    }
    fn copy_object(&self, from: usize, to: usize) -> Result<()> {
        let mut twins = self.twins.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((a, b)) = twins.detach(to) {
            self.copy_rve(a, b)?;
        }
        self.copy_rve(twins.object_of(from), to)
    }
    fn series(&self, state: &[f64]) -> Vec<(&'static str, f64)> {
        let active = match &self.activation {
            Some(a) => a.lock().unwrap_or_else(|e| e.into_inner()).active(),
            None => state.len() / STATE.len(),
        };
        let steps: f64 = state.chunks(STATE.len()).map(|st| st[state::DEM_STEPS]).sum();
        vec![("rve_active", active as f64), ("rve_sphere_steps", steps * self.template.grain_count() as f64)]
    }
    fn process_savings(&self) -> f64 {
        *self.shared_sphere_steps.lock().unwrap_or_else(|e| e.into_inner())
    }
    fn run_summary(&self, state: &[f64], spared: f64) -> Vec<(String, serde_json::Value)> {
        let done: f64 = state.chunks(STATE.len()).map(|st| st[state::DEM_SPHERE_STEPS]).sum();
        // `done` counts the increments' work as if each point had stepped its own RVE.
        let mut out = vec![
            ("rve_sphere_steps".to_string(), done.into()),
            ("rve_sphere_steps_shared".to_string(), spared.into()),
            ("rve_sphere_steps_computed".to_string(), (done - spared).into()),
        ];
        if let Some(a) = &self.activation {
            let followed = a.lock().unwrap_or_else(|e| e.into_inner()).followed();
            let skipped = followed.leader_dem_steps * self.template.grain_count() as f64;
            out.push(("rve_point_steps_followed".to_string(), followed.point_steps.into()));
            out.push(("rve_sphere_steps_followed".to_string(), skipped.into()));
        }
        out
    }
    fn release_objects(&self, keep: &[bool]) {
        // Riders of a point that leaves get its RVE first.
        for (point, _) in keep.iter().enumerate().filter(|(_, &k)| !k) {
            let copy = self.twins.lock().unwrap_or_else(|e| e.into_inner()).detach(point);
            if let Some(Err(e)) = copy.map(|(from, to)| self.copy_rve(from, to)) {
                self.tell_once(point, format!("could not hand its RVE to the points sharing it: {e}"));
            }
        }
        if let Some(device) = &self.device {
            if let Err(e) = device.release(keep) {
                self.tell_once(0, format!("the device kept RVEs that moved to other processes: {e}"));
            }
            return;
        }
        if let Ok(rves) = self.rves.read() {
            for (slot, &keep) in rves.iter().zip(keep) {
                if !keep {
                    *slot.lock().unwrap_or_else(|e| e.into_inner()) = None;
                }
            }
        }
    }
    fn point_object(&self, point: usize) -> Result<serde_json::Value> {
        self.with_rve(point, |rve| rve.to_json())
            .unwrap_or_else(|| Err(GraniteError::Other(format!("no RVE of material point {point} in this process"))))
    }
    fn adopt_point_object(&self, point: usize, object: serde_json::Value) -> Result<()> {
        let rve = Rve::from_json_like(object, &self.template)?;
        if let Some((from, to)) = self.twins.lock().unwrap_or_else(|e| e.into_inner()).detach(point) {
            self.copy_rve(from, to)?;
        }
        if let Some(device) = &self.device {
            return device.put(point, rve);
        }
        let rves = self.rves.read().map_err(|_| GraniteError::Other("RVE store poisoned".into()))?;
        let slot = rves.get(point).ok_or_else(|| GraniteError::Other(format!("no material point {point}")))?;
        *slot.lock().unwrap_or_else(|e| e.into_inner()) = Some(PointRve { rve, stress: None });
        Ok(())
    }
    fn save_objects_from(&self, points: Vec<serde_json::Value>) -> Result<Option<serde_json::Value>> {
        let mut saved = serde_json::json!({ "template": self.template.to_json()?, "rves": points });
        if let Some(device) = &self.device {
            saved["device"] = device.name().into();
        }
        if let Some(a) = &self.activation {
            saved["adaptive"] = a.lock().unwrap_or_else(|e| e.into_inner()).to_json();
        }
        Ok(Some(saved))
    }
    fn pending_event(&self) -> Option<(usize, String)> {
        self.event.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }
    fn set_pending_event(&self, event: Option<(usize, String)>) {
        *self.event.lock().unwrap_or_else(|e| e.into_inner()) = event;
    }
    fn points_removed(&self, keep: &[bool]) {
        {
            let mut twins = self.twins.lock().unwrap_or_else(|e| e.into_inner());
            for (point, _) in keep.iter().enumerate().filter(|(_, &k)| !k) {
                if let Some(Err(e)) = twins.detach(point).map(|(from, to)| self.copy_rve(from, to)) {
                    self.tell_once(point, format!("could not hand its RVE to the points sharing it: {e}"));
                }
            }
            twins.retain(keep);
        }
        if let Some(a) = &self.activation {
            a.lock().unwrap_or_else(|e| e.into_inner()).retain(keep);
        }
        if let Some(Err(e)) = self.device.as_ref().map(|d| d.remove_points(keep)) {
            self.tell_once(0, format!("the device could not drop the removed points' RVEs: {e}"));
        }
        if let Ok(mut rves) = self.rves.write() {
            let mut k = keep.iter();
            rves.retain(|_| *k.next().unwrap_or(&true));
        }
    }
    fn bytes_per_point(&self) -> usize {
        self.template.memory_bytes().max(1)
    }
    fn take_events(&self) -> Vec<String> {
        let Some((point, event)) = self.event.lock().unwrap_or_else(|e| e.into_inner()).take() else {
            return Vec::new();
        };
        self.event_said.store(true, std::sync::atomic::Ordering::Relaxed);
        vec![format!("RVE of material point {point} (said once for all RVEs): {event}")]
    }
    fn object_frame(&self, point: usize) -> Option<(Vec<granite_core::math::Vec3>, Vec<granite_core::io::vtk::Field>)> {
        self.with_rve(point, |rve| rve.frame())
    }
    fn save_objects(&self) -> Result<Option<serde_json::Value>> {
        let count = match &self.device {
            Some(device) => device.points(),
            None => self.rves.read().map_err(|_| GraniteError::Other("RVE store poisoned".into()))?.len(),
        };
        let list = (0..count).map(|k| self.point_object(k)).collect::<Result<Vec<_>>>()?;
        self.save_objects_from(list)
    }
}

/// For each value, the first earlier one equal to it (None: the first of its kind).
fn equal_to_earlier(values: &[serde_json::Value]) -> Vec<Option<usize>> {
    let mut firsts: Vec<usize> = Vec::new();
    values
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let first = firsts.iter().copied().find(|&k| values[k] == *v);
            if first.is_none() {
                firsts.push(i);
            }
            first
        })
        .collect()
}

/// Makes the RVE in slot `to` a copy of the one in slot `from`.
fn copy_within(rves: &[Mutex<Option<PointRve>>], from: usize, to: usize) -> Result<()> {
    let copy = {
        let source = rves.get(from).and_then(|r| r.lock().ok());
        source.as_ref().and_then(|r| r.as_ref()).map(|r| PointRve { rve: r.rve.clone(), stress: r.stress })
    };
    let copy = copy.ok_or_else(|| GraniteError::Other(format!("no RVE of material point {from} to share")))?;
    let slot = rves.get(to).ok_or_else(|| GraniteError::Other(format!("no material point {to}")))?;
    *slot.lock().unwrap_or_else(|e| e.into_inner()) = Some(copy);
    Ok(())
}

impl DemRve {
    /// The order of one RVE for a strain increment `de` (eqs. 4.1-4.6): the velocity gradient
    /// that applies it over T^DEM, and the DEM steps, from the stress `before` (P of eq. 4.3) and
    /// the cell `h` (P^min of eq. 4.2).
    fn order(&self, index: usize, de: &Voigt, before: &Voigt, h: &Matrix3<f64>, dt: f64) -> Result<RveOrder> {
        // -0.0 and 0.0 give one order (exact sharing groups increments by their bits).
        let de = de.map(|x| x + 0.0);
        let e = granite_core::math::strain_matrix(&de);
        let max_strain = SymmetricEigen::new(e).eigenvalues.amax();
        let p = ((before[0] + before[1] + before[2]).abs() / 3.0).max(self.p_min_of_cell(h));
        let plan = self.plan(max_strain, p, dt);
        let steps = plan.full_steps + u64::from(plan.last_step > 0.0);
        if steps > self.max_steps {
            return Err(GraniteError::Other(format!(
                "RVE of point {index} would need {steps} DEM steps for this increment (T = {:.3e} s, P = {p:.3e} Pa); \
                 raise max_dem_steps or lower the MPM time step",
                plan.duration
            )));
        }
        Ok(RveOrder {
            velocity_gradient: if max_strain > 0.0 { e / plan.duration } else { Matrix3::zeros() },
            full_steps: plan.full_steps,
            last_step: plan.last_step,
        })
    }

    /// Carries out an order on this thread (the CPU backend).
    fn run_on_cpu(&self, index: usize, rve: &mut Rve, order: &RveOrder) -> Result<RveReport> {
        let mut report =
            rve.deform(order).map_err(|e| GraniteError::Other(format!("RVE of material point {index}: {e}")))?;
        if !report.events.is_empty() {
            self.tell_once(index, std::mem::take(&mut report.events).swap_remove(0));
        }
        Ok(report)
    }

    /// Passes an RVE event on once for all RVEs (the lowest point's of a step).
    fn tell_once(&self, index: usize, event: String) {
        if !self.event_said.load(std::sync::atomic::Ordering::Relaxed) {
            let mut said = self.event.lock().unwrap_or_else(|e| e.into_inner());
            if said.as_ref().is_none_or(|(point, _)| index < *point) {
                *said = Some((index, event));
            }
        }
    }

    /// A point's stress and state variables from its RVE's report.
    fn record(&self, report: &RveReport, spheres: usize, stress: &mut Voigt, st: &mut [f64]) {
        let no_contacts = report.contacts == 0;
        *stress = if no_contacts { [0.0; 6] } else { report.stress };
        let (mean, q) = granite_core::math::p_q(stress);
        st[0] = mean;
        st[1] = q;
        st[2] = (report.cell.determinant().abs() - self.solid_volume) / self.solid_volume;
        st[3] = report.coordination_no_rattlers(spheres);
        st[4] = report.rattlers as f64;
        st[5] = report.steps as f64;
        st[6] = if no_contacts { 1.0 } else { 0.0 };
        // Work done by this point's RVE so far (throughput figures of benchmarks and runs).
        st[7] += (report.steps as usize * spheres) as f64;
    }

    /// One point's RVE stepped on this thread by the strain `de` (the CPU backend).
    fn step_own(&self, index: usize, de: &Voigt, point: &mut PointRve) -> Result<RveReport> {
        let before = match point.stress {
            Some(stress) => stress,
            None => point.rve.stress(),
        };
        let order = self.order(index, de, &before, &point.rve.cell(), point.rve.dt())?;
        point.stress = None;
        let report = self.run_on_cpu(index, &mut point.rve, &order)?;
        point.stress = Some(report.stress);
        Ok(report)
    }

    /// Material points known (their RVEs here or not).
    fn points(&self) -> usize {
        match &self.device {
            Some(device) => device.points(),
            None => self.rves.read().map(|r| r.len()).unwrap_or(0),
        }
    }

    /// Makes the RVE of point `to` a copy of point `from`'s.
    fn copy_rve(&self, from: usize, to: usize) -> Result<()> {
        match &self.device {
            Some(device) => device.copy(from, to),
            None => {
                copy_within(&self.rves.read().map_err(|_| GraniteError::Other("RVE store poisoned".into()))?, from, to)
            }
        }
    }

    /// The update of all the material's points in one call, of which this process steps those
    /// `here` names: the activation decides which points step (all, without `adaptive`), exact
    /// sharing which RVEs, then they step on the device in one submission or on the CPU
    /// threads. Followers are left to `complete_update`. Returns each point's cost in seconds.
    fn update_batch(&self, here: &[bool], batch: LawBatch<'_>) -> Result<Vec<f64>> {
        let n = self.points();
        if batch.first != 0 || batch.len() != n || here.len() != n {
            return Err(GraniteError::Other(format!(
                "dem_rve updates all {n} points of the material at once, not points {}..{}",
                batch.first,
                batch.first + batch.len()
            )));
        }
        let stride = STATE.len();
        let roles: Vec<Role> = match &self.activation {
            Some(a) => {
                a.lock().unwrap_or_else(|e| e.into_inner()).plan(batch.dstrain, batch.stress, batch.state, stride)
            }
            None => batch.dstrain.iter().map(|de| Role::Steps(*de)).collect(),
        };
        let strain: Vec<Option<Voigt>> = roles
            .iter()
            .zip(here)
            .map(|(role, &here)| match role {
                Role::Steps(de) if here => Some(*de),
                _ => None,
            })
            .collect();
        let shared = self.twins.lock().unwrap_or_else(|e| e.into_inner()).split(&strain);
        for &(from, to) in &shared.copies {
            self.copy_rve(from, to)?;
        }
        let mut stepping = vec![false; n];
        for &p in &shared.steppers {
            stepping[p] = true;
        }
        let started = Instant::now();
        let reports: Vec<(usize, RveReport, f64)> = match &self.device {
            Some(device) => self.step_on_device(device, &stepping, &strain)?,
            None => self.step_on_cpu(&shared.steppers, &strain)?,
        };
        let grains = self.template.grain_count();
        let mut costs = vec![0.0; n];
        let mut report_of = vec![None; n];
        for (point, report, seconds) in &reports {
            self.record(report, grains, &mut batch.stress[*point], &mut batch.state[point * stride..][..stride]);
            costs[*point] = *seconds;
            report_of[*point] = Some(report);
        }
        let mut spared = 0.0;
        for &(point, keeper) in &shared.riders {
            let report = report_of[keeper].ok_or_else(|| {
                GraniteError::Other(format!("RVE of material point {point}: its keeper {keeper} did not step"))
            })?;
            self.record(report, grains, &mut batch.stress[point], &mut batch.state[point * stride..][..stride]);
            spared += (report.steps as usize * grains) as f64;
        }
        *self.shared_sphere_steps.lock().unwrap_or_else(|e| e.into_inner()) += spared;
        if self.device.is_some() {
            // The device's call is one: its time is shared out by the RVEs' DEM steps.
            let seconds = started.elapsed().as_secs_f64();
            let work: u64 = reports.iter().map(|(_, r, _)| r.steps).sum();
            for (point, report, _) in &reports {
                costs[*point] = if work > 0 { seconds * report.steps as f64 / work as f64 } else { 0.0 };
            }
        }
        Ok(costs)
    }

    /// The RVEs of the points `stepping` names, each by its `strain`, on this process's threads.
    fn step_on_cpu(&self, steppers: &[usize], strain: &[Option<Voigt>]) -> Result<Vec<(usize, RveReport, f64)>> {
        let rves = self.rves.read().map_err(|_| GraniteError::Other("RVE store poisoned".into()))?;
        let outcomes: Vec<Result<(usize, RveReport, f64)>> = steppers
            .par_iter()
            .with_min_len(1)
            .map(|&index| {
                let t = Instant::now();
                let de = strain[index].ok_or_else(|| GraniteError::Other(format!("no strain for point {index}")))?;
                let mut rve = rves
                    .get(index)
                    .ok_or_else(|| GraniteError::Other(format!("no RVE for material point {index}")))?
                    .lock()
                    .map_err(|_| GraniteError::Other(format!("RVE {index} poisoned")))?;
                let Some(rve) = &mut *rve else {
                    return Err(GraniteError::Other(format!(
                        "the RVE of material point {index} is in another process"
                    )));
                };
                let report = self.step_own(index, &de, rve)?;
                Ok((index, report, t.elapsed().as_secs_f64()))
            })
            .collect();
        // The lowest failing point's error, whatever thread ran what.
        outcomes.into_iter().collect()
    }

    /// The RVEs of the points `stepping` names stepped on the device in one submission.
    fn step_on_device(
        &self,
        device: &DeviceRves,
        stepping: &[bool],
        strain: &[Option<Voigt>],
    ) -> Result<Vec<(usize, RveReport, f64)>> {
        if !self.time_step_checked.swap(true, std::sync::atomic::Ordering::Relaxed) {
            // The prepared sample is checked here once before the device's first steps (its
            // warning, or the stop of a time step its contacts cannot follow); the device then
            // checks each RVE as the CPU engine does and proves a stop on the host.
            let first = stepping.iter().position(|&h| h).unwrap_or(0);
            let events = self
                .template
                .check_time_step()
                .map_err(|e| GraniteError::Other(format!("RVE of material point {first}: {e}")))?;
            for event in events {
                self.tell_once(first, event);
            }
        }
        let dt = self.template.dt();
        let reports = device
            .step(|p| stepping[p], |p, stress, cell| self.order(p, &strain[p].unwrap_or([0.0; 6]), stress, cell, dt))?;
        for (point, report) in &reports {
            if let Some(event) = report.events.first() {
                self.tell_once(*point, event.clone());
            }
            if let Some(failure) = &report.failure {
                return Err(GraniteError::Other(format!(
                    "RVE of material point {point}: stopped at its DEM step {} of this increment on the device: {failure}",
                    report.steps
                )));
            }
        }
        Ok(reports.into_iter().map(|(p, r)| (p, r, 0.0)).collect())
    }
}

/// Read access to the RVEs (for output of chosen points and tests).
impl DemRve {
    pub fn with_rve<R>(&self, index: usize, f: impl FnOnce(&Rve) -> R) -> Option<R> {
        if index >= self.points() {
            return None;
        }
        let index = self.twins.lock().unwrap_or_else(|e| e.into_inner()).object_of(index);
        if let Some(device) = &self.device {
            return device.get(index).ok().map(|rve| f(&rve));
        }
        let rves = self.rves.read().ok()?;
        let guard = rves.get(index)?.lock().ok()?;
        guard.as_ref().map(|point| f(&point.rve))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_adaptive_controller_reads_the_state_variables_it_names() {
        let at = |k: usize| STATE[k];
        assert_eq!(at(state::MEAN_STRESS), "rve_mean_stress");
        assert_eq!(at(state::DEVIATORIC_STRESS), "rve_deviatoric_stress");
        assert_eq!(at(state::VOID_RATIO), "void_ratio");
        assert_eq!(at(state::COORDINATION), "coordination");
        assert_eq!(at(state::RATTLERS), "rattlers");
        assert_eq!(at(state::DEM_STEPS), "dem_steps");
        assert_eq!(at(state::NO_CONTACTS), "no_contacts");
        assert_eq!(at(state::DEM_SPHERE_STEPS), "dem_sphere_steps");
    }
}
