//! The FFI edge every hook stands on: the panic guard, the caller's names and arrays, the two-call
//! idiom, and a dispatchable handle's loader key.

use std::ffi::{c_char, CStr};
use std::hash::Hasher;
use std::sync::atomic::{AtomicBool, Ordering};

use ash::vk;

/// Runs a Vulkan entry point's body inside the layer's one panic guard
/// ([`crate::common::guard`]): a panic never unwinds into the application, it becomes `fail` and
/// one error line naming the command.
#[inline(always)]
pub fn guard<R>(function: &'static str, fail: R, body: impl FnOnce() -> R) -> R {
    crate::common::guard::guard(function, "panic inside the Vulkan layer", fail, body)
}

/// A NUL-terminated name from the caller.
///
/// # Safety
/// `p` must be NULL or NUL-terminated.
pub unsafe fn name<'a>(p: *const c_char) -> Option<&'a CStr> {
    // SAFETY: as the caller promised.
    (!p.is_null()).then(|| unsafe { CStr::from_ptr(p) })
}

/// Whether `want` is among `count` extension names.
///
/// # Safety
/// `names` must be NULL or hold `count` NUL-terminated strings.
pub unsafe fn extension_enabled(names: *const *const c_char, count: u32, want: &CStr) -> bool {
    if names.is_null() {
        return false;
    }
    // SAFETY: as the caller promised.
    unsafe { std::slice::from_raw_parts(names, count as usize) }
        .iter()
        // SAFETY: as the caller promised.
        .any(|&n| unsafe { name(n) } == Some(want))
}

/// The Vulkan two-call idiom: NULL `out` asks for the count; otherwise as many as fit are written
/// and `VK_INCOMPLETE` says some were left out
/// (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#fundamentals-returncodes>).
///
/// # Safety
/// `count` must be valid for reads and writes; `out` NULL or valid for `*count` writes.
pub unsafe fn two_call<T: Copy>(items: &[T], count: *mut u32, out: *mut T) -> vk::Result {
    if count.is_null() {
        return vk::Result::ERROR_INITIALIZATION_FAILED;
    }
    // SAFETY: as the caller promised.
    unsafe {
        if out.is_null() {
            *count = items.len() as u32;
            return vk::Result::SUCCESS;
        }
        let n = (*count as usize).min(items.len());
        std::ptr::copy_nonoverlapping(items.as_ptr(), out, n);
        *count = n as u32;
        if n < items.len() {
            vk::Result::INCOMPLETE
        } else {
            vk::Result::SUCCESS
        }
    }
}

/// The loader's dispatch pointer of a dispatchable handle.
pub type Key = usize;

/// The key of a dispatchable handle; `None` for a null handle.
///
/// # Safety
/// `handle` must be null or a live dispatchable handle made by the loader.
pub unsafe fn key(handle: impl vk::Handle) -> Option<Key> {
    let raw = handle.as_raw() as usize;
    // SAFETY: a live dispatchable handle points at an object starting with the dispatch pointer.
    (raw != 0).then(|| unsafe { *(raw as *const usize) })
}

/// The raw handle, for log lines.
pub fn raw(handle: impl vk::Handle) -> u64 {
    handle.as_raw()
}

/// The application's array, or an empty one for NULL or a zero count.
///
/// # Safety
/// `p` must be NULL or valid for `n` reads.
pub unsafe fn slice<'a, T>(p: *const T, n: u32) -> &'a [T] {
    if p.is_null() || n == 0 {
        &[]
    } else {
        // SAFETY: as the caller promised.
        unsafe { std::slice::from_raw_parts(p, n as usize) }
    }
}

/// Logs `message` the first time `flag` is seen unset.
pub fn once(flag: &AtomicBool, message: &str) {
    if !flag.swap(true, Ordering::Relaxed) {
        tracing::warn!("{message}");
    }
}

/// A cheap hasher for dispatchable handles, which are heap addresses (their low bits are alignment,
/// so the high bits are mixed in): one multiply.
#[derive(Default)]
pub struct AddressHasher(u64);

impl Hasher for AddressHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ u64::from(b)).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        }
    }
    fn write_u64(&mut self, v: u64) {
        self.0 = (v ^ (v >> 29)).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_call_idiom() {
        let items = [1u32, 2, 3];
        let mut count = 0;
        let mut out = [0u32; 3];
        // SAFETY: valid pointers on the stack.
        unsafe {
            assert_eq!(
                two_call(&items, &mut count, std::ptr::null_mut()),
                vk::Result::SUCCESS
            );
            assert_eq!(count, 3);
            count = 2;
            assert_eq!(
                two_call(&items, &mut count, out.as_mut_ptr()),
                vk::Result::INCOMPLETE
            );
            assert_eq!((count, out), (2, [1, 2, 0]));
            count = 3;
            assert_eq!(
                two_call(&items, &mut count, out.as_mut_ptr()),
                vk::Result::SUCCESS
            );
        }
        assert_eq!(out, items);
    }

    #[test]
    fn guard_turns_panics_into_the_failure_value() {
        assert_eq!(guard("t", 1, || panic!("boom")), 1);
        assert_eq!(guard("t", 1, || 2), 2);
    }
}

/// `VK_EXT_fragment_density_map_offset` and the `VK_QCOM_fragment_density_map_offset` name it was
/// promoted from: the layer offers both on emulating devices (docs/vulkan-layer.md#density-map-offsets).
/// The structs are the same under both names
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/VK_EXT_fragment_density_map_offset.html>):
/// ash's `…QCOM` ones, with the same `sType` values; what ash 0.38 lacks is below.
pub mod offset {
    use std::ffi::{c_void, CStr};

    use ash::vk;

    pub const EXT_NAME: &CStr = c"VK_EXT_fragment_density_map_offset";
    pub const EXT_SPEC_VERSION: u32 = 1;
    pub const QCOM_NAME: &CStr = ash::qcom::fragment_density_map_offset::NAME;
    /// Revision 3, the registry's latest (ash 0.38 has 1).
    pub const QCOM_SPEC_VERSION: u32 = 3;

    /// `VK_STRUCTURE_TYPE_RENDER_PASS_FRAGMENT_DENSITY_MAP_OFFSET_END_INFO_EXT`, the QCOM struct's.
    pub const END_INFO: vk::StructureType =
        vk::StructureType::SUBPASS_FRAGMENT_DENSITY_MAP_OFFSET_END_INFO_QCOM;
    /// `VkRenderPassFragmentDensityMapOffsetEndInfoEXT`.
    pub type EndInfo<'a> = vk::SubpassFragmentDensityMapOffsetEndInfoQCOM<'a>;

    /// `VK_STRUCTURE_TYPE_RENDERING_END_INFO_KHR` (`…_EXT` is the same value), newer than ash's
    /// headers (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderingEndInfoKHR.html>).
    pub const RENDERING_END_INFO: vk::StructureType = vk::StructureType::from_raw(1_000_619_003);

    /// `VkRenderingEndInfoKHR` (= `VkRenderingEndInfoEXT`).
    #[repr(C)]
    #[derive(Clone, Copy, Debug)]
    pub struct RenderingEndInfo {
        pub s_type: vk::StructureType,
        pub p_next: *const c_void,
    }

    impl Default for RenderingEndInfo {
        fn default() -> RenderingEndInfo {
            RenderingEndInfo {
                s_type: RENDERING_END_INFO,
                p_next: std::ptr::null(),
            }
        }
    }
}

/// ash's command pointer types and the ones ash 0.38 lacks, for the one command list
/// ([`crate::vk::base::commands`]).
pub mod pfn {
    pub use ash::vk::*;

    /// `vkCmdEndRendering2KHR` (`VK_KHR_maintenance10`) and `vkCmdEndRendering2EXT`
    /// (`VK_EXT_fragment_density_map_offset`): one signature.
    #[allow(non_camel_case_types)]
    pub type PFN_vkCmdEndRendering2KHR = unsafe extern "system" fn(
        command_buffer: CommandBuffer,
        info: *const super::offset::RenderingEndInfo,
    );
}
