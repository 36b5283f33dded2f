//! Submits on an emulating device: the layer's pending shadow clears run in front of the
//! application's next submit on a graphics queue, and the density-map stage bits of semaphore
//! waits become the shading-rate ones.
//!
//! Clears. A new shadow must hold rate code 0 (1×1, full rate) before any pass reads it
//! (docs/vulkan-fdm-on-fsr.md#shadows), and a clear needs a queue. Vulkan makes every use of a
//! queue externally synchronised by the application
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkQueueSubmit.html>, "Host
//! Synchronization"), so the layer may only use a queue inside a call the application made on it:
//! `vkCreateImage` records the shadow as pending ([`Clears::add`]), and the next
//! `vkQueueSubmit`, `vkQueueSubmit2` or `vkQueueSubmit2KHR` on a queue of a graphics family (where
//! the passes that read the shadow run) first submits one layer-owned command buffer that clears
//! every pending shadow and moves it to the shading-rate layout, with a fence of the layer's own.
//! A separate submission just before the application's is ordered before it like a batch of the
//! same call: both are in the queue's submission order, and the clear's last barrier has every
//! later command in its second scope
//! (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#synchronization-submission-order>).
//! Its own fence tells when the command buffer may be freed; the application's fences of later
//! submissions cover it too ("fence signal operations … include … all commands that occur earlier
//! in submission order", <https://registry.khronos.org/vulkan/specs/latest/man/html/vkQueueSubmit.html>),
//! so an application that waits for its own work before `vkDestroyDevice` has waited for the clear.
//!
//! The command buffer is recorded at that submit, not at `vkCreateImage`: only then is the queue
//! family known, and it is recorded once for all shadows made since the last one. Where recording or
//! submitting it fails, the application's submit returns that result (one of those `vkQueueSubmit`
//! may return) without going down, and the clears stay pending: the application's work would read
//! shadows in an undefined layout otherwise.
//!
//! A shadow destroyed before any submit drops its pending clear (no command buffer exists yet); one
//! destroyed while its clear is in flight is destroyed once that clear's fence has signalled
//! ([`Clears::forget`]). fovea's own density images get no clear: every upload writes the whole
//! shadow, from `UNDEFINED`, before the application can render with the image
//! (`src/gpu/density_images.rs`, docs/ARCHITECTURE.md "Maps are written only on acquire"), so no
//! clear can land after an upload.
//!
//! Uploads. Injected shading-rate maps (docs/injection.md#how-the-attachment-gets-in) are filled
//! with bytes the layer computed, by the same means and at the same moment: [`Clears::upload`]
//! stages them, and the next submit on a graphics queue copies them from a host-visible staging
//! buffer of the layer's own into the image, from `UNDEFINED` (every texel is written) after an
//! execution dependency on everything earlier on that queue (a pass that still reads the image's
//! old content), ending in the shading-rate layout. The staging buffer is freed with the command
//! buffer, once its fence has signalled.
//!
//! With nothing pending anywhere (the steady state) a submit costs one atomic load and a scan of
//! its wait-stage masks before the call down.

use std::sync::atomic::{AtomicUsize, Ordering};

use ash::vk;
use ash::vk::Handle as _;

use crate::vk::barrier;
use crate::vk::base::ffi::{guard, raw, slice};
use crate::vk::image::{Own, SHADOW_LAYOUT};
use crate::vk::registry::{self, ShadowImage};

/// Pending clears in the whole process: what the submit hooks' fast path reads.
static PENDING: AtomicUsize = AtomicUsize::new(0);

/// How long `vkDestroyDevice` waits for a clear still in flight (the application must have waited
/// for its work, and the clear precedes it on the queue; this bounds a misbehaving one).
const DESTROY_WAIT_NS: u64 = 1_000_000_000;

/// One submitted clear.
struct InFlight {
    pool: vk::CommandPool,
    cb: vk::CommandBuffer,
    fence: vk::Fence,
    /// The shadows it clears.
    shadows: Vec<vk::Image>,
    /// Shadows destroyed by the application meanwhile, destroyed when `fence` has signalled.
    retired: Vec<(vk::Image, vk::DeviceMemory)>,
    /// The uploads' staging buffer, freed when `fence` has signalled.
    staging: Option<(vk::Buffer, vk::DeviceMemory)>,
}

/// Bytes waiting to be copied into a layer-owned shading-rate image: `layers` layers of
/// `extent` texels, one byte each, layer after layer.
struct Upload {
    image: vk::Image,
    extent: [u32; 2],
    layers: u32,
    bytes: Vec<u8>,
}

#[derive(Default)]
struct State {
    /// Shadows waiting for their clear, with their layers.
    pending: Vec<(vk::Image, u32)>,
    /// Images waiting for their upload (at most one per image: the newest bytes).
    uploads: Vec<Upload>,
    /// A command pool per graphics family the layer submitted on, made at its first clear there.
    pools: Vec<(u32, vk::CommandPool)>,
    in_flight: Vec<InFlight>,
}

/// One device's shadow clears.
pub struct Clears {
    /// The application's queues of graphics families (handle, family), from the device create info.
    queues: Vec<(u64, u32)>,
    /// A leaf lock outside [`crate::common::lock::Rank`]'s order: under it the layer calls only the
    /// next layer's commands on its own objects (which never call back into fovea), and it may be
    /// taken under fovea's own upload locks, whose submits pass through this layer.
    state: parking_lot::Mutex<State>,
}

impl Clears {
    /// No clears yet, for a device whose graphics queues are `queues`.
    pub fn new(queues: Vec<(u64, u32)>) -> Clears {
        Clears {
            queues,
            state: parking_lot::Mutex::new(State::default()),
        }
    }

    /// The family of `queue`, where it is one of the application's graphics queues.
    fn family_of(&self, queue: vk::Queue) -> Option<u32> {
        self.queues
            .iter()
            .find(|(q, _)| *q == queue.as_raw())
            .map(|&(_, f)| f)
    }

    /// Notes that the new shadow `image` of `layers` layers must be cleared before its first use.
    pub fn add(&self, image: vk::Image, layers: u32) {
        self.state.lock().pending.push((image, layers));
        PENDING.fetch_add(1, Ordering::Release);
    }

    /// Notes that `image` (of `layers` layers of `extent` texels) must hold `bytes` before its next
    /// use; replaces an upload of the same image still pending, whose bytes are out of date.
    pub fn upload(&self, image: vk::Image, extent: [u32; 2], layers: u32, bytes: Vec<u8>) {
        let mut st = self.state.lock();
        let new = Upload {
            image,
            extent,
            layers,
            bytes,
        };
        match st.uploads.iter_mut().find(|u| u.image == image) {
            Some(u) => *u = new,
            None => {
                st.uploads.push(new);
                PENDING.fetch_add(1, Ordering::Release);
            }
        }
    }

    /// Drops a pending upload of `image`, which is about to be destroyed; waits for everything in
    /// flight, which may copy into it.
    ///
    /// # Safety
    /// `d` must be the live device of these uploads.
    pub unsafe fn forget_upload(&self, d: &ash::Device, image: vk::Image) {
        let mut st = self.state.lock();
        if let Some(i) = st.uploads.iter().position(|u| u.image == image) {
            st.uploads.swap_remove(i);
            PENDING.fetch_sub(1, Ordering::Release);
        }
        // SAFETY: the layer's own objects on a live device.
        unsafe { reclaim(d, &mut st, true) };
    }

    /// Destroys a shadow whose application image is being destroyed: at once where its clear is
    /// pending (dropped) or done, once its clear's fence has signalled where it is in flight.
    ///
    /// # Safety
    /// `s` must be a live shadow of `d`'s device that nothing of the application's uses any more.
    pub unsafe fn forget(&self, d: &ash::Device, s: &ShadowImage) {
        let mut st = self.state.lock();
        // SAFETY: the layer's own objects on a live device.
        unsafe { reclaim(d, &mut st, false) };
        if let Some(i) = st.pending.iter().position(|(i, _)| *i == s.image) {
            st.pending.swap_remove(i);
            PENDING.fetch_sub(1, Ordering::Release);
        } else if let Some(f) = st
            .in_flight
            .iter_mut()
            .find(|f| f.shadows.contains(&s.image))
        {
            f.retired.push((s.image, s.memory));
            return;
        }
        drop(st);
        // SAFETY: as the caller promised; no clear of it is pending or in flight.
        unsafe {
            d.destroy_image(s.image, None);
            d.free_memory(s.memory, None);
        }
    }

    /// Submits the pending clears on `queue` ahead of the application's submission, where it is a
    /// graphics queue of the application's.
    ///
    /// # Safety
    /// Called inside the application's submit on `queue`, of `own`'s live device.
    unsafe fn flush(&self, own: &Own, queue: vk::Queue) -> Result<(), vk::Result> {
        let Some(family) = self.family_of(queue) else {
            return Ok(());
        };
        let d = &own.fns;
        // Held across the layer's own submit, so a shadow destroyed meanwhile is either still
        // pending or already in flight, never in between.
        let mut st = self.state.lock();
        // SAFETY: the layer's own objects on a live device.
        unsafe { reclaim(d, &mut st, false) };
        if st.pending.is_empty() && st.uploads.is_empty() {
            return Ok(());
        }
        // SAFETY: a buffer of the layer's own on a live device, freed again on failure.
        let staging = unsafe { stage(own, &st.uploads) }?;
        let free_staging = |d: &ash::Device| {
            if let Some((b, m)) = staging {
                // SAFETY: the layer's own buffer, not in use (its copy was never submitted).
                unsafe {
                    d.destroy_buffer(b, None);
                    d.free_memory(m, None);
                }
            }
        };
        let pool = match st.pools.iter().find(|(f, _)| *f == family) {
            Some(&(_, p)) => Ok(p),
            None => {
                // SAFETY: a pool of the layer's own on a live device.
                match unsafe {
                    d.create_command_pool(
                        &vk::CommandPoolCreateInfo::default()
                            .queue_family_index(family)
                            .flags(vk::CommandPoolCreateFlags::TRANSIENT),
                        None,
                    )
                } {
                    Ok(p) => {
                        st.pools.push((family, p));
                        Ok(p)
                    }
                    Err(e) => Err(e),
                }
            }
        };
        let pool = match pool {
            Ok(p) => p,
            Err(e) => {
                free_staging(d);
                return Err(e);
            }
        };
        // SAFETY: a command buffer and fence of the layer's own, freed again on failure; the
        // shadows are live (pending ones are removed from the list before they are destroyed).
        unsafe {
            let cb = match d.allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool)
                    .level(vk::CommandBufferLevel::PRIMARY)
                    .command_buffer_count(1),
            ) {
                Ok(cbs) => cbs[0],
                Err(e) => {
                    free_staging(d);
                    return Err(e);
                }
            };
            let fence = std::cell::Cell::new(vk::Fence::null());
            let submitted = (|| -> Result<(), vk::Result> {
                own.set_loader_data(cb)?;
                d.begin_command_buffer(
                    cb,
                    &vk::CommandBufferBeginInfo::default()
                        .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
                )?;
                record(d, cb, &st.pending);
                if let Some((buffer, _)) = staging {
                    record_uploads(d, cb, buffer, &st.uploads);
                }
                d.end_command_buffer(cb)?;
                fence.set(d.create_fence(&vk::FenceCreateInfo::default(), None)?);
                let cbs = [cb];
                d.queue_submit(
                    queue,
                    &[vk::SubmitInfo::default().command_buffers(&cbs)],
                    fence.get(),
                )
            })();
            if let Err(e) = submitted {
                // A failed submit may leave the command buffer and fence counted as in use (the
                // validation layer does): drain the queue, which the layer may use here, inside
                // the application's submit, before freeing them, whatever that answers
                // (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkFreeCommandBuffers.html>).
                if fence.get() != vk::Fence::null() {
                    let _ = d.queue_wait_idle(queue);
                }
                d.free_command_buffers(pool, &[cb]);
                if fence.get() != vk::Fence::null() {
                    d.destroy_fence(fence.get(), None);
                }
                free_staging(d);
                return Err(e);
            }
            let shadows: Vec<vk::Image> = st.pending.drain(..).map(|(i, _)| i).collect();
            let uploads = st.uploads.len();
            st.uploads.clear();
            PENDING.fetch_sub(shadows.len() + uploads, Ordering::Release);
            tracing::debug!(
                queue = raw(queue),
                shadows = shadows.len(),
                uploads,
                "shadow clears and shading-rate uploads submitted ahead of the application's submit"
            );
            st.in_flight.push(InFlight {
                pool,
                cb,
                fence: fence.get(),
                shadows,
                retired: Vec::new(),
                staging,
            });
        }
        Ok(())
    }

    /// Frees everything at `vkDestroyDevice`.
    ///
    /// # Safety
    /// The device must be live and about to be destroyed, the application done with it.
    pub unsafe fn destroy(&self, d: &ash::Device) {
        let mut st = self.state.lock();
        PENDING.fetch_sub(st.pending.len() + st.uploads.len(), Ordering::Release);
        st.pending.clear();
        st.uploads.clear();
        // SAFETY: the layer's own objects; the application's work (after the clears on each
        // queue) is done.
        unsafe {
            reclaim(d, &mut st, true);
            for (_, p) in st.pools.drain(..) {
                d.destroy_command_pool(p, None);
            }
        }
    }
}

/// Frees the clears whose fences have signalled (all of them, after waiting, with `all`).
///
/// # Safety
/// The objects in `st` must belong to `d`'s live device.
unsafe fn reclaim(d: &ash::Device, st: &mut State, all: bool) {
    if st.in_flight.is_empty() {
        return;
    }
    if all {
        let fences: Vec<vk::Fence> = st.in_flight.iter().map(|f| f.fence).collect();
        // SAFETY: the layer's own fences.
        if let Err(e) = unsafe { d.wait_for_fences(&fences, true, DESTROY_WAIT_NS) } {
            tracing::warn!(result = ?e, "shadow clears still in flight at vkDestroyDevice");
        }
    }
    let mut i = 0;
    while i < st.in_flight.len() {
        let fence = st.in_flight[i].fence;
        // SAFETY: the layer's own fence.
        let status = (!all).then(|| unsafe { d.get_fence_status(fence) });
        let done = matches!(
            status,
            None | Some(Ok(true)) | Some(Err(vk::Result::ERROR_DEVICE_LOST))
        );
        if !done {
            i += 1;
            continue;
        }
        let f = st.in_flight.swap_remove(i);
        // SAFETY: the clear has completed; these are the layer's own objects.
        unsafe {
            d.free_command_buffers(f.pool, &[f.cb]);
            d.destroy_fence(f.fence, None);
            for (image, memory) in f.retired {
                d.destroy_image(image, None);
                d.free_memory(memory, None);
            }
            if let Some((buffer, memory)) = f.staging {
                d.destroy_buffer(buffer, None);
                d.free_memory(memory, None);
            }
        }
    }
}

/// Records the clear of every shadow in `pending` to rate code 0, ending in [`SHADOW_LAYOUT`].
///
/// # Safety
/// `cb` must be recording on `d`; the shadows live.
unsafe fn record(d: &ash::Device, cb: vk::CommandBuffer, pending: &[(vk::Image, u32)]) {
    // SAFETY: as the caller promised; new shadows have no earlier use to wait for.
    unsafe {
        write_shading_rate_images(
            d,
            cb,
            vk::PipelineStageFlags::TOP_OF_PIPE,
            pending.iter().copied(),
            || {
                for &(image, layers) in pending {
                    d.cmd_clear_color_image(
                        cb,
                        image,
                        vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                        &vk::ClearColorValue { uint32: [0; 4] },
                        &[color_range(layers)],
                    );
                }
            },
        )
    }
}

/// All `layers` of a colour image's one mip level.
fn color_range(layers: u32) -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange {
        aspect_mask: vk::ImageAspectFlags::COLOR,
        base_mip_level: 0,
        level_count: 1,
        base_array_layer: 0,
        layer_count: layers,
    }
}

/// Records `write` (transfer writes covering every image in `images`, each with its layers)
/// between a barrier that takes each image from `UNDEFINED` to `TRANSFER_DST_OPTIMAL` after the
/// `after` stage of earlier work, and one that moves it to [`SHADOW_LAYOUT`] for every later
/// command. ALL_COMMANDS stands for the shading-rate stage: some validation-layer releases take
/// that stage's bit for NVIDIA's shading-rate-image stage, which shares it, and refuse it without
/// that feature.
///
/// # Safety
/// `cb` must be recording on `d`; the images live; `write` records only transfer writes to them.
unsafe fn write_shading_rate_images(
    d: &ash::Device,
    cb: vk::CommandBuffer,
    after: vk::PipelineStageFlags,
    images: impl Iterator<Item = (vk::Image, u32)>,
    write: impl FnOnce(),
) {
    let to_dst: Vec<vk::ImageMemoryBarrier<'_>> = images
        .map(|(image, layers)| {
            vk::ImageMemoryBarrier::default()
                .image(image)
                .subresource_range(color_range(layers))
                .old_layout(vk::ImageLayout::UNDEFINED)
                .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .dst_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        })
        .collect();
    let to_rate: Vec<vk::ImageMemoryBarrier<'_>> = to_dst
        .iter()
        .map(|b| {
            b.old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .new_layout(SHADOW_LAYOUT)
                .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .dst_access_mask(vk::AccessFlags::MEMORY_READ)
        })
        .collect();
    // SAFETY: as the caller promised.
    unsafe {
        d.cmd_pipeline_barrier(
            cb,
            after,
            vk::PipelineStageFlags::TRANSFER,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &to_dst,
        );
        write();
        d.cmd_pipeline_barrier(
            cb,
            vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::ALL_COMMANDS,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &to_rate,
        );
    }
}

/// A host-visible staging buffer holding every upload's bytes, one after the other (`None` where
/// there are none).
///
/// # Safety
/// `own` must belong to a live device.
unsafe fn stage(
    own: &Own,
    uploads: &[Upload],
) -> Result<Option<(vk::Buffer, vk::DeviceMemory)>, vk::Result> {
    let size: usize = uploads.iter().map(|u| u.bytes.len()).sum();
    if size == 0 {
        return Ok(None);
    }
    let d = &own.fns;
    // SAFETY: the layer's own buffer and memory on a live device, each freed again on failure;
    // the mapping covers `size` bytes.
    unsafe {
        let buffer = d.create_buffer(
            &vk::BufferCreateInfo::default()
                .size(size as u64)
                .usage(vk::BufferUsageFlags::TRANSFER_SRC)
                .sharing_mode(vk::SharingMode::EXCLUSIVE),
            None,
        )?;
        let req = d.get_buffer_memory_requirements(buffer);
        let filled = (|| -> Result<vk::DeviceMemory, vk::Result> {
            let ty = own
                .host_memory_type(req.memory_type_bits)
                .ok_or(vk::Result::ERROR_OUT_OF_DEVICE_MEMORY)?;
            let memory = d.allocate_memory(
                &vk::MemoryAllocateInfo::default()
                    .allocation_size(req.size)
                    .memory_type_index(ty),
                None,
            )?;
            let mapped = d.bind_buffer_memory(buffer, memory, 0).and_then(|()| {
                d.map_memory(memory, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())
            });
            let ptr = match mapped {
                Ok(p) => p as *mut u8,
                Err(e) => {
                    d.free_memory(memory, None);
                    return Err(e);
                }
            };
            let mut at = 0;
            for u in uploads {
                std::ptr::copy_nonoverlapping(u.bytes.as_ptr(), ptr.add(at), u.bytes.len());
                at += u.bytes.len();
            }
            // Host-coherent memory is asked for ([`Own::host_memory_type`]): no flush needed, and
            // the submit makes host writes visible to the device.
            d.unmap_memory(memory);
            Ok(memory)
        })();
        match filled {
            Ok(memory) => Ok(Some((buffer, memory))),
            Err(e) => {
                d.destroy_buffer(buffer, None);
                Err(e)
            }
        }
    }
}

/// Records the copies of every upload from `buffer` (their bytes one after the other, as
/// [`stage`] wrote them), each image from `UNDEFINED` to [`SHADOW_LAYOUT`].
///
/// # Safety
/// `cb` must be recording on `d`; the images and `buffer` live.
unsafe fn record_uploads(
    d: &ash::Device,
    cb: vk::CommandBuffer,
    buffer: vk::Buffer,
    uploads: &[Upload],
) {
    // SAFETY: as the caller promised. ALL_COMMANDS first: passes submitted earlier on this queue
    // may still read the old map (a write-after-read hazard needs only this execution
    // dependency).
    unsafe {
        write_shading_rate_images(
            d,
            cb,
            vk::PipelineStageFlags::ALL_COMMANDS,
            uploads.iter().map(|u| (u.image, u.layers)),
            || {
                let mut at = 0u64;
                for u in uploads {
                    let layer_bytes = u64::from(u.extent[0]) * u64::from(u.extent[1]);
                    let regions: Vec<vk::BufferImageCopy> = (0..u.layers)
                        .map(|l| vk::BufferImageCopy {
                            buffer_offset: at + u64::from(l) * layer_bytes,
                            buffer_row_length: 0,
                            buffer_image_height: 0,
                            image_subresource: vk::ImageSubresourceLayers {
                                aspect_mask: vk::ImageAspectFlags::COLOR,
                                mip_level: 0,
                                base_array_layer: l,
                                layer_count: 1,
                            },
                            image_offset: vk::Offset3D::default(),
                            image_extent: vk::Extent3D {
                                width: u.extent[0],
                                height: u.extent[1],
                                depth: 1,
                            },
                        })
                        .collect();
                    d.cmd_copy_buffer_to_image(
                        cb,
                        buffer,
                        u.image,
                        vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                        &regions,
                    );
                    at += u.bytes.len() as u64;
                }
            },
        )
    }
}

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

/// Runs the pending clears ahead of a submit on `queue`: `Err` with the result the application's
/// submit must return instead of going down. One atomic load where nothing is pending.
///
/// # Safety
/// Called inside the application's submit on `queue`, a queue dispatched by the loader.
unsafe fn before_submit(what: &'static str, queue: vk::Queue) -> Result<(), vk::Result> {
    if PENDING.load(Ordering::Acquire) == 0 {
        return Ok(());
    }
    // SAFETY: as the caller promised.
    let Some(own) = (unsafe { crate::vk::image::own_of(queue) }) else {
        return Ok(());
    };
    // SAFETY: as the caller promised.
    unsafe { own.clears.flush(&own, queue) }.map_err(|e| {
        tracing::warn!(
            queue = raw(queue),
            result = ?e,
            "{what}: the layer could not clear new density maps' shadows or upload shading-rate \
             maps ahead of it; the submit fails with that result and they stay pending"
        );
        submit_result(e)
    })
}

/// `vkQueueSubmit`: pending clears first; wait-stage masks without the density-map stage, on a copy.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn queue_submit(
    queue: vk::Queue,
    count: u32,
    submits: *const vk::SubmitInfo<'_>,
    fence: vk::Fence,
) -> vk::Result {
    guard(
        "vkQueueSubmit",
        vk::Result::ERROR_OUT_OF_HOST_MEMORY,
        || {
            // SAFETY: a queue dispatched by the loader (or NULL).
            let Some(rec) = (unsafe { registry::recording(queue) }) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let Some(next) = rec.next.queue_submit else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            // SAFETY: inside the application's submit on `queue`.
            if let Err(e) = unsafe { before_submit("vkQueueSubmit", queue) } {
                return e;
            }
            // SAFETY: the caller's array of `count` submits.
            let list = unsafe { slice(submits, count) };
            // SAFETY: each submit's masks, valid for its wait count.
            let masks = |s: &vk::SubmitInfo<'_>| unsafe {
                slice(s.p_wait_dst_stage_mask, s.wait_semaphore_count)
            };
            if !list
                .iter()
                .any(|s| masks(s).iter().any(|&m| barrier::stage(m) != m))
            {
                // SAFETY: the next layer's function, with the caller's arguments.
                return unsafe { next(queue, count, submits, fence) };
            }
            let stages: Vec<Vec<vk::PipelineStageFlags>> = list
                .iter()
                .map(|s| masks(s).iter().map(|&m| barrier::stage(m)).collect())
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
            // SAFETY: the copies and their masks live across the call.
            unsafe { next(queue, count, copies.as_ptr(), fence) }
        },
    )
}

/// The semaphore infos of a submit with the density-map stage replaced, where any has it.
fn semaphores2<'a>(
    infos: &[vk::SemaphoreSubmitInfo<'a>],
) -> Option<Vec<vk::SemaphoreSubmitInfo<'a>>> {
    infos
        .iter()
        .any(|i| barrier::stage2(i.stage_mask) != i.stage_mask)
        .then(|| {
            infos
                .iter()
                .map(|i| vk::SemaphoreSubmitInfo {
                    stage_mask: barrier::stage2(i.stage_mask),
                    ..*i
                })
                .collect()
        })
}

/// The shared body of `vkQueueSubmit2` and its KHR alias.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn submit2(
    what: &'static str,
    pick: fn(&registry::Recording) -> Option<vk::PFN_vkQueueSubmit2>,
    queue: vk::Queue,
    count: u32,
    submits: *const vk::SubmitInfo2<'_>,
    fence: vk::Fence,
) -> vk::Result {
    guard(what, vk::Result::ERROR_OUT_OF_HOST_MEMORY, || {
        // SAFETY: a queue dispatched by the loader (or NULL).
        let Some(rec) = (unsafe { registry::recording(queue) }) else {
            return vk::Result::ERROR_INITIALIZATION_FAILED;
        };
        let Some(next) = pick(&rec) else {
            return vk::Result::ERROR_INITIALIZATION_FAILED;
        };
        // SAFETY: inside the application's submit on `queue`.
        if let Err(e) = unsafe { before_submit(what, queue) } {
            return e;
        }
        // SAFETY: the caller's array of `count` submits.
        let list = unsafe { slice(submits, count) };
        fn waits<'a>(s: &vk::SubmitInfo2<'a>) -> &'a [vk::SemaphoreSubmitInfo<'a>] {
            // SAFETY: the caller's array, valid for its count (the command's valid usage).
            unsafe { slice(s.p_wait_semaphore_infos, s.wait_semaphore_info_count) }
        }
        fn signals<'a>(s: &vk::SubmitInfo2<'a>) -> &'a [vk::SemaphoreSubmitInfo<'a>] {
            // SAFETY: as above.
            unsafe { slice(s.p_signal_semaphore_infos, s.signal_semaphore_info_count) }
        }
        let touched = |i: &[vk::SemaphoreSubmitInfo<'_>]| {
            i.iter()
                .any(|i| barrier::stage2(i.stage_mask) != i.stage_mask)
        };
        if !list
            .iter()
            .any(|s| touched(waits(s)) || touched(signals(s)))
        {
            // SAFETY: the next layer's function, with the caller's arguments.
            return unsafe { next(queue, count, submits, fence) };
        }
        let arrays: Vec<_> = list
            .iter()
            .map(|s| (semaphores2(waits(s)), semaphores2(signals(s))))
            .collect();
        let copies: Vec<vk::SubmitInfo2<'_>> = list
            .iter()
            .zip(&arrays)
            .map(|(s, (w, g))| {
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
        // SAFETY: the copies and their arrays live across the call.
        unsafe { next(queue, count, copies.as_ptr(), fence) }
    })
}

hook_and_khr_alias! {
    /// `vkQueueSubmit2`: pending clears first; semaphore stage masks without the density-map
    /// stage, on copies.
    queue_submit2, queue_submit2_khr = submit2("vkQueueSubmit2")
    (
        queue: vk::Queue,
        count: u32,
        submits: *const vk::SubmitInfo2<'_>,
        fence: vk::Fence,
    ) -> vk::Result
}

#[cfg(test)]
mod tests {
    use super::*;

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
