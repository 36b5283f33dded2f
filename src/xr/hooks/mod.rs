//! The intercepted OpenXR functions: ordinary Rust functions on typed values that validate what the
//! application passed, translate it to plain Rust values, call into the layer's model, and pass the
//! call on.
//!
//! Their exported entry points are generated from the table in [`crate::xr::dispatch`]: each runs
//! its hook inside [`crate::common::ffi::guard`], so a panic becomes `XR_ERROR_RUNTIME_FAILURE`, and
//! hands it the application's pointers as [`In`](crate::common::ffi::In),
//! [`Out`](crate::common::ffi::Out) and [`OutArray`](crate::common::ffi::OutArray). The only
//! `unsafe` left in a hook is the call down to the next layer and reads of pointer members the
//! spec's valid usage vouches for, each commented.
//! Where the layer cannot do its own work, the application's call still goes down (fail open) and
//! the log says why.

pub mod foveation;
pub mod frame;
pub mod instance;
pub mod session;
pub mod swapchain;
pub mod vulkan_enable;
pub mod vulkan_layer;

use std::sync::Arc;

use openxr_sys as xr;

use crate::common::records::Borrowed;
use crate::xr::registry::{registry, Instance, Session, Swapchain};
use fovea_model::Fov;

pub use crate::common::ffi::HookResult;

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

/// A session's record for the length of the calling hook, or XR_ERROR_HANDLE_INVALID: for the frame
/// loop's hooks, which neither keep it nor destroy the session. No atomic read-modify-write where
/// this thread resolved the handle before ([`crate::common::records`]).
pub fn session_for_call(h: xr::Session) -> HookResult<Borrowed<'static, Session>> {
    registry()
        .session_for_call(h)
        .ok_or(xr::Result::ERROR_HANDLE_INVALID)
}

/// A swapchain's record for the length of the calling hook, or XR_ERROR_HANDLE_INVALID (see
/// [`session_for_call`]).
pub fn swapchain_for_call(h: xr::Swapchain) -> HookResult<Borrowed<'static, Swapchain>> {
    registry()
        .swapchain_for_call(h)
        .ok_or(xr::Result::ERROR_HANDLE_INVALID)
}

/// The next layer's pointer. A hook is only handed out where the next layer offers the function
/// (see `loader::resolve`), so `None` means the table was corrupted: report a runtime failure.
pub fn next<F>(f: Option<F>) -> HookResult<F> {
    crate::common::lock::assert_none_held("going down to the next layer");
    f.ok_or(xr::Result::ERROR_RUNTIME_FAILURE)
}

/// A loss the runtime reported is final: once XR_ERROR_INSTANCE_LOST or XR_ERROR_SESSION_LOST is
/// returned, every later non-destroy call on that object or its children returns it too
/// (fundamentals.adoc, "Instance Lost", "Session Lost"). fovea's own functions are part of the
/// runtime as the application sees it, so they follow: they answer the loss once fovea saw the
/// runtime report it through a call it passed on. Losses reported through calls fovea does not
/// intercept (xrPollEvent, xrBeginSession, ...) stay unseen until an intercepted call reports them.
pub fn check_lost(session: &Session) -> HookResult<()> {
    use std::sync::atomic::Ordering::Relaxed;
    if session.instance.lost.load(Relaxed) {
        return Err(xr::Result::ERROR_INSTANCE_LOST);
    }
    if session.lost.load(Relaxed) {
        return Err(xr::Result::ERROR_SESSION_LOST);
    }
    Ok(())
}

/// Notes a loss in the result of a call on `session` (or its children) that fovea passed on.
pub fn observed(session: &Session, r: xr::Result) -> xr::Result {
    use std::sync::atomic::Ordering::Relaxed;
    if r == xr::Result::ERROR_SESSION_LOST {
        session.lost.store(true, Relaxed);
    }
    observed_instance(&session.instance, r)
}

/// Notes an instance loss in the result of a call on `instance` that fovea passed on.
pub fn observed_instance(instance: &Instance, r: xr::Result) -> xr::Result {
    if r == xr::Result::ERROR_INSTANCE_LOST {
        instance
            .lost
            .store(true, std::sync::atomic::Ordering::Relaxed);
    }
    r
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
