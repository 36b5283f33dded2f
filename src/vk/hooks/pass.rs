//! Render passes, framebuffers and dynamic rendering: the density-map attachment becomes a
//! shading-rate attachment that names the layer's shadow ([`crate::vk::emulation`]), or injection
//! adds one of its own ([`crate::vk::injection`]); the struct translation is
//! [`crate::vk::translate::render_pass`]'s.
//!
//! - `vkCreateFramebuffer`: the density view is replaced by its shadow view; for an imageless
//!   framebuffer the density attachment's
//!   [`VkFramebufferAttachmentImageInfo`](https://registry.khronos.org/vulkan/specs/latest/man/html/VkFramebufferAttachmentImageInfo.html)
//!   describes the shadow (format, usage, flags, layers), and `vkCmdBeginRenderPass(2)` swaps the
//!   view in `VkRenderPassAttachmentBeginInfo`. The shadow has the density image's extent, and
//!   both extensions ask the same of it: at least `ceil(framebuffer size / texel)` texels, with
//!   the density texel fixed to the shading-rate one (docs/vulkan-fdm-on-fsr.md#texel-size).
//! - `vkCmdBeginRendering(KHR)` with
//!   [`VkRenderingFragmentDensityMapAttachmentInfoEXT`](https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderingFragmentDensityMapAttachmentInfoEXT.html)
//!   gets a [`VkRenderingFragmentShadingRateAttachmentInfoKHR`](https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderingFragmentShadingRateAttachmentInfoKHR.html)
//!   with the shadow view instead.
//! - `vkCmdEndRenderPass2`, `vkCmdNextSubpass2`, `vkCmdEndRendering2EXT` (and
//!   `vkCmdEndRendering2KHR`): the density-map offsets of the end go to the conversion in front of
//!   the pass ([`crate::vk::convert::ended`]), their struct never to the driver
//!   (docs/vulkan-layer.md#density-map-offsets).
//!

use std::ffi::c_void;
use std::sync::atomic::AtomicBool;

use ash::vk;
use ash::vk::Handle as _;

use crate::vk::base::chain::{ChainCopy, Chained};
use crate::vk::base::ffi::{offset, once, pfn, raw, slice, Call, In, Out};
use crate::vk::own::injector::Injector;
use crate::vk::registry::Device;
use crate::vk::translate::formats::{SHADOW_FORMAT, SHADOW_LAYOUT};
use crate::vk::translate::render_pass::{
    add_shading_rate, apps_rate_attachment, chain_without, density_attachment, rate_store_op,
    shadow_attachment_info, v2_names_density, Pass2,
};
use crate::vk::translate::render_pass_v1::{v1_names_density, v1_to_v2};
use crate::vk::{convert, emulation, injection, reconstruct};

fn texel_of(dev: &Device) -> Option<vk::Extent2D> {
    dev.fdm.as_ref().map(|f| vk::Extent2D {
        width: f.texel[0],
        height: f.texel[1],
    })
}

/// Creates `pass` below, with the shading-rate attachment where `density` names one; on success
/// records the pass as rewritten.
///
/// # Safety
/// `pass` and `p_next` must be valid and outlive the call; the rest are the caller's arguments.
#[allow(clippy::too_many_arguments)]
unsafe fn create_rewritten(
    dev: &Device,
    create2: vk::PFN_vkCreateRenderPass2,
    mut pass: Pass2,
    flags: vk::RenderPassCreateFlags,
    p_next: *const c_void,
    density: u32,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: Out<'_, vk::RenderPass>,
) -> vk::Result {
    // Whether the application names the map in the density layout itself when the pass begins
    // (before the translation makes it `GENERAL`): `crate::vk::convert` relies on it.
    let density_initial = pass
        .attachments
        .get(density as usize)
        .is_some_and(|a| a.initial_layout == vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT);
    if dev.fdm.is_some() {
        // SAFETY: as the caller promised.
        unsafe { pass.without_density_enums() };
    }
    if let Some(inj) = &dev.injection {
        // SAFETY: as the caller promised.
        return unsafe {
            injection::create_injected(dev, inj, create2, pass, flags, p_next, alloc, out.raw())
        };
    }
    let texel = texel_of(dev);
    let layouts = pass
        .attachments
        .get(density as usize)
        .map(|a| (a.initial_layout, a.final_layout, density_initial));
    if let (Some(texel), true) = (texel, density != vk::ATTACHMENT_UNUSED) {
        add_shading_rate(&mut pass, density, texel, rate_store_op(dev.api_version));
    }
    let info = pass.info(flags, p_next);
    // SAFETY: the copy and everything it points at live across the call.
    let r = unsafe { create2(dev.handle, &info, alloc, out.raw()) };
    match (r, out.read()) {
        // A pass that names the density layout, stage or access but reads no map writes or
        // orders one.
        (vk::Result::SUCCESS, Some(handle)) if density == vk::ATTACHMENT_UNUSED => {
            convert::writer_pass_created(handle)
        }
        (vk::Result::SUCCESS, Some(handle)) if texel.is_some() => {
            rewritten_created(dev, handle, &pass, density, layouts)
        }
        _ => {}
    }
    r
}

/// Notes a render pass just created with its density attachment `density` turned into a
/// shading-rate attachment.
fn rewritten_created(
    dev: &Device,
    handle: vk::RenderPass,
    pass: &Pass2,
    density: u32,
    layouts: Option<(vk::ImageLayout, vk::ImageLayout, bool)>,
) {
    dev.emulation.passes.lock().insert(handle.as_raw(), density);
    // SAFETY: the device is live; the pass was just created on it.
    unsafe { convert::pass_changed(dev, handle, layouts) };
    reconstruct::pass_created(dev, handle, pass, density);
    tracing::debug!(
        render_pass = raw(handle),
        density,
        "render pass: density map → shading-rate attachment"
    );
}

/// The attachment a pass's rewrite is about: the density map's where the create info names one
/// on an emulating device (`density`), `VK_ATTACHMENT_UNUSED` where the pass is rewritten all the
/// same (every pass on an injecting device; on an emulating one, a pass that names the density
/// layout, stage or access without the struct: it writes a map, or orders one); `None` where it
/// goes down untouched.
fn rewritten_about(dev: &Device, density: Option<u32>, names_density: bool) -> Option<u32> {
    density.or((dev.injection.is_some() || names_density).then_some(vk::ATTACHMENT_UNUSED))
}

hook! {
    /// `vkCreateRenderPass`: with the density-map struct, upgraded to `vkCreateRenderPass2` and
    /// rewritten; on an injecting device every pass is (see [`injection::create_injected`]);
    /// otherwise untouched.
    create_render_pass = "vkCreateRenderPass";
    on device(device), next create_render_pass, fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    create_pass(
        device: val vk::Device,
        info: in vk::RenderPassCreateInfo<'_>,
        alloc: val *const vk::AllocationCallbacks<'_>,
        out: out vk::RenderPass,
    ) -> vk::Result
}

fn create_pass(
    c: Call<'_, Device, vk::PFN_vkCreateRenderPass, impl Fn() -> vk::Result>,
    _device: vk::Device,
    info: In<'_, vk::RenderPassCreateInfo<'_>>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: Out<'_, vk::RenderPass>,
) -> vk::Result {
    let dev = c.dev;
    let as_given = || c.as_given();
    let Some(ci) = info.get() else {
        return as_given();
    };
    let emulates = dev.fdm.is_some();
    // SAFETY: the application's create info, valid with its chain and arrays.
    let (density, names) = unsafe {
        (
            emulates.then(|| density_attachment(ci.p_next)).flatten(),
            emulates && v1_names_density(ci),
        )
    };
    let Some(density) = rewritten_about(dev, density, names) else {
        return as_given();
    };
    let Some((create2, chain, pass)) = upgraded(dev, info, ci) else {
        // Every emulating device has render pass 2 (the layer enables it), so this is an
        // injecting one: no density enums are valid on it anyway.
        tracing::warn!(
            inject = dev.injection.is_some(),
            "vkCreateRenderPass: cannot upgrade a render pass to version 2 (no \
             vkCreateRenderPass2 below, or a pNext chain the layer cannot copy); passed on as is, \
             at full rate"
        );
        if emulates {
            // A driver without the density-map extension must not get its enums; an unexpected
            // failure is what any command may answer with VK_ERROR_UNKNOWN
            // (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkResult.html>).
            return vk::Result::ERROR_UNKNOWN;
        }
        return as_given();
    };
    // SAFETY: the converted pass and the chain copy live across the call.
    unsafe {
        create_rewritten(
            dev,
            create2,
            pass,
            ci.flags,
            chain.head(),
            density,
            alloc,
            out,
        )
    }
}

/// A v1 create info upgraded to render pass 2: the next layer's `vkCreateRenderPass2` (below
/// Vulkan 1.2 the extension's, which the layer enabled: drivers return no pointer for the core
/// name), a copy of the chain without what version 2 folds into the pass, and the pass.
fn upgraded<'a>(
    dev: &Device,
    info: In<'a, vk::RenderPassCreateInfo<'a>>,
    ci: &'a vk::RenderPassCreateInfo<'a>,
) -> Option<(vk::PFN_vkCreateRenderPass2, ChainCopy, Pass2)> {
    let (first, second) = (
        dev.next.create_render_pass2,
        dev.next.create_render_pass2_khr,
    );
    let create2 = if dev.api_version < vk::API_VERSION_1_2 {
        second.or(first)
    } else {
        first.or(second)
    };
    use vk::StructureType as S;
    let folded = |t| {
        t == S::RENDER_PASS_FRAGMENT_DENSITY_MAP_CREATE_INFO_EXT
            || t == S::RENDER_PASS_MULTIVIEW_CREATE_INFO
            || t == S::RENDER_PASS_INPUT_ATTACHMENT_ASPECT_CREATE_INFO
    };
    // SAFETY: the application's chain, read only.
    let chain = unsafe { chain_without(ci.p_next, folded, "vkCreateRenderPass") };
    // A chain too long to look through to its end has neither struct where the layer looks; the
    // copy shares what lies past its limit.
    let multiview = info.find::<vk::RenderPassMultiviewCreateInfo>();
    let aspects = info.find::<vk::RenderPassInputAttachmentAspectCreateInfo>();
    let (Some(create2), Ok(chain)) = (create2, chain) else {
        return None;
    };
    let (multiview, aspects) = (multiview.ok().flatten(), aspects.ok().flatten());
    // SAFETY: the application's create info and arrays; the structs were found by their sTypes
    // in its chain.
    let pass = unsafe { v1_to_v2(ci, multiview, aspects) };
    Some((create2, chain, pass))
}

hook! {
    /// `vkCreateRenderPass2`: see the module documentation.
    create_render_pass2 = "vkCreateRenderPass2", create_render_pass2_khr = "vkCreateRenderPass2KHR";
    on device(device), next create_render_pass2 / create_render_pass2_khr,
    fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    create_pass2(
        device: val vk::Device,
        info: in vk::RenderPassCreateInfo2<'_>,
        alloc: val *const vk::AllocationCallbacks<'_>,
        out: out vk::RenderPass,
    ) -> vk::Result
}

fn create_pass2(
    c: Call<'_, Device, vk::PFN_vkCreateRenderPass2, impl Fn() -> vk::Result>,
    _device: vk::Device,
    info: In<'_, vk::RenderPassCreateInfo2<'_>>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: Out<'_, vk::RenderPass>,
) -> vk::Result {
    let (dev, create2, which) = (c.dev, c.next, c.name);
    let as_given = || c.as_given();
    let Some(ci) = info.get() else {
        return as_given();
    };
    let emulates = dev.fdm.is_some();
    // SAFETY: the application's create info, valid with its chain and arrays.
    let (density, names) = unsafe {
        (
            emulates.then(|| density_attachment(ci.p_next)).flatten(),
            emulates && v2_names_density(ci),
        )
    };
    let Some(density) = rewritten_about(dev, density, names) else {
        return as_given();
    };
    if let (Some(inj), vk::ATTACHMENT_UNUSED) = (&dev.injection, density) {
        if let Some(r) = apps_own(which, inj, ci, as_given, &out) {
            return r;
        }
    }
    let fdm = vk::StructureType::RENDER_PASS_FRAGMENT_DENSITY_MAP_CREATE_INFO_EXT;
    // SAFETY: the application's chain, read only.
    let Ok(chain) = (unsafe { chain_without(ci.p_next, |t| t == fdm, which) }) else {
        // `chain_without` leaves out what it cannot copy, so this is not expected; the driver
        // must not get the density-map struct all the same.
        tracing::warn!("{which}: a pNext chain the layer cannot copy; the render pass is refused");
        return vk::Result::ERROR_UNKNOWN;
    };
    // SAFETY: the application's arrays outlive the call; the copied pass and chain live across
    // the call down.
    unsafe {
        let pass = Pass2::from_v2(ci);
        create_rewritten(
            dev,
            create2,
            pass,
            ci.flags,
            chain.head(),
            density,
            alloc,
            out,
        )
    }
}

/// On an injecting device, a pass with the application's own shading-rate attachment, or with a
/// subpass chain the layer cannot read, goes down as it came (`as_given`): `Some` with its
/// result; `None` where the layer injects into it.
fn apps_own(
    which: &str,
    inj: &Injector,
    ci: &vk::RenderPassCreateInfo2<'_>,
    as_given: impl FnOnce() -> vk::Result,
    out: &Out<'_, vk::RenderPass>,
) -> Option<vk::Result> {
    // SAFETY: the application's subpasses and their chains, read only.
    match unsafe { apps_rate_attachment(ci) } {
        Ok(false) => None,
        Ok(true) => {
            inj.apps_own_attachment(which);
            let r = as_given();
            if let (vk::Result::SUCCESS, Some(pass)) = (r, out.read()) {
                inj.apps_pass_created(pass);
            }
            Some(r)
        }
        Err(e) => {
            tracing::warn!(
                error = ?e,
                "{which}: a subpass pNext chain the layer cannot read; passed on as is, at full \
                 rate"
            );
            Some(as_given())
        }
    }
}

hook! {
    /// `vkDestroyRenderPass`: forgets a rewritten pass.
    destroy_render_pass = "vkDestroyRenderPass";
    on device(device), maybe destroy_render_pass, fails(());
    destroy_pass(
        device: val vk::Device,
        pass: val vk::RenderPass,
        alloc: val *const vk::AllocationCallbacks<'_>,
    ) -> ()
}

fn destroy_pass(
    c: Call<'_, Device, Option<vk::PFN_vkDestroyRenderPass>, impl Fn()>,
    _device: vk::Device,
    pass: vk::RenderPass,
    _alloc: *const vk::AllocationCallbacks<'_>,
) {
    let dev = c.dev;
    dev.emulation.passes.lock().remove(&pass.as_raw());
    if let Some(inj) = &dev.injection {
        inj.pass_destroyed(pass);
    }
    // SAFETY: the device is live; the application's uses of the pass have ended.
    unsafe {
        convert::pass_changed(dev, pass, None);
        reconstruct::pass_destroyed(dev, pass);
    }
    // Where the next layer has it.
    c.as_given();
}

hook! {
    /// `vkCreateFramebuffer`: a rewritten pass's density view becomes its shadow view; an
    /// imageless framebuffer describes the shadow instead.
    create_framebuffer = "vkCreateFramebuffer";
    on device(device), next create_framebuffer, fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    framebuffer(
        device: val vk::Device,
        info: in vk::FramebufferCreateInfo<'_>,
        alloc: val *const vk::AllocationCallbacks<'_>,
        out: out vk::Framebuffer,
    ) -> vk::Result
}

fn framebuffer(
    c: Call<'_, Device, vk::PFN_vkCreateFramebuffer, impl Fn() -> vk::Result>,
    device: vk::Device,
    info: In<'_, vk::FramebufferCreateInfo<'_>>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: Out<'_, vk::Framebuffer>,
) -> vk::Result {
    let (dev, next) = (c.dev, c.next);
    let down = |ci: *const vk::FramebufferCreateInfo<'_>| {
        // SAFETY: the next layer's function, with the application's arguments or a copy of its
        // create info that lives across the call.
        unsafe { next(device, ci, alloc, out.raw()) }
    };
    let Some(ci) = info.get() else {
        return down(info.raw());
    };
    if let (Some(inj), Some(own)) = (&dev.injection, &dev.own) {
        let Some(p) = inj.pass(ci.render_pass) else {
            return down(info.raw());
        };
        // SAFETY: the application's arguments; `own` is the device's.
        return unsafe {
            injection::create_injected_framebuffer(inj, own, p, next, device, ci, alloc, out.raw())
        };
    }
    let Some(density) = dev.emulation.density_attachment(ci.render_pass) else {
        return down(info.raw());
    };
    if ci.flags.contains(vk::FramebufferCreateFlags::IMAGELESS) {
        return imageless(dev, info, ci, density, down);
    }
    with_shadow_view(dev, ci, density, down, &out)
}

/// An imageless framebuffer of a rewritten pass: the density attachment's
/// `VkFramebufferAttachmentImageInfo` describes the shadow (format, usage, flags, layers), on
/// copies of the struct and its array.
fn imageless(
    dev: &Device,
    info: In<'_, vk::FramebufferCreateInfo<'_>>,
    ci: &vk::FramebufferCreateInfo<'_>,
    density: u32,
    down: impl Fn(*const vk::FramebufferCreateInfo<'_>) -> vk::Result,
) -> vk::Result {
    let ty = vk::StructureType::FRAMEBUFFER_ATTACHMENTS_CREATE_INFO;
    let found = info.find::<vk::FramebufferAttachmentsCreateInfo>();
    let rest = info.without(|t| t == ty);
    let (Ok(Some(found)), Ok(rest)) = (found, rest) else {
        tracing::warn!(
            "vkCreateFramebuffer: an imageless framebuffer the layer cannot rewrite; passed on as is"
        );
        return down(info.raw());
    };
    // SAFETY: the command's valid usage: the struct's array of `attachmentImageInfoCount`
    // infos.
    let given = unsafe {
        slice(
            found.p_attachment_image_infos,
            found.attachment_image_info_count,
        )
    };
    let mut infos: Vec<vk::FramebufferAttachmentImageInfo<'_>> = given.to_vec();
    let formats = [SHADOW_FORMAT];
    let layered = dev.fdm.as_ref().is_some_and(|f| f.layered);
    if let Some(a) = infos.get_mut(density as usize) {
        *a = shadow_attachment_info(a, layered, &formats);
    }
    let mut attachments = *found;
    attachments.p_next = rest.head();
    attachments.attachment_image_info_count = infos.len() as u32;
    attachments.p_attachment_image_infos = infos.as_ptr();
    let mut copy = *ci;
    copy.p_next = &attachments as *const _ as *const c_void;
    down(&copy)
}

/// A framebuffer of a rewritten pass with views of its own: the density view goes down as its
/// shadow view (or, where it has none, the device's full-rate stand-in,
/// [`crate::vk::own::calls::Own::full_rate_view`]), on a copy of the array; what was made is noted
/// for the conversion and the reconstruction.
fn with_shadow_view(
    dev: &Device,
    ci: &vk::FramebufferCreateInfo<'_>,
    density: u32,
    down: impl Fn(*const vk::FramebufferCreateInfo<'_>) -> vk::Result,
    out: &Out<'_, vk::Framebuffer>,
) -> vk::Result {
    // SAFETY: the command's valid usage: `attachmentCount` views.
    let mut views = unsafe { slice(ci.p_attachments, ci.attachment_count) }.to_vec();
    let app_view = views.get(density as usize).copied();
    if let Some(v) = views.get_mut(density as usize) {
        let shadow = dev.emulation.shadow_view(*v).or_else(|| {
            let (own, fdm) = (dev.own.as_ref()?, dev.fdm.as_ref()?);
            // SAFETY: the device is live and emulates as `fdm` says.
            unsafe { own.full_rate_view(fdm, ci.width, ci.height) }
        });
        match shadow {
            Some(s) => *v = s,
            None => tracing::warn!(
                view = raw(*v),
                "vkCreateFramebuffer: the density view has no shadow; passed on as is"
            ),
        }
    }
    let mut copy = *ci;
    copy.p_attachments = views.as_ptr();
    let r = down(&copy);
    if let (vk::Result::SUCCESS, Some(fb)) = (r, out.read()) {
        // SAFETY: the framebuffer was just created on the live device from `ci`.
        unsafe {
            convert::framebuffer_changed(dev, fb, app_view);
            reconstruct::framebuffer_created(dev, fb, ci);
        }
    }
    r
}

hook! {
    /// `vkDestroyFramebuffer`: forgets what the framebuffer got.
    destroy_framebuffer = "vkDestroyFramebuffer";
    on device(device), maybe destroy_framebuffer, fails(());
    destroy_fb(
        device: val vk::Device,
        fb: val vk::Framebuffer,
        alloc: val *const vk::AllocationCallbacks<'_>,
    ) -> ()
}

fn destroy_fb(
    c: Call<'_, Device, Option<vk::PFN_vkDestroyFramebuffer>, impl Fn()>,
    _device: vk::Device,
    fb: vk::Framebuffer,
    _alloc: *const vk::AllocationCallbacks<'_>,
) {
    if let Some(inj) = &c.dev.injection {
        inj.framebuffer_destroyed(fb);
    }
    // SAFETY: the device is live; the application's uses of the framebuffer have ended.
    unsafe { reconstruct::framebuffer_destroyed(c.dev, fb) };
    // Where the next layer has it.
    c.as_given();
    convert::framebuffer_destroyed(c.dev, fb);
}

/// The begin a render pass goes down with: on an injecting device injection's
/// ([`injection::begin_injected_pass`]), else emulation's ([`emulation::with_swapped_begin`]);
/// `f` runs with it.
///
/// # Safety
/// `begin` must be NULL or valid.
unsafe fn begin_pass(
    dev: &Device,
    cb: vk::CommandBuffer,
    begin: *const vk::RenderPassBeginInfo<'_>,
    f: impl FnOnce(*const vk::RenderPassBeginInfo<'_>),
) {
    if let (Some(inj), Some(own)) = (&dev.injection, &dev.own) {
        // SAFETY: as the caller promised; `own` is the device's.
        return unsafe { injection::begin_injected_pass(inj, own, cb, begin, f) };
    }
    // SAFETY: as the caller promised.
    unsafe { emulation::with_swapped_begin(dev, begin, f) }
}

hook! {
    /// `vkCmdBeginRenderPass`: see [`begin_pass`].
    cmd_begin_render_pass = "vkCmdBeginRenderPass";
    on device_ref(cb), next cmd_begin_render_pass, fails(());
    begin_render_pass(
        cb: val vk::CommandBuffer,
        begin: val *const vk::RenderPassBeginInfo<'_>,
        contents: val vk::SubpassContents,
    ) -> ()
}

fn begin_render_pass(
    c: Call<'_, Device, vk::PFN_vkCmdBeginRenderPass, impl Fn()>,
    cb: vk::CommandBuffer,
    begin: *const vk::RenderPassBeginInfo<'_>,
    contents: vk::SubpassContents,
) {
    // SAFETY: the application's begin info, valid as the command requires: the conversion and
    // the reconstruction's plan are recorded before the pass begins, which goes down through the
    // next layer's function with that begin info or a copy that lives across the call.
    unsafe {
        convert::before_render_pass(c.dev, cb, begin);
        reconstruct::begin_render_pass(c.dev, cb, begin);
        begin_pass(c.dev, cb, begin, |b| (c.next)(cb, b, contents))
    }
}

hook! {
    /// `vkCmdBeginRenderPass2`: see [`begin_pass`].
    cmd_begin_render_pass2 = "vkCmdBeginRenderPass2",
        cmd_begin_render_pass2_khr = "vkCmdBeginRenderPass2KHR";
    on device_ref(cb), next cmd_begin_render_pass2 / cmd_begin_render_pass2_khr, fails(());
    begin_render_pass2(
        cb: val vk::CommandBuffer,
        begin: val *const vk::RenderPassBeginInfo<'_>,
        subpass: val *const vk::SubpassBeginInfo<'_>,
    ) -> ()
}

fn begin_render_pass2(
    c: Call<'_, Device, vk::PFN_vkCmdBeginRenderPass2, impl Fn()>,
    cb: vk::CommandBuffer,
    begin: *const vk::RenderPassBeginInfo<'_>,
    subpass: *const vk::SubpassBeginInfo<'_>,
) {
    // SAFETY: as in `begin_render_pass`.
    unsafe {
        convert::before_render_pass(c.dev, cb, begin);
        reconstruct::begin_render_pass(c.dev, cb, begin);
        begin_pass(c.dev, cb, begin, |b| (c.next)(cb, b, subpass))
    }
}

hook! {
    /// `vkCmdBeginRendering`: the density-map attachment becomes a shading-rate attachment.
    cmd_begin_rendering = "vkCmdBeginRendering", cmd_begin_rendering_khr = "vkCmdBeginRenderingKHR";
    on device_ref(cb), next cmd_begin_rendering / cmd_begin_rendering_khr, fails(());
    begin_rendering(cb: val vk::CommandBuffer, info: in vk::RenderingInfo<'_>) -> ()
}

fn begin_rendering(
    c: Call<'_, Device, vk::PFN_vkCmdBeginRendering, impl Fn()>,
    cb: vk::CommandBuffer,
    info: In<'_, vk::RenderingInfo<'_>>,
) {
    let (dev, next) = (c.dev, c.next);
    // SAFETY: the application's rendering info, valid as the command requires; recorded before
    // rendering begins.
    unsafe { convert::before_rendering(dev, cb, info.raw()) };
    if let (Some(inj), Some(own)) = (&dev.injection, &dev.own) {
        // SAFETY: the application's arguments; `own` is the device's.
        return unsafe { injection::begin_injected(inj, own, next, cb, info.raw()) };
    }
    // SAFETY: the next layer's function, with the application's rendering info or a copy that
    // lives across the call.
    let down = |i: *const vk::RenderingInfo<'_>| unsafe { next(cb, i) };
    let ri = match info.get() {
        Some(ri) if !ri.p_next.is_null() => ri,
        _ => return down(info.raw()),
    };
    let found = info.find::<vk::RenderingFragmentDensityMapAttachmentInfoEXT>();
    let (Ok(Some(found)), Some(texel)) = (found, texel_of(dev)) else {
        return down(info.raw());
    };
    let view = found.image_view;
    let shadow = (view != vk::ImageView::null())
        .then(|| dev.emulation.shadow_view(view))
        .flatten();
    if shadow.is_some() {
        // SAFETY: the application's rendering info.
        unsafe { reconstruct::begin_rendering(dev, cb, ri, view) };
    }
    let attachment = Rate {
        which: c.name,
        texel,
        view,
        shadow,
    };
    with_rate_attachment(info, ri, attachment, down)
}

/// The shading-rate attachment that stands in for a dynamic rendering's density map.
struct Rate {
    which: &'static str,
    texel: vk::Extent2D,
    /// The application's density view.
    view: vk::ImageView,
    /// Its shadow view; `None` renders at full rate.
    shadow: Option<vk::ImageView>,
}

/// Calls `down` with a copy of the rendering info whose chain has the density-map struct replaced
/// by a shading-rate attachment naming the shadow (left out where there is none). The edited
/// chain is built in per-thread scratch storage: no heap allocation per command
/// (docs/ARCHITECTURE.md, "Nothing per frame that can be done at creation").
fn with_rate_attachment(
    info: In<'_, vk::RenderingInfo<'_>>,
    ri: &vk::RenderingInfo<'_>,
    a: Rate,
    down: impl Fn(*const vk::RenderingInfo<'_>),
) {
    let ty = vk::StructureType::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_INFO_EXT;
    info.with_removed(
        |t| t == ty,
        |rest| {
            let Ok(rest) = rest else {
                tracing::warn!(
                    "{}: a pNext chain the layer cannot copy; passed on as is",
                    a.which
                );
                return down(info.raw());
            };
            let mut rate = vk::RenderingFragmentShadingRateAttachmentInfoKHR::default()
                .image_layout(SHADOW_LAYOUT)
                .shading_rate_attachment_texel_size(a.texel);
            rate.p_next = rest;
            let mut copy = *ri;
            match a.shadow {
                Some(s) => {
                    rate.image_view = s;
                    copy.p_next = &rate as *const _ as *const c_void;
                }
                None => {
                    if a.view != vk::ImageView::null() {
                        tracing::debug!(
                            view = raw(a.view),
                            "{}: the density view has no shadow; rendering at full rate",
                            a.which
                        );
                    }
                    copy.p_next = rest;
                }
            }
            // The copy and everything it points at live across the call.
            down(&copy)
        },
    )
}

/// The density-map offsets in an end info's chain (`VkRenderPassFragmentDensityMapOffsetEndInfoEXT`,
/// the QCOM struct under its EXT name), as a slice of the application's array: empty where there
/// are none or the count is zero, which both mean offset (0, 0).
fn offsets_in<'a, T: Chained>(end: In<'a, T>) -> &'a [vk::Offset2D] {
    match end.find::<offset::EndInfo<'a>>().ok().flatten() {
        // SAFETY: the command's valid usage: the struct's array of
        // `fragmentDensityOffsetCount` offsets.
        Some(e) => unsafe {
            slice(
                e.p_fragment_density_offsets,
                e.fragment_density_offset_count,
            )
        },
        None => &[],
    }
}

/// Calls `f` with the end info's chain less the offsets struct, which a driver without offsets
/// must not get. Where the chain cannot be copied (a struct of a type the layer does not know
/// before the offsets), `f` gets an empty chain, logged once: the specification lets nothing but
/// the offsets extend an end info
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkSubpassEndInfo.html>,
/// <https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderingEndInfoKHR.html>), so
/// the end itself is kept.
fn without_offsets<T: Chained>(which: &str, end: In<'_, T>, f: impl FnOnce(*const c_void)) {
    static LOGGED: AtomicBool = AtomicBool::new(false);
    end.with_removed(
        |t| t == offset::END_INFO,
        |rest| match rest {
            Ok(rest) => f(rest),
            Err(e) => {
                once(
                    &LOGGED,
                    &format!(
                        "{which}: an end info's pNext chain with a struct the layer does not                          know ({e:?}): it goes down without a chain"
                    ),
                );
                f(std::ptr::null())
            }
        },
    )
}

hook! {
    /// `vkCmdEndRenderPass2`: the offsets of the last subpass's end ([`convert::ended`]); the end
    /// goes down without their struct.
    cmd_end_render_pass2 = "vkCmdEndRenderPass2", cmd_end_render_pass2_khr = "vkCmdEndRenderPass2KHR";
    on device_ref(cb), next cmd_end_render_pass2 / cmd_end_render_pass2_khr, fails(());
    end_render_pass2(cb: val vk::CommandBuffer, end: in vk::SubpassEndInfo<'_>) -> ()
}

fn end_render_pass2(
    c: Call<'_, Device, vk::PFN_vkCmdEndRenderPass2, impl Fn()>,
    cb: vk::CommandBuffer,
    end: In<'_, vk::SubpassEndInfo<'_>>,
) {
    let Some(e) = end.get().filter(|e| !e.p_next.is_null()) else {
        convert::ended(cb, &[]);
        c.as_given();
        reconstruct::ended(cb);
        return;
    };
    convert::ended(cb, offsets_in(end));
    without_offsets(c.name, end, |rest| {
        let mut copy = *e;
        copy.p_next = rest;
        // SAFETY: the next layer's function; the copy lives across the call.
        unsafe { (c.next)(cb, &copy) }
    });
    reconstruct::ended(cb);
}

hook! {
    /// `vkCmdEndRenderPass`: the end goes down, then the reconstruction its begin planned
    /// ([`reconstruct::ended`], docs/reconstruction.md).
    cmd_end_render_pass = "vkCmdEndRenderPass";
    on device_ref(cb), next cmd_end_render_pass, fails(());
    end_render_pass(cb: val vk::CommandBuffer) -> ()
}

fn end_render_pass(
    c: Call<'_, Device, vk::PFN_vkCmdEndRenderPass, impl Fn()>,
    cb: vk::CommandBuffer,
) {
    c.as_given();
    reconstruct::ended(cb);
}

hook! {
    /// `vkCmdEndRendering`: as [`cmd_end_render_pass`]; a suspending end reconstructs nothing,
    /// the end after the instance's last resumption does.
    cmd_end_rendering = "vkCmdEndRendering", cmd_end_rendering_khr = "vkCmdEndRenderingKHR";
    on device_ref(cb), next cmd_end_rendering / cmd_end_rendering_khr, fails(());
    end_rendering(cb: val vk::CommandBuffer) -> ()
}

fn end_rendering(c: Call<'_, Device, vk::PFN_vkCmdEndRendering, impl Fn()>, cb: vk::CommandBuffer) {
    c.as_given();
    reconstruct::ended(cb);
}

hook! {
    /// `vkCmdNextSubpass2`: offsets at the end of a subpass other than the last are ignored
    /// (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderPassFragmentDensityMapOffsetEndInfoEXT.html>);
    /// their struct is left out all the same.
    cmd_next_subpass2 = "vkCmdNextSubpass2", cmd_next_subpass2_khr = "vkCmdNextSubpass2KHR";
    on device_ref(cb), next cmd_next_subpass2 / cmd_next_subpass2_khr, fails(());
    next_subpass2(
        cb: val vk::CommandBuffer,
        begin: val *const vk::SubpassBeginInfo<'_>,
        end: in vk::SubpassEndInfo<'_>,
    ) -> ()
}

fn next_subpass2(
    c: Call<'_, Device, vk::PFN_vkCmdNextSubpass2, impl Fn()>,
    cb: vk::CommandBuffer,
    begin: *const vk::SubpassBeginInfo<'_>,
    end: In<'_, vk::SubpassEndInfo<'_>>,
) {
    let Some(e) = end.get().filter(|e| !e.p_next.is_null()) else {
        return c.as_given();
    };
    without_offsets(c.name, end, |rest| {
        let mut copy = *e;
        copy.p_next = rest;
        // SAFETY: the next layer's function; the copy lives across the call.
        unsafe { (c.next)(cb, begin, &copy) }
    })
}

hook! {
    /// `vkCmdEndRendering2EXT` and `vkCmdEndRendering2KHR` (`VK_KHR_maintenance10`, where the
    /// driver has it). On an emulating device: the offsets of the end ([`convert::ended`]); the
    /// end goes down as `vkCmdEndRendering2KHR` without their struct where the driver has it, else
    /// as the plain `vkCmdEndRendering`, which the end info's other structs cannot reach (the
    /// specification allows none but the offsets,
    /// <https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderingEndInfoKHR.html>).
    /// Elsewhere (the hook handed out by `vkGetInstanceProcAddr` before the device was known) the
    /// command goes down as it is, where the next layer has it.
    cmd_end_rendering2_ext = "vkCmdEndRendering2EXT",
        cmd_end_rendering2_khr = "vkCmdEndRendering2KHR";
    on device_ref(cb), maybe cmd_end_rendering2_ext / cmd_end_rendering2_khr, fails(());
    end_rendering2(cb: val vk::CommandBuffer, info: in offset::RenderingEndInfo) -> ()
}

fn end_rendering2(
    c: Call<'_, Device, Option<pfn::PFN_vkCmdEndRendering2KHR>, impl Fn()>,
    cb: vk::CommandBuffer,
    info: In<'_, offset::RenderingEndInfo>,
) {
    let dev = c.dev;
    if dev.fdm.is_none() {
        if c.next.is_some() {
            c.as_given();
            reconstruct::ended(cb);
        }
        return;
    }
    convert::ended(cb, offsets_in(info));
    if let Some(down) = dev.next.cmd_end_rendering2_khr {
        if info.get().is_none_or(|i| i.p_next.is_null()) {
            // SAFETY: the next layer's function, with the application's arguments.
            unsafe { down(cb, info.raw()) };
        } else {
            without_offsets(c.name, info, |rest| {
                let copy = offset::RenderingEndInfo {
                    s_type: offset::RENDERING_END_INFO,
                    p_next: rest,
                };
                // SAFETY: the next layer's function; the copy lives across the call.
                unsafe { down(cb, &copy) }
            });
        }
        reconstruct::ended(cb);
        return;
    }
    if let Some(down) = dev.end_rendering {
        // SAFETY: the next layer's function, on the application's command buffer.
        unsafe { down(cb) };
        reconstruct::ended(cb);
    }
}

#[cfg(test)]
mod tests {
    use std::cell::Cell;
    use std::sync::Arc;

    use ash::vk::Handle as _;

    use super::*;
    use crate::bridge::inject;
    use crate::common::lock::{shared_taken, Mutex, Rank};
    use crate::vk::base::chain;
    use crate::vk::own::calls::{Clears, Own};
    use crate::vk::own::injector::{InjectedFramebuffer, InjectedPass, Injector};
    use crate::vk::registry;
    use fovea_model::inject::Views;

    thread_local! {
        /// The shading-rate view the last begin went down with (0: none).
        static WENT_DOWN_WITH: Cell<u64> = const { Cell::new(0) };
    }

    unsafe extern "system" fn no_gdpa(
        _: vk::Device,
        _: *const std::ffi::c_char,
    ) -> vk::PFN_vkVoidFunction {
        None
    }

    unsafe extern "system" fn set_loader_data(_: vk::Device, _: *mut c_void) -> vk::Result {
        vk::Result::SUCCESS
    }

    /// The driver's `vkCmdBeginRendering`: notes the shading-rate view chained on.
    unsafe extern "system" fn rendering_below(
        _: vk::CommandBuffer,
        info: *const vk::RenderingInfo<'_>,
    ) {
        let ty = vk::StructureType::RENDERING_FRAGMENT_SHADING_RATE_ATTACHMENT_INFO_KHR;
        // SAFETY: the layer's valid copy of the begin info.
        let found = unsafe {
            chain::find::<vk::RenderingFragmentShadingRateAttachmentInfoKHR<'_>>((*info).p_next, ty)
        };
        let found = found.ok().flatten();
        // SAFETY: found by its sType.
        let view = found.map_or(0, |f| unsafe { (*f).image_view.as_raw() });
        WENT_DOWN_WITH.with(|w| w.set(view));
    }

    /// The driver's `vkCmdBeginRenderPass2`: notes the last attachment view a begin names (the
    /// injected one of an imageless framebuffer), or 1 for a framebuffer with views of its own.
    unsafe extern "system" fn pass_below(
        _: vk::CommandBuffer,
        begin: *const vk::RenderPassBeginInfo<'_>,
        _: *const vk::SubpassBeginInfo<'_>,
    ) {
        let ty = vk::StructureType::RENDER_PASS_ATTACHMENT_BEGIN_INFO;
        // SAFETY: the layer's valid copy of the begin info.
        let next = unsafe { (*begin).p_next };
        // SAFETY: as above.
        let found = unsafe { chain::find::<vk::RenderPassAttachmentBeginInfo<'_>>(next, ty) };
        let view = match found.ok().flatten() {
            // SAFETY: found by its sType; its array of `attachment_count` views.
            Some(f) => unsafe { slice((*f).p_attachments, (*f).attachment_count) }
                .last()
                .map_or(0, |v| v.as_raw()),
            None => 1,
        };
        WENT_DOWN_WITH.with(|w| w.set(view));
    }

    /// Every begin an injecting device's recording threads make (DXVK's and vkd3d-proton's
    /// dynamic rendering into an eye target and into another target, vkd3d-proton's null-view
    /// shading-rate struct, a render pass with an eye framebuffer and one with an imageless
    /// framebuffer) takes no process-wide lock once its eye map exists: the count of this
    /// thread's process-wide lock acquisitions does not move over 100 rounds of them, while each
    /// begin still goes down with the map it must have.
    #[test]
    fn injecting_begins_take_no_process_wide_lock_in_steady_state() {
        let _one = inject::tests::STATE_TESTS.lock();
        let key_word = Box::new(0x7701usize);
        let handle = &*key_word as *const usize as u64;
        let cb = vk::CommandBuffer::from_raw(handle);
        let (eye_image, eye_view, other_view) = (0x5e1u64, 0x5e2u64, 0x5e3u64);
        let (map_view, eye_fb, imageless_fb, pass) = (0x3a9u64, 0xfb1u64, 0xfb2u64, 0xa55u64);
        let extent = [64, 64];
        inject::tests::start_high_square();
        inject::set_swapchain(
            1,
            fovea_model::inject::Swapchain {
                extent,
                layers: 1,
                holds: fovea_model::inject::Holds::View(0),
            },
            false,
        );
        inject::set_images(1, &[eye_image]);
        let inj = Injector::new(crate::bridge::FdmEmulation::nvidia_like());
        let colour = |image: u64, extent: [u32; 2]| {
            inj.image_created(
                vk::Image::from_raw(image),
                &vk::ImageCreateInfo::default()
                    .image_type(vk::ImageType::TYPE_2D)
                    .extent(vk::Extent3D {
                        width: extent[0],
                        height: extent[1],
                        depth: 1,
                    })
                    .array_layers(1)
                    .usage(vk::ImageUsageFlags::COLOR_ATTACHMENT),
            );
        };
        colour(eye_image, extent);
        // Not eye-shaped: another pass.
        colour(0x5e4, [100, 30]);
        let range = vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: 0,
            layer_count: 1,
        };
        for (view, image) in [(eye_view, eye_image), (other_view, 0x5e4)] {
            inj.view_created(
                vk::ImageView::from_raw(view),
                &vk::ImageViewCreateInfo::default()
                    .image(vk::Image::from_raw(image))
                    .subresource_range(range),
            );
        }
        let views = Views::Layers { first: 0, count: 1 };
        inject::with_current(|s| {
            let s = s.expect("injection is on");
            inj.seed(s, extent, views, vk::ImageView::from_raw(map_view), [4, 4]);
        });
        let injected = InjectedPass {
            rate: 1,
            colour: Some(0),
            view_mask: 0,
            targets: [None; crate::vk::translate::render_pass::MAX_TARGETS],
        };
        inj.pass_created(vk::RenderPass::from_raw(pass), injected);
        inj.framebuffer_created(
            vk::Framebuffer::from_raw(eye_fb),
            InjectedFramebuffer {
                pass: injected,
                extent,
                imageless: false,
                eye: Some((extent, views)),
                colour: None,
                targets: [None; crate::vk::translate::render_pass::MAX_TARGETS],
                layers: 1,
            },
        );
        inj.framebuffer_created(
            vk::Framebuffer::from_raw(imageless_fb),
            InjectedFramebuffer {
                pass: injected,
                extent,
                imageless: true,
                eye: None,
                colour: None,
                targets: [None; crate::vk::translate::render_pass::MAX_TARGETS],
                layers: 1,
            },
        );
        let device = vk::Device::from_raw(handle);
        // SAFETY: a table of functions that are never called (the loader's would return none).
        let fns = unsafe { ash::Device::load_with(|_| std::ptr::null(), device) };
        let own = Own {
            fns,
            memory: vk::PhysicalDeviceMemoryProperties::default(),
            set_loader_data,
            clears: Clears::new(Vec::new()),
            fallbacks: Mutex::ranked(Rank::Record, "test fallbacks", Vec::new()),
        };
        let next = crate::vk::base::next::DeviceNext {
            cmd_begin_rendering: Some(rendering_below),
            cmd_begin_render_pass2: Some(pass_below),
            ..Default::default()
        };
        let own = Arc::new(own);
        // SAFETY: the handle points at a word holding its key, alive for the test.
        unsafe {
            registry::add_device(Device {
                handle: vk::Device::from_raw(handle),
                instance: 0,
                gdpa: no_gdpa,
                next,
                end_rendering: None,
                fdm: None,
                api_version: vk::API_VERSION_1_3,
                own: Some(Arc::clone(&own)),
                emulation: registry::Emulation::new(None),
                injection: Some(inj),
                reconstructor: None,
                command_pools: Default::default(),
            });
        }

        let colour_att = |view: u64| {
            [vk::RenderingAttachmentInfo::default().image_view(vk::ImageView::from_raw(view))]
        };
        let (eye_att, other_att) = (colour_att(eye_view), colour_att(other_view));
        let null_rate = vk::RenderingFragmentShadingRateAttachmentInfoKHR::default();
        let rendering = |att: &[vk::RenderingAttachmentInfo<'_>], vkd3d: bool| {
            let mut info = vk::RenderingInfo::default()
                .layer_count(1)
                .color_attachments(att);
            if vkd3d {
                info.p_next = &null_rate as *const _ as *const c_void;
            }
            // SAFETY: a valid rendering info on the test's command buffer.
            unsafe { cmd_begin_rendering(cb, &info) };
            WENT_DOWN_WITH.with(Cell::get)
        };
        let begin_views = [vk::ImageView::from_raw(eye_view)];
        let attachments = vk::RenderPassAttachmentBeginInfo::default().attachments(&begin_views);
        let render_pass = |fb: u64, imageless: bool| {
            let mut begin = vk::RenderPassBeginInfo::default()
                .render_pass(vk::RenderPass::from_raw(pass))
                .framebuffer(vk::Framebuffer::from_raw(fb));
            if imageless {
                begin.p_next = &attachments as *const _ as *const c_void;
            }
            let subpass = vk::SubpassBeginInfo::default();
            // SAFETY: a valid begin info on the test's command buffer.
            unsafe { cmd_begin_render_pass2(cb, &begin, &subpass) };
            WENT_DOWN_WITH.with(Cell::get)
        };
        let round = || {
            [
                rendering(&eye_att, false),
                rendering(&other_att, false),
                rendering(&eye_att, true),
                render_pass(eye_fb, false),
                render_pass(imageless_fb, true),
            ]
        };
        let want = [map_view, 0, map_view, 1, map_view];
        assert_eq!(round(), want, "the first begins (their look-ups made)");
        let before = shared_taken();
        for i in 0..100 {
            assert_eq!(round(), want, "round {i}");
        }
        let taken = shared_taken() - before;
        // A new published pattern: the next begins decide again, and the eye map is refilled
        // (its bytes staged for the next submit) before it goes down again.
        let uploads = || own.clears.state.lock().dirty_uploads();
        assert_eq!(uploads(), 0);
        inject::set_pattern(
            fovea_model::density::Pattern {
                level: fovea_model::density::Level::Low,
                vertical_offset_deg: 0.0,
            },
            false,
            4,
        );
        assert_eq!(round(), want, "after the pattern changed");
        assert_eq!(uploads(), 1, "the eye map is refilled for the new pattern");
        // SAFETY: nothing is in flight; the device is the test's.
        unsafe { own.clears.destroy(&own.fns) };
        // SAFETY: no call on the device runs.
        drop(unsafe { registry::remove_device(vk::Device::from_raw(handle)) });
        inject::stop();
        assert_eq!(
            taken, 0,
            "process-wide locks taken by 500 begins on an injecting device in steady state"
        );
    }
}
