//! The Vulkan side: `VK_LAYER_FOVEA_fragment_density_map`, a Vulkan layer in the same library as
//! the OpenXR layer, that offers `VK_EXT_fragment_density_map` on devices that have shading-rate
//! attachments (`VK_KHR_fragment_shading_rate`) and no density maps of their own, so that an
//! application's fragment-density-map code path shades fewer fragments on a desktop GPU.
//!
//! This folder never imports the OpenXR side; both meet in [`crate::bridge`].
//!
//! - [`loader`]: the loader interface (negotiation, `vkGetInstanceProcAddr`,
//!   `vkGetDeviceProcAddr`), instance creation, and the panic guard;
//! - [`dispatch`]: the one list of intercepted commands;
//! - [`registry`]: per-instance and per-device state, keyed by the loader's dispatch pointer;
//! - [`physical`]: the per-physical-device decision and what the application sees of a device;
//! - [`device`]: device creation (density maps stripped, shading-rate attachments enabled) and the
//!   device commands;
//! - [`pipeline`]: graphics pipelines get the shading-rate state, shader modules that read the
//!   fragment size are detected, subsampled sampler and dynamic view flags are left out;
//! - [`barrier`]: barriers and event waits without the density-map layout, stage and access bits;
//! - [`image`]: the layer-owned shading-rate shadows of density-map images and views;
//! - [`pass`]: render passes, framebuffers and dynamic rendering, rewritten to name the shadows;
//! - [`chain`], [`link`]: `pNext` chains and the loader's link structs.
//!
//! Per physical device: native density maps → everything passes through untouched;
//! `attachmentFragmentShadingRate` without them → emulate; neither → pass through. Fail open:
//! where the layer cannot do its part, the application's calls go down untouched and the log says
//! why, once.

#![deny(unsafe_op_in_unsafe_fn)]

mod barrier;
mod chain;
mod device;
mod dispatch;
mod image;
mod link;
mod loader;
mod pass;
mod physical;
mod pipeline;
mod registry;
