//! A simulation's state as tables of numbers, one row per sphere or material point, for bindings
//! that hand it on as arrays (the Python package): read between two steps under the
//! simulation's lock, copied out.

use super::dem_api::DemHandle;
use super::mpm_api::SimHandle;
use granite_core::dem::bodies::SphereEdit;
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

/// The arrays `set_array` changes: of a DEM simulation's spheres, of an MPM one's points.
pub const SPHERE_SETTABLE: &[&str] = &["velocity", "angular_velocity", "fixed"];
pub const POINT_SETTABLE: &[&str] = &["velocity"];

/// Sets one array of a simulation value from a table of one row per sphere or point (the order
/// of `array`), with the checks of the script calls that change one (`set_body`,
/// `set_point_velocity`): every row is checked before any is applied.
pub fn set_array(sim: &Dynamic, name: &str, table: &Table) -> Result<()> {
    let finite = |what: &str| -> Result<()> {
        match table.values.iter().position(|v| !v.is_finite()) {
            Some(k) => Err(GraniteError::param(
                what,
                format!("{} in row {}", table.values[k], k / table.columns.max(1)),
                "finite numbers",
            )),
            None => Ok(()),
        }
    };
    let shape = |rows: usize, columns: &[usize], what: &str| -> Result<()> {
        if !columns.contains(&table.columns) || table.values.len() != rows * table.columns {
            let wanted = columns.iter().map(|c| format!("({rows}, {c})")).collect::<Vec<_>>().join(" or ");
            return Err(GraniteError::param(
                what,
                format!("{} values in rows of {}", table.values.len(), table.columns),
                &format!("an array of shape {wanted}"),
            ));
        }
        Ok(())
    };
    if let Some(dem) = sim.clone().try_cast::<DemHandle>() {
        let mut st = dem.lock();
        let world = &mut st.sim.dem.world;
        let n = world.spheres.x.len();
        let edits: Vec<SphereEdit> = match name {
            "velocity" | "angular_velocity" => {
                shape(n, &[3], name)?;
                finite(name)?;
                let rows = table.values.chunks(3).map(|r| [r[0], r[1], r[2]]);
                if name == "velocity" {
                    rows.map(|v| SphereEdit { velocity: Some(v), ..Default::default() }).collect()
                } else {
                    rows.map(|w| SphereEdit { spin: Some(w), ..Default::default() }).collect()
                }
            }
            "fixed" => {
                shape(n, &[1], name)?;
                let all = f64::from(granite_core::dem::particles::dof::ALL);
                if let Some(k) = table.values.iter().position(|&b| !(b >= 0.0 && b <= all && b.fract() == 0.0)) {
                    return Err(GraniteError::param(
                        "fixed",
                        format!("{} in row {k}", table.values[k]),
                        "whole numbers of the x, y, z, rx, ry, rz flags (0 to 63), as `array(\"fixed\")` gives",
                    ));
                }
                table.values.iter().map(|&b| SphereEdit { blocked: Some(b as u8), ..Default::default() }).collect()
            }
            _ => {
                return Err(unknown(
                    "settable arrays of a DEM simulation",
                    name,
                    SPHERE_SETTABLE.iter().map(|s| s.to_string()),
                ))
            }
        };
        // A clump member's motion is its clump's: refused before anything changes.
        if let Some(i) = world.spheres.clump.iter().position(|&c| c != granite_core::dem::particles::FREE) {
            return Err(GraniteError::Setup(format!(
                "sphere {} is a member of clump {}: its {name} is the clump's",
                world.spheres.id[i], world.spheres.clump[i]
            )));
        }
        for (i, edit) in edits.iter().enumerate() {
            world.edit_sphere(i, edit)?;
        }
        return Ok(());
    }
    if let Some(mpm) = sim.clone().try_cast::<SimHandle>() {
        let mut st = mpm.lock();
        let sim = &mut st.sim.mpm;
        if name != "velocity" {
            return Err(unknown(
                "settable arrays of an MPM simulation",
                name,
                POINT_SETTABLE.iter().map(|s| s.to_string()),
            ));
        }
        let (n, dim) = (sim.points.len(), sim.dim());
        shape(n, &[dim, 3], name)?;
        finite(name)?;
        if table.columns == 3 && dim < 3 {
            if let Some(k) = table.values.chunks(3).position(|r| r[2] != 0.0) {
                return Err(GraniteError::param(
                    "velocity",
                    format!("z = {} in row {k}", table.values[3 * k + 2]),
                    "0 in a 2D simulation",
                ));
            }
        }
        for (v, row) in sim.points.v.iter_mut().zip(table.values.chunks(table.columns)) {
            *v = [row[0], row[1], if table.columns == 3 { row[2] } else { 0.0 }];
        }
        return Ok(());
    }
    Err(GraniteError::Setup(format!("a {} holds no arrays: a DEM or MPM simulation does", sim.type_name())))
}
