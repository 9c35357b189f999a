//! Material points as a structure of arrays. Points of one material are stored contiguously, in the
//! order materials were created, so a constitutive law updates a material as one slice.

use crate::math::{Mat3, Vec3, Voigt};

#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Points {
    /// Stable identity of each point (creation order), kept through deletions.
    pub id: Vec<u64>,
    pub material: Vec<u32>,
    pub mass: Vec<f64>,
    /// Volume (an area per unit thickness in 2D plane strain).
    pub volume: Vec<f64>,
    pub x: Vec<Vec3>,
    pub v: Vec<Vec3>,
    pub stress: Vec<Voigt>,
    /// Accumulated strain (eq. 3.38), engineering shear.
    pub strain: Vec<Voigt>,
    /// Strain increment of the last step (eq. 3.37).
    pub dstrain: Vec<Voigt>,
    /// APIC affine velocity matrix `C_p` (row-major), zero for other strategies.
    pub affine: Vec<Mat3>,
}

/// One point's initial data, used when points are created.
#[derive(Debug, Clone, Copy)]
pub struct NewPoint {
    pub x: Vec3,
    pub volume: f64,
    pub mass: f64,
    pub v: Vec3,
    pub stress: Voigt,
}

impl Points {
    pub fn len(&self) -> usize {
        self.x.len()
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Inserts points of `material` at `at` (the end of that material's block).
    pub fn insert(&mut self, at: usize, material: u32, first_id: u64, new: &[NewPoint]) {
        let n = new.len();
        splice(&mut self.id, at, (0..n as u64).map(|k| first_id + k));
        splice(&mut self.material, at, std::iter::repeat_n(material, n));
        splice(&mut self.mass, at, new.iter().map(|p| p.mass));
        splice(&mut self.volume, at, new.iter().map(|p| p.volume));
        splice(&mut self.x, at, new.iter().map(|p| p.x));
        splice(&mut self.v, at, new.iter().map(|p| p.v));
        splice(&mut self.stress, at, new.iter().map(|p| p.stress));
        splice(&mut self.strain, at, std::iter::repeat_n([0.0; 6], n));
        splice(&mut self.dstrain, at, std::iter::repeat_n([0.0; 6], n));
        splice(&mut self.affine, at, std::iter::repeat_n([0.0; 9], n));
    }

    /// Keeps the points whose flag is true, in order.
    pub fn retain(&mut self, keep: &[bool]) {
        retain_by(&mut self.id, keep);
        retain_by(&mut self.material, keep);
        retain_by(&mut self.mass, keep);
        retain_by(&mut self.volume, keep);
        retain_by(&mut self.x, keep);
        retain_by(&mut self.v, keep);
        retain_by(&mut self.stress, keep);
        retain_by(&mut self.strain, keep);
        retain_by(&mut self.dstrain, keep);
        retain_by(&mut self.affine, keep);
    }
}

fn splice<T>(v: &mut Vec<T>, at: usize, items: impl Iterator<Item = T>) {
    v.splice(at..at, items);
}

/// Order-preserving compaction of `v` by a keep-mask (also used for per-point state blocks).
pub fn retain_by<T>(v: &mut Vec<T>, keep: &[bool]) {
    let mut k = keep.iter();
    v.retain(|_| *k.next().unwrap_or(&true));
}

/// Order-preserving compaction of a point-major block with `stride` values per point.
pub fn retain_strided(v: &mut Vec<f64>, stride: usize, keep: &[bool]) {
    if stride == 0 {
        return;
    }
    let mut write = 0;
    for (p, &k) in keep.iter().enumerate() {
        if k {
            v.copy_within(p * stride..(p + 1) * stride, write * stride);
            write += 1;
        }
    }
    v.truncate(write * stride);
}
