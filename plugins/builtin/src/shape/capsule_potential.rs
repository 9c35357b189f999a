//! Capsules meeting potential particles: the geometry of a pair of two families, `capsule` and
//! `potential`, registered as `capsule_potential`.
//!
//! A capsule is the union of the spheres of its radius `r` centred on its segment,
//! `c(t) = e0 + t (e1 - e0)` for `t` in `[0, 1]`. It meets a potential particle as the one of those
//! spheres that meets the particle most. The particles' own contact problem between the particle
//! and the sphere at `c(t)`, `g(t) = min_x max(f_P(x), |x - c(t)|^2 / r^2 - 1)`
//! (`potential::contact`), is convex in `t`: the maximum of two functions jointly convex in `x` and
//! `t`, minimised over `x`. By the envelope theorem its slope is
//! `g'(t) = -2 (1 - lambda) (x* - c(t)) . (e1 - e0) / r^2`, with `x*` the problem's solution and
//! `lambda` its multiplier, so the sign of `(x* - c(t)) . (e1 - e0)` tells on which side of `t` the
//! least value lies. The search starts from the last step's `t`, steps outwards until that sign
//! turns, and closes the bracket by regula falsi on the slope (Illinois' variant) to 1e-7 of the
//! radius along the segment; against a sphere the slope is linear in `t` and one step lands on the
//! answer. Each solve starts from the previous one's solution; a contact takes about five. The
//! contact is the sphere's at the `t` found: normal, overlap and point as between a potential
//! particle and a sphere (thesis 2.2.3), the normal turned to point from the capsule to the
//! particle.

use super::capsule::{along, dot, nearest_on, segment, sub};
use super::potential::contact::{detect_settled, Detection, Placed, Pose, Solution};
use super::potential::{solve_pairs, PotentialBody, FAMILY};
use granite_core::ext::body::{BodyPairGeometry, KindBodies, PairFailure, Touch, WarmStarts};
use granite_core::math::{add3, sub3, Vec3};

pub struct CapsulePotential;

/// Warm values a pair keeps: `t` and whether it is set, then the particle–sphere solution (point,
/// multiplier, whether it is set, the overlap's two parts).
const WARM: usize = 9;

/// How finely `t` is found: this fraction of the capsule's radius along its segment (the overlap
/// errs by about its square).
const T_TOLERANCE: f64 = 1e-7;

/// Most steps of the search within its bracket (it ends in a handful).
const MAX_STEPS: usize = 60;

impl BodyPairGeometry for CapsulePotential {
    fn families(&self) -> [&str; 2] {
        ["capsule", FAMILY]
    }

    fn description(&self) -> &str {
        "a capsule meets a potential particle as the sphere of its axis that meets it most (a 1-D convex search)"
    }

    fn warm_values(&self) -> usize {
        WARM
    }

    fn pairs(
        &self,
        capsules: KindBodies<'_>,
        particles: KindBodies<'_>,
        pairs: &[(u32, u32)],
        warm: WarmStarts<'_>,
        out: &mut [Option<Touch>],
    ) -> std::result::Result<(), PairFailure> {
        solve_pairs(pairs, warm, out, |&(i, j), w| {
            let (i, j) = (i as usize, j as usize);
            let shape = PotentialBody::shape_of(particles.shape_of(j))
                .ok_or_else(|| format!("a {} shape among potential particles", particles.shape_of(j).kind()))?;
            let pose = Pose { position: particles.x[j], rotation: *particles.q[j].to_rotation_matrix().matrix() };
            let touch = meet(&Placed::new(shape, &pose), segment(&capsules, i), w)?;
            Ok(touch.map(|t| Touch { normal: t.normal.map(|c| -c), ..t }))
        })
    }
}

/// The touch of particle `p` and the capsule of segment `[e0, e1]` and radius `r` (normal from the
/// particle to the capsule), from the warm start in `w`.
fn meet(p: &Placed, (e0, e1, r): (Vec3, Vec3, f64), w: &mut [f64]) -> Result<Option<Touch>, String> {
    let d = sub(e1, e0);
    let length = dot(d, d).sqrt();
    // Apart by their bounding shapes: no solve (the warm start waits for the next touch).
    let near = sub(nearest_on(e0, e1, p.position), p.position);
    let middle = along(e0, d, 0.5);
    if dot(near, near) > (p.bounding_radius + r).powi(2) || p.clear_of(middle, 0.5 * length + r) {
        return Ok(None);
    }
    // The kept point is relative to the particle's centre: a pair moved whole (wrapped across a
    // periodic cell) starts where it left off.
    let mut start = (w[6] == 1.0).then(|| Solution {
        point: add3(p.position, [w[2], w[3], w[4]]),
        lambda: w[5],
        depths: [w[7], w[8]],
    });
    let mut at = |t: f64| -> Result<(f64, Detection), String> {
        let c = along(e0, d, t);
        let found = detect_settled(p, &Placed::sphere(c, r), start).map_err(|e| e.to_string())?;
        start = Some(found.solution);
        Ok((dot(sub(found.solution.point, c), d), found))
    };
    let t0 = if w[1] == 1.0 {
        w[0]
    } else if length > 0.0 {
        (dot(sub(p.position, e0), d) / (length * length)).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (slope0, mut found) = at(t0)?;
    let mut t = t0;
    if slope0 != 0.0 && length > 0.0 {
        // Outwards from t0 towards the least value until the slope turns or the segment ends.
        let ahead = slope0 > 0.0;
        let (mut near, mut near_slope, mut step) = (t0, slope0, 1e-3);
        let mut far_end = None;
        loop {
            let next = if ahead { (near + step).min(1.0) } else { (near - step).max(0.0) };
            let (slope, at_next) = at(next)?;
            if (slope > 0.0) != ahead || slope == 0.0 {
                far_end = Some((next, slope, at_next));
                break;
            }
            (near, near_slope, found, t) = (next, slope, at_next, next);
            if next == 0.0 || next == 1.0 {
                break;
            }
            step *= 4.0;
        }
        if let Some((mut far, mut far_slope, at_far)) = far_end {
            (found, t) = (at_far, far);
            // Regula falsi on the slope, Illinois' way: the end kept twice in a row has its slope
            // halved, so both ends close in (the slope is smooth: linear in t against a sphere).
            let tolerance = T_TOLERANCE * r / length;
            let mut kept = 0;
            for _ in 0..MAX_STEPS {
                if far_slope == 0.0 || (far - near).abs() <= tolerance {
                    break;
                }
                let next = (near * far_slope - far * near_slope) / (far_slope - near_slope);
                let next = if next.is_finite() { next.clamp(near.min(far), near.max(far)) } else { 0.5 * (near + far) };
                let (slope, at_next) = at(next)?;
                let moved = (next - t).abs();
                (found, t) = (at_next, next);
                if slope == 0.0 || moved <= 0.5 * tolerance {
                    break;
                }
                if (slope > 0.0) == ahead {
                    (near, near_slope) = (next, slope);
                    if kept == 1 {
                        far_slope *= 0.5;
                    }
                    kept = 1;
                } else {
                    (far, far_slope) = (next, slope);
                    if kept == 2 {
                        near_slope *= 0.5;
                    }
                    kept = 2;
                }
            }
        }
    }
    let s = found.solution;
    w[..2].copy_from_slice(&[t, 1.0]);
    w[2..5].copy_from_slice(&sub3(s.point, p.position));
    w[5] = s.lambda;
    w[6] = 1.0;
    w[7..9].copy_from_slice(&s.depths);
    Ok(found.touch)
}
