//! Blockiness, measured from pixels read back: how much of a region is made of blocks whose
//! pixels are all identical, as coarse fragments leave them on a GPU with shading-rate
//! attachments (one shaded value written to every pixel of a fragment).
//!
//! The measure is what shows, from frames alone, that a periphery is coarse (at HIGH nearly every
//! 4×4 block of a textured periphery is uniform, at full rate nearly none) and, once a layer
//! smooths coarse fragments (issue 30's reconstruction), that they are gone; the fovea is compared
//! with the full-rate frame pixel for pixel instead. `scripts/perceptual.py` computes the same
//! share (docs/measurements.md).

/// Of the `block`×`block` blocks of an image (`size` pixels, `bpp` bytes a pixel, rows top to
/// bottom, blocks aligned to the image's origin, partial blocks at the right and bottom edges
/// left out) whose top-left pixel lies where `inside(x, y)` holds: the share whose pixels are
/// all identical. `None` where no block lies inside.
pub fn uniform_share(
    pixels: &[u8],
    size: [u32; 2],
    bpp: usize,
    block: u32,
    inside: impl Fn(u32, u32) -> bool,
) -> Option<f64> {
    let (uniform, blocks) = uniform_blocks(pixels, size, bpp, block, inside);
    (blocks > 0).then(|| uniform as f64 / blocks as f64)
}

/// As [`uniform_share`]: (uniform blocks, blocks).
pub fn uniform_blocks(
    pixels: &[u8],
    size: [u32; 2],
    bpp: usize,
    block: u32,
    inside: impl Fn(u32, u32) -> bool,
) -> (usize, usize) {
    let [w, h] = size;
    let block = block.max(1);
    let row = w as usize * bpp;
    let at = |x: u32, y: u32| {
        let i = y as usize * row + x as usize * bpp;
        pixels.get(i..i + bpp)
    };
    let (mut uniform, mut blocks) = (0, 0);
    for by in (0..h.saturating_sub(block - 1)).step_by(block as usize) {
        for bx in (0..w.saturating_sub(block - 1)).step_by(block as usize) {
            if !inside(bx, by) {
                continue;
            }
            let Some(first) = at(bx, by) else { continue };
            blocks += 1;
            let same = (by..by + block)
                .all(|y| (bx..bx + block).all(|x| at(x, y).is_some_and(|p| p == first)));
            if same {
                uniform += 1;
            }
        }
    }
    (uniform, blocks)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_uniform_blocks_inside_the_region() {
        // 8×4, one byte a pixel: the left 4×4 block uniform, the right one not.
        let mut p = vec![7u8; 32];
        p[8 + 6] = 1;
        assert_eq!(uniform_blocks(&p, [8, 4], 1, 4, |_, _| true), (1, 2));
        assert_eq!(uniform_share(&p, [8, 4], 1, 4, |x, _| x >= 4), Some(0.0));
        assert_eq!(uniform_share(&p, [8, 4], 1, 4, |x, _| x < 4), Some(1.0));
        assert_eq!(uniform_share(&p, [8, 4], 1, 4, |_, _| false), None);
        // Partial blocks are left out: 8×4 in 3×3 blocks has two whole ones.
        assert_eq!(uniform_blocks(&p, [8, 4], 1, 3, |_, _| true).1, 2);
    }
}
