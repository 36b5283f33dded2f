//! fovea: an OpenXR API layer that brings Meta Quest's fixed foveated rendering API
//! (XR_FB_swapchain_update_state, XR_FB_foveation, XR_FB_foveation_configuration,
//! XR_FB_foveation_vulkan, XR_META_vulkan_swapchain_create_info) to any OpenXR runtime with Vulkan,
//! and XR_META_foveation_eye_tracked where the runtime has eye gaze.
//!
//! The crate builds `libfovea.so`; nothing in it is public but the entry points the loaders call.
//! The folders (see `docs/ARCHITECTURE.md`), in floors: each imports only those below it.
//! - [`xr`] and [`vk`]: the OpenXR side (loader interface, dispatch, handle registry, hooks per
//!   function group, fovea's density images; its own floors in its module doc) and the Vulkan layer.
//!   Neither imports the other;
//! - [`bridge`]: what both sides read, and only that: each device's density-map emulation, the
//!   shadows of density-map images, injection's published state, the reconstruction decisions.
//!   The two API sides meet only here;
//! - [`common`]: plumbing both sides use: ranked locks, logging, settings.
//!
//! The pure model (density, projection, dynamic levels, stats) is the `fovea-model` crate.
//!
//! Every unsafe operation sits in its own `unsafe` block with a `SAFETY:` comment saying why it is
//! sound, also inside `unsafe fn`s, whose `# Safety` sections say what their callers promise.

#![deny(unsafe_op_in_unsafe_fn)]
#![warn(clippy::undocumented_unsafe_blocks)]

mod bridge;
mod common;
mod vk;
mod xr;
