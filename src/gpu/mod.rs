//! The GPU work: fovea's density images on the application's Vulkan device and their upload.

pub mod density_images;
