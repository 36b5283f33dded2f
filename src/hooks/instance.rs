//! Instance lifetime.

use openxr_sys as xr;
use xr::Handle;

use super::{finish, instance, next};
use crate::ffi::guard;
use crate::state::registry;

/// `xrDestroyInstance`: destroys the instance's sessions' layer state (their children die with them,
/// fundamentals.adoc "Object Lifetime"), then passes the call on.
pub unsafe extern "system" fn destroy_instance(handle: xr::Instance) -> xr::Result {
    guard("xrDestroyInstance", || {
        finish((|| {
            let state = instance(handle)?;
            let f = next(state.next.destroy_instance)?;
            let sessions = registry().remove_instance_children(handle);
            drop(sessions);
            registry().instances.write().remove(&handle.into_raw());
            Ok(f(handle))
        })())
    })
}
