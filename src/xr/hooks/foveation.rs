//! XR_FB_foveation and XR_FB_swapchain_update_state: profiles and swapchain foveation state.
//!
//! Error codes follow the generated valid usage
//! (https://registry.khronos.org/OpenXR/specs/1.0/man/html/xrCreateFoveationProfileFB.html,
//! https://registry.khronos.org/OpenXR/specs/1.0/man/html/xrUpdateSwapchainFB.html): a wrong struct type,
//! non-zero flags or a NULL pointer break VU, so XR_ERROR_VALIDATION_FAILURE; a destroyed, unknown or
//! foreign profile is XR_ERROR_HANDLE_INVALID.

use std::sync::Arc;

use openxr_sys as xr;
use xr::Handle;

use crate::xr::extensions::Ext;
use crate::xr::ffi::HookResult;
use crate::xr::ffi::{In, Out};
use crate::xr::foveation::{pack_request, ProfileParams};
use crate::xr::pattern::{publish_injected_pattern, refresh_dynamic_max};
use crate::xr::registry::{check_lost, session, swapchain};
use crate::xr::registry::{registry, Profile};
use fovea_model::density::Level;

/// Reads the profile parameters from a create info's nested chain
/// (XrFoveationProfileCreateInfoFB -> XrFoveationLevelProfileCreateInfoFB ->
/// XrFoveationEyeTrackedProfileCreateInfoMETA). No level struct means no foveation; unknown structs
/// are ignored, as the spec requires. `eye_tracked_enabled`: the application enabled
/// XR_META_foveation_eye_tracked, without which its struct is not one fovea reads.
fn profile_params(
    info: In<xr::FoveationProfileCreateInfoFB>,
    eye_tracked_enabled: bool,
) -> HookResult<ProfileParams> {
    let invalid = |_| xr::Result::ERROR_VALIDATION_FAILURE;
    let level = info
        .chained::<xr::FoveationLevelProfileCreateInfoFB>()
        .map_err(invalid)?;
    let eye_tracked = if eye_tracked_enabled {
        info.chained::<xr::FoveationEyeTrackedProfileCreateInfoMETA>()
            .map_err(invalid)?
    } else {
        None
    };
    let Some(l) = level else {
        // XrFoveationEyeTrackedProfileCreateInfoMETA extends the level struct only (xr.xml
        // `structextends`): without one it is in a chain it cannot be in.
        return match eye_tracked {
            Some(_) => Err(xr::Result::ERROR_VALIDATION_FAILURE),
            None => Ok(ProfileParams::default()),
        };
    };
    let mut params = validate_level(l.level, l.dynamic.into_raw(), l.vertical_offset)?;
    if let Some(e) = eye_tracked {
        // SAFETY: `l` is a struct of the application's valid chain, so its own next chain is valid
        // for the call.
        let after_level = unsafe { In::new(l as *const xr::FoveationLevelProfileCreateInfoFB) }
            .chained::<xr::FoveationEyeTrackedProfileCreateInfoMETA>()
            .map_err(invalid)?;
        params.eye_tracked = validate_eye_tracked(e, after_level.is_some())?;
    }
    Ok(params)
}

/// The checks of XrFoveationEyeTrackedProfileCreateInfoMETA
/// (https://registry.khronos.org/OpenXR/specs/1.0/man/html/XrFoveationEyeTrackedProfileCreateInfoMETA.html):
/// it follows the level struct it extends, and its flags are 0 (no bit is defined). Whether the
/// system has a gaze source does not matter here: `xrCreateFoveationProfileFB` has no result for
/// it, and a profile without gaze foveates as a fixed one.
pub fn validate_eye_tracked(
    info: &xr::FoveationEyeTrackedProfileCreateInfoMETA,
    follows_level: bool,
) -> HookResult<bool> {
    if !follows_level || !info.flags.is_empty() {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    Ok(true)
}

/// The enum and range checks of XrFoveationLevelProfileCreateInfoFB: level NONE..HIGH, dynamic
/// DISABLED or LEVEL_ENABLED, a finite verticalOffset.
/// From here on the level is a [`Level`].
pub fn validate_level(
    level: xr::FoveationLevelFB,
    dynamic: i32,
    vertical_offset: f32,
) -> HookResult<ProfileParams> {
    let level = match level {
        xr::FoveationLevelFB::NONE => Level::None,
        xr::FoveationLevelFB::LOW => Level::Low,
        xr::FoveationLevelFB::MEDIUM => Level::Medium,
        xr::FoveationLevelFB::HIGH => Level::High,
        _ => return Err(xr::Result::ERROR_VALIDATION_FAILURE),
    };
    if !(0..=1).contains(&dynamic) || !vertical_offset.is_finite() {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    Ok(ProfileParams {
        level,
        vertical_offset_deg: vertical_offset,
        dynamic: dynamic == 1,
        eye_tracked: false,
    })
}

/// `xrCreateFoveationProfileFB`.
pub fn create_profile(
    sess: xr::Session,
    info: In<xr::FoveationProfileCreateInfoFB>,
    out: Out<xr::FoveationProfileFB>,
) -> HookResult<xr::Result> {
    let s = session(sess)?;
    check_lost(&s)?;
    info.require()?;
    if out.is_null() {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    let exts = &s.instance.extensions;
    let params = profile_params(info, exts.enabled.contains(Ext::MetaFoveationEyeTracked))?;
    if params.eye_tracked && s.gaze.is_none() {
        tracing::debug!("an eye-tracked profile without a gaze source foveates as a fixed one");
    }
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
    out.write(handle);
    Ok(xr::Result::SUCCESS)
}

/// `xrDestroyFoveationProfileFB`. Swapchains it was applied to keep their copy of its parameters.
pub fn destroy_profile(profile: xr::FoveationProfileFB) -> HookResult<xr::Result> {
    match registry().profiles.write().remove(&profile.into_raw()) {
        Some(_) => Ok(xr::Result::SUCCESS),
        None => Err(xr::Result::ERROR_HANDLE_INVALID),
    }
}

/// `xrUpdateSwapchainFB`: XrSwapchainStateFoveationFB copies the profile's parameters into the
/// swapchain. On a swapchain without density images of an instance fovea injects into, injection
/// foveates its eye passes at the profile's level from then on (docs/injection.md#applications-that-apply-profiles):
/// Qt 6.8's Quick 3D XR applies a profile to swapchains it created without foveation info, and
/// that is how fovea honours it. Where fovea cannot (a swapchain created without foveation info on
/// a session that is not Vulkan), XR_ERROR_VALIDATION_FAILURE, as a Monado-derived runtime answers,
/// and one log line says so. Other state types go to the runtime where it implements
/// XR_FB_swapchain_update_state, and are invalid otherwise.
pub fn update_swapchain(
    handle: xr::Swapchain,
    state: In<xr::SwapchainStateBaseHeaderFB>,
) -> HookResult<xr::Result> {
    let sc = swapchain(handle)?;
    check_lost(&sc.session)?;
    if state.is_null() {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    let Some(st) = state.cast::<xr::SwapchainStateFoveationFB>() else {
        return pass_down_update(&sc, handle, state);
    };
    if !st.flags.is_empty() {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    // The spec gives no rule for a swapchain created without foveation; where fovea cannot
    // foveate it (it takes profiles wherever injection can), a Monado-derived runtime's answer.
    let Some(foveation) = &sc.foveation else {
        refused_once();
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
        // Every density image of the swapchain is now dirty; each is refreshed when its index is
        // next acquired (the queue may only be used where the application synchronises it for the
        // runtime: https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#XR_KHR_vulkan_enable).
        f.generation += 1;
    }
    if sc.density.is_none() && sc.session.instance.inject.is_some() {
        // No density images: injection foveates it, at this profile's level.
        sc.session.inject_request.store(
            pack_request(profile.params),
            std::sync::atomic::Ordering::Relaxed,
        );
        tracing::info!(
            // As `XrFoveationLevelFB` numbers it.
            level = profile.params.level as u32,
            dynamic = profile.params.dynamic,
            "a foveation profile applied to a swapchain without density images: its eye passes \
             are foveated by injection at its level"
        );
        if !crate::bridge::inject::injecting_device() {
            no_injecting_device_once();
        }
    }
    refresh_dynamic_max(&sc.session);
    publish_injected_pattern(&sc.session);
    Ok(xr::Result::SUCCESS)
}

/// The log line, once per process, for a profile fovea takes but cannot apply: no device of the
/// process takes injected maps (the GPU has no shading-rate attachments, has density maps of its
/// own, or the application renders with density maps there), so the swapchain renders at full rate.
fn no_injecting_device_once() {
    static SAID: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
    if !SAID.swap(true, std::sync::atomic::Ordering::Relaxed) {
        tracing::info!(
            "a foveation profile applied to a swapchain without density images, but no Vulkan \
             device of this process takes injected shading-rate maps (no shading-rate \
             attachments, density maps of the driver's own or the application's, or fovea's \
             Vulkan layer not loaded): it renders at full rate"
        );
    }
}

/// The log line for a profile fovea refuses to apply, once per process: the application asked for
/// foveation and gets none, which a result code alone (that toolkits ignore) does not tell a user.
fn refused_once() {
    static SAID: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
    if !SAID.swap(true, std::sync::atomic::Ordering::Relaxed) {
        tracing::info!(
            "xrUpdateSwapchainFB: a foveation profile for a swapchain created without \
             XrSwapchainCreateInfoFoveationFB on a session fovea cannot inject shading rates \
             into (not Vulkan): refused with XR_ERROR_VALIDATION_FAILURE, the swapchain renders at \
             full rate"
        );
    }
}

fn pass_down_update(
    sc: &crate::xr::registry::Swapchain,
    handle: xr::Swapchain,
    state: In<xr::SwapchainStateBaseHeaderFB>,
) -> HookResult<xr::Result> {
    let exts = &sc.session.instance.extensions;
    match sc.session.instance.next.update_swapchain {
        Some(f) if exts.native.contains(Ext::SwapchainUpdateState) => {
            // SAFETY: the runtime's own xrUpdateSwapchainFB, with the application's arguments as
            // it passed them.
            Ok(unsafe { f(handle, state.raw()) })
        }
        _ => Err(xr::Result::ERROR_VALIDATION_FAILURE),
    }
}

/// `xrGetSwapchainStateFB`: flags 0 and the profile last applied while it lives. Once that profile
/// is destroyed the handle reads XR_NULL_HANDLE: the spec leaves this open, and returning a dead
/// handle would invite the app to use it.
pub fn get_swapchain_state(
    handle: xr::Swapchain,
    state: Out<xr::SwapchainStateBaseHeaderFB>,
) -> HookResult<xr::Result> {
    let sc = swapchain(handle)?;
    check_lost(&sc.session)?;
    let Some(base) = state.read() else {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    };
    if base.ty != xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB {
        let exts = &sc.session.instance.extensions;
        return match sc.session.instance.next.get_swapchain_state {
            Some(f) if exts.native.contains(Ext::SwapchainUpdateState) => {
                // SAFETY: the runtime's own xrGetSwapchainStateFB, with the application's
                // arguments as it passed them.
                Ok(unsafe { f(handle, state.raw()) })
            }
            _ => Err(xr::Result::ERROR_VALIDATION_FAILURE),
        };
    }
    let Some(foveation) = &sc.foveation else {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    };
    let current = *foveation.lock();
    let alive = registry().profile(current.profile).is_some();
    let Some(out) = state.cast_mut::<xr::SwapchainStateFoveationFB>() else {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    };
    // Only the output members are written; `type` and `next` stay the app's.
    out.flags = xr::SwapchainStateFoveationFlagsFB::EMPTY;
    out.profile = if alive {
        current.profile
    } else {
        xr::FoveationProfileFB::NULL
    };
    Ok(xr::Result::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eye_tracked_validation() {
        let info = |flags| xr::FoveationEyeTrackedProfileCreateInfoMETA {
            ty: xr::FoveationEyeTrackedProfileCreateInfoMETA::TYPE,
            next: std::ptr::null(),
            flags: xr::FoveationEyeTrackedProfileCreateFlagsMETA::from_raw(flags),
        };
        assert_eq!(validate_eye_tracked(&info(0), true), Ok(true));
        for (flags, after_level) in [(1, true), (1 << 63, true), (0, false)] {
            assert_eq!(
                validate_eye_tracked(&info(flags), after_level),
                Err(xr::Result::ERROR_VALIDATION_FAILURE),
                "{flags:#x} {after_level}"
            );
        }
    }

    #[test]
    fn level_validation() {
        assert_eq!(
            validate_level(xr::FoveationLevelFB::HIGH, 1, -5.0),
            Ok(ProfileParams {
                level: Level::High,
                vertical_offset_deg: -5.0,
                dynamic: true,
                eye_tracked: false,
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
                validate_level(xr::FoveationLevelFB::from_raw(l), d, v),
                Err(xr::Result::ERROR_VALIDATION_FAILURE),
                "{l} {d} {v}"
            );
        }
    }
}
