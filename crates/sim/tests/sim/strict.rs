//! The simulated runtime refuses what real runtimes (Monado) refuse where the spec allows them to:
//! one test per rule, each driving the runtime through its xrGetInstanceProcAddr and checking both
//! the XrResult and that the refusal is counted (`control::refusals`), so that a test running a
//! layer over the runtime can assert that no refused call reached it.
//!
//! Return codes are those the spec lists for each command
//! (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#xrLocateViews,
//! #xrWaitFrame, #xrBeginFrame, #xrEndFrame, #xrAcquireSwapchainImage, #xrWaitSwapchainImage,
//! #xrReleaseSwapchainImage, #xrBeginSession, #xrEndSession).

use std::ptr::{null, null_mut};

use crate::common::*;
use fovea_sim::control::{self, Fault};
use openxr_sys as xr;

fn locate(
    instance: xr::Instance,
    session: xr::Session,
    space: xr::Space,
    ty: xr::ViewConfigurationType,
) -> xr::Result {
    let locate = xrfn!(instance, LocateViews);
    let info = xr::ViewLocateInfo {
        ty: xr::ViewLocateInfo::TYPE,
        next: null(),
        view_configuration_type: ty,
        display_time: xr::Time::from_nanos(1_000_000_000_000),
        space,
    };
    let mut state = xr::ViewState {
        ty: xr::ViewState::TYPE,
        next: null_mut(),
        view_state_flags: xr::ViewStateFlags::EMPTY,
    };
    let blank = xr::View {
        ty: xr::View::TYPE,
        next: null_mut(),
        pose: Default::default(),
        fov: Default::default(),
    };
    let mut views = [blank; 2];
    let mut count = 0;
    unsafe {
        locate(
            session,
            &info,
            &mut state,
            2,
            &mut count,
            views.as_mut_ptr(),
        )
    }
}

const STEREO: xr::ViewConfigurationType = xr::ViewConfigurationType::PRIMARY_STEREO;

/// A headless session created but not begun (READY).
fn ready() -> (xr::Instance, xr::Session) {
    let instance = create_instance(config("quest3"), &["XR_MND_headless"]);
    let session = create_session_with(instance, null()).unwrap();
    (instance, session)
}

/// Drives a running session through exit to STOPPING and ends it (IDLE, EXITING).
fn end_running_session(instance: xr::Instance, session: xr::Session) {
    assert_eq!(
        unsafe { xrfn!(instance, RequestExitSession)(session) },
        xr::Result::SUCCESS
    );
    assert_eq!(
        unsafe { xrfn!(instance, EndSession)(session) },
        xr::Result::SUCCESS
    );
}

/// The refusals counted for `instance`, by command.
fn refusals(instance: xr::Instance) -> Vec<(&'static str, u64)> {
    control::refusals(instance)
}

#[test]
fn locate_views_is_refused_outside_a_running_session() {
    let (instance, session) = ready();
    let local = reference_space(instance, session, xr::ReferenceSpaceType::LOCAL);
    // After xrCreateSession, before xrBeginSession: what apps do while sizing swapchains.
    assert_eq!(
        locate(instance, session, local, STEREO),
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    assert_eq!(begin_session(instance, session), xr::Result::SUCCESS);
    assert_eq!(
        locate(instance, session, local, STEREO),
        xr::Result::SUCCESS
    );
    end_running_session(instance, session);
    // After xrEndSession the views are gone again.
    assert_eq!(
        locate(instance, session, local, STEREO),
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    assert_eq!(refusals(instance), [("xrLocateViews", 2)]);
    let journal = control::journal(instance);
    let refused: Vec<_> = journal.iter().filter(|c| c.refused).collect();
    assert_eq!(refused.len(), 2);
    assert!(
        refused[0].detail.contains("not running"),
        "{}",
        refused[0].detail
    );
    destroy_instance(instance);
}

#[test]
fn locate_views_is_refused_for_another_view_configuration_than_the_sessions() {
    let (instance, session) = headless(config("quest3"));
    let local = reference_space(instance, session, xr::ReferenceSpaceType::LOCAL);
    for other in [
        xr::ViewConfigurationType::PRIMARY_MONO,
        xr::ViewConfigurationType::PRIMARY_QUAD_VARJO,
    ] {
        assert_eq!(
            locate(instance, session, local, other),
            xr::Result::ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED,
            "{other:?}"
        );
    }
    assert_eq!(
        locate(instance, session, local, STEREO),
        xr::Result::SUCCESS
    );
    assert_eq!(refusals(instance), [("xrLocateViews", 2)]);
    destroy_instance(instance);
}

#[test]
fn begin_frame_without_a_waited_frame_is_call_order_invalid() {
    let (instance, session) = headless(config("quest3"));
    assert_eq!(
        begin_frame(instance, session),
        xr::Result::ERROR_CALL_ORDER_INVALID
    );
    // One wait allows one begin, not two.
    let state = wait_frame(instance, session).unwrap();
    assert_eq!(begin_frame(instance, session), xr::Result::SUCCESS);
    assert_eq!(
        end_frame(instance, session, state.predicted_display_time, &[]),
        xr::Result::SUCCESS
    );
    assert_eq!(
        begin_frame(instance, session),
        xr::Result::ERROR_CALL_ORDER_INVALID
    );
    assert_eq!(refusals(instance), [("xrBeginFrame", 2)]);
    destroy_instance(instance);
}

#[test]
fn end_frame_without_a_begun_frame_is_call_order_invalid() {
    let (instance, session) = headless(config("quest3"));
    let t = xr::Time::from_nanos(1_000_000_000_000);
    assert_eq!(
        end_frame(instance, session, t, &[]),
        xr::Result::ERROR_CALL_ORDER_INVALID
    );
    // A waited frame that was not begun cannot be ended either.
    let state = wait_frame(instance, session).unwrap();
    assert_eq!(
        end_frame(instance, session, state.predicted_display_time, &[]),
        xr::Result::ERROR_CALL_ORDER_INVALID
    );
    assert_eq!(refusals(instance), [("xrEndFrame", 2)]);
    destroy_instance(instance);
}

#[test]
fn frame_calls_outside_a_running_session_are_session_not_running() {
    let (instance, session) = ready();
    let t = xr::Time::from_nanos(1_000_000_000_000);
    let check = |when: &str| {
        assert_eq!(
            wait_frame(instance, session).err(),
            Some(xr::Result::ERROR_SESSION_NOT_RUNNING),
            "{when}"
        );
        assert_eq!(
            begin_frame(instance, session),
            xr::Result::ERROR_SESSION_NOT_RUNNING,
            "{when}"
        );
        assert_eq!(
            end_frame(instance, session, t, &[]),
            xr::Result::ERROR_SESSION_NOT_RUNNING,
            "{when}"
        );
    };
    check("before xrBeginSession");
    assert_eq!(begin_session(instance, session), xr::Result::SUCCESS);
    empty_frame(instance, session);
    end_running_session(instance, session);
    check("after xrEndSession");
    assert_eq!(
        refusals(instance),
        [("xrBeginFrame", 2), ("xrEndFrame", 2), ("xrWaitFrame", 2)]
    );
    destroy_instance(instance);
}

fn wait_info() -> xr::SwapchainImageWaitInfo {
    xr::SwapchainImageWaitInfo {
        ty: xr::SwapchainImageWaitInfo::TYPE,
        next: null(),
        timeout: xr::Duration::INFINITE,
    }
}

const RGBA8_SRGB: i64 = 43;

#[test]
fn wait_swapchain_image_without_an_acquired_image_is_call_order_invalid() {
    let (instance, session) = headless(config("quest3"));
    let sc = create_swapchain(instance, session, &swapchain_info(RGBA8_SRGB, 64, 64, 1)).unwrap();
    let wait = xrfn!(instance, WaitSwapchainImage);
    let acquire = xrfn!(instance, AcquireSwapchainImage);
    let mut index = 0;
    unsafe {
        assert_eq!(wait(sc, &wait_info()), xr::Result::ERROR_CALL_ORDER_INVALID);
        assert_eq!(acquire(sc, null(), &mut index), xr::Result::SUCCESS);
        assert_eq!(wait(sc, &wait_info()), xr::Result::SUCCESS);
        // The one acquired image is already waited.
        assert_eq!(wait(sc, &wait_info()), xr::Result::ERROR_CALL_ORDER_INVALID);
    }
    assert_eq!(refusals(instance), [("xrWaitSwapchainImage", 2)]);
    destroy_instance(instance);
}

#[test]
fn release_swapchain_image_without_a_waited_image_is_call_order_invalid() {
    let (instance, session) = headless(config("quest3"));
    let sc = create_swapchain(instance, session, &swapchain_info(RGBA8_SRGB, 64, 64, 1)).unwrap();
    let release = xrfn!(instance, ReleaseSwapchainImage);
    let acquire = xrfn!(instance, AcquireSwapchainImage);
    let mut index = 0;
    unsafe {
        assert_eq!(release(sc, null()), xr::Result::ERROR_CALL_ORDER_INVALID);
        // Acquired but not waited.
        assert_eq!(acquire(sc, null(), &mut index), xr::Result::SUCCESS);
        assert_eq!(release(sc, null()), xr::Result::ERROR_CALL_ORDER_INVALID);
    }
    assert_eq!(refusals(instance), [("xrReleaseSwapchainImage", 2)]);
    destroy_instance(instance);
}

#[test]
fn acquiring_more_images_than_the_swapchain_has_is_call_order_invalid() {
    let (instance, session) = headless(config("quest3"));
    let sc = create_swapchain(instance, session, &swapchain_info(RGBA8_SRGB, 64, 64, 1)).unwrap();
    let images = xrfn!(instance, EnumerateSwapchainImages);
    let mut count = 0;
    assert_eq!(
        unsafe { images(sc, 0, &mut count, null_mut()) },
        xr::Result::SUCCESS
    );
    let acquire = xrfn!(instance, AcquireSwapchainImage);
    let mut index = 0;
    for _ in 0..count {
        assert_eq!(
            unsafe { acquire(sc, null(), &mut index) },
            xr::Result::SUCCESS
        );
    }
    assert_eq!(
        unsafe { acquire(sc, null(), &mut index) },
        xr::Result::ERROR_CALL_ORDER_INVALID
    );
    // A static swapchain's one image can be acquired once, ever.
    let mut info = swapchain_info(RGBA8_SRGB, 64, 64, 1);
    info.create_flags = xr::SwapchainCreateFlags::STATIC_IMAGE;
    let fixed = create_swapchain(instance, session, &info).unwrap();
    assert_eq!(cycle_image(instance, fixed), 0);
    assert_eq!(
        unsafe { acquire(fixed, null(), &mut index) },
        xr::Result::ERROR_CALL_ORDER_INVALID
    );
    assert_eq!(refusals(instance), [("xrAcquireSwapchainImage", 2)]);
    destroy_instance(instance);
}

#[test]
fn end_frame_with_a_swapchain_never_released_is_layer_invalid() {
    let (instance, session) = headless(config("quest3"));
    let space = reference_space(instance, session, xr::ReferenceSpaceType::LOCAL);
    let sc = create_swapchain(instance, session, &swapchain_info(RGBA8_SRGB, 64, 64, 2)).unwrap();
    let view = |i: u32| xr::CompositionLayerProjectionView {
        ty: xr::CompositionLayerProjectionView::TYPE,
        next: null(),
        pose: xr::Posef::IDENTITY,
        fov: Default::default(),
        sub_image: xr::SwapchainSubImage {
            swapchain: sc,
            image_rect: xr::Rect2Di {
                offset: xr::Offset2Di { x: 0, y: 0 },
                extent: xr::Extent2Di {
                    width: 64,
                    height: 64,
                },
            },
            image_array_index: i,
        },
    };
    let views = [view(0), view(1)];
    let layer = xr::CompositionLayerProjection {
        ty: xr::CompositionLayerProjection::TYPE,
        next: null(),
        layer_flags: xr::CompositionLayerFlags::EMPTY,
        space,
        view_count: 2,
        views: views.as_ptr(),
    };
    let layers = [&layer as *const _ as *const xr::CompositionLayerBaseHeader];
    let state = wait_frame(instance, session).unwrap();
    assert_eq!(begin_frame(instance, session), xr::Result::SUCCESS);
    let t = state.predicted_display_time;
    assert_eq!(
        end_frame(instance, session, t, &layers),
        xr::Result::ERROR_LAYER_INVALID
    );
    // The refusal changed nothing: once an image is released the same frame ends.
    cycle_image(instance, sc);
    assert_eq!(
        end_frame(instance, session, t, &layers),
        xr::Result::SUCCESS
    );
    assert_eq!(refusals(instance), [("xrEndFrame", 1)]);
    destroy_instance(instance);
}

#[test]
fn begin_session_with_an_unsupported_view_configuration_is_refused() {
    let (instance, session) = ready();
    let begin = xrfn!(instance, BeginSession);
    for ty in [
        xr::ViewConfigurationType::PRIMARY_MONO,
        xr::ViewConfigurationType::from_raw(0x7fff_0000),
    ] {
        let info = xr::SessionBeginInfo {
            ty: xr::SessionBeginInfo::TYPE,
            next: null(),
            primary_view_configuration_type: ty,
        };
        assert_eq!(
            unsafe { begin(session, &info) },
            xr::Result::ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED,
            "{ty:?}"
        );
    }
    // Nothing started: the session still begins with the supported one.
    assert_eq!(begin_session(instance, session), xr::Result::SUCCESS);
    assert_eq!(refusals(instance), [("xrBeginSession", 2)]);
    destroy_instance(instance);
}

#[test]
fn begin_session_when_not_ready_is_session_not_ready() {
    let (instance, session) = headless(config("quest3"));
    assert_eq!(
        begin_session(instance, session),
        xr::Result::ERROR_SESSION_RUNNING
    );
    end_running_session(instance, session);
    // IDLE then EXITING: the runtime will not make this session READY again.
    assert_eq!(
        begin_session(instance, session),
        xr::Result::ERROR_SESSION_NOT_READY
    );
    assert_eq!(refusals(instance), [("xrBeginSession", 2)]);
    destroy_instance(instance);
}

#[test]
fn end_session_when_not_stopping_is_session_not_stopping() {
    let (instance, session) = ready();
    let end = xrfn!(instance, EndSession);
    assert_eq!(
        unsafe { end(session) },
        xr::Result::ERROR_SESSION_NOT_RUNNING
    );
    assert_eq!(begin_session(instance, session), xr::Result::SUCCESS);
    empty_frame(instance, session);
    // Running and VISIBLE, no exit requested.
    assert_eq!(
        unsafe { end(session) },
        xr::Result::ERROR_SESSION_NOT_STOPPING
    );
    end_running_session(instance, session);
    assert_eq!(refusals(instance), [("xrEndSession", 2)]);
    destroy_instance(instance);
}

#[test]
fn injected_faults_are_errors_but_not_refusals() {
    let (instance, session) = headless(config("quest3"));
    control::inject_fault(
        instance,
        Fault {
            function: "xrWaitFrame".into(),
            result: xr::Result::ERROR_RUNTIME_FAILURE,
            nth: 1,
        },
    );
    assert_eq!(
        wait_frame(instance, session).err(),
        Some(xr::Result::ERROR_RUNTIME_FAILURE)
    );
    assert_eq!(
        begin_frame(instance, session),
        xr::Result::ERROR_CALL_ORDER_INVALID
    );
    destroy_instance(instance);
    // Both survive the instance, as the journal does.
    assert_eq!(
        control::errors(instance),
        [("xrBeginFrame", 1), ("xrWaitFrame", 1)]
    );
    assert_eq!(refusals(instance), [("xrBeginFrame", 1)]);
    let journal = control::journal(instance);
    let flags: Vec<_> = journal
        .iter()
        .filter(|c| c.result.into_raw() < 0)
        .map(|c| (c.function, c.refused))
        .collect();
    assert_eq!(flags, [("xrWaitFrame", false), ("xrBeginFrame", true)]);
}
