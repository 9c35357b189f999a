//! Name-keyed registries of the extension points. A [`Plugin`] adds its factories to a registry;
//! insertion order is kept so listings are stable.

use crate::error::{GraniteError, Result};
use crate::ext::{
    ConstitutiveLaw, ConstitutiveLawFactory, ContactLaw, ContactLawFactory, ShapeModel, ShapeModelFactory,
    VelocityUpdate, VelocityUpdateFactory,
};
use crate::params::Params;
use indexmap::IndexMap;
use std::sync::Arc;

pub use crate::params::ParamMap;

pub trait Plugin {
    fn register(&self, registry: &mut Registry);
}

#[derive(Clone, Default)]
pub struct Registry {
    laws: IndexMap<String, Arc<dyn ConstitutiveLawFactory>>,
    velocity_updates: IndexMap<String, Arc<dyn VelocityUpdateFactory>>,
    contact_laws: IndexMap<String, Arc<dyn ContactLawFactory>>,
    shapes: IndexMap<String, Arc<dyn ShapeModelFactory>>,
    body_kinds: IndexMap<String, Arc<dyn crate::ext::BodyKindFactory>>,
    body_pair_geometries: IndexMap<String, Arc<dyn crate::ext::BodyPairGeometry>>,
    rve_devices: IndexMap<String, Arc<dyn crate::ext::RveDevice>>,
}

/// Exact match first, then case-insensitive: `flip` finds `FLIP`.
fn lookup<'a, T: ?Sized>(map: &'a IndexMap<String, Arc<T>>, name: &str, kind: &str) -> Result<&'a Arc<T>> {
    if let Some(f) = map.get(name) {
        return Ok(f);
    }
    map.iter().find(|(k, _)| k.eq_ignore_ascii_case(name)).map(|(_, f)| f).ok_or_else(|| GraniteError::Unknown {
        kind: kind.into(),
        name: name.into(),
        known: map.keys().cloned().collect::<Vec<_>>().join(", "),
    })
}

impl Registry {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn with(mut self, plugin: &dyn Plugin) -> Self {
        plugin.register(&mut self);
        self
    }

    pub fn add_law(&mut self, factory: Arc<dyn ConstitutiveLawFactory>) {
        self.laws.insert(factory.name().to_string(), factory);
    }

    /// Takes a law out (a plugin replacing it on request).
    pub fn remove_law(&mut self, name: &str) {
        self.laws.shift_remove(name);
    }

    pub fn add_velocity_update(&mut self, factory: Arc<dyn VelocityUpdateFactory>) {
        self.velocity_updates.insert(factory.name().to_string(), factory);
    }

    pub fn add_contact_law(&mut self, factory: Arc<dyn ContactLawFactory>) {
        self.contact_laws.insert(factory.name().to_string(), factory);
    }

    pub fn contact_law_names(&self) -> Vec<String> {
        self.contact_laws.keys().cloned().collect()
    }

    pub fn contact_law_factory(&self, name: &str) -> Result<&Arc<dyn ContactLawFactory>> {
        lookup(&self.contact_laws, name, "contact law")
    }

    pub fn build_contact_law(&self, name: &str, given: &ParamMap) -> Result<Box<dyn ContactLaw>> {
        let factory = self.contact_law_factory(name)?;
        let params = Params::resolve(&format!("contact law \"{}\"", factory.name()), factory.param_specs(), given)?;
        factory.build(params)
    }

    /// Adds a device the RVEs of `dem_rve` can run on (`device: "gpu"`).
    pub fn add_rve_device(&mut self, device: Arc<dyn crate::ext::RveDevice>) {
        self.rve_devices.insert(device.name().to_string(), device);
    }

    /// The RVE device of this name; "cpu" is the engine's own threads, not a device.
    pub fn rve_device(&self, name: &str) -> Result<&Arc<dyn crate::ext::RveDevice>> {
        lookup(&self.rve_devices, name, "RVE device").map_err(|_| {
            let known = self.rve_devices.keys().cloned().collect::<Vec<_>>();
            GraniteError::Setup(if name == "gpu" && known.is_empty() {
                "device \"gpu\": this granite was built without GPU support; build it with \
                 `cargo build --release --features gpu` (needs a Vulkan driver with 64-bit floats)"
                    .to_string()
            } else {
                format!(
                    "no RVE device \"{name}\": known are \"cpu\"{}",
                    known.iter().map(|k| format!(", \"{k}\"")).collect::<String>()
                )
            })
        })
    }

    pub fn add_shape(&mut self, factory: Arc<dyn ShapeModelFactory>) {
        self.shapes.insert(factory.name().to_string(), factory);
    }

    pub fn add_body_kind(&mut self, factory: Arc<dyn crate::ext::BodyKindFactory>) {
        self.body_kinds.insert(factory.name().to_string(), factory);
    }

    /// Adds the contact geometry of bodies of two families (`BodyPairGeometry::families`).
    pub fn add_body_pair_geometry(&mut self, geometry: Arc<dyn crate::ext::BodyPairGeometry>) {
        self.body_pair_geometries.insert(geometry.name(), geometry);
    }

    /// The geometries of pairs of body families, in the order they were added.
    pub fn body_pair_geometries(&self) -> Vec<Arc<dyn crate::ext::BodyPairGeometry>> {
        self.body_pair_geometries.values().cloned().collect()
    }

    pub fn body_kind_names(&self) -> Vec<String> {
        self.body_kinds.keys().cloned().collect()
    }

    pub fn body_kind(&self, name: &str) -> Result<&Arc<dyn crate::ext::BodyKindFactory>> {
        lookup(&self.body_kinds, name, "body kind")
    }

    /// A shape of body kind `kind` from given parameters.
    pub fn build_body_shape(&self, kind: &str, given: &ParamMap) -> Result<Arc<dyn crate::ext::BodyShape>> {
        self.body_kind(kind)?.build_from(given)
    }

    pub fn shape_names(&self) -> Vec<String> {
        self.shapes.keys().cloned().collect()
    }

    pub fn shape_factory(&self, name: &str) -> Result<&Arc<dyn ShapeModelFactory>> {
        lookup(&self.shapes, name, "shape model")
    }

    pub fn build_shape(&self, name: &str, given: &ParamMap) -> Result<Box<dyn ShapeModel>> {
        let factory = self.shape_factory(name)?;
        let params = Params::resolve(&format!("shape \"{}\"", factory.name()), factory.param_specs(), given)?;
        factory.build(params)
    }

    pub fn law_names(&self) -> Vec<String> {
        self.laws.keys().cloned().collect()
    }

    pub fn velocity_update_names(&self) -> Vec<String> {
        self.velocity_updates.keys().cloned().collect()
    }

    pub fn law_factory(&self, name: &str) -> Result<&Arc<dyn ConstitutiveLawFactory>> {
        lookup(&self.laws, name, "constitutive law")
    }

    pub fn velocity_update_factory(&self, name: &str) -> Result<&Arc<dyn VelocityUpdateFactory>> {
        lookup(&self.velocity_updates, name, "velocity update")
    }

    pub fn build_law(&self, name: &str, given: &ParamMap) -> Result<Box<dyn ConstitutiveLaw>> {
        self.build_law_with(name, given, &Default::default())
    }

    /// Builds a law from numbers and named objects (see [`crate::ext::constitutive::ObjectMap`]).
    pub fn build_law_with(
        &self,
        name: &str,
        given: &ParamMap,
        objects: &crate::ext::constitutive::ObjectMap,
    ) -> Result<Box<dyn ConstitutiveLaw>> {
        let factory = self.law_factory(name)?;
        let params = Params::resolve(&format!("law \"{}\"", factory.name()), factory.param_specs(), given)?;
        factory.build_with(params, objects)
    }

    pub fn build_velocity_update(&self, name: &str, given: &ParamMap) -> Result<Box<dyn VelocityUpdate>> {
        let factory = lookup(&self.velocity_updates, name, "velocity update")?;
        let params = Params::resolve(&format!("velocity update \"{}\"", factory.name()), factory.param_specs(), given)?;
        factory.build(params)
    }
}

impl crate::ext::contact::ContactLawSource for Registry {
    fn build_contact_law(&self, name: &str, given: &ParamMap) -> Result<Box<dyn ContactLaw>> {
        Registry::build_contact_law(self, name, given)
    }
    fn rve_device(&self, name: &str) -> Result<Arc<dyn crate::ext::RveDevice>> {
        Registry::rve_device(self, name).cloned()
    }
    fn body_kind(&self, name: &str) -> Result<Arc<dyn crate::ext::BodyKindFactory>> {
        Registry::body_kind(self, name).cloned()
    }
    fn body_pair_geometries(&self) -> Vec<Arc<dyn crate::ext::BodyPairGeometry>> {
        Registry::body_pair_geometries(self)
    }
}
