//! Angle of repose measurement (thesis 2.3.2): outer-surface detection (2.4-2.6), linear and
//! quadratic regressions (2.7-2.8) and the standard deviation of the angle (2.9-2.11).
//!
//! The horizontal coordinate `x~` is measured from the open side of the container (the foot of
//! the heap) towards the heap's top, so the slope and the angle are positive; `y~` is the height.

use crate::error::{GraniteError, Result};
use crate::math::Vec3;

/// The container a heap was formed in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Heap {
    /// Plane strain: the surface is `max z` over cells of `x_range x y_range`; `open_x` is the
    /// x of the open side.
    PlaneStrain { x_range: [f64; 2], y_range: [f64; 2], open_x: f64 },
    /// Axisymmetric: the surface is `max r` over cells of angle and height in `z_range`, around
    /// the vertical axis through `centre`; `radius` is the container's.
    Axisymmetric { centre: [f64; 2], radius: f64, z_range: [f64; 2] },
}

#[derive(Debug, Clone, PartialEq)]
pub struct Repose {
    /// Eq. 2.7, degrees.
    pub angle_deg: f64,
    /// Eq. 2.11, degrees.
    pub std_deg: f64,
    /// Linear fit `y~ = a1 x~ + b1`.
    pub linear: [f64; 2],
    /// Quadratic fit `y~ = a2 x~^2 + b2 x~ + c2` (eq. 2.8 gives the local angle).
    pub quadratic: [f64; 3],
    /// Surface points `(x~, y~)` used in the fits.
    pub points: Vec<[f64; 2]>,
}

impl Repose {
    /// Local angle of the quadratic fit at `x~` (eq. 2.8), degrees.
    pub fn local_angle_deg(&self, x: f64) -> f64 {
        (2.0 * self.quadratic[0] * x + self.quadratic[1]).atan().to_degrees()
    }
}

/// Number of intervals over a length for grains of diameter `d` (eq. 2.4), at least one.
fn intervals(length: f64, d: f64) -> usize {
    ((length / d - 1.0).floor() as i64).max(1) as usize
}

/// Outer-surface points `(x~, y~)` of a heap of particles at `positions` with diameter `d`.
pub fn outer_surface(positions: &[Vec3], heap: &Heap, d: f64) -> Vec<[f64; 2]> {
    match *heap {
        Heap::PlaneStrain { x_range, y_range, open_x } => {
            let (nx, ny) = (intervals(x_range[1] - x_range[0], d), intervals(y_range[1] - y_range[0], d));
            let mut best: Vec<Option<Vec3>> = vec![None; nx * ny];
            for p in positions {
                let fx = (p[0] - x_range[0]) / (x_range[1] - x_range[0]);
                let fy = (p[1] - y_range[0]) / (y_range[1] - y_range[0]);
                if !(0.0..1.0).contains(&fx) || !(0.0..1.0).contains(&fy) {
                    continue;
                }
                let k = (fx * nx as f64) as usize + nx * (fy * ny as f64) as usize;
                if best[k].is_none_or(|b| p[2] > b[2]) {
                    best[k] = Some(*p);
                }
            }
            best.into_iter().flatten().map(|p| [(p[0] - open_x).abs(), p[2]]).collect()
        }
        Heap::Axisymmetric { centre, radius, z_range } => {
            let nt = intervals(2.0 * std::f64::consts::PI * radius, d);
            let nz = intervals(z_range[1] - z_range[0], d);
            let mut best: Vec<Option<(f64, f64)>> = vec![None; nt * nz];
            for p in positions {
                let (dx, dy) = (p[0] - centre[0], p[1] - centre[1]);
                let r = dx.hypot(dy);
                let theta = dy.atan2(dx).rem_euclid(2.0 * std::f64::consts::PI);
                let fz = (p[2] - z_range[0]) / (z_range[1] - z_range[0]);
                if !(0.0..1.0).contains(&fz) {
                    continue;
                }
                let kt = ((theta / (2.0 * std::f64::consts::PI)) * nt as f64) as usize % nt;
                let k = kt + nt * (fz * nz as f64) as usize;
                if best[k].is_none_or(|b| r > b.0) {
                    best[k] = Some((r, p[2]));
                }
            }
            best.into_iter().flatten().map(|(r, z)| [radius - r, z]).collect()
        }
    }
}

/// Angle of repose of a heap from its particle positions, fitted on `x~` in `[x_min, x_max]`.
pub fn measure(positions: &[Vec3], heap: &Heap, d: f64, x_min: f64, x_max: f64) -> Result<Repose> {
    let points: Vec<[f64; 2]> =
        outer_surface(positions, heap, d).into_iter().filter(|p| p[0] >= x_min && p[0] <= x_max).collect();
    let n = points.len();
    if n < 5 {
        return Err(GraniteError::Setup(format!(
            "only {n} outer-surface points in [{x_min}, {x_max}]: too few to fit a slope (check the heap geometry)"
        )));
    }
    let nf = n as f64;
    let mx = points.iter().map(|p| p[0]).sum::<f64>() / nf;
    let my = points.iter().map(|p| p[1]).sum::<f64>() / nf;
    let sxx: f64 = points.iter().map(|p| (p[0] - mx).powi(2)).sum();
    let sxy: f64 = points.iter().map(|p| (p[0] - mx) * (p[1] - my)).sum();
    if sxx <= 0.0 {
        return Err(GraniteError::Setup("all outer-surface points have the same x~: no slope".into()));
    }
    let a1 = sxy / sxx;
    let b1 = my - a1 * mx;
    let residual: f64 = points.iter().map(|p| (a1 * p[0] + b1 - p[1]).powi(2)).sum();
    let std_a1 = (residual / ((nf - 2.0).max(1.0) * sxx)).sqrt();
    // Quadratic least squares on centred x for conditioning.
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    let mut rhs = nalgebra::Vector3::<f64>::zeros();
    for p in &points {
        let x = p[0] - mx;
        let row = [x * x, x, 1.0];
        for i in 0..3 {
            rhs[i] += row[i] * p[1];
            for j in 0..3 {
                m[(i, j)] += row[i] * row[j];
            }
        }
    }
    let q = m.try_inverse().map(|inv| inv * rhs).unwrap_or_else(nalgebra::Vector3::zeros);
    // Back to uncentred x: a (x - mx)^2 + b (x - mx) + c.
    let quadratic = [q[0], q[1] - 2.0 * q[0] * mx, q[0] * mx * mx - q[1] * mx + q[2]];
    Ok(Repose {
        angle_deg: a1.atan().to_degrees(),
        std_deg: (std_a1 / (1.0 + a1 * a1)).to_degrees(),
        linear: [a1, b1],
        quadratic,
        points,
    })
}

/// Mobilised friction angle from the major and minor principal stresses (eq. 2.37), compression
/// positive magnitudes, degrees.
pub fn mobilised_friction_deg(sigma1: f64, sigma3: f64) -> f64 {
    ((sigma1 - sigma3) / (2.0 * (sigma1 * sigma3).sqrt())).atan().to_degrees()
}
