//! Access to single bodies between two steps (YADE's `O.bodies`, `O.forces`): find a sphere by its
//! id, change its state, give it a lasting external load, erase it.
//!
//! Spheres are addressed by their id (creation order), which stays with a sphere when the engine
//! reorders the arrays (spatial ordering before the first step) or compacts them (erasures).

pub use crate::dem::particles::ExternalLoad;
use crate::dem::particles::{dof, FREE};
use crate::dem::sim::DemWorld;
use crate::error::{GraniteError, Result};
use crate::math::Vec3;

/// Changes to one sphere, applied together once all are checked (a refused change leaves the
/// sphere as it was).
#[derive(Debug, Clone, Default)]
pub struct SphereEdit {
    pub position: Option<Vec3>,
    pub velocity: Option<Vec3>,
    pub spin: Option<Vec3>,
    pub radius: Option<f64>,
    pub material: Option<u16>,
    /// A mass of its own (kg), instead of the material's density times the volume; the moment of
    /// inertia follows (`2/5 m r^2`).
    pub mass: Option<f64>,
    /// Blocked degrees of freedom, [`dof`] flags.
    pub blocked: Option<u8>,
    pub force: Option<Vec3>,
    pub torque: Option<Vec3>,
}

/// Degrees of freedom by name: `"xyz"`, `"x"`, `"rz"`, `"all"`, `""`... in a comma- or
/// space-free string of the letters x, y, z (translations) and rx, ry, rz (rotations).
pub fn parse_dofs(text: &str) -> Result<u8> {
    let bad = || {
        GraniteError::param(
            "fixed",
            format!("\"{text}\""),
            "a string of x, y, z, rx, ry, rz (\"xyz\", \"xyzrxryrz\"), \"all\" or \"\"",
        )
    };
    if text == "all" {
        return Ok(dof::ALL);
    }
    let mut flags = 0u8;
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        let rotation = c == 'r';
        let axis = if rotation { chars.next().ok_or_else(bad)? } else { c };
        let bit = match axis {
            'x' => dof::X,
            'y' => dof::Y,
            'z' => dof::Z,
            _ => return Err(bad()),
        };
        flags |= if rotation { bit << 3 } else { bit };
    }
    Ok(flags)
}

/// The names of blocked degrees of freedom, as [`parse_dofs`] reads them.
pub fn dofs_name(flags: u8) -> String {
    let names = ["x", "y", "z", "rx", "ry", "rz"];
    names.iter().enumerate().filter(|(k, _)| flags & (1 << k) != 0).map(|(_, n)| *n).collect()
}

fn finite3(v: Vec3, name: &str) -> Result<Vec3> {
    if v.iter().all(|c| c.is_finite()) {
        Ok(v)
    } else {
        Err(GraniteError::param(name, format!("{v:?}"), "must be finite"))
    }
}

impl DemWorld {
    /// Index of the sphere with `id` now, or None when no sphere has it (never made, or erased).
    pub fn sphere_index(&self, id: u64) -> Option<usize> {
        self.spheres.index_of(id)
    }

    /// The index of sphere `id`, or an error that says there is none.
    pub fn sphere_index_or_err(&self, id: u64) -> Result<usize> {
        self.sphere_index(id).ok_or_else(|| {
            GraniteError::Setup(format!(
                "no sphere with id {id} (ids run from 0 to {}; erased spheres keep their id unused)",
                self.next_sphere_id().saturating_sub(1)
            ))
        })
    }

    /// The lasting external load of sphere `id` (zero when none).
    pub fn external_load(&self, id: u64) -> (Vec3, Vec3) {
        self.external.iter().find(|l| l.id == id).map_or(([0.0; 3], [0.0; 3]), |l| (l.force, l.torque))
    }

    /// Applies `edit` to the sphere at `index`, from the next step on. Moving a sphere or changing
    /// its radius has the candidate lists rebuilt at the next step (contacts that remain keep
    /// their history); a new material re-initialises the parameters of its contacts.
    pub fn edit_sphere(&mut self, index: usize, edit: &SphereEdit) -> Result<()> {
        let s = &self.spheres;
        let id = s.id[index];
        let clump = s.clump[index];
        if clump != FREE {
            let moves = [edit.position.is_some(), edit.velocity.is_some(), edit.spin.is_some()];
            let shape = [edit.radius.is_some(), edit.material.is_some(), edit.blocked.is_some(), edit.mass.is_some()];
            if moves.iter().chain(&shape).any(|&b| b) {
                return Err(GraniteError::Setup(format!(
                    "sphere {id} is a member of clump {clump}: its position, velocity, spin, radius, material \
                     and fixed degrees of freedom are the clump's (a force or torque may be applied to it)"
                )));
            }
        }
        let x = match edit.position {
            Some(p) => finite3(p, "position")?,
            None => s.x[index],
        };
        let v = match edit.velocity {
            Some(v) => finite3(v, "velocity")?,
            None => s.v[index],
        };
        let spin = edit.spin.map(|w| finite3(w, "spin")).transpose()?;
        let radius = edit.radius.unwrap_or(s.radius[index]);
        let material = edit.material.unwrap_or(s.material[index]);
        // The same checks as a new sphere: finite, positive radius, a mass that a step can use.
        let density = self.check_sphere(material, x, radius, v)?;
        if let Some(m) = edit.mass {
            if !(m > 0.0 && m.is_finite()) {
                return Err(GraniteError::param("mass", m, "must be > 0 and finite"));
            }
        }
        let force = edit.force.map(|f| finite3(f, "force")).transpose()?;
        let torque = edit.torque.map(|t| finite3(t, "torque")).transpose()?;
        if let Some(b) = edit.blocked {
            if b & !dof::ALL != 0 {
                return Err(GraniteError::param("fixed", b, "flags of x, y, z, rx, ry, rz"));
            }
        }
        let s = &mut self.spheres;
        let moved = x != s.x[index];
        s.x[index] = x;
        s.v[index] = v;
        if let Some(w) = spin {
            s.w[index] = w;
        }
        if let Some(b) = edit.blocked {
            s.blocked[index] = b;
        }
        let resized = radius != s.radius[index];
        let new_material = material != s.material[index];
        if resized || new_material {
            let mass = crate::dem::particles::sphere_mass(density, radius);
            s.radius[index] = radius;
            s.material[index] = material;
            s.mass[index] = mass;
            s.inertia[index] = 0.4 * mass * radius * radius;
        }
        if let Some(m) = edit.mass {
            s.mass[index] = m;
            s.inertia[index] = 0.4 * m * radius * radius;
        }
        if moved || resized {
            self.needs_rebuild = true;
        }
        if new_material || resized || edit.mass.is_some() {
            // Contact parameters depend on the materials and the radii: set them again.
            let laws = self.contacts.laws.clone();
            self.refresh_pair_laws(&laws);
            self.recheck_time_step();
        }
        if force.is_some() || torque.is_some() {
            let (f0, t0) = self.external_load(id);
            let load = ExternalLoad { id, force: force.unwrap_or(f0), torque: torque.unwrap_or(t0), index };
            self.external.retain(|l| l.id != id);
            if load.force != [0.0; 3] || load.torque != [0.0; 3] {
                self.external.push(load);
                self.external.sort_by_key(|l| l.id);
            }
        }
        Ok(())
    }

    /// Erases the spheres with these ids (a clump member takes its whole clump), with their
    /// contacts and external loads. Returns how many spheres went.
    pub fn erase_spheres(&mut self, ids: &[u64]) -> Result<usize> {
        let mut keep = vec![true; self.spheres.len()];
        for &id in ids {
            keep[self.sphere_index_or_err(id)?] = false;
        }
        let before = self.spheres.len();
        self.remove_spheres(&keep);
        Ok(before - self.spheres.len())
    }

    /// Index of the sphere an external load acts on.
    pub(crate) fn load_index(&self, load: &ExternalLoad) -> Option<usize> {
        load.index_in(&self.spheres)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degrees_of_freedom_read_back_by_name() {
        for name in ["", "x", "xyz", "rz", "xyrxryrz", "xyzrxryrz"] {
            assert_eq!(dofs_name(parse_dofs(name).unwrap()), name);
        }
        assert_eq!(parse_dofs("all").unwrap(), dof::ALL);
        assert!(parse_dofs("w").is_err());
        assert!(parse_dofs("r").is_err());
    }
}
