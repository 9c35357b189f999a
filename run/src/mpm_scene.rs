//! An MPM simulation as a run driver steps it ([`Simulation`] for [`MpmSim`]): the columns of
//! `series.csv`, the fields of a VTK frame, the points table, the runout of a collapsing column.

use crate::simulation::{RunContext, RunEnd, Simulation};
use granite_core::error::Result;
use granite_core::io::vtk::Field;
use granite_core::math::{deviatoric_strain_norm, p_q, Vec3};
use granite_core::mpm::boundary::TimeFunction;
use granite_core::mpm::sim::Snapshot;
use granite_core::mpm::{MpmSim, ShapeFunctions};
use std::path::Path;

/// Reference geometry of a collapsing column, for the runout columns (thesis 5.6-5.9).
#[derive(Debug, Clone, Copy)]
pub struct Runout {
    pub width0: f64,
    pub height0: f64,
    /// Time the collapse started (t~ counts from here).
    pub t0: f64,
}

impl Runout {
    /// `(L_x, d_r, L~, t~)` of eqs. 5.6-5.9, and the body front's `L~` (the x holding 99 % of
    /// the mass in place of L_x).
    pub fn measure(&self, sim: &MpmSim) -> (f64, f64, f64, f64, f64) {
        let lx = sim.voxel_width();
        let dr = lx - self.width0;
        let g = granite_core::math::norm3(sim.gravity).max(f64::MIN_POSITIVE);
        let front = (sim.mass_front(0.99) - self.width0) / self.width0;
        (lx, dr, dr / self.width0, (sim.time - self.t0) / (self.height0 / g).sqrt(), front)
    }
}

/// An MPM simulation as a run driver steps it: the engine, the runout it measures (if any) and the
/// boundary values the driver sets.
pub struct MpmScene {
    pub mpm: MpmSim,
    pub runout: Option<Runout>,
    /// Boundary values a driver function sets, by target index ([`Simulation::set_driven`]).
    pub driven: Vec<Driven>,
}

impl MpmScene {
    pub fn new(mpm: MpmSim) -> MpmScene {
        MpmScene { mpm, runout: None, driven: Vec::new() }
    }
}

/// A boundary value set from outside the engine once per step.
#[derive(Clone, Copy)]
pub enum Driven {
    /// The value of the prescribed velocity `boundary.velocity[i]`.
    Velocity(usize),
    /// The factor of the nodal force `boundary.forces[i]`.
    Force(usize),
    /// The factor of the load carried by points `boundary.point_loads[i]`.
    PointLoad(usize),
}

impl MpmScene {
    /// The laws' state variables by name, a value per point (zero for points whose law lacks
    /// that variable): points lie material after material.
    fn state_columns(&self) -> Vec<(&'static str, Vec<f64>)> {
        let sim = &self.mpm;
        let n = sim.points.len();
        let mut columns: Vec<(&'static str, Vec<f64>)> = Vec::new();
        let mut start = 0;
        for m in &sim.materials {
            let names = m.law.state_names();
            for (k, name) in names.iter().enumerate() {
                let idx = match columns.iter().position(|(c, _)| c == name) {
                    Some(i) => i,
                    None => {
                        columns.push((name, vec![0.0; n]));
                        columns.len() - 1
                    }
                };
                for j in 0..m.count {
                    columns[idx].1[start + j] = m.state[j * names.len() + k];
                }
            }
            start += m.count;
        }
        columns
    }
}

impl Simulation for MpmScene {
    type Snapshot = Snapshot;

    fn validate(&self) -> Result<()> {
        self.mpm.validate()
    }
    fn advance(&mut self) -> Result<()> {
        self.mpm.step()
    }
    fn time(&self) -> f64 {
        self.mpm.time
    }
    fn steps(&self) -> u64 {
        self.mpm.step
    }
    fn dt(&self) -> f64 {
        self.mpm.dt
    }
    fn series_row(&self) -> (Vec<&'static str>, Vec<f64>) {
        let sim = &self.mpm;
        let d = sim.diagnostics();
        let mut cols = vec![
            "step",
            "time",
            "kinetic_energy",
            "elastic_energy",
            "gravitational_energy",
            "total_energy",
            "max_height",
            "max_x",
            "max_deviatoric_strain",
            "points",
            "deleted_points",
            "angular_momentum_x",
            "angular_momentum_y",
            "angular_momentum_z",
        ];
        let mut vals = vec![
            sim.step as f64,
            sim.time,
            d.kinetic_energy,
            d.elastic_energy,
            d.gravitational_energy,
            d.total_energy(),
            d.max_height,
            d.max_x,
            d.max_deviatoric_strain,
            d.points as f64,
            sim.deleted_points as f64,
            d.angular_momentum[0],
            d.angular_momentum[1],
            d.angular_momentum[2],
        ];
        for (name, value) in sim.law_series() {
            cols.push(name);
            vals.push(value);
        }
        if let Some(r) = &self.runout {
            let (lx, dr, l_norm, t_norm, front) = r.measure(sim);
            cols.extend(["lx", "runout", "runout_normalised", "time_normalised", "front_runout_normalised"]);
            vals.extend([lx, dr, l_norm, t_norm, front]);
        }
        (cols, vals)
    }
    fn series_tag(&self) -> &'static str {
        "runout"
    }
    fn vtk_frame(&self) -> (Vec<Vec3>, Vec<Field>) {
        let sim = &self.mpm;
        let p = &sim.points;
        let field = Field::float;
        let mut fields = vec![
            Field::int("id", p.id.iter().map(|&i| i as i64)),
            Field::int("material", p.material.iter().map(|&m| m as i64)),
            field("velocity", 3, p.v.iter().flatten().copied().collect()),
            field("stress", 6, p.stress.iter().flatten().copied().collect()),
            field("strain", 6, p.strain.iter().flatten().copied().collect()),
            field("mean_stress", 1, p.stress.iter().map(|s| p_q(s).0).collect()),
            field("deviatoric_stress", 1, p.stress.iter().map(|s| p_q(s).1).collect()),
            field("deviatoric_strain", 1, p.strain.iter().map(deviatoric_strain_norm).collect()),
            field("volume", 1, p.volume.clone()),
        ];
        fields.extend(self.state_columns().into_iter().map(|(name, values)| field(name, 1, values)));
        (p.x.clone(), fields)
    }
    fn write_points(&self, path: &Path) -> Result<()> {
        const HEADER: &str = "id,material,x,y,z,vx,vy,vz,sxx,syy,szz,sxy,syz,sxz,exx,eyy,ezz,gxy,gyz,gxz,p,q,\
                              deviatoric_strain,volume,mass";
        let p = &self.mpm.points;
        // The laws' state variables after the fixed columns (an RVE's void ratio, coordination...).
        let states = self.state_columns();
        let header: String = std::iter::once(HEADER.to_string())
            .chain(states.iter().map(|(name, _)| name.to_string()))
            .collect::<Vec<_>>()
            .join(",");
        let rows = (0..p.len()).map(|i| {
            let (mean, q) = p_q(&p.stress[i]);
            let mut row = vec![p.id[i] as f64, p.material[i] as f64];
            row.extend(p.x[i]);
            row.extend(p.v[i]);
            row.extend(p.stress[i]);
            row.extend(p.strain[i]);
            row.extend([mean, q, deviatoric_strain_norm(&p.strain[i]), p.volume[i], p.mass[i]]);
            row.extend(states.iter().map(|(_, values)| values[i]));
            row
        });
        crate::output::write_table(path, &header, rows)
    }

    fn diagnostics(&self) -> Vec<(&'static str, f64)> {
        let sim = &self.mpm;
        let d = sim.diagnostics();
        let mut out = vec![
            ("time", sim.time),
            ("step", sim.step as f64),
            ("points", d.points as f64),
            ("mass", d.mass),
            ("momentum_x", d.momentum[0]),
            ("momentum_y", d.momentum[1]),
            ("momentum_z", d.momentum[2]),
            ("angular_momentum_x", d.angular_momentum[0]),
            ("angular_momentum_y", d.angular_momentum[1]),
            ("angular_momentum_z", d.angular_momentum[2]),
            ("kinetic_energy", d.kinetic_energy),
            ("elastic_energy", d.elastic_energy),
            ("gravitational_energy", d.gravitational_energy),
            ("total_energy", d.total_energy()),
            ("max_height", d.max_height),
            ("max_x", d.max_x),
            ("max_deviatoric_strain", d.max_deviatoric_strain),
            ("deleted_points", sim.deleted_points as f64),
        ];
        if let Some(r) = &self.runout {
            let (lx, dr, ln, tn, front) = r.measure(sim);
            out.extend([
                ("lx", lx),
                ("runout", dr),
                ("runout_normalised", ln),
                ("time_normalised", tn),
                ("front_runout_normalised", front),
            ]);
        }
        out
    }
    fn snapshot(&self) -> Snapshot {
        self.mpm.snapshot()
    }
    fn restore(&mut self, snapshot: Snapshot) {
        self.mpm.restore(snapshot)
    }
    fn save_state(&self, path: &std::path::Path, run: &RunContext) -> Result<()> {
        // Collective: every process calls it, the first writes.
        self.mpm.save_as(path, &run.program)
    }
    fn drain_events(&mut self) -> Vec<String> {
        self.mpm.events.drain(..).collect()
    }
    fn setup_warnings(&mut self) -> Vec<String> {
        // Said only when it matters: a script usually sets the new mesh's boundaries right after.
        let bare = std::mem::take(&mut self.mpm.mesh_replaced) && self.mpm.boundary.is_empty();
        let mut warnings = Vec::new();
        if bare {
            warnings.push(
                "the mesh was replaced, which cleared its boundary conditions, and none was set since: the \
                 points run with no boundary"
                    .into(),
            );
        }
        if self.mpm.velocity_update.affine() && self.mpm.shape == ShapeFunctions::Linear && self.mpm.step == 0 {
            warnings.push(format!(
                "{} (an affine transfer) with linear shape functions can gain energy as points cross cells, \
                 whatever the time step (APIC on an elastic bar of 50 cells blows up at 0.1 x critical_dt and \
                 gains 16 % at 0.02 x); sim.shape_functions(\"bspline2\") or \"gimp\" keeps it stable",
                self.mpm.velocity_update.name()
            ));
        }
        warnings
    }
    fn run_ended(&mut self) -> Result<RunEnd> {
        let mut end = RunEnd::default();
        for m in &self.mpm.materials {
            if let Some(objects) = m.law.point_objects() {
                let spared = match &m.spread {
                    Some(spread) => spread.sum(objects.process_savings())?,
                    None => objects.process_savings(),
                };
                end.summary.extend(objects.run_summary(&m.state, spared));
            }
            let Some(spread) = &m.spread else { continue };
            let report = spread.report()?;
            end.notes.push(format!("material \"{}\": {}", m.name, report.line()));
            end.summary.extend(report.summary());
        }
        Ok(end)
    }
    fn set_driven(&mut self, target: usize, value: f64) {
        match self.driven.get(target) {
            Some(Driven::Velocity(i)) => self.mpm.boundary.velocity[*i].value = TimeFunction::Driven(value),
            Some(Driven::Force(i)) => self.mpm.boundary.forces[*i].factor = TimeFunction::Driven(value),
            Some(Driven::PointLoad(i)) => self.mpm.boundary.point_loads[*i].factor = TimeFunction::Driven(value),
            None => {}
        }
    }
}
