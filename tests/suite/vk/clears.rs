//! fovea's Vulkan layer and the application's queues: new shadows are cleared ahead of the
//! application's next submit, never inside `vkCreateImage`; a shadow that cannot be made fails
//! open; the density-map stage bits of submits and event sets reach the driver as shading-rate
//! ones.
//!
//! Stack as in [`crate::support::device`] (this test → fovea → validation → the double → lavapipe), on the
//! `nvidia` profile (16×16 texels). The double counts every `vkQueueSubmit` that reaches it, and at
//! each one reads back the shading-rate images its command buffers use. Validation must report
//! nothing but its 1.3.239 stage false positives
//! ([`crate::support::device::assert_only_stage_false_positives`]), which includes objects left alive at
//! `vkDestroyDevice` (a dropped clear's command buffer, a shadow that outlived its image) and
//! objects destroyed while in use (a shadow destroyed while its clear runs).

use ash::vk;
use fovea_vkdouble::Profile;
use serde_json::{json, Value};

use crate::support::device::{with_fovea, Dev, Env};
use crate::support::vulkan::{
    begin_pass, density_pass, framebuffer, range, COLOR, DENSITY, FDM_LAYOUT, SIZE,
};

/// The density map's side in texels (the `nvidia` profile's 16×16 texel).
const N: u32 = SIZE / 16;

/// What the tests here record with, on the shared test device ([`Dev`]).
impl Dev {
    /// A render pass v2 with a colour and a density-map attachment, and its framebuffer.
    fn pass(&self, color: &Image, density: &Image) -> (vk::RenderPass, vk::Framebuffer) {
        // SAFETY: structs live across the calls.
        unsafe {
            // The map is never written: its content is undefined when the pass begins, and it is
            // still in its initial layout.
            let pass = density_pass(
                &self.d,
                vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
                vk::ImageLayout::UNDEFINED,
            )
            .expect("vkCreateRenderPass2");
            let fb = framebuffer(&self.d, pass, &[color.view, density.view], SIZE);
            (pass, fb)
        }
    }

    /// Records an empty pass over the whole framebuffer.
    fn record_pass(&self, cb: vk::CommandBuffer, pass: vk::RenderPass, fb: vk::Framebuffer) {
        // SAFETY: `cb` is recording; the pass and framebuffer are alive.
        unsafe {
            begin_pass(&self.d, cb, pass, fb);
            self.d
                .cmd_end_render_pass2(cb, &vk::SubpassEndInfo::default());
        }
    }
}

struct Image {
    image: vk::Image,
    memory: vk::DeviceMemory,
    view: vk::ImageView,
}

impl Image {
    fn destroy(self, d: &ash::Device) {
        // SAFETY: nothing uses the image any more (the callers' promise, or on purpose: see the
        // test that destroys one while the layer's clear of its shadow may run).
        unsafe {
            d.destroy_image_view(self.view, None);
            d.destroy_image(self.image, None);
            d.free_memory(self.memory, None);
        }
    }
}

/// An image with device-local memory and a 2D view ([`Dev::image`]).
fn image(dev: &Dev, format: vk::Format, size: u32, usage: vk::ImageUsageFlags) -> Image {
    let (image, memory, view) = dev.image(format, size, 1, usage);
    Image {
        image,
        memory,
        view,
    }
}

fn color(dev: &Dev) -> Image {
    image(dev, COLOR, SIZE, vk::ImageUsageFlags::COLOR_ATTACHMENT)
}

fn density(dev: &Dev) -> Image {
    image(
        dev,
        DENSITY,
        N,
        vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT,
    )
}

/// The shading-rate images the double read back at the submit of `cb`.
fn read_at_submit(env: &Env, cb: vk::CommandBuffer) -> Vec<Value> {
    use ash::vk::Handle as _;
    let submits: Vec<Value> = env
        .double
        .events("submit")
        .into_iter()
        .filter(|s| {
            s["command_buffers"]
                .as_array()
                .is_some_and(|a| a.contains(&json!(cb.as_raw())))
        })
        .collect();
    assert_eq!(submits.len(), 1, "{submits:?}");
    submits[0]["shading_rate_images"]
        .as_array()
        .cloned()
        .unwrap_or_default()
}

fn assert_full_rate(read: &[Value], what: &str) {
    assert_eq!(read.len(), 1, "{what}: {read:?}");
    let codes = read[0]["codes"].as_array().expect("codes");
    assert!(!codes.is_empty(), "{what}");
    assert!(codes.iter().all(|c| c == 0), "{what}: {codes:?}");
}

/// `vkCreateImage` of a density map submits nothing; the application's next submit reaches the
/// driver after one clear of the layer's, whose shadow then reads rate code 0; later submits have
/// nothing ahead of them.
#[test]
fn shadows_are_cleared_ahead_of_the_next_submit_not_at_creation() {
    let Some((_serial, env, vk)) = with_fovea(Profile::Nvidia) else {
        return;
    };
    let dev = Dev::new(&vk, vk.fdm_device(&[], None));
    let (color, density) = (color(&dev), density(&dev));
    assert_eq!(
        env.double.calls("vkQueueSubmit"),
        0,
        "vkCreateImage of a density map used a queue"
    );
    let (pass, fb) = dev.pass(&color, &density);
    let cb = dev.begin();
    dev.record_pass(cb, pass, fb);
    dev.submit(cb);
    assert_eq!(
        env.double.calls("vkQueueSubmit"),
        2,
        "the layer's clear, then the application's submit"
    );
    assert_full_rate(&read_at_submit(env, cb), "first submit");
    let again = dev.begin();
    dev.record_pass(again, pass, fb);
    dev.submit(again);
    assert_eq!(
        env.double.calls("vkQueueSubmit"),
        3,
        "nothing pending: nothing ahead"
    );
    assert_full_rate(&read_at_submit(env, again), "second submit");
    // SAFETY: the queue is idle; each object is destroyed once.
    unsafe {
        dev.d.destroy_framebuffer(fb, None);
        dev.d.destroy_render_pass(pass, None);
    }
    density.destroy(&dev.d);
    color.destroy(&dev.d);
    dev.finish(env, vk);
}

/// A density map destroyed before any submit drops its clear: the next submit is the
/// application's alone, and nothing is left at `vkDestroyDevice`. One destroyed right after the
/// submit that carried its clear (not waited for) outlives the clear; validation would report a
/// shadow destroyed in use.
#[test]
fn destroyed_density_maps_drop_or_outlive_their_clears() {
    let Some((_serial, env, vk)) = with_fovea(Profile::Nvidia) else {
        return;
    };
    let dev = Dev::new(&vk, vk.fdm_device(&[], None));
    density(&dev).destroy(&dev.d);
    let cb = dev.begin();
    dev.submit(cb);
    assert_eq!(
        env.double.calls("vkQueueSubmit"),
        1,
        "a dropped clear was submitted"
    );

    let map = density(&dev);
    let cb = dev.begin();
    // SAFETY: recording; the queue is this thread's. The submit is not waited for before the
    // density map is destroyed: its work does not use the map, the layer's clear ahead of it does.
    unsafe {
        dev.d.end_command_buffer(cb).expect("end");
        let cbs = [cb];
        dev.d
            .queue_submit(
                dev.queue,
                &[vk::SubmitInfo::default().command_buffers(&cbs)],
                vk::Fence::null(),
            )
            .expect("vkQueueSubmit");
    }
    map.destroy(&dev.d);
    assert_eq!(env.double.calls("vkQueueSubmit"), 3, "the clear went ahead");
    dev.finish(env, vk);
}

/// Fail open: the shadow's memory (the second `vkAllocateMemory` below fovea: the colour image's
/// is the first) cannot be had. The density map's `vkCreateImage` and `vkCreateImageView` succeed
/// all the same, the framebuffer gets a full-rate stand-in (rate code 0), and validation says
/// nothing: the driver never sees the density view as a shading-rate attachment.
#[test]
fn a_shadow_that_cannot_be_made_leaves_the_image_at_full_rate() {
    let Some((_serial, env, vk)) = with_fovea(Profile::Nvidia) else {
        return;
    };
    let dev = Dev::new(&vk, vk.fdm_device(&[], None));
    let color = color(&dev);
    // Counted since the instance (colour image, density map, shadow), then since each clear of
    // the records (density map, shadow; the shadow's memory comes before the map's).
    for (call, nth) in [("vkCreateImage", 2), ("vkAllocateMemory", 0)] {
        env.double
            .fail(call, nth, vk::Result::ERROR_OUT_OF_DEVICE_MEMORY);
        let density = density(&dev);
        assert!(
            env.double.calls(call) > nth,
            "{call}: the fault did not fire"
        );
        let (pass, fb) = dev.pass(&color, &density);
        let cb = dev.begin();
        dev.record_pass(cb, pass, fb);
        dev.submit(cb);
        let begins = env.double.events("begin_render_pass");
        let views = begins.last().expect("a begin")["shading_rate_views"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        assert_eq!(views.len(), 1, "{call}: {begins:?}");
        assert_ne!(
            views[0],
            json!(vk::Handle::as_raw(density.view)),
            "{call}: the density view reached the driver as a shading-rate attachment"
        );
        assert_full_rate(&read_at_submit(env, cb), call);
        // SAFETY: the queue is idle; each object is destroyed once.
        unsafe {
            dev.d.destroy_framebuffer(fb, None);
            dev.d.destroy_render_pass(pass, None);
        }
        density.destroy(&dev.d);
        crate::support::device::assert_no_double_errors(env);
        env.double.clear();
    }
    color.destroy(&dev.d);
    dev.finish(env, vk);
}

/// Density-map stage and access bits in a semaphore wait (`vkQueueSubmit`'s `pWaitDstStageMask`,
/// `vkQueueSubmit2`'s `VkSemaphoreSubmitInfo`) and in `vkCmdSetEvent2`'s dependency info reach
/// the driver as the shading-rate ones: validation refuses the density-map bits on a device without
/// density maps, and says nothing here.
#[test]
fn submits_and_event_sets_lose_the_density_map_bits() {
    let Some((_serial, env, vk)) = with_fovea(Profile::Nvidia) else {
        return;
    };
    let dev = Dev::new(&vk, vk.fdm_device(&[], None));
    let map = density(&dev);
    // SAFETY: every struct lives across its call; the queue is this thread's and idle at the end.
    unsafe {
        let d = &dev.d;
        let semaphore = d
            .create_semaphore(&vk::SemaphoreCreateInfo::default(), None)
            .expect("vkCreateSemaphore");
        let event = d
            .create_event(&vk::EventCreateInfo::default(), None)
            .expect("vkCreateEvent");
        let cb = dev.begin();
        let barriers = [vk::ImageMemoryBarrier2::default()
            .image(map.image)
            .subresource_range(range(0, 1))
            .old_layout(vk::ImageLayout::UNDEFINED)
            .new_layout(FDM_LAYOUT)
            .src_stage_mask(vk::PipelineStageFlags2::TOP_OF_PIPE)
            .dst_stage_mask(vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT)
            .dst_access_mask(vk::AccessFlags2::FRAGMENT_DENSITY_MAP_READ_EXT)];
        let dependency = vk::DependencyInfo::default().image_memory_barriers(&barriers);
        d.cmd_set_event2(cb, event, &dependency);
        d.cmd_wait_events2(cb, &[event], &[dependency]);
        d.end_command_buffer(cb).expect("end");
        // Signal the semaphore, then wait for it at the density stage (v1), twice over (v2).
        let signal = [semaphore];
        d.queue_submit(
            dev.queue,
            &[vk::SubmitInfo::default().signal_semaphores(&signal)],
            vk::Fence::null(),
        )
        .expect("signal");
        let masks = [vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT
            | vk::PipelineStageFlags::FRAGMENT_SHADER];
        let cbs = [cb];
        let wait = vk::SubmitInfo::default()
            .wait_semaphores(&signal)
            .wait_dst_stage_mask(&masks)
            .command_buffers(&cbs)
            .signal_semaphores(&signal);
        d.queue_submit(dev.queue, &[wait], vk::Fence::null())
            .expect("vkQueueSubmit with a density-stage wait");
        let waits = [vk::SemaphoreSubmitInfo::default()
            .semaphore(semaphore)
            .stage_mask(vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT)];
        d.queue_submit2(
            dev.queue,
            &[vk::SubmitInfo2::default().wait_semaphore_infos(&waits)],
            vk::Fence::null(),
        )
        .expect("vkQueueSubmit2 with a density-stage wait");
        d.queue_wait_idle(dev.queue).expect("idle");
        assert_eq!(
            masks[0],
            vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT
                | vk::PipelineStageFlags::FRAGMENT_SHADER,
            "the application's mask is kept"
        );
        assert_eq!(
            waits[0].stage_mask,
            vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT
        );
        d.destroy_event(event, None);
        d.destroy_semaphore(semaphore, None);
    }
    map.destroy(&dev.d);
    dev.finish(env, vk);
}
