//! An injected eye pass drawn with 4 samples a pixel and resolved into the swapchain image
//! (docs/reconstruction.md): injection judges the pass by its multisampled attachment (an image
//! of the eye's shape of the application's own), and the resolve target, a swapchain image
//! published for reconstruction (`DEBUG_OCULUS_FOVEATION_SUBSAMPLED=1`), is reconstructed at the
//! pass's end. From the pixels of the swapchain image read back, with the property off (blocky)
//! and on: in the 16×16 tiles of the shading-rate map that the blocky frame shows shaded at 4×4
//! (every 4×4 block uniform; the pattern gives every pixel its own colour) the share of uniform
//! blocks drops, and the tiles it shows at full rate (no uniform 2×2 block) are bit-identical.
//! Version-1 render pass, on a framebuffer with views and on an imageless one (whose attachment
//! infos name the usage the application asked the runtime for: the transfer usage reconstruction
//! added is not it), and dynamic rendering, on `nvidia` (16×16 texels).

use std::ptr::null;

use ash::vk;
use fovea_harness::app::API_1_0;
use fovea_harness::vulkan::{self, Options, Vulkan, VALIDATION_LAYER};
use fovea_harness::{skip, App, Chain};
use fovea_model::density::Level;
use fovea_vkdouble::Profile;
use openxr_sys as xr;
use xr::Handle as _;

use crate::both::fdm_vulkan::{func, running_session, Frame};
use crate::support::process::in_own_process;
use crate::support::vulkan::{allocate_info, range, spv, stages, Fixed, VERTEX};

use super::app::{set_up, swapchain_images, view, Setup, FORMAT, HEIGHT, WIDTH};

const PATTERN: &[u8] = include_bytes!("../../shaders/pattern.frag.spv");
const SAMPLES: vk::SampleCountFlags = vk::SampleCountFlags::TYPE_4;
/// The shading-rate texel on `nvidia`, in pixels.
const TILE: u32 = 16;

/// How the frame's pass is begun.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    /// `vkCmdBeginRenderPass` on a framebuffer with views.
    RenderPass,
    /// `vkCmdBeginRenderPass` on an imageless framebuffer, the views named at the begin.
    Imageless,
    /// `vkCmdBeginRendering`.
    Dynamic,
}

/// One frame: a 4× multisampled eye-shaped pass resolved into the acquired swapchain image, which
/// is read back (RGBA8, rows top to bottom).
fn frame(kind: Kind, subsampled: bool, label: &str) -> Option<Vec<u8>> {
    let dynamic = kind == Kind::Dynamic;
    let _dir = set_up(label, Setup::Inject(Level::High));
    std::env::set_var(
        "DEBUG_OCULUS_FOVEATION_SUBSAMPLED",
        if subsampled { "1" } else { "0" },
    );
    let (_serial, env) = crate::support::device::env()?;
    env.double.set_profile(Some(Profile::Nvidia));
    crate::support::device::assert_no_double_errors(env);
    env.double.clear();
    vulkan::take_messages();
    let app = App::new(Chain::fovea().unwrap(), &["XR_KHR_vulkan_enable2"], API_1_0).unwrap();
    let sys = app.system();
    let ours = std::ffi::CString::new(fovea_abi::VK_LAYER_NAME).unwrap();
    let layers = [
        ours.as_c_str(),
        VALIDATION_LAYER,
        fovea_vkdouble::LAYER_NAME,
    ];
    let imageless = vk::PhysicalDeviceVulkan12Features::default().imageless_framebuffer(true);
    let options = Options {
        layers: &layers,
        api_version: vk::API_VERSION_1_3,
        multiview: false,
        dynamic_rendering: true,
        device_extensions: &[],
        device_next: if kind == Kind::Imageless {
            &imageless as *const _ as *const std::ffi::c_void
        } else {
            null()
        },
        queues: 1,
    };
    let v = match Vulkan::through_xr_with(&env.entry, app.chain.gipa(), app.instance, sys, &options)
    {
        Ok(v) => v,
        Err(why) => {
            skip(&why);
            return None;
        }
    };
    let (session, space) = running_session(&app, sys, &v);
    let create_swapchain: xr::pfn::CreateSwapchain = func(&app, "xrCreateSwapchain");
    let info = xr::SwapchainCreateInfo {
        ty: xr::StructureType::SWAPCHAIN_CREATE_INFO,
        next: null(),
        create_flags: xr::SwapchainCreateFlags::EMPTY,
        usage_flags: xr::SwapchainUsageFlags::COLOR_ATTACHMENT
            | xr::SwapchainUsageFlags::TRANSFER_SRC,
        format: FORMAT.as_raw() as i64,
        sample_count: 1,
        width: WIDTH,
        height: HEIGHT,
        face_count: 1,
        array_size: 1,
        mip_count: 1,
    };
    let mut swapchain = xr::Swapchain::NULL;
    // SAFETY: the struct lives across the call.
    assert_eq!(
        unsafe { create_swapchain(session, &info, &mut swapchain) },
        xr::Result::SUCCESS
    );
    let images = swapchain_images(&app, swapchain);
    let frame = Frame {
        app: &app,
        session,
        space,
    };
    let (index, _, time) = frame.acquire(swapchain);
    let target = images[index as usize];
    let d = &v.device;
    let area = vk::Rect2D {
        offset: vk::Offset2D::default(),
        extent: vk::Extent2D {
            width: WIDTH,
            height: HEIGHT,
        },
    };
    let size = u64::from(WIDTH * HEIGHT * 4);
    // SAFETY: the instance and device are alive; every struct lives across its call; every object
    // made here is destroyed before the device, after the queue is idle.
    let pixels = unsafe {
        let memory = v
            .instance
            .get_physical_device_memory_properties(v.physical_device);
        let queue = d.get_device_queue(v.family, 0);
        let pool = d
            .create_command_pool(
                &vk::CommandPoolCreateInfo::default().queue_family_index(v.family),
                None,
            )
            .unwrap();
        let cb = d
            .allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool)
                    .level(vk::CommandBufferLevel::PRIMARY)
                    .command_buffer_count(1),
            )
            .unwrap()[0];
        // The multisampled image of the eye's shape the pass draws into.
        let ms = d
            .create_image(
                &vk::ImageCreateInfo::default()
                    .image_type(vk::ImageType::TYPE_2D)
                    .format(FORMAT)
                    .extent(vk::Extent3D {
                        width: WIDTH,
                        height: HEIGHT,
                        depth: 1,
                    })
                    .mip_levels(1)
                    .array_layers(1)
                    .samples(SAMPLES)
                    .tiling(vk::ImageTiling::OPTIMAL)
                    .usage(vk::ImageUsageFlags::COLOR_ATTACHMENT),
                None,
            )
            .unwrap();
        let ms_mem = d
            .allocate_memory(
                &allocate_info(
                    &memory,
                    d.get_image_memory_requirements(ms),
                    vk::MemoryPropertyFlags::DEVICE_LOCAL,
                ),
                None,
            )
            .unwrap();
        d.bind_image_memory(ms, ms_mem, 0).unwrap();
        let ms_view = view(d, ms, 1);
        let target_view = view(d, target, 1);
        let colour_layout = vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL;
        let render_pass = (!dynamic).then(|| {
            let atts = [
                vk::AttachmentDescription::default()
                    .format(FORMAT)
                    .samples(SAMPLES)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::DONT_CARE)
                    .initial_layout(vk::ImageLayout::UNDEFINED)
                    .final_layout(colour_layout),
                vk::AttachmentDescription::default()
                    .format(FORMAT)
                    .samples(vk::SampleCountFlags::TYPE_1)
                    .load_op(vk::AttachmentLoadOp::DONT_CARE)
                    .store_op(vk::AttachmentStoreOp::STORE)
                    .initial_layout(vk::ImageLayout::UNDEFINED)
                    .final_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL),
            ];
            let colour = [vk::AttachmentReference {
                attachment: 0,
                layout: colour_layout,
            }];
            let resolve = [vk::AttachmentReference {
                attachment: 1,
                layout: colour_layout,
            }];
            let subpass = [vk::SubpassDescription::default()
                .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
                .color_attachments(&colour)
                .resolve_attachments(&resolve)];
            // The copy after the pass reads what the resolve wrote.
            let out = [vk::SubpassDependency::default()
                .src_subpass(0)
                .dst_subpass(vk::SUBPASS_EXTERNAL)
                .src_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
                .dst_stage_mask(vk::PipelineStageFlags::TRANSFER)
                .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                .dst_access_mask(vk::AccessFlags::TRANSFER_READ)];
            d.create_render_pass(
                &vk::RenderPassCreateInfo::default()
                    .attachments(&atts)
                    .subpasses(&subpass)
                    .dependencies(&out),
                None,
            )
            .unwrap()
        });
        let views = [ms_view, target_view];
        let framebuffer = render_pass.map(|rp| {
            // An imageless framebuffer names each attachment's usage as the application knows it:
            // its own image's, and what it asked the runtime for (colour attachment, transfer
            // source) with the sampled usage the simulated runtime adds.
            let formats = [FORMAT];
            let described = [
                vk::ImageUsageFlags::COLOR_ATTACHMENT,
                vk::ImageUsageFlags::COLOR_ATTACHMENT
                    | vk::ImageUsageFlags::TRANSFER_SRC
                    | vk::ImageUsageFlags::SAMPLED,
            ]
            .map(|usage| {
                vk::FramebufferAttachmentImageInfo::default()
                    .usage(usage)
                    .width(WIDTH)
                    .height(HEIGHT)
                    .layer_count(1)
                    .view_formats(&formats)
            });
            let mut infos =
                vk::FramebufferAttachmentsCreateInfo::default().attachment_image_infos(&described);
            let info = vk::FramebufferCreateInfo::default()
                .render_pass(rp)
                .width(WIDTH)
                .height(HEIGHT)
                .layers(1);
            let info = if kind == Kind::Imageless {
                info.flags(vk::FramebufferCreateFlags::IMAGELESS)
                    .attachment_count(2)
                    .push_next(&mut infos)
            } else {
                info.attachments(&views)
            };
            d.create_framebuffer(&info, None).unwrap()
        });
        let modules = [VERTEX, PATTERN].map(|b| {
            let words = spv(b);
            d.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
                .unwrap()
        });
        let layout = d
            .create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default(), None)
            .unwrap();
        let formats = [FORMAT];
        let mut rendering =
            vk::PipelineRenderingCreateInfo::default().color_attachment_formats(&formats);
        let mut fixed = Fixed::new();
        fixed.multisample = fixed.multisample.rasterization_samples(SAMPLES);
        let st = stages(modules);
        let info = match render_pass {
            Some(rp) => fixed.info(&st, layout).render_pass(rp),
            None => fixed.info(&st, layout).push_next(&mut rendering),
        };
        let pipeline = d
            .create_graphics_pipelines(vk::PipelineCache::null(), &[info], None)
            .unwrap()[0];
        let readback = d
            .create_buffer(
                &vk::BufferCreateInfo::default()
                    .size(size)
                    .usage(vk::BufferUsageFlags::TRANSFER_DST),
                None,
            )
            .unwrap();
        let readback_mem = d
            .allocate_memory(
                &allocate_info(
                    &memory,
                    d.get_buffer_memory_requirements(readback),
                    vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
                ),
                None,
            )
            .unwrap();
        d.bind_buffer_memory(readback, readback_mem, 0).unwrap();

        d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
            .unwrap();
        let draw = || {
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, pipeline);
            d.cmd_set_viewport(
                cb,
                0,
                &[vk::Viewport {
                    x: 0.0,
                    y: 0.0,
                    width: WIDTH as f32,
                    height: HEIGHT as f32,
                    min_depth: 0.0,
                    max_depth: 1.0,
                }],
            );
            d.cmd_set_scissor(cb, 0, &[area]);
            d.cmd_draw(cb, 3, 1, 0, 0);
        };
        let clear = [vk::ClearValue {
            color: vk::ClearColorValue {
                float32: [0.0, 0.0, 0.0, 1.0],
            },
        }; 2];
        let barrier = |image, old, new, src, dst| {
            vk::ImageMemoryBarrier::default()
                .image(image)
                .subresource_range(range(0, 1))
                .old_layout(old)
                .new_layout(new)
                .src_access_mask(src)
                .dst_access_mask(dst)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        };
        match (render_pass, framebuffer) {
            (Some(rp), Some(fb)) => {
                let mut named = vk::RenderPassAttachmentBeginInfo::default().attachments(&views);
                let mut begin = vk::RenderPassBeginInfo::default()
                    .render_pass(rp)
                    .framebuffer(fb)
                    .render_area(area)
                    .clear_values(&clear);
                if kind == Kind::Imageless {
                    begin = begin.push_next(&mut named);
                }
                d.cmd_begin_render_pass(cb, &begin, vk::SubpassContents::INLINE);
                draw();
                d.cmd_end_render_pass(cb);
            }
            _ => {
                let to_attachment = [ms, target].map(|i| {
                    barrier(
                        i,
                        vk::ImageLayout::UNDEFINED,
                        colour_layout,
                        vk::AccessFlags::empty(),
                        vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
                    )
                });
                d.cmd_pipeline_barrier(
                    cb,
                    vk::PipelineStageFlags::TOP_OF_PIPE,
                    vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &to_attachment,
                );
                let colour = [vk::RenderingAttachmentInfo::default()
                    .image_view(ms_view)
                    .image_layout(colour_layout)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::DONT_CARE)
                    .clear_value(clear[0])
                    .resolve_mode(vk::ResolveModeFlags::AVERAGE)
                    .resolve_image_view(target_view)
                    .resolve_image_layout(colour_layout)];
                d.cmd_begin_rendering(
                    cb,
                    &vk::RenderingInfo::default()
                        .render_area(area)
                        .layer_count(1)
                        .color_attachments(&colour),
                );
                draw();
                d.cmd_end_rendering(cb);
                d.cmd_pipeline_barrier(
                    cb,
                    vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[barrier(
                        target,
                        colour_layout,
                        vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                        vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
                        vk::AccessFlags::TRANSFER_READ,
                    )],
                );
            }
        }
        d.cmd_copy_image_to_buffer(
            cb,
            target,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            readback,
            &[vk::BufferImageCopy::default()
                .image_subresource(vk::ImageSubresourceLayers {
                    aspect_mask: vk::ImageAspectFlags::COLOR,
                    mip_level: 0,
                    base_array_layer: 0,
                    layer_count: 1,
                })
                .image_extent(vk::Extent3D {
                    width: WIDTH,
                    height: HEIGHT,
                    depth: 1,
                })],
        );
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
        d.end_command_buffer(cb).unwrap();
        let cbs = [cb];
        d.queue_submit(
            queue,
            &[vk::SubmitInfo::default().command_buffers(&cbs)],
            vk::Fence::null(),
        )
        .unwrap();
        d.queue_wait_idle(queue).unwrap();
        let p = d
            .map_memory(readback_mem, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())
            .unwrap();
        let pixels = std::slice::from_raw_parts(p as *const u8, size as usize).to_vec();
        d.unmap_memory(readback_mem);
        d.destroy_buffer(readback, None);
        d.free_memory(readback_mem, None);
        d.destroy_pipeline(pipeline, None);
        d.destroy_pipeline_layout(layout, None);
        for m in modules {
            d.destroy_shader_module(m, None);
        }
        if let Some(fb) = framebuffer {
            d.destroy_framebuffer(fb, None);
        }
        if let Some(rp) = render_pass {
            d.destroy_render_pass(rp, None);
        }
        d.destroy_image_view(target_view, None);
        d.destroy_image_view(ms_view, None);
        d.destroy_image(ms, None);
        d.free_memory(ms_mem, None);
        d.destroy_command_pool(pool, None);
        pixels
    };
    frame.release(swapchain, time);
    let destroy_swapchain: xr::pfn::DestroySwapchain = func(&app, "xrDestroySwapchain");
    let destroy_session: xr::pfn::DestroySession = func(&app, "xrDestroySession");
    // SAFETY: the handles are live and used no more.
    unsafe {
        assert_eq!(destroy_swapchain(swapchain), xr::Result::SUCCESS);
        assert_eq!(destroy_session(session), xr::Result::SUCCESS);
        v.destroy_device();
    }
    assert_eq!(app.destroy(), xr::Result::SUCCESS);
    // SAFETY: the device is gone.
    unsafe { v.destroy_instance() };
    vulkan::assert_no_messages();
    assert_eq!(env.double.errors(), Vec::<String>::new(), "{label}");
    Some(pixels)
}

/// The pixel at (`x`, `y`) of an RGBA8 frame.
fn pixel(frame: &[u8], x: u32, y: u32) -> &[u8] {
    let at = ((y * WIDTH + x) * 4) as usize;
    &frame[at..at + 4]
}

/// Whether every `block`×`block` block of the tile at (`tx`, `ty`) is uniform (`all`), or any is.
fn uniform_blocks(frame: &[u8], tx: u32, ty: u32, block: u32, all: bool) -> bool {
    let mut blocks = (0..TILE / block).flat_map(|by| (0..TILE / block).map(move |bx| (bx, by)));
    let uniform = |(bx, by): (u32, u32)| {
        let (x0, y0) = (tx * TILE + bx * block, ty * TILE + by * block);
        let first = pixel(frame, x0, y0);
        (0..block).all(|y| (0..block).all(|x| pixel(frame, x0 + x, y0 + y) == first))
    };
    if all {
        blocks.all(uniform)
    } else {
        blocks.any(uniform)
    }
}

#[test]
fn an_injected_multisampled_eye_pass_gets_its_resolve_target_reconstructed() {
    in_own_process(
        module_path!(),
        "an_injected_multisampled_eye_pass_gets_its_resolve_target_reconstructed",
        || {
            for (label, kind) in [
                ("rp", Kind::RenderPass),
                ("imageless", Kind::Imageless),
                ("dynamic", Kind::Dynamic),
            ] {
                let Some(blocky) = frame(kind, false, &format!("resolve-blocky-{label}")) else {
                    return;
                };
                let smooth =
                    frame(kind, true, &format!("resolve-smooth-{label}")).expect("drawn once");
                let (mut coarse, mut still_uniform, mut full, mut kept) = (0, 0, 0, 0);
                for ty in 0..HEIGHT / TILE {
                    for tx in 0..WIDTH / TILE {
                        if uniform_blocks(&blocky, tx, ty, 4, true) {
                            coarse += 16;
                            still_uniform += (0..4)
                                .flat_map(|by| (0..4).map(move |bx| (bx, by)))
                                .filter(|&(bx, by)| {
                                    let (x0, y0) = (tx * TILE + bx * 4, ty * TILE + by * 4);
                                    let first = pixel(&smooth, x0, y0);
                                    (0..4).all(|y| {
                                        (0..4).all(|x| pixel(&smooth, x0 + x, y0 + y) == first)
                                    })
                                })
                                .count();
                        } else if !uniform_blocks(&blocky, tx, ty, 2, false) {
                            full += 1;
                            kept += usize::from((0..TILE).all(|y| {
                                (0..TILE).all(|x| {
                                    pixel(&blocky, tx * TILE + x, ty * TILE + y)
                                        == pixel(&smooth, tx * TILE + x, ty * TILE + y)
                                })
                            }));
                        }
                    }
                }
                let share = still_uniform as f64 / coarse.max(1) as f64;
                eprintln!(
                    "{label}: {coarse} 4×4 blocks shaded coarse, {share:.3} of them uniform \
                     after reconstruction; {full} full-rate tiles, {kept} kept"
                );
                assert!(coarse >= 1000, "{label}: {coarse} coarse 4×4 blocks");
                assert!(
                    share <= 0.2,
                    "{label}: {share:.3} of the coarse blocks uniform with reconstruction"
                );
                assert!(full >= 20, "{label}: {full} full-rate tiles");
                assert_eq!(kept, full, "{label}: full-rate tiles kept");
            }
        },
    );
}
