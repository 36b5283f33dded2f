//! Vulkan device set-up through XR_KHR_vulkan_enable and XR_KHR_vulkan_enable2: fovea asks for
//! VK_EXT_fragment_density_map where the application enabled XR_FB_foveation_vulkan, so its density
//! images can be real FDM attachments (openxr-layer-facts.md §3, "Injecting Vulkan device
//! requirements").

use std::ffi::{c_char, c_void, CStr};

use ash::vk;
use ash::vk::Handle as _;
use openxr_sys as xr;
use xr::Handle;

use super::{finish, instance, next, succeeded, HookResult};
use crate::common::ffi::guard;
use crate::gpu::density_images;
use crate::xr::extensions::Ext;
use crate::xr::registry::{registry, Instance, VulkanDevice};

/// What the physical device the application picked supports, if fovea knows the device.
///
/// # Safety
/// The recorded handles must be live (the spec makes the application keep them).
unsafe fn recorded_support(state: &Instance) -> Option<(u64, density_images::FdmSupport)> {
    let (vk_instance, pd) = state.vulkan.lock().graphics_device?;
    let entry = density_images::entry()?;
    let instance = density_images::instance_fns(entry, vk_instance);
    Some((
        pd,
        density_images::query_support(entry, &instance, vk::PhysicalDevice::from_raw(pd)),
    ))
}

/// The device extension names fovea adds to the runtime's list, given what it knows of the device.
///
/// Where the physical device is known (xrGetVulkanGraphicsDeviceKHR was called first, as the spec's
/// own order and hello_xr have it), exactly the FDM extensions it supports. Where it is not, only
/// VK_EXT_fragment_density_map, as issue #3 asks: an application that then enables it on a device
/// without it fails vkCreateDevice, which is why the known-device path is preferred (README).
pub fn extensions_to_add(support: Option<density_images::FdmSupport>) -> Vec<&'static CStr> {
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

/// The two-call idiom for a string (fundamentals.adoc "Buffer Size Parameters"): counts include the
/// terminating NUL; capacity 0 asks for the size; a non-zero capacity below it is
/// XR_ERROR_SIZE_INSUFFICIENT with the size written.
///
/// # Safety
/// `count` must be valid for a write, `buffer` for `capacity` bytes when `capacity > 0`.
unsafe fn two_call_str(s: &str, capacity: u32, count: *mut u32, buffer: *mut c_char) -> xr::Result {
    if count.is_null() || (capacity > 0 && buffer.is_null()) {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    let needed = s.len() as u32 + 1;
    *count = needed;
    if capacity == 0 {
        return xr::Result::SUCCESS;
    }
    if capacity < needed {
        return xr::Result::ERROR_SIZE_INSUFFICIENT;
    }
    std::ptr::copy_nonoverlapping(s.as_ptr(), buffer as *mut u8, s.len());
    *buffer.add(s.len()) = 0;
    xr::Result::SUCCESS
}

/// `xrGetVulkanDeviceExtensionsKHR` (enable): where fovea provides XR_FB_foveation_vulkan, the
/// runtime's list plus the FDM extensions (see [`extensions_to_add`]), with counts recomputed.
pub unsafe extern "system" fn get_vulkan_device_extensions(
    inst: xr::Instance,
    system: xr::SystemId,
    capacity: u32,
    count: *mut u32,
    buffer: *mut c_char,
) -> xr::Result {
    guard("xrGetVulkanDeviceExtensionsKHR", || {
        finish((|| {
            let s = instance(inst)?;
            let f = next(s.next.get_vulkan_device_extensions)?;
            if !s.extensions.provided(Ext::FoveationVulkan) {
                return Ok(f(inst, system, capacity, count, buffer));
            }
            let runtime = runtime_string(f, inst, system)?;
            let support = recorded_support(&s);
            let add = extensions_to_add(support.map(|(_, s)| s));
            let list = append_extensions(&runtime, &add);
            let r = two_call_str(&list, capacity, count, buffer);
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
        })())
    })
}

/// The runtime's own extension string, through its two-call idiom.
unsafe fn runtime_string(
    f: xr::pfn::GetVulkanDeviceExtensionsKHR,
    inst: xr::Instance,
    system: xr::SystemId,
) -> HookResult<String> {
    let mut n = 0;
    let r = f(inst, system, 0, &mut n, std::ptr::null_mut());
    if !succeeded(r) {
        return Err(r);
    }
    let mut buf = vec![0u8; n.max(1) as usize];
    let r = f(inst, system, n, &mut n, buf.as_mut_ptr() as *mut c_char);
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
pub unsafe extern "system" fn get_vulkan_graphics_device(
    inst: xr::Instance,
    system: xr::SystemId,
    vk_instance: xr::platform::VkInstance,
    physical_device: *mut xr::platform::VkPhysicalDevice,
) -> xr::Result {
    guard("xrGetVulkanGraphicsDeviceKHR", || {
        finish((|| {
            let s = instance(inst)?;
            let r = next(s.next.get_vulkan_graphics_device)?(
                inst,
                system,
                vk_instance,
                physical_device,
            );
            if succeeded(r) && !physical_device.is_null() {
                record_graphics_device(&s, vk_instance, *physical_device as u64);
            }
            Ok(r)
        })())
    })
}

/// `xrGetVulkanGraphicsDevice2KHR` (enable2): passed on; the device is recorded.
pub unsafe extern "system" fn get_vulkan_graphics_device2(
    inst: xr::Instance,
    info: *const xr::VulkanGraphicsDeviceGetInfoKHR,
    physical_device: *mut xr::platform::VkPhysicalDevice,
) -> xr::Result {
    guard("xrGetVulkanGraphicsDevice2KHR", || {
        finish((|| {
            let s = instance(inst)?;
            let r = next(s.next.get_vulkan_graphics_device2)?(inst, info, physical_device);
            if succeeded(r)
                && !physical_device.is_null()
                && !info.is_null()
                && (*info).ty == xr::StructureType::VULKAN_GRAPHICS_DEVICE_GET_INFO_KHR
            {
                record_graphics_device(&s, (*info).vulkan_instance, *physical_device as u64);
            }
            Ok(r)
        })())
    })
}

/// What the application's VkDeviceCreateInfo already asks of FDM.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AppDeviceRequest {
    pub extension: bool,
    /// `Some(enabled)` when its pNext holds VkPhysicalDeviceFragmentDensityMapFeaturesEXT.
    pub feature_struct: Option<bool>,
}

/// What fovea adds to a device create info: (add the extension name, chain a features struct), and
/// whether FDM ends up enabled. Nothing is added that the device lacks; a features struct the
/// application chained itself is respected (Vulkan forbids a second one of the same type).
pub fn device_plan(
    support: density_images::FdmSupport,
    app: AppDeviceRequest,
) -> (bool, bool, bool) {
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
    if !info.pp_enabled_extension_names.is_null() {
        for i in 0..info.enabled_extension_count as usize {
            let p = *info.pp_enabled_extension_names.add(i);
            if !p.is_null() && CStr::from_ptr(p) == ash::ext::fragment_density_map::NAME {
                req.extension = true;
            }
        }
    }
    let mut node = info.p_next as *const vk::BaseInStructure;
    let mut seen = 0;
    while !node.is_null() && seen < crate::common::ffi::MAX_CHAIN_LENGTH {
        if (*node).s_type == vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_FEATURES_EXT {
            let f = &*(node as *const vk::PhysicalDeviceFragmentDensityMapFeaturesEXT);
            req.feature_struct = Some(f.fragment_density_map == vk::TRUE);
            break;
        }
        node = (*node).p_next;
        seen += 1;
    }
    req
}

/// `xrCreateVulkanDeviceKHR` (enable2): where fovea provides XR_FB_foveation_vulkan and the physical
/// device supports VK_EXT_fragment_density_map, a copy of the XrVulkanDeviceCreateInfoKHR and of its
/// VkDeviceCreateInfo goes down with the extension added and `fragmentDensityMap` enabled through a
/// chained VkPhysicalDeviceFragmentDensityMapFeaturesEXT. The application's structs are never
/// written. Whether FDM ended up enabled is recorded for the device, for its density images' usage.
pub unsafe extern "system" fn create_vulkan_device(
    inst: xr::Instance,
    info: *const xr::VulkanDeviceCreateInfoKHR,
    device: *mut xr::platform::VkDevice,
    vk_result: *mut xr::platform::VkResult,
) -> xr::Result {
    guard("xrCreateVulkanDeviceKHR", || {
        finish((|| {
            let s = instance(inst)?;
            let f = next(s.next.create_vulkan_device)?;
            let usable = !info.is_null()
                && (*info).ty == xr::StructureType::VULKAN_DEVICE_CREATE_INFO_KHR
                && !(*info).vulkan_create_info.is_null()
                && !device.is_null()
                && !vk_result.is_null()
                && s.extensions.provided(Ext::FoveationVulkan);
            if !usable {
                return Ok(f(inst, info, device, vk_result));
            }
            let app_info = &*info;
            let app_vk = &*(app_info.vulkan_create_info as *const vk::DeviceCreateInfo);
            if app_vk.s_type != vk::StructureType::DEVICE_CREATE_INFO {
                // Not a VkDeviceCreateInfo: the runtime (and Vulkan) answer it as it is.
                return Ok(f(inst, info, device, vk_result));
            }
            let pd = app_info.vulkan_physical_device as u64;
            let support = match s.vulkan.lock().graphics_device {
                Some((vk_instance, recorded)) if recorded == pd => {
                    density_images::entry().map(|e| {
                        let instance = density_images::instance_fns(e, vk_instance);
                        density_images::query_support(
                            e,
                            &instance,
                            vk::PhysicalDevice::from_raw(pd),
                        )
                    })
                }
                // Not the device the runtime picked: the runtime answers that call.
                _ => None,
            };
            let Some(support) = support else {
                return Ok(f(inst, info, device, vk_result));
            };
            let (add_extension, add_feature, fdm_enabled) =
                device_plan(support, app_request(app_vk));
            let mut names: Vec<*const c_char> = if app_vk.pp_enabled_extension_names.is_null() {
                Vec::new()
            } else {
                std::slice::from_raw_parts(
                    app_vk.pp_enabled_extension_names,
                    app_vk.enabled_extension_count as usize,
                )
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
            let r = f(inst, &xr_copy, device, vk_result);
            if succeeded(r) && *vk_result == vk::Result::SUCCESS.as_raw() && !(*device).is_null() {
                tracing::info!(
                    add_extension,
                    add_feature,
                    fdm_enabled,
                    "Vulkan device created"
                );
                registry().vulkan_devices.lock().insert(
                    *device as u64,
                    VulkanDevice {
                        instance: inst.into_raw(),
                        fdm_enabled,
                    },
                );
            }
            Ok(r)
        })())
    })
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
        let none = density_images::FdmSupport::default();
        let both = density_images::FdmSupport {
            extension: true,
            extension2: true,
            ..none
        };
        assert!(extensions_to_add(Some(none)).is_empty());
        assert_eq!(extensions_to_add(Some(both)), [fdm, fdm2]);
        assert_eq!(extensions_to_add(None), [fdm]);
    }

    #[test]
    fn device_plans() {
        let none = density_images::FdmSupport::default();
        let full = density_images::FdmSupport {
            extension: true,
            feature: true,
            ..none
        };
        let app = AppDeviceRequest::default();
        assert_eq!(device_plan(none, app), (false, false, false));
        assert_eq!(device_plan(full, app), (true, true, true));
        let ext_only = density_images::FdmSupport {
            feature: false,
            ..full
        };
        assert_eq!(device_plan(ext_only, app), (true, false, false));
        let has_both = AppDeviceRequest {
            extension: true,
            feature_struct: Some(true),
        };
        assert_eq!(device_plan(full, has_both), (false, false, true));
        let turned_off = AppDeviceRequest {
            extension: true,
            feature_struct: Some(false),
        };
        assert_eq!(device_plan(full, turned_off), (false, false, false));
    }
}
