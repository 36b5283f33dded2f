//! crates/refuser's two test layers in the in-process fake loader (crates/harness): the refusing
//! one answers every NULL-instance lookup with XR_ERROR_HANDLE_INVALID, the hiding one lists no
//! extensions below it, and both pass an instance's calls through to the runtime untouched.
//!
//! The layer's counters are process-wide and tests run in parallel, so they are compared as
//! "at least" differences; each test holds the library open so that dropping a chain does not
//! unload it and reset them.

use std::ffi::CStr;

use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::{HeadlessLoop, SwapchainSpec};
use fovea_harness::{
    enumerate_extensions, lookup, refuser_stats, runtime_gipa, sim, App, Chain, LayerSpec,
    HIDE_EXTENSIONS_LAYER, REFUSE_NULL_LOOKUPS_LAYER,
};
use openxr_sys as xr;
use openxr_sys::Handle;

const GLOBALS: [&CStr; 3] = [
    c"xrEnumerateInstanceExtensionProperties",
    c"xrEnumerateApiLayerProperties",
    c"xrCreateInstance",
];

fn null_lookup(gipa: xr::pfn::GetInstanceProcAddr, name: &CStr) -> (xr::Result, bool) {
    let mut f = None;
    let r = unsafe { gipa(xr::Instance::NULL, name.as_ptr(), &mut f) };
    (r, f.is_some())
}

/// A configuration whose runtime offers an FB extension natively, so hiding and refusing have
/// something to hide.
fn native_config() -> sim::control::SimConfig {
    sim::control::SimConfig {
        native_swapchain_update_state: true,
        ..Default::default()
    }
}

#[test]
fn the_refusing_layer_refuses_every_null_instance_lookup() {
    let spec = LayerSpec::refuse_null_lookups().unwrap();
    let path = spec.path.clone();
    // Keeps the library (and its counters) loaded when the chain is dropped.
    let _keep = fovea_harness::open_library(&path).unwrap();
    let chain = Chain::new(vec![spec]).unwrap();
    let gipa = chain.layers[0].gipa;
    let before = refuser_stats(&path).unwrap();
    let names = [
        c"xrEnumerateInstanceExtensionProperties",
        c"xrEnumerateApiLayerProperties",
        c"xrCreateInstance",
        c"xrInitializeLoaderKHR",
        c"xrGetInstanceProcAddr",
        c"xrDestroyInstance",
        c"xrNope",
    ];
    for name in names {
        assert_eq!(
            null_lookup(gipa, name),
            (xr::Result::ERROR_HANDLE_INVALID, false),
            "{name:?}"
        );
    }
    // The runtime below would have answered the globals.
    for name in GLOBALS {
        assert_eq!(
            null_lookup(runtime_gipa(), name),
            (xr::Result::SUCCESS, true),
            "{name:?}"
        );
    }
    let after = refuser_stats(&path).unwrap();
    assert!(after.null_lookups_refused - before.null_lookups_refused >= names.len() as u64);
    // The fake loader's pre-check asks every layer by name, as a loader reading manifests would
    // answer: the refusing layer contributes nothing and the runtime's list stands.
    sim::control::set_thread_config(Some(native_config()));
    let available = chain.available_extensions();
    assert!(
        available
            .iter()
            .any(|e| e == "XR_FB_swapchain_update_state"),
        "{available:?}"
    );
    sim::control::set_thread_config(None);
}

#[test]
fn the_refusing_layer_passes_an_instance_through_untouched() {
    let spec = LayerSpec::refuse_null_lookups().unwrap();
    let path = spec.path.clone();
    // Keeps the library (and its counters) loaded when the chain is dropped.
    let _keep = fovea_harness::open_library(&path).unwrap();
    let before = refuser_stats(&path).unwrap();
    sim::control::set_thread_config(Some(native_config()));
    let app = App::new(
        Chain::new(vec![spec]).unwrap(),
        &["XR_MND_headless", "XR_FB_swapchain_update_state"],
        API_1_0,
    )
    .unwrap();
    sim::control::set_thread_config(None);
    let instance = app.instance;
    assert_eq!(
        sim::control::enabled_extensions(instance),
        ["XR_MND_headless", "XR_FB_swapchain_update_state"]
    );
    // Every lookup on the instance yields the runtime's own pointer: no code of the layer runs
    // in those calls.
    let gipa = app.chain.layers[0].gipa;
    for name in [
        c"xrGetSystem",
        c"xrCreateSession",
        c"xrWaitFrame",
        c"xrLocateViews",
        c"xrUpdateSwapchainFB",
    ] {
        let through: xr::pfn::VoidFunction = unsafe { lookup(gipa, instance, name) }.unwrap();
        let direct: xr::pfn::VoidFunction =
            unsafe { lookup(runtime_gipa(), instance, name) }.unwrap();
        assert_eq!(through as usize, direct as usize, "{name:?}");
    }
    // Not enabled, not offered: the runtime's answer, passed on.
    assert_eq!(
        unsafe { lookup::<xr::pfn::VoidFunction>(gipa, instance, c"xrCreateFoveationProfileFB") }
            .err(),
        Some(xr::Result::ERROR_FUNCTION_UNSUPPORTED)
    );
    // A whole frame loop through it, and nothing the runtime refuses reached it.
    let mut frames = HeadlessLoop::new(
        app,
        SwapchainSpec {
            foveation: false,
            array_size: 2,
        },
    )
    .unwrap();
    for _ in 0..5 {
        frames.frame().unwrap();
    }
    assert_eq!(sim::control::refusals(instance), []);
    drop(frames);
    let after = refuser_stats(&path).unwrap();
    assert!(after.instances_created > before.instances_created);
    assert!(after.instances_destroyed > before.instances_destroyed);
    assert!(after.forwarded_lookups - before.forwarded_lookups >= 5);
}

#[test]
fn the_hiding_layer_lists_no_extensions_below_it() {
    let spec = LayerSpec::hide_extensions().unwrap();
    let path = spec.path.clone();
    // Keeps the library (and its counters) loaded when the chain is dropped.
    let _keep = fovea_harness::open_library(&path).unwrap();
    let chain = Chain::new(vec![spec]).unwrap();
    let gipa = chain.layers[0].gipa;
    let before = refuser_stats(&path).unwrap();
    sim::control::set_thread_config(Some(native_config()));
    let below: xr::pfn::EnumerateInstanceExtensionProperties = unsafe {
        lookup(
            runtime_gipa(),
            xr::Instance::NULL,
            c"xrEnumerateInstanceExtensionProperties",
        )
    }
    .unwrap();
    let runtime_has = unsafe { enumerate_extensions(below, std::ptr::null()) };
    assert!(runtime_has.contains(&"XR_FB_swapchain_update_state".to_string()));
    let hidden: xr::pfn::EnumerateInstanceExtensionProperties = unsafe {
        lookup(
            gipa,
            xr::Instance::NULL,
            c"xrEnumerateInstanceExtensionProperties",
        )
    }
    .unwrap();
    assert_eq!(
        unsafe { enumerate_extensions(hidden, std::ptr::null()) },
        Vec::<String>::new()
    );
    let mut n = 7;
    let other = c"XR_APILAYER_SOMEONE_else";
    assert_eq!(
        unsafe { hidden(other.as_ptr(), 0, &mut n, std::ptr::null_mut()) },
        xr::Result::ERROR_API_LAYER_NOT_PRESENT
    );
    // It names itself, and refuses the other NULL-instance names.
    let layers: xr::pfn::EnumerateApiLayerProperties =
        unsafe { lookup(gipa, xr::Instance::NULL, c"xrEnumerateApiLayerProperties") }.unwrap();
    let mut props = [xr::ApiLayerProperties {
        ty: xr::StructureType::API_LAYER_PROPERTIES,
        next: std::ptr::null_mut(),
        layer_name: [0; xr::MAX_API_LAYER_NAME_SIZE],
        spec_version: xr::Version::new(0, 0, 0),
        layer_version: 0,
        description: [0; xr::MAX_API_LAYER_DESCRIPTION_SIZE],
    }];
    assert_eq!(
        unsafe { layers(1, &mut n, props.as_mut_ptr()) },
        xr::Result::SUCCESS
    );
    assert_eq!(n, 1);
    let name = unsafe { CStr::from_ptr(props[0].layer_name.as_ptr()) };
    assert_eq!(name.to_str().unwrap(), HIDE_EXTENSIONS_LAYER);
    assert_eq!(
        null_lookup(gipa, c"xrCreateInstance"),
        (xr::Result::ERROR_HANDLE_INVALID, false)
    );
    // Instances still pass through, with the runtime's extensions (the loader's pre-check reads
    // the runtime, not the layer).
    let app = App::new(
        chain,
        &["XR_MND_headless", "XR_FB_swapchain_update_state"],
        API_1_0,
    )
    .unwrap();
    sim::control::set_thread_config(None);
    assert!(app.headless_session().is_ok());
    let after = refuser_stats(&path).unwrap();
    assert!(after.hidden_enumerations - before.hidden_enumerations >= 3);
    assert_ne!(HIDE_EXTENSIONS_LAYER, REFUSE_NULL_LOOKUPS_LAYER);
}
