//! Pipelines, shader modules, samplers and image views on an emulating or injecting device.
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
//!   dynamic rendering the shading-rate flag. An
//!   application that uses shading rates itself never has an injecting device
//!   ([`crate::vk::device`]), so no pipeline there carries rate state of its own.
//! - Shader modules using `FragSizeEXT` or `FragInvocationCountEXT` (capability
//!   `FragmentDensityEXT`) cannot be emulated (docs/vulkan-fdm-on-fsr.md#shader-built-ins): said
//!   once, passed through.
//! - Samplers lose the subsampled flags and image views the dynamic and deferred density-map flags,
//!   which the emulation does not offer (docs/vulkan-fdm-on-fsr.md#subsampled-images), said once.

use std::ffi::c_void;
use std::sync::atomic::{AtomicBool, Ordering};

use ash::vk;

use crate::vk::chain::{self, ChainCopy};
use crate::vk::loader::guard;
use crate::vk::registry;

const FDM_FLAG: vk::PipelineCreateFlags =
    vk::PipelineCreateFlags::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_EXT;
const FSR_FLAG: vk::PipelineCreateFlags =
    vk::PipelineCreateFlags::RENDERING_FRAGMENT_SHADING_RATE_ATTACHMENT_KHR;
const FDM_FLAG2: vk::PipelineCreateFlags2KHR =
    vk::PipelineCreateFlags2KHR::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_EXT;
const FSR_FLAG2: vk::PipelineCreateFlags2KHR =
    vk::PipelineCreateFlags2KHR::RENDERING_FRAGMENT_SHADING_RATE_ATTACHMENT;

/// Logs `message` the first time `flag` is seen unset.
fn once(flag: &AtomicBool, message: &str) {
    if !flag.swap(true, Ordering::Relaxed) {
        tracing::warn!("{message}");
    }
}

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
    /// A graphics pipeline library without pre-rasterisation or fragment-shader state (the
    /// shading-rate state is no part of it).
    pub no_rate_state: bool,
    /// The device injects maps into eye passes (docs/injection.md#how-the-attachment-gets-in):
    /// every render pass there has a shading-rate attachment, and any dynamic rendering may get
    /// one.
    pub inject: bool,
    /// The pipeline is for dynamic rendering (no render pass).
    pub dynamic: bool,
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

    /// Whether anything is rewritten.
    pub fn rewrite(&self) -> bool {
        self.add_state() || self.flag || self.flag2 || self.inject_flag()
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
    Facts {
        flag: ci.flags.contains(FDM_FLAG),
        flag2: flags2.is_some_and(|f| f.contains(FDM_FLAG2)),
        has_flags2: flags2.is_some(),
        fdm_pass: fdm_pass(ci.render_pass),
        own_state: find(vk::StructureType::PIPELINE_FRAGMENT_SHADING_RATE_STATE_CREATE_INFO_KHR)
            .is_some(),
        no_rate_state: library.is_some_and(|f| !f.intersects(rate_parts)),
        inject: false,
        dynamic: ci.render_pass == vk::RenderPass::null(),
    }
}

/// The storage one rewritten create info points into.
#[derive(Default)]
struct Owned {
    state: Option<Box<vk::PipelineFragmentShadingRateStateCreateInfoKHR<'static>>>,
    flags2: Option<Box<vk::PipelineCreateFlags2CreateInfoKHR<'static>>>,
    _chain: Option<ChainCopy>,
}

/// The rewritten copy of `ci` and what it points into; `Err` where its chain cannot be copied.
///
/// # Safety
/// `ci` must be a valid create info with a valid chain.
unsafe fn rewrite(
    ci: &vk::GraphicsPipelineCreateInfo<'_>,
    f: Facts,
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
    if f.rewrite_flags2() {
        let ty = vk::StructureType::PIPELINE_CREATE_FLAGS_2_CREATE_INFO_KHR;
        // SAFETY: as the caller promised; found by its sType.
        let mine = unsafe {
            let Ok(Some(p)) = chain::find::<vk::PipelineCreateFlags2CreateInfoKHR<'_>>(head, ty)
            else {
                return Err(chain::ChainError::Unknown(ty));
            };
            *p
        };
        // SAFETY: as the caller promised.
        let rest = unsafe { ChainCopy::without(head, |t| t == ty) }?;
        // SAFETY: a plain copy whose pNext is set below.
        let mine: vk::PipelineCreateFlags2CreateInfoKHR<'static> = unsafe {
            std::mem::transmute::<
                vk::PipelineCreateFlags2CreateInfoKHR<'_>,
                vk::PipelineCreateFlags2CreateInfoKHR<'static>,
            >(mine)
        };
        let mut mine = Box::new(mine);
        mine.flags = (mine.flags & !FDM_FLAG2) | FSR_FLAG2;
        mine.p_next = rest.head() as *mut c_void;
        head = &*mine as *const _ as *const c_void;
        owned.flags2 = Some(mine);
        owned._chain = Some(rest);
    }
    if f.add_state() {
        let mut state = Box::new(fsr_state());
        state.p_next = head as *mut c_void;
        head = &*state as *const _ as *const c_void;
        owned.state = Some(state);
    }
    copy.p_next = head;
    Ok((copy, owned))
}

/// `vkCreateGraphicsPipelines` on an emulating device.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn create_graphics_pipelines(
    device: vk::Device,
    cache: vk::PipelineCache,
    count: u32,
    infos: *const vk::GraphicsPipelineCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Pipeline,
) -> vk::Result {
    guard(
        "vkCreateGraphicsPipelines",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let Some(dev) = (unsafe { registry::device(device) }) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let Some(next) = dev.next.create_graphics_pipelines else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let list: &[vk::GraphicsPipelineCreateInfo<'_>] = if infos.is_null() || count == 0 {
                &[]
            } else {
                // SAFETY: `count` create infos, as the caller promised.
                unsafe { std::slice::from_raw_parts(infos, count as usize) }
            };
            let facts: Vec<Facts> = list
                .iter()
                // SAFETY: valid create infos.
                .map(|ci| unsafe { facts(ci, registry::pass_uses_fdm) })
                .map(|f| Facts {
                    inject: dev.inject.is_some(),
                    ..f
                })
                .collect();
            if (dev.fdm.is_none() && dev.inject.is_none()) || !facts.iter().any(Facts::rewrite) {
                // SAFETY: the next layer's function, with the caller's arguments.
                return unsafe { next(device, cache, count, infos, alloc, out) };
            }
            let mut copies = Vec::with_capacity(list.len());
            let mut owned = Vec::with_capacity(list.len());
            for (ci, f) in list.iter().zip(&facts) {
                if !f.rewrite() {
                    // SAFETY: lives as long as the caller's create info, across the call down.
                    copies.push(unsafe {
                        std::mem::transmute::<
                            vk::GraphicsPipelineCreateInfo<'_>,
                            vk::GraphicsPipelineCreateInfo<'static>,
                        >(*ci)
                    });
                    continue;
                }
                // SAFETY: a valid create info.
                match unsafe { rewrite(ci, *f) } {
                    Ok((c, o)) => {
                        copies.push(c);
                        owned.push(o);
                    }
                    Err(e) => {
                        tracing::warn!(
                            error = ?e,
                            "cannot rewrite a graphics pipeline's pNext chain; passing the \
                             pipelines through untouched (they will ignore the density map)"
                        );
                        // SAFETY: the next layer's function, with the caller's arguments.
                        return unsafe { next(device, cache, count, infos, alloc, out) };
                    }
                }
            }
            tracing::debug!(
                count,
                rewritten = facts.iter().filter(|f| f.rewrite()).count(),
                "graphics pipelines get the shading-rate state"
            );
            // SAFETY: the copies and what they point at live across the call.
            let r = unsafe { next(device, cache, count, copies.as_ptr(), alloc, out) };
            drop(owned);
            r
        },
    )
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

static FRAG_SIZE_SAID: AtomicBool = AtomicBool::new(false);

/// `vkCreateShaderModule` on an emulating device: detects shaders that read the fragment size.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn create_shader_module(
    device: vk::Device,
    info: *const vk::ShaderModuleCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::ShaderModule,
) -> vk::Result {
    guard(
        "vkCreateShaderModule",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let Some(dev) = (unsafe { registry::device(device) }) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let Some(next) = dev.next.create_shader_module else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            if dev.fdm.is_some() && !info.is_null() {
                // SAFETY: the caller's create info: `codeSize` bytes of 4-byte-aligned SPIR-V.
                let code = unsafe {
                    let ci = &*info;
                    if ci.p_code.is_null() {
                        &[][..]
                    } else {
                        std::slice::from_raw_parts(ci.p_code, ci.code_size / 4)
                    }
                };
                if uses_fragment_density(code) {
                    once(
                        &FRAG_SIZE_SAID,
                        "a shader uses FragSizeEXT or FragInvocationCountEXT (capability \
                         FragmentDensityEXT), which shading-rate attachments cannot emulate; it is \
                         passed on as is and the driver may refuse it",
                    );
                }
            }
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { next(device, info, alloc, out) }
        },
    )
}

const SUBSAMPLED: vk::SamplerCreateFlags = vk::SamplerCreateFlags::from_raw(
    vk::SamplerCreateFlags::SUBSAMPLED_EXT.as_raw()
        | vk::SamplerCreateFlags::SUBSAMPLED_COARSE_RECONSTRUCTION_EXT.as_raw(),
);
static SUBSAMPLED_SAID: AtomicBool = AtomicBool::new(false);

/// `vkCreateSampler` on an emulating device: the subsampled flags are left out of a copy.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn create_sampler(
    device: vk::Device,
    info: *const vk::SamplerCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Sampler,
) -> vk::Result {
    guard(
        "vkCreateSampler",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let Some(dev) = (unsafe { registry::device(device) }) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let Some(next) = dev.next.create_sampler else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let subsampled = !info.is_null()
                // SAFETY: the caller's create info, read only.
                && unsafe { (*info).flags }.intersects(SUBSAMPLED);
            if dev.fdm.is_none() || !subsampled {
                // SAFETY: the next layer's function, with the caller's arguments.
                return unsafe { next(device, info, alloc, out) };
            }
            once(
                &SUBSAMPLED_SAID,
                "subsampled sampler flags left out: emulated density maps never subsample images",
            );
            // SAFETY: a copy of the caller's create info, alive across the call.
            unsafe {
                let mut copy = *info;
                copy.flags &= !SUBSAMPLED;
                next(device, &copy, alloc, out)
            }
        },
    )
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

#[cfg(test)]
mod tests {
    use super::*;
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
