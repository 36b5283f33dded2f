//! fovea: an OpenXR API layer that brings Meta Quest's fixed foveated rendering API
//! (XR_FB_swapchain_update_state, XR_FB_foveation, XR_FB_foveation_configuration,
//! XR_FB_foveation_vulkan, XR_META_vulkan_swapchain_create_info) to any OpenXR runtime with Vulkan.
//!
//! The loader sees one exported symbol, [`loader::xrNegotiateLoaderApiLayerInterface`]. From there:
//! - [`loader`]: negotiation, `xrCreateApiLayerInstance`, `xrGetInstanceProcAddr`;
//! - [`dispatch`]: the one list of intercepted functions and the next layer's table;
//! - [`state`]: what the layer knows of each handle;
//! - [`hooks`]: the intercepted functions, thin adapters over the model;
//! - [`extensions`]: the provided extensions, their versions and dependencies;
//! - [`density`] and [`projection`]: the density model and projection math, pure functions;
//! - [`fdm`]: the Vulkan density images of XR_FB_foveation_vulkan, filled from the density model;
//! - [`settings`], [`log`]: what the environment configures.

pub mod density;
pub mod dispatch;
pub mod dynamic;
pub mod extensions;
pub mod fdm;
pub mod ffi;
mod hooks;
pub mod loader;
pub mod lock;
pub mod log;
pub mod projection;
pub mod settings;
pub mod state;
pub mod stats;

/// The layer's name, as in its manifests and `XR_ENABLE_API_LAYERS`.
pub const LAYER_NAME: &str = "XR_APILAYER_FOVEA_foveation";
