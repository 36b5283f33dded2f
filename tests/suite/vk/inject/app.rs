//! The application of the injection tests: one frame of three passes, set up as [`Setup`] says
//! and rendered through [`Api`].

use std::ffi::{c_void, CStr};
use std::path::PathBuf;
use std::ptr::{null, null_mut};

use ash::vk;
use ash::vk::Handle as _;
use fovea_harness::app::API_1_0;
use fovea_harness::vulkan::{self, pick_lavapipe, Options, Vulkan, VALIDATION_LAYER};
use fovea_harness::{skip, App, Chain};
use fovea_model::density::Level;
use fovea_vkdouble::Profile;
use openxr_sys as xr;
use xr::Handle as _;

use crate::both::fdm_vulkan::{func, running_session, Frame};
use crate::support::vulkan::{
    cleared_color, draw_fullscreen, range, spv, stages, to_color_attachment, Fixed, FRAGMENT,
    VERTEX,
};

use super::outcome::Outcome;

pub(super) const WIDTH: u32 = 640;
pub(super) const HEIGHT: u32 = 500;
/// The small target: no eye's shape.
pub(super) const SMALL: u32 = 256;
pub(super) const FORMAT: vk::Format = vk::Format::R8G8B8A8_SRGB;
pub(super) const FSR_LAYOUT: vk::ImageLayout =
    vk::ImageLayout::FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR;
pub(super) const FSR: &CStr = c"VK_KHR_fragment_shading_rate";
/// The colour targets' usage: what the simulated runtime gives the swapchain's images (an
/// imageless framebuffer describes it).
pub(super) const USAGE: vk::ImageUsageFlags = vk::ImageUsageFlags::from_raw(
    vk::ImageUsageFlags::COLOR_ATTACHMENT.as_raw() | vk::ImageUsageFlags::SAMPLED.as_raw(),
);

/// How the application renders.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Api {
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
    pub(super) fn dynamic(self) -> bool {
        matches!(self, Api::Dynamic | Api::Multiview)
    }

    /// The colour targets' layers.
    pub(super) fn layers(self) -> u32 {
        if self == Api::Multiview {
            2
        } else {
            1
        }
    }
}

/// How the application is set up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Setup {
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
    /// As Qt 6.8's Quick 3D XR: the application enables `XR_FB_foveation`,
    /// `XR_FB_foveation_configuration` and `XR_FB_swapchain_update_state` (not
    /// `XR_FB_foveation_vulkan`), creates its swapchain without `XrSwapchainCreateInfoFoveationFB`
    /// and applies a HIGH profile to it with `xrUpdateSwapchainFB`, which must succeed; injection
    /// off, or on at this level (the profile's HIGH wins).
    Toolkit(Option<Level>),
}

/// What a [`Setup::Toolkit`] application applies to its swapchain.
pub(super) const TOOLKIT_LEVEL: Level = Level::High;

impl Setup {
    /// The injected level, where injection is on for an application fovea injects into.
    pub(super) fn level(self) -> Option<Level> {
        match self {
            Setup::Inject(level) => Some(level),
            Setup::SetsRates(level) | Setup::Vkd3d(level) => level,
            Setup::AppRates => Some(Level::High),
            Setup::Toolkit(_) => Some(TOOLKIT_LEVEL),
            Setup::Off => None,
        }
    }

    /// The same setup at `level`.
    pub(super) fn at(self, level: Level) -> Setup {
        match self {
            Setup::SetsRates(_) => Setup::SetsRates(Some(level)),
            Setup::Vkd3d(_) => Setup::Vkd3d(Some(level)),
            _ => Setup::Inject(level),
        }
    }
}

/// The application's own combiners, as vkd3d-proton passes them for D3D12's defaults.
pub(super) const KEEP: [vk::FragmentShadingRateCombinerOpKHR; 2] = [
    vk::FragmentShadingRateCombinerOpKHR::KEEP,
    vk::FragmentShadingRateCombinerOpKHR::KEEP,
];
/// The dynamic states of a [`Setup::SetsRates`] application's pipeline.
pub(super) static RATE_DYNAMIC: [vk::DynamicState; 3] = [
    vk::DynamicState::VIEWPORT,
    vk::DynamicState::SCISSOR,
    vk::DynamicState::FRAGMENT_SHADING_RATE_KHR,
];

/// The folder for the log; sets the environment the run reads. Call first in the child process.
pub(super) fn set_up(label: &str, setup: Setup) -> PathBuf {
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
        Setup::SetsRates(Some(level)) | Setup::Vkd3d(Some(level)) | Setup::Toolkit(Some(level)) => {
            std::env::set_var("FOVEA_INJECT", "1");
            std::env::set_var("FOVEA_INJECT_LEVEL", (level as u8).to_string());
        }
        Setup::AppRates => {
            std::env::set_var("FOVEA_INJECT", "1");
            std::env::set_var("FOVEA_INJECT_LEVEL", (Level::High as u8).to_string());
        }
        Setup::Off | Setup::SetsRates(None) | Setup::Vkd3d(None) | Setup::Toolkit(None) => {
            std::env::remove_var("FOVEA_INJECT")
        }
    }
    pick_lavapipe();
    dir
}

/// # Safety
/// `d` must be alive.
pub(super) unsafe fn image(
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
pub(super) unsafe fn rate_image(
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
pub(super) unsafe fn view(d: &ash::Device, image: vk::Image, layers: u32) -> vk::ImageView {
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
pub(super) fn render_pass(d: &ash::Device, api: Api, own: Option<vk::Extent2D>) -> vk::RenderPass {
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
pub(super) fn framebuffer(
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

/// Creates a profile of `level` and applies it to `swapchain` (created without foveation info), as
/// Qt does; fovea must accept it.
pub(super) fn apply_profile(
    app: &App,
    session: xr::Session,
    swapchain: xr::Swapchain,
    level: Level,
) {
    let create: xr::pfn::CreateFoveationProfileFB = func(app, "xrCreateFoveationProfileFB");
    let update: xr::pfn::UpdateSwapchainFB = func(app, "xrUpdateSwapchainFB");
    let level_info = crate::support::level_info(level as i32, 0, 0.0);
    let info = xr::FoveationProfileCreateInfoFB {
        ty: xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
        next: &level_info as *const _ as *mut c_void,
    };
    let mut profile = xr::FoveationProfileFB::NULL;
    // SAFETY: the structs live across the calls.
    unsafe {
        assert_eq!(create(session, &info, &mut profile), xr::Result::SUCCESS);
        let state = crate::support::foveation_state(profile, 0);
        assert_eq!(
            update(swapchain, &state as *const _ as *const _),
            xr::Result::SUCCESS,
            "a profile applied to a swapchain created without foveation info"
        );
    }
}

/// The swapchain's `VkImage`s.
pub(super) fn swapchain_images(app: &App, swapchain: xr::Swapchain) -> Vec<vk::Image> {
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
pub(super) fn run(
    profile: Profile,
    setup: Setup,
    api: Api,
    dir: &std::path::Path,
) -> Option<Outcome> {
    run_with(profile, setup, api, dir, None)
}

/// [`run`]; with `refresh`, after the first submit the level changes to it through the debug
/// property file, frames go by until fovea has read it (it looks every 250 ms of display time),
/// and a second command buffer renders into the swapchain twice more.
pub(super) fn run_with(
    profile: Profile,
    setup: Setup,
    api: Api,
    dir: &std::path::Path,
    refresh: Option<Level>,
) -> Option<Outcome> {
    let (_serial, env) = crate::support::device::env()?;
    env.double.set_profile(Some(profile));
    crate::support::device::assert_no_double_errors(env);
    env.double.clear();
    vulkan::take_messages();
    let toolkit = matches!(setup, Setup::Toolkit(_));
    let extensions: &[&str] = if toolkit {
        &[
            "XR_KHR_vulkan_enable2",
            "XR_FB_foveation",
            "XR_FB_foveation_configuration",
            "XR_FB_swapchain_update_state",
        ]
    } else {
        &["XR_KHR_vulkan_enable2"]
    };
    let app = App::new(Chain::fovea().unwrap(), extensions, API_1_0).unwrap();
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
        queues: 1,
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
    if toolkit {
        apply_profile(&app, session, swapchain, TOOLKIT_LEVEL);
    }
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
        let target_images: Vec<_> = targets.iter().map(|&(i, _)| i).collect();
        to_color_attachment(d, cb, &target_images, target_layers);
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
            let colour = [cleared_color(view)];
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
            to_color_attachment(d, cb2, &[images[i as usize]], target_layers);
            let colour = [cleared_color(target)];
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
