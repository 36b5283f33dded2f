//! XR_META_foveation_eye_tracked through the layer on the simulated runtime: what the application
//! reads back from `xrGetSystemProperties`, `xrCreateFoveationProfileFB` and
//! `xrGetFoveationEyeTrackedStateMETA`, with and without a gaze source, and a runtime that
//! implements the extension itself passed through (docs/eye-tracking.md#xr_meta_foveation_eye_tracked).

use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::{HeadlessLoop, FOVEATION_EXTENSIONS};
use fovea_harness::{sim, App, Chain};
use openxr_sys as xr;
use xr::Handle;

use crate::support::actions::{attach_set, declare, sync_set};
use crate::support::{foveated_loop, in_own_process, level_info};

const META: &str = "XR_META_foveation_eye_tracked";
const EYE_GAZE: &str = "XR_EXT_eye_gaze_interaction";

/// The simulated runtime's configuration from `FOVEA_SIM_*` pairs.
fn config(vars: &[(&str, &str)]) -> sim::control::SimConfig {
    sim::control::SimConfig::from_vars(|k| {
        vars.iter()
            .find(|(n, _)| *n == k)
            .map(|(_, v)| v.to_string())
    })
    .unwrap()
}

/// An application on fovea over the simulated runtime configured by `vars`, with the foveation
/// extensions and `more`.
fn app(vars: &[(&str, &str)], more: &[&str]) -> App {
    sim::control::set_thread_config(Some(config(vars)));
    let mut exts: Vec<&str> = FOVEATION_EXTENSIONS.to_vec();
    exts.extend_from_slice(more);
    let app = App::new(Chain::fovea().unwrap(), &exts, API_1_0).unwrap();
    sim::control::set_thread_config(None);
    app
}

/// `supportsFoveationEyeTracked` as the application reads it, with `XrSystemEyeGazeInteractionPropertiesEXT`
/// chained in front where `gaze_first` (so the struct fovea removes is not the first), and what the
/// runtime wrote into the head and the other struct.
fn system_properties(
    app: &App,
    gaze_first: bool,
) -> (xr::Result, Option<bool>, xr::SystemProperties, xr::Bool32) {
    let mut meta = xr::SystemFoveationEyeTrackedPropertiesMETA {
        ty: xr::SystemFoveationEyeTrackedPropertiesMETA::TYPE,
        next: std::ptr::null_mut(),
        supports_foveation_eye_tracked: xr::Bool32::from_raw(7),
    };
    let mut gaze = xr::SystemEyeGazeInteractionPropertiesEXT {
        ty: xr::SystemEyeGazeInteractionPropertiesEXT::TYPE,
        next: (&mut meta as *mut xr::SystemFoveationEyeTrackedPropertiesMETA).cast(),
        supports_eye_gaze_interaction: xr::Bool32::from_raw(7),
    };
    let head: *mut std::ffi::c_void = if gaze_first {
        (&mut gaze as *mut xr::SystemEyeGazeInteractionPropertiesEXT).cast()
    } else {
        (&mut meta as *mut xr::SystemFoveationEyeTrackedPropertiesMETA).cast()
    };
    let mut props: xr::SystemProperties = unsafe { std::mem::zeroed() };
    props.ty = xr::SystemProperties::TYPE;
    props.next = head;
    let f: xr::pfn::GetSystemProperties = unsafe { app.func(c"xrGetSystemProperties") };
    let r = unsafe { f(app.instance, app.system(), &mut props) };
    assert_eq!(props.next, head, "the application's chain is its own");
    assert_eq!(
        gaze.next,
        (&mut meta as *mut xr::SystemFoveationEyeTrackedPropertiesMETA).cast(),
        "the application's chain is its own"
    );
    let supported = match meta.supports_foveation_eye_tracked.into_raw() {
        0 => Some(false),
        1 => Some(true),
        _ => None,
    };
    (r, supported, props, gaze.supports_eye_gaze_interaction)
}

#[test]
fn supported_only_where_the_system_has_a_gaze_source() {
    let on = app(&[("FOVEA_SIM_EYE_GAZE", "on")], &[META, EYE_GAZE]);
    let (r, supported, props, gaze) = system_properties(&on, true);
    assert_eq!(r, xr::Result::SUCCESS);
    assert_eq!(
        supported,
        Some(true),
        "the sim's eye tracker is a gaze source"
    );
    assert_eq!(
        gaze,
        xr::TRUE,
        "the runtime's answer in a copied struct reached the app"
    );
    assert_eq!(props.system_id, on.system());
    assert_eq!(props.tracking_properties.orientation_tracking, xr::TRUE);
    assert!(
        props.system_name[0] != 0,
        "the runtime's name reached the app"
    );
    let (r, supported, ..) = system_properties(&on, false);
    assert_eq!((r, supported), (xr::Result::SUCCESS, Some(true)));
    // The struct of an extension fovea provides never reaches the runtime.
    let journal = sim::control::journal(on.instance);
    let calls: Vec<_> = journal
        .iter()
        .filter(|c| c.function == "xrGetSystemProperties")
        .collect();
    assert!(!calls.is_empty());
    assert!(calls.iter().all(|c| !c
        .next_types
        .contains(&xr::StructureType::SYSTEM_FOVEATION_EYE_TRACKED_PROPERTIES_META)));

    // fovea enables eye gaze below on its own: the application need not.
    let own = app(&[("FOVEA_SIM_EYE_GAZE", "on")], &[META]);
    let (r, supported, ..) = system_properties(&own, false);
    assert_eq!((r, supported), (xr::Result::SUCCESS, Some(true)));

    for (vars, more) in [
        (
            &[("FOVEA_SIM_EYE_GAZE", "unsupported")][..],
            &[META, EYE_GAZE][..],
        ),
        (&[("FOVEA_SIM_EYE_GAZE", "unsupported")][..], &[META][..]),
        (&[("FOVEA_SIM_EYE_GAZE", "off")][..], &[META][..]),
    ] {
        let a = app(vars, more);
        let (r, supported, ..) = system_properties(&a, false);
        assert_eq!(
            (r, supported),
            (xr::Result::SUCCESS, Some(false)),
            "{vars:?} {more:?}"
        );
    }
}

#[test]
fn the_extension_is_listed_and_needs_the_fb_foveation_pair() {
    let names = Chain::fovea().unwrap().available_extensions();
    assert!(names.iter().any(|n| n == META), "{names:?}");
    sim::control::set_thread_config(None);
    let r = App::new(
        Chain::fovea().unwrap(),
        &["XR_FB_swapchain_update_state", "XR_FB_foveation", META],
        fovea_harness::app::API_1_1,
    );
    assert_eq!(
        r.err(),
        Some(xr::Result::ERROR_EXTENSION_DEPENDENCY_NOT_ENABLED)
    );
}

/// A running headless loop with the given runtime configuration and extensions.
fn running(vars: &[(&str, &str)], more: &[&str]) -> HeadlessLoop {
    let app = app(vars, more);
    foveated_loop(app)
}

fn create_profile(
    lp: &HeadlessLoop,
    level: &xr::FoveationLevelProfileCreateInfoFB,
    head_next: *mut std::ffi::c_void,
) -> Result<xr::FoveationProfileFB, xr::Result> {
    let f: xr::pfn::CreateFoveationProfileFB = unsafe { lp.func(c"xrCreateFoveationProfileFB") };
    let info = xr::FoveationProfileCreateInfoFB {
        ty: xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
        next: if head_next.is_null() {
            level as *const _ as *mut _
        } else {
            head_next
        },
    };
    let mut p = xr::FoveationProfileFB::NULL;
    match unsafe { f(lp.session, &info, &mut p) } {
        xr::Result::SUCCESS => Ok(p),
        r => Err(r),
    }
}

fn eye_tracked_info(flags: u64) -> xr::FoveationEyeTrackedProfileCreateInfoMETA {
    xr::FoveationEyeTrackedProfileCreateInfoMETA {
        ty: xr::FoveationEyeTrackedProfileCreateInfoMETA::TYPE,
        next: std::ptr::null(),
        flags: xr::FoveationEyeTrackedProfileCreateFlagsMETA::from_raw(flags),
    }
}

#[test]
fn eye_tracked_profiles_are_validated() {
    let lp = running(&[("FOVEA_SIM_EYE_GAZE", "on")], &[META, EYE_GAZE]);
    let meta = eye_tracked_info(0);
    let mut level = level_info(3, 0, 0.0);
    level.next = &meta as *const _ as *mut _;
    let p = create_profile(&lp, &level, std::ptr::null_mut());
    assert!(p.is_ok(), "{p:?}");

    let bad = eye_tracked_info(1);
    level.next = &bad as *const _ as *mut _;
    assert_eq!(
        create_profile(&lp, &level, std::ptr::null_mut()),
        Err(xr::Result::ERROR_VALIDATION_FAILURE),
        "no flag is defined"
    );

    // Chained in front of the level struct it extends: a struct where it cannot be.
    let mut first = eye_tracked_info(0);
    let mut level = level_info(3, 0, 0.0);
    first.next = &level as *const _ as *const _;
    assert_eq!(
        create_profile(&lp, &level, &mut first as *mut _ as *mut _),
        Err(xr::Result::ERROR_VALIDATION_FAILURE)
    );
    // Without any level struct.
    level.ty = xr::StructureType::from_raw(1_000_999_000);
    assert_eq!(
        create_profile(&lp, &level, &mut first as *mut _ as *mut _),
        Err(xr::Result::ERROR_VALIDATION_FAILURE)
    );
    // An unknown struct after the level struct is ignored, as the spec requires.
    let unknown = xr::BaseInStructure {
        ty: xr::StructureType::from_raw(1_000_999_000),
        next: std::ptr::null(),
    };
    let mut level = level_info(3, 0, 0.0);
    level.next = &unknown as *const _ as *mut _;
    assert!(create_profile(&lp, &level, std::ptr::null_mut()).is_ok());
}

/// `xrGetFoveationEyeTrackedStateMETA` through the layer.
fn get_state(
    lp: &HeadlessLoop,
    session: xr::Session,
    state: *mut xr::FoveationEyeTrackedStateMETA,
) -> xr::Result {
    let f: xr::pfn::GetFoveationEyeTrackedStateMETA =
        unsafe { lp.func(c"xrGetFoveationEyeTrackedStateMETA") };
    unsafe { f(session, state) }
}

fn state_struct() -> xr::FoveationEyeTrackedStateMETA {
    xr::FoveationEyeTrackedStateMETA {
        ty: xr::FoveationEyeTrackedStateMETA::TYPE,
        next: std::ptr::null_mut(),
        foveation_center: [xr::Vector2f { x: 9.0, y: 9.0 }; 2],
        flags: xr::FoveationEyeTrackedStateFlagsMETA::from_raw(0xff),
    }
}

#[test]
fn state_is_validated_and_without_gaze_is_fixed_foveation() {
    let mut lp = running(&[("FOVEA_SIM_EYE_GAZE", "unsupported")], &[META, EYE_GAZE]);
    assert_eq!(
        get_state(&lp, lp.session, std::ptr::null_mut()),
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    let mut wrong = state_struct();
    wrong.ty = xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB;
    assert_eq!(
        get_state(&lp, lp.session, &mut wrong),
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    assert_eq!(
        wrong.flags.into_raw(),
        0xff,
        "a refused call writes nothing"
    );
    let mut st = state_struct();
    assert_eq!(
        get_state(&lp, xr::Session::from_raw(0xbad), &mut st),
        xr::Result::ERROR_HANDLE_INVALID
    );
    // A looping chain is refused, not followed for ever.
    let mut a = xr::BaseOutStructure {
        ty: xr::StructureType::from_raw(1_000_999_000),
        next: std::ptr::null_mut(),
    };
    let mut b = xr::BaseOutStructure {
        ty: xr::StructureType::from_raw(1_000_999_001),
        next: &mut a,
    };
    a.next = &mut b;
    let mut looped = state_struct();
    looped.next = (&mut a as *mut xr::BaseOutStructure).cast();
    assert_eq!(
        get_state(&lp, lp.session, &mut looped),
        xr::Result::ERROR_VALIDATION_FAILURE
    );

    // No gaze source: the projection centres, y down, not VALID.
    for _ in 0..3 {
        lp.frame().unwrap();
    }
    let mut st = state_struct();
    assert_eq!(get_state(&lp, lp.session, &mut st), xr::Result::SUCCESS);
    assert_eq!(st.ty, xr::FoveationEyeTrackedStateMETA::TYPE);
    assert!(st.next.is_null());
    assert_eq!(st.flags.into_raw(), 0, "no gaze: never VALID");
    let headset = fovea_model::headsets::by_id("quest3").unwrap();
    let fovs = headset.fovs();
    for (i, c) in st.foveation_center.iter().enumerate() {
        let [x, y] = fovs[i].projection_center_ndc();
        assert!((c.x - x).abs() < 1e-5, "view {i}: {c:?} against {x},{y}");
        assert!(
            (c.y + y).abs() < 1e-5,
            "view {i}: y down: {c:?} against {x},{y}"
        );
    }
    assert!(
        st.foveation_center[0].x > 0.05 && st.foveation_center[1].x < -0.05,
        "Quest 3's projection centres lie towards the nose: {:?}",
        st.foveation_center
    );
}

#[test]
fn without_the_extension_enabled_the_function_is_not_found() {
    let lp = running(&[("FOVEA_SIM_EYE_GAZE", "on")], &[EYE_GAZE]);
    let r = unsafe {
        lp.app.try_fn::<xr::pfn::GetFoveationEyeTrackedStateMETA>(
            c"xrGetFoveationEyeTrackedStateMETA",
        )
    };
    assert_eq!(r.err(), Some(xr::Result::ERROR_FUNCTION_UNSUPPORTED));
}

#[test]
fn a_runtime_with_the_extension_is_passed_through() {
    let vars = [
        ("FOVEA_SIM_NATIVE_FOVEATION", "1"),
        ("FOVEA_SIM_META_EYE_TRACKED", "1"),
    ];
    let mut lp = running(&vars, &[META]);
    assert!(
        sim::control::enabled_extensions(lp.app.instance)
            .iter()
            .any(|e| e == META),
        "the runtime's own extension is enabled below"
    );
    let (r, supported, ..) = system_properties(&lp.app, false);
    assert_eq!(
        (r, supported),
        (xr::Result::SUCCESS, Some(true)),
        "the runtime's answer (fovea's would be false: the runtime has no eye gaze)"
    );
    let meta = eye_tracked_info(0);
    let mut level = level_info(2, 0, 0.0);
    level.next = &meta as *const _ as *mut _;
    assert!(create_profile(&lp, &level, std::ptr::null_mut()).is_ok());
    let journal = sim::control::journal(lp.app.instance);
    let create = journal
        .iter()
        .rfind(|c| c.function == "xrCreateFoveationProfileFB")
        .expect("the profile reached the runtime");
    assert!(
        create.detail.ends_with("eye_tracked=true"),
        "{}",
        create.detail
    );
    lp.frame().unwrap();
    let mut st = state_struct();
    assert_eq!(get_state(&lp, lp.session, &mut st), xr::Result::SUCCESS);
    let got = st.foveation_center.map(|c| [c.x, c.y]);
    assert_eq!(
        got,
        sim::control::META_NATIVE_CENTRES,
        "the runtime's centres"
    );
    assert_eq!(st.flags, xr::FoveationEyeTrackedStateFlagsMETA::VALID);
    let calls = sim::control::journal(lp.app.instance);
    assert!(calls
        .iter()
        .any(|c| c.function == "xrGetFoveationEyeTrackedStateMETA"));
}

/// The simulated Quest 3's eye tracker following `script`, the application enabling only
/// XR_META_foveation_eye_tracked (fovea enables eye gaze below on its own).
fn on_script(script: &str) -> (HeadlessLoop, AppInput) {
    let lp = running(
        &[("FOVEA_SIM_EYE_GAZE", "on"), ("FOVEA_SIM_GAZE", script)],
        &[META],
    );
    let input = AppInput::attach(&lp);
    (lp, input)
}

/// An application's own input, attached, so that fovea's gaze set rides along with it: one pose
/// action bound to a controller, synced every frame.
struct AppInput {
    set: xr::ActionSet,
    sync: xr::pfn::SyncActions,
}

impl AppInput {
    /// The application's set and action ([`declare`], bound to a controller), attached.
    fn attach(lp: &HeadlessLoop) -> AppInput {
        let (set, _) = declare(&lp.app, false);
        attach_set(lp, set);
        AppInput {
            set,
            // SAFETY: the type matches the name.
            sync: unsafe { lp.func(c"xrSyncActions") },
        }
    }

    fn sync(&self, lp: &HeadlessLoop) {
        sync_set(lp, self.sync, self.set);
    }
}

/// What the application reads after each of `n` frames: the centres and whether VALID.
fn read_states(lp: &mut HeadlessLoop, input: &AppInput, n: usize) -> Vec<([[f32; 2]; 2], bool)> {
    (0..n)
        .map(|_| {
            lp.frame().unwrap();
            input.sync(lp);
            let mut st = state_struct();
            assert_eq!(get_state(lp, lp.session, &mut st), xr::Result::SUCCESS);
            let valid = st.flags == xr::FoveationEyeTrackedStateFlagsMETA::VALID;
            assert!(valid || st.flags.is_empty(), "{:?}", st.flags);
            (st.foveation_center.map(|c| [c.x, c.y]), valid)
        })
        .collect()
}

/// Where the model puts view `view`'s fovea (y up) for a gaze at (yaw, pitch) on the simulated
/// Quest 3: its eyes 31.5 mm either side of the head's centre, looking ahead, each with its FOV.
fn model_ndc(view: usize, yaw: f32, pitch: f32) -> [f32; 2] {
    use fovea_model::gaze::{eye_centre, EyeView, Gaze, Tracking};
    let headset = fovea_model::headsets::by_id("quest3").unwrap();
    let eye = EyeView {
        fov: headset.fovs()[view],
        position: glam::Vec3::new([-0.0315, 0.0315][view], 0.0, 0.0),
        orientation: glam::Quat::IDENTITY,
    };
    let gaze = Gaze {
        angles: [yaw, pitch],
        weight: 1.0,
        tracking: Tracking::Tracked,
    };
    eye_centre(&gaze, &eye, 1.0)
}

/// How close a centre must be to the model's: 0.01 NDC is about 0.6° at the middle of Quest 3's
/// views (2 NDC across tangents 1.38 + 0.84), under a twentieth of the smallest full-rate radius
/// fovea draws; it leaves room for f32 rounding and the filter's last hundredths of a degree on a
/// fixation, and none for a y of the wrong sign or a centre of the wrong eye.
const TOLERANCE: f32 = 0.01;

fn near(got: [f32; 2], want: [f32; 2]) -> bool {
    (got[0] - want[0]).abs() < TOLERANCE && (got[1] - want[1]).abs() < TOLERANCE
}

/// `want` with y pointing down, as the application reads it by default.
fn down([x, y]: [f32; 2]) -> [f32; 2] {
    [x, -y]
}

const SCRIPT: &str = "fix 10,4 for 600ms; saccade -10,-6 in 1ms; fix for 600ms; blink 150ms; \
                      fix for 600ms";

#[test]
fn the_centres_follow_the_scripted_gaze() {
    let (mut lp, input) = on_script(SCRIPT);
    let got = read_states(&mut lp, &input, 260);
    let at = |yaw, pitch| [0, 1].map(|v| down(model_ndc(v, yaw, pitch)));

    // The first fixation: VALID, each view's centre where the model puts it, y down.
    let first = at(10.0, 4.0);
    let (c, valid) = got[20];
    assert!(valid, "tracked: {:?}", got[20]);
    assert!(
        near(c[0], first[0]) && near(c[1], first[1]),
        "{c:?} vs {first:?}"
    );
    assert!(c[0][1] < 0.0, "looking up reads as y < 0 (y down): {c:?}");

    // After the saccade: on the new point, VALID.
    let second = at(-10.0, -6.0);
    let landed = got
        .iter()
        .position(|(c, v)| *v && near(c[0], second[0]) && near(c[1], second[1]))
        .expect("the centres reach the saccade's target");
    assert!(landed > 20);

    // The blink: not VALID throughout, the centres held where the eye was; VALID again after.
    let blink = landed
        + got[landed..]
            .iter()
            .position(|(_, v)| !v)
            .expect("the blink clears VALID");
    let run = got[blink..].iter().take_while(|(_, v)| !v).count();
    let frames_per_s = 1e9 / lp.last_frame_state.predicted_display_period.as_nanos() as f64;
    let expected = (0.150 * frames_per_s).round() as usize;
    assert!(
        run + 2 >= expected && run <= expected + 2,
        "150 ms without VALID at {frames_per_s:.0} Hz: {run} frames"
    );
    assert!(
        got[blink..blink + run]
            .iter()
            .all(|(c, _)| near(c[0], second[0]) && near(c[1], second[1])),
        "held through the blink"
    );
    let (c, valid) = got[blink + run];
    assert!(valid && near(c[0], second[0]), "followed again: {c:?}");
}

#[test]
fn the_y_flip_setting_flips() {
    in_own_process(
        module_path!(),
        "the_y_flip_setting_flips",
        the_y_flip_setting_flips_here,
    );
}

fn the_y_flip_setting_flips_here() {
    std::env::set_var(fovea_abi::env::EYE_TRACKED_Y_UP, "1");
    let (mut lp, input) = on_script("fix 5,8 for 2s");
    let got = read_states(&mut lp, &input, 30);
    let (c, valid) = got[20];
    assert!(valid);
    for (v, c) in c.iter().enumerate() {
        let want = model_ndc(v, 5.0, 8.0);
        assert!(
            want[1] > 0.05,
            "the model puts a look up at y > 0: {want:?}"
        );
        assert!(near(*c, want), "view {v}: y up as set: {c:?} vs {want:?}");
    }
}

#[test]
fn gaze_switched_off_means_not_supported() {
    in_own_process(
        module_path!(),
        "gaze_switched_off_means_not_supported",
        gaze_switched_off_means_not_supported_here,
    );
}

fn gaze_switched_off_means_not_supported_here() {
    std::env::set_var(fovea_abi::env::GAZE, "0");
    let (mut lp, input) = on_script("fix 5,8 for 2s");
    let (r, supported, ..) = system_properties(&lp.app, false);
    assert_eq!(
        (r, supported),
        (xr::Result::SUCCESS, Some(false)),
        "an eye tracker fovea does not follow is no gaze source"
    );
    let got = read_states(&mut lp, &input, 30);
    assert!(got.iter().all(|(_, valid)| !valid), "never VALID");
}
