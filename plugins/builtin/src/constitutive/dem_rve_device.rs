//! The RVEs of a `dem_rve` material on a device (`device: "gpu"`), indexed by material point: the
//! device holds the RVEs of the points this process owns (all of them outside MPI), in a batch
//! of its own order; this keeps which slot holds which point's RVE, and each point's stress and
//! cell after its last call (the P and P^min of its next plan, eqs. 4.2-4.3).

use granite_core::dem::Rve;
use granite_core::ext::{RveBatch, RveDevice, RveOrder, RveReport};
use granite_core::math::Voigt;
use granite_core::{GraniteError, Result};
use nalgebra::Matrix3;
use std::sync::{Arc, Mutex, MutexGuard};

pub(super) struct DeviceRves {
    device: Arc<dyn RveDevice>,
    held: Mutex<Held>,
}

#[derive(Default)]
struct Held {
    /// None until the material has points here.
    batch: Option<Box<dyn RveBatch>>,
    /// Per material point: its RVE's slot in `batch`, None where it lives in another process.
    slot: Vec<Option<usize>>,
    /// Per material point: its stress after its last call and its cell.
    last: Vec<(Voigt, Matrix3<f64>)>,
}

/// What a point's next plan needs of its RVE: its stress and cell.
fn measures(rve: &Rve) -> (Voigt, Matrix3<f64>) {
    (rve.stress(), rve.cell())
}

impl Held {
    fn slot(&self, point: usize) -> Result<usize> {
        self.slot
            .get(point)
            .copied()
            .flatten()
            .ok_or_else(|| GraniteError::Other(format!("no RVE of material point {point} on this process's device")))
    }

    /// Appends RVEs to the batch (opening it with the first ones); returns their first slot.
    fn push(&mut self, device: &dyn RveDevice, rves: Vec<Rve>) -> Result<usize> {
        let first = self.batch.as_ref().map(|b| b.len()).unwrap_or(0);
        if rves.is_empty() {
            return Ok(first);
        }
        match self.batch.as_mut() {
            Some(batch) => batch.push(rves)?,
            None => self.batch = Some(device.open(rves)?),
        }
        Ok(first)
    }

    /// Takes the RVEs of the points `drop` names off the device; the others keep their order.
    fn drop_rves(&mut self, drop: impl Fn(usize) -> bool) -> Result<()> {
        let Some(batch) = self.batch.as_mut() else { return Ok(()) };
        let mut keep_slot = vec![true; batch.len()];
        for (point, slot) in self.slot.iter().enumerate() {
            if let (Some(s), true) = (slot, drop(point)) {
                keep_slot[*s] = false;
            }
        }
        if keep_slot.iter().all(|&k| k) {
            return Ok(());
        }
        batch.retain(&keep_slot)?;
        let new_index: Vec<usize> = keep_slot
            .iter()
            .scan(0, |next, &k| {
                let at = *next;
                *next += usize::from(k);
                Some(at)
            })
            .collect();
        for (point, slot) in self.slot.iter_mut().enumerate() {
            *slot = match *slot {
                Some(s) if !drop(point) => Some(new_index[s]),
                _ => None,
            };
        }
        Ok(())
    }
}

impl DeviceRves {
    pub(super) fn new(device: Arc<dyn RveDevice>) -> DeviceRves {
        DeviceRves { device, held: Mutex::new(Held::default()) }
    }

    fn held(&self) -> Result<MutexGuard<'_, Held>> {
        self.held.lock().map_err(|_| GraniteError::Other("device RVEs poisoned".into()))
    }

    /// The device's name (`"gpu"`), as checkpoints record it.
    pub(super) fn name(&self) -> &str {
        self.device.name()
    }

    /// Material points appended: one entry each, with its RVE where it lives in this process.
    pub(super) fn add(&self, rves: Vec<Option<Rve>>) -> Result<()> {
        let mut held = self.held()?;
        let (mut here, mut points) = (Vec::new(), Vec::new());
        for rve in rves {
            let point = held.slot.len();
            held.slot.push(None);
            match rve {
                Some(rve) => {
                    held.last.push(measures(&rve));
                    points.push(point);
                    here.push(rve);
                }
                None => held.last.push(([0.0; 6], Matrix3::identity())),
            }
        }
        let first = held.push(self.device.as_ref(), here)?;
        for (k, point) in points.into_iter().enumerate() {
            held.slot[point] = Some(first + k);
        }
        Ok(())
    }

    /// Points whose flag is false keep their place but their RVEs leave this process.
    pub(super) fn release(&self, keep: &[bool]) -> Result<()> {
        self.held()?.drop_rves(|p| !keep.get(p).copied().unwrap_or(true))
    }

    /// Points whose flag is false are gone, RVE and all.
    pub(super) fn remove_points(&self, keep: &[bool]) -> Result<()> {
        let mut held = self.held()?;
        held.drop_rves(|p| !keep.get(p).copied().unwrap_or(true))?;
        let mut k = keep.iter();
        held.slot.retain(|_| *k.next().unwrap_or(&true));
        let mut k = keep.iter();
        held.last.retain(|_| *k.next().unwrap_or(&true));
        Ok(())
    }

    /// Puts `rve` as the RVE of `point` (a checkpoint's, or one moved here from another process).
    pub(super) fn put(&self, point: usize, rve: Rve) -> Result<()> {
        let mut held = self.held()?;
        if point >= held.slot.len() {
            return Err(GraniteError::Other(format!("no material point {point}")));
        }
        held.last[point] = measures(&rve);
        match held.slot[point] {
            Some(s) => held.batch.as_mut().map(|b| b.set(s, rve)).unwrap_or(Ok(())),
            None => {
                let first = held.push(self.device.as_ref(), vec![rve])?;
                held.slot[point] = Some(first);
                Ok(())
            }
        }
    }

    /// Makes the RVE of `to` a copy of the RVE of `from`.
    pub(super) fn copy(&self, from: usize, to: usize) -> Result<()> {
        let rve = self.get(from)?;
        self.put(to, rve)?;
        let mut held = self.held()?;
        held.last[to] = held.last[from];
        Ok(())
    }

    /// A copy of the RVE of `point` as it is now.
    pub(super) fn get(&self, point: usize) -> Result<Rve> {
        let mut held = self.held()?;
        let s = held.slot(point)?;
        held.batch.as_mut().ok_or_else(|| GraniteError::Other("no RVE on the device".into()))?.get(s)
    }

    /// Material points known (here or not).
    pub(super) fn points(&self) -> usize {
        self.held().map(|h| h.slot.len()).unwrap_or(0)
    }

    /// Steps the RVEs of the points `here` names, each by the order `order_of(point, stress,
    /// cell)` gives, in one submission (the others take no step); returns each such point's
    /// report, in point order.
    pub(super) fn step(
        &self,
        here: impl Fn(usize) -> bool,
        order_of: impl Fn(usize, &Voigt, &Matrix3<f64>) -> Result<RveOrder>,
    ) -> Result<Vec<(usize, RveReport)>> {
        let mut held = self.held()?;
        let Some(count) = held.batch.as_ref().map(|b| b.len()) else { return Ok(Vec::new()) };
        // RVEs that do not step this call (sharing another's, following another point) take
        // no step.
        let rest = RveOrder { velocity_gradient: Matrix3::zeros(), full_steps: 0, last_step: 0.0 };
        let mut orders = vec![rest; count];
        let mut points = Vec::new();
        for point in (0..held.slot.len()).filter(|&p| here(p)) {
            let s = held.slot(point)?;
            let (stress, cell) = &held.last[point];
            orders[s] = order_of(point, stress, cell)?;
            points.push((point, s));
        }
        let reports = held.batch.as_mut().map(|b| b.step(&orders)).unwrap_or_else(|| Ok(Vec::new()))?;
        let mut out = Vec::with_capacity(points.len());
        for (point, s) in points {
            let report = reports[s].clone();
            held.last[point] = (report.stress, report.cell);
            out.push((point, report));
        }
        Ok(out)
    }
}
