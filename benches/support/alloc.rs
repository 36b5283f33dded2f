//! Heap allocations counted by interposing `malloc` and friends in the bench executable.
//!
//! The layer is a separately loaded library with its own Rust runtime, so a `#[global_allocator]`
//! here would not see its allocations; ELF symbol interposition routes its `malloc` calls (and the
//! loaders', and the drivers') through these, which count and hand on to glibc's own functions.

use std::ffi::c_void;
use std::sync::atomic::{AtomicU64, Ordering};

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

/// Allocations made in this process so far, by any thread and any library.
pub fn allocations() -> u64 {
    ALLOCATIONS.load(Ordering::Relaxed)
}

extern "C" {
    fn __libc_malloc(size: usize) -> *mut c_void;
    fn __libc_calloc(n: usize, size: usize) -> *mut c_void;
    fn __libc_realloc(p: *mut c_void, size: usize) -> *mut c_void;
    fn __libc_memalign(align: usize, size: usize) -> *mut c_void;
}

/// # Safety
/// The C `malloc` contract.
#[no_mangle]
pub unsafe extern "C" fn malloc(size: usize) -> *mut c_void {
    ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    // SAFETY: glibc's own allocator, with the caller's arguments.
    unsafe { __libc_malloc(size) }
}

/// # Safety
/// The C `calloc` contract.
#[no_mangle]
pub unsafe extern "C" fn calloc(n: usize, size: usize) -> *mut c_void {
    ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    // SAFETY: as in malloc.
    unsafe { __libc_calloc(n, size) }
}

/// # Safety
/// The C `realloc` contract.
#[no_mangle]
pub unsafe extern "C" fn realloc(p: *mut c_void, size: usize) -> *mut c_void {
    ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    // SAFETY: as in malloc.
    unsafe { __libc_realloc(p, size) }
}

/// # Safety
/// The C `posix_memalign` contract.
#[no_mangle]
pub unsafe extern "C" fn posix_memalign(out: *mut *mut c_void, align: usize, size: usize) -> i32 {
    ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    // SAFETY: as in malloc.
    let p = unsafe { __libc_memalign(align, size) };
    if p.is_null() {
        return 12; // ENOMEM
    }
    // SAFETY: the caller's out pointer.
    unsafe { *out = p };
    0
}

/// # Safety
/// The C `aligned_alloc` contract.
#[no_mangle]
pub unsafe extern "C" fn aligned_alloc(align: usize, size: usize) -> *mut c_void {
    ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    // SAFETY: as in malloc.
    unsafe { __libc_memalign(align, size) }
}
