//! XR_FB_swapchain_update_state and XR_FB_foveation: profiles and swapchain foveation state.

use openxr_sys as xr;

use crate::ffi::guard;

/// `xrUpdateSwapchainFB`.
pub unsafe extern "system" fn update_swapchain(
    _swapchain: xr::Swapchain,
    _state: *const xr::SwapchainStateBaseHeaderFB,
) -> xr::Result {
    guard("xrUpdateSwapchainFB", || {
        xr::Result::ERROR_FUNCTION_UNSUPPORTED
    })
}

/// `xrGetSwapchainStateFB`.
pub unsafe extern "system" fn get_swapchain_state(
    _swapchain: xr::Swapchain,
    _state: *mut xr::SwapchainStateBaseHeaderFB,
) -> xr::Result {
    guard("xrGetSwapchainStateFB", || {
        xr::Result::ERROR_FUNCTION_UNSUPPORTED
    })
}

/// `xrCreateFoveationProfileFB`.
pub unsafe extern "system" fn create_profile(
    _session: xr::Session,
    _info: *const xr::FoveationProfileCreateInfoFB,
    _profile: *mut xr::FoveationProfileFB,
) -> xr::Result {
    guard("xrCreateFoveationProfileFB", || {
        xr::Result::ERROR_FUNCTION_UNSUPPORTED
    })
}

/// `xrDestroyFoveationProfileFB`.
pub unsafe extern "system" fn destroy_profile(_profile: xr::FoveationProfileFB) -> xr::Result {
    guard("xrDestroyFoveationProfileFB", || {
        xr::Result::ERROR_FUNCTION_UNSUPPORTED
    })
}
