//! What the application sees of a physical device ([`crate::vk::decide`] decides): the queries
//! that show emulated fragment density maps
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/VK_EXT_fragment_density_map.html>).

use std::ffi::{c_char, c_void};

use ash::vk;

use crate::vk::base::chain;
use crate::vk::base::ffi::{guard, name, two_call};
use crate::vk::decide::{driver_extensions, emulated, has, offsets_offered};
use crate::vk::registry::{self};
use crate::vk::translate::formats::{
    needs_translation, offered_extensions, translate_image, FDM_FORMAT,
};

/// `vkEnumerateDeviceExtensionProperties`: on an emulated device the driver's list plus
/// `VK_EXT_fragment_density_map` and, where they can be applied ([`offsets_offered`]), its offsets
/// under both names ([`offered_extensions`]); asked for this layer's own extensions, those.
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
            let ours = ours(&inst, physical);
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
    for e in ours(&inst, physical) {
        if let Ok(n) = e.extension_name_as_c_str() {
            if !has(&exts, n) {
                exts.push(e);
            }
        }
    }
    // SAFETY: the caller's pointers.
    unsafe { two_call(&exts, count, out) }
}

/// The extensions the layer offers on `physical`: density maps where it emulates them, their
/// offsets too where they can be applied.
fn ours(inst: &registry::Instance, physical: vk::PhysicalDevice) -> Vec<vk::ExtensionProperties> {
    if emulated(inst, physical).is_none() {
        return Vec::new();
    }
    // Density maps first, then their offsets.
    let all = offered_extensions();
    let n = if offsets_offered(inst, physical).is_some() {
        all.len()
    } else {
        1
    };
    all[..n].to_vec()
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
/// non-subsampled images, not dynamic ones; and `VkPhysicalDeviceFragmentDensityMapOffsetFeaturesEXT`
/// (the QCOM struct is the same, with the same `sType`): offsets, where they can be applied.
///
/// # Safety
/// `next` must be a valid, writable output chain.
unsafe fn fill_features(next: *mut c_void, offsets: bool) {
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
    // SAFETY: as the caller promised.
    if let Some(f) = unsafe {
        chain::find_out::<vk::PhysicalDeviceFragmentDensityMapOffsetFeaturesQCOM>(
            next,
            vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_OFFSET_FEATURES_QCOM,
        )
    } {
        // SAFETY: found by its sType in the caller's output chain.
        unsafe { (*f).fragment_density_map_offset = vk::Bool32::from(offsets) };
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
        unsafe { fill_features((*out).p_next, offsets_offered(&inst, physical).is_some()) };
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
/// min = max density texel = the shading-rate texel, and no extra invocations;
/// `VkPhysicalDeviceFragmentDensityMapOffsetPropertiesEXT` with the offset granularity = that
/// texel, so every valid offset shifts the map by whole texels, which the layer applies exactly
/// (docs/vulkan-layer.md#density-map-offsets).
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
    let texel = vk::Extent2D {
        width: fdm.texel[0],
        height: fdm.texel[1],
    };
    // SAFETY: the caller's output chain.
    let offsets = unsafe {
        chain::find_out::<vk::PhysicalDeviceFragmentDensityMapOffsetPropertiesQCOM>(
            (*out).p_next,
            vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_OFFSET_PROPERTIES_QCOM,
        )
    };
    if let (Some(p), Some(_)) = (offsets, offsets_offered(&inst, physical)) {
        // SAFETY: found by its sType in the caller's output chain.
        unsafe { (*p).fragment_density_offset_granularity = texel };
    }
    // SAFETY: the caller's output chain.
    if let Some(p) = unsafe {
        chain::find_out::<vk::PhysicalDeviceFragmentDensityMapPropertiesEXT>(
            (*out).p_next,
            vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_PROPERTIES_EXT,
        )
    } {
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
