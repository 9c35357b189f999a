//! Clumps: rigid aggregates of possibly overlapping spheres (thesis 2.2.2.1). Mass, centre and
//! inertia come from a voxel integration of the union of the members, as YADE and PFC do (or from
//! exact sums when the members do not overlap); rotation is integrated with a quaternion.

use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use nalgebra::{Matrix3, SymmetricEigen, UnitQuaternion, Vector3};
use rayon::prelude::*;

/// Mass properties of a rigid body: mass, centre of mass and inertia tensor about it (world axes).
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub struct MassProperties {
    pub volume: f64,
    pub mass: f64,
    pub centroid: Vec3,
    pub inertia: Matrix3<f64>,
}

impl MassProperties {
    /// A body a step can move: positive finite mass and volume, finite centre and inertia. Radii
    /// near the ends of the f64 range give an infinite or zero volume; their inertia would leave
    /// the principal-axis search of [`Clumps::push`] without an answer.
    pub fn check(&self) -> Result<()> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !(positive(self.volume) && positive(self.mass))
            || self.centroid.iter().any(|c| !c.is_finite())
            || self.inertia.iter().any(|c| !c.is_finite())
        {
            return Err(GraniteError::Setup(format!(
                "a clump with volume {:e} m^3, mass {:e} kg, centre {:?} and inertia up to {:e} kg m^2: its size, \
                 spread or density is out of the range a step can move (volume and mass must be finite and > 0, \
                 centre and inertia finite)",
                self.volume,
                self.mass,
                self.centroid,
                // amax skips a NaN; the message should show it.
                if self.inertia.iter().any(|c| c.is_nan()) { f64::NAN } else { self.inertia.amax() }
            )));
        }
        Ok(())
    }

    /// The same body rotated by `q` (about the origin of its coordinates) then moved by `t`.
    pub fn transformed(&self, q: &UnitQuaternion<f64>, t: Vec3) -> MassProperties {
        let c = q * Vector3::new(self.centroid[0], self.centroid[1], self.centroid[2]);
        let r = q.to_rotation_matrix();
        MassProperties {
            centroid: [c[0] + t[0], c[1] + t[1], c[2] + t[2]],
            inertia: r.matrix() * self.inertia * r.matrix().transpose(),
            ..*self
        }
    }
}

fn overlapping(members: &[(Vec3, f64)]) -> bool {
    for i in 0..members.len() {
        for j in i + 1..members.len() {
            let d: f64 = (0..3).map(|a| (members[i].0[a] - members[j].0[a]).powi(2)).sum::<f64>().sqrt();
            if d < members[i].1 + members[j].1 {
                return true;
            }
        }
    }
    false
}

/// Mass properties of the union of spheres at uniform `density`. Disjoint members are summed
/// exactly; overlapping ones are integrated on a grid of `resolution`^3 voxels spanning the
/// bounding box (each voxel counted once if its centre is in any member).
pub fn mass_properties(members: &[(Vec3, f64)], density: f64, resolution: usize) -> Result<MassProperties> {
    if members.is_empty() {
        return Err(GraniteError::Setup("a clump needs at least one sphere".into()));
    }
    for (k, (x, r)) in members.iter().enumerate() {
        if !(r.is_finite() && *r > 0.0) || x.iter().any(|c| !c.is_finite()) {
            return Err(GraniteError::param(
                &format!("clump member {k}"),
                format!("{x:?}, radius {r}"),
                "needs a finite centre and a finite radius > 0",
            ));
        }
    }
    let props = if overlapping(members) {
        voxel_integration(members, density, resolution)
    } else {
        exact_sums(members, density)
    };
    props.check()?;
    Ok(props)
}

/// Mass properties of spheres that do not overlap: each sphere's own, moved to the common centre.
fn exact_sums(members: &[(Vec3, f64)], density: f64) -> MassProperties {
    let mut volume = 0.0;
    let mut first = [0.0; 3];
    for (x, r) in members {
        let v = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        volume += v;
        for a in 0..3 {
            first[a] += v * x[a];
        }
    }
    let c = first.map(|f| f / volume);
    let mut inertia = Matrix3::zeros();
    for (x, r) in members {
        let v = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        let m = density * v;
        let d = Vector3::new(x[0] - c[0], x[1] - c[1], x[2] - c[2]);
        inertia += Matrix3::identity() * (0.4 * m * r * r) + (Matrix3::identity() * d.dot(&d) - d * d.transpose()) * m;
    }
    MassProperties { volume, mass: density * volume, centroid: c, inertia }
}

/// Mass properties of the union of overlapping spheres on a grid of `resolution`^3 voxels.
fn voxel_integration(members: &[(Vec3, f64)], density: f64, resolution: usize) -> MassProperties {
    let n = resolution.clamp(16, 2048);
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for (x, r) in members {
        for a in 0..3 {
            lo[a] = lo[a].min(x[a] - r);
            hi[a] = hi[a].max(x[a] + r);
        }
    }
    let h = [0, 1, 2].map(|a| (hi[a] - lo[a]) / n as f64);
    let dv = h[0] * h[1] * h[2];
    // Per z-slab sums of the zeroth, first and second moments, added in slab order.
    let slabs: Vec<[f64; 10]> = (0..n)
        .into_par_iter()
        .map(|k| {
            let mut s = [0.0; 10];
            let z = lo[2] + (k as f64 + 0.5) * h[2];
            for j in 0..n {
                let y = lo[1] + (j as f64 + 0.5) * h[1];
                for i in 0..n {
                    let x = lo[0] + (i as f64 + 0.5) * h[0];
                    let inside = members
                        .iter()
                        .any(|(c, r)| (x - c[0]).powi(2) + (y - c[1]).powi(2) + (z - c[2]).powi(2) <= r * r);
                    if inside {
                        s[0] += 1.0;
                        s[1] += x;
                        s[2] += y;
                        s[3] += z;
                        s[4] += x * x;
                        s[5] += y * y;
                        s[6] += z * z;
                        s[7] += x * y;
                        s[8] += y * z;
                        s[9] += x * z;
                    }
                }
            }
            s
        })
        .collect();
    let mut s = [0.0; 10];
    for slab in &slabs {
        for q in 0..10 {
            s[q] += slab[q];
        }
    }
    let volume = s[0] * dv;
    let c = [s[1] / s[0], s[2] / s[0], s[3] / s[0]];
    // Second moments about the centroid; a voxel's own inertia (h^2/12 per axis) is added too.
    let m_vox = density * dv;
    let cov = |p: usize, q: usize, sq: f64, cp: f64, cq: f64| {
        sq - s[0] * cp * cq + if p == q { s[0] * h[p] * h[p] / 12.0 } else { 0.0 }
    };
    let xx = cov(0, 0, s[4], c[0], c[0]);
    let yy = cov(1, 1, s[5], c[1], c[1]);
    let zz = cov(2, 2, s[6], c[2], c[2]);
    let xy = cov(0, 1, s[7], c[0], c[1]);
    let yz = cov(1, 2, s[8], c[1], c[2]);
    let xz = cov(0, 2, s[9], c[0], c[2]);
    let inertia = Matrix3::new(yy + zz, -xy, -xz, -xy, xx + zz, -yz, -xz, -yz, xx + yy) * m_vox;
    MassProperties { volume, mass: density * volume, centroid: c, inertia }
}

/// Clumps as a structure of arrays. Member spheres live in [`crate::dem::Spheres`] with their
/// `clump` index; their positions and velocities follow the clump after every step.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Clumps {
    pub x: Vec<Vec3>,
    pub v: Vec<Vec3>,
    /// Angular velocity (world frame).
    pub w: Vec<Vec3>,
    /// Orientation: body (principal) frame to world.
    pub q: Vec<UnitQuaternion<f64>>,
    pub mass: Vec<f64>,
    /// Principal moments of inertia (body frame).
    pub inertia: Vec<Vec3>,
    pub volume: Vec<f64>,
    /// Members: sphere indices `members[start[c]..start[c + 1]]` and their body-frame offsets.
    pub start: Vec<u32>,
    pub members: Vec<u32>,
    pub local: Vec<Vec3>,
    pub force: Vec<Vec3>,
    pub torque: Vec<Vec3>,
}

impl Clumps {
    pub fn len(&self) -> usize {
        self.x.len()
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    pub fn members_of(&self, c: usize) -> std::ops::Range<usize> {
        self.start[c] as usize..self.start[c + 1] as usize
    }

    /// Registers a clump of the given member spheres (already added) with its mass properties;
    /// the body frame is the principal frame of the inertia tensor.
    pub fn push(&mut self, member_ids: &[u32], positions: &[Vec3], props: &MassProperties) {
        if self.start.is_empty() {
            self.start.push(0);
        }
        let eig = SymmetricEigen::new(props.inertia);
        let mut rot = eig.eigenvectors;
        if rot.determinant() < 0.0 {
            rot.set_column(2, &(-rot.column(2)));
        }
        let q = UnitQuaternion::from_matrix(&rot);
        let c = Vector3::new(props.centroid[0], props.centroid[1], props.centroid[2]);
        for (&m, x) in member_ids.iter().zip(positions) {
            let local = q.inverse() * (Vector3::new(x[0], x[1], x[2]) - c);
            self.members.push(m);
            self.local.push([local[0], local[1], local[2]]);
        }
        self.start.push(self.members.len() as u32);
        self.x.push(props.centroid);
        self.v.push([0.0; 3]);
        self.w.push([0.0; 3]);
        self.q.push(q);
        self.mass.push(props.mass);
        self.inertia.push([eig.eigenvalues[0], eig.eigenvalues[1], eig.eigenvalues[2]]);
        self.volume.push(props.volume);
        self.force.push([0.0; 3]);
        self.torque.push([0.0; 3]);
    }
}

/// The 4-sphere tetrahedral clump of the JGS round robin (thesis 2.2.1, table 2.3): members of
/// radius `r_sphere` at the vertices of a regular tetrahedron, the whole inscribed in a sphere of
/// radius `r_clump`. Returns member centres around `centre` (one orientation).
pub fn tetrahedral_members(centre: Vec3, r_sphere: f64, r_clump: f64) -> Result<Vec<(Vec3, f64)>> {
    if !(r_sphere > 0.0 && r_clump > r_sphere) {
        return Err(GraniteError::param("r_clump", r_clump, "needs r_clump > r_sphere > 0"));
    }
    let d = r_clump - r_sphere;
    let s = d / 3f64.sqrt();
    let verts = [[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]];
    Ok(verts.iter().map(|v| ([centre[0] + s * v[0], centre[1] + s * v[1], centre[2] + s * v[2]], r_sphere)).collect())
}

/// Rotates template members (offsets from the template centre) by a uniformly random orientation
/// drawn from `u` (three numbers in [0, 1)), and places them around `centre`. Returns the members
/// and the rotation.
pub fn place_template(template: &[(Vec3, f64)], centre: Vec3, u: [f64; 3]) -> (Vec<(Vec3, f64)>, UnitQuaternion<f64>) {
    // Shoemake's uniform random unit quaternion.
    let (a, b) = ((1.0 - u[0]).sqrt(), u[0].sqrt());
    let (t1, t2) = (2.0 * std::f64::consts::PI * u[1], 2.0 * std::f64::consts::PI * u[2]);
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
        b * t2.cos(),
        a * t1.sin(),
        a * t1.cos(),
        b * t2.sin(),
    ));
    let members = template
        .iter()
        .map(|(x, r)| {
            let p = q * Vector3::new(x[0], x[1], x[2]);
            ([centre[0] + p[0], centre[1] + p[1], centre[2] + p[2]], *r)
        })
        .collect();
    (members, q)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disjoint_members_sum_exactly() {
        let members = [([0.0, 0.0, 0.0], 1.0), ([3.0, 0.0, 0.0], 1.0)];
        let p = mass_properties(&members, 1.0, 64).unwrap();
        let v = 4.0 / 3.0 * std::f64::consts::PI;
        assert!((p.volume - 2.0 * v).abs() < 1e-12);
        assert!((p.centroid[0] - 1.5).abs() < 1e-12);
        // About x: two spheres 0.4 m r^2 each; about y: plus m d^2 with d = 1.5.
        assert!((p.inertia[(0, 0)] - 2.0 * 0.4 * v).abs() < 1e-12);
        assert!((p.inertia[(1, 1)] - (2.0 * 0.4 * v + 2.0 * v * 2.25)).abs() < 1e-12);
    }

    #[test]
    fn voxels_recover_a_single_sphere() {
        // Two coincident spheres overlap fully: the union is one sphere.
        let members = [([0.0, 0.0, 0.0], 1.0), ([0.0, 0.0, 0.0], 1.0)];
        let p = mass_properties(&members, 1.0, 200).unwrap();
        let v = 4.0 / 3.0 * std::f64::consts::PI;
        assert!((p.volume - v).abs() < 2e-3 * v, "{}", p.volume);
        assert!((p.inertia[(2, 2)] - 0.4 * v).abs() < 3e-3 * 0.4 * v);
    }
}

#[cfg(test)]
mod table_2_3 {
    use super::*;

    /// Thesis table 2.3: the tetrahedral clump (r_s = 0.3101 cm, r_clump = 0.5 cm) has volume
    /// 3.3304e-7 m^3 and an isotropic inertia/rho of 2.584e-12 m^5.
    #[test]
    fn tetrahedral_clump_matches_the_published_mass_properties() {
        let members = tetrahedral_members([0.0; 3], 0.3101e-2, 0.5e-2).unwrap();
        let p = mass_properties(&members, 1.0, 400).unwrap();
        assert!((p.volume - 3.3304e-7).abs() < 0.005 * 3.3304e-7, "volume {}", p.volume);
        for a in 0..3 {
            assert!((p.inertia[(a, a)] - 2.584e-12).abs() < 0.005 * 2.584e-12, "I[{a}] = {}", p.inertia[(a, a)]);
        }
        // The sum of the members (the "non-uniform density" column) is 50 % too heavy.
        let sum = 4.0 * 4.0 / 3.0 * std::f64::consts::PI * 0.3101e-2f64.powi(3);
        assert!((sum - 4.9965e-7).abs() < 0.001 * 4.9965e-7);
    }
}
