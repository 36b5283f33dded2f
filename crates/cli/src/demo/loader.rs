//! The demo through the system's Khronos loader: `examples/foveated_vulkan`, an application on the
//! `openxr` crate, runs as a child process with fovea enabled by the environment and the simulated
//! runtime as the active runtime, both named by manifests written into the output folder. It renders
//! on the machine's Vulkan device (lavapipe where there is no GPU) and reads back what it drew.
//!
//! Where the device has shading-rate attachments and no density maps of its own (a desktop GPU),
//! the example gets fovea's Vulkan layer too ([`vk_layer_env`]): its explicit manifest in the output
//! folder, named by `VK_ADD_LAYER_PATH`, which fovea's `xrCreateVulkanInstanceKHR` then adds to the
//! example's instance; the device offers `VK_EXT_fragment_density_map`, and the example renders its
//! eye passes foveated instead of sampling the maps into its debug overlay. Elsewhere (lavapipe, or
//! a GPU with native density maps) nothing about Vulkan is set.
//!
//! The example runs with `--eye-tracked` (eye-tracked profiles, an action set of its own attached
//! and synced) on a simulated headset whose eye tracker follows [`GAZE`]: fovea moves the fovea in
//! the density maps it hands the example, and the maps read back show it travel.
//!
//! The display clock is not paced: it advances one frame period per frame however long the device
//! takes to draw, so the GPU load script (simulated GPU time added to each frame) tells the same
//! story on a CPU renderer as on a GPU, and the stats lines count display seconds.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Command, Stdio};

use ash::vk;

use super::setup::{build_dir, cargo_build, gaze_description, load_description, Setup, GAZE, LOAD};
use crate::discovery::{Kind, VK_ADD_LAYER_PATH};
use crate::install::{manifest_text, vk_explicit_manifest_text};
use crate::vk_doctor::Fdm;
use fovea_abi::env::DISABLE_VK_LAYER;

const LOADER: &str = "libopenxr_loader.so.1";
const EXAMPLE: &str = "foveated_vulkan";

/// What the loader path needs, found.
pub struct System {
    /// The Vulkan device the simulated runtime will pick, and whether it renders on the CPU.
    device: String,
    cpu: bool,
    /// What the device's driver offers for density maps.
    fdm: Fdm,
    dir: PathBuf,
}

impl System {
    /// The loader, a Vulkan device, and the layer, runtime and example built next to this `fovea`
    /// (built first when Cargo started it), or why not.
    pub fn find() -> Result<System, String> {
        // SAFETY: loading the loader runs its initialisers, nothing else; it is unloaded at once.
        unsafe { libloading::Library::new(LOADER) }
            .map_err(|e| format!("the Khronos OpenXR loader is not installed ({e})"))?;
        let (device, cpu) = vulkan_device()?;
        let fdm = driver_fdm(&device);
        // Errors other than "not started by cargo" are real build failures and are reported.
        if let Err(e) = cargo_build(&[
            "-p",
            "fovea",
            "-p",
            "fovea-sim",
            "--lib",
            "--example",
            EXAMPLE,
        ]) {
            if std::env::var_os("CARGO").is_some() {
                return Err(e);
            }
        }
        let dir = build_dir()?;
        for file in ["libfovea.so", "libfovea_sim.so"] {
            if !dir.join(file).is_file() {
                return Err(format!(
                    "{file} is not built in {}: run `cargo build --release --workspace --examples`",
                    dir.display()
                ));
            }
        }
        if !dir.join("examples").join(EXAMPLE).is_file() {
            return Err(format!(
                "examples/{EXAMPLE} is not built in {}: run `cargo build --release --examples`",
                dir.display()
            ));
        }
        Ok(System {
            device,
            cpu,
            fdm,
            dir,
        })
    }
}

/// The physical device the simulated runtime picks (the first, or the first whose name contains
/// `FOVEA_SIM_VK_DEVICE`), and whether it is a CPU renderer.
fn vulkan_device() -> Result<(String, bool), String> {
    // SAFETY: a throwaway instance, destroyed before returning; nothing else uses it.
    unsafe {
        let entry = ash::Entry::load().map_err(|e| format!("no Vulkan loader ({e})"))?;
        let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_1);
        let instance = entry
            .create_instance(
                &vk::InstanceCreateInfo::default().application_info(&app),
                None,
            )
            .map_err(|e| format!("vkCreateInstance: {e}"))?;
        let wanted = std::env::var("FOVEA_SIM_VK_DEVICE").unwrap_or_default();
        let found = instance
            .enumerate_physical_devices()
            .unwrap_or_default()
            .into_iter()
            .map(|pd| instance.get_physical_device_properties(pd))
            .map(|p| {
                let name = p
                    .device_name_as_c_str()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                (name, p.device_type == vk::PhysicalDeviceType::CPU)
            })
            .find(|(name, _)| name.contains(&wanted));
        instance.destroy_instance(None);
        found.ok_or_else(|| "Vulkan has no device to render with".into())
    }
}

/// What the driver of the device named `device` offers for density maps (unavailable where it
/// cannot be asked).
fn driver_fdm(device: &str) -> Fdm {
    // SAFETY: loading libvulkan runs its initialisers, as any Vulkan application does.
    let Ok(entry) = (unsafe { ash::Entry::load() }) else {
        return Fdm::Unavailable;
    };
    // SAFETY: a loaded loader.
    unsafe { crate::vk_doctor::gpus(&entry) }
        .unwrap_or_default()
        .into_iter()
        .find(|(name, _)| name == device)
        .map_or(Fdm::Unavailable, |(_, fdm)| fdm)
}

/// The environment the example gets so that fovea's Vulkan layer translates its density maps, for a
/// device whose driver offers `fdm`: where it emulates them, `VK_ADD_LAYER_PATH` with `vulkan_dir`
/// (holding the layer's explicit manifest) before any folders already named (`existing`), and
/// `DISABLE_FOVEA_VK_LAYER=1`, which keeps an installed implicit copy of the same layer from
/// loading beside it (`disable_environment` applies to implicit layers only,
/// <https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>). Nothing
/// where the driver has density maps itself or has no shading-rate attachments: the layer would
/// pass everything through.
pub fn vk_layer_env(
    fdm: &Fdm,
    vulkan_dir: &std::path::Path,
    existing: Option<std::ffi::OsString>,
) -> Vec<(&'static str, std::ffi::OsString)> {
    if !matches!(fdm, Fdm::Emulated { .. }) {
        return Vec::new();
    }
    let mut paths = vec![vulkan_dir.to_path_buf()];
    paths.extend(existing.iter().flat_map(std::env::split_paths));
    let joined = std::env::join_paths(paths).unwrap_or_else(|_| vulkan_dir.as_os_str().into());
    vec![(VK_ADD_LAYER_PATH, joined), (DISABLE_VK_LAYER, "1".into())]
}

pub fn run(setup: &Setup, system: System) -> Result<(), String> {
    // Lavapipe draws Quest 3's 2 × 2064×2240 at about 20 frames a second on two cores; Rift CV1's
    // eye buffers take half as long.
    let headset = if system.cpu && !setup.headset_given {
        fovea_model::headsets::by_id("rift-cv1").expect("rift-cv1 preset exists")
    } else {
        setup.headset
    };
    // Half the harness's 20 s where the CPU draws: the story (overload from frame 270, relief from
    // 630, the override) still fits, in about 40 s instead of 80.
    let seconds = setup.seconds_or(if system.cpu { 10 } else { 20 });
    let frames = (seconds as f32 * headset.refresh_hz).round() as u64;
    let manifests = setup.out.join("manifests");
    let layers = manifests.join("api_layers");
    std::fs::create_dir_all(&layers).map_err(|e| format!("{}: {e}", layers.display()))?;
    let write = |path: PathBuf, text: String| {
        std::fs::write(&path, text).map_err(|e| format!("{}: {e}", path.display()))?;
        Ok::<PathBuf, String>(path)
    };
    write(
        layers.join("XR_APILAYER_FOVEA_foveation.json"),
        manifest_text(Kind::Explicit, &system.dir.join("libfovea.so"))?,
    )?;
    let runtime = write(
        manifests.join("fovea_sim_runtime.json"),
        serde_json::json!({
            "file_format_version": "1.0.0",
            "runtime": {
                "name": "fovea simulated headset",
                "library_path": system.dir.join("libfovea_sim.so"),
            }
        })
        .to_string(),
    )?;
    let vulkan_dir = manifests.join("vulkan");
    let vk_env = vk_layer_env(
        &system.fdm,
        &vulkan_dir,
        std::env::var_os(VK_ADD_LAYER_PATH),
    );
    if !vk_env.is_empty() {
        std::fs::create_dir_all(&vulkan_dir)
            .map_err(|e| format!("{}: {e}", vulkan_dir.display()))?;
        write(
            vulkan_dir.join(format!("{}.json", fovea_abi::VK_LAYER_NAME)),
            vk_explicit_manifest_text(&system.dir.join("libfovea.so"))?,
        )?;
    }
    let frames_dir = setup.out.join("frames");
    // Captures from an earlier run would be mistaken for this one's.
    std::fs::remove_dir_all(&frames_dir).ok();
    let script: Vec<String> = LOAD.iter().map(|(f, ms)| format!("{ms}@{f}")).collect();

    println!(
        "fovea demo: examples/{EXAMPLE} through the Khronos loader ({LOADER}), fovea and the \
         simulated {} on {}{}",
        headset.name,
        system.device,
        if system.cpu && !setup.headset_given {
            " (a CPU renderer: the smaller Rift CV1 eye buffers; --headset chooses)"
        } else {
            ""
        }
    );
    println!(
        "{frames} frames ({seconds} s at {} Hz without misses), as fast as the device draws; \
         GPU load {}; eye tracker {}",
        headset.refresh_hz,
        load_description(),
        gaze_description()
    );
    println!(
        "{}: {}",
        system.device,
        if vk_env.is_empty() {
            format!(
                "{}; the example samples the density maps into its debug overlay",
                system.fdm.describe()
            )
        } else {
            format!(
                "{}; fovea's Vulkan layer is enabled for the example (VK_ADD_LAYER_PATH={}), so \
                 its eye passes are shaded at the maps' rates",
                system.fdm.describe(),
                vulkan_dir.display()
            )
        }
    );
    let mut child = Command::new(system.dir.join("examples").join(EXAMPLE))
        .envs(vk_env.iter().map(|(k, v)| (k, v)))
        .args(["--levels", "high", "--dynamic", "--eye-tracked", "--dump"])
        .arg(&frames_dir)
        .args(["--frames", &frames.to_string()])
        .args(["--frames-per-level", &frames.to_string()])
        .env("XR_RUNTIME_JSON", &runtime)
        .env("XR_API_LAYER_PATH", &layers)
        .env("XR_ENABLE_API_LAYERS", fovea_harness::FOVEA_LAYER)
        .env("FOVEA_LOG", &setup.log)
        .env("FOVEA_PROPS", &setup.props)
        .env("FOVEA_SIM_HEADSET", headset.id)
        .env("FOVEA_SIM_LOAD", script.join(","))
        .env("FOVEA_SIM_EYE_GAZE", "on")
        .env("FOVEA_SIM_GAZE", GAZE)
        .env_remove("FOVEA_SIM_REALTIME")
        .env_remove("FOVEA_SIM_EXIT_AFTER_FRAMES")
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("examples/{EXAMPLE}: {e}"))?;
    // The layer logs to stderr; its stats lines come once per display second, which is how the
    // demo knows when to write the override.
    let stderr = child.stderr.take().expect("piped");
    // Four fifths through in display time, which misses stretch: a frame whose GPU time is over
    // the period takes as many periods as it needs.
    let period_ms = 1000.0 / headset.refresh_hz;
    let load = fovea_harness::sim::control::Load {
        gpu_ms: LOAD.to_vec(),
    };
    let periods: f32 = (0..frames)
        .map(|f| (load.gpu_ms_at(f) / period_ms).ceil().max(1.0))
        .sum();
    let override_at = (periods / headset.refresh_hz * 0.8).round() as u64;
    let mut seconds = 0;
    let mut result = Ok(());
    for line in BufReader::new(stderr).lines().map_while(Result::ok) {
        eprintln!("{line}");
        if line.contains(fovea_abi::log_target::STATS) {
            seconds += 1;
            if seconds == override_at && result.is_ok() {
                result = setup.write_override();
            }
        }
    }
    let status = child
        .wait()
        .map_err(|e| format!("examples/{EXAMPLE}: {e}"))?;
    result?;
    if !status.success() {
        return Err(format!("examples/{EXAMPLE} failed: {status}"));
    }
    println!(
        "density maps (fNNNNN_high_density_*.png, one pixel per texel: red = horizontal density, \
         green = vertical) and frames (fNNNNN_high_{{left,right}}.png) read back from the GPU: {}",
        frames_dir.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_vulkan_layer_is_enabled_only_where_it_emulates() {
        let dir = std::path::Path::new("/out/manifests/vulkan");
        let emulated = Fdm::Emulated {
            texel: [16, 16],
            layered: true,
            largest: [4, 4],
        };
        let env = vk_layer_env(&emulated, dir, None);
        assert_eq!(
            env,
            vec![
                (VK_ADD_LAYER_PATH, dir.as_os_str().to_owned()),
                (DISABLE_VK_LAYER, "1".into()),
            ]
        );
        // Folders the user named stay, after the demo's own.
        let env = vk_layer_env(&emulated, dir, Some("/a:/b".into()));
        assert_eq!(env[0].1, "/out/manifests/vulkan:/a:/b");
        // lavapipe (no shading-rate attachments) and native density maps: as before.
        assert!(vk_layer_env(&Fdm::Unavailable, dir, Some("/a".into())).is_empty());
        assert!(vk_layer_env(&Fdm::Native, dir, None).is_empty());
    }

    #[test]
    fn the_explicit_vulkan_manifest_names_the_built_library() {
        let text = vk_explicit_manifest_text(std::path::Path::new("/t/release/libfovea.so"))
            .expect("manifest");
        let v: serde_json::Value = serde_json::from_str(&text).expect("JSON");
        assert_eq!(v["layer"]["name"], fovea_abi::VK_LAYER_NAME);
        assert_eq!(v["layer"]["library_path"], "/t/release/libfovea.so");
        assert!(v["layer"].get("enable_environment").is_none(), "explicit");
    }
}
