//! `dem_rve`: the MPMxDEM law (thesis chapter 4). Every material point owns a periodic DEM sample
//! (a Representative Volume Element), a copy of a prepared one. Each call deforms the RVE by the
//! point's strain increment as a velocity gradient applied over `T_DEM` (eqs. 4.1-4.6), on top of
//! the contact forces, and returns its Love-Weber stress (4.7), tension positive like the MPM.

use granite_core::dem::DemSim;
use granite_core::ext::constitutive::ObjectMap;
use granite_core::ext::{ConstitutiveLaw, ConstitutiveLawFactory, LawBatch};
use granite_core::math::Voigt;
use granite_core::params::{ParamSpec, Params};
use granite_core::{GraniteError, Result};
use nalgebra::{Matrix3, SymmetricEigen};
use std::sync::{Mutex, RwLock};

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
];

/// What one point's RVE carries between calls.
struct Rve {
    sim: DemSim,
    /// Love-Weber stress of `sim` as the last call left it: the next call's P (eq. 4.3) without
    /// a second pass over the contacts. None until computed (a new or reloaded RVE).
    stress: Option<Voigt>,
}

pub struct DemRve {
    params: Params,
    template: DemSim,
    /// One slot per material point; empty for points whose RVE lives in another process.
    rves: RwLock<Vec<Mutex<Option<Rve>>>>,
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
}

impl ConstitutiveLawFactory for DemRveFactory {
    fn name(&self) -> &str {
        "dem_rve"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        SPECS
    }
    fn description(&self) -> &str {
        "MPMxDEM: a periodic DEM sample per material point (needs `rve`, a prepared periodic dem())"
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
        let template = DemSim::from_json(map.remove("template").ok_or_else(bad)?, registry)?;
        let params = Params::resolve("law \"dem_rve\"", SPECS, given)?;
        let mut objects = ObjectMap::new();
        objects.insert("rve".into(), std::sync::Arc::new(template));
        let law = DemRve::new(params, &objects)?;
        let serde_json::Value::Array(rves) = map.remove("rves").ok_or_else(bad)? else { return Err(bad()) };
        {
            let mut store = law.rves.write().map_err(|_| GraniteError::Other("RVE store poisoned".into()))?;
            for v in rves {
                let mut sim = DemSim::from_json(v, registry)?;
                sim.set_sequential(true);
                store.push(Mutex::new(Some(Rve { sim, stress: None })));
            }
        }
        Ok(Box::new(law))
    }
}

impl DemRve {
    /// The law for resolved parameters and the prepared sample in `objects["rve"]`.
    pub fn new(params: Params, objects: &ObjectMap) -> Result<DemRve> {
        let template = objects
            .get("rve")
            .and_then(|o| o.downcast_ref::<DemSim>())
            .ok_or_else(|| GraniteError::MissingParameter {
                name: "rve".into(),
                context: params.owner().into(),
                expected: "a prepared periodic DEM sample: a dem() simulation with periodic(...)".into(),
            })?
            .clone();
        if template.cell.is_none() {
            return Err(GraniteError::Setup(format!("{}: the `rve` must have a periodic cell", params.owner())));
        }
        if template.spheres.is_empty() || template.dt <= 0.0 || template.laws.is_empty() {
            return Err(GraniteError::Setup(format!(
                "{}: the `rve` needs spheres, a contact law and a time step",
                params.owner()
            )));
        }
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
        let s = &template.spheres;
        let mass: f64 = s.mass.iter().sum();
        let volume = template.solid_volume();
        let mean_diameter = 2.0 * s.radius.iter().sum::<f64>() / s.len() as f64;
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
        let mut template = template;
        template.set_sequential(true);
        template.cell_control = None;
        template.gravity = [0.0; 3];
        Ok(DemRve {
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
        })
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
    pub fn p_min(&self, sim: &DemSim) -> f64 {
        let Some(cell) = &sim.cell else { return 0.0 };
        let (i, j) = match self.vertical_axis {
            0 => (1, 2),
            1 => (2, 0),
            _ => (0, 1),
        };
        let area = cell.h.column(i).cross(&cell.h.column(j)).norm();
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
    fn points_added(&self, here: &[bool]) -> Result<()> {
        let mut rves = self.rves.write().map_err(|_| GraniteError::Other("RVE store poisoned".into()))?;
        for &here in here {
            rves.push(Mutex::new(here.then(|| Rve { sim: self.template.clone(), stress: None })));
        }
        Ok(())
    }
    fn spreadable(&self) -> bool {
        true
    }
    fn release_objects(&self, keep: &[bool]) {
        if let Ok(rves) = self.rves.read() {
            for (slot, &keep) in rves.iter().zip(keep) {
                if !keep {
                    *slot.lock().unwrap_or_else(|e| e.into_inner()) = None;
                }
            }
        }
    }
    fn point_object(&self, point: usize) -> Result<serde_json::Value> {
        self.with_rve(point, |sim| sim.to_json())
            .unwrap_or_else(|| Err(GraniteError::Other(format!("no RVE of material point {point} in this process"))))
    }
    fn adopt_point_object(&self, point: usize, object: serde_json::Value) -> Result<()> {
        let mut sim = DemSim::from_json_like(object, &self.template)?;
        sim.set_sequential(true);
        let rves = self.rves.read().map_err(|_| GraniteError::Other("RVE store poisoned".into()))?;
        let slot = rves.get(point).ok_or_else(|| GraniteError::Other(format!("no material point {point}")))?;
        *slot.lock().unwrap_or_else(|e| e.into_inner()) = Some(Rve { sim, stress: None });
        Ok(())
    }
    fn save_objects_from(&self, points: Vec<serde_json::Value>) -> Result<Option<serde_json::Value>> {
        Ok(Some(serde_json::json!({ "template": self.template.to_json()?, "rves": points })))
    }
    fn pending_event(&self) -> Option<(usize, String)> {
        self.event.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }
    fn set_pending_event(&self, event: Option<(usize, String)>) {
        *self.event.lock().unwrap_or_else(|e| e.into_inner()) = event;
    }
    fn points_removed(&self, keep: &[bool]) {
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
        use granite_core::io::vtk::Field;
        self.with_rve(point, |sim| {
            let s = &sim.spheres;
            let counts = sim.contact_counts();
            // Mean stress carried by each particle (its share of the Love-Weber sum), as figure 4.6.
            let mut particle_p = vec![0.0; s.len()];
            let p = &sim.pairs;
            for c in 0..p.len() {
                if !p.touching[c] {
                    continue;
                }
                let (i, j) = (p.a[c] as usize, p.b[c] as usize);
                let image = sim.cell.as_ref().map(|cell| cell.shift_vector(p.shift[c])).unwrap_or([0.0; 3]);
                let l: Vec<f64> = (0..3).map(|a| s.x[j][a] + image[a] - s.x[i][a]).collect();
                let work = p.force[c][0] * l[0] + p.force[c][1] * l[1] + p.force[c][2] * l[2];
                for k in [i, j] {
                    let v = 4.0 / 3.0 * std::f64::consts::PI * s.radius[k].powi(3);
                    particle_p[k] += 0.5 * work / (3.0 * v);
                }
            }
            let fields = vec![
                Field::float("radius", 1, s.radius.clone()),
                Field::float("velocity", 3, s.v.iter().flatten().copied().collect()),
                Field::int("contacts", counts.iter().map(|&c| c as i64)),
                Field::float("mean_stress", 1, particle_p),
            ];
            (s.x.clone(), fields)
        })
    }
    fn save_objects(&self) -> Result<Option<serde_json::Value>> {
        let count = self.rves.read().map_err(|_| GraniteError::Other("RVE store poisoned".into()))?.len();
        let list = (0..count).map(|k| self.point_object(k)).collect::<Result<Vec<_>>>()?;
        self.save_objects_from(list)
    }
    fn update(&self, batch: LawBatch<'_>) -> Result<()> {
        let rves = self.rves.read().map_err(|_| GraniteError::Other("RVE store poisoned".into()))?;
        let stride = STATE.len();
        for k in 0..batch.len() {
            let index = batch.first + k;
            let mut rve = rves
                .get(index)
                .ok_or_else(|| GraniteError::Other(format!("no RVE for material point {index}")))?
                .lock()
                .map_err(|_| GraniteError::Other(format!("RVE {index} poisoned")))?;
            let Some(Rve { sim, stress: last_stress }) = &mut *rve else {
                return Err(GraniteError::Other(format!("the RVE of material point {index} is in another process")));
            };
            let de = batch.dstrain[k];
            let e = granite_core::math::strain_matrix(&de);
            let max_strain = SymmetricEigen::new(e).eigenvalues.amax();
            let before = match *last_stress {
                Some(stress) => stress,
                None => sim.love_weber_stress(sim.cell_volume().unwrap_or(1.0)),
            };
            let p = ((before[0] + before[1] + before[2]).abs() / 3.0).max(self.p_min(sim));
            let dt = sim.dt;
            let plan = self.plan(max_strain, p, dt);
            let steps = plan.full_steps + u64::from(plan.last_step > 0.0);
            if steps > self.max_steps {
                return Err(GraniteError::Other(format!(
                    "RVE of point {index} would need {steps} DEM steps for this increment (T = {:.3e} s, P = {p:.3e} Pa); \
                     raise max_dem_steps or lower the MPM time step",
                    plan.duration
                )));
            }
            if let Some(cell) = sim.cell.as_mut() {
                cell.velocity_gradient = if max_strain > 0.0 { e / plan.duration } else { Matrix3::zeros() };
            }
            *last_stress = None;
            let of_point = |e: GraniteError| GraniteError::Other(format!("RVE of material point {index}: {e}"));
            for _ in 0..plan.full_steps {
                sim.step().map_err(of_point)?;
            }
            if plan.last_step > 0.0 {
                sim.dt = plan.last_step;
                let r = sim.step();
                sim.dt = dt;
                r.map_err(of_point)?;
            }
            if let Some(cell) = sim.cell.as_mut() {
                cell.velocity_gradient = Matrix3::zeros();
            }
            if !sim.events.is_empty() {
                let first = std::mem::take(&mut sim.events).swap_remove(0);
                if !self.event_said.load(std::sync::atomic::Ordering::Relaxed) {
                    let mut event = self.event.lock().unwrap_or_else(|e| e.into_inner());
                    if event.as_ref().is_none_or(|(point, _)| index < *point) {
                        *event = Some((index, first));
                    }
                }
            }
            let volume = sim.cell_volume().unwrap_or(1.0);
            let stress: Voigt = sim.love_weber_stress(volume);
            *last_stress = Some(stress);
            let d = sim.coordination();
            let no_contacts = d.contacts == 0;
            batch.stress[k] = if no_contacts { [0.0; 6] } else { stress };
            let (mean, q) = granite_core::math::p_q(&batch.stress[k]);
            let st = &mut batch.state[k * stride..(k + 1) * stride];
            st[0] = mean;
            st[1] = q;
            st[2] = sim.void_ratio().unwrap_or(f64::NAN);
            st[3] = d.coordination_no_rattlers;
            st[4] = d.rattlers as f64;
            st[5] = steps as f64;
            st[6] = if no_contacts { 1.0 } else { 0.0 };
            // Work done by this point's RVE so far (throughput figures of benchmarks and runs).
            st[7] += (steps as usize * sim.spheres.len()) as f64;
        }
        Ok(())
    }
}

/// Read access to the RVEs (for output of chosen points and tests).
impl DemRve {
    pub fn with_rve<R>(&self, index: usize, f: impl FnOnce(&DemSim) -> R) -> Option<R> {
        let rves = self.rves.read().ok()?;
        let guard = rves.get(index)?.lock().ok()?;
        guard.as_ref().map(|rve| f(&rve.sim))
    }
}
