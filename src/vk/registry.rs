//! The layer's instance and device records, keyed by the loader's dispatch pointer, and each
//! command buffer's record, keyed by its handle: what a hook finds from the dispatchable handle it
//! is given. Everything else the layer keeps per device hangs off the device's record
//! ([`Device`]: each mode's state, the layer's own calls, the command pools' queue families), and
//! per command buffer off its record ([`CbRecord`]: its bindings, its conversions, its plan), so
//! it goes with them (docs/ARCHITECTURE.md#who-owns-what).
//!
//! Every dispatchable handle (instance, physical device, device, queue, command buffer) points at
//! an object whose first word is the loader's dispatch table pointer; a physical device shares its
//! instance's, and queues and command buffers share their device's
//! (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>,
//! "Dispatchable Object Creation"). That word is the key.

use std::collections::{BTreeMap, HashMap};
use std::hash::BuildHasherDefault;
use std::marker::PhantomData;
use std::sync::atomic::{AtomicPtr, AtomicUsize, Ordering};
use std::sync::Arc;

use ash::vk;
use ash::vk::Handle as _;

use crate::bridge::FdmEmulation;
use crate::common::lock::{MapLock, Mutex, Rank, SharedMutex};
use crate::vk::base::ffi::{key, AddressHasher, Key};
use crate::vk::base::next::{DeviceNext, InstanceNext};
use crate::vk::own::bindings::Bound;
use crate::vk::own::calls::Own;
use crate::vk::own::converter::{Conversion, Converter};
use crate::vk::own::injector::Injector;
use crate::vk::own::reconstructor::{Plan, Reconstructor};
use crate::vk::own::shadows::{ShadowImage, ShadowView};

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

/// One `VkDevice` created through the layer, and everything the layer keeps for it: each mode's
/// state is a field here, made before the record is entered and dropped with it.
pub struct Device {
    pub handle: vk::Device,
    /// The dispatch key of the instance it was made from, whose destruction forgets it
    /// ([`forget_devices_of`]).
    pub instance: Key,
    /// The next layer's `vkGetDeviceProcAddr`.
    pub gdpa: vk::PFN_vkGetDeviceProcAddr,
    pub next: DeviceNext,
    /// The next layer's `vkCmdEndRendering` (or its KHR alias), which `vkCmdEndRendering2EXT`
    /// goes down as on an emulating device (`None` elsewhere).
    pub end_rendering: Option<vk::PFN_vkCmdEndRendering>,
    /// `Some` where the device emulates fragment density maps.
    pub fdm: Option<FdmEmulation>,
    /// The device's Vulkan version (the instance's and the physical device's lower one): below
    /// 1.2 render pass 2 is `VK_KHR_create_renderpass2`'s, which the layer enables for emulation,
    /// and the core names may not be called.
    pub api_version: u32,
    /// The layer's own device-level calls (creating, clearing and destroying shadows and injected
    /// maps, the conversion's and the reconstruction's objects), shared by the modes; `None` where
    /// the device neither emulates nor injects, or the layer could not set them up (no shadows,
    /// maps, conversion or reconstruction then).
    pub own: Option<Arc<Own>>,
    /// Emulation's state: shadows, rewritten passes and the converter (empty where not
    /// emulating).
    pub emulation: Emulation,
    /// Where injection is on (docs/injection.md), the device got shading-rate attachments at
    /// `vkCreateDevice` and the layer could set up its own calls on it: its injected maps and what
    /// it tracks to find eye passes ([`crate::vk::own::injector`]).
    pub injection: Option<Injector>,
    /// The reconstruction of coarse blocks (docs/reconstruction.md), where the device injects or
    /// emulates and can record compute dispatches.
    pub reconstructor: Option<Arc<Reconstructor>>,
    /// Command pool → its queue family (from `vkCreateCommandPool`, hooked on emulating devices),
    /// which its command buffers' records take at allocation ([`CbRecord::family`]). A leaf lock,
    /// taken when pools are made and destroyed and command buffers allocated.
    pub command_pools: parking_lot::Mutex<HashMap<u64, u32>>,
}

/// Per device: application handles → the layer's shadows, the render passes the layer rewrote
/// (by handle → the index of the density attachment, now a shading-rate attachment), and the
/// converter of the maps the application writes itself.
pub struct Emulation {
    pub images: Mutex<HashMap<u64, ShadowImage>>,
    pub views: Mutex<HashMap<u64, ShadowView>>,
    pub passes: Mutex<HashMap<u64, u32>>,
    /// Set once the log has said that the application writes density maps itself (converted at
    /// pass begin, [`crate::vk::convert`]).
    pub app_maps_logged: std::sync::atomic::AtomicBool,
    /// The conversion of density maps the application writes (`None` where the device does not
    /// emulate or cannot convert, `crate::vk::convert::converter_for`); each command buffer's
    /// record holds its share ([`CbRecord::conversion`]).
    pub converter: Option<Arc<Converter>>,
}

impl Emulation {
    /// No shadows yet.
    pub fn new(converter: Option<Arc<Converter>>) -> Emulation {
        Emulation {
            images: Mutex::ranked(Rank::Record, "vk shadow images", HashMap::new()),
            views: Mutex::ranked(Rank::Record, "vk shadow views", HashMap::new()),
            passes: Mutex::ranked(Rank::Record, "vk rewritten passes", HashMap::new()),
            app_maps_logged: std::sync::atomic::AtomicBool::new(false),
            converter,
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
    if d.is_some() {
        crate::bridge::set_device_fdm(handle, None);
        crate::bridge::set_device_offsets(handle, None);
    }
    d
}

/// Forgets, without a call to the driver, every device made from the instance with dispatch key
/// `instance`, which the application destroys with them still alive (an application bug,
/// VUID-vkDestroyInstance-instance-00629, that real applications have): the loader frees their
/// dispatch tables with the instance, so their keys may come back for new devices, and their
/// command buffers' handles for new command buffers. Returns the forgotten devices' keys: what
/// their command buffers' records hold is dropped as it is ([`device_key_reused`]).
pub fn forget_devices_of(instance: Key) -> Vec<Key> {
    let gone: Vec<(Key, Arc<Device>)> = {
        let mut devices = DEVICES.write();
        let keys: Vec<Key> = devices
            .iter()
            .filter(|(_, d)| d.instance == instance)
            .map(|(&k, _)| k)
            .collect();
        keys.into_iter()
            .filter_map(|k| {
                fast_remove(k);
                devices.remove(&k).map(|d| (k, d))
            })
            .collect()
    };
    gone.into_iter()
        .map(|(k, d)| {
            crate::bridge::set_device_fdm(d.handle, None);
            crate::bridge::set_device_offsets(d.handle, None);
            k
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Command pools' and command buffers' queue families.

/// Notes the queue family of a command pool `vkCreateCommandPool` just made on `dev`.
pub fn pool_created(dev: &Device, pool: u64, family: u32) {
    dev.command_pools.lock().insert(pool, family);
}

/// Whether a barrier with these queue family indices, recorded into `cb`, is the release half of a
/// queue family ownership transfer. Not a transfer where the indices are equal or either is
/// `IGNORED`; a release where the destination is outside the device (`EXTERNAL`, `FOREIGN`), an
/// acquire where the source is; between two of the device's families, a release where `cb`'s pool
/// belongs to the source family ([`CbRecord::family`]). Where that family is not known, a release:
/// an acquire half then goes without the shadow's barrier, which is what the application wrote.
pub fn is_release(cb: vk::CommandBuffer, src: u32, dst: u32) -> bool {
    let outside = |q: u32| q == vk::QUEUE_FAMILY_EXTERNAL || q == vk::QUEUE_FAMILY_FOREIGN_EXT;
    if src == dst || src == vk::QUEUE_FAMILY_IGNORED || dst == vk::QUEUE_FAMILY_IGNORED {
        return false;
    }
    if outside(dst) {
        return true;
    }
    if outside(src) {
        return false;
    }
    record_of(cb, |r| r.family)
        .flatten()
        .is_none_or(|f| f == src)
}

// ---------------------------------------------------------------------------------------------
// Every command buffer's record.

/// Plans noted in command buffers' records and not yet taken by their pass's end (or dropped by a
/// new recording): while none is, the end of a pass costs one atomic load
/// ([`crate::vk::reconstruct`]'s `ended`).
pub static OPEN_PLANS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Notes `plan` in a command buffer's record, in place of any open one.
pub fn set_plan(record: &CbRecord, plan: Plan) {
    if record.plan.lock().replace(plan).is_none() {
        OPEN_PLANS.fetch_add(1, Ordering::AcqRel);
    }
}

/// Takes a command buffer's open plan, if any.
pub fn take_plan(record: &CbRecord) -> Option<Plan> {
    let p = record.plan.lock().take();
    if p.is_some() {
        OPEN_PLANS.fetch_sub(1, Ordering::AcqRel);
    }
    p
}

/// One command buffer's record: what it has bound ([`Bound`]), behind a lock of its own. Command
/// buffers are externally synchronised (a command buffer and its pool are used by one thread at a
/// time, <https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#fundamentals-threadingbehavior>),
/// so that lock is never contended: it is one uncontended atomic on the record's own memory, which
/// no other command buffer shares.
pub struct CbRecord {
    /// The device's dispatch key, whose destruction drops the record.
    pub device: Key,
    /// The pool it was allocated from (0 where the layer did not see the allocation), whose
    /// destruction drops the record.
    pub pool: u64,
    /// The queue family of its pool, where the layer saw the pool made ([`is_release`]).
    pub family: Option<u32>,
    /// A secondary command buffer (whose begin info's inheritance info is read).
    pub secondary: bool,
    pub bound: parking_lot::Mutex<Bound>,
    /// Its share of the device's converter (`None` where the device converts nothing): the slots
    /// it converts with, which it owns ([`Conversion`]). Taken once at allocation, so that a pass
    /// begin reaches it through this record without a look-up of the device's.
    pub conversion: Option<Conversion>,
    /// The device's reconstructor (`None` where it reconstructs nothing), taken at allocation like
    /// the conversion.
    pub reconstructor: Option<Arc<Reconstructor>>,
    /// What the end of the render pass instance open in this command buffer reconstructs
    /// (docs/reconstruction.md), set where it begins.
    pub plan: parking_lot::Mutex<Option<Plan>>,
}

impl CbRecord {
    /// The record of a command buffer of `dev` (dispatch key `device`) allocated from `pool` (0:
    /// not seen): nothing bound, its share of the device's converter, the device's reconstructor.
    pub fn new(dev: &Device, device: Key, pool: u64, secondary: bool) -> CbRecord {
        CbRecord {
            device,
            pool,
            family: dev.command_pools.lock().get(&pool).copied(),
            secondary,
            bound: parking_lot::Mutex::new(Bound::default()),
            conversion: dev.emulation.converter.clone().map(Conversion::new),
            reconstructor: dev.reconstructor.clone(),
            plan: parking_lot::Mutex::new(None),
        }
    }
}

type Records = HashMap<u64, Arc<CbRecord>, BuildHasherDefault<AddressHasher>>;

/// Every command buffer's record. Taken only to add a record (at allocation), to drop one (free,
/// pool or device destruction), and on a thread's first look-up of a command buffer since any of
/// these: recording threads find their command buffers' records in their own [`CB_CACHE`]
/// without it. A leaf lock.
pub static CB_RECORDS: SharedMutex<Records> =
    SharedMutex::new(HashMap::with_hasher(BuildHasherDefault::new()));

/// Advanced (under [`CB_RECORDS`]) whenever a record is added or dropped: a cached look-up is good
/// only while the generation it was made in is current, so a handle value the driver reuses for a
/// new command buffer never finds the old one's record.
pub static CB_GENERATION: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

/// A thread's cached look-up: command buffer, generation, record.
type CacheEntry = (u64, u64, *const CbRecord);

/// Look-ups a thread keeps: the command buffers it records at once.
const CACHED: usize = 4;

thread_local! {
    static CB_CACHE: std::cell::Cell<[CacheEntry; CACHED]> =
        const { std::cell::Cell::new([(0, 0, std::ptr::null()); CACHED]) };
}

/// `cb`'s record, for the length of a call on `cb`: from this thread's cache where it is current,
/// else from [`CB_RECORDS`], then cached; a command buffer without a record is cached as such
/// (a null record), so that asking again takes no lock either.
///
/// Sound because a record leaves [`CB_RECORDS`] (and may be freed) only when its command buffer is
/// freed, its pool or its device destroyed, which the application synchronises with every call on
/// the command buffer; and every such change advances [`CB_GENERATION`], so no entry made before
/// it is used after it.
#[inline]
pub fn record_of<R>(cb: vk::CommandBuffer, f: impl FnOnce(&CbRecord) -> R) -> Option<R> {
    let raw = cb.as_raw();
    let now = CB_GENERATION.load(Ordering::Acquire);
    let cached = CB_CACHE
        .try_with(|c| {
            c.get()
                .iter()
                .find(|e| e.0 == raw && e.1 == now)
                .map(|e| e.2)
        })
        .ok()
        .flatten();
    let ptr = match cached {
        Some(p) => p,
        None => {
            let map = CB_RECORDS.lock();
            let p = map.get(&raw).map_or(std::ptr::null(), Arc::as_ptr);
            let _ = CB_CACHE.try_with(|c| {
                let mut v = c.get();
                v.rotate_right(1);
                v[0] = (raw, now, p);
                c.set(v);
            });
            p
        }
    };
    // SAFETY: the record is alive for this call on `cb` (see above); null: none.
    unsafe { ptr.as_ref() }.map(f)
}

/// Runs `f` on `cb`'s bindings, if it has a record.
#[inline]
pub fn with_record(cb: vk::CommandBuffer, f: impl FnOnce(&mut Bound)) {
    record_of(cb, |r| f(&mut r.bound.lock()));
}

/// Drops the records `drop` selects, and destroys their conversion objects (their command
/// buffers are being freed, with their pool or device, and so are not pending).
pub fn forget_command_buffers_where(drop: impl Fn(u64, &CbRecord) -> bool) {
    let mut gone = Vec::new();
    {
        let mut map = CB_RECORDS.lock();
        let before = map.len();
        map.retain(|&cb, r| {
            let d = drop(cb, r);
            if d {
                gone.push(Arc::clone(r));
            }
            !d
        });
        if map.len() != before {
            CB_GENERATION.fetch_add(1, Ordering::Release);
        }
    }
    destroy_records(gone);
}

/// Drops the records of freed command buffers (a look-up each, not a scan of every record).
pub fn forget_command_buffers(cbs: &[vk::CommandBuffer]) {
    let mut gone = Vec::new();
    {
        let mut map = CB_RECORDS.lock();
        for cb in cbs {
            if let Some(r) = map.remove(&cb.as_raw()) {
                gone.push(r);
            }
        }
        if !gone.is_empty() {
            CB_GENERATION.fetch_add(1, Ordering::Release);
        }
    }
    destroy_records(gone);
}

/// Destroys the conversion objects of dropped records.
fn destroy_records(gone: Vec<Arc<CbRecord>>) {
    for r in gone {
        if let Some(c) = &r.conversion {
            // SAFETY: the record's own slots; their command buffer is being freed (with its pool
            // or device) or its handle names a new one, so it is not pending.
            unsafe { c.destroy() };
        }
    }
}

/// Adds (or renews) `cb`'s record. A record the handle still had belonged to a command buffer the
/// layer did not see go (its handle now names a new one): its objects go.
pub fn remember_command_buffer(cb: vk::CommandBuffer, record: CbRecord) {
    let old = {
        let mut map = CB_RECORDS.lock();
        let old = map.insert(cb.as_raw(), Arc::new(record));
        CB_GENERATION.fetch_add(1, Ordering::Release);
        old
    };
    destroy_records(old.into_iter().collect());
}

/// The records of a destroyed pool's command buffers go, and the pool's family.
pub fn command_pool_destroyed(dev: &Device, device: Key, pool: u64) {
    dev.command_pools.lock().remove(&pool);
    forget_command_buffers_where(|_, r| r.device == device && r.pool == pool);
}

/// Forgets, without a call to the driver, the command buffers' records of a device that is gone
/// without `vkDestroyDevice` (see [`forget_devices_of`]): the application destroyed its instance
/// with the device still alive (VUID-vkDestroyInstance-instance-00629), and the loader freed the
/// device's dispatch table, whose address a new device may get. Called at that
/// `vkDestroyInstance`, and where a new device has the dispatch key of one the layer still knows.
/// The old device's objects are gone with it; destroying them now would call a driver that no
/// longer has them, so the records are dropped as they are (their [`Conversion`]s destroy
/// nothing on drop), and with the device's record go its converter and reconstructor.
pub fn device_key_reused(k: Key) {
    let mut map = CB_RECORDS.lock();
    let before = map.len();
    map.retain(|_, r| r.device != k);
    if map.len() != before {
        CB_GENERATION.fetch_add(1, Ordering::Release);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A copy of `cb`'s bindings, `None` where it has no record or they cannot be given back.
    fn bound_of(cb: vk::CommandBuffer) -> Option<Bound> {
        record_of(cb, |r| *r.bound.lock()).filter(|b| !b.lost)
    }

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
            instance: 0,
            gdpa: no_gdpa,
            next: DeviceNext::default(),
            end_rendering: None,
            fdm: None,
            api_version,
            own: None,
            emulation: Emulation::new(None),
            injection: None,
            reconstructor: None,
            command_pools: parking_lot::Mutex::new(HashMap::new()),
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
                assert!(device_ref(cb(i)).is_some_and(|d| d.fdm.is_none()));
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

    /// An instance destroyed before its devices (VUID-vkDestroyInstance-instance-00629) takes
    /// them with it: neither its device nor its command buffers' records are found any more, so
    /// a command buffer of a later device with a recycled handle gets a record of its own and
    /// frees nothing of the dead device's; another instance's device and command buffer stay.
    #[test]
    fn an_instance_destroyed_first_takes_its_devices() {
        let keys = [0x4001usize, 0x5001];
        let objects: Vec<Box<usize>> = keys.iter().map(|&k| object(k)).collect();
        let handle = |i: usize| &*objects[i] as *const usize as u64;
        let (dead, alive) = (0x0A00_0001usize, 0x0B00_0001usize);
        // SAFETY: the handles point at words holding their keys, alive for the test.
        unsafe {
            for (i, instance) in [(0, dead), (1, alive)] {
                let mut d = record(&objects[i], 1);
                d.instance = instance;
                add_device(d);
            }
        }
        let cb = |i: u64| vk::CommandBuffer::from_raw(0xE0_0000 + i);
        let dev = record(&objects[0], 1);
        let remember =
            |cb, k, pool| remember_command_buffer(cb, CbRecord::new(&dev, k, pool, false));
        remember(cb(0), keys[0], 9);
        remember(cb(1), keys[1], 9);
        let of = |k: Key| CB_RECORDS.lock().values().filter(|r| r.device == k).count();
        assert_eq!((of(keys[0]), of(keys[1])), (1, 1));

        assert_eq!(forget_devices_of(dead), vec![keys[0]]);
        // What `vkDestroyInstance` does next for each forgotten device: its command buffers'
        // records go, without a driver call.
        device_key_reused(keys[0]);
        // SAFETY: as above.
        unsafe {
            assert!(device_ref(vk::Device::from_raw(handle(0))).is_none());
            assert!(device(vk::Device::from_raw(handle(0))).is_none());
            assert!(device_ref(vk::Device::from_raw(handle(1))).is_some());
        }
        assert_eq!((of(keys[0]), of(keys[1])), (0, 1));
        assert!(
            bound_of(cb(0)).is_none(),
            "no record, in this thread's cache either"
        );
        assert!(forget_devices_of(dead).is_empty(), "forgotten once");
        // The dead device's command buffer handle, recycled by a later device.
        remember(cb(0), keys[1], 10);
        assert_eq!(
            record_of(cb(0), |r| (r.device, r.pool)),
            Some((keys[1], 10))
        );
        forget_command_buffers_where(|_, r| r.device == keys[1]);
        // SAFETY: as above.
        unsafe { remove_device(vk::Device::from_raw(handle(1))) };
    }

    #[test]
    fn release_halves_are_told_from_acquire_halves() {
        let ignored = vk::QUEUE_FAMILY_IGNORED;
        let external = vk::QUEUE_FAMILY_EXTERNAL;
        let cb = vk::CommandBuffer::from_raw(0x5a5a_0010);
        // Not transfers.
        assert!(!is_release(cb, ignored, ignored));
        assert!(!is_release(cb, 1, 1));
        assert!(!is_release(cb, 0, ignored));
        // To and from outside the device.
        assert!(is_release(cb, 0, external));
        assert!(!is_release(cb, external, 0));
        // Between two families: by the command buffer's; unknown counts as a release.
        assert!(is_release(cb, 0, 1));
        let object = object(0x7001);
        let dev = record(&object, 1);
        let pool = 0x5a5a_0020;
        remember_command_buffer(cb, CbRecord::new(&dev, 0x7001, pool, false));
        assert!(is_release(cb, 0, 1), "a pool the layer did not see made");
        pool_created(&dev, pool, 1);
        remember_command_buffer(cb, CbRecord::new(&dev, 0x7001, pool, false));
        assert!(
            !is_release(cb, 0, 1),
            "recorded on the destination family: acquire"
        );
        assert!(
            is_release(cb, 1, 0),
            "recorded on the source family: release"
        );
        command_pool_destroyed(&dev, 0x7001, pool);
        assert!(
            dev.command_pools.lock().is_empty(),
            "the pool's family goes with it"
        );
        assert!(
            is_release(cb, 0, 1),
            "the command buffer's record went with its pool"
        );
    }

    /// A command buffer's queue family is its record's, taken from its pool at allocation: however
    /// many command buffers are allocated after it (more than any fixed-size table of families
    /// holds, so one whose handle hashes where its does), an acquire half recorded into it stays an
    /// acquire, and its pool's family goes with the pool.
    #[test]
    fn a_command_buffers_family_outlives_any_number_of_others() {
        let k: Key = 0x8001;
        let object = object(k);
        let dev = record(&object, 1);
        let (pool, other_pool) = (0x8800_0001u64, 0x8800_0002u64);
        pool_created(&dev, pool, 1);
        pool_created(&dev, other_pool, 0);
        let cb = vk::CommandBuffer::from_raw(0x8100_0000);
        remember_command_buffer(cb, CbRecord::new(&dev, k, pool, false));
        let others: Vec<vk::CommandBuffer> = (1..=5000u64)
            .map(|i| vk::CommandBuffer::from_raw(0x8100_0000 + i * 8))
            .collect();
        for &o in &others {
            remember_command_buffer(o, CbRecord::new(&dev, k, other_pool, false));
        }
        assert!(
            !is_release(cb, 0, 1),
            "recorded on the destination family after 5000 other allocations: acquire"
        );
        assert!(
            is_release(others[0], 0, 1),
            "the others' family is the source's"
        );
        command_pool_destroyed(&dev, k, pool);
        command_pool_destroyed(&dev, k, other_pool);
        assert!(dev.command_pools.lock().is_empty());
    }

    /// A pool's destruction drops the records of the command buffers allocated from it, and only
    /// those: over many create, allocate and destroy cycles the records do not grow.
    #[test]
    fn destroyed_pools_take_their_command_buffers_records() {
        let device: Key = 0xD0_0000;
        let object = object(device);
        let dev = record(&object, 1);
        let remember_command_buffer = |cb, _: Key, pool, secondary| {
            remember_command_buffer(cb, CbRecord::new(&dev, device, pool, secondary))
        };
        let command_pool_destroyed = |_: Key, pool| command_pool_destroyed(&dev, device, pool);
        let count = |pool: u64| {
            CB_RECORDS
                .lock()
                .values()
                .filter(|r| r.device == device && r.pool == pool)
                .count()
        };
        remember_command_buffer(vk::CommandBuffer::from_raw(0xD0_0001), device, 7, false);
        for cycle in 0..100u64 {
            let pool = 100 + cycle;
            for i in 0..4 {
                let cb = vk::CommandBuffer::from_raw(0xD1_0000 + cycle * 8 + i);
                remember_command_buffer(cb, device, pool, i % 2 == 1);
                with_record(cb, |b| b.lost = true);
            }
            assert_eq!(count(pool), 4);
            command_pool_destroyed(device, pool);
            assert_eq!(count(pool), 0, "cycle {cycle}");
        }
        let left = CB_RECORDS
            .lock()
            .values()
            .filter(|r| r.device == device)
            .count();
        assert_eq!(left, 1, "the other pool's command buffer stays");
        assert!(bound_of(vk::CommandBuffer::from_raw(0xD0_0001)).is_some());
        assert!(
            bound_of(vk::CommandBuffer::from_raw(0xD1_0000)).is_none(),
            "a freed handle finds no record, in this thread's cache either"
        );
        forget_command_buffers_where(|_, r| r.device == device);
    }
}
