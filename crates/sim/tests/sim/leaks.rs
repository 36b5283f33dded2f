//! Nothing outlives its parent: the one test runs in a process of its own, so the global object
//! count is not disturbed by other tests.

use std::ptr::null;

use crate::common::*;
use fovea_sim::control;
use openxr_sys as xr;

use crate::process::in_own_process;

/// In a process of its own ([`crate::process::in_own_process`]): it asserts on the process-wide object count.
#[test]
fn destroying_the_instance_destroys_everything() {
    in_own_process(
        module_path!(),
        "destroying_the_instance_destroys_everything",
        destroying_the_instance_destroys_everything_here,
    );
}

fn destroying_the_instance_destroys_everything_here() {
    assert_eq!(control::live_objects(), 0);
    let (instance, session) = headless(config("quest3"));
    reference_space(instance, session, xr::ReferenceSpaceType::VIEW);
    let sc = create_swapchain(instance, session, &swapchain_info(43, 32, 32, 1)).unwrap();
    cycle_image(instance, sc);
    // instance + session + space + swapchain
    assert_eq!(control::live_objects(), 4);
    destroy_instance(instance);
    assert_eq!(control::live_objects(), 0);
    // A failed create leaves nothing behind.
    let plain = create_instance(config("quest3"), &[]);
    assert_eq!(
        create_session_with(plain, null()),
        Err(xr::Result::ERROR_GRAPHICS_DEVICE_INVALID)
    );
    assert_eq!(control::live_objects(), 1);
    destroy_instance(plain);
    assert_eq!(control::live_objects(), 0);
}
