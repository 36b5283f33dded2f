//! The example's rendering: a render pass per eye into that eye's layer of a two-layer swapchain
//! image, with the same layer of the image's density map either attached to the render pass
//! (devices with VK_EXT_fragment_density_map) or sampled into a debug overlay (devices without),
//! and optional read-back of what was drawn.
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

/// GPU timestamps around each eye pass: a query pool of two per eye, and nanoseconds per tick.
struct Timer {
    pool: vk::QueryPool,
    period_ns: f64,
}

/// Eye `i` renders into array layer `i` of the swapchain image and reads layer `i` of the map.
const LAYERS: u32 = 2;

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
            Mode::Overlay | Mode::None => (
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
    pub extent: (u32, u32),
    pub images: &'a [vk::Image],
    /// `(image, width, height)` per swapchain image, from XrSwapchainImageFoveationVulkanFB.
    pub density: &'a [(vk::Image, u32, u32)],
}

/// What a frame reads back into host memory after drawing.
#[derive(Clone, Copy, Debug, Default)]
pub struct Read {
    /// Both layers of the swapchain image (RGBA8, sRGB-encoded).
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

/// One eye of a swapchain image: its layer's views, framebuffer and (overlay) descriptor set.
#[derive(Clone, Copy, Default)]
struct Eye {
    colour: vk::ImageView,
    density: vk::ImageView,
    framebuffer: vk::Framebuffer,
    set: vk::DescriptorSet,
}

/// A swapchain image and its density map.
struct PerImage {
    eyes: [Eye; LAYERS as usize],
    image: vk::Image,
    density_image: vk::Image,
    density_extent: (u32, u32),
}

pub struct Renderer<'d> {
    device: &'d ash::Device,
    queue: vk::Queue,
    mode: Mode,
    extent: (u32, u32),
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    render_pass: vk::RenderPass,
    set_layout: vk::DescriptorSetLayout,
    descriptor_pool: vk::DescriptorPool,
    sampler: vk::Sampler,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    images: Vec<PerImage>,
    readback: Option<Readback>,
    /// The fill-bound fragment shader (`--heavy`).
    heavy: bool,
    /// `None` where the queue cannot write timestamps.
    timer: Option<Timer>,
}

fn e(what: &'static str) -> impl Fn(vk::Result) -> String {
    move |r| format!("{what}: {r}")
}

impl<'d> Renderer<'d> {
    /// Makes everything the frames need. `readback` allocates the host buffer [`Renderer::draw`]
    /// copies into when asked to.
    ///
    /// # Safety
    /// `device` made on `physical_device`; `queue` from `queue_family`; the targets' images are the
    /// swapchain's and fovea's, alive until [`Renderer::destroy`].
    pub unsafe fn new(
        (instance, physical_device): (&ash::Instance, vk::PhysicalDevice),
        device: &'d ash::Device,
        (queue, queue_family): (vk::Queue, u32),
        targets: &Targets,
        mode: Mode,
        readback: bool,
        heavy: bool,
    ) -> Result<Renderer<'d>, String> {
        let mut r = Renderer {
            device,
            queue,
            mode,
            extent: targets.extent,
            pool: vk::CommandPool::null(),
            cmd: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
            render_pass: vk::RenderPass::null(),
            set_layout: vk::DescriptorSetLayout::null(),
            descriptor_pool: vk::DescriptorPool::null(),
            sampler: vk::Sampler::null(),
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            images: Vec::new(),
            readback: None,
            heavy,
            timer: None,
        };
        // On failure part way, what was made is destroyed by `destroy` (null handles are ignored).
        match r.build(instance, physical_device, queue_family, targets, readback) {
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
        readback: bool,
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
        self.render_pass = create_render_pass(device, targets.format, self.mode)?;

        let overlay = self.mode == Mode::Overlay;
        if overlay {
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
            let count = targets.images.len() as u32 * LAYERS;
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
        self.layout = device
            .create_pipeline_layout(
                &vk::PipelineLayoutCreateInfo::default()
                    .set_layouts(if overlay { &set_layouts } else { &[] })
                    .push_constant_ranges(&push),
                None,
            )
            .map_err(e("vkCreatePipelineLayout"))?;
        self.pipeline = self.create_pipeline(match (overlay, self.heavy) {
            (false, false) => PATTERN,
            (true, false) => OVERLAY,
            (false, true) => HEAVY,
            (true, true) => HEAVY_OVERLAY,
        })?;
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
                        .query_count(2 * LAYERS),
                    None,
                )
                .map_err(e("vkCreateQueryPool"))?;
            self.timer = Some(Timer {
                pool,
                period_ns: f64::from(period),
            });
        }

        for (&image, &(density_image, dw, dh)) in targets.images.iter().zip(targets.density) {
            let per = PerImage {
                eyes: [Eye::default(); LAYERS as usize],
                image,
                density_image,
                density_extent: (dw, dh),
            };
            // Pushed first so that `destroy` finds whatever this loop made before failing.
            self.images.push(per);
            let per = self.images.last_mut().expect("just pushed");
            for (layer, eye) in (0..LAYERS).zip(per.eyes.iter_mut()) {
                let view = |image, format| {
                    device.create_image_view(
                        &vk::ImageViewCreateInfo::default()
                            .image(image)
                            .view_type(vk::ImageViewType::TYPE_2D)
                            .format(format)
                            .subresource_range(one_layer(layer)),
                        None,
                    )
                };
                eye.colour = view(image, targets.format).map_err(e("vkCreateImageView"))?;
                if self.mode != Mode::None {
                    eye.density = view(density_image, vk::Format::R8G8_UNORM)
                        .map_err(e("vkCreateImageView"))?;
                }
                // The density view is an attachment only in Attachment mode; in the others it is
                // sampled (or unused) and the framebuffer holds the colour view alone.
                let attachments = [eye.colour, eye.density];
                let used = if self.mode == Mode::Attachment { 2 } else { 1 };
                eye.framebuffer = device
                    .create_framebuffer(
                        &vk::FramebufferCreateInfo::default()
                            .render_pass(self.render_pass)
                            .attachments(&attachments[..used])
                            .width(targets.extent.0)
                            .height(targets.extent.1)
                            .layers(1),
                        None,
                    )
                    .map_err(e("vkCreateFramebuffer"))?;
            }
        }
        if overlay {
            let layouts = vec![self.set_layout; self.images.len() * LAYERS as usize];
            let sets = device
                .allocate_descriptor_sets(
                    &vk::DescriptorSetAllocateInfo::default()
                        .descriptor_pool(self.descriptor_pool)
                        .set_layouts(&layouts),
                )
                .map_err(e("vkAllocateDescriptorSets"))?;
            let eyes = self.images.iter_mut().flat_map(|per| per.eyes.iter_mut());
            for (eye, set) in eyes.zip(sets) {
                eye.set = set;
                let info = [vk::DescriptorImageInfo::default()
                    .sampler(self.sampler)
                    .image_view(eye.density)
                    .image_layout(vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL)];
                device.update_descriptor_sets(
                    &[vk::WriteDescriptorSet::default()
                        .dst_set(set)
                        .dst_binding(0)
                        .descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER)
                        .image_info(&info)],
                    &[],
                );
            }
        }
        if readback {
            let (w, h) = targets.extent;
            let eye_bytes = w as usize * h as usize * 4 * LAYERS as usize;
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

    unsafe fn create_pipeline(&self, fragment: &[u8]) -> Result<vk::Pipeline, String> {
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
        let (w, h) = self.extent;
        let viewports = [vk::Viewport::default()
            .width(w as f32)
            .height(h as f32)
            .max_depth(1.0)];
        let scissors = [vk::Rect2D::default().extent(vk::Extent2D {
            width: w,
            height: h,
        })];
        let blend = [vk::PipelineColorBlendAttachmentState::default()
            .color_write_mask(vk::ColorComponentFlags::RGBA)];
        let vertex_input = vk::PipelineVertexInputStateCreateInfo::default();
        let assembly = vk::PipelineInputAssemblyStateCreateInfo::default()
            .topology(vk::PrimitiveTopology::TRIANGLE_LIST);
        let viewport = vk::PipelineViewportStateCreateInfo::default()
            .viewports(&viewports)
            .scissors(&scissors);
        let raster = vk::PipelineRasterizationStateCreateInfo::default()
            .polygon_mode(vk::PolygonMode::FILL)
            .cull_mode(vk::CullModeFlags::NONE)
            .line_width(1.0);
        let multisample = vk::PipelineMultisampleStateCreateInfo::default()
            .rasterization_samples(vk::SampleCountFlags::TYPE_1);
        let colour_blend = vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend);
        let info = vk::GraphicsPipelineCreateInfo::default()
            .stages(&stages)
            .vertex_input_state(&vertex_input)
            .input_assembly_state(&assembly)
            .viewport_state(&viewport)
            .rasterization_state(&raster)
            .multisample_state(&multisample)
            .color_blend_state(&colour_blend)
            .layout(self.layout)
            .render_pass(self.render_pass)
            .subpass(0);
        let made = device.create_graphics_pipelines(vk::PipelineCache::null(), &[info], None);
        device.destroy_shader_module(vertex, None);
        device.destroy_shader_module(fragment, None);
        made.map(|p| p[0])
            .map_err(|(_, r)| format!("vkCreateGraphicsPipelines: {r}"))
    }

    /// Draws both views of swapchain image `index` in `tint`, reads back what `read` asks for, and
    /// waits for the GPU. xrWaitSwapchainImage hands the image over in COLOR_ATTACHMENT_OPTIMAL and
    /// xrReleaseSwapchainImage expects it back in that layout; the density map goes back to the
    /// layout fovea left it in.
    ///
    /// # Safety
    /// `index` is the acquired and waited image.
    /// Returns the GPU milliseconds of each eye pass (begin to end of its render pass, from
    /// timestamps), empty where the queue has no timestamps.
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
        let clear = [vk::ClearValue {
            color: vk::ClearColorValue {
                float32: [0.0, 0.0, 0.0, 1.0],
            },
        }];
        let mut tint_bytes = [0u8; 16];
        for (dst, c) in tint_bytes.chunks_exact_mut(4).zip(tint) {
            dst.copy_from_slice(&c.to_ne_bytes());
        }
        if let Some(t) = &self.timer {
            device.cmd_reset_query_pool(cmd, t.pool, 0, 2 * LAYERS);
        }
        for (i, eye) in per.eyes.iter().enumerate() {
            if let Some(t) = &self.timer {
                device.cmd_write_timestamp(
                    cmd,
                    vk::PipelineStageFlags::TOP_OF_PIPE,
                    t.pool,
                    2 * i as u32,
                );
            }
            device.cmd_begin_render_pass(
                cmd,
                &vk::RenderPassBeginInfo::default()
                    .render_pass(self.render_pass)
                    .framebuffer(eye.framebuffer)
                    .render_area(vk::Rect2D::default().extent(vk::Extent2D {
                        width: w,
                        height: h,
                    }))
                    .clear_values(&clear),
                vk::SubpassContents::INLINE,
            );
            device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::GRAPHICS, self.pipeline);
            if self.mode == Mode::Overlay {
                device.cmd_bind_descriptor_sets(
                    cmd,
                    vk::PipelineBindPoint::GRAPHICS,
                    self.layout,
                    0,
                    &[eye.set],
                    &[],
                );
            }
            device.cmd_push_constants(
                cmd,
                self.layout,
                vk::ShaderStageFlags::FRAGMENT,
                0,
                &tint_bytes,
            );
            device.cmd_draw(cmd, 3, 1, 0, 0);
            device.cmd_end_render_pass(cmd);
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
                self.copy_out(
                    per.image,
                    (w, h),
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
            if read.density && self.mode != Mode::None {
                self.copy_out(
                    per.density_image,
                    per.density_extent,
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
        let mut ticks = [0u64; 2 * LAYERS as usize];
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

    /// Records a copy of both layers of `image` (in `layout`, last used at `stage` with `access`)
    /// into the readback buffer at `offset`, and puts the image back in `layout`.
    unsafe fn copy_out(
        &self,
        image: vk::Image,
        (width, height): (u32, u32),
        texel_bytes: u64,
        offset: usize,
        (layout, stage, access): (vk::ImageLayout, vk::PipelineStageFlags, vk::AccessFlags),
        rb: &Readback,
    ) {
        let barrier = |from, to, src, dst| {
            vk::ImageMemoryBarrier::default()
                .image(image)
                .subresource_range(all_layers())
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
        // One region per layer, each layer's texels after the previous layer's.
        let layer_bytes = width as u64 * height as u64 * texel_bytes;
        let regions: [vk::BufferImageCopy; LAYERS as usize] = std::array::from_fn(|layer| {
            vk::BufferImageCopy::default()
                .buffer_offset(offset as u64 + layer as u64 * layer_bytes)
                .image_subresource(
                    vk::ImageSubresourceLayers::default()
                        .aspect_mask(vk::ImageAspectFlags::COLOR)
                        .base_array_layer(layer as u32)
                        .layer_count(1),
                )
                .image_extent(vk::Extent3D {
                    width,
                    height,
                    depth: 1,
                })
        });
        self.device.cmd_copy_image_to_buffer(
            cmd,
            image,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            rb.buffer,
            &regions,
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

    /// The eyes read back by the last [`Renderer::draw`] that asked for them: both layers, RGBA8.
    pub fn eyes(&self) -> Option<&[u8]> {
        let rb = self.readback.as_ref()?;
        // SAFETY: the mapping lives as long as `self`; the fence wait in `draw` finished the copy.
        Some(unsafe { std::slice::from_raw_parts(rb.mapped, rb.eye_bytes) })
    }

    /// The density map of swapchain image `index` read back by the last [`Renderer::draw`] of that
    /// image that asked for it: both layers, R8G8.
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
        for eye in self.images.drain(..).flat_map(|per| per.eyes) {
            device.destroy_framebuffer(eye.framebuffer, None);
            device.destroy_image_view(eye.density, None);
            device.destroy_image_view(eye.colour, None);
        }
        if let Some(rb) = self.readback.take() {
            device.destroy_buffer(rb.buffer, None);
            device.free_memory(rb.memory, None);
        }
        device.destroy_pipeline(self.pipeline, None);
        device.destroy_pipeline_layout(self.layout, None);
        device.destroy_sampler(self.sampler, None);
        device.destroy_descriptor_pool(self.descriptor_pool, None);
        device.destroy_descriptor_set_layout(self.set_layout, None);
        device.destroy_render_pass(self.render_pass, None);
        device.destroy_fence(self.fence, None);
        device.destroy_command_pool(self.pool, None);
        if let Some(t) = self.timer.take() {
            device.destroy_query_pool(t.pool, None);
        }
        self.pipeline = vk::Pipeline::null();
        self.layout = vk::PipelineLayout::null();
        self.sampler = vk::Sampler::null();
        self.descriptor_pool = vk::DescriptorPool::null();
        self.set_layout = vk::DescriptorSetLayout::null();
        self.render_pass = vk::RenderPass::null();
        self.fence = vk::Fence::null();
        self.pool = vk::CommandPool::null();
    }
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

fn all_layers() -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange::default()
        .aspect_mask(vk::ImageAspectFlags::COLOR)
        .level_count(1)
        .layer_count(LAYERS)
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
