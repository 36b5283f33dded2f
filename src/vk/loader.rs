//! The loader interface: `vkNegotiateLoaderLayerInterfaceVersion` (interface version 2),
//! `vkGetInstanceProcAddr` and `vkGetDeviceProcAddr` (instance creation and destruction are
//! [`crate::vk::hooks::instance`]'s), following
//! <https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>.

use std::ffi::{c_char, CStr};

use ash::vk;

use crate::vk::base::commands::When;
use crate::vk::base::ffi::{guard, name};
use crate::vk::base::link::{self, NegotiateLayerInterface};
use crate::vk::dispatch;
use crate::vk::hooks::instance::create_instance;
use crate::vk::registry;

/// The loader's entry point into the layer: agrees on interface version 2 and hands over the
/// layer's `vkGetInstanceProcAddr` and `vkGetDeviceProcAddr`
/// (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md#layer-version-negotiation>).
///
/// # Safety
/// `p` must be NULL or point at the loader's `VkNegotiateLayerInterface`.
#[no_mangle]
pub unsafe extern "system" fn vkNegotiateLoaderLayerInterfaceVersion(
    p: *mut NegotiateLayerInterface,
) -> vk::Result {
    guard(
        "vkNegotiateLoaderLayerInterfaceVersion",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            crate::common::log::init();
            if p.is_null() {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            }
            // SAFETY: the loader passes its own struct for the layer to fill.
            let n = unsafe { &mut *p };
            if n.s_type != link::NEGOTIATE_INTERFACE_STRUCT
                || n.loader_layer_interface_version < link::INTERFACE_VERSION
            {
                tracing::warn!(
                    version = n.loader_layer_interface_version,
                    "the Vulkan loader is too old for the layer interface version 2"
                );
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            }
            n.loader_layer_interface_version = link::INTERFACE_VERSION;
            n.pfn_get_instance_proc_addr = Some(get_instance_proc_addr);
            n.pfn_get_device_proc_addr = Some(get_device_proc_addr);
            n.pfn_get_physical_device_proc_addr = None;
            vk::Result::SUCCESS
        },
    )
}

/// The layer's own commands, answered whatever the instance.
fn lifecycle(name: &CStr) -> vk::PFN_vkVoidFunction {
    let f = match name.to_bytes() {
        // SAFETY: function pointers share one representation; the caller casts back to
        // the type the name implies, which the `as` checks here.
        b"vkGetInstanceProcAddr" => unsafe {
            std::mem::transmute::<vk::PFN_vkGetInstanceProcAddr, unsafe extern "system" fn()>(
                get_instance_proc_addr as vk::PFN_vkGetInstanceProcAddr,
            )
        },
        // SAFETY: as above.
        b"vkGetDeviceProcAddr" => unsafe {
            std::mem::transmute::<vk::PFN_vkGetDeviceProcAddr, unsafe extern "system" fn()>(
                get_device_proc_addr as vk::PFN_vkGetDeviceProcAddr,
            )
        },
        // SAFETY: as above.
        b"vkCreateInstance" => unsafe {
            std::mem::transmute::<vk::PFN_vkCreateInstance, unsafe extern "system" fn()>(
                create_instance as vk::PFN_vkCreateInstance,
            )
        },
        _ => return None,
    };
    Some(f)
}

/// `vkGetInstanceProcAddr`: the layer's hooks where it intercepts a command the next layer offers,
/// the next layer's pointer otherwise.
///
/// # Safety
/// `instance` must be NULL or an instance created through the layer; `name` NULL or NUL-terminated.
#[no_mangle]
pub unsafe extern "system" fn vkGetInstanceProcAddr(
    instance: vk::Instance,
    p_name: *const c_char,
) -> vk::PFN_vkVoidFunction {
    // SAFETY: as the caller promised.
    unsafe { get_instance_proc_addr(instance, p_name) }
}

/// [`vkGetInstanceProcAddr`] under a name the library does not export: the pointer the layer hands
/// out. The exported symbol's address may resolve to another library's `vkGetInstanceProcAddr` —
/// the Vulkan loader's, where the application links libvulkan — and the loader's trampoline in
/// the layer chain calls back into the loader, which deadlocks on its own lock.
///
/// # Safety
/// As [`vkGetInstanceProcAddr`].
unsafe extern "system" fn get_instance_proc_addr(
    instance: vk::Instance,
    p_name: *const c_char,
) -> vk::PFN_vkVoidFunction {
    guard("vkGetInstanceProcAddr", None, || {
        // SAFETY: as the caller promised.
        let name = unsafe { name(p_name) }?;
        if let Some(f) = lifecycle(name) {
            return Some(f);
        }
        // SAFETY: as the caller promised.
        let inst = unsafe { registry::instance(instance) }?;
        if let Some(h) = dispatch::instance_hook(name) {
            if (h.offered)(&inst.next) {
                return Some(h.function);
            }
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        let below = unsafe { (inst.gipa)(instance, p_name) };
        let provided = dispatch::device_hook(name).is_some_and(|h| h.when == When::Provided);
        if below.is_some() || provided {
            if let Some(h) = dispatch::device_hook(name) {
                // The device the command will be called on is not known yet: the hook looks it up
                // and forwards where the device does not emulate.
                return Some(h.function);
            }
        }
        below
    })
}

/// `vkGetDeviceProcAddr`: the layer's hook where it intercepts the command on this device, the
/// next layer's own pointer otherwise (no added cost).
///
/// # Safety
/// `device` must be NULL or a device created through the layer; `name` NULL or NUL-terminated.
#[no_mangle]
pub unsafe extern "system" fn vkGetDeviceProcAddr(
    device: vk::Device,
    p_name: *const c_char,
) -> vk::PFN_vkVoidFunction {
    // SAFETY: as the caller promised.
    unsafe { get_device_proc_addr(device, p_name) }
}

/// [`vkGetDeviceProcAddr`] under a name the library does not export (see
/// [`get_instance_proc_addr`]).
///
/// # Safety
/// As [`vkGetDeviceProcAddr`].
unsafe extern "system" fn get_device_proc_addr(
    device: vk::Device,
    p_name: *const c_char,
) -> vk::PFN_vkVoidFunction {
    guard("vkGetDeviceProcAddr", None, || {
        // SAFETY: as the caller promised.
        let name = unsafe { name(p_name) }?;
        if name == c"vkGetDeviceProcAddr" {
            return lifecycle(name);
        }
        // SAFETY: as the caller promised.
        let dev = unsafe { registry::device(device) }?;
        if let Some(h) = dispatch::device_hook(name) {
            let offered = (h.offered)(&dev.next) || h.when == When::Provided;
            if offered && h.when.applies(dev.fdm.is_some(), dev.injection.is_some()) {
                return Some(h.function);
            }
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { (dev.gdpa)(device, p_name) }
    })
}
