//! What fovea promises the outside world: its layers' names, the extensions it provides and their
//! versions, the environment variables it reads, its limits and its log targets.
//!
//! The layer, the `fovea` command-line tool and the tests all take these from here, so a name is
//! written once. `include/fovea.h` is the C mirror of this crate (its test compares the two).
#![forbid(unsafe_code)]

use std::ffi::CStr;

/// fovea's version, as its log header gives it.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The OpenXR API layer's name, as in its manifests and `XR_ENABLE_API_LAYERS`.
pub const LAYER_NAME: &str = "XR_APILAYER_FOVEA_foveation";

/// The Vulkan layer's name, as in its manifests, `VK_INSTANCE_LAYERS` and `ppEnabledLayerNames`. It
/// lives in the same library as the OpenXR layer.
pub const VK_LAYER_NAME: &str = "VK_LAYER_FOVEA_fragment_density_map";

/// The device extension the Vulkan layer provides where it emulates it, and the version it
/// reports (the version its manifest's `device_extensions` lists).
pub const VK_FDM_EXTENSION: &str = "VK_EXT_fragment_density_map";
/// See [`VK_FDM_EXTENSION`].
pub const VK_FDM_SPEC_VERSION: u32 = 3;

/// One of the six extensions the layer can provide.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Ext {
    SwapchainUpdateState,
    Foveation,
    FoveationConfiguration,
    FoveationVulkan,
    MetaFoveationEyeTracked,
    MetaVulkanSwapchainCreateInfo,
}

/// What the registry says of one extension.
#[derive(Clone, Copy, Debug)]
pub struct ExtInfo {
    pub ext: Ext,
    pub name: &'static CStr,
    pub version: u32,
    /// Extensions that must be enabled with it (xr.xml `depends`).
    pub depends: &'static [Ext],
}

/// The extensions fovea implements, in registry order.
pub const EXTENSIONS: [ExtInfo; 6] = [
    ExtInfo {
        ext: Ext::SwapchainUpdateState,
        name: c"XR_FB_swapchain_update_state",
        version: 3,
        depends: &[],
    },
    ExtInfo {
        ext: Ext::Foveation,
        name: c"XR_FB_foveation",
        version: 1,
        depends: &[Ext::SwapchainUpdateState],
    },
    ExtInfo {
        ext: Ext::FoveationConfiguration,
        name: c"XR_FB_foveation_configuration",
        version: 1,
        depends: &[Ext::Foveation],
    },
    ExtInfo {
        ext: Ext::FoveationVulkan,
        name: c"XR_FB_foveation_vulkan",
        version: 1,
        depends: &[Ext::Foveation],
    },
    // Where a gaze source exists (docs/eye-tracking.md#xr_meta_foveation_eye_tracked); xr.xml:
    // depends="XR_VERSION_1_0+XR_FB_foveation+XR_FB_foveation_configuration".
    ExtInfo {
        ext: Ext::MetaFoveationEyeTracked,
        name: c"XR_META_foveation_eye_tracked",
        version: 1,
        depends: &[Ext::Foveation, Ext::FoveationConfiguration],
    },
    ExtInfo {
        ext: Ext::MetaVulkanSwapchainCreateInfo,
        name: c"XR_META_vulkan_swapchain_create_info",
        version: 1,
        depends: &[],
    },
];

/// The Vulkan enable extensions XR_META_vulkan_swapchain_create_info needs one of (its prose; the
/// registry lists no dependency).
pub const VULKAN_ENABLE: [&CStr; 2] = [c"XR_KHR_vulkan_enable", c"XR_KHR_vulkan_enable2"];

impl Ext {
    /// What the registry says of this extension.
    pub fn info(self) -> &'static ExtInfo {
        &EXTENSIONS[self as usize]
    }

    /// The extension named `name`, if fovea implements it.
    pub fn by_name(name: &CStr) -> Option<Ext> {
        EXTENSIONS.iter().find(|e| e.name == name).map(|e| e.ext)
    }
}

/// Environment variables the layer reads, and the two the Vulkan loader reads for its Vulkan layer
/// (docs/settings.md lists each with its meaning).
pub mod env {
    /// `FOVEA_SYMMETRIC_FOV=1`: report one shared symmetric FOV for both eyes.
    pub const SYMMETRIC_FOV: &str = "FOVEA_SYMMETRIC_FOV";
    /// A file of `debug.oculus.foveation.*=value` lines, re-read while the app runs.
    pub const PROPS: &str = "FOVEA_PROPS";
    /// The log filter (a `tracing_subscriber::EnvFilter` string; default: warnings).
    pub const LOG: &str = "FOVEA_LOG";
    /// The log file (default `$XDG_STATE_HOME/fovea/fovea.log`); empty: no log file.
    pub const LOG_FILE: &str = "FOVEA_LOG_FILE";
    /// The configuration file (default `$XDG_CONFIG_HOME/fovea/fovea.toml`); empty: none.
    pub const CONFIG: &str = "FOVEA_CONFIG";
    /// The largest fragment any density map asks for: 1, 2 or 4 pixels per axis (default 4).
    pub const MAX_FRAGMENT: &str = "FOVEA_MAX_FRAGMENT";
    /// `FOVEA_INJECT=1`: foveate an application that never asks for it, by adding shading-rate
    /// attachments to its eye passes (docs/injection.md); above the file's `inject`.
    pub const INJECT: &str = "FOVEA_INJECT";
    /// The level injection uses (0-4 or a level name); above the file's `inject_level`.
    pub const INJECT_LEVEL: &str = "FOVEA_INJECT_LEVEL";
    /// `FOVEA_SUBSAMPLED=0|1`: reconstruct the coarse blocks of foveated swapchains as a subsampled
    /// image sampled bilinearly would show them, or not (docs/openxr-layer.md#subsampled-images);
    /// above the file's `subsampled`, below Quest's `debug.oculus.foveation.subsampled`.
    pub const SUBSAMPLED: &str = "FOVEA_SUBSAMPLED";
    /// `FOVEA_GAZE=0` switches the gaze source off (default on: the fovea follows the eyes where
    /// the runtime has eye gaze; docs/eye-tracking.md); above the file's `gaze`.
    pub const GAZE: &str = "FOVEA_GAZE";
    /// The gaze filter's cutoff at rest, in Hz (`gaze_min_cutoff_hz`).
    pub const GAZE_MIN_CUTOFF_HZ: &str = "FOVEA_GAZE_MIN_CUTOFF_HZ";
    /// How fast the filter's cutoff rises with the gaze's speed (`gaze_beta`).
    pub const GAZE_BETA: &str = "FOVEA_GAZE_BETA";
    /// The cutoff of the filter's speed estimate, in Hz (`gaze_d_cutoff_hz`).
    pub const GAZE_D_CUTOFF_HZ: &str = "FOVEA_GAZE_D_CUTOFF_HZ";
    /// A jump of at least this many degrees is a saccade, taken as it is (`gaze_saccade_deg`).
    pub const GAZE_SACCADE_DEG: &str = "FOVEA_GAZE_SACCADE_DEG";
    /// How long the last good gaze is held while it is invalid, in seconds (`gaze_hold_s`).
    pub const GAZE_HOLD_S: &str = "FOVEA_GAZE_HOLD_S";
    /// How long the fovea then eases back to fixed foveation, in seconds (`gaze_return_s`).
    pub const GAZE_RETURN_S: &str = "FOVEA_GAZE_RETURN_S";
    /// Distance of the fixation plane the gaze ray meets, in metres (`gaze_fixation_m`).
    pub const GAZE_FIXATION_M: &str = "FOVEA_GAZE_FIXATION_M";
    /// Seconds before fovea attaches its gaze action set alone for an application that attached
    /// none, or `never` (`gaze_attach_after_s`).
    pub const GAZE_ATTACH_AFTER_S: &str = "FOVEA_GAZE_ATTACH_AFTER_S";
    /// Names a hook that panics on purpose, to prove panics never cross the FFI boundary.
    pub const INJECT_PANIC: &str = "FOVEA_INJECT_PANIC";
    /// `FOVEA_VK_LAYER=1`: the `enable_environment` of the implicit Vulkan layer manifest that
    /// `fovea install` writes, so the Vulkan loader loads the Vulkan layer only into processes that
    /// set it. The OpenXR layer sets it (once, when an instance enables XR_KHR_vulkan_enable or
    /// XR_KHR_vulkan_enable2) where it is not set already; `FOVEA_VK_LAYER=0` keeps it out.
    pub const VK_LAYER: &str = "FOVEA_VK_LAYER";
    /// `DISABLE_FOVEA_VK_LAYER=1`: the implicit Vulkan layer manifest's `disable_environment`, read
    /// by the Vulkan loader; it wins over [`VK_LAYER`]
    /// (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>).
    pub const DISABLE_VK_LAYER: &str = "DISABLE_FOVEA_VK_LAYER";

    // XR_META_foveation_eye_tracked.
    /// `FOVEA_EYE_TRACKED_Y_UP=1`: the centres `xrGetFoveationEyeTrackedStateMETA` returns have y
    /// up (OpenXR's NDC) instead of y down (Quest's and Godot's); above the file's
    /// `eye_tracked_y_up`.
    pub const EYE_TRACKED_Y_UP: &str = "FOVEA_EYE_TRACKED_Y_UP";
}

/// The longest `next` chain the layer follows. The spec puts no bound on chains, but real ones
/// hold a handful of structs; a longer one is almost certainly a loop, which the spec forbids
/// (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#valid-usage-for-structure-pointer-chains),
/// and following it would hang the application.
pub const MAX_CHAIN_LENGTH: usize = 64;

/// `tracing` targets that tools and tests filter on.
pub mod log_target {
    /// The once-a-second stats line.
    pub const STATS: &str = "fovea::stats";
    /// A step of the dynamic foveation level (one line per change).
    pub const DYNAMIC: &str = "fovea::dynamic";
    /// How fovea learned what the runtime below offers (one line per process).
    pub const BELOW: &str = "fovea::below";
    /// One line per instance: what fovea provides and what is native below.
    pub const INSTANCE: &str = "fovea::instance";
    /// One line per VkInstance created through the Vulkan layer: the layer is loaded there.
    pub const VK_INSTANCE: &str = "fovea::vk_instance";
    /// The gaze source: why it falls back to fixed foveation (one line per cause), and at `trace`
    /// the gaze located for each frame.
    pub const GAZE: &str = "fovea::gaze";
}
