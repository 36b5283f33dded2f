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
//! Separate queues may run in any order the application's semaphores allow, and the double makes
//! that visible instead of hiding it: work submitted on an extra queue is held back (the queue is
//! "behind") and reaches the driver only when something depends on it or waits for it: a
//! submission on any of the device's queues that waits on a semaphore, a fence or semaphore wait
//! or query, `vkQueueWaitIdle`, `vkDeviceWaitIdle`, any other fault-injectable command, or
//! `vkDestroyDevice`. A submission on queue 0 that waits on nothing overtakes it, as it may on
//! hardware. So work on two queues that the application (or a layer) did not order runs in the
//! order that exposes the missing dependency: a pass on queue 0 reads what an extra queue's
//! earlier, unfinished work has not written yet. Submissions whose batches chain anything but a
//! `VkTimelineSemaphoreSubmitInfo` go down at once, after the held-back work.
//!
//! Validation (above the double) sees the queues the double reports, so its synchronization
//! validation checks hazards between them as between separate queues.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex};

use ash::vk::{self, Handle as _};

use super::{execute1, execute2, key, lock, DeviceData, Key};

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
            ci.p_queue_create_infos
                .cast::<vk::DeviceQueueCreateInfo<'static>>(),
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

/// A batch of `vkQueueSubmit` held back, with everything it points at owned.
struct Held1 {
    waits: Vec<vk::Semaphore>,
    masks: Vec<vk::PipelineStageFlags>,
    cbs: Vec<vk::CommandBuffer>,
    signals: Vec<vk::Semaphore>,
    /// The timeline values, where the batch chained them.
    values: Option<(Vec<u64>, Vec<u64>)>,
}

/// A batch of `vkQueueSubmit2` held back.
struct Held2 {
    flags: vk::SubmitFlags,
    waits: Vec<vk::SemaphoreSubmitInfo<'static>>,
    cbs: Vec<vk::CommandBufferSubmitInfo<'static>>,
    signals: Vec<vk::SemaphoreSubmitInfo<'static>>,
}

enum Held {
    V1(Vec<Held1>),
    V2(Vec<Held2>),
}

/// One held-back submission: its extra queue, batches, fence and command buffers.
struct Deferred {
    device: Key,
    queue: vk::Queue,
    held: Held,
    fence: vk::Fence,
    cbs: Vec<u64>,
}

// SAFETY: handles and owned arrays; the raw pointers in `Held2`'s structs are null (checked).
unsafe impl Send for Deferred {}

/// Submissions held back on extra queues, in submission order.
static DEFERRED: Mutex<Vec<Deferred>> = Mutex::new(Vec::new());

/// # Safety
/// `p` null or valid for `n`.
unsafe fn owned<T: Copy>(p: *const T, n: u32) -> Vec<T> {
    if p.is_null() || n == 0 {
        Vec::new()
    } else {
        // SAFETY: as the caller promised.
        unsafe { std::slice::from_raw_parts(p, n as usize) }.to_vec()
    }
}

/// Holds back a `vkQueueSubmit` of `subs` on `queue` where it is an extra queue and every batch
/// chains nothing or a timeline-semaphore struct alone: `true` where it did.
///
/// # Safety
/// `subs` valid as the command requires.
pub unsafe fn defer1(
    d: &DeviceData,
    queue: vk::Queue,
    subs: &[vk::SubmitInfo<'_>],
    fence: vk::Fence,
    cbs: &[u64],
) -> bool {
    if real(queue) == queue {
        return false;
    }
    let mut held = Vec::with_capacity(subs.len());
    for s in subs {
        let mut values = None;
        if !s.p_next.is_null() {
            // SAFETY: a valid chain.
            let b = unsafe { &*(s.p_next as *const vk::BaseInStructure<'_>) };
            if b.s_type != vk::StructureType::TIMELINE_SEMAPHORE_SUBMIT_INFO || !b.p_next.is_null()
            {
                return false;
            }
            // SAFETY: found by its sType.
            let t = unsafe { &*(s.p_next as *const vk::TimelineSemaphoreSubmitInfo<'_>) };
            // SAFETY: the arrays, valid for their counts.
            values = Some(unsafe {
                (
                    owned(t.p_wait_semaphore_values, t.wait_semaphore_value_count),
                    owned(t.p_signal_semaphore_values, t.signal_semaphore_value_count),
                )
            });
        }
        // SAFETY: the batch's arrays, valid for their counts.
        held.push(unsafe {
            Held1 {
                waits: owned(s.p_wait_semaphores, s.wait_semaphore_count),
                masks: owned(s.p_wait_dst_stage_mask, s.wait_semaphore_count),
                cbs: owned(s.p_command_buffers, s.command_buffer_count),
                signals: owned(s.p_signal_semaphores, s.signal_semaphore_count),
                values,
            }
        });
    }
    // SAFETY: a live device handle.
    let device = unsafe { key(d.handle.as_raw()) };
    lock(&DEFERRED).push(Deferred {
        device,
        queue,
        held: Held::V1(held),
        fence,
        cbs: cbs.to_vec(),
    });
    true
}

/// [`defer1`] for `vkQueueSubmit2`: batches, semaphore and command-buffer infos chaining nothing.
///
/// # Safety
/// As [`defer1`].
pub unsafe fn defer2(
    d: &DeviceData,
    queue: vk::Queue,
    subs: &[vk::SubmitInfo2<'_>],
    fence: vk::Fence,
    cbs: &[u64],
) -> bool {
    if real(queue) == queue {
        return false;
    }
    let mut held = Vec::with_capacity(subs.len());
    for s in subs {
        if !s.p_next.is_null() {
            return false;
        }
        // SAFETY: the batch's arrays, valid for their counts; their lifetimes are only made
        // 'static for storage, every pointer in them checked null below.
        let h = unsafe {
            Held2 {
                flags: s.flags,
                waits: owned(
                    s.p_wait_semaphore_infos
                        .cast::<vk::SemaphoreSubmitInfo<'static>>(),
                    s.wait_semaphore_info_count,
                ),
                cbs: owned(
                    s.p_command_buffer_infos
                        .cast::<vk::CommandBufferSubmitInfo<'static>>(),
                    s.command_buffer_info_count,
                ),
                signals: owned(
                    s.p_signal_semaphore_infos
                        .cast::<vk::SemaphoreSubmitInfo<'static>>(),
                    s.signal_semaphore_info_count,
                ),
            }
        };
        if h.waits
            .iter()
            .chain(&h.signals)
            .any(|i| !i.p_next.is_null())
            || h.cbs.iter().any(|i| !i.p_next.is_null())
        {
            return false;
        }
        held.push(h);
    }
    // SAFETY: a live device handle.
    let device = unsafe { key(d.handle.as_raw()) };
    lock(&DEFERRED).push(Deferred {
        device,
        queue,
        held: Held::V2(held),
        fence,
        cbs: cbs.to_vec(),
    });
    true
}

/// Lets `d`'s held-back submissions reach the driver, in the order they were made.
///
/// # Safety
/// `d` must be live; its queues externally synchronised by the caller's command as the
/// specification requires of the command that depends on them.
pub unsafe fn catch_up(d: &Arc<DeviceData>) {
    if !ANY.load(Ordering::Acquire) {
        return;
    }
    // SAFETY: a live device handle.
    let device = unsafe { key(d.handle.as_raw()) };
    let mine: Vec<Deferred> = {
        let mut all = lock(&DEFERRED);
        if all.iter().all(|h| h.device != device) {
            return;
        }
        let (mine, rest) = std::mem::take(&mut *all)
            .into_iter()
            .partition(|h| h.device == device);
        *all = rest;
        mine
    };
    for h in mine {
        let r = match &h.held {
            Held::V1(batches) => {
                let timelines: Vec<Option<vk::TimelineSemaphoreSubmitInfo<'_>>> = batches
                    .iter()
                    .map(|b| {
                        b.values.as_ref().map(|(w, g)| {
                            vk::TimelineSemaphoreSubmitInfo::default()
                                .wait_semaphore_values(w)
                                .signal_semaphore_values(g)
                        })
                    })
                    .collect();
                let infos: Vec<vk::SubmitInfo<'_>> = batches
                    .iter()
                    .zip(&timelines)
                    .map(|(b, t)| vk::SubmitInfo {
                        p_next: t
                            .as_ref()
                            .map_or(std::ptr::null(), |t| t as *const _ as *const _),
                        wait_semaphore_count: b.waits.len() as u32,
                        p_wait_semaphores: b.waits.as_ptr(),
                        p_wait_dst_stage_mask: b.masks.as_ptr(),
                        command_buffer_count: b.cbs.len() as u32,
                        p_command_buffers: b.cbs.as_ptr(),
                        signal_semaphore_count: b.signals.len() as u32,
                        p_signal_semaphores: b.signals.as_ptr(),
                        ..Default::default()
                    })
                    .collect();
                // SAFETY: the owned batches live across the call.
                unsafe { execute1(d, h.queue, &infos, h.fence, h.cbs) }
            }
            Held::V2(batches) => {
                let infos: Vec<vk::SubmitInfo2<'_>> = batches
                    .iter()
                    .map(|b| {
                        vk::SubmitInfo2::default()
                            .flags(b.flags)
                            .wait_semaphore_infos(&b.waits)
                            .command_buffer_infos(&b.cbs)
                            .signal_semaphore_infos(&b.signals)
                    })
                    .collect();
                // SAFETY: as above.
                unsafe { execute2(d, h.queue, &infos, h.fence, h.cbs) }
            }
        };
        if r != vk::Result::SUCCESS {
            crate::record::error(format!(
                "a submission held back on an extra queue failed when it reached the driver: \
                 {r:?}"
            ));
        }
    }
}

/// The lock a device-wide call holds where the device has extra queues.
pub fn device_serial(d: &DeviceData) -> Option<std::sync::MutexGuard<'static, ()>> {
    // SAFETY: a live device handle.
    let k = unsafe { key(d.handle.as_raw()) };
    driver_count(k).map(|_| lock(&SHARED))
}
