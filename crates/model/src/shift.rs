//! Moving the fovea by shifting a fixed map, as `VK_EXT_fragment_density_map_offset` does.
//!
//! With density-map offsets the device reads the map at `x′ = x − offset`, clamped to the map
//! ([VK_EXT_fragment_density_map_offset], "Fragment Density Map Offsets"): the whole fixed map
//! moves, rings and all, and the fovea with it. fovea moves the fovea the same way wherever it
//! follows a gaze (docs/eye-tracking.md): in the maps it fills for apps, in injected maps, and in
//! the emulation of the offsets themselves. One rule for all three keeps them within a texel of
//! each other, and a shift is whole texels, so moving costs no map evaluation: on shading-rate GPUs
//! the conversion applies it while it reads, on the CPU it is a clamped copy.
//!
//! Coordinates: NDC with y up (OpenXR's, and [`crate::Fov::projection_center_ndc`]'s); texels and
//! pixels with y down (row 0 at the top, as [`crate::density::Rect`]).
//!
//! [VK_EXT_fragment_density_map_offset]: https://registry.khronos.org/vulkan/specs/latest/man/html/VK_EXT_fragment_density_map_offset.html

use crate::density::{Grid, View};

/// Where NDC point `ndc` of `view` falls in the framebuffer, in pixels (y down).
pub fn pixel_of(view: &View, ndc: [f32; 2]) -> [f32; 2] {
    let r = view.rect;
    [
        r.x as f32 + (ndc[0] + 1.0) * 0.5 * r.width as f32,
        r.y as f32 + (1.0 - ndc[1]) * 0.5 * r.height as f32,
    ]
}

/// The shift, in whole texels (x right, y down), that carries `view`'s fixed fovea (its projection
/// centre, where [`crate::density::fill`] puts it) to `centre` (NDC, y up), rounded to the nearest
/// texel.
pub fn texel_shift(grid: &Grid, view: &View, centre: [f32; 2]) -> [i32; 2] {
    let from = pixel_of(view, view.fov.projection_center_ndc());
    let to = pixel_of(view, centre);
    [0, 1].map(|i| {
        let t = grid.texel[i].max(1) as f32;
        let s = ((to[i] - from[i]) / t).round();
        if s.is_finite() {
            s as i32
        } else {
            0
        }
    })
}

/// The same shift in framebuffer pixels, a whole number of `granularity` per axis: the offset an
/// application passes to `VkRenderPassFragmentDensityMapOffsetEndInfoEXT`, which must be a multiple
/// of `fragmentDensityOffsetGranularity` (here the map's texel, so that it is exactly a shift).
pub fn pixel_offset(grid: &Grid, view: &View, centre: [f32; 2]) -> [i32; 2] {
    let s = texel_shift(grid, view, centre);
    [0, 1].map(|i| s[i].saturating_mul(grid.texel[i].max(1) as i32))
}

/// Whether a map filled for the fovea at pixel `filled` must be filled again for the fovea at
/// `now`: only once it has moved by half a texel or more on either axis, so that a gaze that
/// trembles inside a texel never costs a refill (the nearest whole-texel shift is the same).
pub fn moved_enough(grid: &Grid, filled: [f32; 2], now: [f32; 2]) -> bool {
    (0..2).any(|i| (now[i] - filled[i]).abs() >= grid.texel[i].max(1) as f32 * 0.5)
}

/// Where one view's fovea was, in framebuffer pixels, when a map was filled for it, and the
/// whole-texel shift that map holds ([`texel_shift`] then).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Filled {
    pub at: [f32; 2],
    pub shift: [i32; 2],
}

/// Whether a map whose views were filled for `held` (per view; `None`: the fixed map) must be
/// looked at again for the foveas `now` (per view, pixels; `None`: fixed foveation): where a view
/// changes between following and fixed, or its fovea [`moved_enough`]. A gaze that trembles inside
/// half a texel of where the map was filled never asks, wherever that is on the grid, so it costs
/// nothing; one that crosses a texel's edge back and forth asks at most once per half texel.
pub fn must_refill(grid: &Grid, held: &[Option<Filled>], now: &[Option<[f32; 2]>]) -> bool {
    held.iter().zip(now).any(|(h, n)| match (h, n) {
        (None, None) => false,
        (Some(h), Some(n)) => moved_enough(grid, h.at, *n),
        _ => true,
    })
}

/// The shift a map's view holds, `None` for the fixed map (no shift): two maps with the same
/// shifts hold the same bytes, so an image asked to refill for the shifts it already holds needs
/// no upload.
pub fn held_shift(f: &Option<Filled>) -> Option<[i32; 2]> {
    f.map(|f| f.shift).filter(|s| *s != [0, 0])
}

/// Writes one layer of `src` (R8G8, row-major, [`Grid::map_extent`] texels) into `dst` shifted by
/// `shift` texels inside `view`'s texels: `dst[x] = src[clamp(x − shift)]`, clamped to the texels
/// the view covers, so that side-by-side views never read each other's texels. Texels outside the
/// view are left as they are.
///
/// # Panics
/// If `src` or `dst` is not `map_extent` texels of two bytes.
pub fn shift_into(grid: &Grid, view: &View, shift: [i32; 2], src: &[u8], dst: &mut [u8]) {
    shift_texels_into::<2>(grid, view, shift, src, dst);
}

/// [`shift_into`] for one layer of shading-rate codes (R8_UINT, one byte per texel): the codes of
/// a map move exactly as its density texels do, since each code is a function of its texel alone.
///
/// # Panics
/// If `src` or `dst` is not `map_extent` texels of one byte.
pub fn shift_codes_into(grid: &Grid, view: &View, shift: [i32; 2], src: &[u8], dst: &mut [u8]) {
    shift_texels_into::<1>(grid, view, shift, src, dst);
}

/// [`shift_into`] for texels of `B` bytes.
fn shift_texels_into<const B: usize>(
    grid: &Grid,
    view: &View,
    shift: [i32; 2],
    src: &[u8],
    dst: &mut [u8],
) {
    let [mw, mh] = grid.map_extent().map(|v| v as usize);
    assert_eq!(
        src.len(),
        mw * mh * B,
        "source is {mw}x{mh} texels, {B} bytes each"
    );
    assert_eq!(dst.len(), src.len(), "destination is the source's size");
    let Some((cols, rows)) = texels_of(grid, view) else {
        return;
    };
    let pick = |i: usize, s: i32, (lo, hi): (usize, usize)| -> usize {
        (i as i64 - i64::from(s)).clamp(lo as i64, hi as i64 - 1) as usize
    };
    // Per row: the columns that read left of the view repeat its first texel, those that read
    // right of it its last, and the rest are one contiguous copy.
    let (lo, hi) = (cols.0 as i64, cols.1 as i64);
    let sx = i64::from(shift[0]);
    let head_end = (lo + sx).clamp(lo, hi) as usize;
    let tail_start = (hi + sx).clamp(lo, hi) as usize;
    for y in rows.0..rows.1 {
        let sy = pick(y, shift[1], rows);
        let (src_row, dst_row) = (
            &src[sy * mw * B..][..mw * B],
            &mut dst[y * mw * B..][..mw * B],
        );
        let mut first = [0u8; B];
        first.copy_from_slice(&src_row[cols.0 * B..][..B]);
        let mut last = [0u8; B];
        last.copy_from_slice(&src_row[(cols.1 - 1) * B..][..B]);
        for d in dst_row[cols.0 * B..head_end * B].chunks_exact_mut(B) {
            d.copy_from_slice(&first);
        }
        if head_end < tail_start {
            let from = (head_end as i64 - sx) as usize;
            let n = tail_start - head_end;
            dst_row[head_end * B..tail_start * B]
                .copy_from_slice(&src_row[from * B..(from + n) * B]);
        }
        for d in dst_row[tail_start.max(head_end) * B..cols.1 * B].chunks_exact_mut(B) {
            d.copy_from_slice(&last);
        }
    }
}

/// Where one view lies in a map of several layers: the layer it is drawn into, and its rect and
/// FOV there. Indexed by the view's index in the projection layer (the eye), as the gaze's
/// per-view centres are.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placed {
    pub layer: usize,
    pub view: View,
}

/// Writes `src` (layers of `B`-byte texels, [`Grid::map_extent`] each, one after the other) into
/// `dst` with each placed view's texels shifted by its shift (`None`: not moved, the view's texels
/// copied as they are); texels outside every placed view are copied unchanged. Views without a
/// place, or placed in a layer `src` does not have, are left out.
///
/// # Panics
/// If `dst` is not `src`'s size, or `src` is not whole layers.
pub fn shift_layers<const B: usize>(
    grid: &Grid,
    placed: &[Option<Placed>],
    shifts: &[Option<[i32; 2]>],
    src: &[u8],
    dst: &mut [u8],
) {
    let [mw, mh] = grid.map_extent().map(|v| v as usize);
    let layer = mw * mh * B;
    assert_eq!(dst.len(), src.len(), "destination is the source's size");
    assert!(
        layer > 0 && src.len() % layer == 0,
        "whole layers of {mw}x{mh} texels"
    );
    dst.copy_from_slice(src);
    for (p, s) in placed.iter().zip(shifts) {
        let (Some(p), Some(s)) = (p, s) else {
            continue;
        };
        let at = p.layer * layer;
        if at + layer > src.len() || *s == [0, 0] {
            continue;
        }
        shift_texels_into::<B>(
            grid,
            &p.view,
            *s,
            &src[at..at + layer],
            &mut dst[at..at + layer],
        );
    }
}

/// The texel columns and rows `[lo, hi)` that `view`'s rect touches on the map, or `None` when
/// it covers none.
fn texels_of(grid: &Grid, view: &View) -> Option<((usize, usize), (usize, usize))> {
    let [mw, mh] = grid.map_extent().map(|v| v as i64);
    let r = view.rect;
    let span = |start: i32, len: u32, texel: u32, max: i64| {
        let t = i64::from(texel.max(1));
        let lo = (i64::from(start).max(0) / t).min(max);
        let hi = ((i64::from(start) + i64::from(len) + t - 1) / t).clamp(0, max);
        (lo < hi).then_some((lo as usize, hi as usize))
    };
    Some((
        span(r.x, r.width, grid.texel[0], mw)?,
        span(r.y, r.height, grid.texel[1], mh)?,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::density::{decode, fill, Level, Pattern, Rect};
    use crate::Fov;

    fn quest3_left() -> View {
        View {
            fov: Fov::from_tangents(1.376382, 0.839100, 0.965689, 1.428148),
            rect: Rect {
                x: 0,
                y: 0,
                width: 2064,
                height: 2240,
            },
            visible: None,
        }
    }

    fn map(grid: &Grid, view: &View, level: Level) -> Vec<u8> {
        let [w, h] = grid.map_extent();
        let mut out = vec![0; (w * h * 2) as usize];
        let pattern = Pattern {
            level,
            vertical_offset_deg: 0.0,
        };
        fill(grid, std::slice::from_ref(view), pattern, &mut out);
        out
    }

    /// The centre, in texels, of the texels that shade at full rate on both axes: the fovea a user
    /// would see.
    fn fovea(grid: &Grid, map: &[u8]) -> [f32; 2] {
        let mw = grid.map_extent()[0] as usize;
        let (mut sum, mut n) = ([0.0f32; 2], 0.0f32);
        for (i, t) in map.chunks_exact(2).enumerate() {
            if decode(t[0]) == 1 && decode(t[1]) == 1 {
                sum[0] += (i % mw) as f32 + 0.5;
                sum[1] += (i / mw) as f32 + 0.5;
                n += 1.0;
            }
        }
        assert!(n > 0.0, "no full-rate texel");
        sum.map(|s| s / n)
    }

    #[test]
    fn no_shift_copies_the_map() {
        let grid = Grid::new([2064, 2240], [16, 16]);
        let view = quest3_left();
        let src = map(&grid, &view, Level::High);
        let shift = texel_shift(&grid, &view, view.fov.projection_center_ndc());
        assert_eq!(shift, [0, 0]);
        let mut dst = vec![0; src.len()];
        shift_into(&grid, &view, shift, &src, &mut dst);
        assert_eq!(dst, src);
    }

    #[test]
    fn the_fovea_lands_on_the_gaze_within_a_texel() {
        let grid = Grid::new([2064, 2240], [16, 16]);
        let view = quest3_left();
        let src = map(&grid, &view, Level::High);
        let fixed = fovea(&grid, &src);
        let axis = pixel_of(&view, view.fov.projection_center_ndc()).map(|p| p / 16.0);
        for i in 0..2 {
            assert!(
                (fixed[i] - axis[i]).abs() <= 0.5,
                "fixed fovea {fixed:?}, axis {axis:?}"
            );
        }
        for centre in [[0.3, 0.2], [-0.5, -0.4], [0.0, 0.0], [0.15, -0.6]] {
            let shift = texel_shift(&grid, &view, centre);
            let mut dst = vec![0; src.len()];
            shift_into(&grid, &view, shift, &src, &mut dst);
            let moved = fovea(&grid, &dst);
            let want = pixel_of(&view, centre).map(|p| p / 16.0);
            for i in 0..2 {
                // The full-rate disc stays inside the view, so it moves by the shift exactly...
                assert!(
                    (moved[i] - (fixed[i] + shift[i] as f32)).abs() < 1e-3,
                    "{centre:?} axis {i}: {moved:?} vs {fixed:?} + {shift:?}"
                );
                // ...and lands within a texel of the gaze (half for rounding the shift, half for
                // the fixed disc's own place on the grid).
                assert!(
                    (moved[i] - want[i]).abs() <= 1.0,
                    "{centre:?} axis {i}: fovea at {moved:?}, gaze at {want:?}"
                );
            }
        }
    }

    #[test]
    fn edges_clamp_and_other_views_are_left_alone() {
        // Two side-by-side views of 64×32 pixels on 16-pixel texels: 4×2 texels each.
        let grid = Grid::new([128, 32], [16, 16]);
        let fov = Fov::from_tangents(1.0, 1.0, 1.0, 1.0);
        let left = View {
            fov,
            rect: Rect {
                x: 0,
                y: 0,
                width: 64,
                height: 32,
            },
            visible: None,
        };
        let src: Vec<u8> = (0..8 * 2 * 2).map(|i| i as u8).collect();
        let mut dst = vec![0xee; src.len()];
        shift_into(&grid, &left, [2, 0], &src, &mut dst);
        let texel = |m: &[u8], x: usize, y: usize| m[(y * 8 + x) * 2];
        for y in 0..2 {
            // x′ = x − 2, clamped to the view's columns 0..4.
            assert_eq!(texel(&dst, 0, y), texel(&src, 0, y));
            assert_eq!(texel(&dst, 1, y), texel(&src, 0, y));
            assert_eq!(texel(&dst, 2, y), texel(&src, 0, y));
            assert_eq!(texel(&dst, 3, y), texel(&src, 1, y));
            for x in 4..8 {
                assert_eq!(texel(&dst, x, y), 0xee, "the right view's texel {x},{y}");
            }
        }
        let mut dst = vec![0xee; src.len()];
        shift_into(&grid, &left, [-9, 5], &src, &mut dst);
        for x in 0..4 {
            assert_eq!(
                texel(&dst, x, 0),
                texel(&src, 3, 0),
                "far shifts clamp to the last texel"
            );
            assert_eq!(texel(&dst, x, 1), texel(&src, 3, 0));
        }
    }

    #[test]
    fn row_copies_match_the_lookup_texel_by_texel() {
        let grid = Grid::new([100, 40], [8, 8]);
        let fov = Fov::from_tangents(1.0, 1.2, 0.9, 1.1);
        let view = View {
            fov,
            rect: Rect {
                x: 20,
                y: 4,
                width: 61,
                height: 30,
            },
            visible: None,
        };
        let [mw, mh] = grid.map_extent().map(|v| v as usize);
        let src: Vec<u8> = (0..mw * mh * 2).map(|i| (i * 7 % 251) as u8).collect();
        let (cols, rows) = texels_of(&grid, &view).expect("covered");
        for sx in -12..=12 {
            for sy in [-9, -1, 0, 2, 7] {
                let mut dst = vec![0xee; src.len()];
                shift_into(&grid, &view, [sx, sy], &src, &mut dst);
                for y in 0..mh {
                    for x in 0..mw {
                        let inside = (cols.0..cols.1).contains(&x) && (rows.0..rows.1).contains(&y);
                        let want = if inside {
                            let rx = (x as i32 - sx).clamp(cols.0 as i32, cols.1 as i32 - 1);
                            let ry = (y as i32 - sy).clamp(rows.0 as i32, rows.1 as i32 - 1);
                            let i = (ry as usize * mw + rx as usize) * 2;
                            [src[i], src[i + 1]]
                        } else {
                            [0xee, 0xee]
                        };
                        let i = (y * mw + x) * 2;
                        assert_eq!([dst[i], dst[i + 1]], want, "shift {sx},{sy} texel {x},{y}");
                    }
                }
            }
        }
    }

    #[test]
    fn bookkeeping_refills_once_per_half_texel_and_on_following_or_not() {
        let grid = Grid::new([2064, 2240], [16, 16]);
        let held = |at: [f32; 2]| Some(Filled { at, shift: [0, 0] });
        // Trembling around where the map was filled, even across a texel's edge: nothing.
        let filled = [held([103.9, 200.0]), None];
        for x in [100.0, 104.1, 96.5, 111.8] {
            assert!(
                !must_refill(&grid, &filled, &[Some([x, 201.0]), None]),
                "{x}"
            );
        }
        assert!(must_refill(&grid, &filled, &[Some([111.9, 200.0]), None]));
        assert!(
            must_refill(&grid, &filled, &[None, None]),
            "back to fixed foveation"
        );
        assert!(
            must_refill(&grid, &filled, &[Some([103.9, 200.0]), Some([0.0, 0.0])]),
            "the second view starts following"
        );
        assert!(!must_refill(&grid, &[None, None], &[None, None]));
        assert_eq!(
            held_shift(&held([0.0, 0.0])),
            None,
            "no shift is the fixed map"
        );
        let moved = Some(Filled {
            at: [0.0, 0.0],
            shift: [2, -1],
        });
        assert_eq!(held_shift(&moved), Some([2, -1]));
    }

    #[test]
    fn layers_shift_per_view_and_codes_as_density() {
        // Two views side by side in layer 0 and one view over the whole of layer 1.
        let grid = Grid::new([128, 32], [16, 16]);
        let fov = Fov::from_tangents(1.0, 1.0, 1.0, 1.0);
        let rect = |x, width| Rect {
            x,
            y: 0,
            width,
            height: 32,
        };
        let place = |layer, r| {
            Some(Placed {
                layer,
                view: View {
                    fov,
                    rect: r,
                    visible: None,
                },
            })
        };
        let placed = [
            place(0, rect(0, 64)),
            place(0, rect(64, 64)),
            place(1, rect(0, 128)),
        ];
        let texels = 8 * 2;
        let src: Vec<u8> = (0..texels * 2).map(|i| i as u8).collect();
        let mut dst = vec![0; src.len()];
        shift_layers::<1>(
            &grid,
            &placed,
            &[Some([1, 0]), None, Some([-2, 0])],
            &src,
            &mut dst,
        );
        let code = |m: &[u8], layer: usize, x: usize, y: usize| m[layer * texels + y * 8 + x];
        for y in 0..2 {
            assert_eq!(code(&dst, 0, 0, y), code(&src, 0, 0, y));
            assert_eq!(
                code(&dst, 0, 3, y),
                code(&src, 0, 2, y),
                "the left view moved right"
            );
            for x in 4..8 {
                assert_eq!(
                    code(&dst, 0, x, y),
                    code(&src, 0, x, y),
                    "the right view stays"
                );
            }
            assert_eq!(
                code(&dst, 1, 0, y),
                code(&src, 1, 2, y),
                "layer 1 moved left"
            );
            assert_eq!(code(&dst, 1, 7, y), code(&src, 1, 7, y));
        }
        // Density (two bytes a texel) shifted, then converted, is the conversion shifted.
        let view = quest3_left();
        let grid = Grid::new([2064, 2240], [16, 16]);
        let fixed = map(&grid, &view, Level::High);
        let n = fixed.len() / 2;
        let rates = [[1, 1], [1, 2], [2, 1], [2, 2], [2, 4], [4, 2], [4, 4]];
        let convert = |d: &[u8]| {
            let mut c = vec![0; n];
            crate::shading_rate::fill_codes(d, n, false, [4, 4], &rates, &mut c);
            c
        };
        let placed = [Some(Placed { layer: 0, view })];
        let shift = [Some(texel_shift(&grid, &view, [0.4, -0.3]))];
        let mut moved = vec![0; fixed.len()];
        shift_layers::<2>(&grid, &placed, &shift, &fixed, &mut moved);
        let mut moved_codes = vec![0; n];
        shift_layers::<1>(&grid, &placed, &shift, &convert(&fixed), &mut moved_codes);
        assert_eq!(moved_codes, convert(&moved));
        assert_ne!(moved, fixed, "it moved");
    }

    #[test]
    fn refills_wait_for_half_a_texel() {
        let grid = Grid::new([2064, 2240], [16, 16]);
        assert!(!moved_enough(&grid, [100.0, 100.0], [107.9, 92.1]));
        assert!(moved_enough(&grid, [100.0, 100.0], [108.0, 100.0]));
        assert!(moved_enough(&grid, [100.0, 100.0], [100.0, 91.5]));
    }

    #[test]
    fn offsets_are_whole_texels_and_bad_centres_do_not_move() {
        let grid = Grid::new([2064, 2240], [16, 16]);
        let view = quest3_left();
        let o = pixel_offset(&grid, &view, [0.5, 0.5]);
        assert!(o.iter().all(|v| v % 16 == 0), "{o:?}");
        assert!(o[0] > 0 && o[1] < 0, "right and up: {o:?}");
        assert_eq!(texel_shift(&grid, &view, [f32::NAN, f32::INFINITY]), [0, 0]);
    }
}
