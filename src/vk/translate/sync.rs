//! Synchronisation without the density map (docs/vulkan-fdm-on-fsr.md#mapping): the density-map
//! layout, stage and access bits become what the driver knows, and a barrier that moves a density
//! image with a shadow into the density-map layout gets the shadow's barrier beside it.
//!
//! - stage `FRAGMENT_DENSITY_PROCESS_EXT` → `FRAGMENT_SHADING_RATE_ATTACHMENT_KHR`, access
//!   `FRAGMENT_DENSITY_MAP_READ_EXT` → `FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR`: the FDM bits
//!   are invalid without the FDM feature, which the driver never has enabled
//!   (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkPipelineStageFlagBits.html>);
//! - layout `FRAGMENT_DENSITY_MAP_OPTIMAL_EXT` → `GENERAL` on the application's own image: that
//!   image is an `R8G8_UNORM` image without the density-map usage on the driver's side, and
//!   `FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR` would need the shading-rate usage, which an
//!   `R8G8_UNORM` image cannot have
//!   (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkImageMemoryBarrier.html>,
//!   VUID-VkImageMemoryBarrier-oldLayout-02088); `GENERAL` is valid for every usage;
//! - where the image has a shading-rate shadow ([`crate::bridge::shadow_of`]), a barrier that moves
//!   it into the density-map layout also orders the shadow: an added barrier on the shadow, in
//!   `FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR` on both sides (the shadow never leaves that
//!   layout outside fovea's own uploads), with the translated stages and accesses.

use ash::vk;

use crate::vk::base::ffi::slice;

pub const FDM_LAYOUT: vk::ImageLayout = vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT;
const FSR_LAYOUT: vk::ImageLayout = vk::ImageLayout::FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR;
/// What the application's own density image is moved to instead of [`FDM_LAYOUT`].
pub const IMAGE_LAYOUT: vk::ImageLayout = vk::ImageLayout::GENERAL;

const STAGE: vk::PipelineStageFlags = vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT;
const FSR_STAGE: vk::PipelineStageFlags =
    vk::PipelineStageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR;
const ACCESS: vk::AccessFlags = vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT;
const FSR_ACCESS: vk::AccessFlags = vk::AccessFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR;
const STAGE2: vk::PipelineStageFlags2 = vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT;
const FSR_STAGE2: vk::PipelineStageFlags2 =
    vk::PipelineStageFlags2::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR;
pub const ACCESS2: vk::AccessFlags2 = vk::AccessFlags2::FRAGMENT_DENSITY_MAP_READ_EXT;
pub const FSR_ACCESS2: vk::AccessFlags2 =
    vk::AccessFlags2::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR;

/// A stage mask without the density-map stage.
pub fn stage(s: vk::PipelineStageFlags) -> vk::PipelineStageFlags {
    if s.intersects(STAGE) {
        (s & !STAGE) | FSR_STAGE
    } else {
        s
    }
}

/// An access mask without the density-map read.
pub fn access(a: vk::AccessFlags) -> vk::AccessFlags {
    if a.intersects(ACCESS) {
        (a & !ACCESS) | FSR_ACCESS
    } else {
        a
    }
}

/// [`stage`] for the 64-bit masks.
pub fn stage2(s: vk::PipelineStageFlags2) -> vk::PipelineStageFlags2 {
    if s.intersects(STAGE2) {
        (s & !STAGE2) | FSR_STAGE2
    } else {
        s
    }
}

/// [`access`] for the 64-bit masks.
pub fn access2(a: vk::AccessFlags2) -> vk::AccessFlags2 {
    if a.intersects(ACCESS2) {
        (a & !ACCESS2) | FSR_ACCESS2
    } else {
        a
    }
}

/// The layout the application's density image gets instead of the density-map layout.
pub fn layout(l: vk::ImageLayout) -> vk::ImageLayout {
    if l == FDM_LAYOUT {
        IMAGE_LAYOUT
    } else {
        l
    }
}

/// The shadow's whole subresource range.
fn shadow_range(layers: u32) -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange {
        aspect_mask: vk::ImageAspectFlags::COLOR,
        base_mip_level: 0,
        level_count: 1,
        base_array_layer: 0,
        layer_count: layers.max(1),
    }
}

/// The translated barrier for the application's image, and, where it moves a density image with a
/// shadow into the density-map layout, the shadow's.
pub fn image_barrier(
    b: &vk::ImageMemoryBarrier<'static>,
    shadow_of: impl Fn(vk::Image) -> Option<crate::bridge::Shadow>,
) -> (
    vk::ImageMemoryBarrier<'static>,
    Option<vk::ImageMemoryBarrier<'static>>,
) {
    let mut out = *b;
    out.src_access_mask = access(b.src_access_mask);
    out.dst_access_mask = access(b.dst_access_mask);
    out.old_layout = layout(b.old_layout);
    out.new_layout = layout(b.new_layout);
    let shadow = (b.new_layout == FDM_LAYOUT)
        .then(|| shadow_of(b.image))
        .flatten()
        .map(|s| {
            let mut sb = out;
            sb.p_next = std::ptr::null();
            sb.old_layout = FSR_LAYOUT;
            sb.new_layout = FSR_LAYOUT;
            sb.src_queue_family_index = vk::QUEUE_FAMILY_IGNORED;
            sb.dst_queue_family_index = vk::QUEUE_FAMILY_IGNORED;
            sb.image = s.image;
            sb.subresource_range = shadow_range(s.layers);
            sb
        });
    (out, shadow)
}

/// [`image_barrier`] for `VkImageMemoryBarrier2`.
pub fn image_barrier2(
    b: &vk::ImageMemoryBarrier2<'static>,
    shadow_of: impl Fn(vk::Image) -> Option<crate::bridge::Shadow>,
) -> (
    vk::ImageMemoryBarrier2<'static>,
    Option<vk::ImageMemoryBarrier2<'static>>,
) {
    let mut out = *b;
    out.src_stage_mask = stage2(b.src_stage_mask);
    out.dst_stage_mask = stage2(b.dst_stage_mask);
    out.src_access_mask = access2(b.src_access_mask);
    out.dst_access_mask = access2(b.dst_access_mask);
    out.old_layout = layout(b.old_layout);
    out.new_layout = layout(b.new_layout);
    let shadow = (b.new_layout == FDM_LAYOUT)
        .then(|| shadow_of(b.image))
        .flatten()
        .map(|s| {
            let mut sb = out;
            sb.p_next = std::ptr::null();
            sb.old_layout = FSR_LAYOUT;
            sb.new_layout = FSR_LAYOUT;
            sb.src_queue_family_index = vk::QUEUE_FAMILY_IGNORED;
            sb.dst_queue_family_index = vk::QUEUE_FAMILY_IGNORED;
            sb.image = s.image;
            sb.subresource_range = shadow_range(s.layers);
            sb
        });
    (out, shadow)
}

fn touches_image(b: &vk::ImageMemoryBarrier<'_>) -> bool {
    b.old_layout == FDM_LAYOUT
        || b.new_layout == FDM_LAYOUT
        || (b.src_access_mask | b.dst_access_mask).intersects(ACCESS)
}

fn touches_image2(b: &vk::ImageMemoryBarrier2<'_>) -> bool {
    b.old_layout == FDM_LAYOUT
        || b.new_layout == FDM_LAYOUT
        || (b.src_access_mask | b.dst_access_mask).intersects(ACCESS2)
        || (b.src_stage_mask | b.dst_stage_mask).intersects(STAGE2)
}

fn touches2(access: vk::AccessFlags2, stage: vk::PipelineStageFlags2) -> bool {
    access.intersects(ACCESS2) || stage.intersects(STAGE2)
}

/// Whether a version-1 barrier call needs translating: a scan of masks and layouts only.
///
/// # Safety
/// The arrays must be valid for their counts.
#[allow(clippy::too_many_arguments)]
pub unsafe fn needs1(
    src: vk::PipelineStageFlags,
    dst: vk::PipelineStageFlags,
    memory: &[vk::MemoryBarrier<'_>],
    buffers: &[vk::BufferMemoryBarrier<'_>],
    images: &[vk::ImageMemoryBarrier<'_>],
) -> bool {
    (src | dst).intersects(STAGE)
        || memory
            .iter()
            .any(|b| (b.src_access_mask | b.dst_access_mask).intersects(ACCESS))
        || buffers
            .iter()
            .any(|b| (b.src_access_mask | b.dst_access_mask).intersects(ACCESS))
        || images.iter().any(touches_image)
}

/// Whether a dependency info needs translating.
pub fn needs2(d: &vk::DependencyInfo<'_>) -> bool {
    // SAFETY: the application's arrays, valid for their counts (the command's valid usage).
    let (m, b, i) = unsafe {
        (
            slice(d.p_memory_barriers, d.memory_barrier_count),
            slice(d.p_buffer_memory_barriers, d.buffer_memory_barrier_count),
            slice(d.p_image_memory_barriers, d.image_memory_barrier_count),
        )
    };
    m.iter().any(|b| {
        touches2(
            b.src_access_mask | b.dst_access_mask,
            b.src_stage_mask | b.dst_stage_mask,
        )
    }) || b.iter().any(|b| {
        touches2(
            b.src_access_mask | b.dst_access_mask,
            b.src_stage_mask | b.dst_stage_mask,
        )
    }) || i.iter().any(touches_image2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bridge::Shadow;
    use ash::vk::Handle as _;

    fn range(layers: u32) -> vk::ImageSubresourceRange {
        vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: 0,
            layer_count: layers,
        }
    }

    #[test]
    fn masks_and_layouts_are_translated_and_nothing_else() {
        let s = vk::PipelineStageFlags::TRANSFER | STAGE;
        assert_eq!(stage(s), vk::PipelineStageFlags::TRANSFER | FSR_STAGE);
        assert_eq!(
            stage(vk::PipelineStageFlags::ALL_COMMANDS),
            vk::PipelineStageFlags::ALL_COMMANDS
        );
        assert_eq!(access(ACCESS | vk::AccessFlags::SHADER_READ).as_raw(), {
            (FSR_ACCESS | vk::AccessFlags::SHADER_READ).as_raw()
        });
        assert_eq!(stage2(STAGE2), FSR_STAGE2);
        assert_eq!(access2(ACCESS2), FSR_ACCESS2);
        assert_eq!(
            access2(vk::AccessFlags2::MEMORY_READ),
            vk::AccessFlags2::MEMORY_READ
        );
        assert_eq!(layout(FDM_LAYOUT), vk::ImageLayout::GENERAL);
        assert_eq!(
            layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL),
            vk::ImageLayout::TRANSFER_DST_OPTIMAL
        );
    }

    #[test]
    fn an_image_moved_into_the_density_layout_orders_its_shadow_too() {
        let image = vk::Image::from_raw(7);
        let shadow = Shadow {
            device: vk::Device::from_raw(3),
            image: vk::Image::from_raw(9),
            extent: [4, 4],
            layers: 1,
            app_layers: 2,
        };
        let lookup = |i: vk::Image| (i == image).then_some(shadow);
        let b = vk::ImageMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(ACCESS)
            .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
            .new_layout(FDM_LAYOUT)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(image)
            .subresource_range(range(2));
        let (c, s) = image_barrier(&b, lookup);
        assert_eq!(c.new_layout, vk::ImageLayout::GENERAL);
        assert_eq!(c.old_layout, vk::ImageLayout::TRANSFER_DST_OPTIMAL);
        assert_eq!(c.dst_access_mask, FSR_ACCESS);
        assert_eq!(c.image, image);
        assert_eq!(c.subresource_range.layer_count, 2);
        let s = s.expect("the shadow's barrier");
        assert_eq!(s.image, shadow.image);
        assert_eq!((s.old_layout, s.new_layout), (FSR_LAYOUT, FSR_LAYOUT));
        assert_eq!(s.subresource_range.layer_count, 1);
        assert_eq!(s.src_access_mask, vk::AccessFlags::TRANSFER_WRITE);
        assert_eq!(s.dst_access_mask, FSR_ACCESS);
        // Out of the density layout, or an image without a shadow: no added barrier.
        let back = b
            .old_layout(FDM_LAYOUT)
            .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL);
        let (c, s) = image_barrier(&back, lookup);
        assert_eq!(c.old_layout, vk::ImageLayout::GENERAL);
        assert!(s.is_none());
        let other = b.image(vk::Image::from_raw(8));
        assert!(image_barrier(&other, lookup).1.is_none());
        // The application's barrier is untouched.
        assert_eq!(b.new_layout, FDM_LAYOUT);

        let b2 = vk::ImageMemoryBarrier2::default()
            .src_stage_mask(vk::PipelineStageFlags2::COPY)
            .dst_stage_mask(STAGE2)
            .dst_access_mask(ACCESS2)
            .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
            .new_layout(FDM_LAYOUT)
            .image(image)
            .subresource_range(range(2));
        let (c, s) = image_barrier2(&b2, lookup);
        assert_eq!(c.dst_stage_mask, FSR_STAGE2);
        assert_eq!(c.new_layout, vk::ImageLayout::GENERAL);
        assert_eq!(s.expect("shadow").dst_stage_mask, FSR_STAGE2);
    }

    #[test]
    fn only_calls_with_density_bits_are_translated() {
        let plain = [vk::ImageMemoryBarrier::default()
            .old_layout(vk::ImageLayout::UNDEFINED)
            .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)];
        let stages = vk::PipelineStageFlags::TRANSFER;
        // SAFETY: arrays on the stack.
        unsafe {
            assert!(!needs1(stages, stages, &[], &[], &plain));
            assert!(needs1(stages, STAGE, &[], &[], &plain));
            let fdm = [plain[0].new_layout(FDM_LAYOUT)];
            assert!(needs1(stages, stages, &[], &[], &fdm));
            let mem = [vk::MemoryBarrier::default().dst_access_mask(ACCESS)];
            assert!(needs1(stages, stages, &mem, &[], &[]));
        }
        let images = [vk::ImageMemoryBarrier2::default().dst_stage_mask(STAGE2)];
        let d = vk::DependencyInfo::default();
        assert!(!needs2(&d));
        assert!(needs2(&d.image_memory_barriers(&images)));
    }
}
