//! RVE devices: where the periodic DEM samples of MPMxDEM (`dem_rve`) are stepped when not on the
//! CPU threads. A device takes the whole batch of one MPM step, each RVE's velocity gradient and
//! DEM steps (thesis eqs. 4.1-4.5), and gives back each RVE's Love-Weber stress (eq. 4.7) and
//! contact counts; the RVEs stay on the device between calls.

use crate::dem::Rve;
use crate::error::Result;
use crate::math::Voigt;
use nalgebra::Matrix3;

/// What one RVE does in one call: full DEM steps of its own time step under a velocity gradient,
/// then possibly a shorter last step (eq. 4.4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RveOrder {
    pub velocity_gradient: Matrix3<f64>,
    pub full_steps: u64,
    /// Length of a last, shorter step, or 0.
    pub last_step: f64,
}

/// What one RVE reports after its steps.
#[derive(Debug, Clone, PartialEq)]
pub struct RveReport {
    /// Love-Weber stress of its sphere contacts (tension positive).
    pub stress: Voigt,
    /// Its periodic cell at the end.
    pub cell: Matrix3<f64>,
    /// Touching sphere pairs.
    pub contacts: usize,
    /// Contact ends summed over the spheres (twice the contacts).
    pub contact_ends: usize,
    /// Spheres with one contact, and with none.
    pub rattlers: usize,
    pub floaters: usize,
    /// DEM steps taken.
    pub steps: u64,
    /// Why it stopped before its last step (the CPU engine's words), if it did.
    pub failure: Option<String>,
    /// What its steps said for the user (a time step above its contacts' bound).
    pub events: Vec<String>,
}

impl RveReport {
    /// Mean contacts per sphere without rattlers and floaters (`Coordination::coordination_no_rattlers`).
    pub fn coordination_no_rattlers(&self, spheres: usize) -> f64 {
        let kept = spheres.saturating_sub(self.rattlers + self.floaters);
        if kept > 0 {
            (self.contact_ends - self.rattlers) as f64 / kept as f64
        } else {
            0.0
        }
    }
}

/// The device a law's options chose (`device: "gpu"`), as `sim.material` hands it to the law
/// among its objects.
pub struct RveDeviceChoice(pub std::sync::Arc<dyn RveDevice>);

/// A device by name (`"gpu"`): what `sim.material("dem_rve", #{ device: ... })` picks.
pub trait RveDevice: Send + Sync {
    fn name(&self) -> &str;
    /// Why these RVEs cannot run on this device (no adapter, a feature the kernels lack), or
    /// the batch holding them on it.
    fn open(&self, rves: Vec<Rve>) -> Result<Box<dyn RveBatch>>;
}

/// The RVEs of one material on a device, indexed by material point.
pub trait RveBatch: Send {
    /// The device's own name (the adapter's), for benchmarks and logs.
    fn device_name(&self) -> String;
    fn len(&self) -> usize;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Appends RVEs.
    fn push(&mut self, rves: Vec<Rve>) -> Result<()>;
    /// Keeps the RVEs whose flag is true, in order.
    fn retain(&mut self, keep: &[bool]) -> Result<()>;
    /// Steps every RVE by its order (one per RVE, in order) in one submission.
    fn step(&mut self, orders: &[RveOrder]) -> Result<Vec<RveReport>>;
    /// A copy of one RVE as it is now (checkpoints, outputs).
    fn get(&mut self, index: usize) -> Result<Rve>;
    /// Replaces one RVE.
    fn set(&mut self, index: usize, rve: Rve) -> Result<()>;
    /// What the device counted since the batch opened (benchmarks); all zero where it counts
    /// nothing.
    fn counters(&self) -> BatchCounters {
        BatchCounters::default()
    }
}

/// A batch's running counts, for benchmarks: differences of two readings cover what happened
/// between them.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BatchCounters {
    /// Calls of [`RveBatch::step`].
    pub calls: u64,
    /// Submissions to the device (its work and the copies back).
    pub submissions: u64,
    /// Distance tests of the candidate searches, and the spheres whose candidates were searched.
    pub pair_tests: u64,
    pub sphere_searches: u64,
    /// Bytes the batch holds on the device now.
    pub device_bytes: u64,
    /// Buffer sets the batch is split into (each within the device's binding limits).
    pub chunks: u64,
    /// Seconds the device spent in the batch's work, where it reports its own time (timestamps).
    pub device_seconds: Option<f64>,
}
