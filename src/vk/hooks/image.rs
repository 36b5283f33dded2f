//! Images and views, created and destroyed side by side: on an injecting device colour images and
//! views are noted for finding eye passes ([`crate::vk::own::injector`]); on an emulating device a
//! density map reaches the driver without the density usage and gets a shading-rate shadow
//! ([`crate::vk::emulation`]) that its views and host-side layout transitions follow, and a map the
//! application writes is handed to [`crate::vk::convert`].

use ash::vk;
use ash::vk::Handle as _;

use crate::bridge;
use crate::vk::base::ffi::{raw, Arr, Call, In, Out};
use crate::vk::own::calls::Own;
use crate::vk::own::shadows::{shadow_view_info, ShadowImage, ShadowView};
use crate::vk::reconstruct;
use crate::vk::registry::Device;
use crate::vk::translate::formats::{needs_translation, translate_image};
use crate::vk::translate::rate_state::view_flags;
use crate::vk::translate::sync;
use crate::vk::{convert, emulation};

hook! {
    /// `vkCreateImageView`: a view of a shadowed image gets a shadow view beside it; on an
    /// injecting device a view of a colour image is noted for finding eye passes
    /// ([`crate::vk::own::injector`]).
    create_image_view = "vkCreateImageView";
    on device(device), next create_image_view, fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    create_view(
        device: val vk::Device,
        info: in vk::ImageViewCreateInfo<'_>,
        alloc: val *const vk::AllocationCallbacks<'_>,
        out: out vk::ImageView,
    ) -> vk::Result
}

fn create_view(
    c: Call<'_, Device, vk::PFN_vkCreateImageView, impl Fn() -> vk::Result>,
    device: vk::Device,
    info: In<'_, vk::ImageViewCreateInfo<'_>>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: Out<'_, vk::ImageView>,
) -> vk::Result {
    let dev = c.dev;
    // Dynamic and deferred density-map views cannot be emulated: those flags are left out of a
    // copy ([`view_flags`]).
    let copy = info.get().and_then(|c| {
        Some(vk::ImageViewCreateInfo {
            flags: view_flags(c.flags)?,
            ..*c
        })
    });
    let down = copy.as_ref().map_or(info.raw(), |c| c as *const _);
    // A view of an image with usage fovea added gets the application's usage (on a copy).
    let mut usage = vk::ImageViewUsageCreateInfo::default();
    // SAFETY: `down` is NULL or the application's valid create info (or a copy of it).
    let hidden = unsafe { reconstruct::hide_added_usage(dev, down, &mut usage) };
    let down = hidden.as_ref().map_or(down, |c| c as *const _);
    // SAFETY: the next layer's function, with the application's arguments (or a copy of its
    // create info that lives across the call).
    let r = unsafe { (c.next)(device, down, alloc, out.raw()) };
    let (vk::Result::SUCCESS, Some(ci), Some(app_view)) = (r, info.get(), out.read()) else {
        return r;
    };
    // SAFETY: the view was just created on the live device from `ci`.
    unsafe { reconstruct::view_created(dev, app_view, ci) };
    if let Some(inj) = &dev.injection {
        inj.view_created(app_view, ci);
        return r;
    }
    let shadow = dev.emulation.images.lock().get(&ci.image.as_raw()).copied();
    if let (Some(s), Some(own)) = (shadow, &dev.own) {
        shadow_view(dev, own, app_view, ci, &s);
    }
    r
}

/// Makes the shadow view of `app_view`, a new view of an image the layer shadows with `s`.
fn shadow_view(
    dev: &Device,
    own: &Own,
    app_view: vk::ImageView,
    ci: &vk::ImageViewCreateInfo<'_>,
    s: &ShadowImage,
) {
    let shadow_info = shadow_view_info(s, ci);
    // SAFETY: the layer's own view of its own live image, on the live device.
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
            // SAFETY: the device is live; the view was just made of `ci.image`.
            unsafe { convert::view_changed(dev, app_view, Some(ci.image)) };
        }
        // Fail open, as for the shadow image ([`emulation::image_created`]): the view is the
        // application's alone, and framebuffers with it get the full-rate stand-in.
        Err(e) => tracing::warn!(
            view = raw(app_view),
            result = ?e,
            "no shadow view for a density-map view: passes with it render at full rate"
        ),
    }
}

hook! {
    /// `vkDestroyImageView`: the shadow view goes with the application's.
    destroy_image_view = "vkDestroyImageView";
    on device(device), maybe destroy_image_view, fails(());
    destroy_view(
        device: val vk::Device,
        view: val vk::ImageView,
        alloc: val *const vk::AllocationCallbacks<'_>,
    ) -> ()
}

fn destroy_view(
    c: Call<'_, Device, Option<vk::PFN_vkDestroyImageView>, impl Fn()>,
    _device: vk::Device,
    view: vk::ImageView,
    _alloc: *const vk::AllocationCallbacks<'_>,
) {
    let dev = c.dev;
    // Where the next layer has it.
    c.as_given();
    if let Some(inj) = &dev.injection {
        inj.view_destroyed(view);
    }
    // SAFETY: the device is live; the view is gone.
    unsafe { reconstruct::view_destroyed(dev, view) };
    let shadow = dev.emulation.views.lock().remove(&view.as_raw());
    // SAFETY: as above.
    unsafe { convert::view_changed(dev, view, None) };
    if let (Some(s), Some(own)) = (shadow, &dev.own) {
        // SAFETY: the layer's own view; the application's use of it ended with its view's.
        unsafe { own.fns.destroy_image_view(s.view, None) };
    }
}

hook! {
    /// `vkDestroyImage`: the shadow and its memory go with the application's image.
    destroy_image = "vkDestroyImage";
    on device(device), maybe destroy_image, fails(());
    destroy(
        device: val vk::Device,
        image: val vk::Image,
        alloc: val *const vk::AllocationCallbacks<'_>,
    ) -> ()
}

fn destroy(
    c: Call<'_, Device, Option<vk::PFN_vkDestroyImage>, impl Fn()>,
    _device: vk::Device,
    image: vk::Image,
    _alloc: *const vk::AllocationCallbacks<'_>,
) {
    let dev = c.dev;
    // The layer's view of the image goes first.
    // SAFETY: the device is live; the application's uses of the image have ended.
    unsafe { convert::map_destroyed(dev, image) };
    // Where the next layer has it.
    c.as_given();
    if let Some(inj) = &dev.injection {
        inj.image_destroyed(image);
    }
    // SAFETY: the device is live; the image is gone.
    unsafe { reconstruct::image_destroyed(dev, image) };
    let shadow = dev.emulation.images.lock().remove(&image.as_raw());
    if let Some(s) = shadow {
        bridge::set_shadow(image, None);
        if let Some(own) = &dev.own {
            // SAFETY: the layer's own image and memory, no longer used by the application (its
            // image, which every use of the shadow stood in for, is being destroyed); a pending
            // clear is dropped, one in flight is waited for.
            unsafe { own.clears.forget(&own.fns, &s) };
        }
    }
}

hook! {
    /// `vkTransitionImageLayout` (`VK_EXT_host_image_copy`, core in Vulkan 1.4): a host-side
    /// layout transition names layouts as barriers do, so the density-map layout becomes the one
    /// the application's density images have on the driver's side (`GENERAL`,
    /// `crate::vk::barrier`), on a copy of the array. The shadow needs nothing: it keeps its own
    /// layout, and whether a map is read is decided by the layout each pass names
    /// (`crate::vk::convert`).
    transition_image_layout = "vkTransitionImageLayout",
        transition_image_layout_ext = "vkTransitionImageLayoutEXT";
    on device(device), next transition_image_layout / transition_image_layout_ext,
    fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    transition(
        device: val vk::Device,
        count: val u32,
        infos: (array count) vk::HostImageLayoutTransitionInfoEXT<'_>,
    ) -> vk::Result
}

fn transition(
    c: Call<'_, Device, vk::PFN_vkTransitionImageLayoutEXT, impl Fn() -> vk::Result>,
    device: vk::Device,
    count: u32,
    infos: Arr<'_, vk::HostImageLayoutTransitionInfoEXT<'_>>,
) -> vk::Result {
    let given = infos.slice();
    let fdm = vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT;
    if !given
        .iter()
        .any(|t| t.old_layout == fdm || t.new_layout == fdm)
    {
        return c.as_given();
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
    unsafe { (c.next)(device, count, copy.as_ptr()) }
}

hook! {
    /// `vkCreateImage` on an injecting device: the image goes down untouched, and a colour
    /// image's extent and layers are noted for finding eye passes ([`crate::vk::own::injector`]).
    ///
    /// `vkCreateImage` on an emulating device: a density map reaches the driver without the
    /// density-map usage and subsampled flag it does not know (on a copy of the create info), and
    /// gets a shading-rate shadow ([`emulation::image_created`]); where the shadow cannot be made,
    /// the application's image is returned all the same (fail open: its passes render at full
    /// rate).
    create_image = "vkCreateImage";
    on device(device), next create_image, fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    create(
        device: val vk::Device,
        info: in vk::ImageCreateInfo<'_>,
        alloc: val *const vk::AllocationCallbacks<'_>,
        out: out vk::Image,
    ) -> vk::Result
}

fn create(
    c: Call<'_, Device, vk::PFN_vkCreateImage, impl Fn() -> vk::Result>,
    device: vk::Device,
    info: In<'_, vk::ImageCreateInfo<'_>>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: Out<'_, vk::Image>,
) -> vk::Result {
    let (dev, next) = (c.dev, c.next);
    // What reconstruction keeps of an image made as the application asked for it.
    let made = |r| {
        // SAFETY: the device is live; the image was just created from the application's create
        // info (where `r` says so).
        unsafe { reconstruct::image_made(dev, r, out.raw(), info.raw(), None) };
        r
    };
    if let Some(inj) = &dev.injection {
        let r = c.as_given();
        if let (vk::Result::SUCCESS, Some(ci), Some(image)) = (r, info.get(), out.read()) {
            inj.image_created(image, ci);
        }
        return made(r);
    }
    let (Some(app), Some(_)) = (info.get(), &dev.fdm) else {
        return c.as_given();
    };
    let (copy, subsampled) = match translated(dev, app) {
        Ok(t) => t,
        Err(Untranslated::Unneeded) => return made(c.as_given()),
        Err(Untranslated::Refused) => return c.as_given(),
    };
    // SAFETY: the next layer's function; the translated copy lives across the call.
    let r = unsafe { next(device, &copy, alloc, out.raw()) };
    let added = subsampled.map(|u| u & !app.usage);
    // SAFETY: the device is live; the image was just created from `app` (where `r` says so).
    unsafe { reconstruct::image_made(dev, r, out.raw(), app, added) };
    if let (vk::Result::SUCCESS, Some(image)) = (r, out.read()) {
        density_map_made(dev, image, app);
    }
    r
}

/// Why an emulating device's image create info goes down as the application passed it.
enum Untranslated {
    /// Nothing in it names the density map.
    Unneeded,
    /// A density map the layer cannot emulate (not 2D, optimal `R8G8_UNORM`).
    Refused,
}

/// The copy of an emulating device's image create info that goes down in its place: the usage
/// its reconstruction needs (docs/reconstruction.md), and without the density-map usage and
/// flags; `Err` where the application's goes down as it came. The second value is the usage the
/// reconstruction asked for, where it reconstructs the image.
fn translated<'a>(
    dev: &Device,
    app: &vk::ImageCreateInfo<'a>,
) -> Result<(vk::ImageCreateInfo<'a>, Option<vk::ImageUsageFlags>), Untranslated> {
    let mut copy = *app;
    // An application's subsampled colour image gets the copies' usage its reconstruction needs.
    // SAFETY: the application's create info, valid as the command requires.
    let subsampled = unsafe { reconstruct::subsampled_usage(dev, &copy) };
    if let Some(usage) = subsampled {
        copy.usage = usage;
    }
    if !needs_translation(copy.usage, copy.flags) {
        return Err(Untranslated::Unneeded);
    }
    let Some((usage, flags)) = translate_image(
        copy.format,
        copy.image_type,
        copy.tiling,
        copy.usage,
        copy.flags,
    ) else {
        tracing::warn!(
            format = ?copy.format,
            "a density-map image that is not 2D, optimal R8G8_UNORM; passed on as is"
        );
        return Err(Untranslated::Refused);
    };
    copy.usage = usage;
    copy.flags = flags;
    Ok((copy, subsampled))
}

/// What an emulating device keeps of a density map just created from `app`: its shadow and its
/// conversion.
fn density_map_made(dev: &Device, image: vk::Image, app: &vk::ImageCreateInfo<'_>) {
    if !app
        .usage
        .contains(vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT)
    {
        return;
    }
    // SAFETY: the image was just created on the live device from `app`.
    if let Some(s) = unsafe { emulation::image_created(dev, image, app) } {
        let offsets = emulation::takes_offsets(app.flags);
        // SAFETY: as above, and shadowed by `s`.
        unsafe { convert::map_created(dev, image, &s, offsets) };
    }
}
