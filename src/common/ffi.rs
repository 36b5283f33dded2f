//! The FFI edge: panic containment, next-chain walking and copying, C strings, and the one struct
//! openxr-sys lays out wrongly.
//!
//! Everything that touches raw pointers handed in by the application or the runtime lives here or in
//! the thin hook adapters; the rest of the crate works with plain Rust values.

use std::ffi::{c_char, c_void, CStr};
use std::panic::{catch_unwind, AssertUnwindSafe};

use openxr_sys as xr;

/// Runs a hook body so that a panic never unwinds into the application (that would be undefined
/// behaviour across `extern "system"`). A panic becomes `XR_ERROR_RUNTIME_FAILURE` and one error
/// line naming the function; the application goes on.
pub fn guard(function: &'static str, body: impl FnOnce() -> xr::Result) -> xr::Result {
    let body = || {
        if injected_panic().is_some_and(|f| f == function) {
            panic!("{INJECT_PANIC_ENV} asked for a panic in {function}");
        }
        body()
    };
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(result) => result,
        Err(payload) => {
            let message = payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_owned())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "non-string panic payload".to_owned());
            tracing::error!(function, %message, "panic inside the layer; returning XR_ERROR_RUNTIME_FAILURE");
            xr::Result::ERROR_RUNTIME_FAILURE
        }
    }
}

/// `FOVEA_INJECT_PANIC=<function name>` makes that hook panic, to prove the guard holds in a real
/// process (tests/panic_containment.rs). Read once per process.
pub const INJECT_PANIC_ENV: &str = "FOVEA_INJECT_PANIC";

fn injected_panic() -> Option<&'static str> {
    static TARGET: std::sync::OnceLock<Option<String>> = std::sync::OnceLock::new();
    TARGET
        .get_or_init(|| std::env::var(INJECT_PANIC_ENV).ok())
        .as_deref()
}

/// The longest next chain the layer follows. The spec puts no bound on chains, but a real chain holds
/// a handful of structs; a longer one is almost certainly a loop (fundamentals.adoc forbids those),
/// and following it would hang the application.
pub const MAX_CHAIN_LENGTH: usize = 64;

/// Why a next chain was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChainError {
    /// More than [`MAX_CHAIN_LENGTH`] structs: a loop or garbage.
    TooLong,
}

/// The structure types in a next chain, in order.
///
/// # Safety
/// `next` must be NULL or point to a valid chain of OpenXR structs (each starting with `type`/`next`).
#[cfg(test)]
pub unsafe fn chain_types(next: *const c_void) -> Result<Vec<xr::StructureType>, ChainError> {
    let mut types = Vec::new();
    let mut node = next as *const xr::BaseInStructure;
    while !node.is_null() {
        if types.len() == MAX_CHAIN_LENGTH {
            return Err(ChainError::TooLong);
        }
        types.push((*node).ty);
        node = (*node).next;
    }
    Ok(types)
}

/// The first struct of type `ty` in a next chain (fundamentals.adoc, "Next Chain Structure
/// Uniqueness": when a type repeats, only the first counts).
///
/// # Safety
/// As [`chain_types`]; the struct found must really be a `T`.
pub unsafe fn find_in_chain<T>(
    next: *const c_void,
    ty: xr::StructureType,
) -> Result<Option<*const T>, ChainError> {
    let mut node = next as *const xr::BaseInStructure;
    let mut seen = 0;
    while !node.is_null() {
        if seen == MAX_CHAIN_LENGTH {
            return Err(ChainError::TooLong);
        }
        if (*node).ty == ty {
            return Ok(Some(node as *const T));
        }
        seen += 1;
        node = (*node).next;
    }
    Ok(None)
}

/// The byte size of the input structs the layer may have to copy while editing a chain. A struct the
/// layer does not know cannot be copied (its size is unknown), so it can only be kept in place.
pub fn known_struct_size(ty: xr::StructureType) -> Option<usize> {
    use std::mem::size_of;
    Some(match ty {
        xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB => {
            size_of::<xr::SwapchainCreateInfoFoveationFB>()
        }
        xr::StructureType::VULKAN_SWAPCHAIN_CREATE_INFO_META => {
            size_of::<VulkanSwapchainCreateInfoMETA>()
        }
        xr::StructureType::VULKAN_SWAPCHAIN_FORMAT_LIST_CREATE_INFO_KHR => {
            size_of::<xr::VulkanSwapchainFormatListCreateInfoKHR>()
        }
        _ => return None,
    })
}

/// An edited copy of a next chain, owning the copied nodes.
///
/// Removing struct `B` from `A → B → C` means the node before `B` must point at `C`; the app's `A`
/// must not be written (the layer never writes input structs), so `A` is copied and the copy
/// relinked. Nodes after the last removed one are shared, not copied. Where a node before a removed
/// one has a type the layer does not know, it cannot be copied; the removed struct then stays in the
/// chain, which the spec allows: runtimes must ignore structs they do not recognise.
pub struct ChainCopy {
    head: *const c_void,
    /// 8-byte aligned storage for copied nodes; boxes do not move when the vector grows.
    _nodes: Vec<Box<[u64]>>,
    removed: Vec<xr::StructureType>,
}

impl ChainCopy {
    /// The head of the edited chain, to put in a copy of the parent struct's `next`.
    pub fn head(&self) -> *const c_void {
        self.head
    }

    /// The struct types actually removed.
    pub fn removed(&self) -> &[xr::StructureType] {
        &self.removed
    }

    /// Copies `next`, leaving out every struct whose type `remove` selects.
    ///
    /// # Safety
    /// As [`chain_types`].
    pub unsafe fn without(
        next: *const c_void,
        remove: impl Fn(xr::StructureType) -> bool,
    ) -> Result<ChainCopy, ChainError> {
        let mut nodes: Vec<*const xr::BaseInStructure> = Vec::new();
        let mut node = next as *const xr::BaseInStructure;
        while !node.is_null() {
            if nodes.len() == MAX_CHAIN_LENGTH {
                return Err(ChainError::TooLong);
            }
            nodes.push(node);
            node = (*node).next;
        }
        // Walk backwards: `tail` is the head of the already-built rest of the chain, and `shared`
        // says whether it is still the app's own tail (so an untouched node can be reused as is).
        let mut tail: *const xr::BaseInStructure = std::ptr::null();
        let mut shared = true;
        let mut owned = Vec::new();
        let mut removed = Vec::new();
        for &node in nodes.iter().rev() {
            let ty = (*node).ty;
            if remove(ty) && known_struct_size(ty).is_some() {
                removed.push(ty);
                shared = false;
                continue;
            }
            if shared {
                tail = node;
                continue;
            }
            match known_struct_size(ty) {
                Some(size) => {
                    let mut storage = vec![0u64; size.div_ceil(8)].into_boxed_slice();
                    std::ptr::copy_nonoverlapping(
                        node as *const u8,
                        storage.as_mut_ptr() as *mut u8,
                        size,
                    );
                    let copy = storage.as_mut_ptr() as *mut xr::BaseInStructure;
                    (*copy).next = tail;
                    tail = copy;
                    owned.push(storage);
                }
                None => {
                    // Cannot relink an unknown struct: keep the app's node and its original tail, so
                    // whatever was removed behind it goes down after all (legal, see above).
                    tracing::debug!(
                        ?ty,
                        "unknown struct precedes a removed one; keeping the chain from here"
                    );
                    removed.clear();
                    tail = node;
                    shared = true;
                    owned.clear();
                }
            }
        }
        removed.reverse();
        Ok(ChainCopy {
            head: tail as *const c_void,
            _nodes: owned,
            removed,
        })
    }
}

/// `XrVulkanSwapchainCreateInfoMETA` as C lays it out: its members are `VkImageCreateFlags` and
/// `VkImageUsageFlags`, and Vulkan's `VkFlags` are 32-bit, so the struct is 24 bytes with
/// `additionalUsageFlags` at offset 20
/// (https://registry.khronos.org/OpenXR/specs/1.0/man/html/XrVulkanSwapchainCreateInfoMETA.html).
/// openxr-sys 0.14 declares both members as `u64`, so its struct must not be used to read it; ash's
/// flag types are `#[repr(transparent)]` over the 32-bit `VkFlags` and give the members their names.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct VulkanSwapchainCreateInfoMETA {
    pub ty: xr::StructureType,
    pub next: *const c_void,
    pub additional_create_flags: ash::vk::ImageCreateFlags,
    pub additional_usage_flags: ash::vk::ImageUsageFlags,
}

/// A NUL-terminated string from the application, if the pointer is non-NULL.
///
/// # Safety
/// `p` must be NULL or point to a NUL-terminated string.
pub unsafe fn cstr<'a>(p: *const c_char) -> Option<&'a CStr> {
    (!p.is_null()).then(|| CStr::from_ptr(p))
}

/// Copies `s` into a fixed-size C `char` array, truncating and always NUL-terminating.
pub fn write_fixed(dst: &mut [c_char], s: &str) {
    let n = s.len().min(dst.len().saturating_sub(1));
    for (d, b) in dst.iter_mut().zip(s.as_bytes()[..n].iter()) {
        *d = *b as c_char;
    }
    if let Some(end) = dst.get_mut(n) {
        *end = 0;
    }
}

/// Reads a fixed-size C `char` array up to its first NUL (or its end).
pub fn read_fixed(src: &[c_char]) -> String {
    let bytes: Vec<u8> = src
        .iter()
        .take_while(|&&c| c != 0)
        .map(|&c| c as u8)
        .collect();
    String::from_utf8_lossy(&bytes).into_owned()
}

/// The two-call idiom (fundamentals.adoc, "Buffer Size Parameters"): capacity 0 asks for the count;
/// a non-zero capacity below the count is `XR_ERROR_SIZE_INSUFFICIENT` with the count written.
///
/// # Safety
/// `count_out` must be valid for writes; `out` valid for `capacity` writes when `capacity > 0`.
pub unsafe fn two_call<T: Copy>(
    items: &[T],
    capacity: u32,
    count_out: *mut u32,
    out: *mut T,
) -> xr::Result {
    if count_out.is_null() || (capacity > 0 && out.is_null()) {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    let count = items.len() as u32;
    *count_out = count;
    if capacity == 0 {
        return xr::Result::SUCCESS;
    }
    if capacity < count {
        return xr::Result::ERROR_SIZE_INSUFFICIENT;
    }
    std::ptr::copy_nonoverlapping(items.as_ptr(), out, items.len());
    xr::Result::SUCCESS
}

#[cfg(test)]
mod tests {
    use super::*;

    const META: xr::StructureType = xr::StructureType::VULKAN_SWAPCHAIN_CREATE_INFO_META;

    fn fov_info(next: *const c_void) -> xr::SwapchainCreateInfoFoveationFB {
        xr::SwapchainCreateInfoFoveationFB {
            ty: xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
            next: next as *mut c_void,
            flags: xr::SwapchainCreateFoveationFlagsFB::FRAGMENT_DENSITY_MAP,
        }
    }

    fn meta(next: *const c_void) -> VulkanSwapchainCreateInfoMETA {
        VulkanSwapchainCreateInfoMETA {
            ty: xr::StructureType::VULKAN_SWAPCHAIN_CREATE_INFO_META,
            next,
            additional_create_flags: ash::vk::ImageCreateFlags::SUBSAMPLED_EXT,
            additional_usage_flags: ash::vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT,
        }
    }

    #[test]
    fn meta_struct_matches_c_layout() {
        assert_eq!(std::mem::size_of::<VulkanSwapchainCreateInfoMETA>(), 24);
        assert_eq!(
            std::mem::offset_of!(VulkanSwapchainCreateInfoMETA, additional_create_flags),
            16
        );
        assert_eq!(
            std::mem::offset_of!(VulkanSwapchainCreateInfoMETA, additional_usage_flags),
            20
        );
    }

    #[test]
    fn removes_without_touching_the_original() {
        let unknown_tail = xr::BaseInStructure {
            ty: xr::StructureType::from_raw(42),
            next: std::ptr::null(),
        };
        let m = meta(&unknown_tail as *const _ as *const c_void);
        let f = fov_info(&m as *const _ as *const c_void);
        let head = &f as *const _ as *const c_void;
        let copy = unsafe { ChainCopy::without(head, |t| t == META) }.unwrap();
        let types = unsafe { chain_types(copy.head()) }.unwrap();
        assert_eq!(
            types,
            [
                xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
                xr::StructureType::from_raw(42)
            ]
        );
        assert_eq!(copy.removed(), [META]);
        // The app's structs are untouched and the unknown tail is shared, not copied.
        assert_eq!(f.next as *const c_void, &m as *const _ as *const c_void);
        let copied = copy.head() as *const xr::SwapchainCreateInfoFoveationFB;
        assert_ne!(copied, &f as *const _);
        assert_eq!(unsafe { (*copied).flags }, f.flags);
        assert_eq!(
            unsafe { (*copied).next } as *const c_void,
            &unknown_tail as *const _ as *const c_void
        );
    }

    #[test]
    fn unknown_node_before_a_removed_one_keeps_it() {
        let m = meta(std::ptr::null());
        let unknown = xr::BaseInStructure {
            ty: xr::StructureType::from_raw(42),
            next: &m as *const _ as *const xr::BaseInStructure,
        };
        let head = &unknown as *const _ as *const c_void;
        let copy = unsafe { ChainCopy::without(head, |t| t == META) }.unwrap();
        assert_eq!(copy.head(), head);
        assert!(copy.removed().is_empty());
    }

    #[test]
    fn loops_are_refused() {
        let mut a = xr::BaseInStructure {
            ty: xr::StructureType::from_raw(1),
            next: std::ptr::null(),
        };
        let b = xr::BaseInStructure {
            ty: xr::StructureType::from_raw(2),
            next: &a,
        };
        a.next = &b;
        let head = &a as *const _ as *const c_void;
        assert_eq!(unsafe { chain_types(head) }, Err(ChainError::TooLong));
        assert_eq!(
            unsafe { find_in_chain::<u8>(head, xr::StructureType::from_raw(3)) },
            Err(ChainError::TooLong)
        );
        assert!(unsafe { ChainCopy::without(head, |_| false) }.is_err());
        assert_eq!(
            unsafe { find_in_chain::<u8>(head, xr::StructureType::from_raw(2)) }.unwrap(),
            Some(&b as *const _ as *const u8)
        );
    }

    #[test]
    fn guard_turns_panics_into_runtime_failure() {
        assert_eq!(
            guard("t", || panic!("boom")),
            xr::Result::ERROR_RUNTIME_FAILURE
        );
        assert_eq!(guard("t", || xr::Result::SUCCESS), xr::Result::SUCCESS);
    }

    #[test]
    fn two_call_idiom() {
        let items = [1u32, 2, 3];
        let mut count = 0;
        let mut out = [0u32; 3];
        unsafe {
            assert_eq!(
                two_call(&items, 0, &mut count, std::ptr::null_mut()),
                xr::Result::SUCCESS
            );
            assert_eq!(count, 3);
            assert_eq!(
                two_call(&items, 2, &mut count, out.as_mut_ptr()),
                xr::Result::ERROR_SIZE_INSUFFICIENT
            );
            assert_eq!(
                two_call(&items, 3, &mut count, out.as_mut_ptr()),
                xr::Result::SUCCESS
            );
            assert_eq!(
                two_call(&items, 3, std::ptr::null_mut(), out.as_mut_ptr()),
                xr::Result::ERROR_VALIDATION_FAILURE
            );
        }
        assert_eq!(out, items);
    }

    #[test]
    fn fixed_strings() {
        let mut buf = [1 as c_char; 4];
        write_fixed(&mut buf, "abcdef");
        assert_eq!(read_fixed(&buf), "abc");
    }
}
