//! Submits on an emulating device: the layer's pending shadow clears and uploads
//! ([`crate::vk::own::calls::Clears`]) run in front of the application's next submit on a graphics
//! queue, and the density-map stage bits of semaphore waits become the shading-rate ones.
//!
//! On a device with more than one graphics queue where the layer acts, every submit on one of them
//! goes down between the layer's wait on its last upload and its signal of the queue's timeline
//! ([`crate::vk::own::order`]), so that a pass on any queue is ordered against the layer's writes.
//!
//! With nothing pending anywhere (the steady state) a submit costs one atomic load and a scan of
//! its wait-stage masks before the call down; on such a device, a shared lock of the device's own
//! and the copy of its batch array into the queue's reused storage besides.

use std::sync::atomic::Ordering;

use ash::vk;

use crate::vk::base::ffi::{raw, slice, Arr, Call};
use crate::vk::own::calls::{Own, PENDING};
use crate::vk::registry::Device;
use crate::vk::translate::sync::{stage, stage2};

/// The result an application's submit returns where the layer's clear ahead of it failed: the
/// failure's own where `vkQueueSubmit` may return it, else out of host memory.
fn submit_result(e: vk::Result) -> vk::Result {
    match e {
        vk::Result::ERROR_OUT_OF_HOST_MEMORY
        | vk::Result::ERROR_OUT_OF_DEVICE_MEMORY
        | vk::Result::ERROR_DEVICE_LOST => e,
        _ => vk::Result::ERROR_OUT_OF_HOST_MEMORY,
    }
}

/// Runs the pending clears ahead of a submit on `queue` of the device whose own calls are `own`:
/// `Err` with the result the application's submit must return instead of going down. One atomic
/// load where nothing is pending.
///
/// # Safety
/// Called inside the application's submit on `queue`, a queue dispatched by the loader.
unsafe fn before_submit(
    what: &'static str,
    queue: vk::Queue,
    own: Option<&Own>,
) -> Result<(), vk::Result> {
    if PENDING.load(Ordering::Acquire) == 0 {
        return Ok(());
    }
    let Some(own) = own else {
        return Ok(());
    };
    // SAFETY: as the caller promised.
    unsafe { own.clears.flush(own, queue) }.map_err(|e| {
        tracing::warn!(
            queue = raw(queue),
            result = ?e,
            "{what}: the layer could not clear new density maps' shadows or upload shading-rate \
             maps ahead of it; the submit fails with that result and they stay pending"
        );
        submit_result(e)
    })
}

hook! {
    /// `vkQueueSubmit`: pending clears first; wait-stage masks without the density-map stage, on
    /// a copy.
    queue_submit = "vkQueueSubmit";
    on device_ref(queue), next queue_submit,
    fails(vk::Result::ERROR_INITIALIZATION_FAILED, panic vk::Result::ERROR_OUT_OF_HOST_MEMORY);
    submit(
        queue: val vk::Queue,
        count: val u32,
        submits: (array count) vk::SubmitInfo<'_>,
        fence: val vk::Fence,
    ) -> vk::Result
}

fn submit(
    c: Call<'_, Device, vk::PFN_vkQueueSubmit, impl Fn() -> vk::Result>,
    queue: vk::Queue,
    count: u32,
    submits: Arr<'_, vk::SubmitInfo<'_>>,
    fence: vk::Fence,
) -> vk::Result {
    let own = c.dev.own.as_deref();
    // SAFETY: inside the application's submit on `queue`, a queue the loader dispatched.
    if let Err(e) = unsafe { before_submit(c.name, queue, own) } {
        return e;
    }
    let order = own.and_then(|o| o.clears.order.as_ref());
    let next = c.next;
    // SAFETY: the next layer's `vkQueueSubmit` on the application's queue and fence, with its
    // array of `count` submits or a copy of it whose masks arrays live across the call.
    let down = |count, submits| unsafe {
        match order {
            Some(o) => o.submit(next, queue, count, submits, fence),
            None => next(queue, count, submits, fence),
        }
    };
    let list = submits.slice();
    let masks = |s: &vk::SubmitInfo<'_>| {
        // SAFETY: the command's valid usage: each submit's `pWaitDstStageMask` holds
        // `waitSemaphoreCount` masks.
        unsafe { slice(s.p_wait_dst_stage_mask, s.wait_semaphore_count) }
    };
    if !list.iter().any(|s| masks(s).iter().any(|&m| stage(m) != m)) {
        return down(count, submits.raw());
    }
    let stages: Vec<Vec<vk::PipelineStageFlags>> = list
        .iter()
        .map(|s| masks(s).iter().map(|&m| stage(m)).collect())
        .collect();
    let copies: Vec<vk::SubmitInfo<'_>> = list
        .iter()
        .zip(&stages)
        .map(|(s, m)| {
            let mut c = *s;
            if !s.p_wait_dst_stage_mask.is_null() {
                c.p_wait_dst_stage_mask = m.as_ptr();
            }
            c
        })
        .collect();
    down(count, copies.as_ptr())
}

/// The semaphore infos of a submit with the density-map stage replaced, where any has it.
fn semaphores2<'a>(
    infos: &[vk::SemaphoreSubmitInfo<'a>],
) -> Option<Vec<vk::SemaphoreSubmitInfo<'a>>> {
    infos
        .iter()
        .any(|i| stage2(i.stage_mask) != i.stage_mask)
        .then(|| {
            infos
                .iter()
                .map(|i| vk::SemaphoreSubmitInfo {
                    stage_mask: stage2(i.stage_mask),
                    ..*i
                })
                .collect()
        })
}

hook! {
    /// `vkQueueSubmit2`: pending clears first; semaphore stage masks without the density-map
    /// stage, on copies.
    queue_submit2 = "vkQueueSubmit2", queue_submit2_khr = "vkQueueSubmit2KHR";
    on device_ref(queue), next queue_submit2 / queue_submit2_khr,
    fails(vk::Result::ERROR_INITIALIZATION_FAILED, panic vk::Result::ERROR_OUT_OF_HOST_MEMORY);
    submit2(
        queue: val vk::Queue,
        count: val u32,
        submits: (array count) vk::SubmitInfo2<'_>,
        fence: val vk::Fence,
    ) -> vk::Result
}

/// The wait and the signal semaphores of a submit.
fn waits_and_signals<'a>(s: &vk::SubmitInfo2<'a>) -> [&'a [vk::SemaphoreSubmitInfo<'a>]; 2] {
    // SAFETY: the command's valid usage: each array holds its count of infos, alive for the call
    // the submit came in.
    unsafe {
        [
            slice(s.p_wait_semaphore_infos, s.wait_semaphore_info_count),
            slice(s.p_signal_semaphore_infos, s.signal_semaphore_info_count),
        ]
    }
}

fn submit2(
    c: Call<'_, Device, vk::PFN_vkQueueSubmit2, impl Fn() -> vk::Result>,
    queue: vk::Queue,
    count: u32,
    submits: Arr<'_, vk::SubmitInfo2<'_>>,
    fence: vk::Fence,
) -> vk::Result {
    let own = c.dev.own.as_deref();
    // SAFETY: inside the application's submit on `queue`, a queue the loader dispatched.
    if let Err(e) = unsafe { before_submit(c.name, queue, own) } {
        return e;
    }
    let order = own.and_then(|o| o.clears.order.as_ref());
    let next = c.next;
    // SAFETY: the next layer's `vkQueueSubmit2` on the application's queue and fence, with its
    // array of `count` submits or a copy whose semaphore arrays live across the call.
    let down = |count, submits| unsafe {
        match order {
            Some(o) => o.submit2(next, queue, count, submits, fence),
            None => next(queue, count, submits, fence),
        }
    };
    let list = submits.slice();
    let touched =
        |i: &[vk::SemaphoreSubmitInfo<'_>]| i.iter().any(|i| stage2(i.stage_mask) != i.stage_mask);
    if !list
        .iter()
        .any(|s| waits_and_signals(s).into_iter().any(touched))
    {
        return down(count, submits.raw());
    }
    let arrays: Vec<_> = list
        .iter()
        .map(|s| waits_and_signals(s).map(semaphores2))
        .collect();
    let copies: Vec<vk::SubmitInfo2<'_>> = list
        .iter()
        .zip(&arrays)
        .map(|(s, [w, g])| {
            let mut c = *s;
            if let Some(w) = w {
                c.p_wait_semaphore_infos = w.as_ptr();
            }
            if let Some(g) = g {
                c.p_signal_semaphore_infos = g.as_ptr();
            }
            c
        })
        .collect();
    down(count, copies.as_ptr())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The chassis answers a command on a handle the layer does not know with the failure value
    /// the hook declares, without a call down (there is no next function to call).
    #[test]
    fn an_unknown_queue_gets_the_declared_failure_value() {
        use ash::vk::Handle as _;
        // A dispatch key no device has.
        let word = Box::new(0x5151usize);
        let queue = vk::Queue::from_raw(&*word as *const usize as u64);
        // SAFETY: a handle whose first word is a dispatch key; no submits.
        let r = unsafe { queue_submit(queue, 0, std::ptr::null(), vk::Fence::null()) };
        assert_eq!(r, vk::Result::ERROR_INITIALIZATION_FAILED);
        // SAFETY: as above.
        let r = unsafe { queue_submit2_khr(queue, 0, std::ptr::null(), vk::Fence::null()) };
        assert_eq!(r, vk::Result::ERROR_INITIALIZATION_FAILED);
    }

    #[test]
    fn semaphore_stages_are_translated_on_a_copy_and_only_where_needed() {
        let plain = [vk::SemaphoreSubmitInfo::default()
            .stage_mask(vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT)];
        assert!(semaphores2(&plain).is_none());
        let fdm = [
            plain[0],
            vk::SemaphoreSubmitInfo::default().stage_mask(
                vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT
                    | vk::PipelineStageFlags2::FRAGMENT_SHADER,
            ),
        ];
        let copy = semaphores2(&fdm).expect("translated");
        assert_eq!(copy[0].stage_mask, plain[0].stage_mask);
        assert_eq!(
            copy[1].stage_mask,
            vk::PipelineStageFlags2::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR
                | vk::PipelineStageFlags2::FRAGMENT_SHADER
        );
        assert_eq!(
            fdm[1].stage_mask,
            vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT
                | vk::PipelineStageFlags2::FRAGMENT_SHADER,
            "the application's array is kept"
        );
    }

    #[test]
    fn a_failed_clear_answers_with_a_result_submit_may_return() {
        for e in [
            vk::Result::ERROR_OUT_OF_HOST_MEMORY,
            vk::Result::ERROR_OUT_OF_DEVICE_MEMORY,
            vk::Result::ERROR_DEVICE_LOST,
        ] {
            assert_eq!(submit_result(e), e);
        }
        assert_eq!(
            submit_result(vk::Result::ERROR_INITIALIZATION_FAILED),
            vk::Result::ERROR_OUT_OF_HOST_MEMORY
        );
    }
}
