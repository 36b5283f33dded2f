//! The example's rendering: eye passes into the swapchain image, with each eye's layer of the
//! image's density map either attached to the pass (devices with VK_EXT_fragment_density_map) or
//! sampled into a debug overlay (devices without), optional offscreen passes before them, and
//! optional read-back of what was drawn.
//!
//! The swapchain holds the two views in one of two layouts ([`Layout`]): an array of two (a pass per
//! eye, each into its layer), or one double-wide image (one pass over the whole image, each eye drawn
//! with its own viewport and scissor in its half). Passes are begun either with classic render
//! passes or with `vkCmdBeginRenderingKHR` (`VK_KHR_dynamic_rendering`), so that a layer that
//! changes passes (fovea's injection, docs/injection.md#how-the-attachment-gets-in) meets both.
//!
//! Not multiview: Mesa 22.3's lavapipe (Debian 12, where the tests run) draws only view 0 of a
//! multiview subpass (its clears reach both layers), and the test reads back both eyes.
//!
//! Everything is made once for the swapchain's images; a frame records one command buffer, submits
//! it and waits for it.

use std::ffi::c_void;

use ash::vk;

/// SPIR-V built from `shaders/` by `shaders/build.sh`.
pub(crate) const VERTEX: &[u8] = include_bytes!("shaders/fullscreen.vert.spv");
pub(crate) const PATTERN: &[u8] = include_bytes!("shaders/pattern.frag.spv");
pub(crate) const OVERLAY: &[u8] = include_bytes!("shaders/overlay.frag.spv");
pub(crate) const HEAVY: &[u8] = include_bytes!("shaders/heavy.frag.spv");
pub(crate) const HEAVY_OVERLAY: &[u8] = include_bytes!("shaders/heavy_overlay.frag.spv");
pub(crate) const COMPOSITE: &[u8] = include_bytes!("shaders/composite.frag.spv");
pub(crate) const SCENE: &[u8] = include_bytes!("shaders/scene.frag.spv");
pub(crate) const SCENE_OVERLAY: &[u8] = include_bytes!("shaders/scene_overlay.frag.spv");

/// GPU timestamps around each eye pass: a query pool of two per pass, and nanoseconds per tick.
struct Timer {
    pool: vk::QueryPool,
    period_ns: f64,
}

/// Two views: eye `i` is view `i` of the projection layer.
const EYES: usize = 2;
/// The density map's layers: one per eye (the FB path renders into an array of two).
const LAYERS: u32 = 2;

/// The offscreen targets (`--offscreen`), rendered before the eye passes every frame: a square
/// "shadow map" and a tiny target sampled from it, which the eye passes then sample into a corner.
/// Neither is eye-shaped (docs/injection.md#which-passes): a layer that foveates eye passes must
/// leave both at full rate.
pub const OFFSCREEN: [(u32, u32); 2] = [(256, 256), (64, 36)];
/// The offscreen "shadow map"'s stripes (linear RGB): blue, unlike any level's tint, so that the
/// corner it reaches the eyes in can be told apart in a frame read back.
pub const OFFSCREEN_TINT: [f32; 4] = [0.1, 0.2, 0.9, 1.0];
/// The eye's corner the tiny target is drawn into: the upper right, a quarter of each side.
pub const CORNER: u32 = 4;

/// How the swapchain holds the two views.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// One image of two layers per swapchain image; view `i` is layer `i` (one pass per eye).
    Array,
    /// One image of one layer, twice a view's width; view `i` is half `i` (one pass, two viewports).
    DoubleWide,
}

/// How the density maps take part in rendering.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Attached to the render pass (`VkRenderPassFragmentDensityMapCreateInfoEXT`): the device shades
    /// coarser fragments where the map asks for them. fovea leaves the maps in
    /// FRAGMENT_DENSITY_MAP_OPTIMAL_EXT on such devices.
    Attachment,
    /// Sampled by the fragment shader into the lower-left quarter of each view. fovea leaves the maps
    /// in SHADER_READ_ONLY_OPTIMAL where the device cannot render with them.
    Overlay,
    /// Neither: the device can do neither with an R8G8 image (or has FDM without
    /// `fragmentDensityMapNonSubsampledImages`, which the runtime's non-subsampled images need).
    None,
    /// The application never asked for foveation (`--no-fb`): no XR_FB_foveation extension, no
    /// density maps; plain passes, as an application unaware of foveation renders.
    Absent,
}

impl Mode {
    /// The layout fovea leaves a density image in, and the stage and access that read it there.
    fn resting(self) -> (vk::ImageLayout, vk::PipelineStageFlags, vk::AccessFlags) {
        match self {
            Mode::Attachment => (
                vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT,
                vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
                vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT,
            ),
            Mode::Overlay | Mode::None | Mode::Absent => (
                vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
                vk::PipelineStageFlags::FRAGMENT_SHADER,
                vk::AccessFlags::SHADER_READ,
            ),
        }
    }
}

/// A swapchain's images and their density maps.
pub struct Targets<'a> {
    pub format: vk::Format,
    /// One view's extent; a double-wide image is twice as wide.
    pub extent: (u32, u32),
    pub layout: Layout,
    pub images: &'a [vk::Image],
    /// `(image, width, height)` per swapchain image, from XrSwapchainImageFoveationVulkanFB; empty
    /// in [`Mode::Absent`].
    pub density: &'a [(vk::Image, u32, u32)],
}

/// What the renderer does besides the eye passes, and how it begins passes.
#[derive(Clone, Copy, Debug, Default)]
pub struct Setup {
    /// Allocate the host buffer [`Renderer::draw`] copies into when asked to.
    pub readback: bool,
    /// The fill-bound fragment shader (`--heavy`).
    pub heavy: bool,
    /// The room of `scene.frag` instead of the stripes (`--scene room`); not with `heavy`.
    pub room: bool,
    /// The offscreen passes of [`OFFSCREEN`] before the eye passes (`--offscreen`).
    pub offscreen: bool,
    /// `vkCmdBeginRenderingKHR` instead of render passes (`--dynamic-rendering`); the device has
    /// `VK_KHR_dynamic_rendering` and its feature enabled.
    pub dynamic_rendering: bool,
}

/// What a frame reads back into host memory after drawing.
#[derive(Clone, Copy, Debug, Default)]
pub struct Read {
    /// Both views of the swapchain image (RGBA8, sRGB-encoded), view 0 first.
    pub eyes: bool,
    /// Both layers of the density map (R8G8).
    pub density: bool,
}

/// The readback buffer: host-visible, mapped once; eyes first, then the density map.
struct Readback {
    buffer: vk::Buffer,
    memory: vk::DeviceMemory,
    mapped: *const u8,
    eye_bytes: usize,
}

/// One eye pass of a swapchain image: the colour view it renders into, its framebuffer (render
/// passes), and the eyes it draws with the x offset of each eye's viewport.
#[derive(Clone, Default)]
struct Pass {
    colour: vk::ImageView,
    /// The density map's layer for this pass ([`Mode::Attachment`], array layout).
    density: vk::ImageView,
    framebuffer: vk::Framebuffer,
    /// The render area's extent.
    extent: (u32, u32),
    /// `(eye, x)`: eye `eye` is drawn with a viewport at `x`, a view's extent wide.
    draws: Vec<(usize, u32)>,
}

/// A swapchain image, its eye passes and its density map.
struct PerImage {
    passes: Vec<Pass>,
    image: vk::Image,
    density_image: vk::Image,
    density_extent: (u32, u32),
    /// Per eye, its layer of the density map and the overlay's descriptor set sampling it.
    density_views: [vk::ImageView; EYES],
    sets: [vk::DescriptorSet; EYES],
}

/// An offscreen target of [`OFFSCREEN`]: an image of the app's own, its view, framebuffer (render
/// passes), and a descriptor set that samples it (for the next pass in the chain).
#[derive(Default)]
struct Offscreen {
    image: vk::Image,
    memory: vk::DeviceMemory,
    view: vk::ImageView,
    framebuffer: vk::Framebuffer,
    set: vk::DescriptorSet,
    extent: (u32, u32),
}

/// Which passes a pipeline is made for (render pass compatibility, or the formats of dynamic
/// rendering).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Target {
    Eye,
    Offscreen,
}

pub struct Renderer<'d> {
    device: &'d ash::Device,
    /// `VK_KHR_dynamic_rendering`'s commands where [`Setup::dynamic_rendering`].
    rendering: Option<ash::khr::dynamic_rendering::Device>,
    queue: vk::Queue,
    mode: Mode,
    setup: Setup,
    format: vk::Format,
    /// One view's extent.
    extent: (u32, u32),
    layout: Layout,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    /// Null with dynamic rendering.
    render_pass: vk::RenderPass,
    offscreen_pass: vk::RenderPass,
    set_layout: vk::DescriptorSetLayout,
    descriptor_pool: vk::DescriptorPool,
    sampler: vk::Sampler,
    pipeline_layout: vk::PipelineLayout,
    /// The eye passes' stripes (with the overlay or the heavy loop as the mode and setup say).
    pipeline: vk::Pipeline,
    /// The tiny offscreen target drawn into an eye's corner (`--offscreen`).
    eye_composite: vk::Pipeline,
    /// The offscreen passes': stripes into the "shadow map", and the shadow map into the tiny one.
    offscreen_pattern: vk::Pipeline,
    offscreen_composite: vk::Pipeline,
    images: Vec<PerImage>,
    offscreen: Vec<Offscreen>,
    readback: Option<Readback>,
    /// `None` where the queue cannot write timestamps.
    timer: Option<Timer>,
}

fn e(what: &'static str) -> impl Fn(vk::Result) -> String {
    move |r| format!("{what}: {r}")
}

impl<'d> Renderer<'d> {
    /// Makes everything the frames need.
    ///
    /// # Safety
    /// `device` made on `physical_device`; `queue` from `queue_family`; the targets' images are the
    /// swapchain's and fovea's, alive until [`Renderer::destroy`]; with
    /// [`Setup::dynamic_rendering`], the device has `VK_KHR_dynamic_rendering` and its feature.
    pub unsafe fn new(
        (instance, physical_device): (&ash::Instance, vk::PhysicalDevice),
        device: &'d ash::Device,
        (queue, queue_family): (vk::Queue, u32),
        targets: &Targets,
        mode: Mode,
        setup: Setup,
    ) -> Result<Renderer<'d>, String> {
        let mut r = Renderer {
            device,
            rendering: setup
                .dynamic_rendering
                .then(|| ash::khr::dynamic_rendering::Device::new(instance, device)),
            queue,
            mode,
            setup,
            format: targets.format,
            extent: targets.extent,
            layout: targets.layout,
            pool: vk::CommandPool::null(),
            cmd: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
            render_pass: vk::RenderPass::null(),
            offscreen_pass: vk::RenderPass::null(),
            set_layout: vk::DescriptorSetLayout::null(),
            descriptor_pool: vk::DescriptorPool::null(),
            sampler: vk::Sampler::null(),
            pipeline_layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            eye_composite: vk::Pipeline::null(),
            offscreen_pattern: vk::Pipeline::null(),
            offscreen_composite: vk::Pipeline::null(),
            images: Vec::new(),
            offscreen: Vec::new(),
            readback: None,
            timer: None,
        };
        // On failure part way, what was made is destroyed by `destroy` (null handles are ignored).
        match r.build(instance, physical_device, queue_family, targets) {
            Ok(()) => Ok(r),
            Err(err) => {
                r.destroy();
                Err(err)
            }
        }
    }

    unsafe fn build(
        &mut self,
        instance: &ash::Instance,
        physical_device: vk::PhysicalDevice,
        queue_family: u32,
        targets: &Targets,
    ) -> Result<(), String> {
        let device = self.device;
        self.pool = device
            .create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(queue_family)
                    .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER),
                None,
            )
            .map_err(e("vkCreateCommandPool"))?;
        self.cmd = device
            .allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(self.pool)
                    .command_buffer_count(1),
            )
            .map_err(e("vkAllocateCommandBuffers"))?[0];
        self.fence = device
            .create_fence(&vk::FenceCreateInfo::default(), None)
            .map_err(e("vkCreateFence"))?;
        if !self.setup.dynamic_rendering {
            self.render_pass = create_render_pass(device, targets.format, self.mode)?;
            if self.setup.offscreen {
                self.offscreen_pass = create_offscreen_pass(device, targets.format)?;
            }
        }

        // One set layout (a sampled image at binding 0) serves the overlay's density map and the
        // offscreen chain's targets.
        let overlay = self.mode == Mode::Overlay;
        let sampled = overlay || self.setup.offscreen;
        if sampled {
            let bindings = [vk::DescriptorSetLayoutBinding::default()
                .binding(0)
                .descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::FRAGMENT)];
            self.set_layout = device
                .create_descriptor_set_layout(
                    &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                    None,
                )
                .map_err(e("vkCreateDescriptorSetLayout"))?;
            let mut count = 0;
            if overlay {
                count += targets.images.len() as u32 * LAYERS;
            }
            if self.setup.offscreen {
                count += OFFSCREEN.len() as u32;
            }
            let sizes = [vk::DescriptorPoolSize::default()
                .ty(vk::DescriptorType::COMBINED_IMAGE_SAMPLER)
                .descriptor_count(count)];
            self.descriptor_pool = device
                .create_descriptor_pool(
                    &vk::DescriptorPoolCreateInfo::default()
                        .max_sets(count)
                        .pool_sizes(&sizes),
                    None,
                )
                .map_err(e("vkCreateDescriptorPool"))?;
            // Nearest: each framebuffer pixel of the overlay shows exactly one texel of the map.
            self.sampler = device
                .create_sampler(
                    &vk::SamplerCreateInfo::default()
                        .mag_filter(vk::Filter::NEAREST)
                        .min_filter(vk::Filter::NEAREST)
                        .mipmap_mode(vk::SamplerMipmapMode::NEAREST)
                        .address_mode_u(vk::SamplerAddressMode::CLAMP_TO_EDGE)
                        .address_mode_v(vk::SamplerAddressMode::CLAMP_TO_EDGE)
                        .address_mode_w(vk::SamplerAddressMode::CLAMP_TO_EDGE),
                    None,
                )
                .map_err(e("vkCreateSampler"))?;
        }
        let push = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::FRAGMENT)
            .size(16)];
        let set_layouts = [self.set_layout];
        self.pipeline_layout = device
            .create_pipeline_layout(
                &vk::PipelineLayoutCreateInfo::default()
                    .set_layouts(if sampled { &set_layouts } else { &[] })
                    .push_constant_ranges(&push),
                None,
            )
            .map_err(e("vkCreatePipelineLayout"))?;
        self.pipeline = self.create_pipeline(
            match (overlay, self.setup.heavy, self.setup.room) {
                (false, _, true) => SCENE,
                (true, _, true) => SCENE_OVERLAY,
                (false, false, false) => PATTERN,
                (true, false, false) => OVERLAY,
                (false, true, false) => HEAVY,
                (true, true, false) => HEAVY_OVERLAY,
            },
            Target::Eye,
        )?;
        if self.setup.offscreen {
            self.eye_composite = self.create_pipeline(COMPOSITE, Target::Eye)?;
            self.offscreen_pattern = self.create_pipeline(PATTERN, Target::Offscreen)?;
            self.offscreen_composite = self.create_pipeline(COMPOSITE, Target::Offscreen)?;
        }
        // Timestamps where the queue family writes them (timestampValidBits) and the device says
        // how long a tick is (timestampPeriod):
        // <https://registry.khronos.org/vulkan/specs/1.3-extensions/html/vkspec.html#queries-timestamps>.
        let families = instance.get_physical_device_queue_family_properties(physical_device);
        let period = instance
            .get_physical_device_properties(physical_device)
            .limits
            .timestamp_period;
        if families
            .get(queue_family as usize)
            .is_some_and(|f| f.timestamp_valid_bits > 0)
            && period > 0.0
        {
            let pool = device
                .create_query_pool(
                    &vk::QueryPoolCreateInfo::default()
                        .query_type(vk::QueryType::TIMESTAMP)
                        .query_count(2 * EYES as u32),
                    None,
                )
                .map_err(e("vkCreateQueryPool"))?;
            self.timer = Some(Timer {
                pool,
                period_ns: f64::from(period),
            });
        }

        let densities = targets
            .density
            .iter()
            .map(Some)
            .chain(std::iter::repeat(None));
        for (&image, density) in targets.images.iter().zip(densities) {
            let &(density_image, dw, dh) = density.unwrap_or(&(vk::Image::null(), 0, 0));
            // Pushed first so that `destroy` finds whatever this loop made before failing.
            self.images.push(PerImage {
                passes: Vec::new(),
                image,
                density_image,
                density_extent: (dw, dh),
                density_views: [vk::ImageView::null(); EYES],
                sets: [vk::DescriptorSet::null(); EYES],
            });
            let per = self.images.last_mut().expect("just pushed");
            let view = |image, format, layer| {
                device
                    .create_image_view(
                        &vk::ImageViewCreateInfo::default()
                            .image(image)
                            .view_type(vk::ImageViewType::TYPE_2D)
                            .format(format)
                            .subresource_range(one_layer(layer)),
                        None,
                    )
                    .map_err(e("vkCreateImageView"))
            };
            if matches!(self.mode, Mode::Attachment | Mode::Overlay) {
                for layer in 0..LAYERS {
                    per.density_views[layer as usize] =
                        view(density_image, vk::Format::R8G8_UNORM, layer)?;
                }
            }
            for (layer, shape) in pass_shapes(targets.layout, targets.extent) {
                per.passes.push(Pass {
                    colour: view(image, targets.format, layer)?,
                    density: if self.mode == Mode::Attachment {
                        per.density_views[layer as usize]
                    } else {
                        vk::ImageView::null()
                    },
                    ..shape
                });
                if self.render_pass == vk::RenderPass::null() {
                    continue;
                }
                let pass = per.passes.last_mut().expect("just pushed");
                // The density view is an attachment only in Attachment mode; in the others it is
                // sampled (or unused) and the framebuffer holds the colour view alone.
                let attachments = [pass.colour, pass.density];
                let used = if self.mode == Mode::Attachment { 2 } else { 1 };
                pass.framebuffer = device
                    .create_framebuffer(
                        &vk::FramebufferCreateInfo::default()
                            .render_pass(self.render_pass)
                            .attachments(&attachments[..used])
                            .width(pass.extent.0)
                            .height(pass.extent.1)
                            .layers(1),
                        None,
                    )
                    .map_err(e("vkCreateFramebuffer"))?;
            }
        }
        if self.setup.offscreen {
            for extent in OFFSCREEN {
                self.offscreen.push(Offscreen {
                    extent,
                    ..Offscreen::default()
                });
                let target = self.offscreen.last_mut().expect("just pushed");
                make_offscreen(
                    instance,
                    physical_device,
                    device,
                    targets.format,
                    self.offscreen_pass,
                    target,
                )?;
            }
        }
        // Descriptor sets: per eye of each image, its layer of the density map (overlay); per
        // offscreen target, the target itself (sampled by the next pass of the chain).
        let mut views: Vec<(vk::ImageView, vk::ImageLayout)> = Vec::new();
        if overlay {
            for per in &self.images {
                for v in per.density_views {
                    views.push((v, vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL));
                }
            }
        }
        for t in &self.offscreen {
            views.push((t.view, vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL));
        }
        if !views.is_empty() {
            let layouts = vec![self.set_layout; views.len()];
            let sets = device
                .allocate_descriptor_sets(
                    &vk::DescriptorSetAllocateInfo::default()
                        .descriptor_pool(self.descriptor_pool)
                        .set_layouts(&layouts),
                )
                .map_err(e("vkAllocateDescriptorSets"))?;
            for (&set, &(view, layout)) in sets.iter().zip(&views) {
                let info = [vk::DescriptorImageInfo::default()
                    .sampler(self.sampler)
                    .image_view(view)
                    .image_layout(layout)];
                device.update_descriptor_sets(
                    &[vk::WriteDescriptorSet::default()
                        .dst_set(set)
                        .dst_binding(0)
                        .descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER)
                        .image_info(&info)],
                    &[],
                );
            }
            let mut sets = sets.into_iter();
            if overlay {
                for per in &mut self.images {
                    for s in &mut per.sets {
                        *s = sets.next().expect("one set per density view");
                    }
                }
            }
            for t in &mut self.offscreen {
                t.set = sets.next().expect("one set per offscreen target");
            }
        }
        if self.setup.readback {
            let (w, h) = targets.extent;
            let eye_bytes = w as usize * h as usize * 4 * EYES;
            let density_bytes = targets
                .density
                .iter()
                .map(|&(_, dw, dh)| dw as usize * dh as usize * 2 * LAYERS as usize)
                .max()
                .unwrap_or(0);
            self.readback = Some(Readback::new(
                instance,
                physical_device,
                device,
                eye_bytes,
                density_bytes,
            )?);
        }
        Ok(())
    }

    /// A pipeline drawing one full-viewport triangle with `fragment`, for the passes of `target`.
    /// Viewport and scissor are dynamic: one pipeline draws each half of a double-wide image and
    /// an eye's corner.
    unsafe fn create_pipeline(
        &self,
        fragment: &[u8],
        target: Target,
    ) -> Result<vk::Pipeline, String> {
        let device = self.device;
        let module = |spirv: &[u8]| {
            let words = ash::util::read_spv(&mut std::io::Cursor::new(spirv))
                .map_err(|err| format!("SPIR-V: {err}"))?;
            device
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
                .map_err(e("vkCreateShaderModule"))
        };
        let vertex = module(VERTEX)?;
        let fragment = match module(fragment) {
            Ok(m) => m,
            Err(err) => {
                device.destroy_shader_module(vertex, None);
                return Err(err);
            }
        };
        let stages = [
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::VERTEX)
                .module(vertex)
                .name(c"main"),
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::FRAGMENT)
                .module(fragment)
                .name(c"main"),
        ];
        let blend = [vk::PipelineColorBlendAttachmentState::default()
            .color_write_mask(vk::ColorComponentFlags::RGBA)];
        let vertex_input = vk::PipelineVertexInputStateCreateInfo::default();
        let assembly = vk::PipelineInputAssemblyStateCreateInfo::default()
            .topology(vk::PrimitiveTopology::TRIANGLE_LIST);
        let viewport = vk::PipelineViewportStateCreateInfo::default()
            .viewport_count(1)
            .scissor_count(1);
        let dynamic_states = [vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];
        let dynamic = vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic_states);
        let raster = vk::PipelineRasterizationStateCreateInfo::default()
            .polygon_mode(vk::PolygonMode::FILL)
            .cull_mode(vk::CullModeFlags::NONE)
            .line_width(1.0);
        let multisample = vk::PipelineMultisampleStateCreateInfo::default()
            .rasterization_samples(vk::SampleCountFlags::TYPE_1);
        let colour_blend = vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend);
        let formats = [self.format];
        let mut rendering =
            vk::PipelineRenderingCreateInfo::default().color_attachment_formats(&formats);
        let mut info = vk::GraphicsPipelineCreateInfo::default()
            .stages(&stages)
            .vertex_input_state(&vertex_input)
            .input_assembly_state(&assembly)
            .viewport_state(&viewport)
            .rasterization_state(&raster)
            .multisample_state(&multisample)
            .color_blend_state(&colour_blend)
            .dynamic_state(&dynamic)
            .layout(self.pipeline_layout);
        if self.setup.dynamic_rendering {
            // A pipeline used where vkCmdBeginRendering names a density map must say so
            // (VUID-vkCmdDraw-imageView-06183).
            if target == Target::Eye && self.mode == Mode::Attachment {
                info = info
                    .flags(vk::PipelineCreateFlags::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_EXT);
            }
            info = info.push_next(&mut rendering);
        } else {
            info = info
                .render_pass(match target {
                    Target::Eye => self.render_pass,
                    Target::Offscreen => self.offscreen_pass,
                })
                .subpass(0);
        }
        let made = device.create_graphics_pipelines(vk::PipelineCache::null(), &[info], None);
        device.destroy_shader_module(vertex, None);
        device.destroy_shader_module(fragment, None);
        made.map(|p| p[0])
            .map_err(|(_, r)| format!("vkCreateGraphicsPipelines: {r}"))
    }

    /// Begins a pass clearing `view` to black: with `pass` and `framebuffer`, or with
    /// vkCmdBeginRenderingKHR naming `view` (and `density` as its fragment density map where not
    /// null).
    unsafe fn begin(
        &self,
        pass: vk::RenderPass,
        framebuffer: vk::Framebuffer,
        (view, density): (vk::ImageView, vk::ImageView),
        (width, height): (u32, u32),
    ) {
        let clear = vk::ClearValue {
            color: vk::ClearColorValue {
                float32: [0.0, 0.0, 0.0, 1.0],
            },
        };
        let area = vk::Rect2D::default().extent(vk::Extent2D { width, height });
        let Some(rendering) = &self.rendering else {
            self.device.cmd_begin_render_pass(
                self.cmd,
                &vk::RenderPassBeginInfo::default()
                    .render_pass(pass)
                    .framebuffer(framebuffer)
                    .render_area(area)
                    .clear_values(std::slice::from_ref(&clear)),
                vk::SubpassContents::INLINE,
            );
            return;
        };
        let colour = [vk::RenderingAttachmentInfo::default()
            .image_view(view)
            .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::STORE)
            .clear_value(clear)];
        let mut fdm = vk::RenderingFragmentDensityMapAttachmentInfoEXT::default()
            .image_view(density)
            .image_layout(vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT);
        let mut info = vk::RenderingInfo::default()
            .render_area(area)
            .layer_count(1)
            .color_attachments(&colour);
        if density != vk::ImageView::null() {
            info = info.push_next(&mut fdm);
        }
        rendering.cmd_begin_rendering(self.cmd, &info);
    }

    unsafe fn end(&self) {
        match &self.rendering {
            Some(r) => r.cmd_end_rendering(self.cmd),
            None => self.device.cmd_end_render_pass(self.cmd),
        }
    }

    /// Sets viewport and scissor to the rectangle at `(x, y)` of `(width, height)`.
    unsafe fn viewport(&self, (x, y): (u32, u32), (width, height): (u32, u32)) {
        self.device.cmd_set_viewport(
            self.cmd,
            0,
            &[vk::Viewport {
                x: x as f32,
                y: y as f32,
                width: width as f32,
                height: height as f32,
                min_depth: 0.0,
                max_depth: 1.0,
            }],
        );
        self.device.cmd_set_scissor(
            self.cmd,
            0,
            &[vk::Rect2D {
                offset: vk::Offset2D {
                    x: x as i32,
                    y: y as i32,
                },
                extent: vk::Extent2D { width, height },
            }],
        );
    }

    /// With dynamic rendering, the layout change a render pass's attachment description and
    /// dependencies make for an offscreen target: `from` (written by colour output, or read by
    /// fragment shaders) to `to`.
    unsafe fn offscreen_barrier(&self, image: vk::Image, to_attachment: bool) {
        let (old, new, src, dst, src_access, dst_access) = if to_attachment {
            // The previous frame's reads are done (its fence was waited for); the contents are
            // cleared, so the old layout is UNDEFINED.
            (
                vk::ImageLayout::UNDEFINED,
                vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
                vk::PipelineStageFlags::FRAGMENT_SHADER,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                vk::AccessFlags::empty(),
                vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
            )
        } else {
            (
                vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
                vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                vk::PipelineStageFlags::FRAGMENT_SHADER,
                vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
                vk::AccessFlags::SHADER_READ,
            )
        };
        self.device.cmd_pipeline_barrier(
            self.cmd,
            src,
            dst,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[vk::ImageMemoryBarrier::default()
                .image(image)
                .subresource_range(one_layer(0))
                .old_layout(old)
                .new_layout(new)
                .src_access_mask(src_access)
                .dst_access_mask(dst_access)],
        );
    }

    /// The offscreen chain: blue stripes into the "shadow map", then the shadow map sampled into
    /// the tiny target; both end in SHADER_READ_ONLY_OPTIMAL for the next pass to sample.
    unsafe fn record_offscreen(&self) {
        let device = self.device;
        for (i, target) in self.offscreen.iter().enumerate() {
            if self.rendering.is_some() {
                self.offscreen_barrier(target.image, true);
            }
            self.begin(
                self.offscreen_pass,
                target.framebuffer,
                (target.view, vk::ImageView::null()),
                target.extent,
            );
            self.viewport((0, 0), target.extent);
            if i == 0 {
                device.cmd_bind_pipeline(
                    self.cmd,
                    vk::PipelineBindPoint::GRAPHICS,
                    self.offscreen_pattern,
                );
                device.cmd_push_constants(
                    self.cmd,
                    self.pipeline_layout,
                    vk::ShaderStageFlags::FRAGMENT,
                    0,
                    &push_bytes(OFFSCREEN_TINT),
                );
            } else {
                device.cmd_bind_pipeline(
                    self.cmd,
                    vk::PipelineBindPoint::GRAPHICS,
                    self.offscreen_composite,
                );
                device.cmd_bind_descriptor_sets(
                    self.cmd,
                    vk::PipelineBindPoint::GRAPHICS,
                    self.pipeline_layout,
                    0,
                    &[self.offscreen[i - 1].set],
                    &[],
                );
            }
            device.cmd_draw(self.cmd, 3, 1, 0, 0);
            self.end();
            if self.rendering.is_some() {
                self.offscreen_barrier(target.image, false);
            }
        }
    }

    /// Draws both views of swapchain image `index` in `tint`, reads back what `read` asks for, and
    /// waits for the GPU. xrWaitSwapchainImage hands the image over in COLOR_ATTACHMENT_OPTIMAL and
    /// xrReleaseSwapchainImage expects it back in that layout; the density map goes back to the
    /// layout fovea left it in.
    ///
    /// # Safety
    /// `index` is the acquired and waited image.
    /// Returns the GPU milliseconds of each eye pass (begin to end of its pass, from timestamps:
    /// two per frame with an array, one covering both eyes when double-wide), empty where the
    /// queue has no timestamps.
    pub unsafe fn draw(
        &self,
        index: usize,
        tint: [f32; 4],
        read: Read,
    ) -> Result<Vec<f64>, String> {
        let device = self.device;
        let per = &self.images[index];
        let cmd = self.cmd;
        device
            .begin_command_buffer(
                cmd,
                &vk::CommandBufferBeginInfo::default()
                    .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
            )
            .map_err(e("vkBeginCommandBuffer"))?;
        let (w, h) = self.extent;
        let tint_bytes = push_bytes(tint);
        let queries = 2 * per.passes.len() as u32;
        if let Some(t) = &self.timer {
            device.cmd_reset_query_pool(cmd, t.pool, 0, queries);
        }
        if self.setup.offscreen {
            self.record_offscreen();
        }
        if self.rendering.is_some() {
            // What the render pass's external dependency says: the previous frame's colour writes
            // come before this pass's.
            device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                vk::DependencyFlags::empty(),
                &[vk::MemoryBarrier::default()
                    .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                    .dst_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)],
                &[],
                &[],
            );
        }
        for (i, pass) in per.passes.iter().enumerate() {
            if let Some(t) = &self.timer {
                device.cmd_write_timestamp(
                    cmd,
                    vk::PipelineStageFlags::TOP_OF_PIPE,
                    t.pool,
                    2 * i as u32,
                );
            }
            self.begin(
                self.render_pass,
                pass.framebuffer,
                (pass.colour, pass.density),
                pass.extent,
            );
            for &(eye, x) in &pass.draws {
                self.viewport((x, 0), (w, h));
                device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::GRAPHICS, self.pipeline);
                if self.mode == Mode::Overlay {
                    device.cmd_bind_descriptor_sets(
                        cmd,
                        vk::PipelineBindPoint::GRAPHICS,
                        self.pipeline_layout,
                        0,
                        &[per.sets[eye]],
                        &[],
                    );
                }
                device.cmd_push_constants(
                    cmd,
                    self.pipeline_layout,
                    vk::ShaderStageFlags::FRAGMENT,
                    0,
                    &tint_bytes,
                );
                device.cmd_draw(cmd, 3, 1, 0, 0);
                if let Some(tiny) = self.offscreen.last() {
                    // The tiny offscreen target, in the eye's upper-right corner.
                    let (cw, ch) = (w / CORNER, h / CORNER);
                    self.viewport((x + w - cw, 0), (cw, ch));
                    device.cmd_bind_pipeline(
                        cmd,
                        vk::PipelineBindPoint::GRAPHICS,
                        self.eye_composite,
                    );
                    device.cmd_bind_descriptor_sets(
                        cmd,
                        vk::PipelineBindPoint::GRAPHICS,
                        self.pipeline_layout,
                        0,
                        &[tiny.set],
                        &[],
                    );
                    device.cmd_draw(cmd, 3, 1, 0, 0);
                }
            }
            self.end();
            if let Some(t) = &self.timer {
                device.cmd_write_timestamp(
                    cmd,
                    vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                    t.pool,
                    2 * i as u32 + 1,
                );
            }
        }
        if let Some(rb) = &self.readback {
            if read.eyes {
                // Eye `i` at `i` eye-sizes into the buffer: its layer, or its half.
                let regions: [(u32, u32); EYES] = match self.layout {
                    Layout::Array => [(0, 0), (1, 0)],
                    Layout::DoubleWide => [(0, 0), (0, w)],
                };
                self.copy_out(
                    per.image,
                    ((w, h), &regions),
                    4,
                    0,
                    (
                        vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
                        vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                        vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
                    ),
                    rb,
                );
            }
            if read.density && matches!(self.mode, Mode::Attachment | Mode::Overlay) {
                self.copy_out(
                    per.density_image,
                    (per.density_extent, &[(0, 0), (1, 0)]),
                    2,
                    rb.eye_bytes,
                    self.mode.resting(),
                    rb,
                );
            }
            // The copies' writes become visible to the host after the fence.
            device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &[vk::MemoryBarrier::default()
                    .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                    .dst_access_mask(vk::AccessFlags::HOST_READ)],
                &[],
                &[],
            );
        }
        device
            .end_command_buffer(cmd)
            .map_err(e("vkEndCommandBuffer"))?;
        let cmds = [cmd];
        device
            .queue_submit(
                self.queue,
                &[vk::SubmitInfo::default().command_buffers(&cmds)],
                self.fence,
            )
            .map_err(e("vkQueueSubmit"))?;
        device
            .wait_for_fences(&[self.fence], true, u64::MAX)
            .map_err(e("vkWaitForFences"))?;
        device
            .reset_fences(&[self.fence])
            .map_err(e("vkResetFences"))?;
        let Some(t) = &self.timer else {
            return Ok(Vec::new());
        };
        let mut ticks = vec![0u64; queries as usize];
        device
            .get_query_pool_results(
                t.pool,
                0,
                &mut ticks,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
            .map_err(e("vkGetQueryPoolResults"))?;
        Ok(ticks
            .chunks_exact(2)
            .map(|p| p[1].saturating_sub(p[0]) as f64 * t.period_ns / 1e6)
            .collect())
    }

    /// Records a copy of `regions` of `image` (in `layout`, last used at `stage` with `access`)
    /// into the readback buffer at `offset`, one after the other, and puts the image back in
    /// `layout`. A region is `(layer, x)`: `extent` texels at `(x, 0)` of that layer.
    unsafe fn copy_out(
        &self,
        image: vk::Image,
        ((width, height), regions): ((u32, u32), &[(u32, u32)]),
        texel_bytes: u64,
        offset: usize,
        (layout, stage, access): (vk::ImageLayout, vk::PipelineStageFlags, vk::AccessFlags),
        rb: &Readback,
    ) {
        let layers = regions.iter().map(|r| r.0 + 1).max().unwrap_or(1);
        let range = vk::ImageSubresourceRange::default()
            .aspect_mask(vk::ImageAspectFlags::COLOR)
            .level_count(1)
            .layer_count(layers);
        let barrier = |from, to, src, dst| {
            vk::ImageMemoryBarrier::default()
                .image(image)
                .subresource_range(range)
                .old_layout(from)
                .new_layout(to)
                .src_access_mask(src)
                .dst_access_mask(dst)
        };
        let cmd = self.cmd;
        self.device.cmd_pipeline_barrier(
            cmd,
            stage,
            vk::PipelineStageFlags::TRANSFER,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[barrier(
                layout,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                access,
                vk::AccessFlags::TRANSFER_READ,
            )],
        );
        let region_bytes = width as u64 * height as u64 * texel_bytes;
        let copies: Vec<vk::BufferImageCopy> = regions
            .iter()
            .enumerate()
            .map(|(i, &(layer, x))| {
                vk::BufferImageCopy::default()
                    .buffer_offset(offset as u64 + i as u64 * region_bytes)
                    .image_subresource(
                        vk::ImageSubresourceLayers::default()
                            .aspect_mask(vk::ImageAspectFlags::COLOR)
                            .base_array_layer(layer)
                            .layer_count(1),
                    )
                    .image_offset(vk::Offset3D {
                        x: x as i32,
                        y: 0,
                        z: 0,
                    })
                    .image_extent(vk::Extent3D {
                        width,
                        height,
                        depth: 1,
                    })
            })
            .collect();
        self.device.cmd_copy_image_to_buffer(
            cmd,
            image,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            rb.buffer,
            &copies,
        );
        self.device.cmd_pipeline_barrier(
            cmd,
            vk::PipelineStageFlags::TRANSFER,
            stage,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[barrier(
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                layout,
                vk::AccessFlags::empty(),
                access,
            )],
        );
    }

    /// The eyes read back by the last [`Renderer::draw`] that asked for them: view 0 then view 1,
    /// each a view's extent of RGBA8.
    pub fn eyes(&self) -> Option<&[u8]> {
        let rb = self.readback.as_ref()?;
        // SAFETY: the mapping lives as long as `self`; the fence wait in `draw` finished the copy.
        Some(unsafe { std::slice::from_raw_parts(rb.mapped, rb.eye_bytes) })
    }

    /// The density map of swapchain image `index` read back by the last [`Renderer::draw`] of that
    /// image that asked for it: both layers, R8G8 (empty without density maps).
    pub fn density(&self, index: usize) -> Option<&[u8]> {
        let rb = self.readback.as_ref()?;
        let (dw, dh) = self.images.get(index)?.density_extent;
        let len = dw as usize * dh as usize * 2 * LAYERS as usize;
        // SAFETY: as in `eyes`; `len` is within the density part of the buffer.
        Some(unsafe { std::slice::from_raw_parts(rb.mapped.add(rb.eye_bytes), len) })
    }

    /// Destroys everything [`Renderer::new`] made. The device must be idle (every draw waits).
    ///
    /// # Safety
    /// No command buffer of this renderer may be pending.
    pub unsafe fn destroy(&mut self) {
        let device = self.device;
        for per in self.images.drain(..) {
            for pass in per.passes {
                device.destroy_framebuffer(pass.framebuffer, None);
                device.destroy_image_view(pass.colour, None);
            }
            for view in per.density_views {
                device.destroy_image_view(view, None);
            }
        }
        for t in self.offscreen.drain(..) {
            device.destroy_framebuffer(t.framebuffer, None);
            device.destroy_image_view(t.view, None);
            device.destroy_image(t.image, None);
            device.free_memory(t.memory, None);
        }
        if let Some(rb) = self.readback.take() {
            device.destroy_buffer(rb.buffer, None);
            device.free_memory(rb.memory, None);
        }
        for p in [
            &mut self.pipeline,
            &mut self.eye_composite,
            &mut self.offscreen_pattern,
            &mut self.offscreen_composite,
        ] {
            device.destroy_pipeline(*p, None);
            *p = vk::Pipeline::null();
        }
        device.destroy_pipeline_layout(self.pipeline_layout, None);
        device.destroy_sampler(self.sampler, None);
        device.destroy_descriptor_pool(self.descriptor_pool, None);
        device.destroy_descriptor_set_layout(self.set_layout, None);
        device.destroy_render_pass(self.render_pass, None);
        device.destroy_render_pass(self.offscreen_pass, None);
        device.destroy_fence(self.fence, None);
        device.destroy_command_pool(self.pool, None);
        if let Some(t) = self.timer.take() {
            device.destroy_query_pool(t.pool, None);
        }
        self.pipeline_layout = vk::PipelineLayout::null();
        self.sampler = vk::Sampler::null();
        self.descriptor_pool = vk::DescriptorPool::null();
        self.set_layout = vk::DescriptorSetLayout::null();
        self.render_pass = vk::RenderPass::null();
        self.offscreen_pass = vk::RenderPass::null();
        self.fence = vk::Fence::null();
        self.pool = vk::CommandPool::null();
    }
}

/// The eye passes of a swapchain image, each with the array layer it renders into; views and
/// framebuffers are made by the caller. An array: a pass per eye into its layer. Double-wide: one
/// pass over the whole image, each eye drawn in its half.
fn pass_shapes(layout: Layout, (w, h): (u32, u32)) -> Vec<(u32, Pass)> {
    let pass = |extent, draws: &[(usize, u32)]| Pass {
        extent,
        draws: draws.to_vec(),
        ..Pass::default()
    };
    match layout {
        Layout::Array => vec![(0, pass((w, h), &[(0, 0)])), (1, pass((w, h), &[(1, 0)]))],
        Layout::DoubleWide => vec![(0, pass((2 * w, h), &[(0, 0), (1, w)]))],
    }
}

/// A tint as the fragment shaders' push constant.
fn push_bytes(tint: [f32; 4]) -> [u8; 16] {
    let mut bytes = [0u8; 16];
    for (dst, c) in bytes.chunks_exact_mut(4).zip(tint) {
        dst.copy_from_slice(&c.to_ne_bytes());
    }
    bytes
}

/// A memory type of `bits` with `wanted`, from the device's list.
fn memory_type(
    props: &vk::PhysicalDeviceMemoryProperties,
    bits: u32,
    wanted: vk::MemoryPropertyFlags,
) -> Option<u32> {
    (0..props.memory_type_count).find(|&i| {
        bits & (1 << i) != 0
            && props.memory_types[i as usize]
                .property_flags
                .contains(wanted)
    })
}

/// Makes `target`'s image (colour attachment, sampled), its memory, view and framebuffer (where
/// `pass` is not null), filling `target` as it goes so that `destroy` finds what was made.
unsafe fn make_offscreen(
    instance: &ash::Instance,
    physical_device: vk::PhysicalDevice,
    device: &ash::Device,
    format: vk::Format,
    pass: vk::RenderPass,
    target: &mut Offscreen,
) -> Result<(), String> {
    let (width, height) = target.extent;
    target.image = device
        .create_image(
            &vk::ImageCreateInfo::default()
                .image_type(vk::ImageType::TYPE_2D)
                .format(format)
                .extent(vk::Extent3D {
                    width,
                    height,
                    depth: 1,
                })
                .mip_levels(1)
                .array_layers(1)
                .samples(vk::SampleCountFlags::TYPE_1)
                .tiling(vk::ImageTiling::OPTIMAL)
                .usage(vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::SAMPLED)
                .initial_layout(vk::ImageLayout::UNDEFINED),
            None,
        )
        .map_err(e("vkCreateImage"))?;
    let needs = device.get_image_memory_requirements(target.image);
    let props = instance.get_physical_device_memory_properties(physical_device);
    let kind = memory_type(
        &props,
        needs.memory_type_bits,
        vk::MemoryPropertyFlags::DEVICE_LOCAL,
    )
    .or_else(|| {
        memory_type(
            &props,
            needs.memory_type_bits,
            vk::MemoryPropertyFlags::empty(),
        )
    })
    .ok_or("no memory type for an offscreen target")?;
    target.memory = device
        .allocate_memory(
            &vk::MemoryAllocateInfo::default()
                .allocation_size(needs.size)
                .memory_type_index(kind),
            None,
        )
        .map_err(e("vkAllocateMemory"))?;
    device
        .bind_image_memory(target.image, target.memory, 0)
        .map_err(e("vkBindImageMemory"))?;
    target.view = device
        .create_image_view(
            &vk::ImageViewCreateInfo::default()
                .image(target.image)
                .view_type(vk::ImageViewType::TYPE_2D)
                .format(format)
                .subresource_range(one_layer(0)),
            None,
        )
        .map_err(e("vkCreateImageView"))?;
    if pass != vk::RenderPass::null() {
        let attachments = [target.view];
        target.framebuffer = device
            .create_framebuffer(
                &vk::FramebufferCreateInfo::default()
                    .render_pass(pass)
                    .attachments(&attachments)
                    .width(width)
                    .height(height)
                    .layers(1),
                None,
            )
            .map_err(e("vkCreateFramebuffer"))?;
    }
    Ok(())
}

impl Readback {
    unsafe fn new(
        instance: &ash::Instance,
        physical_device: vk::PhysicalDevice,
        device: &ash::Device,
        eye_bytes: usize,
        density_bytes: usize,
    ) -> Result<Readback, String> {
        let buffer = device
            .create_buffer(
                &vk::BufferCreateInfo::default()
                    .size((eye_bytes + density_bytes) as u64)
                    .usage(vk::BufferUsageFlags::TRANSFER_DST),
                None,
            )
            .map_err(e("vkCreateBuffer"))?;
        let needs = device.get_buffer_memory_requirements(buffer);
        let props = instance.get_physical_device_memory_properties(physical_device);
        let wanted = vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
        let Some(kind) = (0..props.memory_type_count).find(|&i| {
            needs.memory_type_bits & (1 << i) != 0
                && props.memory_types[i as usize]
                    .property_flags
                    .contains(wanted)
        }) else {
            device.destroy_buffer(buffer, None);
            return Err("no host-visible, coherent memory for the readback buffer".into());
        };
        let memory = match device.allocate_memory(
            &vk::MemoryAllocateInfo::default()
                .allocation_size(needs.size)
                .memory_type_index(kind),
            None,
        ) {
            Ok(m) => m,
            Err(r) => {
                device.destroy_buffer(buffer, None);
                return Err(format!("vkAllocateMemory: {r}"));
            }
        };
        let bound = device.bind_buffer_memory(buffer, memory, 0).and_then(|()| {
            device.map_memory(memory, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())
        });
        match bound {
            Ok(mapped) => Ok(Readback {
                buffer,
                memory,
                mapped: mapped as *const c_void as *const u8,
                eye_bytes,
            }),
            Err(r) => {
                device.destroy_buffer(buffer, None);
                device.free_memory(memory, None);
                Err(format!("binding or mapping the readback buffer: {r}"))
            }
        }
    }
}

fn one_layer(layer: u32) -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange::default()
        .aspect_mask(vk::ImageAspectFlags::COLOR)
        .base_array_layer(layer)
        .level_count(1)
        .layer_count(1)
}

/// One subpass drawing one eye into the colour attachment (0). In [`Mode::Attachment`] the density
/// map is attachment 1, named by `VkRenderPassFragmentDensityMapCreateInfoEXT` and never by the
/// subpass: not loaded and not stored (VUID-VkRenderPassFragmentDensityMapCreateInfoEXT-
/// fragmentDensityMapAttachment-02550 and -02551), in FRAGMENT_DENSITY_MAP_OPTIMAL_EXT throughout
/// (-02549), the layout fovea leaves it in after each upload.
unsafe fn create_render_pass(
    device: &ash::Device,
    format: vk::Format,
    mode: Mode,
) -> Result<vk::RenderPass, String> {
    let attachment = |format, load, store, layout| {
        vk::AttachmentDescription::default()
            .format(format)
            .samples(vk::SampleCountFlags::TYPE_1)
            .load_op(load)
            .store_op(store)
            .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
            .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
            .initial_layout(layout)
            .final_layout(layout)
    };
    let attachments = [
        attachment(
            format,
            vk::AttachmentLoadOp::CLEAR,
            vk::AttachmentStoreOp::STORE,
            vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
        ),
        attachment(
            vk::Format::R8G8_UNORM,
            vk::AttachmentLoadOp::DONT_CARE,
            vk::AttachmentStoreOp::DONT_CARE,
            vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT,
        ),
    ];
    let used = if mode == Mode::Attachment { 2 } else { 1 };
    let colour = [vk::AttachmentReference {
        attachment: 0,
        layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
    }];
    let subpasses = [vk::SubpassDescription::default()
        .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
        .color_attachments(&colour)];
    // The previous frame's colour writes come before this pass's. fovea fenced its upload of the
    // density map and made it visible to the stages that read it.
    let dependencies = [vk::SubpassDependency::default()
        .src_subpass(vk::SUBPASS_EXTERNAL)
        .dst_subpass(0)
        .src_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
        .dst_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
        .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
        .dst_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)];
    let mut density = vk::RenderPassFragmentDensityMapCreateInfoEXT::default()
        .fragment_density_map_attachment(vk::AttachmentReference {
            attachment: 1,
            layout: vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT,
        });
    let mut info = vk::RenderPassCreateInfo::default()
        .attachments(&attachments[..used])
        .subpasses(&subpasses)
        .dependencies(&dependencies);
    if mode == Mode::Attachment {
        info = info.push_next(&mut density);
    }
    device
        .create_render_pass(&info, None)
        .map_err(e("vkCreateRenderPass"))
}

/// The offscreen targets' pass: one colour attachment cleared, stored, and left in
/// SHADER_READ_ONLY_OPTIMAL for the next pass of the chain to sample. Its contents are redrawn
/// every frame, so it starts UNDEFINED; the previous frame's reads of it come first.
unsafe fn create_offscreen_pass(
    device: &ash::Device,
    format: vk::Format,
) -> Result<vk::RenderPass, String> {
    let attachments = [vk::AttachmentDescription::default()
        .format(format)
        .samples(vk::SampleCountFlags::TYPE_1)
        .load_op(vk::AttachmentLoadOp::CLEAR)
        .store_op(vk::AttachmentStoreOp::STORE)
        .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
        .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
        .initial_layout(vk::ImageLayout::UNDEFINED)
        .final_layout(vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL)];
    let colour = [vk::AttachmentReference {
        attachment: 0,
        layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
    }];
    let subpasses = [vk::SubpassDescription::default()
        .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
        .color_attachments(&colour)];
    let dependencies = [
        vk::SubpassDependency::default()
            .src_subpass(vk::SUBPASS_EXTERNAL)
            .dst_subpass(0)
            .src_stage_mask(vk::PipelineStageFlags::FRAGMENT_SHADER)
            .dst_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
            .dst_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE),
        vk::SubpassDependency::default()
            .src_subpass(0)
            .dst_subpass(vk::SUBPASS_EXTERNAL)
            .src_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
            .dst_stage_mask(vk::PipelineStageFlags::FRAGMENT_SHADER)
            .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
            .dst_access_mask(vk::AccessFlags::SHADER_READ),
    ];
    device
        .create_render_pass(
            &vk::RenderPassCreateInfo::default()
                .attachments(&attachments)
                .subpasses(&subpasses)
                .dependencies(&dependencies),
            None,
        )
        .map_err(e("vkCreateRenderPass"))
}
