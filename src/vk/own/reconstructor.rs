//! The reconstruction of coarse blocks (docs/reconstruction.md; [`crate::vk::reconstruct`] says
//! when it runs): per device its pipeline and layouts, made at device creation; scratch buffers
//! made at the first pass of a target size and kept; and the commands recorded into the
//! application's command buffer after a pass instance ends ([`Reconstructor::record`]).

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use ash::vk;

use crate::bridge::FdmEmulation;
use crate::vk::base::ffi::raw;
use crate::vk::own::bindings::{restore, Bound};
use crate::vk::own::calls::Own;
use crate::vk::own::recon_shader::{table, Kind, Push, GROUP, PUSH_BYTES, SHADER};
use crate::vk::translate::formats::SHADOW_LAYOUT;
use crate::vk::translate::render_pass::MAX_TARGETS;

/// Scratch buffers a device keeps at most (one per target size in use; a descriptor set each).
pub const MAX_SCRATCH: u32 = 16;

/// One colour target a pass's end reconstructs: layers of one image, and the layout the pass
/// leaves them in.
#[derive(Clone, Copy, Debug)]
pub struct Colour {
    pub image: vk::Image,
    /// The layers the pass rendered: the view's first layer and how many.
    pub base_layer: u32,
    pub layers: u32,
    /// The layout the pass leaves the image in, which the reconstruction restores.
    pub layout: vk::ImageLayout,
    pub kind: Kind,
    /// The rate image's layers read: 1 (merged, every view reads it) or one per rendered layer.
    pub rate_layers: u32,
}

/// What one pass instance's end reconstructs: its colour targets (each stored single-sample
/// colour attachment and each resolve target whose image is reconstructed, up to
/// [`MAX_TARGETS`]) and the shading-rate image the pass read. Plain data, made where the pass
/// begins (`crate::vk::injection`, `crate::vk::reconstruct`), kept in the command buffer's record
/// until its end.
#[derive(Clone, Copy, Debug)]
pub struct Plan {
    targets: [Option<Colour>; MAX_TARGETS],
    pub area: vk::Rect2D,
    pub rate_image: vk::Image,
    /// The rate image's extent in texels, and its first layer read.
    pub rate_extent: [u32; 2],
    pub rate_base_layer: u32,
    /// The instance was begun suspending: its end is not the instance's last.
    pub suspending: bool,
}

impl Plan {
    /// A plan with no target yet.
    pub fn new(
        area: vk::Rect2D,
        rate_image: vk::Image,
        rate_extent: [u32; 2],
        rate_base_layer: u32,
        suspending: bool,
    ) -> Plan {
        Plan {
            targets: [None; MAX_TARGETS],
            area,
            rate_image,
            rate_extent,
            rate_base_layer,
            suspending,
        }
    }

    /// Adds a target; `false` where the plan holds [`MAX_TARGETS`] already (the target is left
    /// alone).
    pub fn push(&mut self, c: Colour) -> bool {
        match self.targets.iter_mut().find(|t| t.is_none()) {
            Some(slot) => {
                *slot = Some(c);
                true
            }
            None => false,
        }
    }

    /// The targets, in the order the pass names them.
    pub fn targets(&self) -> impl Iterator<Item = &Colour> {
        self.targets.iter().flatten()
    }

    /// Whether the plan reconstructs anything.
    pub fn is_empty(&self) -> bool {
        self.targets[0].is_none()
    }
}

/// The layers of a map of `map_layers` layers a target rendering `layers` layers reads: 1 where
/// the map is merged, else one per rendered layer.
pub fn rate_layers(map_layers: u32, layers: u32) -> u32 {
    if map_layers <= 1 {
        1
    } else {
        map_layers.min(layers)
    }
}

/// An application's colour view on an emulating device whose image is reconstructed
/// (docs/reconstruction.md): decided when the view is made.
#[derive(Clone, Copy, Debug)]
pub struct Target {
    pub image: vk::Image,
    pub base_layer: u32,
    pub layers: u32,
    pub format: vk::Format,
}

/// A rewritten render pass's colour targets: of its first subpass's colour attachments, each
/// stored single-sample one and each stored resolve attachment of a multisampled one (as
/// [`crate::vk::own::injector::InjectedPass`] has them for injection), by attachment index with
/// the layout the pass leaves it in.
#[derive(Clone, Copy, Debug)]
pub struct PassTarget {
    pub colours: [Option<(u32, vk::ImageLayout)>; MAX_TARGETS],
    pub density: u32,
    pub view_mask: u32,
}

/// A framebuffer of a rewritten pass with a reconstructed colour view: per entry of its pass's
/// [`PassTarget::colours`], the view there where it is reconstructed; the density view; the
/// layers rendered.
#[derive(Clone, Copy, Debug)]
pub struct FramebufferTargets {
    pub colours: [Option<u64>; MAX_TARGETS],
    pub density: u64,
    pub layers: u32,
}

/// What an emulating device's reconstruction knows of its objects, filled at their creation
/// (`usage` on injecting devices too).
#[derive(Default)]
pub struct Tables {
    /// Application images created with `VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT`, and their layers.
    pub images: HashMap<u64, u32>,
    /// Colour images with transfer usage (on an emulating or injecting device): the usage each
    /// was created with, and what of it the layer added (`crate::vk::reconstruct::image_made`),
    /// for giving their views the application's usage.
    pub usage: HashMap<u64, (vk::ImageUsageFlags, vk::ImageUsageFlags)>,
    /// Views whose image is reconstructed.
    pub views: HashMap<u64, Target>,
    /// Rewritten render passes' colour targets.
    pub passes: HashMap<u64, PassTarget>,
    /// Framebuffers of those passes with a reconstructed colour view.
    pub framebuffers: HashMap<u64, FramebufferTargets>,
}

/// One scratch buffer: raw texels in, texels out, rate codes, and the set naming them.
#[derive(Clone, Copy)]
struct Scratch {
    /// Texels (of up to 8 bytes) and rate texels it holds.
    texels: u64,
    rate_bytes: u64,
    buffer: vk::Buffer,
    memory: vk::DeviceMemory,
    set: vk::DescriptorSet,
}

impl Scratch {
    fn half(&self) -> u64 {
        self.texels * 8
    }
}

/// One device's reconstruction objects.
pub struct Reconstructor {
    pub own: Arc<Own>,
    /// The shading-rate texel in pixels.
    pub texel: [u32; 2],
    table: [u32; 2],
    set_layout: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    pool: vk::DescriptorPool,
    scratch: parking_lot::Mutex<Vec<Scratch>>,
    logged_formats: parking_lot::Mutex<Vec<vk::Format>>,
    logged_state: AtomicBool,
    logged_scratch: AtomicBool,
    /// An emulating device's tables ([`Tables`]); injection keeps its own in the injector.
    pub tables: parking_lot::Mutex<Tables>,
    /// Set once a view whose image is reconstructed was noted: until then a begin looks no
    /// further.
    pub any: AtomicBool,
    /// The application enabled imageless framebuffers on the device: its views of images whose
    /// usage fovea widened get its usage (`crate::vk::reconstruct::hide_added_usage`).
    pub imageless: bool,
}

impl Reconstructor {
    /// The pipeline, layouts and descriptor pool on a live device with `fdm`'s shading-rate
    /// attachments.
    ///
    /// # Safety
    /// `own` must be the live device's.
    pub unsafe fn new(own: Arc<Own>, fdm: &FdmEmulation) -> Result<Reconstructor, vk::Result> {
        let d = &own.fns;
        let code = ash::util::read_spv(&mut std::io::Cursor::new(SHADER))
            .map_err(|_| vk::Result::ERROR_INITIALIZATION_FAILED)?;
        let binding = |b| {
            vk::DescriptorSetLayoutBinding::default()
                .binding(b)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::COMPUTE)
        };
        let bindings = [binding(0), binding(1), binding(2)];
        let ranges = [vk::PushConstantRange {
            stage_flags: vk::ShaderStageFlags::COMPUTE,
            offset: 0,
            size: PUSH_BYTES as u32,
        }];
        let sizes = [vk::DescriptorPoolSize {
            ty: vk::DescriptorType::STORAGE_BUFFER,
            descriptor_count: 3 * MAX_SCRATCH,
        }];
        // SAFETY: the layer's own objects on a live device; each is destroyed on failure.
        unsafe {
            let set_layout = d.create_descriptor_set_layout(
                &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                None,
            )?;
            let layouts = [set_layout];
            let layout = d
                .create_pipeline_layout(
                    &vk::PipelineLayoutCreateInfo::default()
                        .set_layouts(&layouts)
                        .push_constant_ranges(&ranges),
                    None,
                )
                .inspect_err(|_| d.destroy_descriptor_set_layout(set_layout, None))?;
            let undo = |pipeline: Option<vk::Pipeline>| {
                if let Some(p) = pipeline {
                    d.destroy_pipeline(p, None);
                }
                d.destroy_pipeline_layout(layout, None);
                d.destroy_descriptor_set_layout(set_layout, None);
            };
            let module = d
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&code), None)
                .inspect_err(|_| undo(None))?;
            let stage = vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::COMPUTE)
                .module(module)
                .name(c"main");
            let info = [vk::ComputePipelineCreateInfo::default()
                .stage(stage)
                .layout(layout)];
            let made = d.create_compute_pipelines(vk::PipelineCache::null(), &info, None);
            d.destroy_shader_module(module, None);
            let pipeline = made.map_err(|(_, e)| e).inspect_err(|_| undo(None))?[0];
            let pool = d
                .create_descriptor_pool(
                    &vk::DescriptorPoolCreateInfo::default()
                        .max_sets(MAX_SCRATCH)
                        .pool_sizes(&sizes),
                    None,
                )
                .inspect_err(|_| undo(Some(pipeline)))?;
            Ok(Reconstructor {
                texel: fdm.texel,
                table: table(fdm),
                own,
                set_layout,
                layout,
                pipeline,
                pool,
                scratch: parking_lot::Mutex::new(Vec::new()),
                logged_formats: parking_lot::Mutex::new(Vec::new()),
                logged_state: AtomicBool::new(false),
                logged_scratch: AtomicBool::new(false),
                tables: parking_lot::Mutex::new(Tables::default()),
                any: AtomicBool::new(false),
                imageless: false,
            })
        }
    }

    /// # Safety
    /// The device must be live and idle.
    pub unsafe fn destroy(&self) {
        let d = &self.own.fns;
        // SAFETY: the layer's own objects, unused on an idle device.
        unsafe {
            for s in self.scratch.lock().drain(..) {
                d.destroy_buffer(s.buffer, None);
                d.free_memory(s.memory, None);
            }
            d.destroy_descriptor_pool(self.pool, None);
            d.destroy_pipeline(self.pipeline, None);
            d.destroy_pipeline_layout(self.layout, None);
            d.destroy_descriptor_set_layout(self.set_layout, None);
        }
    }

    /// Whether a colour target of `format` can be reconstructed; the first time a format cannot,
    /// the log says so (once per device and format).
    pub fn handles(&self, format: vk::Format) -> Option<Kind> {
        let kind = Kind::of(format);
        if kind.is_none() {
            let mut logged = self.logged_formats.lock();
            if !logged.contains(&format) {
                logged.push(format);
                tracing::warn!(
                    format = ?format,
                    "coarse blocks are not reconstructed in images of this format (the layer \
                     decodes 8-bit UNORM and sRGB, 10:10:10:2 UNORM and 16-bit float and UNORM \
                     colour): they keep their blocks"
                );
            }
        }
        kind
    }

    /// The scratch for `texels` texels and `rate_bytes` rate texels: one kept from an earlier
    /// pass, or made now (once per size in use, then kept with the device).
    ///
    /// # Safety
    /// The device must be live.
    unsafe fn scratch(&self, texels: u64, rate_bytes: u64) -> Option<Scratch> {
        let mut all = self.scratch.lock();
        if let Some(s) = all
            .iter()
            .find(|s| s.texels >= texels && s.rate_bytes >= rate_bytes)
        {
            return Some(*s);
        }
        if all.len() as u32 >= MAX_SCRATCH {
            return None;
        }
        let rate_bytes = rate_bytes.next_multiple_of(4);
        let size = 2 * texels * 8 + rate_bytes;
        let d = &self.own.fns;
        // SAFETY: the layer's own objects on a live device, destroyed on failure.
        unsafe {
            let buffer = d
                .create_buffer(
                    &vk::BufferCreateInfo::default().size(size).usage(
                        vk::BufferUsageFlags::STORAGE_BUFFER
                            | vk::BufferUsageFlags::TRANSFER_SRC
                            | vk::BufferUsageFlags::TRANSFER_DST,
                    ),
                    None,
                )
                .ok()?;
            let req = d.get_buffer_memory_requirements(buffer);
            let Some(ty) = self.own.memory_type(req.memory_type_bits) else {
                d.destroy_buffer(buffer, None);
                return None;
            };
            let memory = match d.allocate_memory(
                &vk::MemoryAllocateInfo::default()
                    .allocation_size(req.size)
                    .memory_type_index(ty),
                None,
            ) {
                Ok(m) => m,
                Err(_) => {
                    d.destroy_buffer(buffer, None);
                    return None;
                }
            };
            let free = || {
                d.destroy_buffer(buffer, None);
                d.free_memory(memory, None);
            };
            if d.bind_buffer_memory(buffer, memory, 0).is_err() {
                free();
                return None;
            }
            let layouts = [self.set_layout];
            let Ok(sets) = d.allocate_descriptor_sets(
                &vk::DescriptorSetAllocateInfo::default()
                    .descriptor_pool(self.pool)
                    .set_layouts(&layouts),
            ) else {
                free();
                return None;
            };
            let s = Scratch {
                texels,
                rate_bytes,
                buffer,
                memory,
                set: sets[0],
            };
            let infos = [
                [vk::DescriptorBufferInfo {
                    buffer,
                    offset: 0,
                    range: s.half(),
                }],
                [vk::DescriptorBufferInfo {
                    buffer,
                    offset: s.half(),
                    range: s.half(),
                }],
                [vk::DescriptorBufferInfo {
                    buffer,
                    offset: 2 * s.half(),
                    range: rate_bytes,
                }],
            ];
            let writes: Vec<vk::WriteDescriptorSet<'_>> = infos
                .iter()
                .enumerate()
                .map(|(b, info)| {
                    vk::WriteDescriptorSet::default()
                        .dst_set(s.set)
                        .dst_binding(b as u32)
                        .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                        .buffer_info(info)
                })
                .collect();
            d.update_descriptor_sets(&writes, &[]);
            all.push(s);
            Some(s)
        }
    }

    /// Records, after the pass instance of `plan` ended in `cb`, the reconstruction of each of
    /// its colour targets ([`Reconstructor::record_target`]), then gives the application's
    /// compute bindings back.
    ///
    /// # Safety
    /// `cb` must be recording, outside a render pass, on this reconstructor's device; `bound` its
    /// bindings.
    pub unsafe fn record(&self, cb: vk::CommandBuffer, plan: &Plan, bound: Option<&Bound>) {
        let Some(first) = plan.targets().next() else {
            return;
        };
        let Some(bound) = bound.filter(|b| b.conditional.is_none() && !b.inherited_conditional)
        else {
            if !self.logged_state.swap(true, Ordering::Relaxed) {
                tracing::warn!(
                    image = raw(first.image),
                    "a command buffer whose compute bindings the layer cannot give back (push \
                     descriptors, or more sets, dynamic offsets or push-constant ranges than it \
                     records, or conditional rendering, which would discard the dispatch and not the copies): its passes' coarse blocks \
                     are not reconstructed"
                );
            }
            return;
        };
        let mut dispatched = false;
        for t in plan.targets() {
            // SAFETY: as the caller promised.
            dispatched |= unsafe { self.record_target(cb, plan, t) };
        }
        if dispatched {
            // SAFETY: as the caller promised: `bound` is `cb`'s.
            unsafe { restore(&self.own.fns, cb, bound) };
            // The scratch is the device's: submits on its other graphics queues are ordered
            // against this one's from now on (docs/reconstruction.md#queues).
            if let Some(o) = &self.own.clears.order {
                o.serialise();
            }
        }
    }

    /// Records the reconstruction of one colour target `t` of `plan`: its render area's layers
    /// copied into the scratch, the shading-rate image's layers too, a dispatch of the shader,
    /// the result copied back, the image left in the layout the pass left it in. Barriers order
    /// it after everything before it (an earlier target's reads of the scratch included) and
    /// before everything after it; the second scope of the last covers all later commands.
    /// Whether it dispatched (the compute bindings are then the layer's).
    ///
    /// # Safety
    /// As [`Reconstructor::record`].
    unsafe fn record_target(&self, cb: vk::CommandBuffer, plan: &Plan, t: &Colour) -> bool {
        let (w, h) = (plan.area.extent.width, plan.area.extent.height);
        if w == 0 || h == 0 || t.layers == 0 {
            return false;
        }
        let texels = u64::from(w) * u64::from(h) * u64::from(t.layers);
        let rate_bytes = u64::from(plan.rate_extent[0])
            * u64::from(plan.rate_extent[1])
            * u64::from(t.rate_layers);
        // SAFETY: the device is live while its command buffer records.
        let Some(s) = (unsafe {
            self.scratch(
                texels.max(u64::from(w) * u64::from(h) * u64::from(t.layers)),
                rate_bytes,
            )
        }) else {
            if !self.logged_scratch.swap(true, Ordering::Relaxed) {
                tracing::warn!(
                    image = raw(t.image),
                    "no scratch buffer for a reconstruction: this target keeps its coarse blocks"
                );
            }
            return false;
        };
        let d = &self.own.fns;
        let barrier = |image, base_array_layer, layer_count, old, new, src, dst| {
            vk::ImageMemoryBarrier::default()
                .src_access_mask(src)
                .dst_access_mask(dst)
                .old_layout(old)
                .new_layout(new)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .image(image)
                .subresource_range(vk::ImageSubresourceRange {
                    aspect_mask: vk::ImageAspectFlags::COLOR,
                    base_mip_level: 0,
                    level_count: 1,
                    base_array_layer,
                    layer_count,
                })
        };
        let colour =
            |old, new, src, dst| barrier(t.image, t.base_layer, t.layers, old, new, src, dst);
        let rate = |old, new, src, dst| {
            barrier(
                plan.rate_image,
                plan.rate_base_layer,
                t.rate_layers,
                old,
                new,
                src,
                dst,
            )
        };
        let region = vk::BufferImageCopy {
            buffer_offset: 0,
            buffer_row_length: 0,
            buffer_image_height: 0,
            image_subresource: vk::ImageSubresourceLayers {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                mip_level: 0,
                base_array_layer: t.base_layer,
                layer_count: t.layers,
            },
            image_offset: vk::Offset3D {
                x: plan.area.offset.x,
                y: plan.area.offset.y,
                z: 0,
            },
            image_extent: vk::Extent3D {
                width: w,
                height: h,
                depth: 1,
            },
        };
        let push = Push {
            width: w,
            height: h,
            origin: [
                plan.area.offset.x.max(0) as u32,
                plan.area.offset.y.max(0) as u32,
            ],
            rate_extent: plan.rate_extent,
            texel: self.texel,
            kind: t.kind as u32,
            words: t.kind.words(),
            rate_layers: t.rate_layers,
            table: self.table,
        };
        let all = vk::PipelineStageFlags::ALL_COMMANDS;
        let transfer = vk::PipelineStageFlags::TRANSFER;
        let compute = vk::PipelineStageFlags::COMPUTE_SHADER;
        let src = vk::ImageLayout::TRANSFER_SRC_OPTIMAL;
        let dst = vk::ImageLayout::TRANSFER_DST_OPTIMAL;
        // SAFETY: the next layer's commands on the application's recording command buffer,
        // outside a render pass, with the layer's own objects and the images the pass used.
        unsafe {
            // 1. The pass's writes (and an earlier reconstruction's reads of the scratch) before
            // the copies; the rate image from the shading-rate layout to a copy's.
            d.cmd_pipeline_barrier(
                cb,
                all,
                transfer,
                vk::DependencyFlags::empty(),
                &[vk::MemoryBarrier::default()
                    .src_access_mask(vk::AccessFlags::MEMORY_WRITE | vk::AccessFlags::MEMORY_READ)
                    .dst_access_mask(vk::AccessFlags::TRANSFER_WRITE)],
                &[],
                &[
                    colour(
                        t.layout,
                        src,
                        vk::AccessFlags::MEMORY_WRITE,
                        vk::AccessFlags::TRANSFER_READ,
                    ),
                    rate(
                        SHADOW_LAYOUT,
                        src,
                        vk::AccessFlags::empty(),
                        vk::AccessFlags::TRANSFER_READ,
                    ),
                ],
            );
            d.cmd_copy_image_to_buffer(cb, t.image, src, s.buffer, &[region]);
            d.cmd_copy_image_to_buffer(
                cb,
                plan.rate_image,
                src,
                s.buffer,
                &[vk::BufferImageCopy {
                    buffer_offset: 2 * s.half(),
                    buffer_row_length: 0,
                    buffer_image_height: 0,
                    image_subresource: vk::ImageSubresourceLayers {
                        aspect_mask: vk::ImageAspectFlags::COLOR,
                        mip_level: 0,
                        base_array_layer: plan.rate_base_layer,
                        layer_count: t.rate_layers,
                    },
                    image_offset: vk::Offset3D::default(),
                    image_extent: vk::Extent3D {
                        width: plan.rate_extent[0],
                        height: plan.rate_extent[1],
                        depth: 1,
                    },
                }],
            );
            // 2. The copies before the dispatch; the rate image back to the shading-rate layout;
            // the colour image ready for the copy back.
            d.cmd_pipeline_barrier(
                cb,
                transfer,
                compute | transfer | all,
                vk::DependencyFlags::empty(),
                &[vk::MemoryBarrier::default()
                    .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                    .dst_access_mask(vk::AccessFlags::SHADER_READ)],
                &[],
                &[
                    colour(
                        src,
                        dst,
                        vk::AccessFlags::empty(),
                        vk::AccessFlags::TRANSFER_WRITE,
                    ),
                    rate(
                        src,
                        SHADOW_LAYOUT,
                        vk::AccessFlags::empty(),
                        vk::AccessFlags::empty(),
                    ),
                ],
            );
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, self.pipeline);
            d.cmd_bind_descriptor_sets(
                cb,
                vk::PipelineBindPoint::COMPUTE,
                self.layout,
                0,
                &[s.set],
                &[],
            );
            d.cmd_push_constants(
                cb,
                self.layout,
                vk::ShaderStageFlags::COMPUTE,
                0,
                &push.bytes(),
            );
            d.cmd_dispatch(cb, w.div_ceil(GROUP), h.div_ceil(GROUP), t.layers);
            // 3. The dispatch before the copy back.
            d.cmd_pipeline_barrier(
                cb,
                compute,
                transfer,
                vk::DependencyFlags::empty(),
                &[vk::MemoryBarrier::default()
                    .src_access_mask(vk::AccessFlags::SHADER_WRITE)
                    .dst_access_mask(vk::AccessFlags::TRANSFER_READ)],
                &[],
                &[],
            );
            let mut back = region;
            back.buffer_offset = s.half();
            d.cmd_copy_buffer_to_image(cb, s.buffer, t.image, dst, &[back]);
            // 4. The image in the pass's final layout, before everything after.
            d.cmd_pipeline_barrier(
                cb,
                transfer,
                all,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[colour(
                    dst,
                    t.layout,
                    vk::AccessFlags::TRANSFER_WRITE,
                    vk::AccessFlags::MEMORY_READ | vk::AccessFlags::MEMORY_WRITE,
                )],
            );
        }
        true
    }
}
