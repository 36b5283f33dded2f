//! Recording cost of each command fovea's Vulkan layer intercepts, with and without the layer, in
//! the same run, and the heap allocations the layer adds per command.
//!
//! Two instances live side by side in this process, both on lavapipe made to look like an
//! NVIDIA-like GPU with shading-rate attachments by the test double (`crates/vkdouble`): `bare`
//! enables the double only; `fovea` enables `VK_LAYER_FOVEA_fragment_density_map` above it and
//! creates its device with `VK_EXT_fragment_density_map`, so the layer emulates density maps and
//! its command hooks are the ones the application calls. The validation layer is left out: its cost
//! would dominate. Commands are recorded into a primary command buffer that is never submitted; it
//! is reset between rounds (outside the timed part).
//!
//! Cases on the common path (no density image involved): `vkCmdPipelineBarrier` and
//! `vkCmdPipelineBarrier2` with one image barrier, `vkCmdBeginRenderPass` + `vkCmdEndRenderPass` on
//! a pass without a density map, `vkCmdBeginRendering` + `vkCmdEndRendering` without one. For
//! information, the density-map variants (`fovea` only: the bare device has no density maps):
//! a barrier into `FRAGMENT_DENSITY_MAP_OPTIMAL_EXT`, a render pass and a dynamic rendering with a
//! density-map attachment. And injection's (docs/injection.md): a third device, made with the
//! layer through `xrCreateVulkanDeviceKHR` of an OpenXR instance with `FOVEA_INJECT=1` (fovea's
//! OpenXR layer on the simulated runtime), as an XR_KHR_vulkan_enable2 application makes its
//! session's device, the one device injection goes to
//! (docs/injection.md#which-devices-get-the-feature); the session runs on the first such device
//! and its eye swapchain is published. The device begins a dynamic rendering and a render pass
//! into an eye-shaped target of its own, which get fovea's map (made before the timed rounds; what
//! is timed is the classification and the attachment chained on). Before any round is timed, what
//! reached the driver must show injection on for that device (`proves_injection`: the attachment
//! feature, the framebuffer's eye map and, on lavapipe, the passes begun with it and the rewritten
//! combiner), or the run fails: rows that measure a device without injection would say nothing.
//! The bare and injecting devices enable `VK_KHR_fragment_shading_rate`'s pipeline rates (no
//! attachments), as vkd3d-proton does, and record `vkCmdSetFragmentShadingRateKHR` (1×1,
//! {KEEP, KEEP}), which the injecting device's hook passes down with `combinerOps[1]` rewritten
//! (docs/injection.md#apps-that-set-rates).
//! (The density-map passes, once the density-image barrier case has moved the map into the density
//! layout, these include the conversion the layer records in front of the pass.)
//! Density-map offsets (docs/vulkan-layer.md#density-map-offsets): `vkCmdBeginRenderPass2` +
//! `vkCmdEndRenderPass2` on a pass without a density map (both devices; the end is intercepted on
//! emulating devices), and, `fovea` only, the same on a pass whose map was created with the offset
//! flag, ended with an offset, and `vkCmdBeginRendering` + `vkCmdEndRendering2EXT` with an offset
//! (the bare device records the plain pair in their place): each such pass gets a conversion of
//! its own in front of it, whose shifts its end writes.
//! Reconstruction of coarse blocks (docs/reconstruction.md), `fovea` only: the density-map render
//! pass and dynamic rendering again, into a colour image created with
//! `VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT`, whose end gets the copies, the dispatch and the compute
//! bindings given back; before any round is timed, the first such pass must have made the
//! layer's scratch buffer (`proves_reconstruction`), or the run fails. A second table sets each against the same
//! pass into the image without the flag, on the same device in interleaved rounds: what
//! reconstruction adds to recording a pass.
//! `vkCmdBindPipeline` of a compute pipeline (both devices): the layer notes the application's
//! compute bindings on emulating devices, to give them back after it converts a density map the
//! application writes (src/vk/convert.rs).
//!
//! Allocations are counted by interposing `malloc` and friends in this executable, as
//! `benches/frame_loop.rs` does (the layer and the driver are dlopened libraries; ELF symbol
//! interposition routes their `malloc` calls through these). lavapipe allocates as it records
//! (its command queue), so the figure that matters is the difference between the two devices.
//!
//! Each pair runs twice: once on lavapipe (the driver records the commands: a real driver's cost,
//! microseconds per command on a CPU rasteriser, so the layer's share drowns in its noise), and
//! once with the double dropping the commands ([`fovea_vkdouble::NULL_COMMANDS_ENV`]): the bare
//! device then costs a call into an empty function, and the difference is the layer's own cost.
//!
//! Besides criterion's report, the run ends with a table from interleaved rounds: ns per command
//! for both, the difference, the ratio, and allocations per command for both. The run fails where
//! the layer adds an allocation to any command with the null bottom (the fewest in a round,
//! against the bare device's).
//!
//! Run: `cargo bench --bench vk_commands` (needs the Vulkan loader and lavapipe; skips otherwise).

use std::ffi::c_void;
use std::time::{Duration, Instant};

use ash::vk;
use ash::vk::Handle as _;
use criterion::Criterion;
use serde_json::Value;

#[path = "support/vulkan.rs"]
mod vulkan;
use vulkan::{colour_range, compute_pipeline, median, pass_and_framebuffer, Target};

#[path = "support/alloc.rs"]
mod alloc;

#[path = "support/xr_inject.rs"]
mod xr_inject;
use xr_inject::{extent_of, handle, injects, Xr};

/// The colour target's size; the density map's is this over the NVIDIA-like texel (16).
const SIZE: u32 = 64;
const DENSITY: u32 = SIZE / 16;
/// Commands per round (the command buffer is reset between rounds).
const ROUND: usize = 256;
/// The eye swapchain's size, and the injected side's colour target's (an eye-shaped target).
const EYE: [u32; 2] = [640, 500];

/// `VkRenderingEndInfoEXT` (`VK_STRUCTURE_TYPE_RENDERING_END_INFO_EXT`, newer than ash 0.38).
#[repr(C)]
struct RenderingEndInfo {
    s_type: vk::StructureType,
    p_next: *const c_void,
}
const RENDERING_END_INFO: vk::StructureType = vk::StructureType::from_raw(1_000_619_003);
type EndRendering2 = unsafe extern "system" fn(vk::CommandBuffer, *const RenderingEndInfo);

/// Which device a side makes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    /// The double alone.
    Bare,
    /// fovea above the double, emulating density maps.
    Fdm,
    /// fovea above the double, injecting maps into eye passes.
    Inject,
}

/// One instance, device and command buffer, with what the cases record.
struct Side {
    instance: ash::Instance,
    device: ash::Device,
    pool: vk::CommandPool,
    cb: vk::CommandBuffer,
    color: Target,
    pass: vk::RenderPass,
    framebuffer: vk::Framebuffer,
    /// Where the layer emulates density maps: the density image and its pass and framebuffer.
    fdm: Option<(Target, vk::RenderPass, vk::Framebuffer)>,
    /// Where the layer emulates density maps: a density image with the offset flag, its pass and
    /// framebuffer, and `vkCmdEndRendering2EXT`.
    offsets: Option<(Target, vk::RenderPass, vk::Framebuffer, EndRendering2)>,
    /// Where the layer emulates density maps: a subsampled colour image (reconstructed) and a pass
    /// and framebuffer rendering it with the density image of `fdm`.
    subsampled: Option<(Target, vk::RenderPass, vk::Framebuffer)>,
    /// Where the device has pipeline shading rates (not on the emulating one).
    set_rate: Option<ash::khr::fragment_shading_rate::Device>,
    /// A compute pipeline (`tests/suite/shaders/store.comp`) and its layout.
    compute: (vk::PipelineLayout, vk::Pipeline),
    /// Where the instance and device were made through OpenXR (the injecting side): what destroys
    /// them.
    xr: Option<fovea_harness::vulkan::Vulkan>,
}

impl Side {
    /// The bare or the emulating side: an instance and a device of its own, made directly.
    fn new(entry: &ash::Entry, kind: Kind) -> Result<Side, String> {
        assert_ne!(kind, Kind::Inject, "made through OpenXR: Side::injecting");
        let (instance, physical) = vulkan::instance_on_lavapipe(entry, kind != Kind::Bare)?;
        // SAFETY: `physical` is the instance's.
        let device =
            unsafe { vulkan::device(&instance, physical, kind == Kind::Fdm, kind == Kind::Bare) }?;
        // SAFETY: the device is the instance's and the side's alone.
        Ok(unsafe { Side::on(instance, physical, device, kind, None) })
    }

    /// The injecting side: its instance and device made through `xrCreateVulkanInstanceKHR` and
    /// `xrCreateVulkanDeviceKHR`, as an XR_KHR_vulkan_enable2 application makes the device its
    /// session renders with, which is the device injection goes to
    /// (docs/injection.md#which-devices-get-the-feature); the first one made is the session's,
    /// and the eye swapchain is published before the side's framebuffer is made (its map is
    /// picked at `vkCreateFramebuffer`).
    fn injecting(entry: &ash::Entry, xr: &Xr) -> Result<Side, String> {
        let v = xr.vulkan(entry)?;
        xr.publish_eye(&v, EYE)?;
        let (instance, physical, device) =
            (v.instance.clone(), v.physical_device, v.device.clone());
        // SAFETY: the device is the instance's and the side's alone; `v` destroys both.
        Ok(unsafe { Side::on(instance, physical, device, Kind::Inject, Some(v)) })
    }

    /// What a side records with, made on `device`.
    ///
    /// # Safety
    /// `device` must be live and made from `instance`'s `physical`; the side destroys both (or
    /// `xr` does, where given: the objects they were loaded from).
    unsafe fn on(
        instance: ash::Instance,
        physical: vk::PhysicalDevice,
        device: ash::Device,
        kind: Kind,
        xr: Option<fovea_harness::vulkan::Vulkan>,
    ) -> Side {
        // SAFETY: as the caller promised; every struct lives across the calls; handles are used
        // while alive.
        unsafe {
            let (pool, cb) = vulkan::command_buffer(&device);
            let extent = if kind == Kind::Inject {
                EYE
            } else {
                [SIZE, SIZE]
            };
            let color = Target::new(
                &instance,
                physical,
                &device,
                vk::Format::R8G8B8A8_UNORM,
                extent,
                vk::ImageUsageFlags::COLOR_ATTACHMENT,
            );
            let (pass, framebuffer) = pass_and_framebuffer(&device, color.view, None, SIZE);
            // A density map created with `flags`, and a pass and framebuffer reading it.
            let density_pass = |flags| {
                let density = Target::with_flags(
                    &instance,
                    physical,
                    &device,
                    vk::Format::R8G8_UNORM,
                    [DENSITY, DENSITY],
                    vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT,
                    flags,
                );
                let (p, f) = pass_and_framebuffer(&device, color.view, Some(density.view), SIZE);
                (density, p, f)
            };
            let fdm = (kind == Kind::Fdm).then(|| density_pass(vk::ImageCreateFlags::empty()));
            let subsampled = fdm.as_ref().map(|(density, _, _)| {
                let colour = Target::with_flags(
                    &instance,
                    physical,
                    &device,
                    vk::Format::R8G8B8A8_UNORM,
                    [SIZE, SIZE],
                    vk::ImageUsageFlags::COLOR_ATTACHMENT,
                    vk::ImageCreateFlags::SUBSAMPLED_EXT,
                );
                let (p, f) = pass_and_framebuffer(&device, colour.view, Some(density.view), SIZE);
                (colour, p, f)
            });
            let offsets = (kind == Kind::Fdm).then(|| {
                let (density, p, f) =
                    density_pass(vk::ImageCreateFlags::FRAGMENT_DENSITY_MAP_OFFSET_QCOM);
                let end = (instance.fp_v1_0().get_device_proc_addr)(
                    device.handle(),
                    c"vkCmdEndRendering2EXT".as_ptr(),
                )
                .map(|f| std::mem::transmute::<unsafe extern "system" fn(), EndRendering2>(f))
                .expect("vkCmdEndRendering2EXT on an emulating device");
                (density, p, f, end)
            });
            let set_rate = (kind != Kind::Fdm)
                .then(|| ash::khr::fragment_shading_rate::Device::new(&instance, &device));
            let compute = compute_pipeline(&device);
            Side {
                set_rate,
                instance,
                device,
                pool,
                cb,
                color,
                pass,
                framebuffer,
                fdm,
                subsampled,
                offsets,
                compute,
                xr,
            }
        }
    }

    fn begin(&self) {
        // SAFETY: the side's own command buffer, not recording.
        unsafe {
            self.device
                .begin_command_buffer(self.cb, &vk::CommandBufferBeginInfo::default())
                .expect("vkBeginCommandBuffer");
        }
    }

    fn end_and_reset(&self) {
        // SAFETY: the side's own command buffer, recording and never submitted.
        unsafe {
            self.device
                .end_command_buffer(self.cb)
                .expect("vkEndCommandBuffer");
            self.device
                .reset_command_buffer(self.cb, vk::CommandBufferResetFlags::RELEASE_RESOURCES)
                .expect("vkResetCommandBuffer");
        }
    }

    /// Records `case` once; `false` where this side cannot (density-map cases without fovea).
    fn record(&self, case: Case) -> bool {
        let d = &self.device;
        let cb = self.cb;
        let whole = vk::Rect2D {
            offset: vk::Offset2D::default(),
            extent: vk::Extent2D {
                width: SIZE,
                height: SIZE,
            },
        };
        let (image, layout) = match (case, &self.fdm) {
            (Case::BarrierFdm, Some((density, _, _))) => (
                density.image,
                vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT,
            ),
            (
                Case::BarrierFdm
                | Case::RenderPassFdm
                | Case::RenderingFdm
                | Case::RenderPassOffsets
                | Case::RenderingOffsets
                | Case::RenderPassReconstructed
                | Case::RenderingReconstructed,
                None,
            ) => return false,
            (
                Case::RenderPassInjected | Case::RenderingInjected | Case::RenderingInjectedNull,
                _,
            ) if self.fdm.is_some() => return false,
            _ => (self.color.image, vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL),
        };
        // SAFETY: the side's own command buffer, recording; every struct lives across its call.
        unsafe {
            match case {
                Case::SetRate => {
                    let Some(f) = &self.set_rate else {
                        return false;
                    };
                    let keep = [vk::FragmentShadingRateCombinerOpKHR::KEEP; 2];
                    let one = vk::Extent2D {
                        width: 1,
                        height: 1,
                    };
                    (f.fp().cmd_set_fragment_shading_rate_khr)(cb, &one, &keep);
                }
                Case::Barrier | Case::BarrierFdm => {
                    let barrier = [vk::ImageMemoryBarrier::default()
                        .src_access_mask(vk::AccessFlags::SHADER_READ)
                        .dst_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                        .old_layout(vk::ImageLayout::UNDEFINED)
                        .new_layout(layout)
                        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                        .image(image)
                        .subresource_range(colour_range())];
                    d.cmd_pipeline_barrier(
                        cb,
                        vk::PipelineStageFlags::FRAGMENT_SHADER,
                        vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                        vk::DependencyFlags::empty(),
                        &[],
                        &[],
                        &barrier,
                    );
                }
                Case::Barrier2 => {
                    let barrier = [vk::ImageMemoryBarrier2::default()
                        .src_stage_mask(vk::PipelineStageFlags2::FRAGMENT_SHADER)
                        .src_access_mask(vk::AccessFlags2::SHADER_READ)
                        .dst_stage_mask(vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT)
                        .dst_access_mask(vk::AccessFlags2::COLOR_ATTACHMENT_WRITE)
                        .old_layout(vk::ImageLayout::UNDEFINED)
                        .new_layout(layout)
                        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                        .image(image)
                        .subresource_range(colour_range())];
                    d.cmd_pipeline_barrier2(
                        cb,
                        &vk::DependencyInfo::default().image_memory_barriers(&barrier),
                    );
                }
                Case::RenderPass
                | Case::RenderPassFdm
                | Case::RenderPassInjected
                | Case::RenderPassReconstructed => {
                    let (pass, framebuffer) = match (case, &self.fdm, &self.subsampled) {
                        (Case::RenderPassFdm, Some((_, p, f)), _) => (*p, *f),
                        (Case::RenderPassReconstructed, _, Some((_, p, f))) => (*p, *f),
                        _ => (self.pass, self.framebuffer),
                    };
                    let begin = vk::RenderPassBeginInfo::default()
                        .render_pass(pass)
                        .framebuffer(framebuffer)
                        .render_area(whole);
                    d.cmd_begin_render_pass(cb, &begin, vk::SubpassContents::INLINE);
                    d.cmd_end_render_pass(cb);
                }
                Case::RenderPass2 | Case::RenderPassOffsets => {
                    let (pass, framebuffer) = match (case, &self.offsets) {
                        (Case::RenderPassOffsets, Some((_, p, f, _))) => (*p, *f),
                        _ => (self.pass, self.framebuffer),
                    };
                    let begin = vk::RenderPassBeginInfo::default()
                        .render_pass(pass)
                        .framebuffer(framebuffer)
                        .render_area(whole);
                    let offsets = [vk::Offset2D { x: 16, y: -16 }];
                    let mut end = vk::SubpassFragmentDensityMapOffsetEndInfoQCOM::default()
                        .fragment_density_offsets(&offsets);
                    let mut info = vk::SubpassEndInfo::default();
                    if case == Case::RenderPassOffsets {
                        info = info.push_next(&mut end);
                    }
                    d.cmd_begin_render_pass2(
                        cb,
                        &begin,
                        &vk::SubpassBeginInfo::default().contents(vk::SubpassContents::INLINE),
                    );
                    d.cmd_end_render_pass2(cb, &info);
                }
                Case::RenderingOffsets => {
                    let Some((density, _, _, end2)) = &self.offsets else {
                        return false;
                    };
                    let colors = [vk::RenderingAttachmentInfo::default()
                        .image_view(self.color.view)
                        .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                        .load_op(vk::AttachmentLoadOp::DONT_CARE)
                        .store_op(vk::AttachmentStoreOp::STORE)];
                    let mut fdm = vk::RenderingFragmentDensityMapAttachmentInfoEXT::default()
                        .image_view(density.view)
                        .image_layout(vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT);
                    let info = vk::RenderingInfo::default()
                        .render_area(whole)
                        .layer_count(1)
                        .color_attachments(&colors)
                        .push_next(&mut fdm);
                    let offsets = [vk::Offset2D { x: 16, y: -16 }];
                    let end = vk::SubpassFragmentDensityMapOffsetEndInfoQCOM::default()
                        .fragment_density_offsets(&offsets);
                    d.cmd_begin_rendering(cb, &info);
                    end2(
                        cb,
                        &RenderingEndInfo {
                            s_type: RENDERING_END_INFO,
                            p_next: &end as *const _ as *const c_void,
                        },
                    );
                }
                Case::BindPipeline => {
                    d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, self.compute.1);
                }
                Case::Rendering
                | Case::RenderingFdm
                | Case::RenderingInjected
                | Case::RenderingInjectedNull
                | Case::RenderingReconstructed => {
                    let view = match (case, &self.subsampled) {
                        (Case::RenderingReconstructed, Some((colour, _, _))) => colour.view,
                        _ => self.color.view,
                    };
                    let colors = [vk::RenderingAttachmentInfo::default()
                        .image_view(view)
                        .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                        .load_op(vk::AttachmentLoadOp::DONT_CARE)
                        .store_op(vk::AttachmentStoreOp::STORE)];
                    let mut fdm = vk::RenderingFragmentDensityMapAttachmentInfoEXT::default()
                        .image_layout(vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT);
                    let mut info = vk::RenderingInfo::default()
                        .render_area(whole)
                        .layer_count(1)
                        .color_attachments(&colors);
                    if let (
                        Case::RenderingFdm | Case::RenderingReconstructed,
                        Some((density, _, _)),
                    ) = (case, &self.fdm)
                    {
                        fdm.image_view = density.view;
                        info = info.push_next(&mut fdm);
                    }
                    // vkd3d-proton's: no view, so no attachment.
                    let mut null_rate =
                        vk::RenderingFragmentShadingRateAttachmentInfoKHR::default()
                            .shading_rate_attachment_texel_size(vk::Extent2D {
                                width: 16,
                                height: 16,
                            });
                    if case == Case::RenderingInjectedNull {
                        info = info.push_next(&mut null_rate);
                    }
                    d.cmd_begin_rendering(cb, &info);
                    d.cmd_end_rendering(cb);
                }
            }
        }
        true
    }

    /// Records `n` commands of `case` into a fresh command buffer: the time the `n` took, and the
    /// allocations made meanwhile.
    fn round(&self, case: Case, n: usize) -> Option<(Duration, u64)> {
        self.begin();
        let a = alloc::allocations();
        let t = Instant::now();
        for _ in 0..n {
            if !self.record(case) {
                self.end_and_reset();
                return None;
            }
        }
        let elapsed = t.elapsed();
        let allocations = alloc::allocations() - a;
        self.end_and_reset();
        Some((elapsed, allocations))
    }
}

impl Drop for Side {
    fn drop(&mut self) {
        // SAFETY: nothing made from these handles outlives them; each is destroyed once.
        unsafe {
            let d = &self.device;
            if let Some((density, p, f, _)) = self.offsets.take() {
                d.destroy_framebuffer(f, None);
                d.destroy_render_pass(p, None);
                density.destroy(d);
            }
            if let Some((colour, p, f)) = self.subsampled.take() {
                d.destroy_framebuffer(f, None);
                d.destroy_render_pass(p, None);
                colour.destroy(d);
            }
            if let Some((density, p, f)) = self.fdm.take() {
                d.destroy_framebuffer(f, None);
                d.destroy_render_pass(p, None);
                density.destroy(d);
            }
            d.destroy_pipeline(self.compute.1, None);
            d.destroy_pipeline_layout(self.compute.0, None);
            d.destroy_framebuffer(self.framebuffer, None);
            d.destroy_render_pass(self.pass, None);
            self.color.destroy(d);
            d.destroy_command_pool(self.pool, None);
            match self.xr.take() {
                Some(v) => v.destroy(),
                None => {
                    d.destroy_device(None);
                    self.instance.destroy_instance(None);
                }
            }
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Case {
    Barrier,
    Barrier2,
    RenderPass,
    Rendering,
    BindPipeline,
    BarrierFdm,
    RenderPassFdm,
    RenderingFdm,
    RenderPassInjected,
    RenderingInjected,
    /// An injected eye pass whose rendering chains vkd3d-proton's null-view shading-rate struct,
    /// which the layer's copy leaves out (per-thread scratch storage).
    RenderingInjectedNull,
    SetRate,
    RenderPass2,
    RenderPassOffsets,
    RenderingOffsets,
    /// The density-map pass into a subsampled image: reconstructed at its end.
    RenderPassReconstructed,
    /// The density-map rendering into a subsampled image: reconstructed at its end.
    RenderingReconstructed,
}

impl Case {
    const ALL: [Case; 17] = [
        Case::Barrier,
        Case::Barrier2,
        Case::RenderPass,
        Case::Rendering,
        Case::BindPipeline,
        Case::BarrierFdm,
        Case::RenderPassFdm,
        Case::RenderingFdm,
        Case::RenderPassInjected,
        Case::RenderingInjected,
        Case::RenderingInjectedNull,
        Case::SetRate,
        Case::RenderPass2,
        Case::RenderPassOffsets,
        Case::RenderingOffsets,
        Case::RenderPassReconstructed,
        Case::RenderingReconstructed,
    ];

    /// Whether the injecting device records it.
    fn injected(self) -> bool {
        matches!(
            self,
            Case::RenderPassInjected
                | Case::RenderingInjected
                | Case::RenderingInjectedNull
                | Case::SetRate
        )
    }

    fn name(self) -> &'static str {
        match self {
            Case::Barrier => "vkCmdPipelineBarrier",
            Case::Barrier2 => "vkCmdPipelineBarrier2",
            Case::RenderPass => "vkCmdBeginRenderPass+End",
            Case::Rendering => "vkCmdBeginRendering+End",
            Case::BindPipeline => "vkCmdBindPipeline (compute)",
            Case::BarrierFdm => "vkCmdPipelineBarrier (density image)",
            Case::RenderPassFdm => "vkCmdBeginRenderPass+End (FDM pass)",
            Case::RenderingFdm => "vkCmdBeginRendering+End (FDM attachment)",
            Case::RenderPassInjected => "vkCmdBeginRenderPass+End (injected eye pass)",
            Case::RenderingInjected => "vkCmdBeginRendering+End (injected eye pass)",
            Case::RenderingInjectedNull => {
                "vkCmdBeginRendering+End (injected eye pass, null-view shading-rate struct)"
            }
            Case::SetRate => "vkCmdSetFragmentShadingRateKHR (injecting)",
            Case::RenderPass2 => "vkCmdBeginRenderPass2+End2",
            Case::RenderPassOffsets => "vkCmdBeginRenderPass2+End2 (FDM pass, offsets)",
            Case::RenderingOffsets => "vkCmdBeginRendering+End2EXT (FDM attachment, offsets)",
            Case::RenderPassReconstructed => "vkCmdBeginRenderPass+End (FDM pass, reconstructed)",
            Case::RenderingReconstructed => {
                "vkCmdBeginRendering+End (FDM attachment, reconstructed)"
            }
        }
    }

    /// The same pass without reconstruction, for the reconstructed cases.
    fn unreconstructed(self) -> Option<Case> {
        match self {
            Case::RenderPassReconstructed => Some(Case::RenderPassFdm),
            Case::RenderingReconstructed => Some(Case::RenderingFdm),
            _ => None,
        }
    }

    /// The case the bare device records in its place (it has no density maps).
    fn bare(self) -> Case {
        match self {
            Case::BarrierFdm => Case::Barrier,
            Case::RenderPassFdm | Case::RenderPassReconstructed => Case::RenderPass,
            Case::RenderingFdm
            | Case::RenderingInjected
            | Case::RenderingInjectedNull
            | Case::RenderingReconstructed => Case::Rendering,
            Case::RenderPassInjected => Case::RenderPass,
            Case::RenderPassOffsets => Case::RenderPass2,
            Case::RenderingOffsets => Case::Rendering,
            c => c,
        }
    }
}

/// What the commands reach below the layers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Bottom {
    /// lavapipe records them (the driver's cost, microseconds, dominates).
    Lavapipe,
    /// The double drops them ([`fovea_vkdouble::NULL_COMMANDS_ENV`]): what remains is the
    /// layers' own cost.
    Null,
}

impl Bottom {
    fn name(self) -> &'static str {
        match self {
            Bottom::Lavapipe => "lavapipe",
            Bottom::Null => "null",
        }
    }
}

/// The three sides on one bottom.
struct Sides {
    bottom: Bottom,
    bare: Side,
    fovea: Side,
    inject: Side,
}

impl Sides {
    /// The side of fovea's that records `case`.
    fn fovea_for(&self, case: Case) -> &Side {
        if case.injected() {
            &self.inject
        } else {
            &self.fovea
        }
    }
}

/// That injection is on for the injecting side just made, from what reached the driver since the
/// double's records were cleared in front of it: its device with the shading-rate attachment
/// feature (asked for pipeline rates only) and its framebuffer with a second attachment, fovea's
/// map for the eye-shaped target (`EYE` over the profile's texel: a full-rate map would cover the
/// framebuffer only). On lavapipe it also records one of each injected case, outside any timing:
/// the render pass begins with that map, each rendering with one shading-rate struct naming it,
/// and `vkCmdSetFragmentShadingRateKHR` reaches the driver with `combinerOps[1]` = `MAX`. With the
/// null bottom those commands reach nothing the double records; the device and the framebuffer
/// are its evidence there.
fn proves_injection(
    double: &fovea_vkdouble::Loaded,
    side: &Side,
    bottom: Bottom,
) -> Result<(), String> {
    let (map, eye_map) = injects(double, side.framebuffer.as_raw(), EYE)?;
    if bottom == Bottom::Null {
        return Ok(());
    }
    for case in Case::ALL.into_iter().filter(|c| c.injected()) {
        side.round(case, 1)
            .ok_or_else(|| format!("{} not recordable", case.name()))?;
    }
    let events = double.records()["events"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    let cb = side.cb.as_raw();
    let ours = |kind: &str| -> Vec<&Value> {
        events
            .iter()
            .filter(|e| e["kind"] == kind && handle(e, "command_buffer") == cb)
            .collect()
    };
    let passes = ours("begin_render_pass");
    if passes.len() != 1 || passes[0]["shading_rate_views"] != serde_json::json!([map]) {
        return Err(format!(
            "the render pass did not begin with the eye map {map}: {passes:?}"
        ));
    }
    let renderings = ours("begin_rendering");
    let eye = |r: &&Value| {
        r["shading_rate_structs"] == 1
            && extent_of(&events, handle(&r["shading_rate"], "view")).as_ref() == Some(&eye_map)
    };
    if renderings.len() != 2 || !renderings.iter().all(eye) {
        return Err(format!(
            "the renderings did not begin with the eye map, one struct each: {renderings:?}"
        ));
    }
    let max = vk::FragmentShadingRateCombinerOpKHR::MAX.as_raw();
    let set = ours("set_fragment_shading_rate");
    if set.len() != 1 || set[0]["combiner_ops"][1] != max {
        return Err(format!(
            "vkCmdSetFragmentShadingRateKHR reached the driver without combinerOps[1] = MAX: \
             {set:?}"
        ));
    }
    Ok(())
}

/// That the emulating side's reconstructed cases reconstruct, before any round is timed: the
/// first pass into the subsampled image makes the scratch buffer the layer keeps for that target
/// size (one `vkCreateBuffer` reaching the double), after the same passes into the image without
/// the flag made whatever they make; the second reconstructed case reuses it.
fn proves_reconstruction(double: &fovea_vkdouble::Loaded, side: &Side) -> Result<(), String> {
    for case in [Case::RenderPassReconstructed, Case::RenderingReconstructed] {
        let plain = case.unreconstructed().expect("a reconstructed case");
        side.round(plain, 1)
            .ok_or_else(|| format!("{} not recordable", plain.name()))?;
    }
    let before = double.calls("vkCreateBuffer");
    for case in [Case::RenderPassReconstructed, Case::RenderingReconstructed] {
        side.round(case, 1)
            .ok_or_else(|| format!("{} not recordable", case.name()))?;
    }
    let made = double.calls("vkCreateBuffer") - before;
    if made != 1 {
        return Err(format!(
            "{made} buffers made by the first reconstructed passes, not the one scratch"
        ));
    }
    Ok(())
}

/// What reconstruction adds to recording a pass: each reconstructed case against the same pass
/// into an image without the subsampled flag, on the same emulating device, in interleaved
/// rounds.
fn reconstruction_summary(sides: &Sides) {
    const ROUNDS: usize = 200;
    println!(
        "\nvk_commands reconstruction, {} below the layers: median ns per pass over {ROUNDS} \
         interleaved rounds of {ROUND}, fovea's emulating device both",
        sides.bottom.name()
    );
    println!(
        "{:<46} {:>11} {:>11} {:>9} {:>7}",
        "pass", "plain ns", "recon ns", "added ns", "ratio"
    );
    for case in [Case::RenderPassReconstructed, Case::RenderingReconstructed] {
        let plain = case.unreconstructed().expect("a reconstructed case");
        let (mut tp, mut tr) = (Vec::new(), Vec::new());
        for _ in 0..ROUNDS {
            let (t, _) = sides.fovea.round(plain, ROUND).expect("recordable");
            tp.push(t.as_nanos() as f64 / ROUND as f64);
            let (t, _) = sides.fovea.round(case, ROUND).expect("recordable");
            tr.push(t.as_nanos() as f64 / ROUND as f64);
        }
        let (p, r) = (median(tp), median(tr));
        println!(
            "{:<46} {:>11.1} {:>11.1} {:>9.1} {:>7.3}",
            case.name(),
            p,
            r,
            r - p,
            r / p
        );
    }
}

/// The three sides on both bottoms, each injecting side proven to inject, what keeps injection on,
/// and the double's library (kept loaded: its records live there); or why not. Panics where an
/// injecting side does not inject: its rows would measure nothing.
fn sides() -> Result<(Vec<Sides>, Xr, fovea_vkdouble::Loaded), String> {
    let double_lib = vulkan::layers_on_search_path("vkbench")?;
    let double = fovea_vkdouble::Loaded::open(&double_lib)?;
    std::env::remove_var(fovea_vkdouble::NULL_COMMANDS_ENV);
    // SAFETY: loading libvulkan runs its initialisers, as any Vulkan application does.
    let entry = unsafe { ash::Entry::load() }.map_err(|e| format!("no Vulkan loader ({e})"))?;
    // Declared first, dropped last on an early return: the session's swapchain images live on the
    // first injecting device.
    let mut all = Vec::new();
    let xr = Xr::new()?;
    for bottom in [Bottom::Lavapipe, Bottom::Null] {
        if bottom == Bottom::Null {
            // Read by the double at vkCreateDevice.
            std::env::set_var(fovea_vkdouble::NULL_COMMANDS_ENV, "1");
        }
        let bare = Side::new(&entry, Kind::Bare)?;
        let fovea = Side::new(&entry, Kind::Fdm)?;
        if let Err(e) = proves_reconstruction(&double, &fovea) {
            panic!(
                "vk_commands: the emulating device ({} bottom) does not reconstruct, so its \
                 reconstructed rows would measure nothing: {e}",
                bottom.name()
            );
        }
        double.clear();
        let inject = Side::injecting(&entry, &xr)?;
        if let Err(e) = proves_injection(&double, &inject, bottom) {
            panic!(
                "vk_commands: the injecting device ({} bottom) does not inject, so its rows would \
                 measure nothing: {e}",
                bottom.name()
            );
        }
        all.push(Sides {
            bottom,
            bare,
            fovea,
            inject,
        });
    }
    std::env::remove_var(fovea_vkdouble::NULL_COMMANDS_ENV);
    // The entry (the loader library) must outlive every instance: keep it for the process.
    std::mem::forget(entry);
    Ok((all, xr, double))
}

fn bench(c: &mut Criterion, sides: &Sides) {
    let mut g = c.benchmark_group(format!("vk_commands/{}", sides.bottom.name()));
    for case in Case::ALL {
        for (label, side, recorded) in [
            ("bare", &sides.bare, case.bare()),
            ("fovea", sides.fovea_for(case), case),
        ] {
            g.bench_function(format!("{}/{label}", case.name()), |b| {
                b.iter_custom(|iters| {
                    let mut total = Duration::ZERO;
                    let mut left = iters as usize;
                    while left > 0 {
                        let n = left.min(ROUND);
                        total += side.round(recorded, n).expect("recordable").0;
                        left -= n;
                    }
                    total
                })
            });
        }
    }
    g.finish();
}

/// Interleaved rounds of both sides, case by case: the summary table. Returns the cases where the
/// layer allocated per command on the null bottom (fewest allocations in a round, fovea's above
/// the bare device's).
fn summary(sides: &Sides) -> Vec<String> {
    let (bottom, bare) = (sides.bottom, &sides.bare);
    let mut added = Vec::new();
    const ROUNDS: usize = 200;
    println!(
        "\nvk_commands summary, {} below the layers: median ns per command over {ROUNDS} \
         interleaved rounds of {ROUND}; allocations per command (fewest in a round)",
        bottom.name()
    );
    println!(
        "{:<46} {:>9} {:>9} {:>9} {:>7} {:>11} {:>11}",
        "command", "bare ns", "fovea ns", "added ns", "ratio", "bare alloc", "fovea alloc"
    );
    for case in Case::ALL {
        let (mut tb, mut tf) = (Vec::new(), Vec::new());
        let (mut ab, mut af) = (u64::MAX, u64::MAX);
        for _ in 0..ROUNDS {
            let (t, a) = bare.round(case.bare(), ROUND).expect("recordable");
            tb.push(t.as_nanos() as f64 / ROUND as f64);
            ab = ab.min(a);
            let (t, a) = sides
                .fovea_for(case)
                .round(case, ROUND)
                .expect("recordable");
            tf.push(t.as_nanos() as f64 / ROUND as f64);
            af = af.min(a);
        }
        let (b, f) = (median(tb), median(tf));
        println!(
            "{:<46} {:>9.1} {:>9.1} {:>9.1} {:>7.3} {:>11.2} {:>11.2}",
            case.name(),
            b,
            f,
            f - b,
            f / b,
            ab as f64 / ROUND as f64,
            af as f64 / ROUND as f64,
        );
        // On lavapipe the density-map cases make the driver record more than the bare device's
        // stand-in (the shadow's barrier, a shading-rate attachment): only the null bottom
        // compares the layers' own allocations.
        if bottom == Bottom::Null && af > ab {
            added.push(format!(
                "{} ({}): {af} allocations in {ROUND} commands, {ab} without the layer",
                case.name(),
                bottom.name()
            ));
        }
    }
    added
}

fn benches() {
    let (all, xr, _double) = match sides() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("vk_commands: skipped: {e}");
            return;
        }
    };
    // Warm up (lavapipe's command pools grow to their steady size; the layer's scratch too; the
    // injected map is made at the first injected begin).
    for sides in &all {
        for case in Case::ALL {
            for _ in 0..4 {
                sides.bare.round(case.bare(), ROUND);
                sides.fovea_for(case).round(case, ROUND);
            }
        }
    }
    let mut c = Criterion::default()
        .sample_size(20)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1))
        .configure_from_args();
    for sides in &all {
        bench(&mut c, sides);
    }
    c.final_summary();
    let mut added = Vec::new();
    for sides in &all {
        added.extend(summary(sides));
    }
    for sides in &all {
        reconstruction_summary(sides);
    }
    // Recording allocates nothing in the layer, density-map commands included: a regression fails
    // the run.
    assert!(
        added.is_empty(),
        "the layer allocates while recording:\n{}",
        added.join("\n")
    );
    // The session's swapchain images live on the first injecting device.
    drop(xr);
    drop(all);
}

fn main() {
    benches();
}
