//! Formats and image descriptions: the extension and format the layer offers, what a density-map
//! image becomes on the driver's side, and what every shadow is.

use std::ffi::{c_char, CStr};

use ash::vk;

use crate::bridge::FdmEmulation;
use crate::vk::base::ffi::offset;

/// Every device extension the layer offers on an emulating device: `VK_EXT_fragment_density_map`
/// and its offsets under both names (docs/vulkan-layer.md#density-map-offsets).
pub fn offered_extensions() -> [vk::ExtensionProperties; 3] {
    [
        fdm_extension(),
        extension(offset::EXT_NAME, offset::EXT_SPEC_VERSION),
        extension(offset::QCOM_NAME, offset::QCOM_SPEC_VERSION),
    ]
}

/// An extension's properties.
fn extension(name: &CStr, spec_version: u32) -> vk::ExtensionProperties {
    let mut e = vk::ExtensionProperties {
        spec_version,
        ..Default::default()
    };
    for (d, &s) in e.extension_name.iter_mut().zip(name.to_bytes()) {
        *d = s as c_char;
    }
    e
}

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

/// The format that carries density maps: R8G8_UNORM, whose `FRAGMENT_DENSITY_MAP` feature the spec
/// makes mandatory where density maps are supported
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkFormatFeatureFlagBits.html>).
pub const FDM_FORMAT: vk::Format = vk::Format::R8G8_UNORM;

/// How an image's usage and flags reach the driver on an emulated device: without the
/// density-map usage (the driver does not know it; SAMPLED stands in, since usage may not be
/// empty, the application's views of the image need a usage that admits views
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkImageViewCreateInfo.html>,
/// VUID-VkImageViewCreateInfo-image-04441), and the layer reads density maps by sampling) and without
/// `SUBSAMPLED` (emulated passes are never subsampled) or `FRAGMENT_DENSITY_MAP_OFFSET`
/// ([`DENSITY_FLAGS`]). `None` where the image is not a density map
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
    Some((usage, flags & !DENSITY_FLAGS))
}

/// Image create flags of the density-map extensions, which the driver does not know:
/// `SUBSAMPLED` (emulated passes are never subsampled) and `FRAGMENT_DENSITY_MAP_OFFSET` (the
/// layer applies offsets itself, [`crate::vk::convert`]).
pub const DENSITY_FLAGS: vk::ImageCreateFlags = vk::ImageCreateFlags::from_raw(
    vk::ImageCreateFlags::SUBSAMPLED_EXT.as_raw()
        | vk::ImageCreateFlags::FRAGMENT_DENSITY_MAP_OFFSET_QCOM.as_raw(),
);

/// Whether [`translate_image`] has anything to do.
pub fn needs_translation(usage: vk::ImageUsageFlags, flags: vk::ImageCreateFlags) -> bool {
    usage.contains(vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT) || flags.intersects(DENSITY_FLAGS)
}

/// The usage every shadow has.
pub const SHADOW_USAGE: vk::ImageUsageFlags = vk::ImageUsageFlags::from_raw(
    vk::ImageUsageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR.as_raw()
        | vk::ImageUsageFlags::TRANSFER_DST.as_raw()
        | vk::ImageUsageFlags::TRANSFER_SRC.as_raw(),
);
/// The format every shadow has.
pub const SHADOW_FORMAT: vk::Format = vk::Format::R8_UINT;
/// The layout a shadow lives in between uses.
pub const SHADOW_LAYOUT: vk::ImageLayout =
    vk::ImageLayout::FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR;

/// How many layers a shadow of an image with `app_layers` layers has on `fdm`'s device.
pub fn shadow_layers(fdm: &FdmEmulation, app_layers: u32) -> u32 {
    if fdm.layered {
        app_layers.max(1)
    } else {
        1
    }
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
        let names: Vec<_> = offered_extensions()
            .iter()
            .map(|e| e.extension_name_as_c_str().unwrap().to_owned())
            .collect();
        assert_eq!(
            names,
            [
                c"VK_EXT_fragment_density_map",
                c"VK_EXT_fragment_density_map_offset",
                c"VK_QCOM_fragment_density_map_offset"
            ]
        );
    }

    #[test]
    fn image_translation() {
        use vk::{
            Format, ImageCreateFlags as F, ImageTiling as T, ImageType, ImageUsageFlags as U,
        };
        let cases = [
            (
                Format::R8G8_UNORM,
                T::OPTIMAL,
                U::FRAGMENT_DENSITY_MAP_EXT,
                F::empty(),
                Some((U::SAMPLED, F::empty())),
            ),
            (
                Format::R8G8_UNORM,
                T::OPTIMAL,
                U::FRAGMENT_DENSITY_MAP_EXT | U::TRANSFER_DST,
                F::empty(),
                Some((U::TRANSFER_DST | U::SAMPLED, F::empty())),
            ),
            (
                Format::R8G8B8A8_SRGB,
                T::OPTIMAL,
                U::COLOR_ATTACHMENT,
                F::SUBSAMPLED_EXT,
                Some((U::COLOR_ATTACHMENT, F::empty())),
            ),
            (
                Format::R8_UINT,
                T::OPTIMAL,
                U::FRAGMENT_DENSITY_MAP_EXT,
                F::empty(),
                None,
            ),
            (
                Format::R8G8_UNORM,
                T::LINEAR,
                U::FRAGMENT_DENSITY_MAP_EXT,
                F::empty(),
                None,
            ),
            (
                Format::R8G8B8A8_SRGB,
                T::OPTIMAL,
                U::COLOR_ATTACHMENT,
                F::FRAGMENT_DENSITY_MAP_OFFSET_QCOM | F::MUTABLE_FORMAT,
                Some((U::COLOR_ATTACHMENT, F::MUTABLE_FORMAT)),
            ),
        ];
        for (format, tiling, usage, flags, want) in cases {
            assert_eq!(
                translate_image(format, ImageType::TYPE_2D, tiling, usage, flags),
                want,
                "{format:?} {tiling:?} {usage:?} {flags:?}"
            );
        }
        assert!(needs_translation(
            U::COLOR_ATTACHMENT,
            F::FRAGMENT_DENSITY_MAP_OFFSET_QCOM
        ));
        assert!(!needs_translation(U::SAMPLED, F::empty()));
    }

    #[test]
    fn shadow_layers_follow_the_device() {
        let mut fdm = FdmEmulation {
            texel: [16, 16],
            layered: true,
            max_fragment: [4, 4],
            rates: Vec::new(),
            non_trivial_combiners: true,
        };
        assert_eq!(shadow_layers(&fdm, 2), 2);
        fdm.layered = false;
        assert_eq!(shadow_layers(&fdm, 2), 1);
    }
}
