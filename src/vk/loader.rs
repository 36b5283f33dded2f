//! The loader interface: `vkNegotiateLoaderLayerInterfaceVersion` (interface version 2),
//! `vkGetInstanceProcAddr`, `vkGetDeviceProcAddr`, and instance creation and destruction, following
//! <https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>.

use std::ffi::{c_char, CStr};

use ash::vk;

use crate::vk::base::chain;
use crate::vk::base::ffi::{extension_enabled, guard, name, raw};
use crate::vk::base::link::{
    self, LayerInstanceCreateInfo, LayerInstanceLink, NegotiateLayerInterface,
};
use crate::vk::base::next::InstanceNext;
use crate::vk::dispatch;
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
        if below.is_some() {
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
            if (h.offered)(&dev.next) && h.when.applies(dev.fdm.is_some(), dev.inject.is_some()) {
                return Some(h.function);
            }
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { (dev.gdpa)(device, p_name) }
    })
}

/// `vkCreateInstance`: finds the next layer in the loader's link info, advances the link for the
/// layers below, creates the instance there and records it.
///
/// # Safety
/// Called by the loader (or the layer above) with a valid create info carrying link info.
unsafe extern "system" fn create_instance(
    info: *const vk::InstanceCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Instance,
) -> vk::Result {
    guard(
        "vkCreateInstance",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            crate::common::log::init();
            if info.is_null() || out.is_null() {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            }
            // SAFETY: a valid create info from the loader.
            let ci = unsafe { &*info };
            // SAFETY: the chain is valid; link infos are `VkLayerInstanceCreateInfo`.
            let Some(link_info) = (unsafe { instance_link(ci) }) else {
                tracing::error!("vkCreateInstance without the loader's link info");
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            // SAFETY: the loader's list of layers below; the protocol has each layer advance
            // `pLayerInfo` in the loader's struct before calling down (the struct is the loader's,
            // not the application's).
            let (layer, gipa) = unsafe {
                let layer = (*link_info).u[0] as *const LayerInstanceLink;
                if layer.is_null() {
                    return vk::Result::ERROR_INITIALIZATION_FAILED;
                }
                (*link_info).u[0] = (*layer).p_next as *mut _;
                (layer, (*layer).pfn_next_get_instance_proc_addr)
            };
            // SAFETY: the next layer's vkCreateInstance, of the type its name implies.
            let create = unsafe {
                let Some(create) = gipa(vk::Instance::null(), c"vkCreateInstance".as_ptr()) else {
                    return vk::Result::ERROR_INITIALIZATION_FAILED;
                };
                std::mem::transmute::<unsafe extern "system" fn(), vk::PFN_vkCreateInstance>(create)
            };
            // SAFETY: a valid create info, as above.
            let api_version = unsafe {
                if ci.p_application_info.is_null() || (*ci.p_application_info).api_version == 0 {
                    vk::API_VERSION_1_0
                } else {
                    (*ci.p_application_info).api_version
                }
            };
            let properties2 = ash::khr::get_physical_device_properties2::NAME;
            // SAFETY: the application's names, as the create info promises.
            let mut properties2_ext = unsafe {
                extension_enabled(
                    ci.pp_enabled_extension_names,
                    ci.enabled_extension_count,
                    properties2,
                )
            };
            // Injection (docs/injection.md) reads the devices' shading-rate properties and
            // features, which a Vulkan 1.0 instance (hello_xr's) can ask for only through
            // VK_KHR_get_physical_device_properties2: the layer enables it on its copy of the
            // create info. Where the instance cannot be made so, the application's create info
            // goes down as it came, and its devices are passed through.
            let mut r = vk::Result::ERROR_EXTENSION_NOT_PRESENT;
            let mut added = false;
            if api_version < vk::API_VERSION_1_1
                && !properties2_ext
                && crate::bridge::inject::wanted()
            {
                let mut names: Vec<*const c_char> = if ci.pp_enabled_extension_names.is_null() {
                    Vec::new()
                } else {
                    // SAFETY: as above.
                    unsafe {
                        std::slice::from_raw_parts(
                            ci.pp_enabled_extension_names,
                            ci.enabled_extension_count as usize,
                        )
                    }
                    .to_vec()
                };
                names.push(properties2.as_ptr());
                let mut copy = *ci;
                copy.enabled_extension_count = names.len() as u32;
                copy.pp_enabled_extension_names = names.as_ptr();
                // SAFETY: the next layer's function; the copy and its names live across the call.
                r = unsafe { create(&copy, alloc, out) };
                added = r == vk::Result::SUCCESS;
                if !added {
                    tracing::warn!(
                        result = ?r,
                        "cannot enable VK_KHR_get_physical_device_properties2 on a Vulkan 1.0 \
                         instance; its devices are passed through, nothing is injected"
                    );
                    // SAFETY: the loader's struct gets its link back for the retry.
                    unsafe { (*link_info).u[0] = (*layer).p_next as *mut _ };
                }
            }
            if !added {
                // SAFETY: the next layer's function, with the caller's arguments.
                r = unsafe { create(info, alloc, out) };
            }
            if r != vk::Result::SUCCESS {
                return r;
            }
            properties2_ext |= added;
            // SAFETY: the instance was just created; the create info is valid.
            unsafe {
                let handle = *out;
                let next = InstanceNext::load(gipa, handle);
                registry::add_instance(registry::Instance::new(
                    handle,
                    gipa,
                    next,
                    api_version,
                    properties2_ext,
                ));
                tracing::info!(
                    target: fovea_abi::log_target::VK_INSTANCE,
                    instance = raw(handle),
                    api_version = format_args!(
                        "{}.{}",
                        vk::api_version_major(api_version),
                        vk::api_version_minor(api_version)
                    ),
                    "the Vulkan layer is in this VkInstance"
                );
            }
            r
        },
    )
}

/// The loader's `VK_LAYER_LINK_INFO` struct in an instance create info.
///
/// # Safety
/// `ci.p_next` must be a valid chain.
unsafe fn instance_link(ci: &vk::InstanceCreateInfo<'_>) -> Option<*mut LayerInstanceCreateInfo> {
    let mut next = ci.p_next;
    for _ in 0..chain::MAX_CHAIN_LENGTH {
        // SAFETY: as the caller promised.
        let found = unsafe {
            chain::find::<LayerInstanceCreateInfo>(
                next,
                vk::StructureType::LOADER_INSTANCE_CREATE_INFO,
            )
        }
        .ok()
        .flatten()?;
        // SAFETY: found in a valid chain, of the type its sType names.
        let f = unsafe { &*found };
        if f.function == link::LAYER_LINK_INFO {
            return Some(found as *mut _);
        }
        next = f.p_next;
    }
    None
}

/// `vkDestroyInstance`: forgets the instance and destroys it below.
///
/// # Safety
/// `instance` must be NULL or an instance created through the layer.
pub unsafe extern "system" fn destroy_instance(
    instance: vk::Instance,
    alloc: *const vk::AllocationCallbacks<'_>,
) {
    guard("vkDestroyInstance", (), || {
        // SAFETY: as the caller promised.
        let Some(inst) = (unsafe { registry::remove_instance(instance) }) else {
            return;
        };
        if let Some(destroy) = inst.next.destroy_instance {
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { destroy(instance, alloc) };
        }
    })
}
