//! Potential particles (Houlsby 2009; Boon, Houlsby & Utili 2013; thesis 2.2.2.2): rounded convex
//! polyhedra given by a potential function, the thesis's second shape model beside clumps.

pub mod contact;
pub mod shape;

pub use contact::{detect, Placed, Pose};
pub use shape::PotentialShape;
