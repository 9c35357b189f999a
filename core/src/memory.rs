//! What a request would take in memory, checked before it is made: a generator, a fill or a
//! mesh asked for more than the machine has is refused with the numbers, instead of aborting the
//! process in the allocator (or overflowing a size on the way there).

use crate::error::{GraniteError, Result};

/// Bytes a sphere takes in a DEM simulation: its own arrays and its share of the candidate pair
/// list (0.064 MB for a 125-sphere RVE, `granite bench mpmxdem`), rounded up.
pub const BYTES_PER_SPHERE: f64 = 600.0;
/// Bytes a material point takes: its arrays (`mpm::Points`, 200 bytes), its location, its
/// state variables and its output, rounded up.
pub const BYTES_PER_POINT: f64 = 400.0;
/// Bytes a grid node takes: nodal sums, velocities and the scatter's buffers, rounded up.
pub const BYTES_PER_NODE: f64 = 200.0;

/// Memory this process can still take, in bytes (Linux: MemAvailable of /proc/meminfo); None
/// where the system does not say.
pub fn available_bytes() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024.0)
}

/// Refuses `count` `items` of `bytes_each` (counted in f64: no overflow) when they exceed the
/// memory available; `what` names the request and `hint` what to change.
pub fn check(what: &str, count: f64, items: &str, bytes_each: f64, hint: &str) -> Result<()> {
    let need = count * bytes_each;
    let limit = available_bytes().unwrap_or(f64::INFINITY).min(usize::MAX as f64 / 4.0);
    if !(need <= limit) {
        return Err(GraniteError::Setup(format!(
            "{what}: {count:.3e} {items} would take about {:.1} GB of memory, more than the {:.1} GB this machine has \
             available; {hint}",
            need / 1e9,
            limit / 1e9
        )));
    }
    Ok(())
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
