//! The frame loop.

use openxr_sys as xr;

use super::{finish, fov_from_xr, fov_to_xr, next, session, succeeded};
use std::sync::atomic::Ordering;

use crate::ffi::guard;
use crate::state::Instance;

/// `xrWaitFrame`: passed on.
pub unsafe extern "system" fn wait_frame(
    sess: xr::Session,
    info: *const xr::FrameWaitInfo,
    state: *mut xr::FrameState,
) -> xr::Result {
    guard("xrWaitFrame", || {
        finish((|| {
            let s = session(sess)?;
            let r = next(s.instance.next.wait_frame)?(sess, info, state);
            if succeeded(r) && !state.is_null() {
                let t = (*state).predicted_display_time.as_nanos();
                s.last_display_time.store(t, Ordering::Relaxed);
            }
            Ok(r)
        })())
    })
}

/// `xrBeginFrame`: passed on.
pub unsafe extern "system" fn begin_frame(
    sess: xr::Session,
    info: *const xr::FrameBeginInfo,
) -> xr::Result {
    guard("xrBeginFrame", || {
        finish((|| {
            let s = session(sess)?;
            Ok(next(s.instance.next.begin_frame)?(sess, info))
        })())
    })
}

/// `xrEndFrame`: passed on.
pub unsafe extern "system" fn end_frame(
    sess: xr::Session,
    info: *const xr::FrameEndInfo,
) -> xr::Result {
    guard("xrEndFrame", || {
        finish((|| {
            let s = session(sess)?;
            Ok(next(s.instance.next.end_frame)?(sess, info))
        })())
    })
}

/// `xrLocateViews`: passed on.
pub unsafe extern "system" fn locate_views(
    sess: xr::Session,
    info: *const xr::ViewLocateInfo,
    view_state: *mut xr::ViewState,
    capacity: u32,
    count: *mut u32,
    views: *mut xr::View,
) -> xr::Result {
    guard("xrLocateViews", || {
        finish((|| {
            let s = session(sess)?;
            let r =
                next(s.instance.next.locate_views)?(sess, info, view_state, capacity, count, views);
            if succeeded(r) {
                learn_stereo_views(&s.instance, info, capacity, count, views);
            }
            Ok(r)
        })())
    })
}

/// After a successful `xrLocateViews` of the primary stereo views: remembers the runtime's FOVs and,
/// in symmetric-FOV mode, hands the application the shared symmetric FOV instead (the output array
/// is the application's to receive; its input structs are untouched).
unsafe fn learn_stereo_views(
    instance: &Instance,
    info: *const xr::ViewLocateInfo,
    capacity: u32,
    count: *const u32,
    views: *mut xr::View,
) {
    if info.is_null()
        || (*info).view_configuration_type != xr::ViewConfigurationType::PRIMARY_STEREO
        || views.is_null()
        || count.is_null()
        || *count != 2
        || capacity < 2
    {
        return;
    }
    let views = std::slice::from_raw_parts_mut(views, 2);
    if views.iter().any(|v| v.ty != xr::StructureType::VIEW) {
        return;
    }
    let fovs = [0, 1].map(|i| fov_from_xr(views[i].fov));
    {
        let mut known = instance.stereo_fovs.lock();
        if *known != Some(fovs) {
            *known = Some(fovs);
        }
    }
    if instance.symmetric_fov {
        for (v, f) in views.iter_mut().zip(instance.render_fovs(fovs)) {
            v.fov = fov_to_xr(f);
        }
    }
}
