//! The MPM×DEM seam of the DEM: a periodic sample deformed as one piece. An [`Rve`] is made once
//! from a prepared periodic `DemSim`, and then only deformed by an order (a velocity gradient over
//! so many DEM steps, thesis eqs. 4.1-4.5) and read back as a response (Love-Weber stress, eq. 4.7,
//! cell, contact counts, steps taken): what the `dem_rve` law and an RVE device see of the DEM.

use crate::dem::DemSim;
use crate::error::{GraniteError, Result};
use crate::ext::contact::ContactLawSource;
use crate::ext::rve::{RveOrder, RveReport};
use crate::io::vtk::Field;
use crate::math::{Vec3, Voigt};
use nalgebra::Matrix3;

/// A periodic DEM sample stepped only through [`Rve::deform`].
#[derive(Clone)]
pub struct Rve {
    sim: DemSim,
}

impl Rve {
    /// The sample of `sim` as an RVE: periodic, with spheres, a contact law and a time step; no
    /// stress servo or gravity of its own (the MPM strain drives the cell, eq. 4.6), stepped on
    /// the calling thread (the points' RVEs are the parallel work). `owner` names who asks, in
    /// errors.
    pub fn prepare(mut sim: DemSim, owner: &str) -> Result<Rve> {
        if sim.world.cell.is_none() {
            return Err(GraniteError::Setup(format!("{owner}: the `rve` must have a periodic cell")));
        }
        let grains = sim.world.spheres.len() + sim.world.kinds.len();
        if grains == 0 || sim.world.dt <= 0.0 || sim.world.contacts.laws.is_empty() {
            return Err(GraniteError::Setup(format!(
                "{owner}: the `rve` needs grains (spheres or bodies), a contact law and a time step"
            )));
        }
        sim.set_sequential(true);
        sim.world.cell_control = None;
        sim.world.gravity = [0.0; 3];
        Ok(Rve { sim })
    }

    /// An RVE saved by [`Rve::to_json`], its contact laws built from `registry`.
    pub fn from_json(value: serde_json::Value, registry: &dyn ContactLawSource) -> Result<Rve> {
        let mut sim = DemSim::from_json(value, registry)?;
        sim.set_sequential(true);
        Ok(Rve { sim })
    }

    /// An RVE saved by [`Rve::to_json`] with the contact laws of `like`.
    pub fn from_json_like(value: serde_json::Value, like: &Rve) -> Result<Rve> {
        let mut sim = DemSim::from_json_like(value, &like.sim)?;
        sim.set_sequential(true);
        Ok(Rve { sim })
    }

    pub fn to_json(&self) -> Result<serde_json::Value> {
        self.sim.to_json()
    }

    /// Carries out `order` on this thread: full steps of the sample's time step under the order's
    /// velocity gradient, then the shorter last step if any (eq. 4.4); the cell is left at rest.
    /// What the steps said (a time step above the contacts' bound) comes back in the response.
    pub fn deform(&mut self, order: &RveOrder) -> Result<RveReport> {
        self.deform_with(order, false)
    }

    /// [`Rve::deform`] with the candidate lists rebuilt before every step, needed or not: the
    /// CPU's side of a benchmark of the search (a device told to do the same), with the results
    /// of [`Rve::deform`] to rounding.
    pub fn deform_rebuilding_every_step(&mut self, order: &RveOrder) -> Result<RveReport> {
        self.deform_with(order, true)
    }

    fn deform_with(&mut self, order: &RveOrder, rebuild_every_step: bool) -> Result<RveReport> {
        let sim = &mut self.sim;
        if let Some(cell) = sim.world.cell.as_mut() {
            cell.velocity_gradient = order.velocity_gradient;
        }
        let step = |sim: &mut DemSim| {
            if rebuild_every_step {
                sim.rebuild_candidates()?;
            }
            sim.step()
        };
        for _ in 0..order.full_steps {
            step(sim)?;
        }
        if order.last_step > 0.0 {
            let dt = sim.world.dt;
            sim.world.dt = order.last_step;
            let stepped = step(sim);
            sim.world.dt = dt;
            stepped?;
        }
        if let Some(cell) = sim.world.cell.as_mut() {
            cell.velocity_gradient = Matrix3::zeros();
        }
        let mut report = self.response();
        report.steps = order.full_steps + u64::from(order.last_step > 0.0);
        report.events = std::mem::take(&mut self.sim.world.events);
        Ok(report)
    }

    /// The sample as it is, as a response of no steps.
    pub fn response(&self) -> RveReport {
        let sim = &self.sim;
        let d = sim.world.coordination();
        let counts = sim.world.grain_contact_counts();
        RveReport {
            stress: self.stress(),
            cell: self.cell(),
            contacts: d.contacts,
            contact_ends: counts.iter().map(|&c| c as usize).sum(),
            rattlers: d.rattlers,
            floaters: d.floaters,
            steps: 0,
            failure: None,
            events: Vec::new(),
        }
    }

    /// Love-Weber stress of its contacts over the cell's volume (eq. 4.7, tension positive).
    pub fn stress(&self) -> Voigt {
        let volume = self.sim.world.cell_volume().unwrap_or(1.0);
        self.sim.world.stress_and_axis_stiffness(volume, self.sim.in_parallel()).0
    }

    /// The periodic cell's base vectors (columns).
    pub fn cell(&self) -> Matrix3<f64> {
        self.sim.world.cell.as_ref().map(|c| c.h).unwrap_or_else(Matrix3::identity)
    }

    pub fn sphere_count(&self) -> usize {
        self.sim.world.spheres.len()
    }

    /// Its grains: spheres and bodies of plugin kinds (the work of a step is per grain).
    pub fn grain_count(&self) -> usize {
        self.sim.world.spheres.len() + self.sim.world.kinds.len()
    }

    /// The DEM time step.
    pub fn dt(&self) -> f64 {
        self.sim.world.dt
    }

    /// Mass of its grains (kg).
    pub fn mass(&self) -> f64 {
        let w = &self.sim.world;
        w.spheres.mass.iter().sum::<f64>() + w.kinds.mass.iter().sum::<f64>()
    }

    /// Volume of its grains (m^3).
    pub fn solid_volume(&self) -> f64 {
        self.sim.world.solid_volume()
    }

    /// Mean grain diameter (m): of a body of a plugin kind, that of the sphere of its volume.
    pub fn mean_diameter(&self) -> f64 {
        let (s, k) = (&self.sim.world.spheres, &self.sim.world.kinds);
        let radii = s.radius.iter().sum::<f64>() + (0..k.len()).map(|i| k.equivalent_radius(i)).sum::<f64>();
        2.0 * radii / (s.len() + k.len()) as f64
    }

    /// Bytes this RVE holds.
    pub fn memory_bytes(&self) -> usize {
        self.sim.memory_bytes()
    }

    /// Checks the time step against the sample's contacts as its first step would: the warning
    /// it gives, or the error of a time step its contacts cannot follow.
    pub fn check_time_step(&self) -> Result<Vec<String>> {
        let mut sample = self.sim.clone();
        sample.world.check_time_step(sample.stop_on_unstable_dt)?;
        Ok(sample.world.events)
    }

    /// Its spheres for a VTK frame: radius, velocity, contacts, and the mean stress each carries
    /// (its share of the Love-Weber sum, as the thesis's figure 4.6).
    pub fn frame(&self) -> (Vec<Vec3>, Vec<Field>) {
        let sim = &self.sim;
        let s = &sim.world.spheres;
        let counts = sim.world.contact_counts();
        let mut particle_p = vec![0.0; s.len()];
        let p = &sim.world.contacts.spheres;
        for c in 0..p.len() {
            if !p.touching[c] {
                continue;
            }
            let (i, j) = (p.a[c] as usize, p.b[c] as usize);
            let image = sim.world.cell.as_ref().map(|cell| cell.shift_vector(p.shift[c])).unwrap_or([0.0; 3]);
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
    }

    /// The DEM simulation inside, to read (a device laying it out, tests, outputs).
    pub fn dem(&self) -> &DemSim {
        &self.sim
    }

    /// The DEM simulation inside, for a device that keeps its own copy of the samples.
    pub fn into_dem(self) -> DemSim {
        self.sim
    }

    /// The sample as it is, not prepared again: a device handing back its copy of an RVE, tests
    /// stepping a sample they built.
    pub fn as_is(sim: DemSim) -> Rve {
        Rve { sim }
    }
}
