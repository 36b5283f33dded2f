//! The GPU converter of application-written density maps ([`crate::vk::convert`] says when it
//! runs): per emulating device its pipeline, layouts and descriptor pools, what it knows of the
//! device's maps, views, rewritten passes and framebuffers, per map a sampled view, per command
//! buffer its [`Conversion`] (a code buffer and a descriptor set per map it converts, [`Slot`]),
//! and the commands a conversion records into the application's command buffer.
//!
//! Who owns what (docs/ARCHITECTURE.md#who-owns-what): the device record owns its converter
//! ([`Emulation::converter`](crate::vk::registry::Emulation::converter)); each command buffer's
//! record owns its [`Conversion`], which holds the converter it was made from and the slots it
//! made with it. Only a [`Conversion`] makes, hands out and destroys slots, always with its own
//! converter, so a slot cannot reach another command buffer, pool or device, nor outlive the
//! command buffer's record.

use std::collections::HashMap;
use std::hash::BuildHasherDefault;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

use ash::vk;
use ash::vk::Handle as _;

use crate::bridge::FdmEmulation;
use crate::vk::base::ffi::AddressHasher;
use crate::vk::base::next::DeviceNext;
use crate::vk::own::bindings::{restore, Bound};
use crate::vk::own::calls::Own;
use crate::vk::own::convert_shader::{table, Push, GROUP, POOL_SETS, SHADER, SHIFT_BYTES};
use crate::vk::own::shadows::ShadowImage;
use crate::vk::translate::formats::SHADOW_LAYOUT;

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
/// each pass instance has shifts of its own, fixed with the recording. Owned by the command
/// buffer's [`Conversion`], which alone makes and destroys slots, so command buffers that may run
/// at once (on two queues, with `SIMULTANEOUS_USE`, primaries executing secondaries that convert)
/// share no buffer the conversion writes; made at a command buffer's first conversion of the map
/// and kept across its recordings, so recording allocates nothing in steady state; destroyed when
/// the command buffer is freed or its pool or device destroyed, none of which may happen while it
/// is pending, or when the command buffer begins again after its map was destroyed
/// ([`Conversion::begun`]).
#[derive(Clone, Copy, Debug)]
struct Slot {
    image: u64,
    /// The [`SourceAndShadow::generation`] of the map whose view its set names and whose size its
    /// code buffer has.
    generation: u64,
    buffer: vk::Buffer,
    memory: vk::DeviceMemory,
    shifts: vk::Buffer,
    shifts_memory: vk::DeviceMemory,
    /// `shifts_memory` mapped, host-coherent, for the life of the slot: [`SHIFT_BYTES`] bytes.
    shifts_at: *mut u8,
    set: vk::DescriptorSet,
    pool: vk::DescriptorPool,
    /// The recording of its command buffer that last used it ([`Bound::recording`]).
    used_in: u64,
}

// SAFETY: `shifts_at` points at memory the slot owns; it is written only by the thread recording
// the slot's command buffer, which the application synchronises.
unsafe impl Send for Slot {}

impl Slot {
    /// Writes the shader's shifts ([`write_shifts`]).
    ///
    /// # Safety
    /// As [`write_shifts`].
    unsafe fn write_shifts(&self, shifts: &[[i32; 2]]) {
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
struct MapEntry {
    shadow: ShadowImage,
    objects: Option<SourceAndShadow>,
    /// Created with `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT`.
    offsets: bool,
}

/// Words of [`Converter::framebuffer_filter`] and of the conversion's filter of passes that write
/// maps (`crate::vk::convert`).
pub const FILTER_WORDS: usize = 64;

/// The filter word and bit of a handle (12 bits of a multiplicative hash).
pub fn filter_slot(handle: u64) -> (usize, u64) {
    let h = ((handle ^ (handle >> 29)).wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 52) as usize;
    (h / 64, 1 << (h % 64))
}

/// Per emulating device, owned by its record
/// ([`Emulation::converter`](crate::vk::registry::Emulation::converter)): the conversion's
/// objects and what the begin hooks look up. Its tables are the device's own, so a look-up never
/// finds another device's map, view, pass or framebuffer, and they go with the device.
pub struct Converter {
    own: Arc<Own>,
    set_layout: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    table: [u32; 4],
    /// The density (and shading-rate) texel, in pixels: offsets are shifts by whole ones.
    texel: [u32; 2],
    /// Leaf locks (outside [`crate::common::lock::Rank`]'s order): held for a look-up or an
    /// insertion, with nothing called under them but the layer's own object creation.
    pools: parking_lot::Mutex<Vec<vk::DescriptorPool>>,
    /// Application density image → its shadow, and its objects once a view of it exists (the
    /// image has memory then: a view of an image without is invalid,
    /// <https://registry.khronos.org/vulkan/specs/latest/man/html/VkImageViewCreateInfo.html>,
    /// VUID-VkImageViewCreateInfo-image-01020).
    maps: parking_lot::Mutex<HashMap<u64, MapEntry>>,
    /// Application view → its image, for views of converted images.
    views: parking_lot::Mutex<HashMap<u64, u64>>,
    /// Rewritten render pass → its density attachment's `initialLayout` and `finalLayout`, as the
    /// driver knows them (the density layout is `GENERAL` there), and whether the application
    /// named the density layout itself as the initial one.
    passes: parking_lot::Mutex<HashMap<u64, (vk::ImageLayout, vk::ImageLayout, bool)>>,
    /// Framebuffers of rewritten passes → their density view, looked up at every render-pass
    /// begin whose framebuffer passes [`Converter::framebuffer_filter`]. A leaf lock of the
    /// device's, read-mostly.
    framebuffers: parking_lot::RwLock<HashMap<u64, u64, BuildHasherDefault<AddressHasher>>>,
    /// One bit per hash slot ([`filter_slot`]), set for every framebuffer ever entered (never
    /// cleared: a stale bit only costs the table look-up). A clear bit proves the framebuffer is
    /// not in the table, so a begin of a pass without a density map costs one atomic load here.
    framebuffer_filter: [AtomicU64; FILTER_WORDS],
    logged_layout: AtomicBool,
    logged_state: AtomicBool,
    logged_conditional: AtomicBool,
    /// Advanced (after the entry is gone from [`Converter::maps`]) whenever one of the device's
    /// maps is destroyed: a command buffer whose slots were checked at the current value holds
    /// no slot of a dead map ([`Conversion::begun`]).
    maps_destroyed: AtomicU64,
}

/// The descriptor set layout's bindings: the map's sampled view, the code buffer, the shifts.
const BINDINGS: [(u32, vk::DescriptorType); 3] = [
    (0, vk::DescriptorType::SAMPLED_IMAGE),
    (1, vk::DescriptorType::STORAGE_BUFFER),
    (2, vk::DescriptorType::STORAGE_BUFFER),
];

impl Converter {
    /// # Safety
    /// `own` must belong to a live device emulating as `fdm` says.
    pub unsafe fn new(own: Arc<Own>, fdm: &FdmEmulation) -> Result<Converter, vk::Result> {
        let code = ash::util::read_spv(&mut std::io::Cursor::new(SHADER))
            .map_err(|_| vk::Result::ERROR_INITIALIZATION_FAILED)?;
        // SAFETY: as the caller promised.
        let (set_layout, layout, pipeline) = unsafe { pipeline(&own.fns, &code) }?;
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
            framebuffers: parking_lot::RwLock::new(HashMap::with_hasher(BuildHasherDefault::new())),
            framebuffer_filter: [const { AtomicU64::new(0) }; FILTER_WORDS],
            logged_layout: AtomicBool::new(false),
            logged_state: AtomicBool::new(false),
            logged_conditional: AtomicBool::new(false),
            maps_destroyed: AtomicU64::new(0),
        })
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
    unsafe fn allocate_set(&self) -> Result<(vk::DescriptorSet, vk::DescriptorPool), vk::Result> {
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
    unsafe fn make_map(
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
    unsafe fn make_slot(&self, image: u64, m: &SourceAndShadow) -> Result<Slot, vk::Result> {
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
            d.update_descriptor_sets(&set_writes(set, m.view, buffer, shifts.0).writes(), &[]);
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
    unsafe fn destroy_slots(&self, slots: &[Slot]) {
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

/// What a slot's descriptor set names ([`BINDINGS`]): the map's view, the code buffer, the shifts.
struct SetWrites {
    set: vk::DescriptorSet,
    image: [vk::DescriptorImageInfo; 1],
    codes: [vk::DescriptorBufferInfo; 1],
    shifts: [vk::DescriptorBufferInfo; 1],
}

fn set_writes(
    set: vk::DescriptorSet,
    view: vk::ImageView,
    codes: vk::Buffer,
    shifts: vk::Buffer,
) -> SetWrites {
    let whole = |buffer| vk::DescriptorBufferInfo {
        buffer,
        offset: 0,
        range: vk::WHOLE_SIZE,
    };
    SetWrites {
        set,
        image: [vk::DescriptorImageInfo {
            sampler: vk::Sampler::null(),
            image_view: view,
            image_layout: vk::ImageLayout::GENERAL,
        }],
        codes: [whole(codes)],
        shifts: [whole(shifts)],
    }
}

impl SetWrites {
    fn writes(&self) -> [vk::WriteDescriptorSet<'_>; 3] {
        let write = |(binding, ty): (u32, vk::DescriptorType)| {
            vk::WriteDescriptorSet::default()
                .dst_set(self.set)
                .dst_binding(binding)
                .descriptor_type(ty)
        };
        [
            write(BINDINGS[0]).image_info(&self.image),
            write(BINDINGS[1]).buffer_info(&self.codes),
            write(BINDINGS[2]).buffer_info(&self.shifts),
        ]
    }
}

/// The conversion's descriptor set layout, pipeline layout and compute pipeline, made from the
/// shader `code` on the device `d`. Nothing is left behind on failure.
///
/// # Safety
/// `d` must be a live device.
unsafe fn pipeline(
    d: &ash::Device,
    code: &[u32],
) -> Result<(vk::DescriptorSetLayout, vk::PipelineLayout, vk::Pipeline), vk::Result> {
    let bindings = BINDINGS.map(|(binding, ty)| {
        vk::DescriptorSetLayoutBinding::default()
            .binding(binding)
            .descriptor_type(ty)
            .descriptor_count(1)
            .stage_flags(vk::ShaderStageFlags::COMPUTE)
    });
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
        let made = d
            .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(code), None)
            .and_then(|module| {
                let stage = vk::PipelineShaderStageCreateInfo::default()
                    .stage(vk::ShaderStageFlags::COMPUTE)
                    .module(module)
                    .name(c"main");
                let info = [vk::ComputePipelineCreateInfo::default()
                    .stage(stage)
                    .layout(layout)];
                let made = d.create_compute_pipelines(vk::PipelineCache::null(), &info, None);
                d.destroy_shader_module(module, None);
                made.map(|p| p[0]).map_err(|(_, e)| e)
            });
        match made {
            Ok(pipeline) => Ok((set_layout, layout, pipeline)),
            Err(e) => {
                d.destroy_pipeline_layout(layout, None);
                d.destroy_descriptor_set_layout(set_layout, None);
                Err(e)
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

// ---------------------------------------------------------------------------------------------
// What the converter knows of its device's maps, views, passes and framebuffers.

impl Converter {
    /// A density image of the device just got its shadow; its objects are made with its first
    /// view ([`Converter::view_changed`]).
    pub fn map_created(&self, app: vk::Image, shadow: &ShadowImage, offsets: bool) {
        let entry = MapEntry {
            shadow: *shadow,
            objects: None,
            offsets,
        };
        self.maps.lock().insert(app.as_raw(), entry);
    }

    /// The application destroyed a density image: its sampled view goes, and command buffers drop
    /// their slots of it at their next begin ([`Conversion::begun`]).
    ///
    /// # Safety
    /// The device must be live; the application's uses of `app` have ended.
    pub unsafe fn map_destroyed(&self, app: vk::Image) {
        let m = self.maps.lock().remove(&app.as_raw());
        self.maps_destroyed.fetch_add(1, Ordering::Release);
        if let Some(MapEntry {
            objects: Some(m), ..
        }) = m
        {
            // SAFETY: every command buffer that used it used the application's image, which the
            // application no longer uses; command buffers' sets naming it are never bound again
            // (a slot is matched by its map's generation, `Conversion::slot`) and go with their
            // slots.
            unsafe { self.own.fns.destroy_image_view(m.view, None) };
        }
    }

    /// Notes an application view of a density image (`Some`) or its destruction (`None`); the
    /// image's objects are made with its first view.
    ///
    /// # Safety
    /// The device must be live, `image` (where `Some`) a live image of it with memory.
    pub unsafe fn view_changed(&self, view: vk::ImageView, image: Option<vk::Image>) {
        let Some(i) = image else {
            self.views.lock().remove(&view.as_raw());
            return;
        };
        let mut maps = self.maps.lock();
        let Some(entry) = maps.get_mut(&i.as_raw()) else {
            return;
        };
        if entry.objects.is_none() {
            // SAFETY: the application's live image, with memory now (it has a view).
            match unsafe { self.make_map(i, &entry.shadow, entry.offsets) } {
                Ok(m) => entry.objects = Some(m),
                Err(e) => {
                    tracing::warn!(
                        image = i.as_raw(),
                        result = ?e,
                        "no conversion for a density map the application writes: passes with it \
                         render at full rate"
                    );
                    return;
                }
            }
        }
        drop(maps);
        self.views.lock().insert(view.as_raw(), i.as_raw());
    }

    /// Notes a rewritten render pass's density attachment `initialLayout` and `finalLayout` as the
    /// driver gets them, and whether the application named the density layout as the initial one
    /// (`Some`), or its destruction.
    pub fn pass_changed(
        &self,
        pass: vk::RenderPass,
        layouts: Option<(vk::ImageLayout, vk::ImageLayout, bool)>,
    ) {
        let mut passes = self.passes.lock();
        match layouts {
            Some(l) => passes.insert(pass.as_raw(), l),
            None => passes.remove(&pass.as_raw()),
        };
    }

    /// Notes a framebuffer of a rewritten pass and its density view (`Some`; `None` forgets it).
    pub fn framebuffer_changed(&self, fb: vk::Framebuffer, view: Option<vk::ImageView>) {
        let mut fbs = self.framebuffers.write();
        match view {
            Some(v) => {
                let (word, bit) = filter_slot(fb.as_raw());
                self.framebuffer_filter[word].fetch_or(bit, Ordering::Release);
                fbs.insert(fb.as_raw(), v.as_raw())
            }
            None => fbs.remove(&fb.as_raw()),
        };
    }

    /// The density view of a framebuffer of a rewritten pass: one atomic load for a framebuffer
    /// the filter has never seen, else a read of the device's table.
    #[inline]
    pub fn framebuffer_view(&self, fb: vk::Framebuffer) -> Option<u64> {
        let (word, bit) = filter_slot(fb.as_raw());
        if self.framebuffer_filter[word].load(Ordering::Acquire) & bit == 0 {
            return None;
        }
        self.framebuffers.read().get(&fb.as_raw()).copied()
    }

    /// The application image a view shows and its conversion objects, if it is a converted map.
    fn map_of_view(&self, view: u64) -> Option<(u64, SourceAndShadow)> {
        let image = self.views.lock().get(&view).copied()?;
        let m = self.maps.lock().get(&image).and_then(|e| e.objects)?;
        Some((image, m))
    }
}

/// Whether a density map in `layout` (as the application names it) is readable as `GENERAL`:
/// the density layout becomes `GENERAL` on the application's image (`crate::vk::translate::sync`).
fn readable(layout: vk::ImageLayout) -> bool {
    layout == vk::ImageLayout::GENERAL
        || layout == vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT
}

// ---------------------------------------------------------------------------------------------
// One command buffer's conversions.

/// The application's command buffer a conversion is recorded into, with what the layer keeps for
/// it: its compute bindings, which the conversion gives back after its dispatch, and the next
/// layer's table (the conversion suspends the application's conditional rendering around it).
#[derive(Clone, Copy)]
pub struct Recorded<'a> {
    pub cb: vk::CommandBuffer,
    /// The command buffer's bindings, from its record.
    pub bound: &'a parking_lot::Mutex<Bound>,
    /// The next layer's table of the command buffer's device.
    pub next: &'a DeviceNext,
}

/// One command buffer's share of its device's converter: the converter it was allocated under
/// and the slots it converts with ([`Slot`]). Owned by the command buffer's record
/// ([`CbRecord::conversion`](crate::vk::registry::CbRecord::conversion)), made at its
/// allocation; it alone makes, hands out and destroys the command buffer's slots, always with the
/// converter it holds, so a slot is never used by another command buffer, destroyed through
/// another device, or kept past its record. Its slots' lock is the command buffer's own: command
/// buffers are externally synchronised, so it is never contended.
///
/// Dropping it destroys nothing: a record is dropped as it is only where its device is already
/// gone (`crate::vk::registry::device_key_reused`); everywhere else [`Conversion::destroy`] runs
/// first.
pub struct Conversion {
    converter: Arc<Converter>,
    slots: parking_lot::Mutex<Vec<Slot>>,
    /// The converter's [`Converter::maps_destroyed`] when `slots` last lost their dead maps'
    /// slots ([`Conversion::begun`]).
    swept: AtomicU64,
}

impl Conversion {
    /// A command buffer's conversions under `converter`, with no slot yet.
    pub fn new(converter: Arc<Converter>) -> Conversion {
        Conversion {
            converter,
            slots: parking_lot::Mutex::new(Vec::new()),
            swept: AtomicU64::new(0),
        }
    }

    /// `vkBeginCommandBuffer`: where one of the device's maps was destroyed since the command
    /// buffer was last checked, its slots of dead maps are destroyed (their sets name destroyed
    /// views, and a map recreated with the same handles gets slots of its own,
    /// [`Conversion::slot`]), so that a command buffer re-recorded across many recreations keeps
    /// one slot per live map. The command buffer is not pending
    /// (VUID-vkBeginCommandBuffer-commandBuffer-00049), so none of its slots is in use. In steady
    /// state one atomic load.
    pub fn begun(&self) {
        let c = &*self.converter;
        let now = c.maps_destroyed.load(Ordering::Acquire);
        if self.swept.load(Ordering::Relaxed) == now {
            return;
        }
        self.swept.store(now, Ordering::Relaxed);
        let dead: Vec<Slot> = {
            let mut slots = self.slots.lock();
            if slots.is_empty() {
                return;
            }
            let maps = c.maps.lock();
            let live = |s: &Slot| {
                maps.get(&s.image)
                    .and_then(|e| e.objects)
                    .is_some_and(|o| o.generation == s.generation)
            };
            let dead = slots.iter().filter(|s| !live(s)).copied().collect();
            slots.retain(live);
            dead
        };
        // SAFETY: the converter's own slots, of a command buffer that is not pending (above).
        unsafe { c.destroy_slots(&dead) };
    }

    /// Destroys every slot: the command buffer is being freed, with its pool or its device.
    ///
    /// # Safety
    /// The device must be live and the command buffer not pending.
    pub unsafe fn destroy(&self) {
        let slots = std::mem::take(&mut *self.slots.lock());
        // SAFETY: as the caller promised; the slots were made with this converter.
        unsafe { self.converter.destroy_slots(&slots) };
    }

    /// In front of a rewritten render pass `pass` whose density attachment is the application's
    /// `view`: the application's image makes the pass's `initialLayout` → `finalLayout`
    /// transition the driver's pass no longer makes (the shadow stands in for the image there), so
    /// the layouts the application's later barriers name are the image's; and the map is
    /// converted in whichever of the two layouts it can be read, in the order that reads it there.
    /// A map whose content the transition discards (`UNDEFINED`) is not converted: its shadow
    /// keeps what it had, which the density map's undefined content allows. `epoch`: the
    /// conversion's `MAP_EPOCH` now (`crate::vk::convert`). Returns, for a map that takes offsets,
    /// where its shifts are and their texel.
    ///
    /// # Safety
    /// `at.cb` must be recording, outside a render pass, on this conversion's device.
    pub unsafe fn convert_for_pass(
        &self,
        at: Recorded<'_>,
        pass: vk::RenderPass,
        view: u64,
        epoch: u64,
    ) -> Option<(usize, [u32; 2])> {
        let c = &*self.converter;
        let (initial, last, density_initial) = c.passes.lock().get(&pass.as_raw()).copied()?;
        let (image, m) = c.map_of_view(view)?;
        let discarded = matches!(
            initial,
            vk::ImageLayout::UNDEFINED | vk::ImageLayout::PREINITIALIZED
        );
        let before = readable(initial);
        let mut shifts = None;
        if before {
            let unchanged = density_initial && initial == last;
            // SAFETY: as the caller promised.
            shifts = unsafe { self.convert(at, image, &m, true, unchanged, epoch) };
        }
        if initial != last {
            // SAFETY: as the caller promised; the application's image, whole.
            unsafe { c.transition(at.cb, image, &m.shadow, initial, last) };
        }
        if !before {
            let readable = !discarded && readable(last);
            // SAFETY: as the caller promised.
            shifts = unsafe { self.convert(at, image, &m, readable, false, epoch) };
        }
        shifts
    }

    /// In front of a dynamic rendering whose density map is the application's `view` in `layout`:
    /// [`Conversion::convert`] where it is a converted map.
    ///
    /// # Safety
    /// As [`Conversion::convert_for_pass`].
    pub unsafe fn convert_for_rendering(
        &self,
        at: Recorded<'_>,
        view: u64,
        layout: vk::ImageLayout,
        epoch: u64,
    ) -> Option<(usize, [u32; 2])> {
        let (image, m) = self.converter.map_of_view(view)?;
        let fdm = layout == vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT;
        // SAFETY: as the caller promised.
        unsafe { self.convert(at, image, &m, readable(layout), fdm, epoch) }
    }

    /// Records the conversion of the application's map `image` into its shadow, where `readable`
    /// (its layout at this point is `GENERAL`). `in_density_layout`: the application names the map
    /// in the density layout itself here, which nothing can write in, so a change since an earlier
    /// conversion in this command buffer had to move it back into that layout, which the layer
    /// sees (`MAP_EPOCH`, `epoch` now); only then may the conversion be skipped, and never for a
    /// map that takes offsets, whose passes each shift it by their own. Returns, for such a map,
    /// the shifts the conversion reads (zero until the pass's end writes them,
    /// `crate::vk::convert::ended`) and their texel.
    ///
    /// # Safety
    /// As [`Conversion::convert_for_pass`].
    unsafe fn convert(
        &self,
        at: Recorded<'_>,
        image: u64,
        m: &SourceAndShadow,
        readable: bool,
        in_density_layout: bool,
        epoch: u64,
    ) -> Option<(usize, [u32; 2])> {
        let c = &*self.converter;
        let bound = c.convertible(at, image, m, readable, in_density_layout, epoch)?;
        // SAFETY: as the caller promised.
        let slot = unsafe { self.slot(at, image, m, bound.recording) }?;
        // This pass instance's offsets are (0, 0) until its end says otherwise.
        // SAFETY: the slot's own shifts; `cb` is recording.
        unsafe { slot.write_shifts(&[]) };
        let suspend = Suspension::of(&bound, at.next);
        // SAFETY: as the caller promised: the application's condition is active.
        unsafe { suspend.end(at.cb) };
        // SAFETY: as the caller promised, with this converter's slot of a live map.
        unsafe { c.record(at.cb, &slot, &m.shadow, &bound) };
        {
            let mut b = at.bound.lock();
            b.converted.rotate_right(1);
            b.converted[0] = (image, epoch);
        }
        // SAFETY: as above: the application's condition again, as it began it.
        unsafe { suspend.begin(at.cb) };
        m.offsets.then_some((slot.shifts_at as usize, c.texel))
    }

    /// The command buffer's slot for the map `m` of `image` in recording `recording`: one it
    /// converted the map with before (for a map that takes offsets, one that no conversion of this
    /// recording took yet, so that each pass instance has shifts of its own), or a new one (slots
    /// made for an earlier image with the same handle are replaced). A slot is the map's when it
    /// carries the map's generation: the image's and the converter view's handles may both be a
    /// destroyed map's, reused by the driver.
    ///
    /// # Safety
    /// The device must be live, `m` this converter's objects of a live map, `at.cb` recording.
    unsafe fn slot(
        &self,
        at: Recorded<'_>,
        image: u64,
        m: &SourceAndShadow,
        recording: u64,
    ) -> Option<Slot> {
        if let Some(known) = self.known_slot(at, image, m, recording) {
            return Some(known);
        }
        let c = &*self.converter;
        // SAFETY: as the caller promised.
        match unsafe { c.make_slot(image, m) } {
            Ok(mut slot) => {
                slot.used_in = recording;
                let stale: Vec<Slot> = {
                    let mut slots = self.slots.lock();
                    let gone = |s: &Slot| s.image == image && s.generation != m.generation;
                    let stale = slots.iter().filter(|s| gone(s)).copied().collect();
                    slots.retain(|s| !gone(s));
                    slots.push(slot);
                    stale
                };
                // SAFETY: slots of a view destroyed with its image; the command buffer is
                // recording, so none of its earlier recordings is pending.
                unsafe { c.destroy_slots(&stale) };
                Some(slot)
            }
            Err(e) => {
                if !c.logged_state.swap(true, Ordering::Relaxed) {
                    tracing::warn!(
                        image = image,
                        result = ?e,
                        "no code buffer for a density-map conversion: the pass renders with what \
                         the shadow holds"
                    );
                }
                None
            }
        }
    }

    /// A slot of the command buffer for the map, free in this recording: a recording takes its
    /// slots in the order the previous one did, so the search starts after the last one taken and
    /// a recording of many passes finds each at once.
    fn known_slot(
        &self,
        at: Recorded<'_>,
        image: u64,
        m: &SourceAndShadow,
        recording: u64,
    ) -> Option<Slot> {
        let mut slots = self.slots.lock();
        let mut b = at.bound.lock();
        let n = slots.len();
        let start = b.next_slot.min(n);
        let i = (start..n).chain(0..start).find(|&i| {
            let s = &slots[i];
            s.image == image
                && s.generation == m.generation
                && (!m.offsets || s.used_in != recording)
        })?;
        b.next_slot = i + 1;
        slots[i].used_in = recording;
        Some(slots[i])
    }
}

/// The application's conditional rendering around a conversion: conditional rendering discards
/// dispatches but not copies
/// (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#drawing-conditional-rendering>),
/// so the conversion runs outside it, since the pass reads the map whatever the condition. The
/// begin hooks run outside any render pass, where a condition begun outside one may end and begin
/// again (VUID-vkCmdEndConditionalRenderingEXT-None-01986).
struct Suspension(
    Option<(
        (vk::Buffer, u64, vk::ConditionalRenderingFlagsEXT),
        vk::PFN_vkCmdEndConditionalRenderingEXT,
        vk::PFN_vkCmdBeginConditionalRenderingEXT,
    )>,
);

impl Suspension {
    /// The condition active in a command buffer with bindings `bound`, where the next layer can
    /// end and begin it.
    fn of(bound: &Bound, next: &DeviceNext) -> Suspension {
        Suspension(bound.conditional.and_then(|c| {
            Some((
                c,
                next.cmd_end_conditional_rendering_ext?,
                next.cmd_begin_conditional_rendering_ext?,
            ))
        }))
    }

    /// # Safety
    /// `cb` must be the recording command buffer whose condition this is, outside a render pass.
    unsafe fn end(&self, cb: vk::CommandBuffer) {
        if let Some((_, end, _)) = self.0 {
            // SAFETY: the next layer's command, on the application's recording command buffer
            // whose condition is active.
            unsafe { end(cb) };
        }
    }

    /// # Safety
    /// As [`Suspension::end`], after it.
    unsafe fn begin(&self, cb: vk::CommandBuffer) {
        if let Some(((buffer, offset, flags), _, begin)) = self.0 {
            let info = vk::ConditionalRenderingBeginInfoEXT::default()
                .buffer(buffer)
                .offset(offset)
                .flags(flags);
            // SAFETY: the application's condition again, as it began it.
            unsafe { begin(cb, &info) };
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The commands a conversion records.

impl Converter {
    /// Whether a conversion of the map `image` is recorded here, and the command buffer's bindings
    /// to give back after it (see [`Conversion::convert`]); where it is not for a reason the
    /// application should know, the log says so once.
    fn convertible(
        &self,
        at: Recorded<'_>,
        image: u64,
        m: &SourceAndShadow,
        readable: bool,
        in_density_layout: bool,
        epoch: u64,
    ) -> Option<Bound> {
        if !readable {
            if !self.logged_layout.swap(true, Ordering::Relaxed) {
                tracing::warn!(
                    image = image,
                    "a pass reads a density map the application writes from a layout other than \
                     GENERAL or the density-map layout: not converted, it renders at full rate"
                );
            }
            return None;
        }
        let Some(bound) = Some(*at.bound.lock()).filter(|b| !b.lost) else {
            if !self.logged_state.swap(true, Ordering::Relaxed) {
                tracing::warn!(
                    image = image,
                    "a command buffer whose compute bindings the layer cannot give back (push \
                     descriptors, or more sets, dynamic offsets or push-constant ranges than it \
                     records): its passes' density maps are not converted, they render at full rate"
                );
            }
            return None;
        };
        if in_density_layout && !m.offsets && bound.converted.contains(&(image, epoch)) {
            // Converted earlier in this command buffer, and nothing since may have changed it.
            return None;
        }
        if bound.inherited_conditional {
            if !self.logged_conditional.swap(true, Ordering::Relaxed) {
                tracing::warn!(
                    image = image,
                    "a secondary command buffer that inherits conditional rendering begins a \
                     pass with a density map the application writes: the layer cannot suspend \
                     the condition there (its dispatch would be skipped when its copy is not), so \
                     the map is not converted and its shadow keeps what it had"
                );
            }
            return None;
        }
        Some(bound)
    }

    /// Records a layout transition of the application's image, ordered after everything before
    /// it and before everything after it (a render pass's own transitions are ordered by its
    /// external dependencies, which the application made for the pass's use of the map).
    ///
    /// # Safety
    /// `cb` must be recording, outside a render pass, on this converter's device.
    unsafe fn transition(
        &self,
        cb: vk::CommandBuffer,
        image: u64,
        shadow: &ShadowImage,
        old: vk::ImageLayout,
        new: vk::ImageLayout,
    ) {
        let barrier = vk::ImageMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
            .dst_access_mask(vk::AccessFlags::MEMORY_READ | vk::AccessFlags::MEMORY_WRITE)
            .old_layout(old)
            .new_layout(new)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(vk::Image::from_raw(image))
            .subresource_range(colour_layers(shadow.app_layers.max(1)));
        // SAFETY: as the caller promised.
        unsafe {
            self.own.fns.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[barrier],
            );
        }
    }

    /// Records the conversion itself with `slot`: the dispatch writing the shadow `s`'s codes
    /// ([`Converter::dispatch`]), their copy into the shadow ([`Converter::copy`]), and the
    /// application's compute bindings `bound` again.
    ///
    /// # Safety
    /// `cb` must be recording, outside a render pass, on this converter's device; `slot` a slot
    /// made with this converter for the live map shadowed by `s`.
    unsafe fn record(&self, cb: vk::CommandBuffer, slot: &Slot, s: &ShadowImage, bound: &Bound) {
        // SAFETY: as the caller promised.
        unsafe {
            self.dispatch(cb, slot, s);
            self.copy(cb, slot, s);
            restore(&self.own.fns, cb, bound);
        }
    }

    /// Whatever wrote the map comes before the dispatch reads it, and whatever read this command
    /// buffer's code buffer (an earlier conversion's copy) before the dispatch writes it
    /// (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#synchronization-dependencies>):
    /// the application's own dependency into the density layout made its writes available. The
    /// shadow's old content is discarded (UNDEFINED) once earlier passes' shading-rate reads are
    /// done, ready for the copy. ALL_COMMANDS stands in for the unknown writer and for the
    /// shading-rate stage, which validation 1.3.239 refuses without NVIDIA's shading-rate-image
    /// feature (docs/vulkan-fdm-on-fsr.md#shadows). Then the dispatch that writes the codes.
    ///
    /// # Safety
    /// As [`Converter::record`].
    unsafe fn dispatch(&self, cb: vk::CommandBuffer, slot: &Slot, s: &ShadowImage) {
        let d = &self.own.fns;
        let merged = s.layers == 1 && s.app_layers > 1;
        let push = Push {
            width: s.extent.width,
            height: s.extent.height,
            layers: s.app_layers.max(1),
            merged: u32::from(merged),
            table: self.table,
        };
        let codes = u64::from(s.extent.width) * u64::from(s.extent.height) * u64::from(s.layers);
        let groups =
            u32::try_from(codes.div_ceil(4).div_ceil(u64::from(GROUP))).unwrap_or(u32::MAX);
        let discard = shadow_barrier(
            s,
            (
                vk::ImageLayout::UNDEFINED,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            ),
            (vk::AccessFlags::empty(), vk::AccessFlags::TRANSFER_WRITE),
        );
        // SAFETY: the next layer's commands on the application's recording command buffer, with
        // the layer's own objects; outside a render pass, as the begin hooks are.
        unsafe {
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[vk::MemoryBarrier::default()
                    .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
                    .dst_access_mask(vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE)],
                &[],
                &[discard],
            );
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, self.pipeline);
            d.cmd_bind_descriptor_sets(
                cb,
                vk::PipelineBindPoint::COMPUTE,
                self.layout,
                0,
                &[slot.set],
                &[],
            );
            let stage = vk::ShaderStageFlags::COMPUTE;
            d.cmd_push_constants(cb, self.layout, stage, 0, &push.bytes());
            d.cmd_dispatch(cb, groups, 1, 1);
        }
    }

    /// The codes, from the dispatch to the copy (exactly those stages), copied into the shadow,
    /// and the shadow from the copy to the pass's shading-rate read in the shading-rate layout
    /// (ALL_COMMANDS for the shading-rate stage, as in [`Converter::dispatch`]).
    ///
    /// # Safety
    /// As [`Converter::record`].
    unsafe fn copy(&self, cb: vk::CommandBuffer, slot: &Slot, s: &ShadowImage) {
        let d = &self.own.fns;
        let codes = vk::BufferMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE)
            .dst_access_mask(vk::AccessFlags::TRANSFER_READ)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .buffer(slot.buffer)
            .offset(0)
            .size(vk::WHOLE_SIZE);
        let region = vk::BufferImageCopy {
            buffer_offset: 0,
            buffer_row_length: 0,
            buffer_image_height: 0,
            image_subresource: vk::ImageSubresourceLayers {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                mip_level: 0,
                base_array_layer: 0,
                layer_count: s.layers,
            },
            image_offset: vk::Offset3D::default(),
            image_extent: vk::Extent3D {
                width: s.extent.width,
                height: s.extent.height,
                depth: 1,
            },
        };
        let read = shadow_barrier(
            s,
            (vk::ImageLayout::TRANSFER_DST_OPTIMAL, SHADOW_LAYOUT),
            (
                vk::AccessFlags::TRANSFER_WRITE,
                vk::AccessFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR,
            ),
        );
        let (compute, transfer) = (
            vk::PipelineStageFlags::COMPUTE_SHADER,
            vk::PipelineStageFlags::TRANSFER,
        );
        let none = vk::DependencyFlags::empty();
        let dst = vk::ImageLayout::TRANSFER_DST_OPTIMAL;
        // SAFETY: as in `dispatch`.
        unsafe {
            d.cmd_pipeline_barrier(cb, compute, transfer, none, &[], &[codes], &[]);
            d.cmd_copy_buffer_to_image(cb, slot.buffer, s.image, dst, &[region]);
            let all = vk::PipelineStageFlags::ALL_COMMANDS;
            d.cmd_pipeline_barrier(cb, transfer, all, none, &[], &[], &[read]);
        }
    }
}

/// The first `layers` layers of a colour image's only mip level.
fn colour_layers(layers: u32) -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange {
        aspect_mask: vk::ImageAspectFlags::COLOR,
        base_mip_level: 0,
        level_count: 1,
        base_array_layer: 0,
        layer_count: layers,
    }
}

/// A barrier on the whole shadow `s` from the first to the second of `layouts` and `access`.
fn shadow_barrier(
    s: &ShadowImage,
    (old, new): (vk::ImageLayout, vk::ImageLayout),
    (src, dst): (vk::AccessFlags, vk::AccessFlags),
) -> vk::ImageMemoryBarrier<'static> {
    vk::ImageMemoryBarrier::default()
        .src_access_mask(src)
        .dst_access_mask(dst)
        .old_layout(old)
        .new_layout(new)
        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .image(s.image)
        .subresource_range(colour_layers(s.layers))
}
