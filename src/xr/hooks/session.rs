//! Session lifetime and view configuration.

use std::sync::Arc;

use openxr_sys as xr;
use xr::Handle;

use super::{fov_from_xr, instance, next, observed_instance, session, succeeded, HookResult};
use crate::common::ffi::{In, Out, OutArray};
use crate::gpu::density_images::SessionGpu;
use crate::gpu::density_images::VulkanBinding;
use crate::xr::dispatch;
use crate::xr::extensions::Ext;
use crate::xr::registry::{registry, Instance, Session};
use fovea_model::projection::rescaled_size;
use fovea_model::Fov;

/// fovea's Vulkan objects for a new session on `binding`'s device, or `None` (logged) where they
/// cannot be made: the session then works without density images (fail open).
///
/// Whether VK_EXT_fragment_density_map is enabled on the device is known where fovea saw the device
/// created (xrCreateVulkanDeviceKHR, enable2) or told the application to enable it
/// (xrGetVulkanDeviceExtensionsKHR, enable); the application's own vkCreateDevice cannot be seen.
///
/// The binding's handles are live: the runtime accepted the session, and the application must keep
/// its Vulkan objects alive while the session exists.
fn session_gpu(instance: &Instance, binding: &VulkanBinding) -> Option<Arc<SessionGpu>> {
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
    // SAFETY: the handles of an accepted session's binding are live (see above), and they are
    // objects of the system Vulkan loader, as XR_KHR_vulkan_enable requires of the application.
    match unsafe { SessionGpu::new(binding, fdm_enabled) } {
        Ok(gpu) => Some(Arc::new(gpu)),
        Err(e) => {
            tracing::warn!(error = %e, "no density images for this session");
            None
        }
    }
}

/// `xrCreateSession`: records the Vulkan binding (XrGraphicsBindingVulkanKHR; the enable2 type is an
/// alias with the same value) so density images can be made on the application's device.
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
        let record = Session::new(handle, state, binding, gpu);
        registry()
            .sessions
            .write()
            .insert(handle.into_raw(), Arc::new(record));
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
    }
    Ok(r)
}

/// `xrEnumerateViewConfigurationViews`: passed on; in symmetric-FOV mode the recommended sizes of
/// the primary stereo views grow (see [`enlarge_for_symmetric_fov`]).
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
    // SAFETY: the next layer's function, with the application's arguments as it passed them.
    let r = unsafe { f(inst, system, config, capacity, count.raw(), views.raw()) };
    let r = observed_instance(&state, r);
    if succeeded(r)
        && state.symmetric_fov
        && config == xr::ViewConfigurationType::PRIMARY_STEREO
        && count.read() == Some(2)
        && capacity >= 2
    {
        if let Some(views) = views.into_slice(2) {
            enlarge_for_symmetric_fov(&state, views);
        }
    }
    Ok(r)
}

/// Symmetric-FOV mode: the shared FOV is wider than each eye's own, so the recommended sizes grow to
/// keep the runtime's pixels per tangent (the fixed-foveated-rendering seed: the mode costs pixels,
/// which foveation then wins back outside each eye's real FOV). Needs the runtime's FOVs: learned
/// from `xrLocateViews`, or asked for through a live session when the application sizes its
/// swapchains before its first frame (the usual order). Without a session the sizes stay as the
/// runtime gave them, and the log says so.
fn enlarge_for_symmetric_fov(state: &Instance, views: &mut [xr::ViewConfigurationView]) {
    if views
        .iter()
        .any(|v| v.ty != xr::StructureType::VIEW_CONFIGURATION_VIEW)
    {
        return;
    }
    let fovs = state.stereo_fovs().or_else(|| {
        let probed = probe_stereo_fovs(state)?;
        *state.stereo_fovs.lock() = Some(probed);
        Some(probed)
    });
    let Some(fovs) = fovs else {
        tracing::info!(
            "symmetric FOV: recommended sizes left as the runtime reports them until a session \
             exists (create the session before enumerating view configuration views)"
        );
        return;
    };
    let shared = state.render_fovs(fovs)[0];
    for (v, fov) in views.iter_mut().zip(fovs) {
        let [w, h] = rescaled_size(
            [
                v.recommended_image_rect_width,
                v.recommended_image_rect_height,
            ],
            fov,
            shared,
        );
        v.recommended_image_rect_width = w;
        v.recommended_image_rect_height = h;
        v.max_image_rect_width = v.max_image_rect_width.max(w);
        v.max_image_rect_height = v.max_image_rect_height.max(h);
    }
}

/// Locates the primary stereo views once, through a throwaway VIEW space of one of the instance's
/// sessions, at the session's last predicted display time (or the earliest valid time before its
/// first frame: the FOVs do not depend on it).
fn probe_stereo_fovs(state: &Instance) -> Option<[Fov; 2]> {
    let s = registry().any_session_of(state.handle)?;
    // SAFETY: the instance's own next-layer `xrGetInstanceProcAddr` and handle; a pointer the next
    // layer hands out for a name has the signature the spec gives that name.
    let (create, destroy) = unsafe {
        let create = dispatch::load(state.next_gipa, state.handle, c"xrCreateReferenceSpace")?;
        let destroy = dispatch::load(state.next_gipa, state.handle, c"xrDestroySpace")?;
        (
            std::mem::transmute::<xr::pfn::VoidFunction, xr::pfn::CreateReferenceSpace>(create),
            std::mem::transmute::<xr::pfn::VoidFunction, xr::pfn::DestroySpace>(destroy),
        )
    };
    let locate = state.next.locate_views?;
    let identity = xr::Posef {
        orientation: xr::Quaternionf {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        },
        position: xr::Vector3f::default(),
    };
    let info = xr::ReferenceSpaceCreateInfo {
        ty: xr::StructureType::REFERENCE_SPACE_CREATE_INFO,
        next: std::ptr::null(),
        reference_space_type: xr::ReferenceSpaceType::VIEW,
        pose_in_reference_space: identity,
    };
    let mut space = xr::Space::NULL;
    // SAFETY: the next layer's function on a live session, with fovea's own valid structs.
    if !succeeded(unsafe { create(s.handle, &info, &mut space) }) {
        return None;
    }
    let locate_info = xr::ViewLocateInfo {
        ty: xr::StructureType::VIEW_LOCATE_INFO,
        next: std::ptr::null(),
        view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
        display_time: xr::Time::from_nanos(s.frame.lock().display.unwrap_or(0).max(1)),
        space,
    };
    let mut view_state = xr::ViewState {
        ty: xr::StructureType::VIEW_STATE,
        next: std::ptr::null_mut(),
        view_state_flags: xr::ViewStateFlags::EMPTY,
    };
    let blank = xr::View {
        ty: xr::StructureType::VIEW,
        next: std::ptr::null_mut(),
        pose: identity,
        fov: xr::Fovf::default(),
    };
    let mut views = [blank; 2];
    let mut n = 0;
    // SAFETY: as above; `views` holds the 2 elements the capacity says.
    let r = unsafe {
        locate(
            s.handle,
            &locate_info,
            &mut view_state,
            2,
            &mut n,
            views.as_mut_ptr(),
        )
    };
    // SAFETY: the space fovea created above, destroyed once.
    unsafe { destroy(space) };
    if !succeeded(r) || n != 2 {
        tracing::debug!(?r, "symmetric FOV: could not locate the views to size them");
        return None;
    }
    Some(views.map(|v| fov_from_xr(v.fov)))
}
