//! `linear_elastic`: Hooke's law, stress updated incrementally (eq. 3.41-3.42).

use super::elasticity::Isotropic;
use granite_core::ext::{ConstitutiveLaw, ConstitutiveLawFactory, LawBatch};
use granite_core::params::{ParamSpec, Params};
use granite_core::Result;

pub struct LinearElasticFactory;

const SPECS: &[ParamSpec] = &[
    ParamSpec::required("young", "Young's modulus E in Pa, > 0"),
    ParamSpec::required("poisson", "Poisson's ratio, in (-1, 0.5)"),
];

impl ConstitutiveLawFactory for LinearElasticFactory {
    fn name(&self) -> &str {
        "linear_elastic"
    }
    fn param_specs(&self) -> &[ParamSpec] {
        SPECS
    }
    fn description(&self) -> &str {
        "isotropic linear elasticity"
    }
    fn build(&self, params: Params) -> Result<Box<dyn ConstitutiveLaw>> {
        let elastic = Isotropic::from_params(&params)?;
        Ok(Box::new(LinearElastic { params, elastic }))
    }
}

pub struct LinearElastic {
    params: Params,
    elastic: Isotropic,
}

impl ConstitutiveLaw for LinearElastic {
    fn name(&self) -> &str {
        "linear_elastic"
    }
    fn params(&self) -> &Params {
        &self.params
    }
    fn wave_speed(&self, density: f64) -> Option<f64> {
        Some(self.elastic.wave_speed(density))
    }
    fn update(&self, batch: LawBatch<'_>) -> Result<()> {
        for (s, de) in batch.stress.iter_mut().zip(batch.dstrain) {
            let ds = self.elastic.stress_increment(de);
            for c in 0..6 {
                s[c] += ds[c];
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(pairs: &[(&str, f64)]) -> Params {
        crate::constitutive::test_params(SPECS, pairs).unwrap()
    }

    #[test]
    fn uniaxial_strain_and_shear_follow_hooke() {
        let (e, nu) = (52.6e6, 0.3);
        let law = LinearElasticFactory.build(params(&[("young", e), ("poisson", nu)])).unwrap();
        let eps = 1e-4;
        let gamma = 2e-4;
        let mut stress = [[0.0; 6]];
        law.update(LawBatch {
            first: 0,
            stress: &mut stress,
            dstrain: &[[eps, 0.0, 0.0, gamma, 0.0, 0.0]],
            state: &mut [],
        })
        .unwrap();
        // Hand-derived: sigma_xx = E(1-nu)/((1+nu)(1-2nu)) eps, sigma_yy = E nu/((1+nu)(1-2nu)) eps,
        // tau_xy = E/(2(1+nu)) gamma.
        let d = (1.0 + nu) * (1.0 - 2.0 * nu);
        assert!((stress[0][0] - e * (1.0 - nu) / d * eps).abs() < 1e-6);
        assert!((stress[0][1] - e * nu / d * eps).abs() < 1e-6);
        assert!((stress[0][2] - e * nu / d * eps).abs() < 1e-6);
        assert!((stress[0][3] - e / (2.0 * (1.0 + nu)) * gamma).abs() < 1e-6);
    }

    #[test]
    fn rejects_incompressible_and_negative_modulus() {
        let err = LinearElasticFactory.build(params(&[("young", 1e6), ("poisson", 0.5)])).err().unwrap().to_string();
        assert!(err.contains("poisson") && err.contains("0.5"), "{err}");
        let err = LinearElasticFactory.build(params(&[("young", -1.0), ("poisson", 0.2)])).err().unwrap().to_string();
        assert!(err.contains("young") && err.contains("> 0"), "{err}");
    }
}
