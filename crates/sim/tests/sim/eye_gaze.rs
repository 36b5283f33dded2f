//! The simulated eye tracker (`XR_EXT_eye_gaze_interaction`) behaves as the spec and real runtimes
//! do: active only while supported, focused, bound through the latest suggestion and synced; a
//! gaze space that locates where the script says the eye looks, in VIEW space, with the sample's
//! time; nothing during a blink; Monado's "listed, not supported"; optionally no gaze space before
//! attach (<https://registry.khronos.org/OpenXR/specs/1.1/html/xrspec.html#XR_EXT_eye_gaze_interaction>).

use std::ffi::CString;
use std::ptr::{null, null_mut};

use crate::common::*;
use fovea_sim::control::{EyeGaze, SimConfig};
use fovea_sim::gaze_script::GazeScript;
use openxr_sys as xr;
use openxr_sys::Handle as _;

const EXT: &str = "XR_EXT_eye_gaze_interaction";
const PROFILE: &str = "/interaction_profiles/ext/eye_gaze_interaction";
const GAZE: &str = "/user/eyes_ext/input/gaze_ext/pose";

fn gaze_config(supported: bool, script: &str, space_after_attach: bool) -> SimConfig {
    let mut cfg = config("quest3");
    cfg.eye_gaze = Some(EyeGaze {
        supported,
        space_after_attach,
        script: GazeScript::parse(script).unwrap(),
    });
    cfg
}

fn path(instance: xr::Instance, s: &str) -> xr::Path {
    let to_path = xrfn!(instance, StringToPath);
    let c = CString::new(s).unwrap();
    let mut p = xr::Path::NULL;
    assert_eq!(
        unsafe { to_path(instance, c.as_ptr(), &mut p) },
        xr::Result::SUCCESS
    );
    p
}

fn fill(dst: &mut [std::ffi::c_char], s: &str) {
    for (d, b) in dst.iter_mut().zip(s.bytes()) {
        *d = b as _;
    }
}

fn action_set(instance: xr::Instance, name: &str) -> xr::ActionSet {
    let create = xrfn!(instance, CreateActionSet);
    let mut info = xr::ActionSetCreateInfo {
        ty: xr::ActionSetCreateInfo::TYPE,
        next: null(),
        action_set_name: [0; xr::MAX_ACTION_SET_NAME_SIZE],
        localized_action_set_name: [0; xr::MAX_LOCALIZED_ACTION_SET_NAME_SIZE],
        priority: 0,
    };
    fill(&mut info.action_set_name, name);
    fill(&mut info.localized_action_set_name, name);
    let mut set = xr::ActionSet::NULL;
    assert_eq!(
        unsafe { create(instance, &info, &mut set) },
        xr::Result::SUCCESS
    );
    set
}

fn pose_action(instance: xr::Instance, set: xr::ActionSet, name: &str) -> xr::Action {
    let create = xrfn!(instance, CreateAction);
    let mut info = xr::ActionCreateInfo {
        ty: xr::ActionCreateInfo::TYPE,
        next: null(),
        action_name: [0; xr::MAX_ACTION_NAME_SIZE],
        action_type: xr::ActionType::POSE_INPUT,
        count_subaction_paths: 0,
        subaction_paths: null(),
        localized_action_name: [0; xr::MAX_LOCALIZED_ACTION_NAME_SIZE],
    };
    fill(&mut info.action_name, name);
    fill(&mut info.localized_action_name, name);
    let mut action = xr::Action::NULL;
    assert_eq!(
        unsafe { create(set, &info, &mut action) },
        xr::Result::SUCCESS
    );
    action
}

fn suggest(instance: xr::Instance, profile: &str, bindings: &[(xr::Action, &str)]) -> xr::Result {
    let suggest = xrfn!(instance, SuggestInteractionProfileBindings);
    let list: Vec<xr::ActionSuggestedBinding> = bindings
        .iter()
        .map(|(action, p)| xr::ActionSuggestedBinding {
            action: *action,
            binding: path(instance, p),
        })
        .collect();
    let info = xr::InteractionProfileSuggestedBinding {
        ty: xr::InteractionProfileSuggestedBinding::TYPE,
        next: null(),
        interaction_profile: path(instance, profile),
        count_suggested_bindings: list.len() as u32,
        suggested_bindings: list.as_ptr(),
    };
    unsafe { suggest(instance, &info) }
}

fn attach(instance: xr::Instance, session: xr::Session, sets: &[xr::ActionSet]) {
    let attach = xrfn!(instance, AttachSessionActionSets);
    let info = xr::SessionActionSetsAttachInfo {
        ty: xr::SessionActionSetsAttachInfo::TYPE,
        next: null(),
        count_action_sets: sets.len() as u32,
        action_sets: sets.as_ptr(),
    };
    assert_eq!(unsafe { attach(session, &info) }, xr::Result::SUCCESS);
}

fn sync(instance: xr::Instance, session: xr::Session, sets: &[xr::ActionSet]) -> xr::Result {
    let sync = xrfn!(instance, SyncActions);
    let active: Vec<xr::ActiveActionSet> = sets
        .iter()
        .map(|s| xr::ActiveActionSet {
            action_set: *s,
            subaction_path: xr::Path::NULL,
        })
        .collect();
    let info = xr::ActionsSyncInfo {
        ty: xr::ActionsSyncInfo::TYPE,
        next: null(),
        count_active_action_sets: active.len() as u32,
        active_action_sets: active.as_ptr(),
    };
    unsafe { sync(session, &info) }
}

fn active(instance: xr::Instance, session: xr::Session, action: xr::Action) -> bool {
    let get = xrfn!(instance, GetActionStatePose);
    let info = xr::ActionStateGetInfo {
        ty: xr::ActionStateGetInfo::TYPE,
        next: null(),
        action,
        subaction_path: xr::Path::NULL,
    };
    let mut state = xr::ActionStatePose {
        ty: xr::ActionStatePose::TYPE,
        next: null_mut(),
        is_active: xr::FALSE,
    };
    assert_eq!(
        unsafe { get(session, &info, &mut state) },
        xr::Result::SUCCESS
    );
    state.is_active.into()
}

fn action_space(
    instance: xr::Instance,
    session: xr::Session,
    action: xr::Action,
) -> Result<xr::Space, xr::Result> {
    let create = xrfn!(instance, CreateActionSpace);
    let info = xr::ActionSpaceCreateInfo {
        ty: xr::ActionSpaceCreateInfo::TYPE,
        next: null(),
        action,
        subaction_path: xr::Path::NULL,
        pose_in_action_space: xr::Posef::IDENTITY,
    };
    let mut space = xr::Space::NULL;
    match unsafe { create(session, &info, &mut space) } {
        xr::Result::SUCCESS => Ok(space),
        e => Err(e),
    }
}

/// The gaze space's location in `base` at `time`: the flags, the gaze direction and the sample
/// time.
fn locate(
    instance: xr::Instance,
    space: xr::Space,
    base: xr::Space,
    time: xr::Time,
) -> (xr::SpaceLocationFlags, [f32; 3], i64) {
    let locate = xrfn!(instance, LocateSpace);
    let mut sample = xr::EyeGazeSampleTimeEXT {
        ty: xr::EyeGazeSampleTimeEXT::TYPE,
        next: null_mut(),
        time: xr::Time::from_nanos(0),
    };
    let mut location = xr::SpaceLocation {
        ty: xr::SpaceLocation::TYPE,
        next: &mut sample as *mut _ as *mut _,
        location_flags: xr::SpaceLocationFlags::EMPTY,
        pose: xr::Posef::IDENTITY,
    };
    assert_eq!(
        unsafe { locate(space, base, time, &mut location) },
        xr::Result::SUCCESS
    );
    // −Z turned by the orientation: minus the rotation matrix's third column.
    let xr::Quaternionf { x, y, z, w } = location.pose.orientation;
    let d = [
        -2.0 * (x * z + w * y),
        -2.0 * (y * z - w * x),
        -(1.0 - 2.0 * (x * x + y * y)),
    ];
    (location.location_flags, d, sample.time.as_nanos())
}

/// A running, focused Vulkan-less session with the gaze extension enabled.
fn focused(cfg: SimConfig) -> (xr::Instance, xr::Session) {
    let instance = create_instance(cfg, &["XR_MND_headless", EXT]);
    let session = create_session_with(instance, null()).unwrap();
    assert_eq!(begin_session(instance, session), xr::Result::SUCCESS);
    empty_frame(instance, session);
    empty_frame(instance, session);
    assert_eq!(
        poll_states(instance).last(),
        Some(&xr::SessionState::FOCUSED)
    );
    (instance, session)
}

fn supports(instance: xr::Instance) -> bool {
    let get = xrfn!(instance, GetSystemProperties);
    let mut gaze = xr::SystemEyeGazeInteractionPropertiesEXT {
        ty: xr::SystemEyeGazeInteractionPropertiesEXT::TYPE,
        next: null_mut(),
        supports_eye_gaze_interaction: xr::FALSE,
    };
    let mut props: xr::SystemProperties = unsafe { std::mem::zeroed() };
    props.ty = xr::SystemProperties::TYPE;
    props.next = &mut gaze as *mut _ as *mut _;
    assert_eq!(
        unsafe { get(instance, system(instance), &mut props) },
        xr::Result::SUCCESS
    );
    gaze.supports_eye_gaze_interaction.into()
}

fn direction(yaw: f32, pitch: f32) -> [f32; 3] {
    let (y, p) = (yaw.to_radians(), pitch.to_radians());
    [p.cos() * y.sin(), p.sin(), -p.cos() * y.cos()]
}

fn close(a: [f32; 3], b: [f32; 3]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-4)
}

#[test]
fn gaze_follows_the_script_in_view_space_with_its_sample_time() {
    let script = "hz=100; latency=20ms; fix 10,5 for 2s; blink 500ms; fix -8,0 for 10s";
    let (instance, session) = focused(gaze_config(true, script, false));
    assert!(supports(instance));
    let set = action_set(instance, "gaze");
    let action = pose_action(instance, set, "eye");
    assert_eq!(
        suggest(instance, PROFILE, &[(action, GAZE)]),
        xr::Result::SUCCESS
    );
    attach(instance, session, &[set]);
    let view = reference_space(instance, session, xr::ReferenceSpaceType::VIEW);
    let gaze = action_space(instance, session, action).unwrap();
    // Before a sync nothing is active.
    assert!(!active(instance, session, action));
    assert_eq!(sync(instance, session, &[set]), xr::Result::SUCCESS);
    assert!(active(instance, session, action));
    let t = empty_frame(instance, session);
    let (flags, d, sampled) = locate(instance, gaze, view, t);
    assert!(flags.contains(xr::SpaceLocationFlags::ORIENTATION_VALID));
    assert!(close(d, direction(10.0, 5.0)), "{d:?}");
    assert!(sampled <= t.as_nanos() && sampled > t.as_nanos() - 40_000_000);
    // In the blink (2.0–2.5 s after the session began, reported 20 ms late) there is no gaze;
    // after it the eye is elsewhere.
    let at = |ms: i64| xr::Time::from_nanos(t.as_nanos() + ms * 1_000_000);
    let (during, _, _) = locate(instance, gaze, view, at(2_300));
    assert_eq!(during, xr::SpaceLocationFlags::EMPTY);
    let (after, d, _) = locate(instance, gaze, view, at(3_000));
    assert!(after.contains(xr::SpaceLocationFlags::ORIENTATION_VALID));
    assert!(close(d, direction(-8.0, 0.0)), "{d:?}");
    destroy_instance(instance);
}

#[test]
fn monados_listed_but_unsupported_tracker_is_never_active() {
    let (instance, session) = focused(gaze_config(false, "fix 10,5 for 1s", false));
    assert!(!supports(instance));
    let set = action_set(instance, "gaze");
    let action = pose_action(instance, set, "eye");
    assert_eq!(
        suggest(instance, PROFILE, &[(action, GAZE)]),
        xr::Result::SUCCESS
    );
    attach(instance, session, &[set]);
    let view = reference_space(instance, session, xr::ReferenceSpaceType::VIEW);
    let gaze = action_space(instance, session, action).unwrap();
    assert_eq!(sync(instance, session, &[set]), xr::Result::SUCCESS);
    assert!(!active(instance, session, action));
    let t = empty_frame(instance, session);
    assert_eq!(
        locate(instance, gaze, view, t).0,
        xr::SpaceLocationFlags::EMPTY
    );
    destroy_instance(instance);
}

#[test]
fn a_second_suggestion_replaces_the_first_and_only_synced_sets_are_active() {
    let (instance, session) = focused(gaze_config(true, "fix 0,0 for 1s", false));
    let (app, other) = (action_set(instance, "app"), action_set(instance, "other"));
    let first = pose_action(instance, app, "first");
    let second = pose_action(instance, other, "second");
    assert_eq!(
        suggest(instance, PROFILE, &[(first, GAZE)]),
        xr::Result::SUCCESS
    );
    assert_eq!(
        suggest(instance, PROFILE, &[(second, GAZE)]),
        xr::Result::SUCCESS
    );
    attach(instance, session, &[app, other]);
    assert_eq!(sync(instance, session, &[app, other]), xr::Result::SUCCESS);
    assert!(!active(instance, session, first));
    assert!(active(instance, session, second));
    // A sync that leaves the set out deactivates it.
    assert_eq!(sync(instance, session, &[app]), xr::Result::SUCCESS);
    assert!(!active(instance, session, second));
    destroy_instance(instance);
}

#[test]
fn the_profile_needs_its_extension_and_its_one_path() {
    // Without the extension the profile does not exist.
    let instance = create_instance(gaze_config(true, "", false), &["XR_MND_headless"]);
    let set = action_set(instance, "gaze");
    let action = pose_action(instance, set, "eye");
    assert_eq!(
        suggest(instance, PROFILE, &[(action, GAZE)]),
        xr::Result::ERROR_PATH_UNSUPPORTED
    );
    destroy_instance(instance);
    let instance = create_instance(gaze_config(true, "", false), &["XR_MND_headless", EXT]);
    let set = action_set(instance, "gaze");
    let action = pose_action(instance, set, "eye");
    assert_eq!(
        suggest(
            instance,
            PROFILE,
            &[(action, "/user/hand/left/input/grip/pose")]
        ),
        xr::Result::ERROR_PATH_UNSUPPORTED
    );
    destroy_instance(instance);
}

#[test]
fn unfocused_sessions_get_no_gaze() {
    let cfg = gaze_config(true, "fix 0,0 for 1s", false);
    let instance = create_instance(cfg, &["XR_MND_headless", EXT]);
    let session = create_session_with(instance, null()).unwrap();
    assert_eq!(begin_session(instance, session), xr::Result::SUCCESS);
    let set = action_set(instance, "gaze");
    let action = pose_action(instance, set, "eye");
    assert_eq!(
        suggest(instance, PROFILE, &[(action, GAZE)]),
        xr::Result::SUCCESS
    );
    attach(instance, session, &[set]);
    assert_eq!(
        sync(instance, session, &[set]),
        xr::Result::SESSION_NOT_FOCUSED
    );
    assert!(!active(instance, session, action));
    destroy_instance(instance);
}

#[test]
fn a_runtime_may_refuse_the_gaze_space_before_attach() {
    let (instance, session) = focused(gaze_config(true, "", true));
    let set = action_set(instance, "gaze");
    let action = pose_action(instance, set, "eye");
    assert_eq!(
        suggest(instance, PROFILE, &[(action, GAZE)]),
        xr::Result::SUCCESS
    );
    assert_eq!(
        action_space(instance, session, action),
        Err(xr::Result::ERROR_ACTIONSET_NOT_ATTACHED)
    );
    attach(instance, session, &[set]);
    assert!(action_space(instance, session, action).is_ok());
    destroy_instance(instance);
}

#[test]
fn the_extension_is_listed_only_with_a_tracker() {
    for (cfg, listed) in [
        (config("quest3"), false),
        (gaze_config(false, "", false), true),
    ] {
        fovea_sim::control::set_thread_config(Some(cfg));
        let enumerate = xrfn!(xr::Instance::NULL, EnumerateInstanceExtensionProperties);
        let mut n = 0;
        assert_eq!(
            unsafe { enumerate(null(), 0, &mut n, null_mut()) },
            xr::Result::SUCCESS
        );
        let blank = xr::ExtensionProperties {
            ty: xr::ExtensionProperties::TYPE,
            next: null_mut(),
            extension_name: [0; xr::MAX_EXTENSION_NAME_SIZE],
            extension_version: 0,
        };
        let mut props = vec![blank; n as usize];
        assert_eq!(
            unsafe { enumerate(null(), n, &mut n, props.as_mut_ptr()) },
            xr::Result::SUCCESS
        );
        let names: Vec<String> = props
            .iter()
            .map(|p| {
                let bytes: Vec<u8> = p
                    .extension_name
                    .iter()
                    .take_while(|&&c| c != 0)
                    .map(|&c| c as u8)
                    .collect();
                String::from_utf8(bytes).unwrap()
            })
            .collect();
        assert_eq!(names.iter().any(|n| n == EXT), listed, "{names:?}");
    }
}
