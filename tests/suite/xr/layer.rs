//! The loader interface, driven exactly as the Khronos loader drives it, through the fake loader
//! harness and the in-process simulated runtime: negotiation, NULL-instance lookups, the layer's
//! extension list, extension stripping, dependency errors, and pass-through where the runtime has an
//! extension natively.

use std::ffi::CStr;

use fovea_harness::app::{with_create_info, API_1_0, API_1_1};
use fovea_harness::{
    layer_request, loader_info, lookup, negotiate_symbol, open_library, sim, App, Chain, LayerSpec,
};
use openxr_sys as xr;
use xr::Handle;

const FB_ALL: [&str; 6] = [
    "XR_FB_swapchain_update_state",
    "XR_FB_foveation",
    "XR_FB_foveation_configuration",
    "XR_FB_foveation_vulkan",
    "XR_META_foveation_eye_tracked",
    "XR_META_vulkan_swapchain_create_info",
];

fn layer_lib() -> libloading::Library {
    open_library(&LayerSpec::fovea().expect("libfovea.so is built").path).expect("dlopen")
}

fn negotiate(
    edit: impl FnOnce(&mut xr::NegotiateLoaderInfo, &mut xr::NegotiateApiLayerRequest),
) -> xr::Result {
    let lib = layer_lib();
    let f = negotiate_symbol(&lib).unwrap();
    let mut info = loader_info();
    let mut req = layer_request();
    edit(&mut info, &mut req);
    unsafe { f(&info, c"XR_APILAYER_FOVEA_foveation".as_ptr(), &mut req) }
}

#[test]
fn negotiation_answers_the_loaders_request() {
    let lib = layer_lib();
    let f = negotiate_symbol(&lib).unwrap();
    let info = loader_info();
    let mut req = layer_request();
    assert_eq!(
        unsafe { f(&info, c"XR_APILAYER_FOVEA_foveation".as_ptr(), &mut req) },
        xr::Result::SUCCESS
    );
    assert_eq!(req.layer_interface_version, 1);
    assert_eq!(
        (req.layer_api_version.major(), req.layer_api_version.minor()),
        (1, 1)
    );
    assert!(req.get_instance_proc_addr.is_some());
    assert!(req.create_api_layer_instance.is_some());
}

#[test]
fn negotiation_refuses_malformed_requests() {
    let failed = xr::Result::ERROR_INITIALIZATION_FAILED;
    assert_eq!(
        negotiate(|i, _| i.struct_type = xr::LoaderInterfaceStructs::API_LAYER_REQUEST),
        failed
    );
    assert_eq!(negotiate(|i, _| i.struct_version = 2), failed);
    assert_eq!(negotiate(|i, _| i.struct_size -= 8), failed);
    assert_eq!(
        negotiate(|_, r| r.struct_type = xr::LoaderInterfaceStructs::LOADER_INFO),
        failed
    );
    assert_eq!(negotiate(|_, r| r.struct_version = 0), failed);
    assert_eq!(negotiate(|_, r| r.struct_size += 8), failed);
    assert_eq!(
        negotiate(|i, _| {
            i.min_interface_version = 2;
            i.max_interface_version = 3;
        }),
        failed
    );
    assert_eq!(
        negotiate(|i, _| {
            i.min_api_version = xr::Version::new(2, 0, 0);
            i.max_api_version = xr::Version::new(2, 5, 0);
        }),
        failed
    );
    // Only 1.0 on offer (an old loader) is fine.
    assert_eq!(
        negotiate(|i, _| i.max_api_version = xr::Version::new(1, 0, 20)),
        xr::Result::SUCCESS
    );
    let lib = layer_lib();
    let f = negotiate_symbol(&lib).unwrap();
    let mut req = layer_request();
    assert_eq!(
        unsafe { f(std::ptr::null(), std::ptr::null(), &mut req) },
        failed
    );
    assert_eq!(
        unsafe { f(&loader_info(), std::ptr::null(), std::ptr::null_mut()) },
        failed
    );
}

fn raw_lookup(
    gipa: xr::pfn::GetInstanceProcAddr,
    instance: xr::Instance,
    name: &CStr,
) -> (xr::Result, bool) {
    let mut f = None;
    let r = unsafe { gipa(instance, name.as_ptr(), &mut f) };
    assert!(
        !(r == xr::Result::SUCCESS && f.is_none()),
        "{name:?}: XR_SUCCESS with NULL"
    );
    (r, f.is_some())
}

#[test]
fn null_instance_lookups_follow_the_spec_table() {
    let chain = Chain::fovea().unwrap();
    let gipa = chain.gipa();
    for name in [
        c"xrEnumerateInstanceExtensionProperties",
        c"xrEnumerateApiLayerProperties",
        c"xrCreateInstance",
    ] {
        assert_eq!(
            raw_lookup(gipa, xr::Instance::NULL, name),
            (xr::Result::SUCCESS, true),
            "{name:?}"
        );
    }
    // Modern loaders ask for xrInitializeLoaderKHR with NULL: an error, never success with NULL.
    for name in [
        c"xrInitializeLoaderKHR",
        c"xrCreateSession",
        c"xrCreateFoveationProfileFB",
        c"xrNoSuchFunction",
    ] {
        assert_eq!(
            raw_lookup(gipa, xr::Instance::NULL, name),
            (xr::Result::ERROR_HANDLE_INVALID, false),
            "{name:?}"
        );
    }
    assert_eq!(
        unsafe {
            gipa(
                xr::Instance::NULL,
                c"xrCreateInstance".as_ptr(),
                std::ptr::null_mut(),
            )
        },
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    let mut f = None;
    assert_eq!(
        unsafe { gipa(xr::Instance::NULL, std::ptr::null(), &mut f) },
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    assert!(f.is_none());
    // An instance the layer never saw.
    assert_eq!(
        raw_lookup(gipa, xr::Instance::from_raw(0xdead), c"xrPollEvent"),
        (xr::Result::ERROR_HANDLE_INVALID, false)
    );
}

#[test]
fn the_layer_lists_its_own_extensions() {
    let chain = Chain::fovea().unwrap();
    let f: xr::pfn::EnumerateInstanceExtensionProperties = unsafe {
        lookup(
            chain.gipa(),
            xr::Instance::NULL,
            c"xrEnumerateInstanceExtensionProperties",
        )
    }
    .unwrap();
    let names =
        unsafe { fovea_harness::enumerate_extensions(f, c"XR_APILAYER_FOVEA_foveation".as_ptr()) };
    assert_eq!(names, FB_ALL);
    let mut n = 0;
    assert_eq!(
        unsafe {
            f(
                c"XR_APILAYER_OTHER".as_ptr(),
                0,
                &mut n,
                std::ptr::null_mut(),
            )
        },
        xr::Result::ERROR_API_LAYER_NOT_PRESENT
    );
    let mut props = [xr::ExtensionProperties {
        ty: xr::StructureType::EXTENSION_PROPERTIES,
        next: std::ptr::null_mut(),
        extension_name: [0; xr::MAX_EXTENSION_NAME_SIZE],
        extension_version: 0,
    }; 6];
    assert_eq!(
        unsafe { f(std::ptr::null(), 2, &mut n, props.as_mut_ptr()) },
        xr::Result::ERROR_SIZE_INSUFFICIENT
    );
    assert_eq!(n, 6);
    assert_eq!(
        unsafe { f(std::ptr::null(), 6, &mut n, props.as_mut_ptr()) },
        xr::Result::SUCCESS
    );
    assert_eq!(props.map(|p| p.extension_version), [3, 1, 1, 1, 1, 1]);
    props[0].ty = xr::StructureType::SYSTEM_GET_INFO;
    assert_eq!(
        unsafe { f(std::ptr::null(), 6, &mut n, props.as_mut_ptr()) },
        xr::Result::ERROR_VALIDATION_FAILURE
    );
}

#[test]
fn provided_extensions_are_stripped_before_the_runtime() {
    sim::control::set_thread_config(None);
    let mut exts = FB_ALL.to_vec();
    exts.extend(["XR_MND_headless", "XR_KHR_vulkan_enable2"]);
    let app = App::new(Chain::fovea().unwrap(), &exts, API_1_0).expect("instance");
    let below = sim::control::enabled_extensions(app.instance);
    assert_eq!(below, ["XR_MND_headless", "XR_KHR_vulkan_enable2"]);
    // Every provided function resolves to the layer; a non-intercepted one to the runtime itself.
    for name in [
        c"xrUpdateSwapchainFB",
        c"xrGetSwapchainStateFB",
        c"xrCreateFoveationProfileFB",
        c"xrDestroyFoveationProfileFB",
        c"xrGetFoveationEyeTrackedStateMETA",
    ] {
        assert_eq!(
            raw_lookup(app.chain.gipa(), app.instance, name),
            (xr::Result::SUCCESS, true),
            "{name:?}"
        );
    }
    let poll_app: xr::pfn::PollEvent = unsafe { app.func(c"xrPollEvent") };
    let poll_rt: xr::pfn::PollEvent =
        unsafe { fovea_harness::runtime_fn(app.instance, c"xrPollEvent") }.unwrap();
    assert_eq!(
        poll_app as usize, poll_rt as usize,
        "non-intercepted functions come from below untouched"
    );
    assert_eq!(app.destroy(), xr::Result::SUCCESS);
}

#[test]
fn functions_of_extensions_not_enabled_are_unsupported() {
    sim::control::set_thread_config(None);
    let app = App::new(
        Chain::fovea().unwrap(),
        &["XR_FB_swapchain_update_state", "XR_MND_headless"],
        API_1_0,
    )
    .unwrap();
    assert_eq!(
        raw_lookup(app.chain.gipa(), app.instance, c"xrUpdateSwapchainFB"),
        (xr::Result::SUCCESS, true)
    );
    for name in [
        c"xrCreateFoveationProfileFB",
        c"xrDestroyFoveationProfileFB",
        c"xrGetFoveationEyeTrackedStateMETA",
    ] {
        assert_eq!(
            raw_lookup(app.chain.gipa(), app.instance, name),
            (xr::Result::ERROR_FUNCTION_UNSUPPORTED, false)
        );
    }
    // A runtime extension the app did not enable stays unsupported through the layer.
    assert_eq!(
        raw_lookup(app.chain.gipa(), app.instance, c"xrCreateVulkanDeviceKHR"),
        (xr::Result::ERROR_FUNCTION_UNSUPPORTED, false)
    );
}

#[test]
fn missing_dependencies_fail_only_for_1_1_apps() {
    sim::control::set_thread_config(None);
    let cases: [(&[&str], bool); 4] = [
        (&["XR_FB_foveation"], false),
        (
            &[
                "XR_FB_swapchain_update_state",
                "XR_FB_foveation_configuration",
            ],
            false,
        ),
        (
            &[
                "XR_FB_swapchain_update_state",
                "XR_FB_foveation",
                "XR_META_vulkan_swapchain_create_info",
            ],
            false,
        ),
        (
            &[
                "XR_FB_swapchain_update_state",
                "XR_FB_foveation",
                "XR_FB_foveation_vulkan",
                "XR_KHR_vulkan_enable2",
            ],
            true,
        ),
    ];
    for (exts, ok) in cases {
        let r11 = App::new(Chain::fovea().unwrap(), exts, API_1_1)
            .map(|_| ())
            .err();
        let want = if ok {
            None
        } else {
            Some(xr::Result::ERROR_EXTENSION_DEPENDENCY_NOT_ENABLED)
        };
        assert_eq!(r11, want, "{exts:?} as a 1.1 app");
        assert!(
            App::new(Chain::fovea().unwrap(), exts, API_1_0).is_ok(),
            "{exts:?} as a 1.0 app"
        );
    }
}

#[test]
fn native_extensions_pass_through_untouched() {
    let mut cfg = sim::control::SimConfig::from_env().unwrap();
    cfg.native_swapchain_update_state = true;
    sim::control::set_thread_config(Some(cfg));

    // The runtime has XR_FB_swapchain_update_state: it stays enabled below and its functions are the
    // runtime's own.
    let app = App::new(
        Chain::fovea().unwrap(),
        &["XR_FB_swapchain_update_state", "XR_MND_headless"],
        API_1_0,
    )
    .unwrap();
    assert_eq!(
        sim::control::enabled_extensions(app.instance),
        ["XR_FB_swapchain_update_state", "XR_MND_headless"]
    );
    let via_app: xr::pfn::UpdateSwapchainFB = unsafe { app.func(c"xrUpdateSwapchainFB") };
    let native: xr::pfn::UpdateSwapchainFB =
        unsafe { fovea_harness::runtime_fn(app.instance, c"xrUpdateSwapchainFB") }.unwrap();
    assert_eq!(via_app as usize, native as usize);
    drop(app);

    // With XR_FB_foveation on top, which the runtime lacks, fovea takes xrUpdateSwapchainFB (for the
    // foveation state) while the runtime keeps update_state enabled.
    let app = App::new(
        Chain::fovea().unwrap(),
        &[
            "XR_FB_swapchain_update_state",
            "XR_FB_foveation",
            "XR_MND_headless",
        ],
        API_1_0,
    )
    .unwrap();
    assert_eq!(
        sim::control::enabled_extensions(app.instance),
        ["XR_FB_swapchain_update_state", "XR_MND_headless"]
    );
    let via_app: xr::pfn::UpdateSwapchainFB = unsafe { app.func(c"xrUpdateSwapchainFB") };
    assert_ne!(via_app as usize, native as usize);
    drop(app);
    sim::control::set_thread_config(None);
}

#[test]
fn the_loader_pre_check_sees_the_layers_extensions() {
    sim::control::set_thread_config(None);
    let available = Chain::fovea().unwrap().available_extensions();
    for e in FB_ALL {
        assert!(available.iter().any(|a| a == e), "{e}");
    }
    // Without the layer the runtime offers none of them, so the same instance fails.
    let r = with_create_info(&FB_ALL, API_1_0, |info| {
        let mut i = xr::Instance::NULL;
        unsafe { Chain::bare().create_instance(info, &mut i) }
    });
    assert_eq!(r, xr::Result::ERROR_EXTENSION_NOT_PRESENT);
}

#[test]
fn bad_create_infos_are_refused_without_reaching_the_runtime() {
    sim::control::set_thread_config(None);
    let chain = Chain::fovea().unwrap();
    let layer = &chain.layers[0];
    let mut instance = xr::Instance::NULL;
    // A NULL layer info or create info.
    assert_eq!(
        with_create_info(&[], API_1_0, |info| unsafe {
            (layer.create)(info, std::ptr::null(), &mut instance)
        }),
        xr::Result::ERROR_INITIALIZATION_FAILED
    );
    assert_eq!(
        unsafe { chain.create_instance(std::ptr::null(), &mut instance) },
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    // A create info of the wrong type.
    let r = with_create_info(&[], API_1_0, |info| {
        let mut bad = *info;
        bad.ty = xr::StructureType::SESSION_CREATE_INFO;
        unsafe { chain.create_instance(&bad, &mut instance) }
    });
    assert_eq!(r, xr::Result::ERROR_VALIDATION_FAILURE);
    assert_eq!(instance, xr::Instance::NULL);
}

#[test]
fn core_validation_stacks_above_and_below() {
    let Some(cv) = LayerSpec::core_validation() else {
        fovea_harness::skip("openxr-layer-corevalidation is not installed");
        return;
    };
    sim::control::set_thread_config(None);
    let fovea = LayerSpec::fovea().unwrap();
    for order in [
        vec![cv.clone(), fovea.clone()],
        vec![fovea.clone(), cv.clone()],
    ] {
        let names: Vec<_> = order.iter().map(|l| l.name.clone()).collect();
        let app = App::new(
            Chain::new(order).unwrap(),
            &[
                "XR_FB_swapchain_update_state",
                "XR_FB_foveation",
                "XR_MND_headless",
            ],
            API_1_0,
        )
        .unwrap_or_else(|r| panic!("{names:?}: {r:?}"));
        assert_eq!(
            sim::control::enabled_extensions(app.instance),
            ["XR_MND_headless"],
            "{names:?}"
        );
        let session = app
            .headless_session()
            .unwrap_or_else(|r| panic!("{names:?}: session {r:?}"));
        let destroy: xr::pfn::DestroySession = unsafe { app.func(c"xrDestroySession") };
        assert_eq!(unsafe { destroy(session) }, xr::Result::SUCCESS);
        assert_eq!(app.destroy(), xr::Result::SUCCESS, "{names:?}");
    }
}
