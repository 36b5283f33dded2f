//! Injection turns on shading-rate attachments only on the device the OpenXR session renders with
//! (docs/injection.md#which-devices-get-the-feature): an application's other devices (a second
//! device of a DXVK or vkd3d-proton game, a tool's device in the same process) are created as
//! they asked, since on some drivers the feature alone changes how every depth buffer is stored.
//!
//! Stack: this test as an OpenXR application (XR_KHR_vulkan_enable2) → fovea's OpenXR layer → the
//! simulated runtime; Vulkan through fovea's Vulkan layer → VK_LAYER_KHRONOS_validation → the
//! shading-rate double → lavapipe, injection on (`FOVEA_INJECT=1`, read at `xrCreateInstance`, so
//! the test runs in a process of its own). The session's device is made through
//! `xrCreateVulkanDeviceKHR`, a second one with `vkCreateDevice` on the same physical device. On
//! both the application makes a dynamic-rendering pipeline and renders into an image of its own.
//! What reaches the driver: the session's device with the attachment feature and its pipeline
//! with fovea's shading-rate state and flag (every pipeline of an injecting device gets them); the
//! second device as the application asked (no shading-rate extension, no features), its pipeline
//! and rendering without any shading-rate state or attachment; both renderings complete; no
//! validation message, no misuse in the double.

use std::ffi::CStr;

use ash::vk;
use ash::vk::Handle as _;
use fovea_harness::app::API_1_0;
use fovea_harness::vulkan::{self, pick_lavapipe, Options, Vulkan, VALIDATION_LAYER};
use fovea_harness::{App, Chain};
use fovea_vkdouble::Profile;
use serde_json::{json, Value};

use crate::support::in_own_process;
use crate::support::vulkan::{
    cleared_color, draw_fullscreen, range, spv, stages, to_color_attachment, Fixed, FRAGMENT,
    VERTEX,
};

const FORMAT: vk::Format = vk::Format::R8G8B8A8_UNORM;
const WIDTH: u32 = 640;
const HEIGHT: u32 = 500;

/// What one device's rendering left: its pipeline and command buffer, as raw handles.
struct Rendered {
    pipeline: u64,
    command_buffer: u64,
}

/// A pipeline for dynamic rendering, an image of `WIDTH`×`HEIGHT`, one rendering with a draw into
/// it, submitted on queue 0 of `family` and waited for; everything destroyed again.
///
/// # Safety
/// `d` must be a live device of `instance`'s `physical`, with dynamic rendering enabled.
unsafe fn render(
    instance: &ash::Instance,
    physical: vk::PhysicalDevice,
    d: &ash::Device,
    family: u32,
) -> Rendered {
    // SAFETY: the caller's promise; every struct lives across its call; every object made here
    // is destroyed here, after the fence says the work is done.
    unsafe {
        let memory = instance.get_physical_device_memory_properties(physical);
        let image = d
            .create_image(
                &vk::ImageCreateInfo::default()
                    .image_type(vk::ImageType::TYPE_2D)
                    .format(FORMAT)
                    .extent(vk::Extent3D {
                        width: WIDTH,
                        height: HEIGHT,
                        depth: 1,
                    })
                    .mip_levels(1)
                    .array_layers(1)
                    .samples(vk::SampleCountFlags::TYPE_1)
                    .tiling(vk::ImageTiling::OPTIMAL)
                    .usage(vk::ImageUsageFlags::COLOR_ATTACHMENT),
                None,
            )
            .expect("image");
        let req = d.get_image_memory_requirements(image);
        let mem = d
            .allocate_memory(
                &crate::support::vulkan::allocate_info(
                    &memory,
                    req,
                    vk::MemoryPropertyFlags::DEVICE_LOCAL,
                ),
                None,
            )
            .expect("memory");
        d.bind_image_memory(image, mem, 0).expect("bind");
        let view = d
            .create_image_view(
                &vk::ImageViewCreateInfo::default()
                    .image(image)
                    .view_type(vk::ImageViewType::TYPE_2D)
                    .format(FORMAT)
                    .subresource_range(range(0, 1)),
                None,
            )
            .expect("view");
        let modules = [VERTEX, FRAGMENT].map(|b| {
            let words = spv(b);
            d.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
                .expect("shader module")
        });
        let layout = d
            .create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default(), None)
            .expect("layout");
        let formats = [FORMAT];
        let mut rendering =
            vk::PipelineRenderingCreateInfo::default().color_attachment_formats(&formats);
        let fixed = Fixed::new();
        let st = stages(modules);
        let info = fixed.info(&st, layout).push_next(&mut rendering);
        let pipeline = d
            .create_graphics_pipelines(vk::PipelineCache::null(), &[info], None)
            .expect("pipeline")[0];
        let pool = d
            .create_command_pool(
                &vk::CommandPoolCreateInfo::default().queue_family_index(family),
                None,
            )
            .expect("pool");
        let cb = d
            .allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool)
                    .command_buffer_count(1),
            )
            .expect("command buffer")[0];
        d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
            .expect("begin");
        to_color_attachment(d, cb, &[image], 1);
        let colour = [cleared_color(view)];
        let ri = vk::RenderingInfo::default()
            .render_area(vk::Rect2D {
                offset: vk::Offset2D::default(),
                extent: vk::Extent2D {
                    width: WIDTH,
                    height: HEIGHT,
                },
            })
            .layer_count(1)
            .color_attachments(&colour);
        d.cmd_begin_rendering(cb, &ri);
        draw_fullscreen(d, cb, pipeline);
        d.cmd_end_rendering(cb);
        d.end_command_buffer(cb).expect("end");
        let fence = d
            .create_fence(&vk::FenceCreateInfo::default(), None)
            .expect("fence");
        let cbs = [cb];
        d.queue_submit(
            d.get_device_queue(family, 0),
            &[vk::SubmitInfo::default().command_buffers(&cbs)],
            fence,
        )
        .expect("vkQueueSubmit");
        d.wait_for_fences(&[fence], true, u64::MAX)
            .expect("the rendering completes");
        d.destroy_fence(fence, None);
        d.destroy_command_pool(pool, None);
        d.destroy_pipeline(pipeline, None);
        d.destroy_pipeline_layout(layout, None);
        for m in modules {
            d.destroy_shader_module(m, None);
        }
        d.destroy_image_view(view, None);
        d.destroy_image(image, None);
        d.free_memory(mem, None);
        Rendered {
            pipeline: pipeline.as_raw(),
            command_buffer: cb.as_raw(),
        }
    }
}

/// The events of `kind`, in order.
fn of<'a>(events: &'a [Value], kind: &str) -> Vec<&'a Value> {
    events.iter().filter(|e| e["kind"] == kind).collect()
}

/// An OpenXR application (XR_KHR_vulkan_enable2) through fovea on the double posing as
/// `profile`, and the session's Vulkan device made through `xrCreateVulkanDeviceKHR`, with fovea's
/// Vulkan layer above validation and the double; the double's records and validation's messages
/// cleared first. `None` (with the skip said) where the stack cannot be made.
fn session_device(env: &crate::support::device::Env, profile: Profile) -> Option<(App, Vulkan)> {
    env.double.set_profile(Some(profile));
    env.double.clear();
    vulkan::take_messages();
    let app = App::new(Chain::fovea().unwrap(), &["XR_KHR_vulkan_enable2"], API_1_0).unwrap();
    let sys = app.system();
    let ours = std::ffi::CString::new(fovea_abi::VK_LAYER_NAME).unwrap();
    let layers: [&CStr; 3] = [
        ours.as_c_str(),
        VALIDATION_LAYER,
        fovea_vkdouble::LAYER_NAME,
    ];
    let options = Options {
        layers: &layers,
        api_version: vk::API_VERSION_1_3,
        multiview: false,
        dynamic_rendering: true,
        device_extensions: &[],
        device_next: std::ptr::null(),
        queues: 1,
    };
    match Vulkan::through_xr_with(&env.entry, app.chain.gipa(), app.instance, sys, &options) {
        Ok(v) => Some((app, v)),
        Err(why) => {
            fovea_harness::skip(&why);
            None
        }
    }
}

#[test]
fn only_the_sessions_device_gets_shading_rate_attachments() {
    in_own_process(
        module_path!(),
        "only_the_sessions_device_gets_shading_rate_attachments",
        || {
            std::env::set_var("FOVEA_INJECT", "1");
            std::env::set_var("FOVEA_INJECT_LEVEL", "3");
            pick_lavapipe();
            for profile in [Profile::Nvidia, Profile::Amd] {
                let Some((_serial, env)) = crate::support::device::env() else {
                    return;
                };
                let Some((app, v)) = session_device(env, profile) else {
                    return;
                };
                // The application's second device, on the same physical device, made directly.
                let prio = [1.0];
                let queues = [vk::DeviceQueueCreateInfo::default()
                    .queue_family_index(v.family)
                    .queue_priorities(&prio)];
                let mut v13 = vk::PhysicalDeviceVulkan13Features::default().dynamic_rendering(true);
                let info = vk::DeviceCreateInfo::default()
                    .queue_create_infos(&queues)
                    .push_next(&mut v13);
                // SAFETY: the structs live across the call; the device is destroyed below.
                let other = unsafe { v.instance.create_device(v.physical_device, &info, None) }
                    .expect("the second device");
                // SAFETY: both devices are live and have dynamic rendering.
                let (session, second) = unsafe {
                    (
                        render(&v.instance, v.physical_device, &v.device, v.family),
                        render(&v.instance, v.physical_device, &other, v.family),
                    )
                };
                // SAFETY: nothing made from it is alive.
                unsafe { other.destroy_device(None) };
                // SAFETY: the devices are used no more.
                unsafe { v.destroy_device() };
                assert_eq!(app.destroy(), openxr_sys::Result::SUCCESS);
                // SAFETY: the devices are gone.
                unsafe { v.destroy_instance() };
                vulkan::assert_no_messages();
                assert_eq!(env.double.errors(), Vec::<String>::new(), "{profile:?}");

                let events: Vec<Value> = env.double.records()["events"]
                    .as_array()
                    .cloned()
                    .unwrap_or_default();
                // In order: the session's device and what was made on it, then the second's.
                let devices = of(&events, "device");
                assert_eq!(devices.len(), 2, "{profile:?}: {devices:#?}");
                assert_eq!(
                    devices[0]["features"],
                    json!({"pipeline": false, "primitive": false, "attachment": true}),
                    "{profile:?}: the session's device"
                );
                assert_eq!(devices[1]["extension"], false, "{profile:?}: the second");
                assert_eq!(
                    devices[1]["features"],
                    Value::Null,
                    "{profile:?}: the second"
                );
                let pipelines = of(&events, "pipeline");
                assert_eq!(pipelines.len(), 2, "{profile:?}: {pipelines:#?}");
                assert_eq!(pipelines[0]["pipeline"], json!(session.pipeline));
                assert_ne!(
                    pipelines[0]["shading_rate_state"],
                    Value::Null,
                    "{profile:?}"
                );
                assert_eq!(
                    pipelines[0]["rendering_attachment_flag"], true,
                    "{profile:?}"
                );
                assert_eq!(pipelines[1]["pipeline"], json!(second.pipeline));
                assert_eq!(
                    pipelines[1]["shading_rate_state"],
                    Value::Null,
                    "{profile:?}"
                );
                assert_eq!(
                    pipelines[1]["rendering_attachment_flag"], false,
                    "{profile:?}"
                );
                let begun = of(&events, "begin_rendering");
                assert_eq!(begun.len(), 2, "{profile:?}: {begun:#?}");
                assert_eq!(begun[1]["command_buffer"], json!(second.command_buffer));
                assert_eq!(begun[1]["shading_rate"], Value::Null, "{profile:?}");
            }
        },
    );
}

/// Injection on a session whose device has no shading-rate attachments (the double's `none`
/// profile: no `VK_KHR_fragment_shading_rate` at all) cannot work: the device is created as the
/// application asked, the application renders, and fovea's log says once why nothing is injected,
/// where before the stats line's `Inj=0/0` was the only sign. On an NVIDIA-like device the line
/// is not written.
#[test]
fn a_session_device_without_shading_rate_attachments_says_why_once() {
    in_own_process(
        module_path!(),
        "a_session_device_without_shading_rate_attachments_says_why_once",
        || {
            let dir = std::env::temp_dir().join(format!("fovea-inject-why-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).unwrap();
            std::env::set_var("FOVEA_LOG", "info");
            std::env::set_var("FOVEA_LOG_FILE", dir.join("fovea.log"));
            std::env::set_var("FOVEA_INJECT", "1");
            std::env::set_var("FOVEA_INJECT_LEVEL", "3");
            pick_lavapipe();
            let line = "injection is on, but this device cannot take injected maps";
            for profile in [Profile::None, Profile::Nvidia] {
                let Some((_serial, env)) = crate::support::device::env() else {
                    return;
                };
                let Some((app, v)) = session_device(env, profile) else {
                    return;
                };
                // SAFETY: the device is live and has dynamic rendering.
                unsafe { render(&v.instance, v.physical_device, &v.device, v.family) };
                // SAFETY: the device is used no more.
                unsafe { v.destroy_device() };
                assert_eq!(app.destroy(), openxr_sys::Result::SUCCESS);
                // SAFETY: the device is gone.
                unsafe { v.destroy_instance() };
                vulkan::assert_no_messages();
                assert_eq!(env.double.errors(), Vec::<String>::new(), "{profile:?}");
                let events: Vec<Value> = env.double.records()["events"]
                    .as_array()
                    .cloned()
                    .unwrap_or_default();
                let devices = of(&events, "device");
                let log = std::fs::read_to_string(dir.join("fovea.log")).unwrap_or_default();
                let said = log.matches(line).count();
                match profile {
                    Profile::None => {
                        assert_eq!(said, 1, "one line, with the reason:\n{log}");
                        assert!(
                            log.contains(&format!(
                                "{line} (the driver offers no VK_KHR_fragment_shading_rate)"
                            )),
                            "{log}"
                        );
                    }
                    _ => {
                        assert_eq!(devices.len(), 1, "{profile:?}: {devices:#?}");
                        assert_eq!(
                            devices[0]["features"]["attachment"], true,
                            "{profile:?}: injected into"
                        );
                        assert_eq!(said, 1, "{profile:?}: no second line:\n{log}");
                    }
                }
            }
        },
    );
}
