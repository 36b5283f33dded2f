//! Fault injection through fovea's Vulkan layer: the layer below fails each call in turn.
//!
//! Stack as in `vk::layer`: this test → fovea → VK_LAYER_KHRONOS_validation → the double →
//! lavapipe. The double ([`fovea_vkdouble::Loaded::fail`]) makes one call return
//! `VK_ERROR_OUT_OF_DEVICE_MEMORY` or `VK_ERROR_OUT_OF_HOST_MEMORY` without reaching lavapipe.
//! Since it sits below validation, the calls fovea makes for itself (a density map's shadow: image,
//! memory, clear) fail there too. One application flow with fragment density maps (device, density
//! image, view, render pass v2, framebuffer, pipeline, command buffer with barriers, a copy and a
//! draw, submit, wait, teardown) runs once per call it makes, with that call failing. Each run must
//! end one of these ways:
//! - the application's call fails with the injected result, unchanged, and the flow stops there
//!   (fovea's own submit of the shadows' clear, made inside the application's `vkQueueSubmit`,
//!   counts as that call);
//! - fovea's own call failed and it failed open: the flow completes as if nothing happened; for a
//!   density map's shadow (or its view) that means the image and view are the application's alone
//!   and the framebuffer gets a full-rate stand-in;
//! - fovea's own call to record the shadows' clear failed: the application's next `vkQueueSubmit`
//!   fails with that result (its work would read shadows in an undefined layout otherwise).
//!
//! Either way validation stays silent (but for its 1.3.239 stage false positive, see
//! `vk::layer::assert_only_stage_false_positives`), which includes its object tracker's reports of objects
//! left alive at `vkDestroyDevice` and `vkDestroyInstance`
//! (<https://vulkan.lunarg.com/doc/sdk/latest/linux/khronos_validation_layer.html>): nothing
//! fovea made leaks, nothing is destroyed twice.

use std::collections::BTreeMap;

use ash::vk;
use fovea_vkdouble::Profile;

use crate::support::device::{
    assert_only_stage_false_positives, env, take_real_messages, Env, Features, Vk,
};
use crate::support::vulkan::{
    allocate_info, begin_pass, density_pass, draw_fullscreen, image_info, range, spv, stages,
    Fixed, COLOR, DENSITY, FDM_LAYOUT, FRAGMENT, SIZE, VERTEX,
};

/// The calls fovea makes to clear new shadows ahead of the application's submit
/// (`src/vk/own/calls.rs`); where one fails, that submit fails with its result.
const CLEAR_CALLS: [&str; 5] = [
    "vkCreateCommandPool",
    "vkAllocateCommandBuffers",
    "vkBeginCommandBuffer",
    "vkEndCommandBuffer",
    "vkCreateFence",
];

/// The first call that failed: which, and with what.
pub(crate) type Failure = (&'static str, vk::Result);

/// Everything the flow made, destroyed in reverse at [`Flow::teardown`].
#[derive(Default)]
struct Flow {
    device: Option<ash::Device>,
    memories: Vec<vk::DeviceMemory>,
    images: Vec<vk::Image>,
    buffers: Vec<vk::Buffer>,
    views: Vec<vk::ImageView>,
    pass: Option<vk::RenderPass>,
    framebuffer: Option<vk::Framebuffer>,
    modules: Vec<vk::ShaderModule>,
    layout: Option<vk::PipelineLayout>,
    pipeline: Option<vk::Pipeline>,
    sampler: Option<vk::Sampler>,
    pool: Option<vk::CommandPool>,
    fence: Option<vk::Fence>,
}

fn check<T>(what: &'static str, r: Result<T, vk::Result>) -> Result<T, Failure> {
    r.map_err(|e| (what, e))
}

impl Flow {
    /// The application's part, stopping at the first failed call.
    ///
    /// # Safety
    /// `vk` must be alive; everything made is recorded in `self` for [`Flow::teardown`].
    unsafe fn run(&mut self, vk: &Vk) -> Result<(), Failure> {
        // SAFETY: every struct lives across its call; each object is recorded before the next
        // call, so teardown sees it whatever fails later.
        unsafe {
            let d = check(
                "vkCreateDevice",
                vk.try_device_with(&[], Features::FDM, None),
            )?;
            self.device = Some(d.clone());
            let memory = vk
                .instance
                .get_physical_device_memory_properties(vk.physical);
            let texel = vk
                .fdm_properties()
                .max_fragment_density_texel_size
                .width
                .max(1);
            let n = SIZE.div_ceil(texel);
            let mut image = |format, size, usage| -> Result<vk::Image, Failure> {
                let image = check(
                    "vkCreateImage",
                    d.create_image(&image_info(format, size, 1, usage), None),
                )?;
                self.images.push(image);
                let req = d.get_image_memory_requirements(image);
                let mem = check(
                    "vkAllocateMemory",
                    d.allocate_memory(
                        &allocate_info(&memory, req, vk::MemoryPropertyFlags::DEVICE_LOCAL),
                        None,
                    ),
                )?;
                self.memories.push(mem);
                check("vkBindImageMemory", d.bind_image_memory(image, mem, 0))?;
                Ok(image)
            };
            let color = image(
                COLOR,
                SIZE,
                vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
            )?;
            let density = image(
                DENSITY,
                n,
                vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT | vk::ImageUsageFlags::TRANSFER_DST,
            )?;
            // The density values: full rate in the middle, coarse around it.
            let bytes = (n * n * 2) as u64;
            let buffer = check(
                "vkCreateBuffer",
                d.create_buffer(
                    &vk::BufferCreateInfo::default()
                        .size(bytes)
                        .usage(vk::BufferUsageFlags::TRANSFER_SRC),
                    None,
                ),
            )?;
            self.buffers.push(buffer);
            let req = d.get_buffer_memory_requirements(buffer);
            let buffer_mem = check(
                "vkAllocateMemory",
                d.allocate_memory(
                    &allocate_info(
                        &memory,
                        req,
                        vk::MemoryPropertyFlags::HOST_VISIBLE
                            | vk::MemoryPropertyFlags::HOST_COHERENT,
                    ),
                    None,
                ),
            )?;
            self.memories.push(buffer_mem);
            check(
                "vkBindBufferMemory",
                d.bind_buffer_memory(buffer, buffer_mem, 0),
            )?;
            let p = check(
                "vkMapMemory",
                d.map_memory(buffer_mem, 0, bytes, vk::MemoryMapFlags::empty()),
            )?;
            let texels = std::slice::from_raw_parts_mut(p as *mut u8, bytes as usize);
            for (i, t) in texels.iter_mut().enumerate() {
                let (x, y) = ((i as u32 / 2) % n, (i as u32 / 2) / n);
                let centre = x > n / 4 && x < 3 * n / 4 && y > n / 4 && y < 3 * n / 4;
                *t = if centre { 255 } else { 64 };
            }
            d.unmap_memory(buffer_mem);

            let mut view = |image, format| -> Result<vk::ImageView, Failure> {
                let v = check(
                    "vkCreateImageView",
                    d.create_image_view(
                        &vk::ImageViewCreateInfo::default()
                            .image(image)
                            .view_type(vk::ImageViewType::TYPE_2D)
                            .format(format)
                            .subresource_range(range(0, 1)),
                        None,
                    ),
                )?;
                self.views.push(v);
                Ok(v)
            };
            let color_view = view(color, COLOR)?;
            let density_view = view(density, DENSITY)?;

            let pass = check(
                "vkCreateRenderPass2",
                density_pass(&d, vk::ImageLayout::TRANSFER_SRC_OPTIMAL, FDM_LAYOUT),
            )?;
            self.pass = Some(pass);
            let list = [color_view, density_view];
            let framebuffer = check(
                "vkCreateFramebuffer",
                d.create_framebuffer(
                    &vk::FramebufferCreateInfo::default()
                        .render_pass(pass)
                        .attachments(&list)
                        .width(SIZE)
                        .height(SIZE)
                        .layers(1),
                    None,
                ),
            )?;
            self.framebuffer = Some(framebuffer);

            for bytes in [VERTEX, FRAGMENT] {
                let words = spv(bytes);
                let m = check(
                    "vkCreateShaderModule",
                    d.create_shader_module(
                        &vk::ShaderModuleCreateInfo::default().code(&words),
                        None,
                    ),
                )?;
                self.modules.push(m);
            }
            // A sampler an application would use to read a subsampled image.
            self.sampler = Some(check(
                "vkCreateSampler",
                d.create_sampler(&vk::SamplerCreateInfo::default(), None),
            )?);
            let layout = check(
                "vkCreatePipelineLayout",
                d.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default(), None),
            )?;
            self.layout = Some(layout);
            let stages = stages([self.modules[0], self.modules[1]]);
            let fixed = Fixed::new();
            let info = fixed.info(&stages, layout).render_pass(pass).subpass(0);
            let pipeline = d
                .create_graphics_pipelines(vk::PipelineCache::null(), &[info], None)
                .map_err(|(made, e)| {
                    assert!(
                        made.iter().all(|p| *p == vk::Pipeline::null()),
                        "a failed vkCreateGraphicsPipelines left pipelines: {made:?}"
                    );
                    ("vkCreateGraphicsPipelines", e)
                })?[0];
            self.pipeline = Some(pipeline);

            let pool = check(
                "vkCreateCommandPool",
                d.create_command_pool(
                    &vk::CommandPoolCreateInfo::default().queue_family_index(0),
                    None,
                ),
            )?;
            self.pool = Some(pool);
            let cb = check(
                "vkAllocateCommandBuffers",
                d.allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default()
                        .command_pool(pool)
                        .level(vk::CommandBufferLevel::PRIMARY)
                        .command_buffer_count(1),
                ),
            )?[0];
            check(
                "vkBeginCommandBuffer",
                d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default()),
            )?;
            record(&d, cb, density, buffer, n, pass, framebuffer, pipeline);
            check("vkEndCommandBuffer", d.end_command_buffer(cb))?;
            let fence = check(
                "vkCreateFence",
                d.create_fence(&vk::FenceCreateInfo::default(), None),
            )?;
            self.fence = Some(fence);
            let cbs = [cb];
            check(
                "vkQueueSubmit",
                d.queue_submit(
                    d.get_device_queue(0, 0),
                    &[vk::SubmitInfo::default().command_buffers(&cbs)],
                    fence,
                ),
            )?;
            check(
                "vkWaitForFences",
                d.wait_for_fences(&[fence], true, 10_000_000_000),
            )?;
            let _ = color;
            Ok(())
        }
    }

    /// Destroys what [`Flow::run`] made, newest first, after the queue is idle.
    ///
    /// # Safety
    /// Everything in `self` must be alive.
    unsafe fn teardown(self) {
        let Some(d) = self.device else { return };
        // SAFETY: as the caller promised; the device is idle before anything is destroyed.
        unsafe {
            let _ = d.device_wait_idle();
            if let Some(f) = self.fence {
                d.destroy_fence(f, None);
            }
            if let Some(p) = self.pool {
                d.destroy_command_pool(p, None);
            }
            if let Some(p) = self.pipeline {
                d.destroy_pipeline(p, None);
            }
            if let Some(l) = self.layout {
                d.destroy_pipeline_layout(l, None);
            }
            if let Some(s) = self.sampler {
                d.destroy_sampler(s, None);
            }
            for m in self.modules {
                d.destroy_shader_module(m, None);
            }
            if let Some(f) = self.framebuffer {
                d.destroy_framebuffer(f, None);
            }
            if let Some(p) = self.pass {
                d.destroy_render_pass(p, None);
            }
            for v in self.views {
                d.destroy_image_view(v, None);
            }
            for b in self.buffers {
                d.destroy_buffer(b, None);
            }
            for i in self.images {
                d.destroy_image(i, None);
            }
            for m in self.memories {
                d.free_memory(m, None);
            }
            d.destroy_device(None);
        }
    }
}

/// The command buffer: upload the density map, hand it to the density stage, draw the pass.
///
/// # Safety
/// Every handle must be alive and `cb` recording.
#[allow(clippy::too_many_arguments)]
unsafe fn record(
    d: &ash::Device,
    cb: vk::CommandBuffer,
    density: vk::Image,
    buffer: vk::Buffer,
    n: u32,
    pass: vk::RenderPass,
    framebuffer: vk::Framebuffer,
    pipeline: vk::Pipeline,
) {
    let to_transfer = vk::ImageMemoryBarrier::default()
        .image(density)
        .subresource_range(range(0, 1))
        .old_layout(vk::ImageLayout::UNDEFINED)
        .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
        .dst_access_mask(vk::AccessFlags::TRANSFER_WRITE);
    let to_density = vk::ImageMemoryBarrier::default()
        .image(density)
        .subresource_range(range(0, 1))
        .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
        .new_layout(FDM_LAYOUT)
        .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
        .dst_access_mask(vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT);
    // SAFETY: as the caller promised; structs live across the calls.
    unsafe {
        d.cmd_pipeline_barrier(
            cb,
            vk::PipelineStageFlags::TOP_OF_PIPE,
            vk::PipelineStageFlags::TRANSFER,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[to_transfer],
        );
        d.cmd_copy_buffer_to_image(
            cb,
            buffer,
            density,
            vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            &[vk::BufferImageCopy::default()
                .image_subresource(vk::ImageSubresourceLayers {
                    aspect_mask: vk::ImageAspectFlags::COLOR,
                    mip_level: 0,
                    base_array_layer: 0,
                    layer_count: 1,
                })
                .image_extent(vk::Extent3D {
                    width: n,
                    height: n,
                    depth: 1,
                })],
        );
        d.cmd_pipeline_barrier(
            cb,
            vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[to_density],
        );
        begin_pass(d, cb, pass, framebuffer);
        draw_fullscreen(d, cb, pipeline);
        d.cmd_end_render_pass2(cb, &vk::SubpassEndInfo::default());
    }
}

/// Runs the flow once on a fresh instance, with `fault` armed after the instance exists; returns
/// the first failure the application saw and the calls each faultable command made.
pub(crate) fn run_once(
    env: &Env,
    profile: Profile,
    fault: Option<(&str, u64, vk::Result)>,
) -> (Option<Failure>, BTreeMap<&'static str, u64>) {
    let vk = Vk::new(env, profile, true).expect("an instance");
    if let Some((name, nth, result)) = fault {
        env.double.fail(name, nth, result);
    }
    let mut flow = Flow::default();
    // SAFETY: the instance lives across the flow; teardown destroys what the flow made.
    let failure = unsafe {
        let r = flow.run(&vk);
        flow.teardown();
        r.err()
    };
    drop(vk);
    let calls = std::iter::once("vkCreateDevice")
        .chain(fovea_vkdouble::FAULTABLE.iter().copied())
        .map(|name| (name, env.double.calls(name)))
        .filter(|&(_, n)| n > 0)
        .collect();
    (failure, calls)
}

/// Every call the flow makes fails once, on both shading-rate profiles: the application sees the
/// driver's result unchanged where the call was its own, fovea fails open where it was fovea's,
/// and validation (leaks included) stays silent.
#[test]
fn every_call_below_the_layer_fails_in_turn() {
    let Some((_serial, env)) = env() else { return };
    let results = [
        vk::Result::ERROR_OUT_OF_DEVICE_MEMORY,
        vk::Result::ERROR_OUT_OF_HOST_MEMORY,
    ];
    let mut faulted = 0;
    let mut failed_open = 0;
    let mut surfaced = 0;
    for profile in [Profile::Nvidia, Profile::Amd] {
        let (failure, calls) = run_once(env, profile, None);
        assert_eq!(failure, None, "{profile:?}: the flow without faults");
        assert_only_stage_false_positives();
        assert!(env.double.errors().is_empty(), "{:?}", env.double.errors());
        for (&name, &count) in &calls {
            for nth in 0..count {
                let result = results[(nth % 2) as usize];
                let (failure, after) = run_once(env, profile, Some((name, nth, result)));
                let what = format!("{profile:?}: {name} call {nth} failing with {result}");
                assert!(after[name] > nth, "{what}: the fault did not fire");
                match failure {
                    // The application's own call, its result unchanged.
                    Some((call, r)) if call == name => {
                        assert_eq!(r, result, "{what}: the application saw another result")
                    }
                    // A call fovea makes for the shadows' clear ahead of the application's
                    // submit: that submit fails with its result, without going down.
                    Some(("vkQueueSubmit", r)) if CLEAR_CALLS.contains(&name) => {
                        assert_eq!(r, result, "{what}: vkQueueSubmit failed otherwise");
                        surfaced += 1;
                    }
                    Some(other) => panic!("{what}: the application saw {other:?}"),
                    // fovea's own call: it failed open and the application went on.
                    None => failed_open += 1,
                }
                // Validation reports a driver's failed vkCreateDevice itself.
                let messages: Vec<String> = take_real_messages()
                    .into_iter()
                    .filter(|m| {
                        !(name == "vkCreateDevice" && m.contains("Failed to create device chain"))
                    })
                    .collect();
                assert!(
                    messages.is_empty(),
                    "{what}: validation reported {} message(s):\n{}",
                    messages.len(),
                    messages.join("\n")
                );
                let errors = env.double.errors();
                assert!(errors.is_empty(), "{what}: the double saw {errors:?}");
                faulted += 1;
            }
        }
    }
    eprintln!(
        "vk_faults: {faulted} calls faulted; fovea's own: {failed_open} failed open, {surfaced} \
         surfaced as the next vkQueueSubmit's result"
    );
    assert!(
        failed_open + surfaced > 0,
        "no fault reached fovea's own calls"
    );
}
