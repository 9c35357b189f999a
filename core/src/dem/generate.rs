//! Initial packings: random loose clouds and jittered lattices, reproducible from a seed.

use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Particle-size distribution.
#[derive(Debug, Clone, PartialEq)]
pub enum Psd {
    /// Radii uniform in number between `min` and `max`.
    Uniform { min: f64, max: f64 },
    /// Cumulative passing fractions **by mass** at the given diameters (geotechnical grading
    /// curve), increasing from 0 to 1; sampled in number so the mass grading is honoured.
    Table { diameters: Vec<f64>, passing: Vec<f64> },
}

impl Psd {
    pub fn validate(&self) -> Result<()> {
        match self {
            Psd::Uniform { min, max } => {
                if !(*min > 0.0 && max >= min) {
                    return Err(GraniteError::param("radius", format!("[{min}, {max}]"), "needs 0 < min <= max"));
                }
            }
            Psd::Table { diameters, passing } => {
                let ok = diameters.len() >= 2
                    && diameters.len() == passing.len()
                    && diameters.windows(2).all(|w| w[1] > w[0])
                    && passing.windows(2).all(|w| w[1] >= w[0])
                    && diameters[0] > 0.0
                    && passing[0].abs() < 1e-12
                    && (passing[passing.len() - 1] - 1.0).abs() < 1e-12;
                if !ok {
                    return Err(GraniteError::param(
                        "psd",
                        format!("diameters {diameters:?}, passing {passing:?}"),
                        "needs increasing diameters > 0 and passing fractions rising from 0 to 1",
                    ));
                }
            }
        }
        Ok(())
    }

    pub fn max_radius(&self) -> f64 {
        match self {
            Psd::Uniform { max, .. } => *max,
            Psd::Table { diameters, .. } => 0.5 * diameters[diameters.len() - 1],
        }
    }

    /// One radius drawn from the distribution.
    pub fn sample(&self, rng: &mut ChaCha8Rng) -> f64 {
        match self {
            Psd::Uniform { min, max } => {
                if max > min {
                    rng.random_range(*min..*max)
                } else {
                    *min
                }
            }
            Psd::Table { diameters, passing } => loop {
                // Draw a diameter from the mass distribution, then keep it with probability
                // (d_min/d)^3: the number of grains of a size is its mass share over its mass.
                let u: f64 = rng.random();
                let k = passing.windows(2).position(|w| u <= w[1]).unwrap_or(passing.len() - 2);
                let span = passing[k + 1] - passing[k];
                let t = if span > 0.0 { (u - passing[k]) / span } else { 0.5 };
                let d = diameters[k] + t * (diameters[k + 1] - diameters[k]);
                let accept = (diameters[0] / d).powi(3);
                if rng.random::<f64>() < accept {
                    return 0.5 * d;
                }
            },
        }
    }
}

/// Non-overlapping spheres at random positions inside the box `[lo, hi]` (each sphere entirely
/// inside), avoiding `existing` spheres too. Fails with a clear error when the box is too full.
/// `interrupted` is asked every few thousand tries (a few milliseconds): a message from it (a
/// signal asking the run to stop) ends the call with that message.
pub fn cloud(
    lo: Vec3,
    hi: Vec3,
    count: usize,
    psd: &Psd,
    seed: u64,
    existing: &[(Vec3, f64)],
    interrupted: &dyn Fn() -> Option<String>,
) -> Result<Vec<(Vec3, f64)>> {
    psd.validate()?;
    crate::memory::check(
        "sim.cloud",
        count as f64,
        "spheres",
        crate::memory::BYTES_PER_SPHERE,
        "ask for fewer spheres",
    )?;
    let r_max = psd.max_radius();
    for a in 0..3 {
        if !(hi[a] - lo[a] > 2.0 * r_max) {
            return Err(GraniteError::param(
                "box",
                format!("{lo:?} - {hi:?}"),
                "must be wider than the largest diameter on every axis",
            ));
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let cell = 2.0 * r_max;
    let dims: Vec<usize> = (0..3).map(|a| (((hi[a] - lo[a]) / cell).ceil() as usize).max(1)).collect();
    let total = dims[0] * dims[1] * dims[2];
    if total > 50_000_000 {
        return Err(GraniteError::Setup("cloud box too large for its particle size".into()));
    }
    let mut grid: Vec<Vec<u32>> = vec![Vec::new(); total];
    let key = |x: &Vec3| -> [i64; 3] {
        [0, 1, 2].map(|a| (((x[a] - lo[a]) / cell).floor() as i64).clamp(0, dims[a] as i64 - 1))
    };
    let index = |c: [i64; 3]| (c[0] as usize) + dims[0] * ((c[1] as usize) + dims[1] * (c[2] as usize));
    let mut placed: Vec<(Vec3, f64)> = existing.to_vec();
    for (k, (x, _)) in placed.iter().enumerate() {
        grid[index(key(x))].push(k as u32);
    }
    let first_new = placed.len();
    let max_attempts = 1000 * count.max(1) + 10_000;
    let mut attempts = 0;
    while placed.len() - first_new < count {
        attempts += 1;
        if attempts % 4096 == 0 {
            if let Some(why) = interrupted() {
                return Err(GraniteError::Other(format!(
                    "{why} while placing spheres (sim.cloud: {} of {count} placed); nothing was added",
                    placed.len() - first_new
                )));
            }
        }
        if attempts > max_attempts {
            return Err(GraniteError::Setup(format!(
                "could place only {} of {count} non-overlapping spheres in the box: enlarge it or ask for fewer",
                placed.len() - first_new
            )));
        }
        let r = psd.sample(&mut rng);
        let x = [0, 1, 2].map(|a| rng.random_range(lo[a] + r..hi[a] - r));
        let c = key(&x);
        let mut free = true;
        'search: for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let q = [c[0] + dx, c[1] + dy, c[2] + dz];
                    if (0..3).any(|a| q[a] < 0 || q[a] >= dims[a] as i64) {
                        continue;
                    }
                    for &o in &grid[index(q)] {
                        let (y, ry) = placed[o as usize];
                        let d2: f64 = (0..3).map(|a| (x[a] - y[a]).powi(2)).sum();
                        if d2 < (r + ry) * (r + ry) {
                            free = false;
                            break 'search;
                        }
                    }
                }
            }
        }
        if free {
            grid[index(c)].push(placed.len() as u32);
            placed.push((x, r));
        }
    }
    Ok(placed.split_off(first_new))
}

/// Spheres of radius `radius` on a cubic lattice of spacing `spacing` filling `[lo, hi]`, each
/// moved by a random offset in `[-jitter, jitter]` per axis.
pub fn lattice(lo: Vec3, hi: Vec3, spacing: f64, radius: f64, jitter: f64, seed: u64) -> Result<Vec<(Vec3, f64)>> {
    if !(spacing > 0.0 && radius > 0.0 && jitter >= 0.0) {
        return Err(GraniteError::param("spacing", spacing, "spacing, radius must be > 0 and jitter >= 0"));
    }
    if 2.0 * (radius + jitter) > spacing {
        return Err(GraniteError::param(
            "spacing",
            spacing,
            "must exceed 2 (radius + jitter) so spheres do not overlap",
        ));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Sites per axis, counted in f64 first: a tiny spacing must be refused, not overflow.
    let sites: Vec<f64> =
        (0..3).map(|a| (((hi[a] - lo[a] - 2.0 * (radius + jitter)) / spacing).floor() + 1.0).max(0.0)).collect();
    crate::memory::check(
        "sim.lattice",
        sites[0] * sites[1] * sites[2],
        "spheres",
        crate::memory::BYTES_PER_SPHERE,
        "make the spacing larger or the box smaller",
    )?;
    let n: Vec<usize> = sites.iter().map(|&s| s as usize).collect();
    let mut out = Vec::with_capacity(n[0] * n[1] * n[2]);
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                let base = [i, j, k].map(|c| c as f64 * spacing);
                let x = [0, 1, 2].map(|a| {
                    let jit = if jitter > 0.0 { rng.random_range(-jitter..jitter) } else { 0.0 };
                    lo[a] + radius + jitter + base[a] + jit
                });
                out.push((x, radius));
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cloud_is_reproducible_and_overlap_free() {
        let psd = Psd::Uniform { min: 0.01, max: 0.02 };
        let a = cloud([0.0; 3], [0.5, 0.5, 0.5], 300, &psd, 7, &[], &|| None).unwrap();
        let b = cloud([0.0; 3], [0.5, 0.5, 0.5], 300, &psd, 7, &[], &|| None).unwrap();
        assert_eq!(a, b);
        for i in 0..a.len() {
            for j in i + 1..a.len() {
                let d: f64 = (0..3).map(|k| (a[i].0[k] - a[j].0[k]).powi(2)).sum::<f64>().sqrt();
                assert!(d >= a[i].1 + a[j].1);
            }
        }
    }

    #[test]
    fn table_psd_honours_mass_fractions() {
        // Half the mass below 2 mm, half between 2 and 4 mm (uniform within each bin).
        let psd = Psd::Table { diameters: vec![1e-3, 2e-3, 4e-3], passing: vec![0.0, 0.5, 1.0] };
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (mut small, mut total) = (0.0, 0.0);
        for _ in 0..200_000 {
            let r: f64 = psd.sample(&mut rng);
            let m = r.powi(3);
            total += m;
            if 2.0 * r <= 2e-3 {
                small += m;
            }
        }
        assert!((small / total - 0.5).abs() < 0.01, "mass fraction below 2 mm: {}", small / total);
    }
}
