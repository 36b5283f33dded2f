//! The one list of the OpenXR functions fovea intercepts, from which both tables are expanded: the
//! next layer's pointers ([`crate::xr::next_layer::Next`]) and the hook table with its exported
//! entry points ([`crate::xr::dispatch`]). A function is declared in exactly one place.
//!
//! Each line names the OpenXR function, the field that holds the next layer's pointer, its
//! openxr-sys signature, the hook, and who owns the function, then how each C argument reaches the
//! hook body (see [`crate::xr::ffi::shim!`]). The hook paths and owners are tokens here: they are
//! resolved where the list is expanded, in `dispatch.rs`, so this file imports no hook.

/// Hands the list of intercepted functions to `$table`, a macro that expands it.
macro_rules! with_commands {
    ($table:ident) => {
        $table! {
            c"xrDestroyInstance" => destroy_instance: DestroyInstance =
                hooks::instance::destroy_instance, Owner::Below,
                (instance: val xr::Instance);
            c"xrGetSystemProperties" => get_system_properties: GetSystemProperties =
                hooks::eye_tracked::get_system_properties, Owner::Below,
                (instance: val xr::Instance, system: val xr::SystemId, properties: out xr::SystemProperties);
            c"xrCreateSession" => create_session: CreateSession =
                hooks::session::create_session, Owner::Below,
                (instance: val xr::Instance, info: in xr::SessionCreateInfo, session: out xr::Session);
            c"xrDestroySession" => destroy_session: DestroySession =
                hooks::session::destroy_session, Owner::Below,
                (session: val xr::Session);
            c"xrBeginSession" => begin_session: BeginSession =
                hooks::session::begin_session, Owner::Below,
                (session: val xr::Session, info: in xr::SessionBeginInfo);
            c"xrEndSession" => end_session: EndSession =
                hooks::session::end_session, Owner::Below,
                (session: val xr::Session);
            c"xrEnumerateViewConfigurationViews" => enumerate_view_configuration_views: EnumerateViewConfigurationViews =
                hooks::session::enumerate_view_configuration_views, Owner::Below,
                (instance: val xr::Instance, system: val xr::SystemId, config: val xr::ViewConfigurationType,
                 capacity: val u32, count: out u32, views: (array capacity) xr::ViewConfigurationView);
            c"xrLocateViews" => locate_views: LocateViews =
                hooks::frame::locate_views, Owner::Below,
                (session: val xr::Session, info: in xr::ViewLocateInfo, view_state: out xr::ViewState,
                 capacity: val u32, count: out u32, views: (array capacity) xr::View);
            c"xrWaitFrame" => wait_frame: WaitFrame =
                hooks::frame::wait_frame, Owner::Below,
                (session: val xr::Session, info: in xr::FrameWaitInfo, state: out xr::FrameState);
            c"xrBeginFrame" => begin_frame: BeginFrame =
                hooks::frame::begin_frame, Owner::Below,
                (session: val xr::Session, info: in xr::FrameBeginInfo);
            c"xrEndFrame" => end_frame: EndFrame =
                hooks::frame::end_frame, Owner::Below,
                (session: val xr::Session, info: in xr::FrameEndInfo);
            c"xrCreateSwapchain" => create_swapchain: CreateSwapchain =
                hooks::swapchain::create_swapchain, Owner::Below,
                (session: val xr::Session, info: in xr::SwapchainCreateInfo, swapchain: out xr::Swapchain);
            c"xrDestroySwapchain" => destroy_swapchain: DestroySwapchain =
                hooks::swapchain::destroy_swapchain, Owner::Below,
                (swapchain: val xr::Swapchain);
            c"xrEnumerateSwapchainImages" => enumerate_swapchain_images: EnumerateSwapchainImages =
                hooks::swapchain::enumerate_swapchain_images, Owner::Below,
                (swapchain: val xr::Swapchain, capacity: val u32, count: out u32,
                 images: (array capacity) xr::SwapchainImageBaseHeader);
            c"xrAcquireSwapchainImage" => acquire_swapchain_image: AcquireSwapchainImage =
                hooks::swapchain::acquire_swapchain_image, Owner::Below,
                (swapchain: val xr::Swapchain, info: in xr::SwapchainImageAcquireInfo, index: out u32);
            c"xrWaitSwapchainImage" => wait_swapchain_image: WaitSwapchainImage =
                hooks::swapchain::wait_swapchain_image, Owner::Below,
                (swapchain: val xr::Swapchain, info: in xr::SwapchainImageWaitInfo);
            c"xrReleaseSwapchainImage" => release_swapchain_image: ReleaseSwapchainImage =
                hooks::swapchain::release_swapchain_image, Owner::Below,
                (swapchain: val xr::Swapchain, info: in xr::SwapchainImageReleaseInfo);
            c"xrCreateVulkanInstanceKHR" => create_vulkan_instance: CreateVulkanInstanceKHR =
                hooks::vulkan_layer::create_vulkan_instance, Owner::Below,
                (instance: val xr::Instance, info: in xr::VulkanInstanceCreateInfoKHR,
                 vk_instance: out xr::platform::VkInstance, vk_result: out xr::platform::VkResult);
            c"xrGetVulkanDeviceExtensionsKHR" => get_vulkan_device_extensions: GetVulkanDeviceExtensionsKHR =
                hooks::vulkan_enable::get_vulkan_device_extensions, Owner::Below,
                (instance: val xr::Instance, system: val xr::SystemId, capacity: val u32, count: out u32,
                 buffer: (array capacity) std::ffi::c_char);
            c"xrCreateVulkanDeviceKHR" => create_vulkan_device: CreateVulkanDeviceKHR =
                hooks::vulkan_enable::create_vulkan_device, Owner::Below,
                (instance: val xr::Instance, info: in xr::VulkanDeviceCreateInfoKHR,
                 device: out xr::platform::VkDevice, vk_result: out xr::platform::VkResult);
            c"xrGetVulkanGraphicsDeviceKHR" => get_vulkan_graphics_device: GetVulkanGraphicsDeviceKHR =
                hooks::vulkan_enable::get_vulkan_graphics_device, Owner::Below,
                (instance: val xr::Instance, system: val xr::SystemId,
                 vk_instance: val xr::platform::VkInstance, physical_device: out xr::platform::VkPhysicalDevice);
            c"xrGetVulkanGraphicsDevice2KHR" => get_vulkan_graphics_device2: GetVulkanGraphicsDevice2KHR =
                hooks::vulkan_enable::get_vulkan_graphics_device2, Owner::Below,
                (instance: val xr::Instance, info: in xr::VulkanGraphicsDeviceGetInfoKHR,
                 physical_device: out xr::platform::VkPhysicalDevice);
            c"xrSuggestInteractionProfileBindings" => suggest_interaction_profile_bindings: SuggestInteractionProfileBindings =
                hooks::actions::suggest_bindings, Owner::Gaze,
                (instance: val xr::Instance, info: in xr::InteractionProfileSuggestedBinding);
            c"xrAttachSessionActionSets" => attach_session_action_sets: AttachSessionActionSets =
                hooks::actions::attach_action_sets, Owner::Gaze,
                (session: val xr::Session, info: in xr::SessionActionSetsAttachInfo);
            c"xrSyncActions" => sync_actions: SyncActions =
                hooks::actions::sync_actions, Owner::Gaze,
                (session: val xr::Session, info: in xr::ActionsSyncInfo);
            c"xrGetCurrentInteractionProfile" => get_current_interaction_profile: GetCurrentInteractionProfile =
                hooks::actions::get_current_interaction_profile, Owner::Gaze,
                (session: val xr::Session, path: val xr::Path, profile: out xr::InteractionProfileState);
            c"xrPollEvent" => poll_event: PollEvent =
                hooks::actions::poll_event, Owner::Gaze,
                (instance: val xr::Instance, buffer: out xr::EventDataBuffer);
            c"xrUpdateSwapchainFB" => update_swapchain: UpdateSwapchainFB =
                hooks::foveation::update_swapchain, Owner::Layer(Ext::SwapchainUpdateState),
                (swapchain: val xr::Swapchain, state: in xr::SwapchainStateBaseHeaderFB);
            c"xrGetSwapchainStateFB" => get_swapchain_state: GetSwapchainStateFB =
                hooks::foveation::get_swapchain_state, Owner::Layer(Ext::SwapchainUpdateState),
                (swapchain: val xr::Swapchain, state: out xr::SwapchainStateBaseHeaderFB);
            c"xrCreateFoveationProfileFB" => create_foveation_profile: CreateFoveationProfileFB =
                hooks::foveation::create_profile, Owner::Layer(Ext::Foveation),
                (session: val xr::Session, info: in xr::FoveationProfileCreateInfoFB,
                 profile: out xr::FoveationProfileFB);
            c"xrDestroyFoveationProfileFB" => destroy_foveation_profile: DestroyFoveationProfileFB =
                hooks::foveation::destroy_profile, Owner::Layer(Ext::Foveation),
                (profile: val xr::FoveationProfileFB);
            c"xrGetFoveationEyeTrackedStateMETA" => get_foveation_eye_tracked_state: GetFoveationEyeTrackedStateMETA =
                hooks::eye_tracked::get_state, Owner::Layer(Ext::MetaFoveationEyeTracked),
                (session: val xr::Session, state: out xr::FoveationEyeTrackedStateMETA);
        }
    };
}
pub(crate) use with_commands;
