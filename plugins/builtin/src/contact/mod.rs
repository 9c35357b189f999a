//! Contact laws (YADE's Law2 functors; parameters per material pair, values per contact pair).

pub mod hertz_mindlin;
pub mod linear;
pub mod restitution;
pub mod rolling;
pub mod tangential;
pub mod visco_elastic;

use granite_core::ext::contact::uniform;
use granite_core::params::Params;
use granite_core::Registry;
use std::sync::Arc;

pub fn register(registry: &mut Registry) {
    registry.add_contact_law(Arc::new(linear::LinearFactory));
    registry.add_contact_law(Arc::new(visco_elastic::ViscoElasticFactory));
    registry.add_contact_law(Arc::new(rolling::RollingResistanceFactory));
    registry.add_contact_law(Arc::new(hertz_mindlin::HertzMindlinFactory));
}

/// A parameter that may be drawn per contact pair: uniform in `[name, name_max]` when `name_max`
/// is given (thesis 2.2.3, table 2.13), else fixed.
#[derive(Debug, Clone, Copy)]
pub struct Ranged {
    pub min: f64,
    pub max: f64,
}

impl Ranged {
    pub fn read(p: &Params, name: &str) -> Ranged {
        let min = p.get(name);
        let max_name = format!("{name}_max");
        let max = if p.is_set(&max_name) { p.get(&max_name) } else { min };
        Ranged { min, max }
    }

    /// The value of one pair, from the pair's seed and a stream index per property.
    pub fn draw(&self, seed: u64, stream: u64) -> f64 {
        if self.max > self.min {
            self.min + (self.max - self.min) * uniform(seed, stream)
        } else {
            self.min
        }
    }

    pub fn check(&self, p: &Params, name: &str, lo: f64, hi: f64) -> granite_core::Result<()> {
        let ok = self.min >= lo && self.max <= hi && self.max >= self.min;
        if ok {
            Ok(())
        } else {
            Err(granite_core::GraniteError::param_in(
                format!("`{name}` of {}", p.owner()),
                format!("[{}, {}]", self.min, self.max),
                &format!("must lie in [{lo}, {hi}] with {name} <= {name}_max"),
            ))
        }
    }
}
