//! Native XR_FB_foveation and XR_FB_foveation_configuration, offered only with
//! [`SimConfig::native_foveation`](crate::config::SimConfig::native_foveation): the runtime a layer
//! must pass through rather than shadow; and with it, native XR_META_foveation_eye_tracked
//! ([`SimConfig::native_meta_eye_tracked`](crate::config::SimConfig::native_meta_eye_tracked)).
//!
//! Honest and minimal: profiles are created, destroyed and applied with the spec's checks
//! (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#XR_FB_foveation), and each
//! swapchain remembers what was applied so a test can read it back
//! ([`control::swapchain_foveation`](crate::control::swapchain_foveation)). Nothing is rendered
//! differently: the simulated compositor draws nothing.

use openxr_sys as xr;
use openxr_sys::Handle;

use crate::ffi;
use crate::objects::{FoveationParams, Profile};
use crate::state::{entry, world};

pub(crate) unsafe extern "system" fn create_foveation_profile_fb(
    session: xr::Session,
    create_info: *const xr::FoveationProfileCreateInfoFB,
    profile: *mut xr::FoveationProfileFB,
) -> xr::Result {
    entry("xrCreateFoveationProfileFB", |ctx| {
        let mut w = world();
        let session = w.enter_session(ctx, session)?;
        let info = ffi::input(
            create_info,
            xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
        )?;
        ffi::non_null(profile)?;
        ctx.next_types = ffi::chain_types(info.next);
        let instance = w.sessions[&session].instance;
        let configuration =
            w.instances[&instance].has_extension(crate::extensions::FB_FOVEATION_CONFIGURATION);
        // A level struct of an extension that is not enabled is an unrecognised struct: ignored.
        let level = ffi::find_in_chain(
            info.next,
            xr::StructureType::FOVEATION_LEVEL_PROFILE_CREATE_INFO_FB,
        )
        .filter(|_| configuration)
        .map(|p| &*(p as *const xr::FoveationLevelProfileCreateInfoFB));
        let params = match level {
            None => FoveationParams::NONE,
            Some(l) => {
                let known_level = (0..=3).contains(&l.level.into_raw());
                let known_dynamic = (0..=1).contains(&l.dynamic.into_raw());
                if !known_level || !known_dynamic || !l.vertical_offset.is_finite() {
                    return Err(xr::Result::ERROR_VALIDATION_FAILURE);
                }
                FoveationParams {
                    level: l.level,
                    vertical_offset: l.vertical_offset,
                    dynamic: l.dynamic,
                }
            }
        };
        // Native XR_META_foveation_eye_tracked: its struct extends the level struct, flags 0.
        let eye_tracked = w.instances[&instance]
            .has_extension(crate::extensions::META_FOVEATION_EYE_TRACKED)
            .then(|| {
                ffi::find_in_chain(
                    info.next,
                    xr::StructureType::FOVEATION_EYE_TRACKED_PROFILE_CREATE_INFO_META,
                )
            })
            .flatten()
            .map(|p| &*(p as *const xr::FoveationEyeTrackedProfileCreateInfoMETA));
        if eye_tracked.is_some_and(|e| !e.flags.is_empty()) {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        ctx.detail = format!("{params:?} eye_tracked={}", eye_tracked.is_some());
        let id = w.alloc_handle();
        w.profiles.insert(id, Profile { session, params });
        *profile = xr::FoveationProfileFB::from_raw(id);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn destroy_foveation_profile_fb(
    profile: xr::FoveationProfileFB,
) -> xr::Result {
    entry("xrDestroyFoveationProfileFB", |ctx| {
        ctx.allow_lost = true;
        let mut w = world();
        let session = w
            .profiles
            .get(&profile.into_raw())
            .ok_or(xr::Result::ERROR_HANDLE_INVALID)?
            .session;
        w.enter_session(ctx, xr::Session::from_raw(session))?;
        w.profiles.remove(&profile.into_raw());
        Ok(xr::Result::SUCCESS)
    })
}

/// Native `xrGetFoveationEyeTrackedStateMETA`: the session and the struct checked as the spec's
/// valid usage says, then the fixed answer [`META_NATIVE_CENTRES`](crate::config::META_NATIVE_CENTRES),
/// VALID.
pub(crate) unsafe extern "system" fn get_foveation_eye_tracked_state_meta(
    session: xr::Session,
    state: *mut xr::FoveationEyeTrackedStateMETA,
) -> xr::Result {
    entry("xrGetFoveationEyeTrackedStateMETA", |ctx| {
        let mut w = world();
        w.enter_session(ctx, session)?;
        let st = ffi::output(state, xr::StructureType::FOVEATION_EYE_TRACKED_STATE_META)?;
        for (c, [x, y]) in (*st)
            .foveation_center
            .iter_mut()
            .zip(crate::config::META_NATIVE_CENTRES)
        {
            *c = xr::Vector2f { x, y };
        }
        (*st).flags = xr::FoveationEyeTrackedStateFlagsMETA::VALID;
        Ok(xr::Result::SUCCESS)
    })
}
