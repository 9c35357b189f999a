//! Spheres as a structure of arrays.

use crate::math::Vec3;

/// Bit flags of blocked degrees of freedom (their velocity is kept as set).
pub mod dof {
    pub const X: u8 = 1;
    pub const Y: u8 = 2;
    pub const Z: u8 = 4;
    pub const RX: u8 = 8;
    pub const RY: u8 = 16;
    pub const RZ: u8 = 32;
    pub const ALL: u8 = 63;
}

#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Spheres {
    /// Stable identity (creation order), kept through deletions.
    pub id: Vec<u64>,
    pub x: Vec<Vec3>,
    pub v: Vec<Vec3>,
    /// Angular velocity.
    pub w: Vec<Vec3>,
    pub radius: Vec<f64>,
    pub mass: Vec<f64>,
    /// Moment of inertia of the sphere (2/5 m r^2).
    pub inertia: Vec<f64>,
    pub material: Vec<u16>,
    pub force: Vec<Vec3>,
    pub torque: Vec<Vec3>,
    /// Blocked degrees of freedom, see [`dof`].
    pub blocked: Vec<u8>,
    /// Index of the clump a sphere belongs to, or [`FREE`].
    pub clump: Vec<u32>,
}

/// Mass of a sphere of `radius` at `density`.
pub fn sphere_mass(density: f64, radius: f64) -> f64 {
    density * 4.0 / 3.0 * std::f64::consts::PI * radius.powi(3)
}

/// The index each kept item gets once those whose `keep` flag is false are removed (in order),
/// `u32::MAX` for the removed ones.
pub fn compacted_indices(keep: &[bool]) -> Vec<u32> {
    let mut new_index = vec![u32::MAX; keep.len()];
    let mut next = 0u32;
    for (i, &k) in keep.iter().enumerate() {
        if k {
            new_index[i] = next;
            next += 1;
        }
    }
    new_index
}

/// `clump` value of a sphere that belongs to no clump.
pub const FREE: u32 = u32::MAX;

impl Spheres {
    /// The index of the sphere with `id`.
    pub fn index_of(&self, id: u64) -> Option<usize> {
        // Before any reordering or erasure the id is the index.
        if (id as usize) < self.id.len() && self.id[id as usize] == id {
            return Some(id as usize);
        }
        self.id.iter().position(|&i| i == id)
    }

    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// The largest radius (0 without spheres).
    pub fn largest_radius(&self) -> f64 {
        self.radius.iter().cloned().fold(0.0, f64::max)
    }

    /// The smallest radius (infinite without spheres).
    pub fn smallest_radius(&self) -> f64 {
        self.radius.iter().cloned().fold(f64::INFINITY, f64::min)
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    pub fn push(&mut self, id: u64, x: Vec3, radius: f64, density: f64, material: u16, v: Vec3) {
        let mass = sphere_mass(density, radius);
        self.id.push(id);
        self.x.push(x);
        self.v.push(v);
        self.w.push([0.0; 3]);
        self.radius.push(radius);
        self.mass.push(mass);
        self.inertia.push(0.4 * mass * radius * radius);
        self.material.push(material);
        self.force.push([0.0; 3]);
        self.torque.push([0.0; 3]);
        self.blocked.push(0);
        self.clump.push(FREE);
    }

    /// Keeps the spheres whose flag is true, in order.
    pub fn retain(&mut self, keep: &[bool]) {
        use crate::mpm::points::retain_by;
        retain_by(&mut self.id, keep);
        retain_by(&mut self.x, keep);
        retain_by(&mut self.v, keep);
        retain_by(&mut self.w, keep);
        retain_by(&mut self.radius, keep);
        retain_by(&mut self.mass, keep);
        retain_by(&mut self.inertia, keep);
        retain_by(&mut self.material, keep);
        retain_by(&mut self.force, keep);
        retain_by(&mut self.torque, keep);
        retain_by(&mut self.blocked, keep);
        retain_by(&mut self.clump, keep);
    }

    /// Reorders the spheres: the `k`-th becomes the former `order[k]` (ids travel along).
    pub fn permute(&mut self, order: &[usize]) {
        fn pick<T: Copy>(v: &mut Vec<T>, order: &[usize]) {
            *v = order.iter().map(|&k| v[k]).collect();
        }
        pick(&mut self.id, order);
        pick(&mut self.x, order);
        pick(&mut self.v, order);
        pick(&mut self.w, order);
        pick(&mut self.radius, order);
        pick(&mut self.mass, order);
        pick(&mut self.inertia, order);
        pick(&mut self.material, order);
        pick(&mut self.force, order);
        pick(&mut self.torque, order);
        pick(&mut self.blocked, order);
        pick(&mut self.clump, order);
    }

    pub fn volume(&self) -> f64 {
        self.radius.iter().map(|r| 4.0 / 3.0 * std::f64::consts::PI * r * r * r).sum()
    }
}

/// A force and torque applied to one sphere at every step until changed (YADE's permanent
/// forces), on top of contacts and gravity.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExternalLoad {
    pub id: u64,
    pub force: Vec3,
    pub torque: Vec3,
    /// Where the sphere was last found: checked first, so that a step does not search the
    /// spheres for it once they are numbered in space (ids no longer their indices).
    #[serde(skip)]
    pub(crate) index: usize,
}

impl ExternalLoad {
    /// Index of the sphere the load acts on, from its remembered index when that still holds
    /// the sphere.
    pub(crate) fn index_in(&self, spheres: &Spheres) -> Option<usize> {
        match spheres.id.get(self.index) {
            Some(&id) if id == self.id => Some(self.index),
            _ => spheres.index_of(self.id),
        }
    }
}

/// The lasting external loads' stage. Reads the loads; writes the spheres' forces and torques of
/// this step, and where each load found its sphere.
pub(crate) struct ExternalLoads;

impl ExternalLoads {
    pub(crate) fn run(loads: &mut [ExternalLoad], spheres: &mut Spheres) {
        for load in loads {
            let Some(i) = load.index_in(spheres) else { continue };
            load.index = i;
            for a in 0..3 {
                spheres.force[i][a] += load.force[a];
                spheres.torque[i][a] += load.torque[a];
            }
        }
    }
}
