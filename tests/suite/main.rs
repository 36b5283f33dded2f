//! The layer's integration tests, one module per subject, in one test binary: one link instead of
//! one per file, and the tests of every module run side by side. The folders mirror the code:
//! `xr/` tests the OpenXR side (src/xr), `vk/` the Vulkan side (src/vk), `both/` the two together
//! (an OpenXR application whose Vulkan work goes through fovea's Vulkan layer), `meta/` the
//! repository itself (house rules, manifests, the C header); `support/` is what they share.
//!
//! A test that needs a process of its own runs its body in a child process of this binary
//! ([`support::in_own_process`]): the environment it sets, or the process-wide counts it asserts on,
//! are then its alone. Two tests stay binaries of their own, since even the suite's parent process
//! would spoil them: `tests/unload.rs` (no other test may hold libfovea.so open) and
//! `tests/panic_containment.rs` (its environment must be set before the layer is first called).

mod support;

// The layer reads no fovea.toml and writes no log file in the user's home during tests.
fovea_harness::private_home!();

mod both;
mod meta;
mod vk;
mod xr;
