//! Vulkan set-up the `vk::` modules share: the formats and shaders they draw with, the colour +
//! density attachments of their render passes, images and their memory, and a graphics
//! pipeline's fixed state.

use ash::vk;

/// The side of the colour images the modules draw into.
pub const SIZE: u32 = 64;
pub const COLOR: vk::Format = vk::Format::R8G8B8A8_UNORM;
pub const DENSITY: vk::Format = vk::Format::R8G8_UNORM;
pub const FDM_LAYOUT: vk::ImageLayout = vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT;
pub const VERTEX: &[u8] =
    include_bytes!("../../../crates/vkdouble/tests/shaders/fullscreen.vert.spv");
pub const FRAGMENT: &[u8] = include_bytes!("../../../crates/vkdouble/tests/shaders/solid.frag.spv");

/// SPIR-V bytes as the words a shader module takes.
pub fn spv(bytes: &[u8]) -> Vec<u32> {
    ash::util::read_spv(&mut std::io::Cursor::new(bytes)).expect("SPIR-V")
}

/// `layers` colour layers from `base`, one mip level.
pub fn range(base: u32, layers: u32) -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange {
        aspect_mask: vk::ImageAspectFlags::COLOR,
        base_mip_level: 0,
        level_count: 1,
        base_array_layer: base,
        layer_count: layers,
    }
}

/// A square, optimally tiled 2D image of `layers` layers, one mip level and one sample.
pub fn image_info(
    format: vk::Format,
    size: u32,
    layers: u32,
    usage: vk::ImageUsageFlags,
) -> vk::ImageCreateInfo<'static> {
    vk::ImageCreateInfo::default()
        .image_type(vk::ImageType::TYPE_2D)
        .format(format)
        .extent(vk::Extent3D {
            width: size,
            height: size,
            depth: 1,
        })
        .mip_levels(1)
        .array_layers(layers)
        .samples(vk::SampleCountFlags::TYPE_1)
        .tiling(vk::ImageTiling::OPTIMAL)
        .usage(usage)
}

/// The first memory type `bits` allows that has every flag in `want`.
pub fn memory_type(
    memory: &vk::PhysicalDeviceMemoryProperties,
    bits: u32,
    want: vk::MemoryPropertyFlags,
) -> u32 {
    (0..memory.memory_type_count)
        .find(|&i| {
            bits & (1 << i) != 0
                && memory.memory_types[i as usize]
                    .property_flags
                    .contains(want)
        })
        .expect("a memory type")
}

/// An allocation of `req`'s size in the first memory type it allows that has every flag in `want`.
pub fn allocate_info(
    memory: &vk::PhysicalDeviceMemoryProperties,
    req: vk::MemoryRequirements,
    want: vk::MemoryPropertyFlags,
) -> vk::MemoryAllocateInfo<'static> {
    vk::MemoryAllocateInfo::default()
        .allocation_size(req.size)
        .memory_type_index(memory_type(memory, req.memory_type_bits, want))
}

/// The colour attachment (cleared, stored, ending in `color_final`) and the density map
/// attachment of a pass, as v1 or v2 descriptions (both have the same setters).
macro_rules! color_and_density {
    ($ty:ty, $color_final:expr) => {
        [
            <$ty>::default()
                .format(COLOR)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::STORE)
                .initial_layout(vk::ImageLayout::UNDEFINED)
                .final_layout($color_final),
            <$ty>::default()
                .format(DENSITY)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(vk::AttachmentLoadOp::DONT_CARE)
                .store_op(vk::AttachmentStoreOp::DONT_CARE)
                .initial_layout(FDM_LAYOUT)
                .final_layout(FDM_LAYOUT),
        ]
    };
}

/// [`color_and_density!`] for `vkCreateRenderPass`.
pub fn attachments(color_final: vk::ImageLayout) -> [vk::AttachmentDescription; 2] {
    color_and_density!(vk::AttachmentDescription, color_final)
}

/// [`color_and_density!`] for `vkCreateRenderPass2`.
pub fn attachments2(color_final: vk::ImageLayout) -> [vk::AttachmentDescription2<'static>; 2] {
    color_and_density!(vk::AttachmentDescription2, color_final)
}

/// A render pass v2 of one subpass that draws into attachment 0 (in `COLOR_ATTACHMENT_OPTIMAL`)
/// with attachment 1 as its fragment density map: the attachments of [`attachments2`], the colour
/// one ending in `color_final`, the map starting in `map_initial`.
///
/// # Safety
/// `d` must be alive.
pub unsafe fn density_pass(
    d: &ash::Device,
    color_final: vk::ImageLayout,
    map_initial: vk::ImageLayout,
) -> Result<vk::RenderPass, vk::Result> {
    let mut atts = attachments2(color_final);
    atts[1].initial_layout = map_initial;
    let color_ref = [vk::AttachmentReference2::default()
        .attachment(0)
        .layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)];
    let subpass = [vk::SubpassDescription2::default()
        .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
        .color_attachments(&color_ref)];
    let mut fdm = vk::RenderPassFragmentDensityMapCreateInfoEXT::default()
        .fragment_density_map_attachment(vk::AttachmentReference {
            attachment: 1,
            layout: FDM_LAYOUT,
        });
    let info = vk::RenderPassCreateInfo2::default()
        .attachments(&atts)
        .subpasses(&subpass)
        .push_next(&mut fdm);
    // SAFETY: the caller's promise; the structs live across the call.
    unsafe { d.create_render_pass2(&info, None) }
}

/// The vertex and fragment stages of `modules`, each entered at `main`.
pub fn stages(modules: [vk::ShaderModule; 2]) -> [vk::PipelineShaderStageCreateInfo<'static>; 2] {
    [
        vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::VERTEX)
            .module(modules[0])
            .name(c"main"),
        vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::FRAGMENT)
            .module(modules[1])
            .name(c"main"),
    ]
}

static BLEND_ATTACHMENT: [vk::PipelineColorBlendAttachmentState; 1] =
    [vk::PipelineColorBlendAttachmentState {
        blend_enable: vk::FALSE,
        src_color_blend_factor: vk::BlendFactor::ZERO,
        dst_color_blend_factor: vk::BlendFactor::ZERO,
        color_blend_op: vk::BlendOp::ADD,
        src_alpha_blend_factor: vk::BlendFactor::ZERO,
        dst_alpha_blend_factor: vk::BlendFactor::ZERO,
        alpha_blend_op: vk::BlendOp::ADD,
        color_write_mask: vk::ColorComponentFlags::RGBA,
    }];
static DYNAMIC_STATES: [vk::DynamicState; 2] =
    [vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];

/// A graphics pipeline's fixed state: no vertex input, a triangle list, dynamic viewport and
/// scissor, filled and not culled, one sample, one RGBA colour output without blending.
pub struct Fixed {
    pub vertex: vk::PipelineVertexInputStateCreateInfo<'static>,
    pub assembly: vk::PipelineInputAssemblyStateCreateInfo<'static>,
    pub viewport: vk::PipelineViewportStateCreateInfo<'static>,
    pub raster: vk::PipelineRasterizationStateCreateInfo<'static>,
    pub multisample: vk::PipelineMultisampleStateCreateInfo<'static>,
    pub depth: vk::PipelineDepthStencilStateCreateInfo<'static>,
    pub blend: vk::PipelineColorBlendStateCreateInfo<'static>,
    pub dynamic: vk::PipelineDynamicStateCreateInfo<'static>,
}

impl Fixed {
    pub fn new() -> Fixed {
        Fixed {
            vertex: vk::PipelineVertexInputStateCreateInfo::default(),
            assembly: vk::PipelineInputAssemblyStateCreateInfo::default()
                .topology(vk::PrimitiveTopology::TRIANGLE_LIST),
            viewport: vk::PipelineViewportStateCreateInfo::default()
                .viewport_count(1)
                .scissor_count(1),
            raster: vk::PipelineRasterizationStateCreateInfo::default()
                .polygon_mode(vk::PolygonMode::FILL)
                .cull_mode(vk::CullModeFlags::NONE)
                .line_width(1.0),
            multisample: vk::PipelineMultisampleStateCreateInfo::default()
                .rasterization_samples(vk::SampleCountFlags::TYPE_1),
            depth: vk::PipelineDepthStencilStateCreateInfo::default(),
            blend: vk::PipelineColorBlendStateCreateInfo::default().attachments(&BLEND_ATTACHMENT),
            dynamic: vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&DYNAMIC_STATES),
        }
    }

    /// A whole pipeline's create info: `stages`, this state (no depth) and `layout`.
    pub fn info<'a>(
        &'a self,
        stages: &'a [vk::PipelineShaderStageCreateInfo<'a>],
        layout: vk::PipelineLayout,
    ) -> vk::GraphicsPipelineCreateInfo<'a> {
        vk::GraphicsPipelineCreateInfo::default()
            .stages(stages)
            .vertex_input_state(&self.vertex)
            .input_assembly_state(&self.assembly)
            .viewport_state(&self.viewport)
            .rasterization_state(&self.raster)
            .multisample_state(&self.multisample)
            .color_blend_state(&self.blend)
            .dynamic_state(&self.dynamic)
            .layout(layout)
    }
}

/// The whole `SIZE`×`SIZE` colour image.
pub const AREA: vk::Rect2D = vk::Rect2D {
    offset: vk::Offset2D { x: 0, y: 0 },
    extent: vk::Extent2D {
        width: SIZE,
        height: SIZE,
    },
};

/// What the colour attachment is cleared to: opaque blue.
pub const CLEAR: [vk::ClearValue; 1] = [vk::ClearValue {
    color: vk::ClearColorValue {
        float32: [0.0, 0.0, 1.0, 1.0],
    },
}];

/// Records a draw of one full-screen triangle with `pipeline` over [`AREA`].
///
/// # Safety
/// `cb` must be recording on `d` inside a pass or rendering that `pipeline` fits.
pub unsafe fn draw_fullscreen(d: &ash::Device, cb: vk::CommandBuffer, pipeline: vk::Pipeline) {
    // SAFETY: the caller's promise.
    unsafe {
        d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, pipeline);
        d.cmd_set_viewport(
            cb,
            0,
            &[vk::Viewport {
                x: 0.0,
                y: 0.0,
                width: SIZE as f32,
                height: SIZE as f32,
                min_depth: 0.0,
                max_depth: 1.0,
            }],
        );
        d.cmd_set_scissor(cb, 0, &[AREA]);
        d.cmd_draw(cb, 3, 1, 0, 0);
    }
}

/// Records the barrier that takes each of `images` (`layers` layers, content undefined) to
/// `COLOR_ATTACHMENT_OPTIMAL` before a pass clears and writes it.
///
/// # Safety
/// `cb` must be recording on `d`; the images must be `d`'s.
pub unsafe fn to_color_attachment(
    d: &ash::Device,
    cb: vk::CommandBuffer,
    images: &[vk::Image],
    layers: u32,
) {
    let barriers: Vec<_> = images
        .iter()
        .map(|&image| {
            vk::ImageMemoryBarrier::default()
                .image(image)
                .subresource_range(range(0, layers))
                .old_layout(vk::ImageLayout::UNDEFINED)
                .new_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                .dst_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        })
        .collect();
    // SAFETY: the caller's promise; the barriers live across the call.
    unsafe {
        d.cmd_pipeline_barrier(
            cb,
            vk::PipelineStageFlags::TOP_OF_PIPE,
            vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &barriers,
        );
    }
}

/// A framebuffer of `pass` over `views`, `side`×`side` and one layer.
///
/// # Safety
/// `d` must be alive; `pass` and `views` must be `d`'s and fit each other.
pub unsafe fn framebuffer(
    d: &ash::Device,
    pass: vk::RenderPass,
    views: &[vk::ImageView],
    side: u32,
) -> vk::Framebuffer {
    // SAFETY: the caller's promise; the struct lives across the call.
    unsafe {
        d.create_framebuffer(
            &vk::FramebufferCreateInfo::default()
                .render_pass(pass)
                .attachments(views)
                .width(side)
                .height(side)
                .layers(1),
            None,
        )
    }
    .expect("vkCreateFramebuffer")
}

/// Records `vkCmdBeginRenderPass2` of `pass` and `fb` over [`AREA`], clearing colour to [`CLEAR`],
/// with the subpass's commands inline.
///
/// # Safety
/// `cb` must be recording on `d` outside a pass; `pass` and `fb` must be `d`'s and fit [`AREA`].
pub unsafe fn begin_pass(
    d: &ash::Device,
    cb: vk::CommandBuffer,
    pass: vk::RenderPass,
    fb: vk::Framebuffer,
) {
    // SAFETY: the caller's promise; the structs live across the call.
    unsafe {
        d.cmd_begin_render_pass2(
            cb,
            &vk::RenderPassBeginInfo::default()
                .render_pass(pass)
                .framebuffer(fb)
                .render_area(AREA)
                .clear_values(&CLEAR),
            &vk::SubpassBeginInfo::default().contents(vk::SubpassContents::INLINE),
        );
    }
}

/// A colour attachment of `view` for `vkCmdBeginRendering`, in `COLOR_ATTACHMENT_OPTIMAL`, cleared
/// to [`CLEAR`] and stored.
pub fn cleared_color(view: vk::ImageView) -> vk::RenderingAttachmentInfo<'static> {
    vk::RenderingAttachmentInfo::default()
        .image_view(view)
        .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
        .load_op(vk::AttachmentLoadOp::CLEAR)
        .store_op(vk::AttachmentStoreOp::STORE)
        .clear_value(CLEAR[0])
}
