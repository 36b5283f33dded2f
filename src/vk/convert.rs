//! Density maps an application writes itself: converted into their shadows on the GPU, inside the
//! application's command buffer, in front of every pass that reads them.
//!
//! fovea's own density images write shading-rate codes into their shadow at upload
//! (`xr::density_images`). An application's own map is written by the application's commands
//! (copies, draws, dispatches), so its content is known only on the device, when the pass runs. At
//! `vkCmdBeginRenderPass(2)` and `vkCmdBeginRendering` of a pass whose density map is such an image,
//! the layer records, before calling down: a barrier making earlier writes visible to compute
//! (and discarding the shadow's old content once earlier passes read it), a dispatch of
//! `shaders/convert.comp` that reads the map (a layer-owned sampled view) and writes codes into a
//! code buffer the command buffer owns ([`Slot`]), a barrier from that dispatch to a copy of the
//! buffer into the shadow, a barrier handing the shadow to the shading-rate stage in
//! `FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR`, and finally the application's own compute
//! bindings again (docs/vulkan-fdm-on-fsr.md#shadows). The conversion runs at every such pass
//! begin unless the command buffer already converted the map and nothing since may have changed
//! it ([`MAP_EPOCH`]); it runs outside the application's conditional rendering, which would skip
//! the dispatch but not the copy.
//!
//! Density-map offsets (`VK_EXT_fragment_density_map_offset`, docs/vulkan-layer.md#density-map-offsets)
//! arrive with the end of a pass, after its draws are recorded, while the shading-rate attachment
//! is read as they run. A map created with the offset flag is therefore converted in front of every
//! pass that reads it, with a slot of its own per pass instance of the recording whose
//! host-visible shifts the shader reads; the pass's end writes them ([`ended`]), and the host's
//! writes before `vkQueueSubmit` are visible to that submission. The shader's lookup is the
//! specification's, x′ = x − offset clamped to the map, per layer.
//!
//! The byte → code mapping is `fovea_model::shading_rate::fill_codes`; the shader gets everything
//! device-specific (the clamp to `maxFragmentSize` and to the rates
//! `vkGetPhysicalDeviceFragmentShadingRatesKHR` lists) as a 4×4 table of codes indexed by the
//! wanted log2 fragment size, built here at device creation from the model itself.
//!
//! Bound state: a dispatch binds a compute pipeline, a descriptor set and push constants, which
//! persist across passes (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#pipelines-bindpoint-commands>,
//! <https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#descriptorsets-compatibility>).
//! So on emulating devices the layer records per command buffer what the application bound at the
//! compute bind point and the push-constant updates of the compute stage that no later push
//! covered ([`Bound`](crate::vk::own::bindings::Bound), fixed size, made at
//! `vkBeginCommandBuffer`), and binds it all again after the conversion: a compute dispatch
//! disturbs nothing of the graphics stages, so engines' per-draw graphics pushes are not kept. Where it cannot (push
//! descriptors, more sets or dynamic offsets than a record holds), that pass's map is not converted
//! and renders at full rate, and the log says so once. Devices with commands that bind compute
//! state the layer does not intercept (Vulkan 1.4, `VK_KHR_maintenance6`, descriptor buffers,
//! shader objects, device-generated commands) convert nothing.
//!
//! Objects: pipeline, layouts and descriptor pools at device creation; per density image a sampled
//! view of it with its first view; per command buffer and map a code buffer and a descriptor set
//! at the command buffer's first conversion of the map; all destroyed with their owners. Nothing is
//! allocated per command in steady state, and no process-wide lock is taken while recording: each
//! thread finds its command buffers' records in a cache of its own ([`record_of`]).

use std::collections::HashMap;
use std::ffi::CStr;
use std::hash::BuildHasherDefault;
use std::sync::atomic::Ordering;
use std::sync::Arc;

use ash::vk;
use ash::vk::Handle as _;

use crate::common::lock::SharedRwLock;
use crate::vk::base::chain;
use crate::vk::base::ffi::{key, raw, AddressHasher, Key};
use crate::vk::own::bindings::restore;
use crate::vk::own::convert_shader::{texel_shift, Push, GROUP, MAX_SHIFTS};
use crate::vk::own::converter::{write_shifts, Converter, MapEntry, Slot, SourceAndShadow};
use crate::vk::own::shadows::ShadowImage;
use crate::vk::registry::{
    self, bound_of, converter, forget_command_buffers_where, record_of, with_record, Device,
    CB_GENERATION, CB_RECORDS, CONVERTERS,
};
use crate::vk::translate::formats::SHADOW_LAYOUT;

/// Runs `f` with the converter of a command buffer's device, reached through the command
/// buffer's record (this thread's cache: no process-wide lock, no reference count), if the
/// device converts.
fn with_converter<R>(cb: vk::CommandBuffer, f: impl FnOnce(&Converter) -> R) -> Option<R> {
    record_of(cb, |r| r.converter.as_deref().map(f)).flatten()
}

/// Whether a command buffer's device converts.
fn has_converter(cb: vk::CommandBuffer) -> bool {
    record_of(cb, |r| r.converter.is_some()).unwrap_or(false)
}

/// Extensions whose commands bind compute state the layer does not intercept, so it could not
/// give the application its bindings back after a conversion.
const UNTRACKED: &[&CStr] = &[
    c"VK_KHR_maintenance6",
    c"VK_EXT_descriptor_buffer",
    c"VK_EXT_shader_object",
    c"VK_NV_device_generated_commands",
    c"VK_NV_device_generated_commands_compute",
    c"VK_EXT_device_generated_commands",
];

/// Why a device cannot convert, from its create info, or `None` where it can.
///
/// # Safety
/// `ci` must be a valid device create info.
unsafe fn untracked_binds(ci: &vk::DeviceCreateInfo<'_>, api_version: u32) -> Option<String> {
    if api_version >= vk::make_api_version(0, 1, 4, 0) {
        return Some(
            "Vulkan 1.4 binds compute state through commands the layer does not see".into(),
        );
    }
    let names = if ci.pp_enabled_extension_names.is_null() {
        &[][..]
    } else {
        // SAFETY: as the caller promised.
        unsafe {
            std::slice::from_raw_parts(
                ci.pp_enabled_extension_names,
                ci.enabled_extension_count as usize,
            )
        }
    };
    names.iter().find_map(|&p| {
        // SAFETY: enabled extension names are NUL-terminated strings.
        let name = unsafe { CStr::from_ptr(p) };
        UNTRACKED.contains(&name).then(|| {
            format!(
                "{} binds compute state the layer does not see",
                name.to_string_lossy()
            )
        })
    })
}

/// Whether every graphics queue family the device was created with can run compute, which the
/// conversion, recorded into the application's graphics command buffers, needs.
///
/// # Safety
/// As [`device_created`].
unsafe fn graphics_queues_compute(
    inst: &registry::Instance,
    physical: vk::PhysicalDevice,
    ci: &vk::DeviceCreateInfo<'_>,
) -> bool {
    // SAFETY: the next layer's instance command, of the type its name implies.
    let Some(f) = (unsafe {
        (inst.gipa)(
            inst.handle,
            c"vkGetPhysicalDeviceQueueFamilyProperties".as_ptr(),
        )
    }) else {
        return false;
    };
    // SAFETY: as above.
    let f = unsafe {
        std::mem::transmute::<
            unsafe extern "system" fn(),
            vk::PFN_vkGetPhysicalDeviceQueueFamilyProperties,
        >(f)
    };
    let mut n = 0;
    // SAFETY: a two-call query on a live physical device.
    unsafe { f(physical, &mut n, std::ptr::null_mut()) };
    let mut families = vec![vk::QueueFamilyProperties::default(); n as usize];
    // SAFETY: as above.
    unsafe { f(physical, &mut n, families.as_mut_ptr()) };
    families.truncate(n as usize);
    let infos = if ci.p_queue_create_infos.is_null() {
        &[][..]
    } else {
        // SAFETY: as the caller promised.
        unsafe {
            std::slice::from_raw_parts(ci.p_queue_create_infos, ci.queue_create_info_count as usize)
        }
    };
    infos.iter().all(|q| {
        families.get(q.queue_family_index as usize).is_none_or(|f| {
            !f.queue_flags.contains(vk::QueueFlags::GRAPHICS)
                || f.queue_flags.contains(vk::QueueFlags::COMPUTE)
        })
    })
}

/// Why the layer cannot record compute dispatches into a device's command buffers and give the
/// application its compute bindings back after them, or `None` where it can (the conversion's
/// and the reconstruction's condition).
///
/// # Safety
/// As [`device_created`].
pub unsafe fn dispatch_blocked(
    inst: &registry::Instance,
    physical: vk::PhysicalDevice,
    ci: &vk::DeviceCreateInfo<'_>,
    api_version: u32,
) -> Option<String> {
    // SAFETY: as the caller promised.
    unsafe { untracked_binds(ci, api_version) }.or_else(|| {
        // SAFETY: as the caller promised.
        (!unsafe { graphics_queues_compute(inst, physical, ci) })
            .then(|| "a graphics queue family without compute".to_owned())
    })
}

/// Sets up conversion on a device just recorded in the registry, or logs why not (its
/// application-written maps then render at full rate); whether the device converts.
///
/// # Safety
/// `ci` must be the application's create info of the live device `handle`, made on `physical`.
pub unsafe fn device_created(
    inst: &registry::Instance,
    physical: vk::PhysicalDevice,
    ci: &vk::DeviceCreateInfo<'_>,
    handle: vk::Device,
) -> bool {
    // SAFETY: as the caller promised.
    let Some(dev) = (unsafe { registry::device(handle) }) else {
        return false;
    };
    let (Some(fdm), Some(own)) = (&dev.fdm, &dev.attachments.own) else {
        return false;
    };
    // SAFETY: as the caller promised.
    if let Some(why) = unsafe { dispatch_blocked(inst, physical, ci, dev.api_version) } {
        tracing::warn!(
            device = raw(handle),
            why = why.as_str(),
            "density maps the application writes itself are not converted on this device: they \
             render at full rate, and density-map offsets are not applied"
        );
        return false;
    }
    // SAFETY: the layer's own objects on a live device.
    match unsafe { Converter::new(Arc::clone(own), fdm) } {
        Ok(c) => {
            // SAFETY: as the caller promised.
            let Some(k) = (unsafe { key(handle) }) else {
                // SAFETY: made on this live device, used by nothing yet.
                unsafe { c.destroy() };
                return false;
            };
            let mut v = CONVERTERS.write();
            v.retain(|(key, _)| *key != k);
            v.push((k, Arc::new(c)));
            true
        }
        Err(e) => {
            tracing::warn!(
                device = raw(handle),
                result = ?e,
                "no density-map conversion on this device: maps the application writes itself \
                 render at full rate, and density-map offsets are not applied"
            );
            false
        }
    }
}

/// Destroys a device's conversion objects; the device is about to be destroyed.
///
/// # Safety
/// `handle` must be live and idle.
pub unsafe fn device_destroyed(handle: vk::Device) {
    // SAFETY: as the caller promised.
    let Some(k) = (unsafe { key(handle) }) else {
        return;
    };
    // Command buffers go with their device (and pools) without vkFreeCommandBuffers; their slots
    // go while the converter is still there.
    forget_command_buffers_where(|_, r| r.device == k);
    let c = {
        let mut v = CONVERTERS.write();
        let at = v.iter().position(|(key, _)| *key == k);
        at.map(|i| v.swap_remove(i).1)
    };
    if let Some(c) = c {
        // SAFETY: as the caller promised.
        unsafe { c.destroy() };
    }
    FRAMEBUFFERS.write().retain(|_, (key, _)| *key != k);
}

/// Forgets, without a call to the driver, what the layer kept for a device that is gone without
/// `vkDestroyDevice`: the application destroyed its instance with the device still alive
/// (VUID-vkDestroyInstance-instance-00629), and the loader freed the device's dispatch table,
/// whose address a new device may get. Called at that `vkDestroyInstance`, and where a new device
/// has the dispatch key of one the layer still knows. The old device's objects are gone with it; destroying them
/// now would call a driver that no longer has them, so its command buffers' records, its
/// converter and its framebuffers are dropped as they are.
pub fn device_key_reused(k: Key) {
    {
        let mut map = CB_RECORDS.lock();
        let before = map.len();
        map.retain(|_, r| r.device != k);
        if map.len() != before {
            CB_GENERATION.fetch_add(1, Ordering::Release);
        }
    }
    CONVERTERS.write().retain(|(key, _)| *key != k);
    FRAMEBUFFERS.write().retain(|_, (key, _)| *key != k);
}

/// A density image just got its shadow: an application's, or one of fovea's own created with
/// `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT` (`offsets`), whose passes may end with
/// offsets, which only a conversion in front of the pass can apply; its conversion objects are
/// made with its first view ([`view_changed`]).
///
/// # Safety
/// `app` must be the live image just created on `dev`, shadowed by `shadow`.
pub unsafe fn map_created(dev: &Device, app: vk::Image, shadow: &ShadowImage, offsets: bool) {
    // SAFETY: as the caller promised.
    if let Some(c) = unsafe { converter(dev.handle) } {
        c.maps.lock().insert(
            app.as_raw(),
            MapEntry {
                shadow: *shadow,
                objects: None,
                offsets,
            },
        );
    }
    if !crate::bridge::creating_own_density_images()
        && !dev
            .attachments
            .app_maps_logged
            .swap(true, Ordering::Relaxed)
    {
        tracing::info!(
            image = raw(app),
            "this application creates and writes density maps itself: they are converted into \
             shading rates on the GPU at every pass begin that reads them (fovea's own density \
             maps carry their rates)"
        );
    }
}

/// The application destroyed a density image: its conversion objects go too.
///
/// # Safety
/// `dev` must be live; the application's uses of `app` have ended.
pub unsafe fn map_destroyed(dev: &Device, app: vk::Image) {
    // SAFETY: as the caller promised.
    let Some(c) = (unsafe { converter(dev.handle) }) else {
        return;
    };
    let m = c.maps.lock().remove(&app.as_raw());
    // Command buffers drop their slots of this map at their next begin ([`begun`]).
    c.maps_destroyed.fetch_add(1, Ordering::Release);
    if let Some(MapEntry {
        objects: Some(m), ..
    }) = m
    {
        // SAFETY: every command buffer that used it used the application's image, which the
        // application no longer uses; command buffers' sets naming it are never bound again
        // (a slot is matched by its map's generation, `Converter::slot`) and go with their slots.
        unsafe { c.own.fns.destroy_image_view(m.view, None) };
    }
}

/// `vkBeginCommandBuffer` of a command buffer with record `r`: where one of its device's maps
/// was destroyed since the command buffer was last checked, its slots of dead maps are destroyed
/// (their sets name destroyed views, and a map recreated with the same handles gets slots of its
/// own, [`Converter::slot`]), so that a command buffer re-recorded across many recreations keeps
/// one slot per live map. The command buffer is not pending
/// (VUID-vkBeginCommandBuffer-commandBuffer-00049), so none of its slots is in use. In steady
/// state one atomic load.
pub fn begun(r: &registry::CbRecord) {
    let Some(c) = r.converter.as_deref() else {
        return;
    };
    let now = c.maps_destroyed.load(Ordering::Acquire);
    if r.swept.load(Ordering::Relaxed) == now {
        return;
    }
    r.swept.store(now, Ordering::Relaxed);
    let dead: Vec<Slot> = {
        let mut slots = r.slots.lock();
        if slots.is_empty() {
            return;
        }
        let maps = c.maps.lock();
        let live = |s: &Slot| {
            maps.get(&s.image)
                .and_then(|e| e.objects)
                .is_some_and(|o| o.generation == s.generation)
        };
        let dead = slots.iter().filter(|s| !live(s)).copied().collect();
        slots.retain(live);
        dead
    };
    // SAFETY: the converter's own slots, of a command buffer that is not pending (above).
    unsafe { c.destroy_slots(&dead) };
}

/// Notes an application view of a density image (`Some`) or its destruction (`None`).
///
/// # Safety
/// `dev` must be live.
pub unsafe fn view_changed(dev: &Device, view: vk::ImageView, image: Option<vk::Image>) {
    // SAFETY: as the caller promised.
    let Some(c) = (unsafe { converter(dev.handle) }) else {
        return;
    };
    let Some(i) = image else {
        c.views.lock().remove(&view.as_raw());
        return;
    };
    let mut maps = c.maps.lock();
    let Some(entry) = maps.get_mut(&i.as_raw()) else {
        return;
    };
    if entry.objects.is_none() {
        // SAFETY: the application's live image, with memory now (it has a view).
        match unsafe { c.make_map(i, &entry.shadow, entry.offsets) } {
            Ok(m) => entry.objects = Some(m),
            Err(e) => {
                tracing::warn!(
                    image = raw(i),
                    result = ?e,
                    "no conversion for a density map the application writes: passes with it \
                     render at full rate"
                );
                return;
            }
        }
    }
    drop(maps);
    c.views.lock().insert(view.as_raw(), i.as_raw());
}

/// Notes a framebuffer of a rewritten pass and its density view (`Some`; `None` forgets it).
///
/// # Safety
/// `dev` must be live.
pub unsafe fn framebuffer_changed(dev: &Device, fb: vk::Framebuffer, view: Option<vk::ImageView>) {
    // Only converting devices' framebuffers are looked up at begin.
    // SAFETY: as the caller promised.
    if unsafe { converter(dev.handle) }.is_none() {
        return;
    }
    // SAFETY: as the caller promised.
    let Some(k) = (unsafe { key(dev.handle) }) else {
        return;
    };
    let mut fbs = FRAMEBUFFERS.write();
    if view.is_some() {
        let (word, bit) = filter_slot(fb.as_raw());
        FRAMEBUFFER_FILTER[word].fetch_or(bit, Ordering::Release);
    }
    match view {
        Some(v) => fbs.insert(fb.as_raw(), (k, v.as_raw())),
        None => fbs.remove(&fb.as_raw()),
    };
}

/// A filter in front of [`FRAMEBUFFERS`]: one bit per hash slot, set for every framebuffer ever
/// entered (never cleared: a stale bit only costs the table look-up). A clear bit proves the
/// framebuffer is not in the table, so a begin of a pass without a density map costs one atomic
/// load here.
const FILTER_WORDS: usize = 64;
static FRAMEBUFFER_FILTER: [std::sync::atomic::AtomicU64; FILTER_WORDS] =
    [const { std::sync::atomic::AtomicU64::new(0) }; FILTER_WORDS];

/// The filter word and bit of a framebuffer handle (12 bits of a multiplicative hash).
fn filter_slot(fb: u64) -> (usize, u64) {
    let h = ((fb ^ (fb >> 29)).wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 52) as usize;
    (h / 64, 1 << (h % 64))
}

/// Framebuffers of rewritten passes on converting devices → (device key, density view). One
/// table for all devices, looked up first at every render-pass begin whose framebuffer passes
/// [`FRAMEBUFFER_FILTER`], before any per-device look-up. A leaf lock.
static FRAMEBUFFERS: SharedRwLock<HashMap<u64, (Key, u64), BuildHasherDefault<AddressHasher>>> =
    SharedRwLock::new(HashMap::with_hasher(BuildHasherDefault::new()));

/// A filter of render passes that write or order density maps (see [`MAP_EPOCH`]): one bit per
/// hash slot, never cleared; a stale or shared bit only costs a conversion.
static WRITER_FILTER: [std::sync::atomic::AtomicU64; FILTER_WORDS] =
    [const { std::sync::atomic::AtomicU64::new(0) }; FILTER_WORDS];

/// A render pass that names the density layout, stage or access but reads no map was created:
/// its begins advance [`MAP_EPOCH`].
pub fn writer_pass_created(pass: vk::RenderPass) {
    let (word, bit) = filter_slot(pass.as_raw());
    WRITER_FILTER[word].fetch_or(bit, Ordering::Release);
}

/// Notes a rewritten render pass's density attachment `initialLayout` and `finalLayout` as the
/// driver gets them (`Some`), or its destruction.
///
/// # Safety
/// `dev` must be live.
pub unsafe fn pass_changed(
    dev: &Device,
    pass: vk::RenderPass,
    layouts: Option<(vk::ImageLayout, vk::ImageLayout, bool)>,
) {
    // SAFETY: as the caller promised.
    let Some(c) = (unsafe { converter(dev.handle) }) else {
        return;
    };
    let mut passes = c.passes.lock();
    match layouts {
        Some(l) => passes.insert(pass.as_raw(), l),
        None => passes.remove(&pass.as_raw()),
    };
}

/// `vkCmdBeginRenderPass(2)`, before calling down: converts the pass's density map where the
/// application writes it.
///
/// # Safety
/// `cb` must be recording on `dev`; `begin` NULL or valid.
pub unsafe fn before_render_pass(
    dev: &Device,
    cb: vk::CommandBuffer,
    begin: *const vk::RenderPassBeginInfo<'_>,
) {
    // Only emulating devices convert (`device_created`): on an injecting one no table of this
    // module is looked at, however the pass is begun.
    if dev.fdm.is_none() {
        return;
    }
    // SAFETY: as the caller promised.
    let (Some(k), Some(b)) = (unsafe { key(cb) }, unsafe { begin.as_ref() }) else {
        return;
    };
    let (word, bit) = filter_slot(b.render_pass.as_raw());
    if WRITER_FILTER[word].load(Ordering::Acquire) & bit != 0 {
        map_may_have_changed();
    }
    let (word, bit) = filter_slot(b.framebuffer.as_raw());
    let known = (FRAMEBUFFER_FILTER[word].load(Ordering::Acquire) & bit != 0)
        .then(|| FRAMEBUFFERS.read().get(&b.framebuffer.as_raw()).copied())
        .flatten();
    let view = known.filter(|(key, _)| *key == k).map(|(_, v)| v);
    if view.is_none() && b.p_next.is_null() {
        return;
    }
    // SAFETY: as the caller promised.
    if !has_converter(cb) {
        return;
    }
    let Some(density) = dev.attachments.density_attachment(b.render_pass) else {
        return;
    };
    let view = view.or_else(|| {
        // An imageless framebuffer: the view is in the begin info.
        let ty = vk::StructureType::RENDER_PASS_ATTACHMENT_BEGIN_INFO;
        // SAFETY: the caller's chain, read only.
        let found = unsafe { chain::find::<vk::RenderPassAttachmentBeginInfo>(b.p_next, ty) };
        // SAFETY: found by its sType in a valid chain.
        let found = unsafe { found.ok().flatten()?.as_ref()? };
        if density >= found.attachment_count || found.p_attachments.is_null() {
            return None;
        }
        // SAFETY: the caller's array of `attachment_count` views.
        Some(unsafe { *found.p_attachments.add(density as usize) }.as_raw())
    });
    let Some(view) = view else {
        return;
    };
    let shifts = with_converter(cb, |c| {
        let (initial, last, density_initial) =
            c.passes.lock().get(&b.render_pass.as_raw()).copied()?;
        // SAFETY: as the caller promised.
        unsafe { c.convert_for_pass(cb, view, initial, last, density_initial) }
    });
    opened(cb, shifts.flatten(), false);
}

/// Notes the render pass instance just begun in `cb` (a non-resuming begin that names a density
/// map): the shifts its conversion reads where its map takes offsets, which its end writes
/// ([`ended`]); `suspending` where it was begun so.
fn opened(cb: vk::CommandBuffer, shifts: Option<(usize, [u32; 2])>, suspending: bool) {
    with_record(cb, |b| {
        b.open = shifts;
        b.suspended = suspending;
    });
}

/// The end of a render pass instance (`vkCmdEndRenderPass2`, `vkCmdEndRendering2EXT`) with
/// `offsets` (empty: none, or a count of zero, which both mean (0, 0)): where the instance's
/// conversion reads shifts, they get the offsets, per layer, as whole texels
/// ([`texel_shift`]); the recording is not pending, so nothing reads them until its next submit,
/// which sees the host's write. The end of a part of a dynamic render pass instance begun
/// suspending carries no offsets (the specification ignores them): the end after its last
/// resumption does. Offsets beyond the map's layers or [`MAX_SHIFTS`] are ignored; missing ones
/// are (0, 0). The application's errors are handled as the specification's lookup would: an
/// offset that is not a multiple of the granularity shifts by the texel whose centre it lands
/// nearest ([`texel_shift`]); offsets at the end of a pass whose map was created without the
/// offset flag change nothing; those at the end of a pass that reads no map go to the last pass
/// of the recording that read one with the flag, if it ended through the plain
/// `vkCmdEndRenderPass` or `vkCmdEndRendering` (not intercepted, so that they cost nothing), else
/// nowhere (docs/vulkan-layer.md#density-map-offsets).
pub fn ended(cb: vk::CommandBuffer, offsets: &[vk::Offset2D]) {
    record_of(cb, |r| {
        let open = {
            let mut b = r.bound.lock();
            if b.suspended {
                return;
            }
            b.open.take()
        };
        let Some((at, texel)) = open else {
            return;
        };
        let mut shifts = [[0i32; 2]; MAX_SHIFTS];
        for (s, o) in shifts.iter_mut().zip(offsets) {
            *s = [texel_shift(o.x, texel[0]), texel_shift(o.y, texel[1])];
        }
        // SAFETY: a live slot's shifts (the slot lives as long as its command buffer's record,
        // which this call on `cb` holds), written while `cb` records.
        unsafe { write_shifts(at as *mut u8, &shifts) };
    });
}

/// `vkCmdBeginRendering`, before calling down: converts the density map the rendering info names
/// where the application writes it.
///
/// # Safety
/// `cb` must be recording on `dev`; `info` NULL or valid.
pub unsafe fn before_rendering(
    dev: &Device,
    cb: vk::CommandBuffer,
    info: *const vk::RenderingInfo<'_>,
) {
    // As in `before_render_pass`.
    if dev.fdm.is_none() {
        return;
    }
    // SAFETY: as the caller promised.
    let Some(ri) = (unsafe { info.as_ref() }) else {
        return;
    };
    if ri.p_next.is_null() {
        return;
    }
    let ty = vk::StructureType::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_INFO_EXT;
    type Info<'a> = vk::RenderingFragmentDensityMapAttachmentInfoEXT<'a>;
    // SAFETY: the caller's chain, read only.
    let found = unsafe { chain::find::<Info<'_>>(ri.p_next, ty) };
    // SAFETY: found by its sType in a valid chain.
    let Some(f) = found.ok().flatten().and_then(|p| unsafe { p.as_ref() }) else {
        return;
    };
    if f.image_view == vk::ImageView::null() {
        return;
    }
    let suspending = ri.flags.contains(vk::RenderingFlags::SUSPENDING);
    // A resumed render pass instance was converted where it began, and nothing but the
    // instance's own commands may come between its suspension and resumption
    // (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#renderpass-suspension>).
    // Its offsets are those of the end after its last resumption; an instance suspended in
    // another command buffer has its shifts there, which this recording cannot reach.
    if ri.flags.contains(vk::RenderingFlags::RESUMING) {
        with_record(cb, |b| {
            if !b.suspended {
                b.open = None;
            }
            b.suspended = suspending;
        });
        return;
    }
    let shifts = with_converter(cb, |c| {
        let (image, m) = c.map_of_view(f.image_view.as_raw())?;
        let fdm = f.image_layout == vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT;
        // SAFETY: as the caller promised.
        unsafe { c.convert(cb, image, &m, readable(f.image_layout), fdm) }
    });
    opened(cb, shifts.flatten(), suspending);
}

/// Forgets a destroyed framebuffer's density view (called by `pass::destroy_framebuffer`, after
/// the call went down).
///
/// # Safety
/// `device` is a device the loader dispatched.
pub unsafe fn framebuffer_destroyed(device: vk::Device, fb: vk::Framebuffer) {
    // SAFETY: as the caller promised.
    if let Some(k) = unsafe { key(device) } {
        let mut fbs = FRAMEBUFFERS.write();
        if fbs.get(&fb.as_raw()).is_some_and(|(key, _)| *key == k) {
            fbs.remove(&fb.as_raw());
        }
    }
}

/// Advanced whenever the layer sees something that may change an application's density map:
/// a barrier moving an image into the density-map layout, a host-side transition into it, the
/// begin of a render pass that names the density layout, stage or access without reading a map
/// (one that writes or orders one, [`writer_pass_created`]). A conversion recorded in a command
/// buffer at one value is still good for a later pass of the same command buffer that reads the
/// same map at the same value: nothing the application recorded between them made the map change
/// visible to the density-map read, so that pass needs no conversion and no barrier
/// ([`Bound::converted`](crate::vk::own::bindings::Bound::converted)). Within one command buffer the order of execution is the order of
/// recording, so this holds however command buffers are submitted.
static MAP_EPOCH: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

/// Notes that an application's density map may have changed (see [`MAP_EPOCH`]).
pub fn map_may_have_changed() {
    MAP_EPOCH.fetch_add(1, Ordering::AcqRel);
}

/// The barrier translation's look-up of a shadow for an image the application moves into the
/// density-map layout (`crate::vk::translate::sync`). Whether a map may be read is decided by the layout
/// each pass that reads it names, at that pass's recording ([`before_render_pass`],
/// [`before_rendering`]), not by which barriers were recorded before: command buffers may be
/// submitted in another order than they were recorded.
pub fn shadow_of_transitioned(image: vk::Image) -> Option<crate::bridge::Shadow> {
    map_may_have_changed();
    crate::bridge::shadow_of(image)
}

/// Whether a density map in `layout` (as the application names it) is readable as `GENERAL`:
/// the density layout becomes `GENERAL` on the application's image (`crate::vk::translate::sync`).
fn readable(layout: vk::ImageLayout) -> bool {
    layout == vk::ImageLayout::GENERAL
        || layout == vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT
}

impl Converter {
    /// `cb`'s slot for the map `m` of `image` in recording `recording`: one it converted the map
    /// with before (for a map that takes offsets, one that no conversion of this recording took
    /// yet, so that each pass instance has shifts of its own), or a new one (slots made for an
    /// earlier image with the same handle are replaced). A slot is the map's when it carries the
    /// map's generation: the image's and the converter view's handles may both be a destroyed
    /// map's, reused by the driver.
    ///
    /// # Safety
    /// As [`Converter::make_slot`]; `cb` recording on this device.
    unsafe fn slot(
        &self,
        cb: vk::CommandBuffer,
        image: u64,
        m: &SourceAndShadow,
        recording: u64,
    ) -> Option<Slot> {
        let known = record_of(cb, |r| {
            let mut slots = r.slots.lock();
            // A recording takes its slots in the order the previous one did: the search starts
            // after the last one taken, so a recording of many passes finds each at once.
            let mut b = r.bound.lock();
            let n = slots.len();
            let start = b.next_slot.min(n);
            let at = (start..n).chain(0..start).find(|&i| {
                let s = &slots[i];
                s.image == image
                    && s.generation == m.generation
                    && (!m.offsets || s.used_in != recording)
            })?;
            b.next_slot = at + 1;
            slots[at].used_in = recording;
            Some(slots[at])
        })?;
        if known.is_some() {
            return known;
        }
        // SAFETY: as the caller promised.
        match unsafe { self.make_slot(image, m) } {
            Ok(mut slot) => {
                slot.used_in = recording;
                let stale = record_of(cb, |r| {
                    let mut slots = r.slots.lock();
                    let gone = |s: &Slot| s.image == image && s.generation != m.generation;
                    let stale: Vec<Slot> = slots.iter().filter(|s| gone(s)).copied().collect();
                    slots.retain(|s| !gone(s));
                    slots.push(slot);
                    stale
                })
                .unwrap_or_default();
                // SAFETY: slots of a view destroyed with its image; the command buffer is
                // recording, so none of its earlier recordings is pending.
                unsafe { self.destroy_slots(&stale) };
                Some(slot)
            }
            Err(e) => {
                if !self.logged_state.swap(true, Ordering::Relaxed) {
                    tracing::warn!(
                        image = image,
                        result = ?e,
                        "no code buffer for a density-map conversion: the pass renders with what \
                         the shadow holds"
                    );
                }
                None
            }
        }
    }

    /// The application image a view shows and its conversion objects, if it is a converted map.
    fn map_of_view(&self, view: u64) -> Option<(u64, SourceAndShadow)> {
        let image = self.views.lock().get(&view).copied()?;
        let m = self.maps.lock().get(&image).and_then(|e| e.objects)?;
        Some((image, m))
    }

    /// In front of a rewritten render pass: the application's image makes the pass's
    /// `initialLayout` → `finalLayout` transition the driver's pass no longer makes (the shadow
    /// stands in for the image there), so the layouts the application's later barriers name are
    /// the image's; and the map is converted in whichever of the two layouts it can be read, in
    /// the order that reads it there. A map whose content the transition discards (`UNDEFINED`)
    /// is not converted: its shadow keeps what it had, which the density map's undefined content
    /// allows.
    ///
    /// # Safety
    /// As [`Converter::convert`].
    unsafe fn convert_for_pass(
        &self,
        cb: vk::CommandBuffer,
        view: u64,
        initial: vk::ImageLayout,
        last: vk::ImageLayout,
        density_initial: bool,
    ) -> Option<(usize, [u32; 2])> {
        let (image, m) = self.map_of_view(view)?;
        let discarded = matches!(
            initial,
            vk::ImageLayout::UNDEFINED | vk::ImageLayout::PREINITIALIZED
        );
        let before = readable(initial);
        let mut shifts = None;
        if before {
            let unchanged = density_initial && initial == last;
            // SAFETY: as the caller promised.
            shifts = unsafe { self.convert(cb, image, &m, true, unchanged) };
        }
        if initial != last {
            // SAFETY: as the caller promised; the application's image, whole.
            unsafe { self.transition(cb, image, &m.shadow, initial, last) };
        }
        if !before {
            // SAFETY: as the caller promised.
            shifts = unsafe { self.convert(cb, image, &m, !discarded && readable(last), false) };
        }
        shifts
    }

    /// Records a layout transition of the application's image, ordered after everything before
    /// it and before everything after it (a render pass's own transitions are ordered by its
    /// external dependencies, which the application made for the pass's use of the map).
    ///
    /// # Safety
    /// As [`Converter::convert`].
    unsafe fn transition(
        &self,
        cb: vk::CommandBuffer,
        image: u64,
        shadow: &ShadowImage,
        old: vk::ImageLayout,
        new: vk::ImageLayout,
    ) {
        let d = &self.own.fns;
        // SAFETY: as the caller promised.
        unsafe {
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[vk::ImageMemoryBarrier::default()
                    .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
                    .dst_access_mask(vk::AccessFlags::MEMORY_READ | vk::AccessFlags::MEMORY_WRITE)
                    .old_layout(old)
                    .new_layout(new)
                    .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .image(vk::Image::from_raw(image))
                    .subresource_range(vk::ImageSubresourceRange {
                        aspect_mask: vk::ImageAspectFlags::COLOR,
                        base_mip_level: 0,
                        level_count: 1,
                        base_array_layer: 0,
                        layer_count: shadow.app_layers.max(1),
                    })],
            );
        }
    }

    /// Records the conversion of the application's map `image` into its shadow, where `readable`
    /// (its layout at this point is `GENERAL`). `in_density_layout`: the application names the map
    /// in the density layout itself here, which nothing can write in, so a change since an earlier
    /// conversion in this command buffer had to move it back into that layout, which the layer
    /// sees ([`MAP_EPOCH`]); only then may the conversion be skipped, and never for a map that
    /// takes offsets, whose passes each shift it by their own. Returns, for such a map, the shifts
    /// the conversion reads (zero until the pass's end writes them, [`ended`]) and their texel.
    ///
    /// # Safety
    /// `cb` must be recording, outside a render pass, on this converter's device.
    unsafe fn convert(
        &self,
        cb: vk::CommandBuffer,
        image: u64,
        m: &SourceAndShadow,
        readable: bool,
        in_density_layout: bool,
    ) -> Option<(usize, [u32; 2])> {
        if !readable {
            if !self.logged_layout.swap(true, Ordering::Relaxed) {
                tracing::warn!(
                    image = image,
                    "a pass reads a density map the application writes from a layout other than \
                     GENERAL or the density-map layout: not converted, it renders at full rate"
                );
            }
            return None;
        }
        let Some(bound) = bound_of(cb) else {
            if !self.logged_state.swap(true, Ordering::Relaxed) {
                tracing::warn!(
                    image = image,
                    "a command buffer whose compute bindings the layer cannot give back (push \
                     descriptors, or more sets, dynamic offsets or push-constant ranges than it \
                     records): its passes' density maps are not converted, they render at full rate"
                );
            }
            return None;
        };
        let epoch = MAP_EPOCH.load(Ordering::Acquire);
        if in_density_layout && !m.offsets && bound.converted.contains(&(image, epoch)) {
            // Converted earlier in this command buffer, and nothing since may have changed it.
            return None;
        }
        if bound.inherited_conditional {
            if !self.logged_conditional.swap(true, Ordering::Relaxed) {
                tracing::warn!(
                    image = image,
                    "a secondary command buffer that inherits conditional rendering begins a \
                     pass with a density map the application writes: the layer cannot suspend \
                     the condition there (its dispatch would be skipped when its copy is not), so \
                     the map is not converted and its shadow keeps what it had"
                );
            }
            return None;
        }
        // SAFETY: as the caller promised.
        let slot = unsafe { self.slot(cb, image, m, bound.recording) }?;
        // This pass instance's offsets are (0, 0) until its end says otherwise.
        // SAFETY: the slot's own shifts; `cb` is recording.
        unsafe { slot.write_shifts(&[]) };
        // Conditional rendering discards dispatches but not copies
        // (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#drawing-conditional-rendering>):
        // the conversion runs outside it, since the pass reads the map whatever the condition.
        // The begin hooks run outside any render pass, where a condition begun outside one may
        // end and begin again (VUID-vkCmdEndConditionalRenderingEXT-None-01986).
        // SAFETY: `cb` is recording on this device.
        let dev = unsafe { registry::device_ref(cb) };
        let next = dev.as_ref().map(|d| &d.next);
        let suspend = bound.conditional.and_then(|c| {
            let n = next?;
            Some((
                c,
                n.cmd_end_conditional_rendering_ext?,
                n.cmd_begin_conditional_rendering_ext?,
            ))
        });
        if let Some((_, end, _)) = suspend {
            // SAFETY: the next layer's command, on the application's recording command buffer
            // whose condition is active.
            unsafe { end(cb) };
        }
        let d = &self.own.fns;
        let s = &m.shadow;
        let merged = s.layers == 1 && s.app_layers > 1;
        let push = Push {
            width: s.extent.width,
            height: s.extent.height,
            layers: s.app_layers.max(1),
            merged: u32::from(merged),
            table: self.table,
        };
        let codes = u64::from(s.extent.width) * u64::from(s.extent.height) * u64::from(s.layers);
        let groups =
            u32::try_from(codes.div_ceil(4).div_ceil(u64::from(GROUP))).unwrap_or(u32::MAX);
        let shadow_range = vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: 0,
            layer_count: s.layers,
        };
        let shadow_barrier = |old, new, src, dst| {
            vk::ImageMemoryBarrier::default()
                .src_access_mask(src)
                .dst_access_mask(dst)
                .old_layout(old)
                .new_layout(new)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .image(s.image)
                .subresource_range(shadow_range)
        };
        // SAFETY: the next layer's commands on the application's recording command buffer, with
        // the layer's own objects; outside a render pass, as the begin hooks are.
        unsafe {
            // 1. Whatever wrote the map comes before the dispatch reads it, and whatever read this
            // command buffer's code buffer (an earlier conversion's copy) before the dispatch
            // writes it (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#synchronization-dependencies>):
            // the application's own dependency into the density layout made its writes
            // available. The shadow's old content is discarded (UNDEFINED) once earlier passes'
            // shading-rate reads are done, ready for the copy. ALL_COMMANDS stands in for the
            // unknown writer and for the shading-rate stage, which validation 1.3.239 refuses
            // without NVIDIA's shading-rate-image feature (docs/vulkan-fdm-on-fsr.md#shadows).
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[vk::MemoryBarrier::default()
                    .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
                    .dst_access_mask(vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE)],
                &[],
                &[shadow_barrier(
                    vk::ImageLayout::UNDEFINED,
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                    vk::AccessFlags::empty(),
                    vk::AccessFlags::TRANSFER_WRITE,
                )],
            );
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, self.pipeline);
            d.cmd_bind_descriptor_sets(
                cb,
                vk::PipelineBindPoint::COMPUTE,
                self.layout,
                0,
                &[slot.set],
                &[],
            );
            d.cmd_push_constants(
                cb,
                self.layout,
                vk::ShaderStageFlags::COMPUTE,
                0,
                &push.bytes(),
            );
            d.cmd_dispatch(cb, groups, 1, 1);
            // 2. The codes, from the dispatch to the copy: exactly those stages.
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[vk::BufferMemoryBarrier::default()
                    .src_access_mask(vk::AccessFlags::SHADER_WRITE)
                    .dst_access_mask(vk::AccessFlags::TRANSFER_READ)
                    .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .buffer(slot.buffer)
                    .offset(0)
                    .size(vk::WHOLE_SIZE)],
                &[],
            );
            d.cmd_copy_buffer_to_image(
                cb,
                slot.buffer,
                s.image,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &[vk::BufferImageCopy {
                    buffer_offset: 0,
                    buffer_row_length: 0,
                    buffer_image_height: 0,
                    image_subresource: vk::ImageSubresourceLayers {
                        aspect_mask: vk::ImageAspectFlags::COLOR,
                        mip_level: 0,
                        base_array_layer: 0,
                        layer_count: s.layers,
                    },
                    image_offset: vk::Offset3D::default(),
                    image_extent: vk::Extent3D {
                        width: s.extent.width,
                        height: s.extent.height,
                        depth: 1,
                    },
                }],
            );
            // 3. The shadow, from the copy to the pass's shading-rate read (ALL_COMMANDS for the
            // shading-rate stage, as above).
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[shadow_barrier(
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                    SHADOW_LAYOUT,
                    vk::AccessFlags::TRANSFER_WRITE,
                    vk::AccessFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR,
                )],
            );
            restore(d, cb, &bound);
        }
        with_record(cb, |b| {
            b.converted.rotate_right(1);
            b.converted[0] = (image, epoch);
        });
        if let Some(((buffer, offset, flags), _, begin)) = suspend {
            let info = vk::ConditionalRenderingBeginInfoEXT::default()
                .buffer(buffer)
                .offset(offset)
                .flags(flags);
            // SAFETY: the application's condition again, as it began it.
            unsafe { begin(cb, &info) };
        }
        m.offsets.then_some((slot.shifts_at as usize, self.texel))
    }
}
