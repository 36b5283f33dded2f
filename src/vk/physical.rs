//! What the application sees of a physical device: the decision per device, and the queries that
//! show emulated fragment density maps
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/VK_EXT_fragment_density_map.html>).

use std::ffi::{c_char, c_void};
use std::sync::Arc;

use ash::vk;

use crate::bridge::FdmEmulation;
use crate::vk::base::chain;
use crate::vk::base::ffi::{guard, name, raw, two_call};
use crate::vk::registry::{self, Decision, Instance};

/// `VK_EXT_fragment_density_map` as the layer offers it.
pub fn fdm_extension() -> vk::ExtensionProperties {
    let mut e = vk::ExtensionProperties {
        spec_version: fovea_abi::VK_FDM_SPEC_VERSION,
        ..Default::default()
    };
    for (d, s) in e
        .extension_name
        .iter_mut()
        .zip(fovea_abi::VK_FDM_EXTENSION.bytes())
    {
        *d = s as c_char;
    }
    e
}

/// The decision for `physical`, made once per instance and physical device (and logged then).
pub fn decision(inst: &Instance, physical: vk::PhysicalDevice) -> Arc<Decision> {
    let key = raw(physical);
    if let Some(d) = inst.decisions.lock().get(&key) {
        return d.clone();
    }
    // Queried without the lock held: a concurrent first query decides twice, identically.
    // SAFETY: `physical` belongs to `inst` (the loader dispatched it here).
    let d = Arc::new(unsafe { decide(inst, physical) });
    match &*d {
        Decision::Native => {
            tracing::info!(
                physical = key,
                "native fragment density maps: passing through"
            )
        }
        Decision::Emulate { fdm, .. } => tracing::info!(
            physical = key,
            texel = ?fdm.texel,
            layered = fdm.layered,
            max_fragment = ?fdm.max_fragment,
            "emulating VK_EXT_fragment_density_map on shading-rate attachments"
        ),
        Decision::PassThrough(why) => tracing::info!(
            physical = key,
            why = why.as_str(),
            "not emulating fragment density maps: passing through"
        ),
    }
    inst.decisions.lock().entry(key).or_insert(d).clone()
}

/// The emulation facts of `physical`, if it is emulated.
pub fn emulated(inst: &Instance, physical: vk::PhysicalDevice) -> Option<FdmEmulation> {
    match &*decision(inst, physical) {
        Decision::Emulate { fdm, .. } => Some(fdm.clone()),
        _ => None,
    }
}

/// The driver's (the next layer's) device extensions.
///
/// # Safety
/// `physical` must belong to `inst`.
pub unsafe fn driver_extensions(
    inst: &Instance,
    physical: vk::PhysicalDevice,
) -> Result<Vec<vk::ExtensionProperties>, vk::Result> {
    let f = inst
        .next
        .enumerate_device_extension_properties
        .ok_or(vk::Result::ERROR_INITIALIZATION_FAILED)?;
    loop {
        let mut n = 0;
        // SAFETY: the next layer's function; the vector holds `n` elements.
        unsafe {
            let r = f(physical, std::ptr::null(), &mut n, std::ptr::null_mut());
            if r != vk::Result::SUCCESS {
                return Err(r);
            }
            let mut v = vec![vk::ExtensionProperties::default(); n as usize];
            match f(physical, std::ptr::null(), &mut n, v.as_mut_ptr()) {
                vk::Result::SUCCESS => {
                    v.truncate(n as usize);
                    return Ok(v);
                }
                vk::Result::INCOMPLETE => continue,
                r => return Err(r),
            }
        }
    }
}

fn has(exts: &[vk::ExtensionProperties], want: &std::ffi::CStr) -> bool {
    exts.iter().any(|e| e.extension_name_as_c_str() == Ok(want))
}

/// The next layer's `vkGetPhysicalDeviceFeatures2` and `…Properties2` usable on this instance:
/// core where the instance is 1.1 or later, else the KHR ones where the extension is enabled.
fn queries2(
    inst: &Instance,
) -> Option<(
    vk::PFN_vkGetPhysicalDeviceFeatures2,
    vk::PFN_vkGetPhysicalDeviceProperties2,
)> {
    if inst.api_version >= vk::API_VERSION_1_1 {
        if let (Some(f), Some(p)) = (inst.next.get_features2, inst.next.get_properties2) {
            return Some((f, p));
        }
    }
    if inst.properties2_ext {
        if let (Some(f), Some(p)) = (inst.next.get_features2_khr, inst.next.get_properties2_khr) {
            return Some((f, p));
        }
    }
    None
}

/// Whether the driver below implements fragment density maps: its `fragmentDensityMap` feature is
/// TRUE. Where the feature cannot be asked for (no `vkGetPhysicalDeviceFeatures2` usable on the
/// instance), a listed extension is taken at its word: passing through is the choice that cannot
/// break a native implementation.
///
/// # Safety
/// `physical` must belong to `inst`.
unsafe fn native_fdm(inst: &Instance, physical: vk::PhysicalDevice) -> bool {
    let Some((features2, _)) = queries2(inst) else {
        return true;
    };
    let mut fdm = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default();
    let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut fdm);
    // SAFETY: the next layer's function with structs that live across the call; `physical` is the
    // caller's.
    unsafe { features2(physical, &mut f2) };
    fdm.fragment_density_map == vk::TRUE
}

/// Decides from what the driver offers.
///
/// # Safety
/// `physical` must belong to `inst`.
unsafe fn decide(inst: &Instance, physical: vk::PhysicalDevice) -> Decision {
    let pass = |why: &str| Decision::PassThrough(why.to_owned());
    // SAFETY: as the caller promised.
    let exts = match unsafe { driver_extensions(inst, physical) } {
        Ok(e) => e,
        Err(r) => return pass(&format!("vkEnumerateDeviceExtensionProperties failed: {r}")),
    };
    // The extension in the list is not proof of a native implementation: where this layer is
    // installed implicitly, the Vulkan loader adds the `device_extensions` of implicit layers'
    // manifests to what it lists below them, this layer's own VK_EXT_fragment_density_map included
    // (https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md,
    // "Layer Manifest File Format", `device_extensions`). Only a driver that implements it fills
    // its feature struct, so the feature decides.
    // SAFETY: as the caller promised.
    if has(&exts, ash::ext::fragment_density_map::NAME) && unsafe { native_fdm(inst, physical) } {
        return Decision::Native;
    }
    if !has(&exts, ash::khr::fragment_shading_rate::NAME) {
        return pass("the driver offers no VK_KHR_fragment_shading_rate");
    }
    let Some((features2, properties2)) = queries2(inst) else {
        return pass(
            "the instance has neither Vulkan 1.1 nor VK_KHR_get_physical_device_properties2",
        );
    };
    let Some(rates_fn) = inst.get_fragment_shading_rates else {
        return pass("no vkGetPhysicalDeviceFragmentShadingRatesKHR below");
    };
    let mut fsr = vk::PhysicalDeviceFragmentShadingRateFeaturesKHR::default();
    let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut fsr);
    // SAFETY: the next layer's function with structs that live across the call.
    unsafe { features2(physical, &mut f2) };
    if fsr.attachment_fragment_shading_rate != vk::TRUE {
        return pass("the driver has no attachmentFragmentShadingRate");
    }
    let mut props = vk::PhysicalDeviceFragmentShadingRatePropertiesKHR::default();
    let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut props);
    // SAFETY: as above.
    unsafe { properties2(physical, &mut p2) };
    let api_version = p2.properties.api_version;
    if api_version < vk::API_VERSION_1_1 {
        return pass("the device is Vulkan 1.0");
    }
    let min = props.min_fragment_shading_rate_attachment_texel_size;
    let max = props.max_fragment_shading_rate_attachment_texel_size;
    // Any power of two in [min, max] is a legal shading-rate texel; the layer takes the minimum
    // (the finest the driver allows; min = max on every desktop driver known), and reports it as
    // both the minimum and the maximum density texel, which pins the density texel to it.
    let texel = [min.width, min.height];
    if !texel.iter().all(|t| t.is_power_of_two()) || min.width > max.width {
        return pass(&format!(
            "the driver reports an unusable shading-rate texel size {min:?}..{max:?}"
        ));
    }
    if min != max {
        tracing::debug!(?min, ?max, "texel sizes differ; emulating with the minimum");
    }
    let mut n = 0;
    // SAFETY: the next layer's function; the vector holds `n` elements.
    let rates = unsafe {
        let r = rates_fn(physical, &mut n, std::ptr::null_mut());
        if r != vk::Result::SUCCESS {
            return pass(&format!("vkGetPhysicalDeviceFragmentShadingRatesKHR: {r}"));
        }
        let mut v = vec![vk::PhysicalDeviceFragmentShadingRateKHR::default(); n as usize];
        let r = rates_fn(physical, &mut n, v.as_mut_ptr());
        if r != vk::Result::SUCCESS && r != vk::Result::INCOMPLETE {
            return pass(&format!("vkGetPhysicalDeviceFragmentShadingRatesKHR: {r}"));
        }
        v.truncate(n as usize);
        v
    };
    let rates = rates
        .iter()
        .filter(|r| r.sample_counts.contains(vk::SampleCountFlags::TYPE_1))
        .map(|r| [r.fragment_size.width, r.fragment_size.height])
        .collect();
    Decision::Emulate {
        fdm: FdmEmulation {
            texel,
            layered: props.layered_shading_rate_attachments == vk::TRUE,
            max_fragment: [
                props.max_fragment_size.width,
                props.max_fragment_size.height,
            ],
            rates,
            non_trivial_combiners: props.fragment_shading_rate_non_trivial_combiner_ops == vk::TRUE,
        },
        api_version,
    }
}

/// `vkEnumerateDeviceExtensionProperties`: on an emulated device the driver's list plus
/// `VK_EXT_fragment_density_map`; asked for this layer's own extensions, that one where emulated.
unsafe extern "system" fn enumerate_device_extension_properties_impl(
    physical: vk::PhysicalDevice,
    layer: *const c_char,
    count: *mut u32,
    out: *mut vk::ExtensionProperties,
) -> vk::Result {
    // SAFETY: the loader dispatched a physical device of an instance made through the layer.
    let Some(inst) = (unsafe { registry::instance(physical) }) else {
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    };
    let Some(next) = inst.next.enumerate_device_extension_properties else {
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    };
    // SAFETY: the caller's name.
    if let Some(layer_name) = unsafe { name(layer) } {
        if layer_name.to_bytes() == fovea_abi::VK_LAYER_NAME.as_bytes() {
            let ours: Vec<_> = emulated(&inst, physical)
                .map(|_| fdm_extension())
                .into_iter()
                .collect();
            // SAFETY: the caller's pointers.
            return unsafe { two_call(&ours, count, out) };
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        return unsafe { next(physical, layer, count, out) };
    }
    if emulated(&inst, physical).is_none() {
        // SAFETY: as above.
        return unsafe { next(physical, layer, count, out) };
    }
    // SAFETY: `physical` belongs to `inst`.
    let mut exts = match unsafe { driver_extensions(&inst, physical) } {
        Ok(e) => e,
        Err(r) => return r,
    };
    if !has(&exts, ash::ext::fragment_density_map::NAME) {
        exts.push(fdm_extension());
    }
    // SAFETY: the caller's pointers.
    unsafe { two_call(&exts, count, out) }
}

/// See [`enumerate_device_extension_properties_impl`].
pub unsafe extern "system" fn enumerate_device_extension_properties(
    physical: vk::PhysicalDevice,
    layer: *const c_char,
    count: *mut u32,
    out: *mut vk::ExtensionProperties,
) -> vk::Result {
    guard(
        "vkEnumerateDeviceExtensionProperties",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        // SAFETY: the caller's arguments, passed on.
        || unsafe { enumerate_device_extension_properties_impl(physical, layer, count, out) },
    )
}

/// Fills `VkPhysicalDeviceFragmentDensityMapFeaturesEXT` in an output chain: density maps and
/// non-subsampled images, not dynamic ones.
///
/// # Safety
/// `next` must be a valid, writable output chain.
unsafe fn fill_features(next: *mut c_void) {
    // SAFETY: as the caller promised.
    if let Some(f) = unsafe {
        chain::find_out::<vk::PhysicalDeviceFragmentDensityMapFeaturesEXT>(
            next,
            vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_FEATURES_EXT,
        )
    } {
        // SAFETY: found by its sType in the caller's output chain.
        unsafe {
            (*f).fragment_density_map = vk::TRUE;
            (*f).fragment_density_map_dynamic = vk::FALSE;
            (*f).fragment_density_map_non_subsampled_images = vk::TRUE;
        }
    }
}

/// `vkGetPhysicalDeviceFeatures2` (`khr`: the KHR alias).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn features2(
    khr: bool,
    physical: vk::PhysicalDevice,
    out: *mut vk::PhysicalDeviceFeatures2<'_>,
) {
    // SAFETY: a physical device made through the layer.
    let Some(inst) = (unsafe { registry::instance(physical) }) else {
        return;
    };
    let next = if khr {
        inst.next.get_features2_khr
    } else {
        inst.next.get_features2
    };
    let Some(next) = next else { return };
    // SAFETY: the next layer's function, with the caller's arguments.
    unsafe { next(physical, out) };
    if !out.is_null() && emulated(&inst, physical).is_some() {
        // SAFETY: the caller's output chain.
        unsafe { fill_features((*out).p_next) };
    }
}

pub unsafe extern "system" fn get_features2(
    physical: vk::PhysicalDevice,
    out: *mut vk::PhysicalDeviceFeatures2<'_>,
) {
    // SAFETY: the caller's arguments, passed on.
    guard("vkGetPhysicalDeviceFeatures2", (), || unsafe {
        features2(false, physical, out)
    })
}

pub unsafe extern "system" fn get_features2_khr(
    physical: vk::PhysicalDevice,
    out: *mut vk::PhysicalDeviceFeatures2<'_>,
) {
    // SAFETY: the caller's arguments, passed on.
    guard("vkGetPhysicalDeviceFeatures2KHR", (), || unsafe {
        features2(true, physical, out)
    })
}

/// `vkGetPhysicalDeviceProperties2`: `VkPhysicalDeviceFragmentDensityMapPropertiesEXT` with
/// min = max density texel = the shading-rate texel, and no extra invocations.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn properties2(
    khr: bool,
    physical: vk::PhysicalDevice,
    out: *mut vk::PhysicalDeviceProperties2<'_>,
) {
    // SAFETY: a physical device made through the layer.
    let Some(inst) = (unsafe { registry::instance(physical) }) else {
        return;
    };
    let next = if khr {
        inst.next.get_properties2_khr
    } else {
        inst.next.get_properties2
    };
    let Some(next) = next else { return };
    // SAFETY: the next layer's function, with the caller's arguments.
    unsafe { next(physical, out) };
    let Some(fdm) = emulated(&inst, physical) else {
        return;
    };
    if out.is_null() {
        return;
    }
    // SAFETY: the caller's output chain.
    if let Some(p) = unsafe {
        chain::find_out::<vk::PhysicalDeviceFragmentDensityMapPropertiesEXT>(
            (*out).p_next,
            vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_PROPERTIES_EXT,
        )
    } {
        let texel = vk::Extent2D {
            width: fdm.texel[0],
            height: fdm.texel[1],
        };
        // SAFETY: found by its sType in the caller's output chain.
        unsafe {
            (*p).min_fragment_density_texel_size = texel;
            (*p).max_fragment_density_texel_size = texel;
            (*p).fragment_density_invocations = vk::FALSE;
        }
    }
}

pub unsafe extern "system" fn get_properties2(
    physical: vk::PhysicalDevice,
    out: *mut vk::PhysicalDeviceProperties2<'_>,
) {
    // SAFETY: the caller's arguments, passed on.
    guard("vkGetPhysicalDeviceProperties2", (), || unsafe {
        properties2(false, physical, out)
    })
}

pub unsafe extern "system" fn get_properties2_khr(
    physical: vk::PhysicalDevice,
    out: *mut vk::PhysicalDeviceProperties2<'_>,
) {
    // SAFETY: the caller's arguments, passed on.
    guard("vkGetPhysicalDeviceProperties2KHR", (), || unsafe {
        properties2(true, physical, out)
    })
}

/// The format that carries density maps: R8G8_UNORM, whose `FRAGMENT_DENSITY_MAP` feature the spec
/// makes mandatory where density maps are supported
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkFormatFeatureFlagBits.html>).
pub const FDM_FORMAT: vk::Format = vk::Format::R8G8_UNORM;

pub unsafe extern "system" fn get_format_properties(
    physical: vk::PhysicalDevice,
    format: vk::Format,
    out: *mut vk::FormatProperties,
) {
    guard("vkGetPhysicalDeviceFormatProperties", (), || {
        // SAFETY: a physical device made through the layer.
        let Some(inst) = (unsafe { registry::instance(physical) }) else {
            return;
        };
        let Some(next) = inst.next.get_format_properties else {
            return;
        };
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { next(physical, format, out) };
        if format == FDM_FORMAT && !out.is_null() && emulated(&inst, physical).is_some() {
            // SAFETY: the caller's output struct.
            unsafe {
                (*out).optimal_tiling_features |= vk::FormatFeatureFlags::FRAGMENT_DENSITY_MAP_EXT
            };
        }
    })
}

/// `vkGetPhysicalDeviceFormatProperties2`: the density-map bit on R8G8_UNORM optimal tiling, in
/// `VkFormatProperties` and in a chained `VkFormatProperties3`.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn format_properties2(
    khr: bool,
    physical: vk::PhysicalDevice,
    format: vk::Format,
    out: *mut vk::FormatProperties2<'_>,
) {
    // SAFETY: a physical device made through the layer.
    let Some(inst) = (unsafe { registry::instance(physical) }) else {
        return;
    };
    let next = if khr {
        inst.next.get_format_properties2_khr
    } else {
        inst.next.get_format_properties2
    };
    let Some(next) = next else { return };
    // SAFETY: the next layer's function, with the caller's arguments.
    unsafe { next(physical, format, out) };
    if format != FDM_FORMAT || out.is_null() || emulated(&inst, physical).is_none() {
        return;
    }
    // SAFETY: the caller's output struct and chain.
    unsafe {
        (*out).format_properties.optimal_tiling_features |=
            vk::FormatFeatureFlags::FRAGMENT_DENSITY_MAP_EXT;
        if let Some(p3) = chain::find_out::<vk::FormatProperties3>(
            (*out).p_next,
            vk::StructureType::FORMAT_PROPERTIES_3,
        ) {
            (*p3).optimal_tiling_features |= vk::FormatFeatureFlags2::FRAGMENT_DENSITY_MAP_EXT;
        }
    }
}

pub unsafe extern "system" fn get_format_properties2(
    physical: vk::PhysicalDevice,
    format: vk::Format,
    out: *mut vk::FormatProperties2<'_>,
) {
    // SAFETY: the caller's arguments, passed on.
    guard("vkGetPhysicalDeviceFormatProperties2", (), || unsafe {
        format_properties2(false, physical, format, out)
    })
}

pub unsafe extern "system" fn get_format_properties2_khr(
    physical: vk::PhysicalDevice,
    format: vk::Format,
    out: *mut vk::FormatProperties2<'_>,
) {
    // SAFETY: the caller's arguments, passed on.
    guard("vkGetPhysicalDeviceFormatProperties2KHR", (), || unsafe {
        format_properties2(true, physical, format, out)
    })
}

/// How an image's usage and flags reach the driver on an emulated device: without the
/// density-map usage (the driver does not know it; SAMPLED stands in, since usage may not be
/// empty, the application's views of the image need a usage that admits views
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkImageViewCreateInfo.html>,
/// VUID-VkImageViewCreateInfo-image-04441), and the layer reads density maps by sampling) and without
/// `SUBSAMPLED` (emulated passes are never subsampled). `None` where the image is not a density map
/// the layer accepts: not R8G8_UNORM, optimal, 2D.
pub fn translate_image(
    format: vk::Format,
    ty: vk::ImageType,
    tiling: vk::ImageTiling,
    usage: vk::ImageUsageFlags,
    flags: vk::ImageCreateFlags,
) -> Option<(vk::ImageUsageFlags, vk::ImageCreateFlags)> {
    let fdm = usage.contains(vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT);
    if fdm
        && (format != FDM_FORMAT
            || tiling != vk::ImageTiling::OPTIMAL
            || ty != vk::ImageType::TYPE_2D)
    {
        return None;
    }
    let mut usage = usage & !vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT;
    if fdm || usage.is_empty() {
        usage |= vk::ImageUsageFlags::SAMPLED;
    }
    Some((usage, flags & !vk::ImageCreateFlags::SUBSAMPLED_EXT))
}

/// Whether [`translate_image`] has anything to do.
pub fn needs_translation(usage: vk::ImageUsageFlags, flags: vk::ImageCreateFlags) -> bool {
    usage.contains(vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT)
        || flags.contains(vk::ImageCreateFlags::SUBSAMPLED_EXT)
}

#[allow(clippy::too_many_arguments)]
pub unsafe extern "system" fn get_image_format_properties(
    physical: vk::PhysicalDevice,
    format: vk::Format,
    ty: vk::ImageType,
    tiling: vk::ImageTiling,
    usage: vk::ImageUsageFlags,
    flags: vk::ImageCreateFlags,
    out: *mut vk::ImageFormatProperties,
) -> vk::Result {
    guard(
        "vkGetPhysicalDeviceImageFormatProperties",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: a physical device made through the layer.
            let Some(inst) = (unsafe { registry::instance(physical) }) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let Some(next) = inst.next.get_image_format_properties else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let (usage, flags) =
                if needs_translation(usage, flags) && emulated(&inst, physical).is_some() {
                    match translate_image(format, ty, tiling, usage, flags) {
                        Some(t) => t,
                        None => return vk::Result::ERROR_FORMAT_NOT_SUPPORTED,
                    }
                } else {
                    (usage, flags)
                };
            // SAFETY: the next layer's function, with the caller's (or translated) arguments.
            unsafe { next(physical, format, ty, tiling, usage, flags, out) }
        },
    )
}

/// `vkGetPhysicalDeviceImageFormatProperties2`: density-map usage accepted on R8G8_UNORM, asked
/// of the driver in translation (on a copy of the application's struct).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn image_format_properties2(
    khr: bool,
    physical: vk::PhysicalDevice,
    info: *const vk::PhysicalDeviceImageFormatInfo2<'_>,
    out: *mut vk::ImageFormatProperties2<'_>,
) -> vk::Result {
    // SAFETY: a physical device made through the layer.
    let Some(inst) = (unsafe { registry::instance(physical) }) else {
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    };
    let next = if khr {
        inst.next.get_image_format_properties2_khr
    } else {
        inst.next.get_image_format_properties2
    };
    let Some(next) = next else {
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    };
    if info.is_null() {
        // SAFETY: passed on as given; the next layer reports the misuse.
        return unsafe { next(physical, info, out) };
    }
    // SAFETY: the caller's input struct, read only.
    let mut copy = unsafe { *info };
    if !needs_translation(copy.usage, copy.flags) || emulated(&inst, physical).is_none() {
        // SAFETY: the next layer's function, with the caller's arguments.
        return unsafe { next(physical, info, out) };
    }
    match translate_image(copy.format, copy.ty, copy.tiling, copy.usage, copy.flags) {
        Some((usage, flags)) => {
            copy.usage = usage;
            copy.flags = flags;
        }
        None => return vk::Result::ERROR_FORMAT_NOT_SUPPORTED,
    }
    // SAFETY: the translated copy lives across the call; the output is the caller's.
    unsafe { next(physical, &copy, out) }
}

pub unsafe extern "system" fn get_image_format_properties2(
    physical: vk::PhysicalDevice,
    info: *const vk::PhysicalDeviceImageFormatInfo2<'_>,
    out: *mut vk::ImageFormatProperties2<'_>,
) -> vk::Result {
    guard(
        "vkGetPhysicalDeviceImageFormatProperties2",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        // SAFETY: the caller's arguments, passed on.
        || unsafe { image_format_properties2(false, physical, info, out) },
    )
}

pub unsafe extern "system" fn get_image_format_properties2_khr(
    physical: vk::PhysicalDevice,
    info: *const vk::PhysicalDeviceImageFormatInfo2<'_>,
    out: *mut vk::ImageFormatProperties2<'_>,
) -> vk::Result {
    guard(
        "vkGetPhysicalDeviceImageFormatProperties2KHR",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        // SAFETY: the caller's arguments, passed on.
        || unsafe { image_format_properties2(true, physical, info, out) },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_offered_extension() {
        let e = fdm_extension();
        assert_eq!(
            e.extension_name_as_c_str(),
            Ok(ash::ext::fragment_density_map::NAME)
        );
        assert_eq!(e.spec_version, 3);
    }

    #[test]
    fn image_translation() {
        use vk::{
            Format, ImageCreateFlags as F, ImageTiling as T, ImageType, ImageUsageFlags as U,
        };
        let t2 = ImageType::TYPE_2D;
        assert_eq!(
            translate_image(
                Format::R8G8_UNORM,
                t2,
                T::OPTIMAL,
                U::FRAGMENT_DENSITY_MAP_EXT,
                F::empty()
            ),
            Some((U::SAMPLED, F::empty()))
        );
        assert_eq!(
            translate_image(
                Format::R8G8_UNORM,
                t2,
                T::OPTIMAL,
                U::FRAGMENT_DENSITY_MAP_EXT | U::TRANSFER_DST,
                F::empty()
            ),
            Some((U::TRANSFER_DST | U::SAMPLED, F::empty()))
        );
        assert_eq!(
            translate_image(
                Format::R8G8B8A8_SRGB,
                t2,
                T::OPTIMAL,
                U::COLOR_ATTACHMENT,
                F::SUBSAMPLED_EXT
            ),
            Some((U::COLOR_ATTACHMENT, F::empty()))
        );
        assert_eq!(
            translate_image(
                Format::R8_UINT,
                t2,
                T::OPTIMAL,
                U::FRAGMENT_DENSITY_MAP_EXT,
                F::empty()
            ),
            None
        );
        assert_eq!(
            translate_image(
                Format::R8G8_UNORM,
                t2,
                T::LINEAR,
                U::FRAGMENT_DENSITY_MAP_EXT,
                F::empty()
            ),
            None
        );
        assert!(!needs_translation(U::SAMPLED, F::empty()));
    }
}
