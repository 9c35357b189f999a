//! Element tests: one material point driven along a prescribed strain path, or a mixed path
//! where some stress components are held (a triaxial test holds the lateral stresses while the
//! axial strain is prescribed), without a mesh. What CB-Geo and YADE users run to check a law
//! before using it.
//!
//! Components are in Voigt order `xx, yy, zz, xy, yz, xz`; stresses are tension positive, shear
//! strains are engineering strains (as the law receives them in a simulation).

use crate::error::{GraniteError, Result};
use crate::ext::constitutive::{ConstitutiveLaw, LawBatch};
use crate::math::Voigt;

/// The path of an element test.
#[derive(Debug, Clone)]
pub struct Path {
    /// Stress at the start, tension positive.
    pub initial_stress: Voigt,
    /// Strain increment over the whole path of each strain-controlled component (applied in
    /// equal parts over the steps); ignored for held components.
    pub strain: Voigt,
    /// Components held at a stress (`Some(target)`): their strain increments are solved for at
    /// each step so that the stress stays at the target.
    pub hold: [Option<f64>; 6],
    pub steps: usize,
}

/// Stress, strain and state after each step (the initial values first).
#[derive(Debug, Clone, Default)]
pub struct Record {
    pub stress: Vec<Voigt>,
    pub strain: Vec<Voigt>,
    /// One row of state variables per record, in the law's `state_names` order.
    pub state: Vec<Vec<f64>>,
}

/// Newton iterations allowed per step for the held components.
const MAX_ITERATIONS: usize = 50;

/// One update of the law from `(stress, state)` by `dstrain`: the new stress and state.
fn update(law: &dyn ConstitutiveLaw, stress: &Voigt, state: &[f64], dstrain: &Voigt) -> Result<(Voigt, Vec<f64>)> {
    let mut s = [*stress];
    let mut st = state.to_vec();
    law.update(LawBatch { first: 0, stress: &mut s, dstrain: std::slice::from_ref(dstrain), state: &mut st })?;
    Ok((s[0], st))
}

/// Solves the linear system `a x = b` (n <= 6) by Gaussian elimination with partial pivoting;
/// None when it is singular.
fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    for col in 0..n {
        let pivot = (col..n).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if !(a[pivot][col].abs() > 0.0) {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        for row in col + 1..n {
            let f = a[row][col] / a[col][col];
            for k in col..n {
                a[row][k] -= f * a[col][k];
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = vec![0.0; n];
    for row in (0..n).rev() {
        let s: f64 = (row + 1..n).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    Some(x)
}

/// The Newton correction `dx` of `J dx = -r`, as Levenberg-Marquardt damps it:
/// `(J^T J + mu I) dx = -J^T r` with `mu` a 1e-10 share of `J^T J`'s diagonal. On a yield
/// surface's edge the held components may leave a direction free (a triaxial test at failure
/// takes any split of the lateral plastic strains): `J` is then singular, and this gives the
/// smallest change in that direction instead of none.
fn least_change(j: &[Vec<f64>], r: &[f64]) -> Option<Vec<f64>> {
    let n = r.len();
    let mut jtj = vec![vec![0.0; n]; n];
    let mut rhs = vec![0.0; n];
    for a in 0..n {
        for b in 0..n {
            jtj[a][b] = (0..n).map(|k| j[k][a] * j[k][b]).sum();
        }
        rhs[a] = -(0..n).map(|k| j[k][a] * r[k]).sum::<f64>();
    }
    let mu = 1e-10 * (0..n).map(|a| jtj[a][a]).sum::<f64>() / n as f64;
    for (a, row) in jtj.iter_mut().enumerate() {
        row[a] += mu;
    }
    solve(jtj, rhs)
}

/// Drives `law` (a fresh law, its per-point objects made for one point) along `path`.
pub fn run(law: &dyn ConstitutiveLaw, path: &Path) -> Result<Record> {
    let held: Vec<usize> = (0..6).filter(|&c| path.hold[c].is_some()).collect();
    if !held.is_empty() && law.point_objects().is_some() {
        return Err(GraniteError::Setup(format!(
            "law \"{}\" keeps an object per point (a DEM sample): its element test follows a strain path \
             only (no `hold`), since the trial increments of a mixed path cannot be undone on it",
            law.name()
        )));
    }
    if path.steps == 0 {
        return Err(GraniteError::param("steps", 0, "must be >= 1"));
    }
    let mut state = vec![0.0; law.state_names().len()];
    law.init_state(&mut state);
    let mut stress = path.initial_stress;
    let mut strain = [0.0; 6];
    let mut record = Record { stress: vec![stress], strain: vec![strain], state: vec![state.clone()] };
    let step_strain = path.strain.map(|e| e / path.steps as f64);
    // Unknown increments of the held components: the last step's are the first guess.
    let mut guess = vec![0.0; held.len()];
    let scale = step_strain.iter().fold(0.0f64, |m, e| m.max(e.abs())).max(1e-12);
    for step in 0..path.steps {
        let increment = |x: &[f64]| {
            let mut d = step_strain;
            for (k, &c) in held.iter().enumerate() {
                d[c] = x[k];
            }
            d
        };
        let residual = |s: &Voigt| -> Vec<f64> { held.iter().map(|&c| s[c] - path.hold[c].unwrap_or(0.0)).collect() };
        let mut x = guess.clone();
        let (mut next_stress, mut next_state) = update(law, &stress, &state, &increment(&x))?;
        if !held.is_empty() {
            let size = stress.iter().chain(path.hold.iter().flatten()).fold(1.0f64, |m, s| m.max(s.abs()));
            // Laws return to their yield surfaces to about 1e-8 of the stress.
            let tolerance = 1e-7 * size;
            let mut converged = false;
            for _ in 0..MAX_ITERATIONS {
                let r = residual(&next_stress);
                if r.iter().all(|v| v.abs() <= tolerance) {
                    converged = true;
                    break;
                }
                // Jacobian of the held stresses by forward differences.
                // Large enough that the change stands well above the laws' own rounding (returns
                // to a yield surface are exact to about 1e-8 of the stress).
                let h = 1e-3 * scale;
                let mut jacobian = vec![vec![0.0; held.len()]; held.len()];
                for j in 0..held.len() {
                    let mut xp = x.clone();
                    xp[j] += h;
                    let (sp, _) = update(law, &stress, &state, &increment(&xp))?;
                    let rp = residual(&sp);
                    for i in 0..held.len() {
                        jacobian[i][j] = (rp[i] - r[i]) / h;
                    }
                }
                let Some(dx) = least_change(&jacobian, &r) else { break };
                // Backtracking: a full Newton step can cross a corner of a yield surface into a
                // flat region (the apex, where the stress no longer depends on the strain); the
                // step is halved until the residual decreases.
                let norm = |r: &[f64]| r.iter().map(|v| v * v).sum::<f64>();
                let mut fraction = 1.0;
                loop {
                    let trial: Vec<f64> = x.iter().zip(&dx).map(|(xi, di)| xi + fraction * di).collect();
                    let (ts, tst) = update(law, &stress, &state, &increment(&trial))?;
                    if norm(&residual(&ts)) < norm(&r) || fraction < 1e-6 {
                        (x, next_stress, next_state) = (trial, ts, tst);
                        break;
                    }
                    fraction *= 0.5;
                }
            }
            if !converged {
                return Err(GraniteError::Other(format!(
                    "element test of \"{}\": the held stresses could not be kept at step {} (residual {:?} Pa): \
                     the law may have lost its strength under this path; a smaller strain per step may help",
                    law.name(),
                    step + 1,
                    residual(&next_stress)
                )));
            }
            guess = x.clone();
        }
        let d = increment(&x);
        for c in 0..6 {
            strain[c] += d[c];
        }
        stress = next_stress;
        state = next_state;
        if stress.iter().any(|s| !s.is_finite()) {
            return Err(GraniteError::Unstable {
                step: step as u64 + 1,
                time: 0.0,
                reason: format!("element test of \"{}\": the stress is no longer finite ({stress:?})", law.name()),
            });
        }
        record.stress.push(stress);
        record.strain.push(strain);
        record.state.push(state.clone());
    }
    Ok(record)
}

#[cfg(test)]
mod tests {
    use super::solve;

    #[test]
    fn small_systems_are_solved() {
        let x = solve(vec![vec![2.0, 1.0], vec![1.0, 3.0]], vec![3.0, 5.0]).unwrap();
        assert!((x[0] - 0.8).abs() < 1e-12 && (x[1] - 1.4).abs() < 1e-12);
        assert!(solve(vec![vec![1.0, 2.0], vec![2.0, 4.0]], vec![1.0, 2.0]).is_none());
    }
}
