//! The shading-rate state pipelines get in place of density maps, read from and written into
//! copies of their create infos, and the shader, sampler and view flags the emulation leaves out.
//!
//! - Graphics pipelines used with a density map (their render pass has one, or they carry
//!   `RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_BIT_EXT` for dynamic rendering, in the 32-bit flags
//!   or in a chained `VkPipelineCreateFlags2CreateInfoKHR`) reach the driver, on copies, with the
//!   shading-rate flag instead and `VkPipelineFragmentShadingRateStateCreateInfoKHR {1×1, {KEEP,
//!   REPLACE}}`: without that state a pipeline ignores the shading-rate attachment
//!   (docs/vulkan-fdm-on-fsr.md#mapping). Every library with pre-rasterisation or fragment-shader
//!   state gets the same state, so linked libraries agree
//!   (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkGraphicsPipelineCreateInfo.html>,
//!   VUID-VkGraphicsPipelineCreateInfo-flags-06638 and -06639). A pipeline that chains its own
//!   shading-rate state keeps it.
//! - On a device that injects maps into eye passes (docs/injection.md#how-the-attachment-gets-in),
//!   every pipeline gets the same state (every render pass there has a shading-rate attachment,
//!   and whether a dynamic rendering gets one is decided only when it begins), and pipelines for
//!   dynamic rendering the shading-rate flag. An application with shading-rate attachments of its
//!   own never has an injecting device ([`crate::vk::hooks::device`]); one that sets rates per pipeline
//!   or per draw without them (vkd3d-proton) may, and its own state keeps its rate with
//!   `combinerOps[1]` rewritten on a copy ([`attachment_combiner`]), as do its
//!   `vkCmdSetFragmentShadingRateKHR` calls ([`cmd_set_fragment_shading_rate`](crate::vk::hooks::pipeline::cmd_set_fragment_shading_rate)).
//! - Shader modules using `FragSizeEXT` or `FragInvocationCountEXT` (capability
//!   `FragmentDensityEXT`) cannot be emulated (docs/vulkan-fdm-on-fsr.md#shader-built-ins): said
//!   once, passed through.
//! - Samplers lose the subsampled flags and image views the dynamic and deferred density-map flags,
//!   which the emulation does not offer (docs/vulkan-fdm-on-fsr.md#subsampled-images), said once.

use std::ffi::c_void;
use std::sync::atomic::AtomicBool;

use ash::vk;

use crate::vk::base::chain::{self, ChainCopy};
use crate::vk::base::ffi::once;

const FDM_FLAG: vk::PipelineCreateFlags =
    vk::PipelineCreateFlags::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_EXT;
const FSR_FLAG: vk::PipelineCreateFlags =
    vk::PipelineCreateFlags::RENDERING_FRAGMENT_SHADING_RATE_ATTACHMENT_KHR;
const FDM_FLAG2: vk::PipelineCreateFlags2KHR =
    vk::PipelineCreateFlags2KHR::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_EXT;
const FSR_FLAG2: vk::PipelineCreateFlags2KHR =
    vk::PipelineCreateFlags2KHR::RENDERING_FRAGMENT_SHADING_RATE_ATTACHMENT;

/// The shading-rate state that lets the attachment decide: the pipeline's own rate 1×1 kept
/// (`KEEP` with the primitive rate, which is 1×1 too), then replaced by the attachment's.
pub fn fsr_state() -> vk::PipelineFragmentShadingRateStateCreateInfoKHR<'static> {
    vk::PipelineFragmentShadingRateStateCreateInfoKHR::default()
        .fragment_size(vk::Extent2D {
            width: 1,
            height: 1,
        })
        .combiner_ops([
            vk::FragmentShadingRateCombinerOpKHR::KEEP,
            vk::FragmentShadingRateCombinerOpKHR::REPLACE,
        ])
}

pub type CombinerOp = vk::FragmentShadingRateCombinerOpKHR;

/// The `combinerOps[1]` with which an injected shading-rate attachment applies on top of an
/// application's own rate (`size` combined with the primitive rate by `ops[0]`), given the
/// application's `ops` (docs/injection.md#apps-that-set-rates).
///
/// `combinerOps[1]` combines the result of `combinerOps[0]` with the attachment's rate
/// (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#primsrast-fragment-shading-rate-combining>);
/// without an attachment, or with fovea's full-rate map, that rate is 1×1. `MAX` takes the
/// coarser of the application's rate and the map's per axis: the map's rate where the application
/// renders at 1×1 (vkd3d-proton's default), the application's own wherever it asked for coarser,
/// and the application's unchanged outside eye passes. Where the device allows only `KEEP` and
/// `REPLACE` (`fragmentShadingRateNonTrivialCombinerOps` false), `REPLACE` gives the same result
/// only where the application's rate is 1×1 and `ops[0]` keeps it so; elsewhere the application's
/// `KEEP` stays and its own rate wins. An application without the attachment feature has `KEEP`
/// there (VUID-vkCmdSetFragmentShadingRateKHR-attachmentFragmentShadingRate-04508); any other
/// combiner is its own and stays.
pub fn attachment_combiner(
    non_trivial: bool,
    size: vk::Extent2D,
    ops: [CombinerOp; 2],
) -> CombinerOp {
    let one = vk::Extent2D {
        width: 1,
        height: 1,
    };
    if ops[1] != CombinerOp::KEEP {
        ops[1]
    } else if non_trivial {
        CombinerOp::MAX
    } else if size == one && ops[0] == CombinerOp::KEEP {
        CombinerOp::REPLACE
    } else {
        CombinerOp::KEEP
    }
}

/// What one graphics pipeline create info says about density maps.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Facts {
    /// The density-map flag in the 32-bit flags.
    pub flag: bool,
    /// The density-map flag in a chained `VkPipelineCreateFlags2CreateInfoKHR`.
    pub flag2: bool,
    /// A `VkPipelineCreateFlags2CreateInfoKHR` is chained (its flags replace the 32-bit ones).
    pub has_flags2: bool,
    /// Its render pass has a density-map attachment.
    pub fdm_pass: bool,
    /// The application chained shading-rate state itself.
    pub own_state: bool,
    /// That state's fragment size and combiners.
    pub own_rate: Option<(vk::Extent2D, [CombinerOp; 2])>,
    /// A graphics pipeline library without pre-rasterisation or fragment-shader state (the
    /// shading-rate state is no part of it).
    pub no_rate_state: bool,
    /// The device injects maps into eye passes (docs/injection.md#how-the-attachment-gets-in):
    /// every render pass there has a shading-rate attachment, and any dynamic rendering may get
    /// one.
    pub inject: bool,
    /// The pipeline is for dynamic rendering (no render pass).
    pub dynamic: bool,
    /// The injecting device has `fragmentShadingRateNonTrivialCombinerOps`.
    pub non_trivial: bool,
}

impl Facts {
    /// Whether the pipeline is used with a density map.
    pub fn fdm(&self) -> bool {
        (if self.has_flags2 {
            self.flag2
        } else {
            self.flag
        }) || self.fdm_pass
    }

    /// Whether the shading-rate state is added.
    pub fn add_state(&self) -> bool {
        (self.fdm() || self.inject) && !self.own_state && !self.no_rate_state
    }

    /// Whether the shading-rate attachment flag goes into a copy of a chained
    /// `VkPipelineCreateFlags2CreateInfoKHR` (whose flags replace the 32-bit ones).
    fn rewrite_flags2(&self) -> bool {
        self.flag2 || (self.inject_flag() && self.has_flags2)
    }

    /// Whether the shading-rate attachment flag is added for injection: pipelines for dynamic
    /// rendering need it (render passes carry their attachment themselves).
    fn inject_flag(&self) -> bool {
        self.inject && self.dynamic
    }

    /// The `combinerOps[1]` the application's own state gets on an injecting device, where that
    /// differs from its own ([`attachment_combiner`]).
    pub fn retuned_combiner(&self) -> Option<CombinerOp> {
        let (size, ops) = self.own_rate?;
        let op = attachment_combiner(self.non_trivial, size, ops);
        (self.inject && !self.no_rate_state && op != ops[1]).then_some(op)
    }

    /// Whether anything is rewritten.
    pub fn rewrite(&self) -> bool {
        self.add_state()
            || self.flag
            || self.flag2
            || self.inject_flag()
            || self.retuned_combiner().is_some()
    }
}

/// Reads what `ci` says about density maps; `fdm_pass` answers for its render pass.
///
/// # Safety
/// `ci` must be a valid create info with a valid chain.
pub unsafe fn facts(
    ci: &vk::GraphicsPipelineCreateInfo<'_>,
    fdm_pass: impl Fn(vk::RenderPass) -> bool,
) -> Facts {
    let find = |ty| {
        // SAFETY: as the caller promised.
        unsafe { chain::find::<u8>(ci.p_next, ty) }.ok().flatten()
    };
    let flags2 = find(vk::StructureType::PIPELINE_CREATE_FLAGS_2_CREATE_INFO_KHR)
        // SAFETY: found by its sType.
        .map(|p| unsafe { (*(p as *const vk::PipelineCreateFlags2CreateInfoKHR<'_>)).flags });
    let library = find(vk::StructureType::GRAPHICS_PIPELINE_LIBRARY_CREATE_INFO_EXT)
        // SAFETY: found by its sType.
        .map(|p| unsafe { (*(p as *const vk::GraphicsPipelineLibraryCreateInfoEXT<'_>)).flags });
    let rate_parts = vk::GraphicsPipelineLibraryFlagsEXT::PRE_RASTERIZATION_SHADERS
        | vk::GraphicsPipelineLibraryFlagsEXT::FRAGMENT_SHADER;
    let own_state = find(vk::StructureType::PIPELINE_FRAGMENT_SHADING_RATE_STATE_CREATE_INFO_KHR);
    Facts {
        flag: ci.flags.contains(FDM_FLAG),
        flag2: flags2.is_some_and(|f| f.contains(FDM_FLAG2)),
        has_flags2: flags2.is_some(),
        fdm_pass: fdm_pass(ci.render_pass),
        own_state: own_state.is_some(),
        own_rate: own_state.map(|p| {
            let p = p as *const vk::PipelineFragmentShadingRateStateCreateInfoKHR<'_>;
            // SAFETY: found by its sType, read only.
            unsafe { ((*p).fragment_size, (*p).combiner_ops) }
        }),
        no_rate_state: library.is_some_and(|f| !f.intersects(rate_parts)),
        inject: false,
        dynamic: ci.render_pass == vk::RenderPass::null(),
        non_trivial: false,
    }
}

/// The storage one rewritten create info points into.
#[derive(Default)]
pub struct Owned {
    state: Option<Box<vk::PipelineFragmentShadingRateStateCreateInfoKHR<'static>>>,
    flags2: Option<Box<vk::PipelineCreateFlags2CreateInfoKHR<'static>>>,
    _chain: Option<ChainCopy>,
}

/// The rewritten copy of `ci` and what it points into; `Err` where its chain cannot be copied.
///
/// # Safety
/// `ci` must be a valid create info with a valid chain.
pub unsafe fn rewrite(
    ci: &vk::GraphicsPipelineCreateInfo<'_>,
    f: Facts,
) -> Result<(vk::GraphicsPipelineCreateInfo<'static>, Owned), chain::ChainError> {
    // SAFETY: as the caller promised.
    unsafe { rewrite_with(ci, f, true) }
}

/// [`rewrite`]; with `copy_chain` false, only what needs no copy of the application's chain is done (the
/// 32-bit flag, the shading-rate state put in front of the chain): a chained
/// `VkPipelineCreateFlags2CreateInfoKHR` and the application's own shading-rate state stay as
/// given. That cannot fail.
///
/// # Safety
/// `ci` must be a valid create info with a valid chain.
pub unsafe fn rewrite_with(
    ci: &vk::GraphicsPipelineCreateInfo<'_>,
    f: Facts,
    copy_chain: bool,
) -> Result<(vk::GraphicsPipelineCreateInfo<'static>, Owned), chain::ChainError> {
    // SAFETY: lives as long as the caller's create info, across the call down.
    let mut copy = unsafe {
        std::mem::transmute::<
            vk::GraphicsPipelineCreateInfo<'_>,
            vk::GraphicsPipelineCreateInfo<'static>,
        >(*ci)
    };
    let mut owned = Owned::default();
    if f.flag || f.inject_flag() {
        // The shading-rate flag is required of every pipeline used in a rendering with a
        // shading-rate attachment
        // (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkCmdDraw.html>,
        // VUID-vkCmdDraw-imageView-06183).
        copy.flags = (copy.flags & !FDM_FLAG) | FSR_FLAG;
    }
    let mut head = ci.p_next;
    let flags2_ty = vk::StructureType::PIPELINE_CREATE_FLAGS_2_CREATE_INFO_KHR;
    let state_ty = vk::StructureType::PIPELINE_FRAGMENT_SHADING_RATE_STATE_CREATE_INFO_KHR;
    let rewrite_flags2 = copy_chain && f.rewrite_flags2();
    let retuned = f.retuned_combiner().filter(|_| copy_chain);
    if rewrite_flags2 || retuned.is_some() {
        let flags2 = if rewrite_flags2 {
            // SAFETY: as the caller promised; found by its sType.
            unsafe {
                let Ok(Some(p)) =
                    chain::find::<vk::PipelineCreateFlags2CreateInfoKHR<'_>>(head, flags2_ty)
                else {
                    return Err(chain::ChainError::Unknown(flags2_ty));
                };
                Some((*p).flags)
            }
        } else {
            None
        };
        // SAFETY: as the caller promised; the structs left out are replaced by copies below.
        let rest = unsafe {
            ChainCopy::without(head, |t| {
                (rewrite_flags2 && t == flags2_ty) || (retuned.is_some() && t == state_ty)
            })
        }?;
        head = rest.head();
        if let Some(flags) = flags2 {
            let mut mine = Box::new(
                vk::PipelineCreateFlags2CreateInfoKHR::default()
                    .flags((flags & !FDM_FLAG2) | FSR_FLAG2),
            );
            mine.p_next = head as *mut c_void;
            head = &*mine as *const _ as *const c_void;
            owned.flags2 = Some(mine);
        }
        if let (Some(op), Some((size, ops))) = (retuned, f.own_rate) {
            // The application's rate and first combiner kept; the attachment applies on top.
            let mut state = Box::new(
                vk::PipelineFragmentShadingRateStateCreateInfoKHR::default()
                    .fragment_size(size)
                    .combiner_ops([ops[0], op]),
            );
            state.p_next = head as *mut c_void;
            head = &*state as *const _ as *const c_void;
            owned.state = Some(state);
        }
        owned._chain = Some(rest);
    }
    if f.add_state() && owned.state.is_none() {
        let mut state = Box::new(fsr_state());
        state.p_next = head as *mut c_void;
        head = &*state as *const _ as *const c_void;
        owned.state = Some(state);
    }
    copy.p_next = head;
    Ok((copy, owned))
}

pub const SHADER_FDM: vk::ShaderCreateFlagsEXT =
    vk::ShaderCreateFlagsEXT::FRAGMENT_DENSITY_MAP_ATTACHMENT;
const SHADER_FSR: vk::ShaderCreateFlagsEXT =
    vk::ShaderCreateFlagsEXT::FRAGMENT_SHADING_RATE_ATTACHMENT;

/// The flags a shader object's create info reaches the driver with: a fragment shader used with a
/// density-map attachment is one used with the shading-rate attachment standing in for it
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkShaderCreateFlagBitsEXT.html>);
/// the density-map bit is invalid on the driver's device, which has no density maps.
pub fn shader_flags(f: vk::ShaderCreateFlagsEXT) -> vk::ShaderCreateFlagsEXT {
    if f.contains(SHADER_FDM) {
        (f & !SHADER_FDM) | SHADER_FSR
    } else {
        f
    }
}

/// SPIR-V's `OpCapability` opcode and the `FragmentDensityEXT` capability
/// (<https://registry.khronos.org/SPIR-V/specs/unified1/SPIRV.html>, "Capability").
const OP_CAPABILITY: u32 = 17;
const FRAGMENT_DENSITY_EXT: u32 = 5291;
const SPIRV_MAGIC: u32 = 0x0723_0203;

/// Whether a SPIR-V module declares `FragmentDensityEXT`, which `FragSizeEXT` and
/// `FragInvocationCountEXT` need. Capabilities come first after the five-word header, so only
/// those instructions are read.
pub fn uses_fragment_density(code: &[u32]) -> bool {
    if code.len() < 5 || code[0] != SPIRV_MAGIC {
        return false;
    }
    let mut at = 5;
    while at < code.len() {
        let word = code[at];
        let (len, op) = ((word >> 16) as usize, word & 0xffff);
        if op != OP_CAPABILITY || len < 2 {
            return false;
        }
        if code[at + 1..].first() == Some(&FRAGMENT_DENSITY_EXT) {
            return true;
        }
        at += len;
    }
    false
}

const VIEW_FLAGS: vk::ImageViewCreateFlags = vk::ImageViewCreateFlags::from_raw(
    vk::ImageViewCreateFlags::FRAGMENT_DENSITY_MAP_DYNAMIC_EXT.as_raw()
        | vk::ImageViewCreateFlags::FRAGMENT_DENSITY_MAP_DEFERRED_EXT.as_raw(),
);
static VIEW_FLAGS_SAID: AtomicBool = AtomicBool::new(false);

/// The flags an image view reaches the driver with on an emulating device: without the dynamic
/// and deferred density-map flags. `Some` where that differs from `flags`.
pub fn view_flags(flags: vk::ImageViewCreateFlags) -> Option<vk::ImageViewCreateFlags> {
    if !flags.intersects(VIEW_FLAGS) {
        return None;
    }
    once(
        &VIEW_FLAGS_SAID,
        "density-map image view flags DYNAMIC/DEFERRED left out: emulated maps are read as \
         static ones",
    );
    Some(flags & !VIEW_FLAGS)
}

/// The sampler flags the emulation leaves out: it never subsamples images.
pub const SUBSAMPLED: vk::SamplerCreateFlags = vk::SamplerCreateFlags::from_raw(
    vk::SamplerCreateFlags::SUBSAMPLED_EXT.as_raw()
        | vk::SamplerCreateFlags::SUBSAMPLED_COARSE_RECONSTRUCTION_EXT.as_raw(),
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shader_objects_for_density_maps_are_for_the_shading_rate_attachment() {
        let other = vk::ShaderCreateFlagsEXT::LINK_STAGE;
        assert_eq!(shader_flags(SHADER_FDM | other), SHADER_FSR | other);
        assert_eq!(shader_flags(other), other);
        assert_eq!(shader_flags(SHADER_FSR), SHADER_FSR);
    }
    use ash::vk::Handle as _;

    #[test]
    fn density_pipelines_are_recognised() {
        let pass = vk::RenderPass::from_raw(5);
        let fdm_pass = |p: vk::RenderPass| p == pass;
        let ci = vk::GraphicsPipelineCreateInfo::default();
        // SAFETY: create infos on the stack.
        unsafe {
            assert!(!facts(&ci, fdm_pass).rewrite());
            let f = facts(&ci.render_pass(pass), fdm_pass);
            assert!(f.fdm_pass && f.add_state());
            let f = facts(&ci.flags(FDM_FLAG), fdm_pass);
            assert!(f.flag && f.add_state());
            let mut own = fsr_state();
            let f = facts(&ci.flags(FDM_FLAG).push_next(&mut own), fdm_pass);
            assert!(
                f.rewrite() && !f.add_state(),
                "the flag swapped, its state kept"
            );
            let mut f2 = vk::PipelineCreateFlags2CreateInfoKHR::default().flags(FDM_FLAG2);
            let f = facts(&ci.push_next(&mut f2), fdm_pass);
            assert!(f.flag2 && f.add_state());
            let mut f2 = vk::PipelineCreateFlags2CreateInfoKHR::default();
            let f = facts(&ci.flags(FDM_FLAG).push_next(&mut f2), fdm_pass);
            assert!(!f.fdm(), "the 64-bit flags replace the 32-bit ones");
            let mut lib = vk::GraphicsPipelineLibraryCreateInfoEXT::default()
                .flags(vk::GraphicsPipelineLibraryFlagsEXT::VERTEX_INPUT_INTERFACE);
            let f = facts(&ci.flags(FDM_FLAG).push_next(&mut lib), fdm_pass);
            assert!(
                f.rewrite() && !f.add_state(),
                "no rate state in a vertex-input library"
            );
        }
    }

    #[test]
    fn the_rewrite_is_a_copy_with_the_state_in_front() {
        let mut rendering = vk::PipelineRenderingCreateInfo::default();
        let mut f2 = vk::PipelineCreateFlags2CreateInfoKHR::default()
            .flags(FDM_FLAG2 | vk::PipelineCreateFlags2KHR::DISABLE_OPTIMIZATION);
        let ci = vk::GraphicsPipelineCreateInfo::default()
            .flags(FDM_FLAG)
            .push_next(&mut f2)
            .push_next(&mut rendering);
        // SAFETY: create infos on the stack.
        let (copy, owned) = unsafe {
            let f = facts(&ci, |_| false);
            rewrite(&ci, f).expect("rewrite")
        };
        assert_eq!(copy.flags, FSR_FLAG);
        assert_eq!(ci.flags, FDM_FLAG, "the application's struct is kept");
        assert!(f2.flags.contains(FDM_FLAG2));
        // SAFETY: the copy's chain, alive with `owned`.
        unsafe {
            let state = copy.p_next as *const vk::PipelineFragmentShadingRateStateCreateInfoKHR;
            assert_eq!(
                (*state).s_type,
                vk::StructureType::PIPELINE_FRAGMENT_SHADING_RATE_STATE_CREATE_INFO_KHR
            );
            assert_eq!((*state).combiner_ops, fsr_state().combiner_ops);
            let flags2 = chain::find::<vk::PipelineCreateFlags2CreateInfoKHR>(
                copy.p_next,
                vk::StructureType::PIPELINE_CREATE_FLAGS_2_CREATE_INFO_KHR,
            )
            .unwrap()
            .unwrap();
            assert_eq!(
                (*flags2).flags,
                FSR_FLAG2 | vk::PipelineCreateFlags2KHR::DISABLE_OPTIMIZATION
            );
            assert!(chain::find::<u8>(
                copy.p_next,
                vk::StructureType::PIPELINE_RENDERING_CREATE_INFO
            )
            .unwrap()
            .is_some());
        }
        drop(owned);
    }

    #[test]
    fn injected_dynamic_rendering_pipelines_get_the_flag_and_the_state() {
        let mut rendering = vk::PipelineRenderingCreateInfo::default();
        let plain = vk::GraphicsPipelineCreateInfo::default()
            .flags(vk::PipelineCreateFlags::DISABLE_OPTIMIZATION)
            .push_next(&mut rendering);
        // SAFETY: create infos on the stack.
        let f = unsafe { facts(&plain, |_| false) };
        assert!(!f.rewrite(), "without injection nothing changes");
        let f = Facts { inject: true, ..f };
        assert!(f.rewrite() && f.add_state());
        // SAFETY: as above.
        let (copy, owned) = unsafe { rewrite(&plain, f) }.expect("rewrite");
        assert_eq!(
            copy.flags,
            FSR_FLAG | vk::PipelineCreateFlags::DISABLE_OPTIMIZATION
        );
        assert_eq!(plain.flags, vk::PipelineCreateFlags::DISABLE_OPTIMIZATION);
        // SAFETY: the copy's chain, alive with `owned`.
        unsafe {
            let state = copy.p_next as *const vk::PipelineFragmentShadingRateStateCreateInfoKHR;
            assert_eq!((*state).fragment_size, fsr_state().fragment_size);
            assert_eq!((*state).combiner_ops, fsr_state().combiner_ops);
            assert_eq!((*state).p_next, plain.p_next);
        }
        drop(owned);

        // Flags in a chained VkPipelineCreateFlags2CreateInfoKHR replace the 32-bit ones: the flag
        // goes into a copy of that struct too.
        let mut f2 = vk::PipelineCreateFlags2CreateInfoKHR::default()
            .flags(vk::PipelineCreateFlags2KHR::DISABLE_OPTIMIZATION);
        let with2 = vk::GraphicsPipelineCreateInfo::default().push_next(&mut f2);
        // SAFETY: as above.
        let read = unsafe { facts(&with2, |_| false) };
        let f = Facts {
            inject: true,
            ..read
        };
        // SAFETY: as above.
        let (copy, owned) = unsafe { rewrite(&with2, f) }.expect("rewrite");
        // SAFETY: the copy's chain, alive with `owned`.
        unsafe {
            let flags2 = chain::find::<vk::PipelineCreateFlags2CreateInfoKHR>(
                copy.p_next,
                vk::StructureType::PIPELINE_CREATE_FLAGS_2_CREATE_INFO_KHR,
            )
            .unwrap()
            .unwrap();
            assert_eq!(
                (*flags2).flags,
                FSR_FLAG2 | vk::PipelineCreateFlags2KHR::DISABLE_OPTIMIZATION
            );
        }
        assert_eq!(f2.flags, vk::PipelineCreateFlags2KHR::DISABLE_OPTIMIZATION);
        drop(owned);

        // A pipeline for a render pass gets the state, not the flag (the pass has the attachment).
        let with_pass =
            vk::GraphicsPipelineCreateInfo::default().render_pass(vk::RenderPass::from_raw(9));
        // SAFETY: as above.
        let read = unsafe { facts(&with_pass, |_| false) };
        let f = Facts {
            inject: true,
            ..read
        };
        assert!(f.add_state() && f.rewrite());
        // SAFETY: as above.
        let (copy, owned) = unsafe { rewrite(&with_pass, f) }.expect("rewrite");
        assert_eq!(copy.flags, vk::PipelineCreateFlags::empty());
        assert!(!copy.p_next.is_null());
        drop(owned);

        // A library without pre-rasterisation or fragment state gets the flag, not the state.
        let mut lib = vk::GraphicsPipelineLibraryCreateInfoEXT::default()
            .flags(vk::GraphicsPipelineLibraryFlagsEXT::VERTEX_INPUT_INTERFACE);
        let vertex = vk::GraphicsPipelineCreateInfo::default().push_next(&mut lib);
        // SAFETY: as above.
        let read = unsafe { facts(&vertex, |_| false) };
        let f = Facts {
            inject: true,
            ..read
        };
        assert!(f.rewrite() && !f.add_state());
    }

    #[test]
    fn the_attachment_applies_on_top_of_the_applications_rate() {
        use CombinerOp as Op;
        let one = vk::Extent2D {
            width: 1,
            height: 1,
        };
        let two = vk::Extent2D {
            width: 2,
            height: 2,
        };
        let keep = [Op::KEEP, Op::KEEP];
        assert_eq!(attachment_combiner(true, one, keep), Op::MAX);
        assert_eq!(
            attachment_combiner(true, two, keep),
            Op::MAX,
            "MAX keeps the application's coarser rate"
        );
        assert_eq!(attachment_combiner(true, one, [Op::MIN, Op::KEEP]), Op::MAX);
        // Only KEEP and REPLACE: REPLACE where the application's rate is 1×1 all the way through,
        // else its own rate wins.
        assert_eq!(attachment_combiner(false, one, keep), Op::REPLACE);
        assert_eq!(attachment_combiner(false, two, keep), Op::KEEP);
        assert_eq!(
            attachment_combiner(false, one, [Op::REPLACE, Op::KEEP]),
            Op::KEEP,
            "the primitive rate may be coarser"
        );
        // A combiner of the application's own stays.
        assert_eq!(attachment_combiner(true, one, [Op::KEEP, Op::MIN]), Op::MIN);
        assert_eq!(
            attachment_combiner(false, one, [Op::KEEP, Op::REPLACE]),
            Op::REPLACE
        );
    }

    #[test]
    fn an_applications_own_state_gets_the_combiner_on_a_copy() {
        let size = vk::Extent2D {
            width: 2,
            height: 1,
        };
        let mut own = vk::PipelineFragmentShadingRateStateCreateInfoKHR::default()
            .fragment_size(size)
            .combiner_ops([CombinerOp::KEEP, CombinerOp::KEEP]);
        let own_ptr: *const vk::PipelineFragmentShadingRateStateCreateInfoKHR = &own;
        let mut rendering = vk::PipelineRenderingCreateInfo::default();
        let ci = vk::GraphicsPipelineCreateInfo::default()
            .push_next(&mut rendering)
            .push_next(&mut own);
        // SAFETY: create infos on the stack.
        let read = unsafe { facts(&ci, |_| false) };
        assert!(!read.rewrite(), "not on a device that does not inject");
        for (non_trivial, want) in [(true, Some(CombinerOp::MAX)), (false, None)] {
            let f = Facts {
                inject: true,
                non_trivial,
                ..read
            };
            assert_eq!(f.retuned_combiner(), want, "{non_trivial}");
            assert!(
                f.rewrite() && !f.add_state(),
                "the flag, not a second state"
            );
            // SAFETY: as above.
            let (copy, owned) = unsafe { rewrite(&ci, f) }.expect("rewrite");
            // SAFETY: the copy's chain, alive with `owned`.
            unsafe {
                let state = chain::find::<vk::PipelineFragmentShadingRateStateCreateInfoKHR>(
                    copy.p_next,
                    vk::StructureType::PIPELINE_FRAGMENT_SHADING_RATE_STATE_CREATE_INFO_KHR,
                )
                .unwrap()
                .unwrap();
                assert_eq!((*state).fragment_size, size, "its rate kept");
                assert_eq!(
                    (*state).combiner_ops,
                    [CombinerOp::KEEP, want.unwrap_or(CombinerOp::KEEP)]
                );
                assert_eq!(
                    std::ptr::eq(state, own_ptr),
                    want.is_none(),
                    "copied where changed"
                );
                assert!(chain::find::<u8>(
                    copy.p_next,
                    vk::StructureType::PIPELINE_RENDERING_CREATE_INFO
                )
                .unwrap()
                .is_some());
            }
            assert_eq!(copy.flags, FSR_FLAG);
            drop(owned);
        }
        // SAFETY: the application's struct, alive.
        let kept = unsafe { (*own_ptr).combiner_ops };
        assert_eq!(
            kept,
            [CombinerOp::KEEP, CombinerOp::KEEP],
            "the application's struct is kept"
        );
    }

    #[test]
    fn fragment_density_shaders_are_found() {
        let header = [SPIRV_MAGIC, 0x0001_0000, 0, 100, 0];
        let cap = |c: u32| [(2 << 16) | OP_CAPABILITY, c];
        let memory_model = [(3 << 16) | 14, 0, 1];
        let module = |caps: &[u32]| {
            let mut v = header.to_vec();
            for &c in caps {
                v.extend(cap(c));
            }
            v.extend(memory_model);
            v
        };
        assert!(uses_fragment_density(&module(&[1, FRAGMENT_DENSITY_EXT])));
        assert!(!uses_fragment_density(&module(&[1])));
        assert!(!uses_fragment_density(&[]));
        assert!(!uses_fragment_density(&[0, 0, 0, 0, 0, 0]));
        // A truncated capability instruction reads no further.
        let mut cut = header.to_vec();
        cut.push((2 << 16) | OP_CAPABILITY);
        assert!(!uses_fragment_density(&cut));
    }

    #[test]
    fn view_and_sampler_flags() {
        use vk::ImageViewCreateFlags as V;
        assert_eq!(view_flags(V::empty()), None);
        assert_eq!(
            view_flags(V::FRAGMENT_DENSITY_MAP_DYNAMIC_EXT | V::FRAGMENT_DENSITY_MAP_DEFERRED_EXT),
            Some(V::empty())
        );
        assert!(SUBSAMPLED.contains(vk::SamplerCreateFlags::SUBSAMPLED_EXT));
    }
}
