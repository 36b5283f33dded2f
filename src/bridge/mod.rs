//! The foveation bridge: the state both API sides read, and nothing else. Both layers live in one
//! library; the OpenXR side knows which swapchain image, view and map belong together, the Vulkan
//! side sees the devices, images and render passes that use them. Neither imports the other; they
//! meet here:
//!
//! - how each device emulates density maps and whether offsets reach them ([`FdmEmulation`],
//!   [`device_fdm`], [`device_offsets`]), which the Vulkan side decides and fovea's own density
//!   images size themselves by;
//! - the shadows of density-map images ([`Shadow`], [`shadow_of`]) and which density images are
//!   fovea's own ([`own_density_images`]);
//! - what injection publishes for the Vulkan side ([`inject`]);
//! - which swapchain images get their coarse blocks reconstructed ([`subsampled`]).
//!
//! What only the OpenXR side reads (the swapchain's foveation state, `MapKey`, the pattern under
//! the debug overrides) is `crate::xr::foveation`.

pub mod inject;
pub mod subsampled;

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
