//! What the OpenXR side publishes for injection (docs/injection.md), and what the Vulkan side reads
//! when a pass begins: whether injection is on, the pattern in force, the views' FOVs, and the
//! swapchains whose images hold views (with their `VkImage`s and what each holds).
//!
//! The OpenXR side writes only when something changed (a swapchain created or destroyed, a FOV or
//! the pattern changed), so per frame a write is a comparison. Each write replaces the published
//! [`Injection`] with a new `Arc` and bumps the generation: a reader ([`with_current`]) compares one
//! atomic with the generation it cached and reads the `Arc` again only when it moved, and the shading-rate images made
//! for an older generation are stale ([`Injection::key`]).
//!
//! The lock is a leaf, like the shadows' in the parent module: taken for a swap or an `Arc` clone,
//! nothing is called while it is held, so either side may take it under any of its own locks.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

use fovea_model::density::{Level, Pattern};
use fovea_model::inject::{self, Holds, Pass, Target};
use fovea_model::maps::MAX_VIEWS;
use fovea_model::Fov;

/// A swapchain whose images hold views.
#[derive(Clone, Debug, PartialEq)]
pub struct EyeSwapchain {
    /// The `XrSwapchain`'s raw handle.
    pub handle: u64,
    /// Its `VkImage`s as raw handles, once the application enumerated them.
    pub images: Vec<u64>,
    pub shape: inject::Swapchain,
    /// The application foveates it itself, with density images fovea gave it
    /// (XR_FB_foveation_vulkan): passes into its images are not injected into, and its shape
    /// makes no target an eye-shaped one (docs/injection.md#switching-it-on).
    pub own: bool,
}

/// Everything the Vulkan side needs to decide and fill an injected pass.
#[derive(Clone, Debug, PartialEq)]
pub struct Injection {
    /// The level and offset maps use now: the injected level under the debug properties and the
    /// dynamic step (`xr::foveation::effective`, which the OpenXR side applies
    /// before it publishes).
    pub pattern: Pattern,
    /// Whether the level is dynamic (for the stats line's `D`).
    pub dynamic: bool,
    /// The largest fragment a map asks for (`max_fragment`).
    pub max_fragment: u32,
    /// The views' FOVs as last located (none before the first `xrLocateViews`).
    pub fovs: [Option<Fov>; MAX_VIEWS],
    /// How many views the application renders (2 for stereo).
    pub views: u8,
    pub swapchains: Vec<EyeSwapchain>,
    /// Bumped when the pattern, the FOVs or `max_fragment` change: what the fixed maps hold, which
    /// a gaze only shifts.
    pub fixed: u64,
    /// Bumped when anything a map holds changes except the centres: what [`Injection::fixed`]
    /// counts ([`Injection::key`] adds the centres' moves).
    pub maps: u64,
}

impl Injection {
    fn new(level: Level) -> Injection {
        Injection {
            pattern: Pattern {
                level,
                vertical_offset_deg: 0.0,
            },
            dynamic: false,
            max_fragment: fovea_model::maps::DEFAULT_MAX_FRAGMENT,
            fovs: [None; MAX_VIEWS],
            views: 2,
            swapchains: Vec::new(),
            fixed: 0,
            maps: 0,
        }
    }

    /// The generation of what the maps hold: an injected shading-rate image filled for another
    /// key is stale. Both counts only grow, so their sum moves exactly when either does. Read it
    /// before [`Injection::centres`]: a map filled with centres newer than its key is filled again
    /// at the next look, never one with older centres kept.
    pub fn key(&self) -> u64 {
        self.maps + MOVES.load(Ordering::Acquire)
    }

    /// Per view, where its fovea is while a gaze is followed (NDC of its own FOV, y up); `None`:
    /// the fixed map's place (docs/eye-tracking.md#what-moves-when). Published only when a fovea
    /// moved by half a texel or more ([`set_centres`]).
    pub fn centres(&self) -> [Option<[f32; 2]>; MAX_VIEWS] {
        published_centres()
    }

    /// Which swapchain `image` belongs to, if any.
    pub fn swapchain_of(&self, image: u64) -> Option<usize> {
        self.swapchains
            .iter()
            .position(|s| s.images.contains(&image))
    }

    /// What a pass whose colour target is `image` (`extent`, rendering `layers` layers from
    /// `base_layer` of an image with `image_layers`) is: `Other` for an image of a swapchain the
    /// application foveates itself ([`EyeSwapchain::own`]), else as the other swapchains say. At
    /// most [`MAX_SWAPCHAINS`] swapchains are looked at, with no allocation: this may run when a
    /// pass begins.
    pub fn classify(
        &self,
        image: u64,
        extent: [u32; 2],
        base_layer: u32,
        layers: u32,
        image_layers: u32,
    ) -> Pass {
        let mut shapes = [inject::Swapchain {
            extent: [0, 0],
            layers: 0,
            holds: Holds::Layers,
        }; MAX_SWAPCHAINS];
        let mut n = 0;
        let mut swapchain = None;
        for s in &self.swapchains {
            let holds_image = s.images.contains(&image);
            if s.own {
                if holds_image {
                    return Pass::Other;
                }
                continue;
            }
            if n == MAX_SWAPCHAINS {
                break;
            }
            if holds_image && swapchain.is_none() {
                swapchain = Some(n);
            }
            shapes[n] = s.shape;
            n += 1;
        }
        let target = Target {
            extent,
            base_layer,
            layers,
            image_layers,
            swapchain,
        };
        inject::classify(&shapes[..n], self.views, &target)
    }
}

/// Most eye swapchains looked at (stereo apps have one or two; quad views four).
pub const MAX_SWAPCHAINS: usize = 8;

/// Set at `xrCreateInstance` when injection applies, before the application creates its
/// `VkDevice`: the Vulkan side then enables shading-rate attachments on it.
static WANTED: AtomicBool = AtomicBool::new(false);

/// Bumped by every change to [`STATE`].
static GENERATION: AtomicU64 = AtomicU64::new(0);

/// The published centres, one word per view ([`pack`]), beside [`STATE`] rather than in it: a
/// gaze moves them most frames, and a move then costs a few atomic stores, where a new `STATE`
/// would copy the swapchains' lists (heap allocations and the write lock, per frame).
static CENTRES: [AtomicU64; MAX_VIEWS] = [const { AtomicU64::new(NO_CENTRE) }; MAX_VIEWS];

/// Bumped after each publication of [`CENTRES`] (the writer stores the centres first).
static MOVES: AtomicU64 = AtomicU64::new(0);

/// A view without a centre of its own: the bits of two NaNs, which [`pack`] never stores.
const NO_CENTRE: u64 = u64::MAX;

/// A centre as one word (x's bits high, y's low); a centre that is not finite is none.
fn pack(c: Option<[f32; 2]>) -> u64 {
    match c {
        Some([x, y]) if x.is_finite() && y.is_finite() => {
            u64::from(x.to_bits()) << 32 | u64::from(y.to_bits())
        }
        _ => NO_CENTRE,
    }
}

fn unpack(w: u64) -> Option<[f32; 2]> {
    (w != NO_CENTRE).then(|| [f32::from_bits((w >> 32) as u32), f32::from_bits(w as u32)])
}

fn published_centres() -> [Option<[f32; 2]>; MAX_VIEWS] {
    std::array::from_fn(|i| unpack(CENTRES[i].load(Ordering::Acquire)))
}

fn publish_centres(now: &[Option<[f32; 2]>; MAX_VIEWS]) {
    for (word, c) in CENTRES.iter().zip(now) {
        word.store(pack(*c), Ordering::Release);
    }
    MOVES.fetch_add(1, Ordering::AcqRel);
}

static STATE: crate::common::lock::SharedRwLock<Option<Arc<Injection>>> =
    crate::common::lock::SharedRwLock::new(None);

/// Eye passes injected and all passes begun since the last [`take_counts`], for the stats line.
static EYE_PASSES: AtomicU64 = AtomicU64::new(0);
static ALL_PASSES: AtomicU64 = AtomicU64::new(0);

/// Whether injection is on for this process (an instance with injection exists).
pub fn wanted() -> bool {
    WANTED.load(Ordering::Acquire)
}

/// The published state, `None` where injection is off: a reference that stays valid while the
/// caller holds it. For the paths that run per frame or per pass, [`with_current`].
pub fn current() -> Option<Arc<Injection>> {
    STATE.read().clone()
}

/// The generation of the published state: a decision a thread made from the state it read after
/// loading this value is good for as long as the value stays the same (the Vulkan side's per-thread
/// cache of begin decisions, `crate::vk::injection`).
pub fn generation() -> u64 {
    // Both only grow, so the sum moves exactly when either does.
    GENERATION.load(Ordering::Acquire) + MOVES.load(Ordering::Acquire)
}

thread_local! {
    /// The state this thread last read and the generation it was read at.
    static SEEN: std::cell::RefCell<(u64, Option<Arc<Injection>>)> =
        const { std::cell::RefCell::new((u64::MAX, None)) };
}

/// Runs `f` on the published state, `None` where injection is off. In steady state (nothing
/// published since this thread last looked) that is one atomic load: no lock and no reference
/// count touched, so recording threads and the frame loop never contend here. After a change the
/// thread reads the state once under the lock and keeps it.
pub fn with_current<R>(f: impl FnOnce(Option<&Injection>) -> R) -> R {
    let now = GENERATION.load(Ordering::Acquire);
    SEEN.with(|seen| {
        if seen.borrow().0 != now {
            // A writer publishes the state before it bumps the generation, so the state read here
            // is at least generation `now`'s; a newer one is read again at the next bump.
            match seen.try_borrow_mut() {
                Ok(mut s) => *s = (now, STATE.read().clone()),
                // Only inside `f` of an outer call on this thread, which holds the borrow.
                Err(_) => return f(current().as_deref()),
            }
        }
        f(seen.borrow().1.as_deref())
    })
}

/// Applies `f` to a copy of the state and publishes it when it changed; nothing where injection is
/// off.
fn update(f: impl FnOnce(&mut Injection)) {
    let mut guard = STATE.write();
    let Some(old) = guard.as_ref() else {
        return;
    };
    let mut new = Injection::clone(old);
    f(&mut new);
    if new != **old {
        *guard = Some(Arc::new(new));
        GENERATION.fetch_add(1, Ordering::AcqRel);
    }
}

thread_local! {
    /// Set while this thread is inside `xrCreateVulkanDeviceKHR` (XR_KHR_vulkan_enable2): the
    /// `vkCreateDevice` the runtime makes there is the device the session renders its views with.
    static CREATING_XR_DEVICE: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Set once the application asked `xrGetVulkanGraphicsDeviceKHR` (XR_KHR_vulkan_enable), whose
/// applications create their `VkDevice` themselves: nothing at `vkCreateDevice` tells which of
/// their devices the session will use.
static LEGACY_ENABLE: AtomicBool = AtomicBool::new(false);

/// Runs `f` (the runtime's `xrCreateVulkanDeviceKHR`) with this thread marked as creating the
/// session's device.
pub fn creating_xr_device<R>(f: impl FnOnce() -> R) -> R {
    struct Reset(bool);
    impl Drop for Reset {
        fn drop(&mut self) {
            let old = self.0;
            CREATING_XR_DEVICE.with(|c| c.set(old));
        }
    }
    let _reset = Reset(CREATING_XR_DEVICE.with(|c| c.replace(true)));
    f()
}

/// The application uses XR_KHR_vulkan_enable (`xrGetVulkanGraphicsDeviceKHR` answered).
pub fn legacy_enable_used() {
    LEGACY_ENABLE.store(true, Ordering::Release);
}

/// Whether a `vkCreateDevice` now creates a device that will render eye passes, and so gets the
/// shading-rate attachment feature under injection (docs/injection.md#which-devices-get-the-feature):
/// one created inside `xrCreateVulkanDeviceKHR`, or, where the application uses
/// XR_KHR_vulkan_enable, any (its session's device cannot be told from its others at creation).
pub fn device_gets_maps() -> bool {
    CREATING_XR_DEVICE.with(|c| c.get()) || LEGACY_ENABLE.load(Ordering::Acquire)
}

/// Set with [`WANTED`] where `inject` is on for the application; clear where injection is on only
/// for the profiles it applies to swapchains without density images
/// (docs/injection.md#applications-that-apply-profiles).
static FOR_EVERY_APP: AtomicBool = AtomicBool::new(false);

/// Whether `inject` is on for this process's application (not only for the profiles it applies):
/// the Vulkan side says why a device cannot take maps only then, since an application that uses
/// the FB API with density maps would otherwise read that its eye passes render at full rate.
pub fn for_every_app() -> bool {
    FOR_EVERY_APP.load(Ordering::Acquire)
}

/// Switches injection on at `level` (at `xrCreateInstance`); `every_app`: `inject` is on
/// ([`for_every_app`]).
pub fn start(level: Level, every_app: bool) {
    publish_centres(&[None; MAX_VIEWS]);
    *STATE.write() = Some(Arc::new(Injection::new(level)));
    FOR_EVERY_APP.store(every_app, Ordering::Release);
    WANTED.store(true, Ordering::Release);
    GENERATION.fetch_add(1, Ordering::AcqRel);
}

/// Switches injection off (at `xrDestroyInstance`).
pub fn stop() {
    *STATE.write() = None;
    WANTED.store(false, Ordering::Release);
    FOR_EVERY_APP.store(false, Ordering::Release);
    LEGACY_ENABLE.store(false, Ordering::Release);
    GENERATION.fetch_add(1, Ordering::AcqRel);
}

/// The pattern in force changed (overrides, dynamic step).
pub fn set_pattern(pattern: Pattern, dynamic: bool, max_fragment: u32) {
    // A comparison when unchanged (no copy): this runs every frame.
    if with_current(|s| {
        s.is_none_or(|s| (s.pattern, s.dynamic, s.max_fragment) == (pattern, dynamic, max_fragment))
    }) {
        return;
    }
    update(|s| {
        if (s.pattern, s.dynamic, s.max_fragment) != (pattern, dynamic, max_fragment) {
            s.pattern = pattern;
            s.dynamic = dynamic;
            s.max_fragment = max_fragment;
            s.fixed += 1;
            s.maps += 1;
        }
    });
}

/// The FOVs `xrLocateViews` returned. A comparison when unchanged: it runs every frame.
pub fn set_fovs(fovs: &[Fov]) {
    let mut new = [None; MAX_VIEWS];
    for (slot, f) in new.iter_mut().zip(fovs) {
        *slot = Some(*f);
    }
    if with_current(|s| s.is_some_and(|s| s.fovs == new && usize::from(s.views) == fovs.len())) {
        return;
    }
    update(|s| {
        if s.fovs != new {
            s.fovs = new;
            s.fixed += 1;
            s.maps += 1;
            // Each view's left,right,up,down in radians, exactly (the shortest text that reads
            // back the same f32): what the injected maps are drawn for, which a test of a real
            // application compares what its passes shaded at with.
            if tracing::enabled!(tracing::Level::DEBUG) {
                let text: Vec<String> = fovs
                    .iter()
                    .map(|f| format!("{},{},{},{}", f.left, f.right, f.up, f.down))
                    .collect();
                tracing::debug!(fovs = text.join(" "), "injection: the views' FOVs changed");
            }
        }
        s.views = fovs.len().min(MAX_VIEWS) as u8;
    });
}

/// The finest shading-rate texel of the injecting devices, packed (width << 32 | height); 0 before
/// the first: half of it is how far a fovea must move before it is published again.
static TEXEL: AtomicU64 = AtomicU64::new(0);

/// The texel assumed before an injecting device said its own: 8×8, the finest shading-rate texel
/// drivers report, so no move that matters on any device is held back.
const FALLBACK_TEXEL: [u32; 2] = [8, 8];

/// The Vulkan side made an injecting device whose shading-rate attachments have texels of `texel`
/// pixels: the centres are published in steps of half the finest of them.
pub fn set_texel(texel: [u32; 2]) {
    let packed = |t: [u32; 2]| u64::from(t[0]) << 32 | u64::from(t[1]);
    let _ = TEXEL.fetch_update(Ordering::AcqRel, Ordering::Acquire, |old| {
        let old = [(old >> 32) as u32, old as u32];
        let new = if old == [0, 0] {
            texel
        } else {
            [old[0].min(texel[0]), old[1].min(texel[1])]
        };
        Some(packed(new))
    });
}

/// Whether an injecting device exists in this process (one made its injector, [`set_texel`]).
pub fn injecting_device() -> bool {
    TEXEL.load(Ordering::Acquire) != 0
}

fn texel() -> [u32; 2] {
    let t = TEXEL.load(Ordering::Acquire);
    match [(t >> 32) as u32, t as u32] {
        [0, _] | [_, 0] => FALLBACK_TEXEL,
        t => t,
    }
}

/// Whether `now` differs from the published centres by enough to publish: a view starts or stops
/// following, or its fovea moved by half a texel or more in the pixels of the eye swapchains'
/// views ([`fovea_model::shift::moved_enough`]); before any eye swapchain is known, any change.
fn centres_moved(s: &Injection, now: &[Option<[f32; 2]>; MAX_VIEWS]) -> bool {
    let published = s.centres();
    let Some(extent) = s.swapchains.first().map(|e| e.shape.view_extent()) else {
        return published != *now;
    };
    let grid = fovea_model::density::Grid::new(extent, texel());
    let px = |c: [f32; 2]| {
        [
            (c[0] + 1.0) * 0.5 * extent[0] as f32,
            (1.0 - c[1]) * 0.5 * extent[1] as f32,
        ]
    };
    published.iter().zip(now).any(|(a, b)| match (a, b) {
        (None, None) => false,
        (Some(a), Some(b)) => fovea_model::shift::moved_enough(&grid, px(*a), px(*b)),
        _ => true,
    })
}

/// Where each view's fovea is now (`None`: fixed foveation), from the OpenXR side every frame: a
/// comparison in steady state, published only when a fovea moved by half a texel or more, so the
/// generation does not move with a trembling gaze; a publication is a few atomic stores, with no
/// lock and no allocation ([`CENTRES`]). Nothing is published where injection is off.
pub fn set_centres(now: &[Option<[f32; 2]>; MAX_VIEWS]) {
    if with_current(|s| s.is_some_and(|s| centres_moved(s, now))) {
        publish_centres(now);
    }
}

/// A swapchain that holds views was created (or what it holds was learned anew); `own`: the
/// application foveates it itself ([`EyeSwapchain::own`]).
pub fn set_swapchain(handle: u64, shape: inject::Swapchain, own: bool) {
    update(
        |s| match s.swapchains.iter_mut().find(|e| e.handle == handle) {
            Some(e) => {
                e.shape = shape;
                e.own = own;
            }
            None => s.swapchains.push(EyeSwapchain {
                handle,
                images: Vec::new(),
                shape,
                own,
            }),
        },
    );
}

/// The `VkImage`s of a swapchain published with [`set_swapchain`].
pub fn set_images(handle: u64, images: &[u64]) {
    update(|s| {
        if let Some(e) = s.swapchains.iter_mut().find(|e| e.handle == handle) {
            e.images = images.to_vec();
        }
    });
}

/// A swapchain was destroyed.
pub fn remove_swapchain(handle: u64) {
    update(|s| s.swapchains.retain(|e| e.handle != handle));
}

/// Counts a pass begun with injection on; `eye` when it got the attachment.
pub fn count_pass(eye: bool) {
    ALL_PASSES.fetch_add(1, Ordering::Relaxed);
    if eye {
        EYE_PASSES.fetch_add(1, Ordering::Relaxed);
    }
}

/// The passes counted since the last call: `(eye, all)`.
pub fn take_counts() -> (u64, u64) {
    (
        EYE_PASSES.swap(0, Ordering::Relaxed),
        ALL_PASSES.swap(0, Ordering::Relaxed),
    )
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use fovea_model::inject::Views;

    /// The published state is process-wide; the tests that change it take this.
    pub(crate) static STATE_TESTS: parking_lot::Mutex<()> = parking_lot::Mutex::new(());

    /// Injection on at HIGH for the application, both views with one square FOV (0.8 each way):
    /// the published state the Vulkan side's injection tests start from (hold [`STATE_TESTS`]).
    pub(crate) fn start_high_square() {
        start(Level::High, true);
        let fov = Fov {
            left: -0.8,
            right: 0.8,
            up: 0.8,
            down: -0.8,
        };
        set_fovs(&[fov, fov]);
    }

    #[test]
    fn the_sessions_device_is_the_one_created_inside_xr_create_vulkan_device() {
        let _one = STATE_TESTS.lock();
        stop();
        assert!(!device_gets_maps());
        let inner = creating_xr_device(|| {
            // Nested (a runtime calling through another layer's hook): still marked, and
            // unmarked only when the outermost call returns.
            let nested = creating_xr_device(device_gets_maps);
            (nested, device_gets_maps())
        });
        assert_eq!(inner, (true, true));
        assert!(!device_gets_maps(), "unmarked after the call");
        let other_thread = creating_xr_device(|| std::thread::spawn(device_gets_maps).join());
        assert_eq!(other_thread.ok(), Some(false), "the mark is this thread's");
        legacy_enable_used();
        assert!(device_gets_maps(), "XR_KHR_vulkan_enable: every device");
        stop();
        assert!(!device_gets_maps(), "forgotten with the instance");
    }

    #[test]
    fn readers_see_each_change_and_take_no_lock_in_steady_state() {
        let _one = STATE_TESTS.lock();
        stop();
        start(Level::High, true);
        let level = || with_current(|s| s.map(|s| s.pattern.level));
        assert_eq!(level(), Some(Level::High));
        set_pattern(
            Pattern {
                level: Level::Low,
                vertical_offset_deg: 0.0,
            },
            false,
            4,
        );
        assert_eq!(
            level(),
            Some(Level::Low),
            "a change is seen at the next call"
        );
        // Nested calls (a reader's closure that reads again) see the same state.
        assert_eq!(
            with_current(|outer| with_current(|inner| (
                outer.map(|s| s.pattern.level),
                inner.map(|s| s.pattern.level)
            ))),
            (Some(Level::Low), Some(Level::Low))
        );

        // A reader thread that has looked once reads again while a writer holds the lock: in
        // steady state it never waits for it.
        let (ask, asked) = std::sync::mpsc::channel::<()>();
        let (answer, answered) = std::sync::mpsc::channel();
        let reader = std::thread::spawn(move || {
            while asked.recv().is_ok() {
                answer
                    .send(with_current(|s| s.map(|s| s.pattern.level)))
                    .unwrap();
            }
        });
        ask.send(()).unwrap();
        assert_eq!(answered.recv().unwrap(), Some(Level::Low));
        {
            let _writer = STATE.write();
            ask.send(()).unwrap();
            assert_eq!(
                answered.recv_timeout(std::time::Duration::from_secs(10)),
                Ok(Some(Level::Low)),
                "the reader waited for the lock"
            );
        }
        drop(ask);
        reader.join().unwrap();
        stop();
        assert_eq!(level(), None, "off is seen too");
    }

    /// Injection on at HIGH with one layered eye swapchain of 1600×1600 (handle 9), for the
    /// centres' tests, which hold the returned guard (the state is process-wide).
    fn start_with_eye_swapchain() -> parking_lot::MutexGuard<'static, ()> {
        let one = STATE_TESTS.lock();
        stop();
        start(Level::High, true);
        set_swapchain(
            9,
            inject::Swapchain {
                extent: [1600, 1600],
                layers: 2,
                holds: Holds::Layers,
            },
            false,
        );
        one
    }

    #[test]
    fn centres_are_published_per_half_texel_and_keep_the_fixed_maps() {
        let _one = start_with_eye_swapchain();
        set_texel([16, 16]);
        let mut c = [None; MAX_VIEWS];
        c[0] = Some([0.1, 0.0]);
        c[1] = Some([0.1, 0.0]);
        let fixed = current().unwrap().fixed;
        set_centres(&c);
        let s = current().unwrap();
        assert_eq!(s.centres(), c);
        assert_eq!(s.fixed, fixed, "a move keeps the fixed maps");
        let (g, key) = (super::generation(), s.key());
        // A texel of 16 px on 1600 px is 0.02 in NDC: half of it is 0.01.
        let mut tremble = c;
        tremble[0] = Some([0.1 + 0.0099, -0.0099]);
        set_centres(&tremble);
        assert_eq!(super::generation(), g, "inside half a texel");
        assert_eq!(current().unwrap().key(), key);
        let mut moved = c;
        moved[1] = Some([0.1, 0.011]);
        set_centres(&moved);
        assert!(current().unwrap().key() > key, "half a texel: published");
        assert_eq!(current().unwrap().centres(), moved);
        let key = current().unwrap().key();
        set_centres(&[None; MAX_VIEWS]);
        assert!(current().unwrap().key() > key, "back to fixed foveation");
        assert_eq!(current().unwrap().fixed, fixed);
        stop();
    }

    /// An eye tracker moves the centres most frames: each publication is a few stores, with no
    /// heap allocation, and the Vulkan side sees it (the key and the generation move).
    #[test]
    fn a_moving_gaze_is_published_without_allocating() {
        use crate::common::alloc_count::allocations;
        let _one = start_with_eye_swapchain();
        set_images(9, &[0x51, 0x52, 0x53]);
        set_texel([16, 16]);
        let mut c = [None; MAX_VIEWS];
        c[0] = Some([0.0, 0.0]);
        set_centres(&c);
        let mut counts = Vec::new();
        for frame in 1..=30u16 {
            let (key, generation) = (current().unwrap().key(), super::generation());
            c[0] = Some([f32::from(frame) * 0.02, 0.0]);
            let before = allocations();
            set_centres(&c);
            counts.push(allocations() - before);
            let s = current().unwrap();
            assert_eq!(s.centres(), c, "frame {frame}");
            assert!(s.key() > key && super::generation() > generation);
        }
        stop();
        assert_eq!(counts, [0; 30], "allocations per published move");
    }

    #[test]
    fn publishing_bumps_the_generation_only_on_change() {
        let _one = STATE_TESTS.lock();
        stop();
        let g = GENERATION.load(Ordering::Acquire);
        set_fovs(&[fovea_model::maps::FALLBACK_FOV]);
        assert_eq!(
            GENERATION.load(Ordering::Acquire),
            g,
            "nothing is published while off"
        );
        assert!(current().is_none() && !wanted());

        start(Level::High, true);
        assert!(wanted());
        let on = GENERATION.load(Ordering::Acquire);
        assert_eq!(current().unwrap().pattern.level, Level::High);
        let f = fovea_model::maps::FALLBACK_FOV;
        set_fovs(&[f, f.mirrored()]);
        let located = GENERATION.load(Ordering::Acquire);
        assert!(located > on);
        let key = current().unwrap().key();
        set_fovs(&[f, f.mirrored()]);
        assert_eq!(
            GENERATION.load(Ordering::Acquire),
            located,
            "the same FOVs again: no change"
        );
        set_pattern(
            Pattern {
                level: Level::Low,
                vertical_offset_deg: 0.0,
            },
            true,
            4,
        );
        assert!(current().unwrap().key() > key, "a new pattern: maps stale");
        assert!(current().unwrap().dynamic);

        let shape = inject::Swapchain {
            extent: [1440, 1600],
            layers: 1,
            holds: Holds::View(1),
        };
        set_swapchain(7, shape, false);
        set_images(7, &[70, 71, 72]);
        let s = current().unwrap();
        assert_eq!(s.swapchain_of(71), Some(0));
        assert_eq!(s.swapchain_of(73), None);
        assert_eq!(
            s.classify(72, [1440, 1600], 0, 1, 1),
            Pass::Eye(Views::Layers { first: 1, count: 1 }),
            "the right eye's swapchain image"
        );
        assert_eq!(
            s.classify(99, [1440, 1600], 0, 1, 1),
            Pass::Eye(Views::Merged),
            "an eye-shaped target of its own"
        );
        assert_eq!(s.classify(99, [256, 256], 0, 1, 1), Pass::Other);
        // A swapchain with density images of its own (the application foveates it itself): its
        // images are no eye pass, and its shape makes no target an eye-shaped one; the others'
        // images and shapes still count.
        let own = inject::Swapchain {
            extent: [2000, 1000],
            layers: 2,
            holds: Holds::Layers,
        };
        set_swapchain(8, own, true);
        set_images(8, &[80, 81]);
        let s = current().unwrap();
        assert_eq!(s.classify(80, [2000, 1000], 0, 2, 2), Pass::Other);
        assert_eq!(s.classify(98, [2000, 1000], 0, 2, 2), Pass::Other);
        assert_eq!(
            s.classify(72, [1440, 1600], 0, 1, 1),
            Pass::Eye(Views::Layers { first: 1, count: 1 }),
            "the other swapchain's images are still its eye's"
        );
        assert_eq!(
            s.classify(99, [1440, 1600], 0, 1, 1),
            Pass::Eye(Views::Merged)
        );
        set_swapchain(8, own, false);
        assert_eq!(
            current().unwrap().classify(80, [2000, 1000], 0, 2, 2),
            Pass::Eye(Views::Layers { first: 0, count: 2 }),
            "without density images it is injected into"
        );
        remove_swapchain(8);
        let before = current().unwrap().key();
        remove_swapchain(7);
        assert!(current().unwrap().swapchains.is_empty());
        assert_eq!(current().unwrap().key(), before, "maps do not depend on it");

        count_pass(true);
        count_pass(false);
        assert_eq!(take_counts(), (1, 2));
        assert_eq!(take_counts(), (0, 0));
        stop();
        assert!(current().is_none() && !wanted());
    }
}
