//! The engine's [`Communicator`] over MPI (`--features mpi`, Open MPI or MPICH through rsmpi).
//!
//! Messages of any size travel in pieces of at most [`PIECE`] bytes: MPI counts are 32-bit, and a
//! checkpoint of a large run gathers gigabytes of RVEs to the first process.

use granite_core::comm::{Comm, Communicator};
use mpi::datatype::PartitionMut;
use mpi::topology::{Communicator as _, SimpleCommunicator};
use mpi::traits::*;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Largest piece one MPI call carries.
const PIECE: usize = 1 << 30;

/// MPI_COMM_WORLD of this run.
pub struct MpiComm {
    world: SimpleCommunicator,
    watch: Arc<Watch>,
}

/// How long this process has waited in an operation with the others: a watchdog thread ends the
/// run when one waits past the timeout (a process frozen, killed without its launcher noticing,
/// or stuck in a loop, would otherwise leave every other one waiting without limit).
pub struct Watch {
    /// When the present wait began (ms since `origin`), 0 outside any.
    since_ms: std::sync::atomic::AtomicU64,
    /// Which operation it is.
    operation: std::sync::Mutex<&'static str>,
    origin: Instant,
    timeout: Duration,
    /// Where the run's summary.json goes (every process may write it there: the one that speaks
    /// may be the one that hangs); None for a benchmark.
    summary: Option<std::path::PathBuf>,
    /// The process that started this one (the launcher, or its daemon on this node).
    parent: i32,
}

/// How long a process asked to stop by a signal waits for the others in an operation before it
/// ends on its own: they got the same signal and meet within a step, unless they are gone.
const STOPPING_WAIT: Duration = Duration::from_secs(30);

/// Default of `--mpi-timeout`: far beyond any wait of a working run (an MPM step of the thesis
/// column takes well under a second, a checkpoint of thousands of RVEs seconds), short enough
/// that a hung run does not hold a cluster's nodes for hours.
pub const DEFAULT_TIMEOUT_S: f64 = 300.0;

/// The wait of one operation: started when made, ended when dropped; None inside another
/// operation (a gather made of broadcasts), whose wait goes on.
struct Waiting<'a>(Option<&'a Watch>);

impl Drop for Waiting<'_> {
    fn drop(&mut self) {
        if let Some(watch) = self.0 {
            watch.since_ms.store(0, std::sync::atomic::Ordering::SeqCst);
        }
    }
}

impl Watch {
    fn enter(&self, operation: &'static str) -> Waiting<'_> {
        let now = self.origin.elapsed().as_millis() as u64 + 1;
        let ordering = std::sync::atomic::Ordering::SeqCst;
        if self.since_ms.compare_exchange(0, now, ordering, ordering).is_err() {
            return Waiting(None);
        }
        *self.operation.lock().unwrap_or_else(|p| p.into_inner()) = operation;
        Waiting(Some(self))
    }

    /// Checks four times a second. No process outlives its job: past the timeout a waiting
    /// process says so, records the run as failed and ends, which makes the launcher end the
    /// others; one whose launcher has gone (it returned after another process died, or was
    /// killed) ends at once; one asked to stop by a signal that waits for the others more than
    /// [`STOPPING_WAIT`] ends too. Their files, checkpoints included, stay as they were last
    /// written whole.
    fn guard(self: Arc<Self>, rank: usize, size: usize) {
        std::thread::spawn(move || loop {
            std::thread::sleep(Duration::from_millis(250));
            // SAFETY: getppid has no preconditions.
            let parent = unsafe { libc::getppid() };
            if parent != self.parent {
                self.end(
                    1,
                    format!(
                        "rank {rank} of {size}: the process that launched it ({}) has ended, so the job is over; this \
                         process ends with it, its last checkpoint kept",
                        self.parent
                    ),
                );
            }
            let since = self.since_ms.load(std::sync::atomic::Ordering::SeqCst);
            if since == 0 {
                continue;
            }
            let waited = Duration::from_millis(self.origin.elapsed().as_millis() as u64 + 1 - since);
            let operation = *self.operation.lock().unwrap_or_else(|p| p.into_inner());
            if let Some(signal) = crate::signals::received().filter(|_| waited >= STOPPING_WAIT) {
                self.end(
                    128 + signal,
                    format!(
                        "rank {rank} of {size}, asked to stop by signal {signal}, waited {:.0} s for the other processes \
                         in {operation}: they are gone or stuck; this process ends now, its last checkpoint kept",
                        waited.as_secs_f64()
                    ),
                );
            }
            if waited < self.timeout {
                continue;
            }
            self.end(
                1,
                format!(
                    "rank {rank} of {size} waited {:.0} s for the other processes in {operation} (--mpi-timeout {:.0} \
                     s): one of them stopped answering; the run is ended on every process, its last checkpoint kept",
                    waited.as_secs_f64(),
                    self.timeout.as_secs_f64()
                ),
            );
        });
    }

    /// Says why, records the run as failed and ends this process at once.
    fn end(&self, code: i32, message: String) -> ! {
        granite_core::errln!("granite: error: {message}");
        let mut summary = indexmap::IndexMap::new();
        summary.insert("status".to_string(), serde_json::Value::from("failed"));
        summary.insert("error".to_string(), serde_json::Value::from(message));
        if let Some(path) = &self.summary {
            let _ = granite_core::io::write_summary(path, &summary);
        }
        // SAFETY: ends this process at once (the others are ended by the launcher, or by their
        // own watch when it is gone).
        unsafe { libc::_exit(code) }
    }
}

// SAFETY: MPI is initialised with at least MPI_THREAD_SERIALIZED (checked in `start`), and the
// engine calls the communicator only from the thread running the script, one call at a time
// (background runs, the only other stepping threads, are refused when there are several processes).
unsafe impl Send for MpiComm {}
unsafe impl Sync for MpiComm {}

/// Initialises MPI. Returns the universe (MPI is finalised when it is dropped) and the world
/// communicator, or an error saying why MPI cannot be used.
pub fn start(
    timeout: Duration,
    out_dir: Option<&std::path::Path>,
) -> Result<(mpi::environment::Universe, Comm), String> {
    let (universe, threading) = mpi::initialize_with_threading(mpi::Threading::Serialized)
        .ok_or_else(|| "MPI was initialised already".to_string())?;
    if threading < mpi::Threading::Serialized {
        return Err(format!(
            "the MPI library offers thread level {threading:?}; granite needs Serialized (steps run on a worker thread)"
        ));
    }
    let world = universe.world();
    let watch = Arc::new(Watch {
        since_ms: std::sync::atomic::AtomicU64::new(0),
        operation: std::sync::Mutex::new(""),
        origin: Instant::now(),
        timeout,
        summary: out_dir.map(|d| d.join("summary.json")),
        // SAFETY: getppid has no preconditions.
        parent: unsafe { libc::getppid() },
    });
    watch.clone().guard(world.rank() as usize, world.size() as usize);
    Ok((universe, Comm(Arc::new(MpiComm { world, watch }))))
}

fn counts_of(lengths: &[usize]) -> (Vec<i32>, Vec<i32>) {
    let counts: Vec<i32> = lengths.iter().map(|&n| n as i32).collect();
    let mut displs = Vec::with_capacity(counts.len());
    let mut at = 0i32;
    for &c in &counts {
        displs.push(at);
        at += c;
    }
    (counts, displs)
}

/// A receive buffer of `len` bytes that never shares its address with a send buffer: empty Rust
/// vectors all point at the same dangling address, which MPI takes for an aliased buffer.
fn receive_buffer(len: usize) -> Vec<u8> {
    vec![0u8; len.max(1)]
}

fn split(buf: Vec<u8>, lengths: &[usize]) -> Vec<Vec<u8>> {
    let mut out = Vec::with_capacity(lengths.len());
    let mut at = 0;
    for &n in lengths {
        out.push(buf[at..at + n].to_vec());
        at += n;
    }
    out
}

impl MpiComm {
    fn lengths(&self, mine: usize) -> Vec<usize> {
        let mine = mine as u64;
        let mut all = vec![0u64; self.size()];
        self.world.all_gather_into(&mine, &mut all[..]);
        all.into_iter().map(|n| n as usize).collect()
    }

    /// Sends `bytes` to `to` in pieces (its length first).
    fn send_to(&self, to: usize, bytes: &[u8]) {
        let process = self.world.process_at_rank(to as i32);
        process.send(&(bytes.len() as u64));
        for piece in bytes.chunks(PIECE) {
            process.send(piece);
        }
    }

    fn receive_from(&self, from: usize) -> Vec<u8> {
        let process = self.world.process_at_rank(from as i32);
        let (len, _) = process.receive::<u64>();
        let mut out = vec![0u8; len as usize];
        for piece in out.chunks_mut(PIECE) {
            process.receive_into(piece);
        }
        out
    }

    /// Whether every process's part and the total fit one call's 32-bit counts.
    fn fits(lengths: &[usize]) -> bool {
        lengths.iter().sum::<usize>() <= i32::MAX as usize
    }
}

impl Communicator for MpiComm {
    fn rank(&self) -> usize {
        self.world.rank() as usize
    }

    fn size(&self) -> usize {
        self.world.size() as usize
    }

    fn all_gather(&self, mine: &[u8]) -> Vec<Vec<u8>> {
        let _waiting = self.watch.enter("a gather of every process's data");
        let lengths = self.lengths(mine.len());
        if !Self::fits(&lengths) {
            // Rare (per-step messages are kilobytes): one rank after the other, by broadcast.
            return (0..self.size())
                .map(|r| self.broadcast(r, if r == self.rank() { mine.to_vec() } else { Vec::new() }))
                .collect();
        }
        let (counts, displs) = counts_of(&lengths);
        let mut buf = receive_buffer(lengths.iter().sum());
        {
            let mut part = PartitionMut::new(&mut buf[..], &counts[..], &displs[..]);
            self.world.all_gather_varcount_into(mine, &mut part);
        }
        split(buf, &lengths)
    }

    fn exchange(&self, outgoing: Vec<Vec<u8>>) -> Vec<Vec<u8>> {
        let _waiting = self.watch.enter("an exchange of RVEs or results");
        let size = self.size();
        let send_lengths: Vec<u64> = outgoing.iter().map(|b| b.len() as u64).collect();
        let mut receive_lengths = vec![0u64; size];
        self.world.all_to_all_into(&send_lengths[..], &mut receive_lengths[..]);
        let send_lengths: Vec<usize> = send_lengths.into_iter().map(|n| n as usize).collect();
        let receive_lengths: Vec<usize> = receive_lengths.into_iter().map(|n| n as usize).collect();
        let large = [!Self::fits(&send_lengths), !Self::fits(&receive_lengths)];
        let mut any_large = [0u8];
        self.world.all_reduce_into(
            &[u8::from(large[0] || large[1])][..],
            &mut any_large[..],
            mpi::collective::SystemOperation::max(),
        );
        if any_large[0] == 1 {
            // Pairs of ranks in a fixed order: lower rank sends first, so no two wait on each other.
            let me = self.rank();
            let mut incoming = vec![Vec::new(); size];
            incoming[me] = outgoing[me].clone();
            for other in (0..size).filter(|&r| r != me) {
                if me < other {
                    self.send_to(other, &outgoing[other]);
                    incoming[other] = self.receive_from(other);
                } else {
                    incoming[other] = self.receive_from(other);
                    self.send_to(other, &outgoing[other]);
                }
            }
            return incoming;
        }
        let (send_counts, send_displs) = counts_of(&send_lengths);
        let (receive_counts, receive_displs) = counts_of(&receive_lengths);
        let mut sendbuf: Vec<u8> = outgoing.concat();
        sendbuf.push(0);
        let mut buf = receive_buffer(receive_lengths.iter().sum());
        {
            let send = mpi::datatype::Partition::new(&sendbuf[..], &send_counts[..], &send_displs[..]);
            let mut receive = PartitionMut::new(&mut buf[..], &receive_counts[..], &receive_displs[..]);
            self.world.all_to_all_varcount_into(&send, &mut receive);
        }
        split(buf, &receive_lengths)
    }

    fn gather_to_root(&self, mine: &[u8]) -> Option<Vec<Vec<u8>>> {
        let _waiting = self.watch.enter("a gather to the first process (a checkpoint)");
        // Point to point and in pieces: a checkpoint's objects may exceed 32-bit counts.
        if self.rank() == 0 {
            let mut all = vec![mine.to_vec()];
            for r in 1..self.size() {
                all.push(self.receive_from(r));
            }
            Some(all)
        } else {
            self.send_to(0, mine);
            None
        }
    }

    fn broadcast(&self, root: usize, bytes: Vec<u8>) -> Vec<u8> {
        let _waiting = self.watch.enter("a broadcast");
        let process = self.world.process_at_rank(root as i32);
        let mut len = bytes.len() as u64;
        process.broadcast_into(&mut len);
        let mut buf = if self.rank() == root { bytes } else { vec![0u8; len as usize] };
        for piece in buf.chunks_mut(PIECE) {
            process.broadcast_into(piece);
        }
        buf
    }

    fn meet(&self, timeout: Duration) -> bool {
        let started = Instant::now();
        let mut request = self.world.immediate_barrier();
        loop {
            match request.test() {
                Ok(_) => return true,
                Err(pending) => request = pending,
            }
            if started.elapsed() > timeout {
                // The caller aborts the run next; a pending request must not be dropped.
                std::mem::forget(request);
                return false;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    fn abort(&self, code: i32) -> ! {
        self.world.abort(code)
    }
}
