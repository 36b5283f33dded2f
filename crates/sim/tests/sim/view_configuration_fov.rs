//! XR_EPIC_view_configuration_fov in the simulated runtime
//! (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#XR_EPIC_view_configuration_fov):
//! offered only when configured; with the extension enabled, xrEnumerateViewConfigurationViews fills
//! an `XrViewConfigurationViewFovEPIC` chained to each view with the headset's per-eye FOVs, without
//! a session; without it enabled, the struct is ignored and enabling it is refused.

use std::ptr::null_mut;

use crate::common::*;
use fovea_sim::control::{self, SimConfig};
use openxr_sys as xr;
use openxr_sys::Handle;

const EPIC: &str = "XR_EPIC_view_configuration_fov";

fn epic_config() -> SimConfig {
    SimConfig {
        view_configuration_fov: true,
        ..config("quest3")
    }
}

/// Enumerates the stereo views with an EPIC struct chained to each, pre-set to a marker FOV.
fn views_with_epic(instance: xr::Instance) -> [xr::ViewConfigurationViewFovEPIC; 2] {
    let marker = xr::Fovf {
        angle_left: 9.0,
        angle_right: 9.0,
        angle_up: 9.0,
        angle_down: 9.0,
    };
    let mut epic = [xr::ViewConfigurationViewFovEPIC {
        ty: xr::ViewConfigurationViewFovEPIC::TYPE,
        next: std::ptr::null(),
        recommended_fov: marker,
        max_mutable_fov: marker,
    }; 2];
    let mut views: Vec<xr::ViewConfigurationView> = epic
        .iter_mut()
        .map(|e| xr::ViewConfigurationView {
            ty: xr::ViewConfigurationView::TYPE,
            next: (e as *mut xr::ViewConfigurationViewFovEPIC).cast(),
            recommended_image_rect_width: 0,
            max_image_rect_width: 0,
            recommended_image_rect_height: 0,
            max_image_rect_height: 0,
            recommended_swapchain_sample_count: 0,
            max_swapchain_sample_count: 0,
        })
        .collect();
    let enumerate = xrfn!(instance, EnumerateViewConfigurationViews);
    let mut n = 0;
    let r = unsafe {
        enumerate(
            instance,
            system(instance),
            xr::ViewConfigurationType::PRIMARY_STEREO,
            2,
            &mut n,
            views.as_mut_ptr(),
        )
    };
    assert_eq!((r, n), (xr::Result::SUCCESS, 2));
    let [w, h] = fovea_model::headsets::by_id("quest3")
        .unwrap()
        .recommended_size();
    for v in &views {
        assert_eq!(
            [
                v.recommended_image_rect_width,
                v.recommended_image_rect_height
            ],
            [w, h]
        );
    }
    drop(views);
    epic
}

fn offered() -> Vec<String> {
    let enumerate = xrfn!(xr::Instance::NULL, EnumerateInstanceExtensionProperties);
    let mut n = 0;
    assert_eq!(
        unsafe { enumerate(std::ptr::null(), 0, &mut n, null_mut()) },
        xr::Result::SUCCESS
    );
    let blank = xr::ExtensionProperties {
        ty: xr::ExtensionProperties::TYPE,
        next: null_mut(),
        extension_name: [0; xr::MAX_EXTENSION_NAME_SIZE],
        extension_version: 0,
    };
    let mut props = vec![blank; n as usize];
    assert_eq!(
        unsafe { enumerate(std::ptr::null(), n, &mut n, props.as_mut_ptr()) },
        xr::Result::SUCCESS
    );
    props
        .iter()
        .map(|p| {
            let bytes: Vec<u8> = p
                .extension_name
                .iter()
                .take_while(|c| **c != 0)
                .map(|c| *c as u8)
                .collect();
            String::from_utf8(bytes).unwrap()
        })
        .collect()
}

#[test]
fn epic_view_configuration_fov_reports_each_eyes_fov_without_a_session() {
    control::set_thread_config(Some(epic_config()));
    assert!(offered().iter().any(|e| e == EPIC));
    let instance = create_instance(epic_config(), &["XR_MND_headless", EPIC]);
    let epic = views_with_epic(instance);
    let fovs = fovea_model::headsets::by_id("quest3").unwrap().fovs();
    for (e, f) in epic.iter().zip(fovs) {
        let got = e.recommended_fov;
        assert_eq!(
            [
                got.angle_left,
                got.angle_right,
                got.angle_up,
                got.angle_down
            ],
            [f.left, f.right, f.up, f.down]
        );
        assert_eq!(e.max_mutable_fov.angle_left, f.left);
    }
    // Quest 3 is asymmetric: the two eyes differ.
    assert_ne!(
        epic[0].recommended_fov.angle_left,
        -epic[0].recommended_fov.angle_right
    );
    assert!(control::refusals(instance).is_empty());
    destroy_instance(instance);
}

#[test]
fn epic_view_configuration_fov_is_ignored_unless_enabled_and_absent_unless_offered() {
    // Offered, not enabled: the chained struct is not recognised and stays as it came.
    let instance = create_instance(epic_config(), &["XR_MND_headless"]);
    let epic = views_with_epic(instance);
    assert!(epic.iter().all(|e| e.recommended_fov.angle_left == 9.0));
    destroy_instance(instance);
    // Not offered: not listed, and enabling it is XR_ERROR_EXTENSION_NOT_PRESENT.
    control::set_thread_config(Some(config("quest3")));
    assert!(!offered().iter().any(|e| e == EPIC));
    assert_eq!(
        try_create_instance(
            config("quest3"),
            &["XR_MND_headless", EPIC],
            xr::Version::new(1, 0, 34)
        ),
        Err(xr::Result::ERROR_EXTENSION_NOT_PRESENT)
    );
    assert!(
        SimConfig::from_vars(|n| (n == "FOVEA_SIM_VIEW_CONFIGURATION_FOV").then(|| "1".into()))
            .unwrap()
            .view_configuration_fov
    );
}
