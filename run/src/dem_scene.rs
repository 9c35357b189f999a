//! A DEM simulation as a run driver steps it ([`Simulation`] for [`DemSim`]): the columns of
//! `series.csv` (with the periodic cell's stress and strain), the spheres' VTK frame with the
//! contact network and walls beside it, a snapshot to fall back on.

use crate::simulation::{RunContext, Simulation};
use granite_core::dem::walls::Wall;
use granite_core::dem::DemSim;
use granite_core::error::Result;
use granite_core::io::vtk::Field;
use granite_core::math::Vec3;
use std::path::Path;

/// A DEM simulation as a run driver steps it.
pub struct DemScene {
    pub dem: DemSim,
    /// Wall velocity components set from outside the engine once per step: (walls, axis), the
    /// walls moving as one (the triangles of a wall mesh).
    pub driven: Vec<(Vec<usize>, usize)>,
    /// The skin was left to its default (half the smallest radius, as YADE).
    pub auto_skin: bool,
    /// Deep overlaps are looked for before a run while this holds (`sim.allow_overlaps(true)`
    /// turns it off), once per set of bodies: the sphere and wall counts last checked.
    pub check_overlaps: bool,
    overlaps_checked_for: Option<(usize, usize, usize)>,
}

/// Overlap, as a fraction of the smaller radius, above which a body at the start of a run is
/// reported: a sound stiffness keeps a packing at rest well under 1 %; 10 % is a set-up mistake
/// (spheres placed inside one another, a sphere centred on a wall).
pub const DEEP_OVERLAP: f64 = 0.1;

/// Everything a whole-state snapshot needs.
pub struct DemSnapshot {
    spheres: granite_core::dem::Spheres,
    bodies: granite_core::dem::kinds::KindScene,
    walls: Vec<Wall>,
    time: f64,
    step: u64,
}

impl DemScene {
    /// `auto_skin`: the skin follows the smallest radius at the first step (half of it, as YADE).
    pub fn new(dem: DemSim, auto_skin: bool) -> DemScene {
        DemScene { dem, driven: Vec::new(), auto_skin, check_overlaps: true, overlaps_checked_for: None }
    }

    /// A copy ready to be stepped elsewhere (e.g. as an RVE): the default skin is settled.
    pub fn prepared(&self) -> DemSim {
        let mut dem = self.dem.clone();
        if self.auto_skin {
            let r_min = dem.world.spheres.smallest_radius();
            if r_min.is_finite() {
                dem.skin = 0.5 * r_min;
            }
        }
        dem
    }
}

impl Simulation for DemScene {
    fn setup_warnings(&mut self) -> Vec<String> {
        let w = &self.dem.world;
        let bodies = (w.spheres.len(), w.walls.len(), w.kinds.len());
        if !self.check_overlaps || self.overlaps_checked_for == Some(bodies) {
            return Vec::new();
        }
        self.overlaps_checked_for = Some(bodies);
        let deep = self.dem.deep_overlaps_before_run(DEEP_OVERLAP, 5);
        if deep.is_empty() {
            return Vec::new();
        }
        let list: Vec<String> = deep.iter().map(|(what, d)| format!("{what} by {:.0} %", 100.0 * d)).collect();
        vec![format!(
            "bodies overlap by more than {:.0} % of a radius at the start of the run (deepest: {}): they start \
             with forces a packing at rest never has and may fly apart; move them, or sim.allow_overlaps(true) \
             if this is meant",
            100.0 * DEEP_OVERLAP,
            list.join(", ")
        )]
    }
    type Snapshot = DemSnapshot;

    fn validate(&self) -> Result<()> {
        self.dem.validate()
    }
    fn advance(&mut self) -> Result<()> {
        if self.auto_skin {
            let r_min = self.dem.world.spheres.smallest_radius();
            if r_min.is_finite() {
                self.dem.skin = 0.5 * r_min;
            }
            self.auto_skin = false;
        }
        self.dem.step()
    }
    fn time(&self) -> f64 {
        self.dem.world.time
    }
    fn steps(&self) -> u64 {
        self.dem.world.step
    }
    fn dt(&self) -> f64 {
        self.dem.world.dt
    }
    fn series_row(&self) -> (Vec<&'static str>, Vec<f64>) {
        let d = self.dem.world.diagnostics();
        let mut cols = vec![
            "step",
            "time",
            "kinetic_energy",
            "elastic_energy",
            "gravitational_energy",
            "total_energy",
            "unbalanced_force",
            "contacts",
            "wall_contacts",
            "coordination",
            "coordination_no_rattlers",
            "rattlers",
            "particles",
            "max_height",
        ];
        let mut vals = vec![
            self.dem.world.step as f64,
            self.dem.world.time,
            d.kinetic_energy,
            d.elastic_energy,
            d.gravitational_energy,
            d.kinetic_energy + d.elastic_energy + d.gravitational_energy,
            d.unbalanced_force,
            d.contacts as f64,
            d.wall_contacts as f64,
            d.coordination,
            d.coordination_no_rattlers,
            d.rattlers as f64,
            d.particles as f64,
            d.max_height,
        ];
        if let Some(energy) = &self.dem.energy {
            const COLUMNS: [&str; 8] = [
                "energy_kinetic",
                "energy_gravitational",
                "energy_elastic",
                "energy_friction",
                "energy_viscous",
                "energy_damping",
                "energy_boundary_work",
                "energy_total",
            ];
            cols.extend(COLUMNS);
            // Nothing is measured before the first tracked step.
            let measured = energy.initial_total.is_some();
            vals.extend(energy.entries()[..8].iter().map(|(_, v)| if measured { *v } else { f64::NAN }));
        }
        if let (Some(volume), Some(e), Some((strain, vol_strain))) =
            (self.dem.world.cell_volume(), self.dem.world.void_ratio(), self.dem.world.cell_strain())
        {
            let s = self.dem.world.love_weber_stress(volume);
            let (p, q) = granite_core::math::p_q(&s);
            cols.extend([
                "void_ratio",
                "p",
                "q",
                "sxx",
                "syy",
                "szz",
                "sxy",
                "syz",
                "sxz",
                "strain_x",
                "strain_y",
                "strain_z",
                "volumetric_strain",
            ]);
            // p and q as soil mechanics plots them: compression positive.
            vals.extend([e, -p, q, s[0], s[1], s[2], s[3], s[4], s[5], strain[0], strain[1], strain[2], vol_strain]);
        }
        (cols, vals)
    }
    fn vtk_frame(&self) -> (Vec<Vec3>, Vec<Field>) {
        let s = &self.dem.world.spheres;
        let counts = self.dem.world.contact_counts();
        let fields = vec![
            Field::int("id", s.id.iter().map(|&i| i as i64)),
            Field::float("radius", 1, s.radius.clone()),
            Field::int("material", s.material.iter().map(|&m| m as i64)),
            Field::float("velocity", 3, s.v.iter().flatten().copied().collect()),
            Field::float("angular_velocity", 3, s.w.iter().flatten().copied().collect()),
            Field::float("force", 3, s.force.iter().flatten().copied().collect()),
            Field::int("contacts", counts.iter().map(|&c| c as i64)),
        ];
        (s.x.clone(), fields)
    }
    fn vtk_poly(&self) -> Vec<(&'static str, granite_core::io::vtk::PolyData)> {
        let mut out = vec![("contacts", self.dem.world.contacts_picture())];
        if !self.dem.world.walls.is_empty() {
            out.push(("walls", self.dem.world.walls_picture()));
        }
        if !self.dem.world.kinds.is_empty() {
            out.push(("bodies", self.dem.world.kinds_picture()));
        }
        out
    }
    fn write_points(&self, path: &Path) -> Result<()> {
        let s = &self.dem.world.spheres;
        let counts = self.dem.world.contact_counts();
        let rows = (0..s.len()).map(|i| {
            let mut row = vec![s.id[i] as f64, s.material[i] as f64];
            row.extend(s.x[i]);
            row.push(s.radius[i]);
            row.extend(s.v[i]);
            row.extend(s.w[i]);
            row.push(counts[i] as f64);
            row
        });
        crate::output::write_table(path, "id,material,x,y,z,radius,vx,vy,vz,wx,wy,wz,contacts", rows)
    }
    fn diagnostics(&self) -> Vec<(&'static str, f64)> {
        let (cols, vals) = self.series_row();
        cols.into_iter().zip(vals).collect()
    }
    fn snapshot(&self) -> DemSnapshot {
        DemSnapshot {
            spheres: self.dem.world.spheres.clone(),
            bodies: self.dem.world.kinds.clone(),
            walls: self.dem.world.walls.clone(),
            time: self.dem.world.time,
            step: self.dem.world.step,
        }
    }
    fn restore(&mut self, s: DemSnapshot) {
        self.dem.world.spheres = s.spheres;
        self.dem.world.kinds = s.bodies;
        self.dem.world.walls = s.walls;
        self.dem.world.time = s.time;
        self.dem.world.step = s.step;
        self.dem.world.contacts.spheres = Default::default();
        self.dem.world.contacts.sphere_walls = Default::default();
        let _ = self.dem.rebuild_candidates();
    }
    fn save_state(&self, path: &std::path::Path, run: &RunContext) -> Result<()> {
        // Every process of an MPI run holds the same DEM simulation: the first one writes it.
        let written = if run.writes_files() { self.prepared().save_as(path, &run.program) } else { Ok(()) };
        granite_core::comm::agree(run.comm.as_ref(), 0, written)
    }
    fn drain_events(&mut self) -> Vec<String> {
        self.dem.world.events.drain(..).collect()
    }
    fn set_driven(&mut self, target: usize, value: f64) {
        if let Some((walls, axis)) = self.driven.get(target) {
            for &w in walls {
                if let Some(wall) = self.dem.world.walls.get_mut(w) {
                    wall.velocity[*axis] = value;
                }
            }
        }
    }
}
