//! Symmetric-FOV mode (`FOVEA_SYMMETRIC_FOV=1`) through the harness on the strict simulated Quest 3
//! (asymmetric; xrLocateViews only in a running session): one shared symmetric FOV, recommended sizes
//! enlarged to keep pixels per tangent, and nothing changed without the switch. With
//! XR_EPIC_view_configuration_fov the sizes are enlarged whenever the app asks; without it, only once
//! a session runs, and an app that sized before keeps each eye's own FOV (one log line says so). No
//! call the runtime refuses reaches it in any mode. One test function: the switch and the log are
//! process-wide, so it runs in a process of its own.

use fovea_harness::app::API_1_0;
use fovea_harness::{sim, App, Chain};
use fovea_model::projection::symmetric_fov;
use fovea_model::Fov;
use openxr_sys as xr;
use xr::Handle;

use crate::support::in_own_process;

pub(crate) fn views(app: &App) -> [[u32; 4]; 2] {
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

/// xrBeginSession with the stereo configuration: views exist only in a running session (a runtime
/// may refuse xrLocateViews before, as Monado does;
/// https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#xrLocateViews).
pub(crate) fn begin(app: &App, session: xr::Session) {
    let begin: xr::pfn::BeginSession = unsafe { app.func(c"xrBeginSession") };
    let info = xr::SessionBeginInfo {
        ty: xr::StructureType::SESSION_BEGIN_INFO,
        next: std::ptr::null(),
        primary_view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
    };
    assert_eq!(unsafe { begin(session, &info) }, xr::Result::SUCCESS);
}

pub(crate) fn locate(app: &App, session: xr::Session) -> [Fov; 2] {
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

/// The runtime's recommended sizes, and the FOVs located, for one app run.
struct Run {
    before_session: [[u32; 4]; 2],
    with_session: [[u32; 4]; 2],
    /// Asked for again after xrBeginSession, where the run does.
    after_begin: Option<[[u32; 4]; 2]>,
    fovs: [Fov; 2],
    epic_enabled: bool,
}

fn run(symmetric: bool, epic: bool, enumerate_after_begin: bool) -> Run {
    std::env::set_var("FOVEA_SYMMETRIC_FOV", if symmetric { "1" } else { "0" });
    sim::control::set_thread_config(Some(sim::control::SimConfig {
        view_configuration_fov: epic,
        ..Default::default()
    }));
    let app = App::new(Chain::fovea().unwrap(), &["XR_MND_headless"], API_1_0).unwrap();
    sim::control::set_thread_config(None);
    let before_session = views(&app);
    let session = app.headless_session().unwrap();
    let with_session = views(&app);
    begin(&app, session);
    let after_begin = enumerate_after_begin.then(|| views(&app));
    let fovs = locate(&app, session);
    assert_eq!(
        sim::control::refusals(app.instance),
        [],
        "symmetric {symmetric}, EPIC {epic}: fovea made a call the runtime refuses"
    );
    let epic_enabled = sim::control::enabled_extensions(app.instance)
        .iter()
        .any(|e| e == "XR_EPIC_view_configuration_fov");
    Run {
        before_session,
        with_session,
        after_begin,
        fovs,
        epic_enabled,
    }
}

/// Sizes enlarged for the shared FOV, as the preset's symmetric size documents.
fn assert_enlarged(views: [[u32; 4]; 2], q3: &fovea_model::headsets::Headset) {
    let [rw, rh] = q3.recommended_size();
    let [sw, sh] = q3.symmetric_size();
    for v in views {
        assert!(
            v[0].abs_diff(sw) <= 16 && v[1].abs_diff(sh) <= 16,
            "{v:?} vs {sw}x{sh}"
        );
        assert!(v[0] > rw && v[1] > rh);
        assert!(v[2] >= v[0] && v[3] >= v[1]);
    }
}

const FALLBACK_LINE: &str = "symmetric FOV is off for this session";

#[test]
fn symmetric_mode_shares_one_fov_and_enlarges_the_sizes() {
    in_own_process(
        module_path!(),
        "symmetric_mode_shares_one_fov_and_enlarges_the_sizes",
        symmetric_mode_shares_one_fov_and_enlarges_the_sizes_here,
    );
}

fn symmetric_mode_shares_one_fov_and_enlarges_the_sizes_here() {
    let dir = std::env::temp_dir().join(format!("fovea-symmetric-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join("fovea.log");
    let _ = std::fs::remove_file(&log);
    std::env::set_var("FOVEA_LOG_FILE", &log);

    let q3 = fovea_model::headsets::by_id("quest3").unwrap();
    let true_fovs = q3.fovs();
    let [rw, rh] = q3.recommended_size();
    let shared = symmetric_fov(&true_fovs).unwrap();

    // Without the switch nothing changes, and fovea enables nothing.
    for epic in [true, false] {
        let r = run(false, epic, true);
        assert_eq!(r.before_session, r.with_session);
        assert_eq!(Some(r.before_session), r.after_begin);
        assert_eq!([r.before_session[0][0], r.before_session[0][1]], [rw, rh]);
        assert_eq!(
            r.fovs, true_fovs,
            "without the switch the runtime's FOVs pass untouched"
        );
        assert!(!r.epic_enabled);
    }

    // With XR_EPIC_view_configuration_fov fovea learns the FOVs without a session: the sizes are
    // enlarged whenever the app asks, before its session exists too.
    let r = run(true, true, true);
    assert!(r.epic_enabled, "fovea enables the EPIC extension below");
    assert_eq!(r.fovs, [shared; 2]);
    for v in [r.before_session, r.with_session, r.after_begin.unwrap()] {
        assert_enlarged(v, q3);
    }

    // Without it the FOVs are known only once the session runs (fovea locates them right after
    // xrBeginSession): sizes asked for before are the runtime's, and since the app sized from those,
    // each eye keeps its true FOV; sizes asked for after are enlarged (the order that works).
    let r = run(true, false, false);
    assert!(!r.epic_enabled);
    assert_eq!([r.before_session[0][0], r.before_session[0][1]], [rw, rh]);
    assert_eq!(r.before_session, r.with_session);
    assert_eq!(
        r.fovs, true_fovs,
        "sized for each eye's own FOV: the views keep it"
    );
    let lines = || {
        std::fs::read_to_string(&log)
            .unwrap_or_default()
            .matches(FALLBACK_LINE)
            .count()
    };
    assert_eq!(lines(), 1, "one line says what happened");
    // Enumerating again after xrBeginSession (before any swapchain) gets the enlarged sizes, and
    // the shared FOV.
    let r = run(true, false, true);
    assert_eq!(r.before_session, r.with_session);
    assert_enlarged(r.after_begin.unwrap(), q3);
    assert_eq!(r.fovs, [shared; 2]);
    std::env::remove_var("FOVEA_SYMMETRIC_FOV");
}
