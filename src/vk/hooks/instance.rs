//! Instances: `vkCreateInstance` (through the loader's link, with the next layer's table loaded and
//! the instance recorded) and `vkDestroyInstance`.

use std::ffi::c_char;

use ash::vk;

use crate::vk::base::chain;
use crate::vk::base::ffi::{key, raw, In, Out};
use crate::vk::base::link::{self, LayerInstanceCreateInfo, LayerInstanceLink};
use crate::vk::base::next::InstanceNext;
use crate::vk::registry;

hook! {
    /// `vkCreateInstance`: finds the next layer in the loader's link info, advances the link for
    /// the layers below, creates the instance there and records it.
    create_instance = "vkCreateInstance"; raw, fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    create(
        info: in vk::InstanceCreateInfo<'_>,
        alloc: val *const vk::AllocationCallbacks<'_>,
        out: out vk::Instance,
    ) -> vk::Result
}

fn create(
    info: In<'_, vk::InstanceCreateInfo<'_>>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: Out<'_, vk::Instance>,
) -> vk::Result {
    crate::common::log::init();
    let (Some(ci), false) = (info.get(), out.is_null()) else {
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    };
    // SAFETY: the loader's create info, its chain valid.
    let Some(link_info) = (unsafe { instance_link(ci) }) else {
        tracing::error!("vkCreateInstance without the loader's link info");
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    };
    // SAFETY: the loader's link info, found in its create info.
    let Some(link) = (unsafe { Link::advance(link_info) }) else {
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    };
    // SAFETY: the next layer's `vkGetInstanceProcAddr` from the loader's link.
    let Some(create) = (unsafe { link.create() }) else {
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    };
    // SAFETY: the application info is NULL or valid (the command's valid usage).
    let api_version = match unsafe { ci.p_application_info.as_ref() } {
        Some(a) if a.api_version != 0 => a.api_version,
        _ => vk::API_VERSION_1_0,
    };
    let properties2_ext = info.enables(ash::khr::get_physical_device_properties2::NAME);
    let down = Down {
        create,
        info,
        alloc,
        out: out.raw(),
    };
    let wants = api_version < vk::API_VERSION_1_1 && !properties2_ext;
    let (r, added) = down.create(&link, wants && crate::bridge::inject::wanted());
    if let (vk::Result::SUCCESS, Some(handle)) = (r, out.read()) {
        record(&link, handle, api_version, properties2_ext || added);
    }
    r
}

/// The loader's link to the next layer: its `VK_LAYER_LINK_INFO` struct and the layer's entry in
/// it.
struct Link {
    info: *mut LayerInstanceCreateInfo,
    layer: *const LayerInstanceLink,
    gipa: vk::PFN_vkGetInstanceProcAddr,
}

impl Link {
    /// The next layer's link, with the loader's struct advanced past it for the layers below.
    ///
    /// # Safety
    /// `info` must be the loader's link info of the create info being handled.
    unsafe fn advance(info: *mut LayerInstanceCreateInfo) -> Option<Link> {
        // SAFETY: the loader's list of layers below; the protocol has each layer advance
        // `pLayerInfo` in the loader's struct before calling down (the struct is the loader's,
        // not the application's).
        unsafe {
            let layer = (*info).u[0] as *const LayerInstanceLink;
            if layer.is_null() {
                return None;
            }
            let link = Link {
                info,
                layer,
                gipa: (*layer).pfn_next_get_instance_proc_addr,
            };
            link.rewind();
            Some(link)
        }
    }

    /// Points the loader's struct past this layer again, for a retry of the call down.
    ///
    /// # Safety
    /// As [`Link::advance`].
    unsafe fn rewind(&self) {
        // SAFETY: as the caller promised.
        unsafe { (*self.info).u[0] = (*self.layer).p_next as *mut _ };
    }

    /// The next layer's `vkCreateInstance`.
    ///
    /// # Safety
    /// `self.gipa` must be the next layer's `vkGetInstanceProcAddr`.
    unsafe fn create(&self) -> Option<vk::PFN_vkCreateInstance> {
        // SAFETY: as the caller promised; the pointer is of the type its name implies.
        unsafe {
            (self.gipa)(vk::Instance::null(), c"vkCreateInstance".as_ptr()).map(|f| {
                std::mem::transmute::<unsafe extern "system" fn(), vk::PFN_vkCreateInstance>(f)
            })
        }
    }
}

/// The call down: the next layer's `vkCreateInstance` and the application's arguments.
struct Down<'a> {
    create: vk::PFN_vkCreateInstance,
    info: In<'a, vk::InstanceCreateInfo<'a>>,
    alloc: *const vk::AllocationCallbacks<'a>,
    out: *mut vk::Instance,
}

impl Down<'_> {
    /// Creates the instance below: first, where `properties2`, with
    /// `VK_KHR_get_physical_device_properties2` added on a copy of the create info, which
    /// injection (docs/injection.md) needs to read a Vulkan 1.0 instance's (hello_xr's) devices'
    /// shading-rate properties and features; where that fails, or without `properties2`, as the
    /// application asked (its devices are then passed through). The second value says whether
    /// the extension was added.
    fn create(&self, link: &Link, properties2: bool) -> (vk::Result, bool) {
        if properties2 {
            let r = self.with_properties2();
            if r == vk::Result::SUCCESS {
                return (r, true);
            }
            tracing::warn!(
                result = ?r,
                "cannot enable VK_KHR_get_physical_device_properties2 on a Vulkan 1.0 instance; \
                 its devices are passed through, nothing is injected"
            );
            // SAFETY: the loader's struct gets its link back for the retry.
            unsafe { link.rewind() };
        }
        // SAFETY: the next layer's function, with the application's arguments.
        let r = unsafe { (self.create)(self.info.raw(), self.alloc, self.out) };
        (r, false)
    }

    /// The call down with `VK_KHR_get_physical_device_properties2` added to a copy.
    fn with_properties2(&self) -> vk::Result {
        let Some(ci) = self.info.get() else {
            return vk::Result::ERROR_INITIALIZATION_FAILED;
        };
        let mut names: Vec<*const c_char> = self.info.names().to_vec();
        names.push(ash::khr::get_physical_device_properties2::NAME.as_ptr());
        let mut copy = *ci;
        copy.enabled_extension_count = names.len() as u32;
        copy.pp_enabled_extension_names = names.as_ptr();
        // SAFETY: the next layer's function; the copy and its names live across the call.
        unsafe { (self.create)(&copy, self.alloc, self.out) }
    }
}

/// Records the instance just created below, with the next layer's table.
fn record(link: &Link, handle: vk::Instance, api_version: u32, properties2_ext: bool) {
    // SAFETY: the next layer's `vkGetInstanceProcAddr`, and the instance it just created.
    unsafe {
        let next = InstanceNext::load(link.gipa, handle);
        registry::add_instance(registry::Instance::new(
            handle,
            link.gipa,
            next,
            api_version,
            properties2_ext,
        ));
    }
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

hook! {
    /// `vkDestroyInstance`: forgets the instance, and any device of it the application did not
    /// destroy first (without a call to their driver, [`registry::forget_devices_of`]), and
    /// destroys it below.
    destroy_instance = "vkDestroyInstance"; raw, fails(());
    destroy(instance: val vk::Instance, alloc: val *const vk::AllocationCallbacks<'_>) -> ()
}

fn destroy(instance: vk::Instance, alloc: *const vk::AllocationCallbacks<'_>) {
    // SAFETY: an instance the loader dispatched (or NULL): its first word is its dispatch key.
    let Some(inst) = (unsafe { registry::remove_instance(instance) }) else {
        return;
    };
    // SAFETY: as above.
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
        // SAFETY: the next layer's function, with the application's arguments.
        unsafe { destroy(instance, alloc) };
    }
}
