//! Density-map offsets (`VK_EXT_fragment_density_map_offset`, and the
//! `VK_QCOM_fragment_density_map_offset` name) that fovea's Vulkan layer offers on shading-rate
//! GPUs (docs/vulkan-layer.md#density-map-offsets).
//!
//! Stack as in [`crate::support::device`]: this test → fovea → validation → the double (which
//! reports the effective fragment size of every draw per shading-rate texel) → lavapipe (which
//! runs the conversion's compute shader for real). The application enables the offset extension
//! and its feature, creates its map and colour image with the offset flag, uploads a map whose
//! every texel wants another fragment size, and draws one full-screen triangle in a pass it ends
//! with offsets. Checked: each draw shades exactly as the specification's lookup with the offsets
//! says (x′ = x − offset, clamped to the map, whole texels at the reported granularity), with
//! render passes and dynamic rendering, under both names; zero or absent offsets change nothing;
//! offsets are fixed per recording (a resubmission keeps them, a new recording takes its own);
//! two command buffers on one map each get their own; a suspended and resumed instance shifts
//! once, by its last end's offsets; a secondary that begins and ends rendering applies its own, and
//! a secondary's draws inside a primary's pass take the primary's; only the last subpass's end
//! carries offsets; each view is shifted by its own (layered and merged shadows); offsets that
//! break the valid usage shade as the specification's lookup at each texel's centre; command
//! buffers recorded on two threads at once, one of them run twice in one submit
//! (`SIMULTANEOUS_USE`), each shade with their own;
//! nothing of the offsets reaches the driver (the double records every extension name and sType
//! of the device, and errors for offset structs, flags and names anywhere), and validation is
//! silent but for its 1.3.239 stage false positives.

use std::ffi::{c_void, CStr};

use ash::vk;
use ash::vk::Handle as _;
use fovea_vkdouble::Profile;
use serde_json::Value;

use crate::support::device::{env, take_messages, with_fovea, Dev, Env, Features, Vk};
use crate::support::vulkan::{
    attachments2, begin_pass, draw_fullscreen, range, spv, stages, Fixed, AREA, CLEAR, COLOR,
    DENSITY, FDM_LAYOUT, FRAGMENT, SIZE, VERTEX,
};
use crate::vk::convert::{model_codes, Buffer};

const EXT: &CStr = c"VK_EXT_fragment_density_map_offset";
const QCOM: &CStr = c"VK_QCOM_fragment_density_map_offset";
/// `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT` (the QCOM bit's value).
const OFFSET_BIT: vk::ImageCreateFlags = vk::ImageCreateFlags::FRAGMENT_DENSITY_MAP_OFFSET_QCOM;
/// `VK_STRUCTURE_TYPE_RENDERING_END_INFO_EXT`.
const RENDERING_END_INFO: vk::StructureType = vk::StructureType::from_raw(1_000_619_003);

/// `VkRenderingEndInfoEXT`.
#[repr(C)]
struct RenderingEndInfo {
    s_type: vk::StructureType,
    p_next: *const c_void,
}

type EndRendering2 = unsafe extern "system" fn(vk::CommandBuffer, *const RenderingEndInfo);

/// Density bytes that want a fragment edge of 1, 2 and 4 pixels.
const EDGES: [u8; 3] = [255, 127, 63];

/// The map's layers, one after the other: texel (x, y) of layer l wants an edge of
/// `EDGES[(x + 2y + l) % 3]` wide and `EDGES[(2x + y + 2l) % 3]` high, so that a shift by one
/// texel either way changes what almost every texel shades with, and the layers differ.
fn map_bytes(side: u32, layers: u32) -> Vec<u8> {
    let mut out = Vec::new();
    for l in 0..layers {
        for y in 0..side {
            for x in 0..side {
                out.push(EDGES[((x + 2 * y + l) % 3) as usize]);
                out.push(EDGES[((2 * x + y + 2 * l) % 3) as usize]);
            }
        }
    }
    out
}

/// The specification's lookup (x′ = x − offset, texel ⌊x′ / texel⌋ clamped to the map) at the
/// centre of each shading-rate texel, for one layer of `bytes` and its offset.
fn shifted(bytes: &[u8], side: u32, texel: u32, offset: vk::Offset2D) -> Vec<u8> {
    let (t, last) = (i64::from(texel), i64::from(side) - 1);
    let fetch = |i: i64, o: i32| {
        ((2 * i + 1) * t - 2 * i64::from(o))
            .div_euclid(2 * t)
            .clamp(0, last)
    };
    let mut out = Vec::new();
    for y in 0..i64::from(side) {
        for x in 0..i64::from(side) {
            let (mx, my) = (fetch(x, offset.x), fetch(y, offset.y));
            let i = ((my * i64::from(side) + mx) * 2) as usize;
            out.extend_from_slice(&bytes[i..i + 2]);
        }
    }
    out
}

/// How a pass ends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum End<'a> {
    /// No offsets struct.
    Absent,
    /// The offsets struct with these offsets (empty: a count of zero).
    With(&'a [vk::Offset2D]),
}

/// How the pass is begun and ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Path {
    /// `vkCmdBeginRenderPass2` … `vkCmdEndRenderPass2`.
    RenderPass,
    /// `vkCmdBeginRendering` … `vkCmdEndRendering2EXT`.
    Rendering,
}

/// An application with the offset extension (`name`) enabled: its map (with the offset flag), a
/// colour target (with it too, as the specification asks of a pass's attachments), a render pass
/// and framebuffer, a pipeline for each path, and the map's bytes uploaded.
struct Scene {
    dev: Dev,
    profile: Profile,
    texel: u32,
    side: u32,
    /// The map's and the colour image's layers; with 2, every pass has view mask 0b11.
    layers: u32,
    bytes: Vec<u8>,
    images: Vec<(vk::Image, vk::DeviceMemory, vk::ImageView)>,
    pass: vk::RenderPass,
    framebuffer: vk::Framebuffer,
    layout: vk::PipelineLayout,
    pass_pipeline: vk::Pipeline,
    rendering_pipeline: vk::Pipeline,
    end_rendering2: Option<EndRendering2>,
    staging: Option<Buffer>,
}

impl Scene {
    fn new(vk: &Vk, profile: Profile, name: &CStr) -> Scene {
        Scene::with_views(vk, profile, name, 1)
    }

    /// A scene whose map and colour target have `layers` layers, one view each.
    fn with_views(vk: &Vk, profile: Profile, name: &CStr, layers: u32) -> Scene {
        let mut feature = vk::PhysicalDeviceFragmentDensityMapOffsetFeaturesQCOM::default()
            .fragment_density_map_offset(true);
        let d = vk.device_with(&[name], Features::FDM_MULTIVIEW, Some(&mut feature));
        let dev = Dev::new(vk, d);
        let texel = profile.texel().width;
        let side = SIZE / texel;
        let map = image(
            &dev,
            DENSITY,
            side,
            layers,
            vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT,
        );
        let color = image(
            &dev,
            COLOR,
            SIZE,
            layers,
            vk::ImageUsageFlags::COLOR_ATTACHMENT,
        );
        let bytes = map_bytes(side, layers);
        let mask = if layers > 1 { (1u32 << layers) - 1 } else { 0 };
        let staging = dev.buffer(bytes.len() as u64, vk::BufferUsageFlags::TRANSFER_SRC);
        dev.write(&staging, &bytes);
        let d = &dev.d;
        // SAFETY: every struct lives across its call; the objects are destroyed in `finish`.
        unsafe {
            // Two passes of one recording write the colour attachment in order.
            let pass = render_pass(d, mask, 1, &[color_dependency(vk::SUBPASS_EXTERNAL, 0)]);
            let framebuffer = framebuffer(d, pass, &[color.2, map.2]);
            let layout = d
                .create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default(), None)
                .expect("vkCreatePipelineLayout");
            let pipelines = pipelines(d, |stages, fixed| {
                let formats = [COLOR];
                let mut rendering = vk::PipelineRenderingCreateInfo::default()
                    .color_attachment_formats(&formats)
                    .view_mask(mask);
                let infos = [
                    fixed.info(stages, layout).render_pass(pass).subpass(0),
                    fixed
                        .info(stages, layout)
                        .flags(
                            vk::PipelineCreateFlags::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_EXT,
                        )
                        .push_next(&mut rendering),
                ];
                d.create_graphics_pipelines(vk::PipelineCache::null(), &infos, None)
            });
            let f = (vk.instance.fp_v1_0().get_device_proc_addr)(
                d.handle(),
                c"vkCmdEndRendering2EXT".as_ptr(),
            );
            let end_rendering2 =
                f.map(|f| std::mem::transmute::<unsafe extern "system" fn(), EndRendering2>(f));
            Scene {
                dev,
                profile,
                texel,
                side,
                layers,
                bytes,
                images: vec![map, color],
                pass,
                framebuffer,
                layout,
                pass_pipeline: pipelines[0],
                rendering_pipeline: pipelines[1],
                end_rendering2,
                staging: Some(staging),
            }
        }
    }

    fn map(&self) -> (vk::Image, vk::ImageView) {
        (self.images[0].0, self.images[0].2)
    }

    fn color(&self) -> (vk::Image, vk::ImageView) {
        (self.images[1].0, self.images[1].2)
    }

    /// Records the upload of the map (ending in the density layout) and the colour image's move
    /// into `COLOR_ATTACHMENT_OPTIMAL`, after any earlier submission's colour writes (several
    /// command buffers render into the one colour image, and the move is a write).
    fn prepare(&self, cb: vk::CommandBuffer) {
        let staging = self.staging.as_ref().expect("staging");
        self.dev
            .upload(cb, staging, self.map().0, self.side, self.layers);
        let barrier = vk::ImageMemoryBarrier::default()
            .image(self.color().0)
            .subresource_range(range(0, self.layers))
            .old_layout(vk::ImageLayout::UNDEFINED)
            .new_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
            .dst_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED);
        // SAFETY: `cb` is recording on this device.
        unsafe {
            self.dev.d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[barrier],
            );
        }
    }

    /// Records a dependency from one pass's colour writes to the next's (which clears it again).
    fn between(&self, cb: vk::CommandBuffer) {
        let color = vk::AccessFlags::COLOR_ATTACHMENT_WRITE;
        let stage = vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT;
        // SAFETY: `cb` is recording on this device, outside a pass.
        unsafe {
            self.dev.d.cmd_pipeline_barrier(
                cb,
                stage,
                stage,
                vk::DependencyFlags::empty(),
                &[vk::MemoryBarrier::default()
                    .src_access_mask(color)
                    .dst_access_mask(color)],
                &[],
                &[],
            );
        }
    }

    /// Begins `cbs` again (after resetting the pool, which resets every command buffer of it).
    fn record_again(&self, cbs: &[vk::CommandBuffer]) {
        // SAFETY: none of the pool's command buffers is pending (the queue is idle).
        unsafe {
            let d = &self.dev.d;
            d.reset_command_pool(self.dev.pool, vk::CommandPoolResetFlags::empty())
                .expect("vkResetCommandPool");
            for &cb in cbs {
                d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
                    .expect("vkBeginCommandBuffer");
            }
        }
    }

    /// Records one pass on `path` with one full-screen draw, ended as `end` says; a rendering
    /// begun with `flags`.
    fn pass(&self, cb: vk::CommandBuffer, path: Path, flags: vk::RenderingFlags, end: End<'_>) {
        let d = &self.dev.d;
        let mut offsets = vk::SubpassFragmentDensityMapOffsetEndInfoQCOM::default();
        if let End::With(o) = end {
            offsets = offsets.fragment_density_offsets(o);
        }
        let chain = match end {
            End::Absent => std::ptr::null(),
            End::With(_) => &offsets as *const _ as *const c_void,
        };
        // SAFETY: `cb` is recording on this device; every struct lives across its call.
        unsafe {
            match path {
                Path::RenderPass => {
                    let begin = vk::RenderPassBeginInfo::default()
                        .render_pass(self.pass)
                        .framebuffer(self.framebuffer)
                        .render_area(AREA)
                        .clear_values(&CLEAR);
                    d.cmd_begin_render_pass2(
                        cb,
                        &begin,
                        &vk::SubpassBeginInfo::default().contents(vk::SubpassContents::INLINE),
                    );
                    draw_fullscreen(d, cb, self.pass_pipeline);
                    let info = vk::SubpassEndInfo {
                        p_next: chain,
                        ..Default::default()
                    };
                    d.cmd_end_render_pass2(cb, &info);
                }
                Path::Rendering => {
                    let color = [vk::RenderingAttachmentInfo::default()
                        .image_view(self.color().1)
                        .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                        .load_op(vk::AttachmentLoadOp::CLEAR)
                        .store_op(vk::AttachmentStoreOp::STORE)
                        .clear_value(CLEAR[0])];
                    let mut density = vk::RenderingFragmentDensityMapAttachmentInfoEXT::default()
                        .image_view(self.map().1)
                        .image_layout(FDM_LAYOUT);
                    let mut info = vk::RenderingInfo::default()
                        .flags(flags)
                        .render_area(AREA)
                        .layer_count(1)
                        .color_attachments(&color)
                        .push_next(&mut density);
                    if self.layers > 1 {
                        info = info.view_mask((1 << self.layers) - 1);
                    }
                    d.cmd_begin_rendering(cb, &info);
                    draw_fullscreen(d, cb, self.rendering_pipeline);
                    let end2 = self
                        .end_rendering2
                        .expect("vkCmdEndRendering2EXT is offered");
                    end2(
                        cb,
                        &RenderingEndInfo {
                            s_type: RENDERING_END_INFO,
                            p_next: chain,
                        },
                    );
                }
            }
        }
    }

    /// What each view shades with where the pass ends with `offsets` (per view; missing ones are
    /// (0, 0)): the model's rates of each layer seen through its offset, one per view (layered),
    /// or of the finer of all layers, the same for every view (merged).
    fn want(&self, offsets: &[vk::Offset2D]) -> Vec<Vec<u8>> {
        let texels = (self.side * self.side) as usize;
        let layer = |l: usize| {
            let o = offsets.get(l).copied().unwrap_or_default();
            let bytes = &self.bytes[l * texels * 2..(l + 1) * texels * 2];
            shifted(bytes, self.side, self.texel, o)
        };
        let all: Vec<u8> = (0..self.layers as usize).flat_map(layer).collect();
        let codes = model_codes(self.profile, &all, texels, self.layers as usize);
        if codes.len() == texels {
            vec![codes; self.layers as usize]
        } else {
            codes.chunks(texels).map(<[u8]>::to_vec).collect()
        }
    }

    /// Asserts that draw 0 of every pass of `cb`'s latest submit shaded, in every view, as the
    /// map seen through the offsets `ends[pass]`.
    fn assert_shifted(
        &self,
        env: &Env,
        cb: vk::CommandBuffer,
        ends: &[&[vk::Offset2D]],
        what: &str,
    ) {
        let still = self.want(&[]);
        for (pass, &offsets) in ends.iter().enumerate() {
            let got = env
                .double
                .effective_rates(cb.as_raw(), pass, 0)
                .unwrap_or_else(|| panic!("{what}: no draw in pass {pass}"));
            assert_eq!(got.len(), self.layers as usize, "{what}: one rate per view");
            let want = self.want(offsets);
            for (v, w) in got.iter().zip(&want) {
                assert_eq!((v.columns, v.rows), (self.side, self.side), "{what}");
                assert!(
                    &v.codes == w,
                    "{what}, pass {pass}, view {}, offsets {offsets:?}: shaded {:?}, want {w:?}",
                    v.view,
                    v.codes
                );
            }
            if offsets.iter().any(|&o| o != vk::Offset2D::default()) {
                assert_ne!(want, still, "{what}: offsets that test nothing");
            }
        }
    }

    /// Submits the executable `cbs` in one submit and waits for the queue.
    fn submit(&self, cbs: &[vk::CommandBuffer]) {
        // SAFETY: `cbs` are executable on this device (pending more than once only with
        // simultaneous use); the queue is this thread's.
        unsafe {
            self.dev
                .d
                .queue_submit(
                    self.dev.queue,
                    &[vk::SubmitInfo::default().command_buffers(cbs)],
                    vk::Fence::null(),
                )
                .expect("vkQueueSubmit");
            self.dev.d.queue_wait_idle(self.dev.queue).expect("idle");
        }
    }

    /// Records one pass on `path` ended with `end` in a new command buffer (after [`Scene::prepare`]),
    /// submits it and asserts its draw shades as the map seen through `want`; the command buffer.
    fn shade(
        &self,
        env: &Env,
        path: Path,
        end: End<'_>,
        want: &[vk::Offset2D],
        what: &str,
    ) -> vk::CommandBuffer {
        let cb = self.dev.begin();
        self.prepare(cb);
        self.pass(cb, path, vk::RenderingFlags::empty(), end);
        self.dev.submit(cb);
        self.assert_shifted(env, cb, &[want], what);
        cb
    }

    /// A secondary command buffer from the pool, begun with `flags` and `inheritance`.
    fn secondary(
        &self,
        flags: vk::CommandBufferUsageFlags,
        inheritance: &vk::CommandBufferInheritanceInfo<'_>,
    ) -> vk::CommandBuffer {
        let d = &self.dev.d;
        // SAFETY: the pool is this device's; every struct lives across its call.
        unsafe {
            let s = d
                .allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default()
                        .command_pool(self.dev.pool)
                        .level(vk::CommandBufferLevel::SECONDARY)
                        .command_buffer_count(1),
                )
                .expect("vkAllocateCommandBuffers")[0];
            d.begin_command_buffer(
                s,
                &vk::CommandBufferBeginInfo::default()
                    .flags(flags)
                    .inheritance_info(inheritance),
            )
            .expect("vkBeginCommandBuffer");
            s
        }
    }

    /// Asserts that the one draw `primary` ran (itself or through `secondary`) shaded as the map
    /// seen through `offsets`, which must shift it.
    fn assert_one_draw(
        &self,
        env: &Env,
        primary: vk::CommandBuffer,
        secondary: vk::CommandBuffer,
        offsets: &[vk::Offset2D],
        what: &str,
    ) {
        let draws: Vec<_> = env
            .double
            .draws()
            .into_iter()
            .filter(|dr| {
                dr.command_buffer == primary.as_raw() || dr.command_buffer == secondary.as_raw()
            })
            .collect();
        assert_eq!(draws.len(), 1, "{draws:?}");
        let want = &self.want(offsets)[0];
        assert!(
            &draws[0].views[0].codes == want,
            "{what}: shaded {:?}, want {want:?}",
            draws[0].views[0].codes
        );
        assert_ne!(want, &self.want(&[])[0]);
    }

    /// Destroys everything and checks what reached the driver: no offset name, struct or flag
    /// (the double records each as an error), validation silent.
    fn finish(mut self, env: &Env, vk: Vk) {
        let devices = env.double.events("device");
        let last = devices.last().expect("the device reached the double");
        for name in [EXT, QCOM] {
            let name = name.to_str().unwrap();
            assert!(
                !last["extensions"]
                    .as_array()
                    .expect("names")
                    .contains(&Value::from(name)),
                "{name} reached the driver: {last}"
            );
        }
        let feature = vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_OFFSET_FEATURES_QCOM;
        assert!(
            !last["chain"]
                .as_array()
                .expect("sTypes")
                .contains(&Value::from(feature.as_raw())),
            "the offset feature struct reached the driver: {last}"
        );
        if let Some(s) = self.staging.take() {
            self.dev.free(s);
        }
        // SAFETY: the queue is idle; each object is destroyed once.
        unsafe {
            let d = &self.dev.d;
            d.device_wait_idle().expect("idle");
            d.destroy_pipeline(self.pass_pipeline, None);
            d.destroy_pipeline(self.rendering_pipeline, None);
            d.destroy_pipeline_layout(self.layout, None);
            d.destroy_framebuffer(self.framebuffer, None);
            d.destroy_render_pass(self.pass, None);
            for (image, memory, view) in self.images.drain(..) {
                d.destroy_image_view(view, None);
                d.destroy_image(image, None);
                d.free_memory(memory, None);
            }
        }
        self.dev.finish(env, vk);
    }
}

/// A render pass of `subpasses` alike subpasses of view mask `view_mask`: colour attachment 0
/// (cleared, from `UNDEFINED`) and density map 1, as [`attachments2`] has them, ordered by
/// `deps`.
///
/// # Safety
/// `d` must be alive.
unsafe fn render_pass(
    d: &ash::Device,
    view_mask: u32,
    subpasses: usize,
    deps: &[vk::SubpassDependency2<'_>],
) -> vk::RenderPass {
    let atts = attachments2(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL);
    let color_ref = [vk::AttachmentReference2::default()
        .attachment(0)
        .layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)];
    let subpass = vk::SubpassDescription2::default()
        .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
        .view_mask(view_mask)
        .color_attachments(&color_ref);
    let subpasses = vec![subpass; subpasses];
    let mut fdm = vk::RenderPassFragmentDensityMapCreateInfoEXT::default()
        .fragment_density_map_attachment(vk::AttachmentReference {
            attachment: 1,
            layout: FDM_LAYOUT,
        });
    let info = vk::RenderPassCreateInfo2::default()
        .attachments(&atts)
        .subpasses(&subpasses)
        .dependencies(deps)
        .push_next(&mut fdm);
    // SAFETY: the caller's promise; the structs live across the call.
    unsafe { d.create_render_pass2(&info, None) }
        .unwrap_or_else(|e| panic!("vkCreateRenderPass2: {e}; {:?}", take_messages()))
}

/// A dependency of subpass `dst`'s colour writes on `src`'s.
fn color_dependency(src: u32, dst: u32) -> vk::SubpassDependency2<'static> {
    let color = vk::AccessFlags::COLOR_ATTACHMENT_WRITE;
    let stage = vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT;
    vk::SubpassDependency2::default()
        .src_subpass(src)
        .dst_subpass(dst)
        .src_stage_mask(stage)
        .dst_stage_mask(stage)
        .src_access_mask(color)
        .dst_access_mask(color)
}

/// The pipelines `create` makes of the suite's full-screen shaders' stages ([`VERTEX`],
/// [`FRAGMENT`]) and the fixed state ([`Fixed`]); the shader modules go again after.
///
/// # Safety
/// `d` must be alive.
unsafe fn pipelines(
    d: &ash::Device,
    create: impl FnOnce(
        &[vk::PipelineShaderStageCreateInfo<'static>; 2],
        &Fixed,
    ) -> Result<Vec<vk::Pipeline>, (Vec<vk::Pipeline>, vk::Result)>,
) -> Vec<vk::Pipeline> {
    let module = |bytes: &[u8]| {
        let words = spv(bytes);
        // SAFETY: the caller's promise; the struct lives across the call.
        unsafe { d.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None) }
            .expect("vkCreateShaderModule")
    };
    let modules = [module(VERTEX), module(FRAGMENT)];
    let made = create(&stages(modules), &Fixed::new());
    for m in modules {
        // SAFETY: made above, used by nothing once the pipelines are made.
        unsafe { d.destroy_shader_module(m, None) };
    }
    made.unwrap_or_else(|e| panic!("pipelines: {:?}; {:?}", e.1, take_messages()))
}

/// A framebuffer of `pass` on `views` (colour, then map), [`SIZE`] square.
///
/// # Safety
/// `d` must be alive; `pass` and `views` its.
unsafe fn framebuffer(
    d: &ash::Device,
    pass: vk::RenderPass,
    views: &[vk::ImageView],
) -> vk::Framebuffer {
    let info = vk::FramebufferCreateInfo::default()
        .render_pass(pass)
        .attachments(views)
        .width(SIZE)
        .height(SIZE)
        .layers(1);
    // SAFETY: the caller's promise; the struct lives across the call.
    unsafe { d.create_framebuffer(&info, None) }.expect("vkCreateFramebuffer")
}

/// A `side`×`side` image of `layers` layers with the offset flag and a view of every layer.
fn image(
    dev: &Dev,
    format: vk::Format,
    side: u32,
    layers: u32,
    usage: vk::ImageUsageFlags,
) -> (vk::Image, vk::DeviceMemory, vk::ImageView) {
    let usage = usage | vk::ImageUsageFlags::TRANSFER_DST;
    dev.image_with_flags(format, side, layers, usage, OFFSET_BIT)
}

/// Runs `test` on the stack on `nvidia` with fovea ([`with_fovea`]; skipped where a piece is
/// missing) with a one-view [`Scene`] with `name` and its texel size in pixels, then finishes the
/// scene ([`Scene::finish`]).
fn on_nvidia(name: &CStr, test: impl FnOnce(&Env, &Scene, i32)) {
    let Some((_serial, env, vk)) = with_fovea(Profile::Nvidia) else {
        return;
    };
    let scene = Scene::new(&vk, Profile::Nvidia, name);
    test(env, &scene, scene.texel as i32);
    scene.finish(env, vk);
}

fn at(x: i32, y: i32) -> vk::Offset2D {
    vk::Offset2D { x, y }
}

/// On both profiles (16- and 8-pixel texels), with render passes and dynamic rendering: one
/// recording per offset, each pass ending with offsets (whole texels, both signs, beyond the map
/// so that the edge texels are repeated), with a zero offset, with a count of zero, and without
/// the struct; each draw shades as the map seen through its offset.
#[test]
fn passes_ended_with_offsets_shade_as_the_shifted_map() {
    let Some((_serial, env)) = env() else { return };
    for profile in [Profile::Nvidia, Profile::Amd] {
        let Some(vk) = Vk::new(env, profile, true) else {
            return;
        };
        let scene = Scene::new(&vk, profile, EXT);
        let t = scene.texel as i32;
        for path in [Path::RenderPass, Path::Rendering] {
            let cases: [(End<'_>, vk::Offset2D); 7] = [
                (End::With(&[at(t, 0)]), at(t, 0)),
                (End::With(&[at(-t, 2 * t)]), at(-t, 2 * t)),
                (End::With(&[at(3 * t, -2 * t)]), at(3 * t, -2 * t)),
                (End::With(&[at(-20 * t, 20 * t)]), at(-20 * t, 20 * t)),
                (End::With(&[at(0, 0)]), at(0, 0)),
                (End::With(&[]), at(0, 0)),
                (End::Absent, at(0, 0)),
            ];
            for (end, o) in cases {
                let what = format!("{profile:?} {path:?} {end:?}");
                scene.shade(env, path, end, &[o], &what);
            }
        }
        scene.finish(env, vk);
    }
}

/// The QCOM name does the same (it has render passes only): the device gets offsets under it.
#[test]
fn the_qcom_name_shifts_render_passes_alike() {
    on_nvidia(QCOM, |env, scene, t| {
        for o in [at(2 * t, t), at(-t, -t), at(0, 0)] {
            scene.shade(
                env,
                Path::RenderPass,
                End::With(&[o]),
                &[o],
                &format!("QCOM {o:?}"),
            );
        }
    });
}

/// Offsets are fixed per recording, as on a native driver: a command buffer submitted again keeps
/// the offsets it was recorded with (while another command buffer is recorded and submitted with
/// other offsets on the same map in between), and recorded again with new offsets shades with
/// those. Two command buffers recorded with different offsets on the same map, submitted
/// together, each shade with their own; so do two passes of one recording.
#[test]
fn offsets_are_fixed_per_recording_and_per_command_buffer() {
    on_nvidia(EXT, |env, scene, t| {
        let (a, b, c) = (at(t, 0), at(0, -2 * t), at(-3 * t, t));
        for path in [Path::RenderPass, Path::Rendering] {
            let what = format!("{path:?}");
            let first = scene.shade(env, path, End::With(&[a]), &[a], &format!("{what}: first"));
            let other = scene.shade(env, path, End::With(&[b]), &[b], &format!("{what}: other"));
            // Submitted again, unchanged: its own offsets, not the other's.
            scene.submit(&[first]);
            scene.assert_shifted(env, first, &[&[a]], &format!("{what}: first again"));
            // Recorded again with new offsets, two passes of which the second has other offsets.
            scene.record_again(&[first]);
            scene.prepare(first);
            scene.pass(first, path, vk::RenderingFlags::empty(), End::With(&[c]));
            scene.between(first);
            scene.pass(first, path, vk::RenderingFlags::empty(), End::With(&[b]));
            scene.dev.submit(first);
            scene.assert_shifted(
                env,
                first,
                &[&[c], &[b]],
                &format!("{what}: first recorded again"),
            );
            // Both in one submit: each its own.
            scene.record_again(&[first, other]);
            scene.prepare(first);
            scene.pass(first, path, vk::RenderingFlags::empty(), End::With(&[a]));
            scene.between(other);
            scene.prepare(other);
            scene.pass(other, path, vk::RenderingFlags::empty(), End::With(&[c]));
            // SAFETY: both are recording on this device.
            unsafe {
                let d = &scene.dev.d;
                d.end_command_buffer(first).expect("end");
                d.end_command_buffer(other).expect("end");
            }
            scene.submit(&[first, other]);
            scene.assert_shifted(env, first, &[&[a]], &format!("{what}: together, first"));
            scene.assert_shifted(env, other, &[&[c]], &format!("{what}: together, other"));
        }
    });
}

/// A dynamic render pass instance suspended and resumed shifts once, by the offsets of the end
/// after its last resumption: the suspending ends' offsets are ignored, as the specification
/// says, and both parts' draws shade alike.
#[test]
fn a_suspended_and_resumed_instance_shifts_once_by_its_last_end() {
    on_nvidia(EXT, |env, scene, t| {
        let (ignored, last) = (at(2 * t, 2 * t), at(-t, t));
        let cb = scene.dev.begin();
        scene.prepare(cb);
        let flags = vk::RenderingFlags::SUSPENDING;
        scene.pass(cb, Path::Rendering, flags, End::With(&[ignored]));
        let flags = vk::RenderingFlags::RESUMING | vk::RenderingFlags::SUSPENDING;
        scene.pass(cb, Path::Rendering, flags, End::With(&[ignored]));
        scene.pass(
            cb,
            Path::Rendering,
            vk::RenderingFlags::RESUMING,
            End::With(&[last]),
        );
        scene.dev.submit(cb);
        scene.assert_shifted(
            env,
            cb,
            &[&[last], &[last], &[last]],
            "suspended and resumed",
        );
    });
}

/// A secondary command buffer that begins and ends rendering itself, with offsets, executed from
/// a primary: the draw shades with the secondary's offsets.
#[test]
fn a_secondary_that_begins_and_ends_rendering_applies_its_offsets() {
    on_nvidia(EXT, |env, scene, t| {
        let o = at(t, -t);
        let d = &scene.dev.d;
        let secondary = scene.secondary(
            vk::CommandBufferUsageFlags::empty(),
            &vk::CommandBufferInheritanceInfo::default(),
        );
        scene.pass(
            secondary,
            Path::Rendering,
            vk::RenderingFlags::empty(),
            End::With(&[o]),
        );
        let primary = scene.dev.begin();
        scene.prepare(primary);
        // SAFETY: both are this device's; the secondary is executable.
        unsafe {
            d.end_command_buffer(secondary).expect("end");
            d.cmd_execute_commands(primary, &[secondary]);
        }
        scene.dev.submit(primary);
        scene.assert_one_draw(env, primary, secondary, &[o], "secondary");
    });
}

/// Multiview (a two-layer map, view mask 0b11), both paths: each view is shifted by its own
/// offset, on `nvidia` in its own shadow layer, on `amd` before the finer rate of both layers is
/// taken for the one shared layer; a count of one leaves the second view at (0, 0).
#[test]
fn each_view_is_shifted_by_its_own_offset() {
    let Some((_serial, env)) = env() else { return };
    for profile in [Profile::Nvidia, Profile::Amd] {
        let Some(vk) = Vk::new(env, profile, true) else {
            return;
        };
        let scene = Scene::with_views(&vk, profile, EXT, 2);
        let t = scene.texel as i32;
        for path in [Path::RenderPass, Path::Rendering] {
            let ends: [&[vk::Offset2D]; 3] = [
                &[at(t, 0), at(-2 * t, t)],
                &[at(0, 0), at(3 * t, -t)],
                &[at(-t, -t)],
            ];
            for offsets in ends {
                let what = format!("{profile:?} {path:?} {offsets:?}");
                scene.shade(env, path, End::With(offsets), offsets, &what);
            }
        }
        scene.finish(env, vk);
    }
}

/// Offsets that break the specification's valid usage (not multiples of the granularity, more
/// than the views) are the application's error: nothing crashes, the driver and validation hear
/// nothing of them, and each shading-rate texel shades as the specification's lookup at its
/// centre says; offsets beyond the views are ignored.
#[test]
fn invalid_offsets_shade_as_the_lookup_at_each_texel_centre() {
    on_nvidia(EXT, |env, scene, t| {
        let cases: [&[vk::Offset2D]; 5] = [
            &[at(t / 2 + 1, -t / 2)],
            &[at(t + 3, 2 * t - 5)],
            &[at(-t / 2 - 1, t / 2)],
            &[at(-7, 9)],
            &[at(t, 0), at(5 * t, 5 * t), at(-t, 0)],
        ];
        for path in [Path::RenderPass, Path::Rendering] {
            for offsets in cases {
                let what = format!("{path:?} {offsets:?}");
                scene.shade(env, path, End::With(offsets), &offsets[..1], &what);
            }
        }
    });
}

/// A render pass of two subpasses: offsets at the end of the first (`vkCmdNextSubpass2`) are
/// ignored, as the specification says, and never reach the driver; those at the end of the last
/// apply to the whole pass, both subpasses' draws.
#[test]
fn only_the_last_subpass_end_carries_offsets() {
    on_nvidia(EXT, |env, scene, t| {
        let (ignored, last) = (at(3 * t, 3 * t), at(-t, 2 * t));
        let d = &scene.dev.d;
        // SAFETY: every struct lives across its call; the objects are destroyed below.
        let (pass, framebuffer, pipelines) = unsafe {
            let pass = render_pass(
                d,
                0,
                2,
                &[color_dependency(0, 1).dependency_flags(vk::DependencyFlags::BY_REGION)],
            );
            let framebuffer = framebuffer(d, pass, &[scene.color().1, scene.map().1]);
            let pipelines = pipelines(d, |stages, fixed| {
                let infos = [0, 1].map(|subpass| {
                    fixed
                        .info(stages, scene.layout)
                        .render_pass(pass)
                        .subpass(subpass)
                });
                d.create_graphics_pipelines(vk::PipelineCache::null(), &infos, None)
            });
            (pass, framebuffer, pipelines)
        };
        let cb = scene.dev.begin();
        scene.prepare(cb);
        let first = [ignored];
        let second = [last];
        let mut first_end = vk::SubpassFragmentDensityMapOffsetEndInfoQCOM::default()
            .fragment_density_offsets(&first);
        let mut last_end = vk::SubpassFragmentDensityMapOffsetEndInfoQCOM::default()
            .fragment_density_offsets(&second);
        // SAFETY: `cb` is recording on this device; every struct lives across its call.
        unsafe {
            begin_pass(d, cb, pass, framebuffer);
            draw_fullscreen(d, cb, pipelines[0]);
            d.cmd_next_subpass2(
                cb,
                &vk::SubpassBeginInfo::default().contents(vk::SubpassContents::INLINE),
                &vk::SubpassEndInfo::default().push_next(&mut first_end),
            );
            draw_fullscreen(d, cb, pipelines[1]);
            d.cmd_end_render_pass2(cb, &vk::SubpassEndInfo::default().push_next(&mut last_end));
        }
        scene.dev.submit(cb);
        let want = &scene.want(&[last])[0];
        for draw in 0..2 {
            let got = env
                .double
                .effective_rates(cb.as_raw(), 0, draw)
                .unwrap_or_else(|| panic!("no draw {draw}"));
            assert!(
                &got[0].codes == want,
                "draw {draw} (subpass {draw}): shaded {:?}, want {want:?}",
                got[0].codes
            );
        }
        // SAFETY: the queue is idle; each object is destroyed once.
        unsafe {
            for p in pipelines {
                d.destroy_pipeline(p, None);
            }
            d.destroy_framebuffer(framebuffer, None);
            d.destroy_render_pass(pass, None);
        }
    });
}

/// A render pass begun and ended in a primary whose draws a secondary records
/// (`RENDER_PASS_CONTINUE`), as engines record them: the primary's end carries the offsets, and the
/// secondary's draw shades with them.
#[test]
fn draws_of_a_secondary_inside_the_pass_take_the_primarys_offsets() {
    on_nvidia(EXT, |env, scene, t| {
        let o = [at(-2 * t, -t)];
        let d = &scene.dev.d;
        let secondary = scene.secondary(
            vk::CommandBufferUsageFlags::RENDER_PASS_CONTINUE,
            &vk::CommandBufferInheritanceInfo::default()
                .render_pass(scene.pass)
                .subpass(0)
                .framebuffer(scene.framebuffer),
        );
        // SAFETY: the secondary is recording inside the pass it inherits.
        unsafe {
            draw_fullscreen(d, secondary, scene.pass_pipeline);
            d.end_command_buffer(secondary).expect("end");
        }
        let primary = scene.dev.begin();
        scene.prepare(primary);
        let mut end =
            vk::SubpassFragmentDensityMapOffsetEndInfoQCOM::default().fragment_density_offsets(&o);
        // SAFETY: both are this device's; every struct lives across its call.
        unsafe {
            d.cmd_begin_render_pass2(
                primary,
                &vk::RenderPassBeginInfo::default()
                    .render_pass(scene.pass)
                    .framebuffer(scene.framebuffer)
                    .render_area(AREA)
                    .clear_values(&CLEAR),
                &vk::SubpassBeginInfo::default()
                    .contents(vk::SubpassContents::SECONDARY_COMMAND_BUFFERS),
            );
            d.cmd_execute_commands(primary, &[secondary]);
            d.cmd_end_render_pass2(primary, &vk::SubpassEndInfo::default().push_next(&mut end));
        }
        scene.dev.submit(primary);
        scene.assert_one_draw(env, primary, secondary, &o, "secondary inside the pass");
    });
}

/// Two threads record at once, each from a pool of its own, passes on the same map ended with
/// different offsets, one command buffer with `SIMULTANEOUS_USE`; one submit runs that one twice,
/// the other between: every execution shades with its own recording's offsets (the layer keeps
/// them per command buffer, nothing shared is written while recording or running).
#[test]
fn threads_and_simultaneous_use_keep_their_own_offsets() {
    on_nvidia(EXT, |env, scene, t| {
        let (oa, ob) = ([at(t, t)], [at(-2 * t, 0)]);
        let record = |offsets: &[vk::Offset2D], flags: vk::CommandBufferUsageFlags, path: Path| {
            let pool = scene.dev.command_pool();
            let cb = scene.dev.begin_in(pool, flags);
            scene.prepare(cb);
            scene.pass(cb, path, vk::RenderingFlags::empty(), End::With(offsets));
            scene.between(cb);
            // SAFETY: `cb` is recording on this device, from this thread's own pool.
            unsafe { scene.dev.d.end_command_buffer(cb) }.expect("vkEndCommandBuffer");
            (pool, cb)
        };
        for path in [Path::RenderPass, Path::Rendering] {
            let simultaneous = vk::CommandBufferUsageFlags::SIMULTANEOUS_USE;
            let ((pool_a, a), (pool_b, b)) = std::thread::scope(|s| {
                let ta = s.spawn(|| record(&oa, simultaneous, path));
                let tb = s.spawn(|| record(&ob, vk::CommandBufferUsageFlags::empty(), path));
                (ta.join().expect("thread a"), tb.join().expect("thread b"))
            });
            let d = &scene.dev.d;
            // Handles of the first path's command buffers may come back: only this submit's draws.
            let before = env.double.draws().len();
            // `a` may be pending twice: it was recorded with simultaneous use.
            scene.submit(&[a, b, a]);
            for (cb, offsets, runs) in [(a, &oa, 2), (b, &ob, 1)] {
                let draws: Vec<_> = env
                    .double
                    .draws()
                    .into_iter()
                    .skip(before)
                    .filter(|dr| dr.command_buffer == cb.as_raw())
                    .collect();
                assert_eq!(draws.len(), runs, "{path:?}: {draws:?}");
                let want = &scene.want(offsets)[0];
                for dr in &draws {
                    assert!(
                        &dr.views[0].codes == want,
                        "{path:?} {offsets:?}: shaded {:?}, want {want:?}",
                        dr.views[0].codes
                    );
                }
            }
            // SAFETY: the queue is idle; the pools' command buffers go with them.
            unsafe {
                d.destroy_command_pool(pool_a, None);
                d.destroy_command_pool(pool_b, None);
            }
        }
    });
}

/// An engine's recording in front of its eye pass: a pipeline layout per shader, a graphics push
/// per draw (more layouts and ranges than the layer's record of what a conversion must give back
/// holds) and compute shaders with layouts of their own pushing one range. The eye pass still gets
/// its map converted and its offsets applied, on both paths: a conversion gives back only what its
/// compute dispatch disturbs (src/vk/own/bindings.rs, `Bound::push`), where the record used to
/// fill up at the ninth push and leave every map of the recording at full rate.
#[test]
fn engines_per_draw_push_constants_keep_maps_converted_and_offsets_applied() {
    on_nvidia(EXT, |env, scene, t| {
        let d = &scene.dev.d;
        let graphics = vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT;
        let compute = vk::ShaderStageFlags::COMPUTE;
        let layout = |stages, size| {
            let ranges = [vk::PushConstantRange {
                stage_flags: stages,
                offset: 0,
                size,
            }];
            let info = vk::PipelineLayoutCreateInfo::default().push_constant_ranges(&ranges);
            // SAFETY: the device is alive; the struct lives across the call.
            unsafe { d.create_pipeline_layout(&info, None) }.expect("vkCreatePipelineLayout")
        };
        let shaders: Vec<vk::PipelineLayout> = (0..12).map(|_| layout(graphics, 16)).collect();
        let kernels: Vec<vk::PipelineLayout> = (0..12).map(|_| layout(compute, 8)).collect();
        for path in [Path::RenderPass, Path::Rendering] {
            let cb = scene.dev.begin();
            scene.prepare(cb);
            // SAFETY: `cb` is recording; the layouts are alive and name these ranges.
            unsafe {
                for draw in 0..48u8 {
                    let l = shaders[usize::from(draw) % shaders.len()];
                    d.cmd_push_constants(cb, l, graphics, 0, &[draw; 16]);
                }
                for (i, &l) in kernels.iter().enumerate() {
                    d.cmd_push_constants(cb, l, compute, 0, &[i as u8; 8]);
                }
            }
            let offsets = [at(t, -2 * t)];
            scene.pass(cb, path, vk::RenderingFlags::empty(), End::With(&offsets));
            scene.dev.submit(cb);
            let what = format!("{path:?} after 12 graphics and 12 compute layouts' pushes");
            scene.assert_shifted(env, cb, &[&offsets], &what);
        }
        for l in shaders.into_iter().chain(kernels) {
            // SAFETY: the queue is idle; each layout is destroyed once.
            unsafe { d.destroy_pipeline_layout(l, None) };
        }
    });
}
