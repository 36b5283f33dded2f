//! The runtime's objects as data: what each handle holds, and what stays of an instance after it
//! is destroyed. [`crate::state`]'s `World` keeps them; the modules of each chapter of the spec
//! (instance, session, swapchain, ...) implement the calls on them. This file imports none of
//! those, so the state never reaches back up into behaviour.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::sync::Arc;
use std::time::Instant;

use ash::vk;
use openxr_sys as xr;

use crate::config::{Fault, SimConfig};

/// One call that reached the runtime (xrGetInstanceProcAddr lookups are not journaled: the loader
/// makes hundreds of them and they change no state).
#[derive(Clone, Debug, PartialEq)]
pub struct Call {
    /// The OpenXR command name.
    pub function: &'static str,
    /// What the runtime returned.
    pub result: xr::Result,
    /// The structure types seen in the main input struct's `next` chain (xrCreateSwapchain,
    /// xrCreateSession, xrCreateInstance, xrEndFrame, ...).
    pub next_types: Vec<xr::StructureType>,
    /// Call-specific facts: enabled extensions, frame timing, submitted views, injected faults.
    pub detail: String,
    /// The runtime refused the call by its own rules (an error that is not an injected fault): the
    /// caller did something a conformant runtime may refuse.
    pub refused: bool,
}

/// One projection view as xrEndFrame received it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SubmittedView {
    /// Index of the projection layer in the frame's layer list.
    pub layer: usize,
    /// The raw swapchain handle.
    pub swapchain: u64,
    pub image_rect: xr::Rect2Di,
    pub image_array_index: u32,
    pub fov: xr::Fovf,
}

/// What stays observable about an instance after it is destroyed.
#[derive(Default)]
pub(crate) struct Record {
    pub journal: Vec<Call>,
    pub enabled_extensions: Vec<String>,
    pub end_frames: Vec<Vec<SubmittedView>>,
    /// Calls that returned an error code, by command (kept whether or not the journal is).
    pub errors: BTreeMap<&'static str, u64>,
    /// The subset of `errors` the runtime chose itself because the caller broke a rule (every error
    /// that is not an injected fault): what a strict runtime such as Monado would also refuse.
    pub refusals: BTreeMap<&'static str, u64>,
}

/// One successful xrCreateInstance, as the application info named it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CreatedInstance {
    pub instance: xr::Instance,
    pub application_name: String,
    pub api_version: xr::Version,
}

/// An event waiting for xrPollEvent.
pub(crate) enum Event {
    SessionStateChanged {
        session: u64,
        state: xr::SessionState,
        time: i64,
    },
    /// A top-level user path of the session got another interaction profile (at attach, as
    /// Monado queues one for each bound top-level path).
    InteractionProfileChanged { session: u64 },
}

pub(crate) struct InstanceState {
    pub config: SimConfig,
    pub record: Record,
    pub faults: Vec<Fault>,
    pub call_counts: HashMap<&'static str, u32>,
    pub lost: bool,
    pub events: VecDeque<Event>,
    /// The apiVersion the application asked for: OpenXR 1.1's interaction profiles and paths are
    /// there for 1.1 instances only.
    pub api_version: xr::Version,
    /// Path strings; `XrPath` n is `paths[n - 1]`.
    pub paths: Vec<String>,
    /// The virtual clock: advanced by frame timing, never by wall time.
    pub now_ns: i64,
    /// xrGetVulkanGraphicsRequirements(2)KHR was called (required before xrCreateSession).
    pub graphics_requirements_queried: bool,
    pub vulkan: VulkanInstanceState,
    /// Successful xrEndFrame calls over all the instance's sessions, for the summary line.
    pub frames: u64,
    /// The latest suggested bindings per interaction profile path, `(action, binding path)`: a
    /// later suggestion for a profile replaces the earlier one
    /// (<https://registry.khronos.org/OpenXR/specs/1.1/html/xrspec.html#xrSuggestInteractionProfileBindings>).
    pub suggested: HashMap<String, Vec<(u64, String)>>,
}

impl InstanceState {
    pub fn has_extension(&self, name: &str) -> bool {
        self.record.enabled_extensions.iter().any(|e| e == name)
    }

    pub fn path(&self, path: xr::Path) -> Option<&str> {
        let i = usize::try_from(path.into_raw()).ok()?.checked_sub(1)?;
        self.paths.get(i).map(String::as_str)
    }
}

pub(crate) enum Graphics {
    /// XR_MND_headless: no graphics binding, swapchains without images.
    Headless,
    Vulkan(Arc<VulkanSession>),
}

pub(crate) struct Session {
    pub instance: u64,
    /// The latest state announced (queued) to the application.
    pub state: xr::SessionState,
    /// Between a successful xrBeginSession and xrEndSession.
    pub running: bool,
    /// The primary view configuration xrBeginSession was given; `None` while not running. A real
    /// runtime sets up its views only here, so xrLocateViews is refused outside a running session
    /// and for any other configuration (see `space::locate_views`).
    pub view_configuration: Option<xr::ViewConfigurationType>,
    pub exit_requested: bool,
    pub lost: bool,
    pub graphics: Graphics,
    pub frame: FrameClock,
    pub action_sets_attached: Vec<u64>,
    /// Actions bound to the eye gaze pose when the sets were attached.
    pub gaze_actions: Vec<u64>,
    /// The sets the last focused xrSyncActions made active (none while unfocused).
    pub synced_sets: Vec<u64>,
    /// Of those, the sets whose gaze actions get the gaze: the highest priority among the active
    /// sets bound to it (XrActionSetCreateInfo::priority, or the sync's
    /// XrActiveActionSetPrioritiesEXT override).
    pub gaze_sets: Vec<u64>,
    /// The virtual time the session was created at: the eye tracker's script starts there.
    pub gaze_origin_ns: i64,
    /// The current interaction profile of each top-level user path that has one (set at attach).
    pub current_profiles: Vec<(String, String)>,
    /// The runtime asked the user to calibrate the eye tracker (at the first sync of a set bound to
    /// it, as XR_EXT_eye_gaze_interaction says a runtime should).
    pub calibration_requested: bool,
}

pub(crate) enum SpaceKind {
    Reference(xr::ReferenceSpaceType),
    /// An action's space: it locates only while the action is the eye tracker's and active
    /// ([`crate::actions::gaze_active`]) and the tracker has a sample; no controller is tracked.
    Action(u64),
}

pub(crate) struct Space {
    pub session: u64,
    pub kind: SpaceKind,
    pub pose_in_parent: xr::Posef,
}

pub(crate) struct Swapchain {
    pub session: u64,
    pub width: u32,
    pub height: u32,
    pub array_size: u32,
    pub image_count: u32,
    pub(crate) is_static: bool,
    /// Acquired and not yet released, oldest first.
    pub(crate) acquired: VecDeque<u32>,
    /// The oldest acquired image has been waited.
    pub(crate) waited: bool,
    pub(crate) next_index: u32,
    /// Acquisitions ever made (a static swapchain allows one).
    pub(crate) acquisitions: u64,
    /// An image has been released at least once, so the swapchain may be used in a layer.
    pub ever_released: bool,
    /// Real images for Vulkan sessions; destroyed with the swapchain.
    pub(crate) images: Option<SwapchainImages>,
    /// Created with XrSwapchainCreateInfoFoveationFB while XR_FB_foveation was enabled: profiles
    /// may be applied (native foveation only).
    pub foveation_supported: bool,
    /// The foveation xrUpdateSwapchainFB last applied.
    pub foveation: Option<Applied>,
}

pub(crate) struct ActionSet {
    pub instance: u64,
    pub(crate) name: String,
    /// Unique among the instance's sets too (XR_ERROR_LOCALIZED_NAME_DUPLICATED).
    pub(crate) localized_name: String,
    /// Attached to a session: no more actions may be added (XR_ERROR_ACTIONSETS_ALREADY_ATTACHED).
    pub(crate) attached: bool,
    /// `XrActionSetCreateInfo::priority`: of the active sets with actions bound to one input, only
    /// those of the highest priority get it.
    pub(crate) priority: u32,
}

pub(crate) struct Action {
    pub instance: u64,
    pub set: u64,
    pub(crate) name: String,
    /// Unique among the set's actions too (XR_ERROR_LOCALIZED_NAME_DUPLICATED).
    pub(crate) localized_name: String,
    pub(crate) ty: xr::ActionType,
    /// The top-level user paths the action was created with: the only non-null subaction paths
    /// its state may be queried for (XR_ERROR_PATH_UNSUPPORTED otherwise).
    pub(crate) subaction_paths: Vec<String>,
}

/// A foveation profile's parameters (XrFoveationLevelProfileCreateInfoFB; without it the spec
/// requires a profile that applies no foveation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FoveationParams {
    pub level: xr::FoveationLevelFB,
    pub vertical_offset: f32,
    pub dynamic: xr::FoveationDynamicFB,
}

impl FoveationParams {
    pub(crate) const NONE: FoveationParams = FoveationParams {
        level: xr::FoveationLevelFB::NONE,
        vertical_offset: 0.0,
        dynamic: xr::FoveationDynamicFB::DISABLED,
    };
}

pub(crate) struct Profile {
    pub session: u64,
    pub params: FoveationParams,
}

/// What xrUpdateSwapchainFB applied to a swapchain: the profile's handle (for
/// xrGetSwapchainStateFB) and a copy of its parameters (the spec: destroying the profile afterwards
/// does not change the swapchain's foveation).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Applied {
    pub profile: u64,
    pub params: FoveationParams,
}

#[derive(Default)]
pub(crate) struct FrameClock {
    /// xrWaitFrame calls since xrBeginSession: the index of the next frame.
    pub waits: u64,
    /// The last predicted display time.
    pub last_display_ns: Option<i64>,
    /// A wait's display time that no xrBeginFrame has consumed yet.
    pub pending_wait: Option<i64>,
    /// The display time of the frame between xrBeginFrame and xrEndFrame.
    pub begun: Option<i64>,
    /// Successful xrEndFrame calls since xrBeginSession.
    pub ends: u64,
    /// Real time and virtual time at the first wait, for `realtime`.
    pub realtime_origin: Option<(Instant, i64)>,
}

/// What the runtime learned about the application's Vulkan objects through the enable calls.
#[derive(Default)]
pub(crate) struct VulkanInstanceState {
    /// The application's `vkGetInstanceProcAddr` (enable2 only).
    pub gipa: Option<xr::platform::VkGetInstanceProcAddr>,
    /// The VkInstance the physical device was picked from.
    pub vk_instance: Option<vk::Instance>,
    /// The physical device returned by xrGetVulkanGraphicsDevice(2)KHR.
    pub physical_device: Option<vk::PhysicalDevice>,
}

/// A Vulkan session: the application's device, seen through function tables loaded from its
/// instance.
pub(crate) struct VulkanSession {
    pub(crate) instance: ash::Instance,
    pub(crate) device: ash::Device,
    pub(crate) physical_device: vk::PhysicalDevice,
    pub(crate) queue_family: u32,
    pub(crate) queue: vk::Queue,
    /// The offered formats this device can render to.
    pub formats: Vec<vk::Format>,
}

/// A swapchain's images with their memory, plus what the one-time layout transition needs.
pub(crate) struct SwapchainImages {
    pub(crate) vk: Arc<VulkanSession>,
    pub(crate) images: Vec<(vk::Image, vk::DeviceMemory)>,
    pub(crate) prepared: Vec<bool>,
    pub(crate) layout: vk::ImageLayout,
    pub(crate) range: vk::ImageSubresourceRange,
    pub(crate) pool: vk::CommandPool,
    pub(crate) command_buffer: vk::CommandBuffer,
    pub(crate) fence: vk::Fence,
}
