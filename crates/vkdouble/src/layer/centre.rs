//! The value a coarse fragment's shader computes, from the pixels lavapipe shaded one by one.
//!
//! Where a GPU shades a fragment of w×h pixels once, it evaluates the shader at the centre of
//! the fragment area: inputs are interpolated "at the center of the fragment area" (single
//! sample, no `Sample` decoration; Vulkan, "Interpolation Decorations",
//! <https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#shaders-interpolation-decorations>)
//! and `FragCoord` holds "the location of the center of the fragment"
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/FragCoord.html>); the
//! `VK_NV_shading_rate_image` appendix (issue 3) says the same of its coarse fragments. A
//! fragment's area is its whole w×h group of pixels, aligned to multiples of its size, so for
//! an even size that centre lies on the corner shared by the middle pixels, and for a fragment
//! that the framebuffer or the render area cuts, it may lie outside the pixels written.
//!
//! The double has each pixel's value at that pixel's centre, not at arbitrary points. Its
//! stand-in for the value at the fragment's centre is the mean of the pixels nearest it: the
//! middle pixel per axis of odd size (1), the two middle ones of even size (2, 4), so 1, 2 or 4
//! pixels. That mean is the bilinear interpolation of the pixel centres at the fragment centre:
//! exact wherever the shaded value varies linearly over those pixels (a smooth gradient, an
//! interpolated attribute, a texture magnified), and off by up to the step itself where an edge
//! the shader draws runs between them (the GPU gives one side, the mean a mix). Picking one of
//! the middle pixels instead would be right at edges and half a pixel off everywhere else. The
//! mean is taken in linear terms: sRGB channels are decoded first (the shader's output is
//! linear; the attachment encodes it), floats are averaged as floats.
//!
//! Where the framebuffer or render area cuts the fragment, the GPU still shades at the centre of
//! the whole area, extrapolating the attributes beyond the pixels it writes; the double has no
//! pixels there, so it takes the middle pixels clamped into the part written (the written pixels
//! nearest the true centre). The value then differs from a GPU's by the shaded value's change
//! over that distance; it only concerns fragments on the last columns or rows.

use std::sync::OnceLock;

use ash::vk;

/// How a format's texel decodes into linear channel values and back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Codec {
    /// Four 8-bit UNORM channels; with `srgb`, the first three are sRGB-encoded (both
    /// `R8G8B8A8` and `B8G8R8A8`: alpha is the fourth byte either way).
    Rgba8 { srgb: bool },
    /// Channels of 10, 10, 10 and 2 bits, UNORM, in a 32-bit word (either component order).
    Unorm1010102,
    /// `B10G11R11_UFLOAT_PACK32`: 11-, 11- and 10-bit unsigned floats.
    Ufloat111110,
    /// Four 16-bit UNORM channels.
    Rgba16Unorm,
    /// Four 16-bit floats.
    Rgba16Float,
    /// Four 32-bit floats.
    Rgba32Float,
}

impl Codec {
    /// The codec of a colour format the double coarsens (those of `super::pixel_bytes`).
    pub(super) fn of(format: vk::Format) -> Option<Codec> {
        use vk::Format as F;
        Some(match format {
            F::R8G8B8A8_UNORM | F::B8G8R8A8_UNORM => Codec::Rgba8 { srgb: false },
            F::R8G8B8A8_SRGB | F::B8G8R8A8_SRGB => Codec::Rgba8 { srgb: true },
            F::A2B10G10R10_UNORM_PACK32 | F::A2R10G10B10_UNORM_PACK32 => Codec::Unorm1010102,
            F::B10G11R11_UFLOAT_PACK32 => Codec::Ufloat111110,
            F::R16G16B16A16_UNORM => Codec::Rgba16Unorm,
            F::R16G16B16A16_SFLOAT => Codec::Rgba16Float,
            F::R32G32B32A32_SFLOAT => Codec::Rgba32Float,
            _ => return None,
        })
    }

    /// Bytes per texel.
    pub(super) fn bytes(self) -> usize {
        match self {
            Codec::Rgba8 { .. } | Codec::Unorm1010102 | Codec::Ufloat111110 => 4,
            Codec::Rgba16Unorm | Codec::Rgba16Float => 8,
            Codec::Rgba32Float => 16,
        }
    }

    /// The texel's channels as linear values (unused channels 0).
    fn decode(self, t: &[u8]) -> [f32; 4] {
        let word = |i: usize| u32::from_le_bytes([t[i], t[i + 1], t[i + 2], t[i + 3]]);
        let half = |i: usize| u16::from_le_bytes([t[i], t[i + 1]]);
        match self {
            Codec::Rgba8 { srgb } => {
                // In units of the 8-bit step; sRGB channels as linear values so scaled.
                let table = srgb_tables();
                let c = |i: usize| {
                    if srgb && i < 3 {
                        table.linear[usize::from(t[i])]
                    } else {
                        f32::from(t[i])
                    }
                };
                [c(0), c(1), c(2), c(3)]
            }
            Codec::Unorm1010102 => {
                let w = word(0);
                let c = |shift: u32, bits: u32| ((w >> shift) & ((1 << bits) - 1)) as f32;
                [c(0, 10), c(10, 10), c(20, 10), c(30, 2)]
            }
            Codec::Ufloat111110 => {
                let w = word(0);
                [
                    small_float((w & 0x7ff) as u16, 6),
                    small_float(((w >> 11) & 0x7ff) as u16, 6),
                    small_float(((w >> 22) & 0x3ff) as u16, 5),
                    0.0,
                ]
            }
            Codec::Rgba16Unorm => [0, 2, 4, 6].map(|i| f32::from(half(i))),
            Codec::Rgba16Float => [0, 2, 4, 6].map(|i| f16_to_f32(half(i))),
            Codec::Rgba32Float => [0, 4, 8, 12].map(|i| f32::from_bits(word(i))),
        }
    }

    /// Encodes linear channel values as [`Codec::decode`] gives them into `out`.
    fn encode(self, c: [f32; 4], out: &mut [u8]) {
        // UNORM channels: `decode` gives them in units of their step.
        let int = |v: f32, max: u32| v.round().clamp(0.0, max as f32) as u32;
        match self {
            Codec::Rgba8 { srgb } => {
                let table = srgb_tables();
                for (i, v) in c.into_iter().enumerate() {
                    out[i] = if srgb && i < 3 {
                        // The code whose interval holds `v`: round(sRGB(v) · 255).
                        table.up.partition_point(|&u| u <= v) as u8
                    } else {
                        int(v, 255) as u8
                    };
                }
            }
            Codec::Unorm1010102 => {
                let w = int(c[0], 1023)
                    | int(c[1], 1023) << 10
                    | int(c[2], 1023) << 20
                    | int(c[3], 3) << 30;
                out[..4].copy_from_slice(&w.to_le_bytes());
            }
            Codec::Ufloat111110 => {
                let w = u32::from(to_small_float(c[0], 6))
                    | u32::from(to_small_float(c[1], 6)) << 11
                    | u32::from(to_small_float(c[2], 5)) << 22;
                out[..4].copy_from_slice(&w.to_le_bytes());
            }
            Codec::Rgba16Unorm => {
                for (i, v) in c.into_iter().enumerate() {
                    out[2 * i..2 * i + 2].copy_from_slice(&(int(v, 65535) as u16).to_le_bytes());
                }
            }
            Codec::Rgba16Float => {
                for (i, v) in c.into_iter().enumerate() {
                    out[2 * i..2 * i + 2].copy_from_slice(&to_small_float(v, 10).to_le_bytes());
                }
            }
            Codec::Rgba32Float => {
                for (i, v) in c.into_iter().enumerate() {
                    out[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
                }
            }
        }
    }

    /// [`Codec::mean`] of the texels of `pixels` at byte offsets `at` (1, 2 or 4 of them), with
    /// the 8-bit formats (the eye buffers' usual ones) summed directly: the double does this for
    /// every block of every coarse pass.
    pub(super) fn mean_at(self, pixels: &[u8], at: &[usize], out: &mut [u8]) {
        let n = self.bytes();
        if let [one] = at {
            out[..n].copy_from_slice(&pixels[*one..*one + n]);
            return;
        }
        if let Codec::Rgba8 { srgb } = self {
            let k = at.len() as u32;
            let table = srgb_tables();
            for c in 0..4 {
                if srgb && c < 3 {
                    let mut sum = 0f32;
                    for &a in at {
                        sum += table.linear[usize::from(pixels[a + c])];
                    }
                    let v = sum / k as f32;
                    out[c] = table.up.partition_point(|&u| u <= v) as u8;
                } else {
                    let mut sum = 0u32;
                    for &a in at {
                        sum += u32::from(pixels[a + c]);
                    }
                    out[c] = ((sum + k / 2) / k) as u8;
                }
            }
            return;
        }
        let mut texels: [&[u8]; 4] = [&[]; 4];
        for (t, &a) in texels.iter_mut().zip(at) {
            *t = &pixels[a..a + n];
        }
        self.mean(&texels[..at.len()], out);
    }

    /// The mean of `texels` (1, 2 or 4 of them), in linear terms, into `out`. A single texel is
    /// copied as it is (bit for bit: no round trip through the codec).
    pub(super) fn mean(self, texels: &[&[u8]], out: &mut [u8]) {
        let n = self.bytes();
        if let [one] = texels {
            out[..n].copy_from_slice(&one[..n]);
            return;
        }
        let mut sum = [0f32; 4];
        for t in texels {
            for (s, v) in sum.iter_mut().zip(self.decode(t)) {
                *s += v;
            }
        }
        let k = texels.len() as f32;
        self.encode(sum.map(|s| s / k), out);
    }
}

/// The pixels (offsets within the block, per axis) nearest the centre of a fragment `size`
/// pixels long whose first `written` pixels are written: the middle one or two, clamped into
/// those written.
pub(super) fn middle(size: u32, written: u32) -> [u32; 2] {
    let last = written.max(1) - 1;
    [((size - 1) / 2).min(last), (size / 2).min(last)]
}

/// 8-bit sRGB codes as linear values (in units of 1/255), and the linear values (so scaled) where
/// rounding passes from one code to the next: built once, so that coarsening a frame (every
/// block of every coarse pass) costs no transcendental functions.
struct SrgbTables {
    linear: [f32; 256],
    up: [f32; 255],
}

fn srgb_tables() -> &'static SrgbTables {
    static TABLES: OnceLock<SrgbTables> = OnceLock::new();
    TABLES.get_or_init(|| SrgbTables {
        linear: std::array::from_fn(|k| srgb_to_linear(k as f32 / 255.0) * 255.0),
        up: std::array::from_fn(|k| srgb_to_linear((k as f32 + 0.5) / 255.0) * 255.0),
    })
}

/// The sRGB transfer function's inverse ("sRGB EOTF" of the Khronos Data Format
/// Specification, the conversion Vulkan applies on reads of sRGB formats).
fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// A non-negative float with a 5-bit exponent (bias 15) and `mantissa` bits, no sign: the
/// 11- and 10-bit floats of packed formats, and the magnitude of a 16-bit float.
fn small_float(bits: u16, mantissa: u32) -> f32 {
    let e = u32::from(bits >> mantissa) & 0x1f;
    let m = f32::from(bits & ((1 << mantissa) - 1));
    let scale = (1u32 << mantissa) as f32;
    match e {
        0 => m / scale * 2f32.powi(-14),
        31 if m == 0.0 => f32::INFINITY,
        31 => f32::NAN,
        _ => (1.0 + m / scale) * 2f32.powi(e as i32 - 15),
    }
}

/// A 16-bit float's value.
fn f16_to_f32(bits: u16) -> f32 {
    let v = small_float(bits & 0x7fff, 10);
    if bits & 0x8000 != 0 {
        -v
    } else {
        v
    }
}

/// `v` as a float with a 5-bit exponent and `mantissa` bits, rounded to nearest; with 10
/// mantissa bits it has a sign bit (a 16-bit float), else negatives become 0 (the packed
/// unsigned floats cannot hold them).
fn to_small_float(v: f32, mantissa: u32) -> u16 {
    let signed = mantissa == 10;
    let sign = if signed && v.is_sign_negative() {
        0x8000
    } else {
        0
    };
    let a = if signed { v.abs() } else { v.max(0.0) };
    let inf = 0x1fu16 << mantissa;
    if a.is_nan() {
        return sign | inf | 1;
    }
    // Round to the representable neighbours: subnormals step by 2^-14 / 2^mantissa, normals
    // of exponent e by 2^(e-15) / 2^mantissa.
    let step_sub = 2f32.powi(-14 - mantissa as i32);
    if a < 2f32.powi(-14) {
        return sign | (a / step_sub).round() as u16;
    }
    let e = a.log2().floor() as i32;
    let e = if 2f32.powi(e) > a { e - 1 } else { e };
    if e > 15 {
        return sign | inf;
    }
    let step = 2f32.powi(e - mantissa as i32);
    let m = (a / step).round() as u32; // 2^mantissa ..= 2^(mantissa+1)
    let bits = (((e + 15) as u32) << mantissa) + (m - (1 << mantissa));
    // A carry out of the mantissa moves to the next exponent, up to infinity.
    sign | (bits as u16).min(inf)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sRGB transfer function, as writes to sRGB formats apply it.
    fn linear_to_srgb(v: f32) -> f32 {
        if v <= 0.003_130_8 {
            v * 12.92
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        }
    }

    #[test]
    fn srgb_codes_round_as_the_transfer_function_does() {
        let rgba = Codec::Rgba8 { srgb: true };
        let mut out = [0u8; 4];
        for i in 0..=100_000u32 {
            let v = i as f32 / 100_000.0;
            rgba.encode([v * 255.0, 0.0, 0.0, 0.0], &mut out);
            let want = (linear_to_srgb(v) * 255.0).round() as u8;
            assert!(out[0].abs_diff(want) <= 1, "{v}: {} against {want}", out[0]);
            // Off by one only where the value lies on a rounding boundary, to float precision.
            if out[0] != want {
                let s = linear_to_srgb(v) * 255.0;
                assert!((s - s.floor() - 0.5).abs() < 1e-3, "{v}: {s}");
            }
        }
        for k in 0..=255u8 {
            assert_eq!(
                rgba.decode(&[k, 0, 0, 0])[0],
                srgb_to_linear(f32::from(k) / 255.0) * 255.0
            );
        }
    }

    #[test]
    fn the_middle_pixels_are_those_around_the_centre_clamped_into_those_written() {
        assert_eq!(middle(1, 1), [0, 0]);
        assert_eq!(middle(2, 2), [0, 1]);
        assert_eq!(middle(4, 4), [1, 2]);
        // Cut by the framebuffer's edge: the written pixels nearest the centre.
        assert_eq!(middle(4, 2), [1, 1]);
        assert_eq!(middle(4, 1), [0, 0]);
        assert_eq!(middle(2, 1), [0, 0]);
    }

    #[test]
    fn small_floats_round_trip_and_round_to_nearest() {
        for m in [5, 6, 10] {
            for bits in 0..(0x1fu16 << m) {
                let v = small_float(bits, m);
                assert_eq!(
                    to_small_float(v, m),
                    bits,
                    "{m} mantissa bits: {bits:#x} ({v})"
                );
            }
        }
        assert_eq!(f16_to_f32(0x3c00), 1.0);
        assert_eq!(f16_to_f32(0xc000), -2.0);
        assert_eq!(to_small_float(-2.0, 10), 0xc000);
        // Halfway between 1 and 1 + 2^-10 would tie; just above it rounds up.
        assert_eq!(to_small_float(1.0 + 2f32.powi(-10) * 0.6, 10), 0x3c01);
        assert_eq!(to_small_float(70000.0, 10), 0x7c00);
        assert_eq!(to_small_float(-1.0, 6), 0);
    }

    #[test]
    fn the_mean_is_linear_and_a_single_texel_is_kept_bit_for_bit() {
        // 8-bit UNORM: plain integer mean.
        let mut out = [0u8; 4];
        Codec::Rgba8 { srgb: false }.mean(&[&[10, 20, 30, 255], &[20, 40, 31, 255]], &mut out);
        assert_eq!(out, [15, 30, 31, 255]);
        // sRGB: black and white average to linear 0.5, encoded 188, not 128; alpha is linear.
        Codec::Rgba8 { srgb: true }.mean(&[&[0, 0, 0, 0], &[255, 255, 255, 255]], &mut out);
        assert_eq!(out, [188, 188, 188, 128]);
        // sRGB values that are already equal stay as they are.
        for v in 0..=255u8 {
            Codec::Rgba8 { srgb: true }.mean(&[&[v; 4], &[v; 4], &[v; 4], &[v; 4]], &mut out);
            assert_eq!(out, [v; 4]);
        }
        // 10:10:10:2.
        let a = (100u32 | 200 << 10 | 300 << 20 | 1 << 30).to_le_bytes();
        let b = (200u32 | 400 << 10 | 500 << 20 | 3 << 30).to_le_bytes();
        Codec::Unorm1010102.mean(&[&a, &b], &mut out);
        assert_eq!(
            u32::from_le_bytes(out),
            150 | 300 << 10 | 400 << 20 | 2 << 30
        );
        // 11:11:10 floats: 1 and 2 give 1.5.
        let one = (u32::from(to_small_float(1.0, 6)) * (1 | 1 << 11))
            | (u32::from(to_small_float(1.0, 5)) << 22);
        let two = (u32::from(to_small_float(2.0, 6)) * (1 | 1 << 11))
            | (u32::from(to_small_float(2.0, 5)) << 22);
        Codec::Ufloat111110.mean(&[&one.to_le_bytes(), &two.to_le_bytes()], &mut out);
        assert_eq!(Codec::Ufloat111110.decode(&out), [1.5, 1.5, 1.5, 0.0]);
        // 16-bit float and UNORM, 32-bit float.
        let mut wide = [0u8; 16];
        let h = |v: [f32; 4]| {
            let mut t = [0u8; 8];
            Codec::Rgba16Float.encode(v, &mut t);
            t
        };
        let (p, q) = (h([0.25, -1.0, 4.0, 1.0]), h([0.75, 1.0, 8.0, 1.0]));
        Codec::Rgba16Float.mean(&[&p, &q], &mut wide);
        assert_eq!(Codec::Rgba16Float.decode(&wide), [0.5, 0.0, 6.0, 1.0]);
        let u = |v: [u16; 4]| {
            let mut t = [0u8; 8];
            for (i, c) in v.into_iter().enumerate() {
                t[2 * i..2 * i + 2].copy_from_slice(&c.to_le_bytes());
            }
            t
        };
        let (p, q) = (u([0, 1, 65535, 7]), u([2, 2, 65535, 8]));
        Codec::Rgba16Unorm.mean(&[&p, &q, &p, &q], &mut wide);
        assert_eq!(Codec::Rgba16Unorm.decode(&wide), [1.0, 2.0, 65535.0, 8.0]);
        let f = |v: [f32; 4]| {
            let mut t = [0u8; 16];
            Codec::Rgba32Float.encode(v, &mut t);
            t
        };
        let (p, q) = (f([0.1, 0.2, 0.3, 1.0]), f([0.3, 0.4, 0.5, 1.0]));
        Codec::Rgba32Float.mean(&[&p, &q], &mut wide);
        let got = Codec::Rgba32Float.decode(&wide);
        assert!(
            (got[0] - 0.2).abs() < 1e-7 && (got[2] - 0.4).abs() < 1e-7,
            "{got:?}"
        );
        // One texel: the same bytes, even a NaN payload a round trip would not keep.
        let nan = f([f32::from_bits(0x7fc0_1234), 0.0, 0.0, 0.0]);
        Codec::Rgba32Float.mean(&[&nan], &mut wide);
        assert_eq!(wide, nan);
    }
}
