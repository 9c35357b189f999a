//! Workers kept at hand between the parallel stages of one simulation.
//!
//! A DEM step on a few thousand spheres is one stage of 100-300 us. Started with
//! `rayon::broadcast`, the other workers come back to rayon's pool after every stage; there a worker
//! with nothing to do yields its core some 32 times and then sleeps, and a sleeping worker took
//! 30-50 us to wake on the 2-core development machine. Between two stages a step does a few
//! microseconds of serial work, and now and then the next broadcast found a worker asleep: in the
//! 1500-sphere RVE on two threads the second worker started each stage 2-11 us late on average,
//! with a median under 2 us, so a few stages waited far longer. A [`Team`]'s helpers instead stay
//! in a loop of their own between stages, watching one word for the next stage, and go back to the
//! pool when dismissed (before a step's parallel loops of other kinds: the candidate search) or
//! after [`IDLE_BEFORE_RETIRING`] without a stage.
//!
//! The calling worker leads: it opens a stage, runs its own share, then closes the stage and waits
//! for the helpers that joined it. A helper joins a stage only while it is open, so the leader
//! never waits for one that has not joined; stages are written to be finished by any subset of
//! the workers (pieces are claimed, see `par::Runs`).

use std::any::Any;
use std::cell::UnsafeCell;
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::ThreadId;
use std::time::{Duration, Instant};

/// How long a helper waits for the next stage before it goes back to the pool: far above the
/// serial work between two stages of a step (a few us) and what a script does between two steps
/// (tens of us), short against anything that would miss the worker in the pool.
const IDLE_BEFORE_RETIRING: Duration = Duration::from_micros(200);

/// Spin-loop hints between two looks at the clock, and before a waiting helper starts yielding
/// its core (in case more threads than cores were asked for); it then looks at every turn.
const SPINS_BETWEEN_CLOCKS: u32 = 256;
const SPINS_BEFORE_YIELDING: u32 = 4096;

/// The helpers of one simulation (see the module's documentation). A copy starts with none.
#[derive(Default)]
pub struct Team {
    /// The helpers' shared state, and the thread that leads them: a leader on another thread (of
    /// another pool, maybe) dismisses them and calls its own.
    current: Mutex<Option<(ThreadId, Arc<Shared>)>>,
}

impl Clone for Team {
    fn clone(&self) -> Team {
        Team::default()
    }
}

impl std::fmt::Debug for Team {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Team")
    }
}

impl Drop for Team {
    fn drop(&mut self) {
        self.dismiss();
    }
}

/// A stage's body, with the lifetime of the leader's borrow erased: helpers call it only while
/// they are counted in the open stage, and the leader does not return before that count is zero.
type Body = *const (dyn Fn(usize) + Sync + 'static);

/// What the leader and its helpers share. `stage` packs the stage number (high 32 bits), whether
/// it is closed (bit 31) and how many helpers are in it (the rest).
struct Shared {
    stage: AtomicU64,
    body: UnsafeCell<Option<Body>>,
    panic: Mutex<Option<Box<dyn Any + Send>>>,
    /// Helpers in their loop, and helpers asked for that have not started yet.
    serving: AtomicUsize,
    coming: AtomicUsize,
    dismissed: AtomicBool,
}

// SAFETY: `body` is written by the leader only while no helper is in a stage (the stage closed and
// its count at zero), and read by helpers only after they joined an open stage (see `join`).
unsafe impl Send for Shared {}
unsafe impl Sync for Shared {}

const CLOSED: u64 = 1 << 31;
const IN_STAGE: u64 = CLOSED - 1;

impl Team {
    /// Runs `body(worker)` once on the calling worker and once on each helper that joins in time,
    /// `worker` being each one's index in the current pool. Outside a pool's worker, on every
    /// worker of the current pool through `rayon::broadcast` instead.
    pub fn run(&self, body: &(dyn Fn(usize) + Sync)) {
        let Some(leader) = rayon::current_thread_index() else {
            rayon::broadcast(|ctx| body(ctx.index()));
            return;
        };
        let shared = self.helpers(leader);
        // A panic left by a stage that also panicked on the leader is that stage's.
        shared.panic.lock().unwrap_or_else(|e| e.into_inner()).take();
        let number = (shared.stage.load(Ordering::Relaxed) >> 32).wrapping_add(1) & 0xffff_ffff;
        // SAFETY: the previous stage is closed and empty (`Closing` waited for that), so no helper
        // reads `body` until the store below opens the next one.
        unsafe {
            *shared.body.get() = Some(std::mem::transmute::<&(dyn Fn(usize) + Sync), Body>(body));
        }
        shared.stage.store(number << 32, Ordering::Release);
        {
            // Closes the stage and waits for its helpers also when `body` panics here: they may
            // still be running it.
            let _closing = Closing(&shared);
            body(leader);
        }
        let panic = shared.panic.lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some(panic) = panic {
            resume_unwind(panic);
        }
    }

    /// Sends the helpers back to the pool, for parallel work of other kinds.
    pub fn dismiss(&self) {
        if let Some((_, shared)) = self.current.lock().unwrap_or_else(|e| e.into_inner()).take() {
            shared.dismissed.store(true, Ordering::Release);
        }
    }

    /// This leader's shared state, with helpers asked for when none are serving or coming.
    fn helpers(&self, leader: usize) -> Arc<Shared> {
        let me = std::thread::current().id();
        let mut current = self.current.lock().unwrap_or_else(|e| e.into_inner());
        if current.as_ref().is_some_and(|(thread, _)| *thread != me) {
            if let Some((_, old)) = current.take() {
                old.dismissed.store(true, Ordering::Release);
            }
        }
        let shared = current.get_or_insert_with(|| (me, Arc::new(Shared::new()))).1.clone();
        drop(current);
        let workers = rayon::current_num_threads();
        if workers > 1 && shared.serving.load(Ordering::Acquire) + shared.coming.load(Ordering::Acquire) == 0 {
            shared.coming.store(workers - 1, Ordering::Release);
            let helpers = shared.clone();
            rayon::spawn_broadcast(move |ctx| {
                if ctx.index() != leader {
                    helpers.serve(ctx.index());
                }
            });
        }
        shared
    }
}

impl Shared {
    fn new() -> Shared {
        Shared {
            stage: AtomicU64::new(CLOSED),
            body: UnsafeCell::new(None),
            panic: Mutex::new(None),
            serving: AtomicUsize::new(0),
            coming: AtomicUsize::new(0),
            dismissed: AtomicBool::new(false),
        }
    }

    /// A helper's loop: joins each stage it finds open, until dismissed or idle too long.
    fn serve(&self, worker: usize) {
        self.serving.fetch_add(1, Ordering::AcqRel);
        self.coming.fetch_sub(1, Ordering::AcqRel);
        let mut last = None;
        let mut idle_since = Instant::now();
        let mut spins = 0u32;
        while !self.dismissed.load(Ordering::Acquire) {
            if let Some(number) = self.join(last) {
                last = Some(number);
                // SAFETY: joined, so the leader waits for this helper before `body` goes.
                let body = unsafe { (*self.body.get()).expect("an open stage has a body") };
                if let Err(panic) = catch_unwind(AssertUnwindSafe(|| unsafe { (*body)(worker) })) {
                    *self.panic.lock().unwrap_or_else(|e| e.into_inner()) = Some(panic);
                }
                self.stage.fetch_sub(1, Ordering::Release);
                (idle_since, spins) = (Instant::now(), 0);
                continue;
            }
            spins = spins.saturating_add(1);
            // Once yielding, a turn may last a whole time slice: look at the clock every turn.
            let yielding = spins >= SPINS_BEFORE_YIELDING;
            if yielding {
                std::thread::yield_now();
            } else {
                std::hint::spin_loop();
            }
            if (yielding || spins.is_multiple_of(SPINS_BETWEEN_CLOCKS)) && idle_since.elapsed() > IDLE_BEFORE_RETIRING {
                break;
            }
        }
        self.serving.fetch_sub(1, Ordering::AcqRel);
    }

    /// Joins the open stage, unless it is stage `last` (already run): its number, or None.
    fn join(&self, last: Option<u64>) -> Option<u64> {
        let stage = self.stage.load(Ordering::Acquire);
        let number = stage >> 32;
        if stage & CLOSED != 0 || last == Some(number) {
            return None;
        }
        self.stage.compare_exchange(stage, stage + 1, Ordering::AcqRel, Ordering::Relaxed).ok().map(|_| number)
    }
}

/// Closes the leader's stage when dropped and waits until its helpers have left it.
struct Closing<'a>(&'a Shared);

impl Drop for Closing<'_> {
    fn drop(&mut self) {
        let mut stage = self.0.stage.fetch_or(CLOSED, Ordering::AcqRel) | CLOSED;
        let mut spins = 0u32;
        while stage & IN_STAGE != 0 {
            if spins < SPINS_BEFORE_YIELDING {
                spins += 1;
                std::hint::spin_loop();
            } else {
                std::thread::yield_now();
            }
            stage = self.0.stage.load(Ordering::Acquire);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;

    /// Runs a stage of `pieces` claimed pieces through `team` and returns, for each piece, the
    /// index and the thread of the worker that ran it.
    fn stage(team: &Team, pieces: usize, micros: u64) -> Vec<(usize, ThreadId)> {
        let next = AtomicUsize::new(0);
        let ran: Vec<Mutex<Option<(usize, ThreadId)>>> = (0..pieces).map(|_| Mutex::new(None)).collect();
        team.run(&|worker| {
            while let Some(p) = Some(next.fetch_add(1, Ordering::AcqRel)).filter(|&p| p < pieces) {
                std::thread::sleep(Duration::from_micros(micros));
                *ran[p].lock().unwrap() = Some((worker, std::thread::current().id()));
            }
        });
        ran.into_iter().map(|r| r.into_inner().unwrap().expect("every piece ran")).collect()
    }

    fn serving(team: &Team) -> usize {
        team.current.lock().unwrap().as_ref().map_or(0, |(_, s)| s.serving.load(Ordering::Acquire))
    }

    fn threads_of(pool: &rayon::ThreadPool) -> HashSet<ThreadId> {
        pool.broadcast(|_| std::thread::current().id()).into_iter().collect()
    }

    #[test]
    fn helpers_join_stages_retire_when_idle_and_follow_their_leader_to_another_pool() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
        let other = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let others = threads_of(&other);
        let team = Team::default();
        pool.install(|| {
            let mut shared = false;
            for _ in 0..50 {
                let ran = stage(&team, 12, 100);
                assert!(ran.iter().all(|&(w, _)| w < 3), "every piece ran on a worker of the pool: {ran:?}");
                shared |= ran.iter().map(|r| r.1).collect::<HashSet<_>>().len() > 1;
            }
            assert!(shared, "the helpers took pieces in some stage");
            // Idle for longer than IDLE_BEFORE_RETIRING (as long as this machine's other work
            // needs to let them run): back in the pool, where a broadcast reaches them, and
            // called again by the next stage.
            let since = Instant::now();
            while serving(&team) > 0 && since.elapsed() < Duration::from_secs(10) {
                std::thread::sleep(IDLE_BEFORE_RETIRING);
            }
            assert_eq!(serving(&team), 0, "idle helpers retire");
            assert_eq!(rayon::broadcast(|ctx| ctx.index()), vec![0, 1, 2]);
            assert_eq!(stage(&team, 12, 10).len(), 12);
            team.dismiss();
            assert_eq!(rayon::broadcast(|ctx| ctx.index()), vec![0, 1, 2], "dismissed helpers are back in the pool");
            // Led in turns from this pool and from another of two workers: each pool's helpers,
            // still serving when the other leads, must not join its stages.
            let ours = threads_of(&pool);
            for _ in 0..20 {
                let ran = stage(&team, 12, 50);
                assert!(ran.iter().all(|(_, t)| ours.contains(t)), "only the first pool's workers: {ran:?}");
                let ran = other.install(|| stage(&team, 6, 50));
                assert!(
                    ran.iter().all(|(w, t)| *w < 2 && others.contains(t)),
                    "only the second pool's workers: {ran:?}"
                );
            }
        });
        assert_eq!(pool.install(|| rayon::broadcast(|ctx| ctx.index())), vec![0, 1, 2]);
        // Outside any pool's worker, the stage is one broadcast over the global pool.
        assert_eq!(stage(&team, 4, 10).len(), 4);
    }

    #[test]
    fn a_panic_on_a_helper_reaches_the_leader() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let team = Team::default();
        let (mut joined, mut reached) = (0, 0);
        pool.install(|| {
            let leader = rayon::current_thread_index();
            for _ in 0..200 {
                let helped = AtomicBool::new(false);
                let outcome = catch_unwind(AssertUnwindSafe(|| {
                    team.run(&|worker| {
                        if Some(worker) == leader {
                            // Long enough for a serving helper to join.
                            std::thread::sleep(Duration::from_micros(200));
                        } else {
                            helped.store(true, Ordering::Release);
                            panic!("a helper fails");
                        }
                    })
                }));
                if helped.load(Ordering::Acquire) {
                    joined += 1;
                    reached += outcome.is_err() as usize;
                } else {
                    assert!(outcome.is_ok(), "no helper, no panic");
                }
            }
        });
        assert!(joined > 0, "a helper joined some stage");
        assert_eq!(reached, joined, "every helper's panic reached the leader");
    }
}
