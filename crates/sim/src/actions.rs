//! Minimal input (spec chapter "Input and Haptics"): action sets and actions can be created,
//! bindings suggested and sets attached, but the simulated headset has no controllers, so every
//! controller action is inactive. Enough for applications such as Khronos hello_xr to run their
//! input code unchanged.
//!
//! The one device that can be present is an eye tracker (`XR_EXT_eye_gaze_interaction`,
//! <https://registry.khronos.org/OpenXR/specs/1.1/html/xrspec.html#XR_EXT_eye_gaze_interaction>):
//! a pose action bound to its gaze path through the latest suggestion for its profile is active
//! while the tracker is supported, the session focused and the action's set made active by the
//! last xrSyncActions; its action space then locates where the script says the eye looks.

use std::ffi::c_char;

use openxr_sys as xr;
use openxr_sys::Handle;

use crate::extensions::{EXT_ACTIVE_ACTION_SET_PRIORITY, EXT_EYE_GAZE_INTERACTION};
use crate::ffi::{self, check_pose};
use crate::objects::{Action, ActionSet, Event, InstanceState, Space, SpaceKind};
use crate::profiles;
use crate::state::{entry, world, World};

/// The eye gaze interaction profile.
pub(crate) const EYE_GAZE_PROFILE: &str = "/interaction_profiles/ext/eye_gaze_interaction";
/// The eye tracker's top-level user path.
const EYES: &str = "/user/eyes_ext";

/// The top-level user paths of the spec's interaction profiles and the eye tracker's (Monado
/// answers XR_ERROR_PATH_UNSUPPORTED for any other path in xrGetCurrentInteractionProfile).
const TOP_LEVEL_PATHS: [&str; 6] = [
    "/user/hand/left",
    "/user/hand/right",
    "/user/head",
    "/user/gamepad",
    "/user/treadmill",
    "/user/eyes_ext",
];

/// Action and action set names (spec xrCreateActionSet, xrCreateAction): empty is
/// XR_ERROR_NAME_INVALID; one that is not a well-formed path component (lower-case ASCII letters,
/// digits, `-`, `_`, `.`, not only periods; "Well-Formed Path Strings") is
/// XR_ERROR_PATH_FORMAT_INVALID; an empty localized name is XR_ERROR_LOCALIZED_NAME_INVALID.
/// Returns the name and the localized name.
fn check_names(name: &[c_char], localized: &[c_char]) -> Result<(String, String), xr::Result> {
    let name = ffi::fixed_str(name).ok_or(xr::Result::ERROR_NAME_INVALID)?;
    if name.is_empty() {
        return Err(xr::Result::ERROR_NAME_INVALID);
    }
    let well_formed = name
        .bytes()
        .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b"-_.".contains(&b))
        && !name.bytes().all(|b| b == b'.');
    if !well_formed {
        return Err(xr::Result::ERROR_PATH_FORMAT_INVALID);
    }
    match ffi::fixed_str(localized) {
        Some(l) if !l.is_empty() => Ok((name.to_string(), l.to_string())),
        _ => Err(xr::Result::ERROR_LOCALIZED_NAME_INVALID),
    }
}

/// Whether `user` is a top-level user path this instance may use: the spec's, and the eye
/// tracker's with its extension.
fn top_level_path_supported(inst: &InstanceState, user: &str) -> bool {
    TOP_LEVEL_PATHS.contains(&user)
        && (user != EYES || inst.has_extension(EXT_EYE_GAZE_INTERACTION))
}

pub(crate) unsafe extern "system" fn create_action_set(
    instance: xr::Instance,
    create_info: *const xr::ActionSetCreateInfo,
    action_set: *mut xr::ActionSet,
) -> xr::Result {
    entry("xrCreateActionSet", |ctx| {
        let mut w = world();
        let inst = w.enter_instance(ctx, instance)?;
        let info = ffi::input(create_info, xr::StructureType::ACTION_SET_CREATE_INFO)?;
        ffi::non_null(action_set)?;
        let (name, localized_name) =
            check_names(&info.action_set_name, &info.localized_action_set_name)?;
        let mut sets = w.action_sets.values().filter(|s| s.instance == inst);
        if sets.clone().any(|s| s.name == name) {
            return Err(xr::Result::ERROR_NAME_DUPLICATED);
        }
        if sets.any(|s| s.localized_name == localized_name) {
            return Err(xr::Result::ERROR_LOCALIZED_NAME_DUPLICATED);
        }
        ctx.detail = name.clone();
        let id = w.alloc_handle();
        w.action_sets.insert(
            id,
            ActionSet {
                instance: inst,
                name,
                localized_name,
                attached: false,
                priority: info.priority,
            },
        );
        *action_set = xr::ActionSet::from_raw(id);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn destroy_action_set(action_set: xr::ActionSet) -> xr::Result {
    entry("xrDestroyActionSet", |ctx| {
        ctx.allow_lost = true;
        let mut w = world();
        let id = w.enter_action_set(ctx, action_set)?;
        w.action_sets.remove(&id);
        w.actions.retain(|_, a| a.set != id);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn create_action(
    action_set: xr::ActionSet,
    create_info: *const xr::ActionCreateInfo,
    action: *mut xr::Action,
) -> xr::Result {
    entry("xrCreateAction", |ctx| {
        let mut w = world();
        let set = w.enter_action_set(ctx, action_set)?;
        let info = ffi::input(create_info, xr::StructureType::ACTION_CREATE_INFO)?;
        ffi::non_null(action)?;
        let (name, localized_name) = check_names(&info.action_name, &info.localized_action_name)?;
        let known = [
            xr::ActionType::BOOLEAN_INPUT,
            xr::ActionType::FLOAT_INPUT,
            xr::ActionType::VECTOR2F_INPUT,
            xr::ActionType::POSE_INPUT,
            xr::ActionType::VIBRATION_OUTPUT,
        ];
        if !known.contains(&info.action_type) {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        if w.action_sets[&set].attached {
            return Err(xr::Result::ERROR_ACTIONSETS_ALREADY_ATTACHED);
        }
        let mut siblings = w.actions.values().filter(|a| a.set == set);
        if siblings.clone().any(|a| a.name == name) {
            return Err(xr::Result::ERROR_NAME_DUPLICATED);
        }
        if siblings.any(|a| a.localized_name == localized_name) {
            return Err(xr::Result::ERROR_LOCALIZED_NAME_DUPLICATED);
        }
        ctx.detail = name.clone();
        let instance = w.action_sets[&set].instance;
        // Spec (xrCreateAction): each subaction path must be a valid path (XR_ERROR_PATH_INVALID),
        // a top-level user path the runtime supports, and appear once (XR_ERROR_PATH_UNSUPPORTED).
        let inst = &w.instances[&instance];
        let mut subaction_paths = Vec::with_capacity(info.count_subaction_paths as usize);
        if info.count_subaction_paths > 0 {
            ffi::non_null(info.subaction_paths)?;
        }
        for i in 0..info.count_subaction_paths as usize {
            let path = inst
                .path(*info.subaction_paths.add(i))
                .ok_or(xr::Result::ERROR_PATH_INVALID)?;
            if !top_level_path_supported(inst, path) || subaction_paths.iter().any(|p| p == path) {
                return Err(xr::Result::ERROR_PATH_UNSUPPORTED);
            }
            subaction_paths.push(path.to_owned());
        }
        let id = w.alloc_handle();
        w.actions.insert(
            id,
            Action {
                instance,
                set,
                name,
                localized_name,
                ty: info.action_type,
                subaction_paths,
            },
        );
        *action = xr::Action::from_raw(id);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn destroy_action(action: xr::Action) -> xr::Result {
    entry("xrDestroyAction", |ctx| {
        ctx.allow_lost = true;
        let mut w = world();
        let id = w.enter_action(ctx, action)?;
        w.actions.remove(&id);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn suggest_interaction_profile_bindings(
    instance: xr::Instance,
    suggested: *const xr::InteractionProfileSuggestedBinding,
) -> xr::Result {
    entry("xrSuggestInteractionProfileBindings", |ctx| {
        let mut w = world();
        let id = w.enter_instance(ctx, instance)?;
        let info = ffi::input(
            suggested,
            xr::StructureType::INTERACTION_PROFILE_SUGGESTED_BINDING,
        )?;
        let profile = w.instances[&id]
            .path(info.interaction_profile)
            .ok_or(xr::Result::ERROR_PATH_INVALID)?;
        ctx.detail = profile.to_string();
        ctx.next_types = ffi::chain_types(info.next);
        if info.count_suggested_bindings == 0 {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        ffi::non_null(info.suggested_bindings)?;
        // Only the spec's profiles, those of the instance's version and extensions
        // ([`crate::profiles`]).
        let inst = &w.instances[&id];
        let minor = inst.api_version.minor();
        let enabled = |e: &str| inst.has_extension(e);
        if !profiles::is_known_profile(profile, minor, &enabled) {
            return Err(xr::Result::ERROR_PATH_UNSUPPORTED);
        }
        let profile = profile.to_string();
        let mut bindings = Vec::with_capacity(info.count_suggested_bindings as usize);
        for i in 0..info.count_suggested_bindings as usize {
            let b = &*info.suggested_bindings.add(i);
            let action = w
                .actions
                .get(&b.action.into_raw())
                .ok_or(xr::Result::ERROR_HANDLE_INVALID)?;
            if action.instance != id {
                return Err(xr::Result::ERROR_HANDLE_INVALID);
            }
            if w.action_sets[&action.set].attached {
                return Err(xr::Result::ERROR_ACTIONSETS_ALREADY_ATTACHED);
            }
            let path = inst.path(b.binding).ok_or(xr::Result::ERROR_PATH_INVALID)?;
            if !profiles::is_known_binding(&profile, path, minor, &enabled) {
                return Err(xr::Result::ERROR_PATH_UNSUPPORTED);
            }
            bindings.push((b.action.into_raw(), path.to_string()));
        }
        w.instances
            .get_mut(&id)
            .expect("entered instance exists")
            .suggested
            .insert(profile, bindings);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn attach_session_action_sets(
    session: xr::Session,
    attach_info: *const xr::SessionActionSetsAttachInfo,
) -> xr::Result {
    entry("xrAttachSessionActionSets", |ctx| {
        let mut w = world();
        let id = w.enter_session(ctx, session)?;
        let info = ffi::input(
            attach_info,
            xr::StructureType::SESSION_ACTION_SETS_ATTACH_INFO,
        )?;
        if !w.sessions[&id].action_sets_attached.is_empty() {
            return Err(xr::Result::ERROR_ACTIONSETS_ALREADY_ATTACHED);
        }
        if info.count_action_sets == 0 {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        ffi::non_null(info.action_sets)?;
        let sets: Vec<u64> = (0..info.count_action_sets as usize)
            .map(|i| (*info.action_sets.add(i)).into_raw())
            .collect();
        if sets.iter().any(|s| !w.action_sets.contains_key(s)) {
            return Err(xr::Result::ERROR_HANDLE_INVALID);
        }
        for s in &sets {
            w.action_sets.get_mut(s).expect("checked above").attached = true;
        }
        // Bindings are fixed at attach: the gaze actions are those the latest eye gaze
        // suggestion names, in the sets attached now.
        let instance = w.sessions[&id].instance;
        let gaze_actions: Vec<u64> = w.instances[&instance]
            .suggested
            .get(EYE_GAZE_PROFILE)
            .into_iter()
            .flatten()
            .map(|(a, _)| *a)
            .filter(|a| w.actions.get(a).is_some_and(|a| sets.contains(&a.set)))
            .collect();
        // The eye tracker is the one device: /user/eyes_ext gets the eye gaze profile where an
        // attached action is bound to it and the tracker is there, and, as Monado does for each
        // top-level path whose profile changes at attach, an event says so.
        let tracker = w.instances[&instance]
            .config
            .eye_gaze
            .as_ref()
            .is_some_and(|g| g.supported);
        let s = w.sessions.get_mut(&id).expect("entered session exists");
        s.action_sets_attached = sets;
        let bound = tracker && !gaze_actions.is_empty();
        s.gaze_actions = gaze_actions;
        if bound {
            s.current_profiles
                .push((EYES.to_owned(), EYE_GAZE_PROFILE.to_owned()));
            w.instances
                .get_mut(&instance)
                .expect("session's instance exists")
                .events
                .push_back(Event::InteractionProfileChanged { session: id });
        }
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn get_current_interaction_profile(
    session: xr::Session,
    top_level_user_path: xr::Path,
    profile: *mut xr::InteractionProfileState,
) -> xr::Result {
    entry("xrGetCurrentInteractionProfile", |ctx| {
        let mut w = world();
        let id = w.enter_session(ctx, session)?;
        let p = ffi::output(profile, xr::StructureType::INTERACTION_PROFILE_STATE)?;
        let instance = w.sessions[&id].instance;
        let user = w.instances[&instance]
            .path(top_level_user_path)
            .ok_or(xr::Result::ERROR_PATH_INVALID)?
            .to_owned();
        ctx.detail = user.clone();
        if w.sessions[&id].action_sets_attached.is_empty() {
            return Err(xr::Result::ERROR_ACTIONSET_NOT_ATTACHED);
        }
        if !top_level_path_supported(&w.instances[&instance], &user) {
            return Err(xr::Result::ERROR_PATH_UNSUPPORTED);
        }
        let current = w.sessions[&id]
            .current_profiles
            .iter()
            .find(|(u, _)| *u == user)
            .map(|(_, p)| p.clone());
        // The profile's path, as xrStringToPath gives it.
        let inst = w
            .instances
            .get_mut(&instance)
            .expect("session's instance exists");
        (*p).interaction_profile = match current {
            None => xr::Path::NULL,
            Some(profile) => {
                let index = match inst.paths.iter().position(|p| *p == profile) {
                    Some(i) => i,
                    None => {
                        inst.paths.push(profile);
                        inst.paths.len() - 1
                    }
                };
                xr::Path::from_raw(index as u64 + 1)
            }
        };
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn sync_actions(
    session: xr::Session,
    sync_info: *const xr::ActionsSyncInfo,
) -> xr::Result {
    entry("xrSyncActions", |ctx| {
        let mut w = world();
        let id = w.enter_session(ctx, session)?;
        let info = ffi::input(sync_info, xr::StructureType::ACTIONS_SYNC_INFO)?;
        let s = &w.sessions[&id];
        let mut active = Vec::with_capacity(info.count_active_action_sets as usize);
        if info.count_active_action_sets > 0 {
            ffi::non_null(info.active_action_sets)?;
            for i in 0..info.count_active_action_sets as usize {
                let set = (*info.active_action_sets.add(i)).action_set.into_raw();
                if !s.action_sets_attached.contains(&set) {
                    return Err(xr::Result::ERROR_ACTIONSET_NOT_ATTACHED);
                }
                active.push(set);
            }
        }
        // Spec: input is only delivered to the focused session, and a sync activates only the
        // sets it lists. The journal says the state each sync came in.
        let state = s.state;
        ctx.detail = format!("state={state:?}");
        let focused = state == xr::SessionState::FOCUSED;
        // Priorities (XrActionSetCreateInfo::priority, overridden per sync by
        // XR_EXT_active_action_set_priority where enabled): of the active sets with actions bound
        // to the gaze, only those of the highest priority get it.
        let inst = &w.instances[&s.instance];
        let overrides: Vec<(u64, u32)> = match ffi::find_in_chain(
            info.next,
            xr::StructureType::ACTIVE_ACTION_SET_PRIORITIES_EXT,
        ) {
            Some(p) if inst.has_extension(EXT_ACTIVE_ACTION_SET_PRIORITY) => {
                let p = &*(p as *const xr::ActiveActionSetPrioritiesEXT);
                if p.action_set_priority_count > 0 {
                    ffi::non_null(p.action_set_priorities)?;
                }
                (0..p.action_set_priority_count as usize)
                    .map(|i| {
                        let e = &*p.action_set_priorities.add(i);
                        (e.action_set.into_raw(), e.priority_override)
                    })
                    .collect()
            }
            _ => Vec::new(),
        };
        ctx.next_types = ffi::chain_types(info.next);
        let priority = |set: u64| {
            overrides
                .iter()
                .find(|(s, _)| *s == set)
                .map_or(w.action_sets[&set].priority, |(_, p)| *p)
        };
        let bound: Vec<u64> = active
            .iter()
            .copied()
            .filter(|set| {
                s.gaze_actions
                    .iter()
                    .any(|a| w.actions.get(a).is_some_and(|a| a.set == *set))
            })
            .collect();
        let top = bound.iter().map(|set| priority(*set)).max();
        let gaze_sets: Vec<u64> = bound
            .iter()
            .copied()
            .filter(|set| Some(priority(*set)) == top)
            .collect();
        // XR_EXT_eye_gaze_interaction: "the runtime should request eye tracker calibration from
        // the user" at the first sync of a set bound to the tracker; the journal records it.
        let gaze_bound = s
            .gaze_actions
            .iter()
            .any(|a| w.actions.get(a).is_some_and(|a| active.contains(&a.set)));
        let s = w.sessions.get_mut(&id).expect("entered session exists");
        if gaze_bound && !s.calibration_requested {
            s.calibration_requested = true;
            ctx.detail.push_str(" eye tracker calibration requested");
        }
        s.synced_sets = if focused { active } else { Vec::new() };
        s.gaze_sets = if focused { gaze_sets } else { Vec::new() };
        if !focused {
            return Ok(xr::Result::SESSION_NOT_FOCUSED);
        }
        Ok(xr::Result::SUCCESS)
    })
}

/// Validates an XrActionStateGetInfo (or the equivalent haptic info) against the expected type.
/// A non-null `subaction_path` must be a valid path (XR_ERROR_PATH_INVALID) and one the action was
/// created with (XR_ERROR_PATH_UNSUPPORTED), as the spec's state and haptic commands require.
unsafe fn check_action(
    w: &World,
    session: u64,
    action: xr::Action,
    subaction_path: xr::Path,
    types: &[xr::ActionType],
) -> Result<(), xr::Result> {
    let a = w
        .actions
        .get(&action.into_raw())
        .ok_or(xr::Result::ERROR_HANDLE_INVALID)?;
    if !types.contains(&a.ty) {
        return Err(xr::Result::ERROR_ACTION_TYPE_MISMATCH);
    }
    if !w.sessions[&session].action_sets_attached.contains(&a.set) {
        return Err(xr::Result::ERROR_ACTIONSET_NOT_ATTACHED);
    }
    if subaction_path != xr::Path::NULL {
        let path = w.instances[&a.instance]
            .path(subaction_path)
            .ok_or(xr::Result::ERROR_PATH_INVALID)?;
        if !a.subaction_paths.iter().any(|p| p == path) {
            return Err(xr::Result::ERROR_PATH_UNSUPPORTED);
        }
    }
    Ok(())
}

/// Whether `action` gets gaze in `session` now: an eye tracker that is supported and permitted
/// (the script's `permission`), its extension enabled, the session focused, the action bound to the
/// gaze pose at attach and its set active, of the highest priority among those bound to the gaze,
/// since the last sync.
pub(crate) fn gaze_active(w: &World, session: u64, action: u64) -> bool {
    let s = &w.sessions[&session];
    let inst = &w.instances[&s.instance];
    inst.config
        .eye_gaze
        .as_ref()
        .is_some_and(|g| g.supported && inst.now_ns - s.gaze_origin_ns >= g.script.permission_ns)
        && inst.has_extension(EXT_EYE_GAZE_INTERACTION)
        && s.state == xr::SessionState::FOCUSED
        && s.gaze_actions.contains(&action)
        && w.actions
            .get(&action)
            .is_some_and(|a| s.synced_sets.contains(&a.set) && s.gaze_sets.contains(&a.set))
}

macro_rules! action_state_getter {
    ($fn_name:ident, $command:literal, $state:ty, $state_type:ident, $action_type:ident) => {
        pub(crate) unsafe extern "system" fn $fn_name(
            session: xr::Session,
            get_info: *const xr::ActionStateGetInfo,
            state: *mut $state,
        ) -> xr::Result {
            entry($command, |ctx| {
                let mut w = world();
                let id = w.enter_session(ctx, session)?;
                let info = ffi::input(get_info, xr::StructureType::ACTION_STATE_GET_INFO)?;
                let p = ffi::output(state, xr::StructureType::$state_type)?;
                check_action(
                    &w,
                    id,
                    info.action,
                    info.subaction_path,
                    &[xr::ActionType::$action_type],
                )?;
                // No controller: the action is inactive and every value is zero; a pose bound to
                // a present eye tracker is active (its `isActive` follows the zeroed header).
                let active = gaze_active(&w, id, info.action.into_raw());
                let (ty, next) = ((*p).ty, (*p).next);
                std::ptr::write_bytes(p, 0, 1);
                (*p).ty = ty;
                (*p).next = next;
                set_active(p, active);
                Ok(xr::Result::SUCCESS)
            })
        }
    };
}

/// Marks a zeroed action state active; only pose states can be (the eye tracker's).
pub(crate) trait ActionState {
    fn set_active(&mut self, active: bool);
}

macro_rules! inactive_only {
    ($($t:ty),*) => {$(
        impl ActionState for $t {
            fn set_active(&mut self, _: bool) {}
        }
    )*};
}
inactive_only!(
    xr::ActionStateBoolean,
    xr::ActionStateFloat,
    xr::ActionStateVector2f
);

impl ActionState for xr::ActionStatePose {
    fn set_active(&mut self, active: bool) {
        self.is_active = active.into();
    }
}

/// # Safety
/// `p` must be a valid, writable state.
pub(crate) unsafe fn set_active<T: ActionState>(p: *mut T, active: bool) {
    (*p).set_active(active);
}

action_state_getter!(
    get_action_state_boolean,
    "xrGetActionStateBoolean",
    xr::ActionStateBoolean,
    ACTION_STATE_BOOLEAN,
    BOOLEAN_INPUT
);
action_state_getter!(
    get_action_state_float,
    "xrGetActionStateFloat",
    xr::ActionStateFloat,
    ACTION_STATE_FLOAT,
    FLOAT_INPUT
);
action_state_getter!(
    get_action_state_vector2f,
    "xrGetActionStateVector2f",
    xr::ActionStateVector2f,
    ACTION_STATE_VECTOR2F,
    VECTOR2F_INPUT
);
action_state_getter!(
    get_action_state_pose,
    "xrGetActionStatePose",
    xr::ActionStatePose,
    ACTION_STATE_POSE,
    POSE_INPUT
);

pub(crate) unsafe extern "system" fn apply_haptic_feedback(
    session: xr::Session,
    info: *const xr::HapticActionInfo,
    feedback: *const xr::HapticBaseHeader,
) -> xr::Result {
    entry("xrApplyHapticFeedback", |ctx| {
        let mut w = world();
        let id = w.enter_session(ctx, session)?;
        let info = ffi::input(info, xr::StructureType::HAPTIC_ACTION_INFO)?;
        ffi::input(
            feedback as *const xr::HapticVibration,
            xr::StructureType::HAPTIC_VIBRATION,
        )?;
        check_action(
            &w,
            id,
            info.action,
            info.subaction_path,
            &[xr::ActionType::VIBRATION_OUTPUT],
        )?;
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn stop_haptic_feedback(
    session: xr::Session,
    info: *const xr::HapticActionInfo,
) -> xr::Result {
    entry("xrStopHapticFeedback", |ctx| {
        let mut w = world();
        let id = w.enter_session(ctx, session)?;
        let info = ffi::input(info, xr::StructureType::HAPTIC_ACTION_INFO)?;
        check_action(
            &w,
            id,
            info.action,
            info.subaction_path,
            &[xr::ActionType::VIBRATION_OUTPUT],
        )?;
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn create_action_space(
    session: xr::Session,
    create_info: *const xr::ActionSpaceCreateInfo,
    space: *mut xr::Space,
) -> xr::Result {
    entry("xrCreateActionSpace", |ctx| {
        let mut w = world();
        let id = w.enter_session(ctx, session)?;
        let info = ffi::input(create_info, xr::StructureType::ACTION_SPACE_CREATE_INFO)?;
        ffi::non_null(space)?;
        let action = w
            .actions
            .get(&info.action.into_raw())
            .ok_or(xr::Result::ERROR_HANDLE_INVALID)?;
        if action.ty != xr::ActionType::POSE_INPUT {
            return Err(xr::Result::ERROR_ACTION_TYPE_MISMATCH);
        }
        check_pose(&info.pose_in_action_space)?;
        let action_id = info.action.into_raw();
        // Some runtimes cannot make a gaze space before the set is attached (configured).
        let s = &w.sessions[&id];
        let inst = &w.instances[&s.instance];
        let suggested_for_gaze = inst
            .suggested
            .get(EYE_GAZE_PROFILE)
            .is_some_and(|b| b.iter().any(|(a, _)| *a == action_id));
        if inst
            .config
            .eye_gaze
            .as_ref()
            .is_some_and(|g| g.space_after_attach)
            && suggested_for_gaze
            && !s.action_sets_attached.contains(&action.set)
        {
            return Err(xr::Result::ERROR_ACTIONSET_NOT_ATTACHED);
        }
        let space_id = w.alloc_handle();
        w.spaces.insert(
            space_id,
            Space {
                session: id,
                kind: SpaceKind::Action(action_id),
                pose_in_parent: info.pose_in_action_space,
            },
        );
        *space = xr::Space::from_raw(space_id);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn enumerate_bound_sources_for_action(
    session: xr::Session,
    enumerate_info: *const xr::BoundSourcesForActionEnumerateInfo,
    capacity: u32,
    count_out: *mut u32,
    sources: *mut xr::Path,
) -> xr::Result {
    entry("xrEnumerateBoundSourcesForAction", |ctx| {
        let mut w = world();
        let id = w.enter_session(ctx, session)?;
        let info = ffi::input(
            enumerate_info,
            xr::StructureType::BOUND_SOURCES_FOR_ACTION_ENUMERATE_INFO,
        )?;
        let all = [
            xr::ActionType::BOOLEAN_INPUT,
            xr::ActionType::FLOAT_INPUT,
            xr::ActionType::VECTOR2F_INPUT,
            xr::ActionType::POSE_INPUT,
            xr::ActionType::VIBRATION_OUTPUT,
        ];
        check_action(&w, id, info.action, xr::Path::NULL, &all)?;
        ffi::two_call(capacity, count_out, sources, 0, |_, _| Ok(()))?;
        Ok(xr::Result::SUCCESS)
    })
}

/// The name xrGetInputSourceLocalizedName gives `path` for the `which` components: the user path
/// ("Left Hand"), the interaction profile (the simulated headset has one kind of controller, so
/// always "Simulated Controller") and the input or output component ("Select Click"), in that
/// order, from the path's own segments.
fn localized_name(path: &str, which: xr::InputSourceLocalizedNameFlags) -> String {
    let words = |segments: &[&str]| -> Vec<String> {
        segments
            .iter()
            .flat_map(|s| s.split('_'))
            .filter(|w| !w.is_empty())
            .map(|w| {
                let mut c = w.chars();
                c.next()
                    .map(|f| f.to_uppercase().chain(c).collect())
                    .unwrap_or_default()
            })
            .collect()
    };
    let segments: Vec<&str> = path.split('/').filter(|s| !s.is_empty()).collect();
    // /user/<...>/input|output/<component...>
    let split = segments
        .iter()
        .position(|s| *s == "input" || *s == "output")
        .unwrap_or(segments.len());
    let mut parts = Vec::new();
    if which.contains(xr::InputSourceLocalizedNameFlags::USER_PATH) {
        let mut user = words(segments.get(1..split).unwrap_or_default());
        // "hand left" reads "Left Hand".
        user.reverse();
        parts.extend(user);
    }
    if which.contains(xr::InputSourceLocalizedNameFlags::INTERACTION_PROFILE) {
        parts.push("Simulated Controller".to_owned());
    }
    if which.contains(xr::InputSourceLocalizedNameFlags::COMPONENT) {
        parts.extend(words(segments.get(split + 1..).unwrap_or_default()));
    }
    parts.join(" ")
}

/// A core 1.0 command every runtime has: bindings wrappers such as the `openxr` crate resolve the
/// whole core table at xrCreateInstance and fail if any command is missing.
pub(crate) unsafe extern "system" fn get_input_source_localized_name(
    session: xr::Session,
    get_info: *const xr::InputSourceLocalizedNameGetInfo,
    capacity: u32,
    count_out: *mut u32,
    buffer: *mut c_char,
) -> xr::Result {
    entry("xrGetInputSourceLocalizedName", |ctx| {
        let mut w = world();
        let id = w.enter_session(ctx, session)?;
        let info = ffi::input(
            get_info,
            xr::StructureType::INPUT_SOURCE_LOCALIZED_NAME_GET_INFO,
        )?;
        ctx.next_types = ffi::chain_types(info.next);
        // VU: whichComponents must not be 0.
        if info.which_components.is_empty() {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        let instance = w.sessions[&id].instance;
        let path = w.instances[&instance]
            .path(info.source_path)
            .ok_or(xr::Result::ERROR_PATH_INVALID)?;
        if w.sessions[&id].action_sets_attached.is_empty() {
            return Err(xr::Result::ERROR_ACTIONSET_NOT_ATTACHED);
        }
        let name = localized_name(path, info.which_components);
        ctx.detail = format!("{path} -> {name:?}");
        ffi::two_call_str(capacity, count_out, buffer, &name)?;
        Ok(xr::Result::SUCCESS)
    })
}

#[cfg(test)]
mod localized_name_tests {
    use super::*;
    use xr::InputSourceLocalizedNameFlags as F;

    #[test]
    fn names_come_from_the_path() {
        let p = "/user/hand/left/input/select/click";
        assert_eq!(localized_name(p, F::USER_PATH), "Left Hand");
        assert_eq!(localized_name(p, F::COMPONENT), "Select Click");
        assert_eq!(
            localized_name(p, F::USER_PATH | F::INTERACTION_PROFILE | F::COMPONENT),
            "Left Hand Simulated Controller Select Click"
        );
        assert_eq!(
            localized_name("/user/hand/right/output/haptic", F::COMPONENT),
            "Haptic"
        );
        assert_eq!(localized_name("/user/head", F::USER_PATH), "Head");
        assert_eq!(
            localized_name("/user/hand/left/input/trigger_value", F::COMPONENT),
            "Trigger Value"
        );
    }
}
