//! granite-core: the engine and its extension points.
//!
//! Sign convention everywhere: continuum mechanics, tension positive (as in CB-Geo MPM).
//! Tensors travel as Voigt 6-vectors in the order `xx, yy, zz, xy, yz, xz`; strains carry the
//! engineering shear (`gamma_xy = 2 eps_xy`), stresses the plain shear stress.

// Index loops over fixed-size arrays read better than iterator chains in the numerics, and negated
// comparisons are deliberate: they also reject NaN.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod comm;
pub mod dem;
pub mod element_test;
pub mod error;
pub mod ext;
pub mod io;
mod loaded;
pub mod math;
pub mod memory;
pub mod mpm;
pub mod par;
pub mod params;
pub mod plugin;
pub mod registry;
pub mod script;
pub mod simd;

pub use error::{GraniteError, Result};
pub use registry::{Plugin, Registry};
