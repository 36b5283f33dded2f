//! Symmetric-FOV mode (`FOVEA_SYMMETRIC_FOV=1`): learning each eye's FOV in a way every conformant
//! runtime accepts, early enough for the application to size its swapchains from fovea's enlarged
//! recommended sizes.
//!
//! The FOVs come from, in order of preference:
//! 1. `XR_EPIC_view_configuration_fov`, where the runtime offers it: fovea enables it on the instance
//!    and asks for each view's `recommendedFov` in xrEnumerateViewConfigurationViews, which needs no
//!    session (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#XR_EPIC_view_configuration_fov);
//! 2. the application's own successful xrLocateViews;
//! 3. one xrLocateViews of fovea's own, only on a running session: right after the runtime's
//!    xrBeginSession succeeded, or when the application enumerates the views while a session runs.
//!    A runtime may refuse xrLocateViews outside a running session (Monado does;
//!    https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#xrLocateViews), so fovea never
//!    calls it there.
//!
//! Where the application was handed the runtime's own sizes because the FOVs were not known yet (no
//! EPIC extension, views enumerated before xrBeginSession), its swapchains have the pixels for each
//! eye's own FOV only: symmetric mode is then off for the session it begins (each eye keeps its own
//! FOV, never a wider one in too few pixels), and the log says so once. An application that
//! enumerates the views again before creating a swapchain of the session gets the enlarged sizes,
//! and the mode is on again for it.

use std::ffi::{CStr, CString};
use std::sync::atomic::Ordering;
use std::sync::Arc;

use openxr_sys as xr;
use xr::Handle;

use crate::xr::next_layer;
use crate::xr::registry::{registry, Instance, Session};
use crate::xr::values::{fov_from_xr, succeeded};
use fovea_model::projection::rescaled_size;
use fovea_model::Fov;

/// The extension that reports each view's FOV without a session.
pub const EPIC_VIEW_CONFIGURATION_FOV: &CStr = c"XR_EPIC_view_configuration_fov";

/// Most views fovea enumerates into an array of its own (the primary stereo configuration has 2).
const MAX_VIEWS: usize = 16;

/// Whether the session's views get the shared symmetric FOV.
pub fn active(session: &Session) -> bool {
    session.instance.symmetric_fov && !session.fovs.symmetric_off.load(Ordering::Relaxed)
}

/// In symmetric mode, adds XR_EPIC_view_configuration_fov to the extension list going down (a copy
/// of the application's) where the runtime offers it and the application did not enable it.
/// Returns whether the extension is enabled on the instance below.
pub fn enable_epic(
    symmetric: bool,
    app_names: &[&CStr],
    below: &[CString],
    down: &mut Vec<*const std::ffi::c_char>,
) -> bool {
    if app_names.contains(&EPIC_VIEW_CONFIGURATION_FOV) {
        return true;
    }
    if symmetric
        && below
            .iter()
            .any(|b| b.as_c_str() == EPIC_VIEW_CONFIGURATION_FOV)
    {
        down.push(EPIC_VIEW_CONFIGURATION_FOV.as_ptr());
        return true;
    }
    false
}

/// `xrEnumerateViewConfigurationViews` for the hook: calls down (through an array of fovea's own
/// where the EPIC extension reports the FOVs) and, in symmetric mode, enlarges the stereo sizes once
/// the FOVs are known. The application's structs are written only where they are its output: the
/// sizes, and an `XrViewConfigurationViewFovEPIC` it chained itself; never its `next` pointers.
///
/// # Safety
/// `f` must be the next layer's function for `state`'s instance; the other arguments are the
/// application's.
pub unsafe fn enumerate_views(
    state: &Instance,
    f: xr::pfn::EnumerateViewConfigurationViews,
    system: xr::SystemId,
    config: xr::ViewConfigurationType,
    capacity: u32,
    count: *mut u32,
    views: *mut xr::ViewConfigurationView,
) -> xr::Result {
    // SAFETY: the caller upholds this function's `# Safety` contract; the comments inside say
    // what each step relies on.
    unsafe {
        let inst = state.handle;
        let stereo = state.symmetric_fov && config == xr::ViewConfigurationType::PRIMARY_STEREO;
        if !stereo || views.is_null() || count.is_null() || capacity == 0 {
            return f(inst, system, config, capacity, count, views);
        }
        // SAFETY: the application passed `capacity` writable elements (two-call idiom).
        let app = std::slice::from_raw_parts_mut(views, capacity as usize);
        if app
            .iter()
            .any(|v| v.ty != xr::StructureType::VIEW_CONFIGURATION_VIEW)
        {
            // Not fovea's to judge: the runtime answers the malformed call.
            return f(inst, system, config, capacity, count, views);
        }
        let (r, epic_fovs) = if state.fovs.epic && app.len() <= MAX_VIEWS {
            enumerate_with_epic(f, inst, system, config, count, app)
        } else {
            (f(inst, system, config, capacity, count, views), None)
        };
        if !succeeded(r) || *count != 2 {
            return r;
        }
        let app = &mut app[..2];
        if let Some(fovs) = epic_fovs {
            state.stereo_fovs.set_if_unknown(fovs);
        }
        let fovs = state.stereo_fovs().or_else(|| probe_running(state));
        match fovs {
            Some(fovs) => {
                enlarge(state, app, fovs);
                state.fovs.handed_unenlarged.store(false, Ordering::Relaxed);
                // Sessions that have not sized a swapchain yet can render with the shared FOV again.
                for s in sessions_of(state.handle) {
                    if !registry().has_swapchains(s.handle) {
                        s.fovs.symmetric_off.store(false, Ordering::Relaxed);
                    }
                }
            }
            None => {
                state.fovs.handed_unenlarged.store(true, Ordering::Relaxed);
                tracing::debug!(
                    "symmetric FOV: the per-eye FOVs are not known yet; the runtime's sizes pass"
                );
            }
        }
        r
    }
}

/// Calls down with an array of fovea's own whose views each chain an `XrViewConfigurationViewFovEPIC`,
/// then copies the sizes into the application's views (and the FOVs into an EPIC struct it chained
/// itself). Returns the result and, for two views with sane FOVs, each eye's recommended FOV.
unsafe fn enumerate_with_epic(
    f: xr::pfn::EnumerateViewConfigurationViews,
    inst: xr::Instance,
    system: xr::SystemId,
    config: xr::ViewConfigurationType,
    count: *mut u32,
    app: &mut [xr::ViewConfigurationView],
) -> (xr::Result, Option<[Fov; 2]>) {
    // SAFETY: the caller upholds this function's `# Safety` contract; the comments inside say
    // what each step relies on.
    unsafe {
        let n = app.len();
        let mut epic = vec![
            xr::ViewConfigurationViewFovEPIC {
                ty: xr::StructureType::VIEW_CONFIGURATION_VIEW_FOV_EPIC,
                next: std::ptr::null(),
                recommended_fov: xr::Fovf::default(),
                max_mutable_fov: xr::Fovf::default(),
            };
            n
        ];
        let mut own: Vec<xr::ViewConfigurationView> = epic
            .iter_mut()
            .map(|e| xr::ViewConfigurationView {
                ty: xr::StructureType::VIEW_CONFIGURATION_VIEW,
                next: (e as *mut xr::ViewConfigurationViewFovEPIC).cast(),
                recommended_image_rect_width: 0,
                max_image_rect_width: 0,
                recommended_image_rect_height: 0,
                max_image_rect_height: 0,
                recommended_swapchain_sample_count: 0,
                max_swapchain_sample_count: 0,
            })
            .collect();
        let r = f(inst, system, config, n as u32, count, own.as_mut_ptr());
        if !succeeded(r) {
            return (r, None);
        }
        let written = (*count as usize).min(n);
        for i in 0..written {
            let (o, a) = (&own[i], &mut app[i]);
            a.recommended_image_rect_width = o.recommended_image_rect_width;
            a.max_image_rect_width = o.max_image_rect_width;
            a.recommended_image_rect_height = o.recommended_image_rect_height;
            a.max_image_rect_height = o.max_image_rect_height;
            a.recommended_swapchain_sample_count = o.recommended_swapchain_sample_count;
            a.max_swapchain_sample_count = o.max_swapchain_sample_count;
            // SAFETY: the application's chain is valid by the call's valid usage; only the first EPIC
            // struct counts ("Next Chain Structure Uniqueness"), and it is the application's output.
            if let Ok(Some(theirs)) = crate::xr::ffi::find_in_chain::<
                xr::ViewConfigurationViewFovEPIC,
            >(
                a.next, xr::StructureType::VIEW_CONFIGURATION_VIEW_FOV_EPIC
            ) {
                let theirs = theirs.cast_mut();
                (*theirs).recommended_fov = epic[i].recommended_fov;
                (*theirs).max_mutable_fov = epic[i].max_mutable_fov;
            }
        }
        drop(own);
        let fovs = (written == 2)
            .then(|| [0, 1].map(|i| fov_from_xr(epic[i].recommended_fov)))
            .filter(|f| f.iter().all(sane));
        (r, fovs)
    }
}

/// A FOV a runtime actually filled in: left of right, down below up, inside a half turn.
fn sane(f: &Fov) -> bool {
    let half = std::f32::consts::FRAC_PI_2;
    f.left < f.right
        && f.down < f.up
        && [f.left, f.right, f.up, f.down]
            .iter()
            .all(|a| a.is_finite() && a.abs() < half)
}

/// Enlarges the stereo sizes for the shared FOV: it is wider than each eye's own, so the recommended
/// sizes grow to keep the runtime's pixels per tangent (the mode costs pixels, which foveation then
/// wins back outside each eye's real FOV).
fn enlarge(state: &Instance, views: &mut [xr::ViewConfigurationView], fovs: [Fov; 2]) {
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

/// The live sessions of an instance.
fn sessions_of(instance: xr::Instance) -> Vec<Arc<Session>> {
    registry()
        .sessions
        .read()
        .values()
        .filter(|s| s.instance.handle == instance)
        .cloned()
        .collect()
}

/// The FOVs through one of the instance's sessions that runs with the stereo configuration, where
/// there is one; remembered on the instance.
unsafe fn probe_running(state: &Instance) -> Option<[Fov; 2]> {
    // SAFETY: the caller upholds this function's `# Safety` contract; the comments inside say
    // what each step relies on.
    unsafe {
        let s = sessions_of(state.handle)
            .into_iter()
            .find(|s| s.fovs.running_stereo.load(Ordering::Relaxed))?;
        let fovs = probe(&s)?;
        state.stereo_fovs.set(fovs);
        Some(fovs)
    }
}

/// After the runtime's xrBeginSession succeeded: the session runs (views can be located), the FOVs
/// are learned if still unknown, and symmetric mode is turned off for the session where the
/// application was handed the runtime's own sizes.
///
/// # Safety
/// `info` is the application's (checked here), the session live.
pub unsafe fn session_began(s: &Session, info: *const xr::SessionBeginInfo) {
    // SAFETY: the caller upholds this function's `# Safety` contract; the comments inside say
    // what each step relies on.
    unsafe {
        let stereo = !info.is_null()
            && (*info).ty == xr::StructureType::SESSION_BEGIN_INFO
            && (*info).primary_view_configuration_type == xr::ViewConfigurationType::PRIMARY_STEREO;
        s.fovs.running_stereo.store(stereo, Ordering::Relaxed);
        let instance = &s.instance;
        if !instance.symmetric_fov {
            return;
        }
        if stereo && instance.stereo_fovs().is_none() {
            if let Some(fovs) = probe(s) {
                instance.stereo_fovs.set(fovs);
            }
        }
        if instance.fovs.handed_unenlarged.load(Ordering::Relaxed) {
            s.fovs.symmetric_off.store(true, Ordering::Relaxed);
            if !instance.fovs.fallback_logged.swap(true, Ordering::Relaxed) {
                tracing::warn!(
                    "symmetric FOV is off for this session: the application sized its views before \
                     xrBeginSession, when fovea could not know the per-eye FOVs (the runtime does not \
                     offer XR_EPIC_view_configuration_fov, and views can be located only in a running \
                     session), so each eye keeps its own FOV; to use symmetric FOV, enumerate view \
                     configuration views after xrBeginSession, or use a runtime with \
                     XR_EPIC_view_configuration_fov"
                );
            }
        }
    }
}

/// After the runtime's xrEndSession succeeded: views can no longer be located.
pub fn session_ended(s: &Session) {
    s.fovs.running_stereo.store(false, Ordering::Relaxed);
}

/// Locates the primary stereo views once, through a throwaway VIEW space of a session that runs with
/// the stereo configuration, at its last predicted display time (or the earliest valid time before
/// its first frame: the FOVs do not depend on it).
///
/// # Safety
/// The session must be live and running with the primary stereo configuration.
unsafe fn probe(s: &Session) -> Option<[Fov; 2]> {
    // SAFETY: the caller upholds this function's `# Safety` contract; the comments inside say
    // what each step relies on.
    unsafe {
        let state = &s.instance;
        // SAFETY: the names' signatures are those of the pfn types they are cast to.
        let create: xr::pfn::CreateReferenceSpace = std::mem::transmute(next_layer::load(
            state.next_gipa,
            state.handle,
            c"xrCreateReferenceSpace",
        )?);
        // SAFETY: as above.
        let destroy: xr::pfn::DestroySpace = std::mem::transmute(next_layer::load(
            state.next_gipa,
            state.handle,
            c"xrDestroySpace",
        )?);
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
        // SAFETY: fovea's own structs, live for the call; the session is live.
        if !succeeded(create(s.handle, &info, &mut space)) {
            return None;
        }
        let display = s.waits.display().unwrap_or(0).max(1);
        let locate_info = xr::ViewLocateInfo {
            ty: xr::StructureType::VIEW_LOCATE_INFO,
            next: std::ptr::null(),
            view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
            display_time: xr::Time::from_nanos(display),
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
        // SAFETY: fovea's own output array of 2 views; the session runs with the stereo configuration.
        let r = locate(
            s.handle,
            &locate_info,
            &mut view_state,
            2,
            &mut n,
            views.as_mut_ptr(),
        );
        // SAFETY: the space was created above and is destroyed once.
        destroy(space);
        if !succeeded(r) || n != 2 {
            tracing::debug!(?r, "symmetric FOV: could not locate the views to size them");
            return None;
        }
        Some(views.map(|v| fov_from_xr(v.fov)))
    }
}
