//! The conversion's compute shader ([`crate::vk::convert`]): its SPIR-V, built from
//! `shaders/convert.comp` by `shaders/build.sh`, its push constants, and the device's 4×4 table of
//! shading-rate codes built from the model itself.

use crate::bridge::FdmEmulation;

/// The compute shader, built from `shaders/convert.comp` by `shaders/build.sh`.
pub static SHADER: &[u8] = include_bytes!("../shaders/convert.comp.spv");

/// `local_size_x` of the shader; each invocation writes four codes.
pub const GROUP: u32 = 64;
/// Descriptor sets per pool; a new pool is made when one is full.
pub const POOL_SETS: u32 = 64;
/// Density layers the shader shifts by their own offset (`MAX_SHIFTS`); layers from here on are
/// not shifted.
pub const MAX_SHIFTS: usize = 16;
/// Bytes of the shader's shifts (`ivec2 shifts[MAX_SHIFTS]`).
pub const SHIFT_BYTES: u64 = (MAX_SHIFTS * 8) as u64;

/// A density-map offset in framebuffer pixels as the shader's whole-texel shift of one axis: the
/// specification's lookup evaluated at the centre of each shading-rate texel, where the offset
/// fetches texel `floor(i + 1/2 - offset / texel)` for texel `i`
/// (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#fragmentdensitymapops-fetch-density-value>).
/// An offset that is a multiple of the texel (of the granularity the layer reports) shifts by
/// exactly `offset / texel`; another, which is the application's error, by the nearest whole
/// texel (halves toward the smaller shift).
pub fn texel_shift(offset: i32, texel: u32) -> i32 {
    let t = i64::from(texel.max(1));
    let s = (2 * i64::from(offset) + t - 1).div_euclid(2 * t);
    s.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
}

/// The push constants, as the shader declares them.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Push {
    pub width: u32,
    pub height: u32,
    pub layers: u32,
    pub merged: u32,
    pub table: [u32; 4],
}

impl Push {
    pub fn bytes(&self) -> [u8; 32] {
        let mut out = [0; 32];
        let words = [
            self.width,
            self.height,
            self.layers,
            self.merged,
            self.table[0],
            self.table[1],
            self.table[2],
            self.table[3],
        ];
        for (o, w) in out.chunks_exact_mut(4).zip(words) {
            o.copy_from_slice(&w.to_ne_bytes());
        }
        out
    }
}

/// A density byte that wants a fragment edge of `2^l` (`fovea_model::shading_rate::axis_size`).
pub const fn byte_for_log2(l: usize) -> u8 {
    [255, 127, 63, 63][l]
}

/// The shader's table: entry `w * 4 + h` (as byte `i % 4` of word `i / 4`) is the code the model
/// gives a texel that wants a `2^w × 2^h` fragment on this device.
pub fn table(fdm: &FdmEmulation) -> [u32; 4] {
    let mut t = [0u32; 4];
    for w in 0..4 {
        for h in 0..4 {
            let code = fovea_model::shading_rate::fsr_code(
                [byte_for_log2(w), byte_for_log2(h)],
                fdm.max_fragment,
                &fdm.rates,
            );
            let i = w * 4 + h;
            t[i / 4] |= u32::from(code) << ((i % 4) * 8);
        }
    }
    t
}

/// The shader's algorithm on the CPU (one code per output texel): what the tests hold against the
/// model, so the table and the merge order are checked without a GPU.
#[cfg(test)]
pub fn shader_on_cpu(density: &[u8], push: &Push, shifts: &[[i32; 2]]) -> Vec<u8> {
    let table_at = |w: u32, h: u32| {
        let i = w * 4 + h;
        ((push.table[(i >> 2) as usize] >> ((i & 3) * 8)) & 0xff) as u8
    };
    let axis = |b: u8| match b {
        0 | 128..=255 => 0,
        64..=127 => 1,
        _ => 2,
    };
    let texels = (push.width * push.height) as usize;
    let code_of = |t: usize, l: usize| {
        let s = shifts.get(l).copied().unwrap_or([0, 0]);
        let x = (t as i64 % i64::from(push.width) - i64::from(s[0]))
            .clamp(0, i64::from(push.width) - 1);
        let y = (t as i64 / i64::from(push.width) - i64::from(s[1]))
            .clamp(0, i64::from(push.height) - 1);
        let t = (y * i64::from(push.width) + x) as usize;
        let i = (l * texels + t) * 2;
        table_at(axis(density[i]), axis(density[i + 1]))
    };
    let total = if push.merged != 0 {
        texels
    } else {
        texels * push.layers as usize
    };
    (0..total)
        .map(|j| {
            if push.merged != 0 {
                let mut c = code_of(j, 0);
                for l in 1..push.layers as usize {
                    let n = code_of(j, l);
                    c = table_at(
                        u32::from(((c >> 2) & 3).min((n >> 2) & 3)),
                        u32::from((c & 3).min(n & 3)),
                    );
                }
                c
            } else {
                code_of(j % texels, j / texels)
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rates(max: u32, aspect: u32) -> Vec<[u32; 2]> {
        let mut out = Vec::new();
        for w in [4, 2, 1] {
            for h in [4, 2, 1] {
                if w <= max && h <= max && w <= aspect * h && h <= aspect * w {
                    out.push([w, h]);
                }
            }
        }
        out
    }

    fn fdm(max: [u32; 2], rates: Vec<[u32; 2]>, layered: bool) -> FdmEmulation {
        FdmEmulation {
            texel: [16, 16],
            layered,
            max_fragment: max,
            rates,
            non_trivial_combiners: true,
        }
    }

    /// Every byte pair, in one or two layers, merged or not, on several device profiles: the
    /// shader's algorithm gives the model's codes.
    #[test]
    fn shader_algorithm_matches_the_model() {
        let profiles = [
            fdm([4, 4], rates(4, 4), true),
            fdm([2, 2], rates(2, 2), false),
            fdm([4, 4], rates(4, 2), false),
            fdm([2, 4], vec![[1, 2], [2, 1], [2, 2], [1, 4]], true),
        ];
        // 256 × 256 pairs in a 256-wide map; the second layer is the first shifted, so the merge
        // meets every kind of pair.
        let width = 256u32;
        let height = 256u32;
        let texels = (width * height) as usize;
        let mut density = vec![0u8; texels * 4];
        for t in 0..texels {
            density[t * 2] = (t % 256) as u8;
            density[t * 2 + 1] = (t / 256) as u8;
            density[(texels + t) * 2] = (t / 256) as u8;
            density[(texels + t) * 2 + 1] = ((t * 7) % 256) as u8;
        }
        for f in &profiles {
            for (layers, merged) in [(1, false), (2, false), (2, true)] {
                let push = Push {
                    width,
                    height,
                    layers,
                    merged: u32::from(merged),
                    table: table(f),
                };
                let map = &density[..texels * 2 * layers as usize];
                let mut want = vec![
                    0u8;
                    if merged {
                        texels
                    } else {
                        texels * layers as usize
                    }
                ];
                fovea_model::shading_rate::fill_codes(
                    map,
                    texels,
                    merged,
                    f.max_fragment,
                    &f.rates,
                    &mut want,
                );
                assert!(
                    shader_on_cpu(map, &push, &[]) == want,
                    "profile {:?}, {layers} layers, merged {merged}",
                    f.rates
                );
            }
        }
    }

    /// Shifts move each layer's lookup by whole texels, clamped to the map: texel (x, y) of a
    /// layer shifted by (sx, sy) holds what texel (x - sx, y - sy) holds unshifted, the nearest
    /// edge texel where that lies outside.
    #[test]
    fn shifts_move_each_layer_and_clamp_at_the_edges() {
        let f = fdm([4, 4], rates(4, 4), true);
        let (width, height) = (5u32, 4u32);
        let texels = (width * height) as usize;
        let levels = [255u8, 127, 63];
        let mut density = vec![0u8; texels * 4];
        for t in 0..texels * 2 {
            density[t * 2] = levels[t % 3];
            density[t * 2 + 1] = levels[(t / 3) % 3];
        }
        let push = Push {
            width,
            height,
            layers: 2,
            merged: 0,
            table: table(&f),
        };
        let still = shader_on_cpu(&density, &push, &[]);
        let shifts = [[2, -1], [-7, 3]];
        let moved = shader_on_cpu(&density, &push, &shifts);
        for (l, shift) in shifts.iter().enumerate() {
            for y in 0..height as i32 {
                for x in 0..width as i32 {
                    let sx = (x - shift[0]).clamp(0, width as i32 - 1);
                    let sy = (y - shift[1]).clamp(0, height as i32 - 1);
                    let at = |x: i32, y: i32| l * texels + (y * width as i32 + x) as usize;
                    assert_eq!(moved[at(x, y)], still[at(sx, sy)], "layer {l} ({x}, {y})");
                }
            }
        }
        assert_ne!(moved, still, "a pattern that tests nothing");
    }

    /// Offsets in pixels become whole-texel shifts: multiples of the texel exactly, others by the
    /// specification's lookup at the texel's centre.
    #[test]
    fn offsets_become_texel_shifts() {
        for (offset, want) in [
            (0, 0),
            (16, 1),
            (-16, -1),
            (48, 3),
            (-32, -2),
            (8, 0),
            (9, 1),
            (-8, -1),
            (-9, -1),
            (-7, 0),
            (i32::MIN, -(1 << 27)),
        ] {
            assert_eq!(texel_shift(offset, 16), want, "offset {offset}");
        }
        assert_eq!(texel_shift(24, 8), 3);
    }

    #[test]
    fn push_constants_are_the_shaders_layout() {
        let p = Push {
            width: 1,
            height: 2,
            layers: 3,
            merged: 1,
            table: [5, 6, 7, 8],
        };
        let b = p.bytes();
        assert_eq!(b.len(), std::mem::size_of::<Push>());
        assert_eq!(u32::from_ne_bytes(b[8..12].try_into().unwrap()), 3);
        assert_eq!(u32::from_ne_bytes(b[28..32].try_into().unwrap()), 8);
    }

    /// The checked-in SPIR-V is what `shaders/build.sh` makes of the checked-in source.
    #[test]
    fn shader_matches_its_source() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/vk/shaders");
        fovea_harness::assert_spirv_built_from(&dir.join("convert.comp"), &[], SHADER);
    }
}
