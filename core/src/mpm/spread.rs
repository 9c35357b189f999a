//! A material whose law keeps an object per point (an RVE) spread over the processes of a run.
//!
//! Every process holds the whole MPM (mesh, points, stresses, state variables) and takes the
//! same step; a spread material's objects live each in one process, its *owner*. In the stress
//! stage every process updates the points it owns, then one all-gather gives every process the
//! new stresses and state variables of all points. A point's update depends only on its own
//! object and inputs, and every process ends the stage with the same numbers, so the run is bit
//! for bit the run of one process, whatever the number of processes and whoever owns what.
//!
//! Objects cost different amounts to update (an RVE's DEM steps per increment follow its pressure
//! and strain rate, thesis eqs. 4.1-4.5). Each process times its points; the times travel with
//! the stresses, so every process knows every point's cost and, every `balance_every` steps,
//! computes the same new owners and moves the objects that change hands.

use crate::comm::{Comm, Reader, Writer};
use crate::error::{GraniteError, Result};
use crate::ext::{ConstitutiveLaw, LawBatch, PointObjects};
use crate::math::Voigt;
use rayon::prelude::*;
use std::time::Instant;

/// Steps between two balances unless the script says otherwise.
pub const DEFAULT_BALANCE_EVERY: u64 = 50;
/// Imbalance below which the owners stay as they are: moving an RVE costs its serialisation.
const BALANCE_TOLERANCE: f64 = 0.05;

/// Where a spread material's objects live, and what they cost.
pub struct Spread {
    comm: Comm,
    /// Rank holding each point's object.
    pub owner: Vec<u32>,
    /// Seconds each point's updates took since the last balance (known for every point).
    cost: Vec<f64>,
    /// Steps between two balances; 0 keeps the owners as they are.
    pub balance_every: u64,
    steps_since_balance: u64,
    pub stats: SpreadStats,
}

/// What the processes did, for the run log, summary.json and benchmarks.
#[derive(Debug, Clone, Default)]
pub struct SpreadStats {
    /// Per rank: seconds of wall time updating its own points.
    pub busy_s: Vec<f64>,
    /// Seconds this process spent in the stress stage (own updates, waiting and communicating).
    pub stage_s: f64,
    /// Seconds this process spent in the all-gather (waiting for the slowest included).
    pub gather_s: f64,
    /// Bytes this process received in all-gathers.
    pub gather_bytes: u64,
    pub stages: u64,
    /// Objects moved between processes by balancing.
    pub moved: u64,
}

/// The largest of the ranks' busy times over their mean, minus one (0: perfectly even).
pub fn imbalance(busy_s: &[f64]) -> f64 {
    let mean = busy_s.iter().sum::<f64>() / busy_s.len().max(1) as f64;
    let max = busy_s.iter().cloned().fold(0.0, f64::max);
    if mean > 0.0 {
        max / mean - 1.0
    } else {
        0.0
    }
}

/// The processes' share of a spread material's work, as the run log and summary.json give it.
#[derive(Debug, Clone)]
pub struct SpreadReport {
    /// Per rank: seconds updating its points; seconds in the stress stage (updates, waiting for
    /// the others, communicating); seconds in the all-gathers.
    pub busy_s: Vec<f64>,
    pub stage_s: Vec<f64>,
    pub gather_s: Vec<f64>,
    /// Bytes one process received in all-gathers (the largest over processes).
    pub gather_bytes: u64,
    pub stages: u64,
    pub moved: u64,
    /// Points each rank holds now.
    pub points: Vec<usize>,
}

impl SpreadReport {
    /// Per rank: the fraction of the stress stage spent updating its own points.
    pub fn busy_fraction(&self) -> Vec<f64> {
        self.busy_s.iter().zip(&self.stage_s).map(|(b, s)| if *s > 0.0 { (b / s).min(1.0) } else { 0.0 }).collect()
    }

    /// The busiest rank's time over the mean, minus one.
    pub fn imbalance(&self) -> f64 {
        imbalance(&self.busy_s)
    }

    pub fn line(&self) -> String {
        let busy: Vec<String> = self.busy_fraction().iter().map(|f| format!("{:.0} %", 100.0 * f)).collect();
        let per_stage = |x: f64| if self.stages > 0 { x / self.stages as f64 } else { 0.0 };
        let gather_us = 1e6 * per_stage(self.gather_s.iter().cloned().fold(0.0, f64::max));
        format!(
            "{} processes hold {:?} points; busy {} of the stress stage; imbalance {:.1} %; {} objects moved; \
             {:.0} us and {:.0} bytes of all-gather per step",
            self.busy_s.len(),
            self.points,
            busy.join(", "),
            100.0 * self.imbalance(),
            self.moved,
            gather_us,
            per_stage(self.gather_bytes as f64),
        )
    }

    /// Keys for summary.json (timings: they differ from run to run).
    pub fn summary(&self) -> Vec<(String, serde_json::Value)> {
        vec![
            ("processes".into(), self.busy_s.len().into()),
            ("rank_busy_fraction".into(), self.busy_fraction().into()),
            ("rank_imbalance".into(), self.imbalance().into()),
            ("rank_points".into(), self.points.clone().into()),
            ("objects_moved".into(), self.moved.into()),
        ]
    }
}

/// Takes in the point objects other processes sent: (point, JSON) records.
fn adopt_objects(law: &dyn PointObjects, incoming: Vec<Vec<u8>>) -> Result<()> {
    for bytes in incoming {
        let mut r = Reader::new(&bytes);
        while !r.done() {
            let point = r.u64()? as usize;
            let object = serde_json::from_slice(r.bytes()?)
                .map_err(|e| GraniteError::Other(format!("object of material point {point}: {e}")))?;
            law.adopt_point_object(point, object)?;
        }
    }
    Ok(())
}

impl Spread {
    pub fn new(comm: Comm) -> Spread {
        let size = comm.size();
        Spread {
            comm,
            owner: Vec::new(),
            cost: Vec::new(),
            balance_every: DEFAULT_BALANCE_EVERY,
            steps_since_balance: 0,
            stats: SpreadStats { busy_s: vec![0.0; size], ..Default::default() },
        }
    }

    pub fn rank(&self) -> usize {
        self.comm.rank()
    }

    pub fn size(&self) -> usize {
        self.comm.size()
    }

    /// Owners of `count` new points: each to the process holding the fewest points so far
    /// (lowest rank on ties), which interleaves a fill's rows over the processes. Returns which
    /// of them live here.
    pub fn add(&mut self, count: usize) -> Vec<bool> {
        let mut held = vec![0usize; self.size()];
        for &o in &self.owner {
            held[o as usize] += 1;
        }
        let me = self.rank() as u32;
        let mut here = Vec::with_capacity(count);
        for _ in 0..count {
            let r = (0..held.len()).min_by_key(|&r| (held[r], r)).unwrap_or(0);
            held[r] += 1;
            self.owner.push(r as u32);
            self.cost.push(0.0);
            here.push(r as u32 == me);
        }
        here
    }

    /// Points were removed: keep those whose flag is true.
    pub fn retain(&mut self, keep: &[bool]) {
        let mut k = keep.iter();
        self.owner.retain(|_| *k.next().unwrap_or(&true));
        let mut k = keep.iter();
        self.cost.retain(|_| *k.next().unwrap_or(&true));
    }

    /// Which points live here.
    pub fn here(&self) -> Vec<bool> {
        let me = self.rank() as u32;
        self.owner.iter().map(|&o| o == me).collect()
    }

    /// The stress stage of a spread material: this process updates its points, then all
    /// processes swap results. An update that fails in any process fails the stage in every
    /// process, with the lowest failing point's message and the rank that ran it.
    pub fn update(
        &mut self,
        law: &dyn ConstitutiveLaw,
        stress: &mut [Voigt],
        dstrain: &[Voigt],
        state: &mut [f64],
        stride: usize,
    ) -> Result<()> {
        let objects = law
            .point_objects()
            .ok_or_else(|| GraniteError::Other(format!("law {} keeps no objects to spread", law.name())))?;
        let started = Instant::now();
        let n = stress.len();
        let me = self.rank() as u32;
        let owner = &self.owner;
        // Laws without state variables still get one slot per point to split on; it is not passed.
        let mut no_state = vec![0.0; if stride == 0 { n } else { 0 }];
        let states: &mut [f64] = if stride == 0 { &mut no_state } else { state };
        let outcomes: Vec<(usize, f64, Result<()>)> = if objects.whole_batch() {
            // One call for all the points here (a device's submission), its time shared out.
            let here: Vec<bool> = owner.iter().map(|&o| o == me).collect();
            let first_here = here.iter().position(|&h| h);
            let batch = LawBatch { first: 0, stress: &mut *stress, dstrain, state: &mut states[..n * stride] };
            let t = Instant::now();
            match objects.update_where(&here, batch) {
                Ok(costs) => {
                    (0..n).filter(|&i| here[i]).map(|i| (i, costs.get(i).copied().unwrap_or(0.0), Ok(()))).collect()
                }
                Err(e) => first_here.map(|i| vec![(i, t.elapsed().as_secs_f64(), Err(e))]).unwrap_or_default(),
            }
        } else {
            stress
                .par_chunks_mut(1)
                .zip(dstrain.par_chunks(1))
                .zip(states.par_chunks_mut(stride.max(1)))
                .enumerate()
                .with_min_len(1)
                .filter(|(i, _)| owner[*i] == me)
                .map(|(i, ((s, de), st))| {
                    let t = Instant::now();
                    let st = &mut st[..stride];
                    let r = law.update(LawBatch { first: i, stress: s, dstrain: de, state: st });
                    (i, t.elapsed().as_secs_f64(), r)
                })
                .collect()
        };
        let busy = started.elapsed().as_secs_f64();
        let mut w = Writer::default();
        let failures: Vec<&(usize, f64, Result<()>)> = outcomes.iter().filter(|o| o.2.is_err()).collect();
        w.u64(failures.len() as u64);
        for (i, _, r) in failures {
            w.u64(*i as u64).str(&r.as_ref().err().map(|e| e.to_string()).unwrap_or_default());
        }
        match objects.pending_event() {
            Some((point, text)) => w.u64(1).u64(point as u64).str(&text),
            None => w.u64(0),
        };
        w.f64(busy);
        w.u64(outcomes.len() as u64);
        for (i, seconds, _) in &outcomes {
            w.f64s(&stress[*i]).f64s(&states[i * stride..(i + 1) * stride]).f64(*seconds);
        }
        let gather_started = Instant::now();
        let all = self.comm.all_gather(&w.0);
        self.stats.gather_s += gather_started.elapsed().as_secs_f64();
        self.stats.gather_bytes += all.iter().map(|b| b.len() as u64).sum::<u64>();
        let mut failed: Option<(usize, usize, String)> = None;
        let mut event: Option<(usize, String)> = None;
        // Each rank's header first, then its points' results, read in point order through one
        // reader per rank (one pass over the points, whatever the number of ranks).
        let mut readers = Vec::with_capacity(all.len());
        for (rank, bytes) in all.iter().enumerate() {
            let mut r = Reader::new(bytes);
            for _ in 0..r.u64()? {
                let (point, text) = (r.u64()? as usize, r.str()?);
                if failed.as_ref().is_none_or(|f| point < f.0) {
                    failed = Some((point, rank, text));
                }
            }
            if r.u64()? == 1 {
                let (point, text) = (r.u64()? as usize, r.str()?);
                if event.as_ref().is_none_or(|e| point < e.0) {
                    event = Some((point, text));
                }
            }
            self.stats.busy_s[rank] += r.f64()?;
            let count = r.u64()? as usize;
            readers.push((r, count));
        }
        for i in 0..n {
            let rank = self.owner[i] as usize;
            let (r, left) = &mut readers[rank];
            if *left == 0 {
                return Err(disagree(rank));
            }
            *left -= 1;
            if rank as u32 == me {
                // Our own numbers are already in place.
                r.skip_f64s(6 + stride)?;
            } else {
                r.f64s_into(&mut stress[i])?;
                r.f64s_into(&mut states[i * stride..(i + 1) * stride])?;
            }
            self.cost[i] += r.f64()?;
        }
        if let Some(rank) = readers.iter().position(|(r, left)| *left != 0 || !r.done()) {
            return Err(disagree(rank));
        }
        objects.set_pending_event(event);
        self.stats.stages += 1;
        self.stats.stage_s += started.elapsed().as_secs_f64();
        if let Some((_, rank, text)) = failed {
            return Err(GraniteError::Other(format!("{text} (rank {rank} of {})", self.size())));
        }
        self.steps_since_balance += 1;
        if self.balance_every > 0 && self.steps_since_balance >= self.balance_every && self.size() > 1 {
            self.balance(objects)?;
        }
        Ok(())
    }

    /// New owners from the measured costs, the same in every process; moves the objects that
    /// change hands.
    fn balance(&mut self, law: &dyn PointObjects) -> Result<()> {
        let new_owner = balanced_owners(&self.owner, &self.cost, self.size());
        self.steps_since_balance = 0;
        self.cost.iter_mut().for_each(|c| *c = 0.0);
        let me = self.rank() as u32;
        let mut outgoing = vec![Writer::default(); self.size()];
        let mut moved = 0;
        for (i, (&from, &to)) in self.owner.iter().zip(&new_owner).enumerate() {
            if from == to {
                continue;
            }
            moved += 1;
            if from == me {
                let object = serde_json::to_vec(&law.point_object(i)?)
                    .map_err(|e| GraniteError::Other(format!("object of material point {i}: {e}")))?;
                outgoing[to as usize].u64(i as u64).bytes(&object);
            }
        }
        if moved == 0 {
            return Ok(());
        }
        let incoming = self.comm.exchange(outgoing.into_iter().map(|w| w.0).collect());
        self.owner = new_owner;
        law.release_objects(&self.here());
        adopt_objects(law, incoming)?;
        self.stats.moved += moved;
        Ok(())
    }

    /// What every process did so far, in every process (a collective call).
    pub fn report(&self) -> Result<SpreadReport> {
        let mut w = Writer::default();
        w.f64(self.stats.stage_s).f64(self.stats.gather_s).u64(self.stats.gather_bytes);
        let all = self.comm.all_gather(&w.0);
        let mut report = SpreadReport {
            busy_s: self.stats.busy_s.clone(),
            stage_s: Vec::new(),
            gather_s: Vec::new(),
            gather_bytes: 0,
            stages: self.stats.stages,
            moved: self.stats.moved,
            points: vec![0; self.size()],
        };
        for bytes in &all {
            let mut r = Reader::new(bytes);
            report.stage_s.push(r.f64()?);
            report.gather_s.push(r.f64()?);
            report.gather_bytes = report.gather_bytes.max(r.u64()?);
        }
        for &o in &self.owner {
            report.points[o as usize] += 1;
        }
        Ok(report)
    }

    /// Copies point objects (from, to), the same list in every process: in place where one
    /// process owns both, else from the owner of `from` to the owner of `to` (collective).
    pub fn copy_objects(&mut self, law: &dyn PointObjects, copies: &[(usize, usize)]) -> Result<()> {
        let me = self.rank() as u32;
        let mut outgoing = vec![Writer::default(); self.size()];
        let mut across = false;
        for &(from, to) in copies {
            let (a, b) = (self.owner[from], self.owner[to]);
            if a == b {
                if a == me {
                    law.copy_object(from, to)?;
                }
                continue;
            }
            across = true;
            if a == me {
                let object = serde_json::to_vec(&law.point_object(from)?)
                    .map_err(|e| GraniteError::Other(format!("object of material point {from}: {e}")))?;
                outgoing[b as usize].u64(to as u64).bytes(&object);
            }
        }
        if !across {
            return Ok(());
        }
        adopt_objects(law, self.comm.exchange(outgoing.into_iter().map(|w| w.0).collect()))
    }

    /// The sum over the processes of one number each gives (collective).
    pub fn sum(&self, x: f64) -> Result<f64> {
        let mut w = Writer::default();
        w.f64(x);
        let mut total = 0.0;
        for bytes in self.comm.all_gather(&w.0) {
            total += Reader::new(&bytes).f64()?;
        }
        Ok(total)
    }

    /// Every point's object in point order on rank 0 (for a checkpoint); None elsewhere.
    pub fn gather_objects(&self, law: &dyn PointObjects) -> Result<Option<Vec<serde_json::Value>>> {
        let me = self.rank() as u32;
        let mut w = Writer::default();
        let mut failure = String::new();
        for (i, _) in self.owner.iter().enumerate().filter(|(_, &o)| o == me) {
            match law.point_object(i).and_then(|v| {
                serde_json::to_vec(&v).map_err(|e| GraniteError::Other(format!("object of material point {i}: {e}")))
            }) {
                Ok(bytes) => {
                    w.u64(i as u64).bytes(&bytes);
                }
                Err(e) if failure.is_empty() => failure = e.to_string(),
                Err(_) => {}
            }
        }
        let mut packet = Writer::default();
        packet.str(&failure).bytes(&w.0);
        let Some(all) = self.comm.gather_to_root(&packet.0) else { return Ok(None) };
        let mut objects: Vec<Option<serde_json::Value>> = vec![None; self.owner.len()];
        for (rank, bytes) in all.iter().enumerate() {
            let mut r = Reader::new(bytes);
            let failure = r.str()?;
            if !failure.is_empty() {
                return Err(GraniteError::Other(format!("{failure} (rank {rank})")));
            }
            let mut list = Reader::new(r.bytes()?);
            while !list.done() {
                let point = list.u64()? as usize;
                let value = serde_json::from_slice(list.bytes()?)
                    .map_err(|e| GraniteError::Other(format!("object of material point {point}: {e}")))?;
                if let Some(slot) = objects.get_mut(point) {
                    *slot = Some(value);
                }
            }
        }
        objects
            .into_iter()
            .enumerate()
            .map(|(i, o)| {
                o.ok_or_else(|| GraniteError::Other(format!("no process sent the object of material point {i}")))
            })
            .collect::<Result<Vec<_>>>()
            .map(Some)
    }
}

/// Rank `rank` sent results for other points than every process thinks it owns.
fn disagree(rank: usize) -> GraniteError {
    GraniteError::Other(format!(
        "rank {rank} sent results for other points than it owns: the processes disagree on the owners"
    ))
}

/// Owners that even out the processes' summed costs while moving few objects: repeatedly, the
/// point of the busiest process whose cost is nearest half the gap to the idlest one moves
/// there, while that narrows the gap and the busiest is more than the tolerance above the mean.
/// Deterministic: ties go to the lowest rank and the lowest point.
pub fn balanced_owners(owner: &[u32], cost: &[f64], size: usize) -> Vec<u32> {
    let mut owner = owner.to_vec();
    let mut load = vec![0.0; size];
    for (&o, &c) in owner.iter().zip(cost) {
        load[o as usize] += c;
    }
    let mean = load.iter().sum::<f64>() / size as f64;
    if !(mean > 0.0) {
        return owner;
    }
    for _ in 0..owner.len() {
        let busiest = (0..size).fold(0, |b, r| if load[r] > load[b] { r } else { b });
        let idlest = (0..size).fold(0, |b, r| if load[r] < load[b] { r } else { b });
        let gap = load[busiest] - load[idlest];
        if load[busiest] <= mean * (1.0 + BALANCE_TOLERANCE) || busiest == idlest {
            break;
        }
        let best = (0..owner.len())
            .filter(|&i| owner[i] as usize == busiest && cost[i] > 0.0 && cost[i] < gap)
            .min_by(|&a, &b| (cost[a] - gap / 2.0).abs().total_cmp(&(cost[b] - gap / 2.0).abs()).then(a.cmp(&b)));
        let Some(i) = best else { break };
        owner[i] = idlest as u32;
        load[busiest] -= cost[i];
        load[idlest] += cost[i];
    }
    owner
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn balancing_evens_out_costs_with_few_moves() {
        let load = |owner: &[u32], cost: &[f64], r: u32| -> f64 {
            owner.iter().zip(cost).filter(|(&o, _)| o == r).map(|(_, c)| c).sum()
        };
        let moves = |a: &[u32], b: &[u32]| a.iter().zip(b).filter(|(x, y)| x != y).count();
        // Eight equal points on rank 0, two on rank 1: three move, 5 and 5.
        let owner = vec![0, 0, 0, 0, 0, 0, 0, 0, 1, 1];
        let cost = vec![1.0; 10];
        let new = balanced_owners(&owner, &cost, 2);
        assert_eq!((load(&new, &cost, 0), load(&new, &cost, 1)), (5.0, 5.0));
        assert_eq!(moves(&owner, &new), 3);
        // Already even: nothing moves.
        assert_eq!(balanced_owners(&new, &cost, 2), new);
        // Three ranks, one costly point among cheap ones (loads 9, 2, 2): the costly point alone
        // sets the least possible busiest load, 6, and balancing gets there.
        let owner = vec![0, 0, 0, 0, 1, 1, 2, 2];
        let cost = vec![6.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0];
        let new = balanced_owners(&owner, &cost, 3);
        let loads: Vec<f64> = (0..3).map(|r| load(&new, &cost, r)).collect();
        assert_eq!(loads.iter().cloned().fold(0.0, f64::max), 6.0, "{loads:?}");
        assert_eq!(loads.iter().sum::<f64>(), 13.0);
        // No cost measured yet: nothing moves.
        assert_eq!(balanced_owners(&owner, &[0.0; 8], 3), owner);
    }

    #[test]
    fn imbalance_is_the_busiest_over_the_mean() {
        assert!((imbalance(&[3.0, 1.0]) - 0.5).abs() < 1e-12);
        assert_eq!(imbalance(&[2.0, 2.0]), 0.0);
    }
}
