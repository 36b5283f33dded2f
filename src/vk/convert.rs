//! Density maps an application writes itself: converted into their shadows on the GPU, inside the
//! application's command buffer, in front of every pass that reads them.
//!
//! fovea's own density images write shading-rate codes into their shadow at upload
//! (`gpu::density_images`). An application's own map is written by the application's commands
//! (copies, draws, dispatches), so its content is known only on the device, when the pass runs. At
//! `vkCmdBeginRenderPass(2)` and `vkCmdBeginRendering` of a pass whose density map is such an image,
//! the layer records, before calling down: a barrier making earlier writes visible to compute
//! (and discarding the shadow's old content once earlier passes read it), a dispatch of
//! `shaders/convert.comp` that reads the map (a layer-owned sampled view) and writes codes into a
//! code buffer the command buffer owns ([`Slot`]), a barrier from that dispatch to a copy of the
//! buffer into the shadow, a barrier handing the shadow to the shading-rate stage in
//! `FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR`, and finally the application's own compute
//! bindings again (docs/vulkan-fdm-on-fsr.md#shadows). The conversion runs at every such pass
//! begin unless the command buffer already converted the map and nothing since may have changed
//! it ([`MAP_EPOCH`]); it runs outside the application's conditional rendering, which would skip
//! the dispatch but not the copy.
//!
//! The byte → code mapping is `fovea_model::shading_rate::fill_codes`; the shader gets everything
//! device-specific (the clamp to `maxFragmentSize` and to the rates
//! `vkGetPhysicalDeviceFragmentShadingRatesKHR` lists) as a 4×4 table of codes indexed by the
//! wanted log2 fragment size, built here at device creation from the model itself.
//!
//! Bound state: a dispatch binds a compute pipeline, a descriptor set and push constants, which
//! persist across passes (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#pipelines-bindpoint-commands>,
//! <https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#descriptorsets-compatibility>).
//! So on emulating devices the layer records per command buffer what the application bound at the
//! compute bind point and every push-constant update ([`Bound`], fixed size, made at
//! `vkBeginCommandBuffer`), and binds it all again after the conversion. Where it cannot (push
//! descriptors, more sets or dynamic offsets than a record holds), that pass's map is not converted
//! and renders at full rate, and the log says so once. Devices with commands that bind compute
//! state the layer does not intercept (Vulkan 1.4, `VK_KHR_maintenance6`, descriptor buffers,
//! shader objects, device-generated commands) convert nothing.
//!
//! Objects: pipeline, layouts and descriptor pools at device creation; per density image a sampled
//! view of it with its first view; per command buffer and map a code buffer and a descriptor set
//! at the command buffer's first conversion of the map; all destroyed with their owners. Nothing is
//! allocated per command in steady state, and no process-wide lock is taken while recording: each
//! thread finds its command buffers' records in a cache of its own ([`record_of`]).

use std::collections::HashMap;
use std::ffi::{c_void, CStr};
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use ash::vk;
use ash::vk::Handle as _;

use crate::bridge::FdmEmulation;
use crate::vk::base::chain;
use crate::vk::base::ffi::{guard, key, raw, Key};
use crate::vk::image::{Own, SHADOW_LAYOUT};
use crate::vk::registry::{self, Device, ShadowImage};

/// The compute shader, built from `shaders/convert.comp` by `shaders/build.sh`.
static SHADER: &[u8] = include_bytes!("shaders/convert.comp.spv");

/// `local_size_x` of the shader; each invocation writes four codes.
const GROUP: u32 = 64;
/// Descriptor sets per pool; a new pool is made when one is full.
const POOL_SETS: u32 = 64;

/// The push constants, as the shader declares them.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Push {
    pub width: u32,
    pub height: u32,
    pub layers: u32,
    pub merged: u32,
    pub table: [u32; 4],
}

impl Push {
    fn bytes(&self) -> [u8; 32] {
        let mut out = [0; 32];
        let words = [
            self.width,
            self.height,
            self.layers,
            self.merged,
            self.table[0],
            self.table[1],
            self.table[2],
            self.table[3],
        ];
        for (o, w) in out.chunks_exact_mut(4).zip(words) {
            o.copy_from_slice(&w.to_ne_bytes());
        }
        out
    }
}

/// A density byte that wants a fragment edge of `2^l` (`fovea_model::shading_rate::axis_size`).
const fn byte_for_log2(l: usize) -> u8 {
    [255, 127, 63, 63][l]
}

/// The shader's table: entry `w * 4 + h` (as byte `i % 4` of word `i / 4`) is the code the model
/// gives a texel that wants a `2^w × 2^h` fragment on this device.
pub fn table(fdm: &FdmEmulation) -> [u32; 4] {
    let mut t = [0u32; 4];
    for w in 0..4 {
        for h in 0..4 {
            let code = fovea_model::shading_rate::fsr_code(
                [byte_for_log2(w), byte_for_log2(h)],
                fdm.max_fragment,
                &fdm.rates,
            );
            let i = w * 4 + h;
            t[i / 4] |= u32::from(code) << ((i % 4) * 8);
        }
    }
    t
}

/// The shader's algorithm on the CPU (one code per output texel): what the tests hold against the
/// model, so the table and the merge order are checked without a GPU.
#[cfg(test)]
fn shader_on_cpu(density: &[u8], push: &Push) -> Vec<u8> {
    let table_at = |w: u32, h: u32| {
        let i = w * 4 + h;
        ((push.table[(i >> 2) as usize] >> ((i & 3) * 8)) & 0xff) as u8
    };
    let axis = |b: u8| match b {
        0 | 128..=255 => 0,
        64..=127 => 1,
        _ => 2,
    };
    let texels = (push.width * push.height) as usize;
    let code_of = |t: usize, l: usize| {
        let i = (l * texels + t) * 2;
        table_at(axis(density[i]), axis(density[i + 1]))
    };
    let total = if push.merged != 0 {
        texels
    } else {
        texels * push.layers as usize
    };
    (0..total)
        .map(|j| {
            if push.merged != 0 {
                let mut c = code_of(j, 0);
                for l in 1..push.layers as usize {
                    let n = code_of(j, l);
                    c = table_at(
                        u32::from(((c >> 2) & 3).min((n >> 2) & 3)),
                        u32::from((c & 3).min(n & 3)),
                    );
                }
                c
            } else {
                code_of(j % texels, j / texels)
            }
        })
        .collect()
}

/// What the layer made for one application density image.
#[derive(Clone, Copy, Debug)]
struct MapObjects {
    /// A sampled 2D-array view of every layer of the application's image.
    view: vk::ImageView,
    shadow: ShadowImage,
}

/// What one command buffer converts one map with: a code buffer the dispatch writes and the copy
/// reads, and a descriptor set naming it and the map's view. Owned by the command buffer's record
/// ([`CbRecord::slots`]), so command buffers that may run at once (on two queues, with
/// `SIMULTANEOUS_USE`, primaries executing secondaries that convert) share no buffer the
/// conversion writes; made at a command buffer's first conversion of the map and kept across its
/// recordings, so recording allocates nothing in steady state; destroyed when the command buffer
/// is freed or its pool or device destroyed, none of which may happen while it is pending.
#[derive(Clone, Copy, Debug)]
struct Slot {
    image: u64,
    view: vk::ImageView,
    buffer: vk::Buffer,
    memory: vk::DeviceMemory,
    set: vk::DescriptorSet,
    pool: vk::DescriptorPool,
}

/// One application density image.
struct MapEntry {
    shadow: ShadowImage,
    objects: Option<MapObjects>,
}

/// Per emulating device: the conversion's objects and what the begin hooks look up.
pub struct Converter {
    own: Arc<Own>,
    set_layout: vk::DescriptorSetLayout,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    table: [u32; 4],
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
    logged_layout: AtomicBool,
    logged_state: AtomicBool,
    logged_conditional: AtomicBool,
}

/// Each converting device's [`Converter`], by dispatch key; a leaf lock like [`crate::vk::image`]'s.
static CONVERTERS: parking_lot::RwLock<Vec<(Key, Arc<Converter>)>> =
    parking_lot::RwLock::new(Vec::new());

/// The converter of a device's (or command buffer's) dispatch key.
///
/// # Safety
/// `handle` must be NULL or a live dispatchable handle made by the loader.
unsafe fn converter(handle: impl vk::Handle) -> Option<Arc<Converter>> {
    // SAFETY: as the caller promised.
    let k = unsafe { key(handle) }?;
    CONVERTERS
        .read()
        .iter()
        .find(|(key, _)| *key == k)
        .map(|(_, c)| Arc::clone(c))
}

/// The converter of a device's dispatch key.
fn converter_by_key(k: Key) -> Option<Arc<Converter>> {
    CONVERTERS
        .read()
        .iter()
        .find(|(key, _)| *key == k)
        .map(|(_, c)| Arc::clone(c))
}

/// Runs `f` with the converter of a command buffer's device, reached through the command
/// buffer's record (this thread's cache: no process-wide lock, no reference count), if the
/// device converts.
fn with_converter<R>(cb: vk::CommandBuffer, f: impl FnOnce(&Converter) -> R) -> Option<R> {
    record_of(cb, |r| r.converter.as_deref().map(f)).flatten()
}

/// Whether a command buffer's device converts.
fn has_converter(cb: vk::CommandBuffer) -> bool {
    record_of(cb, |r| r.converter.is_some()).unwrap_or(false)
}

/// Extensions whose commands bind compute state the layer does not intercept, so it could not
/// give the application its bindings back after a conversion.
const UNTRACKED: &[&CStr] = &[
    c"VK_KHR_maintenance6",
    c"VK_EXT_descriptor_buffer",
    c"VK_EXT_shader_object",
    c"VK_NV_device_generated_commands",
    c"VK_NV_device_generated_commands_compute",
    c"VK_EXT_device_generated_commands",
];

/// Why a device cannot convert, from its create info, or `None` where it can.
///
/// # Safety
/// `ci` must be a valid device create info.
unsafe fn untracked_binds(ci: &vk::DeviceCreateInfo<'_>, api_version: u32) -> Option<String> {
    if api_version >= vk::make_api_version(0, 1, 4, 0) {
        return Some(
            "Vulkan 1.4 binds compute state through commands the layer does not see".into(),
        );
    }
    let names = if ci.pp_enabled_extension_names.is_null() {
        &[][..]
    } else {
        // SAFETY: as the caller promised.
        unsafe {
            std::slice::from_raw_parts(
                ci.pp_enabled_extension_names,
                ci.enabled_extension_count as usize,
            )
        }
    };
    names.iter().find_map(|&p| {
        // SAFETY: enabled extension names are NUL-terminated strings.
        let name = unsafe { CStr::from_ptr(p) };
        UNTRACKED.contains(&name).then(|| {
            format!(
                "{} binds compute state the layer does not see",
                name.to_string_lossy()
            )
        })
    })
}

/// Whether every graphics queue family the device was created with can run compute, which the
/// conversion, recorded into the application's graphics command buffers, needs.
///
/// # Safety
/// As [`device_created`].
unsafe fn graphics_queues_compute(
    inst: &registry::Instance,
    physical: vk::PhysicalDevice,
    ci: &vk::DeviceCreateInfo<'_>,
) -> bool {
    // SAFETY: the next layer's instance command, of the type its name implies.
    let Some(f) = (unsafe {
        (inst.gipa)(
            inst.handle,
            c"vkGetPhysicalDeviceQueueFamilyProperties".as_ptr(),
        )
    }) else {
        return false;
    };
    // SAFETY: as above.
    let f = unsafe {
        std::mem::transmute::<
            unsafe extern "system" fn(),
            vk::PFN_vkGetPhysicalDeviceQueueFamilyProperties,
        >(f)
    };
    let mut n = 0;
    // SAFETY: a two-call query on a live physical device.
    unsafe { f(physical, &mut n, std::ptr::null_mut()) };
    let mut families = vec![vk::QueueFamilyProperties::default(); n as usize];
    // SAFETY: as above.
    unsafe { f(physical, &mut n, families.as_mut_ptr()) };
    families.truncate(n as usize);
    let infos = if ci.p_queue_create_infos.is_null() {
        &[][..]
    } else {
        // SAFETY: as the caller promised.
        unsafe {
            std::slice::from_raw_parts(ci.p_queue_create_infos, ci.queue_create_info_count as usize)
        }
    };
    infos.iter().all(|q| {
        families.get(q.queue_family_index as usize).is_none_or(|f| {
            !f.queue_flags.contains(vk::QueueFlags::GRAPHICS)
                || f.queue_flags.contains(vk::QueueFlags::COMPUTE)
        })
    })
}

/// Sets up conversion on a device just recorded in the registry, or logs why not (its
/// application-written maps then render at full rate).
///
/// # Safety
/// `ci` must be the application's create info of the live device `handle`, made on `physical`.
pub unsafe fn device_created(
    inst: &registry::Instance,
    physical: vk::PhysicalDevice,
    ci: &vk::DeviceCreateInfo<'_>,
    handle: vk::Device,
) {
    // SAFETY: as the caller promised.
    let Some(dev) = (unsafe { registry::device(handle) }) else {
        return;
    };
    let (Some(fdm), Some(own)) = (&dev.fdm, &dev.attachments.own) else {
        return;
    };
    // SAFETY: as the caller promised.
    let why = unsafe { untracked_binds(ci, dev.api_version) }.or_else(|| {
        // SAFETY: as the caller promised.
        (!unsafe { graphics_queues_compute(inst, physical, ci) })
            .then(|| "a graphics queue family without compute".to_owned())
    });
    if let Some(why) = why {
        tracing::warn!(
            device = raw(handle),
            why = why.as_str(),
            "density maps the application writes itself are not converted on this device: they \
             render at full rate"
        );
        return;
    }
    // SAFETY: the layer's own objects on a live device.
    match unsafe { Converter::new(Arc::clone(own), fdm) } {
        Ok(c) => {
            // SAFETY: as the caller promised.
            if let Some(k) = unsafe { key(handle) } {
                let mut v = CONVERTERS.write();
                v.retain(|(key, _)| *key != k);
                v.push((k, Arc::new(c)));
            }
        }
        Err(e) => tracing::warn!(
            device = raw(handle),
            result = ?e,
            "no density-map conversion on this device: maps the application writes itself \
             render at full rate"
        ),
    }
}

/// Destroys a device's conversion objects; the device is about to be destroyed.
///
/// # Safety
/// `handle` must be live and idle.
pub unsafe fn device_destroyed(handle: vk::Device) {
    // SAFETY: as the caller promised.
    let Some(k) = (unsafe { key(handle) }) else {
        return;
    };
    // Command buffers go with their device (and pools) without vkFreeCommandBuffers; their slots
    // go while the converter is still there.
    forget_where(|_, r| r.device == k);
    let c = {
        let mut v = CONVERTERS.write();
        let at = v.iter().position(|(key, _)| *key == k);
        at.map(|i| v.swap_remove(i).1)
    };
    if let Some(c) = c {
        // SAFETY: as the caller promised.
        unsafe { c.destroy() };
    }
    FRAMEBUFFERS.write().retain(|_, (key, _)| *key != k);
}

/// Forgets, without a call to the driver, what the layer kept for a device whose dispatch key a
/// new device now has: the application destroyed the old device's instance with the device still
/// alive (VUID-vkDestroyInstance-instance-00629), the loader freed the device's dispatch table, and
/// the new device got its address. The old device's objects are gone with it; destroying them
/// now would call a driver that no longer has them, so its command buffers' records, its
/// converter and its framebuffers are dropped as they are.
pub fn device_key_reused(k: Key) {
    {
        let mut map = CB_RECORDS.lock();
        let before = map.len();
        map.retain(|_, r| r.device != k);
        if map.len() != before {
            CB_GENERATION.fetch_add(1, Ordering::Release);
        }
    }
    CONVERTERS.write().retain(|(key, _)| *key != k);
    FRAMEBUFFERS.write().retain(|_, (key, _)| *key != k);
}

impl Converter {
    /// # Safety
    /// `own` must belong to a live device emulating as `fdm` says.
    unsafe fn new(own: Arc<Own>, fdm: &FdmEmulation) -> Result<Converter, vk::Result> {
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
            })
        }
    }

    /// # Safety
    /// The device must be live and idle.
    unsafe fn destroy(&self) {
        let d = &self.own.fns;
        let maps: Vec<MapObjects> = self
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
                descriptor_count: POOL_SETS,
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
    ) -> Result<MapObjects, vk::Result> {
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
        Ok(MapObjects {
            view,
            shadow: *shadow,
        })
    }

    /// A command buffer's code buffer and descriptor set for the map `m` of `image` ([`Slot`]).
    ///
    /// # Safety
    /// The device must be live; `m` this converter's objects of a live map.
    unsafe fn make_slot(&self, image: u64, m: &MapObjects) -> Result<Slot, vk::Result> {
        let d = &self.own.fns;
        let shadow = &m.shadow;
        let codes = u64::from(shadow.extent.width)
            * u64::from(shadow.extent.height)
            * u64::from(shadow.layers);
        let size = codes.div_ceil(4).max(1) * 4;
        // SAFETY: the layer's own objects on a live device; each is destroyed again on failure.
        unsafe {
            let buffer = d.create_buffer(
                &vk::BufferCreateInfo::default()
                    .size(size)
                    .usage(
                        vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_SRC,
                    )
                    .sharing_mode(vk::SharingMode::EXCLUSIVE),
                None,
            )?;
            let req = d.get_buffer_memory_requirements(buffer);
            let memory = match self
                .own
                .memory_type(req.memory_type_bits)
                .ok_or(vk::Result::ERROR_OUT_OF_DEVICE_MEMORY)
                .and_then(|ty| {
                    d.allocate_memory(
                        &vk::MemoryAllocateInfo::default()
                            .allocation_size(req.size)
                            .memory_type_index(ty),
                        None,
                    )
                }) {
                Ok(m) => m,
                Err(e) => {
                    d.destroy_buffer(buffer, None);
                    return Err(e);
                }
            };
            let bound = d.bind_buffer_memory(buffer, memory, 0);
            let (set, pool) = match bound.and_then(|()| self.allocate_set()) {
                Ok(s) => s,
                Err(e) => {
                    d.destroy_buffer(buffer, None);
                    d.free_memory(memory, None);
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
            ];
            d.update_descriptor_sets(&writes, &[]);
            Ok(Slot {
                image,
                view: m.view,
                buffer,
                memory,
                set,
                pool,
            })
        }
    }

    /// `cb`'s slot for the map `m` of `image`: the one it converted the map with before, or a new
    /// one (a slot made for an earlier image with the same handle is replaced).
    ///
    /// # Safety
    /// As [`Converter::make_slot`]; `cb` recording on this device.
    unsafe fn slot(&self, cb: vk::CommandBuffer, image: u64, m: &MapObjects) -> Option<Slot> {
        let known = record_of(cb, |r| {
            r.slots
                .lock()
                .iter()
                .find(|s| s.image == image && s.view == m.view)
                .copied()
        })?;
        if known.is_some() {
            return known;
        }
        // SAFETY: as the caller promised.
        match unsafe { self.make_slot(image, m) } {
            Ok(slot) => {
                let stale = record_of(cb, |r| {
                    let mut slots = r.slots.lock();
                    let stale: Vec<Slot> =
                        slots.iter().filter(|s| s.image == image).copied().collect();
                    slots.retain(|s| s.image != image);
                    slots.push(slot);
                    stale
                })
                .unwrap_or_default();
                // SAFETY: slots of a view destroyed with its image; the command buffer is
                // recording, so none of its earlier recordings is pending.
                unsafe { self.destroy_slots(&stale) };
                Some(slot)
            }
            Err(e) => {
                if !self.logged_state.swap(true, Ordering::Relaxed) {
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
            }
        }
    }
}

/// An application density image (not fovea's own) just got its shadow; its conversion objects
/// are made with its first view ([`view_changed`]).
///
/// # Safety
/// `app` must be the live image just created on `dev`, shadowed by `shadow`.
pub unsafe fn map_created(dev: &Device, app: vk::Image, shadow: &ShadowImage) {
    // SAFETY: as the caller promised.
    if let Some(c) = unsafe { converter(dev.handle) } {
        c.maps.lock().insert(
            app.as_raw(),
            MapEntry {
                shadow: *shadow,
                objects: None,
            },
        );
    }
}

/// The application destroyed a density image: its conversion objects go too.
///
/// # Safety
/// `dev` must be live; the application's uses of `app` have ended.
pub unsafe fn map_destroyed(dev: &Device, app: vk::Image) {
    // SAFETY: as the caller promised.
    let Some(c) = (unsafe { converter(dev.handle) }) else {
        return;
    };
    let m = c.maps.lock().remove(&app.as_raw());
    if let Some(MapEntry {
        objects: Some(m), ..
    }) = m
    {
        // SAFETY: every command buffer that used it used the application's image, which the
        // application no longer uses; command buffers' sets naming it are rewritten before they
        // convert another map with this image's handle (`Converter::slot`).
        unsafe { c.own.fns.destroy_image_view(m.view, None) };
    }
}

/// Notes an application view of a density image (`Some`) or its destruction (`None`).
///
/// # Safety
/// `dev` must be live.
pub unsafe fn view_changed(dev: &Device, view: vk::ImageView, image: Option<vk::Image>) {
    // SAFETY: as the caller promised.
    let Some(c) = (unsafe { converter(dev.handle) }) else {
        return;
    };
    let Some(i) = image else {
        c.views.lock().remove(&view.as_raw());
        return;
    };
    let mut maps = c.maps.lock();
    let Some(entry) = maps.get_mut(&i.as_raw()) else {
        return;
    };
    if entry.objects.is_none() {
        // SAFETY: the application's live image, with memory now (it has a view).
        match unsafe { c.make_map(i, &entry.shadow) } {
            Ok(m) => entry.objects = Some(m),
            Err(e) => {
                tracing::warn!(
                    image = raw(i),
                    result = ?e,
                    "no conversion for a density map the application writes: passes with it \
                     render at full rate"
                );
                return;
            }
        }
    }
    drop(maps);
    c.views.lock().insert(view.as_raw(), i.as_raw());
}

/// Notes a framebuffer of a rewritten pass and its density view (`Some`; `None` forgets it).
///
/// # Safety
/// `dev` must be live.
pub unsafe fn framebuffer_changed(dev: &Device, fb: vk::Framebuffer, view: Option<vk::ImageView>) {
    // Only converting devices' framebuffers are looked up at begin.
    // SAFETY: as the caller promised.
    if unsafe { converter(dev.handle) }.is_none() {
        return;
    }
    // SAFETY: as the caller promised.
    let Some(k) = (unsafe { key(dev.handle) }) else {
        return;
    };
    let mut fbs = FRAMEBUFFERS.write();
    if view.is_some() {
        let (word, bit) = filter_slot(fb.as_raw());
        FRAMEBUFFER_FILTER[word].fetch_or(bit, Ordering::Release);
    }
    match view {
        Some(v) => fbs.insert(fb.as_raw(), (k, v.as_raw())),
        None => fbs.remove(&fb.as_raw()),
    };
}

/// A filter in front of [`FRAMEBUFFERS`]: one bit per hash slot, set for every framebuffer ever
/// entered (never cleared: a stale bit only costs the table look-up). A clear bit proves the
/// framebuffer is not in the table, so a begin of a pass without a density map costs one atomic
/// load here.
const FILTER_WORDS: usize = 64;
static FRAMEBUFFER_FILTER: [std::sync::atomic::AtomicU64; FILTER_WORDS] =
    [const { std::sync::atomic::AtomicU64::new(0) }; FILTER_WORDS];

/// The filter word and bit of a framebuffer handle (12 bits of a multiplicative hash).
fn filter_slot(fb: u64) -> (usize, u64) {
    let h = ((fb ^ (fb >> 29)).wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 52) as usize;
    (h / 64, 1 << (h % 64))
}

/// Framebuffers of rewritten passes on converting devices → (device key, density view). One
/// table for all devices, looked up first at every render-pass begin whose framebuffer passes
/// [`FRAMEBUFFER_FILTER`], before any per-device look-up. A leaf lock.
static FRAMEBUFFERS: parking_lot::RwLock<
    HashMap<u64, (Key, u64), BuildHasherDefault<HandleHasher>>,
> = parking_lot::RwLock::new(HashMap::with_hasher(BuildHasherDefault::new()));

/// Advanced whenever the layer sees something that may change an application's density map:
/// a barrier moving an image into the density-map layout, a host-side transition into it, the
/// begin of a render pass that names the density layout, stage or access without reading a map
/// (one that writes or orders one, [`writer_pass_created`]). A conversion recorded in a command
/// buffer at one value is still good for a later pass of the same command buffer that reads the
/// same map at the same value: nothing the application recorded between them made the map change
/// visible to the density-map read, so that pass needs no conversion and no barrier
/// ([`Bound::converted`]). Within one command buffer the order of execution is the order of
/// recording, so this holds however command buffers are submitted.
static MAP_EPOCH: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

/// Notes that an application's density map may have changed (see [`MAP_EPOCH`]).
pub fn map_may_have_changed() {
    MAP_EPOCH.fetch_add(1, Ordering::AcqRel);
}

/// A filter of render passes that write or order density maps (see [`MAP_EPOCH`]): one bit per
/// hash slot, never cleared; a stale or shared bit only costs a conversion.
static WRITER_FILTER: [std::sync::atomic::AtomicU64; FILTER_WORDS] =
    [const { std::sync::atomic::AtomicU64::new(0) }; FILTER_WORDS];

/// A render pass that names the density layout, stage or access but reads no map was created:
/// its begins advance [`MAP_EPOCH`].
pub fn writer_pass_created(pass: vk::RenderPass) {
    let (word, bit) = filter_slot(pass.as_raw());
    WRITER_FILTER[word].fetch_or(bit, Ordering::Release);
}

/// The barrier translation's look-up of a shadow for an image the application moves into the
/// density-map layout (`crate::vk::barrier`). Whether a map may be read is decided by the layout
/// each pass that reads it names, at that pass's recording ([`before_render_pass`],
/// [`before_rendering`]), not by which barriers were recorded before: command buffers may be
/// submitted in another order than they were recorded.
pub fn shadow_of_transitioned(image: vk::Image) -> Option<crate::bridge::Shadow> {
    map_may_have_changed();
    crate::bridge::shadow_of(image)
}

/// Whether a density map in `layout` (as the application names it) is readable as `GENERAL`:
/// the density layout becomes `GENERAL` on the application's image (`crate::vk::barrier`).
fn readable(layout: vk::ImageLayout) -> bool {
    layout == vk::ImageLayout::GENERAL
        || layout == vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT
}

/// Notes a rewritten render pass's density attachment `initialLayout` and `finalLayout` as the
/// driver gets them (`Some`), or its destruction.
///
/// # Safety
/// `dev` must be live.
pub unsafe fn pass_changed(
    dev: &Device,
    pass: vk::RenderPass,
    layouts: Option<(vk::ImageLayout, vk::ImageLayout, bool)>,
) {
    // SAFETY: as the caller promised.
    let Some(c) = (unsafe { converter(dev.handle) }) else {
        return;
    };
    let mut passes = c.passes.lock();
    match layouts {
        Some(l) => passes.insert(pass.as_raw(), l),
        None => passes.remove(&pass.as_raw()),
    };
}

/// `vkCmdBeginRenderPass(2)`, before calling down: converts the pass's density map where the
/// application writes it.
///
/// # Safety
/// `cb` must be recording on `dev`; `begin` NULL or valid.
pub unsafe fn before_render_pass(
    dev: &Device,
    cb: vk::CommandBuffer,
    begin: *const vk::RenderPassBeginInfo<'_>,
) {
    // SAFETY: as the caller promised.
    let (Some(k), Some(b)) = (unsafe { key(cb) }, unsafe { begin.as_ref() }) else {
        return;
    };
    let (word, bit) = filter_slot(b.render_pass.as_raw());
    if WRITER_FILTER[word].load(Ordering::Acquire) & bit != 0 {
        map_may_have_changed();
    }
    let (word, bit) = filter_slot(b.framebuffer.as_raw());
    let known = (FRAMEBUFFER_FILTER[word].load(Ordering::Acquire) & bit != 0)
        .then(|| FRAMEBUFFERS.read().get(&b.framebuffer.as_raw()).copied())
        .flatten();
    let view = known.filter(|(key, _)| *key == k).map(|(_, v)| v);
    if view.is_none() && b.p_next.is_null() {
        return;
    }
    // SAFETY: as the caller promised.
    if !has_converter(cb) {
        return;
    }
    let Some(density) = dev.attachments.density_attachment(b.render_pass) else {
        return;
    };
    let view = view.or_else(|| {
        // An imageless framebuffer: the view is in the begin info.
        let ty = vk::StructureType::RENDER_PASS_ATTACHMENT_BEGIN_INFO;
        // SAFETY: the caller's chain, read only.
        let found = unsafe { chain::find::<vk::RenderPassAttachmentBeginInfo>(b.p_next, ty) };
        // SAFETY: found by its sType in a valid chain.
        let found = unsafe { found.ok().flatten()?.as_ref()? };
        if density >= found.attachment_count || found.p_attachments.is_null() {
            return None;
        }
        // SAFETY: the caller's array of `attachment_count` views.
        Some(unsafe { *found.p_attachments.add(density as usize) }.as_raw())
    });
    let Some(view) = view else {
        return;
    };
    with_converter(cb, |c| {
        let Some((initial, last, density_initial)) =
            c.passes.lock().get(&b.render_pass.as_raw()).copied()
        else {
            return;
        };
        // SAFETY: as the caller promised.
        unsafe { c.convert_for_pass(cb, view, initial, last, density_initial) };
    });
}

/// `vkCmdBeginRendering`, before calling down: converts the density map the rendering info names
/// where the application writes it.
///
/// # Safety
/// `cb` must be recording on `dev`; `info` NULL or valid.
pub unsafe fn before_rendering(
    _dev: &Device,
    cb: vk::CommandBuffer,
    info: *const vk::RenderingInfo<'_>,
) {
    // SAFETY: as the caller promised.
    let Some(ri) = (unsafe { info.as_ref() }) else {
        return;
    };
    // A resumed render pass instance was converted where it began, and nothing but the
    // instance's own commands may come between its suspension and resumption
    // (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#renderpass-suspension>).
    if ri.p_next.is_null() || ri.flags.contains(vk::RenderingFlags::RESUMING) {
        return;
    }
    let ty = vk::StructureType::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_INFO_EXT;
    type Info<'a> = vk::RenderingFragmentDensityMapAttachmentInfoEXT<'a>;
    // SAFETY: the caller's chain, read only.
    let found = unsafe { chain::find::<Info<'_>>(ri.p_next, ty) };
    // SAFETY: found by its sType in a valid chain.
    let Some(f) = found.ok().flatten().and_then(|p| unsafe { p.as_ref() }) else {
        return;
    };
    if f.image_view == vk::ImageView::null() {
        return;
    }
    with_converter(cb, |c| {
        if let Some((image, m)) = c.map_of_view(f.image_view.as_raw()) {
            let fdm = f.image_layout == vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT;
            // SAFETY: as the caller promised.
            unsafe { c.convert(cb, image, &m, readable(f.image_layout), fdm) };
        }
    });
}

impl Converter {
    /// The application image a view shows and its conversion objects, if it is a converted map.
    fn map_of_view(&self, view: u64) -> Option<(u64, MapObjects)> {
        let image = self.views.lock().get(&view).copied()?;
        let m = self.maps.lock().get(&image).and_then(|e| e.objects)?;
        Some((image, m))
    }

    /// In front of a rewritten render pass: the application's image makes the pass's
    /// `initialLayout` → `finalLayout` transition the driver's pass no longer makes (the shadow
    /// stands in for the image there), so the layouts the application's later barriers name are
    /// the image's; and the map is converted in whichever of the two layouts it can be read, in
    /// the order that reads it there. A map whose content the transition discards (`UNDEFINED`)
    /// is not converted: its shadow keeps what it had, which the density map's undefined content
    /// allows.
    ///
    /// # Safety
    /// As [`Converter::convert`].
    unsafe fn convert_for_pass(
        &self,
        cb: vk::CommandBuffer,
        view: u64,
        initial: vk::ImageLayout,
        last: vk::ImageLayout,
        density_initial: bool,
    ) {
        let Some((image, m)) = self.map_of_view(view) else {
            return;
        };
        let discarded = matches!(
            initial,
            vk::ImageLayout::UNDEFINED | vk::ImageLayout::PREINITIALIZED
        );
        let before = readable(initial);
        if before {
            // SAFETY: as the caller promised.
            unsafe { self.convert(cb, image, &m, true, density_initial && initial == last) };
        }
        if initial != last {
            // SAFETY: as the caller promised; the application's image, whole.
            unsafe { self.transition(cb, image, &m.shadow, initial, last) };
        }
        if !before {
            // SAFETY: as the caller promised.
            unsafe { self.convert(cb, image, &m, !discarded && readable(last), false) };
        }
    }

    /// Records a layout transition of the application's image, ordered after everything before
    /// it and before everything after it (a render pass's own transitions are ordered by its
    /// external dependencies, which the application made for the pass's use of the map).
    ///
    /// # Safety
    /// As [`Converter::convert`].
    unsafe fn transition(
        &self,
        cb: vk::CommandBuffer,
        image: u64,
        shadow: &ShadowImage,
        old: vk::ImageLayout,
        new: vk::ImageLayout,
    ) {
        let d = &self.own.fns;
        // SAFETY: as the caller promised.
        unsafe {
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[vk::ImageMemoryBarrier::default()
                    .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
                    .dst_access_mask(vk::AccessFlags::MEMORY_READ | vk::AccessFlags::MEMORY_WRITE)
                    .old_layout(old)
                    .new_layout(new)
                    .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .image(vk::Image::from_raw(image))
                    .subresource_range(vk::ImageSubresourceRange {
                        aspect_mask: vk::ImageAspectFlags::COLOR,
                        base_mip_level: 0,
                        level_count: 1,
                        base_array_layer: 0,
                        layer_count: shadow.app_layers.max(1),
                    })],
            );
        }
    }

    /// Records the conversion of the application's map `image` into its shadow, where `readable`
    /// (its layout at this point is `GENERAL`). `in_density_layout`: the application names the map
    /// in the density layout itself here, which nothing can write in, so a change since an earlier
    /// conversion in this command buffer had to move it back into that layout, which the layer
    /// sees ([`MAP_EPOCH`]); only then may the conversion be skipped.
    ///
    /// # Safety
    /// `cb` must be recording, outside a render pass, on this converter's device.
    unsafe fn convert(
        &self,
        cb: vk::CommandBuffer,
        image: u64,
        m: &MapObjects,
        readable: bool,
        in_density_layout: bool,
    ) {
        if !readable {
            if !self.logged_layout.swap(true, Ordering::Relaxed) {
                tracing::warn!(
                    image = image,
                    "a pass reads a density map the application writes from a layout other than \
                     GENERAL or the density-map layout: not converted, it renders at full rate"
                );
            }
            return;
        }
        let Some(bound) = bound_of(cb) else {
            if !self.logged_state.swap(true, Ordering::Relaxed) {
                tracing::warn!(
                    image = image,
                    "a command buffer whose compute bindings the layer cannot give back (push \
                     descriptors, or more sets, dynamic offsets or push-constant ranges than it \
                     records): its passes' density maps are not converted, they render at full rate"
                );
            }
            return;
        };
        let epoch = MAP_EPOCH.load(Ordering::Acquire);
        if in_density_layout && bound.converted.contains(&(image, epoch)) {
            // Converted earlier in this command buffer, and nothing since may have changed it.
            return;
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
            return;
        }
        // SAFETY: as the caller promised.
        let Some(slot) = (unsafe { self.slot(cb, image, m) }) else {
            return;
        };
        // Conditional rendering discards dispatches but not copies
        // (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#drawing-conditional-rendering>):
        // the conversion runs outside it, since the pass reads the map whatever the condition.
        // The begin hooks run outside any render pass, where a condition begun outside one may
        // end and begin again (VUID-vkCmdEndConditionalRenderingEXT-None-01986).
        // SAFETY: `cb` is recording on this device.
        let next = unsafe { registry::recording(cb) }.map(|r| r.next);
        let suspend = bound.conditional.and_then(|c| {
            let n = next?;
            Some((
                c,
                n.cmd_end_conditional_rendering_ext?,
                n.cmd_begin_conditional_rendering_ext?,
            ))
        });
        if let Some((_, end, _)) = suspend {
            // SAFETY: the next layer's command, on the application's recording command buffer
            // whose condition is active.
            unsafe { end(cb) };
        }
        let d = &self.own.fns;
        let s = &m.shadow;
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
        let shadow_range = vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: 0,
            layer_count: s.layers,
        };
        let shadow_barrier = |old, new, src, dst| {
            vk::ImageMemoryBarrier::default()
                .src_access_mask(src)
                .dst_access_mask(dst)
                .old_layout(old)
                .new_layout(new)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .image(s.image)
                .subresource_range(shadow_range)
        };
        // SAFETY: the next layer's commands on the application's recording command buffer, with
        // the layer's own objects; outside a render pass, as the begin hooks are.
        unsafe {
            // 1. Whatever wrote the map comes before the dispatch reads it, and whatever read this
            // command buffer's code buffer (an earlier conversion's copy) before the dispatch
            // writes it (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#synchronization-dependencies>):
            // the application's own dependency into the density layout made its writes
            // available. The shadow's old content is discarded (UNDEFINED) once earlier passes'
            // shading-rate reads are done, ready for the copy. ALL_COMMANDS stands in for the
            // unknown writer and for the shading-rate stage, which validation 1.3.239 refuses
            // without NVIDIA's shading-rate-image feature (docs/vulkan-fdm-on-fsr.md#shadows).
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[vk::MemoryBarrier::default()
                    .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
                    .dst_access_mask(vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE)],
                &[],
                &[shadow_barrier(
                    vk::ImageLayout::UNDEFINED,
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                    vk::AccessFlags::empty(),
                    vk::AccessFlags::TRANSFER_WRITE,
                )],
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
            d.cmd_push_constants(
                cb,
                self.layout,
                vk::ShaderStageFlags::COMPUTE,
                0,
                &push.bytes(),
            );
            d.cmd_dispatch(cb, groups, 1, 1);
            // 2. The codes, from the dispatch to the copy: exactly those stages.
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[vk::BufferMemoryBarrier::default()
                    .src_access_mask(vk::AccessFlags::SHADER_WRITE)
                    .dst_access_mask(vk::AccessFlags::TRANSFER_READ)
                    .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .buffer(slot.buffer)
                    .offset(0)
                    .size(vk::WHOLE_SIZE)],
                &[],
            );
            d.cmd_copy_buffer_to_image(
                cb,
                slot.buffer,
                s.image,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &[vk::BufferImageCopy {
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
                }],
            );
            // 3. The shadow, from the copy to the pass's shading-rate read (ALL_COMMANDS for the
            // shading-rate stage, as above).
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[shadow_barrier(
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                    SHADOW_LAYOUT,
                    vk::AccessFlags::TRANSFER_WRITE,
                    vk::AccessFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR,
                )],
            );
            restore(d, cb, &bound);
        }
        with_record(cb, |b| {
            b.converted.rotate_right(1);
            b.converted[0] = (image, epoch);
        });
        if let Some(((buffer, offset, flags), _, begin)) = suspend {
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
// The application's compute bindings, per command buffer.

/// Descriptor set indices a record holds.
const SETS: usize = 8;
/// Dynamic offsets a record holds per set.
const DYNAMIC: usize = 8;
/// Push-constant bytes a record holds (`maxPushConstantsSize` is at least 128, 256 on desktop
/// drivers).
const PUSH_BYTES: usize = 256;
/// Distinct push-constant updates (layout, stages, range) a record holds.
const PUSHES: usize = 8;

#[derive(Clone, Copy, Default)]
struct SetBinding {
    layout: vk::PipelineLayout,
    set: vk::DescriptorSet,
    /// Order of the bind among the command buffer's binds (0: never bound).
    seq: u32,
    dynamic_count: u32,
    dynamic: [u32; DYNAMIC],
}

#[derive(Clone, Copy, Default)]
struct PushRange {
    layout: vk::PipelineLayout,
    stages: vk::ShaderStageFlags,
    offset: u32,
    size: u32,
    /// Order of the range's latest push among the command buffer's pushes: ranges are given back
    /// in the order the application last pushed them, so the last layout it pushed with (which
    /// decides which earlier push constants stay defined,
    /// <https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#descriptorsets-compatibility>)
    /// is the last one again.
    seq: u32,
}

/// What the application has bound at the compute bind point of one command buffer, and its
/// push constants (which are not per bind point).
#[derive(Clone, Copy)]
pub struct Bound {
    pipeline: vk::Pipeline,
    sets: [SetBinding; SETS],
    seq: u32,
    push: [u8; PUSH_BYTES],
    pushes: [PushRange; PUSHES],
    push_count: u32,
    /// Something was bound that this record cannot give back.
    lost: bool,
    /// Conditional rendering the application made active in this command buffer (buffer, offset,
    /// flags), which the conversion suspends.
    conditional: Option<(vk::Buffer, u64, vk::ConditionalRenderingFlagsEXT)>,
    /// A secondary command buffer that inherits conditional rendering: it cannot suspend it.
    inherited_conditional: bool,
    /// Maps this recording converted, with the [`MAP_EPOCH`] they were converted at (image 0:
    /// none).
    converted: [(u64, u64); 4],
}

impl Default for Bound {
    fn default() -> Bound {
        Bound {
            pipeline: vk::Pipeline::null(),
            sets: [SetBinding::default(); SETS],
            seq: 0,
            push: [0; PUSH_BYTES],
            pushes: [PushRange::default(); PUSHES],
            push_count: 0,
            lost: false,
            conditional: None,
            inherited_conditional: false,
            converted: [(0, 0); 4],
        }
    }
}

impl Bound {
    fn bind_sets(
        &mut self,
        layout: vk::PipelineLayout,
        first: u32,
        sets: &[vk::DescriptorSet],
        dynamic: &[u32],
        dynamic_counts: impl Fn(u32) -> Option<u32>,
    ) {
        self.seq = self.seq.wrapping_add(1).max(1);
        let mut used = 0usize;
        for (i, &set) in sets.iter().enumerate() {
            let index = first as usize + i;
            let n = dynamic_counts(index as u32).unwrap_or(0) as usize;
            let Some(slot) = self.sets.get_mut(index) else {
                self.lost = true;
                return;
            };
            if n > DYNAMIC || used + n > dynamic.len() {
                self.lost = true;
                return;
            }
            slot.layout = layout;
            slot.set = set;
            slot.seq = self.seq;
            slot.dynamic_count = n as u32;
            slot.dynamic[..n].copy_from_slice(&dynamic[used..used + n]);
            used += n;
        }
    }

    fn push(&mut self, range: PushRange, values: &[u8]) {
        let end = range.offset as usize + values.len();
        if end > PUSH_BYTES {
            self.lost = true;
            return;
        }
        self.push[range.offset as usize..end].copy_from_slice(values);
        self.seq = self.seq.wrapping_add(1).max(1);
        let seq = self.seq;
        let known = &mut self.pushes[..self.push_count as usize];
        if let Some(p) = known.iter_mut().find(|p| {
            p.layout == range.layout
                && p.stages == range.stages
                && p.offset == range.offset
                && p.size == range.size
        }) {
            p.seq = seq;
            return;
        }
        match self.pushes.get_mut(self.push_count as usize) {
            Some(slot) => {
                *slot = PushRange { seq, ..range };
                self.push_count += 1;
            }
            None => self.lost = true,
        }
    }
}

/// Binds `bound` again on `cb`: the pipeline, the sets in the order the application bound them,
/// and every push-constant range with its latest bytes.
///
/// # Safety
/// `cb` must be recording on `d`'s device; `bound` the application's state of it.
unsafe fn restore(d: &ash::Device, cb: vk::CommandBuffer, bound: &Bound) {
    // SAFETY: the application's own objects, bound as it bound them.
    unsafe {
        if bound.pipeline != vk::Pipeline::null() {
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, bound.pipeline);
        }
        let mut order: [usize; SETS] = std::array::from_fn(|i| i);
        order.sort_by_key(|&i| (bound.sets[i].seq, i));
        for i in order {
            let s = &bound.sets[i];
            if s.seq == 0 || s.set == vk::DescriptorSet::null() {
                continue;
            }
            d.cmd_bind_descriptor_sets(
                cb,
                vk::PipelineBindPoint::COMPUTE,
                s.layout,
                i as u32,
                &[s.set],
                &s.dynamic[..s.dynamic_count as usize],
            );
        }
        let mut pushes = bound.pushes;
        let pushes = &mut pushes[..bound.push_count as usize];
        pushes.sort_by_key(|p| p.seq);
        for p in pushes.iter() {
            let at = p.offset as usize;
            d.cmd_push_constants(
                cb,
                p.layout,
                p.stages,
                p.offset,
                &bound.push[at..at + p.size as usize],
            );
        }
    }
}

/// A cheap hasher for dispatchable handles (heap addresses): one multiply.
#[derive(Default)]
struct HandleHasher(u64);

impl Hasher for HandleHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ u64::from(b)).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        }
    }
    fn write_u64(&mut self, v: u64) {
        self.0 = (v ^ (v >> 29)).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    }
}

/// One command buffer's record: what it has bound ([`Bound`]), behind a lock of its own. Command
/// buffers are externally synchronised (a command buffer and its pool are used by one thread at a
/// time, <https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#fundamentals-threadingbehavior>),
/// so that lock is never contended: it is one uncontended atomic on the record's own memory, which
/// no other command buffer shares.
struct CbRecord {
    /// The device's dispatch key, whose destruction drops the record.
    device: Key,
    /// The pool it was allocated from (0 where the layer did not see the allocation), whose
    /// destruction drops the record.
    pool: u64,
    /// A secondary command buffer (whose begin info's inheritance info is read).
    secondary: bool,
    bound: parking_lot::Mutex<Bound>,
    /// The command buffer's conversion objects, one per map it converted ([`Slot`]).
    slots: parking_lot::Mutex<Vec<Slot>>,
    /// The device's converter (`None` where it converts nothing), found once at allocation, so
    /// that a pass begin reaches it without the process-wide [`CONVERTERS`].
    converter: Option<Arc<Converter>>,
}

type Records = HashMap<u64, Arc<CbRecord>, BuildHasherDefault<HandleHasher>>;

/// Every command buffer's record. Taken only to add a record (at allocation), to drop one (free,
/// pool or device destruction), and on a thread's first look-up of a command buffer since any of
/// these: recording threads find their command buffers' records in their own [`CB_CACHE`]
/// without it. A leaf lock.
static CB_RECORDS: parking_lot::Mutex<Records> =
    parking_lot::Mutex::new(HashMap::with_hasher(BuildHasherDefault::new()));

/// Advanced (under [`CB_RECORDS`]) whenever a record is added or dropped: a cached look-up is good
/// only while the generation it was made in is current, so a handle value the driver reuses for a
/// new command buffer never finds the old one's record.
static CB_GENERATION: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

/// A thread's cached look-up: command buffer, generation, record.
type CacheEntry = (u64, u64, *const CbRecord);

/// Look-ups a thread keeps: the command buffers it records at once.
const CACHED: usize = 4;

thread_local! {
    static CB_CACHE: std::cell::Cell<[CacheEntry; CACHED]> =
        const { std::cell::Cell::new([(0, 0, std::ptr::null()); CACHED]) };
}

/// `cb`'s record, for the length of a call on `cb`: from this thread's cache where it is current,
/// else from [`CB_RECORDS`], then cached.
///
/// Sound because a record leaves [`CB_RECORDS`] (and may be freed) only when its command buffer is
/// freed, its pool or its device destroyed, which the application synchronises with every call on
/// the command buffer; and every such change advances [`CB_GENERATION`], so no entry made before
/// it is used after it.
#[inline]
fn record_of<R>(cb: vk::CommandBuffer, f: impl FnOnce(&CbRecord) -> R) -> Option<R> {
    let raw = cb.as_raw();
    let now = CB_GENERATION.load(Ordering::Acquire);
    let cached = CB_CACHE
        .try_with(|c| {
            c.get()
                .iter()
                .find(|e| e.0 == raw && e.1 == now)
                .map(|e| e.2)
        })
        .ok()
        .flatten();
    let ptr = match cached {
        Some(p) => p,
        None => {
            let map = CB_RECORDS.lock();
            let p = Arc::as_ptr(map.get(&raw)?);
            let _ = CB_CACHE.try_with(|c| {
                let mut v = c.get();
                v.rotate_right(1);
                v[0] = (raw, now, p);
                c.set(v);
            });
            p
        }
    };
    // SAFETY: the record is alive for this call on `cb` (see above).
    Some(f(unsafe { &*ptr }))
}

/// Runs `f` on `cb`'s bindings, if it has a record.
#[inline]
fn with_record(cb: vk::CommandBuffer, f: impl FnOnce(&mut Bound)) {
    record_of(cb, |r| f(&mut r.bound.lock()));
}

/// A copy of `cb`'s bindings, `None` where it has no record or they cannot be given back.
fn bound_of(cb: vk::CommandBuffer) -> Option<Bound> {
    record_of(cb, |r| *r.bound.lock()).filter(|b| !b.lost)
}

/// Drops the records `drop` selects, and destroys their conversion objects (their command
/// buffers are being freed, with their pool or device, and so are not pending).
fn forget_where(drop: impl Fn(u64, &CbRecord) -> bool) {
    let mut gone = Vec::new();
    {
        let mut map = CB_RECORDS.lock();
        let before = map.len();
        map.retain(|&cb, r| {
            let d = drop(cb, r);
            if d {
                gone.push(Arc::clone(r));
            }
            !d
        });
        if map.len() != before {
            CB_GENERATION.fetch_add(1, Ordering::Release);
        }
    }
    destroy_records(gone);
}

/// Drops the records of freed command buffers (a look-up each, not a scan of every record).
fn forget(cbs: &[vk::CommandBuffer]) {
    let mut gone = Vec::new();
    {
        let mut map = CB_RECORDS.lock();
        for cb in cbs {
            if let Some(r) = map.remove(&cb.as_raw()) {
                gone.push(r);
            }
        }
        if !gone.is_empty() {
            CB_GENERATION.fetch_add(1, Ordering::Release);
        }
    }
    destroy_records(gone);
}

/// Destroys the conversion objects of dropped records.
fn destroy_records(gone: Vec<Arc<CbRecord>>) {
    for r in gone {
        let slots = std::mem::take(&mut *r.slots.lock());
        if slots.is_empty() {
            continue;
        }
        if let Some(c) = &r.converter {
            // SAFETY: the converter's own slots; their command buffer is not pending.
            unsafe { c.destroy_slots(&slots) };
        }
    }
}

/// Adds (or renews) `cb`'s record. A record the handle still had belonged to a command buffer the
/// layer did not see go (its handle now names a new one): its objects go.
fn remember(cb: vk::CommandBuffer, device: Key, pool: u64, secondary: bool) {
    let record = Arc::new(CbRecord {
        device,
        pool,
        secondary,
        bound: parking_lot::Mutex::new(Bound::default()),
        slots: parking_lot::Mutex::new(Vec::new()),
        converter: converter_by_key(device),
    });
    let old = {
        let mut map = CB_RECORDS.lock();
        let old = map.insert(cb.as_raw(), record);
        CB_GENERATION.fetch_add(1, Ordering::Release);
        old
    };
    destroy_records(old.into_iter().collect());
}

/// `vkAllocateCommandBuffers`: each new command buffer gets its record, with its pool, and its
/// queue family is noted for ownership transfers ([`crate::vk::barrier::buffers_allocated`]).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn allocate_command_buffers(
    device: vk::Device,
    info: *const vk::CommandBufferAllocateInfo<'_>,
    out: *mut vk::CommandBuffer,
) -> vk::Result {
    guard(
        "vkAllocateCommandBuffers",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let rec = unsafe { registry::recording(device) };
            let Some(next) = rec.and_then(|r| r.next.allocate_command_buffers) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            // SAFETY: the next layer's function, with the caller's arguments.
            let r = unsafe { next(device, info, out) };
            // SAFETY: as the caller promised.
            let (Some(k), Some(i)) = (unsafe { key(device) }, unsafe { info.as_ref() }) else {
                return r;
            };
            if r == vk::Result::SUCCESS && !out.is_null() {
                let n = i.command_buffer_count as usize;
                // SAFETY: the driver wrote `command_buffer_count` handles.
                let cbs = unsafe { std::slice::from_raw_parts(out, n) };
                let secondary = i.level == vk::CommandBufferLevel::SECONDARY;
                for &cb in cbs {
                    remember(cb, k, i.command_pool.as_raw(), secondary);
                }
                crate::vk::barrier::buffers_allocated(i, cbs);
            }
            r
        },
    )
}

/// The records of a destroyed pool's command buffers go.
fn pool_destroyed(device: Key, pool: u64) {
    forget_where(|_, r| r.device == device && r.pool == pool);
}

/// `vkDestroyCommandPool`: its command buffers are freed with it, and their records go
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkDestroyCommandPool.html>).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn destroy_command_pool(
    device: vk::Device,
    pool: vk::CommandPool,
    alloc: *const vk::AllocationCallbacks<'_>,
) {
    guard("vkDestroyCommandPool", (), || {
        // SAFETY: as the caller promised.
        let key = unsafe { key(device) };
        if let (Some(k), false) = (key, pool == vk::CommandPool::null()) {
            pool_destroyed(k, pool.as_raw());
        }
        // SAFETY: as the caller promised.
        let next = unsafe { registry::recording(device) }.and_then(|r| r.next.destroy_command_pool);
        if let Some(next) = next {
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { next(device, pool, alloc) };
        }
    })
}

/// `vkBeginCommandBuffer`: the command buffer's bindings start empty
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkBeginCommandBuffer.html>); its
/// record is made (once per command buffer) or cleared.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn begin_command_buffer(
    cb: vk::CommandBuffer,
    info: *const vk::CommandBufferBeginInfo<'_>,
) -> vk::Result {
    guard(
        "vkBeginCommandBuffer",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let rec = unsafe { registry::recording(cb) };
            let Some(next) = rec.and_then(|r| r.next.begin_command_buffer) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let found = record_of(cb, |r| {
                // SAFETY: the caller's begin info, read only; its inheritance info is read for
                // secondary command buffers only, as the specification says.
                let inherits = r.secondary && unsafe { inherits_conditional_rendering(info) };
                *r.bound.lock() = Bound {
                    inherited_conditional: inherits,
                    ..Bound::default()
                };
            });
            if found.is_none() {
                // Allocated before the layer saw it (not expected on an emulating device): a
                // primary's record without a pool, dropped with the command buffer or its device.
                // SAFETY: as the caller promised.
                let device = unsafe { key(cb) }.unwrap_or(0);
                remember(cb, device, 0, false);
            }
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { next(cb, info) }
        },
    )
}

/// `vkFreeCommandBuffers`: their records go.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn free_command_buffers(
    device: vk::Device,
    pool: vk::CommandPool,
    count: u32,
    cbs: *const vk::CommandBuffer,
) {
    guard("vkFreeCommandBuffers", (), || {
        if !cbs.is_null() {
            // SAFETY: the caller's array.
            forget(unsafe { std::slice::from_raw_parts(cbs, count as usize) });
        }
        // The leaf table, not the registry's ranked map: fovea's own uploads free their command
        // buffers through the layer under their submit lock (`crate::common::lock::Rank`).
        // SAFETY: as the caller promised.
        let next = unsafe { registry::recording(device) }.and_then(|r| r.next.free_command_buffers);
        if let Some(next) = next {
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { next(device, pool, count, cbs) };
        }
    })
}

/// Forgets a destroyed framebuffer's density view (called by `pass::destroy_framebuffer`, after
/// the call went down).
///
/// # Safety
/// `device` is a device the loader dispatched.
pub unsafe fn framebuffer_destroyed(device: vk::Device, fb: vk::Framebuffer) {
    // SAFETY: as the caller promised.
    if let Some(k) = unsafe { key(device) } {
        let mut fbs = FRAMEBUFFERS.write();
        if fbs.get(&fb.as_raw()).is_some_and(|(key, _)| *key == k) {
            fbs.remove(&fb.as_raw());
        }
    }
}

/// Whether a begin info's inheritance info makes the command buffer inherit conditional rendering.
///
/// # Safety
/// `info` must be NULL or a valid begin info of a secondary command buffer.
unsafe fn inherits_conditional_rendering(info: *const vk::CommandBufferBeginInfo<'_>) -> bool {
    // SAFETY: as the caller promised.
    let Some(begin) = (unsafe { info.as_ref() }) else {
        return false;
    };
    // SAFETY: as the caller promised: a secondary's begin info has a valid inheritance info.
    let Some(inh) = (unsafe { begin.p_inheritance_info.as_ref() }) else {
        return false;
    };
    let ty = vk::StructureType::COMMAND_BUFFER_INHERITANCE_CONDITIONAL_RENDERING_INFO_EXT;
    // SAFETY: the caller's chain, read only.
    let found = unsafe {
        chain::find::<vk::CommandBufferInheritanceConditionalRenderingInfoEXT<'_>>(inh.p_next, ty)
    };
    let Some(c) = found.ok().flatten() else {
        return false;
    };
    // SAFETY: found by its sType in a valid chain.
    unsafe { (*c).conditional_rendering_enable == vk::TRUE }
}

/// `vkCmdBeginConditionalRenderingEXT`: the condition is noted, so a conversion can suspend it.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_begin_conditional_rendering(
    cb: vk::CommandBuffer,
    info: *const vk::ConditionalRenderingBeginInfoEXT<'_>,
) {
    guard("vkCmdBeginConditionalRenderingEXT", (), || {
        // SAFETY: as the caller promised.
        let rec = unsafe { registry::recording(cb) };
        let Some(next) = rec.and_then(|r| r.next.cmd_begin_conditional_rendering_ext) else {
            return;
        };
        // SAFETY: as the caller promised.
        if let Some(i) = unsafe { info.as_ref() } {
            let c = (i.buffer, i.offset, i.flags);
            with_record(cb, |b| b.conditional = Some(c));
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { next(cb, info) }
    })
}

/// `vkCmdEndConditionalRenderingEXT`: the condition is forgotten.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_end_conditional_rendering(cb: vk::CommandBuffer) {
    guard("vkCmdEndConditionalRenderingEXT", (), || {
        // SAFETY: as the caller promised.
        let rec = unsafe { registry::recording(cb) };
        let Some(next) = rec.and_then(|r| r.next.cmd_end_conditional_rendering_ext) else {
            return;
        };
        with_record(cb, |b| b.conditional = None);
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { next(cb) }
    })
}

/// `vkCmdBindPipeline`: a compute pipeline is noted.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_bind_pipeline(
    cb: vk::CommandBuffer,
    point: vk::PipelineBindPoint,
    pipeline: vk::Pipeline,
) {
    guard("vkCmdBindPipeline", (), || {
        // SAFETY: as the caller promised.
        let rec = unsafe { registry::recording(cb) };
        let Some(next) = rec.and_then(|r| r.next.cmd_bind_pipeline) else {
            return;
        };
        if point == vk::PipelineBindPoint::COMPUTE {
            with_record(cb, |b| b.pipeline = pipeline);
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { next(cb, point, pipeline) }
    })
}

/// `vkCmdBindDescriptorSets`: compute sets and their dynamic offsets are noted.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
#[allow(clippy::too_many_arguments)]
pub unsafe extern "system" fn cmd_bind_descriptor_sets(
    cb: vk::CommandBuffer,
    point: vk::PipelineBindPoint,
    layout: vk::PipelineLayout,
    first: u32,
    set_count: u32,
    sets: *const vk::DescriptorSet,
    dynamic_count: u32,
    dynamic: *const u32,
) {
    guard("vkCmdBindDescriptorSets", (), || {
        // SAFETY: as the caller promised.
        let rec = unsafe { registry::recording(cb) };
        let Some(next) = rec.and_then(|r| r.next.cmd_bind_descriptor_sets) else {
            return;
        };
        if point == vk::PipelineBindPoint::COMPUTE && !sets.is_null() {
            // SAFETY: the caller's arrays.
            let s = unsafe { std::slice::from_raw_parts(sets, set_count as usize) };
            let dy = if dynamic.is_null() {
                &[][..]
            } else {
                // SAFETY: as above.
                unsafe { std::slice::from_raw_parts(dynamic, dynamic_count as usize) }
            };
            with_record(cb, |b| {
                // Which sets take how many dynamic offsets is in their layouts, which the layer
                // does not look into: one set with all of them is exact; several sets with dynamic
                // offsets cannot be split, so the record gives up.
                if dy.is_empty() || s.len() == 1 {
                    let n = dy.len() as u32;
                    b.bind_sets(layout, first, s, dy, |_| Some(n));
                } else {
                    b.lost = true;
                }
            });
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe {
            next(
                cb,
                point,
                layout,
                first,
                set_count,
                sets,
                dynamic_count,
                dynamic,
            )
        }
    })
}

/// `vkCmdPushConstants`: the bytes and the range are noted.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_push_constants(
    cb: vk::CommandBuffer,
    layout: vk::PipelineLayout,
    stages: vk::ShaderStageFlags,
    offset: u32,
    size: u32,
    values: *const c_void,
) {
    guard("vkCmdPushConstants", (), || {
        // SAFETY: as the caller promised.
        let rec = unsafe { registry::recording(cb) };
        let Some(next) = rec.and_then(|r| r.next.cmd_push_constants) else {
            return;
        };
        if !values.is_null() {
            // SAFETY: the caller's `size` bytes.
            let v = unsafe { std::slice::from_raw_parts(values as *const u8, size as usize) };
            let range = PushRange {
                layout,
                stages,
                offset,
                size,
                seq: 0,
            };
            with_record(cb, |b| b.push(range, v));
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { next(cb, layout, stages, offset, size, values) }
    })
}

/// `vkCmdPushDescriptorSetKHR`: a compute push descriptor cannot be given back (its writes would
/// have to be copied); the command buffer's maps are not converted from then on.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_push_descriptor_set_khr(
    cb: vk::CommandBuffer,
    point: vk::PipelineBindPoint,
    layout: vk::PipelineLayout,
    set: u32,
    count: u32,
    writes: *const vk::WriteDescriptorSet<'_>,
) {
    guard("vkCmdPushDescriptorSetKHR", (), || {
        // SAFETY: as the caller promised.
        let rec = unsafe { registry::recording(cb) };
        let Some(next) = rec.and_then(|r| r.next.cmd_push_descriptor_set_khr) else {
            return;
        };
        if point == vk::PipelineBindPoint::COMPUTE {
            with_record(cb, |b| b.lost = true);
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { next(cb, point, layout, set, count, writes) }
    })
}

/// `vkCmdPushDescriptorSetWithTemplateKHR`: as [`cmd_push_descriptor_set_khr`] (the template's
/// bind point is not looked up, so any use gives up).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_push_descriptor_set_with_template_khr(
    cb: vk::CommandBuffer,
    template: vk::DescriptorUpdateTemplate,
    layout: vk::PipelineLayout,
    set: u32,
    data: *const c_void,
) {
    guard("vkCmdPushDescriptorSetWithTemplateKHR", (), || {
        // SAFETY: as the caller promised.
        let rec = unsafe { registry::recording(cb) };
        let Some(next) = rec.and_then(|r| r.next.cmd_push_descriptor_set_with_template_khr) else {
            return;
        };
        with_record(cb, |b| b.lost = true);
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { next(cb, template, layout, set, data) }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rates(max: u32, aspect: u32) -> Vec<[u32; 2]> {
        let mut out = Vec::new();
        for w in [4, 2, 1] {
            for h in [4, 2, 1] {
                if w <= max && h <= max && w <= aspect * h && h <= aspect * w {
                    out.push([w, h]);
                }
            }
        }
        out
    }

    fn fdm(max: [u32; 2], rates: Vec<[u32; 2]>, layered: bool) -> FdmEmulation {
        FdmEmulation {
            texel: [16, 16],
            layered,
            max_fragment: max,
            rates,
            non_trivial_combiners: true,
        }
    }

    /// Every byte pair, in one or two layers, merged or not, on several device profiles: the
    /// shader's algorithm gives the model's codes.
    #[test]
    fn shader_algorithm_matches_the_model() {
        let profiles = [
            fdm([4, 4], rates(4, 4), true),
            fdm([2, 2], rates(2, 2), false),
            fdm([4, 4], rates(4, 2), false),
            fdm([2, 4], vec![[1, 2], [2, 1], [2, 2], [1, 4]], true),
        ];
        // 256 × 256 pairs in a 256-wide map; the second layer is the first shifted, so the merge
        // meets every kind of pair.
        let width = 256u32;
        let height = 256u32;
        let texels = (width * height) as usize;
        let mut density = vec![0u8; texels * 4];
        for t in 0..texels {
            density[t * 2] = (t % 256) as u8;
            density[t * 2 + 1] = (t / 256) as u8;
            density[(texels + t) * 2] = (t / 256) as u8;
            density[(texels + t) * 2 + 1] = ((t * 7) % 256) as u8;
        }
        for f in &profiles {
            for (layers, merged) in [(1, false), (2, false), (2, true)] {
                let push = Push {
                    width,
                    height,
                    layers,
                    merged: u32::from(merged),
                    table: table(f),
                };
                let map = &density[..texels * 2 * layers as usize];
                let mut want = vec![
                    0u8;
                    if merged {
                        texels
                    } else {
                        texels * layers as usize
                    }
                ];
                fovea_model::shading_rate::fill_codes(
                    map,
                    texels,
                    merged,
                    f.max_fragment,
                    &f.rates,
                    &mut want,
                );
                assert!(
                    shader_on_cpu(map, &push) == want,
                    "profile {:?}, {layers} layers, merged {merged}",
                    f.rates
                );
            }
        }
    }

    #[test]
    fn push_constants_are_the_shaders_layout() {
        let p = Push {
            width: 1,
            height: 2,
            layers: 3,
            merged: 1,
            table: [5, 6, 7, 8],
        };
        let b = p.bytes();
        assert_eq!(b.len(), std::mem::size_of::<Push>());
        assert_eq!(u32::from_ne_bytes(b[8..12].try_into().unwrap()), 3);
        assert_eq!(u32::from_ne_bytes(b[28..32].try_into().unwrap()), 8);
    }

    #[test]
    fn records_give_back_sets_in_bind_order_and_give_up_past_their_size() {
        let l = vk::PipelineLayout::from_raw(1);
        let mut b = Bound::default();
        b.bind_sets(l, 1, &[vk::DescriptorSet::from_raw(10)], &[4, 8], |_| {
            Some(2)
        });
        b.bind_sets(l, 0, &[vk::DescriptorSet::from_raw(11)], &[], |_| None);
        assert_eq!(b.sets[1].set.as_raw(), 10);
        assert_eq!(
            &b.sets[1].dynamic[..b.sets[1].dynamic_count as usize],
            &[4, 8]
        );
        assert!(b.sets[0].seq > b.sets[1].seq);
        assert!(!b.lost);
        b.bind_sets(
            l,
            SETS as u32,
            &[vk::DescriptorSet::from_raw(12)],
            &[],
            |_| None,
        );
        assert!(b.lost, "a set index past the record");

        let mut b = Bound::default();
        let r = |offset, size| PushRange {
            layout: l,
            stages: vk::ShaderStageFlags::COMPUTE,
            offset,
            size,
            seq: 0,
        };
        b.push(r(0, 4), &[1, 2, 3, 4]);
        b.push(r(0, 4), &[5, 6, 7, 8]);
        assert_eq!(b.push_count, 1, "the same range twice is one range");
        assert_eq!(&b.push[..4], &[5, 6, 7, 8]);
        b.push(r(252, 8), &[0; 8]);
        assert!(b.lost, "bytes past the record");
        let mut b = Bound::default();
        for i in 0..=PUSHES as u32 {
            b.push(r(i * 4, 4), &[0; 4]);
        }
        assert!(b.lost, "more ranges than the record holds");
    }

    /// Ranges come back in the order of their latest push, not the order first seen: after
    /// pushes with layouts A, B, A the last layout pushed with is A again.
    #[test]
    fn push_constants_come_back_in_the_order_last_pushed() {
        let a = vk::PipelineLayout::from_raw(1);
        let b = vk::PipelineLayout::from_raw(2);
        let r = |layout| PushRange {
            layout,
            stages: vk::ShaderStageFlags::COMPUTE,
            offset: 0,
            size: 4,
            seq: 0,
        };
        let mut bound = Bound::default();
        bound.push(r(a), &[1; 4]);
        bound.push(r(b), &[2; 4]);
        bound.push(r(a), &[3; 4]);
        let mut order = bound.pushes[..bound.push_count as usize].to_vec();
        order.sort_by_key(|p| p.seq);
        let layouts: Vec<_> = order.iter().map(|p| p.layout).collect();
        assert_eq!(layouts, [b, a]);
        assert_eq!(&bound.push[..4], &[3; 4]);
    }

    /// A pool's destruction drops the records of the command buffers allocated from it, and only
    /// those: over many create, allocate and destroy cycles the records do not grow.
    #[test]
    fn destroyed_pools_take_their_command_buffers_records() {
        let device: Key = 0xD0_0000;
        let count = |pool: u64| {
            CB_RECORDS
                .lock()
                .values()
                .filter(|r| r.device == device && r.pool == pool)
                .count()
        };
        remember(vk::CommandBuffer::from_raw(0xD0_0001), device, 7, false);
        for cycle in 0..100u64 {
            let pool = 100 + cycle;
            for i in 0..4 {
                let cb = vk::CommandBuffer::from_raw(0xD1_0000 + cycle * 8 + i);
                remember(cb, device, pool, i % 2 == 1);
                with_record(cb, |b| b.lost = true);
            }
            assert_eq!(count(pool), 4);
            pool_destroyed(device, pool);
            assert_eq!(count(pool), 0, "cycle {cycle}");
        }
        let left = CB_RECORDS
            .lock()
            .values()
            .filter(|r| r.device == device)
            .count();
        assert_eq!(left, 1, "the other pool's command buffer stays");
        assert!(bound_of(vk::CommandBuffer::from_raw(0xD0_0001)).is_some());
        assert!(
            bound_of(vk::CommandBuffer::from_raw(0xD1_0000)).is_none(),
            "a freed handle finds no record, in this thread's cache either"
        );
        forget_where(|_, r| r.device == device);
    }

    /// The checked-in SPIR-V is what `shaders/build.sh` makes of the checked-in source.
    #[test]
    fn shader_matches_its_source() {
        if std::process::Command::new("glslangValidator")
            .arg("--version")
            .output()
            .is_err()
        {
            eprintln!("skipped: glslangValidator is not installed (glslang-tools)");
            return;
        }
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/vk/shaders");
        let out = std::env::temp_dir().join(format!("fovea-convert-{}.spv", std::process::id()));
        let run = std::process::Command::new("glslangValidator")
            .args(["-V", "--target-env", "vulkan1.1", "-o"])
            .arg(&out)
            .arg(dir.join("convert.comp"))
            .output()
            .unwrap();
        assert!(
            run.status.success(),
            "convert.comp does not compile: {}",
            String::from_utf8_lossy(&run.stdout)
        );
        let built = std::fs::read(&out).unwrap();
        let _ = std::fs::remove_file(&out);
        assert!(
            built == SHADER,
            "the checked-in convert.comp.spv is stale; run src/vk/shaders/build.sh"
        );
    }
}
