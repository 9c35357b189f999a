//! The files one simulation writes: series rows, VTK frames, point tables.

use crate::error::{GraniteError, Result};
use crate::io::vtk::Field;
use crate::io::{SeriesWriter, VtkWriter};
use crate::math::{deviatoric_strain_norm, p_q};
use crate::mpm::MpmSim;
use std::io::Write;
use std::path::PathBuf;

/// Reference geometry of a collapsing column, for the runout columns (thesis 5.6-5.9).
#[derive(Debug, Clone, Copy)]
pub struct Runout {
    pub width0: f64,
    pub height0: f64,
    /// Time the collapse started (t~ counts from here).
    pub t0: f64,
}

impl Runout {
    /// `(L_x, d_r, L~, t~)` of eqs. 5.6-5.9.
    pub fn measure(&self, sim: &MpmSim) -> (f64, f64, f64, f64) {
        let lx = sim.voxel_width();
        let dr = lx - self.width0;
        let g = crate::math::norm3(sim.gravity).max(f64::MIN_POSITIVE);
        (lx, dr, dr / self.width0, (sim.time - self.t0) / (self.height0 / g).sqrt())
    }
}

pub struct Output {
    pub dir: PathBuf,
    /// File name prefix: empty for the first simulation of a script, `sim2_`... for others.
    pub prefix: String,
    series: Option<SeriesWriter>,
    vtk: Option<VtkWriter>,
    /// Steps between series rows / VTK frames; None = chosen per run call.
    pub series_every: Option<u64>,
    pub vtk_every: Option<u64>,
    pub last_series_step: Option<u64>,
    pub last_vtk_step: Option<u64>,
}

impl Output {
    pub fn new(dir: PathBuf, prefix: String) -> Output {
        Output {
            dir,
            prefix,
            series: None,
            vtk: None,
            series_every: None,
            vtk_every: None,
            last_series_step: None,
            last_vtk_step: None,
        }
    }

    pub fn series_row(sim: &MpmSim, runout: Option<&Runout>) -> (Vec<&'static str>, Vec<f64>) {
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
        ];
        if let Some(r) = runout {
            let (lx, dr, l_norm, t_norm) = r.measure(sim);
            cols.extend(["lx", "runout", "runout_normalised", "time_normalised"]);
            vals.extend([lx, dr, l_norm, t_norm]);
        }
        (cols, vals)
    }

    pub fn write_series(&mut self, sim: &MpmSim, runout: Option<&Runout>) -> Result<()> {
        if self.last_series_step == Some(sim.step) {
            return Ok(());
        }
        let (cols, vals) = Self::series_row(sim, runout);
        let needs_new = match &self.series {
            None => true,
            Some(w) => w.columns().len() != cols.len(),
        };
        if needs_new {
            // The column set changes when runout tracking starts: continue in a new file.
            let name = match &self.series {
                None => format!("{}series.csv", self.prefix),
                Some(_) => format!("{}series_runout.csv", self.prefix),
            };
            self.series =
                Some(SeriesWriter::create(&self.dir.join(name), cols.iter().map(|s| s.to_string()).collect())?);
        }
        if let Some(w) = self.series.as_mut() {
            w.write(&vals)?;
        }
        self.last_series_step = Some(sim.step);
        Ok(())
    }

    pub fn write_vtk(&mut self, sim: &MpmSim) -> Result<()> {
        if self.last_vtk_step == Some(sim.step) {
            return Ok(());
        }
        if self.vtk.is_none() {
            self.vtk = Some(VtkWriter::new(&self.dir.join("vtk"), &format!("{}points", self.prefix))?);
        }
        let p = &sim.points;
        let n = p.len();
        let mut fields = vec![
            Field { name: "id", components: 1, values: p.id.iter().map(|&i| i as f64).collect() },
            Field { name: "material", components: 1, values: p.material.iter().map(|&m| m as f64).collect() },
            Field { name: "velocity", components: 3, values: p.v.iter().flatten().copied().collect() },
            Field { name: "stress", components: 6, values: p.stress.iter().flatten().copied().collect() },
            Field { name: "strain", components: 6, values: p.strain.iter().flatten().copied().collect() },
            Field { name: "mean_stress", components: 1, values: p.stress.iter().map(|s| p_q(s).0).collect() },
            Field { name: "deviatoric_stress", components: 1, values: p.stress.iter().map(|s| p_q(s).1).collect() },
            Field {
                name: "deviatoric_strain",
                components: 1,
                values: p.strain.iter().map(deviatoric_strain_norm).collect(),
            },
            Field { name: "volume", components: 1, values: p.volume.clone() },
        ];
        // Law state variables by name (zero for points whose law lacks that variable).
        let mut start = 0;
        for m in &sim.materials {
            let names = m.law.state_names();
            for (k, name) in names.iter().enumerate() {
                let idx = match fields.iter().position(|f| f.name == *name) {
                    Some(i) => i,
                    None => {
                        fields.push(Field { name, components: 1, values: vec![0.0; n] });
                        fields.len() - 1
                    }
                };
                for j in 0..m.count {
                    fields[idx].values[start + j] = m.state[j * names.len() + k];
                }
            }
            start += m.count;
        }
        if let Some(w) = self.vtk.as_mut() {
            w.write_frame(sim.time, &p.x, &fields)?;
        }
        self.last_vtk_step = Some(sim.step);
        Ok(())
    }

    /// A CSV table of every point: position, velocity, stress, strain and law state.
    pub fn write_points(&self, sim: &MpmSim, file: &str) -> Result<PathBuf> {
        let path = self.dir.join(file);
        let f = std::fs::File::create(&path).map_err(|e| GraniteError::io(&path, e))?;
        let mut w = std::io::BufWriter::new(f);
        let io = |e| GraniteError::io(&path, e);
        writeln!(
            w,
            "id,material,x,y,z,vx,vy,vz,sxx,syy,szz,sxy,syz,sxz,exx,eyy,ezz,gxy,gyz,gxz,p,q,deviatoric_strain,volume,mass"
        )
        .map_err(io)?;
        let p = &sim.points;
        for i in 0..p.len() {
            let (mean, q) = p_q(&p.stress[i]);
            let mut row = vec![p.id[i] as f64, p.material[i] as f64];
            row.extend(p.x[i]);
            row.extend(p.v[i]);
            row.extend(p.stress[i]);
            row.extend(p.strain[i]);
            row.extend([mean, q, deviatoric_strain_norm(&p.strain[i]), p.volume[i], p.mass[i]]);
            let line = row.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(",");
            writeln!(w, "{line}").map_err(|e| GraniteError::io(&path, e))?;
        }
        w.flush().map_err(|e| GraniteError::io(&path, e))?;
        Ok(path)
    }
}
