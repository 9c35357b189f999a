//! Processes that run one simulation together (MPI ranks). The engine needs a handful of
//! collective operations on bytes; the `granite` binary provides them over MPI when built with
//! `--features mpi`, and a run in one process has none at all.
//!
//! Every process runs the same script and the same MPM step; only the per-point objects of
//! laws that allow it (`dem_rve`'s RVEs) are spread over the processes (see `mpm::spread`).

use std::sync::Arc;

/// Collective operations over the processes of a run. Every process must make the same calls in
/// the same order (as every process runs the same script, they do).
pub trait Communicator: Send + Sync {
    /// This process's rank, 0 to `size() - 1`.
    fn rank(&self) -> usize;
    /// How many processes run the simulation.
    fn size(&self) -> usize;
    /// Every process's bytes, in rank order, on every process.
    fn all_gather(&self, mine: &[u8]) -> Vec<Vec<u8>>;
    /// Process `r` receives `outgoing[r]`; returns what each process sent to this one, in rank order.
    fn exchange(&self, outgoing: Vec<Vec<u8>>) -> Vec<Vec<u8>>;
    /// Every process's bytes on rank 0 (in rank order); None elsewhere.
    fn gather_to_root(&self, mine: &[u8]) -> Option<Vec<Vec<u8>>>;
    /// Rank `root`'s bytes on every process.
    fn broadcast(&self, root: usize, bytes: Vec<u8>) -> Vec<u8>;
    /// Waits until every process gets here, or gives up after `timeout` (a process that stopped
    /// on an error of its own while others wait in a step would otherwise leave them hanging).
    /// Returns whether every process arrived.
    fn meet(&self, timeout: std::time::Duration) -> bool;
    /// Stops every process of the run with exit code `code`.
    fn abort(&self, code: i32) -> !;
}

/// A shared communicator, as run options carry it.
#[derive(Clone)]
pub struct Comm(pub Arc<dyn Communicator>);

impl std::fmt::Debug for Comm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Comm(rank {} of {})", self.0.rank(), self.0.size())
    }
}

impl std::ops::Deref for Comm {
    type Target = dyn Communicator;
    fn deref(&self) -> &Self::Target {
        &*self.0
    }
}

/// The outcome of something one process did for all (wrote a file), in every process: rank
/// `root`'s `outcome`, whatever the others pass. Without other processes, `outcome` itself.
pub fn agree(comm: Option<&Comm>, root: usize, outcome: crate::Result<()>) -> crate::Result<()> {
    let Some(comm) = comm.filter(|c| c.size() > 1) else { return outcome };
    let mine = match &outcome {
        Ok(()) => Vec::new(),
        Err(e) => e.to_string().into_bytes(),
    };
    let theirs = comm.broadcast(root, mine);
    if theirs.is_empty() {
        Ok(())
    } else {
        Err(crate::GraniteError::Other(String::from_utf8_lossy(&theirs).into_owned()))
    }
}

/// Writes numbers and strings into a byte buffer, read back by [`Reader`] in the same order
/// (little-endian, so bits travel exactly).
#[derive(Default, Clone)]
pub struct Writer(pub Vec<u8>);

impl Writer {
    pub fn f64(&mut self, x: f64) -> &mut Self {
        self.0.extend_from_slice(&x.to_le_bytes());
        self
    }
    pub fn f64s(&mut self, xs: &[f64]) -> &mut Self {
        for &x in xs {
            self.f64(x);
        }
        self
    }
    pub fn u64(&mut self, x: u64) -> &mut Self {
        self.0.extend_from_slice(&x.to_le_bytes());
        self
    }
    pub fn bytes(&mut self, b: &[u8]) -> &mut Self {
        self.u64(b.len() as u64);
        self.0.extend_from_slice(b);
        self
    }
    pub fn str(&mut self, s: &str) -> &mut Self {
        self.bytes(s.as_bytes())
    }
}

/// Reads what a [`Writer`] wrote; a short or malformed buffer is an error, never a panic.
pub struct Reader<'a> {
    data: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    pub fn new(data: &'a [u8]) -> Reader<'a> {
        Reader { data, at: 0 }
    }
    fn take(&mut self, n: usize) -> crate::Result<&'a [u8]> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.data.len()).ok_or_else(|| {
            crate::GraniteError::Other(format!(
                "message between processes ends early ({} bytes, {} more wanted at {})",
                self.data.len(),
                n,
                self.at
            ))
        })?;
        let s = &self.data[self.at..end];
        self.at = end;
        Ok(s)
    }
    pub fn f64(&mut self) -> crate::Result<f64> {
        let b = self.take(8)?;
        Ok(f64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
    }
    pub fn u64(&mut self) -> crate::Result<u64> {
        let b = self.take(8)?;
        Ok(u64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
    }
    /// Passes over `count` numbers.
    pub fn skip_f64s(&mut self, count: usize) -> crate::Result<()> {
        self.take(count.saturating_mul(8)).map(|_| ())
    }
    pub fn f64s_into(&mut self, out: &mut [f64]) -> crate::Result<()> {
        for x in out {
            *x = self.f64()?;
        }
        Ok(())
    }
    pub fn bytes(&mut self) -> crate::Result<&'a [u8]> {
        let n = self.u64()? as usize;
        self.take(n)
    }
    pub fn str(&mut self) -> crate::Result<String> {
        Ok(String::from_utf8_lossy(self.bytes()?).into_owned())
    }
    pub fn done(&self) -> bool {
        self.at == self.data.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_round_trip_exactly_and_short_input_is_an_error() {
        let mut w = Writer::default();
        w.f64(0.1 + 0.2).u64(7).str("rve 3 failed").f64s(&[f64::MIN_POSITIVE, -0.0]);
        let mut r = Reader::new(&w.0);
        assert_eq!(r.f64().unwrap().to_bits(), (0.1f64 + 0.2).to_bits());
        assert_eq!(r.u64().unwrap(), 7);
        assert_eq!(r.str().unwrap(), "rve 3 failed");
        let mut two = [0.0; 2];
        r.f64s_into(&mut two).unwrap();
        assert_eq!(two[0], f64::MIN_POSITIVE);
        assert!(two[1].is_sign_negative());
        assert!(r.done());
        assert!(Reader::new(&w.0[..5]).f64().is_err());
    }
}
