//! The fovea lands where the eye looks, once (docs/eye-tracking.md#what-moves-when), end to end on
//! the simulated runtime's scripted gaze.
//!
//! Stack: as [`crate::both::fdm_emulated`]: this test as an OpenXR application → fovea's OpenXR
//! layer → the simulated runtime with an eye tracker (`XR_EXT_eye_gaze_interaction`, its gaze from
//! a script), the application's VkInstance and VkDevice made through XR_KHR_vulkan_enable2 with
//! fovea's Vulkan layer → VK_LAYER_KHRONOS_validation → the shading-rate double (`nvidia`: 16×16
//! texels, one shading-rate layer per view) → lavapipe. The application renders both eyes into an
//! array swapchain of two layers with one multiview render pass a frame, and submits them as one
//! projection layer. It never touches actions: fovea's gaze source runs on its own.
//!
//! Three modes:
//! - **maps**: the application asks for `XR_FB_foveation_vulkan` with an eye-tracked HIGH profile
//!   (`XrFoveationEyeTrackedProfileCreateInfoMETA`) and renders through fovea's density images:
//!   fovea moves the fovea in them;
//! - **app offsets**: the same, the swapchain created with `FRAGMENT_DENSITY_MAP_OFFSET_BIT` in
//!   `XrVulkanSwapchainCreateInfoMETA`: the application moves the fovea itself, fovea's maps stay
//!   fixed;
//! - **injection**: an application that never asks for foveation, `FOVEA_INJECT=1` at HIGH: the
//!   injected maps follow the gaze.
//!
//! Per frame the double reports what the draw shaded at, per view and shading-rate texel. Each
//! view's rates must be the fixed map's (the density model for the located FOV, converted as
//! `fovea_model::shading_rate` does) shifted by a whole number of texels
//! (`fovea_model::shift::shift_codes_into`), within one texel of where the filtered gaze puts that
//! view's fovea (`fovea_model::gaze::eye_centre` for the script's fixation, through the located
//! eye poses and FOVs); fixed foveation is the shift 0. Validation must say nothing and the double
//! record no misuse. Each test runs in a process of its own (`FOVEA_INJECT` and the log are read
//! from the environment once).

use std::ffi::c_void;
use std::ptr::{null, null_mut};

use fovea_harness::app::API_1_0;
use fovea_harness::sim::control::{EyeGaze, SimConfig};
use fovea_harness::sim::gaze_script::GazeScript;
use fovea_harness::vulkan::{self, pick_lavapipe, take_messages, Vulkan};
use fovea_harness::{skip, App, Chain};
use fovea_model::density::{Grid, Level, Pattern, Rect, View};
use fovea_model::gaze::{eye_centre, EyeView, Gaze, Tracking};
use glam::{Quat, Vec3};
use fovea_model::shift::{pixel_of, shift_codes_into};
use fovea_vkdouble::Profile;
use openxr_sys as xr;
use xr::Handle as _;

use crate::both::fdm_emulated::{color_images, expected_codes, rates_drawn, release, Layout, Renderer};
use crate::both::fdm_vulkan::{
    enumerate, fov_of, func, running_session, swapchain_info, Frame, FDM_BIT, HEIGHT, VALIDATED,
    WIDTH,
};
use crate::support::device::env;
use crate::support::{in_own_process, level_info};

const MS: i64 = 1_000_000;
/// The simulated runtime's clock when its instance is created; a session created before the first
/// frame starts its eye tracker's script there (`crates/sim/src/instance.rs`).
const CLOCK_START_NS: i64 = 1_000_000_000_000;
/// `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT`.
const FDM_OFFSET_BIT: u64 = 0x8000;
/// The gaze source's fixation distance (docs/eye-tracking.md#defaults).
const FIXATION_M: f32 = 1.0;

/// Who moves the fovea.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Mode {
    Maps,
    AppOffsets,
    Inject,
}

/// What one frame drew.
struct Seen {
    /// Its predicted display time, from the script's start.
    t_ns: i64,
    /// The views as located for it: (FOV, position and orientation in VIEW space).
    eyes: [EyeView; 2],
    /// Per view, the rates its draw shaded at (codes, one per texel).
    codes: [Vec<u8>; 2],
}

/// What a run left: every frame and the log.
struct Run {
    frames: Vec<Seen>,
    log: String,
}

fn eye_view(v: &xr::View) -> EyeView {
    let p = v.pose.position;
    let o = v.pose.orientation;
    EyeView {
        fov: fov_of(v),
        position: Vec3::new(p.x, p.y, p.z),
        orientation: Quat::from_xyzw(o.x, o.y, o.z, o.w),
    }
}

/// The located views (poses and FOVs) at `time`.
fn located(frame: &Frame, time: xr::Time) -> [xr::View; 2] {
    let locate: xr::pfn::LocateViews = func(frame.app, "xrLocateViews");
    let info = xr::ViewLocateInfo {
        ty: xr::StructureType::VIEW_LOCATE_INFO,
        next: null(),
        view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
        display_time: time,
        space: frame.space,
    };
    let mut state = xr::ViewState {
        ty: xr::StructureType::VIEW_STATE,
        next: null_mut(),
        view_state_flags: xr::ViewStateFlags::EMPTY,
    };
    let mut views = [xr::View {
        ty: xr::StructureType::VIEW,
        next: null_mut(),
        pose: xr::Posef::IDENTITY,
        fov: xr::Fovf::default(),
    }; 2];
    let mut n = 0;
    // SAFETY: every struct lives across the call; the array holds two views.
    let r = unsafe {
        locate(
            frame.session,
            &info,
            &mut state,
            2,
            &mut n,
            views.as_mut_ptr(),
        )
    };
    assert_eq!((r, n), (xr::Result::SUCCESS, 2));
    views
}

/// Sets the log up for this (child) process; `inject` turns injection on at HIGH.
fn set_up(label: &str, inject: bool) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("fovea-gaze-{label}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::env::set_var("FOVEA_LOG", "info,fovea::vk=debug");
    std::env::set_var("FOVEA_LOG_FILE", dir.join("fovea.log"));
    if inject {
        std::env::set_var("FOVEA_INJECT", "1");
        std::env::set_var("FOVEA_INJECT_LEVEL", (Level::High as u8).to_string());
    } else {
        std::env::remove_var("FOVEA_INJECT");
    }
    pick_lavapipe();
    dir
}

/// `frames` frames of `mode` with the eye following `script`, on `nvidia`; `None` after a skip.
fn run(mode: Mode, script: &str, frames: usize, dir: &std::path::Path) -> Option<Run> {
    let (_serial, env) = env()?;
    let _validated = VALIDATED.lock();
    let profile = Profile::Nvidia;
    env.double.set_profile(Some(profile));
    crate::support::device::assert_no_double_errors(env);
    env.double.clear();
    take_messages();
    let cfg = SimConfig {
        eye_gaze: Some(EyeGaze {
            supported: true,
            space_after_attach: false,
            script: GazeScript::parse(script).expect("a gaze script"),
        }),
        ..SimConfig::default()
    };
    fovea_harness::sim::control::set_thread_config(Some(cfg));
    let mut exts = vec!["XR_KHR_vulkan_enable2"];
    if mode != Mode::Inject {
        exts.extend([
            "XR_FB_swapchain_update_state",
            "XR_FB_foveation",
            "XR_FB_foveation_configuration",
            "XR_FB_foveation_vulkan",
            "XR_META_foveation_eye_tracked",
            "XR_META_vulkan_swapchain_create_info",
        ]);
    }
    let app = App::new(Chain::fovea().unwrap(), &exts, API_1_0).expect("the instance");
    let sys = app.system();
    let layers = [vulkan::VALIDATION_LAYER, fovea_vkdouble::LAYER_NAME];
    let options = vulkan::Options {
        layers: &layers,
        multiview: true,
        ..Default::default()
    };
    let v = match Vulkan::through_xr_with(&env.entry, app.chain.gipa(), app.instance, sys, &options)
    {
        Ok(v) => v,
        Err(why) => {
            assert_eq!(app.destroy(), xr::Result::SUCCESS);
            skip(&why);
            return None;
        }
    };
    let (session, space) = running_session(&app, sys, &v);
    let create_swapchain: xr::pfn::CreateSwapchain = func(&app, "xrCreateSwapchain");
    let offsets = xr::VulkanSwapchainCreateInfoMETA {
        ty: xr::StructureType::VULKAN_SWAPCHAIN_CREATE_INFO_META,
        next: null(),
        additional_create_flags: FDM_OFFSET_BIT,
        additional_usage_flags: 0,
    };
    let fdm_flag = xr::SwapchainCreateInfoFoveationFB {
        ty: xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
        next: if mode == Mode::AppOffsets {
            &offsets as *const _ as *mut c_void
        } else {
            null_mut()
        },
        flags: xr::SwapchainCreateFoveationFlagsFB::from_raw(FDM_BIT),
    };
    let next = match mode {
        Mode::Inject => null(),
        Mode::Maps | Mode::AppOffsets => &fdm_flag as *const _ as *const c_void,
    };
    let info = swapchain_info(next);
    let mut swapchain = xr::Swapchain::NULL;
    // SAFETY: the create info, its chain and the output live across the call.
    let r = unsafe { create_swapchain(session, &info, &mut swapchain) };
    assert_eq!(r, xr::Result::SUCCESS, "{mode:?}");
    let color = color_images(&app, swapchain);
    let density: Option<Vec<u64>> =
        (mode != Mode::Inject).then(|| enumerate(&app, swapchain).iter().map(|d| d.image).collect());
    let renderer = Renderer::new(&v, Layout::Multiview, &color, density.as_deref());
    if mode != Mode::Inject {
        apply_eye_tracked_high(&app, session, swapchain);
    }
    let frame = Frame {
        app: &app,
        session,
        space,
    };
    let t = profile.texel();
    let extent = [WIDTH.div_ceil(t.width), HEIGHT.div_ceil(t.height)];
    let texels = (extent[0] * extent[1]) as usize;
    let mut seen = Vec::new();
    for n in 0..frames {
        let case = format!("{mode:?} frame {n}");
        crate::support::device::assert_no_double_errors(env);
        env.double.clear();
        let (index, fovs, time) = frame.acquire(swapchain);
        let views = located(&frame, time);
        renderer.draw(&v.device, index);
        release(&frame, Layout::Multiview, swapchain, time, fovs);
        let got = rates_drawn(env, &case, Layout::Multiview, 2, extent);
        assert_eq!(got.len(), 2 * texels, "{case}");
        seen.push(Seen {
            t_ns: time.as_nanos() - CLOCK_START_NS,
            eyes: [eye_view(&views[0]), eye_view(&views[1])],
            codes: [got[..texels].to_vec(), got[texels..].to_vec()],
        });
    }
    assert_eq!(env.double.errors(), Vec::<String>::new(), "{mode:?}");
    renderer.destroy(&v.device);
    let destroy_swapchain: xr::pfn::DestroySwapchain = func(&app, "xrDestroySwapchain");
    let destroy_session: xr::pfn::DestroySession = func(&app, "xrDestroySession");
    // SAFETY: the handles are live and used no more.
    unsafe {
        assert_eq!(destroy_swapchain(swapchain), xr::Result::SUCCESS);
        assert_eq!(destroy_session(session), xr::Result::SUCCESS);
        v.destroy_device();
    }
    assert_eq!(app.destroy(), xr::Result::SUCCESS);
    // SAFETY: the device is gone.
    unsafe { v.destroy_instance() };
    vulkan::assert_no_messages();
    Some(Run {
        frames: seen,
        log: std::fs::read_to_string(dir.join("fovea.log")).unwrap_or_default(),
    })
}

/// Applies a HIGH profile created with `XrFoveationEyeTrackedProfileCreateInfoMETA` to `swapchain`.
fn apply_eye_tracked_high(app: &App, session: xr::Session, swapchain: xr::Swapchain) {
    let create_profile: xr::pfn::CreateFoveationProfileFB = func(app, "xrCreateFoveationProfileFB");
    let destroy_profile: xr::pfn::DestroyFoveationProfileFB =
        func(app, "xrDestroyFoveationProfileFB");
    let update: xr::pfn::UpdateSwapchainFB = func(app, "xrUpdateSwapchainFB");
    let tracked = xr::FoveationEyeTrackedProfileCreateInfoMETA {
        ty: xr::StructureType::FOVEATION_EYE_TRACKED_PROFILE_CREATE_INFO_META,
        next: null(),
        flags: xr::FoveationEyeTrackedProfileCreateFlagsMETA::EMPTY,
    };
    let mut level = level_info(3, 0, 0.0);
    level.next = &tracked as *const _ as *mut c_void;
    let pi = xr::FoveationProfileCreateInfoFB {
        ty: xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
        next: &level as *const _ as *mut c_void,
    };
    let mut profile = xr::FoveationProfileFB::NULL;
    // SAFETY: the structs live across the calls.
    unsafe {
        assert_eq!(
            create_profile(session, &pi, &mut profile),
            xr::Result::SUCCESS
        );
        let state = crate::support::foveation_state(profile, 0);
        assert_eq!(
            update(swapchain, &state as *const _ as *const _),
            xr::Result::SUCCESS
        );
        assert_eq!(destroy_profile(profile), xr::Result::SUCCESS);
    }
}

/// What fovea must show in a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Want {
    /// Each view's fovea where the gaze at these angles (yaw, pitch; degrees) puts it.
    At([f32; 2]),
    /// Fixed foveation.
    Fixed,
}

/// The whole-texel shift of each view's rates from the fixed map, found among the shifts within
/// one texel of where `want` puts that view's fovea; panics naming the frame where none matches.
fn check_frame(case: &str, f: &Seen, want: Want) -> [[i32; 2]; 2] {
    let t = Profile::Nvidia.texel();
    let grid = Grid::new([WIDTH, HEIGHT], [t.width, t.height]);
    let pattern = Pattern {
        level: Level::High,
        vertical_offset_deg: 0.0,
    };
    let whole = Rect {
        x: 0,
        y: 0,
        width: WIDTH,
        height: HEIGHT,
    };
    let fovs = [f.eyes[0].fov, f.eyes[1].fov];
    let views = Layout::Multiview.views(fovs, true);
    let fixed = expected_codes(Profile::Nvidia, &views, pattern, false);
    let layer = fixed.len() / 2;
    let mut out = [[0; 2]; 2];
    for (eye, got) in f.codes.iter().enumerate() {
        let view = View {
            fov: fovs[eye],
            rect: whole,
            visible: None,
        };
        let fixed = &fixed[eye * layer..(eye + 1) * layer];
        let exact = match want {
            Want::Fixed => [0.0; 2],
            Want::At(angles) => {
                let gaze = Gaze {
                    angles,
                    weight: 1.0,
                    tracking: Tracking::Tracked,
                };
                let to = pixel_of(&view, eye_centre(&gaze, &f.eyes[eye], FIXATION_M));
                let from = pixel_of(&view, view.fov.projection_center_ndc());
                [0, 1].map(|i| (to[i] - from[i]) / grid.texel[i] as f32)
            }
        };
        let mut found = None;
        let mut shifted = vec![0u8; layer];
        'search: for sx in exact[0].floor() as i32 - 1..=exact[0].ceil() as i32 + 1 {
            for sy in exact[1].floor() as i32 - 1..=exact[1].ceil() as i32 + 1 {
                if (sx as f32 - exact[0]).abs() > 1.0 || (sy as f32 - exact[1]).abs() > 1.0 {
                    continue;
                }
                shifted.copy_from_slice(fixed);
                shift_codes_into(&grid, &view, [sx, sy], fixed, &mut shifted);
                if shifted == *got {
                    found = Some([sx, sy]);
                    break 'search;
                }
            }
        }
        out[eye] = found.unwrap_or_else(|| {
            panic!(
                "{case} (t = {} ms): view {eye}'s rates are not the fixed map shifted within a \
                 texel of {exact:?} texels ({want:?})",
                f.t_ns / MS
            )
        });
    }
    out
}

/// The script of [`the_fovea_follows_the_gaze`]: fixations joined by saccades (instant jumps, which
/// reset the filter), a blink held through, and a loss long enough to go back to fixed foveation.
const SCRIPT: &str = "hz=120; fix 0,0 for 1s; fix 12,6 for 500ms; fix -10,-5 for 500ms; \
                      blink 150ms; fix for 500ms; lost 1200ms; fix 8,-6 for 600ms";

/// Where [`SCRIPT`] says the fovea must be at `t_ns`, where that is sure: `None` within two
/// samples of a change, and while the gaze source starts, holds after a loss or eases back.
fn want_at(t_ns: i64) -> Option<Want> {
    let sample = 1_000_000_000 / 120 + 1;
    let phases: [(i64, i64, Want); 6] = [
        (1000, 1500, Want::At([12.0, 6.0])),
        (1500, 2000, Want::At([-10.0, -5.0])),
        // The blink (150 ms) is held through: the fovea stays.
        (2000, 2650, Want::At([-10.0, -5.0])),
        // Lost: held for 300 ms, then eased back over 300 ms.
        (2650, 2900, Want::At([-10.0, -5.0])),
        (3300, 3850, Want::Fixed),
        (3850, 4450, Want::At([8.0, -6.0])),
    ];
    phases.iter().find_map(|&(from, to, want)| {
        (t_ns >= from * MS + 2 * sample && t_ns < to * MS).then_some(want)
    })
}

#[test]
fn the_fovea_follows_the_gaze_in_fovea_s_maps() {
    follows(
        module_path!(),
        "the_fovea_follows_the_gaze_in_fovea_s_maps",
        Mode::Maps,
    );
}

#[test]
fn injected_maps_follow_the_gaze() {
    follows(module_path!(), "injected_maps_follow_the_gaze", Mode::Inject);
}

/// Frame by frame through [`SCRIPT`]: each view's rates the fixed map shifted to within a texel of
/// the gaze; a saccade lands at the first frame after it; a blink holds; a loss goes back to the
/// fixed map; and the fovea moved at all.
fn follows(module: &str, name: &str, mode: Mode) {
    in_own_process(module, name, || {
        let dir = set_up(name, mode == Mode::Inject);
        // 4.45 s of display time at the simulated headset's 90 Hz.
        let Some(run) = run(mode, SCRIPT, 400, &dir) else {
            return;
        };
        let mut checked = 0;
        let mut shifts = Vec::new();
        for (n, f) in run.frames.iter().enumerate() {
            let Some(want) = want_at(f.t_ns) else {
                continue;
            };
            let s = check_frame(&format!("{mode:?} frame {n}"), f, want);
            shifts.push((f.t_ns, want, s));
            checked += 1;
        }
        assert!(checked > 250, "{mode:?}: {checked} frames checked");
        // The checks above could pass with a fovea that never moves only if every gaze put it at
        // the projection centre; these did not.
        for want in [Want::At([12.0, 6.0]), Want::At([-10.0, -5.0])] {
            let moved = shifts
                .iter()
                .filter(|(_, w, _)| *w == want)
                .all(|(_, _, s)| s.iter().all(|s| *s != [0, 0]));
            assert!(moved, "{mode:?}: the fovea moved for {want:?}: {shifts:?}");
        }
        let fixed = shifts
            .iter()
            .filter(|(_, w, _)| *w == Want::Fixed)
            .all(|(_, _, s)| *s == [[0, 0]; 2]);
        assert!(fixed, "{mode:?}: back to the fixed map: {shifts:?}");
        assert!(!run.log.contains(" ERROR "), "{}", run.log);
    });
}

#[test]
fn an_app_that_applies_offsets_gets_fixed_maps() {
    in_own_process(
        module_path!(),
        "an_app_that_applies_offsets_gets_fixed_maps",
        || {
            let dir = set_up("offsets", false);
            let Some(run) = run(Mode::AppOffsets, SCRIPT, 200, &dir) else {
                return;
            };
            let mut tracked = 0;
            for (n, f) in run.frames.iter().enumerate() {
                // Every frame, whatever the gaze: the fixed map.
                check_frame(&format!("offsets frame {n}"), f, Want::Fixed);
                tracked += usize::from(matches!(want_at(f.t_ns), Some(Want::At(_))));
            }
            assert!(tracked > 50, "the gaze was followed meanwhile: {tracked}");
            assert!(
                run.log.contains("applies density-map offsets to this swapchain itself"),
                "{}",
                run.log
            );
        },
    );
}

/// The `Maps=built/uploaded` pairs of the stats lines, in order.
fn maps_counts(log: &str) -> Vec<(u64, u64)> {
    log.lines()
        .filter_map(|l| {
            let m = l.split_once(" Maps=")?.1;
            let (b, u) = m.split_whitespace().next()?.split_once('/')?;
            Some((b.parse().ok()?, u.parse().ok()?))
        })
        .collect()
}

/// A gaze that trembles inside half a texel (±0.4° of jitter per sample: at most 3 px on this
/// swapchain, where half a texel is 8 px) refills no image once each image holds the moved map;
/// the same gaze moved by a saccade refills each image once.
#[test]
fn a_trembling_gaze_refills_nothing() {
    in_own_process(module_path!(), "a_trembling_gaze_refills_nothing", || {
        let dir = set_up("tremble", false);
        let script = "noise=0.4; fix 12,6 for 4s; fix 12,-6 for 2s";
        let Some(run) = run(Mode::Maps, script, 540, &dir) else {
            return;
        };
        let counts = maps_counts(&run.log);
        assert!(counts.len() >= 5, "a stats line a second: {}", run.log);
        // Lines at 2, 3 and 4 s: the gaze followed since well before, trembling.
        let (built, uploaded) = counts[1];
        assert_eq!(
            counts[3],
            (built, uploaded),
            "trembling refilled: {counts:?}"
        );
        let last = counts[counts.len() - 1];
        assert_eq!(last.0, built, "a move builds no map: {counts:?}");
        assert!(
            (uploaded + 1..=uploaded + 3).contains(&last.1),
            "a saccade refills each of the 3 images once: {counts:?}"
        );
    });
}

/// The same for injected maps: the centres are published, and a map shifted again, only when a
/// fovea moved by half a texel.
#[test]
fn a_trembling_gaze_moves_no_injected_map() {
    in_own_process(
        module_path!(),
        "a_trembling_gaze_moves_no_injected_map",
        || {
            let dir = set_up("tremble-inject", true);
            let script = "noise=0.4; fix 12,6 for 4s; fix 12,-6 for 2s";
            let Some(run) = run(Mode::Inject, script, 540, &dir) else {
                return;
            };
            let moves: Vec<&str> = run
                .log
                .lines()
                .filter(|l| l.contains("injected shading-rate map's fovea moved"))
                .collect();
            assert!(
                (2..=3).contains(&moves.len()),
                "one move to the fixation, one for the saccade: {moves:#?}"
            );
            for f in &run.frames {
                if (2000 * MS..4000 * MS).contains(&f.t_ns) {
                    check_frame("trembling", f, Want::At([12.0, 6.0]));
                }
            }
        },
    );
}
