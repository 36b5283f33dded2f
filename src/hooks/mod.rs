//! The intercepted OpenXR functions: thin adapters that validate what the application passed,
//! translate it to plain Rust values, call into the layer's model, and pass the call on.
//!
//! Each hook runs inside [`crate::ffi::guard`], so a panic becomes `XR_ERROR_RUNTIME_FAILURE`.
//! Where the layer cannot do its own work, the application's call still goes down (fail open) and
//! the log says why.

pub mod foveation;
pub mod frame;
pub mod instance;
pub mod session;
pub mod swapchain;
pub mod vulkan;

use std::sync::Arc;

use openxr_sys as xr;

use crate::density::Fov;
use crate::state::{registry, Instance, Session, Swapchain};

/// A hook body's outcome: `Err` carries the XrResult to return without calling down.
pub type HookResult<T> = Result<T, xr::Result>;

/// Flattens a hook body into the XrResult the application sees.
pub fn finish(r: HookResult<xr::Result>) -> xr::Result {
    r.unwrap_or_else(|e| e)
}

/// The record for an instance handle, or XR_ERROR_HANDLE_INVALID.
pub fn instance(h: xr::Instance) -> HookResult<Arc<Instance>> {
    registry()
        .instance(h)
        .ok_or(xr::Result::ERROR_HANDLE_INVALID)
}

/// The record for a session handle, or XR_ERROR_HANDLE_INVALID.
pub fn session(h: xr::Session) -> HookResult<Arc<Session>> {
    registry()
        .session(h)
        .ok_or(xr::Result::ERROR_HANDLE_INVALID)
}

/// The record for a swapchain handle, or XR_ERROR_HANDLE_INVALID.
pub fn swapchain(h: xr::Swapchain) -> HookResult<Arc<Swapchain>> {
    registry()
        .swapchain(h)
        .ok_or(xr::Result::ERROR_HANDLE_INVALID)
}

/// The next layer's pointer. A hook is only handed out where the next layer offers the function
/// (see `loader::resolve`), so `None` means the table was corrupted: report a runtime failure.
pub fn next<F>(f: Option<F>) -> HookResult<F> {
    crate::lock::assert_none_held("going down to the next layer");
    f.ok_or(xr::Result::ERROR_RUNTIME_FAILURE)
}

/// Whether a result is a success code (XR_SUCCEEDED).
pub fn succeeded(r: xr::Result) -> bool {
    r.into_raw() >= 0
}

/// An `XrFovf` as the density model's FOV.
pub fn fov_from_xr(f: xr::Fovf) -> Fov {
    Fov {
        left: f.angle_left,
        right: f.angle_right,
        up: f.angle_up,
        down: f.angle_down,
    }
}

/// The density model's FOV as an `XrFovf`.
pub fn fov_to_xr(f: Fov) -> xr::Fovf {
    xr::Fovf {
        angle_left: f.left,
        angle_right: f.right,
        angle_up: f.up,
        angle_down: f.down,
    }
}
