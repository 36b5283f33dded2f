//! The input calls refuse what the spec makes them refuse, with the codes the Khronos CTS checks
//! (its xrCreateActionSet, xrCreateAction, xrSuggestInteractionProfileBindings(_avail) and
//! StateQueryFunctionsAndHaptics cases): names that are not path components, duplicated localized
//! names, subaction paths that are not supported top-level paths or repeat, interaction profiles and
//! binding paths the spec does not define for the instance's version and extensions, and state
//! queries for a subaction path that is not a path or not the action's.

use std::ffi::{c_char, CString};
use std::ptr::{null, null_mut};

use crate::common::*;
use openxr_sys as xr;
use openxr_sys::Handle;

fn path(instance: xr::Instance, s: &str) -> xr::Path {
    let c = CString::new(s).unwrap();
    let mut p = xr::Path::NULL;
    assert_eq!(
        unsafe { xrfn!(instance, StringToPath)(instance, c.as_ptr(), &mut p) },
        xr::Result::SUCCESS
    );
    p
}

fn fill(dst: &mut [c_char], s: &str) {
    dst.fill(0);
    for (d, b) in dst.iter_mut().zip(s.bytes()) {
        *d = b as c_char;
    }
}

fn create_set(
    instance: xr::Instance,
    name: &str,
    localized: &str,
) -> Result<xr::ActionSet, xr::Result> {
    let mut info = xr::ActionSetCreateInfo {
        ty: xr::ActionSetCreateInfo::TYPE,
        next: null(),
        action_set_name: [0; xr::MAX_ACTION_SET_NAME_SIZE],
        localized_action_set_name: [0; xr::MAX_LOCALIZED_ACTION_SET_NAME_SIZE],
        priority: 0,
    };
    fill(&mut info.action_set_name, name);
    fill(&mut info.localized_action_set_name, localized);
    let mut set = xr::ActionSet::NULL;
    match unsafe { xrfn!(instance, CreateActionSet)(instance, &info, &mut set) } {
        xr::Result::SUCCESS => Ok(set),
        e => Err(e),
    }
}

fn create_action(
    instance: xr::Instance,
    set: xr::ActionSet,
    name: &str,
    localized: &str,
    subaction_paths: &[xr::Path],
) -> Result<xr::Action, xr::Result> {
    let mut info = xr::ActionCreateInfo {
        ty: xr::ActionCreateInfo::TYPE,
        next: null(),
        action_name: [0; xr::MAX_ACTION_NAME_SIZE],
        action_type: xr::ActionType::BOOLEAN_INPUT,
        count_subaction_paths: subaction_paths.len() as u32,
        subaction_paths: if subaction_paths.is_empty() {
            null()
        } else {
            subaction_paths.as_ptr()
        },
        localized_action_name: [0; xr::MAX_LOCALIZED_ACTION_NAME_SIZE],
    };
    fill(&mut info.action_name, name);
    fill(&mut info.localized_action_name, localized);
    let mut action = xr::Action::NULL;
    match unsafe { xrfn!(instance, CreateAction)(set, &info, &mut action) } {
        xr::Result::SUCCESS => Ok(action),
        e => Err(e),
    }
}

fn suggest(instance: xr::Instance, profile: &str, action: xr::Action, binding: &str) -> xr::Result {
    let binding = xr::ActionSuggestedBinding {
        action,
        binding: path(instance, binding),
    };
    let info = xr::InteractionProfileSuggestedBinding {
        ty: xr::InteractionProfileSuggestedBinding::TYPE,
        next: null(),
        interaction_profile: path(instance, profile),
        count_suggested_bindings: 1,
        suggested_bindings: &binding,
    };
    unsafe { xrfn!(instance, SuggestInteractionProfileBindings)(instance, &info) }
}

#[test]
fn names_follow_path_component_rules_and_localized_names_are_unique() {
    let instance = create_instance(config("quest3"), &["XR_MND_headless"]);
    assert_eq!(
        create_set(instance, "", "Empty"),
        Err(xr::Result::ERROR_NAME_INVALID)
    );
    assert_eq!(
        create_set(instance, "INVALID PATH COMPONENT", "Invalid"),
        Err(xr::Result::ERROR_PATH_FORMAT_INVALID)
    );
    assert_eq!(
        create_set(instance, "..", "Dots"),
        Err(xr::Result::ERROR_PATH_FORMAT_INVALID)
    );
    assert_eq!(
        create_set(instance, "no_localized", ""),
        Err(xr::Result::ERROR_LOCALIZED_NAME_INVALID)
    );
    let set = create_set(instance, "gameplay", "Gameplay").unwrap();
    assert_eq!(
        create_set(instance, "gameplay", "Other"),
        Err(xr::Result::ERROR_NAME_DUPLICATED)
    );
    assert_eq!(
        create_set(instance, "gameplay_2", "Gameplay"),
        Err(xr::Result::ERROR_LOCALIZED_NAME_DUPLICATED)
    );
    let action = create_action(instance, set, "jump", "Jump", &[]).unwrap();
    assert_eq!(
        create_action(instance, set, "Jump Now", "Jump now", &[]),
        Err(xr::Result::ERROR_PATH_FORMAT_INVALID)
    );
    assert_eq!(
        create_action(instance, set, "jump_2", "Jump", &[]),
        Err(xr::Result::ERROR_LOCALIZED_NAME_DUPLICATED)
    );
    // Freed by destruction.
    assert_eq!(
        unsafe { xrfn!(instance, DestroyAction)(action) },
        xr::Result::SUCCESS
    );
    create_action(instance, set, "jump_2", "Jump", &[]).unwrap();
    assert_eq!(
        unsafe { xrfn!(instance, DestroyActionSet)(set) },
        xr::Result::SUCCESS
    );
    create_set(instance, "gameplay_2", "Gameplay").unwrap();
    destroy_instance(instance);
}

#[test]
fn subaction_paths_must_be_supported_top_level_paths_once() {
    let instance = create_instance(config("quest3"), &["XR_MND_headless"]);
    let set = create_set(instance, "gameplay", "Gameplay").unwrap();
    let head = path(instance, "/user/head");
    assert_eq!(
        create_action(instance, set, "a", "A", &[head, head]),
        Err(xr::Result::ERROR_PATH_UNSUPPORTED)
    );
    assert_eq!(
        create_action(instance, set, "b", "B", &[path(instance, "/user/invalid")]),
        Err(xr::Result::ERROR_PATH_UNSUPPORTED)
    );
    // The eye tracker's path needs its extension.
    assert_eq!(
        create_action(instance, set, "c", "C", &[path(instance, "/user/eyes_ext")]),
        Err(xr::Result::ERROR_PATH_UNSUPPORTED)
    );
    assert_eq!(
        create_action(instance, set, "d", "D", &[xr::Path::from_raw(0x1234)]),
        Err(xr::Result::ERROR_PATH_INVALID)
    );
    let left = path(instance, "/user/hand/left");
    let right = path(instance, "/user/hand/right");
    create_action(instance, set, "e", "E", &[left, right]).unwrap();
    destroy_instance(instance);
}

#[test]
fn only_the_spec_profiles_and_their_paths_can_be_suggested() {
    let simple = "/interaction_profiles/khr/simple_controller";
    for (api, grip_surface) in [
        (
            xr::Version::new(1, 0, 34),
            xr::Result::ERROR_PATH_UNSUPPORTED,
        ),
        (xr::Version::new(1, 1, 0), xr::Result::SUCCESS),
    ] {
        let instance = try_create_instance(config("quest3"), &["XR_MND_headless"], api).unwrap();
        let set = create_set(instance, "gameplay", "Gameplay").unwrap();
        let action = create_action(instance, set, "select", "Select", &[]).unwrap();
        let click = "/user/hand/left/input/select/click";
        assert_eq!(
            suggest(instance, simple, action, click),
            xr::Result::SUCCESS
        );
        // An identifier without its component is a binding path too.
        assert_eq!(
            suggest(instance, simple, action, "/user/hand/left/input/select"),
            xr::Result::SUCCESS
        );
        for profile in [
            "/invalid",
            "/interaction_profiles",
            "/interaction_profiles/invalid",
            "/interaction_profiles/khr/simple_controller/invalid",
            "/interaction_profiles/khr/another_controller",
        ] {
            assert_eq!(
                suggest(instance, profile, action, click),
                xr::Result::ERROR_PATH_UNSUPPORTED,
                "{profile}"
            );
        }
        for binding in [
            "/invalid",
            "/user/hand/right",
            "/user/hand/right/input",
            "/user/head/input/select/click",
            "/user/hand/left/input_bad/menu/click",
            "/user/hand/right/input/select/click/invalid",
        ] {
            assert_eq!(
                suggest(instance, simple, action, binding),
                xr::Result::ERROR_PATH_UNSUPPORTED,
                "{binding}"
            );
        }
        // OpenXR 1.1 added grip_surface: a 1.0 instance cannot bind it.
        assert_eq!(
            suggest(
                instance,
                simple,
                action,
                "/user/hand/right/input/grip_surface/pose"
            ),
            grip_surface
        );
        // Another of the spec's 1.0 profiles.
        assert_eq!(
            suggest(
                instance,
                "/interaction_profiles/google/daydream_controller",
                action,
                "/user/hand/right/input/trackpad/click"
            ),
            xr::Result::SUCCESS
        );
        destroy_instance(instance);
    }
}

#[test]
fn state_queries_check_the_subaction_path() {
    let (instance, session) = headless(config("quest3"));
    let set = create_set(instance, "gameplay", "Gameplay").unwrap();
    let left = path(instance, "/user/hand/left");
    let action = create_action(instance, set, "select", "Select", &[left]).unwrap();
    let attach = xr::SessionActionSetsAttachInfo {
        ty: xr::SessionActionSetsAttachInfo::TYPE,
        next: null(),
        count_action_sets: 1,
        action_sets: &set,
    };
    assert_eq!(
        unsafe { xrfn!(instance, AttachSessionActionSets)(session, &attach) },
        xr::Result::SUCCESS
    );
    let get_boolean = xrfn!(instance, GetActionStateBoolean);
    let query = |subaction_path: xr::Path| {
        let info = xr::ActionStateGetInfo {
            ty: xr::ActionStateGetInfo::TYPE,
            next: null(),
            action,
            subaction_path,
        };
        let mut state = xr::ActionStateBoolean {
            ty: xr::ActionStateBoolean::TYPE,
            next: null_mut(),
            current_state: xr::FALSE,
            changed_since_last_sync: xr::FALSE,
            last_change_time: xr::Time::from_nanos(0),
            is_active: xr::FALSE,
        };
        unsafe { get_boolean(session, &info, &mut state) }
    };
    assert_eq!(query(xr::Path::NULL), xr::Result::SUCCESS);
    assert_eq!(query(left), xr::Result::SUCCESS);
    assert_eq!(
        query(xr::Path::from_raw(0x1234)),
        xr::Result::ERROR_PATH_INVALID
    );
    assert_eq!(
        query(path(instance, "/user/gamepad")),
        xr::Result::ERROR_PATH_UNSUPPORTED
    );
    destroy_instance(instance);
}
