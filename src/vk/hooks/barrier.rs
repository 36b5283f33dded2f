//! Barriers (and event sets and waits) on an emulating device: the density-map layout, stage and
//! access bits become what the driver knows ([`crate::vk::translate::sync`]), on copies of the
//! application's arrays.
//!
//! The common path (no density-map bit anywhere in the call) is a scan of the masks and a direct
//! call down. The rewrite path reuses a per-thread scratch buffer, so recording allocates nothing
//! in steady state.

use std::cell::RefCell;

use ash::vk;

use crate::vk::base::ffi::{guard, slice};
use crate::vk::registry;
use crate::vk::translate::sync::{
    access, access2, image_barrier, image_barrier2, needs1, needs2, stage, stage2,
};

/// The shadow's barrier for an application image moved into the density-map layout, except in a
/// queue family release: the release half of an ownership transfer is the source queue's, whose
/// destination stages and accesses the specification ignores
/// (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#synchronization-queue-transfers-release>);
/// it goes down as the application wrote it (translated), and the acquire half orders the shadow.
/// The map is noted as moved into the layout either way.
fn shadow_unless(release: bool, image: vk::Image) -> Option<crate::bridge::Shadow> {
    let s = crate::vk::convert::shadow_of_transitioned(image);
    if release {
        None
    } else {
        s
    }
}

/// `vkCreateCommandPool`: its queue family is noted.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn create_command_pool(
    device: vk::Device,
    info: *const vk::CommandPoolCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::CommandPool,
) -> vk::Result {
    use ash::vk::Handle as _;
    guard(
        "vkCreateCommandPool",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let Some(rec) = (unsafe { registry::recording(device) }) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let Some(next) = rec.next.create_command_pool else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            // SAFETY: the next layer's function, with the caller's arguments.
            let r = unsafe { next(device, info, alloc, out) };
            // SAFETY: the caller's create info.
            let info = unsafe { info.as_ref() };
            if let (vk::Result::SUCCESS, Some(i), false) = (r, info, out.is_null()) {
                // SAFETY: on success `out` holds the new pool.
                let raw = unsafe { *out }.as_raw();
                registry::pool_created(rec.device, raw, i.queue_family_index);
            }
            r
        },
    )
}

/// Per-thread arrays the translated barriers are built in, reused from call to call. They hold
/// plain copies (pointers into the application's chains at most), cleared after each call.
#[derive(Default)]
struct Scratch {
    memory: Vec<vk::MemoryBarrier<'static>>,
    buffers: Vec<vk::BufferMemoryBarrier<'static>>,
    images: Vec<vk::ImageMemoryBarrier<'static>>,
    memory2: Vec<vk::MemoryBarrier2<'static>>,
    buffers2: Vec<vk::BufferMemoryBarrier2<'static>>,
    images2: Vec<vk::ImageMemoryBarrier2<'static>>,
    infos: Vec<vk::DependencyInfo<'static>>,
    /// Where each dependency info's arrays start in the vectors above.
    starts: Vec<[usize; 3]>,
}

impl Scratch {
    fn clear(&mut self) {
        self.memory.clear();
        self.buffers.clear();
        self.images.clear();
        self.memory2.clear();
        self.buffers2.clear();
        self.images2.clear();
        self.infos.clear();
        self.starts.clear();
    }
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// Runs `f` with this thread's scratch buffer (a fresh one if it is busy or gone), cleared after.
fn with_scratch<R>(f: impl FnOnce(&mut Scratch) -> R) -> R {
    let mut f = Some(f);
    let r = SCRATCH.try_with(|s| {
        s.try_borrow_mut().ok().map(|mut s| {
            let r = (f.take().expect("called once"))(&mut s);
            s.clear();
            r
        })
    });
    match (r, f) {
        (Ok(Some(r)), _) => r,
        (_, Some(f)) => f(&mut Scratch::default()),
        (_, None) => unreachable!("the closure ran, so the scratch result is there"),
    }
}

/// Erases the lifetime of a Vulkan struct copy that lives only across one call down.
///
/// # Safety
/// The copy must not outlive what its pointers point at.
unsafe fn forever<T: Copy, U: Copy>(t: T) -> U {
    debug_assert_eq!(std::mem::size_of::<T>(), std::mem::size_of::<U>());
    // SAFETY: T and U are the same struct with different lifetime parameters (callers' contract).
    unsafe { std::mem::transmute_copy::<T, U>(&t) }
}

/// Translates the barriers of a v1 command into `s.memory`, `s.buffers` and `s.images`.
///
/// # Safety
/// The copies must not outlive the caller's barriers (they live across the call down only).
unsafe fn translate1(
    s: &mut Scratch,
    cb: vk::CommandBuffer,
    memory: &[vk::MemoryBarrier<'_>],
    buffers: &[vk::BufferMemoryBarrier<'_>],
    images: &[vk::ImageMemoryBarrier<'_>],
) {
    for b in memory {
        // SAFETY: as the caller promised.
        let mut c: vk::MemoryBarrier<'static> = unsafe { forever(*b) };
        c.src_access_mask = access(c.src_access_mask);
        c.dst_access_mask = access(c.dst_access_mask);
        s.memory.push(c);
    }
    for b in buffers {
        // SAFETY: as above.
        let mut c: vk::BufferMemoryBarrier<'static> = unsafe { forever(*b) };
        c.src_access_mask = access(c.src_access_mask);
        c.dst_access_mask = access(c.dst_access_mask);
        s.buffers.push(c);
    }
    for b in images {
        // SAFETY: as above.
        let b: vk::ImageMemoryBarrier<'static> = unsafe { forever(*b) };
        let release = registry::is_release(cb, b.src_queue_family_index, b.dst_queue_family_index);
        let (c, shadow) = image_barrier(&b, |i| shadow_unless(release, i));
        s.images.push(c);
        s.images.extend(shadow);
    }
}

/// Translates dependency infos into `s` (one copy each) and returns them.
///
/// # Safety
/// The infos' arrays must be valid for their counts.
unsafe fn translate2<'s>(
    s: &'s mut Scratch,
    cb: vk::CommandBuffer,
    infos: &[vk::DependencyInfo<'_>],
) -> &'s [vk::DependencyInfo<'static>] {
    for d in infos {
        s.starts
            .push([s.memory2.len(), s.buffers2.len(), s.images2.len()]);
        // SAFETY: as the caller promised.
        let (m, b, i) = unsafe {
            (
                slice(d.p_memory_barriers, d.memory_barrier_count),
                slice(d.p_buffer_memory_barriers, d.buffer_memory_barrier_count),
                slice(d.p_image_memory_barriers, d.image_memory_barrier_count),
            )
        };
        for b in m {
            // SAFETY: lives across the call down only.
            let mut c: vk::MemoryBarrier2<'static> = unsafe { forever(*b) };
            c.src_stage_mask = stage2(c.src_stage_mask);
            c.dst_stage_mask = stage2(c.dst_stage_mask);
            c.src_access_mask = access2(c.src_access_mask);
            c.dst_access_mask = access2(c.dst_access_mask);
            s.memory2.push(c);
        }
        for b in b {
            // SAFETY: as above.
            let mut c: vk::BufferMemoryBarrier2<'static> = unsafe { forever(*b) };
            c.src_stage_mask = stage2(c.src_stage_mask);
            c.dst_stage_mask = stage2(c.dst_stage_mask);
            c.src_access_mask = access2(c.src_access_mask);
            c.dst_access_mask = access2(c.dst_access_mask);
            s.buffers2.push(c);
        }
        for b in i {
            // SAFETY: as above.
            let b: vk::ImageMemoryBarrier2<'static> = unsafe { forever(*b) };
            let release =
                registry::is_release(cb, b.src_queue_family_index, b.dst_queue_family_index);
            let (c, shadow) = image_barrier2(&b, |i| shadow_unless(release, i));
            s.images2.push(c);
            s.images2.extend(shadow);
        }
    }
    let ends = [s.memory2.len(), s.buffers2.len(), s.images2.len()];
    for (n, d) in infos.iter().enumerate() {
        let [m0, b0, i0] = s.starts[n];
        let [m1, b1, i1] = s.starts.get(n + 1).copied().unwrap_or(ends);
        // SAFETY: lives across the call down only.
        let mut c: vk::DependencyInfo<'static> = unsafe { forever(*d) };
        c.memory_barrier_count = (m1 - m0) as u32;
        c.p_memory_barriers = s.memory2[m0..].as_ptr();
        c.buffer_memory_barrier_count = (b1 - b0) as u32;
        c.p_buffer_memory_barriers = s.buffers2[b0..].as_ptr();
        c.image_memory_barrier_count = (i1 - i0) as u32;
        c.p_image_memory_barriers = s.images2[i0..].as_ptr();
        s.infos.push(c);
    }
    &s.infos
}

/// `vkCmdPipelineBarrier`.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
#[allow(clippy::too_many_arguments)]
pub unsafe extern "system" fn cmd_pipeline_barrier(
    cb: vk::CommandBuffer,
    src: vk::PipelineStageFlags,
    dst: vk::PipelineStageFlags,
    flags: vk::DependencyFlags,
    memory_count: u32,
    memory: *const vk::MemoryBarrier<'_>,
    buffer_count: u32,
    buffers: *const vk::BufferMemoryBarrier<'_>,
    image_count: u32,
    images: *const vk::ImageMemoryBarrier<'_>,
) {
    guard("vkCmdPipelineBarrier", (), || {
        // SAFETY: a command buffer dispatched by the loader.
        let Some(rec) = (unsafe { registry::recording(cb) }) else {
            return;
        };
        let Some(next) = rec.next.cmd_pipeline_barrier else {
            return;
        };
        // SAFETY: the caller's arrays, valid for their counts.
        let (m, b, i) = unsafe {
            (
                slice(memory, memory_count),
                slice(buffers, buffer_count),
                slice(images, image_count),
            )
        };
        // SAFETY: as above.
        if !rec.emulated || !unsafe { needs1(src, dst, m, b, i) } {
            // SAFETY: the next layer's function, with the caller's arguments.
            return unsafe {
                next(
                    cb,
                    src,
                    dst,
                    flags,
                    memory_count,
                    memory,
                    buffer_count,
                    buffers,
                    image_count,
                    images,
                )
            };
        }
        with_scratch(|s| {
            // SAFETY: the next layer's function; the copies live across the call.
            unsafe {
                translate1(s, cb, m, b, i);
                next(
                    cb,
                    stage(src),
                    stage(dst),
                    flags,
                    s.memory.len() as u32,
                    s.memory.as_ptr(),
                    s.buffers.len() as u32,
                    s.buffers.as_ptr(),
                    s.images.len() as u32,
                    s.images.as_ptr(),
                )
            }
        })
    })
}

/// The shared body of `vkCmdPipelineBarrier2` and its KHR alias.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn pipeline_barrier2(
    what: &'static str,
    pick: fn(&registry::Recording) -> Option<vk::PFN_vkCmdPipelineBarrier2>,
    cb: vk::CommandBuffer,
    info: *const vk::DependencyInfo<'_>,
) {
    guard(what, (), || {
        // SAFETY: a command buffer dispatched by the loader.
        let Some(rec) = (unsafe { registry::recording(cb) }) else {
            return;
        };
        let Some(next) = pick(&rec) else { return };
        // SAFETY: the caller's dependency info, read only.
        if !rec.emulated || info.is_null() || !needs2(unsafe { &*info }) {
            // SAFETY: the next layer's function, with the caller's arguments.
            return unsafe { next(cb, info) };
        }
        with_scratch(|s| {
            // SAFETY: the caller's dependency info; the copies live across the call down.
            unsafe {
                let infos = translate2(s, cb, std::slice::from_ref(&*info));
                next(cb, infos.as_ptr())
            }
        })
    })
}

hook_and_khr_alias! {
    /// `vkCmdPipelineBarrier2`.
    cmd_pipeline_barrier2, cmd_pipeline_barrier2_khr = pipeline_barrier2("vkCmdPipelineBarrier2")
    (cb: vk::CommandBuffer, info: *const vk::DependencyInfo<'_>)
}

/// The shared body of `vkCmdSetEvent2` and its KHR alias: the dependency info is translated as a
/// barrier's, so it stays identical to the one `vkCmdWaitEvents2` gets for the same event, as the
/// spec requires
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkCmdWaitEvents2.html>,
/// VUID-vkCmdWaitEvents2-pEvents-03837).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn set_event2(
    what: &'static str,
    pick: fn(&registry::Recording) -> Option<vk::PFN_vkCmdSetEvent2>,
    cb: vk::CommandBuffer,
    event: vk::Event,
    info: *const vk::DependencyInfo<'_>,
) {
    guard(what, (), || {
        // SAFETY: a command buffer dispatched by the loader.
        let Some(rec) = (unsafe { registry::recording(cb) }) else {
            return;
        };
        let Some(next) = pick(&rec) else { return };
        // SAFETY: the caller's dependency info, read only.
        if !rec.emulated || info.is_null() || !needs2(unsafe { &*info }) {
            // SAFETY: the next layer's function, with the caller's arguments.
            return unsafe { next(cb, event, info) };
        }
        with_scratch(|s| {
            // SAFETY: the caller's dependency info; the copies live across the call down.
            unsafe {
                let infos = translate2(s, cb, std::slice::from_ref(&*info));
                next(cb, event, infos.as_ptr())
            }
        })
    })
}

hook_and_khr_alias! {
    /// `vkCmdSetEvent2`.
    cmd_set_event2, cmd_set_event2_khr = set_event2("vkCmdSetEvent2")
    (cb: vk::CommandBuffer, event: vk::Event, info: *const vk::DependencyInfo<'_>)
}

/// `vkCmdWaitEvents`.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
#[allow(clippy::too_many_arguments)]
pub unsafe extern "system" fn cmd_wait_events(
    cb: vk::CommandBuffer,
    event_count: u32,
    events: *const vk::Event,
    src: vk::PipelineStageFlags,
    dst: vk::PipelineStageFlags,
    memory_count: u32,
    memory: *const vk::MemoryBarrier<'_>,
    buffer_count: u32,
    buffers: *const vk::BufferMemoryBarrier<'_>,
    image_count: u32,
    images: *const vk::ImageMemoryBarrier<'_>,
) {
    guard("vkCmdWaitEvents", (), || {
        // SAFETY: a command buffer dispatched by the loader.
        let Some(rec) = (unsafe { registry::recording(cb) }) else {
            return;
        };
        let Some(next) = rec.next.cmd_wait_events else {
            return;
        };
        // SAFETY: the caller's arrays, valid for their counts.
        let (m, b, i) = unsafe {
            (
                slice(memory, memory_count),
                slice(buffers, buffer_count),
                slice(images, image_count),
            )
        };
        // SAFETY: as above.
        if !rec.emulated || !unsafe { needs1(src, dst, m, b, i) } {
            // SAFETY: the next layer's function, with the caller's arguments.
            return unsafe {
                next(
                    cb,
                    event_count,
                    events,
                    src,
                    dst,
                    memory_count,
                    memory,
                    buffer_count,
                    buffers,
                    image_count,
                    images,
                )
            };
        }
        with_scratch(|s| {
            // SAFETY: the next layer's function; the copies live across the call.
            unsafe {
                translate1(s, cb, m, b, i);
                next(
                    cb,
                    event_count,
                    events,
                    stage(src),
                    stage(dst),
                    s.memory.len() as u32,
                    s.memory.as_ptr(),
                    s.buffers.len() as u32,
                    s.buffers.as_ptr(),
                    s.images.len() as u32,
                    s.images.as_ptr(),
                )
            }
        })
    })
}

/// The shared body of `vkCmdWaitEvents2` and its KHR alias: one dependency info per event.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn wait_events2(
    what: &'static str,
    pick: fn(&registry::Recording) -> Option<vk::PFN_vkCmdWaitEvents2>,
    cb: vk::CommandBuffer,
    count: u32,
    events: *const vk::Event,
    infos: *const vk::DependencyInfo<'_>,
) {
    guard(what, (), || {
        // SAFETY: a command buffer dispatched by the loader.
        let Some(rec) = (unsafe { registry::recording(cb) }) else {
            return;
        };
        let Some(next) = pick(&rec) else { return };
        // SAFETY: the caller's array of `count` dependency infos.
        let list = unsafe { slice(infos, count) };
        if !rec.emulated || !list.iter().any(needs2) {
            // SAFETY: the next layer's function, with the caller's arguments.
            return unsafe { next(cb, count, events, infos) };
        }
        with_scratch(|s| {
            // SAFETY: the caller's dependency infos; the copies live across the call down.
            unsafe {
                let infos = translate2(s, cb, list);
                next(cb, count, events, infos.as_ptr())
            }
        })
    })
}

hook_and_khr_alias! {
    /// `vkCmdWaitEvents2`.
    cmd_wait_events2, cmd_wait_events2_khr = wait_events2("vkCmdWaitEvents2")
    (
        cb: vk::CommandBuffer,
        count: u32,
        events: *const vk::Event,
        infos: *const vk::DependencyInfo<'_>,
    )
}

/// Calls `f` with the next layer's function picked from `cb`'s device and, where the device
/// emulates density maps, `translate` applied to the stage mask; nothing where the device is
/// unknown or the next layer lacks the command.
///
/// # Safety
/// `cb` must be a command buffer dispatched by the loader.
#[inline]
unsafe fn with_stage<F: Copy, S: Copy>(
    cb: vk::CommandBuffer,
    pick: impl FnOnce(&registry::Recording) -> Option<F>,
    stage: S,
    translate: fn(S) -> S,
    f: impl FnOnce(F, S),
) {
    // SAFETY: as the caller promised.
    let Some(rec) = (unsafe { registry::recording(cb) }) else {
        return;
    };
    let Some(next) = pick(&rec) else { return };
    f(
        next,
        if rec.emulated {
            translate(stage)
        } else {
            stage
        },
    )
}

/// `vkCmdSetEvent`: the stage mask without the density-map stage (the bits are invalid on the
/// driver's device, VUID-vkCmdSetEvent-stageMask-04093 family,
/// <https://registry.khronos.org/vulkan/specs/latest/man/html/vkCmdSetEvent.html>); it stays
/// matched to the `vkCmdWaitEvents` source stages, which are translated alike.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_set_event(
    cb: vk::CommandBuffer,
    event: vk::Event,
    mask: vk::PipelineStageFlags,
) {
    guard("vkCmdSetEvent", (), || {
        // SAFETY: the caller's arguments; the next layer's function.
        unsafe {
            with_stage(
                cb,
                |r| r.next.cmd_set_event,
                mask,
                stage,
                |next, m| next(cb, event, m),
            )
        }
    })
}

/// `vkCmdResetEvent`: as [`cmd_set_event`].
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_reset_event(
    cb: vk::CommandBuffer,
    event: vk::Event,
    mask: vk::PipelineStageFlags,
) {
    guard("vkCmdResetEvent", (), || {
        // SAFETY: the caller's arguments; the next layer's function.
        unsafe {
            with_stage(
                cb,
                |r| r.next.cmd_reset_event,
                mask,
                stage,
                |next, m| next(cb, event, m),
            )
        }
    })
}

/// The shared body of `vkCmdResetEvent2` and its KHR alias: as [`cmd_set_event`].
///
/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn reset_event2(
    what: &'static str,
    pick: fn(&registry::Recording) -> Option<vk::PFN_vkCmdResetEvent2>,
    cb: vk::CommandBuffer,
    event: vk::Event,
    mask: vk::PipelineStageFlags2,
) {
    guard(what, (), || {
        // SAFETY: the caller's arguments; the next layer's function.
        unsafe { with_stage(cb, pick, mask, stage2, |next, m| next(cb, event, m)) }
    })
}

hook_and_khr_alias! {
    /// `vkCmdResetEvent2`.
    cmd_reset_event2, cmd_reset_event2_khr = reset_event2("vkCmdResetEvent2")
    (cb: vk::CommandBuffer, event: vk::Event, mask: vk::PipelineStageFlags2)
}

/// `vkCmdWriteTimestamp`: a timestamp after the density-map stage is one after the shading-rate
/// attachment stage, which takes its place on the driver's device.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_write_timestamp(
    cb: vk::CommandBuffer,
    at: vk::PipelineStageFlags,
    pool: vk::QueryPool,
    query: u32,
) {
    guard("vkCmdWriteTimestamp", (), || {
        // SAFETY: the caller's arguments; the next layer's function.
        unsafe {
            with_stage(
                cb,
                |r| r.next.cmd_write_timestamp,
                at,
                stage,
                |next, s| next(cb, s, pool, query),
            )
        }
    })
}

/// The shared body of `vkCmdWriteTimestamp2` and its KHR alias: as [`cmd_write_timestamp`].
///
/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn write_timestamp2(
    what: &'static str,
    pick: fn(&registry::Recording) -> Option<vk::PFN_vkCmdWriteTimestamp2>,
    cb: vk::CommandBuffer,
    at: vk::PipelineStageFlags2,
    pool: vk::QueryPool,
    query: u32,
) {
    guard(what, (), || {
        // SAFETY: the caller's arguments; the next layer's function.
        unsafe { with_stage(cb, pick, at, stage2, |next, s| next(cb, s, pool, query)) }
    })
}

hook_and_khr_alias! {
    /// `vkCmdWriteTimestamp2`.
    cmd_write_timestamp2, cmd_write_timestamp2_khr = write_timestamp2("vkCmdWriteTimestamp2")
    (cb: vk::CommandBuffer, at: vk::PipelineStageFlags2, pool: vk::QueryPool, query: u32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vk::translate::sync::{ACCESS2, FDM_LAYOUT, FSR_ACCESS2};

    #[test]
    fn dependency_infos_are_translated_on_copies_with_their_own_arrays() {
        let m = [vk::MemoryBarrier2::default().src_access_mask(ACCESS2)];
        let i = [
            vk::ImageMemoryBarrier2::default().new_layout(FDM_LAYOUT),
            vk::ImageMemoryBarrier2::default(),
        ];
        let infos = [
            vk::DependencyInfo::default().memory_barriers(&m),
            vk::DependencyInfo::default().image_memory_barriers(&i),
        ];
        let mut s = Scratch::default();
        // SAFETY: arrays on the stack.
        let out = unsafe { translate2(&mut s, vk::CommandBuffer::null(), &infos) };
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].memory_barrier_count, 1);
        assert_eq!(out[0].image_memory_barrier_count, 0);
        assert_eq!(out[1].image_memory_barrier_count, 2);
        // SAFETY: pointers into the scratch arrays, alive here.
        unsafe {
            assert_eq!((*out[0].p_memory_barriers).src_access_mask, FSR_ACCESS2);
            assert_eq!(
                (*out[1].p_image_memory_barriers).new_layout,
                vk::ImageLayout::GENERAL
            );
        }
        assert_eq!(
            i[0].new_layout, FDM_LAYOUT,
            "the application's array is kept"
        );
        let cap = s.images2.capacity();
        s.clear();
        assert_eq!(s.images2.capacity(), cap, "the scratch keeps its storage");
    }
}
