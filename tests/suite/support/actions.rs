//! An application's own OpenXR input, as the gaze tests declare it: one action set with one pose
//! action bound to a controller or to the eye tracker, attached and synced by the application,
//! with checks that the layer (whose gaze set rides along with it) leaves the application's structs
//! untouched.

use fovea_harness::frame_loop::HeadlessLoop;
use fovea_harness::App;
use openxr_sys as xr;
use xr::Handle;

/// The eye gaze interaction profile and its pose (`XR_EXT_eye_gaze_interaction`).
pub const EYE_GAZE_PROFILE: &std::ffi::CStr = c"/interaction_profiles/ext/eye_gaze_interaction";
pub const EYE_GAZE_POSE: &std::ffi::CStr = c"/user/eyes_ext/input/gaze_ext/pose";

/// `s` as an OpenXR path of `app`'s instance.
pub fn path(app: &App, s: &std::ffi::CStr) -> xr::Path {
    // SAFETY: the type matches the name; the string is NUL-terminated.
    unsafe {
        let f: xr::pfn::StringToPath = app.func(c"xrStringToPath");
        let mut p = xr::Path::NULL;
        assert_eq!(f(app.instance, s.as_ptr(), &mut p), xr::Result::SUCCESS);
        p
    }
}

/// `s` in a fixed-size C string array (NUL-padded).
fn fixed<const N: usize>(s: &str) -> [std::ffi::c_char; N] {
    let mut a = [0; N];
    for (d, b) in a.iter_mut().zip(s.bytes()) {
        *d = b as std::ffi::c_char;
    }
    a
}

/// The application's own set with one pose action, its binding suggested: to a controller, or
/// (`gaze`) to the eye tracker.
pub fn declare(app: &App, gaze: bool) -> (xr::ActionSet, xr::Action) {
    // SAFETY: every name's type matches; the structs live across their calls.
    unsafe {
        let create_set: xr::pfn::CreateActionSet = app.func(c"xrCreateActionSet");
        let create_action: xr::pfn::CreateAction = app.func(c"xrCreateAction");
        let suggest: xr::pfn::SuggestInteractionProfileBindings =
            app.func(c"xrSuggestInteractionProfileBindings");
        let info = xr::ActionSetCreateInfo {
            ty: xr::StructureType::ACTION_SET_CREATE_INFO,
            next: std::ptr::null(),
            action_set_name: fixed("gameplay"),
            localized_action_set_name: fixed("Gameplay"),
            priority: 0,
        };
        let mut set = xr::ActionSet::NULL;
        assert_eq!(
            create_set(app.instance, &info, &mut set),
            xr::Result::SUCCESS
        );
        let info = xr::ActionCreateInfo {
            ty: xr::StructureType::ACTION_CREATE_INFO,
            next: std::ptr::null(),
            action_name: fixed("aim"),
            action_type: xr::ActionType::POSE_INPUT,
            count_subaction_paths: 0,
            subaction_paths: std::ptr::null(),
            localized_action_name: fixed("Aim"),
        };
        let mut action = xr::Action::NULL;
        assert_eq!(create_action(set, &info, &mut action), xr::Result::SUCCESS);
        let (profile, binding) = if gaze {
            (EYE_GAZE_PROFILE, EYE_GAZE_POSE)
        } else {
            (
                c"/interaction_profiles/khr/simple_controller",
                c"/user/hand/left/input/aim/pose",
            )
        };
        let bindings = [xr::ActionSuggestedBinding {
            action,
            binding: path(app, binding),
        }];
        let suggested = xr::InteractionProfileSuggestedBinding {
            ty: xr::StructureType::INTERACTION_PROFILE_SUGGESTED_BINDING,
            next: std::ptr::null(),
            interaction_profile: path(app, profile),
            count_suggested_bindings: 1,
            suggested_bindings: bindings.as_ptr(),
        };
        assert_eq!(suggest(app.instance, &suggested), xr::Result::SUCCESS);
        assert_eq!(
            bindings[0].action, action,
            "the application's struct is untouched"
        );
        assert_eq!(suggested.count_suggested_bindings, 1);
        (set, action)
    }
}

/// Attaches the application's `set` to `lp`'s session.
pub fn attach_set(lp: &HeadlessLoop, set: xr::ActionSet) {
    let sets = [set];
    let info = xr::SessionActionSetsAttachInfo {
        ty: xr::StructureType::SESSION_ACTION_SETS_ATTACH_INFO,
        next: std::ptr::null(),
        count_action_sets: 1,
        action_sets: sets.as_ptr(),
    };
    // SAFETY: the type matches the name; a live session and set; the struct lives across the call.
    unsafe {
        let attach: xr::pfn::AttachSessionActionSets = lp.func(c"xrAttachSessionActionSets");
        assert_eq!(attach(lp.session, &info), xr::Result::SUCCESS);
    }
    assert_eq!(
        info.count_action_sets, 1,
        "the application's struct is untouched"
    );
}

/// The application's xrSyncActions (`sync`, its own pointer) of `set` alone, its result; the
/// application's struct is untouched.
pub fn sync_of(lp: &HeadlessLoop, sync: xr::pfn::SyncActions, set: xr::ActionSet) -> xr::Result {
    let active = [xr::ActiveActionSet {
        action_set: set,
        subaction_path: xr::Path::NULL,
    }];
    let info = xr::ActionsSyncInfo {
        ty: xr::StructureType::ACTIONS_SYNC_INFO,
        next: std::ptr::null(),
        count_active_action_sets: 1,
        active_action_sets: active.as_ptr(),
    };
    // SAFETY: a live session; the struct lives across the call.
    let r = unsafe { sync(lp.session, &info) };
    assert_eq!(info.count_active_action_sets, 1, "untouched");
    r
}

/// The application's xrSyncActions (`sync`, its own pointer) of its own `set`.
pub fn sync_set(lp: &HeadlessLoop, sync: xr::pfn::SyncActions, set: xr::ActionSet) {
    let r = sync_of(lp, sync, set);
    // Unfocused (the first frames) is a success code: input goes to the focused session only.
    assert!(
        [xr::Result::SUCCESS, xr::Result::SESSION_NOT_FOCUSED].contains(&r),
        "{r:?}"
    );
}

/// The application's action space of its pose `action` (no subaction path, identity pose).
pub fn action_space(lp: &HeadlessLoop, action: xr::Action) -> xr::Space {
    let info = xr::ActionSpaceCreateInfo {
        ty: xr::StructureType::ACTION_SPACE_CREATE_INFO,
        next: std::ptr::null(),
        action,
        subaction_path: xr::Path::NULL,
        pose_in_action_space: xr::Posef::IDENTITY,
    };
    let mut space = xr::Space::NULL;
    // SAFETY: the type matches the name; a live session and action; the struct lives across the
    // call.
    unsafe {
        let create: xr::pfn::CreateActionSpace = lp.func(c"xrCreateActionSpace");
        assert_eq!(create(lp.session, &info, &mut space), xr::Result::SUCCESS);
    }
    space
}

/// The application's xrLocateSpace (`locate`, its own pointer) of `space` in `base` at the last
/// frame's predicted display time, which succeeds.
pub fn locate_at_display(
    lp: &HeadlessLoop,
    locate: xr::pfn::LocateSpace,
    space: xr::Space,
    base: xr::Space,
) -> xr::SpaceLocation {
    let mut loc = xr::SpaceLocation {
        ty: xr::StructureType::SPACE_LOCATION,
        next: std::ptr::null_mut(),
        location_flags: xr::SpaceLocationFlags::EMPTY,
        pose: xr::Posef::IDENTITY,
    };
    // SAFETY: live spaces; the struct lives across the call.
    let r = unsafe {
        locate(
            space,
            base,
            lp.last_frame_state.predicted_display_time,
            &mut loc,
        )
    };
    assert_eq!(r, xr::Result::SUCCESS);
    loc
}
