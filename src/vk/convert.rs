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
//! code buffer the command buffer owns (a slot of its
//! [`Conversion`](crate::vk::own::converter::Conversion)), a barrier from that dispatch to a copy of the
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
//! Objects ([`crate::vk::own::converter`] makes and destroys them): pipeline, layouts and
//! descriptor pools at device creation, owned by the device's record; per density image a sampled
//! view of it with its first view; per command buffer and map a code buffer and a descriptor set
//! at the command buffer's first conversion of the map, owned by the command buffer's record; all
//! destroyed with their owners. Nothing is
//! allocated per command in steady state, and no process-wide lock is taken while recording: each
//! thread finds its command buffers' records in a cache of its own ([`record_of`]).

use std::ffi::CStr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use ash::vk;
use ash::vk::Handle as _;

use crate::bridge::FdmEmulation;
use crate::vk::base::chain;
use crate::vk::base::ffi::{key, raw};
use crate::vk::own::calls::Own;
use crate::vk::own::convert_shader::{texel_shift, MAX_SHIFTS};
use crate::vk::own::converter::{filter_slot, write_shifts, Converter, Recorded, FILTER_WORDS};
use crate::vk::own::shadows::ShadowImage;
use crate::vk::registry::{self, forget_command_buffers_where, record_of, with_record, Device};

/// Runs `f` with `cb`'s share of its device's converter and the command buffer as a conversion
/// records into it, reached through the command buffer's record (this thread's cache: no
/// process-wide lock, no reference count), if the device converts.
fn with_conversion<R>(
    dev: &Device,
    cb: vk::CommandBuffer,
    f: impl FnOnce(&crate::vk::own::converter::Conversion, Recorded<'_>) -> R,
) -> Option<R> {
    record_of(cb, |r| {
        let at = Recorded {
            cb,
            bound: &r.bound,
            next: &dev.next,
        };
        r.conversion.as_ref().map(|c| f(c, at))
    })
    .flatten()
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

/// The converter of a device being created, where it emulates density maps with the layer's own
/// calls (`fdm`, `own`) and can record compute dispatches (`blocked`: why not, from
/// [`dispatch_blocked`]); else `None`, with the log saying why (its application-written maps then
/// render at full rate). The device's record owns it
/// ([`Emulation::converter`](crate::vk::registry::Emulation::converter)).
///
/// # Safety
/// `own` must belong to the live device `handle`, emulating as `fdm` says.
pub unsafe fn converter_for(
    handle: vk::Device,
    fdm: Option<&FdmEmulation>,
    own: Option<&Arc<Own>>,
    blocked: Option<&str>,
) -> Option<Arc<Converter>> {
    let (Some(fdm), Some(own)) = (fdm, own) else {
        return None;
    };
    if let Some(why) = blocked {
        tracing::warn!(
            device = raw(handle),
            why,
            "density maps the application writes itself are not converted on this device: they \
             render at full rate, and density-map offsets are not applied"
        );
        return None;
    }
    // SAFETY: the layer's own objects on a live device.
    match unsafe { Converter::new(Arc::clone(own), fdm) } {
        Ok(c) => Some(Arc::new(c)),
        Err(e) => {
            tracing::warn!(
                device = raw(handle),
                result = ?e,
                "no density-map conversion on this device: maps the application writes itself \
                 render at full rate, and density-map offsets are not applied"
            );
            None
        }
    }
}

/// Destroys a device's conversion objects; the device is about to be destroyed.
///
/// # Safety
/// `dev` must be live and idle.
pub unsafe fn device_destroyed(dev: &Device) {
    // SAFETY: as the caller promised.
    let Some(k) = (unsafe { key(dev.handle) }) else {
        return;
    };
    // Command buffers go with their device (and pools) without vkFreeCommandBuffers; their slots
    // go while the converter is still there.
    forget_command_buffers_where(|_, r| r.device == k);
    if let Some(c) = &dev.emulation.converter {
        // SAFETY: as the caller promised.
        unsafe { c.destroy() };
    }
}

/// A density image just got its shadow: an application's, or one of fovea's own created with
/// `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT` (`offsets`), whose passes may end with
/// offsets, which only a conversion in front of the pass can apply; its conversion objects are
/// made with its first view ([`view_changed`]).
///
/// # Safety
/// `app` must be the live image just created on `dev`, shadowed by `shadow`.
pub unsafe fn map_created(dev: &Device, app: vk::Image, shadow: &ShadowImage, offsets: bool) {
    if let Some(c) = &dev.emulation.converter {
        c.map_created(app, shadow, offsets);
    }
    if !crate::bridge::creating_own_density_images()
        && !dev.emulation.app_maps_logged.swap(true, Ordering::Relaxed)
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
    if let Some(c) = &dev.emulation.converter {
        // SAFETY: as the caller promised.
        unsafe { c.map_destroyed(app) };
    }
}

/// `vkBeginCommandBuffer` of a command buffer with record `r`: its slots of maps destroyed since
/// go ([`Conversion::begun`](crate::vk::own::converter::Conversion::begun)); in steady state one
/// atomic load.
pub fn begun(r: &registry::CbRecord) {
    if let Some(c) = &r.conversion {
        c.begun();
    }
}

/// Notes an application view of a density image (`Some`) or its destruction (`None`).
///
/// # Safety
/// `dev` must be live; `image` (where `Some`) a live image of it with memory.
pub unsafe fn view_changed(dev: &Device, view: vk::ImageView, image: Option<vk::Image>) {
    if let Some(c) = &dev.emulation.converter {
        // SAFETY: as the caller promised.
        unsafe { c.view_changed(view, image) };
    }
}

/// Notes a framebuffer of a rewritten pass and its density view (`Some`; `None` forgets it).
///
/// # Safety
/// `dev` must be live.
pub unsafe fn framebuffer_changed(dev: &Device, fb: vk::Framebuffer, view: Option<vk::ImageView>) {
    // Only converting devices' framebuffers are looked up at begin.
    if let Some(c) = &dev.emulation.converter {
        c.framebuffer_changed(fb, view);
    }
}

/// Forgets a destroyed framebuffer's density view (called by `pass::destroy_framebuffer`, after
/// the call went down).
pub fn framebuffer_destroyed(dev: &Device, fb: vk::Framebuffer) {
    if let Some(c) = &dev.emulation.converter {
        c.framebuffer_changed(fb, None);
    }
}

/// A filter of render passes that write or order density maps (see [`MAP_EPOCH`]): one bit per
/// hash slot, never cleared; a stale or shared bit only costs a conversion.
static WRITER_FILTER: [AtomicU64; FILTER_WORDS] = [const { AtomicU64::new(0) }; FILTER_WORDS];

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
    if let Some(c) = &dev.emulation.converter {
        c.pass_changed(pass, layouts);
    }
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
    // Only emulating devices convert (`converter_for`): on an injecting one nothing of the
    // conversion is looked at, however the pass is begun.
    let Some(c) = dev.emulation.converter.as_deref() else {
        return;
    };
    // SAFETY: as the caller promised.
    let Some(b) = (unsafe { begin.as_ref() }) else {
        return;
    };
    let (word, bit) = filter_slot(b.render_pass.as_raw());
    if WRITER_FILTER[word].load(Ordering::Acquire) & bit != 0 {
        map_may_have_changed();
    }
    let view = c.framebuffer_view(b.framebuffer);
    if view.is_none() && b.p_next.is_null() {
        return;
    }
    let Some(density) = dev.emulation.density_attachment(b.render_pass) else {
        return;
    };
    // SAFETY: as the caller promised.
    let Some(view) = view.or_else(|| unsafe { imageless_view(b, density) }) else {
        return;
    };
    let epoch = MAP_EPOCH.load(Ordering::Acquire);
    let shifts = with_conversion(dev, cb, |c, at| {
        // SAFETY: as the caller promised.
        unsafe { c.convert_for_pass(at, b.render_pass, view, epoch) }
    });
    opened(cb, shifts.flatten(), false);
}

/// The density view of a render pass begun on an imageless framebuffer: the begin info's
/// attachment `density`.
///
/// # Safety
/// `b` must be a valid begin info.
unsafe fn imageless_view(b: &vk::RenderPassBeginInfo<'_>, density: u32) -> Option<u64> {
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
    let epoch = MAP_EPOCH.load(Ordering::Acquire);
    let shifts = with_conversion(dev, cb, |c, at| {
        let view = f.image_view.as_raw();
        // SAFETY: as the caller promised.
        unsafe { c.convert_for_rendering(at, view, f.image_layout, epoch) }
    });
    opened(cb, shifts.flatten(), suspending);
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
static MAP_EPOCH: AtomicU64 = AtomicU64::new(1);

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
