//! The test-facing control API: configure the simulated headset, inject faults and load, and read
//! back exactly what reached the runtime.
//!
//! Plain Rust; no OpenXR call goes through here.

use openxr_sys as xr;
use openxr_sys::Handle;

pub use crate::config::{set_thread_config, EyeGaze, Fault, Load, SimConfig, META_NATIVE_CENTRES};
pub use crate::objects::{Call, CreatedInstance, FoveationParams, SubmittedView};
use crate::state::world;

/// Fails a call to `fault.function` on `instance` (see [`Fault`]).
pub fn inject_fault(instance: xr::Instance, fault: Fault) {
    if let Some(inst) = world().instances.get_mut(&instance.into_raw()) {
        inst.faults.push(fault);
    }
}

/// Replaces the instance's simulated GPU load.
pub fn set_load(instance: xr::Instance, load: Load) {
    if let Some(inst) = world().instances.get_mut(&instance.into_raw()) {
        inst.config.load = load;
    }
}

/// Every call that reached the runtime for `instance`, in order; still available after the instance
/// is destroyed.
pub fn journal(instance: xr::Instance) -> Vec<Call> {
    world()
        .record(instance.into_raw())
        .map(|r| r.journal.clone())
        .unwrap_or_default()
}

/// The extension names the instance was created with.
pub fn enabled_extensions(instance: xr::Instance) -> Vec<String> {
    world()
        .record(instance.into_raw())
        .map(|r| r.enabled_extensions.clone())
        .unwrap_or_default()
}

/// Per successful xrEndFrame, the projection views submitted.
pub fn end_frame_views(instance: xr::Instance) -> Vec<Vec<SubmittedView>> {
    world()
        .record(instance.into_raw())
        .map(|r| r.end_frames.clone())
        .unwrap_or_default()
}

/// Calls that returned an error code, by command name; still available after the instance is
/// destroyed, and counted whether or not the journal is kept.
pub fn errors(instance: xr::Instance) -> Vec<(&'static str, u64)> {
    world()
        .record(instance.into_raw())
        .map(|r| r.errors.iter().map(|(f, n)| (*f, *n)).collect())
        .unwrap_or_default()
}

/// The errors the runtime chose by its own rules (everything in [`errors`] that was not an injected
/// fault), by command name: empty when no call the simulated runtime refuses reached it.
pub fn refusals(instance: xr::Instance) -> Vec<(&'static str, u64)> {
    world()
        .record(instance.into_raw())
        .map(|r| r.refusals.iter().map(|(f, n)| (*f, *n)).collect())
        .unwrap_or_default()
}

/// Every instance created in this process, in order, whoever created it (the application or a
/// layer above the runtime); destroyed ones included.
pub fn created_instances() -> Vec<CreatedInstance> {
    world().created.clone()
}

/// The refusals of calls that belong to no instance (an `xrCreateInstance` the runtime refused), by
/// command name, in this process: the runtime's errors that no instance's [`refusals`] hold.
pub fn refusals_without_instance() -> Vec<(&'static str, u64)> {
    world()
        .refusals_without_instance
        .iter()
        .map(|(f, n)| (*f, *n))
        .collect()
}

/// With native foveation ([`SimConfig::native_foveation`]), what xrUpdateSwapchainFB last applied
/// to `swapchain`; `None` before any (or for an unknown swapchain).
pub fn swapchain_foveation(swapchain: xr::Swapchain) -> Option<FoveationParams> {
    world()
        .swapchains
        .get(&swapchain.into_raw())
        .and_then(|s| s.foveation)
        .map(|a| a.params)
}

/// Instances, sessions, swapchains and spaces alive across all instances (leak checks).
pub fn live_objects() -> usize {
    world().live_objects()
}
