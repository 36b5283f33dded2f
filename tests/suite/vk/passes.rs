//! fovea's Vulkan layer on lavapipe: the attachment path. An application draws through a
//! fragment-density-map attachment (render pass v1 and v2, multiview and per-eye, imageless
//! framebuffer, dynamic rendering); the layer hands the driver shading-rate attachments that name
//! its shadows instead.
//!
//! Stack as in [`crate::support::device`]: this test → fovea → VK_LAYER_KHRONOS_validation → the double
//! (`nvidia`: 16×16 texels, layered; `amd`: 8×8, one layer) → lavapipe. For each case and profile:
//! validation says nothing and the double records no misuse; every pass (or rendering) reached the
//! double with a shading-rate attachment of the device's texel that is a shadow (R8_UINT, 2 layers
//! on `nvidia`, 1 merged layer on `amd`); every draw gets, per view and per attachment texel, the
//! effective fragment size the GPU the double plays would shade with (the application's map holds
//! a different density per layer: 2×2 and 4×4), the one of its layer of the map; and the colour
//! read back equals the same draw without fovea and without the density map (lavapipe renders at
//! 1×1 under the double either way).

use std::collections::HashSet;
use std::ffi::CStr;

use ash::vk;
use ash::vk::Handle as _;
use fovea_vkdouble::Profile;
use serde_json::{json, Value};

use crate::support::device::{
    assert_no_messages, assert_only_stage_false_positives, env, take_messages, Dev, Env, Features,
    Vk,
};
use crate::support::vulkan::{
    allocate_info, attachments, attachments2, draw_fullscreen, image_info, range, spv, stages,
    Fixed, AREA, CLEAR, COLOR, DENSITY, FDM_LAYOUT, FRAGMENT, SIZE, VERTEX,
};

/// The colour attachment's width and height.
const FSR_LAYOUT: vk::ImageLayout = vk::ImageLayout::FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Case {
    /// `vkCreateRenderPass`, one view.
    V1,
    /// `vkCreateRenderPass` with `VkRenderPassMultiviewCreateInfo`, view mask 0b11.
    V1Multiview,
    /// `vkCreateRenderPass2`, one view.
    V2,
    /// `vkCreateRenderPass2`, subpass view mask 0b11.
    V2Multiview,
    /// One version-2 pass per eye, each on its layer of the colour and density images.
    PerEye,
    /// An imageless framebuffer; the views arrive with `vkCmdBeginRenderPass2`.
    Imageless,
    /// `vkCmdBeginRendering` with `VkRenderingFragmentDensityMapAttachmentInfoEXT`.
    Dynamic,
}

impl Case {
    fn multiview(self) -> bool {
        matches!(self, Case::V1Multiview | Case::V2Multiview)
    }

    /// The colour image's layers.
    fn layers(self) -> u32 {
        if self.multiview() || self == Case::PerEye {
            2
        } else {
            1
        }
    }

    /// The framebuffers (or renderings): one per eye for per-eye passes.
    fn passes(self) -> u32 {
        if self == Case::PerEye {
            2
        } else {
            1
        }
    }
}

/// The device the cases draw on ([`Vk::device_with`]): multiview and imageless framebuffers and,
/// with `fdm`, density maps.
fn device(vk: &Vk, fdm: bool) -> ash::Device {
    vk.device_with(
        &[],
        Features {
            fdm,
            multiview: true,
        },
        None,
    )
}

/// # Safety
/// `dev` must be alive.
unsafe fn memory_for(
    dev: &Dev,
    req: vk::MemoryRequirements,
    want: vk::MemoryPropertyFlags,
) -> vk::DeviceMemory {
    // SAFETY: the caller's promise.
    unsafe {
        dev.d
            .allocate_memory(&allocate_info(&dev.memory, req, want), None)
    }
    .expect("vkAllocateMemory")
}

/// # Safety
/// `dev` must be alive.
unsafe fn image(
    dev: &Dev,
    format: vk::Format,
    size: u32,
    layers: u32,
    usage: vk::ImageUsageFlags,
) -> (vk::Image, vk::DeviceMemory) {
    // SAFETY: the caller's promise; structs live across the calls.
    unsafe {
        let image = dev
            .d
            .create_image(&image_info(format, size, layers, usage), None)
            .expect("vkCreateImage");
        let req = dev.d.get_image_memory_requirements(image);
        let memory = memory_for(dev, req, vk::MemoryPropertyFlags::DEVICE_LOCAL);
        dev.d.bind_image_memory(image, memory, 0).unwrap();
        (image, memory)
    }
}

/// A view of `layers` layers from `base`, 2D-array where `array`.
fn view(
    dev: &Dev,
    image: vk::Image,
    format: vk::Format,
    base: u32,
    layers: u32,
    array: bool,
) -> vk::ImageView {
    let ty = if array {
        vk::ImageViewType::TYPE_2D_ARRAY
    } else {
        vk::ImageViewType::TYPE_2D
    };
    // SAFETY: the image is alive; the struct lives across the call.
    unsafe {
        dev.d.create_image_view(
            &vk::ImageViewCreateInfo::default()
                .image(image)
                .view_type(ty)
                .format(format)
                .subresource_range(range(base, layers)),
            None,
        )
    }
    .expect("vkCreateImageView")
}

fn shader(dev: &Dev, bytes: &[u8]) -> vk::ShaderModule {
    let words = spv(bytes);
    // SAFETY: the words live across the call.
    unsafe {
        dev.d
            .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
    }
    .unwrap()
}

/// The case's render pass; with `fdm`, attachment 1 is the density map.
fn render_pass(dev: &Dev, case: Case, fdm: bool) -> vk::RenderPass {
    let d = &dev.d;
    let mask = if case.multiview() { 0b11 } else { 0 };
    let fdm_ref = vk::AttachmentReference {
        attachment: 1,
        layout: FDM_LAYOUT,
    };
    let mut fdm_info = vk::RenderPassFragmentDensityMapCreateInfoEXT::default()
        .fragment_density_map_attachment(fdm_ref);
    let count = if fdm { 2 } else { 1 };
    // SAFETY: every struct lives across the calls.
    unsafe {
        if matches!(case, Case::V1 | Case::V1Multiview) {
            let atts = attachments(vk::ImageLayout::TRANSFER_SRC_OPTIMAL);
            let color = [vk::AttachmentReference {
                attachment: 0,
                layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
            }];
            let subpass = [vk::SubpassDescription::default()
                .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
                .color_attachments(&color)];
            let deps = [vk::SubpassDependency::default()
                .src_subpass(0)
                .dst_subpass(vk::SUBPASS_EXTERNAL)
                .src_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
                .dst_stage_mask(vk::PipelineStageFlags::TRANSFER)
                .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                .dst_access_mask(vk::AccessFlags::TRANSFER_READ)];
            let masks = [mask];
            let correlation = [mask];
            let mut multiview = vk::RenderPassMultiviewCreateInfo::default()
                .view_masks(&masks)
                .correlation_masks(&correlation);
            let mut info = vk::RenderPassCreateInfo::default()
                .attachments(&atts[..count])
                .subpasses(&subpass)
                .dependencies(&deps);
            if case.multiview() {
                info = info.push_next(&mut multiview);
            }
            if fdm {
                info = info.push_next(&mut fdm_info);
            }
            d.create_render_pass(&info, None)
        } else {
            let atts = attachments2(vk::ImageLayout::TRANSFER_SRC_OPTIMAL);
            let color = [vk::AttachmentReference2::default()
                .attachment(0)
                .layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)];
            let subpass = [vk::SubpassDescription2::default()
                .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
                .view_mask(mask)
                .color_attachments(&color)];
            let deps = [vk::SubpassDependency2::default()
                .src_subpass(0)
                .dst_subpass(vk::SUBPASS_EXTERNAL)
                .src_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
                .dst_stage_mask(vk::PipelineStageFlags::TRANSFER)
                .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                .dst_access_mask(vk::AccessFlags::TRANSFER_READ)];
            let correlation = [mask];
            let mut info = vk::RenderPassCreateInfo2::default()
                .attachments(&atts[..count])
                .subpasses(&subpass)
                .dependencies(&deps);
            if case.multiview() {
                info = info.correlated_view_masks(&correlation);
            }
            if fdm {
                info = info.push_next(&mut fdm_info);
            }
            d.create_render_pass2(&info, None)
        }
    }
    .unwrap_or_else(|e| panic!("{case:?}: render pass: {e}; {:?}", take_messages()))
}

fn pipeline(
    dev: &Dev,
    case: Case,
    fdm: bool,
    pass: vk::RenderPass,
    layout: vk::PipelineLayout,
    modules: [vk::ShaderModule; 2],
) -> vk::Pipeline {
    let stages = stages(modules);
    let fixed = Fixed::new();
    let formats = [COLOR];
    let mut rendering =
        vk::PipelineRenderingCreateInfo::default().color_attachment_formats(&formats);
    let mut info = fixed.info(&stages, layout);
    if case == Case::Dynamic {
        info = info.push_next(&mut rendering);
        if fdm {
            // As an application does: fovea's pipeline path swaps the flag for the shading-rate
            // one and adds the rate state that lets the attachment decide.
            info =
                info.flags(vk::PipelineCreateFlags::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_EXT);
        }
    } else {
        info = info.render_pass(pass).subpass(0);
    }
    // SAFETY: every struct lives across the call.
    unsafe {
        dev.d
            .create_graphics_pipelines(vk::PipelineCache::null(), &[info], None)
    }
    .unwrap_or_else(|e| panic!("{case:?}: pipeline: {:?}; {:?}", e.1, take_messages()))[0]
}

/// What one draw left behind.
struct Drawn {
    /// Every colour layer, tightly packed RGBA8.
    pixels: Vec<u8>,
    command_buffer: u64,
}

/// Draws the case once: with `fdm`, through fovea and a 2-layer density map; without, with no
/// density map and no fovea.
fn draw(env: &Env, profile: Profile, case: Case, fdm: bool) -> Drawn {
    let vk = Vk::new(env, profile, fdm).expect("an instance");
    let texel = vk
        .fdm_properties()
        .max_fragment_density_texel_size
        .width
        .max(1);
    let device = device(&vk, fdm);
    // SAFETY: plain queries and creations on live objects; everything is destroyed before the
    // device, after the queue is idle.
    unsafe {
        let dev = Dev::new(&vk, device);
        let d = &dev.d;
        let layers = case.layers();
        let (color, color_mem) = image(
            &dev,
            COLOR,
            SIZE,
            layers,
            vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
        );
        let n = SIZE.div_ceil(texel);
        let density_usage =
            vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT | vk::ImageUsageFlags::TRANSFER_DST;
        let density = fdm.then(|| image(&dev, DENSITY, n, 2, density_usage));
        // Per pass: the colour view and the density view.
        let views: Vec<(vk::ImageView, Option<vk::ImageView>)> = (0..case.passes())
            .map(|eye| {
                let (base, count, array) = match case {
                    Case::PerEye => (eye, 1, false),
                    c if c.multiview() => (0, 2, true),
                    _ => (0, 1, false),
                };
                (
                    view(&dev, color, COLOR, base, count, array),
                    density.map(|(img, _)| view(&dev, img, DENSITY, base, count, array)),
                )
            })
            .collect();
        let pass = (case != Case::Dynamic).then(|| render_pass(&dev, case, fdm));
        let framebuffers: Vec<vk::Framebuffer> = match pass {
            None => Vec::new(),
            Some(pass) if case == Case::Imageless => {
                let color_formats = [COLOR];
                let density_formats = [DENSITY];
                let infos = [
                    vk::FramebufferAttachmentImageInfo::default()
                        .usage(
                            vk::ImageUsageFlags::COLOR_ATTACHMENT
                                | vk::ImageUsageFlags::TRANSFER_SRC,
                        )
                        .width(SIZE)
                        .height(SIZE)
                        .layer_count(1)
                        .view_formats(&color_formats),
                    vk::FramebufferAttachmentImageInfo::default()
                        .usage(density_usage)
                        .width(n)
                        .height(n)
                        .layer_count(1)
                        .view_formats(&density_formats),
                ];
                let count = if fdm { 2 } else { 1 };
                let mut attachments = vk::FramebufferAttachmentsCreateInfo::default()
                    .attachment_image_infos(&infos[..count]);
                let mut info = vk::FramebufferCreateInfo::default()
                    .flags(vk::FramebufferCreateFlags::IMAGELESS)
                    .render_pass(pass)
                    .width(SIZE)
                    .height(SIZE)
                    .layers(1)
                    .push_next(&mut attachments);
                info.attachment_count = count as u32;
                vec![d.create_framebuffer(&info, None).unwrap_or_else(|e| {
                    panic!("{case:?}: framebuffer: {e}; {:?}", take_messages())
                })]
            }
            Some(pass) => views
                .iter()
                .map(|(c, f)| {
                    let list: Vec<vk::ImageView> = std::iter::once(*c).chain(*f).collect();
                    d.create_framebuffer(
                        &vk::FramebufferCreateInfo::default()
                            .render_pass(pass)
                            .attachments(&list)
                            .width(SIZE)
                            .height(SIZE)
                            .layers(1),
                        None,
                    )
                    .unwrap_or_else(|e| panic!("{case:?}: framebuffer: {e}; {:?}", take_messages()))
                })
                .collect(),
        };
        let modules = [shader(&dev, VERTEX), shader(&dev, FRAGMENT)];
        let layout = d
            .create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default(), None)
            .unwrap();
        let pipe = pipeline(&dev, case, fdm, pass.unwrap_or_default(), layout, modules);
        let size = (SIZE * SIZE * 4 * layers) as u64;
        let readback = d
            .create_buffer(
                &vk::BufferCreateInfo::default()
                    .size(size)
                    .usage(vk::BufferUsageFlags::TRANSFER_DST),
                None,
            )
            .unwrap();
        let readback_mem = memory_for(
            &dev,
            d.get_buffer_memory_requirements(readback),
            vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
        );
        d.bind_buffer_memory(readback, readback_mem, 0).unwrap();

        let cb = d
            .allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(dev.pool)
                    .level(vk::CommandBufferLevel::PRIMARY)
                    .command_buffer_count(1),
            )
            .unwrap()[0];
        d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
            .unwrap();
        if let Some((img, _)) = density {
            // The application writes its map: layer 0 [`DENSITY_BYTES`]`[0]`, layer 1 `[1]`.
            let to_dst = vk::ImageMemoryBarrier::default()
                .image(img)
                .subresource_range(range(0, 2))
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
            for (layer, byte) in DENSITY_BYTES.iter().enumerate() {
                let v = *byte as f32 / 255.0;
                d.cmd_clear_color_image(
                    cb,
                    img,
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                    &vk::ClearColorValue {
                        float32: [v, v, 0.0, 0.0],
                    },
                    &[range(layer as u32, 1)],
                );
            }
            let to_fdm = vk::ImageMemoryBarrier::default()
                .image(img)
                .subresource_range(range(0, 2))
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
        }
        let draw_it = || {
            draw_fullscreen(d, cb, pipe);
        };
        match pass {
            None => {
                let barrier = |old, new, src, dst| {
                    vk::ImageMemoryBarrier::default()
                        .image(color)
                        .subresource_range(range(0, layers))
                        .old_layout(old)
                        .new_layout(new)
                        .src_access_mask(src)
                        .dst_access_mask(dst)
                };
                d.cmd_pipeline_barrier(
                    cb,
                    vk::PipelineStageFlags::TOP_OF_PIPE,
                    vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[barrier(
                        vk::ImageLayout::UNDEFINED,
                        vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
                        vk::AccessFlags::empty(),
                        vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
                    )],
                );
                let color_att = [vk::RenderingAttachmentInfo::default()
                    .image_view(views[0].0)
                    .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::STORE)
                    .clear_value(CLEAR[0])];
                let mut density_att = vk::RenderingFragmentDensityMapAttachmentInfoEXT::default()
                    .image_view(views[0].1.unwrap_or_default())
                    .image_layout(FDM_LAYOUT);
                let mut info = vk::RenderingInfo::default()
                    .render_area(AREA)
                    .layer_count(1)
                    .color_attachments(&color_att);
                if fdm {
                    info = info.push_next(&mut density_att);
                }
                d.cmd_begin_rendering(cb, &info);
                draw_it();
                d.cmd_end_rendering(cb);
                d.cmd_pipeline_barrier(
                    cb,
                    vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[barrier(
                        vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
                        vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                        vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
                        vk::AccessFlags::TRANSFER_READ,
                    )],
                );
            }
            Some(pass) => {
                for (i, fb) in framebuffers.iter().enumerate() {
                    let list: Vec<vk::ImageView> =
                        std::iter::once(views[i].0).chain(views[i].1).collect();
                    let mut begin_views =
                        vk::RenderPassAttachmentBeginInfo::default().attachments(&list);
                    let mut begin = vk::RenderPassBeginInfo::default()
                        .render_pass(pass)
                        .framebuffer(*fb)
                        .render_area(AREA)
                        .clear_values(&CLEAR);
                    if case == Case::Imageless {
                        begin = begin.push_next(&mut begin_views);
                    }
                    if matches!(case, Case::V1 | Case::V1Multiview) {
                        d.cmd_begin_render_pass(cb, &begin, vk::SubpassContents::INLINE);
                        draw_it();
                        d.cmd_end_render_pass(cb);
                    } else {
                        d.cmd_begin_render_pass2(
                            cb,
                            &begin,
                            &vk::SubpassBeginInfo::default().contents(vk::SubpassContents::INLINE),
                        );
                        draw_it();
                        d.cmd_end_render_pass2(cb, &vk::SubpassEndInfo::default());
                    }
                }
            }
        }
        d.cmd_copy_image_to_buffer(
            cb,
            color,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            readback,
            &[vk::BufferImageCopy::default()
                .image_subresource(vk::ImageSubresourceLayers {
                    aspect_mask: vk::ImageAspectFlags::COLOR,
                    mip_level: 0,
                    base_array_layer: 0,
                    layer_count: layers,
                })
                .image_extent(vk::Extent3D {
                    width: SIZE,
                    height: SIZE,
                    depth: 1,
                })],
        );
        let host = vk::BufferMemoryBarrier::default()
            .buffer(readback)
            .size(vk::WHOLE_SIZE)
            .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ);
        d.cmd_pipeline_barrier(
            cb,
            vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::HOST,
            vk::DependencyFlags::empty(),
            &[],
            &[host],
            &[],
        );
        d.end_command_buffer(cb).unwrap();
        let cbs = [cb];
        d.queue_submit(
            dev.queue,
            &[vk::SubmitInfo::default().command_buffers(&cbs)],
            vk::Fence::null(),
        )
        .expect("vkQueueSubmit");
        d.queue_wait_idle(dev.queue).unwrap();
        let p = d
            .map_memory(readback_mem, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())
            .unwrap();
        let pixels = std::slice::from_raw_parts(p as *const u8, size as usize).to_vec();
        d.unmap_memory(readback_mem);

        d.free_command_buffers(dev.pool, &cbs);
        d.destroy_buffer(readback, None);
        d.free_memory(readback_mem, None);
        d.destroy_pipeline(pipe, None);
        d.destroy_pipeline_layout(layout, None);
        for m in modules {
            d.destroy_shader_module(m, None);
        }
        for fb in framebuffers {
            d.destroy_framebuffer(fb, None);
        }
        if let Some(p) = pass {
            d.destroy_render_pass(p, None);
        }
        for (c, f) in views {
            d.destroy_image_view(c, None);
            if let Some(f) = f {
                d.destroy_image_view(f, None);
            }
        }
        for (img, mem) in [(color, color_mem)].into_iter().chain(density) {
            d.destroy_image(img, None);
            d.free_memory(mem, None);
        }
        dev.destroy();
        drop(vk);
        Drawn {
            pixels,
            command_buffer: cb.as_raw(),
        }
    }
}

/// What the application writes into its density map's two layers: densities 0.3 (a 2×2
/// fragment) and 0.1 (4×4), so a pass whose pipelines ignored the attachment, or read the wrong
/// layer, shades visibly differently.
const DENSITY_BYTES: [u8; 2] = [77, 26];

/// The fragment size code a draw gets from layer `layer` of the map on `profile`: 2×2 and 4×4 on
/// `nvidia`; on `amd` 2×2 for both (one merged layer holding the finer, fragments up to 2×2).
fn code_of(profile: Profile, layer: usize) -> u8 {
    match (profile, layer) {
        (Profile::Nvidia, 1) => 0b1010,
        _ => 0b0101,
    }
}

fn texel_of(profile: Profile) -> u32 {
    match profile {
        Profile::Amd => 8,
        _ => 16,
    }
}

/// Draws `case` on both profiles with and without fovea and checks what the double saw.
fn check(case: Case) {
    let Some((_serial, env)) = env() else { return };
    for profile in [Profile::Nvidia, Profile::Amd] {
        let reference = draw(env, profile, case, false);
        assert_no_messages();
        let drawn = draw(env, profile, case, true);
        assert_eq!(
            env.double.errors(),
            Vec::<String>::new(),
            "{case:?} {profile:?}"
        );
        // The application's barrier into the density-map layout reaches validation 1.3.239 as
        // one into the shading-rate stage ([`assert_only_stage_false_positives`]).
        assert_only_stage_false_positives();
        // The shader's colour: red on the left 32 columns only, in every layer drawn. (lavapipe
        // 22.3 draws a multiview pass's second view as cleared only, with or without fovea; the
        // comparison below covers it.)
        let drawn_layers = if case.multiview() { 1 } else { case.layers() };
        for layer in 0..drawn_layers {
            for (x, red) in [(0, 255), (31, 255), (32, 0), (SIZE - 1, 0)] {
                let i = ((layer * SIZE * SIZE + (SIZE / 2) * SIZE + x) * 4) as usize;
                assert_eq!(
                    reference.pixels[i],
                    red,
                    "{case:?}: layer {layer}, x {x}: {:?}",
                    &reference.pixels[i..i + 4]
                );
            }
        }
        assert!(
            drawn.pixels == reference.pixels,
            "{case:?} {profile:?}: the colour differs from the draw without fovea"
        );
        let texel = texel_of(profile);
        let n = SIZE / texel;
        let shadow_layers = if profile == Profile::Nvidia { 2 } else { 1 };
        // The shadows: the double sees only images with the shading-rate usage.
        let images = env.double.events("image");
        assert_eq!(
            images.len(),
            1,
            "{case:?} {profile:?}: one shadow: {images:?}"
        );
        let shadow = &images[0];
        assert_eq!(shadow["format"], vk::Format::R8_UINT.as_raw());
        assert_eq!(shadow["extent"], json!([n, n]));
        assert_eq!(shadow["layers"], shadow_layers, "{case:?} {profile:?}");
        let shadow_views: HashSet<u64> = env
            .double
            .events("image_view")
            .iter()
            .filter(|v| v["image"] == shadow["image"])
            .map(|v| v["view"].as_u64().unwrap())
            .collect();
        assert_eq!(
            shadow_views.len() as u32,
            case.passes(),
            "{case:?} {profile:?}"
        );
        let is_shadow = |v: &Value| v.as_u64().is_some_and(|v| shadow_views.contains(&v));
        let rate = json!({
            "attachment": 1,
            "layout": FSR_LAYOUT.as_raw(),
            "texel": [texel, texel],
        });
        if case == Case::Dynamic {
            let begins = env.double.events("begin_rendering");
            assert_eq!(begins.len(), 1, "{begins:?}");
            let r = &begins[0]["shading_rate"];
            assert!(is_shadow(&r["view"]), "{profile:?}: {r}");
            assert_eq!(r["layout"], FSR_LAYOUT.as_raw());
            assert_eq!(r["texel"], json!([texel, texel]));
        } else {
            let passes = env.double.events("render_pass");
            assert_eq!(passes.len(), 1, "{case:?} {profile:?}: {passes:?}");
            assert_eq!(
                passes[0]["attachments"][1]["format"],
                vk::Format::R8_UINT.as_raw()
            );
            for s in passes[0]["subpasses"].as_array().unwrap() {
                assert_eq!(s["shading_rate"], rate, "{case:?} {profile:?}");
            }
            let begins = env.double.events("begin_render_pass");
            assert_eq!(begins.len() as u32, case.passes(), "{begins:?}");
            for b in &begins {
                let v = b["shading_rate_views"].as_array().unwrap();
                assert!(
                    v.len() == 1 && is_shadow(&v[0]),
                    "{case:?} {profile:?}: {b}"
                );
            }
        }
        // What the GPU would shade: every draw gets, at every texel of every view, the rate of its
        // layer of the map (the view index under multiview, the eye's layer per eye).
        let draws: Vec<_> = env
            .double
            .draws()
            .into_iter()
            .filter(|dr| dr.command_buffer == drawn.command_buffer)
            .collect();
        assert_eq!(draws.len() as u32, case.passes(), "{case:?} {profile:?}");
        for (pass, dr) in draws.iter().enumerate() {
            assert_eq!(dr.pass, pass, "{case:?} {profile:?}");
            assert_eq!(dr.rendering, case == Case::Dynamic);
            let views = if case.multiview() { 2 } else { 1 };
            assert_eq!(dr.views.len(), views, "{case:?} {profile:?}: {dr:?}");
            for v in &dr.views {
                let layer = if case == Case::PerEye {
                    pass
                } else {
                    v.view as usize
                };
                assert_eq!((v.columns, v.rows), (n, n), "{case:?} {profile:?}");
                let want = vec![code_of(profile, layer); (n * n) as usize];
                assert_eq!(
                    v.codes, want,
                    "{case:?} {profile:?}: pass {pass} view {}",
                    v.view
                );
            }
        }
        let _ = shadow_layers;
    }
}

#[test]
fn render_pass_v1_density_map_becomes_shading_rate_attachment() {
    check(Case::V1);
}

#[test]
fn render_pass_v1_multiview_is_upgraded_with_view_masks() {
    check(Case::V1Multiview);
}

#[test]
fn render_pass_v2_density_map_becomes_shading_rate_attachment() {
    check(Case::V2);
}

#[test]
fn render_pass_v2_multiview_uses_a_layered_or_merged_shadow() {
    check(Case::V2Multiview);
}

#[test]
fn per_eye_passes_use_their_layer_of_the_shadow() {
    check(Case::PerEye);
}

#[test]
fn imageless_framebuffer_gets_the_shadow_view_at_begin() {
    check(Case::Imageless);
}

#[test]
fn dynamic_rendering_gets_a_shading_rate_attachment() {
    check(Case::Dynamic);
}

/// The names the layer answers with its own hooks on an emulating device include the attachment
/// path's; checked through the loader's `vkGetDeviceProcAddr`, which hands out the first layer's.
#[test]
fn attachment_commands_are_intercepted_on_emulating_devices() {
    let Some((_serial, env)) = env() else { return };
    let plain = Vk::new(env, Profile::Nvidia, false).expect("instance");
    let reference = device(&plain, false);
    let vk = Vk::new(env, Profile::Nvidia, true).expect("instance");
    let emulating = device(&vk, true);
    let gdpa = |i: &ash::Instance, d: &ash::Device, name: &CStr| {
        // SAFETY: a live device of that instance and a NUL-terminated name.
        unsafe { (i.fp_v1_0().get_device_proc_addr)(d.handle(), name.as_ptr()) }.map(|f| f as usize)
    };
    for name in [
        c"vkCreateImageView",
        c"vkCreateRenderPass",
        c"vkCreateRenderPass2",
        c"vkCreateFramebuffer",
        c"vkCmdBeginRenderPass",
        c"vkCmdBeginRenderPass2",
        c"vkCmdBeginRendering",
    ] {
        assert_ne!(
            gdpa(&vk.instance, &emulating, name),
            gdpa(&plain.instance, &reference, name),
            "{name:?}"
        );
    }
    // SAFETY: destroyed once each, nothing made from them.
    unsafe {
        emulating.destroy_device(None);
        reference.destroy_device(None);
    }
    drop(vk);
    drop(plain);
    assert_no_messages();
}
