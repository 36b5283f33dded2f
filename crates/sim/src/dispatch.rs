//! xrGetInstanceProcAddr: the name → function table, following the spec's table
//! (api_initialization.adoc, "xrGetInstanceProcAddr"):
//!
//! - NULL instance: only xrEnumerateInstanceExtensionProperties, xrEnumerateApiLayerProperties and
//!   xrCreateInstance; any other name is XR_ERROR_HANDLE_INVALID.
//! - A valid instance: core commands and commands of *enabled* extensions; anything else is
//!   XR_ERROR_FUNCTION_UNSUPPORTED.
//!
//! On every error `*function` is set to NULL; XR_SUCCESS always comes with a pointer (loaders treat
//! success with NULL as a broken runtime).

use std::ffi::{c_char, CStr};

use openxr_sys as xr;
use openxr_sys::pfn;
use openxr_sys::Handle;

use crate::extensions::{
    FB_FOVEATION, FB_SWAPCHAIN_UPDATE_STATE, KHR_VULKAN_ENABLE, KHR_VULKAN_ENABLE2,
};
use crate::state::world;
use crate::{actions, foveation, frame, instance, session, space, swapchain, system, vulkan};

struct Command {
    name: &'static str,
    /// The extension that must be enabled, `None` for core.
    extension: Option<&'static str>,
    function: pfn::VoidFunction,
}

/// Builds a table entry, checking the Rust function against openxr-sys' exact `PFN_` type.
macro_rules! command {
    ($name:literal, $ext:expr, $f:path as $pfn:ident) => {
        Command {
            name: $name,
            extension: $ext,
            // SAFETY: every PFN has the same representation; the loader casts back to `$pfn`.
            function: unsafe {
                std::mem::transmute::<pfn::$pfn, pfn::VoidFunction>($f as pfn::$pfn)
            },
        }
    };
}

const GLOBAL: [&str; 3] = [
    "xrEnumerateInstanceExtensionProperties",
    "xrEnumerateApiLayerProperties",
    "xrCreateInstance",
];

fn commands() -> &'static [Command] {
    use std::sync::OnceLock;
    static TABLE: OnceLock<Vec<Command>> = OnceLock::new();
    TABLE.get_or_init(|| {
        let core = None;
        let vk1 = Some(KHR_VULKAN_ENABLE);
        let vk2 = Some(KHR_VULKAN_ENABLE2);
        let fb = Some(FB_SWAPCHAIN_UPDATE_STATE);
        let fov = Some(FB_FOVEATION);
        vec![
            command!(
                "xrGetInstanceProcAddr",
                core,
                get_instance_proc_addr as GetInstanceProcAddr
            ),
            command!(
                "xrEnumerateInstanceExtensionProperties",
                core,
                instance::enumerate_instance_extension_properties
                    as EnumerateInstanceExtensionProperties
            ),
            command!(
                "xrEnumerateApiLayerProperties",
                core,
                instance::enumerate_api_layer_properties as EnumerateApiLayerProperties
            ),
            command!(
                "xrCreateInstance",
                core,
                instance::create_instance as CreateInstance
            ),
            command!(
                "xrDestroyInstance",
                core,
                instance::destroy_instance as DestroyInstance
            ),
            command!(
                "xrGetInstanceProperties",
                core,
                instance::get_instance_properties as GetInstanceProperties
            ),
            command!("xrPollEvent", core, instance::poll_event as PollEvent),
            command!(
                "xrResultToString",
                core,
                instance::result_to_string as ResultToString
            ),
            command!(
                "xrStructureTypeToString",
                core,
                instance::structure_type_to_string as StructureTypeToString
            ),
            command!(
                "xrStringToPath",
                core,
                instance::string_to_path as StringToPath
            ),
            command!(
                "xrPathToString",
                core,
                instance::path_to_string as PathToString
            ),
            command!("xrGetSystem", core, system::get_system as GetSystem),
            command!(
                "xrGetSystemProperties",
                core,
                system::get_system_properties as GetSystemProperties
            ),
            command!(
                "xrEnumerateEnvironmentBlendModes",
                core,
                system::enumerate_environment_blend_modes as EnumerateEnvironmentBlendModes
            ),
            command!(
                "xrEnumerateViewConfigurations",
                core,
                system::enumerate_view_configurations as EnumerateViewConfigurations
            ),
            command!(
                "xrGetViewConfigurationProperties",
                core,
                system::get_view_configuration_properties as GetViewConfigurationProperties
            ),
            command!(
                "xrEnumerateViewConfigurationViews",
                core,
                system::enumerate_view_configuration_views as EnumerateViewConfigurationViews
            ),
            command!(
                "xrCreateSession",
                core,
                session::create_session as CreateSession
            ),
            command!(
                "xrDestroySession",
                core,
                session::destroy_session as DestroySession
            ),
            command!(
                "xrBeginSession",
                core,
                session::begin_session as BeginSession
            ),
            command!("xrEndSession", core, session::end_session as EndSession),
            command!(
                "xrRequestExitSession",
                core,
                session::request_exit_session as RequestExitSession
            ),
            command!(
                "xrEnumerateReferenceSpaces",
                core,
                space::enumerate_reference_spaces as EnumerateReferenceSpaces
            ),
            command!(
                "xrCreateReferenceSpace",
                core,
                space::create_reference_space as CreateReferenceSpace
            ),
            command!(
                "xrGetReferenceSpaceBoundsRect",
                core,
                space::get_reference_space_bounds_rect as GetReferenceSpaceBoundsRect
            ),
            command!("xrDestroySpace", core, space::destroy_space as DestroySpace),
            command!("xrLocateSpace", core, space::locate_space as LocateSpace),
            command!("xrLocateViews", core, space::locate_views as LocateViews),
            command!("xrWaitFrame", core, frame::wait_frame as WaitFrame),
            command!("xrBeginFrame", core, frame::begin_frame as BeginFrame),
            command!("xrEndFrame", core, frame::end_frame as EndFrame),
            command!(
                "xrEnumerateSwapchainFormats",
                core,
                swapchain::enumerate_swapchain_formats as EnumerateSwapchainFormats
            ),
            command!(
                "xrCreateSwapchain",
                core,
                swapchain::create_swapchain as CreateSwapchain
            ),
            command!(
                "xrDestroySwapchain",
                core,
                swapchain::destroy_swapchain as DestroySwapchain
            ),
            command!(
                "xrEnumerateSwapchainImages",
                core,
                swapchain::enumerate_swapchain_images as EnumerateSwapchainImages
            ),
            command!(
                "xrAcquireSwapchainImage",
                core,
                swapchain::acquire_swapchain_image as AcquireSwapchainImage
            ),
            command!(
                "xrWaitSwapchainImage",
                core,
                swapchain::wait_swapchain_image as WaitSwapchainImage
            ),
            command!(
                "xrReleaseSwapchainImage",
                core,
                swapchain::release_swapchain_image as ReleaseSwapchainImage
            ),
            command!(
                "xrCreateActionSet",
                core,
                actions::create_action_set as CreateActionSet
            ),
            command!(
                "xrDestroyActionSet",
                core,
                actions::destroy_action_set as DestroyActionSet
            ),
            command!(
                "xrCreateAction",
                core,
                actions::create_action as CreateAction
            ),
            command!(
                "xrDestroyAction",
                core,
                actions::destroy_action as DestroyAction
            ),
            command!(
                "xrSuggestInteractionProfileBindings",
                core,
                actions::suggest_interaction_profile_bindings as SuggestInteractionProfileBindings
            ),
            command!(
                "xrAttachSessionActionSets",
                core,
                actions::attach_session_action_sets as AttachSessionActionSets
            ),
            command!(
                "xrGetCurrentInteractionProfile",
                core,
                actions::get_current_interaction_profile as GetCurrentInteractionProfile
            ),
            command!("xrSyncActions", core, actions::sync_actions as SyncActions),
            command!(
                "xrGetActionStateBoolean",
                core,
                actions::get_action_state_boolean as GetActionStateBoolean
            ),
            command!(
                "xrGetActionStateFloat",
                core,
                actions::get_action_state_float as GetActionStateFloat
            ),
            command!(
                "xrGetActionStateVector2f",
                core,
                actions::get_action_state_vector2f as GetActionStateVector2f
            ),
            command!(
                "xrGetActionStatePose",
                core,
                actions::get_action_state_pose as GetActionStatePose
            ),
            command!(
                "xrApplyHapticFeedback",
                core,
                actions::apply_haptic_feedback as ApplyHapticFeedback
            ),
            command!(
                "xrStopHapticFeedback",
                core,
                actions::stop_haptic_feedback as StopHapticFeedback
            ),
            command!(
                "xrCreateActionSpace",
                core,
                actions::create_action_space as CreateActionSpace
            ),
            command!(
                "xrEnumerateBoundSourcesForAction",
                core,
                actions::enumerate_bound_sources_for_action as EnumerateBoundSourcesForAction
            ),
            command!(
                "xrGetInputSourceLocalizedName",
                core,
                actions::get_input_source_localized_name as GetInputSourceLocalizedName
            ),
            command!(
                "xrGetVulkanInstanceExtensionsKHR",
                vk1,
                vulkan::get_vulkan_instance_extensions as GetVulkanInstanceExtensionsKHR
            ),
            command!(
                "xrGetVulkanDeviceExtensionsKHR",
                vk1,
                vulkan::get_vulkan_device_extensions as GetVulkanDeviceExtensionsKHR
            ),
            command!(
                "xrGetVulkanGraphicsDeviceKHR",
                vk1,
                vulkan::get_vulkan_graphics_device as GetVulkanGraphicsDeviceKHR
            ),
            command!(
                "xrGetVulkanGraphicsRequirementsKHR",
                vk1,
                vulkan::get_vulkan_graphics_requirements as GetVulkanGraphicsRequirementsKHR
            ),
            command!(
                "xrCreateVulkanInstanceKHR",
                vk2,
                vulkan::create_vulkan_instance as CreateVulkanInstanceKHR
            ),
            command!(
                "xrCreateVulkanDeviceKHR",
                vk2,
                vulkan::create_vulkan_device as CreateVulkanDeviceKHR
            ),
            command!(
                "xrGetVulkanGraphicsDevice2KHR",
                vk2,
                vulkan::get_vulkan_graphics_device2 as GetVulkanGraphicsDevice2KHR
            ),
            command!(
                "xrGetVulkanGraphicsRequirements2KHR",
                vk2,
                vulkan::get_vulkan_graphics_requirements2 as GetVulkanGraphicsRequirements2KHR
            ),
            command!(
                "xrUpdateSwapchainFB",
                fb,
                swapchain::update_swapchain_fb as UpdateSwapchainFB
            ),
            command!(
                "xrGetSwapchainStateFB",
                fb,
                swapchain::get_swapchain_state_fb as GetSwapchainStateFB
            ),
            command!(
                "xrCreateFoveationProfileFB",
                fov,
                foveation::create_foveation_profile_fb as CreateFoveationProfileFB
            ),
            command!(
                "xrDestroyFoveationProfileFB",
                fov,
                foveation::destroy_foveation_profile_fb as DestroyFoveationProfileFB
            ),
            command!(
                "xrGetFoveationEyeTrackedStateMETA",
                Some(crate::extensions::META_FOVEATION_EYE_TRACKED),
                foveation::get_foveation_eye_tracked_state_meta as GetFoveationEyeTrackedStateMETA
            ),
        ]
    })
}

/// Every command name the runtime implements (core and extension), for tests and tools.
pub fn command_names() -> impl Iterator<Item = &'static str> {
    commands().iter().map(|c| c.name)
}

fn lookup(instance: xr::Instance, name: &str) -> Result<pfn::VoidFunction, xr::Result> {
    let command = commands().iter().find(|c| c.name == name);
    if instance == xr::Instance::NULL {
        return match command {
            Some(c) if GLOBAL.contains(&c.name) => Ok(c.function),
            _ => Err(xr::Result::ERROR_HANDLE_INVALID),
        };
    }
    let w = world();
    let inst = w
        .instances
        .get(&instance.into_raw())
        .ok_or(xr::Result::ERROR_HANDLE_INVALID)?;
    match command {
        Some(c) if c.extension.is_none_or(|e| inst.has_extension(e)) => Ok(c.function),
        _ => Err(xr::Result::ERROR_FUNCTION_UNSUPPORTED),
    }
}

/// The runtime's `xrGetInstanceProcAddr`: what the loader's negotiation hands out, and what the
/// in-process fake loader calls directly as the bottom of the layer chain.
///
/// # Safety
/// `name` must be NULL or a NUL-terminated string; `function` must be NULL or writable.
pub unsafe extern "system" fn get_instance_proc_addr(
    instance: xr::Instance,
    name: *const c_char,
    function: *mut Option<pfn::VoidFunction>,
) -> xr::Result {
    let found = std::panic::catch_unwind(|| {
        if function.is_null() {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        *function = None;
        if name.is_null() {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        let name = CStr::from_ptr(name)
            .to_str()
            .map_err(|_| xr::Result::ERROR_FUNCTION_UNSUPPORTED)?;
        lookup(instance, name)
    });
    match found {
        Ok(Ok(f)) => {
            *function = Some(f);
            xr::Result::SUCCESS
        }
        Ok(Err(e)) => e,
        Err(_) => xr::Result::ERROR_RUNTIME_FAILURE,
    }
}
