//! The devices the double impersonates.
//!
//! Values follow the desktop drivers with attachment shading rates (Mesa's NVK for NVIDIA Turing+,
//! RADV for AMD gfx10.3+), and the limits the spec requires of every implementation
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkPhysicalDeviceFragmentShadingRatePropertiesKHR.html>).

use ash::vk;

/// Which desktop GPU lavapipe is dressed up as.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Profile {
    /// 16×16 texels, layered attachments, fragments up to 4×4.
    Nvidia,
    /// 8×8 texels, one layer, fragments up to 2×2.
    Amd,
    /// Nothing offered: every call passes through unchanged.
    None,
}

impl Profile {
    /// Parses `nvidia`, `amd` or `none`.
    pub fn parse(name: &str) -> Option<Profile> {
        match name.trim().to_ascii_lowercase().as_str() {
            "nvidia" => Some(Profile::Nvidia),
            "amd" => Some(Profile::Amd),
            "none" => Some(Profile::None),
            _ => None,
        }
    }

    /// The name [`Profile::parse`] accepts.
    pub fn name(self) -> &'static str {
        match self {
            Profile::Nvidia => "nvidia",
            Profile::Amd => "amd",
            Profile::None => "none",
        }
    }

    /// Whether the double offers shading-rate attachments at all.
    pub fn offers_fsr(self) -> bool {
        self != Profile::None
    }

    /// The one shading-rate attachment texel size (min = max on every desktop driver).
    pub fn texel(self) -> vk::Extent2D {
        match self {
            Profile::Nvidia => vk::Extent2D {
                width: 16,
                height: 16,
            },
            _ => vk::Extent2D {
                width: 8,
                height: 8,
            },
        }
    }

    /// The largest fragment, per axis.
    pub fn max_fragment(self) -> u32 {
        match self {
            Profile::Nvidia => 4,
            _ => 2,
        }
    }

    /// Whether a multi-layer view can be the attachment (one rate image per view).
    pub fn layered(self) -> bool {
        self == Profile::Nvidia
    }

    /// The sample counts lavapipe renders with (`framebufferColorSampleCounts`: 1 and 4).
    pub const SAMPLES: vk::SampleCountFlags = vk::SampleCountFlags::from_raw(
        vk::SampleCountFlags::TYPE_1.as_raw() | vk::SampleCountFlags::TYPE_4.as_raw(),
    );

    /// The fragment sizes of [`Profile::rates`], as `[width, height]`: what the double's shading
    /// and coarsening look rates up in.
    pub fn fragment_sizes(self) -> Vec<[u32; 2]> {
        self.rates()
            .iter()
            .map(|(e, _)| [e.width, e.height])
            .collect()
    }

    /// The rates vkGetPhysicalDeviceFragmentShadingRatesKHR lists: every power-of-two size up to
    /// the maximum with an aspect ratio of at most 2, widest first and, for equal widths, tallest
    /// first, as
    /// <https://registry.khronos.org/vulkan/specs/latest/man/html/vkGetPhysicalDeviceFragmentShadingRatesKHR.html>
    /// orders them. The 1×1 entry reports `~0` sample counts, which the spec requires of it.
    pub fn rates(self) -> Vec<(vk::Extent2D, vk::SampleCountFlags)> {
        let mut out = Vec::new();
        if !self.offers_fsr() {
            return out;
        }
        let max = self.max_fragment();
        let mut w = max;
        while w >= 1 {
            let mut h = max;
            while h >= 1 {
                if w <= 2 * h && h <= 2 * w {
                    let samples = if w == 1 && h == 1 {
                        vk::SampleCountFlags::from_raw(!0)
                    } else {
                        Self::SAMPLES
                    };
                    out.push((
                        vk::Extent2D {
                            width: w,
                            height: h,
                        },
                        samples,
                    ));
                }
                h /= 2;
            }
            w /= 2;
        }
        out
    }

    /// Fills the properties struct. Every field is set, within the spec's required limits:
    /// texel min ≤ 32×32 and max ≥ 8×8, aspect ratios ≥ 1, coverage samples = the largest fragment
    /// area times the largest sample count.
    pub fn fill_properties(self, p: &mut vk::PhysicalDeviceFragmentShadingRatePropertiesKHR<'_>) {
        let t = self.texel();
        let m = self.max_fragment();
        p.min_fragment_shading_rate_attachment_texel_size = t;
        p.max_fragment_shading_rate_attachment_texel_size = t;
        p.max_fragment_shading_rate_attachment_texel_size_aspect_ratio = 1;
        // Needs the primitive feature, which the double does not offer.
        p.primitive_fragment_shading_rate_with_multiple_viewports = vk::FALSE;
        p.layered_shading_rate_attachments = self.layered().into();
        // MAX, MIN and MUL besides KEEP and REPLACE: NVIDIA's driver and RADV both report it
        // (`crate::TRIVIAL_COMBINERS_ENV` turns it off).
        p.fragment_shading_rate_non_trivial_combiner_ops = vk::TRUE;
        p.max_fragment_size = vk::Extent2D {
            width: m,
            height: m,
        };
        p.max_fragment_size_aspect_ratio = 2;
        p.max_fragment_shading_rate_coverage_samples = m * m * 4;
        p.max_fragment_shading_rate_rasterization_samples = vk::SampleCountFlags::TYPE_4;
        // RADV has a depth/stencil-export erratum on the hardware it reports; NVK does not.
        p.fragment_shading_rate_with_shader_depth_stencil_writes = (self == Profile::Nvidia).into();
        p.fragment_shading_rate_with_sample_mask = vk::TRUE;
        p.fragment_shading_rate_with_shader_sample_mask = vk::TRUE;
        // lavapipe has neither conservative rasterization, interlock nor sample locations.
        p.fragment_shading_rate_with_conservative_rasterization = vk::FALSE;
        p.fragment_shading_rate_with_fragment_shader_interlock = vk::FALSE;
        p.fragment_shading_rate_with_custom_sample_locations = vk::FALSE;
        p.fragment_shading_rate_strict_multiply_combiner = vk::TRUE;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_are_ordered_widest_then_tallest_and_end_in_1x1() {
        for p in [Profile::Nvidia, Profile::Amd] {
            let rates = p.rates();
            let sizes: Vec<(u32, u32)> = rates.iter().map(|(e, _)| (e.width, e.height)).collect();
            let mut sorted = sizes.clone();
            sorted.sort_by(|a, b| b.cmp(a));
            assert_eq!(sizes, sorted);
            assert_eq!(sizes.last(), Some(&(1, 1)));
            assert_eq!(rates.last().unwrap().1.as_raw(), !0);
            // The spec requires 2x2, 2x1, 1x2 and 1x1 everywhere.
            for r in [(2, 2), (2, 1), (1, 2)] {
                assert!(sizes.contains(&r), "{p:?} lacks {r:?}");
            }
        }
        assert!(Profile::None.rates().is_empty());
    }

    #[test]
    fn properties_meet_the_required_limits() {
        for p in [Profile::Nvidia, Profile::Amd] {
            let mut props = vk::PhysicalDeviceFragmentShadingRatePropertiesKHR::default();
            p.fill_properties(&mut props);
            let min = props.min_fragment_shading_rate_attachment_texel_size;
            let max = props.max_fragment_shading_rate_attachment_texel_size;
            assert!(min.width <= 32 && min.height <= 32);
            assert!(max.width >= 8 && max.height >= 8);
            assert!(props.max_fragment_shading_rate_attachment_texel_size_aspect_ratio >= 1);
            assert!(props.max_fragment_size_aspect_ratio >= 2);
            let m = props.max_fragment_size;
            assert!(m.width >= 2 && m.height >= 2);
            assert!(props.max_fragment_shading_rate_coverage_samples <= m.width * m.height * 16);
            for (size, samples) in p.rates() {
                assert!(size.width <= m.width && size.height <= m.height);
                if samples.as_raw() != !0 {
                    let most = 1 << (31 - samples.as_raw().leading_zeros());
                    assert!(
                        size.width * size.height * most
                            <= props.max_fragment_shading_rate_coverage_samples
                    );
                }
            }
        }
    }

    #[test]
    fn names_round_trip() {
        for p in [Profile::Nvidia, Profile::Amd, Profile::None] {
            assert_eq!(Profile::parse(p.name()), Some(p));
        }
        assert_eq!(Profile::parse(" NVIDIA "), Some(Profile::Nvidia));
        assert_eq!(Profile::parse("intel"), None);
    }
}
