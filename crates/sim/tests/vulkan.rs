//! A Vulkan session on lavapipe through XR_KHR_vulkan_enable2, with real swapchain images, under the
//! Khronos validation layer. Skips (with a reason) when lavapipe or the validation layer is missing,
//! unless FOVEA_REQUIRE_SYSTEM=1.

mod common;

use std::ffi::{c_void, CStr};
use std::ptr::{null, null_mut};

use ash::vk;
use ash::vk::Handle as _;
use common::*;
use fovea_sim::control;
use openxr_sys as xr;
use parking_lot::Mutex;

static MESSAGES: Mutex<Vec<String>> = Mutex::new(Vec::new());

unsafe extern "system" fn on_message(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    _user: *mut c_void,
) -> vk::Bool32 {
    let text = CStr::from_ptr((*data).p_message)
        .to_string_lossy()
        .into_owned();
    MESSAGES.lock().push(format!("{severity:?}: {text}"));
    vk::FALSE
}

fn skip(reason: &str) {
    if std::env::var("FOVEA_REQUIRE_SYSTEM").as_deref() == Ok("1") {
        panic!("FOVEA_REQUIRE_SYSTEM=1 but {reason}");
    }
    eprintln!("skipping: {reason}");
}

const VALIDATION: &CStr = c"VK_LAYER_KHRONOS_validation";

#[test]
fn vulkan_session_on_lavapipe_is_validation_clean() {
    let entry = match unsafe { ash::Entry::load() } {
        Ok(e) => e,
        Err(e) => return skip(&format!("no Vulkan loader ({e})")),
    };
    let layers = unsafe { entry.enumerate_instance_layer_properties() }.unwrap_or_default();
    if !layers
        .iter()
        .any(|l| l.layer_name_as_c_str() == Ok(VALIDATION))
    {
        return skip("VK_LAYER_KHRONOS_validation is not installed");
    }
    // The only test in this binary, so setting the process environment is race-free.
    std::env::set_var("FOVEA_SIM_VK_DEVICE", "llvmpipe");

    let instance = create_instance(config("quest3"), &["XR_KHR_vulkan_enable2"]);
    let sys = system(instance);

    // XR_KHR_vulkan_enable2: the runtime creates the VkInstance through our vkGetInstanceProcAddr.
    let mut reqs = xr::GraphicsRequirementsVulkanKHR {
        ty: xr::GraphicsRequirementsVulkanKHR::TYPE,
        next: null_mut(),
        min_api_version_supported: xr::Version::new(0, 0, 0),
        max_api_version_supported: xr::Version::new(0, 0, 0),
    };
    let binding_early = xr::GraphicsBindingVulkanKHR {
        ty: xr::GraphicsBindingVulkanKHR::TYPE,
        next: null(),
        instance: 1 as _,
        physical_device: 1 as _,
        device: 1 as _,
        queue_family_index: 0,
        queue_index: 0,
    };
    assert_eq!(
        create_session_with(instance, &binding_early as *const _ as *const c_void),
        Err(xr::Result::ERROR_GRAPHICS_REQUIREMENTS_CALL_MISSING)
    );
    assert_eq!(
        unsafe { xrfn!(instance, GetVulkanGraphicsRequirements2KHR)(instance, sys, &mut reqs) },
        xr::Result::SUCCESS
    );
    assert_eq!(reqs.max_api_version_supported, xr::Version::new(1, 3, 0));

    let severity = vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
        | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR;
    let types = vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
        | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
        | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE;
    let mut messenger_info = vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(severity)
        .message_type(types)
        .pfn_user_callback(Some(on_message));
    let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_1);
    let layer_names = [VALIDATION.as_ptr()];
    let ext_names = [ash::ext::debug_utils::NAME.as_ptr()];
    let vk_create = vk::InstanceCreateInfo::default()
        .application_info(&app)
        .enabled_layer_names(&layer_names)
        .enabled_extension_names(&ext_names)
        .push_next(&mut messenger_info);
    let gipa: xr::platform::VkGetInstanceProcAddr =
        unsafe { std::mem::transmute(entry.static_fn().get_instance_proc_addr) };
    let xr_create = xr::VulkanInstanceCreateInfoKHR {
        ty: xr::VulkanInstanceCreateInfoKHR::TYPE,
        next: null(),
        system_id: sys,
        create_flags: xr::VulkanInstanceCreateFlagsKHR::EMPTY,
        pfn_get_instance_proc_addr: Some(gipa),
        vulkan_create_info: &vk_create as *const _ as *const c_void,
        vulkan_allocator: null(),
    };
    let mut raw_instance: xr::platform::VkInstance = null();
    let mut vk_result = 0;
    let r = unsafe {
        xrfn!(instance, CreateVulkanInstanceKHR)(
            instance,
            &xr_create,
            &mut raw_instance,
            &mut vk_result,
        )
    };
    assert_eq!((r, vk_result), (xr::Result::SUCCESS, 0));
    let vk_instance = unsafe {
        ash::Instance::load(
            entry.static_fn(),
            vk::Instance::from_raw(raw_instance as u64),
        )
    };
    let debug_utils = ash::ext::debug_utils::Instance::new(&entry, &vk_instance);
    let messenger =
        unsafe { debug_utils.create_debug_utils_messenger(&messenger_info, None) }.unwrap();

    let get_info = xr::VulkanGraphicsDeviceGetInfoKHR {
        ty: xr::VulkanGraphicsDeviceGetInfoKHR::TYPE,
        next: null(),
        system_id: sys,
        vulkan_instance: raw_instance,
    };
    let mut raw_pd: xr::platform::VkPhysicalDevice = null();
    let r =
        unsafe { xrfn!(instance, GetVulkanGraphicsDevice2KHR)(instance, &get_info, &mut raw_pd) };
    if r != xr::Result::SUCCESS {
        unsafe {
            debug_utils.destroy_debug_utils_messenger(messenger, None);
            vk_instance.destroy_instance(None);
        }
        destroy_instance(instance);
        return skip("lavapipe (llvmpipe) is not available");
    }
    let pd = vk::PhysicalDevice::from_raw(raw_pd as u64);
    let family = unsafe { vk_instance.get_physical_device_queue_family_properties(pd) }
        .iter()
        .position(|f| f.queue_flags.contains(vk::QueueFlags::GRAPHICS))
        .unwrap() as u32;
    let priorities = [1.0];
    let queue_info = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(family)
        .queue_priorities(&priorities)];
    let device_create = vk::DeviceCreateInfo::default().queue_create_infos(&queue_info);
    let xr_device = xr::VulkanDeviceCreateInfoKHR {
        ty: xr::VulkanDeviceCreateInfoKHR::TYPE,
        next: null(),
        system_id: sys,
        create_flags: xr::VulkanDeviceCreateFlagsKHR::EMPTY,
        pfn_get_instance_proc_addr: Some(gipa),
        vulkan_physical_device: raw_pd,
        vulkan_create_info: &device_create as *const _ as *const c_void,
        vulkan_allocator: null(),
    };
    let mut raw_device: xr::platform::VkDevice = null();
    let r = unsafe {
        xrfn!(instance, CreateVulkanDeviceKHR)(
            instance,
            &xr_device,
            &mut raw_device,
            &mut vk_result,
        )
    };
    assert_eq!((r, vk_result), (xr::Result::SUCCESS, 0));
    let device = unsafe {
        ash::Device::load(
            vk_instance.fp_v1_0(),
            vk::Device::from_raw(raw_device as u64),
        )
    };

    let binding = xr::GraphicsBindingVulkanKHR {
        ty: xr::GraphicsBindingVulkanKHR::TYPE,
        next: null(),
        instance: raw_instance,
        physical_device: raw_pd,
        device: raw_device,
        queue_family_index: family,
        queue_index: 0,
    };
    let session = create_session_with(instance, &binding as *const _ as *const c_void).unwrap();
    assert_eq!(begin_session(instance, session), xr::Result::SUCCESS);
    let space = reference_space(instance, session, xr::ReferenceSpaceType::LOCAL);

    let formats_fn = xrfn!(instance, EnumerateSwapchainFormats);
    let mut count = 0;
    unsafe { formats_fn(session, 0, &mut count, null_mut()) };
    let mut formats = vec![0i64; count as usize];
    unsafe { formats_fn(session, count, &mut count, formats.as_mut_ptr()) };
    assert_eq!(formats[0], i64::from(vk::Format::R8G8B8A8_SRGB.as_raw()));
    assert!(
        formats.contains(&i64::from(vk::Format::D32_SFLOAT.as_raw())),
        "{formats:?}"
    );

    let mut color_info = swapchain_info(i64::from(vk::Format::R8G8B8A8_SRGB.as_raw()), 256, 128, 2);
    color_info.usage_flags |= xr::SwapchainUsageFlags::TRANSFER_DST;
    let color = create_swapchain(instance, session, &color_info).unwrap();
    let depth_info = xr::SwapchainCreateInfo {
        usage_flags: xr::SwapchainUsageFlags::DEPTH_STENCIL_ATTACHMENT,
        ..swapchain_info(i64::from(vk::Format::D32_SFLOAT.as_raw()), 256, 128, 2)
    };
    let depth = create_swapchain(instance, session, &depth_info).unwrap();
    // Storage on an sRGB format is not supported by lavapipe: the runtime says so instead of
    // creating an invalid image.
    let storage_info = xr::SwapchainCreateInfo {
        usage_flags: xr::SwapchainUsageFlags::UNORDERED_ACCESS,
        ..swapchain_info(i64::from(vk::Format::R8G8B8A8_SRGB.as_raw()), 64, 64, 1)
    };
    assert_eq!(
        create_swapchain(instance, session, &storage_info),
        Err(xr::Result::ERROR_FEATURE_UNSUPPORTED)
    );

    let images_fn = xrfn!(instance, EnumerateSwapchainImages);
    let blank = xr::SwapchainImageVulkanKHR {
        ty: xr::SwapchainImageVulkanKHR::TYPE,
        next: null_mut(),
        image: 0,
    };
    let mut images = [blank; 3];
    assert_eq!(
        unsafe { images_fn(color, 0, &mut count, null_mut()) },
        xr::Result::SUCCESS
    );
    assert_eq!(count, 3);
    let r = unsafe {
        images_fn(
            color,
            3,
            &mut count,
            images.as_mut_ptr() as *mut xr::SwapchainImageBaseHeader,
        )
    };
    assert_eq!(r, xr::Result::SUCCESS);
    assert!(images.iter().all(|i| i.image != 0) && images[0].image != images[1].image);
    let mut wrong = [xr::SwapchainImageVulkanKHR {
        ty: xr::StructureType::SWAPCHAIN_IMAGE_OPENGL_KHR,
        ..blank
    }; 3];
    let r = unsafe {
        images_fn(
            color,
            3,
            &mut count,
            wrong.as_mut_ptr() as *mut xr::SwapchainImageBaseHeader,
        )
    };
    assert_eq!(r, xr::Result::ERROR_VALIDATION_FAILURE);

    // The application renders (a transfer clear) into each image in the layout the runtime
    // promised; the validation layer checks the layouts at submit.
    let pool = unsafe {
        device.create_command_pool(
            &vk::CommandPoolCreateInfo::default()
                .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER)
                .queue_family_index(family),
            None,
        )
    }
    .unwrap();
    let cb = unsafe {
        device.allocate_command_buffers(
            &vk::CommandBufferAllocateInfo::default()
                .command_pool(pool)
                .level(vk::CommandBufferLevel::PRIMARY)
                .command_buffer_count(1),
        )
    }
    .unwrap()[0];
    let queue = unsafe { device.get_device_queue(family, 0) };
    let acquire = xrfn!(instance, AcquireSwapchainImage);
    let wait = xrfn!(instance, WaitSwapchainImage);
    let release = xrfn!(instance, ReleaseSwapchainImage);
    let wi = xr::SwapchainImageWaitInfo {
        ty: xr::SwapchainImageWaitInfo::TYPE,
        next: null(),
        timeout: xr::Duration::INFINITE,
    };
    let range = vk::ImageSubresourceRange {
        aspect_mask: vk::ImageAspectFlags::COLOR,
        base_mip_level: 0,
        level_count: 1,
        base_array_layer: 0,
        layer_count: 2,
    };
    for frame in 0..4 {
        let state = wait_frame(instance, session).unwrap();
        begin_frame(instance, session);
        let mut index = 0;
        unsafe {
            assert_eq!(acquire(color, null(), &mut index), xr::Result::SUCCESS);
            assert_eq!(wait(color, &wi), xr::Result::SUCCESS);
            let image = vk::Image::from_raw(images[index as usize].image);
            let to_transfer = vk::ImageMemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                .dst_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .old_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .image(image)
                .subresource_range(range);
            let back = to_transfer
                .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .dst_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .new_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL);
            device
                .begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
                .unwrap();
            device.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[to_transfer],
            );
            let clear = vk::ClearColorValue {
                float32: [0.2, 0.4, 0.6, 1.0],
            };
            device.cmd_clear_color_image(
                cb,
                image,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &clear,
                &[range],
            );
            device.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[back],
            );
            device.end_command_buffer(cb).unwrap();
            let cbs = [cb];
            device
                .queue_submit(
                    queue,
                    &[vk::SubmitInfo::default().command_buffers(&cbs)],
                    vk::Fence::null(),
                )
                .unwrap();
            device.queue_wait_idle(queue).unwrap();
            assert_eq!(release(color, null()), xr::Result::SUCCESS);
            assert_eq!(acquire(depth, null(), &mut index), xr::Result::SUCCESS);
            assert_eq!(wait(depth, &wi), xr::Result::SUCCESS);
            assert_eq!(release(depth, null()), xr::Result::SUCCESS);
        }
        let view = |i: u32| xr::CompositionLayerProjectionView {
            ty: xr::CompositionLayerProjectionView::TYPE,
            next: null(),
            pose: Default::default(),
            fov: Default::default(),
            sub_image: xr::SwapchainSubImage {
                swapchain: color,
                image_rect: xr::Rect2Di {
                    offset: Default::default(),
                    extent: xr::Extent2Di {
                        width: 256,
                        height: 128,
                    },
                },
                image_array_index: i,
            },
        };
        let views = [view(0), view(1)];
        let layer = xr::CompositionLayerProjection {
            ty: xr::CompositionLayerProjection::TYPE,
            next: null(),
            layer_flags: xr::CompositionLayerFlags::EMPTY,
            space,
            view_count: 2,
            views: views.as_ptr(),
        };
        let layers = [&layer as *const _ as *const xr::CompositionLayerBaseHeader];
        assert_eq!(
            end_frame(instance, session, state.predicted_display_time, &layers),
            xr::Result::SUCCESS,
            "frame {frame}"
        );
    }
    assert_eq!(control::end_frame_views(instance).len(), 4);

    // Teardown: the runtime's images go with the session; the app's device must then be clean.
    assert_eq!(
        unsafe { xrfn!(instance, DestroySwapchain)(depth) },
        xr::Result::SUCCESS
    );
    assert_eq!(
        unsafe { xrfn!(instance, DestroySession)(session) },
        xr::Result::SUCCESS
    );
    unsafe {
        device.device_wait_idle().unwrap();
        device.destroy_command_pool(pool, None);
        device.destroy_device(None);
    }
    destroy_instance(instance);
    unsafe {
        debug_utils.destroy_debug_utils_messenger(messenger, None);
        vk_instance.destroy_instance(None);
    }
    let messages = MESSAGES.lock();
    assert!(
        messages.is_empty(),
        "validation reported {} message(s):\n{}",
        messages.len(),
        messages.join("\n")
    );
}
