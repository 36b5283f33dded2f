//! `fovea demo` both ways: through the system loader it runs the example app on the
//! simulated headset and writes the maps and frames it read back from the GPU; through the harness
//! it runs headless. Both show the dynamic level climbing under load and the override taking hold,
//! and the fovea following the simulated eye tracker's scripted gaze: the stats lines' `Gaze=`
//! field, and through the loader the density maps read back from the GPU.

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
    // The first and last frames, and one every 180 (2 s at 90 Hz): 180, 360 and 540 of 720.
    assert_eq!(frames, 5, "{files:?}");
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
