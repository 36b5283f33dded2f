//! The per-physical-device decision, made once from what the driver offers: native density maps
//! (everything passes through), emulation on shading-rate attachments, or pass through.

use std::sync::Arc;

use ash::vk;

use crate::bridge::FdmEmulation;
use crate::vk::base::ffi::raw;
use crate::vk::registry::{Decision, Instance};

/// The decision for `physical`, made once per instance and physical device (and logged then).
pub fn decision(inst: &Instance, physical: vk::PhysicalDevice) -> Arc<Decision> {
    let key = raw(physical);
    if let Some(d) = inst.decisions.lock().get(&key) {
        return d.clone();
    }
    // Queried without the lock held: a concurrent first query decides twice, identically.
    // SAFETY: `physical` belongs to `inst` (the loader dispatched it here).
    let d = Arc::new(unsafe { decide(inst, physical) });
    match &*d {
        Decision::Native => {
            tracing::info!(
                physical = key,
                "native fragment density maps: passing through"
            )
        }
        Decision::Emulate { fdm, .. } => tracing::info!(
            physical = key,
            texel = ?fdm.texel,
            layered = fdm.layered,
            max_fragment = ?fdm.max_fragment,
            "emulating VK_EXT_fragment_density_map on shading-rate attachments"
        ),
        Decision::PassThrough(why) => tracing::info!(
            physical = key,
            why = why.as_str(),
            "not emulating fragment density maps: passing through"
        ),
    }
    inst.decisions.lock().entry(key).or_insert(d).clone()
}

/// The emulation facts of `physical`, if it is emulated.
pub fn emulated(inst: &Instance, physical: vk::PhysicalDevice) -> Option<FdmEmulation> {
    match &*decision(inst, physical) {
        Decision::Emulate { fdm, .. } => Some(fdm.clone()),
        _ => None,
    }
}

/// The emulation facts of `physical` where it also offers density-map offsets
/// (docs/vulkan-layer.md#density-map-offsets): they are applied by the conversion in front of each
/// pass, which a device of Vulkan 1.4 (the instance's version and the driver's) never sets up, since
/// 1.4 binds compute state through commands the layer does not see (`crate::vk::convert`).
pub fn offsets_offered(inst: &Instance, physical: vk::PhysicalDevice) -> Option<FdmEmulation> {
    match &*decision(inst, physical) {
        Decision::Emulate { fdm, api_version }
            if converts_at(inst.api_version.min(*api_version)) =>
        {
            Some(fdm.clone())
        }
        _ => None,
    }
}

/// Whether a device of `api_version` can convert density maps on the GPU (below Vulkan 1.4).
fn converts_at(api_version: u32) -> bool {
    api_version < vk::make_api_version(0, 1, 4, 0)
}

/// The driver's (the next layer's) device extensions.
///
/// # Safety
/// `physical` must belong to `inst`.
pub unsafe fn driver_extensions(
    inst: &Instance,
    physical: vk::PhysicalDevice,
) -> Result<Vec<vk::ExtensionProperties>, vk::Result> {
    let f = inst
        .next
        .enumerate_device_extension_properties
        .ok_or(vk::Result::ERROR_INITIALIZATION_FAILED)?;
    loop {
        let mut n = 0;
        // SAFETY: the next layer's function; the vector holds `n` elements.
        unsafe {
            let r = f(physical, std::ptr::null(), &mut n, std::ptr::null_mut());
            if r != vk::Result::SUCCESS {
                return Err(r);
            }
            let mut v = vec![vk::ExtensionProperties::default(); n as usize];
            match f(physical, std::ptr::null(), &mut n, v.as_mut_ptr()) {
                vk::Result::SUCCESS => {
                    v.truncate(n as usize);
                    return Ok(v);
                }
                vk::Result::INCOMPLETE => continue,
                r => return Err(r),
            }
        }
    }
}

pub fn has(exts: &[vk::ExtensionProperties], want: &std::ffi::CStr) -> bool {
    exts.iter().any(|e| e.extension_name_as_c_str() == Ok(want))
}

/// The next layer's `vkGetPhysicalDeviceFeatures2` and `…Properties2` usable on this instance:
/// core where the instance is 1.1 or later, else the KHR ones where the extension is enabled.
pub fn queries2(
    inst: &Instance,
) -> Option<(
    vk::PFN_vkGetPhysicalDeviceFeatures2,
    vk::PFN_vkGetPhysicalDeviceProperties2,
)> {
    if inst.api_version >= vk::API_VERSION_1_1 {
        if let (Some(f), Some(p)) = (inst.next.get_features2, inst.next.get_properties2) {
            return Some((f, p));
        }
    }
    if inst.properties2_ext {
        if let (Some(f), Some(p)) = (inst.next.get_features2_khr, inst.next.get_properties2_khr) {
            return Some((f, p));
        }
    }
    None
}

/// Whether the driver below implements fragment density maps: its `fragmentDensityMap` feature is
/// TRUE. Where the feature cannot be asked for (no `vkGetPhysicalDeviceFeatures2` usable on the
/// instance), a listed extension is taken at its word: passing through is the choice that cannot
/// break a native implementation.
///
/// # Safety
/// `physical` must belong to `inst`.
pub unsafe fn native_fdm(inst: &Instance, physical: vk::PhysicalDevice) -> bool {
    let Some((features2, _)) = queries2(inst) else {
        return true;
    };
    let mut fdm = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default();
    let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut fdm);
    // SAFETY: the next layer's function with structs that live across the call; `physical` is the
    // caller's.
    unsafe { features2(physical, &mut f2) };
    fdm.fragment_density_map == vk::TRUE
}

/// Decides from what the driver offers.
///
/// # Safety
/// `physical` must belong to `inst`.
pub unsafe fn decide(inst: &Instance, physical: vk::PhysicalDevice) -> Decision {
    let pass = |why: &str| Decision::PassThrough(why.to_owned());
    // SAFETY: as the caller promised.
    let exts = match unsafe { driver_extensions(inst, physical) } {
        Ok(e) => e,
        Err(r) => return pass(&format!("vkEnumerateDeviceExtensionProperties failed: {r}")),
    };
    // The extension in the list is not proof of a native implementation: where this layer is
    // installed implicitly, the Vulkan loader adds the `device_extensions` of implicit layers'
    // manifests to what it lists below them, this layer's own VK_EXT_fragment_density_map included
    // (https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md,
    // "Layer Manifest File Format", `device_extensions`). Only a driver that implements it fills
    // its feature struct, so the feature decides.
    // SAFETY: as the caller promised.
    if has(&exts, ash::ext::fragment_density_map::NAME) && unsafe { native_fdm(inst, physical) } {
        return Decision::Native;
    }
    if !has(&exts, ash::khr::fragment_shading_rate::NAME) {
        return pass("the driver offers no VK_KHR_fragment_shading_rate");
    }
    let Some((features2, properties2)) = queries2(inst) else {
        return pass(
            "the instance has neither Vulkan 1.1 nor VK_KHR_get_physical_device_properties2",
        );
    };
    let Some(rates_fn) = inst.get_fragment_shading_rates else {
        return pass("no vkGetPhysicalDeviceFragmentShadingRatesKHR below");
    };
    let mut fsr = vk::PhysicalDeviceFragmentShadingRateFeaturesKHR::default();
    let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut fsr);
    // SAFETY: the next layer's function with structs that live across the call.
    unsafe { features2(physical, &mut f2) };
    if fsr.attachment_fragment_shading_rate != vk::TRUE {
        return pass("the driver has no attachmentFragmentShadingRate");
    }
    let mut props = vk::PhysicalDeviceFragmentShadingRatePropertiesKHR::default();
    let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut props);
    // SAFETY: as above.
    unsafe { properties2(physical, &mut p2) };
    let api_version = p2.properties.api_version;
    if api_version < vk::API_VERSION_1_1 {
        return pass("the device is Vulkan 1.0");
    }
    let min = props.min_fragment_shading_rate_attachment_texel_size;
    let max = props.max_fragment_shading_rate_attachment_texel_size;
    // Any power of two in [min, max] is a legal shading-rate texel; the layer takes the minimum
    // (the finest the driver allows; min = max on every desktop driver known), and reports it as
    // both the minimum and the maximum density texel, which pins the density texel to it.
    let texel = [min.width, min.height];
    if !texel.iter().all(|t| t.is_power_of_two()) || min.width > max.width {
        return pass(&format!(
            "the driver reports an unusable shading-rate texel size {min:?}..{max:?}"
        ));
    }
    if min != max {
        tracing::debug!(?min, ?max, "texel sizes differ; emulating with the minimum");
    }
    let mut n = 0;
    // SAFETY: the next layer's function; the vector holds `n` elements.
    let rates = unsafe {
        let r = rates_fn(physical, &mut n, std::ptr::null_mut());
        if r != vk::Result::SUCCESS {
            return pass(&format!("vkGetPhysicalDeviceFragmentShadingRatesKHR: {r}"));
        }
        let mut v = vec![vk::PhysicalDeviceFragmentShadingRateKHR::default(); n as usize];
        let r = rates_fn(physical, &mut n, v.as_mut_ptr());
        if r != vk::Result::SUCCESS && r != vk::Result::INCOMPLETE {
            return pass(&format!("vkGetPhysicalDeviceFragmentShadingRatesKHR: {r}"));
        }
        v.truncate(n as usize);
        v
    };
    let rates = rates
        .iter()
        .filter(|r| r.sample_counts.contains(vk::SampleCountFlags::TYPE_1))
        .map(|r| [r.fragment_size.width, r.fragment_size.height])
        .collect();
    Decision::Emulate {
        fdm: FdmEmulation {
            texel,
            layered: props.layered_shading_rate_attachments == vk::TRUE,
            max_fragment: [
                props.max_fragment_size.width,
                props.max_fragment_size.height,
            ],
            rates,
            non_trivial_combiners: props.fragment_shading_rate_non_trivial_combiner_ops == vk::TRUE,
        },
        api_version,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_need_a_device_below_vulkan_1_4() {
        assert!(converts_at(vk::API_VERSION_1_3));
        assert!(converts_at(vk::make_api_version(0, 1, 3, 290)));
        assert!(!converts_at(vk::make_api_version(0, 1, 4, 0)));
        assert!(!converts_at(vk::make_api_version(0, 1, 4, 309)));
    }
}
