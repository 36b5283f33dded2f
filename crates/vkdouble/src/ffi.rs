//! The loader–layer structures of `vk_layer.h`, which are not part of `vk.xml` and so not in ash.
//!
//! Layout and protocol: Vulkan-Loader `docs/LoaderLayerInterface.md`
//! (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>),
//! sections "Layer Version Negotiation" and "Layer Dispatch Initialization".

use std::ffi::c_void;

use ash::vk;

/// `VkLayerFunction`: which member of the create-info union the loader filled.
pub const LAYER_LINK_INFO: u32 = 0;
/// `VK_LOADER_DATA_CALLBACK`: the union holds `vkSetDeviceLoaderData`.
pub const LOADER_DATA_CALLBACK: u32 = 1;

/// `LAYER_NEGOTIATE_INTERFACE_STRUCT`.
pub const NEGOTIATE_INTERFACE_STRUCT: u32 = 1;

/// `PFN_GetPhysicalDeviceProcAddr`.
pub type PfnGetPhysicalDeviceProcAddr =
    unsafe extern "system" fn(vk::Instance, *const std::ffi::c_char) -> vk::PFN_vkVoidFunction;

/// `PFN_vkSetDeviceLoaderData`: gives an object the layer made itself (a command buffer) the
/// loader's dispatch pointer, as the LoaderLayerInterface requires for dispatchable objects.
pub type PfnSetDeviceLoaderData = unsafe extern "system" fn(vk::Device, *mut c_void) -> vk::Result;

/// `VkNegotiateLayerInterface`.
#[repr(C)]
pub struct NegotiateLayerInterface {
    pub s_type: u32,
    pub p_next: *mut c_void,
    pub loader_layer_interface_version: u32,
    pub pfn_get_instance_proc_addr: Option<vk::PFN_vkGetInstanceProcAddr>,
    pub pfn_get_device_proc_addr: Option<vk::PFN_vkGetDeviceProcAddr>,
    pub pfn_get_physical_device_proc_addr: Option<PfnGetPhysicalDeviceProcAddr>,
}

/// `VkLayerInstanceLink`: one element of the loader's list of layers below.
#[repr(C)]
pub struct LayerInstanceLink {
    pub p_next: *mut LayerInstanceLink,
    pub pfn_next_get_instance_proc_addr: vk::PFN_vkGetInstanceProcAddr,
    pub pfn_next_get_physical_device_proc_addr: Option<PfnGetPhysicalDeviceProcAddr>,
}

/// `VkLayerInstanceCreateInfo` (sType `VK_STRUCTURE_TYPE_LOADER_INSTANCE_CREATE_INFO`). The union's
/// largest member is a pair of function pointers, so it is declared as two words.
#[repr(C)]
pub struct LayerInstanceCreateInfo {
    pub s_type: vk::StructureType,
    pub p_next: *const c_void,
    pub function: u32,
    pub u: [*mut c_void; 2],
}

/// `VkLayerDeviceLink`.
#[repr(C)]
pub struct LayerDeviceLink {
    pub p_next: *mut LayerDeviceLink,
    pub pfn_next_get_instance_proc_addr: vk::PFN_vkGetInstanceProcAddr,
    pub pfn_next_get_device_proc_addr: vk::PFN_vkGetDeviceProcAddr,
}

/// `VkLayerDeviceCreateInfo` (sType `VK_STRUCTURE_TYPE_LOADER_DEVICE_CREATE_INFO`).
#[repr(C)]
pub struct LayerDeviceCreateInfo {
    pub s_type: vk::StructureType,
    pub p_next: *const c_void,
    pub function: u32,
    pub u: *mut c_void,
}
