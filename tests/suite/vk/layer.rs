//! fovea's Vulkan layer, `VK_LAYER_FOVEA_fragment_density_map`, on lavapipe: the device level.
//!
//! Stack ([`crate::support::device`]): this test → fovea's layer → VK_LAYER_KHRONOS_validation → VK_LAYER_FOVEA_shading_rate_double
//! → lavapipe. The double makes lavapipe look like a desktop GPU with shading-rate attachments
//! (profiles `nvidia`: 16×16 texels, `amd`: 8×8; `none`: lavapipe as it is) and records what reaches
//! it; validation checks every call fovea passes down against that device, and must stay silent.
//! Both manifests are written to a temporary folder named by `VK_ADD_LAYER_PATH`; the layers are
//! enabled through `ppEnabledLayerNames` (first = closest to the application). Tests share the
//! process environment, the validation messages and the double's records, so they run one at a
//! time.
//!
//! Missing system pieces (loader, lavapipe, validation layer, the built libraries) skip, or fail
//! under `FOVEA_REQUIRE_SYSTEM=1`.

use std::ffi::{CStr, CString};

use ash::vk;
use fovea_vkdouble::Profile;
use serde_json::json;

use crate::support::device::{
    assert_no_messages, env, fdm_image_info, take_messages, with_fovea, Vk, FDM,
};

const FSR: &CStr = c"VK_KHR_fragment_shading_rate";

fn fovea_layer() -> CString {
    CString::new(fovea_abi::VK_LAYER_NAME).expect("no NUL")
}

/// What these tests ask of the physical device beneath the layers.
impl Vk {
    fn extensions(&self) -> Vec<(CString, u32)> {
        // SAFETY: a plain query.
        unsafe {
            self.instance
                .enumerate_device_extension_properties(self.physical)
                .expect("extensions")
        }
        .iter()
        .map(|e| {
            (
                e.extension_name_as_c_str().expect("NUL").to_owned(),
                e.spec_version,
            )
        })
        .collect()
    }

    fn fdm_features(&self) -> [vk::Bool32; 3] {
        let mut fdm = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default();
        let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut fdm);
        // SAFETY: structs live across the call.
        unsafe {
            self.instance
                .get_physical_device_features2(self.physical, &mut f2)
        };
        [
            fdm.fragment_density_map,
            fdm.fragment_density_map_dynamic,
            fdm.fragment_density_map_non_subsampled_images,
        ]
    }

    /// R8G8_UNORM's optimal-tiling features: from vkGetPhysicalDeviceFormatProperties, from
    /// …Properties2, and from a chained VkFormatProperties3.
    fn rg8_features(
        &self,
    ) -> (
        vk::FormatFeatureFlags,
        vk::FormatFeatureFlags,
        vk::FormatFeatureFlags2,
    ) {
        // SAFETY: plain queries with structs that live across the calls.
        unsafe {
            let v1 = self
                .instance
                .get_physical_device_format_properties(self.physical, vk::Format::R8G8_UNORM);
            let mut p3 = vk::FormatProperties3::default();
            let mut p2 = vk::FormatProperties2::default().push_next(&mut p3);
            self.instance.get_physical_device_format_properties2(
                self.physical,
                vk::Format::R8G8_UNORM,
                &mut p2,
            );
            (
                v1.optimal_tiling_features,
                p2.format_properties.optimal_tiling_features,
                p3.optimal_tiling_features,
            )
        }
    }

    /// vkGetPhysicalDeviceImageFormatProperties2 for a 2D optimal image.
    fn image_format(&self, format: vk::Format, usage: vk::ImageUsageFlags) -> vk::Result {
        let info = vk::PhysicalDeviceImageFormatInfo2::default()
            .format(format)
            .ty(vk::ImageType::TYPE_2D)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(usage);
        let mut out = vk::ImageFormatProperties2::default();
        // SAFETY: structs live across the call.
        match unsafe {
            self.instance.get_physical_device_image_format_properties2(
                self.physical,
                &info,
                &mut out,
            )
        } {
            Ok(()) => vk::Result::SUCCESS,
            Err(e) => e,
        }
    }
}

/// On the NVIDIA-like and AMD-like profiles the application sees density maps with the driver's
/// shading-rate texel, creates a device with them (which reaches the driver as a shading-rate
/// device) and a density-map image; validation says nothing.
#[test]
fn emulated_density_maps_on_shading_rate_devices() {
    let Some((_serial, env)) = env() else { return };
    for (profile, texel) in [(Profile::Nvidia, 16), (Profile::Amd, 8)] {
        let Some(vk) = Vk::new(env, profile, true) else {
            return;
        };
        let exts = vk.extensions();
        assert!(
            exts.contains(&(FDM.to_owned(), 3)),
            "{profile:?}: {FDM:?} spec 3 offered"
        );
        assert!(exts.iter().any(|(n, _)| n.as_c_str() == FSR));
        // The layer's own extensions, asked by name.
        let ours = fovea_layer();
        // SAFETY: the two-call idiom with a buffer of the reported size.
        let own = unsafe {
            let f = vk.instance.fp_v1_0().enumerate_device_extension_properties;
            let mut n = 0;
            assert_eq!(
                f(vk.physical, ours.as_ptr(), &mut n, std::ptr::null_mut()),
                vk::Result::SUCCESS
            );
            let mut v = vec![vk::ExtensionProperties::default(); n as usize];
            assert_eq!(
                f(vk.physical, ours.as_ptr(), &mut n, v.as_mut_ptr()),
                vk::Result::SUCCESS
            );
            v
        };
        let own: Vec<_> = own
            .iter()
            .map(|e| (e.extension_name_as_c_str().unwrap(), e.spec_version))
            .collect();
        assert_eq!(
            own,
            [
                (FDM, 3),
                (c"VK_EXT_fragment_density_map_offset", 1),
                (c"VK_QCOM_fragment_density_map_offset", 3)
            ]
        );
        // Density-map offsets under both names, with the feature and a granularity of one texel.
        for (name, spec) in &own[1..] {
            assert!(
                exts.contains(&((*name).to_owned(), *spec)),
                "{profile:?}: {name:?} offered"
            );
        }
        let mut offset_features = vk::PhysicalDeviceFragmentDensityMapOffsetFeaturesQCOM::default();
        let mut offset_props = vk::PhysicalDeviceFragmentDensityMapOffsetPropertiesQCOM::default();
        // SAFETY: valid output chains on the stack.
        unsafe {
            vk.instance.get_physical_device_features2(
                vk.physical,
                &mut vk::PhysicalDeviceFeatures2::default().push_next(&mut offset_features),
            );
            vk.instance.get_physical_device_properties2(
                vk.physical,
                &mut vk::PhysicalDeviceProperties2::default().push_next(&mut offset_props),
            );
        }
        assert_eq!(offset_features.fragment_density_map_offset, vk::TRUE);
        assert_eq!(
            offset_props.fragment_density_offset_granularity,
            vk::Extent2D {
                width: texel,
                height: texel
            },
            "{profile:?}"
        );
        // VK_INCOMPLETE where the buffer is one short.
        // SAFETY: as above.
        unsafe {
            let f = vk.instance.fp_v1_0().enumerate_device_extension_properties;
            let mut n = 0;
            assert_eq!(
                f(vk.physical, std::ptr::null(), &mut n, std::ptr::null_mut()),
                vk::Result::SUCCESS
            );
            assert_eq!(n as usize, exts.len());
            let mut v = vec![vk::ExtensionProperties::default(); n as usize];
            n -= 1;
            assert_eq!(
                f(vk.physical, std::ptr::null(), &mut n, v.as_mut_ptr()),
                vk::Result::INCOMPLETE
            );
            assert_eq!(n as usize, exts.len() - 1);
        }

        assert_eq!(vk.fdm_features(), [vk::TRUE, vk::FALSE, vk::TRUE]);
        let props = vk.fdm_properties();
        let t = vk::Extent2D {
            width: texel,
            height: texel,
        };
        assert_eq!(props.min_fragment_density_texel_size, t, "{profile:?}");
        assert_eq!(props.max_fragment_density_texel_size, t, "{profile:?}");
        assert_eq!(props.fragment_density_invocations, vk::FALSE);

        let (v1, v2, v3) = vk.rg8_features();
        assert!(v1.contains(vk::FormatFeatureFlags::FRAGMENT_DENSITY_MAP_EXT));
        assert!(v2.contains(vk::FormatFeatureFlags::FRAGMENT_DENSITY_MAP_EXT));
        assert!(v3.contains(vk::FormatFeatureFlags2::FRAGMENT_DENSITY_MAP_EXT));
        assert!(
            v1.contains(vk::FormatFeatureFlags::SAMPLED_IMAGE),
            "the driver's bits stay"
        );

        assert_eq!(
            vk.image_format(
                vk::Format::R8G8_UNORM,
                vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT
            ),
            vk::Result::SUCCESS
        );
        assert_eq!(
            vk.image_format(
                vk::Format::R8G8B8A8_UNORM,
                vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT
            ),
            vk::Result::ERROR_FORMAT_NOT_SUPPORTED
        );

        let device = vk.fdm_device(&[], None);
        // lavapipe would refuse the density-map extension name: the device's success says it never
        // got there. The double saw the shading-rate extension with the attachment feature only.
        let devices = env.double.events("device");
        assert_eq!(devices.len(), 1, "{devices:?}");
        assert_eq!(devices[0]["extension"], true);
        assert_eq!(
            devices[0]["features"],
            json!({"pipeline": false, "primitive": false, "attachment": true})
        );
        // SAFETY: the image is destroyed before its device.
        unsafe {
            let image = device
                .create_image(&fdm_image_info(), None)
                .expect("an image with FRAGMENT_DENSITY_MAP usage");
            device.destroy_image(image, None);
            device.destroy_device(None);
        }
        assert_eq!(env.double.errors(), Vec::<String>::new());
        drop(vk);
        assert_no_messages();
    }
}

/// A device created without density maps on an emulating physical device is passed through:
/// the driver gets exactly what the application asked for.
#[test]
fn device_without_density_maps_is_untouched() {
    let Some((_serial, env, vk)) = with_fovea(Profile::Nvidia) else {
        return;
    };
    let device = vk.device(&[], None).expect("vkCreateDevice");
    let devices = env.double.events("device");
    assert_eq!(devices[0]["extension"], false);
    assert_eq!(devices[0]["features"], json!(null));
    // SAFETY: destroyed once, nothing made from it.
    unsafe { device.destroy_device(None) };
    drop(vk);
    assert_no_messages();
}

/// An application that enables shading rates itself keeps them: nothing is rewritten.
#[test]
fn application_using_shading_rates_is_not_touched() {
    let Some((_serial, env, vk)) = with_fovea(Profile::Nvidia) else {
        return;
    };
    let mut fsr = vk::PhysicalDeviceFragmentShadingRateFeaturesKHR::default()
        .pipeline_fragment_shading_rate(true)
        .attachment_fragment_shading_rate(true);
    let device = vk.device(&[FSR], Some(&mut fsr)).expect("vkCreateDevice");
    let devices = env.double.events("device");
    assert_eq!(devices[0]["extension"], true);
    assert_eq!(
        devices[0]["features"],
        json!({"pipeline": true, "primitive": false, "attachment": true})
    );
    // SAFETY: destroyed once, nothing made from it.
    unsafe { device.destroy_device(None) };
    drop(vk);
    assert_no_messages();
}

/// On lavapipe as it is (no shading rates), nothing is offered and every answer is the driver's:
/// the same with and without fovea's layer.
#[test]
fn nothing_offered_without_shading_rates() {
    let Some((_serial, env)) = env() else { return };
    let Some(without) = Vk::new(env, Profile::None, false) else {
        return;
    };
    let expected = (
        without.extensions(),
        without.fdm_features(),
        without.rg8_features(),
    );
    drop(without);
    assert_no_messages();
    let Some(vk) = Vk::new(env, Profile::None, true) else {
        return;
    };
    let exts = vk.extensions();
    assert!(!exts.iter().any(|(n, _)| n.as_c_str() == FDM));
    assert_eq!((exts, vk.fdm_features(), vk.rg8_features()), expected);
    assert_eq!(vk.fdm_features(), [vk::FALSE; 3]);
    let device = vk.device(&[], None).expect("vkCreateDevice");
    // SAFETY: destroyed once, nothing made from it.
    unsafe { device.destroy_device(None) };
    drop(vk);
    assert_no_messages();
}

/// `vkGetDeviceProcAddr` hands out fovea's hook only where it is needed: on an emulating device
/// for `vkCreateImage` and the ends of passes; everywhere else, and for every command the layer does not intercept, the
/// pointer is the next layer's own (the one an instance without fovea gets), so those commands
/// cost nothing extra.
#[test]
fn unintercepted_commands_go_straight_to_the_next_layer() {
    let Some((_serial, env)) = env() else { return };
    let Some(plain) = Vk::new(env, Profile::Nvidia, false) else {
        return;
    };
    let Some(vk) = Vk::new(env, Profile::Nvidia, true) else {
        return;
    };
    let emulating = vk.fdm_device(&[], None);
    let untouched = vk.device(&[], None).expect("untouched device");
    let reference = plain.device(&[], None).expect("device without fovea");
    let gdpa = |i: &ash::Instance, d: &ash::Device, name: &CStr| {
        // SAFETY: a live device of that instance and a NUL-terminated name.
        unsafe { (i.fp_v1_0().get_device_proc_addr)(d.handle(), name.as_ptr()) }
            .map(|f| f as usize)
            .expect("a pointer")
    };
    for name in [
        c"vkCmdDraw",
        c"vkQueueWaitIdle",
        c"vkCreateBuffer",
        c"vkCmdDispatch",
    ] {
        let below = gdpa(&plain.instance, &reference, name);
        assert_eq!(gdpa(&vk.instance, &emulating, name), below, "{name:?}");
        assert_eq!(gdpa(&vk.instance, &untouched, name), below, "{name:?}");
    }
    // The compute binds only where density maps the application writes may need converting
    // (src/vk/convert.rs), and the ends of passes only where coarse blocks may need reconstructing
    // after them (docs/reconstruction.md): a device that neither emulates nor injects gets the
    // next layer's own.
    for name in [
        c"vkCmdEndRenderPass",
        c"vkCmdEndRendering",
        c"vkCreateImage",
        c"vkQueueSubmit",
        c"vkQueueSubmit2",
        c"vkCmdBindPipeline",
    ] {
        let below = gdpa(&plain.instance, &reference, name);
        assert_eq!(gdpa(&vk.instance, &untouched, name), below, "{name:?}");
        assert_ne!(
            gdpa(&vk.instance, &emulating, name),
            below,
            "the emulating device's {name:?} is fovea's"
        );
    }
    // SAFETY: destroyed once each, nothing made from them.
    unsafe {
        emulating.destroy_device(None);
        untouched.destroy_device(None);
        reference.destroy_device(None);
    }
    drop(vk);
    drop(plain);
    assert_no_messages();
}

/// The checked-in manifest names the layer as fovea_abi does, points at the release build the way
/// the OpenXR manifest does (relative to the manifest's folder), and lists the device extension
/// the layer provides, which the Vulkan loader requires of a layer that offers one
/// (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>,
/// "Layer Manifest File Format"). Both manifests (explicit and implicit, which `fovea install`
/// writes) name Vulkan 1.4.359, the registry the layer's device-creation struct table is laid
/// out from (src/vk/base/structs.rs): a loader leaves out (before 1.3.227) or warns about (since) an
/// implicit layer older than the application's `apiVersion`, and Vulkan 1.4 applications exist
/// (`vk::api14` shows one getting the layer).
#[test]
fn checked_in_manifest() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let path = root.join("manifest/vulkan/VK_LAYER_FOVEA_fragment_density_map.json");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).expect("manifest")).expect("JSON");
    let l = &m["layer"];
    assert_eq!(l["name"], fovea_abi::VK_LAYER_NAME);
    assert_eq!(l["type"], "GLOBAL");
    for key in [
        "name",
        "library_path",
        "api_version",
        "implementation_version",
        "description",
    ] {
        assert!(l[key].is_string(), "{key} must be a string");
    }
    let library = path
        .parent()
        .expect("folder")
        .join(l["library_path"].as_str().expect("string"));
    assert_eq!(
        library.components().collect::<Vec<_>>(),
        root.join("manifest/vulkan/../../target/release/libfovea.so")
            .components()
            .collect::<Vec<_>>()
    );
    assert!(!l
        .as_object()
        .expect("object")
        .contains_key("disable_environment"));
    let implicit: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(
            root.join("manifest/vulkan/implicit")
                .join(path.file_name().unwrap()),
        )
        .expect("implicit manifest"),
    )
    .expect("JSON");
    for m in [&m, &implicit] {
        assert_eq!(m["layer"]["api_version"], "1.4.359");
    }
    // The loader refuses a device extension that neither the driver nor an enabled layer's
    // manifest names: the offsets under both names, the EXT's command with them.
    let want = json!([{
        "name": fovea_abi::VK_FDM_EXTENSION,
        "spec_version": fovea_abi::VK_FDM_SPEC_VERSION.to_string()
    }, {
        "name": "VK_EXT_fragment_density_map_offset",
        "spec_version": "1",
        "entrypoints": ["vkCmdEndRendering2EXT"]
    }, {
        "name": "VK_QCOM_fragment_density_map_offset",
        "spec_version": "3"
    }]);
    for m in [&m, &implicit] {
        assert_eq!(m["layer"]["device_extensions"], want);
    }
}

/// Synchronization validation is on in these instances (as in every Vulkan test's): two fills of one
/// buffer recorded without a barrier between them are a write-after-write hazard it reports at
/// record time (<https://vulkan.lunarg.com/doc/sdk/latest/linux/synchronization_usage.html>). Without
/// it, the validation layer would stay silent and every "no message" in the suite would say less.
#[test]
fn synchronization_validation_reports_an_unsynchronized_write() {
    let Some((_serial, _env, vk)) = with_fovea(Profile::None) else {
        return;
    };
    let device = vk.device(&[], None).expect("vkCreateDevice");
    // SAFETY: every handle is used while alive and destroyed once, before its device.
    unsafe {
        let buffer = device
            .create_buffer(
                &vk::BufferCreateInfo::default()
                    .size(256)
                    .usage(vk::BufferUsageFlags::TRANSFER_DST),
                None,
            )
            .expect("vkCreateBuffer");
        let needs = device.get_buffer_memory_requirements(buffer);
        let memory = device
            .allocate_memory(
                &vk::MemoryAllocateInfo::default()
                    .allocation_size(needs.size)
                    .memory_type_index(needs.memory_type_bits.trailing_zeros()),
                None,
            )
            .expect("vkAllocateMemory");
        device
            .bind_buffer_memory(buffer, memory, 0)
            .expect("vkBindBufferMemory");
        let pool = device
            .create_command_pool(&vk::CommandPoolCreateInfo::default(), None)
            .expect("vkCreateCommandPool");
        let cb = device
            .allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool)
                    .command_buffer_count(1),
            )
            .expect("vkAllocateCommandBuffers")[0];
        device
            .begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
            .expect("vkBeginCommandBuffer");
        assert_no_messages();
        device.cmd_fill_buffer(cb, buffer, 0, 256, 1);
        device.cmd_fill_buffer(cb, buffer, 0, 256, 2);
        let messages = take_messages();
        device.end_command_buffer(cb).expect("vkEndCommandBuffer");
        device.destroy_command_pool(pool, None);
        device.destroy_buffer(buffer, None);
        device.free_memory(memory, None);
        device.destroy_device(None);
        assert!(
            messages.iter().any(|m| m.contains("WRITE_AFTER_WRITE")),
            "no write-after-write hazard reported: {messages:#?}"
        );
    }
    drop(vk);
    assert_no_messages();
}
