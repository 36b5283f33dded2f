//! Instances: `vkCreateInstance` (through the loader's link, with the next layer's table loaded and
//! the instance recorded) and `vkDestroyInstance`.

use std::ffi::c_char;

use ash::vk;

use crate::vk::base::chain;
use crate::vk::base::ffi::{extension_enabled, guard, key, raw};
use crate::vk::base::link::{self, LayerInstanceCreateInfo, LayerInstanceLink};
use crate::vk::base::next::InstanceNext;
use crate::vk::registry;

/// `vkCreateInstance`: finds the next layer in the loader's link info, advances the link for the
/// layers below, creates the instance there and records it.
///
/// # Safety
/// Called by the loader (or the layer above) with a valid create info carrying link info.
pub unsafe extern "system" fn create_instance(
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

/// `vkDestroyInstance`: forgets the instance, and any device of it the application did not
/// destroy first (without a call to their driver, [`registry::forget_devices_of`]), and destroys
/// it below.
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
        // SAFETY: as the caller promised.
        if let Some(k) = unsafe { key(instance) } {
            let devices = registry::forget_devices_of(k);
            if !devices.is_empty() {
                tracing::warn!(
                    instance = raw(instance),
                    devices = devices.len(),
                    "the application destroys a VkInstance whose devices it has not destroyed \
                     (VUID-vkDestroyInstance-instance-00629): the layer forgets them and their \
                     command buffers without calling their driver"
                );
            }
            for d in devices {
                registry::device_key_reused(d);
            }
        }
        if let Some(destroy) = inst.next.destroy_instance {
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { destroy(instance, alloc) };
        }
    })
}
