//! Per-sphere arrays that one parallel pass both reads and moves, piece by piece.
//!
//! In a parallel step the contact stage of a piece reads the positions and velocities of its own
//! spheres and of spheres in earlier pieces, while the integration of another piece may already
//! be moving that piece's spheres (`par::run_pieces_then` starts it once no contact piece that
//! reads them is still running). One borrow of a whole array cannot express "these rows, not
//! now": the array is lent as a raw pointer, and each piece borrows the rows it needs, shared or
//! exclusive, for as long as the schedule keeps the others off them.

use std::marker::PhantomData;
use std::ops::Range;

/// One per-sphere array lent to a parallel pass.
pub(crate) struct SharedRows<'a, T> {
    ptr: *mut T,
    len: usize,
    _rows: PhantomData<&'a mut [T]>,
}

// SAFETY: the pass's schedule keeps every row either read by any number of workers or written by
// one (see the methods' contracts).
unsafe impl<T: Send + Sync> Sync for SharedRows<'_, T> {}
unsafe impl<T: Send + Sync> Send for SharedRows<'_, T> {}

impl<'a, T> SharedRows<'a, T> {
    pub(crate) fn new(rows: &'a mut [T]) -> SharedRows<'a, T> {
        SharedRows { ptr: rows.as_mut_ptr(), len: rows.len(), _rows: PhantomData }
    }

    fn checked(&self, range: &Range<usize>) {
        assert!(range.start <= range.end && range.end <= self.len, "rows {range:?} of {}", self.len);
    }

    /// The rows `range`, to read; panics when the range does not fit.
    ///
    /// # Safety
    /// While the slice is used, no slice from [`SharedRows::piece`] that is in use may overlap it.
    pub(crate) unsafe fn rows(&self, range: Range<usize>) -> &'a [T] {
        self.checked(&range);
        // SAFETY: in bounds; nobody writes these rows meanwhile, by the caller's promise.
        unsafe { std::slice::from_raw_parts(self.ptr.add(range.start), range.len()) }
    }

    /// The rows `range`, to change; panics when the range does not fit.
    ///
    /// # Safety
    /// While the slice is used, no other slice from `piece` or [`SharedRows::rows`] that is in
    /// use may overlap it; the caller's schedule must order those borrows before or after (with
    /// acquire and release, as `par::run_pieces_then` does).
    #[allow(clippy::mut_from_ref)]
    pub(crate) unsafe fn piece(&self, range: Range<usize>) -> &'a mut [T] {
        self.checked(&range);
        // SAFETY: in bounds; exclusive by the caller's promise.
        unsafe { std::slice::from_raw_parts_mut(self.ptr.add(range.start), range.len()) }
    }
}
