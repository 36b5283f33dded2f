//! Symmetric-FOV mode (`FOVEA_SYMMETRIC_FOV=1`) through the harness on the simulated Quest 3: one
//! shared symmetric FOV from xrLocateViews, recommended sizes enlarged to keep pixels per tangent,
//! and nothing changed without the switch. One test function, in a process of its own: the switch
//! is process-wide.

use fovea_harness::app::API_1_0;
use fovea_harness::{sim, App, Chain};
use fovea_model::projection::symmetric_fov;
use fovea_model::Fov;
use openxr_sys as xr;
use xr::Handle;

use crate::support::in_own_process;

fn views(app: &App) -> [[u32; 4]; 2] {
    let f: xr::pfn::EnumerateViewConfigurationViews =
        unsafe { app.func(c"xrEnumerateViewConfigurationViews") };
    let blank = xr::ViewConfigurationView {
        ty: xr::StructureType::VIEW_CONFIGURATION_VIEW,
        next: std::ptr::null_mut(),
        recommended_image_rect_width: 0,
        max_image_rect_width: 0,
        recommended_image_rect_height: 0,
        max_image_rect_height: 0,
        recommended_swapchain_sample_count: 0,
        max_swapchain_sample_count: 0,
    };
    let mut v = [blank; 2];
    let mut n = 0;
    let r = unsafe {
        f(
            app.instance,
            app.system(),
            xr::ViewConfigurationType::PRIMARY_STEREO,
            2,
            &mut n,
            v.as_mut_ptr(),
        )
    };
    assert_eq!((r, n), (xr::Result::SUCCESS, 2));
    v.map(|v| {
        [
            v.recommended_image_rect_width,
            v.recommended_image_rect_height,
            v.max_image_rect_width,
            v.max_image_rect_height,
        ]
    })
}

fn locate(app: &App, session: xr::Session) -> [Fov; 2] {
    unsafe {
        let create: xr::pfn::CreateReferenceSpace = app.func(c"xrCreateReferenceSpace");
        let locate: xr::pfn::LocateViews = app.func(c"xrLocateViews");
        let info = xr::ReferenceSpaceCreateInfo {
            ty: xr::StructureType::REFERENCE_SPACE_CREATE_INFO,
            next: std::ptr::null(),
            reference_space_type: xr::ReferenceSpaceType::LOCAL,
            pose_in_reference_space: xr::Posef::IDENTITY,
        };
        let mut space = xr::Space::NULL;
        assert_eq!(create(session, &info, &mut space), xr::Result::SUCCESS);
        let li = xr::ViewLocateInfo {
            ty: xr::StructureType::VIEW_LOCATE_INFO,
            next: std::ptr::null(),
            view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
            display_time: xr::Time::from_nanos(1_000_000),
            space,
        };
        let mut vs = xr::ViewState {
            ty: xr::StructureType::VIEW_STATE,
            next: std::ptr::null_mut(),
            view_state_flags: xr::ViewStateFlags::EMPTY,
        };
        let blank = xr::View {
            ty: xr::StructureType::VIEW,
            next: std::ptr::null_mut(),
            pose: xr::Posef::IDENTITY,
            fov: xr::Fovf::default(),
        };
        let mut v = [blank; 2];
        let mut n = 0;
        let r = locate(session, &li, &mut vs, 2, &mut n, v.as_mut_ptr());
        assert_eq!((r, n), (xr::Result::SUCCESS, 2));
        v.map(|v| Fov {
            left: v.fov.angle_left,
            right: v.fov.angle_right,
            up: v.fov.angle_up,
            down: v.fov.angle_down,
        })
    }
}

fn run(symmetric: bool) -> ([[u32; 4]; 2], [[u32; 4]; 2], [Fov; 2]) {
    std::env::set_var("FOVEA_SYMMETRIC_FOV", if symmetric { "1" } else { "0" });
    sim::control::set_thread_config(None);
    let app = App::new(Chain::fovea().unwrap(), &["XR_MND_headless"], API_1_0).unwrap();
    let before_session = views(&app);
    let session = app.headless_session().unwrap();
    let with_session = views(&app);
    let fovs = locate(&app, session);
    (before_session, with_session, fovs)
}

#[test]
fn symmetric_mode_shares_one_fov_and_enlarges_the_sizes() {
    in_own_process(
        module_path!(),
        "symmetric_mode_shares_one_fov_and_enlarges_the_sizes",
        symmetric_mode_shares_one_fov_and_enlarges_the_sizes_here,
    );
}

fn symmetric_mode_shares_one_fov_and_enlarges_the_sizes_here() {
    let q3 = fovea_model::headsets::by_id("quest3").unwrap();
    let true_fovs = q3.fovs();
    let [rw, rh] = q3.recommended_size();

    let (before, with_session, fovs) = run(false);
    assert_eq!(before, with_session);
    assert_eq!([before[0][0], before[0][1]], [rw, rh]);
    assert_eq!(
        fovs, true_fovs,
        "without the switch the runtime's FOVs pass untouched"
    );

    let (before, with_session, fovs) = run(true);
    // Before a session exists fovea cannot know the FOVs: the runtime's sizes pass.
    assert_eq!([before[0][0], before[0][1]], [rw, rh]);
    let shared = symmetric_fov(&true_fovs).unwrap();
    assert_eq!(fovs, [shared; 2]);
    let [sw, sh] = q3.symmetric_size();
    for v in with_session {
        assert!(
            v[0].abs_diff(sw) <= 16 && v[1].abs_diff(sh) <= 16,
            "{v:?} vs {sw}x{sh}"
        );
        assert!(v[0] > rw && v[1] > rh);
        assert!(v[2] >= v[0] && v[3] >= v[1]);
    }
    std::env::remove_var("FOVEA_SYMMETRIC_FOV");
}
