//! Generation of material points cell by cell (thesis 3.4.1 and 5.2.1).

use crate::error::{GraniteError, Result};
use crate::math::Vec3;
use crate::mpm::mesh::Mesh;

/// Where points sit inside their cell, in local coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// Regularly spaced: local positions `-1 + (2k + 1)/n`.
    Regular,
    /// At the roots of the Legendre polynomial of degree n (eq. 5.4).
    Gauss,
}

impl Layout {
    pub fn parse(name: &str) -> Result<Layout> {
        match name {
            "regular" => Ok(Layout::Regular),
            "gauss" => Ok(Layout::Gauss),
            _ => Err(GraniteError::param("layout", name, "must be \"regular\" or \"gauss\"")),
        }
    }

    /// Local coordinates in [-1, 1] of `n` points along one direction.
    pub fn local_positions(&self, n: usize) -> Vec<f64> {
        match self {
            Layout::Regular => (0..n).map(|k| -1.0 + (2 * k + 1) as f64 / n as f64).collect(),
            Layout::Gauss => gauss_legendre_roots(n),
        }
    }
}

/// Roots of the Legendre polynomial P_n, ascending (Newton from Chebyshev guesses).
pub fn gauss_legendre_roots(n: usize) -> Vec<f64> {
    let mut roots: Vec<f64> = (0..n)
        .map(|i| {
            let mut x = -(std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            for _ in 0..100 {
                // P_n(x) and P_n'(x) by the three-term recurrence.
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                    p0 = p1;
                    p1 = p2;
                }
                let (pn, pn_1) = if n == 1 { (x, 1.0) } else { (p1, p0) };
                let dp = n as f64 * (x * pn - pn_1) / (x * x - 1.0);
                let dx = pn / dp;
                x -= dx;
                if dx.abs() < 1e-16 {
                    break;
                }
            }
            if n == 1 {
                0.0
            } else {
                x
            }
        })
        .collect();
    roots.sort_by(f64::total_cmp);
    roots
}

/// Points of every cell, `per_dir` per cell direction, kept where `inside` holds; each gets the
/// volume `cell volume / points per cell` (eq. 3.9).
pub fn cell_points(
    mesh: &Mesh,
    layout: Layout,
    per_dir: usize,
    mut inside: impl FnMut(Vec3) -> Result<bool>,
) -> Result<(Vec<Vec3>, Vec<f64>)> {
    if per_dir == 0 || per_dir > 20 {
        return Err(GraniteError::param("per_cell", per_dir, "points per cell direction must be in [1, 20]"));
    }
    let local = layout.local_positions(per_dir);
    let per_cell = per_dir.pow(mesh.dim as u32);

    let volume = mesh.cell_volume() / per_cell as f64;
    let (mut xs, mut vols) = (Vec::new(), Vec::new());
    let nz = if mesh.dim == 3 { per_dir } else { 1 };
    for c in 0..mesh.cell_count() as u32 {
        let ijk = mesh.cell_ijk(c);
        for kz in 0..nz {
            for ky in 0..per_dir {
                for kx in 0..per_dir {
                    let lx = [local[kx], local[ky], if mesh.dim == 3 { local[kz] } else { 0.0 }];
                    let mut x = [0.0; 3];
                    for a in 0..mesh.dim {
                        x[a] = mesh.origin[a] + mesh.cell[a] * (ijk[a] as f64 + 0.5 * (lx[a] + 1.0));
                    }
                    if inside(x)? {
                        if xs.len() == xs.capacity() {
                            // The arrays are about to double: would the points fit?
                            crate::memory::check(
                                "a fill",
                                2.0 * xs.len().max(1024) as f64,
                                "material points",
                                crate::memory::BYTES_PER_POINT,
                                "use fewer points per cell or a smaller region",
                            )?;
                        }
                        xs.push(x);
                        vols.push(volume);
                    }
                }
            }
        }
    }
    Ok((xs, vols))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_roots_match_eq_5_4_and_integrate_exactly() {
        let r = gauss_legendre_roots(2);
        assert!((r[1] - 1.0 / 3f64.sqrt()).abs() < 1e-15 && (r[0] + r[1]).abs() < 1e-15);
        // Degree-n Gauss rule with its weights integrates x^(2n-2) exactly; check the roots by the
        // defining property P_n(root) = 0 through sum of roots^2 for n = 3: roots 0, +-sqrt(3/5).
        let r3 = gauss_legendre_roots(3);
        assert!((r3[2] - (0.6f64).sqrt()).abs() < 1e-14 && r3[1].abs() < 1e-15);
        assert_eq!(gauss_legendre_roots(7).len(), 7);
    }
}
