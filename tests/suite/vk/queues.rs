//! fovea's writes of its shading-rate images and the application's several graphics queues: a
//! shadow's clear (or a map's upload) runs ahead of whichever graphics queue submits next, and a
//! pass submitted on another queue is ordered after it (docs/vulkan-layer.md#uploads-and-several-queues).
//!
//! Stack as in [`crate::support::device`] (this test → fovea → validation with synchronization
//! validation → the double → lavapipe), on the `nvidia` profile, with the double offering two
//! queues of family 0 (lavapipe has one; the second stands for it, `crates/vkdouble/src/layer/queues.rs`).
//! Validation sees two queues and checks, at each submit, hazards between them (validation
//! 1.4.309 in the Debian 13 root does; 1.3.239 on Debian 12 checks submits on one queue only, so
//! there these tests show the rates and an absence of other messages). Without the ordering,
//! validation 1.4.309 reports the pass's read of the shadow racing the clear on the other queue.

use ash::vk;
use fovea_vkdouble::Profile;
use serde_json::{json, Value};

use crate::support::device::{env, take_real_messages, Dev, Env, Features, Vk};
use crate::support::vulkan::{begin_pass, density_pass, framebuffer, COLOR, DENSITY, SIZE};

/// The density map's side in texels (the `nvidia` profile's 16×16 texel).
const N: u32 = SIZE / 16;

/// The double offers two queues of family 0 while this lives (set before the instance: validation
/// reads the queue families when it sees the physical device).
struct TwoQueues<'a>(&'a Env);

impl<'a> TwoQueues<'a> {
    fn new(env: &'a Env) -> TwoQueues<'a> {
        env.double.set_queues(2);
        TwoQueues(env)
    }
}

impl Drop for TwoQueues<'_> {
    fn drop(&mut self) {
        self.0.double.set_queues(0);
    }
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

/// How the application submits in [`a_shadow_cleared_on_one_queue_is_ordered_before_a_pass_on_another`].
#[derive(Clone, Copy, Debug)]
enum Submit {
    V1,
    V2,
}

/// Submits `cb` on `queue` without a fence or semaphores.
fn submit(d: &ash::Device, how: Submit, queue: vk::Queue, cb: vk::CommandBuffer) {
    // SAFETY: `cb` is executable on `d`; the structs live across the call.
    unsafe {
        match how {
            Submit::V1 => {
                let cbs = [cb];
                d.queue_submit(
                    queue,
                    &[vk::SubmitInfo::default().command_buffers(&cbs)],
                    vk::Fence::null(),
                )
            }
            Submit::V2 => {
                let cbs = [vk::CommandBufferSubmitInfo::default().command_buffer(cb)];
                d.queue_submit2(
                    queue,
                    &[vk::SubmitInfo2::default().command_buffer_infos(&cbs)],
                    vk::Fence::null(),
                )
            }
        }
    }
    .expect("vkQueueSubmit");
}

/// A new density map's shadow is cleared ahead of the next submit on a graphics queue: here an
/// unrelated one on queue 0. A pass that reads the map, submitted next on queue 1 with nothing
/// of the application's between the two (it shares nothing with the first), must see the cleared
/// shadow: full rate at the driver, and no hazard between the queues for validation.
#[test]
fn a_shadow_cleared_on_one_queue_is_ordered_before_a_pass_on_another() {
    for how in [Submit::V1, Submit::V2] {
        let Some((_serial, env)) = env() else {
            return;
        };
        let _two = TwoQueues::new(env);
        let Some(vk) = Vk::new(env, Profile::Nvidia, true) else {
            return;
        };
        let d = vk
            .try_device_queues(&[], Features::FDM, None, 2)
            .unwrap_or_else(|e| panic!("vkCreateDevice with two queues: {e}"));
        let dev = Dev::new(&vk, d);
        // SAFETY: the device is alive; every struct lives across its call; every object made here
        // is destroyed before the device.
        unsafe {
            let q1 = dev.d.get_device_queue(0, 1);
            assert_ne!(q1, dev.queue, "two queues");
            let (color_image, color_memory, color) =
                dev.image(COLOR, SIZE, 1, vk::ImageUsageFlags::COLOR_ATTACHMENT);
            let (map_image, map_memory, map) =
                dev.image(DENSITY, N, 1, vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT);
            let pass = density_pass(
                &dev.d,
                vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
                vk::ImageLayout::UNDEFINED,
            )
            .expect("vkCreateRenderPass2");
            let fb = framebuffer(&dev.d, pass, &[color, map], SIZE);
            let cb = dev.begin();
            begin_pass(&dev.d, cb, pass, fb);
            dev.d
                .cmd_end_render_pass2(cb, &vk::SubpassEndInfo::default());
            dev.d.end_command_buffer(cb).expect("vkEndCommandBuffer");
            let other = dev.begin();
            dev.d.end_command_buffer(other).expect("vkEndCommandBuffer");
            submit(&dev.d, how, dev.queue, other);
            submit(&dev.d, how, q1, cb);
            dev.d.device_wait_idle().expect("vkDeviceWaitIdle");
            let read = read_at_submit(env, cb);
            assert_eq!(read.len(), 1, "{how:?}: {read:?}");
            let codes = read[0]["codes"].as_array().expect("codes");
            assert!(
                !codes.is_empty() && codes.iter().all(|c| c == 0),
                "{how:?}: the pass on queue 1 reads the cleared shadow: {codes:?}"
            );
            let messages = take_real_messages();
            assert!(
                messages.is_empty(),
                "{how:?}: validation reported: {messages:#?}"
            );
            dev.d.destroy_framebuffer(fb, None);
            dev.d.destroy_render_pass(pass, None);
            for (i, m, v) in [
                (color_image, color_memory, color),
                (map_image, map_memory, map),
            ] {
                dev.d.destroy_image_view(v, None);
                dev.d.destroy_image(i, None);
                dev.d.free_memory(m, None);
            }
        }
        dev.finish(env, vk);
    }
}

/// The positions, in the order the driver got them, of the submits of `cbs`.
fn driver_order(env: &Env, cbs: &[vk::CommandBuffer]) -> Vec<usize> {
    use ash::vk::Handle as _;
    let submits = env.double.events("submit");
    cbs.iter()
        .map(|cb| {
            submits
                .iter()
                .position(|s| {
                    s["command_buffers"]
                        .as_array()
                        .is_some_and(|a| a.contains(&json!(cb.as_raw())))
                })
                .expect("submitted")
        })
        .collect()
}

/// Reconstructions of coarse blocks (docs/reconstruction.md#queues) go into the application's
/// command buffers and use one scratch buffer per target size, the device's: two of them on two
/// queues at once would write and read the same scratch. The double runs its queues' work one
/// submission at a time (it cannot show the corrupt pixels of a real overlap), but it runs work
/// the application did not order in the order that exposes a missing dependency: a submission on
/// queue 1 is held back and one on queue 0 that waits on nothing overtakes it. Here two command
/// buffers each reconstruct a subsampled image of the same size (so the same scratch), the first
/// submitted on queue 1, the second on queue 0 with nothing of the application's between them:
/// the driver must get the first before the second (fovea's wait on queue 1's last submission),
/// and validation must report nothing. Without the ordering the second overtakes the first.
#[test]
fn reconstructions_on_two_queues_run_in_submission_order() {
    for how in [Submit::V1, Submit::V2] {
        let Some((_serial, env)) = env() else {
            return;
        };
        let _two = TwoQueues::new(env);
        let Some(vk) = Vk::new(env, Profile::Nvidia, true) else {
            return;
        };
        let d = vk
            .try_device_queues(&[], Features::FDM, None, 2)
            .unwrap_or_else(|e| panic!("vkCreateDevice with two queues: {e}"));
        let dev = Dev::new(&vk, d);
        // SAFETY: the device is alive; every struct lives across its call; every object made here
        // is destroyed before the device.
        unsafe {
            let q1 = dev.d.get_device_queue(0, 1);
            assert_ne!(q1, dev.queue, "two queues");
            let targets: Vec<_> = (0..2)
                .map(|_| {
                    dev.image_with_flags(
                        COLOR,
                        SIZE,
                        1,
                        vk::ImageUsageFlags::COLOR_ATTACHMENT,
                        vk::ImageCreateFlags::SUBSAMPLED_EXT,
                    )
                })
                .collect();
            let (map_image, map_memory, map) =
                dev.image(DENSITY, N, 1, vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT);
            let pass = density_pass(
                &dev.d,
                vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
                vk::ImageLayout::UNDEFINED,
            )
            .expect("vkCreateRenderPass2");
            let fbs: Vec<_> = targets
                .iter()
                .map(|&(_, _, v)| framebuffer(&dev.d, pass, &[v, map], SIZE))
                .collect();
            let cbs: Vec<_> = fbs
                .iter()
                .map(|&fb| {
                    let cb = dev.begin();
                    begin_pass(&dev.d, cb, pass, fb);
                    dev.d
                        .cmd_end_render_pass2(cb, &vk::SubpassEndInfo::default());
                    dev.d.end_command_buffer(cb).expect("vkEndCommandBuffer");
                    cb
                })
                .collect();
            // The map's shadow is cleared ahead of the first submit; each queue waits for that
            // once, here, so that nothing of the layer's uploads orders the submits below.
            for q in [dev.queue, q1] {
                let warm = dev.begin();
                dev.d.end_command_buffer(warm).expect("vkEndCommandBuffer");
                submit(&dev.d, how, q, warm);
            }
            dev.d.device_wait_idle().expect("vkDeviceWaitIdle");
            submit(&dev.d, how, q1, cbs[0]);
            submit(&dev.d, how, dev.queue, cbs[1]);
            dev.d.device_wait_idle().expect("vkDeviceWaitIdle");
            let order = driver_order(env, &cbs);
            assert!(
                order[0] < order[1],
                "{how:?}: the reconstruction submitted second (queue 0) reached the driver \
                 before the first (queue 1): {order:?}"
            );
            let messages = take_real_messages();
            assert!(
                messages.is_empty(),
                "{how:?}: validation reported: {messages:#?}"
            );
            for fb in fbs {
                dev.d.destroy_framebuffer(fb, None);
            }
            dev.d.destroy_render_pass(pass, None);
            for (i, m, v) in targets.into_iter().chain([(map_image, map_memory, map)]) {
                dev.d.destroy_image_view(v, None);
                dev.d.destroy_image(i, None);
                dev.d.free_memory(m, None);
            }
        }
        dev.finish(env, vk);
    }
}
