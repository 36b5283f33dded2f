//! What a driver without fragment density maps refuses: the double's lavapipe, as every desktop
//! driver with shading-rate attachments, has no `VK_EXT_fragment_density_map`, so each of that
//! extension's names, structs, enums and bits is one the application (or a layer above) must not
//! hand it. Each is recorded as an error the tests see
//! (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#fundamentals-validusage-enums>:
//! enums of an extension that is not enabled are invalid).

use std::ffi::{c_char, c_void, CStr};

use ash::vk;

use crate::record::error;

/// The device extensions of density maps, which the driver does not have.
pub const FDM_EXTENSIONS: [&CStr; 4] = [
    c"VK_EXT_fragment_density_map",
    c"VK_EXT_fragment_density_map2",
    c"VK_EXT_fragment_density_map_offset",
    c"VK_QCOM_fragment_density_map_offset",
];

/// Structs of those extensions, by `sType`, wherever they are chained.
const FDM_STRUCTS: [(vk::StructureType, &str); 9] = [
    (
        vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_FEATURES_EXT,
        "VkPhysicalDeviceFragmentDensityMapFeaturesEXT",
    ),
    (
        vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_2_FEATURES_EXT,
        "VkPhysicalDeviceFragmentDensityMap2FeaturesEXT",
    ),
    (
        vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_OFFSET_FEATURES_QCOM,
        "VkPhysicalDeviceFragmentDensityMapOffsetFeaturesEXT",
    ),
    (
        vk::StructureType::RENDER_PASS_FRAGMENT_DENSITY_MAP_CREATE_INFO_EXT,
        "VkRenderPassFragmentDensityMapCreateInfoEXT",
    ),
    (
        vk::StructureType::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_INFO_EXT,
        "VkRenderingFragmentDensityMapAttachmentInfoEXT",
    ),
    (
        vk::StructureType::SUBPASS_FRAGMENT_DENSITY_MAP_OFFSET_END_INFO_QCOM,
        "VkRenderPassFragmentDensityMapOffsetEndInfoEXT",
    ),
    (
        vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_PROPERTIES_EXT,
        "VkPhysicalDeviceFragmentDensityMapPropertiesEXT",
    ),
    (
        vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_2_PROPERTIES_EXT,
        "VkPhysicalDeviceFragmentDensityMap2PropertiesEXT",
    ),
    (
        vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_OFFSET_PROPERTIES_QCOM,
        "VkPhysicalDeviceFragmentDensityMapOffsetPropertiesEXT",
    ),
];

#[repr(C)]
struct Header {
    s_type: vk::StructureType,
    p_next: *const c_void,
}

/// Records an error for each density-map struct in the chain at `head`.
///
/// # Safety
/// `head` must be null or a valid chain.
pub unsafe fn chain(what: &str, head: *const c_void) {
    let mut p = head;
    while !p.is_null() {
        // SAFETY: every chained struct starts with sType and pNext (the caller's promise).
        let h = unsafe { &*(p as *const Header) };
        if let Some((_, name)) = FDM_STRUCTS.iter().find(|(s, _)| *s == h.s_type) {
            error(format!(
                "{what}: {name} in a chain, but the driver has no fragment density maps"
            ));
        }
        p = h.p_next;
    }
}

/// `VK_PIPELINE_STAGE_FRAGMENT_DENSITY_PROCESS_BIT_EXT` (the same bit in the `2` flags).
const STAGE: u64 = vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT.as_raw() as u64;
/// `VK_ACCESS_FRAGMENT_DENSITY_MAP_READ_BIT_EXT` (the same bit in the `2` flags).
const ACCESS: u64 = vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT.as_raw() as u64;

pub fn stage(what: &str, s: u64) {
    if s & STAGE != 0 {
        error(format!(
            "{what}: stage FRAGMENT_DENSITY_PROCESS_EXT, but the driver has no fragment density maps"
        ));
    }
}

pub fn access(what: &str, a: u64) {
    if a & ACCESS != 0 {
        error(format!(
            "{what}: access FRAGMENT_DENSITY_MAP_READ_EXT, but the driver has no fragment density \
             maps"
        ));
    }
}

pub fn layout(what: &str, l: vk::ImageLayout) {
    if l == vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT {
        error(format!(
            "{what}: layout FRAGMENT_DENSITY_MAP_OPTIMAL_EXT, but the driver has no fragment \
             density maps"
        ));
    }
}

pub fn usage(what: &str, u: vk::ImageUsageFlags) {
    if u.contains(vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT) {
        error(format!(
            "{what}: usage FRAGMENT_DENSITY_MAP_EXT, but the driver has no fragment density maps"
        ));
    }
}

/// A flag of the density-map extensions in create flags.
pub fn flag(what: &str, present: bool, name: &str) {
    if present {
        error(format!(
            "{what}: {name}, but the driver has no fragment density maps"
        ));
    }
}

/// Stages and accesses of one barrier (either version; the bits are the same).
pub fn barrier(what: &str, stages: [u64; 2], accesses: [u64; 2]) {
    for s in stages {
        stage(what, s);
    }
    for a in accesses {
        access(what, a);
    }
}

/// A dependency info's barriers.
///
/// # Safety
/// `di` must be valid.
pub unsafe fn dependency(what: &str, di: &vk::DependencyInfo<'_>) {
    // SAFETY: the caller's promise.
    unsafe {
        chain(what, di.p_next);
        for b in crate::layer::slice(di.p_memory_barriers, di.memory_barrier_count) {
            barrier(
                what,
                [b.src_stage_mask.as_raw(), b.dst_stage_mask.as_raw()],
                [b.src_access_mask.as_raw(), b.dst_access_mask.as_raw()],
            );
        }
        for b in crate::layer::slice(di.p_buffer_memory_barriers, di.buffer_memory_barrier_count) {
            barrier(
                what,
                [b.src_stage_mask.as_raw(), b.dst_stage_mask.as_raw()],
                [b.src_access_mask.as_raw(), b.dst_access_mask.as_raw()],
            );
        }
        for b in crate::layer::slice(di.p_image_memory_barriers, di.image_memory_barrier_count) {
            barrier(
                what,
                [b.src_stage_mask.as_raw(), b.dst_stage_mask.as_raw()],
                [b.src_access_mask.as_raw(), b.dst_access_mask.as_raw()],
            );
            layout(what, b.old_layout);
            layout(what, b.new_layout);
        }
    }
}

/// What `vkCreateDevice` refuses: a density-map extension name
/// (`VK_ERROR_EXTENSION_NOT_PRESENT`) or a density-map features struct that enables anything
/// (`VK_ERROR_FEATURE_NOT_PRESENT`).
///
/// # Safety
/// `ci` must be valid.
pub unsafe fn device(ci: &vk::DeviceCreateInfo<'_>) -> Option<vk::Result> {
    // SAFETY: the caller's promise.
    unsafe {
        let names: &[*const c_char] =
            crate::layer::slice(ci.pp_enabled_extension_names, ci.enabled_extension_count);
        for &n in names {
            let n = CStr::from_ptr(n);
            if FDM_EXTENSIONS.contains(&n) {
                error(format!(
                    "vkCreateDevice: {n:?} is not an extension of this driver"
                ));
                return Some(vk::Result::ERROR_EXTENSION_NOT_PRESENT);
            }
        }
        let mut p = ci.p_next;
        while !p.is_null() {
            let h = &*(p as *const Header);
            let on = if h.s_type
                == vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_FEATURES_EXT
            {
                let f = &*(p as *const vk::PhysicalDeviceFragmentDensityMapFeaturesEXT<'_>);
                f.fragment_density_map != 0
                    || f.fragment_density_map_dynamic != 0
                    || f.fragment_density_map_non_subsampled_images != 0
            } else if h.s_type
                == vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_2_FEATURES_EXT
            {
                let f = &*(p as *const vk::PhysicalDeviceFragmentDensityMap2FeaturesEXT<'_>);
                f.fragment_density_map_deferred != 0
            } else if h.s_type
                == vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_OFFSET_FEATURES_QCOM
            {
                let f = &*(p as *const vk::PhysicalDeviceFragmentDensityMapOffsetFeaturesQCOM<'_>);
                f.fragment_density_map_offset != 0
            } else {
                false
            };
            if on {
                error(format!(
                    "vkCreateDevice: {:?} enables density-map features this driver lacks",
                    h.s_type
                ));
                return Some(vk::Result::ERROR_FEATURE_NOT_PRESENT);
            }
            p = h.p_next;
        }
        None
    }
}
