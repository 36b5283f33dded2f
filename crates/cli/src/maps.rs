//! `fovea maps`: PNGs of the resolution multiplier maps, coloured as Meta draws them.
//!
//! Each pixel of the eye buffer (the headset's recommended size, or `--size`) gets the colour of the fraction of
//! pixels its density-map texel shades: white full rate, red 1/2, green 1/4, blue 1/8, magenta 1/16,
//! black not shown (the Quest fixed foveated rendering page's images). A black cross marks the fovea
//! (the projection centre, moved by verticalOffset) and a legend strip runs along the bottom.

use std::path::Path;

use fovea_model::density::{decode, fill, Pattern};

use crate::args::{Eye, MapsArgs};
use crate::target::Target;

/// Colour per shaded fraction `1/area`; `None` for areas the legend does not name.
fn colour(area: u32) -> [u8; 3] {
    match area {
        1 => [255, 255, 255],
        2 => [230, 30, 30],
        4 => [40, 190, 60],
        8 => [40, 80, 230],
        16 => [220, 40, 220],
        _ => [0, 0, 0],
    }
}

/// The legend: `(label, area)`; area 0 is "not shown".
const LEGEND: [(&str, u32); 6] = [
    ("1", 1),
    ("1/2", 2),
    ("1/4", 4),
    ("1/8", 8),
    ("1/16", 16),
    ("0", 0),
];

/// A 3×5 bitmap font for the legend's characters, rows top to bottom, bit 2 = left column.
fn glyph(c: char) -> [u8; 5] {
    match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '4' => [5, 5, 7, 1, 1],
        '6' => [7, 4, 7, 5, 7],
        '8' => [7, 5, 7, 5, 7],
        '/' => [1, 1, 2, 4, 4],
        _ => [0; 5],
    }
}

pub(crate) struct Image {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

impl Image {
    fn rect(&mut self, x0: usize, y0: usize, w: usize, h: usize, c: [u8; 3]) {
        for y in y0..(y0 + h).min(self.height) {
            for x in x0..(x0 + w).min(self.width) {
                self.rgb[(y * self.width + x) * 3..][..3].copy_from_slice(&c);
            }
        }
    }

    fn text(&mut self, x0: usize, y0: usize, scale: usize, s: &str, c: [u8; 3]) {
        for (i, ch) in s.chars().enumerate() {
            for (row, bits) in glyph(ch).iter().enumerate() {
                for col in 0..3 {
                    if bits & (4 >> col) != 0 {
                        let x = x0 + (i * 4 + col) * scale;
                        self.rect(x, y0 + row * scale, scale, scale, c);
                    }
                }
            }
        }
    }

    pub(crate) fn write_png(&self, path: &Path) -> Result<(), String> {
        let file = std::fs::File::create(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let mut enc = png::Encoder::new(
            std::io::BufWriter::new(file),
            self.width as u32,
            self.height as u32,
        );
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Best);
        enc.write_header()
            .and_then(|mut w| w.write_image_data(&self.rgb))
            .map_err(|e| format!("{}: {e}", path.display()))
    }
}

/// Renders one eye's map at full eye-buffer size with the legend below.
pub(crate) fn render(target: &Target, eye: usize, texel: u32, pattern: Pattern) -> Image {
    let (grid, view) = target.eye_view(eye, texel);
    let [mw, mh] = grid.map_extent().map(|v| v as usize);
    let mut map = vec![0; mw * mh * 2];
    fill(&grid, &[view], pattern, &mut map);
    let [w, hh] = grid.extent.map(|v| v as usize);
    let legend_h = (hh / 20).max(48);
    let mut img = Image {
        width: w,
        height: hh + legend_h,
        rgb: vec![0; w * (hh + legend_h) * 3],
    };
    let t = texel as usize;
    for y in 0..hh {
        for x in 0..w {
            let i = ((y / t) * mw + x / t) * 2;
            let area = decode(map[i]) * decode(map[i + 1]);
            img.rgb[(y * w + x) * 3..][..3].copy_from_slice(&colour(area));
        }
    }
    // The fovea: straight ahead, turned by the pattern's vertical offset.
    let [left, right, up, down] = target.fovs[eye].tangents();
    let t0 = f64::from(pattern.effective_offset_deg()).to_radians().tan();
    let fx = left / (left + right) * w as f64;
    let fy = (up - t0) / (up + down) * hh as f64;
    let (arm, thick) = (w / 40, (w / 400).max(2));
    if fx >= 0.0 && fy >= 0.0 && (fy as usize) < hh {
        let (cx, cy) = (fx as usize, fy as usize);
        img.rect(
            cx.saturating_sub(arm),
            cy.saturating_sub(thick / 2),
            2 * arm,
            thick,
            [0; 3],
        );
        img.rect(
            cx.saturating_sub(thick / 2),
            cy.saturating_sub(arm),
            thick,
            2 * arm,
            [0; 3],
        );
    }
    let cell = w / LEGEND.len();
    let scale = (legend_h / 8).max(1);
    for (i, (label, area)) in LEGEND.iter().enumerate() {
        let c = colour(*area);
        img.rect(i * cell, hh, cell, legend_h, c);
        let ink = if *area == 0 { [255; 3] } else { [0; 3] };
        img.text(
            i * cell + scale * 2,
            hh + (legend_h - 5 * scale) / 2,
            scale,
            label,
            ink,
        );
    }
    img
}

pub fn run(args: &MapsArgs) -> Result<(), String> {
    let target = Target::from_args(&args.target);
    let texel = args.texel.value;
    let eyes: &[(usize, &str)] = match args.eye {
        Eye::Left => &[(0, "left")],
        Eye::Right => &[(1, "right")],
        Eye::Both => &[(0, "left"), (1, "right")],
    };
    let out = args.out.as_path();
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let pattern = Pattern {
        level: args.level,
        vertical_offset_deg: args.vertical_offset,
    };
    if let Some(note) = target.sizing_note() {
        println!("note: {}: {note}", target.name);
    }
    for &(eye, name) in eyes {
        let path = out.join(format!("{}_{}_{name}.png", target.id, args.level.name()));
        render(&target, eye, texel, pattern).write_png(&path)?;
        println!("{}", path.display());
    }
    Ok(())
}
