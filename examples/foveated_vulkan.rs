//! The whole XR_FB_foveation flow on Vulkan, written the way a Quest app writes it, on the `openxr`
//! crate: nothing in it knows about fovea, so it runs unchanged on a runtime with native support.
//!
//! 1. Instance with XR_KHR_vulkan_enable2 and the four foveation extensions (fovea provides them
//!    where the runtime does not).
//! 2. VkInstance and VkDevice made through the runtime (xrCreateVulkanInstanceKHR,
//!    xrCreateVulkanDeviceKHR), asking for VK_EXT_fragment_density_map where the GPU has it.
//! 3. One two-layer (multiview) colour swapchain created with `XrSwapchainCreateInfoFoveationFB`
//!    and `FRAGMENT_DENSITY_MAP`, its images enumerated with an `XrSwapchainImageFoveationVulkanFB`
//!    chained on each: one density image per swapchain image.
//! 4. One profile per level (NONE, LOW, MEDIUM, HIGH), applied in turn with xrUpdateSwapchainFB
//!    and read back with xrGetSwapchainStateFB while frames run.
//! 5. Every frame the swapchain image is cleared (a colour per level) and submitted as a
//!    projection layer; after `--frames N` (default: each level twice) the app requests exit.
//!
//! It does not render *through* the density images: that needs a render pass with a
//! `VkRenderPassFragmentDensityMapCreateInfoEXT` on a GPU with the extension (lavapipe has none),
//! and no such GPU has run this example yet. Where the device has no fragment density maps, each
//! frame blits the density map over a corner of the image as a debug overlay, which is how an
//! engine without FDM can still see what fovea computed.
//!
//! Against the simulated headset through the system loader (the checked-in manifests point at
//! target/release):
//!
//! ```sh
//! cargo build --release
//! XR_RUNTIME_JSON=$PWD/manifest/runtime/fovea_sim_runtime.json XR_API_LAYER_PATH=$PWD/manifest \
//!     XR_ENABLE_API_LAYERS=XR_APILAYER_FOVEA_foveation FOVEA_LOG=info \
//!     cargo run --release --example foveated_vulkan
//! ```
//!
//! `cargo test --example foveated_vulkan` runs it the same way (debug build, temporary manifests)
//! and checks what it reports.

use std::ffi::c_void;
use std::ptr;

use ash::vk::{self, Handle as _};
use openxr as xr;
use xr::sys::Handle as _;

const VIEW_TYPE: xr::ViewConfigurationType = xr::ViewConfigurationType::PRIMARY_STEREO;
const LEVELS: [xr::FoveationLevelFB; 4] = [
    xr::FoveationLevelFB::NONE,
    xr::FoveationLevelFB::LOW,
    xr::FoveationLevelFB::MEDIUM,
    xr::FoveationLevelFB::HIGH,
];
/// Long enough at 90 Hz for a level to be seen in a headset, short enough for a test.
const FRAMES_PER_LEVEL: u64 = 30;

/// What a run did: printed at the end, checked by the test.
#[derive(Debug)]
struct Outcome {
    frames: u64,
    swapchain_size: (u32, u32),
    /// `(VkImage, width, height)` per swapchain image, from XrSwapchainImageFoveationVulkanFB.
    density_images: Vec<(u64, u32, u32)>,
    /// Each level in the order xrUpdateSwapchainFB applied it (xrGetSwapchainStateFB confirmed).
    levels_applied: Vec<xr::FoveationLevelFB>,
    /// VK_EXT_fragment_density_map and its feature were enabled on the device.
    fdm_enabled: bool,
    /// Frames drawn with the density map overlaid (where the device has no FDM).
    overlays: u64,
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let frames = match args.iter().position(|a| a == "--frames") {
        Some(i) => args
            .get(i + 1)
            .and_then(|n| n.parse().ok())
            .expect("--frames takes a frame count"),
        None => LEVELS.len() as u64 * FRAMES_PER_LEVEL * 2,
    };
    match run(frames) {
        Ok(o) => {
            println!(
                "foveated_vulkan: {} frames on a {}x{} swapchain; density images {:?}; \
                 levels {:?}; VK_EXT_fragment_density_map {}; density overlay on {} frames",
                o.frames,
                o.swapchain_size.0,
                o.swapchain_size.1,
                o.density_images
                    .iter()
                    .map(|(_, w, h)| format!("{w}x{h}"))
                    .collect::<Vec<_>>(),
                o.levels_applied,
                if o.fdm_enabled { "enabled" } else { "absent" },
                o.overlays,
            );
        }
        Err(e) => {
            eprintln!("foveated_vulkan: {e}");
            std::process::exit(1);
        }
    }
}

/// An OpenXR result as this example's error.
fn check(r: xr::sys::Result, what: &str) -> Result<(), String> {
    if r.into_raw() >= 0 {
        Ok(())
    } else {
        Err(format!("{what}: {r}"))
    }
}

fn run(max_frames: u64) -> Result<Outcome, String> {
    // SAFETY: loading the system's OpenXR loader runs its initialisers; that is its purpose.
    let entry = unsafe { xr::Entry::load(&()) }.map_err(|e| format!("OpenXR loader: {e}"))?;
    let available = entry
        .enumerate_extensions()
        .map_err(|e| format!("xrEnumerateInstanceExtensionProperties: {e}"))?;
    if !(available.khr_vulkan_enable2
        && available.fb_swapchain_update_state
        && available.fb_foveation
        && available.fb_foveation_configuration
        && available.fb_foveation_vulkan)
    {
        return Err(
            "the runtime (or a layer) lacks XR_KHR_vulkan_enable2 or the foveation \
                    extensions: is fovea enabled (XR_ENABLE_API_LAYERS)?"
                .into(),
        );
    }
    let mut extensions = xr::ExtensionSet::default();
    extensions.khr_vulkan_enable2 = true;
    extensions.fb_swapchain_update_state = true;
    extensions.fb_foveation = true;
    extensions.fb_foveation_configuration = true;
    extensions.fb_foveation_vulkan = true;
    let instance = entry
        .create_instance(
            &xr::ApplicationInfo {
                application_name: "fovea foveated_vulkan",
                application_version: 1,
                engine_name: "none",
                engine_version: 0,
                // The Debian 1.0.20 loader refuses anything newer.
                api_version: xr::Version::new(1, 0, 0),
            },
            &extensions,
            &[],
            &(),
        )
        .map_err(|e| format!("xrCreateInstance: {e}"))?;
    let system = instance
        .system(xr::FormFactor::HEAD_MOUNTED_DISPLAY)
        .map_err(|e| format!("xrGetSystem: {e}"))?;
    let blend_mode = instance
        .enumerate_environment_blend_modes(system, VIEW_TYPE)
        .map_err(|e| format!("xrEnumerateEnvironmentBlendModes: {e}"))?[0];
    let requirements = instance
        .graphics_requirements::<xr::Vulkan>(system)
        .map_err(|e| format!("xrGetVulkanGraphicsRequirements2KHR: {e}"))?;
    // Vulkan 1.1: multiview and vkGetPhysicalDeviceFeatures2 (which the FDM query needs) are core.
    if requirements.max_api_version_supported < xr::Version::new(1, 1, 0) {
        return Err(format!(
            "the runtime supports Vulkan up to {} only",
            requirements.max_api_version_supported
        ));
    }
    // SAFETY: every Vulkan object below is made, used and destroyed on this thread, in order.
    unsafe { run_vulkan(&instance, system, blend_mode, max_frames) }
}

/// The Vulkan side: instance, device, session, swapchain, frames.
///
/// # Safety
/// Plain Vulkan use; see the comments where handles cross between OpenXR and Vulkan.
unsafe fn run_vulkan(
    instance: &xr::Instance,
    system: xr::SystemId,
    blend_mode: xr::EnvironmentBlendMode,
    max_frames: u64,
) -> Result<Outcome, String> {
    let vk_entry = ash::Entry::load().map_err(|e| format!("Vulkan loader: {e}"))?;
    let gipa = vk_entry.static_fn().get_instance_proc_addr;
    let app_info = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_1);
    let raw_instance = instance
        .create_vulkan_instance(
            system,
            std::mem::transmute::<
                vk::PFN_vkGetInstanceProcAddr,
                xr::sys::platform::VkGetInstanceProcAddr,
            >(gipa),
            &vk::InstanceCreateInfo::default().application_info(&app_info) as *const _ as *const _,
        )
        .map_err(|e| format!("xrCreateVulkanInstanceKHR: {e}"))?
        .map_err(|r| format!("vkCreateInstance: {:?}", vk::Result::from_raw(r)))?;
    let vk_instance = ash::Instance::load(
        vk_entry.static_fn(),
        vk::Instance::from_raw(raw_instance as u64),
    );
    let physical_device = vk::PhysicalDevice::from_raw(
        instance
            .vulkan_graphics_device(system, raw_instance)
            .map_err(|e| format!("xrGetVulkanGraphicsDevice2KHR: {e}"))? as u64,
    );
    let queue_family = vk_instance
        .get_physical_device_queue_family_properties(physical_device)
        .iter()
        .position(|q| q.queue_flags.contains(vk::QueueFlags::GRAPHICS))
        .ok_or("the Vulkan device has no graphics queue")? as u32;

    // XR_FB_foveation's FRAGMENT_DENSITY_MAP bit makes the app responsible for enabling the
    // extension and its feature where the GPU has them.
    let has_fdm = vk_instance
        .enumerate_device_extension_properties(physical_device)
        .map_err(|e| format!("vkEnumerateDeviceExtensionProperties: {e}"))?
        .iter()
        .any(|e| e.extension_name_as_c_str() == Ok(ash::ext::fragment_density_map::NAME));
    let mut fdm_query = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default();
    if has_fdm {
        let mut features = vk::PhysicalDeviceFeatures2::default().push_next(&mut fdm_query);
        vk_instance.get_physical_device_features2(physical_device, &mut features);
    }
    let fdm_enabled = has_fdm && fdm_query.fragment_density_map == vk::TRUE;
    let mut fdm_features = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default()
        .fragment_density_map(true)
        .fragment_density_map_non_subsampled_images(
            fdm_query.fragment_density_map_non_subsampled_images == vk::TRUE,
        );
    let mut multiview = vk::PhysicalDeviceMultiviewFeatures::default().multiview(true);
    let device_extensions = [ash::ext::fragment_density_map::NAME.as_ptr()];
    let priorities = [1.0];
    let queues = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(queue_family)
        .queue_priorities(&priorities)];
    let mut device_info = vk::DeviceCreateInfo::default()
        .queue_create_infos(&queues)
        .push_next(&mut multiview);
    if fdm_enabled {
        device_info = device_info
            .enabled_extension_names(&device_extensions)
            .push_next(&mut fdm_features);
    }
    let raw_device = instance
        .create_vulkan_device(
            system,
            std::mem::transmute::<
                vk::PFN_vkGetInstanceProcAddr,
                xr::sys::platform::VkGetInstanceProcAddr,
            >(gipa),
            physical_device.as_raw() as usize as _,
            &device_info as *const _ as *const _,
        )
        .map_err(|e| format!("xrCreateVulkanDeviceKHR: {e}"))?
        .map_err(|r| format!("vkCreateDevice: {:?}", vk::Result::from_raw(r)))?;
    let device = ash::Device::load(
        vk_instance.fp_v1_0(),
        vk::Device::from_raw(raw_device as u64),
    );
    let queue = device.get_device_queue(queue_family, 0);
    // The debug overlay blits the R8G8 density map onto the colour image: both formats must allow it.
    let blit = |format, feature| {
        vk_instance
            .get_physical_device_format_properties(physical_device, format)
            .optimal_tiling_features
            .contains(feature)
    };
    let overlay = !fdm_enabled
        && blit(vk::Format::R8G8_UNORM, vk::FormatFeatureFlags::BLIT_SRC)
        && [vk::Format::R8G8B8A8_SRGB, vk::Format::B8G8R8A8_SRGB]
            .into_iter()
            .all(|f| blit(f, vk::FormatFeatureFlags::BLIT_DST));

    let result = session_loop(
        instance,
        system,
        blend_mode,
        max_frames,
        (&device, queue, queue_family),
        (raw_instance, physical_device, raw_device),
        overlay,
    );
    // OpenXR objects are gone (dropped in `session_loop`) before the Vulkan objects they used.
    device.device_wait_idle().ok();
    device.destroy_device(None);
    vk_instance.destroy_instance(None);
    result.map(|mut o| {
        o.fdm_enabled = fdm_enabled;
        o
    })
}

/// Session, foveated swapchain, profiles and the frame loop; every OpenXR object made here is
/// dropped before it returns.
///
/// # Safety
/// `device` must be the device the runtime created; `queue` one of its queues.
unsafe fn session_loop(
    instance: &xr::Instance,
    system: xr::SystemId,
    blend_mode: xr::EnvironmentBlendMode,
    max_frames: u64,
    (device, queue, queue_family): (&ash::Device, vk::Queue, u32),
    (raw_instance, physical_device, raw_device): (
        xr::sys::platform::VkInstance,
        vk::PhysicalDevice,
        xr::sys::platform::VkDevice,
    ),
    overlay: bool,
) -> Result<Outcome, String> {
    let (session, mut frame_wait, mut frame_stream) = instance
        .create_session::<xr::Vulkan>(
            system,
            &xr::vulkan::SessionCreateInfo {
                instance: raw_instance,
                physical_device: physical_device.as_raw() as usize as _,
                device: raw_device,
                queue_family_index: queue_family,
                queue_index: 0,
            },
        )
        .map_err(|e| format!("xrCreateSession: {e}"))?;
    let stage = session
        .create_reference_space(xr::ReferenceSpaceType::LOCAL, xr::Posef::IDENTITY)
        .map_err(|e| format!("xrCreateReferenceSpace: {e}"))?;

    // The swapchain: the `openxr` crate's create_swapchain takes no next chain, so the foveation
    // struct goes in through the raw call and the handle is wrapped afterwards.
    let views = instance
        .enumerate_view_configuration_views(system, VIEW_TYPE)
        .map_err(|e| format!("xrEnumerateViewConfigurationViews: {e}"))?;
    let (width, height) = (
        views[0].recommended_image_rect_width,
        views[0].recommended_image_rect_height,
    );
    let formats = session
        .enumerate_swapchain_formats()
        .map_err(|e| format!("xrEnumerateSwapchainFormats: {e}"))?;
    let format = [vk::Format::R8G8B8A8_SRGB, vk::Format::B8G8R8A8_SRGB]
        .into_iter()
        .find(|f| formats.contains(&(f.as_raw() as u32)))
        .ok_or(format!("no sRGB colour format among {formats:?}"))?;
    let foveation = xr::sys::SwapchainCreateInfoFoveationFB {
        ty: xr::sys::SwapchainCreateInfoFoveationFB::TYPE,
        next: ptr::null_mut(),
        flags: xr::SwapchainCreateFoveationFlagsFB::FRAGMENT_DENSITY_MAP,
    };
    let create_info = xr::sys::SwapchainCreateInfo {
        ty: xr::sys::SwapchainCreateInfo::TYPE,
        next: &foveation as *const _ as *const c_void,
        create_flags: xr::SwapchainCreateFlags::EMPTY,
        usage_flags: xr::SwapchainUsageFlags::COLOR_ATTACHMENT
            | xr::SwapchainUsageFlags::TRANSFER_DST,
        format: i64::from(format.as_raw()),
        sample_count: 1,
        width,
        height,
        face_count: 1,
        array_size: 2,
        mip_count: 1,
    };
    let mut handle = xr::sys::Swapchain::NULL;
    check(
        (instance.fp().create_swapchain)(session.as_raw(), &create_info, &mut handle),
        "xrCreateSwapchain with FRAGMENT_DENSITY_MAP",
    )?;
    let mut swapchain = xr::Swapchain::<xr::Vulkan>::from_raw(session.clone(), handle);

    // The images, each with its density image chained (two-call idiom).
    let mut count = 0;
    check(
        (instance.fp().enumerate_swapchain_images)(handle, 0, &mut count, ptr::null_mut()),
        "xrEnumerateSwapchainImages",
    )?;
    let mut density = vec![
        xr::sys::SwapchainImageFoveationVulkanFB {
            ty: xr::sys::SwapchainImageFoveationVulkanFB::TYPE,
            next: ptr::null_mut(),
            image: 0,
            width: 0,
            height: 0,
        };
        count as usize
    ];
    let mut images: Vec<xr::sys::SwapchainImageVulkanKHR> = density
        .iter_mut()
        .map(|d| xr::sys::SwapchainImageVulkanKHR {
            ty: xr::sys::SwapchainImageVulkanKHR::TYPE,
            next: d as *mut _ as *mut c_void,
            image: 0,
        })
        .collect();
    check(
        (instance.fp().enumerate_swapchain_images)(
            handle,
            count,
            &mut count,
            images.as_mut_ptr() as *mut xr::sys::SwapchainImageBaseHeader,
        ),
        "xrEnumerateSwapchainImages",
    )?;
    let density_images: Vec<(u64, u32, u32)> = density
        .iter()
        .map(|d| (d.image, d.width, d.height))
        .collect();
    if let Some(i) = density_images.iter().position(|(image, ..)| *image == 0) {
        return Err(format!("swapchain image {i} came without a density image"));
    }

    // One profile per level, made up front: profiles may be destroyed once applied, but keeping
    // them lets the loop switch levels without creating anything per frame.
    let profiles = LEVELS
        .iter()
        .map(|&level| {
            session
                .create_foveation_profile(Some(xr::FoveationLevelProfile {
                    level,
                    vertical_offset: 0.0,
                    dynamic: xr::FoveationDynamicFB::DISABLED,
                }))
                .map_err(|e| format!("xrCreateFoveationProfileFB({level:?}): {e}"))
        })
        .collect::<Result<Vec<_>, String>>()?;
    let update_state = instance
        .exts()
        .fb_swapchain_update_state
        .ok_or("XR_FB_swapchain_update_state was enabled but has no functions")?;
    let mut levels_applied = Vec::new();
    let mut apply = |i: usize| -> Result<(), String> {
        let state = xr::sys::SwapchainStateFoveationFB {
            ty: xr::sys::SwapchainStateFoveationFB::TYPE,
            next: ptr::null_mut(),
            flags: xr::SwapchainStateFoveationFlagsFB::EMPTY,
            profile: profiles[i].as_raw(),
        };
        check(
            (update_state.update_swapchain)(handle, &state as *const _ as *const _),
            "xrUpdateSwapchainFB",
        )?;
        let mut read = xr::sys::SwapchainStateFoveationFB {
            profile: xr::sys::FoveationProfileFB::NULL,
            ..state
        };
        check(
            (update_state.get_swapchain_state)(handle, &mut read as *mut _ as *mut _),
            "xrGetSwapchainStateFB",
        )?;
        if read.profile != state.profile {
            return Err(format!(
                "xrGetSwapchainStateFB returned another profile after {:?}",
                LEVELS[i]
            ));
        }
        levels_applied.push(LEVELS[i]);
        Ok(())
    };

    let pool = device
        .create_command_pool(
            &vk::CommandPoolCreateInfo::default()
                .queue_family_index(queue_family)
                .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER),
            None,
        )
        .map_err(|e| format!("vkCreateCommandPool: {e}"))?;
    let cmd = device
        .allocate_command_buffers(
            &vk::CommandBufferAllocateInfo::default()
                .command_pool(pool)
                .command_buffer_count(1),
        )
        .map_err(|e| format!("vkAllocateCommandBuffers: {e}"))?[0];
    let fence = device
        .create_fence(&vk::FenceCreateInfo::default(), None)
        .map_err(|e| format!("vkCreateFence: {e}"))?;

    let mut event_storage = xr::EventDataBuffer::new();
    let mut running = false;
    let mut frames = 0u64;
    let mut overlays = 0u64;
    let mut level = None;
    let mut exit_requested = false;
    let result = 'main: loop {
        while let Some(event) = instance
            .poll_event(&mut event_storage)
            .map_err(|e| format!("xrPollEvent: {e}"))?
        {
            match event {
                xr::Event::SessionStateChanged(e) => match e.state() {
                    xr::SessionState::READY => {
                        session
                            .begin(VIEW_TYPE)
                            .map_err(|e| format!("xrBeginSession: {e}"))?;
                        running = true;
                    }
                    xr::SessionState::STOPPING => {
                        session.end().map_err(|e| format!("xrEndSession: {e}"))?;
                        running = false;
                    }
                    xr::SessionState::EXITING | xr::SessionState::LOSS_PENDING => {
                        break 'main Ok(())
                    }
                    _ => {}
                },
                xr::Event::InstanceLossPending(_) => {
                    break 'main Err("instance loss pending".to_string())
                }
                _ => {}
            }
        }
        if !running {
            std::thread::sleep(std::time::Duration::from_millis(10));
            continue;
        }
        // Frames go on until the runtime says STOPPING, at the level they had.
        if frames >= max_frames && !exit_requested {
            session
                .request_exit()
                .map_err(|e| format!("xrRequestExitSession: {e}"))?;
            exit_requested = true;
        }
        // A new level every FRAMES_PER_LEVEL frames, applied between frames.
        let wanted = (frames / FRAMES_PER_LEVEL) as usize % LEVELS.len();
        if level != Some(wanted) && !exit_requested {
            apply(wanted)?;
            level = Some(wanted);
        }
        let state = frame_wait.wait().map_err(|e| format!("xrWaitFrame: {e}"))?;
        frame_stream
            .begin()
            .map_err(|e| format!("xrBeginFrame: {e}"))?;
        if !state.should_render {
            frame_stream
                .end(state.predicted_display_time, blend_mode, &[])
                .map_err(|e| format!("xrEndFrame: {e}"))?;
            continue;
        }
        let (_, located) = session
            .locate_views(VIEW_TYPE, state.predicted_display_time, &stage)
            .map_err(|e| format!("xrLocateViews: {e}"))?;
        let index = swapchain
            .acquire_image()
            .map_err(|e| format!("xrAcquireSwapchainImage: {e}"))?;
        swapchain
            .wait_image(xr::Duration::INFINITE)
            .map_err(|e| format!("xrWaitSwapchainImage: {e}"))?;
        let (density_image, dw, dh) = density_images[index as usize];
        clear(
            device,
            (queue, cmd, fence),
            vk::Image::from_raw(images[index as usize].image),
            (width, height),
            level.unwrap_or(0),
            overlay.then(|| (vk::Image::from_raw(density_image), dw, dh)),
        )?;
        overlays += u64::from(overlay);
        swapchain
            .release_image()
            .map_err(|e| format!("xrReleaseSwapchainImage: {e}"))?;
        let rect = xr::Rect2Di {
            offset: xr::Offset2Di { x: 0, y: 0 },
            extent: xr::Extent2Di {
                width: width as i32,
                height: height as i32,
            },
        };
        let projection_views: Vec<_> = (0..2)
            .map(|eye| {
                xr::CompositionLayerProjectionView::new()
                    .pose(located[eye].pose)
                    .fov(located[eye].fov)
                    .sub_image(
                        xr::SwapchainSubImage::new()
                            .swapchain(&swapchain)
                            .image_array_index(eye as u32)
                            .image_rect(rect),
                    )
            })
            .collect();
        frame_stream
            .end(
                state.predicted_display_time,
                blend_mode,
                &[&xr::CompositionLayerProjection::new()
                    .space(&stage)
                    .views(&projection_views)],
            )
            .map_err(|e| format!("xrEndFrame: {e}"))?;
        frames += 1;
    };
    device.destroy_fence(fence, None);
    device.destroy_command_pool(pool, None);
    drop((
        profiles,
        swapchain,
        stage,
        frame_stream,
        frame_wait,
        session,
    ));
    result.map(|()| Outcome {
        frames,
        swapchain_size: (width, height),
        density_images,
        levels_applied,
        fdm_enabled: false,
        overlays,
    })
}

/// Clears both layers of a swapchain image to the colour of level `level` and, where the device has
/// no fragment density maps to render with, blits each layer's density map over the lower-left
/// quarter of that layer as a debug overlay (red = horizontal density, green = vertical: yellow is
/// full rate, darker is coarser), then waits for it. xrWaitSwapchainImage hands the image over in
/// COLOR_ATTACHMENT_OPTIMAL and xrReleaseSwapchainImage expects it back in that layout; fovea
/// leaves a density image in SHADER_READ_ONLY_OPTIMAL on such devices, and it goes back there.
///
/// # Safety
/// `image` must be the acquired, waited swapchain image; `cmd` and `fence` idle.
unsafe fn clear(
    device: &ash::Device,
    (queue, cmd, fence): (vk::Queue, vk::CommandBuffer, vk::Fence),
    image: vk::Image,
    (width, height): (u32, u32),
    level: usize,
    density: Option<(vk::Image, u32, u32)>,
) -> Result<(), String> {
    const COLOURS: [[f32; 4]; 4] = [
        [0.1, 0.1, 0.1, 1.0],
        [0.0, 0.3, 0.0, 1.0],
        [0.3, 0.3, 0.0, 1.0],
        [0.3, 0.0, 0.0, 1.0],
    ];
    let range = vk::ImageSubresourceRange::default()
        .aspect_mask(vk::ImageAspectFlags::COLOR)
        .level_count(1)
        .layer_count(2);
    let barrier = |from, to, src, dst| {
        vk::ImageMemoryBarrier::default()
            .image(image)
            .subresource_range(range)
            .old_layout(from)
            .new_layout(to)
            .src_access_mask(src)
            .dst_access_mask(dst)
    };
    fn e(what: &'static str) -> impl Fn(vk::Result) -> String {
        move |r| format!("{what}: {r}")
    }
    device
        .begin_command_buffer(
            cmd,
            &vk::CommandBufferBeginInfo::default()
                .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
        )
        .map_err(e("vkBeginCommandBuffer"))?;
    device.cmd_pipeline_barrier(
        cmd,
        vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
        vk::PipelineStageFlags::TRANSFER,
        vk::DependencyFlags::empty(),
        &[],
        &[],
        &[barrier(
            vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
            vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
            vk::AccessFlags::TRANSFER_WRITE,
        )],
    );
    device.cmd_clear_color_image(
        cmd,
        image,
        vk::ImageLayout::TRANSFER_DST_OPTIMAL,
        &vk::ClearColorValue {
            float32: COLOURS[level],
        },
        &[range],
    );
    if let Some((map, dw, dh)) = density {
        let map_barrier = |from, to, src, dst| {
            vk::ImageMemoryBarrier::default()
                .image(map)
                .subresource_range(range)
                .old_layout(from)
                .new_layout(to)
                .src_access_mask(src)
                .dst_access_mask(dst)
        };
        // The clear's writes are done before the blit writes over them.
        device.cmd_pipeline_barrier(
            cmd,
            vk::PipelineStageFlags::TRANSFER | vk::PipelineStageFlags::FRAGMENT_SHADER,
            vk::PipelineStageFlags::TRANSFER,
            vk::DependencyFlags::empty(),
            &[vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .dst_access_mask(vk::AccessFlags::TRANSFER_WRITE)],
            &[],
            &[map_barrier(
                vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                vk::AccessFlags::SHADER_READ,
                vk::AccessFlags::TRANSFER_READ,
            )],
        );
        let layers = |layer| {
            vk::ImageSubresourceLayers::default()
                .aspect_mask(vk::ImageAspectFlags::COLOR)
                .base_array_layer(layer)
                .layer_count(1)
        };
        let corner = |x: u32, y: u32| vk::Offset3D {
            x: x as i32,
            y: y as i32,
            z: 0,
        };
        let regions: Vec<vk::ImageBlit> = (0..2)
            .map(|layer| {
                vk::ImageBlit::default()
                    .src_subresource(layers(layer))
                    .src_offsets([
                        corner(0, 0),
                        vk::Offset3D {
                            z: 1,
                            ..corner(dw, dh)
                        },
                    ])
                    .dst_subresource(layers(layer))
                    .dst_offsets([
                        corner(0, height / 2),
                        vk::Offset3D {
                            z: 1,
                            ..corner(width / 2, height)
                        },
                    ])
            })
            .collect();
        device.cmd_blit_image(
            cmd,
            map,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            image,
            vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            &regions,
            vk::Filter::NEAREST,
        );
        device.cmd_pipeline_barrier(
            cmd,
            vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::FRAGMENT_SHADER,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[map_barrier(
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
                vk::AccessFlags::TRANSFER_READ,
                vk::AccessFlags::SHADER_READ,
            )],
        );
    }
    device.cmd_pipeline_barrier(
        cmd,
        vk::PipelineStageFlags::TRANSFER,
        vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
        vk::DependencyFlags::empty(),
        &[],
        &[],
        &[barrier(
            vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
            vk::AccessFlags::TRANSFER_WRITE,
            vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
        )],
    );
    device
        .end_command_buffer(cmd)
        .map_err(e("vkEndCommandBuffer"))?;
    let cmds = [cmd];
    device
        .queue_submit(
            queue,
            &[vk::SubmitInfo::default().command_buffers(&cmds)],
            fence,
        )
        .map_err(e("vkQueueSubmit"))?;
    device
        .wait_for_fences(&[fence], true, u64::MAX)
        .map_err(e("vkWaitForFences"))?;
    device.reset_fences(&[fence]).map_err(e("vkResetFences"))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    //! The example against the simulated headset on lavapipe, through the system loader, fovea
    //! enabled by the environment. One test: the loader allows one instance per process and reads
    //! the environment.

    use std::path::Path;

    use fovea_harness::{artifact, skip, FOVEA_LAYER};

    use super::*;

    #[test]
    fn runs_the_foveation_flow_through_the_system_loader() {
        if let Err(e) = unsafe { libloading::Library::new("libopenxr_loader.so.1") } {
            skip(&format!("the Khronos OpenXR loader is not installed: {e}"));
            return;
        }
        let icd = Path::new("/usr/share/vulkan/icd.d/lvp_icd.x86_64.json");
        if !icd.exists() {
            skip("Mesa's lavapipe Vulkan driver is not installed (mesa-vulkan-drivers)");
            return;
        }
        let layer = artifact("libfovea.so").expect("run `cargo build --workspace`");
        let runtime = artifact("libfovea_sim.so").expect("run `cargo build --workspace`");
        let dir = std::env::temp_dir().join(format!("fovea-example-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("layers")).unwrap();
        let checked_in = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("manifest/XR_APILAYER_FOVEA_foveation.json"),
        )
        .unwrap();
        std::fs::write(
            dir.join("layers/fovea.json"),
            checked_in.replace("../target/release/libfovea.so", layer.to_str().unwrap()),
        )
        .unwrap();
        std::fs::write(
            dir.join("runtime.json"),
            format!(
                r#"{{"file_format_version": "1.0.0", "runtime": {{"name": "fovea simulated headset", "library_path": "{}"}}}}"#,
                runtime.display()
            ),
        )
        .unwrap();
        std::env::set_var("XR_RUNTIME_JSON", dir.join("runtime.json"));
        std::env::set_var("XR_API_LAYER_PATH", dir.join("layers"));
        std::env::set_var("XR_ENABLE_API_LAYERS", FOVEA_LAYER);
        std::env::set_var("VK_ICD_FILENAMES", icd);
        std::env::set_var("VK_DRIVER_FILES", icd);
        // A small headset keeps lavapipe's clears quick.
        std::env::set_var("FOVEA_SIM_HEADSET", "rift-cv1");

        let frames = LEVELS.len() as u64 * FRAMES_PER_LEVEL;
        let o = run(frames).unwrap_or_else(|e| panic!("{e}"));
        std::fs::remove_dir_all(&dir).ok();
        // The runtime may take a frame or two to stop after xrRequestExitSession.
        assert!(o.frames >= frames, "{o:?}");
        assert_eq!(o.levels_applied, LEVELS, "{o:?}");
        // lavapipe has no fragment density maps: every rendered frame shows the overlay.
        if !o.fdm_enabled {
            assert_eq!(o.overlays, o.frames, "{o:?}");
        }
        assert!(!o.density_images.is_empty(), "{o:?}");
        let (w, h) = o.swapchain_size;
        for &(image, dw, dh) in &o.density_images {
            assert!(
                image != 0 && dw > 0 && dh > 0 && dw <= w && dh <= h,
                "{o:?}"
            );
        }
        let distinct: std::collections::HashSet<u64> =
            o.density_images.iter().map(|d| d.0).collect();
        assert_eq!(
            distinct.len(),
            o.density_images.len(),
            "one per image: {o:?}"
        );
    }
}
