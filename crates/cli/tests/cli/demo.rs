//! `fovea demo` both ways: through the system loader it runs the example app on the
//! simulated headset and writes the maps and frames it read back from the GPU; through the harness
//! it runs headless. Both show the dynamic level climbing under load and the override taking hold,
//! and the fovea following the simulated eye tracker's scripted gaze: the stats lines' `Gaze=`
//! field, and through the loader the density maps read back from the GPU and the frames drawn with
//! them, which on lavapipe come from the simulated desktop GPU (the shading-rate double): a coarse
//! periphery, and a sharp region where the script put the gaze.

use fovea_harness::sim::gaze_script::GazeScript;
use fovea_harness::skip;

use crate::maps::read_png;
use crate::support::{command, run};

/// Runs `fovea demo` with `args` into a fresh folder; returns (stdout + stderr, folder).
fn demo(args: &[&str], name: &str) -> (String, std::path::PathBuf) {
    let out = std::env::temp_dir().join(format!("fovea-demo-{name}-{}", std::process::id()));
    std::fs::remove_dir_all(&out).ok();
    let r = run(command()
        .arg("demo")
        .args(args)
        .arg("--out")
        .arg(&out)
        // The demo builds the example and libraries it runs with the profile of this `fovea`.
        .env("CARGO", env!("CARGO"))
        .env_remove("FOVEA_LOG")
        .env_remove("FOVEA_PROPS"));
    let text = r.text();
    assert!(r.ok(), "fovea demo {args:?} failed:\n{text}");
    (text, out)
}

/// The levels the stats lines showed, in order, without repeats.
fn fov_sequence(text: &str) -> Vec<String> {
    let mut seen: Vec<String> = Vec::new();
    for fov in text
        .lines()
        .filter(|l| l.contains(fovea_abi::log_target::STATS))
        .filter_map(|l| l.split_whitespace().find_map(|w| w.strip_prefix("Fov=")))
    {
        if seen.last().map(String::as_str) != Some(fov) {
            seen.push(fov.to_owned());
        }
    }
    seen
}

/// Overload raises the dynamic level one step at a time; the override fixes it at MEDIUM.
fn assert_story(text: &str) {
    let fovs = fov_sequence(text);
    assert!(
        fovs.starts_with(&["0D", "1D", "2D", "3D"].map(String::from)),
        "{fovs:?}\n{text}"
    );
    assert_eq!(
        fovs.last().map(String::as_str),
        Some("2"),
        "{fovs:?}\n{text}"
    );
}

/// The left view's fovea centre (NDC, y up) from each stats line: `None` where the line says the
/// fovea is not following a gaze (`Gaze=fixed`, `Gaze=off`).
fn left_gaze(text: &str) -> Vec<Option<[f32; 2]>> {
    text.lines()
        .filter(|l| l.contains(fovea_abi::log_target::STATS))
        .filter_map(|l| l.split_whitespace().find_map(|w| w.strip_prefix("Gaze=")))
        .map(|g| {
            let (_, at) = g.split_once('@')?;
            let left = at.split('/').next()?;
            let (x, y) = left.split_once(',')?;
            Some([x.parse().ok()?, y.parse().ok()?])
        })
        .collect()
}

/// The gaze script (`fovea demo`'s `GAZE`) looks ahead, 15° right and 8° up, then 15° left and 6°
/// down: the fovea follows the gaze (`tracked@`, or `held@` through the blink) on every stats line
/// after the first (the gaze source starts with the session), and moves both ways by well over a
/// tenth of the view, which a centred fovea never does.
fn assert_fovea_follows(text: &str) {
    let gaze = left_gaze(text);
    assert!(gaze.len() >= 5, "{gaze:?}\n{text}");
    let following: Vec<[f32; 2]> = gaze[1..].iter().map_while(|g| *g).collect();
    assert_eq!(following.len(), gaze.len() - 1, "{gaze:?}\n{text}");
    let xs = following.iter().map(|c| c[0]);
    let (lo, hi) = (
        xs.clone().fold(f32::INFINITY, f32::min),
        xs.fold(f32::NEG_INFINITY, f32::max),
    );
    assert!(hi - lo > 0.25, "the fovea stayed put: {gaze:?}\n{text}");
    let ys = following.iter().map(|c| c[1]);
    assert!(
        ys.clone().fold(f32::NEG_INFINITY, f32::max) - ys.fold(f32::INFINITY, f32::min) > 0.1,
        "the fovea never moved vertically: {gaze:?}\n{text}"
    );
}

/// The full-rate texels' centre (texels, from the left and the top) of a density map PNG as the
/// example writes it (red = horizontal density, green = vertical, 255 = full rate), or `None` where
/// half the map or more is full rate (level NONE, LOW at the edge of the FOV: no fovea to place).
fn full_rate_centre(path: &std::path::Path) -> Option<[f32; 2]> {
    let (width, height, rgb) = read_png(path);
    let width = width as usize;
    let texels: Vec<(usize, usize)> = rgb
        .chunks_exact(3)
        .enumerate()
        .filter(|(_, t)| t[0] == 255 && t[1] == 255)
        .map(|(i, _)| (i % width, i / width))
        .collect();
    if texels.is_empty() || 2 * texels.len() >= width * height as usize {
        return None;
    }
    let n = texels.len() as f32;
    Some([
        texels.iter().map(|t| t.0 as f32).sum::<f32>() / n,
        texels.iter().map(|t| t.1 as f32).sum::<f32>() / n,
    ])
}

/// A frame read back: width, height, RGBA8 rows.
struct Frame {
    width: usize,
    height: usize,
    rgba: Vec<u8>,
}

fn read_frame(path: &std::path::Path) -> Frame {
    let decoder = png::Decoder::new(std::fs::File::open(path).expect("frame written"));
    let mut reader = decoder.read_info().expect("png header");
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).expect("png data");
    assert_eq!(info.color_type, png::ColorType::Rgba, "{}", path.display());
    buf.truncate(info.buffer_size());
    Frame {
        width: info.width as usize,
        height: info.height as usize,
        rgba: buf,
    }
}

/// The density map drawn with a frame: width, height, per texel (horizontal, vertical density,
/// 255 full rate).
struct Map {
    width: usize,
    height: usize,
    texels: Vec<[u8; 2]>,
}

impl Map {
    fn read(path: &std::path::Path) -> Map {
        let (width, height, rgb) = read_png(path);
        Map {
            width: width as usize,
            height: height as usize,
            texels: rgb.chunks_exact(3).map(|t| [t[0], t[1]]).collect(),
        }
    }

    /// The texel under frame pixel (x, y), `texel` pixels a side.
    fn at(&self, texel: usize, x: u32, y: u32) -> [u8; 2] {
        let (tx, ty) = (x as usize / texel, y as usize / texel);
        self.texels[ty.min(self.height - 1) * self.width + tx.min(self.width - 1)]
    }
}

/// A texel asking for 4×4 fragments (a quarter of the resolution on both axes).
fn quarter(t: [u8; 2]) -> bool {
    t[0] <= 64 && t[1] <= 64
}

/// The share of `frame`'s 4×4 blocks (aligned as fragments are) that are uniform where `inside`
/// holds for their top-left pixel: `fovea_vkdouble::blocks::uniform_share`.
fn share_4x4(frame: &Frame, inside: impl Fn(u32, u32) -> bool) -> Option<f64> {
    fovea_vkdouble::blocks::uniform_share(
        &frame.rgba,
        [frame.width as u32, frame.height as u32],
        4,
        4,
        inside,
    )
}

/// The sharp region's centre (pixels): of the frame's 16×16 tiles, those where under half of the
/// 2×2 blocks are uniform (a fragment of 2×2 or coarser makes every one uniform; at full rate the
/// room leaves a fifth or fewer so), averaged; `None` where at least half the tiles are sharp
/// (nothing coarse to tell the fovea from).
fn sharp_centre(frame: &Frame) -> Option<[f64; 2]> {
    const TILE: usize = 16;
    let (tw, th) = (frame.width / TILE, frame.height / TILE);
    let px = |x: usize, y: usize| &frame.rgba[(y * frame.width + x) * 4..][..3];
    // Per tile, its uniform 2×2 blocks (of (TILE/2)² blocks), in one pass over the frame.
    let mut uniform = vec![0usize; tw * th];
    for y in (0..th * TILE).step_by(2) {
        for x in (0..tw * TILE).step_by(2) {
            let a = px(x, y);
            if px(x + 1, y) == a && px(x, y + 1) == a && px(x + 1, y + 1) == a {
                uniform[y / TILE * tw + x / TILE] += 1;
            }
        }
    }
    let blocks = (TILE / 2) * (TILE / 2);
    let (mut n, mut sx, mut sy) = (0usize, 0.0, 0.0);
    for (i, u) in uniform.iter().enumerate() {
        if 2 * u < blocks {
            n += 1;
            sx += ((i % tw) * TILE + TILE / 2) as f64;
            sy += ((i / tw) * TILE + TILE / 2) as f64;
        }
    }
    (n > 0 && 2 * n < tw * th).then(|| [sx / n as f64, sy / n as f64])
}

/// The left view's located FOV as tangents (left, right, up, down) from the example's stdout.
fn left_tangents(text: &str) -> [f64; 4] {
    let fov: Vec<f64> = text
        .split_once("(left,right,up,down per view) ")
        .and_then(|(_, rest)| rest.split_whitespace().next())
        .map(|v| {
            v.split(',')
                .map(|a| a.parse::<f64>().unwrap().tan())
                .collect()
        })
        .unwrap_or_else(|| panic!("no located FOVs\n{text}"));
    [fov[0], fov[1], fov[2], fov[3]]
}

/// Where the left eye sees the head's gaze (yaw right, pitch up, degrees) land, in pixels of a view
/// `size` big with FOV tangents `tan`: the gaze ray meets the fixation plane 1 m ahead (fovea's
/// default, docs/eye-tracking.md), seen from the left eye 31.5 mm to the left (the simulated
/// runtime's IPD of 63 mm).
fn gaze_pixel(gaze: [f32; 2], [l, r, u, d]: [f64; 4], size: (usize, usize)) -> [f64; 2] {
    let (yaw, pitch) = (
        f64::from(gaze[0]).to_radians(),
        f64::from(gaze[1]).to_radians(),
    );
    let (x, y, z) = (
        pitch.cos() * yaw.sin() + 0.0315,
        pitch.sin(),
        pitch.cos() * yaw.cos(),
    );
    let (tx, ty) = (x / z, y / z);
    [
        (tx - l) / (r - l) * size.0 as f64,
        (u - ty) / (u - d) * size.1 as f64,
    ]
}

/// The display time (seconds) of each frame of the run, from the first lines the demo prints:
/// `N frames (S s at H Hz ...` and `GPU load X ms from frame F, ...`. The simulated runtime's clock
/// advances a period per frame, or as many as a frame's simulated GPU time takes (a miss).
fn display_clock(text: &str) -> impl Fn(u64) -> f64 {
    let hz: f32 = text
        .split_once(" s at ")
        .and_then(|(_, rest)| rest.split_once(" Hz"))
        .and_then(|(hz, _)| hz.parse().ok())
        .unwrap_or_else(|| panic!("no display rate printed\n{text}"));
    let load: Vec<(u64, f32)> = text
        .split_once("GPU load ")
        .and_then(|(_, rest)| rest.split_once("; "))
        .map(|(load, _)| {
            load.split(", ")
                .map(|step| {
                    let (ms, frame) = step.split_once(" ms from frame ").expect("a load step");
                    (frame.parse().unwrap(), ms.parse().unwrap())
                })
                .collect()
        })
        .unwrap_or_else(|| panic!("no load script printed\n{text}"));
    let load = fovea_harness::sim::control::Load { gpu_ms: load };
    move |n| {
        let period_ms = 1000.0 / hz;
        let periods: f32 = (0..n)
            .map(|f| (load.gpu_ms_at(f) / period_ms).ceil().max(1.0))
            .sum();
        f64::from(periods.max(0.0)) / f64::from(hz)
    }
}

/// The left eye's frames in `dir`: (file name, frame number).
fn left_frames(dir: &std::path::Path) -> Vec<(String, u64)> {
    let mut found: Vec<(String, u64)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.ends_with("_left.png") && !n.contains("_density_"))
        .map(|n| {
            let frame = n[1..].split('_').next().unwrap().parse().unwrap();
            (n, frame)
        })
        .collect();
    found.sort();
    found
}

/// On lavapipe the demo renders on the simulated desktop GPU: every frame whose map asks for 4×4
/// fragments somewhere (HIGH) has nearly every 4×4 block uniform there and few in its fovea, and the
/// first frame (level NONE: the dynamic level starts at full rate) has few anywhere; and the sharp
/// region of every frame with a coarse periphery is centred where the gaze script had the eye look
/// at that frame's display time, at places far apart. Today's demo drew stripes at full rate.
fn assert_frames_foveated(text: &str, frames: &std::path::Path) {
    let gaze = text
        .split_once("FOVEA_SIM_GAZE=\"")
        .and_then(|(_, rest)| rest.split_once('"'))
        .map(|(g, _)| GazeScript::parse(g).expect("the printed gaze script parses"))
        .unwrap_or_else(|| panic!("no gaze script printed\n{text}"));
    let tangents = left_tangents(text);
    let clock = display_clock(text);
    let (mut coarse, mut full, mut placed) = (0, 0, Vec::new());
    for (name, n) in left_frames(frames) {
        let t = clock(n);
        let frame = read_frame(&frames.join(&name));
        let map = Map::read(&frames.join(name.replace("_left.png", "_density_left.png")));
        let texel = frame.width / map.width;
        if map.texels.iter().all(|t| *t == [255, 255]) {
            let share = share_4x4(&frame, |_, _| true).unwrap();
            assert!(
                share < 0.3,
                "{name}: full rate, yet {share:.3} of 4×4 blocks uniform"
            );
            full += 1;
            continue;
        }
        if map.texels.iter().any(|t| quarter(*t)) {
            let periphery = share_4x4(&frame, |x, y| quarter(map.at(texel, x, y))).unwrap();
            let fovea = share_4x4(&frame, |x, y| map.at(texel, x, y) == [255, 255]).unwrap();
            assert!(
                periphery > 0.9 && fovea < 0.3,
                "{name}: uniform 4×4 blocks {periphery:.3} where the map asks 4×4, {fovea:.3} in \
                 the fovea"
            );
            coarse += 1;
        }
        let Some(sharp) = sharp_centre(&frame) else {
            continue;
        };
        let looked = gaze
            .eye_at((t * 1e9) as i64)
            .unwrap_or_else(|| panic!("{name} at {t} s: the script has the eyes closed"));
        let want = gaze_pixel(looked, tangents, (frame.width, frame.height));
        let off = ((sharp[0] - want[0]).powi(2) + (sharp[1] - want[1]).powi(2)).sqrt();
        // Three texels: the shift is whole texels, and pursuit moves the eye 20°/s.
        assert!(
            off < 3.0 * texel as f64,
            "{name} at {t} s: the gaze script looks at {looked:?} (pixel {want:.0?}), the sharp \
             region is centred at {sharp:.0?}, {off:.0} px away"
        );
        placed.push(looked);
    }
    assert!(
        full >= 1 && coarse >= 1,
        "{full} full-rate and {coarse} HIGH frames\n{text}"
    );
    let spread = placed
        .iter()
        .flat_map(|a| placed.iter().map(move |b| (a[0] - b[0]).hypot(a[1] - b[1])))
        .fold(0.0f32, f32::max);
    assert!(
        placed.len() >= 3 && spread > 20.0,
        "the sharp region followed the gaze to {placed:?} only\n{text}"
    );
}

#[test]
fn through_the_system_loader_it_runs_the_example_and_reads_back_its_maps() {
    if let Err(e) = unsafe { libloading::Library::new("libopenxr_loader.so.1") } {
        skip(&format!("the Khronos OpenXR loader is not installed: {e}"));
        return;
    }
    if fovea_harness::vulkan::lavapipe_icd().is_none() {
        skip("Mesa's lavapipe Vulkan driver is not installed (mesa-vulkan-drivers)");
        return;
    }
    let (text, out) = demo(
        &["--via", "loader", "--seconds", "8", "--headset", "rift-cv1"],
        "loader",
    );
    assert!(
        text.contains("examples/foveated_vulkan through the Khronos loader"),
        "{text}"
    );
    assert_story(&text);
    assert_fovea_follows(&text);
    assert!(
        text.contains("-- wrote debug.oculus.foveation.level=2"),
        "{text}"
    );
    // One density map per distinct pattern the run went through, and the first and last frames.
    let mut files: Vec<String> = std::fs::read_dir(out.join("frames"))
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    files.sort();
    let maps = files
        .iter()
        .filter(|f| f.ends_with("_density_left.png"))
        .count();
    let frames = files
        .iter()
        .filter(|f| f.ends_with("_high_left.png"))
        .count();
    assert!(maps >= 5, "0D, 1D, 2D, 3D and the override: {files:?}");
    // On the double (30 Hz): the first and last frames, and one a second: 30, 60, …, 210 of 240.
    assert_eq!(frames, 9, "{files:?}");
    // The maps' full-rate centres, in order: the fovea lands at several places, horizontally more
    // than a Rift CV1 view's 42-texel map's eighth apart (the script's 30° swing is about a third).
    let centres: Vec<[f32; 2]> = files
        .iter()
        .filter(|f| f.ends_with("_density_left.png"))
        .filter_map(|f| full_rate_centre(&out.join("frames").join(f)))
        .collect();
    let xs = centres.iter().map(|c| c[0]);
    let spread = xs.clone().fold(f32::NEG_INFINITY, f32::max) - xs.fold(f32::INFINITY, f32::min);
    assert!(
        centres.len() >= 4 && spread > 5.0,
        "the maps' fovea did not follow the gaze: {centres:?} ({files:?})"
    );
    assert_frames_foveated(&text, &out.join("frames"));
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn through_the_harness_it_needs_nothing_installed() {
    let (text, out) = demo(&["--via", "harness", "--seconds", "10"], "harness");
    assert!(text.contains("in real time"), "{text}");
    assert_story(&text);
    assert_fovea_follows(&text);
    assert!(out.join("map_high_left.png").is_file(), "{text}");
    std::fs::remove_dir_all(&out).ok();
}
