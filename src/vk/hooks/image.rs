//! Images and views, created and destroyed side by side: on an injecting device colour images and
//! views are noted for finding eye passes ([`crate::vk::own::injector`]); on an emulating device a
//! density map reaches the driver without the density usage and gets a shading-rate shadow
//! ([`crate::vk::emulation`]) that its views and host-side layout transitions follow, and a map the
//! application writes is handed to [`crate::vk::convert`].

use ash::vk;
use ash::vk::Handle as _;

use crate::bridge;
use crate::vk::base::ffi::{guard, raw};
use crate::vk::own::shadows::{shadow_view_info, ShadowView};
use crate::vk::reconstruct;
use crate::vk::registry::{self, Device};
use crate::vk::translate::formats::{needs_translation, translate_image};
use crate::vk::translate::rate_state::view_flags;
use crate::vk::translate::sync;
use crate::vk::{convert, emulation};

/// `vkCreateImageView`: a view of a shadowed image gets a shadow view beside it; on an injecting
/// device a view of a colour image is noted for finding eye passes ([`crate::vk::own::injector`]).
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
            // of a copy ([`view_flags`]).
            let copy = (!info.is_null())
                // SAFETY: the caller's create info, read only.
                .then(|| unsafe { *info })
                .and_then(|c| {
                    Some(vk::ImageViewCreateInfo {
                        flags: view_flags(c.flags)?,
                        ..c
                    })
                });
            let down = copy.as_ref().map_or(info, |c| c as *const _);
            // A view of an image with usage fovea added gets the application's usage (on a copy).
            let mut usage = vk::ImageViewUsageCreateInfo::default();
            // SAFETY: `down` is NULL or the caller's valid create info (or a copy of it).
            let hidden = unsafe { reconstruct::hide_added_usage(&dev, down, &mut usage) };
            let down = hidden.as_ref().map_or(down, |c| c as *const _);
            // SAFETY: the next layer's function, with the caller's arguments (or a copy of its
            // create info).
            let r = unsafe { next(device, down, alloc, out) };
            if r != vk::Result::SUCCESS || info.is_null() || out.is_null() {
                return r;
            }
            // SAFETY: the caller's create info, read only.
            let ci = unsafe { &*info };
            // SAFETY: the view was just created on the live device.
            unsafe { reconstruct::view_created(&dev, *out, ci) };
            if let Some(inj) = &dev.injection {
                // SAFETY: the view was just created.
                inj.view_created(unsafe { *out }, ci);
                return r;
            }
            let shadow = dev.emulation.images.lock().get(&ci.image.as_raw()).copied();
            let (Some(s), Some(own)) = (shadow, &dev.own) else {
                return r;
            };
            // SAFETY: the view was just created.
            let app_view = unsafe { *out };
            // SAFETY: the layer's own view of its own live image.
            let shadow_info = shadow_view_info(&s, ci);
            // SAFETY: as above.
            match unsafe { own.fns.create_image_view(&shadow_info, None) } {
                Ok(view) => {
                    let r = shadow_info.subresource_range;
                    dev.emulation.views.lock().insert(
                        app_view.as_raw(),
                        ShadowView {
                            view,
                            image: s.image,
                            texels: [s.extent.width, s.extent.height],
                            base_layer: r.base_array_layer,
                            layers: r.layer_count,
                        },
                    );
                    // SAFETY: the device is live.
                    unsafe { convert::view_changed(&dev, app_view, Some(ci.image)) };
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
        if let Some(inj) = &dev.injection {
            inj.view_destroyed(view);
        }
        // SAFETY: the device is live.
        unsafe { reconstruct::view_destroyed(&dev, view) };
        let shadow = dev.emulation.views.lock().remove(&view.as_raw());
        // SAFETY: the device is live.
        unsafe { convert::view_changed(&dev, view, None) };
        if let (Some(s), Some(own)) = (shadow, &dev.own) {
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
        unsafe { convert::map_destroyed(&dev, image) };
        if let Some(next) = dev.next.destroy_image {
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { next(device, image, alloc) };
        }
        if let Some(inj) = &dev.injection {
            inj.image_destroyed(image);
        }
        // SAFETY: the device is live.
        unsafe { reconstruct::image_destroyed(&dev, image) };
        let shadow = dev.emulation.images.lock().remove(&image.as_raw());
        if let Some(s) = shadow {
            bridge::set_shadow(image, None);
            if let Some(own) = &dev.own {
                // SAFETY: the layer's own image and memory, no longer used by the application
                // (its image, which every use of the shadow stood in for, is being destroyed);
                // a pending clear is dropped, one in flight is waited for.
                unsafe { own.clears.forget(&own.fns, &s) };
            }
        }
    })
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
        convert::map_may_have_changed();
        let copy: Vec<vk::HostImageLayoutTransitionInfoEXT<'_>> = given
            .iter()
            .map(|t| {
                let mut t = *t;
                t.old_layout = sync::layout(t.old_layout);
                t.new_layout = sync::layout(t.new_layout);
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

/// `vkCreateImage` on an injecting device: the image goes down untouched, and a colour image's
/// extent and layers are noted for finding eye passes ([`crate::vk::own::injector`]).
///
/// `vkCreateImage` on an emulating device: a density map reaches the driver without the
/// density-map usage and subsampled flag it does not know (on a copy of the create info), and
/// gets a shading-rate shadow ([`emulation::image_created`]); where the shadow cannot be made, the
/// application's image is returned all the same (fail open: its passes render at full rate).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn create_image(
    device: vk::Device,
    info: *const vk::ImageCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Image,
) -> vk::Result {
    guard(
        "vkCreateImage",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let Some(dev) = (unsafe { registry::device(device) }) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let Some(next) = dev.next.create_image else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            if let Some(inj) = &dev.injection {
                // SAFETY: the next layer's function, with the caller's arguments.
                let r = unsafe { next(device, info, alloc, out) };
                if r == vk::Result::SUCCESS && !info.is_null() && !out.is_null() {
                    // SAFETY: the caller's create info, read only; the image just created.
                    unsafe { inj.image_created(*out, &*info) };
                }
                // SAFETY: as above.
                unsafe { reconstruct::image_made(&dev, r, out, info, None) };
                return r;
            }
            if info.is_null() || dev.fdm.is_none() {
                // SAFETY: the next layer's function, with the caller's arguments.
                return unsafe { next(device, info, alloc, out) };
            }
            // SAFETY: the caller's create info, read only.
            let mut copy = unsafe { *info };
            // An application's subsampled colour image gets the copies' usage its
            // reconstruction needs (docs/reconstruction.md).
            // SAFETY: as above.
            let subsampled = unsafe { reconstruct::subsampled_usage(&dev, &copy) };
            if let Some(usage) = subsampled {
                copy.usage = usage;
            }
            if !needs_translation(copy.usage, copy.flags) {
                // SAFETY: as above.
                let r = unsafe { next(device, info, alloc, out) };
                // SAFETY: as above; the image just created.
                unsafe { reconstruct::image_made(&dev, r, out, info, None) };
                return r;
            }
            match translate_image(
                copy.format,
                copy.image_type,
                copy.tiling,
                copy.usage,
                copy.flags,
            ) {
                Some((usage, flags)) => {
                    copy.usage = usage;
                    copy.flags = flags;
                }
                None => {
                    tracing::warn!(
                        format = ?copy.format,
                        "a density-map image that is not 2D, optimal R8G8_UNORM; passed on as is"
                    );
                    // SAFETY: as above.
                    return unsafe { next(device, info, alloc, out) };
                }
            }
            // SAFETY: the translated copy lives across the call.
            let r = unsafe { next(device, &copy, alloc, out) };
            // SAFETY: the caller's create info, read only.
            let app = unsafe { &*info };
            let added = subsampled.map(|u| u & !app.usage);
            // SAFETY: the image was just created on the live device, from `app`.
            unsafe { reconstruct::image_made(&dev, r, out, app, added) };
            if r == vk::Result::SUCCESS
                && !out.is_null()
                && app
                    .usage
                    .contains(vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT)
            {
                // SAFETY: the image was just created from `app`.
                if let Some(s) = unsafe { emulation::image_created(&dev, *out, app) } {
                    let offsets = emulation::takes_offsets(app.flags);
                    // SAFETY: as above, shadowed by `s`.
                    unsafe { convert::map_created(&dev, *out, &s, offsets) };
                }
            }
            r
        },
    )
}
