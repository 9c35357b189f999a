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
/// Scripts read ids as signed 64-bit integers, and new bodies take ids above the largest.
pub(crate) fn unique_ids(group: &str, ids: &[u64]) -> std::result::Result<(), String> {
    if let Some(id) = ids.iter().find(|&&id| id >= i64::MAX as u64) {
        return Err(format!("{group}: id {id} (ids are below {})", i64::MAX));
    }
    let mut sorted = ids.to_vec();
    sorted.sort_unstable();
    match sorted.windows(2).find(|w| w[0] == w[1]) {
        Some(w) => Err(format!("two {group} have id {}", w[0])),
        None => Ok(()),
    }
}

/// A step count scripts can read (`sim.step` is a signed 64-bit integer there) and a time from
/// the start, not before it, that a step of `dt` still moves on (at 1e308 s, adding a step would
/// leave the time where it is).
pub(crate) fn step_and_time(step: u64, time: f64, dt: f64) -> std::result::Result<(), String> {
    if step > i64::MAX as u64 || !(time.is_finite() && time >= 0.0) {
        return Err(format!("step {step}, time {time} (a step up to {} and a finite time >= 0)", i64::MAX));
    }
    if dt > 0.0 && time + dt == time {
        return Err(crate::error::compact_numbers(&format!(
            "time {time} s is so large that a step of {dt} s leaves it unchanged (a saved time is a run's \
             elapsed time)"
        )));
    }
    Ok(())
}

/// The id the next new body takes: above every id held, and one scripts can read.
pub(crate) fn next_id(group: &str, next: u64, ids: &[u64]) -> std::result::Result<(), String> {
    let largest = ids.iter().max();
    if next >= i64::MAX as u64 || largest.is_some_and(|&m| next <= m) {
        return Err(format!(
            "the next id of new {group} is {next}: it must be above every id held ({}) and below {}",
            largest.map_or("none".to_string(), |m| m.to_string()),
            i64::MAX
        ));
    }
    Ok(())
}
