//! The Vulkan side: fovea's Vulkan layer on lavapipe under the Khronos validation layer and the
//! shading-rate test double ([`crate::support::vulkan`]).

pub mod api14;
pub mod app_written_maps;
pub mod clears;
pub mod convert;
pub mod device_matrix;
pub mod faults;
pub mod fuzz;
pub mod inject;
pub mod layer;
pub mod lifetimes;
pub mod offsets;
pub mod passes;
pub mod pipelines;
pub mod queues;
pub mod reconstruction;
pub mod recording;
pub mod threads;
