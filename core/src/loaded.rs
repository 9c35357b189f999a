//! Checks shared by the readers of saved states (DEM states, MPM checkpoints): a file edited by
//! hand, truncated or written by another program is refused with what is wrong in it.

/// Every array of `group` as long as its `reference` one.
pub(crate) fn same_length(
    group: &str,
    reference: &str,
    n: usize,
    lengths: &[(&str, usize)],
) -> std::result::Result<(), String> {
    match lengths.iter().find(|(_, len)| *len != n) {
        Some((name, len)) => Err(format!("{group}: `{name}` has {len} entries, `{reference}` {n}")),
        None => Ok(()),
    }
}

/// Ids name bodies in every message and output: two bodies under one id would be reported under
/// each other's.
pub(crate) fn unique_ids(group: &str, ids: &[u64]) -> std::result::Result<(), String> {
    let mut sorted = ids.to_vec();
    sorted.sort_unstable();
    match sorted.windows(2).find(|w| w[0] == w[1]) {
        Some(w) => Err(format!("two {group} have id {}", w[0])),
        None => Ok(()),
    }
}

/// A step count scripts can read (`sim.step` is a signed 64-bit integer there) and a time from
/// the start, not before it.
pub(crate) fn step_and_time(step: u64, time: f64) -> std::result::Result<(), String> {
    if step > i64::MAX as u64 || !(time.is_finite() && time >= 0.0) {
        return Err(format!("step {step}, time {time} (a step up to {} and a finite time >= 0)", i64::MAX));
    }
    Ok(())
}
