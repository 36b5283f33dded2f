//! Per-handle state: what the layer knows of each instance, session, swapchain and foveation profile.
//!
//! Handles are the runtime's own (fovea wraps none of them, so calls it does not intercept need no
//! translation); profiles are the one handle type fovea mints itself. Each kind lives in a
//! [`Records`] map, which owns its records as `Arc`s. Children hold their parent's `Arc`, which is
//! how a hook on a swapchain reaches the instance's next-layer table.
//!
//! Per frame, resolving a handle was the layer's main cost (a map lock, a hash, an `Arc` clone and
//! drop: four atomic read-modify-writes). The frame loop's hooks borrow their record for the call
//! instead ([`Registry::session_for_call`], [`Registry::swapchain_for_call`]), which a per-thread
//! cache answers without any (`crate::xr::records` says why that is sound). Hooks that keep a
//! record past their call, or destroy its handle, take the `Arc`.
//!
//! Lock order ([`crate::common::lock::Rank`], outermost first; checked in debug builds by [`crate::common::lock`]):
//! 1. a map lock (the handle maps, the Vulkan device list) is held alone: never while another lock
//!    is held, never while taking another lock, never while calling into the next layer;
//! 2. a record's own lock (a session's frame loop or views, a swapchain's foveation state, an
//!    instance's FOVs or Vulkan set-up); records never lock each other;
//! 3. a swapchain's density-image fill state;
//! 4. the session's GPU submission state (queue, command pool, fence);
//! 5. the debug properties, read under any of the above.
//!
//! No lock is held while calling into the next layer. The logging file's lock is a leaf inside
//! `tracing` and is not ranked.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Instant;

use crate::common::lock::{Mutex, Rank, SpinMutex};
use crate::xr::ffi::HookResult;
use crate::xr::records::{Borrowed, Records};
use openxr_sys as xr;
use xr::Handle;

use crate::common::settings::Overrides;
use crate::xr::density_images::DensityImages;
use crate::xr::extensions::Extensions;
use crate::xr::eye_centres::EyeCentres;
use crate::xr::foveation::{FoveationState, ProfileParams, Submitted, ViewFovs};
use crate::xr::gaze::{InstanceGaze, SessionGaze};
use crate::xr::next_layer::Next;
use crate::xr::session_gpu::{SessionGpu, VulkanBinding};
use fovea_model::density::Level;
use fovea_model::dynamic::Controller;
use fovea_model::projection::symmetric_fov;
use fovea_model::stats::Stats;
use fovea_model::Fov;

/// The application's instance and everything fovea learned when it was created.
pub struct Instance {
    pub handle: xr::Instance,
    /// The next layer's `xrGetInstanceProcAddr`, for functions fovea does not intercept.
    pub next_gipa: xr::pfn::GetInstanceProcAddr,
    /// The next layer's pointers for every intercepted function.
    pub next: Next,
    pub extensions: Extensions,
    /// `FOVEA_SYMMETRIC_FOV=1` when the instance was created.
    pub symmetric_fov: bool,
    /// Quest's debug properties: environment and `FOVEA_PROPS`, re-read while the app runs.
    pub overrides: Overrides,
    /// The primary stereo views' FOVs as the runtime reports them (not the symmetric ones fovea
    /// may hand on), learned from `xrLocateViews`.
    pub stereo_fovs: StereoFovs,
    /// How symmetric-FOV mode learns the FOVs ([`crate::xr::symmetric`]).
    pub fovs: InstanceFovs,
    /// What the application told the runtime about its Vulkan objects.
    pub vulkan: Mutex<VulkanSetup>,
    /// The runtime returned XR_ERROR_INSTANCE_LOST through a call fovea passed on.
    pub lost: AtomicBool,
    /// The level injected into the application's eye passes, where injection applies to it
    /// (docs/injection.md); the Vulkan side reads the published state ([`crate::bridge::inject`]).
    pub inject: Option<Level>,
    /// The application's `subsampled` setting (fovea.toml or `FOVEA_SUBSAMPLED`), read when the
    /// instance was created: one of the switches of reconstruction
    /// (docs/openxr-layer.md#subsampled-images).
    pub subsampled: Option<bool>,
    /// `eye_tracked_y_up` (fovea.toml or `FOVEA_EYE_TRACKED_Y_UP`): the centres
    /// `xrGetFoveationEyeTrackedStateMETA` returns have y up, OpenXR's NDC, instead of Quest's y
    /// down (docs/eye-tracking.md#xr_meta_foveation_eye_tracked).
    pub eye_tracked_y_up: bool,
    /// The gaze source's per-instance part, where gaze is on and XR_EXT_eye_gaze_interaction is
    /// enabled below ([`crate::xr::gaze`]).
    pub gaze: Option<InstanceGaze>,
    /// Gaze is switched on for the instance and something of fovea's uses it
    /// ([`crate::xr::gaze::used`]), whether or not the runtime has any: the stats line tells `off`
    /// from `fixed` by it.
    pub gaze_on: bool,
}

impl Instance {
    /// The runtime's own stereo FOVs, once known.
    pub fn stereo_fovs(&self) -> Option<[Fov; 2]> {
        self.stereo_fovs.get()
    }

    /// What the views are rendered with: the shared symmetric FOV in symmetric-FOV mode, else the
    /// runtime's own.
    pub fn render_fovs(&self, fovs: [Fov; 2]) -> [Fov; 2] {
        match self.symmetric_fov.then(|| symmetric_fov(&fovs)).flatten() {
            Some(shared) => [shared; 2],
            None => fovs,
        }
    }
}

/// The runtime's stereo FOVs, which every `xrLocateViews` reports and which rarely change: the
/// record lock is taken only when they do, so the per-frame report costs loads and compares, not a
/// lock (docs/ARCHITECTURE.md#per-frame-cost).
pub struct StereoFovs {
    known: Mutex<Option<[Fov; 2]>>,
    /// The bits of the FOVs last stored (written under `known`'s lock); 0 with `stored` false
    /// until the first.
    bits: [AtomicU64; 4],
    stored: AtomicBool,
}

impl Default for StereoFovs {
    fn default() -> StereoFovs {
        StereoFovs {
            known: Mutex::new(None),
            bits: Default::default(),
            stored: AtomicBool::new(false),
        }
    }
}

impl StereoFovs {
    fn bits_of(fovs: [Fov; 2]) -> [u64; 4] {
        let b = |f: &Fov| {
            [
                u64::from(f.left.to_bits()) << 32 | u64::from(f.right.to_bits()),
                u64::from(f.up.to_bits()) << 32 | u64::from(f.down.to_bits()),
            ]
        };
        let [l, r] = [b(&fovs[0]), b(&fovs[1])];
        [l[0], l[1], r[0], r[1]]
    }

    /// The FOVs, once known.
    pub fn get(&self) -> Option<[Fov; 2]> {
        *self.known.lock()
    }

    /// Stores the FOVs the runtime reported.
    pub fn set(&self, fovs: [Fov; 2]) {
        let bits = Self::bits_of(fovs);
        let same = self.stored.load(Ordering::Acquire)
            && self
                .bits
                .iter()
                .zip(bits)
                .all(|(a, b)| a.load(Ordering::Relaxed) == b);
        if !same {
            self.store(&mut self.known.lock(), fovs, bits);
        }
    }

    /// Stores the FOVs only where none are known yet (a probe's answer never overrides what
    /// `xrLocateViews` reported).
    pub fn set_if_unknown(&self, fovs: [Fov; 2]) {
        let mut known = self.known.lock();
        if known.is_none() {
            self.store(&mut known, fovs, Self::bits_of(fovs));
        }
    }

    fn store(&self, known: &mut Option<[Fov; 2]>, fovs: [Fov; 2], bits: [u64; 4]) {
        *known = Some(fovs);
        for (a, b) in self.bits.iter().zip(bits) {
            a.store(b, Ordering::Relaxed);
        }
        self.stored.store(true, Ordering::Release);
    }
}

/// What an instance knows about how symmetric-FOV mode learns its FOVs ([`crate::xr::symmetric`]).
#[derive(Debug, Default)]
pub struct InstanceFovs {
    /// XR_EPIC_view_configuration_fov is enabled on the instance below (by the application or by
    /// fovea in symmetric mode).
    pub epic: bool,
    /// The application's last stereo xrEnumerateViewConfigurationViews, in symmetric mode, got the
    /// runtime's own sizes: the FOVs were not known yet.
    pub handed_unenlarged: AtomicBool,
    /// The fallback's log line was written for this instance.
    pub fallback_logged: AtomicBool,
}

impl InstanceFovs {
    pub fn new(epic: bool) -> InstanceFovs {
        InstanceFovs {
            epic,
            ..InstanceFovs::default()
        }
    }
}

/// Per session: whether it runs, and whether symmetric-FOV mode is off for it
/// ([`crate::xr::symmetric`]).
#[derive(Debug, Default)]
pub struct SessionFovs {
    /// Between a successful xrBeginSession with the primary stereo configuration and xrEndSession:
    /// views can be located.
    pub running_stereo: AtomicBool,
    /// The application sized for each eye's own FOV: the views keep it.
    pub symmetric_off: AtomicBool,
}

/// The Vulkan set-up calls fovea watches (XR_KHR_vulkan_enable / enable2), as raw handle values.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct VulkanSetup {
    /// The VkInstance and the VkPhysicalDevice xrGetVulkanGraphicsDevice(2)KHR returned: the spec
    /// makes the session's device come from that physical device.
    pub graphics_device: Option<(u64, u64)>,
    /// xrGetVulkanDeviceExtensionsKHR (enable) listed VK_EXT_fragment_density_map, which the
    /// application must then enable on its device ("required" extensions, khr_vulkan_enable.adoc).
    pub fdm_listed: bool,
    /// The physical device it was listed for; `None` when it was listed before fovea knew the device.
    pub fdm_listed_for: Option<u64>,
    /// VkDevices created through xrCreateVulkanDeviceKHR (enable2) with `imagelessFramebuffer`
    /// enabled (0: a free slot), where reconstruction's added usage would break the application's
    /// framebuffers (docs/openxr-layer.md#subsampled-images). An application has one or two.
    pub imageless_devices: [u64; 4],
}

impl VulkanSetup {
    /// Remembers a device created with `imagelessFramebuffer` (beyond four, the oldest goes).
    pub fn imageless_created(&mut self, device: u64) {
        if !self.imageless_devices.contains(&device) {
            self.imageless_devices.rotate_right(1);
            self.imageless_devices[0] = device;
        }
    }

    /// Whether `device` was created through xrCreateVulkanDeviceKHR with `imagelessFramebuffer`.
    pub fn imageless(&self, device: u64) -> bool {
        device != 0 && self.imageless_devices.contains(&device)
    }

    /// Whether the application was told to enable VK_EXT_fragment_density_map on a device of
    /// `physical_device`.
    pub fn fdm_listed_for(&self, physical_device: u64) -> bool {
        self.fdm_listed && self.fdm_listed_for.is_none_or(|p| p == physical_device)
    }
}

/// A VkDevice created through xrCreateVulkanDeviceKHR (enable2), where fovea saw its create info.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VulkanDevice {
    /// The XrInstance it was created through (the record goes with that instance).
    pub instance: u64,
    /// VK_EXT_fragment_density_map and its `fragmentDensityMap` feature are both enabled.
    pub fdm_enabled: bool,
    /// A density-map offset extension and its `fragmentDensityMapOffset` feature are both enabled
    /// (where fovea's Vulkan layer did not see the device, the only word on it).
    pub offsets_enabled: bool,
}

/// A session and its graphics binding.
pub struct Session {
    pub handle: xr::Session,
    pub instance: Arc<Instance>,
    /// The Vulkan binding, when the session has one (not for headless sessions).
    pub vulkan: Option<VulkanBinding>,
    /// What each `xrWaitFrame` learned.
    pub waits: Waits,
    /// The dynamic controller and the stats window, which `xrEndFrame` runs.
    pub frame: SpinMutex<FrameLoop>,
    /// The dynamic controller's step ([`fovea_model::dynamic::LADDER`]), read when maps are built.
    pub dynamic_step: AtomicUsize,
    /// The highest step any of the session's dynamic swapchains allows (0: none is dynamic).
    pub dynamic_max: AtomicUsize,
    /// Bumped when the dynamic step or the debug overrides change what the swapchains' maps hold.
    pub pattern_generation: AtomicU64,
    /// Density maps built and uploaded, for the stats line.
    pub maps_built: AtomicU64,
    pub maps_uploaded: AtomicU64,
    /// fovea's Vulkan objects on the binding's device, where it provides XR_FB_foveation_vulkan and
    /// could set them up.
    pub gpu: Option<Arc<SessionGpu>>,
    /// The FOVs xrLocateViews last returned, which the density maps are computed for.
    pub views: Mutex<ViewFovs>,
    /// The runtime returned XR_ERROR_SESSION_LOST through a call fovea passed on.
    pub lost: AtomicBool,
    /// Whether the session runs, and whether symmetric-FOV mode is off for it
    /// ([`crate::xr::symmetric`]).
    pub fovs: SessionFovs,
    /// Where each view's fovea is this frame, as the gaze source last left it
    /// ([`crate::xr::eye_centres`]); fixed foveation until a gaze is located.
    pub eyes: SpinMutex<EyeCentres>,
    /// The gaze source's per-session part, where the system has an eye tracker
    /// ([`crate::xr::gaze`]); it writes `eyes`.
    pub gaze: Option<SessionGaze>,
    /// The profile last applied to one of the session's swapchains without density images, which
    /// injection foveates at its level ([`crate::xr::pattern::injected_pattern_at`]), packed by
    /// [`crate::xr::foveation::pack_request`]; 0 before any. An atomic: the frame loop reads it
    /// every frame.
    pub inject_request: AtomicU64,
}

impl Session {
    pub fn new(
        handle: xr::Session,
        instance: Arc<Instance>,
        vulkan: Option<VulkanBinding>,
        gpu: Option<Arc<SessionGpu>>,
    ) -> Session {
        Session {
            handle,
            instance,
            vulkan,
            gpu,
            views: Mutex::default(),
            pattern_generation: AtomicU64::new(0),
            waits: Waits::default(),
            frame: SpinMutex::spin(FrameLoop::default()),
            dynamic_step: AtomicUsize::new(0),
            dynamic_max: AtomicUsize::new(0),
            maps_built: AtomicU64::new(0),
            maps_uploaded: AtomicU64::new(0),
            lost: AtomicBool::new(false),
            fovs: Default::default(),
            eyes: SpinMutex::spin(EyeCentres::FIXED),
            gaze: None,
            inject_request: AtomicU64::new(0),
        }
    }
}

/// What the layer tracks of a session's frame loop between `xrWaitFrame`, `xrBeginFrame` and
/// `xrEndFrame`.
#[derive(Debug, Default)]
pub struct FrameLoop {
    pub controller: Controller,
    pub stats: Stats,
    /// [`Waits::sums`] when the stats last took them.
    pub waits_counted: WaitSums,
    /// When `xrBeginFrame` returned for the frame being rendered (while the stats line is logged).
    pub begin_at: Option<Instant>,
}

/// What `xrWaitFrame` learns, kept in atomics so that it takes no lock: the predicted display time
/// and period, the display periods the frame being rendered skipped, and running sums for the
/// stats, which `xrEndFrame` takes under its own lock. The spec makes every `xrWaitFrame` call
/// externally synchronised with the others
/// (<https://registry.khronos.org/OpenXR/specs/1.0/man/html/xrWaitFrame.html>), so one writer at a
/// time: each field is a load and a store, never a read-modify-write (docs/ARCHITECTURE.md#per-frame-cost).
#[derive(Debug, Default)]
pub struct Waits {
    /// The last predicted display time in nanoseconds; 0 before the first.
    display: AtomicI64,
    period: AtomicI64,
    missed: AtomicU32,
    interval_ns: AtomicI64,
    intervals: AtomicU32,
    missed_sum: AtomicU32,
}

/// Running sums of what `xrWaitFrame` saw since the session began.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WaitSums {
    pub interval_ns: i64,
    pub intervals: u32,
    pub missed: u32,
}

impl Waits {
    /// One `xrWaitFrame` that predicted `display_ns` with a display period of `period_ns`: the
    /// interval since the previous prediction tells how many periods were skipped.
    pub fn waited(&self, display_ns: i64, period_ns: i64) {
        let last = self.display.load(Ordering::Relaxed);
        if last != 0 && period_ns > 0 {
            let interval = display_ns - last;
            let missed = u32::try_from(((interval + period_ns / 2) / period_ns - 1).max(0))
                .unwrap_or(u32::MAX);
            self.missed.store(missed, Ordering::Relaxed);
            let add =
                |a: &AtomicI64, v: i64| a.store(a.load(Ordering::Relaxed) + v, Ordering::Relaxed);
            add(&self.interval_ns, interval);
            let add = |a: &AtomicU32, v: u32| {
                a.store(a.load(Ordering::Relaxed).wrapping_add(v), Ordering::Relaxed)
            };
            add(&self.intervals, 1);
            add(&self.missed_sum, missed);
        }
        self.period.store(period_ns, Ordering::Relaxed);
        // Last: the display time is what `sums` readers pair the rest with.
        self.display.store(display_ns, Ordering::Release);
    }

    /// The last predicted display time, once there is one.
    pub fn display(&self) -> Option<i64> {
        Some(self.display.load(Ordering::Acquire)).filter(|&d| d != 0)
    }

    pub fn period(&self) -> i64 {
        self.period.load(Ordering::Relaxed)
    }

    /// Display periods the frame being rendered skipped.
    pub fn missed(&self) -> u32 {
        self.missed.load(Ordering::Relaxed)
    }

    pub fn sums(&self) -> WaitSums {
        WaitSums {
            interval_ns: self.interval_ns.load(Ordering::Relaxed),
            intervals: self.intervals.load(Ordering::Relaxed),
            missed: self.missed_sum.load(Ordering::Relaxed),
        }
    }
}

impl WaitSums {
    /// What was added since `earlier`.
    pub fn since(self, earlier: WaitSums) -> WaitSums {
        WaitSums {
            interval_ns: self.interval_ns - earlier.interval_ns,
            intervals: self.intervals.wrapping_sub(earlier.intervals),
            missed: self.missed.wrapping_sub(earlier.missed),
        }
    }
}

/// What fovea keeps of `XrSwapchainCreateInfo`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SwapchainInfo {
    pub usage: u64,
    pub format: i64,
    pub sample_count: u32,
    pub width: u32,
    pub height: u32,
    pub face_count: u32,
    pub array_size: u32,
    pub mip_count: u32,
}

/// A swapchain and, when the application asked for foveation, its foveation state.
pub struct Swapchain {
    pub handle: xr::Swapchain,
    pub session: Arc<Session>,
    pub info: SwapchainInfo,
    /// Present when the swapchain was created with `XrSwapchainCreateInfoFoveationFB` and fovea
    /// provides XR_FB_foveation: profiles may be applied to it.
    pub foveation: Option<Mutex<FoveationState>>,
    /// The density images (one per swapchain image) of a FRAGMENT_DENSITY_MAP swapchain on a Vulkan
    /// session, where fovea provides XR_FB_foveation_vulkan and could create them.
    pub density: Option<DensityImages>,
    /// The views the application last submitted into this swapchain (xrEndFrame).
    pub submitted: Mutex<Submitted>,
    /// Created with `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT` in
    /// `XrVulkanSwapchainCreateInfoMETA`: the application moves the fovea itself with density-map
    /// offsets, so fovea keeps its maps fixed (docs/eye-tracking.md#what-moves-when).
    pub app_offsets: bool,
    /// Whether the Vulkan side reconstructs the coarse blocks of this swapchain's images
    /// (docs/openxr-layer.md#subsampled-images), decided at creation; `None`: nothing is decided
    /// for it (nobody foveates it as far as fovea knows, and the application asked nothing).
    pub reconstruct: Option<bool>,
    /// The usage fovea had the runtime add to the images that the application did not ask for
    /// (reconstruction's transfer usage), published with the decision: the Vulkan side hides it
    /// from the application's views (docs/reconstruction.md#usage-the-application-does-not-see).
    pub added_usage: xr::SwapchainUsageFlags,
    /// The `VkImage`s the decision was published for ([`crate::bridge::subsampled`]), forgotten
    /// when the runtime has destroyed them ([`Swapchain::forget_published`]).
    pub published: Mutex<Vec<u64>>,
}

/// The Vulkan usage of the transfer bits of `usage`, as XR_KHR_vulkan_enable maps them ("Swapchain
/// usage flags"): the only ones fovea adds.
fn vulkan_usage(usage: xr::SwapchainUsageFlags) -> ash::vk::ImageUsageFlags {
    use ash::vk::ImageUsageFlags as V;
    let mut v = V::empty();
    if usage.contains(xr::SwapchainUsageFlags::TRANSFER_SRC) {
        v |= V::TRANSFER_SRC;
    }
    if usage.contains(xr::SwapchainUsageFlags::TRANSFER_DST) {
        v |= V::TRANSFER_DST;
    }
    v
}

impl Swapchain {
    /// Publishes the reconstruction decision for the images the runtime's enumeration returned
    /// (raw `VkImage`s); nothing where none was decided.
    pub fn publish(&self, images: &[u64]) {
        let Some(reconstruct) = self.reconstruct else {
            return;
        };
        crate::bridge::subsampled::publish(images, reconstruct, vulkan_usage(self.added_usage));
        tracing::debug!(
            swapchain = self.handle.into_raw(),
            ?images,
            reconstruct,
            "reconstruction decision published for the swapchain's images"
        );
        let mut published = self.published.lock();
        for i in images {
            if !published.contains(i) {
                published.push(*i);
            }
        }
    }

    /// The runtime destroyed the swapchain (directly, or with its session or instance): its
    /// images' handles may come back for other images, which must not inherit its decision.
    pub fn forget_published(&self) {
        let images = std::mem::take(&mut *self.published.lock());
        if images.is_empty() {
            return;
        }
        crate::bridge::subsampled::forget(&images);
        tracing::debug!(
            swapchain = self.handle.into_raw(),
            ?images,
            "reconstruction decision forgotten: the runtime destroyed the swapchain's images"
        );
    }
}

/// A foveation profile fovea created.
pub struct Profile {
    pub handle: xr::FoveationProfileFB,
    /// The session it belongs to (xr.xml: `parent="XrSession"`).
    pub session: xr::Session,
    pub params: ProfileParams,
}

/// Every live handle fovea knows.
pub struct Registry {
    pub instances: Records<Instance>,
    pub sessions: Records<Session>,
    pub swapchains: Records<Swapchain>,
    pub profiles: Records<Profile>,
    /// VkDevices created through xrCreateVulkanDeviceKHR, keyed by the raw VkDevice.
    pub vulkan_devices: Mutex<HashMap<u64, VulkanDevice>>,
    next_profile: AtomicU64,
}

/// Records taken out of the [`Registry`] while a destroy goes down. Dropping it releases them (and
/// with the last reference, the density images and fovea's Vulkan objects they own).
#[derive(Default)]
pub struct Detached {
    pub instance: Option<Arc<Instance>>,
    pub sessions: Vec<Arc<Session>>,
    pub swapchains: Vec<Arc<Swapchain>>,
    pub profiles: Vec<Arc<Profile>>,
    pub vulkan_devices: Vec<(u64, VulkanDevice)>,
}

impl Detached {
    /// The runtime destroyed the detached session or instance, and with it the swapchains' images.
    pub fn forget_published(&self) {
        for s in &self.swapchains {
            s.forget_published();
        }
    }
}

impl Default for Registry {
    fn default() -> Registry {
        Registry {
            instances: Records::new("instances"),
            sessions: Records::new("sessions"),
            swapchains: Records::new("swapchains"),
            profiles: Records::new("profiles"),
            vulkan_devices: Mutex::ranked(Rank::Map, "vulkan devices", HashMap::new()),
            next_profile: AtomicU64::new(0),
        }
    }
}

/// The process-wide registry. A static behind `OnceLock`: no `static mut`.
pub fn registry() -> &'static Registry {
    static REGISTRY: OnceLock<Registry> = OnceLock::new();
    REGISTRY.get_or_init(Registry::default)
}

/// The record for an instance handle, or XR_ERROR_HANDLE_INVALID.
pub fn instance(h: xr::Instance) -> HookResult<Arc<Instance>> {
    registry()
        .instance(h)
        .ok_or(xr::Result::ERROR_HANDLE_INVALID)
}

/// The record for a session handle, or XR_ERROR_HANDLE_INVALID.
pub fn session(h: xr::Session) -> HookResult<Arc<Session>> {
    registry()
        .session(h)
        .ok_or(xr::Result::ERROR_HANDLE_INVALID)
}

/// The record for a swapchain handle, or XR_ERROR_HANDLE_INVALID.
pub fn swapchain(h: xr::Swapchain) -> HookResult<Arc<Swapchain>> {
    registry()
        .swapchain(h)
        .ok_or(xr::Result::ERROR_HANDLE_INVALID)
}

/// A session's record for the length of the calling hook, or XR_ERROR_HANDLE_INVALID: for the frame
/// loop's hooks, which neither keep it nor destroy the session. No atomic read-modify-write where
/// this thread resolved the handle before ([`crate::xr::records`]).
pub fn session_for_call(h: xr::Session) -> HookResult<Borrowed<'static, Session>> {
    registry()
        .session_for_call(h)
        .ok_or(xr::Result::ERROR_HANDLE_INVALID)
}

/// A swapchain's record for the length of the calling hook, or XR_ERROR_HANDLE_INVALID (see
/// [`session_for_call`]).
pub fn swapchain_for_call(h: xr::Swapchain) -> HookResult<Borrowed<'static, Swapchain>> {
    registry()
        .swapchain_for_call(h)
        .ok_or(xr::Result::ERROR_HANDLE_INVALID)
}

/// A loss the runtime reported is final: once XR_ERROR_INSTANCE_LOST or XR_ERROR_SESSION_LOST is
/// returned, every later non-destroy call on that object or its children returns it too
/// (fundamentals.adoc, "Instance Lost", "Session Lost"). fovea's own functions are part of the
/// runtime as the application sees it, so they follow: they answer the loss once fovea saw the
/// runtime report it through a call it passed on. Losses reported through calls fovea does not
/// intercept (xrPollEvent, xrBeginSession, ...) stay unseen until an intercepted call reports them.
pub fn check_lost(session: &Session) -> HookResult<()> {
    use std::sync::atomic::Ordering::Relaxed;
    if session.instance.lost.load(Relaxed) {
        return Err(xr::Result::ERROR_INSTANCE_LOST);
    }
    if session.lost.load(Relaxed) {
        return Err(xr::Result::ERROR_SESSION_LOST);
    }
    Ok(())
}

/// Notes a loss in the result of a call on `session` (or its children) that fovea passed on.
pub fn observed(session: &Session, r: xr::Result) -> xr::Result {
    use std::sync::atomic::Ordering::Relaxed;
    if r == xr::Result::ERROR_SESSION_LOST {
        session.lost.store(true, Relaxed);
    }
    observed_instance(&session.instance, r)
}

/// Notes an instance loss in the result of a call on `instance` that fovea passed on.
pub fn observed_instance(instance: &Instance, r: xr::Result) -> xr::Result {
    if r == xr::Result::ERROR_INSTANCE_LOST {
        instance
            .lost
            .store(true, std::sync::atomic::Ordering::Relaxed);
    }
    r
}

impl Registry {
    pub fn instance(&self, h: xr::Instance) -> Option<Arc<Instance>> {
        self.instances.get(h.into_raw())
    }

    pub fn session(&self, h: xr::Session) -> Option<Arc<Session>> {
        self.sessions.get(h.into_raw())
    }

    /// A session's record for the length of the calling hook ([`Records::borrow`]): for hooks that
    /// neither keep it nor destroy the session.
    pub fn session_for_call(&self, h: xr::Session) -> Option<Borrowed<'_, Session>> {
        self.sessions.borrow(h.into_raw())
    }

    /// A swapchain's record for the length of the calling hook ([`Records::borrow`]).
    pub fn swapchain_for_call(&self, h: xr::Swapchain) -> Option<Borrowed<'_, Swapchain>> {
        self.swapchains.borrow(h.into_raw())
    }

    /// The session's swapchains created with foveation.
    pub fn foveated_swapchains_of(&self, session: xr::Session) -> Vec<Arc<Swapchain>> {
        self.swapchains
            .read()
            .values()
            .filter(|sc| sc.session.handle == session && sc.foveation.is_some())
            .cloned()
            .collect()
    }

    /// Whether any swapchain of `session` is alive.
    pub fn has_swapchains(&self, session: xr::Session) -> bool {
        self.swapchains
            .read()
            .values()
            .any(|sc| sc.session.handle == session)
    }

    pub fn swapchain(&self, h: xr::Swapchain) -> Option<Arc<Swapchain>> {
        self.swapchains.get(h.into_raw())
    }

    pub fn profile(&self, h: xr::FoveationProfileFB) -> Option<Arc<Profile>> {
        self.profiles.get(h.into_raw())
    }

    /// A new profile handle value: never 0 (XR_NULL_HANDLE) and never reused in this process, so a
    /// destroyed profile's handle stays invalid.
    pub fn mint_profile_handle(&self) -> xr::FoveationProfileFB {
        xr::FoveationProfileFB::from_raw(
            self.next_profile.fetch_add(1, Ordering::Relaxed) + 0xF0FE_A000_0000_0001,
        )
    }

    /// Takes a session, its swapchains and its profiles (they die with it: xr.xml parents) out of
    /// the maps, for `xrDestroySession`. They are taken out before the call goes down, so that a
    /// handle value the runtime frees and hands out again at once cannot meet a stale record, and
    /// kept until the runtime answered: a destroy the runtime refuses leaves the session alive, and
    /// [`Registry::restore`] puts them back.
    pub fn detach_session(&self, session: xr::Session) -> Detached {
        let mut d = Detached::default();
        self.detach_session_into(session, &mut d);
        d
    }

    fn detach_session_into(&self, session: xr::Session, d: &mut Detached) {
        d.sessions
            .extend(self.sessions.write().remove(&session.into_raw()));
        let mut profiles = self.profiles.write();
        let dead: Vec<u64> = profiles
            .iter()
            .filter(|(_, p)| p.session == session)
            .map(|(k, _)| *k)
            .collect();
        d.profiles
            .extend(dead.iter().filter_map(|k| profiles.remove(k)));
        drop(profiles);
        let mut swapchains = self.swapchains.write();
        let dead: Vec<u64> = swapchains
            .iter()
            .filter(|(_, s)| s.session.handle == session)
            .map(|(k, _)| *k)
            .collect();
        d.swapchains
            .extend(dead.iter().filter_map(|k| swapchains.remove(k)));
    }

    /// Takes an instance and everything under it out of the maps, for `xrDestroyInstance` (see
    /// [`Registry::detach_session`]).
    pub fn detach_instance(&self, instance: xr::Instance) -> Detached {
        let mut d = Detached {
            instance: self.instances.write().remove(&instance.into_raw()),
            ..Detached::default()
        };
        let sessions: Vec<xr::Session> = self
            .sessions
            .read()
            .values()
            .filter(|s| s.instance.handle == instance)
            .map(|s| s.handle)
            .collect();
        for s in sessions {
            self.detach_session_into(s, &mut d);
        }
        let raw = instance.into_raw();
        let mut devices = self.vulkan_devices.lock();
        let dead: Vec<u64> = devices
            .iter()
            .filter(|(_, dev)| dev.instance == raw)
            .map(|(k, _)| *k)
            .collect();
        d.vulkan_devices
            .extend(dead.iter().filter_map(|k| devices.remove_entry(k)));
        d
    }

    /// Puts detached records back: the runtime refused the destroy, so the handles still live.
    pub fn restore(&self, d: Detached) {
        if let Some(i) = d.instance {
            self.instances.write().insert(i.handle.into_raw(), i);
        }
        let mut sessions = self.sessions.write();
        for s in d.sessions {
            sessions.insert(s.handle.into_raw(), s);
        }
        drop(sessions);
        let mut swapchains = self.swapchains.write();
        for s in d.swapchains {
            swapchains.insert(s.handle.into_raw(), s);
        }
        drop(swapchains);
        let mut profiles = self.profiles.write();
        for p in d.profiles {
            profiles.insert(p.handle.into_raw(), p);
        }
        drop(profiles);
        self.vulkan_devices.lock().extend(d.vulkan_devices);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waits_count_skipped_periods_and_sum_for_the_stats() {
        let w = Waits::default();
        let p = 11_111_111;
        assert_eq!(w.display(), None);
        w.waited(1_000, p);
        assert_eq!(
            (w.display(), w.missed(), w.sums()),
            (Some(1_000), 0, WaitSums::default())
        );
        w.waited(1_000 + p, p);
        assert_eq!(w.missed(), 0);
        let before = w.sums();
        w.waited(1_000 + 3 * p, p);
        assert_eq!(w.missed(), 1, "one period skipped");
        w.waited(1_000 + 6 * p + p / 3, p);
        assert_eq!(w.missed(), 2, "rounded to the nearest period");
        assert_eq!(w.period(), p);
        let d = w.sums().since(before);
        assert_eq!(d.intervals, 2);
        assert_eq!(d.missed, 3);
        assert_eq!(d.interval_ns, 5 * p + p / 3);
    }

    #[test]
    fn stereo_fovs_follow_every_change_and_a_probe_never_overrides() {
        let f = |x: f32| Fov {
            left: -x,
            right: x,
            up: x,
            down: -x,
        };
        let s = StereoFovs::default();
        assert_eq!(s.get(), None);
        s.set_if_unknown([f(0.5), f(0.6)]);
        assert_eq!(s.get(), Some([f(0.5), f(0.6)]));
        s.set_if_unknown([f(0.7), f(0.7)]);
        assert_eq!(s.get(), Some([f(0.5), f(0.6)]));
        s.set([f(0.5), f(0.6)]);
        assert_eq!(s.get(), Some([f(0.5), f(0.6)]));
        // One component of one eye changes: seen.
        let mut moved = [f(0.5), f(0.6)];
        moved[1].down = -0.61;
        s.set(moved);
        assert_eq!(s.get(), Some(moved));
        s.set([f(0.5), f(0.6)]);
        assert_eq!(s.get(), Some([f(0.5), f(0.6)]));
    }

    #[test]
    fn minted_profile_handles_are_distinct_and_non_null() {
        let r = Registry::default();
        let a = r.mint_profile_handle();
        let b = r.mint_profile_handle();
        assert_ne!(a, b);
        assert_ne!(a.into_raw(), 0);
    }
}
