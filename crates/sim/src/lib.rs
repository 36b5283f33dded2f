//! Simulated headset runtime (being written).

use std::ffi::c_char;

use openxr_sys as xr;

/// The runtime's `xrGetInstanceProcAddr` (being written).
///
/// # Safety
/// `function` must be writable.
pub unsafe extern "system" fn get_instance_proc_addr(
    _instance: xr::Instance,
    _name: *const c_char,
    function: *mut Option<xr::pfn::VoidFunction>,
) -> xr::Result {
    if !function.is_null() {
        *function = None;
    }
    xr::Result::ERROR_RUNTIME_UNAVAILABLE
}

pub mod control {}
