//! The layer's added CPU per frame in steady state, and its heap allocations per frame.
//!
//! Both loops run in this process, through the fake loader harness, on the simulated runtime (Quest 3
//! preset, headless): `bare` calls the runtime directly, `fovea` goes through the layer with a
//! foveated multiview swapchain whose state asks for HIGH with dynamic foveation on. A frame is wait,
//! begin, locate views, one acquire/wait/release, end with one two-view projection layer.
//!
//! Allocations are counted by interposing `malloc` and friends in this executable: the layer is a
//! separately dlopened library with its own Rust runtime, so a `#[global_allocator]` here would not
//! see its allocations, but ELF symbol interposition routes its `malloc` calls through these.
//!
//! Following a gaze, side by side in the same run: `fovea+gaze` is the `fovea` loop on a runtime with
//! an eye tracker whose gaze moves every frame (smooth pursuit), its application enabling
//! `XR_META_foveation_eye_tracked` (fovea uses the gaze only where something follows it:
//! docs/eye-tracking.md#who-uses-the-gaze), attaching an action set of its own and polling its
//! events until the session is FOCUSED, so fovea's gaze source syncs, locates and filters a gaze and
//! each view's fovea moves every frame; `fixed` foveation is the `fovea` loop. The summary's `gaze:` line gives what
//! the moving gaze adds, and subtracts the runtime's share of it: an application on the bare runtime
//! making the same three calls per frame ([`AppGaze`]).
//!
//! Besides criterion's own report, the run ends with a summary line: ns per frame for both loops from
//! interleaved timing rounds in the same run (the tenth percentile of 2,000 rounds of 250 frames: see
//! [`summary`]), the difference, the ratio, and allocations per frame.
//!
//! `FOVEA_BENCH_BASELINE=/path/to/libfovea.so` adds a third loop, `baseline`, through that library (an
//! older build of the layer, loaded beside this workspace's own: `dlopen` keeps the two apart), to both
//! criterion's report and the interleaved summary, so that a change is compared with the code it
//! replaces in the same run on the same machine state. `benches/compare-baseline.sh` builds the
//! baseline from a commit and runs this.

use std::time::Instant;

use criterion::{criterion_group, Criterion};
use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::{HeadlessLoop, SwapchainSpec, FOVEATION_EXTENSIONS};
use fovea_harness::{sim, App, Chain, LayerSpec, FOVEA_LAYER};
use openxr_sys as xr;
use xr::Handle;

#[path = "support/alloc.rs"]
mod alloc;
#[path = "support/layer_allocs.rs"]
mod layer_allocs;

fn running_loop(chain: Chain) -> HeadlessLoop {
    running_loop_with(chain, None)
}

/// Where the simulated eye looks in the `fovea+gaze` loop: smooth pursuit back and forth at 30°/s
/// (the speed of smooth pursuit), so the located gaze, and each view's fovea, moves every frame.
const MOVING_GAZE: &str = "hz=120; pursue 15,5 at 30; pursue -15,-5 at 30; loop";

/// A running loop; with `gaze`, the simulated runtime has an eye tracker following that script and
/// the application enables `XR_META_foveation_eye_tracked` and attaches an action set of its own,
/// so fovea's gaze source locates a gaze every frame (fovea's set goes down with the application's
/// attach and is synced alone each frame once the session polled is FOCUSED).
fn running_loop_with(chain: Chain, gaze: Option<&str>) -> HeadlessLoop {
    let mut cfg = sim::control::SimConfig::from_env().expect("simulated runtime configuration");
    cfg.journal = false;
    cfg.eye_gaze = gaze.map(|script| sim::control::EyeGaze {
        supported: true,
        space_after_attach: false,
        script: sim::gaze_script::GazeScript::parse(script).expect("a gaze script"),
    });
    sim::control::set_thread_config(Some(cfg));
    // The bare runtime offers none of the foveation extensions: its loop is the same without them.
    let layered = !chain.layers.is_empty();
    let mut extensions: Vec<&str> = if layered {
        FOVEATION_EXTENSIONS.to_vec()
    } else {
        vec!["XR_MND_headless"]
    };
    if layered && gaze.is_some() {
        extensions.push(EYE_TRACKED);
    }
    let app = App::new(chain, &extensions, API_1_0).expect("instance");
    let spec = SwapchainSpec {
        foveation: layered,
        array_size: 2,
    };
    let mut lp = HeadlessLoop::new(app, spec).expect("session");
    if gaze.is_some() {
        attach_a_set(&lp);
    }
    if layered {
        lp.apply_profile(
            xr::FoveationLevelFB::HIGH,
            xr::FoveationDynamicFB::LEVEL_ENABLED,
        )
        .expect("HIGH dynamic profile");
    }
    for _ in 0..300 {
        lp.poll_events();
        lp.frame().expect("warm-up frame");
    }
    lp
}

/// What makes fovea follow the gaze in the `fovea+gaze` loop.
const EYE_TRACKED: &str = "XR_META_foveation_eye_tracked";

/// `s` in a C string array of `N` (NUL-padded): an action or set name.
fn fixed<const N: usize>(s: &str) -> [std::ffi::c_char; N] {
    let mut out = [0; N];
    for (o, b) in out.iter_mut().zip(s.bytes()) {
        *o = b as std::ffi::c_char;
    }
    out
}

/// Attaches an action set of the application's own with one boolean action, as an application with
/// input does.
fn attach_a_set(lp: &HeadlessLoop) {
    // SAFETY: every name's type matches; every struct lives across its call.
    unsafe {
        let create_set: xr::pfn::CreateActionSet = lp.app.func(c"xrCreateActionSet");
        let create_action: xr::pfn::CreateAction = lp.app.func(c"xrCreateAction");
        let attach: xr::pfn::AttachSessionActionSets = lp.app.func(c"xrAttachSessionActionSets");
        let set_info = xr::ActionSetCreateInfo {
            ty: xr::StructureType::ACTION_SET_CREATE_INFO,
            next: std::ptr::null(),
            action_set_name: fixed("menu"),
            localized_action_set_name: fixed("Menu"),
            priority: 0,
        };
        let mut set = xr::ActionSet::NULL;
        assert_eq!(
            create_set(lp.app.instance, &set_info, &mut set),
            xr::Result::SUCCESS
        );
        let action_info = xr::ActionCreateInfo {
            ty: xr::StructureType::ACTION_CREATE_INFO,
            next: std::ptr::null(),
            action_name: fixed("select"),
            action_type: xr::ActionType::BOOLEAN_INPUT,
            count_subaction_paths: 0,
            subaction_paths: std::ptr::null(),
            localized_action_name: fixed("Select"),
        };
        let mut action = xr::Action::NULL;
        assert_eq!(
            create_action(set, &action_info, &mut action),
            xr::Result::SUCCESS
        );
        let sets = [set];
        let info = xr::SessionActionSetsAttachInfo {
            ty: xr::StructureType::SESSION_ACTION_SETS_ATTACH_INFO,
            next: std::ptr::null(),
            count_action_sets: 1,
            action_sets: sets.as_ptr(),
        };
        assert_eq!(attach(lp.session, &info), xr::Result::SUCCESS);
    }
}

/// The runtime's share of following a gaze, without the layer: an application on the bare runtime
/// (eye tracker on, [`MOVING_GAZE`]) that makes per frame the calls fovea's gaze source makes down
/// (`xrSyncActions` of one set, `xrGetActionStatePose`, `xrLocateSpace` of the gaze action space in
/// VIEW space at the predicted display time with `XrEyeGazeSampleTimeEXT` chained). Timed against
/// `fovea+gaze`, what is left is the layer's own CPU.
struct AppGaze {
    lp: HeadlessLoop,
    set: xr::ActionSet,
    action: xr::Action,
    gaze: xr::Space,
    view: xr::Space,
    sync: xr::pfn::SyncActions,
    pose: xr::pfn::GetActionStatePose,
    locate: xr::pfn::LocateSpace,
}

impl AppGaze {
    fn new() -> AppGaze {
        let mut cfg = sim::control::SimConfig::from_env().expect("simulated runtime configuration");
        cfg.journal = false;
        cfg.eye_gaze = Some(sim::control::EyeGaze {
            supported: true,
            space_after_attach: false,
            script: sim::gaze_script::GazeScript::parse(MOVING_GAZE).expect("a gaze script"),
        });
        sim::control::set_thread_config(Some(cfg));
        let app = App::new(
            Chain::bare(),
            &["XR_MND_headless", "XR_EXT_eye_gaze_interaction"],
            API_1_0,
        )
        .expect("instance");
        let spec = SwapchainSpec {
            foveation: false,
            array_size: 2,
        };
        let lp = HeadlessLoop::new(app, spec).expect("session");
        // SAFETY: every name's type matches; every struct lives across its call.
        unsafe {
            let path_of: xr::pfn::StringToPath = lp.app.func(c"xrStringToPath");
            let path = |s: &std::ffi::CStr| {
                let mut p = xr::Path::NULL;
                assert_eq!(
                    path_of(lp.app.instance, s.as_ptr(), &mut p),
                    xr::Result::SUCCESS
                );
                p
            };
            let create_set: xr::pfn::CreateActionSet = lp.app.func(c"xrCreateActionSet");
            let create_action: xr::pfn::CreateAction = lp.app.func(c"xrCreateAction");
            let suggest: xr::pfn::SuggestInteractionProfileBindings =
                lp.app.func(c"xrSuggestInteractionProfileBindings");
            let attach: xr::pfn::AttachSessionActionSets =
                lp.app.func(c"xrAttachSessionActionSets");
            let action_space: xr::pfn::CreateActionSpace = lp.app.func(c"xrCreateActionSpace");
            let reference_space: xr::pfn::CreateReferenceSpace =
                lp.app.func(c"xrCreateReferenceSpace");
            let mut set = xr::ActionSet::NULL;
            assert_eq!(
                create_set(
                    lp.app.instance,
                    &xr::ActionSetCreateInfo {
                        ty: xr::StructureType::ACTION_SET_CREATE_INFO,
                        next: std::ptr::null(),
                        action_set_name: fixed("gaze"),
                        localized_action_set_name: fixed("Gaze"),
                        priority: 0,
                    },
                    &mut set
                ),
                xr::Result::SUCCESS
            );
            let mut action = xr::Action::NULL;
            assert_eq!(
                create_action(
                    set,
                    &xr::ActionCreateInfo {
                        ty: xr::StructureType::ACTION_CREATE_INFO,
                        next: std::ptr::null(),
                        action_name: fixed("gaze"),
                        action_type: xr::ActionType::POSE_INPUT,
                        count_subaction_paths: 0,
                        subaction_paths: std::ptr::null(),
                        localized_action_name: fixed("Gaze"),
                    },
                    &mut action
                ),
                xr::Result::SUCCESS
            );
            let binding = [xr::ActionSuggestedBinding {
                action,
                binding: path(c"/user/eyes_ext/input/gaze_ext/pose"),
            }];
            assert_eq!(
                suggest(
                    lp.app.instance,
                    &xr::InteractionProfileSuggestedBinding {
                        ty: xr::StructureType::INTERACTION_PROFILE_SUGGESTED_BINDING,
                        next: std::ptr::null(),
                        interaction_profile: path(
                            c"/interaction_profiles/ext/eye_gaze_interaction"
                        ),
                        count_suggested_bindings: 1,
                        suggested_bindings: binding.as_ptr(),
                    }
                ),
                xr::Result::SUCCESS
            );
            let sets = [set];
            assert_eq!(
                attach(
                    lp.session,
                    &xr::SessionActionSetsAttachInfo {
                        ty: xr::StructureType::SESSION_ACTION_SETS_ATTACH_INFO,
                        next: std::ptr::null(),
                        count_action_sets: 1,
                        action_sets: sets.as_ptr(),
                    }
                ),
                xr::Result::SUCCESS
            );
            let mut gaze = xr::Space::NULL;
            assert_eq!(
                action_space(
                    lp.session,
                    &xr::ActionSpaceCreateInfo {
                        ty: xr::StructureType::ACTION_SPACE_CREATE_INFO,
                        next: std::ptr::null(),
                        action,
                        subaction_path: xr::Path::NULL,
                        pose_in_action_space: xr::Posef::IDENTITY,
                    },
                    &mut gaze
                ),
                xr::Result::SUCCESS
            );
            let mut view = xr::Space::NULL;
            assert_eq!(
                reference_space(
                    lp.session,
                    &xr::ReferenceSpaceCreateInfo {
                        ty: xr::StructureType::REFERENCE_SPACE_CREATE_INFO,
                        next: std::ptr::null(),
                        reference_space_type: xr::ReferenceSpaceType::VIEW,
                        pose_in_reference_space: xr::Posef::IDENTITY,
                    },
                    &mut view
                ),
                xr::Result::SUCCESS
            );
            let mut g = AppGaze {
                sync: lp.app.func(c"xrSyncActions"),
                pose: lp.app.func(c"xrGetActionStatePose"),
                locate: lp.app.func(c"xrLocateSpace"),
                lp,
                set,
                action,
                gaze,
                view,
            };
            for _ in 0..300 {
                g.frame();
            }
            assert!(g.frame(), "the bare application locates the gaze");
            g
        }
    }

    /// One frame and the gaze calls; whether the gaze was located with a valid orientation.
    fn frame(&mut self) -> bool {
        self.lp.frame().expect("frame");
        let active = [xr::ActiveActionSet {
            action_set: self.set,
            subaction_path: xr::Path::NULL,
        }];
        let mut state = xr::ActionStatePose {
            ty: xr::StructureType::ACTION_STATE_POSE,
            next: std::ptr::null_mut(),
            is_active: xr::FALSE,
        };
        let mut sampled = xr::EyeGazeSampleTimeEXT {
            ty: xr::StructureType::EYE_GAZE_SAMPLE_TIME_EXT,
            next: std::ptr::null_mut(),
            time: xr::Time::from_nanos(0),
        };
        let mut location = xr::SpaceLocation {
            ty: xr::StructureType::SPACE_LOCATION,
            next: &mut sampled as *mut _ as *mut std::ffi::c_void,
            location_flags: xr::SpaceLocationFlags::EMPTY,
            pose: xr::Posef::IDENTITY,
        };
        // SAFETY: the application's own live handles; every struct lives across its call.
        unsafe {
            (self.sync)(
                self.lp.session,
                &xr::ActionsSyncInfo {
                    ty: xr::StructureType::ACTIONS_SYNC_INFO,
                    next: std::ptr::null(),
                    count_active_action_sets: 1,
                    active_action_sets: active.as_ptr(),
                },
            );
            (self.pose)(
                self.lp.session,
                &xr::ActionStateGetInfo {
                    ty: xr::StructureType::ACTION_STATE_GET_INFO,
                    next: std::ptr::null(),
                    action: self.action,
                    subaction_path: xr::Path::NULL,
                },
                &mut state,
            );
            (self.locate)(
                self.gaze,
                self.view,
                self.lp.last_frame_state.predicted_display_time,
                &mut location,
            );
        }
        state.is_active == xr::TRUE
            && location
                .location_flags
                .contains(xr::SpaceLocationFlags::ORIENTATION_VALID)
    }
}

/// Mean ns per frame over `n` frames of the bare application following the gaze itself, and
/// allocations per frame.
fn timed_app_gaze(g: &mut AppGaze, n: u32) -> (f64, f64) {
    let a0 = alloc::allocations();
    let t0 = Instant::now();
    for _ in 0..n {
        g.frame();
    }
    let ns = t0.elapsed().as_nanos() as f64 / f64::from(n);
    let allocs = (alloc::allocations() - a0) as f64 / f64::from(n);
    (ns, allocs)
}

/// The `fovea+gaze` loop must follow a gaze, or its rows would time fixed foveation twice: in the
/// same set-up with the runtime's call journal on (off in the timed loops), fovea's gaze source
/// locates the gaze in every frame.
fn check_gaze_is_followed() {
    let mut cfg = sim::control::SimConfig::from_env().expect("simulated runtime configuration");
    cfg.eye_gaze = Some(sim::control::EyeGaze {
        supported: true,
        space_after_attach: false,
        script: sim::gaze_script::GazeScript::parse(MOVING_GAZE).expect("a gaze script"),
    });
    sim::control::set_thread_config(Some(cfg));
    let mut extensions = FOVEATION_EXTENSIONS.to_vec();
    extensions.push(EYE_TRACKED);
    let app = App::new(
        Chain::fovea().expect("libfovea.so is built"),
        &extensions,
        API_1_0,
    )
    .expect("instance");
    let spec = SwapchainSpec {
        foveation: true,
        array_size: 2,
    };
    let mut lp = HeadlessLoop::new(app, spec).expect("session");
    attach_a_set(&lp);
    for _ in 0..20 {
        lp.poll_events();
        lp.frame().expect("frame");
    }
    let located = sim::control::journal(lp.app.instance)
        .iter()
        .filter(|c| c.function == "xrLocateSpace" && c.result == xr::Result::SUCCESS)
        .count();
    assert!(
        located >= 15,
        "the gaze source locates the gaze every frame once focused: {located} in 20 frames"
    );
}

/// The environment variable naming a baseline build of the layer to compare with.
const BASELINE_ENV: &str = "FOVEA_BENCH_BASELINE";

/// The baseline layer named by [`BASELINE_ENV`], loaded as the loader would load fovea.
fn baseline_chain() -> Option<Chain> {
    let path = std::env::var_os(BASELINE_ENV)?;
    let spec = LayerSpec {
        path: path.into(),
        name: FOVEA_LAYER.to_owned(),
    };
    Some(Chain::new(vec![spec]).expect("the baseline layer loads"))
}

fn bench_frames(c: &mut Criterion) {
    let mut group = c.benchmark_group("frame");
    let mut bare = running_loop(Chain::bare());
    group.bench_function("bare", |b| b.iter(|| bare.frame().unwrap()));
    if let Some(chain) = baseline_chain() {
        let mut baseline = running_loop(chain);
        group.bench_function("baseline", |b| b.iter(|| baseline.frame().unwrap()));
    }
    let mut fovea = running_loop(Chain::fovea().expect("libfovea.so is built"));
    group.bench_function("fovea", |b| b.iter(|| fovea.frame().unwrap()));
    let mut gaze = running_loop_with(
        Chain::fovea().expect("libfovea.so is built"),
        Some(MOVING_GAZE),
    );
    group.bench_function("fovea+gaze", |b| b.iter(|| gaze.frame().unwrap()));
    group.finish();
}

/// Mean ns per frame over `n` frames, and allocations per frame.
fn timed(lp: &mut HeadlessLoop, n: u32) -> (f64, f64) {
    let a0 = alloc::allocations();
    let t0 = Instant::now();
    for _ in 0..n {
        lp.frame().unwrap();
    }
    let ns = t0.elapsed().as_nanos() as f64 / f64::from(n);
    let allocs = (alloc::allocations() - a0) as f64 / f64::from(n);
    (ns, allocs)
}

/// Interleaved rounds of the loops in the same run (bare, the baseline when named, fovea); the tenth
/// percentile round of each. Many short rounds (2,000 of 250 frames, under a millisecond each) and a
/// low percentile rather than a few long rounds and their median: on a shared machine other work
/// only ever adds time, and lands in most rounds of ten milliseconds or more, so that the median of
/// long rounds measures the machine's load as much as the loop (ratios from 0.3 to 1.1 between the
/// same two builds in one afternoon); a low percentile of short rounds is what the loop costs when
/// nothing else interrupts it. Allocations per frame are the median round's.
fn summary() {
    let mut bare = running_loop(Chain::bare());
    let mut baseline = baseline_chain().map(running_loop);
    let mut fovea = running_loop(Chain::fovea().expect("libfovea.so is built"));
    let mut gaze = running_loop_with(
        Chain::fovea().expect("libfovea.so is built"),
        Some(MOVING_GAZE),
    );
    let mut app_gaze = AppGaze::new();
    let (mut b, mut o, mut f, mut g) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut a = Vec::new();
    for _ in 0..ROUNDS {
        b.push(timed(&mut bare, ROUND_FRAMES));
        a.push(timed_app_gaze(&mut app_gaze, ROUND_FRAMES));
        if let Some(lp) = &mut baseline {
            o.push(timed(lp, ROUND_FRAMES));
        }
        f.push(timed(&mut fovea, ROUND_FRAMES));
        g.push(timed(&mut gaze, ROUND_FRAMES));
    }
    let median = |v: &mut Vec<(f64, f64)>| {
        v.sort_by(|x, y| x.0.total_cmp(&y.0));
        (v[v.len() / 10].0, v[v.len() / 2].1)
    };
    let (bare_ns, bare_allocs) = median(&mut b);
    let (fovea_ns, fovea_allocs) = median(&mut f);
    println!(
        "summary: bare {bare_ns:.0} ns/frame, fovea {fovea_ns:.0} ns/frame, added {:.0} ns/frame, ratio {:.3}; \
         heap allocations per frame: bare {bare_allocs:.2}, fovea {fovea_allocs:.2}, added by the layer {:.2}",
        fovea_ns - bare_ns,
        fovea_ns / bare_ns,
        fovea_allocs - bare_allocs,
    );
    let (gaze_ns, gaze_allocs) = median(&mut g);
    let (app_ns, app_allocs) = median(&mut a);
    println!(
        "gaze: fovea {fovea_ns:.0} ns/frame with fixed foveation, {gaze_ns:.0} ns/frame with the gaze \
         moving every frame (+{:.0} ns, +{:.2} allocations); the runtime's share, an application \
         making the same calls on the bare runtime: {app_ns:.0} ns/frame (+{:.0} ns, +{:.2} \
         allocations); the layer's own added by the moving gaze: {:.0} ns/frame, {:.2} heap \
         allocations per frame",
        gaze_ns - fovea_ns,
        gaze_allocs - fovea_allocs,
        app_ns - bare_ns,
        app_allocs - bare_allocs,
        (gaze_ns - fovea_ns) - (app_ns - bare_ns),
        (gaze_allocs - fovea_allocs) - (app_allocs - bare_allocs),
    );
    if !o.is_empty() {
        let (base_ns, base_allocs) = median(&mut o);
        println!(
            "baseline: bare {bare_ns:.0} ns/frame, baseline {base_ns:.0} ns/frame, added {:.0} ns/frame, ratio {:.3}, \
             allocations added {:.2}; fovea's added cost is {:.2} of the baseline's",
            base_ns - bare_ns,
            base_ns / bare_ns,
            base_allocs - bare_allocs,
            (fovea_ns - bare_ns) / (base_ns - bare_ns),
        );
    }
}

/// Interleaved timing rounds in the summary, and frames per round.
const ROUNDS: usize = 2_000;
const ROUND_FRAMES: u32 = 250;

criterion_group!(benches, bench_frames);

fn main() {
    layer_allocs::check_counter_sees_the_layer(&Chain::fovea().expect("libfovea.so is built"));
    check_gaze_is_followed();
    benches();
    summary();
    Criterion::default().configure_from_args().final_summary();
}
