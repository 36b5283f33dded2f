//! The frame loop: timing for the dynamic controller and the stats, the views the application
//! locates.

use std::sync::atomic::Ordering;
use std::time::Instant;

use openxr_sys as xr;
use xr::Handle;

use super::{finish, fov_from_xr, fov_to_xr, next, observed, session, succeeded};
use crate::common::ffi::guard;
use crate::xr::registry::{registry, Instance, Session};
use fovea_model::density::Rect;
use fovea_model::dynamic::LADDER;
use fovea_model::maps::{SubmittedView, MAX_VIEWS};
use fovea_model::stats::{Line, Window};

/// `xrWaitFrame`: the predicted display time and period tell how many display periods the previous
/// frame missed, the dynamic controller's and the stats' input.
pub unsafe extern "system" fn wait_frame(
    sess: xr::Session,
    info: *const xr::FrameWaitInfo,
    state: *mut xr::FrameState,
) -> xr::Result {
    guard("xrWaitFrame", || {
        finish((|| {
            let s = session(sess)?;
            let r = observed(&s, next(s.instance.next.wait_frame)?(sess, info, state));
            if succeeded(r) && !state.is_null() {
                let display = (*state).predicted_display_time.as_nanos();
                let period = (*state).predicted_display_period.as_nanos();
                let mut f = s.frame.lock();
                if let (Some(last), true) = (f.display, period > 0) {
                    let interval = display - last;
                    f.missed = u32::try_from(((interval + period / 2) / period - 1).max(0))
                        .unwrap_or(u32::MAX);
                    let missed = f.missed;
                    f.stats.waited(interval, missed);
                }
                f.display = Some(display);
                f.period = period;
            }
            Ok(r)
        })())
    })
}

/// `xrBeginFrame`: starts the application's frame time.
pub unsafe extern "system" fn begin_frame(
    sess: xr::Session,
    info: *const xr::FrameBeginInfo,
) -> xr::Result {
    guard("xrBeginFrame", || {
        finish((|| {
            let s = session(sess)?;
            let r = observed(&s, next(s.instance.next.begin_frame)?(sess, info));
            if succeeded(r) {
                s.frame.lock().begin_at = Some(Instant::now());
            }
            Ok(r)
        })())
    })
}

/// `xrEndFrame`: runs the dynamic controller, checks the debug property file when due, and once a
/// second of display time writes the stats line; then passes the frame on untouched.
pub unsafe extern "system" fn end_frame(
    sess: xr::Session,
    info: *const xr::FrameEndInfo,
) -> xr::Result {
    guard("xrEndFrame", || {
        finish((|| {
            let s = session(sess)?;
            let entered = Instant::now();
            if s.gpu.is_some() {
                learn_submitted(&s, info);
            }
            let overrides_changed = {
                let mut f = s.frame.lock();
                let display = if !info.is_null() && (*info).ty == xr::StructureType::FRAME_END_INFO
                {
                    (*info).display_time.as_nanos()
                } else {
                    f.display.unwrap_or(0)
                };
                let app_ns = f.begin_at.take().map(|b| (entered - b).as_nanos() as u64);
                let max = s.dynamic_max.load(Ordering::Relaxed);
                let missed = f.missed;
                if f.controller.frame(display, missed, max) {
                    let step = f.controller.step();
                    s.dynamic_step.store(step, Ordering::Relaxed);
                    s.pattern_generation.fetch_add(1, Ordering::Relaxed);
                    tracing::info!(
                        target: fovea_abi::log_target::DYNAMIC,
                        step,
                        level = ?LADDER[step],
                        "dynamic foveation"
                    );
                }
                let changed = s.instance.overrides.poll(display);
                let own = (Instant::now() - entered).as_nanos() as u64;
                let window = f.stats.ended(display, app_ns, own);
                let period = f.period;
                drop(f);
                if let Some(w) = window {
                    report(&s, w, period);
                }
                changed
            };
            if overrides_changed {
                s.pattern_generation.fetch_add(1, Ordering::Relaxed);
                s.refresh_dynamic_max();
            }
            Ok(observed(&s, next(s.instance.next.end_frame)?(sess, info)))
        })())
    })
}

/// Most composition layers read per frame when learning views.
const MAX_LAYERS: usize = 16;

/// Records which views this frame's projection layers put into which rectangle and array layer of
/// which of the session's swapchains with density images, so each map covers exactly the views
/// rendered into it (multiview arrays, double-wide images, one swapchain per eye alike). A change
/// bumps the swapchain's generation, rebuilding its maps once. Read-only on the application's
/// structs, no allocation; other layer types and chained structs are not looked at.
unsafe fn learn_submitted(s: &Session, info: *const xr::FrameEndInfo) {
    if info.is_null() || (*info).ty != xr::StructureType::FRAME_END_INFO || (*info).layers.is_null()
    {
        return;
    }
    let count = ((*info).layer_count as usize).min(MAX_LAYERS);
    let layers = std::slice::from_raw_parts((*info).layers, count);
    let mut found = [(xr::Swapchain::NULL, [None; MAX_VIEWS]); MAX_VIEWS];
    for &layer in layers {
        if layer.is_null() || (*layer).ty != xr::StructureType::COMPOSITION_LAYER_PROJECTION {
            continue;
        }
        let p = layer.cast::<xr::CompositionLayerProjection>();
        if (*p).views.is_null() {
            continue;
        }
        let n = ((*p).view_count as usize).min(MAX_VIEWS);
        for (eye, v) in std::slice::from_raw_parts((*p).views, n).iter().enumerate() {
            let (offset, extent) = (v.sub_image.image_rect.offset, v.sub_image.image_rect.extent);
            if v.ty != xr::StructureType::COMPOSITION_LAYER_PROJECTION_VIEW
                || extent.width <= 0
                || extent.height <= 0
            {
                continue;
            }
            let sc = v.sub_image.swapchain;
            let Some(slot) = found
                .iter_mut()
                .find(|f| f.0 == sc || f.0 == xr::Swapchain::NULL)
            else {
                continue;
            };
            slot.0 = sc;
            if let Some(free) = slot.1.iter_mut().find(|v| v.is_none()) {
                *free = Some(SubmittedView {
                    eye,
                    layer: v.sub_image.image_array_index,
                    rect: Rect {
                        x: offset.x,
                        y: offset.y,
                        width: extent.width as u32,
                        height: extent.height as u32,
                    },
                    fov: fov_from_xr(v.fov),
                });
            }
        }
    }
    for (sc, views) in found.iter().take_while(|f| f.0 != xr::Swapchain::NULL) {
        let Some(record) = registry().swapchain(*sc) else {
            continue;
        };
        if record.density.is_none() || record.session.handle != s.handle {
            continue;
        }
        let mut sub = record.submitted.lock();
        if sub.views != *views {
            sub.views = *views;
            sub.generation += 1;
        }
    }
}

/// Writes the stats line for a finished window, when `fovea::stats` is enabled.
fn report(s: &Session, window: Window, period_ns: i64) {
    if !tracing::enabled!(target: fovea_abi::log_target::STATS, tracing::Level::INFO) {
        return;
    }
    let level = registry()
        .foveated_swapchains_of(s.handle)
        .iter()
        .filter_map(|sc| Some(s.pattern_for(&sc.foveation.as_ref()?.lock())))
        .map(|(p, dynamic)| (p.level, dynamic))
        .max();
    let line = Line {
        window,
        refresh_hz: if period_ns > 0 {
            (1e9 / period_ns as f64).round() as u32
        } else {
            0
        },
        level,
        maps_built: s.maps_built.load(Ordering::Relaxed),
        maps_uploaded: s.maps_uploaded.load(Ordering::Relaxed),
    };
    tracing::info!(target: fovea_abi::log_target::STATS, "{line}");
}

/// `xrLocateViews`: passed on.
/// `xrLocateViews`: the FOVs the application gets are recorded, since the density maps
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
            let locate = next(s.instance.next.locate_views)?;
            let r = observed(&s, locate(sess, info, view_state, capacity, count, views));
            if succeeded(r) {
                learn_stereo_views(&s.instance, info, capacity, count, views);
            }
            if succeeded(r)
                && s.gpu.is_some()
                && capacity > 0
                && !views.is_null()
                && !count.is_null()
            {
                let n = (*count).min(capacity) as usize;
                let located = std::slice::from_raw_parts(views, n);
                if located.iter().any(|v| v.ty != xr::StructureType::VIEW) {
                    return Ok(r);
                }
                s.views
                    .lock()
                    .record(located.iter().map(|v| fov_from_xr(v.fov)));
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
        || (*info).ty != xr::StructureType::VIEW_LOCATE_INFO
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
    *instance.stereo_fovs.lock() = Some(fovs);
    if instance.symmetric_fov {
        for (v, f) in views.iter_mut().zip(instance.render_fovs(fovs)) {
            v.fov = fov_to_xr(f);
        }
    }
}
