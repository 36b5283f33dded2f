//! The frame loop against a simulated, deterministic display clock (spec chapter "Frame
//! Submission": xrWaitFrame, xrBeginFrame, xrEndFrame).
//!
//! Time is virtual. Frame `n` (counted by xrWaitFrame) is predicted for one display period after
//! frame `n − 1`, unless frame `n − 1`'s simulated GPU time exceeded the period: then, as with a
//! compositor that misses vsync, the prediction skips whole periods: `ceil(gpu / period)` periods
//! in all. With `realtime`, xrWaitFrame additionally sleeps until one period before the predicted
//! display time, measured from the first wait.

use std::fmt::Write;
use std::time::{Duration, Instant};

use openxr_sys as xr;
use openxr_sys::Handle;

use crate::ffi::{self, check_pose};
use crate::objects::SubmittedView;
use crate::session::{request_exit, set_state};
use crate::state::{entry, notify_frame_begun, wait_frame_begun, world, World, XrResult};
use crate::system::{MAX_LAYER_COUNT, VIEW_COUNT};

/// Whole display periods a frame of `gpu_ms` occupies (at least one).
pub(crate) fn periods_for(gpu_ms: f32, period_ns: i64) -> i64 {
    let gpu_ns = (f64::from(gpu_ms) * 1e6).round() as i64;
    ((gpu_ns + period_ns - 1) / period_ns).max(1)
}

fn running(w: &World, session: u64) -> Result<(), xr::Result> {
    if w.sessions[&session].running {
        Ok(())
    } else {
        Err(xr::Result::ERROR_SESSION_NOT_RUNNING)
    }
}

pub(crate) unsafe extern "system" fn wait_frame(
    session: xr::Session,
    wait_info: *const xr::FrameWaitInfo,
    frame_state: *mut xr::FrameState,
) -> xr::Result {
    let mut sleep_until = None;
    let result = entry("xrWaitFrame", |ctx| {
        let mut w = world();
        let id = w.enter_session(ctx, session)?;
        // frameWaitInfo is optional (may be NULL) but must be valid when given.
        if !wait_info.is_null() {
            ctx.next_types =
                ffi::chain_types(ffi::input(wait_info, xr::StructureType::FRAME_WAIT_INFO)?.next);
        }
        let frame_state = ffi::output(frame_state, xr::StructureType::FRAME_STATE)?;
        running(&w, id)?;
        // Spec (xrWaitFrame): "Subsequent xrWaitFrame calls must block until the previous frame
        // has been begun with xrBeginFrame". Pipelining applications (the CTS's
        // Timed_Pipelined_Frame_Submission) wait frame N+1 on one thread while another begins
        // frame N; without the block the second wait's frame replaced the first and the later
        // xrBeginFrame found no waited frame. A caller that could never unblock (one thread,
        // waiting twice) is refused after the configured `wait_block_ms` instead of hanging
        // forever.
        let limit = w.instances[&w.sessions[&id].instance].config.wait_block_ms;
        let deadline = Instant::now() + Duration::from_millis(limit);
        while w.sessions[&id].frame.pending_wait.is_some() {
            if !wait_frame_begun(&mut w, deadline) {
                ctx.detail = "the previous waited frame was never begun".into();
                return Err(xr::Result::ERROR_CALL_ORDER_INVALID);
            }
            // The session may have been destroyed or ended while the lock was released.
            if !w.sessions.contains_key(&id) {
                return Err(xr::Result::ERROR_HANDLE_INVALID);
            }
            running(&w, id)?;
        }
        let World {
            sessions,
            instances,
            ..
        } = &mut *w;
        let s = sessions.get_mut(&id).expect("entered session exists");
        let inst = instances
            .get_mut(&s.instance)
            .expect("session's instance exists");
        let period = inst.config.period_ns();
        let n = s.frame.waits;
        let (display, skipped) = match s.frame.last_display_ns {
            None => (inst.now_ns + period, 0),
            Some(prev) => {
                let k = periods_for(inst.config.load.gpu_ms_at(n - 1), period);
                (prev + k * period, k - 1)
            }
        };
        inst.now_ns = inst.now_ns.max(display - period);
        s.frame.waits += 1;
        s.frame.last_display_ns = Some(display);
        s.frame.pending_wait = Some(display);
        if inst.config.realtime {
            let (origin, origin_ns) = *s
                .frame
                .realtime_origin
                .get_or_insert((Instant::now(), display - period));
            let offset = u64::try_from(display - period - origin_ns).unwrap_or(0);
            sleep_until = Some(origin + Duration::from_nanos(offset));
        }
        if s.state == xr::SessionState::READY {
            set_state(&mut w, id, xr::SessionState::SYNCHRONIZED);
        }
        let state = w.sessions[&id].state;
        let should_render = matches!(state, xr::SessionState::VISIBLE | xr::SessionState::FOCUSED);
        (*frame_state).predicted_display_time = xr::Time::from_nanos(display);
        (*frame_state).predicted_display_period = xr::Duration::from_nanos(period);
        (*frame_state).should_render = should_render.into();
        ctx.detail = format!("frame={n} display={display} period={period} skipped={skipped} should_render={should_render}");
        Ok(xr::Result::SUCCESS)
    });
    // Sleep with the lock released: other threads' instances keep running.
    if let Some(deadline) = sleep_until {
        std::thread::sleep(deadline.saturating_duration_since(Instant::now()));
    }
    result
}

pub(crate) unsafe extern "system" fn begin_frame(
    session: xr::Session,
    begin_info: *const xr::FrameBeginInfo,
) -> xr::Result {
    entry("xrBeginFrame", |ctx| {
        let mut w = world();
        let id = w.enter_session(ctx, session)?;
        if !begin_info.is_null() {
            ctx.next_types =
                ffi::chain_types(ffi::input(begin_info, xr::StructureType::FRAME_BEGIN_INFO)?.next);
        }
        running(&w, id)?;
        let frame = &mut w
            .sessions
            .get_mut(&id)
            .expect("entered session exists")
            .frame;
        // Spec: xrBeginFrame without a preceding xrWaitFrame is a call-order error.
        let display = frame
            .pending_wait
            .take()
            .ok_or(xr::Result::ERROR_CALL_ORDER_INVALID)?;
        notify_frame_begun();
        // Spec: beginning a frame while another one is begun discards the earlier one.
        let result = if frame.begun.is_some() {
            xr::Result::FRAME_DISCARDED
        } else {
            xr::Result::SUCCESS
        };
        frame.begun = Some(display);
        ctx.detail = format!("display={display}");
        Ok(result)
    })
}

/// A validated sub-image of a composition layer.
unsafe fn check_sub_image(
    w: &World,
    session: u64,
    sub: &xr::SwapchainSubImage,
) -> Result<(), xr::Result> {
    let sc = w
        .swapchains
        .get(&sub.swapchain.into_raw())
        .ok_or(xr::Result::ERROR_HANDLE_INVALID)?;
    if sc.session != session {
        return Err(xr::Result::ERROR_HANDLE_INVALID);
    }
    // Spec: the swapchain must have had an image released before it is used in a layer.
    if !sc.ever_released {
        return Err(xr::Result::ERROR_LAYER_INVALID);
    }
    let r = sub.image_rect;
    let inside = r.offset.x >= 0
        && r.offset.y >= 0
        && r.extent.width > 0
        && r.extent.height > 0
        && i64::from(r.offset.x) + i64::from(r.extent.width) <= i64::from(sc.width)
        && i64::from(r.offset.y) + i64::from(r.extent.height) <= i64::from(sc.height);
    if !inside {
        return Err(xr::Result::ERROR_SWAPCHAIN_RECT_INVALID);
    }
    if sub.image_array_index >= sc.array_size {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    Ok(())
}

fn check_space(w: &World, session: u64, space: xr::Space) -> Result<(), xr::Result> {
    match w.spaces.get(&space.into_raw()) {
        Some(s) if s.session == session => Ok(()),
        _ => Err(xr::Result::ERROR_HANDLE_INVALID),
    }
}

/// Validates the frame's layers and collects what was submitted.
unsafe fn read_layers(
    w: &World,
    session: u64,
    info: &xr::FrameEndInfo,
    detail: &mut String,
) -> Result<Vec<SubmittedView>, xr::Result> {
    if info.layer_count > MAX_LAYER_COUNT {
        return Err(xr::Result::ERROR_LAYER_LIMIT_EXCEEDED);
    }
    if info.layer_count > 0 {
        ffi::non_null(info.layers)?;
    }
    let mut views = Vec::new();
    for i in 0..info.layer_count as usize {
        let layer = *info.layers.add(i);
        if layer.is_null() {
            return Err(xr::Result::ERROR_LAYER_INVALID);
        }
        check_space(w, session, (*layer).space)?;
        match (*layer).ty {
            xr::StructureType::COMPOSITION_LAYER_PROJECTION => {
                let proj = &*(layer as *const xr::CompositionLayerProjection);
                if proj.view_count as usize != VIEW_COUNT {
                    return Err(xr::Result::ERROR_VALIDATION_FAILURE);
                }
                ffi::non_null(proj.views)?;
                let _ = write!(detail, " layer{i}=PROJECTION[");
                for v in 0..VIEW_COUNT {
                    let view = ffi::input(
                        proj.views.add(v),
                        xr::StructureType::COMPOSITION_LAYER_PROJECTION_VIEW,
                    )?;
                    check_sub_image(w, session, &view.sub_image)?;
                    // Spec (xrEndFrame): a layer or projection view pose whose orientation is not
                    // unit length within 1% is XR_ERROR_POSE_INVALID.
                    check_pose(&view.pose)?;
                    let sub = view.sub_image;
                    let (o, e) = (sub.image_rect.offset, sub.image_rect.extent);
                    let f = view.fov;
                    let _ = write!(
                        detail,
                        "{{swapchain={:#x} rect=({},{} {}x{}) index={} fov=({:.6},{:.6},{:.6},{:.6}) next={:?}}}",
                        sub.swapchain.into_raw(),
                        o.x,
                        o.y,
                        e.width,
                        e.height,
                        sub.image_array_index,
                        f.angle_left,
                        f.angle_right,
                        f.angle_up,
                        f.angle_down,
                        ffi::chain_types(view.next),
                    );
                    views.push(SubmittedView {
                        layer: i,
                        swapchain: sub.swapchain.into_raw(),
                        image_rect: sub.image_rect,
                        image_array_index: sub.image_array_index,
                        fov: view.fov,
                    });
                }
                detail.push(']');
            }
            xr::StructureType::COMPOSITION_LAYER_QUAD => {
                let quad = &*(layer as *const xr::CompositionLayerQuad);
                check_sub_image(w, session, &quad.sub_image)?;
                check_pose(&quad.pose)?;
                let _ = write!(
                    detail,
                    " layer{i}=QUAD[swapchain={:#x}]",
                    quad.sub_image.swapchain.into_raw()
                );
            }
            // Layer types of extensions this runtime does not offer.
            _ => return Err(xr::Result::ERROR_LAYER_INVALID),
        }
    }
    Ok(views)
}

pub(crate) unsafe extern "system" fn end_frame(
    session: xr::Session,
    end_info: *const xr::FrameEndInfo,
) -> xr::Result {
    entry("xrEndFrame", |ctx| end_frame_impl(ctx, session, end_info))
}

unsafe fn end_frame_impl(
    ctx: &mut crate::state::Ctx,
    session: xr::Session,
    end_info: *const xr::FrameEndInfo,
) -> XrResult {
    let mut w = world();
    let id = w.enter_session(ctx, session)?;
    let info = ffi::input(end_info, xr::StructureType::FRAME_END_INFO)?;
    ctx.next_types = ffi::chain_types(info.next);
    running(&w, id)?;
    let begun = w.sessions[&id]
        .frame
        .begun
        .ok_or(xr::Result::ERROR_CALL_ORDER_INVALID)?;
    if info.display_time.as_nanos() <= 0 {
        return Err(xr::Result::ERROR_TIME_INVALID);
    }
    if info.environment_blend_mode != xr::EnvironmentBlendMode::OPAQUE {
        return Err(xr::Result::ERROR_ENVIRONMENT_BLEND_MODE_UNSUPPORTED);
    }
    let mut detail = format!("display={} predicted={begun}", info.display_time.as_nanos());
    let views = read_layers(&w, id, info, &mut detail)?;
    ctx.detail = detail;
    let s = w.sessions.get_mut(&id).expect("entered session exists");
    s.frame.begun = None;
    s.frame.ends += 1;
    let ends = s.frame.ends;
    let instance = s.instance;
    let state = s.state;
    let inst = w
        .instances
        .get_mut(&instance)
        .expect("session's instance exists");
    inst.frames += 1;
    if inst.config.journal {
        inst.record.end_frames.push(views);
    }
    let exit_after = inst.config.exit_after_frames;
    match (state, ends) {
        (xr::SessionState::SYNCHRONIZED, _) => set_state(&mut w, id, xr::SessionState::VISIBLE),
        (xr::SessionState::VISIBLE, 2..) => set_state(&mut w, id, xr::SessionState::FOCUSED),
        _ => {}
    }
    if exit_after.is_some_and(|n| ends >= n) {
        request_exit(&mut w, id);
    }
    Ok(xr::Result::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missed_vsync_skips_whole_periods() {
        let p = 11_111_111;
        assert_eq!(periods_for(0.0, p), 1);
        assert_eq!(periods_for(11.1, p), 1);
        assert_eq!(periods_for(11.2, p), 2);
        assert_eq!(periods_for(22.3, p), 3);
    }
}
