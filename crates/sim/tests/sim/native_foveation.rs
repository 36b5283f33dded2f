//! The simulated runtime with native XR_FB_foveation (`SimConfig::native_foveation`,
//! `FOVEA_SIM_NATIVE_FOVEATION=1`): what a layer above must pass through
//! (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#XR_FB_foveation).

use std::ptr::null;

use crate::common::*;
use fovea_sim::control::{self, FoveationParams};
use openxr_sys as xr;
use openxr_sys::Handle;

const EXTENSIONS: [&str; 4] = [
    "XR_MND_headless",
    "XR_FB_swapchain_update_state",
    "XR_FB_foveation",
    "XR_FB_foveation_configuration",
];

fn native() -> control::SimConfig {
    control::SimConfig {
        native_foveation: true,
        ..config("quest3")
    }
}

fn profile(
    instance: xr::Instance,
    session: xr::Session,
    level: Option<xr::FoveationLevelFB>,
) -> Result<xr::FoveationProfileFB, xr::Result> {
    let create = xrfn!(instance, CreateFoveationProfileFB);
    let level_info = level.map(|level| xr::FoveationLevelProfileCreateInfoFB {
        ty: xr::FoveationLevelProfileCreateInfoFB::TYPE,
        next: std::ptr::null_mut(),
        level,
        vertical_offset: 5.0,
        dynamic: xr::FoveationDynamicFB::LEVEL_ENABLED,
    });
    let info = xr::FoveationProfileCreateInfoFB {
        ty: xr::FoveationProfileCreateInfoFB::TYPE,
        next: level_info
            .as_ref()
            .map_or(std::ptr::null_mut(), |l| l as *const _ as *mut _),
    };
    let mut p = xr::FoveationProfileFB::NULL;
    match unsafe { create(session, &info, &mut p) } {
        xr::Result::SUCCESS => Ok(p),
        e => Err(e),
    }
}

fn state(profile: xr::FoveationProfileFB) -> xr::SwapchainStateFoveationFB {
    xr::SwapchainStateFoveationFB {
        ty: xr::SwapchainStateFoveationFB::TYPE,
        next: std::ptr::null_mut(),
        flags: xr::SwapchainStateFoveationFlagsFB::EMPTY,
        profile,
    }
}

#[test]
fn native_foveation_offers_the_extensions_and_applies_profiles() {
    let instance = create_instance(native(), &EXTENSIONS);
    assert_eq!(control::enabled_extensions(instance), EXTENSIONS);
    let session = create_session_with(instance, null()).unwrap();
    let fov_info = xr::SwapchainCreateInfoFoveationFB {
        ty: xr::SwapchainCreateInfoFoveationFB::TYPE,
        next: std::ptr::null_mut(),
        flags: xr::SwapchainCreateFoveationFlagsFB::EMPTY,
    };
    let mut info = swapchain_info(43, 64, 64, 2);
    info.next = &fov_info as *const _ as *const _;
    let sc = create_swapchain(instance, session, &info).unwrap();
    let plain = create_swapchain(instance, session, &swapchain_info(43, 64, 64, 2)).unwrap();
    let update = xrfn!(instance, UpdateSwapchainFB);
    let get = xrfn!(instance, GetSwapchainStateFB);
    let destroy = xrfn!(instance, DestroyFoveationProfileFB);
    let base =
        |s: &mut xr::SwapchainStateFoveationFB| s as *mut _ as *mut xr::SwapchainStateBaseHeaderFB;

    let high = profile(instance, session, Some(xr::FoveationLevelFB::HIGH)).unwrap();
    assert_eq!(control::swapchain_foveation(sc), None);
    let mut s = state(high);
    assert_eq!(unsafe { update(sc, base(&mut s)) }, xr::Result::SUCCESS);
    let applied = FoveationParams {
        level: xr::FoveationLevelFB::HIGH,
        vertical_offset: 5.0,
        dynamic: xr::FoveationDynamicFB::LEVEL_ENABLED,
    };
    assert_eq!(control::swapchain_foveation(sc), Some(applied));
    let mut read = state(xr::FoveationProfileFB::NULL);
    assert_eq!(unsafe { get(sc, base(&mut read)) }, xr::Result::SUCCESS);
    assert_eq!(read.profile, high);

    // Destroying an applied profile leaves the swapchain's foveation as it was.
    assert_eq!(unsafe { destroy(high) }, xr::Result::SUCCESS);
    assert_eq!(control::swapchain_foveation(sc), Some(applied));
    assert_eq!(unsafe { get(sc, base(&mut read)) }, xr::Result::SUCCESS);
    assert_eq!(read.profile, xr::FoveationProfileFB::NULL);
    assert_eq!(
        unsafe { update(sc, base(&mut s)) },
        xr::Result::ERROR_HANDLE_INVALID
    );

    // Without a level struct, a profile applies no foveation.
    let none = profile(instance, session, None).unwrap();
    let mut s = state(none);
    assert_eq!(unsafe { update(sc, base(&mut s)) }, xr::Result::SUCCESS);
    assert_eq!(
        control::swapchain_foveation(sc).map(|p| p.level),
        Some(xr::FoveationLevelFB::NONE)
    );
    // Invalid usage: non-zero flags, a swapchain made without foveation support.
    let mut flagged = state(none);
    flagged.flags = xr::SwapchainStateFoveationFlagsFB::from_raw(1);
    assert_eq!(
        unsafe { update(sc, base(&mut flagged)) },
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    assert_eq!(
        unsafe { update(plain, base(&mut s)) },
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    assert_eq!(
        control::refusals(instance),
        [("xrUpdateSwapchainFB", 3)],
        "the refusals are counted"
    );
    destroy_instance(instance);
}

#[test]
fn without_the_switch_there_is_no_foveation() {
    let instance = create_instance(config("quest3"), &["XR_MND_headless"]);
    let mut f = None;
    let r = unsafe {
        fovea_sim::get_instance_proc_addr(instance, c"xrCreateFoveationProfileFB".as_ptr(), &mut f)
    };
    assert_eq!(r, xr::Result::ERROR_FUNCTION_UNSUPPORTED);
    destroy_instance(instance);
    assert_eq!(
        try_create_instance(
            config("quest3"),
            &["XR_FB_foveation"],
            xr::Version::new(1, 0, 0)
        ),
        Err(xr::Result::ERROR_EXTENSION_NOT_PRESENT)
    );
}
