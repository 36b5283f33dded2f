//! What lies below fovea, whatever layers are stacked: fovea → a layer refusing every NULL-instance
//! lookup (crates/refuser) → the simulated runtime, through the harness. With native XR_FB_foveation
//! below, the application's FB calls reach the runtime's own implementation; without it, fovea
//! provides the extensions as usual. Either way no per-instance warning, and one line for the
//! process. One test function: the log is process-wide.

use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::{HeadlessLoop, SwapchainSpec, FOVEATION_EXTENSIONS};
use fovea_harness::{open_library, sim, App, Chain, LayerSpec};
use openxr_sys as xr;

use crate::support::in_own_process;

fn run(native: bool) -> (Vec<String>, bool, Vec<(&'static str, u64)>) {
    let config = sim::control::SimConfig {
        native_foveation: native,
        ..Default::default()
    };
    sim::control::set_thread_config(Some(config));
    let chain = Chain::new(vec![
        LayerSpec::fovea().unwrap(),
        LayerSpec::refuse_null_lookups().unwrap(),
    ])
    .unwrap();
    let app = App::new(chain, &FOVEATION_EXTENSIONS, API_1_0).unwrap();
    sim::control::set_thread_config(None);
    let instance = app.instance;
    let enabled = sim::control::enabled_extensions(instance);
    let mut lp = HeadlessLoop::new(
        app,
        SwapchainSpec {
            foveation: true,
            array_size: 2,
        },
    )
    .unwrap();
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

    for _ in 0..2 {
        let (enabled, native, refusals) = run(true);
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
    let (enabled, native, refusals) = run(false);
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
