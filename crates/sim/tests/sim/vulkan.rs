//! A Vulkan session on lavapipe through XR_KHR_vulkan_enable2, with real swapchain images, under the
//! Khronos validation layer. Skips (with a reason) when lavapipe or the validation layer is missing,
//! unless FOVEA_REQUIRE_SYSTEM=1.

use std::ffi::c_void;
use std::ptr::{null, null_mut};

use crate::common::*;
use ash::vk;
use ash::vk::Handle as _;
use fovea_harness::skip;
use fovea_harness::vulkan::{assert_no_messages, pick_lavapipe, validated_entry, Vulkan};
use fovea_sim::control;
use openxr_sys as xr;

use crate::process::in_own_process;

/// In a process of its own ([`crate::process::in_own_process`]): it sets process-wide environment variables.
#[test]
fn vulkan_session_on_lavapipe_is_validation_clean() {
    in_own_process(
        module_path!(),
        "vulkan_session_on_lavapipe_is_validation_clean",
        vulkan_session_on_lavapipe_is_validation_clean_here,
    );
}

fn vulkan_session_on_lavapipe_is_validation_clean_here() {
    let Ok(entry) = validated_entry().map_err(|why| skip(&why)) else {
        return;
    };
    // In a process of its own, so setting the process environment is race-free.
    pick_lavapipe();

    let instance = create_instance(config("quest3"), &["XR_KHR_vulkan_enable2"]);
    let sys = system(instance);

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
    // XR_KHR_vulkan_enable2: the runtime creates the VkInstance through our vkGetInstanceProcAddr.
    let v = match Vulkan::through_xr(&entry, fovea_sim::get_instance_proc_addr, instance, sys) {
        Ok(v) => v,
        Err(why) => {
            destroy_instance(instance);
            skip(&why);
            return;
        }
    };
    assert_eq!(
        v.requirements.max_api_version_supported,
        xr::Version::new(1, 3, 0)
    );
    let (device, family) = (&v.device, v.family);

    let binding = v.binding();
    // A binding without a device (or physical device) names no valid graphics device: the CTS's
    // XR_KHR_vulkan_enable case requires XR_ERROR_GRAPHICS_DEVICE_INVALID for it.
    for bad in [
        xr::GraphicsBindingVulkanKHR {
            device: null_mut(),
            ..binding
        },
        xr::GraphicsBindingVulkanKHR {
            physical_device: null_mut(),
            ..binding
        },
    ] {
        assert_eq!(
            create_session_with(instance, &bad as *const _ as *const c_void),
            Err(xr::Result::ERROR_GRAPHICS_DEVICE_INVALID)
        );
    }
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
            pose: xr::Posef::IDENTITY,
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
    // SAFETY: the queue is idle (waited after each submit); nothing uses the device afterwards.
    unsafe {
        device.destroy_command_pool(pool, None);
        v.destroy_device();
    }
    destroy_instance(instance);
    unsafe { v.destroy_instance() };
    assert_no_messages();
}
