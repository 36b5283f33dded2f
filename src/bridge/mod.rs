//! The foveation bridge: per-swapchain density-map state, and the one rule for when a map is stale.
//!
//! A density map depends on exactly the inputs named in [`MapKey`]: the swapchain's foveation state
//! (its last applied profile), the FOVs the session last located, the session's pattern (dynamic
//! step and debug overrides) and the views last submitted into the swapchain. Each input carries a
//! generation that its owner bumps when it changes; an image whose stored key differs from the
//! current one is stale and is rebuilt (only in `xrAcquireSwapchainImage`). Adding an input means
//! adding a field here and bumping it where it changes; nothing else decides staleness.
//!
//! Both API sides meet here: the OpenXR side records what the application asked for and rendered,
//! the GPU side fills images from [`MapInputs`]. Neither imports the other.

pub mod inject;
pub mod subsampled;

use fovea_model::density::{Level, Pattern};
use fovea_model::dynamic::level_at;
use fovea_model::maps::{Inputs, SubmittedView, MAX_VIEWS};
use fovea_model::Fov;
use openxr_sys as xr;

use crate::common::settings::DebugProperties;

/// Which state a density image holds: the generation of each input a map depends on, as it was when
/// the image was filled.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MapKey {
    /// [`FoveationState::generation`]: bumped by every `xrUpdateSwapchainFB`.
    pub foveation: u64,
    /// [`ViewFovs::generation`]: bumped when a located FOV changes.
    pub located: u64,
    /// The session's pattern generation: bumped when the dynamic step or the debug overrides change
    /// what the maps hold.
    pub pattern: u64,
    /// [`Submitted::generation`]: bumped when the views submitted into the swapchain change.
    pub submitted: u64,
}

/// What one swapchain image's map is computed from, read once per acquire.
#[derive(Clone, Copy, Debug)]
pub struct MapSources {
    pub foveation: FoveationState,
    pub located: ViewFovs,
    pub pattern_generation: u64,
    pub submitted: Submitted,
}

impl MapSources {
    /// The key a map filled from these sources holds.
    pub fn key(&self) -> MapKey {
        MapKey {
            foveation: self.foveation.generation,
            located: self.located.generation,
            pattern: self.pattern_generation,
            submitted: self.submitted.generation,
        }
    }

    /// The map's inputs for a swapchain of `extent` with `layers` array layers, under `pattern`;
    /// `visible` gives the eyes' true FOVs in symmetric-FOV mode. Called only for a stale image.
    pub fn inputs(
        &self,
        pattern: Pattern,
        extent: [u32; 2],
        layers: u32,
        visible: Option<[Fov; 2]>,
    ) -> Inputs {
        Inputs::new(
            pattern,
            extent,
            layers,
            &self.submitted.views,
            &self.located.fovs,
            visible,
        )
    }
}

/// The pattern for a swapchain state under debug overrides at a dynamic step. As on Quest: the
/// level property replaces the application's level (the maximum when dynamic), the dynamic property
/// replaces its dynamic flag.
pub fn effective(params: ProfileParams, over: DebugProperties, step: usize) -> (Pattern, bool) {
    let asked = Level::from_index(params.level).unwrap_or(Level::None);
    let max = over.level.unwrap_or(asked);
    let dynamic = over.dynamic.unwrap_or(params.dynamic);
    let level = if dynamic { level_at(step, max) } else { max };
    (
        Pattern {
            level,
            vertical_offset_deg: over
                .vertical_offset_deg
                .unwrap_or(params.vertical_offset_deg),
        },
        dynamic,
    )
}

/// The views' FOVs as the application last got them from xrLocateViews.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ViewFovs {
    pub fovs: [Option<Fov>; MAX_VIEWS],
    /// Bumped whenever a FOV changes, so density maps computed for older FOVs are refreshed.
    pub generation: u64,
}

impl ViewFovs {
    /// Records the FOVs of one xrLocateViews call; bumps the generation only when one changed.
    pub fn record(&mut self, fovs: impl IntoIterator<Item = Fov>) {
        let mut new = [None; MAX_VIEWS];
        for (slot, fov) in new.iter_mut().zip(fovs) {
            *slot = Some(fov);
        }
        if new != self.fovs {
            self.fovs = new;
            self.generation += 1;
        }
    }
}

/// The projection views one `xrEndFrame` put into a swapchain.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Submitted {
    pub views: [Option<SubmittedView>; MAX_VIEWS],
    /// Bumped when the views change (FOV, rectangle or array layer): the maps are rebuilt once.
    pub generation: u64,
}

/// What an `XrFoveationLevelProfileCreateInfoFB` asks for. A profile without one applies no
/// foveation (fb_foveation.adoc), which is level NONE.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProfileParams {
    /// `XrFoveationLevelFB`: 0 none, 1 low, 2 medium, 3 high; the maximum when dynamic.
    pub level: u32,
    /// Degrees, positive up: where the centre of the pattern sits.
    pub vertical_offset_deg: f32,
    /// XR_FOVEATION_DYNAMIC_LEVEL_ENABLED_FB.
    pub dynamic: bool,
    /// The profile was created with `XrFoveationEyeTrackedProfileCreateInfoMETA`
    /// (XR_META_foveation_eye_tracked): its fovea follows the gaze where a gaze source exists.
    pub eye_tracked: bool,
}

/// A foveated swapchain's current state: a copy of the last applied profile's parameters, so
/// destroying the profile afterwards changes nothing (fb_foveation.adoc).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FoveationState {
    pub params: ProfileParams,
    /// The profile last applied (XR_NULL_HANDLE before the first update).
    pub profile: xr::FoveationProfileFB,
    /// Bumped by every xrUpdateSwapchainFB: density images filled for an older state are dirty.
    pub generation: u64,
}

/// How one `VkDevice` runs fragment density maps on shading-rate attachments, as the Vulkan side
/// decided at `vkCreateDevice`. fovea's own density images size their texels from it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FdmEmulation {
    /// The shading-rate attachment texel, which is also the density-map texel the device reports
    /// (`minFragmentDensityTexelSize` = `maxFragmentDensityTexelSize`).
    pub texel: [u32; 2],
    /// `layeredShadingRateAttachments`: one rate layer per view, else one merged layer.
    pub layered: bool,
    /// `maxFragmentSize`.
    pub max_fragment: [u32; 2],
    /// The fragment sizes `vkGetPhysicalDeviceFragmentShadingRatesKHR` lists for one sample.
    pub rates: Vec<[u32; 2]>,
    /// `fragmentShadingRateNonTrivialCombinerOps`: combiners other than `KEEP` and `REPLACE`
    /// (`MAX` among them) are allowed; how an injected map meets an application's own rates
    /// (docs/injection.md#how-the-attachment-gets-in).
    pub non_trivial_combiners: bool,
}

#[cfg(test)]
impl FdmEmulation {
    /// The NVIDIA-like device of the unit tests: 16×16 layered texels, fragments up to 4×4.
    pub(crate) fn nvidia_like() -> FdmEmulation {
        FdmEmulation {
            texel: [16, 16],
            layered: true,
            max_fragment: [4, 4],
            rates: vec![[1, 1], [2, 2], [4, 4]],
            non_trivial_combiners: true,
        }
    }
}

/// Emulating devices, by `VkDevice` handle.
static DEVICE_FDM: crate::common::lock::MapLock<std::collections::BTreeMap<u64, FdmEmulation>> =
    crate::common::lock::MapLock::new("bridge device FDM", std::collections::BTreeMap::new());

/// Records (or, with `None`, forgets) how `device` emulates fragment density maps.
pub fn set_device_fdm(device: ash::vk::Device, fdm: Option<FdmEmulation>) {
    use ash::vk::Handle as _;
    let mut map = DEVICE_FDM.write();
    match fdm {
        Some(f) => map.insert(device.as_raw(), f),
        None => map.remove(&device.as_raw()),
    };
}

/// How `device` emulates fragment density maps; `None` where it does not (native, unavailable,
/// or a device the Vulkan layer did not see).
pub fn device_fdm(device: ash::vk::Device) -> Option<FdmEmulation> {
    use ash::vk::Handle as _;
    DEVICE_FDM.read().get(&device.as_raw()).cloned()
}

/// Devices the Vulkan layer saw created, by `VkDevice` handle: whether density-map offsets reach
/// density maps on them, because the application enabled `VK_EXT_fragment_density_map_offset` or
/// `VK_QCOM_fragment_density_map_offset` with the `fragmentDensityMapOffset` feature, and the layer
/// emulates them (docs/vulkan-layer.md#density-map-offsets) or the driver has them itself. fovea
/// creates its own density images with `VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT` for
/// applications that apply offsets only there (docs/eye-tracking.md#what-moves-when).
static DEVICE_OFFSETS: crate::common::lock::MapLock<std::collections::BTreeMap<u64, bool>> =
    crate::common::lock::MapLock::new("bridge device offsets", std::collections::BTreeMap::new());

/// Records (or, with `None`, forgets) whether density-map offsets reach density maps on `device`.
pub fn set_device_offsets(device: ash::vk::Device, offsets: Option<bool>) {
    use ash::vk::Handle as _;
    let mut map = DEVICE_OFFSETS.write();
    match offsets {
        Some(o) => map.insert(device.as_raw(), o),
        None => map.remove(&device.as_raw()),
    };
}

/// Whether density-map offsets reach density maps on `device`; `None` for a device the Vulkan
/// layer did not see created.
pub fn device_offsets(device: ash::vk::Device) -> Option<bool> {
    use ash::vk::Handle as _;
    DEVICE_OFFSETS.read().get(&device.as_raw()).copied()
}

/// A layer-owned shading-rate image that stands in for an application's density-map image on an
/// emulating device (see docs/vulkan-fdm-on-fsr.md#shadows). Render passes, framebuffers and
/// dynamic rendering read the shadow, never the application's image; whoever converts density into
/// rates writes it.
///
/// Format `R8_UINT` (one rate code per texel, width `2^((v >> 2) & 3)`, height `2^(v & 3)`, see
/// docs/vulkan-fdm-on-fsr.md#rate-encoding), usage shading-rate attachment and transfer
/// destination, one mip level, optimal tiling, device-local memory. Made with rate code 0 (1×1,
/// full rate) everywhere, and kept in `VK_IMAGE_LAYOUT_FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR`
/// between uses: a writer transitions it from and back to that layout, since every rewritten pass
/// names that layout as its initial and final one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shadow {
    /// The device both images belong to.
    pub device: ash::vk::Device,
    pub image: ash::vk::Image,
    /// Array layers: the application image's where the device has
    /// `layeredShadingRateAttachments`; otherwise 1, and that one layer must hold, per texel, the
    /// finer rate of all the application image's layers (both eyes share it; see
    /// docs/vulkan-fdm-on-fsr.md#multiview).
    pub layers: u32,
    /// The application image's array layers (more than `layers` where the layers are merged).
    pub app_layers: u32,
    /// Width and height in texels, the application image's.
    pub extent: [u32; 2],
}

/// Shadows by the application's `VkImage` handle. A leaf lock, not one of
/// [`crate::common::lock::Rank`]'s: it is taken for a look-up and a copy only, nothing is called while
/// it is held, so it may be taken under any other lock (fovea's own uploads record their barriers
/// under their fill and submit locks, and those barriers pass through the Vulkan layer, which asks
/// here).
static SHADOWS: crate::common::lock::SharedRwLock<std::collections::BTreeMap<u64, Shadow>> =
    crate::common::lock::SharedRwLock::new(std::collections::BTreeMap::new());

/// Records (or, with `None`, forgets) the shadow of the application's density-map image `app`.
pub fn set_shadow(app: ash::vk::Image, shadow: Option<Shadow>) {
    use ash::vk::Handle as _;
    let mut map = SHADOWS.write();
    match shadow {
        Some(s) => map.insert(app.as_raw(), s),
        None => map.remove(&app.as_raw()),
    };
}

/// The shadow of the application's density-map image `app`; `None` where it has none (not a
/// density map, not on an emulating device, or the shadow could not be made).
pub fn shadow_of(app: ash::vk::Image) -> Option<Shadow> {
    use ash::vk::Handle as _;
    SHADOWS.read().get(&app.as_raw()).copied()
}

thread_local! {
    /// Set while fovea creates its own density images on this thread.
    static OWN_DENSITY_IMAGES: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f` (fovea creating its own density images through the application's device) so that the
/// Vulkan layer, which sees those `vkCreateImage` calls like any other, can tell them from density
/// images the application creates and writes itself ([`creating_own_density_images`]).
pub fn own_density_images<R>(f: impl FnOnce() -> R) -> R {
    struct Reset(bool);
    impl Drop for Reset {
        fn drop(&mut self) {
            OWN_DENSITY_IMAGES.with(|c| c.set(self.0));
        }
    }
    let _reset = Reset(OWN_DENSITY_IMAGES.with(|c| c.replace(true)));
    f()
}

/// Whether this thread is inside [`own_density_images`]: the image being created is fovea's own,
/// and fovea writes its shading rates.
pub fn creating_own_density_images() -> bool {
    OWN_DENSITY_IMAGES.with(|c| c.get())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Quest's semantics for the debug properties: the level property is the level, or the
    /// maximum when dynamic; the dynamic property overrides the application's flag.
    #[test]
    fn overrides_apply_above_the_application() {
        let app = ProfileParams {
            level: 1,
            vertical_offset_deg: 5.0,
            dynamic: false,
            eye_tracked: false,
        };
        let none = DebugProperties::default();
        let level = |p: ProfileParams, o: DebugProperties, step| {
            let (pat, dynamic) = effective(p, o, step);
            (pat.level, dynamic)
        };
        assert_eq!(level(app, none, 0), (Level::Low, false));
        assert_eq!(effective(app, none, 0).0.vertical_offset_deg, 5.0);
        let high = DebugProperties {
            level: Some(Level::High),
            ..none
        };
        assert_eq!(
            level(app, high, 0),
            (Level::High, false),
            "the level, not dynamic"
        );
        let high_dynamic = DebugProperties {
            dynamic: Some(true),
            ..high
        };
        assert_eq!(level(app, high_dynamic, 0), (Level::None, true));
        assert_eq!(level(app, high_dynamic, 2), (Level::Medium, true));
        assert_eq!(
            level(app, high_dynamic, 3),
            (Level::High, true),
            "the maximum"
        );
        let app_dynamic = ProfileParams {
            dynamic: true,
            level: 3,
            ..app
        };
        let off = DebugProperties {
            dynamic: Some(false),
            ..none
        };
        assert_eq!(level(app_dynamic, off, 1), (Level::High, false));
        assert_eq!(level(app_dynamic, none, 1), (Level::Low, true));
        let top = DebugProperties {
            level: Some(Level::HighTop),
            ..none
        };
        assert_eq!(level(app, top, 0).0, Level::HighTop);
    }
}
