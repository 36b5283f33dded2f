//! The frame loop: timing for the dynamic controller and the stats, the views the application
//! locates.

use std::sync::atomic::Ordering;
use std::time::Instant;

use openxr_sys as xr;
use xr::Handle;

use crate::xr::ffi::HookResult;
use crate::xr::ffi::{In, Out, OutArray};
use crate::xr::gaze::Due;
use crate::xr::next_layer::next;
use crate::xr::pattern::{injected_pattern_at, pattern_for, refresh_dynamic_max};
use crate::xr::pattern::{publish_injected_centres, publish_injected_pattern};
use crate::xr::registry::{observed, session_for_call};
use crate::xr::registry::{registry, Instance, Session};
use crate::xr::values::{fov_from_xr, fov_to_xr, succeeded};
use fovea_model::density::Rect;
use fovea_model::dynamic::LADDER;
use fovea_model::maps::{SubmittedView, MAX_VIEWS};
use fovea_model::stats::{GazeShown, Line, Window};

/// `xrWaitFrame`: the predicted display time and period tell how many display periods the previous
/// frame missed, the dynamic controller's and the stats' input; the gaze is located at that time
/// for this frame ([`crate::xr::gaze`]), after the gaze source attached or synced its set alone
/// where the application does not (and a setting or the session's focus allows it).
pub fn wait_frame(
    sess: xr::Session,
    info: In<xr::FrameWaitInfo>,
    state: Out<xr::FrameState>,
) -> HookResult<xr::Result> {
    let s = session_for_call(sess)?;
    let f = next(s.instance.next.wait_frame)?;
    // SAFETY: the next layer's xrWaitFrame, with the application's arguments as it passed them.
    let r = observed(&s, unsafe { f(sess, info.raw(), state.raw()) });
    if let (true, Some(state)) = (succeeded(r), state.read()) {
        s.waits.waited(
            state.predicted_display_time.as_nanos(),
            state.predicted_display_period.as_nanos(),
        );
        if let (Some(g), Some(ig)) = (&s.gaze, &s.instance.gaze) {
            match g.waited(state.predicted_display_time.as_nanos()) {
                Due::Nothing => {}
                Due::AttachAlone => ig.attach_alone(g),
                Due::SyncAlone => g.sync_alone(),
            }
            // The gaze of the frame the application renders now: located at this frame's
            // predicted display time, with the action state of the last sync.
            if let Some(centres) = g.update() {
                *s.eyes.lock() = centres;
            }
        }
    }
    Ok(r)
}

/// Whether the stats line is logged: only then are the application's frame time and the layer's own
/// time measured, since reading the clock is a third of the layer's cost per frame
/// (docs/ARCHITECTURE.md#per-frame-cost). The filter's answer is cached per call site by `tracing`
/// and renewed when the filter is reloaded, so asking costs a load.
fn stats_logged() -> bool {
    tracing::enabled!(target: fovea_abi::log_target::STATS, tracing::Level::INFO)
}

/// `xrBeginFrame`: starts the application's frame time, while the stats line is logged.
pub fn begin_frame(sess: xr::Session, info: In<xr::FrameBeginInfo>) -> HookResult<xr::Result> {
    let s = session_for_call(sess)?;
    let f = next(s.instance.next.begin_frame)?;
    // SAFETY: the next layer's xrBeginFrame, with the application's arguments as it passed them.
    let r = observed(&s, unsafe { f(sess, info.raw()) });
    if succeeded(r) && stats_logged() {
        s.frame.lock().begin_at = Some(Instant::now());
    }
    Ok(r)
}

/// `xrEndFrame`: runs the dynamic controller, checks the debug property file when due, and once a
/// second of display time writes the stats line; then passes the frame on untouched.
pub fn end_frame(sess: xr::Session, info: In<xr::FrameEndInfo>) -> HookResult<xr::Result> {
    let s = session_for_call(sess)?;
    let entered = stats_logged().then(Instant::now);
    if s.gpu.is_some() {
        learn_submitted(&s, info);
    }
    if s.instance.inject.is_some() {
        learn_eye_swapchains(info);
    }
    let overrides_changed = {
        let mut f = s.frame.lock();
        let display = match info.get() {
            Some(i) => i.display_time.as_nanos(),
            None => s.waits.display().unwrap_or(0),
        };
        let sums = s.waits.sums();
        let new = sums.since(f.waits_counted);
        f.waits_counted = sums;
        f.stats.waited(new.interval_ns, new.intervals, new.missed);
        let app_ns = f
            .begin_at
            .take()
            .zip(entered)
            .map(|(b, e)| (e - b).as_nanos() as u64);
        let max = s.dynamic_max.load(Ordering::Relaxed);
        let missed = s.waits.missed();
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
        let own = entered.map(|e| (Instant::now() - e).as_nanos() as u64);
        let window = f.stats.ended(display, app_ns, own);
        drop(f);
        let period = s.waits.period();
        if let Some(w) = window {
            report(&s, w, period);
        }
        changed
    };
    if overrides_changed {
        s.pattern_generation.fetch_add(1, Ordering::Relaxed);
        refresh_dynamic_max(&s);
    }
    publish_injected_pattern(&s);
    publish_injected_centres(&s);
    let f = next(s.instance.next.end_frame)?;
    // SAFETY: the next layer's xrEndFrame, with the application's arguments as it passed them.
    Ok(observed(&s, unsafe { f(sess, info.raw()) }))
}

/// Most composition layers read per frame when learning views.
const MAX_LAYERS: usize = 16;

/// The views of each projection layer the frame submits (at most [`MAX_LAYERS`] layers of
/// [`MAX_VIEWS`] views); other layer types, and chained structs, are not looked at. Read-only on
/// the application's structs, no allocation.
fn projection_layers<'a>(
    info: In<'a, xr::FrameEndInfo>,
) -> impl Iterator<Item = &'a [xr::CompositionLayerProjectionView]> + 'a {
    let layers: &'a [*const xr::CompositionLayerBaseHeader] = match info.get() {
        Some(i) if !i.layers.is_null() => {
            // SAFETY: a valid XrFrameEndInfo (`In`) has `layers` pointing to `layerCount` layer
            // pointers (https://registry.khronos.org/OpenXR/specs/1.0/man/html/XrFrameEndInfo.html);
            // fovea reads at most that many.
            unsafe {
                std::slice::from_raw_parts(i.layers, (i.layer_count as usize).min(MAX_LAYERS))
            }
        }
        _ => &[],
    };
    layers.iter().filter_map(|&layer| {
        // SAFETY: each element is a valid layer pointer (as above) for the call, so `In`'s
        // contract holds for it.
        let p = unsafe { In::<'a, _>::new(layer) }.cast::<xr::CompositionLayerProjection>()?;
        if p.views.is_null() {
            return None;
        }
        let n = (p.view_count as usize).min(MAX_VIEWS);
        // SAFETY: a valid XrCompositionLayerProjection has `views` pointing to `viewCount` views
        // (https://registry.khronos.org/OpenXR/specs/1.0/man/html/XrCompositionLayerProjection.html).
        Some(unsafe { std::slice::from_raw_parts(p.views, n) })
    })
}

/// Records which views this frame's projection layers put into which rectangle and array layer of
/// which of the session's swapchains with density images, so each map covers exactly the views
/// rendered into it (multiview arrays, double-wide images, one swapchain per eye alike). A change
/// bumps the swapchain's generation, rebuilding its maps once. Read-only on the application's
/// structs, no allocation; other layer types and chained structs are not looked at.
fn learn_submitted(s: &Session, info: In<xr::FrameEndInfo>) {
    let mut found = [(xr::Swapchain::NULL, [None; MAX_VIEWS]); MAX_VIEWS];
    for views in projection_layers(info) {
        for (eye, v) in views.iter().enumerate() {
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
        let Some(record) = registry().swapchain_for_call(*sc) else {
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

/// Corrects what the published eye swapchains hold from this frame's projection layers
/// (docs/injection.md#which-passes): a swapchain named by one view is that view's; by views in
/// several array layers, an array; by two views side by side in one layer, double-wide. Published
/// swapchains that no projection layer names (UI, quad layers) are dropped once the app submits
/// projection layers. No allocation unless something changed.
fn learn_eye_swapchains(info: In<xr::FrameEndInfo>) {
    crate::bridge::inject::with_current(|published| {
        if let Some(published) = published {
            learn_from(published, info);
        }
    });
}

/// [`learn_eye_swapchains`] against the published state.
fn learn_from(published: &crate::bridge::inject::Injection, info: In<xr::FrameEndInfo>) {
    use fovea_model::inject::Holds;
    // Per published swapchain (at most MAX_SWAPCHAINS): the views named, their layers and x.
    const N: usize = crate::bridge::inject::MAX_SWAPCHAINS;
    let mut seen = [(0u32, 0u32, u32::MAX, i32::MAX, i32::MIN); N];
    let mut first_view = [0u8; N];
    let mut any_projection = false;
    for views in projection_layers(info) {
        any_projection = true;
        for (eye, v) in views.iter().enumerate() {
            if v.ty != xr::StructureType::COMPOSITION_LAYER_PROJECTION_VIEW {
                continue;
            }
            let raw = v.sub_image.swapchain.into_raw();
            let Some(i) = published
                .swapchains
                .iter()
                .take(N)
                .position(|e| e.handle == raw)
            else {
                continue;
            };
            let s = &mut seen[i];
            if s.0 == 0 {
                first_view[i] = eye as u8;
            }
            s.0 += 1;
            let layer = v.sub_image.image_array_index;
            s.1 = s.1.max(layer + 1);
            s.2 = s.2.min(layer);
            s.3 = s.3.min(v.sub_image.image_rect.offset.x);
            s.4 = s.4.max(v.sub_image.image_rect.offset.x);
        }
    }
    if !any_projection {
        return;
    }
    for (i, e) in published.swapchains.iter().take(N).enumerate() {
        let (views, top, bottom, min_x, max_x) = seen[i];
        let holds = match views {
            0 => None,
            1 => Some(Holds::View(first_view[i])),
            _ if top > bottom + 1 || (top == bottom + 1 && bottom > 0) => Some(Holds::Layers),
            _ if max_x > min_x => Some(Holds::Halves),
            _ => Some(Holds::Layers),
        };
        match holds {
            Some(h) if h != e.shape.holds => crate::bridge::inject::set_swapchain(
                e.handle,
                fovea_model::inject::Swapchain {
                    holds: h,
                    ..e.shape
                },
                e.own,
            ),
            Some(_) => {}
            None => crate::bridge::inject::remove_swapchain(e.handle),
        }
    }
}

/// Writes the stats line for a finished window, when `fovea::stats` is enabled.
fn report(s: &Session, window: Window, period_ns: i64) {
    if !stats_logged() {
        return;
    }
    let injected = injected_pattern_at(s, s.dynamic_step.load(Ordering::Relaxed))
        .map(|(p, dynamic)| (p.level, dynamic));
    let level = registry()
        .foveated_swapchains_of(s.handle)
        .iter()
        .filter_map(|sc| Some(pattern_for(s, &sc.foveation.as_ref()?.lock())))
        .map(|(p, dynamic)| (p.level, dynamic))
        .chain(injected)
        .max();
    let passes = injected.map(|_| {
        let (eye, all) = crate::bridge::inject::take_counts();
        Line::per_frame(eye, all, window.frames)
    });
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
        injected: passes,
        gaze: gaze_shown(s),
    };
    tracing::info!(target: fovea_abi::log_target::STATS, "{line}");
}

/// The gaze for the stats line: where the gaze source put each view's fovea last.
fn gaze_shown(s: &Session) -> GazeShown {
    if !s.instance.gaze_on {
        return GazeShown::Off;
    }
    let eyes = *s.eyes.lock();
    if !eyes.follows() {
        return GazeShown::Fixed;
    }
    GazeShown::Follows {
        tracking: eyes.tracking,
        ndc: [0, 1].map(|i| eyes.of(i).unwrap_or_default()),
        views: eyes.views.min(2),
    }
}

/// `xrLocateViews`: the FOVs the application gets are recorded, since the density maps
/// of its swapchains are computed for the FOVs it renders with. No allocation: this runs every frame.
pub fn locate_views(
    sess: xr::Session,
    info: In<xr::ViewLocateInfo>,
    view_state: Out<xr::ViewState>,
    capacity: u32,
    count: Out<u32>,
    views: OutArray<xr::View>,
) -> HookResult<xr::Result> {
    let s = session_for_call(sess)?;
    let locate = next(s.instance.next.locate_views)?;
    // SAFETY: the next layer's xrLocateViews, with the application's arguments as it passed them.
    let r = unsafe {
        locate(
            sess,
            info.raw(),
            view_state.raw(),
            capacity,
            count.raw(),
            views.raw(),
        )
    };
    let r = observed(&s, r);
    if !succeeded(r) {
        return Ok(r);
    }
    let Some(n) = count.read() else {
        return Ok(r);
    };
    let Some(located) = views.into_slice(n.min(capacity) as usize) else {
        return Ok(r);
    };
    let symmetric = crate::xr::symmetric::active(&s);
    learn_stereo_views(&s.instance, symmetric, info, n, located);
    if let Some(g) = &s.gaze {
        if located.iter().all(|v| v.ty == xr::StructureType::VIEW) {
            g.app_located(located.iter().map(|v| fov_from_xr(v.fov)));
        }
    }
    if s.instance.inject.is_some() && located.iter().all(|v| v.ty == xr::StructureType::VIEW) {
        // The FOVs the application renders with (after symmetric-FOV mode's change), at most
        // MAX_VIEWS, in a fixed array: this runs every frame.
        let mut fovs = [fovea_model::maps::FALLBACK_FOV; MAX_VIEWS];
        let n = located.len().min(MAX_VIEWS);
        for (slot, v) in fovs.iter_mut().zip(located.iter()) {
            *slot = fov_from_xr(v.fov);
        }
        crate::bridge::inject::set_fovs(&fovs[..n]);
        publish_injected_centres(&s);
    }
    if s.gpu.is_some() && capacity > 0 {
        if located.iter().any(|v| v.ty != xr::StructureType::VIEW) {
            return Ok(r);
        }
        s.views
            .lock()
            .record(located.iter().map(|v| fov_from_xr(v.fov)));
    }
    Ok(r)
}

/// After a successful `xrLocateViews` of the primary stereo views: remembers the runtime's FOVs and,
/// in symmetric-FOV mode, hands the application the shared symmetric FOV instead (the output array
/// is the application's to receive; its input structs are untouched). `views` holds the located
/// views that fit the application's array (`min(count, capacity)`).
fn learn_stereo_views(
    instance: &Instance,
    symmetric: bool,
    info: In<xr::ViewLocateInfo>,
    count: u32,
    views: &mut [xr::View],
) {
    let stereo = info
        .get()
        .is_some_and(|i| i.view_configuration_type == xr::ViewConfigurationType::PRIMARY_STEREO);
    if !stereo || count != 2 || views.len() != 2 {
        return;
    }
    if views.iter().any(|v| v.ty != xr::StructureType::VIEW) {
        return;
    }
    let fovs = [0, 1].map(|i| fov_from_xr(views[i].fov));
    instance.stereo_fovs.set(fovs);
    if symmetric {
        for (v, f) in views.iter_mut().zip(instance.render_fovs(fovs)) {
            v.fov = fov_to_xr(f);
        }
    }
}
