//! Devices: `vkCreateDevice` (what reaches the driver, the layer's own calls and the modes set up)
//! and `vkDestroyDevice`.
//!
//! On an emulated physical device, a `vkCreateDevice` that enables `VK_EXT_fragment_density_map`
//! reaches the driver as one that enables `VK_KHR_fragment_shading_rate` with only
//! `attachmentFragmentShadingRate`: the density-map name and feature struct are left out of a copy
//! of the application's create info. The spec makes the two exclusive
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkDeviceCreateInfo.html>,
//! VUID-VkDeviceCreateInfo-fragmentDensityMap-04481), so the layer owns shading rates on such a
//! device outright; an application that enables shading rates itself (or NV shading-rate images)
//! is left alone there, less any density-map name or struct it sent too (Godot sends both). No
//! density-map name or struct ever reaches a driver the layer emulates them on; where one cannot be
//! left out (behind a struct of unknown type), the device is refused
//! (docs/vulkan-fdm-on-fsr.md#device-creation). With injection on
//! (docs/injection.md#switching-it-on), the device that renders the session's views
//! (docs/injection.md#which-devices-get-the-feature) gets the attachment feature, and an
//! application that enables shading rates, attachments included, is injected into; its own
//! attachments win per pass.

use std::ffi::{c_char, CStr};
use std::sync::Arc;

use ash::vk;

use crate::bridge::FdmEmulation;
use crate::vk::base::chain::{self, ChainCopy};
use crate::vk::base::ffi::{key, offset, raw, In, Out};
use crate::vk::base::link::{self, LayerDeviceCreateInfo, LayerDeviceLink};
use crate::vk::base::next::DeviceNext;
use crate::vk::own::calls::{self, Own};
use crate::vk::own::converter::Converter;
use crate::vk::own::injector::Injector;
use crate::vk::own::reconstructor::Reconstructor;
use crate::vk::registry::{self, Decision, Instance};
use crate::vk::{convert, decide, emulation, reconstruct};

/// The loader's `VK_LAYER_LINK_INFO` struct in a device create info.
///
/// # Safety
/// `ci.p_next` must be a valid chain.
unsafe fn device_link(ci: &vk::DeviceCreateInfo<'_>) -> Option<*mut LayerDeviceCreateInfo> {
    let mut next = ci.p_next;
    for _ in 0..chain::MAX_CHAIN_LENGTH {
        // SAFETY: as the caller promised.
        let found = unsafe {
            chain::find::<LayerDeviceCreateInfo>(next, vk::StructureType::LOADER_DEVICE_CREATE_INFO)
        }
        .ok()
        .flatten()?;
        // SAFETY: found in a valid chain, of the type its sType names.
        let f = unsafe { &*found };
        if f.function == link::LAYER_LINK_INFO {
            return Some(found as *mut _);
        }
        next = f.p_next;
    }
    None
}

/// A rewritten device create info and what it points at.
struct Rewrite {
    /// The copied chain: behind `fsr`, or the one the copy points at where `fsr` is `None`.
    chain: ChainCopy,
    names: Vec<*const c_char>,
    /// The layer's feature struct in front of the chain; `None` where the application's own,
    /// enabling attachments, stays in it.
    fsr: Option<Box<vk::PhysicalDeviceFragmentShadingRateFeaturesKHR<'static>>>,
    /// The timeline-semaphore feature, where the layer orders its uploads against several
    /// graphics queues ([`Timelines`]): between `fsr` and `chain`.
    timeline: Option<Timeline>,
}

impl Rewrite {
    /// The head of the rewritten chain.
    fn head(&self) -> *const std::ffi::c_void {
        match (&self.fsr, &self.timeline) {
            (Some(fsr), _) => &**fsr as *const _ as *const _,
            (None, Some(t)) => t.head(),
            (None, None) => self.chain.head(),
        }
    }
}

/// The struct that enables `timelineSemaphore`: the application's Vulkan 1.2 features with it set
/// (a chain may not hold both, VUID-VkDeviceCreateInfo-pNext-02830), or a struct of the layer's
/// own, which stands in for the application's timeline-semaphore struct where it had one (that
/// struct has no other member).
enum Timeline {
    V12(Box<vk::PhysicalDeviceVulkan12Features<'static>>),
    Own(Box<vk::PhysicalDeviceTimelineSemaphoreFeatures<'static>>),
}

impl Timeline {
    fn head(&self) -> *const std::ffi::c_void {
        match self {
            Timeline::V12(f) => &**f as *const _ as *const _,
            Timeline::Own(f) => &**f as *const _ as *const _,
        }
    }

    fn link(&mut self, next: *const std::ffi::c_void) {
        match self {
            Timeline::V12(f) => f.p_next = next as *mut _,
            Timeline::Own(f) => f.p_next = next as *mut _,
        }
    }
}

/// Whether the layer orders its uploads against the application's graphics queues with timeline
/// semaphores ([`crate::vk::own::order`]).
#[derive(Clone, Copy, PartialEq)]
enum Timelines {
    /// One graphics queue at most: its submission order is enough.
    Unneeded,
    /// With `VK_KHR_timeline_semaphore` added to the names where `name`.
    Enable { name: bool },
    /// Several graphics queues, and no timeline semaphores to order them with.
    Unsupported,
}

/// Whether `ty` is a struct that enables the timeline-semaphore feature.
fn timeline_struct(ty: vk::StructureType) -> bool {
    ty == vk::StructureType::PHYSICAL_DEVICE_VULKAN_1_2_FEATURES
        || ty == vk::StructureType::PHYSICAL_DEVICE_TIMELINE_SEMAPHORE_FEATURES
}

/// Decides [`Timelines`] for a device `ci` creates on `physical`, at the device version `version`
/// the application may use: timeline semaphores are core (and required) from Vulkan 1.2; below,
/// `VK_KHR_timeline_semaphore` where the application enables it or the driver has it (the layer
/// adds it then).
///
/// # Safety
/// `physical` must belong to `inst`.
unsafe fn timelines(
    inst: &Instance,
    physical: vk::PhysicalDevice,
    info: In<'_, vk::DeviceCreateInfo<'_>>,
    version: u32,
    enabled: &dyn Fn(&CStr) -> bool,
) -> Timelines {
    // SAFETY: as the caller promised.
    let Some(families) = (unsafe { calls::queue_families(inst.handle, inst.gipa, physical) })
    else {
        return Timelines::Unneeded;
    };
    let Some(ci) = info.get() else {
        return Timelines::Unneeded;
    };
    // SAFETY: the application's create info, valid with its queue create infos ([`In`]).
    let readers: u32 = unsafe { calls::graphics_queues(ci, &families) }
        .map(|(_, n)| n)
        .sum();
    let name = ash::khr::timeline_semaphore::NAME;
    if readers <= 1 {
        Timelines::Unneeded
    } else if version >= vk::API_VERSION_1_2 || enabled(name) {
        Timelines::Enable { name: false }
    } else if version >= vk::API_VERSION_1_1
        // SAFETY: as the caller promised.
        && unsafe { decide::driver_extensions(inst, physical) }
            .is_ok_and(|e| decide::has(&e, name))
    {
        // The extension's one dependency, VK_KHR_get_physical_device_properties2, is core in
        // Vulkan 1.1; a driver with the extension supports its feature (the extension's
        // specification requires it).
        Timelines::Enable { name: true }
    } else {
        Timelines::Unsupported
    }
}

/// The [`Timeline`] struct for the create info's chain, built from the application's Vulkan 1.2
/// features where it has them.
fn timeline_feature(info: In<'_, vk::DeviceCreateInfo<'_>>) -> Timeline {
    match info.find::<vk::PhysicalDeviceVulkan12Features<'static>>() {
        Ok(Some(f)) => {
            let mut copy = *f;
            copy.timeline_semaphore = vk::TRUE;
            Timeline::V12(Box::new(copy))
        }
        _ => Timeline::Own(Box::new(
            vk::PhysicalDeviceTimelineSemaphoreFeatures::default().timeline_semaphore(true),
        )),
    }
}

/// What to do with one `vkCreateDevice`.
enum Plan {
    /// Pass the application's create info down untouched; `Some(why)` is logged.
    Untouched(Option<String>),
    /// The application's request less the density-map extension and structs, which the driver
    /// does not have (docs/vulkan-fdm-on-fsr.md#device-creation); `why` is logged.
    Stripped(Rewrite, String),
    /// Refused with `VK_ERROR_FEATURE_NOT_PRESENT` without reaching the driver: a density-map
    /// struct sits behind a struct the layer cannot copy, so it cannot be left out, and the driver
    /// must never see it (docs/vulkan-fdm-on-fsr.md#device-creation); `why` is logged.
    Refused(String),
    Emulate(FdmEmulation, Rewrite),
    /// Injection is on (docs/injection.md#how-the-attachment-gets-in), the device has
    /// shading-rate attachments and will render eye passes
    /// (docs/injection.md#which-devices-get-the-feature): the create info gains
    /// `VK_KHR_fragment_shading_rate` and its attachment feature (the application's own feature
    /// struct kept where it enables it); the device's facts are those the injected maps are made
    /// for. Where the driver refuses that, the fallback (the application's request, less density
    /// maps where it had any) goes down instead.
    Inject(FdmEmulation, Rewrite, Option<Rewrite>),
}

/// The feature structs of the density-map family: on a device the layer emulates density maps
/// for, the driver has none of these extensions, so none of the structs may reach it.
fn density_map_struct(ty: vk::StructureType) -> bool {
    ty == vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_FEATURES_EXT
        || ty == vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_2_FEATURES_EXT
        || ty == vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_OFFSET_FEATURES_QCOM
        || ty == FRAGMENT_DENSITY_MAP_LAYERED_FEATURES_VALVE
}

/// `VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_LAYERED_FEATURES_VALVE`, newer than
/// ash's headers (<https://registry.khronos.org/vulkan/specs/latest/man/html/VK_VALVE_fragment_density_map_layered.html>).
const FRAGMENT_DENSITY_MAP_LAYERED_FEATURES_VALVE: vk::StructureType =
    vk::StructureType::from_raw(1_000_611_000);

/// The refusal's log line for a chain the layer cannot strip density maps from.
fn cannot_strip(e: chain::ChainError) -> String {
    match e {
        chain::ChainError::Unknown(ty) => format!(
            "a struct of unknown type {} sits before a density-map struct in the device create \
             info's pNext chain, so the density-map struct cannot be left out, and this driver \
             does not have density maps: VK_ERROR_FEATURE_NOT_PRESENT",
            ty.as_raw()
        ),
        chain::ChainError::TooLong => "the device create info's pNext chain is too long to \
            leave its density-map struct out, and this driver does not have density maps: \
            VK_ERROR_FEATURE_NOT_PRESENT"
            .into(),
    }
}

/// Why injection cannot reach the device being created, where it is on and this is the device
/// the OpenXR session renders with but the layer does not emulate on it: without that line the
/// only sign is the stats line's `Inj=0/0` (docs/injection.md#which-devices-get-the-feature).
fn injection_impossible(decision: &Decision) -> Option<String> {
    // Only where `inject` is on: an application that applies FB profiles has its own word on
    // this from the OpenXR side (docs/injection.md#applications-that-apply-profiles).
    if !crate::bridge::inject::for_every_app() || !crate::bridge::inject::device_gets_maps() {
        return None;
    }
    let why = match decision {
        Decision::Native => "the driver has density maps of its own, and injection puts \
                             shading-rate attachments into passes"
            .to_owned(),
        Decision::PassThrough(why) => why.clone(),
        Decision::Emulate { .. } => return None,
    };
    Some(format!(
        "injection is on, but this device cannot take injected maps ({why}): its eye passes \
         render at full rate"
    ))
}

/// What the application's device create info asks for, read once for [`plan`].
struct Request<'a> {
    info: In<'a, vk::DeviceCreateInfo<'a>>,
    /// The application's own shading-rate feature struct.
    app_fsr: Option<vk::PhysicalDeviceFragmentShadingRateFeaturesKHR<'static>>,
    /// NV shading-rate images, by name or feature struct.
    nv_rates: bool,
    /// Shading rates of its own: the KHR extension, its feature struct, or NV's.
    own_rates: bool,
    fdm_named: bool,
    /// Any density-map feature struct in the chain.
    fdm_structs: bool,
    offset_named: bool,
    /// The names less the density-map family, which the driver does not have.
    kept: Vec<*const c_char>,
}

impl<'a> Request<'a> {
    fn read(info: In<'a, vk::DeviceCreateInfo<'a>>) -> Request<'a> {
        let app_fsr = info
            .find::<vk::PhysicalDeviceFragmentShadingRateFeaturesKHR<'static>>()
            .ok()
            .flatten()
            .copied();
        let nv_rates = info.enables(ash::nv::shading_rate_image::NAME)
            || info.has(vk::StructureType::PHYSICAL_DEVICE_SHADING_RATE_IMAGE_FEATURES_NV);
        let fdm_name = ash::ext::fragment_density_map::NAME;
        // The offset extensions, which the layer offers with density maps, go with them.
        let leaves = |n: &CStr| n == fdm_name || n == offset::EXT_NAME || n == offset::QCOM_NAME;
        Request {
            info,
            app_fsr,
            nv_rates,
            own_rates: info.enables(ash::khr::fragment_shading_rate::NAME)
                || nv_rates
                || app_fsr.is_some(),
            fdm_named: info.enables(fdm_name),
            fdm_structs: [
                vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_FEATURES_EXT,
                vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_2_FEATURES_EXT,
                vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_OFFSET_FEATURES_QCOM,
                FRAGMENT_DENSITY_MAP_LAYERED_FEATURES_VALVE,
            ]
            .into_iter()
            .any(|t| info.has(t)),
            offset_named: info.enables(offset::EXT_NAME) || info.enables(offset::QCOM_NAME),
            kept: info
                .named()
                .filter(|(_, n)| !n.is_some_and(leaves))
                .map(|(p, _)| p)
                .collect(),
        }
    }

    /// Whether the application enables the extension `want`.
    fn enabled(&self, want: &CStr) -> bool {
        self.info.enables(want)
    }
}

/// Decides and builds the rewritten create info.
///
/// On a physical device the layer emulates density maps for, whatever else happens, the
/// density-map extension name and every density-map feature struct are left out of what reaches
/// the driver, which has neither (a copy of the name list and of the chain up to the last such
/// struct; the application's create info is never written). Every struct that can extend a
/// device create info up to Vulkan 1.4 can be copied ([`crate::vk::base::structs`]); where one of a type
/// no registry the layer knows sits before a density-map struct, the device is refused
/// ([`Plan::Refused`]).
///
/// # Safety
/// `physical` must belong to `inst`.
unsafe fn plan(
    inst: &Instance,
    physical: vk::PhysicalDevice,
    info: In<'_, vk::DeviceCreateInfo<'_>>,
) -> Plan {
    let decision = decide::decision(inst, physical);
    let Decision::Emulate { fdm, api_version } = &*decision else {
        return Plan::Untouched(injection_impossible(&decision));
    };
    let req = Request::read(info);
    let version = inst.api_version.min(*api_version);
    // SAFETY: as the caller promised.
    let timelines = unsafe { timelines(inst, physical, info, version, &|n| req.enabled(n)) };
    let ordered = matches!(timelines, Timelines::Enable { .. });
    if timelines == Timelines::Unsupported {
        tracing::warn!(
            "the device has several graphics queues but no timeline semaphores (Vulkan 1.2 or \
             VK_KHR_timeline_semaphore): the layer's map uploads are not ordered against passes \
             on other queues than the one they run on"
        );
    }
    let mut kept = req.kept.clone();
    if timelines == (Timelines::Enable { name: true }) {
        kept.push(ash::khr::timeline_semaphore::NAME.as_ptr());
    }
    let goal = Goal {
        fdm,
        version,
        kept,
        ordered,
        timeline: ordered.then(|| timeline_feature(info)),
    };
    if req.fdm_named && !req.own_rates {
        return plan_emulate(&req, goal);
    }
    plan_other(physical, &req, goal)
}

/// What an emulating or injecting device's create info becomes, decided by [`plan`].
struct Goal<'a> {
    fdm: &'a FdmEmulation,
    /// The device's Vulkan version.
    version: u32,
    /// The names that go down: the application's less the density-map family, with
    /// `VK_KHR_timeline_semaphore` where the layer adds it.
    kept: Vec<*const c_char>,
    /// Whether the layer orders its uploads across queues with timeline semaphores.
    ordered: bool,
    timeline: Option<Timeline>,
}

impl Goal<'_> {
    /// The structs that leave the chain: the density-map family, and where the layer puts its own
    /// timeline-semaphore struct in front, the application's.
    fn leaves_chain(&self, t: vk::StructureType) -> bool {
        density_map_struct(t) || (self.ordered && timeline_struct(t))
    }
}

/// The application asks for density maps and has no shading rates of its own: they are emulated.
fn plan_emulate(req: &Request<'_>, goal: Goal<'_>) -> Plan {
    let dynamic = req
        .info
        .find::<vk::PhysicalDeviceFragmentDensityMapFeaturesEXT>()
        .ok()
        .flatten()
        .is_some_and(|f| f.fragment_density_map_dynamic == vk::TRUE);
    if dynamic {
        tracing::warn!(
            "the application enables fragmentDensityMapDynamic, which the layer does not offer; \
             density maps are emulated as static ones"
        );
    }
    let chain = match req.info.without(|t| goal.leaves_chain(t)) {
        Ok(c) => c,
        Err(e) => return Plan::Refused(cannot_strip(e)),
    };
    tracing::debug!(
        feature_structs_removed = chain.removed(),
        "density maps stripped from the device create info"
    );
    let enabled = |n: &CStr| req.enabled(n);
    Plan::Emulate(
        goal.fdm.clone(),
        with_shading_rates(
            &goal.kept,
            &enabled,
            chain,
            goal.version,
            None,
            goal.timeline,
        ),
    )
}

/// Density maps are not emulated on this device: the application does not ask for them, or it
/// enables shading rates itself (Godot enables every extension the device lists, density maps
/// included, and then uses shading rates; the two are exclusive,
/// VUID-VkDeviceCreateInfo-fragmentDensityMap-04481). Whatever density-map name or struct it
/// sent still leaves the create info; injection, where it is on, may still come in.
fn plan_other(physical: vk::PhysicalDevice, req: &Request<'_>, goal: Goal<'_>) -> Plan {
    let stripped = if req.fdm_named || req.offset_named || req.fdm_structs {
        match req.info.without(density_map_struct) {
            Ok(chain) => Some(Rewrite {
                chain,
                names: req.kept.clone(),
                fsr: None,
                timeline: None,
            }),
            Err(e) => return Plan::Refused(cannot_strip(e)),
        }
    } else {
        None
    };
    let why_stripped = if req.fdm_named {
        "the application enables shading rates itself; VK_EXT_fragment_density_map is not \
         emulated on this device, and its name and structs are left out"
    } else {
        "density-map structs in a device create info without VK_EXT_fragment_density_map are \
         left out"
    };
    let untouched = |stripped: Option<Rewrite>, why: Option<String>| match stripped {
        Some(rewrite) => Plan::Stripped(rewrite, why.unwrap_or_else(|| why_stripped.to_owned())),
        None => Plan::Untouched(why),
    };
    if !crate::bridge::inject::wanted() {
        return untouched(stripped, None);
    }
    // NV shading-rate images: the application's maps are the ones that count
    // (docs/injection.md#switching-it-on).
    if req.nv_rates {
        let why = "the application uses NV shading-rate images; nothing is injected on this device";
        return untouched(stripped, Some(why.into()));
    }
    if !crate::bridge::inject::device_gets_maps() {
        tracing::info!(
            physical = raw(physical),
            "injection is on, but this device is not the one the OpenXR session renders with \
             (docs/injection.md#which-devices-get-the-feature): it gets no shading-rate \
             attachments"
        );
        return untouched(stripped, None);
    }
    match plan_inject(req, goal) {
        Ok((fdm, rewrite)) => Plan::Inject(fdm, rewrite, stripped),
        Err(why) => untouched(stripped, Some(why)),
    }
}

/// Injection is on and this device renders the session's views: the create info gains the
/// attachment feature. `Err` says why it cannot.
fn plan_inject(req: &Request<'_>, goal: Goal<'_>) -> Result<(FdmEmulation, Rewrite), String> {
    // The attachment feature enabled (vkd3d-proton enables every shading-rate feature the
    // device has): whether the application uses attachments of its own is told per pass, and
    // where it does, its own wins (docs/injection.md#apps-that-set-rates). Its feature struct
    // already asks for what injection needs and goes down as it came.
    let app_fsr = req.app_fsr;
    let own_attachments = app_fsr.is_some_and(|f| f.attachment_fragment_shading_rate == vk::TRUE);
    // Pipeline or primitive rates (vkd3d-proton's every pipeline): the injected attachment is
    // combined with them (docs/injection.md#apps-that-set-rates).
    let app_sets_rates = app_fsr.is_some_and(|f| {
        f.pipeline_fragment_shading_rate == vk::TRUE
            || f.primitive_fragment_shading_rate == vk::TRUE
    });
    let fsr_features = vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_SHADING_RATE_FEATURES_KHR;
    // The application's feature struct, if any, is left out and stands in the layer's copy in
    // front, unless it enables attachments itself.
    let chain = req
        .info
        .without(|t| goal.leaves_chain(t) || (!own_attachments && t == fsr_features))
        .map_err(|e| {
            format!(
            "cannot extend the device create info's pNext chain ({e:?}); nothing is injected on \
             this device"
        )
        })?;
    if own_attachments {
        tracing::info!(
            "the application enables shading-rate attachments itself: fovea's maps go into its \
             eye passes without attachments of their own; where it names one, its own wins"
        );
    }
    if app_sets_rates {
        tracing::info!(
            non_trivial_combiners = goal.fdm.non_trivial_combiners,
            "the application sets shading rates per pipeline or per draw: injected maps are \
             combined with its rates"
        );
    }
    let enabled = |n: &CStr| req.enabled(n);
    let mut rewrite = with_shading_rates(
        &goal.kept,
        &enabled,
        chain,
        goal.version,
        app_fsr.as_ref(),
        goal.timeline,
    );
    if own_attachments {
        rewrite.fsr = None;
    }
    Ok((goal.fdm.clone(), rewrite))
}

/// Whether a device create info enables density-map offsets: `VK_EXT_fragment_density_map_offset`
/// or `VK_QCOM_fragment_density_map_offset` named, and `fragmentDensityMapOffset` true in its
/// features struct, which images with `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT` need
/// (VUID-VkImageCreateInfo-fragmentDensityMapOffset-06514).
fn enables_offsets(info: In<'_, vk::DeviceCreateInfo<'_>>) -> bool {
    let named = info.enables(offset::EXT_NAME) || info.enables(offset::QCOM_NAME);
    let feature = info
        .find::<vk::PhysicalDeviceFragmentDensityMapOffsetFeaturesQCOM<'_>>()
        .ok()
        .flatten()
        .is_some_and(|f| f.fragment_density_map_offset == vk::TRUE);
    named && feature
}

/// The create info's extensions (`names`) with `VK_KHR_fragment_shading_rate` and what it needs,
/// and a `VkPhysicalDeviceFragmentShadingRateFeaturesKHR` in front of `chain` enabling the
/// attachment feature and, from `app` (the application's own struct, left out of `chain`), the
/// features it enabled itself; the layer asks for no other: they would oblige every draw to set
/// a rate (docs/vulkan-fdm-on-fsr.md#other-pipeline-paths). `timeline`, where the layer orders
/// its uploads across queues, goes between that struct and `chain`.
fn with_shading_rates(
    names: &[*const c_char],
    enabled: &dyn Fn(&CStr) -> bool,
    chain: ChainCopy,
    version: u32,
    app: Option<&vk::PhysicalDeviceFragmentShadingRateFeaturesKHR<'_>>,
    mut timeline: Option<Timeline>,
) -> Rewrite {
    let mut new_names = names.to_vec();
    if !enabled(ash::khr::fragment_shading_rate::NAME) {
        new_names.push(ash::khr::fragment_shading_rate::NAME.as_ptr());
    }
    // Shading rates need render pass 2 (core in 1.2) and, through it, multiview and maintenance2
    // (core in 1.1).
    if version < vk::API_VERSION_1_2 {
        for dep in [
            ash::khr::create_renderpass2::NAME,
            ash::khr::multiview::NAME,
            ash::khr::maintenance2::NAME,
        ] {
            if !enabled(dep) {
                new_names.push(dep.as_ptr());
            }
        }
    }
    let mut fsr = Box::new(
        vk::PhysicalDeviceFragmentShadingRateFeaturesKHR::default()
            .pipeline_fragment_shading_rate(
                app.is_some_and(|f| f.pipeline_fragment_shading_rate == vk::TRUE),
            )
            .primitive_fragment_shading_rate(
                app.is_some_and(|f| f.primitive_fragment_shading_rate == vk::TRUE),
            )
            .attachment_fragment_shading_rate(true),
    );
    fsr.p_next = match &mut timeline {
        Some(t) => {
            t.link(chain.head());
            t.head() as *mut _
        }
        None => chain.head() as *mut _,
    };
    Rewrite {
        chain,
        names: new_names,
        fsr: Some(fsr),
        timeline,
    }
}

hook! {
    /// `vkCreateDevice`: finds the next layer in the loader's link info, creates the device there
    /// (rewritten where the layer emulates density maps or injects, [`plan`]) and records it.
    create_device = "vkCreateDevice"; raw, fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    create(
        physical: val vk::PhysicalDevice,
        info: in vk::DeviceCreateInfo<'_>,
        alloc: val *const vk::AllocationCallbacks<'_>,
        out: out vk::Device,
    ) -> vk::Result
}

fn create(
    physical: vk::PhysicalDevice,
    info: In<'_, vk::DeviceCreateInfo<'_>>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: Out<'_, vk::Device>,
) -> vk::Result {
    let (Some(ci), false) = (info.get(), out.is_null()) else {
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    };
    // SAFETY: a physical device the loader dispatched: its first word is its dispatch key.
    let Some(inst) = (unsafe { registry::instance(physical) }) else {
        tracing::error!("vkCreateDevice on a physical device the layer does not know");
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    };
    // SAFETY: the loader's create info, its chain valid.
    let Some(link_info) = (unsafe { device_link(ci) }) else {
        tracing::error!("vkCreateDevice without the loader's link info");
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    };
    // SAFETY: the loader's link info, found in its create info; the next layer's
    // `vkGetInstanceProcAddr` from it, asked with the instance (not NULL, which would reach the
    // wrong layer).
    let Some((link, create)) = (unsafe { Link::advance(link_info, inst.handle) }) else {
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    };
    // SAFETY: `physical` belongs to `inst`, which the loader dispatched it through.
    let plan = unsafe { plan(&inst, physical, info) };
    let made = Made::of(&plan, enables_offsets(info));
    let down = Down {
        create,
        physical,
        info,
        alloc,
        out: out.raw(),
        link: &link,
    };
    let (r, fdm) = match down.go(plan) {
        Ok(made) => made,
        Err(refused) => return refused,
    };
    if let (vk::Result::SUCCESS, Some(handle)) = (r, out.read()) {
        let new = New {
            inst: &inst,
            physical,
            ci,
            handle,
            gdpa: link.gdpa,
        };
        new.record(fdm, made);
    }
    r
}

/// The loader's link to the next layer: its `VK_LAYER_LINK_INFO` struct and the layer's entry in
/// it.
struct Link {
    info: *mut LayerDeviceCreateInfo,
    layer: *mut LayerDeviceLink,
    gdpa: vk::PFN_vkGetDeviceProcAddr,
}

impl Link {
    /// The next layer's link, with the loader's struct advanced past it for the layers below, and
    /// the next layer's `vkCreateDevice`.
    ///
    /// # Safety
    /// `info` must be the loader's link info of the create info being handled, `instance` the
    /// physical device's instance.
    unsafe fn advance(
        info: *mut LayerDeviceCreateInfo,
        instance: vk::Instance,
    ) -> Option<(Link, vk::PFN_vkCreateDevice)> {
        // SAFETY: the loader's list of layers below. The protocol has each layer advance
        // `pLayerInfo` in the loader's struct before calling down; it is the loader's struct, not
        // the application's. The pointer the next layer returns is of the type its name implies.
        unsafe {
            let layer = (*info).u as *mut LayerDeviceLink;
            if layer.is_null() {
                return None;
            }
            let link = Link {
                info,
                layer,
                gdpa: (*layer).pfn_next_get_device_proc_addr,
            };
            link.rewind();
            let gipa = (*layer).pfn_next_get_instance_proc_addr;
            let f = gipa(instance, c"vkCreateDevice".as_ptr())?;
            let create =
                std::mem::transmute::<unsafe extern "system" fn(), vk::PFN_vkCreateDevice>(f);
            Some((link, create))
        }
    }

    /// Points the loader's struct past this layer (again, for a retry of the call down).
    ///
    /// # Safety
    /// As [`Link::advance`].
    unsafe fn rewind(&self) {
        // SAFETY: as the caller promised.
        unsafe { (*self.info).u = (*self.layer).p_next as *mut _ };
    }
}

/// What [`create`] knew of the device before it went down.
#[derive(Clone, Copy)]
struct Made {
    inject: bool,
    timelines: bool,
    app_offsets: bool,
    untouched: bool,
}

impl Made {
    /// What `plan` says of the device; `app_offsets`: whether the application enables offsets.
    fn of(plan: &Plan, app_offsets: bool) -> Made {
        Made {
            inject: matches!(plan, Plan::Inject(..)),
            timelines: matches!(
                plan,
                Plan::Emulate(_, r) | Plan::Inject(_, r, _) if r.timeline.is_some()
            ),
            app_offsets,
            untouched: matches!(plan, Plan::Untouched(_)),
        }
    }
}

/// The call down: the next layer's `vkCreateDevice` and the application's arguments.
struct Down<'a> {
    create: vk::PFN_vkCreateDevice,
    physical: vk::PhysicalDevice,
    info: In<'a, vk::DeviceCreateInfo<'a>>,
    alloc: *const vk::AllocationCallbacks<'a>,
    out: *mut vk::Device,
    link: &'a Link,
}

impl Down<'_> {
    /// Creates the device below as `plan` says: the driver's answer and, on success, the facts
    /// it emulates (or injects) with; `Err` with the answer of a refusal that never reached it.
    fn go(&self, plan: Plan) -> Result<(vk::Result, Option<FdmEmulation>), vk::Result> {
        let physical = raw(self.physical);
        Ok(match plan {
            Plan::Untouched(why) => {
                if let Some(why) = why {
                    tracing::warn!(physical, why = why.as_str(), "vkCreateDevice");
                }
                (self.as_given(), None)
            }
            Plan::Refused(why) => {
                tracing::error!(physical, why = why.as_str(), "vkCreateDevice");
                return Err(vk::Result::ERROR_FEATURE_NOT_PRESENT);
            }
            Plan::Stripped(rewrite, why) => {
                tracing::info!(physical, why = why.as_str(), "vkCreateDevice");
                (self.rewritten(&rewrite), None)
            }
            Plan::Emulate(fdm, rewrite) => {
                // No retry: the application asked for density maps, which this driver has only
                // as shading-rate attachments; its own request would name an extension the
                // driver lacks. The driver's answer is the application's.
                let r = self.rewritten(&rewrite);
                (r, (r == vk::Result::SUCCESS).then_some(fdm))
            }
            Plan::Inject(fdm, rewrite, fallback) => self.inject(fdm, rewrite, fallback),
        })
    }

    /// The application's create info, as it came.
    fn as_given(&self) -> vk::Result {
        // SAFETY: the next layer's function, with the application's arguments.
        unsafe { (self.create)(self.physical, self.info.raw(), self.alloc, self.out) }
    }

    /// The application's create info as `rewrite` describes it: its chain and names.
    fn rewritten(&self, rewrite: &Rewrite) -> vk::Result {
        let Some(ci) = self.info.get() else {
            return self.as_given();
        };
        let mut copy = *ci;
        copy.p_next = rewrite.head();
        copy.enabled_extension_count = rewrite.names.len() as u32;
        copy.pp_enabled_extension_names = rewrite.names.as_ptr();
        // SAFETY: the next layer's function; the copy and everything it points at live across
        // the call.
        unsafe { (self.create)(self.physical, &copy, self.alloc, self.out) }
    }

    /// The create info with shading-rate attachments for injection; where the driver refuses
    /// it, the application's own request (`fallback`: less density maps, which the driver does
    /// not have) gets its answer (fail open).
    fn inject(
        &self,
        fdm: FdmEmulation,
        rewrite: Rewrite,
        fallback: Option<Rewrite>,
    ) -> (vk::Result, Option<FdmEmulation>) {
        let r = self.rewritten(&rewrite);
        drop(rewrite);
        if r == vk::Result::SUCCESS {
            return (r, Some(fdm));
        }
        if matches!(
            r,
            vk::Result::ERROR_OUT_OF_HOST_MEMORY
                | vk::Result::ERROR_OUT_OF_DEVICE_MEMORY
                | vk::Result::ERROR_DEVICE_LOST
        ) {
            // Not the rewrite's doing: the driver's answer, unchanged.
            return (r, None);
        }
        tracing::warn!(
            physical = raw(self.physical),
            result = ?r,
            inject = true,
            "creating the device with shading-rate attachments failed; retrying without"
        );
        // SAFETY: the loader's struct gets its link back for the retry.
        unsafe { self.link.rewind() };
        let r = match &fallback {
            Some(f) => self.rewritten(f),
            None => self.as_given(),
        };
        (r, None)
    }
}

/// A device just created below, to be recorded.
struct New<'a> {
    inst: &'a Instance,
    physical: vk::PhysicalDevice,
    ci: &'a vk::DeviceCreateInfo<'a>,
    handle: vk::Device,
    gdpa: vk::PFN_vkGetDeviceProcAddr,
}

impl New<'_> {
    /// Records the device with the next layer's table, the layer's own calls on it and each
    /// mode's state, and tells the bridge whether offsets reach its density maps.
    fn record(&self, fdm: Option<FdmEmulation>, made: Made) {
        let (inst, handle) = (self.inst, self.handle);
        // Injection uses the device's shading-rate facts, but emulates nothing.
        let (fdm, inject) = if made.inject {
            (None, fdm)
        } else {
            (fdm, None)
        };
        // SAFETY: the next layer's `vkGetDeviceProcAddr`, and the device it just created.
        let next = unsafe { DeviceNext::load(self.gdpa, handle) };
        let api_version = match &*decide::decision(inst, self.physical) {
            Decision::Emulate { api_version, .. } => inst.api_version.min(*api_version),
            _ => inst.api_version,
        };
        let (own, inject) = self.own(fdm.is_some(), inject, made.timelines);
        self.forget_reused_key();
        let end_rendering = if fdm.is_some() {
            self.end_rendering(api_version)
        } else {
            None
        };
        let emulated = fdm.is_some();
        let (converter, reconstructor) = self.modes(fdm.as_ref(), &inject, &own, api_version);
        let converts = converter.is_some();
        // SAFETY: the live device just created.
        unsafe {
            registry::add_device(registry::Device {
                handle,
                instance: key(inst.handle).unwrap_or(0),
                gdpa: self.gdpa,
                next,
                end_rendering,
                fdm,
                api_version,
                own,
                emulation: registry::Emulation::new(converter),
                injection: inject,
                reconstructor,
                command_pools: Default::default(),
            });
        }
        // Offsets reach density maps where the driver got the application's request as it was
        // (so it has the extension), or where the layer emulates them and converts: an emulated
        // map takes offsets only through its conversion in front of each pass
        // (docs/vulkan-layer.md#density-map-offsets), and a device that cannot convert (Vulkan
        // 1.4, maintenance6, descriptor buffers, ...) said why above. Published only now, after
        // that decision: the OpenXR side makes fovea's own density images take offsets where
        // this says they apply (docs/eye-tracking.md#what-moves-when).
        crate::bridge::set_device_offsets(
            handle,
            Some(made.app_offsets && (made.untouched || (emulated && converts))),
        );
    }

    /// The converter of the maps the application writes and the reconstructor of coarse blocks,
    /// where the layer can record compute dispatches into the device's command buffers (their
    /// condition, [`convert::dispatch_blocked`]).
    fn modes(
        &self,
        fdm: Option<&FdmEmulation>,
        inject: &Option<Injector>,
        own: &Option<Arc<Own>>,
        api_version: u32,
    ) -> (Option<Arc<Converter>>, Option<Arc<Reconstructor>>) {
        let (inst, handle, ci) = (self.inst, self.handle, self.ci);
        // SAFETY: the live device just created from `ci` on `physical`, a physical device of
        // `inst`; `own` is its own calls, and it emulates as `fdm` says.
        unsafe {
            let blocked = (own.is_some() && (inject.is_some() || fdm.is_some()))
                .then(|| convert::dispatch_blocked(inst, self.physical, ci, api_version))
                .flatten();
            let converter = convert::converter_for(handle, fdm, own.as_ref(), blocked.as_deref());
            let recon_fdm = inject.as_ref().map(|i| &i.fdm).or(fdm);
            let reconstructor = reconstruct::reconstructor_for(
                handle,
                recon_fdm,
                own.as_ref(),
                blocked.as_deref(),
                ci,
                api_version,
            );
            (converter, reconstructor)
        }
    }

    /// The layer's own calls on the device, where it emulates (`emulates`) or injects
    /// (`inject`: the facts the maps are made for), and the injector; where they cannot be set
    /// up, the device renders at full rate (fail open).
    fn own(
        &self,
        emulates: bool,
        inject: Option<FdmEmulation>,
        timelines: bool,
    ) -> (Option<Arc<Own>>, Option<Injector>) {
        let handle = raw(self.handle);
        if emulates {
            tracing::info!(device = handle, "device emulates fragment density maps");
            let own = self.own_calls(timelines).map_err(|why| {
                tracing::warn!(
                    device = handle,
                    why = why.as_str(),
                    "density maps on this device get no shading-rate shadows: they render at \
                     full rate"
                )
            });
            return (own.ok(), None);
        }
        let Some(facts) = inject else {
            return (None, None);
        };
        match self.own_calls(timelines) {
            Ok(o) => {
                tracing::info!(
                    device = handle,
                    "device has shading-rate attachments for injection"
                );
                (Some(o), Some(Injector::new(facts)))
            }
            // Fail open: the device keeps the feature, and its passes run unmodified.
            Err(why) => {
                tracing::warn!(
                    device = handle,
                    why = why.as_str(),
                    "nothing is injected on this device: the layer cannot make its shading-rate \
                     maps there"
                );
                (None, None)
            }
        }
    }

    fn own_calls(&self, timelines: bool) -> Result<Arc<Own>, String> {
        let inst = self.inst;
        // SAFETY: the live device just created from `ci` on `physical`, with the next layer's
        // pointers.
        unsafe {
            Own::new(
                inst.handle,
                inst.gipa,
                self.physical,
                self.ci,
                self.handle,
                self.gdpa,
                timelines,
            )
        }
        .map(Arc::new)
    }

    /// A new device with the dispatch key of one that was never destroyed (its instance was
    /// destroyed first): what the layer kept for the old one is forgotten.
    fn forget_reused_key(&self) {
        // SAFETY: the device was just created, so its handle is live for `key`.
        let Some(k) = (unsafe { key(self.handle) }).filter(|&k| registry::has_key(k)) else {
            return;
        };
        tracing::warn!(
            device = raw(self.handle),
            "a new device has the dispatch key of one that was never destroyed (its instance was \
             destroyed first): what the layer kept for the old one is forgotten"
        );
        registry::device_key_reused(k);
    }

    /// The next layer's plain end of dynamic rendering, which `vkCmdEndRendering2EXT` (the driver
    /// does not have it) goes down as: the core name from Vulkan 1.3, `VK_KHR_dynamic_rendering`'s
    /// below (a driver returns no pointer for a core name above the device's version).
    fn end_rendering(&self, api_version: u32) -> Option<vk::PFN_vkCmdEndRendering> {
        let (first, second) = if api_version >= vk::API_VERSION_1_3 {
            (c"vkCmdEndRendering", c"vkCmdEndRenderingKHR")
        } else {
            (c"vkCmdEndRenderingKHR", c"vkCmdEndRendering")
        };
        // SAFETY: the next layer's `vkGetDeviceProcAddr` and its live device; the pointer is of
        // the type its name implies.
        unsafe {
            (self.gdpa)(self.handle, first.as_ptr())
                .or_else(|| (self.gdpa)(self.handle, second.as_ptr()))
                .map(|f| {
                    std::mem::transmute::<unsafe extern "system" fn(), vk::PFN_vkCmdEndRendering>(f)
                })
        }
    }
}

hook! {
    /// `vkDestroyDevice`: forgets the device and destroys it below.
    destroy_device = "vkDestroyDevice"; raw, fails(());
    destroy(device: val vk::Device, alloc: val *const vk::AllocationCallbacks<'_>) -> ()
}

fn destroy(device: vk::Device, alloc: *const vk::AllocationCallbacks<'_>) {
    // SAFETY: a device the loader dispatched (or NULL): its first word is its dispatch key.
    let Some(dev) = (unsafe { registry::remove_device(device) }) else {
        return;
    };
    // SAFETY: the device is live; the application has finished with it (destroy_all waits for
    // the layer's clears and uploads in flight before the maps go).
    unsafe {
        convert::device_destroyed(&dev);
        reconstruct::device_destroyed(&dev);
        emulation::destroy_all(&dev);
        if let (Some(inj), Some(own)) = (&dev.injection, &dev.own) {
            inj.destroy(own);
        }
    }
    if let Some(destroy) = dev.next.destroy_device {
        // SAFETY: the next layer's function, with the application's arguments.
        unsafe { destroy(device, alloc) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Offsets count as enabled with either name and the feature on, not with either alone.
    #[test]
    fn offsets_need_a_name_and_the_feature() {
        let enables = |names: &[&CStr], feature: Option<bool>| {
            let ptrs: Vec<*const c_char> = names.iter().map(|n| n.as_ptr()).collect();
            let mut f = vk::PhysicalDeviceFragmentDensityMapOffsetFeaturesQCOM::default()
                .fragment_density_map_offset(feature.unwrap_or(false));
            let mut multiview = vk::PhysicalDeviceMultiviewFeatures::default().multiview(true);
            let mut info = vk::DeviceCreateInfo::default()
                .enabled_extension_names(&ptrs)
                .push_next(&mut multiview);
            if feature.is_some() {
                info = info.push_next(&mut f);
            }
            // SAFETY: a valid create info whose names and chain live across the call.
            enables_offsets(unsafe { In::new(&info) })
        };
        assert!(enables(&[offset::EXT_NAME], Some(true)));
        assert!(enables(&[offset::QCOM_NAME], Some(true)));
        assert!(!enables(&[offset::EXT_NAME], Some(false)));
        assert!(!enables(&[offset::EXT_NAME], None));
        assert!(!enables(&[], Some(true)));
    }
}
