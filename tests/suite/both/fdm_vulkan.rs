//! XR_FB_foveation_vulkan on a real Vulkan device: fovea in front of the simulated runtime through the
//! harness, a VkInstance and VkDevice on lavapipe made through XR_KHR_vulkan_enable2 under the Khronos
//! validation layer, and a debug messenger that must stay silent. The density images are read back
//! layer by layer and compared byte for byte with the density model; the validation layer reports any
//! Vulkan object fovea leaves alive when the device is destroyed.
//!
//! Skips with a reason when the Vulkan loader, the validation layer or lavapipe is missing; fails
//! instead under `FOVEA_REQUIRE_SYSTEM=1` (CI).

use std::ffi::{c_void, CStr, CString};
use std::ptr::{null, null_mut};

use ash::vk;
use ash::vk::Handle as _;
use fovea_harness::app::API_1_0;
use fovea_harness::vulkan::{self, assert_no_messages, pick_lavapipe, Vulkan};
use fovea_harness::{skip, App, Chain};
use fovea_model::density::{self, Grid, Level, Pattern, Rect, View};
use fovea_model::Fov;
use openxr_sys as xr;
use parking_lot::Mutex;
use xr::Handle;

use crate::support::device::{allocate, resettable_pool};
use crate::support::level_info;

/// Held by each test that creates a validated device, so the messages are that test's own.
pub(crate) static VALIDATED: Mutex<()> = Mutex::new(());

pub(crate) const FDM_BIT: u64 = 0x2;
const SRGB: i64 = 43; // VK_FORMAT_R8G8B8A8_SRGB
pub(crate) const WIDTH: u32 = 640;
pub(crate) const HEIGHT: u32 = 500;
/// lavapipe has no VK_EXT_fragment_density_map: fovea's documented default texel size.
const TEXEL: [u32; 2] = fovea_model::maps::DEFAULT_TEXEL;

/// The application's VkInstance and VkDevice made through `app`'s runtime
/// (`XR_KHR_vulkan_enable2`) from `entry` as `options` says, with `app` handed back; `None` after a
/// skip where the system cannot make them, with `app`'s instance destroyed first.
pub(crate) fn vulkan_or_skip(
    entry: &ash::Entry,
    app: App,
    sys: xr::SystemId,
    options: &vulkan::Options<'_>,
) -> Option<(App, Vulkan)> {
    match Vulkan::through_xr_with(entry, app.chain.gipa(), app.instance, sys, options) {
        Ok(v) => Some((app, v)),
        Err(why) => {
            assert_eq!(app.destroy(), xr::Result::SUCCESS);
            skip(&why);
            None
        }
    }
}

/// The application's VkInstance and VkDevice through the runtime, under the validation layer, or
/// `None` after a skip.
fn vulkan_through_xr(app: &App, sys: xr::SystemId) -> Option<Vulkan> {
    vulkan::validated_entry()
        .and_then(|entry| Vulkan::through_xr(&entry, app.chain.gipa(), app.instance, sys))
        .map_err(|why| skip(&why))
        .ok()
}

pub(crate) fn func<T: Copy>(app: &App, name: &str) -> T {
    let c = CString::new(name).unwrap();
    unsafe { app.func(&c) }
}

/// Creates a foveation profile of `level` (an `XrFoveationLevelProfileCreateInfoFB` and its
/// chain), applies it to `swapchain` with `xrUpdateSwapchainFB` and destroys it again.
pub(crate) fn apply_profile(
    app: &App,
    session: xr::Session,
    swapchain: xr::Swapchain,
    level: &xr::FoveationLevelProfileCreateInfoFB,
) {
    let create_profile: xr::pfn::CreateFoveationProfileFB = func(app, "xrCreateFoveationProfileFB");
    let destroy_profile: xr::pfn::DestroyFoveationProfileFB =
        func(app, "xrDestroyFoveationProfileFB");
    let update: xr::pfn::UpdateSwapchainFB = func(app, "xrUpdateSwapchainFB");
    let pi = xr::FoveationProfileCreateInfoFB {
        ty: xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
        next: level as *const _ as *mut c_void,
    };
    let mut profile = xr::FoveationProfileFB::NULL;
    // SAFETY: the structs live across the calls.
    unsafe {
        assert_eq!(
            create_profile(session, &pi, &mut profile),
            xr::Result::SUCCESS
        );
        let state = crate::support::foveation_state(profile, 0);
        assert_eq!(
            update(swapchain, &state as *const _ as *const _),
            xr::Result::SUCCESS
        );
        assert_eq!(destroy_profile(profile), xr::Result::SUCCESS);
    }
}

const FOVEATION_VULKAN: [&str; 4] = [
    "XR_FB_swapchain_update_state",
    "XR_FB_foveation",
    "XR_FB_foveation_configuration",
    "XR_FB_foveation_vulkan",
];

pub(crate) fn app(vulkan_ext: &str, foveation: bool) -> App {
    fovea_harness::sim::control::set_thread_config(None);
    let mut exts = vec![vulkan_ext];
    if foveation {
        exts.extend(FOVEATION_VULKAN);
    }
    App::new(Chain::fovea().unwrap(), &exts, API_1_0).unwrap()
}

/// A host-visible buffer and a command buffer to read density images back with.
struct Readback {
    pool: vk::CommandPool,
    cb: vk::CommandBuffer,
    buffer: vk::Buffer,
    memory: vk::DeviceMemory,
    size: u64,
}

impl Readback {
    fn new(v: &Vulkan, size: u64) -> Readback {
        let d = &v.device;
        unsafe {
            let pool = resettable_pool(d, v.family);
            let cb = allocate(d, pool);
            let buffer = d
                .create_buffer(
                    &vk::BufferCreateInfo::default()
                        .size(size)
                        .usage(vk::BufferUsageFlags::TRANSFER_DST),
                    None,
                )
                .unwrap();
            let req = d.get_buffer_memory_requirements(buffer);
            let wanted =
                vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
            let types = v
                .instance
                .get_physical_device_memory_properties(v.physical_device);
            let index = (0..types.memory_type_count)
                .find(|i| {
                    req.memory_type_bits & (1 << i) != 0
                        && types.memory_types[*i as usize]
                            .property_flags
                            .contains(wanted)
                })
                .unwrap();
            let memory = d
                .allocate_memory(
                    &vk::MemoryAllocateInfo::default()
                        .allocation_size(req.size)
                        .memory_type_index(index),
                    None,
                )
                .unwrap();
            d.bind_buffer_memory(buffer, memory, 0).unwrap();
            Readback {
                pool,
                cb,
                buffer,
                memory,
                size,
            }
        }
    }

    /// Copies every layer of `image` (R8G8, `extent` texels, `layers` layers, left by fovea in
    /// SHADER_READ_ONLY_OPTIMAL) into the buffer, restores its layout, and returns the bytes.
    fn read(&self, v: &Vulkan, image: u64, extent: [u32; 2], layers: u32) -> Vec<u8> {
        let d = &v.device;
        let image = vk::Image::from_raw(image);
        let range = vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: 0,
            layer_count: layers,
        };
        let to_src = vk::ImageMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_READ)
            .dst_access_mask(vk::AccessFlags::TRANSFER_READ)
            .old_layout(vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL)
            .new_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(image)
            .subresource_range(range);
        let back = to_src
            .src_access_mask(vk::AccessFlags::TRANSFER_READ)
            .dst_access_mask(vk::AccessFlags::SHADER_READ)
            .old_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL)
            .new_layout(vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL);
        let region = vk::BufferImageCopy {
            buffer_offset: 0,
            buffer_row_length: 0,
            buffer_image_height: 0,
            image_subresource: vk::ImageSubresourceLayers {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                mip_level: 0,
                base_array_layer: 0,
                layer_count: layers,
            },
            image_offset: vk::Offset3D::default(),
            image_extent: vk::Extent3D {
                width: extent[0],
                height: extent[1],
                depth: 1,
            },
        };
        let bytes = (extent[0] * extent[1] * 2 * layers) as usize;
        assert!(bytes as u64 <= self.size);
        unsafe {
            d.begin_command_buffer(self.cb, &vk::CommandBufferBeginInfo::default())
                .unwrap();
            d.cmd_pipeline_barrier(
                self.cb,
                vk::PipelineStageFlags::FRAGMENT_SHADER,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[to_src],
            );
            d.cmd_copy_image_to_buffer(
                self.cb,
                image,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                self.buffer,
                &[region],
            );
            let host = vk::BufferMemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .dst_access_mask(vk::AccessFlags::HOST_READ)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .buffer(self.buffer)
                .offset(0)
                .size(vk::WHOLE_SIZE);
            d.cmd_pipeline_barrier(
                self.cb,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::HOST | vk::PipelineStageFlags::FRAGMENT_SHADER,
                vk::DependencyFlags::empty(),
                &[],
                &[host],
                &[back],
            );
            d.end_command_buffer(self.cb).unwrap();
            let queue = d.get_device_queue(v.family, 0);
            let cbs = [self.cb];
            d.queue_submit(
                queue,
                &[vk::SubmitInfo::default().command_buffers(&cbs)],
                vk::Fence::null(),
            )
            .unwrap();
            d.queue_wait_idle(queue).unwrap();
            let p = d
                .map_memory(self.memory, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())
                .unwrap() as *const u8;
            let out = std::slice::from_raw_parts(p, bytes).to_vec();
            d.unmap_memory(self.memory);
            out
        }
    }

    /// Overwrites every layer of `image` with one R8G8 value, as an application may (the images
    /// have TRANSFER_DST usage), leaving it in SHADER_READ_ONLY_OPTIMAL.
    fn clear(&self, v: &Vulkan, image: u64, layers: u32, value: [u8; 2]) {
        let d = &v.device;
        let range = vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: 0,
            layer_count: layers,
        };
        let to_dst = vk::ImageMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_READ)
            .dst_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .old_layout(vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL)
            .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(vk::Image::from_raw(image))
            .subresource_range(range);
        let back = to_dst
            .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::SHADER_READ)
            .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
            .new_layout(vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL);
        let color = vk::ClearColorValue {
            float32: [
                f32::from(value[0]) / 255.0,
                f32::from(value[1]) / 255.0,
                0.0,
                0.0,
            ],
        };
        unsafe {
            d.begin_command_buffer(self.cb, &vk::CommandBufferBeginInfo::default())
                .unwrap();
            d.cmd_pipeline_barrier(
                self.cb,
                vk::PipelineStageFlags::FRAGMENT_SHADER,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[to_dst],
            );
            d.cmd_clear_color_image(
                self.cb,
                vk::Image::from_raw(image),
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &color,
                &[range],
            );
            d.cmd_pipeline_barrier(
                self.cb,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::FRAGMENT_SHADER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[back],
            );
            d.end_command_buffer(self.cb).unwrap();
            let queue = d.get_device_queue(v.family, 0);
            let cbs = [self.cb];
            d.queue_submit(
                queue,
                &[vk::SubmitInfo::default().command_buffers(&cbs)],
                vk::Fence::null(),
            )
            .unwrap();
            d.queue_wait_idle(queue).unwrap();
        }
    }

    fn destroy(self, v: &Vulkan) {
        unsafe {
            v.device.destroy_buffer(self.buffer, None);
            v.device.free_memory(self.memory, None);
            v.device.destroy_command_pool(self.pool, None);
        }
    }
}

pub(crate) fn fov_of(v: &xr::View) -> Fov {
    Fov {
        left: v.fov.angle_left,
        right: v.fov.angle_right,
        up: v.fov.angle_up,
        down: v.fov.angle_down,
    }
}

/// A view of `fov` over the whole `WIDTH`×`HEIGHT` image, every pixel visible.
pub(crate) fn whole_view(fov: Fov) -> View {
    View {
        fov,
        rect: Rect {
            x: 0,
            y: 0,
            width: WIDTH,
            height: HEIGHT,
        },
        visible: None,
    }
}

/// What the density model gives for one layer of a WIDTH×HEIGHT swapchain drawn with `fov`.
fn model(fov: Fov, pattern: Pattern) -> Vec<u8> {
    let grid = Grid::new([WIDTH, HEIGHT], TEXEL);
    let [mw, mh] = grid.map_extent();
    let mut out = vec![0u8; (mw * mh * 2) as usize];
    density::fill(&grid, &[whole_view(fov)], pattern, &mut out);
    out
}

pub(crate) fn swapchain_info(next: *const c_void) -> xr::SwapchainCreateInfo {
    xr::SwapchainCreateInfo {
        ty: xr::StructureType::SWAPCHAIN_CREATE_INFO,
        next,
        create_flags: xr::SwapchainCreateFlags::EMPTY,
        usage_flags: xr::SwapchainUsageFlags::COLOR_ATTACHMENT | xr::SwapchainUsageFlags::SAMPLED,
        format: SRGB,
        sample_count: 1,
        width: WIDTH,
        height: HEIGHT,
        face_count: 1,
        array_size: 2,
        mip_count: 1,
    }
}

/// The chain that asks for a swapchain with density images (XR_FB_foveation_vulkan).
pub(crate) fn fdm_flag() -> xr::SwapchainCreateInfoFoveationFB {
    xr::SwapchainCreateInfoFoveationFB {
        ty: xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
        next: null_mut(),
        flags: xr::SwapchainCreateFoveationFlagsFB::from_raw(FDM_BIT),
    }
}

/// A [`swapchain_info`] swapchain of `layers` layers with density images, created on `session`.
pub(crate) fn fdm_swapchain(app: &App, session: xr::Session, layers: u32) -> xr::Swapchain {
    let create_swapchain: xr::pfn::CreateSwapchain = func(app, "xrCreateSwapchain");
    let flag = fdm_flag();
    let info = xr::SwapchainCreateInfo {
        array_size: layers,
        ..swapchain_info(&flag as *const _ as *const c_void)
    };
    let mut swapchain = xr::Swapchain::NULL;
    // SAFETY: the create info, its chain and the output live across the call.
    let r = unsafe { create_swapchain(session, &info, &mut swapchain) };
    assert_eq!(r, xr::Result::SUCCESS);
    swapchain
}

fn foveation_image() -> xr::SwapchainImageFoveationVulkanFB {
    xr::SwapchainImageFoveationVulkanFB {
        ty: xr::StructureType::SWAPCHAIN_IMAGE_FOVEATION_VULKAN_FB,
        next: null_mut(),
        image: 0,
        width: 0,
        height: 0,
    }
}

/// Enumerates a swapchain's images with an XrSwapchainImageFoveationVulkanFB chained on each element,
/// through the two-call idiom.
pub(crate) fn enumerate(
    app: &App,
    swapchain: xr::Swapchain,
) -> Vec<xr::SwapchainImageFoveationVulkanFB> {
    let images_fn: xr::pfn::EnumerateSwapchainImages = func(app, "xrEnumerateSwapchainImages");
    let mut count = 0;
    assert_eq!(
        unsafe { images_fn(swapchain, 0, &mut count, null_mut()) },
        xr::Result::SUCCESS
    );
    assert_eq!(count, 3);
    let mut fov = vec![foveation_image(); count as usize];
    let mut images: Vec<xr::SwapchainImageVulkanKHR> = fov
        .iter_mut()
        .map(|f| xr::SwapchainImageVulkanKHR {
            ty: xr::StructureType::SWAPCHAIN_IMAGE_VULKAN_KHR,
            next: f as *mut _ as *mut c_void,
            image: 0,
        })
        .collect();
    // Too small a capacity: the runtime's error, nothing written.
    assert_eq!(
        unsafe {
            images_fn(
                swapchain,
                1,
                &mut count,
                images.as_mut_ptr() as *mut xr::SwapchainImageBaseHeader,
            )
        },
        xr::Result::ERROR_SIZE_INSUFFICIENT
    );
    assert_eq!(images[0].image, 0);
    let r = unsafe {
        images_fn(
            swapchain,
            count,
            &mut count,
            images.as_mut_ptr() as *mut xr::SwapchainImageBaseHeader,
        )
    };
    assert_eq!(r, xr::Result::SUCCESS);
    for (i, (img, f)) in images.iter().zip(&fov).enumerate() {
        assert_ne!(img.image, 0, "runtime image {i}");
        // type and next are the application's own, untouched.
        assert_eq!(f.ty, xr::StructureType::SWAPCHAIN_IMAGE_FOVEATION_VULKAN_FB);
        assert!(f.next.is_null());
        assert_eq!(img.next, &fov[i] as *const _ as *mut c_void);
    }
    fov
}

/// One frame that acquires, checks and releases one image of `swapchain`: returns its index.
pub(crate) struct Frame<'a> {
    pub(crate) app: &'a App,
    pub(crate) session: xr::Session,
    pub(crate) space: xr::Space,
}

impl Frame<'_> {
    /// Waits and begins a frame, locates the views, acquires an image and returns (index, FOVs).
    pub(crate) fn acquire(&self, swapchain: xr::Swapchain) -> (u32, [Fov; 2], xr::Time) {
        let wait_frame: xr::pfn::WaitFrame = func(self.app, "xrWaitFrame");
        let begin_frame: xr::pfn::BeginFrame = func(self.app, "xrBeginFrame");
        let locate: xr::pfn::LocateViews = func(self.app, "xrLocateViews");
        let acquire: xr::pfn::AcquireSwapchainImage = func(self.app, "xrAcquireSwapchainImage");
        let wait: xr::pfn::WaitSwapchainImage = func(self.app, "xrWaitSwapchainImage");
        let mut state = xr::FrameState {
            ty: xr::StructureType::FRAME_STATE,
            next: null_mut(),
            predicted_display_time: xr::Time::from_nanos(0),
            predicted_display_period: xr::Duration::from_nanos(0),
            should_render: xr::FALSE,
        };
        let begin = xr::FrameBeginInfo {
            ty: xr::StructureType::FRAME_BEGIN_INFO,
            next: null(),
        };
        let info = xr::ViewLocateInfo {
            ty: xr::StructureType::VIEW_LOCATE_INFO,
            next: null(),
            view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
            display_time: xr::Time::from_nanos(0),
            space: self.space,
        };
        let mut view_state = xr::ViewState {
            ty: xr::StructureType::VIEW_STATE,
            next: null_mut(),
            view_state_flags: xr::ViewStateFlags::EMPTY,
        };
        let empty_view = xr::View {
            ty: xr::StructureType::VIEW,
            next: null_mut(),
            pose: xr::Posef::IDENTITY,
            fov: xr::Fovf::default(),
        };
        let mut views = [empty_view; 2];
        let mut n = 0;
        let wi = xr::SwapchainImageWaitInfo {
            ty: xr::StructureType::SWAPCHAIN_IMAGE_WAIT_INFO,
            next: null(),
            timeout: xr::Duration::INFINITE,
        };
        let mut index = u32::MAX;
        unsafe {
            assert_eq!(
                wait_frame(self.session, null(), &mut state),
                xr::Result::SUCCESS
            );
            assert_eq!(begin_frame(self.session, &begin), xr::Result::SUCCESS);
            let info = xr::ViewLocateInfo {
                display_time: state.predicted_display_time,
                ..info
            };
            assert_eq!(
                locate(
                    self.session,
                    &info,
                    &mut view_state,
                    2,
                    &mut n,
                    views.as_mut_ptr()
                ),
                xr::Result::SUCCESS
            );
            assert_eq!(acquire(swapchain, null(), &mut index), xr::Result::SUCCESS);
            assert_eq!(wait(swapchain, &wi), xr::Result::SUCCESS);
        }
        (
            index,
            [fov_of(&views[0]), fov_of(&views[1])],
            state.predicted_display_time,
        )
    }

    pub(crate) fn release(&self, swapchain: xr::Swapchain, time: xr::Time) {
        let release: xr::pfn::ReleaseSwapchainImage = func(self.app, "xrReleaseSwapchainImage");
        let end_frame: xr::pfn::EndFrame = func(self.app, "xrEndFrame");
        let end = xr::FrameEndInfo {
            ty: xr::StructureType::FRAME_END_INFO,
            next: null(),
            display_time: time,
            environment_blend_mode: xr::EnvironmentBlendMode::OPAQUE,
            layer_count: 0,
            layers: null(),
        };
        unsafe {
            assert_eq!(release(swapchain, null()), xr::Result::SUCCESS);
            assert_eq!(end_frame(self.session, &end), xr::Result::SUCCESS);
        }
    }
}

/// A Vulkan session on the application's device, begun, with a LOCAL space.
pub(crate) fn running_session(
    app: &App,
    sys: xr::SystemId,
    v: &Vulkan,
) -> (xr::Session, xr::Space) {
    let binding = v.binding();
    let create_session: xr::pfn::CreateSession = func(app, "xrCreateSession");
    let session_info = xr::SessionCreateInfo {
        ty: xr::StructureType::SESSION_CREATE_INFO,
        next: &binding as *const _ as *const c_void,
        create_flags: xr::SessionCreateFlags::EMPTY,
        system_id: sys,
    };
    let mut session = xr::Session::NULL;
    assert_eq!(
        unsafe { create_session(app.instance, &session_info, &mut session) },
        xr::Result::SUCCESS
    );
    let begin_session: xr::pfn::BeginSession = func(app, "xrBeginSession");
    let begin_info = xr::SessionBeginInfo {
        ty: xr::StructureType::SESSION_BEGIN_INFO,
        next: null(),
        primary_view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
    };
    assert_eq!(
        unsafe { begin_session(session, &begin_info) },
        xr::Result::SUCCESS
    );
    let create_space: xr::pfn::CreateReferenceSpace = func(app, "xrCreateReferenceSpace");
    let space_info = xr::ReferenceSpaceCreateInfo {
        ty: xr::StructureType::REFERENCE_SPACE_CREATE_INFO,
        next: null(),
        reference_space_type: xr::ReferenceSpaceType::LOCAL,
        pose_in_reference_space: xr::Posef::IDENTITY,
    };
    let mut space = xr::Space::NULL;
    assert_eq!(
        unsafe { create_space(session, &space_info, &mut space) },
        xr::Result::SUCCESS
    );

    (session, space)
}

/// The left eye's FOV as the runtime reports it (one frame, nothing acquired).
fn frame_fovs(frame: &Frame) -> Fov {
    let locate: xr::pfn::LocateViews = func(frame.app, "xrLocateViews");
    let info = xr::ViewLocateInfo {
        ty: xr::StructureType::VIEW_LOCATE_INFO,
        next: null(),
        view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
        display_time: xr::Time::from_nanos(1),
        space: frame.space,
    };
    let mut view_state = xr::ViewState {
        ty: xr::StructureType::VIEW_STATE,
        next: null_mut(),
        view_state_flags: xr::ViewStateFlags::EMPTY,
    };
    let mut views = [xr::View {
        ty: xr::StructureType::VIEW,
        next: null_mut(),
        pose: xr::Posef::IDENTITY,
        fov: xr::Fovf::default(),
    }; 2];
    let mut n = 0;
    let r = unsafe {
        locate(
            frame.session,
            &info,
            &mut view_state,
            2,
            &mut n,
            views.as_mut_ptr(),
        )
    };
    assert_eq!(r, xr::Result::SUCCESS);
    fov_of(&views[0])
}

#[test]
fn density_images_on_lavapipe_hold_the_model_and_leave_nothing_behind() {
    let _serial = VALIDATED.lock();
    pick_lavapipe();
    let app = app("XR_KHR_vulkan_enable2", true);
    let sys = app.system();
    let Some(v) = vulkan_through_xr(&app, sys) else {
        return;
    };

    let (session, space) = running_session(&app, sys, &v);
    // The log file (the suite's private XDG_STATE_HOME) says which GPU the session's density
    // images are on and how they reach the rasterizer.
    let log = std::path::Path::new(&std::env::var_os("XDG_STATE_HOME").expect("private home"))
        .join("fovea/fovea.log");
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(
        text.lines()
            .any(|l| l.contains("fovea session: gpu=\"llvmpipe")
                && l.contains("density_maps=\"not attached by this device")),
        "no session line for lavapipe in {}:\n{text}",
        log.display()
    );

    // A foveated swapchain with the FRAGMENT_DENSITY_MAP flag, and one without the flag.
    let create_swapchain: xr::pfn::CreateSwapchain = func(&app, "xrCreateSwapchain");
    let fdm_flag = fdm_flag();
    let no_flag = xr::SwapchainCreateInfoFoveationFB {
        flags: xr::SwapchainCreateFoveationFlagsFB::EMPTY,
        ..fdm_flag
    };
    let mut swapchain = xr::Swapchain::NULL;
    let mut plain = xr::Swapchain::NULL;
    unsafe {
        assert_eq!(
            create_swapchain(
                session,
                &swapchain_info(&fdm_flag as *const _ as *const c_void),
                &mut swapchain
            ),
            xr::Result::SUCCESS
        );
        assert_eq!(
            create_swapchain(
                session,
                &swapchain_info(&no_flag as *const _ as *const c_void),
                &mut plain
            ),
            xr::Result::SUCCESS
        );
    }

    let density_images = enumerate(&app, swapchain);
    let extent = [WIDTH.div_ceil(TEXEL[0]), HEIGHT.div_ceil(TEXEL[1])];
    assert_eq!(extent, [20, 16]);
    for (i, d) in density_images.iter().enumerate() {
        assert_ne!(d.image, 0, "density image {i}");
        assert_eq!([d.width, d.height], extent, "density image {i}");
        assert!(density_images[..i].iter().all(|o| o.image != d.image));
    }
    for d in enumerate(&app, plain) {
        assert_eq!(
            (d.image, d.width, d.height),
            (0, 0, 0),
            "no FDM flag, no density image"
        );
    }

    let layer_bytes = (extent[0] * extent[1] * 2) as usize;
    let readback = Readback::new(&v, (layer_bytes * 2) as u64);
    let create_profile: xr::pfn::CreateFoveationProfileFB =
        func(&app, "xrCreateFoveationProfileFB");
    let destroy_profile: xr::pfn::DestroyFoveationProfileFB =
        func(&app, "xrDestroyFoveationProfileFB");
    let update: xr::pfn::UpdateSwapchainFB = func(&app, "xrUpdateSwapchainFB");
    let frame = Frame {
        app: &app,
        session,
        space,
    };
    let check = |pattern: Pattern, what: &str| {
        // Every image of the swapchain, each acquired once.
        for _ in 0..3 {
            let (index, fovs, time) = frame.acquire(swapchain);
            let got = readback.read(&v, density_images[index as usize].image, extent, 2);
            for (layer, fov) in fovs.into_iter().enumerate() {
                let want = model(fov, pattern);
                let have = &got[layer * layer_bytes..(layer + 1) * layer_bytes];
                assert!(
                    have == want.as_slice(),
                    "{what}: image {index} layer {layer} differs from the model"
                );
            }
            frame.release(swapchain, time);
        }
    };

    // Before any profile: no foveation (every texel full rate).
    let none = Pattern {
        level: Level::None,
        vertical_offset_deg: 0.0,
    };
    check(none, "before any update");
    let mut live_profile = xr::FoveationProfileFB::NULL;
    for level in 0..=3 {
        let offset = if level == 3 { -7.5 } else { 0.0 };
        let li = level_info(level, 0, offset);
        let info = xr::FoveationProfileCreateInfoFB {
            ty: xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
            next: &li as *const _ as *mut c_void,
        };
        let mut profile = xr::FoveationProfileFB::NULL;
        let st = |profile| xr::SwapchainStateFoveationFB {
            ty: xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB,
            next: null_mut(),
            flags: xr::SwapchainStateFoveationFlagsFB::EMPTY,
            profile,
        };
        unsafe {
            assert_eq!(
                create_profile(session, &info, &mut profile),
                xr::Result::SUCCESS
            );
            let state = st(profile);
            assert_eq!(
                update(swapchain, &state as *const _ as *const _),
                xr::Result::SUCCESS
            );
        }
        let pattern = Pattern {
            level: Level::from_index(level as u32).unwrap(),
            vertical_offset_deg: offset,
        };
        if level > 0 {
            // The comparison below is not vacuous: foveation changes the map on this swapchain.
            let f = frame_fovs(&frame);
            assert_ne!(model(f, pattern), model(f, none), "level {level}");
        }
        if level == 2 {
            // Destroying the profile after the update changes nothing (fb_foveation.adoc).
            assert_eq!(unsafe { destroy_profile(profile) }, xr::Result::SUCCESS);
        }
        check(pattern, &format!("level {level}"));
        if level == 3 {
            live_profile = profile;
            // Nothing changed since: an acquire leaves the images alone. The application overwrites
            // them with a marker, and the marker is what it reads back after the next acquires.
            let marker = [7u8, 9];
            for d in &density_images {
                readback.clear(&v, d.image, 2, marker);
            }
            for _ in 0..3 {
                let (index, _, time) = frame.acquire(swapchain);
                let got = readback.read(&v, density_images[index as usize].image, extent, 2);
                assert!(
                    got.chunks_exact(2).all(|t| t == marker),
                    "image {index} was re-uploaded although nothing changed"
                );
                frame.release(swapchain, time);
            }
            // A new update (same profile) makes them dirty again: the model is back.
            let state = xr::SwapchainStateFoveationFB {
                ty: xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB,
                next: null_mut(),
                flags: xr::SwapchainStateFoveationFlagsFB::EMPTY,
                profile,
            };
            assert_eq!(
                unsafe { update(swapchain, &state as *const _ as *const _) },
                xr::Result::SUCCESS
            );
            check(pattern, "level 3 after a second update");
        } else if level != 2 {
            assert_eq!(unsafe { destroy_profile(profile) }, xr::Result::SUCCESS);
        }
    }
    assert_ne!(live_profile, xr::FoveationProfileFB::NULL);

    // The session goes with a live profile and two live swapchains: fovea destroys its images,
    // buffers, command buffers, pool and fence before the runtime sees the call.
    let destroy_session: xr::pfn::DestroySession = func(&app, "xrDestroySession");
    assert_eq!(unsafe { destroy_session(session) }, xr::Result::SUCCESS);
    assert_eq!(
        unsafe { destroy_profile(live_profile) },
        xr::Result::ERROR_HANDLE_INVALID
    );
    readback.destroy(&v);
    teardown(app, v);
}

/// Destroys the device (the validation layer reports every object still alive on it here), the
/// OpenXR instance and the Vulkan instance, and requires that validation said nothing.
fn teardown(app: App, v: Vulkan) {
    // SAFETY: the test is done with the device; the instance goes after it.
    unsafe { v.destroy_device() };
    assert_eq!(app.destroy(), xr::Result::SUCCESS);
    unsafe { v.destroy_instance() };
    assert_no_messages();
}

#[test]
fn instance_destruction_takes_live_sessions_density_images_with_it() {
    let _serial = VALIDATED.lock();
    pick_lavapipe();
    let app = app("XR_KHR_vulkan_enable2", true);
    let sys = app.system();
    let Some(v) = vulkan_through_xr(&app, sys) else {
        return;
    };
    let (session, space) = running_session(&app, sys, &v);
    let swapchain = fdm_swapchain(&app, session, 2);
    let frame = Frame {
        app: &app,
        session,
        space,
    };
    let (_, _, time) = frame.acquire(swapchain);
    frame.release(swapchain, time);
    // Neither the swapchain nor the session is destroyed: xrDestroyInstance takes them along.
    assert_eq!(app.destroy(), xr::Result::SUCCESS);
    v.destroy();
    assert_no_messages();
}

/// xrGetVulkanDeviceExtensionsKHR through the two-call idiom: (result, count, string).
fn device_extensions(app: &App, sys: xr::SystemId, capacity: u32) -> (xr::Result, u32, String) {
    let f: xr::pfn::GetVulkanDeviceExtensionsKHR = func(app, "xrGetVulkanDeviceExtensionsKHR");
    let mut buf = vec![b'#' as std::ffi::c_char; capacity as usize];
    let mut count = 0;
    let ptr = if capacity == 0 {
        null_mut()
    } else {
        buf.as_mut_ptr()
    };
    let r = unsafe { f(app.instance, sys, capacity, &mut count, ptr) };
    let s = if r == xr::Result::SUCCESS && capacity > 0 {
        unsafe { CStr::from_ptr(buf.as_ptr()) }
            .to_string_lossy()
            .into_owned()
    } else {
        String::new()
    };
    (r, count, s)
}

#[test]
fn vulkan_enable_device_extensions_gain_fdm_where_it_can_be_had() {
    pick_lavapipe();
    const RUNTIME: &str = "VK_KHR_external_memory";
    const WITH_FDM: &str = "VK_KHR_external_memory VK_EXT_fragment_density_map";

    // Without XR_FB_foveation_vulkan the runtime's list goes through untouched.
    let plain = app("XR_KHR_vulkan_enable", false);
    let sys = plain.system();
    let n = RUNTIME.len() as u32 + 1;
    assert_eq!(
        device_extensions(&plain, sys, 64),
        (xr::Result::SUCCESS, n, RUNTIME.into())
    );
    drop(plain);

    // With it, before the application said which device it uses: VK_EXT_fragment_density_map is
    // appended, with the counts (NUL included) and the size errors of the two-call idiom.
    let fov = app("XR_KHR_vulkan_enable", true);
    let sys = fov.system();
    let n = WITH_FDM.len() as u32 + 1;
    assert_eq!(
        device_extensions(&fov, sys, 0),
        (xr::Result::SUCCESS, n, String::new())
    );
    assert_eq!(
        device_extensions(&fov, sys, n - 1),
        (xr::Result::ERROR_SIZE_INSUFFICIENT, n, String::new())
    );
    assert_eq!(
        device_extensions(&fov, sys, 1),
        (xr::Result::ERROR_SIZE_INSUFFICIENT, n, String::new())
    );
    assert_eq!(
        device_extensions(&fov, sys, n),
        (xr::Result::SUCCESS, n, WITH_FDM.into())
    );
    assert_eq!(
        device_extensions(&fov, sys, n + 10),
        (xr::Result::SUCCESS, n, WITH_FDM.into())
    );
    let f: xr::pfn::GetVulkanDeviceExtensionsKHR = func(&fov, "xrGetVulkanDeviceExtensionsKHR");
    let mut count = 0;
    assert_eq!(
        unsafe { f(fov.instance, sys, 8, &mut count, null_mut()) },
        xr::Result::ERROR_VALIDATION_FAILURE,
        "a capacity without a buffer"
    );
    // The runtime's own errors come back as they are.
    assert_eq!(
        device_extensions(&fov, xr::SystemId::from_raw(0xbad), 0).0,
        xr::Result::ERROR_SYSTEM_INVALID
    );

    // Once the physical device is known, only what it supports: lavapipe has no FDM.
    let Ok(entry) = vulkan::entry().map_err(|why| skip(&why)) else {
        return;
    };
    let app_info = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_1);
    let instance = unsafe {
        entry.create_instance(
            &vk::InstanceCreateInfo::default().application_info(&app_info),
            None,
        )
    }
    .unwrap();
    let graphics_device: xr::pfn::GetVulkanGraphicsDeviceKHR =
        func(&fov, "xrGetVulkanGraphicsDeviceKHR");
    let mut pd: xr::platform::VkPhysicalDevice = null();
    let r = unsafe {
        graphics_device(
            fov.instance,
            sys,
            instance.handle().as_raw() as usize as xr::platform::VkInstance,
            &mut pd,
        )
    };
    if r != xr::Result::SUCCESS {
        unsafe { instance.destroy_instance(None) };
        skip("lavapipe (llvmpipe) is not available");
        return;
    }
    let name = unsafe {
        let props =
            instance.get_physical_device_properties(vk::PhysicalDevice::from_raw(pd as u64));
        CStr::from_ptr(props.device_name.as_ptr())
            .to_string_lossy()
            .into_owned()
    };
    assert!(name.contains("llvmpipe"), "{name}");
    let n = RUNTIME.len() as u32 + 1;
    assert_eq!(
        device_extensions(&fov, sys, 0),
        (xr::Result::SUCCESS, n, String::new())
    );
    assert_eq!(
        device_extensions(&fov, sys, n),
        (xr::Result::SUCCESS, n, RUNTIME.into())
    );
    assert_eq!(fov.destroy(), xr::Result::SUCCESS);
    unsafe { instance.destroy_instance(None) };
}

/// Releases the image and ends the frame with one projection layer whose two views are drawn
/// side by side into array layer 0 of `swapchain` (a double-wide layout).
fn release_side_by_side(frame: &Frame, swapchain: xr::Swapchain, time: xr::Time, fovs: [Fov; 2]) {
    let release: xr::pfn::ReleaseSwapchainImage = func(frame.app, "xrReleaseSwapchainImage");
    let end_frame: xr::pfn::EndFrame = func(frame.app, "xrEndFrame");
    let half = (WIDTH / 2) as i32;
    let view = |eye: usize| xr::CompositionLayerProjectionView {
        ty: xr::StructureType::COMPOSITION_LAYER_PROJECTION_VIEW,
        next: null(),
        pose: xr::Posef::IDENTITY,
        fov: xr::Fovf {
            angle_left: fovs[eye].left,
            angle_right: fovs[eye].right,
            angle_up: fovs[eye].up,
            angle_down: fovs[eye].down,
        },
        sub_image: xr::SwapchainSubImage {
            swapchain,
            image_rect: xr::Rect2Di {
                offset: xr::Offset2Di {
                    x: half * eye as i32,
                    y: 0,
                },
                extent: xr::Extent2Di {
                    width: half,
                    height: HEIGHT as i32,
                },
            },
            image_array_index: 0,
        },
    };
    let views = [view(0), view(1)];
    let layer = xr::CompositionLayerProjection {
        ty: xr::StructureType::COMPOSITION_LAYER_PROJECTION,
        next: null(),
        layer_flags: xr::CompositionLayerFlags::EMPTY,
        space: frame.space,
        view_count: 2,
        views: views.as_ptr(),
    };
    let layers = [&layer as *const _ as *const xr::CompositionLayerBaseHeader];
    let end = xr::FrameEndInfo {
        ty: xr::StructureType::FRAME_END_INFO,
        next: null(),
        display_time: time,
        environment_blend_mode: xr::EnvironmentBlendMode::OPAQUE,
        layer_count: 1,
        layers: layers.as_ptr(),
    };
    unsafe {
        assert_eq!(release(swapchain, null()), xr::Result::SUCCESS);
        assert_eq!(end_frame(frame.session, &end), xr::Result::SUCCESS);
    }
}

/// Maps follow what the application submits: once both eyes are drawn side by side into layer 0,
/// every image's layer 0 holds both views' maps in their own halves and layer 1, which nothing
/// is drawn into, the lowest density.
#[test]
fn submitted_views_decide_what_each_layer_holds() {
    let _serial = VALIDATED.lock();
    pick_lavapipe();
    let app = app("XR_KHR_vulkan_enable2", true);
    let sys = app.system();
    let Some(v) = vulkan_through_xr(&app, sys) else {
        return;
    };
    let (session, space) = running_session(&app, sys, &v);
    let swapchain = fdm_swapchain(&app, session, 2);
    let images = enumerate(&app, swapchain);
    let create_profile: xr::pfn::CreateFoveationProfileFB =
        func(&app, "xrCreateFoveationProfileFB");
    let update: xr::pfn::UpdateSwapchainFB = func(&app, "xrUpdateSwapchainFB");
    let level = level_info(3, 0, 0.0);
    let profile_info = xr::FoveationProfileCreateInfoFB {
        ty: xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
        next: &level as *const _ as *mut c_void,
    };
    let mut profile = xr::FoveationProfileFB::NULL;
    unsafe {
        assert_eq!(
            create_profile(session, &profile_info, &mut profile),
            xr::Result::SUCCESS
        );
        let state = xr::SwapchainStateFoveationFB {
            ty: xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB,
            next: null_mut(),
            flags: xr::SwapchainStateFoveationFlagsFB::EMPTY,
            profile,
        };
        assert_eq!(
            update(swapchain, &state as *const _ as *const _),
            xr::Result::SUCCESS
        );
    }
    let frame = Frame {
        app: &app,
        session,
        space,
    };
    let (_, fovs, time) = frame.acquire(swapchain);
    release_side_by_side(&frame, swapchain, time, fovs);

    let grid = Grid::new([WIDTH, HEIGHT], TEXEL);
    let [mw, mh] = grid.map_extent();
    let layer_bytes = (mw * mh * 2) as usize;
    let pattern = Pattern {
        level: fovea_model::density::Level::High,
        vertical_offset_deg: 0.0,
    };
    let half = |eye: usize| View {
        fov: fovs[eye],
        rect: Rect {
            x: (WIDTH / 2 * eye as u32) as i32,
            y: 0,
            width: WIDTH / 2,
            height: HEIGHT,
        },
        visible: None,
    };
    let mut want0 = vec![0u8; layer_bytes];
    density::fill(&grid, &[half(0), half(1)], pattern, &mut want0);
    let mut want1 = vec![0u8; layer_bytes];
    density::fill(&grid, &[], pattern, &mut want1);
    assert_ne!(want0, model(fovs[0], pattern), "the layout changes the map");
    let readback = Readback::new(&v, (layer_bytes * 2) as u64);
    for _ in 0..images.len() {
        let (index, fovs, time) = frame.acquire(swapchain);
        let got = readback.read(&v, images[index as usize].image, [mw, mh], 2);
        assert!(got[..layer_bytes] == want0[..], "image {index} layer 0");
        assert!(got[layer_bytes..] == want1[..], "image {index} layer 1");
        release_side_by_side(&frame, swapchain, time, fovs);
    }

    let destroy_session: xr::pfn::DestroySession = func(&app, "xrDestroySession");
    assert_eq!(unsafe { destroy_session(session) }, xr::Result::SUCCESS);
    readback.destroy(&v);
    teardown(app, v);
}
