//! `vkCreateRenderPass` made `vkCreateRenderPass2`: shading-rate attachments exist only on
//! [`VkSubpassDescription2`](https://registry.khronos.org/vulkan/specs/latest/man/html/VkSubpassDescription2.html),
//! so a version-1 pass with a density map is upgraded ([`v1_to_v2`]); `VkRenderPassMultiviewCreateInfo`
//! folds into the subpasses' view masks, the dependencies' view offsets and the correlated masks,
//! `VkRenderPassInputAttachmentAspectCreateInfo` into the input references' aspect masks
//! (docs/vulkan-fdm-on-fsr.md#render-passes). Mesa's runtime does the same: one v1→v2 conversion,
//! one v2 implementation.

use ash::vk;

use crate::vk::base::ffi::slice;
use crate::vk::translate::render_pass::{density_bits, Pass2};

/// Whether a version-1 create info names a density-map layout, stage or access bit outside the
/// density-map struct (see [`Pass2::without_density_enums`]).
///
/// # Safety
/// `ci` must be a valid create info.
pub unsafe fn v1_names_density(ci: &vk::RenderPassCreateInfo<'_>) -> bool {
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

/// The aspects an input attachment of `format` reads where version 1 names none: all of the
/// format's (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderPassInputAttachmentAspectCreateInfo.html>).
pub fn format_aspects(format: vk::Format) -> vk::ImageAspectFlags {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vk::translate::formats::SHADOW_LAYOUT;
    use crate::vk::translate::render_pass::add_shading_rate;

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
}
