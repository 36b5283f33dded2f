//! The layer's per-instance and per-device state, keyed by the loader's dispatch pointer.
//!
//! Every dispatchable handle (instance, physical device, device, queue, command buffer) points at
//! an object whose first word is the loader's dispatch table pointer; a physical device shares its
//! instance's, and queues and command buffers share their device's
//! (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>,
//! "Dispatchable Object Creation"). That word is the key.

use std::collections::{BTreeMap, HashMap};
use std::marker::PhantomData;
use std::sync::atomic::{AtomicPtr, AtomicUsize, Ordering};
use std::sync::Arc;

use ash::vk;
use ash::vk::Handle as _;

use crate::bridge::FdmEmulation;
use crate::common::lock::{MapLock, Mutex, Rank};
use crate::vk::base::ffi::{key, Key};
use crate::vk::base::next::{DeviceNext, InstanceNext};

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

/// The device of a device (or queue, or command buffer) handle, as an `Arc` the caller may keep:
/// for hooks that create or destroy objects. A recording hook borrows the record instead
/// ([`device_ref`]): no lock and no reference count.
///
/// # Safety
/// As [`key`].
pub unsafe fn device(handle: impl vk::Handle) -> Option<Arc<Device>> {
    // SAFETY: as the caller promised.
    let k = unsafe { key(handle) }?;
    DEVICES.read().get(&k).cloned()
}

/// Slots in [`FAST`]: more devices than a process makes at once (an engine has one, an OpenXR
/// app with a runtime compositor two or three). Devices beyond it are found through [`DEVICES`].
const FAST_SLOTS: usize = 64;

/// One live device: its dispatch key and its record (the `Arc` in [`DEVICES`] owns it).
struct FastSlot {
    /// 0 where the slot is free.
    key: AtomicUsize,
    device: AtomicPtr<Device>,
}

/// The devices the recording hooks look up, without a lock: a scan of atomics that only device
/// creation and destruction write, so every thread's copy of these cache lines stays shared while
/// commands are recorded. Aligned so that nothing written more often shares its first line.
#[repr(align(64))]
struct FastTable {
    /// Slots `0..used` may be taken; a scan reads no further.
    used: AtomicUsize,
    slots: [FastSlot; FAST_SLOTS],
}

static FAST: FastTable = FastTable {
    used: AtomicUsize::new(0),
    slots: [const {
        FastSlot {
            key: AtomicUsize::new(0),
            device: AtomicPtr::new(std::ptr::null_mut()),
        }
    }; FAST_SLOTS],
};

/// Enters a device into [`FAST`] (where a slot is free). Called with [`DEVICES`]' write lock
/// held, which orders every writer of the table.
fn fast_insert(k: Key, d: &Arc<Device>) {
    let used = FAST.used.load(Ordering::Relaxed);
    let Some(i) =
        (0..FAST_SLOTS).find(|&i| i >= used || FAST.slots[i].key.load(Ordering::Relaxed) == 0)
    else {
        return;
    };
    let s = &FAST.slots[i];
    s.device.store(Arc::as_ptr(d).cast_mut(), Ordering::Relaxed);
    // Publishes the pointer: a reader that sees the key sees the pointer stored before it.
    s.key.store(k, Ordering::Release);
    if i >= used {
        FAST.used.store(i + 1, Ordering::Release);
    }
}

/// Takes a device out of [`FAST`]; with [`DEVICES`]' write lock held, before its record is freed.
fn fast_remove(k: Key) {
    let used = FAST.used.load(Ordering::Relaxed);
    for s in &FAST.slots[..used] {
        if s.key.load(Ordering::Relaxed) == k {
            s.key.store(0, Ordering::Release);
            s.device.store(std::ptr::null_mut(), Ordering::Relaxed);
        }
    }
}

/// The device of a command buffer, queue or device handle, borrowed for the length of the hook's
/// call: no lock, no reference count, no copy. A scan of [`FAST`] (one compare where the process
/// has one device), else the map.
///
/// Why the borrow is sound (docs/ARCHITECTURE.md#recording-without-locks):
/// - the record is owned by [`DEVICES`] from `vkCreateDevice` until `vkDestroyDevice` has taken it
///   out of both tables; its address does not move (it lives in an `Arc`);
/// - `vkDestroyDevice` may be called only once every object made from the device is destroyed
///   and no call on it or its children runs (external synchronisation of `device`, and
///   VUID-vkDestroyDevice-device-05137: all child objects destroyed;
///   <https://registry.khronos.org/vulkan/specs/latest/man/html/vkDestroyDevice.html>), so while a
///   hook runs on a command buffer or queue of the device, the record cannot be freed;
/// - a slot is rewritten only for another device, after its old device's record was taken out
///   with the key cleared first: a reader that finds its own key (its device is live, so that is
///   the current entry, seen through the handle the application passed it after creating the
///   device) reads the pointer published with it (release/acquire).
///
/// # Safety
/// `handle` must be NULL or a live dispatchable handle made by the loader, and the reference must
/// not be kept beyond the call in which the application hands the layer that handle.
#[inline]
pub unsafe fn device_ref<'a>(handle: impl vk::Handle) -> Option<DeviceRef<'a>> {
    // SAFETY: as the caller promised.
    let k = unsafe { key(handle) }?;
    let used = FAST.used.load(Ordering::Acquire).min(FAST_SLOTS);
    let mut found = None;
    for s in &FAST.slots[..used] {
        if s.key.load(Ordering::Acquire) == k {
            found = Some(s.device.load(Ordering::Relaxed).cast_const());
            break;
        }
    }
    // More devices than slots: the map. The record outlives the lock by the same argument.
    let p = match found {
        Some(p) => p,
        None => DEVICES.read().get(&k).map(Arc::as_ptr)?,
    };
    // SAFETY: published with its key (or owned by the map); alive for the caller's call (above).
    let device = unsafe { p.as_ref() }?;
    Some(DeviceRef {
        device,
        _here: PhantomData,
    })
}

/// A device record borrowed for one hook's call ([`device_ref`]): neither `Send` nor `Sync`, so it
/// cannot be handed to another thread and outlive the call there.
pub struct DeviceRef<'a> {
    device: &'a Device,
    _here: PhantomData<*const ()>,
}

impl std::ops::Deref for DeviceRef<'_> {
    type Target = Device;

    #[inline]
    fn deref(&self) -> &Device {
        self.device
    }
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
        crate::vk::image::set_own(k, data.attachments.own.clone());
        let d = Arc::new(data);
        let mut devices = DEVICES.write();
        // A key reused by a new device (the old one's gone, or the loader's tables are at
        // another address): the old entry is replaced.
        fast_remove(k);
        fast_insert(k, &d);
        devices.insert(k, d);
    }
}

/// Whether a device with dispatch key `k` is recorded.
pub fn has_key(k: Key) -> bool {
    DEVICES.read().contains_key(&k)
}

/// Forgets a device, returning its record.
///
/// # Safety
/// As [`key`].
pub unsafe fn remove_device(handle: vk::Device) -> Option<Arc<Device>> {
    // SAFETY: as the caller promised.
    let k = unsafe { key(handle) }?;
    let d = {
        let mut devices = DEVICES.write();
        fast_remove(k);
        devices.remove(&k)
    };
    crate::vk::image::set_own(k, None);
    if d.is_some() {
        crate::bridge::set_device_fdm(handle, None);
    }
    d
}

/// What a command-recording hook needs of its device: whether it emulates density maps, and the
/// next layer's pointers, borrowed from the device's record (see [`device_ref`]).
#[derive(Clone, Copy)]
pub struct Recording<'a> {
    pub emulated: bool,
    pub next: &'a DeviceNext,
}

/// The recording state of a command buffer's (or queue's) device: [`device_ref`], without a lock,
/// a reference count or a copy of the next layer's table.
///
/// # Safety
/// As [`device_ref`].
#[inline]
pub unsafe fn recording<'a>(handle: impl vk::Handle) -> Option<Recording<'a>> {
    // SAFETY: as the caller promised.
    unsafe { device_ref::<'a>(handle) }.map(|d| Recording {
        emulated: d.device.fdm.is_some(),
        next: &d.device.next,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    unsafe extern "system" fn no_gdpa(
        _: vk::Device,
        _: *const std::ffi::c_char,
    ) -> vk::PFN_vkVoidFunction {
        None
    }

    /// A stand-in for a loader-made dispatchable object: its first word is the dispatch key.
    fn object(key: usize) -> Box<usize> {
        Box::new(key)
    }

    fn record(handle: &usize, api_version: u32) -> Device {
        Device {
            handle: vk::Device::from_raw(handle as *const usize as u64),
            gdpa: no_gdpa,
            next: DeviceNext::default(),
            fdm: None,
            inject: None,
            api_version,
            attachments: Attachments::new(None),
        }
    }

    /// Devices come and go; a command buffer (any object with the device's key) finds its own
    /// record and nothing else, and a key a destroyed device leaves behind finds the new device.
    #[test]
    fn recording_hooks_find_their_device_without_the_map() {
        // Keys no live loader table has (odd addresses).
        let keys = [0x1001usize, 0x2001, 0x3001];
        let objects: Vec<Box<usize>> = keys.iter().map(|&k| object(k)).collect();
        let cb = |i: usize| vk::CommandBuffer::from_raw(&*objects[i] as *const usize as u64);
        // SAFETY: the handles point at words holding their keys, alive for the test.
        unsafe {
            for (i, o) in objects.iter().enumerate() {
                add_device(record(o, i as u32));
            }
            for i in 0..3 {
                assert_eq!(device_ref(cb(i)).map(|d| d.api_version), Some(i as u32));
                assert_eq!(recording(cb(i)).map(|r| r.emulated), Some(false));
            }
            let gone = remove_device(vk::Device::from_raw(cb(1).as_raw())).expect("recorded");
            assert_eq!(gone.api_version, 1);
            drop(gone);
            assert!(device_ref(cb(1)).is_none());
            assert_eq!(device_ref(cb(2)).map(|d| d.api_version), Some(2));
            // The same key for a new device: its record, not the freed one.
            add_device(record(&objects[1], 7));
            assert_eq!(device_ref(cb(1)).map(|d| d.api_version), Some(7));
            assert!(device_ref(vk::CommandBuffer::null()).is_none());
            for i in 0..3 {
                remove_device(vk::Device::from_raw(cb(i).as_raw()));
                assert!(device_ref(cb(i)).is_none());
            }
        }
    }
}
