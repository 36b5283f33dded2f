//! The layer's own calls on a device ([`Own`]): the next layer's device commands, memory types,
//! `vkSetDeviceLoaderData` for the command buffers it allocates
//! (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>,
//! "Creating New Dispatchable Objects"), full-rate stand-ins, and the clears and uploads it runs
//! ahead of the application's next submit ([`Clears`]).
//!
//! Clears. A new shadow must hold rate code 0 (1×1, full rate) before any pass reads it
//! (docs/vulkan-fdm-on-fsr.md#shadows), and a clear needs a queue. Vulkan makes every use of a
//! queue externally synchronised by the application
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkQueueSubmit.html>, "Host
//! Synchronization"), so the layer may only use a queue inside a call the application made on it:
//! `vkCreateImage` records the shadow as pending ([`Clears::add`]), and the next
//! `vkQueueSubmit`, `vkQueueSubmit2` or `vkQueueSubmit2KHR` on a queue of a graphics family (where
//! the passes that read the shadow run) first submits one layer-owned command buffer that clears
//! every pending shadow and moves it to the shading-rate layout, with a fence of the layer's own.
//! A separate submission just before the application's is ordered before it like a batch of the
//! same call: both are in the queue's submission order, and the clear's last barrier has every
//! later command in its second scope
//! (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#synchronization-submission-order>).
//! Its own fence tells when the command buffer may be recorded again; the application's fences of later
//! submissions cover it too ("fence signal operations … include … all commands that occur earlier
//! in submission order", <https://registry.khronos.org/vulkan/specs/latest/man/html/vkQueueSubmit.html>),
//! so an application that waits for its own work before `vkDestroyDevice` has waited for the clear.
//!
//! The command buffer is recorded at that submit, not at `vkCreateImage`: only then is the queue
//! family known, and it is recorded once for all shadows made since the last one. Where recording or
//! submitting it fails, the application's submit returns that result (one of those `vkQueueSubmit`
//! may return) without going down, and the clears stay pending: the application's work would read
//! shadows in an undefined layout otherwise.
//!
//! A shadow destroyed before any submit drops its pending clear (no command buffer exists yet); one
//! destroyed while its clear is in flight is destroyed once that clear's fence has signalled
//! ([`Clears::forget`]). fovea's own density images get no clear: every upload writes the whole
//! shadow, from `UNDEFINED`, before the application can render with the image
//! (`src/xr/density_images.rs`, docs/ARCHITECTURE.md "Maps are written only on acquire"), so no
//! clear can land after an upload.
//!
//! Uploads. Injected shading-rate maps (docs/injection.md#how-the-attachment-gets-in) are filled
//! with bytes the layer computed, by the same means and at the same moment: [`Clears::upload`]
//! stages them, and the next submit on a graphics queue copies them from a host-visible staging
//! buffer of the layer's own into the image, from `UNDEFINED` (every texel is written) after an
//! execution dependency on everything earlier on that queue (a pass that still reads the image's
//! old content), ending in the shading-rate layout.
//!
//! Nothing per move. A gaze that moves refills a map every frame, so the submission's objects are
//! kept ([`Batch`]: its command buffer, fence and mapped staging buffer, per queue family) and
//! recorded again once their fence has signalled; an image's bytes wait in a slot of their own
//! ([`Upload`]), overwritten by newer ones. In steady state a move allocates nothing, host or
//! device. Recording threads hand their clears and uploads over under [`Clears::state`], held for
//! a list update or a copy of bytes; the submit runs under [`Clears::submits`], which no recording
//! path takes.

use std::ffi::c_void;
use std::sync::atomic::{AtomicUsize, Ordering};

use ash::vk;
use ash::vk::Handle as _;

use crate::bridge::FdmEmulation;
use crate::common::lock::{Mutex, Rank};
use crate::vk::base::chain;
use crate::vk::base::ffi::raw;
use crate::vk::base::link::LayerDeviceCreateInfo;
use crate::vk::own::order::Order;
use crate::vk::own::shadows::ShadowImage;
use crate::vk::translate::formats::{shadow_layers, SHADOW_FORMAT, SHADOW_LAYOUT, SHADOW_USAGE};

/// `PFN_vkSetDeviceLoaderData`.
pub type SetDeviceLoaderData = unsafe extern "system" fn(vk::Device, *mut c_void) -> vk::Result;

/// `VK_LOADER_DATA_CALLBACK`: the `VkLayerDeviceCreateInfo` that carries `pfnSetDeviceLoaderData`.
pub const LOADER_DATA_CALLBACK: u32 = 1;

/// What the layer needs to make, clear and destroy shadows on one device.
pub struct Own {
    /// The next layer's device commands.
    pub fns: ash::Device,
    pub memory: vk::PhysicalDeviceMemoryProperties,
    pub set_loader_data: SetDeviceLoaderData,
    /// The shadows' clears, run ahead of the application's submits ([`Clears`]).
    pub clears: Clears,
    /// Full-rate stand-ins for density views without a shadow ([`Own::full_rate_view`]): one
    /// layer each, kept until the device is destroyed.
    pub fallbacks: Mutex<Vec<(ShadowImage, vk::ImageView)>>,
}

impl Own {
    /// Sets up the layer's own calls on a device just created.
    ///
    /// # Safety
    /// `ci` must be the application's valid create info of `device`, made on `physical` of
    /// `instance`, whose next layer's `vkGetInstanceProcAddr` is `gipa`;
    /// `gdpa` the next layer's `vkGetDeviceProcAddr`. With `timelines` (the device was created
    /// with the timeline-semaphore feature for it) and more than one graphics queue, the layer's
    /// uploads are ordered against every queue ([`Order`]).
    pub unsafe fn new(
        instance: vk::Instance,
        gipa: vk::PFN_vkGetInstanceProcAddr,
        physical: vk::PhysicalDevice,
        ci: &vk::DeviceCreateInfo<'_>,
        device: vk::Device,
        gdpa: vk::PFN_vkGetDeviceProcAddr,
        timelines: bool,
    ) -> Result<Own, String> {
        // SAFETY: a valid chain, as the caller promised.
        let set_loader_data = unsafe { loader_data_callback(ci) }
            .ok_or("the loader passed no vkSetDeviceLoaderData")?;
        // SAFETY: the next layer's instance commands, of the types their names imply.
        let (families, memory) = unsafe {
            let families = queue_families(instance, gipa, physical)
                .ok_or("no vkGetPhysicalDeviceQueueFamilyProperties")?;
            let m = gipa(instance, c"vkGetPhysicalDeviceMemoryProperties".as_ptr())
                .ok_or("no vkGetPhysicalDeviceMemoryProperties")?;
            let m = std::mem::transmute::<
                unsafe extern "system" fn(),
                vk::PFN_vkGetPhysicalDeviceMemoryProperties,
            >(m);
            let mut memory = vk::PhysicalDeviceMemoryProperties::default();
            m(physical, &mut memory);
            (families, memory)
        };
        // SAFETY: the next layer's commands for the live device, of the types their names imply.
        let fns = unsafe {
            ash::Device::load_with(
                |name| gdpa(device, name.as_ptr()).map_or(std::ptr::null(), |f| f as *const c_void),
                device,
            )
        };
        // The application's queues of graphics families, where the passes that read shadows run
        // and so where their clears go. Protected-capable queues (created with flags) are left out:
        // they need vkGetDeviceQueue2, and a clear never needs one.
        let mut queues = Vec::new();
        // SAFETY: as the caller promised.
        for (family, count) in unsafe { graphics_queues(ci, &families) } {
            for i in 0..count {
                // SAFETY: a queue the application created; only its handle is kept.
                let queue = unsafe { fns.get_device_queue(family, i) };
                queues.push((queue.as_raw(), family));
            }
        }
        if queues.is_empty() {
            return Err("the device has no graphics queue the layer could clear shadows on".into());
        }
        let mut clears = Clears::new(queues);
        if timelines && clears.queues.len() > 1 {
            // SAFETY: the live device, created with the timeline-semaphore feature.
            match unsafe { Order::new(&fns, &clears.queues) } {
                Ok(o) => {
                    tracing::info!(
                        queues = clears.queues.len(),
                        "the layer's uploads are ordered against every graphics queue with \
                         timeline semaphores"
                    );
                    clears.order = Some(o);
                }
                Err(e) => tracing::warn!(
                    result = ?e,
                    "no timeline semaphores for the layer's uploads: a pass on another graphics \
                     queue than the one an upload runs on is not ordered against it"
                ),
            }
        }
        Ok(Own {
            fns,
            memory,
            set_loader_data,
            clears,
            fallbacks: Mutex::ranked(Rank::Record, "vk full-rate shadows", Vec::new()),
        })
    }

    /// Gives a command buffer the layer allocated the loader's dispatch pointer
    /// (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>,
    /// "Creating New Dispatchable Objects").
    ///
    /// # Safety
    /// `cb` must be a command buffer the layer just allocated on this device.
    pub unsafe fn set_loader_data(&self, cb: vk::CommandBuffer) -> Result<(), vk::Result> {
        // SAFETY: as the caller promised.
        unsafe { (self.set_loader_data)(self.fns.handle(), cb.as_raw() as *mut c_void) }.result()
    }

    /// A full-rate shading-rate view (rate code 0 everywhere, one layer) that covers a framebuffer
    /// of `width`×`height` pixels: the stand-in for a density view whose shadow could not be made,
    /// in a framebuffer of a pass translated for shading rates, where the density view itself is
    /// invalid usage
    /// (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkFramebufferCreateInfo.html>,
    /// VUID-VkFramebufferCreateInfo-flags-04548). One layer is valid with any framebuffer layer count
    /// and view mask (a shading-rate attachment's layer count "must be either 1, or greater than"
    /// them, same page). Made at framebuffer
    /// creation, shared by every framebuffer it covers; `None` (logged) where it cannot be made.
    ///
    /// # Safety
    /// `self` must belong to a live device emulating as `fdm` says.
    pub unsafe fn full_rate_view(
        &self,
        fdm: &FdmEmulation,
        width: u32,
        height: u32,
    ) -> Option<vk::ImageView> {
        let need = vk::Extent2D {
            width: width.div_ceil(fdm.texel[0].max(1)).max(1),
            height: height.div_ceil(fdm.texel[1].max(1)).max(1),
        };
        let mut list = self.fallbacks.lock();
        if let Some((_, v)) = list
            .iter()
            .find(|(s, _)| s.extent.width >= need.width && s.extent.height >= need.height)
        {
            return Some(*v);
        }
        let extent = vk::Extent3D {
            width: need.width,
            height: need.height,
            depth: 1,
        };
        // SAFETY: the layer's own image and view on a live device; the image is destroyed again
        // where its view cannot be made (its clear, still pending, is dropped first).
        let made = unsafe {
            make_shadow(self, fdm, extent, 1, true).and_then(|s| {
                let info = vk::ImageViewCreateInfo::default()
                    .image(s.image)
                    .view_type(vk::ImageViewType::TYPE_2D)
                    .format(SHADOW_FORMAT)
                    .subresource_range(vk::ImageSubresourceRange {
                        aspect_mask: vk::ImageAspectFlags::COLOR,
                        base_mip_level: 0,
                        level_count: 1,
                        base_array_layer: 0,
                        layer_count: 1,
                    });
                match self.fns.create_image_view(&info, None) {
                    Ok(v) => Ok((s, v)),
                    Err(e) => {
                        self.clears.forget(&self.fns, &s);
                        Err(e)
                    }
                }
            })
        };
        match made {
            Ok((s, v)) => {
                tracing::info!(
                    width = need.width,
                    height = need.height,
                    "a full-rate shading-rate attachment stands in for density views without a \
                     shadow"
                );
                list.push((s, v));
                Some(v)
            }
            Err(e) => {
                tracing::warn!(
                    result = ?e,
                    "no full-rate stand-in for a density view without a shadow either; the \
                     framebuffer is passed on as the application made it"
                );
                None
            }
        }
    }

    /// A host-visible, host-coherent memory type among `bits`, for staging uploads.
    pub fn host_memory_type(&self, bits: u32) -> Option<u32> {
        let want = vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
        let types = &self.memory.memory_types[..self.memory.memory_type_count as usize];
        (0..types.len() as u32)
            .find(|&i| bits & (1 << i) != 0 && types[i as usize].property_flags.contains(want))
    }

    /// A device-local memory type among `bits` (any allowed one where none is device-local).
    /// A layer-owned shading-rate image (`R8_UINT`, [`SHADOW_USAGE`], 2D, optimal tiling) of
    /// `texels` and `layers`, bound to device-local memory of its own: what shadows and injection's
    /// maps are made of. Nothing is left behind on failure.
    ///
    /// # Safety
    /// The device must be live.
    pub unsafe fn shading_rate_image(
        &self,
        texels: [u32; 2],
        layers: u32,
    ) -> Result<(vk::Image, vk::DeviceMemory), vk::Result> {
        let d = &self.fns;
        let info = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(SHADOW_FORMAT)
            .extent(vk::Extent3D {
                width: texels[0],
                height: texels[1],
                depth: 1,
            })
            .mip_levels(1)
            .array_layers(layers)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(SHADOW_USAGE)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        // SAFETY: the layer's own objects on a live device (the caller's promise); each is
        // destroyed again on failure.
        unsafe {
            let image = d.create_image(&info, None)?;
            let req = d.get_image_memory_requirements(image);
            let bound = self.bound_memory(
                req,
                Self::memory_type,
                vk::Result::ERROR_OUT_OF_DEVICE_MEMORY,
                |memory| d.bind_image_memory(image, memory, 0),
            );
            if bound.is_err() {
                d.destroy_image(image, None);
            }
            Ok((image, bound?))
        }
    }

    /// Memory for `req` of the type `pick` finds among the allowed ones (`lacking` where there
    /// is none), bound by `bind`; freed again where binding fails, so that the caller has only
    /// its own object to destroy on failure.
    ///
    /// # Safety
    /// The device must be live; `bind` must bind the object `req` was asked for.
    pub unsafe fn bound_memory(
        &self,
        req: vk::MemoryRequirements,
        pick: fn(&Self, u32) -> Option<u32>,
        lacking: vk::Result,
        bind: impl FnOnce(vk::DeviceMemory) -> Result<(), vk::Result>,
    ) -> Result<vk::DeviceMemory, vk::Result> {
        let ty = pick(self, req.memory_type_bits).ok_or(lacking)?;
        // SAFETY: a live device (the caller's promise); the memory is freed again on failure.
        let memory = unsafe {
            self.fns.allocate_memory(
                &vk::MemoryAllocateInfo::default()
                    .allocation_size(req.size)
                    .memory_type_index(ty),
                None,
            )
        }?;
        if let Err(e) = bind(memory) {
            // SAFETY: just allocated, bound to nothing.
            unsafe { self.fns.free_memory(memory, None) };
            return Err(e);
        }
        Ok(memory)
    }

    pub fn memory_type(&self, bits: u32) -> Option<u32> {
        let allowed = |i: u32| bits & (1 << i) != 0;
        let types = &self.memory.memory_types[..self.memory.memory_type_count as usize];
        (0..types.len() as u32)
            .find(|&i| {
                allowed(i)
                    && types[i as usize]
                        .property_flags
                        .contains(vk::MemoryPropertyFlags::DEVICE_LOCAL)
            })
            .or_else(|| (0..types.len() as u32).find(|&i| allowed(i)))
    }
}

/// The loader's `vkSetDeviceLoaderData` from a device create info.
///
/// # Safety
/// `ci.p_next` must be a valid chain.
pub unsafe fn loader_data_callback(ci: &vk::DeviceCreateInfo<'_>) -> Option<SetDeviceLoaderData> {
    let mut next = ci.p_next;
    for _ in 0..chain::MAX_CHAIN_LENGTH {
        // SAFETY: as the caller promised.
        let found = unsafe {
            chain::find::<LayerDeviceCreateInfo>(next, vk::StructureType::LOADER_DEVICE_CREATE_INFO)
        }
        .ok()
        .flatten()?;
        // SAFETY: found in a valid chain, of the type its sType names.
        let f = unsafe { &*found };
        if f.function == LOADER_DATA_CALLBACK && !f.u.is_null() {
            // SAFETY: with this function value the union holds `pfnSetDeviceLoaderData`.
            return Some(unsafe { std::mem::transmute::<*mut c_void, SetDeviceLoaderData>(f.u) });
        }
        next = f.p_next;
    }
    None
}

/// The queue families of `physical`, from the next layer's
/// `vkGetPhysicalDeviceQueueFamilyProperties`; `None` where it has none.
///
/// # Safety
/// `gipa` must be the next layer's `vkGetInstanceProcAddr` of the live `instance` of `physical`.
pub unsafe fn queue_families(
    instance: vk::Instance,
    gipa: vk::PFN_vkGetInstanceProcAddr,
    physical: vk::PhysicalDevice,
) -> Option<Vec<vk::QueueFamilyProperties>> {
    // SAFETY: as the caller promised; the command of the type its name implies.
    unsafe {
        let f = gipa(
            instance,
            c"vkGetPhysicalDeviceQueueFamilyProperties".as_ptr(),
        )?;
        let f = std::mem::transmute::<
            unsafe extern "system" fn(),
            vk::PFN_vkGetPhysicalDeviceQueueFamilyProperties,
        >(f);
        let mut n = 0;
        f(physical, &mut n, std::ptr::null_mut());
        let mut families = vec![vk::QueueFamilyProperties::default(); n as usize];
        f(physical, &mut n, families.as_mut_ptr());
        families.truncate(n as usize);
        Some(families)
    }
}

/// The graphics-family queues `ci` creates without flags (family, count): where passes, and so
/// the reads of the layer's shading-rate images, run.
///
/// # Safety
/// `ci` must be a valid device create info.
pub unsafe fn graphics_queues<'a>(
    ci: &'a vk::DeviceCreateInfo<'_>,
    families: &'a [vk::QueueFamilyProperties],
) -> impl Iterator<Item = (u32, u32)> + 'a {
    let infos = if ci.p_queue_create_infos.is_null() {
        &[][..]
    } else {
        // SAFETY: as the caller promised.
        unsafe {
            std::slice::from_raw_parts(ci.p_queue_create_infos, ci.queue_create_info_count as usize)
        }
    };
    infos
        .iter()
        .filter(|q| {
            q.flags.is_empty()
                && families
                    .get(q.queue_family_index as usize)
                    .is_some_and(|f| f.queue_flags.contains(vk::QueueFlags::GRAPHICS))
        })
        .map(|q| (q.queue_family_index, q.queue_count))
}

/// Pending clears and uploads in the whole process: what the submit hooks' fast path reads.
pub static PENDING: AtomicUsize = AtomicUsize::new(0);

/// How long `vkDestroyDevice` waits for a clear still in flight (the application must have waited
/// for its work, and the clear precedes it on the queue; this bounds a misbehaving one).
pub const DESTROY_WAIT_NS: u64 = 1_000_000_000;

/// A host-visible staging buffer, mapped for its lifetime.
pub struct Staging {
    pub buffer: vk::Buffer,
    pub memory: vk::DeviceMemory,
    pub ptr: *mut u8,
    pub size: u64,
}

/// One of the layer's submissions of clears and uploads, with everything it owns: made at the
/// first flush on its queue family that finds no idle one, and kept (its command buffer recorded
/// again, its fence reset, its staging written again, its lists cleared to their capacity) for
/// every later flush once its fence has signalled. A moving gaze refills a map every frame, so
/// this is what keeps the uploads from allocating per move.
pub struct Batch {
    pub family: u32,
    pub cb: vk::CommandBuffer,
    pub fence: vk::Fence,
    /// Grown (made again, larger) only when a flush needs more bytes than it holds.
    pub staging: Option<Staging>,
    /// The shadows it clears, with their layers.
    pub clears: Vec<(vk::Image, u32)>,
    /// The copies it makes: image, extent, layers, offset of their bytes in `staging`.
    pub copies: Vec<(vk::Image, [u32; 2], u32, u64)>,
    /// Shadows destroyed by the application while it was in flight, destroyed when `fence` has
    /// signalled.
    pub retired: Vec<(vk::Image, vk::DeviceMemory)>,
}

// SAFETY: `Staging::ptr` is the mapping of the batch's own memory, written only under the
// submit lock of its device's `Clears`.
unsafe impl Send for Batch {}

/// The newest bytes for a layer-owned shading-rate image: `layers` layers of `extent` texels, one
/// byte each, layer after layer; `dirty` until a flush copies them. One slot per image, kept
/// with its bytes' allocation while the image lives.
pub struct Upload {
    pub image: vk::Image,
    pub extent: [u32; 2],
    pub layers: u32,
    pub bytes: Vec<u8>,
    pub dirty: bool,
}

/// What recording threads hand to the next flush.
#[derive(Default)]
pub struct State {
    /// Shadows waiting for their clear, with their layers.
    pub pending: Vec<(vk::Image, u32)>,
    /// Each layer-owned image's newest bytes ([`Upload`]).
    pub uploads: Vec<Upload>,
}

impl State {
    /// Uploads waiting for a flush.
    pub fn dirty_uploads(&self) -> usize {
        self.uploads.iter().filter(|u| u.dirty).count()
    }
}

/// The layer's own submissions on a device.
#[derive(Default)]
pub struct Submits {
    /// A command pool per graphics family the layer submitted on, made at its first clear there.
    pub pools: Vec<(u32, vk::CommandPool)>,
    pub in_flight: Vec<Batch>,
    /// Batches whose fences have signalled, ready to be recorded again.
    pub idle: Vec<Batch>,
}

/// One device's shadow clears and map uploads.
pub struct Clears {
    /// The application's queues of graphics families (handle, family), from the device create info.
    pub queues: Vec<(u64, u32)>,
    /// What recording threads (a pass begin refilling a map, a shadow made) write: a leaf lock
    /// outside [`crate::common::lock::Rank`]'s order, held for a list update or a copy of a map's
    /// bytes, never across a call to the driver.
    pub state: parking_lot::Mutex<State>,
    /// The layer's submissions: taken by the submit hooks, the destruction of shadows and maps and
    /// `vkDestroyDevice`, never by a recording path, and held across the layer's own submit (so a
    /// shadow destroyed meanwhile is either still pending or in a batch in flight, never in
    /// between). Taken before [`Clears::state`] where both are, so a recording thread waits for
    /// no submit. A leaf like it otherwise.
    pub submits: parking_lot::Mutex<Submits>,
    /// The ordering of the layer's submissions against the application's other graphics queues,
    /// on a device with more than one ([`Order`]); `None` elsewhere.
    pub order: Option<Order>,
}

impl Clears {
    /// No clears yet, for a device whose graphics queues are `queues`.
    pub fn new(queues: Vec<(u64, u32)>) -> Clears {
        Clears {
            queues,
            state: parking_lot::Mutex::new(State::default()),
            submits: parking_lot::Mutex::new(Submits::default()),
            order: None,
        }
    }

    /// The family of `queue`, where it is one of the application's graphics queues.
    pub fn family_of(&self, queue: vk::Queue) -> Option<u32> {
        self.queues
            .iter()
            .find(|(q, _)| *q == queue.as_raw())
            .map(|&(_, f)| f)
    }

    /// Notes that the new shadow `image` of `layers` layers must be cleared before its first use.
    pub fn add(&self, image: vk::Image, layers: u32) {
        self.state.lock().pending.push((image, layers));
        PENDING.fetch_add(1, Ordering::Release);
    }

    /// Notes that `image` (of `layers` layers of `extent` texels) must hold `bytes` before its next
    /// use; replaces bytes of the same image not yet copied, which are out of date. The bytes go
    /// into the image's slot: no allocation once it has held as many.
    pub fn upload(&self, image: vk::Image, extent: [u32; 2], layers: u32, bytes: &[u8]) {
        let mut st = self.state.lock();
        let at = match st.uploads.iter().position(|u| u.image == image) {
            Some(i) => i,
            None => {
                st.uploads.push(Upload {
                    image,
                    extent,
                    layers,
                    bytes: Vec::new(),
                    dirty: false,
                });
                st.uploads.len() - 1
            }
        };
        let u = &mut st.uploads[at];
        u.extent = extent;
        u.layers = layers;
        u.bytes.clear();
        u.bytes.extend_from_slice(bytes);
        if !u.dirty {
            u.dirty = true;
            PENDING.fetch_add(1, Ordering::Release);
        }
    }

    /// Drops the upload slot of `image`, which is about to be destroyed; waits for everything in
    /// flight, which may copy into it.
    ///
    /// # Safety
    /// `d` must be the live device of these uploads.
    pub unsafe fn forget_upload(&self, d: &ash::Device, image: vk::Image) {
        let mut sub = self.submits.lock();
        {
            let mut st = self.state.lock();
            if let Some(i) = st.uploads.iter().position(|u| u.image == image) {
                if st.uploads.swap_remove(i).dirty {
                    PENDING.fetch_sub(1, Ordering::Release);
                }
            }
        }
        // SAFETY: the layer's own objects on a live device.
        unsafe { reclaim(d, &mut sub, true) };
    }

    /// Destroys a shadow whose application image is being destroyed: at once where its clear is
    /// pending (dropped) or done, once its clear's fence has signalled where it is in flight.
    ///
    /// # Safety
    /// `s` must be a live shadow of `d`'s device that nothing of the application's uses any more.
    pub unsafe fn forget(&self, d: &ash::Device, s: &ShadowImage) {
        let mut sub = self.submits.lock();
        // SAFETY: the layer's own objects on a live device.
        unsafe { reclaim(d, &mut sub, false) };
        {
            let mut st = self.state.lock();
            if let Some(i) = st.pending.iter().position(|(i, _)| *i == s.image) {
                st.pending.swap_remove(i);
                PENDING.fetch_sub(1, Ordering::Release);
            } else if let Some(b) = sub
                .in_flight
                .iter_mut()
                .find(|b| b.clears.iter().any(|(i, _)| *i == s.image))
            {
                b.retired.push((s.image, s.memory));
                return;
            }
        }
        drop(sub);
        // SAFETY: as the caller promised; no clear of it is pending or in flight.
        unsafe {
            d.destroy_image(s.image, None);
            d.free_memory(s.memory, None);
        }
    }

    /// Submits the pending clears and uploads on `queue` ahead of the application's submission,
    /// where it is a graphics queue of the application's. In steady state (a batch of this family
    /// idle, its staging large enough) nothing is allocated: the batch is recorded again.
    ///
    /// # Safety
    /// Called inside the application's submit on `queue`, of `own`'s live device.
    pub unsafe fn flush(&self, own: &Own, queue: vk::Queue) -> Result<(), vk::Result> {
        let Some(family) = self.family_of(queue) else {
            return Ok(());
        };
        let d = &own.fns;
        let mut sub = self.submits.lock();
        // SAFETY: the layer's own objects on a live device.
        unsafe { reclaim(d, &mut sub, false) };
        {
            let st = self.state.lock();
            if st.pending.is_empty() && !st.uploads.iter().any(|u| u.dirty) {
                return Ok(());
            }
        }
        let mut batch = match sub.idle.iter().position(|b| b.family == family) {
            Some(i) => sub.idle.swap_remove(i),
            // SAFETY: a live device; the new objects are the layer's own.
            None => unsafe { new_batch(own, &mut sub, family) }?,
        };
        // Take what is pending, under the recording threads' lock for the copies only.
        let taken = {
            let mut st = self.state.lock();
            let size: u64 = st
                .uploads
                .iter()
                .filter(|u| u.dirty)
                .map(|u| u.bytes.len() as u64)
                .sum();
            // SAFETY: the batch's own staging on a live device, not in flight (the batch is idle).
            match unsafe { ensure_staging(own, &mut batch, size) } {
                Ok(()) => {
                    batch.clears.append(&mut st.pending);
                    let mut at = 0u64;
                    let mut n = 0;
                    for u in st.uploads.iter_mut().filter(|u| u.dirty) {
                        if let Some(s) = &batch.staging {
                            // SAFETY: `at + len` ≤ `size` ≤ the mapping's size.
                            unsafe {
                                std::ptr::copy_nonoverlapping(
                                    u.bytes.as_ptr(),
                                    s.ptr.add(at as usize),
                                    u.bytes.len(),
                                );
                            }
                        }
                        batch.copies.push((u.image, u.extent, u.layers, at));
                        at += u.bytes.len() as u64;
                        u.dirty = false;
                        n += 1;
                    }
                    PENDING.fetch_sub(batch.clears.len() + n, Ordering::Release);
                    Ok(())
                }
                Err(e) => Err(e),
            }
        };
        let order = self.order.as_ref();
        let submitted = taken.and_then(|()| {
            // SAFETY: the batch's own command buffer and fence; the images are live (a pending
            // shadow is removed from its list before it is destroyed, and maps wait for their
            // batches at destruction).
            unsafe { record_and_submit(own, &batch, queue, order) }
        });
        if let Err(e) = submitted {
            // What it would have done stays pending: the application's work would read shadows in
            // an undefined layout otherwise.
            let mut st = self.state.lock();
            let n = batch.clears.len();
            st.pending.append(&mut batch.clears);
            let mut again = 0;
            for (image, ..) in batch.copies.drain(..) {
                if let Some(u) = st.uploads.iter_mut().find(|u| u.image == image && !u.dirty) {
                    u.dirty = true;
                    again += 1;
                }
            }
            PENDING.fetch_add(n + again, Ordering::Release);
            drop(st);
            // A failed submit may leave the command buffer and fence counted as in use (the
            // validation layer does): drain the queue, which the layer may use here, inside the
            // application's submit, before they are recorded again
            // (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkFreeCommandBuffers.html>).
            // SAFETY: as the caller promised.
            let _ = unsafe { d.queue_wait_idle(queue) };
            // SAFETY: the batch's own fence, not pending after the wait.
            let _ = unsafe { d.reset_fences(&[batch.fence]) };
            sub.idle.push(batch);
            return Err(e);
        }
        tracing::debug!(
            queue = raw(queue),
            shadows = batch.clears.len(),
            uploads = batch.copies.len(),
            "shadow clears and shading-rate uploads submitted ahead of the application's submit"
        );
        sub.in_flight.push(batch);
        Ok(())
    }

    /// Frees everything at `vkDestroyDevice`.
    ///
    /// # Safety
    /// The device must be live and about to be destroyed, the application done with it.
    pub unsafe fn destroy(&self, d: &ash::Device) {
        let mut sub = self.submits.lock();
        {
            let mut st = self.state.lock();
            let dirty = st.dirty_uploads();
            PENDING.fetch_sub(st.pending.len() + dirty, Ordering::Release);
            st.pending.clear();
            st.uploads.clear();
        }
        // SAFETY: the layer's own objects; the application's work (after the clears on each
        // queue) is done.
        unsafe {
            reclaim(d, &mut sub, true);
            for b in sub.idle.drain(..) {
                d.destroy_fence(b.fence, None);
                if let Some(s) = b.staging {
                    destroy_staging(d, s);
                }
            }
            for (_, p) in sub.pools.drain(..) {
                d.destroy_command_pool(p, None);
            }
            if let Some(o) = &self.order {
                o.destroy(d);
            }
        }
    }
}

/// A new batch on `family`: its command buffer (from the family's pool, made here the first
/// time) and fence; its staging comes with its first upload.
///
/// # Safety
/// `own` must belong to a live device; `sub` is its.
unsafe fn new_batch(own: &Own, sub: &mut Submits, family: u32) -> Result<Batch, vk::Result> {
    let d = &own.fns;
    let pool = match sub.pools.iter().find(|(f, _)| *f == family) {
        Some(&(_, p)) => p,
        None => {
            // SAFETY: a pool of the layer's own on a live device; its command buffers are
            // recorded again, so each may be reset alone.
            let p = unsafe {
                d.create_command_pool(
                    &vk::CommandPoolCreateInfo::default()
                        .queue_family_index(family)
                        .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER),
                    None,
                )
            }?;
            sub.pools.push((family, p));
            p
        }
    };
    // SAFETY: a command buffer and fence of the layer's own, freed again on failure.
    unsafe {
        let cb = d.allocate_command_buffers(
            &vk::CommandBufferAllocateInfo::default()
                .command_pool(pool)
                .level(vk::CommandBufferLevel::PRIMARY)
                .command_buffer_count(1),
        )?[0];
        let made = own
            .set_loader_data(cb)
            .and_then(|()| d.create_fence(&vk::FenceCreateInfo::default(), None));
        match made {
            Ok(fence) => Ok(Batch {
                family,
                cb,
                fence,
                staging: None,
                clears: Vec::new(),
                copies: Vec::new(),
                retired: Vec::new(),
            }),
            Err(e) => {
                d.free_command_buffers(pool, &[cb]);
                Err(e)
            }
        }
    }
}

/// Makes `batch`'s staging hold at least `size` bytes: kept where it does, else made again
/// (twice the size, so that a growing map does not make it again at every move).
///
/// # Safety
/// `own` must belong to a live device; `batch` is idle.
unsafe fn ensure_staging(own: &Own, batch: &mut Batch, size: u64) -> Result<(), vk::Result> {
    if size == 0 || batch.staging.as_ref().is_some_and(|s| s.size >= size) {
        return Ok(());
    }
    let want = size.max(batch.staging.as_ref().map_or(0, |s| s.size * 2));
    if let Some(s) = batch.staging.take() {
        // SAFETY: the batch is idle: nothing reads its staging.
        unsafe { destroy_staging(&own.fns, s) };
    }
    // SAFETY: as the caller promised.
    batch.staging = Some(unsafe { make_staging(own, want) }?);
    Ok(())
}

/// Records `batch` (its clears, then its copies from its staging) into its command buffer and
/// submits it on `queue` with its fence; with `order`, after every other graphics queue's
/// submitted work, and before every later submission there ([`Order::upload`]).
///
/// # Safety
/// `batch` idle, its images live; inside the application's submit on `queue`.
unsafe fn record_and_submit(
    own: &Own,
    batch: &Batch,
    queue: vk::Queue,
    order: Option<&Order>,
) -> Result<(), vk::Result> {
    let d = &own.fns;
    // SAFETY: as the caller promised; beginning the command buffer resets it (its pool allows).
    unsafe {
        d.begin_command_buffer(
            batch.cb,
            &vk::CommandBufferBeginInfo::default()
                .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
        )?;
        for &(image, layers) in &batch.clears {
            // New shadows have no earlier use to wait for.
            write_shading_rate_image(
                d,
                batch.cb,
                vk::PipelineStageFlags::TOP_OF_PIPE,
                image,
                layers,
                || {
                    d.cmd_clear_color_image(
                        batch.cb,
                        image,
                        vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                        &vk::ClearColorValue { uint32: [0; 4] },
                        &[color_range(layers)],
                    );
                },
            );
        }
        if let Some(s) = &batch.staging {
            for &(image, extent, layers, at) in &batch.copies {
                // ALL_COMMANDS first: passes submitted earlier on this queue may still read the
                // old map (a write-after-read hazard needs only this execution dependency).
                write_shading_rate_image(
                    d,
                    batch.cb,
                    vk::PipelineStageFlags::ALL_COMMANDS,
                    image,
                    layers,
                    || {
                        let layer_bytes = u64::from(extent[0]) * u64::from(extent[1]);
                        for l in 0..layers {
                            d.cmd_copy_buffer_to_image(
                                batch.cb,
                                s.buffer,
                                image,
                                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                                &[vk::BufferImageCopy {
                                    buffer_offset: at + u64::from(l) * layer_bytes,
                                    buffer_row_length: 0,
                                    buffer_image_height: 0,
                                    image_subresource: vk::ImageSubresourceLayers {
                                        aspect_mask: vk::ImageAspectFlags::COLOR,
                                        mip_level: 0,
                                        base_array_layer: l,
                                        layer_count: 1,
                                    },
                                    image_offset: vk::Offset3D::default(),
                                    image_extent: vk::Extent3D {
                                        width: extent[0],
                                        height: extent[1],
                                        depth: 1,
                                    },
                                }],
                            );
                        }
                    },
                );
            }
        }
        d.end_command_buffer(batch.cb)?;
        let cbs = [batch.cb];
        let Some(order) = order else {
            return d.queue_submit(
                queue,
                &[vk::SubmitInfo::default().command_buffers(&cbs)],
                batch.fence,
            );
        };
        order.upload(queue, |w, value| {
            let signal = [order.upload];
            let values = [value];
            let mut timeline = vk::TimelineSemaphoreSubmitInfo::default()
                .wait_semaphore_values(&w.values)
                .signal_semaphore_values(&values);
            d.queue_submit(
                queue,
                &[vk::SubmitInfo::default()
                    .wait_semaphores(&w.semaphores)
                    .wait_dst_stage_mask(&w.stages)
                    .command_buffers(&cbs)
                    .signal_semaphores(&signal)
                    .push_next(&mut timeline)],
                batch.fence,
            )
        })
    }
}

/// Makes the batches whose fences have signalled (all of them, after waiting, with `all`) idle
/// again, destroying the shadows retired meanwhile.
///
/// # Safety
/// The objects in `sub` must belong to `d`'s live device.
pub unsafe fn reclaim(d: &ash::Device, sub: &mut Submits, all: bool) {
    if sub.in_flight.is_empty() {
        return;
    }
    if all {
        let fences: Vec<vk::Fence> = sub.in_flight.iter().map(|b| b.fence).collect();
        // SAFETY: the layer's own fences.
        if let Err(e) = unsafe { d.wait_for_fences(&fences, true, DESTROY_WAIT_NS) } {
            tracing::warn!(result = ?e, "shadow clears still in flight at vkDestroyDevice");
        }
    }
    let mut i = 0;
    while i < sub.in_flight.len() {
        let fence = sub.in_flight[i].fence;
        // SAFETY: the layer's own fence.
        let status = (!all).then(|| unsafe { d.get_fence_status(fence) });
        let done = matches!(
            status,
            None | Some(Ok(true)) | Some(Err(vk::Result::ERROR_DEVICE_LOST))
        );
        if !done {
            i += 1;
            continue;
        }
        let mut b = sub.in_flight.swap_remove(i);
        // SAFETY: the batch has completed; these are the layer's own objects.
        unsafe {
            let _ = d.reset_fences(&[b.fence]);
            for (image, memory) in b.retired.drain(..) {
                d.destroy_image(image, None);
                d.free_memory(memory, None);
            }
        }
        b.clears.clear();
        b.copies.clear();
        sub.idle.push(b);
    }
}

/// A mapped host-visible, host-coherent staging buffer of `size` bytes.
///
/// # Safety
/// `own` must belong to a live device.
unsafe fn make_staging(own: &Own, size: u64) -> Result<Staging, vk::Result> {
    let d = &own.fns;
    // SAFETY: the layer's own buffer and memory on a live device, each freed again on failure.
    unsafe {
        let buffer = d.create_buffer(
            &vk::BufferCreateInfo::default()
                .size(size)
                .usage(vk::BufferUsageFlags::TRANSFER_SRC)
                .sharing_mode(vk::SharingMode::EXCLUSIVE),
            None,
        )?;
        let req = d.get_buffer_memory_requirements(buffer);
        let memory = own.bound_memory(
            req,
            Own::host_memory_type,
            vk::Result::ERROR_OUT_OF_DEVICE_MEMORY,
            |m| d.bind_buffer_memory(buffer, m, 0),
        );
        let memory = match memory {
            Ok(m) => m,
            Err(e) => {
                d.destroy_buffer(buffer, None);
                return Err(e);
            }
        };
        // Host-coherent memory ([`Own::host_memory_type`]): no flush needed, and the submit makes
        // the host's writes visible to the device.
        match d.map_memory(memory, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty()) {
            Ok(p) => Ok(Staging {
                buffer,
                memory,
                ptr: p as *mut u8,
                size,
            }),
            Err(e) => {
                d.destroy_buffer(buffer, None);
                d.free_memory(memory, None);
                Err(e)
            }
        }
    }
}

/// Destroys a staging buffer and its memory (unmapped with it).
///
/// # Safety
/// Nothing may use it any more.
unsafe fn destroy_staging(d: &ash::Device, s: Staging) {
    // SAFETY: as the caller promised.
    unsafe {
        d.destroy_buffer(s.buffer, None);
        d.free_memory(s.memory, None);
    }
}

/// All `layers` of a colour image's one mip level.
pub fn color_range(layers: u32) -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange {
        aspect_mask: vk::ImageAspectFlags::COLOR,
        base_mip_level: 0,
        level_count: 1,
        base_array_layer: 0,
        layer_count: layers,
    }
}

/// Records `write` (transfer writes covering `layers` layers of `image`) between a barrier that
/// takes the image from `UNDEFINED` to `TRANSFER_DST_OPTIMAL` after the `after` stage of earlier
/// work, and one that moves it to [`SHADOW_LAYOUT`] for every later command. ALL_COMMANDS stands
/// for the shading-rate stage: some validation-layer releases take that stage's bit for NVIDIA's
/// shading-rate-image stage, which shares it, and refuse it without that feature. One image at a
/// time: no list to allocate.
///
/// # Safety
/// `cb` must be recording on `d`; the image live; `write` records only transfer writes to it.
pub unsafe fn write_shading_rate_image(
    d: &ash::Device,
    cb: vk::CommandBuffer,
    after: vk::PipelineStageFlags,
    image: vk::Image,
    layers: u32,
    write: impl FnOnce(),
) {
    let to_dst = vk::ImageMemoryBarrier::default()
        .image(image)
        .subresource_range(color_range(layers))
        .old_layout(vk::ImageLayout::UNDEFINED)
        .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
        .dst_access_mask(vk::AccessFlags::TRANSFER_WRITE)
        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED);
    let to_rate = to_dst
        .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
        .new_layout(SHADOW_LAYOUT)
        .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
        .dst_access_mask(vk::AccessFlags::MEMORY_READ);
    // SAFETY: as the caller promised.
    unsafe {
        d.cmd_pipeline_barrier(
            cb,
            after,
            vk::PipelineStageFlags::TRANSFER,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[to_dst],
        );
        write();
        d.cmd_pipeline_barrier(
            cb,
            vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::ALL_COMMANDS,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[to_rate],
        );
    }
}

/// Creates and binds one shadow of `extent` for an image of `app_layers` layers; with `clear`, its
/// clear to rate code 0 is left pending for the next submit.
///
/// # Safety
/// `own` must belong to a live device.
pub unsafe fn make_shadow(
    own: &Own,
    fdm: &FdmEmulation,
    extent: vk::Extent3D,
    app_layers: u32,
    clear: bool,
) -> Result<ShadowImage, vk::Result> {
    let layers = shadow_layers(fdm, app_layers);
    // SAFETY: as the caller promised.
    let (image, memory) = unsafe { own.shading_rate_image([extent.width, extent.height], layers) }?;
    if clear {
        own.clears.add(image, layers);
    }
    Ok(ShadowImage {
        image,
        memory,
        extent: vk::Extent2D {
            width: extent.width,
            height: extent.height,
        },
        layers,
        app_layers,
    })
}
