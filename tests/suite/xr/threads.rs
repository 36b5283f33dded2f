//! Profiles, updates and destruction on four threads while the frame loop runs on another, through
//! fovea and the simulated runtime (headless), for a bounded count.
//!
//! - No deadlock: a watchdog ends the process with a failure if the run takes longer than
//!   [`DEADLINE`]. Debug builds of the layer also check the lock order on every lock taken
//!   (`src/common/lock.rs`), so an inversion fails at once even when no other thread is there to deadlock
//!   with: it would surface here as XR_ERROR_RUNTIME_FAILURE.
//! - No lost or mixed-up update: each worker owns a swapchain that only it updates, and reads back
//!   after every update exactly the profile it applied; at the end each swapchain holds the last
//!   profile its worker applied (still alive). All workers also update one shared swapchain; what it
//!   reads back is always a profile some worker created, or XR_NULL_HANDLE once that was destroyed.
//!
//! `FOVEA_THREADS_ITERATIONS` sets the iterations per worker (default 2000), e.g. for a run under
//! valgrind's DRD (docs/hardening.md).

use std::collections::HashSet;
use std::ptr::null_mut;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Barrier};
use std::time::{Duration, Instant};

use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::FOVEATION_EXTENSIONS;
use fovea_harness::{sim, App, Chain};
use openxr_sys as xr;
// parking_lot rather than std: ThreadSanitizer sees its atomics (std is not instrumented).
use parking_lot::Mutex;
use xr::Handle;

use crate::support::{foveated_loop, foveation_state, level_info};

const WORKERS: usize = 4;
/// The whole run must end within this (debug build, two shared cores, or valgrind).
const DEADLINE: Duration = Duration::from_secs(600);

fn iterations() -> u64 {
    std::env::var("FOVEA_THREADS_ITERATIONS")
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(2000)
}

/// The functions the workers call; plain function pointers, shared by every thread.
#[derive(Clone, Copy)]
struct Fns {
    create_profile: xr::pfn::CreateFoveationProfileFB,
    destroy_profile: xr::pfn::DestroyFoveationProfileFB,
    update: xr::pfn::UpdateSwapchainFB,
    get_state: xr::pfn::GetSwapchainStateFB,
    create_swapchain: xr::pfn::CreateSwapchain,
    destroy_swapchain: xr::pfn::DestroySwapchain,
}

fn profile(f: &Fns, session: xr::Session, level: i32) -> xr::FoveationProfileFB {
    let level = level_info(level, level & 1, 0.0);
    let info = xr::FoveationProfileCreateInfoFB {
        ty: xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
        next: &level as *const _ as *mut _,
    };
    let mut p = xr::FoveationProfileFB::NULL;
    assert_eq!(
        unsafe { (f.create_profile)(session, &info, &mut p) },
        xr::Result::SUCCESS
    );
    p
}

fn update(f: &Fns, sc: xr::Swapchain, p: xr::FoveationProfileFB) {
    let st = foveation_state(p, 0);
    assert_eq!(
        unsafe { (f.update)(sc, &st as *const _ as *const _) },
        xr::Result::SUCCESS
    );
}

fn state(f: &Fns, sc: xr::Swapchain) -> xr::FoveationProfileFB {
    let mut st = foveation_state(xr::FoveationProfileFB::from_raw(0x77), 0);
    assert_eq!(
        unsafe { (f.get_state)(sc, &mut st as *mut _ as *mut _) },
        xr::Result::SUCCESS
    );
    st.profile
}

fn swapchain(f: &Fns, session: xr::Session) -> xr::Swapchain {
    let foveation = xr::SwapchainCreateInfoFoveationFB {
        ty: xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
        next: null_mut(),
        flags: xr::SwapchainCreateFoveationFlagsFB::EMPTY,
    };
    let info = xr::SwapchainCreateInfo {
        ty: xr::StructureType::SWAPCHAIN_CREATE_INFO,
        next: &foveation as *const _ as *const _,
        create_flags: xr::SwapchainCreateFlags::EMPTY,
        usage_flags: xr::SwapchainUsageFlags::COLOR_ATTACHMENT,
        format: 43,
        sample_count: 1,
        width: 32,
        height: 32,
        face_count: 1,
        array_size: 1,
        mip_count: 1,
    };
    let mut sc = xr::Swapchain::NULL;
    assert_eq!(
        unsafe { (f.create_swapchain)(session, &info, &mut sc) },
        xr::Result::SUCCESS
    );
    sc
}

#[test]
fn four_threads_of_profiles_and_updates_beside_the_frame_loop() {
    let done = Arc::new(AtomicBool::new(false));
    {
        let done = done.clone();
        std::thread::spawn(move || {
            let start = Instant::now();
            while start.elapsed() < DEADLINE {
                if done.load(Ordering::Relaxed) {
                    return;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            eprintln!("threads: not finished after {DEADLINE:?}: deadlock");
            std::process::exit(101);
        });
    }

    sim::control::set_thread_config(None);
    let app = App::new(Chain::fovea().unwrap(), &FOVEATION_EXTENSIONS, API_1_0).unwrap();
    let mut lp = foveated_loop(app);
    let f = unsafe {
        Fns {
            create_profile: lp.func(c"xrCreateFoveationProfileFB"),
            destroy_profile: lp.func(c"xrDestroyFoveationProfileFB"),
            update: lp.func(c"xrUpdateSwapchainFB"),
            get_state: lp.func(c"xrGetSwapchainStateFB"),
            create_swapchain: lp.func(c"xrCreateSwapchain"),
            destroy_swapchain: lp.func(c"xrDestroySwapchain"),
        }
    };
    let session = lp.session;
    let shared = lp.swapchain;
    // A dynamic profile on the frame loop's swapchain, so every xrEndFrame runs the controller.
    update(&f, shared, profile(&f, session, 3));

    let n = iterations();
    let created: Arc<Mutex<HashSet<u64>>> = Arc::default();
    let updates = Arc::new(AtomicU64::new(0));
    let start = Barrier::new(WORKERS + 1);
    let started = Instant::now();
    let (frames, finals) = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..WORKERS)
            .map(|w| {
                let (created, updates, start) = (&created, &updates, &start);
                scope.spawn(move || {
                    let mut own = swapchain(&f, session);
                    start.wait();
                    let mut last = xr::FoveationProfileFB::NULL;
                    for i in 0..n {
                        let p = profile(&f, session, ((w as u64 + i) % 4) as i32);
                        created.lock().insert(p.into_raw());
                        update(&f, own, p);
                        update(&f, shared, p);
                        updates.fetch_add(2, Ordering::Relaxed);
                        // Only this thread updates `own`: it reads back exactly `p`.
                        assert_eq!(state(&f, own), p, "worker {w} iteration {i}");
                        let seen = state(&f, shared);
                        assert!(
                            seen == xr::FoveationProfileFB::NULL
                                || created.lock().contains(&seen.into_raw()),
                            "the shared swapchain reads {seen:?}, which no worker created"
                        );
                        // Keep every 7th profile a while; destroy the rest at once (while other
                        // threads may be applying or reading them).
                        if i % 7 != 0 {
                            assert_eq!(unsafe { (f.destroy_profile)(p) }, xr::Result::SUCCESS);
                        } else {
                            if last != xr::FoveationProfileFB::NULL {
                                assert_eq!(
                                    unsafe { (f.destroy_profile)(last) },
                                    xr::Result::SUCCESS
                                );
                            }
                            last = p;
                        }
                        // Now and then the worker's swapchain goes and a new one comes.
                        if i % 250 == 249 {
                            assert_eq!(unsafe { (f.destroy_swapchain)(own) }, xr::Result::SUCCESS);
                            own = swapchain(&f, session);
                            update(&f, own, last);
                        }
                    }
                    update(&f, own, last);
                    (own, last)
                })
            })
            .collect();
        start.wait();
        let mut frames = 0u64;
        while !workers.iter().all(|w| w.is_finished()) {
            lp.frame().expect("frame");
            frames += 1;
            // The simulated runtime does not block in xrWaitFrame: without a pause the loop would
            // starve the workers wherever threads are serialised (valgrind runs one at a time).
            std::thread::sleep(Duration::from_micros(200));
        }
        let finals: Vec<_> = workers.into_iter().map(|w| w.join().unwrap()).collect();
        (frames, finals)
    });
    let elapsed = started.elapsed();
    // No lost update: every worker's swapchain holds the last profile the worker applied.
    for (w, (own, last)) in finals.iter().enumerate() {
        assert_eq!(state(&f, *own), *last, "worker {w}");
        assert_eq!(unsafe { (f.destroy_profile)(*last) }, xr::Result::SUCCESS);
        assert_eq!(state(&f, *own), xr::FoveationProfileFB::NULL);
        assert_eq!(unsafe { (f.destroy_swapchain)(*own) }, xr::Result::SUCCESS);
    }
    assert!(frames > 0, "the frame loop never ran beside the workers");
    eprintln!(
        "threads: {WORKERS} workers x {n} iterations ({} updates) beside {frames} frames in {:.1} s",
        updates.load(Ordering::Relaxed),
        elapsed.as_secs_f64()
    );
    drop(lp);
    done.store(true, Ordering::Relaxed);
}
