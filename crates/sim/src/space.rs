//! Spaces and view location (spec chapters "Spaces", "View Configurations": xrLocateViews).
//!
//! The simulated head stays at LOCAL's origin, and STAGE's origin lies on the floor 1.6 m below. It
//! does not turn (VIEW coincides with LOCAL) unless the eye tracker's script turns it (`head=V`,
//! [`crate::gaze_script`]): then VIEW turns right about LOCAL's vertical at V degrees per second
//! from the session's start, and the views turn with it. Eyes sit ±31.5 mm (IPD 63 mm) along the head's x axis and look down −z
//! with the headset preset's per-eye FOV.

use openxr_sys as xr;
use openxr_sys::Handle;

use crate::ffi::{self, check_pose};
use crate::objects::{Space, SpaceKind};
use crate::state::{entry, world, World};
use crate::system::VIEW_COUNT;

const EYE_HEIGHT_M: f32 = 1.6;
pub(crate) const IPD_M: f32 = 0.063;

/// The head's pose in LOCAL at `time` in `session`: turned right by the script's head speed since
/// the session started (identity without a turning head).
fn head_in_local(w: &World, session: u64, time: i64) -> xr::Posef {
    let s = &w.sessions[&session];
    let speed = w.instances[&s.instance]
        .config
        .eye_gaze
        .as_ref()
        .map_or(0.0, |g| g.script.head_deg_per_s);
    if speed == 0.0 {
        return IDENTITY;
    }
    let yaw = speed * ((time - s.gaze_origin_ns) as f32 * 1e-9);
    // Turning right is a negative rotation about +y.
    let half = -yaw.to_radians() / 2.0;
    xr::Posef {
        orientation: xr::Quaternionf {
            x: 0.0,
            y: half.sin(),
            z: 0.0,
            w: half.cos(),
        },
        ..IDENTITY
    }
}

impl Space {
    /// The space's pose in LOCAL at `time`, or `None` when untracked; for a gaze space also the
    /// time its sample was taken (`XrEyeGazeSampleTimeEXT`).
    fn pose_in_local(&self, w: &World, time: i64) -> Option<(xr::Posef, Option<i64>)> {
        let (origin, sampled) = match self.kind {
            // LOCAL_FLOOR: LOCAL's origin and yaw, on the floor (spec "Reference Spaces"); the
            // stage here is centred under LOCAL, so the two share a pose.
            SpaceKind::Reference(
                xr::ReferenceSpaceType::STAGE | xr::ReferenceSpaceType::LOCAL_FLOOR,
            ) => (translation(0.0, -EYE_HEIGHT_M, 0.0), None),
            SpaceKind::Reference(xr::ReferenceSpaceType::VIEW) => {
                (head_in_local(w, self.session, time), None)
            }
            SpaceKind::Reference(_) => (IDENTITY, None),
            SpaceKind::Action(action) => {
                if !crate::actions::gaze_active(w, self.session, action) {
                    return None;
                }
                let s = &w.sessions[&self.session];
                let gaze = w.instances[&s.instance].config.eye_gaze.as_ref()?;
                let ([yaw, pitch], at) = gaze.script.sample_at(time - s.gaze_origin_ns)?;
                // The gaze pose sits between the eyes, −Z turned right by the yaw and up by the
                // pitch: in VIEW space, or, with a turning head (`head=V`), in LOCAL space, where
                // the eye holds its target while the head turns.
                let half = |deg: f32| deg.to_radians() / 2.0;
                let turn = xr::Quaternionf {
                    x: 0.0,
                    y: (-half(yaw)).sin(),
                    z: 0.0,
                    w: (-half(yaw)).cos(),
                };
                let lift = xr::Quaternionf {
                    x: half(pitch).sin(),
                    y: 0.0,
                    z: 0.0,
                    w: half(pitch).cos(),
                };
                let pose = xr::Posef {
                    orientation: quat_mul(turn, lift),
                    ..IDENTITY
                };
                (pose, Some(at + s.gaze_origin_ns))
            }
        };
        Some((compose(origin, self.pose_in_parent), sampled))
    }
}

const IDENTITY: xr::Posef = xr::Posef {
    orientation: xr::Quaternionf {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    },
    position: xr::Vector3f {
        x: 0.0,
        y: 0.0,
        z: 0.0,
    },
};

fn translation(x: f32, y: f32, z: f32) -> xr::Posef {
    xr::Posef {
        position: xr::Vector3f { x, y, z },
        ..IDENTITY
    }
}

fn quat_mul(a: xr::Quaternionf, b: xr::Quaternionf) -> xr::Quaternionf {
    xr::Quaternionf {
        w: a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z,
        x: a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
        y: a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
        z: a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w,
    }
}

fn conjugate(q: xr::Quaternionf) -> xr::Quaternionf {
    xr::Quaternionf {
        x: -q.x,
        y: -q.y,
        z: -q.z,
        w: q.w,
    }
}

fn rotate(q: xr::Quaternionf, v: xr::Vector3f) -> xr::Vector3f {
    let p = quat_mul(
        quat_mul(
            q,
            xr::Quaternionf {
                x: v.x,
                y: v.y,
                z: v.z,
                w: 0.0,
            },
        ),
        conjugate(q),
    );
    xr::Vector3f {
        x: p.x,
        y: p.y,
        z: p.z,
    }
}

/// `a ∘ b`: `b` expressed in `a`'s frame, mapped to `a`'s parent.
fn compose(a: xr::Posef, b: xr::Posef) -> xr::Posef {
    let r = rotate(a.orientation, b.position);
    xr::Posef {
        orientation: quat_mul(a.orientation, b.orientation),
        position: xr::Vector3f {
            x: a.position.x + r.x,
            y: a.position.y + r.y,
            z: a.position.z + r.z,
        },
    }
}

fn inverse(p: xr::Posef) -> xr::Posef {
    let q = conjugate(p.orientation);
    let t = rotate(q, p.position);
    xr::Posef {
        orientation: q,
        position: xr::Vector3f {
            x: -t.x,
            y: -t.y,
            z: -t.z,
        },
    }
}

/// The reference spaces of an instance of API 1.0, then `LOCAL_FLOOR`, which OpenXR 1.1 made core
/// and requires of every runtime (spec "Reference Spaces": XR_REFERENCE_SPACE_TYPE_LOCAL_FLOOR,
/// "available in OpenXR 1.1"; under 1.0 it needs XR_EXT_local_floor, which this runtime does
/// not offer).
const REFERENCE_SPACES: [xr::ReferenceSpaceType; 4] = [
    xr::ReferenceSpaceType::VIEW,
    xr::ReferenceSpaceType::LOCAL,
    xr::ReferenceSpaceType::STAGE,
    xr::ReferenceSpaceType::LOCAL_FLOOR,
];

/// The reference spaces `session`'s instance offers.
fn reference_spaces(w: &World, session: u64) -> &'static [xr::ReferenceSpaceType] {
    let version = w.instances[&w.sessions[&session].instance].api_version;
    if (version.major(), version.minor()) >= (1, 1) {
        &REFERENCE_SPACES
    } else {
        &REFERENCE_SPACES[..3]
    }
}

pub(crate) unsafe extern "system" fn enumerate_reference_spaces(
    session: xr::Session,
    capacity: u32,
    count_out: *mut u32,
    spaces: *mut xr::ReferenceSpaceType,
) -> xr::Result {
    entry("xrEnumerateReferenceSpaces", |ctx| {
        let mut w = world();
        let session = w.enter_session(ctx, session)?;
        let offered = reference_spaces(&w, session);
        ffi::two_call(capacity, count_out, spaces, offered.len(), |i, p| {
            *p = offered[i];
            Ok(())
        })?;
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn create_reference_space(
    session: xr::Session,
    create_info: *const xr::ReferenceSpaceCreateInfo,
    space: *mut xr::Space,
) -> xr::Result {
    entry("xrCreateReferenceSpace", |ctx| {
        let mut w = world();
        let session = w.enter_session(ctx, session)?;
        let info = ffi::input(create_info, xr::StructureType::REFERENCE_SPACE_CREATE_INFO)?;
        ffi::non_null(space)?;
        ctx.next_types = ffi::chain_types(info.next);
        if !reference_spaces(&w, session).contains(&info.reference_space_type) {
            return Err(xr::Result::ERROR_REFERENCE_SPACE_UNSUPPORTED);
        }
        check_pose(&info.pose_in_reference_space)?;
        ctx.detail = format!("{:?}", info.reference_space_type);
        let id = w.alloc_handle();
        let kind = SpaceKind::Reference(info.reference_space_type);
        w.spaces.insert(
            id,
            Space {
                session,
                kind,
                pose_in_parent: info.pose_in_reference_space,
            },
        );
        *space = xr::Space::from_raw(id);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn get_reference_space_bounds_rect(
    session: xr::Session,
    reference_space_type: xr::ReferenceSpaceType,
    bounds: *mut xr::Extent2Df,
) -> xr::Result {
    entry("xrGetReferenceSpaceBoundsRect", |ctx| {
        let mut w = world();
        let session = w.enter_session(ctx, session)?;
        ffi::non_null(bounds)?;
        if !reference_spaces(&w, session).contains(&reference_space_type) {
            return Err(xr::Result::ERROR_REFERENCE_SPACE_UNSUPPORTED);
        }
        // Spec: with no known bounds the runtime returns XR_SPACE_BOUNDS_UNAVAILABLE and zero extents.
        *bounds = xr::Extent2Df {
            width: 0.0,
            height: 0.0,
        };
        Ok(xr::Result::SPACE_BOUNDS_UNAVAILABLE)
    })
}

pub(crate) unsafe extern "system" fn destroy_space(space: xr::Space) -> xr::Result {
    entry("xrDestroySpace", |ctx| {
        ctx.allow_lost = true;
        let mut w = world();
        let id = w.enter_space(ctx, space)?;
        w.spaces.remove(&id);
        Ok(xr::Result::SUCCESS)
    })
}

fn check_time(time: xr::Time) -> Result<(), xr::Result> {
    if time.as_nanos() > 0 {
        Ok(())
    } else {
        Err(xr::Result::ERROR_TIME_INVALID)
    }
}

fn tracked() -> xr::SpaceLocationFlags {
    xr::SpaceLocationFlags::ORIENTATION_VALID
        | xr::SpaceLocationFlags::POSITION_VALID
        | xr::SpaceLocationFlags::ORIENTATION_TRACKED
        | xr::SpaceLocationFlags::POSITION_TRACKED
}

pub(crate) unsafe extern "system" fn locate_space(
    space: xr::Space,
    base_space: xr::Space,
    time: xr::Time,
    location: *mut xr::SpaceLocation,
) -> xr::Result {
    entry("xrLocateSpace", |ctx| {
        let mut w = world();
        let id = w.enter_space(ctx, space)?;
        let base = base_space.into_raw();
        let base_space = w
            .spaces
            .get(&base)
            .ok_or(xr::Result::ERROR_HANDLE_INVALID)?;
        let space = &w.spaces[&id];
        if base_space.session != space.session {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        let location = ffi::output(location, xr::StructureType::SPACE_LOCATION)?;
        check_time(time)?;
        match (
            space.pose_in_local(&w, time.as_nanos()),
            base_space.pose_in_local(&w, time.as_nanos()),
        ) {
            (Some((s, sampled)), Some((b, _))) => {
                (*location).pose = compose(inverse(b), s);
                // A sub-nominal tracker (the script's `tracked=no`) gives its gaze VALID only.
                let sub_nominal = sampled.is_some()
                    && w.instances[&w.sessions[&space.session].instance]
                        .config
                        .eye_gaze
                        .as_ref()
                        .is_some_and(|g| g.script.sub_nominal);
                (*location).location_flags = if sub_nominal {
                    xr::SpaceLocationFlags::ORIENTATION_VALID
                        | xr::SpaceLocationFlags::POSITION_VALID
                } else {
                    tracked()
                };
                let ty = xr::StructureType::EYE_GAZE_SAMPLE_TIME_EXT;
                if let (Some(t), Some(e)) = (sampled, ffi::find_in_chain((*location).next, ty)) {
                    (*(e as *mut xr::EyeGazeSampleTimeEXT)).time = xr::Time::from_nanos(t);
                }
            }
            _ => {
                (*location).pose = IDENTITY;
                (*location).location_flags = xr::SpaceLocationFlags::EMPTY;
            }
        }
        Ok(xr::Result::SUCCESS)
    })
}

/// The per-eye FOVs of the session's headset.
pub(crate) fn eye_fovs(w: &World, session: u64) -> [xr::Fovf; VIEW_COUNT] {
    let headset = w.instances[&w.sessions[&session].instance].config.headset;
    headset.fovs().map(|f| xr::Fovf {
        angle_left: f.left,
        angle_right: f.right,
        angle_up: f.up,
        angle_down: f.down,
    })
}

pub(crate) unsafe extern "system" fn locate_views(
    session: xr::Session,
    view_locate_info: *const xr::ViewLocateInfo,
    view_state: *mut xr::ViewState,
    capacity: u32,
    count_out: *mut u32,
    views: *mut xr::View,
) -> xr::Result {
    entry("xrLocateViews", |ctx| {
        let mut w = world();
        let session = w.enter_session(ctx, session)?;
        let info = ffi::input(view_locate_info, xr::StructureType::VIEW_LOCATE_INFO)?;
        ctx.next_types = ffi::chain_types(info.next);
        let view_state = ffi::output(view_state, xr::StructureType::VIEW_STATE)?;
        crate::system::check_view_configuration(info.view_configuration_type)?;
        // Views exist only while the session runs, for the configuration it began with (a real
        // runtime such as Monado sets its view configuration up in xrBeginSession). The spec's
        // return codes for xrLocateViews do not include XR_ERROR_SESSION_NOT_RUNNING, so outside a
        // running session the answer is XR_ERROR_VALIDATION_FAILURE, as Monado gives; a supported
        // configuration other than the session's is XR_ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED
        // (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#xrLocateViews).
        match w.sessions[&session].view_configuration {
            None => {
                ctx.detail = "refused: the session is not running".into();
                return Err(xr::Result::ERROR_VALIDATION_FAILURE);
            }
            Some(begun) if begun != info.view_configuration_type => {
                ctx.detail = format!("refused: the session began with {begun:?}");
                return Err(xr::Result::ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED);
            }
            Some(_) => {}
        }
        check_time(info.display_time)?;
        let space = w
            .spaces
            .get(&info.space.into_raw())
            .ok_or(xr::Result::ERROR_HANDLE_INVALID)?;
        if space.session != session {
            return Err(xr::Result::ERROR_VALIDATION_FAILURE);
        }
        let base = space
            .pose_in_local(&w, info.display_time.as_nanos())
            .map(|(pose, _)| pose);
        let fovs = eye_fovs(&w, session);
        ffi::two_call(capacity, count_out, views, VIEW_COUNT, |i, p| {
            let p = ffi::output(p, xr::StructureType::VIEW)?;
            let x = if i == 0 { -IPD_M / 2.0 } else { IPD_M / 2.0 };
            let head = head_in_local(&w, session, info.display_time.as_nanos());
            (*p).pose = base.map_or(IDENTITY, |b| {
                compose(inverse(b), compose(head, translation(x, 0.0, 0.0)))
            });
            (*p).fov = fovs[i];
            Ok(())
        })?;
        (*view_state).view_state_flags = if base.is_some() {
            xr::ViewStateFlags::ORIENTATION_VALID
                | xr::ViewStateFlags::POSITION_VALID
                | xr::ViewStateFlags::ORIENTATION_TRACKED
                | xr::ViewStateFlags::POSITION_TRACKED
        } else {
            xr::ViewStateFlags::EMPTY
        };
        Ok(xr::Result::SUCCESS)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_algebra() {
        let yaw90 = xr::Posef {
            orientation: xr::Quaternionf {
                x: 0.0,
                y: std::f32::consts::FRAC_1_SQRT_2,
                z: 0.0,
                w: std::f32::consts::FRAC_1_SQRT_2,
            },
            position: xr::Vector3f {
                x: 1.0,
                y: 2.0,
                z: 3.0,
            },
        };
        let id = compose(inverse(yaw90), yaw90);
        assert!(
            id.position.x.abs() < 1e-6
                && id.position.z.abs() < 1e-6
                && (id.orientation.w - 1.0).abs() < 1e-6
        );
        // Rotating +x by 90° about +y gives −z.
        let r = rotate(
            yaw90.orientation,
            xr::Vector3f {
                x: 1.0,
                y: 0.0,
                z: 0.0,
            },
        );
        assert!((r.z + 1.0).abs() < 1e-6 && r.x.abs() < 1e-6);
        assert!(check_pose(&yaw90).is_ok());
        let bad = xr::Posef {
            orientation: xr::Quaternionf {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 0.0,
            },
            ..IDENTITY
        };
        assert_eq!(check_pose(&bad), Err(xr::Result::ERROR_POSE_INVALID));
    }
}
