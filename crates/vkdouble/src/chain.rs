//! pNext chains: finding a struct, and removing structs without writing the application's memory.
//!
//! Removing a struct means changing its predecessor's `pNext`, so every struct before the last
//! removed one is copied; the tail after it is shared. Copying needs each struct's size, which the
//! chain does not carry; [`size_of_stype`] knows the structs that extend the create infos the
//! double rewrites. Chain semantics:
//! <https://registry.khronos.org/vulkan/specs/latest/man/html/VkBaseInStructure.html>.

use std::ffi::c_void;

use ash::vk;
use ash::vk::TaggedStructure;

use crate::ffi;

/// The `sType` and `pNext` every chained struct starts with.
#[repr(C)]
struct Header {
    s_type: vk::StructureType,
    p_next: *const c_void,
}

macro_rules! sizes {
    ($($t:ident),* $(,)?) => {
        /// The size of a struct that can sit in a chain the double copies, by its `sType`.
        fn size_of_stype(s: vk::StructureType) -> Option<usize> {
            $( if s == vk::$t::STRUCTURE_TYPE { return Some(std::mem::size_of::<vk::$t<'static>>()); } )*
            if s == vk::StructureType::LOADER_INSTANCE_CREATE_INFO {
                return Some(std::mem::size_of::<ffi::LayerInstanceCreateInfo>());
            }
            if s == vk::StructureType::LOADER_DEVICE_CREATE_INFO {
                return Some(std::mem::size_of::<ffi::LayerDeviceCreateInfo>());
            }
            None
        }
    };
}

sizes![
    // vkCreateDevice
    PhysicalDeviceFeatures2,
    PhysicalDeviceVulkan11Features,
    PhysicalDeviceVulkan12Features,
    PhysicalDeviceVulkan13Features,
    PhysicalDeviceFragmentShadingRateFeaturesKHR,
    PhysicalDeviceDynamicRenderingFeatures,
    PhysicalDeviceSynchronization2Features,
    PhysicalDeviceMultiviewFeatures,
    PhysicalDeviceImagelessFramebufferFeatures,
    PhysicalDeviceTimelineSemaphoreFeatures,
    PhysicalDeviceBufferDeviceAddressFeatures,
    PhysicalDeviceDescriptorIndexingFeatures,
    PhysicalDeviceShaderDrawParametersFeatures,
    PhysicalDevice16BitStorageFeatures,
    PhysicalDevice8BitStorageFeatures,
    PhysicalDeviceShaderFloat16Int8Features,
    PhysicalDeviceSamplerYcbcrConversionFeatures,
    PhysicalDeviceHostQueryResetFeatures,
    PhysicalDeviceScalarBlockLayoutFeatures,
    PhysicalDeviceUniformBufferStandardLayoutFeatures,
    PhysicalDeviceVulkanMemoryModelFeatures,
    PhysicalDeviceSeparateDepthStencilLayoutsFeatures,
    PhysicalDeviceMaintenance4Features,
    DeviceGroupDeviceCreateInfo,
    DebugUtilsMessengerCreateInfoEXT,
    // VkSubpassDescription2
    FragmentShadingRateAttachmentInfoKHR,
    SubpassDescriptionDepthStencilResolve,
    // VkGraphicsPipelineCreateInfo
    PipelineFragmentShadingRateStateCreateInfoKHR,
    PipelineRenderingCreateInfo,
    PipelineCreationFeedbackCreateInfo,
    PipelineLibraryCreateInfoKHR,
    // VkRenderingInfo
    RenderingFragmentShadingRateAttachmentInfoKHR,
    DeviceGroupRenderPassBeginInfo,
    MultiviewPerViewAttributesInfoNVX,
    RenderingFragmentDensityMapAttachmentInfoEXT,
];

/// A chain rebuilt without some structs; owns the copies its head points into.
pub struct Stripped {
    _storage: Vec<Vec<u64>>,
    /// The new chain's first struct (may be the original tail, or null).
    pub head: *const c_void,
}

/// Rebuilds the chain at `head` without the structs whose `sType` is in `drop`.
///
/// `Err(sType)` names a struct before a removed one whose size is unknown, so it cannot be copied.
///
/// # Safety
/// `head` must be null or a valid chain of Vulkan structs.
pub unsafe fn strip(
    head: *const c_void,
    drop: &[vk::StructureType],
) -> Result<Stripped, vk::StructureType> {
    let mut nodes = Vec::new();
    let mut p = head;
    while !p.is_null() {
        nodes.push(p);
        // SAFETY: every struct in a chain starts with sType and pNext (the caller's promise).
        p = unsafe { (*(p as *const Header)).p_next };
    }
    // SAFETY: as above.
    let stype = |n: *const c_void| unsafe { (*(n as *const Header)).s_type };
    let Some(last) = nodes.iter().rposition(|&n| drop.contains(&stype(n))) else {
        return Ok(Stripped {
            _storage: Vec::new(),
            head,
        });
    };
    let mut storage = Vec::new();
    let mut next: *const c_void = nodes.get(last + 1).copied().unwrap_or(std::ptr::null());
    for &n in nodes[..=last].iter().rev() {
        let s = stype(n);
        if drop.contains(&s) {
            continue;
        }
        let size = size_of_stype(s).ok_or(s)?;
        let mut copy = vec![0u64; size.div_ceil(8)];
        // SAFETY: `n` points at a struct of `size` bytes (its sType says so); `copy` holds at
        // least `size` bytes and does not overlap it.
        unsafe {
            std::ptr::copy_nonoverlapping(n as *const u8, copy.as_mut_ptr() as *mut u8, size)
        };
        // SAFETY: `copy` starts with a Header (it is a copy of a chained struct).
        unsafe { (*(copy.as_mut_ptr() as *mut Header)).p_next = next };
        next = copy.as_ptr() as *const c_void;
        storage.push(copy);
    }
    Ok(Stripped {
        _storage: storage,
        head: next,
    })
}

/// The first struct of type `T` in the chain at `head`.
///
/// # Safety
/// `head` must be null or a valid chain of Vulkan structs.
pub unsafe fn find<T: TaggedStructure>(head: *const c_void) -> Option<*const T> {
    let mut p = head;
    while !p.is_null() {
        // SAFETY: every struct in a chain starts with sType and pNext.
        let h = unsafe { &*(p as *const Header) };
        if h.s_type == T::STRUCTURE_TYPE {
            return Some(p as *const T);
        }
        p = h.p_next;
    }
    None
}

/// The first struct with `sType` `s` in the chain at `head`, for output chains the caller owns.
///
/// # Safety
/// `head` must be null or a valid chain of Vulkan structs.
pub unsafe fn find_raw(head: *const c_void, s: vk::StructureType) -> Option<*mut c_void> {
    let mut p = head;
    while !p.is_null() {
        // SAFETY: every struct in a chain starts with sType and pNext.
        let h = unsafe { &*(p as *const Header) };
        if h.s_type == s {
            return Some(p as *mut c_void);
        }
        p = h.p_next;
    }
    None
}

/// Every struct with `sType` `s` in the chain at `head` (loader link infos come several to a chain).
///
/// # Safety
/// `head` must be null or a valid chain of Vulkan structs.
pub unsafe fn find_all(head: *const c_void, s: vk::StructureType) -> Vec<*mut c_void> {
    let mut out = Vec::new();
    let mut p = head;
    while !p.is_null() {
        // SAFETY: every struct in a chain starts with sType and pNext.
        let h = unsafe { &*(p as *const Header) };
        if h.s_type == s {
            out.push(p as *mut c_void);
        }
        p = h.p_next;
    }
    out
}
