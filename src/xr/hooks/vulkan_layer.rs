//! fovea's Vulkan layer (`VK_LAYER_FOVEA_fragment_density_map`, the same library) under the
//! application's VkInstance, with nothing for the application to do. Two ways, one per Vulkan enable
//! extension (docs/vulkan-layer.md):
//!
//! - XR_KHR_vulkan_enable2: the runtime creates the VkInstance in `xrCreateVulkanInstanceKHR`
//!   (https://registry.khronos.org/OpenXR/specs/1.0/man/html/xrCreateVulkanInstanceKHR.html). fovea
//!   hands it a copy of the application's VkInstanceCreateInfo with the layer first in
//!   `ppEnabledLayerNames`, where the Vulkan loader the application named finds the layer. First
//!   means closest to the application
//!   (https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderApplicationInterface.md), so
//!   layers the application enables itself (validation) see the calls the driver gets.
//! - XR_KHR_vulkan_enable: the application calls vkCreateInstance itself, and nothing of OpenXR sits
//!   on that path. The implicit Vulkan manifest `fovea install` writes is switched on by the
//!   environment variable `FOVEA_VK_LAYER=1` (its `enable_environment`, read by the Vulkan loader at
//!   every vkCreateInstance; docs/vulkan-fdm-on-fsr.md#layer-plumbing), and fovea's OpenXR layer sets
//!   that variable when an instance enables either Vulkan extension ([`request_for_process`]). So
//!   only processes that run an OpenXR application through fovea ever load the Vulkan layer.
//!
//! Where the layer cannot be found, everything goes on as before and the log says so once.

use std::ffi::{c_char, c_void, CStr};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Once;

use ash::vk;
use openxr_sys as xr;

use crate::xr::ffi::HookResult;
use crate::xr::ffi::{self, In, Out};
use crate::xr::next_layer::next;
use crate::xr::registry::instance;
use crate::xr::values::succeeded;
use fovea_abi::env::{DISABLE_VK_LAYER, VK_LAYER};

/// The Vulkan layer's name (fovea_abi::VK_LAYER_NAME) as a C string.
pub const LAYER: &CStr = c"VK_LAYER_FOVEA_fragment_density_map";

/// Whether the Vulkan loader behind `gipa` lists fovea's Vulkan layer, or why it cannot say.
///
/// # Safety
/// `gipa` must be a Vulkan loader's `vkGetInstanceProcAddr` (the application's, from
/// XrVulkanInstanceCreateInfoKHR).
unsafe fn layer_listed(gipa: xr::platform::VkGetInstanceProcAddr) -> Result<bool, String> {
    // SAFETY: the caller's contract; a NULL instance is how global commands are looked up
    // (https://registry.khronos.org/vulkan/specs/latest/man/html/vkGetInstanceProcAddr.html).
    let f = unsafe {
        gipa(
            std::ptr::null(),
            c"vkEnumerateInstanceLayerProperties".as_ptr(),
        )
    }
    .ok_or("its vkGetInstanceProcAddr has no vkEnumerateInstanceLayerProperties")?;
    // SAFETY: the loader answered for that name, so the pointer has that command's signature.
    let f = unsafe {
        std::mem::transmute::<unsafe extern "system" fn(), vk::PFN_vkEnumerateInstanceLayerProperties>(
            f,
        )
    };
    // The list may grow between the two calls (VK_INCOMPLETE): ask again, a few times.
    for _ in 0..4 {
        let mut n = 0u32;
        // SAFETY: a count query into a local.
        let r = unsafe { f(&mut n, std::ptr::null_mut()) };
        if r != vk::Result::SUCCESS {
            return Err(format!("vkEnumerateInstanceLayerProperties: {r:?}"));
        }
        let mut props = vec![vk::LayerProperties::default(); n as usize];
        // SAFETY: `props` holds the `n` elements the count says.
        let r = unsafe { f(&mut n, props.as_mut_ptr()) };
        if r == vk::Result::INCOMPLETE {
            continue;
        }
        if r != vk::Result::SUCCESS {
            return Err(format!("vkEnumerateInstanceLayerProperties: {r:?}"));
        }
        props.truncate(n as usize);
        return Ok(props.iter().any(|p| p.layer_name_as_c_str() == Ok(LAYER)));
    }
    Err("vkEnumerateInstanceLayerProperties kept changing its count".into())
}

/// Logs, once per process, that the Vulkan layer stays out of the application's VkInstance.
fn not_added_once(why: &str) {
    static SAID: AtomicBool = AtomicBool::new(false);
    if !SAID.swap(true, Ordering::Relaxed) {
        tracing::info!(
            why,
            "{} not added to the application's VkInstance: density maps are not emulated on \
             shading-rate devices (`fovea install` installs the Vulkan layer; VK_ADD_LAYER_PATH \
             names a folder with its manifest)",
            LAYER.to_string_lossy()
        );
    }
}

/// The application's enabled layer names, or `None` where the create info is not one fovea reads.
///
/// # Safety
/// `info` must be a valid VkInstanceCreateInfo.
unsafe fn app_layers(info: &vk::InstanceCreateInfo) -> Option<Vec<*const c_char>> {
    if info.enabled_layer_count == 0 {
        return Some(Vec::new());
    }
    if info.pp_enabled_layer_names.is_null() {
        return None;
    }
    // SAFETY: a valid VkInstanceCreateInfo has `enabledLayerCount` names, each NUL-terminated
    // (https://registry.khronos.org/vulkan/specs/latest/man/html/VkInstanceCreateInfo.html).
    let names = unsafe {
        std::slice::from_raw_parts(
            info.pp_enabled_layer_names,
            info.enabled_layer_count as usize,
        )
    };
    Some(names.to_vec())
}

/// `xrCreateVulkanInstanceKHR` (enable2): where the application's Vulkan loader lists fovea's Vulkan
/// layer and the application did not enable it itself, a copy of the XrVulkanInstanceCreateInfoKHR
/// and of its VkInstanceCreateInfo goes down with the layer first in `ppEnabledLayerNames`. The
/// application's structs are never written. Fail open: where the copy's vkCreateInstance fails, the
/// application's own create info is tried as it was, and the log says why.
pub fn create_vulkan_instance(
    inst: xr::Instance,
    info: In<xr::VulkanInstanceCreateInfoKHR>,
    vk_instance: Out<xr::platform::VkInstance>,
    vk_result: Out<xr::platform::VkResult>,
) -> HookResult<xr::Result> {
    let f = next(instance(inst)?.next.create_vulkan_instance)?;
    // SAFETY: for every call of `down`: the next layer's function, with the application's
    // arguments as it passed them.
    let down = || unsafe { f(inst, info.raw(), vk_instance.raw(), vk_result.raw()) };
    let (Some(app_info), false, false) = (info.get(), vk_instance.is_null(), vk_result.is_null())
    else {
        return Ok(down());
    };
    let (Some(gipa), false) = (
        app_info.pfn_get_instance_proc_addr,
        app_info.vulkan_create_info.is_null(),
    ) else {
        return Ok(down());
    };
    // SAFETY: a valid XrVulkanInstanceCreateInfoKHR (`In`) points to a valid VkInstanceCreateInfo
    // (https://registry.khronos.org/OpenXR/specs/1.0/man/html/XrVulkanInstanceCreateInfoKHR.html),
    // checked by its sType before anything else is read.
    let app_vk = unsafe { &*(app_info.vulkan_create_info as *const vk::InstanceCreateInfo) };
    if app_vk.s_type != vk::StructureType::INSTANCE_CREATE_INFO {
        return Ok(down());
    }
    // SAFETY: `app_vk` is the application's valid VkInstanceCreateInfo (above).
    let Some(names) = (unsafe { app_layers(app_vk) }) else {
        return Ok(down());
    };
    let is_ours = |&n: &*const c_char| {
        // SAFETY: each name of a valid VkInstanceCreateInfo is NUL-terminated (above).
        (unsafe { ffi::cstr(n) }) == Some(LAYER)
    };
    if names.iter().any(is_ours) {
        return Ok(down());
    }
    // SAFETY: the application's vkGetInstanceProcAddr, which the runtime calls the same way.
    match unsafe { layer_listed(gipa) } {
        Ok(true) => {}
        Ok(false) => {
            not_added_once("the Vulkan loader does not list it");
            return Ok(down());
        }
        Err(why) => {
            not_added_once(&why);
            return Ok(down());
        }
    }
    let mut layers = Vec::with_capacity(names.len() + 1);
    layers.push(LAYER.as_ptr());
    layers.extend(names);
    let mut vk_copy = *app_vk;
    vk_copy.enabled_layer_count = layers.len() as u32;
    vk_copy.pp_enabled_layer_names = layers.as_ptr();
    let mut xr_copy = *app_info;
    xr_copy.vulkan_create_info = &vk_copy as *const vk::InstanceCreateInfo as *const c_void;
    // SAFETY: the next layer's function, with copies of the application's structs that point to
    // locals living through the call, and the application's output pointers.
    let r = unsafe { f(inst, &xr_copy, vk_instance.raw(), vk_result.raw()) };
    let vr = vk_result.read().map(vk::Result::from_raw);
    match vr {
        Some(vk::Result::SUCCESS) if succeeded(r) => {
            tracing::info!(
                layer = ?LAYER,
                "the Vulkan layer is in the application's VkInstance"
            );
            Ok(r)
        }
        Some(e) if e.as_raw() < 0 => {
            tracing::warn!(
                vk_result = ?e,
                "vkCreateInstance failed with {} added; trying the application's own create info",
                LAYER.to_string_lossy()
            );
            Ok(down())
        }
        _ => Ok(r),
    }
}

/// Sets `FOVEA_VK_LAYER=1` in the process environment, once, where `vulkan` (the instance enables
/// XR_KHR_vulkan_enable or XR_KHR_vulkan_enable2) and neither that variable nor
/// `DISABLE_FOVEA_VK_LAYER` is set already (the user's `FOVEA_VK_LAYER=0` keeps the layer out).
///
/// Called from `xrCreateApiLayerInstance`, before the runtime's instance exists. Why there: an
/// XR_KHR_vulkan_enable application can only call vkCreateInstance after xrCreateInstance (it needs
/// `xrGetVulkanInstanceExtensionsKHR` for the instance extensions), and the Vulkan loader reads the
/// variable at each vkCreateInstance, so the variable is always in place in time.
///
/// The risk: `setenv` is not thread-safe against `getenv` in other threads (POSIX; glibc may move
/// the environment while another thread reads it). Rust's own environment functions take a lock,
/// C code does not. The variable is therefore set at most once per process, at the earliest point
/// fovea is called, before the runtime below starts its threads, when an application usually still
/// runs on one thread; an application that creates its XrInstance while other threads of its own
/// read the environment in C takes that (small, one-time) risk, and can avoid it by setting
/// `FOVEA_VK_LAYER` itself (or in its launcher), in which case fovea leaves the environment alone.
/// The variable is inherited by child processes, which then load the layer too where they use
/// Vulkan; the layer passes through every device that does not use density maps.
pub fn request_for_process(vulkan: bool) {
    static ONCE: Once = Once::new();
    if !vulkan {
        return;
    }
    ONCE.call_once(|| {
        if let Some(set) = [VK_LAYER, DISABLE_VK_LAYER]
            .into_iter()
            .find(|v| std::env::var_os(v).is_some())
        {
            tracing::info!(
                set,
                "left the environment as it is for the implicit Vulkan layer"
            );
            return;
        }
        // Not thread-safe against C's getenv on other threads: see above.
        std::env::set_var(VK_LAYER, "1");
        tracing::info!("{VK_LAYER}=1 set: the implicit Vulkan layer, where installed, loads");
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_layer_name_is_the_abi_one() {
        assert_eq!(LAYER.to_str().unwrap(), fovea_abi::VK_LAYER_NAME);
    }
}
