//! fovea on Monado, a real OpenXR runtime nobody here wrote: Debian 13's `monado-service` (its null
//! compositor and simulated headset, `XRT_COMPOSITOR_NULL=1 SIMULATED_ENABLE=1`) on Mesa's
//! lavapipe, with the Khronos OpenXR core validation layer above fovea and the Vulkan validation
//! layer (synchronization validation on) in every VkInstance.
//!
//! Each test starts its own `monado-service` (its own `XDG_RUNTIME_DIR`, where it serves
//! `monado_comp_ipc`; stdin a pipe, which it polls), runs the applications as child processes
//! against it (`XR_RUNTIME_JSON` = Monado's manifest), and kills it at the end; every wait is
//! bounded. What must hold:
//! - Khronos `hello_xr` (`-g Vulkan2` and `-g Vulkan`) renders frames through fovea (its stats
//!   lines count them), reaches FOCUSED, quits when its stdin closes (its "press a key"), exits 0,
//!   with fovea's Vulkan layer in its VkInstance and no validation message. (Monado's
//!   XR_KHR_vulkan_enable asks for `VK_KHR_external_semaphore_fd`, which lavapipe 25.0 lacks: there
//!   `-g Vulkan` stops at vkCreateDevice without fovea too, and must end the same through it.)
//! - `examples/foveated_vulkan` applies every level, exits 0 with no message, and every density
//!   map it read back is fovea's model at the FOVs Monado located for it, texel for texel; in
//!   symmetric-FOV mode the FOVs it located are the model's symmetric FOV of Monado's and the maps
//!   the model's for those, with Monado's own FOVs as what is visible; with injection on, the same.
//! - Eye gaze: Monado's simulated headset lists XR_EXT_eye_gaze_interaction without an eye tracker;
//!   fovea's gaze source (on by default) falls back to fixed foveation with one line, and hello_xr
//!   runs clean.
//!
//! Monado is not packaged for Debian 12: the tests print why they skip where it is absent, and fail
//! instead under `FOVEA_REQUIRE_MONADO=1`, which `.ci/trixie` sets in its Debian 13 root
//! (`FOVEA_REQUIRE_SYSTEM=1` alone keeps meaning the components both roots have).

use std::ffi::OsString;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{mpsc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use fovea_abi::log_target;
use fovea_harness::{CORE_VALIDATION_LAYER, FOVEA_LAYER};
use fovea_model::density::{Grid, Level, Pattern, Rect, View};
use fovea_model::maps::{fill_layers, Inputs};
use fovea_model::projection::symmetric_fov;
use fovea_model::Fov;

use crate::both::hello_xr::{self, Run, SYNC_VALIDATION, VK_INSTANCE_LINE, VK_MANIFEST};
use crate::support::{fovs_of, root, Manifests, CORE_VALIDATION_MANIFEST, DEBIAN_LAYERS};

/// Monado's runtime manifest (libopenxr1-monado).
const RUNTIME_JSON: &str = "/usr/share/openxr/1/openxr_monado.json";
const VALIDATION: &str = "/usr/share/vulkan/explicit_layer.d/VkLayer_khronos_validation.json";
/// Set to 1 where Monado must be there (the Debian 13 root): absent, the tests fail.
pub(super) const REQUIRE: &str = "FOVEA_REQUIRE_MONADO";
/// How long Monado may take to serve, and an application to finish; past it the test fails.
pub(super) const TIMEOUT: Duration = Duration::from_secs(300);
/// Frames per level of the example, and its frames in all (every level, each read back).
const FRAMES_PER_LEVEL: u64 = 2;
const FRAMES: u64 = 4 * FRAMES_PER_LEVEL;
/// One Monado and one lavapipe application at a time.
pub(super) static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// What the tests need from the system.
pub(super) struct Monado {
    service: PathBuf,
    hello_xr: PathBuf,
    lavapipe: PathBuf,
}

fn find() -> Result<Monado, String> {
    let service = std::env::var_os("PATH")
        .iter()
        .flat_map(std::env::split_paths)
        .map(|d| d.join("monado-service"))
        .find(|p| p.is_file())
        .ok_or("Monado is not installed (Debian 13: monado-service)")?;
    if !Path::new(RUNTIME_JSON).is_file() {
        return Err(format!(
            "{RUNTIME_JSON} is missing (Debian 13: libopenxr1-monado)"
        ));
    }
    let system = hello_xr::find_system()?;
    if !Path::new(DEBIAN_LAYERS)
        .join(CORE_VALIDATION_MANIFEST)
        .exists()
    {
        return Err(
            "the Khronos core validation layer is not installed (openxr-layer-corevalidation)"
                .into(),
        );
    }
    if !Path::new(VALIDATION).exists() {
        return Err(
            "the Vulkan validation layer is not installed (vulkan-validationlayers)".into(),
        );
    }
    Ok(Monado {
        service,
        hello_xr: system.hello_xr,
        lavapipe: system.lavapipe_icd,
    })
}

/// Monado, or `None` after printing why the test skips; under `FOVEA_REQUIRE_MONADO=1` a missing
/// piece fails the test.
pub(super) fn monado() -> Option<Monado> {
    match find() {
        Ok(m) => Some(m),
        Err(reason) if std::env::var(REQUIRE).is_ok_and(|v| v == "1") => {
            panic!("{REQUIRE}=1 but {reason}")
        }
        Err(reason) => {
            eprintln!("SKIPPED: {reason}");
            None
        }
    }
}

/// Nothing from the caller's environment may change what the loaders, the layers or the runtime
/// do (an exported XR_ENABLE_API_LAYERS, VK_INSTANCE_LAYERS, FOVEA_PROPS, XRT_...).
fn clean_env(cmd: &mut Command) {
    for (key, _) in std::env::vars_os() {
        let k = key.to_string_lossy();
        if [
            "XR_",
            "VK_",
            "FOVEA_",
            "XRT_",
            "SIMULATED_",
            "XDG_",
            "OXR_",
            "IPC_",
        ]
        .iter()
        .any(|p| k.starts_with(p))
        {
            cmd.env_remove(&key);
        }
    }
}

/// A pipe read to its end on a thread of its own.
fn drain(mut pipe: impl Read + Send + 'static) -> JoinHandle<String> {
    std::thread::spawn(move || {
        let mut bytes = Vec::new();
        pipe.read_to_end(&mut bytes).ok();
        String::from_utf8_lossy(&bytes).into_owned()
    })
}

/// A running `monado-service` in a folder of its own.
pub(super) struct Service {
    child: Child,
    dir: PathBuf,
    output: Option<(JoinHandle<String>, JoinHandle<String>)>,
    _stdin: Option<std::process::ChildStdin>,
}

impl Service {
    /// Starts Monado and waits until it serves (its socket exists).
    pub(super) fn start(m: &Monado, label: &str) -> Service {
        let dir = std::env::temp_dir().join(format!("fovea-monado-{label}-{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        let xdg = dir.join("xdg");
        std::fs::create_dir_all(&xdg).unwrap();
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&xdg, std::fs::Permissions::from_mode(0o700)).unwrap();
        let mut cmd = Command::new(&m.service);
        clean_env(&mut cmd);
        cmd.env("XRT_COMPOSITOR_NULL", "1")
            .env("SIMULATED_ENABLE", "1")
            .env("XDG_RUNTIME_DIR", &xdg)
            .env("VK_ICD_FILENAMES", &m.lavapipe)
            .env("VK_DRIVER_FILES", &m.lavapipe)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        let mut child = cmd.spawn().expect("spawn monado-service");
        let stdin = child.stdin.take();
        let output = Some((
            drain(child.stdout.take().unwrap()),
            drain(child.stderr.take().unwrap()),
        ));
        let mut service = Service {
            child,
            dir,
            output,
            _stdin: stdin,
        };
        let socket = xdg.join("monado_comp_ipc");
        let started = Instant::now();
        while !socket.exists() {
            let exited = service.child.try_wait().unwrap();
            if exited.is_some() || started.elapsed() > TIMEOUT {
                let (_, out) = service.stop();
                panic!(
                    "monado-service never served {} ({exited:?})\n{out}",
                    socket.display()
                );
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        service
    }

    fn xdg(&self) -> PathBuf {
        self.dir.join("xdg")
    }

    /// Kills Monado; whether it was still running, and what it printed.
    pub(super) fn stop(&mut self) -> (bool, String) {
        let running = self.child.try_wait().unwrap().is_none();
        self.child.kill().ok();
        self.child.wait().ok();
        let out = self.output.take().map_or_else(String::new, |(o, e)| {
            format!(
                "--- monado-service stdout ---\n{}\n--- monado-service stderr ---\n{}",
                o.join().unwrap(),
                e.join().unwrap()
            )
        });
        (running, out)
    }
}

impl Drop for Service {
    fn drop(&mut self) {
        self.stop();
        std::fs::remove_dir_all(&self.dir).ok();
    }
}

/// The environment of an application run against `service`: Monado as the runtime, core validation
/// above fovea, lavapipe, the Vulkan validation layer's synchronization validation, fovea's Vulkan
/// layer findable (`implicit`: its implicit manifest in the per-user folder, for
/// XR_KHR_vulkan_enable, where the application makes the VkInstance; otherwise the explicit one on
/// `VK_ADD_LAYER_PATH`), per-user folders of the run's own.
pub(super) fn app_env(
    cmd: &mut Command,
    m: &Monado,
    service: &Service,
    manifests: &Manifests,
    implicit: bool,
) {
    let home = manifests.dir.join("home");
    let explicit = manifests.dir.join("vulkan");
    let (folder, checked_in) = if implicit {
        (
            home.join("data/vulkan/implicit_layer.d"),
            root().join("manifest/vulkan/implicit").join(VK_MANIFEST),
        )
    } else {
        (
            explicit.clone(),
            root().join("manifest/vulkan").join(VK_MANIFEST),
        )
    };
    std::fs::create_dir_all(&folder).unwrap();
    std::fs::create_dir_all(&explicit).unwrap();
    let lib = fovea_harness::artifact("libfovea.so").expect("libfovea.so: cargo build");
    let mut manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(checked_in).unwrap()).unwrap();
    manifest["layer"]["library_path"] = lib.canonicalize().unwrap().to_str().unwrap().into();
    std::fs::write(folder.join(VK_MANIFEST), manifest.to_string()).unwrap();
    clean_env(cmd);
    cmd.env("XR_RUNTIME_JSON", RUNTIME_JSON)
        .env("XDG_RUNTIME_DIR", service.xdg())
        .env(
            "XR_API_LAYER_PATH",
            format!("{}:{DEBIAN_LAYERS}", manifests.dir.join("layers").display()),
        )
        .env(
            "XR_ENABLE_API_LAYERS",
            format!("{CORE_VALIDATION_LAYER}:{FOVEA_LAYER}"),
        )
        .env("VK_ICD_FILENAMES", &m.lavapipe)
        .env("VK_DRIVER_FILES", &m.lavapipe)
        .env("VK_ADD_LAYER_PATH", &explicit)
        .env("VK_LAYER_ENABLES", SYNC_VALIDATION)
        .env("VK_LAYER_VALIDATE_SYNC", "1")
        .env("XDG_DATA_HOME", home.join("data"))
        .env("XDG_CONFIG_HOME", home.join("config"))
        .env("HOME", &home)
        .env(
            fovea_abi::env::LOG,
            format!("info,{}=info", log_target::VK_INSTANCE),
        )
        .env(fovea_abi::env::LOG_FILE, OsString::new());
}

/// The lines of a run that are messages: validation (the example prints each as
/// `foveated_vulkan: Vulkan ...`; hello_xr's are picked by [`hello_xr::messages`]), warnings and
/// errors of fovea, anything else on stderr but fovea's info lines.
pub(super) fn example_messages(stderr: &str) -> Vec<&str> {
    stderr
        .lines()
        .filter(|l| {
            !l.trim().is_empty()
                && !is_fovea_info(l)
                && !l.starts_with("Core Validation output type:")
        })
        .collect()
}

/// `text` less the info records Monado's client library prints to stderr (`LOG in xrFoo: ...`,
/// then lines indented with a tab); its warnings and errors (`WARNING in`, `ERROR in`) stay.
pub(super) fn without_monado_info(text: &str) -> String {
    let mut out = String::new();
    let mut in_log = false;
    for line in text.lines() {
        if line.starts_with("LOG in ") {
            in_log = true;
        } else if !(in_log && line.starts_with('\t')) {
            in_log = false;
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// fovea's log lines below warning level (`<time>  INFO fovea::…: …`).
fn is_fovea_info(line: &str) -> bool {
    let mut words = line.split_whitespace().take(3);
    let level = words.find(|w| ["INFO", "DEBUG", "TRACE"].contains(w));
    level.is_some() && words.next().is_some_and(|t| t.starts_with("fovea"))
}

/// One hello_xr `-g graphics` run against a Monado of its own, with fovea's layers or without;
/// hello_xr is told to quit (its stdin closes, a key press to it) once frames pass, or as soon as it
/// ends by itself. The run, whether frames passed (fovea's stats lines count them; without fovea,
/// FOCUSED on its stdout), and the transcript with Monado's output.
fn hello_xr_run(m: &Monado, graphics: &str, fovea: bool) -> (Run, bool, String) {
    hello_xr_run_with(m, graphics, fovea, &[])
}

/// [`hello_xr_run`] with these variables set for hello_xr (fovea's settings).
fn hello_xr_run_with(
    m: &Monado,
    graphics: &str,
    fovea: bool,
    env: &[(&str, &str)],
) -> (Run, bool, String) {
    let label = format!("hello_xr -g {graphics} on Monado, fovea {fovea} {env:?}");
    let mut service = Service::start(m, &format!("hello-xr-{graphics}-{fovea}"));
    let manifests = Manifests::write(&format!("monado-hello-xr-{graphics}-{fovea}"));
    let mut cmd = Command::new(&m.hello_xr);
    cmd.args(["-g", graphics, "-v"]);
    app_env(&mut cmd, m, &service, &manifests, graphics == "Vulkan");
    cmd.envs(env.iter().copied());
    if !fovea {
        cmd.env("XR_ENABLE_API_LAYERS", CORE_VALIDATION_LAYER)
            .env_remove("VK_ADD_LAYER_PATH")
            .env("XDG_DATA_HOME", manifests.dir.join("none"));
    }
    cmd.stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut child = cmd.spawn().expect("spawn hello_xr");
    let stdin = child.stdin.take();
    // hello_xr's stdout is a pipe, which C's stdio flushes only at exit; fovea's stats lines on
    // stderr come once a display second while frames pass through xrEndFrame.
    let (frames, seen) = mpsc::channel();
    let stderr = child.stderr.take().unwrap();
    let stderr = std::thread::spawn(move || {
        let mut all = String::new();
        let mut stats = 0;
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            // hello_xr logs what stopped it, then waits for its key press.
            if line.contains("[Error  ]") {
                frames.send(false).ok();
            }
            if line.contains("fovea::stats: FPS=") && !line.contains("FPS=0/") {
                stats += 1;
                if stats == 2 {
                    frames.send(true).ok();
                }
            }
            all.push_str(&line);
            all.push('\n');
        }
        frames.send(false).ok();
        all
    });
    let stdout = drain(child.stdout.take().unwrap());
    let passed = if fovea {
        seen.recv_timeout(TIMEOUT).unwrap_or(false)
    } else {
        // Without fovea nothing says when frames pass: a few display seconds' worth of time, or
        // its end, whichever comes first (what the run shows is checked after it).
        seen.recv_timeout(Duration::from_secs(10)).ok();
        false
    };
    drop(stdin);
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break Some(status);
        }
        if started.elapsed() > TIMEOUT {
            child.kill().ok();
            child.wait().ok();
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let run = Run {
        code: status.and_then(|s| s.code()),
        stdout: stdout.join().unwrap(),
        stderr: stderr.join().unwrap(),
    };
    let (serving, monado_out) = service.stop();
    let transcript = format!("{label}\n{}\n{monado_out}", run.transcript());
    assert!(
        status.is_some(),
        "still running after {TIMEOUT:?}\n{transcript}"
    );
    assert!(serving, "monado-service died\n{transcript}");
    let passed = passed || (!fovea && run.stdout.contains("->XR_SESSION_STATE_FOCUSED"));
    (run, passed, transcript)
}

/// hello_xr's and fovea's messages of a run: validation (core validation, the Vulkan validation
/// layer), fovea's warnings, anything else on stderr but Monado's client library's info records.
fn hello_xr_messages(run: &Run) -> Vec<String> {
    hello_xr::messages(&Run {
        code: run.code,
        stdout: run.stdout.clone(),
        stderr: without_monado_info(&run.stderr),
    })
}

/// What Monado's XR_KHR_vulkan_enable asks of the device and lavapipe lacks: hello_xr `-g Vulkan`
/// stops at its vkCreateDevice without any layer of fovea's.
const SEMAPHORE_FD_MISSING: &str =
    "Device extension VK_KHR_external_semaphore_fd not supported by selected physical device";

/// hello_xr `-g graphics` through fovea against Monado: frames pass through fovea, FOCUSED,
/// hello_xr quits on its key press with status 0, fovea's Vulkan layer was in its VkInstance, and
/// nothing is said. Where hello_xr cannot run on Monado and lavapipe without fovea either, the run
/// through fovea must end exactly as the run without.
fn hello_xr_on_monado(graphics: &str) {
    let Some(m) = monado() else { return };
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let (run, passed, transcript) = hello_xr_run(&m, graphics, true);
    assert!(
        run.stderr.contains(VK_INSTANCE_LINE),
        "fovea's Vulkan layer was not in hello_xr's VkInstance\n{transcript}"
    );
    let says = |r: &Run, what: &str| r.stdout.contains(what) || r.stderr.contains(what);
    if !passed && says(&run, SEMAPHORE_FD_MISSING) {
        let (bare, bare_passed, bare_transcript) = hello_xr_run(&m, graphics, false);
        assert!(
            !bare_passed && says(&bare, SEMAPHORE_FD_MISSING),
            "hello_xr -g {graphics} fails through fovea only\n{transcript}\n\n{bare_transcript}"
        );
        assert_eq!(run.code, bare.code, "{transcript}\n\n{bare_transcript}");
        // The same errors, less their times and handles.
        let errors = |r: &Run| -> Vec<String> {
            r.stdout
                .lines()
                .chain(r.stderr.lines())
                .filter(|l| l.contains("[Error  ]"))
                .map(|l| {
                    l.split_once("[Error  ]")
                        .unwrap()
                        .1
                        .split(')')
                        .next_back()
                        .unwrap()
                        .to_owned()
                })
                .collect()
        };
        assert_eq!(
            errors(&run),
            errors(&bare),
            "{transcript}\n\n{bare_transcript}"
        );
        let ours: Vec<String> = hello_xr_messages(&run)
            .into_iter()
            .filter(|l| !l.contains("[Error  ]") && !l.starts_with("    "))
            .collect();
        assert!(
            ours.is_empty(),
            "messages beyond the runtime's: {ours:#?}\n{transcript}"
        );
        eprintln!(
            "hello_xr -g {graphics} on Monado and lavapipe: Monado's XR_KHR_vulkan_enable asks for \
             VK_KHR_external_semaphore_fd, which lavapipe lacks; it fails the same without fovea"
        );
        return;
    }
    assert!(passed, "no frames through fovea\n{transcript}");
    assert_eq!(run.code, Some(0), "{transcript}");
    // Monado never asks an application to exit: hello_xr leaves its loop on the key press
    // without xrRequestExitSession, so FOCUSED is the last state it reports.
    assert!(
        run.stdout.contains("->XR_SESSION_STATE_FOCUSED"),
        "never FOCUSED\n{transcript}"
    );
    let messages = hello_xr_messages(&run);
    assert!(
        messages.is_empty(),
        "{} messages:\n{}\n\n{transcript}",
        messages.len(),
        messages.join("\n")
    );
}

#[test]
fn hello_xr_vulkan2_through_fovea_on_monado_is_clean() {
    hello_xr_on_monado("Vulkan2");
}

#[test]
fn hello_xr_vulkan_through_fovea_on_monado_ends_as_without_fovea() {
    hello_xr_on_monado("Vulkan");
}

/// Monado's simulated headset lists XR_EXT_eye_gaze_interaction and reports no eye tracker
/// (`supportsEyeGazeInteraction` false). hello_xr (actions of its own, nothing of fovea's) gets no
/// eye gaze from fovea at all: no line about it, `Gaze=off`. With injection on, whose maps follow
/// the eyes (docs/eye-tracking.md#who-uses-the-gaze), fovea enables the extension, asks the
/// system, says once why the foveation stays fixed, and neither Monado nor a validation layer says
/// anything.
#[test]
fn eye_gaze_on_monado_only_where_used_and_falls_back_to_fixed_foveation_cleanly() {
    let Some(m) = monado() else { return };
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    for (env, used) in [(&[][..], false), (&[("FOVEA_INJECT", "1")][..], true)] {
        let (run, passed, transcript) = hello_xr_run_with(&m, "Vulkan2", true, env);
        assert!(passed, "no frames through fovea\n{transcript}");
        assert_eq!(run.code, Some(0), "{transcript}");
        let gaze: Vec<&str> = run
            .stderr
            .lines()
            .filter(|l| l.contains(log_target::GAZE))
            .collect();
        let stats: Vec<&str> = run
            .stderr
            .lines()
            .filter(|l| l.contains("fovea::stats: FPS="))
            .collect();
        let shown = if used { " Gaze=fixed " } else { " Gaze=off " };
        assert!(
            !stats.is_empty() && stats.iter().all(|l| l.contains(shown)),
            "{shown}: {stats:#?}\n{transcript}"
        );
        if used {
            assert_eq!(
                gaze.len(),
                1,
                "one line about the gaze: {gaze:#?}\n{transcript}"
            );
            assert!(
                gaze[0].contains("INFO") && gaze[0].contains("no eye tracker"),
                "{}\n{transcript}",
                gaze[0]
            );
        } else {
            assert_eq!(gaze, Vec::<&str>::new(), "{transcript}");
        }
        // With injection on, lavapipe's device (no shading-rate attachments) gets the one line
        // that says its eye passes stay at full rate; nothing else may be said.
        let messages: Vec<String> = hello_xr_messages(&run)
            .into_iter()
            .filter(|l| !(used && l.contains("cannot take injected maps")))
            .collect();
        assert!(
            messages.is_empty(),
            "{} messages:\n{}\n\n{transcript}",
            messages.len(),
            messages.join("\n")
        );
    }
}

/// What one example run printed and read back.
struct ExampleRun {
    label: String,
    stdout: String,
    stderr: String,
    monado: String,
    frames: PathBuf,
}

impl ExampleRun {
    fn transcript(&self) -> String {
        format!(
            "{}\n--- stdout ---\n{}\n--- stderr ---\n{}\n{}",
            self.label, self.stdout, self.stderr, self.monado
        )
    }

    /// The text after `key` on the example's summary lines, up to `end`.
    fn field(&self, key: &str, end: char) -> &str {
        let at = self
            .stdout
            .find(key)
            .unwrap_or_else(|| panic!("no {key:?}\n{}", self.transcript()));
        let rest = &self.stdout[at + key.len()..];
        &rest[..rest.find(end).unwrap_or(rest.len())]
    }

    /// The swapchain's (one view's) extent.
    fn view_size(&self) -> [u32; 2] {
        let size = self.field(" frames on a ", ' ');
        let (w, h) = size.split_once('x').unwrap();
        [w.parse().unwrap(), h.parse().unwrap()]
    }

    /// The FOVs the example located (left, right, up, down), exactly.
    fn fovs(&self) -> Vec<Fov> {
        fovs_of(self.field("per view) ", '\n'))
    }

    /// Each density map read back (level index, both layers as R8G8 in the model's layout), and the
    /// map's extent.
    fn maps(&self) -> (Vec<(usize, Vec<u8>)>, [u32; 2]) {
        let levels = ["none", "low", "medium", "high"];
        let mut names: Vec<PathBuf> = std::fs::read_dir(&self.frames)
            .unwrap_or_else(|e| panic!("{}: {e}\n{}", self.frames.display(), self.transcript()))
            .map(|e| e.unwrap().path())
            .filter(|p| p.to_string_lossy().ends_with("_density_left.png"))
            .collect();
        names.sort();
        let mut extent = [0, 0];
        let maps = names
            .iter()
            .map(|left| {
                let name = left.file_name().unwrap().to_str().unwrap();
                let level = levels
                    .iter()
                    .position(|l| name.contains(&format!("_{l}_")))
                    .unwrap();
                let right = PathBuf::from(left.to_string_lossy().replace("_left.", "_right."));
                let mut map = Vec::new();
                for path in [left, &right] {
                    let decoder = png::Decoder::new(std::fs::File::open(path).unwrap());
                    let mut reader = decoder.read_info().unwrap();
                    let mut pixels = vec![0; reader.output_buffer_size()];
                    let info = reader.next_frame(&mut pixels).unwrap();
                    assert_eq!(info.color_type, png::ColorType::Rgb, "{}", path.display());
                    extent = [info.width, info.height];
                    pixels.truncate(info.buffer_size());
                    map.extend(pixels.chunks_exact(3).flat_map(|p| [p[0], p[1]]));
                }
                (level, map)
            })
            .collect();
        (maps, extent)
    }
}

impl Drop for ExampleRun {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.frames).ok();
    }
}

/// The example against Monado with `args` and `env` added: every level, each new density map read
/// back (`--dump`), the Vulkan validation layer watching (`--validate`). Asserts the clean exit and
/// the silence.
fn example_on_monado(
    m: &Monado,
    label: &str,
    args: &[&str],
    env: &[(&str, &str)],
    allowed: &[&str],
) -> ExampleRun {
    let example = crate::both::example_modes::example();
    let mut service = Service::start(m, &format!("example-{label}"));
    let manifests = Manifests::write(&format!("monado-example-{label}"));
    let frames = std::env::temp_dir().join(format!(
        "fovea-monado-example-{label}-frames-{}",
        std::process::id()
    ));
    std::fs::remove_dir_all(&frames).ok();
    let mut cmd = Command::new(example);
    let (count, per_level) = (FRAMES.to_string(), FRAMES_PER_LEVEL.to_string());
    cmd.args(["--validate", "--frames", &count])
        .args(["--frames-per-level", &per_level])
        .arg("--dump")
        .arg(&frames)
        .args(args);
    app_env(&mut cmd, m, &service, &manifests, false);
    cmd.envs(env.iter().copied())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let done = crate::support::run_with_timeout(&mut cmd, TIMEOUT);
    let (serving, monado) = service.stop();
    let run = ExampleRun {
        label: format!("foveated_vulkan {args:?} {env:?} on Monado"),
        stdout: done.stdout,
        stderr: done.stderr,
        monado,
        frames,
    };
    assert!(
        done.status.is_some(),
        "still running after {TIMEOUT:?}\n{}",
        run.transcript()
    );
    assert_eq!(
        done.status.and_then(|s| s.code()),
        Some(0),
        "{}",
        run.transcript()
    );
    assert!(serving, "monado-service died\n{}", run.transcript());
    assert!(
        run.stderr.contains(VK_INSTANCE_LINE),
        "fovea's Vulkan layer was not in the VkInstance\n{}",
        run.transcript()
    );
    let stderr = without_monado_info(&run.stderr);
    let messages: Vec<&str> = example_messages(&stderr)
        .into_iter()
        .filter(|l| !allowed.iter().any(|a| l.contains(a)))
        .collect();
    assert!(
        messages.is_empty(),
        "{} messages:\n{}\n\n{}",
        messages.len(),
        messages.join("\n"),
        run.transcript()
    );
    let want = if args.contains(&"--no-fb") {
        "density maps not asked for"
    } else {
        "levels [NONE, LOW, MEDIUM, HIGH]"
    };
    assert!(
        run.stdout.contains(want),
        "no {want:?}\n{}",
        run.transcript()
    );
    run
}

/// Every density map the example read back is fovea's model for its level at `fovs` (what the
/// example located), with `visible` the eyes' true FOVs in symmetric-FOV mode.
fn assert_maps_are_the_model(run: &ExampleRun, fovs: &[Fov], visible: Option<&[Fov]>) {
    let [w, h] = run.view_size();
    let (maps, [mw, mh]) = run.maps();
    // The density texel: lavapipe has no fragment density maps, so fovea's own (docs), or a
    // shading-rate texel where the driver has shading-rate attachments; the one that gives the
    // extent read back.
    let texel = [8, 16, 32, 64]
        .into_iter()
        .find(|t| (w.div_ceil(*t), h.div_ceil(*t)) == (mw, mh))
        .unwrap_or_else(|| panic!("a {mw}x{mh} map for {w}x{h}\n{}", run.transcript()));
    let grid = Grid::new([w, h], [texel, texel]);
    assert_eq!(grid.map_extent(), [mw, mh]);
    let rect = Rect {
        x: 0,
        y: 0,
        width: w,
        height: h,
    };
    assert_eq!(fovs.len(), 2, "{}", run.transcript());
    let views: Vec<Vec<View>> = fovs
        .iter()
        .enumerate()
        .map(|(eye, &fov)| {
            vec![View {
                fov,
                rect,
                visible: visible.map(|v| v[eye]),
            }]
        })
        .collect();
    let model = |level: usize| {
        let inputs = Inputs {
            pattern: Pattern {
                level: Level::from_index(level as u32).unwrap(),
                vertical_offset_deg: 0.0,
            },
            max_fragment: fovea_model::maps::DEFAULT_MAX_FRAGMENT,
            layers: views.clone(),
        };
        let mut out = vec![0; (mw * mh * 2 * 2) as usize];
        fill_layers(&grid, &inputs, &mut out);
        out
    };
    let seen: std::collections::BTreeSet<usize> = maps.iter().map(|(l, _)| *l).collect();
    assert_eq!(
        seen,
        (0..4).collect(),
        "maps of every level read back\n{}",
        run.transcript()
    );
    for (level, map) in &maps {
        let want = model(*level);
        assert!(
            *map == want,
            "level {level}: {} of {} bytes differ from fovea's model at {fovs:?}\n{}",
            map.iter().zip(&want).filter(|(a, b)| a != b).count(),
            want.len(),
            run.transcript()
        );
    }
    assert_ne!(model(0), model(3), "the levels give different maps");
}

/// The example at every level on Monado: the maps are fovea's model at Monado's FOVs; in
/// symmetric-FOV mode the FOVs the example located are the model's symmetric FOV of Monado's and
/// the maps the model's for those, Monado's own being what each eye shows.
#[test]
fn example_maps_are_the_model_at_monado_s_fovs_in_both_fov_modes() {
    let Some(m) = monado() else { return };
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let plain = example_on_monado(&m, "levels", &[], &[], &[]);
    let fovs = plain.fovs();
    println!(
        "Monado's simulated headset: FOVs (radians) {fovs:?}, views {:?}",
        plain.view_size()
    );
    assert_maps_are_the_model(&plain, &fovs, None);

    // Monado offers no XR_EPIC_view_configuration_fov and locates views only in a running
    // session; the example sizes its swapchains before: fovea keeps each eye's own FOV and says
    // so once (docs/headsets.md#symmetric-fov). Elsewhere the FOVs located are the symmetric one.
    let symmetric = example_on_monado(
        &m,
        "symmetric",
        &[],
        &[("FOVEA_SYMMETRIC_FOV", "1")],
        &[SYMMETRIC_OFF],
    );
    let located = symmetric.fovs();
    if symmetric.stderr.contains(SYMMETRIC_OFF) {
        assert_eq!(located, fovs, "{}", symmetric.transcript());
        assert_maps_are_the_model(&symmetric, &located, None);
    } else {
        let want = symmetric_fov(&fovs).unwrap();
        assert_eq!(located, vec![want; 2], "{}", symmetric.transcript());
        assert_maps_are_the_model(&symmetric, &located, Some(&fovs));
    }
}

/// fovea's line where symmetric-FOV mode cannot apply to a session.
const SYMMETRIC_OFF: &str = "symmetric FOV is off for this session";

/// Injection on (`FOVEA_INJECT=1`) and off, the example with and without the FB API: the same
/// clean exits and silence (but for fovea's one line, with injection on, that this GPU cannot take
/// injected maps), and with the FB API the same maps of fovea's model.
#[test]
fn example_with_injection_on_and_off_on_monado_is_clean() {
    let Some(m) = monado() else { return };
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    for inject in ["0", "1"] {
        // Where the GPU has no shading-rate attachments (lavapipe), injection cannot work, and
        // fovea's Vulkan layer says so once, at the session's vkCreateDevice.
        let allowed: &[&str] = if inject == "1" {
            &["injection is on, but this device cannot take injected maps"]
        } else {
            &[]
        };
        let fb = example_on_monado(
            &m,
            &format!("inject-{inject}"),
            &[],
            &[("FOVEA_INJECT", inject)],
            allowed,
        );
        let fovs = fb.fovs();
        assert_maps_are_the_model(&fb, &fovs, None);
        example_on_monado(
            &m,
            &format!("inject-{inject}-no-fb"),
            &["--no-fb"],
            &[("FOVEA_INJECT", inject)],
            allowed,
        );
    }
}
