//! Device creation and the device commands.
//!
//! On an emulated physical device, a `vkCreateDevice` that enables `VK_EXT_fragment_density_map`
//! reaches the driver as one that enables `VK_KHR_fragment_shading_rate` with only
//! `attachmentFragmentShadingRate`: the density-map name and feature struct are left out of a copy
//! of the application's create info. The spec makes the two exclusive
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkDeviceCreateInfo.html>,
//! VUID-VkDeviceCreateInfo-fragmentDensityMap-04481), so the layer owns shading rates on such a
//! device outright; an application that enables shading rates itself (or NV shading-rate images)
//! is left alone there. With injection on (docs/injection.md#switching-it-on), an application that
//! enables shading rates, attachments included, is injected into; its own attachments win per
//! pass.

use std::ffi::{c_char, CStr};

use ash::vk;

use crate::bridge::FdmEmulation;
use crate::vk::chain::{self, ChainCopy};
use crate::vk::dispatch::DeviceNext;
use crate::vk::image;
use crate::vk::link::{self, LayerDeviceCreateInfo, LayerDeviceLink};
use crate::vk::loader::{guard, name};
use crate::vk::physical::{self, needs_translation, translate_image};
use crate::vk::registry::{self, raw, Decision, Instance};

/// The loader's `VK_LAYER_LINK_INFO` struct in a device create info.
///
/// # Safety
/// `ci.p_next` must be a valid chain.
unsafe fn device_link(ci: &vk::DeviceCreateInfo<'_>) -> Option<*mut LayerDeviceCreateInfo> {
    let mut next = ci.p_next;
    for _ in 0..chain::MAX_CHAIN_LENGTH {
        // SAFETY: as the caller promised.
        let found = unsafe {
            chain::find::<LayerDeviceCreateInfo>(next, vk::StructureType::LOADER_DEVICE_CREATE_INFO)
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

/// A rewritten device create info and what it points at.
struct Rewrite {
    /// The copied chain: behind `fsr`, or the one the copy points at where `fsr` is `None`.
    chain: ChainCopy,
    names: Vec<*const c_char>,
    /// The layer's feature struct in front of the chain; `None` where the application's own,
    /// enabling attachments, stays in it.
    fsr: Option<Box<vk::PhysicalDeviceFragmentShadingRateFeaturesKHR<'static>>>,
}

/// What to do with one `vkCreateDevice`.
enum Plan {
    /// Pass the application's create info down untouched; `Some(why)` is logged.
    Untouched(Option<String>),
    Emulate(FdmEmulation, Rewrite),
    /// Injection is on (docs/injection.md#how-the-attachment-gets-in) and the device has
    /// shading-rate attachments: the create info gains `VK_KHR_fragment_shading_rate` and its
    /// attachment feature (the application's own feature struct kept where it enables it); the
    /// device's facts are those the injected maps are made for.
    Inject(FdmEmulation, Rewrite),
}

/// Decides and, for emulation, builds the rewritten create info.
///
/// # Safety
/// `ci` must be a valid create info; `physical` must belong to `inst`.
unsafe fn plan(
    inst: &Instance,
    physical: vk::PhysicalDevice,
    ci: &vk::DeviceCreateInfo<'_>,
) -> Plan {
    let decision = physical::decision(inst, physical);
    let Decision::Emulate { fdm, api_version } = &*decision else {
        return Plan::Untouched(None);
    };
    let names: &[*const c_char] = if ci.pp_enabled_extension_names.is_null() {
        &[]
    } else {
        // SAFETY: as the caller promised.
        unsafe {
            std::slice::from_raw_parts(
                ci.pp_enabled_extension_names,
                ci.enabled_extension_count as usize,
            )
        }
    };
    // SAFETY: the application's names, NUL-terminated.
    let enabled = |want: &CStr| names.iter().any(|&n| unsafe { name(n) } == Some(want));
    // SAFETY: as the caller promised.
    let in_chain = |ty| matches!(unsafe { chain::find::<u8>(ci.p_next, ty) }, Ok(Some(_)));
    let fsr_features = vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_SHADING_RATE_FEATURES_KHR;
    // SAFETY: as the caller promised; found by its sType, read only.
    let app_fsr = unsafe {
        chain::find::<vk::PhysicalDeviceFragmentShadingRateFeaturesKHR<'_>>(ci.p_next, fsr_features)
    }
    .ok()
    .flatten()
    // SAFETY: as above.
    .map(|f| unsafe { *f });
    let nv_rates = enabled(ash::nv::shading_rate_image::NAME)
        || in_chain(vk::StructureType::PHYSICAL_DEVICE_SHADING_RATE_IMAGE_FEATURES_NV);
    let own_rates = enabled(ash::khr::fragment_shading_rate::NAME) || nv_rates || app_fsr.is_some();
    if !enabled(ash::ext::fragment_density_map::NAME) {
        if !crate::bridge::inject::wanted() {
            return Plan::Untouched(None);
        }
        // NV shading-rate images: the application's maps are the ones that count
        // (docs/injection.md#switching-it-on).
        if nv_rates {
            return Plan::Untouched(Some(
                "the application uses NV shading-rate images; nothing is injected on this device"
                    .into(),
            ));
        }
        // The attachment feature enabled (vkd3d-proton enables every shading-rate feature the
        // device has): whether the application uses attachments of its own is told per pass, and
        // where it does, its own wins (docs/injection.md#apps-that-set-rates). Its feature struct
        // already asks for what injection needs and goes down as it came.
        let own_attachments =
            app_fsr.is_some_and(|f| f.attachment_fragment_shading_rate == vk::TRUE);
        // Pipeline or primitive rates (vkd3d-proton's every pipeline): the injected attachment is
        // combined with them (docs/injection.md#apps-that-set-rates).
        let app_sets_rates = app_fsr.is_some_and(|f| {
            f.pipeline_fragment_shading_rate == vk::TRUE
                || f.primitive_fragment_shading_rate == vk::TRUE
        });
        // SAFETY: as the caller promised; the application's feature struct, if any, is left out
        // and stands in the layer's copy in front, unless it enables attachments itself.
        let chain = match unsafe {
            ChainCopy::without(ci.p_next, |t| !own_attachments && t == fsr_features)
        } {
            Ok(c) => c,
            Err(e) => {
                return Plan::Untouched(Some(format!(
                    "cannot extend the device create info's pNext chain ({e:?}); nothing is \
                     injected on this device"
                )))
            }
        };
        if own_attachments {
            tracing::info!(
                "the application enables shading-rate attachments itself: fovea's maps go into \
                 its eye passes without attachments of their own; where it names one, its own \
                 wins"
            );
        }
        if app_sets_rates {
            tracing::info!(
                non_trivial_combiners = fdm.non_trivial_combiners,
                "the application sets shading rates per pipeline or per draw: injected maps are \
                 combined with its rates"
            );
        }
        let version = inst.api_version.min(*api_version);
        let mut rewrite = with_shading_rates(names, &enabled, chain, version, app_fsr.as_ref());
        if own_attachments {
            rewrite.fsr = None;
        }
        return Plan::Inject(fdm.clone(), rewrite);
    }
    if own_rates {
        return Plan::Untouched(Some(
            "the application enables shading rates itself; VK_EXT_fragment_density_map is not \
             emulated on this device"
                .into(),
        ));
    }
    let fdm_features = vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_FEATURES_EXT;
    // SAFETY: as the caller promised.
    if let Ok(Some(f)) = unsafe {
        chain::find::<vk::PhysicalDeviceFragmentDensityMapFeaturesEXT>(ci.p_next, fdm_features)
    } {
        // SAFETY: found by its sType.
        if unsafe { (*f).fragment_density_map_dynamic } == vk::TRUE {
            tracing::warn!(
                "the application enables fragmentDensityMapDynamic, which the layer does not \
                 offer; density maps are emulated as static ones"
            );
        }
    }
    // SAFETY: as the caller promised.
    let chain = match unsafe { ChainCopy::without(ci.p_next, |t| t == fdm_features) } {
        Ok(c) => c,
        Err(e) => {
            return Plan::Untouched(Some(format!(
                "cannot rewrite the device create info's pNext chain ({e:?}); passing it through"
            )))
        }
    };
    tracing::debug!(
        feature_structs_removed = chain.removed(),
        "density maps stripped from the device create info"
    );
    let fdm_name = ash::ext::fragment_density_map::NAME;
    let kept: Vec<*const c_char> = names
        .iter()
        .copied()
        .filter(|&n| {
            // SAFETY: the application's names, NUL-terminated.
            unsafe { name(n) != Some(fdm_name) }
        })
        .collect();
    let version = inst.api_version.min(*api_version);
    Plan::Emulate(
        fdm.clone(),
        with_shading_rates(&kept, &enabled, chain, version, None),
    )
}

/// The create info's extensions (`names`) with `VK_KHR_fragment_shading_rate` and what it needs,
/// and a `VkPhysicalDeviceFragmentShadingRateFeaturesKHR` in front of `chain` enabling the
/// attachment feature and, from `app` (the application's own struct, left out of `chain`), the
/// features it enabled itself; the layer asks for no other: they would oblige every draw to set
/// a rate (docs/vulkan-fdm-on-fsr.md#other-pipeline-paths).
fn with_shading_rates(
    names: &[*const c_char],
    enabled: &dyn Fn(&CStr) -> bool,
    chain: ChainCopy,
    version: u32,
    app: Option<&vk::PhysicalDeviceFragmentShadingRateFeaturesKHR<'_>>,
) -> Rewrite {
    let mut new_names = names.to_vec();
    if !enabled(ash::khr::fragment_shading_rate::NAME) {
        new_names.push(ash::khr::fragment_shading_rate::NAME.as_ptr());
    }
    // Shading rates need render pass 2 (core in 1.2) and, through it, multiview and maintenance2
    // (core in 1.1).
    if version < vk::API_VERSION_1_2 {
        for dep in [
            ash::khr::create_renderpass2::NAME,
            ash::khr::multiview::NAME,
            ash::khr::maintenance2::NAME,
        ] {
            if !enabled(dep) {
                new_names.push(dep.as_ptr());
            }
        }
    }
    let mut fsr = Box::new(
        vk::PhysicalDeviceFragmentShadingRateFeaturesKHR::default()
            .pipeline_fragment_shading_rate(
                app.is_some_and(|f| f.pipeline_fragment_shading_rate == vk::TRUE),
            )
            .primitive_fragment_shading_rate(
                app.is_some_and(|f| f.primitive_fragment_shading_rate == vk::TRUE),
            )
            .attachment_fragment_shading_rate(true),
    );
    fsr.p_next = chain.head() as *mut _;
    Rewrite {
        chain,
        names: new_names,
        fsr: Some(fsr),
    }
}

/// `vkCreateDevice`: finds the next layer in the loader's link info, creates the device there
/// (rewritten where the layer emulates density maps) and records it.
///
/// # Safety
/// Called by the loader with valid arguments and link info.
pub unsafe extern "system" fn create_device(
    physical: vk::PhysicalDevice,
    info: *const vk::DeviceCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Device,
) -> vk::Result {
    guard(
        "vkCreateDevice",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        // SAFETY: the caller's arguments, checked and passed on.
        || unsafe { create_device_impl(physical, info, alloc, out) },
    )
}

unsafe fn create_device_impl(
    physical: vk::PhysicalDevice,
    info: *const vk::DeviceCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Device,
) -> vk::Result {
    if info.is_null() || out.is_null() {
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    }
    // SAFETY: a physical device dispatched by the loader.
    let Some(inst) = (unsafe { registry::instance(physical) }) else {
        tracing::error!("vkCreateDevice on a physical device the layer does not know");
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    };
    // SAFETY: the loader's create info.
    let ci = unsafe { &*info };
    // SAFETY: the chain is valid.
    let Some(link_info) = (unsafe { device_link(ci) }) else {
        tracing::error!("vkCreateDevice without the loader's link info");
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    };
    // SAFETY: the loader's list of layers below. The protocol has each layer advance `pLayerInfo`
    // in the loader's struct before calling down; it is the loader's struct, not the app's.
    let (layer, gipa, gdpa) = unsafe {
        let layer = (*link_info).u as *mut LayerDeviceLink;
        if layer.is_null() {
            return vk::Result::ERROR_INITIALIZATION_FAILED;
        }
        (*link_info).u = (*layer).p_next as *mut _;
        (
            layer,
            (*layer).pfn_next_get_instance_proc_addr,
            (*layer).pfn_next_get_device_proc_addr,
        )
    };
    // SAFETY: the next layer's vkCreateDevice, asked of it with the instance (not NULL, which
    // would reach the wrong layer), of the type its name implies.
    let create = unsafe {
        let Some(f) = gipa(inst.handle, c"vkCreateDevice".as_ptr()) else {
            return vk::Result::ERROR_INITIALIZATION_FAILED;
        };
        std::mem::transmute::<unsafe extern "system" fn(), vk::PFN_vkCreateDevice>(f)
    };
    // SAFETY: as the caller promised.
    let plan = unsafe { plan(&inst, physical, ci) };
    let inject = matches!(plan, Plan::Inject(..));
    let (r, fdm) = match plan {
        Plan::Untouched(why) => {
            if let Some(why) = why {
                tracing::warn!(
                    physical = raw(physical),
                    why = why.as_str(),
                    "vkCreateDevice"
                );
            }
            // SAFETY: the next layer's function, with the caller's arguments.
            (unsafe { create(physical, info, alloc, out) }, None)
        }
        Plan::Emulate(fdm, rewrite) | Plan::Inject(fdm, rewrite) => {
            let mut copy = *ci;
            copy.p_next = match &rewrite.fsr {
                Some(fsr) => &**fsr as *const _ as *const _,
                None => rewrite.chain.head(),
            };
            copy.enabled_extension_count = rewrite.names.len() as u32;
            copy.pp_enabled_extension_names = rewrite.names.as_ptr();
            // SAFETY: the copy and everything it points at live across the call.
            let r = unsafe { create(physical, &copy, alloc, out) };
            drop(rewrite);
            if r == vk::Result::SUCCESS {
                (r, Some(fdm))
            } else if matches!(
                r,
                vk::Result::ERROR_OUT_OF_HOST_MEMORY
                    | vk::Result::ERROR_OUT_OF_DEVICE_MEMORY
                    | vk::Result::ERROR_DEVICE_LOST
            ) {
                // Not the rewrite's doing: the driver's answer, unchanged. A retry without the
                // rewrite would ask for the density-map extension the driver lacks and answer
                // with that instead.
                (r, None)
            } else {
                // Fail open: the application's own request, as it was, gets its answer.
                tracing::warn!(
                    physical = raw(physical),
                    result = ?r,
                    inject,
                    "creating the device with shading-rate attachments failed; retrying untouched"
                );
                // SAFETY: the loader's struct gets its link back for the retry.
                unsafe { (*link_info).u = (*layer).p_next as *mut _ };
                // SAFETY: the next layer's function, with the caller's arguments.
                (unsafe { create(physical, info, alloc, out) }, None)
            }
        }
    };
    if r != vk::Result::SUCCESS {
        return r;
    }
    // Injection uses the device's shading-rate facts, but emulates nothing.
    let (fdm, inject) = if inject { (None, fdm) } else { (fdm, None) };
    // SAFETY: the device was just created.
    unsafe {
        let handle = *out;
        let next = DeviceNext::load(gdpa, handle);
        let api_version = match &*physical::decision(&inst, physical) {
            registry::Decision::Emulate { api_version, .. } => inst.api_version.min(*api_version),
            _ => inst.api_version,
        };
        let mut own = None;
        if fdm.is_some() {
            tracing::info!(
                device = raw(handle),
                "device emulates fragment density maps"
            );
            match image::Own::new(&inst, physical, ci, handle, gdpa) {
                Ok(o) => own = Some(std::sync::Arc::new(o)),
                Err(why) => tracing::warn!(
                    device = raw(handle),
                    why = why.as_str(),
                    "density maps on this device get no shading-rate shadows: they render at \
                     full rate"
                ),
            }
        }
        let inject = inject.and_then(|facts| {
            match image::Own::new(&inst, physical, ci, handle, gdpa) {
                Ok(o) => {
                    own = Some(std::sync::Arc::new(o));
                    tracing::info!(
                        device = raw(handle),
                        "device has shading-rate attachments for injection"
                    );
                    Some(crate::vk::inject::Injector::new(facts))
                }
                // Fail open: the device keeps the feature, and its passes run unmodified.
                Err(why) => {
                    tracing::warn!(
                        device = raw(handle),
                        why = why.as_str(),
                        "nothing is injected on this device: the layer cannot make its \
                         shading-rate maps there"
                    );
                    None
                }
            }
        });
        registry::add_device(registry::Device {
            handle,
            gdpa,
            next,
            fdm,
            inject,
            api_version,
            attachments: registry::Attachments::new(own),
        });
        crate::vk::convert::device_created(&inst, physical, ci, handle);
    }
    r
}

/// `vkDestroyDevice`: forgets the device and destroys it below.
///
/// # Safety
/// `device` must be NULL or a device created through the layer.
pub unsafe extern "system" fn destroy_device(
    device: vk::Device,
    alloc: *const vk::AllocationCallbacks<'_>,
) {
    guard("vkDestroyDevice", (), || {
        // SAFETY: as the caller promised.
        let Some(dev) = (unsafe { registry::remove_device(device) }) else {
            return;
        };
        // SAFETY: the device is live; the application has finished with it (destroy_all waits
        // for the layer's clears and uploads in flight before the maps go).
        unsafe {
            crate::vk::convert::device_destroyed(device);
            image::destroy_all(&dev);
            if let (Some(inj), Some(own)) = (&dev.inject, &dev.attachments.own) {
                inj.destroy(own);
            }
        }
        if let Some(destroy) = dev.next.destroy_device {
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { destroy(device, alloc) };
        }
    })
}

/// `vkCreateImage` on an injecting device: the image goes down untouched, and a colour image's
/// extent and layers are noted for finding eye passes ([`crate::vk::inject`]).
///
/// `vkCreateImage` on an emulating device: a density map reaches the driver without the
/// density-map usage and subsampled flag it does not know (on a copy of the create info), and
/// gets a shading-rate shadow ([`image::image_created`]); where the shadow cannot be made, the
/// application's image is returned all the same (fail open: its passes render at full rate).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn create_image(
    device: vk::Device,
    info: *const vk::ImageCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Image,
) -> vk::Result {
    guard(
        "vkCreateImage",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let Some(dev) = (unsafe { registry::device(device) }) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let Some(next) = dev.next.create_image else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            if let Some(inj) = &dev.inject {
                // SAFETY: the next layer's function, with the caller's arguments.
                let r = unsafe { next(device, info, alloc, out) };
                if r == vk::Result::SUCCESS && !info.is_null() && !out.is_null() {
                    // SAFETY: the caller's create info, read only; the image just created.
                    unsafe { inj.image_created(*out, &*info) };
                }
                return r;
            }
            if info.is_null() || dev.fdm.is_none() {
                // SAFETY: the next layer's function, with the caller's arguments.
                return unsafe { next(device, info, alloc, out) };
            }
            // SAFETY: the caller's create info, read only.
            let mut copy = unsafe { *info };
            if !needs_translation(copy.usage, copy.flags) {
                // SAFETY: as above.
                return unsafe { next(device, info, alloc, out) };
            }
            match translate_image(
                copy.format,
                copy.image_type,
                copy.tiling,
                copy.usage,
                copy.flags,
            ) {
                Some((usage, flags)) => {
                    copy.usage = usage;
                    copy.flags = flags;
                }
                None => {
                    tracing::warn!(
                        format = ?copy.format,
                        "a density-map image that is not 2D, optimal R8G8_UNORM; passed on as is"
                    );
                    // SAFETY: as above.
                    return unsafe { next(device, info, alloc, out) };
                }
            }
            // SAFETY: the translated copy lives across the call.
            let r = unsafe { next(device, &copy, alloc, out) };
            // SAFETY: the caller's create info, read only.
            let app = unsafe { &*info };
            if r == vk::Result::SUCCESS
                && !out.is_null()
                && app
                    .usage
                    .contains(vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT)
            {
                // SAFETY: the image was just created from `app`.
                unsafe { image::image_created(&dev, *out, app) };
            }
            r
        },
    )
}
