//! Periodic cell (thesis 1.1.4, formulas.md): a parallelepiped of base vectors (the columns of
//! `h`) deformed by a velocity gradient `L` (`dh/dt = L h`), with particle images across its faces
//! and Kraynik-Reinelt flipping so that shear can go on indefinitely.
//!
//! Particle positions are Cartesian and are not wrapped at every step: a contact pair stores the
//! integer shift `n` of its second particle's image (`x_b + h n`), which stays valid while both
//! move continuously. Positions are brought back into the cell when the candidate lists are
//! rebuilt, and the shifts of their pairs corrected at the same time.

use crate::math::Vec3;
use nalgebra::{Matrix3, Vector3};

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PeriodicCell {
    /// Base vectors as columns.
    pub h: Matrix3<f64>,
    /// Velocity gradient `L_ij = d v_i / d x_j` applied to the cell and, affinely, to the particles.
    pub velocity_gradient: Matrix3<f64>,
    /// Flips done so far.
    pub flips: u64,
    /// How the particles' fluctuations follow the field `L x` (see [`CellUpdate`]).
    #[serde(default)]
    pub update: CellUpdate,
}

/// How a particle's fluctuation velocity `v` (its velocity less the field `L x`) changes over a
/// step besides the forces, the particle having moved by `(v + L x) dt`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum CellUpdate {
    /// SLLOD's `v <- v - L v dt`: the peculiar velocity's equation of motion, the same for a
    /// particle and all its images (a free particle with no fluctuation keeps none wherever it
    /// sits), so a thin cell steps as its supercell under any `L`.
    #[default]
    Sllod,
    /// Newton's law for the whole velocity `v + L x`, which only forces change:
    /// `v <- v - L (v + L x) dt`. Differs from SLLOD by `-L L x dt`, a pull towards or away from
    /// the cell's origin that splits a particle from its images under stretching (YADE's
    /// `Cell.homoDeform` 1).
    Newton,
    /// The fluctuation changes by the forces alone (YADE's default `Cell.homoDeform` 2, and 3,
    /// whose convective term `L u` in the acceleration of the whole velocity `u` keeps the
    /// fluctuation to first order in `dt`).
    Yade,
}

impl CellUpdate {
    pub const NAMES: [(&'static str, CellUpdate); 3] =
        [("sllod", CellUpdate::Sllod), ("newton", CellUpdate::Newton), ("yade", CellUpdate::Yade)];

    /// The update of a script's name, or what the names are.
    pub fn named(name: &str) -> Result<CellUpdate, String> {
        Self::NAMES.iter().find(|(n, _)| *n == name).map(|(_, u)| *u).ok_or_else(|| {
            let names: Vec<&str> = Self::NAMES.iter().map(|(n, _)| *n).collect();
            format!("cell update \"{name}\": one of {}", names.join(", "))
        })
    }

    pub fn name(self) -> &'static str {
        Self::NAMES.iter().find(|(_, u)| *u == self).map_or("sllod", |(n, _)| n)
    }

    /// What the field takes from a fluctuation `v` (after the step's forces) of a particle moving
    /// at `moving` = `v + L x`: `L w dt` for the velocity `w` the update acts on, None for none.
    #[inline(always)]
    pub fn field_velocity(self, v: Vec3, moving: Vec3) -> Option<Vec3> {
        match self {
            CellUpdate::Sllod => Some(v),
            CellUpdate::Newton => Some(moving),
            CellUpdate::Yade => None,
        }
    }
}

impl PeriodicCell {
    /// An axis-aligned box cell with the given edge lengths.
    pub fn new_box(size: Vec3) -> PeriodicCell {
        PeriodicCell {
            h: Matrix3::from_diagonal(&Vector3::new(size[0], size[1], size[2])),
            velocity_gradient: Matrix3::zeros(),
            flips: 0,
            update: CellUpdate::default(),
        }
    }

    pub fn volume(&self) -> f64 {
        self.h.determinant().abs()
    }

    pub fn inverse(&self) -> Matrix3<f64> {
        self.h.try_inverse().unwrap_or_else(Matrix3::zeros)
    }

    /// Distances between opposite faces: the thickness of the cell along each face normal.
    pub fn widths(&self) -> Vec3 {
        let v = self.volume();
        let c = |a: usize, b: usize| self.h.column(a).cross(&self.h.column(b)).norm();
        [v / c(1, 2), v / c(2, 0), v / c(0, 1)]
    }

    /// Image of a lattice shift: `h n`.
    #[inline]
    pub fn shift_vector(&self, n: [i32; 3]) -> Vec3 {
        crate::math::mat_vec(&self.h, n.map(f64::from))
    }

    /// Reduced coordinates `h^-1 x`.
    pub fn reduced(&self, inv: &Matrix3<f64>, x: Vec3) -> Vec3 {
        let s = inv * Vector3::new(x[0], x[1], x[2]);
        [s[0], s[1], s[2]]
    }

    /// Advances the cell by one step of its velocity gradient.
    pub fn deform(&mut self, dt: f64) {
        self.h += self.velocity_gradient * self.h * dt;
    }

    /// Kraynik-Reinelt flip: when a base vector leans more than half another along it, subtract
    /// that one (an integer unimodular change of basis, so no particle or contact appears or
    /// disappears). Returns the matrix `M` with `h_new = h_old M`, or None.
    pub fn flip_if_needed(&mut self) -> Option<Matrix3<i32>> {
        let mut m = Matrix3::<i32>::identity();
        let mut changed = false;
        for j in 0..3 {
            for i in 0..3 {
                if i == j {
                    continue;
                }
                let ai = self.h.column(i).into_owned();
                let aj = self.h.column(j).into_owned();
                let k = (aj.dot(&ai) / ai.dot(&ai)).round();
                if k != 0.0 {
                    self.h.set_column(j, &(aj - ai * k));
                    // Column j of M gets -k times column i of M.
                    for r in 0..3 {
                        m[(r, j)] -= k as i32 * m[(r, i)];
                    }
                    changed = true;
                }
            }
        }
        if changed {
            self.flips += 1;
            Some(m)
        } else {
            None
        }
    }
}

/// Re-expresses a lattice shift after a flip `h_new = h_old M`: `h_old n = h_new M^-1 n`.
pub fn shift_after_flip(m: &Matrix3<i32>, n: [i32; 3]) -> [i32; 3] {
    let mf = m.map(|v| v as f64);
    let inv = mf.try_inverse().unwrap_or_else(Matrix3::identity);
    let v = inv * Vector3::new(n[0] as f64, n[1] as f64, n[2] as f64);
    [v[0].round() as i32, v[1].round() as i32, v[2].round() as i32]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flip_keeps_the_lattice_and_the_images() {
        let mut cell = PeriodicCell::new_box([1.0, 1.0, 1.0]);
        // Simple shear: x velocity grows with z, gamma = 0.7 > 0.5.
        cell.velocity_gradient[(0, 2)] = 0.7;
        cell.deform(1.0);
        let before = cell.clone();
        let m = cell.flip_if_needed().expect("gamma 0.7 must flip");
        assert!((cell.volume() - before.volume()).abs() < 1e-12);
        assert!(cell.h[(0, 2)].abs() <= 0.5);
        // Every old image position is an image of the new lattice too.
        for n in [[1, 0, 0], [0, 0, 1], [1, -1, 1], [2, 3, -1]] {
            let old = before.shift_vector(n);
            let new = cell.shift_vector(shift_after_flip(&m, n));
            for a in 0..3 {
                assert!((old[a] - new[a]).abs() < 1e-12);
            }
        }
    }
}

/// What drives one diagonal component of the cell's velocity gradient.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum AxisGoal {
    /// Prescribed strain rate `L_aa` (1/s; negative compresses).
    Rate(f64),
    /// Servo on the stress `sigma_aa` (Pa, tension positive): a proportional-integral control of
    /// the strain rate, scaled by the packing's stiffness along that axis, at most `max_rate`.
    Stress { target: f64, max_rate: f64 },
}

/// A stress- or strain-controlled periodic cell (like YADE's PeriTriaxController): each diagonal
/// component of `L` follows its goal, off-diagonal components are prescribed rates.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CellControl {
    pub axes: [AxisGoal; 3],
    /// Prescribed off-diagonal `L_ij` (shear rates), e.g. `(0, 2, rate)` for x velocity along z.
    pub shear: Vec<(usize, usize, f64)>,
    /// Steps over which the servo's proportional part closes a stress error (its relaxation
    /// time, in time steps).
    pub relax_steps: f64,
    /// The integral part of each servoed axis's strain rate (1/s).
    #[serde(default)]
    pub integral: [f64; 3],
}

impl CellControl {
    /// Integral time over proportional time: 4 makes the loop critically damped when the
    /// stiffness is right (error'' + error'/tau + error/(4 tau^2) = 0 has a double root).
    const INTEGRAL_OVER_PROPORTIONAL: f64 = 4.0;

    pub fn new(axes: [AxisGoal; 3], shear: Vec<(usize, usize, f64)>, relax_steps: f64) -> CellControl {
        CellControl { axes, shear, relax_steps, integral: [0.0; 3] }
    }

    /// The velocity gradient for the current stress (Voigt, tension positive), given the
    /// packing's stiffness along each axis (`d sigma_aa / d eps_aa`, Pa) and the time step.
    ///
    /// Each servoed axis runs a proportional-integral control, both parts scaled by the
    /// stiffness: the proportional part closes an error in about `relax_steps` steps, so the
    /// servo cannot outrun the contacts; the integral part learns the rate a steady load needs
    /// (a sample dilating under a triaxial's axial compression), which a proportional servo can
    /// only give by holding an error proportional to that rate. The integral stops growing while
    /// the rate is at `max_rate` (no wind-up while a loose cloud is squeezed), and a cloud with
    /// no contact is squeezed at `max_rate`.
    pub fn velocity_gradient(&mut self, stress: &crate::math::Voigt, stiffness: [f64; 3], dt: f64) -> Matrix3<f64> {
        let mut l = Matrix3::zeros();
        let tau = self.relax_steps.max(1.0) * dt;
        for a in 0..3 {
            l[(a, a)] = match self.axes[a] {
                AxisGoal::Rate(r) => r,
                AxisGoal::Stress { target, max_rate } => {
                    // Too little compression (stress above a negative target): compress.
                    let error = target - stress[a];
                    if stiffness[a] > 0.0 {
                        let proportional = error / (stiffness[a] * tau);
                        let growth = proportional * dt / (Self::INTEGRAL_OVER_PROPORTIONAL * tau);
                        let integral = self.integral[a] + growth;
                        // Integrate while the rate is within its bound, or when the error draws the
                        // integral towards zero without carrying it across.
                        if (proportional + integral).abs() < max_rate || growth * integral < 0.0 {
                            self.integral[a] = integral.clamp(-max_rate, max_rate);
                        }
                        (proportional + self.integral[a]).clamp(-max_rate, max_rate)
                    } else {
                        self.integral[a] = 0.0;
                        error.signum() * max_rate
                    }
                }
            };
        }
        for &(i, j, r) in &self.shear {
            l[(i, j)] = r;
        }
        l
    }

    /// True when every stress-controlled axis is within `tolerance` (relative) of its target.
    pub fn stress_reached(&self, stress: &crate::math::Voigt, tolerance: f64) -> bool {
        (0..3).all(|a| match self.axes[a] {
            AxisGoal::Rate(_) => true,
            AxisGoal::Stress { target, .. } => (stress[a] - target).abs() <= tolerance * target.abs(),
        })
    }
}
