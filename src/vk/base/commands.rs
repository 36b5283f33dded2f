//! The one list of Vulkan commands the layer intercepts.
//!
//! Each line names the command, the field that holds the next layer's pointer, its ash `PFN_` type
//! and the hook; device commands also say when the hook is needed. From that list
//! [`crate::vk::base::next`] derives the next-layer tables and [`crate::vk::dispatch`] the hook
//! tables that `vkGetInstanceProcAddr` and `vkGetDeviceProcAddr` answer from, so a command is
//! declared once and the compiler checks each hook against the command's signature. A command not
//! listed here is never intercepted: `vkGetDeviceProcAddr` hands out the next layer's own pointer
//! for it (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>,
//! "Layer Conventions and Rules"). The hooks are named by the module they live in under
//! `crate::vk::hooks`, where each is declared with the chassis (`hook!`: how its record is found,
//! which field of the next-layer table it goes down through, what it returns where the layer
//! cannot act; docs/ARCHITECTURE.md#how-a-hook-is-declared); only the hook tables, where they are
//! expanded, resolve those names.

/// When a device command's hook is handed out by `vkGetDeviceProcAddr`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum When {
    /// On every device (the layer must see it, e.g. to forget the device).
    Always,
    /// Only on devices that emulate fragment density maps; others get the next layer's pointer.
    Emulated,
    /// On every device fovea foveates, by emulating density maps or by injecting shading-rate maps
    /// into eye passes (docs/injection.md): image and view tracking, pipelines, dynamic rendering,
    /// command buffers' records, and the submits that carry the maps' uploads.
    Foveating,
    /// Only on devices that inject: what concerns an application's own shading rates, which an
    /// emulating device never has (docs/injection.md#apps-that-set-rates).
    Injecting,
    /// A command of an extension the layer itself offers on emulating devices
    /// (`VK_EXT_fragment_density_map_offset`'s `vkCmdEndRendering2EXT`): handed out there whether
    /// or not the next layer has it, which it does not.
    Provided,
}

impl When {
    /// Whether the hook is handed out on a device that emulates (`emulated`) or injects
    /// (`injected`).
    pub fn applies(self, emulated: bool, injected: bool) -> bool {
        match self {
            When::Always => true,
            When::Emulated => emulated,
            When::Foveating => emulated || injected,
            When::Injecting => injected,
            When::Provided => emulated,
        }
    }
}

/// Hands the command list to `$then`, a macro taking
/// `instance { name => field: PFN = hook; ... } device { name => field: PFN = hook, when; ... }`.
macro_rules! command_list {
    ($then:ident) => {
        $then! {
            instance {
                c"vkDestroyInstance" => destroy_instance: PFN_vkDestroyInstance = instance::destroy_instance;
                c"vkCreateDevice" => create_device: PFN_vkCreateDevice = device::create_device;
                c"vkEnumerateDeviceExtensionProperties" => enumerate_device_extension_properties:
                    PFN_vkEnumerateDeviceExtensionProperties = physical::enumerate_device_extension_properties;
                c"vkGetPhysicalDeviceFeatures2" => get_features2: PFN_vkGetPhysicalDeviceFeatures2 =
                    physical::get_features2;
                c"vkGetPhysicalDeviceFeatures2KHR" => get_features2_khr: PFN_vkGetPhysicalDeviceFeatures2 =
                    physical::get_features2_khr;
                c"vkGetPhysicalDeviceProperties2" => get_properties2: PFN_vkGetPhysicalDeviceProperties2 =
                    physical::get_properties2;
                c"vkGetPhysicalDeviceProperties2KHR" => get_properties2_khr: PFN_vkGetPhysicalDeviceProperties2 =
                    physical::get_properties2_khr;
                c"vkGetPhysicalDeviceFormatProperties" => get_format_properties:
                    PFN_vkGetPhysicalDeviceFormatProperties = physical::get_format_properties;
                c"vkGetPhysicalDeviceFormatProperties2" => get_format_properties2:
                    PFN_vkGetPhysicalDeviceFormatProperties2 = physical::get_format_properties2;
                c"vkGetPhysicalDeviceFormatProperties2KHR" => get_format_properties2_khr:
                    PFN_vkGetPhysicalDeviceFormatProperties2 = physical::get_format_properties2_khr;
                c"vkGetPhysicalDeviceImageFormatProperties" => get_image_format_properties:
                    PFN_vkGetPhysicalDeviceImageFormatProperties = physical::get_image_format_properties;
                c"vkGetPhysicalDeviceImageFormatProperties2" => get_image_format_properties2:
                    PFN_vkGetPhysicalDeviceImageFormatProperties2 = physical::get_image_format_properties2;
                c"vkGetPhysicalDeviceImageFormatProperties2KHR" => get_image_format_properties2_khr:
                    PFN_vkGetPhysicalDeviceImageFormatProperties2 = physical::get_image_format_properties2_khr;
            }
            device {
                c"vkDestroyDevice" => destroy_device: PFN_vkDestroyDevice = device::destroy_device, When::Always;
                c"vkCreateImage" => create_image: PFN_vkCreateImage = image::create_image, When::Foveating;
                c"vkCreateGraphicsPipelines" => create_graphics_pipelines: PFN_vkCreateGraphicsPipelines =
                    pipeline::create_graphics_pipelines, When::Foveating;
                c"vkCreateShadersEXT" => create_shaders_ext: PFN_vkCreateShadersEXT =
                    pipeline::create_shaders_ext, When::Emulated;
                c"vkCreateShaderModule" => create_shader_module: PFN_vkCreateShaderModule =
                    pipeline::create_shader_module, When::Emulated;
                c"vkCreateSampler" => create_sampler: PFN_vkCreateSampler = pipeline::create_sampler,
                    When::Emulated;
                c"vkCmdPipelineBarrier" => cmd_pipeline_barrier: PFN_vkCmdPipelineBarrier =
                    barrier::cmd_pipeline_barrier, When::Emulated;
                c"vkCmdPipelineBarrier2" => cmd_pipeline_barrier2: PFN_vkCmdPipelineBarrier2 =
                    barrier::cmd_pipeline_barrier2, When::Emulated;
                c"vkCmdPipelineBarrier2KHR" => cmd_pipeline_barrier2_khr: PFN_vkCmdPipelineBarrier2 =
                    barrier::cmd_pipeline_barrier2_khr, When::Emulated;
                c"vkCmdWaitEvents" => cmd_wait_events: PFN_vkCmdWaitEvents = barrier::cmd_wait_events,
                    When::Emulated;
                c"vkCmdWaitEvents2" => cmd_wait_events2: PFN_vkCmdWaitEvents2 = barrier::cmd_wait_events2,
                    When::Emulated;
                c"vkCmdWaitEvents2KHR" => cmd_wait_events2_khr: PFN_vkCmdWaitEvents2 =
                    barrier::cmd_wait_events2_khr, When::Emulated;
                c"vkCmdSetEvent2" => cmd_set_event2: PFN_vkCmdSetEvent2 = barrier::cmd_set_event2,
                    When::Emulated;
                c"vkCmdSetEvent2KHR" => cmd_set_event2_khr: PFN_vkCmdSetEvent2 =
                    barrier::cmd_set_event2_khr, When::Emulated;
                // Command buffers' queue families, to tell the release half of an ownership transfer.
                c"vkCreateCommandPool" => create_command_pool: PFN_vkCreateCommandPool =
                    barrier::create_command_pool, When::Emulated;
                // Stage masks of event sets and resets and of timestamps lose the density-map stage.
                c"vkCmdSetEvent" => cmd_set_event: PFN_vkCmdSetEvent = barrier::cmd_set_event,
                    When::Emulated;
                c"vkCmdResetEvent" => cmd_reset_event: PFN_vkCmdResetEvent = barrier::cmd_reset_event,
                    When::Emulated;
                c"vkCmdResetEvent2" => cmd_reset_event2: PFN_vkCmdResetEvent2 = barrier::cmd_reset_event2,
                    When::Emulated;
                c"vkCmdResetEvent2KHR" => cmd_reset_event2_khr: PFN_vkCmdResetEvent2 =
                    barrier::cmd_reset_event2_khr, When::Emulated;
                c"vkCmdWriteTimestamp" => cmd_write_timestamp: PFN_vkCmdWriteTimestamp =
                    barrier::cmd_write_timestamp, When::Emulated;
                c"vkCmdWriteTimestamp2" => cmd_write_timestamp2: PFN_vkCmdWriteTimestamp2 =
                    barrier::cmd_write_timestamp2, When::Emulated;
                c"vkCmdWriteTimestamp2KHR" => cmd_write_timestamp2_khr: PFN_vkCmdWriteTimestamp2 =
                    barrier::cmd_write_timestamp2_khr, When::Emulated;
                // Shadow clears go ahead of the application's submits; wait stages are translated.
                c"vkQueueSubmit" => queue_submit: PFN_vkQueueSubmit = submit::queue_submit, When::Foveating;
                c"vkQueueSubmit2" => queue_submit2: PFN_vkQueueSubmit2 = submit::queue_submit2,
                    When::Foveating;
                c"vkQueueSubmit2KHR" => queue_submit2_khr: PFN_vkQueueSubmit2 = submit::queue_submit2_khr,
                    When::Foveating;
                // The attachment path: shadows, render passes, framebuffers, dynamic rendering.
                c"vkDestroyImage" => destroy_image: PFN_vkDestroyImage = image::destroy_image, When::Foveating;
                // Host-side transitions name the density-map layout as barriers do (host image copy).
                c"vkTransitionImageLayout" => transition_image_layout: PFN_vkTransitionImageLayoutEXT =
                    image::transition_image_layout, When::Emulated;
                c"vkTransitionImageLayoutEXT" => transition_image_layout_ext:
                    PFN_vkTransitionImageLayoutEXT = image::transition_image_layout_ext, When::Emulated;
                c"vkCreateImageView" => create_image_view: PFN_vkCreateImageView =
                    image::create_image_view, When::Foveating;
                c"vkDestroyImageView" => destroy_image_view: PFN_vkDestroyImageView =
                    image::destroy_image_view, When::Foveating;
                c"vkCreateRenderPass" => create_render_pass: PFN_vkCreateRenderPass =
                    pass::create_render_pass, When::Foveating;
                c"vkCreateRenderPass2" => create_render_pass2: PFN_vkCreateRenderPass2 =
                    pass::create_render_pass2, When::Foveating;
                c"vkCreateRenderPass2KHR" => create_render_pass2_khr: PFN_vkCreateRenderPass2 =
                    pass::create_render_pass2_khr, When::Foveating;
                c"vkDestroyRenderPass" => destroy_render_pass: PFN_vkDestroyRenderPass =
                    pass::destroy_render_pass, When::Foveating;
                c"vkCreateFramebuffer" => create_framebuffer: PFN_vkCreateFramebuffer =
                    pass::create_framebuffer, When::Foveating;
                c"vkDestroyFramebuffer" => destroy_framebuffer: PFN_vkDestroyFramebuffer =
                    pass::destroy_framebuffer, When::Foveating;
                c"vkCmdBeginRenderPass" => cmd_begin_render_pass: PFN_vkCmdBeginRenderPass =
                    pass::cmd_begin_render_pass, When::Foveating;
                c"vkCmdBeginRenderPass2" => cmd_begin_render_pass2: PFN_vkCmdBeginRenderPass2 =
                    pass::cmd_begin_render_pass2, When::Foveating;
                c"vkCmdBeginRenderPass2KHR" => cmd_begin_render_pass2_khr: PFN_vkCmdBeginRenderPass2 =
                    pass::cmd_begin_render_pass2_khr, When::Foveating;
                c"vkCmdBeginRendering" => cmd_begin_rendering: PFN_vkCmdBeginRendering =
                    pass::cmd_begin_rendering, When::Foveating;
                c"vkCmdBeginRenderingKHR" => cmd_begin_rendering_khr: PFN_vkCmdBeginRendering =
                    pass::cmd_begin_rendering_khr, When::Foveating;
                // Density-map offsets arrive with the end of a pass; their structs never reach the
                // driver (docs/vulkan-layer.md#density-map-offsets).
                // Coarse blocks are reconstructed after the pass instance ends
                // (docs/reconstruction.md).
                c"vkCmdEndRenderPass" => cmd_end_render_pass: PFN_vkCmdEndRenderPass =
                    pass::cmd_end_render_pass, When::Foveating;
                c"vkCmdEndRendering" => cmd_end_rendering: PFN_vkCmdEndRendering =
                    pass::cmd_end_rendering, When::Foveating;
                c"vkCmdEndRenderingKHR" => cmd_end_rendering_khr: PFN_vkCmdEndRendering =
                    pass::cmd_end_rendering_khr, When::Foveating;
                c"vkCmdEndRenderPass2" => cmd_end_render_pass2: PFN_vkCmdEndRenderPass2 =
                    pass::cmd_end_render_pass2, When::Foveating;
                c"vkCmdEndRenderPass2KHR" => cmd_end_render_pass2_khr: PFN_vkCmdEndRenderPass2 =
                    pass::cmd_end_render_pass2_khr, When::Foveating;
                c"vkCmdNextSubpass2" => cmd_next_subpass2: PFN_vkCmdNextSubpass2 =
                    pass::cmd_next_subpass2, When::Emulated;
                c"vkCmdNextSubpass2KHR" => cmd_next_subpass2_khr: PFN_vkCmdNextSubpass2 =
                    pass::cmd_next_subpass2_khr, When::Emulated;
                c"vkCmdEndRendering2EXT" => cmd_end_rendering2_ext: PFN_vkCmdEndRendering2KHR =
                    pass::cmd_end_rendering2_ext, When::Provided;
                c"vkCmdEndRendering2KHR" => cmd_end_rendering2_khr: PFN_vkCmdEndRendering2KHR =
                    pass::cmd_end_rendering2_khr, When::Foveating;
                // The application's own rates meet the injected attachment.
                c"vkCmdSetFragmentShadingRateKHR" => cmd_set_fragment_shading_rate:
                    PFN_vkCmdSetFragmentShadingRateKHR = pipeline::cmd_set_fragment_shading_rate,
                    When::Injecting;
                // Density maps the application writes are converted at pass begin, and coarse blocks
                // reconstructed at pass end (docs/reconstruction.md); the application's compute
                // bindings are recorded so that they can be given back after either dispatch.
                c"vkBeginCommandBuffer" => begin_command_buffer: PFN_vkBeginCommandBuffer =
                    record::begin_command_buffer, When::Foveating;
                c"vkAllocateCommandBuffers" => allocate_command_buffers: PFN_vkAllocateCommandBuffers =
                    record::allocate_command_buffers, When::Foveating;
                c"vkFreeCommandBuffers" => free_command_buffers: PFN_vkFreeCommandBuffers =
                    record::free_command_buffers, When::Foveating;
                c"vkDestroyCommandPool" => destroy_command_pool: PFN_vkDestroyCommandPool =
                    record::destroy_command_pool, When::Foveating;
                // Conversions run outside the application's conditional rendering.
                c"vkCmdBeginConditionalRenderingEXT" => cmd_begin_conditional_rendering_ext:
                    PFN_vkCmdBeginConditionalRenderingEXT = record::cmd_begin_conditional_rendering,
                    When::Foveating;
                c"vkCmdEndConditionalRenderingEXT" => cmd_end_conditional_rendering_ext:
                    PFN_vkCmdEndConditionalRenderingEXT = record::cmd_end_conditional_rendering,
                    When::Foveating;
                c"vkCmdBindPipeline" => cmd_bind_pipeline: PFN_vkCmdBindPipeline =
                    record::cmd_bind_pipeline, When::Foveating;
                c"vkCmdBindDescriptorSets" => cmd_bind_descriptor_sets: PFN_vkCmdBindDescriptorSets =
                    record::cmd_bind_descriptor_sets, When::Foveating;
                c"vkCmdPushConstants" => cmd_push_constants: PFN_vkCmdPushConstants =
                    record::cmd_push_constants, When::Foveating;
                c"vkCmdPushDescriptorSetKHR" => cmd_push_descriptor_set_khr: PFN_vkCmdPushDescriptorSetKHR =
                    record::cmd_push_descriptor_set_khr, When::Foveating;
                c"vkCmdPushDescriptorSetWithTemplateKHR" => cmd_push_descriptor_set_with_template_khr:
                    PFN_vkCmdPushDescriptorSetWithTemplateKHR =
                    record::cmd_push_descriptor_set_with_template_khr, When::Foveating;
            }
        }
    };
}

pub(in crate::vk) use command_list;
