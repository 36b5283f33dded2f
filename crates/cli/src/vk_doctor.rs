//! `fovea doctor`'s Vulkan half: whether each GPU's driver has fragment density maps natively, can
//! have them emulated by fovea's Vulkan layer on shading-rate attachments, or neither
//! (docs/vulkan-fdm-on-fsr.md#drivers); and whether that layer is installed where the Vulkan loader
//! looks and would load.
//!
//! Where the loader looks is [`crate::discovery::vk_layer_dirs`]; what it makes of a manifest
//! follows <https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>.
//! The GPUs are asked without fovea's layer, so the answer is the driver's own.

use std::ffi::CStr;
use std::path::{Path, PathBuf};

use ash::vk;
use serde_json::Value;

use crate::discovery::{vk_layer_dirs, Environment, Kind};
use fovea_abi::env::{DISABLE_VK_LAYER, VK_LAYER};
use fovea_abi::VK_LAYER_NAME;

/// The symbol the Vulkan loader looks up in a layer library (interface version 2 and later).
const NEGOTIATE: &str = "vkNegotiateLoaderLayerInterfaceVersion";

/// What doctor prints about Vulkan, and the problems it found.
#[derive(Debug, Default)]
pub struct Report {
    pub lines: Vec<String>,
    pub problems: Vec<String>,
}

/// What one GPU's driver offers.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Fdm {
    Native,
    /// Shading-rate attachments: texel size, layered, largest fragment.
    Emulated {
        texel: [u32; 2],
        layered: bool,
        largest: [u32; 2],
    },
    Unavailable,
}

impl Fdm {
    pub fn describe(&self) -> String {
        match self {
            Fdm::Native => {
                "fragment density maps native (the driver has VK_EXT_fragment_density_map; \
                            fovea's Vulkan layer passes it through)"
                    .to_owned()
            }
            Fdm::Emulated {
                texel,
                layered,
                largest,
            } => {
                format!(
                "fragment density maps emulated by {VK_LAYER_NAME} on shading-rate attachments: \
                 texel {}×{}, {}, up to {}×{}",
                texel[0],
                texel[1],
                if *layered { "layered" } else { "one layer for both eyes" },
                largest[0],
                largest[1]
            )
            }
            Fdm::Unavailable => "fragment density maps unavailable (neither \
                                 VK_EXT_fragment_density_map nor a shading-rate attachment): \
                                 foveated frames render at full rate"
                .to_owned(),
        }
    }
}

/// One manifest of fovea's Vulkan layer where the loader looks.
#[derive(Debug)]
struct Found {
    path: PathBuf,
    kind: Kind,
    /// Why the loader would not load it, or `None`.
    problem: Option<String>,
    library: Option<PathBuf>,
}

/// The layers a Vulkan manifest describes: `layer`, or each of `layers` (file format 1.0.1+).
fn layers(v: &Value) -> Vec<&Value> {
    match (&v["layer"], v["layers"].as_array()) {
        (l, _) if l.is_object() => vec![l],
        (_, Some(ls)) => ls.iter().collect(),
        _ => Vec::new(),
    }
}

/// Whether `library` exports the loader's negotiation function, by loading it as the loader would.
fn exports_negotiate(library: &Path) -> Result<(), String> {
    // SAFETY: loading a layer library runs its initialisers, as the Vulkan loader would; fovea's
    // own has none beyond Rust's. Nothing of it is called.
    let lib = unsafe { libloading::Library::new(library) }.map_err(|e| e.to_string())?;
    // SAFETY: only the symbol's presence is checked; it is never called through this type.
    unsafe { lib.get::<unsafe extern "C" fn()>(NEGOTIATE.as_bytes()) }
        .map(|_| ())
        .map_err(|_| format!("it does not export {NEGOTIATE}"))
}

fn check(path: &Path, kind: Kind, layer: &Value, env: &Environment) -> Found {
    let mut found = Found {
        path: path.to_path_buf(),
        kind,
        problem: None,
        library: None,
    };
    let Some(lib) = layer["library_path"].as_str() else {
        found.problem = Some("it has no library_path string: the loader skips it".into());
        return found;
    };
    let p = Path::new(lib);
    let library = if p.is_absolute() || !lib.contains('/') {
        p.to_path_buf()
    } else {
        path.parent().unwrap_or(Path::new(".")).join(p)
    };
    found.library = Some(library.clone());
    let disable = layer["disable_environment"].as_object();
    found.problem = if kind == Kind::Implicit && disable.is_none_or(|d| d.is_empty()) {
        Some(format!(
            "implicit Vulkan layer manifest without disable_environment: the loader rejects it \
             (`fovea install` writes {DISABLE_VK_LAYER})"
        ))
    } else if let Some(var) = disable
        .filter(|_| kind == Kind::Implicit)
        .and_then(|d| d.keys().find(|k| env.is_set(k)))
    {
        Some(format!(
            "the implicit Vulkan layer is disabled because {var} is set; unset it"
        ))
    } else if library.is_absolute() && !library.is_file() {
        Some(format!(
            "its library_path {} is not a file, so the loader cannot load the Vulkan layer \
             (`cargo build --release` builds it; `fovea install` points the manifests at a build)",
            library.display()
        ))
    } else if let Err(why) = exports_negotiate(&library) {
        Some(format!(
            "its library {} cannot serve as the Vulkan layer: {why} (`fovea install` points the \
             manifests at this build's libfovea.so)",
            library.display()
        ))
    } else {
        None
    };
    if found.problem.is_none() && kind == Kind::Implicit {
        if let Some((var, want)) = layer["enable_environment"]
            .as_object()
            .and_then(|e| e.iter().next())
        {
            let want = want.as_str().unwrap_or_default();
            if let Some(have) = env.vars.get(var).filter(|v| v.as_str() != want) {
                found.problem = Some(format!(
                    "{var}={have} keeps the implicit Vulkan layer out of OpenXR applications \
                     (fovea sets {var}={want} where it is unset); unset it"
                ));
            }
        }
    }
    found
}

/// fovea's Vulkan layer manifests in the loader's search, implicit first.
fn find_layer(env: &Environment) -> Vec<Found> {
    let mut out = Vec::new();
    for kind in [Kind::Implicit, Kind::Explicit] {
        for dir in vk_layer_dirs(env, kind) {
            let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
                .into_iter()
                .flatten()
                .flatten()
                .map(|e| e.path())
                .filter(|p| p.extension().is_some_and(|x| x == "json") && p.is_file())
                .collect();
            files.sort();
            for f in files {
                let Some(v) = std::fs::read_to_string(&f)
                    .ok()
                    .and_then(|t| serde_json::from_str::<Value>(&t).ok())
                else {
                    continue;
                };
                for l in layers(&v) {
                    if l["name"] == VK_LAYER_NAME {
                        out.push(check(&f, kind, l, env));
                    }
                }
            }
        }
    }
    out
}

/// What the loader would do with fovea's Vulkan layer. `openxr_found`: a manifest of fovea's OpenXR
/// layer exists, so an install is under way and a missing Vulkan manifest is a problem.
pub fn layer_report(env: &Environment, openxr_found: bool, report: &mut Report) -> bool {
    let found = find_layer(env);
    for f in &found {
        let how = match (f.kind, &f.problem) {
            (_, Some(p)) => format!("would not load: {p}"),
            (Kind::Implicit, None) => format!(
                "implicit; loads into processes with {VK_LAYER}=1, which fovea sets for OpenXR \
                 applications that use Vulkan"
            ),
            (Kind::Explicit, None) => "explicit; fovea adds it to VkInstances made through \
                                       XR_KHR_vulkan_enable2, VK_INSTANCE_LAYERS names it for others"
                .to_owned(),
        };
        let library = f
            .library
            .as_ref()
            .map(|l| format!(", library {}", l.display()))
            .unwrap_or_default();
        report
            .lines
            .push(format!("  {}{library}: {how}", f.path.display()));
        if let Some(p) = &f.problem {
            report.problems.push(format!("{}: {p}", f.path.display()));
        }
    }
    let usable = found.iter().any(|f| f.problem.is_none());
    if found.is_empty() {
        report.lines.push("  (no manifest found)".into());
        if openxr_found {
            report.problems.push(format!(
                "the Vulkan layer {VK_LAYER_NAME} is not installed: on GPUs with shading-rate \
                 attachments density maps save nothing; `fovea install` writes its manifest"
            ));
        }
    }
    usable
}

/// The fragment sizes `pd` supports (vkGetPhysicalDeviceFragmentShadingRatesKHR; none on error).
///
/// # Safety
/// `pd` must belong to the instance `fsr` was loaded for, and the device have the extension.
unsafe fn rates(
    fsr: &ash::khr::fragment_shading_rate::Instance,
    pd: vk::PhysicalDevice,
) -> Vec<vk::PhysicalDeviceFragmentShadingRateKHR<'static>> {
    let f = fsr.fp().get_physical_device_fragment_shading_rates_khr;
    let mut n = 0;
    // SAFETY: the caller's contract; a count query into a local.
    if unsafe { f(pd, &mut n, std::ptr::null_mut()) } != vk::Result::SUCCESS {
        return Vec::new();
    }
    let mut v = vec![vk::PhysicalDeviceFragmentShadingRateKHR::default(); n as usize];
    // SAFETY: `v` holds `n` initialised structs with their sType set.
    match unsafe { f(pd, &mut n, v.as_mut_ptr()) } {
        vk::Result::SUCCESS | vk::Result::INCOMPLETE => {
            v.truncate(n as usize);
            v
        }
        _ => Vec::new(),
    }
}

/// What each GPU's driver offers, asked through `entry` without fovea's layer.
///
/// # Safety
/// `entry` must be a loaded Vulkan loader.
pub unsafe fn gpus(entry: &ash::Entry) -> Result<Vec<(String, Fdm)>, String> {
    let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_1);
    let info = vk::InstanceCreateInfo::default().application_info(&app);
    // SAFETY: the caller's contract; the create info lives across the call.
    let instance = unsafe { entry.create_instance(&info, None) }
        .map_err(|e| format!("vkCreateInstance: {e}"))?;
    // SAFETY: `instance` is live until destroyed below; every struct lives across its call.
    let result = unsafe {
        let fsr = ash::khr::fragment_shading_rate::Instance::new(entry, &instance);
        instance.enumerate_physical_devices().map(|pds| {
            pds.into_iter()
                .map(|pd| {
                    let props = instance.get_physical_device_properties(pd);
                    let name = props
                        .device_name_as_c_str()
                        .map(|n| n.to_string_lossy().into_owned())
                        .unwrap_or_default();
                    let exts = instance
                        .enumerate_device_extension_properties(pd)
                        .unwrap_or_default();
                    let has =
                        |want: &CStr| exts.iter().any(|e| e.extension_name_as_c_str() == Ok(want));
                    let fdm = if has(ash::ext::fragment_density_map::NAME) {
                        Fdm::Native
                    } else if has(ash::khr::fragment_shading_rate::NAME) {
                        let mut features =
                            vk::PhysicalDeviceFragmentShadingRateFeaturesKHR::default();
                        let mut f2 =
                            vk::PhysicalDeviceFeatures2::default().push_next(&mut features);
                        instance.get_physical_device_features2(pd, &mut f2);
                        let attachment = features.attachment_fragment_shading_rate == vk::TRUE;
                        let mut p = vk::PhysicalDeviceFragmentShadingRatePropertiesKHR::default();
                        let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut p);
                        instance.get_physical_device_properties2(pd, &mut p2);
                        let texel = p.min_fragment_shading_rate_attachment_texel_size;
                        let largest = rates(&fsr, pd)
                            .iter()
                            .map(|r| r.fragment_size)
                            .max_by_key(|s| (s.width * s.height, s.width))
                            .map(|s| [s.width, s.height])
                            .unwrap_or([1, 1]);
                        if attachment {
                            Fdm::Emulated {
                                texel: [texel.width, texel.height],
                                layered: p.layered_shading_rate_attachments == vk::TRUE,
                                largest,
                            }
                        } else {
                            Fdm::Unavailable
                        }
                    } else {
                        Fdm::Unavailable
                    };
                    (name, fdm)
                })
                .collect()
        })
    };
    // SAFETY: nothing made from the instance outlives it.
    unsafe { instance.destroy_instance(None) };
    result.map_err(|e| format!("vkEnumeratePhysicalDevices: {e}"))
}

/// The GPU lines, and a problem where a GPU needs the layer that would not load.
///
/// Asks the driver, not fovea's layer: call it with `DISABLE_FOVEA_VK_LAYER` (and
/// `VK_LOADER_LAYERS_DISABLE` naming the layer) already in the process environment, so neither an
/// implicit nor an explicitly enabled copy of the layer answers.
pub fn gpu_report(layer_usable: bool, report: &mut Report) {
    // SAFETY: loading libvulkan runs its initialisers, as any Vulkan application does.
    let entry = match unsafe { ash::Entry::load() } {
        Ok(e) => e,
        Err(e) => {
            report
                .lines
                .push(format!("GPUs: not asked, no Vulkan loader ({e})"));
            return;
        }
    };
    // SAFETY: a loaded loader.
    match unsafe { gpus(&entry) } {
        Err(e) => report.lines.push(format!("GPUs: not asked ({e})")),
        Ok(g) if g.is_empty() => report
            .lines
            .push("GPUs: the Vulkan loader finds none".into()),
        Ok(g) => {
            report.lines.push("GPUs (the drivers' own answers):".into());
            for (i, (name, fdm)) in g.iter().enumerate() {
                report
                    .lines
                    .push(format!("  {i}. {name}: {}", fdm.describe()));
                if matches!(fdm, Fdm::Emulated { .. }) && !layer_usable {
                    report.problems.push(format!(
                        "{name} needs fovea's Vulkan layer to save GPU time with density maps, and \
                         it would not load (see the Vulkan layer lines above; `fovea install` \
                         writes its manifest)"
                    ));
                }
            }
        }
    }
}

/// Sets, in this single-threaded process, the variables that keep fovea's Vulkan layer out of the
/// instance [`gpu_report`] makes.
pub fn keep_layer_out() {
    std::env::set_var(DISABLE_VK_LAYER, "1");
    let disable = "VK_LOADER_LAYERS_DISABLE";
    let list = match std::env::var(disable) {
        Ok(v) if !v.is_empty() => format!("{v},{VK_LAYER_NAME}"),
        _ => VK_LAYER_NAME.to_owned(),
    };
    std::env::set_var(disable, list);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn descriptions() {
        let e = Fdm::Emulated {
            texel: [16, 16],
            layered: true,
            largest: [4, 4],
        };
        assert!(e.describe().ends_with("texel 16×16, layered, up to 4×4"));
        assert!(Fdm::Unavailable.describe().contains("unavailable"));
        assert!(Fdm::Native.describe().contains("native"));
    }

    #[test]
    fn manifests_with_one_or_many_layers() {
        let one: Value = serde_json::json!({"layer": {"name": "a"}});
        let many: Value = serde_json::json!({"layers": [{"name": "a"}, {"name": "b"}]});
        assert_eq!(layers(&one).len(), 1);
        assert_eq!(layers(&many).len(), 2);
        assert!(layers(&serde_json::json!({})).is_empty());
    }
}
