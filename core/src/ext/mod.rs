//! Extension points: each is a trait, plus a factory trait that the name-keyed [`Registry`]
//! stores. Built-in implementations live in the `granite-plugins` crate; nothing here names them.
//!
//! [`Registry`]: crate::registry::Registry

pub mod body;
pub mod constitutive;
pub mod contact;
pub mod rve;
pub mod shape;
pub mod velocity_update;

pub use body::{BodyGeometry, BodyKindFactory, BodyPairGeometry, BodyShape, PlacedBodies};
pub use constitutive::{ConstitutiveLaw, ConstitutiveLawFactory, LawBatch, PointObjects};
pub use contact::{ContactBatch, ContactLaw, ContactLawFactory, DeviceLaw, PairInfo};
pub use rve::{BatchCounters, RveBatch, RveDevice, RveOrder, RveReport};
pub use shape::{ShapeModel, ShapeModelFactory};
pub use velocity_update::{G2pBatch, VelocityUpdate, VelocityUpdateFactory};
