//! The layer's locks, with their order (docs/ARCHITECTURE.md#lock-order) checked in debug builds.
//!
//! A layer runs on the application's threads, and a deadlock in it hangs the application. The order
//! that rules it out is written down in docs/ARCHITECTURE.md#lock-order; here it is enforced: every lock has a [`Rank`],
//! and a debug build keeps, per thread, the ranks it holds and panics (which the hook's guard turns
//! into XR_ERROR_RUNTIME_FAILURE and an error line, and the tests into a failure) as soon as a
//! thread takes a lock out of order, whether or not another thread is there to deadlock with. A
//! cycle needs two threads taking the same two locks in opposite orders; a total order that every
//! thread follows has none. Release builds compile to plain `parking_lot` locks.
//!
//! The logging file's lock (`log.rs`) is left out: it is taken inside `tracing` calls, which may run
//! under any lock, and takes no other lock itself.

use std::ops::{Deref, DerefMut};

/// Where a lock sits in the order, outermost first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Rank {
    /// The registry's handle maps. Held alone: taken with no other lock held, and no lock is taken
    /// while one is held (hooks copy the `Arc` out and drop the map lock first).
    Map,
    /// A record's own state (a session's frame loop and views, a swapchain's foveation state, an
    /// instance's FOVs and Vulkan set-up). Records never lock each other.
    Record,
    /// A swapchain's density images being filled.
    DensityFill,
    /// A session's queue, command pool and fence.
    GpuSubmit,
    /// The debug properties, read by everything above.
    Settings,
}

#[cfg(debug_assertions)]
mod check {
    use super::Rank;
    use std::cell::RefCell;

    thread_local! {
        static HELD: RefCell<Vec<(Rank, &'static str)>> = const { RefCell::new(Vec::new()) };
    }

    pub fn acquire(rank: Rank, what: &'static str) {
        HELD.with(|h| {
            let mut h = h.borrow_mut();
            if let Some(&(top, top_what)) = h.iter().max_by_key(|(r, _)| *r) {
                let map_held = h.iter().any(|(r, _)| *r == Rank::Map);
                if rank <= top || map_held {
                    let held: Vec<_> = h.iter().map(|(_, w)| *w).collect();
                    drop(h);
                    panic!(
                        "lock order violated: taking {what} ({rank:?}) while holding {top_what} \
                         ({top:?}); held: {held:?}"
                    );
                }
            }
            h.push((rank, what));
        });
    }

    pub fn release(rank: Rank, what: &'static str) {
        HELD.with(|h| {
            let mut h = h.borrow_mut();
            if let Some(i) = h.iter().rposition(|e| *e == (rank, what)) {
                h.remove(i);
            }
        });
    }

    pub fn assert_none_held(why: &str) {
        HELD.with(|h| {
            let h = h.borrow();
            if !h.is_empty() {
                let held: Vec<_> = h.iter().map(|(_, w)| *w).collect();
                drop(h);
                panic!("lock order violated: {why} while holding {held:?}");
            }
        });
    }
}

#[cfg(not(debug_assertions))]
mod check {
    use super::Rank;

    #[inline(always)]
    pub fn acquire(_: Rank, _: &'static str) {}

    #[inline(always)]
    pub fn release(_: Rank, _: &'static str) {}

    #[inline(always)]
    pub fn assert_none_held(_: &str) {}
}

/// Debug builds: panics if this thread holds any lock. Called before going down to the next layer,
/// which may block (xrWaitFrame) or call back into the application.
#[inline]
pub fn assert_none_held(why: &str) {
    check::assert_none_held(why);
}

use parking_lot::lock_api::{self, GuardSend, RawMutex};

/// A mutex with a rank: `parking_lot`'s, or (`R` = [`RawSpin`]) a spin lock.
pub struct Mutex<T, R: RawMutex = parking_lot::RawMutex> {
    rank: Rank,
    what: &'static str,
    inner: lock_api::Mutex<R, T>,
}

/// A record lock that spins: for the one lock the frame loop takes every frame
/// (docs/ARCHITECTURE.md#per-frame-cost).
pub type SpinMutex<T> = Mutex<T, RawSpin>;

/// A spin lock: taking it is one compare-and-swap, releasing it a plain store, where
/// `parking_lot`'s release is a second compare-and-swap (it must look for parked threads). Only for
/// locks that are held for nanoseconds and that correct applications never contend: after a
/// short spin a waiter yields its time slice.
pub struct RawSpin(std::sync::atomic::AtomicBool);

// SAFETY: `lock` returns only once this thread turned the flag from false to true with Acquire
// ordering, and `unlock` (called only by the holder, lock_api's contract) turns it back with
// Release ordering: one holder at a time, and the holder's writes happen before the next holder's
// reads.
unsafe impl RawMutex for RawSpin {
    const INIT: RawSpin = RawSpin(std::sync::atomic::AtomicBool::new(false));
    type GuardMarker = GuardSend;

    #[inline]
    fn lock(&self) {
        use std::sync::atomic::Ordering::{Acquire, Relaxed};
        let mut spins = 0u32;
        while self
            .0
            .compare_exchange_weak(false, true, Acquire, Relaxed)
            .is_err()
        {
            while self.0.load(Relaxed) {
                if spins < 100 {
                    spins += 1;
                    std::hint::spin_loop();
                } else {
                    std::thread::yield_now();
                }
            }
        }
    }

    #[inline]
    fn try_lock(&self) -> bool {
        use std::sync::atomic::Ordering::{Acquire, Relaxed};
        self.0
            .compare_exchange(false, true, Acquire, Relaxed)
            .is_ok()
    }

    #[inline]
    unsafe fn unlock(&self) {
        self.0.store(false, std::sync::atomic::Ordering::Release);
    }
}

impl<T> Mutex<T> {
    /// A record's lock ([`Rank::Record`]).
    pub const fn new(value: T) -> Mutex<T> {
        Mutex::ranked(Rank::Record, "record", value)
    }

    /// A lock of another rank; `what` names it in violation reports.
    pub const fn ranked(rank: Rank, what: &'static str, value: T) -> Mutex<T> {
        Mutex::with_raw(rank, what, value)
    }
}

impl<T> SpinMutex<T> {
    /// A record's spin lock ([`Rank::Record`]).
    pub const fn spin(value: T) -> SpinMutex<T> {
        Mutex::with_raw(Rank::Record, "record", value)
    }
}

impl<T, R: RawMutex> Mutex<T, R> {
    const fn with_raw(rank: Rank, what: &'static str, value: T) -> Mutex<T, R> {
        Mutex {
            rank,
            what,
            inner: lock_api::Mutex::const_new(R::INIT, value),
        }
    }

    pub fn lock(&self) -> MutexGuard<'_, T, R> {
        check::acquire(self.rank, self.what);
        MutexGuard {
            rank: self.rank,
            what: self.what,
            inner: self.inner.lock(),
        }
    }

    /// Through `&mut self` no lock is taken, so none is checked.
    pub fn get_mut(&mut self) -> &mut T {
        self.inner.get_mut()
    }
}

impl<T: Default, R: RawMutex> Default for Mutex<T, R> {
    fn default() -> Mutex<T, R> {
        Mutex::with_raw(Rank::Record, "record", T::default())
    }
}

impl<T: std::fmt::Debug, R: RawMutex> std::fmt::Debug for Mutex<T, R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.inner.fmt(f)
    }
}

pub struct MutexGuard<'a, T, R: RawMutex = parking_lot::RawMutex> {
    rank: Rank,
    what: &'static str,
    inner: lock_api::MutexGuard<'a, R, T>,
}

impl<T, R: RawMutex> Deref for MutexGuard<'_, T, R> {
    type Target = T;
    fn deref(&self) -> &T {
        &self.inner
    }
}

impl<T, R: RawMutex> DerefMut for MutexGuard<'_, T, R> {
    fn deref_mut(&mut self) -> &mut T {
        &mut self.inner
    }
}

impl<T, R: RawMutex> Drop for MutexGuard<'_, T, R> {
    fn drop(&mut self) {
        check::release(self.rank, self.what);
    }
}

/// How many process-wide locks (the registries' maps, [`MapLock`], and the tables every thread
/// shares, [`SharedMutex`] and [`SharedRwLock`]) this thread has taken so far: the unit tests
/// check the claim that a recording path takes none
/// (docs/ARCHITECTURE.md#recording-without-locks) against it, the way the benches' `malloc`
/// counter checks that it allocates nothing. Counted in test builds only (a thread-local
/// increment); the library itself compiles to the plain locks.
#[cfg(test)]
pub fn shared_taken() -> u64 {
    SHARED_TAKEN.try_with(std::cell::Cell::get).unwrap_or(0)
}

#[cfg(test)]
thread_local! {
    static SHARED_TAKEN: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
}

#[inline(always)]
fn count_shared() {
    #[cfg(test)]
    let _ = SHARED_TAKEN.try_with(|c| c.set(c.get().wrapping_add(1)));
}

/// A process-wide mutex outside [`Rank`]'s order (a leaf: nothing is taken under it that could
/// wait for another lock of the layer's), whose acquisitions are counted ([`shared_taken`]).
pub struct SharedMutex<T>(parking_lot::Mutex<T>);

impl<T> SharedMutex<T> {
    pub const fn new(value: T) -> SharedMutex<T> {
        SharedMutex(parking_lot::Mutex::new(value))
    }

    #[inline]
    pub fn lock(&self) -> parking_lot::MutexGuard<'_, T> {
        count_shared();
        self.0.lock()
    }
}

/// A process-wide reader-writer lock, a leaf like [`SharedMutex`], counted alike.
pub struct SharedRwLock<T>(parking_lot::RwLock<T>);

impl<T> SharedRwLock<T> {
    pub const fn new(value: T) -> SharedRwLock<T> {
        SharedRwLock(parking_lot::RwLock::new(value))
    }

    #[inline]
    pub fn read(&self) -> parking_lot::RwLockReadGuard<'_, T> {
        count_shared();
        self.0.read()
    }

    #[inline]
    pub fn write(&self) -> parking_lot::RwLockWriteGuard<'_, T> {
        count_shared();
        self.0.write()
    }
}

/// The lock of rank [`Rank::Map`] around each of the registry's handle maps.
///
/// An exclusive lock, though the maps are read far more often than written: a map lock is held
/// alone and only for a hash look-up and a copy (rank [`Rank::Map`]), so readers would share it for a
/// few nanoseconds at most, while `parking_lot`'s reader-writer lock costs more than its mutex on the
/// uncontended path every frame takes (both are one atomic read-modify-write to take and one to
/// release, but the reader path checks more state). `read` and `write` name what the caller does.
pub struct MapLock<T> {
    what: &'static str,
    inner: parking_lot::Mutex<T>,
}

impl<T> MapLock<T> {
    pub const fn new(what: &'static str, value: T) -> MapLock<T> {
        MapLock {
            what,
            inner: parking_lot::Mutex::new(value),
        }
    }

    /// Takes the lock to read the map.
    #[inline]
    pub fn read(&self) -> MapGuard<'_, parking_lot::MutexGuard<'_, T>> {
        self.lock()
    }

    /// Takes the lock to change the map.
    #[inline]
    pub fn write(&self) -> MapGuard<'_, parking_lot::MutexGuard<'_, T>> {
        self.lock()
    }

    #[inline]
    fn lock(&self) -> MapGuard<'_, parking_lot::MutexGuard<'_, T>> {
        check::acquire(Rank::Map, self.what);
        count_shared();
        MapGuard {
            _lock: std::marker::PhantomData,
            what: self.what,
            inner: self.inner.lock(),
        }
    }
}

/// A held map lock (read or write).
pub struct MapGuard<'a, G> {
    _lock: std::marker::PhantomData<&'a ()>,
    what: &'static str,
    inner: G,
}

impl<G: Deref> Deref for MapGuard<'_, G> {
    type Target = G::Target;
    fn deref(&self) -> &G::Target {
        &self.inner
    }
}

impl<G: DerefMut> DerefMut for MapGuard<'_, G> {
    fn deref_mut(&mut self) -> &mut G::Target {
        &mut self.inner
    }
}

impl<G> Drop for MapGuard<'_, G> {
    fn drop(&mut self) {
        check::release(Rank::Map, self.what);
    }
}

#[cfg(all(test, debug_assertions))]
mod tests {
    use super::*;

    fn panics(f: impl FnOnce()) -> bool {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).is_err()
    }

    #[test]
    fn the_spin_lock_excludes_and_is_ranked() {
        let counter = std::sync::Arc::new(SpinMutex::spin(0u64));
        let threads: Vec<_> = (0..4)
            .map(|_| {
                let c = std::sync::Arc::clone(&counter);
                std::thread::spawn(move || {
                    for _ in 0..20_000 {
                        // A non-atomic read-modify-write: a lost update shows a broken lock.
                        let mut g = c.lock();
                        let v = *g;
                        std::hint::black_box(&v);
                        *g = v + 1;
                    }
                })
            })
            .collect();
        for t in threads {
            t.join().unwrap();
        }
        assert_eq!(*counter.lock(), 80_000);
        let other = Mutex::new(0);
        assert!(panics(|| {
            let _a = counter.lock();
            let _b = other.lock();
        }));
    }

    #[test]
    fn the_order_is_enforced() {
        let map = MapLock::new("map", 0);
        let a = Mutex::new(1);
        let b = Mutex::new(2);
        let settings = Mutex::ranked(Rank::Settings, "settings", 3);
        // In order: fine, and released guards are forgotten.
        {
            let _a = a.lock();
            let _s = settings.lock();
        }
        drop(map.write());
        // Two records at once, a record inside a map lock, a map lock inside a record lock, and
        // inverted ranks all panic.
        assert!(panics(|| {
            let _a = a.lock();
            let _b = b.lock();
        }));
        assert!(panics(|| {
            let _m = map.read();
            let _a = a.lock();
        }));
        assert!(panics(|| {
            let _a = a.lock();
            let _m = map.read();
        }));
        assert!(panics(|| {
            let _s = settings.lock();
            let _a = a.lock();
        }));
        assert!(panics(|| {
            let _a = a.lock();
            assert_none_held("calling down");
        }));
        // Unwinding released everything.
        assert_none_held("after the panics");
    }
}
