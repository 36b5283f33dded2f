//! Pipelines, shader modules, samplers and image views on an emulating or injecting device, with
//! the state of [`crate::vk::translate::rate_state`].

use std::sync::atomic::AtomicBool;

use ash::vk;

use crate::vk::base::ffi::{guard, once};
use crate::vk::registry;
use crate::vk::translate::rate_state::{
    attachment_combiner, facts, rewrite, rewrite_with, shader_flags, uses_fragment_density,
    CombinerOp, Facts, Owned, SHADER_FDM, SUBSAMPLED,
};

/// Set once the log has said that a graphics pipeline's chain could not be copied.
static CHAIN_LOGGED: AtomicBool = AtomicBool::new(false);

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
            // The render passes this device rewrote for a density map: their pipelines need the
            // state that lets the shading-rate attachment decide, or they ignore it.
            let fdm_pass = |pass: vk::RenderPass| {
                use ash::vk::Handle as _;
                pass != vk::RenderPass::null()
                    && dev.emulation.passes.lock().contains_key(&pass.as_raw())
            };
            let facts: Vec<Facts> = list
                .iter()
                // SAFETY: valid create infos.
                .map(|ci| (ci, unsafe { facts(ci, fdm_pass) }))
                .map(|(ci, f)| Facts {
                    // A render pass with the application's own shading-rate attachment is created
                    // as it came (docs/injection.md#switching-it-on): its pipelines keep the
                    // application's state, as they would without the layer.
                    inject: dev
                        .injection
                        .as_ref()
                        .is_some_and(|i| !i.is_apps_pass(ci.render_pass)),
                    non_trivial: dev
                        .injection
                        .as_ref()
                        .is_some_and(|i| i.fdm.non_trivial_combiners),
                    ..f
                })
                .collect();
            if (dev.fdm.is_none() && dev.injection.is_none()) || !facts.iter().any(Facts::rewrite) {
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
                let (c, o) = match unsafe { rewrite(ci, *f) } {
                    Ok(r) => r,
                    Err(e) => {
                        // This pipeline alone falls back; the others in the batch are rewritten
                        // in full.
                        once(
                            &CHAIN_LOGGED,
                            &format!(
                                "cannot copy a graphics pipeline's pNext chain ({e:?}): that \
                                 pipeline gets the shading-rate state in front of its chain, \
                                 its own chained flags and rate stay as given"
                            ),
                        );
                        // SAFETY: a valid create info; without a chain copy this cannot fail.
                        match unsafe { rewrite_with(ci, *f, false) } {
                            Ok(r) => r,
                            Err(_) => (
                                // SAFETY: lives as long as the caller's create info.
                                unsafe {
                                    std::mem::transmute::<
                                        vk::GraphicsPipelineCreateInfo<'_>,
                                        vk::GraphicsPipelineCreateInfo<'static>,
                                    >(*ci)
                                },
                                Owned::default(),
                            ),
                        }
                    }
                };
                copies.push(c);
                owned.push(o);
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

/// `vkCmdSetFragmentShadingRateKHR` on an injecting device: the application's rate and
/// `combinerOps[0]` go down as given, `combinerOps[1]` as [`attachment_combiner`] makes it, on a
/// copy of the two combiners on the stack, so an injected map applies to pipelines with the
/// dynamic shading-rate state too (docs/injection.md#apps-that-set-rates). Whether the device has
/// non-trivial combiners was read at `vkCreateDevice`; nothing is looked up per call but the
/// device.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_set_fragment_shading_rate(
    cb: vk::CommandBuffer,
    size: *const vk::Extent2D,
    ops: *const [CombinerOp; 2],
) {
    guard("vkCmdSetFragmentShadingRateKHR", (), || {
        // SAFETY: a command buffer dispatched by the loader.
        let Some(dev) = (unsafe { registry::device_ref(cb) }) else {
            return;
        };
        let Some(next) = dev.next.cmd_set_fragment_shading_rate else {
            return;
        };
        let retuned = match &dev.injection {
            Some(inj) if !size.is_null() && !ops.is_null() => {
                // SAFETY: the caller's arguments, read only.
                let (s, o) = unsafe { (*size, *ops) };
                let op = attachment_combiner(inj.fdm.non_trivial_combiners, s, o);
                (op != o[1]).then_some([o[0], op])
            }
            _ => None,
        };
        match retuned {
            // SAFETY: the next layer's function; the copy lives across the call.
            Some(copy) => unsafe { next(cb, size, &copy) },
            // SAFETY: the next layer's function, with the caller's arguments.
            None => unsafe { next(cb, size, ops) },
        }
    })
}

/// `vkCreateShadersEXT` on an emulating device: create infos with the density-map flag go down as
/// copies with [`shader_flags`] (the application's array is not written).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn create_shaders_ext(
    device: vk::Device,
    count: u32,
    infos: *const vk::ShaderCreateInfoEXT<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::ShaderEXT,
) -> vk::Result {
    guard(
        "vkCreateShadersEXT",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let Some(dev) = (unsafe { registry::device(device) }) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let Some(next) = dev.next.create_shaders_ext else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let list: &[vk::ShaderCreateInfoEXT<'_>] = if infos.is_null() || count == 0 {
                &[]
            } else {
                // SAFETY: `count` create infos, as the caller promised.
                unsafe { std::slice::from_raw_parts(infos, count as usize) }
            };
            if dev.fdm.is_none() || !list.iter().any(|ci| ci.flags.contains(SHADER_FDM)) {
                // SAFETY: the next layer's function, with the caller's arguments.
                return unsafe { next(device, count, infos, alloc, out) };
            }
            let copies: Vec<vk::ShaderCreateInfoEXT<'_>> = list
                .iter()
                .map(|ci| {
                    let mut c = *ci;
                    c.flags = shader_flags(ci.flags);
                    c
                })
                .collect();
            // SAFETY: the copies (pointing into the application's create infos) live across the
            // call.
            unsafe { next(device, count, copies.as_ptr(), alloc, out) }
        },
    )
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
