//! What fovea keeps of a session's Vulkan device for its density images: the graphics binding,
//! the system loader's entry points, what the device supports for fragment density maps (the
//! images' texel size, usage and final layout), and the queue, command pool and fence it submits
//! uploads with ([`SessionGpu`]). The images themselves are [`crate::xr::density_images`]'s.
//!
//! Entry points come from the system Vulkan loader (`ash::Entry::load`), as with
//! XR_KHR_vulkan_enable (v1) a runtime must do too: the binding carries no `vkGetInstanceProcAddr`.
//! That assumes the application uses the same loader, which is what the spec assumes of runtimes.

use std::ffi::CStr;
use std::sync::OnceLock;

use ash::vk;
use ash::vk::Handle as _;

use crate::common::lock::{Mutex, Rank};
use fovea_model::maps::DEFAULT_TEXEL;

/// The density image format: the one Vulkan makes mandatory for FDM (fragmentdensitymapops.adoc).
pub const FORMAT: vk::Format = vk::Format::R8G8_UNORM;

/// `XrGraphicsBindingVulkanKHR`'s handles, as raw values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VulkanBinding {
    pub instance: u64,
    pub physical_device: u64,
    pub device: u64,
    pub queue_family_index: u32,
    pub queue_index: u32,
}

/// A failed Vulkan step, for the log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VkError {
    pub step: &'static str,
    pub result: vk::Result,
}

impl std::fmt::Display for VkError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} failed: {:?}", self.step, self.result)
    }
}

pub(crate) fn step(step: &'static str) -> impl Fn(vk::Result) -> VkError {
    move |result| VkError { step, result }
}

/// The system Vulkan loader, loaded once per process (never unloaded: the application's objects
/// live in it).
pub fn entry() -> Option<&'static ash::Entry> {
    static ENTRY: OnceLock<Option<ash::Entry>> = OnceLock::new();
    ENTRY
        // SAFETY: loading the system Vulkan loader runs no application code; it is kept for the
        // process's lifetime, so no function pointer from it outlives it.
        .get_or_init(|| match unsafe { ash::Entry::load() } {
            Ok(e) => Some(e),
            Err(e) => {
                tracing::warn!(error = %e, "cannot load the Vulkan loader; no density images");
                None
            }
        })
        .as_ref()
}

/// Instance-level functions for the application's VkInstance.
///
/// # Safety
/// `instance` must be a live VkInstance of the system loader.
pub unsafe fn instance_fns(entry: &ash::Entry, instance: u64) -> ash::Instance {
    // SAFETY: the caller's contract: a live VkInstance of this loader.
    unsafe { ash::Instance::load(entry.static_fn(), vk::Instance::from_raw(instance)) }
}

/// What a physical device offers of VK_EXT_fragment_density_map(2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FdmSupport {
    /// VK_EXT_fragment_density_map is among the device's extensions.
    pub extension: bool,
    /// VK_EXT_fragment_density_map2 is among the device's extensions.
    pub extension2: bool,
    /// `VkPhysicalDeviceFragmentDensityMapFeaturesEXT::fragmentDensityMap`.
    pub feature: bool,
    /// `VkPhysicalDeviceFragmentDensityMapPropertiesEXT` texel sizes ([0, 0] when unknown).
    pub min_texel: [u32; 2],
    pub max_texel: [u32; 2],
}

impl FdmSupport {
    /// The density texel size: the device's smallest (the finest map it can use), clamped into its
    /// [min, max] range; [`DEFAULT_TEXEL`] where the device has no FDM or reports nonsense.
    pub fn texel(&self) -> [u32; 2] {
        let valid = self.extension
            && (0..2).all(|i| self.min_texel[i] >= 1 && self.min_texel[i] <= self.max_texel[i]);
        if !valid {
            return DEFAULT_TEXEL;
        }
        [0, 1].map(|i| self.min_texel[i].clamp(self.min_texel[i], self.max_texel[i]))
    }
}

/// Looks an instance-level command up, `None` where the loader has none (a 1.1 command on a 1.0
/// loader, say), so ash's panicking placeholder is never called.
///
/// # Safety
/// `instance` must be a live instance of `entry`'s loader.
unsafe fn instance_proc(
    entry: &ash::Entry,
    instance: &ash::Instance,
    names: &[&CStr],
) -> Option<vk::PFN_vkVoidFunction> {
    names.iter().find_map(|n| {
        // SAFETY: the caller's contract; the name is NUL-terminated.
        let f = unsafe { entry.get_instance_proc_addr(instance.handle(), n.as_ptr()) };
        f.is_some().then_some(f)
    })
}

/// Asks a physical device what it offers of VK_EXT_fragment_density_map. Features and properties
/// need vkGetPhysicalDevice{Features,Properties}2 (core 1.1, or
/// VK_KHR_get_physical_device_properties2, which FDM requires anyway); they are only asked for when
/// the extension is there, so a device without FDM (lavapipe, desktop drivers) sees core 1.0 calls
/// only.
///
/// # Safety
/// `instance` must be the physical device's live instance.
pub unsafe fn query_support(
    entry: &ash::Entry,
    instance: &ash::Instance,
    physical_device: vk::PhysicalDevice,
) -> FdmSupport {
    let mut s = FdmSupport::default();
    // SAFETY: the caller's contract: a live instance and one of its physical devices.
    let Ok(exts) = (unsafe { instance.enumerate_device_extension_properties(physical_device) })
    else {
        return s;
    };
    let has = |name: &CStr| exts.iter().any(|e| e.extension_name_as_c_str() == Ok(name));
    s.extension = has(ash::ext::fragment_density_map::NAME);
    s.extension2 = has(ash::ext::fragment_density_map2::NAME);
    if !s.extension {
        return s;
    }
    let names = [
        c"vkGetPhysicalDeviceFeatures2",
        c"vkGetPhysicalDeviceFeatures2KHR",
    ];
    // SAFETY: the caller's contract.
    if let Some(f) = unsafe { instance_proc(entry, instance, &names) } {
        // SAFETY: the loader's pointer for that name has that signature (the KHR alias too).
        let f = unsafe {
            std::mem::transmute::<vk::PFN_vkVoidFunction, vk::PFN_vkGetPhysicalDeviceFeatures2>(f)
        };
        let mut fdm = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default();
        let mut features = vk::PhysicalDeviceFeatures2::default().push_next(&mut fdm);
        // SAFETY: a physical device of the live instance; the output chain is made of locals.
        unsafe { f(physical_device, &mut features) };
        s.feature = fdm.fragment_density_map == vk::TRUE;
    }
    let names = [
        c"vkGetPhysicalDeviceProperties2",
        c"vkGetPhysicalDeviceProperties2KHR",
    ];
    // SAFETY: the caller's contract.
    if let Some(f) = unsafe { instance_proc(entry, instance, &names) } {
        // SAFETY: the loader's pointer for that name has that signature (the KHR alias too).
        let f = unsafe {
            std::mem::transmute::<vk::PFN_vkVoidFunction, vk::PFN_vkGetPhysicalDeviceProperties2>(f)
        };
        let mut fdm = vk::PhysicalDeviceFragmentDensityMapPropertiesEXT::default();
        let mut props = vk::PhysicalDeviceProperties2::default().push_next(&mut fdm);
        // SAFETY: as above.
        unsafe { f(physical_device, &mut props) };
        let e = |x: vk::Extent2D| [x.width, x.height];
        s.min_texel = e(fdm.min_fragment_density_texel_size);
        s.max_texel = e(fdm.max_fragment_density_texel_size);
    }
    s
}

/// The density images' usage: FRAGMENT_DENSITY_MAP where FDM is usable on the device and the format
/// supports it, plus SAMPLED, STORAGE and the transfers where the format's optimal-tiling features
/// allow. Before Vulkan 1.1 (and VK_KHR_maintenance1) formats do not report TRANSFER_SRC/DST and
/// every format allows transfers.
pub fn usage_for(
    features: vk::FormatFeatureFlags,
    fdm: bool,
    device_api: u32,
) -> vk::ImageUsageFlags {
    use vk::FormatFeatureFlags as F;
    use vk::ImageUsageFlags as U;
    let pre_1_1 = vk::api_version_major(device_api) == 1 && vk::api_version_minor(device_api) == 0;
    let mut usage = U::empty();
    let pairs = [
        (
            F::FRAGMENT_DENSITY_MAP_EXT,
            U::FRAGMENT_DENSITY_MAP_EXT,
            fdm,
        ),
        (F::SAMPLED_IMAGE, U::SAMPLED, true),
        (F::STORAGE_IMAGE, U::STORAGE, true),
        (F::TRANSFER_SRC, U::TRANSFER_SRC, true),
        (F::TRANSFER_DST, U::TRANSFER_DST, true),
    ];
    for (feature, bit, wanted) in pairs {
        if wanted && features.contains(feature) {
            usage |= bit;
        }
    }
    if pre_1_1 {
        usage |= U::TRANSFER_SRC | U::TRANSFER_DST;
    }
    usage
}

/// The layout (and the access that reads it) density images are left in after an upload:
/// FRAGMENT_DENSITY_MAP_OPTIMAL_EXT for an FDM attachment; SHADER_READ_ONLY_OPTIMAL for images
/// engines sample or convert; GENERAL where the images can do neither.
pub fn final_layout(usage: vk::ImageUsageFlags) -> (vk::ImageLayout, vk::AccessFlags) {
    use vk::ImageUsageFlags as U;
    if usage.contains(U::FRAGMENT_DENSITY_MAP_EXT) {
        (
            vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT,
            vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT,
        )
    } else if usage.contains(U::SAMPLED) {
        (
            vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
            vk::AccessFlags::SHADER_READ,
        )
    } else {
        (vk::ImageLayout::GENERAL, vk::AccessFlags::MEMORY_READ)
    }
}

/// A memory type allowed by `bits` with all of `wanted`, else (when `fallback`) any allowed type.
pub(crate) fn memory_type(
    props: &vk::PhysicalDeviceMemoryProperties,
    bits: u32,
    wanted: vk::MemoryPropertyFlags,
    fallback: bool,
) -> Option<u32> {
    let allowed = |i: &u32| bits & (1 << i) != 0;
    let types = &props.memory_types[..props.memory_type_count as usize];
    (0..props.memory_type_count)
        .filter(allowed)
        .find(|i| types[*i as usize].property_flags.contains(wanted))
        .or_else(|| {
            fallback
                .then(|| (0..props.memory_type_count).find(allowed))
                .flatten()
        })
}

/// What the queue mutex guards: the binding's queue and the session's command pool and fence.
/// Command pools and queues need external synchronisation (Vulkan "Threading Behavior"), and one
/// session's swapchains may be acquired from different threads.
pub(crate) struct Submit {
    pub(crate) queue: vk::Queue,
    pub(crate) pool: vk::CommandPool,
    pub(crate) fence: vk::Fence,
}

/// fovea's Vulkan objects for one session, on the device of its XrGraphicsBindingVulkanKHR.
pub struct SessionGpu {
    pub(crate) instance: ash::Instance,
    pub(crate) device: ash::Device,
    /// Density texel size in framebuffer pixels.
    pub texel: [u32; 2],
    /// Usage of the density images.
    pub usage: vk::ImageUsageFlags,
    /// Whether the device takes density-map offsets on density maps
    /// (docs/vulkan-layer.md#density-map-offsets); `None` where fovea cannot tell (neither its
    /// Vulkan layer nor `xrCreateVulkanDeviceKHR` saw the device created). Where it does, fovea's
    /// density images for swapchains whose application applies offsets are made with
    /// `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT` (docs/eye-tracking.md#what-moves-when).
    pub offsets: Option<bool>,
    pub(crate) memory: vk::PhysicalDeviceMemoryProperties,
    pub(crate) physical_device: vk::PhysicalDevice,
    pub(crate) submit: Mutex<Submit>,
}

impl SessionGpu {
    /// Sets up for a session: reads what the device supports, creates the command pool on the
    /// binding's queue family and the fence. `fdm_enabled`: the application's device has
    /// VK_EXT_fragment_density_map enabled (known from xrCreateVulkanDeviceKHR or the extension
    /// list fovea handed out, see `hooks::vulkan`). `offsets`: whether it enabled a density-map
    /// offset extension with its feature and offsets reach density maps there (`None`: unknown);
    /// they count only where the images are density maps.
    ///
    /// # Safety
    /// The binding's handles must be live objects of the system Vulkan loader.
    pub unsafe fn new(
        binding: &VulkanBinding,
        fdm_enabled: bool,
        offsets: Option<bool>,
    ) -> Result<SessionGpu, VkError> {
        let no_loader = VkError {
            step: "loading the Vulkan loader",
            result: vk::Result::ERROR_INITIALIZATION_FAILED,
        };
        let entry = entry().ok_or(no_loader)?;
        let physical_device = vk::PhysicalDevice::from_raw(binding.physical_device);
        // SAFETY: the caller's contract: the binding's VkInstance and VkPhysicalDevice are live
        // objects of the system loader; these are queries only.
        let (instance, support, props, features, memory) = unsafe {
            let instance = instance_fns(entry, binding.instance);
            let support = query_support(entry, &instance, physical_device);
            let props = instance.get_physical_device_properties(physical_device);
            let features = instance
                .get_physical_device_format_properties(physical_device, FORMAT)
                .optimal_tiling_features;
            let memory = instance.get_physical_device_memory_properties(physical_device);
            (instance, support, props, features, memory)
        };
        let fdm = fdm_enabled && support.extension;
        let usage = usage_for(features, fdm, props.api_version);
        if !usage.contains(vk::ImageUsageFlags::TRANSFER_DST) {
            return Err(VkError {
                step: "R8G8_UNORM as a transfer destination",
                result: vk::Result::ERROR_FORMAT_NOT_SUPPORTED,
            });
        }
        // SAFETY: the caller's contract: the binding's VkDevice is live and its queue family and
        // index name a queue it was created with (XrGraphicsBindingVulkanKHR's valid usage). The
        // pool and fence are fovea's own; the pool is destroyed if the fence cannot be made.
        let (device, queue, pool, fence) = unsafe {
            let device =
                ash::Device::load(instance.fp_v1_0(), vk::Device::from_raw(binding.device));
            let queue = device.get_device_queue(binding.queue_family_index, binding.queue_index);
            let pool = device
                .create_command_pool(
                    &vk::CommandPoolCreateInfo::default()
                        .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER)
                        .queue_family_index(binding.queue_family_index),
                    None,
                )
                .map_err(step("vkCreateCommandPool"))?;
            let fence = match device.create_fence(&vk::FenceCreateInfo::default(), None) {
                Ok(f) => f,
                Err(e) => {
                    device.destroy_command_pool(pool, None);
                    return Err(step("vkCreateFence")(e));
                }
            };
            (device, queue, pool, fence)
        };
        tracing::info!(
            texel = ?support.texel(),
            ?usage,
            fdm_extension = support.extension,
            fdm_feature = support.feature,
            fdm_enabled,
            ?offsets,
            "density images for this session"
        );
        // The log file's session line (after the instance header): which GPU, and how its density
        // maps reach the rasterizer.
        let gpu = props
            .device_name_as_c_str()
            .map_or_else(|_| "unknown".into(), |n| n.to_string_lossy().into_owned());
        let maps = if crate::bridge::device_fdm(vk::Device::from_raw(binding.device)).is_some() {
            "emulated on shading-rate attachments"
        } else if fdm {
            "native VK_EXT_fragment_density_map"
        } else {
            "not attached by this device (density images only)"
        };
        crate::common::log::header(&format!(
            "fovea session: gpu={gpu:?} density_maps={maps:?} texel={:?}",
            support.texel()
        ));
        Ok(SessionGpu {
            memory,
            instance,
            device,
            texel: support.texel(),
            usage,
            offsets: offsets.map(|o| o && fdm),
            physical_device,
            submit: Mutex::ranked(Rank::GpuSubmit, "gpu submit", Submit { queue, pool, fence }),
        })
    }
}

impl Drop for SessionGpu {
    fn drop(&mut self) {
        let s = self.submit.get_mut();
        // SAFETY: every submission was waited on the fence before its call returned, and the
        // swapchains' command buffers were freed with them (they hold this record's Arc).
        unsafe {
            self.device.destroy_fence(s.fence, None);
            self.device.destroy_command_pool(s.pool, None);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texel_size_is_the_devices_minimum_or_the_default() {
        let mut s = FdmSupport::default();
        assert_eq!(s.texel(), DEFAULT_TEXEL);
        s.extension = true;
        assert_eq!(s.texel(), DEFAULT_TEXEL, "no properties read");
        s.min_texel = [16, 8];
        s.max_texel = [64, 64];
        assert_eq!(s.texel(), [16, 8]);
        s.max_texel = [8, 8];
        assert_eq!(s.texel(), DEFAULT_TEXEL, "min above max is nonsense");
    }

    #[test]
    fn usage_follows_format_features_and_fdm() {
        use vk::FormatFeatureFlags as F;
        use vk::ImageUsageFlags as U;
        let all = F::FRAGMENT_DENSITY_MAP_EXT
            | F::SAMPLED_IMAGE
            | F::STORAGE_IMAGE
            | F::TRANSFER_SRC
            | F::TRANSFER_DST;
        let v13 = vk::make_api_version(0, 1, 3, 0);
        assert_eq!(
            usage_for(all, true, v13),
            U::FRAGMENT_DENSITY_MAP_EXT
                | U::SAMPLED
                | U::STORAGE
                | U::TRANSFER_SRC
                | U::TRANSFER_DST
        );
        assert_eq!(
            usage_for(all, false, v13),
            U::SAMPLED | U::STORAGE | U::TRANSFER_SRC | U::TRANSFER_DST
        );
        assert_eq!(
            usage_for(F::SAMPLED_IMAGE, false, v13),
            U::SAMPLED,
            "no transfer bits reported on 1.1+"
        );
        assert_eq!(
            usage_for(F::SAMPLED_IMAGE, false, vk::make_api_version(0, 1, 0, 0)),
            U::SAMPLED | U::TRANSFER_SRC | U::TRANSFER_DST,
            "1.0 formats do not report transfers and allow them"
        );
        assert_eq!(
            final_layout(U::FRAGMENT_DENSITY_MAP_EXT | U::SAMPLED).0,
            vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT
        );
        assert_eq!(
            final_layout(U::SAMPLED | U::TRANSFER_DST).0,
            vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL
        );
        assert_eq!(final_layout(U::TRANSFER_DST).0, vk::ImageLayout::GENERAL);
    }
}
