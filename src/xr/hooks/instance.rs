//! Instance lifetime.

use openxr_sys as xr;

use crate::xr::ffi::HookResult;
use crate::xr::next_layer::next;
use crate::xr::registry::instance;
use crate::xr::registry::registry;
use crate::xr::values::succeeded;

/// `xrDestroyInstance`: the instance's sessions, swapchains and profiles die with it
/// (fundamentals.adoc "Object Lifetime"). As in `xrDestroySession`, their records leave the
/// registry before the call goes down, are released once the runtime has destroyed the instance,
/// and go back where it refuses, so the application can retry.
pub fn destroy_instance(handle: xr::Instance) -> HookResult<xr::Result> {
    let state = instance(handle)?;
    let f = next(state.next.destroy_instance)?;
    let injected = state.inject.is_some();
    drop(state);
    let detached = registry().detach_instance(handle);
    // SAFETY: the next layer's xrDestroyInstance, with the application's handle.
    let r = unsafe { f(handle) };
    if !succeeded(r) {
        tracing::warn!(
            ?r,
            "the runtime refused xrDestroyInstance; the instance lives on"
        );
        registry().restore(detached);
    } else {
        detached.forget_published();
        if injected {
            crate::bridge::inject::stop();
        }
    }
    Ok(r)
}
