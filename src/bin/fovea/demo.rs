//! `fovea demo`: a small application runs its frame loop through the fake loader harness, the layer
//! and the simulated Quest 3, paced in real time. It applies a HIGH profile with dynamic foveation,
//! the simulated GPU load rises past the frame budget and falls back (the dynamic level follows),
//! and four fifths through, a Quest debug property file fixes the level at MEDIUM while the app runs. The layer's once-a-second
//! stats lines (target `fovea::stats`) show what it does.

use std::path::PathBuf;
use std::time::Instant;

use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::{HeadlessLoop, SwapchainSpec, FOVEATION_EXTENSIONS};
use fovea_harness::{sim, App, Chain};
use openxr_sys as xr;

use fovea::density::{Level, Pattern};

use crate::args::Args;
use crate::maps::render;

/// The load script, in frames at 90 Hz: light, then past the 11.1 ms budget, then light again.
const LOAD: [(u64, f32); 3] = [(0, 6.0), (270, 14.0), (630, 6.0)];

pub fn run(args: &Args) -> Result<(), String> {
    let seconds: u64 = args.parsed_or("seconds", 20)?;
    let out = PathBuf::from(args.value("out").unwrap_or("target/demo"));
    std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;
    // The layer reads these when it is loaded, so they are set before the harness opens it.
    let props = out.join("foveation.props");
    std::fs::write(
        &props,
        "# Quest debug properties, re-read while the app runs\n",
    )
    .map_err(|e| format!("{}: {e}", props.display()))?;
    if std::env::var_os("FOVEA_LOG").is_none() {
        std::env::set_var("FOVEA_LOG", "warn,fovea::stats=info");
    }
    std::env::set_var("FOVEA_PROPS", &props);

    let mut cfg = sim::control::SimConfig::from_env()?;
    cfg.realtime = true;
    cfg.journal = false;
    cfg.load = sim::control::Load {
        gpu_ms: LOAD.to_vec(),
    };
    println!(
        "fovea demo: {} (simulated, {} Hz), {seconds} s; GPU load {}",
        cfg.headset.name,
        cfg.refresh_hz,
        LOAD.iter()
            .map(|(f, ms)| format!("{ms} ms from frame {f}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    sim::control::set_thread_config(Some(cfg.clone()));
    ensure_layer_built()?;
    let chain = Chain::fovea()?;
    println!("layer: {}", chain.layers[0].spec.path.display());
    let app = App::new(chain, &FOVEATION_EXTENSIONS, API_1_0)
        .map_err(|r| format!("xrCreateInstance: {r:?}"))?;
    let mut lp = HeadlessLoop::new(
        app,
        SwapchainSpec {
            foveation: true,
            array_size: 2,
        },
    )?;
    println!(
        "swapchain: {}x{}, 2 layers (multiview)",
        lp.eye_size[0], lp.eye_size[1]
    );
    match lp.apply_profile(
        xr::FoveationLevelFB::HIGH,
        xr::FoveationDynamicFB::LEVEL_ENABLED,
    ) {
        Ok(()) => println!("profile: level HIGH, dynamic on"),
        // The frame loop still runs through the layer; the line says exactly what failed.
        Err(e) => println!("profile not applied: {e}"),
    }

    let start = Instant::now();
    let mut override_written = false;
    while start.elapsed().as_secs() < seconds {
        lp.frame().map_err(|(f, r)| format!("{f}: {r:?}"))?;
        if !override_written && start.elapsed().as_secs() >= seconds * 4 / 5 {
            std::fs::write(
                &props,
                "debug.oculus.foveation.level=2\ndebug.oculus.foveation.dynamic=0\n",
            )
            .map_err(|e| e.to_string())?;
            println!(
                "-- wrote debug.oculus.foveation.level=2, dynamic=0 to {}",
                props.display()
            );
            override_written = true;
        }
    }
    println!(
        "ran {} frames in {:.1} s",
        lp.frames(),
        start.elapsed().as_secs_f64()
    );
    // The session is headless (no Vulkan device, so no density images to read back): the maps the
    // layer builds for this swapchain at the levels the run went through come from the same model.
    for (level, name) in [
        (Level::High, "dynamic maximum (HIGH)"),
        (Level::Medium, "the override (MEDIUM)"),
    ] {
        let pattern = Pattern {
            level,
            vertical_offset_deg: 0.0,
        };
        for (eye, side) in [(0, "left"), (1, "right")] {
            let path = out.join(format!("map_{}_{side}.png", level.name()));
            render(cfg.headset, eye, 32, pattern).write_png(&path)?;
            println!("map, {name}, {side} eye: {}", path.display());
        }
    }
    Ok(())
}

/// `cargo run` builds only what the binary links, which is the layer's rlib, not `libfovea.so`. The
/// demo loads the shared library as the loader would, so when it is missing and the demo was started
/// by Cargo (`$CARGO` is set), it asks Cargo to build it with the same profile.
fn ensure_layer_built() -> Result<(), String> {
    if fovea_harness::LayerSpec::fovea().is_ok() {
        return Ok(());
    }
    let Some(cargo) = std::env::var_os("CARGO") else {
        return Err("libfovea.so is not built: run `cargo build --release` first".into());
    };
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let profile = exe
        .parent()
        .and_then(|d| d.file_name())
        .and_then(|n| n.to_str())
        .unwrap_or("debug");
    let profile = if profile == "debug" { "dev" } else { profile };
    println!("building libfovea.so (cargo build --lib --profile {profile}) ...");
    let status = std::process::Command::new(cargo)
        .args([
            "build",
            "--quiet",
            "--lib",
            "-p",
            "fovea",
            "--profile",
            profile,
        ])
        .status()
        .map_err(|e| format!("cargo: {e}"))?;
    if !status.success() {
        return Err(format!("building libfovea.so failed: {status}"));
    }
    Ok(())
}
