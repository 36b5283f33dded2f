//! The whole XR_FB_foveation flow on Vulkan, written the way a Quest app writes it, on the `openxr`
//! crate: nothing in it knows about fovea, so it runs unchanged on a runtime with native support.
//!
//! 1. Instance with XR_KHR_vulkan_enable2 and the four foveation extensions (fovea provides them
//!    where the runtime does not).
//! 2. VkInstance and VkDevice made through the runtime (xrCreateVulkanInstanceKHR,
//!    xrCreateVulkanDeviceKHR), asking for VK_EXT_fragment_density_map where the GPU has it.
//! 3. One two-layer colour swapchain (layer i is eye i) created with `XrSwapchainCreateInfoFoveationFB`
//!    and `FRAGMENT_DENSITY_MAP`, its images enumerated with an `XrSwapchainImageFoveationVulkanFB`
//!    chained on each: one density image per swapchain image.
//! 4. One profile per level (NONE, LOW, MEDIUM, HIGH by default), applied in turn with
//!    xrUpdateSwapchainFB and read back with xrGetSwapchainStateFB while frames run.
//! 5. Every frame a render pass per eye draws fine diagonal stripes in the level's tint into that
//!    eye's layer, and the layers are submitted as a projection layer. Where the device has
//!    VK_EXT_fragment_density_map (with `fragmentDensityMapNonSubsampledImages`, since the runtime's
//!    images are not subsampled) the image's density map is the render pass's fragment density map
//!    attachment, and the periphery is shaded in coarser fragments; elsewhere the fragment shader
//!    samples the density map into the lower-left quarter of each view as a debug overlay
//!    (`render.rs`).
//!
//! Options: `--frames N` (default: each level twice), `--frames-per-level N` (30), `--levels
//! none,low,medium,high`, `--dynamic` (profiles with XR_FOVEATION_DYNAMIC_LEVEL_ENABLED_FB),
//! `--dump DIR` (read back each new density map and the frames where a level starts, and the last
//! frame, as PNGs), `--validate` (the Vulkan validation layer with a messenger; the run fails on
//! any message), `--vk-layer NAME` (one more Vulkan layer for the VkInstance, after validation;
//! repeatable), `--heavy` (a fill-bound fragment shader, for timing eye passes), `--scene room`
//! (instead of the stripes, a room like VR apps draw: `shaders/scene.frag`), `--check-rates`
//! (with `--heavy`: the fragment size each density-map texel was shaded at, read from the pixels
//! of frames read back, against what the map allows), `--eye-tracked` (below), `--help`.
//!
//! `--eye-tracked` makes it an app whose fovea follows the eyes, as Quest Pro apps do
//! (docs/eye-tracking.md#xr_meta_foveation_eye_tracked): it enables `XR_META_foveation_eye_tracked`,
//! chains `XrFoveationEyeTrackedProfileCreateInfoMETA` on every level profile, and, as an app with
//! input does, attaches an action set of its own (a controller's aim pose) and syncs it every frame.
//! The runtime (or fovea) then moves the fovea in the density maps; with `--dump`, a changed map is
//! read back at most every [`EYE_TRACKED_CAPTURE_FRAMES`] frames, not on every move, and a frame
//! every [`EYE_TRACKED_READ_FRAMES`] (`--read-every N` chooses: `fovea demo` reads one a second).
//!
//! The options below make the example a test subject for fovea's injection (docs/injection.md),
//! which foveates applications that never ask, by their eye passes:
//!
//! - `--no-fb`: none of the above foveation: no XR_FB_foveation* extension, no profile, no
//!   density map; the swapchain and passes are plain, as hello_xr's are. Only a layer that injects
//!   shading rates can foveate it.
//! - `--offscreen`: each frame first renders a 256×256 "shadow map" and a 64×36 target sampled from
//!   it, which the eye passes sample into their upper-right corner: passes that are not eye passes
//!   (docs/injection.md#which-passes) and must stay at full rate.
//! - `--double-wide` (with `--no-fb`): one swapchain image twice a view wide, both eyes drawn in one
//!   pass with a viewport and scissor per half, submitted as two projection views whose image rects
//!   are the halves (docs/injection.md#telling-the-views-apart).
//! - `--dynamic-rendering`: every pass begun with `vkCmdBeginRenderingKHR`
//!   (`VK_KHR_dynamic_rendering`) instead of a render pass.
//!
//! `fovea demo` runs it against the simulated headset through the system loader where that is
//! installed. By hand (the checked-in manifests point at target/release):
//!
//! ```sh
//! cargo build --release
//! XR_RUNTIME_JSON=$PWD/manifest/runtime/fovea_sim_runtime.json XR_API_LAYER_PATH=$PWD/manifest \
//!     XR_ENABLE_API_LAYERS=XR_APILAYER_FOVEA_foveation FOVEA_LOG=info \
//!     cargo run --release --example foveated_vulkan
//! ```
//!
//! `cargo test --example foveated_vulkan` runs it the same way (debug build, temporary manifests),
//! reads back what it drew and checks it against fovea's density model.

mod render;

use std::ffi::{c_void, CStr};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::ptr;
use std::sync::Mutex;

use ash::vk::{self, Handle as _};
use openxr as xr;
use xr::sys::Handle as _;

use render::{Layout, Mode, Read, Renderer, Setup, Targets};

const VIEW_TYPE: xr::ViewConfigurationType = xr::ViewConfigurationType::PRIMARY_STEREO;
const LEVELS: [xr::FoveationLevelFB; 4] = [
    xr::FoveationLevelFB::NONE,
    xr::FoveationLevelFB::LOW,
    xr::FoveationLevelFB::MEDIUM,
    xr::FoveationLevelFB::HIGH,
];
/// The stripes' tint per level (linear RGB): grey, green, yellow, red.
const TINTS: [[f32; 4]; 4] = [
    [0.6, 0.6, 0.6, 1.0],
    [0.2, 0.7, 0.2, 1.0],
    [0.7, 0.7, 0.1, 1.0],
    [0.8, 0.2, 0.1, 1.0],
];
/// With `--eye-tracked`, the fewest frames between two density maps read back: the maps change
/// whenever the fovea moves by half a texel, which smooth pursuit does every few frames.
const EYE_TRACKED_CAPTURE_FRAMES: u64 = 30;
/// With `--eye-tracked` and `--dump`, a frame is also read back every this many frames (2 s at
/// 90 Hz), so that the frames show the fovea at a few places.
const EYE_TRACKED_READ_FRAMES: u64 = 180;
/// Long enough at 90 Hz for a level to be seen in a headset, short enough for a test.
const FRAMES_PER_LEVEL: u64 = 30;

/// What to run: the command line.
#[derive(Clone, Debug)]
struct Options {
    frames: u64,
    frames_per_level: u64,
    /// Indices into [`LEVELS`], applied in turn.
    levels: Vec<usize>,
    dynamic: bool,
    /// Read back density maps and frames into [`Outcome::captures`].
    capture: bool,
    /// Write the captures there as PNGs.
    dump: Option<PathBuf>,
    validate: bool,
    /// More Vulkan layers for the VkInstance, after the validation layer (`--vk-layer NAME`).
    vk_layers: Vec<std::ffi::CString>,
    /// The fill-bound fragment shader: a loop of arithmetic per fragment.
    heavy: bool,
    /// The room of `shaders/scene.frag` instead of the stripes (`--scene room`).
    room: bool,
    /// Read the fragment sizes the GPU shaded at from the frames' pixels (`--check-rates`).
    check_rates: bool,
    /// No XR_FB_foveation* extension and no density maps (`--no-fb`).
    no_fb: bool,
    /// Offscreen passes before the eye passes (`--offscreen`).
    offscreen: bool,
    /// How the swapchain holds the views (`--double-wide`).
    layout: Layout,
    /// `vkCmdBeginRenderingKHR` instead of render passes (`--dynamic-rendering`).
    dynamic_rendering: bool,
    /// Eye-tracked profiles and an attached action set (`--eye-tracked`).
    eye_tracked: bool,
    /// With `--eye-tracked` and `--dump`, frames between two frames read back (`--read-every`).
    read_every: u64,
}

impl Options {
    fn parse(args: &[String]) -> Result<Options, String> {
        let mut o = Options {
            frames: 0,
            frames_per_level: FRAMES_PER_LEVEL,
            levels: (0..LEVELS.len()).collect(),
            dynamic: false,
            capture: false,
            dump: None,
            validate: false,
            vk_layers: Vec::new(),
            heavy: false,
            room: false,
            check_rates: false,
            no_fb: false,
            offscreen: false,
            layout: Layout::Array,
            dynamic_rendering: false,
            eye_tracked: false,
            read_every: EYE_TRACKED_READ_FRAMES,
        };
        let mut frames = None;
        let mut levels_given = false;
        let mut it = args.iter();
        while let Some(arg) = it.next() {
            let mut value = || it.next().ok_or(format!("{arg} takes a value"));
            let count = |v: &String| {
                v.parse::<u64>()
                    .ok()
                    .filter(|n| *n > 0)
                    .ok_or(format!("{arg} takes a positive count, not {v:?}"))
            };
            match arg.as_str() {
                "--frames" => frames = Some(count(value()?)?),
                "--frames-per-level" => o.frames_per_level = count(value()?)?,
                "--levels" => {
                    levels_given = true;
                    o.levels = value()?
                        .split(',')
                        .map(|name| {
                            ["none", "low", "medium", "high"]
                                .iter()
                                .position(|l| l.eq_ignore_ascii_case(name.trim()))
                                .ok_or(format!(
                                    "--levels: {name:?} is not one of none, low, medium, high"
                                ))
                        })
                        .collect::<Result<_, _>>()?
                }
                "--dynamic" => o.dynamic = true,
                "--dump" => {
                    o.dump = Some(PathBuf::from(value()?));
                    o.capture = true;
                }
                "--validate" => o.validate = true,
                "--vk-layer" => o.vk_layers.push(
                    std::ffi::CString::new(value()?.as_str())
                        .map_err(|_| format!("{arg}: a layer name has no NUL"))?,
                ),
                "--heavy" => o.heavy = true,
                "--scene" => {
                    o.room = match value()?.as_str() {
                        "stripes" => false,
                        "room" => true,
                        other => return Err(format!("--scene: {other:?} is not stripes or room")),
                    }
                }
                "--check-rates" => {
                    o.check_rates = true;
                    o.capture = true;
                }
                "--no-fb" => o.no_fb = true,
                "--offscreen" => o.offscreen = true,
                "--double-wide" => o.layout = Layout::DoubleWide,
                "--dynamic-rendering" => o.dynamic_rendering = true,
                "--eye-tracked" => o.eye_tracked = true,
                "--read-every" => o.read_every = count(value()?)?,
                other => return Err(format!("unknown option {other:?} (--help lists them)")),
            }
        }
        if o.no_fb {
            // Levels and profiles are the FB API's; without it the stripes keep level NONE's tint
            // and every eye pass is timed under it.
            if levels_given || o.dynamic || o.eye_tracked {
                return Err(
                    "--levels, --dynamic and --eye-tracked choose FB foveation profiles; --no-fb \
                     has none"
                        .into(),
                );
            }
            o.levels = vec![0];
        } else if o.layout == Layout::DoubleWide {
            // The FB path's density maps, overlay and read-back are per layer of an array.
            return Err("--double-wide renders without the FB API: add --no-fb".into());
        }
        if o.room && o.heavy {
            return Err("--scene room and --heavy are two different scenes: pick one".into());
        }
        if o.check_rates && (!o.heavy || o.no_fb) {
            // Only the heavy shader gives every pixel its own colour, which is what tells a
            // coarse fragment from fine ones; and only the FB path has maps to compare with.
            return Err("--check-rates needs --heavy and the FB path (no --no-fb)".into());
        }
        o.frames = frames.unwrap_or(o.levels.len() as u64 * o.frames_per_level * 2);
        Ok(o)
    }
}

/// What a frame read back (with `--dump`, and in the test).
#[derive(Debug)]
struct Capture {
    /// The frame's number, from 0.
    frame: u64,
    /// The level the app had applied: an index into [`LEVELS`].
    level: usize,
    /// Both layers of the density map, R8G8 (a capture is made whenever it changed).
    density: Vec<u8>,
    /// Both layers of the swapchain image, RGBA8 in `format`, on the first frame of each level
    /// and the last frame.
    eyes: Option<Vec<u8>>,
}

/// What a run did: printed at the end, checked by the test.
#[derive(Debug)]
struct Outcome {
    frames: u64,
    /// The swapchain's images: a view's size, or twice its width when double-wide.
    swapchain_size: (u32, u32),
    /// One view's size (the recommended image rect).
    view_size: (u32, u32),
    format: vk::Format,
    /// `(VkImage, width, height)` per swapchain image, from XrSwapchainImageFoveationVulkanFB.
    density_images: Vec<(u64, u32, u32)>,
    /// Each level in the order xrUpdateSwapchainFB applied it (xrGetSwapchainStateFB confirmed).
    levels_applied: Vec<xr::FoveationLevelFB>,
    /// VK_EXT_fragment_density_map and its feature were enabled on the device.
    fdm_enabled: bool,
    /// How the density maps took part in rendering.
    mode: Mode,
    /// The FOVs the views were rendered with (the last xrLocateViews).
    fovs: Vec<xr::Fovf>,
    captures: Vec<Capture>,
    /// Messages from the Vulkan validation layer (`--validate`).
    vk_messages: Vec<String>,
    /// GPU milliseconds of each eye pass, by level (an index into [`LEVELS`]); empty where the
    /// queue has no timestamps.
    eye_ms: [Vec<f64>; 4],
    /// The last frame's projection views as submitted: `(image_array_index, image_rect)`.
    submitted: Vec<(u32, xr::Rect2Di)>,
}

/// What `--help` prints: every option [`Options::parse`] accepts.
const USAGE: &str = "\
usage: foveated_vulkan [options]   (run through an OpenXR runtime; see the file's header)

  --frames N              frames to run (default: each level's frames twice)
  --frames-per-level N    frames before the next level's profile is applied (default 30)
  --levels LIST           comma-separated levels to cycle: none,low,medium,high (default all)
  --dynamic               profiles with XR_FOVEATION_DYNAMIC_LEVEL_ENABLED_FB
  --dump DIR              write each new density map, the frames where a level starts and the
                          last frame, read back from the GPU, as PNGs
  --validate              the Vulkan validation layer with a messenger; any message fails the run
  --vk-layer NAME         one more Vulkan layer for the VkInstance, after validation (repeatable)
  --heavy                 a fill-bound fragment shader (a loop of arithmetic per fragment), for
                          timing eye passes on a real GPU
  --scene stripes|room    what the eyes show: diagonal stripes in the level's tint (default), or
                          a room like VR apps draw (textured wall and floor, hard edges, small
                          text at several eccentricities, a slow pan), the same at every level
  --check-rates           (with --heavy) read the fragment size each density-map texel was shaded
                          at from the frames read back, and compare it with what the map allows
  --no-fb                 no XR_FB_foveation* extension, profile or density map: plain passes, as
                          an app unaware of foveation renders (levels and --dynamic do not apply)
  --offscreen             before the eye passes, render a 256x256 and a 64x36 offscreen target
                          (the second samples the first; the eyes sample the second in a corner)
  --double-wide           (with --no-fb) one swapchain twice a view wide, one pass with a viewport
                          per eye, submitted as two views with the halves as image rects
  --dynamic-rendering     begin passes with vkCmdBeginRenderingKHR instead of render passes
  --eye-tracked           eye-tracked profiles (XR_META_foveation_eye_tracked) and an action set
                          attached and synced each frame, as apps with input do; with --dump, a
                          changed map is written at most every 30 frames and a frame every 180
  --read-every N          (with --eye-tracked and --dump) a frame every N frames instead of 180
  -h, --help              this text";

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.iter().any(|a| a == "--help" || a == "-h") {
        println!("{USAGE}");
        return;
    }
    let options = match Options::parse(&args) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("foveated_vulkan: {e}");
            std::process::exit(2);
        }
    };
    let outcome = run(&options).and_then(|o| {
        if let Some(dir) = &options.dump {
            dump(&o, dir)?;
        }
        if options.check_rates {
            check_rates(&o)?;
        }
        Ok(o)
    });
    match outcome {
        Ok(o) => {
            println!(
                "foveated_vulkan: {} frames on a {}x{} swapchain; density images {:?}; \
                 levels {:?}; FOVs (left, right, up, down) {}; VK_EXT_fragment_density_map {}; \
                 density maps {}",
                o.frames,
                o.swapchain_size.0,
                o.swapchain_size.1,
                o.density_images
                    .iter()
                    .map(|(_, w, h)| format!("{w}x{h}"))
                    .collect::<Vec<_>>(),
                o.levels_applied,
                o.fovs
                    .iter()
                    .map(|f| format!(
                        "{:.1}/{:.1}/{:.1}/{:.1}°",
                        f.angle_left.to_degrees(),
                        f.angle_right.to_degrees(),
                        f.angle_up.to_degrees(),
                        f.angle_down.to_degrees()
                    ))
                    .collect::<Vec<_>>()
                    .join(" and "),
                if o.fdm_enabled { "enabled" } else { "absent" },
                match o.mode {
                    Mode::Attachment => "attached to the render pass",
                    Mode::Overlay => "sampled into the debug overlay (lower left of each eye)",
                    Mode::None => "not used (the device can neither render with nor sample them)",
                    Mode::Absent => "not asked for (--no-fb: no XR_FB_foveation)",
                },
            );
            // The FOVs exactly (`{:?}` of an f32 reads back as the same f32), for tests that
            // compare the maps read back with fovea's model at the runtime's FOVs.
            println!(
                "foveated_vulkan: located FOVs in radians (left,right,up,down per view) {}",
                o.fovs
                    .iter()
                    .map(|f| format!(
                        "{:?},{:?},{:?},{:?}",
                        f.angle_left, f.angle_right, f.angle_up, f.angle_down
                    ))
                    .collect::<Vec<_>>()
                    .join(" ")
            );
            // What the passes and the submitted views were, for tests and scripts.
            println!(
                "foveated_vulkan: {} layout; eye passes begun with {}; offscreen passes {}; \
                 views submitted {}",
                match options.layout {
                    Layout::Array => "array",
                    Layout::DoubleWide => "double-wide",
                },
                if options.dynamic_rendering {
                    "vkCmdBeginRenderingKHR"
                } else {
                    "vkCmdBeginRenderPass"
                },
                if options.offscreen {
                    render::OFFSCREEN
                        .iter()
                        .map(|(w, h)| format!("{w}x{h}"))
                        .collect::<Vec<_>>()
                        .join(",")
                } else {
                    "none".into()
                },
                o.submitted
                    .iter()
                    .map(|(layer, r)| format!(
                        "layer={layer}:{},{}+{}x{}",
                        r.offset.x, r.offset.y, r.extent.width, r.extent.height
                    ))
                    .collect::<Vec<_>>()
                    .join(" "),
            );
            // One line per level, for scripts (scripts/gpu-proof.sh reads them).
            for (name, ms) in ["none", "low", "medium", "high"].iter().zip(&o.eye_ms) {
                if !ms.is_empty() {
                    println!(
                        "foveated_vulkan: eye-pass GPU ms level={name} mean={:.4} passes={}",
                        ms.iter().sum::<f64>() / ms.len() as f64,
                        ms.len()
                    );
                }
            }
            if !o.vk_messages.is_empty() {
                eprintln!(
                    "foveated_vulkan: {} Vulkan validation messages",
                    o.vk_messages.len()
                );
                std::process::exit(1);
            }
        }
        Err(e) => {
            eprintln!("foveated_vulkan: {e}");
            std::process::exit(1);
        }
    }
}

/// An OpenXR result as this example's error.
fn check(r: xr::sys::Result, what: &str) -> Result<(), String> {
    if r.into_raw() >= 0 {
        Ok(())
    } else {
        Err(format!("{what}: {r}"))
    }
}

fn run(options: &Options) -> Result<Outcome, String> {
    // SAFETY: loading the system's OpenXR loader runs its initialisers; that is its purpose.
    let entry = unsafe { xr::Entry::load(&()) }.map_err(|e| format!("OpenXR loader: {e}"))?;
    let available = entry
        .enumerate_extensions()
        .map_err(|e| format!("xrEnumerateInstanceExtensionProperties: {e}"))?;
    if !available.khr_vulkan_enable2 {
        return Err("the runtime lacks XR_KHR_vulkan_enable2".into());
    }
    let fb = available.fb_swapchain_update_state
        && available.fb_foveation
        && available.fb_foveation_configuration
        && available.fb_foveation_vulkan;
    if !fb && !options.no_fb {
        return Err(
            "the runtime (or a layer) lacks the foveation extensions: is fovea enabled \
             (XR_ENABLE_API_LAYERS)?"
                .into(),
        );
    }
    let mut extensions = xr::ExtensionSet::default();
    extensions.khr_vulkan_enable2 = true;
    // With --no-fb, none of them, however many are offered: the app renders as one unaware of
    // foveation.
    extensions.fb_swapchain_update_state = !options.no_fb;
    extensions.fb_foveation = !options.no_fb;
    extensions.fb_foveation_configuration = !options.no_fb;
    extensions.fb_foveation_vulkan = !options.no_fb;
    if options.eye_tracked && !available.meta_foveation_eye_tracked {
        return Err(
            "--eye-tracked: the runtime (or a layer) lacks XR_META_foveation_eye_tracked".into(),
        );
    }
    extensions.meta_foveation_eye_tracked = options.eye_tracked;
    let instance = entry
        .create_instance(
            &xr::ApplicationInfo {
                application_name: "fovea foveated_vulkan",
                application_version: 1,
                engine_name: "none",
                engine_version: 0,
                // The Debian 1.0.20 loader refuses anything newer.
                api_version: xr::Version::new(1, 0, 0),
            },
            &extensions,
            &[],
            &(),
        )
        .map_err(|e| format!("xrCreateInstance: {e}"))?;
    let system = instance
        .system(xr::FormFactor::HEAD_MOUNTED_DISPLAY)
        .map_err(|e| format!("xrGetSystem: {e}"))?;
    let blend_mode = instance
        .enumerate_environment_blend_modes(system, VIEW_TYPE)
        .map_err(|e| format!("xrEnumerateEnvironmentBlendModes: {e}"))?[0];
    let requirements = instance
        .graphics_requirements::<xr::Vulkan>(system)
        .map_err(|e| format!("xrGetVulkanGraphicsRequirements2KHR: {e}"))?;
    // Vulkan 1.1: vkGetPhysicalDeviceFeatures2, which the FDM query needs, is core.
    if requirements.max_api_version_supported < xr::Version::new(1, 1, 0) {
        return Err(format!(
            "the runtime supports Vulkan up to {} only",
            requirements.max_api_version_supported
        ));
    }
    // SAFETY: every Vulkan object below is made, used and destroyed on this thread, in order.
    unsafe { run_vulkan(&instance, system, blend_mode, options) }
}

/// Validation messages seen by [`on_vulkan_message`].
static VK_MESSAGES: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// The debug messenger's callback (`--validate`): prints and keeps warnings and errors.
unsafe extern "system" fn on_vulkan_message(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    _user: *mut c_void,
) -> vk::Bool32 {
    let message = data
        .as_ref()
        .filter(|d| !d.p_message.is_null())
        .map(|d| CStr::from_ptr(d.p_message).to_string_lossy())
        .unwrap_or_default();
    // Not eprintln!: a closed stderr must not panic inside a callback the driver calls.
    let _ = writeln!(
        std::io::stderr(),
        "foveated_vulkan: Vulkan {severity:?}: {message}"
    );
    if let Ok(mut m) = VK_MESSAGES.lock() {
        m.push(message.into_owned());
    }
    vk::FALSE
}

/// The Vulkan side: instance, device, session, swapchain, frames.
///
/// # Safety
/// Plain Vulkan use; see the comments where handles cross between OpenXR and Vulkan.
unsafe fn run_vulkan(
    instance: &xr::Instance,
    system: xr::SystemId,
    blend_mode: xr::EnvironmentBlendMode,
    options: &Options,
) -> Result<Outcome, String> {
    let vk_entry = ash::Entry::load().map_err(|e| format!("Vulkan loader: {e}"))?;
    let gipa = vk_entry.static_fn().get_instance_proc_addr;
    let app_info = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_1);
    let mut layers = Vec::new();
    if options.validate {
        layers.push(c"VK_LAYER_KHRONOS_validation".as_ptr());
    }
    layers.extend(options.vk_layers.iter().map(|l| l.as_ptr()));
    let instance_extensions = [
        ash::ext::debug_utils::NAME.as_ptr(),
        ash::ext::validation_features::NAME.as_ptr(),
    ];
    // Synchronization validation too: hazards between commands and submissions
    // (<https://vulkan.lunarg.com/doc/sdk/latest/linux/synchronization_usage.html>).
    let enabled_features = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
    let mut validation_features =
        vk::ValidationFeaturesEXT::default().enabled_validation_features(&enabled_features);
    let mut messenger_info = vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(
            vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
        )
        .message_type(
            vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
        )
        .pfn_user_callback(Some(on_vulkan_message));
    let mut instance_info = vk::InstanceCreateInfo::default()
        .application_info(&app_info)
        .enabled_layer_names(&layers);
    if options.validate {
        // Chained, the messenger also sees vkCreateInstance and vkDestroyInstance.
        instance_info = instance_info
            .enabled_extension_names(&instance_extensions)
            .push_next(&mut messenger_info)
            .push_next(&mut validation_features);
    }
    let raw_instance = instance
        .create_vulkan_instance(
            system,
            std::mem::transmute::<
                vk::PFN_vkGetInstanceProcAddr,
                xr::sys::platform::VkGetInstanceProcAddr,
            >(gipa),
            &instance_info as *const _ as *const _,
        )
        .map_err(|e| format!("xrCreateVulkanInstanceKHR: {e}"))?
        .map_err(|r| format!("vkCreateInstance: {:?}", vk::Result::from_raw(r)))?;
    let vk_instance = ash::Instance::load(
        vk_entry.static_fn(),
        vk::Instance::from_raw(raw_instance as u64),
    );
    let debug_utils = options
        .validate
        .then(|| ash::ext::debug_utils::Instance::new(&vk_entry, &vk_instance));
    let messenger = match &debug_utils {
        Some(d) => d
            .create_debug_utils_messenger(&messenger_info, None)
            .map_err(|e| format!("vkCreateDebugUtilsMessengerEXT: {e}"))?,
        None => vk::DebugUtilsMessengerEXT::null(),
    };
    let result = with_instance(
        instance,
        system,
        blend_mode,
        options,
        (&vk_instance, raw_instance),
    );
    if let Some(d) = &debug_utils {
        d.destroy_debug_utils_messenger(messenger, None);
    }
    vk_instance.destroy_instance(None);
    result.map(|mut o| {
        o.vk_messages = VK_MESSAGES
            .lock()
            .map(|mut m| std::mem::take(&mut *m))
            .unwrap_or_default();
        o
    })
}

/// The device, and everything made on it.
///
/// # Safety
/// `vk_instance` is the instance the runtime made for `raw_instance`.
unsafe fn with_instance(
    instance: &xr::Instance,
    system: xr::SystemId,
    blend_mode: xr::EnvironmentBlendMode,
    options: &Options,
    (vk_instance, raw_instance): (&ash::Instance, xr::sys::platform::VkInstance),
) -> Result<Outcome, String> {
    let gipa = ash::Entry::load()
        .map_err(|e| format!("Vulkan loader: {e}"))?
        .static_fn()
        .get_instance_proc_addr;
    let physical_device = vk::PhysicalDevice::from_raw(
        instance
            .vulkan_graphics_device(system, raw_instance)
            .map_err(|e| format!("xrGetVulkanGraphicsDevice2KHR: {e}"))? as u64,
    );
    let queue_family = vk_instance
        .get_physical_device_queue_family_properties(physical_device)
        .iter()
        .position(|q| q.queue_flags.contains(vk::QueueFlags::GRAPHICS))
        .ok_or("the Vulkan device has no graphics queue")? as u32;

    // XR_FB_foveation's FRAGMENT_DENSITY_MAP bit makes the app responsible for enabling the
    // extension and its feature where the GPU has them. An app without the FB API (--no-fb) never
    // asks.
    let offered = vk_instance
        .enumerate_device_extension_properties(physical_device)
        .map_err(|e| format!("vkEnumerateDeviceExtensionProperties: {e}"))?;
    let has = |name: &CStr| {
        offered
            .iter()
            .any(|e| e.extension_name_as_c_str() == Ok(name))
    };
    let has_fdm = !options.no_fb && has(ash::ext::fragment_density_map::NAME);
    let mut fdm_query = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default();
    if has_fdm {
        let mut features = vk::PhysicalDeviceFeatures2::default().push_next(&mut fdm_query);
        vk_instance.get_physical_device_features2(physical_device, &mut features);
    }
    let fdm_enabled = has_fdm && fdm_query.fragment_density_map == vk::TRUE;
    let non_subsampled = fdm_query.fragment_density_map_non_subsampled_images == vk::TRUE;
    let mut fdm_features = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default()
        .fragment_density_map(true)
        .fragment_density_map_non_subsampled_images(non_subsampled);
    let mut device_extensions = Vec::new();
    let priorities = [1.0];
    let queues = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(queue_family)
        .queue_priorities(&priorities)];
    let mut device_info = vk::DeviceCreateInfo::default().queue_create_infos(&queues);
    if fdm_enabled {
        device_extensions.push(ash::ext::fragment_density_map::NAME.as_ptr());
        device_info = device_info.push_next(&mut fdm_features);
    }
    // VK_KHR_dynamic_rendering on a Vulkan 1.1 instance, with what it requires there
    // (VK_KHR_depth_stencil_resolve, which requires VK_KHR_create_renderpass2):
    // <https://registry.khronos.org/vulkan/specs/1.3-extensions/man/html/VK_KHR_dynamic_rendering.html>.
    let mut dynamic_rendering =
        vk::PhysicalDeviceDynamicRenderingFeatures::default().dynamic_rendering(true);
    if options.dynamic_rendering {
        let needed = [
            ash::khr::dynamic_rendering::NAME,
            ash::khr::depth_stencil_resolve::NAME,
            ash::khr::create_renderpass2::NAME,
        ];
        if let Some(missing) = needed.iter().find(|n| !has(n)) {
            return Err(format!(
                "--dynamic-rendering: the device lacks {}",
                missing.to_string_lossy()
            ));
        }
        device_extensions.extend(needed.iter().map(|n| n.as_ptr()));
        device_info = device_info.push_next(&mut dynamic_rendering);
    }
    device_info = device_info.enabled_extension_names(&device_extensions);
    let raw_device = instance
        .create_vulkan_device(
            system,
            std::mem::transmute::<
                vk::PFN_vkGetInstanceProcAddr,
                xr::sys::platform::VkGetInstanceProcAddr,
            >(gipa),
            physical_device.as_raw() as usize as _,
            &device_info as *const _ as *const _,
        )
        .map_err(|e| format!("xrCreateVulkanDeviceKHR: {e}"))?
        .map_err(|r| format!("vkCreateDevice: {:?}", vk::Result::from_raw(r)))?;
    let device = ash::Device::load(
        vk_instance.fp_v1_0(),
        vk::Device::from_raw(raw_device as u64),
    );
    let queue = device.get_device_queue(queue_family, 0);
    let sampled = vk_instance
        .get_physical_device_format_properties(physical_device, vk::Format::R8G8_UNORM)
        .optimal_tiling_features
        .contains(vk::FormatFeatureFlags::SAMPLED_IMAGE);
    // The runtime's swapchain images are not subsampled, so rendering them with a density map
    // needs fragmentDensityMapNonSubsampledImages (VUID-VkFramebufferCreateInfo-renderPass-02553).
    // fovea leaves the maps in FRAGMENT_DENSITY_MAP_OPTIMAL_EXT on any device with FDM enabled, where
    // they cannot be sampled either.
    let mode = match (fdm_enabled, non_subsampled, sampled) {
        _ if options.no_fb => Mode::Absent,
        (true, true, _) => Mode::Attachment,
        (false, _, true) => Mode::Overlay,
        _ => Mode::None,
    };

    let result = session_loop(
        instance,
        system,
        blend_mode,
        options,
        (vk_instance, physical_device),
        (&device, queue, queue_family),
        (raw_instance, raw_device),
        mode,
    );
    // OpenXR objects are gone (dropped in `session_loop`) before the Vulkan objects they used.
    device.device_wait_idle().ok();
    device.destroy_device(None);
    result.map(|mut o| {
        o.fdm_enabled = fdm_enabled;
        o
    })
}

/// Session, foveated swapchain, profiles and the frame loop; every OpenXR object made here is
/// dropped before it returns.
///
/// # Safety
/// `device` must be the device the runtime created; `queue` one of its queues.
#[allow(clippy::too_many_arguments)]
unsafe fn session_loop(
    instance: &xr::Instance,
    system: xr::SystemId,
    blend_mode: xr::EnvironmentBlendMode,
    options: &Options,
    (vk_instance, physical_device): (&ash::Instance, vk::PhysicalDevice),
    (device, queue, queue_family): (&ash::Device, vk::Queue, u32),
    (raw_instance, raw_device): (xr::sys::platform::VkInstance, xr::sys::platform::VkDevice),
    mode: Mode,
) -> Result<Outcome, String> {
    let (session, mut frame_wait, mut frame_stream) = instance
        .create_session::<xr::Vulkan>(
            system,
            &xr::vulkan::SessionCreateInfo {
                instance: raw_instance,
                physical_device: physical_device.as_raw() as usize as _,
                device: raw_device,
                queue_family_index: queue_family,
                queue_index: 0,
            },
        )
        .map_err(|e| format!("xrCreateSession: {e}"))?;
    let stage = session
        .create_reference_space(xr::ReferenceSpaceType::LOCAL, xr::Posef::IDENTITY)
        .map_err(|e| format!("xrCreateReferenceSpace: {e}"))?;

    // The swapchain: the `openxr` crate's create_swapchain takes no next chain, so the foveation
    // struct goes in through the raw call and the handle is wrapped afterwards.
    let views = instance
        .enumerate_view_configuration_views(system, VIEW_TYPE)
        .map_err(|e| format!("xrEnumerateViewConfigurationViews: {e}"))?;
    let (width, height) = (
        views[0].recommended_image_rect_width,
        views[0].recommended_image_rect_height,
    );
    let formats = session
        .enumerate_swapchain_formats()
        .map_err(|e| format!("xrEnumerateSwapchainFormats: {e}"))?;
    let format = [vk::Format::R8G8B8A8_SRGB, vk::Format::B8G8R8A8_SRGB]
        .into_iter()
        .find(|f| formats.contains(&(f.as_raw() as u32)))
        .ok_or(format!("no sRGB colour format among {formats:?}"))?;
    let foveation = xr::sys::SwapchainCreateInfoFoveationFB {
        ty: xr::sys::SwapchainCreateInfoFoveationFB::TYPE,
        next: ptr::null_mut(),
        flags: xr::SwapchainCreateFoveationFlagsFB::FRAGMENT_DENSITY_MAP,
    };
    let mut usage = xr::SwapchainUsageFlags::COLOR_ATTACHMENT;
    if options.capture {
        usage |= xr::SwapchainUsageFlags::TRANSFER_SRC;
    }
    // An array of two (view i in layer i), or one layer twice a view wide (view i in half i).
    let (image_width, array_size) = match options.layout {
        Layout::Array => (width, 2),
        Layout::DoubleWide => (2 * width, 1),
    };
    let create_info = xr::sys::SwapchainCreateInfo {
        ty: xr::sys::SwapchainCreateInfo::TYPE,
        next: if options.no_fb {
            ptr::null()
        } else {
            &foveation as *const _ as *const c_void
        },
        create_flags: xr::SwapchainCreateFlags::EMPTY,
        usage_flags: usage,
        format: i64::from(format.as_raw()),
        sample_count: 1,
        width: image_width,
        height,
        face_count: 1,
        array_size,
        mip_count: 1,
    };
    let mut handle = xr::sys::Swapchain::NULL;
    check(
        (instance.fp().create_swapchain)(session.as_raw(), &create_info, &mut handle),
        if options.no_fb {
            "xrCreateSwapchain"
        } else {
            "xrCreateSwapchain with FRAGMENT_DENSITY_MAP"
        },
    )?;
    let mut swapchain = xr::Swapchain::<xr::Vulkan>::from_raw(session.clone(), handle);

    // The images, each with its density image chained (two-call idiom).
    let mut count = 0;
    check(
        (instance.fp().enumerate_swapchain_images)(handle, 0, &mut count, ptr::null_mut()),
        "xrEnumerateSwapchainImages",
    )?;
    let mut density = vec![
        xr::sys::SwapchainImageFoveationVulkanFB {
            ty: xr::sys::SwapchainImageFoveationVulkanFB::TYPE,
            next: ptr::null_mut(),
            image: 0,
            width: 0,
            height: 0,
        };
        count as usize
    ];
    let mut images: Vec<xr::sys::SwapchainImageVulkanKHR> = density
        .iter_mut()
        .map(|d| xr::sys::SwapchainImageVulkanKHR {
            ty: xr::sys::SwapchainImageVulkanKHR::TYPE,
            next: if options.no_fb {
                ptr::null_mut()
            } else {
                d as *mut _ as *mut c_void
            },
            image: 0,
        })
        .collect();
    check(
        (instance.fp().enumerate_swapchain_images)(
            handle,
            count,
            &mut count,
            images.as_mut_ptr() as *mut xr::sys::SwapchainImageBaseHeader,
        ),
        "xrEnumerateSwapchainImages",
    )?;
    let density_images: Vec<(u64, u32, u32)> = if options.no_fb {
        Vec::new()
    } else {
        density
            .iter()
            .map(|d| (d.image, d.width, d.height))
            .collect()
    };
    if let Some(i) = density_images.iter().position(|(image, ..)| *image == 0) {
        return Err(format!("swapchain image {i} came without a density image"));
    }

    // One profile per level, made up front: profiles may be destroyed once applied, but keeping
    // them lets the loop switch levels without creating anything per frame.
    let dynamic = if options.dynamic {
        xr::FoveationDynamicFB::LEVEL_ENABLED
    } else {
        xr::FoveationDynamicFB::DISABLED
    };
    let profiles = options
        .levels
        .iter()
        .filter(|_| !options.no_fb)
        .map(|&i| {
            let level = xr::FoveationLevelProfile {
                level: LEVELS[i],
                vertical_offset: 0.0,
                dynamic,
            };
            if options.eye_tracked {
                eye_tracked_profile(instance, &session, level)
            } else {
                session.create_foveation_profile(Some(level))
            }
            .map_err(|e| format!("xrCreateFoveationProfileFB({:?}): {e}", LEVELS[i]))
        })
        .collect::<Result<Vec<_>, String>>()?;
    let input = if options.eye_tracked {
        Some(attach_input(instance, &session)?)
    } else {
        None
    };
    let update_state = instance.exts().fb_swapchain_update_state;
    if update_state.is_none() && !options.no_fb {
        return Err("XR_FB_swapchain_update_state was enabled but has no functions".into());
    }
    let mut levels_applied = Vec::new();
    let mut apply = |i: usize| -> Result<(), String> {
        // Nothing to apply without the FB API (--no-fb).
        let Some(update_state) = update_state else {
            return Ok(());
        };
        let state = xr::sys::SwapchainStateFoveationFB {
            ty: xr::sys::SwapchainStateFoveationFB::TYPE,
            next: ptr::null_mut(),
            flags: xr::SwapchainStateFoveationFlagsFB::EMPTY,
            profile: profiles[i].as_raw(),
        };
        check(
            (update_state.update_swapchain)(handle, &state as *const _ as *const _),
            "xrUpdateSwapchainFB",
        )?;
        let mut read = xr::sys::SwapchainStateFoveationFB {
            profile: xr::sys::FoveationProfileFB::NULL,
            ..state
        };
        check(
            (update_state.get_swapchain_state)(handle, &mut read as *mut _ as *mut _),
            "xrGetSwapchainStateFB",
        )?;
        if read.profile != state.profile {
            return Err(format!(
                "xrGetSwapchainStateFB returned another profile after {:?}",
                LEVELS[options.levels[i]]
            ));
        }
        levels_applied.push(LEVELS[options.levels[i]]);
        Ok(())
    };

    let vk_images: Vec<vk::Image> = images
        .iter()
        .map(|i| vk::Image::from_raw(i.image))
        .collect();
    let vk_density: Vec<(vk::Image, u32, u32)> = density_images
        .iter()
        .map(|&(image, w, h)| (vk::Image::from_raw(image), w, h))
        .collect();
    let mut renderer = Renderer::new(
        (vk_instance, physical_device),
        device,
        (queue, queue_family),
        &Targets {
            format,
            extent: (width, height),
            layout: options.layout,
            images: &vk_images,
            density: &vk_density,
        },
        mode,
        Setup {
            readback: options.capture,
            heavy: options.heavy,
            room: options.room,
            offscreen: options.offscreen,
            dynamic_rendering: options.dynamic_rendering,
        },
    )?;

    let mut event_storage = xr::EventDataBuffer::new();
    let mut running = false;
    let mut frames = 0u64;
    let mut applied = None;
    let mut exit_requested = false;
    let mut fovs = Vec::new();
    let mut captures: Vec<Capture> = Vec::new();
    let mut eye_ms: [Vec<f64>; 4] = Default::default();
    let mut submitted = Vec::new();
    // The first frame drawn at each level is read back (frames the runtime says not to render
    // draw nothing).
    let mut read_eyes = false;
    let result = 'main: loop {
        while let Some(event) = instance
            .poll_event(&mut event_storage)
            .map_err(|e| format!("xrPollEvent: {e}"))?
        {
            match event {
                xr::Event::SessionStateChanged(e) => match e.state() {
                    xr::SessionState::READY => {
                        session
                            .begin(VIEW_TYPE)
                            .map_err(|e| format!("xrBeginSession: {e}"))?;
                        running = true;
                    }
                    xr::SessionState::STOPPING => {
                        session.end().map_err(|e| format!("xrEndSession: {e}"))?;
                        running = false;
                    }
                    xr::SessionState::EXITING | xr::SessionState::LOSS_PENDING => {
                        break 'main Ok(())
                    }
                    _ => {}
                },
                xr::Event::InstanceLossPending(_) => {
                    break 'main Err("instance loss pending".to_string())
                }
                _ => {}
            }
        }
        if !running {
            std::thread::sleep(std::time::Duration::from_millis(10));
            continue;
        }
        // Frames go on until the runtime says STOPPING, at the level they had.
        if frames >= options.frames && !exit_requested {
            session
                .request_exit()
                .map_err(|e| format!("xrRequestExitSession: {e}"))?;
            exit_requested = true;
        }
        // A new level every `frames_per_level` frames, applied between frames.
        let wanted = (frames / options.frames_per_level) as usize % options.levels.len();
        if applied != Some(wanted) && !exit_requested {
            apply(wanted)?;
            applied = Some(wanted);
            read_eyes = options.capture;
        }
        let level = options.levels[applied.unwrap_or(0)];
        let state = frame_wait.wait().map_err(|e| format!("xrWaitFrame: {e}"))?;
        frame_stream
            .begin()
            .map_err(|e| format!("xrBeginFrame: {e}"))?;
        if let Some((set, _)) = &input {
            session
                .sync_actions(&[set.into()])
                .map_err(|e| format!("xrSyncActions: {e}"))?;
        }
        if !state.should_render {
            frame_stream
                .end(state.predicted_display_time, blend_mode, &[])
                .map_err(|e| format!("xrEndFrame: {e}"))?;
            continue;
        }
        let (_, located) = session
            .locate_views(VIEW_TYPE, state.predicted_display_time, &stage)
            .map_err(|e| format!("xrLocateViews: {e}"))?;
        let index = swapchain
            .acquire_image()
            .map_err(|e| format!("xrAcquireSwapchainImage: {e}"))? as usize;
        swapchain
            .wait_image(xr::Duration::INFINITE)
            .map_err(|e| format!("xrWaitSwapchainImage: {e}"))?;
        let read = Read {
            eyes: read_eyes
                || (options.capture && frames + 1 == options.frames)
                || (options.capture
                    && options.eye_tracked
                    && frames > 0
                    && frames % options.read_every == 0),
            density: options.capture,
        };
        // The room is the same at every level; its push constant's w is the frame, for the pan.
        let push = if options.room {
            [0.0, 0.0, 0.0, frames as f32]
        } else {
            TINTS[level]
        };
        eye_ms[level].extend(renderer.draw(index, push, read)?);
        read_eyes = false;
        if options.capture {
            let map = renderer.density(index).unwrap_or_default();
            let changed = captures.last().is_none_or(|c| {
                c.density != map
                    && (!options.eye_tracked || frames >= c.frame + EYE_TRACKED_CAPTURE_FRAMES)
            });
            if changed || read.eyes {
                captures.push(Capture {
                    frame: frames,
                    level,
                    density: map.to_vec(),
                    eyes: read
                        .eyes
                        .then(|| renderer.eyes().unwrap_or_default().to_vec()),
                });
            }
        }
        swapchain
            .release_image()
            .map_err(|e| format!("xrReleaseSwapchainImage: {e}"))?;
        // View i: layer i of the array, or half i of the double-wide image.
        let sub_images: [(u32, xr::Rect2Di); 2] = std::array::from_fn(|eye| {
            let (layer, x) = match options.layout {
                Layout::Array => (eye as u32, 0),
                Layout::DoubleWide => (0, eye as i32 * width as i32),
            };
            let extent = xr::Extent2Di {
                width: width as i32,
                height: height as i32,
            };
            let offset = xr::Offset2Di { x, y: 0 };
            (layer, xr::Rect2Di { offset, extent })
        });
        let projection_views: [_; 2] = std::array::from_fn(|eye| {
            xr::CompositionLayerProjectionView::new()
                .pose(located[eye].pose)
                .fov(located[eye].fov)
                .sub_image(
                    xr::SwapchainSubImage::new()
                        .swapchain(&swapchain)
                        .image_array_index(sub_images[eye].0)
                        .image_rect(sub_images[eye].1),
                )
        });
        frame_stream
            .end(
                state.predicted_display_time,
                blend_mode,
                &[&xr::CompositionLayerProjection::new()
                    .space(&stage)
                    .views(&projection_views)],
            )
            .map_err(|e| format!("xrEndFrame: {e}"))?;
        if fovs.is_empty() {
            fovs = located.iter().map(|v| v.fov).collect();
        }
        submitted = sub_images.to_vec();
        frames += 1;
    };
    renderer.destroy();
    drop((
        input,
        profiles,
        swapchain,
        stage,
        frame_stream,
        frame_wait,
        session,
    ));
    result.map(|()| Outcome {
        frames,
        swapchain_size: (image_width, height),
        view_size: (width, height),
        format,
        density_images,
        levels_applied,
        fdm_enabled: false,
        mode,
        fovs,
        captures,
        vk_messages: Vec::new(),
        eye_ms,
        submitted,
    })
}

/// A profile of `level` created with `XrFoveationEyeTrackedProfileCreateInfoMETA` chained on its
/// level struct: the `openxr` crate's `create_foveation_profile` takes no chain there, so the raw
/// call makes it and the handle is wrapped.
fn eye_tracked_profile(
    instance: &xr::Instance,
    session: &xr::Session<xr::Vulkan>,
    level: xr::FoveationLevelProfile,
) -> xr::Result<xr::FoveationProfileFB> {
    let fp = instance
        .exts()
        .fb_foveation
        .ok_or(xr::sys::Result::ERROR_EXTENSION_NOT_PRESENT)?;
    let tracked = xr::sys::FoveationEyeTrackedProfileCreateInfoMETA {
        ty: xr::sys::FoveationEyeTrackedProfileCreateInfoMETA::TYPE,
        next: ptr::null(),
        flags: xr::sys::FoveationEyeTrackedProfileCreateFlagsMETA::EMPTY,
    };
    let level_info = xr::sys::FoveationLevelProfileCreateInfoFB {
        ty: xr::sys::FoveationLevelProfileCreateInfoFB::TYPE,
        next: &tracked as *const _ as *mut c_void,
        level: level.level,
        vertical_offset: level.vertical_offset,
        dynamic: level.dynamic,
    };
    let info = xr::sys::FoveationProfileCreateInfoFB {
        ty: xr::sys::FoveationProfileCreateInfoFB::TYPE,
        next: &level_info as *const _ as *mut c_void,
    };
    let mut profile = xr::sys::FoveationProfileFB::NULL;
    // SAFETY: a live session; `info` and its chain outlive the call.
    let r = unsafe { (fp.create_foveation_profile)(session.as_raw(), &info, &mut profile) };
    if r.into_raw() < 0 {
        return Err(r);
    }
    // SAFETY: a profile just made on this instance, owned by the wrapper from here on.
    Ok(unsafe { xr::FoveationProfileFB::from_raw(instance.clone(), profile) })
}

/// An action set with a controller's aim pose, bound for the simple controller and attached to
/// `session`: what an app with input has, and what fovea's gaze action set rides along with
/// (docs/eye-tracking.md#applications-that-do-not-cooperate: an app that attaches nothing gets
/// fovea's set attached alone only after a grace period).
fn attach_input(
    instance: &xr::Instance,
    session: &xr::Session<xr::Vulkan>,
) -> Result<(xr::ActionSet, xr::Action<xr::Posef>), String> {
    let set = instance
        .create_action_set("gameplay", "Gameplay", 0)
        .map_err(|e| format!("xrCreateActionSet: {e}"))?;
    let aim = set
        .create_action::<xr::Posef>("aim", "Aim", &[])
        .map_err(|e| format!("xrCreateAction: {e}"))?;
    let path = |p: &str| {
        instance
            .string_to_path(p)
            .map_err(|e| format!("xrStringToPath({p}): {e}"))
    };
    instance
        .suggest_interaction_profile_bindings(
            path("/interaction_profiles/khr/simple_controller")?,
            &[xr::Binding::new(
                &aim,
                path("/user/hand/left/input/aim/pose")?,
            )],
        )
        .map_err(|e| format!("xrSuggestInteractionProfileBindings: {e}"))?;
    session
        .attach_action_sets(&[&set])
        .map_err(|e| format!("xrAttachSessionActionSets: {e}"))?;
    Ok((set, aim))
}

/// Writes the captures as PNGs, named for the frame and the app's level:
/// `fNNNNN_LEVEL_density_{left,right}.png` (red = horizontal density, green = vertical; one pixel
/// per texel) and `fNNNNN_LEVEL_{left,right}.png` (the frame as drawn).
fn dump(o: &Outcome, dir: &Path) -> Result<(), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    // One view's extent: the swapchain's, or half of it when double-wide.
    let (w, h) = o.view_size;
    let (dw, dh) = o.density_images.first().map_or((0, 0), |d| (d.1, d.2));
    let mut written = 0;
    for c in &o.captures {
        let level = ["none", "low", "medium", "high"][c.level];
        for (layer, eye) in ["left", "right"].into_iter().enumerate() {
            let texels = (dw * dh) as usize;
            let maps = (texels > 0).then(|| c.density.chunks_exact(texels * 2));
            if let Some(map) = maps.and_then(|mut m| m.nth(layer)) {
                let rgb: Vec<u8> = map.chunks_exact(2).flat_map(|t| [t[0], t[1], 0]).collect();
                let path = dir.join(format!("f{:05}_{level}_density_{eye}.png", c.frame));
                write_png(&path, (dw, dh), png::ColorType::Rgb, &rgb)?;
                written += 1;
            }
            if let Some(eyes) = &c.eyes {
                let pixels = (w * h) as usize * 4;
                let mut rgba = eyes[layer * pixels..][..pixels].to_vec();
                if o.format == vk::Format::B8G8R8A8_SRGB {
                    rgba.chunks_exact_mut(4).for_each(|p| p.swap(0, 2));
                }
                let path = dir.join(format!("f{:05}_{level}_{eye}.png", c.frame));
                write_png(&path, (w, h), png::ColorType::Rgba, &rgba)?;
                written += 1;
            }
        }
    }
    println!("foveated_vulkan: wrote {written} PNGs to {}", dir.display());
    Ok(())
}

/// The fragment sizes a GPU with rates up to 4×4 offers (NVIDIA, NVK, Intel): every power-of-two
/// size with an aspect of at most 2.
const RATES_UP_TO_4X4: [[u32; 2]; 7] = [[1, 1], [1, 2], [2, 1], [2, 2], [2, 4], [4, 2], [4, 4]];

/// The fragment size one `texel`-square tile of an eye was shaded at, read from its pixels (RGBA8
/// rows of `width`): the largest power-of-two width (height) such that every aligned run of that
/// many pixels in each row (column) has one colour. With the heavy shader every fragment has its
/// own colour, so a fine tile is never read as coarse: that would take every pair of its
/// neighbouring fragments to agree.
fn shaded_size(pixels: &[u8], width: usize, x0: usize, y0: usize, texel: usize) -> [u32; 2] {
    let at = |x: usize, y: usize| &pixels[(y * width + x) * 4..][..3];
    let uniform = |horizontal: bool, n: usize| {
        (0..texel).all(|a| {
            (0..texel).step_by(n).all(|b| {
                let p = |k: usize| {
                    if horizontal {
                        at(x0 + b + k, y0 + a)
                    } else {
                        at(x0 + a, y0 + b + k)
                    }
                };
                (1..n).all(|k| p(k) == p(0))
            })
        })
    };
    let size = |horizontal| {
        [4u32, 2]
            .into_iter()
            .find(|&n| uniform(horizontal, n as usize))
            .unwrap_or(1)
    };
    [size(true), size(false)]
}

/// `--check-rates`: for each frame read back with its map, the fragment size every whole
/// density-map texel of each eye was shaded at, from the pixels, against the map: never coarser
/// than the texel's density allows (the extension's rule,
/// <https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#fragmentdensitymapops>), and
/// how many texels got the full allowance as a GPU with rates up to 4×4 gives it. Fails on any
/// texel shaded coarser than its map allows.
fn check_rates(o: &Outcome) -> Result<(), String> {
    let (w, h) = o.view_size;
    let (dw, dh) = o.density_images.first().map_or((0, 0), |d| (d.1, d.2));
    if o.mode != Mode::Attachment || dw == 0 {
        println!("foveated_vulkan: rates not checked: the density maps were not attached");
        return Ok(());
    }
    // The density texel: the view over the map, rounded up (the map covers the whole view).
    let texel = (w.div_ceil(dw)).max(h.div_ceil(dh)) as usize;
    let texels = (dw * dh) as usize;
    let mut coarser = 0;
    for c in &o.captures {
        let Some(eyes) = &c.eyes else { continue };
        let level = ["none", "low", "medium", "high"][c.level];
        for (layer, eye) in ["left", "right"].into_iter().enumerate() {
            let Some(map) = c.density.chunks_exact(texels * 2).nth(layer) else {
                continue;
            };
            let pixels = &eyes[layer * (w * h) as usize * 4..][..(w * h) as usize * 4];
            let (mut whole, mut allowed, mut full) = (0, 0, 0);
            let mut sizes = std::collections::BTreeMap::new();
            for ty in 0..(h as usize / texel) {
                for tx in 0..(w as usize / texel) {
                    let d = &map[(ty * dw as usize + tx) * 2..][..2];
                    let allowance = [
                        fovea_model::shading_rate::axis_size(d[0], 4),
                        fovea_model::shading_rate::axis_size(d[1], 4),
                    ];
                    let got = shaded_size(pixels, w as usize, tx * texel, ty * texel, texel);
                    whole += 1;
                    *sizes.entry(format!("{}x{}", got[0], got[1])).or_insert(0) += 1;
                    if got[0] <= allowance[0] && got[1] <= allowance[1] {
                        allowed += 1;
                    }
                    if got == fovea_model::shading_rate::clamp(allowance, &RATES_UP_TO_4X4) {
                        full += 1;
                    }
                }
            }
            coarser += whole - allowed;
            println!(
                "foveated_vulkan: shaded sizes from pixels, frame {} level={level} eye={eye}: \
                 {whole} texels of {texel}x{texel}; {} coarser than the map allows; {full} at \
                 the map's full allowance (rates up to 4x4); sizes {sizes:?}",
                c.frame,
                whole - allowed,
            );
        }
    }
    if coarser > 0 {
        return Err(format!(
            "{coarser} texels were shaded coarser than their density map allows"
        ));
    }
    Ok(())
}

fn write_png(
    path: &Path,
    (width, height): (u32, u32),
    colour: png::ColorType,
    data: &[u8],
) -> Result<(), String> {
    let file = std::fs::File::create(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    enc.set_color(colour);
    enc.set_depth(png::BitDepth::Eight);
    enc.write_header()
        .and_then(|mut w| w.write_image_data(data))
        .map_err(|e| format!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    //! The example against the simulated headset on lavapipe, through the system loader, fovea
    //! enabled by the environment, the Vulkan validation layer watching. One run: the loader allows
    //! one instance per process and reads the environment.

    use std::path::{Path, PathBuf};

    use fovea_harness::{artifact, skip, FOVEA_LAYER};
    use fovea_model::density::{Grid, Level, Pattern, Rect, View};
    use fovea_model::maps::{fill_layers, Inputs};
    use fovea_model::Fov;

    use super::*;

    /// `--help` names every option the parser takes, and each is accepted as written there.
    #[test]
    fn help_lists_every_option() {
        let taken = [
            vec!["--frames", "3"],
            vec!["--frames-per-level", "2"],
            vec!["--levels", "none,high"],
            vec!["--dynamic"],
            vec!["--dump", "/tmp/x"],
            vec!["--validate"],
            vec!["--vk-layer", "VK_LAYER_X"],
            vec!["--heavy"],
            vec!["--scene", "room"],
            vec!["--no-fb"],
            vec!["--offscreen"],
            vec!["--double-wide", "--no-fb"],
            vec!["--dynamic-rendering"],
            vec!["--eye-tracked"],
            vec!["--read-every", "30"],
            vec!["--check-rates", "--heavy"],
        ];
        for args in &taken {
            assert!(USAGE.contains(args[0]), "{} missing from --help", args[0]);
            let owned: Vec<String> = args.iter().map(|a| a.to_string()).collect();
            assert!(Options::parse(&owned).is_ok(), "{args:?}");
        }
        let listed = USAGE.matches("\n  --").count();
        assert_eq!(
            listed,
            taken.len(),
            "an option in --help the test does not know"
        );
        let err = Options::parse(&["--nope".to_string()]).unwrap_err();
        assert!(err.contains("--help"), "{err}");
        let err = Options::parse(&["--check-rates".to_string()]).unwrap_err();
        assert!(err.contains("--heavy"), "{err}");
        let args = |a: &[&str]| a.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let err = Options::parse(&args(&["--scene", "room", "--heavy"])).unwrap_err();
        assert!(err.contains("pick one"), "{err}");
        let err = Options::parse(&args(&["--scene", "forest"])).unwrap_err();
        assert!(err.contains("stripes or room"), "{err}");
        assert!(!Options::parse(&args(&["--scene", "stripes"])).unwrap().room);
    }

    /// The shaded size of a tile is read from its pixels: blocks of one colour as large as the
    /// fragments, every fragment its own colour.
    #[test]
    fn shaded_sizes_are_read_from_pixels() {
        let (width, texel) = (32usize, 16usize);
        // Tile (0,0) in 4x2 fragments, tile (16,0) in 1x1 fragments, tile (0,16) in 2x4.
        let tile = |x: usize, y: usize| -> [u32; 2] {
            match (x / texel, y / texel) {
                (0, 0) => [4, 2],
                (1, 0) => [1, 1],
                (0, 1) => [2, 4],
                _ => [4, 4],
            }
        };
        let mut pixels = vec![0u8; width * width * 4];
        for y in 0..width {
            for x in 0..width {
                let [fw, fh] = tile(x, y).map(|v| v as usize);
                // A colour per fragment: its index in the image.
                let id = ((y / fh) * width + x / fw) as u32;
                pixels[(y * width + x) * 4..][..4].copy_from_slice(&id.to_le_bytes());
            }
        }
        // Alpha carries the id's top byte; only RGB is compared, and ids stay below 2^24.
        for (x, y) in [(0, 0), (16, 0), (0, 16), (16, 16)] {
            assert_eq!(
                shaded_size(&pixels, width, x, y, texel),
                tile(x, y),
                "tile at ({x},{y})"
            );
        }
    }

    const VALIDATION: &str = "/usr/share/vulkan/explicit_layer.d/VkLayer_khronos_validation.json";
    /// fovea's density texel without VK_EXT_fragment_density_map (lavapipe).
    const TEXEL: u32 = 32;

    /// The environment for one run of the example through the system loaders: the simulated
    /// headset as the runtime, fovea as the OpenXR layer, lavapipe as the Vulkan driver, in a fresh
    /// temporary folder (returned). `None` where a system component is missing (skipped).
    fn set_up(label: &str) -> Option<PathBuf> {
        if let Err(e) = unsafe { libloading::Library::new("libopenxr_loader.so.1") } {
            skip(&format!("the Khronos OpenXR loader is not installed: {e}"));
            return None;
        }
        let Some(lavapipe) = fovea_harness::vulkan::lavapipe_icd() else {
            skip("Mesa's lavapipe Vulkan driver is not installed (mesa-vulkan-drivers)");
            return None;
        };
        if !Path::new(VALIDATION).exists() {
            skip("the Vulkan validation layer is not installed (vulkan-validationlayers)");
            return None;
        }
        let layer = artifact("libfovea.so").expect("run `cargo build --workspace`");
        let runtime = artifact("libfovea_sim.so").expect("run `cargo build --workspace`");
        let dir =
            std::env::temp_dir().join(format!("fovea-example-{label}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("layers")).unwrap();
        let checked_in = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("manifest/XR_APILAYER_FOVEA_foveation.json"),
        )
        .unwrap();
        std::fs::write(
            dir.join("layers/fovea.json"),
            checked_in.replace("../target/release/libfovea.so", layer.to_str().unwrap()),
        )
        .unwrap();
        std::fs::write(
            dir.join("runtime.json"),
            format!(
                r#"{{"file_format_version": "1.0.0", "runtime": {{"name": "fovea simulated headset", "library_path": "{}"}}}}"#,
                runtime.display()
            ),
        )
        .unwrap();
        // The layer reads no fovea.toml and writes no log file in the user's home during tests.
        fovea_harness::use_private_home();
        std::env::set_var("XR_RUNTIME_JSON", dir.join("runtime.json"));
        std::env::set_var("XR_API_LAYER_PATH", dir.join("layers"));
        std::env::set_var("XR_ENABLE_API_LAYERS", FOVEA_LAYER);
        std::env::set_var("VK_ICD_FILENAMES", &lavapipe);
        std::env::set_var("VK_DRIVER_FILES", &lavapipe);
        // The maps must be the app's levels: no debug override from the environment.
        for var in [
            "FOVEA_PROPS",
            "FOVEA_SYMMETRIC_FOV",
            "DEBUG_OCULUS_FOVEATION_LEVEL",
            "DEBUG_OCULUS_FOVEATION_DYNAMIC",
        ] {
            std::env::remove_var(var);
        }
        // A small headset keeps lavapipe quick.
        std::env::set_var("FOVEA_SIM_HEADSET", "rift-cv1");
        Some(dir)
    }

    /// fovea's density model for the views the example rendered, per level (both layers, R8G8),
    /// with `texel`-pixel texels.
    fn expected_maps(o: &Outcome, texel: u32, summary: &str) -> Vec<Vec<u8>> {
        let (w, h) = o.view_size;
        let grid = Grid::new([w, h], [texel, texel]);
        let rect = Rect {
            x: 0,
            y: 0,
            width: w,
            height: h,
        };
        let views: Vec<Vec<View>> = o
            .fovs
            .iter()
            .map(|f| {
                vec![View {
                    fov: Fov {
                        left: f.angle_left,
                        right: f.angle_right,
                        up: f.angle_up,
                        down: f.angle_down,
                    },
                    rect,
                    visible: None,
                }]
            })
            .collect();
        assert_eq!(views.len(), 2, "{summary}");
        let expected: Vec<Vec<u8>> = (0..LEVELS.len())
            .map(|level| {
                let inputs = Inputs {
                    pattern: Pattern {
                        level: Level::from_index(level as u32).unwrap(),
                        vertical_offset_deg: 0.0,
                    },
                    max_fragment: fovea_model::maps::DEFAULT_MAX_FRAGMENT,
                    layers: views.clone(),
                };
                let [mw, mh] = grid.map_extent();
                let mut out = vec![0; (mw * mh * 2 * 2) as usize];
                fill_layers(&grid, &inputs, &mut out);
                out
            })
            .collect();
        for (a, b) in [(0, 1), (1, 2), (2, 3)] {
            assert_ne!(expected[a], expected[b], "levels {a} and {b} give one map");
        }
        expected
    }

    /// What every run shows: all levels applied, one density image per swapchain image of the
    /// density texel `texel`, every map read back the applied level's, the frames drawn as the
    /// shaders say. Returns fovea's model maps per level.
    fn check_run(o: &Outcome, options: &Options, texel: u32) -> Vec<Vec<u8>> {
        let summary = format!(
            "{} frames, {:?}, {:?}, {} captures",
            o.frames,
            o.levels_applied,
            o.mode,
            o.captures.len()
        );
        // The runtime may take a frame or two to stop after xrRequestExitSession.
        assert!(o.frames >= options.frames, "{summary}");
        assert_eq!(o.levels_applied, LEVELS, "{summary}");
        let (w, h) = o.view_size;
        let distinct: std::collections::HashSet<u64> =
            o.density_images.iter().map(|d| d.0).collect();
        assert_eq!(distinct.len(), o.density_images.len(), "one per image");
        for &(image, dw, dh) in &o.density_images {
            assert!(image != 0, "{summary}");
            assert_eq!((dw, dh), (w.div_ceil(texel), h.div_ceil(texel)));
        }
        // What fovea's model gives for the views the example rendered: every map read back is
        // that of the level the app had applied.
        let expected = expected_maps(o, texel, &summary);
        for c in &o.captures {
            assert!(
                c.density == expected[c.level],
                "frame {}: the density map read back is not {:?}'s",
                c.frame,
                LEVELS[c.level]
            );
        }
        let drawn: Vec<usize> = o
            .captures
            .iter()
            .filter(|c| c.eyes.is_some())
            .map(|c| c.level)
            .collect();
        assert!(
            drawn.starts_with(&[0, 1, 2, 3]),
            "frames read back: {drawn:?}"
        );
        for c in o.captures.iter().filter(|c| c.eyes.is_some()) {
            check_frame(o, c);
        }
        expected
    }

    #[test]
    fn draws_with_fovea_s_density_maps_through_the_system_loader() {
        let Some(dir) = set_up("lavapipe") else {
            return;
        };
        let options = Options {
            frames: LEVELS.len() as u64 * FRAMES_PER_LEVEL,
            capture: true,
            validate: true,
            ..Options::parse(&[]).unwrap()
        };
        let o = run(&options).unwrap_or_else(|e| panic!("{e}"));
        // The fill-bound shader (`--heavy`), briefly: validation-clean, and its passes timed.
        let heavy = Options {
            frames: 2,
            frames_per_level: 2,
            levels: vec![3],
            validate: true,
            heavy: true,
            ..Options::parse(&[]).unwrap()
        };
        let h = run(&heavy).unwrap_or_else(|e| panic!("--heavy: {e}"));
        std::fs::remove_dir_all(&dir).ok();
        assert_eq!(
            h.vk_messages,
            Vec::<String>::new(),
            "--heavy: Vulkan validation messages"
        );
        assert!(!h.eye_ms[3].is_empty(), "--heavy: no eye pass timed");
        assert_eq!(
            o.vk_messages,
            Vec::<String>::new(),
            "Vulkan validation messages"
        );
        // Every eye pass of every level is timed (lavapipe writes timestamps), two per frame.
        for (level, ms) in o.eye_ms.iter().enumerate() {
            assert!(ms.len() >= 2, "level {level}: {} passes timed", ms.len());
            assert!(ms.iter().all(|t| t.is_finite() && *t >= 0.0), "{ms:?}");
        }
        // lavapipe has no fragment density maps: they are sampled into the overlay.
        assert!(!o.fdm_enabled, "{:?}", o.mode);
        assert_eq!(o.mode, Mode::Overlay);
        check_run(&o, &options, TEXEL);
    }

    /// The variable that makes [`through_the_vulkan_layer_and_the_double`] run, naming the
    /// double's profile.
    const DOUBLE_CHILD: &str = "FOVEA_EXAMPLE_DOUBLE_PROFILE";

    /// The example's density-map path on desktop-like GPUs: fovea's Vulkan layer over the
    /// validation layer over the test double (`nvidia`: 16×16 texels, layered, up to 4×4; `amd`:
    /// 8×8, one merged layer, up to 2×2) over lavapipe. Each profile in a process of its own (the
    /// loaders read the environment once).
    #[test]
    fn density_maps_become_shading_rates_on_desktop_like_gpus() {
        for profile in ["nvidia", "amd"] {
            let test = "tests::through_the_vulkan_layer_and_the_double";
            let out = std::process::Command::new(std::env::current_exe().unwrap())
                .args([
                    test,
                    "--exact",
                    "--ignored",
                    "--nocapture",
                    "--test-threads=1",
                ])
                .env(DOUBLE_CHILD, profile)
                .output()
                .expect("run the example in a child process");
            let stdout = String::from_utf8_lossy(&out.stdout);
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert!(
                out.status.success() && stdout.contains("test result: ok. 1 passed"),
                "{profile}: {}\n{stdout}\n{stderr}",
                out.status
            );
            print!("{stdout}");
            eprint!("{stderr}");
        }
    }

    /// One profile of [`density_maps_become_shading_rates_on_desktop_like_gpus`]: every eye pass
    /// reaches the driver with a shading-rate attachment of the device's texel, the rate codes in
    /// it at each submit are fovea's density model for that frame's level, texel for texel
    /// (layered on `nvidia`, the finer rate of both eyes on `amd`), validation says nothing but
    /// its known false positive, and the frames are drawn as before (lavapipe renders at 1×1).
    #[test]
    #[ignore = "run in a child process by density_maps_become_shading_rates_on_desktop_like_gpus"]
    fn through_the_vulkan_layer_and_the_double() {
        use fovea_model::shading_rate::{finer, fsr_code};
        use fovea_vkdouble::Profile;

        let Some(profile) = std::env::var(DOUBLE_CHILD)
            .ok()
            .and_then(|p| Profile::parse(&p))
        else {
            return;
        };
        let Some(dir) = set_up(profile.name()) else {
            return;
        };
        let double_lib = match fovea_vkdouble::find_library() {
            Ok(l) => l,
            Err(e) => {
                skip(&e);
                return;
            }
        };
        let fovea = artifact("libfovea.so").unwrap().canonicalize().unwrap();
        let vk_layers = dir.join("vklayers");
        fovea_vkdouble::write_manifest(&vk_layers, &double_lib).unwrap();
        let manifest = "VK_LAYER_FOVEA_fragment_density_map.json";
        let checked_in = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("manifest/vulkan")
                .join(manifest),
        )
        .unwrap();
        let mut m: serde_json::Value = serde_json::from_str(&checked_in).unwrap();
        m["layer"]["library_path"] = fovea.to_str().unwrap().into();
        std::fs::write(vk_layers.join(manifest), m.to_string()).unwrap();
        std::env::set_var("VK_ADD_LAYER_PATH", &vk_layers);
        std::env::set_var(fovea_vkdouble::PROFILE_ENV, profile.name());
        // No implicit layer from the user's own install.
        std::env::set_var("XDG_DATA_HOME", dir.join("data"));
        std::env::set_var("XDG_CONFIG_HOME", dir.join("config"));
        std::env::set_var("FOVEA_LOG", "info");
        std::env::set_var("FOVEA_LOG_FILE", dir.join("fovea.log"));
        // Opened before the first VkInstance, kept to the end (see `Loaded::open`).
        let double = fovea_vkdouble::Loaded::open(&double_lib).unwrap();

        let per_level = 4;
        let options = Options {
            frames: LEVELS.len() as u64 * per_level,
            frames_per_level: per_level,
            capture: true,
            validate: true,
            // Below validation, which so checks what fovea's layer (which fovea's
            // xrCreateVulkanInstanceKHR puts first, closest to the application) hands down.
            vk_layers: vec![fovea_vkdouble::LAYER_NAME.to_owned()],
            ..Options::parse(&[]).unwrap()
        };
        let o = run(&options).unwrap_or_else(|e| panic!("{e}"));
        let log = std::fs::read_to_string(dir.join("fovea.log")).unwrap_or_default();
        std::fs::remove_dir_all(&dir).ok();

        // Validation 1.3.239 checks the shading-rate attachment stage against the NVIDIA
        // shading-rate-image feature alone (VUID-vkCmdPipelineBarrier-dstStageMask-07318); later
        // versions accept attachmentFragmentShadingRate. Nothing else may be said.
        let others: Vec<&String> = o
            .vk_messages
            .iter()
            .filter(|m| !m.contains("when the device does not have shadingRate feature enabled"))
            .collect();
        assert!(others.is_empty(), "validation reported: {others:#?}");
        assert!(
            o.fdm_enabled,
            "the layer offers VK_EXT_fragment_density_map"
        );
        assert_eq!(o.mode, Mode::Attachment, "{log}");
        let texel = profile.texel().width;
        let expected = check_run(&o, &options, texel);
        assert!(
            log.contains("density images carry their shading rates"),
            "{log}"
        );
        assert!(
            !log.contains("creates and writes density maps itself"),
            "fovea's own maps are not the application's: {log}"
        );

        // The rate codes fovea's model gives, per level, as the shadow holds them.
        let supported: Vec<[u32; 2]> = profile
            .rates()
            .iter()
            .filter(|(_, samples)| samples.contains(vk::SampleCountFlags::TYPE_1))
            .map(|(e, _)| [e.width, e.height])
            .collect();
        let max = [profile.max_fragment(); 2];
        let (dw, dh) = (o.density_images[0].1, o.density_images[0].2);
        let texels = (dw * dh) as usize;
        let codes: Vec<Vec<u8>> = expected
            .iter()
            .map(|map| {
                let layer = |l: usize| -> Vec<u8> {
                    map[l * texels * 2..][..texels * 2]
                        .chunks_exact(2)
                        .map(|t| fsr_code([t[0], t[1]], max, &supported))
                        .collect()
                };
                let (left, right) = (layer(0), layer(1));
                if profile.layered() {
                    [left, right].concat()
                } else {
                    left.iter()
                        .zip(&right)
                        .map(|(&a, &b)| finer(a, b, &supported))
                        .collect()
                }
            })
            .collect();
        assert_ne!(codes[0], codes[3], "the levels shade differently");
        assert!(codes[0].iter().all(|&c| c == 0), "level none: full rate");

        let records = double.records();
        assert_eq!(
            records["errors"],
            serde_json::json!([]),
            "the double saw misuse"
        );
        let events = records["events"].as_array().unwrap();
        let of = |kind: &'static str| events.iter().filter(move |e| e["kind"] == kind);
        let passes: std::collections::HashMap<String, &serde_json::Value> = of("render_pass")
            .map(|e| (e["render_pass"].to_string(), e))
            .collect();
        let begins: Vec<_> = of("begin_render_pass").collect();
        assert!(
            begins.len() as u64 >= 2 * o.frames,
            "{} passes",
            begins.len()
        );
        for b in &begins {
            let pass = passes[&b["render_pass"].to_string()];
            for sub in pass["subpasses"].as_array().unwrap() {
                assert_eq!(
                    sub["shading_rate"]["texel"],
                    serde_json::json!([texel, texel]),
                    "every eye pass carries a shading-rate attachment: {pass}"
                );
            }
            assert_eq!(
                b["shading_rate_views"].as_array().map(Vec::len),
                Some(1),
                "{b}"
            );
        }
        let frames: Vec<_> = of("submit")
            .filter(|s| {
                s["shading_rate_images"]
                    .as_array()
                    .is_some_and(|a| !a.is_empty())
            })
            .collect();
        assert_eq!(frames.len() as u64, o.frames, "one frame submit per frame");
        let layers = if profile.layered() { 2 } else { 1 };
        for (i, submit) in frames.iter().enumerate() {
            // Levels change every `per_level` frames and stay at the last after the exit request.
            let level = (i as u64 / per_level).min(LEVELS.len() as u64 - 1) as usize;
            let images = submit["shading_rate_images"].as_array().unwrap();
            assert_eq!(
                images.len(),
                1,
                "both eyes read one shadow: {}",
                images.len()
            );
            let image = &images[0];
            assert_eq!(image["extent"], serde_json::json!([dw, dh]));
            assert_eq!(image["layers"], serde_json::json!(layers));
            let got: Vec<u8> = serde_json::from_value(image["codes"].clone()).unwrap();
            assert!(
                got == codes[level],
                "frame {i} ({:?}): {} of {} codes differ from fovea's model",
                LEVELS[level],
                got.iter()
                    .zip(&codes[level])
                    .filter(|(a, b)| a != b)
                    .count(),
                codes[level].len()
            );
        }
        drop(double);
    }

    /// The frame as the shaders drew it: outside the overlay the level's tinted stripes, inside it
    /// each view's own layer of the density map, one texel per (nearest-sampled) pixel. With the
    /// map attached (a GPU with shading-rate attachments, or the double playing one, which leaves
    /// each pass's colour as coarse fragments shade it), a pixel may hold its fragment's value
    /// instead of its own, in a fragment no larger than its density texel allows; where the map
    /// allows only 1×1 it is its own. A fragment's value is the shader's at the centre of the
    /// fragment area (Vulkan, "Interpolation Decorations"), which the double takes as the mean,
    /// in linear terms, of the pixels nearest it (crates/vkdouble/src/layer/centre.rs): the
    /// middle one or two per axis, clamped into the image where its edge cuts the fragment. On
    /// the stripes that is a stripe's colour, or the mean of the two where a stripe's edge runs
    /// between the middle pixels.
    fn check_frame(o: &Outcome, c: &Capture) {
        let (w, h) = (o.view_size.0 as usize, o.view_size.1 as usize);
        let (dw, dh) = (
            o.density_images[0].1 as usize,
            o.density_images[0].2 as usize,
        );
        let eyes = c.eyes.as_ref().unwrap();
        let rgb = |r: f32, g: f32, b: f32| {
            let rgb = [r, g, b].map(srgb);
            if o.format == vk::Format::B8G8R8A8_SRGB {
                [rgb[2], rgb[1], rgb[0]]
            } else {
                rgb
            }
        };
        let tint = TINTS[c.level];
        let stripes = [0.5, 1.0].map(|k| rgb(tint[0] * k, tint[1] * k, tint[2] * k));
        let close = |a: &[u8], b: [u8; 3]| a.iter().zip(b).all(|(x, y)| x.abs_diff(y) <= 1);
        // Texel coordinates the overlay samples; pixels whose coordinate falls within 1% of a
        // texel's edge could sample either neighbour and are left out.
        let texel = |p: usize, size: usize, n: usize, shift: usize| {
            let t = ((2 * p + 1 - shift) as f64 / size as f64) * n as f64;
            (t - t.round()).abs().gt(&0.01).then_some(t as usize)
        };
        let stripe_at = |x: usize, y: usize| stripes[usize::from((x + y + 1) % 8 >= 4)];
        // The stripes' linear colour, and a fragment's value as the double computes it.
        let linear_at = |x: usize, y: usize| {
            let k = if (x + y + 1) % 8 >= 4 { 1.0 } else { 0.5 };
            [tint[0] * k, tint[1] * k, tint[2] * k]
        };
        let middle = |origin: usize, size: usize, extent: usize| {
            let last = size.min(extent - origin) - 1;
            [
                origin + ((size - 1) / 2).min(last),
                origin + (size / 2).min(last),
            ]
        };
        let fragment_value = |x: usize, y: usize, fw: usize, fh: usize| {
            let (xs, ys) = (middle(x - x % fw, fw, w), middle(y - y % fh, fh, h));
            let mut sum = [0f32; 3];
            for py in ys {
                for px in xs {
                    for (s, v) in sum.iter_mut().zip(linear_at(px, py)) {
                        *s += v / 4.0;
                    }
                }
            }
            rgb(sum[0], sum[1], sum[2])
        };
        let density_texel = w.div_ceil(dw).max(h.div_ceil(dh));
        let (mut overlay, mut stripe, mut coarse) = (0, 0, 0);
        for layer in 0..2 {
            let image = &eyes[layer * w * h * 4..][..w * h * 4];
            let map = &c.density[layer * dw * dh * 2..][..dw * dh * 2];
            for y in 0..h {
                for x in 0..w {
                    let px = &image[(y * w + x) * 4..][..3];
                    let at = format!("frame {}, layer {layer}, pixel ({x}, {y})", c.frame);
                    if o.mode == Mode::Overlay && x < w / 2 && y >= h / 2 {
                        // Sampled at uv * 2 (x) and uv * 2 - 1 (y) over the lower-left quarter.
                        let (Some(i), Some(j)) = (texel(x, w, dw, 0), texel(y, h, dh, h)) else {
                            continue;
                        };
                        let t = &map[(j.min(dh - 1) * dw + i.min(dw - 1)) * 2..][..2];
                        let want = rgb(f32::from(t[0]) / 255.0, f32::from(t[1]) / 255.0, 0.0);
                        assert!(close(px, want), "{at}: {px:?}, map texel {t:?}");
                        overlay += 1;
                    } else {
                        let want = stripe_at(x, y);
                        if o.mode == Mode::Attachment && !close(px, want) {
                            let (tx, ty) = (x / density_texel, y / density_texel);
                            let t = &map[(ty.min(dh - 1) * dw + tx.min(dw - 1)) * 2..][..2];
                            let allow =
                                [t[0], t[1]].map(|v| fovea_model::shading_rate::axis_size(v, 4));
                            let sizes = [1, 2, 4];
                            let shaded = sizes.iter().any(|&fw| {
                                sizes.iter().any(|&fh| {
                                    fw <= allow[0] as usize
                                        && fh <= allow[1] as usize
                                        && close(px, fragment_value(x, y, fw, fh))
                                })
                            });
                            assert!(
                                shaded,
                                "{at}: {px:?}, stripe {want:?}, no fragment within {allow:?}"
                            );
                            coarse += 1;
                        }
                        stripe += 1;
                    }
                }
            }
        }
        if o.mode == Mode::Overlay {
            assert!(overlay > w * h / 3 && stripe > w * h, "{overlay} {stripe}");
        } else {
            assert_eq!((overlay, stripe), (0, 2 * w * h));
        }
        if o.mode == Mode::Attachment && c.level == 3 {
            // HIGH's quarter resolution beyond 30°: many pixels hold a neighbour's stripe.
            assert!(
                coarse > w * h / 10,
                "frame {}: {coarse} coarse pixels",
                c.frame
            );
        }
    }

    /// Linear to sRGB-encoded 8-bit, as the sRGB attachment stores it.
    fn srgb(linear: f32) -> u8 {
        let v = if linear <= 0.003_130_8 {
            linear * 12.92
        } else {
            1.055 * linear.powf(1.0 / 2.4) - 0.055
        };
        (v * 255.0).round().clamp(0.0, 255.0) as u8
    }

    #[test]
    fn shaders_match_their_sources() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/foveated_vulkan/shaders");
        for (source, defines, built) in [
            ("fullscreen.vert", &[][..], render::VERTEX),
            ("pattern.frag", &[], render::PATTERN),
            ("pattern.frag", &["-DOVERLAY"], render::OVERLAY),
            ("pattern.frag", &["-DHEAVY"], render::HEAVY),
            (
                "pattern.frag",
                &["-DHEAVY", "-DOVERLAY"],
                render::HEAVY_OVERLAY,
            ),
            ("composite.frag", &[], render::COMPOSITE),
            ("scene.frag", &[], render::SCENE),
            ("scene.frag", &["-DOVERLAY"], render::SCENE_OVERLAY),
        ] {
            fovea_harness::assert_spirv_built_from(&dir.join(source), defines, built);
        }
    }

    #[test]
    fn options_say_what_is_wrong() {
        let parse =
            |s: &str| Options::parse(&s.split_whitespace().map(String::from).collect::<Vec<_>>());
        let o = parse("").unwrap();
        assert_eq!(o.levels, [0, 1, 2, 3]);
        assert_eq!(o.frames, 4 * FRAMES_PER_LEVEL * 2);
        let o = parse("--levels high --dynamic --frames-per-level 5 --dump d").unwrap();
        assert_eq!(
            (o.levels.as_slice(), o.dynamic, o.frames),
            (&[3][..], true, 10)
        );
        assert!(o.capture && o.dump == Some(PathBuf::from("d")) && !o.eye_tracked);
        assert!(parse("--levels high --eye-tracked").unwrap().eye_tracked);
        let o = parse("--no-fb --double-wide --offscreen --dynamic-rendering").unwrap();
        assert!(o.no_fb && o.offscreen && o.dynamic_rendering);
        assert_eq!(
            (o.layout, o.levels.as_slice()),
            (Layout::DoubleWide, &[0][..])
        );
        for (bad, says) in [
            ("--double-wide", "add --no-fb"),
            ("--no-fb --levels high", "--no-fb has none"),
            ("--no-fb --dynamic", "--no-fb has none"),
            ("--no-fb --eye-tracked", "--no-fb has none"),
            ("--levels ultra", "\"ultra\" is not one of"),
            ("--frames 0", "positive count"),
            ("--frames", "takes a value"),
            ("--fast", "unknown option"),
        ] {
            let e = parse(bad).unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }
}
