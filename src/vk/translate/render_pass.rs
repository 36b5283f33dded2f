//! Render pass translation, with no device call: version 1 → version 2, the density-map attachment
//! made a shading-rate attachment, and the density enums left out.
//!
//! - `vkCreateRenderPass` with a
//!   [`VkRenderPassFragmentDensityMapCreateInfoEXT`](https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderPassFragmentDensityMapCreateInfoEXT.html)
//!   is upgraded to `vkCreateRenderPass2` ([`crate::vk::translate::render_pass_v1`]): shading-rate
//!   attachments exist only on
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
use std::sync::atomic::{AtomicBool, Ordering};

use ash::vk;

use crate::vk::base::chain::{self, ChainCopy, ChainError};
use crate::vk::base::ffi::slice;
use crate::vk::translate::formats::{SHADOW_FORMAT, SHADOW_LAYOUT, SHADOW_USAGE};
use crate::vk::translate::sync;

/// A version-2 render pass the layer builds, owning every array its pointers reach (apart from
/// what it shares with the application's create info: preserve lists and `pNext` chains).
pub struct Pass2 {
    pub attachments: Vec<vk::AttachmentDescription2<'static>>,
    pub subpasses: Vec<vk::SubpassDescription2<'static>>,
    pub dependencies: Vec<vk::SubpassDependency2<'static>>,
    pub correlated: Vec<u32>,
    /// Reference arrays of converted subpasses, kept alive for the pointers into them; each inner
    /// vector is final once pointed at.
    pub _refs: Vec<Vec<vk::AttachmentReference2<'static>>>,
    /// The shading-rate reference and one info per subpass ([`add_shading_rate`]).
    pub rate_ref: Box<vk::AttachmentReference2<'static>>,
    pub rate_infos: Vec<vk::FragmentShadingRateAttachmentInfoKHR<'static>>,
    /// Subpass chains copied without the application's attachment-less shading-rate infos
    /// ([`Pass2::without_apps_rate_infos`]), kept alive for the subpasses pointing into them.
    pub _subpass_chains: Vec<ChainCopy>,
    /// Dependency chains copied without the application's `VkMemoryBarrier2`, and the translated
    /// barriers put in front of them ([`Pass2::without_density_enums`]).
    pub _dependency_chains: Vec<ChainCopy>,
    /// Boxed: the dependencies point at them, and a growing vector would move them.
    #[allow(clippy::vec_box)]
    pub _barriers: Vec<Box<vk::MemoryBarrier2<'static>>>,
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
    /// `crate::vk::translate::sync` gives the application's density images (`GENERAL`), stages and
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
        for a in &mut self.attachments {
            a.initial_layout = sync::layout(a.initial_layout);
            a.final_layout = sync::layout(a.final_layout);
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
                    r.layout = sync::layout(r.layout);
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
            d.src_stage_mask = sync::stage(d.src_stage_mask);
            d.dst_stage_mask = sync::stage(d.dst_stage_mask);
            d.src_access_mask = sync::access(d.src_access_mask);
            d.dst_access_mask = sync::access(d.dst_access_mask);
            // SAFETY: as the caller promised; found by its sType, read only.
            let found = unsafe { chain::find::<vk::MemoryBarrier2<'static>>(d.p_next, ty) };
            let Some(m) = found.ok().flatten() else {
                continue;
            };
            // SAFETY: found by its sType in a valid chain.
            let m = unsafe { *m };
            let mut t = m;
            t.src_stage_mask = sync::stage2(m.src_stage_mask);
            t.dst_stage_mask = sync::stage2(m.dst_stage_mask);
            t.src_access_mask = sync::access2(m.src_access_mask);
            t.dst_access_mask = sync::access2(m.dst_access_mask);
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

/// [`v1_names_density`](crate::vk::translate::render_pass_v1::v1_names_density) for version 2 (dependencies' chained `VkMemoryBarrier2`s included).
///
/// # Safety
/// `ci` must be a valid create info.
pub unsafe fn v2_names_density(ci: &vk::RenderPassCreateInfo2<'_>) -> bool {
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
                            sync::stage2(m.src_stage_mask | m.dst_stage_mask)
                                != (m.src_stage_mask | m.dst_stage_mask)
                                || sync::access2(m.src_access_mask | m.dst_access_mask)
                                    != (m.src_access_mask | m.dst_access_mask)
                        })
                })
    }
}

pub fn density_bits(stages: vk::PipelineStageFlags, access: vk::AccessFlags) -> bool {
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
pub unsafe fn chain_without(
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

/// How a shading-rate attachment that later passes read again is stored: with `DONT_CARE` its
/// contents are undefined after every pass
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkAttachmentStoreOp.html>), so the
/// next pass would shade with whatever the driver left there. `NONE` keeps them without a write
/// and is core from Vulkan 1.3; below that, `STORE` (the layer enables no
/// `VK_*_load_store_op_none` of its own).
pub fn rate_store_op(api_version: u32) -> vk::AttachmentStoreOp {
    if api_version >= vk::API_VERSION_1_3 {
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

/// The density attachment of a create info's chain, if it has the density-map struct.
///
/// # Safety
/// `p_next` must be a valid chain.
pub unsafe fn density_attachment(p_next: *const c_void) -> Option<u32> {
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

/// Whether a subpass of `ci` names a shading-rate attachment of the application's own (a
/// `VkFragmentShadingRateAttachmentInfoKHR` whose reference is not `VK_ATTACHMENT_UNUSED`): such
/// a pass is the application's to shade, and is created as it came
/// (docs/injection.md#switching-it-on). `Ok(false)` also where a subpass chains the struct with no
/// attachment: the injected info then takes its place ([`Pass2::without_apps_rate_infos`]).
///
/// # Safety
/// `ci` must be a valid create info.
pub unsafe fn apps_rate_attachment(ci: &vk::RenderPassCreateInfo2<'_>) -> Result<bool, ChainError> {
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

/// The imageless framebuffer's description of the density attachment, made the shadow's.
pub fn shadow_attachment_info(
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

/// Colour targets one pass instance's end reconstructs at most: a pass with more has the rest
/// left alone, with one line in the log (docs/reconstruction.md). A fixed array keeps the plan
/// (`crate::vk::own::reconstructor::Plan`) plain data in the command buffer's record, with no
/// allocation per pass.
pub const MAX_TARGETS: usize = 8;

/// Logs, once per process, that a pass names more colour targets than a plan holds.
pub fn too_many_targets() {
    static LOGGED: AtomicBool = AtomicBool::new(false);
    if !LOGGED.swap(true, Ordering::Relaxed) {
        tracing::warn!(
            most = MAX_TARGETS,
            "a pass with more colour attachments than the layer reconstructs: the ones after \
             these keep their coarse blocks"
        );
    }
}

/// The attachments of `pass` that are reconstructed where their images are
/// (docs/reconstruction.md): of every subpass (each gets the shading-rate attachment,
/// [`add_shading_rate`], so each renders coarse), each stored single-sample colour attachment,
/// and for a multisampled one its resolve attachment where that is stored (what is read; the
/// multisampled attachment itself is left alone); with the layout the pass leaves each in. In
/// subpass order, each attachment once (the pass's end reconstructs what it leaves, whichever
/// subpasses wrote it). At most [`MAX_TARGETS`].
pub fn pass_colours(pass: &Pass2) -> [Option<(u32, vk::ImageLayout)>; MAX_TARGETS] {
    let mut out = [None; MAX_TARGETS];
    let mut n = 0;
    for s in &pass.subpasses {
        // SAFETY: the application's array, alive while `pass` is.
        let colours = unsafe { slice(s.p_color_attachments, s.color_attachment_count) };
        let resolves = if s.p_resolve_attachments.is_null() {
            &[]
        } else {
            // SAFETY: the application's array, one per colour attachment.
            unsafe { slice(s.p_resolve_attachments, s.color_attachment_count) }
        };
        for (i, c) in colours.iter().enumerate() {
            let Some(a) = pass.attachments.get(c.attachment as usize) else {
                continue;
            };
            let index = if a.samples == vk::SampleCountFlags::TYPE_1 {
                c.attachment
            } else {
                match resolves.get(i).map(|r| r.attachment) {
                    Some(r) if r != vk::ATTACHMENT_UNUSED => r,
                    _ => continue,
                }
            };
            let Some(a) = pass.attachments.get(index as usize) else {
                continue;
            };
            let kept = a.samples == vk::SampleCountFlags::TYPE_1
                && !matches!(
                    a.store_op,
                    vk::AttachmentStoreOp::DONT_CARE | vk::AttachmentStoreOp::NONE
                );
            if !kept || out[..n].iter().flatten().any(|(j, _)| *j == index) {
                continue;
            }
            if n == MAX_TARGETS {
                too_many_targets();
                return out;
            }
            out[n] = Some((index, a.final_layout));
            n += 1;
        }
    }
    out
}

/// The view mask of every subpass of `pass` together: the views it renders.
pub fn pass_view_mask(pass: &Pass2) -> u32 {
    pass.subpasses.iter().fold(0, |m, s| m | s.view_mask)
}

/// The view a dynamic rendering's colour attachment `a` leaves what it renders in, and its
/// layout: a multisampled attachment resolves into the view that is read, which the resolve
/// writes whatever the attachment's store operation; a single-sample one where it is stored.
pub fn rendering_target(
    a: &vk::RenderingAttachmentInfo<'_>,
) -> Option<(vk::ImageView, vk::ImageLayout)> {
    if a.resolve_mode != vk::ResolveModeFlags::NONE {
        return Some((a.resolve_image_view, a.resolve_image_layout))
            .filter(|(v, _)| *v != vk::ImageView::null());
    }
    let stored = !matches!(
        a.store_op,
        vk::AttachmentStoreOp::DONT_CARE | vk::AttachmentStoreOp::NONE
    );
    Some((a.image_view, a.image_layout)).filter(|(v, _)| stored && *v != vk::ImageView::null())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Of a first subpass's colour attachments, the reconstructed targets: each stored
    /// single-sample one (not one stored `DONT_CARE`), the stored resolve of a multisampled one
    /// (not the multisampled one, nor one without a resolve), in the subpass's order with their
    /// final layouts; at most [`MAX_TARGETS`].
    #[test]
    fn a_passs_colour_targets_are_its_stored_single_sample_attachments_and_resolves() {
        let att = |samples, store, layout| {
            vk::AttachmentDescription2::default()
                .format(vk::Format::R8G8B8A8_UNORM)
                .samples(samples)
                .store_op(store)
                .final_layout(layout)
        };
        let one = vk::SampleCountFlags::TYPE_1;
        let four = vk::SampleCountFlags::TYPE_4;
        let store = vk::AttachmentStoreOp::STORE;
        let src = vk::ImageLayout::TRANSFER_SRC_OPTIMAL;
        let mut atts = vec![
            att(one, store, vk::ImageLayout::GENERAL),
            att(one, vk::AttachmentStoreOp::DONT_CARE, src),
            att(four, vk::AttachmentStoreOp::DONT_CARE, src),
            att(one, store, src),
            att(four, store, src),
        ];
        // Ten more stored single-sample ones, beyond what a plan holds.
        atts.extend((0..10).map(|_| att(one, store, src)));
        let r = |a| vk::AttachmentReference2::default().attachment(a);
        let unused = r(vk::ATTACHMENT_UNUSED);
        let mut colours = vec![r(0), r(1), r(2), r(4), unused];
        let mut resolves = vec![unused, unused, r(3), unused, unused];
        colours.extend((5..15).map(r));
        resolves.extend((5..15).map(|_| unused));
        let subpasses = [vk::SubpassDescription2::default()
            .color_attachments(&colours)
            .resolve_attachments(&resolves)];
        let ci = vk::RenderPassCreateInfo2::default()
            .attachments(&atts)
            .subpasses(&subpasses);
        // SAFETY: the arrays live across the test.
        let pass = unsafe { Pass2::from_v2(&ci) };
        let got = pass_colours(&pass);
        let mut want = vec![Some((0, vk::ImageLayout::GENERAL)), Some((3, src))];
        want.extend((5..11).map(|a| Some((a, src))));
        assert_eq!(got.to_vec(), want);
    }

    /// A later subpass's stored colour attachments are targets too (every subpass renders with
    /// the shading-rate attachment), after the earlier subpasses', each attachment once; an
    /// empty subpass adds nothing; the view masks of all subpasses make the pass's.
    #[test]
    fn every_subpasss_colour_attachments_are_targets_once() {
        let att = |layout| {
            vk::AttachmentDescription2::default()
                .format(vk::Format::R8G8B8A8_UNORM)
                .samples(vk::SampleCountFlags::TYPE_1)
                .store_op(vk::AttachmentStoreOp::STORE)
                .final_layout(layout)
        };
        let (a, b) = (
            vk::ImageLayout::GENERAL,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
        );
        let atts = [att(a), att(b), att(a)];
        let r = |i| [vk::AttachmentReference2::default().attachment(i)];
        let (first, second, third) = (r(2), r(1), r(2));
        let subpasses = [
            vk::SubpassDescription2::default().view_mask(0b01),
            vk::SubpassDescription2::default()
                .color_attachments(&first)
                .view_mask(0b01),
            vk::SubpassDescription2::default()
                .color_attachments(&second)
                .view_mask(0b10),
            vk::SubpassDescription2::default()
                .color_attachments(&third)
                .view_mask(0b01),
        ];
        let ci = vk::RenderPassCreateInfo2::default()
            .attachments(&atts)
            .subpasses(&subpasses);
        // SAFETY: the arrays live across the test.
        let pass = unsafe { Pass2::from_v2(&ci) };
        let got: Vec<_> = pass_colours(&pass).into_iter().flatten().collect();
        assert_eq!(got, [(2, a), (1, b)]);
        assert_eq!(pass_view_mask(&pass), 0b11);
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
