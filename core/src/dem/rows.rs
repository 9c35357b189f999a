//! Per-sphere arrays that one parallel pass both reads anywhere and moves piece by piece.
//!
//! In a parallel step the contact stage of a piece reads the positions and velocities of its own
//! spheres and of spheres in earlier pieces, while the integration of another piece may already
//! be moving that piece's spheres (`par::run_pieces_then` starts it once no contact piece that
//! reads them is still running). Shared and exclusive borrows cannot express "these rows, not
//! now": the array is shared as a raw pointer instead, and the schedule keeps the two apart.

use std::marker::PhantomData;
use std::ops::Range;

/// Read access to the rows `from..to` of one per-sphere array, indexed as in the whole array and
/// checked: a read outside them panics.
#[derive(Clone, Copy)]
pub(crate) struct ReadRows<'a, T> {
    /// Row 0 of the whole array.
    ptr: *const T,
    from: usize,
    to: usize,
    _rows: PhantomData<&'a [T]>,
}

// SAFETY: a `ReadRows` only reads, like the `&[T]` it stands for; whoever made one from
// `SharedRows::reader` promised that no row it reads is written meanwhile.
unsafe impl<T: Sync> Sync for ReadRows<'_, T> {}
unsafe impl<T: Sync> Send for ReadRows<'_, T> {}

impl<'a, T: Copy> ReadRows<'a, T> {
    /// Every row of `rows`.
    pub(crate) fn new(rows: &'a [T]) -> ReadRows<'a, T> {
        ReadRows { ptr: rows.as_ptr(), from: 0, to: rows.len(), _rows: PhantomData }
    }

    /// Row `i`; panics when it is not one of these rows.
    #[inline(always)]
    pub(crate) fn get(&self, i: usize) -> T {
        assert!(i >= self.from && i < self.to, "row {i} read, rows {}..{} lent", self.from, self.to);
        // SAFETY: in the array, and among the rows lent to this reader, which nobody writes
        // while it is in use (see the constructors).
        unsafe { *self.ptr.add(i) }
    }
}

/// One per-sphere array lent to a parallel pass: read through [`SharedRows::reader`], and moved
/// piece by piece through [`SharedRows::piece`].
pub(crate) struct SharedRows<'a, T> {
    ptr: *mut T,
    len: usize,
    _rows: PhantomData<&'a mut [T]>,
}

// SAFETY: the pass's schedule keeps every row either read by any number of workers or written by
// one (see the methods' contracts).
unsafe impl<T: Send + Sync> Sync for SharedRows<'_, T> {}
unsafe impl<T: Send + Sync> Send for SharedRows<'_, T> {}

impl<'a, T: Copy> SharedRows<'a, T> {
    pub(crate) fn new(rows: &'a mut [T]) -> SharedRows<'a, T> {
        SharedRows { ptr: rows.as_mut_ptr(), len: rows.len(), _rows: PhantomData }
    }

    /// Reads the rows `range`; panics when the range does not fit.
    ///
    /// # Safety
    /// While the reader is used, no slice returned by [`SharedRows::piece`] that is still in use
    /// may overlap `range` (the reader checks every read against `range`).
    pub(crate) unsafe fn reader(&self, range: Range<usize>) -> ReadRows<'a, T> {
        assert!(range.start <= range.end && range.end <= self.len, "rows {range:?} of {}", self.len);
        ReadRows { ptr: self.ptr, from: range.start, to: range.end, _rows: PhantomData }
    }

    /// The rows `range`, to change; panics when the range does not fit.
    ///
    /// # Safety
    /// While the slice is used, no other slice from `piece` may overlap it and no reader may read
    /// a row inside it; the caller's schedule must order those accesses before or after (with
    /// acquire and release, as `par::run_pieces_then` does).
    #[allow(clippy::mut_from_ref)]
    pub(crate) unsafe fn piece(&self, range: Range<usize>) -> &'a mut [T] {
        assert!(range.start <= range.end && range.end <= self.len, "rows {range:?} of {}", self.len);
        // SAFETY: in bounds; exclusive by the caller's promise.
        unsafe { std::slice::from_raw_parts_mut(self.ptr.add(range.start), range.len()) }
    }
}
