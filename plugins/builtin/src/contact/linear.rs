//! `linear`: linear normal spring and incremental tangential spring with Coulomb friction
//! (thesis eqs. 1.1-1.2). Stiffnesses are given directly (`kn`, `kt` or `kt_ratio`) or from a
//! contact modulus as YADE does (`young`: `kn = 2 E r1 r2 / (r1 + r2)`; a wall counts as a sphere
//! of the particle's own radius, so `kn = E r` against a wall).

use super::tangential::{dot, minus_along, spring_slider};
use super::Ranged;
use granite_core::ext::contact::{Contact, ContactPhysics};
use granite_core::ext::{ContactBatch, ContactLaw, ContactLawFactory, DeviceLaw, PairInfo};
use granite_core::math::Vec3;
use granite_core::params::{ParamSpec, Params};
use granite_core::{GraniteError, Result};

pub struct LinearFactory;

pub(crate) const STIFFNESS_SPECS: [ParamSpec; 4] = [
    ParamSpec::unset("kn", "normal stiffness in N/m (or give `young`)"),
    ParamSpec::unset("young", "contact modulus E in Pa: kn = 2 E r1 r2/(r1 + r2) (or give `kn`)"),
    ParamSpec::unset("kt", "tangential stiffness in N/m (or give `kt_ratio`)"),
    ParamSpec::optional("kt_ratio", 0.0, "kt / kn"),
];

const SPECS: &[ParamSpec] = &[
    STIFFNESS_SPECS[0],
    STIFFNESS_SPECS[1],
    STIFFNESS_SPECS[2],
    STIFFNESS_SPECS[3],
    ParamSpec::optional("friction", 0.0, "inter-particle friction angle in degrees, [0, 90)"),
    ParamSpec::unset("friction_max", "upper bound: friction drawn per contact pair in [friction, friction_max]"),
];

/// How a law gets its normal and tangential stiffness.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Stiffness {
    Fixed { kn: f64 },
    Modulus { young: f64 },
}

#[derive(Debug, Clone, Copy)]
pub(crate) struct Springs {
    pub normal: Stiffness,
    pub kt: Option<f64>,
    pub kt_ratio: f64,
}

impl Springs {
    pub fn read(p: &Params) -> Result<Springs> {
        let normal = match (p.is_set("kn"), p.is_set("young")) {
            (true, false) => Stiffness::Fixed { kn: p.positive("kn")? },
            (false, true) => Stiffness::Modulus { young: p.positive("young")? },
            _ => {
                return Err(GraniteError::param_in(
                    format!("stiffness of {}", p.owner()),
                    "kn/young",
                    "give exactly one of `kn` (N/m) and `young` (Pa)",
                ))
            }
        };
        let kt = if p.is_set("kt") { Some(p.non_negative("kt")?) } else { None };
        let kt_ratio = p.non_negative("kt_ratio")?;
        Ok(Springs { normal, kt, kt_ratio })
    }

    /// `(kn, kt)` of a pair; a wall (infinite radius) counts as a sphere of the particle's radius.
    pub fn of(&self, info: &PairInfo) -> (f64, f64) {
        let kn = match self.normal {
            Stiffness::Fixed { kn } => kn,
            Stiffness::Modulus { young } => {
                let r1 = info.radius[0];
                let r2 = if info.radius[1].is_finite() { info.radius[1] } else { r1 };
                2.0 * young * r1 * r2 / (r1 + r2)
            }
        };
        (kn, self.kt.unwrap_or(self.kt_ratio * kn))
    }
}

pub(crate) fn read_friction(p: &Params) -> Result<Ranged> {
    let f = Ranged::read(p, "friction");
    f.check(p, "friction", 0.0, 89.999)?;
    Ok(f)
}

struct Linear {
    params: Params,
    springs: Springs,
    friction: Ranged,
}

impl ContactLawFactory for LinearFactory {
    fn name(&self) -> &str {
        "linear"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        SPECS
    }
    fn description(&self) -> &str {
        "linear spring + Coulomb friction (eqs. 1.1-1.2)"
    }
    fn build(&self, params: Params) -> Result<Box<dyn ContactLaw>> {
        let springs = Springs::read(&params)?;
        let friction = read_friction(&params)?;
        Ok(Box::new(Linear { params, springs, friction }))
    }
}

impl ContactLaw for Linear {
    fn name(&self) -> &str {
        "linear"
    }
    fn params(&self) -> &Params {
        &self.params
    }
    fn param_count(&self) -> usize {
        3
    }
    fn history_count(&self) -> usize {
        3
    }
    fn pair_param_names(&self) -> &[&'static str] {
        &["kn", "kt", "mu"]
    }
    fn init_pair(&self, info: &PairInfo, out: &mut [f64]) {
        let (kn, kt) = self.springs.of(info);
        out[0] = kn;
        out[1] = kt;
        out[2] = self.friction.draw(info.seed, 0).to_radians().tan();
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
        let kt = c.params[1];
        (
            super::tangential::spring_slip_work(c.history_before, c.history_after, c.normal, c.rel_velocity, c.dt, kt),
            0.0,
        )
    }
    fn device_form(&self) -> std::result::Result<DeviceLaw, String> {
        if self.friction.max > self.friction.min {
            return Err("draws its friction per pair (friction_max)".into());
        }
        let (young, kn) = match self.springs.normal {
            Stiffness::Modulus { young } => (young, 0.0),
            Stiffness::Fixed { kn } => (0.0, kn),
        };
        let mu = self.friction.min.to_radians().tan();
        Ok(DeviceLaw {
            wgsl: include_str!("linear.wgsl"),
            constants: vec![young, kn, self.springs.kt_ratio, self.springs.kt.unwrap_or(-1.0), mu],
        })
    }
}

// The law on every contact of a batch, compiled for AVX2 where the CPU has it.
granite_core::contact_kernel!(fn batch_wide => Physics);

/// Eqs. 1.1-1.2 on one contact.
struct Physics;

impl ContactPhysics<3, 3> for Physics {
    #[inline(always)]
    fn contact(&mut self, c: Contact<'_, 3, 3>) -> (Vec3, Vec3) {
        let [kn, kt, mu] = *c.params;
        let n = c.normal;
        let fn_ = kn * c.overlap;
        let ft = spring_slider(c.history, n, c.rel_velocity, c.dt, kt, mu, fn_);
        (minus_along(ft, fn_, n), [0.0; 3])
    }
}
