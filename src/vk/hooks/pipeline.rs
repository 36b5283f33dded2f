//! Pipelines, shader modules, samplers and image views on an emulating or injecting device, with
//! the state of [`crate::vk::translate::rate_state`].

use std::sync::atomic::AtomicBool;

use ash::vk;

use crate::vk::base::ffi::{once, slice, Arr, Call, In};
use crate::vk::registry::Device;
use crate::vk::translate::rate_state::{
    attachment_combiner, facts, rewrite, rewrite_with, shader_flags, uses_fragment_density,
    CombinerOp, Facts, Owned, SHADER_FDM, SUBSAMPLED,
};

/// Set once the log has said that a graphics pipeline's chain could not be copied.
static CHAIN_LOGGED: AtomicBool = AtomicBool::new(false);

hook! {
    /// `vkCreateGraphicsPipelines` on an emulating or injecting device: pipelines of a rewritten
    /// pass (or of any pass, injecting) go down as copies with the shading-rate state
    /// ([`rewrite`]).
    create_graphics_pipelines = "vkCreateGraphicsPipelines";
    on device(device), next create_graphics_pipelines,
    fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    create_pipelines(
        device: val vk::Device,
        cache: val vk::PipelineCache,
        count: val u32,
        infos: (array count) vk::GraphicsPipelineCreateInfo<'_>,
        alloc: val *const vk::AllocationCallbacks<'_>,
        out: val *mut vk::Pipeline,
    ) -> vk::Result
}

/// What [`rewrite`] needs to know of each create info in `list` on `dev`.
fn facts_of(dev: &Device, list: &[vk::GraphicsPipelineCreateInfo<'_>]) -> Vec<Facts> {
    // The render passes this device rewrote for a density map: their pipelines need the state
    // that lets the shading-rate attachment decide, or they ignore it.
    let fdm_pass = |pass: vk::RenderPass| {
        use ash::vk::Handle as _;
        pass != vk::RenderPass::null() && dev.emulation.passes.lock().contains_key(&pass.as_raw())
    };
    list.iter()
        // SAFETY: the application's create infos, valid as the command requires.
        .map(|ci| (ci, unsafe { facts(ci, fdm_pass) }))
        .map(|(ci, f)| Facts {
            // A render pass with the application's own shading-rate attachment is created as it
            // came (docs/injection.md#switching-it-on): its pipelines keep the application's
            // state, as they would without the layer.
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
        .collect()
}

/// A create info as the application passed it, its lifetime erased for the array of copies.
///
/// # Safety
/// The copy must not outlive the application's create info (it lives across the call down).
unsafe fn as_is(
    ci: &vk::GraphicsPipelineCreateInfo<'_>,
) -> vk::GraphicsPipelineCreateInfo<'static> {
    // SAFETY: the same struct with another lifetime; the caller keeps it within the original's.
    unsafe {
        std::mem::transmute::<
            vk::GraphicsPipelineCreateInfo<'_>,
            vk::GraphicsPipelineCreateInfo<'static>,
        >(*ci)
    }
}

/// One create info rewritten as `f` says, and what the copy owns; where its chain cannot be
/// copied, the shading-rate state goes in front of the application's chain (logged once).
///
/// # Safety
/// `ci` must be the application's valid create info; the copy lives across the call down only.
unsafe fn rewritten(
    ci: &vk::GraphicsPipelineCreateInfo<'_>,
    f: Facts,
) -> (vk::GraphicsPipelineCreateInfo<'static>, Owned) {
    // SAFETY: as the caller promised.
    let e = match unsafe { rewrite(ci, f) } {
        Ok(r) => return r,
        Err(e) => e,
    };
    // This pipeline alone falls back; the others in the batch are rewritten in full.
    once(
        &CHAIN_LOGGED,
        &format!(
            "cannot copy a graphics pipeline's pNext chain ({e:?}): that pipeline gets the \
             shading-rate state in front of its chain, its own chained flags and rate stay as given"
        ),
    );
    // SAFETY: as the caller promised; without a chain copy this cannot fail.
    match unsafe { rewrite_with(ci, f, false) } {
        Ok(r) => r,
        // SAFETY: as the caller promised.
        Err(_) => (unsafe { as_is(ci) }, Owned::default()),
    }
}

fn create_pipelines(
    c: Call<'_, Device, vk::PFN_vkCreateGraphicsPipelines, impl Fn() -> vk::Result>,
    device: vk::Device,
    cache: vk::PipelineCache,
    count: u32,
    infos: Arr<'_, vk::GraphicsPipelineCreateInfo<'_>>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Pipeline,
) -> vk::Result {
    let (dev, next) = (c.dev, c.next);
    let list = infos.slice();
    let facts = facts_of(dev, list);
    if (dev.fdm.is_none() && dev.injection.is_none()) || !facts.iter().any(Facts::rewrite) {
        return c.as_given();
    }
    let mut copies = Vec::with_capacity(list.len());
    let mut owned = Vec::with_capacity(list.len());
    for (ci, f) in list.iter().zip(&facts) {
        if !f.rewrite() {
            // SAFETY: the application's create info, alive across the call down.
            copies.push(unsafe { as_is(ci) });
            continue;
        }
        // SAFETY: as above; the copy lives across the call down.
        let (c, o) = unsafe { rewritten(ci, *f) };
        copies.push(c);
        owned.push(o);
    }
    tracing::debug!(
        count,
        rewritten = facts.iter().filter(|f| f.rewrite()).count(),
        "graphics pipelines get the shading-rate state"
    );
    // SAFETY: the next layer's function; the copies and what they own live across the call.
    let r = unsafe { next(device, cache, count, copies.as_ptr(), alloc, out) };
    drop(owned);
    r
}

hook! {
    /// `vkCmdSetFragmentShadingRateKHR` on an injecting device: the application's rate and
    /// `combinerOps[0]` go down as given, `combinerOps[1]` as [`attachment_combiner`] makes it, on
    /// a copy of the two combiners on the stack, so an injected map applies to pipelines with the
    /// dynamic shading-rate state too (docs/injection.md#apps-that-set-rates). Whether the device
    /// has non-trivial combiners was read at `vkCreateDevice`; nothing is looked up per call but
    /// the device.
    cmd_set_fragment_shading_rate = "vkCmdSetFragmentShadingRateKHR";
    on device_ref(cb), next cmd_set_fragment_shading_rate, fails(());
    set_rate(cb: val vk::CommandBuffer, size: in vk::Extent2D, ops: in [CombinerOp; 2]) -> ()
}

fn set_rate(
    c: Call<'_, Device, vk::PFN_vkCmdSetFragmentShadingRateKHR, impl Fn()>,
    cb: vk::CommandBuffer,
    size: In<'_, vk::Extent2D>,
    ops: In<'_, [CombinerOp; 2]>,
) {
    let retuned = match (&c.dev.injection, size.get(), ops.get()) {
        (Some(inj), Some(&s), Some(&o)) => {
            let op = attachment_combiner(inj.fdm.non_trivial_combiners, s, o);
            (op != o[1]).then_some([o[0], op])
        }
        _ => None,
    };
    match retuned {
        // SAFETY: the next layer's function; the copy of the combiners lives across the call.
        Some(copy) => unsafe { (c.next)(cb, size.raw(), &copy) },
        None => c.as_given(),
    }
}

hook! {
    /// `vkCreateShadersEXT` on an emulating device: create infos with the density-map flag go
    /// down as copies with [`shader_flags`] (the application's array is not written).
    create_shaders_ext = "vkCreateShadersEXT";
    on device(device), next create_shaders_ext, fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    create_shaders(
        device: val vk::Device,
        count: val u32,
        infos: (array count) vk::ShaderCreateInfoEXT<'_>,
        alloc: val *const vk::AllocationCallbacks<'_>,
        out: val *mut vk::ShaderEXT,
    ) -> vk::Result
}

fn create_shaders(
    c: Call<'_, Device, vk::PFN_vkCreateShadersEXT, impl Fn() -> vk::Result>,
    device: vk::Device,
    count: u32,
    infos: Arr<'_, vk::ShaderCreateInfoEXT<'_>>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::ShaderEXT,
) -> vk::Result {
    let list = infos.slice();
    if c.dev.fdm.is_none() || !list.iter().any(|ci| ci.flags.contains(SHADER_FDM)) {
        return c.as_given();
    }
    let copies: Vec<vk::ShaderCreateInfoEXT<'_>> = list
        .iter()
        .map(|ci| {
            let mut c = *ci;
            c.flags = shader_flags(ci.flags);
            c
        })
        .collect();
    // SAFETY: the next layer's function; the copies (pointing into the application's create
    // infos) live across the call.
    unsafe { (c.next)(device, count, copies.as_ptr(), alloc, out) }
}

static FRAG_SIZE_SAID: AtomicBool = AtomicBool::new(false);

hook! {
    /// `vkCreateShaderModule` on an emulating device: detects shaders that read the fragment size.
    create_shader_module = "vkCreateShaderModule";
    on device(device), next create_shader_module, fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    create_module(
        device: val vk::Device,
        info: in vk::ShaderModuleCreateInfo<'_>,
        alloc: val *const vk::AllocationCallbacks<'_>,
        out: val *mut vk::ShaderModule,
    ) -> vk::Result
}

fn create_module(
    c: Call<'_, Device, vk::PFN_vkCreateShaderModule, impl Fn() -> vk::Result>,
    _device: vk::Device,
    info: In<'_, vk::ShaderModuleCreateInfo<'_>>,
    _alloc: *const vk::AllocationCallbacks<'_>,
    _out: *mut vk::ShaderModule,
) -> vk::Result {
    if let (Some(_), Some(ci)) = (&c.dev.fdm, info.get()) {
        // SAFETY: the command's valid usage: `pCode` holds `codeSize` bytes of 4-byte-aligned
        // SPIR-V.
        let code = unsafe { slice(ci.p_code, (ci.code_size / 4) as u32) };
        if uses_fragment_density(code) {
            once(
                &FRAG_SIZE_SAID,
                "a shader uses FragSizeEXT or FragInvocationCountEXT (capability \
                 FragmentDensityEXT), which shading-rate attachments cannot emulate; it is \
                 passed on as is and the driver may refuse it",
            );
        }
    }
    c.as_given()
}

static SUBSAMPLED_SAID: AtomicBool = AtomicBool::new(false);

hook! {
    /// `vkCreateSampler` on an emulating device: the subsampled flags are left out of a copy.
    create_sampler = "vkCreateSampler";
    on device(device), next create_sampler, fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    sampler(
        device: val vk::Device,
        info: in vk::SamplerCreateInfo<'_>,
        alloc: val *const vk::AllocationCallbacks<'_>,
        out: val *mut vk::Sampler,
    ) -> vk::Result
}

fn sampler(
    c: Call<'_, Device, vk::PFN_vkCreateSampler, impl Fn() -> vk::Result>,
    device: vk::Device,
    info: In<'_, vk::SamplerCreateInfo<'_>>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Sampler,
) -> vk::Result {
    let subsampled = info.get().filter(|i| i.flags.intersects(SUBSAMPLED));
    let (Some(ci), Some(_)) = (subsampled, &c.dev.fdm) else {
        return c.as_given();
    };
    once(
        &SUBSAMPLED_SAID,
        "subsampled sampler flags left out: emulated density maps never subsample images",
    );
    let mut copy = *ci;
    copy.flags &= !SUBSAMPLED;
    // SAFETY: the next layer's function; the copy lives across the call.
    unsafe { (c.next)(device, &copy, alloc, out) }
}
