//! The simulated runtime's integration tests, one module per subject, in one test binary. Tests
//! that set the process environment or count the runtime's objects process-wide run in a child
//! process of this binary ([`process::in_own_process`]).

#[macro_use]
mod common;
#[path = "../../../../tests/suite/support/process.rs"]
mod process;

mod actions;
mod eye_gaze;
mod khronos_loader;
mod leaks;
mod lifecycle;
mod native_foveation;
mod refuser_harness;
mod refuser_khronos_loader;
mod strict;
mod view_configuration_fov;
mod vulkan;
