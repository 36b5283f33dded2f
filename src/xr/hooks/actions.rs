//! The application's action system, where fovea's own gaze action set joins it
//! ([`crate::xr::gaze`], docs/eye-tracking.md#where-gaze-comes-from): its suggestions for the eye
//! gaze profile carry fovea's binding, its attach carries fovea's set, its syncs sync fovea's set
//! too; the events it polls tell fovea the session's state. The application's structs are never
//! written: what goes down changed is a copy.
//!
//! These hooks are handed out only for instances with a gaze source (`Owner::Gaze`): in every
//! other instance the application calls the runtime's functions directly.

use openxr_sys as xr;

use crate::xr::ffi::{HookResult, In, Out};
use crate::xr::gaze::app_caused;
use crate::xr::next_layer::next;
use crate::xr::registry::{
    instance, observed, observed_instance, registry, session, session_for_call,
};

/// Active sets a sync copies on the stack; an application with more gets a heap copy.
const STACK_SETS: usize = 16;

/// `xrSuggestInteractionProfileBindings`: a suggestion for the eye gaze profile replaces any earlier
/// one, so fovea's binding goes down merged into a copy of the application's. An application that
/// did not enable XR_EXT_eye_gaze_interaction gets the profile refused, as it would without fovea
/// (which enabled the extension for itself).
pub fn suggest_bindings(
    inst: xr::Instance,
    info: In<xr::InteractionProfileSuggestedBinding>,
) -> HookResult<xr::Result> {
    let state = instance(inst)?;
    let f = next(state.next.suggest_interaction_profile_bindings)?;
    // SAFETY: the next layer's function, with the application's arguments or fovea's copy of them.
    let down = |i: *const xr::InteractionProfileSuggestedBinding| unsafe { f(inst, i) };
    let (Some(g), Some(app)) = (&state.gaze, info.get()) else {
        return Ok(observed_instance(&state, down(info.raw())));
    };
    if app.interaction_profile != g.profile() {
        return Ok(observed_instance(&state, down(info.raw())));
    }
    if !g.app_enabled {
        // XR_EXT_eye_gaze_interaction: the profile exists only with the extension enabled.
        return Ok(xr::Result::ERROR_PATH_UNSUPPORTED);
    }
    // SAFETY: a valid suggestion (`In`) for the eye gaze profile, checked above.
    let r = unsafe { g.suggest(app, |i| down(i)) };
    Ok(observed_instance(&state, r))
}

/// `xrAttachSessionActionSets`: fovea's set goes down with the application's, after fovea's binding
/// was suggested; the gaze spaces are made once the sets are attached.
pub fn attach_action_sets(
    sess: xr::Session,
    info: In<xr::SessionActionSetsAttachInfo>,
) -> HookResult<xr::Result> {
    let s = session(sess)?;
    let f = next(s.instance.next.attach_session_action_sets)?;
    // SAFETY: the next layer's function, with the application's arguments or fovea's copy of them.
    let down = |i: *const xr::SessionActionSetsAttachInfo| unsafe { f(sess, i) };
    let (Some(ig), Some(sg), Some(app)) = (&s.instance.gaze, &s.gaze, info.get()) else {
        return Ok(observed(&s, down(info.raw())));
    };
    // SAFETY: a valid attach info (`In`).
    let r = unsafe { ig.attach(sg, app, |i| down(i)) };
    Ok(observed(&s, r))
}

/// `xrSyncActions`: a copy of the application's active sets with fovea's added goes down (the gaze
/// is located after the next `xrWaitFrame`, for that frame). No allocation for up to
/// [`STACK_SETS`] sets.
pub fn sync_actions(sess: xr::Session, info: In<xr::ActionsSyncInfo>) -> HookResult<xr::Result> {
    let s = session_for_call(sess)?;
    let f = next(s.instance.next.sync_actions)?;
    // SAFETY: the next layer's function, with the application's arguments or fovea's copy of them.
    let down = |i: *const xr::ActionsSyncInfo| unsafe { f(sess, i) };
    let (Some(sg), Some(app)) = (&s.gaze, info.get()) else {
        return Ok(observed(&s, down(info.raw())));
    };
    let Some(ours) = sg.active_set() else {
        return Ok(observed(&s, down(info.raw())));
    };
    let n = app.count_active_action_sets as usize;
    let listed: &[xr::ActiveActionSet] = match n {
        0 => &[],
        _ if app.active_action_sets.is_null() => return Ok(observed(&s, down(info.raw()))),
        // SAFETY: a valid XrActionsSyncInfo (`In`) has `countActiveActionSets` sets at
        // `activeActionSets`.
        _ => unsafe { std::slice::from_raw_parts(app.active_action_sets, n) },
    };
    let mut stack = [ours; STACK_SETS];
    let mut heap = Vec::new();
    let sets: &[xr::ActiveActionSet] = if n < STACK_SETS {
        stack[..n].copy_from_slice(listed);
        &stack[..=n]
    } else {
        heap.extend_from_slice(listed);
        heap.push(ours);
        &heap
    };
    let copy = xr::ActionsSyncInfo {
        count_active_action_sets: sets.len() as u32,
        active_action_sets: sets.as_ptr(),
        ..*app
    };
    let r = observed(&s, down(&copy));
    if r.into_raw() >= 0 || app_caused(r) {
        return Ok(r);
    }
    // Refused with fovea's set: the application's own sync decides what it gets.
    let again = observed(&s, down(info.raw()));
    if again.into_raw() >= 0 {
        sg.fail(
            r,
            "the runtime refused fovea's eye gaze set in the application's sync",
        );
    }
    Ok(again)
}

/// `xrPollEvent`: passed on; a session state change the application receives tells the gaze source
/// whether the session is FOCUSED (fovea syncs alone only then), and interaction-profile changes
/// that only fovea's binding can have caused (its set attached alone, in an application that never
/// enabled XR_EXT_eye_gaze_interaction) are not delivered
/// (docs/eye-tracking.md#events-and-queries-the-application-sees).
pub fn poll_event(inst: xr::Instance, buffer: Out<xr::EventDataBuffer>) -> HookResult<xr::Result> {
    let state = instance(inst)?;
    let f = next(state.next.poll_event)?;
    let app_enabled = state.gaze.as_ref().is_none_or(|g| g.app_enabled);
    // The application's header, to restore before asking again for the event after one dropped
    // (the runtime wrote its event's over it; the call wants an XrEventDataBuffer).
    let header = (!buffer.is_null()).then(|| {
        // SAFETY: a non-NULL buffer is the application's XrEventDataBuffer, valid for the call.
        unsafe { *buffer.raw().cast::<xr::BaseOutStructure>() }
    });
    loop {
        // SAFETY: the next layer's xrPollEvent with the application's arguments as it passed them.
        let r = observed_instance(&state, unsafe { f(inst, buffer.raw()) });
        if r != xr::Result::SUCCESS || buffer.is_null() {
            return Ok(r);
        }
        // SAFETY: the runtime wrote an event into the application's buffer, whose `type` says
        // which; a session state change is that struct.
        let ty = unsafe { (*buffer.raw().cast::<xr::BaseInStructure>()).ty };
        match ty {
            xr::StructureType::EVENT_DATA_SESSION_STATE_CHANGED => {
                // SAFETY: as above.
                let e = unsafe { &*buffer.raw().cast::<xr::EventDataSessionStateChanged>() };
                if let Some(s) = registry().session(e.session) {
                    if let Some(g) = &s.gaze {
                        g.state_changed(e.state);
                    }
                }
                return Ok(r);
            }
            xr::StructureType::EVENT_DATA_INTERACTION_PROFILE_CHANGED if !app_enabled => {
                // SAFETY: as above.
                let e = unsafe {
                    &*buffer
                        .raw()
                        .cast::<xr::EventDataInteractionProfileChanged>()
                };
                let ours = registry()
                    .session(e.session)
                    .is_some_and(|s| s.gaze.as_ref().is_some_and(|g| g.attached_alone()));
                if !ours {
                    return Ok(r);
                }
                // fovea's own: the application never sees it; the next event, if any, instead.
                if let Some(h) = header {
                    // SAFETY: as above; the header is the application's own, written back.
                    unsafe { *buffer.raw().cast::<xr::BaseOutStructure>() = h };
                }
            }
            _ => return Ok(r),
        }
    }
}

/// `xrGetCurrentInteractionProfile`: where fovea attached its set alone (an opt-in), the session
/// has no set of the application's attached, and the answer is the one the runtime gives without
/// fovea: XR_ERROR_ACTIONSET_NOT_ATTACHED. Otherwise passed on.
pub fn get_current_interaction_profile(
    sess: xr::Session,
    path: xr::Path,
    profile: Out<xr::InteractionProfileState>,
) -> HookResult<xr::Result> {
    let s = session_for_call(sess)?;
    let f = next(s.instance.next.get_current_interaction_profile)?;
    if s.gaze.as_ref().is_some_and(|g| g.attached_alone()) {
        return Ok(xr::Result::ERROR_ACTIONSET_NOT_ATTACHED);
    }
    // SAFETY: the next layer's function with the application's arguments as it passed them.
    Ok(observed(&s, unsafe { f(sess, path, profile.raw()) }))
}
