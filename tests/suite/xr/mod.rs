//! The OpenXR side: the layer as the OpenXR loader and applications see it, through the harness
//! (fake loader, simulated runtime) or the Khronos loader.

pub mod below;
pub mod bystander;
pub mod eye_tracked;
pub mod faults;
pub mod foveation_state;
pub mod frame_pipeline;
pub mod fuzz;
pub mod gaze;
pub mod gaze_spec;
pub mod khronos_loader;
pub mod layer;
pub mod settings_file;
pub mod subsampled;
pub mod symmetric_fov;
pub mod threads;
