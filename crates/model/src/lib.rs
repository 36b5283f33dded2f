//! fovea's model: plain Rust, no FFI, no `unsafe`. Everything here is a pure function of its inputs
//! and is tested directly; the layer's hooks translate OpenXR and Vulkan values into these types and
//! call in.
//!
//! - [`fov`]: the one FOV type and the projection centre;
//! - [`projection`]: projection matrices and symmetric-FOV sizing;
//! - [`density`]: the density model (which fragment size each density-map texel may use);
//! - [`dynamic`]: the dynamic-level controller;
//! - [`gaze`]: eye-tracker samples filtered, held and projected into each eye;
//! - [`stats`]: the once-a-second stats window and its line;
//! - [`maps`]: what each layer of a density map holds, and filling it;
//! - [`headsets`]: headset presets as runtimes report them, and eye-buffer sizing;
//! - [`inject`]: which passes of an app that never asked are eye passes, and their rate codes;
//! - [`shading_rate`]: density-map bytes to shading-rate attachment codes;
//! - [`shift`]: moving the fovea by shifting a fixed map, as density-map offsets do.
#![forbid(unsafe_code)]

pub mod density;
pub mod dynamic;
pub mod fov;
pub mod gaze;
pub mod headsets;
pub mod inject;
pub mod maps;
pub mod projection;
pub mod shading_rate;
pub mod shift;
pub mod stats;

pub use fov::Fov;
