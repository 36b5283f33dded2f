//! What several of the suite's modules share: the repository's root and its Rust files, running a
//! test in a process of its own, an application's own OpenXR actions, manifests pointed at this
//! build, a running headless loop, the system's OpenXR layer folder, the gaze the layer logged, the
//! FOVs a log line prints, and the foveation structs most tests fill in.

use std::path::{Path, PathBuf};
use std::process::Command;

use fovea_harness::artifact;
use fovea_harness::frame_loop::{HeadlessLoop, SwapchainSpec};
use fovea_harness::App;
use openxr_sys as xr;

pub mod actions;
pub mod device;
pub mod gaze_log;
pub mod process;
pub mod vulkan;

pub use process::in_own_process;

/// The FOVs in `text`, separated by white space, each `left,right,up,down` in radians, as fovea's
/// debug lines and the example print them.
pub fn fovs_of(text: &str) -> Vec<fovea_model::Fov> {
    text.split_whitespace()
        .map(|v| {
            let a: Vec<f32> = v.split(',').map(|x| x.parse().unwrap()).collect();
            fovea_model::Fov {
                left: a[0],
                right: a[1],
                up: a[2],
                down: a[3],
            }
        })
        .collect()
}

/// The repository's root (the layer package's folder).
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every `*.rs` file under `dir`, in a stable order (none when `dir` does not exist).
pub fn rust_files(dir: &Path) -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for e in entries {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, &mut out);
    out.sort();
    out
}

/// Where Debian installs explicit OpenXR API layers (the Khronos core validation layer).
pub const DEBIAN_LAYERS: &str = "/usr/share/openxr/1/api_layers/explicit.d";
/// The Khronos core validation layer's manifest in [`DEBIAN_LAYERS`].
pub const CORE_VALIDATION_MANIFEST: &str = "XrApiLayer_core_validation.x86_64-linux-gnu.json";

/// A temporary folder with the checked-in layer manifest pointed at this build's libfovea.so
/// (`layers/fovea.json`) and a runtime manifest for this build's libfovea_sim.so (`runtime.json`);
/// the checked-in ones name target/release by a relative path. Removed when dropped.
pub struct Manifests {
    pub dir: PathBuf,
}

impl Manifests {
    pub fn write(label: &str) -> Manifests {
        let layer = artifact("libfovea.so").expect("libfovea.so: run `cargo build --workspace`");
        let runtime =
            artifact("libfovea_sim.so").expect("libfovea_sim.so: run `cargo build --workspace`");
        let dir = std::env::temp_dir().join(format!("fovea-{label}-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("layers")).unwrap();
        let checked_in =
            std::fs::read_to_string(root().join("manifest/XR_APILAYER_FOVEA_foveation.json"))
                .unwrap();
        let manifest = checked_in.replace("../target/release/libfovea.so", layer.to_str().unwrap());
        assert_ne!(
            manifest, checked_in,
            "the checked-in manifest's library_path moved"
        );
        std::fs::write(dir.join("layers/fovea.json"), manifest).unwrap();
        std::fs::write(
            dir.join("runtime.json"),
            format!(
                r#"{{"file_format_version": "1.0.0", "runtime": {{"name": "fovea simulated headset", "library_path": "{}"}}}}"#,
                runtime.display()
            ),
        )
        .unwrap();
        Manifests { dir }
    }
}

impl Drop for Manifests {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.dir).ok();
    }
}

/// An `XrFoveationLevelProfileCreateInfoFB` with raw values (tests pass invalid ones too).
pub fn level_info(level: i32, dynamic: i32, offset: f32) -> xr::FoveationLevelProfileCreateInfoFB {
    xr::FoveationLevelProfileCreateInfoFB {
        ty: xr::StructureType::FOVEATION_LEVEL_PROFILE_CREATE_INFO_FB,
        next: std::ptr::null_mut(),
        level: xr::FoveationLevelFB::from_raw(level),
        vertical_offset: offset,
        dynamic: xr::FoveationDynamicFB::from_raw(dynamic),
    }
}

/// A running headless loop of `app` with a foveated two-layer swapchain (one layer per eye).
pub fn foveated_loop(app: App) -> HeadlessLoop {
    HeadlessLoop::new(
        app,
        SwapchainSpec {
            foveation: true,
            array_size: 2,
        },
    )
    .unwrap()
}

/// An `XrSwapchainStateFoveationFB` naming `profile`, with raw `flags`.
pub fn foveation_state(
    profile: xr::FoveationProfileFB,
    flags: u64,
) -> xr::SwapchainStateFoveationFB {
    xr::SwapchainStateFoveationFB {
        ty: xr::StructureType::SWAPCHAIN_STATE_FOVEATION_FB,
        next: std::ptr::null_mut(),
        flags: xr::SwapchainStateFoveationFlagsFB::from_raw(flags),
        profile,
    }
}

/// What a child process left when it ended or was killed.
pub struct Finished {
    /// `None` where it ran past the timeout and was killed.
    pub status: Option<std::process::ExitStatus>,
    pub stdout: String,
    pub stderr: String,
}

/// Spawns `cmd` (its stdout and stderr piped) and waits at most `timeout` for it, draining both
/// pipes meanwhile so a chatty child cannot block on a full pipe. A piped stdin is held open until
/// the child has ended (hello_xr reads a closed stdin as a key press, which quits it).
pub fn run_with_timeout(cmd: &mut Command, timeout: std::time::Duration) -> Finished {
    use std::io::Read;
    let what = format!("{:?}", cmd.get_program());
    let mut child = cmd.spawn().unwrap_or_else(|e| panic!("spawn {what}: {e}"));
    let stdin = child.stdin.take();
    let drain = |mut pipe: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            pipe.read_to_end(&mut bytes).ok();
            String::from_utf8_lossy(&bytes).into_owned()
        })
    };
    let stdout = drain(Box::new(child.stdout.take().expect("stdout piped")));
    let stderr = drain(Box::new(child.stderr.take().expect("stderr piped")));
    let started = std::time::Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait for the child") {
            break Some(status);
        }
        if started.elapsed() > timeout {
            child.kill().ok();
            child.wait().ok();
            break None;
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    drop(stdin);
    Finished {
        status,
        stdout: stdout.join().unwrap(),
        stderr: stderr.join().unwrap(),
    }
}
