//! The reconstruction's compute shader ([`crate::vk::reconstruct`], docs/reconstruction.md): its
//! SPIR-V, built from `shaders/reconstruct.comp` by `shaders/build.sh`, its push constants, the
//! formats it decodes, and the device's table from a shading-rate code to the fragment size the
//! driver really shades.

use ash::vk;

use crate::bridge::FdmEmulation;

/// The compute shader, built from `shaders/reconstruct.comp` by `shaders/build.sh`.
pub static SHADER: &[u8] = include_bytes!("../shaders/reconstruct.comp.spv");

/// `local_size_x` and `local_size_y` of the shader.
pub const GROUP: u32 = 8;

/// How the shader decodes a colour format's raw texels (its `kind`). Channel order does not
/// matter: every channel is interpolated alike, and each kind's alpha sits where the shader looks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// Four 8-bit UNORM channels, any order.
    Unorm8 = 1,
    /// Four 8-bit channels, colour sRGB and alpha (the last byte) linear: decoded, blended in
    /// linear space and encoded again, as a filtered sample of an sRGB view is.
    Srgb8 = 2,
    /// 10:10:10:2 UNORM, either colour order.
    Unorm10 = 3,
    /// Four 16-bit floats.
    Half = 4,
    /// Four 16-bit UNORM channels.
    Unorm16 = 5,
}

impl Kind {
    /// The kind of `format`, `None` where the shader cannot decode it (left alone, said once).
    pub fn of(format: vk::Format) -> Option<Kind> {
        use vk::Format as F;
        Some(match format {
            F::R8G8B8A8_UNORM | F::B8G8R8A8_UNORM | F::A8B8G8R8_UNORM_PACK32 => Kind::Unorm8,
            F::R8G8B8A8_SRGB | F::B8G8R8A8_SRGB | F::A8B8G8R8_SRGB_PACK32 => Kind::Srgb8,
            F::A2B10G10R10_UNORM_PACK32 | F::A2R10G10B10_UNORM_PACK32 => Kind::Unorm10,
            F::R16G16B16A16_SFLOAT => Kind::Half,
            F::R16G16B16A16_UNORM => Kind::Unorm16,
            _ => return None,
        })
    }

    /// 32-bit words per texel.
    pub fn words(self) -> u32 {
        match self {
            Kind::Half | Kind::Unorm16 => 2,
            _ => 1,
        }
    }
}

/// The shader's table: nibble `c % 8` of word `c / 8` is `log2 w << 2 | log2 h` of the fragment
/// the device shades where the shading-rate attachment holds code `c`. fovea's pipelines shade
/// 1×1 and combine the attachment with `REPLACE` (emulation) or `MAX` against 1×1 (injection,
/// `crate::vk::translate::rate_state`), so the rate is the attachment's, clamped to one the device
/// lists ("Combining the Fragment Shading Rates",
/// <https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#primsrast-fragment-shading-rate-combining>).
pub fn table(fdm: &FdmEmulation) -> [u32; 2] {
    use fovea_model::shading_rate::{clamp, decode};
    let mut t = [0u32; 2];
    for c in 0..16u8 {
        let max = fdm.max_fragment;
        let want = decode(c);
        let s = clamp([want[0].min(max[0]), want[1].min(max[1])], &fdm.rates);
        let log2 = |v: u32| 31 - v.max(1).leading_zeros();
        let nibble = (log2(s[0]) << 2) | log2(s[1]);
        t[usize::from(c / 8)] |= nibble << ((u32::from(c) % 8) * 4);
    }
    t
}

/// The fragment size the table gives code `code`.
#[cfg(test)]
pub fn size_in(table: [u32; 2], code: u8) -> [u32; 2] {
    let n = (table[usize::from(code / 8 % 2)] >> ((u32::from(code) % 8) * 4)) & 15;
    [1 << (n >> 2), 1 << (n & 3)]
}

/// The push constants, as the shader declares them.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Push {
    pub width: u32,
    pub height: u32,
    pub origin: [u32; 2],
    pub rate_extent: [u32; 2],
    pub texel: [u32; 2],
    pub kind: u32,
    pub words: u32,
    pub rate_layers: u32,
    pub table: [u32; 2],
}

/// Bytes of [`Push`].
pub const PUSH_BYTES: usize = 13 * 4;

impl Push {
    pub fn bytes(&self) -> [u8; PUSH_BYTES] {
        let words = [
            self.width,
            self.height,
            self.origin[0],
            self.origin[1],
            self.rate_extent[0],
            self.rate_extent[1],
            self.texel[0],
            self.texel[1],
            self.kind,
            self.words,
            self.rate_layers,
            self.table[0],
            self.table[1],
        ];
        let mut out = [0; PUSH_BYTES];
        for (o, w) in out.chunks_exact_mut(4).zip(words) {
            o.copy_from_slice(&w.to_ne_bytes());
        }
        out
    }
}

/// For a pixel at framebuffer coordinate `p` (one axis) of a fragment `b` wide: the two block
/// centres (pixels) it lies between and the weight of the second, as the shader computes them
/// (the shader's arithmetic on the CPU, for the tests).
#[cfg(test)]
pub fn neighbours(p: u32, b: u32) -> ([i64; 2], f32) {
    let b = b.max(1);
    let g = (p as f32 + 0.5 - 0.5 * b as f32) / b as f32;
    let g0 = g.floor();
    let i = g0 as i64;
    let b = i64::from(b);
    ([i * b + b / 2, (i + 1) * b + b / 2], g - g0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_map_to_the_sizes_the_device_shades() {
        let nvidia = FdmEmulation::nvidia_like();
        let t = table(&nvidia);
        use fovea_model::shading_rate::code;
        // The NVIDIA-like device lists 1×1, 2×2 and 4×4 (fragments up to 4×4).
        for (want, shaded) in [
            ([1, 1], [1, 1]),
            ([1, 2], [1, 1]),
            ([2, 1], [1, 1]),
            ([2, 2], [2, 2]),
            ([2, 4], [2, 2]),
            ([4, 2], [2, 2]),
            ([4, 4], [4, 4]),
            ([4, 1], [1, 1]),
        ] {
            assert_eq!(size_in(t, code(want)), shaded, "{want:?}");
        }
        // Codes of 8-pixel edges are clamped to the device's maxFragmentSize first.
        assert_eq!(size_in(t, 0b1111), [4, 4]);
        let small = FdmEmulation {
            max_fragment: [2, 2],
            rates: vec![[1, 1], [2, 1], [1, 2], [2, 2]],
            ..FdmEmulation::nvidia_like()
        };
        let t = table(&small);
        assert_eq!(size_in(t, code([4, 4])), [2, 2]);
        assert_eq!(size_in(t, code([4, 1])), [2, 1]);
        assert_eq!(size_in(t, 0), [1, 1]);
    }

    #[test]
    fn formats_get_their_kind_and_others_none() {
        assert_eq!(Kind::of(vk::Format::B8G8R8A8_SRGB), Some(Kind::Srgb8));
        assert_eq!(Kind::of(vk::Format::R8G8B8A8_UNORM), Some(Kind::Unorm8));
        assert_eq!(
            Kind::of(vk::Format::A2B10G10R10_UNORM_PACK32),
            Some(Kind::Unorm10)
        );
        assert_eq!(
            Kind::of(vk::Format::R16G16B16A16_SFLOAT).map(Kind::words),
            Some(2)
        );
        assert_eq!(Kind::of(vk::Format::B10G11R11_UFLOAT_PACK32), None);
        assert_eq!(Kind::of(vk::Format::R32G32B32A32_SFLOAT), None);
    }

    #[test]
    fn a_pixel_blends_the_centres_around_it() {
        // 4-wide blocks: centres at 2, 6, 10, ...; pixel 2's centre (2.5) is 1/8 past centre 2.
        assert_eq!(neighbours(2, 4), ([2, 6], 0.125));
        assert_eq!(neighbours(5, 4), ([2, 6], 0.875));
        // Before the first centre, the grid's block -1 (clamped to the render area by the shader).
        assert_eq!(neighbours(0, 4), ([-2, 2], 0.625));
        // A 1-wide axis takes the pixel itself.
        assert_eq!(neighbours(7, 1), ([7, 8], 0.0));
        // 2-wide blocks: centres at 1, 3, 5 (the edge between a block's two pixels, stored as
        // its right pixel); pixel 3's centre (3.5) is a quarter of the way from 3 to 5.
        assert_eq!(neighbours(3, 2), ([3, 5], 0.25));
        assert_eq!(neighbours(2, 2), ([1, 3], 0.75));
    }

    #[test]
    fn shader_matches_its_source() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/vk/shaders");
        fovea_harness::assert_spirv_built_from(&dir.join("reconstruct.comp"), &[], SHADER);
    }
}
