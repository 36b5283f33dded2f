//! Calls into the simulated runtime the way a loader would: through its xrGetInstanceProcAddr.

use std::ffi::CString;

use fovea_sim::control::{set_thread_config, SimConfig};
use openxr_sys as xr;
use openxr_sys::Handle;

/// Looks `name` up and casts it to its PFN type `T`.
pub fn load<T: Copy>(instance: xr::Instance, name: &str) -> T {
    assert_eq!(
        std::mem::size_of::<T>(),
        std::mem::size_of::<xr::pfn::VoidFunction>()
    );
    let c = CString::new(name).unwrap();
    let mut f = None;
    let r = unsafe { fovea_sim::get_instance_proc_addr(instance, c.as_ptr(), &mut f) };
    assert_eq!(r, xr::Result::SUCCESS, "{name}");
    let f = f.expect("success comes with a pointer");
    unsafe { std::mem::transmute_copy(&f) }
}

/// `xrfn!(instance, CreateSession)` is `xrCreateSession` as `pfn::CreateSession`.
#[macro_export]
macro_rules! xrfn {
    ($instance:expr, $name:ident) => {
        $crate::common::load::<openxr_sys::pfn::$name>($instance, concat!("xr", stringify!($name)))
    };
}

pub fn config(headset: &str) -> SimConfig {
    SimConfig::for_headset(fovea_model::headsets::by_id(headset).unwrap())
}

pub fn app_info(api: xr::Version) -> xr::ApplicationInfo {
    let mut info = xr::ApplicationInfo {
        application_name: [0; xr::MAX_APPLICATION_NAME_SIZE],
        application_version: 1,
        engine_name: [0; xr::MAX_ENGINE_NAME_SIZE],
        engine_version: 1,
        api_version: api,
    };
    for (d, s) in info.application_name.iter_mut().zip(b"fovea-sim tests") {
        *d = *s as _;
    }
    info
}

/// xrCreateInstance with `extensions` under `cfg` (set as this thread's configuration).
pub fn try_create_instance(
    cfg: SimConfig,
    extensions: &[&str],
    api: xr::Version,
) -> Result<xr::Instance, xr::Result> {
    set_thread_config(Some(cfg));
    let names: Vec<CString> = extensions
        .iter()
        .map(|e| CString::new(*e).unwrap())
        .collect();
    let ptrs: Vec<*const std::ffi::c_char> = names.iter().map(|n| n.as_ptr()).collect();
    let info = xr::InstanceCreateInfo {
        ty: xr::InstanceCreateInfo::TYPE,
        next: std::ptr::null(),
        create_flags: xr::InstanceCreateFlags::EMPTY,
        application_info: app_info(api),
        enabled_api_layer_count: 0,
        enabled_api_layer_names: std::ptr::null(),
        enabled_extension_count: ptrs.len() as u32,
        enabled_extension_names: ptrs.as_ptr(),
    };
    let create = xrfn!(xr::Instance::NULL, CreateInstance);
    let mut instance = xr::Instance::NULL;
    match unsafe { create(&info, &mut instance) } {
        xr::Result::SUCCESS => Ok(instance),
        e => Err(e),
    }
}

pub fn create_instance(cfg: SimConfig, extensions: &[&str]) -> xr::Instance {
    try_create_instance(cfg, extensions, xr::Version::new(1, 0, 34)).unwrap()
}

pub fn system(instance: xr::Instance) -> xr::SystemId {
    let get = xrfn!(instance, GetSystem);
    let info = xr::SystemGetInfo {
        ty: xr::SystemGetInfo::TYPE,
        next: std::ptr::null(),
        form_factor: xr::FormFactor::HEAD_MOUNTED_DISPLAY,
    };
    let mut id = xr::SystemId::NULL;
    assert_eq!(
        unsafe { get(instance, &info, &mut id) },
        xr::Result::SUCCESS
    );
    id
}

/// Session state changes waiting in the event queue.
pub fn poll_states(instance: xr::Instance) -> Vec<xr::SessionState> {
    let poll = xrfn!(instance, PollEvent);
    let mut states = Vec::new();
    loop {
        let mut buffer = xr::EventDataBuffer {
            ty: xr::EventDataBuffer::TYPE,
            next: std::ptr::null(),
            varying: [0; 4000],
        };
        match unsafe { poll(instance, &mut buffer) } {
            xr::Result::EVENT_UNAVAILABLE => return states,
            xr::Result::SUCCESS => {
                assert_eq!(
                    buffer.ty,
                    xr::StructureType::EVENT_DATA_SESSION_STATE_CHANGED
                );
                let e =
                    unsafe { &*(&buffer as *const _ as *const xr::EventDataSessionStateChanged) };
                states.push(e.state);
            }
            e => panic!("xrPollEvent: {e:?}"),
        }
    }
}

pub fn create_session_with(
    instance: xr::Instance,
    next: *const std::ffi::c_void,
) -> Result<xr::Session, xr::Result> {
    let create = xrfn!(instance, CreateSession);
    let info = xr::SessionCreateInfo {
        ty: xr::SessionCreateInfo::TYPE,
        next,
        create_flags: xr::SessionCreateFlags::EMPTY,
        system_id: system(instance),
    };
    let mut session = xr::Session::NULL;
    match unsafe { create(instance, &info, &mut session) } {
        xr::Result::SUCCESS => Ok(session),
        e => Err(e),
    }
}

pub fn begin_session(instance: xr::Instance, session: xr::Session) -> xr::Result {
    let begin = xrfn!(instance, BeginSession);
    let info = xr::SessionBeginInfo {
        ty: xr::SessionBeginInfo::TYPE,
        next: std::ptr::null(),
        primary_view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
    };
    unsafe { begin(session, &info) }
}

/// A headless instance with a running session.
pub fn headless(cfg: SimConfig) -> (xr::Instance, xr::Session) {
    let instance = create_instance(cfg, &["XR_MND_headless"]);
    let session = create_session_with(instance, std::ptr::null()).unwrap();
    assert_eq!(begin_session(instance, session), xr::Result::SUCCESS);
    (instance, session)
}

pub fn wait_frame(
    instance: xr::Instance,
    session: xr::Session,
) -> Result<xr::FrameState, xr::Result> {
    let wait = xrfn!(instance, WaitFrame);
    let mut state = xr::FrameState {
        ty: xr::FrameState::TYPE,
        next: std::ptr::null_mut(),
        predicted_display_time: xr::Time::from_nanos(0),
        predicted_display_period: xr::Duration::from_nanos(0),
        should_render: xr::FALSE,
    };
    match unsafe { wait(session, std::ptr::null(), &mut state) } {
        xr::Result::SUCCESS => Ok(state),
        e => Err(e),
    }
}

pub fn begin_frame(instance: xr::Instance, session: xr::Session) -> xr::Result {
    let begin = xrfn!(instance, BeginFrame);
    let info = xr::FrameBeginInfo {
        ty: xr::FrameBeginInfo::TYPE,
        next: std::ptr::null(),
    };
    unsafe { begin(session, &info) }
}

pub fn end_frame(
    instance: xr::Instance,
    session: xr::Session,
    time: xr::Time,
    layers: &[*const xr::CompositionLayerBaseHeader],
) -> xr::Result {
    let end = xrfn!(instance, EndFrame);
    let info = xr::FrameEndInfo {
        ty: xr::FrameEndInfo::TYPE,
        next: std::ptr::null(),
        display_time: time,
        environment_blend_mode: xr::EnvironmentBlendMode::OPAQUE,
        layer_count: layers.len() as u32,
        layers: layers.as_ptr(),
    };
    unsafe { end(session, &info) }
}

/// One empty frame; returns the predicted display time.
pub fn empty_frame(instance: xr::Instance, session: xr::Session) -> xr::Time {
    let state = wait_frame(instance, session).unwrap();
    assert_eq!(begin_frame(instance, session), xr::Result::SUCCESS);
    assert_eq!(
        end_frame(instance, session, state.predicted_display_time, &[]),
        xr::Result::SUCCESS
    );
    state.predicted_display_time
}

pub fn reference_space(
    instance: xr::Instance,
    session: xr::Session,
    ty: xr::ReferenceSpaceType,
) -> xr::Space {
    let create = xrfn!(instance, CreateReferenceSpace);
    let info = xr::ReferenceSpaceCreateInfo {
        ty: xr::ReferenceSpaceCreateInfo::TYPE,
        next: std::ptr::null(),
        reference_space_type: ty,
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
    assert_eq!(
        unsafe { create(session, &info, &mut space) },
        xr::Result::SUCCESS
    );
    space
}

pub fn swapchain_info(
    format: i64,
    width: u32,
    height: u32,
    array_size: u32,
) -> xr::SwapchainCreateInfo {
    xr::SwapchainCreateInfo {
        ty: xr::SwapchainCreateInfo::TYPE,
        next: std::ptr::null(),
        create_flags: xr::SwapchainCreateFlags::EMPTY,
        usage_flags: xr::SwapchainUsageFlags::COLOR_ATTACHMENT | xr::SwapchainUsageFlags::SAMPLED,
        format,
        sample_count: 1,
        width,
        height,
        face_count: 1,
        array_size,
        mip_count: 1,
    }
}

pub fn create_swapchain(
    instance: xr::Instance,
    session: xr::Session,
    info: &xr::SwapchainCreateInfo,
) -> Result<xr::Swapchain, xr::Result> {
    let create = xrfn!(instance, CreateSwapchain);
    let mut sc = xr::Swapchain::NULL;
    match unsafe { create(session, info, &mut sc) } {
        xr::Result::SUCCESS => Ok(sc),
        e => Err(e),
    }
}

/// Acquire, wait and release one image; returns its index.
pub fn cycle_image(instance: xr::Instance, swapchain: xr::Swapchain) -> u32 {
    let acquire = xrfn!(instance, AcquireSwapchainImage);
    let wait = xrfn!(instance, WaitSwapchainImage);
    let release = xrfn!(instance, ReleaseSwapchainImage);
    let mut index = u32::MAX;
    unsafe {
        assert_eq!(
            acquire(swapchain, std::ptr::null(), &mut index),
            xr::Result::SUCCESS
        );
        let wi = xr::SwapchainImageWaitInfo {
            ty: xr::SwapchainImageWaitInfo::TYPE,
            next: std::ptr::null(),
            timeout: xr::Duration::INFINITE,
        };
        assert_eq!(wait(swapchain, &wi), xr::Result::SUCCESS);
        assert_eq!(release(swapchain, std::ptr::null()), xr::Result::SUCCESS);
    }
    index
}

pub fn destroy_instance(instance: xr::Instance) {
    let destroy = xrfn!(instance, DestroyInstance);
    assert_eq!(unsafe { destroy(instance) }, xr::Result::SUCCESS);
}
