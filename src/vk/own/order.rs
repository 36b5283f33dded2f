//! Ordering the layer's uploads against the application's other graphics queues ([`Order`]).
//!
//! The layer writes its shading-rate images (new shadows' clears, injected maps' uploads) in a
//! submission of its own on whichever graphics queue the application submits on next
//! (`crate::vk::own::calls`). The queue's submission order and the write's barriers order it
//! against that queue's work; the application's other queues are not ordered against it at all
//! (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#synchronization-implicit>:
//! implicit ordering holds within one queue only). vkd3d-proton, for one, submits on more than
//! one graphics-family queue, so on such a device a pass on another queue could read a map while
//! the upload writes it (write-after-read, the pass submitted before), or read it before the
//! upload has written it (read-after-write, the pass submitted after). Timeline semaphores of the
//! layer's own order both (docs/vulkan-layer.md#uploads-and-several-queues):
//!
//! - each application submit on a graphics queue gets, in the same call, a batch of the layer's
//!   in front (only where an upload happened since the queue last waited) that waits on the
//!   upload timeline at the last upload's value, and one behind that signals the queue's own
//!   timeline at the next value. A wait orders every command later in submission order, a signal
//!   every command earlier
//!   (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#synchronization-semaphores-waiting>,
//!   "…all commands that occur later in submission order";
//!   <https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#synchronization-semaphores-signaling>,
//!   "…all commands that occur earlier in submission order"), so the application's own batches,
//!   their chains, semaphores and values are passed down untouched: only the array around them is
//!   the layer's;
//! - the upload's submission waits on every other queue's timeline at the value its last
//!   submission signalled, and signals the upload timeline.
//!
//! Every wait is for a signal already submitted, never one still to come, so no queue can wait on
//! work the application may never submit. [`Order::gate`] makes "already submitted" exact: an
//! application submit holds it shared from reading the upload value to storing its own signal
//! value; the upload holds it exclusively from reading the queues' values to storing its own. A
//! shared lock of the device's own (one atomic operation when uncontended) and the queue's own
//! array storage, reused from call to call (the application synchronises each queue externally,
//! so its storage is never contended), keep a submit free of allocation and of process-wide
//! locks.
//!
//! The same timelines order the layer's reconstructions of coarse blocks (docs/reconstruction.md#queues):
//! they go into the application's command buffers and use scratch buffers of the device, shared
//! by every queue. Within one queue their barriers order them; across queues nothing would, so
//! once the device has recorded one ([`Order::serialise`]), every application submit on one of
//! these queues also waits, in the same front batch, on every other queue's last signal, already
//! submitted as above. Two queues' submissions then run one after the other, in the order they
//! were submitted: the price of one scratch per target size rather than one per queue.
//!
//! Only a device where the layer acts (emulating or injecting) and whose application created more
//! than one graphics-family queue gets an [`Order`]; with one such queue there is nothing to
//! order and submits go down as before. The timeline-semaphore feature is enabled for it at
//! device creation (`crate::vk::hooks::device`).

use std::sync::atomic::{AtomicU64, Ordering};

use ash::vk;
use ash::vk::Handle as _;

/// One application graphics queue's timeline and the storage its submits are rebuilt in.
pub struct Lane {
    pub queue: u64,
    pub timeline: vk::Semaphore,
    /// The value the queue's last submission signals (0: none yet).
    pub signalled: AtomicU64,
    /// The upload value the queue's submissions wait for already.
    pub waited: AtomicU64,
    scratch: parking_lot::Mutex<Scratch>,
}

/// The arrays a submit is rebuilt in: the application's batches between the layer's two, and the
/// layer's semaphore structs they point at. Filled and used within one call.
struct Scratch {
    submits: Vec<vk::SubmitInfo<'static>>,
    submits2: Vec<vk::SubmitInfo2<'static>>,
    /// The front batch's waits: the upload timeline, then (where the order serialises) the other
    /// queues' timelines; sized for all of them at device creation.
    waits: Vec<vk::Semaphore>,
    wait_values: Vec<u64>,
    wait_stages: Vec<vk::PipelineStageFlags>,
    waits2: Vec<vk::SemaphoreSubmitInfo<'static>>,
    signal_value: u64,
    wait_timeline: vk::TimelineSemaphoreSubmitInfo<'static>,
    signal_timeline: vk::TimelineSemaphoreSubmitInfo<'static>,
    signal2: vk::SemaphoreSubmitInfo<'static>,
}

// SAFETY: the raw pointers in `Scratch` point into the same `Scratch` or at the caller's arrays,
// and only during one submit call made under the lane's lock; nothing reads them afterwards.
unsafe impl Send for Scratch {}

/// The waits of an upload's submission, rebuilt in storage made at device creation.
pub struct UploadWaits {
    pub semaphores: Vec<vk::Semaphore>,
    pub values: Vec<u64>,
    pub stages: Vec<vk::PipelineStageFlags>,
}

// SAFETY: plain handles and values.
unsafe impl Send for UploadWaits {}

/// A device's cross-queue ordering of the layer's uploads (see the module documentation).
pub struct Order {
    pub upload: vk::Semaphore,
    /// The value the last upload's submission signals on [`Order::upload`] (0: none yet).
    pub uploaded: AtomicU64,
    pub lanes: Box<[Lane]>,
    /// Shared by application submits, exclusive for an upload's (see the module documentation).
    pub gate: parking_lot::RwLock<()>,
    pub waits: parking_lot::Mutex<UploadWaits>,
    /// Set once the device recorded a reconstruction of coarse blocks (docs/reconstruction.md):
    /// its scratch buffers are the device's, shared by every queue, so from then on each
    /// application submit on one of these queues also waits on every other queue's last signal
    /// ([`Order::serialise`]), and no two queues' reconstructions run at once.
    serialised: std::sync::atomic::AtomicBool,
}

/// A timeline semaphore at 0.
///
/// # Safety
/// `d` must be live, with the timeline-semaphore feature enabled.
unsafe fn timeline(d: &ash::Device) -> Result<vk::Semaphore, vk::Result> {
    let mut ty = vk::SemaphoreTypeCreateInfo::default()
        .semaphore_type(vk::SemaphoreType::TIMELINE)
        .initial_value(0);
    // SAFETY: as the caller promised; the struct lives across the call.
    unsafe { d.create_semaphore(&vk::SemaphoreCreateInfo::default().push_next(&mut ty), None) }
}

impl Order {
    /// Timelines for the application's graphics `queues` of `d` (more than one), and an upload
    /// timeline; nothing is left behind on failure.
    ///
    /// # Safety
    /// `d` must be live, created with the timeline-semaphore feature.
    pub unsafe fn new(d: &ash::Device, queues: &[(u64, u32)]) -> Result<Order, vk::Result> {
        let mut made = Vec::with_capacity(queues.len() + 1);
        for _ in 0..=queues.len() {
            // SAFETY: as the caller promised.
            match unsafe { timeline(d) } {
                Ok(s) => made.push(s),
                Err(e) => {
                    for s in made {
                        // SAFETY: just made, never used.
                        unsafe { d.destroy_semaphore(s, None) };
                    }
                    return Err(e);
                }
            }
        }
        Ok(Order::from_parts(queues, &made))
    }

    /// An order for `queues` with their timelines `made` (one per queue, then the upload's).
    fn from_parts(queues: &[(u64, u32)], made: &[vk::Semaphore]) -> Order {
        let upload = made[queues.len()];
        let lanes = queues
            .iter()
            .zip(made)
            .map(|(&(queue, _), &timeline)| Lane {
                queue,
                timeline,
                signalled: AtomicU64::new(0),
                waited: AtomicU64::new(0),
                scratch: parking_lot::Mutex::new(Scratch {
                    submits: Vec::with_capacity(4),
                    submits2: Vec::with_capacity(4),
                    waits: Vec::with_capacity(queues.len()),
                    wait_values: Vec::with_capacity(queues.len()),
                    wait_stages: Vec::with_capacity(queues.len()),
                    waits2: Vec::with_capacity(queues.len()),
                    signal_value: 0,
                    wait_timeline: vk::TimelineSemaphoreSubmitInfo::default(),
                    signal_timeline: vk::TimelineSemaphoreSubmitInfo::default(),
                    signal2: vk::SemaphoreSubmitInfo::default(),
                }),
            })
            .collect();
        Order {
            upload,
            uploaded: AtomicU64::new(0),
            lanes,
            gate: parking_lot::RwLock::new(()),
            waits: parking_lot::Mutex::new(UploadWaits {
                semaphores: Vec::with_capacity(queues.len()),
                values: Vec::with_capacity(queues.len()),
                stages: Vec::with_capacity(queues.len()),
            }),
            serialised: std::sync::atomic::AtomicBool::new(false),
        }
    }

    /// From now on each application submit on one of the queues waits, in front of its batches,
    /// on every other queue's last signal as well: the queues' submissions run in the order they
    /// were submitted in, one queue's after another's. Called when the device first records a
    /// reconstruction, whose scratch buffers every queue shares (docs/reconstruction.md#queues).
    pub fn serialise(&self) {
        self.serialised.store(true, Ordering::Release);
    }

    /// The front batch's waits for a submit on `lane`, into its storage: the upload timeline at
    /// `uploaded` where `wait`, then where the order serialises every other queue's last signal.
    fn front_waits(&self, lane: &Lane, s: &mut Scratch, wait: bool, uploaded: u64) {
        s.waits.clear();
        s.wait_values.clear();
        s.wait_stages.clear();
        if wait {
            s.waits.push(self.upload);
            s.wait_values.push(uploaded);
            s.wait_stages.push(vk::PipelineStageFlags::ALL_COMMANDS);
        }
        if self.serialised.load(Ordering::Acquire) {
            for l in self.lanes.iter().filter(|l| l.queue != lane.queue) {
                let v = l.signalled.load(Ordering::Acquire);
                if v > 0 {
                    s.waits.push(l.timeline);
                    s.wait_values.push(v);
                    s.wait_stages.push(vk::PipelineStageFlags::ALL_COMMANDS);
                }
            }
        }
        s.waits2.clear();
        for (&semaphore, &value) in s.waits.iter().zip(&s.wait_values) {
            s.waits2.push(
                vk::SemaphoreSubmitInfo::default()
                    .semaphore(semaphore)
                    .value(value)
                    .stage_mask(vk::PipelineStageFlags2::ALL_COMMANDS),
            );
        }
    }

    /// The lane of `queue`, where it is one of the application's graphics queues.
    pub fn lane(&self, queue: vk::Queue) -> Option<&Lane> {
        self.lanes.iter().find(|l| l.queue == queue.as_raw())
    }

    /// Submits an upload on `queue`: `submit` gets the waits on every other queue's last signal
    /// and the upload timeline's next value to signal, and returns the driver's result. On
    /// success later application submits on other queues wait for it.
    ///
    /// # Safety
    /// Inside the application's submit on `queue`; `submit` submits on it.
    pub unsafe fn upload(
        &self,
        queue: vk::Queue,
        submit: impl FnOnce(&UploadWaits, u64) -> Result<(), vk::Result>,
    ) -> Result<(), vk::Result> {
        let _exclusive = self.gate.write();
        let mut w = self.waits.lock();
        w.semaphores.clear();
        w.values.clear();
        w.stages.clear();
        for l in self.lanes.iter().filter(|l| l.queue != queue.as_raw()) {
            let v = l.signalled.load(Ordering::Acquire);
            if v > 0 {
                w.semaphores.push(l.timeline);
                w.values.push(v);
                // The upload's first barrier waits on ALL_COMMANDS of earlier work; the same here.
                w.stages.push(vk::PipelineStageFlags::ALL_COMMANDS);
            }
        }
        let value = self.uploaded.load(Ordering::Acquire) + 1;
        submit(&w, value)?;
        self.uploaded.store(value, Ordering::Release);
        // The uploading queue's own later work is ordered by its submission order.
        if let Some(l) = self.lane(queue) {
            l.waited.store(value, Ordering::Release);
        }
        Ok(())
    }

    /// `vkQueueSubmit` of the application's `count` batches at `submits` on `queue`, between the
    /// layer's wait on the last upload (where the queue has not waited for it yet) and its signal
    /// of the queue's timeline; passed down as it is on a queue without a lane.
    ///
    /// # Safety
    /// The application's valid arguments; `next` the next layer's `vkQueueSubmit`.
    pub unsafe fn submit(
        &self,
        next: vk::PFN_vkQueueSubmit,
        queue: vk::Queue,
        count: u32,
        submits: *const vk::SubmitInfo<'_>,
        fence: vk::Fence,
    ) -> vk::Result {
        let Some(lane) = self.lane(queue) else {
            // SAFETY: the caller's arguments.
            return unsafe { next(queue, count, submits, fence) };
        };
        let _shared = self.gate.read();
        let mut s = lane.scratch.lock();
        let s = &mut *s;
        let uploaded = self.uploaded.load(Ordering::Acquire);
        let wait = uploaded > lane.waited.load(Ordering::Acquire);
        let value = lane.signalled.load(Ordering::Acquire) + 1;
        self.front_waits(lane, s, wait, uploaded);
        s.signal_value = value;
        s.wait_timeline = vk::TimelineSemaphoreSubmitInfo {
            wait_semaphore_value_count: s.wait_values.len() as u32,
            p_wait_semaphore_values: s.wait_values.as_ptr(),
            ..Default::default()
        };
        s.signal_timeline = vk::TimelineSemaphoreSubmitInfo {
            signal_semaphore_value_count: 1,
            p_signal_semaphore_values: &s.signal_value,
            ..Default::default()
        };
        s.submits.clear();
        if !s.waits.is_empty() {
            s.submits.push(vk::SubmitInfo {
                p_next: &s.wait_timeline as *const _ as *const _,
                wait_semaphore_count: s.waits.len() as u32,
                p_wait_semaphores: s.waits.as_ptr(),
                p_wait_dst_stage_mask: s.wait_stages.as_ptr(),
                ..Default::default()
            });
        }
        if count > 0 && !submits.is_null() {
            // SAFETY: the caller's array of `count` batches, copied as they are (their pointers
            // stay the application's); only the lifetime parameter differs.
            let app = unsafe {
                std::slice::from_raw_parts(
                    submits.cast::<vk::SubmitInfo<'static>>(),
                    count as usize,
                )
            };
            s.submits.extend_from_slice(app);
        }
        s.submits.push(vk::SubmitInfo {
            p_next: &s.signal_timeline as *const _ as *const _,
            signal_semaphore_count: 1,
            p_signal_semaphores: &lane.timeline,
            ..Default::default()
        });
        // SAFETY: the rebuilt array and everything it points at live across the call.
        let r = unsafe { next(queue, s.submits.len() as u32, s.submits.as_ptr(), fence) };
        if r == vk::Result::SUCCESS {
            lane.signalled.store(value, Ordering::Release);
            if wait {
                lane.waited.store(uploaded, Ordering::Release);
            }
        }
        r
    }

    /// [`Order::submit`] for `vkQueueSubmit2` and its KHR alias.
    ///
    /// # Safety
    /// As [`Order::submit`]; `next` the next layer's `vkQueueSubmit2`.
    pub unsafe fn submit2(
        &self,
        next: vk::PFN_vkQueueSubmit2,
        queue: vk::Queue,
        count: u32,
        submits: *const vk::SubmitInfo2<'_>,
        fence: vk::Fence,
    ) -> vk::Result {
        let Some(lane) = self.lane(queue) else {
            // SAFETY: the caller's arguments.
            return unsafe { next(queue, count, submits, fence) };
        };
        let _shared = self.gate.read();
        let mut s = lane.scratch.lock();
        let s = &mut *s;
        let uploaded = self.uploaded.load(Ordering::Acquire);
        let wait = uploaded > lane.waited.load(Ordering::Acquire);
        let value = lane.signalled.load(Ordering::Acquire) + 1;
        self.front_waits(lane, s, wait, uploaded);
        s.signal2 = vk::SemaphoreSubmitInfo::default()
            .semaphore(lane.timeline)
            .value(value)
            .stage_mask(vk::PipelineStageFlags2::ALL_COMMANDS);
        s.submits2.clear();
        if !s.waits2.is_empty() {
            s.submits2.push(vk::SubmitInfo2 {
                wait_semaphore_info_count: s.waits2.len() as u32,
                p_wait_semaphore_infos: s.waits2.as_ptr(),
                ..Default::default()
            });
        }
        if count > 0 && !submits.is_null() {
            // SAFETY: as in [`Order::submit`].
            let app = unsafe {
                std::slice::from_raw_parts(
                    submits.cast::<vk::SubmitInfo2<'static>>(),
                    count as usize,
                )
            };
            s.submits2.extend_from_slice(app);
        }
        s.submits2.push(vk::SubmitInfo2 {
            signal_semaphore_info_count: 1,
            p_signal_semaphore_infos: &s.signal2,
            ..Default::default()
        });
        // SAFETY: the rebuilt array and everything it points at live across the call.
        let r = unsafe { next(queue, s.submits2.len() as u32, s.submits2.as_ptr(), fence) };
        if r == vk::Result::SUCCESS {
            lane.signalled.store(value, Ordering::Release);
            if wait {
                lane.waited.store(uploaded, Ordering::Release);
            }
        }
        r
    }

    /// Destroys the semaphores at `vkDestroyDevice`.
    ///
    /// # Safety
    /// The device must be live, the application done with it.
    pub unsafe fn destroy(&self, d: &ash::Device) {
        // SAFETY: as the caller promised.
        unsafe {
            for l in self.lanes.iter() {
                d.destroy_semaphore(l.timeline, None);
            }
            d.destroy_semaphore(self.upload, None);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::common::alloc_count::allocations;
    use crate::common::lock::shared_taken;

    thread_local! {
        /// What the fake driver's last submit got: per batch, its waits (semaphore, value), its
        /// command buffer count and its signals (semaphore, value).
        static SEEN: std::cell::RefCell<Vec<Batch>> = const { std::cell::RefCell::new(Vec::new()) };
    }

    type Batch = (Vec<(u64, u64)>, u32, Vec<(u64, u64)>);

    /// A driver's `vkQueueSubmit`: notes what it got (into storage sized beforehand).
    unsafe extern "system" fn next(
        _: vk::Queue,
        count: u32,
        submits: *const vk::SubmitInfo<'_>,
        _: vk::Fence,
    ) -> vk::Result {
        SEEN.with(|seen| {
            let mut seen = seen.borrow_mut();
            for (i, slot) in seen.iter_mut().enumerate() {
                slot.0.clear();
                slot.2.clear();
                slot.1 = u32::MAX;
                if i >= count as usize {
                    continue;
                }
                // SAFETY: the caller's batches and what they point at, valid for their counts.
                unsafe {
                    let s = &*submits.add(i);
                    let t = (s.p_next as *const vk::TimelineSemaphoreSubmitInfo<'_>).as_ref();
                    for w in 0..s.wait_semaphore_count as usize {
                        let v = t.map_or(0, |t| *t.p_wait_semaphore_values.add(w));
                        slot.0.push(((*s.p_wait_semaphores.add(w)).as_raw(), v));
                    }
                    slot.1 = s.command_buffer_count;
                    for g in 0..s.signal_semaphore_count as usize {
                        let v = t.map_or(0, |t| *t.p_signal_semaphore_values.add(g));
                        slot.2.push(((*s.p_signal_semaphores.add(g)).as_raw(), v));
                    }
                }
            }
        });
        vk::Result::SUCCESS
    }

    fn seen() -> Vec<Batch> {
        SEEN.with(|s| {
            s.borrow()
                .iter()
                .filter(|b| b.1 != u32::MAX)
                .cloned()
                .collect()
        })
    }

    /// Two graphics queues: each application submit goes down between a wait on the last upload
    /// (only where one happened since that queue last waited) and a signal of its own timeline
    /// at a value one higher each time; an upload waits on the other queue's last signal. In
    /// steady state a submit allocates nothing and takes no process-wide lock.
    #[test]
    fn submits_are_wrapped_in_the_queues_timelines_without_allocating_or_locking() {
        let (q0, q1) = (0x9000_u64, 0x9001_u64);
        let sems = [0x51, 0x52, 0x5f].map(vk::Semaphore::from_raw);
        let order = Order::from_parts(&[(q0, 0), (q1, 0)], &sems);
        SEEN.with(|s| {
            *s.borrow_mut() = (0..4)
                .map(|_| (Vec::with_capacity(4), 0, Vec::with_capacity(4)))
                .collect()
        });
        let cbs = [vk::CommandBuffer::from_raw(0xcb)];
        let app = [vk::SubmitInfo::default().command_buffers(&cbs)];
        let submit = |q: u64| {
            // SAFETY: the fake driver reads what it is given.
            unsafe {
                order.submit(
                    next,
                    vk::Queue::from_raw(q),
                    1,
                    app.as_ptr(),
                    vk::Fence::null(),
                )
            }
        };
        // Warm-up: the queues' storage grows once.
        assert_eq!(submit(q0), vk::Result::SUCCESS);
        assert_eq!(submit(q1), vk::Result::SUCCESS);
        assert_eq!(seen(), [(vec![], 1, vec![]), (vec![], 0, vec![(0x52, 1)])]);
        // An upload on queue 0 waits on queue 1's last signal and signals the upload timeline.
        // SAFETY: the closure stands for the driver.
        let r = unsafe {
            order.upload(vk::Queue::from_raw(q0), |w, value| {
                assert_eq!(w.semaphores, [sems[1]]);
                assert_eq!(w.values, [1]);
                assert_eq!(value, 1);
                Ok(())
            })
        };
        assert_eq!(r, Ok(()));
        // Allocations and process-wide locks counted around the submits alone (reading what the
        // fake driver saw allocates).
        let (mut allocs, mut locks) = (0, 0);
        let mut counted = |q: u64| {
            let (a, l) = (allocations(), shared_taken());
            assert_eq!(submit(q), vk::Result::SUCCESS);
            allocs += allocations() - a;
            locks += shared_taken() - l;
            seen()
        };
        // Queue 1 now waits for the upload once; queue 0 never (its submission order covers it).
        let first = counted(q1);
        let second = counted(q1);
        let third = counted(q0);
        assert_eq!(allocs, 0, "allocations per submit");
        assert_eq!(locks, 0, "process-wide locks per submit");
        assert_eq!(
            first,
            [
                (vec![(0x5f, 1)], 0, vec![]),
                (vec![], 1, vec![]),
                (vec![], 0, vec![(0x52, 2)])
            ]
        );
        assert_eq!(second, [(vec![], 1, vec![]), (vec![], 0, vec![(0x52, 3)])]);
        assert_eq!(third, [(vec![], 1, vec![]), (vec![], 0, vec![(0x51, 2)])]);
        // A queue the order does not know goes down as it came.
        assert_eq!(submit(0x9999), vk::Result::SUCCESS);
        assert_eq!(seen(), [(vec![], 1, vec![])]);
        // Once the device reconstructs, each submit also waits on the other queue's last signal,
        // still without allocating or taking a process-wide lock.
        order.serialise();
        let (a, l) = (allocations(), shared_taken());
        assert_eq!(submit(q0), vk::Result::SUCCESS);
        let (allocs, locks) = (allocations() - a, shared_taken() - l);
        let on_q0 = seen();
        let (a, l) = (allocations(), shared_taken());
        assert_eq!(submit(q1), vk::Result::SUCCESS);
        let (allocs, locks) = (allocs + allocations() - a, locks + shared_taken() - l);
        let on_q1 = seen();
        assert_eq!(allocs, 0, "allocations per serialised submit");
        assert_eq!(locks, 0, "process-wide locks per serialised submit");
        assert_eq!(
            on_q0,
            [
                (vec![(0x52, 3)], 0, vec![]),
                (vec![], 1, vec![]),
                (vec![], 0, vec![(0x51, 3)])
            ]
        );
        assert_eq!(
            on_q1,
            [
                (vec![(0x51, 3)], 0, vec![]),
                (vec![], 1, vec![]),
                (vec![], 0, vec![(0x52, 4)])
            ]
        );
    }
}
