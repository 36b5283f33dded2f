//! Barriers (and event sets and waits) on an emulating device: the density-map layout, stage and
//! access bits become what the driver knows ([`crate::vk::translate::sync`]), on copies of the
//! application's arrays.
//!
//! The common path (no density-map bit anywhere in the call) is a scan of the masks and a direct
//! call down. The rewrite path reuses a per-thread scratch buffer, so recording allocates nothing
//! in steady state.

use std::cell::RefCell;

use ash::vk;

use crate::vk::base::ffi::{slice, Arr, Call, In, Out};
use crate::vk::registry::{self, Device};
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

hook! {
    /// `vkCreateCommandPool`: its queue family is noted.
    create_command_pool = "vkCreateCommandPool";
    on device_ref(device), next create_command_pool,
    fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    create_pool(
        device: val vk::Device,
        info: in vk::CommandPoolCreateInfo<'_>,
        alloc: val *const vk::AllocationCallbacks<'_>,
        out: out vk::CommandPool,
    ) -> vk::Result
}

fn create_pool(
    c: Call<'_, Device, vk::PFN_vkCreateCommandPool, impl Fn() -> vk::Result>,
    _device: vk::Device,
    info: In<'_, vk::CommandPoolCreateInfo<'_>>,
    _alloc: *const vk::AllocationCallbacks<'_>,
    out: Out<'_, vk::CommandPool>,
) -> vk::Result {
    use ash::vk::Handle as _;
    let r = c.as_given();
    if let (vk::Result::SUCCESS, Some(i), Some(pool)) = (r, info.get(), out.read()) {
        registry::pool_created(c.dev, pool.as_raw(), i.queue_family_index);
    }
    r
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

hook! {
    /// `vkCmdPipelineBarrier`.
    cmd_pipeline_barrier = "vkCmdPipelineBarrier";
    on device_ref(cb), next cmd_pipeline_barrier, fails(());
    pipeline_barrier(
        cb: val vk::CommandBuffer,
        src: val vk::PipelineStageFlags,
        dst: val vk::PipelineStageFlags,
        flags: val vk::DependencyFlags,
        memory_count: val u32,
        memory: (array memory_count) vk::MemoryBarrier<'_>,
        buffer_count: val u32,
        buffers: (array buffer_count) vk::BufferMemoryBarrier<'_>,
        image_count: val u32,
        images: (array image_count) vk::ImageMemoryBarrier<'_>,
    ) -> ()
}

/// The three barrier arrays of a v1 barrier or event wait.
type Barriers1<'a> = (
    &'a [vk::MemoryBarrier<'a>],
    &'a [vk::BufferMemoryBarrier<'a>],
    &'a [vk::ImageMemoryBarrier<'a>],
);

/// The barriers of a v1 command, where they must be translated: on an emulating device, where
/// any of them or the stages names the density map.
fn to_translate1<'a>(
    dev: &Device,
    [src, dst]: [vk::PipelineStageFlags; 2],
    memory: Arr<'a, vk::MemoryBarrier<'a>>,
    buffers: Arr<'a, vk::BufferMemoryBarrier<'a>>,
    images: Arr<'a, vk::ImageMemoryBarrier<'a>>,
) -> Option<Barriers1<'a>> {
    dev.fdm.as_ref()?;
    let (m, b, i) = (memory.slice(), buffers.slice(), images.slice());
    // SAFETY: the application's barriers, valid as the command requires.
    unsafe { needs1(src, dst, m, b, i) }.then_some((m, b, i))
}

/// Calls `down` with translated copies of a v1 command's stages and barriers, built in this
/// thread's scratch.
fn translated1(
    cb: vk::CommandBuffer,
    [src, dst]: [vk::PipelineStageFlags; 2],
    (m, b, i): Barriers1<'_>,
    down: impl FnOnce(
        [vk::PipelineStageFlags; 2],
        (u32, *const vk::MemoryBarrier<'_>),
        (u32, *const vk::BufferMemoryBarrier<'_>),
        (u32, *const vk::ImageMemoryBarrier<'_>),
    ),
) {
    with_scratch(|s| {
        // SAFETY: the copies live in the scratch across the call down only.
        unsafe { translate1(s, cb, m, b, i) };
        down(
            [stage(src), stage(dst)],
            (s.memory.len() as u32, s.memory.as_ptr()),
            (s.buffers.len() as u32, s.buffers.as_ptr()),
            (s.images.len() as u32, s.images.as_ptr()),
        )
    })
}

#[allow(clippy::too_many_arguments)]
fn pipeline_barrier(
    c: Call<'_, Device, vk::PFN_vkCmdPipelineBarrier, impl Fn()>,
    cb: vk::CommandBuffer,
    src: vk::PipelineStageFlags,
    dst: vk::PipelineStageFlags,
    flags: vk::DependencyFlags,
    _memory_count: u32,
    memory: Arr<'_, vk::MemoryBarrier<'_>>,
    _buffer_count: u32,
    buffers: Arr<'_, vk::BufferMemoryBarrier<'_>>,
    _image_count: u32,
    images: Arr<'_, vk::ImageMemoryBarrier<'_>>,
) {
    let Some(given) = to_translate1(c.dev, [src, dst], memory, buffers, images) else {
        return c.as_given();
    };
    translated1(cb, [src, dst], given, |[src, dst], m, b, i| {
        // SAFETY: the next layer's function, with the application's arrays or copies that live
        // across the call.
        unsafe { (c.next)(cb, src, dst, flags, m.0, m.1, b.0, b.1, i.0, i.1) }
    })
}

/// Calls `down` with a v2 command's dependency infos: the application's where nothing in them
/// names the density map (or the device does not emulate), else translated copies in this
/// thread's scratch.
fn with_dependencies(
    dev: &Device,
    cb: vk::CommandBuffer,
    infos: Arr<'_, vk::DependencyInfo<'_>>,
    down: impl FnOnce(*const vk::DependencyInfo<'_>),
) {
    let list = infos.slice();
    if dev.fdm.is_none() || !list.iter().any(needs2) {
        return down(infos.raw());
    }
    with_scratch(|s| {
        // SAFETY: the application's dependency infos, valid as the command requires; the copies
        // live in the scratch across the call down only.
        let copies = unsafe { translate2(s, cb, list) };
        down(copies.as_ptr())
    })
}

hook! {
    /// `vkCmdPipelineBarrier2`.
    cmd_pipeline_barrier2 = "vkCmdPipelineBarrier2",
        cmd_pipeline_barrier2_khr = "vkCmdPipelineBarrier2KHR";
    on device_ref(cb), next cmd_pipeline_barrier2 / cmd_pipeline_barrier2_khr, fails(());
    pipeline_barrier2(cb: val vk::CommandBuffer, info: (array ONE) vk::DependencyInfo<'_>) -> ()
}

/// The one dependency info of `vkCmdPipelineBarrier2` and `vkCmdSetEvent2`, as an array.
const ONE: u32 = 1;

fn pipeline_barrier2(
    c: Call<'_, Device, vk::PFN_vkCmdPipelineBarrier2, impl Fn()>,
    cb: vk::CommandBuffer,
    info: Arr<'_, vk::DependencyInfo<'_>>,
) {
    // SAFETY: the next layer's function, with the application's dependency info or a copy that
    // lives across the call.
    with_dependencies(c.dev, cb, info, |i| unsafe { (c.next)(cb, i) })
}

hook! {
    /// `vkCmdSetEvent2`: the dependency info is translated as a barrier's, so it stays identical
    /// to the one `vkCmdWaitEvents2` gets for the same event, as the spec requires
    /// (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkCmdWaitEvents2.html>,
    /// VUID-vkCmdWaitEvents2-pEvents-03837).
    cmd_set_event2 = "vkCmdSetEvent2", cmd_set_event2_khr = "vkCmdSetEvent2KHR";
    on device_ref(cb), next cmd_set_event2 / cmd_set_event2_khr, fails(());
    set_event2(
        cb: val vk::CommandBuffer,
        event: val vk::Event,
        info: (array ONE) vk::DependencyInfo<'_>,
    ) -> ()
}

fn set_event2(
    c: Call<'_, Device, vk::PFN_vkCmdSetEvent2, impl Fn()>,
    cb: vk::CommandBuffer,
    event: vk::Event,
    info: Arr<'_, vk::DependencyInfo<'_>>,
) {
    // SAFETY: the next layer's function, with the application's dependency info or a copy that
    // lives across the call.
    with_dependencies(c.dev, cb, info, |i| unsafe { (c.next)(cb, event, i) })
}

hook! {
    /// `vkCmdWaitEvents`.
    cmd_wait_events = "vkCmdWaitEvents";
    on device_ref(cb), next cmd_wait_events, fails(());
    wait_events(
        cb: val vk::CommandBuffer,
        event_count: val u32,
        events: val *const vk::Event,
        src: val vk::PipelineStageFlags,
        dst: val vk::PipelineStageFlags,
        memory_count: val u32,
        memory: (array memory_count) vk::MemoryBarrier<'_>,
        buffer_count: val u32,
        buffers: (array buffer_count) vk::BufferMemoryBarrier<'_>,
        image_count: val u32,
        images: (array image_count) vk::ImageMemoryBarrier<'_>,
    ) -> ()
}

#[allow(clippy::too_many_arguments)]
fn wait_events(
    c: Call<'_, Device, vk::PFN_vkCmdWaitEvents, impl Fn()>,
    cb: vk::CommandBuffer,
    event_count: u32,
    events: *const vk::Event,
    src: vk::PipelineStageFlags,
    dst: vk::PipelineStageFlags,
    _memory_count: u32,
    memory: Arr<'_, vk::MemoryBarrier<'_>>,
    _buffer_count: u32,
    buffers: Arr<'_, vk::BufferMemoryBarrier<'_>>,
    _image_count: u32,
    images: Arr<'_, vk::ImageMemoryBarrier<'_>>,
) {
    let Some(given) = to_translate1(c.dev, [src, dst], memory, buffers, images) else {
        return c.as_given();
    };
    translated1(cb, [src, dst], given, |[src, dst], m, b, i| {
        // SAFETY: the next layer's function, with the application's arrays or copies that live
        // across the call.
        unsafe {
            (c.next)(
                cb,
                event_count,
                events,
                src,
                dst,
                m.0,
                m.1,
                b.0,
                b.1,
                i.0,
                i.1,
            )
        }
    })
}

hook! {
    /// `vkCmdWaitEvents2`: one dependency info per event.
    cmd_wait_events2 = "vkCmdWaitEvents2", cmd_wait_events2_khr = "vkCmdWaitEvents2KHR";
    on device_ref(cb), next cmd_wait_events2 / cmd_wait_events2_khr, fails(());
    wait_events2(
        cb: val vk::CommandBuffer,
        count: val u32,
        events: val *const vk::Event,
        infos: (array count) vk::DependencyInfo<'_>,
    ) -> ()
}

fn wait_events2(
    c: Call<'_, Device, vk::PFN_vkCmdWaitEvents2, impl Fn()>,
    cb: vk::CommandBuffer,
    count: u32,
    events: *const vk::Event,
    infos: Arr<'_, vk::DependencyInfo<'_>>,
) {
    // SAFETY: the next layer's function, with the application's dependency infos or copies that
    // live across the call.
    with_dependencies(c.dev, cb, infos, |i| unsafe {
        (c.next)(cb, count, events, i)
    })
}

/// A stage mask as the driver must get it: without the density-map stage on an emulating device.
#[inline]
fn stage_on<S>(dev: &Device, mask: S, translate: fn(S) -> S) -> S {
    if dev.fdm.is_some() {
        translate(mask)
    } else {
        mask
    }
}

hook! {
    /// `vkCmdSetEvent`: the stage mask without the density-map stage (the bits are invalid on the
    /// driver's device, VUID-vkCmdSetEvent-stageMask-04093 family,
    /// <https://registry.khronos.org/vulkan/specs/latest/man/html/vkCmdSetEvent.html>); it stays
    /// matched to the `vkCmdWaitEvents` source stages, which are translated alike.
    cmd_set_event = "vkCmdSetEvent";
    on device_ref(cb), next cmd_set_event, fails(());
    set_event(cb: val vk::CommandBuffer, event: val vk::Event, mask: val vk::PipelineStageFlags) -> ()
}

fn set_event(
    c: Call<'_, Device, vk::PFN_vkCmdSetEvent, impl Fn()>,
    cb: vk::CommandBuffer,
    event: vk::Event,
    mask: vk::PipelineStageFlags,
) {
    // SAFETY: the next layer's function, with the application's arguments (the mask translated).
    unsafe { (c.next)(cb, event, stage_on(c.dev, mask, stage)) }
}

hook! {
    /// `vkCmdResetEvent`: as [`cmd_set_event`].
    cmd_reset_event = "vkCmdResetEvent";
    on device_ref(cb), next cmd_reset_event, fails(());
    reset_event(
        cb: val vk::CommandBuffer,
        event: val vk::Event,
        mask: val vk::PipelineStageFlags,
    ) -> ()
}

fn reset_event(
    c: Call<'_, Device, vk::PFN_vkCmdResetEvent, impl Fn()>,
    cb: vk::CommandBuffer,
    event: vk::Event,
    mask: vk::PipelineStageFlags,
) {
    // SAFETY: the next layer's function, with the application's arguments (the mask translated).
    unsafe { (c.next)(cb, event, stage_on(c.dev, mask, stage)) }
}

hook! {
    /// `vkCmdResetEvent2`: as [`cmd_set_event`].
    cmd_reset_event2 = "vkCmdResetEvent2", cmd_reset_event2_khr = "vkCmdResetEvent2KHR";
    on device_ref(cb), next cmd_reset_event2 / cmd_reset_event2_khr, fails(());
    reset_event2(
        cb: val vk::CommandBuffer,
        event: val vk::Event,
        mask: val vk::PipelineStageFlags2,
    ) -> ()
}

fn reset_event2(
    c: Call<'_, Device, vk::PFN_vkCmdResetEvent2, impl Fn()>,
    cb: vk::CommandBuffer,
    event: vk::Event,
    mask: vk::PipelineStageFlags2,
) {
    // SAFETY: the next layer's function, with the application's arguments (the mask translated).
    unsafe { (c.next)(cb, event, stage_on(c.dev, mask, stage2)) }
}

hook! {
    /// `vkCmdWriteTimestamp`: a timestamp after the density-map stage is one after the
    /// shading-rate attachment stage, which takes its place on the driver's device.
    cmd_write_timestamp = "vkCmdWriteTimestamp";
    on device_ref(cb), next cmd_write_timestamp, fails(());
    write_timestamp(
        cb: val vk::CommandBuffer,
        at: val vk::PipelineStageFlags,
        pool: val vk::QueryPool,
        query: val u32,
    ) -> ()
}

fn write_timestamp(
    c: Call<'_, Device, vk::PFN_vkCmdWriteTimestamp, impl Fn()>,
    cb: vk::CommandBuffer,
    at: vk::PipelineStageFlags,
    pool: vk::QueryPool,
    query: u32,
) {
    // SAFETY: the next layer's function, with the application's arguments (the stage
    // translated).
    unsafe { (c.next)(cb, stage_on(c.dev, at, stage), pool, query) }
}

hook! {
    /// `vkCmdWriteTimestamp2`: as [`cmd_write_timestamp`].
    cmd_write_timestamp2 = "vkCmdWriteTimestamp2",
        cmd_write_timestamp2_khr = "vkCmdWriteTimestamp2KHR";
    on device_ref(cb), next cmd_write_timestamp2 / cmd_write_timestamp2_khr, fails(());
    write_timestamp2(
        cb: val vk::CommandBuffer,
        at: val vk::PipelineStageFlags2,
        pool: val vk::QueryPool,
        query: val u32,
    ) -> ()
}

fn write_timestamp2(
    c: Call<'_, Device, vk::PFN_vkCmdWriteTimestamp2, impl Fn()>,
    cb: vk::CommandBuffer,
    at: vk::PipelineStageFlags2,
    pool: vk::QueryPool,
    query: u32,
) {
    // SAFETY: the next layer's function, with the application's arguments (the stage
    // translated).
    unsafe { (c.next)(cb, stage_on(c.dev, at, stage2), pool, query) }
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
