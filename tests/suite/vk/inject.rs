//! Injection (docs/injection.md) end to end on lavapipe: an application that never asks for
//! foveation, its eye passes foveated by fovea all the same.
//!
//! Stack: this test as an OpenXR application → fovea's OpenXR layer → the simulated runtime; its
//! VkInstance and VkDevice made through XR_KHR_vulkan_enable2 with the layers fovea's Vulkan layer →
//! VK_LAYER_KHRONOS_validation → the shading-rate double (`nvidia`: 16×16 texels, layered; `amd`:
//! 8×8) → lavapipe, validation's handle wrapping off so the double's records name the test's
//! handles. Each run is a child process of its own: `FOVEA_INJECT` and `FOVEA_INJECT_LEVEL` are read
//! from the environment at `xrCreateInstance`.
//!
//! One frame: a per-eye swapchain of 640×500 (so the left eye's: fovea guesses view 0 from the
//! first of its size), the views located, then three passes with one pipeline: into the acquired
//! swapchain image, into a 256×256 image of the application's own, and into an eye-shaped 640×500
//! image of its own; as dynamic renderings, as version-1 render passes with a framebuffer each, or
//! as version-2 passes with imageless framebuffers; or, multiview (view mask 0b11), into two-layer
//! targets with a swapchain that is an array of both views. What must reach the driver, per profile
//! and level:
//!
//! - injection on: the device with `VK_KHR_fragment_shading_rate`'s attachment feature; the pipeline
//!   with the state {1×1, {KEEP, REPLACE}} (and, for dynamic rendering, the shading-rate flag);
//!   render passes with a shading-rate attachment after the colour one in their subpass; the
//!   swapchain pass with a shading-rate attachment of the device's texel whose draws shade (the
//!   double's effective rates per view and texel) exactly at `fovea_model::inject::codes` for
//!   view 0 at the located FOVs and the level, and off-eye passes at full rate everywhere; the
//!   eye-shaped one with the merged map of both eyes; the small one with none (dynamic rendering)
//!   or a full-rate map covering it (render passes); multiview, one map of both views for both
//!   two-layer targets, two layers on `nvidia` and one merged layer on `amd`; a level changed while
//!   the application runs refills the map in place, once;
//! - injection off: none of it, the double sees the application's calls as they were;
//! - an application that names a shading-rate view of its own in the swapchain's rendering: that
//!   view reaches the driver there, fovea's map in the eye-shaped target's; one whose render pass
//!   references its own attachment: the pass, its framebuffers and pipeline as it made them; the
//!   log says so once;
//! - a vkd3d-like application (the attachment feature enabled, a null-view shading-rate struct in
//!   every rendering): its eye renderings with fovea's map in place of that struct, one in the chain;
//!
//! and in every case validation says nothing and the double records no misuse.

use std::ffi::{c_void, CStr};
use std::path::PathBuf;
use std::ptr::{null, null_mut};

use ash::vk;
use ash::vk::Handle as _;
use fovea_harness::app::API_1_0;
use fovea_harness::vulkan::{self, pick_lavapipe, Options, Vulkan, VALIDATION_LAYER};
use fovea_harness::{skip, App, Chain};
use fovea_model::density::{Level, Pattern};
use fovea_model::inject::Views;
use fovea_model::maps::MAX_VIEWS;
use fovea_model::Fov;
use fovea_vkdouble::Profile;
use openxr_sys as xr;
use serde_json::{json, Value};
use xr::Handle as _;

use crate::both::fdm_vulkan::{func, running_session, Frame};
use crate::support::in_own_process;
use crate::support::vulkan::{draw_fullscreen, range, spv, stages, Fixed, FRAGMENT, VERTEX};

const WIDTH: u32 = 640;
const HEIGHT: u32 = 500;
/// The small target: no eye's shape.
const SMALL: u32 = 256;
const FORMAT: vk::Format = vk::Format::R8G8B8A8_SRGB;
const FSR_LAYOUT: vk::ImageLayout = vk::ImageLayout::FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR;
const FSR: &CStr = c"VK_KHR_fragment_shading_rate";
/// The colour targets' usage: what the simulated runtime gives the swapchain's images (an
/// imageless framebuffer describes it).
const USAGE: vk::ImageUsageFlags = vk::ImageUsageFlags::from_raw(
    vk::ImageUsageFlags::COLOR_ATTACHMENT.as_raw() | vk::ImageUsageFlags::SAMPLED.as_raw(),
);

/// How the application renders.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Api {
    /// `vkCmdBeginRendering`.
    Dynamic,
    /// `vkCreateRenderPass` (version 1) and a framebuffer per target.
    RenderPass,
    /// `vkCreateRenderPass2` and an imageless framebuffer per target, the views named at
    /// `vkCmdBeginRenderPass2`.
    Imageless,
    /// `vkCmdBeginRendering` with view mask 0b11 into two-layer targets: the swapchain an array of
    /// both views.
    Multiview,
}

impl Api {
    /// Whether the passes are dynamic renderings.
    fn dynamic(self) -> bool {
        matches!(self, Api::Dynamic | Api::Multiview)
    }

    /// The colour targets' layers.
    fn layers(self) -> u32 {
        if self == Api::Multiview {
            2
        } else {
            1
        }
    }
}

/// How the application is set up.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Setup {
    /// `FOVEA_INJECT=1` at this level.
    Inject(Level),
    /// Injection off.
    Off,
    /// `FOVEA_INJECT=1` at `high`; the application enables shading-rate attachments itself, its
    /// pipeline with the attachment flag and the state {1×1, {KEEP, REPLACE}}, and names a
    /// shading-rate view of its own in the rendering into the swapchain image.
    AppRates,
    /// As vkd3d-proton: the application enables pipeline shading rates (no attachments), makes its
    /// pipeline with shading-rate state {2×2, {KEEP, KEEP}} and the dynamic shading-rate state,
    /// and sets 1×1 with {KEEP, KEEP} before each draw; injection on at this level, or off.
    SetsRates(Option<Level>),
    /// As vkd3d-proton really is: [`Setup::SetsRates`], and the attachment feature enabled too, the
    /// pipeline with the attachment flag, a `VkRenderingFragmentShadingRateAttachmentInfoKHR` with
    /// a null view in every rendering, and an R8_UINT image with the shading-rate usage it never
    /// attaches.
    Vkd3d(Option<Level>),
}

impl Setup {
    /// The injected level, where injection is on for an application fovea injects into.
    fn level(self) -> Option<Level> {
        match self {
            Setup::Inject(level) => Some(level),
            Setup::SetsRates(level) | Setup::Vkd3d(level) => level,
            Setup::AppRates => Some(Level::High),
            Setup::Off => None,
        }
    }

    /// The same setup at `level`.
    fn at(self, level: Level) -> Setup {
        match self {
            Setup::SetsRates(_) => Setup::SetsRates(Some(level)),
            Setup::Vkd3d(_) => Setup::Vkd3d(Some(level)),
            _ => Setup::Inject(level),
        }
    }
}

/// The application's own combiners, as vkd3d-proton passes them for D3D12's defaults.
const KEEP: [vk::FragmentShadingRateCombinerOpKHR; 2] = [
    vk::FragmentShadingRateCombinerOpKHR::KEEP,
    vk::FragmentShadingRateCombinerOpKHR::KEEP,
];
/// The dynamic states of a [`Setup::SetsRates`] application's pipeline.
static RATE_DYNAMIC: [vk::DynamicState; 3] = [
    vk::DynamicState::VIEWPORT,
    vk::DynamicState::SCISSOR,
    vk::DynamicState::FRAGMENT_SHADING_RATE_KHR,
];

/// What one run left behind.
struct Outcome {
    events: Vec<Value>,
    command_buffer: u64,
    /// With a refresh: the command buffer recorded after the level changed.
    second: Option<u64>,
    fovs: [Fov; 2],
    log: String,
    /// [`Setup::AppRates`]: the application's own shading-rate view.
    apps_view: Option<u64>,
}

/// The folder for the log; sets the environment the run reads. Call first in the child process.
fn set_up(label: &str, setup: Setup) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fovea-inject-{label}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::env::set_var("FOVEA_LOG", "info");
    std::env::set_var("FOVEA_LOG_FILE", dir.join("fovea.log"));
    // Absent until a test changes the level while the application runs.
    std::env::set_var("FOVEA_PROPS", dir.join("props"));
    match setup {
        Setup::Inject(level) => {
            std::env::set_var("FOVEA_INJECT", "1");
            std::env::set_var("FOVEA_INJECT_LEVEL", (level as u8).to_string());
        }
        Setup::SetsRates(Some(level)) | Setup::Vkd3d(Some(level)) => {
            std::env::set_var("FOVEA_INJECT", "1");
            std::env::set_var("FOVEA_INJECT_LEVEL", (level as u8).to_string());
        }
        Setup::AppRates => {
            std::env::set_var("FOVEA_INJECT", "1");
            std::env::set_var("FOVEA_INJECT_LEVEL", (Level::High as u8).to_string());
        }
        Setup::Off | Setup::SetsRates(None) | Setup::Vkd3d(None) => {
            std::env::remove_var("FOVEA_INJECT")
        }
    }
    pick_lavapipe();
    dir
}

/// # Safety
/// `d` must be alive.
unsafe fn image(
    d: &ash::Device,
    memory: &vk::PhysicalDeviceMemoryProperties,
    extent: [u32; 2],
    layers: u32,
) -> (vk::Image, vk::DeviceMemory) {
    let info = vk::ImageCreateInfo::default()
        .image_type(vk::ImageType::TYPE_2D)
        .format(FORMAT)
        .extent(vk::Extent3D {
            width: extent[0],
            height: extent[1],
            depth: 1,
        })
        .mip_levels(1)
        .array_layers(layers)
        .samples(vk::SampleCountFlags::TYPE_1)
        .tiling(vk::ImageTiling::OPTIMAL)
        .usage(USAGE);
    // SAFETY: the caller's promise; the structs live across the calls.
    unsafe {
        let image = d.create_image(&info, None).unwrap();
        let req = d.get_image_memory_requirements(image);
        let mem = d
            .allocate_memory(
                &crate::support::vulkan::allocate_info(
                    memory,
                    req,
                    vk::MemoryPropertyFlags::DEVICE_LOCAL,
                ),
                None,
            )
            .unwrap();
        d.bind_image_memory(image, mem, 0).unwrap();
        (image, mem)
    }
}

/// An R8_UINT shading-rate image of the application's own, `extent` texels, and a view of it.
///
/// # Safety
/// `d` must be alive.
unsafe fn rate_image(
    d: &ash::Device,
    memory: &vk::PhysicalDeviceMemoryProperties,
    extent: [u32; 2],
) -> (vk::Image, vk::DeviceMemory, vk::ImageView) {
    let info = vk::ImageCreateInfo::default()
        .image_type(vk::ImageType::TYPE_2D)
        .format(vk::Format::R8_UINT)
        .extent(vk::Extent3D {
            width: extent[0],
            height: extent[1],
            depth: 1,
        })
        .mip_levels(1)
        .array_layers(1)
        .samples(vk::SampleCountFlags::TYPE_1)
        .tiling(vk::ImageTiling::OPTIMAL)
        .usage(
            vk::ImageUsageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR
                | vk::ImageUsageFlags::TRANSFER_DST,
        );
    // SAFETY: the caller's promise; the structs live across the calls.
    unsafe {
        let image = d.create_image(&info, None).unwrap();
        let req = d.get_image_memory_requirements(image);
        let mem = d
            .allocate_memory(
                &crate::support::vulkan::allocate_info(
                    memory,
                    req,
                    vk::MemoryPropertyFlags::DEVICE_LOCAL,
                ),
                None,
            )
            .unwrap();
        d.bind_image_memory(image, mem, 0).unwrap();
        let view = d
            .create_image_view(
                &vk::ImageViewCreateInfo::default()
                    .image(image)
                    .view_type(vk::ImageViewType::TYPE_2D)
                    .format(vk::Format::R8_UINT)
                    .subresource_range(range(0, 1)),
                None,
            )
            .unwrap();
        (image, mem, view)
    }
}

/// # Safety
/// `d` and `image` must be alive.
unsafe fn view(d: &ash::Device, image: vk::Image, layers: u32) -> vk::ImageView {
    let ty = if layers > 1 {
        vk::ImageViewType::TYPE_2D_ARRAY
    } else {
        vk::ImageViewType::TYPE_2D
    };
    // SAFETY: the caller's promise.
    unsafe {
        d.create_image_view(
            &vk::ImageViewCreateInfo::default()
                .image(image)
                .view_type(ty)
                .format(FORMAT)
                .subresource_range(range(0, layers)),
            None,
        )
    }
    .unwrap()
}

/// The application's render pass: one colour attachment, cleared and stored, already in and left
/// in `COLOR_ATTACHMENT_OPTIMAL`; version 1, or version 2 for [`Api::Imageless`], then with
/// `own`, a shading-rate attachment of the application's own of that texel after it.
fn render_pass(d: &ash::Device, api: Api, own: Option<vk::Extent2D>) -> vk::RenderPass {
    let layout = vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL;
    // SAFETY: the device is alive; the structs live across the calls.
    unsafe {
        if api == Api::Imageless {
            let atts = [
                vk::AttachmentDescription2::default()
                    .format(FORMAT)
                    .samples(vk::SampleCountFlags::TYPE_1)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::STORE)
                    .initial_layout(layout)
                    .final_layout(layout),
                vk::AttachmentDescription2::default()
                    .format(vk::Format::R8_UINT)
                    .samples(vk::SampleCountFlags::TYPE_1)
                    .load_op(vk::AttachmentLoadOp::LOAD)
                    .store_op(vk::AttachmentStoreOp::DONT_CARE)
                    .initial_layout(FSR_LAYOUT)
                    .final_layout(FSR_LAYOUT),
            ];
            let colour = [vk::AttachmentReference2::default()
                .attachment(0)
                .layout(layout)
                .aspect_mask(vk::ImageAspectFlags::COLOR)];
            let rate_ref = vk::AttachmentReference2::default()
                .attachment(1)
                .layout(FSR_LAYOUT);
            let mut rate = vk::FragmentShadingRateAttachmentInfoKHR::default()
                .fragment_shading_rate_attachment(&rate_ref)
                .shading_rate_attachment_texel_size(own.unwrap_or_default());
            let mut subpass = vk::SubpassDescription2::default()
                .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
                .color_attachments(&colour);
            if own.is_some() {
                subpass = subpass.push_next(&mut rate);
            }
            let subpass = [subpass];
            d.create_render_pass2(
                &vk::RenderPassCreateInfo2::default()
                    .attachments(&atts[..1 + usize::from(own.is_some())])
                    .subpasses(&subpass),
                None,
            )
        } else {
            let atts = [vk::AttachmentDescription::default()
                .format(FORMAT)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::STORE)
                .initial_layout(layout)
                .final_layout(layout)];
            let colour = [vk::AttachmentReference {
                attachment: 0,
                layout,
            }];
            let subpass = [vk::SubpassDescription::default()
                .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
                .color_attachments(&colour)];
            d.create_render_pass(
                &vk::RenderPassCreateInfo::default()
                    .attachments(&atts)
                    .subpasses(&subpass),
                None,
            )
        }
    }
    .unwrap()
}

/// A framebuffer of `rp` over `view` of `extent`; imageless for [`Api::Imageless`], there with
/// `rate` (the extent of the application's own shading-rate image) a second attachment of it.
fn framebuffer(
    d: &ash::Device,
    rp: vk::RenderPass,
    api: Api,
    view: vk::ImageView,
    extent: [u32; 2],
    rate: Option<[u32; 2]>,
) -> vk::Framebuffer {
    let formats = [FORMAT];
    let rate_formats = [vk::Format::R8_UINT];
    let rate_extent = rate.unwrap_or_default();
    let described = [
        vk::FramebufferAttachmentImageInfo::default()
            .usage(USAGE)
            .width(extent[0])
            .height(extent[1])
            .layer_count(1)
            .view_formats(&formats),
        vk::FramebufferAttachmentImageInfo::default()
            .usage(
                vk::ImageUsageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR
                    | vk::ImageUsageFlags::TRANSFER_DST,
            )
            .width(rate_extent[0])
            .height(rate_extent[1])
            .layer_count(1)
            .view_formats(&rate_formats),
    ];
    let mut imageless = vk::FramebufferAttachmentsCreateInfo::default()
        .attachment_image_infos(&described[..1 + usize::from(rate.is_some())]);
    let views = [view];
    let mut info = vk::FramebufferCreateInfo::default()
        .render_pass(rp)
        .width(extent[0])
        .height(extent[1])
        .layers(1);
    if api == Api::Imageless {
        info = info
            .flags(vk::FramebufferCreateFlags::IMAGELESS)
            .push_next(&mut imageless);
        info.attachment_count = 1 + u32::from(rate.is_some());
    } else {
        info = info.attachments(&views);
    }
    // SAFETY: the device and view are alive; the structs live across the call.
    unsafe { d.create_framebuffer(&info, None) }.unwrap()
}

/// The swapchain's `VkImage`s.
fn swapchain_images(app: &App, swapchain: xr::Swapchain) -> Vec<vk::Image> {
    let images_fn: xr::pfn::EnumerateSwapchainImages = func(app, "xrEnumerateSwapchainImages");
    let mut count = 0;
    // SAFETY: the two-call idiom with arrays that live across the calls.
    unsafe {
        assert_eq!(
            images_fn(swapchain, 0, &mut count, null_mut()),
            xr::Result::SUCCESS
        );
        let mut images = vec![
            xr::SwapchainImageVulkanKHR {
                ty: xr::StructureType::SWAPCHAIN_IMAGE_VULKAN_KHR,
                next: null_mut(),
                image: 0,
            };
            count as usize
        ];
        assert_eq!(
            images_fn(
                swapchain,
                count,
                &mut count,
                images.as_mut_ptr() as *mut xr::SwapchainImageBaseHeader,
            ),
            xr::Result::SUCCESS
        );
        images
            .iter()
            .map(|i| vk::Image::from_raw(i.image))
            .collect()
    }
}

/// One frame as described in the module documentation, on `profile`.
fn run(profile: Profile, setup: Setup, api: Api, dir: &std::path::Path) -> Option<Outcome> {
    run_with(profile, setup, api, dir, None)
}

/// [`run`]; with `refresh`, after the first submit the level changes to it through the debug
/// property file, frames go by until fovea has read it (it looks every 250 ms of display time),
/// and a second command buffer renders into the swapchain twice more.
fn run_with(
    profile: Profile,
    setup: Setup,
    api: Api,
    dir: &std::path::Path,
    refresh: Option<Level>,
) -> Option<Outcome> {
    let (_serial, env) = crate::vk::layer::env()?;
    env.double.set_profile(Some(profile));
    crate::vk::layer::assert_no_double_errors(env);
    env.double.clear();
    vulkan::take_messages();
    let app = App::new(Chain::fovea().unwrap(), &["XR_KHR_vulkan_enable2"], API_1_0).unwrap();
    let sys = app.system();
    let ours = std::ffi::CString::new(fovea_abi::VK_LAYER_NAME).unwrap();
    let layers = [
        ours.as_c_str(),
        VALIDATION_LAYER,
        fovea_vkdouble::LAYER_NAME,
    ];
    let sets_rates = matches!(setup, Setup::SetsRates(_) | Setup::Vkd3d(_));
    let vkd3d = matches!(setup, Setup::Vkd3d(_));
    let mut rates = if sets_rates {
        vk::PhysicalDeviceFragmentShadingRateFeaturesKHR::default()
            .pipeline_fragment_shading_rate(true)
            .attachment_fragment_shading_rate(vkd3d)
    } else {
        vk::PhysicalDeviceFragmentShadingRateFeaturesKHR::default()
            .attachment_fragment_shading_rate(true)
    };
    let app_rates = setup == Setup::AppRates || sets_rates;
    let mut v11 = vk::PhysicalDeviceVulkan11Features::default().multiview(true);
    if app_rates {
        v11.p_next = &mut rates as *mut _ as *mut c_void;
    }
    let mut v12 = vk::PhysicalDeviceVulkan12Features::default().imageless_framebuffer(true);
    v12.p_next = &mut v11 as *mut _ as *mut c_void;
    let target_layers = api.layers();
    let view_mask = if api == Api::Multiview { 0b11 } else { 0 };
    let exts = [FSR];
    let options = Options {
        layers: &layers,
        api_version: vk::API_VERSION_1_3,
        multiview: false,
        dynamic_rendering: true,
        device_extensions: if app_rates { &exts } else { &[] },
        device_next: &v12 as *const _ as *const c_void,
    };
    let v = match Vulkan::through_xr_with(&env.entry, app.chain.gipa(), app.instance, sys, &options)
    {
        Ok(v) => v,
        Err(why) => {
            skip(&why);
            return None;
        }
    };
    let (session, space) = running_session(&app, sys, &v);
    let create_swapchain: xr::pfn::CreateSwapchain = func(&app, "xrCreateSwapchain");
    let info = xr::SwapchainCreateInfo {
        ty: xr::StructureType::SWAPCHAIN_CREATE_INFO,
        next: null(),
        create_flags: xr::SwapchainCreateFlags::EMPTY,
        usage_flags: xr::SwapchainUsageFlags::COLOR_ATTACHMENT,
        format: FORMAT.as_raw() as i64,
        sample_count: 1,
        width: WIDTH,
        height: HEIGHT,
        face_count: 1,
        array_size: target_layers,
        mip_count: 1,
    };
    let mut swapchain = xr::Swapchain::NULL;
    // SAFETY: the struct lives across the call.
    assert_eq!(
        unsafe { create_swapchain(session, &info, &mut swapchain) },
        xr::Result::SUCCESS
    );
    let images = swapchain_images(&app, swapchain);
    let frame = Frame {
        app: &app,
        session,
        space,
    };
    let (index, fovs, mut time) = frame.acquire(swapchain);
    let mut second = None;
    let apps_view;

    let d = &v.device;
    // SAFETY: the instance and device are alive; every struct lives across its call; every object
    // made here is destroyed before the device.
    let cb = unsafe {
        let memory = v
            .instance
            .get_physical_device_memory_properties(v.physical_device);
        let queue = d.get_device_queue(v.family, 0);
        let pool = d
            .create_command_pool(
                &vk::CommandPoolCreateInfo::default().queue_family_index(v.family),
                None,
            )
            .unwrap();
        let cb = d
            .allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool)
                    .level(vk::CommandBufferLevel::PRIMARY)
                    .command_buffer_count(1),
            )
            .unwrap()[0];
        let modules = [VERTEX, FRAGMENT].map(|b| {
            let words = spv(b);
            d.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
                .unwrap()
        });
        let layout = d
            .create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default(), None)
            .unwrap();
        let formats = [FORMAT];
        let mut rendering = vk::PipelineRenderingCreateInfo::default()
            .color_attachment_formats(&formats)
            .view_mask(view_mask);
        let texel = profile.texel();
        let rate_extent = [WIDTH.div_ceil(texel.width), HEIGHT.div_ceil(texel.height)];
        // An application with rates of its own names its shading-rate image in its render pass.
        let apps_pass = setup == Setup::AppRates && api == Api::Imageless;
        let render_pass = (!api.dynamic()).then(|| render_pass(d, api, apps_pass.then_some(texel)));
        let mut fixed = Fixed::new();
        let mut own_state = vk::PipelineFragmentShadingRateStateCreateInfoKHR::default()
            .fragment_size(vk::Extent2D {
                width: 2,
                height: 2,
            })
            .combiner_ops(KEEP);
        if sets_rates {
            fixed.dynamic =
                vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&RATE_DYNAMIC);
        }
        let st = stages(modules);
        let mut pipeline_info = match render_pass {
            Some(rp) => fixed.info(&st, layout).render_pass(rp),
            None => fixed.info(&st, layout).push_next(&mut rendering),
        };
        let mut attaching_state = vk::PipelineFragmentShadingRateStateCreateInfoKHR::default()
            .fragment_size(vk::Extent2D {
                width: 1,
                height: 1,
            })
            .combiner_ops([
                vk::FragmentShadingRateCombinerOpKHR::KEEP,
                vk::FragmentShadingRateCombinerOpKHR::REPLACE,
            ]);
        if sets_rates {
            pipeline_info = pipeline_info.push_next(&mut own_state);
        } else if setup == Setup::AppRates && api.dynamic() {
            pipeline_info = pipeline_info.push_next(&mut attaching_state);
        }
        if api.dynamic() && (vkd3d || setup == Setup::AppRates) {
            // Required of pipelines used in a rendering with a shading-rate struct, as vkd3d-proton
            // sets it.
            pipeline_info = pipeline_info
                .flags(vk::PipelineCreateFlags::RENDERING_FRAGMENT_SHADING_RATE_ATTACHMENT_KHR);
        }
        let set_rate = ash::khr::fragment_shading_rate::Device::new(&v.instance, d);
        let one = vk::Extent2D {
            width: 1,
            height: 1,
        };
        let pipeline = d
            .create_graphics_pipelines(vk::PipelineCache::null(), &[pipeline_info], None)
            .unwrap()[0];
        let (small, small_mem) = image(d, &memory, [SMALL, SMALL], target_layers);
        let (own, own_mem) = image(d, &memory, [WIDTH, HEIGHT], target_layers);
        let targets = [
            (images[index as usize], [WIDTH, HEIGHT]),
            (small, [SMALL, SMALL]),
            (own, [WIDTH, HEIGHT]),
        ];
        let views = targets.map(|(i, _)| view(d, i, target_layers));
        // The application's own shading-rate image: vkd3d-proton's, never attached; an
        // application with rates of its own, for the swapchain's rendering.
        let own_rate =
            (vkd3d || setup == Setup::AppRates).then(|| rate_image(d, &memory, rate_extent));
        let framebuffers = render_pass.map(|rp| {
            [0, 1, 2].map(|i| {
                framebuffer(
                    d,
                    rp,
                    api,
                    views[i],
                    targets[i].1,
                    apps_pass.then_some(rate_extent),
                )
            })
        });
        d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
            .unwrap();
        let to_colour: Vec<_> = targets
            .iter()
            .map(|&(i, _)| {
                vk::ImageMemoryBarrier::default()
                    .image(i)
                    .subresource_range(range(0, target_layers))
                    .old_layout(vk::ImageLayout::UNDEFINED)
                    .new_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                    .dst_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                    .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            })
            .collect();
        d.cmd_pipeline_barrier(
            cb,
            vk::PipelineStageFlags::TOP_OF_PIPE,
            vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &to_colour,
        );
        if let (Some((image, _, _)), Setup::AppRates) = (own_rate, setup) {
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TOP_OF_PIPE,
                // (Validation as installed refuses the shading-rate stage here with the rule for NV
                // shading-rate images, VUID-vkCmdPipelineBarrier-dstStageMask-04097.)
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[vk::ImageMemoryBarrier::default()
                    .image(image)
                    .subresource_range(range(0, 1))
                    .old_layout(vk::ImageLayout::UNDEFINED)
                    .new_layout(FSR_LAYOUT)
                    .dst_access_mask(vk::AccessFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR)
                    .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)],
            );
        }
        for (i, (&(_, extent), &view)) in targets.iter().zip(&views).enumerate() {
            let area = vk::Rect2D {
                offset: vk::Offset2D::default(),
                extent: vk::Extent2D {
                    width: extent[0],
                    height: extent[1],
                },
            };
            if let (Some(rp), Some(fbs)) = (render_pass, framebuffers) {
                let attachments = [view, own_rate.map(|r| r.2).unwrap_or_default()];
                let mut named = vk::RenderPassAttachmentBeginInfo::default()
                    .attachments(&attachments[..1 + usize::from(apps_pass)]);
                let mut begin = vk::RenderPassBeginInfo::default()
                    .render_pass(rp)
                    .framebuffer(fbs[i])
                    .render_area(area)
                    .clear_values(&crate::support::vulkan::CLEAR);
                if api == Api::Imageless {
                    begin = begin.push_next(&mut named);
                    d.cmd_begin_render_pass2(
                        cb,
                        &begin,
                        &vk::SubpassBeginInfo::default().contents(vk::SubpassContents::INLINE),
                    );
                } else {
                    d.cmd_begin_render_pass(cb, &begin, vk::SubpassContents::INLINE);
                }
                if sets_rates {
                    (set_rate.fp().cmd_set_fragment_shading_rate_khr)(cb, &one, &KEEP);
                }
                draw_fullscreen(d, cb, pipeline);
                d.cmd_end_render_pass(cb);
                continue;
            }
            let colour = [vk::RenderingAttachmentInfo::default()
                .image_view(view)
                .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::STORE)
                .clear_value(crate::support::vulkan::CLEAR[0])];
            let mut ri = vk::RenderingInfo::default()
                .render_area(vk::Rect2D {
                    offset: vk::Offset2D::default(),
                    extent: vk::Extent2D {
                        width: extent[0],
                        height: extent[1],
                    },
                })
                .layer_count(1)
                .view_mask(view_mask)
                .color_attachments(&colour);
            // vkd3d-proton's null view in every rendering; the application's own view in the
            // swapchain's.
            let apps = match (setup, own_rate) {
                (Setup::AppRates, Some((_, _, v))) if i == 0 => Some(v),
                (Setup::Vkd3d(_), _) => Some(vk::ImageView::null()),
                _ => None,
            };
            let mut apps_rate = vk::RenderingFragmentShadingRateAttachmentInfoKHR::default()
                .image_view(apps.unwrap_or_default())
                .image_layout(FSR_LAYOUT)
                .shading_rate_attachment_texel_size(texel);
            if apps.is_some() {
                ri = ri.push_next(&mut apps_rate);
            }
            d.cmd_begin_rendering(cb, &ri);
            if sets_rates {
                (set_rate.fp().cmd_set_fragment_shading_rate_khr)(cb, &one, &KEEP);
            }
            draw_fullscreen(d, cb, pipeline);
            d.cmd_end_rendering(cb);
        }
        d.end_command_buffer(cb).unwrap();
        let fence = d
            .create_fence(&vk::FenceCreateInfo::default(), None)
            .unwrap();
        let cbs = [cb];
        d.queue_submit(
            queue,
            &[vk::SubmitInfo::default().command_buffers(&cbs)],
            fence,
        )
        .unwrap();
        d.wait_for_fences(&[fence], true, u64::MAX).unwrap();
        d.reset_fences(&[fence]).unwrap();
        if let Some(level) = refresh {
            frame.release(swapchain, time);
            std::fs::write(
                dir.join("props"),
                format!("debug.oculus.foveation.level={}\n", level as u8),
            )
            .unwrap();
            for _ in 0..40 {
                let (_, _, t) = frame.acquire(swapchain);
                frame.release(swapchain, t);
            }
            let (i, _, t) = frame.acquire(swapchain);
            time = t;
            let target = view(d, images[i as usize], target_layers);
            let cb2 = d
                .allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default()
                        .command_pool(pool)
                        .level(vk::CommandBufferLevel::PRIMARY)
                        .command_buffer_count(1),
                )
                .unwrap()[0];
            d.begin_command_buffer(cb2, &vk::CommandBufferBeginInfo::default())
                .unwrap();
            d.cmd_pipeline_barrier(
                cb2,
                vk::PipelineStageFlags::TOP_OF_PIPE,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[to_colour[0].image(images[i as usize])],
            );
            let colour = [vk::RenderingAttachmentInfo::default()
                .image_view(target)
                .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::STORE)
                .clear_value(crate::support::vulkan::CLEAR[0])];
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
            for _ in 0..2 {
                d.cmd_begin_rendering(cb2, &ri);
                draw_fullscreen(d, cb2, pipeline);
                d.cmd_end_rendering(cb2);
            }
            d.end_command_buffer(cb2).unwrap();
            let cbs = [cb2];
            d.queue_submit(
                queue,
                &[vk::SubmitInfo::default().command_buffers(&cbs)],
                fence,
            )
            .unwrap();
            d.wait_for_fences(&[fence], true, u64::MAX).unwrap();
            d.destroy_image_view(target, None);
            second = Some(cb2.as_raw());
        }
        d.destroy_fence(fence, None);
        for fb in framebuffers.into_iter().flatten() {
            d.destroy_framebuffer(fb, None);
        }
        if let Some(rp) = render_pass {
            d.destroy_render_pass(rp, None);
        }
        for v in views {
            d.destroy_image_view(v, None);
        }
        for (i, m) in [(small, small_mem), (own, own_mem)] {
            d.destroy_image(i, None);
            d.free_memory(m, None);
        }
        if let Some((i, m, v)) = own_rate {
            d.destroy_image_view(v, None);
            d.destroy_image(i, None);
            d.free_memory(m, None);
        }
        d.destroy_pipeline(pipeline, None);
        d.destroy_pipeline_layout(layout, None);
        for m in modules {
            d.destroy_shader_module(m, None);
        }
        d.destroy_command_pool(pool, None);
        apps_view = own_rate
            .filter(|_| setup == Setup::AppRates)
            .map(|(_, _, v)| v.as_raw());
        cb.as_raw()
    };
    frame.release(swapchain, time);
    let destroy_swapchain: xr::pfn::DestroySwapchain = func(&app, "xrDestroySwapchain");
    let destroy_session: xr::pfn::DestroySession = func(&app, "xrDestroySession");
    // SAFETY: the handles are live and used no more.
    unsafe {
        assert_eq!(destroy_swapchain(swapchain), xr::Result::SUCCESS);
        assert_eq!(destroy_session(session), xr::Result::SUCCESS);
        v.destroy_device();
    }
    assert_eq!(app.destroy(), xr::Result::SUCCESS);
    // SAFETY: the device is gone.
    unsafe { v.destroy_instance() };
    vulkan::assert_no_messages();
    assert_eq!(
        env.double.errors(),
        Vec::<String>::new(),
        "{profile:?} {setup:?}"
    );
    Some(Outcome {
        second,
        events: env.double.records()["events"]
            .as_array()
            .cloned()
            .unwrap_or_default(),
        command_buffer: cb,
        fovs,
        log: std::fs::read_to_string(dir.join("fovea.log")).unwrap_or_default(),
        apps_view,
    })
}

impl Outcome {
    fn of(&self, kind: &str) -> Vec<&Value> {
        self.events.iter().filter(|e| e["kind"] == kind).collect()
    }

    /// The shading-rate view of each of the test's three renderings or passes as the driver got
    /// them, in order (`Null` for none).
    fn rates(&self, api: Api) -> Vec<Value> {
        let kind = if api.dynamic() {
            "begin_rendering"
        } else {
            "begin_render_pass"
        };
        let r: Vec<Value> = self
            .of(kind)
            .into_iter()
            .filter(|b| b["command_buffer"] == json!(self.command_buffer))
            .map(|b| {
                if api.dynamic() {
                    b["shading_rate"].clone()
                } else {
                    let v = b["shading_rate_views"]
                        .as_array()
                        .cloned()
                        .unwrap_or_default();
                    assert!(v.len() <= 1, "{b}");
                    v.first().cloned().unwrap_or(Value::Null)
                }
            })
            .collect();
        assert_eq!(r.len(), 3, "{r:?}");
        r
    }

    /// How many `VkRenderingFragmentShadingRateAttachmentInfoKHR`s the driver got in each of the
    /// test's three renderings.
    fn rate_structs(&self) -> Vec<u64> {
        self.of("begin_rendering")
            .into_iter()
            .filter(|b| b["command_buffer"] == json!(self.command_buffer))
            .map(|b| b["shading_rate_structs"].as_u64().unwrap())
            .collect()
    }

    /// What the submit of the test's command buffer read of `image`: (extent, layers, codes).
    fn codes_of(&self, image: &Value) -> ([u32; 2], u32, Vec<u8>) {
        self.codes_in(self.command_buffer, image)
    }

    /// What the submit of command buffer `cb` read of `image`.
    fn codes_in(&self, cb: u64, image: &Value) -> ([u32; 2], u32, Vec<u8>) {
        let submits: Vec<&Value> = self
            .of("submit")
            .into_iter()
            .filter(|s| {
                s["command_buffers"]
                    .as_array()
                    .unwrap()
                    .contains(&json!(cb))
            })
            .collect();
        assert_eq!(submits.len(), 1, "{submits:?}");
        let read = submits[0]["shading_rate_images"].as_array().unwrap();
        let r = read
            .iter()
            .find(|r| &r["image"] == image)
            .unwrap_or_else(|| panic!("{image} not read at submit: {read:?}"));
        let e = r["extent"].as_array().unwrap();
        (
            [e[0].as_u64().unwrap() as u32, e[1].as_u64().unwrap() as u32],
            r["layers"].as_u64().unwrap() as u32,
            r["codes"]
                .as_array()
                .unwrap()
                .iter()
                .map(|c| c.as_u64().unwrap() as u8)
                .collect(),
        )
    }

    /// What each draw of the test's `pass`-th pass or rendering shaded at, per view: its
    /// effective fragment size per shading-rate attachment texel, as the GPU the double plays
    /// computes it.
    fn effective(&self, pass: usize) -> Vec<Vec<fovea_vkdouble::ViewRates>> {
        let draws: Vec<Vec<fovea_vkdouble::ViewRates>> = self
            .of("draw")
            .into_iter()
            .filter(|d| d["command_buffer"] == json!(self.command_buffer) && d["pass"] == pass)
            .map(|d| {
                d["views"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|v| fovea_vkdouble::ViewRates {
                        view: v["view"].as_u64().unwrap() as u32,
                        layer: v["layer"].as_u64().map(|l| l as u32),
                        columns: v["columns"].as_u64().unwrap() as u32,
                        rows: v["rows"].as_u64().unwrap() as u32,
                        codes: v["codes"]
                            .as_str()
                            .unwrap()
                            .chars()
                            .map(|c| c.to_digit(16).unwrap() as u8)
                            .collect(),
                    })
                    .collect()
            })
            .collect();
        assert!(!draws.is_empty(), "no draw in pass {pass}");
        draws
    }

    /// The shading-rate image a view the double saw made is of.
    fn image_of(&self, view: &Value) -> Value {
        self.of("image_view")
            .into_iter()
            .find(|v| &v["view"] == view)
            .unwrap_or_else(|| panic!("no shading-rate view {view}"))["image"]
            .clone()
    }
}

/// What fovea's model gives a map for `views` over a 640×500 target on `profile`.
fn expected(
    profile: Profile,
    views: Views,
    fovs: [Fov; 2],
    level: Level,
) -> ([u32; 2], u32, Vec<u8>) {
    let device = fovea_model::inject::Device {
        texel: [profile.texel().width, profile.texel().height],
        layered: profile.layered(),
        max_fragment: [profile.max_fragment(); 2],
        rates: profile
            .rates()
            .iter()
            .filter(|(_, s)| s.contains(vk::SampleCountFlags::TYPE_1))
            .map(|(e, _)| [e.width, e.height])
            .collect(),
    };
    let mut all = [None; MAX_VIEWS];
    all[0] = Some(fovs[0]);
    all[1] = Some(fovs[1]);
    fovea_model::inject::codes(
        &device,
        views,
        [WIDTH, HEIGHT],
        &all,
        Pattern {
            level,
            vertical_offset_deg: 0.0,
        },
        fovea_model::maps::DEFAULT_MAX_FRAGMENT,
    )
}

/// Runs `setup` with `api` on both profiles in a child process of its own and checks the outcome.
fn check(test: &str, setup: Setup, api: Api, levels: &[Level]) {
    in_own_process(module_path!(), test, || {
        for profile in [Profile::Nvidia, Profile::Amd] {
            let setups: Vec<Setup> = match setup {
                Setup::Inject(_) | Setup::SetsRates(Some(_)) => {
                    levels.iter().map(|&l| setup.at(l)).collect()
                }
                s => vec![s],
            };
            for s in setups {
                let dir = set_up(&format!("{test}-{profile:?}"), s);
                let Some(out) = run(profile, s, api, &dir) else {
                    return;
                };
                assert_outcome(profile, s, api, &out);
            }
        }
    });
}

fn assert_outcome(profile: Profile, setup: Setup, api: Api, out: &Outcome) {
    let what = format!("{profile:?} {setup:?} {api:?}");
    let devices = out.of("device");
    assert_eq!(devices.len(), 1, "{what}: {devices:?}");
    let pipelines = out.of("pipeline");
    assert_eq!(pipelines.len(), 1, "{what}: {pipelines:?}");
    let passes = out.of("render_pass");
    let sets_rates = matches!(setup, Setup::SetsRates(_) | Setup::Vkd3d(_));
    let vkd3d = matches!(setup, Setup::Vkd3d(_));
    // The application's own rates: the pipeline's dynamic state and, per pass, its 1×1.
    let sets: Vec<&Value> = out
        .of("set_fragment_shading_rate")
        .into_iter()
        .filter(|s| s["command_buffer"] == json!(out.command_buffer))
        .collect();
    assert_eq!(sets.len(), if sets_rates { 3 } else { 0 }, "{what}");
    assert_eq!(pipelines[0]["dynamic_rate"], sets_rates, "{what}");
    let ops = |o: [vk::FragmentShadingRateCombinerOpKHR; 2]| json!([o[0].as_raw(), o[1].as_raw()]);
    let Some(level) = setup.level() else {
        // Nothing of fovea's: no shading rates added to the device, no flag or state on the
        // pipeline, no attachment in any pass or rendering; an application's own rates as it set
        // them.
        let enabled = vkd3d;
        assert_eq!(
            devices[0]["features"]["attachment"]
                .as_bool()
                .unwrap_or(false),
            enabled,
            "{what}: {}",
            devices[0]
        );
        assert_eq!(
            devices[0]["features"]["pipeline"]
                .as_bool()
                .unwrap_or(false),
            sets_rates,
            "{what}: {}",
            devices[0]
        );
        assert_eq!(
            pipelines[0]["rendering_attachment_flag"],
            vkd3d && api.dynamic(),
            "{what}"
        );
        let own = sets_rates.then(|| json!({"fragment_size": [2, 2], "combiner_ops": ops(KEEP)}));
        assert_eq!(
            pipelines[0]["shading_rate_state"],
            own.unwrap_or(Value::Null),
            "{what}"
        );
        for s in &sets {
            assert_eq!(s["fragment_size"], json!([1, 1]), "{what}: {s}");
            assert_eq!(s["combiner_ops"], ops(KEEP), "{what}: {s}");
        }
        // (The double records passes and begins only where shading rates are in play.)
        for p in &passes {
            assert_eq!(p["attachments"].as_array().unwrap().len(), 1, "{what}: {p}");
            assert_eq!(
                p["subpasses"][0]["shading_rate"],
                Value::Null,
                "{what}: {p}"
            );
        }
        for b in out.of("begin_rendering") {
            assert_eq!(b["shading_rate"], Value::Null, "{what}: {b}");
        }
        for b in out.of("begin_render_pass") {
            assert_eq!(b["shading_rate_views"], json!([]), "{what}: {b}");
        }
        if api.dynamic() {
            assert_eq!(out.rates(api), vec![Value::Null; 3], "{what}");
            assert_eq!(out.rate_structs(), vec![u64::from(vkd3d); 3], "{what}");
        }
        assert!(
            !out.log.contains("injected shading-rate map"),
            "{what}: {}",
            out.log
        );
        // What the GPU shades: full rate everywhere, unless the application asked otherwise.
        if !sets_rates {
            for pass in 0..3 {
                for draw in out.effective(pass) {
                    for v in &draw {
                        assert!(
                            v.codes.iter().all(|&c| c == 0),
                            "{what}: pass {pass} shades at full rate: {v:?}"
                        );
                    }
                }
            }
        }
        return;
    };
    if setup == Setup::AppRates {
        return assert_apps_own(profile, api, out, level);
    }
    assert_eq!(
        passes.len(),
        usize::from(!api.dynamic()),
        "{what}: {passes:?}"
    );
    let rates = out.rates(api);
    let texel = profile.texel();
    // The attachment feature added; an application's own features kept.
    assert_eq!(
        devices[0]["features"],
        json!({"pipeline": sets_rates, "primitive": false, "attachment": true}),
        "{what}: {}",
        devices[0]
    );
    // The flag is for dynamic rendering; a render pass carries its attachment itself.
    assert_eq!(
        pipelines[0]["rendering_attachment_flag"],
        api.dynamic(),
        "{what}"
    );
    // An application's own rate and first combiner stay, and the attachment applies on top: MAX,
    // both profiles reporting fragmentShadingRateNonTrivialCombinerOps as the drivers they stand
    // for do. Without it, REPLACE where the application's rate is 1×1 (its calls), and its own
    // KEEP where it asked for coarser (its pipeline's 2×2).
    let trivial = std::env::var_os(fovea_vkdouble::TRIVIAL_COMBINERS_ENV).is_some();
    let (own_op, max) = if trivial {
        (
            vk::FragmentShadingRateCombinerOpKHR::KEEP,
            vk::FragmentShadingRateCombinerOpKHR::REPLACE,
        )
    } else {
        (
            vk::FragmentShadingRateCombinerOpKHR::MAX,
            vk::FragmentShadingRateCombinerOpKHR::MAX,
        )
    };
    let state = if sets_rates {
        json!({"fragment_size": [2, 2], "combiner_ops": ops([KEEP[0], own_op])})
    } else {
        json!({"fragment_size": [1, 1], "combiner_ops": ops([
            vk::FragmentShadingRateCombinerOpKHR::KEEP,
            vk::FragmentShadingRateCombinerOpKHR::REPLACE,
        ])})
    };
    assert_eq!(pipelines[0]["shading_rate_state"], state, "{what}");
    for s in &sets {
        assert_eq!(s["fragment_size"], json!([1, 1]), "{what}: its rate: {s}");
        assert_eq!(s["combiner_ops"], ops([KEEP[0], max]), "{what}: {s}");
    }
    if sets_rates {
        assert!(
            out.log.contains(&format!(
                "the application sets shading rates per pipeline or per draw: injected maps are \
                 combined with its rates non_trivial_combiners={}",
                !trivial
            )),
            "{what}: {}",
            out.log
        );
    }
    for p in &passes {
        let atts = p["attachments"].as_array().unwrap();
        assert_eq!(atts.len(), 2, "{what}: {p}");
        assert_eq!(atts[1]["format"], vk::Format::R8_UINT.as_raw(), "{what}");
        assert_eq!(
            p["subpasses"][0]["shading_rate"],
            json!({"attachment": 1, "layout": FSR_LAYOUT.as_raw(),
                   "texel": [texel.width, texel.height]}),
            "{what}: {p}"
        );
    }
    if api.dynamic() {
        for r in [&rates[0], &rates[2]] {
            assert_eq!(r["layout"], FSR_LAYOUT.as_raw(), "{what}: {r}");
            assert_eq!(r["texel"], json!([texel.width, texel.height]), "{what}");
        }
        // One struct in each eye rendering (vkd3d-proton's null-view one replaced by fovea's);
        // the small target's as the application chained it.
        assert_eq!(out.rate_structs(), vec![1, u64::from(vkd3d), 1], "{what}");
    }
    assert!(
        !out.log.contains("a shading-rate attachment of its own"),
        "{what}: {}",
        out.log
    );
    let view_of = |r: &Value| {
        if api.dynamic() {
            r["view"].clone()
        } else {
            r.clone()
        }
    };
    // The swapchain image (view 0) and the eye-shaped target of the application's own (both
    // eyes merged) get maps; in a multiview rendering both hold both views, layer by layer (on
    // `amd`, without layered attachments, merged into one).
    let (swapchain_views, own_views) = if api == Api::Multiview {
        let both = Views::Layers { first: 0, count: 2 };
        (both, both)
    } else {
        (Views::Layers { first: 0, count: 1 }, Views::Merged)
    };
    for (r, views) in [(&rates[0], swapchain_views), (&rates[2], own_views)] {
        let image = out.image_of(&view_of(r));
        let got = out.codes_of(&image);
        let want = expected(profile, views, out.fovs, level);
        assert_eq!(
            (got.0, got.1),
            (want.0, want.1),
            "{what} {views:?}: extent, layers"
        );
        let texels = (want.0[0] * want.0[1]) as usize;
        if level == Level::None {
            assert!(
                want.2.iter().all(|&c| c == 0),
                "{what}: level none is full rate"
            );
        } else {
            assert!(
                want.2.iter().any(|&c| c != 0),
                "{what}: {level:?} coarsens somewhere"
            );
        }
        // What the GPU shades: every draw of the pass, every view (its layer of the map where the
        // map is layered, else the one layer), the model's rates texel for texel.
        let pass = if std::ptr::eq(r, &rates[0]) { 0 } else { 2 };
        for draw in out.effective(pass) {
            let view_count = if api == Api::Multiview { 2 } else { 1 };
            assert_eq!(draw.len(), view_count, "{what}: pass {pass}: {draw:?}");
            for v in &draw {
                let layer = if want.1 > 1 { v.view as usize } else { 0 };
                assert_eq!([v.columns, v.rows], want.0, "{what}: pass {pass}");
                assert!(
                    v.codes[..] == want.2[layer * texels..(layer + 1) * texels],
                    "{what} {views:?}: pass {pass} view {}: the effective rates differ from \
                     the model",
                    v.view
                );
            }
        }
    }
    // Off the eyes, full rate: every draw of the small target's pass, everywhere.
    for draw in out.effective(1) {
        for v in &draw {
            assert!(
                v.codes.iter().all(|&c| c == 0),
                "{what}: the small target shades at full rate: {v:?}"
            );
        }
    }
    if api == Api::Multiview {
        assert_eq!(
            view_of(&rates[0]),
            view_of(&rates[2]),
            "{what}: one map per shape and views"
        );
        let (_, layers, _) = out.codes_of(&out.image_of(&view_of(&rates[0])));
        assert_eq!(layers, if profile.layered() { 2 } else { 1 }, "{what}");
    } else {
        assert_ne!(
            view_of(&rates[0]),
            view_of(&rates[2]),
            "{what}: one map per shape and views"
        );
    }
    // The small target: no attachment in a rendering; a full-rate map covering it in a pass.
    if api.dynamic() {
        assert_eq!(rates[1], Value::Null, "{what}: small target");
    } else {
        let (extent, layers, codes) = out.codes_of(&out.image_of(&rates[1]));
        let n = [SMALL.div_ceil(texel.width), SMALL.div_ceil(texel.height)];
        assert_eq!((extent, layers), (n, 1), "{what}: the full-rate map");
        assert!(codes.iter().all(|&c| c == 0), "{what}: full rate");
    }
}

/// [`Setup::AppRates`]: the application's own view reaches the driver in the swapchain's
/// rendering, fovea's map in the eye-shaped target's (which names none), and the log says once
/// that the application's own attachment wins.
fn assert_apps_own(profile: Profile, api: Api, out: &Outcome, level: Level) {
    let what = format!("{profile:?} AppRates {api:?}");
    let devices = out.of("device");
    assert_eq!(
        devices[0]["features"],
        json!({"pipeline": false, "primitive": false, "attachment": true}),
        "{what}: {}",
        devices[0]
    );
    let pipelines = out.of("pipeline");
    let apps = json!(out.apps_view.expect("the application's view"));
    let once = || {
        assert_eq!(
            out.log
                .matches("the application uses a shading-rate attachment of its own")
                .count(),
            1,
            "{what}: {}",
            out.log
        )
    };
    if api == Api::Imageless {
        // The application's render pass names its own attachment: the pass, its framebuffers'
        // attachments and its pipeline (no shading-rate state: the application's attachment is
        // not applied, as it chose) as it made them.
        let passes = out.of("render_pass");
        assert_eq!(passes.len(), 1, "{what}: {passes:?}");
        let texel = profile.texel();
        assert_eq!(
            passes[0]["attachments"].as_array().unwrap().len(),
            2,
            "{what}: {}",
            passes[0]
        );
        assert_eq!(
            passes[0]["subpasses"][0]["shading_rate"],
            json!({"attachment": 1, "layout": FSR_LAYOUT.as_raw(),
                   "texel": [texel.width, texel.height]}),
            "{what}: {}",
            passes[0]
        );
        assert_eq!(pipelines[0]["rendering_attachment_flag"], false, "{what}");
        assert_eq!(pipelines[0]["shading_rate_state"], Value::Null, "{what}");
        assert_eq!(out.rates(api), vec![apps.clone(); 3], "{what}");
        return once();
    }
    assert_eq!(pipelines[0]["rendering_attachment_flag"], true, "{what}");
    // The application's own state, which lets its attachment decide: kept.
    assert_eq!(
        pipelines[0]["shading_rate_state"],
        json!({"fragment_size": [1, 1], "combiner_ops": [
            vk::FragmentShadingRateCombinerOpKHR::KEEP.as_raw(),
            vk::FragmentShadingRateCombinerOpKHR::REPLACE.as_raw(),
        ]}),
        "{what}"
    );
    let rates = out.rates(api);
    assert_eq!(rates[0]["view"], apps, "{what}: the application's own view");
    assert_eq!(rates[1], Value::Null, "{what}: small target");
    assert_ne!(rates[2]["view"], apps, "{what}");
    let got = out.codes_of(&out.image_of(&rates[2]["view"]));
    let want = expected(profile, Views::Merged, out.fovs, level);
    assert!(
        got == want,
        "{what}: the eye-shaped target gets fovea's map"
    );
    assert_eq!(out.rate_structs(), vec![1, 0, 1], "{what}");
    once();
}

#[test]
fn injected_eye_passes_carry_the_models_codes_at_every_level() {
    check(
        "injected_eye_passes_carry_the_models_codes_at_every_level",
        Setup::Inject(Level::None),
        Api::Dynamic,
        &Level::ALL,
    );
}

#[test]
fn multiview_renderings_into_an_array_of_views_get_a_layered_or_merged_map() {
    check(
        "multiview_renderings_into_an_array_of_views_get_a_layered_or_merged_map",
        Setup::Inject(Level::None),
        Api::Multiview,
        &[Level::High],
    );
}

#[test]
fn render_pass_eye_passes_get_the_eye_map_and_others_the_full_rate_map() {
    check(
        "render_pass_eye_passes_get_the_eye_map_and_others_the_full_rate_map",
        Setup::Inject(Level::None),
        Api::RenderPass,
        &[Level::None, Level::High],
    );
}

#[test]
fn imageless_framebuffers_get_their_map_at_each_begin() {
    check(
        "imageless_framebuffers_get_their_map_at_each_begin",
        Setup::Inject(Level::None),
        Api::Imageless,
        &[Level::Medium],
    );
}

/// A map is refilled in place, once, when the published maps' key moves (here the level, through
/// the debug property file while the application runs), and the passes after it read the new
/// codes; nothing is refilled per pass.
#[test]
fn a_changed_level_refills_the_map_in_place_once() {
    in_own_process(
        module_path!(),
        "a_changed_level_refills_the_map_in_place_once",
        || {
            let (first, then) = (Level::Low, Level::High);
            for profile in [Profile::Nvidia, Profile::Amd] {
                let setup = Setup::Inject(first);
                let dir = set_up(&format!("refresh-{profile:?}"), setup);
                let Some(out) = run_with(profile, setup, Api::Dynamic, &dir, Some(then)) else {
                    return;
                };
                let what = format!("{profile:?}");
                assert_outcome(profile, setup, Api::Dynamic, &out);
                let cb2 = out.second.expect("a second command buffer");
                let before = out.rates(Api::Dynamic)[0]["view"].clone();
                let after: Vec<&Value> = out
                    .of("begin_rendering")
                    .into_iter()
                    .filter(|b| b["command_buffer"] == json!(cb2))
                    .collect();
                assert_eq!(after.len(), 2, "{what}: {after:?}");
                for b in &after {
                    assert_eq!(b["shading_rate"]["view"], before, "{what}: the same map");
                }
                let image = out.image_of(&before);
                let views = Views::Layers { first: 0, count: 1 };
                let old = out.codes_in(out.command_buffer, &image);
                let new = out.codes_in(cb2, &image);
                assert!(
                    old.2 == expected(profile, views, out.fovs, first).2,
                    "{what}"
                );
                assert!(
                    new.2 == expected(profile, views, out.fovs, then).2,
                    "{what}"
                );
                assert!(old.2 != new.2, "{what}: {first:?} and {then:?} differ");
                let refills = out
                    .log
                    .matches("injected shading-rate map refilled")
                    .count();
                assert_eq!(refills, 1, "{what}: one refill\n{}", out.log);
            }
        },
    );
}

#[test]
fn without_injection_nothing_reaches_the_driver() {
    check(
        "without_injection_nothing_reaches_the_driver",
        Setup::Off,
        Api::Dynamic,
        &[],
    );
}

#[test]
fn without_injection_render_passes_reach_the_driver_unchanged() {
    check(
        "without_injection_render_passes_reach_the_driver_unchanged",
        Setup::Off,
        Api::RenderPass,
        &[],
    );
}

/// vkd3d-proton's way: pipeline rates enabled without attachments, every pipeline with the dynamic
/// shading-rate state, 1×1 and {KEEP, KEEP} set before each draw. Its eye passes get the injected
/// map all the same, and its rates combine with it by MAX, in dynamic renderings and render passes.
#[test]
fn an_application_that_sets_rates_without_attachments_is_injected_into() {
    check(
        "an_application_that_sets_rates_without_attachments_is_injected_into",
        Setup::SetsRates(Some(Level::None)),
        Api::Dynamic,
        &[Level::High],
    );
}

/// As [`an_application_that_sets_rates_without_attachments_is_injected_into`], in render passes:
/// the full-rate map of the small target's pass leaves its rates as they were (MAX with 1×1).
#[test]
fn an_application_that_sets_rates_without_attachments_is_injected_into_passes() {
    check(
        "an_application_that_sets_rates_without_attachments_is_injected_into_passes",
        Setup::SetsRates(Some(Level::None)),
        Api::RenderPass,
        &[Level::Medium],
    );
}

/// On a device with only `KEEP` and `REPLACE` (the double told to report
/// `fragmentShadingRateNonTrivialCombinerOps` false, which validation then enforces): the
/// application's 1×1 calls get `REPLACE` (the map's rate, as `MAX` would give), its pipeline's own
/// 2×2 keeps `KEEP` and so its rate.
#[test]
fn without_non_trivial_combiners_replace_stands_in_where_the_rate_is_1x1() {
    in_own_process(
        module_path!(),
        "without_non_trivial_combiners_replace_stands_in_where_the_rate_is_1x1",
        || {
            std::env::set_var(fovea_vkdouble::TRIVIAL_COMBINERS_ENV, "1");
            for profile in [Profile::Nvidia, Profile::Amd] {
                let setup = Setup::SetsRates(Some(Level::High));
                let dir = set_up(&format!("trivial-{profile:?}"), setup);
                let Some(out) = run(profile, setup, Api::Dynamic, &dir) else {
                    return;
                };
                assert_outcome(profile, setup, Api::Dynamic, &out);
            }
        },
    );
}

#[test]
fn without_injection_an_applications_rates_reach_the_driver_unchanged() {
    check(
        "without_injection_an_applications_rates_reach_the_driver_unchanged",
        Setup::SetsRates(None),
        Api::Dynamic,
        &[],
    );
}

/// An application that names a shading-rate view of its own in a rendering of an eye target: that
/// view reaches the driver, fovea's map only the eye rendering that names none.
#[test]
fn an_applications_own_shading_rate_attachment_is_left_alone() {
    check(
        "an_applications_own_shading_rate_attachment_is_left_alone",
        Setup::AppRates,
        Api::Dynamic,
        &[],
    );
}

/// An application whose render pass references a shading-rate attachment of its own: the pass,
/// its framebuffers and its pipeline reach the driver as it made them, its view in every begin.
#[test]
fn an_applications_render_pass_with_its_own_attachment_is_left_alone() {
    check(
        "an_applications_render_pass_with_its_own_attachment_is_left_alone",
        Setup::AppRates,
        Api::Imageless,
        &[],
    );
}

/// vkd3d-proton as it is: the attachment feature enabled, a null-view shading-rate struct in every
/// rendering, shading-rate images it never attaches, its own rates. Its eye renderings reach the
/// driver with fovea's map (the model's codes) in place of its null-view struct, one struct in
/// the chain; its other rendering unchanged.
#[test]
fn a_vkd3d_like_application_is_injected_into() {
    check(
        "a_vkd3d_like_application_is_injected_into",
        Setup::Vkd3d(Some(Level::None)),
        Api::Dynamic,
        &[Level::High],
    );
}

#[test]
fn without_injection_a_vkd3d_like_application_reaches_the_driver_unchanged() {
    check(
        "without_injection_a_vkd3d_like_application_reaches_the_driver_unchanged",
        Setup::Vkd3d(None),
        Api::Dynamic,
        &[],
    );
}
