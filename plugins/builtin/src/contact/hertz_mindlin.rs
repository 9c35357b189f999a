//! `hertz_mindlin`: Hertz's non-linear elastic normal force between spheres and Mindlin's
//! tangential stiffness (no-slip simplification, as YADE's `Law2_ScGeom_MindlinPhys_Mindlin`),
//! limited by Coulomb friction:
//!
//! - `F_n = 4/3 E* sqrt(R*) δ^(3/2)`, `1/E* = (1 − ν1²)/E1 + (1 − ν2²)/E2`, `R* = R1 R2/(R1 + R2)`
//!   (a wall counts as a flat, rigid-radius-free body: `R* = R1`, and the same material);
//! - `k_t = 8 G* a`, `a = sqrt(R* δ)`, `1/G* = (2 − ν1)/G1 + (2 − ν2)/G2`, `G = E/(2(1 + ν))`;
//!   the tangential force grows by `k_t v_t dt` (its stiffness follows the overlap) and turns with
//!   the contact plane; `|F_t| ≤ μ F_n`.
//!
//! No viscous damping: energy leaves by friction, or by the simulation's Cundall damping.

use super::tangential::{beyond_limit, dot, minus_along, rotate_into_plane, scaled};
use super::Ranged;
use granite_core::ext::contact::{Contact, ContactPhysics};
use granite_core::ext::{ContactBatch, ContactLaw, ContactLawFactory, PairInfo};
use granite_core::math::Vec3;
use granite_core::params::{ParamSpec, Params};
use granite_core::Result;

pub struct HertzMindlinFactory;

const SPECS: &[ParamSpec] = &[
    ParamSpec::required("young", "Young's modulus E of the grains, Pa"),
    ParamSpec::required("poisson", "Poisson's ratio of the grains, [0, 0.5)"),
    ParamSpec::optional("friction", 0.0, "inter-particle friction angle in degrees, [0, 90)"),
    ParamSpec::unset("friction_max", "upper bound: friction drawn per contact pair in [friction, friction_max]"),
];

/// Overlap, as a fraction of R*, at which the stiffness for time-step estimates is taken.
const REFERENCE_OVERLAP: f64 = 0.01;

struct HertzMindlin {
    params: Params,
    /// E* and G* of two grains of this material.
    e_star: f64,
    g_star: f64,
    friction: Ranged,
}

impl ContactLawFactory for HertzMindlinFactory {
    fn name(&self) -> &str {
        "hertz_mindlin"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        SPECS
    }
    fn description(&self) -> &str {
        "Hertz normal force + Mindlin tangential stiffness + Coulomb friction (no damping)"
    }
    fn build(&self, params: Params) -> Result<Box<dyn ContactLaw>> {
        let young = params.positive("young")?;
        let nu = params.get("poisson");
        if !(0.0..0.5).contains(&nu) {
            return Err(granite_core::GraniteError::param_in(
                format!("`poisson` of {}", params.owner()),
                nu,
                "must lie in [0, 0.5)",
            ));
        }
        let friction = super::linear::read_friction(&params)?;
        let shear = young / (2.0 * (1.0 + nu));
        // Two grains of the same material.
        let e_star = young / (2.0 * (1.0 - nu * nu));
        let g_star = shear / (2.0 * (2.0 - nu));
        Ok(Box::new(HertzMindlin { params, e_star, g_star, friction }))
    }
}

/// Effective radius of a pair; a wall (infinite radius) leaves the sphere's.
fn effective_radius(info: &PairInfo) -> f64 {
    let [r1, r2] = info.radius;
    if r2.is_finite() {
        r1 * r2 / (r1 + r2)
    } else {
        r1
    }
}

impl ContactLaw for HertzMindlin {
    fn name(&self) -> &str {
        "hertz_mindlin"
    }
    fn params(&self) -> &Params {
        &self.params
    }
    fn param_count(&self) -> usize {
        4
    }
    fn history_count(&self) -> usize {
        3
    }
    fn init_pair(&self, info: &PairInfo, out: &mut [f64]) {
        out[0] = self.e_star;
        out[1] = self.g_star;
        out[2] = effective_radius(info);
        out[3] = self.friction.draw(info.seed, 0).to_radians().tan();
    }
    fn max_normal_stiffness(&self, info: &PairInfo) -> f64 {
        // dF_n/dδ = 2 E* sqrt(R* δ) at the reference overlap.
        let r = effective_radius(info);
        2.0 * self.e_star * r * REFERENCE_OVERLAP.sqrt()
    }
    fn resists_rotation(&self) -> bool {
        false
    }
    fn compute(&self, b: ContactBatch<'_>) {
        batch_wide(b);
    }
    fn normal_stiffness(&self, params: &[f64]) -> f64 {
        2.0 * params[0] * params[2] * REFERENCE_OVERLAP.sqrt()
    }
    fn tangent_stiffness(&self, overlap: f64, params: &[f64]) -> (f64, f64) {
        // dF_n/dδ = 2 E* a and Mindlin's k_t = 8 G* a, with a = sqrt(R* δ) the contact radius.
        let a = (params[2] * overlap.max(0.0)).sqrt();
        (2.0 * params[0] * a, 8.0 * params[1] * a)
    }
    fn elastic_energy(&self, overlap: f64, p: &[f64], h: &[f64]) -> f64 {
        let (e_star, g_star, r_star) = (p[0], p[1], p[2]);
        let a = (r_star * overlap).sqrt();
        let normal = 8.0 / 15.0 * e_star * a * overlap * overlap;
        let kt = 8.0 * g_star * a;
        let ft2 = h[0] * h[0] + h[1] * h[1] + h[2] * h[2];
        normal + if kt > 0.0 { 0.5 * ft2 / kt } else { 0.0 }
    }
}

// The law on every contact of a batch, compiled for AVX2 where the CPU has it.
granite_core::contact_kernel!(fn batch_wide => Physics);

/// Hertz-Mindlin on one contact.
struct Physics;

impl ContactPhysics<4, 3> for Physics {
    #[inline(always)]
    fn contact(&mut self, c: Contact<'_, 4, 3>) -> (Vec3, Vec3) {
        let dt = c.dt;
        let [e_star, g_star, r_star, mu] = *c.params;
        let (n, overlap) = (c.normal, c.overlap);
        let a = (r_star * overlap).sqrt();
        let fn_ = 4.0 / 3.0 * e_star * a * overlap;
        let kt = 8.0 * g_star * a;
        // Incremental tangential force: the stiffness changes with the overlap, so the force
        // (not a displacement) is what carries over between steps.
        let f_old = rotate_into_plane(*c.history, n);
        let v = c.rel_velocity;
        let vn = dot(v, n);
        let vt = minus_along(v, vn, n);
        let mut ft = [f_old[0] + kt * vt[0] * dt, f_old[1] + kt * vt[1] * dt, f_old[2] + kt * vt[2] * dt];
        if let Some(scale) = beyond_limit(ft, mu * fn_) {
            ft = scaled(ft, scale);
        }
        *c.history = ft;
        (minus_along(ft, fn_, n), [0.0; 3])
    }
}
