//! How loops whose items cost very different times are spread over the threads.
//!
//! Rayon cuts an indexed parallel loop into a few tasks per thread and never cuts a task it has begun,
//! so the last task of a loop may hold a quarter of its items while the other threads have nothing left
//! to take. Where items cost from microseconds to milliseconds (a coupling with or without a
//! near-field integral or an item buffer to draw, a patch tree of one element or of thousands, a final
//! gather) that tail is most of a thread's idle time: 3.6–4.5 of the classroom's 52 CPU-seconds
//! (goal command, two threads), 1.7–2.0 with tasks bounded and Gauss–Seidel's patches relaxed in runs
//! (`solvers::gathering::PatchRuns`; BENCHMARKS.md, "Uneven loops"). Bounding a task's items makes the
//! tail at most that many items long. The split changes only which thread computes an item, never what
//! it computes or the order results are collected in, so answers do not depend on it.

use rayon::iter::IndexedParallelIterator;

/// Most items one task of an uneven loop takes: enough that a task's own cost (a deque push and pop)
/// is small beside its items' (microseconds each at the least); 4 and 64 measured the same as 16 on the
/// classroom's couplings, whose tails had held thousands of items.
pub const UNEVEN_TASK_ITEMS: usize = 16;

/// Rayon's indexed loops, cut into tasks of at most [`UNEVEN_TASK_ITEMS`] items.
pub trait Uneven: IndexedParallelIterator + Sized {
    /// The loop with its tasks bounded to [`UNEVEN_TASK_ITEMS`] items.
    fn uneven(self) -> rayon::iter::MaxLen<Self> {
        self.with_max_len(UNEVEN_TASK_ITEMS)
    }

    /// The loop with every item a task of its own: items of a millisecond or more (an image row, a
    /// final gather), where even [`UNEVEN_TASK_ITEMS`] of them make a long tail.
    fn one_per_task(self) -> rayon::iter::MaxLen<Self> {
        self.with_max_len(1)
    }
}

impl<I: IndexedParallelIterator> Uneven for I {}
