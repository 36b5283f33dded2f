//! The layer's integration tests, one module per subject, in one test binary: one link instead of
//! one per file, and the tests of every module run side by side.
//!
//! A test that needs a process of its own runs its body in a child process of this binary
//! ([`support::in_own_process`]): the environment it sets, or the process-wide counts it asserts on,
//! are then its alone. Two tests stay binaries of their own, since even the suite's parent process
//! would spoil them: `tests/unload.rs` (no other test may hold libfovea.so open) and
//! `tests/panic_containment.rs` (its environment must be set before the layer is first called).

mod support;

// The layer reads no fovea.toml and writes no log file in the user's home during tests.
fovea_harness::private_home!();

mod below;
mod c_header;
mod docs_commands;
mod example_modes;
mod fault_injection;
mod fdm_emulated;
mod fdm_vulkan;
mod foveation_state;
mod fuzz_sequences;
mod hello_xr;
mod khronos_loader;
mod layer_core;
mod manifests;
mod monado;
mod pipeline;
mod settings_file;
mod symmetric_fov;
mod threads;
mod tidy;
mod vk_api14;
mod vk_app_written_maps;
mod vk_clears;
mod vk_convert;
mod vk_device_matrix;
mod vk_enable;
mod vk_faults;
mod vk_fuzz;
mod vk_inject;
mod vk_inject_devices;
mod vk_layer;
mod vk_passes;
mod vk_pipelines;
mod vk_recording;
mod vk_threads;
