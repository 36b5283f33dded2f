//! Profiles and swapchain foveation state on headless sessions, through the harness: every error code
//! the valid usage implies, the copy semantics of xrUpdateSwapchainFB, and what reaches the runtime.

use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::{HeadlessLoop, SwapchainSpec, FOVEATION_EXTENSIONS};
use fovea_harness::{sim, App, Chain};
use openxr_sys as xr;
use xr::Handle;

use crate::support::{foveation_state, level_info};

struct Fns {
    create: xr::pfn::CreateFoveationProfileFB,
    destroy: xr::pfn::DestroyFoveationProfileFB,
    update: xr::pfn::UpdateSwapchainFB,
    get: xr::pfn::GetSwapchainStateFB,
}

fn running(foveation: bool) -> (HeadlessLoop, Fns) {
    sim::control::set_thread_config(None);
    let app = App::new(Chain::fovea().unwrap(), &FOVEATION_EXTENSIONS, API_1_0).unwrap();
    let lp = HeadlessLoop::new(
        app,
        SwapchainSpec {
            foveation,
            array_size: 2,
        },
    )
    .unwrap();
    let fns = unsafe {
        Fns {
            create: lp.func(c"xrCreateFoveationProfileFB"),
            destroy: lp.func(c"xrDestroyFoveationProfileFB"),
            update: lp.func(c"xrUpdateSwapchainFB"),
            get: lp.func(c"xrGetSwapchainStateFB"),
        }
    };
    (lp, fns)
}

fn create(
    f: &Fns,
    session: xr::Session,
    level: Option<&xr::FoveationLevelProfileCreateInfoFB>,
) -> Result<xr::FoveationProfileFB, xr::Result> {
    let info = xr::FoveationProfileCreateInfoFB {
        ty: xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
        next: level.map_or(std::ptr::null_mut(), |l| l as *const _ as *mut _),
    };
    let mut p = xr::FoveationProfileFB::NULL;
    match unsafe { (f.create)(session, &info, &mut p) } {
        xr::Result::SUCCESS => Ok(p),
        r => Err(r),
    }
}

fn update(f: &Fns, sc: xr::Swapchain, st: &xr::SwapchainStateFoveationFB) -> xr::Result {
    unsafe { (f.update)(sc, st as *const _ as *const _) }
}

fn get(f: &Fns, sc: xr::Swapchain) -> Result<xr::SwapchainStateFoveationFB, xr::Result> {
    let mut st = foveation_state(xr::FoveationProfileFB::from_raw(0x1234), 7);
    match unsafe { (f.get)(sc, &mut st as *mut _ as *mut _) } {
        xr::Result::SUCCESS => Ok(st),
        r => Err(r),
    }
}

#[test]
fn profiles_validate_their_level_chain() {
    let (lp, f) = running(true);
    assert!(
        create(&f, lp.session, None).is_ok(),
        "an empty chain is a profile without foveation"
    );
    assert!(create(&f, lp.session, Some(&level_info(3, 1, -10.0))).is_ok());
    for (l, d, v) in [(4, 0, 0.0), (-1, 0, 0.0), (2, 2, 0.0), (2, 0, f32::NAN)] {
        assert_eq!(
            create(&f, lp.session, Some(&level_info(l, d, v))),
            Err(xr::Result::ERROR_VALIDATION_FAILURE)
        );
    }
    let mut p = xr::FoveationProfileFB::NULL;
    assert_eq!(
        unsafe { (f.create)(lp.session, std::ptr::null(), &mut p) },
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    assert_eq!(
        create(&f, xr::Session::from_raw(0xbad), None),
        Err(xr::Result::ERROR_HANDLE_INVALID)
    );
    assert_eq!(
        unsafe { (f.destroy)(xr::FoveationProfileFB::from_raw(0xbad)) },
        xr::Result::ERROR_HANDLE_INVALID
    );
}

#[test]
fn update_copies_the_profile_and_survives_its_destruction() {
    let (lp, f) = running(true);
    let p = create(&f, lp.session, Some(&level_info(2, 0, 5.0))).unwrap();
    assert_eq!(
        get(&f, lp.swapchain).unwrap().profile,
        xr::FoveationProfileFB::NULL,
        "no profile before the first update"
    );
    assert_eq!(
        update(&f, lp.swapchain, &foveation_state(p, 0)),
        xr::Result::SUCCESS
    );
    let st = get(&f, lp.swapchain).unwrap();
    assert_eq!((st.profile, st.flags.into_raw()), (p, 0));
    assert_eq!(st.ty, xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB);
    assert_eq!(unsafe { (f.destroy)(p) }, xr::Result::SUCCESS);
    // The swapchain keeps the parameters; the handle reads NULL once the profile is gone.
    assert_eq!(
        get(&f, lp.swapchain).unwrap().profile,
        xr::FoveationProfileFB::NULL
    );
    assert_eq!(
        update(&f, lp.swapchain, &foveation_state(p, 0)),
        xr::Result::ERROR_HANDLE_INVALID
    );
    assert_eq!(unsafe { (f.destroy)(p) }, xr::Result::ERROR_HANDLE_INVALID);
}

#[test]
fn update_rejects_bad_states() {
    let (lp, f) = running(true);
    let p = create(&f, lp.session, Some(&level_info(1, 0, 0.0))).unwrap();
    assert_eq!(
        update(&f, lp.swapchain, &foveation_state(p, 1)),
        xr::Result::ERROR_VALIDATION_FAILURE,
        "flags must be 0"
    );
    let mut wrong = foveation_state(p, 0);
    wrong.ty = xr::StructureType::SWAPCHAIN_CREATE_INFO;
    assert_eq!(
        update(&f, lp.swapchain, &wrong),
        xr::Result::ERROR_VALIDATION_FAILURE,
        "unknown state type"
    );
    assert_eq!(
        unsafe { (f.update)(lp.swapchain, std::ptr::null()) },
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    assert_eq!(
        update(&f, xr::Swapchain::from_raw(0xbad), &foveation_state(p, 0)),
        xr::Result::ERROR_HANDLE_INVALID
    );
    assert_eq!(
        update(
            &f,
            lp.swapchain,
            &foveation_state(xr::FoveationProfileFB::from_raw(0xbad), 0)
        ),
        xr::Result::ERROR_HANDLE_INVALID
    );
}

#[test]
fn a_swapchain_without_foveation_refuses_profiles() {
    let (lp, f) = running(false);
    let p = create(&f, lp.session, Some(&level_info(3, 0, 0.0))).unwrap();
    assert_eq!(
        update(&f, lp.swapchain, &foveation_state(p, 0)),
        xr::Result::ERROR_VALIDATION_FAILURE
    );
    assert_eq!(
        get(&f, lp.swapchain).err(),
        Some(xr::Result::ERROR_VALIDATION_FAILURE)
    );
}

/// Where fovea still refuses a profile an application applied (a swapchain created without
/// foveation info on a session fovea cannot inject into: headless here), one info line says so,
/// once however often the application tries: toolkits ignore the result code.
#[test]
fn a_refused_profile_is_logged_once() {
    crate::support::in_own_process(module_path!(), "a_refused_profile_is_logged_once", || {
        let dir = std::env::temp_dir().join(format!("fovea-refused-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let log = dir.join("fovea.log");
        std::env::set_var("FOVEA_LOG", "info");
        std::env::set_var("FOVEA_LOG_FILE", &log);
        let (lp, f) = running(false);
        let p = create(&f, lp.session, Some(&level_info(3, 0, 0.0))).unwrap();
        for _ in 0..3 {
            assert_eq!(
                update(&f, lp.swapchain, &foveation_state(p, 0)),
                xr::Result::ERROR_VALIDATION_FAILURE
            );
        }
        let text = std::fs::read_to_string(&log).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        let said = "xrUpdateSwapchainFB: a foveation profile for a swapchain created without \
                    XrSwapchainCreateInfoFoveationFB on a session fovea cannot inject shading \
                    rates into (not Vulkan)";
        assert_eq!(text.matches(said).count(), 1, "{text}");
    });
}

#[test]
fn a_profile_of_another_session_is_an_invalid_handle() {
    let (a, fa) = running(true);
    let (b, _) = running(true);
    let foreign = create(&fa, a.session, Some(&level_info(3, 0, 0.0))).unwrap();
    let update_b: xr::pfn::UpdateSwapchainFB = unsafe { b.func(c"xrUpdateSwapchainFB") };
    let st = foveation_state(foreign, 0);
    assert_eq!(
        unsafe { update_b(b.swapchain, &st as *const _ as *const _) },
        xr::Result::ERROR_HANDLE_INVALID
    );
}

#[test]
fn the_foveation_struct_does_not_reach_the_runtime_and_profiles_die_with_their_session() {
    let (lp, f) = running(true);
    let instance = lp.app.instance;
    let created = sim::control::journal(instance)
        .into_iter()
        .find(|c| c.function == "xrCreateSwapchain")
        .unwrap();
    assert!(created.next_types.is_empty(), "{:?}", created.next_types);
    let p = create(&f, lp.session, None).unwrap();
    let destroy_session: xr::pfn::DestroySession = unsafe { lp.func(c"xrDestroySession") };
    assert_eq!(unsafe { destroy_session(lp.session) }, xr::Result::SUCCESS);
    assert_eq!(unsafe { (f.destroy)(p) }, xr::Result::ERROR_HANDLE_INVALID);
}
