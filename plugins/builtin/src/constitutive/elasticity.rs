//! Isotropic linear elasticity shared by the laws.

use granite_core::math::Voigt;
use granite_core::params::Params;
use granite_core::Result;

#[derive(Debug, Clone, Copy)]
pub struct Isotropic {
    pub young: f64,
    pub poisson: f64,
    /// Lamé's first parameter.
    pub lambda: f64,
    /// Shear modulus.
    pub shear: f64,
}

impl Isotropic {
    /// Reads and checks `young` (> 0) and `poisson` (in (-1, 0.5)).
    pub fn from_params(p: &Params) -> Result<Isotropic> {
        let young = p.positive("young")?;
        let poisson = p.get("poisson");
        if !(poisson > -1.0 && poisson < 0.5) {
            return Err(granite_core::GraniteError::param_in(
                format!("`poisson` of {}", p.owner()),
                poisson,
                "must be in (-1, 0.5): 0.5 is incompressible, which explicit MPM cannot run",
            ));
        }
        Ok(Isotropic::new(young, poisson))
    }

    pub fn new(young: f64, poisson: f64) -> Isotropic {
        let lambda = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson));
        let shear = young / (2.0 * (1.0 + poisson));
        Isotropic { young, poisson, lambda, shear }
    }

    /// P-wave modulus `lambda + 2G`.
    pub fn p_modulus(&self) -> f64 {
        self.lambda + 2.0 * self.shear
    }

    pub fn bulk(&self) -> f64 {
        self.lambda + 2.0 * self.shear / 3.0
    }

    /// `D : d_eps` for an engineering-shear strain increment.
    #[inline]
    pub fn stress_increment(&self, de: &Voigt) -> Voigt {
        let vol = self.lambda * (de[0] + de[1] + de[2]);
        let g2 = 2.0 * self.shear;
        [
            vol + g2 * de[0],
            vol + g2 * de[1],
            vol + g2 * de[2],
            self.shear * de[3],
            self.shear * de[4],
            self.shear * de[5],
        ]
    }

    pub fn wave_speed(&self, density: f64) -> f64 {
        (self.p_modulus() / density).sqrt()
    }
}
