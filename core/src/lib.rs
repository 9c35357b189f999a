//! granite-core: the engine and its extension points.
//!
//! Sign convention everywhere: continuum mechanics, tension positive (as in CB-Geo MPM).
//! Tensors travel as Voigt 6-vectors in the order `xx, yy, zz, xy, yz, xz`; strains carry the
//! engineering shear (`gamma_xy = 2 eps_xy`), stresses the plain shear stress.

// Index loops over fixed-size arrays read better than iterator chains in the numerics, and negated
// comparisons are deliberate: they also reject NaN.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

/// `eprintln!` that never panics: with standard error closed or full (`2>/dev/full`, a batch
/// killed under its runs) the line is lost, and the run goes on; its warnings are also kept in
/// summary.json.
#[macro_export]
macro_rules! errln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($arg)*);
    }};
}

/// `println!` that never panics (standard output closed, a pipe whose reader left).
#[macro_export]
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($arg)*);
    }};
}

/// `print!` that never panics.
#[macro_export]
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = write!(std::io::stdout(), $($arg)*);
    }};
}

pub mod box_bins;
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
pub mod region;
pub mod registry;
pub mod simd;

pub use error::{GraniteError, Result};
pub use registry::{Plugin, Registry};
