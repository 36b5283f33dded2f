//! A Vulkan 1.4 application gets fovea's Vulkan layer through the system's Khronos loader from the
//! implicit manifest, and the layer works for it.
//!
//! The Khronos loader compares every active layer's manifest `api_version` with the application's
//! requested `apiVersion`: loaders before 1.3.227 (Ubuntu 22.04 ships 1.3.204) leave out an
//! implicit layer written for an older Vulkan, later ones load it and warn that it "may cause
//! issues" (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>,
//! "Layer Manifest File Format"). The manifests therefore name Vulkan 1.4, and the loader says
//! nothing about fovea's layer to an application asking for 1.4. Here: the checked-in implicit manifest, pointed at this build, in this test's own
//! per-user folder, switched on by its `enable_environment`; the shading-rate double (NVIDIA-like)
//! as an explicit layer below it, over lavapipe. An application asking for Vulkan 1.4 sees the
//! density-map extension the layer offers (neither lavapipe nor the double has it, so only an
//! active fovea lists it), creates a device with it, and the driver gets the shading-rate
//! extension and the attachment feature in its place. The environment is the test's own, so it
//! runs in a process of its own.

use std::ffi::{c_void, CStr};
use std::sync::Mutex;

use ash::vk;
use fovea_harness::skip;
use fovea_vkdouble::{Loaded, Profile};
use serde_json::json;

use crate::support::device::FDM;
use crate::support::{in_own_process, root};

const FSR: &CStr = c"VK_KHR_fragment_shading_rate";
const MANIFEST: &str = "VK_LAYER_FOVEA_fragment_density_map.json";

static MESSAGES: Mutex<Vec<String>> = Mutex::new(Vec::new());

unsafe extern "system" fn on_message(
    _severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    _user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: the loader passes valid callback data with a NUL-terminated message.
    let text = unsafe { CStr::from_ptr((*data).p_message) }.to_string_lossy();
    if let Ok(mut m) = MESSAGES.lock() {
        m.push(text.into_owned());
    }
    vk::FALSE
}

#[test]
fn a_vulkan_1_4_application_gets_the_implicit_layer() {
    in_own_process(
        module_path!(),
        "a_vulkan_1_4_application_gets_the_implicit_layer",
        body,
    );
}

fn body() {
    let (double_lib, fovea_lib) = match (
        fovea_vkdouble::find_library(),
        fovea_harness::artifact("libfovea.so"),
    ) {
        (Ok(d), Ok(f)) => (d, f.canonicalize().unwrap()),
        (Err(e), _) | (_, Err(e)) => {
            skip(&e);
            return;
        }
    };
    let dir = std::env::temp_dir().join(format!("fovea-vk14-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let implicit = dir.join("data/vulkan/implicit_layer.d");
    let explicit = dir.join("explicit");
    std::fs::create_dir_all(&implicit).unwrap();
    fovea_vkdouble::write_manifest(&explicit, &double_lib).unwrap();
    let checked_in = root().join("manifest/vulkan/implicit").join(MANIFEST);
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(checked_in).unwrap()).unwrap();
    m["layer"]["library_path"] = json!(fovea_lib.to_string_lossy());
    std::fs::write(implicit.join(MANIFEST), m.to_string()).unwrap();
    // The per-user folders are the test's own: no implicit layer from the user's install.
    std::env::set_var("XDG_DATA_HOME", dir.join("data"));
    std::env::set_var("XDG_CONFIG_HOME", dir.join("config"));
    std::env::set_var("VK_ADD_LAYER_PATH", &explicit);
    let enable = m["layer"]["enable_environment"]
        .as_object()
        .expect("the implicit manifest's enable_environment");
    for (k, v) in enable {
        std::env::set_var(k, v.as_str().unwrap());
    }
    std::env::set_var(fovea_vkdouble::PROFILE_ENV, Profile::Nvidia.name());
    // SAFETY: loading libvulkan runs its initialisers, as any Vulkan application does.
    let entry = match unsafe { ash::Entry::load() } {
        Ok(e) => e,
        Err(e) => {
            skip(&format!("no Vulkan loader ({e})"));
            return;
        }
    };
    let double = Loaded::open(&double_lib).unwrap();
    let ours = std::ffi::CString::new(fovea_abi::VK_LAYER_NAME).unwrap();
    let layers = [fovea_vkdouble::LAYER_NAME.as_ptr()];
    let app = vk::ApplicationInfo::default().api_version(vk::make_api_version(0, 1, 4, 0));
    // The loader's own messages about the instance it creates, warnings included.
    let mut messenger = vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(
            vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
        )
        .message_type(
            vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION,
        )
        .pfn_user_callback(Some(on_message));
    let exts = [ash::ext::debug_utils::NAME.as_ptr()];
    let info = vk::InstanceCreateInfo::default()
        .application_info(&app)
        .enabled_layer_names(&layers)
        .enabled_extension_names(&exts)
        .push_next(&mut messenger);
    // SAFETY: every struct lives across the calls; every handle is destroyed before the end.
    unsafe {
        let found = entry.enumerate_instance_layer_properties().unwrap();
        assert!(
            found
                .iter()
                .any(|l| l.layer_name_as_c_str() == Ok(ours.as_c_str())),
            "the loader does not list the implicit layer"
        );
        let instance = entry
            .create_instance(&info, None)
            .expect("vkCreateInstance for Vulkan 1.4");
        let Some(physical) = instance
            .enumerate_physical_devices()
            .unwrap_or_default()
            .into_iter()
            .find(|&p| {
                instance
                    .get_physical_device_properties(p)
                    .device_name_as_c_str()
                    .is_ok_and(|n| n.to_string_lossy().contains("llvmpipe"))
            })
        else {
            instance.destroy_instance(None);
            skip("lavapipe (llvmpipe) is not installed");
            return;
        };
        let exts = instance
            .enumerate_device_extension_properties(physical)
            .unwrap();
        assert!(
            exts.iter().any(|e| e.extension_name_as_c_str() == Ok(FDM)),
            "fovea's layer is not active for a Vulkan 1.4 application: no {FDM:?}"
        );
        double.clear();
        let prio = [1.0];
        let queues = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(0)
            .queue_priorities(&prio)];
        let names = [FDM.as_ptr()];
        let mut fdm = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default()
            .fragment_density_map(true)
            .fragment_density_map_non_subsampled_images(true);
        let device = instance
            .create_device(
                physical,
                &vk::DeviceCreateInfo::default()
                    .queue_create_infos(&queues)
                    .enabled_extension_names(&names)
                    .push_next(&mut fdm),
                None,
            )
            .expect("vkCreateDevice with density maps");
        let devices = double.events("device");
        assert_eq!(devices.len(), 1, "{devices:?}");
        assert_eq!(
            devices[0]["features"],
            json!({"pipeline": false, "primitive": false, "attachment": true})
        );
        let reached: Vec<&str> = devices[0]["extensions"]
            .as_array()
            .expect("names")
            .iter()
            .filter_map(|n| n.as_str())
            .collect();
        assert!(reached.contains(&FSR.to_str().unwrap()), "{reached:?}");
        assert!(!reached.contains(&FDM.to_str().unwrap()), "{reached:?}");
        device.destroy_device(None);
        instance.destroy_instance(None);
    }
    assert_eq!(double.errors(), Vec::<String>::new());
    // The loader has nothing to say about fovea's layer (the double's own manifest is older).
    let ours = ours.to_str().unwrap();
    let about_us: Vec<String> = MESSAGES
        .lock()
        .unwrap()
        .iter()
        .filter(|m| m.contains(ours))
        .cloned()
        .collect();
    assert!(about_us.is_empty(), "the loader: {about_us:#?}");
    std::fs::remove_dir_all(&dir).ok();
}
