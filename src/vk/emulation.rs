//! Emulation: the layer-owned shading-rate shadows that stand in for an application's density-map
//! images and views on an emulating device, made and destroyed with them, and the render pass
//! begins that name them.
//!
//! A density map is `R8G8_UNORM` with the `FRAGMENT_DENSITY_MAP` usage; a shading-rate attachment
//! is an integer image (`R8_UINT`) with the `FRAGMENT_SHADING_RATE_ATTACHMENT` usage
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkFragmentShadingRateAttachmentInfoKHR.html>,
//! docs/vulkan-fdm-on-fsr.md#mapping, #shadows). The application keeps its own image, which the driver gets
//! without the density usage ([`crate::vk::hooks::image::create_image`]); beside it the layer makes a
//! shadow of the same extent, 2D, one sample, optimal tiling, in device-local memory it owns, and
//! destroys it with the image. Render passes, framebuffers and dynamic rendering name the shadow
//! ([`crate::vk::hooks::pass`]); the bridge ([`crate::bridge::shadow_of`]) tells fovea's own density
//! images where to upload their rates.
//!
//! Layers: one per application layer where the driver has `layeredShadingRateAttachments`;
//! otherwise one, which both eyes share, so whoever fills it writes per texel the finer rate of all
//! the application's layers (docs/vulkan-fdm-on-fsr.md#multiview).
//!
//! Content: rate code 0 (1×1, full rate) before first use, so a density map nobody converts renders
//! correctly, at full rate; the shadow then lives in `FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR`.
//! The clear never takes a queue on its own: it waits, pending, for the application's next submit
//! on one of its graphics queues and runs in front of it ([`crate::vk::own::calls::Clears`]), since Vulkan makes
//! queue use externally synchronised by the application
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkQueueSubmit.html>). Command
//! buffers the layer allocates get the loader's dispatch pointer through `vkSetDeviceLoaderData`
//! (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>,
//! "Creating New Dispatchable Objects").
//!
//! Fail open: where a shadow cannot be made, the image (or view) is the application's alone, the
//! passes that would have used it run at full rate (a framebuffer gets a full-rate stand-in,
//! [`crate::vk::own::calls::Own::full_rate_view`]), and one log line says so.

use std::ffi::c_void;

use ash::vk;
use ash::vk::Handle as _;

use crate::bridge::{self, Shadow};
use crate::vk::base::chain::{self, ChainCopy};
use crate::vk::base::ffi::{raw, slice};
use crate::vk::own::calls::make_shadow;
use crate::vk::own::shadows::{ShadowImage, ShadowView};
use crate::vk::registry::Device;

/// Makes the shadow of a density-map image the application just created (`ci` as the
/// application gave it), or logs why not.
///
/// Fail open: a shadow that cannot be made (the driver is out of memory) leaves the application's
/// image as the driver made it, without a shadow; its views get none either, dynamic rendering with
/// it goes down without a shading-rate attachment, and a framebuffer with it gets the device's
/// full-rate stand-in ([`crate::vk::own::calls::Own::full_rate_view`]), so its passes render at full rate. One log line
/// says why. The shadow's clear is left pending for the application's next submit
/// ([`crate::vk::own::calls::Clears`]), except for fovea's own density images, whose uploads write the whole
/// shadow before first use.
///
/// # Safety
/// `app` must be the live image just created on `dev` from `ci`.
pub unsafe fn image_created(
    dev: &Device,
    app: vk::Image,
    ci: &vk::ImageCreateInfo<'_>,
) -> Option<ShadowImage> {
    let (Some(fdm), Some(own)) = (&dev.fdm, &dev.own) else {
        if dev.fdm.is_some() {
            tracing::warn!(
                image = raw(app),
                "no shadow for a density map: the layer could not set up its own calls on this \
                 device; passes with it render at full rate"
            );
        }
        return None;
    };
    let own_image = bridge::creating_own_density_images();
    // SAFETY: as the caller promised.
    match unsafe { make_shadow(own, fdm, ci.extent, ci.array_layers, !own_image) } {
        Ok(s) => {
            dev.emulation.images.lock().insert(app.as_raw(), s);
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
            // (`xr::density_images`); an application's own maps are converted at every pass
            // begin that reads them ([`crate::vk::convert`]): the caller hands those on, and
            // fovea's own that take density-map offsets, which only a conversion in front of
            // the pass can apply (docs/vulkan-layer.md#density-map-offsets).
            (!own_image || takes_offsets(ci.flags)).then_some(s)
        }
        Err(e) => {
            tracing::warn!(
                image = raw(app),
                result = ?e,
                "no shadow for a density map: the image is the application's alone, and passes \
                 with it render at full rate"
            );
            None
        }
    }
}

/// Whether an image was created for density-map offsets
/// (`VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT`, the QCOM bit's value).
pub fn takes_offsets(flags: vk::ImageCreateFlags) -> bool {
    flags.contains(vk::ImageCreateFlags::FRAGMENT_DENSITY_MAP_OFFSET_QCOM)
}

/// Destroys every shadow left on a device about to be destroyed.
///
/// # Safety
/// `dev` must be live, with nothing in flight.
pub unsafe fn destroy_all(dev: &Device) {
    let Some(own) = &dev.own else {
        return;
    };
    let views: Vec<ShadowView> = dev.emulation.views.lock().drain().map(|(_, v)| v).collect();
    let images: Vec<(u64, ShadowImage)> = dev.emulation.images.lock().drain().collect();
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

/// For a begin of a rewritten pass with an imageless framebuffer: a copy of `begin` whose
/// `VkRenderPassAttachmentBeginInfo` names the shadow view; `f` runs with it (or with `begin`
/// where nothing is swapped).
///
/// # Safety
/// `begin` must be NULL or valid.
pub unsafe fn with_swapped_begin(
    dev: &Device,
    begin: *const vk::RenderPassBeginInfo<'_>,
    f: impl FnOnce(*const vk::RenderPassBeginInfo<'_>),
) {
    // SAFETY: as the caller promised.
    let Some(b) = (unsafe { begin.as_ref() }) else {
        return f(begin);
    };
    if b.p_next.is_null() {
        return f(begin);
    }
    let ty = vk::StructureType::RENDER_PASS_ATTACHMENT_BEGIN_INFO;
    let Ok(Some(found)) =
        // SAFETY: the caller's chain, read only.
        (unsafe { chain::find::<vk::RenderPassAttachmentBeginInfo>(b.p_next, ty) })
    else {
        return f(begin);
    };
    let Some(density) = dev.emulation.density_attachment(b.render_pass) else {
        return f(begin);
    };
    // SAFETY: found by its sType in a valid chain.
    let found = unsafe { &*found };
    let mut views: Vec<vk::ImageView> =
        // SAFETY: the caller's array.
        unsafe { slice(found.p_attachments, found.attachment_count) }.to_vec();
    let Some(shadow) = views
        .get(density as usize)
        .and_then(|v| dev.emulation.shadow_view(*v))
    else {
        return f(begin);
    };
    views[density as usize] = shadow;
    // SAFETY: as above.
    let Ok(rest) = (unsafe { ChainCopy::without(b.p_next, |t| t == ty) }) else {
        tracing::warn!(
            "vkCmdBeginRenderPass: a pNext chain the layer cannot copy; passed on as is"
        );
        return f(begin);
    };
    let mut attachments = *found;
    attachments.p_next = rest.head();
    attachments.p_attachments = views.as_ptr();
    let mut copy = *b;
    copy.p_next = &attachments as *const _ as *const c_void;
    f(&copy)
}
