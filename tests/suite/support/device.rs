//! The Vulkan stack the `vk::` and `both::` modules test on, and its one test device.
//!
//! Stack: the test → fovea's layer (optional) → VK_LAYER_KHRONOS_validation →
//! VK_LAYER_FOVEA_shading_rate_double → lavapipe. The double makes lavapipe look like a desktop
//! GPU with shading-rate attachments (profiles `nvidia`: 16×16 texels, `amd`: 8×8; `none`:
//! lavapipe as it is) and records what reaches it; validation checks every call fovea passes down
//! against that device. [`env`] writes both manifests once per process to a temporary folder named
//! by `VK_ADD_LAYER_PATH` and serialises the tests (they share the process environment, the
//! validation messages and the double's records); [`Vk`] is an instance on that stack with
//! lavapipe's physical device, [`Vk::device_with`] a device on it with the [`Features`] a test
//! needs, and [`Dev`] that device with a queue, a command pool and its teardown.
//!
//! Missing system pieces (loader, lavapipe, validation layer, the built libraries) skip, or fail
//! under `FOVEA_REQUIRE_SYSTEM=1`.

use std::ffi::{c_void, CStr, CString};
use std::sync::{Mutex, MutexGuard, OnceLock};

use ash::vk;
use fovea_harness::skip;
use fovea_vkdouble::{Loaded, Profile};
use serde_json::json;

use super::vulkan::{allocate_info, image_info, range, spv};

const VALIDATION: &CStr = c"VK_LAYER_KHRONOS_validation";
pub const FDM: &CStr = c"VK_EXT_fragment_density_map";

static SERIAL: Mutex<()> = Mutex::new(());
static MESSAGES: Mutex<Vec<String>> = Mutex::new(Vec::new());

fn fovea_layer() -> CString {
    CString::new(fovea_abi::VK_LAYER_NAME).expect("no NUL")
}

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

pub fn take_messages() -> Vec<String> {
    std::mem::take(&mut *MESSAGES.lock().unwrap_or_else(|e| e.into_inner()))
}

pub fn assert_no_messages() {
    let m = take_messages();
    assert!(
        m.is_empty(),
        "validation reported {} message(s):\n{}",
        m.len(),
        m.join("\n")
    );
}

/// Validation 1.3.239 checks the shading-rate attachment stage (the same bit as NVIDIA's
/// shading-rate-image stage) against `shadingRateImage` alone, as the specification of its day
/// worded it; later versions also accept `attachmentFragmentShadingRate`
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkCmdPipelineBarrier.html>,
/// VUID-vkCmdPipelineBarrier-dstStageMask-07318). Those messages, and nothing else, are allowed.
pub fn assert_only_stage_false_positives() {
    let others = take_real_messages();
    assert!(others.is_empty(), "validation reported: {others:#?}");
}

/// The messages so far, less validation 1.3.239's stage false positives (see
/// [`assert_only_stage_false_positives`]) and its threading checks' reports on a handle it says
/// it lost ([`lost_handles`]).
pub fn take_real_messages() -> Vec<String> {
    real(take_messages())
}

/// [`take_real_messages`]'s filter.
fn real(all: Vec<String>) -> Vec<String> {
    let lost = lost_handles(&all);
    all.into_iter()
        .filter(|m| !m.contains("when the device does not have shadingRate feature enabled"))
        .filter(|m| {
            !lost
                .iter()
                .any(|h| m.contains("UNASSIGNED-Threading") && m.contains(h))
        })
        .collect()
}

/// Handles the threading checks report as unknown ("Couldn't find VkDeviceMemory Object 0x…").
/// With unique handles off, as real drivers hand them out, a handle one thread frees is given
/// again to another thread's allocation before the checks' record of the free has run, so the
/// checks drop the new object and then report its uses as simultaneous with the old one's. That
/// is the checks' own race, and validation says so in this message; a real simultaneous use of
/// one live object is reported without it and still fails the test.
fn lost_handles(messages: &[String]) -> Vec<String> {
    messages
        .iter()
        .filter_map(|m| {
            let rest = m.split("Couldn't find ").nth(1)?;
            let handle = rest.split_whitespace().nth(2)?.trim_end_matches('.');
            handle.starts_with("0x").then(|| handle.to_string())
        })
        .collect()
}

pub struct Env {
    pub entry: ash::Entry,
    pub double: Loaded,
}

/// Fails the test where the double recorded a misuse a driver would refuse: every test that runs
/// on the double asserts that at its end (the guard [`env`] returns) and whenever it makes a new
/// instance ([`Vk::new`]), which forgets the records. A test that provokes misuse on purpose reads
/// and clears them itself.
pub fn assert_no_double_errors(env: &Env) {
    if std::thread::panicking() {
        return;
    }
    let errors = env.double.errors();
    assert!(
        errors.is_empty(),
        "the shading-rate double refused {} call(s), as a driver would:\n{}",
        errors.len(),
        errors.join("\n")
    );
}

/// What [`env`] returns with the environment: the suite's serialisation, and at its end the
/// check that the double recorded no misuse ([`assert_no_double_errors`]).
pub struct Serial {
    _lock: MutexGuard<'static, ()>,
    env: &'static Env,
}

impl Drop for Serial {
    fn drop(&mut self) {
        if std::thread::panicking() {
            self.env.double.clear();
            return;
        }
        assert_no_double_errors(self.env);
    }
}

/// Both manifests, `VK_ADD_LAYER_PATH`, the loader and the double's loaded copy; once per process.
pub fn env() -> Option<(Serial, &'static Env)> {
    let guard = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    static ENV: OnceLock<Result<Env, String>> = OnceLock::new();
    let env = ENV.get_or_init(|| {
        let double_lib = fovea_vkdouble::find_library()?;
        let fovea_lib = fovea_harness::artifact("libfovea.so")?
            .canonicalize()
            .map_err(|e| e.to_string())?;
        let dir = std::env::temp_dir().join(format!("fovea-vklayer-{}", std::process::id()));
        fovea_vkdouble::write_manifest(&dir, &double_lib).map_err(|e| e.to_string())?;
        // The checked-in manifest, pointed at this build's library.
        let checked_in = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("manifest/vulkan/VK_LAYER_FOVEA_fragment_density_map.json");
        let mut manifest: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&checked_in).map_err(|e| e.to_string())?)
                .map_err(|e| e.to_string())?;
        manifest["layer"]["library_path"] = json!(fovea_lib.to_string_lossy());
        std::fs::write(
            dir.join("VK_LAYER_FOVEA_fragment_density_map.json"),
            manifest.to_string(),
        )
        .map_err(|e| e.to_string())?;
        // Set before the loader first reads the environment, every test serialised behind SERIAL.
        std::env::set_var("VK_ADD_LAYER_PATH", &dir);
        // SAFETY: loading libvulkan runs its initialisers, as any Vulkan application does.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| format!("no Vulkan loader ({e})"))?;
        // SAFETY: a plain query.
        let layers = unsafe { entry.enumerate_instance_layer_properties() }
            .map_err(|e| format!("vkEnumerateInstanceLayerProperties: {e}"))?;
        let ours = fovea_layer();
        for want in [VALIDATION, fovea_vkdouble::LAYER_NAME, ours.as_c_str()] {
            if !layers.iter().any(|l| l.layer_name_as_c_str() == Ok(want)) {
                return Err(format!("{want:?} is not available"));
            }
        }
        let double = Loaded::open(&double_lib)?;
        Ok(Env { entry, double })
    });
    match env {
        Ok(e) => Some((
            Serial {
                _lock: guard,
                env: e,
            },
            e,
        )),
        Err(e) => {
            skip(e);
            None
        }
    }
}

/// The stack on `profile` with fovea's layer on top: [`env`] and an instance on it ([`Vk::new`]);
/// `None` where a system piece is missing (the test then skips).
pub fn with_fovea(profile: Profile) -> Option<(Serial, &'static Env, Vk)> {
    let (serial, env) = env()?;
    let vk = Vk::new(env, profile, true)?;
    Some((serial, env, vk))
}

/// An instance with the stack above (fovea's layer optional) and lavapipe's physical device.
pub struct Vk {
    pub instance: ash::Instance,
    debug_utils: ash::ext::debug_utils::Instance,
    messenger: vk::DebugUtilsMessengerEXT,
    pub physical: vk::PhysicalDevice,
}

impl Vk {
    pub fn new(env: &Env, profile: Profile, with_fovea: bool) -> Option<Vk> {
        assert_no_double_errors(env);
        env.double.set_profile(Some(profile));
        env.double.clear();
        take_messages();
        let ours = fovea_layer();
        let mut layers = vec![VALIDATION.as_ptr(), fovea_vkdouble::LAYER_NAME.as_ptr()];
        if with_fovea {
            layers.insert(0, ours.as_ptr());
        }
        let exts = [
            ash::ext::debug_utils::NAME.as_ptr(),
            ash::ext::validation_features::NAME.as_ptr(),
        ];
        let disabled = [vk::ValidationFeatureDisableEXT::UNIQUE_HANDLES];
        let mut features = vk::ValidationFeaturesEXT::default()
            .disabled_validation_features(&disabled)
            .enabled_validation_features(fovea_harness::validation_enables());
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
                .expect("vkCreateInstance");
            let debug_utils = ash::ext::debug_utils::Instance::new(&env.entry, &instance);
            let messenger = debug_utils
                .create_debug_utils_messenger(&messenger_info, None)
                .expect("messenger");
            let physical = instance
                .enumerate_physical_devices()
                .unwrap_or_default()
                .into_iter()
                .find(|&p| {
                    instance
                        .get_physical_device_properties(p)
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
                skip("lavapipe (llvmpipe) is not installed");
                return None;
            }
            Some(vk)
        }
    }

    pub fn fdm_properties(&self) -> vk::PhysicalDeviceFragmentDensityMapPropertiesEXT<'static> {
        let mut fdm = vk::PhysicalDeviceFragmentDensityMapPropertiesEXT::default();
        let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut fdm);
        // SAFETY: structs live across the call.
        unsafe {
            self.instance
                .get_physical_device_properties2(self.physical, &mut p2)
        };
        fdm.p_next = std::ptr::null_mut();
        fdm
    }

    /// A device with one queue of family 0, `exts`, the Vulkan 1.3 features fovea's users enable
    /// (dynamic rendering, synchronization2), and the given extra feature struct.
    pub fn device(
        &self,
        exts: &[&CStr],
        extra: Option<&mut dyn vk::ExtendsDeviceCreateInfo>,
    ) -> Result<ash::Device, vk::Result> {
        self.try_device_with(exts, Features::default(), extra)
    }

    /// [`Vk::device`] with `features` besides; a failed `vkCreateDevice` fails the test with
    /// validation's messages.
    pub fn device_with(
        &self,
        exts: &[&CStr],
        features: Features,
        extra: Option<&mut dyn vk::ExtendsDeviceCreateInfo>,
    ) -> ash::Device {
        self.try_device_with(exts, features, extra)
            .unwrap_or_else(|e| panic!("vkCreateDevice: {e}; {:?}", take_messages()))
    }

    /// A device fovea emulates density maps on: [`Vk::device_with`] [`Features::FDM`].
    pub fn fdm_device(
        &self,
        exts: &[&CStr],
        extra: Option<&mut dyn vk::ExtendsDeviceCreateInfo>,
    ) -> ash::Device {
        self.device_with(exts, Features::FDM, extra)
    }

    /// [`Vk::device_with`], its result as `vkCreateDevice` returned it.
    pub fn try_device_with(
        &self,
        exts: &[&CStr],
        features: Features,
        extra: Option<&mut dyn vk::ExtendsDeviceCreateInfo>,
    ) -> Result<ash::Device, vk::Result> {
        self.try_device_queues(exts, features, extra, 1)
    }

    /// [`Vk::try_device_with`] with `count` queues of family 0 (the double offers more than
    /// lavapipe's one where a test asks it to, `fovea_vkdouble::Loaded::set_queues`).
    pub fn try_device_queues(
        &self,
        exts: &[&CStr],
        features: Features,
        extra: Option<&mut dyn vk::ExtendsDeviceCreateInfo>,
        count: u32,
    ) -> Result<ash::Device, vk::Result> {
        let prio = vec![1.0; count as usize];
        let queues = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(0)
            .queue_priorities(&prio)];
        let names: Vec<_> = features
            .fdm
            .then_some(FDM)
            .into_iter()
            .chain(exts.iter().copied())
            .map(CStr::as_ptr)
            .collect();
        let mut fdm = fdm_features();
        let mut v11 = vk::PhysicalDeviceVulkan11Features::default().multiview(true);
        let mut v12 = vk::PhysicalDeviceVulkan12Features::default().imageless_framebuffer(true);
        let mut v13 = vk::PhysicalDeviceVulkan13Features::default()
            .dynamic_rendering(true)
            .synchronization2(true);
        let mut info = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queues)
            .enabled_extension_names(&names);
        if let Some(extra) = extra {
            info = info.push_next(extra);
        }
        if features.fdm {
            info = info.push_next(&mut fdm);
        }
        if features.multiview {
            info = info.push_next(&mut v12).push_next(&mut v11);
        }
        // Vulkan 1.3 features pushed last, ahead of the one the layer removes in the chain: the
        // copy must keep the application's tail.
        info = info.push_next(&mut v13);
        // SAFETY: every struct lives across the call.
        unsafe { self.instance.create_device(self.physical, &info, None) }
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

pub fn fdm_image_info() -> vk::ImageCreateInfo<'static> {
    image_info(
        vk::Format::R8G8_UNORM,
        8,
        2,
        vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT | vk::ImageUsageFlags::TRANSFER_DST,
    )
}

/// What a test device enables besides one queue of family 0 and Vulkan 1.3's dynamic rendering
/// and synchronization2.
#[derive(Clone, Copy, Debug, Default)]
pub struct Features {
    /// `VK_EXT_fragment_density_map` with [`fdm_features`]: a device fovea emulates density maps
    /// on.
    pub fdm: bool,
    /// Vulkan 1.1's multiview and 1.2's imageless framebuffers.
    pub multiview: bool,
}

impl Features {
    /// Density maps.
    pub const FDM: Features = Features {
        fdm: true,
        multiview: false,
    };
    /// Density maps, multiview and imageless framebuffers.
    pub const FDM_MULTIVIEW: Features = Features {
        fdm: true,
        multiview: true,
    };
}

/// The density-map features the tests' devices enable: maps, and maps on non-subsampled images.
pub fn fdm_features() -> vk::PhysicalDeviceFragmentDensityMapFeaturesEXT<'static> {
    vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default()
        .fragment_density_map(true)
        .fragment_density_map_non_subsampled_images(true)
}

/// The double's device on `profile` as fovea's injection model takes it: the texel, whether its
/// maps are layered, the largest fragment and the rates it offers for one sample.
pub fn inject_device(profile: Profile) -> fovea_model::inject::Device {
    fovea_model::inject::Device {
        texel: [profile.texel().width, profile.texel().height],
        layered: profile.layered(),
        max_fragment: [profile.max_fragment(); 2],
        rates: profile
            .rates()
            .iter()
            .filter(|(_, s)| s.contains(vk::SampleCountFlags::TYPE_1))
            .map(|(e, _)| [e.width, e.height])
            .collect(),
    }
}

/// A test device: one queue of family 0, a command pool on it, and the physical device's memory
/// types. Made by [`Dev::new`]; torn down by [`Dev::destroy`].
pub struct Dev {
    pub d: ash::Device,
    pub queue: vk::Queue,
    pub pool: vk::CommandPool,
    pub memory: vk::PhysicalDeviceMemoryProperties,
}

impl Dev {
    /// `d`, made on `vk` with a queue of family 0 ([`Vk::device_with`]), with that queue, a
    /// command pool on it and the physical device's memory types.
    pub fn new(vk: &Vk, d: ash::Device) -> Dev {
        // SAFETY: `d` is alive and has a queue of family 0.
        unsafe {
            let queue = d.get_device_queue(0, 0);
            let pool = command_pool(&d);
            let memory = vk
                .instance
                .get_physical_device_memory_properties(vk.physical);
            Dev {
                d,
                queue,
                pool,
                memory,
            }
        }
    }

    /// An optimally tiled image of `side`×`side` texels and `layers` layers with device-local
    /// memory, and a view of every layer (2D for one layer, 2D array for more).
    pub fn image(
        &self,
        format: vk::Format,
        side: u32,
        layers: u32,
        usage: vk::ImageUsageFlags,
    ) -> (vk::Image, vk::DeviceMemory, vk::ImageView) {
        self.image_with_flags(format, side, layers, usage, vk::ImageCreateFlags::empty())
    }

    /// [`Dev::image`] created with `flags`.
    pub fn image_with_flags(
        &self,
        format: vk::Format,
        side: u32,
        layers: u32,
        usage: vk::ImageUsageFlags,
        flags: vk::ImageCreateFlags,
    ) -> (vk::Image, vk::DeviceMemory, vk::ImageView) {
        // SAFETY: the device is alive; structs live across the calls.
        unsafe {
            let d = &self.d;
            let image = d
                .create_image(&image_info(format, side, layers, usage).flags(flags), None)
                .unwrap_or_else(|e| panic!("vkCreateImage: {e}; {:?}", take_messages()));
            let req = d.get_image_memory_requirements(image);
            let memory = d
                .allocate_memory(
                    &allocate_info(&self.memory, req, vk::MemoryPropertyFlags::DEVICE_LOCAL),
                    None,
                )
                .expect("vkAllocateMemory");
            d.bind_image_memory(image, memory, 0).expect("bind");
            let ty = if layers > 1 {
                vk::ImageViewType::TYPE_2D_ARRAY
            } else {
                vk::ImageViewType::TYPE_2D
            };
            let view = d
                .create_image_view(
                    &vk::ImageViewCreateInfo::default()
                        .image(image)
                        .view_type(ty)
                        .format(format)
                        .subresource_range(range(0, layers)),
                    None,
                )
                .expect("vkCreateImageView");
            (image, memory, view)
        }
    }

    /// A [`ComputePipeline`] of the SPIR-V `code`: binding 0 one `ty` descriptor, `push` bytes of
    /// push constants.
    pub fn compute_pipeline(
        &self,
        code: &[u8],
        ty: vk::DescriptorType,
        push: u32,
    ) -> ComputePipeline {
        // SAFETY: the device is alive; structs live across the calls.
        unsafe {
            let d = &self.d;
            let bindings = [vk::DescriptorSetLayoutBinding::default()
                .binding(0)
                .descriptor_type(ty)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::COMPUTE)];
            let set_layout = d
                .create_descriptor_set_layout(
                    &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                    None,
                )
                .expect("set layout");
            let ranges = [vk::PushConstantRange {
                stage_flags: vk::ShaderStageFlags::COMPUTE,
                offset: 0,
                size: push,
            }];
            let set_layouts = [set_layout];
            let layout = d
                .create_pipeline_layout(
                    &vk::PipelineLayoutCreateInfo::default()
                        .set_layouts(&set_layouts)
                        .push_constant_ranges(&ranges),
                    None,
                )
                .expect("pipeline layout");
            let code = spv(code);
            let module = d
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&code), None)
                .expect("module");
            let info = [vk::ComputePipelineCreateInfo::default()
                .stage(
                    vk::PipelineShaderStageCreateInfo::default()
                        .stage(vk::ShaderStageFlags::COMPUTE)
                        .module(module)
                        .name(c"main"),
                )
                .layout(layout)];
            let pipeline = d
                .create_compute_pipelines(vk::PipelineCache::null(), &info, None)
                .expect("compute pipeline")[0];
            d.destroy_shader_module(module, None);
            let sizes = [vk::DescriptorPoolSize {
                ty,
                descriptor_count: 1,
            }];
            let pool = d
                .create_descriptor_pool(
                    &vk::DescriptorPoolCreateInfo::default()
                        .max_sets(1)
                        .pool_sizes(&sizes),
                    None,
                )
                .expect("pool");
            let set = d
                .allocate_descriptor_sets(
                    &vk::DescriptorSetAllocateInfo::default()
                        .descriptor_pool(pool)
                        .set_layouts(&set_layouts),
                )
                .expect("set")[0];
            ComputePipeline {
                set_layout,
                layout,
                pipeline,
                pool,
                set,
            }
        }
    }

    /// A primary command buffer from the pool, recording.
    pub fn begin(&self) -> vk::CommandBuffer {
        self.begin_in(self.pool, vk::CommandBufferUsageFlags::empty())
    }

    /// Another command pool on the queue's family, for a thread of its own; the caller destroys
    /// it.
    pub fn command_pool(&self) -> vk::CommandPool {
        command_pool(&self.d)
    }

    /// A primary command buffer from `pool` (this device's, used by this thread only), recording
    /// with `flags`.
    pub fn begin_in(
        &self,
        pool: vk::CommandPool,
        flags: vk::CommandBufferUsageFlags,
    ) -> vk::CommandBuffer {
        let cb = allocate(&self.d, pool);
        // SAFETY: the pool is this device's and used by this thread only.
        unsafe {
            self.d
                .begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default().flags(flags))
                .expect("vkBeginCommandBuffer");
            cb
        }
    }

    /// Ends `cb`, submits it with `vkQueueSubmit` and waits for the queue.
    pub fn submit(&self, cb: vk::CommandBuffer) {
        // SAFETY: `cb` is recording on this device; the queue is this thread's.
        unsafe {
            self.d.end_command_buffer(cb).expect("vkEndCommandBuffer");
            let cbs = [cb];
            self.d
                .queue_submit(
                    self.queue,
                    &[vk::SubmitInfo::default().command_buffers(&cbs)],
                    vk::Fence::null(),
                )
                .expect("vkQueueSubmit");
            self.d.queue_wait_idle(self.queue).expect("vkQueueWaitIdle");
        }
    }

    /// The end of a test on this device: the device destroyed ([`Dev::destroy`]), the double's
    /// records free of misuse, the instance destroyed, and validation silent but for its stage
    /// false positives ([`assert_only_stage_false_positives`]), which includes any object left
    /// alive at `vkDestroyDevice`.
    pub fn finish(self, env: &Env, vk: Vk) {
        self.destroy();
        assert_eq!(env.double.errors(), Vec::<String>::new());
        drop(vk);
        assert_only_stage_false_positives();
    }

    /// Waits for the device, then destroys the pool and the device (everything else made from
    /// it must be gone).
    pub fn destroy(self) {
        // SAFETY: the queue is idle; nothing else made from the device is left.
        unsafe {
            self.d.device_wait_idle().expect("idle");
            self.d.destroy_command_pool(self.pool, None);
            self.d.destroy_device(None);
        }
    }
}

/// A command pool on queue family 0 of `d`.
fn command_pool(d: &ash::Device) -> vk::CommandPool {
    // SAFETY: `d` is alive (a borrowed device); the struct lives across the call.
    unsafe {
        d.create_command_pool(
            &vk::CommandPoolCreateInfo::default().queue_family_index(0),
            None,
        )
    }
    .expect("vkCreateCommandPool")
}

/// A command pool on queue family `family` of `d` whose command buffers may be reset one by one
/// (`VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT`); the caller destroys it.
pub fn resettable_pool(d: &ash::Device, family: u32) -> vk::CommandPool {
    // SAFETY: `d` is alive (a borrowed device); the struct lives across the call.
    unsafe {
        d.create_command_pool(
            &vk::CommandPoolCreateInfo::default()
                .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER)
                .queue_family_index(family),
            None,
        )
    }
    .expect("vkCreateCommandPool")
}

/// One primary command buffer from `pool` (`d`'s, used by this thread only).
pub fn allocate(d: &ash::Device, pool: vk::CommandPool) -> vk::CommandBuffer {
    // SAFETY: the pool is `d`'s and this thread's.
    unsafe {
        d.allocate_command_buffers(
            &vk::CommandBufferAllocateInfo::default()
                .command_pool(pool)
                .level(vk::CommandBufferLevel::PRIMARY)
                .command_buffer_count(1),
        )
    }
    .expect("vkAllocateCommandBuffers")[0]
}

/// A compute pipeline entered at `main`, with one descriptor set (from a pool of its own) of one
/// binding 0, and push constants; made by [`Dev::compute_pipeline`], its set written by the caller.
pub struct ComputePipeline {
    pub set_layout: vk::DescriptorSetLayout,
    pub layout: vk::PipelineLayout,
    pub pipeline: vk::Pipeline,
    pub pool: vk::DescriptorPool,
    pub set: vk::DescriptorSet,
}

impl ComputePipeline {
    /// Destroys it; nothing may use it any more.
    pub fn destroy(self, d: &ash::Device) {
        // SAFETY: the caller's promise; each object destroyed once.
        unsafe {
            d.destroy_descriptor_pool(self.pool, None);
            d.destroy_pipeline(self.pipeline, None);
            d.destroy_pipeline_layout(self.layout, None);
            d.destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

/// The threading checks' own race is dropped only for the handle validation says it lost: the
/// messages of a run that met it (`vk::threads`, validation 1.3.239), and one real report kept.
#[test]
fn only_threading_reports_on_a_lost_handle_are_dropped() {
    let lost = "0x7f99709d1b90";
    let run = [
        format!("ERROR: Validation Error: [ UNASSIGNED-Threading-MultipleThreads ] Object 0: handle = {lost}, type = VK_OBJECT_TYPE_DEVICE_MEMORY; | THREADING ERROR : vkMapMemory(): object of type VkDeviceMemory is simultaneously used in thread 1 and thread 2"),
        format!("ERROR: Validation Error: [ UNASSIGNED-Threading-Info ] Object 0: handle = {lost}, type = VK_OBJECT_TYPE_DEVICE_MEMORY; | Couldn't find VkDeviceMemory Object {lost}. This should not happen and may indicate a bug in the application."),
        "ERROR: Validation Error: [ UNASSIGNED-Threading-MultipleThreads ] Object 0: handle = 0x55, type = VK_OBJECT_TYPE_COMMAND_POOL; | THREADING ERROR : vkAllocateCommandBuffers(): object of type VkCommandPool is simultaneously used in thread 1 and thread 2".to_string(),
    ];
    assert_eq!(lost_handles(&run), vec![lost.to_string()]);
    assert_eq!(real(run.to_vec()), vec![run[2].clone()]);
}
