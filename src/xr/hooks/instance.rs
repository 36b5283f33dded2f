//! Instance lifetime.

use openxr_sys as xr;

use super::{finish, instance, next, succeeded};
use crate::common::ffi::guard;
use crate::xr::registry::registry;

/// `xrDestroyInstance`: the instance's sessions, swapchains and profiles die with it
/// (fundamentals.adoc "Object Lifetime"). As in `xrDestroySession`, their records leave the
/// registry before the call goes down, are released once the runtime has destroyed the instance,
/// and go back where it refuses, so the application can retry.
pub unsafe extern "system" fn destroy_instance(handle: xr::Instance) -> xr::Result {
    guard("xrDestroyInstance", || {
        finish((|| {
            let state = instance(handle)?;
            let f = next(state.next.destroy_instance)?;
            drop(state);
            let detached = registry().detach_instance(handle);
            let r = f(handle);
            if !succeeded(r) {
                tracing::warn!(
                    ?r,
                    "the runtime refused xrDestroyInstance; the instance lives on"
                );
                registry().restore(detached);
            }
            Ok(r)
        })())
    })
}
