//! Barriers (and event sets and waits) on an emulating device: the density-map layout, stage and
//! access bits become what the driver knows (docs/vulkan-fdm-on-fsr.md#mapping), on copies of the application's arrays.
//!
//! - stage `FRAGMENT_DENSITY_PROCESS_EXT` → `FRAGMENT_SHADING_RATE_ATTACHMENT_KHR`, access
//!   `FRAGMENT_DENSITY_MAP_READ_EXT` → `FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR`: the FDM bits
//!   are invalid without the FDM feature, which the driver never has enabled
//!   (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkPipelineStageFlagBits.html>);
//! - layout `FRAGMENT_DENSITY_MAP_OPTIMAL_EXT` → `GENERAL` on the application's own image: that
//!   image is an `R8G8_UNORM` image without the density-map usage on the driver's side, and
//!   `FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR` would need the shading-rate usage, which an
//!   `R8G8_UNORM` image cannot have
//!   (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkImageMemoryBarrier.html>,
//!   VUID-VkImageMemoryBarrier-oldLayout-02088); `GENERAL` is valid for every usage;
//! - where the image has a shading-rate shadow ([`crate::bridge::shadow_of`]), a barrier that moves
//!   it into the density-map layout also orders the shadow: an added barrier on the shadow, in
//!   `FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR` on both sides (the shadow never leaves that
//!   layout outside fovea's own uploads), with the translated stages and accesses.
//!
//! The common path (no density-map bit anywhere in the call) is a scan of the masks and a direct
//! call down. The rewrite path reuses a per-thread scratch buffer, so recording allocates nothing
//! in steady state.

use std::cell::RefCell;

use ash::vk;

use crate::vk::base::ffi::{guard, slice};
use crate::vk::registry;

const FDM_LAYOUT: vk::ImageLayout = vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT;
const FSR_LAYOUT: vk::ImageLayout = vk::ImageLayout::FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR;
/// What the application's own density image is moved to instead of [`FDM_LAYOUT`].
pub const IMAGE_LAYOUT: vk::ImageLayout = vk::ImageLayout::GENERAL;

const STAGE: vk::PipelineStageFlags = vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT;
const FSR_STAGE: vk::PipelineStageFlags =
    vk::PipelineStageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR;
const ACCESS: vk::AccessFlags = vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT;
const FSR_ACCESS: vk::AccessFlags = vk::AccessFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR;
const STAGE2: vk::PipelineStageFlags2 = vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT;
const FSR_STAGE2: vk::PipelineStageFlags2 =
    vk::PipelineStageFlags2::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR;
const ACCESS2: vk::AccessFlags2 = vk::AccessFlags2::FRAGMENT_DENSITY_MAP_READ_EXT;
const FSR_ACCESS2: vk::AccessFlags2 = vk::AccessFlags2::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR;

/// A stage mask without the density-map stage.
pub fn stage(s: vk::PipelineStageFlags) -> vk::PipelineStageFlags {
    if s.intersects(STAGE) {
        (s & !STAGE) | FSR_STAGE
    } else {
        s
    }
}

/// An access mask without the density-map read.
pub fn access(a: vk::AccessFlags) -> vk::AccessFlags {
    if a.intersects(ACCESS) {
        (a & !ACCESS) | FSR_ACCESS
    } else {
        a
    }
}

/// [`stage`] for the 64-bit masks.
pub fn stage2(s: vk::PipelineStageFlags2) -> vk::PipelineStageFlags2 {
    if s.intersects(STAGE2) {
        (s & !STAGE2) | FSR_STAGE2
    } else {
        s
    }
}

/// [`access`] for the 64-bit masks.
pub fn access2(a: vk::AccessFlags2) -> vk::AccessFlags2 {
    if a.intersects(ACCESS2) {
        (a & !ACCESS2) | FSR_ACCESS2
    } else {
        a
    }
}

/// The layout the application's density image gets instead of the density-map layout.
pub fn layout(l: vk::ImageLayout) -> vk::ImageLayout {
    if l == FDM_LAYOUT {
        IMAGE_LAYOUT
    } else {
        l
    }
}

/// The shadow's whole subresource range.
fn shadow_range(layers: u32) -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange {
        aspect_mask: vk::ImageAspectFlags::COLOR,
        base_mip_level: 0,
        level_count: 1,
        base_array_layer: 0,
        layer_count: layers.max(1),
    }
}

/// The translated barrier for the application's image, and, where it moves a density image with a
/// shadow into the density-map layout, the shadow's.
pub fn image_barrier(
    b: &vk::ImageMemoryBarrier<'static>,
    shadow_of: impl Fn(vk::Image) -> Option<crate::bridge::Shadow>,
) -> (
    vk::ImageMemoryBarrier<'static>,
    Option<vk::ImageMemoryBarrier<'static>>,
) {
    let mut out = *b;
    out.src_access_mask = access(b.src_access_mask);
    out.dst_access_mask = access(b.dst_access_mask);
    out.old_layout = layout(b.old_layout);
    out.new_layout = layout(b.new_layout);
    let shadow = (b.new_layout == FDM_LAYOUT)
        .then(|| shadow_of(b.image))
        .flatten()
        .map(|s| {
            let mut sb = out;
            sb.p_next = std::ptr::null();
            sb.old_layout = FSR_LAYOUT;
            sb.new_layout = FSR_LAYOUT;
            sb.src_queue_family_index = vk::QUEUE_FAMILY_IGNORED;
            sb.dst_queue_family_index = vk::QUEUE_FAMILY_IGNORED;
            sb.image = s.image;
            sb.subresource_range = shadow_range(s.layers);
            sb
        });
    (out, shadow)
}

/// [`image_barrier`] for `VkImageMemoryBarrier2`.
pub fn image_barrier2(
    b: &vk::ImageMemoryBarrier2<'static>,
    shadow_of: impl Fn(vk::Image) -> Option<crate::bridge::Shadow>,
) -> (
    vk::ImageMemoryBarrier2<'static>,
    Option<vk::ImageMemoryBarrier2<'static>>,
) {
    let mut out = *b;
    out.src_stage_mask = stage2(b.src_stage_mask);
    out.dst_stage_mask = stage2(b.dst_stage_mask);
    out.src_access_mask = access2(b.src_access_mask);
    out.dst_access_mask = access2(b.dst_access_mask);
    out.old_layout = layout(b.old_layout);
    out.new_layout = layout(b.new_layout);
    let shadow = (b.new_layout == FDM_LAYOUT)
        .then(|| shadow_of(b.image))
        .flatten()
        .map(|s| {
            let mut sb = out;
            sb.p_next = std::ptr::null();
            sb.old_layout = FSR_LAYOUT;
            sb.new_layout = FSR_LAYOUT;
            sb.src_queue_family_index = vk::QUEUE_FAMILY_IGNORED;
            sb.dst_queue_family_index = vk::QUEUE_FAMILY_IGNORED;
            sb.image = s.image;
            sb.subresource_range = shadow_range(s.layers);
            sb
        });
    (out, shadow)
}

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

/// Whether a barrier with these queue family indices, recorded into `cb`, is the release half of a
/// queue family ownership transfer. Not a transfer where the indices are equal or either is
/// `IGNORED`; a release where the destination is outside the device (`EXTERNAL`, `FOREIGN`), an
/// acquire where the source is; between two of the device's families, a release where `cb`'s pool
/// belongs to the source family ([`FAMILIES`]). Where that family is not known, a release: an
/// acquire half then goes without the shadow's barrier, which is what the application wrote.
fn is_release(cb: vk::CommandBuffer, src: u32, dst: u32) -> bool {
    let outside = |q: u32| q == vk::QUEUE_FAMILY_EXTERNAL || q == vk::QUEUE_FAMILY_FOREIGN_EXT;
    if src == dst || src == vk::QUEUE_FAMILY_IGNORED || dst == vk::QUEUE_FAMILY_IGNORED {
        return false;
    }
    if outside(dst) {
        return true;
    }
    if outside(src) {
        return false;
    }
    FAMILIES.command_buffer(cb).is_none_or(|f| f == src)
}

/// Slots per table in [`Families`]: more command pools and command buffers than an application
/// keeps alive at once, so that a live one is rarely evicted.
const POOL_SLOTS: usize = 256;
const BUFFER_SLOTS: usize = 4096;

/// The queue family of command pools (from `vkCreateCommandPool`) and of command buffers (from
/// their pool at `vkAllocateCommandBuffers`), for [`is_release`]. Direct-mapped tables of fixed
/// size, so nothing grows however many pools and buffers come and go (a freed handle's slot is
/// taken by the next one that maps there, and a handle the driver reuses is entered again when it
/// is made). Written when pools and buffers are made, read only for an ownership transfer of a
/// density image: a leaf lock, never taken per command on the common path.
struct Families {
    pools: parking_lot::Mutex<[(u64, u32); POOL_SLOTS]>,
    buffers: parking_lot::Mutex<[(u64, u32); BUFFER_SLOTS]>,
}

static FAMILIES: Families = Families {
    pools: parking_lot::Mutex::new([(0, 0); POOL_SLOTS]),
    buffers: parking_lot::Mutex::new([(0, 0); BUFFER_SLOTS]),
};

fn slot(raw: u64, slots: usize) -> usize {
    ((raw ^ (raw >> 29)).wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 40) as usize % slots
}

impl Families {
    fn command_buffer(&self, cb: vk::CommandBuffer) -> Option<u32> {
        use ash::vk::Handle as _;
        let raw = cb.as_raw();
        let t = self.buffers.lock();
        let (h, f) = t[slot(raw, BUFFER_SLOTS)];
        (raw != 0 && h == raw).then_some(f)
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
                FAMILIES.pools.lock()[slot(raw, POOL_SLOTS)] = (raw, i.queue_family_index);
            }
            r
        },
    )
}

/// Notes the queue family (their pool's) of command buffers `vkAllocateCommandBuffers` just made
/// from `info` (its hook is [`crate::vk::convert::allocate_command_buffers`], which also gives
/// each its record).
pub fn buffers_allocated(info: &vk::CommandBufferAllocateInfo<'_>, cbs: &[vk::CommandBuffer]) {
    use ash::vk::Handle as _;
    let pool = info.command_pool.as_raw();
    let family = {
        let t = FAMILIES.pools.lock();
        let (h, f) = t[slot(pool, POOL_SLOTS)];
        (h == pool).then_some(f)
    };
    let mut t = FAMILIES.buffers.lock();
    for cb in cbs {
        let raw = cb.as_raw();
        // A pool whose family is not known leaves its buffers unknown too.
        t[slot(raw, BUFFER_SLOTS)] = family.map_or((0, 0), |f| (raw, f));
    }
}

fn touches_image(b: &vk::ImageMemoryBarrier<'_>) -> bool {
    b.old_layout == FDM_LAYOUT
        || b.new_layout == FDM_LAYOUT
        || (b.src_access_mask | b.dst_access_mask).intersects(ACCESS)
}

fn touches_image2(b: &vk::ImageMemoryBarrier2<'_>) -> bool {
    b.old_layout == FDM_LAYOUT
        || b.new_layout == FDM_LAYOUT
        || (b.src_access_mask | b.dst_access_mask).intersects(ACCESS2)
        || (b.src_stage_mask | b.dst_stage_mask).intersects(STAGE2)
}

fn touches2(access: vk::AccessFlags2, stage: vk::PipelineStageFlags2) -> bool {
    access.intersects(ACCESS2) || stage.intersects(STAGE2)
}

/// Whether a version-1 barrier call needs translating: a scan of masks and layouts only.
///
/// # Safety
/// The arrays must be valid for their counts.
#[allow(clippy::too_many_arguments)]
unsafe fn needs1(
    src: vk::PipelineStageFlags,
    dst: vk::PipelineStageFlags,
    memory: &[vk::MemoryBarrier<'_>],
    buffers: &[vk::BufferMemoryBarrier<'_>],
    images: &[vk::ImageMemoryBarrier<'_>],
) -> bool {
    (src | dst).intersects(STAGE)
        || memory
            .iter()
            .any(|b| (b.src_access_mask | b.dst_access_mask).intersects(ACCESS))
        || buffers
            .iter()
            .any(|b| (b.src_access_mask | b.dst_access_mask).intersects(ACCESS))
        || images.iter().any(touches_image)
}

/// Whether a dependency info needs translating.
fn needs2(d: &vk::DependencyInfo<'_>) -> bool {
    // SAFETY: the application's arrays, valid for their counts (the command's valid usage).
    let (m, b, i) = unsafe {
        (
            slice(d.p_memory_barriers, d.memory_barrier_count),
            slice(d.p_buffer_memory_barriers, d.buffer_memory_barrier_count),
            slice(d.p_image_memory_barriers, d.image_memory_barrier_count),
        )
    };
    m.iter().any(|b| {
        touches2(
            b.src_access_mask | b.dst_access_mask,
            b.src_stage_mask | b.dst_stage_mask,
        )
    }) || b.iter().any(|b| {
        touches2(
            b.src_access_mask | b.dst_access_mask,
            b.src_stage_mask | b.dst_stage_mask,
        )
    }) || i.iter().any(touches_image2)
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
        let release = is_release(cb, b.src_queue_family_index, b.dst_queue_family_index);
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
            let release = is_release(cb, b.src_queue_family_index, b.dst_queue_family_index);
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
    use crate::bridge::Shadow;
    use ash::vk::Handle as _;

    fn range(layers: u32) -> vk::ImageSubresourceRange {
        vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: 0,
            layer_count: layers,
        }
    }

    #[test]
    fn release_halves_are_told_from_acquire_halves() {
        let ignored = vk::QUEUE_FAMILY_IGNORED;
        let external = vk::QUEUE_FAMILY_EXTERNAL;
        let cb = vk::CommandBuffer::from_raw(0x5a5a_0010);
        // Not transfers.
        assert!(!is_release(cb, ignored, ignored));
        assert!(!is_release(cb, 1, 1));
        assert!(!is_release(cb, 0, ignored));
        // To and from outside the device.
        assert!(is_release(cb, 0, external));
        assert!(!is_release(cb, external, 0));
        // Between two families: by the command buffer's; unknown counts as a release.
        assert!(is_release(cb, 0, 1));
        FAMILIES.buffers.lock()[slot(cb.as_raw(), BUFFER_SLOTS)] = (cb.as_raw(), 1);
        assert!(
            !is_release(cb, 0, 1),
            "recorded on the destination family: acquire"
        );
        assert!(
            is_release(cb, 1, 0),
            "recorded on the source family: release"
        );
        FAMILIES.buffers.lock()[slot(cb.as_raw(), BUFFER_SLOTS)] = (0, 0);
    }

    #[test]
    fn masks_and_layouts_are_translated_and_nothing_else() {
        let s = vk::PipelineStageFlags::TRANSFER | STAGE;
        assert_eq!(stage(s), vk::PipelineStageFlags::TRANSFER | FSR_STAGE);
        assert_eq!(
            stage(vk::PipelineStageFlags::ALL_COMMANDS),
            vk::PipelineStageFlags::ALL_COMMANDS
        );
        assert_eq!(access(ACCESS | vk::AccessFlags::SHADER_READ).as_raw(), {
            (FSR_ACCESS | vk::AccessFlags::SHADER_READ).as_raw()
        });
        assert_eq!(stage2(STAGE2), FSR_STAGE2);
        assert_eq!(access2(ACCESS2), FSR_ACCESS2);
        assert_eq!(
            access2(vk::AccessFlags2::MEMORY_READ),
            vk::AccessFlags2::MEMORY_READ
        );
        assert_eq!(layout(FDM_LAYOUT), vk::ImageLayout::GENERAL);
        assert_eq!(
            layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL),
            vk::ImageLayout::TRANSFER_DST_OPTIMAL
        );
    }

    #[test]
    fn an_image_moved_into_the_density_layout_orders_its_shadow_too() {
        let image = vk::Image::from_raw(7);
        let shadow = Shadow {
            device: vk::Device::from_raw(3),
            image: vk::Image::from_raw(9),
            extent: [4, 4],
            layers: 1,
            app_layers: 2,
        };
        let lookup = |i: vk::Image| (i == image).then_some(shadow);
        let b = vk::ImageMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(ACCESS)
            .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
            .new_layout(FDM_LAYOUT)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(image)
            .subresource_range(range(2));
        let (c, s) = image_barrier(&b, lookup);
        assert_eq!(c.new_layout, vk::ImageLayout::GENERAL);
        assert_eq!(c.old_layout, vk::ImageLayout::TRANSFER_DST_OPTIMAL);
        assert_eq!(c.dst_access_mask, FSR_ACCESS);
        assert_eq!(c.image, image);
        assert_eq!(c.subresource_range.layer_count, 2);
        let s = s.expect("the shadow's barrier");
        assert_eq!(s.image, shadow.image);
        assert_eq!((s.old_layout, s.new_layout), (FSR_LAYOUT, FSR_LAYOUT));
        assert_eq!(s.subresource_range.layer_count, 1);
        assert_eq!(s.src_access_mask, vk::AccessFlags::TRANSFER_WRITE);
        assert_eq!(s.dst_access_mask, FSR_ACCESS);
        // Out of the density layout, or an image without a shadow: no added barrier.
        let back = b
            .old_layout(FDM_LAYOUT)
            .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL);
        let (c, s) = image_barrier(&back, lookup);
        assert_eq!(c.old_layout, vk::ImageLayout::GENERAL);
        assert!(s.is_none());
        let other = b.image(vk::Image::from_raw(8));
        assert!(image_barrier(&other, lookup).1.is_none());
        // The application's barrier is untouched.
        assert_eq!(b.new_layout, FDM_LAYOUT);

        let b2 = vk::ImageMemoryBarrier2::default()
            .src_stage_mask(vk::PipelineStageFlags2::COPY)
            .dst_stage_mask(STAGE2)
            .dst_access_mask(ACCESS2)
            .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
            .new_layout(FDM_LAYOUT)
            .image(image)
            .subresource_range(range(2));
        let (c, s) = image_barrier2(&b2, lookup);
        assert_eq!(c.dst_stage_mask, FSR_STAGE2);
        assert_eq!(c.new_layout, vk::ImageLayout::GENERAL);
        assert_eq!(s.expect("shadow").dst_stage_mask, FSR_STAGE2);
    }

    #[test]
    fn only_calls_with_density_bits_are_translated() {
        let plain = [vk::ImageMemoryBarrier::default()
            .old_layout(vk::ImageLayout::UNDEFINED)
            .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)];
        let stages = vk::PipelineStageFlags::TRANSFER;
        // SAFETY: arrays on the stack.
        unsafe {
            assert!(!needs1(stages, stages, &[], &[], &plain));
            assert!(needs1(stages, STAGE, &[], &[], &plain));
            let fdm = [plain[0].new_layout(FDM_LAYOUT)];
            assert!(needs1(stages, stages, &[], &[], &fdm));
            let mem = [vk::MemoryBarrier::default().dst_access_mask(ACCESS)];
            assert!(needs1(stages, stages, &mem, &[], &[]));
        }
        let images = [vk::ImageMemoryBarrier2::default().dst_stage_mask(STAGE2)];
        let d = vk::DependencyInfo::default();
        assert!(!needs2(&d));
        assert!(needs2(&d.image_memory_barriers(&images)));
    }

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
