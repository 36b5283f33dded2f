//! The frame loop.

use openxr_sys as xr;

use super::{finish, next, session, succeeded};
use crate::density::Fov;
use crate::ffi::guard;

/// `xrWaitFrame`: passed on.
pub unsafe extern "system" fn wait_frame(
    sess: xr::Session,
    info: *const xr::FrameWaitInfo,
    state: *mut xr::FrameState,
) -> xr::Result {
    guard("xrWaitFrame", || {
        finish((|| {
            let s = session(sess)?;
            Ok(next(s.instance.next.wait_frame)?(sess, info, state))
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

/// `xrLocateViews`: passed on; the FOVs the application gets are recorded, since the density maps
/// of its swapchains are computed for the FOVs it renders with. No allocation: this runs every frame.
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
            if succeeded(r)
                && s.gpu.is_some()
                && capacity > 0
                && !views.is_null()
                && !count.is_null()
            {
                let n = (*count).min(capacity) as usize;
                let located = std::slice::from_raw_parts(views, n);
                s.views.lock().record(located.iter().map(|v| Fov {
                    left: v.fov.angle_left,
                    right: v.fov.angle_right,
                    up: v.fov.angle_up,
                    down: v.fov.angle_down,
                }));
            }
            Ok(r)
        })())
    })
}
