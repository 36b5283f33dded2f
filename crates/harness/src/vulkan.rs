//! The Vulkan side of tests that run a session on a real device: lavapipe picked in the simulated
//! runtime, the Khronos validation layer, and a VkInstance and VkDevice made through
//! XR_KHR_vulkan_enable2 the way an application makes them.
//!
//! Every message the validation layer reports (warnings and errors) is collected, so a test can
//! require that Vulkan said nothing about the application, fovea or the runtime. The collection is
//! process-wide (the callback is a plain function, and messages come while the instance is created
//! and destroyed too), so tests in one binary that make validated devices must run one at a time.
//!
//! Functions that find a system component missing return `Err` with the reason, for the test to
//! hand to [`crate::skip`] after it has cleaned up what it made.

use std::ffi::{c_void, CStr};
use std::ptr::{null, null_mut};
use std::sync::{Mutex, Once};

use ash::vk;
use ash::vk::Handle as _;
use openxr_sys as xr;

use crate::lookup;

/// The Khronos Vulkan validation layer.
pub const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// What the validation layer reported since the last [`take_messages`].
static MESSAGES: Mutex<Vec<String>> = Mutex::new(Vec::new());

unsafe extern "system" fn on_message(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    _user: *mut c_void,
) -> vk::Bool32 {
    let text = CStr::from_ptr((*data).p_message).to_string_lossy();
    let mut messages = MESSAGES.lock().unwrap_or_else(|e| e.into_inner());
    messages.push(format!("{severity:?}: {text}"));
    vk::FALSE
}

/// The validation messages collected so far; the collection starts empty again.
pub fn take_messages() -> Vec<String> {
    std::mem::take(&mut *MESSAGES.lock().unwrap_or_else(|e| e.into_inner()))
}

/// Requires that the validation layer reported nothing since the last [`take_messages`].
pub fn assert_no_messages() {
    let messages = take_messages();
    assert!(
        messages.is_empty(),
        "validation reported {} message(s):\n{}",
        messages.len(),
        messages.join("\n")
    );
}

/// Makes the simulated runtime pick lavapipe (llvmpipe) among the system's devices, so results do
/// not depend on the machine's GPU. Call it before anything reads the environment: the variable is
/// set once per process, and `set_var` races with readers on other threads.
pub fn pick_lavapipe() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| std::env::set_var("FOVEA_SIM_VK_DEVICE", "llvmpipe"));
}

/// Mesa's lavapipe ICD manifest in the Vulkan loader's system folders: Debian 12 names it
/// `lvp_icd.x86_64.json`, Debian 13 `lvp_icd.json`. `None` where Mesa's Vulkan drivers are absent.
pub fn lavapipe_icd() -> Option<std::path::PathBuf> {
    ["/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d"]
        .iter()
        .filter_map(|d| std::fs::read_dir(d).ok())
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("lvp_icd") && n.ends_with(".json"))
        })
        .min()
}

/// The system Vulkan loader, or why there is none.
pub fn entry() -> Result<ash::Entry, String> {
    // SAFETY: loading libvulkan runs its initialisers, as any Vulkan application does.
    unsafe { ash::Entry::load() }.map_err(|e| format!("no Vulkan loader ({e})"))
}

/// The system Vulkan loader where it has the validation layer, or why not.
pub fn validated_entry() -> Result<ash::Entry, String> {
    let entry = entry()?;
    // SAFETY: a plain query of the loader.
    let layers = unsafe { entry.enumerate_instance_layer_properties() }.unwrap_or_default();
    if !layers
        .iter()
        .any(|l| l.layer_name_as_c_str() == Ok(VALIDATION_LAYER))
    {
        return Err("VK_LAYER_KHRONOS_validation is not installed".into());
    }
    Ok(entry)
}

/// A function through `gipa`; the runtime must have it (the instance enabled its extension).
///
/// # Safety
/// `F` must be the function type the name implies.
unsafe fn func<F: Copy>(
    gipa: xr::pfn::GetInstanceProcAddr,
    instance: xr::Instance,
    name: &CStr,
) -> F {
    lookup(gipa, instance, name).unwrap_or_else(|r| panic!("{name:?}: {r:?}"))
}

/// How [`Vulkan::through_xr_with`] makes the instance and device.
#[derive(Clone, Copy, Debug)]
pub struct Options<'a> {
    /// The instance's layers, first closest to the application; the validation layer must be
    /// among them for the messages to be collected.
    pub layers: &'a [&'a CStr],
    /// `VkApplicationInfo::apiVersion`.
    pub api_version: u32,
    /// Enables the Vulkan 1.1 `multiview` feature, which render passes with view masks need
    /// (ignored with `dynamic_rendering` or `device_next`, whose feature structs the caller owns).
    pub multiview: bool,
    /// Enables Vulkan 1.3's `dynamicRendering` and `synchronization2` on the device (the
    /// instance's `api_version` must be 1.3).
    pub dynamic_rendering: bool,
    /// Device extensions the application enables itself.
    pub device_extensions: &'a [&'a CStr],
    /// Chained in front of the device create info (`NULL` for none): the application's own
    /// feature structs. Must outlive the call.
    pub device_next: *const c_void,
    /// Queues of the graphics family the device gets (1 where 0).
    pub queues: u32,
}

impl Default for Options<'_> {
    /// The validation layer alone, Vulkan 1.1, a device with no extensions or features.
    fn default() -> Self {
        Options {
            layers: &[VALIDATION_LAYER],
            api_version: vk::API_VERSION_1_1,
            multiview: false,
            dynamic_rendering: false,
            device_extensions: &[],
            device_next: null(),
            queues: 1,
        }
    }
}

/// The application's Vulkan objects, made through XR_KHR_vulkan_enable2 under the validation layer.
pub struct Vulkan {
    /// Keeps libvulkan loaded while the instance lives.
    pub entry: ash::Entry,
    pub instance: ash::Instance,
    pub physical_device: vk::PhysicalDevice,
    pub device: ash::Device,
    /// The graphics queue family; the device has [`Options::queues`] queues in it.
    pub family: u32,
    /// What xrGetVulkanGraphicsRequirements2KHR returned.
    pub requirements: xr::GraphicsRequirementsVulkanKHR,
    debug_utils: ash::ext::debug_utils::Instance,
    messenger: vk::DebugUtilsMessengerEXT,
}

impl Vulkan {
    /// Creates the VkInstance (validation layer, a messenger chained at creation and one after it,
    /// so nothing the instance reports goes unheard) and a VkDevice with one graphics queue, both
    /// through the runtime behind `gipa` for `instance`'s system `sys`, as the spec orders it:
    /// requirements, instance, physical device, device. `entry` should come from
    /// [`validated_entry`].
    ///
    /// `Err` when the runtime finds no device (lavapipe missing), with the instance made so far
    /// destroyed again. Panics, as a failed assertion, on any other failure.
    pub fn through_xr(
        entry: &ash::Entry,
        gipa: xr::pfn::GetInstanceProcAddr,
        instance: xr::Instance,
        sys: xr::SystemId,
    ) -> Result<Vulkan, String> {
        Vulkan::through_xr_with(entry, gipa, instance, sys, &Options::default())
    }

    /// As [`Vulkan::through_xr`], with the instance's layers and version and the device's
    /// features and extensions as `options` says.
    pub fn through_xr_with(
        entry: &ash::Entry,
        gipa: xr::pfn::GetInstanceProcAddr,
        instance: xr::Instance,
        sys: xr::SystemId,
        options: &Options<'_>,
    ) -> Result<Vulkan, String> {
        // SAFETY: each function is looked up as the type its name implies; every struct passed
        // below lives across its call; handles from the runtime are loaded before use.
        unsafe {
            let requirements_fn: xr::pfn::GetVulkanGraphicsRequirements2KHR =
                func(gipa, instance, c"xrGetVulkanGraphicsRequirements2KHR");
            let create_instance: xr::pfn::CreateVulkanInstanceKHR =
                func(gipa, instance, c"xrCreateVulkanInstanceKHR");
            let graphics_device: xr::pfn::GetVulkanGraphicsDevice2KHR =
                func(gipa, instance, c"xrGetVulkanGraphicsDevice2KHR");
            let create_device: xr::pfn::CreateVulkanDeviceKHR =
                func(gipa, instance, c"xrCreateVulkanDeviceKHR");

            let mut requirements = xr::GraphicsRequirementsVulkanKHR {
                ty: xr::GraphicsRequirementsVulkanKHR::TYPE,
                next: null_mut(),
                min_api_version_supported: xr::Version::new(0, 0, 0),
                max_api_version_supported: xr::Version::new(0, 0, 0),
            };
            assert_eq!(
                requirements_fn(instance, sys, &mut requirements),
                xr::Result::SUCCESS
            );

            let mut messenger_info = vk::DebugUtilsMessengerCreateInfoEXT::default()
                .message_severity(
                    vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                        | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
                )
                .message_type(
                    vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                        | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                        | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
                )
                .pfn_user_callback(Some(on_message));
            let app_info = vk::ApplicationInfo::default().api_version(options.api_version);
            let layer_names: Vec<_> = options.layers.iter().map(|l| l.as_ptr()).collect();
            let mut ext_names = vec![ash::ext::debug_utils::NAME.as_ptr()];
            // Handle wrapping off on every validated instance
            // (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkValidationFeatureDisableEXT.html>),
            // so the handles a layer below validation records are the application's. The
            // validation layer keeps that switch in one process-wide variable (`wrap_handles` in its
            // chassis), which an instance created with the feature disabled turns off for good: an
            // instance that still wraps while another test creates one without passes its wrapped
            // handles on unwrapped from then on, and the Vulkan loader dereferences them (a SIGSEGV
            // in vkDestroyDebugUtilsMessengerEXT). With every validated instance alike, tests in one
            // process cannot flip it under each other.
            let disabled = [vk::ValidationFeatureDisableEXT::UNIQUE_HANDLES];
            let mut features = vk::ValidationFeaturesEXT::default()
                .disabled_validation_features(&disabled)
                .enabled_validation_features(crate::validation_enables());
            let mut vk_create = vk::InstanceCreateInfo::default()
                .application_info(&app_info)
                .push_next(&mut messenger_info);
            if options.layers.contains(&VALIDATION_LAYER) {
                ext_names.push(ash::ext::validation_features::NAME.as_ptr());
                vk_create = vk_create.push_next(&mut features);
            }
            let vk_create = vk_create
                .enabled_layer_names(&layer_names)
                .enabled_extension_names(&ext_names);
            let vk_gipa: xr::platform::VkGetInstanceProcAddr =
                std::mem::transmute(entry.static_fn().get_instance_proc_addr);
            let xr_create = xr::VulkanInstanceCreateInfoKHR {
                ty: xr::VulkanInstanceCreateInfoKHR::TYPE,
                next: null(),
                system_id: sys,
                create_flags: xr::VulkanInstanceCreateFlagsKHR::EMPTY,
                pfn_get_instance_proc_addr: Some(vk_gipa),
                vulkan_create_info: &vk_create as *const _ as *const c_void,
                vulkan_allocator: null(),
            };
            let mut raw_instance: xr::platform::VkInstance = null();
            let mut vk_result = 0;
            let r = create_instance(instance, &xr_create, &mut raw_instance, &mut vk_result);
            assert_eq!((r, vk_result), (xr::Result::SUCCESS, 0));
            let vk_instance = ash::Instance::load(
                entry.static_fn(),
                vk::Instance::from_raw(raw_instance as u64),
            );
            let debug_utils = ash::ext::debug_utils::Instance::new(entry, &vk_instance);
            let messenger = debug_utils
                .create_debug_utils_messenger(&messenger_info, None)
                .unwrap();

            let get_info = xr::VulkanGraphicsDeviceGetInfoKHR {
                ty: xr::VulkanGraphicsDeviceGetInfoKHR::TYPE,
                next: null(),
                system_id: sys,
                vulkan_instance: raw_instance,
            };
            let mut raw_pd: xr::platform::VkPhysicalDevice = null();
            if graphics_device(instance, &get_info, &mut raw_pd) != xr::Result::SUCCESS {
                debug_utils.destroy_debug_utils_messenger(messenger, None);
                vk_instance.destroy_instance(None);
                return Err("lavapipe (llvmpipe) is not available".into());
            }
            let physical_device = vk::PhysicalDevice::from_raw(raw_pd as u64);
            let family = vk_instance
                .get_physical_device_queue_family_properties(physical_device)
                .iter()
                .position(|q| q.queue_flags.contains(vk::QueueFlags::GRAPHICS))
                .unwrap() as u32;
            let priorities = vec![1.0; options.queues.max(1) as usize];
            let queue_info = [vk::DeviceQueueCreateInfo::default()
                .queue_family_index(family)
                .queue_priorities(&priorities)];
            let mut v13 = vk::PhysicalDeviceVulkan13Features::default()
                .dynamic_rendering(true)
                .synchronization2(true);
            v13.p_next = options.device_next as *mut c_void;
            let device_exts: Vec<_> = options
                .device_extensions
                .iter()
                .map(|e| e.as_ptr())
                .collect();
            let mut device_create = vk::DeviceCreateInfo::default()
                .queue_create_infos(&queue_info)
                .enabled_extension_names(&device_exts);
            let multiview = vk::PhysicalDeviceMultiviewFeatures::default().multiview(true);
            device_create.p_next = if options.dynamic_rendering {
                &v13 as *const _ as *const c_void
            } else if options.device_next.is_null() && options.multiview {
                &multiview as *const _ as *const c_void
            } else {
                options.device_next
            };
            let app_next = device_create.p_next;
            let xr_device = xr::VulkanDeviceCreateInfoKHR {
                ty: xr::VulkanDeviceCreateInfoKHR::TYPE,
                next: null(),
                system_id: sys,
                create_flags: xr::VulkanDeviceCreateFlagsKHR::EMPTY,
                pfn_get_instance_proc_addr: Some(vk_gipa),
                vulkan_physical_device: raw_pd,
                vulkan_create_info: &device_create as *const _ as *const c_void,
                vulkan_allocator: null(),
            };
            let mut raw_device: xr::platform::VkDevice = null();
            let r = create_device(instance, &xr_device, &mut raw_device, &mut vk_result);
            assert_eq!((r, vk_result), (xr::Result::SUCCESS, 0));
            // The application's create info is untouched: a layer that adds extensions (fovea adds
            // VK_EXT_fragment_density_map) goes down with copies.
            assert_eq!(
                device_create.enabled_extension_count as usize,
                options.device_extensions.len()
            );
            assert_eq!(device_create.p_next, app_next);
            let device = ash::Device::load(
                vk_instance.fp_v1_0(),
                vk::Device::from_raw(raw_device as u64),
            );
            Ok(Vulkan {
                entry: entry.clone(),
                instance: vk_instance,
                physical_device,
                device,
                family,
                requirements,
                debug_utils,
                messenger,
            })
        }
    }

    /// The binding that makes a session on this device, queue 0 of [`Vulkan::family`].
    pub fn binding(&self) -> xr::GraphicsBindingVulkanKHR {
        xr::GraphicsBindingVulkanKHR {
            ty: xr::GraphicsBindingVulkanKHR::TYPE,
            next: null(),
            instance: self.instance.handle().as_raw() as usize as xr::platform::VkInstance,
            physical_device: self.physical_device.as_raw() as usize
                as xr::platform::VkPhysicalDevice,
            device: self.device.handle().as_raw() as usize as xr::platform::VkDevice,
            queue_family_index: self.family,
            queue_index: 0,
        }
    }

    /// Waits for the device and destroys it: the validation layer reports every object still
    /// alive on it here.
    ///
    /// # Safety
    /// Nothing uses the device afterwards.
    pub unsafe fn destroy_device(&self) {
        self.device.device_wait_idle().unwrap();
        self.device.destroy_device(None);
    }

    /// Destroys the messenger and the instance, after [`Vulkan::destroy_device`].
    ///
    /// # Safety
    /// The device is destroyed.
    pub unsafe fn destroy_instance(self) {
        self.debug_utils
            .destroy_debug_utils_messenger(self.messenger, None);
        self.instance.destroy_instance(None);
    }

    /// Destroys the device, then the messenger and the instance; the validation layer reports any
    /// object of the application's still alive on the device.
    pub fn destroy(self) {
        // SAFETY: `self` is consumed: nothing can use the device or the instance after this.
        unsafe {
            self.destroy_device();
            self.destroy_instance();
        }
    }
}
