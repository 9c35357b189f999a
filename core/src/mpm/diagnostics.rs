//! Global measures of an MPM state: energies (thesis 3.45-3.48), heights and runout (5.6-5.9).

use crate::math::{deviatoric_strain_norm, stress_strain_work, Vec3};
use crate::mpm::sim::MpmSim;

#[derive(Debug, Clone, Default)]
pub struct Diagnostics {
    pub points: usize,
    pub mass: f64,
    pub momentum: Vec3,
    /// Angular momentum about the coordinate origin: `sum m x × v`, plus, for the affine updates
    /// (APIC, ASFLIP) on B-splines, the spin of each point's affine velocity field,
    /// `m axial(B - B^T)` with `B = C D` (Jiang et al. 2015; `D` its value away from the mesh
    /// edges). With linear or GIMP functions the affine part is not counted.
    pub angular_momentum: Vec3,
    /// Eq. 3.47.
    pub kinetic_energy: f64,
    /// Eqs. 3.45-3.46: `sum v/2 sigma : eps`.
    pub elastic_energy: f64,
    /// Eq. 3.48 generalised to any gravity direction: `-sum m g . x`.
    pub gravitational_energy: f64,
    /// Highest point along the last axis (eq. 3.44: z in 3D, y in 2D).
    pub max_height: f64,
    /// Rightmost point along x.
    pub max_x: f64,
    /// Largest deviatoric strain norm (eq. 5.12).
    pub max_deviatoric_strain: f64,
}

impl Diagnostics {
    /// Mechanical energy (eq. 5.10).
    pub fn total_energy(&self) -> f64 {
        self.kinetic_energy + self.elastic_energy + self.gravitational_energy
    }
}

impl MpmSim {
    /// Sums are taken in point order, so they do not depend on the thread count.
    pub fn diagnostics(&self) -> Diagnostics {
        let p = &self.points;
        let up = self.mesh.dim - 1;
        let mut d = Diagnostics {
            points: p.len(),
            max_height: f64::NEG_INFINITY,
            max_x: f64::NEG_INFINITY,
            ..Default::default()
        };
        let g = self.gravity;
        let affine_moment = if self.velocity_update.affine() { self.shape.interior_moment(&self.mesh) } else { None };
        for i in 0..p.len() {
            let (m, v, x) = (p.mass[i], p.v[i], p.x[i]);
            d.mass += m;
            for a in 0..3 {
                d.momentum[a] += m * v[a];
            }
            d.angular_momentum[0] += m * (x[1] * v[2] - x[2] * v[1]);
            d.angular_momentum[1] += m * (x[2] * v[0] - x[0] * v[2]);
            d.angular_momentum[2] += m * (x[0] * v[1] - x[1] * v[0]);
            if let Some(dm) = affine_moment {
                // B = C D, row-major; the field's spin about the point is m (B_kj - B_jk) e_i.
                let c = &p.affine[i];
                let b = |r: usize, col: usize| c[3 * r + col] * dm[col];
                d.angular_momentum[0] += m * (b(2, 1) - b(1, 2));
                d.angular_momentum[1] += m * (b(0, 2) - b(2, 0));
                d.angular_momentum[2] += m * (b(1, 0) - b(0, 1));
            }
            d.kinetic_energy += 0.5 * m * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
            d.elastic_energy += 0.5 * p.volume[i] * stress_strain_work(&p.stress[i], &p.strain[i]);
            d.gravitational_energy -= m * (g[0] * x[0] + g[1] * x[1] + g[2] * x[2]);
            d.max_height = d.max_height.max(x[up]);
            d.max_x = d.max_x.max(x[0]);
            d.max_deviatoric_strain = d.max_deviatoric_strain.max(deviatoric_strain_norm(&p.strain[i]));
        }
        d
    }

    /// The x below which `fraction` of the mass lies, from the mesh origin: a body front that
    /// isolated points thrown ahead do not move (eq. 5.6's voxelised width follows the farthest).
    pub fn mass_front(&self, fraction: f64) -> f64 {
        let p = &self.points;
        let mut order: Vec<usize> = (0..p.len()).collect();
        order.sort_by(|&a, &b| p.x[a][0].total_cmp(&p.x[b][0]));
        let total: f64 = p.mass.iter().sum();
        let mut below = 0.0;
        for &i in &order {
            below += p.mass[i];
            if below >= fraction * total {
                return p.x[i][0] - self.mesh.origin[0];
            }
        }
        order.last().map_or(0.0, |&i| p.x[i][0] - self.mesh.origin[0])
    }

    /// Width of the material measured from the mesh origin, voxelised by cells (eq. 5.6).
    pub fn voxel_width(&self) -> f64 {
        let h = self.mesh.cell[0];
        let max_x = self.points.x.iter().map(|x| x[0]).fold(f64::NEG_INFINITY, f64::max);
        if !max_x.is_finite() {
            return 0.0;
        }
        (((max_x - self.mesh.origin[0]) / h) + 1.0).floor() * h
    }
}
