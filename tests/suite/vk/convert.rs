//! Density maps the application writes itself: fovea's Vulkan layer converts them into their
//! shading-rate shadows on the GPU at every pass begin that reads them, and gives the application
//! its compute bindings back afterwards (src/vk/convert.rs).
//!
//! Stack as in [`crate::support::device`] (this test → fovea → validation → the double → lavapipe, which
//! runs the conversion's compute shader for real). The application uploads a known pattern with
//! `vkCmdCopyBufferToImage`, binds its own compute pipeline, descriptor set and push constants,
//! renders a pass with the map (render pass or dynamic rendering), and after the pass dispatches
//! with those bindings. Checked: the codes the double reads back from the shadow at the submit are
//! `fovea_model::shading_rate::fill_codes` of the application's bytes (layered on `nvidia`, one
//! merged layer on `amd`), a second frame with another pattern included (with dynamic rendering,
//! one instance suspended and resumed, converted once); the dispatch after the pass wrote the
//! application's push constant
//! through the application's buffer; validation says nothing (leaks at `vkDestroyDevice`
//! included) but its 1.3.239 stage false positives.

use ash::vk;
use fovea_vkdouble::Profile;
use serde_json::{json, Value};

use crate::support::device::{
    assert_only_stage_false_positives, env, with_fovea, ComputePipeline, Dev, Env, Features, Vk,
};
use crate::support::vulkan::{
    allocate_info, cleared_color, density_pass, range, to_color_attachment, AREA, CLEAR, COLOR,
    DENSITY, FDM_LAYOUT, SIZE,
};

/// The application's compute shader: `value[index] = word` (push constants `{word, index}`).
const STORE: &[u8] = include_bytes!("../shaders/store.comp.spv");
/// The word the application pushes before the pass.
const WORD: u32 = 0xC0FF_EE01;

/// Density bytes that sit on and beside every boundary of the mapping (0 undefined, 63/64, 127/128).
const BYTES: [u8; 10] = [0, 1, 32, 63, 64, 100, 127, 128, 200, 255];

/// The application's R8G8 bytes for `layers` layers of `texels` texels each.
fn pattern(texels: usize, layers: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(texels * layers * 2);
    for l in 0..layers {
        for t in 0..texels {
            out.push(BYTES[(t + l) % BYTES.len()]);
            out.push(BYTES[(t * 3 + l * 5 + 1) % BYTES.len()]);
        }
    }
    out
}

/// The codes the model gives `bytes` on `profile`.
pub(crate) fn model_codes(profile: Profile, bytes: &[u8], texels: usize, layers: usize) -> Vec<u8> {
    let merged = !profile.layered() && layers > 1;
    let rates: Vec<[u32; 2]> = profile
        .rates()
        .iter()
        .map(|(e, _)| [e.width, e.height])
        .collect();
    let m = profile.max_fragment();
    let mut out = vec![0u8; if merged { texels } else { texels * layers }];
    fovea_model::shading_rate::fill_codes(bytes, texels, merged, [m, m], &rates, &mut out);
    out
}

pub(crate) struct Buffer {
    pub(crate) buffer: vk::Buffer,
    pub(crate) memory: vk::DeviceMemory,
}

/// The application's compute work: a pipeline that stores its push constant through its set.
struct Compute {
    pipe: ComputePipeline,
    out: Buffer,
}

/// The device these tests convert on ([`Features::FDM_MULTIVIEW`]), with
/// `VK_EXT_conditional_rendering` and its feature where `conditional`.
pub(crate) fn converting_device(vk: &Vk, conditional: bool) -> Dev {
    let mut cond =
        vk::PhysicalDeviceConditionalRenderingFeaturesEXT::default().conditional_rendering(true);
    let exts = [ash::ext::conditional_rendering::NAME];
    let d = if conditional {
        vk.device_with(&exts, Features::FDM_MULTIVIEW, Some(&mut cond))
    } else {
        vk.device_with(&[], Features::FDM_MULTIVIEW, None)
    };
    Dev::new(vk, d)
}

/// What the tests here do with the shared test device ([`Dev`]).
impl Dev {
    pub(crate) fn buffer(&self, size: u64, usage: vk::BufferUsageFlags) -> Buffer {
        // SAFETY: the device is alive; structs live across the calls.
        unsafe {
            let buffer = self
                .d
                .create_buffer(
                    &vk::BufferCreateInfo::default().size(size).usage(usage),
                    None,
                )
                .expect("vkCreateBuffer");
            let req = self.d.get_buffer_memory_requirements(buffer);
            let memory = self
                .d
                .allocate_memory(
                    &allocate_info(
                        &self.memory,
                        req,
                        vk::MemoryPropertyFlags::HOST_VISIBLE
                            | vk::MemoryPropertyFlags::HOST_COHERENT,
                    ),
                    None,
                )
                .expect("vkAllocateMemory");
            self.d.bind_buffer_memory(buffer, memory, 0).expect("bind");
            Buffer { buffer, memory }
        }
    }

    pub(crate) fn write(&self, b: &Buffer, bytes: &[u8]) {
        // SAFETY: host-visible, coherent memory of at least `bytes.len()` bytes, idle.
        unsafe {
            let p = self
                .d
                .map_memory(b.memory, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())
                .expect("map");
            std::ptr::copy_nonoverlapping(bytes.as_ptr(), p as *mut u8, bytes.len());
            self.d.unmap_memory(b.memory);
        }
    }

    pub(crate) fn read_words(&self, b: &Buffer, n: usize) -> Vec<u32> {
        // SAFETY: as in write.
        unsafe {
            let p = self
                .d
                .map_memory(b.memory, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())
                .expect("map");
            let out = std::slice::from_raw_parts(p as *const u32, n).to_vec();
            self.d.unmap_memory(b.memory);
            out
        }
    }

    pub(crate) fn free(&self, b: Buffer) {
        // SAFETY: idle, destroyed once.
        unsafe {
            self.d.destroy_buffer(b.buffer, None);
            self.d.free_memory(b.memory, None);
        }
    }

    fn compute(&self) -> Compute {
        // SAFETY: structs live across the calls.
        unsafe {
            let d = &self.d;
            // More push constants than the shader reads, room for the ranges of
            // `bind_compute(.., true)`.
            let pipe = self.compute_pipeline(STORE, vk::DescriptorType::STORAGE_BUFFER, 64);
            let set = pipe.set;
            let out = self.buffer(64, vk::BufferUsageFlags::STORAGE_BUFFER);
            self.write(&out, &[0; 64]);
            let info = [vk::DescriptorBufferInfo {
                buffer: out.buffer,
                offset: 0,
                range: vk::WHOLE_SIZE,
            }];
            d.update_descriptor_sets(
                &[vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(0)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .buffer_info(&info)],
                &[],
            );
            Compute { pipe, out }
        }
    }

    fn destroy_compute(&self, c: Compute) {
        c.pipe.destroy(&self.d);
        self.free(c.out);
    }

    /// Records the application's upload of `staging` into every layer of `image`, ending in the
    /// density-map layout.
    pub(crate) fn upload(
        &self,
        cb: vk::CommandBuffer,
        staging: &Buffer,
        image: vk::Image,
        side: u32,
        layers: u32,
    ) {
        let barrier = |old, new, src, dst| {
            vk::ImageMemoryBarrier::default()
                .image(image)
                .subresource_range(range(0, layers))
                .old_layout(old)
                .new_layout(new)
                .src_access_mask(src)
                .dst_access_mask(dst)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        };
        // SAFETY: `cb` is recording; the objects are alive.
        unsafe {
            let d = &self.d;
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TOP_OF_PIPE,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[barrier(
                    vk::ImageLayout::UNDEFINED,
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                    vk::AccessFlags::empty(),
                    vk::AccessFlags::TRANSFER_WRITE,
                )],
            );
            d.cmd_copy_buffer_to_image(
                cb,
                staging.buffer,
                image,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &[vk::BufferImageCopy {
                    buffer_offset: 0,
                    buffer_row_length: 0,
                    buffer_image_height: 0,
                    image_subresource: vk::ImageSubresourceLayers {
                        aspect_mask: vk::ImageAspectFlags::COLOR,
                        mip_level: 0,
                        base_array_layer: 0,
                        layer_count: layers,
                    },
                    image_offset: vk::Offset3D::default(),
                    image_extent: vk::Extent3D {
                        width: side,
                        height: side,
                        depth: 1,
                    },
                }],
            );
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[barrier(
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                    FDM_LAYOUT,
                    vk::AccessFlags::TRANSFER_WRITE,
                    vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT,
                )],
            );
        }
    }

    /// Binds the application's compute state: pipeline, set 0 and push constants `{WORD, index}`;
    /// with `many`, eight more push-constant ranges after them: more than the layer records, so it
    /// cannot give them back and must leave the pass's map unconverted.
    fn bind_compute(&self, cb: vk::CommandBuffer, c: &Compute, index: u32, many: bool) {
        let mut bytes = [0u8; 8];
        bytes[..4].copy_from_slice(&WORD.to_ne_bytes());
        bytes[4..].copy_from_slice(&index.to_ne_bytes());
        // SAFETY: `cb` is recording; the objects are alive.
        unsafe {
            self.d
                .cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, c.pipe.pipeline);
            self.d.cmd_bind_descriptor_sets(
                cb,
                vk::PipelineBindPoint::COMPUTE,
                c.pipe.layout,
                0,
                &[c.pipe.set],
                &[],
            );
            self.d
                .cmd_push_constants(cb, c.pipe.layout, vk::ShaderStageFlags::COMPUTE, 0, &bytes);
            for i in 0..8u32 * u32::from(many) {
                self.d.cmd_push_constants(
                    cb,
                    c.pipe.layout,
                    vk::ShaderStageFlags::COMPUTE,
                    8 + 4 * i,
                    &i.to_ne_bytes(),
                );
            }
        }
    }

    /// A dispatch with whatever is bound, then its writes made visible to the host.
    fn dispatch(&self, cb: vk::CommandBuffer) {
        // SAFETY: `cb` is recording outside a pass.
        unsafe {
            self.d.cmd_dispatch(cb, 1, 1, 1);
            self.d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &[vk::MemoryBarrier::default()
                    .src_access_mask(vk::AccessFlags::SHADER_WRITE)
                    .dst_access_mask(vk::AccessFlags::HOST_READ)],
                &[],
                &[],
            );
        }
    }
}

/// How many barrier commands the double has recorded for a command buffer with `cb`'s handle.
fn barriers_of(env: &Env, cb: vk::CommandBuffer) -> usize {
    use ash::vk::Handle as _;
    env.double
        .events("barrier")
        .iter()
        .filter(|b| b["command_buffer"] == json!(cb.as_raw()))
        .count()
}

/// The shading-rate images the double read back at the latest submit of `cb`. The latest: the
/// records outlive devices, and a command buffer of an earlier device can have had the same
/// handle (the driver reuses the memory).
pub(crate) fn read_at_submit(env: &Env, cb: vk::CommandBuffer) -> Vec<Value> {
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
    let last = submits.last().expect("the command buffer was submitted");
    last["shading_rate_images"]
        .as_array()
        .cloned()
        .unwrap_or_default()
}

pub(crate) fn codes_of(read: &[Value], what: &str) -> Vec<u8> {
    assert_eq!(read.len(), 1, "{what}: {read:?}");
    read[0]["codes"]
        .as_array()
        .unwrap_or_else(|| panic!("{what}: no codes in {read:?}"))
        .iter()
        .map(|c| c.as_u64().expect("a code") as u8)
        .collect()
}

/// How the pass names the density map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Begin {
    /// `vkCmdBeginRenderPass2` with a framebuffer (one view).
    Framebuffer,
    /// `vkCmdBeginRenderPass2` with an imageless framebuffer: the views come with the begin.
    Imageless,
    /// `vkCmdBeginRendering` with `VkRenderingFragmentDensityMapAttachmentInfoEXT` and a view
    /// mask over every layer.
    Rendering,
}

/// Two application frames: upload `layers` layers of a pattern, bind compute state, render a pass
/// with the map, dispatch after it. Asserts the shadow's codes at the submit (the model's; with
/// `lose`, where the app's bindings cannot be given back, full rate), and that the dispatch after
/// the pass used the application's bindings.
fn frame(env: &Env, vk: &Vk, profile: Profile, pass: Begin, layers: u32, lose: bool) {
    let what = format!("{profile:?} {pass:?} {layers} layer(s), unrestorable {lose}");
    let dev = converting_device(vk, false);
    let texel = profile.texel();
    let side = SIZE / texel.width;
    let texels = (side * side) as usize;
    let bytes = pattern(texels, layers as usize);
    let staging = dev.buffer(bytes.len() as u64, vk::BufferUsageFlags::TRANSFER_SRC);
    dev.write(&staging, &bytes);
    let (map, map_memory, map_view) = dev.image(
        DENSITY,
        side,
        layers,
        vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT | vk::ImageUsageFlags::TRANSFER_DST,
    );
    let (color, color_memory, color_view) =
        dev.image(COLOR, SIZE, 1, vk::ImageUsageFlags::COLOR_ATTACHMENT);
    let compute = dev.compute();

    // Two frames: the second with a different pattern, so a conversion that ran only once (or
    // that read a stale map) would show.
    let mut barrier_counts = Vec::new();
    for round in 0..2u32 {
        let bytes: Vec<u8> = if round == 0 {
            bytes.clone()
        } else {
            bytes.iter().rev().copied().collect()
        };
        dev.write(&staging, &bytes);
        let cb = dev.begin();
        // An earlier device's command buffer may have had this handle: only barriers from here on
        // are this recording's.
        let barriers_before = barriers_of(env, cb);
        dev.upload(cb, &staging, map, side, layers);
        dev.bind_compute(cb, &compute, round, lose);
        let mut made = None;
        // SAFETY: `cb` is recording; every struct lives across its call.
        unsafe {
            let d = &dev.d;
            to_color_attachment(d, cb, &[color], 1);
            match pass {
                Begin::Framebuffer | Begin::Imageless => {
                    let rp = density_pass(d, vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL, FDM_LAYOUT)
                        .expect("vkCreateRenderPass2");
                    let views = [color_view, map_view];
                    let color_formats = [COLOR];
                    let density_formats = [DENSITY];
                    let infos = [
                        vk::FramebufferAttachmentImageInfo::default()
                            .usage(vk::ImageUsageFlags::COLOR_ATTACHMENT)
                            .width(SIZE)
                            .height(SIZE)
                            .layer_count(1)
                            .view_formats(&color_formats),
                        vk::FramebufferAttachmentImageInfo::default()
                            .usage(
                                vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT
                                    | vk::ImageUsageFlags::TRANSFER_DST,
                            )
                            .width(side)
                            .height(side)
                            .layer_count(1)
                            .view_formats(&density_formats),
                    ];
                    let mut attachments = vk::FramebufferAttachmentsCreateInfo::default()
                        .attachment_image_infos(&infos);
                    let mut fb_info = vk::FramebufferCreateInfo::default()
                        .render_pass(rp)
                        .width(SIZE)
                        .height(SIZE)
                        .layers(1);
                    if pass == Begin::Imageless {
                        fb_info = fb_info
                            .flags(vk::FramebufferCreateFlags::IMAGELESS)
                            .push_next(&mut attachments);
                        fb_info.attachment_count = 2;
                    } else {
                        fb_info = fb_info.attachments(&views);
                    }
                    let fb = d
                        .create_framebuffer(&fb_info, None)
                        .expect("vkCreateFramebuffer");
                    let mut begin_views =
                        vk::RenderPassAttachmentBeginInfo::default().attachments(&views);
                    let mut begin = vk::RenderPassBeginInfo::default()
                        .render_pass(rp)
                        .framebuffer(fb)
                        .render_area(AREA)
                        .clear_values(&CLEAR);
                    if pass == Begin::Imageless {
                        begin = begin.push_next(&mut begin_views);
                    }
                    d.cmd_begin_render_pass2(
                        cb,
                        &begin,
                        &vk::SubpassBeginInfo::default().contents(vk::SubpassContents::INLINE),
                    );
                    d.cmd_end_render_pass2(cb, &vk::SubpassEndInfo::default());
                    made = Some((rp, fb));
                }
                Begin::Rendering => {
                    let color_att = [cleared_color(color_view)];
                    let mut density_att =
                        vk::RenderingFragmentDensityMapAttachmentInfoEXT::default()
                            .image_view(map_view)
                            .image_layout(FDM_LAYOUT);
                    let mut info = vk::RenderingInfo::default()
                        .render_area(AREA)
                        .layer_count(1)
                        .push_next(&mut density_att);
                    if layers > 1 {
                        info = info.view_mask((1 << layers) - 1);
                    } else {
                        info = info.color_attachments(&color_att);
                    }
                    if round == 0 {
                        d.cmd_begin_rendering(cb, &info);
                        d.cmd_end_rendering(cb);
                    } else {
                        // One render pass instance, suspended and resumed: converted once, in
                        // front of it; a conversion before the resumption would be invalid.
                        let flags = info.flags;
                        info = info.flags(flags | vk::RenderingFlags::SUSPENDING);
                        d.cmd_begin_rendering(cb, &info);
                        d.cmd_end_rendering(cb);
                        info = info.flags(flags | vk::RenderingFlags::RESUMING);
                        d.cmd_begin_rendering(cb, &info);
                        d.cmd_end_rendering(cb);
                    }
                }
            }
        }
        dev.dispatch(cb);
        dev.submit(cb);
        let got = codes_of(&read_at_submit(env, cb), &what);
        // Both rounds record the same commands but for the suspended and resumed instance of
        // round 1: one conversion each, so as many barriers reach the driver.
        let barriers = barriers_of(env, cb) - barriers_before;
        match barrier_counts.first() {
            Some(&first) => assert_eq!(
                barriers, first,
                "{what}, round {round}: not one conversion per render pass instance"
            ),
            None => barrier_counts.push(barriers),
        }
        let model = model_codes(profile, &bytes, texels, layers as usize);
        assert!(
            model.iter().any(|&c| c != 0),
            "{what}: a pattern that tests nothing"
        );
        let want = if lose { vec![0; model.len()] } else { model };
        assert!(
            got == want,
            "{what}, round {round}: shadow codes {got:?}, want {want:?}"
        );
        let words = dev.read_words(&compute.out, 2);
        assert_eq!(
            words[round as usize], WORD,
            "{what}, round {round}: the dispatch after the pass did not use the application's \
             pipeline, set and push constants: {words:x?}"
        );
        if let Some((rp, fb)) = made {
            // SAFETY: the queue is idle.
            unsafe {
                dev.d.destroy_framebuffer(fb, None);
                dev.d.destroy_render_pass(rp, None);
            }
        }
    }
    dev.destroy_compute(compute);
    dev.free(staging);
    // SAFETY: the queue is idle; each object is destroyed once.
    unsafe {
        dev.d.destroy_image_view(map_view, None);
        dev.d.destroy_image(map, None);
        dev.d.free_memory(map_memory, None);
        dev.d.destroy_image_view(color_view, None);
        dev.d.destroy_image(color, None);
        dev.d.free_memory(color_memory, None);
    }
    dev.destroy();
    assert_eq!(env.double.errors(), Vec::<String>::new(), "{what}");
}

/// A one-layer map in a render pass, with a framebuffer and with an imageless one (`nvidia`, 4×4
/// fragments): the shadow holds the model's codes
/// of the application's bytes, frame after frame, and the application's compute bindings survive.
#[test]
fn app_written_maps_are_converted_for_render_passes() {
    let Some((_serial, env, vk)) = with_fovea(Profile::Nvidia) else {
        return;
    };
    frame(env, &vk, Profile::Nvidia, Begin::Framebuffer, 1, false);
    frame(env, &vk, Profile::Nvidia, Begin::Imageless, 1, false);
    drop(vk);
    assert_only_stage_false_positives();
}

/// Dynamic rendering, one layer and a two-layer multiview map: one shadow layer per view on
/// `nvidia` (layered), one merged layer with the finer rate of both on `amd`.
#[test]
fn app_written_maps_are_converted_for_dynamic_rendering_layered_and_merged() {
    let Some((_serial, env)) = env() else { return };
    for profile in [Profile::Nvidia, Profile::Amd] {
        let Some(vk) = Vk::new(env, profile, true) else {
            return;
        };
        for layers in [1, 2] {
            frame(env, &vk, profile, Begin::Rendering, layers, false);
        }
        drop(vk);
        assert_only_stage_false_positives();
    }
}

/// Fail open: a command buffer with more push-constant ranges than the layer's record holds cannot
/// get its bindings back after a conversion, so its pass's map is not converted (the shadow keeps
/// its full-rate clear) and the application's dispatch after the pass still finds its own state.
#[test]
fn unrestorable_bindings_leave_the_map_at_full_rate() {
    let Some((_serial, env, vk)) = with_fovea(Profile::Nvidia) else {
        return;
    };
    frame(env, &vk, Profile::Nvidia, Begin::Framebuffer, 1, true);
    frame(env, &vk, Profile::Nvidia, Begin::Rendering, 1, true);
    drop(vk);
    assert_only_stage_false_positives();
}
