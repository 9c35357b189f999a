//! Constitutive laws: pure functions of (stress, strain increment, state) -> (new stress, new state),
//! called over batches of material points so that one virtual call serves many points.

use crate::error::Result;
use crate::ext::contact::ContactLawSource;
use crate::math::Voigt;
use crate::params::{ParamMap, ParamSpec, Params};

/// The points a law updates in one call. All slices have the same number of points `n`;
/// `state` holds `n * state_names().len()` values, point after point.
pub struct LawBatch<'a> {
    /// Index, within the material's points, of the first point of this batch (laws that keep
    /// per-point objects, like an RVE, find them with it).
    pub first: usize,
    /// Stress at the start of the increment on entry, updated stress on return (tension positive).
    pub stress: &'a mut [Voigt],
    /// Strain increment (engineering shear) of this step.
    pub dstrain: &'a [Voigt],
    /// State variables, point-major.
    pub state: &'a mut [f64],
}

impl LawBatch<'_> {
    pub fn len(&self) -> usize {
        self.stress.len()
    }
    pub fn is_empty(&self) -> bool {
        self.stress.is_empty()
    }
}

/// A constitutive law with its parameters fixed (one per material).
pub trait ConstitutiveLaw: Send + Sync {
    /// Registry name of the law (e.g. `mohr_coulomb`).
    fn name(&self) -> &str;
    /// Parameters in force, by name.
    fn params(&self) -> &Params;
    /// Names of the per-point state variables, in storage order.
    fn state_names(&self) -> &[&'static str] {
        &[]
    }
    /// Initial state of one point (defaults to zeros).
    fn init_state(&self, state: &mut [f64]) {
        state.fill(0.0);
    }
    /// Speed of the fastest (P) wave for a given density, used to check the time step.
    fn wave_speed(&self, _density: f64) -> Option<f64> {
        None
    }
    /// Updates stress and state of a batch of points from their strain increments.
    fn update(&self, batch: LawBatch<'_>) -> Result<()>;
    /// The law's per-point objects (an RVE per point), or None for a plain law.
    fn point_objects(&self) -> Option<&dyn PointObjects> {
        None
    }
}

/// What a law that keeps an object per material point (`dem_rve`: an RVE) does with those
/// objects beyond `ConstitutiveLaw::update`: make and drop them with the points, spread them over
/// the processes of a run, save them in checkpoints, picture them, report their work.
pub trait PointObjects: Send + Sync {
    /// `here.len()` points were appended to the material. Laws with per-point objects make one for
    /// each point whose flag is true; the others' objects live in other processes of the run.
    fn points_added(&self, _here: &[bool]) -> Result<()> {
        Ok(())
    }
    /// Whether the points' objects may live in different processes: a point's update reads and
    /// writes only its own object, stress, strain increment and state. A run over MPI spreads the
    /// objects of such laws over its processes (`mpm::spread`).
    fn spreadable(&self) -> bool {
        false
    }
    /// Whether `update` takes all the material's points in one call (a law that hands them to a
    /// device in one submission) rather than in parallel chunks.
    fn whole_batch(&self) -> bool {
        false
    }
    /// A whole-batch law's update of the points whose flag is true (the others' objects live in
    /// other processes; their entries are left as they are), in one call over all the material's
    /// points. Returns each point's share of the call's time (its cost, for balancing).
    fn update_where(&self, _here: &[bool], _batch: LawBatch<'_>) -> Result<Vec<f64>> {
        Err(crate::GraniteError::Other("this law updates its points one batch at a time".into()))
    }
    /// After the update of all the material's points (and, in a spread run, after every process
    /// has every point's result): what a law that couples its points does last, the same in
    /// every process (adaptive RVEs: followers take their leader's stress increment). Returns
    /// the point objects to copy, (from, to), before the next update (`copy_object`, or across
    /// processes `point_object` and `adopt_point_object`).
    fn complete_update(&self, _stress: &mut [Voigt], _state: &mut [f64]) -> Result<Vec<(usize, usize)>> {
        Ok(Vec::new())
    }
    /// Makes the object of point `to` a copy of point `from`'s, both in this process.
    fn copy_object(&self, from: usize, to: usize) -> Result<()> {
        Err(crate::GraniteError::Other(format!("this law cannot copy the object of point {from} to point {to}")))
    }
    /// Values for each row of series.csv, from the material's state variables (summed over the
    /// materials that give the same name).
    fn series(&self, _state: &[f64]) -> Vec<(&'static str, f64)> {
        Vec::new()
    }
    /// Entries for summary.json at the end of a run (`spared`: what this law's process-local
    /// savings came to, summed over the run's processes; see `process_savings`).
    fn run_summary(&self, _state: &[f64], _spared: f64) -> Vec<(String, serde_json::Value)> {
        Vec::new()
    }
    /// Work this process alone spared (a spread run sums it over processes for `run_summary`).
    fn process_savings(&self) -> f64 {
        0.0
    }
    /// Drops the objects of the points whose flag is false (they live in another process now).
    fn release_objects(&self, _keep: &[bool]) {}
    /// One point's object as JSON, to move it to another process or gather it into a checkpoint.
    fn point_object(&self, point: usize) -> Result<serde_json::Value>;
    /// Takes in the object `point_object` wrote for `point` in another process.
    fn adopt_point_object(&self, point: usize, object: serde_json::Value) -> Result<()>;
    /// What `save_objects` writes, from every point's `point_object` in point order (gathered
    /// from the processes that hold them).
    fn save_objects_from(&self, _points: Vec<serde_json::Value>) -> Result<Option<serde_json::Value>> {
        Ok(None)
    }
    /// A law that tells one event for all its points (the lowest point's): the event it holds
    /// for the points of this process, if any. A spread run gathers these and puts the one of
    /// the lowest point back into every process with `set_pending_event` before `take_events`.
    fn pending_event(&self) -> Option<(usize, String)> {
        None
    }
    fn set_pending_event(&self, _event: Option<(usize, String)>) {}
    /// Points of the material were removed: keep those whose flag is true, in order.
    fn points_removed(&self, _keep: &[bool]) {}
    /// The law's own per-point objects as JSON for a checkpoint (None: it has none).
    fn save_objects(&self) -> Result<Option<serde_json::Value>> {
        Ok(None)
    }
    /// A picture of one point's object (e.g. its RVE's particles) for ParaView: positions and
    /// per-particle fields, or None when the law has no such object.
    fn object_frame(&self, _point: usize) -> Option<(Vec<crate::math::Vec3>, Vec<crate::io::vtk::Field>)> {
        None
    }
    /// Memory held per point by the law's own objects, in bytes (0 for plain state variables).
    fn bytes_per_point(&self) -> usize {
        0
    }
    /// What the law has to tell the user since it was last asked (warnings, not errors); the
    /// simulation passes it on with its events.
    fn take_events(&self) -> Vec<String> {
        Vec::new()
    }
}

/// Non-numeric inputs of a law by name (e.g. a prepared DEM sample for `dem_rve`).
pub type ObjectMap = indexmap::IndexMap<String, std::sync::Arc<dyn std::any::Any + Send + Sync>>;

/// Builds a law from user parameters; this is what the registry stores under the law's name.
pub trait ConstitutiveLawFactory: Send + Sync {
    fn name(&self) -> &str;
    fn param_specs(&self) -> &[ParamSpec];
    /// Validates the parameters (a clear error names any bad one) and builds the law.
    fn build(&self, params: Params) -> Result<Box<dyn ConstitutiveLaw>>;
    /// Builds with non-numeric inputs too; laws that take none refuse any.
    fn build_with(&self, params: Params, objects: &ObjectMap) -> Result<Box<dyn ConstitutiveLaw>> {
        if let Some(name) = objects.keys().next() {
            return Err(crate::GraniteError::Unknown {
                kind: format!("input of {}", params.owner()),
                name: name.clone(),
                known: "numbers only".into(),
            });
        }
        self.build(params)
    }
    fn description(&self) -> &str {
        ""
    }
    /// Rebuilds a law with per-point objects from a checkpoint (`objects` from `save_objects`).
    fn restore(
        &self,
        given: &ParamMap,
        objects: serde_json::Value,
        contact_laws: &dyn ContactLawSource,
    ) -> Result<Box<dyn ConstitutiveLaw>> {
        let _ = (given, objects, contact_laws);
        Err(crate::GraniteError::Other(format!("law {} cannot be restored from a checkpoint", self.name())))
    }
}
