//! fovea's gaze source as the spec and the application see it, in applications that use the gaze
//! (`XR_META_foveation_eye_tracked`, docs/eye-tracking.md#who-uses-the-gaze), on the simulated
//! runtime's eye tracker: an application that attaches after 31 s of frames still can; each frame
//! renders with the gaze of its own display time; the application's eye gaze properties, binding
//! modifications, events and profile queries are what they are without fovea; nothing is synced
//! before the session is FOCUSED; the application's own errors reach the runtime once; a
//! sub-nominal gaze (VALID, not TRACKED) is followed; the tracker's permission and calibration
//! request.

use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::{HeadlessLoop, FOVEATION_EXTENSIONS};
use fovea_harness::{sim, App, Chain};
use openxr_sys as xr;
use xr::Handle;

use crate::support::actions::{
    action_space, attach_set, declare, locate_at_display, path, sync_of, sync_set, EYE_GAZE_PROFILE,
};
use crate::support::{foveated_loop, in_own_process};

const EYE_TRACKED: &str = "XR_META_foveation_eye_tracked";
const EYE_GAZE: &str = "XR_EXT_eye_gaze_interaction";

/// The simulated Quest 3 with an eye tracker following `script`.
fn tracker(script: &str) -> sim::control::SimConfig {
    let mut cfg =
        sim::control::SimConfig::for_headset(fovea_model::headsets::by_id("quest3").unwrap());
    cfg.eye_gaze = Some(sim::control::EyeGaze {
        supported: true,
        space_after_attach: false,
        script: sim::gaze_script::GazeScript::parse(script).unwrap(),
    });
    cfg
}

/// An application on `chain` with `exts` (and, where `eye_tracked`, the foveation extensions and
/// `XR_META_foveation_eye_tracked`), its foveated loop running on `script`.
fn running(chain: Chain, script: &str, eye_tracked: bool, exts: &[&str]) -> HeadlessLoop {
    sim::control::set_thread_config(Some(tracker(script)));
    let mut all: Vec<&str> = if eye_tracked {
        let mut v = FOVEATION_EXTENSIONS.to_vec();
        v.push(EYE_TRACKED);
        v
    } else {
        vec!["XR_MND_headless"]
    };
    all.extend_from_slice(exts);
    let app = App::new(chain, &all, API_1_0).unwrap();
    if eye_tracked {
        foveated_loop(app)
    } else {
        HeadlessLoop::new(
            app,
            fovea_harness::frame_loop::SwapchainSpec {
                foveation: false,
                array_size: 2,
            },
        )
        .unwrap()
    }
}

/// An application with a pose action of its own bound to the eye gaze ([`declare`]; `exts` enabled
/// besides the eye-tracked foveation's), its set attached, on a tracker following `script`, through fovea.
fn gaze_app(script: &str, exts: &[&str]) -> (HeadlessLoop, xr::ActionSet, xr::Action) {
    let lp = running(Chain::fovea().unwrap(), script, true, exts);
    let (set, action) = declare(&lp.app, true);
    assert_eq!(attach(&lp, &[set]), xr::Result::SUCCESS);
    (lp, set, action)
}

/// [`running`] with the application's own controller set ([`declare`]) attached.
fn attached(chain: Chain, script: &str, eye_tracked: bool) -> (HeadlessLoop, xr::ActionSet) {
    let lp = running(chain, script, eye_tracked, &[]);
    let (set, _) = declare(&lp.app, false);
    attach_set(&lp, set);
    (lp, set)
}

/// `xrGetFoveationEyeTrackedStateMETA`: each view's centre and whether VALID.
fn meta_state(lp: &HeadlessLoop) -> ([[f32; 2]; 2], bool) {
    let mut st = xr::FoveationEyeTrackedStateMETA {
        ty: xr::FoveationEyeTrackedStateMETA::TYPE,
        next: std::ptr::null_mut(),
        foveation_center: [xr::Vector2f { x: 9.0, y: 9.0 }; 2],
        flags: xr::FoveationEyeTrackedStateFlagsMETA::EMPTY,
    };
    // SAFETY: the type matches the name; the struct lives across the call.
    let r = unsafe {
        let f: xr::pfn::GetFoveationEyeTrackedStateMETA =
            lp.func(c"xrGetFoveationEyeTrackedStateMETA");
        f(lp.session, &mut st)
    };
    assert_eq!(r, xr::Result::SUCCESS);
    (
        st.foveation_center.map(|c| [c.x, c.y]),
        st.flags == xr::FoveationEyeTrackedStateFlagsMETA::VALID,
    )
}

/// The application's attach of `sets`, its result.
fn attach(lp: &HeadlessLoop, sets: &[xr::ActionSet]) -> xr::Result {
    let info = xr::SessionActionSetsAttachInfo {
        ty: xr::StructureType::SESSION_ACTION_SETS_ATTACH_INFO,
        next: std::ptr::null(),
        count_action_sets: sets.len() as u32,
        action_sets: sets.as_ptr(),
    };
    // SAFETY: the type matches the name; the struct lives across the call.
    unsafe {
        let f: xr::pfn::AttachSessionActionSets = lp.func(c"xrAttachSessionActionSets");
        f(lp.session, &info)
    }
}

/// Runs frames, polling events first as applications do, until `seconds` of display time passed.
fn frames_for(lp: &mut HeadlessLoop, seconds: f64) {
    lp.poll_events();
    lp.frame().unwrap();
    let first = lp.last_frame_state.predicted_display_time.as_nanos();
    while (lp.last_frame_state.predicted_display_time.as_nanos() - first) as f64 / 1e9 < seconds {
        lp.poll_events();
        lp.frame().unwrap();
    }
}

fn calls<'a>(journal: &'a [sim::control::Call], function: &str) -> Vec<&'a sim::control::Call> {
    journal.iter().filter(|c| c.function == function).collect()
}

fn late_attach(eye_tracked: bool) {
    for chain in [Chain::bare(), Chain::fovea().unwrap()] {
        let with = !chain.layers.is_empty();
        if eye_tracked && !with {
            // XR_META_foveation_eye_tracked exists only with fovea here.
            continue;
        }
        let mut lp = running(chain, "fix 5,5 for 100s", eye_tracked, &[]);
        frames_for(&mut lp, 31.0);
        let (set, _) = declare(&lp.app, false);
        assert_eq!(
            attach(&lp, &[set]),
            xr::Result::SUCCESS,
            "an attach after 31 s of frames (fovea: {with})"
        );
        let sync: xr::pfn::SyncActions = unsafe { lp.func(c"xrSyncActions") };
        for _ in 0..10 {
            lp.poll_events();
            sync_set(&lp, sync, set);
            lp.frame().unwrap();
        }
        if eye_tracked {
            let (_, valid) = meta_state(&lp);
            assert!(valid, "the gaze is followed once the application attached");
        }
        let instance = lp.app.instance;
        drop(lp);
        assert_eq!(sim::control::refusals(instance), vec![]);
    }
}

#[test]
fn an_app_that_attaches_after_31_s_succeeds() {
    in_own_process(
        module_path!(),
        "an_app_that_attaches_after_31_s_succeeds",
        || late_attach(false),
    );
}

#[test]
fn an_eye_tracked_app_that_attaches_after_31_s_succeeds() {
    in_own_process(
        module_path!(),
        "an_eye_tracked_app_that_attaches_after_31_s_succeeds",
        || late_attach(true),
    );
}

#[test]
fn each_frame_renders_with_the_gaze_of_its_own_display_time() {
    in_own_process(
        module_path!(),
        "each_frame_renders_with_the_gaze_of_its_own_display_time",
        || {
            // A saccade of 15° to the right, sampled at 1 kHz: the first frame displayed after it
            // must render with the new gaze, not with the gaze of the frame before.
            // The application's own gaze action, located at each frame's display time: where the
            // eye is when the frame is shown.
            let (mut lp, set, action) = gaze_app(
                "hz=1000; fix 0,0 for 1s; saccade 15,0 in 1ms; fix for 20s",
                &[EYE_GAZE],
            );
            let space = action_space(&lp, action);
            // SAFETY: every name's type matches.
            let (sync, locate): (xr::pfn::SyncActions, xr::pfn::LocateSpace) =
                unsafe { (lp.func(c"xrSyncActions"), lp.func(c"xrLocateSpace")) };
            let mut seen = Vec::new();
            for _ in 0..200 {
                // hello_xr's order: events, input, then the frame.
                lp.poll_events();
                sync_set(&lp, sync, set);
                lp.frame().unwrap();
                let loc = locate_at_display(&lp, locate, space, lp.space);
                let o = loc.pose.orientation;
                let dir = glam::Quat::from_xyzw(o.x, o.y, o.z, o.w) * glam::Vec3::NEG_Z;
                let yaw = dir.x.atan2(-dir.z).to_degrees();
                let (centres, _) = meta_state(&lp);
                seen.push((yaw, centres[0][0]));
            }
            let k = seen
                .iter()
                .position(|(yaw, _)| *yaw > 7.5)
                .expect("the saccade happened");
            assert!(k > 10, "the gaze was followed before the saccade");
            let (before, at, after) = (seen[k - 1].1, seen[k].1, seen[k + 1].1);
            assert!(
                at - before > 0.2,
                "the frame shown first after the saccade renders with the new gaze: left centre x \
                 {before} in the frame before, {at} in that frame"
            );
            assert!((after - at).abs() < 0.01, "{at} then {after}");
        },
    );
}

#[test]
fn the_app_s_eye_gaze_properties_are_left_alone() {
    in_own_process(
        module_path!(),
        "the_app_s_eye_gaze_properties_are_left_alone",
        || {
            // The application did not enable XR_EXT_eye_gaze_interaction; fovea did, for itself.
            sim::control::set_thread_config(Some(tracker("")));
            let mut exts = FOVEATION_EXTENSIONS.to_vec();
            exts.push(EYE_TRACKED);
            let app = App::new(Chain::fovea().unwrap(), &exts, API_1_0).unwrap();
            let mut gaze = xr::SystemEyeGazeInteractionPropertiesEXT {
                ty: xr::SystemEyeGazeInteractionPropertiesEXT::TYPE,
                next: std::ptr::null_mut(),
                supports_eye_gaze_interaction: xr::Bool32::from_raw(7),
            };
            // SAFETY: an all-zero XrSystemProperties is valid once typed.
            let mut props: xr::SystemProperties = unsafe { std::mem::zeroed() };
            props.ty = xr::SystemProperties::TYPE;
            props.next = (&mut gaze as *mut xr::SystemEyeGazeInteractionPropertiesEXT).cast();
            // SAFETY: the type matches the name; the structs live across the call.
            let r = unsafe {
                let f: xr::pfn::GetSystemProperties = app.func(c"xrGetSystemProperties");
                f(app.instance, app.system(), &mut props)
            };
            assert_eq!(r, xr::Result::SUCCESS);
            assert_eq!(
                props.system_id,
                app.system(),
                "the runtime answered the rest"
            );
            assert_eq!(
                gaze.supports_eye_gaze_interaction.into_raw(),
                7,
                "an extension the application did not enable: neither passed down nor filled"
            );
            assert!(gaze.next.is_null());
        },
    );
}

#[test]
fn nothing_is_synced_before_the_session_is_focused() {
    in_own_process(
        module_path!(),
        "nothing_is_synced_before_the_session_is_focused",
        || {
            // The application attaches its own set and never syncs: fovea syncs alone, and only
            // once the session the application polled is FOCUSED.
            let (mut lp, _) = attached(Chain::fovea().unwrap(), "fix 6,0 for 10s", true);
            for _ in 0..40 {
                lp.poll_events();
                lp.frame().unwrap();
            }
            let (_, valid) = meta_state(&lp);
            assert!(valid, "the gaze is followed");
            let instance = lp.app.instance;
            drop(lp);
            let journal = sim::control::journal(instance);
            let syncs = calls(&journal, "xrSyncActions");
            assert!(syncs.len() > 20, "fovea synced alone: {}", syncs.len());
            for c in &syncs {
                assert!(
                    c.detail.starts_with("state=FOCUSED"),
                    "an xrSyncActions before the session was focused: {}",
                    c.detail
                );
            }
            assert_eq!(sim::control::refusals(instance), vec![]);
        },
    );
}

#[test]
fn the_app_s_binding_modifications_survive() {
    in_own_process(
        module_path!(),
        "the_app_s_binding_modifications_survive",
        || {
            sim::control::set_thread_config(Some(tracker("fix 3,3 for 10s")));
            let mut exts = FOVEATION_EXTENSIONS.to_vec();
            exts.extend([EYE_TRACKED, EYE_GAZE, "XR_KHR_binding_modification"]);
            let app = App::new(Chain::fovea().unwrap(), &exts, API_1_0).unwrap();
            // Its suggestion for the eye gaze profile chains XrBindingModificationsKHR, before any
            // session exists (as engines suggest at start-up).
            let (set, action) = declare(&app, false);
            let modifications = xr::BindingModificationsKHR {
                ty: xr::StructureType::BINDING_MODIFICATIONS_KHR,
                next: std::ptr::null(),
                binding_modification_count: 0,
                binding_modifications: std::ptr::null(),
            };
            let bindings = [xr::ActionSuggestedBinding {
                action,
                binding: path(&app, crate::support::actions::EYE_GAZE_POSE),
            }];
            let info = xr::InteractionProfileSuggestedBinding {
                ty: xr::StructureType::INTERACTION_PROFILE_SUGGESTED_BINDING,
                next: (&modifications as *const xr::BindingModificationsKHR).cast(),
                interaction_profile: path(&app, EYE_GAZE_PROFILE),
                count_suggested_bindings: 1,
                suggested_bindings: bindings.as_ptr(),
            };
            // SAFETY: the type matches the name; the structs live across the call.
            let r = unsafe {
                let f: xr::pfn::SuggestInteractionProfileBindings =
                    app.func(c"xrSuggestInteractionProfileBindings");
                f(app.instance, &info)
            };
            assert_eq!(r, xr::Result::SUCCESS);
            let mut lp = foveated_loop(app);
            attach_set(&lp, set);
            for _ in 0..5 {
                lp.poll_events();
                lp.frame().unwrap();
            }
            let instance = lp.app.instance;
            drop(lp);
            let journal = sim::control::journal(instance);
            let eye: Vec<_> = calls(&journal, "xrSuggestInteractionProfileBindings")
                .into_iter()
                .filter(|c| c.detail == EYE_GAZE_PROFILE.to_str().unwrap())
                .collect();
            assert!(!eye.is_empty());
            for c in &eye {
                assert_eq!(
                    c.next_types,
                    [xr::StructureType::BINDING_MODIFICATIONS_KHR],
                    "every suggestion for the profile carries the application's chain"
                );
            }
            assert_eq!(sim::control::refusals(instance), vec![]);
        },
    );
}

/// The interaction-profile events the application polls in `frames` frames, and the events of
/// that type the runtime queued.
fn profile_events(lp: &mut HeadlessLoop, frames: usize) -> usize {
    let mut got = 0;
    for _ in 0..frames {
        got += lp
            .poll_events()
            .iter()
            .filter(|(ty, _)| *ty == xr::StructureType::EVENT_DATA_INTERACTION_PROFILE_CHANGED)
            .count();
        lp.frame().unwrap();
    }
    got
}

/// `xrGetCurrentInteractionProfile` for `/user/hand/left`.
fn current_profile(lp: &HeadlessLoop) -> (xr::Result, xr::Path) {
    let mut state = xr::InteractionProfileState {
        ty: xr::StructureType::INTERACTION_PROFILE_STATE,
        next: std::ptr::null_mut(),
        interaction_profile: xr::Path::from_raw(99),
    };
    // SAFETY: the type matches the name; the struct lives across the call.
    let r = unsafe {
        let f: xr::pfn::GetCurrentInteractionProfile = lp.func(c"xrGetCurrentInteractionProfile");
        f(lp.session, path(&lp.app, c"/user/hand/left"), &mut state)
    };
    (r, state.interaction_profile)
}

#[test]
fn fovea_s_own_attach_causes_no_event_and_no_profile() {
    in_own_process(
        module_path!(),
        "fovea_s_own_attach_causes_no_event_and_no_profile",
        || {
            // The opt-in: fovea attaches its set alone at once, in an application that attaches
            // none and never enabled XR_EXT_eye_gaze_interaction.
            std::env::set_var("FOVEA_GAZE_ATTACH_AFTER_S", "0");
            let mut lp = running(Chain::fovea().unwrap(), "fix 4,4 for 10s", true, &[]);
            assert_eq!(
                profile_events(&mut lp, 40),
                0,
                "no event reached the application"
            );
            let (_, valid) = meta_state(&lp);
            assert!(valid, "fovea follows the gaze");
            assert_eq!(
                current_profile(&lp).0,
                xr::Result::ERROR_ACTIONSET_NOT_ATTACHED,
                "as without fovea: the application attached nothing"
            );
            // An attach of its own after fovea's is refused, as a second attach is.
            let (set, _) = declare(&lp.app, false);
            assert_eq!(
                attach(&lp, &[set]),
                xr::Result::ERROR_ACTIONSETS_ALREADY_ATTACHED
            );
            let instance = lp.app.instance;
            drop(lp);
            let journal = sim::control::journal(instance);
            assert_eq!(
                journal
                    .iter()
                    .filter(|c| c.function == "xrPollEvent"
                        && c.detail == "interaction profile changed")
                    .count(),
                1,
                "the runtime queued one, for /user/eyes_ext"
            );
            // The one refusal is the application's late attach; fovea's re-poll is valid.
            assert_eq!(
                sim::control::refusals(instance),
                vec![("xrAttachSessionActionSets", 1)]
            );
        },
    );
}

#[test]
fn an_event_fovea_cannot_tell_apart_is_delivered() {
    in_own_process(
        module_path!(),
        "an_event_fovea_cannot_tell_apart_is_delivered",
        || {
            // fovea's set rides with the application's controller set: the runtime's event for
            // /user/eyes_ext names only the session, so fovea cannot tell it from one for the
            // application's paths and delivers it (docs/eye-tracking.md#events-and-queries-the-application-sees).
            // The application's own paths still have the profile they would have without fovea.
            for chain in [Chain::bare(), Chain::fovea().unwrap()] {
                let with = !chain.layers.is_empty();
                let (mut lp, _) = attached(chain, "fix 4,4 for 10s", with);
                let events = profile_events(&mut lp, 20);
                assert_eq!(events, usize::from(with), "fovea: {with}");
                assert_eq!(
                    current_profile(&lp),
                    (xr::Result::SUCCESS, xr::Path::NULL),
                    "no controller: no profile for the application's path"
                );
            }
        },
    );
}

#[test]
fn the_app_s_own_errors_reach_the_runtime_once() {
    in_own_process(
        module_path!(),
        "the_app_s_own_errors_reach_the_runtime_once",
        || {
            let mut lp = running(Chain::fovea().unwrap(), "fix 4,4 for 10s", true, &[]);
            let (set, _) = declare(&lp.app, false);
            let (unattached, _) = {
                // A second set of the application's, never attached.
                let create: xr::pfn::CreateActionSet = unsafe { lp.func(c"xrCreateActionSet") };
                let mut info = xr::ActionSetCreateInfo {
                    ty: xr::StructureType::ACTION_SET_CREATE_INFO,
                    next: std::ptr::null(),
                    action_set_name: [0; xr::MAX_ACTION_SET_NAME_SIZE],
                    localized_action_set_name: [0; xr::MAX_LOCALIZED_ACTION_SET_NAME_SIZE],
                    priority: 0,
                };
                info.action_set_name[..5]
                    .copy_from_slice(&[b'm', b'e', b'n', b'u', 0].map(|b| b as _));
                info.localized_action_set_name[..5]
                    .copy_from_slice(&[b'M', b'e', b'n', b'u', 0].map(|b| b as _));
                let mut s = xr::ActionSet::NULL;
                assert_eq!(
                    unsafe { create(lp.app.instance, &info, &mut s) },
                    xr::Result::SUCCESS
                );
                (s, ())
            };
            // An attach naming a handle that is no set: the application's error.
            let bogus = xr::ActionSet::from_raw(0xdead);
            assert_eq!(attach(&lp, &[set, bogus]), xr::Result::ERROR_HANDLE_INVALID);
            attach_set(&lp, set);
            for _ in 0..5 {
                lp.poll_events();
                lp.frame().unwrap();
            }
            // A sync naming a set never attached: the application's error.
            let sync: xr::pfn::SyncActions = unsafe { lp.func(c"xrSyncActions") };
            assert_eq!(
                sync_of(&lp, sync, unattached),
                xr::Result::ERROR_ACTIONSET_NOT_ATTACHED
            );
            let instance = lp.app.instance;
            drop(lp);
            let refusals = sim::control::refusals(instance);
            assert_eq!(
                refusals,
                vec![("xrAttachSessionActionSets", 1), ("xrSyncActions", 1)],
                "each of the application's errors reached the runtime once"
            );
        },
    );
}

#[test]
fn a_sub_nominal_gaze_is_followed() {
    in_own_process(module_path!(), "a_sub_nominal_gaze_is_followed", || {
        // VALID without TRACKED: the tracker's best estimate, which OpenXR Toolkit and
        // Quad-Views-Foveated use too.
        let (mut lp, set) = attached(
            Chain::fovea().unwrap(),
            "tracked=no; fix 12,0 for 10s",
            true,
        );
        let sync: xr::pfn::SyncActions = unsafe { lp.func(c"xrSyncActions") };
        for _ in 0..30 {
            lp.poll_events();
            sync_set(&lp, sync, set);
            lp.frame().unwrap();
        }
        let (centres, valid) = meta_state(&lp);
        assert!(valid, "the gaze is followed");
        assert!(centres[0][0] > 0.15, "to the right: {centres:?}");
    });
}

#[test]
fn the_gaze_waits_for_the_permission_and_calibration_is_asked_once() {
    in_own_process(
        module_path!(),
        "the_gaze_waits_for_the_permission_and_calibration_is_asked_once",
        || {
            let (mut lp, set) = attached(
                Chain::fovea().unwrap(),
                "permission=2s; fix 12,0 for 10s",
                true,
            );
            let sync: xr::pfn::SyncActions = unsafe { lp.func(c"xrSyncActions") };
            let mut valid = Vec::new();
            for _ in 0..360 {
                lp.poll_events();
                sync_set(&lp, sync, set);
                lp.frame().unwrap();
                valid.push(meta_state(&lp).1);
            }
            // 90 Hz: nothing in the first 1.5 s, the gaze followed from 2.5 s on.
            assert!(
                valid[..135].iter().all(|v| !v),
                "no gaze before the permission"
            );
            assert!(valid[225..].iter().all(|v| *v), "followed once permitted");
            let instance = lp.app.instance;
            drop(lp);
            let journal = sim::control::journal(instance);
            assert_eq!(
                calls(&journal, "xrSyncActions")
                    .iter()
                    .filter(|c| c.detail.contains("calibration requested"))
                    .count(),
                1
            );
        },
    );
}

#[test]
fn with_a_turning_head_each_frame_renders_with_the_gaze_of_its_own_display_time() {
    in_own_process(
        module_path!(),
        "with_a_turning_head_each_frame_renders_with_the_gaze_of_its_own_display_time",
        || {
            // Every sample taken as it is (a saccade threshold below any step between frames), so
            // each view's fovea is exactly the projection of the gaze fovea located.
            std::env::set_var("FOVEA_GAZE_SACCADE_DEG", "0.001");
            // The head turns right at 60°/s while the eye holds a point straight ahead in the
            // world: in VIEW space the gaze turns left at 60°/s, 0.67° a frame at 90 Hz.
            let (mut lp, set, action) = gaze_app("hz=1000; head=60; fix 0,0 for 20s", &[EYE_GAZE]);
            let gaze = action_space(&lp, action);
            // SAFETY: every name's type matches; the structs live across their calls.
            let (sync, view, locate) = unsafe {
                let reference: xr::pfn::CreateReferenceSpace = lp.func(c"xrCreateReferenceSpace");
                let info = xr::ReferenceSpaceCreateInfo {
                    ty: xr::StructureType::REFERENCE_SPACE_CREATE_INFO,
                    next: std::ptr::null(),
                    reference_space_type: xr::ReferenceSpaceType::VIEW,
                    pose_in_reference_space: xr::Posef::IDENTITY,
                };
                let mut view = xr::Space::NULL;
                assert_eq!(reference(lp.session, &info, &mut view), xr::Result::SUCCESS);
                let sync: xr::pfn::SyncActions = lp.func(c"xrSyncActions");
                let locate: xr::pfn::LocateSpace = lp.func(c"xrLocateSpace");
                (sync, view, locate)
            };
            let headset = fovea_model::headsets::by_id("quest3").unwrap();
            let left = fovea_model::gaze::EyeView {
                fov: headset.fovs()[0],
                position: glam::Vec3::new(-0.0315, 0.0, 0.0),
                orientation: glam::Quat::IDENTITY,
            };
            let mut compared = 0;
            let mut moved = 0.0f32;
            let mut last = None;
            for n in 0..45 {
                // hello_xr's order: events, input, then the frame.
                lp.poll_events();
                sync_set(&lp, sync, set);
                lp.frame().unwrap();
                let loc = locate_at_display(&lp, locate, gaze, view);
                let (centres, valid) = meta_state(&lp);
                if n < 5 || !valid {
                    continue;
                }
                // Where the eye looks, in VIEW space, when this frame is shown.
                let o = loc.pose.orientation;
                let dir = glam::Quat::from_xyzw(o.x, o.y, o.z, o.w) * glam::Vec3::NEG_Z;
                let angles = fovea_model::gaze::angles_of(dir).unwrap();
                let want = fovea_model::gaze::eye_centre(
                    &fovea_model::gaze::Gaze {
                        angles,
                        weight: 1.0,
                        tracking: fovea_model::gaze::Tracking::Tracked,
                    },
                    &left,
                    1.0,
                );
                // META's y points down.
                let got = [centres[0][0], -centres[0][1]];
                assert!(
                    (got[0] - want[0]).abs() < 0.003 && (got[1] - want[1]).abs() < 0.003,
                    "frame {n}: the fovea is at {got:?}, the gaze for this frame's display time at \
                     {want:?} (yaw {:.2}°)",
                    angles[0]
                );
                if let Some(prev) = last {
                    moved += got[0] - prev;
                }
                last = Some(got[0]);
                compared += 1;
            }
            assert!(compared > 30, "frames compared: {compared}");
            assert!(moved < -0.3, "the gaze turned left in VIEW space: {moved}");
        },
    );
}

#[test]
fn an_app_s_higher_priority_gaze_set_keeps_the_gaze() {
    in_own_process(
        module_path!(),
        "an_app_s_higher_priority_gaze_set_keeps_the_gaze",
        || {
            // The application binds the gaze itself and raises its set's priority for each sync
            // (XR_EXT_active_action_set_priority): the runtime gives the gaze only to the highest
            // priority. fovea's set has the lowest (0), so it never takes the application's input;
            // here it gets none, and fovea keeps fixed foveation.
            let (mut lp, set, action) = gaze_app(
                "fix 8,0 for 10s",
                &[EYE_GAZE, "XR_EXT_active_action_set_priority"],
            );
            let sync: xr::pfn::SyncActions = unsafe { lp.func(c"xrSyncActions") };
            let get: xr::pfn::GetActionStatePose = unsafe { lp.func(c"xrGetActionStatePose") };
            let raised = [xr::ActiveActionSetPriorityEXT {
                action_set: set,
                priority_override: 5,
            }];
            let priorities = xr::ActiveActionSetPrioritiesEXT {
                ty: xr::StructureType::ACTIVE_ACTION_SET_PRIORITIES_EXT,
                next: std::ptr::null(),
                action_set_priority_count: 1,
                action_set_priorities: raised.as_ptr(),
            };
            let active = [xr::ActiveActionSet {
                action_set: set,
                subaction_path: xr::Path::NULL,
            }];
            let info = xr::ActionsSyncInfo {
                ty: xr::StructureType::ACTIONS_SYNC_INFO,
                next: (&priorities as *const xr::ActiveActionSetPrioritiesEXT).cast(),
                count_active_action_sets: 1,
                active_action_sets: active.as_ptr(),
            };
            let mut own_active = 0;
            let mut followed = 0;
            for _ in 0..40 {
                lp.poll_events();
                // SAFETY: live handles; the structs live across the calls.
                let r = unsafe { sync(lp.session, &info) };
                assert!(r.into_raw() >= 0, "{r:?}");
                lp.frame().unwrap();
                let mut state = xr::ActionStatePose {
                    ty: xr::StructureType::ACTION_STATE_POSE,
                    next: std::ptr::null_mut(),
                    is_active: xr::FALSE,
                };
                let get_info = xr::ActionStateGetInfo {
                    ty: xr::StructureType::ACTION_STATE_GET_INFO,
                    next: std::ptr::null(),
                    action,
                    subaction_path: xr::Path::NULL,
                };
                // SAFETY: as above.
                assert_eq!(
                    unsafe { get(lp.session, &get_info, &mut state) },
                    xr::Result::SUCCESS
                );
                own_active += usize::from(state.is_active == xr::TRUE);
                followed += usize::from(meta_state(&lp).1);
            }
            assert!(
                own_active > 30,
                "the application's gaze stays its own: {own_active}"
            );
            assert_eq!(followed, 0, "fovea's lower-priority action gets no gaze");
            let instance = lp.app.instance;
            drop(lp);
            let journal = sim::control::journal(instance);
            assert!(calls(&journal, "xrSyncActions").iter().any(|c| c
                .next_types
                .contains(&xr::StructureType::ACTIVE_ACTION_SET_PRIORITIES_EXT)));
            assert_eq!(sim::control::refusals(instance), vec![]);
        },
    );
}

#[test]
fn the_app_s_attach_and_fovea_s_own_claim_a_session_once() {
    in_own_process(
        module_path!(),
        "the_app_s_attach_and_fovea_s_own_claim_a_session_once",
        || {
            // The opt-in at once: fovea attaches alone in the first xrWaitFrame, while the
            // application attaches on another thread at the same moment. Exactly one wins: the
            // runtime never sees fovea's attach refused (a second attach after the application's),
            // and the application gets SUCCESS or, where fovea won, the second attach's answer.
            std::env::set_var("FOVEA_GAZE_ATTACH_AFTER_S", "0");
            // The window between fovea's claim and its attach reaching the runtime is a few calls
            // wide: 200 sessions hit it in most runs.
            const SESSIONS: usize = 200;
            let (mut app_won, mut fovea_won) = (0, 0);
            for _ in 0..SESSIONS {
                let mut lp = running(Chain::fovea().unwrap(), "fix 4,4 for 10s", true, &[]);
                let (set, _) = declare(&lp.app, false);
                let session = lp.session;
                let f: xr::pfn::AttachSessionActionSets =
                    unsafe { lp.func(c"xrAttachSessionActionSets") };
                let go = std::sync::Arc::new(std::sync::Barrier::new(2));
                let other = std::sync::Arc::clone(&go);
                let app = std::thread::spawn(move || {
                    let sets = [set];
                    let info = xr::SessionActionSetsAttachInfo {
                        ty: xr::StructureType::SESSION_ACTION_SETS_ATTACH_INFO,
                        next: std::ptr::null(),
                        count_action_sets: 1,
                        action_sets: sets.as_ptr(),
                    };
                    other.wait();
                    // SAFETY: a live session and set; the struct lives across the call.
                    unsafe { f(session, &info) }
                });
                go.wait();
                lp.frame().unwrap();
                let r = app.join().unwrap();
                let instance = lp.app.instance;
                drop(lp);
                let refusals = sim::control::refusals(instance);
                match r {
                    xr::Result::SUCCESS => {
                        app_won += 1;
                        assert_eq!(refusals, vec![], "the application won");
                    }
                    xr::Result::ERROR_ACTIONSETS_ALREADY_ATTACHED => {
                        fovea_won += 1;
                        assert_eq!(
                            refusals,
                            vec![("xrAttachSessionActionSets", 1)],
                            "fovea won: only the application's attach was refused"
                        );
                    }
                    other => panic!("the application's attach: {other:?}"),
                }
            }
            assert_eq!(app_won + fovea_won, SESSIONS);
        },
    );
}
