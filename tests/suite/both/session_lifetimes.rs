//! Whole sessions recreated under one application command buffer: fovea's own density images (made
//! by its OpenXR side for each foveated swapchain, shadowed and uploaded by its Vulkan layer) come
//! and go with their swapchains and sessions, while the application keeps its device, its command
//! pool and one command buffer that every session's passes are recorded into again, as an
//! application that restarts its session (a headset taken off and put on, a mode switch) or
//! recreates its swapchains does.
//!
//! Stack as in [`crate::both::fdm_emulated`]: the application → fovea's OpenXR layer → the
//! simulated runtime, and the application's Vulkan device made through `XR_KHR_vulkan_enable2`:
//! fovea's Vulkan layer → validation (unique handles off) → the shading-rate double → lavapipe.
//! Each cycle: a session, a foveated swapchain at HIGH, the application's render pass,
//! framebuffers and pipeline for it, frames drawn through the density images into the one command
//! buffer, each checked against the density model; then everything of the cycle destroyed, in one
//! order (the application's objects, the swapchain, the session) or the other (the session first:
//! the runtime takes its swapchain with it, then the application's objects that named its
//! images). Over the cycles: the shading rates each frame got are the model's, validation says
//! nothing, the double records no misuse, and the buffers, memory and image views alive below the
//! layers (the double counts them, `fovea_vkdouble::COUNTED`) are the same after every cycle.

use std::ffi::c_void;

use fovea_harness::vulkan::{self, pick_lavapipe};
use fovea_model::density::{Level, Pattern};
use fovea_vkdouble::Profile;
use openxr_sys as xr;
use xr::Handle as _;

use crate::both::fdm_emulated::{
    color_images, expected_codes, rates_drawn, release, start, Layout, Renderer,
};
use crate::both::fdm_vulkan::{
    apply_profile, enumerate, fdm_flag, func, running_session, swapchain_info, Frame, HEIGHT,
    VALIDATED, WIDTH,
};
use crate::support::device::{allocate, env, resettable_pool, Env};
use crate::support::{in_own_process, level_info};

/// Sessions per profile, and frames per session (three swapchain images: each drawn at least once).
const SESSIONS: usize = 40;
const FRAMES: usize = 4;

/// Objects alive below the layers, by the double's counts since its last clear.
fn alive(env: &Env) -> [i64; 3] {
    let n = |name: &str| env.double.calls(name) as i64;
    [
        n("vkCreateBuffer") - n("vkDestroyBuffer"),
        n("vkAllocateMemory") - n("vkFreeMemory"),
        n("vkCreateImageView") - n("vkDestroyImageView"),
    ]
}

/// [`SESSIONS`] sessions on `profile`; false after a skip. With `inject`, the application asks for
/// no foveation and fovea injects its own maps into the eye passes (docs/injection.md; injection
/// must be on in this process); else its swapchains are foveated and their passes read fovea's
/// density images.
fn sessions(env: &Env, profile: Profile, inject: bool) -> bool {
    let what = format!(
        "{}{}",
        profile.name(),
        if inject { " injected" } else { "" }
    );
    let Some((app, sys, v)) = start(env, profile, !inject) else {
        return false;
    };
    let d = &v.device;
    // The application's own pool and the one command buffer every session records into; destroyed
    // below, after the device is idle.
    let pool = resettable_pool(d, v.family);
    let cb = allocate(d, pool);
    let create_swapchain: xr::pfn::CreateSwapchain = func(&app, "xrCreateSwapchain");
    let destroy_swapchain: xr::pfn::DestroySwapchain = func(&app, "xrDestroySwapchain");
    let destroy_session: xr::pfn::DestroySession = func(&app, "xrDestroySession");
    let layout = Layout::Multiview;
    let t = profile.texel();
    let extent = [WIDTH.div_ceil(t.width), HEIGHT.div_ceil(t.height)];
    let shading_layers = if profile.layered() { 2 } else { 1 };
    let merged = shading_layers < layout.layers();
    let pattern = Pattern {
        level: Level::High,
        vertical_offset_deg: 0.0,
    };
    let mut counted = [0i64; 3];
    let mut after = Vec::new();
    for cycle in 0..SESSIONS {
        let (session, space) = running_session(&app, sys, &v);
        let fdm_flag = fdm_flag();
        let next = if inject {
            std::ptr::null()
        } else {
            &fdm_flag as *const _ as *const c_void
        };
        let info = xr::SwapchainCreateInfo {
            array_size: layout.layers(),
            ..swapchain_info(next)
        };
        let mut swapchain = xr::Swapchain::NULL;
        // SAFETY: the create info and the output live across the call.
        let r = unsafe { create_swapchain(session, &info, &mut swapchain) };
        assert_eq!(r, xr::Result::SUCCESS, "{what} session {cycle}");
        let color = color_images(&app, swapchain);
        let renderer = if inject {
            Renderer::new(&v, layout, &color, None)
        } else {
            apply_profile(&app, session, swapchain, &level_info(3, 0, 0.0));
            let density: Vec<u64> = enumerate(&app, swapchain).iter().map(|d| d.image).collect();
            Renderer::new(&v, layout, &color, Some(&density))
        };
        let frame = Frame {
            app: &app,
            session,
            space,
        };
        for n in 0..FRAMES {
            let case = format!("{what} session {cycle} frame {n}");
            counted = add(counted, alive(env));
            env.double.clear();
            let (index, fovs, time) = frame.acquire(swapchain);
            renderer.draw_in(d, cb, index, None);
            release(&frame, layout, swapchain, time, fovs);
            let got = rates_drawn(env, &case, layout, shading_layers, extent);
            // The first frame of a session draws before any submission told fovea where the
            // views go; later ones after.
            let want = expected_codes(profile, &layout.views(fovs, n > 0), pattern, merged);
            assert!(
                want.iter().any(|&c| c != 0),
                "{case}: HIGH shades coarsely somewhere"
            );
            if inject {
                // Injected maps are made for the eye swapchain's views as fovea located them.
                let want = expected_codes(profile, &layout.views(fovs, true), pattern, merged);
                assert!(got == want, "{case}: image {index}: not the model's rates");
            } else {
                assert!(got == want, "{case}: image {index}: not the model's rates");
            }
            let messages = vulkan::take_messages();
            assert!(messages.is_empty(), "{case}: validation: {messages:#?}");
        }
        // SAFETY: the handles are live and used no more; the device is idle after the renderer's
        // destruction (it waits for the device).
        unsafe {
            if cycle % 2 == 0 {
                renderer.destroy(d);
                assert_eq!(destroy_swapchain(swapchain), xr::Result::SUCCESS);
                assert_eq!(destroy_session(session), xr::Result::SUCCESS);
            } else {
                d.device_wait_idle().expect("vkDeviceWaitIdle");
                // The session takes its swapchain, its images and fovea's density images.
                assert_eq!(destroy_session(session), xr::Result::SUCCESS);
                renderer.destroy(d);
            }
        }
        counted = add(counted, alive(env));
        env.double.clear();
        after.push(counted);
        let messages = vulkan::take_messages();
        assert!(messages.is_empty(), "{what} session {cycle}: {messages:#?}");
    }
    for (i, a) in after.iter().enumerate().skip(2) {
        assert_eq!(
            *a, after[1],
            "{what}: buffers, memory and views alive below the layers after session {i}, \
             against session 1"
        );
    }
    // SAFETY: the device is idle; the pool is the application's.
    unsafe {
        d.device_wait_idle().expect("vkDeviceWaitIdle");
        d.destroy_command_pool(pool, None);
        v.destroy_device();
    }
    assert_eq!(app.destroy(), xr::Result::SUCCESS);
    // SAFETY: the device is gone.
    unsafe { v.destroy_instance() };
    vulkan::assert_no_messages();
    assert_eq!(env.double.errors(), Vec::<String>::new(), "{what}");
    true
}

fn add(a: [i64; 3], b: [i64; 3]) -> [i64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// Sessions, swapchains and fovea's own density images recreated under one live application
/// command buffer, in both orders of destruction, on both profiles: every frame shades as the
/// model says, and nothing alive below the layers grows.
#[test]
fn sessions_recreated_under_a_live_command_buffer_leave_nothing_behind() {
    let Some((_serial, env)) = env() else { return };
    let _validated = VALIDATED.lock();
    pick_lavapipe();
    for profile in [Profile::Nvidia, Profile::Amd] {
        if !sessions(env, profile, false) {
            return;
        }
    }
}

/// The same with injection at HIGH: fovea's injected maps come and go with the sessions' eye
/// swapchains under the application's one command buffer, every frame shades as the model says,
/// and nothing alive below the layers grows.
#[test]
fn injected_sessions_recreated_under_a_live_command_buffer_leave_nothing_behind() {
    in_own_process(
        module_path!(),
        "injected_sessions_recreated_under_a_live_command_buffer_leave_nothing_behind",
        || {
            std::env::set_var("FOVEA_INJECT", "1");
            std::env::set_var("FOVEA_INJECT_LEVEL", (Level::High as u8).to_string());
            let Some((_serial, env)) = env() else { return };
            let _validated = VALIDATED.lock();
            pick_lavapipe();
            for profile in [Profile::Nvidia, Profile::Amd] {
                if !sessions(env, profile, true) {
                    return;
                }
            }
        },
    );
}
