//! Native XR_FB_foveation and XR_FB_foveation_configuration, offered only with
//! [`SimConfig::native_foveation`](crate::config::SimConfig::native_foveation): the runtime a layer
//! must pass through rather than shadow.
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
        ctx.detail = format!("{params:?}");
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
