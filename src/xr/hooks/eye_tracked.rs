//! XR_META_foveation_eye_tracked where fovea provides it: whether the system can foveate with the
//! eyes (`XrSystemFoveationEyeTrackedPropertiesMETA` in `xrGetSystemProperties`) and where each
//! view's fovea is now (`xrGetFoveationEyeTrackedStateMETA`). Where the runtime implements the
//! extension itself, `xrGetInstanceProcAddr` hands out the runtime's function and
//! `xrGetSystemProperties` goes down untouched. docs/eye-tracking.md#xr_meta_foveation_eye_tracked.
//!
//! Error codes follow the generated valid usage
//! (https://registry.khronos.org/OpenXR/specs/1.0/man/html/xrGetFoveationEyeTrackedStateMETA.html):
//! a NULL or mistyped state struct is XR_ERROR_VALIDATION_FAILURE, an unknown session
//! XR_ERROR_HANDLE_INVALID. A system without a gaze source is no error: the spec requires none, and
//! the state then says fixed foveation (projection centres, VALID clear), so an application that
//! asks every frame keeps running.

use std::ffi::c_void;

use openxr_sys as xr;

use crate::xr::extensions::Ext;
use crate::xr::ffi::{find_in_chain, ChainCopy, HookResult, Out};
use crate::xr::next_layer::next;
use crate::xr::registry::{check_lost, instance, observed_instance, session_for_call, Instance};
use crate::xr::values::succeeded;
use fovea_model::gaze::Tracking;
use fovea_model::Fov;

const META_PROPERTIES: xr::StructureType =
    xr::StructureType::SYSTEM_FOVEATION_EYE_TRACKED_PROPERTIES_META;
const EYE_GAZE_PROPERTIES: xr::StructureType =
    xr::StructureType::SYSTEM_EYE_GAZE_INTERACTION_PROPERTIES_EXT;

/// `xrGetSystemProperties`: where fovea provides XR_META_foveation_eye_tracked and the application
/// chained `XrSystemFoveationEyeTrackedPropertiesMETA`, the call goes down with a copy of the chain
/// without it (the runtime was not asked for the extension), what the runtime wrote is handed back
/// to the application's structs, and fovea fills `supportsFoveationEyeTracked` itself: true where
/// the system has a gaze source ([`has_gaze_source`]). Where fovea enabled XR_EXT_eye_gaze_interaction
/// below for itself, the application's `XrSystemEyeGazeInteractionPropertiesEXT` is left out of
/// the copy the same way and left as the application passed it.
pub fn get_system_properties(
    inst: xr::Instance,
    system: xr::SystemId,
    properties: Out<xr::SystemProperties>,
) -> HookResult<xr::Result> {
    let state = instance(inst)?;
    let f = next(state.next.get_system_properties)?;
    let down = |p: *mut xr::SystemProperties| {
        // SAFETY: the next layer's xrGetSystemProperties with the application's instance and
        // system, and either the application's output pointer as it passed it or fovea's copy of
        // its struct.
        let r = unsafe { f(inst, system, p) };
        observed_instance(&state, r)
    };
    let app = properties
        .read()
        .filter(|p| p.ty == xr::SystemProperties::TYPE);
    // The eye gaze struct of an application that did not enable XR_EXT_eye_gaze_interaction (fovea
    // enabled it below for itself) stays out of the runtime's reach: without fovea the runtime
    // would not know it, so fovea neither passes it down nor fills it.
    let hide_eye_gaze = state.gaze.as_ref().is_some_and(|g| !g.app_enabled);
    let provides_meta = state.extensions.provided(Ext::MetaFoveationEyeTracked);
    let Some(app) = app.filter(|_| provides_meta || hide_eye_gaze) else {
        return Ok(down(properties.raw()));
    };
    let next_chain = app.next as *const c_void;
    // SAFETY: the application's output chain is valid for the call (the shim's contract); a node
    // of the META type is that struct.
    let meta = unsafe {
        find_in_chain::<xr::SystemFoveationEyeTrackedPropertiesMETA>(next_chain, META_PROPERTIES)
    }
    .map_err(|_| xr::Result::ERROR_VALIDATION_FAILURE)?
    .filter(|_| provides_meta);
    // SAFETY: as above.
    let eye_gaze = unsafe {
        find_in_chain::<xr::SystemEyeGazeInteractionPropertiesEXT>(next_chain, EYE_GAZE_PROPERTIES)
    }
    .map_err(|_| xr::Result::ERROR_VALIDATION_FAILURE)?
    .filter(|_| hide_eye_gaze);
    if meta.is_none() && eye_gaze.is_none() {
        return Ok(down(properties.raw()));
    }
    let hidden = |t: xr::StructureType| {
        (t == META_PROPERTIES && meta.is_some()) || (t == EYE_GAZE_PROPERTIES && eye_gaze.is_some())
    };
    // SAFETY: as above; the copy shares only the chain's tail, which goes down within this call.
    let chain = unsafe { ChainCopy::without(next_chain, hidden) }
        .map_err(|_| xr::Result::ERROR_VALIDATION_FAILURE)?;
    let mut copy = app;
    copy.next = chain.head() as *mut c_void;
    let r = down(&mut copy);
    if !succeeded(r) {
        return Ok(r);
    }
    // SAFETY: the chain copied is the application's output chain of this call.
    unsafe { chain.write_back() };
    if let Some(meta) = meta {
        let supported = has_gaze_source(&state, system);
        // SAFETY: `meta` is the application's XrSystemFoveationEyeTrackedPropertiesMETA in its
        // output chain, valid for writes; only its output member is written.
        unsafe {
            (*meta.cast_mut()).supports_foveation_eye_tracked = supported.into();
        }
    }
    let Some(out) = properties.into_mut() else {
        return Ok(r);
    };
    // The runtime's answer into the application's struct: every output member, `type` and `next`
    // stay the application's.
    out.system_id = copy.system_id;
    out.vendor_id = copy.vendor_id;
    out.system_name = copy.system_name;
    out.graphics_properties = copy.graphics_properties;
    out.tracking_properties = copy.tracking_properties;
    Ok(r)
}

/// `xrGetFoveationEyeTrackedStateMETA`, called every frame: each view's fovea in the NDC of the
/// view's FOV, VALID while the gaze is fresh ([`Tracking::Tracked`]); held, returning or no gaze
/// give the centres the maps use now without VALID, and no gaze at all the projection centres
/// (fixed foveation). y points down unless the application's settings say up. No allocation and
/// no process-wide lock: the session is borrowed, its gaze copied under its record lock, and only
/// where a view does not follow the gaze is the instance's FOV record locked, after that one.
pub fn get_state(
    sess: xr::Session,
    state: Out<xr::FoveationEyeTrackedStateMETA>,
) -> HookResult<xr::Result> {
    let s = session_for_call(sess)?;
    check_lost(&s)?;
    let Some(st) = state.read() else {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    };
    if st.ty != xr::FoveationEyeTrackedStateMETA::TYPE {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    // No struct may extend it and unknown ones are ignored; a chain without end is refused.
    // SAFETY: the application's output chain is valid for the call (the shim's contract).
    unsafe {
        find_in_chain::<xr::BaseOutStructure>(st.next.cast_const(), xr::StructureType::UNKNOWN)
    }
    .map_err(|_| xr::Result::ERROR_VALIDATION_FAILURE)?;
    let eyes = if s.gaze.is_some() {
        *s.eyes.lock()
    } else {
        crate::xr::eye_centres::EyeCentres::FIXED
    };
    let flip = if s.instance.eye_tracked_y_up {
        1.0
    } else {
        -1.0
    };
    let Some(out) = state.into_mut() else {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    };
    // The projection centres cost eight tangents: only where a view does not follow the gaze.
    let mut fixed = None;
    for (i, c) in out.foveation_center.iter_mut().enumerate() {
        let [x, y] = eyes
            .of(i)
            .unwrap_or_else(|| fixed.get_or_insert_with(|| projection_centres(&s))[i]);
        *c = xr::Vector2f { x, y: y * flip };
    }
    out.flags = if eyes.tracking == Tracking::Tracked && eyes.follows() {
        xr::FoveationEyeTrackedStateFlagsMETA::VALID
    } else {
        xr::FoveationEyeTrackedStateFlagsMETA::EMPTY
    };
    Ok(xr::Result::SUCCESS)
}

/// Whether `system` has a gaze source fovea follows: the gaze source is on for the instance
/// (XR_EXT_eye_gaze_interaction enabled below, gaze not switched off) and the system reports
/// `supportsEyeGazeInteraction` ([`crate::xr::gaze`]). A session of such a system gets one
/// (`Session::gaze`), which is what `xrGetFoveationEyeTrackedStateMETA` follows.
fn has_gaze_source(instance: &Instance, system: xr::SystemId) -> bool {
    instance
        .gaze
        .as_ref()
        .is_some_and(|g| g.supported(system) == Ok(true))
}

/// Each stereo view's projection centre in the NDC of the FOV the application renders with (y up),
/// where fixed foveation puts the fovea; the image centre before `xrLocateViews` told the FOVs.
fn projection_centres(
    s: &crate::xr::registry::Session,
) -> [[f32; 2]; xr::FOVEATION_CENTER_SIZE_META] {
    let Some(fovs) = s.instance.stereo_fovs() else {
        return [[0.0, 0.0]; xr::FOVEATION_CENTER_SIZE_META];
    };
    let fovs: [Fov; 2] = if crate::xr::symmetric::active(s) {
        s.instance.render_fovs(fovs)
    } else {
        fovs
    };
    fovs.map(|f| f.projection_center_ndc())
}
