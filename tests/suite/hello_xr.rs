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

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::time::Duration;

use fovea_abi::log_target;
use fovea_harness::{skip, CORE_VALIDATION_LAYER, FOVEA_LAYER};

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
struct System {
    hello_xr: PathBuf,
    lavapipe_icd: PathBuf,
}

fn find_system() -> Result<System, String> {
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
struct Run {
    code: Option<i32>,
    stdout: String,
    stderr: String,
}

impl Run {
    fn transcript(&self) -> String {
        format!(
            "exit code {:?}\n--- stdout ---\n{}\n--- stderr ---\n{}",
            self.code, self.stdout, self.stderr
        )
    }
}

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
fn messages(run: &Run) -> Vec<String> {
    let banner = |l: &str| l.starts_with("Core Validation output type:");
    let stdout = run.stdout.lines().filter(|l| {
        let l = l.trim_end();
        if l.is_empty() || banner(l) {
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
    });
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

const VK_MANIFEST: &str = "VK_LAYER_FOVEA_fragment_density_map.json";
/// fovea's line on creating a VkInstance (target [`log_target::VK_INSTANCE`]).
const VK_INSTANCE_LINE: &str = "the Vulkan layer is in this VkInstance";
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
