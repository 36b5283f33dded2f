//! What `xrGetFoveationEyeTrackedStateMETA` costs: an application calls it once a frame, so it must
//! stay cheap and never allocate (docs/eye-tracking.md#xr_meta_foveation_eye_tracked).
//!
//! In this process, through the fake loader harness, on the simulated Quest 3 whose eye tracker
//! follows a fixation: fovea's gaze source attaches its own set after the grace period (the
//! application here never attaches one), and the bench checks that the state reads VALID before it
//! times anything. Allocations are counted by interposing `malloc` (`support/alloc.rs`).
//!
//! Prints one line: ns per call (the tenth percentile of 2,000 rounds of 1,000 calls: on a shared
//! machine other work only adds time) and heap allocations per call; fails if any call allocated.

use std::time::Instant;

use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::{HeadlessLoop, SwapchainSpec, FOVEATION_EXTENSIONS};
use fovea_harness::{sim, App, Chain};
use openxr_sys as xr;

#[path = "support/alloc.rs"]
mod alloc;
#[path = "support/layer_allocs.rs"]
mod layer_allocs;

const ROUNDS: usize = 2_000;
const CALLS: u32 = 1_000;

fn main() {
    layer_allocs::check_counter_sees_the_layer(&Chain::fovea().expect("libfovea.so is built"));
    let mut cfg = sim::control::SimConfig::from_vars(|k| match k {
        "FOVEA_SIM_EYE_GAZE" => Some("on".into()),
        "FOVEA_SIM_GAZE" => Some("fix 8,4 for 1000s".into()),
        _ => None,
    })
    .expect("simulated runtime configuration");
    cfg.journal = false;
    sim::control::set_thread_config(Some(cfg));
    let mut exts = FOVEATION_EXTENSIONS.to_vec();
    exts.push("XR_META_foveation_eye_tracked");
    let app = App::new(
        Chain::fovea().expect("libfovea.so is built"),
        &exts,
        API_1_0,
    )
    .expect("instance");
    let spec = SwapchainSpec {
        foveation: true,
        array_size: 2,
    };
    let mut lp = HeadlessLoop::new(app, spec).expect("session");
    // SAFETY: the name's type matches.
    let get: xr::pfn::GetFoveationEyeTrackedStateMETA =
        unsafe { lp.func(c"xrGetFoveationEyeTrackedStateMETA") };
    let mut state = xr::FoveationEyeTrackedStateMETA {
        ty: xr::FoveationEyeTrackedStateMETA::TYPE,
        next: std::ptr::null_mut(),
        foveation_center: [xr::Vector2f { x: 0.0, y: 0.0 }; 2],
        flags: xr::FoveationEyeTrackedStateFlagsMETA::EMPTY,
    };
    let session = lp.session;
    let mut call = || {
        // SAFETY: a live session and a valid state struct.
        let r = unsafe { get(session, &mut state) };
        assert_eq!(r, xr::Result::SUCCESS);
        state.flags
    };
    // Past the gaze source's grace period (30 s of display time) and a little more.
    for _ in 0..4_000 {
        lp.frame().expect("frame");
    }
    assert_eq!(
        call(),
        xr::FoveationEyeTrackedStateFlagsMETA::VALID,
        "the gaze is tracked before timing"
    );
    let mut rounds: Vec<(f64, u64)> = (0..ROUNDS)
        .map(|_| {
            let a0 = alloc::allocations();
            let t0 = Instant::now();
            for _ in 0..CALLS {
                std::hint::black_box(call());
            }
            let ns = t0.elapsed().as_nanos() as f64 / f64::from(CALLS);
            (ns, alloc::allocations() - a0)
        })
        .collect();
    let allocations: u64 = rounds.iter().map(|r| r.1).sum();
    rounds.sort_by(|a, b| a.0.total_cmp(&b.0));
    let calls = ROUNDS as f64 * f64::from(CALLS);
    println!(
        "xrGetFoveationEyeTrackedStateMETA: {:.1} ns/call (p10 of {ROUNDS} rounds of {CALLS}), \
         median round {:.1} ns/call; heap allocations per call {:.4}",
        rounds[ROUNDS / 10].0,
        rounds[ROUNDS / 2].0,
        allocations as f64 / calls,
    );
    assert_eq!(allocations, 0, "the per-frame call allocated");
}
