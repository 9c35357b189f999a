//! An MPM simulation driven from Rust, without Rhai: a linear-elastic column settles under its own
//! weight (Cundall damping, thesis eq. 3.26) and writes the output contract of a script run:
//! `series.csv`, `vtk/points.pvd`, a checkpoint every 5000 steps and `summary.json`.
//!
//!     cargo run --release -p granite-run --example self_weight [OUT_DIR]
//!
//! At rest the vertical stress is the overburden, sigma_yy = -rho g (H - y) (tension positive);
//! the program prints it beside the points' stress, averaged per cell row.

use granite_core::error::Result;
use granite_core::mpm::boundary::{Face, TimeFunction, VelocityConstraint};
use granite_core::mpm::fill::{cell_points, Layout};
use granite_core::mpm::{Mesh, MpmSim, StressScheme};
use granite_core::registry::{ParamMap, Registry};
use granite_run::{MpmScene, RunContext, Runner};

/// The column: width and height (m), cell size (m), density (kg/m^3), Young's modulus (Pa).
pub struct Column {
    pub width: f64,
    pub height: f64,
    pub cell: f64,
    pub density: f64,
    pub young: f64,
}

pub const GRAVITY: f64 = 9.81;

impl Column {
    /// A 2D (plane strain) column on a fixed floor between smooth walls, at rest, 2 x 2 points a cell.
    pub fn build(&self, registry: &Registry) -> Result<MpmSim> {
        let cells = [(self.width / self.cell).round() as usize, (self.height / self.cell).round() as usize, 1];
        let mesh = Mesh::new(2, [0.0; 3], [self.cell, self.cell, 1.0], cells)?;
        let mut sim = MpmSim::new(mesh.clone(), registry.build_velocity_update("FLIP", &ParamMap::new())?);
        let elastic: ParamMap = [("young".to_string(), self.young), ("poisson".to_string(), 0.0)].into_iter().collect();
        let soil = sim.add_material("soil", self.density, registry.build_law("linear_elastic", &elastic)?)?;
        let (x, volumes) = cell_points(&mesh, Layout::Gauss, 2, |_| Ok(true))?;
        sim.add_points(soil, &x, &volumes, [0.0; 3], [0.0; 6])?;
        for (face, axis) in [("x-", 0), ("x+", 0), ("y-", 0), ("y-", 1)] {
            let face = Face::parse(face, 2)?;
            let nodes = face.nodes(&mesh);
            sim.boundary.velocity.push(VelocityConstraint { nodes, axis, value: TimeFunction::Constant(0.0) });
        }
        sim.gravity = [0.0, -GRAVITY, 0.0];
        sim.damping = 0.1;
        sim.scheme = StressScheme::Usf;
        let dt = 0.2 * sim.critical_dt().unwrap_or(1e-5);
        sim.set_dt(dt)?;
        Ok(sim)
    }

    /// Per cell row below the top one: (mean y, mean sigma_yy, overburden at that y).
    pub fn stress_profile(&self, sim: &MpmSim) -> Vec<(f64, f64, f64)> {
        let rows = (self.height / self.cell).round() as usize;
        let mut sums = vec![(0.0, 0.0, 0usize); rows];
        for (x, stress) in sim.points.x.iter().zip(&sim.points.stress) {
            let row = ((x[1] / self.cell).floor().max(0.0) as usize).min(rows - 1);
            sums[row].0 += x[1];
            sums[row].1 += stress[1];
            sums[row].2 += 1;
        }
        // Linear shape functions make the stress uniform in a cell: the top cell carries half a
        // cell of overburden spread over it, so it is left out.
        sums[..rows - 1]
            .iter()
            .filter(|s| s.2 > 0)
            .map(|&(y, s, n)| {
                let (y, s) = (y / n as f64, s / n as f64);
                (y, s, -self.density * GRAVITY * (self.height - y))
            })
            .collect()
    }
}

#[allow(dead_code)]
fn main() -> Result<()> {
    let out = std::env::args().nth(1).unwrap_or_else(|| "out/self_weight_rust".into());
    let column = Column { width: 0.2, height: 1.0, cell: 0.05, density: 2000.0, young: 1e8 };
    let sim = column.build(&granite_plugins::default_registry())?;
    let run =
        RunContext { program: format!("self_weight example {}", env!("CARGO_PKG_VERSION")), ..Default::default() };
    let mut runner = Runner::new(MpmScene::new(sim), &out, run);
    runner.output.series_every = Some(100);
    runner.output.vtk_every = Some(2000);
    runner.checkpoint = Some((5000, "checkpoint.json".into()));
    runner.run_until(1.0)?;
    runner.write_summary()?;
    println!("{:>8} {:>14} {:>14}", "y (m)", "sigma_yy (Pa)", "overburden");
    for (y, s, expected) in column.stress_profile(&runner.sim.mpm) {
        println!("{y:>8.3} {s:>14.1} {expected:>14.1}");
    }
    println!("outputs in {out}/ (series.csv, vtk/points.pvd, checkpoint.json, summary.json)");
    Ok(())
}
