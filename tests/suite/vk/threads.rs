//! fovea's Vulkan layer on lavapipe, from several threads at once: [`WORKERS`] threads record
//! command buffers through the layer concurrently, each from its own command pool, while another
//! thread creates and destroys density-map images and views in a loop.
//!
//! Stack as in [`crate::support::device`], on the `nvidia` profile. Each iteration of a worker records, in
//! one command buffer: an image barrier with density-map bits (`vkCmdPipelineBarrier`), a render
//! pass v2 with a density attachment on a framebuffer holding the density view, dynamic rendering
//! with `VkRenderingFragmentDensityMapAttachmentInfoEXT`, and a synchronization2 barrier with
//! density-map bits. At the end each worker submits its last command buffer (serially, under a
//! mutex: a `VkQueue` needs external synchronisation) and waits for it.
//!
//! Density maps are made without holding the queue's mutex while the workers submit: the layer
//! must not use the queue inside `vkCreateImage` (it clears new shadows ahead of the application's
//! next submit instead, `src/vk/own/calls.rs`). A layer that did would make validation's thread checks
//! report `vkQueueSubmit` on one queue from two threads at once. Shadows destroyed before any
//! submit drop their clear, ones destroyed while it runs outlive it; validation's object tracker
//! reports anything left at `vkDestroyDevice`.
//!
//! - No deadlock: a watchdog ends the process with a failure after [`DEADLINE`].
//! - No crash, the double records no misuse, and validation reports nothing but validation
//!   1.3.239's stage false positives ([`crate::support::device::assert_only_stage_false_positives`]).
//! - Every pass and rendering reached the driver with a shading-rate attachment.
//!
//! `FOVEA_THREADS_ITERATIONS` sets the iterations per worker (default 200), e.g. for a run under
//! valgrind (`.ci/valgrind`).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use ash::vk;
use fovea_vkdouble::Profile;

use crate::support::device::{
    assert_only_stage_false_positives, fdm_image_info, take_messages, with_fovea,
};
use crate::support::vulkan::{
    allocate_info, density_pass, framebuffer, image_info, range, COLOR, DENSITY, FDM_LAYOUT, SIZE,
};

const WORKERS: usize = 4;
/// The whole run must end within this (debug build, two shared cores, or valgrind).
const DEADLINE: Duration = Duration::from_secs(300);
/// The colour attachment's width and height; the density map has one texel per 16×16.
const COLOR_LAYOUT: vk::ImageLayout = vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL;

fn iterations() -> u64 {
    std::env::var("FOVEA_THREADS_ITERATIONS")
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(200)
}

/// An image with memory bound, and a 2D view of its first layer.
struct Image {
    image: vk::Image,
    memory: vk::DeviceMemory,
    view: vk::ImageView,
}

impl Image {
    /// # Safety
    /// `d` must be alive; `memory` its physical device's.
    unsafe fn new(
        d: &ash::Device,
        memory: &vk::PhysicalDeviceMemoryProperties,
        info: &vk::ImageCreateInfo<'_>,
    ) -> Image {
        // SAFETY: the caller's promise; the structs live across the calls.
        unsafe {
            let image = d.create_image(info, None).expect("vkCreateImage");
            let req = d.get_image_memory_requirements(image);
            // The first memory type the image allows, whatever its properties.
            let memory = d
                .allocate_memory(
                    &allocate_info(memory, req, vk::MemoryPropertyFlags::empty()),
                    None,
                )
                .expect("vkAllocateMemory");
            d.bind_image_memory(image, memory, 0)
                .expect("vkBindImageMemory");
            let view = d
                .create_image_view(
                    &vk::ImageViewCreateInfo::default()
                        .image(image)
                        .view_type(vk::ImageViewType::TYPE_2D)
                        .format(info.format)
                        .subresource_range(range(0, 1)),
                    None,
                )
                .expect("vkCreateImageView");
            Image {
                image,
                memory,
                view,
            }
        }
    }

    /// # Safety
    /// Nothing may use the image any more.
    unsafe fn destroy(self, d: &ash::Device) {
        // SAFETY: the caller's promise.
        unsafe {
            d.destroy_image_view(self.view, None);
            d.destroy_image(self.image, None);
            d.free_memory(self.memory, None);
        }
    }
}

/// A colour + density pass, version 2; the colour attachment ends in `COLOR_LAYOUT` for the
/// dynamic rendering that follows it.
///
/// # Safety
/// `d` must be alive.
unsafe fn render_pass(d: &ash::Device) -> vk::RenderPass {
    // SAFETY: the caller's promise.
    unsafe { density_pass(d, COLOR_LAYOUT, FDM_LAYOUT) }
        .unwrap_or_else(|e| panic!("vkCreateRenderPass2: {e}; {:?}", take_messages()))
}

/// One worker's objects: its images, pass, framebuffer and command pool.
struct Worker {
    color: Image,
    density: Image,
    pass: vk::RenderPass,
    framebuffer: vk::Framebuffer,
    pool: vk::CommandPool,
}

impl Worker {
    /// # Safety
    /// `d` must be alive; `memory` its physical device's.
    unsafe fn new(d: &ash::Device, memory: &vk::PhysicalDeviceMemoryProperties) -> Worker {
        // SAFETY: the caller's promise; the structs live across the calls.
        unsafe {
            let color = Image::new(
                d,
                memory,
                &image_info(COLOR, SIZE, 1, vk::ImageUsageFlags::COLOR_ATTACHMENT),
            );
            let density = Image::new(
                d,
                memory,
                &image_info(
                    DENSITY,
                    SIZE / 16,
                    1,
                    vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT
                        | vk::ImageUsageFlags::TRANSFER_DST,
                ),
            );
            let pass = render_pass(d);
            let framebuffer = framebuffer(d, pass, &[color.view, density.view], SIZE);
            let pool = d
                .create_command_pool(
                    &vk::CommandPoolCreateInfo::default().queue_family_index(0),
                    None,
                )
                .expect("vkCreateCommandPool");
            Worker {
                color,
                density,
                pass,
                framebuffer,
                pool,
            }
        }
    }

    /// One iteration's command buffer, recorded and ended.
    ///
    /// # Safety
    /// `d` must be alive; only this thread uses the worker's pool.
    unsafe fn record(&self, d: &ash::Device) -> vk::CommandBuffer {
        let area = vk::Rect2D {
            offset: vk::Offset2D { x: 0, y: 0 },
            extent: vk::Extent2D {
                width: SIZE,
                height: SIZE,
            },
        };
        // SAFETY: the caller's promise; every struct lives across its call.
        unsafe {
            let cb = d
                .allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default()
                        .command_pool(self.pool)
                        .command_buffer_count(1),
                )
                .expect("vkAllocateCommandBuffers")[0];
            d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
                .expect("vkBeginCommandBuffer");
            // The application writes its density map (full density; a map left undefined would
            // hand the layer's conversion undefined bytes), then moves it into its layout for the
            // pass: density-map stage and access.
            let to_dst = vk::ImageMemoryBarrier::default()
                .image(self.density.image)
                .subresource_range(range(0, 1))
                .old_layout(vk::ImageLayout::UNDEFINED)
                .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .dst_access_mask(vk::AccessFlags::TRANSFER_WRITE);
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TOP_OF_PIPE,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[to_dst],
            );
            d.cmd_clear_color_image(
                cb,
                self.density.image,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &vk::ClearColorValue {
                    float32: [1.0, 1.0, 0.0, 0.0],
                },
                &[range(0, 1)],
            );
            let to_fdm = vk::ImageMemoryBarrier::default()
                .image(self.density.image)
                .subresource_range(range(0, 1))
                .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .new_layout(FDM_LAYOUT)
                .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .dst_access_mask(vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT);
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[to_fdm],
            );
            let clear = [vk::ClearValue::default(), vk::ClearValue::default()];
            d.cmd_begin_render_pass2(
                cb,
                &vk::RenderPassBeginInfo::default()
                    .render_pass(self.pass)
                    .framebuffer(self.framebuffer)
                    .render_area(area)
                    .clear_values(&clear),
                &vk::SubpassBeginInfo::default().contents(vk::SubpassContents::INLINE),
            );
            d.cmd_end_render_pass2(cb, &vk::SubpassEndInfo::default());
            let color = [vk::RenderingAttachmentInfo::default()
                .image_view(self.color.view)
                .image_layout(COLOR_LAYOUT)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::STORE)];
            let mut density = vk::RenderingFragmentDensityMapAttachmentInfoEXT::default()
                .image_view(self.density.view)
                .image_layout(FDM_LAYOUT);
            d.cmd_begin_rendering(
                cb,
                &vk::RenderingInfo::default()
                    .render_area(area)
                    .layer_count(1)
                    .color_attachments(&color)
                    .push_next(&mut density),
            );
            d.cmd_end_rendering(cb);
            // Synchronization2: the density map read by the next frame's density processing.
            let again = [vk::ImageMemoryBarrier2::default()
                .image(self.density.image)
                .subresource_range(range(0, 1))
                .old_layout(FDM_LAYOUT)
                .new_layout(FDM_LAYOUT)
                .src_stage_mask(vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT)
                .src_access_mask(vk::AccessFlags2::FRAGMENT_DENSITY_MAP_READ_EXT)
                .dst_stage_mask(vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT)
                .dst_access_mask(vk::AccessFlags2::FRAGMENT_DENSITY_MAP_READ_EXT)];
            d.cmd_pipeline_barrier2(
                cb,
                &vk::DependencyInfo::default().image_memory_barriers(&again),
            );
            d.end_command_buffer(cb).expect("vkEndCommandBuffer");
            cb
        }
    }

    /// # Safety
    /// Nothing made from the worker may be in use.
    unsafe fn destroy(self, d: &ash::Device) {
        // SAFETY: the caller's promise.
        unsafe {
            d.destroy_command_pool(self.pool, None);
            d.destroy_framebuffer(self.framebuffer, None);
            d.destroy_render_pass(self.pass, None);
            self.color.destroy(d);
            self.density.destroy(d);
        }
    }
}

/// Recording on four threads, each with its own pool, and density images made and destroyed on a
/// fifth: no deadlock, no crash, no misuse seen by the double, and validation silent but for its
/// known false positive.
#[test]
fn recording_on_four_threads_while_density_images_come_and_go() {
    let Some((_serial, env, vk)) = with_fovea(Profile::Nvidia) else {
        return;
    };
    let d = vk.fdm_device(&[], None);
    // SAFETY: plain queries on live objects.
    let (memory, queue) = unsafe {
        (
            vk.instance
                .get_physical_device_memory_properties(vk.physical),
            d.get_device_queue(0, 0),
        )
    };
    let iterations = iterations();
    let queue = Mutex::new(queue);
    let done = AtomicBool::new(false);
    let made = AtomicU64::new(0);
    let start = Instant::now();
    std::thread::scope(|s| {
        let (d, memory, queue, done, made) = (&d, &memory, &queue, &done, &made);
        // The watchdog: a deadlock ends the process with a failure instead of hanging the suite.
        let watchdog = s.spawn(move || {
            while start.elapsed() < DEADLINE {
                if done.load(Ordering::Acquire) {
                    return;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            eprintln!("vk_threads: not finished after {DEADLINE:?}: deadlock");
            std::process::exit(101);
        });
        // Density images and views made and destroyed until the workers are done.
        let churn = s.spawn(move || {
            while !done.load(Ordering::Acquire) {
                // SAFETY: the device is alive; the image is this thread's alone. The queue is not
                // held: making a density map uses no queue (see the module's documentation).
                unsafe {
                    let image = Image::new(d, memory, &fdm_image_info());
                    image.destroy(d);
                }
                made.fetch_add(1, Ordering::Relaxed);
            }
        });
        let workers: Vec<_> = (0..WORKERS)
            .map(|_| {
                s.spawn(move || {
                    // SAFETY: the device is alive; the worker's objects are this thread's alone,
                    // its pool used by no other thread; the command buffer is submitted under the
                    // queue's mutex and waited for before anything is destroyed.
                    unsafe {
                        let w = Worker::new(d, memory);
                        let mut last = vk::CommandBuffer::null();
                        for _ in 0..iterations {
                            if last != vk::CommandBuffer::null() {
                                d.free_command_buffers(w.pool, &[last]);
                            }
                            last = w.record(d);
                        }
                        {
                            let queue = queue.lock().unwrap_or_else(|e| e.into_inner());
                            let cbs = [last];
                            d.queue_submit(
                                *queue,
                                &[vk::SubmitInfo::default().command_buffers(&cbs)],
                                vk::Fence::null(),
                            )
                            .expect("vkQueueSubmit");
                            d.queue_wait_idle(*queue).expect("vkQueueWaitIdle");
                        }
                        w.destroy(d);
                    }
                })
            })
            .collect();
        let panics = workers
            .into_iter()
            .map(|w| w.join())
            .filter(Result::is_err)
            .count();
        done.store(true, Ordering::Release);
        let churned = churn.join().is_ok();
        watchdog.join().expect("watchdog");
        assert_eq!(panics, 0, "workers panicked");
        assert!(churned, "the image thread panicked");
    });
    eprintln!(
        "vk_threads: {WORKERS} threads × {iterations} iterations, {} density images made meanwhile, in {:?}",
        made.load(Ordering::Relaxed),
        start.elapsed()
    );
    // SAFETY: every object made from the device is destroyed; the queue is idle.
    unsafe { d.destroy_device(None) };
    assert_eq!(env.double.errors(), Vec::<String>::new());
    // Every pass and every rendering reached the driver with a shading-rate attachment.
    let passes = env.double.events("begin_render_pass");
    assert_eq!(passes.len() as u64, WORKERS as u64 * iterations);
    for p in &passes {
        let v = p["shading_rate_views"].as_array().expect("views");
        assert_eq!(v.len(), 1, "{p}");
    }
    let renderings = env.double.events("begin_rendering");
    assert_eq!(renderings.len() as u64, WORKERS as u64 * iterations);
    for r in &renderings {
        assert!(!r["shading_rate"].is_null(), "{r}");
    }
    drop(vk);
    assert_only_stage_false_positives();
}
