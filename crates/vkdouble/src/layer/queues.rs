//! More queues of family 0 than the driver has ([`crate::fovea_vkdouble_set_queues`]): lavapipe
//! has one, and a layer that must order work across several graphics queues (vkd3d-proton uses
//! more than one) needs a device that has them.
//!
//! The extra queues are handles of the double's own (a word holding the loader's dispatch
//! pointer, as every dispatchable handle does) that stand for the driver's queue 0: each call on
//! one goes down on that queue, under one lock, so the queues are externally synchronised below
//! as the specification requires of the one queue they share. Semaphores, fences and submission
//! order are the driver's own and behave as they do: a semaphore signalled on one queue and waited
//! on another orders the two. What differs from separate hardware queues is only that their work
//! runs one submission after the other, in the order the calls reached the driver, so a
//! submission that waits for a signal still to be submitted on another of these queues would
//! wait for ever (the tests that use them never do). Only family 0 gets extra queues, and only on
//! a profile that offers shading rates (the double intercepts queue commands there); calls on
//! them: `vkGetDeviceQueue(2)`, `vkQueueSubmit`, `vkQueueSubmit2(KHR)`, `vkQueueWaitIdle`,
//! `vkQueueBindSparse`.
//!
//! Validation (above the double) sees the queues the double reports, so its synchronization
//! validation checks hazards between them as between separate queues.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::Mutex;

use ash::vk::{self, Handle as _};

use super::{key, lock, Key};

/// The queues of family 0 the next devices get, where above the driver's count (0: the driver's).
static WANTED: AtomicU32 = AtomicU32::new(0);
/// Whether any extra queue exists: the translation's fast path.
static ANY: AtomicBool = AtomicBool::new(false);

/// An extra queue: the driver's queue it stands for, and its device.
struct Extra {
    real: u64,
    device: Key,
    /// Which extra queue of the device (from 1).
    n: u32,
    /// The handle's storage: one word, the loader's dispatch pointer.
    _object: Box<usize>,
}

/// Extra queues by handle.
static EXTRA: Mutex<BTreeMap<u64, Extra>> = Mutex::new(BTreeMap::new());
/// Devices made with extra queues: the driver's queue count of family 0.
static DEVICES: Mutex<BTreeMap<Key, u32>> = Mutex::new(BTreeMap::new());
/// Held across every call on the driver's queue that extra queues share.
static SHARED: Mutex<()> = Mutex::new(());

/// Sets the queue count of family 0 the next devices are offered (0 or 1: the driver's).
pub fn set_wanted(n: u32) {
    WANTED.store(n, Ordering::Relaxed);
}

/// The count family 0 reports: the driver's, or more where more are wanted.
pub fn reported(family: u32, driver: u32) -> u32 {
    let w = WANTED.load(Ordering::Relaxed);
    if family == 0 && w > driver {
        w
    } else {
        driver
    }
}

/// Fills the family counts `props` (of `n`) with [`reported`].
///
/// # Safety
/// `props` must be valid for `n` writes.
pub unsafe fn fix_counts(props: *mut vk::QueueFamilyProperties, n: u32) {
    if props.is_null() || n == 0 {
        return;
    }
    // SAFETY: as the caller promised.
    let p = unsafe { &mut *props };
    p.queue_count = reported(0, p.queue_count);
}

/// The device create info's queue infos with family 0's count cut to the driver's `driver`
/// count, where it asks for more (the extra queues are the double's); `None` where it does not.
///
/// # Safety
/// `ci` must be a valid create info.
pub unsafe fn cut(
    ci: &vk::DeviceCreateInfo<'_>,
    driver: u32,
) -> Option<Vec<vk::DeviceQueueCreateInfo<'static>>> {
    if ci.p_queue_create_infos.is_null() || WANTED.load(Ordering::Relaxed) <= driver {
        return None;
    }
    // SAFETY: as the caller promised.
    let infos = unsafe {
        std::slice::from_raw_parts(
            ci.p_queue_create_infos as *const vk::DeviceQueueCreateInfo<'static>,
            ci.queue_create_info_count as usize,
        )
    };
    if !infos
        .iter()
        .any(|q| q.queue_family_index == 0 && q.queue_count > driver)
    {
        return None;
    }
    Some(
        infos
            .iter()
            .map(|q| {
                let mut q = *q;
                if q.queue_family_index == 0 {
                    q.queue_count = q.queue_count.min(driver);
                }
                q
            })
            .collect(),
    )
}

/// Notes that `device` was made with extra queues of family 0 beyond the driver's `driver`.
pub fn device_created(device: Key, driver: u32) {
    lock(&DEVICES).insert(device, driver);
}

/// The driver's queue count of family 0 where `device` has extra queues.
pub fn driver_count(device: Key) -> Option<u32> {
    lock(&DEVICES).get(&device).copied()
}

/// The `n`-th extra queue (from 1) of family 0 on `device` (whose dispatch word is `dispatch`),
/// standing for the driver's `real` queue: the same handle every time.
pub fn extra(device: Key, dispatch: usize, n: u32, real: vk::Queue) -> vk::Queue {
    let mut m = lock(&EXTRA);
    if let Some((&h, _)) = m.iter().find(|(_, e)| e.device == device && e.n == n) {
        return vk::Queue::from_raw(h);
    }
    let object = Box::new(dispatch);
    let h = &*object as *const usize as u64;
    m.insert(
        h,
        Extra {
            real: real.as_raw(),
            device,
            n,
            _object: object,
        },
    );
    ANY.store(true, Ordering::Release);
    vk::Queue::from_raw(h)
}

/// The driver's queue for `queue`: itself where it is not an extra one.
pub fn real(queue: vk::Queue) -> vk::Queue {
    if !ANY.load(Ordering::Acquire) {
        return queue;
    }
    lock(&EXTRA)
        .get(&queue.as_raw())
        .map_or(queue, |e| vk::Queue::from_raw(e.real))
}

/// The lock calls on `queue` of a device with extra queues hold: the queue they share.
///
/// # Safety
/// `queue` must be a live queue.
pub unsafe fn serial(queue: vk::Queue) -> Option<std::sync::MutexGuard<'static, ()>> {
    if !ANY.load(Ordering::Acquire) {
        return None;
    }
    // SAFETY: as the caller promised.
    let k = unsafe { key(queue.as_raw()) };
    driver_count(k).map(|_| lock(&SHARED))
}

/// What the double calls the driver with in place of a dispatchable handle: the driver's queue
/// for an extra one, the handle itself otherwise; and the lock a call on it holds.
pub trait Down: Copy {
    fn down(self) -> Self {
        self
    }

    /// # Safety
    /// `self` must be a live handle.
    unsafe fn serial(self) -> Option<std::sync::MutexGuard<'static, ()>> {
        None
    }
}

impl Down for vk::Device {}
impl Down for vk::CommandBuffer {}
impl Down for vk::Queue {
    fn down(self) -> Self {
        real(self)
    }

    unsafe fn serial(self) -> Option<std::sync::MutexGuard<'static, ()>> {
        // SAFETY: as the caller promised.
        unsafe { serial(self) }
    }
}

/// Forgets `device`'s extra queues at `vkDestroyDevice`.
pub fn device_destroyed(device: Key) {
    if lock(&DEVICES).remove(&device).is_some() {
        lock(&EXTRA).retain(|_, e| e.device != device);
    }
}
