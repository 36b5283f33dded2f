//! Random call sequences through the fake loader, fovea and the simulated runtime (headless
//! sessions), checked call by call against a small reference model of the live handles.
//!
//! The model is exact for what fovea implements itself (XR_FB_foveation profiles and
//! XR_FB_swapchain_update_state): every result, the profile handle xrGetSwapchainStateFB reads, and
//! that a destroyed parent takes its children along. For what fovea passes on (sessions,
//! swapchains, frames, images) the runtime is the reference: a call on a live handle must reach the
//! runtime exactly once and hand the application the result the runtime journaled; a call on a
//! destroyed, foreign-type or random handle must be XR_ERROR_HANDLE_INVALID without reaching the
//! runtime. Inputs include NULL pointers, wrong structure types, bad enums, NaN and infinite offsets,
//! next chains that are empty, loop, repeat a struct, hold structs of the wrong type or are longer
//! than fovea follows, and absurd capacities and sizes.
//!
//! At the end of each case every instance is destroyed; then every handle the case ever saw must be
//! invalid in the layer (so no record leaked in fovea's registry, which lives in the loaded
//! libfovea.so and is not reachable from here) and the runtime must hold no object.
//!
//! `FOVEA_FUZZ_CASES=N` runs N cases instead of 64 (docs/hardening.md). This module holds a single
//! test, in a process of its own: the runtime's object count is process-wide, and it sets the
//! layer's log filter.

use std::collections::BTreeMap;
use std::ffi::c_void;
use std::ptr::{null, null_mut};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use fovea_harness::app::{with_create_info, API_1_0};
use fovea_harness::fns::Fns;
use fovea_harness::frame_loop::FOVEATION_EXTENSIONS;
use fovea_harness::{lookup, sim, Chain};
use openxr_sys as xr;
use proptest::prelude::*;
use xr::Handle;

use crate::support::in_own_process;

/// Calls made into the layer, over all cases.
static CALLS: AtomicU64 = AtomicU64::new(0);
/// How often each function returned each result, over all cases: shows the sequences reach the
/// successful paths, not only the early errors.
static RESULTS: Mutex<BTreeMap<(&'static str, i32), u64>> = Mutex::new(BTreeMap::new());

fn tally(name: &'static str, r: xr::Result) {
    CALLS.fetch_add(1, Ordering::Relaxed);
    *RESULTS
        .lock()
        .unwrap()
        .entry((name, r.into_raw()))
        .or_default() += 1;
}

/// The most instances alive at once (each costs a layer record and a runtime instance).
const MAX_INSTANCES: usize = 3;
/// The longest chain fovea follows (`fovea_abi::MAX_CHAIN_LENGTH`).
const MAX_CHAIN: usize = fovea_abi::MAX_CHAIN_LENGTH;

// ---------------------------------------------------------------------------------------------
// What a sequence is made of.

/// How an operation names a handle.
#[derive(Clone, Debug)]
enum Pick {
    /// A live one, by index modulo the count (any the case created when none lives).
    Live(u8),
    /// One the case created (live or destroyed), by index modulo the count.
    Ever(u8),
    /// One the case created, of another handle type.
    OtherType(u8),
    /// Any value: random, or near the runtime's and fovea's handle ranges.
    Raw(u64),
    Null,
}

fn pick() -> impl Strategy<Value = Pick> {
    prop_oneof![
        10 => any::<u8>().prop_map(Pick::Live),
        3 => any::<u8>().prop_map(Pick::Ever),
        1 => any::<u8>().prop_map(Pick::OtherType),
        1 => prop_oneof![
            any::<u64>(),
            (0u64..400).prop_map(|n| 0x5100_0000 + n),
            (0u64..400).prop_map(|n| 0xF0FE_A000_0000_0001 + n),
        ]
        .prop_map(Pick::Raw),
        1 => Just(Pick::Null),
    ]
}

/// One struct of a next chain. Every node is built in a 64-byte buffer, so a struct of the wrong
/// type is still readable as any struct fovea knows.
#[derive(Clone, Debug)]
enum Node {
    Level {
        level: i32,
        dynamic: i32,
        offset: f32,
    },
    SwapchainFoveation {
        flags: u64,
    },
    Unknown(i32),
}

/// A next chain: its nodes, an optional loop from the last node back to an earlier one, and
/// unknown structs appended (more than fovea follows, sometimes).
#[derive(Clone, Debug)]
struct ChainSpec {
    nodes: Vec<Node>,
    loop_to: Option<usize>,
    padding: usize,
}

fn offset() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => -60.0f32..60.0,
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => Just(f32::NEG_INFINITY),
        1 => any::<f32>(),
    ]
}

fn node() -> impl Strategy<Value = Node> {
    prop_oneof![
        4 => (prop_oneof![4 => 0i32..=3, 1 => any::<i32>()],
              prop_oneof![4 => 0i32..=1, 1 => any::<i32>()],
              offset())
            .prop_map(|(level, dynamic, offset)| Node::Level { level, dynamic, offset }),
        2 => prop_oneof![Just(0u64), Just(1), Just(2), Just(3), any::<u64>()]
            .prop_map(|flags| Node::SwapchainFoveation { flags }),
        2 => prop_oneof![Just(42i32), Just(1000227000), any::<i32>()].prop_map(Node::Unknown),
    ]
}

fn chain_spec() -> impl Strategy<Value = ChainSpec> {
    (
        prop::collection::vec(node(), 0..4),
        prop_oneof![6 => Just(None), 1 => any::<u8>().prop_map(Some)],
        prop_oneof![8 => Just(0usize), 1 => 60usize..70],
    )
        .prop_map(|(nodes, lp, padding)| {
            let loop_to = lp.filter(|_| !nodes.is_empty() || padding > 0);
            let len = nodes.len() + padding;
            ChainSpec {
                nodes,
                loop_to: loop_to.map(|l| l as usize % len.max(1)),
                padding,
            }
        })
}

/// Node storage: 8 words, 8-byte aligned.
type Slot = [u64; 8];

impl ChainSpec {
    /// Builds the chain in `slots`; returns its head (NULL for an empty chain).
    fn build(&self, slots: &mut Vec<Slot>) -> *mut c_void {
        let unknown = Node::Unknown(7);
        let all: Vec<&Node> = self
            .nodes
            .iter()
            .chain(std::iter::repeat_n(&unknown, self.padding))
            .collect();
        *slots = vec![[0u64; 8]; all.len()];
        let base = slots.as_mut_ptr();
        for (i, n) in all.iter().enumerate() {
            // SAFETY: each slot is 64 bytes, larger than every struct written into it.
            unsafe {
                let p = base.add(i) as *mut c_void;
                match n {
                    Node::Level {
                        level,
                        dynamic,
                        offset,
                    } => {
                        *(p as *mut xr::FoveationLevelProfileCreateInfoFB) =
                            xr::FoveationLevelProfileCreateInfoFB {
                                ty: xr::StructureType::FOVEATION_LEVEL_PROFILE_CREATE_INFO_FB,
                                next: null_mut(),
                                level: xr::FoveationLevelFB::from_raw(*level),
                                vertical_offset: *offset,
                                dynamic: xr::FoveationDynamicFB::from_raw(*dynamic),
                            }
                    }
                    Node::SwapchainFoveation { flags } => {
                        *(p as *mut xr::SwapchainCreateInfoFoveationFB) =
                            xr::SwapchainCreateInfoFoveationFB {
                                ty: xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
                                next: null_mut(),
                                flags: xr::SwapchainCreateFoveationFlagsFB::from_raw(*flags),
                            }
                    }
                    Node::Unknown(t) => {
                        *(p as *mut xr::BaseOutStructure) = xr::BaseOutStructure {
                            ty: xr::StructureType::from_raw(*t),
                            next: null_mut(),
                        }
                    }
                }
            }
        }
        for i in 0..all.len() {
            let next = if i + 1 < all.len() {
                unsafe { base.add(i + 1) as *mut xr::BaseOutStructure }
            } else {
                match self.loop_to {
                    Some(k) => unsafe { base.add(k) as *mut xr::BaseOutStructure },
                    None => null_mut(),
                }
            };
            unsafe { (*(base.add(i) as *mut xr::BaseOutStructure)).next = next };
        }
        if all.is_empty() {
            null_mut()
        } else {
            base as *mut c_void
        }
    }

    fn len(&self) -> usize {
        self.nodes.len() + self.padding
    }

    /// What fovea's bounded search finds: `Ok(Some(i))` for the first node `want` selects,
    /// `Ok(None)` when there is none, `Err` when the search gives up (a loop, or a chain longer than
    /// fovea follows).
    fn find(&self, want: impl Fn(&Node) -> bool) -> Result<Option<usize>, ()> {
        let i = self.nodes.iter().position(want);
        match i {
            Some(i) if i < MAX_CHAIN => Ok(Some(i)),
            _ if self.loop_to.is_some() || self.len() > MAX_CHAIN => Err(()),
            _ => Ok(None),
        }
    }

    /// Whether fovea walks the whole chain without giving up.
    fn walkable(&self) -> bool {
        self.loop_to.is_none() && self.len() <= MAX_CHAIN
    }
}

/// How an input struct pointer is passed.
#[derive(Clone, Copy, Debug)]
enum Ptr {
    Valid,
    Null,
    WrongType,
    /// The output handle pointer is NULL (create functions only).
    NullOut,
}

fn ptr() -> impl Strategy<Value = Ptr> {
    prop_oneof![
        12 => Just(Ptr::Valid),
        1 => Just(Ptr::Null),
        1 => Just(Ptr::WrongType),
        1 => Just(Ptr::NullOut),
    ]
}

#[derive(Clone, Debug)]
enum Op {
    CreateInstance,
    DestroyInstance(Pick),
    CreateSession(Pick, Ptr),
    DestroySession(Pick),
    BeginSession(Pick),
    CreateSwapchain {
        session: Pick,
        info: Ptr,
        chain: ChainSpec,
        width: u32,
    },
    DestroySwapchain(Pick),
    CreateProfile {
        session: Pick,
        info: Ptr,
        chain: ChainSpec,
    },
    DestroyProfile(Pick),
    Update {
        swapchain: Pick,
        state: Ptr,
        flags: u64,
        profile: Pick,
    },
    GetState(Pick, Ptr),
    WaitFrame(Pick, bool),
    BeginFrame(Pick, bool),
    EndFrame(Pick, Option<Pick>),
    LocateViews(Pick, u32, bool),
    Acquire(Pick),
    WaitImage(Pick),
    Release(Pick),
    EnumerateImages(Pick, u32, bool),
    /// A whole frame on a session: wait, begin, locate, one image of a swapchain, end with a
    /// projection layer on it at the predicted display time.
    Frame(Pick, Pick),
}

fn op() -> impl Strategy<Value = Op> {
    let capacity = prop_oneof![Just(0u32), Just(1), Just(2), Just(3), Just(u32::MAX)];
    prop_oneof![
        3 => Just(Op::CreateInstance),
        1 => pick().prop_map(Op::DestroyInstance),
        4 => (pick(), ptr()).prop_map(|(s, p)| Op::CreateSession(s, p)),
        1 => pick().prop_map(Op::DestroySession),
        3 => pick().prop_map(Op::BeginSession),
        6 => (pick(), ptr(), chain_spec(), prop_oneof![6 => Just(64u32), 1 => Just(0), 1 => Just(u32::MAX)])
            .prop_map(|(session, info, chain, width)| Op::CreateSwapchain { session, info, chain, width }),
        1 => pick().prop_map(Op::DestroySwapchain),
        6 => (pick(), ptr(), chain_spec())
            .prop_map(|(session, info, chain)| Op::CreateProfile { session, info, chain }),
        2 => pick().prop_map(Op::DestroyProfile),
        8 => (pick(), ptr(), prop_oneof![8 => Just(0u64), 1 => any::<u64>()], pick())
            .prop_map(|(swapchain, state, flags, profile)| Op::Update { swapchain, state, flags, profile }),
        4 => (pick(), ptr()).prop_map(|(s, p)| Op::GetState(s, p)),
        2 => (pick(), any::<bool>()).prop_map(|(s, n)| Op::WaitFrame(s, n)),
        2 => (pick(), any::<bool>()).prop_map(|(s, n)| Op::BeginFrame(s, n)),
        2 => (pick(), prop::option::of(pick())).prop_map(|(s, l)| Op::EndFrame(s, l)),
        2 => (pick(), capacity.clone(), any::<bool>()).prop_map(|(s, c, n)| Op::LocateViews(s, c, n)),
        1 => pick().prop_map(Op::Acquire),
        1 => pick().prop_map(Op::WaitImage),
        1 => pick().prop_map(Op::Release),
        1 => (pick(), capacity, any::<bool>()).prop_map(|(s, c, n)| Op::EnumerateImages(s, c, n)),
        4 => (pick(), pick()).prop_map(|(s, sc)| Op::Frame(s, sc)),
    ]
}

// ---------------------------------------------------------------------------------------------
// The reference model.

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Kind {
    Instance,
    Session,
    Swapchain,
    Profile,
}

struct Obj {
    raw: u64,
    live: bool,
    /// Session: its instance; swapchain and profile: their session (indices into the model).
    parent: usize,
    /// Swapchains: created with XrSwapchainCreateInfoFoveationFB.
    foveation: bool,
    /// Swapchains: the profile last applied.
    applied: Option<usize>,
    /// Sessions: their LOCAL space; swapchains: nothing.
    space: xr::Space,
}

#[derive(Default)]
struct Model {
    instances: Vec<Obj>,
    sessions: Vec<Obj>,
    swapchains: Vec<Obj>,
    profiles: Vec<Obj>,
}

impl Model {
    fn list(&self, k: Kind) -> &Vec<Obj> {
        match k {
            Kind::Instance => &self.instances,
            Kind::Session => &self.sessions,
            Kind::Swapchain => &self.swapchains,
            Kind::Profile => &self.profiles,
        }
    }

    /// The raw value a pick names.
    fn raw(&self, k: Kind, p: &Pick) -> u64 {
        let from = |l: &Vec<Obj>, i: u8| {
            if l.is_empty() {
                0xdead_0000 + u64::from(i)
            } else {
                l[i as usize % l.len()].raw
            }
        };
        match p {
            Pick::Live(i) => {
                let live: Vec<&Obj> = self.list(k).iter().filter(|o| o.live).collect();
                if live.is_empty() {
                    from(self.list(k), *i)
                } else {
                    live[*i as usize % live.len()].raw
                }
            }
            Pick::Ever(i) => from(self.list(k), *i),
            Pick::OtherType(i) => {
                let other = match k {
                    Kind::Instance => Kind::Session,
                    Kind::Session => Kind::Swapchain,
                    Kind::Swapchain => Kind::Profile,
                    Kind::Profile => Kind::Session,
                };
                from(self.list(other), *i)
            }
            Pick::Raw(v) => *v,
            Pick::Null => 0,
        }
    }

    /// The live object of kind `k` with this raw value.
    fn live(&self, k: Kind, raw: u64) -> Option<usize> {
        self.list(k).iter().position(|o| o.live && o.raw == raw)
    }

    fn instance_of_session(&self, s: usize) -> xr::Instance {
        xr::Instance::from_raw(self.instances[self.sessions[s].parent].raw)
    }

    fn instance_of_swapchain(&self, sc: usize) -> xr::Instance {
        self.instance_of_session(self.swapchains[sc].parent)
    }

    fn kill_session(&mut self, s: usize) {
        self.sessions[s].live = false;
        for sc in self.swapchains.iter_mut().filter(|o| o.parent == s) {
            sc.live = false;
        }
        for p in self.profiles.iter_mut().filter(|o| o.parent == s) {
            p.live = false;
        }
    }

    fn kill_instance(&mut self, i: usize) {
        self.instances[i].live = false;
        let sessions: Vec<usize> = (0..self.sessions.len())
            .filter(|s| self.sessions[*s].parent == i)
            .collect();
        for s in sessions {
            self.kill_session(s);
        }
    }

    fn live_instances(&self) -> Vec<xr::Instance> {
        self.instances
            .iter()
            .filter(|o| o.live)
            .map(|o| xr::Instance::from_raw(o.raw))
            .collect()
    }

    fn every_raw(&self) -> Vec<u64> {
        [
            &self.instances,
            &self.sessions,
            &self.swapchains,
            &self.profiles,
        ]
        .iter()
        .flat_map(|l| l.iter().map(|o| o.raw))
        .collect()
    }
}

fn obj(raw: u64, parent: usize) -> Obj {
    Obj {
        raw,
        live: true,
        parent,
        foveation: false,
        applied: None,
        space: xr::Space::NULL,
    }
}

/// The runtime's journal lengths for the live instances.
fn journal_lengths(model: &Model) -> Vec<usize> {
    model
        .live_instances()
        .into_iter()
        .map(|i| sim::control::journal(i).len())
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Running a sequence.

struct Runner<'a> {
    chain: &'a Chain,
    f: Fns,
    m: Model,
}

type Check = Result<(), TestCaseError>;

impl Runner<'_> {
    /// Runs a pass-through call on the object `target` (of instance `instance`) names: a live target
    /// reaches the runtime once and the application gets the runtime's result; anything else is
    /// XR_ERROR_HANDLE_INVALID and reaches nothing.
    fn through(
        &self,
        name: &'static str,
        target: Option<xr::Instance>,
        call: impl FnOnce() -> xr::Result,
    ) -> Result<xr::Result, TestCaseError> {
        let before = journal_lengths(&self.m);
        let mine = target.map(|i| sim::control::journal(i).len());
        let r = call();
        tally(name, r);
        match (target, mine) {
            (Some(i), Some(n)) => {
                let j = sim::control::journal(i);
                prop_assert_eq!(j.len(), n + 1, "{} did not reach the runtime once", name);
                let last = j.last().unwrap();
                prop_assert_eq!(last.function, name);
                prop_assert_eq!(last.result, r, "{}: the runtime's result was changed", name);
            }
            _ => {
                prop_assert_eq!(
                    r,
                    xr::Result::ERROR_HANDLE_INVALID,
                    "{} on a dead handle",
                    name
                );
                prop_assert_eq!(
                    journal_lengths(&self.m),
                    before,
                    "{} reached the runtime",
                    name
                );
            }
        }
        Ok(r)
    }

    fn layer_call(&self, name: &'static str, call: impl FnOnce() -> xr::Result) -> xr::Result {
        let r = call();
        tally(name, r);
        r
    }

    fn create_instance(&mut self) -> Check {
        if self.m.live_instances().len() >= MAX_INSTANCES {
            return Ok(());
        }
        let mut instance = xr::Instance::NULL;
        let r = with_create_info(&FOVEATION_EXTENSIONS, API_1_0, |info| unsafe {
            self.chain.create_instance(info, &mut instance)
        });
        tally("xrCreateInstance", r);
        prop_assert_eq!(r, xr::Result::SUCCESS);
        prop_assert!(!self.m.every_raw().contains(&instance.into_raw()));
        self.m.instances.push(obj(instance.into_raw(), 0));
        Ok(())
    }

    fn step(&mut self, op: &Op) -> Check {
        let f = self.f;
        let m = &self.m;
        match op {
            Op::CreateInstance => self.create_instance()?,
            Op::DestroyInstance(p) => {
                let raw = m.raw(Kind::Instance, p);
                let live = m.live(Kind::Instance, raw);
                let h = xr::Instance::from_raw(raw);
                let r = self.through("xrDestroyInstance", live.map(|_| h), || unsafe {
                    (f.destroy_instance)(h)
                })?;
                if let Some(i) = live {
                    prop_assert_eq!(r, xr::Result::SUCCESS);
                    self.m.kill_instance(i);
                }
            }
            Op::CreateSession(p, ptr) => {
                let raw = m.raw(Kind::Instance, p);
                let live = m.live(Kind::Instance, raw);
                let h = xr::Instance::from_raw(raw);
                // The system id is the runtime's constant for the HMD (1 for the simulated runtime
                // when asked); a wrong one is the runtime's error to report.
                let info = xr::SessionCreateInfo {
                    ty: match ptr {
                        Ptr::WrongType => xr::StructureType::SWAPCHAIN_CREATE_INFO,
                        _ => xr::StructureType::SESSION_CREATE_INFO,
                    },
                    next: null(),
                    create_flags: xr::SessionCreateFlags::EMPTY,
                    system_id: live.map_or(xr::SystemId::from_raw(1), |_| system_of(&f, h)),
                };
                let mut out = xr::Session::NULL;
                let ip = if matches!(ptr, Ptr::Null) {
                    null()
                } else {
                    &info as *const _
                };
                let op = if matches!(ptr, Ptr::NullOut) {
                    null_mut()
                } else {
                    &mut out as *mut _
                };
                let r = self.through("xrCreateSession", live.map(|_| h), || unsafe {
                    (f.create_session)(h, ip, op)
                })?;
                if let (Some(i), xr::Result::SUCCESS) = (live, r) {
                    prop_assert!(matches!(ptr, Ptr::Valid));
                    let mut session = obj(out.into_raw(), i);
                    let space_info = xr::ReferenceSpaceCreateInfo {
                        ty: xr::StructureType::REFERENCE_SPACE_CREATE_INFO,
                        next: null(),
                        reference_space_type: xr::ReferenceSpaceType::LOCAL,
                        pose_in_reference_space: xr::Posef::IDENTITY,
                    };
                    let r = self.through("xrCreateReferenceSpace", Some(h), || unsafe {
                        (f.create_space)(out, &space_info, &mut session.space)
                    })?;
                    prop_assert_eq!(r, xr::Result::SUCCESS);
                    self.m.sessions.push(session);
                }
            }
            Op::DestroySession(p) => {
                let raw = m.raw(Kind::Session, p);
                let live = m.live(Kind::Session, raw);
                let target = live.map(|s| m.instance_of_session(s));
                let r = self.through("xrDestroySession", target, || unsafe {
                    (f.destroy_session)(xr::Session::from_raw(raw))
                })?;
                if let Some(s) = live {
                    prop_assert_eq!(r, xr::Result::SUCCESS);
                    self.m.kill_session(s);
                }
            }
            Op::BeginSession(p) => {
                let raw = m.raw(Kind::Session, p);
                let target = m.live(Kind::Session, raw).map(|s| m.instance_of_session(s));
                let info = xr::SessionBeginInfo {
                    ty: xr::StructureType::SESSION_BEGIN_INFO,
                    next: null(),
                    primary_view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
                };
                self.through("xrBeginSession", target, || unsafe {
                    (f.begin_session)(xr::Session::from_raw(raw), &info)
                })?;
            }
            Op::CreateSwapchain {
                session,
                info,
                chain,
                width,
            } => self.create_swapchain(session, *info, chain, *width)?,
            Op::DestroySwapchain(p) => {
                let raw = m.raw(Kind::Swapchain, p);
                let live = m.live(Kind::Swapchain, raw);
                let target = live.map(|s| m.instance_of_swapchain(s));
                let r = self.through("xrDestroySwapchain", target, || unsafe {
                    (f.destroy_swapchain)(xr::Swapchain::from_raw(raw))
                })?;
                if let Some(s) = live {
                    prop_assert_eq!(r, xr::Result::SUCCESS);
                    self.m.swapchains[s].live = false;
                }
            }
            Op::CreateProfile {
                session,
                info,
                chain,
            } => self.create_profile(session, *info, chain)?,
            Op::DestroyProfile(p) => {
                let raw = m.raw(Kind::Profile, p);
                let live = m.live(Kind::Profile, raw);
                let r = self.layer_call("xrDestroyFoveationProfileFB", || unsafe {
                    (f.destroy_profile)(xr::FoveationProfileFB::from_raw(raw))
                });
                let want = if live.is_some() {
                    xr::Result::SUCCESS
                } else {
                    xr::Result::ERROR_HANDLE_INVALID
                };
                prop_assert_eq!(r, want);
                if let Some(i) = live {
                    self.m.profiles[i].live = false;
                }
            }
            Op::Update {
                swapchain,
                state,
                flags,
                profile,
            } => self.update(swapchain, *state, *flags, profile)?,
            Op::GetState(p, ptr) => self.get_state(p, *ptr)?,
            Op::WaitFrame(p, null_info) => {
                let raw = m.raw(Kind::Session, p);
                let target = m.live(Kind::Session, raw).map(|s| m.instance_of_session(s));
                let info = xr::FrameWaitInfo {
                    ty: xr::StructureType::FRAME_WAIT_INFO,
                    next: null(),
                };
                let mut state = frame_state();
                let ip = if *null_info {
                    null()
                } else {
                    &info as *const _
                };
                self.through("xrWaitFrame", target, || unsafe {
                    (f.wait_frame)(xr::Session::from_raw(raw), ip, &mut state)
                })?;
            }
            Op::BeginFrame(p, null_info) => {
                let raw = m.raw(Kind::Session, p);
                let target = m.live(Kind::Session, raw).map(|s| m.instance_of_session(s));
                let info = xr::FrameBeginInfo {
                    ty: xr::StructureType::FRAME_BEGIN_INFO,
                    next: null(),
                };
                let ip = if *null_info {
                    null()
                } else {
                    &info as *const _
                };
                self.through("xrBeginFrame", target, || unsafe {
                    (f.begin_frame)(xr::Session::from_raw(raw), ip)
                })?;
            }
            Op::Frame(session, swapchain) => self.frame(session, swapchain)?,
            Op::EndFrame(p, layer) => {
                let raw = m.raw(Kind::Session, p);
                let s = m.live(Kind::Session, raw);
                let target = s.map(|s| m.instance_of_session(s));
                let space = s.map_or(xr::Space::NULL, |s| m.sessions[s].space);
                let sc = layer.as_ref().map_or(0, |l| m.raw(Kind::Swapchain, l));
                let mut views = [projection_view(sc, 0), projection_view(sc, 1)];
                views[1].sub_image.image_array_index = 1;
                let projection = xr::CompositionLayerProjection {
                    ty: xr::StructureType::COMPOSITION_LAYER_PROJECTION,
                    next: null(),
                    layer_flags: xr::CompositionLayerFlags::EMPTY,
                    space,
                    view_count: 2,
                    views: views.as_ptr(),
                };
                let layers = [&projection as *const _ as *const xr::CompositionLayerBaseHeader];
                let info = xr::FrameEndInfo {
                    ty: xr::StructureType::FRAME_END_INFO,
                    next: null(),
                    display_time: xr::Time::from_nanos(1),
                    environment_blend_mode: xr::EnvironmentBlendMode::OPAQUE,
                    layer_count: u32::from(layer.is_some()),
                    layers: if layer.is_some() {
                        layers.as_ptr()
                    } else {
                        null()
                    },
                };
                self.through("xrEndFrame", target, || unsafe {
                    (f.end_frame)(xr::Session::from_raw(raw), &info)
                })?;
            }
            Op::LocateViews(p, capacity, null_views) => {
                let raw = m.raw(Kind::Session, p);
                let s = m.live(Kind::Session, raw);
                let target = s.map(|s| m.instance_of_session(s));
                let info = xr::ViewLocateInfo {
                    ty: xr::StructureType::VIEW_LOCATE_INFO,
                    next: null(),
                    view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
                    display_time: xr::Time::from_nanos(1),
                    space: s.map_or(xr::Space::NULL, |s| m.sessions[s].space),
                };
                let mut view_state = xr::ViewState {
                    ty: xr::StructureType::VIEW_STATE,
                    next: null_mut(),
                    view_state_flags: xr::ViewStateFlags::EMPTY,
                };
                let mut views = [view(); 2];
                // A capacity above the buffer is a lie the runtime cannot catch; it writes only the
                // two views there are, so the buffer holds two.
                let vp = if *null_views {
                    null_mut()
                } else {
                    views.as_mut_ptr()
                };
                let mut n = 0;
                self.through("xrLocateViews", target, || unsafe {
                    (f.locate_views)(
                        xr::Session::from_raw(raw),
                        &info,
                        &mut view_state,
                        *capacity,
                        &mut n,
                        vp,
                    )
                })?;
            }
            Op::Acquire(p) => {
                let raw = m.raw(Kind::Swapchain, p);
                let target = m
                    .live(Kind::Swapchain, raw)
                    .map(|s| m.instance_of_swapchain(s));
                let mut index = 0;
                self.through("xrAcquireSwapchainImage", target, || unsafe {
                    (f.acquire)(xr::Swapchain::from_raw(raw), null(), &mut index)
                })?;
            }
            Op::WaitImage(p) => {
                let raw = m.raw(Kind::Swapchain, p);
                let target = m
                    .live(Kind::Swapchain, raw)
                    .map(|s| m.instance_of_swapchain(s));
                let info = xr::SwapchainImageWaitInfo {
                    ty: xr::StructureType::SWAPCHAIN_IMAGE_WAIT_INFO,
                    next: null(),
                    timeout: xr::Duration::INFINITE,
                };
                self.through("xrWaitSwapchainImage", target, || unsafe {
                    (f.wait_image)(xr::Swapchain::from_raw(raw), &info)
                })?;
            }
            Op::Release(p) => {
                let raw = m.raw(Kind::Swapchain, p);
                let target = m
                    .live(Kind::Swapchain, raw)
                    .map(|s| m.instance_of_swapchain(s));
                self.through("xrReleaseSwapchainImage", target, || unsafe {
                    (f.release)(xr::Swapchain::from_raw(raw), null())
                })?;
            }
            Op::EnumerateImages(p, capacity, null_images) => {
                let raw = m.raw(Kind::Swapchain, p);
                let target = m
                    .live(Kind::Swapchain, raw)
                    .map(|s| m.instance_of_swapchain(s));
                // Headless swapchains have no image type: only the count can be asked for; the
                // buffer is large enough for what any capacity makes the runtime write.
                let mut images = [xr::SwapchainImageVulkanKHR {
                    ty: xr::StructureType::SWAPCHAIN_IMAGE_VULKAN_KHR,
                    next: null_mut(),
                    image: 0,
                }; 8];
                let ip = if *null_images {
                    null_mut()
                } else {
                    images.as_mut_ptr() as *mut xr::SwapchainImageBaseHeader
                };
                let mut n = 0;
                self.through("xrEnumerateSwapchainImages", target, || unsafe {
                    (f.enumerate_images)(xr::Swapchain::from_raw(raw), *capacity, &mut n, ip)
                })?;
            }
        }
        Ok(())
    }

    fn frame(&mut self, p: &Pick, swapchain: &Pick) -> Check {
        let f = self.f;
        let m = &self.m;
        let raw = m.raw(Kind::Session, p);
        let s = m.live(Kind::Session, raw);
        let target = s.map(|s| m.instance_of_session(s));
        let session = xr::Session::from_raw(raw);
        let sc_raw = m.raw(Kind::Swapchain, swapchain);
        let sc_target = m
            .live(Kind::Swapchain, sc_raw)
            .map(|s| m.instance_of_swapchain(s));
        let sc = xr::Swapchain::from_raw(sc_raw);
        let space = s.map_or(xr::Space::NULL, |s| m.sessions[s].space);
        let mut state = frame_state();
        if self.through("xrWaitFrame", target, || unsafe {
            (f.wait_frame)(session, null(), &mut state)
        })? != xr::Result::SUCCESS
        {
            return Ok(());
        }
        self.through("xrBeginFrame", target, || unsafe {
            (f.begin_frame)(session, null())
        })?;
        let info = xr::ViewLocateInfo {
            ty: xr::StructureType::VIEW_LOCATE_INFO,
            next: null(),
            view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
            display_time: state.predicted_display_time,
            space,
        };
        let mut view_state = xr::ViewState {
            ty: xr::StructureType::VIEW_STATE,
            next: null_mut(),
            view_state_flags: xr::ViewStateFlags::EMPTY,
        };
        let mut views = [view(); 2];
        let mut n = 0;
        self.through("xrLocateViews", target, || unsafe {
            (f.locate_views)(
                session,
                &info,
                &mut view_state,
                2,
                &mut n,
                views.as_mut_ptr(),
            )
        })?;
        let mut index = 0;
        self.through("xrAcquireSwapchainImage", sc_target, || unsafe {
            (f.acquire)(sc, null(), &mut index)
        })?;
        let wait = xr::SwapchainImageWaitInfo {
            ty: xr::StructureType::SWAPCHAIN_IMAGE_WAIT_INFO,
            next: null(),
            timeout: xr::Duration::INFINITE,
        };
        self.through("xrWaitSwapchainImage", sc_target, || unsafe {
            (f.wait_image)(sc, &wait)
        })?;
        self.through("xrReleaseSwapchainImage", sc_target, || unsafe {
            (f.release)(sc, null())
        })?;
        let mut pviews = [projection_view(sc_raw, 0), projection_view(sc_raw, 1)];
        for (pv, v) in pviews.iter_mut().zip(&views) {
            pv.fov = v.fov;
            pv.pose = v.pose;
        }
        let projection = xr::CompositionLayerProjection {
            ty: xr::StructureType::COMPOSITION_LAYER_PROJECTION,
            next: null(),
            layer_flags: xr::CompositionLayerFlags::EMPTY,
            space,
            view_count: 2,
            views: pviews.as_ptr(),
        };
        let layers = [&projection as *const _ as *const xr::CompositionLayerBaseHeader];
        let end = xr::FrameEndInfo {
            ty: xr::StructureType::FRAME_END_INFO,
            next: null(),
            display_time: state.predicted_display_time,
            environment_blend_mode: xr::EnvironmentBlendMode::OPAQUE,
            layer_count: 1,
            layers: layers.as_ptr(),
        };
        self.through("xrEndFrame", target, || unsafe {
            (f.end_frame)(session, &end)
        })?;
        Ok(())
    }

    fn create_swapchain(&mut self, p: &Pick, ptr: Ptr, chain: &ChainSpec, width: u32) -> Check {
        let f = self.f;
        let raw = self.m.raw(Kind::Session, p);
        let s = self.m.live(Kind::Session, raw);
        let mut slots = Vec::new();
        let head = chain.build(&mut slots);
        let info = xr::SwapchainCreateInfo {
            ty: match ptr {
                Ptr::WrongType => xr::StructureType::SESSION_CREATE_INFO,
                _ => xr::StructureType::SWAPCHAIN_CREATE_INFO,
            },
            next: head,
            create_flags: xr::SwapchainCreateFlags::EMPTY,
            usage_flags: xr::SwapchainUsageFlags::COLOR_ATTACHMENT,
            format: 43,
            sample_count: 1,
            width,
            height: 64,
            face_count: 1,
            array_size: 2,
            mip_count: 1,
        };
        let ip = if matches!(ptr, Ptr::Null) {
            null()
        } else {
            &info as *const _
        };
        let mut out = xr::Swapchain::NULL;
        let op = if matches!(ptr, Ptr::NullOut) {
            null_mut()
        } else {
            &mut out as *mut _
        };
        let call = || unsafe { (f.create_swapchain)(xr::Session::from_raw(raw), ip, op) };
        let Some(s) = s else {
            self.through("xrCreateSwapchain", None, call)?;
            return Ok(());
        };
        let instance = self.m.instance_of_session(s);
        if !matches!(ptr, Ptr::Valid) {
            // Not fovea's to judge: the runtime's validation answers.
            let r = self.through("xrCreateSwapchain", Some(instance), call)?;
            prop_assert!(r.into_raw() < 0);
            return Ok(());
        }
        let foveation = chain.find(|n| matches!(n, Node::SwapchainFoveation { .. }));
        let refused = match foveation {
            Err(()) => true,
            Ok(Some(i)) => {
                let Node::SwapchainFoveation { flags } = chain.nodes[i] else {
                    unreachable!()
                };
                // Unknown flags, or SCALED_BIN (GLES only).
                flags & !0x2 != 0 || !chain.walkable()
            }
            Ok(None) => !chain.walkable(),
        };
        if refused {
            let before = journal_lengths(&self.m);
            let r = self.layer_call("xrCreateSwapchain", call);
            prop_assert_eq!(r, xr::Result::ERROR_VALIDATION_FAILURE, "{:?}", chain);
            prop_assert_eq!(journal_lengths(&self.m), before);
            return Ok(());
        }
        let r = self.through("xrCreateSwapchain", Some(instance), call)?;
        if r == xr::Result::SUCCESS {
            prop_assert!(!self.m.every_raw().contains(&out.into_raw()));
            let mut sc = obj(out.into_raw(), s);
            sc.foveation = matches!(foveation, Ok(Some(_)));
            self.m.swapchains.push(sc);
        }
        Ok(())
    }

    fn create_profile(&mut self, p: &Pick, ptr: Ptr, chain: &ChainSpec) -> Check {
        let f = self.f;
        let raw = self.m.raw(Kind::Session, p);
        let s = self.m.live(Kind::Session, raw);
        let mut slots = Vec::new();
        let head = chain.build(&mut slots);
        let info = xr::FoveationProfileCreateInfoFB {
            ty: match ptr {
                Ptr::WrongType => xr::StructureType::FOVEATION_LEVEL_PROFILE_CREATE_INFO_FB,
                _ => xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
            },
            next: head,
        };
        let mut out = xr::FoveationProfileFB::from_raw(0x7777);
        let ip = if matches!(ptr, Ptr::Null) {
            null()
        } else {
            &info as *const _
        };
        let op = if matches!(ptr, Ptr::NullOut) {
            null_mut()
        } else {
            &mut out as *mut _
        };
        let r = self.layer_call("xrCreateFoveationProfileFB", || unsafe {
            (f.create_profile)(xr::Session::from_raw(raw), ip, op)
        });
        let want = match s {
            None => xr::Result::ERROR_HANDLE_INVALID,
            Some(_) if !matches!(ptr, Ptr::Valid) => xr::Result::ERROR_VALIDATION_FAILURE,
            Some(_) => match chain.find(|n| matches!(n, Node::Level { .. })) {
                Err(()) => xr::Result::ERROR_VALIDATION_FAILURE,
                Ok(None) => xr::Result::SUCCESS,
                Ok(Some(i)) => {
                    let Node::Level {
                        level,
                        dynamic,
                        offset,
                    } = chain.nodes[i]
                    else {
                        unreachable!()
                    };
                    if (0..=3).contains(&level) && (0..=1).contains(&dynamic) && offset.is_finite()
                    {
                        xr::Result::SUCCESS
                    } else {
                        xr::Result::ERROR_VALIDATION_FAILURE
                    }
                }
            },
        };
        prop_assert_eq!(r, want, "{:?}", chain);
        if r == xr::Result::SUCCESS {
            prop_assert_ne!(out.into_raw(), 0);
            prop_assert!(!self.m.every_raw().contains(&out.into_raw()));
            self.m.profiles.push(obj(out.into_raw(), s.unwrap()));
        } else {
            prop_assert_eq!(out.into_raw(), 0x7777, "written on failure");
        }
        Ok(())
    }

    fn update(&mut self, p: &Pick, ptr: Ptr, flags: u64, profile: &Pick) -> Check {
        let f = self.f;
        let raw = self.m.raw(Kind::Swapchain, p);
        let sc = self.m.live(Kind::Swapchain, raw);
        let praw = self.m.raw(Kind::Profile, profile);
        let prof = self.m.live(Kind::Profile, praw);
        let state = xr::SwapchainStateFoveationFB {
            ty: match ptr {
                Ptr::WrongType => xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
                _ => xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB,
            },
            next: null_mut(),
            flags: xr::SwapchainStateFoveationFlagsFB::from_raw(flags),
            profile: xr::FoveationProfileFB::from_raw(praw),
        };
        let sp = if matches!(ptr, Ptr::Null) {
            null()
        } else {
            &state as *const _ as *const xr::SwapchainStateBaseHeaderFB
        };
        let before = journal_lengths(&self.m);
        let r = self.layer_call("xrUpdateSwapchainFB", || unsafe {
            (f.update)(xr::Swapchain::from_raw(raw), sp)
        });
        let want = match sc {
            None => xr::Result::ERROR_HANDLE_INVALID,
            Some(_) if matches!(ptr, Ptr::Null | Ptr::WrongType) => {
                xr::Result::ERROR_VALIDATION_FAILURE
            }
            Some(_) if flags != 0 => xr::Result::ERROR_VALIDATION_FAILURE,
            Some(s) if !self.m.swapchains[s].foveation => xr::Result::ERROR_VALIDATION_FAILURE,
            Some(s) => match prof {
                Some(pi) if self.m.profiles[pi].parent == self.m.swapchains[s].parent => {
                    xr::Result::SUCCESS
                }
                _ => xr::Result::ERROR_HANDLE_INVALID,
            },
        };
        prop_assert_eq!(r, want);
        prop_assert_eq!(journal_lengths(&self.m), before, "reached the runtime");
        if r == xr::Result::SUCCESS {
            self.m.swapchains[sc.unwrap()].applied = prof;
        }
        Ok(())
    }

    fn get_state(&mut self, p: &Pick, ptr: Ptr) -> Check {
        let f = self.f;
        let raw = self.m.raw(Kind::Swapchain, p);
        let sc = self.m.live(Kind::Swapchain, raw);
        let mut state = xr::SwapchainStateFoveationFB {
            ty: match ptr {
                Ptr::WrongType => xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
                _ => xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB,
            },
            next: null_mut(),
            flags: xr::SwapchainStateFoveationFlagsFB::from_raw(0xff),
            profile: xr::FoveationProfileFB::from_raw(0x7777),
        };
        let sp = if matches!(ptr, Ptr::Null) {
            null_mut()
        } else {
            &mut state as *mut _ as *mut xr::SwapchainStateBaseHeaderFB
        };
        let r = self.layer_call("xrGetSwapchainStateFB", || unsafe {
            (f.get_state)(xr::Swapchain::from_raw(raw), sp)
        });
        let want = match sc {
            None => xr::Result::ERROR_HANDLE_INVALID,
            Some(_) if matches!(ptr, Ptr::Null | Ptr::WrongType) => {
                xr::Result::ERROR_VALIDATION_FAILURE
            }
            Some(s) if !self.m.swapchains[s].foveation => xr::Result::ERROR_VALIDATION_FAILURE,
            Some(_) => xr::Result::SUCCESS,
        };
        prop_assert_eq!(r, want);
        if r == xr::Result::SUCCESS {
            let s = &self.m.swapchains[sc.unwrap()];
            let profile = s
                .applied
                .filter(|p| self.m.profiles[*p].live)
                .map_or(0, |p| self.m.profiles[p].raw);
            prop_assert_eq!(state.profile.into_raw(), profile);
            prop_assert_eq!(state.flags.into_raw(), 0);
            prop_assert_eq!(state.ty, xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB);
        } else {
            prop_assert_eq!(state.profile.into_raw(), 0x7777, "written on failure");
        }
        Ok(())
    }

    /// Destroys every live instance, then checks that nothing the case created is still known to
    /// fovea or the runtime.
    fn teardown(&mut self) -> Check {
        let f = self.f;
        for i in 0..self.m.instances.len() {
            if self.m.instances[i].live {
                let h = xr::Instance::from_raw(self.m.instances[i].raw);
                let r = self.layer_call("xrDestroyInstance", || unsafe { (f.destroy_instance)(h) });
                prop_assert_eq!(r, xr::Result::SUCCESS);
                self.m.kill_instance(i);
            }
        }
        for o in &self.m.instances {
            let mut pfn = None;
            let r = self.layer_call("xrGetInstanceProcAddr", || unsafe {
                (f.gipa)(
                    xr::Instance::from_raw(o.raw),
                    c"xrDestroyInstance".as_ptr(),
                    &mut pfn,
                )
            });
            prop_assert_eq!(
                r,
                xr::Result::ERROR_HANDLE_INVALID,
                "instance record leaked"
            );
        }
        for o in &self.m.sessions {
            let info = xr::FoveationProfileCreateInfoFB {
                ty: xr::StructureType::FOVEATION_PROFILE_CREATE_INFO_FB,
                next: null_mut(),
            };
            let mut p = xr::FoveationProfileFB::NULL;
            let r = self.layer_call("xrCreateFoveationProfileFB", || unsafe {
                (f.create_profile)(xr::Session::from_raw(o.raw), &info, &mut p)
            });
            prop_assert_eq!(r, xr::Result::ERROR_HANDLE_INVALID, "session record leaked");
        }
        for o in &self.m.swapchains {
            let mut st = xr::SwapchainStateFoveationFB {
                ty: xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB,
                next: null_mut(),
                flags: xr::SwapchainStateFoveationFlagsFB::EMPTY,
                profile: xr::FoveationProfileFB::NULL,
            };
            let r = self.layer_call("xrGetSwapchainStateFB", || unsafe {
                (f.get_state)(
                    xr::Swapchain::from_raw(o.raw),
                    &mut st as *mut _ as *mut xr::SwapchainStateBaseHeaderFB,
                )
            });
            prop_assert_eq!(
                r,
                xr::Result::ERROR_HANDLE_INVALID,
                "swapchain record leaked"
            );
        }
        for o in &self.m.profiles {
            let r = self.layer_call("xrDestroyFoveationProfileFB", || unsafe {
                (f.destroy_profile)(xr::FoveationProfileFB::from_raw(o.raw))
            });
            prop_assert_eq!(r, xr::Result::ERROR_HANDLE_INVALID, "profile record leaked");
        }
        prop_assert_eq!(sim::control::live_objects(), 0, "the runtime holds objects");
        Ok(())
    }
}

unsafe fn system(f: &Fns, instance: xr::Instance) -> xr::SystemId {
    let get: xr::pfn::GetSystem = lookup(f.gipa, instance, c"xrGetSystem").unwrap();
    let info = xr::SystemGetInfo {
        ty: xr::StructureType::SYSTEM_GET_INFO,
        next: null(),
        form_factor: xr::FormFactor::HEAD_MOUNTED_DISPLAY,
    };
    let mut id = xr::SystemId::NULL;
    assert_eq!(get(instance, &info, &mut id), xr::Result::SUCCESS);
    id
}

fn system_of(f: &Fns, instance: xr::Instance) -> xr::SystemId {
    unsafe { system(f, instance) }
}

fn frame_state() -> xr::FrameState {
    xr::FrameState {
        ty: xr::StructureType::FRAME_STATE,
        next: null_mut(),
        predicted_display_time: xr::Time::from_nanos(0),
        predicted_display_period: xr::Duration::from_nanos(0),
        should_render: xr::FALSE,
    }
}

fn view() -> xr::View {
    xr::View {
        ty: xr::StructureType::VIEW,
        next: null_mut(),
        pose: xr::Posef::IDENTITY,
        fov: xr::Fovf::default(),
    }
}

fn projection_view(swapchain: u64, layer: u32) -> xr::CompositionLayerProjectionView {
    xr::CompositionLayerProjectionView {
        ty: xr::StructureType::COMPOSITION_LAYER_PROJECTION_VIEW,
        next: null(),
        pose: xr::Posef::IDENTITY,
        fov: xr::Fovf {
            angle_left: -0.7,
            angle_right: 0.7,
            angle_up: 0.7,
            angle_down: -0.7,
        },
        sub_image: xr::SwapchainSubImage {
            swapchain: xr::Swapchain::from_raw(swapchain),
            image_rect: xr::Rect2Di {
                offset: xr::Offset2Di { x: 0, y: 0 },
                extent: xr::Extent2Di {
                    width: 64,
                    height: 64,
                },
            },
            image_array_index: layer,
        },
    }
}

/// Cases to run: `FOVEA_FUZZ_CASES`, else 64.
fn cases() -> u32 {
    std::env::var("FOVEA_FUZZ_CASES")
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(64)
}

#[test]
fn random_call_sequences_match_the_reference_model() {
    in_own_process(
        module_path!(),
        "random_call_sequences_match_the_reference_model",
        random_call_sequences_match_the_reference_model_here,
    );
}

fn random_call_sequences_match_the_reference_model_here() {
    // Most sequences make fovea warn about what it refuses; only errors are worth reading here.
    if std::env::var_os("FOVEA_LOG").is_none() {
        std::env::set_var("FOVEA_LOG", "error");
    }
    // A second xrWaitFrame before the first frame is begun blocks in the runtime until a begin
    // that a single-threaded sequence never makes; the runtime refuses it after this long.
    std::env::set_var("FOVEA_SIM_WAIT_BLOCK_MS", "1");
    sim::control::set_thread_config(None);
    // One chain for the whole run keeps libfovea.so loaded, so the function pointers stay valid.
    let chain = Chain::fovea().unwrap();
    // Looked up once, on an instance made for the purpose: hooks and runtime functions alike are
    // the same for every instance.
    let f = {
        let mut boot = xr::Instance::NULL;
        let r = with_create_info(&FOVEATION_EXTENSIONS, API_1_0, |info| unsafe {
            chain.create_instance(info, &mut boot)
        });
        assert_eq!(r, xr::Result::SUCCESS);
        let f = unsafe { Fns::load(&chain, boot) };
        assert_eq!(unsafe { (f.destroy_instance)(boot) }, xr::Result::SUCCESS);
        f
    };
    let started = Instant::now();
    let config = ProptestConfig {
        cases: cases(),
        max_shrink_iters: 2000,
        ..ProptestConfig::default()
    };
    let mut runner = proptest::test_runner::TestRunner::new(config);
    let result = runner.run(&(prop::collection::vec(op(), 1..60)), |ops| {
        let mut r = Runner {
            chain: &chain,
            f,
            m: Model::default(),
        };
        // Most sequences start with an instance and a session, so the rest has something to
        // work on; some start bare.
        if ops.len() % 4 != 0 {
            r.create_instance()?;
            r.step(&Op::CreateSession(Pick::Ever(0), Ptr::Valid))?;
            r.step(&Op::BeginSession(Pick::Ever(0)))?;
            let foveated = ChainSpec {
                nodes: vec![Node::SwapchainFoveation { flags: 0 }],
                loop_to: None,
                padding: 0,
            };
            r.create_swapchain(&Pick::Ever(0), Ptr::Valid, &foveated, 64)?;
            let level = ChainSpec {
                nodes: vec![Node::Level {
                    level: 2,
                    dynamic: 0,
                    offset: 0.0,
                }],
                loop_to: None,
                padding: 0,
            };
            r.create_profile(&Pick::Ever(0), Ptr::Valid, &level)?;
        }
        let steps = ops.iter().try_for_each(|op| r.step(op));
        // Tear down even after a failure, so the next case starts from an empty runtime.
        let torn = r.teardown();
        steps.and(torn)
    });
    let calls = CALLS.load(Ordering::Relaxed);
    eprintln!(
        "fuzz_sequences: {} cases, {calls} calls into the layer in {:.1} s",
        cases(),
        started.elapsed().as_secs_f64()
    );
    if std::env::var_os("FOVEA_FUZZ_RESULTS").is_some() {
        for ((name, r), n) in RESULTS.lock().unwrap().iter() {
            eprintln!(
                "  {name:<32} {:<40} {n}",
                format!("{:?}", xr::Result::from_raw(*r))
            );
        }
    }
    if let Err(e) = result {
        panic!("{e}");
    }
}
