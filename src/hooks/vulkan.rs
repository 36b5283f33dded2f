//! Vulkan device set-up through XR_KHR_vulkan_enable and XR_KHR_vulkan_enable2.

use openxr_sys as xr;

use super::{finish, instance, next};
use crate::ffi::guard;

/// `xrGetVulkanDeviceExtensionsKHR`: passed on.
pub unsafe extern "system" fn get_vulkan_device_extensions(
    inst: xr::Instance,
    system: xr::SystemId,
    capacity: u32,
    count: *mut u32,
    buffer: *mut std::ffi::c_char,
) -> xr::Result {
    guard("xrGetVulkanDeviceExtensionsKHR", || {
        finish((|| {
            let s = instance(inst)?;
            Ok(next(s.next.get_vulkan_device_extensions)?(
                inst, system, capacity, count, buffer,
            ))
        })())
    })
}

/// `xrCreateVulkanDeviceKHR`: passed on.
pub unsafe extern "system" fn create_vulkan_device(
    inst: xr::Instance,
    info: *const xr::VulkanDeviceCreateInfoKHR,
    device: *mut xr::platform::VkDevice,
    vk_result: *mut xr::platform::VkResult,
) -> xr::Result {
    guard("xrCreateVulkanDeviceKHR", || {
        finish((|| {
            let s = instance(inst)?;
            Ok(next(s.next.create_vulkan_device)?(
                inst, info, device, vk_result,
            ))
        })())
    })
}
