//! Render passes, framebuffers and dynamic rendering: the density-map attachment becomes a
//! shading-rate attachment that names the layer's shadow ([`crate::vk::image`]).
//!
//! - `vkCreateRenderPass` with a
//!   [`VkRenderPassFragmentDensityMapCreateInfoEXT`](https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderPassFragmentDensityMapCreateInfoEXT.html)
//!   is upgraded to `vkCreateRenderPass2` ([`v1_to_v2`]): shading-rate attachments exist only on
//!   [`VkSubpassDescription2`](https://registry.khronos.org/vulkan/specs/latest/man/html/VkSubpassDescription2.html).
//!   `VkRenderPassMultiviewCreateInfo` folds into the subpasses' view masks, the dependencies' view
//!   offsets and the correlated masks; `VkRenderPassInputAttachmentAspectCreateInfo` into the input
//!   references' aspect masks (docs/vulkan-fdm-on-fsr.md#render-passes).
//! - `vkCreateRenderPass2(KHR)` with the density-map struct: the struct is dropped, every subpass
//!   gets a [`VkFragmentShadingRateAttachmentInfoKHR`](https://registry.khronos.org/vulkan/specs/latest/man/html/VkFragmentShadingRateAttachmentInfoKHR.html)
//!   naming the density attachment with the device's texel, and that attachment's description
//!   becomes `R8_UINT`, loaded (never cleared), not stored (as density maps require too), in
//!   `FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR` before and after ([`add_shading_rate`]).
//!   Dependencies' density stage and access bits become the shading-rate ones.
//! - `vkCreateFramebuffer`: the density view is replaced by its shadow view; for an imageless
//!   framebuffer the density attachment's
//!   [`VkFramebufferAttachmentImageInfo`](https://registry.khronos.org/vulkan/specs/latest/man/html/VkFramebufferAttachmentImageInfo.html)
//!   describes the shadow (format, usage, flags, layers), and `vkCmdBeginRenderPass(2)` swaps the
//!   view in `VkRenderPassAttachmentBeginInfo`. The shadow has the density image's extent, and
//!   both extensions ask the same of it: at least `ceil(framebuffer size / texel)` texels, with
//!   the density texel fixed to the shading-rate one (docs/vulkan-fdm-on-fsr.md#texel-size).
//! - `vkCmdBeginRendering(KHR)` with
//!   [`VkRenderingFragmentDensityMapAttachmentInfoEXT`](https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderingFragmentDensityMapAttachmentInfoEXT.html)
//!   gets a [`VkRenderingFragmentShadingRateAttachmentInfoKHR`](https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderingFragmentShadingRateAttachmentInfoKHR.html)
//!   with the shadow view instead.
//!
//! - On an emulating device, a pass without the density-map struct that names the density layout
//!   (an attachment's initial or final layout, a reference's), stage or access (a dependency's, or
//!   a `VkMemoryBarrier2` chained to one) goes down translated ([`Pass2::without_density_enums`]):
//!   such a pass writes a density map (its colour attachment ends in the density layout, as the
//!   Khronos sample's fragment path does) or orders one, and the driver never has the extension
//!   those values belong to. A map written so is the application's; the pass that reads it
//!   converts it (`crate::vk::convert`).
//!
//! Everything is rewritten in copies; the application's structs are never written. Other passes,
//! and begin infos without views to swap, go down untouched (a begin with an empty `pNext` costs
//! one null test). Fail open, never with density enums: where a struct of unknown size stands
//! before the density-map struct, it is left out of the driver's copy with the struct
//! ([`chain_without`]); where a view has no shadow the pass renders at full rate; one log line
//! says so.

use std::ffi::c_void;

use ash::vk;
use ash::vk::Handle as _;

use crate::vk::base::chain::{self, ChainCopy, ChainError};
use crate::vk::base::ffi::{guard, raw, slice};
use crate::vk::image::{SHADOW_FORMAT, SHADOW_LAYOUT, SHADOW_USAGE};
use crate::vk::registry::{self, Device};

/// A version-2 render pass the layer builds, owning every array its pointers reach (apart from
/// what it shares with the application's create info: preserve lists and `pNext` chains).
pub struct Pass2 {
    pub attachments: Vec<vk::AttachmentDescription2<'static>>,
    pub subpasses: Vec<vk::SubpassDescription2<'static>>,
    pub dependencies: Vec<vk::SubpassDependency2<'static>>,
    pub correlated: Vec<u32>,
    /// Reference arrays of converted subpasses, kept alive for the pointers into them; each inner
    /// vector is final once pointed at.
    _refs: Vec<Vec<vk::AttachmentReference2<'static>>>,
    /// The shading-rate reference and one info per subpass ([`add_shading_rate`]).
    rate_ref: Box<vk::AttachmentReference2<'static>>,
    rate_infos: Vec<vk::FragmentShadingRateAttachmentInfoKHR<'static>>,
    /// Subpass chains copied without the application's attachment-less shading-rate infos
    /// ([`Pass2::without_apps_rate_infos`]), kept alive for the subpasses pointing into them.
    _subpass_chains: Vec<ChainCopy>,
    /// Dependency chains copied without the application's `VkMemoryBarrier2`, and the translated
    /// barriers put in front of them ([`Pass2::without_density_enums`]).
    _dependency_chains: Vec<ChainCopy>,
    /// Boxed: the dependencies point at them, and a growing vector would move them.
    #[allow(clippy::vec_box)]
    _barriers: Vec<Box<vk::MemoryBarrier2<'static>>>,
}

impl Pass2 {
    /// The create info for this pass, with `flags` and `p_next` (which must outlive its use).
    pub fn info(
        &self,
        flags: vk::RenderPassCreateFlags,
        p_next: *const c_void,
    ) -> vk::RenderPassCreateInfo2<'_> {
        vk::RenderPassCreateInfo2 {
            p_next,
            flags,
            attachment_count: self.attachments.len() as u32,
            p_attachments: self.attachments.as_ptr(),
            subpass_count: self.subpasses.len() as u32,
            p_subpasses: self.subpasses.as_ptr(),
            dependency_count: self.dependencies.len() as u32,
            p_dependencies: self.dependencies.as_ptr(),
            correlated_view_mask_count: self.correlated.len() as u32,
            p_correlated_view_masks: self.correlated.as_ptr(),
            ..Default::default()
        }
    }

    /// A copy of a version-2 create info's arrays (the subpasses shallow).
    ///
    /// # Safety
    /// `ci` must be a valid create info whose arrays outlive the result.
    pub unsafe fn from_v2(ci: &vk::RenderPassCreateInfo2<'_>) -> Pass2 {
        // SAFETY: as the caller promised; the copies keep pointing at the application's arrays.
        unsafe {
            let cast = |a: &[vk::AttachmentDescription2<'_>]| {
                a.iter()
                    .map(|x| std::mem::transmute::<_, vk::AttachmentDescription2<'static>>(*x))
                    .collect()
            };
            Pass2 {
                attachments: cast(slice(ci.p_attachments, ci.attachment_count)),
                subpasses: slice(ci.p_subpasses, ci.subpass_count)
                    .iter()
                    .map(|x| std::mem::transmute::<_, vk::SubpassDescription2<'static>>(*x))
                    .collect(),
                dependencies: slice(ci.p_dependencies, ci.dependency_count)
                    .iter()
                    .map(|x| std::mem::transmute::<_, vk::SubpassDependency2<'static>>(*x))
                    .collect(),
                correlated: slice(ci.p_correlated_view_masks, ci.correlated_view_mask_count)
                    .to_vec(),
                _refs: Vec::new(),
                rate_ref: Box::default(),
                rate_infos: Vec::new(),
                _subpass_chains: Vec::new(),
                _dependency_chains: Vec::new(),
                _barriers: Vec::new(),
            }
        }
    }

    /// Leaves the application's `VkFragmentShadingRateAttachmentInfoKHR`s (those naming no
    /// attachment, [`apps_rate_attachment`]) out of copies of the subpasses' chains, so that the
    /// one [`add_shading_rate`] puts in front is the only one in each
    /// (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#fundamentals-validusage-pNext>).
    ///
    /// # Safety
    /// The subpasses' chains must be valid and outlive `self`.
    pub unsafe fn without_apps_rate_infos(&mut self) -> Result<(), ChainError> {
        let ty = vk::StructureType::FRAGMENT_SHADING_RATE_ATTACHMENT_INFO_KHR;
        for s in &mut self.subpasses {
            // SAFETY: as the caller promised.
            if unsafe { chain::find::<u8>(s.p_next, ty)? }.is_none() {
                continue;
            }
            // SAFETY: as above.
            let copy = unsafe { ChainCopy::without(s.p_next, |t| t == ty)? };
            s.p_next = copy.head();
            self._subpass_chains.push(copy);
        }
        Ok(())
    }
}

impl Pass2 {
    /// Every density-map layout, stage and access bit of the pass becomes what the driver knows
    /// (docs/vulkan-fdm-on-fsr.md#mapping): layouts of attachments and references the one
    /// `crate::vk::barrier` gives the application's density images (`GENERAL`), stages and
    /// accesses of dependencies (and of a `VkMemoryBarrier2` chained to one) the shading-rate
    /// ones. The driver never has the density-map extension enabled, so these are invalid values
    /// for it; a pass that names them without the density-map struct (one that writes a map, or
    /// orders it for a later pass) is otherwise left as it is. References are copied where they
    /// change; the application's arrays are never written.
    ///
    /// # Safety
    /// The subpasses' reference arrays and the dependencies' chains must be valid and outlive
    /// `self`.
    pub unsafe fn without_density_enums(&mut self) {
        use crate::vk::barrier;
        for a in &mut self.attachments {
            a.initial_layout = barrier::layout(a.initial_layout);
            a.final_layout = barrier::layout(a.final_layout);
        }
        let fdm = vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT;
        let refs = &mut self._refs;
        let mut fix = |p: *const vk::AttachmentReference2<'static>, n: u32| {
            // SAFETY: as the caller promised.
            let old = unsafe { slice(p, n) };
            if !old.iter().any(|r| r.layout == fdm) {
                return p;
            }
            let v: Vec<vk::AttachmentReference2<'static>> = old
                .iter()
                .map(|r| {
                    let mut r = *r;
                    r.layout = barrier::layout(r.layout);
                    r
                })
                .collect();
            let ptr = v.as_ptr();
            refs.push(v);
            ptr
        };
        for s in &mut self.subpasses {
            s.p_input_attachments = fix(s.p_input_attachments, s.input_attachment_count);
            s.p_color_attachments = fix(s.p_color_attachments, s.color_attachment_count);
            s.p_resolve_attachments = fix(s.p_resolve_attachments, s.color_attachment_count);
            s.p_depth_stencil_attachment = fix(s.p_depth_stencil_attachment, 1);
        }
        let ty = vk::StructureType::MEMORY_BARRIER_2;
        for d in &mut self.dependencies {
            d.src_stage_mask = barrier::stage(d.src_stage_mask);
            d.dst_stage_mask = barrier::stage(d.dst_stage_mask);
            d.src_access_mask = barrier::access(d.src_access_mask);
            d.dst_access_mask = barrier::access(d.dst_access_mask);
            // SAFETY: as the caller promised; found by its sType, read only.
            let found = unsafe { chain::find::<vk::MemoryBarrier2<'static>>(d.p_next, ty) };
            let Some(m) = found.ok().flatten() else {
                continue;
            };
            // SAFETY: found by its sType in a valid chain.
            let m = unsafe { *m };
            let mut t = m;
            t.src_stage_mask = barrier::stage2(m.src_stage_mask);
            t.dst_stage_mask = barrier::stage2(m.dst_stage_mask);
            t.src_access_mask = barrier::access2(m.src_access_mask);
            t.dst_access_mask = barrier::access2(m.dst_access_mask);
            if (
                t.src_stage_mask,
                t.dst_stage_mask,
                t.src_access_mask,
                t.dst_access_mask,
            ) == (
                m.src_stage_mask,
                m.dst_stage_mask,
                m.src_access_mask,
                m.dst_access_mask,
            ) {
                continue;
            }
            // SAFETY: as the caller promised.
            let rest = unsafe { chain_without(d.p_next, |s| s == ty, "VkSubpassDependency2") };
            let Ok(rest) = rest else {
                // Only the translated barrier goes down: it is what the dependency orders.
                t.p_next = std::ptr::null();
                let b = Box::new(t);
                d.p_next = &*b as *const vk::MemoryBarrier2<'static> as *const c_void;
                self._barriers.push(b);
                continue;
            };
            t.p_next = rest.head();
            let b = Box::new(t);
            d.p_next = &*b as *const vk::MemoryBarrier2<'static> as *const c_void;
            self._barriers.push(b);
            self._dependency_chains.push(rest);
        }
    }
}

/// Whether a version-1 create info names a density-map layout, stage or access bit outside the
/// density-map struct (see [`Pass2::without_density_enums`]).
///
/// # Safety
/// `ci` must be a valid create info.
unsafe fn v1_names_density(ci: &vk::RenderPassCreateInfo<'_>) -> bool {
    let fdm = vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT;
    // SAFETY: as the caller promised.
    unsafe {
        slice(ci.p_attachments, ci.attachment_count)
            .iter()
            .any(|a| a.initial_layout == fdm || a.final_layout == fdm)
            || slice(ci.p_subpasses, ci.subpass_count).iter().any(|s| {
                [
                    slice(s.p_input_attachments, s.input_attachment_count),
                    slice(s.p_color_attachments, s.color_attachment_count),
                    slice(s.p_resolve_attachments, s.color_attachment_count),
                    slice(s.p_depth_stencil_attachment, 1),
                ]
                .iter()
                .any(|refs| refs.iter().any(|r| r.layout == fdm))
            })
            || slice(ci.p_dependencies, ci.dependency_count)
                .iter()
                .any(|d| {
                    density_bits(
                        d.src_stage_mask | d.dst_stage_mask,
                        d.src_access_mask | d.dst_access_mask,
                    )
                })
    }
}

/// [`v1_names_density`] for version 2 (dependencies' chained `VkMemoryBarrier2`s included).
///
/// # Safety
/// `ci` must be a valid create info.
unsafe fn v2_names_density(ci: &vk::RenderPassCreateInfo2<'_>) -> bool {
    let fdm = vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT;
    let ty = vk::StructureType::MEMORY_BARRIER_2;
    // SAFETY: as the caller promised.
    unsafe {
        slice(ci.p_attachments, ci.attachment_count)
            .iter()
            .any(|a| a.initial_layout == fdm || a.final_layout == fdm)
            || slice(ci.p_subpasses, ci.subpass_count).iter().any(|s| {
                [
                    slice(s.p_input_attachments, s.input_attachment_count),
                    slice(s.p_color_attachments, s.color_attachment_count),
                    slice(s.p_resolve_attachments, s.color_attachment_count),
                    slice(s.p_depth_stencil_attachment, 1),
                ]
                .iter()
                .any(|refs| refs.iter().any(|r| r.layout == fdm))
            })
            || slice(ci.p_dependencies, ci.dependency_count)
                .iter()
                .any(|d| {
                    density_bits(
                        d.src_stage_mask | d.dst_stage_mask,
                        d.src_access_mask | d.dst_access_mask,
                    ) || chain::find::<vk::MemoryBarrier2<'_>>(d.p_next, ty)
                        .ok()
                        .flatten()
                        .is_some_and(|m| {
                            let m = &*m;
                            crate::vk::barrier::stage2(m.src_stage_mask | m.dst_stage_mask)
                                != (m.src_stage_mask | m.dst_stage_mask)
                                || crate::vk::barrier::access2(
                                    m.src_access_mask | m.dst_access_mask,
                                ) != (m.src_access_mask | m.dst_access_mask)
                        })
                })
    }
}

fn density_bits(stages: vk::PipelineStageFlags, access: vk::AccessFlags) -> bool {
    stages.intersects(vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT)
        || access.intersects(vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT)
}

/// [`ChainCopy::without`] that never gives up: a struct of a size the layer does not know that
/// stands before one to remove is left out too (one log line names it). The driver gets no
/// density-map struct, which it does not know, at the price of a struct the layer cannot copy;
/// passing the chain down as it came would hand the driver enums of an extension it never
/// enabled. Past [`chain::MAX_CHAIN_LENGTH`] structs the rest is shared as it is.
///
/// # Safety
/// `next` must be NULL or a valid chain.
unsafe fn chain_without(
    next: *const c_void,
    remove: impl Fn(vk::StructureType) -> bool,
    which: &str,
) -> Result<ChainCopy, ChainError> {
    let mut dropped: Vec<vk::StructureType> = Vec::new();
    loop {
        // SAFETY: as the caller promised.
        match unsafe { ChainCopy::without(next, |t| remove(t) || dropped.contains(&t)) } {
            Ok(c) => {
                if !dropped.is_empty() {
                    tracing::warn!(
                        which,
                        dropped = ?dropped,
                        "structs of a size the layer does not know stand before a density-map \
                         struct it must remove: they are left out of the driver's copy"
                    );
                }
                return Ok(c);
            }
            Err(ChainError::Unknown(t)) if !dropped.contains(&t) => dropped.push(t),
            Err(e) => return Err(e),
        }
    }
}

/// The aspects an input attachment of `format` reads where version 1 names none: all of the
/// format's (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderPassInputAttachmentAspectCreateInfo.html>).
fn format_aspects(format: vk::Format) -> vk::ImageAspectFlags {
    use vk::Format as F;
    match format {
        F::D16_UNORM | F::X8_D24_UNORM_PACK32 | F::D32_SFLOAT => vk::ImageAspectFlags::DEPTH,
        F::S8_UINT => vk::ImageAspectFlags::STENCIL,
        F::D16_UNORM_S8_UINT | F::D24_UNORM_S8_UINT | F::D32_SFLOAT_S8_UINT => {
            vk::ImageAspectFlags::DEPTH | vk::ImageAspectFlags::STENCIL
        }
        _ => vk::ImageAspectFlags::COLOR,
    }
}

/// Converts a version-1 render pass to version 2, folding in its multiview and input-aspect
/// structs. The result's `pNext` chains are the caller's to choose (the subpasses' and
/// dependencies' are NULL; version 1 has none).
///
/// # Safety
/// `ci` and the structs must be valid; their arrays must outlive the result.
pub unsafe fn v1_to_v2(
    ci: &vk::RenderPassCreateInfo<'_>,
    multiview: Option<&vk::RenderPassMultiviewCreateInfo<'_>>,
    aspects: Option<&vk::RenderPassInputAttachmentAspectCreateInfo<'_>>,
) -> Pass2 {
    // SAFETY: as the caller promised.
    let (attachments_in, subpasses_in, deps_in) = unsafe {
        (
            slice(ci.p_attachments, ci.attachment_count),
            slice(ci.p_subpasses, ci.subpass_count),
            slice(ci.p_dependencies, ci.dependency_count),
        )
    };
    // SAFETY: as the caller promised.
    let (view_masks, view_offsets, correlated, aspect_refs) = unsafe {
        (
            multiview.map_or(&[][..], |m| slice(m.p_view_masks, m.subpass_count)),
            multiview.map_or(&[][..], |m| slice(m.p_view_offsets, m.dependency_count)),
            multiview.map_or(&[][..], |m| {
                slice(m.p_correlation_masks, m.correlation_mask_count)
            }),
            aspects.map_or(&[][..], |a| {
                slice(a.p_aspect_references, a.aspect_reference_count)
            }),
        )
    };
    let attachments: Vec<vk::AttachmentDescription2<'static>> = attachments_in
        .iter()
        .map(|a| {
            vk::AttachmentDescription2::default()
                .flags(a.flags)
                .format(a.format)
                .samples(a.samples)
                .load_op(a.load_op)
                .store_op(a.store_op)
                .stencil_load_op(a.stencil_load_op)
                .stencil_store_op(a.stencil_store_op)
                .initial_layout(a.initial_layout)
                .final_layout(a.final_layout)
        })
        .collect();
    let mut refs: Vec<Vec<vk::AttachmentReference2<'static>>> = Vec::new();
    let mut subpasses = Vec::with_capacity(subpasses_in.len());
    for (i, s) in subpasses_in.iter().enumerate() {
        let mut convert = |p: *const vk::AttachmentReference, n: u32, input: bool| {
            if p.is_null() {
                return std::ptr::null();
            }
            // SAFETY: as the caller promised.
            let v: Vec<vk::AttachmentReference2<'static>> = unsafe { slice(p, n) }
                .iter()
                .enumerate()
                .map(|(j, r)| {
                    let aspect = if !input || r.attachment == vk::ATTACHMENT_UNUSED {
                        vk::ImageAspectFlags::empty()
                    } else {
                        aspect_refs
                            .iter()
                            .find(|a| {
                                a.subpass as usize == i && a.input_attachment_index as usize == j
                            })
                            .map(|a| a.aspect_mask)
                            .unwrap_or_else(|| {
                                attachments
                                    .get(r.attachment as usize)
                                    .map_or(vk::ImageAspectFlags::COLOR, |a| {
                                        format_aspects(a.format)
                                    })
                            })
                    };
                    vk::AttachmentReference2::default()
                        .attachment(r.attachment)
                        .layout(r.layout)
                        .aspect_mask(aspect)
                })
                .collect();
            let ptr = v.as_ptr();
            refs.push(v);
            ptr
        };
        subpasses.push(vk::SubpassDescription2 {
            flags: s.flags,
            pipeline_bind_point: s.pipeline_bind_point,
            view_mask: view_masks.get(i).copied().unwrap_or(0),
            input_attachment_count: s.input_attachment_count,
            p_input_attachments: convert(s.p_input_attachments, s.input_attachment_count, true),
            color_attachment_count: s.color_attachment_count,
            p_color_attachments: convert(s.p_color_attachments, s.color_attachment_count, false),
            p_resolve_attachments: convert(
                s.p_resolve_attachments,
                s.color_attachment_count,
                false,
            ),
            p_depth_stencil_attachment: convert(s.p_depth_stencil_attachment, 1, false),
            preserve_attachment_count: s.preserve_attachment_count,
            p_preserve_attachments: s.p_preserve_attachments,
            ..Default::default()
        });
    }
    let dependencies = deps_in
        .iter()
        .enumerate()
        .map(|(i, d)| {
            vk::SubpassDependency2::default()
                .src_subpass(d.src_subpass)
                .dst_subpass(d.dst_subpass)
                .src_stage_mask(d.src_stage_mask)
                .dst_stage_mask(d.dst_stage_mask)
                .src_access_mask(d.src_access_mask)
                .dst_access_mask(d.dst_access_mask)
                .dependency_flags(d.dependency_flags)
                .view_offset(view_offsets.get(i).copied().unwrap_or(0))
        })
        .collect();
    Pass2 {
        attachments,
        subpasses,
        dependencies,
        correlated: correlated.to_vec(),
        _refs: refs,
        rate_ref: Box::default(),
        rate_infos: Vec::new(),
        _subpass_chains: Vec::new(),
        _dependency_chains: Vec::new(),
        _barriers: Vec::new(),
    }
}

/// How a shading-rate attachment that later passes read again is stored: with `DONT_CARE` its
/// contents are undefined after every pass
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkAttachmentStoreOp.html>), so the
/// next pass would shade with whatever the driver left there. `NONE` keeps them without a write
/// and is core from Vulkan 1.3; below that, `STORE` (the layer enables no
/// `VK_*_load_store_op_none` of its own).
pub fn rate_store_op(dev: &Device) -> vk::AttachmentStoreOp {
    if dev.api_version >= vk::API_VERSION_1_3 {
        vk::AttachmentStoreOp::NONE
    } else {
        vk::AttachmentStoreOp::STORE
    }
}

/// Makes attachment `density` the shading-rate attachment of every subpass, at `texel`, stored
/// with `store` ([`rate_store_op`]).
pub fn add_shading_rate(
    pass: &mut Pass2,
    density: u32,
    texel: vk::Extent2D,
    store: vk::AttachmentStoreOp,
) {
    if let Some(a) = pass.attachments.get_mut(density as usize) {
        a.format = SHADOW_FORMAT;
        a.samples = vk::SampleCountFlags::TYPE_1;
        // The shadow's content is the point: loaded, never cleared
        // (VUID-VkRenderPassCreateInfo2-pAttachments-09387), and kept for the passes after.
        a.load_op = vk::AttachmentLoadOp::LOAD;
        a.store_op = store;
        a.stencil_load_op = vk::AttachmentLoadOp::DONT_CARE;
        a.stencil_store_op = vk::AttachmentStoreOp::DONT_CARE;
        a.initial_layout = SHADOW_LAYOUT;
        a.final_layout = SHADOW_LAYOUT;
    }
    *pass.rate_ref = vk::AttachmentReference2::default()
        .attachment(density)
        .layout(SHADOW_LAYOUT);
    let rate_ref: *const vk::AttachmentReference2<'static> = &*pass.rate_ref;
    pass.rate_infos = pass
        .subpasses
        .iter()
        .map(|s| {
            let mut f = vk::FragmentShadingRateAttachmentInfoKHR::default()
                .shading_rate_attachment_texel_size(texel);
            f.p_fragment_shading_rate_attachment = rate_ref;
            f.p_next = s.p_next;
            f
        })
        .collect();
    for (s, f) in pass.subpasses.iter_mut().zip(&pass.rate_infos) {
        s.p_next = f as *const _ as *const c_void;
    }
}

fn texel_of(dev: &Device) -> Option<vk::Extent2D> {
    dev.fdm.as_ref().map(|f| vk::Extent2D {
        width: f.texel[0],
        height: f.texel[1],
    })
}

/// The density attachment of a create info's chain, if it has the density-map struct.
///
/// # Safety
/// `p_next` must be a valid chain.
unsafe fn density_attachment(p_next: *const c_void) -> Option<u32> {
    // SAFETY: as the caller promised.
    let f = unsafe {
        chain::find::<vk::RenderPassFragmentDensityMapCreateInfoEXT>(
            p_next,
            vk::StructureType::RENDER_PASS_FRAGMENT_DENSITY_MAP_CREATE_INFO_EXT,
        )
    }
    .ok()
    .flatten()?;
    // SAFETY: found by its sType.
    Some(unsafe { (*f).fragment_density_map_attachment.attachment })
}

/// Creates `pass` below, with the shading-rate attachment where `density` names one; on success
/// records the pass as rewritten.
///
/// # Safety
/// `pass` and `p_next` must be valid and outlive the call; the rest are the caller's arguments.
#[allow(clippy::too_many_arguments)]
unsafe fn create_rewritten(
    dev: &Device,
    create2: vk::PFN_vkCreateRenderPass2,
    mut pass: Pass2,
    flags: vk::RenderPassCreateFlags,
    p_next: *const c_void,
    density: u32,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::RenderPass,
) -> vk::Result {
    // Whether the application names the map in the density layout itself when the pass begins
    // (before the translation makes it `GENERAL`): `crate::vk::convert` relies on it.
    let density_initial = pass
        .attachments
        .get(density as usize)
        .is_some_and(|a| a.initial_layout == vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT);
    if dev.fdm.is_some() {
        // SAFETY: as the caller promised.
        unsafe { pass.without_density_enums() };
    }
    if let Some(inj) = &dev.inject {
        // SAFETY: as the caller promised.
        return unsafe { create_injected(dev, inj, create2, pass, flags, p_next, alloc, out) };
    }
    let texel = texel_of(dev);
    let layouts = pass
        .attachments
        .get(density as usize)
        .map(|a| (a.initial_layout, a.final_layout, density_initial));
    if let (Some(texel), true) = (texel, density != vk::ATTACHMENT_UNUSED) {
        add_shading_rate(&mut pass, density, texel, rate_store_op(dev));
    }
    let info = pass.info(flags, p_next);
    // SAFETY: the copy and everything it points at live across the call.
    let r = unsafe { create2(dev.handle, &info, alloc, out) };
    if r == vk::Result::SUCCESS && density == vk::ATTACHMENT_UNUSED {
        // A pass that names the density layout, stage or access but reads no map writes or
        // orders one.
        // SAFETY: just created.
        crate::vk::convert::writer_pass_created(unsafe { *out });
    }
    if r == vk::Result::SUCCESS && density != vk::ATTACHMENT_UNUSED && texel.is_some() {
        // SAFETY: just created.
        let handle = unsafe { *out };
        dev.attachments
            .passes
            .lock()
            .insert(handle.as_raw(), density);
        // SAFETY: the device is live.
        unsafe { crate::vk::convert::pass_changed(dev, handle, layouts) };
        tracing::debug!(
            render_pass = raw(handle),
            density,
            "render pass: density map → shading-rate attachment"
        );
    }
    r
}

/// On an injecting device (docs/injection.md#how-the-attachment-gets-in): creates `pass` below with
/// a shading-rate attachment added after the application's, named by every subpass; whether a
/// framebuffer's pass is an eye pass is not known yet, and compatibility of render passes would
/// not let a framebuffer or pipeline made for one pass serve the other
/// (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#renderpass-compatibility>).
/// Where the driver refuses the rewritten pass, the application's goes down as it came (fail
/// open: its framebuffers are then left alone).
///
/// # Safety
/// As [`create_rewritten`].
#[allow(clippy::too_many_arguments)]
unsafe fn create_injected(
    dev: &Device,
    inj: &crate::vk::inject::Injector,
    create2: vk::PFN_vkCreateRenderPass2,
    mut pass: Pass2,
    flags: vk::RenderPassCreateFlags,
    p_next: *const c_void,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::RenderPass,
) -> vk::Result {
    let (first, view_mask) = match pass.subpasses.first() {
        Some(s) => (
            // SAFETY: the application's array, as the caller promised, alive across the call.
            unsafe { slice(s.p_color_attachments, s.color_attachment_count) }
                .first()
                .map(|r| r.attachment)
                .filter(|&a| a != vk::ATTACHMENT_UNUSED),
            s.view_mask,
        ),
        None => (None, 0),
    };
    // SAFETY: the application's subpass chains, alive across the call, as the caller promised.
    if let Err(e) = unsafe { pass.without_apps_rate_infos() } {
        tracing::warn!(
            error = ?e,
            "a subpass pNext chain the layer cannot copy; the render pass is created as it came, \
             at full rate"
        );
        let info = pass.info(flags, p_next);
        // SAFETY: the application's pass, its arrays alive across the call.
        return unsafe { create2(dev.handle, &info, alloc, out) };
    }
    let rate = pass.attachments.len() as u32;
    pass.attachments.push(vk::AttachmentDescription2::default());
    add_shading_rate(&mut pass, rate, inj.texel(), rate_store_op(dev));
    let info = pass.info(flags, p_next);
    // SAFETY: the copy and everything it points at live across the call.
    let r = unsafe { create2(dev.handle, &info, alloc, out) };
    if !matches!(
        r,
        vk::Result::SUCCESS
            | vk::Result::ERROR_OUT_OF_HOST_MEMORY
            | vk::Result::ERROR_OUT_OF_DEVICE_MEMORY
    ) {
        tracing::warn!(
            result = ?r,
            "a render pass with an injected shading-rate attachment was refused; the \
             application's pass is created as it came, at full rate"
        );
        // The application's pass: its attachments and its subpasses' own chains.
        pass.attachments.pop();
        for (s, f) in pass.subpasses.iter_mut().zip(&pass.rate_infos) {
            s.p_next = f.p_next;
        }
        let info = pass.info(flags, p_next);
        // SAFETY: as above.
        return unsafe { create2(dev.handle, &info, alloc, out) };
    }
    if r == vk::Result::SUCCESS {
        // SAFETY: just created.
        let handle = unsafe { *out };
        inj.pass_created(
            handle,
            crate::vk::inject::InjectedPass {
                rate,
                colour: first,
                view_mask,
            },
        );
        tracing::debug!(
            render_pass = raw(handle),
            rate,
            "render pass: a shading-rate attachment added for injection"
        );
    }
    r
}

/// Whether a subpass of `ci` names a shading-rate attachment of the application's own (a
/// `VkFragmentShadingRateAttachmentInfoKHR` whose reference is not `VK_ATTACHMENT_UNUSED`): such
/// a pass is the application's to shade, and is created as it came
/// (docs/injection.md#switching-it-on). `Ok(false)` also where a subpass chains the struct with no
/// attachment: the injected info then takes its place ([`without_apps_rate_infos`]).
///
/// # Safety
/// `ci` must be a valid create info.
unsafe fn apps_rate_attachment(ci: &vk::RenderPassCreateInfo2<'_>) -> Result<bool, ChainError> {
    let ty = vk::StructureType::FRAGMENT_SHADING_RATE_ATTACHMENT_INFO_KHR;
    // SAFETY: as the caller promised.
    for s in unsafe { slice(ci.p_subpasses, ci.subpass_count) } {
        let found =
            // SAFETY: as above; found by its sType, read only.
            unsafe { chain::find::<vk::FragmentShadingRateAttachmentInfoKHR<'_>>(s.p_next, ty)? };
        // SAFETY: as above; the reference, where there is one, is the application's.
        let used = found.is_some_and(|f| unsafe {
            (*f).p_fragment_shading_rate_attachment
                .as_ref()
                .is_some_and(|r| r.attachment != vk::ATTACHMENT_UNUSED)
        });
        if used {
            return Ok(true);
        }
    }
    Ok(false)
}

/// `vkCreateRenderPass`: with the density-map struct, upgraded to `vkCreateRenderPass2` and
/// rewritten; on an injecting device every pass is (see [`create_injected`]); otherwise untouched.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn create_render_pass(
    device: vk::Device,
    info: *const vk::RenderPassCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::RenderPass,
) -> vk::Result {
    guard(
        "vkCreateRenderPass",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let Some(dev) = (unsafe { registry::device(device) }) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let Some(next) = dev.next.create_render_pass else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            // SAFETY: the caller's create info, read only.
            let density = match unsafe { info.as_ref() } {
                // SAFETY: the caller's valid chain.
                Some(ci) if dev.fdm.is_some() => unsafe { density_attachment(ci.p_next) },
                _ => None,
            };
            let inject = dev.inject.is_some() && !info.is_null();
            // A pass without the density-map struct that still names the density layout, stage
            // or access (it writes a map, or orders one) goes down translated.
            // SAFETY: the caller's create info, read only.
            let ci = unsafe { info.as_ref() };
            // SAFETY: as above.
            let names = dev.fdm.is_some() && ci.is_some_and(|ci| unsafe { v1_names_density(ci) });
            let Some(density) = density.or((inject || names).then_some(vk::ATTACHMENT_UNUSED))
            else {
                // SAFETY: the next layer's function, with the caller's arguments.
                return unsafe { next(device, info, alloc, out) };
            };
            // Below Vulkan 1.2 the core name may not be called (drivers return no pointer for
            // it); the extension's, which the layer enabled, is the one.
            let (first, second) = (
                dev.next.create_render_pass2,
                dev.next.create_render_pass2_khr,
            );
            let create2 = if dev.api_version < vk::API_VERSION_1_2 {
                second.or(first)
            } else {
                first.or(second)
            };
            // SAFETY: as above.
            let ci = unsafe { &*info };
            use vk::StructureType as S;
            let folded = |t| {
                t == S::RENDER_PASS_FRAGMENT_DENSITY_MAP_CREATE_INFO_EXT
                    || t == S::RENDER_PASS_MULTIVIEW_CREATE_INFO
                    || t == S::RENDER_PASS_INPUT_ATTACHMENT_ASPECT_CREATE_INFO
            };
            // SAFETY: the caller's chain, read only.
            let (chain, multiview, aspects) = unsafe {
                (
                    chain_without(ci.p_next, folded, "vkCreateRenderPass"),
                    chain::find::<vk::RenderPassMultiviewCreateInfo>(
                        ci.p_next,
                        S::RENDER_PASS_MULTIVIEW_CREATE_INFO,
                    ),
                    chain::find::<vk::RenderPassInputAttachmentAspectCreateInfo>(
                        ci.p_next,
                        S::RENDER_PASS_INPUT_ATTACHMENT_ASPECT_CREATE_INFO,
                    ),
                )
            };
            // A chain too long to look through to its end has neither struct where the layer
            // looks; the copy shares what lies past its limit.
            let (multiview, aspects) = (multiview.ok().flatten(), aspects.ok().flatten());
            let (Some(create2), Ok(chain)) = (create2, chain) else {
                // Every emulating device has render pass 2 (the layer enables it), so this is an
                // injecting one: no density enums are valid on it anyway.
                tracing::warn!(
                    inject,
                    "vkCreateRenderPass: cannot upgrade a render pass to version 2 (no \
                     vkCreateRenderPass2 below, or a pNext chain the layer cannot copy); passed \
                     on as is, at full rate"
                );
                if dev.fdm.is_some() {
                    // A driver without the density-map extension must not get its enums; an
                    // unexpected failure is what any command may answer with VK_ERROR_UNKNOWN
                    // (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkResult.html>).
                    return vk::Result::ERROR_UNKNOWN;
                }
                // SAFETY: the next layer's function, with the caller's arguments.
                return unsafe { next(device, info, alloc, out) };
            };
            // SAFETY: the structs were found by their sTypes in the caller's valid chain.
            let pass = unsafe { v1_to_v2(ci, multiview.map(|m| &*m), aspects.map(|a| &*a)) };
            // SAFETY: the converted pass and the chain copy live across the call.
            unsafe {
                create_rewritten(
                    &dev,
                    create2,
                    pass,
                    ci.flags,
                    chain.head(),
                    density,
                    alloc,
                    out,
                )
            }
        },
    )
}

/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn create_render_pass2_with(
    which: &'static str,
    next: fn(&Device) -> Option<vk::PFN_vkCreateRenderPass2>,
    device: vk::Device,
    info: *const vk::RenderPassCreateInfo2<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::RenderPass,
) -> vk::Result {
    guard(which, vk::Result::ERROR_INITIALIZATION_FAILED, || {
        // SAFETY: as the caller promised.
        let Some(dev) = (unsafe { registry::device(device) }) else {
            return vk::Result::ERROR_INITIALIZATION_FAILED;
        };
        let Some(create2) = next(&dev) else {
            return vk::Result::ERROR_INITIALIZATION_FAILED;
        };
        // SAFETY: the caller's create info, read only.
        let density = match unsafe { info.as_ref() } {
            // SAFETY: the caller's valid chain.
            Some(ci) if dev.fdm.is_some() => unsafe { density_attachment(ci.p_next) },
            _ => None,
        };
        let inject = dev.inject.is_some() && !info.is_null();
        // As in `create_render_pass`: density enums outside the density-map struct.
        // SAFETY: the caller's create info, read only.
        let ci = unsafe { info.as_ref() };
        // SAFETY: as above.
        let names = dev.fdm.is_some() && ci.is_some_and(|ci| unsafe { v2_names_density(ci) });
        let Some(density) = density.or((inject || names).then_some(vk::ATTACHMENT_UNUSED)) else {
            // SAFETY: the next layer's function, with the caller's arguments.
            return unsafe { create2(device, info, alloc, out) };
        };
        // SAFETY: as above.
        let ci = unsafe { &*info };
        if let (Some(inj), vk::ATTACHMENT_UNUSED) = (&dev.inject, density) {
            // SAFETY: the caller's subpasses and their chains, read only.
            match unsafe { apps_rate_attachment(ci) } {
                Ok(false) => {}
                Ok(true) => {
                    inj.apps_own_attachment(which);
                    // SAFETY: the next layer's function, with the caller's arguments.
                    let r = unsafe { create2(device, info, alloc, out) };
                    if r == vk::Result::SUCCESS {
                        // SAFETY: just created.
                        inj.apps_pass_created(unsafe { *out });
                    }
                    return r;
                }
                Err(e) => {
                    tracing::warn!(
                        error = ?e,
                        "{which}: a subpass pNext chain the layer cannot read; passed on as is, \
                         at full rate"
                    );
                    // SAFETY: the next layer's function, with the caller's arguments.
                    return unsafe { create2(device, info, alloc, out) };
                }
            }
        }
        let fdm = vk::StructureType::RENDER_PASS_FRAGMENT_DENSITY_MAP_CREATE_INFO_EXT;
        // SAFETY: the caller's chain, read only.
        let Ok(chain) = (unsafe { chain_without(ci.p_next, |t| t == fdm, which) }) else {
            // `chain_without` leaves out what it cannot copy, so this is not expected; the
            // driver must not get the density-map struct all the same.
            tracing::warn!(
                "{which}: a pNext chain the layer cannot copy; the render pass is refused"
            );
            return vk::Result::ERROR_UNKNOWN;
        };
        // SAFETY: the caller's arrays outlive the call.
        let pass = unsafe { Pass2::from_v2(ci) };
        // SAFETY: the copied pass and chain live across the call.
        unsafe {
            create_rewritten(
                &dev,
                create2,
                pass,
                ci.flags,
                chain.head(),
                density,
                alloc,
                out,
            )
        }
    })
}

hook_and_khr_alias! {
    /// `vkCreateRenderPass2`: see the module documentation.
    create_render_pass2, create_render_pass2_khr = create_render_pass2_with("vkCreateRenderPass2")
    (
        device: vk::Device,
        info: *const vk::RenderPassCreateInfo2<'_>,
        alloc: *const vk::AllocationCallbacks<'_>,
        out: *mut vk::RenderPass,
    ) -> vk::Result
}

/// `vkDestroyRenderPass`: forgets a rewritten pass.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn destroy_render_pass(
    device: vk::Device,
    pass: vk::RenderPass,
    alloc: *const vk::AllocationCallbacks<'_>,
) {
    guard("vkDestroyRenderPass", (), || {
        // SAFETY: as the caller promised.
        let Some(dev) = (unsafe { registry::device(device) }) else {
            return;
        };
        dev.attachments.passes.lock().remove(&pass.as_raw());
        if let Some(inj) = &dev.inject {
            inj.pass_destroyed(pass);
        }
        // SAFETY: the device is live.
        unsafe { crate::vk::convert::pass_changed(&dev, pass, None) };
        if let Some(next) = dev.next.destroy_render_pass {
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { next(device, pass, alloc) };
        }
    })
}

/// The imageless framebuffer's description of the density attachment, made the shadow's.
fn shadow_attachment_info(
    a: &vk::FramebufferAttachmentImageInfo<'_>,
    layered: bool,
    formats: &[vk::Format; 1],
) -> vk::FramebufferAttachmentImageInfo<'static> {
    vk::FramebufferAttachmentImageInfo {
        p_next: a.p_next,
        flags: vk::ImageCreateFlags::empty(),
        usage: SHADOW_USAGE,
        width: a.width,
        height: a.height,
        layer_count: if layered { a.layer_count } else { 1 },
        view_format_count: 1,
        p_view_formats: formats.as_ptr(),
        ..Default::default()
    }
}

/// `vkCreateFramebuffer`: a rewritten pass's density view becomes its shadow view; an imageless
/// framebuffer describes the shadow instead.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn create_framebuffer(
    device: vk::Device,
    info: *const vk::FramebufferCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Framebuffer,
) -> vk::Result {
    guard(
        "vkCreateFramebuffer",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let Some(dev) = (unsafe { registry::device(device) }) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let Some(next) = dev.next.create_framebuffer else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            // SAFETY: the caller's create info, read only.
            let Some(ci) = (unsafe { info.as_ref() }) else {
                // SAFETY: the next layer's function, with the caller's arguments.
                return unsafe { next(device, info, alloc, out) };
            };
            if let (Some(inj), Some(own)) = (&dev.inject, &dev.attachments.own) {
                let Some(p) = inj.pass(ci.render_pass) else {
                    // SAFETY: as above.
                    return unsafe { next(device, info, alloc, out) };
                };
                // SAFETY: the caller's arguments; `own` is the device's.
                return unsafe {
                    create_injected_framebuffer(inj, own, p, next, device, ci, alloc, out)
                };
            }
            let Some(density) = dev.attachments.density_attachment(ci.render_pass) else {
                // SAFETY: as above.
                return unsafe { next(device, info, alloc, out) };
            };
            let mut copy = *ci;
            if ci.flags.contains(vk::FramebufferCreateFlags::IMAGELESS) {
                let ty = vk::StructureType::FRAMEBUFFER_ATTACHMENTS_CREATE_INFO;
                let found =
                    // SAFETY: the caller's chain, read only.
                    unsafe { chain::find::<vk::FramebufferAttachmentsCreateInfo>(ci.p_next, ty) };
                // SAFETY: as above.
                let rest = unsafe { ChainCopy::without(ci.p_next, |t| t == ty) };
                let (Ok(Some(found)), Ok(rest)) = (found, rest) else {
                    tracing::warn!(
                        "vkCreateFramebuffer: an imageless framebuffer the layer cannot rewrite; \
                         passed on as is"
                    );
                    // SAFETY: as above.
                    return unsafe { next(device, info, alloc, out) };
                };
                // SAFETY: found by its sType in a valid chain.
                let found = unsafe { &*found };
                // SAFETY: the caller's array.
                let mut infos: Vec<vk::FramebufferAttachmentImageInfo<'_>> = unsafe {
                    slice(
                        found.p_attachment_image_infos,
                        found.attachment_image_info_count,
                    )
                }
                .to_vec();
                let formats = [SHADOW_FORMAT];
                let layered = dev.fdm.as_ref().is_some_and(|f| f.layered);
                if let Some(a) = infos.get_mut(density as usize) {
                    *a = shadow_attachment_info(a, layered, &formats);
                }
                let mut attachments = *found;
                attachments.p_next = rest.head();
                attachments.attachment_image_info_count = infos.len() as u32;
                attachments.p_attachment_image_infos = infos.as_ptr();
                copy.p_next = &attachments as *const _ as *const c_void;
                // SAFETY: the copies live across the call.
                return unsafe { next(device, &copy, alloc, out) };
            }
            let mut views: Vec<vk::ImageView> =
                // SAFETY: the caller's array.
                unsafe { slice(ci.p_attachments, ci.attachment_count) }.to_vec();
            let app_view = views.get(density as usize).copied();
            if let Some(v) = views.get_mut(density as usize) {
                // A density view without a shadow (it could not be made) gets the device's
                // full-rate stand-in ([`crate::vk::image::Own::full_rate_view`]).
                let shadow = dev.attachments.shadow_view(*v).or_else(|| {
                    let (own, fdm) = (dev.attachments.own.as_ref()?, dev.fdm.as_ref()?);
                    // SAFETY: the device is live and emulates as `fdm` says.
                    unsafe { own.full_rate_view(fdm, ci.width, ci.height) }
                });
                match shadow {
                    Some(s) => *v = s,
                    None => tracing::warn!(
                        view = raw(*v),
                        "vkCreateFramebuffer: the density view has no shadow; passed on as is"
                    ),
                }
            }
            copy.p_attachments = views.as_ptr();
            // SAFETY: the copy and the views live across the call.
            let r = unsafe { next(device, &copy, alloc, out) };
            if r == vk::Result::SUCCESS && !out.is_null() {
                // SAFETY: the framebuffer was just created on the live device.
                unsafe { crate::vk::convert::framebuffer_changed(&dev, *out, app_view) };
            }
            r
        },
    )
}

/// `vkCreateFramebuffer` of a pass with an injected shading-rate attachment
/// (docs/injection.md#how-the-attachment-gets-in): the framebuffer gets that attachment after the
/// application's, the eye map where its colour target is an eye target, otherwise a full-rate map
/// covering it ([`crate::vk::inject::Injector::neutral`]). An imageless framebuffer describes a
/// one-layer map of exactly `ceil(size / texel)` texels, which each begin names
/// ([`begin_injected_pass`]).
///
/// # Safety
/// The caller's arguments, valid as the command requires; `own` must be `inj`'s device's.
#[allow(clippy::too_many_arguments)]
unsafe fn create_injected_framebuffer(
    inj: &crate::vk::inject::Injector,
    own: &crate::vk::image::Own,
    p: crate::vk::inject::InjectedPass,
    next: vk::PFN_vkCreateFramebuffer,
    device: vk::Device,
    ci: &vk::FramebufferCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Framebuffer,
) -> vk::Result {
    let extent = [ci.width, ci.height];
    let texels = inj.texels_for(extent);
    let mut copy = *ci;
    let record = |eye: Option<([u32; 2], fovea_model::inject::Views)>, imageless: bool| {
        // SAFETY: just created.
        let fb = unsafe { *out };
        inj.framebuffer_created(
            fb,
            crate::vk::inject::InjectedFramebuffer {
                pass: p,
                extent,
                imageless,
                eye,
            },
        );
        tracing::debug!(
            framebuffer = raw(fb),
            eye = eye.is_some(),
            imageless,
            "framebuffer: injected shading-rate attachment"
        );
    };
    if ci.flags.contains(vk::FramebufferCreateFlags::IMAGELESS) {
        let ty = vk::StructureType::FRAMEBUFFER_ATTACHMENTS_CREATE_INFO;
        // SAFETY: the caller's chain, read only.
        let found = unsafe { chain::find::<vk::FramebufferAttachmentsCreateInfo>(ci.p_next, ty) };
        // SAFETY: as above.
        let rest = unsafe { ChainCopy::without(ci.p_next, |t| t == ty) };
        let (Ok(Some(found)), Ok(rest)) = (found, rest) else {
            tracing::warn!(
                "vkCreateFramebuffer: an imageless framebuffer of an injected pass the layer \
                 cannot extend; passed on as is"
            );
            // SAFETY: the next layer's function, with the caller's arguments.
            return unsafe { next(device, ci, alloc, out) };
        };
        // SAFETY: found by its sType in a valid chain.
        let found = unsafe { &*found };
        // SAFETY: the caller's array.
        let mut infos: Vec<vk::FramebufferAttachmentImageInfo<'_>> = unsafe {
            slice(
                found.p_attachment_image_infos,
                found.attachment_image_info_count,
            )
        }
        .to_vec();
        let formats = [SHADOW_FORMAT];
        infos.push(vk::FramebufferAttachmentImageInfo {
            usage: SHADOW_USAGE,
            width: texels[0],
            height: texels[1],
            layer_count: 1,
            view_format_count: 1,
            p_view_formats: formats.as_ptr(),
            ..Default::default()
        });
        let mut attachments = *found;
        attachments.p_next = rest.head();
        attachments.attachment_image_info_count = infos.len() as u32;
        attachments.p_attachment_image_infos = infos.as_ptr();
        copy.p_next = &attachments as *const _ as *const c_void;
        copy.attachment_count = ci.attachment_count + 1;
        // SAFETY: the copies live across the call.
        let r = unsafe { next(device, &copy, alloc, out) };
        if r == vk::Result::SUCCESS {
            record(None, true);
        }
        return r;
    }
    let mut views: Vec<vk::ImageView> =
        // SAFETY: the caller's array.
        unsafe { slice(ci.p_attachments, ci.attachment_count) }.to_vec();
    let colour = p.colour.and_then(|c| views.get(c as usize).copied());
    let layers = if p.view_mask != 0 {
        crate::vk::inject::rendered_layers(p.view_mask, 0)
    } else {
        Some(ci.layers)
    };
    let eye = match (colour, crate::bridge::inject::current()) {
        // SAFETY: `own` is the device's, as the caller promised.
        (Some(v), Some(state)) => unsafe { inj.eye_map(own, &state, v, layers) },
        _ => None,
    };
    let rate = eye.map(|e| e.0).or_else(|| {
        // SAFETY: as above.
        unsafe { inj.neutral(own, texels) }
    });
    let Some(rate) = rate else {
        // The pass names an attachment the framebuffer cannot fill: the driver's answer for
        // memory it cannot get (logged by `neutral`).
        return vk::Result::ERROR_OUT_OF_DEVICE_MEMORY;
    };
    views.push(rate);
    copy.attachment_count = views.len() as u32;
    copy.p_attachments = views.as_ptr();
    // SAFETY: the copy and the views live across the call.
    let r = unsafe { next(device, &copy, alloc, out) };
    if r == vk::Result::SUCCESS {
        record(eye.map(|(_, e, v)| (e, v)), false);
    }
    r
}

/// `vkDestroyFramebuffer` on an injecting device: forgets what the framebuffer got.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn destroy_framebuffer(
    device: vk::Device,
    fb: vk::Framebuffer,
    alloc: *const vk::AllocationCallbacks<'_>,
) {
    guard("vkDestroyFramebuffer", (), || {
        // SAFETY: as the caller promised.
        let Some(dev) = (unsafe { registry::device(device) }) else {
            return;
        };
        if let Some(inj) = &dev.inject {
            inj.framebuffer_destroyed(fb);
        }
        if let Some(next) = dev.next.destroy_framebuffer {
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { next(device, fb, alloc) };
        }
        // SAFETY: as the caller promised.
        unsafe { crate::vk::convert::framebuffer_destroyed(device, fb) };
    })
}

/// Views a begin names inline, before a longer list takes the heap.
const INLINE_VIEWS: usize = 16;

/// A begin of a render pass on an injecting device: the eye map a framebuffer names is refilled
/// where the published maps moved on, and the pass is counted; for an imageless framebuffer, a copy
/// of `begin` whose `VkRenderPassAttachmentBeginInfo` adds the map of this begin's colour view (or
/// the full-rate one of the framebuffer's size). No allocation for up to [`INLINE_VIEWS`] views.
///
/// # Safety
/// `begin` must be NULL or valid; `own` must be `inj`'s device's.
unsafe fn begin_injected_pass(
    inj: &crate::vk::inject::Injector,
    own: &crate::vk::image::Own,
    begin: *const vk::RenderPassBeginInfo<'_>,
    f: impl FnOnce(*const vk::RenderPassBeginInfo<'_>),
) {
    // SAFETY: as the caller promised.
    let Some(b) = (unsafe { begin.as_ref() }) else {
        return f(begin);
    };
    let Some(fb) = inj.framebuffer(b.framebuffer) else {
        crate::bridge::inject::count_pass(false);
        return f(begin);
    };
    let state = crate::bridge::inject::current();
    if !fb.imageless {
        if let (Some((extent, views)), Some(state)) = (fb.eye, &state) {
            // SAFETY: as the caller promised.
            unsafe { inj.refresh(own, state, extent, views) };
        }
        crate::bridge::inject::count_pass(fb.eye.is_some());
        return f(begin);
    }
    let ty = vk::StructureType::RENDER_PASS_ATTACHMENT_BEGIN_INFO;
    let Ok(Some(found)) =
        // SAFETY: the caller's chain, read only.
        (unsafe { chain::find::<vk::RenderPassAttachmentBeginInfo>(b.p_next, ty) })
    else {
        return f(begin);
    };
    // SAFETY: found by its sType in a valid chain.
    let found = unsafe { &*found };
    // SAFETY: the caller's array.
    let app = unsafe { slice(found.p_attachments, found.attachment_count) };
    let texels = inj.texels_for(fb.extent);
    let layers = if fb.pass.view_mask != 0 {
        crate::vk::inject::rendered_layers(fb.pass.view_mask, 0)
    } else {
        None
    };
    let colour = fb.pass.colour.and_then(|c| app.get(c as usize).copied());
    let eye = match (colour, &state) {
        // SAFETY: as the caller promised.
        (Some(v), Some(state)) => unsafe { inj.eye_map(own, state, v, layers) },
        _ => None,
    }
    // The framebuffer describes a one-layer map of exactly its texels.
    .filter(|&(_, e, v)| inj.map_size(e, v) == Some((texels, 1)));
    let Some(rate) = eye.map(|e| e.0).or_else(|| {
        // SAFETY: as the caller promised.
        unsafe { inj.neutral(own, texels) }
    }) else {
        return f(begin);
    };
    crate::bridge::inject::count_pass(eye.is_some());
    let mut inline = [vk::ImageView::null(); INLINE_VIEWS];
    let heap: Vec<vk::ImageView>;
    let views: &[vk::ImageView] = if app.len() < INLINE_VIEWS {
        inline[..app.len()].copy_from_slice(app);
        inline[app.len()] = rate;
        &inline[..=app.len()]
    } else {
        heap = app.iter().copied().chain([rate]).collect();
        &heap
    };
    // SAFETY: the caller's chain, read only; the copy lives across `f`.
    unsafe {
        chain::with_removed(
            b.p_next,
            |t| t == ty,
            |rest| {
                let Ok(rest) = rest else {
                    tracing::warn!(
                        "vkCmdBeginRenderPass: a pNext chain the layer cannot copy; passed on as is"
                    );
                    return f(begin);
                };
                let mut attachments = *found;
                attachments.p_next = rest;
                attachments.attachment_count = views.len() as u32;
                attachments.p_attachments = views.as_ptr();
                let mut copy = *b;
                copy.p_next = &attachments as *const _ as *const c_void;
                f(&copy)
            },
        )
    }
}

/// For a begin of a rewritten pass with an imageless framebuffer: a copy of `begin` whose
/// `VkRenderPassAttachmentBeginInfo` names the shadow view; `f` runs with it (or with `begin`
/// where nothing is swapped).
///
/// # Safety
/// `begin` must be NULL or valid.
unsafe fn with_swapped_begin(
    dev: &Device,
    begin: *const vk::RenderPassBeginInfo<'_>,
    f: impl FnOnce(*const vk::RenderPassBeginInfo<'_>),
) {
    if let (Some(inj), Some(own)) = (&dev.inject, &dev.attachments.own) {
        // SAFETY: as the caller promised; `own` is the device's.
        return unsafe { begin_injected_pass(inj, own, begin, f) };
    }
    // SAFETY: as the caller promised.
    let Some(b) = (unsafe { begin.as_ref() }) else {
        return f(begin);
    };
    if b.p_next.is_null() {
        return f(begin);
    }
    let ty = vk::StructureType::RENDER_PASS_ATTACHMENT_BEGIN_INFO;
    let Ok(Some(found)) =
        // SAFETY: the caller's chain, read only.
        (unsafe { chain::find::<vk::RenderPassAttachmentBeginInfo>(b.p_next, ty) })
    else {
        return f(begin);
    };
    let Some(density) = dev.attachments.density_attachment(b.render_pass) else {
        return f(begin);
    };
    // SAFETY: found by its sType in a valid chain.
    let found = unsafe { &*found };
    let mut views: Vec<vk::ImageView> =
        // SAFETY: the caller's array.
        unsafe { slice(found.p_attachments, found.attachment_count) }.to_vec();
    let Some(shadow) = views
        .get(density as usize)
        .and_then(|v| dev.attachments.shadow_view(*v))
    else {
        return f(begin);
    };
    views[density as usize] = shadow;
    // SAFETY: as above.
    let Ok(rest) = (unsafe { ChainCopy::without(b.p_next, |t| t == ty) }) else {
        tracing::warn!(
            "vkCmdBeginRenderPass: a pNext chain the layer cannot copy; passed on as is"
        );
        return f(begin);
    };
    let mut attachments = *found;
    attachments.p_next = rest.head();
    attachments.p_attachments = views.as_ptr();
    let mut copy = *b;
    copy.p_next = &attachments as *const _ as *const c_void;
    f(&copy)
}

/// `vkCmdBeginRenderPass`: see [`with_swapped_begin`].
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_begin_render_pass(
    cb: vk::CommandBuffer,
    begin: *const vk::RenderPassBeginInfo<'_>,
    contents: vk::SubpassContents,
) {
    guard("vkCmdBeginRenderPass", (), || {
        // SAFETY: as the caller promised.
        let Some(dev) = (unsafe { registry::device_ref(cb) }) else {
            return;
        };
        let Some(next) = dev.next.cmd_begin_render_pass else {
            return;
        };
        // SAFETY: as the caller promised; recorded before the pass begins.
        unsafe { crate::vk::convert::before_render_pass(&dev, cb, begin) };
        // SAFETY: the next layer's function, with the caller's arguments or a copy that lives
        // across the call.
        unsafe { with_swapped_begin(&dev, begin, |b| next(cb, b, contents)) }
    })
}

/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn cmd_begin_render_pass2_with(
    which: &'static str,
    next: fn(&Device) -> Option<vk::PFN_vkCmdBeginRenderPass2>,
    cb: vk::CommandBuffer,
    begin: *const vk::RenderPassBeginInfo<'_>,
    subpass: *const vk::SubpassBeginInfo<'_>,
) {
    guard(which, (), || {
        // SAFETY: as the caller promised.
        let Some(dev) = (unsafe { registry::device_ref(cb) }) else {
            return;
        };
        let Some(next) = next(&dev) else {
            return;
        };
        // SAFETY: as the caller promised; recorded before the pass begins.
        unsafe { crate::vk::convert::before_render_pass(&dev, cb, begin) };
        // SAFETY: as in cmd_begin_render_pass.
        unsafe { with_swapped_begin(&dev, begin, |b| next(cb, b, subpass)) }
    })
}

hook_and_khr_alias! {
    /// `vkCmdBeginRenderPass2`: see [`with_swapped_begin`].
    cmd_begin_render_pass2, cmd_begin_render_pass2_khr =
        cmd_begin_render_pass2_with("vkCmdBeginRenderPass2")
    (
        cb: vk::CommandBuffer,
        begin: *const vk::RenderPassBeginInfo<'_>,
        subpass: *const vk::SubpassBeginInfo<'_>,
    )
}

/// # Safety
/// The caller's arguments, valid as the command requires.
unsafe fn cmd_begin_rendering_with(
    which: &'static str,
    next: fn(&Device) -> Option<vk::PFN_vkCmdBeginRendering>,
    cb: vk::CommandBuffer,
    info: *const vk::RenderingInfo<'_>,
) {
    guard(which, (), || {
        // SAFETY: as the caller promised.
        let Some(dev) = (unsafe { registry::device_ref(cb) }) else {
            return;
        };
        let Some(next) = next(&dev) else {
            return;
        };
        // SAFETY: as the caller promised; recorded before rendering begins.
        unsafe { crate::vk::convert::before_rendering(&dev, cb, info) };
        if let (Some(inj), Some(own)) = (&dev.inject, &dev.attachments.own) {
            // SAFETY: the caller's arguments; `own` is the device's.
            return unsafe { begin_injected(inj, own, next, cb, info) };
        }
        // SAFETY: the caller's rendering info, read only.
        let ri = match unsafe { info.as_ref() } {
            Some(ri) if !ri.p_next.is_null() => ri,
            // SAFETY: the next layer's function, with the caller's arguments.
            _ => return unsafe { next(cb, info) },
        };
        let ty = vk::StructureType::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_INFO_EXT;
        // SAFETY: the caller's chain, read only.
        let found = unsafe {
            chain::find::<vk::RenderingFragmentDensityMapAttachmentInfoEXT>(ri.p_next, ty)
        };
        let (Ok(Some(found)), Some(texel)) = (found, texel_of(&dev)) else {
            // SAFETY: as above.
            return unsafe { next(cb, info) };
        };
        // SAFETY: found by its sType.
        let view = unsafe { (*found).image_view };
        let shadow = (view != vk::ImageView::null())
            .then(|| dev.attachments.shadow_view(view))
            .flatten();
        // The edited chain is built in per-thread scratch storage: no heap allocation per
        // command (docs/ARCHITECTURE.md, "Nothing per frame that can be done at creation").
        // SAFETY: the caller's chain, read only.
        unsafe {
            chain::with_removed(
                ri.p_next,
                |t| t == ty,
                |rest| {
                    let Ok(rest) = rest else {
                        tracing::warn!(
                            "{which}: a pNext chain the layer cannot copy; passed on as is"
                        );
                        return next(cb, info);
                    };
                    let mut rate = vk::RenderingFragmentShadingRateAttachmentInfoKHR::default()
                        .image_layout(SHADOW_LAYOUT)
                        .shading_rate_attachment_texel_size(texel);
                    rate.p_next = rest;
                    let mut copy = *ri;
                    match shadow {
                        Some(s) => {
                            rate.image_view = s;
                            copy.p_next = &rate as *const _ as *const c_void;
                        }
                        None => {
                            if view != vk::ImageView::null() {
                                tracing::debug!(
                                    view = raw(view),
                                    "{which}: the density view has no shadow; rendering at full \
                                     rate"
                                );
                            }
                            copy.p_next = rest;
                        }
                    }
                    // The copy and everything it points at live across the call.
                    next(cb, &copy)
                },
            )
        }
    })
}

/// `vkCmdBeginRendering` on an injecting device (docs/injection.md#how-the-attachment-gets-in): where
/// the first colour attachment's view is an eye target, a copy of the begin info goes down with a
/// `VkRenderingFragmentShadingRateAttachmentInfoKHR` naming the map for its shape in front of the
/// application's chain (on the stack: no allocation per command); any other rendering goes down
/// untouched. Either is counted for the stats line's `Inj=`.
///
/// An application's own `VkRenderingFragmentShadingRateAttachmentInfoKHR` with a view wins: the
/// rendering goes down as it came. One with a null view (vkd3d-proton chains one into every
/// rendering, docs/injection.md#apps-that-set-rates) names no attachment; in an eye pass it is
/// left out of the copy's chain (built in per-thread scratch storage, no allocation per command)
/// and fovea's takes its place, since a struct may appear only once in a chain
/// (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#fundamentals-validusage-pNext>).
///
/// The attachment's layer count is 1 (merged, or one view) or the rendered views', as
/// <https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderingFragmentShadingRateAttachmentInfoKHR.html>
/// asks of a multiview rendering; its extent covers the whole colour target.
///
/// # Safety
/// The caller's arguments, valid as the command requires; `own` must be `inj`'s device's.
unsafe fn begin_injected(
    inj: &crate::vk::inject::Injector,
    own: &crate::vk::image::Own,
    next: vk::PFN_vkCmdBeginRendering,
    cb: vk::CommandBuffer,
    info: *const vk::RenderingInfo<'_>,
) {
    // SAFETY: the caller's rendering info, read only.
    let (Some(ri), Some(state)) = (unsafe { info.as_ref() }, crate::bridge::inject::current())
    else {
        // SAFETY: the next layer's function, with the caller's arguments.
        return unsafe { next(cb, info) };
    };
    let rate_ty = vk::StructureType::RENDERING_FRAGMENT_SHADING_RATE_ATTACHMENT_INFO_KHR;
    // SAFETY: the caller's chain, read only; found by its sType.
    let apps = match unsafe {
        chain::find::<vk::RenderingFragmentShadingRateAttachmentInfoKHR<'_>>(ri.p_next, rate_ty)
    } {
        // SAFETY: found by its sType in the caller's chain.
        Ok(found) => found.map(|f| unsafe { (*f).image_view }),
        Err(_) => {
            crate::bridge::inject::count_pass(false);
            // SAFETY: the next layer's function, with the caller's arguments.
            return unsafe { next(cb, info) };
        }
    };
    if apps.is_some_and(|v| v != vk::ImageView::null()) {
        inj.apps_own_attachment("vkCmdBeginRendering");
        crate::bridge::inject::count_pass(false);
        // SAFETY: the next layer's function, with the caller's arguments.
        return unsafe { next(cb, info) };
    }
    // SAFETY: the caller's colour attachments, `colorAttachmentCount` of them.
    let colour = unsafe { slice(ri.p_color_attachments, ri.color_attachment_count) }
        .first()
        .map(|a| a.image_view)
        .filter(|v| *v != vk::ImageView::null());
    let layers = crate::vk::inject::rendered_layers(ri.view_mask, ri.layer_count);
    // SAFETY: `own` is the device's, as the caller promised.
    let map = colour.and_then(|v| unsafe { inj.eye_view(own, &state, v, layers) });
    crate::bridge::inject::count_pass(map.is_some());
    let Some(map) = map else {
        // SAFETY: the next layer's function, with the caller's arguments.
        return unsafe { next(cb, info) };
    };
    let begin = |rest: *const c_void| {
        let mut rate = vk::RenderingFragmentShadingRateAttachmentInfoKHR::default()
            .image_view(map)
            .image_layout(SHADOW_LAYOUT)
            .shading_rate_attachment_texel_size(inj.texel());
        rate.p_next = rest;
        let mut copy = *ri;
        copy.p_next = &rate as *const _ as *const c_void;
        // SAFETY: the copy and the struct in front of the chain live across the call.
        unsafe { next(cb, &copy) }
    };
    if apps.is_none() {
        return begin(ri.p_next);
    }
    // SAFETY: the caller's chain, read only; the copy lives across `begin`.
    unsafe {
        chain::with_removed(
            ri.p_next,
            |t| t == rate_ty,
            |rest| match rest {
                Ok(rest) => begin(rest),
                Err(e) => {
                    tracing::warn!(
                        error = ?e,
                        "vkCmdBeginRendering: a pNext chain the layer cannot copy; passed on as \
                         is, at full rate"
                    );
                    next(cb, info)
                }
            },
        )
    }
}

hook_and_khr_alias! {
    /// `vkCmdBeginRendering`: the density-map attachment becomes a shading-rate attachment.
    cmd_begin_rendering, cmd_begin_rendering_khr = cmd_begin_rendering_with("vkCmdBeginRendering")
    (cb: vk::CommandBuffer, info: *const vk::RenderingInfo<'_>)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn att(format: vk::Format) -> vk::AttachmentDescription {
        vk::AttachmentDescription::default()
            .format(format)
            .samples(vk::SampleCountFlags::TYPE_1)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::STORE)
            .initial_layout(vk::ImageLayout::UNDEFINED)
            .final_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL)
    }

    /// Colour, depth, density; one subpass reading an input attachment, multiview over two views.
    #[test]
    fn v1_converts_with_multiview_and_input_aspects() {
        let atts = [
            att(vk::Format::R8G8B8A8_UNORM),
            att(vk::Format::D24_UNORM_S8_UINT),
            att(vk::Format::R8G8_UNORM)
                .load_op(vk::AttachmentLoadOp::DONT_CARE)
                .store_op(vk::AttachmentStoreOp::DONT_CARE)
                .initial_layout(vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT)
                .final_layout(vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT),
        ];
        let color = [vk::AttachmentReference {
            attachment: 0,
            layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
        }];
        let depth = vk::AttachmentReference {
            attachment: 1,
            layout: vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL,
        };
        let inputs = [
            vk::AttachmentReference {
                attachment: 1,
                layout: vk::ImageLayout::DEPTH_STENCIL_READ_ONLY_OPTIMAL,
            },
            vk::AttachmentReference {
                attachment: 0,
                layout: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
            },
        ];
        let preserve = [2u32];
        let subpasses = [
            vk::SubpassDescription::default()
                .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
                .color_attachments(&color)
                .depth_stencil_attachment(&depth),
            vk::SubpassDescription::default()
                .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
                .input_attachments(&inputs)
                .color_attachments(&color)
                .preserve_attachments(&preserve),
        ];
        let deps = [vk::SubpassDependency {
            src_subpass: 0,
            dst_subpass: 1,
            src_stage_mask: vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
            dst_stage_mask: vk::PipelineStageFlags::FRAGMENT_SHADER
                | vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
            src_access_mask: vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
            dst_access_mask: vk::AccessFlags::INPUT_ATTACHMENT_READ
                | vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT,
            dependency_flags: vk::DependencyFlags::BY_REGION | vk::DependencyFlags::VIEW_LOCAL,
        }];
        let masks = [0b11, 0b11];
        let offsets = [0];
        let correlation = [0b11];
        let multiview = vk::RenderPassMultiviewCreateInfo::default()
            .view_masks(&masks)
            .view_offsets(&offsets)
            .correlation_masks(&correlation);
        let aspect_refs = [vk::InputAttachmentAspectReference {
            subpass: 1,
            input_attachment_index: 0,
            aspect_mask: vk::ImageAspectFlags::DEPTH,
        }];
        let aspects = vk::RenderPassInputAttachmentAspectCreateInfo::default()
            .aspect_references(&aspect_refs);
        let ci = vk::RenderPassCreateInfo::default()
            .attachments(&atts)
            .subpasses(&subpasses)
            .dependencies(&deps);
        // SAFETY: every array lives to the end of the test.
        let mut pass = unsafe { v1_to_v2(&ci, Some(&multiview), Some(&aspects)) };
        assert_eq!(pass.attachments.len(), 3);
        assert_eq!(pass.attachments[1].format, vk::Format::D24_UNORM_S8_UINT);
        assert_eq!(
            pass.attachments[0].final_layout,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL
        );
        assert_eq!(pass.subpasses.len(), 2);
        assert_eq!(pass.subpasses[0].view_mask, 0b11);
        assert_eq!(pass.subpasses[1].view_mask, 0b11);
        // SAFETY: pointers into `pass`.
        unsafe {
            let s0 = &pass.subpasses[0];
            assert_eq!((*s0.p_depth_stencil_attachment).attachment, 1);
            assert!(s0.p_input_attachments.is_null());
            assert!(s0.p_resolve_attachments.is_null());
            let s1 = &pass.subpasses[1];
            let ins = slice(s1.p_input_attachments, s1.input_attachment_count);
            assert_eq!(ins[0].aspect_mask, vk::ImageAspectFlags::DEPTH, "named");
            assert_eq!(
                ins[1].aspect_mask,
                vk::ImageAspectFlags::COLOR,
                "the format's"
            );
            assert_eq!(ins[1].layout, vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL);
            let cs = slice(s1.p_color_attachments, s1.color_attachment_count);
            assert_eq!(cs[0].aspect_mask, vk::ImageAspectFlags::empty());
            assert_eq!(
                slice(s1.p_preserve_attachments, s1.preserve_attachment_count),
                [2]
            );
        }
        assert_eq!(pass.dependencies[0].view_offset, 0);
        assert_eq!(
            pass.dependencies[0].dependency_flags,
            vk::DependencyFlags::BY_REGION | vk::DependencyFlags::VIEW_LOCAL
        );
        assert_eq!(pass.correlated, [0b11]);

        let texel = vk::Extent2D {
            width: 16,
            height: 16,
        };
        // SAFETY: the converted pass owns its references; its dependencies have no chains.
        unsafe { pass.without_density_enums() };
        add_shading_rate(&mut pass, 2, texel, vk::AttachmentStoreOp::NONE);
        let d = &pass.attachments[2];
        assert_eq!(d.format, vk::Format::R8_UINT);
        assert_eq!(d.load_op, vk::AttachmentLoadOp::LOAD);
        assert_eq!(d.store_op, vk::AttachmentStoreOp::NONE);
        assert_eq!(d.initial_layout, SHADOW_LAYOUT);
        assert_eq!(d.final_layout, SHADOW_LAYOUT);
        assert_eq!(
            pass.attachments[0].load_op,
            vk::AttachmentLoadOp::CLEAR,
            "others untouched"
        );
        for s in &pass.subpasses {
            // SAFETY: pointers into `pass`.
            unsafe {
                let f = &*(s.p_next as *const vk::FragmentShadingRateAttachmentInfoKHR);
                assert_eq!(
                    f.s_type,
                    vk::StructureType::FRAGMENT_SHADING_RATE_ATTACHMENT_INFO_KHR
                );
                assert!(f.p_next.is_null());
                assert_eq!(f.shading_rate_attachment_texel_size, texel);
                let r = &*f.p_fragment_shading_rate_attachment;
                assert_eq!((r.attachment, r.layout), (2, SHADOW_LAYOUT));
            }
        }
        let dep = &pass.dependencies[0];
        assert_eq!(
            dep.dst_stage_mask,
            vk::PipelineStageFlags::FRAGMENT_SHADER
                | vk::PipelineStageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR
        );
        assert_eq!(
            dep.dst_access_mask,
            vk::AccessFlags::INPUT_ATTACHMENT_READ
                | vk::AccessFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR
        );
        let info = pass.info(vk::RenderPassCreateFlags::empty(), std::ptr::null());
        assert_eq!(info.subpass_count, 2);
        assert_eq!(info.correlated_view_mask_count, 1);
    }

    #[test]
    fn v1_without_multiview_has_no_view_masks() {
        let atts = [att(vk::Format::R8G8B8A8_UNORM)];
        let color = [vk::AttachmentReference {
            attachment: 0,
            layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
        }];
        let subpasses = [vk::SubpassDescription::default().color_attachments(&color)];
        let ci = vk::RenderPassCreateInfo::default()
            .attachments(&atts)
            .subpasses(&subpasses);
        // SAFETY: every array lives to the end of the test.
        let pass = unsafe { v1_to_v2(&ci, None, None) };
        assert_eq!(pass.subpasses[0].view_mask, 0);
        assert!(pass.dependencies.is_empty());
        assert!(pass.correlated.is_empty());
    }

    /// A pass that writes a density map (no density-map struct): its attachment's final layout,
    /// a reference's layout, a dependency's masks and a `VkMemoryBarrier2` chained to another
    /// dependency lose every density-map value, on copies; the rest of the dependency's chain
    /// stays behind the translated barrier, and the application's structs are unchanged.
    #[test]
    fn a_pass_that_writes_a_map_loses_the_density_enums() {
        let fdm = vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT;
        let atts = [vk::AttachmentDescription2::default()
            .format(vk::Format::R8G8_UNORM)
            .initial_layout(vk::ImageLayout::UNDEFINED)
            .final_layout(fdm)];
        let input = [vk::AttachmentReference2::default()
            .attachment(0)
            .layout(fdm)];
        let subpasses = [vk::SubpassDescription2::default().input_attachments(&input)];
        // A struct the layer does not know, after the barrier.
        let tail = vk::BaseInStructure {
            s_type: vk::StructureType::from_raw(1_000_999_000),
            ..Default::default()
        };
        let mut barrier = vk::MemoryBarrier2::default()
            .src_stage_mask(vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT)
            .dst_stage_mask(vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT)
            .dst_access_mask(vk::AccessFlags2::FRAGMENT_DENSITY_MAP_READ_EXT);
        barrier.p_next = &tail as *const _ as *const c_void;
        let mut with_barrier = vk::SubpassDependency2::default().src_subpass(0);
        with_barrier.dst_subpass = vk::SUBPASS_EXTERNAL;
        with_barrier.p_next = &barrier as *const _ as *const c_void;
        let deps = [
            with_barrier,
            vk::SubpassDependency2::default()
                .dst_stage_mask(vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT)
                .dst_access_mask(vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT),
        ];
        let ci = vk::RenderPassCreateInfo2::default()
            .attachments(&atts)
            .subpasses(&subpasses)
            .dependencies(&deps);
        // SAFETY: the arrays and chains live across the test.
        unsafe {
            assert!(v2_names_density(&ci));
            let mut pass = Pass2::from_v2(&ci);
            pass.without_density_enums();
            assert_eq!(pass.attachments[0].final_layout, vk::ImageLayout::GENERAL);
            assert_eq!(
                (*pass.subpasses[0].p_input_attachments).layout,
                vk::ImageLayout::GENERAL
            );
            assert_eq!(
                input[0].layout, fdm,
                "the application's reference is not written"
            );
            assert_eq!(
                pass.dependencies[1].dst_stage_mask,
                vk::PipelineStageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR
            );
            assert_eq!(
                pass.dependencies[1].dst_access_mask,
                vk::AccessFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR
            );
            let b = &*(pass.dependencies[0].p_next as *const vk::MemoryBarrier2);
            assert_eq!(b.s_type, vk::StructureType::MEMORY_BARRIER_2);
            assert_eq!(
                b.dst_stage_mask,
                vk::PipelineStageFlags2::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR
            );
            assert_eq!(
                b.dst_access_mask,
                vk::AccessFlags2::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR
            );
            assert_eq!(
                b.p_next, &tail as *const _ as *const c_void,
                "the rest stays"
            );
            assert_eq!(
                barrier.dst_stage_mask,
                vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT,
                "the application's barrier is not written"
            );
            let plain = vk::RenderPassCreateInfo2::default().subpasses(&subpasses[..0]);
            assert!(!v2_names_density(&plain));
        }
    }

    #[test]
    fn v2_keeps_the_subpass_chain_behind_the_rate_info() {
        let tail = vk::BaseInStructure {
            s_type: vk::StructureType::from_raw(4242),
            ..Default::default()
        };
        let color = [vk::AttachmentReference2::default().attachment(0)];
        let mut sub = vk::SubpassDescription2::default().color_attachments(&color);
        sub.p_next = &tail as *const _ as *const c_void;
        let subs = [sub];
        let atts = [
            vk::AttachmentDescription2::default().format(vk::Format::R8G8B8A8_UNORM),
            vk::AttachmentDescription2::default().format(vk::Format::R8G8_UNORM),
        ];
        let ci = vk::RenderPassCreateInfo2::default()
            .attachments(&atts)
            .subpasses(&subs);
        // SAFETY: every array lives to the end of the test.
        let mut pass = unsafe { Pass2::from_v2(&ci) };
        add_shading_rate(
            &mut pass,
            1,
            vk::Extent2D {
                width: 8,
                height: 8,
            },
            vk::AttachmentStoreOp::STORE,
        );
        // SAFETY: pointers into `pass`.
        let f = unsafe {
            &*(pass.subpasses[0].p_next as *const vk::FragmentShadingRateAttachmentInfoKHR)
        };
        assert_eq!(f.p_next, &tail as *const _ as *const c_void);
        assert_eq!(
            subs[0].p_next, &tail as *const _ as *const c_void,
            "not written"
        );
        assert_eq!(atts[1].format, vk::Format::R8G8_UNORM, "not written");
        assert_eq!(pass.attachments[1].format, vk::Format::R8_UINT);
    }

    /// A subpass naming an attachment of the application's own makes the pass the application's;
    /// one whose shading-rate info names `VK_ATTACHMENT_UNUSED` (or no reference) does not, and
    /// that info is left out of the rewritten subpass's chain, the one in front the only one.
    #[test]
    fn an_applications_rate_info_decides_whose_pass_it_is() {
        let tail = vk::BaseInStructure {
            s_type: vk::StructureType::from_raw(4242),
            ..Default::default()
        };
        let texel = vk::Extent2D {
            width: 16,
            height: 16,
        };
        let color = [vk::AttachmentReference2::default().attachment(0)];
        let atts = [vk::AttachmentDescription2::default().format(vk::Format::R8G8B8A8_UNORM)];
        let ty = vk::StructureType::FRAGMENT_SHADING_RATE_ATTACHMENT_INFO_KHR;
        for (attachment, apps) in [
            (Some(1), true),
            (Some(vk::ATTACHMENT_UNUSED), false),
            (None, false),
        ] {
            let reference = vk::AttachmentReference2::default().attachment(attachment.unwrap_or(0));
            let mut info = vk::FragmentShadingRateAttachmentInfoKHR::default()
                .shading_rate_attachment_texel_size(texel);
            if attachment.is_some() {
                info.p_fragment_shading_rate_attachment = &reference;
            }
            info.p_next = &tail as *const _ as *const c_void;
            let mut sub = vk::SubpassDescription2::default().color_attachments(&color);
            sub.p_next = &info as *const _ as *const c_void;
            let subs = [sub];
            let ci = vk::RenderPassCreateInfo2::default()
                .attachments(&atts)
                .subpasses(&subs);
            // SAFETY: every array and chain lives to the end of the iteration.
            let found = unsafe { apps_rate_attachment(&ci) };
            assert_eq!(found, Ok(apps), "{attachment:?}");
            if apps {
                continue;
            }
            // SAFETY: as above.
            let mut pass = unsafe { Pass2::from_v2(&ci) };
            // SAFETY: as above.
            unsafe { pass.without_apps_rate_infos() }.unwrap();
            add_shading_rate(&mut pass, 1, texel, vk::AttachmentStoreOp::STORE);
            let mut found = 0;
            let mut node = pass.subpasses[0].p_next as *const vk::BaseInStructure<'_>;
            while !node.is_null() {
                // SAFETY: the rewritten chain, alive in `pass` and the test.
                let n = unsafe { &*node };
                found += usize::from(n.s_type == ty);
                if n.s_type == tail.s_type {
                    assert_eq!(node, &tail as *const _, "the rest shared");
                }
                node = n.p_next;
            }
            assert_eq!(found, 1, "{attachment:?}");
            assert_eq!(
                subs[0].p_next, &info as *const _ as *const c_void,
                "not written"
            );
        }
    }

    #[test]
    fn imageless_info_describes_the_shadow() {
        let formats = [SHADOW_FORMAT];
        let app_formats = [vk::Format::R8G8_UNORM];
        let app = vk::FramebufferAttachmentImageInfo::default()
            .usage(vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT)
            .width(8)
            .height(8)
            .layer_count(2)
            .view_formats(&app_formats);
        let s = shadow_attachment_info(&app, true, &formats);
        assert_eq!(s.usage, SHADOW_USAGE);
        assert_eq!((s.width, s.height, s.layer_count), (8, 8, 2));
        // SAFETY: points at `formats`.
        assert_eq!(unsafe { *s.p_view_formats }, vk::Format::R8_UINT);
        assert_eq!(shadow_attachment_info(&app, false, &formats).layer_count, 1);
    }
}
