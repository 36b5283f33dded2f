//! Session lifetime and the session state machine (spec chapter "Session", "Session Lifecycle").
//!
//! States are announced with XrEventDataSessionStateChanged in the order a real runtime uses:
//! IDLE→READY on create; SYNCHRONIZED at the first xrWaitFrame, VISIBLE after the first xrEndFrame,
//! FOCUSED after the second; exit walks back down through VISIBLE and SYNCHRONIZED to STOPPING (from
//! READY too: a session begun but not yet waited goes READY→SYNCHRONIZED→STOPPING, the only path the
//! spec's state diagram has); and xrEndSession ends in IDLE→EXITING.

use std::sync::Arc;

use openxr_sys as xr;
use openxr_sys::Handle;

use crate::extensions::{KHR_VULKAN_ENABLE, KHR_VULKAN_ENABLE2, MND_HEADLESS};
use crate::ffi;
use crate::objects::{Event, FrameClock, Graphics, Session};
use crate::state::{entry, notify_frame_begun, world, World};
use crate::system::check_system;
use crate::vulkan;

/// Announces a state change: records it and queues the event with the instance's current time.
pub(crate) fn set_state(w: &mut World, session: u64, state: xr::SessionState) {
    let s = w.sessions.get_mut(&session).expect("session exists");
    s.state = state;
    let inst = w
        .instances
        .get_mut(&s.instance)
        .expect("session's instance exists");
    inst.events.push_back(Event::SessionStateChanged {
        session,
        state,
        time: inst.now_ns,
    });
}

/// Starts the exit sequence down to STOPPING (spec: xrRequestExitSession, or the runtime's own
/// decision to end the session).
pub(crate) fn request_exit(w: &mut World, session: u64) {
    let s = &w.sessions[&session];
    if s.exit_requested {
        return;
    }
    let from = s.state;
    w.sessions
        .get_mut(&session)
        .expect("session exists")
        .exit_requested = true;
    let ladder = [
        xr::SessionState::FOCUSED,
        xr::SessionState::VISIBLE,
        xr::SessionState::SYNCHRONIZED,
    ];
    // A running session that has not waited a frame yet is still READY; the spec's lifecycle (and
    // the CTS's conformance layer) has no READY→STOPPING edge, only READY→SYNCHRONIZED→STOPPING.
    let start = match from {
        xr::SessionState::READY => ladder.len() - 1,
        _ => ladder
            .iter()
            .position(|s| *s == from)
            .map_or(ladder.len(), |i| i + 1),
    };
    for state in &ladder[start..] {
        set_state(w, session, *state);
    }
    set_state(w, session, xr::SessionState::STOPPING);
}

pub(crate) unsafe extern "system" fn create_session(
    instance: xr::Instance,
    create_info: *const xr::SessionCreateInfo,
    session: *mut xr::Session,
) -> xr::Result {
    entry("xrCreateSession", |ctx| {
        let mut w = world();
        let inst_id = w.enter_instance(ctx, instance)?;
        let info = ffi::input(create_info, xr::StructureType::SESSION_CREATE_INFO)?;
        ffi::non_null(session)?;
        ctx.next_types = ffi::chain_types(info.next);
        check_system(info.system_id)?;
        if info.create_flags != xr::SessionCreateFlags::EMPTY {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        // Like most runtimes, one session per instance at a time.
        if w.sessions.values().any(|s| s.instance == inst_id) {
            return Err(xr::Result::ERROR_LIMIT_REACHED);
        }
        let inst = &w.instances[&inst_id];
        // A binding struct of an extension that is not enabled is an unrecognised struct, which the
        // spec says to ignore.
        let vulkan_enabled =
            inst.has_extension(KHR_VULKAN_ENABLE) || inst.has_extension(KHR_VULKAN_ENABLE2);
        let binding = ffi::find_in_chain(info.next, xr::StructureType::GRAPHICS_BINDING_VULKAN_KHR)
            .filter(|_| vulkan_enabled)
            .map(|p| &*(p as *const xr::GraphicsBindingVulkanKHR));
        let graphics = match binding {
            Some(binding) => {
                if !inst.graphics_requirements_queried {
                    return Err(xr::Result::ERROR_GRAPHICS_REQUIREMENTS_CALL_MISSING);
                }
                ctx.detail = format!(
                    "vulkan queue family {} index {}",
                    binding.queue_family_index, binding.queue_index
                );
                Graphics::Vulkan(Arc::new(vulkan::open_session(&inst.vulkan, binding)?))
            }
            None if inst.has_extension(MND_HEADLESS) => {
                ctx.detail = "headless".into();
                Graphics::Headless
            }
            // Spec: without a (recognised) graphics binding the session cannot be created.
            None => return Err(xr::Result::ERROR_GRAPHICS_DEVICE_INVALID),
        };
        let gaze_origin_ns = inst.now_ns;
        let id = w.alloc_handle();
        w.sessions.insert(
            id,
            Session {
                instance: inst_id,
                state: xr::SessionState::UNKNOWN,
                running: false,
                view_configuration: None,
                exit_requested: false,
                lost: false,
                graphics,
                frame: FrameClock::default(),
                action_sets_attached: Vec::new(),
                gaze_actions: Vec::new(),
                synced_sets: Vec::new(),
                gaze_sets: Vec::new(),
                gaze_origin_ns,
                current_profiles: Vec::new(),
                calibration_requested: false,
            },
        );
        set_state(&mut w, id, xr::SessionState::IDLE);
        set_state(&mut w, id, xr::SessionState::READY);
        *session = xr::Session::from_raw(id);
        Ok(xr::Result::SUCCESS)
    })
}

/// Destroys a session's children (spec: child handles are destroyed with their parent) and drops its
/// undelivered events.
pub(crate) fn destroy_session_objects(w: &mut World, session: u64) {
    // An xrWaitFrame blocked on this session's unbegun frame wakes and finds it gone.
    notify_frame_begun();
    w.swapchains.retain(|_, s| s.session != session);
    w.spaces.retain(|_, s| s.session != session);
    w.profiles.retain(|_, p| p.session != session);
    let instance = w.sessions[&session].instance;
    if let Some(inst) = w.instances.get_mut(&instance) {
        inst.events.retain(|e| {
            !matches!(e, Event::SessionStateChanged { session: s, .. }
                | Event::InteractionProfileChanged { session: s } if *s == session)
        });
    }
}

pub(crate) unsafe extern "system" fn destroy_session(session: xr::Session) -> xr::Result {
    entry("xrDestroySession", |ctx| {
        ctx.allow_lost = true;
        let mut w = world();
        let id = w.enter_session(ctx, session)?;
        destroy_session_objects(&mut w, id);
        w.sessions.remove(&id);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn begin_session(
    session: xr::Session,
    begin_info: *const xr::SessionBeginInfo,
) -> xr::Result {
    entry("xrBeginSession", |ctx| {
        let mut w = world();
        let id = w.enter_session(ctx, session)?;
        let info = ffi::input(begin_info, xr::StructureType::SESSION_BEGIN_INFO)?;
        ctx.next_types = ffi::chain_types(info.next);
        if info.primary_view_configuration_type != xr::ViewConfigurationType::PRIMARY_STEREO {
            return Err(xr::Result::ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED);
        }
        let s = w.sessions.get_mut(&id).expect("entered session exists");
        if s.running {
            return Err(xr::Result::ERROR_SESSION_RUNNING);
        }
        if s.state != xr::SessionState::READY {
            return Err(xr::Result::ERROR_SESSION_NOT_READY);
        }
        s.running = true;
        s.view_configuration = Some(info.primary_view_configuration_type);
        s.frame = FrameClock::default();
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn end_session(session: xr::Session) -> xr::Result {
    entry("xrEndSession", |ctx| {
        let mut w = world();
        let id = w.enter_session(ctx, session)?;
        let s = w.sessions.get_mut(&id).expect("entered session exists");
        if !s.running {
            return Err(xr::Result::ERROR_SESSION_NOT_RUNNING);
        }
        if s.state != xr::SessionState::STOPPING {
            return Err(xr::Result::ERROR_SESSION_NOT_STOPPING);
        }
        s.running = false;
        s.view_configuration = None;
        s.frame = FrameClock::default();
        notify_frame_begun();
        let exiting = s.exit_requested;
        set_state(&mut w, id, xr::SessionState::IDLE);
        if exiting {
            set_state(&mut w, id, xr::SessionState::EXITING);
        }
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn request_exit_session(session: xr::Session) -> xr::Result {
    entry("xrRequestExitSession", |ctx| {
        let mut w = world();
        let id = w.enter_session(ctx, session)?;
        if !w.sessions[&id].running {
            return Err(xr::Result::ERROR_SESSION_NOT_RUNNING);
        }
        request_exit(&mut w, id);
        Ok(xr::Result::SUCCESS)
    })
}
