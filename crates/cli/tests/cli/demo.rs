//! `fovea demo` both ways: through the system loader it runs the example app on the
//! simulated headset and writes the maps and frames it read back from the GPU; through the harness
//! it runs headless. Both show the dynamic level climbing under load and the override taking hold.

use fovea_harness::skip;

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
    assert!(
        text.contains("-- wrote debug.oculus.foveation.level=2"),
        "{text}"
    );
    // One density map per distinct pattern the run went through, and the first and last frames.
    let files: Vec<String> = std::fs::read_dir(out.join("frames"))
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    let maps = files
        .iter()
        .filter(|f| f.ends_with("_density_left.png"))
        .count();
    let frames = files
        .iter()
        .filter(|f| f.ends_with("_high_left.png"))
        .count();
    assert!(maps >= 5, "0D, 1D, 2D, 3D and the override: {files:?}");
    assert_eq!(frames, 2, "{files:?}");
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn through_the_harness_it_needs_nothing_installed() {
    let (text, out) = demo(&["--via", "harness", "--seconds", "10"], "harness");
    assert!(text.contains("in real time"), "{text}");
    assert_story(&text);
    assert!(out.join("map_high_left.png").is_file(), "{text}");
    std::fs::remove_dir_all(&out).ok();
}
