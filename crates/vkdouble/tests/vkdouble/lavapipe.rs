//! The double on lavapipe, under the Khronos validation layer: what it advertises per profile,
//! draws through a render pass and through dynamic rendering with a shading-rate attachment (real
//! pixels read back), what it recorded, and that misuse is recorded.
//!
//! Stack: this test → VK_LAYER_KHRONOS_validation → VK_LAYER_FOVEA_shading_rate_double → lavapipe.
//! The manifest is written to a temporary folder named by `VK_ADD_LAYER_PATH` (Debian's loader
//! 1.3.239 has it; `VK_LAYER_PATH` would replace the system folders and hide the validation
//! layer). Tests here share process-wide state (the environment, the validation messages, the
//! double's records), so they run one at a time.
//!
//! Missing components (loader, lavapipe, validation layer, the built library) skip, or fail under
//! `FOVEA_REQUIRE_SYSTEM=1`.

use std::ffi::{c_void, CStr};
use std::sync::{Mutex, MutexGuard, OnceLock};

use ash::vk;
use ash::vk::Handle as _;
use fovea_vkdouble::{Loaded, Profile, ViewRates, LAYER_NAME};
use serde_json::{json, Value};

use crate::skip;

const VALIDATION: &CStr = c"VK_LAYER_KHRONOS_validation";
const FSR: &CStr = c"VK_KHR_fragment_shading_rate";
const SIZE: u32 = 64;

static SERIAL: Mutex<()> = Mutex::new(());
static MESSAGES: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// Skips (prints why, returns `true`) or, under `FOVEA_REQUIRE_SYSTEM=1`, fails.
unsafe extern "system" fn on_message(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    _user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: the layer passes valid callback data with a NUL-terminated message.
    let text = unsafe { CStr::from_ptr((*data).p_message) }.to_string_lossy();
    if let Ok(mut m) = MESSAGES.lock() {
        m.push(format!("{severity:?}: {text}"));
    }
    vk::FALSE
}

fn take_messages() -> Vec<String> {
    std::mem::take(&mut *MESSAGES.lock().unwrap_or_else(|e| e.into_inner()))
}

struct Env {
    entry: ash::Entry,
    double: Loaded,
}

/// The manifest, `VK_ADD_LAYER_PATH`, the loader and the double's loaded copy; once per process.
fn env() -> Result<(MutexGuard<'static, ()>, &'static Env), String> {
    let guard = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    static ENV: OnceLock<Result<Env, String>> = OnceLock::new();
    let env = ENV.get_or_init(|| {
        let lib = fovea_vkdouble::find_library()?;
        let dir = std::env::temp_dir().join(format!("fovea-vkdouble-{}", std::process::id()));
        fovea_vkdouble::write_manifest(&dir, &lib).map_err(|e| e.to_string())?;
        // Set before the loader first reads the environment (the first Vulkan call below), with
        // every test serialised behind SERIAL.
        std::env::set_var("VK_ADD_LAYER_PATH", &dir);
        // SAFETY: loading libvulkan runs its initialisers, as any Vulkan application does.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| format!("no Vulkan loader ({e})"))?;
        // SAFETY: a plain query.
        let layers = unsafe { entry.enumerate_instance_layer_properties() }
            .map_err(|e| format!("vkEnumerateInstanceLayerProperties: {e}"))?;
        for want in [VALIDATION, LAYER_NAME] {
            if !layers.iter().any(|l| l.layer_name_as_c_str() == Ok(want)) {
                return Err(format!("{want:?} is not available"));
            }
        }
        let double = Loaded::open(&lib)?;
        Ok(Env { entry, double })
    });
    match env {
        Ok(e) => Ok((guard, e)),
        Err(e) => Err(e.clone()),
    }
}

/// An instance with validation above the double, lavapipe's physical device, and (optionally) a
/// device with one graphics queue.
struct Vk {
    instance: ash::Instance,
    debug_utils: ash::ext::debug_utils::Instance,
    messenger: vk::DebugUtilsMessengerEXT,
    physical: vk::PhysicalDevice,
}

impl Vk {
    fn new(env: &Env, profile: Profile) -> Result<Vk, String> {
        env.double.set_profile(Some(profile));
        Self::new_without_override(env)
    }

    /// An instance whose profile comes from `FOVEA_VKDOUBLE_PROFILE` (or the override already set).
    fn new_without_override(env: &Env) -> Result<Vk, String> {
        take_messages();
        let layers = [VALIDATION.as_ptr(), LAYER_NAME.as_ptr()];
        let exts = [
            ash::ext::debug_utils::NAME.as_ptr(),
            ash::ext::validation_features::NAME.as_ptr(),
        ];
        // Without handle wrapping, the double records the handles the application holds.
        let disabled = [vk::ValidationFeatureDisableEXT::UNIQUE_HANDLES];
        // Synchronization validation: hazards between commands and submissions
        // (<https://vulkan.lunarg.com/doc/sdk/latest/linux/synchronization_usage.html>).
        let enabled = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
        let mut features = vk::ValidationFeaturesEXT::default()
            .disabled_validation_features(&disabled)
            .enabled_validation_features(&enabled);
        let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_3);
        let mut messenger_info = vk::DebugUtilsMessengerCreateInfoEXT::default()
            .message_severity(
                vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                    | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
            )
            .message_type(
                vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                    | vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                    | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
            )
            .pfn_user_callback(Some(on_message));
        let info = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layers)
            .enabled_extension_names(&exts)
            .push_next(&mut messenger_info)
            .push_next(&mut features);
        // SAFETY: every struct lives across the calls; handles are used while alive.
        unsafe {
            let instance = env
                .entry
                .create_instance(&info, None)
                .map_err(|e| format!("vkCreateInstance: {e}"))?;
            let debug_utils = ash::ext::debug_utils::Instance::new(&env.entry, &instance);
            let messenger = debug_utils
                .create_debug_utils_messenger(&messenger_info, None)
                .expect("messenger");
            let physical = instance
                .enumerate_physical_devices()
                .unwrap_or_default()
                .into_iter()
                .find(|&p| {
                    let props = instance.get_physical_device_properties(p);
                    props
                        .device_name_as_c_str()
                        .is_ok_and(|n| n.to_string_lossy().contains("llvmpipe"))
                });
            let vk = Vk {
                instance,
                debug_utils,
                messenger,
                physical: physical.unwrap_or_default(),
            };
            if physical.is_none() {
                return Err("lavapipe (llvmpipe) is not installed".into());
            }
            Ok(vk)
        }
    }

    fn fsr_instance(&self, env: &Env) -> ash::khr::fragment_shading_rate::Instance {
        ash::khr::fragment_shading_rate::Instance::new(&env.entry, &self.instance)
    }

    /// A device with one graphics queue; with `fsr`, the extension and the pipeline and attachment
    /// features.
    fn device(&self, fsr: bool) -> Dev {
        // SAFETY: every struct lives across the calls.
        unsafe {
            let family = self
                .instance
                .get_physical_device_queue_family_properties(self.physical)
                .iter()
                .position(|f| f.queue_flags.contains(vk::QueueFlags::GRAPHICS))
                .expect("a graphics queue") as u32;
            let prio = [1.0];
            let queues = [vk::DeviceQueueCreateInfo::default()
                .queue_family_index(family)
                .queue_priorities(&prio)];
            let exts = if fsr { vec![FSR.as_ptr()] } else { vec![] };
            let mut v13 = vk::PhysicalDeviceVulkan13Features::default()
                .dynamic_rendering(true)
                .synchronization2(true);
            let mut v11 = vk::PhysicalDeviceVulkan11Features::default().multiview(true);
            let mut fsr_features = vk::PhysicalDeviceFragmentShadingRateFeaturesKHR::default()
                .pipeline_fragment_shading_rate(true)
                .attachment_fragment_shading_rate(true);
            let mut info = vk::DeviceCreateInfo::default()
                .queue_create_infos(&queues)
                .enabled_extension_names(&exts)
                .push_next(&mut v13)
                .push_next(&mut v11);
            if fsr {
                info = info.push_next(&mut fsr_features);
            }
            let device = self
                .instance
                .create_device(self.physical, &info, None)
                .expect("vkCreateDevice");
            let queue = device.get_device_queue(family, 0);
            let pool = device
                .create_command_pool(
                    &vk::CommandPoolCreateInfo::default().queue_family_index(family),
                    None,
                )
                .expect("pool");
            Dev {
                device,
                queue,
                pool,
                props: self
                    .instance
                    .get_physical_device_memory_properties(self.physical),
            }
        }
    }
}

impl Drop for Vk {
    fn drop(&mut self) {
        // SAFETY: nothing made from the instance outlives it.
        unsafe {
            self.debug_utils
                .destroy_debug_utils_messenger(self.messenger, None);
            self.instance.destroy_instance(None);
        }
    }
}

struct Dev {
    device: ash::Device,
    queue: vk::Queue,
    pool: vk::CommandPool,
    props: vk::PhysicalDeviceMemoryProperties,
}

impl Drop for Dev {
    fn drop(&mut self) {
        // SAFETY: the device is idle; everything made from it was destroyed.
        unsafe {
            let _ = self.device.device_wait_idle();
            self.device.destroy_command_pool(self.pool, None);
            self.device.destroy_device(None);
        }
    }
}

/// Requires that validation said nothing since the last call.
fn assert_no_messages() {
    let m = take_messages();
    assert!(
        m.is_empty(),
        "validation reported {} message(s):\n{}",
        m.len(),
        m.join("\n")
    );
}

/// Runs `f` with the environment and an instance, or skips.
fn with_vk(profile: Profile, f: impl FnOnce(&Env, &Vk)) {
    let (_guard, env) = match env() {
        Ok(e) => e,
        Err(reason) => {
            skip(&reason);
            return;
        }
    };
    env.double.clear();
    let vk = match Vk::new(env, profile) {
        Ok(v) => v,
        Err(reason) => {
            skip(&reason);
            return;
        }
    };
    f(env, &vk);
    drop(vk);
    env.double.set_profile(None);
}

#[test]
fn advertises_per_profile() {
    for profile in [Profile::Nvidia, Profile::Amd] {
        with_vk(profile, |env, vk| {
            let (texel, max, layered) = match profile {
                Profile::Nvidia => (16, 4, vk::TRUE),
                _ => (8, 2, vk::FALSE),
            };
            // SAFETY: every struct lives across the calls.
            unsafe {
                let exts = vk
                    .instance
                    .enumerate_device_extension_properties(vk.physical)
                    .unwrap();
                let fsr_ext = exts
                    .iter()
                    .find(|e| e.extension_name_as_c_str() == Ok(FSR))
                    .expect("VK_KHR_fragment_shading_rate listed");
                assert_eq!(fsr_ext.spec_version, 2);
                assert!(
                    exts.iter()
                        .any(|e| e.extension_name_as_c_str() == Ok(c"VK_KHR_create_renderpass2")),
                    "lavapipe has create_renderpass2 itself"
                );

                // The two-call idiom with a short array.
                let f = vk.instance.fp_v1_0().enumerate_device_extension_properties;
                let mut n = 1;
                let mut one = [vk::ExtensionProperties::default()];
                assert_eq!(
                    f(vk.physical, std::ptr::null(), &mut n, one.as_mut_ptr()),
                    vk::Result::INCOMPLETE
                );
                assert_eq!(n, 1);

                let mut features = vk::PhysicalDeviceFragmentShadingRateFeaturesKHR::default();
                let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut features);
                vk.instance
                    .get_physical_device_features2(vk.physical, &mut f2);
                assert_eq!(
                    (
                        features.pipeline_fragment_shading_rate,
                        features.primitive_fragment_shading_rate,
                        features.attachment_fragment_shading_rate
                    ),
                    (vk::TRUE, vk::FALSE, vk::TRUE)
                );

                let mut p = vk::PhysicalDeviceFragmentShadingRatePropertiesKHR::default();
                let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut p);
                vk.instance
                    .get_physical_device_properties2(vk.physical, &mut p2);
                let t = vk::Extent2D {
                    width: texel,
                    height: texel,
                };
                assert_eq!(p.min_fragment_shading_rate_attachment_texel_size, t);
                assert_eq!(p.max_fragment_shading_rate_attachment_texel_size, t);
                assert_eq!(p.layered_shading_rate_attachments, layered);
                assert_eq!(
                    p.max_fragment_size,
                    vk::Extent2D {
                        width: max,
                        height: max
                    }
                );
                assert_eq!(p.max_fragment_size_aspect_ratio, 2);
                assert_eq!(p.fragment_shading_rate_non_trivial_combiner_ops, vk::TRUE);

                let fsr = vk.fsr_instance(env);
                let get = fsr.fp().get_physical_device_fragment_shading_rates_khr;
                let mut n = 0;
                assert_eq!(
                    get(vk.physical, &mut n, std::ptr::null_mut()),
                    vk::Result::SUCCESS
                );
                let mut rates =
                    vec![vk::PhysicalDeviceFragmentShadingRateKHR::default(); n as usize];
                assert_eq!(
                    get(vk.physical, &mut n, rates.as_mut_ptr()),
                    vk::Result::SUCCESS
                );
                let sizes: Vec<(u32, u32)> = rates
                    .iter()
                    .map(|r| (r.fragment_size.width, r.fragment_size.height))
                    .collect();
                let want: &[(u32, u32)] = match profile {
                    Profile::Nvidia => &[(4, 4), (4, 2), (2, 4), (2, 2), (2, 1), (1, 2), (1, 1)],
                    _ => &[(2, 2), (2, 1), (1, 2), (1, 1)],
                };
                assert_eq!(sizes, want);
                assert_eq!(rates.last().unwrap().sample_counts.as_raw(), !0);
                let mut short = 2;
                assert_eq!(
                    get(vk.physical, &mut short, rates.as_mut_ptr()),
                    vk::Result::INCOMPLETE
                );

                let bit = vk::FormatFeatureFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR;
                let fp = vk
                    .instance
                    .get_physical_device_format_properties(vk.physical, vk::Format::R8_UINT);
                assert!(fp.optimal_tiling_features.contains(bit));
                assert!(!fp.linear_tiling_features.contains(bit));
                let mut f3 = vk::FormatProperties3::default();
                let mut fp2 = vk::FormatProperties2::default().push_next(&mut f3);
                vk.instance.get_physical_device_format_properties2(
                    vk.physical,
                    vk::Format::R8_UINT,
                    &mut fp2,
                );
                assert!(fp2.format_properties.optimal_tiling_features.contains(bit));
                assert!(f3
                    .optimal_tiling_features
                    .contains(vk::FormatFeatureFlags2::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR));
                let other = vk
                    .instance
                    .get_physical_device_format_properties(vk.physical, vk::Format::R8G8_UNORM);
                assert!(!other.optimal_tiling_features.contains(bit));

                let usage = vk::ImageUsageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR
                    | vk::ImageUsageFlags::TRANSFER_DST;
                let ifp = vk
                    .instance
                    .get_physical_device_image_format_properties(
                        vk.physical,
                        vk::Format::R8_UINT,
                        vk::ImageType::TYPE_2D,
                        vk::ImageTiling::OPTIMAL,
                        usage,
                        vk::ImageCreateFlags::empty(),
                    )
                    .expect("R8_UINT shading-rate image");
                assert_eq!(ifp.sample_counts, vk::SampleCountFlags::TYPE_1);
                let info = vk::PhysicalDeviceImageFormatInfo2::default()
                    .format(vk::Format::R8_UINT)
                    .ty(vk::ImageType::TYPE_2D)
                    .tiling(vk::ImageTiling::OPTIMAL)
                    .usage(vk::ImageUsageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR);
                let mut out = vk::ImageFormatProperties2::default();
                vk.instance
                    .get_physical_device_image_format_properties2(vk.physical, &info, &mut out)
                    .expect("R8_UINT shading-rate image (2)");
                let bad = vk.instance.get_physical_device_image_format_properties(
                    vk.physical,
                    vk::Format::R8G8_UNORM,
                    vk::ImageType::TYPE_2D,
                    vk::ImageTiling::OPTIMAL,
                    usage,
                    vk::ImageCreateFlags::empty(),
                );
                assert_eq!(bad.err(), Some(vk::Result::ERROR_FORMAT_NOT_SUPPORTED));

                // A device with the extension and features, and a shading-rate image on it.
                let dev = vk.device(true);
                let image = make_image(
                    &dev,
                    vk::Format::R8_UINT,
                    4,
                    1,
                    vk::ImageUsageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR,
                );
                let images = env.double.events("image");
                assert_eq!(
                    images[0]["image"],
                    json!(image.0.as_raw()),
                    "validation must not wrap handles"
                );
                dev.device.destroy_image(image.0, None);
                dev.device.free_memory(image.1, None);
            }
            drop_ok(env, profile);
        });
    }
}

/// No validation message and no recorded error; the instance event names `profile`.
fn drop_ok(env: &Env, profile: Profile) {
    assert_no_messages();
    assert_eq!(env.double.errors(), Vec::<String>::new());
    let inst = env.double.events("instance");
    assert_eq!(inst.last().unwrap()["profile"], profile.name());
}

/// A square image of `layers` layers with its own memory.
///
/// # Safety
/// `dev` must be alive.
unsafe fn make_image(
    dev: &Dev,
    format: vk::Format,
    size: u32,
    layers: u32,
    usage: vk::ImageUsageFlags,
) -> (vk::Image, vk::DeviceMemory) {
    // SAFETY: the caller's promise; the struct lives across the call.
    unsafe {
        let image = dev
            .device
            .create_image(
                &vk::ImageCreateInfo::default()
                    .image_type(vk::ImageType::TYPE_2D)
                    .format(format)
                    .extent(vk::Extent3D {
                        width: size,
                        height: size,
                        depth: 1,
                    })
                    .mip_levels(1)
                    .array_layers(layers)
                    .samples(vk::SampleCountFlags::TYPE_1)
                    .tiling(vk::ImageTiling::OPTIMAL)
                    .usage(usage),
                None,
            )
            .expect("vkCreateImage");
        let req = dev.device.get_image_memory_requirements(image);
        let memory = allocate(dev, req, vk::MemoryPropertyFlags::DEVICE_LOCAL);
        dev.device.bind_image_memory(image, memory, 0).unwrap();
        (image, memory)
    }
}

/// # Safety
/// `dev` must be alive.
unsafe fn allocate(
    dev: &Dev,
    req: vk::MemoryRequirements,
    want: vk::MemoryPropertyFlags,
) -> vk::DeviceMemory {
    let ty = (0..dev.props.memory_type_count)
        .find(|&i| {
            req.memory_type_bits & (1 << i) != 0
                && dev.props.memory_types[i as usize]
                    .property_flags
                    .contains(want)
        })
        .expect("a memory type");
    // SAFETY: the caller's promise.
    unsafe {
        dev.device
            .allocate_memory(
                &vk::MemoryAllocateInfo::default()
                    .allocation_size(req.size)
                    .memory_type_index(ty),
                None,
            )
            .expect("memory")
    }
}

/// A host-visible buffer.
///
/// # Safety
/// `dev` must be alive.
unsafe fn make_buffer(
    dev: &Dev,
    size: u64,
    usage: vk::BufferUsageFlags,
) -> (vk::Buffer, vk::DeviceMemory) {
    // SAFETY: the caller's promise.
    unsafe {
        let buffer = dev
            .device
            .create_buffer(
                &vk::BufferCreateInfo::default().size(size).usage(usage),
                None,
            )
            .unwrap();
        let req = dev.device.get_buffer_memory_requirements(buffer);
        let memory = allocate(
            dev,
            req,
            vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
        );
        dev.device.bind_buffer_memory(buffer, memory, 0).unwrap();
        (buffer, memory)
    }
}

/// A view of the first `layers` layers (an array view where more than one).
fn view_layers(dev: &Dev, image: vk::Image, format: vk::Format, layers: u32) -> vk::ImageView {
    let ty = if layers == 1 {
        vk::ImageViewType::TYPE_2D
    } else {
        vk::ImageViewType::TYPE_2D_ARRAY
    };
    // SAFETY: the image is alive; the struct lives across the call.
    unsafe {
        dev.device
            .create_image_view(
                &vk::ImageViewCreateInfo::default()
                    .image(image)
                    .view_type(ty)
                    .format(format)
                    .subresource_range(layers_range(layers)),
                None,
            )
            .unwrap()
    }
}

fn layers_range(layers: u32) -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange {
        layer_count: layers,
        ..color_range()
    }
}

fn color_range() -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange {
        aspect_mask: vk::ImageAspectFlags::COLOR,
        base_mip_level: 0,
        level_count: 1,
        base_array_layer: 0,
        layer_count: 1,
    }
}

/// Records one v1 image barrier from `src` to `dst` stages.
///
/// # Safety
/// `cb` must be recording on `d`.
unsafe fn image_barrier(
    d: &ash::Device,
    cb: vk::CommandBuffer,
    src: vk::PipelineStageFlags,
    dst: vk::PipelineStageFlags,
    barrier: vk::ImageMemoryBarrier,
) {
    // SAFETY: the caller's promise.
    unsafe {
        d.cmd_pipeline_barrier(
            cb,
            src,
            dst,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[barrier],
        )
    }
}

/// A copy of the first colour layer of a `size`×`size` image.
fn whole_layer(size: u32) -> vk::BufferImageCopy {
    vk::BufferImageCopy::default()
        .image_subresource(vk::ImageSubresourceLayers {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            mip_level: 0,
            base_array_layer: 0,
            layer_count: 1,
        })
        .image_extent(vk::Extent3D {
            width: size,
            height: size,
            depth: 1,
        })
}

fn shader(dev: &Dev, bytes: &[u8]) -> vk::ShaderModule {
    let words = ash::util::read_spv(&mut std::io::Cursor::new(bytes)).unwrap();
    // SAFETY: the words live across the call.
    unsafe {
        dev.device
            .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
            .unwrap()
    }
}

/// How the draw reaches the shading-rate attachment.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Path {
    /// vkCreateRenderPass2 with the attachment in the subpass.
    RenderPass,
    /// vkCmdBeginRendering with the attachment struct.
    Dynamic,
    /// Dynamic rendering without any shading rate (for the `none` profile).
    Plain,
}

/// What [`draw`] made and saw.
struct Drawn {
    pixels: Vec<u8>,
    /// The colour read back in a submit after the draw's completed.
    after: Vec<u8>,
    texel: u32,
    codes: Vec<u8>,
    command_buffer: u64,
    /// Raw handles as the application holds them (0 where not made).
    render_pass: u64,
    framebuffer: u64,
    pipeline: u64,
    fsr_image: u64,
    fsr_view: u64,
}

type Ops = [vk::FragmentShadingRateCombinerOpKHR; 2];
const KEEP_REPLACE: Ops = [
    vk::FragmentShadingRateCombinerOpKHR::KEEP,
    vk::FragmentShadingRateCombinerOpKHR::REPLACE,
];

fn extent(w: u32, h: u32) -> vk::Extent2D {
    vk::Extent2D {
        width: w,
        height: h,
    }
}

/// What [`draw_case`] draws.
struct Case<'a> {
    path: Path,
    texel: u32,
    /// The shading-rate image's codes, layer after layer (`SIZE / texel` texels per side).
    codes: Vec<u8>,
    /// The shading-rate image's (and its view's) layers.
    rate_layers: u32,
    /// The pipeline's `VkPipelineFragmentShadingRateStateCreateInfoKHR`, if any.
    state: Option<(vk::Extent2D, Ops)>,
    /// With the dynamic rate state: the device's functions and what is set before the draw.
    dynamic: Option<(
        &'a ash::khr::fragment_shading_rate::Device,
        vk::Extent2D,
        Ops,
    )>,
    /// The shading-rate attachment's store operation (render pass path).
    store: vk::AttachmentStoreOp,
    /// Multiview: the view mask (the colour image then has two layers).
    view_mask: u32,
    /// How often the pass (with its one draw) runs in the one command buffer.
    passes: u32,
    /// Draw with a colour that differs at every pixel (else red on the left, none on the right).
    gradient: bool,
}

impl Case<'_> {
    /// Code (log2 w << 2) | log2 h: 1x1 in the left half, 2x2 on the right.
    fn halves(texel: u32) -> Vec<u8> {
        let n = SIZE / texel;
        (0..n * n)
            .map(|i| if i % n < n / 2 { 0 } else { 0b0101 })
            .collect()
    }

    fn new(path: Path, texel: u32) -> Case<'static> {
        Case {
            path,
            texel,
            codes: Case::halves(texel),
            rate_layers: 1,
            state: Some((extent(1, 1), KEEP_REPLACE)),
            dynamic: None,
            store: vk::AttachmentStoreOp::STORE,
            view_mask: 0,
            passes: 1,
            gradient: false,
        }
    }
}

/// Uploads rate codes into a shading-rate image (`SIZE / texel` texels per side), draws a
/// full-screen triangle into a `SIZE`² colour image through `path`, and reads the colour back.
fn draw(
    dev: &Dev,
    path: Path,
    texel: u32,
    rate_device: Option<&ash::khr::fragment_shading_rate::Device>,
) -> Drawn {
    let mut c = Case::new(path, texel);
    c.dynamic = rate_device.map(|r| (r, extent(1, 1), KEEP_REPLACE));
    draw_case(dev, &c)
}

/// [`draw`] as `c` says.
fn draw_case(dev: &Dev, c: &Case<'_>) -> Drawn {
    let (path, texel) = (c.path, c.texel);
    let d = &dev.device;
    let color_format = vk::Format::R8G8B8A8_UNORM;
    let n = SIZE / texel;
    let codes = c.codes.clone();
    let color_layers = if c.view_mask == 0 { 1 } else { 2 };
    // SAFETY: every struct lives across its call; objects are destroyed after the queue is idle.
    unsafe {
        let (color, color_mem) = make_image(
            dev,
            color_format,
            SIZE,
            color_layers,
            vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
        );
        let color_view = view_layers(dev, color, color_format, color_layers);
        let fsr = (path != Path::Plain).then(|| {
            let (img, mem) = make_image(
                dev,
                vk::Format::R8_UINT,
                n,
                c.rate_layers,
                vk::ImageUsageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR
                    | vk::ImageUsageFlags::TRANSFER_DST,
            );
            (
                img,
                mem,
                view_layers(dev, img, vk::Format::R8_UINT, c.rate_layers),
            )
        });
        let (staging, staging_mem) =
            make_buffer(dev, codes.len() as u64, vk::BufferUsageFlags::TRANSFER_SRC);
        let p = d
            .map_memory(staging_mem, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())
            .unwrap();
        std::ptr::copy_nonoverlapping(codes.as_ptr(), p as *mut u8, codes.len());
        d.unmap_memory(staging_mem);
        let (readback, readback_mem) = make_buffer(
            dev,
            (SIZE * SIZE * 4) as u64,
            vk::BufferUsageFlags::TRANSFER_DST,
        );

        let fsr_layout = vk::ImageLayout::FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR;
        let render_pass = (path == Path::RenderPass).then(|| {
            let atts = [
                vk::AttachmentDescription2::default()
                    .format(color_format)
                    .samples(vk::SampleCountFlags::TYPE_1)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::STORE)
                    .initial_layout(vk::ImageLayout::UNDEFINED)
                    .final_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL),
                vk::AttachmentDescription2::default()
                    .format(vk::Format::R8_UINT)
                    .samples(vk::SampleCountFlags::TYPE_1)
                    .load_op(vk::AttachmentLoadOp::LOAD)
                    .store_op(c.store)
                    .initial_layout(fsr_layout)
                    .final_layout(fsr_layout),
            ];
            let color_ref = [vk::AttachmentReference2::default()
                .attachment(0)
                .layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                .aspect_mask(vk::ImageAspectFlags::COLOR)];
            let fsr_ref = vk::AttachmentReference2::default()
                .attachment(1)
                .layout(fsr_layout);
            let mut fsr_info = vk::FragmentShadingRateAttachmentInfoKHR::default()
                .fragment_shading_rate_attachment(&fsr_ref)
                .shading_rate_attachment_texel_size(vk::Extent2D {
                    width: texel,
                    height: texel,
                });
            let subpass = [vk::SubpassDescription2::default()
                .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
                .view_mask(c.view_mask)
                .color_attachments(&color_ref)
                .push_next(&mut fsr_info)];
            let deps = [
                vk::SubpassDependency2::default()
                    .src_subpass(vk::SUBPASS_EXTERNAL)
                    .dst_subpass(0)
                    .src_stage_mask(vk::PipelineStageFlags::TRANSFER)
                    // The colour attachment's clear too: it must follow the layout transition
                    // this dependency carries (synchronization validation 1.4.309,
                    // SYNC-HAZARD-WRITE-AFTER-WRITE at vkCmdBeginRenderPass2).
                    .dst_stage_mask(
                        vk::PipelineStageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR
                            | vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                    )
                    .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                    .dst_access_mask(
                        vk::AccessFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR
                            | vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
                    ),
                vk::SubpassDependency2::default()
                    .src_subpass(0)
                    .dst_subpass(vk::SUBPASS_EXTERNAL)
                    .src_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
                    .dst_stage_mask(vk::PipelineStageFlags::TRANSFER)
                    .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                    .dst_access_mask(vk::AccessFlags::TRANSFER_READ),
            ];
            d.create_render_pass2(
                &vk::RenderPassCreateInfo2::default()
                    .attachments(&atts)
                    .subpasses(&subpass)
                    .dependencies(&deps),
                None,
            )
            .expect("vkCreateRenderPass2")
        });
        let framebuffer = render_pass.map(|rp| {
            let views = [color_view, fsr.unwrap().2];
            d.create_framebuffer(
                &vk::FramebufferCreateInfo::default()
                    .render_pass(rp)
                    .attachments(&views)
                    .width(SIZE)
                    .height(SIZE)
                    .layers(1),
                None,
            )
            .expect("vkCreateFramebuffer")
        });

        let vert = shader(dev, include_bytes!("../shaders/fullscreen.vert.spv"));
        let frag = if c.gradient {
            shader(dev, include_bytes!("../shaders/gradient.frag.spv"))
        } else {
            shader(dev, include_bytes!("../shaders/solid.frag.spv"))
        };
        let layout = d
            .create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default(), None)
            .unwrap();
        let stages = [
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::VERTEX)
                .module(vert)
                .name(c"main"),
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::FRAGMENT)
                .module(frag)
                .name(c"main"),
        ];
        let vertex_input = vk::PipelineVertexInputStateCreateInfo::default();
        let assembly = vk::PipelineInputAssemblyStateCreateInfo::default()
            .topology(vk::PrimitiveTopology::TRIANGLE_LIST);
        let viewport = vk::PipelineViewportStateCreateInfo::default()
            .viewport_count(1)
            .scissor_count(1);
        let raster = vk::PipelineRasterizationStateCreateInfo::default()
            .polygon_mode(vk::PolygonMode::FILL)
            .cull_mode(vk::CullModeFlags::NONE)
            .line_width(1.0);
        let multisample = vk::PipelineMultisampleStateCreateInfo::default()
            .rasterization_samples(vk::SampleCountFlags::TYPE_1);
        let blend_att = [vk::PipelineColorBlendAttachmentState::default()
            .color_write_mask(vk::ColorComponentFlags::RGBA)];
        let blend = vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend_att);
        let mut dynamic_states = vec![vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];
        if c.dynamic.is_some() {
            dynamic_states.push(vk::DynamicState::FRAGMENT_SHADING_RATE_KHR);
        }
        let dynamic = vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic_states);
        let formats = [color_format];
        let mut rendering = vk::PipelineRenderingCreateInfo::default()
            .color_attachment_formats(&formats)
            .view_mask(c.view_mask);
        let (size, ops) = c.state.unwrap_or((extent(1, 1), KEEP_REPLACE));
        let mut rate_state = vk::PipelineFragmentShadingRateStateCreateInfoKHR::default()
            .fragment_size(size)
            .combiner_ops(ops);
        let mut info = vk::GraphicsPipelineCreateInfo::default()
            .stages(&stages)
            .vertex_input_state(&vertex_input)
            .input_assembly_state(&assembly)
            .viewport_state(&viewport)
            .rasterization_state(&raster)
            .multisample_state(&multisample)
            .color_blend_state(&blend)
            .dynamic_state(&dynamic)
            .layout(layout);
        match path {
            Path::RenderPass => {
                info = info.render_pass(render_pass.unwrap()).subpass(0);
                if c.state.is_some() {
                    info = info.push_next(&mut rate_state);
                }
            }
            Path::Dynamic => {
                info = info
                    .flags(vk::PipelineCreateFlags::RENDERING_FRAGMENT_SHADING_RATE_ATTACHMENT_KHR)
                    .push_next(&mut rendering);
                if c.state.is_some() {
                    info = info.push_next(&mut rate_state);
                }
            }
            Path::Plain => info = info.push_next(&mut rendering),
        }
        let pipeline = d
            .create_graphics_pipelines(vk::PipelineCache::null(), &[info], None)
            .expect("vkCreateGraphicsPipelines")[0];

        let cb = d
            .allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(dev.pool)
                    .level(vk::CommandBufferLevel::PRIMARY)
                    .command_buffer_count(1),
            )
            .unwrap()[0];
        d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
            .unwrap();
        if let Some((img, _, _)) = fsr {
            let to_dst = vk::ImageMemoryBarrier::default()
                .image(img)
                .subresource_range(layers_range(c.rate_layers))
                .old_layout(vk::ImageLayout::UNDEFINED)
                .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .dst_access_mask(vk::AccessFlags::TRANSFER_WRITE);
            image_barrier(
                d,
                cb,
                vk::PipelineStageFlags::TOP_OF_PIPE,
                vk::PipelineStageFlags::TRANSFER,
                to_dst,
            );
            let mut region = whole_layer(n);
            region.image_subresource.layer_count = c.rate_layers;
            d.cmd_copy_buffer_to_image(
                cb,
                staging,
                img,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &[region],
            );
            // sync2, so both barrier paths of the double are crossed.
            let to_fsr = [vk::ImageMemoryBarrier2::default()
                .image(img)
                .subresource_range(layers_range(c.rate_layers))
                .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .new_layout(fsr_layout)
                .src_stage_mask(vk::PipelineStageFlags2::COPY)
                .src_access_mask(vk::AccessFlags2::TRANSFER_WRITE)
                .dst_stage_mask(vk::PipelineStageFlags2::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR)
                .dst_access_mask(vk::AccessFlags2::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR)];
            d.cmd_pipeline_barrier2(
                cb,
                &vk::DependencyInfo::default().image_memory_barriers(&to_fsr),
            );
        }
        let area = vk::Rect2D {
            offset: vk::Offset2D { x: 0, y: 0 },
            extent: vk::Extent2D {
                width: SIZE,
                height: SIZE,
            },
        };
        let clear = [vk::ClearValue {
            color: vk::ClearColorValue {
                float32: [0.0, 0.0, 1.0, 1.0],
            },
        }];
        for _ in 0..c.passes {
            match path {
                Path::RenderPass => d.cmd_begin_render_pass2(
                    cb,
                    &vk::RenderPassBeginInfo::default()
                        .render_pass(render_pass.unwrap())
                        .framebuffer(framebuffer.unwrap())
                        .render_area(area)
                        .clear_values(&clear),
                    &vk::SubpassBeginInfo::default().contents(vk::SubpassContents::INLINE),
                ),
                Path::Dynamic | Path::Plain => {
                    let to_color = vk::ImageMemoryBarrier::default()
                        .image(color)
                        .subresource_range(layers_range(color_layers))
                        .old_layout(vk::ImageLayout::UNDEFINED)
                        .new_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                        .dst_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE);
                    image_barrier(
                        d,
                        cb,
                        vk::PipelineStageFlags::TOP_OF_PIPE,
                        vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                        to_color,
                    );
                    let color_att = [vk::RenderingAttachmentInfo::default()
                        .image_view(color_view)
                        .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                        .load_op(vk::AttachmentLoadOp::CLEAR)
                        .store_op(vk::AttachmentStoreOp::STORE)
                        .clear_value(clear[0])];
                    let mut fsr_att = vk::RenderingFragmentShadingRateAttachmentInfoKHR::default()
                        .image_view(fsr.map(|f| f.2).unwrap_or_default())
                        .image_layout(fsr_layout)
                        .shading_rate_attachment_texel_size(vk::Extent2D {
                            width: texel,
                            height: texel,
                        });
                    let mut ri = vk::RenderingInfo::default()
                        .render_area(area)
                        .layer_count(1)
                        .view_mask(c.view_mask)
                        .color_attachments(&color_att);
                    if path == Path::Dynamic {
                        ri = ri.push_next(&mut fsr_att);
                    }
                    d.cmd_begin_rendering(cb, &ri);
                }
            }
            d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, pipeline);
            d.cmd_set_viewport(
                cb,
                0,
                &[vk::Viewport {
                    x: 0.0,
                    y: 0.0,
                    width: SIZE as f32,
                    height: SIZE as f32,
                    min_depth: 0.0,
                    max_depth: 1.0,
                }],
            );
            d.cmd_set_scissor(cb, 0, &[area]);
            if let Some((rd, size, ops)) = c.dynamic {
                (rd.fp().cmd_set_fragment_shading_rate_khr)(cb, &size, &ops);
            }
            d.cmd_draw(cb, 3, 1, 0, 0);
            match path {
                Path::RenderPass => d.cmd_end_render_pass2(cb, &vk::SubpassEndInfo::default()),
                _ => d.cmd_end_rendering(cb),
            }
        }
        match path {
            Path::RenderPass => {}
            _ => {
                let to_src = vk::ImageMemoryBarrier::default()
                    .image(color)
                    .subresource_range(layers_range(color_layers))
                    .old_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                    .new_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL)
                    .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                    .dst_access_mask(vk::AccessFlags::TRANSFER_READ);
                image_barrier(
                    d,
                    cb,
                    vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                    vk::PipelineStageFlags::TRANSFER,
                    to_src,
                );
            }
        }
        d.cmd_copy_image_to_buffer(
            cb,
            color,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            readback,
            &[whole_layer(SIZE)],
        );
        let host = vk::BufferMemoryBarrier::default()
            .buffer(readback)
            .size(vk::WHOLE_SIZE)
            .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ);
        d.cmd_pipeline_barrier(
            cb,
            vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::HOST,
            vk::DependencyFlags::empty(),
            &[],
            &[host],
            &[],
        );
        d.end_command_buffer(cb).unwrap();
        let fence = d
            .create_fence(&vk::FenceCreateInfo::default(), None)
            .unwrap();
        let cbs = [cb];
        if path == Path::Dynamic {
            // vkQueueSubmit2, so both submit paths of the double are crossed.
            let infos = [vk::CommandBufferSubmitInfo::default().command_buffer(cb)];
            d.queue_submit2(
                dev.queue,
                &[vk::SubmitInfo2::default().command_buffer_infos(&infos)],
                fence,
            )
            .expect("vkQueueSubmit2");
        } else {
            d.queue_submit(
                dev.queue,
                &[vk::SubmitInfo::default().command_buffers(&cbs)],
                fence,
            )
            .expect("vkQueueSubmit");
        }
        d.wait_for_fences(&[fence], true, u64::MAX).unwrap();
        let p = d
            .map_memory(readback_mem, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())
            .unwrap();
        let pixels =
            std::slice::from_raw_parts(p as *const u8, (SIZE * SIZE * 4) as usize).to_vec();
        d.unmap_memory(readback_mem);
        // The colour once more, in a submit of its own after the first completed.
        let again = d
            .allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(dev.pool)
                    .level(vk::CommandBufferLevel::PRIMARY)
                    .command_buffer_count(1),
            )
            .unwrap();
        d.begin_command_buffer(again[0], &vk::CommandBufferBeginInfo::default())
            .unwrap();
        d.cmd_copy_image_to_buffer(
            again[0],
            color,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            readback,
            &[whole_layer(SIZE)],
        );
        d.cmd_pipeline_barrier(
            again[0],
            vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::HOST,
            vk::DependencyFlags::empty(),
            &[],
            &[host],
            &[],
        );
        d.end_command_buffer(again[0]).unwrap();
        d.reset_fences(&[fence]).unwrap();
        d.queue_submit(
            dev.queue,
            &[vk::SubmitInfo::default().command_buffers(&again)],
            fence,
        )
        .expect("vkQueueSubmit");
        d.wait_for_fences(&[fence], true, u64::MAX).unwrap();
        let p = d
            .map_memory(readback_mem, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())
            .unwrap();
        let after = std::slice::from_raw_parts(p as *const u8, (SIZE * SIZE * 4) as usize).to_vec();
        d.unmap_memory(readback_mem);
        d.free_command_buffers(dev.pool, &again);

        d.destroy_fence(fence, None);
        d.free_command_buffers(dev.pool, &cbs);
        d.destroy_pipeline(pipeline, None);
        d.destroy_pipeline_layout(layout, None);
        d.destroy_shader_module(vert, None);
        d.destroy_shader_module(frag, None);
        if let Some(fb) = framebuffer {
            d.destroy_framebuffer(fb, None);
        }
        if let Some(rp) = render_pass {
            d.destroy_render_pass(rp, None);
        }
        for (b, m) in [(staging, staging_mem), (readback, readback_mem)] {
            d.destroy_buffer(b, None);
            d.free_memory(m, None);
        }
        if let Some((img, mem, v)) = fsr {
            d.destroy_image_view(v, None);
            d.destroy_image(img, None);
            d.free_memory(mem, None);
        }
        d.destroy_image_view(color_view, None);
        d.destroy_image(color, None);
        d.free_memory(color_mem, None);
        Drawn {
            pixels,
            after,
            texel,
            codes,
            command_buffer: cb.as_raw(),
            render_pass: render_pass.map_or(0, |h| h.as_raw()),
            framebuffer: framebuffer.map_or(0, |h| h.as_raw()),
            pipeline: pipeline.as_raw(),
            fsr_image: fsr.map_or(0, |f| f.0.as_raw()),
            fsr_view: fsr.map_or(0, |f| f.2.as_raw()),
        }
    }
}

/// The shader's colour: red on the left 32 columns, none on the right; green and blue constant.
fn assert_pixels(pixels: &[u8]) {
    for y in [0, SIZE / 2, SIZE - 1] {
        for x in [0, 31, 32, SIZE - 1] {
            let i = ((y * SIZE + x) * 4) as usize;
            let px = &pixels[i..i + 4];
            let red = if x < 32 { 255 } else { 0 };
            assert_eq!(px[0], red, "red at ({x},{y}): {px:?}");
            assert!(px[1].abs_diff(128) <= 1, "green at ({x},{y}): {px:?}");
            assert!(px[2].abs_diff(64) <= 1, "blue at ({x},{y}): {px:?}");
            assert_eq!(px[3], 255);
        }
    }
}

/// The one submit event for `cb`.
fn submit_of(env: &Env, cb: u64) -> Value {
    let submits: Vec<Value> = env
        .double
        .events("submit")
        .into_iter()
        .filter(|e| {
            e["command_buffers"]
                .as_array()
                .unwrap()
                .contains(&json!(cb))
        })
        .collect();
    assert_eq!(submits.len(), 1, "{submits:?}");
    submits[0].clone()
}

/// The rate codes the double read back at the submit equal those uploaded.
fn assert_codes(env: &Env, drawn: &Drawn, texel: u32) {
    let submit = submit_of(env, drawn.command_buffer);
    let images = submit["shading_rate_images"].as_array().unwrap();
    assert_eq!(images.len(), 1, "{submit}");
    let n = SIZE / texel;
    assert_eq!(images[0]["extent"], json!([n, n]));
    let codes: Vec<u8> = images[0]["codes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_u64().unwrap() as u8)
        .collect();
    assert_eq!(codes, drawn.codes);
}

#[test]
fn render_pass_with_shading_rate_attachment_draws_and_is_recorded() {
    with_vk(Profile::Nvidia, |env, vk| {
        let dev = vk.device(true);
        let rates = ash::khr::fragment_shading_rate::Device::new(&vk.instance, &dev.device);
        let drawn = draw(&dev, Path::RenderPass, 16, Some(&rates));
        assert_pixels(&drawn.pixels);

        let passes = env.double.events("render_pass");
        assert_eq!(passes.len(), 1, "{passes:?}");
        let rp = &passes[0];
        assert_eq!(rp["render_pass"], json!(drawn.render_pass));
        assert_eq!(
            rp["subpasses"][0]["shading_rate"],
            json!({"attachment": 1, "layout": vk::ImageLayout::FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR.as_raw(), "texel": [16, 16]})
        );
        let fbs = env.double.events("framebuffer");
        assert_eq!(fbs.len(), 1);
        assert_eq!(fbs[0]["render_pass"], rp["render_pass"]);
        assert_eq!(fbs[0]["framebuffer"], json!(drawn.framebuffer));
        assert_eq!(fbs[0]["attachments"][1], json!(drawn.fsr_view));
        let begins = env.double.events("begin_render_pass");
        assert_eq!(begins.len(), 1);
        assert_eq!(begins[0]["command_buffer"], json!(drawn.command_buffer));
        assert_eq!(begins[0]["render_pass"], rp["render_pass"]);
        assert_eq!(begins[0]["framebuffer"], fbs[0]["framebuffer"]);
        assert_eq!(begins[0]["shading_rate_views"], json!([drawn.fsr_view]));
        let pipelines = env.double.events("pipeline");
        assert_eq!(pipelines.len(), 1);
        assert_eq!(pipelines[0]["render_pass"], rp["render_pass"]);
        assert_eq!(pipelines[0]["pipeline"], json!(drawn.pipeline));
        assert_eq!(
            pipelines[0]["shading_rate_state"],
            json!({"fragment_size": [1, 1], "combiner_ops": [0, 1]})
        );
        assert_eq!(pipelines[0]["dynamic_rate"], true);
        assert_eq!(pipelines[0]["rendering_attachment_flag"], false);
        let sets = env.double.events("set_fragment_shading_rate");
        assert_eq!(sets.len(), 1);
        assert_eq!(sets[0]["command_buffer"], json!(drawn.command_buffer));
        assert_eq!(sets[0]["fragment_size"], json!([1, 1]));
        assert_codes(env, &drawn, 16);
        let devices = env.double.events("device");
        assert_eq!(devices[0]["extension"], true);
        assert_eq!(
            devices[0]["features"],
            json!({"pipeline": true, "primitive": false, "attachment": true})
        );
        drop(dev);
        drop_ok(env, Profile::Nvidia);
    });
}

#[test]
fn dynamic_rendering_with_shading_rate_attachment_draws_and_is_recorded() {
    with_vk(Profile::Amd, |env, vk| {
        let dev = vk.device(true);
        let drawn = draw(&dev, Path::Dynamic, 8, None);
        assert_pixels(&drawn.pixels);

        let begins = env.double.events("begin_rendering");
        assert_eq!(begins.len(), 1);
        assert_eq!(begins[0]["command_buffer"], json!(drawn.command_buffer));
        let views = env.double.events("image_view");
        assert_eq!(views.len(), 1, "only the shading-rate image's view");
        assert_eq!(views[0]["view"], json!(drawn.fsr_view));
        assert_eq!(views[0]["image"], json!(drawn.fsr_image));
        assert_eq!(
            begins[0]["shading_rate"],
            json!({"view": drawn.fsr_view, "layout": vk::ImageLayout::FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR.as_raw(), "texel": [8, 8]})
        );
        let pipelines = env.double.events("pipeline");
        assert_eq!(pipelines.len(), 1);
        assert_eq!(pipelines[0]["pipeline"], json!(drawn.pipeline));
        assert_eq!(pipelines[0]["rendering_attachment_flag"], true);
        assert_eq!(pipelines[0]["dynamic_rate"], false);
        assert_codes(env, &drawn, 8);
        drop(dev);
        drop_ok(env, Profile::Amd);
    });
}

#[test]
fn none_profile_passes_everything_through() {
    with_vk(Profile::None, |env, vk| {
        // SAFETY: plain queries; the structs live across the calls.
        unsafe {
            let exts = vk
                .instance
                .enumerate_device_extension_properties(vk.physical)
                .unwrap();
            assert!(!exts.iter().any(|e| e.extension_name_as_c_str() == Ok(FSR)));
            let mut features = vk::PhysicalDeviceFragmentShadingRateFeaturesKHR::default();
            let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut features);
            vk.instance
                .get_physical_device_features2(vk.physical, &mut f2);
            assert_eq!(features.attachment_fragment_shading_rate, vk::FALSE);
            let fp = vk
                .instance
                .get_physical_device_format_properties(vk.physical, vk::Format::R8_UINT);
            assert!(!fp
                .optimal_tiling_features
                .contains(vk::FormatFeatureFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR));
        }
        let dev = vk.device(false);
        let drawn = draw(&dev, Path::Plain, 8, None);
        assert_pixels(&drawn.pixels);
        // Nothing intercepted, so nothing recorded beyond the instance.
        let events = env.double.records()["events"].as_array().unwrap().clone();
        assert_eq!(events.len(), 1, "{events:?}");
        drop(dev);
        drop_ok(env, Profile::None);
    });
}

#[test]
fn texel_size_other_than_the_devices_is_recorded_as_an_error() {
    with_vk(Profile::Nvidia, |env, vk| {
        let dev = vk.device(true);
        // 8×8 texels on a 16×16-only device.
        let drawn = draw(&dev, Path::RenderPass, 8, None);
        assert_pixels(&drawn.pixels);
        let errors = env.double.errors();
        assert!(
            errors
                .iter()
                .any(|e| e.contains("texel 8x8 is not the device's 16x16")),
            "{errors:?}"
        );
        let messages = take_messages();
        assert!(
            messages
                .iter()
                .any(|m| m.contains("shadingRateAttachmentTexelSize")),
            "validation should refuse it too: {messages:?}"
        );
        env.double.clear();

        // Refusals a real driver makes at creation: a cleared load, a format without the
        // shading-rate feature, a multisampled shading-rate image.
        let fsr_layout = vk::ImageLayout::FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR;
        for (format, load, want) in [
            (
                vk::Format::R8_UINT,
                vk::AttachmentLoadOp::CLEAR,
                "loadOp CLEAR",
            ),
            (
                vk::Format::R8_UNORM,
                vk::AttachmentLoadOp::LOAD,
                "attachment format",
            ),
        ] {
            let atts = [vk::AttachmentDescription2::default()
                .format(format)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(load)
                .store_op(vk::AttachmentStoreOp::DONT_CARE)
                .initial_layout(fsr_layout)
                .final_layout(fsr_layout)];
            let fsr_ref = vk::AttachmentReference2::default()
                .attachment(0)
                .layout(fsr_layout);
            let mut fsr_info = vk::FragmentShadingRateAttachmentInfoKHR::default()
                .fragment_shading_rate_attachment(&fsr_ref)
                .shading_rate_attachment_texel_size(vk::Extent2D {
                    width: 16,
                    height: 16,
                });
            let subpass = [vk::SubpassDescription2::default()
                .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
                .push_next(&mut fsr_info)];
            // SAFETY: the structs live across the call.
            unsafe {
                if let Ok(rp) = dev.device.create_render_pass2(
                    &vk::RenderPassCreateInfo2::default()
                        .attachments(&atts)
                        .subpasses(&subpass),
                    None,
                ) {
                    dev.device.destroy_render_pass(rp, None);
                }
            }
            let errors = env.double.errors();
            assert!(
                errors.iter().any(|e| e.contains(want)),
                "{want}: {errors:?}"
            );
            env.double.clear();
        }
        // SAFETY: the struct lives across the call.
        unsafe {
            let info = vk::ImageCreateInfo::default()
                .image_type(vk::ImageType::TYPE_2D)
                .format(vk::Format::R8_UINT)
                .extent(vk::Extent3D {
                    width: 4,
                    height: 4,
                    depth: 1,
                })
                .mip_levels(1)
                .array_layers(1)
                .samples(vk::SampleCountFlags::TYPE_4)
                .tiling(vk::ImageTiling::OPTIMAL)
                .usage(
                    vk::ImageUsageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR
                        | vk::ImageUsageFlags::COLOR_ATTACHMENT,
                );
            if let Ok(image) = dev.device.create_image(&info, None) {
                dev.device.destroy_image(image, None);
            }
        }
        let errors = env.double.errors();
        assert!(errors.iter().any(|e| e.contains("TYPE_4")), "{errors:?}");
        env.double.clear();
        drop(dev);
        take_messages();
    });
}

#[test]
fn profile_comes_from_the_environment_without_an_override() {
    let (_guard, env) = match env() {
        Ok(e) => e,
        Err(reason) => {
            skip(&reason);
            return;
        }
    };
    env.double.clear();
    env.double.set_profile(None);
    // Tests run one at a time (SERIAL), and the variable is read only at vkCreateInstance.
    std::env::set_var(fovea_vkdouble::PROFILE_ENV, "amd");
    let vk = Vk::new_without_override(env);
    std::env::remove_var(fovea_vkdouble::PROFILE_ENV);
    let vk = match vk {
        Ok(v) => v,
        Err(reason) => {
            skip(&reason);
            return;
        }
    };
    let mut p = vk::PhysicalDeviceFragmentShadingRatePropertiesKHR::default();
    let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut p);
    // SAFETY: the structs live across the call.
    unsafe {
        vk.instance
            .get_physical_device_properties2(vk.physical, &mut p2)
    };
    assert_eq!(p.max_fragment_shading_rate_attachment_texel_size.width, 8);
    drop(vk);
    drop_ok(env, Profile::Amd);
}

#[test]
fn multi_layer_views_need_layered_attachments() {
    for profile in [Profile::Nvidia, Profile::Amd] {
        with_vk(profile, |env, vk| {
            let dev = vk.device(true);
            // SAFETY: every struct lives across its call; objects are destroyed before the device.
            unsafe {
                let d = &dev.device;
                let (image, memory) = make_image(
                    &dev,
                    vk::Format::R8_UINT,
                    4,
                    2,
                    vk::ImageUsageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR,
                );
                let view = d
                    .create_image_view(
                        &vk::ImageViewCreateInfo::default()
                            .image(image)
                            .view_type(vk::ImageViewType::TYPE_2D_ARRAY)
                            .format(vk::Format::R8_UINT)
                            .subresource_range(vk::ImageSubresourceRange {
                                layer_count: 2,
                                ..color_range()
                            }),
                        None,
                    )
                    .unwrap();
                d.destroy_image_view(view, None);
                d.destroy_image(image, None);
                d.free_memory(memory, None);
            }
            drop(dev);
            let errors = env.double.errors();
            let messages = take_messages();
            if profile == Profile::Nvidia {
                assert_eq!(errors, Vec::<String>::new());
                assert!(messages.is_empty(), "{messages:?}");
            } else {
                assert!(
                    errors
                        .iter()
                        .any(|e| e.contains("layeredShadingRateAttachments")),
                    "{errors:?}"
                );
                assert!(
                    messages.iter().any(|m| m.contains("04551")),
                    "validation should refuse it too: {messages:?}"
                );
                env.double.clear();
            }
        });
    }
}

// ---------------------------------------------------------------------------------------------
// Effects: the fragment size each draw gets, as the device the double plays would shade it.

use vk::FragmentShadingRateCombinerOpKHR as Op;

/// The effective codes per view of draw 0 of pass `pass` in what `drawn` submitted; the double
/// recorded no misuse.
fn effective(env: &Env, drawn: &Drawn, pass: usize) -> Vec<ViewRates> {
    assert_eq!(env.double.errors(), Vec::<String>::new());
    let views = env
        .double
        .effective_rates(drawn.command_buffer, pass, 0)
        .expect("a draw record");
    let n = SIZE / (drawn.texel.max(1));
    for v in &views {
        if v.layer.is_some() {
            assert_eq!((v.columns, v.rows), (n, n), "{v:?}");
        }
    }
    views
}

/// Runs `c` on a fresh device of `profile` and returns the effective codes of each view of the one
/// draw in each pass.
fn effective_of(
    profile: Profile,
    c: impl Fn(&ash::khr::fragment_shading_rate::Device) -> Case<'_>,
) -> Vec<Vec<Vec<u8>>> {
    let mut out = Vec::new();
    with_vk(profile, |env, vk| {
        let dev = vk.device(true);
        let rates = ash::khr::fragment_shading_rate::Device::new(&vk.instance, &dev.device);
        let case = c(&rates);
        let drawn = draw_case(&dev, &case);
        for pass in 0..case.passes as usize {
            out.push(
                effective(env, &drawn, pass)
                    .into_iter()
                    .map(|v| v.codes)
                    .collect(),
            );
        }
        drop(dev);
        drop_ok(env, profile);
    });
    out
}

fn uniform(texel: u32, code: u8) -> Vec<u8> {
    vec![code; ((SIZE / texel) * (SIZE / texel)) as usize]
}

#[test]
fn the_attachment_decides_with_keep_replace_on_both_paths_and_profiles() {
    for (profile, texel) in [(Profile::Nvidia, 16), (Profile::Amd, 8)] {
        for path in [Path::RenderPass, Path::Dynamic] {
            let got = effective_of(profile, |_| Case::new(path, texel));
            if got.is_empty() {
                return;
            }
            assert_eq!(got, vec![vec![Case::halves(texel)]], "{profile:?}");
        }
    }
}

#[test]
fn a_pipeline_without_rate_state_ignores_the_attachment() {
    for path in [Path::RenderPass, Path::Dynamic] {
        let got = effective_of(Profile::Nvidia, |_| Case {
            state: None,
            ..Case::new(path, 16)
        });
        if got.is_empty() {
            return;
        }
        assert_eq!(got, vec![vec![uniform(16, 0)]]);
    }
}

#[test]
fn max_min_and_mul_combine_the_pipeline_rate_with_the_attachment() {
    // The attachment: 1x1 on the left half, 2x2 on the right.
    for (size, op, left, right) in [
        (extent(2, 2), Op::MAX, 0b0101, 0b0101),
        (extent(2, 1), Op::MIN, 0b0000, 0b0100),
        (extent(2, 1), Op::MUL, 0b0100, 0b1001),
    ] {
        let got = effective_of(Profile::Nvidia, |_| Case {
            state: Some((size, [Op::KEEP, op])),
            ..Case::new(Path::RenderPass, 16)
        });
        if got.is_empty() {
            return;
        }
        let n = SIZE / 16;
        let want: Vec<u8> = (0..n * n)
            .map(|i| if i % n < n / 2 { left } else { right })
            .collect();
        assert_eq!(got, vec![vec![want]], "{op:?}");
    }
}

#[test]
fn the_dynamic_rate_replaces_the_pipelines_where_the_state_is_dynamic() {
    let got = effective_of(Profile::Nvidia, |rates| Case {
        state: None,
        dynamic: Some((rates, extent(2, 1), [Op::KEEP, Op::MUL])),
        ..Case::new(Path::Dynamic, 16)
    });
    if got.is_empty() {
        return;
    }
    let n = SIZE / 16;
    let want: Vec<u8> = (0..n * n)
        .map(|i| if i % n < n / 2 { 0b0100 } else { 0b1001 })
        .collect();
    assert_eq!(got, vec![vec![want]]);
}

#[test]
fn rates_the_device_lacks_are_clamped_to_its_list() {
    // 4x4 and 4x1 on the AMD profile (fragments up to 2x2): 2x2 and 2x1.
    let n = SIZE / 8;
    let codes: Vec<u8> = (0..n * n)
        .map(|i| if i % n < n / 2 { 0b1010 } else { 0b1000 })
        .collect();
    let got = effective_of(Profile::Amd, |_| Case {
        codes: codes.clone(),
        ..Case::new(Path::RenderPass, 8)
    });
    if got.is_empty() {
        return;
    }
    let want: Vec<u8> = (0..n * n)
        .map(|i| if i % n < n / 2 { 0b0101 } else { 0b0100 })
        .collect();
    assert_eq!(got, vec![vec![want]]);
}

#[test]
fn multiview_reads_the_view_index_layer_of_a_layered_attachment_else_layer_zero() {
    for path in [Path::RenderPass, Path::Dynamic] {
        // NVIDIA: two layers, the second all 2x2; each view its own.
        let mut codes = Case::halves(16);
        codes.extend(uniform(16, 0b0101));
        let got = effective_of(Profile::Nvidia, |_| Case {
            codes: codes.clone(),
            rate_layers: 2,
            view_mask: 0b11,
            ..Case::new(path, 16)
        });
        if got.is_empty() {
            return;
        }
        assert_eq!(got, vec![vec![Case::halves(16), uniform(16, 0b0101)]]);
        // AMD: one layer serves both views.
        let got = effective_of(Profile::Amd, |_| Case {
            view_mask: 0b11,
            ..Case::new(path, 8)
        });
        assert_eq!(got, vec![vec![Case::halves(8), Case::halves(8)]]);
    }
}

#[test]
fn a_pass_that_stores_its_attachment_with_dont_care_leaves_it_poisoned() {
    for (store, second) in [
        (vk::AttachmentStoreOp::STORE, Case::halves(16)),
        (vk::AttachmentStoreOp::NONE, Case::halves(16)),
        (vk::AttachmentStoreOp::DONT_CARE, uniform(16, 0b1010)),
    ] {
        let got = effective_of(Profile::Nvidia, |_| Case {
            store,
            passes: 2,
            ..Case::new(Path::RenderPass, 16)
        });
        if got.is_empty() {
            return;
        }
        assert_eq!(got, vec![vec![Case::halves(16)], vec![second]], "{store:?}");
    }
}

// ---------------------------------------------------------------------------------------------
// Strictness: the driver has no fragment density maps.

/// The double's errors, which must name `want`; forgets them and validation's messages (which
/// report the same misuse from above).
fn take_errors_naming(env: &Env, want: &str) {
    let errors = env.double.errors();
    assert!(
        errors.iter().any(|e| e.contains(want)),
        "no error naming {want}: {errors:?}"
    );
    env.double.clear();
    take_messages();
}

#[test]
fn density_map_enums_in_barriers_events_and_timestamps_are_errors() {
    with_vk(Profile::Nvidia, |env, vk| {
        let dev = vk.device(true);
        let d = &dev.device;
        // SAFETY: every struct lives across its call; the objects are destroyed after use.
        unsafe {
            let (img, mem) = make_image(
                &dev,
                vk::Format::R8G8B8A8_UNORM,
                8,
                1,
                vk::ImageUsageFlags::SAMPLED,
            );
            let cb = d
                .allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default()
                        .command_pool(dev.pool)
                        .level(vk::CommandBufferLevel::PRIMARY)
                        .command_buffer_count(1),
                )
                .unwrap()[0];
            d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
                .unwrap();
            assert_eq!(env.double.errors(), Vec::<String>::new());
            let layout = vk::ImageMemoryBarrier::default()
                .image(img)
                .subresource_range(color_range())
                .old_layout(vk::ImageLayout::UNDEFINED)
                .new_layout(vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT);
            image_barrier(
                d,
                cb,
                vk::PipelineStageFlags::TOP_OF_PIPE,
                vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                layout,
            );
            take_errors_naming(env, "FRAGMENT_DENSITY_MAP_OPTIMAL_EXT");
            let access = [vk::MemoryBarrier2::default()
                .src_stage_mask(vk::PipelineStageFlags2::ALL_COMMANDS)
                .dst_stage_mask(vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT)
                .dst_access_mask(vk::AccessFlags2::FRAGMENT_DENSITY_MAP_READ_EXT)];
            d.cmd_pipeline_barrier2(cb, &vk::DependencyInfo::default().memory_barriers(&access));
            take_errors_naming(env, "FRAGMENT_DENSITY_MAP_READ_EXT");
            let ev = d
                .create_event(&vk::EventCreateInfo::default(), None)
                .unwrap();
            d.cmd_set_event(cb, ev, vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT);
            take_errors_naming(env, "vkCmdSetEvent: stage FRAGMENT_DENSITY_PROCESS_EXT");
            d.cmd_set_event2(
                cb,
                ev,
                &vk::DependencyInfo::default().memory_barriers(&access),
            );
            take_errors_naming(env, "vkCmdSetEvent2");
            d.end_command_buffer(cb).unwrap();
            d.free_command_buffers(dev.pool, &[cb]);
            d.destroy_event(ev, None);
            d.destroy_image(img, None);
            d.free_memory(mem, None);
        }
        drop(dev);
        assert_eq!(env.double.errors(), Vec::<String>::new());
        take_messages();
    });
}

#[test]
fn a_device_asking_for_density_map_features_is_refused() {
    with_vk(Profile::Amd, |env, vk| {
        // SAFETY: every struct lives across the call.
        unsafe {
            let prio = [1.0];
            let queues = [vk::DeviceQueueCreateInfo::default()
                .queue_family_index(0)
                .queue_priorities(&prio)];
            let mut fdm = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default()
                .fragment_density_map(true);
            let info = vk::DeviceCreateInfo::default()
                .queue_create_infos(&queues)
                .push_next(&mut fdm);
            let r = vk.instance.create_device(vk.physical, &info, None);
            assert_eq!(r.err(), Some(vk::Result::ERROR_FEATURE_NOT_PRESENT));
        }
        take_errors_naming(env, "vkCreateDevice");
    });
}

#[test]
fn a_shading_rate_attachment_without_the_feature_is_an_error() {
    with_vk(Profile::Nvidia, |env, vk| {
        let dev = vk.device(false);
        // SAFETY: the image is destroyed before the device.
        unsafe {
            let (img, mem) = make_image(
                &dev,
                vk::Format::R8_UINT,
                4,
                1,
                vk::ImageUsageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR,
            );
            take_errors_naming(env, "attachmentFragmentShadingRate");
            dev.device.destroy_image(img, None);
            dev.device.free_memory(mem, None);
        }
        drop(dev);
        take_messages();
    });
}

#[test]
fn load_store_op_none_is_offered_as_desktop_drivers_do_and_a_device_gets_it() {
    with_vk(Profile::Nvidia, |env, vk| {
        let name = c"VK_EXT_load_store_op_none";
        // SAFETY: plain queries; the structs live across the calls.
        unsafe {
            let exts = vk
                .instance
                .enumerate_device_extension_properties(vk.physical)
                .unwrap();
            assert!(exts.iter().any(|e| e.extension_name_as_c_str() == Ok(name)));
            let prio = [1.0];
            let queues = [vk::DeviceQueueCreateInfo::default()
                .queue_family_index(0)
                .queue_priorities(&prio)];
            let names = [name.as_ptr()];
            let info = vk::DeviceCreateInfo::default()
                .queue_create_infos(&queues)
                .enabled_extension_names(&names);
            let device = vk
                .instance
                .create_device(vk.physical, &info, None)
                .expect("a device with VK_EXT_load_store_op_none");
            device.destroy_device(None);
        }
        drop_ok(env, Profile::Nvidia);
    });
}

/// Where a GPU leaves coarse fragments: at the end of the pass instance, so a copy recorded in
/// the same command buffer right after the pass (the example's `--dump`) reads the blocks, and so
/// does a later submit. And what they hold: the shader's value at the centre of the fragment
/// area (Vulkan, "Interpolation Decorations"; `FragCoord` is the fragment's centre), here the
/// gradient (x / 64, y / 64) at the block's centre, within one 8-bit step, which a block filled
/// with its top-left pixel misses by 1.5 / 64 (4×4) or 0.5 / 64 (2×2) of the range: 6 or 2 steps.
/// Codes: 1×1 on the left half, 4×4 on the right (the AMD profile clamps it to 2×2); the
/// reference is the same gradient drawn without a shading-rate attachment.
#[test]
fn a_read_back_in_the_same_command_buffer_sees_the_blocks_shaded_at_their_centres() {
    for (profile, texel, block) in [(Profile::Nvidia, 16, 4), (Profile::Amd, 8, 2)] {
        for path in [Path::RenderPass, Path::Dynamic] {
            with_vk(profile, |env, vk| {
                let dev = vk.device(true);
                let n = SIZE / texel;
                let codes = (0..n * n)
                    .map(|i| if i % n < n / 2 { 0 } else { 0b1010 })
                    .collect();
                let full = draw_case(
                    &dev,
                    &Case {
                        gradient: true,
                        ..Case::new(Path::Plain, texel)
                    },
                );
                let drawn = draw_case(
                    &dev,
                    &Case {
                        gradient: true,
                        codes,
                        ..Case::new(path, texel)
                    },
                );
                let px = |p: &[u8], x: u32, y: u32| {
                    let i = ((y * SIZE + x) * 4) as usize;
                    [p[i], p[i + 1], p[i + 2], p[i + 3]]
                };
                // The gradient's 8-bit value at the centre of the block holding `p`.
                let centre = |p: u32| {
                    let c = f64::from(p / block * block) + f64::from(block) / 2.0;
                    c / 64.0 * 255.0
                };
                for y in 0..SIZE {
                    for x in 0..SIZE {
                        let what = format!("{profile:?} {path:?} ({x},{y})");
                        let full_px = px(&full.pixels, x, y);
                        for (when, got) in [
                            ("same command buffer", px(&drawn.pixels, x, y)),
                            ("later submit", px(&drawn.after, x, y)),
                        ] {
                            if x < SIZE / 2 {
                                assert_eq!(got, full_px, "{when} {what}");
                                continue;
                            }
                            let [r, g] = [x, y].map(centre);
                            assert!(
                                (f64::from(got[0]) - r).abs() <= 1.0
                                    && (f64::from(got[1]) - g).abs() <= 1.0
                                    && got[2..] == full_px[2..],
                                "{when} {what}: {got:?}, the gradient at the block's centre \
                                 ({r:.1}, {g:.1}), full rate {full_px:?}"
                            );
                        }
                    }
                }
                // The gradient differs between neighbours, so the comparison shows something.
                assert_ne!(px(&full.pixels, 40, 40), px(&full.pixels, 41, 40));
                let blocks = fovea_vkdouble::blocks::uniform_share(
                    &drawn.pixels,
                    [SIZE, SIZE],
                    4,
                    block,
                    |x, _| x >= SIZE / 2,
                );
                assert_eq!(blocks, Some(1.0), "{profile:?} {path:?}");
                let plain = fovea_vkdouble::blocks::uniform_share(
                    &full.pixels,
                    [SIZE, SIZE],
                    4,
                    block,
                    |x, _| x >= SIZE / 2,
                );
                assert_eq!(plain, Some(0.0), "{profile:?} {path:?}");
                drop(dev);
                drop_ok(env, profile);
            });
        }
    }
}
