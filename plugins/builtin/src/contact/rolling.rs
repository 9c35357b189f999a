//! `rolling_resistance`: the contact law of the Camargue sand (thesis table 5.2, Aboul Hosn et al.
//! 2017): `kn = 2 E r1 r2/(r1 + r2)`, `kt = alpha_s kn`, Coulomb friction, and elastic-perfectly
//! plastic rolling and twisting resistance with `k_r = alpha_r kt r1 r2`, `k_tw = alpha_t kt r1 r2`,
//! both capped at `eta_r |F_n| min(r1, r2)`. Relative rotations are incremental: the relative
//! spin projected on the contact plane (rolling) or on the normal (twisting). A wall counts as a
//! sphere of the particle's own radius.

use super::linear::read_friction;
use super::tangential::{dot, minus_along, rotate_into_plane, rotational_spring, spring_slider};
use super::Ranged;
use granite_core::ext::contact::{Contact, ContactPhysics};
use granite_core::ext::{ContactBatch, ContactLaw, ContactLawFactory, DeviceLaw, PairInfo};
use granite_core::math::Vec3;
use granite_core::params::{ParamSpec, Params};
use granite_core::Result;

pub struct RollingResistanceFactory;

const SPECS: &[ParamSpec] = &[
    ParamSpec::required("young", "contact modulus in Pa (the thesis's G, 2.8e8 for Camargue sand)"),
    ParamSpec::optional("alpha_s", 0.2, "kt / kn"),
    ParamSpec::optional("alpha_r", 7.5, "rolling stiffness factor: k_r = alpha_r kt r1 r2"),
    ParamSpec::optional("alpha_t", 0.2, "twisting stiffness factor: k_tw = alpha_t kt r1 r2"),
    ParamSpec::optional("friction", 25.0, "inter-particle friction angle in degrees"),
    ParamSpec::unset("friction_max", "upper bound: friction drawn per contact pair in [friction, friction_max]"),
    ParamSpec::optional("eta_r", 0.22, "rolling/twisting limit: moment <= eta_r |F_n| min(r1, r2)"),
];

struct RollingResistance {
    params: Params,
    young: f64,
    alpha_s: f64,
    alpha_r: f64,
    alpha_t: f64,
    eta_r: f64,
    friction: Ranged,
}

impl ContactLawFactory for RollingResistanceFactory {
    fn name(&self) -> &str {
        "rolling_resistance"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        SPECS
    }
    fn description(&self) -> &str {
        "Camargue sand law (table 5.2): friction with rolling and twisting resistance"
    }
    fn build(&self, params: Params) -> Result<Box<dyn ContactLaw>> {
        Ok(Box::new(RollingResistance {
            young: params.positive("young")?,
            alpha_s: params.non_negative("alpha_s")?,
            alpha_r: params.non_negative("alpha_r")?,
            alpha_t: params.non_negative("alpha_t")?,
            eta_r: params.non_negative("eta_r")?,
            friction: read_friction(&params)?,
            params,
        }))
    }
}

impl RollingResistance {
    fn radii(info: &PairInfo) -> (f64, f64) {
        let r1 = info.radius[0];
        (r1, if info.radius[1].is_finite() { info.radius[1] } else { r1 })
    }
}

const PARAMS: usize = 6;
const HISTORY: usize = 7;

impl ContactLaw for RollingResistance {
    fn name(&self) -> &str {
        "rolling_resistance"
    }
    fn params(&self) -> &Params {
        &self.params
    }
    fn param_count(&self) -> usize {
        PARAMS
    }
    fn history_count(&self) -> usize {
        HISTORY
    }
    fn pair_param_names(&self) -> &[&'static str] {
        &["kn", "kt", "mu", "k_rolling", "k_twisting", "moment_arm"]
    }
    fn init_pair(&self, info: &PairInfo, out: &mut [f64]) {
        let (r1, r2) = Self::radii(info);
        let kn = 2.0 * self.young * r1 * r2 / (r1 + r2);
        let kt = self.alpha_s * kn;
        out[0] = kn;
        out[1] = kt;
        out[2] = self.friction.draw(info.seed, 0).to_radians().tan();
        out[3] = self.alpha_r * kt * r1 * r2;
        out[4] = self.alpha_t * kt * r1 * r2;
        out[5] = self.eta_r * r1.min(r2);
    }
    fn device_form(&self) -> std::result::Result<DeviceLaw, String> {
        if self.friction.max > self.friction.min {
            return Err("draws its friction per pair (friction_max)".into());
        }
        let mu = self.friction.min.to_radians().tan();
        Ok(DeviceLaw {
            wgsl: include_str!("rolling.wgsl"),
            constants: vec![self.young, self.alpha_s, self.alpha_r, self.alpha_t, self.eta_r, mu],
        })
    }
    fn max_normal_stiffness(&self, info: &PairInfo) -> f64 {
        let (r1, r2) = Self::radii(info);
        2.0 * self.young * r1 * r2 / (r1 + r2)
    }
    fn compute(&self, b: ContactBatch<'_>) {
        batch_wide(b);
    }
    fn normal_stiffness(&self, params: &[f64]) -> f64 {
        params[0]
    }
    fn tangent_stiffness(&self, _overlap: f64, params: &[f64]) -> (f64, f64) {
        (params[0], params[1])
    }
    fn elastic_energy(&self, overlap: f64, p: &[f64], h: &[f64]) -> f64 {
        let u = [h[0], h[1], h[2]];
        let tr = [h[3], h[4], h[5]];
        0.5 * p[0] * overlap * overlap + 0.5 * p[1] * dot(u, u) + 0.5 * p[3] * dot(tr, tr) + 0.5 * p[4] * h[6] * h[6]
    }
    fn tracks_dissipation(&self) -> bool {
        true
    }
    fn dissipation(&self, c: &granite_core::ext::contact::ContactStep<'_>) -> (f64, f64) {
        use super::tangential::spring_slip_work;
        let [_, kt, _, kr, ktw, _] = [c.params[0], c.params[1], c.params[2], c.params[3], c.params[4], c.params[5]];
        let (before, after) = (c.history_before, c.history_after);
        let sliding = spring_slip_work(&before[..3], &after[..3], c.normal, c.rel_velocity, c.dt, kt);
        // Rolling: the same spring-slider on the relative rotation in the contact plane.
        let rolling = spring_slip_work(&before[3..6], &after[3..6], c.normal, c.rel_spin, c.dt, kr);
        // Twisting: a scalar spring on the relative rotation about the normal (trapezoid rule).
        let trial = before[6] + dot(c.rel_spin, c.normal) * c.dt;
        let twisting = ktw * 0.5 * (before[6] + after[6]) * (trial - after[6]);
        (sliding + rolling + twisting, 0.0)
    }
}

// The law on every contact of a batch, compiled for AVX2 where the CPU has it.
granite_core::contact_kernel!(fn batch_wide => Physics);

/// Spring-slider with rolling and twisting resistance on one contact.
struct Physics;

impl ContactPhysics<PARAMS, HISTORY> for Physics {
    #[inline(always)]
    fn contact(&mut self, c: Contact<'_, PARAMS, HISTORY>) -> (Vec3, Vec3) {
        let dt = c.dt;
        let [kn, kt, mu, kr, ktw, arm] = *c.params;
        let n = c.normal;
        let fn_ = kn * c.overlap;
        let h = c.history;
        let mut u = [h[0], h[1], h[2]];
        let ft = spring_slider(&mut u, n, c.rel_velocity, dt, kt, mu, fn_);
        let spin = c.rel_spin;
        let s_n = dot(spin, n);
        let roll = minus_along(spin, s_n, n);
        let limit = arm * fn_;
        let mut theta_r = rotate_into_plane([h[3], h[4], h[5]], n);
        let m_roll = rotational_spring(&mut theta_r, roll, dt, kr, limit);
        let mut theta_t = [h[6], 0.0, 0.0];
        let m_twist = rotational_spring(&mut theta_t, [s_n, 0.0, 0.0], dt, ktw, limit)[0];
        h[..3].copy_from_slice(&u);
        h[3..6].copy_from_slice(&theta_r);
        h[6] = theta_t[0];
        let force = minus_along(ft, fn_, n);
        // Particle 1 is pulled along the relative rotation of 2 (and 2 held back).
        let moment = [m_roll[0] + m_twist * n[0], m_roll[1] + m_twist * n[1], m_roll[2] + m_twist * n[2]];
        (force, moment)
    }
}
