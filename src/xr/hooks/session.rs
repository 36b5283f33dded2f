//! Session lifetime and view configuration.

use std::sync::Arc;

use openxr_sys as xr;
use xr::Handle;

use super::{finish, instance, next, observed, observed_instance, session, succeeded};
use crate::common::ffi::{self, guard};
use crate::gpu::density_images::SessionGpu;
use crate::xr::extensions::Ext;
use crate::xr::registry::{registry, Instance, Session, VulkanBinding};
use crate::xr::symmetric;

/// fovea's Vulkan objects for a new session on `binding`'s device, or `None` (logged) where they
/// cannot be made: the session then works without density images (fail open).
///
/// Whether VK_EXT_fragment_density_map is enabled on the device is known where fovea saw the device
/// created (xrCreateVulkanDeviceKHR, enable2) or told the application to enable it
/// (xrGetVulkanDeviceExtensionsKHR, enable); the application's own vkCreateDevice cannot be seen.
///
/// # Safety
/// The binding's handles must be live (the runtime accepted the session).
unsafe fn session_gpu(instance: &Instance, binding: &VulkanBinding) -> Option<Arc<SessionGpu>> {
    let recorded = registry()
        .vulkan_devices
        .lock()
        .get(&binding.device)
        .map(|d| d.fdm_enabled);
    let fdm_enabled = recorded.unwrap_or_else(|| {
        instance
            .vulkan
            .lock()
            .fdm_listed_for(binding.physical_device)
    });
    match SessionGpu::new(binding, fdm_enabled) {
        Ok(gpu) => Some(Arc::new(gpu)),
        Err(e) => {
            tracing::warn!(error = %e, "no density images for this session");
            None
        }
    }
}

/// `xrCreateSession`: records the Vulkan binding (XrGraphicsBindingVulkanKHR; the enable2 type is an
/// alias with the same value) so density images can be made on the application's device.
pub unsafe extern "system" fn create_session(
    inst: xr::Instance,
    info: *const xr::SessionCreateInfo,
    out: *mut xr::Session,
) -> xr::Result {
    guard("xrCreateSession", || {
        finish((|| {
            let state = instance(inst)?;
            let f = next(state.next.create_session)?;
            if info.is_null()
                || out.is_null()
                || (*info).ty != xr::StructureType::SESSION_CREATE_INFO
            {
                return Ok(observed_instance(&state, f(inst, info, out)));
            }
            let binding = match ffi::find_in_chain::<xr::GraphicsBindingVulkanKHR>(
                (*info).next,
                xr::StructureType::GRAPHICS_BINDING_VULKAN_KHR,
            ) {
                Ok(b) => b.map(|b| {
                    let b = &*b;
                    VulkanBinding {
                        instance: b.instance as u64,
                        physical_device: b.physical_device as u64,
                        device: b.device as u64,
                        queue_family_index: b.queue_family_index,
                        queue_index: b.queue_index,
                    }
                }),
                Err(_) => return Err(xr::Result::ERROR_VALIDATION_FAILURE),
            };
            let r = observed_instance(&state, f(inst, info, out));
            if succeeded(r) {
                let handle = *out;
                let gpu = binding
                    .filter(|_| state.extensions.provided(Ext::FoveationVulkan))
                    .and_then(|b| session_gpu(&state, &b));
                let record = Session::new(handle, state, binding, gpu);
                registry()
                    .sessions
                    .write()
                    .insert(handle.into_raw(), Arc::new(record));
            }
            Ok(r)
        })())
    })
}

/// `xrDestroySession`: the session's swapchains and profiles die with it (xr.xml parents). Their
/// records leave the registry before the call goes down and are released once the runtime has
/// destroyed the session, still before the call returns and so while the application's device
/// exists (it must outlive the session). Where the runtime refuses, the session is still alive and
/// the records go back: a retry, or any other call on it, finds them.
pub unsafe extern "system" fn destroy_session(handle: xr::Session) -> xr::Result {
    guard("xrDestroySession", || {
        finish((|| {
            let state = session(handle)?;
            let f = next(state.instance.next.destroy_session)?;
            let instance = state.instance.clone();
            drop(state);
            let detached = registry().detach_session(handle);
            let r = observed_instance(&instance, f(handle));
            if !succeeded(r) {
                tracing::warn!(
                    ?r,
                    "the runtime refused xrDestroySession; the session lives on"
                );
                registry().restore(detached);
            }
            Ok(r)
        })())
    })
}

/// `xrBeginSession`: once the runtime has begun the session, views can be located; symmetric-FOV
/// mode learns the FOVs there if it has not yet ([`crate::xr::symmetric`]).
pub unsafe extern "system" fn begin_session(
    handle: xr::Session,
    info: *const xr::SessionBeginInfo,
) -> xr::Result {
    guard("xrBeginSession", || {
        finish((|| {
            let s = session(handle)?;
            let f = next(s.instance.next.begin_session)?;
            let r = observed(&s, f(handle, info));
            if succeeded(r) {
                symmetric::session_began(&s, info);
            }
            Ok(r)
        })())
    })
}

/// `xrEndSession`: once the runtime has ended the session, its views can no longer be located.
pub unsafe extern "system" fn end_session(handle: xr::Session) -> xr::Result {
    guard("xrEndSession", || {
        finish((|| {
            let s = session(handle)?;
            let f = next(s.instance.next.end_session)?;
            let r = observed(&s, f(handle));
            if succeeded(r) {
                symmetric::session_ended(&s);
            }
            Ok(r)
        })())
    })
}

/// `xrEnumerateViewConfigurationViews`: passed on; in symmetric-FOV mode the stereo sizes are
/// enlarged for the shared FOV once the FOVs are known ([`crate::xr::symmetric`]).
pub unsafe extern "system" fn enumerate_view_configuration_views(
    inst: xr::Instance,
    system: xr::SystemId,
    config: xr::ViewConfigurationType,
    capacity: u32,
    count: *mut u32,
    views: *mut xr::ViewConfigurationView,
) -> xr::Result {
    guard("xrEnumerateViewConfigurationViews", || {
        finish((|| {
            let state = instance(inst)?;
            let f = next(state.next.enumerate_view_configuration_views)?;
            let r = symmetric::enumerate_views(&state, f, system, config, capacity, count, views);
            Ok(observed_instance(&state, r))
        })())
    })
}
