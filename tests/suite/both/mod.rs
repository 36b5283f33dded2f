//! Both layers at once: OpenXR applications whose Vulkan work goes through fovea's Vulkan layer,
//! the example application, Khronos `hello_xr`, Monado and Qt's Quick 3D XR on it.

pub mod example_modes;
pub mod fdm_emulated;
pub mod fdm_vulkan;
pub mod gaze_follow;
pub mod hello_xr;
pub mod monado;
pub mod qt_xr;
pub mod session_lifetimes;
pub mod vulkan_enable;
