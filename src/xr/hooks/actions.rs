//! The application's action system, where fovea's own gaze action set joins it
//! ([`crate::xr::gaze`], docs/eye-tracking.md#where-gaze-comes-from): its suggestions for the eye
//! gaze profile carry fovea's binding, its attach carries fovea's set, its syncs sync fovea's set
//! too and then locate the gaze for the frame. The application's structs are never written: what
//! goes down changed is a copy.

use openxr_sys as xr;

use crate::xr::ffi::{HookResult, In};
use crate::xr::next_layer::next;
use crate::xr::registry::{instance, observed, observed_instance, session, session_for_call};

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

/// `xrSyncActions`: a copy of the application's active sets with fovea's added goes down; after it,
/// the gaze is located for the frame and each view's fovea written. No allocation for up to
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
    if r.into_raw() >= 0 {
        if let Some(centres) = sg.update() {
            *s.eyes.lock() = centres;
        }
    }
    Ok(r)
}
