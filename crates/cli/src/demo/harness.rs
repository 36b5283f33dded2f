//! The demo through fovea's fake loader harness: a small headless application runs its frame loop
//! through the layer and the simulated headset in-process, paced in real time. No system component
//! is needed, and no Vulkan: the maps it writes are the model's.

use std::time::Instant;

use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::{HeadlessLoop, SwapchainSpec, FOVEATION_EXTENSIONS};
use fovea_harness::{sim, App, Chain};
use openxr_sys as xr;

use fovea_model::density::{Level, Pattern};

use super::setup::{cargo_build, load_description, Setup, LOAD};
use crate::maps::render;
use crate::target::Target;

pub fn run(setup: &Setup) -> Result<(), String> {
    let (seconds, out, props) = (setup.seconds_or(20), &setup.out, &setup.props);
    // The layer reads these when it is loaded, so they are set before the harness opens it.
    std::env::set_var("FOVEA_LOG", &setup.log);
    std::env::set_var("FOVEA_PROPS", props);

    let mut cfg = sim::control::SimConfig::for_headset(setup.headset);
    cfg.realtime = true;
    cfg.journal = false;
    cfg.load = sim::control::Load {
        gpu_ms: LOAD.to_vec(),
    };
    println!(
        "fovea demo: {} (simulated, {} Hz), {seconds} s in real time; GPU load {}",
        cfg.headset.name,
        cfg.refresh_hz,
        load_description()
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
            setup.write_override()?;
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
            render(&Target::preset(setup.headset), eye, 32, pattern).write_png(&path)?;
            println!("map, {name}, {side} eye: {}", path.display());
        }
    }
    Ok(())
}

/// `cargo run` builds only what the binary links, which is the layer's rlib, not `libfovea.so`. The
/// demo loads the shared library as the loader would.
fn ensure_layer_built() -> Result<(), String> {
    if fovea_harness::LayerSpec::fovea().is_ok() {
        return Ok(());
    }
    cargo_build(&["--lib", "-p", "fovea"])
        .map_err(|e| format!("libfovea.so is not built ({e}): run `cargo build --release` first"))
}
