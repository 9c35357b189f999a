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
