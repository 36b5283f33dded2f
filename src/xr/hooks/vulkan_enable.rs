//! Vulkan device set-up through XR_KHR_vulkan_enable and XR_KHR_vulkan_enable2: fovea asks for
//! VK_EXT_fragment_density_map where the application enabled XR_FB_foveation_vulkan, so its density
//! images can be real FDM attachments
//! (https://registry.khronos.org/OpenXR/specs/1.0/man/html/xrCreateVulkanDeviceKHR.html,
//! https://registry.khronos.org/OpenXR/specs/1.0/man/html/xrGetVulkanDeviceExtensionsKHR.html).

use std::ffi::{c_char, c_void, CStr};

use ash::vk;
use ash::vk::Handle as _;
use openxr_sys as xr;
use xr::Handle;

use crate::xr::extensions::Ext;
use crate::xr::ffi::HookResult;
use crate::xr::ffi::{In, Out, OutArray};
use crate::xr::next_layer::next;
use crate::xr::registry::instance;
use crate::xr::registry::{registry, Instance, VulkanDevice};
use crate::xr::session_gpu;
use crate::xr::values::succeeded;

/// What the physical device the application picked supports, if fovea knows the device.
fn recorded_support(state: &Instance) -> Option<(u64, session_gpu::FdmSupport)> {
    let (vk_instance, pd) = state.vulkan.lock().graphics_device?;
    Some((pd, support_of(vk_instance, pd)?))
}

/// Asks a physical device of a VkInstance the runtime handed out (or was handed) about FDM.
fn support_of(vk_instance: u64, pd: u64) -> Option<session_gpu::FdmSupport> {
    let entry = session_gpu::entry()?;
    // SAFETY: the recorded VkInstance is live: the application made it for the runtime and must
    // keep it while the OpenXR instance uses it (XR_KHR_vulkan_enable), and `pd` came from it.
    unsafe {
        let instance = session_gpu::instance_fns(entry, vk_instance);
        Some(session_gpu::query_support(
            entry,
            &instance,
            vk::PhysicalDevice::from_raw(pd),
        ))
    }
}

/// The device extension names fovea adds to the runtime's list, given what it knows of the device.
///
/// Where the physical device is known (xrGetVulkanGraphicsDeviceKHR was called first, as the spec's
/// own order and hello_xr have it), exactly the FDM extensions it supports. Where it is not, only
/// VK_EXT_fragment_density_map: an application that then enables it on a device
/// without it fails vkCreateDevice, which is why the known-device path is preferred (docs/vulkan-layer.md).
pub fn extensions_to_add(support: Option<session_gpu::FdmSupport>) -> Vec<&'static CStr> {
    match support {
        Some(s) => {
            let mut v = Vec::new();
            if s.extension {
                v.push(ash::ext::fragment_density_map::NAME);
                if s.extension2 {
                    v.push(ash::ext::fragment_density_map2::NAME);
                }
            }
            v
        }
        None => vec![ash::ext::fragment_density_map::NAME],
    }
}

/// The runtime's space-separated list with `add` appended, each name once.
pub fn append_extensions(runtime: &str, add: &[&CStr]) -> String {
    let mut out = runtime.trim_end_matches('\0').to_owned();
    for name in add {
        let name = name.to_str().unwrap_or_default();
        if out.split(' ').any(|n| n == name) {
            continue;
        }
        if !out.is_empty() {
            out.push(' ');
        }
        out.push_str(name);
    }
    out
}

/// The two-call idiom for a string
/// (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#buffer-size-parameters): counts
/// include the terminating NUL; capacity 0 asks for the size; a non-zero capacity below it is
/// XR_ERROR_SIZE_INSUFFICIENT with the size written.
fn two_call_str(s: &str, count: Out<u32>, buffer: OutArray<c_char>) -> xr::Result {
    let capacity = buffer.capacity();
    if count.is_null() || (capacity > 0 && buffer.is_null()) {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    let needed = s.len() as u32 + 1;
    count.write(needed);
    if capacity == 0 {
        return xr::Result::SUCCESS;
    }
    if capacity < needed {
        return xr::Result::ERROR_SIZE_INSUFFICIENT;
    }
    let Some(dst) = buffer.into_slice(needed as usize) else {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    };
    for (d, b) in dst.iter_mut().zip(s.bytes().chain([0])) {
        *d = b as c_char;
    }
    xr::Result::SUCCESS
}

/// `xrGetVulkanDeviceExtensionsKHR` (enable): where fovea provides XR_FB_foveation_vulkan, the
/// runtime's list plus the FDM extensions (see [`extensions_to_add`]), with counts recomputed.
pub fn get_vulkan_device_extensions(
    inst: xr::Instance,
    system: xr::SystemId,
    capacity: u32,
    count: Out<u32>,
    buffer: OutArray<c_char>,
) -> HookResult<xr::Result> {
    let s = instance(inst)?;
    let f = next(s.next.get_vulkan_device_extensions)?;
    if !s.extensions.provided(Ext::FoveationVulkan) {
        // SAFETY: the next layer's function, with the application's arguments as it passed them.
        return Ok(unsafe { f(inst, system, capacity, count.raw(), buffer.raw()) });
    }
    let runtime = runtime_string(f, inst, system)?;
    let support = recorded_support(&s);
    let add = extensions_to_add(support.map(|(_, s)| s));
    let list = append_extensions(&runtime, &add);
    let r = two_call_str(&list, count, buffer);
    if r == xr::Result::SUCCESS && capacity > 0 && !add.is_empty() {
        let mut v = s.vulkan.lock();
        v.fdm_listed = true;
        v.fdm_listed_for = support.map(|(pd, _)| pd);
        if support.is_none() {
            tracing::warn!(
                "VK_EXT_fragment_density_map listed before xrGetVulkanGraphicsDeviceKHR: \
                 vkCreateDevice fails if the device lacks it"
            );
        }
    }
    Ok(r)
}

/// The runtime's own extension string, through its two-call idiom.
fn runtime_string(
    f: xr::pfn::GetVulkanDeviceExtensionsKHR,
    inst: xr::Instance,
    system: xr::SystemId,
) -> HookResult<String> {
    let mut n = 0;
    // SAFETY: the next layer's function; capacity 0 writes only the count, into a local.
    let r = unsafe { f(inst, system, 0, &mut n, std::ptr::null_mut()) };
    if !succeeded(r) {
        return Err(r);
    }
    let mut buf = vec![0u8; n.max(1) as usize];
    // SAFETY: as above; `buf` holds at least the `n` bytes the capacity says.
    let r = unsafe { f(inst, system, n, &mut n, buf.as_mut_ptr() as *mut c_char) };
    if !succeeded(r) {
        return Err(r);
    }
    let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    Ok(String::from_utf8_lossy(&buf[..end]).into_owned())
}

/// Records the physical device the runtime picked, with the VkInstance it came from.
fn record_graphics_device(state: &Instance, vk_instance: xr::platform::VkInstance, pd: u64) {
    if !vk_instance.is_null() && pd != 0 {
        state.vulkan.lock().graphics_device = Some((vk_instance as u64, pd));
    }
}

/// `xrGetVulkanGraphicsDeviceKHR` (enable): passed on; the device is recorded so that
/// xrGetVulkanDeviceExtensionsKHR lists only the FDM extensions it has.
pub fn get_vulkan_graphics_device(
    inst: xr::Instance,
    system: xr::SystemId,
    vk_instance: xr::platform::VkInstance,
    physical_device: Out<xr::platform::VkPhysicalDevice>,
) -> HookResult<xr::Result> {
    let s = instance(inst)?;
    let f = next(s.next.get_vulkan_graphics_device)?;
    // SAFETY: the next layer's function, with the application's arguments as it passed them.
    let r = unsafe { f(inst, system, vk_instance, physical_device.raw()) };
    if let (true, Some(pd)) = (succeeded(r), physical_device.read()) {
        record_graphics_device(&s, vk_instance, pd as u64);
        crate::bridge::inject::legacy_enable_used();
    }
    Ok(r)
}

/// `xrGetVulkanGraphicsDevice2KHR` (enable2): passed on; the device is recorded.
pub fn get_vulkan_graphics_device2(
    inst: xr::Instance,
    info: In<xr::VulkanGraphicsDeviceGetInfoKHR>,
    physical_device: Out<xr::platform::VkPhysicalDevice>,
) -> HookResult<xr::Result> {
    let s = instance(inst)?;
    let f = next(s.next.get_vulkan_graphics_device2)?;
    // SAFETY: the next layer's function, with the application's arguments as it passed them.
    let r = unsafe { f(inst, info.raw(), physical_device.raw()) };
    if let (true, Some(pd), Some(info)) = (succeeded(r), physical_device.read(), info.get()) {
        record_graphics_device(&s, info.vulkan_instance, pd as u64);
    }
    Ok(r)
}

/// What the application's VkDeviceCreateInfo already asks of FDM.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AppDeviceRequest {
    pub extension: bool,
    /// `Some(enabled)` when its pNext holds VkPhysicalDeviceFragmentDensityMapFeaturesEXT.
    pub feature_struct: Option<bool>,
    /// VK_EXT_fragment_density_map_offset or VK_QCOM_fragment_density_map_offset is named and
    /// `fragmentDensityMapOffset` enabled: density maps made with
    /// `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT` are valid on the device.
    pub offsets: bool,
}

/// What fovea adds to a device create info: (add the extension name, chain a features struct), and
/// whether FDM ends up enabled. Nothing is added that the device lacks; a features struct the
/// application chained itself is respected (Vulkan forbids a second one of the same type).
pub fn device_plan(support: session_gpu::FdmSupport, app: AppDeviceRequest) -> (bool, bool, bool) {
    let add_extension = support.extension && !app.extension;
    let add_feature = support.extension && support.feature && app.feature_struct.is_none();
    let extension = app.extension || add_extension;
    let feature = app.feature_struct.unwrap_or(add_feature);
    (add_extension, add_feature, extension && feature)
}

/// Reads the application's VkDeviceCreateInfo for FDM.
///
/// # Safety
/// `info` must be a valid VkDeviceCreateInfo.
unsafe fn app_request(info: &vk::DeviceCreateInfo) -> AppDeviceRequest {
    let mut req = AppDeviceRequest::default();
    let mut offsets_named = false;
    if !info.pp_enabled_extension_names.is_null() {
        // SAFETY: a valid VkDeviceCreateInfo (the caller's contract) has that many names, each
        // NUL-terminated
        // (https://registry.khronos.org/vulkan/specs/latest/man/html/VkDeviceCreateInfo.html).
        let names = unsafe {
            std::slice::from_raw_parts(
                info.pp_enabled_extension_names,
                info.enabled_extension_count as usize,
            )
        };
        for &p in names {
            // SAFETY: as above.
            let name = unsafe { crate::xr::ffi::cstr(p) };
            if name == Some(ash::ext::fragment_density_map::NAME) {
                req.extension = true;
            }
            offsets_named |= name.is_some_and(|n| OFFSET_NAMES.contains(&n));
        }
    }
    let mut offsets_feature = false;
    let mut node = info.p_next as *const vk::BaseInStructure;
    let mut seen = 0;
    while !node.is_null() && seen < crate::xr::ffi::MAX_CHAIN_LENGTH {
        // SAFETY: the pNext chain of a valid VkDeviceCreateInfo is a chain of valid structs, each
        // starting with sType and pNext; a node of one of the features types read here is that
        // struct.
        unsafe {
            let ty = (*node).s_type;
            if ty == vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_FEATURES_EXT
                && req.feature_struct.is_none()
            {
                let f = &*(node as *const vk::PhysicalDeviceFragmentDensityMapFeaturesEXT);
                req.feature_struct = Some(f.fragment_density_map == vk::TRUE);
            } else if ty
                == vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_OFFSET_FEATURES_QCOM
            {
                let f = &*(node as *const vk::PhysicalDeviceFragmentDensityMapOffsetFeaturesQCOM);
                offsets_feature = f.fragment_density_map_offset == vk::TRUE;
            }
            node = (*node).p_next;
        }
        seen += 1;
    }
    req.offsets = offsets_named && offsets_feature;
    req
}

/// The density-map offset extension and the name it was promoted from.
const OFFSET_NAMES: [&CStr; 2] = [
    c"VK_EXT_fragment_density_map_offset",
    ash::qcom::fragment_density_map_offset::NAME,
];

/// `xrCreateVulkanDeviceKHR` (enable2): where fovea provides XR_FB_foveation_vulkan and the physical
/// device supports VK_EXT_fragment_density_map, a copy of the XrVulkanDeviceCreateInfoKHR and of its
/// VkDeviceCreateInfo goes down with the extension added and `fragmentDensityMap` enabled through a
/// chained VkPhysicalDeviceFragmentDensityMapFeaturesEXT. The application's structs are never
/// written. Whether FDM ended up enabled is recorded for the device, for its density images' usage.
///
/// The `vkCreateDevice` the runtime makes in it is marked as the session's device: under injection
/// it is the one that gets shading-rate attachments (docs/injection.md#which-devices-get-the-feature).
pub fn create_vulkan_device(
    inst: xr::Instance,
    info: In<xr::VulkanDeviceCreateInfoKHR>,
    device: Out<xr::platform::VkDevice>,
    vk_result: Out<xr::platform::VkResult>,
) -> HookResult<xr::Result> {
    let r = crate::bridge::inject::creating_xr_device(|| {
        create_vulkan_device_marked(inst, info, &device, &vk_result)
    })?;
    let created = device.read().filter(|d| !d.is_null());
    let vk_ok = vk_result.read().map(vk::Result::from_raw) == Some(vk::Result::SUCCESS);
    if let (true, true, Some(created), Some(i)) = (succeeded(r), vk_ok, created, info.get()) {
        if !i.vulkan_create_info.is_null() {
            // SAFETY: a valid XrVulkanDeviceCreateInfoKHR points to a valid VkDeviceCreateInfo,
            // which the runtime just accepted; its sType is checked before anything else is read.
            let app_vk = unsafe { &*(i.vulkan_create_info as *const vk::DeviceCreateInfo) };
            let imageless = app_vk.s_type == vk::StructureType::DEVICE_CREATE_INFO
                // SAFETY: a VkDeviceCreateInfo (its sType just checked), valid as above.
                && unsafe { enables_imageless(app_vk) };
            // The device exists: whatever happens here, the application's result stands.
            if let (true, Ok(s)) = (imageless, instance(inst)) {
                s.vulkan.lock().imageless_created(created as u64);
            }
        }
    }
    Ok(r)
}

/// Whether a VkDeviceCreateInfo enables `imagelessFramebuffer` (Vulkan 1.2 or
/// VK_KHR_imageless_framebuffer). Such an application names, for each framebuffer attachment, the
/// usage it expects of the image it binds later, and that usage must equal the image's
/// (VUID-VkRenderPassBeginInfo-framebuffer-04627): usage added to its swapchain's images breaks it.
///
/// # Safety
/// `info` must be a valid VkDeviceCreateInfo.
unsafe fn enables_imageless(info: &vk::DeviceCreateInfo) -> bool {
    let mut node = info.p_next as *const vk::BaseInStructure;
    let mut seen = 0;
    while !node.is_null() && seen < crate::xr::ffi::MAX_CHAIN_LENGTH {
        // SAFETY: the pNext chain of a valid VkDeviceCreateInfo is a chain of valid structs, each
        // starting with sType and pNext; a node of one of the features types read here is that
        // struct.
        unsafe {
            let ty = (*node).s_type;
            if ty == vk::StructureType::PHYSICAL_DEVICE_IMAGELESS_FRAMEBUFFER_FEATURES {
                let f = &*(node as *const vk::PhysicalDeviceImagelessFramebufferFeatures);
                if f.imageless_framebuffer == vk::TRUE {
                    return true;
                }
            } else if ty == vk::StructureType::PHYSICAL_DEVICE_VULKAN_1_2_FEATURES {
                let f = &*(node as *const vk::PhysicalDeviceVulkan12Features);
                if f.imageless_framebuffer == vk::TRUE {
                    return true;
                }
            }
            node = (*node).p_next;
        }
        seen += 1;
    }
    false
}

/// [`create_vulkan_device`]'s work.
fn create_vulkan_device_marked(
    inst: xr::Instance,
    info: In<xr::VulkanDeviceCreateInfoKHR>,
    device: &Out<xr::platform::VkDevice>,
    vk_result: &Out<xr::platform::VkResult>,
) -> HookResult<xr::Result> {
    let s = instance(inst)?;
    let f = next(s.next.create_vulkan_device)?;
    // SAFETY: for every call of `down`: the next layer's function, with the application's
    // arguments as it passed them.
    let down = || unsafe { f(inst, info.raw(), device.raw(), vk_result.raw()) };
    let app_info = match info.get() {
        Some(i)
            if !i.vulkan_create_info.is_null()
                && !device.is_null()
                && !vk_result.is_null()
                && s.extensions.provided(Ext::FoveationVulkan) =>
        {
            i
        }
        _ => return Ok(down()),
    };
    // SAFETY: a valid XrVulkanDeviceCreateInfoKHR (`In`) points to a valid VkDeviceCreateInfo
    // (https://registry.khronos.org/OpenXR/specs/1.0/man/html/XrVulkanDeviceCreateInfoKHR.html),
    // which is checked by its sType before anything else is read.
    let app_vk = unsafe { &*(app_info.vulkan_create_info as *const vk::DeviceCreateInfo) };
    if app_vk.s_type != vk::StructureType::DEVICE_CREATE_INFO {
        // Not a VkDeviceCreateInfo: the runtime (and Vulkan) answer it as it is.
        return Ok(down());
    }
    let pd = app_info.vulkan_physical_device as u64;
    // Copied out first: a guard in the match scrutinee would live through `support_of`, whose
    // Vulkan calls pass through fovea's own Vulkan layer and its registry (lock order).
    let graphics_device = s.vulkan.lock().graphics_device;
    let support = match graphics_device {
        Some((vk_instance, recorded)) if recorded == pd => support_of(vk_instance, pd),
        // Not the device the runtime picked: the runtime answers that call.
        _ => None,
    };
    let Some(support) = support else {
        return Ok(down());
    };
    // SAFETY: `app_vk` is the application's valid VkDeviceCreateInfo (above).
    let request = unsafe { app_request(app_vk) };
    let (add_extension, add_feature, fdm_enabled) = device_plan(support, request);
    let mut names: Vec<*const c_char> = if app_vk.pp_enabled_extension_names.is_null() {
        Vec::new()
    } else {
        // SAFETY: a valid VkDeviceCreateInfo has `enabledExtensionCount` names.
        unsafe {
            std::slice::from_raw_parts(
                app_vk.pp_enabled_extension_names,
                app_vk.enabled_extension_count as usize,
            )
        }
        .to_vec()
    };
    if add_extension {
        names.push(ash::ext::fragment_density_map::NAME.as_ptr());
    }
    let mut features = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT {
        fragment_density_map: vk::TRUE,
        ..Default::default()
    };
    let mut vk_copy = *app_vk;
    vk_copy.enabled_extension_count = names.len() as u32;
    vk_copy.pp_enabled_extension_names = if names.is_empty() {
        std::ptr::null()
    } else {
        names.as_ptr()
    };
    if add_feature {
        features.p_next = app_vk.p_next as *mut c_void;
        vk_copy.p_next = &features as *const _ as *const c_void;
    }
    let mut xr_copy = *app_info;
    xr_copy.vulkan_create_info = &vk_copy as *const _ as *const c_void;
    // SAFETY: the next layer's function, with copies of the application's structs that point to
    // locals living through the call, and the application's output pointers.
    let r = unsafe { f(inst, &xr_copy, device.raw(), vk_result.raw()) };
    let created = device.read().filter(|d| !d.is_null());
    if let (true, Some(vk::Result::SUCCESS), Some(created)) = (
        succeeded(r),
        vk_result.read().map(vk::Result::from_raw),
        created,
    ) {
        tracing::info!(
            add_extension,
            add_feature,
            fdm_enabled,
            "Vulkan device created"
        );
        registry().vulkan_devices.lock().insert(
            created as u64,
            VulkanDevice {
                instance: inst.into_raw(),
                fdm_enabled,
                offsets_enabled: request.offsets,
            },
        );
    }
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extension_lists() {
        let fdm = ash::ext::fragment_density_map::NAME;
        let fdm2 = ash::ext::fragment_density_map2::NAME;
        assert_eq!(
            append_extensions("VK_KHR_external_memory", &[fdm]),
            "VK_KHR_external_memory VK_EXT_fragment_density_map"
        );
        assert_eq!(append_extensions("", &[fdm]), "VK_EXT_fragment_density_map");
        assert_eq!(
            append_extensions("VK_EXT_fragment_density_map", &[fdm, fdm2]),
            "VK_EXT_fragment_density_map VK_EXT_fragment_density_map2"
        );
        assert_eq!(append_extensions("A B", &[]), "A B");
        let none = session_gpu::FdmSupport::default();
        let both = session_gpu::FdmSupport {
            extension: true,
            extension2: true,
            ..none
        };
        assert!(extensions_to_add(Some(none)).is_empty());
        assert_eq!(extensions_to_add(Some(both)), [fdm, fdm2]);
        assert_eq!(extensions_to_add(None), [fdm]);
    }

    /// Offsets count as enabled with a name of the extension and its feature on, not with either
    /// alone; the FDM feature struct is read wherever it sits in the chain.
    #[test]
    fn offsets_are_read_from_the_device_create_info() {
        let read = |names: &[&CStr], offsets: Option<bool>| {
            let ptrs: Vec<*const c_char> = names.iter().map(|n| n.as_ptr()).collect();
            let mut fdm = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default()
                .fragment_density_map(true);
            let mut feature = vk::PhysicalDeviceFragmentDensityMapOffsetFeaturesQCOM::default()
                .fragment_density_map_offset(offsets.unwrap_or(false));
            let mut info = vk::DeviceCreateInfo::default()
                .enabled_extension_names(&ptrs)
                .push_next(&mut fdm);
            if offsets.is_some() {
                info = info.push_next(&mut feature);
            }
            // SAFETY: a valid create info whose names and chain live across the call.
            unsafe { app_request(&info) }
        };
        let [ext, qcom] = OFFSET_NAMES;
        let fdm = ash::ext::fragment_density_map::NAME;
        let on = read(&[fdm, ext], Some(true));
        assert!(on.offsets && on.extension);
        assert_eq!(on.feature_struct, Some(true), "behind the offsets struct");
        assert!(read(&[qcom], Some(true)).offsets, "the QCOM name");
        assert!(!read(&[fdm, ext], Some(false)).offsets, "the feature off");
        assert!(!read(&[fdm, ext], None).offsets, "no feature struct");
        assert!(!read(&[fdm], Some(true)).offsets, "no name");
    }

    #[test]
    fn device_plans() {
        let none = session_gpu::FdmSupport::default();
        let full = session_gpu::FdmSupport {
            extension: true,
            feature: true,
            ..none
        };
        let app = AppDeviceRequest::default();
        assert_eq!(device_plan(none, app), (false, false, false));
        assert_eq!(device_plan(full, app), (true, true, true));
        let ext_only = session_gpu::FdmSupport {
            feature: false,
            ..full
        };
        assert_eq!(device_plan(ext_only, app), (true, false, false));
        let has_both = AppDeviceRequest {
            extension: true,
            feature_struct: Some(true),
            ..app
        };
        assert_eq!(device_plan(full, has_both), (false, false, true));
        let turned_off = AppDeviceRequest {
            extension: true,
            feature_struct: Some(false),
            ..app
        };
        assert_eq!(device_plan(full, turned_off), (false, false, false));
    }
}
