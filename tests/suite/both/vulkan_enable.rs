//! OpenXR applications get fovea's Vulkan layer without doing anything (docs/vulkan-layer.md):
//!
//! - XR_KHR_vulkan_enable2: fovea's `xrCreateVulkanInstanceKHR` puts the layer into the VkInstance
//!   the simulated runtime creates, where the Vulkan loader finds it. Stack: application → fovea's
//!   Vulkan layer → the shading-rate double (`nvidia` profile) → lavapipe; the device then offers
//!   VK_EXT_fragment_density_map, which only fovea's layer adds. Where the loader does not find the
//!   layer, the instance is made as before and the log says so once.
//! - XR_KHR_vulkan_enable: the application's own vkCreateInstance loads the implicit manifest
//!   `fovea install` writes, because fovea set its `enable_environment` variable.
//!
//! Each test sets the environment the loaders read, so each runs in a process of its own. Missing
//! system pieces (the Vulkan loader, lavapipe, the built libraries) skip, or fail under
//! `FOVEA_REQUIRE_SYSTEM=1`.

use std::ffi::{c_void, CStr};
use std::path::{Path, PathBuf};
use std::ptr::{null, null_mut};

use ash::vk;
use ash::vk::Handle as _;
use fovea_harness::app::API_1_0;
use fovea_harness::{skip, App, Chain};
use openxr_sys as xr;

use crate::support::{in_own_process, root};

const FDM: &CStr = c"VK_EXT_fragment_density_map";
const VK_FILE: &str = "VK_LAYER_FOVEA_fragment_density_map.json";

/// The per-test folder: the log file, and `layers/` for `VK_ADD_LAYER_PATH` with the double's
/// manifest and, where `with_fovea`, fovea's explicit Vulkan manifest pointed at this build.
/// Sets the process environment: call it first in the child process.
fn set_up(label: &str, with_fovea: bool) -> Option<PathBuf> {
    let dir = std::env::temp_dir().join(format!("fovea-vkenable-{label}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let layers = dir.join("layers");
    std::fs::create_dir_all(&layers).unwrap();
    let double = match fovea_vkdouble::find_library() {
        Ok(d) => d,
        Err(e) => {
            skip(&e);
            return None;
        }
    };
    fovea_vkdouble::write_manifest(&layers, &double).unwrap();
    if with_fovea {
        let lib = fovea_harness::artifact("libfovea.so").expect("libfovea.so: cargo build");
        let mut m: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(root().join("manifest/vulkan").join(VK_FILE)).unwrap(),
        )
        .unwrap();
        m["layer"]["library_path"] = lib.canonicalize().unwrap().to_str().unwrap().into();
        std::fs::write(layers.join(VK_FILE), m.to_string()).unwrap();
    }
    // No implicit layer from the user's own install.
    std::env::set_var("XDG_DATA_HOME", dir.join("data"));
    std::env::set_var("XDG_CONFIG_HOME", dir.join("config"));
    std::env::set_var("VK_ADD_LAYER_PATH", &layers);
    std::env::set_var("FOVEA_SIM_VK_DEVICE", "llvmpipe");
    std::env::set_var(fovea_vkdouble::PROFILE_ENV, "nvidia");
    std::env::set_var("FOVEA_LOG", "info");
    std::env::set_var("FOVEA_LOG_FILE", dir.join("fovea.log"));
    Some(dir)
}

fn log(dir: &Path) -> String {
    std::fs::read_to_string(dir.join("fovea.log")).unwrap_or_default()
}

/// The Vulkan loader, or a skip.
fn entry() -> Option<ash::Entry> {
    // SAFETY: loading libvulkan runs its initialisers, as any Vulkan application does.
    match unsafe { ash::Entry::load() } {
        Ok(e) => Some(e),
        Err(e) => {
            skip(&format!("no Vulkan loader ({e})"));
            None
        }
    }
}

/// A VkInstance made through `xrCreateVulkanInstanceKHR` with the double in the application's own
/// layer list, and the physical device the runtime picks; whether that device offers FDM.
/// `None` where lavapipe is missing.
fn enable2_instance(app: &App, entry: &ash::Entry) -> Option<bool> {
    let sys = app.system();
    // SAFETY: each function is looked up as the type its name implies; every struct lives across
    // its call; the instance is destroyed before return.
    unsafe {
        let requirements: xr::pfn::GetVulkanGraphicsRequirements2KHR =
            app.func(c"xrGetVulkanGraphicsRequirements2KHR");
        let create: xr::pfn::CreateVulkanInstanceKHR = app.func(c"xrCreateVulkanInstanceKHR");
        let device: xr::pfn::GetVulkanGraphicsDevice2KHR =
            app.func(c"xrGetVulkanGraphicsDevice2KHR");
        let mut req = xr::GraphicsRequirementsVulkanKHR {
            ty: xr::GraphicsRequirementsVulkanKHR::TYPE,
            next: null_mut(),
            min_api_version_supported: xr::Version::new(0, 0, 0),
            max_api_version_supported: xr::Version::new(0, 0, 0),
        };
        assert_eq!(
            requirements(app.instance, sys, &mut req),
            xr::Result::SUCCESS
        );
        let layers = [fovea_vkdouble::LAYER_NAME.as_ptr()];
        let info_app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_1);
        let vk_info = vk::InstanceCreateInfo::default()
            .application_info(&info_app)
            .enabled_layer_names(&layers);
        let gipa: xr::platform::VkGetInstanceProcAddr =
            std::mem::transmute(entry.static_fn().get_instance_proc_addr);
        let xr_info = xr::VulkanInstanceCreateInfoKHR {
            ty: xr::VulkanInstanceCreateInfoKHR::TYPE,
            next: null(),
            system_id: sys,
            create_flags: xr::VulkanInstanceCreateFlagsKHR::EMPTY,
            pfn_get_instance_proc_addr: Some(gipa),
            vulkan_create_info: &vk_info as *const _ as *const c_void,
            vulkan_allocator: null(),
        };
        let mut raw: xr::platform::VkInstance = null();
        let mut vr = 0;
        let r = create(app.instance, &xr_info, &mut raw, &mut vr);
        assert_eq!((r, vr), (xr::Result::SUCCESS, 0));
        // The application's struct is as it made it.
        assert_eq!(vk_info.enabled_layer_count, 1);
        assert_eq!(vk_info.pp_enabled_layer_names, layers.as_ptr());
        let instance = ash::Instance::load(entry.static_fn(), vk::Instance::from_raw(raw as u64));
        let get = xr::VulkanGraphicsDeviceGetInfoKHR {
            ty: xr::VulkanGraphicsDeviceGetInfoKHR::TYPE,
            next: null(),
            system_id: sys,
            vulkan_instance: raw,
        };
        let mut pd: xr::platform::VkPhysicalDevice = null();
        if device(app.instance, &get, &mut pd) != xr::Result::SUCCESS {
            instance.destroy_instance(None);
            skip("lavapipe (llvmpipe) is not available");
            return None;
        }
        let exts = instance
            .enumerate_device_extension_properties(vk::PhysicalDevice::from_raw(pd as u64))
            .unwrap();
        let fdm = exts.iter().any(|e| e.extension_name_as_c_str() == Ok(FDM));
        instance.destroy_instance(None);
        Some(fdm)
    }
}

fn enable2_app() -> App {
    App::new(Chain::fovea().unwrap(), &["XR_KHR_vulkan_enable2"], API_1_0).unwrap()
}

#[test]
fn an_enable2_app_gets_the_vulkan_layer_in_its_vkinstance() {
    in_own_process(
        module_path!(),
        "an_enable2_app_gets_the_vulkan_layer_in_its_vkinstance",
        || {
            let Some(dir) = set_up("found", true) else {
                return;
            };
            let Some(entry) = entry() else { return };
            let app = enable2_app();
            let Some(fdm) = enable2_instance(&app, &entry) else {
                return;
            };
            assert!(
                fdm,
                "no VK_EXT_fragment_density_map: fovea's layer is not in\n{}",
                log(&dir)
            );
            assert!(
                log(&dir).contains("the Vulkan layer is in the application's VkInstance"),
                "{}",
                log(&dir)
            );
            // And the process now asks implicit copies of the layer in too.
            assert_eq!(std::env::var(fovea_abi::env::VK_LAYER).as_deref(), Ok("1"));
            assert_eq!(app.destroy(), xr::Result::SUCCESS);
        },
    );
}

#[test]
fn without_the_vulkan_layer_an_enable2_app_works_as_before_with_one_log_line() {
    in_own_process(
        module_path!(),
        "without_the_vulkan_layer_an_enable2_app_works_as_before_with_one_log_line",
        || {
            let Some(dir) = set_up("missing", false) else {
                return;
            };
            let Some(entry) = entry() else { return };
            let app = enable2_app();
            for _ in 0..2 {
                let Some(fdm) = enable2_instance(&app, &entry) else {
                    return;
                };
                // The double offers shading rates, not density maps.
                assert!(!fdm);
            }
            let text = log(&dir);
            assert_eq!(
                text.matches("not added to the application's VkInstance")
                    .count(),
                1,
                "{text}"
            );
            assert!(!text.contains("ERROR") && !text.contains("WARN"), "{text}");
            assert_eq!(app.destroy(), xr::Result::SUCCESS);
        },
    );
}

#[test]
fn an_enable_app_loads_the_implicit_vulkan_layer_through_the_variable_fovea_sets() {
    in_own_process(
        module_path!(),
        "an_enable_app_loads_the_implicit_vulkan_layer_through_the_variable_fovea_sets",
        || {
            let Some(dir) = set_up("implicit", false) else {
                return;
            };
            // The implicit manifest as `fovea install` writes it, in the loader's per-user folder.
            let data = dir.join("data");
            let implicit = data.join("vulkan/implicit_layer.d");
            std::fs::create_dir_all(&implicit).unwrap();
            let lib = fovea_harness::artifact("libfovea.so").expect("libfovea.so");
            let mut m: serde_json::Value = serde_json::from_str(
                &std::fs::read_to_string(root().join("manifest/vulkan/implicit").join(VK_FILE))
                    .unwrap(),
            )
            .unwrap();
            m["layer"]["library_path"] = lib.canonicalize().unwrap().to_str().unwrap().into();
            std::fs::write(implicit.join(VK_FILE), m.to_string()).unwrap();
            std::env::set_var("XDG_DATA_HOME", &data);
            std::env::remove_var(fovea_abi::env::VK_LAYER);
            let Some(entry) = entry() else { return };

            // Before any OpenXR instance: the implicit layer stays out.
            let fdm_now = || {
                let layers = [fovea_vkdouble::LAYER_NAME.as_ptr()];
                let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_1);
                let info = vk::InstanceCreateInfo::default()
                    .application_info(&app)
                    .enabled_layer_names(&layers);
                // SAFETY: the structs live across the calls; the instance is destroyed at the end.
                unsafe {
                    let instance = entry.create_instance(&info, None).unwrap();
                    let found = instance
                        .enumerate_physical_devices()
                        .unwrap()
                        .into_iter()
                        .find(|&p| {
                            instance
                                .get_physical_device_properties(p)
                                .device_name_as_c_str()
                                .is_ok_and(|n| n.to_string_lossy().contains("llvmpipe"))
                        })
                        .map(|p| {
                            instance
                                .enumerate_device_extension_properties(p)
                                .unwrap()
                                .iter()
                                .any(|e| e.extension_name_as_c_str() == Ok(FDM))
                        });
                    instance.destroy_instance(None);
                    found
                }
            };
            let Some(before) = fdm_now() else {
                skip("lavapipe (llvmpipe) is not installed");
                return;
            };
            assert!(!before);
            let app =
                App::new(Chain::fovea().unwrap(), &["XR_KHR_vulkan_enable"], API_1_0).unwrap();
            assert_eq!(std::env::var(fovea_abi::env::VK_LAYER).as_deref(), Ok("1"));
            // The application's own vkCreateInstance now has fovea's layer above the double.
            assert_eq!(fdm_now(), Some(true), "{}", log(&dir));
            assert_eq!(app.destroy(), xr::Result::SUCCESS);

            // The user's own value is left alone.
            std::env::set_var(fovea_abi::env::VK_LAYER, "0");
            let app =
                App::new(Chain::fovea().unwrap(), &["XR_KHR_vulkan_enable"], API_1_0).unwrap();
            assert_eq!(std::env::var(fovea_abi::env::VK_LAYER).as_deref(), Ok("0"));
            assert_eq!(fdm_now(), Some(false));
            assert_eq!(app.destroy(), xr::Result::SUCCESS);
        },
    );
}

/// The checked-in implicit manifest is the explicit one plus the two variables, with its library
/// path one folder further up (it lies one folder deeper).
#[test]
fn the_implicit_vulkan_manifest_is_the_explicit_one_switched_by_the_environment() {
    let read = |p: PathBuf| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let explicit = read(root().join("manifest/vulkan").join(VK_FILE));
    let mut implicit = read(root().join("manifest/vulkan/implicit").join(VK_FILE));
    let l = implicit["layer"].as_object_mut().unwrap();
    assert_eq!(
        l.remove("enable_environment").unwrap(),
        serde_json::json!({ fovea_abi::env::VK_LAYER: "1" })
    );
    assert_eq!(
        l.remove("disable_environment").unwrap(),
        serde_json::json!({ fovea_abi::env::DISABLE_VK_LAYER: "1" })
    );
    assert_eq!(l["library_path"], "../../../target/release/libfovea.so");
    l.insert(
        "library_path".into(),
        explicit["layer"]["library_path"].clone(),
    );
    assert_eq!(implicit, explicit);
}
