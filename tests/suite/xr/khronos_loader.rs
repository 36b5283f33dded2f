//! fovea through the real Khronos loader (Debian's libopenxr-loader1, 1.0.20): discovered by manifest
//! through `XR_API_LAYER_PATH`, enabled by `XR_ENABLE_API_LAYERS`, in front of the simulated runtime
//! selected by `XR_RUNTIME_JSON`, alone and with the Khronos core validation layer above and below.
//!
//! The loader allows one live instance per process and reads the environment, so everything runs in
//! one test, in order, in a process of its own (the suite's other tests load the layer themselves).

use std::ffi::{c_char, CStr};
use std::path::Path;

use fovea_harness::app::{with_create_info, API_1_0};
use fovea_harness::{enumerate_extensions, skip, CORE_VALIDATION_LAYER};
use openxr_sys as xr;
use xr::Handle;

use crate::support::{in_own_process, Manifests, CORE_VALIDATION_MANIFEST, DEBIAN_LAYERS};

type Gipa = xr::pfn::GetInstanceProcAddr;

unsafe fn get<F: Copy>(gipa: Gipa, instance: xr::Instance, name: &CStr) -> Result<F, xr::Result> {
    fovea_harness::lookup(gipa, instance, name)
}

/// Creates an instance with the foveation extensions and a headless session, then tears both down.
unsafe fn instance_and_session(gipa: Gipa, label: &str) {
    let create: xr::pfn::CreateInstance =
        get(gipa, xr::Instance::NULL, c"xrCreateInstance").unwrap();
    let exts = [
        "XR_FB_swapchain_update_state",
        "XR_FB_foveation",
        "XR_FB_foveation_configuration",
        "XR_MND_headless",
    ];
    let mut instance = xr::Instance::NULL;
    let r = with_create_info(&exts, API_1_0, |info| create(info, &mut instance));
    assert_eq!(r, xr::Result::SUCCESS, "{label}: xrCreateInstance");
    // The layer's functions resolve through the loader's trampoline chain.
    for name in [
        c"xrCreateFoveationProfileFB",
        c"xrUpdateSwapchainFB",
        c"xrGetSwapchainStateFB",
    ] {
        assert!(
            get::<xr::pfn::VoidFunction>(gipa, instance, name).is_ok(),
            "{label}: {name:?}"
        );
    }
    let get_system: xr::pfn::GetSystem = get(gipa, instance, c"xrGetSystem").unwrap();
    let system_info = xr::SystemGetInfo {
        ty: xr::StructureType::SYSTEM_GET_INFO,
        next: std::ptr::null(),
        form_factor: xr::FormFactor::HEAD_MOUNTED_DISPLAY,
    };
    let mut system = xr::SystemId::NULL;
    assert_eq!(
        get_system(instance, &system_info, &mut system),
        xr::Result::SUCCESS,
        "{label}"
    );
    let create_session: xr::pfn::CreateSession = get(gipa, instance, c"xrCreateSession").unwrap();
    let info = xr::SessionCreateInfo {
        ty: xr::StructureType::SESSION_CREATE_INFO,
        next: std::ptr::null(),
        create_flags: xr::SessionCreateFlags::EMPTY,
        system_id: system,
    };
    let mut session = xr::Session::NULL;
    assert_eq!(
        create_session(instance, &info, &mut session),
        xr::Result::SUCCESS,
        "{label}: xrCreateSession"
    );
    let destroy_session: xr::pfn::DestroySession =
        get(gipa, instance, c"xrDestroySession").unwrap();
    assert_eq!(destroy_session(session), xr::Result::SUCCESS, "{label}");
    let destroy: xr::pfn::DestroyInstance = get(gipa, instance, c"xrDestroyInstance").unwrap();
    assert_eq!(destroy(instance), xr::Result::SUCCESS, "{label}");
}

/// The scenario runs in a child process whose standard output the parent reads: the core
/// validation layer prints its findings with `printf`, which the test harness does not capture.
/// Zero validation messages is part of the result.
#[test]
fn discovered_by_manifest_and_stacked_with_core_validation() {
    let Some(out) = in_own_process(
        module_path!(),
        "discovered_by_manifest_and_stacked_with_core_validation",
        scenario,
    ) else {
        return;
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let findings: Vec<&str> = stdout
        .lines()
        .chain(stderr.lines())
        .filter(|l| {
            let l = l.to_ascii_lowercase();
            l.contains("error") || l.contains("vuid") || l.contains("warning")
        })
        .filter(|l| !l.contains("test result"))
        // Core validation 1.1's own debug and info records (`[time][VALID_DEBUG|VUID-...|...]:`,
        // that it was initialised and destroyed); its warnings and errors are VALID_WARNING and
        // VALID_ERROR.
        .filter(|l| !l.contains("][VALID_DEBUG|") && !l.contains("][VALID_INFO|"))
        .collect();
    assert!(
        findings.is_empty(),
        "validation or layer messages: {findings:#?}"
    );
    if !stdout.contains("SKIPPED") && !stderr.contains("SKIPPED") {
        assert!(
            stderr.contains("Core Validation output type"),
            "core validation was stacked: {stderr}"
        );
    }
}

fn scenario() {
    let loader = match unsafe { libloading::Library::new("libopenxr_loader.so.1") } {
        Ok(l) => l,
        Err(e) => {
            skip(&format!(
                "the Khronos OpenXR loader (libopenxr-loader1) is not installed: {e}"
            ));
            return;
        }
    };
    let manifests = Manifests::write("khronos-loader");
    let dir = &manifests.dir;
    std::env::set_var("XR_RUNTIME_JSON", dir.join("runtime.json"));
    std::env::set_var(
        "XR_API_LAYER_PATH",
        format!("{}:{DEBIAN_LAYERS}", dir.join("layers").display()),
    );
    std::env::set_var("XR_ENABLE_API_LAYERS", fovea_abi::LAYER_NAME);
    let gipa: Gipa = unsafe { *loader.get::<Gipa>(b"xrGetInstanceProcAddr\0").unwrap() };

    // Enabled by the environment, the layer's extensions are listed with the runtime's.
    let enumerate: xr::pfn::EnumerateInstanceExtensionProperties = unsafe {
        get(
            gipa,
            xr::Instance::NULL,
            c"xrEnumerateInstanceExtensionProperties",
        )
    }
    .unwrap();
    let listed = unsafe { enumerate_extensions(enumerate, std::ptr::null::<c_char>()) };
    for e in fovea_abi::EXTENSIONS {
        assert!(
            listed.iter().any(|l| l.as_bytes() == e.name.to_bytes()),
            "{:?} not listed: {listed:?}",
            e.name
        );
    }
    assert!(listed.iter().any(|l| l == "XR_MND_headless"), "{listed:?}");
    unsafe { instance_and_session(gipa, "fovea alone") };

    if !Path::new(DEBIAN_LAYERS)
        .join(CORE_VALIDATION_MANIFEST)
        .exists()
    {
        skip("openxr-layer-corevalidation is not installed");
        return;
    }
    for order in [
        format!("{CORE_VALIDATION_LAYER}:{}", fovea_abi::LAYER_NAME),
        format!("{}:{CORE_VALIDATION_LAYER}", fovea_abi::LAYER_NAME),
    ] {
        std::env::set_var("XR_ENABLE_API_LAYERS", &order);
        unsafe { instance_and_session(gipa, &order) };
    }
}
