//! The fovea lands where the eye looks, once (docs/eye-tracking.md#what-moves-when), end to end on
//! the simulated runtime's scripted gaze.
//!
//! Stack: as [`crate::both::fdm_emulated`]: this test as an OpenXR application → fovea's OpenXR
//! layer → the simulated runtime with an eye tracker (`XR_EXT_eye_gaze_interaction`, its gaze from
//! a script), the application's VkInstance and VkDevice made through XR_KHR_vulkan_enable2 with
//! fovea's Vulkan layer → VK_LAYER_KHRONOS_validation → the shading-rate double (`nvidia`: 16×16
//! texels, one shading-rate layer per view; `amd`: 8×8, one layer with the finer rate of both
//! views) → lavapipe. The application renders both eyes into an
//! array swapchain of two layers with one multiview render pass a frame, and submits them as one
//! projection layer. It attaches an action set of its own and never syncs: fovea's set goes down
//! with its attach, and fovea syncs it alone each frame.
//!
//! Three modes:
//! - **maps**: the application asks for `XR_FB_foveation_vulkan` with an eye-tracked HIGH profile
//!   (`XrFoveationEyeTrackedProfileCreateInfoMETA`) and renders through fovea's density images:
//!   fovea moves the fovea in them;
//! - **app offsets**: the same, the swapchain created with `FRAGMENT_DENSITY_MAP_OFFSET_BIT` in
//!   `XrVulkanSwapchainCreateInfoMETA`: the application moves the fovea itself, fovea's maps stay
//!   fixed. Its device enables `VK_EXT_fragment_density_map_offset` (which fovea's Vulkan layer
//!   emulates) with its feature; each frame it reads `xrGetFoveationEyeTrackedStateMETA` and ends
//!   its pass with `vkCmdEndRenderPass2` and each view's offset, a multiple of
//!   `fragmentDensityOffsetGranularity` (`fovea_model::shift::pixel_offset`, META's +y down turned
//!   up): the rates are the fixed map shifted by exactly those offsets, not twice. On a device
//!   without the extension it sends none, and the maps stay fixed;
//! - **injection**: an application that never asks for foveation, `FOVEA_INJECT=1` at HIGH: the
//!   injected maps follow the gaze.
//!
//! Per frame the double reports what the draw shaded at, per view and shading-rate texel, and the
//! gaze source logs (at `trace` on `fovea::gaze`) the filtered gaze it located for that frame's
//! display time: its tracking state and each view's centre. Each view's rates must be the fixed
//! map's (the density model for the located FOV, converted as `fovea_model::shading_rate` does)
//! shifted by a whole number of texels (`fovea_model::shift::shift_codes_into`), within one texel of
//! that view's centre; fixed foveation is the shift 0. The script's fixations, saccade, blink and
//! loss are checked on top: the fovea moved, a saccade lands at once, a blink holds, a loss goes
//! back to the fixed map. Validation must say nothing and the double
//! record no misuse. Each test runs in a process of its own (`FOVEA_INJECT` and the log are read
//! from the environment once).
//!
//! The maps and app-offsets tests create eye-tracked profiles through fovea's
//! `XR_META_foveation_eye_tracked`.

use std::ffi::c_void;
use std::ptr::{null, null_mut};

use fovea_harness::app::API_1_0;
use fovea_harness::sim::control::{EyeGaze, SimConfig};
use fovea_harness::sim::gaze_script::GazeScript;
use fovea_harness::vulkan::{self, pick_lavapipe, take_messages, Vulkan};
use fovea_harness::{App, Chain};
use fovea_model::density::{Grid, Level, Pattern};
use fovea_model::gaze::Tracking;
use fovea_model::shading_rate;
use fovea_model::shift::{pixel_of, pixel_offset, shift_codes_into};
use fovea_model::Fov;
use fovea_vkdouble::Profile;
use openxr_sys as xr;
use xr::Handle as _;

use crate::both::fdm_emulated::{
    color_images, expected_codes, rates_drawn, release, Layout, Renderer,
};
use crate::both::fdm_vulkan::{
    apply_profile, enumerate, func, running_session, swapchain_info, vulkan_or_skip, whole_view,
    Frame, FDM_BIT, HEIGHT, VALIDATED, WIDTH,
};
use crate::support::device::env;
use crate::support::gaze_log::{located, Located};
use crate::support::{in_own_process, level_info};

const MS: i64 = 1_000_000;
/// The simulated runtime's clock when its instance is created; a session created before the first
/// frame starts its eye tracker's script there (`crates/sim/src/instance.rs`).
const CLOCK_START_NS: i64 = 1_000_000_000_000;
/// `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT`.
const FDM_OFFSET_BIT: u64 = 0x8000;

/// Who moves the fovea.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Mode {
    Maps,
    /// The swapchain asks for `FDM_OFFSET_BIT`; `enabled`: the device enables
    /// `VK_EXT_fragment_density_map_offset` with its feature, and the application ends each pass
    /// with the offsets that put the fovea on each view's centre from
    /// `xrGetFoveationEyeTrackedStateMETA`.
    AppOffsets {
        enabled: bool,
    },
    Inject,
}

/// `VK_EXT_fragment_density_map_offset`, which fovea's Vulkan layer offers on the double.
const OFFSET_EXT: &std::ffi::CStr = c"VK_EXT_fragment_density_map_offset";

/// What one frame drew.
struct Seen {
    /// Its predicted display time, from the script's start.
    t_ns: i64,
    /// The views' FOVs as located for it.
    fovs: [Fov; 2],
    /// Per shading-rate layer, the rates the draw shaded at (codes, one per texel): one layer per
    /// view on `nvidia`, one merged layer for both on `amd`.
    codes: Vec<Vec<u8>>,
    /// Per view, the density-map offset the application ended its pass with, in pixels.
    applied: [[i32; 2]; 2],
}

/// What a run left: every frame and the log.
struct Run {
    frames: Vec<Seen>,
    log: String,
}

/// Sets the log up for this (child) process; `inject` turns injection on at HIGH.
fn set_up(label: &str, inject: bool) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("fovea-gaze-{label}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::env::set_var(
        "FOVEA_LOG",
        format!(
            "info,{}=trace,fovea::vk::own::injector=debug",
            fovea_abi::log_target::GAZE
        ),
    );
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

/// Set in a test's own process: the device fovea's Vulkan layer emulates on gets no converter
/// (its shader module fails to be made), so it converts nothing, and density-map offsets cannot
/// be applied there.
static NO_CONVERTER: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Set in a test's own process: the application's device has two graphics queues (the double
/// offers a second, `crates/vkdouble/src/layer/queues.rs`), and each frame, once its pass is
/// recorded, it submits an unrelated empty command buffer on queue 1 before the pass on queue 0.
/// fovea's upload of the moved map goes ahead of the first of the two, on queue 1, whose work the
/// double holds back until something depends on it: the pass on queue 0 must wait for it.
static TWO_QUEUES: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// `frames` frames of `mode` on `profile` with the eye following `script`; `None` after a skip.
fn run(
    mode: Mode,
    profile: Profile,
    script: &str,
    frames: usize,
    dir: &std::path::Path,
) -> Option<Run> {
    let (_serial, env) = env()?;
    let _validated = VALIDATED.lock();
    let two_queues = TWO_QUEUES.load(std::sync::atomic::Ordering::Relaxed);
    // Before the instance: validation reads the queue families when it sees the physical device.
    env.double.set_queues(if two_queues { 2 } else { 0 });
    env.double.set_profile(Some(profile));
    crate::support::device::assert_no_double_errors(env);
    env.double.clear();
    take_messages();
    if NO_CONVERTER.load(std::sync::atomic::Ordering::Relaxed) {
        // The first shader module made after this is the converter's, at vkCreateDevice.
        env.double.fail(
            "vkCreateShaderModule",
            0,
            ash::vk::Result::ERROR_OUT_OF_DEVICE_MEMORY,
        );
    }
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
    let mut offset_feature = ash::vk::PhysicalDeviceFragmentDensityMapOffsetFeaturesQCOM::default()
        .fragment_density_map_offset(true);
    let multiview = ash::vk::PhysicalDeviceMultiviewFeatures {
        multiview: ash::vk::TRUE,
        p_next: &mut offset_feature as *mut _ as *mut c_void,
        ..Default::default()
    };
    let applies = mode == Mode::AppOffsets { enabled: true };
    let extensions = [OFFSET_EXT];
    let options = if applies {
        // `vkCmdEndRenderPass2` is Vulkan 1.2's.
        vulkan::Options {
            layers: &layers,
            api_version: ash::vk::API_VERSION_1_2,
            device_extensions: &extensions,
            device_next: &multiview as *const _ as *const c_void,
            ..Default::default()
        }
    } else {
        vulkan::Options {
            layers: &layers,
            multiview: true,
            queues: if two_queues { 2 } else { 1 },
            ..Default::default()
        }
    };
    let (app, v) = vulkan_or_skip(&env.entry, app, sys, &options)?;
    let (session, space) = running_session(&app, sys, &v);
    attach_a_set(&app, session);
    let create_swapchain: xr::pfn::CreateSwapchain = func(&app, "xrCreateSwapchain");
    let offsets = xr::VulkanSwapchainCreateInfoMETA {
        ty: xr::StructureType::VULKAN_SWAPCHAIN_CREATE_INFO_META,
        next: null(),
        additional_create_flags: FDM_OFFSET_BIT,
        additional_usage_flags: 0,
    };
    let fdm_flag = xr::SwapchainCreateInfoFoveationFB {
        ty: xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
        next: if matches!(mode, Mode::AppOffsets { .. }) {
            &offsets as *const _ as *mut c_void
        } else {
            null_mut()
        },
        flags: xr::SwapchainCreateFoveationFlagsFB::from_raw(FDM_BIT),
    };
    let next = match mode {
        Mode::Inject => null(),
        Mode::Maps | Mode::AppOffsets { .. } => &fdm_flag as *const _ as *const c_void,
    };
    let info = swapchain_info(next);
    let mut swapchain = xr::Swapchain::NULL;
    // SAFETY: the create info, its chain and the output live across the call.
    let r = unsafe { create_swapchain(session, &info, &mut swapchain) };
    assert_eq!(r, xr::Result::SUCCESS, "{mode:?}");
    let color = color_images(&app, swapchain);
    let density: Option<Vec<u64>> = (mode != Mode::Inject)
        .then(|| enumerate(&app, swapchain).iter().map(|d| d.image).collect());
    let renderer = Renderer::new(&v, Layout::Multiview, &color, density.as_deref());
    // The unrelated work submitted on queue 1 each frame (see [`TWO_QUEUES`]).
    // SAFETY: the device is alive; the command buffer is the renderer's pool's, recorded once.
    let other = two_queues.then(|| unsafe {
        let cb = v
            .device
            .allocate_command_buffers(
                &ash::vk::CommandBufferAllocateInfo::default()
                    .command_pool(renderer.pool)
                    .level(ash::vk::CommandBufferLevel::PRIMARY)
                    .command_buffer_count(1),
            )
            .expect("vkAllocateCommandBuffers")[0];
        v.device
            .begin_command_buffer(cb, &ash::vk::CommandBufferBeginInfo::default())
            .expect("vkBeginCommandBuffer");
        v.device.end_command_buffer(cb).expect("vkEndCommandBuffer");
        (v.device.get_device_queue(v.family, 1), cb)
    });
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
    let granularity = applies.then(|| {
        let g = offset_granularity(&v);
        assert_eq!(
            [g.width, g.height],
            [t.width, t.height],
            "the shading-rate texel"
        );
        g
    });
    let mut seen = Vec::new();
    for n in 0..frames {
        poll_events(&app);
        let case = format!("{mode:?} {} frame {n}", profile.name());
        crate::support::device::assert_no_double_errors(env);
        env.double.clear();
        let (index, fovs, time) = frame.acquire(swapchain);
        let applied =
            granularity.map_or([[0; 2]; 2], |g| offsets_from_state(&app, session, fovs, g));
        let ends_with = applied.map(|[x, y]| ash::vk::Offset2D { x, y });
        renderer.draw_after(
            &v.device,
            renderer.cb,
            index,
            applies.then_some(&ends_with[..]),
            other,
        );
        release(&frame, Layout::Multiview, swapchain, time, fovs);
        let layers = if profile.layered() { 2 } else { 1 };
        let got = rates_drawn(env, &case, Layout::Multiview, layers, extent);
        assert_eq!(got.len(), layers as usize * texels, "{case}");
        seen.push(Seen {
            t_ns: time.as_nanos() - CLOCK_START_NS,
            fovs,
            codes: got.chunks_exact(texels).map(<[u8]>::to_vec).collect(),
            applied,
        });
    }
    assert_eq!(env.double.errors(), Vec::<String>::new(), "{mode:?}");
    renderer.destroy(&v.device);
    env.double.set_queues(0);
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

/// `fragmentDensityOffsetGranularity`, as the device reports it.
fn offset_granularity(v: &Vulkan) -> ash::vk::Extent2D {
    let mut offsets = ash::vk::PhysicalDeviceFragmentDensityMapOffsetPropertiesQCOM::default();
    let mut props = ash::vk::PhysicalDeviceProperties2::default().push_next(&mut offsets);
    // SAFETY: the physical device is the instance's; the structs live across the call.
    unsafe {
        v.instance
            .get_physical_device_properties2(v.physical_device, &mut props)
    };
    offsets.fragment_density_offset_granularity
}

/// What an application that applies `XR_META_foveation_eye_tracked` with density-map offsets does
/// each frame, as Godot does: each view's centre from `xrGetFoveationEyeTrackedStateMETA` (NDC of
/// the view's FOV, +y down, META's default) turned into the offset, a whole number of
/// `granularity` per axis, that carries the fixed map's fovea there
/// (`fovea_model::shift::pixel_offset`). A view whose state is not `VALID` still gets the centre
/// fovea reports (where it holds the gaze, or the fixed map's).
fn offsets_from_state(
    app: &App,
    session: xr::Session,
    fovs: [Fov; 2],
    granularity: ash::vk::Extent2D,
) -> [[i32; 2]; 2] {
    let get_state: xr::pfn::GetFoveationEyeTrackedStateMETA =
        func(app, "xrGetFoveationEyeTrackedStateMETA");
    let mut state = xr::FoveationEyeTrackedStateMETA {
        ty: xr::StructureType::FOVEATION_EYE_TRACKED_STATE_META,
        next: null_mut(),
        foveation_center: [xr::Vector2f { x: 0.0, y: 0.0 }; 2],
        flags: xr::FoveationEyeTrackedStateFlagsMETA::EMPTY,
    };
    // SAFETY: the struct lives across the call.
    assert_eq!(
        unsafe { get_state(session, &mut state) },
        xr::Result::SUCCESS
    );
    let grid = Grid::new([WIDTH, HEIGHT], [granularity.width, granularity.height]);
    [0, 1].map(|eye| {
        let c = state.foveation_center[eye];
        pixel_offset(&grid, &whole_view(fovs[eye]), [c.x, -c.y])
    })
}

/// Polls every queued event, as applications do once a frame (fovea syncs its set alone for this
/// application, which never syncs, only once the session it polled is FOCUSED).
fn poll_events(app: &App) {
    let poll: xr::pfn::PollEvent = func(app, "xrPollEvent");
    loop {
        let mut event = xr::EventDataBuffer {
            ty: xr::StructureType::EVENT_DATA_BUFFER,
            next: null(),
            varying: [0; 4000],
        };
        // SAFETY: the buffer lives across the call.
        if unsafe { poll(app.instance, &mut event) } != xr::Result::SUCCESS {
            return;
        }
    }
}

/// Attaches an action set of the application's own (with one boolean action, bound to nothing),
/// as applications with input do: fovea's set goes down with it.
fn attach_a_set(app: &App, session: xr::Session) {
    let create_set: xr::pfn::CreateActionSet = func(app, "xrCreateActionSet");
    let create_action: xr::pfn::CreateAction = func(app, "xrCreateAction");
    let attach: xr::pfn::AttachSessionActionSets = func(app, "xrAttachSessionActionSets");
    let name = |s: &str| {
        let mut out = [0 as std::ffi::c_char; 64];
        for (o, b) in out.iter_mut().zip(s.bytes()) {
            *o = b as std::ffi::c_char;
        }
        out
    };
    let mut set_info = xr::ActionSetCreateInfo {
        ty: xr::StructureType::ACTION_SET_CREATE_INFO,
        next: null(),
        action_set_name: name("menu"),
        localized_action_set_name: [0; 128],
        priority: 0,
    };
    set_info.localized_action_set_name[..4].copy_from_slice(&name("Menu")[..4]);
    let mut set = xr::ActionSet::NULL;
    let mut action_info = xr::ActionCreateInfo {
        ty: xr::StructureType::ACTION_CREATE_INFO,
        next: null(),
        action_name: name("select"),
        action_type: xr::ActionType::BOOLEAN_INPUT,
        count_subaction_paths: 0,
        subaction_paths: null(),
        localized_action_name: [0; 128],
    };
    action_info.localized_action_name[..6].copy_from_slice(&name("Select")[..6]);
    let mut action = xr::Action::NULL;
    // SAFETY: every struct lives across its call.
    unsafe {
        assert_eq!(
            create_set(app.instance, &set_info, &mut set),
            xr::Result::SUCCESS
        );
        assert_eq!(
            create_action(set, &action_info, &mut action),
            xr::Result::SUCCESS
        );
        let sets = [set];
        let info = xr::SessionActionSetsAttachInfo {
            ty: xr::StructureType::SESSION_ACTION_SETS_ATTACH_INFO,
            next: null(),
            count_action_sets: 1,
            action_sets: sets.as_ptr(),
        };
        assert_eq!(attach(session, &info), xr::Result::SUCCESS);
    }
}

/// The gaze located for the frame shown at `t_ns` (from the script's start), if any.
fn gaze_for(gaze: &[Located], t_ns: i64) -> Option<&Located> {
    gaze.iter()
        .rev()
        .find(|g| g.time_ns == t_ns + CLOCK_START_NS)
}

/// Applies a HIGH profile created with `XrFoveationEyeTrackedProfileCreateInfoMETA` to `swapchain`.
fn apply_eye_tracked_high(app: &App, session: xr::Session, swapchain: xr::Swapchain) {
    let tracked = xr::FoveationEyeTrackedProfileCreateInfoMETA {
        ty: xr::StructureType::FOVEATION_EYE_TRACKED_PROFILE_CREATE_INFO_META,
        next: null(),
        flags: xr::FoveationEyeTrackedProfileCreateFlagsMETA::EMPTY,
    };
    let mut level = level_info(3, 0, 0.0);
    level.next = &tracked as *const _ as *mut c_void;
    apply_profile(app, session, swapchain, &level);
}

/// What fovea must show in a frame.
#[derive(Clone, Debug, PartialEq)]
enum Want {
    /// Each view's fovea at this centre (NDC of its own FOV, y up).
    At([[f32; 2]; 2]),
    /// Fixed foveation.
    Fixed,
}

impl Want {
    /// What the gaze located for a frame asks of its maps.
    fn of(g: &Located) -> Want {
        if g.tracking == Tracking::Fixed || g.ndc.len() < 2 {
            Want::Fixed
        } else {
            Want::At([g.ndc[0], g.ndc[1]])
        }
    }
}

/// The whole shifts within one texel of `exact` (texels, per axis), nearest first.
fn candidates(exact: [f32; 2]) -> Vec<[i32; 2]> {
    let mut out = Vec::new();
    for sx in exact[0].floor() as i32 - 1..=exact[0].ceil() as i32 + 1 {
        for sy in exact[1].floor() as i32 - 1..=exact[1].ceil() as i32 + 1 {
            if (sx as f32 - exact[0]).abs() <= 1.0 && (sy as f32 - exact[1]).abs() <= 1.0 {
                out.push([sx, sy]);
            }
        }
    }
    let d = |s: &[i32; 2]| (s[0] as f32 - exact[0]).powi(2) + (s[1] as f32 - exact[1]).powi(2);
    out.sort_by(|a, b| d(a).total_cmp(&d(b)));
    out
}

/// The whole-texel shift of each view's rates from the fixed map, found among the shifts within
/// one texel of where `want` puts that view's fovea; panics naming the frame where none matches.
/// On `amd` both views share one merged layer: each view's fixed codes shifted, then per texel the
/// finer of the two (docs/vulkan-fdm-on-fsr.md#multiview), for every pair of candidate shifts.
fn check_frame(case: &str, profile: Profile, f: &Seen, want: &Want) -> [[i32; 2]; 2] {
    let t = profile.texel();
    let grid = Grid::new([WIDTH, HEIGHT], [t.width, t.height]);
    let pattern = Pattern {
        level: Level::High,
        vertical_offset_deg: 0.0,
    };
    let fovs = f.fovs;
    let views = Layout::Multiview.views(fovs, true);
    let fixed = expected_codes(profile, &views, pattern, false);
    let layer = fixed.len() / 2;
    let view = |eye: usize| whole_view(fovs[eye]);
    let exact = |eye: usize| match want {
        Want::Fixed => [0.0; 2],
        Want::At(ndc) => {
            let v = view(eye);
            let to = pixel_of(&v, ndc[eye]);
            let from = pixel_of(&v, v.fov.projection_center_ndc());
            [0, 1].map(|i| (to[i] - from[i]) / grid.texel[i] as f32)
        }
    };
    let shifted = |eye: usize, s: [i32; 2]| {
        let fixed = &fixed[eye * layer..(eye + 1) * layer];
        let mut out = fixed.to_vec();
        shift_codes_into(&grid, &view(eye), s, fixed, &mut out);
        out
    };
    let fail = |what: &str| -> ! {
        panic!(
            "{case} (t = {} ms): {what} not the fixed map shifted within a texel of {:?} / {:?} \
             texels ({want:?})",
            f.t_ns / MS,
            exact(0),
            exact(1),
        )
    };
    if f.codes.len() == 2 {
        let mut out = [[0; 2]; 2];
        for (eye, got) in f.codes.iter().enumerate() {
            out[eye] = candidates(exact(eye))
                .into_iter()
                .find(|&s| shifted(eye, s) == *got)
                .unwrap_or_else(|| fail(&format!("view {eye}'s rates are")));
        }
        return out;
    }
    let rates: Vec<[u32; 2]> = profile
        .rates()
        .iter()
        .map(|(e, _)| [e.width, e.height])
        .collect();
    let (c0, c1) = (candidates(exact(0)), candidates(exact(1)));
    let left: Vec<Vec<u8>> = c0.iter().map(|&s| shifted(0, s)).collect();
    let right: Vec<Vec<u8>> = c1.iter().map(|&s| shifted(1, s)).collect();
    let mut merged = vec![0u8; layer];
    for (i, l) in left.iter().enumerate() {
        for (j, r) in right.iter().enumerate() {
            let both = [l.as_slice(), r.as_slice()].concat();
            shading_rate::merge_codes(&both, layer, &rates, &mut merged);
            if merged == f.codes[0] {
                return [c0[i], c1[j]];
            }
        }
    }
    fail("the merged rates are")
}

/// What a draw through the fixed map for `fovs` shades at with each view's map shifted by `shifts`
/// whole texels: a layer per view, or on a device with one layer for both views the finer of the
/// two per texel (docs/vulkan-fdm-on-fsr.md#multiview).
fn fixed_shifted(profile: Profile, fovs: [Fov; 2], shifts: [[i32; 2]; 2]) -> Vec<Vec<u8>> {
    let t = profile.texel();
    let grid = Grid::new([WIDTH, HEIGHT], [t.width, t.height]);
    let pattern = Pattern {
        level: Level::High,
        vertical_offset_deg: 0.0,
    };
    let fixed = expected_codes(
        profile,
        &Layout::Multiview.views(fovs, true),
        pattern,
        false,
    );
    let layer = fixed.len() / 2;
    let views: Vec<Vec<u8>> = (0..2)
        .map(|eye| {
            let fixed = &fixed[eye * layer..(eye + 1) * layer];
            let mut out = fixed.to_vec();
            shift_codes_into(&grid, &whole_view(fovs[eye]), shifts[eye], fixed, &mut out);
            out
        })
        .collect();
    if profile.layered() {
        return views;
    }
    let rates: Vec<[u32; 2]> = profile
        .rates()
        .iter()
        .map(|(e, _)| [e.width, e.height])
        .collect();
    let mut merged = vec![0u8; layer];
    shading_rate::merge_codes(&views.concat(), layer, &rates, &mut merged);
    vec![merged]
}

/// The script of the following tests: fixations joined by jumps (saccades, which reset the filter),
/// a blink held through, smooth pursuit, and a loss long enough to go back to fixed foveation.
const SCRIPT: &str = "hz=120; fix 0,0 for 300ms; fix 12,6 for 500ms; fix -10,-5 for 500ms; \
                      blink 150ms; fix for 300ms; pursue 10,5 at 30; lost 1200ms; \
                      fix 8,-6 for 600ms";

#[test]
fn the_fovea_follows_the_gaze_in_fovea_s_maps() {
    follows(
        module_path!(),
        "the_fovea_follows_the_gaze_in_fovea_s_maps",
        Mode::Maps,
        Profile::Nvidia,
    );
}

/// On a device with one shading-rate layer for both views, each view's codes move before they are
/// merged.
#[test]
fn the_fovea_follows_the_gaze_in_fovea_s_merged_maps() {
    follows(
        module_path!(),
        "the_fovea_follows_the_gaze_in_fovea_s_merged_maps",
        Mode::Maps,
        Profile::Amd,
    );
}

/// The application moves the fovea itself: it ends each pass with the density-map offsets it
/// computes from `xrGetFoveationEyeTrackedStateMETA`, on fovea's density images, which fovea makes
/// with `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT` and keeps fixed, so the emulated
/// offsets apply to them and the fovea moves once.
#[test]
fn the_fovea_follows_the_gaze_by_the_app_s_offsets() {
    follows(
        module_path!(),
        "the_fovea_follows_the_gaze_by_the_app_s_offsets",
        Mode::AppOffsets { enabled: true },
        Profile::Nvidia,
    );
}

/// The same with one shading-rate layer for both views.
#[test]
fn the_fovea_follows_the_gaze_by_the_app_s_offsets_in_merged_maps() {
    follows(
        module_path!(),
        "the_fovea_follows_the_gaze_by_the_app_s_offsets_in_merged_maps",
        Mode::AppOffsets { enabled: true },
        Profile::Amd,
    );
}

#[test]
fn injected_maps_follow_the_gaze() {
    follows(
        module_path!(),
        "injected_maps_follow_the_gaze",
        Mode::Inject,
        Profile::Nvidia,
    );
}

#[test]
fn merged_injected_maps_follow_the_gaze() {
    follows(
        module_path!(),
        "merged_injected_maps_follow_the_gaze",
        Mode::Inject,
        Profile::Amd,
    );
}

/// The injected maps follow the gaze on an application that renders on one of two graphics
/// queues and submits other work on the second first ([`TWO_QUEUES`]): each pass's rates are the
/// map published for its frame, not the one before (issue 28 point 4: without fovea's timeline
/// ordering the pass overtakes the upload on the other queue and draws with the last frame's map).
#[test]
fn injected_maps_follow_the_gaze_across_two_queues() {
    follows_with(
        module_path!(),
        "injected_maps_follow_the_gaze_across_two_queues",
        Mode::Inject,
        Profile::Nvidia,
        true,
    );
}

/// Frame by frame through [`SCRIPT`]: each view's rates the fixed map shifted to within a texel of
/// the gaze located for that frame; then what the script's events must look like.
fn follows(module: &str, name: &str, mode: Mode, profile: Profile) {
    follows_with(module, name, mode, profile, false);
}

/// [`follows`], on two queues with `two_queues` ([`TWO_QUEUES`]).
fn follows_with(module: &str, name: &str, mode: Mode, profile: Profile, two_queues: bool) {
    in_own_process(module, name, || {
        TWO_QUEUES.store(two_queues, std::sync::atomic::Ordering::Relaxed);
        let dir = set_up(name, mode == Mode::Inject);
        // 5 s of display time at the simulated headset's 90 Hz.
        let Some(run) = run(mode, profile, SCRIPT, 450, &dir) else {
            return;
        };
        let gaze = located(run.log.lines());
        let mut moved_once = 0;
        let mut shifts: Vec<(&Located, [[i32; 2]; 2])> = Vec::new();
        for (n, f) in run.frames.iter().enumerate() {
            let case = format!("{mode:?} {} frame {n}", profile.name());
            let want = gaze_for(&gaze, f.t_ns).map_or(Want::Fixed, Want::of);
            let s = check_frame(&case, profile, f, &want);
            if mode == (Mode::AppOffsets { enabled: true }) {
                moved_once += usize::from(moved_once_by_the_app(&case, profile, f));
            }
            if let Some(g) = gaze_for(&gaze, f.t_ns) {
                shifts.push((g, s));
            }
        }
        assert!(
            shifts.len() > 400,
            "{mode:?}: a gaze a frame: {}",
            shifts.len()
        );
        if mode == (Mode::AppOffsets { enabled: true }) {
            assert!(
                moved_once > 200,
                "frames the app moved the fovea: {moved_once}"
            );
            assert!(
                run.log.contains("FRAGMENT_DENSITY_MAP_OFFSET"),
                "fovea's density images take offsets: {}",
                run.log
            );
        }
        let at = |yaw: f32, pitch: f32| {
            move |g: &Located| {
                g.tracking == Tracking::Tracked
                    && (g.angles[0] - yaw).abs() < 0.01
                    && (g.angles[1] - pitch).abs() < 0.01
            }
        };
        // The fixations moved the fovea, each view's its own way, and the saccade between them
        // landed at the first frame that located the gaze there.
        let first = |p: &dyn Fn(&Located) -> bool| {
            shifts
                .iter()
                .position(|(g, _)| p(g))
                .unwrap_or_else(|| panic!("{mode:?}: no frame for the fixation: {gaze:?}"))
        };
        let a = first(&at(12.0, 6.0));
        let b = first(&at(-10.0, -5.0));
        let (sa, sb) = (shifts[a].1, shifts[b].1);
        assert!(
            sa[0][0] > 0 && sa[0][1] < 0,
            "{mode:?}: right and up: {sa:?}"
        );
        assert!(
            sb[0][0] < 0 && sb[0][1] > 0,
            "{mode:?}: left and down: {sb:?}"
        );
        assert_ne!(shifts[b - 1].1, sb, "{mode:?}: the saccade lands at once");
        // The blink is held: the frames held show the fovea where it was.
        let held: Vec<_> = shifts
            .iter()
            .skip(b)
            .take_while(|(g, _)| g.tracking != Tracking::Returning)
            .filter(|(g, _)| g.tracking == Tracking::Held)
            .take(10)
            .collect();
        assert!(held.len() >= 10, "{mode:?}: the blink held");
        assert!(
            held.iter().all(|(_, s)| *s == sb),
            "{mode:?}: held where it was: {held:?}"
        );
        // The loss ends in fixed foveation: the fixed map, shift 0.
        let fixed: Vec<_> = shifts
            .iter()
            .filter(|(g, _)| {
                g.tracking == Tracking::Fixed && g.time_ns > CLOCK_START_NS + 1000 * MS
            })
            .collect();
        assert!(fixed.len() > 30, "{mode:?}: back to fixed foveation");
        assert!(
            fixed.iter().all(|(_, s)| *s == [[0, 0]; 2]),
            "{mode:?}: {fixed:?}"
        );
        // And back again when the tracker is.
        let c = first(&at(8.0, -6.0));
        assert_ne!(shifts[c].1, [[0, 0]; 2], "{mode:?}");
        assert!(!run.log.contains(" ERROR "), "{}", run.log);
    });
}

/// The same application on a device that did not enable the offset extension: fovea's density
/// images cannot take offsets there, so they are made as for any swapchain and stay fixed, and the
/// log says why once.
#[test]
fn an_app_without_the_offset_extension_gets_fixed_maps() {
    in_own_process(
        module_path!(),
        "an_app_without_the_offset_extension_gets_fixed_maps",
        || {
            let dir = set_up("offsets", false);
            let mode = Mode::AppOffsets { enabled: false };
            let Some(run) = run(mode, Profile::Nvidia, SCRIPT, 200, &dir) else {
                return;
            };
            let gaze = located(run.log.lines());
            let mut tracked = 0;
            for (n, f) in run.frames.iter().enumerate() {
                // Every frame, whatever the gaze: the fixed map.
                check_frame(
                    &format!("offsets frame {n}"),
                    Profile::Nvidia,
                    f,
                    &Want::Fixed,
                );
                tracked += usize::from(
                    gaze_for(&gaze, f.t_ns).is_some_and(|g| g.tracking == Tracking::Tracked),
                );
            }
            assert!(tracked > 50, "the gaze was followed meanwhile: {tracked}");
            assert!(
                run.log
                    .contains("applies density-map offsets to this swapchain itself"),
                "{}",
                run.log
            );
            let why = "did not enable VK_EXT_fragment_density_map_offset or \
                       VK_QCOM_fragment_density_map_offset with fragmentDensityMapOffset";
            assert_eq!(run.log.matches(why).count(), 1, "{}", run.log);
        },
    );
}

/// The same application with the offset extension enabled, on a device where fovea's Vulkan layer
/// cannot convert (here its converter could not be made; elsewhere Vulkan 1.4, maintenance6 or
/// descriptor buffers): offsets cannot apply there, so the device must not report them as
/// applied. fovea's density images are made as for any swapchain and stay fixed, and the log says
/// why once, at the device and at the swapchain. Before the device published whether offsets
/// apply only after deciding whether it converts, the images were made to take offsets that
/// nothing applied, and the log said nothing.
#[test]
fn an_app_whose_device_cannot_convert_gets_fixed_maps_and_a_reason() {
    in_own_process(
        module_path!(),
        "an_app_whose_device_cannot_convert_gets_fixed_maps_and_a_reason",
        || {
            let dir = set_up("offsets-no-converter", false);
            NO_CONVERTER.store(true, std::sync::atomic::Ordering::Relaxed);
            let mode = Mode::AppOffsets { enabled: true };
            let Some(run) = run(mode, Profile::Nvidia, SCRIPT, 200, &dir) else {
                return;
            };
            let gaze = located(run.log.lines());
            let mut tracked = 0;
            for (n, f) in run.frames.iter().enumerate() {
                check_frame(
                    &format!("no converter, frame {n}"),
                    Profile::Nvidia,
                    f,
                    &Want::Fixed,
                );
                tracked += usize::from(
                    gaze_for(&gaze, f.t_ns).is_some_and(|g| g.tracking == Tracking::Tracked),
                );
            }
            assert!(tracked > 50, "the gaze was followed meanwhile: {tracked}");
            assert!(
                run.frames.iter().any(|f| f.applied != [[0, 0]; 2]),
                "the application ended its passes with offsets"
            );
            let device = "no density-map conversion on this device";
            assert_eq!(run.log.matches(device).count(), 1, "{}", run.log);
            let why = "or fovea's Vulkan layer cannot apply offsets on it";
            assert_eq!(run.log.matches(why).count(), 1, "{}", run.log);
        },
    );
}

/// The rates drawn are the fixed map with each view shifted by exactly the offsets the application
/// ended the pass with; where those are not zero, not by twice them (what fovea moving its own map
/// to the gaze as well would give). Returns whether the application moved a view's fovea.
fn moved_once_by_the_app(case: &str, profile: Profile, f: &Seen) -> bool {
    let t = profile.texel();
    let shifts = f.applied.map(|[x, y]| {
        assert_eq!(
            [x % t.width as i32, y % t.height as i32],
            [0, 0],
            "{case}: whole texels"
        );
        [x / t.width as i32, y / t.height as i32]
    });
    assert!(
        fixed_shifted(profile, f.fovs, shifts) == f.codes,
        "{case}: the fixed map shifted by the application's {shifts:?} texels"
    );
    let moved = shifts != [[0, 0]; 2];
    if moved {
        let twice = shifts.map(|s| s.map(|v| 2 * v));
        assert!(
            fixed_shifted(profile, f.fovs, twice) != f.codes,
            "{case}: not shifted twice"
        );
    }
    moved
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
        let script = "noise=0.4; fix 12,6 for 4500ms; fix 12,-6 for 1500ms";
        let Some(run) = run(Mode::Maps, Profile::Nvidia, script, 540, &dir) else {
            return;
        };
        let counts = maps_counts(&run.log);
        assert!(counts.len() >= 5, "a stats line a second: {}", run.log);
        // Lines at 2, 3 and 4 s of display time: the gaze followed since well before, trembling;
        // the saccade at 4.5 s.
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
            let Some(run) = run(Mode::Inject, Profile::Nvidia, script, 540, &dir) else {
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
            let gaze = located(run.log.lines());
            for f in &run.frames {
                if let Some(g) = gaze_for(&gaze, f.t_ns) {
                    check_frame("trembling", Profile::Nvidia, f, &Want::of(g));
                }
            }
        },
    );
}
