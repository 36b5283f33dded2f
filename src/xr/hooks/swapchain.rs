//! Swapchain lifetime and image access.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use ash::vk;
use openxr_sys as xr;
use xr::Handle;

use crate::common::lock::Mutex;

use crate::xr::density_images::{DensityImages, Foveas, Refreshed};
use crate::xr::extensions::Ext;
use crate::xr::ffi::HookResult;
use crate::xr::ffi::{self, In, Out, OutArray};
use crate::xr::foveation::{FoveationState, MapSources};
use crate::xr::next_layer::next;
use crate::xr::registry::{observed, session, swapchain, swapchain_for_call};
use crate::xr::registry::{registry, Session, Swapchain, SwapchainInfo};
use crate::xr::values::succeeded;

/// What the foveation structs in a swapchain create info ask for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FoveationRequest {
    /// `XrSwapchainCreateInfoFoveationFB` was chained.
    pub foveation: bool,
    /// Its flags.
    pub flags: xr::SwapchainCreateFoveationFlagsFB,
    /// `XrVulkanSwapchainCreateInfoMETA`'s flags, when chained.
    pub meta: Option<(vk::ImageCreateFlags, vk::ImageUsageFlags)>,
}

/// Who foveates a new swapchain, as far as fovea can tell when it is created.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Foveator {
    /// Nobody fovea knows of: no density images of fovea's and no injection (an application that
    /// asks for subsampled images foveates them with density maps of its own).
    Nobody,
    /// The application, with the FB profiles it applies and the density images fovea hands it
    /// (`XR_FB_foveation_vulkan`'s `FRAGMENT_DENSITY_MAP`).
    Profiles,
    /// fovea, with the shading rates it injects into the eye passes of an application that never
    /// asked (docs/injection.md).
    Injected,
}

/// What decides whether a swapchain's coarse blocks are reconstructed
/// (docs/openxr-layer.md#subsampled-images).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SubsampledInputs {
    /// `VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT` in the application's `XrVulkanSwapchainCreateInfoMETA`.
    pub asked: bool,
    /// Quest's `debug.oculus.foveation.subsampled`: forced on or off.
    pub property: Option<bool>,
    /// The application's `subsampled` setting (fovea.toml or `FOVEA_SUBSAMPLED`).
    pub setting: Option<bool>,
    pub foveator: Foveator,
    /// A colour swapchain of a Vulkan session: the only kind whose images fovea's Vulkan layer
    /// draws into and can reconstruct.
    pub vulkan_colour: bool,
    /// The session's VkDevice enabled `imagelessFramebuffer` (known where it was created through
    /// `xrCreateVulkanDeviceKHR`) and fovea's Vulkan layer does not hide the added usage from the
    /// application's views on it: the application names the usage it expects of each image its
    /// framebuffers bind, which must equal its view's
    /// (VUID-VkRenderPassBeginInfo-framebuffer-04627), so the usage reconstruction adds would
    /// break its render passes.
    pub imageless: bool,
}

/// What decided a swapchain's reconstruction, for its log line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Why {
    /// `debug.oculus.foveation.subsampled`, which wins over everything (Quest's debug override).
    Property,
    /// The application's `subsampled` setting.
    Setting,
    /// The application asked for subsampled images.
    Asked,
    /// The default for an injected swapchain: on.
    Injected,
    /// The default for a swapchain the application foveates and asked nothing for: off, as the
    /// application asks.
    NotAsked,
    /// Asked for, but not a colour swapchain of a Vulkan session.
    NotVulkanColour,
    /// The runtime refused the transfer usage reconstruction needs.
    UsageRefused,
    /// Decided on only once the swapchain was made without the transfer usage it needs.
    CreatedWithoutUsage,
    /// On by a switch, but the application's device uses imageless framebuffers, which the added
    /// usage would break.
    Imageless,
}

/// The decision for one swapchain: reconstruct or not, and why.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Reconstruction {
    pub on: bool,
    pub why: Why,
}

/// Whether a swapchain's coarse blocks are reconstructed (docs/openxr-layer.md#subsampled-images):
/// Quest's debug property over the application's setting over its request over the default, which
/// is the request for a swapchain the application foveates itself and on for an injected one.
/// `None` where there is nothing to decide: nobody foveates the swapchain and the application asked
/// nothing, or it asked nothing for a swapchain fovea's Vulkan layer does not draw into. Such a
/// swapchain keeps what the application asked for, unchanged (docs/ARCHITECTURE.md: do no harm).
pub fn decide(i: SubsampledInputs) -> Option<Reconstruction> {
    let on = |why| Some(Reconstruction { on: true, why });
    let off = |why| Some(Reconstruction { on: false, why });
    if !i.vulkan_colour {
        return if i.asked {
            off(Why::NotVulkanColour)
        } else {
            None
        };
    }
    if i.foveator == Foveator::Nobody && !i.asked {
        return None;
    }
    let switched = match (i.property, i.setting) {
        (Some(p), _) => Some(Reconstruction {
            on: p,
            why: Why::Property,
        }),
        (None, Some(s)) => Some(Reconstruction {
            on: s,
            why: Why::Setting,
        }),
        (None, None) => None,
    };
    if switched.is_some() {
        return switched_on_unless_imageless(switched, i.imageless);
    }
    let d = if i.asked {
        on(Why::Asked)
    } else if i.foveator == Foveator::Injected {
        on(Why::Injected)
    } else {
        off(Why::NotAsked)
    };
    switched_on_unless_imageless(d, i.imageless)
}

/// An "on" that the application's imageless framebuffers rule out becomes off, whatever switched
/// it on: the added usage would make its render passes invalid (fail safe, not open).
fn switched_on_unless_imageless(
    d: Option<Reconstruction>,
    imageless: bool,
) -> Option<Reconstruction> {
    match d {
        Some(Reconstruction { on: true, .. }) if imageless => Some(Reconstruction {
            on: false,
            why: Why::Imageless,
        }),
        d => d,
    }
}

impl Reconstruction {
    /// The one line a swapchain's decision gets: what happens to its coarse blocks, and why.
    fn log(self) {
        let because = match self.why {
            Why::Property if self.on => "debug.oculus.foveation.subsampled=1",
            Why::Property => "debug.oculus.foveation.subsampled=0",
            Why::Setting if self.on => "subsampled = on (fovea.toml or FOVEA_SUBSAMPLED)",
            Why::Setting => "subsampled = off (fovea.toml or FOVEA_SUBSAMPLED)",
            Why::Asked => {
                "the application asked for VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT, which the runtime's \
                 images cannot have"
            }
            Why::Injected => "fovea injects shading rates into it (the default there)",
            Why::NotAsked => "the application did not ask for subsampled images",
            Why::UsageRefused => "the runtime refused the transfer usage it needs",
            Why::Imageless => {
                "the application's VkDevice enabled imagelessFramebuffer, and the transfer usage \
                 reconstruction needs would make its framebuffers' attachment usage wrong \
                 (VUID-VkRenderPassBeginInfo-framebuffer-04627)"
            }
            Why::CreatedWithoutUsage => {
                "it was created without the transfer usage reconstruction needs (its density \
                 images could not be made, and injection took it over)"
            }
            Why::NotVulkanColour => {
                "VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT asked for a swapchain that is not a colour \
                 swapchain of a Vulkan session"
            }
        };
        match (self.on, self.why) {
            (true, _) => tracing::info!(
                "coarse blocks reconstructed by fovea's Vulkan layer, as a subsampled image \
                 sampled bilinearly shows them: {because}"
            ),
            (false, Why::NotAsked) => {
                tracing::debug!("coarse blocks not reconstructed: {because}")
            }
            (false, _) => tracing::info!("coarse blocks not reconstructed: {because}"),
        }
    }
}

/// A loss the application must see as it is: no retry after it.
fn is_loss(r: xr::Result) -> bool {
    r == xr::Result::ERROR_SESSION_LOST || r == xr::Result::ERROR_INSTANCE_LOST
}

/// `XR_SWAPCHAIN_USAGE_TRANSFER_SRC_BIT | XR_SWAPCHAIN_USAGE_TRANSFER_DST_BIT`: reconstruction
/// copies a pass's colour out and draws the result back (docs/openxr-layer.md#subsampled-images).
fn reconstruction_usage() -> xr::SwapchainUsageFlags {
    xr::SwapchainUsageFlags::TRANSFER_SRC | xr::SwapchainUsageFlags::TRANSFER_DST
}

/// The create flags fovea accepts in `XrVulkanSwapchainCreateInfoMETA`: SUBSAMPLED (answered
/// with reconstruction, [`decide`]) and FRAGMENT_DENSITY_MAP_OFFSET, which says the application moves the fovea itself
/// with density-map offsets (fovea keeps its maps fixed, docs/eye-tracking.md#what-moves-when).
const META_CREATE_FLAGS: vk::ImageCreateFlags = vk::ImageCreateFlags::from_raw(
    vk::ImageCreateFlags::SUBSAMPLED_EXT.as_raw()
        | vk::ImageCreateFlags::FRAGMENT_DENSITY_MAP_OFFSET_QCOM.as_raw(),
);

/// Whether a request's `XrVulkanSwapchainCreateInfoMETA` asks for
/// `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT` (the QCOM name's value).
pub fn asks_for_offsets(req: FoveationRequest) -> bool {
    req.meta.is_some_and(|(create, _)| {
        create.contains(vk::ImageCreateFlags::FRAGMENT_DENSITY_MAP_OFFSET_QCOM)
    })
}

/// Checks a request against what fovea can honour without runtime support for the structs:
/// SCALED_BIN is a GLES flag (QCOM_texture_foveated) and a Vulkan or headless session cannot use it;
/// the runtime allocates the images, so additional Vulkan flags cannot be honoured, except
/// SUBSAMPLED, which fovea answers with reconstruction instead ([`decide`],
/// docs/openxr-layer.md#subsampled-images), and FRAGMENT_DENSITY_MAP_OFFSET, which changes what
/// fovea does with its maps, not the images ([`asks_for_offsets`]). `Ok(asked)`: whether SUBSAMPLED
/// was asked for.
pub fn check_request(req: FoveationRequest) -> HookResult<bool> {
    use xr::SwapchainCreateFoveationFlagsFB as F;
    if !(F::SCALED_BIN | F::FRAGMENT_DENSITY_MAP).contains(req.flags) {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    if req.flags.contains(F::SCALED_BIN) {
        tracing::warn!("XR_SWAPCHAIN_CREATE_FOVEATION_SCALED_BIN_BIT_FB needs OpenGL ES; this is not a GLES session");
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    let Some((create, usage)) = req.meta else {
        return Ok(false);
    };
    if !usage.is_empty() || !META_CREATE_FLAGS.contains(create) {
        tracing::warn!(
            ?create,
            ?usage,
            "additional Vulkan swapchain flags the runtime cannot honour"
        );
        return Err(xr::Result::ERROR_FEATURE_UNSUPPORTED);
    }
    Ok(create.contains(vk::ImageCreateFlags::SUBSAMPLED_EXT))
}

/// `xrCreateSwapchain`: takes the foveation structs fovea provides out of a copied chain, checks
/// them, and records the swapchain's layout and foveation state.
pub fn create_swapchain(
    sess: xr::Session,
    info: In<xr::SwapchainCreateInfo>,
    out: Out<xr::Swapchain>,
) -> HookResult<xr::Result> {
    let state = session(sess)?;
    let f = next(state.instance.next.create_swapchain)?;
    let (Some(i), false) = (info.get(), out.is_null()) else {
        // SAFETY: the next layer's xrCreateSwapchain, with the application's arguments as it
        // passed them.
        return Ok(observed(&state, unsafe { f(sess, info.raw(), out.raw()) }));
    };
    let exts = state.instance.extensions;
    let provided_fov = exts.provided(Ext::Foveation);
    let provided_meta = exts.provided(Ext::MetaVulkanSwapchainCreateInfo);
    let invalid = |_| xr::Result::ERROR_VALIDATION_FAILURE;
    let mut req = FoveationRequest::default();
    if provided_fov {
        if let Some(fov) = info
            .chained::<xr::SwapchainCreateInfoFoveationFB>()
            .map_err(invalid)?
        {
            req.foveation = true;
            req.flags = fov.flags;
        }
    }
    if provided_meta {
        let meta = info
            .chained::<ffi::VulkanSwapchainCreateInfoMETA>()
            .map_err(invalid)?;
        req.meta = meta.map(|m| (m.additional_create_flags, m.additional_usage_flags));
    }
    let asked = check_request(req)?;
    let fdm_asked = req
        .flags
        .contains(xr::SwapchainCreateFoveationFlagsFB::FRAGMENT_DENSITY_MAP)
        && exts.provided(Ext::FoveationVulkan);
    let imageless = state.vulkan.as_ref().is_some_and(|b| {
        // Where fovea's Vulkan layer hides the added usage from the application's views
        // (docs/reconstruction.md#usage-the-application-does-not-see), its imageless
        // framebuffers name the usage it asked for, and the added usage breaks nothing.
        state.instance.vulkan.lock().imageless(b.device)
            && !crate::bridge::subsampled::hides_usage(b.device)
    });
    let inputs = |foveator| SubsampledInputs {
        asked,
        property: state.instance.overrides.current().subsampled,
        setting: state.instance.subsampled,
        foveator,
        imageless,
        vulkan_colour: state.vulkan.is_some()
            && i.usage_flags
                .contains(xr::SwapchainUsageFlags::COLOR_ATTACHMENT)
            && i.face_count == 1,
    };
    // Who will foveate it, foretold: density images are made once the runtime made the swapchain.
    let foretold = if fdm_asked && state.gpu.is_some() {
        Foveator::Profiles
    } else if state.instance.inject.is_some() {
        Foveator::Injected
    } else {
        Foveator::Nobody
    };
    let planned = decide(inputs(foretold));
    // Structs of extensions fovea provides are unknown below: take them out of a copy.
    let chain = info
        .chain_without(|t| {
            (provided_fov && t == xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB)
                || (provided_meta && t == xr::StructureType::VULKAN_SWAPCHAIN_CREATE_INFO_META)
        })
        .map_err(invalid)?;
    if !chain.removed().is_empty() {
        tracing::debug!(removed = ?chain.removed(), "provided extensions' structs kept from the runtime");
    }
    let mut down = *i;
    down.next = chain.head();
    // Reconstruction copies the colour out and back: the runtime is asked for transfer usage on a
    // copy of the create info (the application's struct is never written).
    let added = match planned {
        Some(Reconstruction { on: true, .. }) => reconstruction_usage() & !i.usage_flags,
        _ => xr::SwapchainUsageFlags::EMPTY,
    };
    down.usage_flags |= added;
    // SAFETY: the next layer's xrCreateSwapchain, with a copy of the application's create info
    // whose chain `chain` keeps alive, and the application's output pointer.
    let mut r = observed(&state, unsafe { f(sess, &down, out.raw()) });
    let mut refused = false;
    if !succeeded(r) && added != xr::SwapchainUsageFlags::EMPTY && !is_loss(r) {
        // A runtime that cannot give the usage refuses the swapchain (XR_ERROR_FEATURE_UNSUPPORTED
        // in the spec, others in practice): the application gets its swapchain as it asked,
        // without reconstruction (fail open).
        tracing::warn!(
            ?r,
            ?added,
            "the runtime refused the transfer usage reconstruction needs; the swapchain is \
             created as the application asked, its coarse blocks not reconstructed"
        );
        down.usage_flags = i.usage_flags;
        refused = true;
        // SAFETY: as above, with the application's own usage.
        r = observed(&state, unsafe { f(sess, &down, out.raw()) });
    }
    let Some(handle) = out.read().filter(|_| succeeded(r)) else {
        return Ok(r);
    };
    let app_offsets = asks_for_offsets(req);
    let density = if fdm_asked {
        density_images(&state, handle, i, app_offsets)
    } else {
        None
    };
    // Who foveates it now that the density images are made or not: injection takes a swapchain
    // without them.
    let foveator = if density.is_some() {
        Foveator::Profiles
    } else if state.instance.inject.is_some() {
        Foveator::Injected
    } else {
        Foveator::Nobody
    };
    let decision = if refused {
        Some(Reconstruction {
            on: false,
            why: Why::UsageRefused,
        })
    } else {
        // On only where the runtime was asked for the usage it needs: the foretold decision can
        // be off where this one is on (density images that could not be made leave the
        // swapchain to injection).
        decide(inputs(foveator)).map(|d| {
            match d.on && !down.usage_flags.contains(reconstruction_usage()) {
                true => Reconstruction {
                    on: false,
                    why: Why::CreatedWithoutUsage,
                },
                false => d,
            }
        })
    };
    if let Some(d) = decision {
        d.log();
    }
    let takes = takes_profiles(&state, req);
    let record = Swapchain {
        handle,
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
        foveation: takes.then(|| Mutex::new(FoveationState::default())),
        density,
        submitted: Mutex::default(),
        app_offsets,
        reconstruct: decision.map(|d| d.on),
        added_usage: xr::SwapchainUsageFlags::from_raw(
            down.usage_flags.into_raw() & !i.usage_flags.into_raw(),
        ),
        published: Mutex::default(),
    };
    if record.app_offsets {
        tracing::info!(
            "the application applies density-map offsets to this swapchain itself: its maps stay \
             fixed"
        );
    }
    let injected = record.session.instance.inject.is_some();
    let info = record.info;
    let own = record.density.is_some();
    registry()
        .swapchains
        .write()
        .insert(handle.into_raw(), Arc::new(record));
    if injected {
        publish_eye_swapchain(handle, &info, own);
    }
    Ok(r)
}

/// Whether profiles may be applied to a new swapchain: one created with
/// `XrSwapchainCreateInfoFoveationFB`, and on a Vulkan session of an instance fovea injects into
/// (docs/openxr-layer.md#swapchains-without-foveation-info), any swapchain where the application
/// enabled XR_FB_foveation: XR_FB_foveation's create flags only ask for the swapchain to be created
/// with foveation support ("explicitly create the swapchain with ... support",
/// https://registry.khronos.org/OpenXR/specs/1.1/man/html/XrSwapchainCreateFoveationFlagBitsFB.html),
/// and nothing forbids a runtime to foveate a swapchain made without them in its own way, which on
/// Vulkan is fovea's injection.
fn takes_profiles(session: &Session, req: FoveationRequest) -> bool {
    let exts = &session.instance.extensions;
    req.foveation
        || (exts.enabled.contains(Ext::Foveation)
            && exts.provided(Ext::Foveation)
            && session.vulkan.is_some()
            && session.instance.inject.is_some())
}

/// `XR_SWAPCHAIN_USAGE_COLOR_ATTACHMENT_BIT`.
const COLOR_ATTACHMENT: u64 = 0x1;

/// What a new colour swapchain's images hold, guessed before the application first submits it
/// (docs/injection.md#which-passes): an array holds one view per layer; an image at least 1.5 times
/// as wide as high is double-wide (no headset's eye is that wide); otherwise it is the next eye's
/// of the per-eye swapchains of that size (applications create them in view order). `xrEndFrame`
/// corrects the guess from what is submitted.
pub fn guess_holds(
    info: &SwapchainInfo,
    earlier: &[fovea_model::inject::Swapchain],
) -> Option<fovea_model::inject::Holds> {
    use fovea_model::inject::Holds;
    if info.usage & COLOR_ATTACHMENT == 0 || info.face_count != 1 || info.height == 0 {
        return None;
    }
    if info.array_size >= 2 {
        return Some(Holds::Layers);
    }
    if f64::from(info.width) >= 1.5 * f64::from(info.height) {
        return Some(Holds::Halves);
    }
    let eye = earlier
        .iter()
        .filter(|s| s.extent == [info.width, info.height] && matches!(s.holds, Holds::View(_)))
        .count();
    Some(Holds::View(eye.min(usize::from(u8::MAX)) as u8))
}

/// Publishes a new swapchain for injection where it may hold views; `own`: it has density images,
/// and the application foveates it itself.
fn publish_eye_swapchain(handle: xr::Swapchain, info: &SwapchainInfo, own: bool) {
    let earlier: Vec<_> = crate::bridge::inject::current()
        .map(|s| s.swapchains.iter().map(|e| e.shape).collect())
        .unwrap_or_default();
    if let Some(holds) = guess_holds(info, &earlier) {
        crate::bridge::inject::set_swapchain(
            handle.into_raw(),
            fovea_model::inject::Swapchain {
                extent: [info.width, info.height],
                layers: info.array_size,
                holds,
            },
            own,
        );
    }
}

/// `xrDestroySwapchain`: forgets the swapchain; its density images and their Vulkan objects are
/// destroyed with the record, after the runtime destroyed its images. The record leaves the registry
/// before the call goes down (a handle value the runtime reuses at once cannot meet it) and goes
/// back where the runtime refuses, since the swapchain then still lives.
pub fn destroy_swapchain(handle: xr::Swapchain) -> HookResult<xr::Result> {
    let state = swapchain(handle)?;
    let f = next(state.session.instance.next.destroy_swapchain)?;
    let Some(record) = registry().swapchains.write().remove(&handle.into_raw()) else {
        // Another thread destroyed it meanwhile (the application broke external
        // synchronisation): the handle is gone.
        return Err(xr::Result::ERROR_HANDLE_INVALID);
    };
    // SAFETY: the next layer's xrDestroySwapchain, with the application's handle.
    let r = observed(&state.session, unsafe { f(handle) });
    if succeeded(r) {
        state.forget_published();
        if state.foveation.is_some() {
            crate::xr::pattern::refresh_dynamic_max(&state.session);
        }
        if state.session.instance.inject.is_some() {
            crate::bridge::inject::remove_swapchain(handle.into_raw());
        }
    } else {
        registry()
            .swapchains
            .write()
            .insert(handle.into_raw(), record);
    }
    Ok(r)
}

/// `xrEnumerateSwapchainImages`: the runtime fills the images; then, on a swapchain with density
/// images, every XrSwapchainImageFoveationVulkanFB chained on an XrSwapchainImageVulkanKHR element
/// gets the density image of that index and its size
/// (https://registry.khronos.org/OpenXR/specs/1.0/man/html/XrSwapchainImageFoveationVulkanFB.html).
/// Those are output structs, the only ones fovea writes. Capacity 0 (the count query of the
/// two-call idiom) writes nothing.
pub fn enumerate_swapchain_images(
    handle: xr::Swapchain,
    capacity: u32,
    count: Out<u32>,
    images: OutArray<xr::SwapchainImageBaseHeader>,
) -> HookResult<xr::Result> {
    let state = swapchain(handle)?;
    let f = next(state.session.instance.next.enumerate_swapchain_images)?;
    // SAFETY: the next layer's function, with the application's arguments as it passed them.
    let r = unsafe { f(handle, capacity, count.raw(), images.raw()) };
    let r = observed(&state.session, r);
    let injected = state.session.instance.inject.is_some();
    if (injected || state.reconstruct.is_some()) && succeeded(r) && capacity > 0 {
        if let Some(raw) = vulkan_images(&state, capacity, &count, &images) {
            if injected {
                crate::bridge::inject::set_images(state.handle.into_raw(), &raw);
            }
            state.publish(&raw);
        }
    }
    let Some(density) = &state.density else {
        return Ok(r);
    };
    if !succeeded(r) || capacity == 0 {
        return Ok(r);
    }
    let Some(n) = count.read() else {
        return Ok(r);
    };
    let n = n.min(capacity) as usize;
    let Some(elements) = images.cast_slice::<xr::SwapchainImageVulkanKHR>(n) else {
        return Ok(r);
    };
    for (i, element) in elements.iter().enumerate().take(density.count()) {
        // SAFETY: the element's chain is the application's output chain, valid for the call
        // (the array's contract, `OutArray`); a node of the foveation type is that struct.
        let found = unsafe {
            ffi::find_in_chain::<xr::SwapchainImageFoveationVulkanFB>(
                element.next,
                xr::StructureType::SWAPCHAIN_IMAGE_FOVEATION_VULKAN_FB,
            )
        }
        .map_err(|_| xr::Result::ERROR_VALIDATION_FAILURE)?;
        if let (Some(out), Some(image)) = (found, density.image(i)) {
            let out = out as *mut xr::SwapchainImageFoveationVulkanFB;
            // SAFETY: an output struct of the application's, writable for the call; only its
            // output members are written.
            unsafe {
                (*out).image = image;
                (*out).width = density.extent[0];
                (*out).height = density.extent[1];
            }
        }
    }
    Ok(r)
}

/// The `VkImage`s a Vulkan swapchain's enumeration returned, for the Vulkan side: injection knows
/// passes into them (docs/injection.md#which-passes), reconstruction its decision for them
/// (docs/openxr-layer.md#subsampled-images). `None` where the array does not hold
/// `XrSwapchainImageVulkanKHR`s.
fn vulkan_images(
    state: &Swapchain,
    capacity: u32,
    count: &Out<u32>,
    images: &OutArray<xr::SwapchainImageBaseHeader>,
) -> Option<Vec<u64>> {
    state.session.vulkan.as_ref()?;
    let n = count.read()?.min(capacity) as usize;
    // SAFETY: the application's array as the caller's `OutArray` holds it (valid for `capacity`
    // elements for the call); this view of it ends before the caller uses its own again.
    let images = unsafe { OutArray::new(images.raw(), images.capacity()) };
    let elements = images.cast_slice::<xr::SwapchainImageVulkanKHR>(n)?;
    if elements
        .iter()
        .any(|e| e.ty != xr::StructureType::SWAPCHAIN_IMAGE_VULKAN_KHR)
    {
        return None;
    }
    Some(elements.iter().map(|e| e.image).collect())
}

/// `xrAcquireSwapchainImage`: once the runtime has handed out the index, that index's density image
/// is refreshed if the swapchain's foveation state or the located FOVs changed since it was filled.
/// xrAcquireSwapchainImage is one of the calls where the application synchronises its queue for the
/// runtime (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#XR_KHR_vulkan_enable,
/// "Concurrency"), and the upload is finished before the call returns, because by default the map is
/// read when the application records its render pass
/// (without VK_IMAGE_VIEW_CREATE_FRAGMENT_DENSITY_MAP_DYNAMIC_BIT_EXT, the host reads it during
/// vkCmdBeginRenderPass:
/// https://registry.khronos.org/vulkan/specs/latest/man/html/VkImageViewCreateFlagBits.html). With nothing changed this costs four uncontended locks and a key
/// compare.
pub fn acquire_swapchain_image(
    handle: xr::Swapchain,
    info: In<xr::SwapchainImageAcquireInfo>,
    index: Out<u32>,
) -> HookResult<xr::Result> {
    let state = swapchain_for_call(handle)?;
    let f = next(state.session.instance.next.acquire_swapchain_image)?;
    // SAFETY: the next layer's function, with the application's arguments as it passed them.
    let r = observed(&state.session, unsafe {
        f(handle, info.raw(), index.raw())
    });
    if let (Some(density), true, Some(index)) = (&state.density, succeeded(r), index.read()) {
        refresh_density(&state, density, index);
    }
    Ok(r)
}

/// Refreshes one density image; a failure is logged and the acquire still succeeds (fail open).
/// The map holds the swapchain's effective pattern (its state under the debug overrides and the
/// dynamic step) for the FOVs the application renders with; in symmetric-FOV mode each eye's own
/// FOV is what is shown.
fn refresh_density(state: &Swapchain, density: &DensityImages, index: u32) {
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
    let foveas = foveas(state, &sources, density.layers);
    // Read before the fill lock is taken: the FOVs sit behind a record lock, which ranks outside
    // it (crate::common::lock::Rank).
    let visible = crate::xr::symmetric::active(session)
        .then(|| session.instance.stereo_fovs())
        .flatten();
    let inputs = || {
        // Only when the image is stale: the debug properties rank below the fill lock.
        let (pattern, _) = crate::xr::pattern::pattern_for(session, &sources.foveation);
        let cap = session.instance.overrides.current().max_fragment();
        sources
            .inputs(
                pattern,
                [state.info.width, state.info.height],
                density.layers,
                visible,
            )
            .capped(cap)
    };
    // SAFETY: called from xrAcquireSwapchainImage, where the application synchronises the
    // binding's queue for the runtime (`DensityImages::refresh`'s contract).
    match unsafe { density.refresh(index, key, &foveas, inputs) } {
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

/// Where the fovea of each view of a swapchain's maps goes this frame: to the gaze
/// (`Session::eyes`) where the swapchain's current profile is eye-tracked
/// (XR_META_foveation_eye_tracked), the gaze is followed, and the application does not move the
/// fovea itself with density-map offsets; the fixed map's place otherwise. Each view's centre is in
/// NDC of its own FOV, so it is placed with the views the maps are drawn from (submitted, else
/// located). No allocation, one record lock (the gaze's copy) where the profile is eye-tracked.
fn foveas(state: &Swapchain, sources: &MapSources, layers: u32) -> Foveas {
    if !sources.foveation.params.eye_tracked || state.app_offsets {
        return Foveas::FIXED;
    }
    let eyes = *state.session.eyes.lock();
    if !eyes.follows() {
        return Foveas::FIXED;
    }
    let placed = fovea_model::maps::placed(
        [state.info.width, state.info.height],
        layers,
        &sources.submitted.views,
        &sources.located.fovs,
        None,
    );
    let mut centres = [None; fovea_model::maps::MAX_VIEWS];
    for (eye, (c, p)) in centres.iter_mut().zip(&placed).enumerate() {
        if p.is_some() {
            *c = eyes.of(eye);
        }
    }
    Foveas { centres, placed }
}

/// The density images for a new FRAGMENT_DENSITY_MAP swapchain on a session with fovea's Vulkan
/// objects, one per swapchain image (the runtime is asked for the count). `None`, with a warning,
/// where they cannot be made: the swapchain then works without them.
///
/// `handle` is the swapchain the runtime just created from `info`.
fn density_images(
    session: &Session,
    handle: xr::Swapchain,
    info: &xr::SwapchainCreateInfo,
    app_offsets: bool,
) -> Option<DensityImages> {
    let Some(gpu) = &session.gpu else {
        if session.vulkan.is_some() {
            tracing::warn!("no Vulkan objects for this session; swapchain without density images");
        }
        return None;
    };
    let flags = offset_flags(app_offsets, gpu.offsets);
    let enumerate = session.instance.next.enumerate_swapchain_images?;
    let mut count = 0;
    // SAFETY: the next layer's function on a swapchain it just created; capacity 0 writes only
    // the count, into a local.
    let r = unsafe { enumerate(handle, 0, &mut count, std::ptr::null_mut()) };
    if !succeeded(r) || count == 0 {
        tracing::warn!(?r, "cannot count the swapchain's images; no density images");
        return None;
    }
    // SAFETY: the session's device outlives it (the application must keep it alive).
    match unsafe {
        DensityImages::new(
            gpu,
            [info.width, info.height],
            info.array_size,
            count,
            flags,
        )
    } {
        Ok(d) => {
            tracing::info!(
                count,
                extent = ?d.extent,
                layers = d.layers,
                ?flags,
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

/// The create flags of fovea's density images for a swapchain whose application applies
/// density-map offsets itself (`app_offsets`) on a device where offsets reach density maps
/// (`device_offsets`, [`crate::xr::session_gpu::SessionGpu::offsets`]):
/// `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT`, without which the offsets its passes end
/// with do not apply to them (and are invalid on a driver that has the extension). Where the
/// device did not enable an offset extension, fovea's Vulkan layer cannot apply offsets there (it
/// emulates density maps on a device it cannot convert on), or fovea cannot tell (the flag
/// without the feature is invalid), the images are made as for any swapchain, and the log says once why the application's
/// offsets cannot move them (docs/eye-tracking.md#what-moves-when).
fn offset_flags(app_offsets: bool, device_offsets: Option<bool>) -> vk::ImageCreateFlags {
    static NOT_ENABLED_SAID: AtomicBool = AtomicBool::new(false);
    static UNKNOWN_SAID: AtomicBool = AtomicBool::new(false);
    if !app_offsets {
        return vk::ImageCreateFlags::empty();
    }
    match device_offsets {
        Some(true) => return vk::ImageCreateFlags::FRAGMENT_DENSITY_MAP_OFFSET_QCOM,
        Some(false) if !NOT_ENABLED_SAID.swap(true, Ordering::Relaxed) => tracing::warn!(
            "the application applies density-map offsets to a swapchain, but its VkDevice did \
             not enable VK_EXT_fragment_density_map_offset or VK_QCOM_fragment_density_map_offset \
             with fragmentDensityMapOffset, or fovea's Vulkan layer cannot apply offsets on it \
             (its log said why at vkCreateDevice): fovea's density images cannot take offsets \
             there, and its fovea stays where the fixed maps put it"
        ),
        None if !UNKNOWN_SAID.swap(true, Ordering::Relaxed) => tracing::warn!(
            "the application applies density-map offsets to a swapchain, but fovea cannot tell \
             whether its VkDevice enabled VK_EXT_fragment_density_map_offset (it was created \
             without fovea's Vulkan layer and outside xrCreateVulkanDeviceKHR): fovea's density \
             images are made without VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT, so \
             offsets cannot apply to them, and their fovea stays where the fixed maps put it"
        ),
        Some(false) | None => {}
    }
    vk::ImageCreateFlags::empty()
}

/// `xrWaitSwapchainImage`: passed on.
pub fn wait_swapchain_image(
    handle: xr::Swapchain,
    info: In<xr::SwapchainImageWaitInfo>,
) -> HookResult<xr::Result> {
    let state = swapchain_for_call(handle)?;
    let f = next(state.session.instance.next.wait_swapchain_image)?;
    // SAFETY: the next layer's function, with the application's arguments as it passed them.
    Ok(observed(&state.session, unsafe { f(handle, info.raw()) }))
}

/// `xrReleaseSwapchainImage`: passed on.
pub fn release_swapchain_image(
    handle: xr::Swapchain,
    info: In<xr::SwapchainImageReleaseInfo>,
) -> HookResult<xr::Result> {
    let state = swapchain_for_call(handle)?;
    let f = next(state.session.instance.next.release_swapchain_image)?;
    // SAFETY: the next layer's function, with the application's arguments as it passed them.
    Ok(observed(&state.session, unsafe { f(handle, info.raw()) }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// fovea's density images take offsets only for an application that applies them, on a
    /// device known to take them.
    #[test]
    fn density_images_take_offsets_where_the_device_does() {
        let flag = vk::ImageCreateFlags::FRAGMENT_DENSITY_MAP_OFFSET_QCOM;
        assert_eq!(offset_flags(true, Some(true)), flag);
        for device in [Some(false), None] {
            assert_eq!(offset_flags(true, device), vk::ImageCreateFlags::empty());
        }
        for device in [Some(true), Some(false), None] {
            assert_eq!(offset_flags(false, device), vk::ImageCreateFlags::empty());
        }
    }

    #[test]
    fn what_a_new_swapchain_holds_is_guessed_from_its_shape() {
        use fovea_model::inject::{Holds, Swapchain as Shape};
        let info = |usage: u64, width: u32, height: u32, array_size: u32| SwapchainInfo {
            usage,
            format: 43,
            sample_count: 1,
            width,
            height,
            face_count: 1,
            array_size,
            mip_count: 1,
        };
        let eye = info(COLOR_ATTACHMENT, 1440, 1600, 1);
        assert_eq!(guess_holds(&eye, &[]), Some(Holds::View(0)));
        let first = Shape {
            extent: [1440, 1600],
            layers: 1,
            holds: Holds::View(0),
        };
        assert_eq!(
            guess_holds(&eye, &[first]),
            Some(Holds::View(1)),
            "the second of that size is the second eye"
        );
        assert_eq!(
            guess_holds(&info(COLOR_ATTACHMENT, 1440, 1600, 2), &[]),
            Some(Holds::Layers)
        );
        assert_eq!(
            guess_holds(&info(COLOR_ATTACHMENT, 2880, 1600, 1), &[]),
            Some(Holds::Halves)
        );
        assert_eq!(
            guess_holds(&info(0x2, 1440, 1600, 1), &[]),
            None,
            "a depth swapchain holds no colour target"
        );
        let cube = SwapchainInfo {
            face_count: 6,
            ..eye
        };
        assert_eq!(guess_holds(&cube, &[]), None);
    }

    #[test]
    fn requests_fovea_can_and_cannot_honour() {
        let req = |flags, meta| FoveationRequest {
            foveation: true,
            flags,
            meta,
        };
        let ok = |flags, meta| check_request(req(flags, meta));
        use vk::{ImageCreateFlags as C, ImageUsageFlags as U};
        use xr::SwapchainCreateFoveationFlagsFB as F;
        let fdm = F::FRAGMENT_DENSITY_MAP;
        let sub = Some((C::SUBSAMPLED_EXT, U::empty()));
        assert_eq!(ok(fdm, None), Ok(false));
        assert_eq!(ok(F::EMPTY, sub), Ok(true));
        assert_eq!(ok(fdm, sub), Ok(true));
        assert_eq!(check_request(FoveationRequest::default()), Ok(false));
        assert_eq!(
            ok(F::SCALED_BIN, None),
            Err(xr::Result::ERROR_VALIDATION_FAILURE)
        );
        assert_eq!(
            ok(F::from_raw(1 << 2), None),
            Err(xr::Result::ERROR_VALIDATION_FAILURE)
        );
        assert_eq!(
            ok(fdm, Some((C::empty(), U::FRAGMENT_DENSITY_MAP_EXT))),
            Err(xr::Result::ERROR_FEATURE_UNSUPPORTED)
        );
        assert_eq!(
            ok(fdm, Some((C::SPARSE_BINDING, U::empty()))),
            Err(xr::Result::ERROR_FEATURE_UNSUPPORTED)
        );
        // Density-map offsets: accepted, remembered, and not taken for SUBSAMPLED.
        let offsets = Some((C::FRAGMENT_DENSITY_MAP_OFFSET_QCOM, U::empty()));
        assert_eq!(ok(fdm, offsets), Ok(false));
        assert!(asks_for_offsets(req(fdm, offsets)));
        let both = Some((
            C::FRAGMENT_DENSITY_MAP_OFFSET_QCOM | C::SUBSAMPLED_EXT,
            U::empty(),
        ));
        assert_eq!(ok(fdm, both), Ok(true));
        assert!(!asks_for_offsets(req(fdm, sub)));
        assert!(!asks_for_offsets(req(fdm, None)));
        assert_eq!(
            ok(
                fdm,
                Some((
                    C::FRAGMENT_DENSITY_MAP_OFFSET_QCOM | C::SPARSE_BINDING,
                    U::empty()
                ))
            ),
            Err(xr::Result::ERROR_FEATURE_UNSUPPORTED)
        );
    }

    /// The whole table of docs/openxr-layer.md#subsampled-images: every foveator, request,
    /// property and setting.
    #[test]
    fn reconstruction_is_decided_property_over_setting_over_request_over_default() {
        use Foveator::{Injected, Nobody, Profiles};
        let tri = [None, Some(false), Some(true)];
        for foveator in [Nobody, Profiles, Injected] {
            for asked in [false, true] {
                for property in tri {
                    for setting in tri {
                        let i = SubsampledInputs {
                            asked,
                            property,
                            setting,
                            foveator,
                            vulkan_colour: true,
                            imageless: false,
                        };
                        let got = decide(i);
                        let want = if foveator == Nobody && !asked {
                            // Nobody foveates it and the app asked nothing: nothing at all.
                            None
                        } else if let Some(p) = property {
                            Some((p, Why::Property))
                        } else if let Some(s) = setting {
                            Some((s, Why::Setting))
                        } else if asked {
                            Some((true, Why::Asked))
                        } else if foveator == Injected {
                            Some((true, Why::Injected))
                        } else {
                            Some((false, Why::NotAsked))
                        };
                        assert_eq!(got.map(|d| (d.on, d.why)), want, "{i:?}");
                        // On a device with imageless framebuffers, every "on" is off, and says
                        // why; every other answer stays.
                        let imageless = decide(SubsampledInputs {
                            imageless: true,
                            ..i
                        });
                        let want = match want {
                            Some((true, _)) => Some((false, Why::Imageless)),
                            w => w,
                        };
                        assert_eq!(imageless.map(|d| (d.on, d.why)), want, "{i:?}");
                    }
                }
            }
        }
    }

    /// A depth, cube or headless swapchain is never reconstructed: nothing is decided where the
    /// application asked nothing, whatever forces it on; where it asked, the line says why not.
    #[test]
    fn only_colour_swapchains_of_vulkan_sessions_are_reconstructed() {
        for foveator in [Foveator::Nobody, Foveator::Profiles, Foveator::Injected] {
            for forced in [None, Some(true)] {
                let i = SubsampledInputs {
                    asked: false,
                    property: forced,
                    setting: forced,
                    foveator,
                    vulkan_colour: false,
                    imageless: false,
                };
                assert_eq!(decide(i), None, "{i:?}");
                assert_eq!(
                    decide(SubsampledInputs { asked: true, ..i }),
                    Some(Reconstruction {
                        on: false,
                        why: Why::NotVulkanColour
                    })
                );
            }
        }
    }
}
