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

use super::setup::{
    build_dir, cargo_build, gaze_description, load_at, load_description, Setup, GAZE,
};
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
    /// The shading-rate double's library, where it is built beside the rest.
    double: Option<PathBuf>,
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
            "-p",
            "fovea-vkdouble",
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
        let double = Some(dir.join(DOUBLE_LIBRARY)).filter(|d| d.is_file());
        Ok(System {
            device,
            cpu,
            fdm,
            dir,
            double,
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

/// The environment the example gets so that fovea's Vulkan layer translates its density maps
/// (`translate`: the device has shading-rate attachments and no density maps, or the double plays
/// such a device): `VK_ADD_LAYER_PATH` with `vulkan_dir`
/// (holding the layer's explicit manifest) before any folders already named (`existing`), and
/// `DISABLE_FOVEA_VK_LAYER=1`, which keeps an installed implicit copy of the same layer from
/// loading beside it (`disable_environment` applies to implicit layers only,
/// <https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>). Nothing
/// where the driver has density maps itself or has no shading-rate attachments: the layer would
/// pass everything through.
pub fn vk_layer_env(
    translate: bool,
    vulkan_dir: &std::path::Path,
    existing: Option<std::ffi::OsString>,
) -> Vec<(&'static str, std::ffi::OsString)> {
    if !translate {
        return Vec::new();
    }
    let mut paths = vec![vulkan_dir.to_path_buf()];
    paths.extend(existing.iter().flat_map(std::env::split_paths));
    let joined = std::env::join_paths(paths).unwrap_or_else(|_| vulkan_dir.as_os_str().into());
    vec![(VK_ADD_LAYER_PATH, joined), (DISABLE_VK_LAYER, "1".into())]
}

/// What the example renders, and on what.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Render {
    /// The room, foveated by the device itself (native density maps, or fovea's Vulkan layer on
    /// its shading-rate attachments).
    Device,
    /// The room, foveated by fovea's Vulkan layer over the shading-rate double on a device that
    /// has neither (lavapipe): what a desktop GPU shades, as a user would see it.
    Double,
    /// The stripes at full rate, the density maps sampled into a debug overlay (`--overlay`, or
    /// no double built).
    Overlay,
}

/// The display rate over the double on a CPU renderer: lavapipe draws the room's two Rift CV1 eye
/// buffers in about half a second, so the story's 8 seconds are 240 frames instead of 720.
const CPU_ROOM_HZ: f32 = 30.0;

/// Seconds of display time before frame `n`, with `load` (frames, GPU ms) on a display at `hz`:
/// the simulated runtime's clock advances a period per frame, or as many as a frame's GPU time
/// needs (a miss).
fn display_seconds(load: &[(u64, f32)], hz: f32, n: u64) -> f64 {
    let load = fovea_harness::sim::control::Load {
        gpu_ms: load.to_vec(),
    };
    let period_ms = 1000.0 / hz;
    let periods: f32 = (0..n)
        .map(|f| (load.gpu_ms_at(f) / period_ms).ceil().max(1.0))
        .sum();
    // An empty sum of floats is -0.0; adding 0.0 makes it 0.0.
    (f64::from(periods) + 0.0) / f64::from(hz)
}

pub fn run(setup: &Setup, system: System) -> Result<(), String> {
    let render = match (&system.fdm, &system.double) {
        (Fdm::Unavailable, Some(_)) if !setup.overlay => Render::Double,
        (Fdm::Unavailable, None) if !setup.overlay => {
            println!(
                "fovea demo: {} is not built, so the frames are not foveated: the maps are \
                 sampled into an overlay instead (cargo build -p fovea-vkdouble)",
                DOUBLE_LIBRARY
            );
            Render::Overlay
        }
        (Fdm::Unavailable, _) => Render::Overlay,
        _ => {
            if setup.overlay {
                println!(
                    "fovea demo: --overlay is for devices without shading-rate attachments; this \
                     one renders the maps itself, so the frames are foveated"
                );
            }
            Render::Device
        }
    };
    if setup.compare && render == Render::Overlay {
        return Err("--compare needs foveated frames: a shading-rate GPU or the double".into());
    }
    // Lavapipe draws Quest 3's 2 × 2064×2240 at about 20 frames a second on two cores (the room:
    // 2 a second); Rift CV1's eye buffers take half as long.
    let headset = if system.cpu && !setup.headset_given {
        fovea_model::headsets::by_id("rift-cv1").expect("rift-cv1 preset exists")
    } else {
        setup.headset
    };
    let hz = if system.cpu && render == Render::Double {
        CPU_ROOM_HZ
    } else {
        headset.refresh_hz
    };
    let load = load_at(hz);
    // Half the harness's 20 s where the CPU draws: the story (overload from 3 s, relief 4 s later,
    // the override) still fits.
    let seconds = setup.seconds_or(match (system.cpu, render) {
        (true, Render::Double) => 8,
        (true, _) => 10,
        (false, _) => 20,
    });
    let frames = (seconds as f32 * hz).round() as u64;
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
    let translate = matches!(system.fdm, Fdm::Emulated { .. }) || render == Render::Double;
    let mut vk_env = vk_layer_env(translate, &vulkan_dir, std::env::var_os(VK_ADD_LAYER_PATH));
    let mut example_args: Vec<String> = Vec::new();
    if !vk_env.is_empty() {
        std::fs::create_dir_all(&vulkan_dir)
            .map_err(|e| format!("{}: {e}", vulkan_dir.display()))?;
        write(
            vulkan_dir.join(format!("{}.json", fovea_abi::VK_LAYER_NAME)),
            vk_explicit_manifest_text(&system.dir.join("libfovea.so"))?,
        )?;
    }
    if let (Render::Double, Some(double)) = (render, &system.double) {
        write(
            vulkan_dir.join(DOUBLE_MANIFEST),
            double_manifest_text(double),
        )?;
        vk_env.push((DOUBLE_PROFILE_ENV, "nvidia".into()));
        example_args.extend(["--vk-layer".into(), DOUBLE_LAYER.into()]);
    }
    if render != Render::Overlay {
        // A frame read back each second of frames (each two on a GPU, whose eye buffers are
        // larger and whose runs longer: the example holds what it reads back until it ends), so
        // the frames show the fovea at each place the gaze script goes and the periphery at each
        // level the run goes through.
        let seconds_apart = if render == Render::Double { 1.0 } else { 2.0 };
        example_args.extend([
            "--scene".into(),
            "room".into(),
            "--read-every".into(),
            ((hz * seconds_apart).round() as u64).max(1).to_string(),
        ]);
    }
    let script: Vec<String> = load.iter().map(|(f, ms)| format!("{ms}@{f}")).collect();

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
        "{frames} frames ({seconds} s at {hz} Hz without misses), as fast as the device draws; \
         GPU load {}; eye tracker {}",
        load_description(&load),
        gaze_description()
    );
    println!(
        "{}: {}",
        system.device,
        match render {
            Render::Overlay => format!(
                "{}; the example draws stripes at full rate and samples the density maps into its \
                 debug overlay",
                system.fdm.describe()
            ),
            Render::Double => format!(
                "{}; the example renders its room on the simulated desktop GPU instead: fovea's \
                 Vulkan layer over {DOUBLE_LAYER} (NVIDIA-like shading-rate attachments, 16×16 \
                 texels, up to 4×4 fragments), so its eye passes are shaded at the maps' rates \
                 and the frames read back show what a headset would: the fovea sharp where the \
                 eye looks, the periphery in coarse blocks",
                system.fdm.describe()
            ),
            Render::Device if vk_env.is_empty() => format!(
                "{}; the example renders its room with them",
                system.fdm.describe()
            ),
            Render::Device => format!(
                "{}; fovea's Vulkan layer is enabled for the example (VK_ADD_LAYER_PATH={}), so \
                 its eye passes are shaded at the maps' rates",
                system.fdm.describe(),
                vulkan_dir.display()
            ),
        }
    );
    let frames_dir = setup.out.join("frames");
    // Captures from an earlier run would be mistaken for this one's.
    std::fs::remove_dir_all(&frames_dir).ok();
    std::fs::remove_dir_all(setup.out.join("compare")).ok();
    // `--compare`: the same frames twice, the coarse blocks as they are and reconstructed
    // (docs/settings.md, `subsampled`); otherwise once, as the settings say.
    let runs: Vec<(PathBuf, Option<&str>)> = if setup.compare {
        vec![
            (frames_dir.join("blocky"), Some("off")),
            (frames_dir.join("smooth"), Some("on")),
        ]
    } else {
        vec![(frames_dir.clone(), None)]
    };
    for (i, (dir, subsampled)) in runs.iter().enumerate() {
        if i > 0 {
            setup.reset_props()?;
        }
        if let Some(s) = subsampled {
            println!("-- run {} of {}: {SUBSAMPLED_ENV}={s}", i + 1, runs.len());
        }
        let mut command = Command::new(system.dir.join("examples").join(EXAMPLE));
        command
            .envs(vk_env.iter().map(|(k, v)| (k, v)))
            .args(["--levels", "high", "--dynamic", "--eye-tracked", "--dump"])
            .arg(dir)
            .args(["--frames", &frames.to_string()])
            .args(["--frames-per-level", &frames.to_string()])
            .args(&example_args)
            .env("XR_RUNTIME_JSON", &runtime)
            .env("XR_API_LAYER_PATH", &layers)
            .env("XR_ENABLE_API_LAYERS", fovea_harness::FOVEA_LAYER)
            .env("FOVEA_LOG", &setup.log)
            .env("FOVEA_PROPS", &setup.props)
            .env("FOVEA_SIM_HEADSET", headset.id)
            .env("FOVEA_SIM_REFRESH_HZ", hz.to_string())
            .env("FOVEA_SIM_LOAD", script.join(","))
            .env("FOVEA_SIM_EYE_GAZE", "on")
            .env("FOVEA_SIM_GAZE", GAZE)
            .env_remove("FOVEA_SIM_REALTIME")
            .env_remove("FOVEA_SIM_EXIT_AFTER_FRAMES");
        if let Some(s) = subsampled {
            command.env(SUBSAMPLED_ENV, s);
        }
        run_example(setup, command, &load, hz, frames)?;
    }

    if render == Render::Overlay {
        println!(
            "density maps (fNNNNN_high_density_*.png, one pixel per texel: red = horizontal \
             density, green = vertical) and frames (fNNNNN_high_{{left,right}}.png, the maps in \
             the overlay at the lower left) read back from the GPU: {}",
            frames_dir.display()
        );
        return Ok(());
    }
    let gaze = fovea_harness::sim::gaze_script::GazeScript::parse(GAZE)?;
    for (dir, subsampled) in &runs {
        println!(
            "frames read back from the GPU (fNNNNN_high_{{left,right}}.png; the density map each \
             was drawn with beside it, fNNNNN_high_density_*.png: red = \
             horizontal density, green = vertical){}: {}",
            match subsampled {
                Some("on") => ", coarse blocks reconstructed",
                Some(_) => ", coarse blocks as shaded",
                None => "",
            },
            dir.display()
        );
        for line in super::frames::summary(dir, &gaze, |n| display_seconds(&load, hz, n))? {
            println!("{line}");
        }
    }
    if setup.compare {
        let out = setup.out.join("compare");
        let (written, identical) = super::frames::side_by_side(&runs[0].0, &runs[1].0, &out)?;
        println!(
            "{written} frames side by side, coarse blocks on the left, reconstructed on the right: \
             {}{}",
            out.display(),
            if written > 0 && identical == written {
                format!(
                    "\n(every pair is identical: {SUBSAMPLED_ENV}=on changed nothing, so this build \
                     of fovea does not reconstruct coarse blocks)"
                )
            } else {
                String::new()
            }
        );
    }
    Ok(())
}

/// Runs the example `command` to its end, its stderr (the layer's log) passed through, and writes
/// the override four fifths through in display time, which misses stretch: a frame whose GPU time
/// is over the period takes as many periods as it needs.
fn run_example(
    setup: &Setup,
    mut command: Command,
    load: &[(u64, f32)],
    hz: f32,
    frames: u64,
) -> Result<(), String> {
    let mut child = command
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("examples/{EXAMPLE}: {e}"))?;
    // The layer logs to stderr; its stats lines come once per display second, which is how the
    // demo knows when to write the override.
    let stderr = child.stderr.take().expect("piped");
    let override_at = (display_seconds(load, hz, frames) * 0.8).round() as u64;
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
    Ok(())
}

/// The shading-rate double's layer (`crates/vkdouble`), its library, manifest and profile
/// variable, as `fovea_vkdouble` names them (the unit tests hold them to it).
const DOUBLE_LAYER: &str = "VK_LAYER_FOVEA_shading_rate_double";
const DOUBLE_LIBRARY: &str = "libfovea_vkdouble.so";
const DOUBLE_MANIFEST: &str = "VkLayer_fovea_shading_rate_double.json";
const DOUBLE_PROFILE_ENV: &str = "FOVEA_VKDOUBLE_PROFILE";
/// The setting that switches reconstruction of coarse fragments (docs/settings.md).
const SUBSAMPLED_ENV: &str = "FOVEA_SUBSAMPLED";

/// The double's layer manifest for its library at `library`: the device extensions it adds are
/// listed, since the loader refuses device extensions that neither the driver nor an enabled
/// layer's manifest names.
fn double_manifest_text(library: &std::path::Path) -> String {
    serde_json::json!({
        "file_format_version": "1.1.2",
        "layer": {
            "name": DOUBLE_LAYER,
            "type": "GLOBAL",
            "library_path": library.to_string_lossy(),
            "api_version": "1.4.359",
            "implementation_version": "1",
            "description": "fovea test double: shading-rate attachments on a device without them",
            "device_extensions": [{
                "name": "VK_KHR_fragment_shading_rate",
                "spec_version": "2",
                "entrypoints": ["vkCmdSetFragmentShadingRateKHR"]
            }, {
                "name": "VK_EXT_load_store_op_none",
                "spec_version": "1"
            }]
        }
    })
    .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_vulkan_layer_is_enabled_only_where_it_emulates() {
        let dir = std::path::Path::new("/out/manifests/vulkan");
        let env = vk_layer_env(true, dir, None);
        assert_eq!(
            env,
            vec![
                (VK_ADD_LAYER_PATH, dir.as_os_str().to_owned()),
                (DISABLE_VK_LAYER, "1".into()),
            ]
        );
        // Folders the user named stay, after the demo's own.
        let env = vk_layer_env(true, dir, Some("/a:/b".into()));
        assert_eq!(env[0].1, "/out/manifests/vulkan:/a:/b");
        // lavapipe (no shading-rate attachments) and native density maps: as before.
        assert!(vk_layer_env(false, dir, Some("/a".into())).is_empty());
    }

    /// The demo names the double as the double names itself.
    #[test]
    fn the_doubles_names_and_manifest_are_its_own() {
        assert_eq!(DOUBLE_LAYER, fovea_vkdouble::LAYER_NAME.to_str().unwrap());
        assert_eq!(DOUBLE_LIBRARY, fovea_vkdouble::LIBRARY_FILE);
        assert_eq!(DOUBLE_PROFILE_ENV, fovea_vkdouble::PROFILE_ENV);
        let dir = std::env::temp_dir().join(format!("fovea-demo-double-{}", std::process::id()));
        let lib = std::path::Path::new("/t/debug/libfovea_vkdouble.so");
        let written = fovea_vkdouble::write_manifest(&dir, lib).expect("manifest");
        assert_eq!(written.file_name().unwrap(), DOUBLE_MANIFEST);
        let theirs: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&written).unwrap()).unwrap();
        let ours: serde_json::Value = serde_json::from_str(&double_manifest_text(lib)).unwrap();
        assert_eq!(ours, theirs);
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Misses stretch the display clock: a frame over the period takes two.
    #[test]
    fn display_time_counts_the_periods_misses_take() {
        let load = [(0, 6.0), (3, 14.0), (5, 6.0)];
        // 3 light frames, 2 missed (2 periods each), 1 light: 8 periods at 90 Hz.
        assert!((display_seconds(&load, 90.0, 6) - 8.0 / 90.0).abs() < 1e-9);
        assert_eq!(display_seconds(&load, 90.0, 0), 0.0);
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
