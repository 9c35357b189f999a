//! Built-in granite plugins: the constitutive laws and velocity-update strategies of the thesis,
//! each registered by name in a [`Registry`].

// Index loops over fixed-size arrays read better than iterator chains in the numerics, and negated
// comparisons are deliberate: they also reject NaN.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod constitutive;
pub mod contact;
pub mod shape;
pub mod velocity_update;

use granite_core::{Plugin, Registry};

/// Every built-in plugin.
pub struct DefaultPlugins;

impl Plugin for DefaultPlugins {
    fn register(&self, registry: &mut Registry) {
        constitutive::register(registry);
        contact::register(registry);
        shape::register(registry);
        velocity_update::register(registry);
    }
}

/// A registry holding every built-in plugin.
pub fn default_registry() -> Registry {
    Registry::new().with(&DefaultPlugins)
}
