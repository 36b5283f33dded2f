//! Handle maps: records keyed by the raw value of the handle they describe, with a per-thread cache
//! that resolves a handle on the per-frame path without an atomic read-modify-write.
//!
//! The map holds each record in an `Arc`; it is the record's owner from creation until the handle is
//! destroyed. A hook that only needs the record for the length of its own call borrows it
//! ([`Records::borrow`]): no lock and no reference count when this thread resolved the same handle
//! before and no map has changed since; one map lock otherwise. On the frame loop this turns each
//! look-up (seven a frame with one swapchain; each was a lock, a hash and an `Arc` clone and drop,
//! four atomic read-modify-writes) into a thread-local read (docs/ARCHITECTURE.md#per-frame-cost).
//!
//! Why a borrow outlives the map lock soundly:
//! - a record leaves its map only when its handle (or a parent) is destroyed, and every change to
//!   any map advances one process-wide generation while the map lock is held, so a cache entry made
//!   before a removal never matches again;
//! - a borrow lasts one call on that handle, and OpenXR makes destroying a handle externally
//!   synchronised with every other use of it and of its children
//!   (<https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#threading-behavior>): no call
//!   on the handle runs while it is destroyed, so the record cannot be freed under the borrow.
//!
//! [`Borrowed`] is neither `Send` nor `Sync` and cannot be cloned, so it cannot be kept past the
//! call on another thread. Hooks that create or destroy handles, or keep a record beyond their call,
//! take the `Arc` ([`Records::get`]).

use std::cell::Cell;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::marker::PhantomData;
use std::ops::{Deref, DerefMut};
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use crate::common::lock::{MapGuard, MapLock};

/// A `Hasher` for handle keys: handles are already unique integers, so a multiplicative mix is all a
/// hash map needs, at a fraction of SipHash's cost.
#[derive(Default)]
pub struct HandleHasher(u64);

impl Hasher for HandleHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ u64::from(b)).wrapping_mul(MIX);
        }
    }

    fn write_u64(&mut self, v: u64) {
        self.0 = v.wrapping_mul(MIX);
    }
}

/// The 64-bit golden-ratio constant of Fibonacci hashing.
const MIX: u64 = 0x9E37_79B9_7F4A_7C15;

/// The map itself.
pub type HandleMap<T> = HashMap<u64, Arc<T>, BuildHasherDefault<HandleHasher>>;

/// Advanced whenever any [`Records`] is created or changed: a cache entry is good only while it
/// holds the value read before the entry's record was looked up.
static GENERATION: AtomicU64 = AtomicU64::new(1);

/// Cache slots per thread: enough for the handles a render thread uses every frame (a session, and
/// two to six swapchains) to sit in distinct slots.
const SLOTS: usize = 16;

/// One thread's cached resolution of one handle.
#[derive(Clone, Copy)]
struct Entry {
    /// The address of the [`Records`] it came from (0: empty).
    owner: usize,
    raw: u64,
    generation: u64,
    record: *const (),
}

/// A cache slot: an [`Entry`] field by field, so a look-up loads only the fields it compares (a
/// whole-entry copy costs a store-forwarding stall on every hit).
struct Slot {
    owner: Cell<usize>,
    raw: Cell<u64>,
    generation: Cell<u64>,
    record: Cell<*const ()>,
}

impl Slot {
    const fn empty() -> Slot {
        Slot {
            owner: Cell::new(0),
            raw: Cell::new(0),
            generation: Cell::new(0),
            record: Cell::new(std::ptr::null()),
        }
    }

    /// The record, where this slot holds `raw` of `owner` as of `generation`.
    fn hit(&self, owner: usize, raw: u64, generation: u64) -> Option<*const ()> {
        (self.raw.get() == raw && self.owner.get() == owner && self.generation.get() == generation)
            .then(|| self.record.get())
    }

    fn get(&self) -> Entry {
        Entry {
            owner: self.owner.get(),
            raw: self.raw.get(),
            generation: self.generation.get(),
            record: self.record.get(),
        }
    }

    fn set(&self, e: Entry) {
        self.owner.set(e.owner);
        self.raw.set(e.raw);
        self.generation.set(e.generation);
        self.record.set(e.record);
    }
}

thread_local! {
    /// Per thread, so entries need no synchronisation; `const`-initialised and without a
    /// destructor, so access is a plain thread-local read.
    static CACHE: [Slot; SLOTS] = const { [const { Slot::empty() }; SLOTS] };
}

/// The first of the two slots where `raw` of `owner` may sit: the cache is two-way set-associative,
/// so two handles used in turn every frame (a session and its swapchain) never evict each other.
fn set_of(owner: usize, raw: u64) -> usize {
    (((raw ^ owner as u64).wrapping_mul(MIX) >> 61) as usize % (SLOTS / 2)) * 2
}

/// Records of one handle type.
pub struct Records<T> {
    map: MapLock<HandleMap<T>>,
}

impl<T> Records<T> {
    pub fn new(what: &'static str) -> Records<T> {
        // A new map may sit where a dropped one was: entries of the old one must not match.
        GENERATION.fetch_add(1, Ordering::Release);
        Records {
            map: MapLock::new(what, HashMap::default()),
        }
    }

    /// Takes the map lock to read the map.
    pub fn read(&self) -> MapGuard<'_, parking_lot::MutexGuard<'_, HandleMap<T>>> {
        self.map.read()
    }

    /// Takes the map lock to change the map; every thread's cached look-ups are void once it is
    /// released.
    pub fn write(&self) -> RecordsWrite<'_, T> {
        RecordsWrite {
            guard: self.map.write(),
        }
    }

    /// The record of `raw`, shared: for a hook that keeps it past its call or destroys it.
    pub fn get(&self, raw: u64) -> Option<Arc<T>> {
        self.map.read().get(&raw).cloned()
    }

    /// The record of `raw`, borrowed for the call that asks (see the module documentation for why
    /// that is sound): from this thread's cache where it is still good, else from the map under its
    /// lock, then cached.
    #[inline]
    pub fn borrow(&self, raw: u64) -> Option<Borrowed<'_, T>> {
        let owner = self as *const Records<T> as usize;
        let set = set_of(owner, raw);
        // Read before the map is: an entry made from this look-up is void if the map changes
        // after it.
        let now = GENERATION.load(Ordering::Acquire);
        let cached = CACHE
            .try_with(|c| {
                c[set]
                    .hit(owner, raw, now)
                    .or_else(|| c[set + 1].hit(owner, raw, now))
            })
            .ok()
            .flatten();
        match cached {
            Some(record) => NonNull::new(record.cast_mut().cast::<T>()).map(Borrowed::new),
            None => self.borrow_from_map(raw, owner, set, now),
        }
    }

    /// [`Records::borrow`]'s miss: the map under its lock, then the cache.
    #[cold]
    #[inline(never)]
    fn borrow_from_map(
        &self,
        raw: u64,
        owner: usize,
        set: usize,
        now: u64,
    ) -> Option<Borrowed<'_, T>> {
        let record = NonNull::from(&**self.map.read().get(&raw)?);
        let entry = Entry {
            owner,
            raw,
            generation: now,
            record: record.as_ptr().cast_const().cast(),
        };
        // The newest entry goes first in its set and the one it displaces second, unless that
        // one is void anyway. Ignored where the thread's cache is gone (the thread is exiting):
        // the look-up stands.
        let _ = CACHE.try_with(|c| {
            let first = c[set].get();
            c[set].set(entry);
            if first.generation == now && first.owner != 0 {
                c[set + 1].set(first);
            }
        });
        Some(Borrowed::new(record))
    }
}

/// A held map lock for changing a map; advances the generation before the lock is released.
pub struct RecordsWrite<'a, T> {
    guard: MapGuard<'a, parking_lot::MutexGuard<'a, HandleMap<T>>>,
}

impl<T> Deref for RecordsWrite<'_, T> {
    type Target = HandleMap<T>;
    fn deref(&self) -> &HandleMap<T> {
        &self.guard
    }
}

impl<T> DerefMut for RecordsWrite<'_, T> {
    fn deref_mut(&mut self) -> &mut HandleMap<T> {
        &mut self.guard
    }
}

impl<T> Drop for RecordsWrite<'_, T> {
    fn drop(&mut self) {
        // Runs before `guard` is dropped, so inside the lock: a reader that found a record this
        // write removes read the generation before this.
        GENERATION.fetch_add(1, Ordering::Release);
    }
}

/// A record borrowed from its map for one call ([`Records::borrow`]).
pub struct Borrowed<'a, T> {
    record: NonNull<T>,
    /// Tied to the map, and `!Send`/`!Sync`: a borrow stays on the thread whose call made it.
    _map: PhantomData<(&'a Records<T>, *const T)>,
}

impl<T> Borrowed<'_, T> {
    fn new(record: NonNull<T>) -> Self {
        Borrowed {
            record,
            _map: PhantomData,
        }
    }
}

impl<T> Deref for Borrowed<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        // SAFETY: the pointer came from an `Arc` the map held when this thread looked it up, and
        // the map has not changed since (the generation matched), so the record is alive; it stays
        // alive for the call, because only destroying its handle frees it and the application
        // must not do that while this call on the handle runs (module documentation).
        unsafe { self.record.as_ref() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn borrows_find_the_record_and_never_one_that_left() {
        let r: Records<u32> = Records::new("test");
        r.write().insert(7, Arc::new(70));
        assert_eq!(r.borrow(7).as_deref(), Some(&70));
        // Cached now; still the same.
        assert_eq!(r.borrow(7).as_deref(), Some(&70));
        assert!(r.borrow(8).is_none());
        let gone = r.write().remove(&7);
        assert_eq!(gone.as_deref(), Some(&70));
        assert!(r.borrow(7).is_none(), "a removed record was still borrowed");
        // The same handle value for a new record: the new one, not the cached old one.
        r.write().insert(7, Arc::new(71));
        assert_eq!(r.borrow(7).as_deref(), Some(&71));
    }

    #[test]
    fn maps_with_the_same_handles_do_not_mix() {
        let a: Records<u32> = Records::new("a");
        let b: Records<u32> = Records::new("b");
        a.write().insert(1, Arc::new(10));
        b.write().insert(1, Arc::new(20));
        for _ in 0..3 {
            assert_eq!(a.borrow(1).as_deref(), Some(&10));
            assert_eq!(b.borrow(1).as_deref(), Some(&20));
        }
    }

    #[test]
    fn many_handles_sharing_slots_each_find_their_own() {
        let r: Records<u64> = Records::new("many");
        for h in 1..=100u64 {
            r.write().insert(h, Arc::new(h * 3));
        }
        for _ in 0..2 {
            for h in 1..=100u64 {
                assert_eq!(r.borrow(h).as_deref(), Some(&(h * 3)));
            }
        }
    }

    #[test]
    fn a_change_on_another_thread_voids_this_threads_cache() {
        let r: Arc<Records<u32>> = Arc::new(Records::new("threads"));
        r.write().insert(5, Arc::new(50));
        assert_eq!(r.borrow(5).as_deref(), Some(&50));
        let other = Arc::clone(&r);
        std::thread::spawn(move || {
            other.write().remove(&5);
        })
        .join()
        .unwrap();
        assert!(r.borrow(5).is_none());
    }
}
