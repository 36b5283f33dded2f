//! A panic inside a hook becomes XR_ERROR_RUNTIME_FAILURE and a log line; the application goes on.
//!
//! `FOVEA_INJECT_PANIC` is read once per process, so this file holds a single test and sets it before
//! the layer is first called. A test binary of its own, not a module of the suite (tests/suite): the
//! suite's process calls the layer in its other tests, so the variable would be read too late there
//! (and would make their xrCreateSession fail).

use fovea_harness::app::API_1_0;
use fovea_harness::{sim, App, Chain};
use openxr_sys as xr;
use xr::Handle;

// The layer reads no fovea.toml and writes no log file in the user's home during tests.
fovea_harness::private_home!();

#[test]
fn a_panicking_hook_returns_runtime_failure_and_the_app_goes_on() {
    std::env::set_var("FOVEA_INJECT_PANIC", "xrCreateSession");
    sim::control::set_thread_config(None);
    let app = App::new(Chain::fovea().unwrap(), &["XR_MND_headless"], API_1_0).expect("instance");
    assert_eq!(
        app.headless_session(),
        Err(xr::Result::ERROR_RUNTIME_FAILURE)
    );
    // Nothing reached the runtime, and every other call still works.
    assert!(sim::control::journal(app.instance)
        .iter()
        .all(|c| c.function != "xrCreateSession"));
    let poll: xr::pfn::PollEvent = unsafe { app.func(c"xrPollEvent") };
    let mut event = xr::EventDataBuffer {
        ty: xr::StructureType::EVENT_DATA_BUFFER,
        next: std::ptr::null(),
        varying: [0; 4000],
    };
    let r = unsafe { poll(app.instance, &mut event) };
    assert!(
        r == xr::Result::SUCCESS || r == xr::Result::EVENT_UNAVAILABLE,
        "{r:?}"
    );
    assert_ne!(app.instance.into_raw(), 0);
    assert_eq!(app.destroy(), xr::Result::SUCCESS);
}
