//! The demo through fovea's fake loader harness: a small headless application runs its frame loop
//! through the layer and the simulated headset in-process, paced in real time. No system component
//! is needed, and no Vulkan: the maps it writes are the model's.
//!
//! The simulated headset has an eye tracker following [`GAZE`], and the app's profile is
//! eye-tracked (`XrFoveationEyeTrackedProfileCreateInfoMETA` on the level profile,
//! docs/eye-tracking.md#xr_meta_foveation_eye_tracked). The loop has no input of its own to attach,
//! so fovea is told to attach its gaze action set at once (`FOVEA_GAZE_ATTACH_AFTER_S=0`; by default
//! fovea never attaches alone, docs/eye-tracking.md#applications-that-do-not-cooperate).

use std::time::Instant;

use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::{HeadlessLoop, SwapchainSpec, FOVEATION_EXTENSIONS};
use fovea_harness::{sim, App, Chain};
use openxr_sys as xr;
use xr::Handle as _;

use fovea_model::density::{Level, Pattern};

use super::setup::{cargo_build, gaze_description, load_description, Setup, GAZE, LOAD};
use crate::maps::render;
use crate::target::Target;

pub fn run(setup: &Setup) -> Result<(), String> {
    let (seconds, out, props) = (setup.seconds_or(20), &setup.out, &setup.props);
    // The layer reads these when it is loaded, so they are set before the harness opens it.
    std::env::set_var("FOVEA_LOG", &setup.log);
    std::env::set_var("FOVEA_PROPS", props);
    std::env::set_var(fovea_abi::env::GAZE_ATTACH_AFTER_S, "0");

    let mut cfg = sim::control::SimConfig::for_headset(setup.headset);
    cfg.realtime = true;
    cfg.journal = false;
    cfg.load = sim::control::Load {
        gpu_ms: LOAD.to_vec(),
    };
    cfg.eye_gaze = Some(sim::control::EyeGaze {
        supported: true,
        space_after_attach: false,
        script: sim::gaze_script::GazeScript::parse(GAZE)?,
    });
    println!(
        "fovea demo: {} (simulated, {} Hz), {seconds} s in real time; GPU load {}; eye tracker {}",
        cfg.headset.name,
        cfg.refresh_hz,
        load_description(&LOAD),
        gaze_description()
    );
    sim::control::set_thread_config(Some(cfg.clone()));
    ensure_layer_built()?;
    let chain = Chain::fovea()?;
    println!("layer: {}", chain.layers[0].spec.path.display());
    let mut extensions = FOVEATION_EXTENSIONS.to_vec();
    extensions.push(EYE_TRACKED);
    let app =
        App::new(chain, &extensions, API_1_0).map_err(|r| format!("xrCreateInstance: {r:?}"))?;
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
    match apply_eye_tracked_profile(&lp) {
        Ok(()) => println!("profile: level HIGH, dynamic on, eye-tracked"),
        // The frame loop still runs through the layer; the line says exactly what failed.
        Err(e) => println!("profile not applied: {e}"),
    }

    let start = Instant::now();
    let mut override_written = false;
    while start.elapsed().as_secs() < seconds {
        // Events first, as applications poll them: fovea syncs its gaze set alone only once the
        // session it saw polled is FOCUSED.
        lp.poll_events();
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
    // layer builds for this swapchain at the levels the run went through come from the same model,
    // with the fovea straight ahead (where the gaze put it, the stats lines' `Gaze=` says).
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

const EYE_TRACKED: &str = "XR_META_foveation_eye_tracked";

/// Applies a HIGH dynamic profile created with `XrFoveationEyeTrackedProfileCreateInfoMETA` chained
/// on its level struct to the loop's swapchain, then destroys the profile (the swapchain keeps its
/// state). `Err` names the call that failed.
fn apply_eye_tracked_profile(lp: &HeadlessLoop) -> Result<(), String> {
    let tracked = xr::FoveationEyeTrackedProfileCreateInfoMETA {
        ty: xr::FoveationEyeTrackedProfileCreateInfoMETA::TYPE,
        next: std::ptr::null(),
        flags: xr::FoveationEyeTrackedProfileCreateFlagsMETA::EMPTY,
    };
    let level = xr::FoveationLevelProfileCreateInfoFB {
        ty: xr::FoveationLevelProfileCreateInfoFB::TYPE,
        next: &tracked as *const _ as *mut _,
        level: xr::FoveationLevelFB::HIGH,
        vertical_offset: 0.0,
        dynamic: xr::FoveationDynamicFB::LEVEL_ENABLED,
    };
    let info = xr::FoveationProfileCreateInfoFB {
        ty: xr::FoveationProfileCreateInfoFB::TYPE,
        next: &level as *const _ as *mut _,
    };
    // SAFETY: the names' types match the functions; the structs live across the calls.
    let create: xr::pfn::CreateFoveationProfileFB =
        unsafe { lp.func(c"xrCreateFoveationProfileFB") };
    // SAFETY: as above.
    let update: xr::pfn::UpdateSwapchainFB = unsafe { lp.func(c"xrUpdateSwapchainFB") };
    // SAFETY: as above.
    let destroy: xr::pfn::DestroyFoveationProfileFB =
        unsafe { lp.func(c"xrDestroyFoveationProfileFB") };
    let mut profile = xr::FoveationProfileFB::NULL;
    // SAFETY: a live session; `info` and its chain outlive the call.
    let r = unsafe { create(lp.session, &info, &mut profile) };
    if r != xr::Result::SUCCESS {
        return Err(format!("xrCreateFoveationProfileFB: {r:?}"));
    }
    let state = xr::SwapchainStateFoveationFB {
        ty: xr::SwapchainStateFoveationFB::TYPE,
        next: std::ptr::null_mut(),
        flags: xr::SwapchainStateFoveationFlagsFB::EMPTY,
        profile,
    };
    // SAFETY: a live swapchain; `state` outlives the call.
    let r = unsafe { update(lp.swapchain, &state as *const _ as *const _) };
    // SAFETY: the profile was made above and is not used after this.
    unsafe { destroy(profile) };
    if r != xr::Result::SUCCESS {
        return Err(format!("xrUpdateSwapchainFB: {r:?}"));
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
