//! Session lifetime and view configuration.

use std::sync::Arc;

use openxr_sys as xr;
use xr::Handle;

use crate::xr::extensions::Ext;
use crate::xr::eye_centres::EyeCentres;
use crate::xr::ffi::HookResult;
use crate::xr::ffi::{In, Out, OutArray};
use crate::xr::next_layer::next;
use crate::xr::registry::{instance, observed, observed_instance, session};
use crate::xr::registry::{registry, Instance, Session};
use crate::xr::session_gpu::{SessionGpu, VulkanBinding};
use crate::xr::symmetric;
use crate::xr::values::succeeded;

/// fovea's Vulkan objects for a new session on `binding`'s device, or `None` (logged) where they
/// cannot be made: the session then works without density images (fail open).
///
/// Whether VK_EXT_fragment_density_map is enabled on the device is known where fovea saw the device
/// created (xrCreateVulkanDeviceKHR, enable2) or told the application to enable it
/// (xrGetVulkanDeviceExtensionsKHR, enable); the application's own vkCreateDevice cannot be seen
/// from here. Whether density-map offsets reach density maps on it, fovea's Vulkan layer tells
/// through [`crate::bridge::device_offsets`].
///
/// The binding's handles are live: the runtime accepted the session, and the application must keep
/// its Vulkan objects alive while the session exists.
fn session_gpu(instance: &Instance, binding: &VulkanBinding) -> Option<Arc<SessionGpu>> {
    let recorded = registry()
        .vulkan_devices
        .lock()
        .get(&binding.device)
        .copied();
    // Whether offsets reach density maps: fovea's Vulkan layer knows for every device it saw
    // created (it may have left the offset extensions out); where it did not see it, what
    // xrCreateVulkanDeviceKHR's create info enabled.
    let offsets = crate::bridge::device_offsets(<ash::vk::Device as ash::vk::Handle>::from_raw(
        binding.device,
    ))
    .or(recorded.map(|d| d.offsets_enabled));
    let fdm_enabled = recorded.map(|d| d.fdm_enabled).unwrap_or_else(|| {
        instance
            .vulkan
            .lock()
            .fdm_listed_for(binding.physical_device)
    });
    // SAFETY: the handles of an accepted session's binding are live (see above), and they are
    // objects of the system Vulkan loader, as XR_KHR_vulkan_enable requires of the application.
    match unsafe { SessionGpu::new(binding, fdm_enabled, offsets) } {
        Ok(gpu) => Some(Arc::new(gpu)),
        Err(e) => {
            tracing::warn!(error = %e, "no density images for this session");
            None
        }
    }
}

/// `xrCreateSession`: records the Vulkan binding (XrGraphicsBindingVulkanKHR; the enable2 type is an
/// alias with the same value) so density images can be made on the application's device, and sets
/// up the gaze source where the system has an eye tracker ([`crate::xr::gaze`]).
pub fn create_session(
    inst: xr::Instance,
    info: In<xr::SessionCreateInfo>,
    out: Out<xr::Session>,
) -> HookResult<xr::Result> {
    let state = instance(inst)?;
    let f = next(state.next.create_session)?;
    // SAFETY: for both calls below: the next layer's xrCreateSession, with the application's
    // arguments as it passed them.
    let down = || unsafe { f(inst, info.raw(), out.raw()) };
    if info.get().is_none() || out.is_null() {
        return Ok(observed_instance(&state, down()));
    }
    let binding = match info.chained::<xr::GraphicsBindingVulkanKHR>() {
        Ok(b) => b.map(|b| VulkanBinding {
            instance: b.instance as u64,
            physical_device: b.physical_device as u64,
            device: b.device as u64,
            queue_family_index: b.queue_family_index,
            queue_index: b.queue_index,
        }),
        Err(_) => return Err(xr::Result::ERROR_VALIDATION_FAILURE),
    };
    let r = observed_instance(&state, down());
    if succeeded(r) {
        let Some(handle) = out.read() else {
            return Ok(r);
        };
        let gpu = binding
            .filter(|_| state.extensions.provided(Ext::FoveationVulkan))
            .and_then(|b| session_gpu(&state, &b));
        // The system the application's session runs on: its eye tracker, if it has one.
        let system = info.get().map(|i| i.system_id);
        let gaze = state
            .gaze
            .as_ref()
            .zip(system)
            .and_then(|(g, system)| g.session(handle, system));
        let record = Arc::new(Session {
            gaze,
            ..Session::new(handle, state, binding, gpu)
        });
        registry()
            .sessions
            .write()
            .insert(handle.into_raw(), Arc::clone(&record));
        if record.instance.inject.is_some() {
            // An injected level made dynamic by the debug properties from the start (no change
            // to notice later) must still let the controller step up to it.
            crate::xr::pattern::refresh_dynamic_max(&record);
            crate::xr::pattern::publish_injected_pattern(&record);
        }
    }
    Ok(r)
}

/// `xrDestroySession`: the session's swapchains and profiles die with it (xr.xml parents). Their
/// records leave the registry before the call goes down and are released once the runtime has
/// destroyed the session, still before the call returns and so while the application's device
/// exists (it must outlive the session). Where the runtime refuses, the session is still alive and
/// the records go back: a retry, or any other call on it, finds them.
pub fn destroy_session(handle: xr::Session) -> HookResult<xr::Result> {
    let state = session(handle)?;
    let f = next(state.instance.next.destroy_session)?;
    let instance = state.instance.clone();
    drop(state);
    let detached = registry().detach_session(handle);
    // SAFETY: the next layer's xrDestroySession, with the application's handle.
    let r = observed_instance(&instance, unsafe { f(handle) });
    if !succeeded(r) {
        tracing::warn!(
            ?r,
            "the runtime refused xrDestroySession; the session lives on"
        );
        registry().restore(detached);
    } else {
        detached.forget_published();
    }
    Ok(r)
}

/// `xrBeginSession`: once the runtime has begun the session, views can be located; symmetric-FOV
/// mode learns the FOVs there if it has not yet ([`crate::xr::symmetric`]).
pub fn begin_session(
    handle: xr::Session,
    info: In<xr::SessionBeginInfo>,
) -> HookResult<xr::Result> {
    let s = session(handle)?;
    let f = next(s.instance.next.begin_session)?;
    // SAFETY: the next layer's function, with the application's arguments as it passed them.
    let r = observed(&s, unsafe { f(handle, info.raw()) });
    if succeeded(r) {
        // SAFETY: the application's XrSessionBeginInfo, which the runtime just accepted.
        unsafe { symmetric::session_began(&s, info.raw()) };
        if let (Some(g), Some(i)) = (&s.gaze, info.get()) {
            g.began(i.primary_view_configuration_type);
        }
    }
    Ok(r)
}

/// `xrEndSession`: once the runtime has ended the session, its views can no longer be located.
pub fn end_session(handle: xr::Session) -> HookResult<xr::Result> {
    let s = session(handle)?;
    let f = next(s.instance.next.end_session)?;
    // SAFETY: the next layer's function, with the application's argument.
    let r = observed(&s, unsafe { f(handle) });
    if succeeded(r) {
        symmetric::session_ended(&s);
        if let Some(g) = &s.gaze {
            g.ended();
            // No frames until the next begin: whatever follows the eyes goes back to fixed
            // foveation.
            *s.eyes.lock() = EyeCentres::FIXED;
        }
    }
    Ok(r)
}

/// `xrEnumerateViewConfigurationViews`: passed on; in symmetric-FOV mode the stereo sizes are
/// enlarged for the shared FOV once the FOVs are known ([`crate::xr::symmetric`]).
pub fn enumerate_view_configuration_views(
    inst: xr::Instance,
    system: xr::SystemId,
    config: xr::ViewConfigurationType,
    capacity: u32,
    count: Out<u32>,
    views: OutArray<xr::ViewConfigurationView>,
) -> HookResult<xr::Result> {
    let state = instance(inst)?;
    let f = next(state.next.enumerate_view_configuration_views)?;
    // SAFETY: the next layer's function and the application's output pointers as it passed them.
    let r = unsafe {
        symmetric::enumerate_views(
            &state,
            f,
            system,
            config,
            capacity,
            count.raw(),
            views.raw(),
        )
    };
    Ok(observed_instance(&state, r))
}
