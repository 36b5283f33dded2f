//! What the demo says about the frames it read back: for each frame of the left eye, where the
//! scripted gaze was, where the density map read back with it put the fovea, and how coarse the
//! pixels are in each zone of that map: the share of 4×4 pixel blocks whose 16 pixels are
//! identical (what a 4×4 fragment leaves; the room is textured down to the pixel, so at full rate
//! few are). The same measure as `fovea_vkdouble::blocks::uniform_share` and
//! `scripts/perceptual.py`. With `--compare`, each frame of the two runs side by side.

use std::path::{Path, PathBuf};

use fovea_harness::sim::gaze_script::GazeScript;

/// A PNG as the example writes it: width, height, channels (3 for maps, 4 for frames), rows top to
/// bottom.
pub(super) struct Image {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<u8>,
}

pub(super) fn read_png(path: &Path) -> Result<Image, String> {
    let file = std::fs::File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut reader = png::Decoder::new(file)
        .read_info()
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let mut data = vec![0; reader.output_buffer_size()];
    let info = reader
        .next_frame(&mut data)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    if info.bit_depth != png::BitDepth::Eight {
        return Err(format!("{}: not 8 bits a channel", path.display()));
    }
    data.truncate(info.buffer_size());
    Ok(Image {
        width: info.width as usize,
        height: info.height as usize,
        channels: info.color_type.samples(),
        data,
    })
}

fn write_png(path: &Path, image: &Image) -> Result<(), String> {
    let file = std::fs::File::create(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut encoder = png::Encoder::new(
        std::io::BufWriter::new(file),
        image.width as u32,
        image.height as u32,
    );
    encoder.set_color(match image.channels {
        3 => png::ColorType::Rgb,
        _ => png::ColorType::Rgba,
    });
    encoder.set_depth(png::BitDepth::Eight);
    encoder
        .write_header()
        .and_then(|mut w| w.write_image_data(&image.data))
        .map_err(|e| format!("{}: {e}", path.display()))
}

/// Of the 4×4 blocks (aligned to the image's origin, as fragments are) whose top-left pixel lies
/// in a map texel for which `zone` holds: (uniform blocks, blocks).
fn uniform_4x4(
    frame: &Image,
    texel: usize,
    map: &Image,
    zone: impl Fn(u8, u8) -> bool,
) -> (u32, u32) {
    let (mut uniform, mut blocks) = (0, 0);
    let c = frame.channels;
    let px = |x: usize, y: usize| &frame.data[(y * frame.width + x) * c..][..3];
    for by in (0..frame.height / 4 * 4).step_by(4) {
        for bx in (0..frame.width / 4 * 4).step_by(4) {
            let (tx, ty) = (bx / texel, by / texel);
            if tx >= map.width || ty >= map.height {
                continue;
            }
            let t = &map.data[(ty * map.width + tx) * map.channels..];
            if !zone(t[0], t[1]) {
                continue;
            }
            blocks += 1;
            let first = px(bx, by);
            uniform += u32::from((0..16).all(|i| px(bx + i % 4, by + i / 4) == first));
        }
    }
    (uniform, blocks)
}

/// A map texel's density (red horizontal, green vertical; 255 full rate) asks for full rate.
fn full_rate(r: u8, g: u8) -> bool {
    r == 255 && g == 255
}

/// A map texel asks for a quarter of the resolution or less on both axes (4×4 fragments).
fn quarter(r: u8, g: u8) -> bool {
    r <= 64 && g <= 64
}

/// The centre of the map's full-rate texels in frame pixels, where under half of the map is full
/// rate (else there is no fovea to place: level NONE).
fn fovea_centre(map: &Image, texel: usize) -> Option<[f64; 2]> {
    let (mut n, mut sx, mut sy) = (0usize, 0.0, 0.0);
    for (i, t) in map.data.chunks_exact(map.channels).enumerate() {
        if full_rate(t[0], t[1]) {
            n += 1;
            sx += ((i % map.width) as f64 + 0.5) * texel as f64;
            sy += ((i / map.width) as f64 + 0.5) * texel as f64;
        }
    }
    (n > 0 && 2 * n < map.width * map.height).then(|| [sx / n as f64, sy / n as f64])
}

/// The left eye's frames in `dir` (`fNNNNN_LEVEL_left.png`), by frame number.
pub(super) fn left_frames(dir: &Path) -> Vec<(u64, PathBuf)> {
    let mut found: Vec<(u64, PathBuf)> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter_map(|p| {
            let name = p.file_name()?.to_str()?;
            if !name.ends_with("_left.png") || name.contains("_density_") {
                return None;
            }
            let frame = name.strip_prefix('f')?.split('_').next()?.parse().ok()?;
            Some((frame, p))
        })
        .collect();
    found.sort();
    found
}

/// The density map read back with a frame (`..._left.png` → `..._density_left.png`).
fn map_of(frame: &Path) -> PathBuf {
    let name = frame
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or_default();
    frame.with_file_name(name.replace("_left.png", "_density_left.png"))
}

/// One line per frame of the left eye in `dir`: the display time (`seconds_at(frame)`), where
/// `gaze` looked then, where the map put the fovea, and the uniform 4×4 blocks per zone.
pub(super) fn summary(
    dir: &Path,
    gaze: &GazeScript,
    seconds_at: impl Fn(u64) -> f64,
) -> Result<Vec<String>, String> {
    let mut lines = Vec::new();
    for (frame, path) in left_frames(dir) {
        let image = read_png(&path)?;
        let t = seconds_at(frame);
        let looked = match gaze.eye_at((t * 1e9) as i64) {
            Some([yaw, pitch]) => format!("gaze {yaw:+.1}°,{pitch:+.1}°"),
            None => "eyes closed".to_owned(),
        };
        let mut line = format!(
            "  {}: {t:5.2} s, {looked}",
            path.file_name().unwrap_or_default().to_string_lossy()
        );
        let map_path = map_of(&path);
        if let Ok(map) = read_png(&map_path) {
            let texel = (image.width / map.width.max(1)).max(1);
            let share = |(u, n): (u32, u32)| {
                if n == 0 {
                    "–".to_owned()
                } else {
                    format!("{:.2}", f64::from(u) / f64::from(n))
                }
            };
            let quarters = uniform_4x4(&image, texel, &map, quarter);
            let fovea = uniform_4x4(&image, texel, &map, full_rate);
            line += &match fovea_centre(&map, texel) {
                Some([x, y]) => format!(
                    ", fovea (full-rate texels) centred at pixel {x:.0},{y:.0}; uniform 4×4 \
                     blocks: {} where the map asks for 4×4 fragments, {} in the fovea",
                    share(quarters),
                    share(fovea)
                ),
                None => format!(
                    ", the map at full rate everywhere; uniform 4×4 blocks: {}",
                    share(fovea)
                ),
            };
        }
        lines.push(line);
    }
    Ok(lines)
}

/// Each frame of `left` beside the frame of the same name in `right`, a 16-pixel black gap
/// between them, written to `out`: how many were written, and how many of those pairs were
/// identical.
pub(super) fn side_by_side(
    left: &Path,
    right: &Path,
    out: &Path,
) -> Result<(usize, usize), String> {
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let (mut written, mut identical) = (0, 0);
    for (_, a_path) in left_frames(left) {
        let name = a_path.file_name().unwrap_or_default();
        let b_path = right.join(name);
        let Ok(b) = read_png(&b_path) else {
            continue;
        };
        let a = read_png(&a_path)?;
        if (a.width, a.height, a.channels) != (b.width, b.height, b.channels) {
            return Err(format!(
                "{} and {} differ in size",
                a_path.display(),
                b_path.display()
            ));
        }
        const GAP: usize = 16;
        let c = a.channels;
        let width = 2 * a.width + GAP;
        let mut data = vec![0u8; width * a.height * c];
        for y in 0..a.height {
            let row = &mut data[y * width * c..][..width * c];
            row[..a.width * c].copy_from_slice(&a.data[y * a.width * c..][..a.width * c]);
            row[(a.width + GAP) * c..].copy_from_slice(&b.data[y * b.width * c..][..b.width * c]);
            if c == 4 {
                row[a.width * c..(a.width + GAP) * c]
                    .chunks_exact_mut(4)
                    .for_each(|p| p[3] = 255);
            }
        }
        let path = out.join(name);
        write_png(
            &path,
            &Image {
                width,
                height: a.height,
                channels: c,
                data,
            },
        )?;
        written += 1;
        identical += usize::from(a.data == b.data);
    }
    Ok((written, identical))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(
        width: usize,
        height: usize,
        channels: usize,
        f: impl Fn(usize, usize) -> Vec<u8>,
    ) -> Image {
        let mut out = Vec::new();
        for y in 0..height {
            for x in 0..width {
                out.extend(f(x, y));
            }
        }
        Image {
            width,
            height,
            channels,
            data: out,
        }
    }

    #[test]
    fn quarter_zones_of_4x4_fragments_count_as_uniform_and_the_fovea_is_placed() {
        // A 4×2-texel map (texel 8): the left column full rate, the rest ¼.
        let map = image(4, 2, 3, |x, _| {
            if x == 0 {
                vec![255, 255, 0]
            } else {
                vec![64, 64, 0]
            }
        });
        // A 32×16 frame: distinct pixels in the left 8 columns, 4×4 blocks elsewhere.
        let frame = image(32, 16, 4, |x, y| {
            if x < 8 {
                vec![(x * 16 + y) as u8, 1, 2, 255]
            } else {
                vec![(x / 4 * 4) as u8, (y / 4 * 4) as u8, 0, 255]
            }
        });
        assert_eq!(uniform_4x4(&frame, 8, &map, quarter), (24, 24));
        assert_eq!(uniform_4x4(&frame, 8, &map, full_rate), (0, 8));
        assert_eq!(fovea_centre(&map, 8), Some([4.0, 8.0]));
        // A map at full rate everywhere has no fovea to place.
        let none = image(4, 2, 3, |_, _| vec![255, 255, 0]);
        assert_eq!(fovea_centre(&none, 8), None);
    }

    #[test]
    fn pairs_are_written_side_by_side_and_identical_ones_counted() {
        let dir = std::env::temp_dir().join(format!("fovea-demo-pairs-{}", std::process::id()));
        let (a, b, out) = (dir.join("a"), dir.join("b"), dir.join("out"));
        for d in [&a, &b] {
            std::fs::create_dir_all(d).unwrap();
        }
        let frame = |v: u8| image(4, 2, 4, move |x, _| vec![v, x as u8, 0, 255]);
        write_png(&a.join("f00001_high_left.png"), &frame(10)).unwrap();
        write_png(&b.join("f00001_high_left.png"), &frame(10)).unwrap();
        write_png(&a.join("f00002_high_left.png"), &frame(10)).unwrap();
        write_png(&b.join("f00002_high_left.png"), &frame(20)).unwrap();
        // A density map is not a frame, and a frame with no partner is left out.
        write_png(&a.join("f00002_high_density_left.png"), &frame(1)).unwrap();
        write_png(&a.join("f00003_high_left.png"), &frame(1)).unwrap();
        assert_eq!(side_by_side(&a, &b, &out).unwrap(), (2, 1));
        let pair = read_png(&out.join("f00002_high_left.png")).unwrap();
        assert_eq!((pair.width, pair.height, pair.channels), (4 + 16 + 4, 2, 4));
        let px = |x: usize| &pair.data[x * 4..][..4];
        assert_eq!(px(1), [10, 1, 0, 255]);
        assert_eq!(px(10), [0, 0, 0, 255]);
        assert_eq!(px(21), [20, 1, 0, 255]);
        std::fs::remove_dir_all(&dir).ok();
    }
}
