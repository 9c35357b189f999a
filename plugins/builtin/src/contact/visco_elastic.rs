//! `visco_elastic`: linear spring and dashpot in the normal direction, clamped at zero
//! (eqs. 2.2 and 2.40), tangential spring with Coulomb friction (2.3, 2.41). The dashpot `c_n`
//! is derived per pair from a target restitution coefficient `e_n` and the pair's effective mass,
//! following Schwager & Pöschel (2007), as YADE's ViscElPhys does; or from a damping ratio
//! `beta_n`, `c_n = 2 beta_n sqrt(m* K_n)`, as YADE's KnKsPhys does for potential particles
//! (thesis 2.2.3, Antypov & Elliott 2011).

use super::linear::{read_friction, Springs, STIFFNESS_SPECS};
use super::restitution::damping_ratio;
use super::tangential::{dot, minus_along, spring_slider};
use super::Ranged;
use granite_core::ext::contact::{Contact, ContactPhysics};
use granite_core::ext::{ContactBatch, ContactLaw, ContactLawFactory, PairInfo};
use granite_core::math::Vec3;
use granite_core::params::{ParamSpec, Params};
use granite_core::Result;

pub struct ViscoElasticFactory;

const SPECS: &[ParamSpec] = &[
    STIFFNESS_SPECS[0],
    STIFFNESS_SPECS[1],
    STIFFNESS_SPECS[2],
    STIFFNESS_SPECS[3],
    ParamSpec::optional("friction", 0.0, "inter-particle friction angle in degrees, [0, 90)"),
    ParamSpec::unset("friction_max", "upper bound: friction drawn per contact pair in [friction, friction_max]"),
    ParamSpec::unset("restitution", "normal restitution coefficient e_n in (0, 1] (or give `beta_n`)"),
    ParamSpec::unset("restitution_max", "upper bound: e_n drawn per contact pair in [restitution, restitution_max]"),
    ParamSpec::unset("beta_n", "damping ratio in [0, 1): c_n = 2 beta_n sqrt(m* kn) (or give `restitution`)"),
];

/// How the dashpot is given.
enum Damping {
    Restitution(Ranged),
    Ratio(f64),
}

struct ViscoElastic {
    params: Params,
    springs: Springs,
    friction: Ranged,
    damping: Damping,
}

impl ContactLawFactory for ViscoElasticFactory {
    fn name(&self) -> &str {
        "visco_elastic"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        SPECS
    }
    fn description(&self) -> &str {
        "linear spring-dashpot from a restitution coefficient (Schwager & Poschel 2007) + Coulomb friction"
    }
    fn build(&self, params: Params) -> Result<Box<dyn ContactLaw>> {
        let springs = Springs::read(&params)?;
        let friction = read_friction(&params)?;
        let damping = match (params.is_set("restitution"), params.is_set("beta_n")) {
            (true, false) => {
                let restitution = Ranged::read(&params, "restitution");
                restitution.check(&params, "restitution", 1e-6, 1.0)?;
                Damping::Restitution(restitution)
            }
            (false, true) => {
                let beta = params.get("beta_n");
                if !(0.0..1.0).contains(&beta) {
                    return Err(granite_core::GraniteError::param(
                        "beta_n",
                        beta,
                        "the damping ratio must be in [0, 1)",
                    ));
                }
                Damping::Ratio(beta)
            }
            (true, true) => {
                return Err(granite_core::GraniteError::Setup(format!(
                    "{}: give `restitution` or `beta_n`, not both",
                    params.owner()
                )))
            }
            (false, false) => {
                return Err(granite_core::GraniteError::Setup(format!(
                    "{}: give the dashpot as `restitution` (e_n in (0, 1]) or `beta_n` (damping ratio in [0, 1))",
                    params.owner()
                )))
            }
        };
        Ok(Box::new(ViscoElastic { params, springs, friction, damping }))
    }
}

impl ContactLaw for ViscoElastic {
    fn name(&self) -> &str {
        "visco_elastic"
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
    fn pair_param_names(&self) -> &[&'static str] {
        &["kn", "kt", "mu", "cn"]
    }
    fn init_pair(&self, info: &PairInfo, out: &mut [f64]) {
        let (kn, kt) = self.springs.of(info);
        let m = info.effective_mass();
        let x = match &self.damping {
            Damping::Restitution(e) => damping_ratio(e.draw(info.seed, 1)),
            Damping::Ratio(beta) => *beta,
        };
        out[0] = kn;
        out[1] = kt;
        out[2] = self.friction.draw(info.seed, 0).to_radians().tan();
        // c_n = 2 m* beta, beta = x w0, w0 = sqrt(kn / m*).
        out[3] = 2.0 * m * x * (kn / m).sqrt();
    }
    fn max_normal_stiffness(&self, info: &PairInfo) -> f64 {
        self.springs.of(info).0
    }
    fn resists_rotation(&self) -> bool {
        false
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
        0.5 * p[0] * overlap * overlap + 0.5 * p[1] * dot(u, u)
    }
    fn tracks_dissipation(&self) -> bool {
        true
    }
    fn dissipation(&self, c: &granite_core::ext::contact::ContactStep<'_>) -> (f64, f64) {
        let (kn, kt) = (c.params[0], c.params[1]);
        let friction =
            super::tangential::spring_slip_work(c.history_before, c.history_after, c.normal, c.rel_velocity, c.dt, kt);
        (friction, super::tangential::dashpot_work(c.force, c.normal, kn * c.overlap, c.mean_rel_velocity, c.dt))
    }
}

// The law on every contact of a batch, compiled for AVX2 where the CPU has it.
granite_core::contact_kernel!(fn batch_wide => Physics);

/// Eqs. 2.2-2.3 and 2.40-2.41 on one contact.
struct Physics;

impl ContactPhysics<4, 3> for Physics {
    #[inline(always)]
    fn contact(&mut self, c: Contact<'_, 4, 3>) -> (Vec3, Vec3) {
        let dt = c.dt;
        let [kn, kt, mu, cn] = *c.params;
        let n = c.normal;
        // Overlap rate: particle 2 approaching particle 1 means a negative normal velocity.
        let rate = -dot(c.rel_velocity, n);
        let fn_ = (kn * c.overlap + cn * rate).max(0.0);
        let ft = spring_slider(c.history, n, c.rel_velocity, dt, kt, mu, fn_);
        (minus_along(ft, fn_, n), [0.0; 3])
    }
}
