//! A global allocator that counts allocations made by the measuring thread only (the test
//! harness's own threads may allocate meanwhile), for "the tick path allocates nothing" tests.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    // Per thread: two tests of a binary measuring at once do not add to each other's counts.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn count() {
    if COUNTING.with(|c| c.get()) {
        ALLOCATIONS.with(|n| n.set(n.get() + 1));
    }
}

// SAFETY: forwards to the system allocator unchanged; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations made by `f` on the calling thread. Checks first that the counter works.
pub fn allocations(f: impl FnOnce()) -> usize {
    COUNTING.with(|c| c.set(true));
    let probe = ALLOCATIONS.with(|n| n.get());
    let v = std::hint::black_box(vec![0u8; 64]);
    assert!(
        ALLOCATIONS.with(|n| n.get()) > probe && v.len() == 64,
        "the allocation counter does not count"
    );
    drop(v);
    let before = ALLOCATIONS.with(|n| n.get());
    f();
    let n = ALLOCATIONS.with(|n| n.get()) - before;
    COUNTING.with(|c| c.set(false));
    n
}

/// The running count of the measuring thread's allocations (inside [`allocations`]), to single
/// out one step of the measured closure.
pub fn allocations_so_far() -> usize {
    ALLOCATIONS.with(|n| n.get())
}
