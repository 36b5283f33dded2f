//! Runtime faults, one at a time, through fovea: a realistic session runs once cleanly, then once per
//! call the runtime saw, with that call failing (the simulated runtime's fault injection).
//!
//! Each run checks that the application gets exactly the runtime's error from the failing call, that
//! fovea's own state is still right afterwards (the swapchain's foveation state reads back, an update
//! still applies), that teardown works (a destroy the runtime refused can be retried: fovea must
//! still know the handle), and that afterwards neither fovea nor the runtime knows any of the
//! run's handles. The Vulkan test does the same around density images on lavapipe under the Khronos
//! validation layer, which reports every Vulkan object still alive when the device is destroyed.
//!
//! The runtime's object count is process-wide, so each test of this module runs in a process of its
//! own.

use std::ffi::c_void;
use std::ptr::{null, null_mut};

use fovea_harness::app::{with_create_info, API_1_0};
use fovea_harness::fns::Fns;
use fovea_harness::frame_loop::FOVEATION_EXTENSIONS;
use fovea_harness::sim::control::{self, Fault, SimConfig};
use fovea_harness::vulkan::{pick_lavapipe, take_messages, validated_entry, Vulkan};
use fovea_harness::{skip, Chain};
use openxr_sys as xr;
use xr::Handle;

use crate::support::{foveation_state, in_own_process, level_info};

/// The handles a run made, to tear down and to probe afterwards.
#[derive(Default)]
struct Handles {
    instance: xr::Instance,
    session: xr::Session,
    space: xr::Space,
    swapchain: xr::Swapchain,
    profile: xr::FoveationProfileFB,
    /// The profile last applied to the swapchain.
    applied: xr::FoveationProfileFB,
}

/// One run: the fault in force and what the application saw.
struct Run {
    fault: Option<Fault>,
    /// The first call that failed, as the application saw it.
    first_error: Option<(&'static str, xr::Result)>,
    /// Destroys refused by the runtime and retried.
    retried: u32,
}

/// A failed call stops the flow; teardown follows.
type Step = Result<(), ()>;

impl Run {
    fn call(&mut self, name: &'static str, r: xr::Result) -> Step {
        if r.into_raw() < 0 {
            self.first_error.get_or_insert((name, r));
            return Err(());
        }
        Ok(())
    }

    /// A destroy during teardown: must succeed, except the one call the fault hits, which must then
    /// succeed when retried (the handle is still alive in the runtime, so fovea must still know it).
    fn destroy(&mut self, name: &'static str, mut f: impl FnMut() -> xr::Result) {
        let r = f();
        if r == xr::Result::SUCCESS {
            return;
        }
        self.first_error.get_or_insert((name, r));
        let injected = self
            .fault
            .as_ref()
            .is_some_and(|fault| fault.function == name && fault.result == r);
        assert!(injected, "{name} failed with {r:?} ({:?})", self.fault);
        self.retried += 1;
        assert_eq!(f(), xr::Result::SUCCESS, "{name} retried after {r:?}");
    }
}

/// Polls events until the session reaches `state` (a bounded number of polls).
unsafe fn poll_until(run: &mut Run, f: &Fns, h: &Handles, state: xr::SessionState) -> Step {
    for _ in 0..32 {
        let mut event = xr::EventDataBuffer {
            ty: xr::StructureType::EVENT_DATA_BUFFER,
            next: null(),
            varying: [0; 4000],
        };
        let r = (f.poll_event)(h.instance, &mut event);
        run.call("xrPollEvent", r)?;
        if r == xr::Result::SUCCESS
            && event.ty == xr::StructureType::EVENT_DATA_SESSION_STATE_CHANGED
        {
            let changed = &*(&event as *const _ as *const xr::EventDataSessionStateChanged);
            if changed.state == state {
                return Ok(());
            }
        }
    }
    panic!("the session never reached {state:?}");
}

/// One frame: wait, begin, locate, acquire/wait/release an image, end with a projection layer.
unsafe fn frame(run: &mut Run, f: &Fns, h: &Handles, size: [u32; 2]) -> Step {
    let mut state = xr::FrameState {
        ty: xr::StructureType::FRAME_STATE,
        next: null_mut(),
        predicted_display_time: xr::Time::from_nanos(0),
        predicted_display_period: xr::Duration::from_nanos(0),
        should_render: xr::FALSE,
    };
    run.call("xrWaitFrame", (f.wait_frame)(h.session, null(), &mut state))?;
    run.call("xrBeginFrame", (f.begin_frame)(h.session, null()))?;
    let info = xr::ViewLocateInfo {
        ty: xr::StructureType::VIEW_LOCATE_INFO,
        next: null(),
        view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
        display_time: state.predicted_display_time,
        space: h.space,
    };
    let mut view_state = xr::ViewState {
        ty: xr::StructureType::VIEW_STATE,
        next: null_mut(),
        view_state_flags: xr::ViewStateFlags::EMPTY,
    };
    let mut views = [xr::View {
        ty: xr::StructureType::VIEW,
        next: null_mut(),
        pose: xr::Posef::IDENTITY,
        fov: xr::Fovf::default(),
    }; 2];
    let mut n = 0;
    run.call(
        "xrLocateViews",
        (f.locate_views)(
            h.session,
            &info,
            &mut view_state,
            2,
            &mut n,
            views.as_mut_ptr(),
        ),
    )?;
    let mut index = 0;
    run.call(
        "xrAcquireSwapchainImage",
        (f.acquire)(h.swapchain, null(), &mut index),
    )?;
    let wait = xr::SwapchainImageWaitInfo {
        ty: xr::StructureType::SWAPCHAIN_IMAGE_WAIT_INFO,
        next: null(),
        timeout: xr::Duration::INFINITE,
    };
    run.call("xrWaitSwapchainImage", (f.wait_image)(h.swapchain, &wait))?;
    run.call("xrReleaseSwapchainImage", (f.release)(h.swapchain, null()))?;
    let pviews: Vec<xr::CompositionLayerProjectionView> = views
        .iter()
        .enumerate()
        .map(|(i, v)| xr::CompositionLayerProjectionView {
            ty: xr::StructureType::COMPOSITION_LAYER_PROJECTION_VIEW,
            next: null(),
            pose: v.pose,
            fov: v.fov,
            sub_image: xr::SwapchainSubImage {
                swapchain: h.swapchain,
                image_rect: xr::Rect2Di {
                    offset: xr::Offset2Di { x: 0, y: 0 },
                    extent: xr::Extent2Di {
                        width: size[0] as i32,
                        height: size[1] as i32,
                    },
                },
                image_array_index: i as u32,
            },
        })
        .collect();
    let projection = xr::CompositionLayerProjection {
        ty: xr::StructureType::COMPOSITION_LAYER_PROJECTION,
        next: null(),
        layer_flags: xr::CompositionLayerFlags::EMPTY,
        space: h.space,
        view_count: 2,
        views: pviews.as_ptr(),
    };
    let layers = [&projection as *const _ as *const xr::CompositionLayerBaseHeader];
    let end = xr::FrameEndInfo {
        ty: xr::StructureType::FRAME_END_INFO,
        next: null(),
        display_time: state.predicted_display_time,
        environment_blend_mode: xr::EnvironmentBlendMode::OPAQUE,
        layer_count: 1,
        layers: layers.as_ptr(),
    };
    run.call("xrEndFrame", (f.end_frame)(h.session, &end))
}

/// Creates the instance of a run (with the fault configured for it); `None` when that failed.
fn create_instance(run: &mut Run, chain: &Chain, extensions: &[&str]) -> Option<xr::Instance> {
    control::set_thread_config(Some(SimConfig {
        faults: run.fault.iter().cloned().collect(),
        ..SimConfig::default()
    }));
    let mut instance = xr::Instance::NULL;
    let r = with_create_info(extensions, API_1_0, |info| unsafe {
        chain.create_instance(info, &mut instance)
    });
    control::set_thread_config(None);
    run.call("xrCreateInstance", r).ok().map(|_| instance)
}

/// The headless session flow, up to the first failure.
unsafe fn headless_flow(run: &mut Run, f: &Fns, h: &mut Handles) -> Step {
    let info = xr::SystemGetInfo {
        ty: xr::StructureType::SYSTEM_GET_INFO,
        next: null(),
        form_factor: xr::FormFactor::HEAD_MOUNTED_DISPLAY,
    };
    let mut system = xr::SystemId::NULL;
    run.call(
        "xrGetSystem",
        (f.get_system)(h.instance, &info, &mut system),
    )?;
    let mut n = 0;
    let stereo = xr::ViewConfigurationType::PRIMARY_STEREO;
    run.call(
        "xrEnumerateViewConfigurationViews",
        (f.enumerate_views)(h.instance, system, stereo, 0, &mut n, null_mut()),
    )?;
    let session_info = xr::SessionCreateInfo {
        ty: xr::StructureType::SESSION_CREATE_INFO,
        next: null(),
        create_flags: xr::SessionCreateFlags::EMPTY,
        system_id: system,
    };
    run.call(
        "xrCreateSession",
        (f.create_session)(h.instance, &session_info, &mut h.session),
    )?;
    session_flow(run, f, h, null(), [64, 64])
}

/// Everything after xrCreateSession: begin, space, a foveated swapchain (chain `swapchain_next`),
/// a profile applied, three frames, exit.
unsafe fn session_flow(
    run: &mut Run,
    f: &Fns,
    h: &mut Handles,
    swapchain_next: *const c_void,
    size: [u32; 2],
) -> Step {
    poll_until(run, f, h, xr::SessionState::READY)?;
    let begin = xr::SessionBeginInfo {
        ty: xr::StructureType::SESSION_BEGIN_INFO,
        next: null(),
        primary_view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
    };
    run.call("xrBeginSession", (f.begin_session)(h.session, &begin))?;
    let space_info = xr::ReferenceSpaceCreateInfo {
        ty: xr::StructureType::REFERENCE_SPACE_CREATE_INFO,
        next: null(),
        reference_space_type: xr::ReferenceSpaceType::LOCAL,
        pose_in_reference_space: xr::Posef::IDENTITY,
    };
    run.call(
        "xrCreateReferenceSpace",
        (f.create_space)(h.session, &space_info, &mut h.space),
    )?;
    let foveation = xr::SwapchainCreateInfoFoveationFB {
        ty: xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
        next: swapchain_next as *mut c_void,
        flags: xr::SwapchainCreateFoveationFlagsFB::EMPTY,
    };
    let sc_info = xr::SwapchainCreateInfo {
        ty: xr::StructureType::SWAPCHAIN_CREATE_INFO,
        next: if swapchain_next.is_null() {
            &foveation as *const _ as *const c_void
        } else {
            swapchain_next
        },
        create_flags: xr::SwapchainCreateFlags::EMPTY,
        usage_flags: xr::SwapchainUsageFlags::COLOR_ATTACHMENT | xr::SwapchainUsageFlags::SAMPLED,
        format: 43,
        sample_count: 1,
        width: size[0],
        height: size[1],
        face_count: 1,
        array_size: 2,
        mip_count: 1,
    };
    run.call(
        "xrCreateSwapchain",
        (f.create_swapchain)(h.session, &sc_info, &mut h.swapchain),
    )?;
    let mut count = 0;
    run.call(
        "xrEnumerateSwapchainImages",
        (f.enumerate_images)(h.swapchain, 0, &mut count, null_mut()),
    )?;
    let level = level_info(3, 0, 0.0);
    let profile_info = xr::FoveationProfileCreateInfoFB {
        ty: xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
        next: &level as *const _ as *mut c_void,
    };
    run.call(
        "xrCreateFoveationProfileFB",
        (f.create_profile)(h.session, &profile_info, &mut h.profile),
    )?;
    let st = foveation_state(h.profile, 0);
    run.call(
        "xrUpdateSwapchainFB",
        (f.update)(h.swapchain, &st as *const _ as *const _),
    )?;
    h.applied = h.profile;
    for _ in 0..3 {
        frame(run, f, h, size)?;
    }
    run.call("xrRequestExitSession", (f.request_exit)(h.session))?;
    poll_until(run, f, h, xr::SessionState::STOPPING)?;
    run.call("xrEndSession", (f.end_session)(h.session))
}

/// Whether fovea intercepts `function`, found as an application could: the pointer the layer chain
/// hands out differs from the runtime's own. Asked on an instance of its own, so faults do not matter.
fn intercepted_by_fovea(function: &str) -> bool {
    let chain = Chain::fovea().unwrap();
    let name = std::ffi::CString::new(function).unwrap();
    let mut instance = xr::Instance::NULL;
    let r = with_create_info(&FOVEATION_EXTENSIONS, API_1_0, |info| unsafe {
        chain.create_instance(info, &mut instance)
    });
    assert_eq!(r, xr::Result::SUCCESS);
    let (mut through_layer, mut runtime) = (None, None);
    unsafe {
        (chain.gipa())(instance, name.as_ptr(), &mut through_layer);
        (fovea_harness::runtime_gipa())(instance, name.as_ptr(), &mut runtime);
        let destroy: xr::pfn::DestroyInstance =
            fovea_harness::lookup(chain.gipa(), instance, c"xrDestroyInstance").unwrap();
        assert_eq!(destroy(instance), xr::Result::SUCCESS);
    }
    through_layer.map(|f| f as usize) != runtime.map(|f| f as usize)
}

/// The loss fovea saw, when the fault was XR_ERROR_SESSION_LOST or XR_ERROR_INSTANCE_LOST on a call
/// it intercepts: from then on its own functions must answer that loss as the runtime does.
fn loss_seen_by_fovea(fault: &Option<Fault>) -> Option<xr::Result> {
    let f = fault.as_ref()?;
    let loss = matches!(
        f.result,
        xr::Result::ERROR_SESSION_LOST | xr::Result::ERROR_INSTANCE_LOST
    );
    (loss && intercepted_by_fovea(&f.function)).then_some(f.result)
}

/// fovea's own state after whatever failed: the swapchain reads back the profile last applied, and
/// a new profile still applies; after a loss fovea saw, all three answer the loss instead.
unsafe fn check_layer_state(f: &Fns, h: &Handles, lost: Option<xr::Result>) {
    if h.swapchain == xr::Swapchain::NULL {
        return;
    }
    let mut st = foveation_state(xr::FoveationProfileFB::from_raw(0x77), 0);
    if let Some(loss) = lost {
        assert_eq!(
            (f.get_state)(h.swapchain, &mut st as *mut _ as *mut _),
            loss
        );
        let info = xr::FoveationProfileCreateInfoFB {
            ty: xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
            next: null_mut(),
        };
        let mut p = xr::FoveationProfileFB::NULL;
        assert_eq!((f.create_profile)(h.session, &info, &mut p), loss);
        let st = foveation_state(h.applied, 0);
        assert_eq!((f.update)(h.swapchain, &st as *const _ as *const _), loss);
        return;
    }
    assert_eq!(
        (f.get_state)(h.swapchain, &mut st as *mut _ as *mut _),
        xr::Result::SUCCESS
    );
    assert_eq!(st.profile, h.applied);
    let mut p = xr::FoveationProfileFB::NULL;
    let info = xr::FoveationProfileCreateInfoFB {
        ty: xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
        next: null_mut(),
    };
    assert_eq!(
        (f.create_profile)(h.session, &info, &mut p),
        xr::Result::SUCCESS
    );
    let st = foveation_state(p, 0);
    assert_eq!(
        (f.update)(h.swapchain, &st as *const _ as *const _),
        xr::Result::SUCCESS
    );
    assert_eq!((f.destroy_profile)(p), xr::Result::SUCCESS);
}

/// Destroys what the run made (children first), retrying the destroy the fault refused.
unsafe fn teardown(run: &mut Run, f: &Fns, h: &Handles) {
    if h.profile != xr::FoveationProfileFB::NULL {
        assert_eq!((f.destroy_profile)(h.profile), xr::Result::SUCCESS);
    }
    if h.swapchain != xr::Swapchain::NULL {
        run.destroy("xrDestroySwapchain", || (f.destroy_swapchain)(h.swapchain));
    }
    if h.space != xr::Space::NULL {
        run.destroy("xrDestroySpace", || (f.destroy_space)(h.space));
    }
    if h.session != xr::Session::NULL {
        run.destroy("xrDestroySession", || (f.destroy_session)(h.session));
    }
    run.destroy("xrDestroyInstance", || (f.destroy_instance)(h.instance));
}

/// After teardown nothing of the run is known to fovea: every handle is invalid there.
unsafe fn assert_forgotten(f: &Fns, h: &Handles) {
    let mut pfn = None;
    assert_eq!(
        (f.gipa)(h.instance, c"xrDestroyInstance".as_ptr(), &mut pfn),
        xr::Result::ERROR_HANDLE_INVALID,
        "fovea still knows the instance"
    );
    if h.session != xr::Session::NULL {
        let info = xr::FoveationProfileCreateInfoFB {
            ty: xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
            next: null_mut(),
        };
        let mut p = xr::FoveationProfileFB::NULL;
        assert_eq!(
            (f.create_profile)(h.session, &info, &mut p),
            xr::Result::ERROR_HANDLE_INVALID,
            "fovea still knows the session"
        );
    }
    if h.swapchain != xr::Swapchain::NULL {
        let mut st = foveation_state(xr::FoveationProfileFB::NULL, 0);
        assert_eq!(
            (f.get_state)(h.swapchain, &mut st as *mut _ as *mut _),
            xr::Result::ERROR_HANDLE_INVALID,
            "fovea still knows the swapchain"
        );
    }
}

/// Runs the headless flow with `fault`; returns the run and the functions the runtime saw.
fn headless_run(chain: &Chain, fault: Option<Fault>) -> (Run, Vec<&'static str>) {
    let mut run = Run {
        fault,
        first_error: None,
        retried: 0,
    };
    let Some(instance) = create_instance(&mut run, chain, &FOVEATION_EXTENSIONS) else {
        assert_eq!(control::live_objects(), 0);
        return (run, Vec::new());
    };
    let mut h = Handles {
        instance,
        ..Handles::default()
    };
    unsafe {
        let f = Fns::load(chain, instance);
        let flowed = headless_flow(&mut run, &f, &mut h);
        if flowed.is_err() {
            check_layer_state(&f, &h, loss_seen_by_fovea(&run.fault));
        }
        teardown(&mut run, &f, &h);
        assert_forgotten(&f, &h);
    }
    assert_eq!(control::live_objects(), 0, "the runtime holds objects");
    let seen = control::journal(instance)
        .iter()
        .map(|c| c.function)
        .collect();
    (run, seen)
}

/// The errors each call is made to fail with: its own typical failures, and for every call
/// XR_ERROR_RUNTIME_FAILURE and XR_ERROR_INSTANCE_LOST.
fn errors_for(function: &str) -> Vec<xr::Result> {
    use xr::Result as R;
    let mut errors = vec![R::ERROR_RUNTIME_FAILURE, R::ERROR_INSTANCE_LOST];
    match function {
        "xrCreateInstance" | "xrCreateSession" | "xrCreateReferenceSpace" => {
            errors.push(R::ERROR_OUT_OF_MEMORY)
        }
        "xrCreateSwapchain" => errors.extend([
            R::ERROR_SWAPCHAIN_FORMAT_UNSUPPORTED,
            R::ERROR_OUT_OF_MEMORY,
            R::ERROR_SESSION_LOST,
        ]),
        "xrGetSystem" => errors.push(R::ERROR_FORM_FACTOR_UNAVAILABLE),
        "xrEnumerateViewConfigurationViews" | "xrPollEvent" | "xrDestroyInstance" => {}
        _ => errors.push(R::ERROR_SESSION_LOST),
    }
    errors
}

/// Every runtime call of the flow, in turn, with each of its errors.
fn faults_for(seen: &[&'static str]) -> Vec<Fault> {
    let mut faults = Vec::new();
    for (k, function) in seen.iter().enumerate() {
        let nth = seen[..=k].iter().filter(|f| *f == function).count() as u32;
        for result in errors_for(function) {
            faults.push(Fault {
                function: function.to_string(),
                result,
                nth,
            });
        }
    }
    faults
}

#[test]
fn every_runtime_call_of_a_headless_session_failing_in_turn() {
    in_own_process(
        module_path!(),
        "every_runtime_call_of_a_headless_session_failing_in_turn",
        every_runtime_call_of_a_headless_session_failing_in_turn_here,
    );
}

fn every_runtime_call_of_a_headless_session_failing_in_turn_here() {
    let chain = Chain::fovea().unwrap();
    let (clean, seen) = headless_run(&chain, None);
    assert_eq!(clean.first_error, None);
    assert!(seen.len() > 30, "{seen:?}");
    let faults = faults_for(&seen);
    let mut retried = 0;
    for fault in &faults {
        let (run, _) = headless_run(&chain, Some(fault.clone()));
        if fault.function == "xrGetInstanceProperties" && fault.nth == 1 {
            // fovea's own call, for the runtime's name in its log header: a failure costs the
            // header its runtime name and nothing else, but a lost instance stays lost and the
            // application's next call says so.
            let lost = fault.result == xr::Result::ERROR_INSTANCE_LOST
                && run
                    .first_error
                    .is_some_and(|(_, r)| r == xr::Result::ERROR_INSTANCE_LOST);
            assert!(
                run.first_error.is_none() || lost,
                "{fault:?}: {:?}",
                run.first_error
            );
            continue;
        }
        // The application saw exactly the runtime's error, from the call that failed.
        assert_eq!(
            run.first_error.map(|(f, r)| (f.to_string(), r)),
            Some((fault.function.clone(), fault.result)),
            "{fault:?}"
        );
        retried += run.retried;
    }
    let losses = faults
        .iter()
        .filter(|f| !f.function.starts_with("xrDestroy"))
        .filter(|f| loss_seen_by_fovea(&Some((*f).clone())).is_some())
        .count();
    eprintln!(
        "fault_injection: {} runtime calls, {} faults injected, {losses} losses fovea saw and \
         answered, {retried} refused destroys retried",
        seen.len(),
        faults.len()
    );
}

// ---------------------------------------------------------------------------------------------
// Vulkan: faults around density images on lavapipe, under the validation layer.

const VULKAN_EXTENSIONS: [&str; 5] = [
    "XR_KHR_vulkan_enable2",
    "XR_FB_swapchain_update_state",
    "XR_FB_foveation",
    "XR_FB_foveation_configuration",
    "XR_FB_foveation_vulkan",
];

/// One Vulkan run with `fault`: a session on lavapipe with a FRAGMENT_DENSITY_MAP swapchain, frames,
/// teardown, then the device destroyed under the validation layer. `Err` with a reason to skip.
fn vulkan_run(chain: &Chain, entry: &ash::Entry, fault: Option<Fault>) -> Result<Run, String> {
    let mut run = Run {
        fault,
        first_error: None,
        retried: 0,
    };
    let instance = create_instance(&mut run, chain, &VULKAN_EXTENSIONS).expect("xrCreateInstance");
    let mut h = Handles {
        instance,
        ..Handles::default()
    };
    unsafe {
        let f = Fns::load(chain, instance);
        let info = xr::SystemGetInfo {
            ty: xr::StructureType::SYSTEM_GET_INFO,
            next: null(),
            form_factor: xr::FormFactor::HEAD_MOUNTED_DISPLAY,
        };
        let mut sys = xr::SystemId::NULL;
        assert_eq!(
            (f.get_system)(instance, &info, &mut sys),
            xr::Result::SUCCESS
        );
        let v = match Vulkan::through_xr(entry, f.gipa, instance, sys) {
            Ok(v) => v,
            Err(why) => {
                assert_eq!((f.destroy_instance)(instance), xr::Result::SUCCESS);
                return Err(why);
            }
        };
        let binding = v.binding();
        let session_info = xr::SessionCreateInfo {
            ty: xr::StructureType::SESSION_CREATE_INFO,
            next: &binding as *const _ as *const c_void,
            create_flags: xr::SessionCreateFlags::EMPTY,
            system_id: sys,
        };
        let fdm = xr::SwapchainCreateInfoFoveationFB {
            ty: xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
            next: null_mut(),
            flags: xr::SwapchainCreateFoveationFlagsFB::FRAGMENT_DENSITY_MAP,
        };
        let flowed = run
            .call(
                "xrCreateSession",
                (f.create_session)(instance, &session_info, &mut h.session),
            )
            .and_then(|_| {
                session_flow(
                    &mut run,
                    &f,
                    &mut h,
                    &fdm as *const _ as *const c_void,
                    [320, 256],
                )
            });
        if flowed.is_err() {
            check_layer_state(&f, &h, loss_seen_by_fovea(&run.fault));
        }
        teardown(&mut run, &f, &h);
        assert_forgotten(&f, &h);
        // The validation layer reports every object still alive on the device here.
        v.destroy();
    }
    assert_eq!(control::live_objects(), 0, "the runtime holds objects");
    let messages = take_messages();
    assert!(
        messages.is_empty(),
        "{:?}: validation reported {} message(s):\n{}",
        run.fault,
        messages.len(),
        messages.join("\n")
    );
    Ok(run)
}

#[test]
fn faults_around_density_images_leave_no_vulkan_object_behind() {
    in_own_process(
        module_path!(),
        "faults_around_density_images_leave_no_vulkan_object_behind",
        faults_around_density_images_leave_no_vulkan_object_behind_here,
    );
}

fn faults_around_density_images_leave_no_vulkan_object_behind_here() {
    pick_lavapipe();
    let Ok(entry) = validated_entry().map_err(|why| skip(&why)) else {
        return;
    };
    let chain = Chain::fovea().unwrap();
    let fault = |function: &str, result, nth| {
        Some(Fault {
            function: function.into(),
            result,
            nth,
        })
    };
    use xr::Result as R;
    let runs = [
        None,
        fault("xrCreateSession", R::ERROR_OUT_OF_MEMORY, 1),
        fault(
            "xrCreateSwapchain",
            R::ERROR_SWAPCHAIN_FORMAT_UNSUPPORTED,
            1,
        ),
        fault("xrCreateSwapchain", R::ERROR_RUNTIME_FAILURE, 1),
        // fovea's own count of the new swapchain's images: the swapchain works without density
        // images, and the application's call succeeds.
        fault("xrEnumerateSwapchainImages", R::ERROR_RUNTIME_FAILURE, 1),
        fault("xrEnumerateSwapchainImages", R::ERROR_SESSION_LOST, 2),
        fault("xrAcquireSwapchainImage", R::ERROR_SESSION_LOST, 1),
        fault("xrAcquireSwapchainImage", R::ERROR_RUNTIME_FAILURE, 2),
        fault("xrEndFrame", R::ERROR_SESSION_LOST, 2),
        fault("xrDestroySwapchain", R::ERROR_RUNTIME_FAILURE, 1),
        fault("xrDestroySession", R::ERROR_INSTANCE_LOST, 1),
        fault("xrDestroyInstance", R::ERROR_RUNTIME_FAILURE, 1),
    ];
    for fault in runs {
        let run = match vulkan_run(&chain, &entry, fault.clone()) {
            Ok(run) => run,
            Err(why) => {
                skip(&why);
                return;
            }
        };
        match &fault {
            None => assert_eq!(run.first_error, None),
            Some(f) if f.function == "xrEnumerateSwapchainImages" && f.nth == 1 => {
                assert_eq!(
                    run.first_error, None,
                    "fovea's own call failed; the app's did not"
                )
            }
            Some(f) => assert_eq!(
                run.first_error.map(|(n, r)| (n.to_string(), r)),
                Some((f.function.clone(), f.result)),
            ),
        }
    }
}
