//! The Discrete Element Method engine (thesis chapters 1.1 and 2; YADE's feature set).
//!
//! One step: broad phase (cell lists + Verlet skin, rebuilt only when something moved more than
//! half the skin) -> contact geometry -> contact law, per contact in parallel -> forces gathered per
//! particle in a fixed order -> integration (gravity, Cundall damping, leapfrog).

pub mod bodies;
pub mod broad_phase;
pub mod cell;
pub mod clump;
pub mod contact_set;
pub mod contact_stage;
pub mod contacts;
pub mod delaunay;
pub mod energy;
pub mod generate;
pub mod inspect;
pub mod kind_stage;
pub mod kinds;
pub mod measures;
pub mod mesh_walls;
mod motion;
mod pairing;
pub mod particles;
pub mod picture;
mod pieces;
mod rebuild;
pub mod repose;
mod rigid;
mod rows;
pub mod rve;
pub mod sim;
pub mod stability;
pub mod state;
pub mod step;
pub mod voids;
pub mod walls;

pub use particles::Spheres;
pub use rve::Rve;
pub use sim::{DemMaterial, DemSim, DemWorld};
pub use walls::{Wall, WallShape};
