//! Vulkan `pNext` chains: finding a struct, and editing a copy without writing the application's
//! structs (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkBaseInStructure.html>).

use std::ffi::c_void;
use std::mem::size_of;

use ash::vk;

use crate::vk::base::ffi::In;
use crate::vk::base::{link, structs};

/// The longest chain the layer follows; a longer one is taken for a loop, which the spec forbids
/// (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#fundamentals-validusage-pNext>).
/// Longer than the OpenXR side's ([`fovea_abi::MAX_CHAIN_LENGTH`]): a struct the layer must remove
/// or translate (a density-map struct a driver without density maps would see) has to be found
/// wherever a valid chain puts it, so the bound only guards against loops. Walks stop at the
/// chain's end, so a real chain costs what its length costs.
pub const MAX_CHAIN_LENGTH: usize = 1024;

/// Why a chain could not be handled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChainError {
    /// More than [`MAX_CHAIN_LENGTH`] structs.
    TooLong,
    /// A struct of unknown size sits before one to remove, so its link cannot be rewritten in a copy.
    Unknown(vk::StructureType),
}

/// The first struct of type `ty` in an input chain.
///
/// # Safety
/// `next` must be NULL or a valid chain of Vulkan structs; the struct found must really be a `T`.
pub unsafe fn find<T>(
    next: *const c_void,
    ty: vk::StructureType,
) -> Result<Option<*const T>, ChainError> {
    let mut node = next as *const vk::BaseInStructure<'static>;
    for _ in 0..MAX_CHAIN_LENGTH {
        if node.is_null() {
            return Ok(None);
        }
        // SAFETY: the caller promised a valid chain; every node starts with sType/pNext.
        let n = unsafe { &*node };
        if n.s_type == ty {
            return Ok(Some(node as *const T));
        }
        node = n.p_next;
    }
    if node.is_null() {
        Ok(None)
    } else {
        Err(ChainError::TooLong)
    }
}

/// The first struct of type `ty` in an output chain (one the application hands in to be filled).
///
/// # Safety
/// As [`find`], and the chain must be writable.
pub unsafe fn find_out<T>(next: *mut c_void, ty: vk::StructureType) -> Option<*mut T> {
    // SAFETY: as the caller promised.
    unsafe { find::<T>(next, ty) }
        .ok()
        .flatten()
        .map(|p| p as *mut T)
}

/// An input struct whose `pNext` chain the layer reads through [`In`] without `unsafe`.
///
/// # Safety
/// [`Chained::p_next`] must return the struct's own `pNext` member.
pub unsafe trait Chained {
    fn p_next(&self) -> *const c_void;
}

macro_rules! chained {
    ($($t:ident),* $(,)?) => {
        $(
            // SAFETY: the struct's own `pNext`.
            unsafe impl Chained for vk::$t<'_> {
                fn p_next(&self) -> *const c_void {
                    self.p_next
                }
            }
        )*
    };
}

chained!(
    RenderPassCreateInfo,
    RenderPassCreateInfo2,
    FramebufferCreateInfo,
    RenderPassBeginInfo,
    RenderingInfo,
    SubpassEndInfo,
    DeviceCreateInfo,
);

// SAFETY: the struct's own `pNext`.
unsafe impl Chained for crate::vk::base::ffi::offset::RenderingEndInfo {
    fn p_next(&self) -> *const c_void {
        self.p_next
    }
}

impl<'a, T: Chained> In<'a, T> {
    /// The first struct of `U`'s type in the struct's chain (`None` for a NULL struct).
    pub fn find<U: vk::TaggedStructure>(self) -> Result<Option<&'a U>, ChainError> {
        let Some(s) = self.get() else {
            return Ok(None);
        };
        // SAFETY: the chain is valid for `'a` ([`In::new`]); the struct found by `U`'s sType is a
        // `U`.
        unsafe { find::<U>(s.p_next(), U::STRUCTURE_TYPE).map(|f| f.map(|p| &*p)) }
    }

    /// Whether a struct of type `ty` is in the struct's chain.
    pub fn has(self, ty: vk::StructureType) -> bool {
        let Some(s) = self.get() else {
            return false;
        };
        // SAFETY: the chain is valid for `'a` ([`In::new`]); nothing is read as the struct found.
        matches!(unsafe { find::<u8>(s.p_next(), ty) }, Ok(Some(_)))
    }

    /// [`ChainCopy::without`] on the struct's chain (an empty copy for a NULL struct).
    pub fn without(
        self,
        remove: impl Fn(vk::StructureType) -> bool,
    ) -> Result<ChainCopy, ChainError> {
        let next = self.get().map_or(std::ptr::null(), |s| s.p_next());
        // SAFETY: the chain is valid for `'a` ([`In::new`]).
        unsafe { ChainCopy::without(next, remove) }
    }

    /// [`with_removed`] on the struct's chain.
    pub fn with_removed<R>(
        self,
        remove: impl Fn(vk::StructureType) -> bool,
        f: impl FnOnce(Result<*const c_void, ChainError>) -> R,
    ) -> R {
        let next = self.get().map_or(std::ptr::null(), |s| s.p_next());
        // SAFETY: the chain is valid for `'a` ([`In::new`]).
        unsafe { with_removed(next, remove, f) }
    }
}

/// Byte sizes of the structs that may precede one the layer removes from a chain: every struct
/// that extends a device create info up to Vulkan 1.4's registry ([`structs`]), and those of
/// graphics pipeline infos and render pass, framebuffer and rendering infos. A struct not listed
/// cannot be copied; see [`ChainCopy::without`].
fn known_size(ty: vk::StructureType) -> Option<usize> {
    macro_rules! sizes {
        ($($t:ident),* $(,)?) => {
            [$((<vk::$t<'static> as vk::TaggedStructure>::STRUCTURE_TYPE, size_of::<vk::$t<'static>>())),*]
        };
    }
    static SIZES: &[(vk::StructureType, usize)] = &sizes![
        // Device create infos: [`structs`].
        // VkGraphicsPipelineCreateInfo chains.
        PipelineRenderingCreateInfo,
        GraphicsPipelineLibraryCreateInfoEXT,
        PipelineLibraryCreateInfoKHR,
        PipelineCreationFeedbackCreateInfo,
        PipelineRobustnessCreateInfoEXT,
        PipelineFragmentShadingRateStateCreateInfoKHR,
        PipelineCreateFlags2CreateInfoKHR,
        PipelineDiscardRectangleStateCreateInfoEXT,
        PipelineCompilerControlCreateInfoAMD,
        AttachmentSampleCountInfoAMD,
        MultiviewPerViewAttributesInfoNVX,
        // Render pass, framebuffer and rendering chains (src/vk/pass.rs).
        RenderPassMultiviewCreateInfo,
        RenderPassInputAttachmentAspectCreateInfo,
        RenderPassFragmentDensityMapCreateInfoEXT,
        RenderPassCreationControlEXT,
        RenderPassCreationFeedbackCreateInfoEXT,
        RenderPassSampleLocationsBeginInfoEXT,
        RenderPassAttachmentBeginInfo,
        RenderPassTransformBeginInfoQCOM,
        DeviceGroupRenderPassBeginInfo,
        FramebufferAttachmentsCreateInfo,
        MultisampledRenderToSingleSampledInfoEXT,
        MultiviewPerViewRenderAreasRenderPassBeginInfoQCOM,
        RenderingFragmentDensityMapAttachmentInfoEXT,
        RenderingFragmentShadingRateAttachmentInfoKHR,
        RenderingAttachmentLocationInfoKHR,
        RenderingInputAttachmentIndexInfoKHR,
    ];
    if ty == vk::StructureType::LOADER_DEVICE_CREATE_INFO {
        return Some(size_of::<link::LayerDeviceCreateInfo>());
    }
    SIZES
        .iter()
        .find(|(t, _)| *t == ty)
        .map(|&(_, size)| size)
        .or_else(|| structs::device_create_info_extender(ty))
}

/// An edited copy of an input chain, owning the nodes it copied.
///
/// Removing `B` from `A → B → C` means `A` must point at `C`; the application's `A` is never
/// written, so `A` is copied and the copy relinked. Nodes after the last removed one are shared.
pub struct ChainCopy {
    head: *const c_void,
    /// 8-byte aligned storage of copied nodes; a box does not move when the vector grows.
    _nodes: Vec<Box<[u64]>>,
    removed: usize,
}

impl ChainCopy {
    /// The head of the edited chain.
    pub fn head(&self) -> *const c_void {
        self.head
    }

    /// How many structs were left out.
    pub fn removed(&self) -> usize {
        self.removed
    }

    /// Copies `next` without every struct `remove` selects. Unlike the OpenXR side, a struct of
    /// unknown size before a removed one is an error: the removed structs here are ones the driver
    /// must not see (they would make the device creation invalid), so keeping them is no option,
    /// and the caller refuses the call instead (docs/vulkan-fdm-on-fsr.md#device-creation). Every
    /// struct that can extend a device create info up to Vulkan 1.4 has a known size.
    ///
    /// # Safety
    /// `next` must be NULL or a valid chain of Vulkan structs.
    pub unsafe fn without(
        next: *const c_void,
        remove: impl Fn(vk::StructureType) -> bool,
    ) -> Result<ChainCopy, ChainError> {
        let mut nodes: Vec<*const vk::BaseInStructure<'static>> = Vec::new();
        let mut node = next as *const vk::BaseInStructure<'static>;
        while !node.is_null() {
            if nodes.len() == MAX_CHAIN_LENGTH {
                // A loop (no valid chain is this long): the layer looks no further ([`find`]
                // neither), and the rest stays as it is, shared.
                break;
            }
            nodes.push(node);
            // SAFETY: a valid chain, as the caller promised.
            node = unsafe { (*node).p_next };
        }
        let mut tail: *const vk::BaseInStructure<'static> = node;
        let mut shared = true;
        let mut owned = Vec::new();
        let mut removed = 0;
        for &node in nodes.iter().rev() {
            // SAFETY: as above.
            let ty = unsafe { (*node).s_type };
            if remove(ty) {
                removed += 1;
                shared = false;
                continue;
            }
            if shared {
                tail = node;
                continue;
            }
            let size = known_size(ty).ok_or(ChainError::Unknown(ty))?;
            let mut storage = vec![0u64; size.div_ceil(8)].into_boxed_slice();
            // SAFETY: `node` is a `size`-byte struct of type `ty` (known_size); the storage holds
            // at least `size` bytes, 8-aligned, and is ours to write.
            unsafe {
                std::ptr::copy_nonoverlapping(
                    node as *const u8,
                    storage.as_mut_ptr() as *mut u8,
                    size,
                );
                let copy = storage.as_mut_ptr() as *mut vk::BaseInStructure<'static>;
                (*copy).p_next = tail;
                tail = copy;
            }
            owned.push(storage);
        }
        Ok(ChainCopy {
            head: tail as *const c_void,
            _nodes: owned,
            removed,
        })
    }
}

/// Per-thread storage for [`with_removed`], reused from call to call so that a command recorded
/// with an edited chain allocates nothing in steady state.
#[derive(Default)]
struct Scratch {
    nodes: Vec<*const vk::BaseInStructure<'static>>,
    /// 8-byte aligned storage of the copied nodes; sized once per call before any node is copied,
    /// so the pointers into it stay valid.
    words: Vec<u64>,
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// [`ChainCopy::without`] for a chain that lives across one call only: `f` gets the head of the
/// edited chain (or why there is none), built in this thread's scratch storage (a fresh one where
/// that is busy, e.g. re-entered). The copy must not outlive `f`.
///
/// # Safety
/// `next` must be NULL or a valid chain of Vulkan structs.
pub unsafe fn with_removed<R>(
    next: *const c_void,
    remove: impl Fn(vk::StructureType) -> bool,
    f: impl FnOnce(Result<*const c_void, ChainError>) -> R,
) -> R {
    let mut f = Some(f);
    let mut run = |s: &mut Scratch| {
        // SAFETY: as the caller promised.
        let head = unsafe { removed_into(s, next, &remove) };
        (f.take().expect("called once"))(head)
    };
    let r = SCRATCH.try_with(|s| s.try_borrow_mut().ok().map(|mut s| run(&mut s)));
    match r {
        Ok(Some(r)) => r,
        _ => run(&mut Scratch::default()),
    }
}

/// The work of [`with_removed`], in `s`.
///
/// # Safety
/// As [`with_removed`].
unsafe fn removed_into(
    s: &mut Scratch,
    next: *const c_void,
    remove: &impl Fn(vk::StructureType) -> bool,
) -> Result<*const c_void, ChainError> {
    s.nodes.clear();
    let mut node = next as *const vk::BaseInStructure<'static>;
    while !node.is_null() && s.nodes.len() < MAX_CHAIN_LENGTH {
        s.nodes.push(node);
        // SAFETY: a valid chain, as the caller promised.
        node = unsafe { (*node).p_next };
    }
    // SAFETY: as above.
    let ty = |n: *const vk::BaseInStructure<'static>| unsafe { (*n).s_type };
    // Nodes after the last removed one are shared; those before it (kept) are copied.
    let Some(last) = s.nodes.iter().rposition(|&n| remove(ty(n))) else {
        return Ok(next);
    };
    let mut words = 0;
    for &n in &s.nodes[..last] {
        if !remove(ty(n)) {
            words += known_size(ty(n))
                .ok_or(ChainError::Unknown(ty(n)))?
                .div_ceil(8);
        }
    }
    s.words.clear();
    s.words.resize(words, 0);
    let mut tail: *const vk::BaseInStructure<'static> =
        s.nodes.get(last + 1).copied().unwrap_or(node);
    let mut end = words;
    for &n in s.nodes[..last].iter().rev() {
        if remove(ty(n)) {
            continue;
        }
        let size = known_size(ty(n)).ok_or(ChainError::Unknown(ty(n)))?;
        let start = end - size.div_ceil(8);
        let dst = s.words[start..end].as_mut_ptr();
        // SAFETY: `n` is a `size`-byte struct of its type (known_size); `dst` holds at least `size`
        // bytes, 8-aligned, and is ours to write; `words` is not resized until the next call.
        unsafe {
            std::ptr::copy_nonoverlapping(n as *const u8, dst as *mut u8, size);
            let copy = dst as *mut vk::BaseInStructure<'static>;
            (*copy).p_next = tail;
            tail = copy;
        }
        end = start;
    }
    Ok(tail as *const c_void)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_typed_input_finds_and_leaves_out_structs_of_its_chain() {
        use ash::vk::Handle as _;
        let fdm = vk::RenderingFragmentDensityMapAttachmentInfoEXT::default()
            .image_view(vk::ImageView::from_raw(0x77));
        let multiview = vk::MultiviewPerViewAttributesInfoNVX {
            p_next: &fdm as *const _ as *const c_void,
            ..Default::default()
        };
        let info = vk::RenderingInfo {
            p_next: &multiview as *const _ as *const c_void,
            ..Default::default()
        };
        // SAFETY: a rendering info whose chain lives across the test.
        let info = unsafe { In::new(&info) };
        let found = info.find::<vk::RenderingFragmentDensityMapAttachmentInfoEXT>();
        assert_eq!(
            found.map(|f| f.map(|f| f.image_view.as_raw())),
            Ok(Some(0x77))
        );
        let ty = vk::StructureType::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_INFO_EXT;
        assert!(info.has(ty));
        let copy = info.without(|t| t == ty).expect("copied");
        assert_eq!(copy.removed(), 1);
        // SAFETY: the copy's chain, alive with it.
        let left = unsafe { find::<u8>(copy.head(), ty) };
        assert_eq!(left, Ok(None), "the copy has no density-map struct");
        assert_eq!(
            multiview.p_next, &fdm as *const _ as *const c_void,
            "the original is kept"
        );
        // SAFETY: NULL.
        let null = unsafe { In::<vk::RenderingInfo<'_>>::new(std::ptr::null()) };
        assert!(matches!(
            null.find::<vk::RenderingFragmentDensityMapAttachmentInfoEXT>(),
            Ok(None)
        ));
    }

    fn types(head: *const c_void) -> Vec<vk::StructureType> {
        let mut out = Vec::new();
        let mut node = head as *const vk::BaseInStructure<'static>;
        while !node.is_null() {
            // SAFETY: test chains built below.
            unsafe {
                out.push((*node).s_type);
                node = (*node).p_next;
            }
        }
        out
    }

    #[test]
    fn removes_on_a_copy_and_shares_the_tail() {
        let tail = vk::BaseInStructure {
            s_type: vk::StructureType::from_raw(12345),
            ..Default::default()
        };
        let fdm = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT {
            p_next: &tail as *const _ as *mut c_void,
            ..Default::default()
        };
        let mut v13 = vk::PhysicalDeviceVulkan13Features::default().dynamic_rendering(true);
        v13.p_next = &fdm as *const _ as *mut c_void;
        let head = &v13 as *const _ as *const c_void;
        let ty = vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_FEATURES_EXT;
        // SAFETY: a valid chain on the stack.
        let copy = unsafe { ChainCopy::without(head, |t| t == ty) }.unwrap();
        assert_eq!(copy.removed(), 1);
        assert_eq!(
            types(copy.head()),
            [
                vk::StructureType::PHYSICAL_DEVICE_VULKAN_1_3_FEATURES,
                vk::StructureType::from_raw(12345)
            ]
        );
        assert_ne!(copy.head(), head, "the application's struct is copied");
        assert_eq!(
            v13.p_next, &fdm as *const _ as *mut c_void,
            "and not written"
        );
        // SAFETY: the copy is a Vulkan13Features.
        let c = unsafe { &*(copy.head() as *const vk::PhysicalDeviceVulkan13Features) };
        assert_eq!(c.dynamic_rendering, vk::TRUE);
        assert_eq!(
            c.p_next as *const c_void,
            &tail as *const _ as *const c_void
        );
        // SAFETY: as above.
        let found = unsafe { find::<u8>(head, ty) }.unwrap();
        assert_eq!(found, Some(&fdm as *const _ as *const u8));
    }

    #[test]
    fn scratch_copies_relink_like_chain_copy_and_keep_their_storage() {
        let tail = vk::BaseInStructure {
            s_type: vk::StructureType::from_raw(12345),
            ..Default::default()
        };
        let fdm = vk::RenderingFragmentDensityMapAttachmentInfoEXT {
            p_next: &tail as *const _ as *const c_void,
            ..Default::default()
        };
        let first = vk::RenderingAttachmentLocationInfoKHR {
            p_next: &fdm as *const _ as *const c_void,
            ..Default::default()
        };
        let head = &first as *const _ as *const c_void;
        let ty = vk::StructureType::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_INFO_EXT;
        let check = |h: Result<*const c_void, ChainError>| {
            let h = h.expect("copied");
            assert_ne!(h, head, "the application's struct is copied");
            assert_eq!(
                types(h),
                [
                    vk::StructureType::RENDERING_ATTACHMENT_LOCATION_INFO_KHR,
                    vk::StructureType::from_raw(12345)
                ]
            );
            h
        };
        // SAFETY: a valid chain on the stack.
        let a = unsafe { with_removed(head, |t| t == ty, check) };
        // SAFETY: as above.
        let b = unsafe { with_removed(head, |t| t == ty, check) };
        assert_eq!(a, b, "the same storage, reused");
        assert_eq!(
            first.p_next, &fdm as *const _ as *const c_void,
            "not written"
        );
        // The struct to remove at the head: nothing copied, the rest shared.
        // SAFETY: as above.
        let rest = unsafe { with_removed(&fdm as *const _ as *const c_void, |t| t == ty, |h| h) };
        assert_eq!(rest, Ok(&tail as *const _ as *const c_void));
        // Re-entered (the scratch is busy): a fresh one does the same.
        // SAFETY: as above.
        unsafe {
            with_removed(
                head,
                |t| t == ty,
                |_| with_removed(head, |t| t == ty, check),
            )
        };
    }

    #[test]
    fn unknown_struct_before_a_removed_one_is_an_error() {
        let fdm = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default();
        let unknown = vk::BaseInStructure {
            s_type: vk::StructureType::from_raw(777),
            p_next: &fdm as *const _ as *const vk::BaseInStructure<'static>,
            ..Default::default()
        };
        let head = &unknown as *const _ as *const c_void;
        let ty = vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_FEATURES_EXT;
        // SAFETY: a valid chain on the stack.
        let r = unsafe { ChainCopy::without(head, |t| t == ty) };
        assert_eq!(
            r.err(),
            Some(ChainError::Unknown(vk::StructureType::from_raw(777)))
        );
        // Nothing to remove: the chain is shared as is, unknown structs and all.
        // SAFETY: as above.
        let same = unsafe { ChainCopy::without(head, |_| false) }.unwrap();
        assert_eq!(same.head(), head);
    }

    #[test]
    fn loops_are_refused() {
        let mut a = vk::BaseInStructure::default();
        let b = vk::BaseInStructure {
            p_next: &a,
            ..Default::default()
        };
        a.p_next = &b;
        let head = &a as *const _ as *const c_void;
        // SAFETY: a (looping) chain of valid nodes.
        unsafe {
            assert_eq!(
                find::<u8>(head, vk::StructureType::from_raw(9)),
                Err(ChainError::TooLong)
            );
            // Past the walk's end the chain is shared as it is: nothing to remove, nothing copied.
            let copy = ChainCopy::without(head, |_| false).expect("shared");
            assert_eq!(copy.head(), head);
        }
    }
}
