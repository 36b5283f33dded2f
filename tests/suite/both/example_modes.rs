//! `examples/foveated_vulkan` in the modes that make it a test subject for injection
//! (docs/injection.md): without the FB API (`--no-fb`), with offscreen passes that are not eye
//! passes (`--offscreen`), double-wide (`--double-wide`) and with dynamic rendering
//! (`--dynamic-rendering`). Each run is the built example as a child process, a few frames through
//! the Khronos loader, fovea's OpenXR layer, fovea's Vulkan layer (explicit manifest) and the Khronos
//! validation layer (`--validate`, which makes the example fail on any message) on lavapipe, against
//! the simulated headset.
//!
//! A run passes when the example exits with status 0, the runtime's summary line
//! (`FOVEA_SIM_SUMMARY=1`) counts the frames and no failed call, fovea's Vulkan layer was in the
//! VkInstance, and stderr holds nothing but fovea's info lines and that summary: no validation
//! message, no warning from fovea. Each test then checks what its mode is for, in the frames read
//! back (`--dump`) and in the projection views the runtime received (the summary's `views=`).

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Mutex, OnceLock};
use std::time::Duration;

use fovea_abi::log_target;
use fovea_harness::{skip, FOVEA_LAYER};

use crate::support::{root, Manifests};

const VALIDATION: &str = "/usr/share/vulkan/explicit_layer.d/VkLayer_khronos_validation.json";
const LOADER: &str = "libopenxr_loader.so.1";
const VK_MANIFEST: &str = "VK_LAYER_FOVEA_fragment_density_map.json";
/// Frames the example renders; the runtime may see one or two more before the session stops.
const FRAMES: u64 = 3;
/// A debug build on lavapipe takes a few seconds a run; one stuck must fail, not hang CI.
const TIMEOUT: Duration = Duration::from_secs(180);
/// lavapipe renders on the CPU: runs at once only slow each other (and every other test) down.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// The grey of level NONE's tint (the stripes' brighter half is 0.6 linear, the darker 0.3).
const GREY: [u8; 3] = [203, 203, 203];
const DARK_GREY: [u8; 3] = [149, 149, 149];

/// What the example's runs need from the system, or the reason to skip.
fn system() -> Result<(), String> {
    // SAFETY: loading the loader runs its initialisers, nothing else; it is unloaded at once.
    unsafe { libloading::Library::new(LOADER) }
        .map_err(|e| format!("the Khronos OpenXR loader is not installed: {e}"))?;
    if fovea_harness::vulkan::lavapipe_icd().is_none() {
        return Err("Mesa's lavapipe Vulkan driver is not installed (mesa-vulkan-drivers)".into());
    }
    if !Path::new(VALIDATION).exists() {
        return Err(
            "the Vulkan validation layer is not installed (vulkan-validationlayers)".into(),
        );
    }
    Ok(())
}

/// The example built with this test binary's profile, next to it (`target/<profile>/examples`).
/// `cargo test --test suite` builds no example, so the first call builds it with the Cargo that
/// built the suite; once per process.
pub(crate) fn example() -> &'static Path {
    static BUILT: OnceLock<PathBuf> = OnceLock::new();
    BUILT.get_or_init(|| {
        let exe = std::env::current_exe().unwrap();
        // target/<profile>/deps/suite-<hash>
        let dir = exe.parent().and_then(Path::parent).unwrap().to_path_buf();
        let profile = match dir.file_name().and_then(|n| n.to_str()) {
            Some("debug") | None => "dev".to_owned(),
            Some(p) => p.to_owned(),
        };
        let status = Command::new(env!("CARGO"))
            .current_dir(root())
            .args(["build", "--quiet", "--profile", &profile])
            .args(["--example", "foveated_vulkan"])
            .status()
            .expect("run cargo");
        assert!(
            status.success(),
            "cargo build --example foveated_vulkan: {status}"
        );
        let path = dir.join("examples/foveated_vulkan");
        assert!(path.is_file(), "{} was not built", path.display());
        path
    })
}

/// What one run of the example left behind.
struct Run {
    label: String,
    code: Option<i32>,
    stdout: String,
    stderr: String,
    /// Where `--dump` wrote its PNGs.
    frames: PathBuf,
}

impl Run {
    fn transcript(&self) -> String {
        format!(
            "{}: exit code {:?}\n--- stdout ---\n{}\n--- stderr ---\n{}",
            self.label, self.code, self.stdout, self.stderr
        )
    }

    /// The runtime's summary line's fields after `fovea-sim: summary `.
    fn summary(&self) -> &str {
        self.stderr
            .lines()
            .find_map(|l| l.split_once("fovea-sim: summary ").map(|(_, s)| s))
            .unwrap_or_else(|| panic!("no runtime summary line\n{}", self.transcript()))
    }

    /// A `name=value` field of the summary line.
    fn field(&self, name: &str) -> &str {
        let prefix = format!("{name}=");
        self.summary()
            .split_whitespace()
            .find_map(|w| w.strip_prefix(prefix.as_str()))
            .unwrap_or_else(|| panic!("no {name}= in the summary\n{}", self.transcript()))
    }

    /// The last frame's projection views as the runtime received them:
    /// `(swapchain, array index, (x, y, width, height))`.
    fn views(&self) -> Vec<(u64, u32, [i32; 4])> {
        let parse = |v: &str| -> Option<(u64, u32, [i32; 4])> {
            let mut parts = v.split(':');
            let (_layer, swapchain, index, rect) =
                (parts.next()?, parts.next()?, parts.next()?, parts.next()?);
            let (offset, extent) = rect.split_once('+')?;
            let (x, y) = offset.split_once(',')?;
            let (w, h) = extent.split_once('x')?;
            Some((
                swapchain.parse().ok()?,
                index.parse().ok()?,
                [
                    x.parse().ok()?,
                    y.parse().ok()?,
                    w.parse().ok()?,
                    h.parse().ok()?,
                ],
            ))
        };
        self.field("views")
            .split(';')
            .filter(|v| !v.is_empty())
            .map(|v| parse(v).unwrap_or_else(|| panic!("view {v:?}\n{}", self.transcript())))
            .collect()
    }

    /// The swapchain's size from the example's summary (`on a WxH swapchain`).
    fn swapchain_size(&self) -> (i32, i32) {
        let size = self
            .stdout
            .split_once(" frames on a ")
            .and_then(|(_, rest)| rest.split_once(' '))
            .and_then(|(size, _)| size.split_once('x'))
            .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)));
        size.unwrap_or_else(|| panic!("no swapchain size\n{}", self.transcript()))
    }

    /// The last frame read back, of `eye` (`left`, `right`): width, height, RGBA8.
    fn frame(&self, eye: &str) -> (usize, usize, Vec<u8>) {
        let suffix = format!("_{eye}.png");
        let mut names: Vec<PathBuf> = std::fs::read_dir(&self.frames)
            .unwrap_or_else(|e| panic!("{}: {e}\n{}", self.frames.display(), self.transcript()))
            .map(|e| e.unwrap().path())
            .filter(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.ends_with(&suffix) && !n.contains("density"))
            })
            .collect();
        names.sort();
        let path = names
            .last()
            .unwrap_or_else(|| panic!("no {eye} frame read back\n{}", self.transcript()));
        let decoder = png::Decoder::new(std::fs::File::open(path).unwrap());
        let mut reader = decoder.read_info().unwrap();
        let mut pixels = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut pixels).unwrap();
        assert_eq!(info.color_type, png::ColorType::Rgba, "{}", path.display());
        pixels.truncate(info.buffer_size());
        (info.width as usize, info.height as usize, pixels)
    }
}

impl Drop for Run {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.frames).ok();
    }
}

/// Runs the example with `--validate --frames 3 --dump DIR` and `args` through both of fovea's
/// layers on lavapipe, and checks everything every mode must show (see the module's doc); `None`
/// (skipped) where the system lacks a component.
fn run_example(label: &str, args: &[&str]) -> Option<Run> {
    run_example_with(label, args, &[])
}

/// [`run_example`] with more environment variables (`env`, set last).
fn run_example_with(label: &str, args: &[&str], env: &[(&str, OsString)]) -> Option<Run> {
    if let Err(reason) = system() {
        skip(&reason);
        return None;
    }
    let example = example();
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let manifests = Manifests::write(&format!("example-{label}"));
    let vk_layers = manifests.dir.join("vulkan");
    std::fs::create_dir_all(&vk_layers).unwrap();
    let lib = fovea_harness::artifact("libfovea.so").expect("libfovea.so: cargo build");
    let checked_in = std::fs::read_to_string(root().join("manifest/vulkan").join(VK_MANIFEST));
    let mut m: serde_json::Value = serde_json::from_str(&checked_in.unwrap()).unwrap();
    m["layer"]["library_path"] = lib.canonicalize().unwrap().to_str().unwrap().into();
    std::fs::write(vk_layers.join(VK_MANIFEST), m.to_string()).unwrap();
    let frames = manifests.dir.join("frames");

    let frame_count = FRAMES.to_string();
    let lavapipe = fovea_harness::vulkan::lavapipe_icd().expect("checked by system()");
    let mut cmd = Command::new(example);
    cmd.args(["--validate", "--frames", &frame_count])
        .args(["--frames-per-level", &frame_count])
        .arg("--dump")
        .arg(&frames)
        .args(args);
    // Nothing from the caller's environment may change what the loaders, the layers or the runtime
    // do (an exported XR_ENABLE_API_LAYERS, FOVEA_PROPS or VK_INSTANCE_LAYERS).
    for (key, _) in std::env::vars_os() {
        let k = key.to_string_lossy();
        if k.starts_with("XR_") || k.starts_with("FOVEA_") || k.starts_with("VK_") {
            cmd.env_remove(&key);
        }
    }
    // Info: the Vulkan layer's line on the VkInstance, and whether density images were made.
    let filter = format!("info,{}=info", log_target::VK_INSTANCE);
    let home = manifests.dir.join("home");
    cmd.env("XR_RUNTIME_JSON", manifests.dir.join("runtime.json"))
        .env("XR_API_LAYER_PATH", manifests.dir.join("layers"))
        .env("XR_ENABLE_API_LAYERS", FOVEA_LAYER)
        .env("VK_ICD_FILENAMES", &lavapipe)
        .env("VK_DRIVER_FILES", &lavapipe)
        .env("VK_ADD_LAYER_PATH", &vk_layers)
        // The per-user folders are the run's own: no implicit layer or fovea.toml from the user.
        .env("XDG_DATA_HOME", home.join("data"))
        .env("XDG_CONFIG_HOME", home.join("config"))
        .env("HOME", &home)
        .env(fovea_abi::env::LOG, filter)
        .env(fovea_abi::env::LOG_FILE, OsString::new())
        // A small headset keeps lavapipe quick.
        .env("FOVEA_SIM_HEADSET", "rift-cv1")
        .env("FOVEA_SIM_SUMMARY", "1")
        .envs(env.iter().map(|(k, v)| (k, v)))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let done = crate::support::run_with_timeout(&mut cmd, TIMEOUT);
    let status = done.status;
    // The frames outlive the manifests' folder (removed when `manifests` drops): moved out first.
    let kept = std::env::temp_dir().join(format!(
        "fovea-example-{label}-frames-{}",
        std::process::id()
    ));
    std::fs::remove_dir_all(&kept).ok();
    std::fs::rename(&frames, &kept).ok();
    let run = Run {
        label: format!("foveated_vulkan {args:?}"),
        code: status.and_then(|s| s.code()),
        stdout: done.stdout,
        stderr: done.stderr,
        frames: kept,
    };
    assert!(
        status.is_some(),
        "still running after {TIMEOUT:?}; killed\n{}",
        run.transcript()
    );
    assert_eq!(run.code, Some(0), "{}", run.transcript());
    let seen: u64 = run.field("frames").parse().unwrap();
    assert!(
        seen >= FRAMES,
        "the runtime saw {seen} frames\n{}",
        run.transcript()
    );
    assert_eq!(
        (run.field("errors"), run.field("refused")),
        ("0", "0"),
        "calls failed in the runtime\n{}",
        run.transcript()
    );
    assert!(
        run.stderr
            .contains("the Vulkan layer is in this VkInstance"),
        "fovea's Vulkan layer was not loaded\n{}",
        run.transcript()
    );
    // Validation messages (the example prints each as `foveated_vulkan: Vulkan ...`), fovea's
    // warnings, anything else.
    let messages: Vec<&str> = run
        .stderr
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.contains("fovea-sim: summary ") && !is_fovea_info(l))
        .collect();
    assert!(
        messages.is_empty(),
        "{} messages:\n{}\n\n{}",
        messages.len(),
        messages.join("\n"),
        run.transcript()
    );
    Some(run)
}

/// fovea's log lines below warning level (`<time>  INFO fovea::…: …`).
fn is_fovea_info(line: &str) -> bool {
    let mut words = line.split_whitespace().take(3);
    let level = words.find(|w| ["INFO", "DEBUG", "TRACE"].contains(w));
    level.is_some() && words.next().is_some_and(|t| t.starts_with("fovea"))
}

/// The pixel at `(x, y)` of an RGBA8 frame `width` wide, as RGB.
fn pixel((width, _, rgba): &(usize, usize, Vec<u8>), x: usize, y: usize) -> [u8; 3] {
    let p = &rgba[(y * width + x) * 4..][..3];
    [p[0], p[1], p[2]]
}

/// Whether `p` is one of level NONE's two greys (within the rounding of sRGB encoding).
fn is_grey_stripe(p: [u8; 3]) -> bool {
    let close = |a: [u8; 3], b: [u8; 3]| a.iter().zip(b).all(|(x, y)| x.abs_diff(y) <= 1);
    close(p, GREY) || close(p, DARK_GREY)
}

/// Both eyes of the last frame are level NONE's grey stripes over the whole view (outside the
/// offscreen corner where there is one): every 7th pixel of every 7th row checked.
fn assert_stripes(run: &Run, corner: bool) {
    for eye in ["left", "right"] {
        let frame = run.frame(eye);
        let (w, h) = (frame.0, frame.1);
        for y in (0..h).step_by(7) {
            for x in (0..w).step_by(7) {
                if corner && x >= w - w / 4 && y < h / 4 {
                    continue;
                }
                let p = pixel(&frame, x, y);
                assert!(
                    is_grey_stripe(p),
                    "{eye} ({x}, {y}): {p:?} is not a stripe\n{}",
                    run.transcript()
                );
            }
        }
    }
}

/// `--no-fb`: no XR_FB_foveation, so no density image for any swapchain image and no density map
/// in any pass; the eyes are the plain stripes, each in its layer of the array.
#[test]
fn without_the_fb_api_it_renders_plain_passes_validation_clean() {
    let Some(run) = run_example("no-fb", &["--no-fb"]) else {
        return;
    };
    assert!(
        run.stdout.contains("density images [];")
            && run.stdout.contains("density maps not asked for"),
        "{}",
        run.transcript()
    );
    assert!(
        !run.stderr.contains("density images created"),
        "fovea made density images for an app that never asked\n{}",
        run.transcript()
    );
    let (w, h) = run.swapchain_size();
    let views = run.views();
    assert_eq!(views.len(), 2, "{}", run.transcript());
    for (eye, &(swapchain, index, rect)) in views.iter().enumerate() {
        assert_eq!(swapchain, views[0].0, "one swapchain");
        assert_eq!((index, rect), (eye as u32, [0, 0, w, h]), "view {eye}");
    }
    assert_stripes(&run, false);
}

/// `--offscreen`: the 256×256 and 64×36 passes run before the eyes, and what they drew reaches
/// each eye's upper-right corner (the "shadow map"'s blue stripes, through the tiny target), so
/// neither is dead work; the rest of each eye is the stripes.
#[test]
fn offscreen_passes_reach_the_eyes_validation_clean() {
    let Some(run) = run_example("offscreen", &["--no-fb", "--offscreen"]) else {
        return;
    };
    assert!(
        run.stdout.contains("offscreen passes 256x256,64x36"),
        "{}",
        run.transcript()
    );
    assert_stripes(&run, true);
    for eye in ["left", "right"] {
        let frame = run.frame(eye);
        let (w, h) = (frame.0, frame.1);
        let mut blue = 0;
        for y in (0..h / 4).step_by(5) {
            for x in (w - w / 4..w).step_by(5) {
                let [r, g, b] = pixel(&frame, x, y);
                assert!(
                    b > r.saturating_add(60) && b > g.saturating_add(30),
                    "{eye} corner ({x}, {y}): {:?} is not the offscreen target's blue\n{}",
                    [r, g, b],
                    run.transcript()
                );
                blue += 1;
            }
        }
        assert!(blue > 100, "{blue}");
    }
    // With the FB API too: the offscreen pipelines beside the overlay's sampled density maps.
    run_example("offscreen-fb", &["--offscreen", "--levels", "high"]);
}

/// `--double-wide`: one swapchain twice a view wide, one layer; the runtime receives two views of
/// that swapchain, array index 0, whose image rects are the left and the right half; and both
/// halves are drawn.
#[test]
fn double_wide_submits_the_two_halves_validation_clean() {
    let Some(run) = run_example("double-wide", &["--no-fb", "--double-wide"]) else {
        return;
    };
    assert!(
        run.stdout.contains("double-wide layout"),
        "{}",
        run.transcript()
    );
    let (w, h) = run.swapchain_size();
    assert_eq!(w % 2, 0, "{}", run.transcript());
    let half = w / 2;
    let views = run.views();
    assert_eq!(views.len(), 2, "{}", run.transcript());
    assert_eq!(views[0].0, views[1].0, "one swapchain: {views:?}");
    assert_eq!(
        views.iter().map(|v| (v.1, v.2)).collect::<Vec<_>>(),
        [(0, [0, 0, half, h]), (0, [half, 0, half, h])],
        "{}",
        run.transcript()
    );
    for eye in ["left", "right"] {
        let (fw, fh, _) = run.frame(eye);
        assert_eq!(
            (fw as i32, fh as i32),
            (half, h),
            "{eye}: one half read back"
        );
    }
    assert_stripes(&run, false);
}

/// `--dynamic-rendering`: every pass begun with vkCmdBeginRenderingKHR, in the layouts and modes
/// above: the FB API's overlay with offscreen passes, and a double-wide app without the FB API.
#[test]
fn dynamic_rendering_runs_validation_clean() {
    let Some(run) = run_example(
        "dynamic-rendering-fb",
        &["--dynamic-rendering", "--offscreen", "--levels", "high"],
    ) else {
        return;
    };
    assert!(
        run.stdout
            .contains("eye passes begun with vkCmdBeginRenderingKHR"),
        "{}",
        run.transcript()
    );
    assert!(
        run.stderr.contains("density images created"),
        "{}",
        run.transcript()
    );
    let Some(run) = run_example(
        "dynamic-rendering-no-fb",
        &[
            "--no-fb",
            "--dynamic-rendering",
            "--double-wide",
            "--offscreen",
        ],
    ) else {
        return;
    };
    assert!(
        run.stdout
            .contains("eye passes begun with vkCmdBeginRenderingKHR"),
        "{}",
        run.transcript()
    );
    assert_eq!(run.views().len(), 2, "{}", run.transcript());
    assert_stripes(&run, true);
}

/// On the shading-rate double, playing a desktop GPU (`nvidia`) under the validation layer the
/// example enables: the validation layer it finds is a meta layer of the real one with the double
/// below it (as `hello_xr` does; the loader's "Meta-layers",
/// <https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>). Returns
/// the run and the double's records.
fn run_on_the_double(label: &str, args: &[&str], inject: bool) -> Option<(Run, serde_json::Value)> {
    run_on_the_double_with(label, args, inject, &[])
}

/// [`run_on_the_double`] with more of the example's environment.
fn run_on_the_double_with(
    label: &str,
    args: &[&str],
    inject: bool,
    more: &[(&'static str, &str)],
) -> Option<(Run, serde_json::Value)> {
    let double = match fovea_vkdouble::find_library() {
        Ok(d) => d,
        Err(reason) => {
            skip(&reason);
            return None;
        }
    };
    let Ok(text) = std::fs::read_to_string(VALIDATION) else {
        skip("the Vulkan validation layer is not installed");
        return None;
    };
    let dir = std::env::temp_dir().join(format!(
        "fovea-example-double-{label}-{}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    let explicit = dir.join("explicit");
    std::fs::create_dir_all(&explicit).unwrap();
    fovea_vkdouble::write_manifest(&explicit, &double).unwrap();
    // `VK_LAYER_PATH` replaces the loader's explicit folders, `VK_ADD_LAYER_PATH` included: fovea's
    // Vulkan layer goes there too.
    let lib = fovea_harness::artifact("libfovea.so").expect("libfovea.so: cargo build");
    let checked_in = std::fs::read_to_string(root().join("manifest/vulkan").join(VK_MANIFEST));
    let mut m: serde_json::Value = serde_json::from_str(&checked_in.unwrap()).unwrap();
    m["layer"]["library_path"] = lib.canonicalize().unwrap().to_str().unwrap().into();
    std::fs::write(explicit.join(VK_MANIFEST), m.to_string()).unwrap();
    let mut real: serde_json::Value = serde_json::from_str(&text).unwrap();
    real["layer"]["name"] = "VK_LAYER_FOVEA_test_khronos_validation".into();
    std::fs::write(explicit.join("validation_real.json"), real.to_string()).unwrap();
    let meta = serde_json::json!({
        "file_format_version": "1.1.2",
        "layer": {
            "name": "VK_LAYER_KHRONOS_validation",
            "type": "GLOBAL",
            "api_version": real["layer"]["api_version"],
            "implementation_version": "1",
            "description": "the validation layer above the shading-rate double (fovea's tests)",
            "component_layers": [
                "VK_LAYER_FOVEA_test_khronos_validation",
                fovea_vkdouble::LAYER_NAME.to_str().unwrap(),
            ],
        }
    });
    std::fs::write(explicit.join("validation_meta.json"), meta.to_string()).unwrap();
    let records = dir.join("records.json");
    let mut env: Vec<(&str, OsString)> = vec![
        ("VK_LAYER_PATH", explicit.into_os_string()),
        (
            fovea_vkdouble::RECORDS_FILE_ENV,
            records.clone().into_os_string(),
        ),
        (fovea_vkdouble::PROFILE_ENV, "nvidia".into()),
    ];
    if inject {
        env.push(("FOVEA_INJECT", "1".into()));
        env.push(("FOVEA_INJECT_LEVEL", "high".into()));
    }
    env.extend(more.iter().map(|(k, v)| (*k, OsString::from(v))));
    let run = run_example_with(label, args, &env)?;
    let text = std::fs::read_to_string(&records)
        .unwrap_or_else(|e| panic!("no records ({e})\n{}", run.transcript()));
    std::fs::remove_dir_all(&dir).ok();
    Some((run, serde_json::from_str(&text).unwrap()))
}

/// What the GPU the double plays shades in the example at level HIGH: the double refused nothing;
/// every draw of an eye pass (one whose shading-rate grid spans the swapchain) is coarse somewhere
/// and at full rate somewhere (the fovea), in render passes and dynamic rendering; every draw of the offscreen passes (256×256, 64×36) is at full rate everywhere.
#[test]
fn on_a_desktop_gpu_eye_passes_shade_coarse_and_offscreen_passes_at_full_rate() {
    // Injected (the application without the FB API): the FB API's modes hand validation 1.3.239
    // barriers into the shading-rate stage, which it checks against `shadingRateImage` alone
    // (`vk::layer::assert_only_stage_false_positives`), and the example fails on any message.
    for (label, args, inject) in [
        ("double-inject", &["--no-fb", "--offscreen"][..], true),
        (
            "double-inject-dynamic",
            &["--no-fb", "--offscreen", "--dynamic-rendering"][..],
            true,
        ),
    ] {
        let Some((run, records)) = run_on_the_double(label, args, inject) else {
            return;
        };
        assert_eq!(
            records["errors"],
            serde_json::json!([]),
            "{label}\n{}",
            run.transcript()
        );
        let (width, _) = run.swapchain_size();
        let draws: Vec<&serde_json::Value> = records["events"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|e| e["kind"] == "draw")
            .collect();
        let (mut eye, mut offscreen) = (0, 0);
        for d in &draws {
            for v in d["views"].as_array().unwrap() {
                let codes = v["codes"].as_str().unwrap();
                let columns = v["columns"].as_u64().unwrap() as i32;
                if columns * 16 >= width / 2 {
                    eye += 1;
                    assert!(
                        codes.contains('0') && codes.chars().any(|c| c != '0'),
                        "{label}: an eye pass's draw at HIGH: {d}"
                    );
                } else {
                    offscreen += 1;
                    assert!(
                        codes.chars().all(|c| c == '0'),
                        "{label}: an offscreen pass's draw: {d}"
                    );
                }
            }
        }
        assert!(
            eye >= 2 && offscreen >= 2,
            "{label}: {eye} eye and {offscreen} offscreen draws"
        );
    }
}

/// The left view's located FOV from the example's stdout, as tangents (left, right, up, down).
fn left_tangents(run: &Run) -> [f64; 4] {
    let fov = run
        .stdout
        .split_once("(left,right,up,down per view) ")
        .and_then(|(_, rest)| rest.split_whitespace().next())
        .map(|v| {
            v.split(',')
                .map(|a| a.parse::<f64>().unwrap().tan())
                .collect::<Vec<_>>()
        })
        .unwrap_or_else(|| panic!("no located FOVs\n{}", run.transcript()));
    [fov[0], fov[1], fov[2], fov[3]]
}

/// Degrees from the projection centre (the fixed fovea) of pixel `(x, y)` of a view `size` big.
fn eccentricity([l, r, u, d]: [f64; 4], size: (usize, usize), x: f64, y: f64) -> f64 {
    let tx = l + x / size.0 as f64 * (r - l);
    let ty = u - y / size.1 as f64 * (u - d);
    (tx * tx + ty * ty).sqrt().atan().to_degrees()
}

/// What a user of a desktop GPU sees of the room scene (`--scene room`: textured down to the
/// pixel, so a block of pixels is uniform only where coarse fragments made it so) with fovea's
/// injection at HIGH (HIGH's floor is ¼ beyond 30°, so the map asks for 4×4 there), on the
/// shading-rate double, read back in the frame's own command buffer (`--dump`) and compared with
/// the same frame at full rate (injection off): beyond 40° from the fovea nearly every 4×4 block is
/// uniform (at full rate nearly none), and within 12° every pixel is the full-rate one. The check
/// issue 30's reconstruction will turn around in the periphery (few uniform blocks) while keeping
/// the fovea; `scripts/perceptual.sh` measures the same per band with a perceptual metric.
#[test]
fn on_a_desktop_gpu_the_rooms_periphery_is_coarse_blocks_and_its_fovea_full_rate() {
    let args = ["--no-fb", "--scene", "room"];
    let Some((full, records)) = run_on_the_double("room-full", &args, false) else {
        return;
    };
    assert_eq!(
        records["errors"],
        serde_json::json!([]),
        "{}",
        full.transcript()
    );
    // The blocks as they are: reconstruction off, whatever its default (docs/reconstruction.md).
    let off = [("DEBUG_OCULUS_FOVEATION_SUBSAMPLED", "0")];
    let Some((high, records)) = run_on_the_double_with("room-high", &args, true, &off) else {
        return;
    };
    assert_eq!(
        records["errors"],
        serde_json::json!([]),
        "{}",
        high.transcript()
    );
    let tangents = left_tangents(&full);
    let (f, h) = (full.frame("left"), high.frame("left"));
    assert_eq!((f.0, f.1), (h.0, h.1));
    let size = (f.0, f.1);
    let block = 4;
    let share = |frame: &(usize, usize, Vec<u8>)| {
        fovea_vkdouble::blocks::uniform_share(
            &frame.2,
            [size.0 as u32, size.1 as u32],
            4,
            block,
            |x, y| {
                let c = (x + block / 2) as f64;
                eccentricity(tangents, size, c, (y + block / 2) as f64) >= 40.0
            },
        )
        .expect("blocks beyond 40°")
    };
    let (blocky_full, blocky_high) = (share(&f), share(&h));
    assert!(
        blocky_high >= 0.95 && blocky_full <= 0.2,
        "uniform 4×4 blocks beyond 40°: {blocky_high:.3} at HIGH, {blocky_full:.3} at full rate\n{}",
        high.transcript()
    );
    let (mut fovea, mut same) = (0, 0);
    for y in 0..size.1 {
        for x in 0..size.0 {
            if eccentricity(tangents, size, x as f64 + 0.5, y as f64 + 0.5) < 12.0 {
                fovea += 1;
                same += usize::from(pixel(&f, x, y) == pixel(&h, x, y));
            }
        }
    }
    assert!(fovea > 1000, "{fovea} pixels within 12°");
    assert_eq!(
        same,
        fovea,
        "fovea pixels equal to full rate\n{}",
        high.transcript()
    );
}

/// The share of uniform 4×4 blocks beyond 40° from the fovea of the left eye's frame.
fn periphery_uniform_share(tangents: [f64; 4], frame: &(usize, usize, Vec<u8>)) -> f64 {
    let size = (frame.0, frame.1);
    let block = 4;
    fovea_vkdouble::blocks::uniform_share(
        &frame.2,
        [size.0 as u32, size.1 as u32],
        4,
        block,
        |x, y| {
            let c = (x + block / 2) as f64;
            eccentricity(tangents, size, c, (y + block / 2) as f64) >= 40.0
        },
    )
    .expect("blocks beyond 40°")
}

/// Issue 30's reconstruction, as a user of a desktop GPU sees it (docs/reconstruction.md): the room
/// scene with injection at HIGH on the shading-rate double, read back in the frame's own command
/// buffer (`--dump`, after the double left each eye pass's colour coarse at its end), with and
/// without `debug.oculus.foveation.subsampled=1` (Quest's property, forcing the subsampled
/// layout on, which fovea turns into reconstruction on desktop GPUs). Without it, beyond 40°
/// nearly every 4×4 block is uniform; with it few are, and within 12° every pixel is the one
/// the frame has without reconstruction: the fovea, shaded at full rate, is never touched. In a
/// render pass (multiview, two layers) and in dynamic rendering; the swapchain is sRGB.
#[test]
fn on_a_desktop_gpu_reconstruction_smooths_the_rooms_periphery_and_keeps_its_fovea() {
    for (label, extra) in [("rp", &[][..]), ("dynamic", &["--dynamic-rendering"][..])] {
        let mut args = vec!["--no-fb", "--scene", "room"];
        args.extend_from_slice(extra);
        // Quest's property off: no reconstruction, whatever the default.
        let off = [("DEBUG_OCULUS_FOVEATION_SUBSAMPLED", "0")];
        let Some((blocky, records)) =
            run_on_the_double_with(&format!("room-blocky-{label}"), &args, true, &off)
        else {
            return;
        };
        assert_eq!(
            records["errors"],
            serde_json::json!([]),
            "{}",
            blocky.transcript()
        );
        let recon_env = [("DEBUG_OCULUS_FOVEATION_SUBSAMPLED", "1")];
        let Some((smooth, records)) =
            run_on_the_double_with(&format!("room-smooth-{label}"), &args, true, &recon_env)
        else {
            return;
        };
        assert_eq!(
            records["errors"],
            serde_json::json!([]),
            "{}",
            smooth.transcript()
        );
        let tangents = left_tangents(&blocky);
        let (b, r) = (blocky.frame("left"), smooth.frame("left"));
        assert_eq!((b.0, b.1), (r.0, r.1));
        let (before, after) = (
            periphery_uniform_share(tangents, &b),
            periphery_uniform_share(tangents, &r),
        );
        eprintln!(
            "{label}: uniform 4×4 blocks beyond 40°: {before:.3} blocky, {after:.3} reconstructed"
        );
        assert!(
            before >= 0.95 && after <= 0.2,
            "{label}: uniform 4×4 blocks beyond 40°: {before:.3} without, {after:.3} with \
             reconstruction\n{}",
            smooth.transcript()
        );
        let size = (b.0, b.1);
        let (mut fovea, mut same) = (0, 0);
        for y in 0..size.1 {
            for x in 0..size.0 {
                if eccentricity(tangents, size, x as f64 + 0.5, y as f64 + 0.5) < 12.0 {
                    fovea += 1;
                    same += usize::from(pixel(&b, x, y) == pixel(&r, x, y));
                }
            }
        }
        assert!(fovea > 1000, "{fovea} pixels within 12°");
        assert_eq!(
            same,
            fovea,
            "{label}: fovea pixels kept\n{}",
            smooth.transcript()
        );
    }
}
