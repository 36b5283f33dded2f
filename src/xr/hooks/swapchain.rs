//! Swapchain lifetime and image access.

use std::sync::atomic::Ordering;
use std::sync::Arc;

use openxr_sys as xr;
use xr::Handle;

use crate::common::lock::Mutex;

use super::{finish, next, observed, session, succeeded, swapchain, HookResult};
use crate::bridge::{FoveationState, MapSources};
use crate::common::ffi::{self, guard};
use crate::gpu::density_images::{DensityImages, Refreshed};
use crate::xr::extensions::Ext;
use crate::xr::registry::{registry, Session, Swapchain, SwapchainInfo};

/// VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT (VK_EXT_fragment_density_map).
const VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT: u32 = 0x4000;

/// What the foveation structs in a swapchain create info ask for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FoveationRequest {
    /// `XrSwapchainCreateInfoFoveationFB` was chained.
    pub foveation: bool,
    /// Its flags (SCALED_BIN 0x1, FRAGMENT_DENSITY_MAP 0x2).
    pub flags: u64,
    /// `XrVulkanSwapchainCreateInfoMETA`'s flags, when chained.
    pub meta: Option<(u32, u32)>,
}

/// What becomes of VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT for a swapchain.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Subsampled {
    /// Not asked for, not forced.
    No,
    /// Asked for; dropped because the runtime allocates the images (as Quest does where the
    /// device cannot subsample).
    Dropped,
    /// Asked for; `debug.oculus.foveation.subsampled=0` turns it off.
    Off,
    /// `debug.oculus.foveation.subsampled=1` on a foveated swapchain: it cannot be forced on, for
    /// the same reason.
    CannotForce,
}

/// Checks a request against what fovea can honour without runtime support for the structs:
/// SCALED_BIN is a GLES flag (QCOM_texture_foveated) and a Vulkan or headless session cannot use it;
/// the runtime allocates the images, so additional Vulkan flags cannot be honoured, except
/// SUBSAMPLED, which Quest's runtime also drops when unsupported (fixed-foveated-rendering seed) and
/// which `debug.oculus.foveation.subsampled` forces on or off.
pub fn check_request(req: FoveationRequest, forced: Option<bool>) -> HookResult<Subsampled> {
    if req.flags & !0x3 != 0 {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    if req.flags & 0x1 != 0 {
        tracing::warn!("XR_SWAPCHAIN_CREATE_FOVEATION_SCALED_BIN_BIT_FB needs OpenGL ES; this is not a GLES session");
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    let mut asked = false;
    if let Some((create, usage)) = req.meta {
        if usage != 0 || create & !VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT != 0 {
            tracing::warn!(
                create,
                usage,
                "additional Vulkan swapchain flags the runtime cannot honour"
            );
            return Err(xr::Result::ERROR_FEATURE_UNSUPPORTED);
        }
        asked = create != 0;
    }
    Ok(match (asked, forced) {
        (true, Some(false)) => Subsampled::Off,
        (true, _) => Subsampled::Dropped,
        (false, Some(true)) if req.foveation => Subsampled::CannotForce,
        (false, _) => Subsampled::No,
    })
}

/// `xrCreateSwapchain`: takes the foveation structs fovea provides out of a copied chain, checks
/// them, and records the swapchain's layout and foveation state.
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
                return Ok(observed(&state, f(sess, info, out)));
            }
            let exts = state.instance.extensions;
            let i = &*info;
            let provided_fov = exts.provided(Ext::Foveation);
            let provided_meta = exts.provided(Ext::MetaVulkanSwapchainCreateInfo);
            let mut req = FoveationRequest::default();
            if provided_fov {
                let fov = ffi::find_in_chain::<xr::SwapchainCreateInfoFoveationFB>(
                    i.next,
                    xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
                )
                .map_err(|_| xr::Result::ERROR_VALIDATION_FAILURE)?;
                if let Some(fov) = fov {
                    req.foveation = true;
                    req.flags = (*fov).flags.into_raw();
                }
            }
            if provided_meta {
                let meta = ffi::find_in_chain::<ffi::VulkanSwapchainCreateInfoMETA>(
                    i.next,
                    ffi::TYPE_VULKAN_SWAPCHAIN_CREATE_INFO_META,
                )
                .map_err(|_| xr::Result::ERROR_VALIDATION_FAILURE)?;
                req.meta =
                    meta.map(|m| ((*m).additional_create_flags, (*m).additional_usage_flags));
            }
            match check_request(req, state.instance.overrides.current().subsampled)? {
                Subsampled::Dropped => tracing::warn!(
                    "VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT dropped: the runtime allocates the images \
                     and cannot make them subsampled"
                ),
                Subsampled::Off => tracing::info!(
                    "VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT off: debug.oculus.foveation.subsampled=0"
                ),
                Subsampled::CannotForce => tracing::warn!(
                    "debug.oculus.foveation.subsampled=1 cannot be honoured: the runtime \
                     allocates the images"
                ),
                Subsampled::No => {}
            }
            // Structs of extensions fovea provides are unknown below: take them out of a copy.
            let chain = ffi::ChainCopy::without(i.next, |t| {
                (provided_fov && t == xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB)
                    || (provided_meta && t == ffi::TYPE_VULKAN_SWAPCHAIN_CREATE_INFO_META)
            })
            .map_err(|_| xr::Result::ERROR_VALIDATION_FAILURE)?;
            if !chain.removed().is_empty() {
                tracing::debug!(removed = ?chain.removed(), "provided extensions' structs kept from the runtime");
            }
            let mut down = *i;
            down.next = chain.head();
            let r = observed(&state, f(sess, &down, out));
            if succeeded(r) {
                let density = if req.flags & FRAGMENT_DENSITY_MAP_BIT != 0
                    && exts.provided(Ext::FoveationVulkan)
                {
                    density_images(&state, *out, i)
                } else {
                    None
                };
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
                    foveation: req.foveation.then(|| Mutex::new(FoveationState::default())),
                    density,
                    submitted: Mutex::default(),
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

/// `xrDestroySwapchain`: forgets the swapchain; its density images and their Vulkan objects are
/// destroyed with the record, after the runtime destroyed its images. The record leaves the registry
/// before the call goes down (a handle value the runtime reuses at once cannot meet it) and goes
/// back where the runtime refuses, since the swapchain then still lives.
pub unsafe extern "system" fn destroy_swapchain(handle: xr::Swapchain) -> xr::Result {
    guard("xrDestroySwapchain", || {
        finish((|| {
            let state = swapchain(handle)?;
            let f = next(state.session.instance.next.destroy_swapchain)?;
            let Some(record) = registry().swapchains.write().remove(&handle.into_raw()) else {
                // Another thread destroyed it meanwhile (the application broke external
                // synchronisation): the handle is gone.
                return Err(xr::Result::ERROR_HANDLE_INVALID);
            };
            let r = observed(&state.session, f(handle));
            if succeeded(r) {
                if state.foveation.is_some() {
                    state.session.refresh_dynamic_max();
                }
            } else {
                registry()
                    .swapchains
                    .write()
                    .insert(handle.into_raw(), record);
            }
            Ok(r)
        })())
    })
}

/// `xrEnumerateSwapchainImages`: the runtime fills the images; then, on a swapchain with density
/// images, every XrSwapchainImageFoveationVulkanFB chained on an XrSwapchainImageVulkanKHR element
/// gets the density image of that index and its size (fb_foveation_vulkan.adoc). Those are output
/// structs, the only ones fovea writes. Capacity 0 (the count query of the two-call idiom) writes
/// nothing.
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
            let r = observed(&state.session, f(handle, capacity, count, images));
            let Some(density) = &state.density else {
                return Ok(r);
            };
            if !succeeded(r) || capacity == 0 || images.is_null() || count.is_null() {
                return Ok(r);
            }
            if (*images).ty != xr::StructureType::SWAPCHAIN_IMAGE_VULKAN_KHR {
                return Ok(r);
            }
            let n = (*count).min(capacity) as usize;
            let elements = images as *mut xr::SwapchainImageVulkanKHR;
            for i in 0..n.min(density.count()) {
                let element = &*elements.add(i);
                let found = ffi::find_in_chain::<xr::SwapchainImageFoveationVulkanFB>(
                    element.next,
                    xr::StructureType::SWAPCHAIN_IMAGE_FOVEATION_VULKAN_FB,
                )
                .map_err(|_| xr::Result::ERROR_VALIDATION_FAILURE)?;
                if let (Some(out), Some(image)) = (found, density.image(i)) {
                    let out = out as *mut xr::SwapchainImageFoveationVulkanFB;
                    (*out).image = image;
                    (*out).width = density.extent[0];
                    (*out).height = density.extent[1];
                }
            }
            Ok(r)
        })())
    })
}

/// `xrAcquireSwapchainImage`: once the runtime has handed out the index, that index's density image
/// is refreshed if the swapchain's foveation state or the located FOVs changed since it was filled.
/// xrAcquireSwapchainImage is one of the calls where the application synchronises its queue for the
/// runtime (XR_KHR_vulkan_enable, "Concurrency"), and the upload is finished before the call returns,
/// because by default the map is read when the application records its render pass
/// (openxr-layer-facts.md §4). With nothing changed this costs four uncontended locks and a key compare.
pub unsafe extern "system" fn acquire_swapchain_image(
    handle: xr::Swapchain,
    info: *const xr::SwapchainImageAcquireInfo,
    index: *mut u32,
) -> xr::Result {
    guard("xrAcquireSwapchainImage", || {
        finish((|| {
            let state = swapchain(handle)?;
            let f = next(state.session.instance.next.acquire_swapchain_image)?;
            let r = observed(&state.session, f(handle, info, index));
            if let (Some(density), true) = (&state.density, succeeded(r) && !index.is_null()) {
                refresh_density(&state, density, *index);
            }
            Ok(r)
        })())
    })
}

/// Refreshes one density image; a failure is logged and the acquire still succeeds (fail open).
/// The map holds the swapchain's effective pattern (its state under the debug overrides and the
/// dynamic step) for the FOVs the application renders with; in symmetric-FOV mode each eye's own
/// FOV is what is shown.
unsafe fn refresh_density(state: &Swapchain, density: &DensityImages, index: u32) {
    let session = &state.session;
    let foveation = state
        .foveation
        .as_ref()
        .map(|f| *f.lock())
        .unwrap_or_default();
    // One record lock at a time (crate::common::lock::Rank): each guard ends with its statement.
    let located = *session.views.lock();
    let submitted = *state.submitted.lock();
    let sources = MapSources {
        foveation,
        located,
        pattern_generation: session.pattern_generation.load(Ordering::Relaxed),
        submitted,
    };
    let key = sources.key();
    // Read before the fill lock is taken: the FOVs sit behind a record lock, which ranks outside
    // it (crate::common::lock::Rank).
    let visible = crate::xr::symmetric::active(session)
        .then(|| session.instance.stereo_fovs())
        .flatten();
    let inputs = || {
        // Only when the image is stale: the debug properties rank below the fill lock.
        let (pattern, _) = session.pattern_for(&sources.foveation);
        sources.inputs(
            pattern,
            [state.info.width, state.info.height],
            density.layers,
            visible,
        )
    };
    match density.refresh(index, key, inputs) {
        Ok(Refreshed::Nothing) => {}
        Ok(done) => {
            if done == Refreshed::Built {
                session.maps_built.fetch_add(1, Ordering::Relaxed);
            }
            session.maps_uploaded.fetch_add(1, Ordering::Relaxed);
            tracing::debug!(index, ?key, ?done, "density image refreshed");
        }
        Err(e) => tracing::warn!(error = %e, index, "density image not refreshed"),
    }
}

/// `XR_SWAPCHAIN_CREATE_FOVEATION_FRAGMENT_DENSITY_MAP_BIT_FB`.
const FRAGMENT_DENSITY_MAP_BIT: u64 = 0x2;

/// The density images for a new FRAGMENT_DENSITY_MAP swapchain on a session with fovea's Vulkan
/// objects, one per swapchain image (the runtime is asked for the count). `None`, with a warning,
/// where they cannot be made: the swapchain then works without them.
///
/// # Safety
/// `handle` must be the swapchain the runtime just created from `info`.
unsafe fn density_images(
    session: &Session,
    handle: xr::Swapchain,
    info: &xr::SwapchainCreateInfo,
) -> Option<DensityImages> {
    let Some(gpu) = &session.gpu else {
        if session.vulkan.is_some() {
            tracing::warn!("no Vulkan objects for this session; swapchain without density images");
        }
        return None;
    };
    let enumerate = session.instance.next.enumerate_swapchain_images?;
    let mut count = 0;
    let r = enumerate(handle, 0, &mut count, std::ptr::null_mut());
    if !succeeded(r) || count == 0 {
        tracing::warn!(?r, "cannot count the swapchain's images; no density images");
        return None;
    }
    match DensityImages::new(gpu, [info.width, info.height], info.array_size, count) {
        Ok(d) => {
            tracing::info!(
                count,
                extent = ?d.extent,
                layers = d.layers,
                "density images created"
            );
            Some(d)
        }
        Err(e) => {
            tracing::warn!(error = %e, "swapchain without density images");
            None
        }
    }
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
            Ok(observed(&state.session, f(handle, info)))
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
            Ok(observed(&state.session, f(handle, info)))
        })())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_fovea_can_and_cannot_honour() {
        let req = |flags, meta| FoveationRequest {
            foveation: true,
            flags,
            meta,
        };
        let ok = |flags, meta| check_request(req(flags, meta), None);
        let sub = Some((VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT, 0));
        assert_eq!(ok(0x2, None), Ok(Subsampled::No));
        assert_eq!(ok(0x0, sub), Ok(Subsampled::Dropped));
        assert_eq!(
            check_request(req(0x2, sub), Some(false)),
            Ok(Subsampled::Off)
        );
        assert_eq!(
            check_request(req(0x2, sub), Some(true)),
            Ok(Subsampled::Dropped)
        );
        assert_eq!(
            check_request(req(0x2, None), Some(true)),
            Ok(Subsampled::CannotForce)
        );
        let plain = FoveationRequest::default();
        assert_eq!(check_request(plain, Some(true)), Ok(Subsampled::No));
        assert_eq!(ok(0x1, None), Err(xr::Result::ERROR_VALIDATION_FAILURE));
        assert_eq!(ok(0x4, None), Err(xr::Result::ERROR_VALIDATION_FAILURE));
        assert_eq!(
            ok(0x2, Some((0, 0x200))),
            Err(xr::Result::ERROR_FEATURE_UNSUPPORTED)
        );
        assert_eq!(
            ok(0x2, Some((0x1, 0))),
            Err(xr::Result::ERROR_FEATURE_UNSUPPORTED)
        );
    }
}
