//! `hertz_mindlin`: Hertz's non-linear elastic normal force between spheres and Mindlin's
//! tangential stiffness (no-slip simplification, as YADE's `Law2_ScGeom_MindlinPhys_Mindlin`),
//! limited by Coulomb friction:
//!
//! - `F_n = 4/3 E* sqrt(R*) δ^(3/2) + c_n δ'`, clamped at zero (no attraction);
//!   `1/E* = (1 − ν1²)/E1 + (1 − ν2²)/E2`, `R* = R1 R2/(R1 + R2)` (a wall is flat: `R* = R1`);
//! - `k_t = 8 G* a`, `a = sqrt(R* δ)`, `1/G* = (2 − ν1)/G1 + (2 − ν2)/G2`, `G = E/(2(1 + ν))`;
//!   the tangential force grows by `k_t v_t dt` (its stiffness follows the overlap) and turns with
//!   the contact plane; `|F_t| ≤ μ F_n`;
//! - the normal dashpot `c_n = 2 β sqrt(m* k_n)`, `k_n = 2 E* a` the tangent stiffness (the
//!   form of Thornton, Cummins & Cleary 2013, YADE's `MindlinPhys` with `betan`), with `β` set from
//!   the `restitution` coefficient: the restitution of this contact depends on `β` alone, and is
//!   found by integrating one contact (`restitution::hertz_damping_ratio`). `restitution = 1` (the
//!   default) is the undamped law.
//!
//! The moduli: `young` and `poisson` given to the law serve both bodies (a wall included, as a
//! body of the same material), except a body whose material is rigid (`rigid: true`): rigidity
//! belongs to the body and stays. Left out, each body's material gives its own
//! (`sim.material(#{ young, poisson })`, a modulus of infinity for a rigid wall).

use super::tangential::{beyond_limit, dot, minus_along, rotate_into_plane, scaled};
use super::Ranged;
use granite_core::dem::sim::Elastic;
use granite_core::ext::contact::{Contact, ContactPhysics};
use granite_core::ext::{ContactBatch, ContactLaw, ContactLawFactory, PairInfo};
use granite_core::math::Vec3;
use granite_core::params::{ParamSpec, Params};
use granite_core::Result;

pub struct HertzMindlinFactory;

const SPECS: &[ParamSpec] = &[
    ParamSpec::unset("young", "Young's modulus E of both bodies, Pa (or left out: each material's own `young`)"),
    ParamSpec::unset("poisson", "Poisson's ratio of both bodies, [0, 0.5) (or each material's own)"),
    ParamSpec::optional("friction", 0.0, "inter-particle friction angle in degrees, [0, 90)"),
    ParamSpec::unset("friction_max", "upper bound: friction drawn per contact pair in [friction, friction_max]"),
    ParamSpec::optional("restitution", 1.0, "normal restitution coefficient e in (0, 1]; 1: no damping"),
];

/// Overlap, as a fraction of R*, at which the stiffness for time-step estimates is taken.
const REFERENCE_OVERLAP: f64 = 0.01;

struct HertzMindlin {
    params: Params,
    /// E and ν of both bodies, when the law gives them.
    own: Option<Elastic>,
    friction: Ranged,
    /// Damping ratio β of the normal dashpot.
    beta: f64,
}

impl ContactLawFactory for HertzMindlinFactory {
    fn name(&self) -> &str {
        "hertz_mindlin"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        SPECS
    }
    fn description(&self) -> &str {
        "Hertz normal force + Mindlin tangential stiffness + Coulomb friction, optional normal damping from a restitution coefficient"
    }
    fn build(&self, params: Params) -> Result<Box<dyn ContactLaw>> {
        let own = match (params.is_set("young"), params.is_set("poisson")) {
            (true, true) => {
                let young = params.positive("young")?;
                let poisson = params.in_range("poisson", 0.0, 0.5, false)?;
                Some(Elastic { young, poisson })
            }
            (false, false) => None,
            _ => {
                return Err(granite_core::GraniteError::param_in(
                    format!("moduli of {}", params.owner()),
                    "young/poisson",
                    "give both `young` and `poisson`, or neither (each material's own are then used)",
                ))
            }
        };
        let friction = super::linear::read_friction(&params)?;
        let e = params.get("restitution");
        if !(e > 0.0 && e <= 1.0) {
            return Err(granite_core::GraniteError::param_in(
                format!("`restitution` of {}", params.owner()),
                e,
                "must lie in (0, 1]",
            ));
        }
        let beta = super::restitution::hertz_damping_ratio(e);
        Ok(Box::new(HertzMindlin { params, own, friction, beta }))
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

impl HertzMindlin {
    /// The two bodies' moduli: the law's own for both (a rigid body staying rigid), else each
    /// material's.
    fn moduli(&self, info: &PairInfo) -> std::result::Result<[Elastic; 2], String> {
        if let Some(own) = self.own {
            let body = |material: Option<Elastic>| match material {
                Some(rigid) if rigid.young.is_infinite() => rigid,
                _ => own,
            };
            return Ok([body(info.elastic[0]), body(info.elastic[1])]);
        }
        match info.elastic {
            [Some(a), Some(b)] => Ok([a, b]),
            _ => Err("give the law `young` and `poisson`, or give both materials `young` and `poisson`".into()),
        }
    }

    /// `(E*, G*)` of a pair; NaN when the moduli are missing (refused before a run by `check_pair`).
    fn effective_moduli(&self, info: &PairInfo) -> (f64, f64) {
        let Ok(m) = self.moduli(info) else { return (f64::NAN, f64::NAN) };
        // Compliances: a rigid body (infinite modulus) adds none.
        let normal = |e: &Elastic| if e.young.is_infinite() { 0.0 } else { (1.0 - e.poisson * e.poisson) / e.young };
        let shear = |e: &Elastic| {
            if e.young.is_infinite() {
                0.0
            } else {
                (2.0 - e.poisson) * 2.0 * (1.0 + e.poisson) / e.young
            }
        };
        (1.0 / (normal(&m[0]) + normal(&m[1])), 1.0 / (shear(&m[0]) + shear(&m[1])))
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
        5
    }
    fn history_count(&self) -> usize {
        3
    }
    fn pair_param_names(&self) -> &[&'static str] {
        &["e_star", "g_star", "r_star", "mu", "damping"]
    }
    fn init_pair(&self, info: &PairInfo, out: &mut [f64]) {
        let (e_star, g_star) = self.effective_moduli(info);
        out[0] = e_star;
        out[1] = g_star;
        out[2] = effective_radius(info);
        out[3] = self.friction.draw(info.seed, 0).to_radians().tan();
        // c_n = out[4] sqrt(k_n), k_n = 2 E* a: 2 β sqrt(m*).
        out[4] = 2.0 * self.beta * info.effective_mass().sqrt();
    }
    fn check_pair(&self, info: &PairInfo) -> std::result::Result<(), String> {
        let m = self.moduli(info)?;
        if m.iter().all(|e| e.young.is_infinite()) {
            return Err("both bodies are rigid (infinite `young`): Hertz's law needs one deformable body".into());
        }
        Ok(())
    }
    fn max_normal_stiffness(&self, info: &PairInfo) -> f64 {
        // dF_n/dδ = 2 E* sqrt(R* δ) at the reference overlap.
        let r = effective_radius(info);
        let k = 2.0 * self.effective_moduli(info).0 * r * REFERENCE_OVERLAP.sqrt();
        if k.is_nan() {
            0.0
        } else {
            k
        }
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
    fn tracks_dissipation(&self) -> bool {
        true
    }
    fn dissipation(&self, c: &granite_core::ext::contact::ContactStep<'_>) -> (f64, f64) {
        let (e_star, g_star, r_star) = (c.params[0], c.params[1], c.params[2]);
        let a = (r_star * c.overlap.max(0.0)).sqrt();
        let kt = 8.0 * g_star * a;
        // The history is a force: the slip is the force the cap took off, over k_t.
        let friction = if kt > 0.0 {
            let before = [0, 1, 2].map(|a| c.history_before[a] / kt);
            let after = [0, 1, 2].map(|a| c.history_after[a] / kt);
            super::tangential::spring_slip_work(&before, &after, c.normal, c.rel_velocity, c.dt, kt)
        } else {
            0.0
        };
        let elastic = 4.0 / 3.0 * e_star * a * c.overlap;
        (friction, super::tangential::dashpot_work(c.force, c.normal, elastic, c.mean_rel_velocity, c.dt))
    }
}

// The law on every contact of a batch, compiled for AVX2 where the CPU has it.
granite_core::contact_kernel!(fn batch_wide => Physics);

/// Hertz-Mindlin on one contact.
struct Physics;

impl ContactPhysics<5, 3> for Physics {
    #[inline(always)]
    fn contact(&mut self, c: Contact<'_, 5, 3>) -> (Vec3, Vec3) {
        let dt = c.dt;
        let [e_star, g_star, r_star, mu, damping] = *c.params;
        let (n, overlap) = (c.normal, c.overlap);
        let a = (r_star * overlap).sqrt();
        let v = c.rel_velocity;
        let vn = dot(v, n);
        // The overlap grows at -vn (n points from 1 to 2, v is 2's velocity relative to 1).
        let dashpot = damping * (2.0 * e_star * a).sqrt() * -vn;
        let fn_ = (4.0 / 3.0 * e_star * a * overlap + dashpot).max(0.0);
        let kt = 8.0 * g_star * a;
        // Incremental tangential force: the stiffness changes with the overlap, so the force
        // (not a displacement) is what carries over between steps.
        let f_old = rotate_into_plane(*c.history, n);
        let vt = minus_along(v, vn, n);
        let mut ft = [f_old[0] + kt * vt[0] * dt, f_old[1] + kt * vt[1] * dt, f_old[2] + kt * vt[2] * dt];
        if let Some(scale) = beyond_limit(ft, mu * fn_) {
            ft = scaled(ft, scale);
        }
        *c.history = ft;
        (minus_along(ft, fn_, n), [0.0; 3])
    }
}
