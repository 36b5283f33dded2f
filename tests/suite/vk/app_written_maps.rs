//! An application that writes its own density maps the two ways the Khronos fragment-density-map
//! sample does, frame after frame: one frame's map is the colour attachment of a render pass (one
//! without the density-map struct) that ends in `FRAGMENT_DENSITY_MAP_OPTIMAL_EXT`, the next
//! frame's is written by a compute dispatch with `imageStore` and handed over with a barrier, and
//! so on, the contents changing every frame. Each frame then renders a pass that reads the map.
//!
//! Stack as in [`crate::support::device`] (this test → fovea → validation → the double → lavapipe).
//! Checked per frame: what the GPU would shade with ([`rates_of`]) is the model's
//! (`fovea_model::shading_rate`) for the bytes the application wrote; validation says nothing
//! but its 1.3.239 stage false positives (so the driver got no density-map enum, and every layout
//! the application names is the image's). Also: a pass that moves its map from another layout
//! into the density layout leaves the application's image in the layout its later barriers name;
//! a pass recorded inside the application's conditional rendering shades with its map whether
//! the condition holds or not.

use ash::vk;
use fovea_vkdouble::Profile;

use crate::support::device::{assert_only_stage_false_positives, env, Env, Vk};
use crate::support::device::{ComputePipeline, Dev};
use crate::support::vulkan::{
    cleared_color, density_pass, framebuffer, range, AREA, CLEAR, COLOR, DENSITY, FDM_LAYOUT, SIZE,
};
use crate::vk::convert::{codes_of, converting_device, model_codes, read_at_submit, Buffer};

/// `shaders/write_map.comp`: the application's compute path.
const WRITE_MAP: &[u8] = include_bytes!("../shaders/write_map.comp.spv");

/// The density bytes both paths write: away from the mapping's boundaries (63/64, 127/128), so
/// that a unorm rounding of one either way changes nothing.
const LEVELS: [u8; 5] = [0, 30, 100, 160, 255];

/// What `write_map.comp` writes for `frame` into a `side`×`side` map (R8G8, row by row).
fn compute_bytes(side: u32, frame: u32) -> Vec<u8> {
    let mut out = Vec::new();
    for y in 0..side {
        for x in 0..side {
            out.push(LEVELS[((x * 3 + y + frame) % 5) as usize]);
            out.push(LEVELS[((x + y * 2 + frame * 3) % 5) as usize]);
        }
    }
    out
}

/// The colour quadrant `q` of the map-writing pass is cleared to in `frame`.
fn quadrant_bytes(q: u32, frame: u32) -> [u8; 2] {
    [
        LEVELS[((q + frame) % 5) as usize],
        LEVELS[((q * 2 + frame * 3 + 1) % 5) as usize],
    ]
}

/// The quadrant of texel (`x`, `y`) of a `side`×`side` map.
fn quadrant(x: u32, y: u32, side: u32) -> u32 {
    u32::from(x >= side / 2) + 2 * u32::from(y >= side / 2)
}

/// What the map-writing pass leaves in the map for `frame`.
fn pass_bytes(side: u32, frame: u32) -> Vec<u8> {
    let mut out = Vec::new();
    for y in 0..side {
        for x in 0..side {
            out.extend(quadrant_bytes(quadrant(x, y, side), frame));
        }
    }
    out
}

/// What the GPU would shade the pass recorded in `cb` with, per map texel: for now the shading-rate
/// codes the double reads back from the shading-rate attachment at the submit (every pipeline of a
/// rewritten pass lets the attachment decide, `vk::pipelines`). Where the double reports effective
/// rates per draw, this is the one function to change.
fn rates_of(env: &Env, cb: vk::CommandBuffer, what: &str) -> Vec<u8> {
    codes_of(&read_at_submit(env, cb), what)
}

/// The model's rates for one layer of `bytes` on `profile`, in [`rates_of`]'s terms.
fn model_rates(profile: Profile, bytes: &[u8]) -> Vec<u8> {
    model_codes(profile, bytes, bytes.len() / 2, 1)
}

/// The objects of the application: its map, a colour target, the pass that writes the map, the
/// pass that reads it, and the compute pipeline that writes it.
struct App {
    side: u32,
    map: (vk::Image, vk::DeviceMemory, vk::ImageView),
    color: (vk::Image, vk::DeviceMemory, vk::ImageView),
    writer: vk::RenderPass,
    writer_fb: vk::Framebuffer,
    reader: vk::RenderPass,
    reader_fb: vk::Framebuffer,
    compute: ComputePipeline,
}

/// The pass that reads the map: colour + density attachment (the density-map struct), the map
/// moved from `initial` into the density layout.
///
/// # Safety
/// The device must be alive.
unsafe fn reader_pass(dev: &Dev, initial: vk::ImageLayout) -> vk::RenderPass {
    // SAFETY: as the caller promised.
    unsafe { density_pass(&dev.d, vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL, initial) }
        .expect("vkCreateRenderPass2")
}

impl App {
    /// # Safety
    /// The device must be alive.
    unsafe fn new(dev: &Dev, profile: Profile, map_usage: vk::ImageUsageFlags) -> App {
        let side = SIZE / profile.texel().width;
        let map = dev.image(
            DENSITY,
            side,
            1,
            vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT | map_usage,
        );
        let color = dev.image(COLOR, SIZE, 1, vk::ImageUsageFlags::COLOR_ATTACHMENT);
        let d = &dev.d;
        // SAFETY: as the caller promised; every struct lives across its call.
        unsafe {
            // The Khronos sample's fragment path, as a version-1 pass without the density-map
            // struct: the map is its colour attachment, ending in the density layout, with a
            // dependency that hands it to the density-map stage.
            let atts = [vk::AttachmentDescription::default()
                .format(DENSITY)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(vk::AttachmentLoadOp::DONT_CARE)
                .store_op(vk::AttachmentStoreOp::STORE)
                .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
                .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
                .initial_layout(vk::ImageLayout::UNDEFINED)
                .final_layout(FDM_LAYOUT)];
            let color_ref = [vk::AttachmentReference {
                attachment: 0,
                layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
            }];
            let subpass = [vk::SubpassDescription::default()
                .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
                .color_attachments(&color_ref)];
            let deps = [vk::SubpassDependency {
                src_subpass: 0,
                dst_subpass: vk::SUBPASS_EXTERNAL,
                src_stage_mask: vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                dst_stage_mask: vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
                src_access_mask: vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
                dst_access_mask: vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT,
                dependency_flags: vk::DependencyFlags::empty(),
            }];
            let writer = d
                .create_render_pass(
                    &vk::RenderPassCreateInfo::default()
                        .attachments(&atts)
                        .subpasses(&subpass)
                        .dependencies(&deps),
                    None,
                )
                .expect("vkCreateRenderPass (the map's writer)");
            let views = [map.2];
            let writer_fb = d
                .create_framebuffer(
                    &vk::FramebufferCreateInfo::default()
                        .render_pass(writer)
                        .attachments(&views)
                        .width(side)
                        .height(side)
                        .layers(1),
                    None,
                )
                .expect("vkCreateFramebuffer (the map's writer)");
            let reader = reader_pass(dev, FDM_LAYOUT);
            let views = [color.2, map.2];
            let reader_fb = d
                .create_framebuffer(
                    &vk::FramebufferCreateInfo::default()
                        .render_pass(reader)
                        .attachments(&views)
                        .width(SIZE)
                        .height(SIZE)
                        .layers(1),
                    None,
                )
                .expect("vkCreateFramebuffer (the map's reader)");
            let compute = dev.compute_pipeline(WRITE_MAP, vk::DescriptorType::STORAGE_IMAGE, 4);
            let set = compute.set;
            let image_info = [vk::DescriptorImageInfo {
                sampler: vk::Sampler::null(),
                image_view: map.2,
                image_layout: vk::ImageLayout::GENERAL,
            }];
            d.update_descriptor_sets(
                &[vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(0)
                    .descriptor_type(vk::DescriptorType::STORAGE_IMAGE)
                    .image_info(&image_info)],
                &[],
            );
            App {
                side,
                map,
                color,
                writer,
                writer_fb,
                reader,
                reader_fb,
                compute,
            }
        }
    }

    /// The fragment path: the map-writing pass clears each quadrant of the map to its bytes.
    ///
    /// # Safety
    /// `cb` must be recording outside a pass.
    unsafe fn write_by_pass(&self, dev: &Dev, cb: vk::CommandBuffer, frame: u32) {
        let d = &dev.d;
        let half = self.side / 2;
        // SAFETY: as the caller promised; structs live across the calls.
        unsafe {
            d.cmd_begin_render_pass(
                cb,
                &vk::RenderPassBeginInfo::default()
                    .render_pass(self.writer)
                    .framebuffer(self.writer_fb)
                    .render_area(vk::Rect2D {
                        offset: vk::Offset2D::default(),
                        extent: vk::Extent2D {
                            width: self.side,
                            height: self.side,
                        },
                    }),
                vk::SubpassContents::INLINE,
            );
            for q in 0..4u32 {
                let [r, g] = quadrant_bytes(q, frame);
                let clear = vk::ClearAttachment {
                    aspect_mask: vk::ImageAspectFlags::COLOR,
                    color_attachment: 0,
                    clear_value: vk::ClearValue {
                        color: vk::ClearColorValue {
                            float32: [f32::from(r) / 255.0, f32::from(g) / 255.0, 0.0, 0.0],
                        },
                    },
                };
                let rect = vk::ClearRect {
                    rect: vk::Rect2D {
                        offset: vk::Offset2D {
                            x: ((q % 2) * half) as i32,
                            y: ((q / 2) * half) as i32,
                        },
                        extent: vk::Extent2D {
                            width: half,
                            height: half,
                        },
                    },
                    base_array_layer: 0,
                    layer_count: 1,
                };
                d.cmd_clear_attachments(cb, &[clear], &[rect]);
            }
            d.cmd_end_render_pass(cb);
        }
    }

    /// The compute path: `write_map.comp` stores the frame's bytes, and a barrier hands the map
    /// to the density-map stage in the density layout.
    ///
    /// # Safety
    /// `cb` must be recording outside a pass.
    unsafe fn write_by_compute(&self, dev: &Dev, cb: vk::CommandBuffer, frame: u32) {
        let d = &dev.d;
        let barrier = |old, new, src, dst| {
            vk::ImageMemoryBarrier::default()
                .image(self.map.0)
                .subresource_range(range(0, 1))
                .old_layout(old)
                .new_layout(new)
                .src_access_mask(src)
                .dst_access_mask(dst)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        };
        // SAFETY: as the caller promised.
        unsafe {
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[barrier(
                    vk::ImageLayout::UNDEFINED,
                    vk::ImageLayout::GENERAL,
                    vk::AccessFlags::empty(),
                    vk::AccessFlags::SHADER_WRITE,
                )],
            );
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, self.compute.pipeline);
            d.cmd_bind_descriptor_sets(
                cb,
                vk::PipelineBindPoint::COMPUTE,
                self.compute.layout,
                0,
                &[self.compute.set],
                &[],
            );
            d.cmd_push_constants(
                cb,
                self.compute.layout,
                vk::ShaderStageFlags::COMPUTE,
                0,
                &frame.to_ne_bytes(),
            );
            d.cmd_dispatch(cb, self.side, self.side, 1);
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[barrier(
                    vk::ImageLayout::GENERAL,
                    FDM_LAYOUT,
                    vk::AccessFlags::SHADER_WRITE,
                    vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT,
                )],
            );
        }
    }

    /// The pass that reads the map (`reader` with `fb`), into the colour target.
    ///
    /// # Safety
    /// `cb` must be recording outside a pass.
    unsafe fn read(
        &self,
        dev: &Dev,
        cb: vk::CommandBuffer,
        pass: vk::RenderPass,
        fb: vk::Framebuffer,
    ) {
        let d = &dev.d;
        // SAFETY: as the caller promised.
        unsafe {
            // After an earlier read in the same command buffer, its pass's colour writes come
            // before this transition (synchronization validation sees the hazard otherwise).
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[vk::ImageMemoryBarrier::default()
                    .image(self.color.0)
                    .subresource_range(range(0, 1))
                    .old_layout(vk::ImageLayout::UNDEFINED)
                    .new_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                    .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                    .dst_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                    .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)],
            );
            d.cmd_begin_render_pass(
                cb,
                &vk::RenderPassBeginInfo::default()
                    .render_pass(pass)
                    .framebuffer(fb)
                    .render_area(AREA)
                    .clear_values(&CLEAR),
                vk::SubpassContents::INLINE,
            );
            d.cmd_end_render_pass(cb);
        }
    }

    /// # Safety
    /// The device must be idle.
    unsafe fn destroy(self, dev: &Dev) {
        let d = &dev.d;
        self.compute.destroy(d);
        // SAFETY: as the caller promised; each object destroyed once.
        unsafe {
            d.destroy_framebuffer(self.reader_fb, None);
            d.destroy_framebuffer(self.writer_fb, None);
            d.destroy_render_pass(self.reader, None);
            d.destroy_render_pass(self.writer, None);
            for (image, memory, view) in [self.map, self.color] {
                d.destroy_image_view(view, None);
                d.destroy_image(image, None);
                d.free_memory(memory, None);
            }
        }
    }
}

/// Six frames, the map written by a render pass and by compute in turn, its contents changing
/// every frame: each frame's rates are the model's for what the application wrote that frame, on
/// a layered and on a merging profile.
#[test]
fn maps_written_by_render_passes_and_by_compute_shade_each_frame() {
    let Some((_serial, env)) = env() else { return };
    for profile in [Profile::Nvidia, Profile::Amd] {
        let Some(vk) = Vk::new(env, profile, true) else {
            return;
        };
        let dev = converting_device(&vk, false);
        // SAFETY: the device is alive until `destroy`; every recording is submitted and waited
        // for before the next.
        unsafe {
            let app = App::new(
                &dev,
                profile,
                vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::STORAGE,
            );
            let mut seen = Vec::new();
            for frame in 0..6u32 {
                let by_pass = frame % 2 == 0;
                let what = format!(
                    "{profile:?} frame {frame}, map written by {}",
                    if by_pass { "a render pass" } else { "compute" }
                );
                let cb = dev.begin();
                let bytes = if by_pass {
                    app.write_by_pass(&dev, cb, frame);
                    pass_bytes(app.side, frame)
                } else {
                    app.write_by_compute(&dev, cb, frame);
                    compute_bytes(app.side, frame)
                };
                app.read(&dev, cb, app.reader, app.reader_fb);
                dev.submit(cb);
                let got = rates_of(env, cb, &what);
                let want = model_rates(profile, &bytes);
                assert!(
                    want.iter().any(|&c| c != 0),
                    "{what}: a map that tests nothing"
                );
                assert!(got == want, "{what}: rates {got:?}, want {want:?}");
                seen.push(want);
            }
            seen.dedup();
            assert_eq!(seen.len(), 6, "every frame's map differs from the last");
            dev.d.device_wait_idle().expect("idle");
            app.destroy(&dev);
        }
        dev.destroy();
        assert_eq!(env.double.errors(), Vec::<String>::new(), "{profile:?}");
        drop(vk);
        assert_only_stage_false_positives();
    }
}

/// A pass that moves its map from `SHADER_READ_ONLY_OPTIMAL` into the density layout: the map is
/// converted (it has content), and the application's later barrier out of the density layout
/// and its copy of the map back name the layout the image is in (validation is silent), and read
/// back what it uploaded.
#[test]
fn a_pass_that_moves_its_map_into_the_density_layout_keeps_the_apps_layouts() {
    let Some((_serial, env)) = env() else { return };
    let profile = Profile::Nvidia;
    let Some(vk) = Vk::new(env, profile, true) else {
        return;
    };
    let dev = converting_device(&vk, false);
    // SAFETY: as in the test above.
    unsafe {
        let app = App::new(
            &dev,
            profile,
            vk::ImageUsageFlags::COLOR_ATTACHMENT
                | vk::ImageUsageFlags::STORAGE
                | vk::ImageUsageFlags::SAMPLED
                | vk::ImageUsageFlags::TRANSFER_SRC
                | vk::ImageUsageFlags::TRANSFER_DST,
        );
        let bytes = compute_bytes(app.side, 7);
        let staging = dev.buffer(bytes.len() as u64, vk::BufferUsageFlags::TRANSFER_SRC);
        dev.write(&staging, &bytes);
        let back: Buffer = dev.buffer(bytes.len() as u64, vk::BufferUsageFlags::TRANSFER_DST);
        let reader = reader_pass(&dev, vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL);
        let fb = framebuffer(&dev.d, reader, &[app.color.2, app.map.2], SIZE);
        let d = &dev.d;
        let barrier = |old, new, src, dst| {
            vk::ImageMemoryBarrier::default()
                .image(app.map.0)
                .subresource_range(range(0, 1))
                .old_layout(old)
                .new_layout(new)
                .src_access_mask(src)
                .dst_access_mask(dst)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        };
        let copy = vk::BufferImageCopy {
            image_subresource: vk::ImageSubresourceLayers {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                mip_level: 0,
                base_array_layer: 0,
                layer_count: 1,
            },
            image_extent: vk::Extent3D {
                width: app.side,
                height: app.side,
                depth: 1,
            },
            ..Default::default()
        };
        let cb = dev.begin();
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
            app.map.0,
            vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            &[copy],
        );
        d.cmd_pipeline_barrier(
            cb,
            vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::FRAGMENT_SHADER,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[barrier(
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
                vk::AccessFlags::TRANSFER_WRITE,
                vk::AccessFlags::SHADER_READ,
            )],
        );
        app.read(&dev, cb, reader, fb);
        // The pass left the map in the density layout: the application's next barrier says so.
        d.cmd_pipeline_barrier(
            cb,
            vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
            vk::PipelineStageFlags::TRANSFER,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[barrier(
                FDM_LAYOUT,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                vk::AccessFlags::empty(),
                vk::AccessFlags::TRANSFER_READ,
            )],
        );
        d.cmd_copy_image_to_buffer(
            cb,
            app.map.0,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            back.buffer,
            &[copy],
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
        dev.submit(cb);
        let what = "a pass moving its map from SHADER_READ_ONLY_OPTIMAL";
        let got = rates_of(env, cb, what);
        assert_eq!(got, model_rates(profile, &bytes), "{what}");
        let words = dev.read_words(&back, bytes.len() / 4);
        let read: Vec<u8> = words.iter().flat_map(|w| w.to_ne_bytes()).collect();
        assert_eq!(read, bytes, "{what}: the map read back");
        dev.d.device_wait_idle().expect("idle");
        dev.d.destroy_framebuffer(fb, None);
        dev.d.destroy_render_pass(reader, None);
        dev.free(staging);
        dev.free(back);
        app.destroy(&dev);
    }
    dev.finish(env, vk);
}

/// A pass inside the application's conditional rendering, with the condition false and true: the
/// pass reads its map either way (conditional rendering discards draws and dispatches, not the
/// density map's read), so the rates are the model's for the map the application wrote this
/// frame, not what an earlier frame left behind.
#[test]
fn maps_read_inside_conditional_rendering_shade_whatever_the_condition() {
    let Some((_serial, env)) = env() else { return };
    let profile = Profile::Nvidia;
    let Some(vk) = Vk::new(env, profile, true) else {
        return;
    };
    let dev = converting_device(&vk, true);
    // SAFETY: as in the tests above.
    unsafe {
        let app = App::new(
            &dev,
            profile,
            vk::ImageUsageFlags::COLOR_ATTACHMENT
                | vk::ImageUsageFlags::STORAGE
                | vk::ImageUsageFlags::TRANSFER_DST,
        );
        let condition = dev.buffer(4, vk::BufferUsageFlags::CONDITIONAL_RENDERING_EXT);
        for (round, value) in [(0u32, None), (1, Some(0u32)), (2, Some(1)), (3, Some(0))] {
            let what = format!("round {round}, condition {value:?}");
            let bytes = compute_bytes(app.side, round * 2 + 1);
            let staging = dev.buffer(bytes.len() as u64, vk::BufferUsageFlags::TRANSFER_SRC);
            dev.write(&staging, &bytes);
            if let Some(v) = value {
                dev.write(&condition, &v.to_ne_bytes());
            }
            let cb = dev.begin();
            dev.upload(cb, &staging, app.map.0, app.side, 1);
            let loader = ash::ext::conditional_rendering::Device::new(&vk.instance, &dev.d);
            if value.is_some() {
                (loader.fp().cmd_begin_conditional_rendering_ext)(
                    cb,
                    &vk::ConditionalRenderingBeginInfoEXT::default()
                        .buffer(condition.buffer)
                        .offset(0),
                );
            }
            app.read(&dev, cb, app.reader, app.reader_fb);
            if value.is_some() {
                (loader.fp().cmd_end_conditional_rendering_ext)(cb);
            }
            dev.submit(cb);
            let got = rates_of(env, cb, &what);
            assert_eq!(got, model_rates(profile, &bytes), "{what}");
            dev.free(staging);
        }
        dev.d.device_wait_idle().expect("idle");
        dev.free(condition);
        app.destroy(&dev);
    }
    dev.finish(env, vk);
}

/// The barriers the double saw recorded in command buffers with `cb`'s handle.
fn barriers_in(env: &Env, cb: vk::CommandBuffer) -> usize {
    use ash::vk::Handle as _;
    env.double
        .events("barrier")
        .iter()
        .filter(|b| b["command_buffer"] == serde_json::json!(cb.as_raw()))
        .count()
}

/// Two passes in one command buffer read the same map: where nothing between them wrote it, the
/// second costs no conversion and no barrier (the double counts the same barriers as for one
/// pass); where the application wrote it between them (compute and a barrier), the second pass
/// is converted again and shades with the new content.
#[test]
fn a_map_read_again_unchanged_costs_no_barrier() {
    let Some((_serial, env)) = env() else { return };
    let profile = Profile::Nvidia;
    let Some(vk) = Vk::new(env, profile, true) else {
        return;
    };
    let dev = converting_device(&vk, false);
    // SAFETY: as in the tests above.
    unsafe {
        let app = App::new(
            &dev,
            profile,
            vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::STORAGE,
        );
        let mut counts = Vec::new();
        for (passes, rewrite) in [(1, false), (2, false), (2, true)] {
            let what = format!("{passes} pass(es), map rewritten between: {rewrite}");
            let cb = dev.begin();
            // An earlier device's command buffer may have had this handle.
            let before = barriers_in(env, cb);
            app.write_by_compute(&dev, cb, 1);
            let mut bytes = compute_bytes(app.side, 1);
            app.read(&dev, cb, app.reader, app.reader_fb);
            if passes == 2 {
                if rewrite {
                    app.write_by_compute(&dev, cb, 2);
                    bytes = compute_bytes(app.side, 2);
                }
                app.read(&dev, cb, app.reader, app.reader_fb);
            }
            dev.submit(cb);
            assert_eq!(
                rates_of(env, cb, &what),
                model_rates(profile, &bytes),
                "{what}"
            );
            counts.push(barriers_in(env, cb) - before);
        }
        let (one, unchanged, rewritten) = (counts[0], counts[1], counts[2]);
        // The second pass's own colour barrier is the application's: one more than one pass.
        assert_eq!(
            unchanged,
            one + 1,
            "a second pass over an unchanged map added barriers beyond the application's: {counts:?}"
        );
        assert!(
            rewritten > unchanged + 2,
            "a rewritten map was not converted again: {counts:?}"
        );
        dev.d.device_wait_idle().expect("idle");
        app.destroy(&dev);
    }
    dev.finish(env, vk);
}

/// A secondary command buffer (`SIMULTANEOUS_USE`) renders with the map through dynamic rendering
/// and is executed from two primaries, each of which first uploads its own content into the map;
/// both primaries go down in one submit, in either order. The conversion recorded in the
/// secondary uses the secondary's own code buffer, and the rates after the submit are the model's
/// for the content the last primary uploaded; validation (which checks simultaneous use) says
/// nothing.
///
/// lavapipe runs one queue in order, so a code buffer shared between command buffers could not
/// race here; the test holds the conversion's per-command-buffer objects to what the application
/// sees, whichever order its command buffers run in.
#[test]
fn a_secondary_executed_from_two_primaries_shades_with_each_primarys_map() {
    let Some((_serial, env)) = env() else { return };
    let profile = Profile::Amd;
    let Some(vk) = Vk::new(env, profile, true) else {
        return;
    };
    let dev = converting_device(&vk, false);
    // SAFETY: as in the tests above.
    unsafe {
        let app = App::new(
            &dev,
            profile,
            vk::ImageUsageFlags::COLOR_ATTACHMENT
                | vk::ImageUsageFlags::STORAGE
                | vk::ImageUsageFlags::TRANSFER_DST,
        );
        let d = &dev.d;
        let secondary = d
            .allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(dev.pool)
                    .level(vk::CommandBufferLevel::SECONDARY)
                    .command_buffer_count(1),
            )
            .expect("a secondary")[0];
        let inheritance = vk::CommandBufferInheritanceInfo::default();
        d.begin_command_buffer(
            secondary,
            &vk::CommandBufferBeginInfo::default()
                .flags(vk::CommandBufferUsageFlags::SIMULTANEOUS_USE)
                .inheritance_info(&inheritance),
        )
        .expect("vkBeginCommandBuffer (secondary)");
        let color_att = [cleared_color(app.color.2)];
        let mut density_att = vk::RenderingFragmentDensityMapAttachmentInfoEXT::default()
            .image_view(app.map.2)
            .image_layout(FDM_LAYOUT);
        let info = vk::RenderingInfo::default()
            .render_area(AREA)
            .layer_count(1)
            .color_attachments(&color_att)
            .push_next(&mut density_att);
        d.cmd_begin_rendering(secondary, &info);
        d.cmd_end_rendering(secondary);
        d.end_command_buffer(secondary).expect("vkEndCommandBuffer");
        let contents = [compute_bytes(app.side, 3), compute_bytes(app.side, 4)];
        let staging: Vec<Buffer> = contents
            .iter()
            .map(|bytes| {
                let b = dev.buffer(bytes.len() as u64, vk::BufferUsageFlags::TRANSFER_SRC);
                dev.write(&b, bytes);
                b
            })
            .collect();
        let primaries: Vec<vk::CommandBuffer> = staging
            .iter()
            .map(|s| {
                let cb = dev.begin();
                dev.upload(cb, s, app.map.0, app.side, 1);
                d.cmd_pipeline_barrier(
                    cb,
                    vk::PipelineStageFlags::ALL_COMMANDS,
                    vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[vk::ImageMemoryBarrier::default()
                        .image(app.color.0)
                        .subresource_range(range(0, 1))
                        .old_layout(vk::ImageLayout::UNDEFINED)
                        .new_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                        .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                        .dst_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)],
                );
                d.cmd_execute_commands(cb, &[secondary]);
                d.end_command_buffer(cb).expect("vkEndCommandBuffer");
                cb
            })
            .collect();
        for (order, last) in [([0usize, 1usize], 1usize), ([1, 0], 0)] {
            let cbs = [primaries[order[0]], primaries[order[1]]];
            d.queue_submit(
                dev.queue,
                &[vk::SubmitInfo::default().command_buffers(&cbs)],
                vk::Fence::null(),
            )
            .expect("vkQueueSubmit");
            d.queue_wait_idle(dev.queue).expect("idle");
            let what = format!("primaries in order {order:?}");
            let submits = env.double.events("submit");
            let read = submits
                .last()
                .and_then(|s| s["shading_rate_images"].as_array().cloned())
                .unwrap_or_default();
            assert_eq!(
                codes_of(&read, &what),
                model_rates(profile, &contents[last]),
                "{what}"
            );
        }
        d.device_wait_idle().expect("idle");
        for s in staging {
            dev.free(s);
        }
        app.destroy(&dev);
    }
    dev.finish(env, vk);
}
