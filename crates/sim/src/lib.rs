//! fovea-sim: a simulated headset OpenXR runtime for testing the fovea layer without a headset.
//!
//! It plays a *desktop* runtime: Vulkan (XR_KHR_vulkan_enable, XR_KHR_vulkan_enable2), headless
//! sessions (XR_MND_headless) and none of the foveation extensions. Optionally it offers
//! XR_FB_swapchain_update_state with no state types of its own, so the layer's pass-through path can
//! be exercised, or (`native_foveation`) XR_FB_foveation and XR_FB_foveation_configuration
//! natively, as a headset runtime does, so a test can check that a layer passes them through.
//!
//! Two ways in:
//! - the Khronos loader loads `libfovea_sim.so` through `manifest/runtime/fovea_sim_runtime.json`
//!   and calls [`xrNegotiateLoaderRuntimeInterface`];
//! - the in-process fake loader links this crate and calls [`get_instance_proc_addr`] directly.
//!
//! It is at least as strict as real runtimes (Monado) where the spec lets a runtime refuse a call:
//! xrLocateViews only while the session runs and for the view configuration it began with, the
//! frame-loop and swapchain call orders, the session state machine. Every refusal is counted apart
//! from injected faults ([`control::refusals`], the `refused=` field of the summary line), so a
//! test can assert that nothing a strict runtime refuses reached this one.
//!
//! Time is virtual and deterministic (see [`frame`](crate::frame) docs), every call is journaled, and
//! faults and GPU load can be injected through [`control`].
//!
//! Optionally (`FOVEA_SIM_EYE_GAZE`) it has an eye tracker behind `XR_EXT_eye_gaze_interaction`
//! whose gaze follows a script ([`gaze_script`]), as strict as real runtimes: inactive without
//! focus or without a synced set bound to it, a second suggestion for its profile replacing the
//! first, optionally no gaze space before attach, or listed without support as Monado does.

mod actions;
mod config;
pub mod control;
mod dispatch;
mod ffi;
mod foveation;
mod frame;
pub mod gaze_script;
mod instance;
mod negotiate;
mod session;
mod space;
mod state;
mod swapchain;
mod system;
mod vulkan;

use openxr_sys as xr;

pub use dispatch::{command_names, get_instance_proc_addr};

/// The runtime's only export (spec api_initialization.adoc, "Runtime Interface Negotiation").
///
/// # Safety
/// Both pointers must be NULL or point to the loader's structs.
#[no_mangle]
pub unsafe extern "system" fn xrNegotiateLoaderRuntimeInterface(
    loader_info: *const xr::NegotiateLoaderInfo,
    request: *mut xr::NegotiateRuntimeRequest,
) -> xr::Result {
    std::panic::catch_unwind(|| negotiate::negotiate(loader_info, request))
        .unwrap_or(xr::Result::ERROR_INITIALIZATION_FAILED)
}
