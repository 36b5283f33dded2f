//! XR_KHR_vulkan_enable / XR_KHR_vulkan_enable2 and the Vulkan side of swapchains.
//!
//! Function pointers: with enable2 the application hands the runtime its `vkGetInstanceProcAddr`
//! (xrCreateVulkanInstanceKHR/DeviceKHR), and the runtime keeps using it; with enable (v1) the
//! binding carries none, so the runtime loads the system Vulkan loader itself (`ash::Entry::load`),
//! which the spec assumes is the same loader the application uses.
//!
//! Queue use: only xrAcquireSwapchainImage submits (the one-time UNDEFINED → attachment layout
//! transition), on the binding's queue, and waits for it on a fence before returning. The spec
//! allows queue use in xrBeginFrame, xrEndFrame, xrAcquireSwapchainImage and xrReleaseSwapchainImage
//! only (XR_KHR_vulkan_enable, "Concurrency").

use std::ffi::{c_char, c_void, CStr};
use std::sync::{Arc, OnceLock};

use ash::vk;
use ash::vk::Handle as _;
use openxr_sys as xr;

use crate::ffi;
use crate::objects::{SwapchainImages, VulkanInstanceState, VulkanSession};
use crate::state::{entry, world, World};
use crate::system::check_system;

/// Vulkan formats offered, in order of preference (sRGB colour first, as the spec recommends).
pub(crate) const FORMATS: [ash::vk::Format; 7] = [
    ash::vk::Format::R8G8B8A8_SRGB,
    ash::vk::Format::B8G8R8A8_SRGB,
    ash::vk::Format::R8G8B8A8_UNORM,
    ash::vk::Format::B8G8R8A8_UNORM,
    ash::vk::Format::D32_SFLOAT,
    ash::vk::Format::D16_UNORM,
    ash::vk::Format::D24_UNORM_S8_UINT,
];

/// The system Vulkan loader, loaded once and kept for the process lifetime.
fn system_entry() -> Result<ash::Entry, xr::Result> {
    static ENTRY: OnceLock<Option<ash::Entry>> = OnceLock::new();
    ENTRY
        .get_or_init(|| unsafe { ash::Entry::load() }.ok())
        .clone()
        .ok_or(xr::Result::ERROR_RUNTIME_FAILURE)
}

fn entry_for(state: &VulkanInstanceState) -> Result<ash::Entry, xr::Result> {
    match state.gipa {
        // SAFETY: PFN_vkGetInstanceProcAddr in openxr-sys and ash are the same C function type.
        Some(gipa) => Ok(unsafe {
            ash::Entry::from_static_fn(ash::StaticFn {
                get_instance_proc_addr: std::mem::transmute::<
                    xr::platform::VkGetInstanceProcAddr,
                    vk::PFN_vkGetInstanceProcAddr,
                >(gipa),
            })
        }),
        None => system_entry(),
    }
}

fn is_depth(format: vk::Format) -> bool {
    matches!(
        format,
        vk::Format::D32_SFLOAT | vk::Format::D16_UNORM | vk::Format::D24_UNORM_S8_UINT
    )
}

/// Validates an XrGraphicsBindingVulkanKHR and loads the device's functions.
pub(crate) unsafe fn open_session(
    state: &VulkanInstanceState,
    binding: &xr::GraphicsBindingVulkanKHR,
) -> Result<VulkanSession, xr::Result> {
    if binding.instance.is_null() {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    // No device is no valid graphics device: XR_ERROR_GRAPHICS_DEVICE_INVALID, which the CTS's
    // XR_KHR_vulkan_enable case requires for a VK_NULL_HANDLE device.
    if binding.physical_device.is_null() || binding.device.is_null() {
        return Err(xr::Result::ERROR_GRAPHICS_DEVICE_INVALID);
    }
    let physical_device = vk::PhysicalDevice::from_raw(binding.physical_device as u64);
    // Spec: the physical device must be the one xrGetVulkanGraphicsDevice(2)KHR returned.
    if state
        .physical_device
        .is_some_and(|pd| pd != physical_device)
    {
        return Err(xr::Result::ERROR_GRAPHICS_DEVICE_INVALID);
    }
    let entry = entry_for(state)?;
    let instance = ash::Instance::load(
        entry.static_fn(),
        vk::Instance::from_raw(binding.instance as u64),
    );
    let families = instance.get_physical_device_queue_family_properties(physical_device);
    let family = families
        .get(binding.queue_family_index as usize)
        .ok_or(xr::Result::ERROR_VALIDATION_FAILURE)?;
    if binding.queue_index >= family.queue_count {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    let device = ash::Device::load(
        instance.fp_v1_0(),
        vk::Device::from_raw(binding.device as u64),
    );
    let formats = FORMATS
        .iter()
        .copied()
        .filter(|f| {
            let features = instance
                .get_physical_device_format_properties(physical_device, *f)
                .optimal_tiling_features;
            let needed = if is_depth(*f) {
                vk::FormatFeatureFlags::DEPTH_STENCIL_ATTACHMENT
            } else {
                vk::FormatFeatureFlags::COLOR_ATTACHMENT
            };
            features.contains(needed)
        })
        .collect();
    let queue = device.get_device_queue(binding.queue_family_index, binding.queue_index);
    Ok(VulkanSession {
        instance,
        device,
        physical_device,
        queue_family: binding.queue_family_index,
        queue,
        formats,
    })
}

fn vk_error(_: vk::Result) -> xr::Result {
    xr::Result::ERROR_RUNTIME_FAILURE
}

/// Maps XR_SWAPCHAIN_USAGE_* to Vulkan usage (XR_KHR_vulkan_enable, "Swapchain usage flags"), plus
/// SAMPLED, which the compositor needs to read the images.
fn usage_flags(
    xr_usage: xr::SwapchainUsageFlags,
    features: vk::FormatFeatureFlags,
) -> vk::ImageUsageFlags {
    use xr::SwapchainUsageFlags as U;
    let map = [
        (U::COLOR_ATTACHMENT, vk::ImageUsageFlags::COLOR_ATTACHMENT),
        (
            U::DEPTH_STENCIL_ATTACHMENT,
            vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT,
        ),
        (U::UNORDERED_ACCESS, vk::ImageUsageFlags::STORAGE),
        (U::TRANSFER_SRC, vk::ImageUsageFlags::TRANSFER_SRC),
        (U::TRANSFER_DST, vk::ImageUsageFlags::TRANSFER_DST),
        (U::SAMPLED, vk::ImageUsageFlags::SAMPLED),
    ];
    let mut usage = map
        .iter()
        .filter(|(x, _)| xr_usage.contains(*x))
        .fold(vk::ImageUsageFlags::empty(), |u, (_, v)| u | *v);
    if features.contains(vk::FormatFeatureFlags::SAMPLED_IMAGE) {
        usage |= vk::ImageUsageFlags::SAMPLED;
    }
    usage
}

pub(crate) unsafe fn create_images(
    vk: &Arc<VulkanSession>,
    info: &xr::SwapchainCreateInfo,
    format: vk::Format,
    count: u32,
) -> Result<SwapchainImages, xr::Result> {
    let features = vk
        .instance
        .get_physical_device_format_properties(vk.physical_device, format)
        .optimal_tiling_features;
    let usage = usage_flags(info.usage_flags, features);
    let mut flags = vk::ImageCreateFlags::empty();
    if info
        .usage_flags
        .contains(xr::SwapchainUsageFlags::MUTABLE_FORMAT)
    {
        flags |= vk::ImageCreateFlags::MUTABLE_FORMAT;
    }
    if info.face_count == 6 {
        flags |= vk::ImageCreateFlags::CUBE_COMPATIBLE;
    }
    let layers = info.array_size * info.face_count;
    let samples = vk::SampleCountFlags::from_raw(info.sample_count);
    // Vulkan: multisampled images have one mip level and are not cube-compatible.
    if samples != vk::SampleCountFlags::TYPE_1 && (info.mip_count != 1 || info.face_count != 1) {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    let props = vk
        .instance
        .get_physical_device_image_format_properties(
            vk.physical_device,
            format,
            vk::ImageType::TYPE_2D,
            vk::ImageTiling::OPTIMAL,
            usage,
            flags,
        )
        .map_err(|_| xr::Result::ERROR_FEATURE_UNSUPPORTED)?;
    let fits = props.sample_counts.contains(samples)
        && props.max_array_layers >= layers
        && props.max_mip_levels >= info.mip_count
        && props.max_extent.width >= info.width
        && props.max_extent.height >= info.height;
    if !fits {
        return Err(xr::Result::ERROR_FEATURE_UNSUPPORTED);
    }
    let depth = is_depth(format);
    let (layout, aspect) = if depth {
        let aspect = if format == vk::Format::D24_UNORM_S8_UINT {
            vk::ImageAspectFlags::DEPTH | vk::ImageAspectFlags::STENCIL
        } else {
            vk::ImageAspectFlags::DEPTH
        };
        let layout = if usage.contains(vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT) {
            vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL
        } else {
            vk::ImageLayout::GENERAL
        };
        (layout, aspect)
    } else {
        let layout = if usage.contains(vk::ImageUsageFlags::COLOR_ATTACHMENT) {
            vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL
        } else {
            vk::ImageLayout::GENERAL
        };
        (layout, vk::ImageAspectFlags::COLOR)
    };
    let mut out = SwapchainImages {
        vk: vk.clone(),
        images: Vec::new(),
        prepared: vec![false; count as usize],
        layout,
        range: vk::ImageSubresourceRange {
            aspect_mask: aspect,
            base_mip_level: 0,
            level_count: info.mip_count,
            base_array_layer: 0,
            layer_count: layers,
        },
        pool: vk::CommandPool::null(),
        command_buffer: vk::CommandBuffer::null(),
        fence: vk::Fence::null(),
    };
    // On any error `out` is dropped, which destroys what was created so far.
    let memory_props = vk
        .instance
        .get_physical_device_memory_properties(vk.physical_device);
    for _ in 0..count {
        let create = vk::ImageCreateInfo::default()
            .flags(flags)
            .image_type(vk::ImageType::TYPE_2D)
            .format(format)
            .extent(vk::Extent3D {
                width: info.width,
                height: info.height,
                depth: 1,
            })
            .mip_levels(info.mip_count)
            .array_layers(layers)
            .samples(samples)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        let image = vk.device.create_image(&create, None).map_err(vk_error)?;
        let req = vk.device.get_image_memory_requirements(image);
        let type_index = memory_type(&memory_props, req.memory_type_bits);
        let memory = match type_index {
            Some(i) => vk.device.allocate_memory(
                &vk::MemoryAllocateInfo::default()
                    .allocation_size(req.size)
                    .memory_type_index(i),
                None,
            ),
            None => Err(vk::Result::ERROR_OUT_OF_DEVICE_MEMORY),
        };
        let memory = match memory {
            Ok(m) => m,
            Err(e) => {
                vk.device.destroy_image(image, None);
                return Err(vk_error(e));
            }
        };
        out.images.push((image, memory));
        vk.device
            .bind_image_memory(image, memory, 0)
            .map_err(vk_error)?;
    }
    out.pool = vk
        .device
        .create_command_pool(
            &vk::CommandPoolCreateInfo::default()
                .flags(
                    vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER
                        | vk::CommandPoolCreateFlags::TRANSIENT,
                )
                .queue_family_index(vk.queue_family),
            None,
        )
        .map_err(vk_error)?;
    out.command_buffer = vk
        .device
        .allocate_command_buffers(
            &vk::CommandBufferAllocateInfo::default()
                .command_pool(out.pool)
                .level(vk::CommandBufferLevel::PRIMARY)
                .command_buffer_count(1),
        )
        .map_err(vk_error)?[0];
    out.fence = vk
        .device
        .create_fence(&vk::FenceCreateInfo::default(), None)
        .map_err(vk_error)?;
    Ok(out)
}

/// Device-local memory if the image allows it, otherwise any allowed type.
fn memory_type(props: &vk::PhysicalDeviceMemoryProperties, bits: u32) -> Option<u32> {
    let allowed = |i: &u32| bits & (1 << i) != 0;
    let types = &props.memory_types[..props.memory_type_count as usize];
    (0..props.memory_type_count)
        .filter(allowed)
        .find(|i| {
            types[*i as usize]
                .property_flags
                .contains(vk::MemoryPropertyFlags::DEVICE_LOCAL)
        })
        .or_else(|| (0..props.memory_type_count).find(allowed))
}

impl SwapchainImages {
    pub fn image(&self, i: usize) -> vk::Image {
        self.images[i].0
    }

    /// Brings image `i` from UNDEFINED to its attachment layout the first time it is acquired, on
    /// the application's queue, and waits for it.
    pub unsafe fn prepare(&mut self, i: u32) -> Result<(), xr::Result> {
        if self.prepared[i as usize] {
            return Ok(());
        }
        let d = &self.vk.device;
        let cb = self.command_buffer;
        d.begin_command_buffer(
            cb,
            &vk::CommandBufferBeginInfo::default()
                .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
        )
        .map_err(vk_error)?;
        let barrier = vk::ImageMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::empty())
            .dst_access_mask(vk::AccessFlags::MEMORY_READ | vk::AccessFlags::MEMORY_WRITE)
            .old_layout(vk::ImageLayout::UNDEFINED)
            .new_layout(self.layout)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(self.images[i as usize].0)
            .subresource_range(self.range);
        d.cmd_pipeline_barrier(
            cb,
            vk::PipelineStageFlags::TOP_OF_PIPE,
            vk::PipelineStageFlags::ALL_COMMANDS,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[barrier],
        );
        d.end_command_buffer(cb).map_err(vk_error)?;
        let cbs = [cb];
        let submit = vk::SubmitInfo::default().command_buffers(&cbs);
        d.queue_submit(self.vk.queue, &[submit], self.fence)
            .map_err(vk_error)?;
        let waited = d.wait_for_fences(&[self.fence], true, u64::MAX);
        d.reset_fences(&[self.fence]).map_err(vk_error)?;
        waited.map_err(vk_error)?;
        self.prepared[i as usize] = true;
        Ok(())
    }
}

impl Drop for SwapchainImages {
    fn drop(&mut self) {
        let d = &self.vk.device;
        // SAFETY: every submission was waited on its fence, so none of these objects is in use by
        // the runtime; the application must not use images of a destroyed swapchain (spec).
        unsafe {
            if self.fence != vk::Fence::null() {
                d.destroy_fence(self.fence, None);
            }
            if self.pool != vk::CommandPool::null() {
                d.destroy_command_pool(self.pool, None);
            }
            for (image, memory) in self.images.drain(..) {
                d.destroy_image(image, None);
                d.free_memory(memory, None);
            }
        }
    }
}

/// What a desktop runtime asks of the application's VkInstance (Monado's list, trimmed to memory).
/// VK_KHR_external_memory_capabilities requires VK_KHR_get_physical_device_properties2 on a Vulkan
/// 1.0 instance (hello_xr's `-g Vulkan` makes one), so both are listed: a list that names one
/// without the other makes the Vulkan validation layer report VUID-vkCreateInstance-
/// ppEnabledExtensionNames-01388 in every app that follows it.
const INSTANCE_EXTENSIONS: &str =
    "VK_KHR_external_memory_capabilities VK_KHR_get_physical_device_properties2";
/// What the runtime asks of the VkDevice: what a compositor importing app images would need.
const DEVICE_EXTENSIONS: &str = "VK_KHR_external_memory";

pub(crate) unsafe extern "system" fn get_vulkan_instance_extensions(
    instance: xr::Instance,
    system_id: xr::SystemId,
    capacity: u32,
    count_out: *mut u32,
    buffer: *mut c_char,
) -> xr::Result {
    entry("xrGetVulkanInstanceExtensionsKHR", |ctx| {
        let mut w = world();
        w.enter_instance(ctx, instance)?;
        check_system(system_id)?;
        ffi::two_call_str(capacity, count_out, buffer, INSTANCE_EXTENSIONS)?;
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn get_vulkan_device_extensions(
    instance: xr::Instance,
    system_id: xr::SystemId,
    capacity: u32,
    count_out: *mut u32,
    buffer: *mut c_char,
) -> xr::Result {
    entry("xrGetVulkanDeviceExtensionsKHR", |ctx| {
        let mut w = world();
        w.enter_instance(ctx, instance)?;
        check_system(system_id)?;
        ffi::two_call_str(capacity, count_out, buffer, DEVICE_EXTENSIONS)?;
        Ok(xr::Result::SUCCESS)
    })
}

unsafe fn graphics_requirements(
    ctx: &mut crate::state::Ctx,
    instance: xr::Instance,
    system_id: xr::SystemId,
    requirements: *mut xr::GraphicsRequirementsVulkanKHR,
) -> crate::state::XrResult {
    let mut w = world();
    let id = w.enter_instance(ctx, instance)?;
    check_system(system_id)?;
    // GRAPHICS_REQUIREMENTS_VULKAN2_KHR is an alias of the same value.
    let p = ffi::output(
        requirements,
        xr::StructureType::GRAPHICS_REQUIREMENTS_VULKAN_KHR,
    )?;
    (*p).min_api_version_supported = xr::Version::new(1, 0, 0);
    (*p).max_api_version_supported = xr::Version::new(1, 3, 0);
    w.instances
        .get_mut(&id)
        .expect("entered instance exists")
        .graphics_requirements_queried = true;
    Ok(xr::Result::SUCCESS)
}

pub(crate) unsafe extern "system" fn get_vulkan_graphics_requirements(
    instance: xr::Instance,
    system_id: xr::SystemId,
    requirements: *mut xr::GraphicsRequirementsVulkanKHR,
) -> xr::Result {
    entry("xrGetVulkanGraphicsRequirementsKHR", |ctx| {
        graphics_requirements(ctx, instance, system_id, requirements)
    })
}

pub(crate) unsafe extern "system" fn get_vulkan_graphics_requirements2(
    instance: xr::Instance,
    system_id: xr::SystemId,
    requirements: *mut xr::GraphicsRequirementsVulkanKHR,
) -> xr::Result {
    entry("xrGetVulkanGraphicsRequirements2KHR", |ctx| {
        graphics_requirements(ctx, instance, system_id, requirements)
    })
}

/// The first physical device, or the first whose name contains `FOVEA_SIM_VK_DEVICE`.
unsafe fn pick_physical_device(
    entry: &ash::Entry,
    vk_instance: vk::Instance,
) -> Result<vk::PhysicalDevice, xr::Result> {
    let instance = ash::Instance::load(entry.static_fn(), vk_instance);
    let devices = instance.enumerate_physical_devices().map_err(vk_error)?;
    let wanted = std::env::var("FOVEA_SIM_VK_DEVICE")
        .ok()
        .filter(|s| !s.is_empty());
    let name_of = |pd: vk::PhysicalDevice| {
        let props = instance.get_physical_device_properties(pd);
        CStr::from_ptr(props.device_name.as_ptr())
            .to_string_lossy()
            .into_owned()
    };
    let found = match &wanted {
        Some(want) => devices
            .iter()
            .copied()
            .find(|pd| name_of(*pd).contains(want.as_str())),
        None => devices.first().copied(),
    };
    found.ok_or_else(|| {
        let names: Vec<String> = devices.iter().map(|pd| name_of(*pd)).collect();
        eprintln!("fovea-sim: no Vulkan device matches FOVEA_SIM_VK_DEVICE={wanted:?}; devices: {names:?}");
        xr::Result::ERROR_RUNTIME_FAILURE
    })
}

unsafe fn graphics_device(
    ctx: &mut crate::state::Ctx,
    w: &mut World,
    id: u64,
    system_id: xr::SystemId,
    vk_instance: xr::platform::VkInstance,
    physical_device: *mut xr::platform::VkPhysicalDevice,
) -> crate::state::XrResult {
    check_system(system_id)?;
    ffi::non_null(physical_device)?;
    if vk_instance.is_null() {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    let vk_instance = vk::Instance::from_raw(vk_instance as u64);
    let state = &mut w
        .instances
        .get_mut(&id)
        .expect("entered instance exists")
        .vulkan;
    let pd = pick_physical_device(&entry_for(state)?, vk_instance)?;
    state.vk_instance = Some(vk_instance);
    state.physical_device = Some(pd);
    ctx.detail = format!("physical device {:#x}", pd.as_raw());
    *physical_device = pd.as_raw() as usize as xr::platform::VkPhysicalDevice;
    Ok(xr::Result::SUCCESS)
}

pub(crate) unsafe extern "system" fn get_vulkan_graphics_device(
    instance: xr::Instance,
    system_id: xr::SystemId,
    vk_instance: xr::platform::VkInstance,
    physical_device: *mut xr::platform::VkPhysicalDevice,
) -> xr::Result {
    entry("xrGetVulkanGraphicsDeviceKHR", |ctx| {
        let mut w = world();
        let id = w.enter_instance(ctx, instance)?;
        graphics_device(ctx, &mut w, id, system_id, vk_instance, physical_device)
    })
}

pub(crate) unsafe extern "system" fn get_vulkan_graphics_device2(
    instance: xr::Instance,
    get_info: *const xr::VulkanGraphicsDeviceGetInfoKHR,
    physical_device: *mut xr::platform::VkPhysicalDevice,
) -> xr::Result {
    entry("xrGetVulkanGraphicsDevice2KHR", |ctx| {
        let mut w = world();
        let id = w.enter_instance(ctx, instance)?;
        let info = ffi::input(
            get_info,
            xr::StructureType::VULKAN_GRAPHICS_DEVICE_GET_INFO_KHR,
        )?;
        ctx.next_types = ffi::chain_types(info.next);
        graphics_device(
            ctx,
            &mut w,
            id,
            info.system_id,
            info.vulkan_instance,
            physical_device,
        )
    })
}

/// Looks a Vulkan command up through the application's loader.
unsafe fn vk_proc(
    gipa: xr::platform::VkGetInstanceProcAddr,
    instance: xr::platform::VkInstance,
    name: &CStr,
) -> Result<unsafe extern "system" fn(), xr::Result> {
    gipa(instance, name.as_ptr()).ok_or(xr::Result::ERROR_RUNTIME_FAILURE)
}

pub(crate) unsafe extern "system" fn create_vulkan_instance(
    instance: xr::Instance,
    create_info: *const xr::VulkanInstanceCreateInfoKHR,
    vulkan_instance: *mut xr::platform::VkInstance,
    vulkan_result: *mut xr::platform::VkResult,
) -> xr::Result {
    entry("xrCreateVulkanInstanceKHR", |ctx| {
        let id;
        let info = {
            let mut w = world();
            id = w.enter_instance(ctx, instance)?;
            *ffi::input(
                create_info,
                xr::StructureType::VULKAN_INSTANCE_CREATE_INFO_KHR,
            )?
        };
        ctx.next_types = ffi::chain_types(info.next);
        check_system(info.system_id)?;
        ffi::non_null(vulkan_instance)?;
        ffi::non_null(vulkan_result)?;
        ffi::non_null(info.vulkan_create_info)?;
        let gipa = info
            .pfn_get_instance_proc_addr
            .ok_or(xr::Result::ERROR_VALIDATION_FAILURE)?;
        if info.create_flags != xr::VulkanInstanceCreateFlagsKHR::EMPTY {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        let create: vk::PFN_vkCreateInstance =
            std::mem::transmute(vk_proc(gipa, std::ptr::null(), c"vkCreateInstance")?);
        // The runtime needs nothing from Vulkan, so the application's create info goes through
        // unchanged; the call is made without the runtime lock held.
        let mut out = vk::Instance::null();
        let result = create(
            info.vulkan_create_info as *const vk::InstanceCreateInfo,
            info.vulkan_allocator as *const vk::AllocationCallbacks,
            &mut out,
        );
        *vulkan_result = result.as_raw();
        ctx.detail = format!("vkCreateInstance {result:?}");
        if result == vk::Result::SUCCESS {
            *vulkan_instance = out.as_raw() as usize as *const c_void;
            if let Some(inst) = world().instances.get_mut(&id) {
                inst.vulkan.gipa = Some(gipa);
                inst.vulkan.vk_instance = Some(out);
            }
        }
        // The Vulkan error travels in vulkanResult; the OpenXR call itself succeeded.
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn create_vulkan_device(
    instance: xr::Instance,
    create_info: *const xr::VulkanDeviceCreateInfoKHR,
    vulkan_device: *mut xr::platform::VkDevice,
    vulkan_result: *mut xr::platform::VkResult,
) -> xr::Result {
    entry("xrCreateVulkanDeviceKHR", |ctx| {
        let (info, vk_instance, picked) = {
            let mut w = world();
            let id = w.enter_instance(ctx, instance)?;
            let info = *ffi::input(
                create_info,
                xr::StructureType::VULKAN_DEVICE_CREATE_INFO_KHR,
            )?;
            let state = &w.instances[&id].vulkan;
            (info, state.vk_instance, state.physical_device)
        };
        ctx.next_types = ffi::chain_types(info.next);
        check_system(info.system_id)?;
        ffi::non_null(vulkan_device)?;
        ffi::non_null(vulkan_result)?;
        ffi::non_null(info.vulkan_create_info)?;
        let gipa = info
            .pfn_get_instance_proc_addr
            .ok_or(xr::Result::ERROR_VALIDATION_FAILURE)?;
        if info.create_flags != xr::VulkanDeviceCreateFlagsKHR::EMPTY {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        let pd = vk::PhysicalDevice::from_raw(info.vulkan_physical_device as u64);
        // Spec: the physical device must be the one xrGetVulkanGraphicsDevice2KHR returned.
        let (Some(vk_instance), true) = (vk_instance, picked == Some(pd)) else {
            return Err(xr::Result::ERROR_HANDLE_INVALID);
        };
        let create: vk::PFN_vkCreateDevice = std::mem::transmute(vk_proc(
            gipa,
            vk_instance.as_raw() as usize as *const c_void,
            c"vkCreateDevice",
        )?);
        let mut out = vk::Device::null();
        let result = create(
            pd,
            info.vulkan_create_info as *const vk::DeviceCreateInfo,
            info.vulkan_allocator as *const vk::AllocationCallbacks,
            &mut out,
        );
        *vulkan_result = result.as_raw();
        ctx.detail = format!("vkCreateDevice {result:?}");
        if result == vk::Result::SUCCESS {
            *vulkan_device = out.as_raw() as usize as *const c_void;
        }
        Ok(xr::Result::SUCCESS)
    })
}
