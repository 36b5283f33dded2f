//! What the application sees of a physical device ([`crate::vk::decide`] decides): the queries
//! that show emulated fragment density maps
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/VK_EXT_fragment_density_map.html>).

use std::ffi::{c_char, c_void};

use ash::vk;

use crate::vk::base::chain;
use crate::vk::base::ffi::{name, two_call, Call, In, Out};
use crate::vk::decide::{driver_extensions, emulated, has, offsets_offered};
use crate::vk::registry::{self, Instance};
use crate::vk::translate::formats::{
    needs_translation, offered_extensions, translate_image, FDM_FORMAT,
};

hook! {
    /// `vkEnumerateDeviceExtensionProperties`: on an emulated device the driver's list plus
    /// `VK_EXT_fragment_density_map` and, where they can be applied ([`offsets_offered`]), its
    /// offsets under both names ([`offered_extensions`]); asked for this layer's own extensions,
    /// those.
    enumerate_device_extension_properties = "vkEnumerateDeviceExtensionProperties";
    on instance(physical), next enumerate_device_extension_properties,
    fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    enumerate_extensions(
        physical: val vk::PhysicalDevice,
        layer: val *const c_char,
        count: val *mut u32,
        out: val *mut vk::ExtensionProperties,
    ) -> vk::Result
}

fn enumerate_extensions(
    c: Call<'_, Instance, vk::PFN_vkEnumerateDeviceExtensionProperties, impl Fn() -> vk::Result>,
    physical: vk::PhysicalDevice,
    layer: *const c_char,
    count: *mut u32,
    out: *mut vk::ExtensionProperties,
) -> vk::Result {
    let inst = c.dev;
    // SAFETY: the command's valid usage: NULL or a NUL-terminated layer name.
    let asked = unsafe { name(layer) };
    let ours_asked = asked.map(|n| n.to_bytes() == fovea_abi::VK_LAYER_NAME.as_bytes());
    let list = match ours_asked {
        Some(true) => ours(inst, physical),
        Some(false) => return c.as_given(),
        None if emulated(inst, physical).is_none() => return c.as_given(),
        None => {
            // SAFETY: `physical` belongs to `inst`.
            let mut exts = match unsafe { driver_extensions(inst, physical) } {
                Ok(e) => e,
                Err(r) => return r,
            };
            for e in ours(inst, physical) {
                if let Ok(n) = e.extension_name_as_c_str() {
                    if !has(&exts, n) {
                        exts.push(e);
                    }
                }
            }
            exts
        }
    };
    // SAFETY: the command's valid usage (the two-call idiom): `count` valid, `out` NULL or valid
    // for `*count` elements.
    unsafe { two_call(&list, count, out) }
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

/// Fills `VkPhysicalDeviceFragmentDensityMapFeaturesEXT` in an output chain: density maps and
/// non-subsampled images, not dynamic ones; and `VkPhysicalDeviceFragmentDensityMapOffsetFeaturesEXT`
/// (the QCOM struct is the same, with the same `sType`): offsets, where they can be applied.
///
/// # Safety
/// `next` must be a valid, writable output chain.
unsafe fn fill_features(next: *mut c_void, offsets: bool) {
    // SAFETY: as the caller promised; each struct found by its sType is of that type.
    unsafe {
        if let Some(f) = chain::find_out::<vk::PhysicalDeviceFragmentDensityMapFeaturesEXT>(
            next,
            vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_FEATURES_EXT,
        ) {
            (*f).fragment_density_map = vk::TRUE;
            (*f).fragment_density_map_dynamic = vk::FALSE;
            (*f).fragment_density_map_non_subsampled_images = vk::TRUE;
        }
        if let Some(f) = chain::find_out::<vk::PhysicalDeviceFragmentDensityMapOffsetFeaturesQCOM>(
            next,
            vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_OFFSET_FEATURES_QCOM,
        ) {
            (*f).fragment_density_map_offset = vk::Bool32::from(offsets);
        }
    }
}

hook! {
    /// `vkGetPhysicalDeviceFeatures2`: density maps shown where the layer emulates them
    /// ([`fill_features`]).
    get_features2 = "vkGetPhysicalDeviceFeatures2",
        get_features2_khr = "vkGetPhysicalDeviceFeatures2KHR";
    on instance(physical), next get_features2 / get_features2_khr, fails(());
    features2(physical: val vk::PhysicalDevice, out: out vk::PhysicalDeviceFeatures2<'_>) -> ()
}

fn features2(
    c: Call<'_, Instance, vk::PFN_vkGetPhysicalDeviceFeatures2, impl Fn()>,
    physical: vk::PhysicalDevice,
    out: Out<'_, vk::PhysicalDeviceFeatures2<'_>>,
) {
    c.as_given();
    if emulated(c.dev, physical).is_none() {
        return;
    }
    if let Some(f) = out.into_mut() {
        // SAFETY: the application's output chain, valid and writable (the command's valid usage).
        unsafe { fill_features(f.p_next, offsets_offered(c.dev, physical).is_some()) };
    }
}

hook! {
    /// `vkGetPhysicalDeviceProperties2`: `VkPhysicalDeviceFragmentDensityMapPropertiesEXT` with
    /// min = max density texel = the shading-rate texel, and no extra invocations;
    /// `VkPhysicalDeviceFragmentDensityMapOffsetPropertiesEXT` with the offset granularity = that
    /// texel, so every valid offset shifts the map by whole texels, which the layer applies
    /// exactly (docs/vulkan-layer.md#density-map-offsets).
    get_properties2 = "vkGetPhysicalDeviceProperties2",
        get_properties2_khr = "vkGetPhysicalDeviceProperties2KHR";
    on instance(physical), next get_properties2 / get_properties2_khr, fails(());
    properties2(
        physical: val vk::PhysicalDevice,
        out: out vk::PhysicalDeviceProperties2<'_>,
    ) -> ()
}

fn properties2(
    c: Call<'_, Instance, vk::PFN_vkGetPhysicalDeviceProperties2, impl Fn()>,
    physical: vk::PhysicalDevice,
    out: Out<'_, vk::PhysicalDeviceProperties2<'_>>,
) {
    c.as_given();
    let (Some(fdm), Some(props)) = (emulated(c.dev, physical), out.into_mut()) else {
        return;
    };
    let texel = vk::Extent2D {
        width: fdm.texel[0],
        height: fdm.texel[1],
    };
    let offsets = offsets_offered(c.dev, physical).is_some();
    // SAFETY: the application's output chain, valid and writable (the command's valid usage);
    // each struct found by its sType is of that type.
    unsafe {
        if let (Some(p), true) = (
            chain::find_out::<vk::PhysicalDeviceFragmentDensityMapOffsetPropertiesQCOM>(
                props.p_next,
                vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_OFFSET_PROPERTIES_QCOM,
            ),
            offsets,
        ) {
            (*p).fragment_density_offset_granularity = texel;
        }
        if let Some(p) = chain::find_out::<vk::PhysicalDeviceFragmentDensityMapPropertiesEXT>(
            props.p_next,
            vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_PROPERTIES_EXT,
        ) {
            (*p).min_fragment_density_texel_size = texel;
            (*p).max_fragment_density_texel_size = texel;
            (*p).fragment_density_invocations = vk::FALSE;
        }
    }
}

hook! {
    /// `vkGetPhysicalDeviceFormatProperties`: the density-map bit on R8G8_UNORM optimal tiling.
    get_format_properties = "vkGetPhysicalDeviceFormatProperties";
    on instance(physical), next get_format_properties, fails(());
    format_properties(
        physical: val vk::PhysicalDevice,
        format: val vk::Format,
        out: out vk::FormatProperties,
    ) -> ()
}

fn format_properties(
    c: Call<'_, Instance, vk::PFN_vkGetPhysicalDeviceFormatProperties, impl Fn()>,
    physical: vk::PhysicalDevice,
    format: vk::Format,
    out: Out<'_, vk::FormatProperties>,
) {
    c.as_given();
    if format != FDM_FORMAT || emulated(c.dev, physical).is_none() {
        return;
    }
    if let Some(p) = out.into_mut() {
        p.optimal_tiling_features |= vk::FormatFeatureFlags::FRAGMENT_DENSITY_MAP_EXT;
    }
}

hook! {
    /// `vkGetPhysicalDeviceFormatProperties2`: the density-map bit on R8G8_UNORM optimal tiling,
    /// in `VkFormatProperties` and in a chained `VkFormatProperties3`.
    get_format_properties2 = "vkGetPhysicalDeviceFormatProperties2",
        get_format_properties2_khr = "vkGetPhysicalDeviceFormatProperties2KHR";
    on instance(physical), next get_format_properties2 / get_format_properties2_khr, fails(());
    format_properties2(
        physical: val vk::PhysicalDevice,
        format: val vk::Format,
        out: out vk::FormatProperties2<'_>,
    ) -> ()
}

fn format_properties2(
    c: Call<'_, Instance, vk::PFN_vkGetPhysicalDeviceFormatProperties2, impl Fn()>,
    physical: vk::PhysicalDevice,
    format: vk::Format,
    out: Out<'_, vk::FormatProperties2<'_>>,
) {
    c.as_given();
    if format != FDM_FORMAT || emulated(c.dev, physical).is_none() {
        return;
    }
    let Some(p) = out.into_mut() else {
        return;
    };
    p.format_properties.optimal_tiling_features |= vk::FormatFeatureFlags::FRAGMENT_DENSITY_MAP_EXT;
    // SAFETY: the application's output chain, valid and writable (the command's valid usage);
    // found by its sType.
    if let Some(p3) = unsafe {
        chain::find_out::<vk::FormatProperties3>(p.p_next, vk::StructureType::FORMAT_PROPERTIES_3)
    } {
        // SAFETY: as above.
        unsafe {
            (*p3).optimal_tiling_features |= vk::FormatFeatureFlags2::FRAGMENT_DENSITY_MAP_EXT
        };
    }
}

hook! {
    /// `vkGetPhysicalDeviceImageFormatProperties`: density-map usage accepted on R8G8_UNORM,
    /// asked of the driver in translation.
    get_image_format_properties = "vkGetPhysicalDeviceImageFormatProperties";
    on instance(physical), next get_image_format_properties,
    fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    image_format_properties(
        physical: val vk::PhysicalDevice,
        format: val vk::Format,
        ty: val vk::ImageType,
        tiling: val vk::ImageTiling,
        usage: val vk::ImageUsageFlags,
        flags: val vk::ImageCreateFlags,
        out: val *mut vk::ImageFormatProperties,
    ) -> vk::Result
}

#[allow(clippy::too_many_arguments)]
fn image_format_properties(
    c: Call<
        '_,
        Instance,
        vk::PFN_vkGetPhysicalDeviceImageFormatProperties,
        impl Fn() -> vk::Result,
    >,
    physical: vk::PhysicalDevice,
    format: vk::Format,
    ty: vk::ImageType,
    tiling: vk::ImageTiling,
    usage: vk::ImageUsageFlags,
    flags: vk::ImageCreateFlags,
    out: *mut vk::ImageFormatProperties,
) -> vk::Result {
    let (usage, flags) = if needs_translation(usage, flags) && emulated(c.dev, physical).is_some() {
        match translate_image(format, ty, tiling, usage, flags) {
            Some(t) => t,
            None => return vk::Result::ERROR_FORMAT_NOT_SUPPORTED,
        }
    } else {
        (usage, flags)
    };
    // SAFETY: the next layer's function, with the application's (or translated) arguments.
    unsafe { (c.next)(physical, format, ty, tiling, usage, flags, out) }
}

hook! {
    /// `vkGetPhysicalDeviceImageFormatProperties2`: density-map usage accepted on R8G8_UNORM,
    /// asked of the driver in translation (on a copy of the application's struct).
    get_image_format_properties2 = "vkGetPhysicalDeviceImageFormatProperties2",
        get_image_format_properties2_khr = "vkGetPhysicalDeviceImageFormatProperties2KHR";
    on instance(physical), next get_image_format_properties2 / get_image_format_properties2_khr,
    fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    image_format_properties2(
        physical: val vk::PhysicalDevice,
        info: in vk::PhysicalDeviceImageFormatInfo2<'_>,
        out: val *mut vk::ImageFormatProperties2<'_>,
    ) -> vk::Result
}

fn image_format_properties2(
    c: Call<
        '_,
        Instance,
        vk::PFN_vkGetPhysicalDeviceImageFormatProperties2,
        impl Fn() -> vk::Result,
    >,
    physical: vk::PhysicalDevice,
    info: In<'_, vk::PhysicalDeviceImageFormatInfo2<'_>>,
    out: *mut vk::ImageFormatProperties2<'_>,
) -> vk::Result {
    let translate = info
        .get()
        .filter(|i| needs_translation(i.usage, i.flags) && emulated(c.dev, physical).is_some());
    let Some(app) = translate else {
        // SAFETY: the next layer's function, with the application's arguments (a NULL info
        // goes down as given: the next layer reports the misuse).
        return unsafe { (c.next)(physical, info.raw(), out) };
    };
    let mut copy = *app;
    match translate_image(copy.format, copy.ty, copy.tiling, copy.usage, copy.flags) {
        Some((usage, flags)) => {
            copy.usage = usage;
            copy.flags = flags;
        }
        None => return vk::Result::ERROR_FORMAT_NOT_SUPPORTED,
    }
    // SAFETY: the next layer's function; the translated copy lives across the call, the output
    // is the application's.
    unsafe { (c.next)(physical, &copy, out) }
}
