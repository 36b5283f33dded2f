//! The unit tests' heap-allocation counter: the test binary's global allocator counts each
//! allocation in a thread-local word, so that tests can check that a path allocates nothing in
//! steady state (a moving gaze's refills, a submit's ordering across queues), as the benches'
//! `malloc` counter does for the built library. Test builds only.

/// Heap allocations this thread made, counted by the test binary's allocator.
struct Counting;

thread_local! {
    static ALLOCATIONS: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
}

// SAFETY: the system allocator's contract, handed on; the count is a thread-local word.
unsafe impl std::alloc::GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
        // SAFETY: as the caller promised.
        unsafe { std::alloc::System.alloc(layout) }
    }

    unsafe fn dealloc(&self, p: *mut u8, layout: std::alloc::Layout) {
        // SAFETY: as the caller promised.
        unsafe { std::alloc::System.dealloc(p, layout) }
    }

    unsafe fn realloc(&self, p: *mut u8, layout: std::alloc::Layout, size: usize) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
        // SAFETY: as the caller promised.
        unsafe { std::alloc::System.realloc(p, layout, size) }
    }
}

#[global_allocator]
static COUNTING: Counting = Counting;

/// Heap allocations this thread has made so far (the test binary's counting allocator).
pub fn allocations() -> u64 {
    ALLOCATIONS.with(std::cell::Cell::get)
}
