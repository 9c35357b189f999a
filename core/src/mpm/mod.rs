//! The Material Point Method engine (thesis chapter 3).

pub mod boundary;
pub mod checkpoint;
pub mod diagnostics;
pub mod fill;
pub mod grid;
pub mod mesh;
pub mod points;
pub mod shape;
pub mod sim;
pub mod spread;
pub mod step;

pub use boundary::{Boundary, Face, TimeFunction};
pub use diagnostics::Diagnostics;
pub use mesh::Mesh;
pub use points::Points;
pub use sim::{Material, MpmSim, OutOfMeshPolicy, ShapeFunctions, StressRate, StressScheme, VolumetricStrain};
