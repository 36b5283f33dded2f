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

use crate::vk::base::chain::{self, ChainCopy};
use crate::vk::base::ffi::{guard, offset, once, pfn, raw, slice};
use crate::vk::registry::{self, Device};
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

/// The body of a command-buffer hook under [`guard`]: `body` gets the command buffer's device;
/// a command buffer the layer does not know is left alone.
///
/// # Safety
/// `cb` must be the caller's command buffer, valid as the command requires.
unsafe fn on_device(which: &'static str, cb: vk::CommandBuffer, body: impl FnOnce(&Device)) {
    guard(which, (), || {
        // SAFETY: as the caller promised.
        if let Some(dev) = unsafe { registry::device_ref(cb) } {
            body(&dev)
        }
    })
}

/// [`on_device`] where `body` also gets the next layer's function (`next` picks it from the
/// device's table); without one the command goes nowhere.
///
/// # Safety
/// As [`on_device`].
unsafe fn with_next<F>(
    which: &'static str,
    cb: vk::CommandBuffer,
    next: impl FnOnce(&Device) -> Option<F>,
    body: impl FnOnce(&Device, F),
) {
    // SAFETY: as the caller promised.
    unsafe {
        on_device(which, cb, |dev| {
            if let Some(down) = next(dev) {
                body(dev, down)
            }
        })
    }
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
    out: *mut vk::RenderPass,
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
            injection::create_injected(dev, inj, create2, pass, flags, p_next, alloc, out)
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
    let r = unsafe { create2(dev.handle, &info, alloc, out) };
    if r == vk::Result::SUCCESS && density == vk::ATTACHMENT_UNUSED {
        // A pass that names the density layout, stage or access but reads no map writes or
        // orders one.
        // SAFETY: just created.
        convert::writer_pass_created(unsafe { *out });
    }
    if r == vk::Result::SUCCESS && density != vk::ATTACHMENT_UNUSED && texel.is_some() {
        // SAFETY: just created.
        let handle = unsafe { *out };
        dev.emulation.passes.lock().insert(handle.as_raw(), density);
        // SAFETY: the device is live.
        unsafe { convert::pass_changed(dev, handle, layouts) };
        reconstruct::pass_created(dev, handle, &pass, density);
        tracing::debug!(
            render_pass = raw(handle),
            density,
            "render pass: density map → shading-rate attachment"
        );
    }
    r
}

/// `vkCreateRenderPass`: with the density-map struct, upgraded to `vkCreateRenderPass2` and
/// rewritten; on an injecting device every pass is (see [`injection::create_injected`]); otherwise untouched.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn create_render_pass(
    device: vk::Device,
    info: *const vk::RenderPassCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::RenderPass,
) -> vk::Result {
    guard(
        "vkCreateRenderPass",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let Some(dev) = (unsafe { registry::device(device) }) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let Some(next) = dev.next.create_render_pass else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            // SAFETY: the caller's create info, read only.
            let density = match unsafe { info.as_ref() } {
                // SAFETY: the caller's valid chain.
                Some(ci) if dev.fdm.is_some() => unsafe { density_attachment(ci.p_next) },
                _ => None,
            };
            let inject = dev.injection.is_some() && !info.is_null();
            // A pass without the density-map struct that still names the density layout, stage
            // or access (it writes a map, or orders one) goes down translated.
            // SAFETY: the caller's create info, read only.
            let ci = unsafe { info.as_ref() };
            // SAFETY: as above.
            let names = dev.fdm.is_some() && ci.is_some_and(|ci| unsafe { v1_names_density(ci) });
            let Some(density) = density.or((inject || names).then_some(vk::ATTACHMENT_UNUSED))
            else {
                // SAFETY: the next layer's function, with the caller's arguments.
                return unsafe { next(device, info, alloc, out) };
            };
            // Below Vulkan 1.2 the core name may not be called (drivers return no pointer for
            // it); the extension's, which the layer enabled, is the one.
            let (first, second) = (
                dev.next.create_render_pass2,
                dev.next.create_render_pass2_khr,
            );
            let create2 = if dev.api_version < vk::API_VERSION_1_2 {
                second.or(first)
            } else {
                first.or(second)
            };
            // SAFETY: as above.
            let ci = unsafe { &*info };
            use vk::StructureType as S;
            let folded = |t| {
                t == S::RENDER_PASS_FRAGMENT_DENSITY_MAP_CREATE_INFO_EXT
                    || t == S::RENDER_PASS_MULTIVIEW_CREATE_INFO
                    || t == S::RENDER_PASS_INPUT_ATTACHMENT_ASPECT_CREATE_INFO
            };
            // SAFETY: the caller's chain, read only.
            let (chain, multiview, aspects) = unsafe {
                (
                    chain_without(ci.p_next, folded, "vkCreateRenderPass"),
                    chain::find::<vk::RenderPassMultiviewCreateInfo>(
                        ci.p_next,
                        S::RENDER_PASS_MULTIVIEW_CREATE_INFO,
                    ),
                    chain::find::<vk::RenderPassInputAttachmentAspectCreateInfo>(
                        ci.p_next,
                        S::RENDER_PASS_INPUT_ATTACHMENT_ASPECT_CREATE_INFO,
                    ),
                )
            };
            // A chain too long to look through to its end has neither struct where the layer
            // looks; the copy shares what lies past its limit.
            let (multiview, aspects) = (multiview.ok().flatten(), aspects.ok().flatten());
            let (Some(create2), Ok(chain)) = (create2, chain) else {
                // Every emulating device has render pass 2 (the layer enables it), so this is an
                // injecting one: no density enums are valid on it anyway.
                tracing::warn!(
                    inject,
                    "vkCreateRenderPass: cannot upgrade a render pass to version 2 (no \
                     vkCreateRenderPass2 below, or a pNext chain the layer cannot copy); passed \
                     on as is, at full rate"
                );
                if dev.fdm.is_some() {
                    // A driver without the density-map extension must not get its enums; an
                    // unexpected failure is what any command may answer with VK_ERROR_UNKNOWN
                    // (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkResult.html>).
                    return vk::Result::ERROR_UNKNOWN;
                }
                // SAFETY: the next layer's function, with the caller's arguments.
                return unsafe { next(device, info, alloc, out) };
            };
            // SAFETY: the structs were found by their sTypes in the caller's valid chain.
            let pass = unsafe { v1_to_v2(ci, multiview.map(|m| &*m), aspects.map(|a| &*a)) };
            // SAFETY: the converted pass and the chain copy live across the call.
            unsafe {
                create_rewritten(
                    &dev,
                    create2,
                    pass,
                    ci.flags,
                    chain.head(),
                    density,
                    alloc,
                    out,
                )
            }
        },
    )
}

/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn create_render_pass2_with(
    which: &'static str,
    next: fn(&Device) -> Option<vk::PFN_vkCreateRenderPass2>,
    device: vk::Device,
    info: *const vk::RenderPassCreateInfo2<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::RenderPass,
) -> vk::Result {
    guard(which, vk::Result::ERROR_INITIALIZATION_FAILED, || {
        // SAFETY: as the caller promised.
        let Some(dev) = (unsafe { registry::device(device) }) else {
            return vk::Result::ERROR_INITIALIZATION_FAILED;
        };
        let Some(create2) = next(&dev) else {
            return vk::Result::ERROR_INITIALIZATION_FAILED;
        };
        // SAFETY: the caller's create info, read only.
        let density = match unsafe { info.as_ref() } {
            // SAFETY: the caller's valid chain.
            Some(ci) if dev.fdm.is_some() => unsafe { density_attachment(ci.p_next) },
            _ => None,
        };
        let inject = dev.injection.is_some() && !info.is_null();
        // As in `create_render_pass`: density enums outside the density-map struct.
        // SAFETY: the caller's create info, read only.
        let ci = unsafe { info.as_ref() };
        // SAFETY: as above.
        let names = dev.fdm.is_some() && ci.is_some_and(|ci| unsafe { v2_names_density(ci) });
        let Some(density) = density.or((inject || names).then_some(vk::ATTACHMENT_UNUSED)) else {
            // SAFETY: the next layer's function, with the caller's arguments.
            return unsafe { create2(device, info, alloc, out) };
        };
        // SAFETY: as above.
        let ci = unsafe { &*info };
        if let (Some(inj), vk::ATTACHMENT_UNUSED) = (&dev.injection, density) {
            // SAFETY: the caller's subpasses and their chains, read only.
            match unsafe { apps_rate_attachment(ci) } {
                Ok(false) => {}
                Ok(true) => {
                    inj.apps_own_attachment(which);
                    // SAFETY: the next layer's function, with the caller's arguments.
                    let r = unsafe { create2(device, info, alloc, out) };
                    if r == vk::Result::SUCCESS {
                        // SAFETY: just created.
                        inj.apps_pass_created(unsafe { *out });
                    }
                    return r;
                }
                Err(e) => {
                    tracing::warn!(
                        error = ?e,
                        "{which}: a subpass pNext chain the layer cannot read; passed on as is, \
                         at full rate"
                    );
                    // SAFETY: the next layer's function, with the caller's arguments.
                    return unsafe { create2(device, info, alloc, out) };
                }
            }
        }
        let fdm = vk::StructureType::RENDER_PASS_FRAGMENT_DENSITY_MAP_CREATE_INFO_EXT;
        // SAFETY: the caller's chain, read only.
        let Ok(chain) = (unsafe { chain_without(ci.p_next, |t| t == fdm, which) }) else {
            // `chain_without` leaves out what it cannot copy, so this is not expected; the
            // driver must not get the density-map struct all the same.
            tracing::warn!(
                "{which}: a pNext chain the layer cannot copy; the render pass is refused"
            );
            return vk::Result::ERROR_UNKNOWN;
        };
        // SAFETY: the caller's arrays outlive the call.
        let pass = unsafe { Pass2::from_v2(ci) };
        // SAFETY: the copied pass and chain live across the call.
        unsafe {
            create_rewritten(
                &dev,
                create2,
                pass,
                ci.flags,
                chain.head(),
                density,
                alloc,
                out,
            )
        }
    })
}

hook_and_khr_alias! {
    /// `vkCreateRenderPass2`: see the module documentation.
    create_render_pass2, create_render_pass2_khr = create_render_pass2_with("vkCreateRenderPass2")
    (
        device: vk::Device,
        info: *const vk::RenderPassCreateInfo2<'_>,
        alloc: *const vk::AllocationCallbacks<'_>,
        out: *mut vk::RenderPass,
    ) -> vk::Result
}

/// `vkDestroyRenderPass`: forgets a rewritten pass.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn destroy_render_pass(
    device: vk::Device,
    pass: vk::RenderPass,
    alloc: *const vk::AllocationCallbacks<'_>,
) {
    guard("vkDestroyRenderPass", (), || {
        // SAFETY: as the caller promised.
        let Some(dev) = (unsafe { registry::device(device) }) else {
            return;
        };
        dev.emulation.passes.lock().remove(&pass.as_raw());
        if let Some(inj) = &dev.injection {
            inj.pass_destroyed(pass);
        }
        // SAFETY: the device is live.
        unsafe { convert::pass_changed(&dev, pass, None) };
        // SAFETY: the device is live.
        unsafe { reconstruct::pass_destroyed(&dev, pass) };
        if let Some(next) = dev.next.destroy_render_pass {
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { next(device, pass, alloc) };
        }
    })
}

/// `vkCreateFramebuffer`: a rewritten pass's density view becomes its shadow view; an imageless
/// framebuffer describes the shadow instead.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn create_framebuffer(
    device: vk::Device,
    info: *const vk::FramebufferCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Framebuffer,
) -> vk::Result {
    guard(
        "vkCreateFramebuffer",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let Some(dev) = (unsafe { registry::device(device) }) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let Some(next) = dev.next.create_framebuffer else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            // SAFETY: the caller's create info, read only.
            let Some(ci) = (unsafe { info.as_ref() }) else {
                // SAFETY: the next layer's function, with the caller's arguments.
                return unsafe { next(device, info, alloc, out) };
            };
            if let (Some(inj), Some(own)) = (&dev.injection, &dev.own) {
                let Some(p) = inj.pass(ci.render_pass) else {
                    // SAFETY: as above.
                    return unsafe { next(device, info, alloc, out) };
                };
                // SAFETY: the caller's arguments; `own` is the device's.
                return unsafe {
                    injection::create_injected_framebuffer(
                        inj, own, p, next, device, ci, alloc, out,
                    )
                };
            }
            let Some(density) = dev.emulation.density_attachment(ci.render_pass) else {
                // SAFETY: as above.
                return unsafe { next(device, info, alloc, out) };
            };
            let mut copy = *ci;
            if ci.flags.contains(vk::FramebufferCreateFlags::IMAGELESS) {
                let ty = vk::StructureType::FRAMEBUFFER_ATTACHMENTS_CREATE_INFO;
                let found =
                    // SAFETY: the caller's chain, read only.
                    unsafe { chain::find::<vk::FramebufferAttachmentsCreateInfo>(ci.p_next, ty) };
                // SAFETY: as above.
                let rest = unsafe { ChainCopy::without(ci.p_next, |t| t == ty) };
                let (Ok(Some(found)), Ok(rest)) = (found, rest) else {
                    tracing::warn!(
                        "vkCreateFramebuffer: an imageless framebuffer the layer cannot rewrite; \
                         passed on as is"
                    );
                    // SAFETY: as above.
                    return unsafe { next(device, info, alloc, out) };
                };
                // SAFETY: found by its sType in a valid chain.
                let found = unsafe { &*found };
                // SAFETY: the caller's array.
                let mut infos: Vec<vk::FramebufferAttachmentImageInfo<'_>> = unsafe {
                    slice(
                        found.p_attachment_image_infos,
                        found.attachment_image_info_count,
                    )
                }
                .to_vec();
                let formats = [SHADOW_FORMAT];
                let layered = dev.fdm.as_ref().is_some_and(|f| f.layered);
                if let Some(a) = infos.get_mut(density as usize) {
                    *a = shadow_attachment_info(a, layered, &formats);
                }
                let mut attachments = *found;
                attachments.p_next = rest.head();
                attachments.attachment_image_info_count = infos.len() as u32;
                attachments.p_attachment_image_infos = infos.as_ptr();
                copy.p_next = &attachments as *const _ as *const c_void;
                // SAFETY: the copies live across the call.
                return unsafe { next(device, &copy, alloc, out) };
            }
            let mut views: Vec<vk::ImageView> =
                // SAFETY: the caller's array.
                unsafe { slice(ci.p_attachments, ci.attachment_count) }.to_vec();
            let app_view = views.get(density as usize).copied();
            if let Some(v) = views.get_mut(density as usize) {
                // A density view without a shadow (it could not be made) gets the device's
                // full-rate stand-in ([`crate::vk::own::calls::Own::full_rate_view`]).
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
            copy.p_attachments = views.as_ptr();
            // SAFETY: the copy and the views live across the call.
            let r = unsafe { next(device, &copy, alloc, out) };
            if r == vk::Result::SUCCESS && !out.is_null() {
                // SAFETY: the framebuffer was just created on the live device.
                unsafe { convert::framebuffer_changed(&dev, *out, app_view) };
                // SAFETY: as above, from the application's create info.
                unsafe { reconstruct::framebuffer_created(&dev, *out, ci) };
            }
            r
        },
    )
}

/// `vkDestroyFramebuffer` on an injecting device: forgets what the framebuffer got.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn destroy_framebuffer(
    device: vk::Device,
    fb: vk::Framebuffer,
    alloc: *const vk::AllocationCallbacks<'_>,
) {
    guard("vkDestroyFramebuffer", (), || {
        // SAFETY: as the caller promised.
        let Some(dev) = (unsafe { registry::device(device) }) else {
            return;
        };
        if let Some(inj) = &dev.injection {
            inj.framebuffer_destroyed(fb);
        }
        // SAFETY: the device is live.
        unsafe { reconstruct::framebuffer_destroyed(&dev, fb) };
        if let Some(next) = dev.next.destroy_framebuffer {
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { next(device, fb, alloc) };
        }
        convert::framebuffer_destroyed(&dev, fb);
    })
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

/// `vkCmdBeginRenderPass`: see [`begin_pass`].
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_begin_render_pass(
    cb: vk::CommandBuffer,
    begin: *const vk::RenderPassBeginInfo<'_>,
    contents: vk::SubpassContents,
) {
    let body = |dev: &Device, next: vk::PFN_vkCmdBeginRenderPass| {
        // SAFETY: as the caller promised; recorded before the pass begins.
        unsafe { convert::before_render_pass(dev, cb, begin) };
        // SAFETY: as the caller promised.
        unsafe { reconstruct::begin_render_pass(dev, cb, begin) };
        // SAFETY: the next layer's function, with the caller's arguments or a copy that lives
        // across the call.
        unsafe { begin_pass(dev, cb, begin, |b| next(cb, b, contents)) }
    };
    // SAFETY: as the caller promised.
    unsafe {
        with_next(
            "vkCmdBeginRenderPass",
            cb,
            |d| d.next.cmd_begin_render_pass,
            body,
        )
    }
}

/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn cmd_begin_render_pass2_with(
    which: &'static str,
    next: fn(&Device) -> Option<vk::PFN_vkCmdBeginRenderPass2>,
    cb: vk::CommandBuffer,
    begin: *const vk::RenderPassBeginInfo<'_>,
    subpass: *const vk::SubpassBeginInfo<'_>,
) {
    let body = |dev: &Device, next: vk::PFN_vkCmdBeginRenderPass2| {
        // SAFETY: as the caller promised; recorded before the pass begins.
        unsafe { convert::before_render_pass(dev, cb, begin) };
        // SAFETY: as the caller promised.
        unsafe { reconstruct::begin_render_pass(dev, cb, begin) };
        // SAFETY: as in cmd_begin_render_pass.
        unsafe { begin_pass(dev, cb, begin, |b| next(cb, b, subpass)) }
    };
    // SAFETY: as the caller promised.
    unsafe { with_next(which, cb, next, body) }
}

hook_and_khr_alias! {
    /// `vkCmdBeginRenderPass2`: see [`begin_pass`].
    cmd_begin_render_pass2, cmd_begin_render_pass2_khr =
        cmd_begin_render_pass2_with("vkCmdBeginRenderPass2")
    (
        cb: vk::CommandBuffer,
        begin: *const vk::RenderPassBeginInfo<'_>,
        subpass: *const vk::SubpassBeginInfo<'_>,
    )
}

/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn cmd_begin_rendering_with(
    which: &'static str,
    next: fn(&Device) -> Option<vk::PFN_vkCmdBeginRendering>,
    cb: vk::CommandBuffer,
    info: *const vk::RenderingInfo<'_>,
) {
    let body = |dev: &Device, next: vk::PFN_vkCmdBeginRendering| {
        // SAFETY: as the caller promised; recorded before rendering begins.
        unsafe { convert::before_rendering(dev, cb, info) };
        if let (Some(inj), Some(own)) = (&dev.injection, &dev.own) {
            // SAFETY: the caller's arguments; `own` is the device's.
            return unsafe { injection::begin_injected(inj, own, next, cb, info) };
        }
        // SAFETY: the caller's rendering info, read only.
        let ri = match unsafe { info.as_ref() } {
            Some(ri) if !ri.p_next.is_null() => ri,
            // SAFETY: the next layer's function, with the caller's arguments.
            _ => return unsafe { next(cb, info) },
        };
        let ty = vk::StructureType::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_INFO_EXT;
        // SAFETY: the caller's chain, read only.
        let found = unsafe {
            chain::find::<vk::RenderingFragmentDensityMapAttachmentInfoEXT>(ri.p_next, ty)
        };
        let (Ok(Some(found)), Some(texel)) = (found, texel_of(dev)) else {
            // SAFETY: as above.
            return unsafe { next(cb, info) };
        };
        // SAFETY: found by its sType.
        let view = unsafe { (*found).image_view };
        let shadow = (view != vk::ImageView::null())
            .then(|| dev.emulation.shadow_view(view))
            .flatten();
        if shadow.is_some() {
            // SAFETY: the caller's rendering info.
            unsafe { reconstruct::begin_rendering(dev, cb, ri, view) };
        }
        // The edited chain is built in per-thread scratch storage: no heap allocation per
        // command (docs/ARCHITECTURE.md, "Nothing per frame that can be done at creation").
        // SAFETY: the caller's chain, read only.
        unsafe {
            chain::with_removed(
                ri.p_next,
                |t| t == ty,
                |rest| {
                    let Ok(rest) = rest else {
                        tracing::warn!(
                            "{which}: a pNext chain the layer cannot copy; passed on as is"
                        );
                        return next(cb, info);
                    };
                    let mut rate = vk::RenderingFragmentShadingRateAttachmentInfoKHR::default()
                        .image_layout(SHADOW_LAYOUT)
                        .shading_rate_attachment_texel_size(texel);
                    rate.p_next = rest;
                    let mut copy = *ri;
                    match shadow {
                        Some(s) => {
                            rate.image_view = s;
                            copy.p_next = &rate as *const _ as *const c_void;
                        }
                        None => {
                            if view != vk::ImageView::null() {
                                tracing::debug!(
                                    view = raw(view),
                                    "{which}: the density view has no shadow; rendering at full \
                                     rate"
                                );
                            }
                            copy.p_next = rest;
                        }
                    }
                    // The copy and everything it points at live across the call.
                    next(cb, &copy)
                },
            )
        }
    };
    // SAFETY: as the caller promised.
    unsafe { with_next(which, cb, next, body) }
}

hook_and_khr_alias! {
    /// `vkCmdBeginRendering`: the density-map attachment becomes a shading-rate attachment.
    cmd_begin_rendering, cmd_begin_rendering_khr = cmd_begin_rendering_with("vkCmdBeginRendering")
    (cb: vk::CommandBuffer, info: *const vk::RenderingInfo<'_>)
}

/// The density-map offsets in an end info's chain (`VkRenderPassFragmentDensityMapOffsetEndInfoEXT`,
/// the QCOM struct under its EXT name), as a slice of the caller's array: empty where there are
/// none or the count is zero, which both mean offset (0, 0).
///
/// # Safety
/// `next` must be NULL or a valid chain; the slice must not outlive the caller's call.
unsafe fn offsets_in<'a>(next: *const c_void) -> &'a [vk::Offset2D] {
    // SAFETY: as the caller promised.
    let found = unsafe { chain::find::<offset::EndInfo<'_>>(next, offset::END_INFO) };
    // SAFETY: found by its sType in a valid chain.
    match found.ok().flatten().and_then(|p| unsafe { p.as_ref() }) {
        // SAFETY: the caller's array of `fragment_density_offset_count` offsets.
        Some(e) => unsafe {
            slice(
                e.p_fragment_density_offsets,
                e.fragment_density_offset_count,
            )
        },
        None => &[],
    }
}

/// Calls `f` with `next` less the offsets struct, which a driver without offsets must not get.
/// Where the chain cannot be copied (a struct of a type the layer does not know before the
/// offsets), `f` gets an empty chain, logged once: the specification lets nothing but the offsets
/// extend an end info (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkSubpassEndInfo.html>,
/// <https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderingEndInfoKHR.html>), so
/// the end itself is kept.
///
/// # Safety
/// `next` must be NULL or a valid chain.
unsafe fn without_offsets(which: &str, next: *const c_void, f: impl FnOnce(*const c_void)) {
    static LOGGED: AtomicBool = AtomicBool::new(false);
    // SAFETY: as the caller promised.
    unsafe {
        chain::with_removed(
            next,
            |t| t == offset::END_INFO,
            |rest| match rest {
                Ok(rest) => f(rest),
                Err(e) => {
                    once(
                        &LOGGED,
                        &format!(
                            "{which}: an end info's pNext chain with a struct the layer does not \
                             know ({e:?}): it goes down without a chain"
                        ),
                    );
                    f(std::ptr::null())
                }
            },
        )
    }
}

/// `vkCmdEndRenderPass2(KHR)`: the offsets of the last subpass's end
/// ([`convert::ended`]); the end goes down without their struct.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn cmd_end_render_pass2_with(
    which: &'static str,
    next: fn(&Device) -> Option<vk::PFN_vkCmdEndRenderPass2>,
    cb: vk::CommandBuffer,
    end: *const vk::SubpassEndInfo<'_>,
) {
    let body = |_: &Device, down: vk::PFN_vkCmdEndRenderPass2| {
        // SAFETY: the caller's end info, read only.
        let Some(e) = (unsafe { end.as_ref() }).filter(|e| !e.p_next.is_null()) else {
            convert::ended(cb, &[]);
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { down(cb, end) };
            reconstruct::ended(cb);
            return;
        };
        // SAFETY: the caller's chain, read only; the offsets live across the call.
        let offsets = unsafe { offsets_in(e.p_next) };
        convert::ended(cb, offsets);
        // SAFETY: as above.
        unsafe {
            without_offsets(which, e.p_next, |rest| {
                let mut copy = *e;
                copy.p_next = rest;
                down(cb, &copy)
            })
        }
        reconstruct::ended(cb);
    };
    // SAFETY: as the caller promised.
    unsafe { with_next(which, cb, next, body) }
}

hook_and_khr_alias! {
    /// `vkCmdEndRenderPass2`: see [`cmd_end_render_pass2_with`].
    cmd_end_render_pass2, cmd_end_render_pass2_khr =
        cmd_end_render_pass2_with("vkCmdEndRenderPass2")
    (cb: vk::CommandBuffer, end: *const vk::SubpassEndInfo<'_>)
}

/// `vkCmdEndRenderPass`: the end goes down, then the reconstruction its begin planned
/// ([`reconstruct::ended`], docs/reconstruction.md).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_end_render_pass(cb: vk::CommandBuffer) {
    let body = |_: &Device, down: vk::PFN_vkCmdEndRenderPass| {
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { down(cb) };
        reconstruct::ended(cb);
    };
    // SAFETY: as the caller promised.
    unsafe {
        with_next(
            "vkCmdEndRenderPass",
            cb,
            |d| d.next.cmd_end_render_pass,
            body,
        )
    }
}

/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn cmd_end_rendering_with(
    which: &'static str,
    next: fn(&Device) -> Option<vk::PFN_vkCmdEndRendering>,
    cb: vk::CommandBuffer,
) {
    let body = |_: &Device, down: vk::PFN_vkCmdEndRendering| {
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { down(cb) };
        reconstruct::ended(cb);
    };
    // SAFETY: as the caller promised.
    unsafe { with_next(which, cb, next, body) }
}

hook_and_khr_alias! {
    /// `vkCmdEndRendering`: as [`cmd_end_render_pass`]; a suspending end reconstructs nothing,
    /// the end after the instance's last resumption does.
    cmd_end_rendering, cmd_end_rendering_khr = cmd_end_rendering_with("vkCmdEndRendering")
    (cb: vk::CommandBuffer)
}

/// `vkCmdNextSubpass2(KHR)`: offsets at the end of a subpass other than the last are ignored
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderPassFragmentDensityMapOffsetEndInfoEXT.html>);
/// their struct is left out all the same.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn cmd_next_subpass2_with(
    which: &'static str,
    next: fn(&Device) -> Option<vk::PFN_vkCmdNextSubpass2>,
    cb: vk::CommandBuffer,
    begin: *const vk::SubpassBeginInfo<'_>,
    end: *const vk::SubpassEndInfo<'_>,
) {
    let body = |_: &Device, down: vk::PFN_vkCmdNextSubpass2| {
        // SAFETY: the caller's end info, read only.
        let Some(e) = (unsafe { end.as_ref() }).filter(|e| !e.p_next.is_null()) else {
            // SAFETY: the next layer's function, with the caller's arguments.
            return unsafe { down(cb, begin, end) };
        };
        // SAFETY: the caller's chain, read only.
        unsafe {
            without_offsets(which, e.p_next, |rest| {
                let mut copy = *e;
                copy.p_next = rest;
                down(cb, begin, &copy)
            })
        }
    };
    // SAFETY: as the caller promised.
    unsafe { with_next(which, cb, next, body) }
}

hook_and_khr_alias! {
    /// `vkCmdNextSubpass2`: see [`cmd_next_subpass2_with`].
    cmd_next_subpass2, cmd_next_subpass2_khr = cmd_next_subpass2_with("vkCmdNextSubpass2")
    (
        cb: vk::CommandBuffer,
        begin: *const vk::SubpassBeginInfo<'_>,
        end: *const vk::SubpassEndInfo<'_>,
    )
}

/// `vkCmdEndRendering2EXT` and `vkCmdEndRendering2KHR` (`VK_KHR_maintenance10`, where the driver
/// has it). On an emulating device: the offsets of the end ([`convert::ended`]); the end goes down
/// as `vkCmdEndRendering2KHR` without their struct where the driver has it, else as the plain
/// `vkCmdEndRendering`, which the end info's other structs cannot reach (the specification allows
/// none but the offsets,
/// <https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderingEndInfoKHR.html>).
/// Elsewhere (the hook handed out by `vkGetInstanceProcAddr` before the device was known) the
/// command goes down as it is, where the next layer has it.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn cmd_end_rendering2_with(
    which: &'static str,
    own: fn(&Device) -> Option<pfn::PFN_vkCmdEndRendering2KHR>,
    cb: vk::CommandBuffer,
    info: *const offset::RenderingEndInfo,
) {
    let body = |dev: &Device| {
        if dev.fdm.is_none() {
            if let Some(down) = own(dev) {
                // SAFETY: the next layer's function, with the caller's arguments.
                unsafe { down(cb, info) };
                reconstruct::ended(cb);
            }
            return;
        }
        // SAFETY: the caller's end info, read only.
        let next = unsafe { info.as_ref() }.map_or(std::ptr::null(), |i| i.p_next);
        // SAFETY: the caller's chain, read only; the offsets live across the call.
        convert::ended(cb, unsafe { offsets_in(next) });
        if let Some(down) = dev.next.cmd_end_rendering2_khr {
            if next.is_null() {
                // SAFETY: the next layer's function, with the caller's arguments.
                unsafe { down(cb, info) };
            } else {
                // SAFETY: the caller's chain, read only.
                unsafe {
                    without_offsets(which, next, |rest| {
                        let copy = offset::RenderingEndInfo {
                            s_type: offset::RENDERING_END_INFO,
                            p_next: rest,
                        };
                        down(cb, &copy)
                    })
                };
            }
            reconstruct::ended(cb);
            return;
        }
        if let Some(down) = dev.end_rendering {
            // SAFETY: the next layer's function, on the caller's command buffer.
            unsafe { down(cb) };
            reconstruct::ended(cb);
        }
    };
    // SAFETY: as the caller promised.
    unsafe { on_device(which, cb, body) }
}

/// `vkCmdEndRendering2EXT`: see [`cmd_end_rendering2_with`].
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_end_rendering2_ext(
    cb: vk::CommandBuffer,
    info: *const offset::RenderingEndInfo,
) {
    // SAFETY: the caller's arguments.
    unsafe {
        cmd_end_rendering2_with(
            "vkCmdEndRendering2EXT",
            |d| d.next.cmd_end_rendering2_ext,
            cb,
            info,
        )
    }
}

/// `vkCmdEndRendering2KHR`: see [`cmd_end_rendering2_with`].
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_end_rendering2_khr(
    cb: vk::CommandBuffer,
    info: *const offset::RenderingEndInfo,
) {
    // SAFETY: the caller's arguments.
    unsafe {
        cmd_end_rendering2_with(
            "vkCmdEndRendering2KHR",
            |d| d.next.cmd_end_rendering2_khr,
            cb,
            info,
        )
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
    use crate::vk::own::calls::{Clears, Own};
    use crate::vk::own::injector::{InjectedFramebuffer, InjectedPass, Injector};
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
