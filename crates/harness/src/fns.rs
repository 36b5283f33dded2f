//! The functions of a session's whole life and of the foveation extensions as one table of plain
//! function pointers, looked up once per instance through a chain: for tests that drive most of the
//! API directly, with arguments of their own, many times over (fault injection, random call
//! sequences), rather than through [`crate::App`]'s lookup at each call.

use openxr_sys as xr;

use crate::{lookup, Chain};

/// Every function of a session's life (instance to frames) and of the foveation extensions.
#[derive(Clone, Copy)]
pub struct Fns {
    /// The topmost `xrGetInstanceProcAddr`, for anything else.
    pub gipa: xr::pfn::GetInstanceProcAddr,
    pub destroy_instance: xr::pfn::DestroyInstance,
    pub get_system: xr::pfn::GetSystem,
    pub enumerate_views: xr::pfn::EnumerateViewConfigurationViews,
    pub create_session: xr::pfn::CreateSession,
    pub destroy_session: xr::pfn::DestroySession,
    pub poll_event: xr::pfn::PollEvent,
    pub begin_session: xr::pfn::BeginSession,
    pub request_exit: xr::pfn::RequestExitSession,
    pub end_session: xr::pfn::EndSession,
    pub create_space: xr::pfn::CreateReferenceSpace,
    pub destroy_space: xr::pfn::DestroySpace,
    pub create_swapchain: xr::pfn::CreateSwapchain,
    pub destroy_swapchain: xr::pfn::DestroySwapchain,
    pub enumerate_images: xr::pfn::EnumerateSwapchainImages,
    pub acquire: xr::pfn::AcquireSwapchainImage,
    pub wait_image: xr::pfn::WaitSwapchainImage,
    pub release: xr::pfn::ReleaseSwapchainImage,
    pub wait_frame: xr::pfn::WaitFrame,
    pub begin_frame: xr::pfn::BeginFrame,
    pub end_frame: xr::pfn::EndFrame,
    pub locate_views: xr::pfn::LocateViews,
    pub create_profile: xr::pfn::CreateFoveationProfileFB,
    pub destroy_profile: xr::pfn::DestroyFoveationProfileFB,
    pub update: xr::pfn::UpdateSwapchainFB,
    pub get_state: xr::pfn::GetSwapchainStateFB,
}

impl Fns {
    /// Looks every function up through `chain` for `instance`, which must have XR_FB_foveation and
    /// XR_FB_swapchain_update_state enabled; panics with the name of any function missing.
    ///
    /// # Safety
    /// `instance` was created through `chain` and is live.
    pub unsafe fn load(chain: &Chain, instance: xr::Instance) -> Fns {
        let gipa = chain.gipa();
        macro_rules! get {
            ($name:literal) => {
                lookup(gipa, instance, $name).unwrap_or_else(|r| panic!("{:?}: {r:?}", $name))
            };
        }
        Fns {
            gipa,
            destroy_instance: get!(c"xrDestroyInstance"),
            get_system: get!(c"xrGetSystem"),
            enumerate_views: get!(c"xrEnumerateViewConfigurationViews"),
            create_session: get!(c"xrCreateSession"),
            destroy_session: get!(c"xrDestroySession"),
            poll_event: get!(c"xrPollEvent"),
            begin_session: get!(c"xrBeginSession"),
            request_exit: get!(c"xrRequestExitSession"),
            end_session: get!(c"xrEndSession"),
            create_space: get!(c"xrCreateReferenceSpace"),
            destroy_space: get!(c"xrDestroySpace"),
            create_swapchain: get!(c"xrCreateSwapchain"),
            destroy_swapchain: get!(c"xrDestroySwapchain"),
            enumerate_images: get!(c"xrEnumerateSwapchainImages"),
            acquire: get!(c"xrAcquireSwapchainImage"),
            wait_image: get!(c"xrWaitSwapchainImage"),
            release: get!(c"xrReleaseSwapchainImage"),
            wait_frame: get!(c"xrWaitFrame"),
            begin_frame: get!(c"xrBeginFrame"),
            end_frame: get!(c"xrEndFrame"),
            locate_views: get!(c"xrLocateViews"),
            create_profile: get!(c"xrCreateFoveationProfileFB"),
            destroy_profile: get!(c"xrDestroyFoveationProfileFB"),
            update: get!(c"xrUpdateSwapchainFB"),
            get_state: get!(c"xrGetSwapchainStateFB"),
        }
    }
}
