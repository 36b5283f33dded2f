//! The FFI edge every hook stands on: the panic guard, the caller's names and arrays, typed views of
//! the caller's pointers ([`In`], [`Arr`], [`Out`]) and what a hook body gets ([`Call`]), the
//! two-call idiom, and a dispatchable handle's loader key.

use std::ffi::{c_char, CStr};
use std::hash::Hasher;
use std::marker::PhantomData;
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

/// What a hook body gets besides the command's own arguments (the `hook!` chassis of
/// `crate::vk::hooks`): the command's name for its log lines, the record its dispatchable handle
/// was looked up in (a device, or an instance for a physical device), the next layer's function,
/// picked from that record's table, and the call down with the application's arguments as they
/// came ([`Call::as_given`]).
pub struct Call<'a, D, F, G> {
    pub name: &'static str,
    pub dev: &'a D,
    pub next: F,
    pub given: G,
}

impl<D, F, G> Call<'_, D, F, G> {
    /// Calls the next layer's function with the application's own arguments, unchanged: the
    /// chassis made this call where it still had them raw, under the caller's promise that they
    /// are valid as the command requires (a `maybe` hook goes down only where the next layer has
    /// the command).
    #[inline(always)]
    pub fn as_given<R>(&self) -> R
    where
        G: Fn() -> R,
    {
        (self.given)()
    }
}

/// An input struct the application passes by pointer (`const T*`): NULL or valid, with a valid
/// `pNext` chain, for the whole call, which the hook's caller promises and [`In::new`] takes on.
/// Read through it without `unsafe`; the pointer goes down as it came ([`In::raw`]).
pub struct In<'a, T> {
    ptr: *const T,
    _call: PhantomData<&'a T>,
}

impl<T> Clone for In<'_, T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for In<'_, T> {}

impl<'a, T> In<'a, T> {
    /// # Safety
    /// `ptr` must be NULL or point at a `T` valid as the command's valid usage defines it (its
    /// `pNext` chain, and the arrays and strings its members point at, valid too), not written
    /// while `'a` lasts.
    #[inline(always)]
    pub unsafe fn new(ptr: *const T) -> Self {
        In {
            ptr,
            _call: PhantomData,
        }
    }

    /// The pointer as the application passed it, to hand down.
    #[inline(always)]
    pub fn raw(self) -> *const T {
        self.ptr
    }

    /// The struct, `None` for NULL.
    #[inline(always)]
    pub fn get(self) -> Option<&'a T> {
        // SAFETY: NULL or valid for `'a` ([`In::new`]).
        unsafe { self.ptr.as_ref() }
    }
}

/// A create info that enables extensions by name (`ppEnabledExtensionNames`).
pub trait Named {
    /// The names' array and its count, as the application set them.
    fn names(&self) -> (*const *const c_char, u32);
}

impl Named for vk::InstanceCreateInfo<'_> {
    fn names(&self) -> (*const *const c_char, u32) {
        (
            self.pp_enabled_extension_names,
            self.enabled_extension_count,
        )
    }
}

impl Named for vk::DeviceCreateInfo<'_> {
    fn names(&self) -> (*const *const c_char, u32) {
        (
            self.pp_enabled_extension_names,
            self.enabled_extension_count,
        )
    }
}

impl<'a, T: Named> In<'a, T> {
    /// The extension names the application enables, as it passed them (none for a NULL struct).
    pub fn names(self) -> &'a [*const c_char] {
        let Some((p, n)) = self.get().map(Named::names) else {
            return &[];
        };
        // SAFETY: the array of `n` names is valid for `'a` ([`In::new`]).
        unsafe { slice(p, n) }
    }

    /// Each name the application enables, with the string it points at (`None` for NULL).
    pub fn named(self) -> impl Iterator<Item = (*const c_char, Option<&'a CStr>)> {
        self.names().iter().map(|&n| {
            // SAFETY: each name is NULL or NUL-terminated, valid for `'a` ([`In::new`]).
            (n, unsafe { name(n) })
        })
    }

    /// Whether the application enables the extension `want`.
    pub fn enables(self, want: &CStr) -> bool {
        self.named().any(|(_, n)| n == Some(want))
    }
}

/// An input array the application passes as a count and a pointer: NULL, or valid for that many
/// elements for the whole call ([`Arr::new`]).
pub struct Arr<'a, T> {
    ptr: *const T,
    count: u32,
    _call: PhantomData<&'a [T]>,
}

impl<T> Clone for Arr<'_, T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for Arr<'_, T> {}

impl<'a, T> Arr<'a, T> {
    /// # Safety
    /// `ptr` must be NULL, or valid for reads of `count` elements not written while `'a` lasts.
    #[inline(always)]
    pub unsafe fn new(ptr: *const T, count: u32) -> Self {
        Arr {
            ptr,
            count,
            _call: PhantomData,
        }
    }

    /// The pointer as the application passed it, to hand down with its count.
    #[inline(always)]
    pub fn raw(self) -> *const T {
        self.ptr
    }

    /// The elements; empty for NULL or a zero count, as [`slice`] makes them.
    #[inline(always)]
    pub fn slice(self) -> &'a [T] {
        // SAFETY: NULL or valid for `count` reads ([`Arr::new`]).
        unsafe { slice(self.ptr, self.count) }
    }
}

/// An output the application passes by pointer (`T*`), for the next layer to write: NULL or valid
/// for reads and writes for the whole call ([`Out::new`]).
pub struct Out<'a, T> {
    ptr: *mut T,
    _call: PhantomData<&'a mut T>,
}

impl<'a, T> Out<'a, T> {
    /// # Safety
    /// `ptr` must be NULL or valid for reads and writes of a `T` for `'a`, and not otherwise
    /// borrowed meanwhile.
    #[inline(always)]
    pub unsafe fn new(ptr: *mut T) -> Self {
        Out {
            ptr,
            _call: PhantomData,
        }
    }

    /// The pointer as the application passed it, to hand down.
    #[inline(always)]
    pub fn raw(&self) -> *mut T {
        self.ptr
    }

    #[inline(always)]
    pub fn is_null(&self) -> bool {
        self.ptr.is_null()
    }

    /// What it holds (what the next layer wrote, after a success); `None` for NULL.
    #[inline(always)]
    pub fn read(&self) -> Option<T>
    where
        T: Copy,
    {
        // SAFETY: NULL or valid for reads ([`Out::new`]).
        (!self.ptr.is_null()).then(|| unsafe { self.ptr.read() })
    }

    /// The struct to fill in, `None` for NULL.
    #[inline(always)]
    pub fn into_mut(self) -> Option<&'a mut T> {
        // SAFETY: NULL or valid for reads and writes for `'a`, borrowed by nothing else
        // ([`Out::new`]); `self` is consumed, so this is the only reference made from it.
        unsafe { self.ptr.as_mut() }
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
    fn typed_views_read_what_the_application_passed_and_nothing_for_null() {
        let x = 7u32;
        // SAFETY: NULL, or a local alive for the test.
        let (none, some) = unsafe { (In::<u32>::new(std::ptr::null()), In::new(&x)) };
        assert_eq!((none.get(), some.get()), (None, Some(&7)));
        let a = [1u32, 2, 3];
        // SAFETY: NULL, or the local array with at least as many elements.
        let (null, two) = unsafe {
            (
                Arr::<u32>::new(std::ptr::null(), 3),
                Arr::new(a.as_ptr(), 2),
            )
        };
        assert!(null.slice().is_empty(), "NULL with a count is no array");
        assert_eq!((two.slice(), two.raw()), (&a[..2], a.as_ptr()));
        let mut y = 1u32;
        // SAFETY: a local, borrowed by nothing else while `out` lives.
        let out = unsafe { Out::new(&mut y) };
        assert_eq!(out.read(), Some(1));
        *out.into_mut().expect("not NULL") = 5;
        assert_eq!(y, 5);
        // SAFETY: NULL.
        let null = unsafe { Out::<u32>::new(std::ptr::null_mut()) };
        assert_eq!(null.read(), None);
        let names = [c"VK_KHR_a".as_ptr(), std::ptr::null(), c"VK_KHR_b".as_ptr()];
        let ci = vk::DeviceCreateInfo {
            enabled_extension_count: 3,
            pp_enabled_extension_names: names.as_ptr(),
            ..Default::default()
        };
        // SAFETY: a create info whose names live across the test.
        let info = unsafe { In::new(&ci) };
        assert!(info.enables(c"VK_KHR_b") && !info.enables(c"VK_KHR_c"));
        assert_eq!(info.names().len(), 3);
        assert_eq!(info.named().filter(|(_, n)| n.is_none()).count(), 1);
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
