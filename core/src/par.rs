//! Parallel loops over pieces of data, for stages run every time step.
//!
//! One stage is one `rayon::broadcast`. Worker `t` of the current pool owns the `t`-th run of
//! consecutive pieces (the runs laid round the pieces as on a ring, see `Runs::piece_at`) and claims
//! them one by one from its front; when its run is done it claims what is left of the others'
//! runs from their back. Balanced stages keep each piece on the same worker
//! from one step to the next (its data stays in that core's cache); uneven ones, like the
//! contacts at the bottom of a settling heap, still balance. On small DEM systems, where a stage
//! lasts tens of microseconds, this costs less than rayon's recursive splitting of zipped
//! iterators. Results never depend on which worker ran a piece: each piece is computed on its own
//! and results come back in piece order. Two stages over the same pieces, the second of which may
//! change what the first reads, run in one broadcast with [`run_pieces_then`]. Where each worker
//! holds too few pieces to take any over, the caller can cut them to the workers' speeds instead
//! ([`WorkerSpeeds`], [`owners`], [`piece_starts`]).

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::Mutex;

/// Pieces per worker at most: enough for a worker that finishes early to find pieces to take
/// over, few enough that cutting a stage up, which the calling thread does alone every time
/// step, costs little (about 0.15 us a piece).
const PIECES_PER_WORKER: usize = 16;

/// Spin-loop hints a worker out of pieces waits through before it starts yielding its core
/// (a few microseconds).
const SPINS_BEFORE_YIELDING: u32 = 4096;

/// Into how many pieces to cut `len` items so each holds at least `min_per_piece` (one piece
/// means: run on the calling thread; so does a pool of one thread).
pub fn piece_count(len: usize, min_per_piece: usize) -> usize {
    let workers = rayon::current_num_threads();
    if workers == 1 {
        return 1;
    }
    (len / min_per_piece.max(1)).clamp(1, workers * PIECES_PER_WORKER)
}

/// How many workers of the current pool take part in a stage of `pieces` pieces: one run of
/// pieces each.
pub fn workers_for(pieces: usize) -> usize {
    rayon::current_num_threads().clamp(1, pieces.max(1))
}

/// The worker of the current pool whose run holds each of `pieces` pieces (see `Runs::piece_at`).
pub fn owners(pieces: usize) -> Vec<usize> {
    let runs = Runs::in_pool(pieces);
    (0..pieces).map(|p| runs.owner(p)).collect()
}

/// Weight of the latest step in [`WorkerSpeeds`]: the last ten steps or so count.
const SPEED_MEMORY: f64 = 0.1;
/// A step's timing is clipped to within this factor of the estimate before it is learnt.
const SPEED_STEP_AT_MOST: f64 = 1.5;

/// How long each worker of a pool has lately taken per unit of work, learnt from the pieces it
/// ran, so that the next cut gives a slower core less work: on a shared machine one core can run
/// a third slower than the other for tens of milliseconds, longer than a stage of a small system
/// (in the 1500-sphere RVE on two workers each holds two pieces of about 60 us, too few to take
/// over one from the other in the middle of a stage).
#[derive(Debug, Clone, Default)]
pub struct WorkerSpeeds {
    seconds_per_unit: Vec<f64>,
}

impl WorkerSpeeds {
    /// Learns from one stage's pieces: `(worker, units of work, seconds)` for each, where
    /// `worker` ran it. A worker that ran nothing keeps its estimate.
    pub fn learn(&mut self, workers: usize, pieces: impl Iterator<Item = (usize, f64, f64)>) {
        if self.seconds_per_unit.len() != workers {
            self.seconds_per_unit = vec![f64::NAN; workers];
        }
        let mut sums = vec![(0.0, 0.0); workers];
        for (w, units, seconds) in pieces {
            if let Some(sum) = sums.get_mut(w) {
                *sum = (sum.0 + seconds, sum.1 + units);
            }
        }
        for (estimate, (seconds, units)) in self.seconds_per_unit.iter_mut().zip(sums) {
            if units > 0.0 && seconds > 0.0 && seconds.is_finite() {
                let now = seconds / units;
                *estimate = if estimate.is_nan() {
                    now
                } else {
                    // One stage in which the thread was put off its core for a millisecond
                    // tells nothing of the next ones.
                    let now = now.clamp(*estimate / SPEED_STEP_AT_MOST, *estimate * SPEED_STEP_AT_MOST);
                    *estimate + SPEED_MEMORY * (now - *estimate)
                };
            }
        }
    }

    /// How many workers it holds an estimate for.
    pub fn workers(&self) -> usize {
        self.seconds_per_unit.len()
    }

    /// The share of the work to give each of `workers` workers so that they finish together:
    /// equal until every one has been timed, and never below half an equal share (a worker
    /// stalled for a while must not be left out of the next stages).
    pub fn shares(&self, workers: usize) -> Vec<f64> {
        let equal = 1.0 / workers.max(1) as f64;
        if self.seconds_per_unit.len() != workers || self.seconds_per_unit.iter().any(|s| !(s.is_finite() && *s > 0.0))
        {
            return vec![equal; workers];
        }
        let speeds: Vec<f64> = self.seconds_per_unit.iter().map(|s| 1.0 / s).collect();
        let floor = 0.5 * equal;
        // Workers held at the floor, and the rest shared in proportion to speed; holding one
        // there lowers the others' shares, so repeat until none falls below it.
        let mut held = vec![false; workers];
        loop {
            let free_speed: f64 = speeds.iter().zip(&held).filter(|(_, h)| !**h).map(|(v, _)| v).sum();
            let left = 1.0 - floor * held.iter().filter(|h| **h).count() as f64;
            let shares: Vec<f64> =
                speeds.iter().zip(&held).map(|(v, h)| if *h { floor } else { v / free_speed * left }).collect();
            let below: Vec<usize> = (0..workers).filter(|&w| !held[w] && shares[w] < floor).collect();
            if below.is_empty() {
                return shares;
            }
            below.into_iter().for_each(|w| held[w] = true);
        }
    }
}

/// Where each piece should start, as the fraction of the work before it, then 1: worker `w`
/// gets `shares[w]` of the work, split equally between the pieces it owns (`owners`).
pub fn piece_starts(owners: &[usize], shares: &[f64]) -> Vec<f64> {
    let mut held = vec![0usize; shares.len()];
    owners.iter().for_each(|&w| held[w] += 1);
    let mut starts = Vec::with_capacity(owners.len() + 1);
    let mut before = 0.0;
    for &w in owners {
        starts.push(before);
        before += shares[w] / held[w] as f64;
    }
    starts.push(1.0);
    starts
}

/// Runs `work` on every piece, spread over the workers of the current pool, and returns the
/// results in piece order. A single piece, or a pool of one thread, runs on the calling thread.
pub fn run_pieces<T: Send, R: Send>(pieces: Vec<T>, work: impl Fn(T) -> R + Sync) -> Vec<R> {
    if pieces.len() <= 1 || rayon::current_num_threads() == 1 {
        return pieces.into_iter().map(work).collect();
    }
    let n = pieces.len();
    let slots: Vec<Mutex<Option<T>>> = pieces.into_iter().map(|p| Mutex::new(Some(p))).collect();
    let results: Vec<Mutex<Option<R>>> = (0..n).map(|_| Mutex::new(None)).collect();
    let runs = Runs::in_pool(n);
    // What is left of each run: its owner takes from the front, helpers from the back, so the
    // owner's pieces stay its own from one step to the next wherever the two meet.
    let left = runs.left();
    let done = AtomicUsize::new(0);
    rayon::broadcast(|ctx| {
        runs.claim_each(&left, ctx.index(), |t| {
            let _counted = Finished(&done);
            let piece = slots[t].lock().unwrap_or_else(|e| e.into_inner()).take();
            if let Some(piece) = piece {
                let out = work(piece);
                *results[t].lock().unwrap_or_else(|e| e.into_inner()) = Some(out);
            }
        });
        // The stage ends when its last piece does. A worker out of pieces waits for that here,
        // awake, rather than in the pool, which puts a thread to sleep after some tens of
        // microseconds idle: waking it for the next stage then took 30-50 us on a 2-core virtual
        // machine, as long as a small stage.
        wait_until(|| done.load(Ordering::Acquire) == n);
    });
    in_piece_order(results)
}

/// Runs two stages over the same pieces in one broadcast, and returns the second's results in
/// piece order: `first(p)` for every piece `p`, then `second(p)`. `first(q)` may read the data of
/// pieces `reads_from[q]..=q` and `second(p)` may change piece `p`'s, so `second(p)` waits until
/// every `first(q)` that reads piece `p` has finished. A worker out of first-stage pieces goes on
/// with second-stage pieces that are ready, instead of waiting for the slowest first-stage piece
/// (on two workers whose speeds differ, as a shared machine's cores do from moment to moment, one
/// of them always waited for the other); and the join and start between two broadcasts go.
pub fn run_pieces_then<R: Send>(
    reads_from: &[usize],
    first: impl Fn(usize) + Sync,
    second: impl Fn(usize) -> R + Sync,
) -> Vec<R> {
    let n = reads_from.len();
    if n <= 1 || rayon::current_num_threads() == 1 {
        (0..n).for_each(&first);
        return (0..n).map(second).collect();
    }
    let runs = Runs::in_pool(n);
    let left = runs.left();
    let first_done: Vec<AtomicBool> = (0..n).map(|_| AtomicBool::new(false)).collect();
    let second_taken: Vec<AtomicBool> = (0..n).map(|_| AtomicBool::new(false)).collect();
    let results: Vec<Mutex<Option<R>>> = (0..n).map(|_| Mutex::new(None)).collect();
    let done = AtomicUsize::new(0);
    // No unfinished first(q) reads piece p. Every first-stage piece has been claimed before any
    // worker waits on this, and a first-stage piece waits for nothing, so the wait ends.
    let ready = |p: usize| (p..n).all(|q| reads_from[q] > p || first_done[q].load(Ordering::Acquire));
    rayon::broadcast(|ctx| {
        runs.claim_each(&left, ctx.index(), |t| {
            let _finished = Flag(&first_done[t]);
            first(t);
        });
        // Own pieces first (their data is in this core's cache), from the last: in the DEM stages
        // a piece's first stage reads the pieces before it, so the last pieces are ready first.
        let own = (0..n).rev().filter(|&p| runs.owner(p) == ctx.index());
        for p in own.chain((0..n).rev()) {
            if second_taken[p].swap(true, Ordering::AcqRel) {
                continue;
            }
            let _counted = Finished(&done);
            wait_until(|| ready(p));
            let out = second(p);
            *results[p].lock().unwrap_or_else(|e| e.into_inner()) = Some(out);
        }
        wait_until(|| done.load(Ordering::Acquire) == n);
    });
    in_piece_order(results)
}

fn in_piece_order<R>(results: Vec<Mutex<Option<R>>>) -> Vec<R> {
    results.into_iter().map(|r| r.into_inner().unwrap_or_else(|e| e.into_inner()).expect("every piece ran")).collect()
}

/// Waits, awake, until `ready()`: a short spin, then yielding the core in case more threads than
/// cores were asked for.
fn wait_until(ready: impl Fn() -> bool) {
    let mut spins = 0u32;
    while !ready() {
        if spins < SPINS_BEFORE_YIELDING {
            spins += 1;
            std::hint::spin_loop();
        } else {
            std::thread::yield_now();
        }
    }
}

/// How a stage's pieces are dealt out: `runs` runs of consecutive positions, one per worker, on a
/// ring of `pieces` positions.
struct Runs {
    pieces: usize,
    runs: usize,
}

impl Runs {
    /// The runs of the current pool's workers over `pieces` pieces.
    fn in_pool(pieces: usize) -> Runs {
        Runs { pieces, runs: workers_for(pieces) }
    }

    /// The first position of run `r` (of `runs`, then the count).
    fn start(&self, r: usize) -> usize {
        r * self.pieces / self.runs
    }

    /// What is left of each run to claim (see [`claim`]): all of it.
    fn left(&self) -> Vec<AtomicU64> {
        (0..self.runs).map(|r| AtomicU64::new(pack(self.start(r), self.start(r + 1)))).collect()
    }

    /// The worker whose run holds piece `p`.
    fn owner(&self, p: usize) -> usize {
        let at = (p + self.start(1) / 2) % self.pieces;
        (0..self.runs).rev().find(|&r| self.start(r) <= at).unwrap_or(0)
    }

    /// Runs `work` on pieces as worker `worker` claims them: its own run from the front, then
    /// what is left of the others' runs from their back (`left`: what is left of each run).
    fn claim_each(&self, left: &[AtomicU64], worker: usize, mut work: impl FnMut(usize)) {
        for (k, r) in (0..self.runs).map(|k| (k, (worker + k) % self.runs)) {
            while let Some(at) = claim(&left[r], k == 0) {
                work(self.piece_at(at));
            }
        }
    }

    /// The piece at position `at`: the runs start half a run before piece 0, so the first worker
    /// owns the last pieces and the first ones.
    ///
    /// Why: in the DEM stages a pair between two workers' runs belongs to the later run, whose worker
    /// computes it reading the other's spheres, and hands its load over to the earlier run's worker,
    /// which reads it from the other core's cache in the gather. With runs from piece 0 the first
    /// worker would only receive such loads and the last would only compute such pairs; in a
    /// periodic cell the pairs that wrap round from the last spheres to the first cross that same
    /// boundary, so both stages were lopsided (in the 1500-sphere RVE on two workers the gather's
    /// two pieces that received them took 15-17 us against 9-12 us). Half a run in, every worker has
    /// one boundary of each kind.
    fn piece_at(&self, at: usize) -> usize {
        (at + self.pieces - self.start(1) / 2) % self.pieces
    }
}

/// Counts a piece as finished when dropped, also when its work panicked: the other workers then
/// stop waiting, and the panic reaches the caller instead of leaving them waiting for ever.
struct Finished<'a>(&'a AtomicUsize);

impl Drop for Finished<'_> {
    fn drop(&mut self) {
        self.0.fetch_add(1, Ordering::Release);
    }
}

/// Marks a first-stage piece as finished when dropped, also when its work panicked (see
/// [`Finished`]).
struct Flag<'a>(&'a AtomicBool);

impl Drop for Flag<'_> {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Release);
    }
}

/// A range `[front, back)` of piece indices in one word.
fn pack(front: usize, back: usize) -> u64 {
    ((back as u64) << 32) | front as u64
}

/// Takes one piece index off the front (`own`) or the back of a range, or None when it is empty.
fn claim(range: &AtomicU64, own: bool) -> Option<usize> {
    let mut current = range.load(Ordering::Relaxed);
    loop {
        let (front, back) = ((current & 0xffff_ffff) as usize, (current >> 32) as usize);
        if front >= back {
            return None;
        }
        let (taken, next) = if own { (front, pack(front + 1, back)) } else { (back - 1, pack(front, back - 1)) };
        match range.compare_exchange_weak(current, next, Ordering::AcqRel, Ordering::Relaxed) {
            Ok(_) => return Some(taken),
            Err(seen) => current = seen,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_piece_runs_once_and_results_keep_piece_order() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let out = pool.install(|| run_pieces((0..50).collect(), |p: usize| p * 10));
        assert_eq!(out, (0..50).map(|p| p * 10).collect::<Vec<_>>());
        assert_eq!(pool.install(|| piece_count(1000, 300)), 3);
        assert_eq!(pool.install(|| piece_count(100, 300)), 1);
        let single = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        assert_eq!(single.install(|| piece_count(1000, 300)), 1);
    }

    #[test]
    fn every_worker_computes_pairs_across_one_run_boundary_and_receives_loads_across_one() {
        // Pieces on a ring (a periodic cell): the pair across the boundary between pieces p and
        // p + 1 belongs to p + 1, and across the wrap (n - 1 to 0) to n - 1, the larger index.
        for (n, runs) in [(4, 2), (8, 2), (12, 3), (32, 2), (26, 2)] {
            let deal = Runs { pieces: n, runs };
            let owner: Vec<usize> = (0..runs)
                .flat_map(|r| (deal.start(r)..deal.start(r + 1)).map(move |at| (at, r)))
                .map(|(at, r)| (deal.piece_at(at), r))
                .fold(vec![usize::MAX; n], |mut owner, (piece, r)| {
                    owner[piece] = r;
                    owner
                });
            assert!(owner.iter().all(|&r| r < runs), "every piece has one owner");
            assert!((0..n).all(|p| deal.owner(p) == owner[p]), "{n} pieces on {runs} workers: owners");
            let (mut computes, mut receives) = (vec![0; runs], vec![0; runs]);
            for p in 0..n {
                let (low, high) = (p, (p + 1) % n);
                let holder = low.max(high);
                let other = low.min(high);
                if owner[holder] != owner[other] {
                    computes[owner[holder]] += 1;
                    receives[owner[other]] += 1;
                }
            }
            assert_eq!(computes, vec![1; runs], "{n} pieces on {runs} workers: pair boundaries computed");
            assert_eq!(receives, vec![1; runs], "{n} pieces on {runs} workers: loads received");
        }
    }

    #[test]
    fn shares_follow_the_workers_speeds_but_not_one_stalled_stage() {
        let mut speeds = WorkerSpeeds::default();
        assert_eq!(speeds.shares(2), vec![0.5, 0.5], "equal before any timing");
        // Worker 1 ran 300 units in 0.9 ms, worker 0 twice as many in the same time.
        speeds.learn(2, [(0, 400.0, 6e-4), (1, 300.0, 9e-4), (0, 200.0, 3e-4)].into_iter());
        let shares = speeds.shares(2);
        assert!((shares[0] - 2.0 / 3.0).abs() < 1e-12, "{shares:?}");
        // A stage in which worker 1 was put off its core for 10 ms moves its estimate by at most
        // SPEED_MEMORY * (SPEED_STEP_AT_MOST - 1).
        speeds.learn(2, [(0, 600.0, 9e-4), (1, 300.0, 1e-2)].into_iter());
        let after = speeds.shares(2);
        let slower = 1.0 + SPEED_MEMORY * (SPEED_STEP_AT_MOST - 1.0);
        let expected = 1.0 / (1.0 + 0.5 / slower);
        assert!((after[0] - expected).abs() < 1e-12, "{after:?}, expected worker 0 at {expected}");
        // Never below half an equal share.
        let mut stalled = WorkerSpeeds::default();
        stalled.learn(2, [(0, 1.0, 1e-9), (1, 1.0, 1e-3)].into_iter());
        assert_eq!(stalled.shares(2), vec![0.75, 0.25]);
    }

    #[test]
    fn a_second_stage_piece_waits_for_every_first_stage_piece_that_reads_it() {
        use std::sync::atomic::AtomicBool;
        // Eight pieces on a ring: first(q) reads q - 1 and q, and the last one also piece 0.
        let n = 8;
        let mut reads_from: Vec<usize> = (0..n).map(|q: usize| q.saturating_sub(1)).collect();
        reads_from[n - 1] = 0;
        let finished: Vec<AtomicBool> = (0..n).map(|_| AtomicBool::new(false)).collect();
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        for round in 0..20 {
            let out = pool.install(|| {
                run_pieces_then(
                    &reads_from,
                    |q| {
                        // Uneven first stages, so that the second stage of the other worker's
                        // pieces would start early if it did not wait.
                        if (q + round) % 3 == 0 {
                            std::thread::sleep(std::time::Duration::from_micros(300));
                        }
                        finished[q].store(true, Ordering::Release);
                    },
                    |p| {
                        let unfinished: Vec<usize> =
                            (p..n).filter(|&q| reads_from[q] <= p && !finished[q].load(Ordering::Acquire)).collect();
                        (p, unfinished)
                    },
                )
            });
            for (p, (piece, unfinished)) in out.into_iter().enumerate() {
                assert_eq!(piece, p, "results in piece order");
                assert!(unfinished.is_empty(), "round {round}: piece {p} moved while {unfinished:?} still read it");
            }
            finished.iter().for_each(|f| f.store(false, Ordering::Relaxed));
        }
    }

    #[test]
    fn a_panicking_piece_reaches_the_caller_instead_of_leaving_the_others_waiting() {
        let fails = |p: usize| assert!(p != 5, "piece {p} fails");
        let reads_from: Vec<usize> = (0..8usize).map(|q| q.saturating_sub(1)).collect();
        type Stage = Box<dyn Fn() + Send + Sync>;
        let stages: [(&str, Stage); 3] = [
            ("one stage", Box::new(move || drop(run_pieces((0..8).collect(), fails)))),
            (
                "first of two",
                Box::new({
                    let reads_from = reads_from.clone();
                    move || drop(run_pieces_then(&reads_from, fails, |_| ()))
                }),
            ),
            ("second of two", Box::new(move || drop(run_pieces_then(&reads_from, |_| (), fails)))),
        ];
        for (stage, run) in stages {
            let (sender, receiver) = std::sync::mpsc::channel();
            std::thread::spawn(move || {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
                let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| pool.install(&run)));
                sender.send(outcome.is_err()).ok();
            });
            let outcome = receiver.recv_timeout(std::time::Duration::from_secs(30));
            assert_eq!(outcome, Ok(true), "{stage}: the panic must reach the caller, not leave the others waiting");
        }
    }
}
