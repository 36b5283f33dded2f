//! The runtime's objects, all in one map-of-maps behind one lock, and the per-call bookkeeping every
//! entry point shares: handle resolution, injected faults, lost objects and the journal.
//!
//! One lock keeps parent/child invariants (a session's swapchains, an instance's sessions) trivially
//! consistent. Nothing calls back into the application while it is held except Vulkan commands on
//! objects the runtime owns; calls through application-provided function pointers
//! (xrCreateVulkanInstanceKHR/DeviceKHR) and real-time sleeps happen with the lock released.

use std::collections::{BTreeMap, HashMap};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::LazyLock;

use openxr_sys as xr;
use openxr_sys::Handle;
use parking_lot::{Condvar, Mutex, MutexGuard};

use crate::objects::{
    Action, ActionSet, Call, CreatedInstance, InstanceState, Profile, Record, Session, Space,
    Swapchain,
};

/// `Ok` carries a success code (XR_SUCCESS, XR_FRAME_DISCARDED, ...), `Err` an error code, so
/// implementations can use `?` on validation.
pub(crate) type XrResult = Result<xr::Result, xr::Result>;

#[derive(Default)]
pub(crate) struct World {
    next_handle: u64,
    pub instances: HashMap<u64, InstanceState>,
    pub sessions: HashMap<u64, Session>,
    pub swapchains: HashMap<u64, Swapchain>,
    pub spaces: HashMap<u64, Space>,
    pub action_sets: HashMap<u64, ActionSet>,
    pub actions: HashMap<u64, Action>,
    pub profiles: HashMap<u64, Profile>,
    /// Records of destroyed instances, so tests can read the journal after teardown.
    pub retired: HashMap<u64, Record>,
    /// Every instance created in this process, in order: what a layer above created on its own
    /// shows here beside the application's.
    pub created: Vec<CreatedInstance>,
    /// Refusals of calls that belong to no instance (an `xrCreateInstance` refused), by command: an
    /// instance's own are in its [`Record`].
    pub refusals_without_instance: BTreeMap<&'static str, u64>,
}

static WORLD: LazyLock<Mutex<World>> = LazyLock::new(|| Mutex::new(World::default()));

pub(crate) fn world() -> MutexGuard<'static, World> {
    WORLD.lock()
}

/// Signalled whenever a waited frame stops blocking the next xrWaitFrame (xrBeginFrame consumed it,
/// or its session stopped running or went away); waited on with the [`world`] lock.
static FRAME_BEGUN: Condvar = Condvar::new();

/// Wakes the xrWaitFrame calls blocked on a frame that is not yet begun (see [`wait_frame_begun`]).
pub(crate) fn notify_frame_begun() {
    FRAME_BEGUN.notify_all();
}

/// Releases the world lock until [`notify_frame_begun`] or `deadline`; false on timeout.
pub(crate) fn wait_frame_begun(
    w: &mut MutexGuard<'static, World>,
    deadline: std::time::Instant,
) -> bool {
    !FRAME_BEGUN.wait_until(w, deadline).timed_out()
}

/// One call in progress: which instance it belongs to (once the handle is resolved) and what it
/// will put in the journal.
pub(crate) struct Ctx {
    pub name: &'static str,
    instance: Option<u64>,
    /// Destroy commands must work on lost objects (the app has to clean up).
    pub allow_lost: bool,
    pub next_types: Vec<xr::StructureType>,
    pub detail: String,
    /// The result comes from an injected fault, not from the runtime's own checks.
    injected: bool,
}

impl Ctx {
    /// Attributes a call that creates its instance (xrCreateInstance) once the handle exists.
    pub fn set_instance(&mut self, id: u64) {
        self.instance = Some(id);
    }

    /// The call fails by an injected fault, not by the runtime's own checks.
    pub fn set_injected(&mut self) {
        self.injected = true;
    }
}

/// Runs one entry point: catches panics (they must not cross the FFI boundary; the spec's catch-all
/// is XR_ERROR_RUNTIME_FAILURE) and journals the call under its instance.
pub(crate) fn entry(name: &'static str, body: impl FnOnce(&mut Ctx) -> XrResult) -> xr::Result {
    let mut ctx = Ctx {
        name,
        instance: None,
        allow_lost: false,
        next_types: Vec::new(),
        detail: String::new(),
        injected: false,
    };
    let result = match catch_unwind(AssertUnwindSafe(|| body(&mut ctx))) {
        Ok(Ok(r) | Err(r)) => r,
        Err(_) => xr::Result::ERROR_RUNTIME_FAILURE,
    };
    let refused = result.into_raw() < 0 && !ctx.injected;
    if ctx.instance.is_none() && refused {
        let _ = catch_unwind(AssertUnwindSafe(|| {
            *world().refusals_without_instance.entry(name).or_default() += 1;
        }));
    }
    if let Some(id) = ctx.instance {
        let call = Call {
            function: name,
            result,
            next_types: ctx.next_types,
            detail: ctx.detail,
            refused,
        };
        let _ = catch_unwind(AssertUnwindSafe(|| {
            let mut w = world();
            let keep = w.instances.get(&id).is_none_or(|i| i.config.journal);
            if refused && w.instances.get(&id).is_some_and(|i| i.config.log_refusals) {
                eprintln!(
                    "fovea-sim: refused {name}: XR_{result:?} ({})",
                    if call.detail.is_empty() {
                        "no detail"
                    } else {
                        &call.detail
                    }
                );
            }
            if let Some(record) = w.record_mut(id) {
                if result.into_raw() < 0 {
                    *record.errors.entry(name).or_default() += 1;
                }
                if refused {
                    *record.refusals.entry(name).or_default() += 1;
                }
                if keep {
                    record.journal.push(call);
                }
            }
        }));
    }
    result
}

impl World {
    pub fn alloc_handle(&mut self) -> u64 {
        // Handles are unique across all object types, so a handle of the wrong type is always
        // detected as invalid.
        self.next_handle += 1;
        0x5100_0000 + self.next_handle
    }

    pub fn record_mut(&mut self, id: u64) -> Option<&mut Record> {
        match self.instances.get_mut(&id) {
            Some(inst) => Some(&mut inst.record),
            None => self.retired.get_mut(&id),
        }
    }

    pub fn record(&self, id: u64) -> Option<&Record> {
        self.instances
            .get(&id)
            .map(|i| &i.record)
            .or_else(|| self.retired.get(&id))
    }

    /// Resolves an instance handle, counts the call, applies injected faults and loss.
    pub fn enter_instance(
        &mut self,
        ctx: &mut Ctx,
        instance: xr::Instance,
    ) -> Result<u64, xr::Result> {
        let id = instance.into_raw();
        if !self.instances.contains_key(&id) {
            return Err(xr::Result::ERROR_HANDLE_INVALID);
        }
        self.enter(ctx, id, None)?;
        Ok(id)
    }

    pub fn enter_session(
        &mut self,
        ctx: &mut Ctx,
        session: xr::Session,
    ) -> Result<u64, xr::Result> {
        let id = session.into_raw();
        let instance = self
            .sessions
            .get(&id)
            .ok_or(xr::Result::ERROR_HANDLE_INVALID)?
            .instance;
        self.enter(ctx, instance, Some(id))?;
        Ok(id)
    }

    pub fn enter_swapchain(
        &mut self,
        ctx: &mut Ctx,
        swapchain: xr::Swapchain,
    ) -> Result<u64, xr::Result> {
        let id = swapchain.into_raw();
        let session = self
            .swapchains
            .get(&id)
            .ok_or(xr::Result::ERROR_HANDLE_INVALID)?
            .session;
        let instance = self.sessions[&session].instance;
        self.enter(ctx, instance, Some(session))?;
        Ok(id)
    }

    pub fn enter_space(&mut self, ctx: &mut Ctx, space: xr::Space) -> Result<u64, xr::Result> {
        let id = space.into_raw();
        let session = self
            .spaces
            .get(&id)
            .ok_or(xr::Result::ERROR_HANDLE_INVALID)?
            .session;
        let instance = self.sessions[&session].instance;
        self.enter(ctx, instance, Some(session))?;
        Ok(id)
    }

    pub fn enter_action_set(
        &mut self,
        ctx: &mut Ctx,
        set: xr::ActionSet,
    ) -> Result<u64, xr::Result> {
        let id = set.into_raw();
        let instance = self
            .action_sets
            .get(&id)
            .ok_or(xr::Result::ERROR_HANDLE_INVALID)?
            .instance;
        self.enter(ctx, instance, None)?;
        Ok(id)
    }

    pub fn enter_action(&mut self, ctx: &mut Ctx, action: xr::Action) -> Result<u64, xr::Result> {
        let id = action.into_raw();
        let instance = self
            .actions
            .get(&id)
            .ok_or(xr::Result::ERROR_HANDLE_INVALID)?
            .instance;
        self.enter(ctx, instance, None)?;
        Ok(id)
    }

    fn enter(
        &mut self,
        ctx: &mut Ctx,
        instance: u64,
        session: Option<u64>,
    ) -> Result<(), xr::Result> {
        ctx.instance = Some(instance);
        let inst = self
            .instances
            .get_mut(&instance)
            .ok_or(xr::Result::ERROR_HANDLE_INVALID)?;
        let count = inst.call_counts.entry(ctx.name).or_insert(0);
        *count += 1;
        let count = *count;
        if inst.lost && !ctx.allow_lost {
            return Err(xr::Result::ERROR_INSTANCE_LOST);
        }
        if let Some(s) = session {
            if self.sessions[&s].lost && !ctx.allow_lost {
                return Err(xr::Result::ERROR_SESSION_LOST);
            }
        }
        let fault = inst
            .faults
            .iter()
            .find(|f| f.function == ctx.name && (f.nth == 0 || f.nth == count));
        let Some(result) = fault.map(|f| f.result) else {
            return Ok(());
        };
        ctx.detail = format!("injected fault {result:?} on call {count}");
        ctx.injected = true;
        // A real runtime that reports a lost object keeps reporting it (spec: "Session Lost",
        // "Instance Lost"), so the fault sticks.
        if result == xr::Result::ERROR_INSTANCE_LOST {
            inst.lost = true;
        }
        if result == xr::Result::ERROR_SESSION_LOST {
            for (id, s) in self.sessions.iter_mut() {
                if s.instance == instance && session.is_none_or(|only| only == *id) {
                    s.lost = true;
                }
            }
        }
        Err(result)
    }

    pub fn live_objects(&self) -> usize {
        self.instances.len() + self.sessions.len() + self.swapchains.len() + self.spaces.len()
    }
}
