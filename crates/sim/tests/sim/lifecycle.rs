//! The simulated runtime driven directly through its xrGetInstanceProcAddr (no layer, no loader).

use std::ffi::{c_char, CStr, CString};
use std::ptr::{null, null_mut};

use crate::common::*;
use fovea_sim::control::{self, Fault, Load};
use openxr_sys as xr;
use openxr_sys::Handle;

fn lookup(instance: xr::Instance, name: &str) -> (xr::Result, bool) {
    let c = CString::new(name).unwrap();
    let mut f = None;
    let r = unsafe { fovea_sim::get_instance_proc_addr(instance, c.as_ptr(), &mut f) };
    (r, f.is_some())
}

#[test]
fn get_instance_proc_addr_follows_the_spec_table() {
    let null = xr::Instance::NULL;
    for global in [
        "xrEnumerateInstanceExtensionProperties",
        "xrEnumerateApiLayerProperties",
        "xrCreateInstance",
    ] {
        assert_eq!(
            lookup(null, global),
            (xr::Result::SUCCESS, true),
            "{global}"
        );
    }
    for other in [
        "xrDestroyInstance",
        "xrInitializeLoaderKHR",
        "xrGetInstanceProcAddr",
        "xrNope",
    ] {
        assert_eq!(
            lookup(null, other),
            (xr::Result::ERROR_HANDLE_INVALID, false),
            "{other}"
        );
    }
    let instance = create_instance(config("quest3"), &["XR_KHR_vulkan_enable2"]);
    assert_eq!(
        lookup(instance, "xrCreateSession"),
        (xr::Result::SUCCESS, true)
    );
    assert_eq!(
        lookup(instance, "xrCreateVulkanDeviceKHR"),
        (xr::Result::SUCCESS, true)
    );
    // Extensions that are not enabled, or not offered, and unknown names.
    for name in [
        "xrGetVulkanGraphicsDeviceKHR",
        "xrUpdateSwapchainFB",
        "xrCreateFoveationProfileFB",
        "xrFoo",
    ] {
        assert_eq!(
            lookup(instance, name),
            (xr::Result::ERROR_FUNCTION_UNSUPPORTED, false),
            "{name}"
        );
    }
    assert!(fovea_sim::command_names().any(|n| n == "xrLocateViews"));
    destroy_instance(instance);
}

fn extension_names() -> Vec<(String, u32)> {
    let enumerate = xrfn!(xr::Instance::NULL, EnumerateInstanceExtensionProperties);
    let mut count = 0;
    assert_eq!(
        unsafe { enumerate(null(), 0, &mut count, null_mut()) },
        xr::Result::SUCCESS
    );
    let blank = xr::ExtensionProperties {
        ty: xr::ExtensionProperties::TYPE,
        next: null_mut(),
        extension_name: [0; xr::MAX_EXTENSION_NAME_SIZE],
        extension_version: 0,
    };
    let mut props = vec![blank; count as usize];
    if count > 1 {
        let mut short = 0;
        let r = unsafe { enumerate(null(), 1, &mut short, props.as_mut_ptr()) };
        assert_eq!((r, short), (xr::Result::ERROR_SIZE_INSUFFICIENT, count));
    }
    assert_eq!(
        unsafe { enumerate(null(), count, &mut count, props.as_mut_ptr()) },
        xr::Result::SUCCESS
    );
    props
        .iter()
        .map(|p| {
            (
                unsafe { CStr::from_ptr(p.extension_name.as_ptr()) }
                    .to_str()
                    .unwrap()
                    .to_string(),
                p.extension_version,
            )
        })
        .collect()
}

#[test]
fn extensions_depend_on_the_configuration() {
    control::set_thread_config(Some(config("quest3")));
    let plain = extension_names();
    assert_eq!(
        plain,
        [
            ("XR_KHR_vulkan_enable".to_string(), 8),
            ("XR_KHR_vulkan_enable2".to_string(), 2),
            ("XR_MND_headless".to_string(), 2)
        ]
    );
    let mut cfg = config("quest3");
    cfg.native_swapchain_update_state = true;
    control::set_thread_config(Some(cfg.clone()));
    assert!(extension_names().contains(&("XR_FB_swapchain_update_state".to_string(), 3)));

    // Not offered → XR_ERROR_EXTENSION_NOT_PRESENT; no foveation extension ever.
    let r = try_create_instance(
        config("quest3"),
        &["XR_FB_swapchain_update_state"],
        xr::Version::new(1, 0, 0),
    );
    assert_eq!(r, Err(xr::Result::ERROR_EXTENSION_NOT_PRESENT));
    let r = try_create_instance(cfg.clone(), &["XR_FB_foveation"], xr::Version::new(1, 0, 0));
    assert_eq!(r, Err(xr::Result::ERROR_EXTENSION_NOT_PRESENT));
    let r = try_create_instance(cfg.clone(), &[], xr::Version::new(2, 0, 0));
    assert_eq!(r, Err(xr::Result::ERROR_API_VERSION_UNSUPPORTED));
    let v11 = try_create_instance(cfg.clone(), &[], xr::Version::new(1, 1, 40)).unwrap();
    destroy_instance(v11);

    // With the switch on, the pass-through target exists and accepts no state of its own.
    let (instance, session) =
        headless_with(cfg, &["XR_MND_headless", "XR_FB_swapchain_update_state"]);
    assert_eq!(
        control::enabled_extensions(instance),
        ["XR_MND_headless", "XR_FB_swapchain_update_state"]
    );
    let sc = create_swapchain(instance, session, &swapchain_info(43, 64, 64, 1)).unwrap();
    let update = xrfn!(instance, UpdateSwapchainFB);
    let get = xrfn!(instance, GetSwapchainStateFB);
    let mut state = xr::SwapchainStateFoveationFB {
        ty: xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB,
        next: null_mut(),
        flags: xr::SwapchainStateFoveationFlagsFB::EMPTY,
        profile: xr::FoveationProfileFB::NULL,
    };
    let base = &mut state as *mut _ as *mut xr::SwapchainStateBaseHeaderFB;
    assert_eq!(
        unsafe { update(sc, base) },
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    assert_eq!(
        unsafe { get(sc, base) },
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    let journal = control::journal(instance);
    let last = &journal[journal.len() - 2..];
    assert_eq!(last[0].function, "xrUpdateSwapchainFB");
    assert_eq!(last[1].function, "xrGetSwapchainStateFB");
    assert!(
        last[0].detail.contains("SWAPCHAIN_STATE_FOVEATION_FB"),
        "{}",
        last[0].detail
    );
    destroy_instance(instance);
}

fn headless_with(cfg: control::SimConfig, extensions: &[&str]) -> (xr::Instance, xr::Session) {
    let instance = create_instance(cfg, extensions);
    let session = create_session_with(instance, null()).unwrap();
    (instance, session)
}

#[test]
fn instance_properties_and_strings() {
    let instance = create_instance(config("quest3"), &[]);
    let props_fn = xrfn!(instance, GetInstanceProperties);
    let mut props = xr::InstanceProperties {
        ty: xr::InstanceProperties::TYPE,
        next: null_mut(),
        runtime_version: xr::Version::new(0, 0, 0),
        runtime_name: [0; xr::MAX_RUNTIME_NAME_SIZE],
    };
    assert_eq!(
        unsafe { props_fn(instance, &mut props) },
        xr::Result::SUCCESS
    );
    assert_eq!(
        unsafe { CStr::from_ptr(props.runtime_name.as_ptr()) }
            .to_str()
            .unwrap(),
        "fovea simulated headset"
    );
    props.ty = xr::StructureType::SYSTEM_PROPERTIES;
    assert_eq!(
        unsafe { props_fn(instance, &mut props) },
        xr::Result::ERROR_VALIDATION_FAILURE
    );

    let result_to_string = xrfn!(instance, ResultToString);
    let type_to_string = xrfn!(instance, StructureTypeToString);
    let mut buf = [0 as c_char; 64];
    let text = |buf: &[c_char]| {
        unsafe { CStr::from_ptr(buf.as_ptr()) }
            .to_str()
            .unwrap()
            .to_string()
    };
    unsafe { result_to_string(instance, xr::Result::ERROR_SESSION_LOST, buf.as_mut_ptr()) };
    assert_eq!(text(&buf), "XR_ERROR_SESSION_LOST");
    unsafe { result_to_string(instance, xr::Result::from_raw(-999_999), buf.as_mut_ptr()) };
    assert_eq!(text(&buf), "XR_UNKNOWN_FAILURE_-999999");
    unsafe {
        type_to_string(
            instance,
            xr::StructureType::SWAPCHAIN_CREATE_INFO,
            buf.as_mut_ptr(),
        )
    };
    assert_eq!(text(&buf), "XR_TYPE_SWAPCHAIN_CREATE_INFO");

    let to_path = xrfn!(instance, StringToPath);
    let path_to_string = xrfn!(instance, PathToString);
    let s = CString::new("/user/hand/left").unwrap();
    let mut path = xr::Path::NULL;
    assert_eq!(
        unsafe { to_path(instance, s.as_ptr(), &mut path) },
        xr::Result::SUCCESS
    );
    let mut again = xr::Path::NULL;
    unsafe { to_path(instance, s.as_ptr(), &mut again) };
    assert_eq!(path, again);
    let mut count = 0;
    assert_eq!(
        unsafe { path_to_string(instance, path, 0, &mut count, null_mut()) },
        xr::Result::SUCCESS
    );
    assert_eq!(count, 16);
    assert_eq!(
        unsafe { path_to_string(instance, path, 3, &mut count, buf.as_mut_ptr()) },
        xr::Result::ERROR_SIZE_INSUFFICIENT
    );
    assert_eq!(
        unsafe { path_to_string(instance, path, 64, &mut count, buf.as_mut_ptr()) },
        xr::Result::SUCCESS
    );
    assert_eq!(text(&buf), "/user/hand/left");
    let bad = CString::new("/user//x").unwrap();
    assert_eq!(
        unsafe { to_path(instance, bad.as_ptr(), &mut path) },
        xr::Result::ERROR_PATH_FORMAT_INVALID
    );
    assert_eq!(
        unsafe {
            path_to_string(
                instance,
                xr::Path::from_raw(999),
                64,
                &mut count,
                buf.as_mut_ptr(),
            )
        },
        xr::Result::ERROR_PATH_INVALID
    );
    destroy_instance(instance);
    // The handle is gone; only the journal remains.
    assert_eq!(
        lookup(instance, "xrCreateSession").0,
        xr::Result::ERROR_HANDLE_INVALID
    );
    assert!(control::journal(instance)
        .iter()
        .any(|c| c.function == "xrDestroyInstance"));
}

#[test]
fn system_and_recommended_sizes_come_from_the_preset() {
    for (id, size) in [
        ("quest3", [2064, 2240]),
        ("rift-cv1", [1344, 1600]),
        ("index", [2480, 2752]),
    ] {
        let instance = create_instance(config(id), &[]);
        let sys = system(instance);
        let get = xrfn!(instance, GetSystem);
        let hand = xr::SystemGetInfo {
            ty: xr::SystemGetInfo::TYPE,
            next: null(),
            form_factor: xr::FormFactor::HANDHELD_DISPLAY,
        };
        let mut other = xr::SystemId::NULL;
        assert_eq!(
            unsafe { get(instance, &hand, &mut other) },
            xr::Result::ERROR_FORM_FACTOR_UNSUPPORTED
        );
        // A form factor the runtime does not know is unsupported too (the CTS's xrGetSystem case
        // passes XR_FORM_FACTOR_MAX_ENUM and requires this code).
        let unknown = xr::SystemGetInfo {
            form_factor: xr::FormFactor::from_raw(0x7FFF_FFFF),
            ..hand
        };
        assert_eq!(
            unsafe { get(instance, &unknown, &mut other) },
            xr::Result::ERROR_FORM_FACTOR_UNSUPPORTED
        );

        let views_fn = xrfn!(instance, EnumerateViewConfigurationViews);
        let stereo = xr::ViewConfigurationType::PRIMARY_STEREO;
        let mut count = 0;
        assert_eq!(
            unsafe { views_fn(instance, sys, stereo, 0, &mut count, null_mut()) },
            xr::Result::SUCCESS
        );
        assert_eq!(count, 2);
        let blank = xr::ViewConfigurationView {
            ty: xr::ViewConfigurationView::TYPE,
            next: null_mut(),
            recommended_image_rect_width: 0,
            max_image_rect_width: 0,
            recommended_image_rect_height: 0,
            max_image_rect_height: 0,
            recommended_swapchain_sample_count: 0,
            max_swapchain_sample_count: 0,
        };
        let mut views = [blank; 2];
        assert_eq!(
            unsafe { views_fn(instance, sys, stereo, 1, &mut count, views.as_mut_ptr()) },
            xr::Result::ERROR_SIZE_INSUFFICIENT
        );
        assert_eq!(
            unsafe { views_fn(instance, sys, stereo, 2, &mut count, views.as_mut_ptr()) },
            xr::Result::SUCCESS
        );
        for v in views {
            assert_eq!(
                [
                    v.recommended_image_rect_width,
                    v.recommended_image_rect_height
                ],
                size,
                "{id}"
            );
            assert_eq!(
                (
                    v.max_image_rect_width,
                    v.recommended_swapchain_sample_count,
                    v.max_swapchain_sample_count
                ),
                (8192, 1, 4)
            );
        }
        let mono = xr::ViewConfigurationType::PRIMARY_MONO;
        assert_eq!(
            unsafe { views_fn(instance, sys, mono, 0, &mut count, null_mut()) },
            xr::Result::ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED
        );
        let bad_system = xr::SystemId::from_raw(12345);
        assert_eq!(
            unsafe { views_fn(instance, bad_system, stereo, 0, &mut count, null_mut()) },
            xr::Result::ERROR_SYSTEM_INVALID
        );

        let blend = xrfn!(instance, EnumerateEnvironmentBlendModes);
        let mut mode = xr::EnvironmentBlendMode::ADDITIVE;
        assert_eq!(
            unsafe { blend(instance, sys, stereo, 1, &mut count, &mut mode) },
            xr::Result::SUCCESS
        );
        assert_eq!((count, mode), (1, xr::EnvironmentBlendMode::OPAQUE));
        destroy_instance(instance);
    }
}

#[test]
fn located_views_carry_the_preset_fovs_and_ipd() {
    let (instance, session) = headless(config("quest3"));
    let local = reference_space(instance, session, xr::ReferenceSpaceType::LOCAL);
    let stage = reference_space(instance, session, xr::ReferenceSpaceType::STAGE);
    let locate = xrfn!(instance, LocateViews);
    let info = xr::ViewLocateInfo {
        ty: xr::ViewLocateInfo::TYPE,
        next: null(),
        view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
        display_time: xr::Time::from_nanos(1_000_000_000_000),
        space: local,
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
    assert_eq!(
        unsafe { locate(session, &info, &mut state, 0, &mut count, null_mut()) },
        xr::Result::SUCCESS
    );
    assert_eq!(count, 2);
    assert_eq!(
        unsafe {
            locate(
                session,
                &info,
                &mut state,
                1,
                &mut count,
                views.as_mut_ptr(),
            )
        },
        xr::Result::ERROR_SIZE_INSUFFICIENT
    );
    assert_eq!(
        unsafe {
            locate(
                session,
                &info,
                &mut state,
                2,
                &mut count,
                views.as_mut_ptr(),
            )
        },
        xr::Result::SUCCESS
    );
    let q3 = fovea_model::headsets::by_id("quest3").unwrap();
    for (eye, view) in views.iter().enumerate() {
        let want = q3.fovs()[eye];
        assert_eq!(
            [
                view.fov.angle_left,
                view.fov.angle_right,
                view.fov.angle_up,
                view.fov.angle_down
            ],
            [want.left, want.right, want.up, want.down]
        );
    }
    // Left eye: 54° out to the left, 40° in to the nose (hmdgdb MetaQuest3).
    assert!((views[0].fov.angle_left.to_degrees() + 54.0).abs() < 1e-3);
    assert!((views[1].fov.angle_right.to_degrees() - 54.0).abs() < 1e-3);
    let ipd = views[1].pose.position.x - views[0].pose.position.x;
    assert!((ipd - 0.063).abs() < 1e-6, "{ipd}");
    assert!(state
        .view_state_flags
        .contains(xr::ViewStateFlags::POSITION_VALID));

    // In STAGE the eyes are 1.6 m up.
    let info_stage = xr::ViewLocateInfo {
        space: stage,
        ..info
    };
    assert_eq!(
        unsafe {
            locate(
                session,
                &info_stage,
                &mut state,
                2,
                &mut count,
                views.as_mut_ptr(),
            )
        },
        xr::Result::SUCCESS
    );
    assert!((views[0].pose.position.y - 1.6).abs() < 1e-6);

    // Validation of the locate info.
    let bad_time = xr::ViewLocateInfo {
        display_time: xr::Time::from_nanos(0),
        ..info
    };
    assert_eq!(
        unsafe {
            locate(
                session,
                &bad_time,
                &mut state,
                2,
                &mut count,
                views.as_mut_ptr(),
            )
        },
        xr::Result::ERROR_TIME_INVALID
    );
    let bad_type = xr::ViewLocateInfo {
        ty: xr::StructureType::VIEW_STATE,
        ..info
    };
    assert_eq!(
        unsafe {
            locate(
                session,
                &bad_type,
                &mut state,
                2,
                &mut count,
                views.as_mut_ptr(),
            )
        },
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    let bad_space = xr::ViewLocateInfo {
        space: xr::Space::from_raw(7),
        ..info
    };
    assert_eq!(
        unsafe {
            locate(
                session,
                &bad_space,
                &mut state,
                2,
                &mut count,
                views.as_mut_ptr(),
            )
        },
        xr::Result::ERROR_HANDLE_INVALID
    );
    let mut wrong = [xr::View {
        ty: xr::StructureType::VIEW_STATE,
        ..blank
    }; 2];
    assert_eq!(
        unsafe {
            locate(
                session,
                &info,
                &mut state,
                2,
                &mut count,
                wrong.as_mut_ptr(),
            )
        },
        xr::Result::ERROR_VALIDATION_FAILURE
    );

    // xrLocateSpace: LOCAL seen from STAGE is 1.6 m up.
    let locate_space = xrfn!(instance, LocateSpace);
    let mut loc = xr::SpaceLocation {
        ty: xr::SpaceLocation::TYPE,
        next: null_mut(),
        location_flags: xr::SpaceLocationFlags::EMPTY,
        pose: Default::default(),
    };
    assert_eq!(
        unsafe { locate_space(local, stage, info.display_time, &mut loc) },
        xr::Result::SUCCESS
    );
    assert!((loc.pose.position.y - 1.6).abs() < 1e-6);
    assert!(loc
        .location_flags
        .contains(xr::SpaceLocationFlags::POSITION_TRACKED));
    destroy_instance(instance);
}

#[test]
fn session_lifecycle_announces_every_state() {
    use xr::SessionState as S;
    let instance = create_instance(config("quest3"), &["XR_MND_headless"]);
    // Without XR_MND_headless and without a binding there is no session.
    let plain = create_instance(config("quest3"), &[]);
    assert_eq!(
        create_session_with(plain, null()),
        Err(xr::Result::ERROR_GRAPHICS_DEVICE_INVALID)
    );
    destroy_instance(plain);

    let session = create_session_with(instance, null()).unwrap();
    assert_eq!(
        create_session_with(instance, null()),
        Err(xr::Result::ERROR_LIMIT_REACHED)
    );
    assert_eq!(poll_states(instance), [S::IDLE, S::READY]);
    let end_session = xrfn!(instance, EndSession);
    let request_exit = xrfn!(instance, RequestExitSession);
    assert_eq!(
        unsafe { request_exit(session) },
        xr::Result::ERROR_SESSION_NOT_RUNNING
    );
    assert_eq!(
        unsafe { end_session(session) },
        xr::Result::ERROR_SESSION_NOT_RUNNING
    );
    assert_eq!(begin_session(instance, session), xr::Result::SUCCESS);
    assert_eq!(
        begin_session(instance, session),
        xr::Result::ERROR_SESSION_RUNNING
    );
    assert_eq!(
        unsafe { end_session(session) },
        xr::Result::ERROR_SESSION_NOT_STOPPING
    );

    let first = wait_frame(instance, session).unwrap();
    assert_eq!(first.should_render, xr::FALSE);
    assert_eq!(poll_states(instance), [S::SYNCHRONIZED]);
    begin_frame(instance, session);
    end_frame(instance, session, first.predicted_display_time, &[]);
    assert_eq!(poll_states(instance), [S::VISIBLE]);
    assert_eq!(
        wait_frame(instance, session).unwrap().should_render,
        xr::TRUE
    );
    begin_frame(instance, session);
    end_frame(instance, session, first.predicted_display_time, &[]);
    assert_eq!(poll_states(instance), [S::FOCUSED]);
    empty_frame(instance, session);
    assert_eq!(poll_states(instance), []);

    assert_eq!(unsafe { request_exit(session) }, xr::Result::SUCCESS);
    assert_eq!(
        poll_states(instance),
        [S::VISIBLE, S::SYNCHRONIZED, S::STOPPING]
    );
    assert_eq!(unsafe { end_session(session) }, xr::Result::SUCCESS);
    assert_eq!(poll_states(instance), [S::IDLE, S::EXITING]);
    assert_eq!(
        wait_frame(instance, session).unwrap_err(),
        xr::Result::ERROR_SESSION_NOT_RUNNING
    );

    let destroy = xrfn!(instance, DestroySession);
    assert_eq!(unsafe { destroy(session) }, xr::Result::SUCCESS);
    assert_eq!(
        unsafe { destroy(session) },
        xr::Result::ERROR_HANDLE_INVALID
    );
    destroy_instance(instance);
}

/// A session that exits before its first xrWaitFrame (the CTS's FrameSubmission and
/// XR_EXT_debug_utils cases) still goes through SYNCHRONIZED: the spec's lifecycle has no
/// READY→STOPPING edge, and the CTS's conformance layer fails the run on one.
#[test]
fn exit_before_the_first_frame_passes_through_synchronized() {
    use xr::SessionState as S;
    let instance = create_instance(config("quest3"), &["XR_MND_headless"]);
    let session = create_session_with(instance, null()).unwrap();
    assert_eq!(begin_session(instance, session), xr::Result::SUCCESS);
    assert_eq!(poll_states(instance), [S::IDLE, S::READY]);
    assert_eq!(
        unsafe { xrfn!(instance, RequestExitSession)(session) },
        xr::Result::SUCCESS
    );
    assert_eq!(poll_states(instance), [S::SYNCHRONIZED, S::STOPPING]);
    assert_eq!(
        unsafe { xrfn!(instance, EndSession)(session) },
        xr::Result::SUCCESS
    );
    assert_eq!(poll_states(instance), [S::IDLE, S::EXITING]);
    destroy_instance(instance);
}

#[test]
fn the_runtime_requests_exit_after_the_configured_frames() {
    use xr::SessionState as S;
    let mut cfg = config("quest3");
    cfg.exit_after_frames = Some(3);
    let (instance, session) = headless(cfg);
    for _ in 0..3 {
        empty_frame(instance, session);
    }
    let states = poll_states(instance);
    assert_eq!(
        states,
        [
            S::IDLE,
            S::READY,
            S::SYNCHRONIZED,
            S::VISIBLE,
            S::FOCUSED,
            S::VISIBLE,
            S::SYNCHRONIZED,
            S::STOPPING
        ]
    );
    assert_eq!(
        unsafe { xrfn!(instance, EndSession)(session) },
        xr::Result::SUCCESS
    );
    assert_eq!(poll_states(instance), [S::IDLE, S::EXITING]);
    destroy_instance(instance);
}

#[test]
fn frame_calls_out_of_order_are_rejected() {
    let (instance, session) = headless(config("quest3"));
    assert_eq!(
        begin_frame(instance, session),
        xr::Result::ERROR_CALL_ORDER_INVALID
    );
    let t = xr::Time::from_nanos(1);
    assert_eq!(
        end_frame(instance, session, t, &[]),
        xr::Result::ERROR_CALL_ORDER_INVALID
    );
    let state = wait_frame(instance, session).unwrap();
    assert_eq!(begin_frame(instance, session), xr::Result::SUCCESS);
    // A second wait+begin before the end discards the begun frame.
    wait_frame(instance, session).unwrap();
    assert_eq!(begin_frame(instance, session), xr::Result::FRAME_DISCARDED);
    assert_eq!(
        end_frame(instance, session, xr::Time::from_nanos(0), &[]),
        xr::Result::ERROR_TIME_INVALID
    );
    let end = xrfn!(instance, EndFrame);
    let additive = xr::FrameEndInfo {
        ty: xr::FrameEndInfo::TYPE,
        next: null(),
        display_time: state.predicted_display_time,
        environment_blend_mode: xr::EnvironmentBlendMode::ADDITIVE,
        layer_count: 0,
        layers: null(),
    };
    assert_eq!(
        unsafe { end(session, &additive) },
        xr::Result::ERROR_ENVIRONMENT_BLEND_MODE_UNSUPPORTED
    );
    // Errors change nothing: the frame is still begun and can be ended.
    assert_eq!(
        end_frame(instance, session, state.predicted_display_time, &[]),
        xr::Result::SUCCESS
    );
    assert_eq!(
        end_frame(instance, session, state.predicted_display_time, &[]),
        xr::Result::ERROR_CALL_ORDER_INVALID
    );
    destroy_instance(instance);
}

/// Pipelining (the CTS's Timed_Pipelined_Frame_Submission): one thread waits frames, another begins
/// and ends them. The spec makes a wait block until the previous waited frame is begun, so each
/// begin finds its own waited frame.
#[test]
fn a_wait_blocks_until_the_previous_frame_is_begun() {
    use std::sync::mpsc;
    use std::time::Duration;
    let (instance, session) = headless(config("quest3"));
    let first = wait_frame(instance, session).unwrap();
    let (tx, rx) = mpsc::channel();
    let waiter = std::thread::spawn(move || {
        let state = wait_frame(instance, session).map(|s| s.predicted_display_time);
        tx.send(state).unwrap();
    });
    // The second wait does not return while the first frame is not begun.
    assert!(rx.recv_timeout(Duration::from_millis(300)).is_err());
    assert_eq!(begin_frame(instance, session), xr::Result::SUCCESS);
    let second = rx
        .recv_timeout(Duration::from_secs(5))
        .expect("the wait returns once the first frame is begun")
        .unwrap();
    waiter.join().unwrap();
    assert!(second.as_nanos() > first.predicted_display_time.as_nanos());
    assert_eq!(
        end_frame(instance, session, first.predicted_display_time, &[]),
        xr::Result::SUCCESS
    );
    // The second waited frame is still there to begin.
    assert_eq!(begin_frame(instance, session), xr::Result::SUCCESS);
    assert_eq!(
        end_frame(instance, session, second, &[]),
        xr::Result::SUCCESS
    );
    destroy_instance(instance);
}

#[test]
fn the_display_clock_is_deterministic_and_load_misses_frames() {
    let run = |load: Load| {
        let mut cfg = config("quest3");
        cfg.load = load;
        let (instance, session) = headless(cfg);
        let times: Vec<i64> = (0..8)
            .map(|_| empty_frame(instance, session).as_nanos())
            .collect();
        let journal = control::journal(instance);
        destroy_instance(instance);
        (times, journal)
    };
    let period = 11_111_111;
    let (idle, _) = run(Load::default());
    let (again, _) = run(Load::default());
    assert_eq!(idle, again, "virtual time is deterministic");
    assert!(idle.windows(2).all(|w| w[1] - w[0] == period));

    // Frames 3 and 4 take 12 ms (> 11.1 ms): each pushes the next frame one extra period out;
    // frame 5 takes 25 ms: two extra periods.
    let (loaded, journal) = run(Load {
        gpu_ms: vec![(0, 5.0), (3, 12.0), (5, 25.0), (6, 5.0)],
    });
    let steps: Vec<i64> = loaded.windows(2).map(|w| (w[1] - w[0]) / period).collect();
    assert_eq!(steps, [1, 1, 1, 2, 2, 3, 1]);
    let waits: Vec<&str> = journal
        .iter()
        .filter(|c| c.function == "xrWaitFrame")
        .map(|c| c.detail.as_str())
        .collect();
    assert!(
        waits[5].contains("skipped=1") && waits[6].contains("skipped=2"),
        "{waits:?}"
    );

    // set_load changes an existing instance.
    let (instance, session) = headless(config("quest3"));
    let t0 = empty_frame(instance, session).as_nanos();
    control::set_load(instance, Load::constant(30.0));
    let t1 = empty_frame(instance, session).as_nanos();
    let t2 = empty_frame(instance, session).as_nanos();
    assert_eq!(((t1 - t0) / period, (t2 - t1) / period), (3, 3));
    destroy_instance(instance);
}

#[test]
fn faults_fail_exactly_the_chosen_call_and_loss_sticks() {
    let mut cfg = config("quest3");
    cfg.faults = vec![Fault {
        function: "xrCreateSwapchain".into(),
        result: xr::Result::ERROR_RUNTIME_FAILURE,
        nth: 2,
    }];
    let (instance, session) = headless(cfg);
    let info = swapchain_info(43, 128, 128, 1);
    let first = create_swapchain(instance, session, &info).unwrap();
    assert_eq!(
        create_swapchain(instance, session, &info),
        Err(xr::Result::ERROR_RUNTIME_FAILURE)
    );
    let third = create_swapchain(instance, session, &info).unwrap();
    assert_ne!(first, third);

    control::inject_fault(
        instance,
        Fault {
            function: "xrWaitFrame".into(),
            result: xr::Result::ERROR_SESSION_LOST,
            nth: 0,
        },
    );
    assert_eq!(
        wait_frame(instance, session).unwrap_err(),
        xr::Result::ERROR_SESSION_LOST
    );
    // Lost sticks for the session and its children, but destroying still works.
    assert_eq!(
        begin_frame(instance, session),
        xr::Result::ERROR_SESSION_LOST
    );
    assert_eq!(
        create_swapchain(instance, session, &info),
        Err(xr::Result::ERROR_SESSION_LOST)
    );
    assert_eq!(
        unsafe { xrfn!(instance, DestroySwapchain)(first) },
        xr::Result::SUCCESS
    );
    assert_eq!(
        unsafe { xrfn!(instance, DestroySession)(session) },
        xr::Result::SUCCESS
    );

    control::inject_fault(
        instance,
        Fault {
            function: "xrGetSystem".into(),
            result: xr::Result::ERROR_INSTANCE_LOST,
            nth: 1,
        },
    );
    let get = xrfn!(instance, GetSystem);
    let gi = xr::SystemGetInfo {
        ty: xr::SystemGetInfo::TYPE,
        next: null(),
        form_factor: xr::FormFactor::HEAD_MOUNTED_DISPLAY,
    };
    let mut id = xr::SystemId::NULL;
    // The config already made one xrGetSystem call (in `headless`), so the next is the 2nd: no fault.
    assert_eq!(unsafe { get(instance, &gi, &mut id) }, xr::Result::SUCCESS);
    control::inject_fault(
        instance,
        Fault {
            function: "xrGetSystem".into(),
            result: xr::Result::ERROR_INSTANCE_LOST,
            nth: 3,
        },
    );
    assert_eq!(
        unsafe { get(instance, &gi, &mut id) },
        xr::Result::ERROR_INSTANCE_LOST
    );
    assert_eq!(
        unsafe { get(instance, &gi, &mut id) },
        xr::Result::ERROR_INSTANCE_LOST
    );
    let poll = xrfn!(instance, PollEvent);
    let mut buffer = xr::EventDataBuffer {
        ty: xr::EventDataBuffer::TYPE,
        next: null(),
        varying: [0; 4000],
    };
    assert_eq!(
        unsafe { poll(instance, &mut buffer) },
        xr::Result::ERROR_INSTANCE_LOST
    );

    let journal = control::journal(instance);
    let faulted: Vec<_> = journal
        .iter()
        .filter(|c| c.detail.starts_with("injected fault"))
        .map(|c| c.function)
        .collect();
    assert_eq!(faulted, ["xrCreateSwapchain", "xrWaitFrame", "xrGetSystem"]);
    destroy_instance(instance);

    // A configured xrCreateInstance fault.
    let mut cfg = config("quest3");
    cfg.faults = vec![Fault {
        function: "xrCreateInstance".into(),
        result: xr::Result::ERROR_OUT_OF_MEMORY,
        nth: 0,
    }];
    assert_eq!(
        try_create_instance(cfg, &[], xr::Version::new(1, 0, 0)),
        Err(xr::Result::ERROR_OUT_OF_MEMORY)
    );
}

#[test]
fn headless_swapchains_cycle_and_frames_record_what_was_submitted() {
    let (instance, session) = headless(config("rift-cv1"));
    let space = reference_space(instance, session, xr::ReferenceSpaceType::LOCAL);

    // Formats: the full list, colour first.
    let formats_fn = xrfn!(instance, EnumerateSwapchainFormats);
    let mut count = 0;
    unsafe { formats_fn(session, 0, &mut count, null_mut()) };
    let mut formats = vec![0i64; count as usize];
    assert_eq!(
        unsafe { formats_fn(session, count, &mut count, formats.as_mut_ptr()) },
        xr::Result::SUCCESS
    );
    assert_eq!(formats[0], 43); // VK_FORMAT_R8G8B8A8_SRGB

    // Create-info validation.
    for bad in [
        xr::SwapchainCreateInfo {
            width: 0,
            ..swapchain_info(43, 1344, 1600, 2)
        },
        xr::SwapchainCreateInfo {
            array_size: 0,
            ..swapchain_info(43, 1344, 1600, 2)
        },
        xr::SwapchainCreateInfo {
            mip_count: 20,
            ..swapchain_info(43, 1344, 1600, 2)
        },
        xr::SwapchainCreateInfo {
            face_count: 2,
            ..swapchain_info(43, 1344, 1600, 2)
        },
    ] {
        assert_eq!(
            create_swapchain(instance, session, &bad),
            Err(xr::Result::ERROR_VALIDATION_FAILURE)
        );
    }
    assert_eq!(
        create_swapchain(instance, session, &swapchain_info(9999, 64, 64, 1)),
        Err(xr::Result::ERROR_SWAPCHAIN_FORMAT_UNSUPPORTED)
    );

    // Unknown next structs are ignored but journaled.
    let foveation = xr::SwapchainCreateInfoFoveationFB {
        ty: xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
        next: null_mut(),
        flags: xr::SwapchainCreateFoveationFlagsFB::FRAGMENT_DENSITY_MAP,
    };
    let info = xr::SwapchainCreateInfo {
        next: &foveation as *const _ as *const _,
        ..swapchain_info(43, 1344, 1600, 2)
    };
    let sc = create_swapchain(instance, session, &info).unwrap();
    let created = control::journal(instance)
        .into_iter()
        .rev()
        .find(|c| c.function == "xrCreateSwapchain")
        .unwrap();
    assert_eq!(
        (created.result, created.next_types),
        (
            xr::Result::SUCCESS,
            vec![xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB]
        )
    );

    // Images: count only; there is no image type to fill.
    let images_fn = xrfn!(instance, EnumerateSwapchainImages);
    assert_eq!(
        unsafe { images_fn(sc, 0, &mut count, null_mut()) },
        xr::Result::SUCCESS
    );
    assert_eq!(count, 3);
    let mut vk_images = [xr::SwapchainImageVulkanKHR {
        ty: xr::SwapchainImageVulkanKHR::TYPE,
        next: null_mut(),
        image: 0,
    }; 3];
    let r = unsafe {
        images_fn(
            sc,
            3,
            &mut count,
            vk_images.as_mut_ptr() as *mut xr::SwapchainImageBaseHeader,
        )
    };
    assert_eq!(r, xr::Result::ERROR_VALIDATION_FAILURE);

    // Order rules.
    let acquire = xrfn!(instance, AcquireSwapchainImage);
    let wait = xrfn!(instance, WaitSwapchainImage);
    let release = xrfn!(instance, ReleaseSwapchainImage);
    let wi = xr::SwapchainImageWaitInfo {
        ty: xr::SwapchainImageWaitInfo::TYPE,
        next: null(),
        timeout: xr::Duration::INFINITE,
    };
    let mut index = 0;
    unsafe {
        assert_eq!(wait(sc, &wi), xr::Result::ERROR_CALL_ORDER_INVALID);
        assert_eq!(release(sc, null()), xr::Result::ERROR_CALL_ORDER_INVALID);
        for expect in 0..3 {
            assert_eq!(acquire(sc, null(), &mut index), xr::Result::SUCCESS);
            assert_eq!(index, expect);
        }
        assert_eq!(
            acquire(sc, null(), &mut index),
            xr::Result::ERROR_CALL_ORDER_INVALID
        );
        assert_eq!(wait(sc, &wi), xr::Result::SUCCESS);
        assert_eq!(wait(sc, &wi), xr::Result::ERROR_CALL_ORDER_INVALID);
        for _ in 0..3 {
            if release(sc, null()) == xr::Result::ERROR_CALL_ORDER_INVALID {
                assert_eq!(wait(sc, &wi), xr::Result::SUCCESS);
                assert_eq!(release(sc, null()), xr::Result::SUCCESS);
            }
        }
    }
    assert_eq!(cycle_image(instance, sc), 0);

    // A frame with a projection layer; fovs as the app chooses to submit them.
    let state = wait_frame(instance, session).unwrap();
    begin_frame(instance, session);
    let fov = xr::Fovf {
        angle_left: -0.7,
        angle_right: 0.6,
        angle_up: 0.7,
        angle_down: -0.8,
    };
    let view = |i: u32, x: i32| xr::CompositionLayerProjectionView {
        ty: xr::CompositionLayerProjectionView::TYPE,
        next: null(),
        pose: xr::Posef::IDENTITY,
        fov,
        sub_image: xr::SwapchainSubImage {
            swapchain: sc,
            image_rect: xr::Rect2Di {
                offset: xr::Offset2Di { x, y: 0 },
                extent: xr::Extent2Di {
                    width: 1344 - x,
                    height: 1600,
                },
            },
            image_array_index: i,
        },
    };
    let views = [view(0, 0), view(1, 100)];
    let layer = xr::CompositionLayerProjection {
        ty: xr::CompositionLayerProjection::TYPE,
        next: null(),
        layer_flags: xr::CompositionLayerFlags::EMPTY,
        space,
        view_count: 2,
        views: views.as_ptr(),
    };
    let layers = [&layer as *const _ as *const xr::CompositionLayerBaseHeader];
    let t = state.predicted_display_time;
    // Rect outside the swapchain, array index out of range, one view, NULL layer.
    let too_wide = [
        view(0, 0),
        xr::CompositionLayerProjectionView {
            sub_image: xr::SwapchainSubImage {
                image_rect: xr::Rect2Di {
                    offset: xr::Offset2Di { x: 1, y: 0 },
                    extent: xr::Extent2Di {
                        width: 1344,
                        height: 1600,
                    },
                },
                ..views[1].sub_image
            },
            ..views[1]
        },
    ];
    let bad_rect = xr::CompositionLayerProjection {
        views: too_wide.as_ptr(),
        ..layer
    };
    assert_eq!(
        end_frame(instance, session, t, &[&bad_rect as *const _ as *const _]),
        xr::Result::ERROR_SWAPCHAIN_RECT_INVALID
    );
    let bad_index = [view(0, 0), view(2, 0)];
    let bad_layer = xr::CompositionLayerProjection {
        views: bad_index.as_ptr(),
        ..layer
    };
    assert_eq!(
        end_frame(instance, session, t, &[&bad_layer as *const _ as *const _]),
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    let one_view = xr::CompositionLayerProjection {
        view_count: 1,
        ..layer
    };
    assert_eq!(
        end_frame(instance, session, t, &[&one_view as *const _ as *const _]),
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    assert_eq!(
        end_frame(instance, session, t, &[null()]),
        xr::Result::ERROR_LAYER_INVALID
    );
    // A pose whose orientation is off unit length by more than 1% (the CTS's projection and quad
    // cases): XR_ERROR_POSE_INVALID, in a projection view and in a quad layer.
    let skewed = xr::Posef {
        orientation: xr::Quaternionf {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 0.98,
        },
        ..xr::Posef::IDENTITY
    };
    let bad_pose = [
        view(0, 0),
        xr::CompositionLayerProjectionView {
            pose: skewed,
            ..views[1]
        },
    ];
    let bad_pose_layer = xr::CompositionLayerProjection {
        views: bad_pose.as_ptr(),
        ..layer
    };
    assert_eq!(
        end_frame(
            instance,
            session,
            t,
            &[&bad_pose_layer as *const _ as *const _]
        ),
        xr::Result::ERROR_POSE_INVALID
    );
    let quad = xr::CompositionLayerQuad {
        ty: xr::CompositionLayerQuad::TYPE,
        next: null(),
        layer_flags: xr::CompositionLayerFlags::EMPTY,
        space,
        eye_visibility: xr::EyeVisibility::BOTH,
        sub_image: views[0].sub_image,
        pose: xr::Posef::IDENTITY,
        size: xr::Extent2Df {
            width: 1.0,
            height: 1.0,
        },
    };
    let bad_quad = xr::CompositionLayerQuad {
        pose: skewed,
        ..quad
    };
    assert_eq!(
        end_frame(instance, session, t, &[&bad_quad as *const _ as *const _]),
        xr::Result::ERROR_POSE_INVALID
    );
    assert_eq!(
        end_frame(instance, session, t, &layers),
        xr::Result::SUCCESS
    );

    let submitted = control::end_frame_views(instance);
    assert_eq!(submitted.len(), 1);
    assert_eq!(submitted[0].len(), 2);
    assert_eq!(submitted[0][1].swapchain, sc.into_raw());
    assert_eq!(submitted[0][1].image_rect.offset.x, 100);
    assert_eq!(submitted[0][1].image_array_index, 1);
    assert_eq!(submitted[0][1].fov, fov);
    let end_call = control::journal(instance)
        .into_iter()
        .rev()
        .find(|c| c.function == "xrEndFrame")
        .unwrap();
    assert!(
        end_call.detail.contains("PROJECTION") && end_call.detail.contains("index=1"),
        "{}",
        end_call.detail
    );

    // A swapchain never released cannot be submitted.
    let fresh = create_swapchain(instance, session, &swapchain_info(43, 1344, 1600, 2)).unwrap();
    let fresh_views = [
        xr::CompositionLayerProjectionView {
            sub_image: xr::SwapchainSubImage {
                swapchain: fresh,
                ..views[0].sub_image
            },
            ..views[0]
        },
        views[1],
    ];
    let fresh_layer = xr::CompositionLayerProjection {
        views: fresh_views.as_ptr(),
        ..layer
    };
    wait_frame(instance, session).unwrap();
    begin_frame(instance, session);
    assert_eq!(
        end_frame(
            instance,
            session,
            t,
            &[&fresh_layer as *const _ as *const _]
        ),
        xr::Result::ERROR_LAYER_INVALID
    );

    // Static swapchains have one image, acquired once.
    let static_info = xr::SwapchainCreateInfo {
        create_flags: xr::SwapchainCreateFlags::STATIC_IMAGE,
        ..swapchain_info(43, 64, 64, 1)
    };
    let st = create_swapchain(instance, session, &static_info).unwrap();
    assert_eq!(cycle_image(instance, st), 0);
    assert_eq!(
        unsafe { acquire(st, null(), &mut index) },
        xr::Result::ERROR_CALL_ORDER_INVALID
    );

    // Destroying the session destroys its swapchains and spaces.
    assert_eq!(
        unsafe { xrfn!(instance, DestroySession)(session) },
        xr::Result::SUCCESS
    );
    assert_eq!(
        unsafe { acquire(sc, null(), &mut index) },
        xr::Result::ERROR_HANDLE_INVALID
    );
    assert_eq!(
        unsafe { xrfn!(instance, DestroySpace)(space) },
        xr::Result::ERROR_HANDLE_INVALID
    );
    destroy_instance(instance);
}

#[test]
fn minimal_input_is_accepted_and_inactive() {
    use xr::SessionState as S;
    let (instance, session) = headless(config("quest3"));
    let mut set_info = xr::ActionSetCreateInfo {
        ty: xr::ActionSetCreateInfo::TYPE,
        next: null(),
        action_set_name: [0; xr::MAX_ACTION_SET_NAME_SIZE],
        localized_action_set_name: [0; xr::MAX_LOCALIZED_ACTION_SET_NAME_SIZE],
        priority: 0,
    };
    for (d, s) in set_info.action_set_name.iter_mut().zip(b"gameplay") {
        *d = *s as c_char;
    }
    for (d, s) in set_info
        .localized_action_set_name
        .iter_mut()
        .zip(b"Gameplay")
    {
        *d = *s as c_char;
    }
    let mut set = xr::ActionSet::NULL;
    assert_eq!(
        unsafe { xrfn!(instance, CreateActionSet)(instance, &set_info, &mut set) },
        xr::Result::SUCCESS
    );
    let mut action_info = xr::ActionCreateInfo {
        ty: xr::ActionCreateInfo::TYPE,
        next: null(),
        action_name: [0; xr::MAX_ACTION_NAME_SIZE],
        action_type: xr::ActionType::FLOAT_INPUT,
        count_subaction_paths: 0,
        subaction_paths: null(),
        localized_action_name: [0; xr::MAX_LOCALIZED_ACTION_NAME_SIZE],
    };
    for (d, s) in action_info.action_name.iter_mut().zip(b"grab") {
        *d = *s as c_char;
    }
    for (d, s) in action_info.localized_action_name.iter_mut().zip(b"Grab") {
        *d = *s as c_char;
    }
    let mut action = xr::Action::NULL;
    assert_eq!(
        unsafe { xrfn!(instance, CreateAction)(set, &action_info, &mut action) },
        xr::Result::SUCCESS
    );
    let attach = xr::SessionActionSetsAttachInfo {
        ty: xr::SessionActionSetsAttachInfo::TYPE,
        next: null(),
        count_action_sets: 1,
        action_sets: &set,
    };
    assert_eq!(
        unsafe { xrfn!(instance, AttachSessionActionSets)(session, &attach) },
        xr::Result::SUCCESS
    );
    let active = xr::ActiveActionSet {
        action_set: set,
        subaction_path: xr::Path::NULL,
    };
    let sync = xr::ActionsSyncInfo {
        ty: xr::ActionsSyncInfo::TYPE,
        next: null(),
        count_active_action_sets: 1,
        active_action_sets: &active,
    };
    assert_eq!(
        unsafe { xrfn!(instance, SyncActions)(session, &sync) },
        xr::Result::SESSION_NOT_FOCUSED
    );
    for _ in 0..2 {
        empty_frame(instance, session);
    }
    assert_eq!(poll_states(instance).last(), Some(&S::FOCUSED));
    assert_eq!(
        unsafe { xrfn!(instance, SyncActions)(session, &sync) },
        xr::Result::SUCCESS
    );
    let get = xr::ActionStateGetInfo {
        ty: xr::ActionStateGetInfo::TYPE,
        next: null(),
        action,
        subaction_path: xr::Path::NULL,
    };
    let mut state = xr::ActionStateFloat {
        ty: xr::ActionStateFloat::TYPE,
        next: null_mut(),
        current_state: 5.0,
        changed_since_last_sync: xr::TRUE,
        last_change_time: xr::Time::from_nanos(3),
        is_active: xr::TRUE,
    };
    assert_eq!(
        unsafe { xrfn!(instance, GetActionStateFloat)(session, &get, &mut state) },
        xr::Result::SUCCESS
    );
    assert_eq!(
        (state.is_active, state.current_state, state.ty),
        (xr::FALSE, 0.0, xr::ActionStateFloat::TYPE)
    );
    let mut b = xr::ActionStateBoolean {
        ty: xr::ActionStateBoolean::TYPE,
        next: null_mut(),
        current_state: xr::FALSE,
        changed_since_last_sync: xr::FALSE,
        last_change_time: xr::Time::from_nanos(0),
        is_active: xr::FALSE,
    };
    assert_eq!(
        unsafe { xrfn!(instance, GetActionStateBoolean)(session, &get, &mut b) },
        xr::Result::ERROR_ACTION_TYPE_MISMATCH
    );
    assert_eq!(
        unsafe { xrfn!(instance, CreateAction)(set, &action_info, &mut action) },
        xr::Result::ERROR_ACTIONSETS_ALREADY_ATTACHED
    );
    destroy_instance(instance);
}

/// OpenXR 1.1 made `LOCAL_FLOOR` core and every runtime offers it there; under 1.0 it needs
/// XR_EXT_local_floor, which the runtime does not offer, so a 1.0 session neither lists nor makes it.
#[test]
fn local_floor_is_a_reference_space_of_api_1_1_only() {
    for (api, floor) in [
        (xr::Version::new(1, 0, 34), false),
        (xr::Version::new(1, 1, 40), true),
    ] {
        let instance = try_create_instance(config("quest3"), &["XR_MND_headless"], api).unwrap();
        let session = create_session_with(instance, null()).unwrap();
        let enumerate = xrfn!(instance, EnumerateReferenceSpaces);
        let mut count = 0;
        let mut spaces = [xr::ReferenceSpaceType::VIEW; 8];
        assert_eq!(
            unsafe { enumerate(session, 8, &mut count, spaces.as_mut_ptr()) },
            xr::Result::SUCCESS
        );
        let listed = &spaces[..count as usize];
        assert_eq!(
            listed.contains(&xr::ReferenceSpaceType::LOCAL_FLOOR),
            floor,
            "{api:?}: {listed:?}"
        );
        let create = xrfn!(instance, CreateReferenceSpace);
        let info = xr::ReferenceSpaceCreateInfo {
            ty: xr::ReferenceSpaceCreateInfo::TYPE,
            next: null(),
            reference_space_type: xr::ReferenceSpaceType::LOCAL_FLOOR,
            pose_in_reference_space: xr::Posef {
                orientation: xr::Quaternionf {
                    x: 0.0,
                    y: 0.0,
                    z: 0.0,
                    w: 1.0,
                },
                position: xr::Vector3f {
                    x: 0.0,
                    y: 0.0,
                    z: 0.0,
                },
            },
        };
        let mut space = xr::Space::NULL;
        let want = if floor {
            xr::Result::SUCCESS
        } else {
            xr::Result::ERROR_REFERENCE_SPACE_UNSUPPORTED
        };
        assert_eq!(
            unsafe { create(session, &info, &mut space) },
            want,
            "{api:?}"
        );
        if floor {
            // On the floor, under LOCAL's origin: as far below LOCAL as the stage.
            let locate = xrfn!(instance, LocateSpace);
            let local = reference_space(instance, session, xr::ReferenceSpaceType::LOCAL);
            let stage = reference_space(instance, session, xr::ReferenceSpaceType::STAGE);
            let at = |s: xr::Space| {
                let mut l = xr::SpaceLocation {
                    ty: xr::SpaceLocation::TYPE,
                    next: null_mut(),
                    location_flags: xr::SpaceLocationFlags::EMPTY,
                    pose: Default::default(),
                };
                let t = xr::Time::from_nanos(1_000_000_000);
                assert_eq!(unsafe { locate(s, local, t, &mut l) }, xr::Result::SUCCESS);
                l.pose.position.y
            };
            let (floor_y, stage_y) = (at(space), at(stage));
            assert!(floor_y < -1.0 && floor_y == stage_y, "{floor_y} {stage_y}");
        }
        destroy_instance(instance);
    }
}
