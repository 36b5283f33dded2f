//! Instance lifetime, extensions, events, strings and paths (spec chapters "Instance", "Events",
//! "Semantic Paths").

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::ffi::c_char;

use openxr_sys as xr;
use openxr_sys::Handle;

use crate::config;
use crate::extensions::extensions;
use crate::ffi;
use crate::objects::{
    CreatedInstance, Event, InstanceState, Record, SubmittedView, VulkanInstanceState,
};
use crate::state::{entry, world, World};

pub(crate) const RUNTIME_NAME: &str = "fovea simulated headset";
pub(crate) const RUNTIME_VERSION: xr::Version = xr::Version::new(0, 1, 0);

/// Virtual time starts here (1000 s) so that "zero" and small times stay recognisably invalid.
pub(crate) const CLOCK_START_NS: i64 = 1_000_000_000_000;

pub(crate) unsafe extern "system" fn enumerate_instance_extension_properties(
    layer_name: *const c_char,
    capacity: u32,
    count_out: *mut u32,
    properties: *mut xr::ExtensionProperties,
) -> xr::Result {
    entry("xrEnumerateInstanceExtensionProperties", |_| {
        // The runtime has no layers of its own to answer for.
        if !layer_name.is_null() {
            return Err(xr::Result::ERROR_API_LAYER_NOT_PRESENT);
        }
        let list = extensions(&config::current());
        ffi::two_call(capacity, count_out, properties, list.len(), |i, p| {
            let p = ffi::output(p, xr::StructureType::EXTENSION_PROPERTIES)?;
            ffi::copy_str(&mut (*p).extension_name, list[i].0);
            (*p).extension_version = list[i].1;
            Ok(())
        })?;
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn enumerate_api_layer_properties(
    capacity: u32,
    count_out: *mut u32,
    properties: *mut xr::ApiLayerProperties,
) -> xr::Result {
    entry("xrEnumerateApiLayerProperties", |_| {
        ffi::two_call(capacity, count_out, properties, 0, |_, _| Ok(()))?;
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn create_instance(
    create_info: *const xr::InstanceCreateInfo,
    instance: *mut xr::Instance,
) -> xr::Result {
    entry("xrCreateInstance", |ctx| {
        let cfg = config::current();
        // A fault on xrCreateInstance comes from the configuration: there is no instance to inject
        // it into yet.
        if let Some(f) = cfg
            .faults
            .iter()
            .find(|f| f.function == ctx.name && f.nth <= 1)
        {
            ctx.set_injected();
            return Err(f.result);
        }
        let info = ffi::input(create_info, xr::StructureType::INSTANCE_CREATE_INFO)?;
        ffi::non_null(instance)?;
        let next_types = ffi::chain_types(info.next);
        if info.create_flags != xr::InstanceCreateFlags::EMPTY {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        let app = &info.application_info;
        let application_name = match ffi::fixed_str(&app.application_name) {
            Some(name) if !name.is_empty() => name.to_owned(),
            _ => return Err(xr::Result::ERROR_NAME_INVALID),
        };
        ffi::fixed_str(&app.engine_name).ok_or(xr::Result::ERROR_NAME_INVALID)?;
        let v = app.api_version;
        if v.major() != 1 || v.minor() > 1 {
            return Err(xr::Result::ERROR_API_VERSION_UNSUPPORTED);
        }
        // API layer names are the loader's business; the Khronos loader passes the application's
        // list through unchanged, so they are not validated here.
        let offered = extensions(&cfg);
        let mut enabled = Vec::new();
        if info.enabled_extension_count > 0 {
            ffi::non_null(info.enabled_extension_names)?;
        }
        for i in 0..info.enabled_extension_count as usize {
            let name = ffi::c_str(*info.enabled_extension_names.add(i))
                .ok_or(xr::Result::ERROR_VALIDATION_FAILURE)?;
            if !offered.iter().any(|(o, _)| *o == name) {
                return Err(xr::Result::ERROR_EXTENSION_NOT_PRESENT);
            }
            if !enabled.iter().any(|e| e == name) {
                enabled.push(name.to_string());
            }
        }
        let mut w = world();
        let id = w.alloc_handle();
        ctx.set_instance(id);
        ctx.next_types = next_types;
        ctx.detail = format!(
            "api {v}; extensions [{}]; headset {}",
            enabled.join(", "),
            cfg.headset.id
        );
        let state = InstanceState {
            faults: cfg.faults.clone(),
            config: cfg,
            record: Record {
                enabled_extensions: enabled,
                ..Record::default()
            },
            call_counts: HashMap::from([("xrCreateInstance", 1)]),
            lost: false,
            events: VecDeque::new(),
            api_version: v,
            paths: Vec::new(),
            now_ns: CLOCK_START_NS,
            graphics_requirements_queried: false,
            vulkan: VulkanInstanceState::default(),
            frames: 0,
            suggested: HashMap::new(),
        };
        w.instances.insert(id, state);
        w.created.push(CreatedInstance {
            instance: xr::Instance::from_raw(id),
            application_name,
            api_version: v,
        });
        *instance = xr::Instance::from_raw(id);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn destroy_instance(instance: xr::Instance) -> xr::Result {
    entry("xrDestroyInstance", |ctx| {
        ctx.allow_lost = true;
        let mut w = world();
        let id = w.enter_instance(ctx, instance)?;
        destroy_instance_objects(&mut w, id);
        let state = w.instances.remove(&id).expect("entered instance exists");
        if state.config.summary {
            // The last frame that submitted projection views (frames the app was told not to
            // render submit none).
            let views = state
                .record
                .end_frames
                .iter()
                .rev()
                .find(|v| !v.is_empty())
                .map_or(&[][..], Vec::as_slice);
            eprintln!(
                "{}",
                summary_line(
                    state.frames,
                    &state.record.errors,
                    &state.record.refusals,
                    views
                )
            );
        }
        w.retired.insert(id, state.record);
        Ok(xr::Result::SUCCESS)
    })
}

/// `fovea-sim: summary frames=N errors=M refused=K [xrFoo:2 xrBar:1] views=V;V`: what a test
/// driving an application as a child process reads back (see [`SimConfig::summary`]). `errors`
/// counts every error code returned, the bracket lists them by command, and `refused` is the part
/// of `errors` the runtime chose by its own rules rather than by an injected fault. `views` are the
/// projection views of the last frame that submitted any (with the journal on), each
/// `LAYER:SWAPCHAIN:ARRAY_INDEX:X,Y+WxH`: how the app laid its views out in its swapchains (an
/// array, a double-wide image's halves, a swapchain per eye), which a layer that tells views apart
/// must read the same way (docs/injection.md#telling-the-views-apart).
fn summary_line(
    frames: u64,
    errors: &BTreeMap<&'static str, u64>,
    refusals: &BTreeMap<&'static str, u64>,
    views: &[SubmittedView],
) -> String {
    let total: u64 = errors.values().sum();
    let refused: u64 = refusals.values().sum();
    let each: Vec<String> = errors.iter().map(|(f, n)| format!("{f}:{n}")).collect();
    let views: Vec<String> = views
        .iter()
        .map(|v| {
            let r = v.image_rect;
            format!(
                "{}:{}:{}:{},{}+{}x{}",
                v.layer,
                v.swapchain,
                v.image_array_index,
                r.offset.x,
                r.offset.y,
                r.extent.width,
                r.extent.height
            )
        })
        .collect();
    format!(
        "fovea-sim: summary frames={frames} errors={total} refused={refused} [{}] views={}",
        each.join(" "),
        views.join(";")
    )
}

/// Destroys everything the instance owns (spec: destroying a handle destroys its children).
fn destroy_instance_objects(w: &mut World, id: u64) {
    let sessions: Vec<u64> = w
        .sessions
        .iter()
        .filter(|(_, s)| s.instance == id)
        .map(|(k, _)| *k)
        .collect();
    for s in sessions {
        crate::session::destroy_session_objects(w, s);
        w.sessions.remove(&s);
    }
    w.actions.retain(|_, a| a.instance != id);
    w.action_sets.retain(|_, a| a.instance != id);
}

pub(crate) unsafe extern "system" fn get_instance_properties(
    instance: xr::Instance,
    properties: *mut xr::InstanceProperties,
) -> xr::Result {
    entry("xrGetInstanceProperties", |ctx| {
        let mut w = world();
        w.enter_instance(ctx, instance)?;
        let p = ffi::output(properties, xr::StructureType::INSTANCE_PROPERTIES)?;
        (*p).runtime_version = RUNTIME_VERSION;
        ffi::copy_str(&mut (*p).runtime_name, RUNTIME_NAME);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn poll_event(
    instance: xr::Instance,
    buffer: *mut xr::EventDataBuffer,
) -> xr::Result {
    entry("xrPollEvent", |ctx| {
        let mut w = world();
        let id = w.enter_instance(ctx, instance)?;
        let buffer = ffi::output(buffer, xr::StructureType::EVENT_DATA_BUFFER)?;
        let inst = w.instances.get_mut(&id).expect("entered instance exists");
        let Some(event) = inst.events.pop_front() else {
            return Ok(xr::Result::EVENT_UNAVAILABLE);
        };
        match event {
            Event::SessionStateChanged {
                session,
                state,
                time,
            } => {
                ctx.detail = format!("session state {state:?}");
                (buffer as *mut xr::EventDataSessionStateChanged).write(
                    xr::EventDataSessionStateChanged {
                        ty: xr::StructureType::EVENT_DATA_SESSION_STATE_CHANGED,
                        next: std::ptr::null(),
                        session: xr::Session::from_raw(session),
                        state,
                        time: xr::Time::from_nanos(time),
                    },
                );
            }
            Event::InteractionProfileChanged { session } => {
                ctx.detail = "interaction profile changed".into();
                (buffer as *mut xr::EventDataInteractionProfileChanged).write(
                    xr::EventDataInteractionProfileChanged {
                        ty: xr::StructureType::EVENT_DATA_INTERACTION_PROFILE_CHANGED,
                        next: std::ptr::null(),
                        session: xr::Session::from_raw(session),
                    },
                );
            }
        }
        Ok(xr::Result::SUCCESS)
    })
}

/// `XR_<NAME>` from openxr-sys' Debug output, which prints the bare name for known values and the
/// number otherwise.
fn enum_name(debug: String) -> Option<String> {
    let numeric = debug
        .trim_start_matches('-')
        .chars()
        .all(|c| c.is_ascii_digit());
    (!numeric).then(|| format!("XR_{debug}"))
}

pub(crate) unsafe extern "system" fn result_to_string(
    instance: xr::Instance,
    value: xr::Result,
    buffer: *mut c_char,
) -> xr::Result {
    entry("xrResultToString", |ctx| {
        let mut w = world();
        w.enter_instance(ctx, instance)?;
        ffi::non_null(buffer)?;
        // Spec: unknown values print as XR_UNKNOWN_SUCCESS_<n> / XR_UNKNOWN_FAILURE_<n>.
        let s = enum_name(format!("{value:?}")).unwrap_or_else(|| {
            let kind = if value.into_raw() >= 0 {
                "SUCCESS"
            } else {
                "FAILURE"
            };
            format!("XR_UNKNOWN_{kind}_{}", value.into_raw())
        });
        ffi::copy_str(
            std::slice::from_raw_parts_mut(buffer, xr::MAX_RESULT_STRING_SIZE),
            &s,
        );
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn structure_type_to_string(
    instance: xr::Instance,
    value: xr::StructureType,
    buffer: *mut c_char,
) -> xr::Result {
    entry("xrStructureTypeToString", |ctx| {
        let mut w = world();
        w.enter_instance(ctx, instance)?;
        ffi::non_null(buffer)?;
        let s = enum_name(format!("{value:?}"))
            .map(|n| n.replacen("XR_", "XR_TYPE_", 1))
            .unwrap_or_else(|| format!("XR_UNKNOWN_STRUCTURE_TYPE_{}", value.into_raw()));
        ffi::copy_str(
            std::slice::from_raw_parts_mut(buffer, xr::MAX_STRUCTURE_NAME_SIZE),
            &s,
        );
        Ok(xr::Result::SUCCESS)
    })
}

/// Path syntax (spec "Path Names"): absolute, lower-case letters, digits, `-_./`, no empty, `.` or
/// `..` components, no trailing slash.
fn well_formed_path(s: &str) -> bool {
    s.len() < xr::MAX_PATH_LENGTH
        && s.starts_with('/')
        && s[1..].split('/').all(|c| {
            !c.is_empty()
                && c != "."
                && c != ".."
                && c.bytes()
                    .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b"-_.".contains(&b))
        })
}

pub(crate) unsafe extern "system" fn string_to_path(
    instance: xr::Instance,
    path_string: *const c_char,
    path: *mut xr::Path,
) -> xr::Result {
    entry("xrStringToPath", |ctx| {
        let mut w = world();
        let id = w.enter_instance(ctx, instance)?;
        ffi::non_null(path)?;
        let s = ffi::c_str(path_string).ok_or(xr::Result::ERROR_VALIDATION_FAILURE)?;
        ctx.detail = s.to_string();
        if !well_formed_path(s) {
            return Err(xr::Result::ERROR_PATH_FORMAT_INVALID);
        }
        let inst = w.instances.get_mut(&id).expect("entered instance exists");
        let index = match inst.paths.iter().position(|p| p == s) {
            Some(i) => i,
            None => {
                inst.paths.push(s.to_string());
                inst.paths.len() - 1
            }
        };
        *path = xr::Path::from_raw(index as u64 + 1);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn path_to_string(
    instance: xr::Instance,
    path: xr::Path,
    capacity: u32,
    count_out: *mut u32,
    buffer: *mut c_char,
) -> xr::Result {
    entry("xrPathToString", |ctx| {
        let mut w = world();
        let id = w.enter_instance(ctx, instance)?;
        let s = w.instances[&id]
            .path(path)
            .ok_or(xr::Result::ERROR_PATH_INVALID)?
            .to_string();
        ffi::two_call_str(capacity, count_out, buffer, &s)?;
        Ok(xr::Result::SUCCESS)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_line_counts_frames_and_errors_by_command() {
        assert_eq!(
            summary_line(300, &BTreeMap::new(), &BTreeMap::new(), &[]),
            "fovea-sim: summary frames=300 errors=0 refused=0 [] views="
        );
        let errors = BTreeMap::from([("xrEndFrame", 1), ("xrCreateSwapchain", 2)]);
        let refusals = BTreeMap::from([("xrEndFrame", 1)]);
        // A double-wide swapchain's halves.
        let half = |x| SubmittedView {
            layer: 0,
            swapchain: 5,
            image_rect: xr::Rect2Di {
                offset: xr::Offset2Di { x, y: 0 },
                extent: xr::Extent2Di {
                    width: 640,
                    height: 480,
                },
            },
            image_array_index: 0,
            fov: xr::Fovf {
                angle_left: -0.5,
                angle_right: 0.5,
                angle_up: 0.5,
                angle_down: -0.5,
            },
        };
        assert_eq!(
            summary_line(7, &errors, &refusals, &[half(0), half(640)]),
            "fovea-sim: summary frames=7 errors=3 refused=1 [xrCreateSwapchain:2 xrEndFrame:1] \
             views=0:5:0:0,0+640x480;0:5:0:640,0+640x480"
        );
    }

    #[test]
    fn path_syntax() {
        for good in [
            "/user/hand/left",
            "/interaction_profiles/khr/simple_controller",
            "/a.b-c_d/0",
        ] {
            assert!(well_formed_path(good), "{good}");
        }
        for bad in [
            "", "user", "/", "/user/", "//a", "/a/./b", "/a/../b", "/User", "/a b",
        ] {
            assert!(!well_formed_path(bad), "{bad}");
        }
    }

    #[test]
    fn enum_names() {
        assert_eq!(
            enum_name(format!("{:?}", xr::Result::ERROR_HANDLE_INVALID)).unwrap(),
            "XR_ERROR_HANDLE_INVALID"
        );
        assert_eq!(enum_name(format!("{:?}", xr::Result::from_raw(-987))), None);
    }
}
