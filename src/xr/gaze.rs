//! fovea's own gaze source: where the eye looks, from the runtime's `XR_EXT_eye_gaze_interaction`
//! through an action set of the layer's own, filtered and projected into each view
//! (docs/eye-tracking.md#where-gaze-comes-from). This file is its instance's part: whether it is
//! used at all, the action set and pose action, fovea's binding merged into the application's
//! suggestions, and the attach with the application's sets or alone. The sampling, per session and
//! per frame, is [`crate::xr::gaze_sampling`].
//!
//! The steps it takes to survive real runtimes and applications, and why each, are
//! docs/eye-tracking.md#the-steps-where-the-gaze-is-used; who uses the gaze at all ([`used`]) is
//! docs/eye-tracking.md#who-uses-the-gaze, and which refused calls go down again as the application
//! made them ([`app_caused`]) docs/eye-tracking.md#when-there-is-no-gaze.
//!
//! Every way this fails falls back to fixed foveation with one log line saying why.

use std::ffi::{c_char, c_void, CStr};
use std::sync::atomic::AtomicBool;
use std::sync::atomic::Ordering::{AcqRel, Acquire, Release};

use openxr_sys as xr;
use xr::Handle;

use crate::common::lock::Mutex;
use crate::common::settings::GazeSettings;
use crate::xr::ffi;
use crate::xr::values::succeeded;

use crate::xr::gaze_sampling::{
    ok, Calls, BY_APP, BY_FOVEA, FOVEA_ATTACHING, OPEN, TARGET, WAITING,
};
pub use crate::xr::gaze_sampling::{Due, SessionGaze};

/// The extension the gaze comes through.
pub const EXTENSION: &CStr = c"XR_EXT_eye_gaze_interaction";
/// Its interaction profile and the one input fovea binds.
const PROFILE: &CStr = c"/interaction_profiles/ext/eye_gaze_interaction";
const GAZE_POSE: &CStr = c"/user/eyes_ext/input/gaze_ext/pose";

/// Whether anything of fovea's follows the eyes in an instance (docs/eye-tracking.md#who-uses-the-gaze):
/// `XR_META_foveation_eye_tracked` as fovea provides it (its state and eye-tracked profiles), or
/// injection (its maps follow the gaze). Decided at `xrCreateInstance`; where neither, fovea adds
/// nothing of eye gaze to the instance.
pub fn used(meta_eye_tracked_provided: bool, injects: bool) -> bool {
    meta_eye_tracked_provided || injects
}

/// Whether a refusal of a call that went down with fovea's part added is one the application's own
/// part caused whatever fovea added: fovea's part is its own live, well-formed handles and paths,
/// so invalid handles or structs, a wrong call order, a lost session or instance are the
/// application's. Such a refusal is the application's answer, and its call does not go down a
/// second time.
pub fn app_caused(r: xr::Result) -> bool {
    [
        xr::Result::ERROR_HANDLE_INVALID,
        xr::Result::ERROR_VALIDATION_FAILURE,
        xr::Result::ERROR_ACTIONSETS_ALREADY_ATTACHED,
        xr::Result::ERROR_ACTIONSET_NOT_ATTACHED,
        xr::Result::ERROR_PATH_INVALID,
        xr::Result::ERROR_SESSION_LOST,
        xr::Result::ERROR_INSTANCE_LOST,
    ]
    .contains(&r)
}

/// The gaze source's per-instance part: the runtime's functions, the profile's paths, and fovea's
/// action set once made.
pub struct InstanceGaze {
    pub settings: GazeSettings,
    /// The application enabled XR_EXT_eye_gaze_interaction itself (else fovea did, on the copy).
    pub app_enabled: bool,
    instance: xr::Instance,
    calls: Calls,
    profile: xr::Path,
    pose_path: xr::Path,
    own: Mutex<Own>,
    /// A thread is making fovea's action set now, or the runtime refused it.
    creating: AtomicBool,
}

/// What the instance's suggestions and attaches left, under the instance's record lock.
#[derive(Default)]
struct Own {
    /// fovea's action set and its gaze action, once made.
    set: Option<(xr::ActionSet, xr::Action)>,
    /// The application's last suggestion for the eye gaze profile (it is replaced by the next).
    app_bindings: Vec<xr::ActionSuggestedBinding>,
    /// The suggestion in force for the profile binds fovea's action.
    ours_in_force: bool,
    /// A session of the instance has action sets attached: suggestions are refused from now on.
    attached: bool,
    /// The runtime refused fovea's binding merged into the application's suggestion: fovea does
    /// not suggest again (that would drop what the application chained to its own).
    refused: bool,
}

impl InstanceGaze {
    /// The per-instance part for a new instance on which the extension is enabled, or why not.
    ///
    /// # Safety
    /// `gipa` must be the next layer's `xrGetInstanceProcAddr` and `instance` its live instance.
    pub unsafe fn new(
        gipa: xr::pfn::GetInstanceProcAddr,
        instance: xr::Instance,
        settings: GazeSettings,
        app_enabled: bool,
    ) -> Result<InstanceGaze, &'static str> {
        // SAFETY: the caller's contract.
        let calls = unsafe { Calls::load(gipa, instance) }
            .ok_or("the runtime lacks a function of the action system")?;
        let path = |s: &CStr| {
            let mut p = xr::Path::NULL;
            // SAFETY: a live instance, a NUL-terminated well-formed path and a live output.
            let r = unsafe { (calls.string_to_path)(instance, s.as_ptr(), &mut p) };
            ok("xrStringToPath", r).ok()?;
            (p != xr::Path::NULL).then_some(p)
        };
        let (Some(profile), Some(pose_path)) = (path(PROFILE), path(GAZE_POSE)) else {
            return Err("the runtime refused the eye gaze profile's paths");
        };
        Ok(InstanceGaze {
            settings,
            app_enabled,
            instance,
            calls,
            profile,
            pose_path,
            own: Mutex::new(Own::default()),
            creating: AtomicBool::new(false),
        })
    }

    /// The interaction profile's path.
    pub fn profile(&self) -> xr::Path {
        self.profile
    }

    /// Whether `system` has an eye tracker (`supportsEyeGazeInteraction`), from fovea's own
    /// `xrGetSystemProperties`.
    pub fn supported(&self, system: xr::SystemId) -> Result<bool, xr::Result> {
        let mut eye = xr::SystemEyeGazeInteractionPropertiesEXT {
            ty: xr::StructureType::SYSTEM_EYE_GAZE_INTERACTION_PROPERTIES_EXT,
            next: std::ptr::null_mut(),
            supports_eye_gaze_interaction: xr::FALSE,
        };
        let mut props = xr::SystemProperties {
            ty: xr::StructureType::SYSTEM_PROPERTIES,
            next: &mut eye as *mut _ as *mut c_void,
            system_id: xr::SystemId::NULL,
            vendor_id: 0,
            system_name: [0; xr::MAX_SYSTEM_NAME_SIZE],
            graphics_properties: xr::SystemGraphicsProperties {
                max_swapchain_image_height: 0,
                max_swapchain_image_width: 0,
                max_layer_count: 0,
            },
            tracking_properties: xr::SystemTrackingProperties {
                orientation_tracking: xr::FALSE,
                position_tracking: xr::FALSE,
            },
        };
        // SAFETY: a live instance, the system the application's session was created for, and
        // fovea's own output structs, chained as the extension defines.
        let r = unsafe { (self.calls.get_system_properties)(self.instance, system, &mut props) };
        ok("xrGetSystemProperties", r)?;
        Ok(eye.supports_eye_gaze_interaction != xr::FALSE)
    }

    /// fovea's action set and gaze action, made at the first call.
    fn own_action(&self) -> Result<(xr::ActionSet, xr::Action), xr::Result> {
        if let Some(set) = self.own.lock().set {
            return Ok(set);
        }
        // Sessions of one instance are made one at a time in practice; should two threads get
        // here at once, only one makes the set (a second set of the same name would be refused),
        // and the other session goes without gaze.
        if self.creating.swap(true, AcqRel) {
            return Err(xr::Result::ERROR_CALL_ORDER_INVALID);
        }
        let made = self.make_action();
        if let Ok(set) = made {
            self.own.lock().set = Some(set);
            self.creating.store(false, Release);
        }
        // After a refusal `creating` stays set: the instance is not asked again (a set the runtime
        // made before refusing the action would make a second one of the same name fail).
        made
    }

    /// Creates fovea's action set and its gaze action.
    fn make_action(&self) -> Result<(xr::ActionSet, xr::Action), xr::Result> {
        let mut info = xr::ActionSetCreateInfo {
            ty: xr::StructureType::ACTION_SET_CREATE_INFO,
            next: std::ptr::null(),
            action_set_name: [0; xr::MAX_ACTION_SET_NAME_SIZE],
            localized_action_set_name: [0; xr::MAX_LOCALIZED_ACTION_SET_NAME_SIZE],
            priority: 0,
        };
        ffi::write_fixed(&mut info.action_set_name, "fovea_layer_eye_gaze");
        ffi::write_fixed(&mut info.localized_action_set_name, "fovea eye gaze");
        let mut set = xr::ActionSet::NULL;
        // SAFETY: a live instance, fovea's own create info with well-formed names, a live output.
        let r = unsafe { (self.calls.create_action_set)(self.instance, &info, &mut set) };
        ok("xrCreateActionSet", r)?;
        let mut info = xr::ActionCreateInfo {
            ty: xr::StructureType::ACTION_CREATE_INFO,
            next: std::ptr::null(),
            action_name: [0; xr::MAX_ACTION_NAME_SIZE],
            action_type: xr::ActionType::POSE_INPUT,
            count_subaction_paths: 0,
            subaction_paths: std::ptr::null(),
            localized_action_name: [0; xr::MAX_LOCALIZED_ACTION_NAME_SIZE],
        };
        ffi::write_fixed(&mut info.action_name, "gaze");
        ffi::write_fixed(&mut info.localized_action_name, "fovea gaze");
        let mut action = xr::Action::NULL;
        // SAFETY: fovea's own live set and create info, a live output.
        let r = unsafe { (self.calls.create_action)(set, &info, &mut action) };
        ok("xrCreateAction", r)?;
        Ok((set, action))
    }

    /// The gaze source of a new session on `system`, or `None` (logged once) where it cannot be had.
    pub fn session(&self, session: xr::Session, system: xr::SystemId) -> Option<SessionGaze> {
        match self.supported(system) {
            Ok(true) => {}
            Ok(false) => {
                tracing::info!(
                    target: TARGET,
                    "the runtime offers XR_EXT_eye_gaze_interaction but this system has no eye \
                     tracker (supportsEyeGazeInteraction is false): fixed foveation"
                );
                return None;
            }
            Err(r) => {
                tracing::warn!(
                    target: TARGET,
                    ?r,
                    "the runtime refused fovea's xrGetSystemProperties for eye gaze: fixed foveation"
                );
                return None;
            }
        }
        match self.own_action() {
            Ok((_, action)) => Some(SessionGaze::new(session, self.calls, action, self.settings)),
            Err(r) => {
                tracing::warn!(
                    target: TARGET,
                    ?r,
                    "the runtime refused fovea's eye gaze action: fixed foveation"
                );
                None
            }
        }
    }

    /// `xrSuggestInteractionProfileBindings` for the eye gaze profile: remembers the application's
    /// bindings and sends down a copy with fovea's own added, where fovea has its action and no set
    /// is attached yet; else the application's as they are. `down` makes the next layer's call.
    ///
    /// # Safety
    /// `info` must be the application's valid suggestion for [`InstanceGaze::profile`].
    pub unsafe fn suggest(
        &self,
        info: &xr::InteractionProfileSuggestedBinding,
        down: impl Fn(&xr::InteractionProfileSuggestedBinding) -> xr::Result,
    ) -> xr::Result {
        // An empty or NULL list is the application's error: it goes down as it is.
        let app: &[xr::ActionSuggestedBinding] = match info.count_suggested_bindings {
            _ if info.suggested_bindings.is_null() => return down(info),
            0 => return down(info),
            // SAFETY: the caller's contract: a valid suggestion has `countSuggestedBindings`
            // bindings at `suggestedBindings`.
            n => unsafe { std::slice::from_raw_parts(info.suggested_bindings, n as usize) },
        };
        // The application suggests for the eye gaze profile: fovea's action is made now if it is
        // not yet, so its binding joins this suggestion with the application's own chain.
        let action = if self.own.lock().set.is_none() {
            self.own_action().ok().map(|(_, a)| a)
        } else {
            self.own.lock().set.map(|(_, a)| a)
        };
        let merged = {
            let own = self.own.lock();
            match action {
                Some(action) if !own.attached && !own.refused => Some(self.with_ours(app, action)),
                _ => None,
            }
        };
        let (r, ours) = match merged {
            Some(merged) => {
                let copy = xr::InteractionProfileSuggestedBinding {
                    count_suggested_bindings: merged.len() as u32,
                    suggested_bindings: merged.as_ptr(),
                    ..*info
                };
                match down(&copy) {
                    r if succeeded(r) => (r, true),
                    r if app_caused(r) => (r, false),
                    refused => {
                        // Refused with fovea's binding: the application's own call decides.
                        let again = down(info);
                        if succeeded(again) {
                            self.own.lock().refused = true;
                            tracing::warn!(
                                target: TARGET,
                                r = ?refused,
                                "the runtime refused fovea's eye gaze binding merged into the \
                                 application's: fixed foveation"
                            );
                        }
                        (again, false)
                    }
                }
            }
            None => (down(info), false),
        };
        // Only a suggestion the runtime took replaces the one in force, and is suggested again with
        // fovea's binding at the attach.
        if succeeded(r) {
            let mut own = self.own.lock();
            own.app_bindings = app.to_vec();
            own.ours_in_force = ours;
        }
        r
    }

    /// `app` with fovea's binding added.
    fn with_ours(
        &self,
        app: &[xr::ActionSuggestedBinding],
        action: xr::Action,
    ) -> Vec<xr::ActionSuggestedBinding> {
        let mut list = Vec::with_capacity(app.len() + 1);
        list.extend_from_slice(app);
        list.push(xr::ActionSuggestedBinding {
            action,
            binding: self.pose_path,
        });
        list
    }

    /// Makes sure the suggestion in force binds fovea's action: suggests the application's last
    /// bindings with fovea's, unless that is already so.
    fn suggest_ours(&self, action: xr::Action) -> Result<(), xr::Result> {
        let list = {
            let own = self.own.lock();
            if own.ours_in_force {
                return Ok(());
            }
            if own.refused {
                return Err(xr::Result::ERROR_PATH_UNSUPPORTED);
            }
            // Only where the application suggested nothing for the profile (else its suggestion
            // carried fovea's binding): nothing of the application's is replaced.
            self.with_ours(&own.app_bindings, action)
        };
        let info = xr::InteractionProfileSuggestedBinding {
            ty: xr::StructureType::INTERACTION_PROFILE_SUGGESTED_BINDING,
            next: std::ptr::null(),
            interaction_profile: self.profile,
            count_suggested_bindings: list.len() as u32,
            suggested_bindings: list.as_ptr(),
        };
        // SAFETY: a live instance and fovea's own suggestion of live actions.
        let r = unsafe { (self.calls.suggest)(self.instance, &info) };
        ok("xrSuggestInteractionProfileBindings", r)?;
        self.own.lock().ours_in_force = true;
        Ok(())
    }

    /// `xrAttachSessionActionSets` by the application: suggests fovea's binding if needed, then
    /// sends down a copy of the application's list with fovea's set appended, and makes the
    /// session's gaze spaces once it is attached. `down` makes the next layer's call.
    ///
    /// # Safety
    /// `info` must be the application's valid attach info.
    pub unsafe fn attach(
        &self,
        g: &SessionGaze,
        info: &xr::SessionActionSetsAttachInfo,
        down: impl Fn(&xr::SessionActionSetsAttachInfo) -> xr::Result,
    ) -> xr::Result {
        let app: &[xr::ActionSet] = match info.count_action_sets {
            _ if info.action_sets.is_null() => return down(info),
            // SAFETY: the caller's contract: `countActionSets` sets at `actionSets`.
            n => unsafe { std::slice::from_raw_parts(info.action_sets, n as usize) },
        };
        if app.is_empty() {
            return down(info);
        }
        // The claim: the application's attach and fovea's alone race for one session; exactly
        // one wins. Lost to fovea's alone attach (an opt-in), the application's goes down as it
        // made it once fovea's has reached the runtime (never before it: the runtime would then
        // refuse fovea's instead), and the runtime answers it as it answers a second attach.
        let claimed = loop {
            match g.claim.compare_exchange(OPEN, BY_APP, AcqRel, Acquire) {
                // fovea's attach is on its way down (a few runtime calls, once a session).
                Err(FOVEA_ATTACHING) => std::thread::yield_now(),
                other => break other,
            }
        };
        match claimed {
            Ok(_) => {}
            Err(BY_FOVEA) => {
                tracing::warn!(
                    target: TARGET,
                    "the application attaches its action sets after fovea attached its own alone \
                     (gaze_attach_after_s): the runtime refuses a second attach; set \
                     gaze_attach_after_s = \"never\" for this application \
                     (docs/eye-tracking.md#applications-that-do-not-cooperate)"
                );
                return down(info);
            }
            Err(_) => return down(info),
        }
        if g.phase.load(Acquire) != WAITING {
            return down(info);
        }
        let Ok((set, action)) = self.own_action() else {
            return down(info);
        };
        if let Err(r) = self.suggest_ours(action) {
            g.fail(r, "the runtime refused fovea's eye gaze binding");
            return down(info);
        }
        let mut sets = Vec::with_capacity(app.len() + 1);
        sets.extend_from_slice(app);
        sets.push(set);
        let copy = xr::SessionActionSetsAttachInfo {
            count_action_sets: sets.len() as u32,
            action_sets: sets.as_ptr(),
            ..*info
        };
        let r = down(&copy);
        if succeeded(r) {
            self.own.lock().attached = true;
            g.attached(set);
            return r;
        }
        if app_caused(r) {
            // Refused for the application's own part: it may attach again, with fovea's set.
            g.claim.store(OPEN, Release);
            return r;
        }
        // Refused with fovea's set: the application's own list decides what it gets.
        let again = down(info);
        if succeeded(again) {
            g.fail(
                r,
                "the runtime refused fovea's eye gaze set in the application's attach",
            );
        }
        again
    }

    /// Attaches fovea's set alone, for an application that has not attached any in the grace
    /// period.
    pub fn attach_alone(&self, g: &SessionGaze) {
        if g.phase.load(Acquire) != WAITING {
            return;
        }
        // The claim (see `attach`): an application attach in flight or done wins; one that
        // comes while fovea's is on its way down waits for it.
        if g.claim
            .compare_exchange(OPEN, FOVEA_ATTACHING, AcqRel, Acquire)
            .is_err()
        {
            return;
        }
        // Nothing of fovea's attached: the application's attach goes down as it made it.
        let unclaim = || g.claim.store(OPEN, Release);
        let (set, action) = match self.own_action() {
            Ok(made) => made,
            Err(r) => {
                g.fail(r, "fovea could not make its eye gaze action set");
                unclaim();
                return;
            }
        };
        if let Err(r) = self.suggest_ours(action) {
            g.fail(r, "the runtime refused fovea's eye gaze binding");
            unclaim();
            return;
        }
        let info = xr::SessionActionSetsAttachInfo {
            ty: xr::StructureType::SESSION_ACTION_SETS_ATTACH_INFO,
            next: std::ptr::null(),
            count_action_sets: 1,
            action_sets: &set,
        };
        // SAFETY: a live session and fovea's own set.
        let r = unsafe { (self.calls.attach)(g.session, &info) };
        if let Err(r) = ok("xrAttachSessionActionSets", r) {
            g.fail(
                r,
                "the runtime refused to attach fovea's eye gaze action set",
            );
            unclaim();
            return;
        }
        g.claim.store(BY_FOVEA, Release);
        tracing::info!(
            target: TARGET,
            after_s = ?self.settings.attach_after_s,
            "the application attached no action set in the grace period (gaze_attach_after_s); \
             fovea attached its own for eye gaze (an attach by the application from now on fails: \
             see docs/eye-tracking.md#applications-that-do-not-cooperate)"
        );
        self.own.lock().attached = true;
        g.attached(set);
    }
}

/// Whether an extension list names XR_EXT_eye_gaze_interaction.
pub fn listed(names: impl IntoIterator<Item = impl AsRef<CStr>>) -> bool {
    names.into_iter().any(|n| n.as_ref() == EXTENSION)
}

/// The name to add to the copy of the create info.
pub fn name_ptr() -> *const c_char {
    EXTENSION.as_ptr()
}
