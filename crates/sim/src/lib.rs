//! fovea-sim: a simulated headset OpenXR runtime for testing the fovea layer without a headset.
//!
//! It plays a *desktop* runtime: Vulkan (XR_KHR_vulkan_enable, XR_KHR_vulkan_enable2), headless
//! sessions (XR_MND_headless) and none of the foveation extensions. Optionally it offers
//! XR_FB_swapchain_update_state with no state types of its own, so the layer's pass-through path can
//! be exercised, or (`native_foveation`) XR_FB_foveation and XR_FB_foveation_configuration
//! natively, as a headset runtime does, so a test can check that a layer passes them through.
//!
//! Two ways in:
//! - the Khronos loader loads `libfovea_sim.so` through `manifest/runtime/fovea_sim_runtime.json`
//!   and calls [`xrNegotiateLoaderRuntimeInterface`];
//! - the in-process fake loader links this crate and calls [`get_instance_proc_addr`] directly.
//!
//! It is at least as strict as real runtimes (Monado) where the spec lets a runtime refuse a call:
//! xrLocateViews only while the session runs and for the view configuration it began with, the
//! frame-loop and swapchain call orders (a second xrWaitFrame blocks until the previous frame is
//! begun), the session state machine (only the spec's transitions), layer poses, action and action
//! set names and localized names, subaction paths, and only the spec's interaction profiles and
//! binding paths for the instance's version and extensions ([`profiles`](crate::profiles)). The
//! Khronos conformance suite's (CTS 1.1.41) non-interactive cases pass against it. Every refusal is
//! counted apart from injected faults ([`control::refusals`], the `refused=` field of the summary
//! line), so a test can assert that nothing a strict runtime refuses reached this one.
//!
//! Time is virtual and deterministic (see [`frame`](crate::frame) docs), every call is journaled, and
//! faults and GPU load can be injected through [`control`].
//!
//! Optionally (`FOVEA_SIM_EYE_GAZE`) it has an eye tracker behind `XR_EXT_eye_gaze_interaction`
//! whose gaze follows a script ([`gaze_script`]), as strict as real runtimes: inactive without
//! focus or without a synced set bound to it, or before the user's permission (`permission=T`); a
//! second suggestion for its profile replacing the first; optionally no gaze space before attach,
//! or listed without support as Monado does. As Monado, an attach that binds the tracker queues
//! `XR_TYPE_EVENT_DATA_INTERACTION_PROFILE_CHANGED` and gives `/user/eyes_ext` its profile in
//! `xrGetCurrentInteractionProfile` (`XR_ERROR_ACTIONSET_NOT_ATTACHED` before any attach); the
//! first sync of a set bound to it journals a calibration request; its samples can be sub-nominal
//! (`tracked=no`: VALID without TRACKED), and the head can turn (`head=V`) while the eye holds a
//! point in the world. Each `xrSyncActions` journals the session state it came in.
//!
//! The files stand in floors: each imports only files on floors below its own. The objects are
//! plain data that the state holds (`objects.rs`, `state.rs`); the modules of the spec's chapters
//! implement the calls on them, and the state never imports one of them.
//!
//! | floor | path | job |
//! |---|---|---|
//! | 1 | `ffi.rs` | the C side of entry points: next chains, the two-call idiom, strings, pose valid usage |
//! | 1 | `gaze_script.rs` | the simulated eye tracker's script |
//! | 2 | `config.rs` | what the simulated headset is: preset, refresh rate, optional extensions, faults and load |
//! | 3 | `objects.rs` | the runtime's objects as data: what each handle holds, the journal's records |
//! | 3 | `extensions.rs` | the extensions the runtime knows and which it offers under a configuration |
//! | 4 | `state.rs` | the objects in one map-of-maps behind one lock; the per-call bookkeeping (`entry`) |
//! | 4 | `profiles.rs` | the spec's interaction profiles and the binding paths each accepts, by version and extension |
//! | 5 | `control.rs` | the test-facing control API |
//! | 5 | `system.rs` | the one system and its view configuration |
//! | 6 | `vulkan.rs` | XR_KHR_vulkan_enable(2) and the Vulkan side of sessions and swapchains |
//! | 6 | `actions.rs` | input: action sets, actions, the eye tracker's gaze action |
//! | 6 | `foveation.rs` | native XR_FB_foveation profiles |
//! | 7 | `session.rs` | session lifetime and state machine |
//! | 7 | `space.rs` | spaces and view location |
//! | 7 | `swapchain.rs` | swapchains and native XR_FB_swapchain_update_state |
//! | 8 | `frame.rs` | the frame loop against the virtual display clock |
//! | 8 | `instance.rs` | instance lifetime, events, strings and paths |
//! | 9 | `dispatch.rs` | `xrGetInstanceProcAddr`: the name → function table |
//! | 10 | `negotiate.rs` | loader ↔ runtime negotiation |
//! | 11 | `lib.rs` | the runtime's export and the module list |

mod actions;
mod config;
pub mod control;
mod dispatch;
mod extensions;
mod ffi;
mod foveation;
mod frame;
pub mod gaze_script;
mod instance;
mod negotiate;
mod objects;
mod profiles;
mod session;
mod space;
mod state;
mod swapchain;
mod system;
mod vulkan;

use openxr_sys as xr;

pub use dispatch::{command_names, get_instance_proc_addr};

/// The runtime's only export (spec api_initialization.adoc, "Runtime Interface Negotiation").
///
/// # Safety
/// Both pointers must be NULL or point to the loader's structs.
#[no_mangle]
pub unsafe extern "system" fn xrNegotiateLoaderRuntimeInterface(
    loader_info: *const xr::NegotiateLoaderInfo,
    request: *mut xr::NegotiateRuntimeRequest,
) -> xr::Result {
    std::panic::catch_unwind(|| negotiate::negotiate(loader_info, request))
        .unwrap_or(xr::Result::ERROR_INITIALIZATION_FAILED)
}
