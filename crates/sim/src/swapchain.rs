//! Swapchains (spec chapter "Swapchain Image Management") and the XR_FB_swapchain_update_state
//! entry points the runtime offers natively when configured to.
//!
//! Image order rules: images are acquired round-robin; at most `image_count` may be acquired and not
//! released; xrWaitSwapchainImage waits the oldest acquired image and only one image may be waited
//! at a time; xrReleaseSwapchainImage releases the oldest acquired image, which must have been
//! waited. Violations are XR_ERROR_CALL_ORDER_INVALID. Static swapchains have one image that can be
//! acquired once.

use std::collections::VecDeque;

use openxr_sys as xr;
use openxr_sys::Handle;

use crate::extensions::FB_FOVEATION;
use crate::ffi;
use crate::objects::{Applied, Graphics, Swapchain};
use crate::state::{entry, world};
use crate::system::MAX_IMAGE_SIZE;
use crate::vulkan::{self, FORMATS};

/// How many images a non-static swapchain has.
const IMAGE_COUNT: u32 = 3;

pub(crate) unsafe extern "system" fn enumerate_swapchain_formats(
    session: xr::Session,
    capacity: u32,
    count_out: *mut u32,
    formats: *mut i64,
) -> xr::Result {
    entry("xrEnumerateSwapchainFormats", |ctx| {
        let mut w = world();
        let id = w.enter_session(ctx, session)?;
        let list: Vec<i64> = match &w.sessions[&id].graphics {
            Graphics::Headless => FORMATS.iter().map(|f| i64::from(f.as_raw())).collect(),
            Graphics::Vulkan(vk) => vk.formats.iter().map(|f| i64::from(f.as_raw())).collect(),
        };
        ffi::two_call(capacity, count_out, formats, list.len(), |i, p| {
            *p = list[i];
            Ok(())
        })?;
        Ok(xr::Result::SUCCESS)
    })
}

const KNOWN_USAGE: u64 = 0x7f; // COLOR_ATTACHMENT .. MUTABLE_FORMAT, the core bits

pub(crate) unsafe extern "system" fn create_swapchain(
    session: xr::Session,
    create_info: *const xr::SwapchainCreateInfo,
    swapchain: *mut xr::Swapchain,
) -> xr::Result {
    entry("xrCreateSwapchain", |ctx| {
        let mut w = world();
        let session = w.enter_session(ctx, session)?;
        let info = ffi::input(create_info, xr::StructureType::SWAPCHAIN_CREATE_INFO)?;
        ffi::non_null(swapchain)?;
        // Unknown structs are ignored (spec), but the journal shows what reached the runtime.
        ctx.next_types = ffi::chain_types(info.next);
        ctx.detail = format!(
            "{}x{} format={} samples={} faces={} array={} mips={} usage={:#x} flags={:#x}",
            info.width,
            info.height,
            info.format,
            info.sample_count,
            info.face_count,
            info.array_size,
            info.mip_count,
            info.usage_flags.into_raw(),
            info.create_flags.into_raw()
        );
        let flags = info.create_flags;
        let known_flags =
            xr::SwapchainCreateFlags::PROTECTED_CONTENT | xr::SwapchainCreateFlags::STATIC_IMAGE;
        if !known_flags.contains(flags) || info.usage_flags.into_raw() & !KNOWN_USAGE != 0 {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        if flags.contains(xr::SwapchainCreateFlags::PROTECTED_CONTENT) {
            return Err(xr::Result::ERROR_FEATURE_UNSUPPORTED);
        }
        let zero = [
            info.width,
            info.height,
            info.sample_count,
            info.face_count,
            info.array_size,
            info.mip_count,
        ];
        if zero.contains(&0) || info.width > MAX_IMAGE_SIZE || info.height > MAX_IMAGE_SIZE {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        if !matches!(info.face_count, 1 | 6) || (info.face_count == 6 && info.width != info.height)
        {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        let max_mips = 32 - info.width.max(info.height).leading_zeros();
        if info.mip_count > max_mips || !matches!(info.sample_count, 1 | 2 | 4) {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        let instance = w.sessions[&session].instance;
        let foveation = ffi::find_in_chain(
            info.next,
            xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
        )
        .filter(|_| w.instances[&instance].has_extension(FB_FOVEATION))
        .map(|p| &*(p as *const xr::SwapchainCreateInfoFoveationFB));
        if let Some(f) = foveation {
            // SCALED_BIN (0x1) and FRAGMENT_DENSITY_MAP (0x2) are the only bits.
            if f.flags.into_raw() & !0x3 != 0 {
                return Err(xr::Result::ERROR_VALIDATION_FAILURE);
            }
        }
        let format = i32::try_from(info.format)
            .map(ash::vk::Format::from_raw)
            .ok();
        let images = match &w.sessions[&session].graphics {
            Graphics::Headless => {
                format
                    .filter(|f| FORMATS.contains(f))
                    .ok_or(xr::Result::ERROR_SWAPCHAIN_FORMAT_UNSUPPORTED)?;
                None
            }
            Graphics::Vulkan(vk) => {
                let format = format
                    .filter(|f| vk.formats.contains(f))
                    .ok_or(xr::Result::ERROR_SWAPCHAIN_FORMAT_UNSUPPORTED)?;
                let count = if flags.contains(xr::SwapchainCreateFlags::STATIC_IMAGE) {
                    1
                } else {
                    IMAGE_COUNT
                };
                Some(vulkan::create_images(vk, info, format, count)?)
            }
        };
        let is_static = flags.contains(xr::SwapchainCreateFlags::STATIC_IMAGE);
        let id = w.alloc_handle();
        w.swapchains.insert(
            id,
            Swapchain {
                session,
                width: info.width,
                height: info.height,
                array_size: info.array_size,
                image_count: if is_static { 1 } else { IMAGE_COUNT },
                is_static,
                acquired: VecDeque::new(),
                waited: false,
                next_index: 0,
                acquisitions: 0,
                ever_released: false,
                images,
                foveation_supported: foveation.is_some(),
                foveation: None,
            },
        );
        *swapchain = xr::Swapchain::from_raw(id);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn destroy_swapchain(swapchain: xr::Swapchain) -> xr::Result {
    entry("xrDestroySwapchain", |ctx| {
        ctx.allow_lost = true;
        let mut w = world();
        let id = w.enter_swapchain(ctx, swapchain)?;
        w.swapchains.remove(&id);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn enumerate_swapchain_images(
    swapchain: xr::Swapchain,
    capacity: u32,
    count_out: *mut u32,
    images: *mut xr::SwapchainImageBaseHeader,
) -> xr::Result {
    entry("xrEnumerateSwapchainImages", |ctx| {
        let mut w = world();
        let id = w.enter_swapchain(ctx, swapchain)?;
        let sc = &w.swapchains[&id];
        let count = sc.image_count as usize;
        match &sc.images {
            Some(vk) => ffi::two_call(
                capacity,
                count_out,
                images as *mut xr::SwapchainImageVulkanKHR,
                count,
                |i, p| {
                    let p = ffi::output(p, xr::StructureType::SWAPCHAIN_IMAGE_VULKAN_KHR)?;
                    (*p).image = ash::vk::Handle::as_raw(vk.image(i));
                    Ok(())
                },
            )?,
            // Headless: there is no image type to fill, so only the count can be asked for.
            None => ffi::two_call(capacity, count_out, images, count, |_, _| {
                Err(xr::Result::ERROR_VALIDATION_FAILURE)
            })?,
        }
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn acquire_swapchain_image(
    swapchain: xr::Swapchain,
    acquire_info: *const xr::SwapchainImageAcquireInfo,
    index: *mut u32,
) -> xr::Result {
    entry("xrAcquireSwapchainImage", |ctx| {
        let mut w = world();
        let id = w.enter_swapchain(ctx, swapchain)?;
        if !acquire_info.is_null() {
            ffi::input(
                acquire_info,
                xr::StructureType::SWAPCHAIN_IMAGE_ACQUIRE_INFO,
            )?;
        }
        ffi::non_null(index)?;
        let sc = w.swapchains.get_mut(&id).expect("entered swapchain exists");
        if sc.acquired.len() as u32 >= sc.image_count || (sc.is_static && sc.acquisitions > 0) {
            return Err(xr::Result::ERROR_CALL_ORDER_INVALID);
        }
        let i = sc.next_index;
        // The one-time layout transition runs here: xrAcquireSwapchainImage is one of the four
        // calls allowed to use the application's queue (XR_KHR_vulkan_enable, "Concurrency").
        if let Some(images) = &mut sc.images {
            images.prepare(i)?;
        }
        sc.next_index = (i + 1) % sc.image_count;
        sc.acquired.push_back(i);
        sc.acquisitions += 1;
        ctx.detail = format!("index={i}");
        *index = i;
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn wait_swapchain_image(
    swapchain: xr::Swapchain,
    wait_info: *const xr::SwapchainImageWaitInfo,
) -> xr::Result {
    entry("xrWaitSwapchainImage", |ctx| {
        let mut w = world();
        let id = w.enter_swapchain(ctx, swapchain)?;
        ffi::input(wait_info, xr::StructureType::SWAPCHAIN_IMAGE_WAIT_INFO)?;
        let sc = w.swapchains.get_mut(&id).expect("entered swapchain exists");
        if sc.acquired.is_empty() || sc.waited {
            return Err(xr::Result::ERROR_CALL_ORDER_INVALID);
        }
        // The image was ready when acquired (its transition completed on a fence), so there is
        // never anything to wait for.
        sc.waited = true;
        ctx.detail = format!("index={}", sc.acquired[0]);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn release_swapchain_image(
    swapchain: xr::Swapchain,
    release_info: *const xr::SwapchainImageReleaseInfo,
) -> xr::Result {
    entry("xrReleaseSwapchainImage", |ctx| {
        let mut w = world();
        let id = w.enter_swapchain(ctx, swapchain)?;
        if !release_info.is_null() {
            ffi::input(
                release_info,
                xr::StructureType::SWAPCHAIN_IMAGE_RELEASE_INFO,
            )?;
        }
        let sc = w.swapchains.get_mut(&id).expect("entered swapchain exists");
        if !sc.waited {
            return Err(xr::Result::ERROR_CALL_ORDER_INVALID);
        }
        let i = sc.acquired.pop_front().expect("a waited image is acquired");
        sc.waited = false;
        sc.ever_released = true;
        ctx.detail = format!("index={i}");
        Ok(xr::Result::SUCCESS)
    })
}

/// XR_FB_swapchain_update_state: the only state type this runtime implements is
/// XrSwapchainStateFoveationFB, and only while XR_FB_foveation is enabled (native foveation). Every
/// other state struct is invalid usage (XR_ERROR_VALIDATION_FAILURE), which lets a layer's
/// pass-through of foreign states be observed.
unsafe fn swapchain_state_call(
    ctx: &mut crate::state::Ctx,
    swapchain: xr::Swapchain,
    state: *mut xr::SwapchainStateBaseHeaderFB,
    update: bool,
) -> crate::state::XrResult {
    let mut w = world();
    let id = w.enter_swapchain(ctx, swapchain)?;
    ffi::non_null(state)?;
    ctx.next_types = ffi::chain_types((*state).next);
    ctx.detail = format!("state type {:?}", (*state).ty);
    let session = w.swapchains[&id].session;
    let instance = w.sessions[&session].instance;
    if (*state).ty != xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB
        || !w.instances[&instance].has_extension(FB_FOVEATION)
    {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    let state = state as *mut xr::SwapchainStateFoveationFB;
    // The spec gives no code for a swapchain created without foveation support; like the
    // Monado-derived runtimes, treat it as invalid usage.
    if !w.swapchains[&id].foveation_supported {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    if !update {
        let applied = w.swapchains[&id].foveation;
        // A destroyed profile reads back as XR_NULL_HANDLE.
        let profile = applied
            .map(|a| a.profile)
            .filter(|p| w.profiles.contains_key(p))
            .unwrap_or(0);
        (*state).flags = xr::SwapchainStateFoveationFlagsFB::EMPTY;
        (*state).profile = xr::FoveationProfileFB::from_raw(profile);
        return Ok(xr::Result::SUCCESS);
    }
    // Valid usage: flags must be 0, profile a valid handle (of this session).
    if (*state).flags != xr::SwapchainStateFoveationFlagsFB::EMPTY {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    let profile = (*state).profile.into_raw();
    let params = match w.profiles.get(&profile) {
        Some(p) if p.session == session => p.params,
        _ => return Err(xr::Result::ERROR_HANDLE_INVALID),
    };
    ctx.detail = format!("applied {params:?}");
    w.swapchains
        .get_mut(&id)
        .expect("entered swapchain exists")
        .foveation = Some(Applied { profile, params });
    Ok(xr::Result::SUCCESS)
}

pub(crate) unsafe extern "system" fn update_swapchain_fb(
    swapchain: xr::Swapchain,
    state: *const xr::SwapchainStateBaseHeaderFB,
) -> xr::Result {
    entry("xrUpdateSwapchainFB", |ctx| {
        swapchain_state_call(ctx, swapchain, state as *mut _, true)
    })
}

pub(crate) unsafe extern "system" fn get_swapchain_state_fb(
    swapchain: xr::Swapchain,
    state: *mut xr::SwapchainStateBaseHeaderFB,
) -> xr::Result {
    entry("xrGetSwapchainStateFB", |ctx| {
        swapchain_state_call(ctx, swapchain, state, false)
    })
}
