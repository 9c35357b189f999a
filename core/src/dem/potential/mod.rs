//! Potential particles (Houlsby 2009; Boon, Houlsby & Utili 2013; thesis 2.2.2.2): rounded convex
//! polyhedra given by a potential function, the thesis's second shape model beside clumps.

pub mod bodies;
pub mod contact;
mod scene;
pub mod shape;
mod stage;

pub use bodies::Potentials;
pub use contact::{detect, detect_plane, Placed, Pose};
pub use shape::PotentialShape;
