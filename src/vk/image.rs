//! Shadows: the layer-owned shading-rate images and views that stand in for an application's
//! density-map images and views on an emulating device.
//!
//! A density map is `R8G8_UNORM` with the `FRAGMENT_DENSITY_MAP` usage; a shading-rate attachment
//! is an integer image (`R8_UINT`) with the `FRAGMENT_SHADING_RATE_ATTACHMENT` usage
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkFragmentShadingRateAttachmentInfoKHR.html>,
//! docs/vulkan-fdm-on-fsr.md#mapping, #shadows). The application keeps its own image, which the driver gets
//! without the density usage ([`crate::vk::device::create_image`]); beside it the layer makes a
//! shadow of the same extent, 2D, one sample, optimal tiling, in device-local memory it owns, and
//! destroys it with the image. Render passes, framebuffers and dynamic rendering name the shadow
//! ([`crate::vk::pass`]); the bridge ([`crate::bridge::shadow_of`]) tells fovea's own density
//! images where to upload their rates.
//!
//! Layers: one per application layer where the driver has `layeredShadingRateAttachments`;
//! otherwise one, which both eyes share, so whoever fills it writes per texel the finer rate of all
//! the application's layers (docs/vulkan-fdm-on-fsr.md#multiview).
//!
//! Content: rate code 0 (1×1, full rate) before first use, so a density map nobody converts renders
//! correctly, at full rate; the shadow then lives in `FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR`.
//! The clear never takes a queue on its own: it waits, pending, for the application's next submit
//! on one of its graphics queues and runs in front of it ([`crate::vk::submit`]), since Vulkan makes
//! queue use externally synchronised by the application
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkQueueSubmit.html>). Command
//! buffers the layer allocates get the loader's dispatch pointer through `vkSetDeviceLoaderData`
//! (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>,
//! "Creating New Dispatchable Objects").
//!
//! Fail open: where a shadow cannot be made, the image (or view) is the application's alone, the
//! passes that would have used it run at full rate (a framebuffer gets a full-rate stand-in,
//! [`Own::full_rate_view`]), and one log line says so.

use std::ffi::c_void;

use ash::vk;
use ash::vk::Handle as _;

use crate::bridge::{self, FdmEmulation, Shadow};
use std::sync::Arc;

use crate::common::lock::{Mutex, Rank};
use crate::vk::base::chain;
use crate::vk::base::ffi::{guard, key, raw, Key};
use crate::vk::base::link::LayerDeviceCreateInfo;
use crate::vk::pipeline;
use crate::vk::registry::{self, Device, Instance, ShadowImage, ShadowView};
use crate::vk::submit::Clears;

/// `PFN_vkSetDeviceLoaderData`.
type SetDeviceLoaderData = unsafe extern "system" fn(vk::Device, *mut c_void) -> vk::Result;

/// `VK_LOADER_DATA_CALLBACK`: the `VkLayerDeviceCreateInfo` that carries `pfnSetDeviceLoaderData`.
const LOADER_DATA_CALLBACK: u32 = 1;

/// The usage every shadow has.
pub const SHADOW_USAGE: vk::ImageUsageFlags = vk::ImageUsageFlags::from_raw(
    vk::ImageUsageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR.as_raw()
        | vk::ImageUsageFlags::TRANSFER_DST.as_raw(),
);
/// The format every shadow has.
pub const SHADOW_FORMAT: vk::Format = vk::Format::R8_UINT;
/// The layout a shadow lives in between uses.
pub const SHADOW_LAYOUT: vk::ImageLayout =
    vk::ImageLayout::FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR;

/// What the layer needs to make, clear and destroy shadows on one device.
pub struct Own {
    /// The next layer's device commands.
    pub fns: ash::Device,
    memory: vk::PhysicalDeviceMemoryProperties,
    set_loader_data: SetDeviceLoaderData,
    /// The shadows' clears, run ahead of the application's submits ([`crate::vk::submit`]).
    pub clears: Clears,
    /// Full-rate stand-ins for density views without a shadow ([`Own::full_rate_view`]): one
    /// layer each, kept until the device is destroyed.
    fallbacks: Mutex<Vec<(ShadowImage, vk::ImageView)>>,
}

impl Own {
    /// Sets up the layer's own calls on a device just created.
    ///
    /// # Safety
    /// `ci` must be the application's valid create info of `device`, made on `physical` of `inst`;
    /// `gdpa` the next layer's `vkGetDeviceProcAddr`.
    pub unsafe fn new(
        inst: &Instance,
        physical: vk::PhysicalDevice,
        ci: &vk::DeviceCreateInfo<'_>,
        device: vk::Device,
        gdpa: vk::PFN_vkGetDeviceProcAddr,
    ) -> Result<Own, String> {
        // SAFETY: a valid chain, as the caller promised.
        let set_loader_data = unsafe { loader_data_callback(ci) }
            .ok_or("the loader passed no vkSetDeviceLoaderData")?;
        // SAFETY: the next layer's instance commands, of the types their names imply.
        let (families, memory) = unsafe {
            let gipa = inst.gipa;
            let f = gipa(
                inst.handle,
                c"vkGetPhysicalDeviceQueueFamilyProperties".as_ptr(),
            )
            .ok_or("no vkGetPhysicalDeviceQueueFamilyProperties")?;
            let f = std::mem::transmute::<
                unsafe extern "system" fn(),
                vk::PFN_vkGetPhysicalDeviceQueueFamilyProperties,
            >(f);
            let mut n = 0;
            f(physical, &mut n, std::ptr::null_mut());
            let mut families = vec![vk::QueueFamilyProperties::default(); n as usize];
            f(physical, &mut n, families.as_mut_ptr());
            families.truncate(n as usize);
            let m = gipa(inst.handle, c"vkGetPhysicalDeviceMemoryProperties".as_ptr())
                .ok_or("no vkGetPhysicalDeviceMemoryProperties")?;
            let m = std::mem::transmute::<
                unsafe extern "system" fn(),
                vk::PFN_vkGetPhysicalDeviceMemoryProperties,
            >(m);
            let mut memory = vk::PhysicalDeviceMemoryProperties::default();
            m(physical, &mut memory);
            (families, memory)
        };
        let infos = if ci.p_queue_create_infos.is_null() {
            &[][..]
        } else {
            // SAFETY: as the caller promised.
            unsafe {
                std::slice::from_raw_parts(
                    ci.p_queue_create_infos,
                    ci.queue_create_info_count as usize,
                )
            }
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
        for q in infos.iter().filter(|q| {
            q.flags.is_empty()
                && families
                    .get(q.queue_family_index as usize)
                    .is_some_and(|f| f.queue_flags.contains(vk::QueueFlags::GRAPHICS))
        }) {
            for i in 0..q.queue_count {
                // SAFETY: a queue the application created; only its handle is kept.
                let queue = unsafe { fns.get_device_queue(q.queue_family_index, i) };
                queues.push((queue.as_raw(), q.queue_family_index));
            }
        }
        if queues.is_empty() {
            return Err("the device has no graphics queue the layer could clear shadows on".into());
        }
        Ok(Own {
            fns,
            memory,
            set_loader_data,
            clears: Clears::new(queues),
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
            let Some(ty) = self.memory_type(req.memory_type_bits) else {
                d.destroy_image(image, None);
                return Err(vk::Result::ERROR_OUT_OF_DEVICE_MEMORY);
            };
            let memory = match d.allocate_memory(
                &vk::MemoryAllocateInfo::default()
                    .allocation_size(req.size)
                    .memory_type_index(ty),
                None,
            ) {
                Ok(m) => m,
                Err(e) => {
                    d.destroy_image(image, None);
                    return Err(e);
                }
            };
            if let Err(e) = d.bind_image_memory(image, memory, 0) {
                d.destroy_image(image, None);
                d.free_memory(memory, None);
                return Err(e);
            }
            Ok((image, memory))
        }
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
unsafe fn loader_data_callback(ci: &vk::DeviceCreateInfo<'_>) -> Option<SetDeviceLoaderData> {
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

/// Each emulating device's [`Own`] by the loader's dispatch key, for the submit hooks. A leaf lock
/// outside [`crate::common::lock::Rank`]'s order, like the recording table
/// ([`registry::recording`]): held for a scan and an `Arc` clone only, so it may be taken under
/// fovea's own upload locks, whose submits pass through the layer.
static OWNS: parking_lot::RwLock<Vec<(Key, Arc<Own>)>> = parking_lot::RwLock::new(Vec::new());

/// Records (or, with `None`, forgets) the device `k`'s own calls.
pub fn set_own(k: Key, own: Option<Arc<Own>>) {
    let mut v = OWNS.write();
    v.retain(|(key, _)| *key != k);
    if let Some(o) = own {
        v.push((k, o));
    }
}

/// The own calls of a queue's (or any dispatchable handle's) device.
///
/// # Safety
/// `handle` must be NULL or a live dispatchable handle made by the loader.
pub unsafe fn own_of(handle: impl vk::Handle) -> Option<Arc<Own>> {
    // SAFETY: as the caller promised.
    let k = unsafe { key(handle) }?;
    OWNS.read()
        .iter()
        .find(|(key, _)| *key == k)
        .map(|(_, o)| Arc::clone(o))
}

/// How many layers a shadow of an image with `app_layers` layers has on `fdm`'s device.
pub fn shadow_layers(fdm: &FdmEmulation, app_layers: u32) -> u32 {
    if fdm.layered {
        app_layers.max(1)
    } else {
        1
    }
}

/// Makes the shadow of a density-map image the application just created (`ci` as the
/// application gave it), or logs why not.
///
/// Fail open: a shadow that cannot be made (the driver is out of memory) leaves the application's
/// image as the driver made it, without a shadow; its views get none either, dynamic rendering with
/// it goes down without a shading-rate attachment, and a framebuffer with it gets the device's
/// full-rate stand-in ([`Own::full_rate_view`]), so its passes render at full rate. One log line
/// says why. The shadow's clear is left pending for the application's next submit
/// ([`crate::vk::submit`]), except for fovea's own density images, whose uploads write the whole
/// shadow before first use.
///
/// # Safety
/// `app` must be the live image just created on `dev` from `ci`.
pub unsafe fn image_created(dev: &Device, app: vk::Image, ci: &vk::ImageCreateInfo<'_>) {
    let (Some(fdm), Some(own)) = (&dev.fdm, &dev.attachments.own) else {
        if dev.fdm.is_some() {
            tracing::warn!(
                image = raw(app),
                "no shadow for a density map: the layer could not set up its own calls on this \
                 device; passes with it render at full rate"
            );
        }
        return;
    };
    let own_image = bridge::creating_own_density_images();
    // SAFETY: as the caller promised.
    match unsafe { make_shadow(own, fdm, ci.extent, ci.array_layers, !own_image) } {
        Ok(s) => {
            dev.attachments.images.lock().insert(app.as_raw(), s);
            bridge::set_shadow(
                app,
                Some(Shadow {
                    device: dev.handle,
                    image: s.image,
                    layers: s.layers,
                    app_layers: s.app_layers,
                    extent: [s.extent.width, s.extent.height],
                }),
            );
            tracing::debug!(
                image = raw(app),
                shadow = raw(s.image),
                layers = s.layers,
                "density map shadowed"
            );
            // fovea's own density images get their rates with every upload
            // (`gpu::density_images`); an application's own maps are converted at every pass
            // begin that reads them ([`crate::vk::convert`]).
            let logged = &dev.attachments.app_maps_logged;
            if !own_image {
                // SAFETY: as the caller promised.
                unsafe { crate::vk::convert::map_created(dev, app, &s) };
                if !logged.swap(true, std::sync::atomic::Ordering::Relaxed) {
                    tracing::info!(
                        image = raw(app),
                        "this application creates and writes density maps itself: they are \
                         converted into shading rates on the GPU at every pass begin that reads \
                         them (fovea's own density maps carry their rates)"
                    );
                }
            }
        }
        Err(e) => tracing::warn!(
            image = raw(app),
            result = ?e,
            "no shadow for a density map: the image is the application's alone, and passes with \
             it render at full rate"
        ),
    }
}

/// Creates and binds one shadow of `extent` for an image of `app_layers` layers; with `clear`, its
/// clear to rate code 0 is left pending for the next submit.
///
/// # Safety
/// `own` must belong to a live device.
unsafe fn make_shadow(
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

/// The shadow view's create info for an application view `ci` of an image shadowed by `s`: the
/// application's layers where the shadow has them, else its one merged layer; 2D or 2D-array, as
/// shading-rate views must be, identity swizzle.
pub fn shadow_view_info(
    s: &ShadowImage,
    ci: &vk::ImageViewCreateInfo<'_>,
) -> vk::ImageViewCreateInfo<'static> {
    let r = ci.subresource_range;
    let (base, count) = if s.layers == 1 {
        (0, 1)
    } else {
        let count = if r.layer_count == vk::REMAINING_ARRAY_LAYERS {
            s.layers.saturating_sub(r.base_array_layer)
        } else {
            r.layer_count
        };
        (r.base_array_layer, count)
    };
    let view_type = if ci.view_type == vk::ImageViewType::TYPE_2D_ARRAY || count > 1 {
        vk::ImageViewType::TYPE_2D_ARRAY
    } else {
        vk::ImageViewType::TYPE_2D
    };
    vk::ImageViewCreateInfo::default()
        .image(s.image)
        .view_type(view_type)
        .format(SHADOW_FORMAT)
        .components(vk::ComponentMapping::default())
        .subresource_range(vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: base,
            layer_count: count,
        })
}

/// `vkCreateImageView`: a view of a shadowed image gets a shadow view beside it; on an injecting
/// device a view of a colour image is noted for finding eye passes ([`crate::vk::inject`]).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn create_image_view(
    device: vk::Device,
    info: *const vk::ImageViewCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::ImageView,
) -> vk::Result {
    guard(
        "vkCreateImageView",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let Some(dev) = (unsafe { registry::device(device) }) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let Some(next) = dev.next.create_image_view else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            // Dynamic and deferred density-map views cannot be emulated: those flags are left out
            // of a copy ([`pipeline::view_flags`]).
            let copy = (!info.is_null())
                // SAFETY: the caller's create info, read only.
                .then(|| unsafe { *info })
                .and_then(|c| {
                    Some(vk::ImageViewCreateInfo {
                        flags: pipeline::view_flags(c.flags)?,
                        ..c
                    })
                });
            let down = copy.as_ref().map_or(info, |c| c as *const _);
            // SAFETY: the next layer's function, with the caller's arguments (or a copy of its
            // create info).
            let r = unsafe { next(device, down, alloc, out) };
            if r != vk::Result::SUCCESS || info.is_null() || out.is_null() {
                return r;
            }
            // SAFETY: the caller's create info, read only.
            let ci = unsafe { &*info };
            if let Some(inj) = &dev.inject {
                // SAFETY: the view was just created.
                inj.view_created(unsafe { *out }, ci);
                return r;
            }
            let shadow = dev
                .attachments
                .images
                .lock()
                .get(&ci.image.as_raw())
                .copied();
            let (Some(s), Some(own)) = (shadow, &dev.attachments.own) else {
                return r;
            };
            // SAFETY: the view was just created.
            let app_view = unsafe { *out };
            // SAFETY: the layer's own view of its own live image.
            match unsafe { own.fns.create_image_view(&shadow_view_info(&s, ci), None) } {
                Ok(view) => {
                    dev.attachments
                        .views
                        .lock()
                        .insert(app_view.as_raw(), ShadowView { view });
                    // SAFETY: the device is live.
                    unsafe { crate::vk::convert::view_changed(&dev, app_view, Some(ci.image)) };
                }
                // Fail open, as for the shadow image ([`image_created`]): the view is the
                // application's alone, and framebuffers with it get the full-rate stand-in.
                Err(e) => tracing::warn!(
                    view = raw(app_view),
                    result = ?e,
                    "no shadow view for a density-map view: passes with it render at full rate"
                ),
            }
            r
        },
    )
}

/// `vkDestroyImageView`: the shadow view goes with the application's.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn destroy_image_view(
    device: vk::Device,
    view: vk::ImageView,
    alloc: *const vk::AllocationCallbacks<'_>,
) {
    guard("vkDestroyImageView", (), || {
        // SAFETY: as the caller promised.
        let Some(dev) = (unsafe { registry::device(device) }) else {
            return;
        };
        if let Some(next) = dev.next.destroy_image_view {
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { next(device, view, alloc) };
        }
        if let Some(inj) = &dev.inject {
            inj.view_destroyed(view);
        }
        let shadow = dev.attachments.views.lock().remove(&view.as_raw());
        // SAFETY: the device is live.
        unsafe { crate::vk::convert::view_changed(&dev, view, None) };
        if let (Some(s), Some(own)) = (shadow, &dev.attachments.own) {
            // SAFETY: the layer's own view; the application's use of it ended with its view's.
            unsafe { own.fns.destroy_image_view(s.view, None) };
        }
    })
}

/// `vkDestroyImage`: the shadow and its memory go with the application's image.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn destroy_image(
    device: vk::Device,
    image: vk::Image,
    alloc: *const vk::AllocationCallbacks<'_>,
) {
    guard("vkDestroyImage", (), || {
        // SAFETY: as the caller promised.
        let Some(dev) = (unsafe { registry::device(device) }) else {
            return;
        };
        // The layer's view of the image goes first.
        // SAFETY: the device is live; the application's uses of the image have ended.
        unsafe { crate::vk::convert::map_destroyed(&dev, image) };
        if let Some(next) = dev.next.destroy_image {
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { next(device, image, alloc) };
        }
        if let Some(inj) = &dev.inject {
            inj.image_destroyed(image);
        }
        let shadow = dev.attachments.images.lock().remove(&image.as_raw());
        if let Some(s) = shadow {
            bridge::set_shadow(image, None);
            if let Some(own) = &dev.attachments.own {
                // SAFETY: the layer's own image and memory, no longer used by the application
                // (its image, which every use of the shadow stood in for, is being destroyed);
                // a pending clear is dropped, one in flight is waited for.
                unsafe { own.clears.forget(&own.fns, &s) };
            }
        }
    })
}

/// Destroys every shadow left on a device about to be destroyed.
///
/// # Safety
/// `dev` must be live, with nothing in flight.
pub unsafe fn destroy_all(dev: &Device) {
    let Some(own) = &dev.attachments.own else {
        return;
    };
    let views: Vec<ShadowView> = dev
        .attachments
        .views
        .lock()
        .drain()
        .map(|(_, v)| v)
        .collect();
    let images: Vec<(u64, ShadowImage)> = dev.attachments.images.lock().drain().collect();
    let fallbacks: Vec<(ShadowImage, vk::ImageView)> = own.fallbacks.lock().drain(..).collect();
    // SAFETY: the layer's own objects on a live, idle device.
    unsafe {
        own.clears.destroy(&own.fns);
        for v in views {
            own.fns.destroy_image_view(v.view, None);
        }
        for (s, v) in fallbacks {
            own.fns.destroy_image_view(v, None);
            own.fns.destroy_image(s.image, None);
            own.fns.free_memory(s.memory, None);
        }
        for (app, s) in images {
            bridge::set_shadow(vk::Image::from_raw(app), None);
            own.fns.destroy_image(s.image, None);
            own.fns.free_memory(s.memory, None);
        }
    }
}

/// `vkTransitionImageLayout(EXT)` (`VK_EXT_host_image_copy`, core in Vulkan 1.4): a host-side
/// layout transition names layouts as barriers do, so the density-map layout becomes the one the
/// application's density images have on the driver's side (`GENERAL`, `crate::vk::barrier`), on a
/// copy of the array. The shadow needs nothing: it keeps its own layout, and whether a map is read
/// is decided by the layout each pass names (`crate::vk::convert`).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn transition_image_layout_with(
    which: &'static str,
    next: fn(&Device) -> Option<vk::PFN_vkTransitionImageLayoutEXT>,
    device: vk::Device,
    count: u32,
    infos: *const vk::HostImageLayoutTransitionInfoEXT<'_>,
) -> vk::Result {
    guard(which, vk::Result::ERROR_INITIALIZATION_FAILED, || {
        // SAFETY: as the caller promised.
        let Some(dev) = (unsafe { registry::device(device) }) else {
            return vk::Result::ERROR_INITIALIZATION_FAILED;
        };
        let Some(down) = next(&dev) else {
            return vk::Result::ERROR_INITIALIZATION_FAILED;
        };
        let given = if infos.is_null() || count == 0 {
            &[][..]
        } else {
            // SAFETY: the caller's array of `count` infos.
            unsafe { std::slice::from_raw_parts(infos, count as usize) }
        };
        let fdm = vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT;
        if !given
            .iter()
            .any(|t| t.old_layout == fdm || t.new_layout == fdm)
        {
            // SAFETY: the next layer's function, with the caller's arguments.
            return unsafe { down(device, count, infos) };
        }
        crate::vk::convert::map_may_have_changed();
        let copy: Vec<vk::HostImageLayoutTransitionInfoEXT<'_>> = given
            .iter()
            .map(|t| {
                let mut t = *t;
                t.old_layout = crate::vk::barrier::layout(t.old_layout);
                t.new_layout = crate::vk::barrier::layout(t.new_layout);
                t
            })
            .collect();
        // SAFETY: the next layer's function, with a copy that lives across the call.
        unsafe { down(device, count, copy.as_ptr()) }
    })
}

/// `vkTransitionImageLayout` (Vulkan 1.4): see [`transition_image_layout_with`].
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn transition_image_layout(
    device: vk::Device,
    count: u32,
    infos: *const vk::HostImageLayoutTransitionInfoEXT<'_>,
) -> vk::Result {
    // SAFETY: the caller's arguments.
    unsafe {
        transition_image_layout_with(
            "vkTransitionImageLayout",
            |d| d.next.transition_image_layout,
            device,
            count,
            infos,
        )
    }
}

/// `vkTransitionImageLayoutEXT`: see [`transition_image_layout_with`].
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn transition_image_layout_ext(
    device: vk::Device,
    count: u32,
    infos: *const vk::HostImageLayoutTransitionInfoEXT<'_>,
) -> vk::Result {
    // SAFETY: the caller's arguments.
    unsafe {
        transition_image_layout_with(
            "vkTransitionImageLayoutEXT",
            |d| d.next.transition_image_layout_ext,
            device,
            count,
            infos,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shadow(layers: u32, app_layers: u32) -> ShadowImage {
        ShadowImage {
            image: vk::Image::from_raw(7),
            memory: vk::DeviceMemory::null(),
            extent: vk::Extent2D {
                width: 8,
                height: 8,
            },
            layers,
            app_layers,
        }
    }

    fn app_view(ty: vk::ImageViewType, base: u32, count: u32) -> vk::ImageViewCreateInfo<'static> {
        vk::ImageViewCreateInfo::default()
            .view_type(ty)
            .format(vk::Format::R8G8_UNORM)
            .components(vk::ComponentMapping {
                r: vk::ComponentSwizzle::G,
                ..Default::default()
            })
            .subresource_range(vk::ImageSubresourceRange {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                base_mip_level: 0,
                level_count: 1,
                base_array_layer: base,
                layer_count: count,
            })
    }

    #[test]
    fn layered_shadow_views_follow_the_applications_layers() {
        let s = shadow(2, 2);
        let v = shadow_view_info(&s, &app_view(vk::ImageViewType::TYPE_2D_ARRAY, 0, 2));
        assert_eq!(v.view_type, vk::ImageViewType::TYPE_2D_ARRAY);
        assert_eq!(v.format, vk::Format::R8_UINT);
        assert_eq!(
            v.components.r,
            vk::ComponentSwizzle::IDENTITY,
            "identity swizzle"
        );
        assert_eq!(
            (
                v.subresource_range.base_array_layer,
                v.subresource_range.layer_count
            ),
            (0, 2)
        );
        let eye = shadow_view_info(&s, &app_view(vk::ImageViewType::TYPE_2D, 1, 1));
        assert_eq!(eye.view_type, vk::ImageViewType::TYPE_2D);
        assert_eq!(eye.subresource_range.base_array_layer, 1);
        let rest = shadow_view_info(
            &s,
            &app_view(
                vk::ImageViewType::TYPE_2D_ARRAY,
                1,
                vk::REMAINING_ARRAY_LAYERS,
            ),
        );
        assert_eq!(rest.subresource_range.layer_count, 1);
    }

    #[test]
    fn merged_shadow_views_have_one_layer() {
        let s = shadow(1, 2);
        for (ty, base, count) in [
            (vk::ImageViewType::TYPE_2D_ARRAY, 0, 2),
            (vk::ImageViewType::TYPE_2D, 1, 1),
        ] {
            let v = shadow_view_info(&s, &app_view(ty, base, count));
            assert_eq!(
                (
                    v.subresource_range.base_array_layer,
                    v.subresource_range.layer_count
                ),
                (0, 1)
            );
        }
    }

    #[test]
    fn shadow_layers_follow_the_device() {
        let mut fdm = FdmEmulation {
            texel: [16, 16],
            layered: true,
            max_fragment: [4, 4],
            rates: Vec::new(),
            non_trivial_combiners: true,
        };
        assert_eq!(shadow_layers(&fdm, 2), 2);
        fdm.layered = false;
        assert_eq!(shadow_layers(&fdm, 2), 1);
    }
}
