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

/// Writes one layer of `src` (R8G8, row-major, [`Grid::map_extent`] texels) into `dst` shifted by
/// `shift` texels inside `view`'s texels: `dst[x] = src[clamp(x − shift)]`, clamped to the texels
/// the view covers, so that side-by-side views never read each other's texels. Texels outside the
/// view are left as they are.
///
/// # Panics
/// If `src` or `dst` is not `map_extent` texels of two bytes.
pub fn shift_into(grid: &Grid, view: &View, shift: [i32; 2], src: &[u8], dst: &mut [u8]) {
    let [mw, mh] = grid.map_extent().map(|v| v as usize);
    assert_eq!(
        src.len(),
        mw * mh * 2,
        "source is {mw}x{mh} texels, 2 bytes each"
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
            &src[sy * mw * 2..][..mw * 2],
            &mut dst[y * mw * 2..][..mw * 2],
        );
        let texel = |x: usize| [src_row[x * 2], src_row[x * 2 + 1]];
        let first = texel(cols.0);
        let last = texel(cols.1 - 1);
        for d in dst_row[cols.0 * 2..head_end * 2].chunks_exact_mut(2) {
            d.copy_from_slice(&first);
        }
        if head_end < tail_start {
            let from = (head_end as i64 - sx) as usize;
            let n = tail_start - head_end;
            dst_row[head_end * 2..tail_start * 2]
                .copy_from_slice(&src_row[from * 2..(from + n) * 2]);
        }
        for d in dst_row[tail_start.max(head_end) * 2..cols.1 * 2].chunks_exact_mut(2) {
            d.copy_from_slice(&last);
        }
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
