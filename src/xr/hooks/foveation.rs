//! XR_FB_foveation and XR_FB_swapchain_update_state: profiles and swapchain foveation state.
//!
//! Error codes follow the generated valid usage (openxr-layer-facts.md §1.3): a wrong struct type,
//! non-zero flags or a NULL pointer break VU, so XR_ERROR_VALIDATION_FAILURE; a destroyed, unknown or
//! foreign profile is XR_ERROR_HANDLE_INVALID.

use std::sync::Arc;

use openxr_sys as xr;
use xr::Handle;

use super::{check_lost, finish, session, swapchain, HookResult};
use crate::bridge::ProfileParams;
use crate::common::ffi::{self, guard};
use crate::xr::extensions::Ext;
use crate::xr::registry::{registry, Profile};

/// Reads the profile parameters from a create info's nested chain
/// (XrFoveationProfileCreateInfoFB -> XrFoveationLevelProfileCreateInfoFB). No level struct means
/// no foveation; unknown structs are ignored, as the spec requires.
///
/// # Safety
/// `info` must point to a valid `XrFoveationProfileCreateInfoFB` whose chain is valid.
unsafe fn profile_params(info: &xr::FoveationProfileCreateInfoFB) -> HookResult<ProfileParams> {
    let level = ffi::find_in_chain::<xr::FoveationLevelProfileCreateInfoFB>(
        info.next,
        xr::StructureType::FOVEATION_LEVEL_PROFILE_CREATE_INFO_FB,
    )
    .map_err(|_| xr::Result::ERROR_VALIDATION_FAILURE)?;
    let Some(level) = level else {
        return Ok(ProfileParams::default());
    };
    let l = &*level;
    validate_level(l.level.into_raw(), l.dynamic.into_raw(), l.vertical_offset)
}

/// The enum and range checks of XrFoveationLevelProfileCreateInfoFB: level NONE..HIGH, dynamic
/// DISABLED or LEVEL_ENABLED, a finite verticalOffset.
pub fn validate_level(level: i32, dynamic: i32, vertical_offset: f32) -> HookResult<ProfileParams> {
    if !(0..=3).contains(&level) || !(0..=1).contains(&dynamic) || !vertical_offset.is_finite() {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    Ok(ProfileParams {
        level: level as u32,
        vertical_offset_deg: vertical_offset,
        dynamic: dynamic == 1,
    })
}

/// `xrCreateFoveationProfileFB`.
pub unsafe extern "system" fn create_profile(
    sess: xr::Session,
    info: *const xr::FoveationProfileCreateInfoFB,
    out: *mut xr::FoveationProfileFB,
) -> xr::Result {
    guard("xrCreateFoveationProfileFB", || {
        finish((|| {
            let s = session(sess)?;
            check_lost(&s)?;
            if info.is_null()
                || out.is_null()
                || (*info).ty != xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB
            {
                return Err(xr::Result::ERROR_VALIDATION_FAILURE);
            }
            let params = profile_params(&*info)?;
            let handle = registry().mint_profile_handle();
            let profile = Profile {
                handle,
                session: s.handle,
                params,
            };
            registry()
                .profiles
                .write()
                .insert(handle.into_raw(), Arc::new(profile));
            *out = handle;
            Ok(xr::Result::SUCCESS)
        })())
    })
}

/// `xrDestroyFoveationProfileFB`. Swapchains it was applied to keep their copy of its parameters.
pub unsafe extern "system" fn destroy_profile(profile: xr::FoveationProfileFB) -> xr::Result {
    guard("xrDestroyFoveationProfileFB", || {
        match registry().profiles.write().remove(&profile.into_raw()) {
            Some(_) => xr::Result::SUCCESS,
            None => xr::Result::ERROR_HANDLE_INVALID,
        }
    })
}

/// `xrUpdateSwapchainFB`: XrSwapchainStateFoveationFB copies the profile's parameters into the
/// swapchain. Other state types go to the runtime where it implements XR_FB_swapchain_update_state,
/// and are invalid otherwise.
pub unsafe extern "system" fn update_swapchain(
    handle: xr::Swapchain,
    state: *const xr::SwapchainStateBaseHeaderFB,
) -> xr::Result {
    guard("xrUpdateSwapchainFB", || {
        finish((|| {
            let sc = swapchain(handle)?;
            check_lost(&sc.session)?;
            if state.is_null() {
                return Err(xr::Result::ERROR_VALIDATION_FAILURE);
            }
            if (*state).ty != xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB {
                return pass_down_update(&sc, handle, state);
            }
            let st = &*(state as *const xr::SwapchainStateFoveationFB);
            if st.flags.into_raw() != 0 {
                return Err(xr::Result::ERROR_VALIDATION_FAILURE);
            }
            // The spec gives no rule for a swapchain created without foveation; a Monado-derived
            // runtime answers validation failure, and so does fovea (openxr-layer-facts.md §1.4).
            let Some(foveation) = &sc.foveation else {
                return Err(xr::Result::ERROR_VALIDATION_FAILURE);
            };
            let profile = registry()
                .profile(st.profile)
                .ok_or(xr::Result::ERROR_HANDLE_INVALID)?;
            if profile.session != sc.session.handle {
                return Err(xr::Result::ERROR_HANDLE_INVALID);
            }
            {
                let mut f = foveation.lock();
                f.params = profile.params;
                f.profile = profile.handle;
                // Every density image of the swapchain is now dirty; each is refreshed when its
                // index is next acquired (the queue may not be used here, openxr-layer-facts.md §3).
                f.generation += 1;
            }
            sc.session.refresh_dynamic_max();
            Ok(xr::Result::SUCCESS)
        })())
    })
}

unsafe fn pass_down_update(
    sc: &crate::xr::registry::Swapchain,
    handle: xr::Swapchain,
    state: *const xr::SwapchainStateBaseHeaderFB,
) -> HookResult<xr::Result> {
    let exts = &sc.session.instance.extensions;
    match sc.session.instance.next.update_swapchain {
        Some(f) if exts.native.contains(Ext::SwapchainUpdateState) => Ok(f(handle, state)),
        _ => Err(xr::Result::ERROR_VALIDATION_FAILURE),
    }
}

/// `xrGetSwapchainStateFB`: flags 0 and the profile last applied while it lives. Once that profile
/// is destroyed the handle reads XR_NULL_HANDLE: the spec leaves this open, and returning a dead
/// handle would invite the app to use it.
pub unsafe extern "system" fn get_swapchain_state(
    handle: xr::Swapchain,
    state: *mut xr::SwapchainStateBaseHeaderFB,
) -> xr::Result {
    guard("xrGetSwapchainStateFB", || {
        finish((|| {
            let sc = swapchain(handle)?;
            check_lost(&sc.session)?;
            if state.is_null() {
                return Err(xr::Result::ERROR_VALIDATION_FAILURE);
            }
            if (*state).ty != xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB {
                let exts = &sc.session.instance.extensions;
                return match sc.session.instance.next.get_swapchain_state {
                    Some(f) if exts.native.contains(Ext::SwapchainUpdateState) => {
                        Ok(f(handle, state))
                    }
                    _ => Err(xr::Result::ERROR_VALIDATION_FAILURE),
                };
            }
            let Some(foveation) = &sc.foveation else {
                return Err(xr::Result::ERROR_VALIDATION_FAILURE);
            };
            let current = *foveation.lock();
            let alive = registry().profile(current.profile).is_some();
            // Only the output members are written; `type` and `next` stay the app's.
            let out = state as *mut xr::SwapchainStateFoveationFB;
            (*out).flags = xr::SwapchainStateFoveationFlagsFB::EMPTY;
            (*out).profile = if alive {
                current.profile
            } else {
                xr::FoveationProfileFB::NULL
            };
            Ok(xr::Result::SUCCESS)
        })())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn level_validation() {
        assert_eq!(
            validate_level(3, 1, -5.0),
            Ok(ProfileParams {
                level: 3,
                vertical_offset_deg: -5.0,
                dynamic: true
            })
        );
        for (l, d, v) in [
            (4, 0, 0.0),
            (-1, 0, 0.0),
            (1, 2, 0.0),
            (1, 0, f32::NAN),
            (1, 0, f32::INFINITY),
        ] {
            assert_eq!(
                validate_level(l, d, v),
                Err(xr::Result::ERROR_VALIDATION_FAILURE),
                "{l} {d} {v}"
            );
        }
    }
}
