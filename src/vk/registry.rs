//! The layer's per-instance and per-device state, keyed by the loader's dispatch pointer.
//!
//! Every dispatchable handle (instance, physical device, device, queue, command buffer) points at
//! an object whose first word is the loader's dispatch table pointer; a physical device shares its
//! instance's, and queues and command buffers share their device's
//! (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>,
//! "Dispatchable Object Creation"). That word is the key.

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

use ash::vk;
use ash::vk::Handle as _;

use crate::bridge::FdmEmulation;
use crate::common::lock::{MapLock, Mutex, Rank};
use crate::vk::dispatch::{DeviceNext, InstanceNext};

/// The loader's dispatch pointer of a dispatchable handle.
pub type Key = usize;

/// The key of a dispatchable handle; `None` for a null handle.
///
/// # Safety
/// `handle` must be null or a live dispatchable handle made by the loader.
pub unsafe fn key(handle: impl vk::Handle) -> Option<Key> {
    let raw = handle.as_raw() as usize;
    // SAFETY: a live dispatchable handle points at an object starting with the dispatch pointer.
    (raw != 0).then(|| unsafe { *(raw as *const usize) })
}

/// What the layer does for one physical device, decided once from what the driver offers.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Decision {
    /// The driver has `VK_EXT_fragment_density_map`: everything passes through.
    Native,
    /// Shading-rate attachments and no native density maps: the layer offers them.
    Emulate {
        fdm: FdmEmulation,
        /// The physical device's `apiVersion`.
        api_version: u32,
    },
    /// Nothing to emulate with (or a query failed): everything passes through.
    PassThrough(String),
}

/// One `VkInstance` created through the layer.
pub struct Instance {
    pub handle: vk::Instance,
    /// The next layer's `vkGetInstanceProcAddr`.
    pub gipa: vk::PFN_vkGetInstanceProcAddr,
    pub next: InstanceNext,
    /// Queried, not intercepted.
    pub get_fragment_shading_rates: Option<vk::PFN_vkGetPhysicalDeviceFragmentShadingRatesKHR>,
    /// `VkApplicationInfo::apiVersion` (1.0 where absent).
    pub api_version: u32,
    /// Whether `VK_KHR_get_physical_device_properties2` is enabled.
    pub properties2_ext: bool,
    /// Decisions by physical device handle.
    pub decisions: Mutex<BTreeMap<u64, Arc<Decision>>>,
}

impl Instance {
    /// A new record with no decisions yet.
    ///
    /// # Safety
    /// `gipa` must be the next layer's `vkGetInstanceProcAddr` and `handle` its live instance.
    pub unsafe fn new(
        handle: vk::Instance,
        gipa: vk::PFN_vkGetInstanceProcAddr,
        next: InstanceNext,
        api_version: u32,
        properties2_ext: bool,
    ) -> Instance {
        // SAFETY: the next layer returns pointers of the types the names imply.
        let get_fragment_shading_rates = unsafe {
            gipa(
                handle,
                c"vkGetPhysicalDeviceFragmentShadingRatesKHR".as_ptr(),
            )
        }
        .map(
            // SAFETY: as above.
            |f| unsafe {
                std::mem::transmute::<
                    unsafe extern "system" fn(),
                    vk::PFN_vkGetPhysicalDeviceFragmentShadingRatesKHR,
                >(f)
            },
        );
        Instance {
            handle,
            gipa,
            next,
            get_fragment_shading_rates,
            api_version,
            properties2_ext,
            decisions: Mutex::ranked(Rank::Record, "vk instance decisions", BTreeMap::new()),
        }
    }
}

/// One `VkDevice` created through the layer.
pub struct Device {
    pub handle: vk::Device,
    /// The next layer's `vkGetDeviceProcAddr`.
    pub gdpa: vk::PFN_vkGetDeviceProcAddr,
    pub next: DeviceNext,
    /// `Some` where the device emulates fragment density maps.
    pub fdm: Option<FdmEmulation>,
    /// Where injection is on (docs/injection.md), the device got shading-rate attachments at
    /// `vkCreateDevice` and the layer could set up its own calls on it: its injected maps and what
    /// it tracks to find eye passes ([`crate::vk::inject`]).
    pub inject: Option<crate::vk::inject::Injector>,
    /// The device's Vulkan version (the instance's and the physical device's lower one): below
    /// 1.2 render pass 2 is `VK_KHR_create_renderpass2`'s, which the layer enables for emulation,
    /// and the core names may not be called.
    pub api_version: u32,
    /// The attachment path's state: shadows and rewritten passes (empty where not emulating).
    pub attachments: Attachments,
}

/// A layer-owned shading-rate image standing in for an application's density-map image
/// ([`crate::vk::image`]).
#[derive(Clone, Copy, Debug)]
pub struct ShadowImage {
    pub image: vk::Image,
    pub memory: vk::DeviceMemory,
    pub extent: vk::Extent2D,
    /// The shadow's array layers: the application image's, or 1 where the device lacks
    /// `layeredShadingRateAttachments` (one merged layer).
    pub layers: u32,
    /// The application image's array layers.
    pub app_layers: u32,
}

/// A layer-owned view of a shadow, standing in for a view of a density-map image.
#[derive(Clone, Copy, Debug)]
pub struct ShadowView {
    pub view: vk::ImageView,
}

/// Per device: application handles → the layer's shadows, and the render passes the layer
/// rewrote (by handle → the index of the density attachment, now a shading-rate attachment).
pub struct Attachments {
    /// The layer's own device-level calls (creating, clearing and destroying shadows and injected
    /// maps); `None` where the device neither emulates nor injects, or the layer could not set them
    /// up (no shadows or maps then).
    pub own: Option<Arc<crate::vk::image::Own>>,
    pub images: Mutex<HashMap<u64, ShadowImage>>,
    pub views: Mutex<HashMap<u64, ShadowView>>,
    pub passes: Mutex<HashMap<u64, u32>>,
    /// Set once the log has said that the application writes density maps itself (converted at
    /// pass begin, [`crate::vk::convert`]).
    pub app_maps_logged: std::sync::atomic::AtomicBool,
}

impl Attachments {
    /// No shadows yet.
    pub fn new(own: Option<Arc<crate::vk::image::Own>>) -> Attachments {
        Attachments {
            own,
            images: Mutex::ranked(Rank::Record, "vk shadow images", HashMap::new()),
            views: Mutex::ranked(Rank::Record, "vk shadow views", HashMap::new()),
            passes: Mutex::ranked(Rank::Record, "vk rewritten passes", HashMap::new()),
            app_maps_logged: std::sync::atomic::AtomicBool::new(false),
        }
    }

    /// The shadow view standing in for an application view.
    pub fn shadow_view(&self, view: vk::ImageView) -> Option<vk::ImageView> {
        self.views.lock().get(&view.as_raw()).map(|s| s.view)
    }

    /// The density attachment of a render pass the layer rewrote.
    pub fn density_attachment(&self, pass: vk::RenderPass) -> Option<u32> {
        self.passes.lock().get(&pass.as_raw()).copied()
    }
}

static INSTANCES: MapLock<BTreeMap<Key, Arc<Instance>>> =
    MapLock::new("vk instances", BTreeMap::new());
static DEVICES: MapLock<BTreeMap<Key, Arc<Device>>> = MapLock::new("vk devices", BTreeMap::new());

/// The instance of an instance or physical-device handle.
///
/// # Safety
/// As [`key`].
pub unsafe fn instance(handle: impl vk::Handle) -> Option<Arc<Instance>> {
    // SAFETY: as the caller promised.
    let k = unsafe { key(handle) }?;
    INSTANCES.read().get(&k).cloned()
}

/// The device of a device (or queue, or command buffer) handle.
///
/// # Safety
/// As [`key`].
pub unsafe fn device(handle: impl vk::Handle) -> Option<Arc<Device>> {
    // SAFETY: as the caller promised.
    let k = unsafe { key(handle) }?;
    DEVICES.read().get(&k).cloned()
}

/// Records a new instance.
///
/// # Safety
/// `data.handle` must be the live instance just created.
pub unsafe fn add_instance(data: Instance) {
    // SAFETY: as the caller promised.
    if let Some(k) = unsafe { key(data.handle) } {
        INSTANCES.write().insert(k, Arc::new(data));
    }
}

/// Forgets an instance, returning its record.
///
/// # Safety
/// As [`key`].
pub unsafe fn remove_instance(handle: vk::Instance) -> Option<Arc<Instance>> {
    // SAFETY: as the caller promised.
    let k = unsafe { key(handle) }?;
    INSTANCES.write().remove(&k)
}

/// Records a new device and tells the bridge how it emulates density maps.
///
/// # Safety
/// `data.handle` must be the live device just created.
pub unsafe fn add_device(data: Device) {
    crate::bridge::set_device_fdm(data.handle, data.fdm.clone());
    // SAFETY: as the caller promised.
    if let Some(k) = unsafe { key(data.handle) } {
        set_recording(k, Some(Recording::of(&data)));
        crate::vk::image::set_own(k, data.attachments.own.clone());
        DEVICES.write().insert(k, Arc::new(data));
    }
}

/// Forgets a device, returning its record.
///
/// # Safety
/// As [`key`].
pub unsafe fn remove_device(handle: vk::Device) -> Option<Arc<Device>> {
    // SAFETY: as the caller promised.
    let k = unsafe { key(handle) }?;
    let d = DEVICES.write().remove(&k);
    set_recording(k, None);
    crate::vk::image::set_own(k, None);
    if d.is_some() {
        crate::bridge::set_device_fdm(handle, None);
    }
    d
}

/// The raw handle, for log lines.
pub fn raw(handle: impl vk::Handle) -> u64 {
    handle.as_raw()
}

/// What a command-recording hook needs of its device: whether it emulates density maps, and the
/// next layer's pointers. Copied out of [`RECORDING`] by value, so no `Arc` is counted per command.
#[derive(Clone, Copy)]
pub struct Recording {
    pub emulated: bool,
    pub next: DeviceNext,
}

impl Recording {
    fn of(d: &Device) -> Recording {
        Recording {
            emulated: d.fdm.is_some(),
            next: d.next,
        }
    }
}

/// Devices by key, for the hooks of recorded commands. A leaf lock outside the [`Rank`] order:
/// held for a scan and a copy only, nothing called under it, so commands recorded under fovea's own
/// locks (its density-image uploads) may pass through the layer. A short vector: a process has few
/// devices, and a scan of it is cheaper than a tree walk.
static RECORDING: parking_lot::RwLock<Vec<(Key, Recording)>> = parking_lot::RwLock::new(Vec::new());

fn set_recording(k: Key, r: Option<Recording>) {
    let mut v = RECORDING.write();
    v.retain(|(key, _)| *key != k);
    if let Some(r) = r {
        v.push((k, r));
    }
}

/// The recording state of a command buffer's (or queue's) device.
///
/// # Safety
/// `handle` must be NULL or a live command buffer or queue made by the loader.
#[inline]
pub unsafe fn recording(handle: impl vk::Handle) -> Option<Recording> {
    // SAFETY: as the caller promised.
    let k = unsafe { key(handle) }?;
    RECORDING
        .read()
        .iter()
        .find(|(key, _)| *key == k)
        .map(|(_, r)| *r)
}
