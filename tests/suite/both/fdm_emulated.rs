//! XR_FB_foveation_vulkan end to end on a device that has no fragment density maps of its own:
//! the rates fovea's OpenXR side computes are the rates the rasterizer gets.
//!
//! Stack: the application → fovea's OpenXR layer → the simulated runtime (in-process harness), and
//! the application's VkInstance and VkDevice made through XR_KHR_vulkan_enable2, where fovea's
//! `xrCreateVulkanInstanceKHR` puts its Vulkan layer first: fovea's Vulkan layer →
//! VK_LAYER_KHRONOS_validation → the shading-rate double → lavapipe. The double plays `nvidia`
//! (16×16 texels, one shading-rate layer per view, fragments up to 4×4) and `amd` (8×8, one merged
//! layer, fragments up to 2×2). The application does what a Quest application does: sets a
//! foveation profile, acquires, renders one pass with the density image as its fragment density
//! map, submits, releases and ends the frame with its projection views. Two layouts: one eye per
//! array layer drawn in one multiview pass, and both eyes side by side in one layer (double-wide).
//! The double computes what the draw shades at, per view and shading-rate attachment texel (its
//! pipeline's rate state combined with the attachment the pass read, clamped to the device's
//! rates); those effective rates must equal, texel for texel, the density model for the views'
//! FOVs and rectangles at the device's texel, converted by `fovea_model::shading_rate` for the
//! profile's rates. Validation must say nothing,
//! leaks included (it reports them when the device is destroyed).
//!
//! Why a test of its own: the modules below test the halves apart. `fdm_vulkan` reads the density
//! images back on lavapipe as it is (no emulation, fovea's default texel), and the `vk::` modules
//! drive the Vulkan layer with density images the test makes itself, whose shadows hold rate 0.
//! Only here do fovea's own density images, their uploads into the shadows (`bridge::shadow_of`)
//! and the rewritten render pass meet.
//!
//! Shares [`crate::support::device::env`] (manifests, `VK_ADD_LAYER_PATH`, the double's records) and
//! [`crate::both::fdm_vulkan`]'s frame helpers and its lock on the harness's validation messages. Skips
//! with a reason when a system piece is missing; fails instead under `FOVEA_REQUIRE_SYSTEM=1`.

use std::ptr::{null, null_mut};

use ash::vk;
use ash::vk::Handle as _;
use fovea_harness::vulkan::{self, assert_no_messages, pick_lavapipe, take_messages, Vulkan};
use fovea_harness::App;
use fovea_model::density::{self, Grid, Level, Pattern, Rect, View};
use fovea_model::{shading_rate, Fov};
use fovea_vkdouble::Profile;
use openxr_sys as xr;

use crate::both::fdm_vulkan::{
    app, apply_profile, enumerate, fdm_swapchain, func, running_session, vulkan_or_skip, Frame,
    HEIGHT, VALIDATED, WIDTH,
};
use crate::support::device::{allocate, env, resettable_pool, Env};
use crate::support::level_info;
use crate::support::vulkan::{spv, stages, Fixed, FRAGMENT, VERTEX};

/// The simulated runtime's swapchain format (VK_FORMAT_R8G8B8A8_SRGB), as `swapchain_info` asks.
const COLOR: vk::Format = vk::Format::R8G8B8A8_SRGB;
const DENSITY: vk::Format = vk::Format::R8G8_UNORM;
const FDM_LAYOUT: vk::ImageLayout = vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT;
/// The multiview layout draws both eyes in one pass.
const VIEW_MASK: u32 = 0b11;

/// How the application lays its two eyes out in the swapchain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Layout {
    /// Two array layers, eye `i` in layer `i` over the whole image, drawn in one multiview pass.
    Multiview,
    /// One layer, the left eye in the left half and the right eye in the right half, drawn in
    /// one pass.
    DoubleWide,
}

impl Layout {
    pub(crate) fn layers(self) -> u32 {
        match self {
            Layout::Multiview => 2,
            Layout::DoubleWide => 1,
        }
    }

    /// Where the application draws eye `eye`: its array layer and rectangle.
    pub(crate) fn place(self, eye: usize) -> (u32, Rect) {
        let whole = Rect {
            x: 0,
            y: 0,
            width: WIDTH,
            height: HEIGHT,
        };
        match self {
            Layout::Multiview => (eye as u32, whole),
            Layout::DoubleWide => (
                0,
                Rect {
                    x: (WIDTH / 2 * eye as u32) as i32,
                    width: WIDTH / 2,
                    ..whole
                },
            ),
        }
    }

    /// Per density-map layer, the views the map of an image acquired now is made for: those the
    /// application submitted into the swapchain, or before its first submission, view `i` over
    /// the whole of layer `i` (docs/ARCHITECTURE.md, crates/model/src/maps.rs).
    pub(crate) fn views(self, fovs: [Fov; 2], submitted: bool) -> Vec<Vec<View>> {
        let mut out = vec![Vec::new(); self.layers() as usize];
        for (eye, fov) in fovs.into_iter().enumerate() {
            let (layer, rect) = if submitted {
                self.place(eye)
            } else {
                Layout::Multiview.place(eye)
            };
            if let Some(views) = out.get_mut(layer as usize) {
                views.push(View {
                    fov,
                    rect,
                    visible: None,
                });
            }
        }
        out
    }
}

#[test]
fn multiview_foveation_reaches_the_shading_rate_attachment_texel_for_texel() {
    each_profile(Layout::Multiview);
}

#[test]
fn double_wide_foveation_reaches_the_shading_rate_attachment_texel_for_texel() {
    each_profile(Layout::DoubleWide);
}

fn each_profile(layout: Layout) {
    let Some((_serial, env)) = env() else { return };
    // The harness collects every validated instance's messages in one place.
    let _validated = VALIDATED.lock();
    pick_lavapipe();
    for profile in [Profile::Nvidia, Profile::Amd] {
        if !run(env, profile, layout) {
            return;
        }
    }
}

/// The application's objects for one swapchain: a pass with the density map (multiview where the
/// layout has a layer per eye), one framebuffer per swapchain image, a pipeline, and a command
/// buffer with its fence.
pub(crate) struct Renderer {
    pass: vk::RenderPass,
    views: Vec<vk::ImageView>,
    framebuffers: Vec<vk::Framebuffer>,
    modules: [vk::ShaderModule; 2],
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    pub(crate) pool: vk::CommandPool,
    pub(crate) cb: vk::CommandBuffer,
    fence: vk::Fence,
    queue: vk::Queue,
}

/// A view of every layer of `image` (2D-array for the multiview layout).
fn whole_view(d: &ash::Device, layout: Layout, image: u64, format: vk::Format) -> vk::ImageView {
    let ty = match layout {
        Layout::Multiview => vk::ImageViewType::TYPE_2D_ARRAY,
        Layout::DoubleWide => vk::ImageViewType::TYPE_2D,
    };
    let info = vk::ImageViewCreateInfo::default()
        .image(vk::Image::from_raw(image))
        .view_type(ty)
        .format(format)
        .subresource_range(vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: 0,
            layer_count: layout.layers(),
        });
    // SAFETY: a live image of the device; the struct lives across the call.
    unsafe { d.create_image_view(&info, None) }.expect("vkCreateImageView")
}

impl Renderer {
    /// `color` and `density`: the swapchain's images and their density images, by index; without
    /// density images, a pass with the colour attachment alone.
    pub(crate) fn new(
        v: &Vulkan,
        layout: Layout,
        color: &[u64],
        density: Option<&[u64]>,
    ) -> Renderer {
        let d = &v.device;
        let atts = [
            vk::AttachmentDescription::default()
                .format(COLOR)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::STORE)
                .initial_layout(vk::ImageLayout::UNDEFINED)
                .final_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL),
            vk::AttachmentDescription::default()
                .format(DENSITY)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(vk::AttachmentLoadOp::DONT_CARE)
                .store_op(vk::AttachmentStoreOp::DONT_CARE)
                .initial_layout(FDM_LAYOUT)
                .final_layout(FDM_LAYOUT),
        ];
        let color_ref = [vk::AttachmentReference {
            attachment: 0,
            layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
        }];
        let subpass = [vk::SubpassDescription::default()
            .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
            .color_attachments(&color_ref)];
        let masks = [VIEW_MASK];
        let mut multiview = vk::RenderPassMultiviewCreateInfo::default()
            .view_masks(&masks)
            .correlation_masks(&masks);
        let mut fdm = vk::RenderPassFragmentDensityMapCreateInfoEXT::default()
            .fragment_density_map_attachment(vk::AttachmentReference {
                attachment: 1,
                layout: FDM_LAYOUT,
            });
        let mut info = vk::RenderPassCreateInfo::default()
            .attachments(&atts[..1 + usize::from(density.is_some())])
            .subpasses(&subpass);
        if density.is_some() {
            info = info.push_next(&mut fdm);
        }
        if layout == Layout::Multiview {
            info = info.push_next(&mut multiview);
        }
        // SAFETY: every struct lives across its call; every object is the device's own and is
        // destroyed in `destroy`.
        unsafe {
            let pass = d
                .create_render_pass(&info, None)
                .expect("vkCreateRenderPass");
            let mut views = Vec::new();
            let mut framebuffers = Vec::new();
            for (i, &c) in color.iter().enumerate() {
                let mut pair = vec![whole_view(d, layout, c, COLOR)];
                if let Some(&f) = density.and_then(|d| d.get(i)) {
                    pair.push(whole_view(d, layout, f, DENSITY));
                }
                views.extend(pair.iter().copied());
                framebuffers.push(
                    d.create_framebuffer(
                        &vk::FramebufferCreateInfo::default()
                            .render_pass(pass)
                            .attachments(&pair)
                            .width(WIDTH)
                            .height(HEIGHT)
                            .layers(1),
                        None,
                    )
                    .expect("vkCreateFramebuffer"),
                );
            }
            let module = |bytes: &[u8]| {
                let words = spv(bytes);
                d.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
                    .expect("vkCreateShaderModule")
            };
            let modules = [module(VERTEX), module(FRAGMENT)];
            let layout = d
                .create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default(), None)
                .expect("vkCreatePipelineLayout");
            let stages = stages(modules);
            let fixed = Fixed::new();
            let pipeline = d
                .create_graphics_pipelines(
                    vk::PipelineCache::null(),
                    &[fixed.info(&stages, layout).render_pass(pass).subpass(0)],
                    None,
                )
                .expect("vkCreateGraphicsPipelines")[0];
            let pool = resettable_pool(d, v.family);
            let cb = allocate(d, pool);
            let fence = d
                .create_fence(&vk::FenceCreateInfo::default(), None)
                .expect("vkCreateFence");
            Renderer {
                pass,
                views,
                framebuffers,
                modules,
                layout,
                pipeline,
                pool,
                cb,
                fence,
                queue: d.get_device_queue(v.family, 0),
            }
        }
    }

    /// Records and submits one full-screen draw into swapchain image `index` through its density
    /// map, and waits for it. Called between acquire and release, where the application owns the
    /// image and its queue.
    pub(crate) fn draw(&self, d: &ash::Device, index: u32) {
        self.draw_ending_with(d, index, None);
    }

    /// As [`Renderer::draw`]; with `offsets`, the pass ends with `vkCmdEndRenderPass2` (the
    /// device must have Vulkan 1.2) carrying them in a
    /// `VkRenderPassFragmentDensityMapOffsetEndInfoEXT`, one per view.
    pub(crate) fn draw_ending_with(
        &self,
        d: &ash::Device,
        index: u32,
        offsets: Option<&[vk::Offset2D]>,
    ) {
        self.draw_in(d, self.cb, index, offsets);
    }

    /// As [`Renderer::draw_ending_with`], recorded into the application's own `cb` (of the
    /// device's queue family, not pending; a pool that lets it be begun again).
    pub(crate) fn draw_in(
        &self,
        d: &ash::Device,
        cb: vk::CommandBuffer,
        index: u32,
        offsets: Option<&[vk::Offset2D]>,
    ) {
        self.draw_after(d, cb, index, offsets, None);
    }

    /// As [`Renderer::draw_in`]; with `before`, once the draw is recorded, that command buffer
    /// (executable, of the same family) is submitted on that other queue of the device first,
    /// with nothing of the application's between the two submits, and waited for at the end.
    pub(crate) fn draw_after(
        &self,
        d: &ash::Device,
        cb: vk::CommandBuffer,
        index: u32,
        offsets: Option<&[vk::Offset2D]>,
        before: Option<(vk::Queue, vk::CommandBuffer)>,
    ) {
        let area = vk::Rect2D {
            offset: vk::Offset2D::default(),
            extent: vk::Extent2D {
                width: WIDTH,
                height: HEIGHT,
            },
        };
        let clear = [
            vk::ClearValue {
                color: vk::ClearColorValue {
                    float32: [0.0, 0.0, 1.0, 1.0],
                },
            },
            vk::ClearValue::default(),
        ];
        // SAFETY: the command buffer is idle (every submit is waited for); all objects are alive.
        unsafe {
            d.begin_command_buffer(
                cb,
                &vk::CommandBufferBeginInfo::default()
                    .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
            )
            .unwrap();
            d.cmd_begin_render_pass(
                cb,
                &vk::RenderPassBeginInfo::default()
                    .render_pass(self.pass)
                    .framebuffer(self.framebuffers[index as usize])
                    .render_area(area)
                    .clear_values(&clear),
                vk::SubpassContents::INLINE,
            );
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, self.pipeline);
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
            match offsets {
                Some(o) => {
                    let mut end = vk::SubpassFragmentDensityMapOffsetEndInfoQCOM::default()
                        .fragment_density_offsets(o);
                    d.cmd_end_render_pass2(cb, &vk::SubpassEndInfo::default().push_next(&mut end));
                }
                None => d.cmd_end_render_pass(cb),
            }
            d.end_command_buffer(cb).unwrap();
            if let Some((queue, other)) = before {
                let cbs = [other];
                d.queue_submit(
                    queue,
                    &[vk::SubmitInfo::default().command_buffers(&cbs)],
                    vk::Fence::null(),
                )
                .expect("vkQueueSubmit on the other queue");
            }
            let cbs = [cb];
            d.queue_submit(
                self.queue,
                &[vk::SubmitInfo::default().command_buffers(&cbs)],
                self.fence,
            )
            .expect("vkQueueSubmit");
            d.wait_for_fences(&[self.fence], true, u64::MAX).unwrap();
            d.reset_fences(&[self.fence]).unwrap();
            if let Some((queue, _)) = before {
                d.queue_wait_idle(queue).unwrap();
            }
        }
    }

    pub(crate) fn destroy(self, d: &ash::Device) {
        // SAFETY: the device is idle; each object is destroyed once.
        unsafe {
            d.device_wait_idle().unwrap();
            d.destroy_fence(self.fence, None);
            d.destroy_command_pool(self.pool, None);
            d.destroy_pipeline(self.pipeline, None);
            d.destroy_pipeline_layout(self.layout, None);
            for m in self.modules {
                d.destroy_shader_module(m, None);
            }
            for f in self.framebuffers {
                d.destroy_framebuffer(f, None);
            }
            for v in self.views {
                d.destroy_image_view(v, None);
            }
            d.destroy_render_pass(self.pass, None);
        }
    }
}

/// The swapchain's own VkImages, by index.
pub(crate) fn color_images(app: &App, swapchain: xr::Swapchain) -> Vec<u64> {
    let f: xr::pfn::EnumerateSwapchainImages = func(app, "xrEnumerateSwapchainImages");
    let mut n = 0;
    // SAFETY: the two-call idiom with a buffer of the reported size.
    unsafe {
        assert_eq!(f(swapchain, 0, &mut n, null_mut()), xr::Result::SUCCESS);
        let mut images = vec![
            xr::SwapchainImageVulkanKHR {
                ty: xr::StructureType::SWAPCHAIN_IMAGE_VULKAN_KHR,
                next: null_mut(),
                image: 0,
            };
            n as usize
        ];
        assert_eq!(
            f(swapchain, n, &mut n, images.as_mut_ptr() as *mut _),
            xr::Result::SUCCESS
        );
        images.iter().map(|i| i.image).collect()
    }
}

/// What the density model and the rate conversion give on `profile`'s device for a map whose
/// layers hold `views`: per shading-rate layer (one per map layer, or with `merged` one layer with
/// the finer rate of all), the codes of every texel.
pub(crate) fn expected_codes(
    profile: Profile,
    views: &[Vec<View>],
    pattern: Pattern,
    merged: bool,
) -> Vec<u8> {
    let t = profile.texel();
    let grid = Grid::new([WIDTH, HEIGHT], [t.width, t.height]);
    let [mw, mh] = grid.map_extent();
    let texels = (mw * mh) as usize;
    let mut density_bytes = vec![0u8; texels * 2 * views.len()];
    for (layer, out) in views.iter().zip(density_bytes.chunks_exact_mut(texels * 2)) {
        density::fill(&grid, layer, pattern, out);
    }
    let rates: Vec<[u32; 2]> = profile
        .rates()
        .iter()
        .map(|(e, _)| [e.width, e.height])
        .collect();
    let m = profile.max_fragment();
    let mut codes = vec![0xffu8; if merged { texels } else { texels * views.len() }];
    shading_rate::fill_codes(&density_bytes, texels, merged, [m, m], &rates, &mut codes);
    codes
}

/// What the one draw submitted since the double's last clear shaded at: its effective fragment
/// size per shading-rate attachment texel (`extent` texels), per shading-rate layer, as the GPU the
/// double plays computes it from the pipeline's rate state and the attachment the pass read. Each
/// view reads its own layer where `layers` is 2 (layered attachment, multiview), else layer 0:
/// then every view must get the same rates. The double recorded no misuse meanwhile.
pub(crate) fn rates_drawn(
    env: &Env,
    case: &str,
    layout: Layout,
    layers: u32,
    extent: [u32; 2],
) -> Vec<u8> {
    assert_eq!(env.double.errors(), Vec::<String>::new(), "{case}");
    let draws = env.double.draws();
    assert_eq!(draws.len(), 1, "{case}: {draws:?}");
    let views = &draws[0].views;
    let want_views = if layout == Layout::Multiview { 2 } else { 1 };
    assert_eq!(views.len(), want_views, "{case}: {views:?}");
    for (i, v) in views.iter().enumerate() {
        assert_eq!(v.view, i as u32, "{case}");
        let layer = if layers > 1 { i as u32 } else { 0 };
        assert_eq!(v.layer, Some(layer), "{case}: view {i}");
        assert_eq!([v.columns, v.rows], extent, "{case}: view {i}");
    }
    if layers > 1 {
        views.iter().flat_map(|v| v.codes.iter().copied()).collect()
    } else {
        for v in &views[1..] {
            assert_eq!(
                v.codes, views[0].codes,
                "{case}: one layer, one rate for every view"
            );
        }
        views[0].codes.clone()
    }
}

/// What the comparison with the model stands on, checked without the model: every code is a
/// fragment size the device lists; NONE is full rate everywhere; any other level has coarse
/// texels but shades each view's fovea, its projection centre (docs/density-model.md), at full
/// rate, within every level's full-rate region even when lowered by 7.5°.
fn plausible(
    case: &str,
    profile: Profile,
    level: i32,
    views: &[Vec<View>],
    extent: [u32; 2],
    got: &[u8],
) {
    let m = profile.max_fragment();
    let listed: Vec<[u32; 2]> = profile
        .rates()
        .iter()
        .map(|(e, _)| [e.width, e.height])
        .collect();
    for &c in got {
        let s = shading_rate::decode(c);
        assert!(
            s[0] <= m && s[1] <= m && listed.contains(&s),
            "{case}: {s:?}"
        );
    }
    if level == 0 {
        assert!(got.iter().all(|&c| c == 0), "{case}: NONE is full rate");
        return;
    }
    assert!(got.iter().any(|&c| c != 0), "{case}: no coarse texel");
    let t = profile.texel();
    let texels = (extent[0] * extent[1]) as usize;
    let shadow_layers = got.len() / texels;
    for (layer, views) in views.iter().enumerate() {
        for view in views {
            let r = view.rect;
            let [x, y] = view.fov.projection_center_ndc();
            let px = r.x as f32 + (x + 1.0) / 2.0 * r.width as f32;
            let py = r.y as f32 + (1.0 - y) / 2.0 * r.height as f32;
            let col = (px as u32 / t.width).min(extent[0] - 1);
            let row = (py as u32 / t.height).min(extent[1] - 1);
            let at = (layer.min(shadow_layers - 1)) * texels + (row * extent[0] + col) as usize;
            assert_eq!(got[at], 0, "{case}: the fovea of {view:?}");
        }
    }
}

/// Releases the image and ends the frame with one projection layer: both eyes where `layout`
/// draws them, with the FOVs they were located with.
pub(crate) fn release(
    frame: &Frame,
    layout: Layout,
    swapchain: xr::Swapchain,
    time: xr::Time,
    fovs: [Fov; 2],
) {
    let release: xr::pfn::ReleaseSwapchainImage = func(frame.app, "xrReleaseSwapchainImage");
    let end_frame: xr::pfn::EndFrame = func(frame.app, "xrEndFrame");
    let view = |eye: usize| {
        let (layer, r) = layout.place(eye);
        xr::CompositionLayerProjectionView {
            ty: xr::StructureType::COMPOSITION_LAYER_PROJECTION_VIEW,
            next: null(),
            pose: xr::Posef::IDENTITY,
            fov: xr::Fovf {
                angle_left: fovs[eye].left,
                angle_right: fovs[eye].right,
                angle_up: fovs[eye].up,
                angle_down: fovs[eye].down,
            },
            sub_image: xr::SwapchainSubImage {
                swapchain,
                image_rect: xr::Rect2Di {
                    offset: xr::Offset2Di { x: r.x, y: r.y },
                    extent: xr::Extent2Di {
                        width: r.width as i32,
                        height: r.height as i32,
                    },
                },
                image_array_index: layer,
            },
        }
    };
    let views = [view(0), view(1)];
    let projection = xr::CompositionLayerProjection {
        ty: xr::StructureType::COMPOSITION_LAYER_PROJECTION,
        next: null(),
        layer_flags: xr::CompositionLayerFlags::EMPTY,
        space: frame.space,
        view_count: 2,
        views: views.as_ptr(),
    };
    let layers = [&projection as *const _ as *const xr::CompositionLayerBaseHeader];
    let end = xr::FrameEndInfo {
        ty: xr::StructureType::FRAME_END_INFO,
        next: null(),
        display_time: time,
        environment_blend_mode: xr::EnvironmentBlendMode::OPAQUE,
        layer_count: 1,
        layers: layers.as_ptr(),
    };
    // SAFETY: every struct lives across the calls.
    unsafe {
        assert_eq!(release(swapchain, null()), xr::Result::SUCCESS);
        assert_eq!(end_frame(frame.session, &end), xr::Result::SUCCESS);
    }
}

/// A run's start on `profile`: the double's records and validation's messages from before cleared,
/// an application through fovea on `XR_KHR_vulkan_enable2` (with `foveation`, enabling the
/// `XR_FB_foveation` extensions too), its system, and its multiview Vulkan under validation and the double;
/// `None` after a skip.
pub(crate) fn start(
    env: &Env,
    profile: Profile,
    foveation: bool,
) -> Option<(App, xr::SystemId, Vulkan)> {
    env.double.set_profile(Some(profile));
    crate::support::device::assert_no_double_errors(env);
    env.double.clear();
    take_messages();
    let app = app("XR_KHR_vulkan_enable2", foveation);
    let sys = app.system();
    let layers = [vulkan::VALIDATION_LAYER, fovea_vkdouble::LAYER_NAME];
    let options = vulkan::Options {
        layers: &layers,
        multiview: true,
        ..Default::default()
    };
    let (app, v) = vulkan_or_skip(&env.entry, app, sys, &options)?;
    Some((app, sys, v))
}

/// One profile end to end; false after a skip.
fn run(env: &Env, profile: Profile, layout: Layout) -> bool {
    let what = format!("{} {layout:?}", profile.name());
    let Some((app, sys, v)) = start(env, profile, true) else {
        return false;
    };
    // fovea's xrCreateVulkanDeviceKHR asked for density maps; the driver got shading rates.
    let devices = env.double.events("device");
    assert_eq!(devices.len(), 1, "{what}: {devices:?}");
    assert_eq!(devices[0]["extension"], true, "{what}");
    assert_eq!(devices[0]["features"]["attachment"], true, "{what}");

    let (session, space) = running_session(&app, sys, &v);
    let swapchain = fdm_swapchain(&app, session, layout.layers());

    // The density images follow the device's texel: 16×16 on `nvidia`, 8×8 on `amd`.
    let t = profile.texel();
    let extent = [WIDTH.div_ceil(t.width), HEIGHT.div_ceil(t.height)];
    let density_images = enumerate(&app, swapchain);
    for (i, d) in density_images.iter().enumerate() {
        assert_eq!([d.width, d.height], extent, "{what}: density image {i}");
    }
    // Each got a shadow when fovea made it, in order: R8_UINT, the density image's extent, its
    // layers where the device has layered attachments, else one.
    let layers = if profile.layered() {
        layout.layers()
    } else {
        1
    };
    let merged = layers < layout.layers();
    let shadows: Vec<u64> = env
        .double
        .events("image")
        .iter()
        .filter(|e| e["format"] == vk::Format::R8_UINT.as_raw())
        .map(|e| {
            assert_eq!(e["extent"], serde_json::json!(extent), "{what}: {e}");
            assert_eq!(e["layers"], layers, "{what}: {e}");
            e["image"].as_u64().expect("a handle")
        })
        .collect();
    assert_eq!(
        shadows.len(),
        density_images.len(),
        "{what}: one shadow each"
    );

    let color = color_images(&app, swapchain);
    let density: Vec<u64> = density_images.iter().map(|d| d.image).collect();
    let renderer = Renderer::new(&v, layout, &color, Some(&density));
    // The pass reached the driver with a shading-rate attachment of the device's texel.
    let passes = env.double.events("render_pass");
    assert_eq!(passes.len(), 1, "{what}: {passes:?}");
    assert_eq!(
        passes[0]["subpasses"][0]["shading_rate"]["texel"],
        serde_json::json!([t.width, t.height]),
        "{what}: {passes:?}"
    );

    let frame = Frame {
        app: &app,
        session,
        space,
    };
    let texels = (extent[0] * extent[1]) as usize;
    let mut high = None;
    let mut submitted = false;
    // NONE, LOW, MEDIUM, HIGH, then HIGH lowered by 7.5° (XrFoveationLevelProfileCreateInfoFB's
    // verticalOffset).
    for (level, offset) in [(0, 0.0), (1, 0.0), (2, 0.0), (3, 0.0), (3, -7.5)] {
        apply_profile(&app, session, swapchain, &level_info(level, 0, offset));
        let pattern = Pattern {
            level: Level::from_index(level as u32).expect("a level"),
            vertical_offset_deg: offset,
        };
        // Four frames: the first image acquired gets the map computed anew, the next two the
        // cached map uploaded, and the fourth is the first again, which keeps what it holds.
        let mut seen = [0; 3];
        for n in 0..4 {
            let case = format!("{what} level {level} offset {offset} frame {n}");
            crate::support::device::assert_no_double_errors(env);
            env.double.clear();
            let (index, fovs, time) = frame.acquire(swapchain);
            renderer.draw(&v.device, index);
            release(&frame, layout, swapchain, time, fovs);
            seen[index as usize] += 1;
            let got = rates_drawn(env, &case, layout, layers, extent);
            let views = layout.views(fovs, submitted);
            submitted = true;
            let want = expected_codes(profile, &views, pattern, merged);
            if let Some(at) = got.iter().zip(&want).position(|(g, w)| g != w) {
                panic!(
                    "{case}: image {index}: code {} at texel {} of layer {} (extent {extent:?}), \
                     the model says {}",
                    got[at],
                    at % texels,
                    at / texels,
                    want[at]
                );
            }
            plausible(&case, profile, level, &views, extent, &got);
            if n > 0 || level != 3 {
                continue;
            }
            if offset == 0.0 {
                // What the comparison tells apart. Multiview: the eyes differ (their FOVs mirror
                // each other); `nvidia` keeps each eye's own rates, `amd` per texel the finer of
                // the two, which is neither eye's map. Double-wide: the map follows the submitted
                // halves, not the whole layer as before the first submission.
                if layout == Layout::Multiview {
                    let per_eye = expected_codes(profile, &views, pattern, false);
                    assert_ne!(per_eye[..texels], per_eye[texels..], "{case}: the eyes");
                    if merged {
                        assert_ne!(got[..], per_eye[..texels], "{case}: merged");
                        assert_ne!(got[..], per_eye[texels..], "{case}: merged");
                    }
                } else {
                    let before =
                        expected_codes(profile, &layout.views(fovs, false), pattern, merged);
                    assert_ne!(got, before, "{case}: the submitted views");
                }
                high = Some(got);
            } else {
                assert_ne!(
                    high.as_ref(),
                    Some(&got),
                    "{case}: the offset moves the map"
                );
            }
        }
        assert!(
            seen.iter().all(|&s| s >= 1) && seen.contains(&2),
            "{what} level {level}: every image drawn, one twice: {seen:?}"
        );
    }
    assert_eq!(env.double.errors(), Vec::<String>::new(), "{what}");

    renderer.destroy(&v.device);
    let destroy_session: xr::pfn::DestroySession = func(&app, "xrDestroySession");
    // SAFETY: the session is live and nothing of it is in use.
    assert_eq!(unsafe { destroy_session(session) }, xr::Result::SUCCESS);
    // SAFETY: the test is done with the device: validation reports what is still alive on it.
    unsafe { v.destroy_device() };
    assert_eq!(app.destroy(), xr::Result::SUCCESS);
    // SAFETY: the device is gone.
    unsafe { v.destroy_instance() };
    assert_no_messages();
    true
}
