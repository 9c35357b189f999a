//! The memory a script's own data (arrays, strings, maps) may take: checked at every operation
//! against what the process could still take when the script last looked, so that a script that
//! grows its data without end stops with an error naming its line instead of aborting the
//! process when an allocation fails.
//!
//! Rhai's own size limits would do this per value, but they measure a whole array after every
//! change to it: a loop of `a.push(x)` then costs the square of its length (1e5 pushes took
//! 5.8 s, 1e6 about ten minutes). Counting the process's allocations (the `granite` binary's
//! [`CountingAllocator`](granite_core::memory::CountingAllocator)) costs one comparison an operation.

use granite_core::memory::{allocated_bytes, available_bytes};
use rhai::{Array, Blob, Dynamic, Engine, EvalAltResult, ImmutableString};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::Arc;

/// Operations between two readings of what the machine has available (a reading opens three
/// small /proc files, about 30 µs; 65 536 operations take some milliseconds).
const REFRESH_EVERY: u64 = 1 << 16;
/// Share of the memory available at a reading the script's data may grow into before the next:
/// the rest is for the operation that crosses the line (`s += s` holds the old string, a copy
/// and the new one at once: up to four times the value) and for the simulations.
const SHARE: f64 = 0.2;

/// The line a script's data may not cross: bytes held, as f64 bits (0: not yet read).
#[derive(Clone, Default)]
pub(crate) struct DataBudget {
    limit: Arc<AtomicU64>,
    available: Arc<AtomicU64>,
}

impl DataBudget {
    /// Called at each operation: an error message once the process holds more than the line.
    pub(crate) fn check(&self, operations: u64) -> Option<String> {
        let held = allocated_bytes()?;
        let mut limit = f64::from_bits(self.limit.load(Relaxed));
        if limit == 0.0 || operations.is_multiple_of(REFRESH_EVERY) {
            let available = available_bytes().unwrap_or(f64::INFINITY);
            limit = held + SHARE * available;
            self.limit.store(limit.to_bits(), Relaxed);
            self.available.store(available.to_bits(), Relaxed);
        }
        (held > limit).then(|| {
            let available = f64::from_bits(self.available.load(Relaxed));
            format!(
                "the script's data grew past the memory this process can take ({:.2} GB held, {:.2} GB were still \
                 available); keep particles and points in simulations, not in script arrays",
                held / 1e9,
                available / 1e9
            )
        })
    }
}

/// Refuses a request for `count` items of `bytes_each` beyond what the process can take.
fn fits(what: &str, count: i64, bytes_each: f64) -> Result<usize, Box<EvalAltResult>> {
    let need = count.max(0) as f64 * bytes_each;
    let available = available_bytes().unwrap_or(f64::INFINITY);
    if !(need <= SHARE * available) || count > isize::MAX as i64 / 64 {
        return Err(format!(
            "{what}({count}): {:.2} GB, more than this process can take ({:.2} GB available)",
            need / 1e9,
            available / 1e9
        )
        .into());
    }
    Ok(count.max(0) as usize)
}

/// Rhai's functions that allocate in one call as much as they are asked (`pad`, `blob`), checked
/// first against the memory available; the others grow a value by at most its own size.
pub(crate) fn register_sized_builtins(engine: &mut Engine) {
    engine.register_fn("pad", |a: &mut Array, len: i64, item: Dynamic| -> Result<(), Box<EvalAltResult>> {
        let len = fits("pad", len, std::mem::size_of::<Dynamic>() as f64)?;
        if len > a.len() {
            a.resize(len, item);
        }
        Ok(())
    });
    engine.register_fn("pad", |s: &mut ImmutableString, len: i64, c: char| -> Result<(), Box<EvalAltResult>> {
        let len = fits("pad", len, c.len_utf8() as f64)?;
        let have = s.chars().count();
        if len > have {
            let mut t = s.to_string();
            t.extend(std::iter::repeat_n(c, len - have));
            *s = t.into();
        }
        Ok(())
    });
    engine.register_fn("pad", |s: &mut ImmutableString, len: i64, p: &str| -> Result<(), Box<EvalAltResult>> {
        let len = fits("pad", len, 1.0)?;
        if p.is_empty() {
            return Ok(());
        }
        let mut t = s.to_string();
        let mut have = t.chars().count();
        while have < len {
            for c in p.chars() {
                if have >= len {
                    break;
                }
                t.push(c);
                have += 1;
            }
        }
        *s = t.into();
        Ok(())
    });
    engine.register_fn("blob", |len: i64| -> Result<Blob, Box<EvalAltResult>> { Ok(vec![0; fits("blob", len, 1.0)?]) });
    engine.register_fn("blob", |len: i64, value: i64| -> Result<Blob, Box<EvalAltResult>> {
        Ok(vec![value as u8; fits("blob", len, 1.0)?])
    });
    engine.register_fn("pad", |b: &mut Blob, len: i64, value: i64| -> Result<(), Box<EvalAltResult>> {
        let len = fits("pad", len, 1.0)?;
        if len > b.len() {
            b.resize(len, value as u8);
        }
        Ok(())
    });
}
