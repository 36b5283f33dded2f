//! The intercepted OpenXR functions: ordinary Rust functions on typed values that validate what the
//! application passed, translate it to plain Rust values, call into the layer's model, and pass the
//! call on.
//!
//! Their exported entry points are generated from the table in [`crate::xr::dispatch`]: each runs
//! its hook inside [`crate::xr::ffi::run_hook`] (the panic guard), so a panic becomes `XR_ERROR_RUNTIME_FAILURE`, and
//! hands it the application's pointers as [`In`](crate::xr::ffi::In),
//! [`Out`](crate::xr::ffi::Out) and [`OutArray`](crate::xr::ffi::OutArray). The only
//! `unsafe` left in a hook is the call down to the next layer and reads of pointer members the
//! spec's valid usage vouches for, each commented.
//! Where the layer cannot do its own work, the application's call still goes down (fail open) and
//! the log says why.

pub mod actions;
pub mod foveation;
pub mod frame;
pub mod instance;
pub mod session;
pub mod swapchain;
pub mod vulkan_enable;
pub mod vulkan_layer;
