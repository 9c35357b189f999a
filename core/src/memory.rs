//! What a request would take in memory, checked before it is made: a generator, a fill or a
//! mesh asked for more than the machine has is refused with the numbers, instead of aborting the
//! process in the allocator (or overflowing a size on the way there).

use crate::error::{GraniteError, Result};

/// Bytes a sphere takes at the peak of a DEM run's first steps: its arrays, its share of the
/// candidate pair list and of the first VTK frame. Measured as the growth of the peak resident
/// memory of a lattice run for two steps (`sim.lattice` of 64 000 and 512 000 spheres, linear
/// law, one thread: 1 029 bytes a sphere), rounded up.
pub const BYTES_PER_SPHERE: f64 = 1100.0;
/// Bytes a material point takes at the peak of an MPM run's first steps, its share of the grid
/// nodes included. Measured like [`BYTES_PER_SPHERE`] (3D linear-elastic block, 8 points a cell,
/// 80 000 and 240 000 points: 923 bytes a point), rounded up.
pub const BYTES_PER_POINT: f64 = 1000.0;
/// Bytes a grid node takes: nodal sums, velocities and the scatter's buffers, rounded up.
pub const BYTES_PER_NODE: f64 = 200.0;

/// Memory this process can still take, in bytes: the least of what the machine has available
/// (Linux: MemAvailable of /proc/meminfo), what the process's address-space limit leaves
/// (`ulimit -v`, RLIMIT_AS, against its present size) and what its control group leaves (cgroup
/// v2 `memory.max`, v1 `memory.limit_in_bytes`, against their usage: a container's or a batch
/// job's limit). None where none of these is known.
pub fn available_bytes() -> Option<f64> {
    [machine_available(), address_space_left(), cgroup_left()].into_iter().flatten().reduce(f64::min)
}

fn machine_available() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    kilobytes(&text, "MemAvailable:")
}

/// A `NAME:  1234 kB` line of a /proc file, in bytes.
fn kilobytes(text: &str, name: &str) -> Option<f64> {
    let line = text.lines().find(|l| l.starts_with(name))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024.0)
}

#[cfg(unix)]
fn address_space_left() -> Option<f64> {
    let mut limit = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
    // SAFETY: getrlimit writes the limit into `limit`.
    if unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut limit) } != 0 || limit.rlim_cur == libc::RLIM_INFINITY {
        return None;
    }
    let size = std::fs::read_to_string("/proc/self/status").ok().and_then(|t| kilobytes(&t, "VmSize:")).unwrap_or(0.0);
    Some((limit.rlim_cur as f64 - size).max(0.0))
}

#[cfg(not(unix))]
fn address_space_left() -> Option<f64> {
    None
}

/// Bytes left under this process's control-group memory limit, v2 or v1.
fn cgroup_left() -> Option<f64> {
    let groups = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    let read = |path: String| -> Option<f64> { std::fs::read_to_string(path).ok()?.trim().parse::<f64>().ok() };
    for line in groups.lines() {
        let mut fields = line.splitn(3, ':');
        let (id, controllers, path) = (fields.next()?, fields.next()?, fields.next()?);
        let (limit, usage) = if id == "0" && controllers.is_empty() {
            // v2: "max" when unlimited, which does not parse.
            (read(format!("/sys/fs/cgroup{path}/memory.max")), read(format!("/sys/fs/cgroup{path}/memory.current")))
        } else if controllers.split(',').any(|c| c == "memory") {
            let dir = format!("/sys/fs/cgroup/memory{path}");
            (read(format!("{dir}/memory.limit_in_bytes")), read(format!("{dir}/memory.usage_in_bytes")))
        } else {
            continue;
        };
        // v1 writes "no limit" as a number near 2^63.
        if let (Some(limit), Some(usage)) = (limit, usage) {
            if limit < 1e18 {
                return Some((limit - usage).max(0.0));
            }
        }
    }
    None
}

/// Refuses `count` `items` of `bytes_each` (counted in f64: no overflow) when they exceed the
/// memory available; `what` names the request and `hint` what to change.
pub fn check(what: &str, count: f64, items: &str, bytes_each: f64, hint: &str) -> Result<()> {
    let need = count * bytes_each;
    let limit = available_bytes().unwrap_or(f64::INFINITY).min(usize::MAX as f64 / 4.0);
    if !(need <= limit) {
        return Err(GraniteError::Setup(format!(
            "{what}: {count:.3e} {items} would take about {:.1} GB of memory, more than the {:.1} GB this process \
             can still take (the machine's available memory, its `ulimit -v` and its control group's limit); {hint}",
            need / 1e9,
            limit / 1e9
        )));
    }
    Ok(())
}

/// The system allocator, counting the bytes it holds, so that a script's data can be stopped
/// with an error before it takes all the memory (an allocation that fails aborts the process).
/// The `granite` binary installs it; a library user may (`#[global_allocator]`), and without it
/// [`allocated_bytes`] is None and scripts are not checked.
pub struct CountingAllocator;

/// Bytes held through [`CountingAllocator`], less what each thread has not yet passed on.
static ALLOCATED: std::sync::atomic::AtomicIsize = std::sync::atomic::AtomicIsize::new(0);
static COUNTING: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
/// A thread passes its count on in steps of this many bytes: the shared counter is touched once
/// per many small allocations, not at each.
const PASS_ON: isize = 1 << 16;

thread_local! {
    static PENDING: std::cell::Cell<isize> = const { std::cell::Cell::new(0) };
}

#[inline]
fn count(bytes: isize) {
    use std::sync::atomic::Ordering::Relaxed;
    let passed = PENDING.try_with(|p| {
        let v = p.get() + bytes;
        if v.abs() >= PASS_ON {
            ALLOCATED.fetch_add(v, Relaxed);
            p.set(0);
        } else {
            p.set(v);
        }
    });
    if passed.is_err() {
        ALLOCATED.fetch_add(bytes, Relaxed);
    }
}

// SAFETY: every call goes to the system allocator with the caller's arguments; the count is a
// side effect that allocates nothing.
unsafe impl std::alloc::GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        let p = unsafe { std::alloc::System.alloc(layout) };
        if !p.is_null() {
            count(layout.size() as isize);
        }
        p
    }
    unsafe fn alloc_zeroed(&self, layout: std::alloc::Layout) -> *mut u8 {
        let p = unsafe { std::alloc::System.alloc_zeroed(layout) };
        if !p.is_null() {
            count(layout.size() as isize);
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
        unsafe { std::alloc::System.dealloc(ptr, layout) };
        count(-(layout.size() as isize));
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: std::alloc::Layout, new_size: usize) -> *mut u8 {
        let p = unsafe { std::alloc::System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            count(new_size as isize - layout.size() as isize);
        }
        p
    }
}

impl CountingAllocator {
    /// Says that this allocator is the process's (call once from `main`).
    pub fn installed() {
        COUNTING.store(true, std::sync::atomic::Ordering::Relaxed);
    }
}

/// Bytes the process holds through [`CountingAllocator`] (within 64 kB a thread), or None where
/// it is not the process's allocator.
pub fn allocated_bytes() -> Option<f64> {
    COUNTING
        .load(std::sync::atomic::Ordering::Relaxed)
        .then(|| ALLOCATED.load(std::sync::atomic::Ordering::Relaxed) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_beyond_the_memory_is_refused_with_the_numbers() {
        let e =
            check("sim.lattice", 1e18, "spheres", BYTES_PER_SPHERE, "use a larger spacing").unwrap_err().to_string();
        assert!(e.contains("1.000e18 spheres") && e.contains("GB") && e.contains("larger spacing"), "{e}");
        assert!(check("sim.lattice", 1000.0, "spheres", BYTES_PER_SPHERE, "").is_ok());
    }
}
