//! Fragment-density-map bytes to fragment-shading-rate codes.
//!
//! A density map (`VK_EXT_fragment_density_map`, R8G8_UNORM) stores per texel a density `d` per
//! axis (R → x, G → y); the fragment area the implementation may use is at most `1/d` texels per
//! axis, and any supported size not larger than that is a conformant result
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/VK_EXT_fragment_density_map.html>).
//! A shading-rate attachment (`VK_KHR_fragment_shading_rate`, R8_UINT) stores per texel a code
//! `(log2 w << 2) | log2 h` for a fragment of `w × h` pixels, `w, h ∈ {1, 2, 4}`
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkFragmentShadingRateAttachmentInfoKHR.html>),
//! which the driver clamps to the sizes `vkGetPhysicalDeviceFragmentShadingRatesKHR` lists
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkGetPhysicalDeviceFragmentShadingRatesKHR.html>).
//!
//! The translation per axis: the largest power of two `s ≤ min(4, maxFragmentSize, 255 / byte)`;
//! byte 0 (undefined density) shades at full rate. The pair is then clamped to a size the driver
//! lists, so the code the attachment holds is already the rate the GPU will use.

/// The largest fragment edge a shading-rate code can express.
pub const MAX_EDGE: u32 = 4;

/// The fragment edge for one density byte (`255` = full density = 1 pixel): the largest power of
/// two that is at most `min(4, max_edge, 255 / byte)`; byte 0 → 1. `max_edge` below 1 counts as 1.
pub fn axis_size(byte: u8, max_edge: u32) -> u32 {
    if byte == 0 {
        return 1;
    }
    let limit = (255 / u32::from(byte)).min(MAX_EDGE).min(max_edge.max(1));
    // The largest power of two ≤ limit (limit ≥ 1 here).
    1 << (31 - limit.leading_zeros())
}

/// The shading-rate code of a `w × h` fragment (`w`, `h` powers of two ≤ 4).
pub fn code(size: [u32; 2]) -> u8 {
    let log2 = |v: u32| (31 - v.clamp(1, MAX_EDGE).leading_zeros()) as u8;
    (log2(size[0]) << 2) | log2(size[1])
}

/// The fragment size a shading-rate code stands for.
pub fn decode(code: u8) -> [u32; 2] {
    [1 << ((code >> 2) & 3), 1 << (code & 3)]
}

/// Clamps `want` to a size in `supported`: of the listed sizes no larger than `want` on either
/// axis, the one with the largest area, then the squarest, then the wider one (the spec leaves
/// wide-versus-tall ties to the implementation; this picks one so the result is deterministic).
/// 1×1 is always allowed, listed or not (every implementation supports it).
pub fn clamp(want: [u32; 2], supported: &[[u32; 2]]) -> [u32; 2] {
    let log2 = |v: u32| 31 - v.max(1).leading_zeros();
    supported
        .iter()
        .copied()
        .filter(|s| s[0] >= 1 && s[1] >= 1 && s[0] <= want[0] && s[1] <= want[1])
        .chain(std::iter::once([1, 1]))
        .max_by_key(|s| {
            let aspect = log2(s[0]).abs_diff(log2(s[1]));
            (s[0] * s[1], std::cmp::Reverse(aspect), s[0])
        })
        .unwrap_or([1, 1])
}

/// The shading-rate code for one density-map texel `[R, G]`, on a device whose largest fragment is
/// `max_fragment` and which lists the sizes `supported` (for one sample).
pub fn fsr_code(density: [u8; 2], max_fragment: [u32; 2], supported: &[[u32; 2]]) -> u8 {
    let want = [
        axis_size(density[0], max_fragment[0]),
        axis_size(density[1], max_fragment[1]),
    ];
    code(clamp(want, supported))
}

/// The finer of two shading-rate codes, as one merged shading-rate layer shared by several views
/// needs it (docs/vulkan-fdm-on-fsr.md#multiview): per axis the smaller fragment edge, clamped
/// to a size in `supported`.
pub fn finer(a: u8, b: u8, supported: &[[u32; 2]]) -> u8 {
    let (a, b) = (decode(a), decode(b));
    code(clamp([a[0].min(b[0]), a[1].min(b[1])], supported))
}

/// Converts a whole density map into shading-rate codes: `density` holds `layers` layers of
/// `texels` R8G8 texels each; `out` gets `texels` codes per output layer, one layer per density
/// layer, or (with `merged`) one layer holding per texel the [`finer`] code of all density layers.
/// Texels missing from either slice are left alone.
pub fn fill_codes(
    density: &[u8],
    texels: usize,
    merged: bool,
    max_fragment: [u32; 2],
    supported: &[[u32; 2]],
    out: &mut [u8],
) {
    if texels == 0 {
        return;
    }
    for (layer, map) in density.chunks_exact(texels * 2).enumerate() {
        let at = if merged { 0 } else { layer * texels };
        let Some(dst) = out.get_mut(at..at + texels) else {
            return;
        };
        for (c, t) in dst.iter_mut().zip(map.chunks_exact(2)) {
            let new = fsr_code([t[0], t[1]], max_fragment, supported);
            *c = if merged && layer > 0 {
                finer(*c, new, supported)
            } else {
                new
            };
        }
    }
}

/// Merges `layers` layers of `texels` codes each (`codes`) into one (`out`, `texels` codes): per
/// texel the [`finer`] code of all layers, as [`fill_codes`] does with `merged`. Shifted per-view
/// layers become one merged layer this way without converting density again.
pub fn merge_codes(codes: &[u8], texels: usize, supported: &[[u32; 2]], out: &mut [u8]) {
    if texels == 0 || out.len() < texels {
        return;
    }
    for (layer, src) in codes.chunks_exact(texels).enumerate() {
        if layer == 0 {
            out[..texels].copy_from_slice(src);
        } else {
            for (c, n) in out.iter_mut().zip(src) {
                *c = finer(*c, *n, supported);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What `vkGetPhysicalDeviceFragmentShadingRatesKHR` lists on a device with fragments up to
    /// `max` and aspect ratios up to 2 (NVIDIA: 4, AMD: 2).
    fn rates(max: u32) -> Vec<[u32; 2]> {
        let mut out = Vec::new();
        for w in [4, 2, 1] {
            for h in [4, 2, 1] {
                if w <= max && h <= max && w <= 2 * h && h <= 2 * w {
                    out.push([w, h]);
                }
            }
        }
        out
    }

    #[test]
    fn merging_layers_of_codes_is_the_merged_conversion() {
        let supported = rates(4);
        let texels = 64;
        let density: Vec<u8> = (0..texels * 2 * 2).map(|i| (i * 37 % 256) as u8).collect();
        let mut layered = vec![0; texels * 2];
        fill_codes(&density, texels, false, [4, 4], &supported, &mut layered);
        let mut want = vec![0; texels];
        fill_codes(&density, texels, true, [4, 4], &supported, &mut want);
        let mut got = vec![0xff; texels];
        merge_codes(&layered, texels, &supported, &mut got);
        assert_eq!(got, want);
        assert_ne!(layered[..texels], want[..], "the second layer counts");
    }

    #[test]
    fn bytes_map_to_the_largest_allowed_power_of_two() {
        for b in 128..=255u8 {
            assert_eq!(axis_size(b, 4), 1, "{b}");
        }
        for b in 64..=127u8 {
            assert_eq!(axis_size(b, 4), 2, "{b}");
        }
        for b in 1..=63u8 {
            assert_eq!(axis_size(b, 4), 4, "{b}");
        }
        assert_eq!(axis_size(0, 4), 1, "undefined density shades at full rate");
        assert_eq!(axis_size(1, 2), 2, "the driver's largest fragment caps it");
        assert_eq!(axis_size(1, 0), 1);
        assert_eq!(axis_size(100, 3), 2);
    }

    #[test]
    fn codes_round_trip() {
        for w in [1, 2, 4] {
            for h in [1, 2, 4] {
                assert_eq!(decode(code([w, h])), [w, h]);
            }
        }
        assert_eq!(code([1, 1]), 0);
        assert_eq!(code([2, 1]), 4);
        assert_eq!(code([1, 2]), 1);
        assert_eq!(code([2, 2]), 5);
        assert_eq!(code([4, 4]), 10);
        assert_eq!(code([4, 2]), 9);
    }

    #[test]
    fn nvidia_like_device() {
        let r = rates(4);
        assert_eq!(fsr_code([255, 255], [4, 4], &r), code([1, 1]));
        assert_eq!(fsr_code([127, 127], [4, 4], &r), code([2, 2]));
        assert_eq!(fsr_code([10, 10], [4, 4], &r), code([4, 4]));
        assert_eq!(fsr_code([10, 127], [4, 4], &r), code([4, 2]));
        // 4×1 is not listed (aspect 4): the largest listed size within it is 2×1.
        assert_eq!(fsr_code([10, 255], [4, 4], &r), code([2, 1]));
        assert_eq!(fsr_code([255, 10], [4, 4], &r), code([1, 2]));
        assert_eq!(fsr_code([0, 0], [4, 4], &r), 0);
    }

    #[test]
    fn amd_like_device_stops_at_two_by_two() {
        let r = rates(2);
        assert_eq!(fsr_code([10, 10], [2, 2], &r), code([2, 2]));
        // Even if the device claimed larger fragments, only listed sizes come out.
        assert_eq!(fsr_code([10, 10], [4, 4], &r), code([2, 2]));
        assert_eq!(fsr_code([10, 200], [2, 2], &r), code([2, 1]));
    }

    #[test]
    fn ties_and_empty_lists() {
        // Want 4×4 from {2×1, 1×2}: equal area and aspect, the wider wins.
        assert_eq!(clamp([4, 4], &[[2, 1], [1, 2]]), [2, 1]);
        assert_eq!(clamp([4, 4], &[]), [1, 1]);
        // Squarer beats wider at equal area.
        assert_eq!(clamp([4, 4], &[[4, 1], [2, 2]]), [2, 2]);
    }

    #[test]
    fn every_byte_pair_gives_a_listed_code() {
        for max in [1, 2, 4] {
            let r = rates(max);
            for x in 0..=255u8 {
                for y in (0..=255u8).step_by(7) {
                    let s = decode(fsr_code([x, y], [max, max], &r));
                    assert!(s == [1, 1] || r.contains(&s), "{x},{y} → {s:?}");
                    assert!(s[0] <= axis_size(x, max) && s[1] <= axis_size(y, max));
                }
            }
        }
    }

    #[test]
    fn merged_layers_keep_the_finer_rate() {
        let r = rates(2);
        assert_eq!(finer(code([2, 2]), code([2, 1]), &r), code([2, 1]));
        assert_eq!(finer(code([2, 1]), code([1, 2]), &r), code([1, 1]));
        assert_eq!(finer(code([4, 4]), code([4, 2]), &rates(4)), code([4, 2]));
        // Two layers of two texels: left eye coarse then fine, right eye fine then coarse.
        let density = [10, 10, 255, 255, 255, 100, 10, 10];
        let mut out = [0xff; 4];
        fill_codes(&density, 2, false, [2, 2], &r, &mut out);
        assert_eq!(out, [code([2, 2]), 0, code([1, 2]), code([2, 2])]);
        let mut merged = [0xff; 2];
        fill_codes(&density, 2, true, [2, 2], &r, &mut merged);
        assert_eq!(merged, [code([1, 2]), 0]);
    }
}
