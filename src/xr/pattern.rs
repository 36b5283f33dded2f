//! The pattern policy of a session: which pattern each foveated swapchain's maps and injection use
//! now (the application's profile under Quest's debug overrides and the dynamic step,
//! [`crate::xr::foveation::effective`]), how far the dynamic controller may step, and what
//! injection publishes for the Vulkan side ([`crate::bridge::inject`]). The records it reads are
//! [`crate::xr::registry`]'s; the hooks call it where an input changed (`xrUpdateSwapchainFB`,
//! `xrEndFrame`, `xrCreateSession`, a swapchain destroyed) and when a map is built.

use std::sync::atomic::Ordering;

use fovea_model::density::Pattern;
use fovea_model::dynamic::step_of;

use crate::xr::foveation::{effective, unpack_request, FoveationState, ProfileParams};
use crate::xr::registry::{registry, Session};

/// The pattern a foveated swapchain's maps use now, and whether it is dynamic: the application's
/// state under the debug overrides and the dynamic step.
pub fn pattern_for(session: &Session, state: &FoveationState) -> (Pattern, bool) {
    effective(
        state.params,
        session.instance.overrides.current(),
        session.dynamic_step.load(Ordering::Relaxed),
    )
}

/// Recomputes [`Session::dynamic_max`] after a swapchain's state or the overrides changed.
pub fn refresh_dynamic_max(session: &Session) {
    let over = session.instance.overrides.current();
    let injected = injected_pattern_at(session, usize::MAX)
        .and_then(|(p, dynamic)| dynamic.then_some(step_of(p.level)));
    let max = registry()
        .foveated_swapchains_of(session.handle)
        .iter()
        .filter_map(|sc| {
            let (p, dynamic) = effective(sc.foveation.as_ref()?.lock().params, over, usize::MAX);
            dynamic.then_some(step_of(p.level))
        })
        .chain(injected)
        .max()
        .unwrap_or(0);
    session.dynamic_max.store(max, Ordering::Relaxed);
}

/// The injected pattern at dynamic step `step`, and whether it is dynamic: the profile the
/// application last applied to a swapchain without density images
/// (docs/injection.md#applications-that-apply-profiles), else the injected level as if an
/// application had asked for it, under the debug overrides with Quest's meaning ([`effective`]).
/// `None` where injection does not apply to the session's instance.
pub fn injected_pattern_at(session: &Session, step: usize) -> Option<(Pattern, bool)> {
    let level = session.instance.inject?;
    let params =
        unpack_request(session.inject_request.load(Ordering::Relaxed)).unwrap_or(ProfileParams {
            level,
            ..ProfileParams::default()
        });
    Some(effective(
        params,
        session.instance.overrides.current(),
        step,
    ))
}

/// Publishes the injected pattern in force now for the Vulkan side (a comparison when it did not
/// change).
pub fn publish_injected_pattern(session: &Session) {
    if let Some((pattern, dynamic)) =
        injected_pattern_at(session, session.dynamic_step.load(Ordering::Relaxed))
    {
        let max_fragment = session.instance.overrides.current().max_fragment();
        crate::bridge::inject::set_pattern(pattern, dynamic, max_fragment);
    }
}

/// Publishes where each view's fovea is for injected maps (docs/eye-tracking.md#what-moves-when):
/// the gaze's centres while `eyes` follows it, fixed foveation otherwise. Per frame one record lock
/// for the copy and a comparison; the bridge publishes only a move of half a texel or more.
pub fn publish_injected_centres(session: &Session) {
    if session.instance.inject.is_none() {
        return;
    }
    let eyes = *session.eyes.lock();
    let mut centres = [None; fovea_model::maps::MAX_VIEWS];
    for (i, c) in centres.iter_mut().enumerate() {
        *c = eyes.of(i);
    }
    crate::bridge::inject::set_centres(&centres);
}
