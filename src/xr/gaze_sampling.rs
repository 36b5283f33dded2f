//! The gaze source's per-session part, its sampling: the attach state a session's gaze waits in,
//! the syncs fovea makes alone for an application that never syncs, the gaze located right after
//! each `xrWaitFrame`, filtered and projected into each view (docs/eye-tracking.md#the-steps-where-the-gaze-is-used,
//! steps 5 to 7), and the calls down it makes through pointers loaded once per instance
//! ([`Calls`]). The instance's part, which makes the action set and merges fovea's binding into
//! the application's suggestions and attaches, is [`crate::xr::gaze`].
//!
//! Every way this fails falls back to fixed foveation with one log line saying why. Per frame: two
//! or three calls down, one record lock, no allocation; no lock is held while a call runs.

use std::ffi::{c_void, CStr};
use std::sync::atomic::Ordering::{AcqRel, Acquire, Relaxed, Release};
use std::sync::atomic::{AtomicBool, AtomicI32, AtomicI64, AtomicU32, AtomicU64, AtomicU8};

use glam::{Quat, Vec3};
use openxr_sys as xr;
use xr::Handle;

use crate::common::lock::SpinMutex;
use crate::common::settings::GazeSettings;
use crate::xr::eye_centres::EyeCentres;
use crate::xr::values::{fov_from_xr, succeeded};
use fovea_model::gaze::{centre_in, EyeProjection, EyeView, GazeFilter, Sample};
use fovea_model::maps::MAX_VIEWS;
use fovea_model::Fov;

/// The log target of every gaze line.
pub(crate) const TARGET: &str = fovea_abi::log_target::GAZE;

/// Display time after an attach without a single active gaze sample before fovea says so.
const NEVER_ACTIVE_NS: i64 = 5_000_000_000;

/// The runtime's functions the gaze source calls, loaded from the next layer once per instance.
#[derive(Clone, Copy)]
pub(crate) struct Calls {
    pub(crate) string_to_path: xr::pfn::StringToPath,
    pub(crate) get_system_properties: xr::pfn::GetSystemProperties,
    pub(crate) create_action_set: xr::pfn::CreateActionSet,
    pub(crate) create_action: xr::pfn::CreateAction,
    pub(crate) suggest: xr::pfn::SuggestInteractionProfileBindings,
    pub(crate) attach: xr::pfn::AttachSessionActionSets,
    pub(crate) sync: xr::pfn::SyncActions,
    pub(crate) create_action_space: xr::pfn::CreateActionSpace,
    pub(crate) create_reference_space: xr::pfn::CreateReferenceSpace,
    pub(crate) get_action_state_pose: xr::pfn::GetActionStatePose,
    pub(crate) locate_space: xr::pfn::LocateSpace,
    pub(crate) locate_views: xr::pfn::LocateViews,
}

/// Asks `gipa` for `name` as the function type `F`; `None` where it is not offered.
///
/// # Safety
/// `gipa` must be the next layer's `xrGetInstanceProcAddr` and `instance` its instance; `F` the
/// function type the name implies.
unsafe fn load<F: Copy>(
    gipa: xr::pfn::GetInstanceProcAddr,
    instance: xr::Instance,
    name: &CStr,
) -> Option<F> {
    let mut f = None;
    // SAFETY: the caller's contract; the name is NUL-terminated and `f` a live local.
    let r = unsafe { gipa(instance, name.as_ptr(), &mut f) };
    let f: xr::pfn::VoidFunction = f.filter(|_| succeeded(r))?;
    debug_assert_eq!(std::mem::size_of::<F>(), std::mem::size_of_val(&f));
    // SAFETY: the next layer answered for `name`, so the pointer has the signature the spec gives
    // that name, which the caller names as `F`.
    Some(unsafe { std::mem::transmute_copy::<xr::pfn::VoidFunction, F>(&f) })
}

impl Calls {
    /// # Safety
    /// As [`load`].
    pub(crate) unsafe fn load(
        gipa: xr::pfn::GetInstanceProcAddr,
        i: xr::Instance,
    ) -> Option<Calls> {
        // SAFETY: the caller's contract; each name's type is the field's.
        unsafe {
            Some(Calls {
                string_to_path: load(gipa, i, c"xrStringToPath")?,
                get_system_properties: load(gipa, i, c"xrGetSystemProperties")?,
                create_action_set: load(gipa, i, c"xrCreateActionSet")?,
                create_action: load(gipa, i, c"xrCreateAction")?,
                suggest: load(gipa, i, c"xrSuggestInteractionProfileBindings")?,
                attach: load(gipa, i, c"xrAttachSessionActionSets")?,
                sync: load(gipa, i, c"xrSyncActions")?,
                create_action_space: load(gipa, i, c"xrCreateActionSpace")?,
                create_reference_space: load(gipa, i, c"xrCreateReferenceSpace")?,
                get_action_state_pose: load(gipa, i, c"xrGetActionStatePose")?,
                locate_space: load(gipa, i, c"xrLocateSpace")?,
                locate_views: load(gipa, i, c"xrLocateViews")?,
            })
        }
    }
}

/// Whether the runtime answered a call fovea made with success; the log says which call failed.
pub(crate) fn ok(call: &'static str, r: xr::Result) -> Result<(), xr::Result> {
    crate::common::lock::assert_none_held(call);
    if succeeded(r) {
        Ok(())
    } else {
        Err(r)
    }
}
/// The session's gaze source is waiting for an attach.
pub(crate) const WAITING: u8 = 0;
/// fovea's set is attached and its spaces made: the gaze is located every frame.
const ATTACHED: u8 = 1;
/// Something was refused: fixed foveation for the rest of the session (logged once).
const FAILED: u8 = 2;

/// Who attached the session's action sets ([`SessionGaze::claim`]): nobody yet, the application
/// (with fovea's set appended), or fovea alone.
pub(crate) const OPEN: u8 = 0;
pub(crate) const BY_APP: u8 = 1;
pub(crate) const BY_FOVEA: u8 = 2;
/// fovea has claimed the session and its attach is on its way down.
pub(crate) const FOVEA_ATTACHING: u8 = 3;

/// What the frame loop's `xrWaitFrame` should do for the gaze this frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Due {
    Nothing,
    /// The application attached nothing in the grace period (an opt-in): attach fovea's set alone.
    AttachAlone,
    /// The application attached but never synced: sync fovea's set alone and locate the gaze.
    SyncAlone,
}

/// The gaze source's per-session part.
pub struct SessionGaze {
    pub(crate) session: xr::Session,
    calls: Calls,
    action: xr::Action,
    attach_after_ns: Option<i64>,
    pub(crate) phase: AtomicU8,
    gaze_space: AtomicU64,
    view_space: AtomicU64,
    /// fovea's set, once attached to this session.
    set: AtomicU64,
    /// Who attached the session's sets (`OPEN`, `BY_APP`, `FOVEA_ATTACHING`, `BY_FOVEA`),
    /// claimed atomically.
    pub(crate) claim: AtomicU8,
    app_synced: AtomicBool,
    /// The last session state the application polled is FOCUSED: only then does fovea sync alone.
    focused: AtomicBool,
    /// The view configuration the session began with (0: not running).
    view_config: AtomicI32,
    /// The predicted display time of the last `xrWaitFrame`, and of the first.
    display_ns: AtomicI64,
    first_display_ns: AtomicI64,
    /// The display time of the first update after fovea's set was attached, and whether the action was ever active since.
    attached_ns: AtomicI64,
    ever_active: AtomicBool,
    /// `xrWaitFrame` calls since the attach while the application has never synced.
    waits_unsynced: AtomicU32,
    /// The bits of the FOVs the application last located (two `f32` per word), how many views,
    /// and whether they changed since fovea located the views itself.
    app_fov_bits: [AtomicU64; 2 * MAX_VIEWS],
    app_views: AtomicU32,
    views_stale: AtomicBool,
    /// Once-lines said (one bit per cause).
    said: AtomicU32,
    track: SpinMutex<Track>,
}

/// The filter and the views it projects into, each with its projection computed when the views
/// were located (not every frame).
struct Track {
    filter: GazeFilter,
    views: [EyeProjection; MAX_VIEWS],
    count: usize,
}

const NO_VIEW: EyeView = EyeView {
    fov: fovea_model::maps::FALLBACK_FOV,
    position: Vec3::ZERO,
    orientation: Quat::IDENTITY,
};

/// The once-lines of a session.
const SAID_NEVER_ACTIVE: u32 = 1;
const SAID_VIEWS: u32 = 2;
const SAID_LOCATE: u32 = 4;

impl SessionGaze {
    pub(crate) fn new(
        session: xr::Session,
        calls: Calls,
        action: xr::Action,
        settings: GazeSettings,
    ) -> SessionGaze {
        SessionGaze {
            session,
            calls,
            action,
            attach_after_ns: settings
                .attach_after_s
                .map(|s| (f64::from(s.max(0.0)) * 1e9) as i64),
            phase: AtomicU8::new(WAITING),
            gaze_space: AtomicU64::new(0),
            view_space: AtomicU64::new(0),
            set: AtomicU64::new(0),
            claim: AtomicU8::new(OPEN),
            app_synced: AtomicBool::new(false),
            focused: AtomicBool::new(false),
            view_config: AtomicI32::new(0),
            display_ns: AtomicI64::new(0),
            first_display_ns: AtomicI64::new(0),
            attached_ns: AtomicI64::new(0),
            ever_active: AtomicBool::new(false),
            waits_unsynced: AtomicU32::new(0),
            app_fov_bits: Default::default(),
            app_views: AtomicU32::new(0),
            views_stale: AtomicBool::new(true),
            said: AtomicU32::new(0),
            track: SpinMutex::spin(Track {
                filter: GazeFilter::new(settings.params),
                views: [NO_VIEW.projection(); MAX_VIEWS],
                count: 0,
            }),
        }
    }

    /// Whether the line for `cause` is still to be said (and marks it said).
    fn first(&self, cause: u32) -> bool {
        self.said.fetch_or(cause, AcqRel) & cause == 0
    }

    /// A refusal: fixed foveation for the rest of the session, said once.
    pub fn fail(&self, r: xr::Result, why: &'static str) {
        if self.phase.swap(FAILED, AcqRel) != FAILED {
            tracing::warn!(target: TARGET, ?r, "{why}: fixed foveation for this session");
        }
    }

    /// fovea's set is attached: make the gaze space and the VIEW space (only now: some runtimes
    /// refuse a gaze space before).
    pub(crate) fn attached(&self, set: xr::ActionSet) {
        let info = xr::ActionSpaceCreateInfo {
            ty: xr::StructureType::ACTION_SPACE_CREATE_INFO,
            next: std::ptr::null(),
            action: self.action,
            subaction_path: xr::Path::NULL,
            pose_in_action_space: xr::Posef::IDENTITY,
        };
        let mut gaze = xr::Space::NULL;
        // SAFETY: a live session, fovea's own attached action and a live output.
        let r = unsafe { (self.calls.create_action_space)(self.session, &info, &mut gaze) };
        if let Err(r) = ok("xrCreateActionSpace", r) {
            return self.fail(r, "the runtime refused fovea's eye gaze space");
        }
        let info = xr::ReferenceSpaceCreateInfo {
            ty: xr::StructureType::REFERENCE_SPACE_CREATE_INFO,
            next: std::ptr::null(),
            reference_space_type: xr::ReferenceSpaceType::VIEW,
            pose_in_reference_space: xr::Posef::IDENTITY,
        };
        let mut view = xr::Space::NULL;
        // SAFETY: a live session, fovea's own create info and a live output.
        let r = unsafe { (self.calls.create_reference_space)(self.session, &info, &mut view) };
        if let Err(r) = ok("xrCreateReferenceSpace", r) {
            return self.fail(r, "the runtime refused fovea's VIEW space");
        }
        self.gaze_space.store(gaze.into_raw(), Relaxed);
        self.view_space.store(view.into_raw(), Relaxed);
        self.set.store(set.into_raw(), Relaxed);
        self.phase.store(ATTACHED, Release);
    }

    /// fovea's set, while it is attached to the session (atomics only: this runs every frame).
    fn attached_set(&self) -> Option<xr::ActionSet> {
        (self.phase.load(Acquire) == ATTACHED)
            .then(|| xr::ActionSet::from_raw(self.set.load(Relaxed)))
    }

    /// The active set fovea adds to the application's `xrSyncActions`, while it is attached.
    pub fn active_set(&self) -> Option<xr::ActiveActionSet> {
        self.app_synced.store(true, Relaxed);
        self.attached_set().map(|action_set| xr::ActiveActionSet {
            action_set,
            subaction_path: xr::Path::NULL,
        })
    }

    /// Syncs fovea's set alone, for an application that attached but has never synced.
    pub fn sync_alone(&self) {
        let Some(action_set) = self.attached_set() else {
            return;
        };
        let active = xr::ActiveActionSet {
            action_set,
            subaction_path: xr::Path::NULL,
        };
        let info = xr::ActionsSyncInfo {
            ty: xr::StructureType::ACTIONS_SYNC_INFO,
            next: std::ptr::null(),
            count_active_action_sets: 1,
            active_action_sets: &active,
        };
        // SAFETY: a live session and fovea's own attached set.
        let r = unsafe { (self.calls.sync)(self.session, &info) };
        if let Err(r) = ok("xrSyncActions", r) {
            self.fail(r, "the runtime refused to sync fovea's eye gaze action set");
        }
    }

    /// The application polled a session state change: fovea syncs alone only while FOCUSED.
    pub fn state_changed(&self, state: xr::SessionState) {
        self.focused
            .store(state == xr::SessionState::FOCUSED, Relaxed);
    }

    /// fovea attached its set alone (an opt-in): the session holds no set of the application's.
    pub fn attached_alone(&self) -> bool {
        self.claim.load(Relaxed) == BY_FOVEA
    }

    /// `xrBeginSession` succeeded with this primary view configuration.
    pub fn began(&self, config: xr::ViewConfigurationType) {
        self.view_config.store(config.into_raw(), Relaxed);
        self.views_stale.store(true, Relaxed);
    }

    /// `xrEndSession` succeeded: no views to locate until the next begin.
    pub fn ended(&self) {
        self.view_config.store(0, Relaxed);
    }

    /// `xrWaitFrame` returned this predicted display time: what the gaze source should do now.
    pub fn waited(&self, display_ns: i64) -> Due {
        self.display_ns.store(display_ns, Relaxed);
        let first = match self.first_display_ns.load(Relaxed) {
            0 => {
                self.first_display_ns.store(display_ns, Relaxed);
                display_ns
            }
            t => t,
        };
        match self.phase.load(Acquire) {
            WAITING if self.claim.load(Relaxed) == OPEN => match self.attach_after_ns {
                Some(grace) if display_ns - first >= grace => Due::AttachAlone,
                _ => Due::Nothing,
            },
            // The application's own first sync comes after its first xrWaitFrame: a whole frame
            // without one is an application that does not sync.
            ATTACHED if !self.app_synced.load(Relaxed) && self.focused.load(Relaxed) => {
                if self.waits_unsynced.fetch_add(1, Relaxed) >= 1 {
                    Due::SyncAlone
                } else {
                    Due::Nothing
                }
            }
            _ => Due::Nothing,
        }
    }

    /// The FOVs the application just located (after fovea's own changes to them): fovea locates
    /// the views again at the next update where they changed. Compares bits, takes no lock.
    pub fn app_located(&self, fovs: impl Iterator<Item = Fov>) {
        let mut n = 0;
        let mut changed = false;
        for (i, f) in fovs.take(MAX_VIEWS).enumerate() {
            let words = [
                u64::from(f.left.to_bits()) << 32 | u64::from(f.right.to_bits()),
                u64::from(f.up.to_bits()) << 32 | u64::from(f.down.to_bits()),
            ];
            for (slot, w) in self.app_fov_bits[2 * i..2 * i + 2].iter().zip(words) {
                if slot.swap(w, Relaxed) != w {
                    changed = true;
                }
            }
            n = i + 1;
        }
        if self.app_views.swap(n as u32, Relaxed) != n as u32 {
            changed = true;
        }
        if changed {
            self.views_stale.store(true, Release);
        }
    }

    /// The application's located FOV of view `i`.
    fn app_fov(&self, i: usize) -> Fov {
        let [a, b] = [0, 1].map(|k| self.app_fov_bits[2 * i + k].load(Relaxed));
        Fov {
            left: f32::from_bits((a >> 32) as u32),
            right: f32::from_bits(a as u32),
            up: f32::from_bits((b >> 32) as u32),
            down: f32::from_bits(b as u32),
        }
    }

    /// Locates the views in fovea's VIEW space at `time`: each eye's pose there, with the FOV the
    /// application renders with where it located the same views.
    fn locate_views(&self, config: xr::ViewConfigurationType, time: i64, view: xr::Space) {
        let empty = xr::View {
            ty: xr::StructureType::VIEW,
            next: std::ptr::null_mut(),
            pose: xr::Posef::IDENTITY,
            fov: xr::Fovf {
                angle_left: 0.0,
                angle_right: 0.0,
                angle_up: 0.0,
                angle_down: 0.0,
            },
        };
        let mut views = [empty; MAX_VIEWS];
        let mut state = xr::ViewState {
            ty: xr::StructureType::VIEW_STATE,
            next: std::ptr::null_mut(),
            view_state_flags: xr::ViewStateFlags::EMPTY,
        };
        let info = xr::ViewLocateInfo {
            ty: xr::StructureType::VIEW_LOCATE_INFO,
            next: std::ptr::null(),
            view_configuration_type: config,
            display_time: xr::Time::from_nanos(time),
            space: view,
        };
        let mut n = 0;
        // SAFETY: a running session, fovea's own VIEW space and outputs for MAX_VIEWS views.
        let r = unsafe {
            (self.calls.locate_views)(
                self.session,
                &info,
                &mut state,
                MAX_VIEWS as u32,
                &mut n,
                views.as_mut_ptr(),
            )
        };
        if let Err(r) = ok("xrLocateViews", r) {
            if self.first(SAID_VIEWS) {
                tracing::warn!(
                    target: TARGET,
                    ?r,
                    "the runtime refused fovea's xrLocateViews; the fovea keeps the views it knew"
                );
            }
            return;
        }
        let n = (n as usize).min(MAX_VIEWS);
        let app_views = self.app_views.load(Acquire) as usize;
        let mut located = [NO_VIEW.projection(); MAX_VIEWS];
        for (i, (slot, v)) in located.iter_mut().zip(&views[..n]).enumerate() {
            let (p, o) = (v.pose.position, v.pose.orientation);
            *slot = EyeView {
                fov: if app_views == n {
                    self.app_fov(i)
                } else {
                    fov_from_xr(v.fov)
                },
                position: Vec3::new(p.x, p.y, p.z),
                orientation: Quat::from_xyzw(o.x, o.y, o.z, o.w).normalize(),
            }
            .projection();
        }
        let mut t = self.track.lock();
        t.views = located;
        t.count = n;
    }

    /// This frame's sample: the gaze action's pose in VIEW space at `time`, where the action is
    /// active and the orientation valid.
    fn sample(&self, time: i64, gaze: xr::Space, view: xr::Space) -> Option<Sample> {
        let get = xr::ActionStateGetInfo {
            ty: xr::StructureType::ACTION_STATE_GET_INFO,
            next: std::ptr::null(),
            action: self.action,
            subaction_path: xr::Path::NULL,
        };
        let mut state = xr::ActionStatePose {
            ty: xr::StructureType::ACTION_STATE_POSE,
            next: std::ptr::null_mut(),
            is_active: xr::FALSE,
        };
        // SAFETY: a live session, fovea's own attached action and a live output.
        let r = unsafe { (self.calls.get_action_state_pose)(self.session, &get, &mut state) };
        if let Err(r) = ok("xrGetActionStatePose", r) {
            if self.first(SAID_LOCATE) {
                tracing::warn!(target: TARGET, ?r, "the runtime refused fovea's gaze action state");
            }
            return None;
        }
        if state.is_active == xr::FALSE {
            return None;
        }
        self.ever_active.store(true, Relaxed);
        let mut sampled = xr::EyeGazeSampleTimeEXT {
            ty: xr::StructureType::EYE_GAZE_SAMPLE_TIME_EXT,
            next: std::ptr::null_mut(),
            time: xr::Time::from_nanos(0),
        };
        let mut location = xr::SpaceLocation {
            ty: xr::StructureType::SPACE_LOCATION,
            next: &mut sampled as *mut _ as *mut c_void,
            location_flags: xr::SpaceLocationFlags::EMPTY,
            pose: xr::Posef::IDENTITY,
        };
        let at = xr::Time::from_nanos(time);
        // SAFETY: fovea's own live spaces of this session, a valid time, its own outputs.
        let r = unsafe { (self.calls.locate_space)(gaze, view, at, &mut location) };
        if let Err(r) = ok("xrLocateSpace", r) {
            if self.first(SAID_LOCATE) {
                tracing::warn!(target: TARGET, ?r, "the runtime refused to locate fovea's gaze");
            }
            return None;
        }
        // VALID is enough: a sub-nominal gaze (VALID without TRACKED) is still the runtime's best
        // estimate, and OpenXR Toolkit and Quad-Views-Foveated use it too
        // (docs/eye-tracking.md#where-gaze-comes-from).
        if !location
            .location_flags
            .contains(xr::SpaceLocationFlags::ORIENTATION_VALID)
        {
            return None;
        }
        let o = location.pose.orientation;
        let direction = Quat::from_xyzw(o.x, o.y, o.z, o.w) * Vec3::NEG_Z;
        let t = sampled.time.as_nanos();
        Some(Sample {
            time_ns: if t > 0 { t } else { time },
            direction,
        })
    }

    /// Locates the gaze for the frame of the last `xrWaitFrame` (right after it) and answers where
    /// each view's fovea is; `None` where the source has nothing to say (not attached, not running,
    /// no views).
    pub fn update(&self) -> Option<EyeCentres> {
        if self.phase.load(Acquire) != ATTACHED {
            return None;
        }
        let config = self.view_config.load(Relaxed);
        let time = self.display_ns.load(Relaxed);
        if config == 0 || time <= 0 {
            return None;
        }
        let gaze = xr::Space::from_raw(self.gaze_space.load(Relaxed));
        let view = xr::Space::from_raw(self.view_space.load(Relaxed));
        if self.views_stale.swap(false, AcqRel) {
            self.locate_views(xr::ViewConfigurationType::from_raw(config), time, view);
        }
        let sample = self.sample(time, gaze, view);
        let attached_ns = match self.attached_ns.load(Relaxed) {
            0 => {
                self.attached_ns.store(time, Relaxed);
                time
            }
            t => t,
        };
        if sample.is_none()
            && !self.ever_active.load(Relaxed)
            && time - attached_ns >= NEVER_ACTIVE_NS
            && self.first(SAID_NEVER_ACTIVE)
        {
            tracing::info!(
                target: TARGET,
                "the runtime's eye gaze has not been active for 5 s since fovea's action set was \
                 attached (no permission, tracker off, or the session not focused): fixed \
                 foveation until it is"
            );
        }
        let mut t = self.track.lock();
        if t.count == 0 {
            return None;
        }
        let g = t.filter.update(sample, time);
        let fixation = t.filter.params().fixation_m;
        let mut ndc = [[0.0; 2]; MAX_VIEWS];
        for (c, eye) in ndc.iter_mut().zip(&t.views[..t.count]) {
            *c = centre_in(&g, eye, fixation);
        }
        let centres = EyeCentres {
            ndc,
            views: t.count as u8,
            tracking: g.tracking,
            time_ns: time,
        };
        drop(t);
        tracing::trace!(
            target: TARGET,
            time_ns = time,
            tracking = ?centres.tracking,
            yaw = g.angles[0],
            pitch = g.angles[1],
            weight = g.weight,
            ndc = ?&centres.ndc[..usize::from(centres.views)],
            "gaze"
        );
        Some(centres)
    }
}
