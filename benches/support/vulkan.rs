//! What the Vulkan benches share: the layer manifests on a search path, an instance on lavapipe
//! through the strict test double (and fovea's layer above it, or not), and the few objects every
//! side records with.

use ash::vk;

/// fovea's Vulkan layer.
pub const FOVEA: &std::ffi::CStr = c"VK_LAYER_FOVEA_fragment_density_map";
/// The extension fovea offers on emulating devices.
pub const FDM_EXT: &std::ffi::CStr = c"VK_EXT_fragment_density_map";
pub const FDM_OFFSET_EXT: &std::ffi::CStr = c"VK_EXT_fragment_density_map_offset";

/// Writes the double's and this workspace's fovea manifests into a folder of their own and puts
/// it on the loader's search path, with the double posing as an NVIDIA GPU (shading-rate
/// attachments, no density maps: the emulating case). Call before the loader first reads the
/// environment, while nothing else runs. Returns the double's library as its manifest names it,
/// for [`fovea_vkdouble::Loaded::open`].
pub fn layers_on_search_path(tag: &str) -> Result<std::path::PathBuf, String> {
    let fovea_lib = fovea_harness::artifact("libfovea.so")?
        .canonicalize()
        .map_err(|e| e.to_string())?;
    let double_lib = fovea_vkdouble::find_library()?;
    let dir = std::env::temp_dir().join(format!("fovea-{tag}-{}", std::process::id()));
    fovea_vkdouble::write_manifest(&dir, &double_lib).map_err(|e| e.to_string())?;
    let checked_in = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("manifest/vulkan/VK_LAYER_FOVEA_fragment_density_map.json");
    let mut manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&checked_in).map_err(|e| e.to_string())?)
            .map_err(|e| e.to_string())?;
    manifest["layer"]["library_path"] = serde_json::json!(fovea_lib.to_string_lossy());
    std::fs::write(
        dir.join("VK_LAYER_FOVEA_fragment_density_map.json"),
        manifest.to_string(),
    )
    .map_err(|e| e.to_string())?;
    std::env::set_var("VK_ADD_LAYER_PATH", &dir);
    std::env::set_var(fovea_vkdouble::PROFILE_ENV, "nvidia");
    Ok(double_lib)
}

/// An instance with the double (and fovea above it where `with_fovea`), and lavapipe's physical
/// device in it.
pub fn instance_on_lavapipe(
    entry: &ash::Entry,
    with_fovea: bool,
) -> Result<(ash::Instance, vk::PhysicalDevice), String> {
    let mut layers = vec![fovea_vkdouble::LAYER_NAME.as_ptr()];
    if with_fovea {
        layers.insert(0, FOVEA.as_ptr());
    }
    let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_3);
    let info = vk::InstanceCreateInfo::default()
        .application_info(&app)
        .enabled_layer_names(&layers);
    // SAFETY: every struct lives across its call.
    let instance = unsafe { entry.create_instance(&info, None) }
        .map_err(|e| format!("vkCreateInstance: {e}"))?;
    // SAFETY: plain queries on the live instance.
    let physical = unsafe { instance.enumerate_physical_devices() }
        .unwrap_or_default()
        .into_iter()
        .find(|&p| {
            // SAFETY: as above.
            unsafe { instance.get_physical_device_properties(p) }
                .device_name_as_c_str()
                .is_ok_and(|n| n.to_string_lossy().contains("llvmpipe"))
        });
    match physical {
        Some(p) => Ok((instance, p)),
        None => {
            // SAFETY: nothing was made from it.
            unsafe { instance.destroy_instance(None) };
            Err("lavapipe (llvmpipe) is not installed".into())
        }
    }
}

/// A device on queue family 0 with dynamic rendering and synchronization2, and
/// `VK_EXT_fragment_density_map` with `VK_EXT_fragment_density_map_offset` (which fovea emulates on
/// the double's shading-rate GPU) or `VK_KHR_fragment_shading_rate` with pipeline rates where
/// asked.
///
/// # Safety
/// `physical` must be `instance`'s.
pub unsafe fn device(
    instance: &ash::Instance,
    physical: vk::PhysicalDevice,
    density_maps: bool,
    pipeline_rates: bool,
) -> Result<ash::Device, String> {
    // SAFETY: as the caller promised.
    unsafe { device_queues(instance, physical, density_maps, pipeline_rates, 1) }
}

/// [`device`] with `count` queues of family 0 (the double offers more than lavapipe's one where
/// asked, `fovea_vkdouble::Loaded::set_queues`).
///
/// # Safety
/// `physical` must be `instance`'s.
#[allow(dead_code)] // Not every bench that includes this file makes several queues.
pub unsafe fn device_queues(
    instance: &ash::Instance,
    physical: vk::PhysicalDevice,
    density_maps: bool,
    pipeline_rates: bool,
    count: u32,
) -> Result<ash::Device, String> {
    assert!(!(density_maps && pipeline_rates), "one extension at a time");
    let prio = vec![1.0; count as usize];
    let queues = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(0)
        .queue_priorities(&prio)];
    let fdm_exts = [FDM_EXT.as_ptr(), FDM_OFFSET_EXT.as_ptr()];
    let mut fdm = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default()
        .fragment_density_map(true)
        .fragment_density_map_non_subsampled_images(true);
    let mut offsets = vk::PhysicalDeviceFragmentDensityMapOffsetFeaturesQCOM::default()
        .fragment_density_map_offset(true);
    let fsr_exts = [ash::khr::fragment_shading_rate::NAME.as_ptr()];
    let mut rates = vk::PhysicalDeviceFragmentShadingRateFeaturesKHR::default()
        .pipeline_fragment_shading_rate(true);
    let mut v13 = vk::PhysicalDeviceVulkan13Features::default()
        .dynamic_rendering(true)
        .synchronization2(true);
    let mut info = vk::DeviceCreateInfo::default()
        .queue_create_infos(&queues)
        .push_next(&mut v13);
    if density_maps {
        info = info
            .enabled_extension_names(&fdm_exts)
            .push_next(&mut fdm)
            .push_next(&mut offsets);
    }
    if pipeline_rates {
        info = info
            .enabled_extension_names(&fsr_exts)
            .push_next(&mut rates);
    }
    // SAFETY: as the caller promised; every struct lives across the call.
    unsafe { instance.create_device(physical, &info, None) }
        .map_err(|e| format!("vkCreateDevice: {e}"))
}

/// A resettable command pool on queue family 0 and one primary command buffer from it.
///
/// # Safety
/// `device` must be live.
pub unsafe fn command_buffer(device: &ash::Device) -> (vk::CommandPool, vk::CommandBuffer) {
    // SAFETY: as the caller promised; every struct lives across its call.
    unsafe {
        let pool = device
            .create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER)
                    .queue_family_index(0),
                None,
            )
            .expect("vkCreateCommandPool");
        let cb = device
            .allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool)
                    .level(vk::CommandBufferLevel::PRIMARY)
                    .command_buffer_count(1),
            )
            .expect("vkAllocateCommandBuffers")[0];
        (pool, cb)
    }
}

/// One image with memory and a view.
pub struct Target {
    pub image: vk::Image,
    pub memory: vk::DeviceMemory,
    pub view: vk::ImageView,
}

impl Target {
    /// A 2D image of one level and layer, with memory bound and a view of it.
    ///
    /// # Safety
    /// `device` must be live and made from `physical`.
    pub unsafe fn new(
        instance: &ash::Instance,
        physical: vk::PhysicalDevice,
        device: &ash::Device,
        format: vk::Format,
        extent: [u32; 2],
        usage: vk::ImageUsageFlags,
    ) -> Target {
        // SAFETY: as the caller promised.
        unsafe {
            Target::with_flags(
                instance,
                physical,
                device,
                format,
                extent,
                usage,
                vk::ImageCreateFlags::empty(),
            )
        }
    }

    /// [`Target::new`] with image create `flags`.
    ///
    /// # Safety
    /// As [`Target::new`].
    pub unsafe fn with_flags(
        instance: &ash::Instance,
        physical: vk::PhysicalDevice,
        device: &ash::Device,
        format: vk::Format,
        extent: [u32; 2],
        usage: vk::ImageUsageFlags,
        flags: vk::ImageCreateFlags,
    ) -> Target {
        let info = vk::ImageCreateInfo::default()
            .flags(flags)
            .image_type(vk::ImageType::TYPE_2D)
            .format(format)
            .extent(vk::Extent3D {
                width: extent[0],
                height: extent[1],
                depth: 1,
            })
            .mip_levels(1)
            .array_layers(1)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(usage);
        // SAFETY: as the caller promised; every struct lives across its call.
        unsafe {
            let image = device.create_image(&info, None).expect("vkCreateImage");
            let req = device.get_image_memory_requirements(image);
            let props = instance.get_physical_device_memory_properties(physical);
            let ty = (0..props.memory_type_count)
                .find(|i| req.memory_type_bits & (1 << i) != 0)
                .expect("a memory type");
            let alloc = vk::MemoryAllocateInfo::default()
                .allocation_size(req.size)
                .memory_type_index(ty);
            let memory = device.allocate_memory(&alloc, None).expect("memory");
            device
                .bind_image_memory(image, memory, 0)
                .expect("vkBindImageMemory");
            let view = device
                .create_image_view(
                    &vk::ImageViewCreateInfo::default()
                        .image(image)
                        .view_type(vk::ImageViewType::TYPE_2D)
                        .format(format)
                        .subresource_range(colour_range()),
                    None,
                )
                .expect("vkCreateImageView");
            Target {
                image,
                memory,
                view,
            }
        }
    }

    /// # Safety
    /// `device` must be the one that made it, and nothing may use it any more.
    pub unsafe fn destroy(&self, device: &ash::Device) {
        // SAFETY: as the caller promised.
        unsafe {
            device.destroy_image_view(self.view, None);
            device.destroy_image(self.image, None);
            device.free_memory(self.memory, None);
        }
    }
}

/// The one level and layer of a colour image.
pub fn colour_range() -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange::default()
        .aspect_mask(vk::ImageAspectFlags::COLOR)
        .level_count(1)
        .layer_count(1)
}

/// A one-subpass pass writing an RGBA8 colour attachment, with a density map read through
/// `VkRenderPassFragmentDensityMapCreateInfoEXT` where `density` is given, and its framebuffer.
///
/// # Safety
/// `device` must be live; the views must be its own.
pub unsafe fn pass_and_framebuffer(
    device: &ash::Device,
    color: vk::ImageView,
    density: Option<vk::ImageView>,
    size: u32,
) -> (vk::RenderPass, vk::Framebuffer) {
    let mut attachments = vec![vk::AttachmentDescription::default()
        .format(vk::Format::R8G8B8A8_UNORM)
        .samples(vk::SampleCountFlags::TYPE_1)
        .load_op(vk::AttachmentLoadOp::DONT_CARE)
        .store_op(vk::AttachmentStoreOp::STORE)
        .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
        .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
        .initial_layout(vk::ImageLayout::UNDEFINED)
        .final_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)];
    if density.is_some() {
        attachments.push(
            vk::AttachmentDescription::default()
                .format(vk::Format::R8G8_UNORM)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(vk::AttachmentLoadOp::LOAD)
                .store_op(vk::AttachmentStoreOp::DONT_CARE)
                .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
                .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
                .initial_layout(vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT)
                .final_layout(vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT),
        );
    }
    let refs = [vk::AttachmentReference::default()
        .attachment(0)
        .layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)];
    let subpasses = [vk::SubpassDescription::default()
        .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
        .color_attachments(&refs)];
    let mut fdm = vk::RenderPassFragmentDensityMapCreateInfoEXT::default()
        .fragment_density_map_attachment(
            vk::AttachmentReference::default()
                .attachment(1)
                .layout(vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT),
        );
    let mut info = vk::RenderPassCreateInfo::default()
        .attachments(&attachments)
        .subpasses(&subpasses);
    if density.is_some() {
        info = info.push_next(&mut fdm);
    }
    let views: Vec<vk::ImageView> = std::iter::once(color).chain(density).collect();
    // SAFETY: as the caller promised; every struct lives across its call.
    unsafe {
        let pass = device
            .create_render_pass(&info, None)
            .expect("vkCreateRenderPass");
        let framebuffer = device
            .create_framebuffer(
                &vk::FramebufferCreateInfo::default()
                    .render_pass(pass)
                    .attachments(&views)
                    .width(size)
                    .height(size)
                    .layers(1),
                None,
            )
            .expect("vkCreateFramebuffer");
        (pass, framebuffer)
    }
}

/// A compute pipeline (`tests/suite/shaders/store.comp`) and its layout (one storage buffer,
/// eight bytes of push constants).
///
/// # Safety
/// `device` must be live.
pub unsafe fn compute_pipeline(device: &ash::Device) -> (vk::PipelineLayout, vk::Pipeline) {
    let code = ash::util::read_spv(&mut std::io::Cursor::new(
        &include_bytes!("../../tests/suite/shaders/store.comp.spv")[..],
    ))
    .expect("SPIR-V");
    let bindings = [vk::DescriptorSetLayoutBinding::default()
        .binding(0)
        .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
        .descriptor_count(1)
        .stage_flags(vk::ShaderStageFlags::COMPUTE)];
    let ranges = [vk::PushConstantRange {
        stage_flags: vk::ShaderStageFlags::COMPUTE,
        offset: 0,
        size: 8,
    }];
    // SAFETY: as the caller promised; every struct lives across its call.
    unsafe {
        let set_layout = device
            .create_descriptor_set_layout(
                &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                None,
            )
            .expect("vkCreateDescriptorSetLayout");
        let set_layouts = [set_layout];
        let layout = device
            .create_pipeline_layout(
                &vk::PipelineLayoutCreateInfo::default()
                    .set_layouts(&set_layouts)
                    .push_constant_ranges(&ranges),
                None,
            )
            .expect("vkCreatePipelineLayout");
        device.destroy_descriptor_set_layout(set_layout, None);
        let module = device
            .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&code), None)
            .expect("vkCreateShaderModule");
        let info = [vk::ComputePipelineCreateInfo::default()
            .stage(
                vk::PipelineShaderStageCreateInfo::default()
                    .stage(vk::ShaderStageFlags::COMPUTE)
                    .module(module)
                    .name(c"main"),
            )
            .layout(layout)];
        let pipeline = device
            .create_compute_pipelines(vk::PipelineCache::null(), &info, None)
            .expect("vkCreateComputePipelines")[0];
        device.destroy_shader_module(module, None);
        (layout, pipeline)
    }
}

/// The median of `v` (the upper one of an even count).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
