//! Shadows: the layer-owned shading-rate images and views that stand in for an application's
//! density-map images and views on an emulating device ([`crate::vk::emulation`] makes them).

use ash::vk;

use crate::vk::translate::formats::SHADOW_FORMAT;

/// A layer-owned shading-rate image standing in for an application's density-map image
/// ([`crate::vk::emulation`]).
#[derive(Clone, Copy, Debug)]
pub struct ShadowImage {
    pub image: vk::Image,
    pub memory: vk::DeviceMemory,
    pub extent: vk::Extent2D,
    /// The shadow's array layers: the application image's, or 1 where the device lacks
    /// `layeredShadingRateAttachments` (one merged layer).
    pub layers: u32,
    /// The application image's array layers.
    pub app_layers: u32,
}

/// A layer-owned view of a shadow, standing in for a view of a density-map image.
#[derive(Clone, Copy, Debug)]
pub struct ShadowView {
    pub view: vk::ImageView,
    /// The shadow image it shows, its extent in texels, and the layers of it the view shows.
    pub image: vk::Image,
    pub texels: [u32; 2],
    pub base_layer: u32,
    pub layers: u32,
}

/// The shadow view's create info for an application view `ci` of an image shadowed by `s`: the
/// application's layers where the shadow has them, else its one merged layer; 2D or 2D-array, as
/// shading-rate views must be, identity swizzle.
pub fn shadow_view_info(
    s: &ShadowImage,
    ci: &vk::ImageViewCreateInfo<'_>,
) -> vk::ImageViewCreateInfo<'static> {
    let r = ci.subresource_range;
    let (base, count) = if s.layers == 1 {
        (0, 1)
    } else {
        let count = if r.layer_count == vk::REMAINING_ARRAY_LAYERS {
            s.layers.saturating_sub(r.base_array_layer)
        } else {
            r.layer_count
        };
        (r.base_array_layer, count)
    };
    let view_type = if ci.view_type == vk::ImageViewType::TYPE_2D_ARRAY || count > 1 {
        vk::ImageViewType::TYPE_2D_ARRAY
    } else {
        vk::ImageViewType::TYPE_2D
    };
    vk::ImageViewCreateInfo::default()
        .image(s.image)
        .view_type(view_type)
        .format(SHADOW_FORMAT)
        .components(vk::ComponentMapping::default())
        .subresource_range(vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: base,
            layer_count: count,
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ash::vk::Handle as _;

    fn shadow(layers: u32, app_layers: u32) -> ShadowImage {
        ShadowImage {
            image: vk::Image::from_raw(7),
            memory: vk::DeviceMemory::null(),
            extent: vk::Extent2D {
                width: 8,
                height: 8,
            },
            layers,
            app_layers,
        }
    }

    fn app_view(ty: vk::ImageViewType, base: u32, count: u32) -> vk::ImageViewCreateInfo<'static> {
        vk::ImageViewCreateInfo::default()
            .view_type(ty)
            .format(vk::Format::R8G8_UNORM)
            .components(vk::ComponentMapping {
                r: vk::ComponentSwizzle::G,
                ..Default::default()
            })
            .subresource_range(vk::ImageSubresourceRange {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                base_mip_level: 0,
                level_count: 1,
                base_array_layer: base,
                layer_count: count,
            })
    }

    #[test]
    fn layered_shadow_views_follow_the_applications_layers() {
        let s = shadow(2, 2);
        let v = shadow_view_info(&s, &app_view(vk::ImageViewType::TYPE_2D_ARRAY, 0, 2));
        assert_eq!(v.view_type, vk::ImageViewType::TYPE_2D_ARRAY);
        assert_eq!(v.format, vk::Format::R8_UINT);
        assert_eq!(
            v.components.r,
            vk::ComponentSwizzle::IDENTITY,
            "identity swizzle"
        );
        assert_eq!(
            (
                v.subresource_range.base_array_layer,
                v.subresource_range.layer_count
            ),
            (0, 2)
        );
        let eye = shadow_view_info(&s, &app_view(vk::ImageViewType::TYPE_2D, 1, 1));
        assert_eq!(eye.view_type, vk::ImageViewType::TYPE_2D);
        assert_eq!(eye.subresource_range.base_array_layer, 1);
        let rest = shadow_view_info(
            &s,
            &app_view(
                vk::ImageViewType::TYPE_2D_ARRAY,
                1,
                vk::REMAINING_ARRAY_LAYERS,
            ),
        );
        assert_eq!(rest.subresource_range.layer_count, 1);
    }

    #[test]
    fn merged_shadow_views_have_one_layer() {
        let s = shadow(1, 2);
        for (ty, base, count) in [
            (vk::ImageViewType::TYPE_2D_ARRAY, 0, 2),
            (vk::ImageViewType::TYPE_2D, 1, 1),
        ] {
            let v = shadow_view_info(&s, &app_view(ty, base, count));
            assert_eq!(
                (
                    v.subresource_range.base_array_layer,
                    v.subresource_range.layer_count
                ),
                (0, 1)
            );
        }
    }
}
