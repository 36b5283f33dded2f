//! A running headless session with one stereo swapchain and the frame loop a typical application
//! runs: wait, begin, locate views, acquire/wait/release, end with one two-view projection layer.
//! Used by the per-frame benchmark, the demo and the frame-pipeline tests, so all three measure the
//! same loop. Every call after set-up reuses preallocated structs: the loop itself allocates nothing.

use openxr_sys as xr;
use xr::Handle;

use crate::App;

/// The functions the loop calls, looked up once.
struct Fns {
    poll_event: xr::pfn::PollEvent,
    begin_session: xr::pfn::BeginSession,
    wait_frame: xr::pfn::WaitFrame,
    begin_frame: xr::pfn::BeginFrame,
    end_frame: xr::pfn::EndFrame,
    locate_views: xr::pfn::LocateViews,
    acquire: xr::pfn::AcquireSwapchainImage,
    wait_image: xr::pfn::WaitSwapchainImage,
    release: xr::pfn::ReleaseSwapchainImage,
    destroy_swapchain: xr::pfn::DestroySwapchain,
    destroy_space: xr::pfn::DestroySpace,
    destroy_session: xr::pfn::DestroySession,
}

/// What the frame loop's swapchain is created with.
#[derive(Clone, Copy, Debug)]
pub struct SwapchainSpec {
    /// Chain an `XrSwapchainCreateInfoFoveationFB` (flags 0: headless sessions have no Vulkan).
    pub foveation: bool,
    /// 2: one multiview swapchain, a layer per eye. 1: side by side, double width.
    pub array_size: u32,
}

/// A headless session in the FOCUSED state with one swapchain.
pub struct HeadlessLoop {
    pub app: App,
    pub session: xr::Session,
    pub space: xr::Space,
    pub swapchain: xr::Swapchain,
    /// Per-eye size from xrEnumerateViewConfigurationViews.
    pub eye_size: [u32; 2],
    pub last_frame_state: xr::FrameState,
    fns: Fns,
    views: [xr::View; 2],
    projection_views: [xr::CompositionLayerProjectionView; 2],
    frames: u64,
}

/// Extensions a foveating headless app enables.
pub const FOVEATION_EXTENSIONS: [&str; 4] = [
    "XR_FB_swapchain_update_state",
    "XR_FB_foveation",
    "XR_FB_foveation_configuration",
    "XR_MND_headless",
];

impl HeadlessLoop {
    /// Creates the session, begins it, and makes the swapchain.
    pub fn new(app: App, spec: SwapchainSpec) -> Result<HeadlessLoop, String> {
        // SAFETY: every name's type matches; pointers passed below are valid for the calls.
        unsafe {
            let fns = Fns {
                poll_event: app.func(c"xrPollEvent"),
                begin_session: app.func(c"xrBeginSession"),
                wait_frame: app.func(c"xrWaitFrame"),
                begin_frame: app.func(c"xrBeginFrame"),
                end_frame: app.func(c"xrEndFrame"),
                locate_views: app.func(c"xrLocateViews"),
                acquire: app.func(c"xrAcquireSwapchainImage"),
                wait_image: app.func(c"xrWaitSwapchainImage"),
                release: app.func(c"xrReleaseSwapchainImage"),
                destroy_swapchain: app.func(c"xrDestroySwapchain"),
                destroy_space: app.func(c"xrDestroySpace"),
                destroy_session: app.func(c"xrDestroySession"),
            };
            let session = app
                .headless_session()
                .map_err(|r| format!("xrCreateSession: {r:?}"))?;
            let system = app.system();
            let eye_size = view_size(&app, system)?;
            let mut lp = HeadlessLoop {
                session,
                space: xr::Space::NULL,
                swapchain: xr::Swapchain::NULL,
                eye_size,
                last_frame_state: xr::FrameState {
                    ty: xr::StructureType::FRAME_STATE,
                    next: std::ptr::null_mut(),
                    predicted_display_time: xr::Time::from_nanos(0),
                    predicted_display_period: xr::Duration::from_nanos(0),
                    should_render: xr::FALSE,
                },
                views: [empty_view(); 2],
                projection_views: [empty_projection_view(); 2],
                frames: 0,
                fns,
                app,
            };
            lp.wait_for_state(xr::SessionState::READY)?;
            let begin = xr::SessionBeginInfo {
                ty: xr::StructureType::SESSION_BEGIN_INFO,
                next: std::ptr::null(),
                primary_view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
            };
            check("xrBeginSession", (lp.fns.begin_session)(session, &begin))?;
            let create_space: xr::pfn::CreateReferenceSpace =
                lp.app.func(c"xrCreateReferenceSpace");
            let space_info = xr::ReferenceSpaceCreateInfo {
                ty: xr::StructureType::REFERENCE_SPACE_CREATE_INFO,
                next: std::ptr::null(),
                reference_space_type: xr::ReferenceSpaceType::LOCAL,
                pose_in_reference_space: xr::Posef::IDENTITY,
            };
            check(
                "xrCreateReferenceSpace",
                create_space(session, &space_info, &mut lp.space),
            )?;
            lp.swapchain = lp.create_swapchain(spec)?;
            for (i, pv) in lp.projection_views.iter_mut().enumerate() {
                pv.sub_image.swapchain = lp.swapchain;
                let (x, layer) = if spec.array_size >= 2 {
                    (0, i as u32)
                } else {
                    (i as i32 * eye_size[0] as i32, 0)
                };
                pv.sub_image.image_rect = xr::Rect2Di {
                    offset: xr::Offset2Di { x, y: 0 },
                    extent: xr::Extent2Di {
                        width: eye_size[0] as i32,
                        height: eye_size[1] as i32,
                    },
                };
                pv.sub_image.image_array_index = layer;
            }
            Ok(lp)
        }
    }

    unsafe fn create_swapchain(&self, spec: SwapchainSpec) -> Result<xr::Swapchain, String> {
        let create: xr::pfn::CreateSwapchain = self.app.func(c"xrCreateSwapchain");
        let foveation = xr::SwapchainCreateInfoFoveationFB {
            ty: xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
            next: std::ptr::null_mut(),
            flags: xr::SwapchainCreateFoveationFlagsFB::EMPTY,
        };
        let info = xr::SwapchainCreateInfo {
            ty: xr::StructureType::SWAPCHAIN_CREATE_INFO,
            next: if spec.foveation {
                &foveation as *const _ as *const _
            } else {
                std::ptr::null()
            },
            create_flags: xr::SwapchainCreateFlags::EMPTY,
            usage_flags: xr::SwapchainUsageFlags::COLOR_ATTACHMENT
                | xr::SwapchainUsageFlags::SAMPLED,
            format: 43, // VK_FORMAT_R8G8B8A8_SRGB
            sample_count: 1,
            width: if spec.array_size >= 2 {
                self.eye_size[0]
            } else {
                2 * self.eye_size[0]
            },
            height: self.eye_size[1],
            face_count: 1,
            array_size: spec.array_size.max(1),
            mip_count: 1,
        };
        let mut swapchain = xr::Swapchain::NULL;
        check(
            "xrCreateSwapchain",
            create(self.session, &info, &mut swapchain),
        )?;
        Ok(swapchain)
    }

    /// Polls events until the session reaches `state`.
    pub fn wait_for_state(&mut self, state: xr::SessionState) -> Result<(), String> {
        for _ in 0..64 {
            let mut event = xr::EventDataBuffer {
                ty: xr::StructureType::EVENT_DATA_BUFFER,
                next: std::ptr::null(),
                varying: [0; 4000],
            };
            // SAFETY: the buffer is valid for the call.
            let r = unsafe { (self.fns.poll_event)(self.app.instance, &mut event) };
            if r == xr::Result::EVENT_UNAVAILABLE {
                continue;
            }
            check("xrPollEvent", r)?;
            if event.ty == xr::StructureType::EVENT_DATA_SESSION_STATE_CHANGED {
                // SAFETY: the type says what the buffer holds.
                let changed =
                    unsafe { &*(&event as *const _ as *const xr::EventDataSessionStateChanged) };
                if changed.state == state {
                    return Ok(());
                }
            }
        }
        Err(format!("session never reached {state:?}"))
    }

    /// Polls every queued event, as an application does once a frame: each event's type and, for a
    /// session state change, the new state.
    pub fn poll_events(&mut self) -> Vec<(xr::StructureType, Option<xr::SessionState>)> {
        let mut got = Vec::new();
        loop {
            let mut event = xr::EventDataBuffer {
                ty: xr::StructureType::EVENT_DATA_BUFFER,
                next: std::ptr::null(),
                varying: [0; 4000],
            };
            // SAFETY: the buffer is valid for the call.
            let r = unsafe { (self.fns.poll_event)(self.app.instance, &mut event) };
            if r != xr::Result::SUCCESS {
                return got;
            }
            let state =
                (event.ty == xr::StructureType::EVENT_DATA_SESSION_STATE_CHANGED).then(|| {
                    // SAFETY: the type says what the buffer holds.
                    unsafe {
                        (*(&event as *const _ as *const xr::EventDataSessionStateChanged)).state
                    }
                });
            got.push((event.ty, state));
        }
    }

    /// One frame. Returns the first failing call's name and result.
    pub fn frame(&mut self) -> Result<(), (&'static str, xr::Result)> {
        let f = &self.fns;
        let on = |name: &'static str, r: xr::Result| {
            if r.into_raw() < 0 {
                Err((name, r))
            } else {
                Ok(())
            }
        };
        // SAFETY: every struct passed is valid and lives across its call.
        unsafe {
            let wait_info = xr::FrameWaitInfo {
                ty: xr::StructureType::FRAME_WAIT_INFO,
                next: std::ptr::null(),
            };
            on(
                "xrWaitFrame",
                (f.wait_frame)(self.session, &wait_info, &mut self.last_frame_state),
            )?;
            let begin_info = xr::FrameBeginInfo {
                ty: xr::StructureType::FRAME_BEGIN_INFO,
                next: std::ptr::null(),
            };
            on("xrBeginFrame", (f.begin_frame)(self.session, &begin_info))?;
            let display_time = self.last_frame_state.predicted_display_time;
            let locate = xr::ViewLocateInfo {
                ty: xr::StructureType::VIEW_LOCATE_INFO,
                next: std::ptr::null(),
                view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
                display_time,
                space: self.space,
            };
            let mut view_state = xr::ViewState {
                ty: xr::StructureType::VIEW_STATE,
                next: std::ptr::null_mut(),
                view_state_flags: xr::ViewStateFlags::EMPTY,
            };
            let mut n = 0;
            on(
                "xrLocateViews",
                (f.locate_views)(
                    self.session,
                    &locate,
                    &mut view_state,
                    2,
                    &mut n,
                    self.views.as_mut_ptr(),
                ),
            )?;
            let mut index = 0;
            let acquire_info = xr::SwapchainImageAcquireInfo {
                ty: xr::StructureType::SWAPCHAIN_IMAGE_ACQUIRE_INFO,
                next: std::ptr::null(),
            };
            on(
                "xrAcquireSwapchainImage",
                (f.acquire)(self.swapchain, &acquire_info, &mut index),
            )?;
            let wait_image = xr::SwapchainImageWaitInfo {
                ty: xr::StructureType::SWAPCHAIN_IMAGE_WAIT_INFO,
                next: std::ptr::null(),
                timeout: xr::Duration::INFINITE,
            };
            on(
                "xrWaitSwapchainImage",
                (f.wait_image)(self.swapchain, &wait_image),
            )?;
            let release_info = xr::SwapchainImageReleaseInfo {
                ty: xr::StructureType::SWAPCHAIN_IMAGE_RELEASE_INFO,
                next: std::ptr::null(),
            };
            on(
                "xrReleaseSwapchainImage",
                (f.release)(self.swapchain, &release_info),
            )?;
            for (pv, v) in self.projection_views.iter_mut().zip(&self.views) {
                pv.pose = v.pose;
                pv.fov = v.fov;
            }
            let projection = xr::CompositionLayerProjection {
                ty: xr::StructureType::COMPOSITION_LAYER_PROJECTION,
                next: std::ptr::null(),
                layer_flags: xr::CompositionLayerFlags::EMPTY,
                space: self.space,
                view_count: 2,
                views: self.projection_views.as_ptr(),
            };
            let layers = [&projection as *const _ as *const xr::CompositionLayerBaseHeader];
            let end_info = xr::FrameEndInfo {
                ty: xr::StructureType::FRAME_END_INFO,
                next: std::ptr::null(),
                display_time,
                environment_blend_mode: xr::EnvironmentBlendMode::OPAQUE,
                layer_count: 1,
                layers: layers.as_ptr(),
            };
            on("xrEndFrame", (f.end_frame)(self.session, &end_info))?;
        }
        self.frames += 1;
        Ok(())
    }

    /// Frames run so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// A function through the application's chain.
    ///
    /// # Safety
    /// `F` must be the function type the name implies.
    pub unsafe fn func<F: Copy>(&self, name: &std::ffi::CStr) -> F {
        self.app.func(name)
    }

    /// Applies a foveation profile of `level` (dynamic or not) to the loop's swapchain with
    /// xrUpdateSwapchainFB, then destroys the profile (the swapchain keeps a copy of its state).
    /// `Err` names the call that failed, or says the chain lacks XR_FB_foveation.
    pub fn apply_profile(
        &self,
        level: xr::FoveationLevelFB,
        dynamic: xr::FoveationDynamicFB,
    ) -> Result<(), String> {
        // SAFETY: the names' types match; the structs live across the calls.
        unsafe {
            let create: xr::pfn::CreateFoveationProfileFB = self
                .app
                .try_fn(c"xrCreateFoveationProfileFB")
                .map_err(|r| format!("no xrCreateFoveationProfileFB: {r:?}"))?;
            let update: xr::pfn::UpdateSwapchainFB = self.func(c"xrUpdateSwapchainFB");
            let destroy: xr::pfn::DestroyFoveationProfileFB =
                self.func(c"xrDestroyFoveationProfileFB");
            let level_info = xr::FoveationLevelProfileCreateInfoFB {
                ty: xr::StructureType::FOVEATION_LEVEL_PROFILE_CREATE_INFO_FB,
                next: std::ptr::null_mut(),
                level,
                vertical_offset: 0.0,
                dynamic,
            };
            let info = xr::FoveationProfileCreateInfoFB {
                ty: xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
                next: &level_info as *const _ as *mut _,
            };
            let mut profile = xr::FoveationProfileFB::NULL;
            let r = create(self.session, &info, &mut profile);
            if r != xr::Result::SUCCESS {
                return Err(format!("xrCreateFoveationProfileFB: {r:?}"));
            }
            let state = xr::SwapchainStateFoveationFB {
                ty: xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB,
                next: std::ptr::null_mut(),
                flags: xr::SwapchainStateFoveationFlagsFB::EMPTY,
                profile,
            };
            let r = update(self.swapchain, &state as *const _ as *const _);
            destroy(profile);
            if r != xr::Result::SUCCESS {
                return Err(format!("xrUpdateSwapchainFB: {r:?}"));
            }
        }
        Ok(())
    }
}

impl Drop for HeadlessLoop {
    fn drop(&mut self) {
        // SAFETY: the handles are live and owned by this loop.
        unsafe {
            (self.fns.destroy_swapchain)(self.swapchain);
            (self.fns.destroy_space)(self.space);
            (self.fns.destroy_session)(self.session);
        }
    }
}

fn check(name: &str, r: xr::Result) -> Result<(), String> {
    if r.into_raw() < 0 {
        Err(format!("{name}: {r:?}"))
    } else {
        Ok(())
    }
}

unsafe fn view_size(app: &App, system: xr::SystemId) -> Result<[u32; 2], String> {
    let enumerate: xr::pfn::EnumerateViewConfigurationViews =
        app.func(c"xrEnumerateViewConfigurationViews");
    let empty = xr::ViewConfigurationView {
        ty: xr::StructureType::VIEW_CONFIGURATION_VIEW,
        next: std::ptr::null_mut(),
        recommended_image_rect_width: 0,
        max_image_rect_width: 0,
        recommended_image_rect_height: 0,
        max_image_rect_height: 0,
        recommended_swapchain_sample_count: 0,
        max_swapchain_sample_count: 0,
    };
    let mut views = [empty; 2];
    let mut n = 0;
    check(
        "xrEnumerateViewConfigurationViews",
        enumerate(
            app.instance,
            system,
            xr::ViewConfigurationType::PRIMARY_STEREO,
            2,
            &mut n,
            views.as_mut_ptr(),
        ),
    )?;
    Ok([
        views[0].recommended_image_rect_width,
        views[0].recommended_image_rect_height,
    ])
}

fn empty_view() -> xr::View {
    xr::View {
        ty: xr::StructureType::VIEW,
        next: std::ptr::null_mut(),
        pose: xr::Posef::IDENTITY,
        fov: xr::Fovf {
            angle_left: 0.0,
            angle_right: 0.0,
            angle_up: 0.0,
            angle_down: 0.0,
        },
    }
}

fn empty_projection_view() -> xr::CompositionLayerProjectionView {
    xr::CompositionLayerProjectionView {
        ty: xr::StructureType::COMPOSITION_LAYER_PROJECTION_VIEW,
        next: std::ptr::null(),
        pose: xr::Posef::IDENTITY,
        fov: empty_view().fov,
        sub_image: xr::SwapchainSubImage {
            swapchain: xr::Swapchain::NULL,
            image_rect: xr::Rect2Di::default(),
            image_array_index: 0,
        },
    }
}
