//! Khronos `hello_xr` (Debian's libopenxr-utils) through the real Khronos loader, fovea and the
//! simulated headset on Mesa's lavapipe: an application nobody here wrote, with both Vulkan paths
//! (`-g Vulkan2` = XR_KHR_vulkan_enable2, `-g Vulkan` = XR_KHR_vulkan_enable), alone and under the
//! Khronos core validation layer.
//!
//! Each run is a child process, so the loader's one-instance-per-process rule and its environment
//! stay out of the test process. The simulated runtime requests exit after
//! `FOVEA_SIM_EXIT_AFTER_FRAMES` frames and prints a `fovea-sim: summary frames=N errors=M` line
//! when hello_xr destroys its instance (`FOVEA_SIM_SUMMARY=1`); that line is how the test knows how
//! many frames reached the runtime and that none of hello_xr's calls failed there.
//!
//! A run passes when hello_xr exits with status 0, the runtime saw at least [`FRAMES`] frames and
//! no errors, hello_xr went through FOCUSED to EXITING, and nothing on stdout or stderr is a
//! validation message (OpenXR core validation, the Vulkan validation layer that hello_xr enables
//! where it is installed, fovea's own warnings).
//!
//! The same runs with fovea's Vulkan layer where the Vulkan loader finds it (an explicit manifest on
//! `VK_ADD_LAYER_PATH` for `-g Vulkan2`, the implicit manifest in the per-user folder for
//! `-g Vulkan`) show that the layer is loaded into hello_xr's VkInstance, decides to pass lavapipe
//! through (no shading-rate attachments to emulate density maps on), and changes nothing: the
//! same frames, exit and silence.
//!
//! Injection (docs/injection.md): hello_xr never asks for foveation. With `FOVEA_INJECT=1` at each
//! level, through fovea's Vulkan layer above the Vulkan validation layer and the shading-rate double
//! (a meta layer puts the double below the validation layer hello_xr enables itself), each of its
//! eye passes reaches the driver with a shading-rate attachment whose codes are
//! `fovea_model::inject::codes` for that eye at the headset's FOVs, with the same clean exit and
//! silence; with injection off, no pass gets one.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::time::Duration;

use fovea_abi::log_target;
use fovea_harness::{skip, CORE_VALIDATION_LAYER, FOVEA_LAYER};

use crate::support::device::inject_device;
use crate::support::{root, Manifests, CORE_VALIDATION_MANIFEST, DEBIAN_LAYERS};

/// Frames the runtime asks for before it requests exit (the "at least 300 frames").
const FRAMES: u64 = 300;
/// A run takes 5-15 s on two shared cores with a debug build; hello_xr stuck in a loop that never
/// sees the exit request must fail the test, not hang CI.
const TIMEOUT: Duration = Duration::from_secs(240);
/// Where Mesa installs lavapipe's ICD manifest on Debian (x86-64), and the generic search folders.
const ICD_DIRS: [&str; 2] = ["/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d"];

/// lavapipe renders 2 × 2064×2240 per frame on the CPU; two runs at once only slow each other down
/// (and every other test) on a small CI machine.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// What a run needs from the system, or the reason to skip.
pub(crate) struct System {
    pub(crate) hello_xr: PathBuf,
    pub(crate) lavapipe_icd: PathBuf,
}

pub(crate) fn find_system() -> Result<System, String> {
    let hello_xr = std::env::var_os("PATH")
        .iter()
        .flat_map(std::env::split_paths)
        .map(|d| d.join("hello_xr"))
        .find(|p| p.is_file())
        .ok_or("hello_xr is not installed (Debian: libopenxr-utils)")?;
    let lavapipe_icd = ICD_DIRS
        .iter()
        .filter_map(|d| std::fs::read_dir(d).ok())
        .flatten()
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("lvp_icd") && n.ends_with(".json"))
        })
        .ok_or("Mesa's lavapipe Vulkan driver is not installed (Debian: mesa-vulkan-drivers)")?;
    Ok(System {
        hello_xr,
        lavapipe_icd,
    })
}

/// What one hello_xr run left behind.
pub(crate) struct Run {
    pub(crate) code: Option<i32>,
    pub(crate) stdout: String,
    pub(crate) stderr: String,
}

impl Run {
    pub(crate) fn transcript(&self) -> String {
        format!(
            "exit code {:?}\n--- stdout ---\n{}\n--- stderr ---\n{}",
            self.code, self.stdout, self.stderr
        )
    }
}

/// The validation layer's environment value that turns on synchronization validation.
pub(crate) const SYNC_VALIDATION: &str =
    "VK_VALIDATION_FEATURE_ENABLE_SYNCHRONIZATION_VALIDATION_EXT";

/// Runs hello_xr with `-g graphics -v`, `layers` enabled (first = closest to the app) and `env` set
/// on top of the test's own environment.
fn run_hello_xr(system: &System, graphics: &str, layers: &[&str], env: &[(&str, OsString)]) -> Run {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let manifests = Manifests::write(&format!("hello-xr-{graphics}"));
    let mut cmd = Command::new(&system.hello_xr);
    cmd.args(["-g", graphics, "-v"]);
    // Nothing from the caller's environment may change what the loader, Vulkan, the layer or the
    // runtime do (an exported XR_ENABLE_API_LAYERS, FOVEA_SIM_FAULT or VK_INSTANCE_LAYERS).
    for (key, _) in std::env::vars_os() {
        let k = key.to_string_lossy();
        if k.starts_with("XR_") || k.starts_with("FOVEA_") || k.starts_with("VK_") {
            cmd.env_remove(&key);
        }
    }
    cmd.env("XR_RUNTIME_JSON", manifests.dir.join("runtime.json"))
        .env(
            "XR_API_LAYER_PATH",
            format!("{}:{DEBIAN_LAYERS}", manifests.dir.join("layers").display()),
        )
        .env("XR_ENABLE_API_LAYERS", layers.join(":"))
        .env("VK_ICD_FILENAMES", &system.lavapipe_icd)
        .env("VK_DRIVER_FILES", &system.lavapipe_icd)
        // hello_xr enables the validation layer without its synchronization validation: the
        // layer's environment settings turn it on (`VK_LAYER_ENABLES` in 1.3.2xx, still read by
        // 1.4.3xx beside `VK_LAYER_VALIDATE_SYNC`;
        // <https://vulkan.lunarg.com/doc/sdk/latest/linux/khronos_validation_layer.html>).
        .env("VK_LAYER_ENABLES", SYNC_VALIDATION)
        .env("VK_LAYER_VALIDATE_SYNC", "1")
        .env("FOVEA_SIM_EXIT_AFTER_FRAMES", FRAMES.to_string())
        .env("FOVEA_SIM_SUMMARY", "1")
        .envs(env.iter().map(|(k, v)| (k, v)))
        // hello_xr quits when a key is pressed, and a closed stdin reads as one: keep a pipe open
        // until it has exited.
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let done = crate::support::run_with_timeout(&mut cmd, TIMEOUT);
    let status = done.status;
    let run = Run {
        code: status.and_then(|s| s.code()),
        stdout: done.stdout,
        stderr: done.stderr,
    };
    assert!(
        status.is_some(),
        "hello_xr -g {graphics} still running after {TIMEOUT:?}; killed\n{}",
        run.transcript()
    );
    run
}

/// `(frames, errors)` from the runtime's summary line.
fn summary(stderr: &str) -> Option<(u64, u64)> {
    let line = stderr
        .lines()
        .find_map(|l| l.split_once("fovea-sim: summary ").map(|(_, s)| s))?;
    let field = |name: &str| {
        line.split_whitespace()
            .find_map(|w| w.strip_prefix(name)?.parse::<u64>().ok())
    };
    Some((field("frames=")?, field("errors=")?))
}

/// fovea's log lines below warning level on stderr (`<time>  INFO fovea::…: …`): what the runs with
/// `FOVEA_LOG=…=info` read, not complaints.
fn is_fovea_info(line: &str) -> bool {
    let mut words = line.split_whitespace().take(3);
    let level = words.find(|w| ["INFO", "DEBUG", "TRACE"].contains(w));
    level.is_some() && words.next().is_some_and(|t| t.starts_with("fovea"))
}

/// hello_xr's own log lines start with `[HH:MM:SS.mmm][Level  ]`.
fn is_hello_xr_log(line: &str) -> bool {
    let b = line.as_bytes();
    b.len() > 15 && b[0] == b'[' && b[3] == b':' && b[6] == b':' && b[13] == b']' && b[14] == b'['
}

/// Every line that is a message from a validation layer or a complaint from fovea:
/// - on stdout, anything that is not hello_xr's own log: the OpenXR core validation layer and the
///   Vulkan validation layer (before hello_xr's debug messenger exists) print raw lines there. The
///   core validation layer's banner ("Core Validation output type: text", on stdout or stderr
///   depending on the build) is not a message;
/// - hello_xr log lines of level Error or Warning, and the Vulkan validation layer's messages that
///   hello_xr's debug callback forwards (logged at Info as `ERROR:`, `WARNING:`, `PERF:`);
/// - on stderr, any line other than the runtime's summary and fovea's info lines (fovea logs
///   warnings and errors there).
pub(crate) fn messages(run: &Run) -> Vec<String> {
    let banner = |l: &str| l.starts_with("Core Validation output type:");
    // An indented line continues the record above it (the validation layer's "Khronos Validation
    // Layer Active" info record lists its enables so) and is a message where that record is.
    let mut previous = false;
    let stdout = run.stdout.lines().filter(move |l| {
        let l = l.trim_end();
        if l.starts_with("    ") && !l.trim().is_empty() {
            return previous;
        }
        previous = is_message(l);
        previous
    });
    fn is_message(l: &str) -> bool {
        let banner = |l: &str| l.starts_with("Core Validation output type:");
        // Core validation 1.1's own debug and info records (`[time][VALID_DEBUG|VUID|function]:
        // ...`, e.g. that it was initialised and destroyed); its warnings and errors are
        // `VALID_WARNING` and `VALID_ERROR`.
        let core_info = |l: &str| {
            l.starts_with('[') && (l.contains("][VALID_DEBUG|") || l.contains("][VALID_INFO|"))
        };
        if l.is_empty() || banner(l) || core_info(l) {
            return false;
        }
        if !is_hello_xr_log(l) {
            return true;
        }
        let body = &l[15..];
        body.starts_with("Error")
            || body.starts_with("Warning")
            || ["] ERROR:", "] WARNING:", "] PERF:"]
                .iter()
                .any(|m| l.contains(m))
    }
    let stderr = run.stderr.lines().filter(|l| {
        !l.trim().is_empty()
            && !banner(l)
            && !l.contains("fovea-sim: summary ")
            && !is_fovea_info(l)
    });
    stdout.chain(stderr).map(str::to_owned).collect()
}

/// The whole check for one configuration; skips where the system lacks hello_xr or lavapipe.
fn hello_xr_passes(graphics: &str, layers: &[&str]) {
    hello_xr_passes_with(graphics, layers, &[]);
}

/// [`hello_xr_passes`] with `env` added; the run, `None` where it skipped.
fn hello_xr_passes_with(graphics: &str, layers: &[&str], env: &[(&str, OsString)]) -> Option<Run> {
    let system = match find_system() {
        Ok(s) => s,
        Err(reason) => {
            skip(&reason);
            return None;
        }
    };
    if layers.contains(&CORE_VALIDATION_LAYER)
        && !Path::new(DEBIAN_LAYERS)
            .join(CORE_VALIDATION_MANIFEST)
            .exists()
    {
        skip("the Khronos core validation layer is not installed (openxr-layer-corevalidation)");
        return None;
    }
    let run = run_hello_xr(&system, graphics, layers, env);
    let label = format!("hello_xr -g {graphics} with {layers:?}");
    assert_eq!(run.code, Some(0), "{label}\n{}", run.transcript());
    let (frames, errors) = summary(&run.stderr)
        .unwrap_or_else(|| panic!("{label}: no runtime summary line\n{}", run.transcript()));
    assert!(
        frames >= FRAMES,
        "{label}: {frames} frames\n{}",
        run.transcript()
    );
    assert_eq!(
        errors,
        0,
        "{label}: calls failed in the runtime\n{}",
        run.transcript()
    );
    for state in [
        "->XR_SESSION_STATE_FOCUSED",
        "->XR_SESSION_STATE_STOPPING",
        "->XR_SESSION_STATE_EXITING",
    ] {
        assert!(
            run.stdout.contains(state),
            "{label}: never {state}\n{}",
            run.transcript()
        );
    }
    let messages = messages(&run);
    assert!(
        messages.is_empty(),
        "{label}: {} validation messages:\n{}\n\n{}",
        messages.len(),
        messages.join("\n"),
        run.transcript()
    );
    Some(run)
}

pub(crate) const VK_MANIFEST: &str = "VK_LAYER_FOVEA_fragment_density_map.json";
/// fovea's line on creating a VkInstance (target [`log_target::VK_INSTANCE`]).
pub(crate) const VK_INSTANCE_LINE: &str = "the Vulkan layer is in this VkInstance";
/// The end of fovea's line on a physical device it does not emulate on.
const PASS_THROUGH_LINE: &str = "fragment density maps: passing through";
/// Why lavapipe is passed through: no shading-rate attachments. With the implicit manifest the
/// Vulkan loader lists the manifest's own `device_extensions` below the layer; the layer must not
/// take that for a native implementation (it asks for the feature).
const PASS_THROUGH_WHY: &str = "the driver offers no VK_KHR_fragment_shading_rate";

/// hello_xr with fovea's Vulkan layer findable: `implicit` puts the implicit manifest (switched on
/// by the variable fovea's OpenXR layer sets) in the loader's per-user folder, otherwise the
/// explicit manifest goes on `VK_ADD_LAYER_PATH`. Both point at this build's libfovea.so. Asserts
/// everything [`hello_xr_passes`] does, and that the layer was in the VkInstance and passed
/// lavapipe through.
fn hello_xr_passes_through_the_vulkan_layer(graphics: &str, implicit: bool) {
    if let Err(reason) = find_system() {
        skip(&reason);
        return;
    }
    let dir = std::env::temp_dir().join(format!(
        "fovea-hello-xr-vk-{graphics}-{}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    let data = dir.join("data");
    let explicit = dir.join("explicit");
    let (manifest_dir, checked_in) = if implicit {
        (
            data.join("vulkan/implicit_layer.d"),
            root().join("manifest/vulkan/implicit").join(VK_MANIFEST),
        )
    } else {
        (
            explicit.clone(),
            root().join("manifest/vulkan").join(VK_MANIFEST),
        )
    };
    std::fs::create_dir_all(&manifest_dir).unwrap();
    std::fs::create_dir_all(&explicit).unwrap();
    let lib = fovea_harness::artifact("libfovea.so").expect("libfovea.so: cargo build");
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(checked_in).unwrap()).unwrap();
    m["layer"]["library_path"] = lib.canonicalize().unwrap().to_str().unwrap().into();
    std::fs::write(manifest_dir.join(VK_MANIFEST), m.to_string()).unwrap();
    let filter = format!("warn,fovea::vk=info,{}=info", log_target::VK_INSTANCE);
    let env = [
        // The per-user folders are the test's own: no implicit layer from the user's install.
        ("XDG_DATA_HOME", data.into_os_string()),
        ("XDG_CONFIG_HOME", dir.join("config").into_os_string()),
        ("VK_ADD_LAYER_PATH", explicit.into_os_string()),
        (fovea_abi::env::LOG, filter.into()),
        (fovea_abi::env::LOG_FILE, OsString::new()),
    ];
    let run = hello_xr_passes_with(graphics, &[FOVEA_LAYER], &env);
    std::fs::remove_dir_all(&dir).ok();
    let Some(run) = run else { return };
    let label = format!("hello_xr -g {graphics} with fovea's Vulkan layer");
    assert!(
        run.stderr.contains(VK_INSTANCE_LINE),
        "{label}: the Vulkan layer was not loaded\n{}",
        run.transcript()
    );
    assert!(
        run.stderr
            .lines()
            .any(|l| l.contains(PASS_THROUGH_LINE) && l.contains(PASS_THROUGH_WHY)),
        "{label}: no pass-through decision for lavapipe, for want of shading-rate attachments\n{}",
        run.transcript()
    );
    assert!(
        !run.stderr.lines().any(|l| {
            l.contains("emulates fragment density maps")
                || l.contains("emulating VK_EXT_fragment_density_map")
        }),
        "{label}: the layer emulates on lavapipe\n{}",
        run.transcript()
    );
}

#[test]
fn vulkan2_runs_300_frames_and_exits_cleanly() {
    hello_xr_passes("Vulkan2", &[FOVEA_LAYER]);
}

#[test]
fn vulkan_runs_300_frames_and_exits_cleanly() {
    hello_xr_passes("Vulkan", &[FOVEA_LAYER]);
}

/// Core validation above fovea checks every call hello_xr makes, as the app made it. (Below fovea,
/// Debian's 1.0.20 core validation prints an internal error on the NULL-instance lookups fovea
/// makes while creating its instance, a bug of that layer, so that order is not tested here; the
/// in-process harness covers both orders without hello_xr.)
#[test]
fn vulkan2_under_core_validation_has_no_messages() {
    hello_xr_passes("Vulkan2", &[CORE_VALIDATION_LAYER, FOVEA_LAYER]);
}

#[test]
fn vulkan_under_core_validation_has_no_messages() {
    hello_xr_passes("Vulkan", &[CORE_VALIDATION_LAYER, FOVEA_LAYER]);
}

/// hello_xr with the simulated headset's eye tracker on: its stats lines, and whether the runtime
/// refused anything (under core validation). `inject` turns injection on, which uses the gaze.
fn hello_xr_with_an_eye_tracker(inject: bool) -> Option<(Vec<String>, Run)> {
    let mut env = vec![
        ("FOVEA_SIM_EYE_GAZE", OsString::from("on")),
        ("FOVEA_SIM_GAZE", OsString::from("fix 12,0 for 60s")),
        ("FOVEA_SIM_LOG_REFUSALS", OsString::from("1")),
        (
            fovea_abi::env::LOG,
            OsString::from(format!("warn,{}=info", log_target::STATS)),
        ),
    ];
    if inject {
        env.push(("FOVEA_INJECT", OsString::from("1")));
    }
    let run = hello_xr_passes_with("Vulkan2", &[CORE_VALIDATION_LAYER, FOVEA_LAYER], &env)?;
    let stats: Vec<String> = run
        .stderr
        .lines()
        .filter(|l| l.contains("fovea::stats: FPS="))
        .map(String::from)
        .collect();
    assert!(stats.len() >= 2, "{}", run.transcript());
    assert!(
        !run.stderr.contains("fovea-sim: refused"),
        "{}",
        run.transcript()
    );
    Some((stats, run))
}

/// hello_xr has input of its own (action sets, suggestions for controllers, a sync every frame) but
/// enables nothing of fovea's: with the simulated headset's eye tracker on, fovea touches no eye
/// gaze (docs/eye-tracking.md#who-uses-the-gaze), and the stats line says the gaze is off.
#[test]
fn vulkan2_with_an_eye_tracker_and_nothing_that_uses_it_the_gaze_is_off() {
    let Some((stats, _)) = hello_xr_with_an_eye_tracker(false) else {
        return;
    };
    assert!(stats.iter().all(|l| l.contains(" Gaze=off")), "{stats:#?}");
}

/// With injection on (which follows the gaze), fovea's gaze set rides along with hello_xr's, the
/// stats line shows the gaze tracked where the script looks (right of centre in the left eye), and
/// nothing is refused or said, under core validation.
#[test]
fn vulkan2_with_an_eye_tracker_and_injection_the_gaze_is_tracked_and_nothing_is_said() {
    let Some((stats, _)) = hello_xr_with_an_eye_tracker(true) else {
        return;
    };
    assert!(
        stats[1..].iter().all(|l| l.contains(" Gaze=tracked@+")),
        "{stats:#?}"
    );
}

#[test]
fn vulkan2_with_the_explicit_vulkan_layer_passes_through_unchanged() {
    hello_xr_passes_through_the_vulkan_layer("Vulkan2", false);
}

#[test]
fn vulkan_with_the_implicit_vulkan_layer_passes_through_unchanged() {
    hello_xr_passes_through_the_vulkan_layer("Vulkan", true);
}

#[test]
fn summary_and_message_filters() {
    assert_eq!(
        summary("x\nfovea-sim: summary frames=301 errors=2 [xrFoo:2]\n"),
        Some((301, 2))
    );
    assert_eq!(summary("nothing"), None);
    let run = Run {
        code: Some(0),
        stdout: [
            "[12:36:35.306][Info   ] Instance RuntimeName=fovea simulated headset",
            "[12:36:35.634][Info   ] INFO: (INSTANCE 0x1) [Loader Message] linux_read_sorted",
            "",
            "Core Validation output type: text, first time = true",
            "VUID-vkCreateInstance-ppEnabledExtensionNames-01388(ERROR / SPEC): msgNum: 1",
            "[12:36:35.634][Info   ] WARNING: (DEVICE 0x2) [Validation] something",
            "[12:36:35.634][Error  ] Error: xrFoo failed",
        ]
        .join("\n"),
        stderr: "Core Validation output type: text, first time = true\n\
                 fovea-sim: summary frames=300 errors=0 []\nWARN fovea::loader: x\n\
                 2026-11-23T19:41:57.123456Z  INFO fovea::vk_instance: the Vulkan layer\n"
            .into(),
    };
    let m = messages(&run);
    assert_eq!(m.len(), 4, "{m:?}");
    assert!(m[0].starts_with("VUID-") && m[3].starts_with("WARN fovea"));
}

/// Frames an injected run asks for: the double keeps every shading-rate image's codes per submit.
const INJECTED_FRAMES: u64 = 40;

/// The recommended view size and the FOVs the simulated headset gives an application through
/// fovea, asked in this process (hello_xr gets the same: one runtime, its default configuration).
fn headset_views() -> ([u32; 2], [fovea_model::Fov; 2]) {
    use fovea_harness::{app::API_1_0, App, Chain};
    fovea_harness::sim::control::set_thread_config(None);
    let app = App::new(Chain::fovea().unwrap(), &["XR_MND_headless"], API_1_0).unwrap();
    let sizes = crate::xr::symmetric_fov::views(&app);
    let session = app.headless_session().unwrap();
    crate::xr::symmetric_fov::begin(&app, session);
    let fovs = crate::xr::symmetric_fov::locate(&app, session);
    assert_eq!(app.destroy(), openxr_sys::Result::SUCCESS);
    ([sizes[0][0], sizes[0][1]], fovs)
}

/// hello_xr with injection on (`level`) or off through fovea's OpenXR layer and its Vulkan layer,
/// above the Vulkan validation layer and the shading-rate double (`nvidia` profile), which writes
/// what reached the driver to a file when hello_xr destroys its VkInstance. Asserts a clean run (exit
/// status 0, the frames, no runtime errors, no validation message, the double saw no misuse) and
/// returns the double's events; `None` where the system lacks hello_xr or lavapipe.
fn hello_xr_on_the_double(graphics: &str, level: Option<&str>) -> Option<Vec<serde_json::Value>> {
    hello_xr_on_the_double_for(graphics, level, INJECTED_FRAMES).map(|(events, _)| events)
}

/// [`hello_xr_on_the_double`] for `frames` frames, with fovea's stats lines on; also returns
/// hello_xr's stderr, where fovea logs.
fn hello_xr_on_the_double_for(
    graphics: &str,
    level: Option<&str>,
    frames: u64,
) -> Option<(Vec<serde_json::Value>, String)> {
    let system = match find_system() {
        Ok(s) => s,
        Err(reason) => {
            skip(&reason);
            return None;
        }
    };
    let double = match fovea_vkdouble::find_library() {
        Ok(d) => d,
        Err(reason) => {
            skip(&reason);
            return None;
        }
    };
    let dir = std::env::temp_dir().join(format!(
        "fovea-hello-xr-inject-{graphics}-{}-{}",
        level.unwrap_or("off"),
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    let explicit = dir.join("explicit");
    std::fs::create_dir_all(&explicit).unwrap();
    fovea_vkdouble::write_manifest(&explicit, &double).unwrap();
    let lib = fovea_harness::artifact("libfovea.so").expect("libfovea.so: cargo build");
    let lib = lib.canonicalize().unwrap();
    // fovea's Vulkan layer: explicit (fovea's OpenXR layer names it in the VkInstance for
    // XR_KHR_vulkan_enable2) and implicit (switched on by the variable it sets, for
    // XR_KHR_vulkan_enable, where hello_xr makes the VkInstance itself).
    let implicit = dir.join("data/vulkan/implicit_layer.d");
    std::fs::create_dir_all(&implicit).unwrap();
    let mut manifests = vec![(root().join("manifest/vulkan").join(VK_MANIFEST), &explicit)];
    if graphics == "Vulkan" {
        manifests.push((
            root().join("manifest/vulkan/implicit").join(VK_MANIFEST),
            &implicit,
        ));
    }
    for (from, to) in manifests {
        let mut m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(from).unwrap()).unwrap();
        m["layer"]["library_path"] = lib.to_str().unwrap().into();
        std::fs::write(to.join(VK_MANIFEST), m.to_string()).unwrap();
    }
    // hello_xr enables VK_LAYER_KHRONOS_validation itself, and the loader puts layers named in
    // the environment above the application's, so the double cannot be named there: it would sit
    // above fovea. Instead the validation layer hello_xr finds (the only explicit folder is the
    // test's, `VK_LAYER_PATH`) is a meta layer of the real one, under another name, and the double
    // below it (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>,
    // "Meta-layers").
    let system_validation =
        std::path::Path::new("/usr/share/vulkan/explicit_layer.d/VkLayer_khronos_validation.json");
    let Ok(text) = std::fs::read_to_string(system_validation) else {
        skip("the Vulkan validation layer is not installed");
        return None;
    };
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
    let mut env = vec![
        ("XDG_DATA_HOME", dir.join("data").into_os_string()),
        ("XDG_CONFIG_HOME", dir.join("config").into_os_string()),
        ("VK_LAYER_PATH", explicit.into_os_string()),
        (
            fovea_vkdouble::RECORDS_FILE_ENV,
            records.clone().into_os_string(),
        ),
        (fovea_vkdouble::PROFILE_ENV, "nvidia".into()),
        ("FOVEA_SIM_EXIT_AFTER_FRAMES", frames.to_string().into()),
        (
            fovea_abi::env::LOG,
            format!(
                "warn,fovea::vk=info,fovea::xr::loader=info,{}=info",
                log_target::STATS
            )
            .into(),
        ),
        (fovea_abi::env::LOG_FILE, OsString::new()),
    ];
    if let Some(level) = level {
        env.push(("FOVEA_INJECT", "1".into()));
        env.push(("FOVEA_INJECT_LEVEL", level.into()));
    }
    let run = run_hello_xr(&system, graphics, &[FOVEA_LAYER], &env);
    let label = format!("hello_xr -g {graphics} on the double, injection {level:?}");
    assert_eq!(run.code, Some(0), "{label}\n{}", run.transcript());
    let (ran, errors) = summary(&run.stderr)
        .unwrap_or_else(|| panic!("{label}: no runtime summary line\n{}", run.transcript()));
    assert!(ran >= frames, "{label}: {ran} frames");
    assert_eq!(errors, 0, "{label}\n{}", run.transcript());
    let messages = messages(&run);
    assert!(
        messages.is_empty(),
        "{label}: {} validation messages:\n{}",
        messages.len(),
        messages.join("\n")
    );
    let text = std::fs::read_to_string(&records)
        .unwrap_or_else(|e| panic!("{label}: no records ({e})\n{}", run.transcript()));
    std::fs::remove_dir_all(&dir).ok();
    let records: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(records["errors"], serde_json::json!([]), "{label}");
    if level.is_some() {
        assert!(
            run.stderr.contains("injected shading-rate map made"),
            "{label}\n{}",
            run.transcript()
        );
    }
    Some((
        records["events"].as_array().cloned().unwrap_or_default(),
        run.stderr,
    ))
}

/// hello_xr's eye passes (one swapchain per eye: fovea guesses view 0 and view 1 from the first two
/// of the recommended size) carry the maps of `fovea_model::inject::codes` for the headset's FOVs at
/// each level; nothing else reaches a shading-rate attachment but full-rate maps.
fn hello_xr_eye_passes_carry_the_injected_maps(graphics: &str) {
    use fovea_model::density::{Level, Pattern};
    use fovea_model::inject::Views;
    let (extent, fovs) = headset_views();
    for level in Level::ALL {
        let Some(events) = hello_xr_on_the_double(graphics, Some(level.name())) else {
            return;
        };
        let of = |kind: &'static str| events.iter().filter(move |e| e["kind"] == kind);
        let device = of("device").next().expect("a device");
        assert_eq!(
            device["features"]["attachment"], true,
            "{level:?}: {device}"
        );
        // Every pass hello_xr begins names a shading-rate view of fovea's.
        let begins: Vec<&serde_json::Value> = of("begin_render_pass").collect();
        assert!(
            begins.len() as u64 >= INJECTED_FRAMES,
            "{level:?}: {} passes",
            begins.len()
        );
        let image_of = |view: &serde_json::Value| {
            of("image_view")
                .find(|v| &v["view"] == view)
                .map(|v| v["image"].clone())
                .unwrap_or_else(|| panic!("{level:?}: no shading-rate view {view}"))
        };
        let mut images: Vec<serde_json::Value> = begins
            .iter()
            .map(|b| {
                let v = b["shading_rate_views"].as_array().unwrap();
                assert_eq!(v.len(), 1, "{level:?}: {b}");
                image_of(&v[0])
            })
            .collect();
        images.sort_by_key(|i| i.as_u64());
        images.dedup();
        assert_eq!(images.len(), 2, "{level:?}: one map per eye: {images:?}");
        // The codes each map held when the last submit read it.
        let device_model = inject_device(fovea_vkdouble::Profile::Nvidia);
        let mut all = [None; fovea_model::maps::MAX_VIEWS];
        all[0] = Some(fovs[0]);
        all[1] = Some(fovs[1]);
        let wants: Vec<Vec<u8>> = (0..2u8)
            .map(|v| {
                fovea_model::inject::codes(
                    &device_model,
                    Views::Layers { first: v, count: 1 },
                    extent,
                    &all,
                    Pattern {
                        level,
                        vertical_offset_deg: 0.0,
                    },
                    fovea_model::maps::DEFAULT_MAX_FRAGMENT,
                )
                .2
            })
            .collect();
        // What the GPU shades: every draw in every eye pass gets, texel for texel, one eye's map as
        // the model gives it (its pipeline lets the attachment decide), and each eye is seen.
        let mut matched = [false; 2];
        let draws: Vec<&serde_json::Value> = of("draw").collect();
        assert!(
            draws.len() as u64 >= INJECTED_FRAMES,
            "{level:?}: {} draws",
            draws.len()
        );
        for d in &draws {
            let views = d["views"].as_array().unwrap();
            assert_eq!(views.len(), 1, "{level:?}: {d}");
            let codes: Vec<u8> = views[0]["codes"]
                .as_str()
                .unwrap()
                .chars()
                .map(|c| c.to_digit(16).unwrap() as u8)
                .collect();
            let Some(eye) = wants.iter().position(|w| *w == codes) else {
                panic!(
                    "{level:?}: draw {} of pass {} shades with neither eye's rates: {}",
                    d["draw"], d["pass"], views[0]["codes"]
                );
            };
            matched[eye] = true;
        }
        if wants[0] != wants[1] {
            assert_eq!(matched, [true, true], "{level:?}: each eye its own map");
        }
    }
    // The stats line counts the passes: hello_xr renders each eye once a frame, nothing else.
    let Some((_, stderr)) = hello_xr_on_the_double_for(graphics, Some("high"), 120) else {
        return;
    };
    let stats: Vec<&str> = stderr.lines().filter(|l| l.contains("Inj=")).collect();
    assert!(!stats.is_empty(), "no stats line with Inj=:\n{stderr}");
    assert!(
        stats.iter().all(|l| l.contains("Fov=3 Inj=2/2")),
        "{stats:#?}"
    );
    // Injection off: the device gets no shading rates, and no pass an attachment.
    let Some(events) = hello_xr_on_the_double(graphics, None) else {
        return;
    };
    for e in &events {
        if e["kind"] == "device" {
            assert_ne!(e["features"]["attachment"], true, "off: {e}");
        }
        if e["kind"] == "begin_render_pass" {
            assert_eq!(e["shading_rate_views"], serde_json::json!([]), "off: {e}");
        }
    }
}

#[test]
fn vulkan2_eye_passes_carry_the_injected_maps_at_every_level() {
    hello_xr_eye_passes_carry_the_injected_maps("Vulkan2");
}

#[test]
fn vulkan_eye_passes_carry_the_injected_maps_at_every_level() {
    hello_xr_eye_passes_carry_the_injected_maps("Vulkan");
}
