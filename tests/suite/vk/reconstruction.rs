//! Reconstruction of coarse blocks on an emulating device (docs/reconstruction.md), from pixels
//! read back: an application renders a texture-like pattern (every pixel its own colour) through
//! a density map that asks for the coarsest fragments in the left half and full rate in the
//! right, into a colour image it created with `VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT` (or without:
//! the blocky reference), and copies the image out in the same command buffer, after the pass.
//! The double leaves the pass's colour coarse at its end as a GPU would, so without
//! reconstruction nearly every block of the left half is uniform; with it few are, and every
//! pixel of the right half (shaded 1×1) is bit-identical to the blocky frame's. Render passes
//! (v2, and multiview over two layers), dynamic rendering, UNORM and sRGB; a format the layer
//! does not decode is left as it was.
//!
//! Stack as in [`crate::support::device`]: this test → fovea → validation → the double → lavapipe.

use ash::vk;
use fovea_vkdouble::Profile;

use crate::support::device::{assert_only_stage_false_positives, env, Dev, Features, Vk};
use crate::support::vulkan::{allocate_info, range, spv, stages, Fixed, FDM_LAYOUT, VERTEX};

const SIDE: u32 = 128;
const PATTERN: &[u8] = include_bytes!("../shaders/pattern.frag.spv");
/// The density the left half asks for (4×4 where the device has it) and the right half's (1×1).
const COARSE: u8 = 26;
const FULL: u8 = 255;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Case {
    Pass,
    Multiview,
    Dynamic,
    /// A render pass drawing 4 samples a pixel, resolved into the image read back.
    Msaa,
    /// Dynamic rendering drawing 4 samples a pixel, resolved into the image read back.
    DynamicMsaa,
    /// A render pass with two colour attachments, both read back, both loading a pattern that
    /// the draw leaves as it is (its write masks are empty).
    Mrt,
    /// The same in dynamic rendering.
    DynamicMrt,
    /// As `Pass`, with an imageless framebuffer whose colour attachment names the usage the
    /// application gave its image: `COLOR_ATTACHMENT | TRANSFER_SRC` (for the read-back), without
    /// the `TRANSFER_DST` reconstruction adds to a subsampled image.
    Imageless,
    /// As `Pass`, drawn in the second subpass of a pass whose first names no attachment.
    Subpass,
}

impl Case {
    fn msaa(self) -> bool {
        matches!(self, Case::Msaa | Case::DynamicMsaa)
    }

    fn dynamic(self) -> bool {
        matches!(self, Case::Dynamic | Case::DynamicMsaa | Case::DynamicMrt)
    }

    fn mrt(self) -> bool {
        matches!(self, Case::Mrt | Case::DynamicMrt)
    }
}

struct Drawn {
    /// Every layer (of every colour attachment read back), tightly packed, 4 bytes a pixel.
    pixels: Vec<u8>,
    layers: u32,
    /// Layer 1's map was mirrored (coarse on the right).
    mirrored: bool,
}

/// Draws `case` once on `profile` into a `format` image, subsampled or not, on a device of its
/// own.
fn draw(profile: Profile, case: Case, format: vk::Format, subsampled: bool) -> Option<Drawn> {
    let (_serial, env) = env()?;
    let vk = Vk::new(env, profile, true)?;
    let device = vk.device_with(&[], Features::FDM_MULTIVIEW, None);
    let dev = Dev::new(&vk, device);
    // A device with one rate layer per view gets a second layer mirrored; one that merges them
    // (the finer rate of all views) the same map in both.
    let mirrored = case == Case::Multiview && profile.layered();
    let drawn = draw_on(&vk, &dev, case, format, subsampled, mirrored);
    dev.destroy();
    assert_only_stage_false_positives();
    drop(vk);
    Some(drawn)
}

/// Draws `case` once on `dev` (made on `vk`): everything but the device is made and destroyed
/// here.
fn draw_on(
    vk: &Vk,
    dev: &Dev,
    case: Case,
    format: vk::Format,
    subsampled: bool,
    mirrored: bool,
) -> Drawn {
    let texel = vk
        .fdm_properties()
        .max_fragment_density_texel_size
        .width
        .max(1);
    let layers = if case == Case::Multiview { 2 } else { 1 };
    // SAFETY: creations and commands on live objects, all destroyed before the function returns,
    // after the queue is idle; every struct lives across its call.
    unsafe {
        let d = &dev.d;
        let image = |format, side, layers, usage, flags, samples| {
            let info = vk::ImageCreateInfo::default()
                .flags(flags)
                .image_type(vk::ImageType::TYPE_2D)
                .format(format)
                .extent(vk::Extent3D {
                    width: side,
                    height: side,
                    depth: 1,
                })
                .mip_levels(1)
                .array_layers(layers)
                .samples(samples)
                .tiling(vk::ImageTiling::OPTIMAL)
                .usage(usage);
            let i = d.create_image(&info, None).expect("vkCreateImage");
            let req = d.get_image_memory_requirements(i);
            let m = d
                .allocate_memory(
                    &allocate_info(&dev.memory, req, vk::MemoryPropertyFlags::DEVICE_LOCAL),
                    None,
                )
                .unwrap();
            d.bind_image_memory(i, m, 0).unwrap();
            (i, m)
        };
        let view = |i, format, layers: u32| {
            let ty = if layers > 1 {
                vk::ImageViewType::TYPE_2D_ARRAY
            } else {
                vk::ImageViewType::TYPE_2D
            };
            d.create_image_view(
                &vk::ImageViewCreateInfo::default()
                    .image(i)
                    .view_type(ty)
                    .format(format)
                    .subresource_range(range(0, layers)),
                None,
            )
            .unwrap()
        };
        let flags = if subsampled {
            vk::ImageCreateFlags::SUBSAMPLED_EXT
        } else {
            vk::ImageCreateFlags::empty()
        };
        let colour_usage = if case == Case::Imageless {
            vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC
        } else {
            vk::ImageUsageFlags::COLOR_ATTACHMENT
                | vk::ImageUsageFlags::TRANSFER_SRC
                | vk::ImageUsageFlags::TRANSFER_DST
        };
        let (colour, colour_mem) = image(
            format,
            SIDE,
            layers,
            colour_usage,
            flags,
            vk::SampleCountFlags::TYPE_1,
        );
        // Multisampled: the pass draws 4 samples a pixel into an image of its own and resolves
        // into `colour`, which is read back.
        let samples = vk::SampleCountFlags::TYPE_4;
        let ms = case.msaa().then(|| {
            let (i, m) = image(
                format,
                SIDE,
                layers,
                vk::ImageUsageFlags::COLOR_ATTACHMENT,
                vk::ImageCreateFlags::empty(),
                samples,
            );
            (i, m, view(i, format, layers))
        });
        // Two colour attachments: the second, `second`, as subsampled as the first.
        let second = case.mrt().then(|| {
            let (i, m) = image(
                format,
                SIDE,
                layers,
                vk::ImageUsageFlags::COLOR_ATTACHMENT
                    | vk::ImageUsageFlags::TRANSFER_SRC
                    | vk::ImageUsageFlags::TRANSFER_DST,
                flags,
                vk::SampleCountFlags::TYPE_1,
            );
            (i, m, view(i, format, layers))
        });
        let n = SIDE / texel;
        let density_usage =
            vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT | vk::ImageUsageFlags::TRANSFER_DST;
        let (density, density_mem) = image(
            vk::Format::R8G8_UNORM,
            n,
            layers,
            density_usage,
            vk::ImageCreateFlags::empty(),
            vk::SampleCountFlags::TYPE_1,
        );
        let colour_view = view(colour, format, layers);
        let density_view = view(density, vk::Format::R8G8_UNORM, layers);
        let mask = if case == Case::Multiview { 0b11 } else { 0 };
        let pass = (!case.dynamic()).then(|| {
            // Multiview: lavapipe 22.3 draws a multiview pass's second view as cleared only
            // (tests/suite/vk/passes.rs), so the pass loads a pattern copied in before it, which
            // the double leaves coarse at the pass's end in every view as in the first.
            let (load, initial) = if case == Case::Multiview {
                (
                    vk::AttachmentLoadOp::LOAD,
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                )
            } else {
                (vk::AttachmentLoadOp::CLEAR, vk::ImageLayout::UNDEFINED)
            };
            let resolved = vk::AttachmentDescription2::default()
                .format(format)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(load)
                .store_op(vk::AttachmentStoreOp::STORE)
                .initial_layout(initial)
                .final_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL);
            let loaded = vk::AttachmentDescription2::default()
                .format(format)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(vk::AttachmentLoadOp::LOAD)
                .store_op(vk::AttachmentStoreOp::STORE)
                .initial_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .final_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL);
            let drawn = if case.mrt() {
                loaded
            } else if case.msaa() {
                vk::AttachmentDescription2::default()
                    .format(format)
                    .samples(samples)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::DONT_CARE)
                    .initial_layout(vk::ImageLayout::UNDEFINED)
                    .final_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            } else {
                resolved
            };
            let atts = [
                drawn,
                vk::AttachmentDescription2::default()
                    .format(vk::Format::R8G8_UNORM)
                    .samples(vk::SampleCountFlags::TYPE_1)
                    .load_op(vk::AttachmentLoadOp::DONT_CARE)
                    .store_op(vk::AttachmentStoreOp::DONT_CARE)
                    .initial_layout(FDM_LAYOUT)
                    .final_layout(FDM_LAYOUT),
                if case.mrt() { loaded } else { resolved },
            ];
            let colour_ref = [0, 2].map(|a| {
                vk::AttachmentReference2::default()
                    .attachment(a)
                    .layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            });
            let colours = if case.mrt() { 2 } else { 1 };
            let resolve_ref = [vk::AttachmentReference2::default()
                .attachment(2)
                .layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)];
            let mut subpass = [
                vk::SubpassDescription2::default()
                    .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
                    .view_mask(mask)
                    .color_attachments(&colour_ref[..colours]),
                vk::SubpassDescription2::default()
                    .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
                    .view_mask(mask),
            ];
            if case.msaa() {
                subpass[0] = subpass[0].resolve_attachments(&resolve_ref);
            }
            // The drawing subpass second, after one that names nothing.
            let drawing = if case == Case::Subpass {
                subpass.swap(0, 1);
                1
            } else {
                0
            };
            let subpasses = if case == Case::Subpass { 2 } else { 1 };
            let count = if case.msaa() || case.mrt() { 3 } else { 2 };
            let mut fdm = vk::RenderPassFragmentDensityMapCreateInfoEXT::default()
                .fragment_density_map_attachment(vk::AttachmentReference {
                    attachment: 1,
                    layout: FDM_LAYOUT,
                });
            // The pass loads what the copy in front of it wrote; the copy after it reads what it
            // wrote.
            let out = [
                vk::SubpassDependency2::default()
                    .src_subpass(vk::SUBPASS_EXTERNAL)
                    .dst_subpass(drawing)
                    .src_stage_mask(vk::PipelineStageFlags::TRANSFER)
                    .dst_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
                    .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                    .dst_access_mask(
                        vk::AccessFlags::COLOR_ATTACHMENT_READ
                            | vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
                    ),
                vk::SubpassDependency2::default()
                    .src_subpass(drawing)
                    .dst_subpass(vk::SUBPASS_EXTERNAL)
                    .src_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
                    .dst_stage_mask(vk::PipelineStageFlags::TRANSFER)
                    .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                    .dst_access_mask(vk::AccessFlags::TRANSFER_READ),
            ];
            let info = vk::RenderPassCreateInfo2::default()
                .attachments(&atts[..count])
                .subpasses(&subpass[..subpasses])
                .dependencies(&out)
                .push_next(&mut fdm);
            d.create_render_pass2(&info, None).unwrap()
        });
        let framebuffer = pass.map(|p| {
            let list: Vec<vk::ImageView> = match (ms, second) {
                (Some((_, _, v)), _) => vec![v, density_view, colour_view],
                (_, Some((_, _, v))) => vec![colour_view, density_view, v],
                _ => vec![colour_view, density_view],
            };
            let formats = [[format], [vk::Format::R8G8_UNORM]];
            let described = [
                vk::FramebufferAttachmentImageInfo::default()
                    .usage(colour_usage)
                    .width(SIDE)
                    .height(SIDE)
                    .layer_count(layers)
                    .view_formats(&formats[0]),
                vk::FramebufferAttachmentImageInfo::default()
                    .usage(density_usage)
                    .width(n)
                    .height(n)
                    .layer_count(layers)
                    .view_formats(&formats[1]),
            ];
            let mut imageless =
                vk::FramebufferAttachmentsCreateInfo::default().attachment_image_infos(&described);
            let mut info = vk::FramebufferCreateInfo::default()
                .render_pass(p)
                .width(SIDE)
                .height(SIDE)
                .layers(1);
            info = if case == Case::Imageless {
                info.flags(vk::FramebufferCreateFlags::IMAGELESS)
                    .attachment_count(2)
                    .push_next(&mut imageless)
            } else {
                info.attachments(&list)
            };
            d.create_framebuffer(&info, None).unwrap()
        });
        let words = spv(VERTEX);
        let vert = d
            .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
            .unwrap();
        let words = spv(PATTERN);
        let frag = d
            .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
            .unwrap();
        let layout = d
            .create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default(), None)
            .unwrap();
        let st = stages([vert, frag]);
        let mut fixed = Fixed::new();
        if case.msaa() {
            fixed.multisample = fixed.multisample.rasterization_samples(samples);
        }
        if case.mrt() {
            fixed.blend =
                vk::PipelineColorBlendStateCreateInfo::default().attachments(&TWO_TARGETS);
        }
        let formats = [format; 2];
        let mut rendering = vk::PipelineRenderingCreateInfo::default()
            .color_attachment_formats(&formats[..if case.mrt() { 2 } else { 1 }])
            .view_mask(mask);
        let mut info = fixed.info(&st, layout);
        match pass {
            Some(p) => {
                info = info
                    .render_pass(p)
                    .subpass(u32::from(case == Case::Subpass))
            }
            None => {
                info = info
                    .push_next(&mut rendering)
                    .flags(vk::PipelineCreateFlags::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_EXT)
            }
        }
        let pipeline = d
            .create_graphics_pipelines(vk::PipelineCache::null(), &[info], None)
            .unwrap()[0];
        // Per colour attachment read back; the noise a pass loads lies after both.
        let size = u64::from(SIDE * SIDE * 4 * layers);
        let readback = d
            .create_buffer(
                &vk::BufferCreateInfo::default()
                    .size(3 * size)
                    .usage(vk::BufferUsageFlags::TRANSFER_DST | vk::BufferUsageFlags::TRANSFER_SRC),
                None,
            )
            .unwrap();
        let readback_mem = d
            .allocate_memory(
                &allocate_info(
                    &dev.memory,
                    d.get_buffer_memory_requirements(readback),
                    vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
                ),
                None,
            )
            .unwrap();
        d.bind_buffer_memory(readback, readback_mem, 0).unwrap();
        // The density map: coarse in the left half, full rate in the right.
        let p = d
            .map_memory(readback_mem, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())
            .unwrap() as *mut u8;
        let texels = (n * n * layers) as usize;
        let bytes = std::slice::from_raw_parts_mut(p, texels * 2);
        for t in 0..texels {
            let x = t as u32 % n;
            // Layer 1 mirrored where the device has a rate layer per view: a view that read
            // layer 0's rates would be coarse in the wrong half.
            let left = if mirrored && t as u32 / (n * n) == 1 {
                x >= n / 2
            } else {
                x < n / 2
            };
            let b = if left { COARSE } else { FULL };
            bytes[2 * t] = b;
            bytes[2 * t + 1] = b;
        }
        // The pattern a multiview pass (or a second colour attachment) loads, after it: every
        // byte its own.
        let noise = std::slice::from_raw_parts_mut(p.add(2 * size as usize), size as usize);
        for (i, b) in noise.iter_mut().enumerate() {
            let h = (i as u32).wrapping_mul(0x9e37_79b1);
            *b = if i % 4 == 3 { 255 } else { (h >> 24) as u8 };
        }
        d.unmap_memory(readback_mem);

        let cb = dev.begin();
        let barrier = |i, layers, old, new, src, dst| {
            vk::ImageMemoryBarrier::default()
                .image(i)
                .subresource_range(range(0, layers))
                .old_layout(old)
                .new_layout(new)
                .src_access_mask(src)
                .dst_access_mask(dst)
        };
        let all = vk::PipelineStageFlags::ALL_COMMANDS;
        d.cmd_pipeline_barrier(
            cb,
            all,
            all,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[barrier(
                density,
                layers,
                vk::ImageLayout::UNDEFINED,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                vk::AccessFlags::empty(),
                vk::AccessFlags::TRANSFER_WRITE,
            )],
        );
        d.cmd_copy_buffer_to_image(
            cb,
            readback,
            density,
            vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            &[vk::BufferImageCopy::default()
                .image_subresource(vk::ImageSubresourceLayers {
                    aspect_mask: vk::ImageAspectFlags::COLOR,
                    mip_level: 0,
                    base_array_layer: 0,
                    layer_count: layers,
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
            &[barrier(
                density,
                layers,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                FDM_LAYOUT,
                vk::AccessFlags::TRANSFER_WRITE,
                vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT,
            )],
        );
        let loaded = match second {
            Some((i, _, _)) => vec![colour, i],
            None if case == Case::Multiview => vec![colour],
            None => vec![],
        };
        for loaded in loaded {
            d.cmd_pipeline_barrier(
                cb,
                all,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[barrier(
                    loaded,
                    layers,
                    vk::ImageLayout::UNDEFINED,
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                    vk::AccessFlags::empty(),
                    vk::AccessFlags::TRANSFER_WRITE,
                )],
            );
            d.cmd_copy_buffer_to_image(
                cb,
                readback,
                loaded,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &[vk::BufferImageCopy::default()
                    .buffer_offset(2 * size)
                    .image_subresource(vk::ImageSubresourceLayers {
                        aspect_mask: vk::ImageAspectFlags::COLOR,
                        mip_level: 0,
                        base_array_layer: 0,
                        layer_count: layers,
                    })
                    .image_extent(vk::Extent3D {
                        width: SIDE,
                        height: SIDE,
                        depth: 1,
                    })],
            );
        }
        let area = vk::Rect2D {
            offset: vk::Offset2D::default(),
            extent: vk::Extent2D {
                width: SIDE,
                height: SIDE,
            },
        };
        // One per attachment: colour (or multisampled), density map, resolve.
        let clear = [vk::ClearValue {
            color: vk::ClearColorValue {
                float32: [0.0, 0.0, 0.0, 1.0],
            },
        }; 3];
        let draw_it = || {
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, pipeline);
            d.cmd_set_viewport(
                cb,
                0,
                &[vk::Viewport {
                    x: 0.0,
                    y: 0.0,
                    width: SIDE as f32,
                    height: SIDE as f32,
                    min_depth: 0.0,
                    max_depth: 1.0,
                }],
            );
            d.cmd_set_scissor(cb, 0, &[area]);
            d.cmd_draw(cb, 3, 1, 0, 0);
        };
        match (pass, framebuffer) {
            (Some(p), Some(fb)) => {
                let views = [colour_view, density_view];
                let mut named = vk::RenderPassAttachmentBeginInfo::default().attachments(&views);
                let mut begin = vk::RenderPassBeginInfo::default()
                    .render_pass(p)
                    .framebuffer(fb)
                    .render_area(area)
                    .clear_values(&clear);
                if case == Case::Imageless {
                    begin = begin.push_next(&mut named);
                }
                let inline = vk::SubpassBeginInfo::default().contents(vk::SubpassContents::INLINE);
                d.cmd_begin_render_pass2(cb, &begin, &inline);
                if case == Case::Subpass {
                    d.cmd_next_subpass2(cb, &inline, &vk::SubpassEndInfo::default());
                }
                draw_it();
                d.cmd_end_render_pass2(cb, &vk::SubpassEndInfo::default());
            }
            _ => {
                // Both attachments of a pass with two load the pattern copied in before it.
                let old = if case.mrt() {
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL
                } else {
                    vk::ImageLayout::UNDEFINED
                };
                let to_attachment = |i| {
                    barrier(
                        i,
                        layers,
                        old,
                        vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
                        vk::AccessFlags::TRANSFER_WRITE,
                        vk::AccessFlags::COLOR_ATTACHMENT_READ
                            | vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
                    )
                };
                let barriers = [
                    to_attachment(colour),
                    to_attachment(second.map_or(colour, |(i, _, _)| i)),
                ];
                d.cmd_pipeline_barrier(
                    cb,
                    all,
                    vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &barriers[..if case.mrt() { 2 } else { 1 }],
                );
                let mut colour_att = [vk::RenderingAttachmentInfo::default()
                    .image_view(colour_view)
                    .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::STORE)
                    .clear_value(clear[0]); 2];
                let mut attachments = 1;
                if let Some((_, _, v)) = second {
                    colour_att[0] = colour_att[0].load_op(vk::AttachmentLoadOp::LOAD);
                    colour_att[1] = colour_att[0].image_view(v);
                    attachments = 2;
                }
                if let Some((ms, _, v)) = ms {
                    d.cmd_pipeline_barrier(
                        cb,
                        all,
                        vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                        vk::DependencyFlags::empty(),
                        &[],
                        &[],
                        &[barrier(
                            ms,
                            layers,
                            vk::ImageLayout::UNDEFINED,
                            vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
                            vk::AccessFlags::empty(),
                            vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
                        )],
                    );
                    colour_att[0] = colour_att[0]
                        .image_view(v)
                        .store_op(vk::AttachmentStoreOp::DONT_CARE)
                        .resolve_mode(vk::ResolveModeFlags::AVERAGE)
                        .resolve_image_view(colour_view)
                        .resolve_image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL);
                }
                let mut density_att = vk::RenderingFragmentDensityMapAttachmentInfoEXT::default()
                    .image_view(density_view)
                    .image_layout(FDM_LAYOUT);
                let info = vk::RenderingInfo::default()
                    .render_area(area)
                    .layer_count(1)
                    .view_mask(mask)
                    .color_attachments(&colour_att[..attachments])
                    .push_next(&mut density_att);
                d.cmd_begin_rendering(cb, &info);
                draw_it();
                d.cmd_end_rendering(cb);
                let read = |i| {
                    barrier(
                        i,
                        layers,
                        vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
                        vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                        vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
                        vk::AccessFlags::TRANSFER_READ,
                    )
                };
                let reads = [read(colour), read(second.map_or(colour, |(i, _, _)| i))];
                d.cmd_pipeline_barrier(
                    cb,
                    vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &reads[..attachments],
                );
            }
        }
        let targets = [Some(colour), second.map(|(i, _, _)| i)];
        for (k, i) in targets.into_iter().flatten().enumerate() {
            d.cmd_copy_image_to_buffer(
                cb,
                i,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                readback,
                &[vk::BufferImageCopy::default()
                    .buffer_offset(k as u64 * size)
                    .image_subresource(vk::ImageSubresourceLayers {
                        aspect_mask: vk::ImageAspectFlags::COLOR,
                        mip_level: 0,
                        base_array_layer: 0,
                        layer_count: layers,
                    })
                    .image_extent(vk::Extent3D {
                        width: SIDE,
                        height: SIDE,
                        depth: 1,
                    })],
            );
        }
        let read_back = targets.iter().flatten().count() as u64;
        d.cmd_pipeline_barrier(
            cb,
            vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::HOST,
            vk::DependencyFlags::empty(),
            &[vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .dst_access_mask(vk::AccessFlags::HOST_READ)],
            &[],
            &[],
        );
        dev.submit(cb);
        d.queue_wait_idle(dev.queue).unwrap();
        let p = d
            .map_memory(readback_mem, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())
            .unwrap();
        let pixels =
            std::slice::from_raw_parts(p as *const u8, (read_back * size) as usize).to_vec();
        d.unmap_memory(readback_mem);

        d.free_command_buffers(dev.pool, &[cb]);
        d.destroy_buffer(readback, None);
        d.free_memory(readback_mem, None);
        d.destroy_pipeline(pipeline, None);
        d.destroy_pipeline_layout(layout, None);
        d.destroy_shader_module(vert, None);
        d.destroy_shader_module(frag, None);
        if let Some(fb) = framebuffer {
            d.destroy_framebuffer(fb, None);
        }
        if let Some(p) = pass {
            d.destroy_render_pass(p, None);
        }
        d.destroy_image_view(colour_view, None);
        for (i, m, v) in ms.into_iter().chain(second) {
            d.destroy_image_view(v, None);
            d.destroy_image(i, None);
            d.free_memory(m, None);
        }
        d.destroy_image_view(density_view, None);
        for (i, m) in [(colour, colour_mem), (density, density_mem)] {
            d.destroy_image(i, None);
            d.free_memory(m, None);
        }
        Drawn {
            pixels,
            layers: layers * read_back as u32,
            mirrored,
        }
    }
}

/// The blend state of a pass with two colour attachments: nothing written (identical for both,
/// as a device without `independentBlend` requires), so each keeps the pattern it loads, and the
/// double leaves it coarse where the draw's fragments are.
static TWO_TARGETS: [vk::PipelineColorBlendAttachmentState; 2] = [
    vk::PipelineColorBlendAttachmentState {
        blend_enable: vk::FALSE,
        src_color_blend_factor: vk::BlendFactor::ZERO,
        dst_color_blend_factor: vk::BlendFactor::ZERO,
        color_blend_op: vk::BlendOp::ADD,
        src_alpha_blend_factor: vk::BlendFactor::ZERO,
        dst_alpha_blend_factor: vk::BlendFactor::ZERO,
        alpha_blend_op: vk::BlendOp::ADD,
        color_write_mask: vk::ColorComponentFlags::empty(),
    },
    vk::PipelineColorBlendAttachmentState {
        blend_enable: vk::FALSE,
        src_color_blend_factor: vk::BlendFactor::ZERO,
        dst_color_blend_factor: vk::BlendFactor::ZERO,
        color_blend_op: vk::BlendOp::ADD,
        src_alpha_blend_factor: vk::BlendFactor::ZERO,
        dst_alpha_blend_factor: vk::BlendFactor::ZERO,
        alpha_blend_op: vk::BlendOp::ADD,
        color_write_mask: vk::ColorComponentFlags::empty(),
    },
];

/// Whether column `x` of layer `layer` of `d` lies in the coarse half (the left one, the right
/// one in a mirrored layer 1).
fn coarse_column(d: &Drawn, layer: usize, x: u32) -> bool {
    (x < SIDE / 2) != (d.mirrored && layer == 1)
}

/// Per layer: the share of uniform `block`×`block` blocks in the coarse half.
fn left_uniform(d: &Drawn, block: u32) -> Vec<f64> {
    let layer = (SIDE * SIDE * 4) as usize;
    (0..d.layers as usize)
        .map(|l| {
            fovea_vkdouble::blocks::uniform_share(
                &d.pixels[l * layer..][..layer],
                [SIDE, SIDE],
                4,
                block,
                |x, _| coarse_column(d, l, x) && coarse_column(d, l, x + block - 1),
            )
            .unwrap()
        })
        .collect()
}

/// Whether the full-rate halves of two frames are bit-identical, every layer.
fn right_identical(a: &Drawn, b: &Drawn) -> bool {
    let row = (SIDE * 4) as usize;
    let rows = SIDE as usize;
    a.pixels
        .chunks_exact(row)
        .zip(b.pixels.chunks_exact(row))
        .enumerate()
        .all(|(i, (x, y))| {
            let full = if coarse_column(a, i / rows, 0) {
                row / 2..row
            } else {
                0..row / 2
            };
            x[full.clone()] == y[full]
        })
}

fn check(profile: Profile, case: Case, format: vk::Format) {
    let Some(blocky) = draw(profile, case, format, false) else {
        return;
    };
    let smooth = draw(profile, case, format, true).expect("drawn once");
    let block = profile.max_fragment();
    let (before, after) = (left_uniform(&blocky, block), left_uniform(&smooth, block));
    eprintln!(
        "{profile:?} {case:?} {format:?}: uniform {block}×{block} blocks in the coarse half: \
         {before:?} without, {after:?} with reconstruction"
    );
    for (b, a) in before.iter().zip(&after) {
        assert!(
            *b >= 0.95 && *a <= 0.2,
            "{profile:?} {case:?} {format:?}: uniform blocks {before:?} without, {after:?} with"
        );
    }
    assert!(
        right_identical(&blocky, &smooth),
        "{profile:?} {case:?} {format:?}: the full-rate half changed"
    );
}

#[test]
fn a_subsampled_images_coarse_blocks_are_reconstructed_in_a_render_pass() {
    check(Profile::Nvidia, Case::Pass, vk::Format::R8G8B8A8_UNORM);
    check(Profile::Amd, Case::Pass, vk::Format::B8G8R8A8_SRGB);
}

#[test]
fn a_subsampled_images_coarse_blocks_are_reconstructed_in_both_views_of_a_multiview_pass() {
    check(Profile::Amd, Case::Multiview, vk::Format::R8G8B8A8_UNORM);
    check(Profile::Nvidia, Case::Multiview, vk::Format::R8G8B8A8_SRGB);
}

#[test]
fn a_subsampled_images_coarse_blocks_are_reconstructed_in_dynamic_rendering() {
    check(Profile::Nvidia, Case::Dynamic, vk::Format::R8G8B8A8_SRGB);
}

/// A format the shader does not decode (B10G11R11 floats) is left as the pass left it, and fovea's
/// log says so once for the device and format, however many passes render it.
#[test]
fn a_format_the_layer_cannot_decode_keeps_its_blocks_with_one_line() {
    crate::support::in_own_process(
        module_path!(),
        "a_format_the_layer_cannot_decode_keeps_its_blocks_with_one_line",
        || {
            let dir =
                std::env::temp_dir().join(format!("fovea-recon-format-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).unwrap();
            std::env::set_var("FOVEA_LOG", "info");
            std::env::set_var("FOVEA_LOG_FILE", dir.join("fovea.log"));
            let format = vk::Format::B10G11R11_UFLOAT_PACK32;
            let Some(blocky) = draw(Profile::Nvidia, Case::Pass, format, false) else {
                return;
            };
            let (_serial, env) = env().expect("drawn once");
            let vk = Vk::new(env, Profile::Nvidia, true).expect("an instance");
            let device = vk.device_with(&[], Features::FDM_MULTIVIEW, None);
            let dev = Dev::new(&vk, device);
            let smooth = draw_on(&vk, &dev, Case::Pass, format, true, false);
            let again = draw_on(&vk, &dev, Case::Dynamic, format, true, false);
            dev.destroy();
            assert_only_stage_false_positives();
            drop(vk);
            assert!(left_uniform(&blocky, 4)[0] >= 0.95);
            assert!(
                blocky.pixels == smooth.pixels && again.pixels == smooth.pixels,
                "a format the layer cannot decode was changed"
            );
            let log = std::fs::read_to_string(dir.join("fovea.log")).unwrap_or_default();
            let line = "coarse blocks are not reconstructed in images of this format";
            assert_eq!(log.matches(line).count(), 1, "one line:\n{log}");
            assert!(log.contains("B10G11R11_UFLOAT_PACK32"), "{log}");
        },
    );
}

/// A long-running application that recreates its targets (a resolution change, a session
/// restart) with reconstruction on: a thousand cycles on one device, each with a new colour image
/// (subsampled every other cycle), density map, views, render pass and framebuffer, destroyed at
/// its end. Each cycle reconstructs exactly when its image is subsampled, however the driver
/// reuses the handles of the previous cycle's objects (lavapipe does), so no decision outlives its
/// view; and the buffers, memory and views alive below the layers do not grow after the first
/// cycles, so the layer keeps one scratch per size, not per target.
#[test]
fn targets_recreated_a_thousand_times_with_reconstruction_on() {
    let Some((_serial, env)) = env() else { return };
    let Some(vk) = Vk::new(env, Profile::Nvidia, true) else {
        return;
    };
    let device = vk.device_with(&[], Features::FDM_MULTIVIEW, None);
    let dev = Dev::new(&vk, device);
    let alive = |env: &crate::support::device::Env| {
        let n = |name: &str| env.double.calls(name) as i64;
        (
            n("vkCreateBuffer") - n("vkDestroyBuffer"),
            n("vkAllocateMemory") - n("vkFreeMemory"),
            n("vkCreateImageView") - n("vkDestroyImageView"),
        )
    };
    let mut settled = None;
    for cycle in 0..1000u32 {
        let subsampled = cycle % 2 == 1;
        let case = if cycle % 4 < 2 {
            Case::Pass
        } else {
            Case::Dynamic
        };
        let drawn = draw_on(
            &vk,
            &dev,
            case,
            vk::Format::R8G8B8A8_UNORM,
            subsampled,
            false,
        );
        let share = left_uniform(&drawn, 4)[0];
        if subsampled {
            assert!(
                share <= 0.2,
                "cycle {cycle} ({case:?}): {share} uniform, subsampled"
            );
        } else {
            assert!(
                share >= 0.95,
                "cycle {cycle} ({case:?}): {share} uniform, not subsampled"
            );
        }
        if cycle == 8 {
            settled = Some(alive(env));
        }
        if cycle > 8 {
            assert_eq!(
                Some(alive(env)),
                settled,
                "objects alive below the layers at cycle {cycle}"
            );
        }
    }
    dev.destroy();
    assert_only_stage_false_positives();
    drop(vk);
}

/// An imageless framebuffer names, for each attachment, the usage the application gave its image,
/// which must equal its view's at each begin (VUID-VkRenderPassBeginInfo-framebuffer-04627): the
/// transfer usage fovea adds to a subsampled image for the copies is not the application's, and
/// validation says nothing, while the coarse blocks are reconstructed all the same.
#[test]
fn an_imageless_framebuffer_names_the_applications_usage_and_is_reconstructed() {
    check(Profile::Nvidia, Case::Imageless, vk::Format::R8G8B8A8_UNORM);
}

/// Every subpass renders with the shading-rate attachment: a colour attachment that only the
/// second subpass draws into is reconstructed at the pass's end as one of the first's is.
#[test]
fn a_colour_attachment_of_a_second_subpass_is_reconstructed() {
    check(Profile::Nvidia, Case::Subpass, vk::Format::R8G8B8A8_UNORM);
}

/// A multisampled pass resolves into the image that is read: that image is reconstructed (the
/// multisampled attachment itself is left alone), in a render pass and in dynamic rendering.
#[test]
fn a_subsampled_resolve_targets_coarse_blocks_are_reconstructed() {
    check(Profile::Nvidia, Case::Msaa, vk::Format::R8G8B8A8_UNORM);
    check(
        Profile::Nvidia,
        Case::DynamicMsaa,
        vk::Format::B8G8R8A8_SRGB,
    );
}

/// A pass with two colour attachments into subsampled images: each is reconstructed, not only
/// the first, in a render pass and in dynamic rendering (both read back, one after the other, as
/// layers of the frame checked).
#[test]
fn every_subsampled_colour_attachment_of_a_pass_is_reconstructed() {
    check(Profile::Nvidia, Case::Mrt, vk::Format::R8G8B8A8_UNORM);
    check(Profile::Amd, Case::DynamicMrt, vk::Format::R8G8B8A8_SRGB);
}
