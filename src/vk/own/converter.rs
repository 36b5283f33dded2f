//! The GPU converter of application-written density maps ([`crate::vk::convert`] says when it
//! runs): per emulating device its pipeline, layouts and descriptor pools, per map a sampled view,
//! per command buffer and map a code buffer and a descriptor set ([`Slot`]), and the commands a
//! conversion records into the application's command buffer.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64};
use std::sync::Arc;

use ash::vk;

use crate::bridge::FdmEmulation;
use crate::vk::own::calls::Own;
use crate::vk::own::convert_shader::{table, Push, POOL_SETS, SHADER, SHIFT_BYTES};
use crate::vk::own::shadows::ShadowImage;

/// What the layer made for one application density image.
#[derive(Clone, Copy, Debug)]
pub struct SourceAndShadow {
    /// A sampled 2D-array view of every layer of the application's image.
    pub view: vk::ImageView,
    /// This map's number, unique in the process ([`MAP_GENERATION`]): drivers hand a destroyed
    /// image's and view's handles to the next ones (lavapipe every second recreation), so a
    /// command buffer's [`Slot`] is matched to its map by this, never by handles.
    pub generation: u64,
    pub shadow: ShadowImage,
    /// The image was created with `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT`: passes
    /// with it may end with offsets ([`crate::vk::convert`]).
    pub offsets: bool,
}

/// What one command buffer converts one map with: a code buffer the dispatch writes and the copy
/// reads, a host-visible shifts buffer the dispatch reads (the density-map offsets of the pass,
/// written when its end is recorded), and a descriptor set naming them and the map's view. The
/// n-th conversion of a map in one recording uses the command buffer's n-th slot of that map, so
/// each pass instance has shifts of its own, fixed with the recording. Owned by the command buffer's record
/// ([`CbRecord::slots`](crate::vk::registry::CbRecord::slots)), so command buffers that may run at once (on two queues, with
/// `SIMULTANEOUS_USE`, primaries executing secondaries that convert) share no buffer the
/// conversion writes; made at a command buffer's first conversion of the map and kept across its
/// recordings, so recording allocates nothing in steady state; destroyed when the command buffer
/// is freed or its pool or device destroyed, none of which may happen while it is pending.
#[derive(Clone, Copy, Debug)]
pub struct Slot {
    pub image: u64,
    /// The [`SourceAndShadow::generation`] of the map whose view its set names and whose size its
    /// code buffer has.
    pub generation: u64,
    pub buffer: vk::Buffer,
    pub memory: vk::DeviceMemory,
    pub shifts: vk::Buffer,
    pub shifts_memory: vk::DeviceMemory,
    /// `shifts_memory` mapped, host-coherent, for the life of the slot: [`SHIFT_BYTES`] bytes.
    pub shifts_at: *mut u8,
    pub set: vk::DescriptorSet,
    pub pool: vk::DescriptorPool,
    /// The recording of its command buffer that last used it ([`Bound::recording`](crate::vk::own::bindings::Bound::recording)).
    pub used_in: u64,
}

// SAFETY: `shifts_at` points at memory the slot owns; it is written only by the thread recording
// the slot's command buffer, which the application synchronises.
unsafe impl Send for Slot {}

impl Slot {
    /// Writes the shader's shifts ([`write_shifts`]).
    ///
    /// # Safety
    /// As [`write_shifts`].
    pub unsafe fn write_shifts(&self, shifts: &[[i32; 2]]) {
        // SAFETY: the slot's own mapped memory; as the caller promised.
        unsafe { write_shifts(self.shifts_at, shifts) }
    }
}

/// Writes the shader's shifts (whole texels per layer,
/// [`MAX_SHIFTS`](crate::vk::own::convert_shader::MAX_SHIFTS) at most; the rest 0) into a slot's
/// mapped shifts memory `at`.
///
/// # Safety
/// `at` must be a live slot's `shifts_at`, whose command buffer is recording (so none of its
/// submissions is pending).
pub unsafe fn write_shifts(at: *mut u8, shifts: &[[i32; 2]]) {
    let mut bytes = [0u8; SHIFT_BYTES as usize];
    for (o, s) in bytes.chunks_exact_mut(8).zip(shifts) {
        o[..4].copy_from_slice(&s[0].to_ne_bytes());
        o[4..].copy_from_slice(&s[1].to_ne_bytes());
    }
    // SAFETY: mapped memory of `SHIFT_BYTES` bytes; no submission reads it now (as the caller
    // promised). Host-coherent, so the next submit sees it
    // (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#synchronization-submission-host-writes>).
    unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), at, bytes.len()) };
}

/// The source of [`SourceAndShadow::generation`]: advanced for every map the converters make.
static MAP_GENERATION: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

/// One application density image.
pub struct MapEntry {
    pub shadow: ShadowImage,
    pub objects: Option<SourceAndShadow>,
    /// Created with `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT`.
    pub offsets: bool,
}

/// Per emulating device: the conversion's objects and what the begin hooks look up.
pub struct Converter {
    pub own: Arc<Own>,
    pub set_layout: vk::DescriptorSetLayout,
    pub layout: vk::PipelineLayout,
    pub pipeline: vk::Pipeline,
    pub table: [u32; 4],
    /// The density (and shading-rate) texel, in pixels: offsets are shifts by whole ones.
    pub texel: [u32; 2],
    /// Leaf locks (outside [`crate::common::lock::Rank`]'s order): held for a look-up or an
    /// insertion, with nothing called under them but the layer's own object creation.
    pub pools: parking_lot::Mutex<Vec<vk::DescriptorPool>>,
    /// Application density image → its shadow, and its objects once a view of it exists (the
    /// image has memory then: a view of an image without is invalid,
    /// <https://registry.khronos.org/vulkan/specs/latest/man/html/VkImageViewCreateInfo.html>,
    /// VUID-VkImageViewCreateInfo-image-01020).
    pub maps: parking_lot::Mutex<HashMap<u64, MapEntry>>,
    /// Application view → its image, for views of converted images.
    pub views: parking_lot::Mutex<HashMap<u64, u64>>,
    /// Rewritten render pass → its density attachment's `initialLayout` and `finalLayout`, as the
    /// driver knows them (the density layout is `GENERAL` there), and whether the application
    /// named the density layout itself as the initial one.
    pub passes: parking_lot::Mutex<HashMap<u64, (vk::ImageLayout, vk::ImageLayout, bool)>>,
    pub logged_layout: AtomicBool,
    pub logged_state: AtomicBool,
    pub logged_conditional: AtomicBool,
    /// Advanced (after the entry is gone from [`Converter::maps`]) whenever one of the device's
    /// maps is destroyed: a command buffer whose slots were checked at the current value holds
    /// no slot of a dead map ([`crate::vk::convert::begun`]).
    pub maps_destroyed: AtomicU64,
}

impl Converter {
    /// # Safety
    /// `own` must belong to a live device emulating as `fdm` says.
    pub unsafe fn new(own: Arc<Own>, fdm: &FdmEmulation) -> Result<Converter, vk::Result> {
        let d = &own.fns;
        let code = ash::util::read_spv(&mut std::io::Cursor::new(SHADER))
            .map_err(|_| vk::Result::ERROR_INITIALIZATION_FAILED)?;
        let bindings = [
            vk::DescriptorSetLayoutBinding::default()
                .binding(0)
                .descriptor_type(vk::DescriptorType::SAMPLED_IMAGE)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::COMPUTE),
            vk::DescriptorSetLayoutBinding::default()
                .binding(1)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::COMPUTE),
            vk::DescriptorSetLayoutBinding::default()
                .binding(2)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::COMPUTE),
        ];
        let ranges = [vk::PushConstantRange {
            stage_flags: vk::ShaderStageFlags::COMPUTE,
            offset: 0,
            size: std::mem::size_of::<Push>() as u32,
        }];
        // SAFETY: the layer's own objects on a live device; each is destroyed on failure.
        unsafe {
            let set_layout = d.create_descriptor_set_layout(
                &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                None,
            )?;
            let layouts = [set_layout];
            let layout = match d.create_pipeline_layout(
                &vk::PipelineLayoutCreateInfo::default()
                    .set_layouts(&layouts)
                    .push_constant_ranges(&ranges),
                None,
            ) {
                Ok(l) => l,
                Err(e) => {
                    d.destroy_descriptor_set_layout(set_layout, None);
                    return Err(e);
                }
            };
            let module = match d
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&code), None)
            {
                Ok(m) => m,
                Err(e) => {
                    d.destroy_pipeline_layout(layout, None);
                    d.destroy_descriptor_set_layout(set_layout, None);
                    return Err(e);
                }
            };
            let stage = vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::COMPUTE)
                .module(module)
                .name(c"main");
            let info = [vk::ComputePipelineCreateInfo::default()
                .stage(stage)
                .layout(layout)];
            let made = d.create_compute_pipelines(vk::PipelineCache::null(), &info, None);
            d.destroy_shader_module(module, None);
            let pipeline = match made {
                Ok(p) => p[0],
                Err((_, e)) => {
                    d.destroy_pipeline_layout(layout, None);
                    d.destroy_descriptor_set_layout(set_layout, None);
                    return Err(e);
                }
            };
            Ok(Converter {
                table: table(fdm),
                texel: fdm.texel,
                own,
                set_layout,
                layout,
                pipeline,
                pools: parking_lot::Mutex::new(Vec::new()),
                maps: parking_lot::Mutex::new(HashMap::new()),
                views: parking_lot::Mutex::new(HashMap::new()),
                passes: parking_lot::Mutex::new(HashMap::new()),
                logged_layout: AtomicBool::new(false),
                logged_state: AtomicBool::new(false),
                logged_conditional: AtomicBool::new(false),
                maps_destroyed: AtomicU64::new(0),
            })
        }
    }

    /// # Safety
    /// The device must be live and idle.
    pub unsafe fn destroy(&self) {
        let d = &self.own.fns;
        let maps: Vec<SourceAndShadow> = self
            .maps
            .lock()
            .drain()
            .filter_map(|(_, e)| e.objects)
            .collect();
        // SAFETY: the layer's own objects, unused on an idle device.
        unsafe {
            for m in maps {
                d.destroy_image_view(m.view, None);
            }
            for p in self.pools.lock().drain(..) {
                d.destroy_descriptor_pool(p, None);
            }
            d.destroy_pipeline(self.pipeline, None);
            d.destroy_pipeline_layout(self.layout, None);
            d.destroy_descriptor_set_layout(self.set_layout, None);
        }
    }

    /// A descriptor set from the device's pools (a new pool where all are full) and its pool.
    ///
    /// # Safety
    /// The device must be live.
    pub unsafe fn allocate_set(
        &self,
    ) -> Result<(vk::DescriptorSet, vk::DescriptorPool), vk::Result> {
        let d = &self.own.fns;
        let layouts = [self.set_layout];
        let mut pools = self.pools.lock();
        for &pool in pools.iter().rev() {
            let info = vk::DescriptorSetAllocateInfo::default()
                .descriptor_pool(pool)
                .set_layouts(&layouts);
            // SAFETY: the layer's own pool on a live device.
            if let Ok(s) = unsafe { d.allocate_descriptor_sets(&info) } {
                return Ok((s[0], pool));
            }
        }
        let sizes = [
            vk::DescriptorPoolSize {
                ty: vk::DescriptorType::SAMPLED_IMAGE,
                descriptor_count: POOL_SETS,
            },
            vk::DescriptorPoolSize {
                ty: vk::DescriptorType::STORAGE_BUFFER,
                descriptor_count: POOL_SETS * 2,
            },
        ];
        // SAFETY: as above.
        let pool = unsafe {
            d.create_descriptor_pool(
                &vk::DescriptorPoolCreateInfo::default()
                    .flags(vk::DescriptorPoolCreateFlags::FREE_DESCRIPTOR_SET)
                    .max_sets(POOL_SETS)
                    .pool_sizes(&sizes),
                None,
            )
        }?;
        pools.push(pool);
        let info = vk::DescriptorSetAllocateInfo::default()
            .descriptor_pool(pool)
            .set_layouts(&layouts);
        // SAFETY: as above.
        let s = unsafe { d.allocate_descriptor_sets(&info) }?;
        Ok((s[0], pool))
    }

    /// # Safety
    /// `app` must be a live density image of the device, shadowed by `shadow`.
    pub unsafe fn make_map(
        &self,
        app: vk::Image,
        shadow: &ShadowImage,
        offsets: bool,
    ) -> Result<SourceAndShadow, vk::Result> {
        // SAFETY: a view of the application's live image, which has memory (it has a view).
        let view = unsafe {
            self.own.fns.create_image_view(
                &vk::ImageViewCreateInfo::default()
                    .image(app)
                    .view_type(vk::ImageViewType::TYPE_2D_ARRAY)
                    .format(vk::Format::R8G8_UNORM)
                    .subresource_range(vk::ImageSubresourceRange {
                        aspect_mask: vk::ImageAspectFlags::COLOR,
                        base_mip_level: 0,
                        level_count: 1,
                        base_array_layer: 0,
                        layer_count: shadow.app_layers.max(1),
                    }),
                None,
            )
        }?;
        Ok(SourceAndShadow {
            view,
            generation: MAP_GENERATION.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
            shadow: *shadow,
            offsets,
        })
    }

    /// A command buffer's code buffer and descriptor set for the map `m` of `image` ([`Slot`]).
    ///
    /// # Safety
    /// The device must be live; `m` this converter's objects of a live map.
    pub unsafe fn make_slot(&self, image: u64, m: &SourceAndShadow) -> Result<Slot, vk::Result> {
        let d = &self.own.fns;
        let shadow = &m.shadow;
        let codes = u64::from(shadow.extent.width)
            * u64::from(shadow.extent.height)
            * u64::from(shadow.layers);
        let size = codes.div_ceil(4).max(1) * 4;
        // SAFETY: the layer's own objects on a live device; each is destroyed again on failure.
        unsafe {
            let (buffer, memory) = bound_buffer(
                &self.own,
                size,
                vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_SRC,
                Own::memory_type,
                vk::Result::ERROR_OUT_OF_DEVICE_MEMORY,
            )?;
            let shifts = match self.shifts_buffer() {
                Ok(s) => s,
                Err(e) => {
                    d.destroy_buffer(buffer, None);
                    d.free_memory(memory, None);
                    return Err(e);
                }
            };
            let (set, pool) = match self.allocate_set() {
                Ok(s) => s,
                Err(e) => {
                    d.destroy_buffer(buffer, None);
                    d.free_memory(memory, None);
                    d.destroy_buffer(shifts.0, None);
                    d.free_memory(shifts.1, None);
                    return Err(e);
                }
            };
            let image_info = [vk::DescriptorImageInfo {
                sampler: vk::Sampler::null(),
                image_view: m.view,
                image_layout: vk::ImageLayout::GENERAL,
            }];
            let buf = [vk::DescriptorBufferInfo {
                buffer,
                offset: 0,
                range: vk::WHOLE_SIZE,
            }];
            let shift_info = [vk::DescriptorBufferInfo {
                buffer: shifts.0,
                offset: 0,
                range: vk::WHOLE_SIZE,
            }];
            let writes = [
                vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(0)
                    .descriptor_type(vk::DescriptorType::SAMPLED_IMAGE)
                    .image_info(&image_info),
                vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(1)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .buffer_info(&buf),
                vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(2)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .buffer_info(&shift_info),
            ];
            d.update_descriptor_sets(&writes, &[]);
            let slot = Slot {
                image,
                generation: m.generation,
                buffer,
                memory,
                shifts: shifts.0,
                shifts_memory: shifts.1,
                shifts_at: shifts.2,
                set,
                pool,
                used_in: 0,
            };
            slot.write_shifts(&[]);
            Ok(slot)
        }
    }

    /// A slot's shifts buffer: host-visible, host-coherent memory (every device has such a type,
    /// <https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#memory-device>),
    /// mapped for the life of the slot.
    ///
    /// # Safety
    /// The device must be live.
    unsafe fn shifts_buffer(&self) -> Result<(vk::Buffer, vk::DeviceMemory, *mut u8), vk::Result> {
        let d = &self.own.fns;
        // SAFETY: the layer's own objects on a live device; each is destroyed again on failure.
        unsafe {
            let (buffer, memory) = bound_buffer(
                &self.own,
                SHIFT_BYTES,
                vk::BufferUsageFlags::STORAGE_BUFFER,
                Own::host_memory_type,
                vk::Result::ERROR_OUT_OF_HOST_MEMORY,
            )?;
            match d.map_memory(memory, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty()) {
                Ok(p) => Ok((buffer, memory, p.cast())),
                Err(e) => {
                    d.destroy_buffer(buffer, None);
                    d.free_memory(memory, None);
                    Err(e)
                }
            }
        }
    }

    /// Destroys a command buffer's slots. The set goes back to its pool under the pools' lock,
    /// which serialises every use of the pools (descriptor pools are externally synchronised,
    /// <https://registry.khronos.org/vulkan/specs/latest/man/html/vkFreeDescriptorSets.html>,
    /// and command buffers are freed on any of the application's threads).
    ///
    /// # Safety
    /// The slots must be this converter's, on its live device, and their command buffer not
    /// pending.
    pub unsafe fn destroy_slots(&self, slots: &[Slot]) {
        if slots.is_empty() {
            return;
        }
        let d = &self.own.fns;
        let pools = self.pools.lock();
        // SAFETY: as the caller promised.
        unsafe {
            for s in slots {
                if pools.contains(&s.pool) {
                    let _ = d.free_descriptor_sets(s.pool, &[s.set]);
                }
                d.destroy_buffer(s.buffer, None);
                d.free_memory(s.memory, None);
                d.destroy_buffer(s.shifts, None);
                // Freeing mapped memory unmaps it.
                d.free_memory(s.shifts_memory, None);
            }
        }
    }
}

/// A buffer of `size` bytes for `usage`, bound to memory of the type `pick` finds among those the
/// buffer allows (`lacking` where there is none): a slot's code buffer and its shifts buffer.
/// Nothing is left behind on failure.
///
/// # Safety
/// `own` must belong to a live device.
unsafe fn bound_buffer(
    own: &Own,
    size: vk::DeviceSize,
    usage: vk::BufferUsageFlags,
    pick: fn(&Own, u32) -> Option<u32>,
    lacking: vk::Result,
) -> Result<(vk::Buffer, vk::DeviceMemory), vk::Result> {
    let d = &own.fns;
    // SAFETY: the layer's own objects on a live device; each is destroyed again on failure.
    unsafe {
        let buffer = d.create_buffer(
            &vk::BufferCreateInfo::default()
                .size(size)
                .usage(usage)
                .sharing_mode(vk::SharingMode::EXCLUSIVE),
            None,
        )?;
        let req = d.get_buffer_memory_requirements(buffer);
        let bound = own.bound_memory(req, pick, lacking, |memory| {
            d.bind_buffer_memory(buffer, memory, 0)
        });
        if bound.is_err() {
            d.destroy_buffer(buffer, None);
        }
        Ok((buffer, bound?))
    }
}
