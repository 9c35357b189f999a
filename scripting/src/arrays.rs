//! A simulation's state as tables of numbers, one row per sphere or material point, for bindings
//! that hand it on as arrays (the Python package): read between two steps under the
//! simulation's lock, copied out.

use super::dem_api::DemHandle;
use super::mpm_api::SimHandle;
use granite_core::error::{GraniteError, Result};
use rhai::Dynamic;

/// Rows of `columns` numbers each, row after row.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    pub values: Vec<f64>,
    pub columns: usize,
}

impl Table {
    fn of<const N: usize>(rows: impl Iterator<Item = [f64; N]>) -> Table {
        Table { values: rows.flatten().collect(), columns: N }
    }

    fn single(rows: impl Iterator<Item = f64>) -> Table {
        Table { values: rows.collect(), columns: 1 }
    }
}

const SPHERE_ARRAYS: &[&str] =
    &["id", "position", "velocity", "angular_velocity", "radius", "mass", "force", "torque", "material", "fixed"];
const POINT_ARRAYS: &[&str] = &["id", "material", "position", "velocity", "stress", "strain", "volume", "mass"];

/// The arrays a simulation value offers: its spheres' (a DEM simulation) or its material points'
/// and their laws' state variables (an MPM one); None for any other value.
pub fn names(sim: &Dynamic) -> Option<Vec<String>> {
    if sim.is::<DemHandle>() {
        return Some(SPHERE_ARRAYS.iter().map(|s| s.to_string()).collect());
    }
    let sim = sim.clone().try_cast::<SimHandle>()?;
    let st = sim.lock();
    let mut names: Vec<String> = POINT_ARRAYS.iter().map(|s| s.to_string()).collect();
    for material in &st.sim.mpm.materials {
        for name in material.law.state_names() {
            if !names.iter().any(|n| n == name) {
                names.push(name.to_string());
            }
        }
    }
    Some(names)
}

/// One array of a simulation value: spheres (DEM) or material points (MPM). A state variable of
/// the points' laws is NaN at points whose law does not have it.
pub fn array(sim: &Dynamic, name: &str) -> Result<Table> {
    if let Some(dem) = sim.clone().try_cast::<DemHandle>() {
        let st = dem.lock();
        let s = &st.sim.dem.world.spheres;
        let table = match name {
            "id" => Table::single(s.id.iter().map(|&i| i as f64)),
            "position" => Table::of(s.x.iter().copied()),
            "velocity" => Table::of(s.v.iter().copied()),
            "angular_velocity" => Table::of(s.w.iter().copied()),
            "radius" => Table::single(s.radius.iter().copied()),
            "mass" => Table::single(s.mass.iter().copied()),
            "force" => Table::of(s.force.iter().copied()),
            "torque" => Table::of(s.torque.iter().copied()),
            "material" => Table::single(s.material.iter().map(|&m| f64::from(m))),
            "fixed" => Table::single(s.blocked.iter().map(|&b| f64::from(b))),
            _ => return Err(unknown("a DEM simulation's spheres", name, SPHERE_ARRAYS.iter().map(|s| s.to_string()))),
        };
        return Ok(table);
    }
    if let Some(mpm) = sim.clone().try_cast::<SimHandle>() {
        let st = mpm.lock();
        let sim = &st.sim.mpm;
        let p = &sim.points;
        let table = match name {
            "id" => Table::single(p.id.iter().map(|&i| i as f64)),
            "material" => Table::single(p.material.iter().map(|&m| f64::from(m))),
            "position" => Table::of(p.x.iter().copied()),
            "velocity" => Table::of(p.v.iter().copied()),
            "stress" => Table::of(p.stress.iter().copied()),
            "strain" => Table::of(p.strain.iter().copied()),
            "volume" => Table::single(p.volume.iter().copied()),
            "mass" => Table::single(p.mass.iter().copied()),
            _ => {
                let mut values = vec![f64::NAN; p.len()];
                let mut found = false;
                for (m, material) in sim.materials.iter().enumerate() {
                    let names = material.law.state_names();
                    let Some(k) = names.iter().position(|n| *n == name) else { continue };
                    found = true;
                    for (row, i) in sim.material_range(m).enumerate() {
                        values[i] = material.state[row * names.len() + k];
                    }
                }
                drop(st);
                if !found {
                    let known = names(&Dynamic::from(mpm)).unwrap_or_default();
                    return Err(unknown("an MPM simulation's material points", name, known.into_iter()));
                }
                Table { values, columns: 1 }
            }
        };
        return Ok(table);
    }
    Err(GraniteError::Setup(format!("a {} holds no arrays: a DEM or MPM simulation does", sim.type_name())))
}

fn unknown(of: &str, name: &str, known: impl Iterator<Item = String>) -> GraniteError {
    GraniteError::Unknown {
        kind: format!("array of {of}"),
        name: name.to_string(),
        known: known.collect::<Vec<_>>().join(", "),
    }
}
