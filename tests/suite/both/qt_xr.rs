//! Qt 6.8's Quick 3D XR (`xr_simple` of Debian 13's qt6-quick3d-examples), a real toolkit nobody
//! here wrote, on Monado through both of fovea's layers and the shading-rate double.
//!
//! Qt asks for foveation its own way (docs/openxr-layer.md#swapchains-without-foveation-info): it
//! enables `XR_FB_foveation`, `XR_FB_foveation_configuration` and `XR_FB_swapchain_update_state`,
//! never `XR_FB_foveation_vulkan`, creates its multiview swapchain (two layers) without
//! `XrSwapchainCreateInfoFoveationFB`, and applies a HIGH profile with `xrUpdateSwapchainFB`,
//! ignoring the result; it uses `XR_KHR_vulkan_enable`, so fovea's Vulkan layer is the implicit
//! one. What must hold, with `inject` off (the default) and on at another level:
//! - fovea accepts the profile (its log says so) and xr_simple runs and exits 0 when
//!   `QCoreApplication::quit()` is called (through gdb: the app ignores SIGINT here);
//! - the device reaches the driver (the double, NVIDIA-like: 16×16 texels, layered attachments)
//!   with the attachment feature, and every draw of every eye pass shades, per view and texel
//!   (the double's effective rates), exactly at `fovea_model::inject::codes` for that view at HIGH
//!   for the FOVs Monado located (fovea's debug line gives them, exactly) and Qt's swapchain size:
//!   the profile's level, whatever `inject_level` says;
//! - the double saw no misuse, and nothing on stderr is a warning or error of fovea's.
//!
//! Before fovea honoured the profile (`xrUpdateSwapchainFB` answered
//! `XR_ERROR_VALIDATION_FAILURE` and injection was refused for the instance), the same run's
//! device had no shading-rate feature and every draw shaded at 1×1.
//!
//! Skips with the reason where Monado or Qt's example is missing; fails instead under
//! `FOVEA_REQUIRE_MONADO=1` (the Debian 13 root of `.ci/trixie`, whose package list has them).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use fovea_model::density::{Level, Pattern};
use fovea_model::inject::Views;
use fovea_model::Fov;

use crate::both::monado::{self, Service};
use crate::support::device::inject_device;
use crate::support::{fovs_of, Manifests};

/// Debian 13's build of the example (qt6-quick3d-examples).
const XR_SIMPLE: &str = "/usr/lib/x86_64-linux-gnu/qt6/examples/quick3d/xr_simple/bin/xr_simple";
/// fovea's stats lines (one a second of display time) before Qt is told to quit.
const STATS_LINES: usize = 3;
/// The one line fovea writes when it accepts Qt's profile.
const ACCEPTED: &str = "a foveation profile applied to a swapchain without density images";

/// Xvfb and gdb, or why the test cannot run.
fn find_tools() -> Result<(PathBuf, PathBuf), String> {
    if !Path::new(XR_SIMPLE).is_file() {
        return Err(format!(
            "{XR_SIMPLE} is missing (Debian 13: qt6-quick3d-examples qml6-module-qtquick3d-xr ...)"
        ));
    }
    let on_path = |name: &str| {
        std::env::var_os("PATH")
            .iter()
            .flat_map(std::env::split_paths)
            .map(|d| d.join(name))
            .find(|p| p.is_file())
    };
    let xvfb = on_path("Xvfb").ok_or("Xvfb is not installed (Debian: xvfb)")?;
    let gdb = on_path("gdb").ok_or("gdb is not installed")?;
    Ok((xvfb, gdb))
}

/// A virtual X server on a display of its own, killed when dropped.
struct Xvfb {
    child: std::process::Child,
    display: String,
}

impl Xvfb {
    fn start(xvfb: &Path) -> Xvfb {
        let n = 90 + std::process::id() % 800;
        let mut child = Command::new(xvfb)
            .args([
                format!(":{n}").as_str(),
                "-screen",
                "0",
                "640x480x24",
                "-nolisten",
                "tcp",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("spawn Xvfb");
        let socket = PathBuf::from(format!("/tmp/.X11-unix/X{n}"));
        let started = Instant::now();
        while !socket.exists() {
            assert!(
                child.try_wait().unwrap().is_none() && started.elapsed() < Duration::from_secs(30),
                "Xvfb :{n} never served"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        Xvfb {
            child,
            display: format!(":{n}"),
        }
    }
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        self.child.kill().ok();
        self.child.wait().ok();
    }
}

/// What one xr_simple run left.
struct QtRun {
    label: String,
    code: Option<i32>,
    stderr: String,
    stdout: String,
    monado: String,
    records: serde_json::Value,
}

impl QtRun {
    fn transcript(&self) -> String {
        let stderr = monado::without_monado_info(&self.stderr);
        format!(
            "{}\n--- stdout ---\n{}\n--- stderr ---\n{stderr}\n{}",
            self.label, self.stdout, self.monado
        )
    }

    /// The FOVs fovea last published for its injected maps (its debug line, exactly).
    fn fovs(&self) -> [Fov; 2] {
        let key = "injection: the views' FOVs changed fovs=\"";
        let line = self
            .stderr
            .lines()
            .rfind(|l| l.contains(key))
            .unwrap_or_else(|| panic!("no FOVs line\n{}", self.transcript()));
        let text = &line[line.find(key).unwrap() + key.len()..];
        let fovs = fovs_of(text.trim_end_matches('"'));
        assert_eq!(fovs.len(), 2, "{line}");
        [fovs[0], fovs[1]]
    }

    /// The swapchain's extent, as Qt logs it (`qt.quick3d.xr`).
    fn extent(&self) -> [u32; 2] {
        let key = "Creating multiview swapchain for 2 view(s) with dimensions Width=";
        let line = self
            .stderr
            .lines()
            .find(|l| l.contains(key))
            .unwrap_or_else(|| panic!("Qt made no multiview swapchain\n{}", self.transcript()));
        let rest = &line[line.find(key).unwrap() + key.len()..];
        let width = rest.split_whitespace().next().unwrap().parse().unwrap();
        let height = rest.split("Height=").nth(1).unwrap();
        let height = height.split_whitespace().next().unwrap().parse().unwrap();
        [width, height]
    }
}

/// xr_simple against a Monado of its own, `env` added; told to quit once [`STATS_LINES`] stats lines
/// passed, every wait bounded.
fn run(m: &monado::Monado, xvfb: &Path, gdb: &Path, label: &str, env: &[(&str, &str)]) -> QtRun {
    let double = fovea_vkdouble::find_library().expect("libfovea_vkdouble.so: cargo build");
    let x = Xvfb::start(xvfb);
    let mut service = Service::start(m, &format!("qt-{label}"));
    let manifests = Manifests::write(&format!("monado-qt-{label}"));
    fovea_vkdouble::write_manifest(&manifests.dir.join("vulkan"), &double).unwrap();
    let records = manifests.dir.join("records.json");
    let stderr_file = manifests.dir.join("stderr");
    let stdout_file = manifests.dir.join("stdout");
    let mut cmd = Command::new(XR_SIMPLE);
    monado::app_env(&mut cmd, m, &service, &manifests, true);
    cmd.env("DISPLAY", &x.display)
        .env("QSG_RHI_BACKEND", "vulkan")
        .env("QT_LOGGING_RULES", "qt.quick3d.xr*=true")
        // Validation above the double: the loader puts the layers named here below the
        // implicit ones (fovea's), in this order from the application down.
        .env(
            "VK_INSTANCE_LAYERS",
            format!(
                "VK_LAYER_KHRONOS_validation:{}",
                fovea_vkdouble::LAYER_NAME.to_str().unwrap()
            ),
        )
        .env(fovea_vkdouble::RECORDS_FILE_ENV, &records)
        .env(fovea_vkdouble::PROFILE_ENV, "nvidia")
        .env(
            fovea_abi::env::LOG,
            format!(
                "info,fovea::bridge::inject=debug,{}=info",
                fovea_abi::log_target::STATS
            ),
        )
        .envs(env.iter().copied())
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&stdout_file).unwrap())
        .stderr(std::fs::File::create(&stderr_file).unwrap());
    let mut child = cmd.spawn().expect("spawn xr_simple");
    let started = Instant::now();
    let stderr = || std::fs::read_to_string(&stderr_file).unwrap_or_default();
    let counted = |text: &str| text.lines().filter(|l| l.contains(" FPS=")).count();
    while child.try_wait().unwrap().is_none()
        && counted(&stderr()) < STATS_LINES
        && started.elapsed() < monado::TIMEOUT
    {
        std::thread::sleep(Duration::from_millis(100));
    }
    if child.try_wait().unwrap().is_none() {
        // The example ignores SIGINT here; QCoreApplication::quit() ends it as a user would.
        let mut quit = Command::new(gdb);
        quit.args(["-p", &child.id().to_string(), "-batch", "-ex"])
            .arg("call (void)'_ZN16QCoreApplication4quitEv'()")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        crate::support::run_with_timeout(&mut quit, Duration::from_secs(60));
    }
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break Some(s);
        }
        if started.elapsed() > monado::TIMEOUT {
            child.kill().ok();
            child.wait().ok();
            break None;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let (_, monado) = service.stop();
    let label = format!("xr_simple on Monado, {label} {env:?}");
    let text = std::fs::read_to_string(&records).unwrap_or_default();
    QtRun {
        label,
        code: status.and_then(|s| s.code()),
        stderr: stderr(),
        stdout: std::fs::read_to_string(&stdout_file).unwrap_or_default(),
        monado,
        records: serde_json::from_str(&text).unwrap_or(serde_json::Value::Null),
    }
}

#[test]
fn qt_xr_simple_on_monado_is_foveated_at_the_level_it_applied() {
    let Some(m) = monado::monado() else {
        return;
    };
    let (xvfb, gdb) = match find_tools() {
        Ok(t) => t,
        Err(reason) if std::env::var(monado::REQUIRE).is_ok_and(|v| v == "1") => {
            panic!("{}=1 but {reason}", monado::REQUIRE)
        }
        Err(reason) => {
            eprintln!("SKIPPED: {reason}");
            return;
        }
    };
    let _one = monado::ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    // inject off (the default), and on at another level: Qt's HIGH wins either way.
    for (label, env) in [
        ("inject-off", &[][..]),
        (
            "inject-low",
            &[("FOVEA_INJECT", "1"), ("FOVEA_INJECT_LEVEL", "low")][..],
        ),
    ] {
        let run = run(&m, &xvfb, &gdb, label, env);
        assert_eq!(run.code, Some(0), "{}", run.transcript());
        assert!(run.stderr.contains(ACCEPTED), "{}", run.transcript());
        let messages: Vec<&str> = run
            .stderr
            .lines()
            .filter(|l| {
                let mut w = l.split_whitespace().skip(1);
                matches!(w.next(), Some("WARN" | "ERROR"))
                    && w.next().is_some_and(|t| t.starts_with("fovea"))
            })
            .collect();
        assert!(messages.is_empty(), "{messages:#?}\n{}", run.transcript());
        let validation: Vec<&str> = run
            .stdout
            .lines()
            .chain(run.stderr.lines())
            // The Vulkan validation layer's; the OpenXR core validation layer above fovea
            // (`[time][VALID_ERROR|VUID-…]`) judges Qt's own calls (it passes a null hand tracker
            // and a passthrough struct Monado leaves empty, without fovea too).
            .filter(|l| {
                (l.contains("VUID-") || l.contains("Validation Error")) && !l.contains("][VALID_")
            })
            .collect();
        assert!(
            validation.is_empty(),
            "{} validation messages:\n{}\n{}",
            validation.len(),
            validation.join("\n"),
            run.transcript()
        );
        assert_eq!(
            run.records["errors"],
            serde_json::json!([]),
            "{}",
            run.transcript()
        );
        let events = run.records["events"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        let of = |kind: &'static str| events.iter().filter(move |e| e["kind"] == kind);
        let device = of("device").next().expect("a device");
        assert_eq!(device["features"]["attachment"], true, "{label}: {device}");
        let (fovs, extent) = (run.fovs(), run.extent());
        let mut all = [None; fovea_model::maps::MAX_VIEWS];
        all[0] = Some(fovs[0]);
        all[1] = Some(fovs[1]);
        let pattern = Pattern {
            level: Level::High,
            vertical_offset_deg: 0.0,
        };
        let (texels, layers, want) = fovea_model::inject::codes(
            &inject_device(fovea_vkdouble::Profile::Nvidia),
            Views::Layers { first: 0, count: 2 },
            extent,
            &all,
            pattern,
            fovea_model::maps::DEFAULT_MAX_FRAGMENT,
        );
        assert_eq!(layers, 2);
        let per_view = (texels[0] * texels[1]) as usize;
        let coarse = want.iter().filter(|&&c| c != 0).count() as f64 / want.len() as f64;
        assert!(coarse > 0.5, "HIGH coarsens most of {extent:?}: {coarse}");
        // Qt's eye passes are its multiview passes (both views, one per layer): each of their
        // draws shades at the model's codes for its view, texel for texel.
        let eye_draws: Vec<&serde_json::Value> = of("draw")
            .filter(|d| d["views"].as_array().is_some_and(|v| v.len() == 2))
            .collect();
        assert!(
            eye_draws.len() >= 20,
            "{label}: {} multiview draws\n{}",
            eye_draws.len(),
            run.transcript()
        );
        for d in &eye_draws {
            for v in d["views"].as_array().unwrap() {
                let view = v["view"].as_u64().unwrap() as usize;
                let codes: Vec<u8> = v["codes"]
                    .as_str()
                    .unwrap()
                    .chars()
                    .map(|c| c.to_digit(16).unwrap() as u8)
                    .collect();
                assert_eq!(
                    (v["columns"].as_u64(), v["rows"].as_u64()),
                    (Some(u64::from(texels[0])), Some(u64::from(texels[1]))),
                    "{label}: {d}"
                );
                assert!(
                    codes == want[view * per_view..(view + 1) * per_view],
                    "{label}: draw {} of pass {} view {view} shades at {} where the model's HIGH \
                     gives {:?}",
                    d["draw"],
                    d["pass"],
                    v["codes"],
                    &want[view * per_view..(view + 1) * per_view]
                );
            }
        }
        eprintln!(
            "{label}: {} multiview draws, all at HIGH ({:.1} % of texels coarser than 1×1), \
             {extent:?}",
            eye_draws.len(),
            coarse * 100.0
        );
    }
}
