//! Swapchain lifetime and image access.

use std::sync::Arc;

use openxr_sys as xr;
use xr::Handle;

use super::{finish, next, session, succeeded, swapchain};
use crate::ffi::guard;
use crate::state::{registry, Swapchain, SwapchainInfo};

/// `xrCreateSwapchain`: records the swapchain's layout.
pub unsafe extern "system" fn create_swapchain(
    sess: xr::Session,
    info: *const xr::SwapchainCreateInfo,
    out: *mut xr::Swapchain,
) -> xr::Result {
    guard("xrCreateSwapchain", || {
        finish((|| {
            let state = session(sess)?;
            let f = next(state.instance.next.create_swapchain)?;
            if info.is_null()
                || out.is_null()
                || (*info).ty != xr::StructureType::SWAPCHAIN_CREATE_INFO
            {
                return Ok(f(sess, info, out));
            }
            let i = &*info;
            let r = f(sess, info, out);
            if succeeded(r) {
                let record = Swapchain {
                    handle: *out,
                    session: state,
                    info: SwapchainInfo {
                        usage: i.usage_flags.into_raw(),
                        format: i.format,
                        sample_count: i.sample_count,
                        width: i.width,
                        height: i.height,
                        face_count: i.face_count,
                        array_size: i.array_size,
                        mip_count: i.mip_count,
                    },
                };
                registry()
                    .swapchains
                    .write()
                    .insert((*out).into_raw(), Arc::new(record));
            }
            Ok(r)
        })())
    })
}

/// `xrDestroySwapchain`: forgets the swapchain (its layer resources go with the record).
pub unsafe extern "system" fn destroy_swapchain(handle: xr::Swapchain) -> xr::Result {
    guard("xrDestroySwapchain", || {
        finish((|| {
            let state = swapchain(handle)?;
            let f = next(state.session.instance.next.destroy_swapchain)?;
            let r = f(handle);
            if succeeded(r) {
                registry().swapchains.write().remove(&handle.into_raw());
            }
            Ok(r)
        })())
    })
}

/// `xrEnumerateSwapchainImages`: passed on.
pub unsafe extern "system" fn enumerate_swapchain_images(
    handle: xr::Swapchain,
    capacity: u32,
    count: *mut u32,
    images: *mut xr::SwapchainImageBaseHeader,
) -> xr::Result {
    guard("xrEnumerateSwapchainImages", || {
        finish((|| {
            let state = swapchain(handle)?;
            let f = next(state.session.instance.next.enumerate_swapchain_images)?;
            Ok(f(handle, capacity, count, images))
        })())
    })
}

/// `xrAcquireSwapchainImage`: passed on.
pub unsafe extern "system" fn acquire_swapchain_image(
    handle: xr::Swapchain,
    info: *const xr::SwapchainImageAcquireInfo,
    index: *mut u32,
) -> xr::Result {
    guard("xrAcquireSwapchainImage", || {
        finish((|| {
            let state = swapchain(handle)?;
            let f = next(state.session.instance.next.acquire_swapchain_image)?;
            Ok(f(handle, info, index))
        })())
    })
}

/// `xrWaitSwapchainImage`: passed on.
pub unsafe extern "system" fn wait_swapchain_image(
    handle: xr::Swapchain,
    info: *const xr::SwapchainImageWaitInfo,
) -> xr::Result {
    guard("xrWaitSwapchainImage", || {
        finish((|| {
            let state = swapchain(handle)?;
            let f = next(state.session.instance.next.wait_swapchain_image)?;
            Ok(f(handle, info))
        })())
    })
}

/// `xrReleaseSwapchainImage`: passed on.
pub unsafe extern "system" fn release_swapchain_image(
    handle: xr::Swapchain,
    info: *const xr::SwapchainImageReleaseInfo,
) -> xr::Result {
    guard("xrReleaseSwapchainImage", || {
        finish((|| {
            let state = swapchain(handle)?;
            let f = next(state.session.instance.next.release_swapchain_image)?;
            Ok(f(handle, info))
        })())
    })
}
