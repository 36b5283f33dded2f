//! What lies below fovea, whatever layers are stacked: fovea → a layer refusing every NULL-instance
//! lookup (crates/refuser) → the simulated runtime, through the harness. With native XR_FB_foveation
//! below, the application's FB calls reach the runtime's own implementation; without it, fovea
//! provides the extensions as usual. Either way no per-instance warning, and one line for the
//! process. fovea learns it through an instance of its own (a probe) once per process and stack of
//! layers, with a create info of its own, and never for a create info every runtime refuses
//! (src/xr/below.rs). Each test runs in a process of its own: the log, fovea's answers and the
//! simulated runtime's count of instances are process-wide.

use fovea_harness::app::{with_create_info, API_1_0};
use fovea_harness::frame_loop::FOVEATION_EXTENSIONS;
use fovea_harness::{open_library, sim, App, Chain, LayerSpec};
use openxr_sys as xr;
use xr::Handle;

use crate::support::{foveated_loop, in_own_process};

/// The refusing layer under another name: to fovea, a different stack below.
const OTHER_REFUSER: &str = "XR_APILAYER_FOVEA_test_refuse_null_lookups_too";

/// fovea over the refusing layer, named `below` (the library picks the refusing mode for any name
/// but the hiding layer's).
fn chain_over(below: &str) -> Chain {
    Chain::new(vec![
        LayerSpec::fovea().unwrap(),
        LayerSpec {
            name: below.to_owned(),
            ..LayerSpec::refuse_null_lookups().unwrap()
        },
    ])
    .unwrap()
}

fn run(native: bool, below: &str) -> (Vec<String>, bool, Vec<(&'static str, u64)>) {
    let config = sim::control::SimConfig {
        native_foveation: native,
        ..Default::default()
    };
    sim::control::set_thread_config(Some(config));
    let chain = chain_over(below);
    let app = App::new(chain, &FOVEATION_EXTENSIONS, API_1_0).unwrap();
    sim::control::set_thread_config(None);
    let instance = app.instance;
    let enabled = sim::control::enabled_extensions(instance);
    let mut lp = foveated_loop(app);
    lp.apply_profile(xr::FoveationLevelFB::HIGH, xr::FoveationDynamicFB::DISABLED)
        .unwrap();
    for _ in 0..3 {
        lp.frame().unwrap();
    }
    let applied_natively = sim::control::swapchain_foveation(lp.swapchain).is_some();
    drop(lp);
    (enabled, applied_natively, sim::control::refusals(instance))
}

#[test]
fn fovea_learns_what_lies_below_a_layer_refusing_null_instance_lookups() {
    in_own_process(
        module_path!(),
        "fovea_learns_what_lies_below_a_layer_refusing_null_instance_lookups",
        fovea_learns_what_lies_below_here,
    );
}

/// Runs in a process of its own: it sets the log filter and counts a once-per-process line.
fn fovea_learns_what_lies_below_here() {
    let dir = std::env::temp_dir().join(format!("fovea-below-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join("fovea.log");
    let _ = std::fs::remove_file(&log);
    std::env::set_var(
        "FOVEA_LOG",
        format!("warn,{}=info", fovea_abi::log_target::BELOW),
    );
    std::env::set_var("FOVEA_LOG_FILE", &log);
    // Keeps the refuser loaded across chains.
    let _keep = open_library(&LayerSpec::refuse_null_lookups().unwrap().path).unwrap();

    let refuser = fovea_harness::REFUSE_NULL_LOOKUPS_LAYER;
    for _ in 0..2 {
        let (enabled, native, refusals) = run(true, refuser);
        for fb in [
            "XR_FB_swapchain_update_state",
            "XR_FB_foveation",
            "XR_FB_foveation_configuration",
        ] {
            assert!(
                enabled.iter().any(|e| e == fb),
                "{fb} passed down: {enabled:?}"
            );
        }
        assert!(
            native,
            "the profile reached the runtime's native xrUpdateSwapchainFB"
        );
        assert_eq!(refusals, []);
    }
    // A runtime without FB foveation: under another stack, as fovea keeps what it learned under one.
    let (enabled, native, refusals) = run(false, OTHER_REFUSER);
    assert!(
        !enabled.iter().any(|e| e.starts_with("XR_FB_")),
        "fovea provides the FB extensions itself: {enabled:?}"
    );
    assert!(!native);
    assert_eq!(refusals, []);

    let text = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(
        !text.contains("does not offer xrEnumerateInstanceExtensionProperties"),
        "{text}"
    );
    assert_eq!(
        text.matches("refuses lookups without an instance").count(),
        1,
        "said once per process: {text}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The instances the runtime created, by application name, and how many calls it refused that
/// belong to no instance (refused `xrCreateInstance`s).
fn runtime_saw() -> (Vec<String>, Vec<(&'static str, u64)>) {
    let names = sim::control::created_instances()
        .into_iter()
        .map(|c| c.application_name)
        .collect();
    (names, sim::control::refusals_without_instance())
}

/// The harness's application name (`fovea_harness::app::with_create_info`), and fovea's probe's.
const APP: &str = "fovea-harness";
const PROBE: &str = "fovea";

#[test]
fn n_application_instances_make_n_plus_one_runtime_instances() {
    in_own_process(
        module_path!(),
        "n_application_instances_make_n_plus_one_runtime_instances",
        n_plus_one_here,
    );
}

/// Runs in a process of its own: it counts the simulated runtime's instances, process-wide.
fn n_plus_one_here() {
    let config = sim::control::SimConfig {
        native_foveation: true,
        ..Default::default()
    };
    sim::control::set_thread_config(Some(config));
    let n = 3;
    for _ in 0..n {
        let app = App::new(
            chain_over(fovea_harness::REFUSE_NULL_LOOKUPS_LAYER),
            &FOVEATION_EXTENSIONS,
            API_1_0,
        )
        .unwrap();
        let enabled = sim::control::enabled_extensions(app.instance);
        assert!(
            enabled.iter().any(|e| e == "XR_FB_foveation"),
            "the native extension passed down, as learned: {enabled:?}"
        );
        assert_eq!(app.destroy(), xr::Result::SUCCESS);
    }
    let (names, refused) = runtime_saw();
    assert_eq!(
        names,
        [PROBE, APP, APP, APP],
        "one probe for {n} application instances under one stack"
    );
    let probe = &sim::control::created_instances()[0];
    assert_eq!(
        (probe.api_version.major(), probe.api_version.minor()),
        (1, 0),
        "the probe asks for 1.0, which every 1.x runtime supports"
    );
    assert!(
        sim::control::enabled_extensions(probe.instance).is_empty(),
        "the probe enables nothing"
    );
    assert_eq!(refused, []);

    // Another stack below fovea: asked once again, then known too.
    for _ in 0..2 {
        let app = App::new(chain_over(OTHER_REFUSER), &FOVEATION_EXTENSIONS, API_1_0).unwrap();
        let enabled = sim::control::enabled_extensions(app.instance);
        assert!(
            enabled.iter().any(|e| e == "XR_FB_foveation"),
            "{enabled:?}"
        );
    }
    let (names, refused) = runtime_saw();
    assert_eq!(names, [PROBE, APP, APP, APP, PROBE, APP, APP]);
    assert_eq!(refused, []);
    assert_eq!(sim::control::live_objects(), 0, "the probes were destroyed");
    sim::control::set_thread_config(None);
}

#[test]
fn an_invalid_create_info_reaches_the_runtime_without_a_probe() {
    in_own_process(
        module_path!(),
        "an_invalid_create_info_reaches_the_runtime_without_a_probe",
        invalid_create_info_here,
    );
}

/// Creates an instance over the refusing layer with the harness's create info changed by `change`.
fn create_changed(change: impl FnOnce(&mut xr::InstanceCreateInfo)) -> xr::Result {
    let chain = chain_over(fovea_harness::REFUSE_NULL_LOOKUPS_LAYER);
    with_create_info(&FOVEATION_EXTENSIONS, API_1_0, |info| {
        let mut info = *info;
        change(&mut info);
        let mut instance = xr::Instance::NULL;
        // SAFETY: the harness's create info, its strings alive across the call.
        let r = unsafe { chain.create_instance(&info, &mut instance) };
        assert_eq!(instance, xr::Instance::NULL, "{r:?}");
        r
    })
}

/// Runs in a process of its own: it counts the simulated runtime's instances and refusals, and
/// needs fovea to have learned nothing yet.
fn invalid_create_info_here() {
    let r = create_changed(|i| i.application_info.api_version = xr::Version::new(0, 0, 0));
    assert_eq!(r, xr::Result::ERROR_API_VERSION_UNSUPPORTED);
    let r = create_changed(|i| {
        i.application_info.application_name = [0; xr::MAX_APPLICATION_NAME_SIZE]
    });
    assert_eq!(r, xr::Result::ERROR_NAME_INVALID);
    let (names, refused) = runtime_saw();
    assert_eq!(names, Vec::<String>::new(), "no instance below");
    assert_eq!(
        refused,
        [("xrCreateInstance", 2)],
        "the runtime refused the application's two calls and nothing else"
    );

    // A valid create info next: fovea learns then, and the runtime refuses nothing more.
    let app = App::new(
        chain_over(fovea_harness::REFUSE_NULL_LOOKUPS_LAYER),
        &FOVEATION_EXTENSIONS,
        API_1_0,
    )
    .unwrap();
    assert_ne!(app.instance.into_raw(), 0);
    let (names, refused) = runtime_saw();
    assert_eq!(names, [PROBE, APP]);
    assert_eq!(refused, [("xrCreateInstance", 2)]);
}

#[test]
fn instances_created_at_once_under_a_new_stack_share_one_probe() {
    in_own_process(
        module_path!(),
        "instances_created_at_once_under_a_new_stack_share_one_probe",
        at_once_here,
    );
}

/// Runs in a process of its own: it counts the simulated runtime's instances, and needs fovea to
/// have learned nothing yet.
fn at_once_here() {
    let threads = 4;
    let start = std::sync::Barrier::new(threads);
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| {
                let chain = chain_over(fovea_harness::REFUSE_NULL_LOOKUPS_LAYER);
                start.wait();
                let app = App::new(chain, &FOVEATION_EXTENSIONS, API_1_0).unwrap();
                assert_eq!(app.destroy(), xr::Result::SUCCESS);
            });
        }
    });
    let (names, refused) = runtime_saw();
    assert_eq!(
        names.iter().filter(|n| *n == PROBE).count(),
        1,
        "one probe between {threads} threads: {names:?}"
    );
    assert_eq!(names.len(), threads + 1, "{names:?}");
    assert_eq!(refused, []);
}

#[test]
fn a_probe_the_runtime_could_not_create_is_tried_again() {
    in_own_process(
        module_path!(),
        "a_probe_the_runtime_could_not_create_is_tried_again",
        tried_again_here,
    );
}

/// Runs in a process of its own: it counts the simulated runtime's instances, and needs fovea to
/// have learned nothing yet.
fn tried_again_here() {
    let native = sim::control::SimConfig {
        native_foveation: true,
        ..Default::default()
    };
    // The runtime cannot create instances yet (not running): the probe and the app's call fail.
    sim::control::set_thread_config(Some(sim::control::SimConfig {
        faults: vec![sim::control::Fault {
            function: "xrCreateInstance".into(),
            result: xr::Result::ERROR_RUNTIME_UNAVAILABLE,
            nth: 0,
        }],
        ..native.clone()
    }));
    let chain = chain_over(fovea_harness::REFUSE_NULL_LOOKUPS_LAYER);
    let r = App::new(chain, &FOVEATION_EXTENSIONS, API_1_0).err();
    assert_eq!(r, Some(xr::Result::ERROR_RUNTIME_UNAVAILABLE));

    // Now it can: fovea asks again rather than keeping "unknown", and passes the native FB down.
    sim::control::set_thread_config(Some(native));
    let chain = chain_over(fovea_harness::REFUSE_NULL_LOOKUPS_LAYER);
    let app = App::new(chain, &FOVEATION_EXTENSIONS, API_1_0).unwrap();
    let enabled = sim::control::enabled_extensions(app.instance);
    assert!(
        enabled.iter().any(|e| e == "XR_FB_foveation"),
        "{enabled:?}"
    );
    let (names, refused) = runtime_saw();
    assert_eq!(names, [PROBE, APP]);
    assert_eq!(
        refused,
        [],
        "injected failures are not the runtime's refusals"
    );
    sim::control::set_thread_config(None);
}
