//! The double enabled the way a user enables layers without touching the application:
//! `VK_ADD_LAYER_PATH` names the folder with its manifest and `VK_INSTANCE_LAYERS` orders the
//! stack (first = closest to the application), with the validation layer above the double
//! (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderInterfaceArchitecture.md>,
//! "Table of Debug Environment Variables"). In a process of its own, since the variables apply to
//! every instance the process creates.

use std::ffi::CStr;

use ash::vk;

use crate::process::in_own_process;
use crate::skip;

const FSR: &CStr = c"VK_KHR_fragment_shading_rate";

/// In a process of its own ([`crate::process::in_own_process`]): the variables it sets apply to
/// every instance the process creates.
#[test]
fn instance_layers_variable_puts_the_double_under_validation() {
    in_own_process(
        module_path!(),
        "instance_layers_variable_puts_the_double_under_validation",
        instance_layers_variable_puts_the_double_under_validation_here,
    );
}

fn instance_layers_variable_puts_the_double_under_validation_here() {
    let lib = match fovea_vkdouble::find_library() {
        Ok(l) => l,
        Err(e) => return skip(&e),
    };
    let dir = std::env::temp_dir().join(format!("fovea-vkdouble-env-{}", std::process::id()));
    fovea_vkdouble::write_manifest(&dir, &lib).unwrap();
    // The only test in this process, set before the loader first reads the environment.
    std::env::set_var("VK_ADD_LAYER_PATH", &dir);
    std::env::set_var(
        "VK_INSTANCE_LAYERS",
        "VK_LAYER_KHRONOS_validation:VK_LAYER_FOVEA_shading_rate_double",
    );
    std::env::set_var(fovea_vkdouble::PROFILE_ENV, "amd");
    // Opened before the loader opens it and kept open: the loader closes the layer's library at
    // vkDestroyInstance, which would unload the records with it.
    let double = fovea_vkdouble::Loaded::open(&lib).unwrap();
    // SAFETY: loading libvulkan runs its initialisers, as any Vulkan application does.
    let entry = match unsafe { ash::Entry::load() } {
        Ok(e) => e,
        Err(e) => return skip(&format!("no Vulkan loader ({e})")),
    };
    // SAFETY: plain queries and an instance destroyed at the end; structs live across calls.
    unsafe {
        let layers = entry
            .enumerate_instance_layer_properties()
            .unwrap_or_default();
        if !layers
            .iter()
            .any(|l| l.layer_name_as_c_str() == Ok(c"VK_LAYER_KHRONOS_validation"))
        {
            return skip("VK_LAYER_KHRONOS_validation is not installed");
        }
        let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_3);
        let instance = entry
            .create_instance(
                &vk::InstanceCreateInfo::default().application_info(&app),
                None,
            )
            .expect("vkCreateInstance");
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
        let Some(physical) = physical else {
            instance.destroy_instance(None);
            return skip("lavapipe (llvmpipe) is not installed");
        };
        let exts = instance
            .enumerate_device_extension_properties(physical)
            .unwrap();
        assert!(exts.iter().any(|e| e.extension_name_as_c_str() == Ok(FSR)));
        let mut p = vk::PhysicalDeviceFragmentShadingRatePropertiesKHR::default();
        let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut p);
        instance.get_physical_device_properties2(physical, &mut p2);
        assert_eq!(
            p.min_fragment_shading_rate_attachment_texel_size,
            vk::Extent2D {
                width: 8,
                height: 8
            }
        );
        instance.destroy_instance(None);
    }
    let instances = double.events("instance");
    assert_eq!(instances.len(), 1);
    assert_eq!(instances[0]["profile"], "amd");
}
