//! Reconstruction of coarse blocks (docs/reconstruction.md): after an eye pass on a device with
//! shading-rate attachments from fovea, each coarse block of its colour target becomes what a
//! compositor's bilinear sample of a subsampled image gives, and full-rate texels stay as they
//! are. Where the pass begins, `crate::vk::injection` notes what its end reconstructs in the
//! command buffer's record ([`Plan`](crate::vk::own::reconstructor::Plan)); the end hooks call
//! [`ended`] after the end went down, which records the copies and the dispatch
//! ([`Reconstructor::record`]).
//!
//! Objects: the pipeline and layouts at device creation ([`reconstructor_for`]), owned by the
//! device's record; scratch buffers at
//! the first pass of a target size, kept with the device. Per end of a pass that reconstructs
//! nothing: one atomic load while no command buffer of the process has a plan open
//! ([`registry::OPEN_PLANS`]), else the command buffer's record (this thread's cache) and one
//! uncontended lock of its own; no allocation and no process-wide lock.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use ash::vk;
use ash::vk::Handle as _;

use crate::bridge::FdmEmulation;
use crate::vk::base::chain;
use crate::vk::base::ffi::{raw, slice};
use crate::vk::own::calls::Own;
use crate::vk::own::reconstructor::{
    rate_layers, Colour, FramebufferTargets, PassTarget, Plan, Reconstructor, Target,
};
use crate::vk::registry::{self, record_of, Device};
use crate::vk::translate::render_pass::{
    pass_colours, pass_view_mask, rendering_target, too_many_targets, Pass2, MAX_TARGETS,
};

/// The reconstructor of a device being created that injects shading-rate maps or emulates density
/// maps (`fdm`: how) with the layer's own calls `own`, or `None` with the log saying why.
/// `why_not`: why the device cannot record compute dispatches into the application's command
/// buffers and give its bindings back (`crate::vk::convert::dispatch_blocked`). The device's
/// record owns it ([`Device::reconstructor`]). `ci`, the application's create info, and
/// `api_version` decide whether its views need the added usage hidden ([`hide_added_usage`]),
/// which the bridge is told.
///
/// # Safety
/// `own` must belong to the live device `handle`; `ci` must be the application's valid create
/// info.
pub unsafe fn reconstructor_for(
    handle: vk::Device,
    fdm: Option<&FdmEmulation>,
    own: Option<&Arc<Own>>,
    why_not: Option<&str>,
    ci: &vk::DeviceCreateInfo<'_>,
    api_version: u32,
) -> Option<Arc<Reconstructor>> {
    crate::bridge::subsampled::set_hides_usage(handle.as_raw(), false);
    let (Some(fdm), Some(own)) = (fdm, own) else {
        return None;
    };
    if let Some(why) = why_not {
        tracing::info!(
            device = raw(handle),
            why,
            "coarse blocks are not reconstructed on this device"
        );
        return None;
    }
    // SAFETY: the layer's own objects on a live device.
    match unsafe { Reconstructor::new(Arc::clone(own), fdm) } {
        Ok(mut r) => {
            // SAFETY: as the caller promised.
            r.imageless = unsafe { enables_imageless(ci) };
            crate::bridge::subsampled::set_hides_usage(
                handle.as_raw(),
                hides_usage(api_version, r.imageless),
            );
            Some(Arc::new(r))
        }
        Err(e) => {
            tracing::warn!(
                device = raw(handle),
                result = ?e,
                "coarse blocks are not reconstructed on this device: its objects could not be made"
            );
            None
        }
    }
}

/// Whether a device created from `ci` enables `imagelessFramebuffer` (Vulkan 1.2's features, or
/// `VK_KHR_imageless_framebuffer`'s): only such an application names a view's usage that added
/// usage could contradict (VUID-VkRenderPassBeginInfo-framebuffer-04627).
///
/// # Safety
/// `ci` must be a valid create info.
unsafe fn enables_imageless(ci: &vk::DeviceCreateInfo<'_>) -> bool {
    let v12 = vk::StructureType::PHYSICAL_DEVICE_VULKAN_1_2_FEATURES;
    let ext = vk::StructureType::PHYSICAL_DEVICE_IMAGELESS_FRAMEBUFFER_FEATURES;
    // SAFETY: the caller's chain, read only; a node found by its sType is that struct.
    unsafe {
        let core = chain::find::<vk::PhysicalDeviceVulkan12Features<'_>>(ci.p_next, v12)
            .ok()
            .flatten()
            .is_some_and(|f| (*f).imageless_framebuffer == vk::TRUE);
        let own = chain::find::<vk::PhysicalDeviceImagelessFramebufferFeatures<'_>>(ci.p_next, ext)
            .ok()
            .flatten()
            .is_some_and(|f| (*f).imageless_framebuffer == vk::TRUE);
        core || own
    }
}

/// Whether the layer hides added usage from the application's views on a device of `api_version`
/// whose application enabled imageless framebuffers or not: where they are enabled (nobody else
/// can tell a view's usage from its image's), from Vulkan 1.1 (`VkImageViewUsageCreateInfo`).
fn hides_usage(api_version: u32, imageless: bool) -> bool {
    imageless && api_version >= vk::API_VERSION_1_1
}

/// Destroys a device's reconstruction objects; the device is about to be destroyed, and its
/// command buffers' records are gone.
///
/// # Safety
/// `dev` must be live and idle.
pub unsafe fn device_destroyed(dev: &Device) {
    crate::bridge::subsampled::set_hides_usage(dev.handle.as_raw(), false);
    if let Some(r) = &dev.reconstructor {
        // SAFETY: as the caller promised.
        unsafe { r.destroy() };
    }
}

/// The end of a render pass instance just went down in `cb` (`vkCmdEndRenderPass(2)`,
/// `vkCmdEndRendering(2)`): where its begin planned a reconstruction and the end is not a
/// suspending one, it is recorded now.
pub fn ended(cb: vk::CommandBuffer) {
    if registry::OPEN_PLANS.load(Ordering::Acquire) == 0 {
        return;
    }
    record_of(cb, |r| {
        let Some(rc) = r.reconstructor.as_deref() else {
            return;
        };
        if r.plan.lock().is_none_or(|p| p.suspending) {
            return;
        }
        let Some(plan) = registry::take_plan(r) else {
            return;
        };
        let bound = Some(*r.bound.lock()).filter(|b| !b.lost);
        // SAFETY: `cb` is recording outside a render pass (its instance just ended), on the
        // reconstructor's device; `bound` is its bindings.
        unsafe { rc.record(cb, &plan, bound.as_ref()) };
    });
}

// ---------------------------------------------------------------------------------------------
// Emulating devices: the application's subsampled images and the passes that render them.

/// Runs `f` with the reconstructor of an emulating device, if it has one.
fn with_reconstructor<R>(dev: &Device, f: impl FnOnce(&Reconstructor) -> R) -> Option<R> {
    dev.fdm.as_ref()?;
    dev.reconstructor.as_deref().map(f)
}

/// The usage an application's colour image created with `VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT` on an
/// emulating device gets on the copy of its create info that goes down: its own and the copies'
/// (`TRANSFER_SRC`, `TRANSFER_DST`); `None` for any other image, and for one with external memory,
/// whose usage must stay what the other side of the memory expects (said once).
///
/// # Safety
/// `ci` must be a valid create info.
pub unsafe fn subsampled_usage(
    dev: &Device,
    ci: &vk::ImageCreateInfo<'_>,
) -> Option<vk::ImageUsageFlags> {
    static LOGGED: AtomicBool = AtomicBool::new(false);
    if !ci.flags.contains(vk::ImageCreateFlags::SUBSAMPLED_EXT)
        || !ci.usage.contains(vk::ImageUsageFlags::COLOR_ATTACHMENT)
    {
        return None;
    }
    with_reconstructor(dev, |_| ())?;
    let ty = vk::StructureType::EXTERNAL_MEMORY_IMAGE_CREATE_INFO;
    // SAFETY: the caller's chain, read only.
    let external = unsafe { chain::find::<vk::ExternalMemoryImageCreateInfo<'_>>(ci.p_next, ty) };
    if !matches!(external, Ok(None)) {
        if !LOGGED.swap(true, Ordering::Relaxed) {
            tracing::warn!(
                "a subsampled colour image with external memory (or a chain the layer cannot \
                 read): its coarse blocks are not reconstructed, its usage stays the application's"
            );
        }
        return None;
    }
    Some(ci.usage | vk::ImageUsageFlags::TRANSFER_SRC | vk::ImageUsageFlags::TRANSFER_DST)
}

/// An image was created on a device that reconstructs, from the application's create info `ci`
/// (`r`: what the creation returned, `out`: where it wrote the image). `subsampled`: for an image
/// the application created subsampled, the usage the layer added on the copy that went down
/// ([`subsampled_usage`]; `None` where the create info went down with the application's usage).
/// Two facts are kept: an image the application created subsampled is reconstructed (with its
/// layers); and, on a device with imageless framebuffers, a colour image with transfer usage (the
/// runtime's swapchain images, whose transfer usage the OpenXR side may have added) keeps its
/// usage, so that its views can be given the application's ([`hide_added_usage`]).
///
/// # Safety
/// `dev` must be live; `out` and `ci` NULL or valid.
pub unsafe fn image_made(
    dev: &Device,
    r: vk::Result,
    out: *const vk::Image,
    ci: *const vk::ImageCreateInfo<'_>,
    subsampled: Option<vk::ImageUsageFlags>,
) {
    if r != vk::Result::SUCCESS || out.is_null() || ci.is_null() {
        return;
    }
    // SAFETY: as the caller promised.
    let (image, ci) = unsafe { ((*out).as_raw(), &*ci) };
    let added = subsampled.unwrap_or_default();
    let usage = ci.usage | added;
    let transfer = vk::ImageUsageFlags::TRANSFER_SRC | vk::ImageUsageFlags::TRANSFER_DST;
    let colour = usage.contains(vk::ImageUsageFlags::COLOR_ATTACHMENT);
    if subsampled.is_none() && (!colour || !usage.intersects(transfer)) {
        return;
    }
    with_any_reconstructor(dev, |r| {
        let mut t = r.tables.lock();
        if subsampled.is_some() {
            t.images.insert(image, ci.array_layers.max(1));
        }
        if r.imageless {
            t.usage.insert(image, (usage, added));
        }
    });
}

/// # Safety
/// `dev` must be live.
pub unsafe fn image_destroyed(dev: &Device, image: vk::Image) {
    with_any_reconstructor(dev, |r| {
        let mut t = r.tables.lock();
        t.images.remove(&image.as_raw());
        t.usage.remove(&image.as_raw());
    });
}

/// Runs `f` with the reconstructor of a device that emulates or injects, if it has one.
fn with_any_reconstructor<R>(dev: &Device, f: impl FnOnce(&Reconstructor) -> R) -> Option<R> {
    dev.reconstructor.as_deref().map(f)
}

/// `vkCreateImageView` of an image whose usage fovea widened for reconstruction (the OpenXR side's
/// transfer usage on a swapchain image, [`crate::bridge::subsampled::added_usage`], or the layer's
/// on an application's subsampled image, [`subsampled_usage`]): a copy of `ci` (NULL or the
/// create info going down) with `slot` in front of its chain, a `VkImageViewUsageCreateInfo`
/// naming the usage the application gave the image, so the view's usage is what the application
/// believes it is. An application's imageless framebuffer names that usage for each attachment,
/// and it must equal the view's at each begin (VUID-VkRenderPassBeginInfo-framebuffer-04627):
/// docs/reconstruction.md#usage-the-application-does-not-see. The copies reconstruction records
/// name the image, whose usage has the transfer bits; a view never needs them.
///
/// `None` (the create info goes down as it is) for any other image, on a device whose application
/// did not enable imageless framebuffers (nothing there compares a view's usage with what the
/// application believes), where the application chained a `VkImageViewUsageCreateInfo` itself
/// (its usage is then the one it names), on a device below
/// Vulkan 1.1 (where that struct is `VK_KHR_maintenance2`'s; such a device's imageless
/// framebuffers keep the mismatch, said once), and for a swapchain image the layer did not see
/// created (its usage unknown; said once).
///
/// # Safety
/// `dev` must be live; `ci` NULL or valid.
pub unsafe fn hide_added_usage<'a>(
    dev: &Device,
    ci: *const vk::ImageViewCreateInfo<'a>,
    slot: &'a mut vk::ImageViewUsageCreateInfo<'a>,
) -> Option<vk::ImageViewCreateInfo<'a>> {
    static LOGGED: AtomicBool = AtomicBool::new(false);
    // SAFETY: as the caller promised.
    let ci = unsafe { ci.as_ref() }?;
    let image = ci.image.as_raw();
    let (usage, own) = with_any_reconstructor(dev, |r| {
        r.imageless.then(|| {
            r.tables
                .lock()
                .usage
                .get(&image)
                .copied()
                .unwrap_or_default()
        })
    })
    .flatten()?;
    let added = own | crate::bridge::subsampled::added_usage(image);
    if added.is_empty() {
        return None;
    }
    let ty = vk::StructureType::IMAGE_VIEW_USAGE_CREATE_INFO;
    // SAFETY: the caller's chain, read only.
    let apps = unsafe { chain::find::<vk::ImageViewUsageCreateInfo<'_>>(ci.p_next, ty) };
    if !matches!(apps, Ok(None)) {
        return None;
    }
    if usage.is_empty() || !hides_usage(dev.api_version, true) {
        if !LOGGED.swap(true, Ordering::Relaxed) {
            tracing::warn!(
                image = image,
                "a view of an image with the transfer usage reconstruction added keeps that usage                  (the layer did not see the image created, or the device is below Vulkan 1.1): an                  imageless framebuffer that names the application's usage for it does not match"
            );
        }
        return None;
    }
    slot.usage = usage & !added;
    slot.p_next = ci.p_next;
    Some(vk::ImageViewCreateInfo {
        p_next: (slot as *const vk::ImageViewUsageCreateInfo<'a>).cast(),
        ..*ci
    })
}

/// A view was created on an emulating device: where its image is reconstructed (the OpenXR side
/// published so for a swapchain image, or the application created it subsampled), it is noted
/// with its layers and format.
///
/// # Safety
/// `dev` must be live.
pub unsafe fn view_created(dev: &Device, view: vk::ImageView, ci: &vk::ImageViewCreateInfo<'_>) {
    with_reconstructor(dev, |r| {
        let image = ci.image.as_raw();
        let mut t = r.tables.lock();
        let own_layers = t.images.get(&image).copied();
        let reconstruct = match crate::bridge::subsampled::published(image) {
            Some(decided) => decided,
            None => own_layers.is_some(),
        };
        if !reconstruct {
            return;
        }
        let range = ci.subresource_range;
        let layers = if range.layer_count == vk::REMAINING_ARRAY_LAYERS {
            own_layers.map_or(1, |l| l.saturating_sub(range.base_array_layer).max(1))
        } else {
            range.layer_count
        };
        t.views.insert(
            view.as_raw(),
            Target {
                image: ci.image,
                base_layer: range.base_array_layer,
                layers,
                format: ci.format,
            },
        );
        r.any.store(true, Ordering::Release);
    });
}

/// # Safety
/// `dev` must be live.
pub unsafe fn view_destroyed(dev: &Device, view: vk::ImageView) {
    with_reconstructor(dev, |r| r.tables.lock().views.remove(&view.as_raw()));
}

/// A render pass rewritten for emulation was created from `pass` (its density attachment
/// `density`): its colour targets ([`pass_colours`]) are noted.
pub fn pass_created(dev: &Device, handle: vk::RenderPass, pass: &Pass2, density: u32) {
    with_reconstructor(dev, |r| {
        let colours = pass_colours(pass);
        if colours[0].is_none() {
            return;
        }
        let view_mask = pass_view_mask(pass);
        r.tables.lock().passes.insert(
            handle.as_raw(),
            PassTarget {
                colours,
                density,
                view_mask,
            },
        );
    });
}

/// # Safety
/// `dev` must be live.
pub unsafe fn pass_destroyed(dev: &Device, pass: vk::RenderPass) {
    with_reconstructor(dev, |r| r.tables.lock().passes.remove(&pass.as_raw()));
}

/// A framebuffer (with views) of a rewritten pass was created from `ci`: where its colour view is
/// reconstructed, it is noted with its density view and rendered layers.
///
/// # Safety
/// `dev` must be live; `ci` the application's valid create info.
pub unsafe fn framebuffer_created(
    dev: &Device,
    fb: vk::Framebuffer,
    ci: &vk::FramebufferCreateInfo<'_>,
) {
    with_reconstructor(dev, |r| {
        if !r.any.load(Ordering::Acquire)
            || ci.flags.contains(vk::FramebufferCreateFlags::IMAGELESS)
        {
            return;
        }
        let mut t = r.tables.lock();
        let Some(p) = t.passes.get(&ci.render_pass.as_raw()).copied() else {
            return;
        };
        // SAFETY: the caller's array.
        let views = unsafe { slice(ci.p_attachments, ci.attachment_count) };
        let Some(d) = views.get(p.density as usize) else {
            return;
        };
        let mut colours = [None; MAX_TARGETS];
        for (out, c) in colours.iter_mut().zip(&p.colours) {
            *out = c
                .and_then(|(i, _)| views.get(i as usize))
                .map(|v| v.as_raw())
                .filter(|v| t.views.contains_key(v));
        }
        if colours.iter().all(Option::is_none) {
            return;
        }
        t.framebuffers.insert(
            fb.as_raw(),
            FramebufferTargets {
                colours,
                density: d.as_raw(),
                layers: rendered(p.view_mask, ci.layers),
            },
        );
    });
}

/// # Safety
/// `dev` must be live.
pub unsafe fn framebuffer_destroyed(dev: &Device, fb: vk::Framebuffer) {
    with_reconstructor(dev, |r| r.tables.lock().framebuffers.remove(&fb.as_raw()));
}

/// The layers a pass renders: its views' (the highest view + 1) or `layers`.
fn rendered(view_mask: u32, layers: u32) -> u32 {
    if view_mask != 0 {
        32 - view_mask.leading_zeros()
    } else {
        layers.max(1)
    }
}

/// Notes in `r`'s command buffer record what the end of a pass begun on the colour targets
/// `targets` (each with the layout the pass leaves it in) and the density view `density` (its
/// shadow is the pass's shading-rate attachment) reconstructs.
#[allow(clippy::too_many_arguments)]
fn plan(
    dev: &Device,
    rc: &Reconstructor,
    record: &registry::CbRecord,
    targets: impl Iterator<Item = (Target, vk::ImageLayout)>,
    density: u64,
    layers: u32,
    area: vk::Rect2D,
    suspending: bool,
) {
    let Some(sv) = dev.emulation.views.lock().get(&density).copied() else {
        return;
    };
    let mut p = Plan::new(area, sv.image, sv.texels, sv.base_layer, suspending);
    for (t, layout) in targets {
        let Some(kind) = rc.handles(t.format) else {
            continue;
        };
        let layers = layers.min(t.layers).max(1);
        let c = Colour {
            image: t.image,
            base_layer: t.base_layer,
            layers,
            layout,
            kind,
            rate_layers: rate_layers(sv.layers, layers),
        };
        if !p.push(c) {
            too_many_targets();
            break;
        }
    }
    if !p.is_empty() {
        registry::set_plan(record, p);
    }
}

/// `vkCmdBeginRenderPass(2)` on an emulating device: where the pass renders reconstructed
/// colour targets, its end is planned. One atomic load where no view of the device is
/// reconstructed.
///
/// # Safety
/// `begin` must be NULL or valid.
pub unsafe fn begin_render_pass(
    dev: &Device,
    cb: vk::CommandBuffer,
    begin: *const vk::RenderPassBeginInfo<'_>,
) {
    if dev.fdm.is_none() {
        return;
    }
    // SAFETY: as the caller promised.
    let Some(b) = (unsafe { begin.as_ref() }) else {
        return;
    };
    record_of(cb, |r| {
        let Some(rc) = r.reconstructor.as_deref() else {
            return;
        };
        if !rc.any.load(Ordering::Acquire) {
            return;
        }
        let mut targets = [None; MAX_TARGETS];
        let found = {
            let t = rc.tables.lock();
            t.passes
                .get(&b.render_pass.as_raw())
                .copied()
                .and_then(|p| {
                    let f = match t.framebuffers.get(&b.framebuffer.as_raw()) {
                        Some(&f) => f,
                        None => {
                            // An imageless framebuffer: the views are in the begin info.
                            let ty = vk::StructureType::RENDER_PASS_ATTACHMENT_BEGIN_INFO;
                            // SAFETY: the caller's chain, read only.
                            let found = unsafe {
                                chain::find::<vk::RenderPassAttachmentBeginInfo<'_>>(b.p_next, ty)
                            };
                            // SAFETY: found by its sType in a valid chain.
                            let a = unsafe { found.ok().flatten()?.as_ref()? };
                            // SAFETY: the caller's array.
                            let views = unsafe { slice(a.p_attachments, a.attachment_count) };
                            let mut colours = [None; MAX_TARGETS];
                            for (out, c) in colours.iter_mut().zip(&p.colours) {
                                *out = c
                                    .and_then(|(i, _)| views.get(i as usize))
                                    .map(|v| v.as_raw());
                            }
                            FramebufferTargets {
                                colours,
                                density: views.get(p.density as usize)?.as_raw(),
                                layers: rendered(p.view_mask, 1),
                            }
                        }
                    };
                    for ((out, view), c) in targets.iter_mut().zip(&f.colours).zip(&p.colours) {
                        *out = view
                            .and_then(|v| t.views.get(&v).copied())
                            .zip(c.map(|(_, layout)| layout));
                    }
                    Some((f.density, f.layers))
                })
        };
        if let Some((density, layers)) = found {
            plan(
                dev,
                rc,
                r,
                targets.into_iter().flatten(),
                density,
                layers,
                b.render_area,
                false,
            );
        }
    });
}

/// `vkCmdBeginRendering` on an emulating device with the density view `density`: where its
/// colour attachments (their resolve views, for multisampled ones) are reconstructed targets the
/// rendering keeps, its end is planned; a resuming rendering keeps the plan of the instance it
/// continues.
///
/// # Safety
/// `ri` must be valid.
pub unsafe fn begin_rendering(
    dev: &Device,
    cb: vk::CommandBuffer,
    ri: &vk::RenderingInfo<'_>,
    density: vk::ImageView,
) {
    if dev.fdm.is_none() {
        return;
    }
    record_of(cb, |r| {
        let Some(rc) = r.reconstructor.as_deref() else {
            return;
        };
        if !rc.any.load(Ordering::Acquire) {
            return;
        }
        let suspending = ri.flags.contains(vk::RenderingFlags::SUSPENDING);
        if ri.flags.contains(vk::RenderingFlags::RESUMING) {
            if let Some(p) = r.plan.lock().as_mut() {
                p.suspending = suspending;
            }
            return;
        }
        // SAFETY: the caller's colour attachments, `colorAttachmentCount` of them.
        let colours = unsafe { slice(ri.p_color_attachments, ri.color_attachment_count) };
        let mut targets = [None; MAX_TARGETS];
        {
            let t = rc.tables.lock();
            let mut n = 0;
            for a in colours {
                let Some((view, layout)) = rendering_target(a) else {
                    continue;
                };
                let Some(target) = t.views.get(&view.as_raw()).copied() else {
                    continue;
                };
                if n == MAX_TARGETS {
                    too_many_targets();
                    break;
                }
                targets[n] = Some((target, layout));
                n += 1;
            }
        }
        if targets[0].is_none() {
            return;
        }
        let layers = rendered(ri.view_mask, ri.layer_count);
        plan(
            dev,
            rc,
            r,
            targets.into_iter().flatten(),
            density.as_raw(),
            layers,
            ri.render_area,
            suspending,
        );
    });
}
