//! fovea's gaze source on the simulated runtime's eye tracker, through the real layer: where each
//! view's fovea goes follows the scripted gaze (fixation, a saccade that resets the filter, a blink
//! held then followed again, a loss eased back to fixed foveation, smooth pursuit); runtimes and
//! systems without eye gaze give fixed foveation and one line saying why; a runtime that refuses
//! the gaze space before attach, an application that never attaches, one that never syncs, and one
//! that uses eye gaze itself all work; no call reaches the runtime that it refuses.
//!
//! The layer writes the gaze it located for each frame at `trace` on `fovea::gaze` and the stats
//! line once a second; the tests read both from the log file. Each test runs in a process of its
//! own, since the log is set up once per process from the environment.

use std::path::{Path, PathBuf};

use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::{HeadlessLoop, FOVEATION_EXTENSIONS};
use fovea_harness::{sim, App, Chain};
use fovea_model::gaze::{eye_centre, EyeView, Gaze, Tracking};
use glam::{Quat, Vec3};
use openxr_sys as xr;
use xr::Handle;

use crate::support::actions::{
    action_space, attach_set, declare, locate_at_display, path, sync_set, EYE_GAZE_POSE,
    EYE_GAZE_PROFILE,
};
use crate::support::gaze_log::{located, Located};
use crate::support::{foveated_loop, in_own_process};

/// The eye gaze extension.
const EXT: &str = "XR_EXT_eye_gaze_interaction";
/// What makes fovea use the gaze in these applications (docs/eye-tracking.md#who-uses-the-gaze):
/// `XR_META_foveation_eye_tracked`, which fovea provides on the simulated runtime.
const EYE_TRACKED: &str = "XR_META_foveation_eye_tracked";

/// A log file of this process's own, with the gaze at `trace` and the stats line on.
fn log_here(label: &str, extra_env: &[(&str, &str)]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fovea-gaze-{label}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join("fovea.log");
    std::fs::remove_file(&log).ok();
    std::env::set_var(
        "FOVEA_LOG",
        format!(
            "warn,{}=trace,{}=info",
            fovea_abi::log_target::GAZE,
            fovea_abi::log_target::STATS
        ),
    );
    std::env::set_var("FOVEA_LOG_FILE", &log);
    for (k, v) in extra_env {
        std::env::set_var(k, v);
    }
    log
}

fn log_lines(log: &Path) -> Vec<String> {
    std::fs::read_to_string(log)
        .unwrap_or_default()
        .lines()
        .map(String::from)
        .collect()
}

fn stats(lines: &[String]) -> Vec<&String> {
    lines
        .iter()
        .filter(|l| l.contains(fovea_abi::log_target::STATS))
        .collect()
}

/// The simulated Quest 3 with an eye tracker following `script`.
fn eye_tracker(supported: bool, space_after_attach: bool, script: &str) -> sim::control::SimConfig {
    let mut cfg =
        sim::control::SimConfig::for_headset(fovea_model::headsets::by_id("quest3").unwrap());
    cfg.eye_gaze = Some(sim::control::EyeGaze {
        supported,
        space_after_attach,
        script: sim::gaze_script::GazeScript::parse(script).unwrap(),
    });
    cfg
}

fn running(cfg: sim::control::SimConfig, extensions: &[&str]) -> HeadlessLoop {
    sim::control::set_thread_config(Some(cfg));
    let mut exts: Vec<&str> = FOVEATION_EXTENSIONS.to_vec();
    exts.push(EYE_TRACKED);
    exts.extend_from_slice(extensions);
    let app = App::new(Chain::fovea().unwrap(), &exts, API_1_0).unwrap();
    foveated_loop(app)
}

/// The application's own input: an action set with one pose action, bound to a controller (or,
/// `gaze`, to the eye tracker, which the application then locates itself).
struct AppInput {
    set: xr::ActionSet,
    action: xr::Action,
    space: xr::Space,
    sync: xr::pfn::SyncActions,
    get_pose: xr::pfn::GetActionStatePose,
    locate: xr::pfn::LocateSpace,
}

impl AppInput {
    /// Declares the application's set and action ([`declare`]); `attach` attaches the set.
    fn new(lp: &HeadlessLoop, gaze: bool, attach: bool) -> AppInput {
        let (set, action) = declare(&lp.app, gaze);
        AppInput::with(lp, set, action, attach)
    }

    /// The application's input with a set and action declared already; `attach` attaches the set.
    fn with(lp: &HeadlessLoop, set: xr::ActionSet, action: xr::Action, attach: bool) -> AppInput {
        // SAFETY: every name's type matches; the structs live across their calls.
        unsafe {
            let mut space = xr::Space::NULL;
            if attach {
                attach_set(lp, set);
                space = action_space(lp, action);
            }
            AppInput {
                set,
                action,
                space,
                sync: lp.func(c"xrSyncActions"),
                get_pose: lp.func(c"xrGetActionStatePose"),
                locate: lp.func(c"xrLocateSpace"),
            }
        }
    }

    /// The application's xrSyncActions of its own set.
    fn sync(&self, lp: &HeadlessLoop) {
        sync_set(lp, self.sync, self.set);
    }

    /// Whether the application's own action is active, and its space's pose in `base` at the last
    /// frame's display time where it is located.
    fn own_pose(&self, lp: &HeadlessLoop) -> (bool, Option<xr::Posef>) {
        // SAFETY: live handles; the structs live across the calls.
        unsafe {
            let get = xr::ActionStateGetInfo {
                ty: xr::StructureType::ACTION_STATE_GET_INFO,
                next: std::ptr::null(),
                action: self.action,
                subaction_path: xr::Path::NULL,
            };
            let mut state = xr::ActionStatePose {
                ty: xr::StructureType::ACTION_STATE_POSE,
                next: std::ptr::null_mut(),
                is_active: xr::FALSE,
            };
            assert_eq!(
                (self.get_pose)(lp.session, &get, &mut state),
                xr::Result::SUCCESS
            );
            let loc = locate_at_display(lp, self.locate, self.space, lp.space);
            let valid = loc
                .location_flags
                .contains(xr::SpaceLocationFlags::ORIENTATION_VALID);
            (state.is_active != xr::FALSE, valid.then_some(loc.pose))
        }
    }
}

/// Where the fovea of the left view goes for a gaze at (yaw, pitch), by the model, with the
/// simulated headset's left eye (Quest 3's FOV, 31.5 mm left of the head's centre).
fn left_eye_ndc(yaw: f32, pitch: f32) -> [f32; 2] {
    let headset = fovea_model::headsets::by_id("quest3").unwrap();
    let eye = EyeView {
        fov: headset.fovs()[0],
        position: Vec3::new(-0.0315, 0.0, 0.0),
        orientation: Quat::IDENTITY,
    };
    let gaze = Gaze {
        angles: [yaw, pitch],
        weight: 1.0,
        tracking: Tracking::Tracked,
    };
    eye_centre(&gaze, &eye, 1.0)
}

/// No call fovea made was refused by the runtime (nor any other).
fn assert_no_refusals(instance: xr::Instance) {
    assert_eq!(sim::control::refusals(instance), vec![], "refused calls");
    assert_eq!(sim::control::errors(instance), vec![], "failed calls");
}

const SCRIPT: &str = "fix 10,0 for 600ms; saccade -10,5 in 1ms; fix for 600ms; blink 150ms; \
                      fix for 600ms; lost 1500ms; fix for 500ms; pursue 10,5 at 20; fix for 1s";

#[test]
fn the_fovea_follows_the_scripted_gaze() {
    in_own_process(
        module_path!(),
        "the_fovea_follows_the_scripted_gaze",
        the_fovea_follows_the_scripted_gaze_here,
    );
}

fn the_fovea_follows_the_scripted_gaze_here() {
    let log = log_here("follows", &[]);
    let mut lp = running(eye_tracker(true, false, SCRIPT), &[]);
    let input = AppInput::new(&lp, false, true);
    for _ in 0..600 {
        lp.frame().unwrap();
        input.sync(&lp);
    }
    let instance = lp.app.instance;
    let lines = log_lines(&log);
    let got = located(&lines);
    assert!(got.len() >= 590, "a located gaze per frame: {}", got.len());

    // Fixation at (10, 0): tracked, on the point, and the left view's fovea where the model puts it.
    let first = &got[10];
    assert_eq!(first.tracking, Tracking::Tracked, "{first:?}");
    assert!((first.angles[0] - 10.0).abs() < 0.1, "{first:?}");
    let want = left_eye_ndc(10.0, 0.0);
    assert!(
        (first.ndc[0][0] - want[0]).abs() < 0.01 && (first.ndc[0][1] - want[1]).abs() < 0.01,
        "{first:?} vs {want:?}"
    );
    assert!(first.ndc[0][0] > 0.2, "right of centre: {first:?}");

    // The saccade resets the filter: the fovea is on the new point at most a frame after the eye.
    let start = 10
        + got[10..]
            .iter()
            .position(|g| g.angles[0] < 9.0)
            .expect("a saccade");
    let arrived = got[start..]
        .iter()
        .position(|g| (g.angles[0] + 10.0).abs() < 0.1 && (g.angles[1] - 5.0).abs() < 0.1)
        .expect("the fovea reaches the saccade's target");
    // The jump falls between two of the tracker's samples (120 Hz). Without the reset, a one-euro
    // filter at rest (cutoff 1 Hz) would take tens of frames to get there.
    assert!(arrived <= 1, "the saccade took {arrived} frames");

    // The blink: held where the eye was, then followed again.
    let held = got
        .iter()
        .position(|g| g.tracking == Tracking::Held)
        .unwrap();
    let held_run = got[held..]
        .iter()
        .take_while(|g| g.tracking == Tracking::Held)
        .count();
    assert!((12..=15).contains(&held_run), "150 ms held: {held_run}");
    assert!(got[held..held + held_run]
        .iter()
        .all(|g| (g.angles[0] + 10.0).abs() < 0.1 && g.weight == 1.0));
    assert_eq!(got[held + held_run].tracking, Tracking::Tracked);

    // The loss: held for 0.3 s, eased back over 0.3 s, then fixed foveation.
    let lost = held
        + held_run
        + got[held + held_run..]
            .iter()
            .position(|g| g.tracking == Tracking::Held)
            .unwrap();
    let run = |t: Tracking, from: usize| got[from..].iter().take_while(|g| g.tracking == t).count();
    let held2 = run(Tracking::Held, lost);
    let back = run(Tracking::Returning, lost + held2);
    let fixed = run(Tracking::Fixed, lost + held2 + back);
    assert!((25..=29).contains(&held2), "0.3 s held: {held2}");
    assert!((25..=29).contains(&back), "0.3 s returning: {back}");
    assert!(fixed >= 70, "fixed until the tracker is back: {fixed}");
    let weights: Vec<f32> = got[lost + held2..lost + held2 + back]
        .iter()
        .map(|g| g.weight)
        .collect();
    assert!(weights.windows(2).all(|w| w[1] <= w[0]), "{weights:?}");
    let centre = fovea_model::headsets::by_id("quest3").unwrap().fovs()[0].projection_center_ndc();
    let f = &got[lost + held2 + back];
    assert!(
        (f.ndc[0][0] - centre[0]).abs() < 1e-4 && (f.ndc[0][1] - centre[1]).abs() < 1e-4,
        "fixed foveation's centre: {f:?} vs {centre:?}"
    );

    // Pursuit from (-10, 5) to (10, 5) at 20°/s: the fovea moves right every frame, close behind.
    let pursuit_from = lost + held2 + back + fixed;
    let pursuit: Vec<&Located> = got[pursuit_from..]
        .iter()
        .skip(50)
        .take_while(|g| g.angles[0] < 9.0)
        .collect();
    assert!(
        pursuit.len() >= 60,
        "a second of pursuit: {}",
        pursuit.len()
    );
    assert!(
        pursuit.windows(2).all(|w| w[1].angles[0] > w[0].angles[0]),
        "pursuit moves on every frame"
    );

    // The stats line says where the fovea is.
    let st = stats(&lines);
    assert!(st.iter().any(|l| l.contains(" Gaze=tracked@+")), "{st:#?}");
    assert!(st.iter().any(|l| l.contains(" Gaze=fixed ")), "{st:#?}");
    drop(lp);
    assert_no_refusals(instance);
}

/// The yaw and pitch (degrees) a pose's −Z points at.
fn pose_angles(p: xr::Posef) -> [f32; 2] {
    let o = p.orientation;
    let d = Quat::from_xyzw(o.x, o.y, o.z, o.w) * Vec3::NEG_Z;
    fovea_model::gaze::angles_of(d).unwrap()
}

#[test]
fn an_app_with_its_own_eye_gaze_binding_keeps_getting_it() {
    in_own_process(
        module_path!(),
        "an_app_with_its_own_eye_gaze_binding_keeps_getting_it",
        an_app_with_its_own_eye_gaze_binding_keeps_getting_it_here,
    );
}

fn an_app_with_its_own_eye_gaze_binding_keeps_getting_it_here() {
    let log = log_here("own", &[]);
    let mut lp = running(eye_tracker(true, false, "fix 8,-3 for 10s"), &[EXT]);
    let input = AppInput::new(&lp, true, true);
    let mut own = Vec::new();
    for _ in 0..120 {
        lp.frame().unwrap();
        input.sync(&lp);
        own.push(input.own_pose(&lp));
    }
    // From the third frame on the session is focused: the application's own gaze is active, and
    // points where the eye looks.
    for (active, pose) in &own[5..] {
        assert!(*active, "the application's gaze action is active");
        let [yaw, pitch] = pose_angles(pose.expect("the application's gaze is located"));
        assert!(
            (yaw - 8.0).abs() < 0.01 && (pitch + 3.0).abs() < 0.01,
            "{yaw} {pitch}"
        );
    }
    let got = located(log_lines(&log));
    let last = got.last().expect("fovea located the gaze too");
    assert_eq!(last.tracking, Tracking::Tracked);
    assert!((last.angles[0] - 8.0).abs() < 0.05 && (last.angles[1] + 3.0).abs() < 0.05);
    let instance = lp.app.instance;
    drop(lp);
    assert_no_refusals(instance);
}

/// The lines of `target`'s at `level` that contain `text`.
fn said<'a>(lines: &'a [String], level: &str, text: &str) -> Vec<&'a String> {
    lines
        .iter()
        .filter(|l| {
            l.contains(level) && l.contains(fovea_abi::log_target::GAZE) && l.contains(text)
        })
        .collect()
}

/// Runs `frames` frames of an application that attaches and syncs its own set.
fn attach_and_sync(lp: &mut HeadlessLoop, frames: usize) {
    let input = AppInput::new(lp, false, true);
    for _ in 0..frames {
        lp.frame().unwrap();
        input.sync(lp);
    }
}

#[test]
fn without_eye_gaze_the_foveation_stays_fixed_with_one_line_saying_why() {
    in_own_process(
        module_path!(),
        "without_eye_gaze_the_foveation_stays_fixed_with_one_line_saying_why",
        without_eye_gaze_here,
    );
}

fn without_eye_gaze_here() {
    let log = log_here("without", &[]);
    // A runtime without the extension, twice: one line for the process.
    let mut instances = Vec::new();
    for _ in 0..2 {
        let mut cfg =
            sim::control::SimConfig::for_headset(fovea_model::headsets::by_id("quest3").unwrap());
        cfg.eye_gaze = None;
        let mut lp = running(cfg, &[]);
        attach_and_sync(&mut lp, 200);
        assert!(
            !sim::control::enabled_extensions(lp.app.instance).contains(&EXT.to_string()),
            "nothing enabled that the runtime does not offer"
        );
        instances.push(lp.app.instance);
    }
    // A runtime that lists the extension on a system without an eye tracker (Monado's simulated
    // headset): enabled, asked, and not used.
    let mut lp = running(eye_tracker(false, false, ""), &[]);
    attach_and_sync(&mut lp, 200);
    assert!(sim::control::enabled_extensions(lp.app.instance).contains(&EXT.to_string()));
    instances.push(lp.app.instance);
    drop(lp);
    let lines = log_lines(&log);
    assert!(located(&lines).is_empty(), "no gaze located");
    let st = stats(&lines);
    assert!(st.len() >= 6, "{st:#?}");
    assert!(st.iter().all(|l| l.contains(" Gaze=fixed ")), "{st:#?}");
    assert_eq!(
        said(&lines, "INFO", "does not offer XR_EXT_eye_gaze_interaction").len(),
        1,
        "{lines:#?}"
    );
    assert_eq!(
        said(&lines, "INFO", "no eye tracker").len(),
        1,
        "{lines:#?}"
    );
    let gaze_lines = lines
        .iter()
        .filter(|l| l.contains(fovea_abi::log_target::GAZE))
        .count();
    assert_eq!(gaze_lines, 2, "one line per cause: {lines:#?}");
    for i in instances {
        assert_no_refusals(i);
    }
}

#[test]
fn gaze_switched_off_is_off() {
    in_own_process(module_path!(), "gaze_switched_off_is_off", || {
        let log = log_here("off", &[("FOVEA_GAZE", "0")]);
        let mut lp = running(eye_tracker(true, false, "fix 10,0 for 10s"), &[]);
        attach_and_sync(&mut lp, 200);
        assert!(
            !sim::control::enabled_extensions(lp.app.instance).contains(&EXT.to_string()),
            "fovea enables nothing with gaze off"
        );
        let lines = log_lines(&log);
        assert!(located(&lines).is_empty());
        let st = stats(&lines);
        assert!(
            !st.is_empty() && st.iter().all(|l| l.contains(" Gaze=off ")),
            "{st:#?}"
        );
    });
}

#[test]
fn a_runtime_that_refuses_the_gaze_space_before_attach_works() {
    in_own_process(
        module_path!(),
        "a_runtime_that_refuses_the_gaze_space_before_attach_works",
        || {
            let log = log_here("after-attach", &[]);
            let mut lp = running(eye_tracker(true, true, "fix -6,4 for 10s"), &[]);
            attach_and_sync(&mut lp, 60);
            let got = located(log_lines(&log));
            let last = got.last().expect("located");
            assert_eq!(last.tracking, Tracking::Tracked);
            assert!((last.angles[0] + 6.0).abs() < 0.05 && (last.angles[1] - 4.0).abs() < 0.05);
            let instance = lp.app.instance;
            drop(lp);
            assert_no_refusals(instance);
        },
    );
}

#[test]
fn an_app_that_never_attaches_gets_gaze_after_the_grace_period() {
    in_own_process(
        module_path!(),
        "an_app_that_never_attaches_gets_gaze_after_the_grace_period",
        || {
            let log = log_here("never-attaches", &[("FOVEA_GAZE_ATTACH_AFTER_S", "1")]);
            let mut lp = running(eye_tracker(true, true, "fix 5,5 for 10s"), &[]);
            for _ in 0..200 {
                lp.poll_events();
                lp.frame().unwrap();
            }
            let lines = log_lines(&log);
            let got = located(&lines);
            // Attached after 1 s (90 frames), then synced alone every frame.
            assert!((100..=112).contains(&got.len()), "{}", got.len());
            let last = got.last().unwrap();
            assert_eq!(last.tracking, Tracking::Tracked);
            assert!((last.angles[0] - 5.0).abs() < 0.05 && (last.angles[1] - 5.0).abs() < 0.05);
            assert_eq!(said(&lines, "INFO", "attached its own").len(), 1);
            let instance = lp.app.instance;
            drop(lp);
            assert_no_refusals(instance);
        },
    );
}

#[test]
fn never_attaching_alone_is_a_setting() {
    in_own_process(module_path!(), "never_attaching_alone_is_a_setting", || {
        let log = log_here("never", &[("FOVEA_GAZE_ATTACH_AFTER_S", "never")]);
        let mut lp = running(eye_tracker(true, false, "fix 5,5 for 10s"), &[]);
        // 35 s of virtual display time: past the default grace period.
        for _ in 0..3150 {
            lp.frame().unwrap();
        }
        // The application attaches late, and still can.
        let input = AppInput::new(&lp, false, true);
        for _ in 0..20 {
            lp.frame().unwrap();
            input.sync(&lp);
        }
        let lines = log_lines(&log);
        assert!(said(&lines, "INFO", "attached its own").is_empty());
        assert_eq!(located(&lines).last().unwrap().tracking, Tracking::Tracked);
        let instance = lp.app.instance;
        drop(lp);
        assert_no_refusals(instance);
    });
}

#[test]
fn an_app_that_attaches_but_never_syncs_gets_gaze() {
    in_own_process(
        module_path!(),
        "an_app_that_attaches_but_never_syncs_gets_gaze",
        || {
            let log = log_here("never-syncs", &[]);
            let mut lp = running(eye_tracker(true, false, "fix 0,-8 for 10s"), &[]);
            let _input = AppInput::new(&lp, false, true);
            // The profile exists only for applications that enabled the extension, as without fovea.
            // SAFETY: the type matches the name; the struct lives across the call.
            let r = unsafe {
                let suggest: xr::pfn::SuggestInteractionProfileBindings =
                    lp.func(c"xrSuggestInteractionProfileBindings");
                let binding = [xr::ActionSuggestedBinding {
                    action: _input.action,
                    binding: path(&lp.app, EYE_GAZE_POSE),
                }];
                let info = xr::InteractionProfileSuggestedBinding {
                    ty: xr::StructureType::INTERACTION_PROFILE_SUGGESTED_BINDING,
                    next: std::ptr::null(),
                    interaction_profile: path(&lp.app, EYE_GAZE_PROFILE),
                    count_suggested_bindings: 1,
                    suggested_bindings: binding.as_ptr(),
                };
                suggest(lp.app.instance, &info)
            };
            assert_eq!(r, xr::Result::ERROR_PATH_UNSUPPORTED);
            for _ in 0..60 {
                // The application polls its events: fovea syncs alone only once it is FOCUSED.
                lp.poll_events();
                lp.frame().unwrap();
            }
            let got = located(log_lines(&log));
            assert!(got.len() >= 55, "synced alone every frame: {}", got.len());
            let last = got.last().unwrap();
            assert_eq!(last.tracking, Tracking::Tracked);
            assert!((last.angles[1] + 8.0).abs() < 0.05, "{last:?}");
            let instance = lp.app.instance;
            drop(lp);
            assert_no_refusals(instance);
        },
    );
}

#[test]
fn a_refused_call_falls_back_to_fixed_foveation_with_one_line() {
    in_own_process(
        module_path!(),
        "a_refused_call_falls_back_to_fixed_foveation_with_one_line",
        || {
            let log = log_here("refused", &[]);
            // Each of fovea's calls refused in turn, with the call number that is fovea's (the
            // application makes its own action set and spaces after fovea's, and its LOCAL space
            // before fovea's VIEW space; 0: every call), and what fovea then says. An attach or
            // sync refused with fovea's set added goes down again as the application made it,
            // which the application gets.
            let cases = [
                (
                    "xrGetSystemProperties",
                    1,
                    "xrGetSystemProperties for eye gaze",
                ),
                ("xrCreateActionSet", 1, "refused fovea's eye gaze action"),
                ("xrCreateAction", 1, "refused fovea's eye gaze action"),
                ("xrCreateActionSpace", 1, "refused fovea's eye gaze space"),
                ("xrCreateReferenceSpace", 2, "refused fovea's VIEW space"),
                (
                    "xrGetActionStatePose",
                    0,
                    "refused fovea's gaze action state",
                ),
                ("xrLocateSpace", 0, "refused to locate fovea's gaze"),
                (
                    "xrAttachSessionActionSets",
                    1,
                    "eye gaze set in the application's attach",
                ),
                ("xrSyncActions", 1, "eye gaze set in the application's sync"),
            ];
            for (function, nth, text) in cases {
                let from = std::fs::read_to_string(&log).map_or(0, |t| t.len());
                let mut cfg = eye_tracker(true, false, "fix 3,3 for 10s");
                cfg.faults.push(sim::control::Fault {
                    function: function.into(),
                    result: xr::Result::ERROR_RUNTIME_FAILURE,
                    nth,
                });
                let mut lp = running(cfg, &[]);
                attach_and_sync(&mut lp, 200);
                let text_since = std::fs::read_to_string(&log).unwrap();
                let lines: Vec<String> = text_since[from..].lines().map(String::from).collect();
                assert!(
                    located(&lines)
                        .iter()
                        .all(|g| g.tracking == Tracking::Fixed),
                    "{function}: no gaze"
                );
                // One line about it (the per-frame trace lines aside).
                let gaze_lines: Vec<&String> = said(&lines, "", "")
                    .into_iter()
                    .filter(|l| !l.contains(" TRACE "))
                    .collect();
                assert_eq!(gaze_lines.len(), 1, "{function}: one line: {gaze_lines:#?}");
                assert!(
                    gaze_lines[0].contains(" WARN ") && gaze_lines[0].contains(text),
                    "{function}: {}",
                    gaze_lines[0]
                );
                let st = stats(&lines);
                assert!(
                    !st.is_empty() && st.iter().all(|l| l.contains(" Gaze=fixed ")),
                    "{function}: {st:#?}"
                );
                let instance = lp.app.instance;
                drop(lp);
                assert_eq!(
                    sim::control::refusals(instance),
                    vec![],
                    "{function}: only the injected fault"
                );
            }
        },
    );
}

#[test]
fn a_gaze_that_never_becomes_active_is_said_once() {
    in_own_process(
        module_path!(),
        "a_gaze_that_never_becomes_active_is_said_once",
        || {
            let log = log_here("never-active", &[]);
            let mut cfg = eye_tracker(true, false, "fix 3,3 for 20s");
            // Every sync answers XR_SESSION_NOT_FOCUSED and activates nothing, as a runtime does for
            // a session that never gets the focus.
            cfg.faults.push(sim::control::Fault {
                function: "xrSyncActions".into(),
                result: xr::Result::SESSION_NOT_FOCUSED,
                nth: 0,
            });
            let mut lp = running(cfg, &[]);
            attach_and_sync(&mut lp, 700);
            let lines = log_lines(&log);
            let got = located(&lines);
            assert!(got.len() >= 690, "{}", got.len());
            assert!(got.iter().all(|g| g.tracking == Tracking::Fixed));
            assert_eq!(
                said(&lines, "INFO", "has not been active for 5 s").len(),
                1,
                "{lines:#?}"
            );
            let instance = lp.app.instance;
            drop(lp);
            assert_eq!(sim::control::refusals(instance), vec![]);
        },
    );
}

#[test]
fn an_eye_gaze_suggestion_made_before_the_session_still_binds_both() {
    in_own_process(
        module_path!(),
        "an_eye_gaze_suggestion_made_before_the_session_still_binds_both",
        || {
            let log = log_here("early-suggestion", &[]);
            sim::control::set_thread_config(Some(eye_tracker(true, false, "fix -4,2 for 10s")));
            let mut exts: Vec<&str> = FOVEATION_EXTENSIONS.to_vec();
            exts.extend([EXT, EYE_TRACKED]);
            let app = App::new(Chain::fovea().unwrap(), &exts, API_1_0).unwrap();
            // Suggested before any session: fovea makes its action then, and its binding goes
            // down merged into the application's suggestion.
            let (set, action) = declare(&app, true);
            let mut lp = foveated_loop(app);
            let input = AppInput::with(&lp, set, action, true);
            for _ in 0..30 {
                lp.frame().unwrap();
                input.sync(&lp);
            }
            let (active, pose) = input.own_pose(&lp);
            assert!(active, "the application's gaze action is active");
            let [yaw, pitch] = pose_angles(pose.expect("located"));
            assert!((yaw + 4.0).abs() < 0.01 && (pitch - 2.0).abs() < 0.01);
            let last = located(log_lines(&log))
                .pop()
                .expect("fovea located the gaze");
            assert_eq!(last.tracking, Tracking::Tracked);
            assert!((last.angles[0] + 4.0).abs() < 0.05);
            let instance = lp.app.instance;
            drop(lp);
            assert_no_refusals(instance);
        },
    );
}
