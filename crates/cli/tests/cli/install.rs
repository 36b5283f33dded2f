//! `fovea install`, `uninstall` and `doctor`, from the built binary, in a scratch directory: `HOME`,
//! `XDG_DATA_HOME`, `XDG_CONFIG_HOME`, `XDG_DATA_DIRS` and `XDG_CONFIG_DIRS` all point into it and
//! nothing else of the caller's environment gets through, so the real home directory is never read
//! or written.
//!
//! The loader's compiled-in `/etc` is the one directory no variable moves; these tests assume it
//! holds no OpenXR manifests (the binary's unit tests cover it under a scratch root).

use std::path::{Path, PathBuf};

use fovea_abi::EXTENSIONS;
use serde_json::Value;

use crate::support::{command, run, Run};

const FOVEA: &str = "XR_APILAYER_FOVEA_foveation";
const FILE: &str = "XR_APILAYER_FOVEA_foveation.json";
const VK_FILE: &str = "VK_LAYER_FOVEA_fragment_density_map.json";

/// `fovea doctor`'s problem lines.
impl Run {
    fn problems(&self) -> Vec<&str> {
        self.out
            .lines()
            .filter_map(|l| l.strip_prefix("problem: "))
            .collect()
    }

    /// The one problem line containing `needle`.
    fn problem(&self, needle: &str) -> &str {
        let found: Vec<&str> = self
            .problems()
            .into_iter()
            .filter(|p| p.contains(needle))
            .collect();
        assert_eq!(
            found.len(),
            1,
            "one problem with {needle:?} in:\n{}",
            self.out
        );
        found[0]
    }
}

/// A scratch directory standing in for the user's home and the system data directories.
struct Sandbox {
    dir: PathBuf,
}

impl Sandbox {
    fn new(name: &str) -> Sandbox {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
            .join("cli-install")
            .join(name);
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("lib")).unwrap();
        // This build's libfovea.so under the sandbox's own name (a hard link, so the manifests
        // name the sandbox path): doctor loads it to find the Vulkan layer's entry point.
        let lib = dir.join("lib/libfovea.so");
        let real = fovea_harness::artifact("libfovea.so").expect("libfovea.so: cargo build");
        if std::fs::hard_link(&real, &lib).is_err() {
            std::fs::copy(&real, &lib).unwrap();
        }
        let dir = std::fs::canonicalize(dir).unwrap();
        Sandbox { dir }
    }

    fn library(&self) -> PathBuf {
        self.dir.join("lib/libfovea.so")
    }

    fn data_home(&self) -> PathBuf {
        self.dir.join("data")
    }

    /// Where install writes for the user: `$XDG_DATA_HOME/openxr/1/api_layers/<kind>.d`.
    fn layers(&self, kind: &str) -> PathBuf {
        self.data_home()
            .join(format!("openxr/1/api_layers/{kind}.d"))
    }

    /// A directory of `XDG_DATA_DIRS`, searched before `XDG_DATA_HOME`.
    fn system_layers(&self, kind: &str) -> PathBuf {
        self.dir
            .join(format!("sysdata/openxr/1/api_layers/{kind}.d"))
    }

    /// A valid runtime manifest, for `XR_RUNTIME_JSON`.
    fn runtime(&self) -> String {
        let path = self.dir.join("runtime.json");
        std::fs::write(
            &path,
            format!(
                r#"{{"file_format_version": "1.0.0", "runtime": {{"name": "test runtime", "library_path": "{}"}}}}"#,
                self.library().display()
            ),
        )
        .unwrap();
        path.to_str().unwrap().to_owned()
    }

    /// Where install writes the Vulkan layer's manifest: `$XDG_DATA_HOME/vulkan/implicit_layer.d`.
    fn vk_manifest(&self) -> PathBuf {
        self.data_home()
            .join("vulkan/implicit_layer.d")
            .join(VK_FILE)
    }

    fn run(&self, args: &[&str], env: &[(&str, &str)]) -> Run {
        let s = |p: PathBuf| p.to_str().unwrap().to_owned();
        run(command()
            .args(args)
            .env_clear()
            .env("HOME", s(self.dir.join("home")))
            .env("XDG_DATA_HOME", s(self.data_home()))
            .env("XDG_CONFIG_HOME", s(self.dir.join("config")))
            .env("XDG_DATA_DIRS", s(self.dir.join("sysdata")))
            .env("XDG_CONFIG_DIRS", s(self.dir.join("sysconfig")))
            .envs(env.iter().copied()))
    }

    fn install(&self, args: &[&str]) -> Run {
        let lib = self.library();
        let r = self.run(args, &[("FOVEA_LIBRARY", lib.to_str().unwrap())]);
        assert_eq!(r.code, 0, "{args:?}: {}{}", r.out, r.err);
        r
    }

    fn doctor(&self, env: &[(&str, &str)]) -> Run {
        self.run(&["doctor"], env)
    }
}

fn read(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap()
}

/// The checked-in manifest of that kind with `library_path` replaced: what install must write.
fn expected(kind: &str, library: &Path) -> Value {
    let rel = match kind {
        "explicit" => "manifest",
        _ => "manifest/implicit",
    };
    let mut v = read(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../..")
            .join(rel)
            .join(FILE),
    );
    v["api_layer"]["library_path"] = library.to_str().unwrap().into();
    v
}

fn extensions(v: &Value) -> Vec<(String, String)> {
    v["api_layer"]["instance_extensions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            (
                e["name"].as_str().unwrap().to_owned(),
                e["extension_version"].as_str().unwrap().to_owned(),
            )
        })
        .collect()
}

#[test]
fn install_writes_an_explicit_manifest_with_the_absolute_library_path() {
    let sb = Sandbox::new("explicit");
    // A roundabout path: the manifest gets the canonical one.
    let roundabout = sb.dir.join("lib/../lib/libfovea.so");
    let r = sb.run(
        &["install"],
        &[("FOVEA_LIBRARY", roundabout.to_str().unwrap())],
    );
    assert_eq!(r.code, 0, "{}{}", r.out, r.err);
    let path = sb.layers("explicit").join(FILE);
    assert!(
        r.out.contains(&format!("wrote {}", path.display())),
        "{}",
        r.out
    );
    let v = read(&path);
    let lib = v["api_layer"]["library_path"].as_str().unwrap();
    assert_eq!(Path::new(lib), sb.library());
    assert!(Path::new(lib).is_absolute() && Path::new(lib).is_file());
    assert_eq!(v, expected("explicit", &sb.library()));
    let listed = extensions(&v);
    let ours: Vec<(String, String)> = EXTENSIONS
        .iter()
        .map(|e| (e.name.to_str().unwrap().to_owned(), e.version.to_string()))
        .collect();
    assert_eq!(listed, ours);
    assert!(v["api_layer"].get("disable_environment").is_none());
    assert!(!sb.layers("implicit").exists());
    // Again: replaced, same content.
    let r = sb.install(&["install"]);
    assert!(r.out.starts_with("replaced "), "{}", r.out);
    assert_eq!(read(&path), expected("explicit", &sb.library()));
}

#[test]
fn install_defaults_to_home_local_share_without_xdg_data_home() {
    let sb = Sandbox::new("home");
    let lib = sb.library();
    let r = sb.run(
        &["install"],
        &[
            ("FOVEA_LIBRARY", lib.to_str().unwrap()),
            ("XDG_DATA_HOME", ""),
        ],
    );
    assert_eq!(r.code, 0, "{}{}", r.out, r.err);
    let path = sb
        .dir
        .join("home/.local/share/openxr/1/api_layers/explicit.d")
        .join(FILE);
    assert_eq!(read(&path), expected("explicit", &lib));
}

#[test]
fn install_implicit_keeps_disable_environment() {
    let sb = Sandbox::new("implicit");
    let r = sb.install(&["install", "--implicit"]);
    let path = sb.layers("implicit").join(FILE);
    assert!(r.out.contains(&path.display().to_string()), "{}", r.out);
    assert!(r.out.contains("FOVEA_DISABLE"), "{}", r.out);
    let v = read(&path);
    assert_eq!(v["api_layer"]["disable_environment"], "FOVEA_DISABLE");
    assert_eq!(v, expected("implicit", &sb.library()));
    assert!(!sb.layers("explicit").exists());
}

#[test]
fn uninstall_removes_exactly_that_file_and_twice_is_harmless() {
    let sb = Sandbox::new("uninstall");
    sb.install(&["install"]);
    sb.install(&["install", "--implicit"]);
    let explicit = sb.layers("explicit").join(FILE);
    let implicit = sb.layers("implicit").join(FILE);
    let neighbour = sb.layers("implicit").join("other.json");
    std::fs::write(&neighbour, "{}").unwrap();

    let r = sb.run(&["uninstall", "--implicit"], &[]);
    assert_eq!(r.code, 0, "{}{}", r.out, r.err);
    assert_eq!(
        r.out.lines().next().unwrap(),
        format!("removed {}", implicit.display())
    );
    assert!(!implicit.exists() && neighbour.exists() && explicit.exists());
    // The Vulkan manifest stays while the explicit OpenXR manifest uses it.
    assert!(sb.vk_manifest().exists(), "{}", r.out);
    assert!(r.out.contains("kept "), "{}", r.out);

    let r = sb.run(&["uninstall", "--implicit"], &[]);
    assert_eq!(r.code, 0, "{}{}", r.out, r.err);
    assert!(r.out.contains("nothing to remove"), "{}", r.out);

    let r = sb.run(&["uninstall"], &[]);
    assert_eq!(r.code, 0);
    assert!(!explicit.exists());
    assert!(!sb.vk_manifest().exists(), "{}", r.out);
    assert!(
        r.out
            .contains(&format!("removed {}", sb.vk_manifest().display())),
        "{}",
        r.out
    );
}

#[test]
fn install_refuses_a_missing_library() {
    let sb = Sandbox::new("missing");
    let missing = sb.dir.join("lib/nothing.so");
    let r = sb.run(
        &["install"],
        &[("FOVEA_LIBRARY", missing.to_str().unwrap())],
    );
    assert_eq!(r.code, 1);
    assert!(r.err.contains("nothing.so"), "{}", r.err);
    assert!(!sb.layers("explicit").exists());
    let r = sb.run(&["install"], &[("FOVEA_LIBRARY", sb.dir.to_str().unwrap())]);
    assert_eq!(r.code, 1);
    assert!(r.err.contains("not a file"), "{}", r.err);

    // Without the override: the library next to the binary, or an error that says how to build it.
    let exe = std::fs::canonicalize(env!("CARGO_BIN_EXE_fovea")).unwrap();
    let beside = exe.parent().unwrap().join("libfovea.so");
    let r = sb.run(&["install"], &[]);
    if beside.is_file() {
        assert_eq!(r.code, 0, "{}", r.err);
        let v = read(&sb.layers("explicit").join(FILE));
        assert_eq!(v, expected("explicit", &beside));
    } else {
        assert_eq!(r.code, 1);
        assert!(r.err.contains("cargo build --release"), "{}", r.err);
    }
}

#[test]
fn doctor_finds_an_explicit_fovea_and_enables_it_by_name() {
    let sb = Sandbox::new("doctor-explicit");
    let runtime = sb.runtime();
    sb.install(&["install"]);
    let path = sb.layers("explicit").join(FILE);

    let r = sb.doctor(&[("XR_RUNTIME_JSON", &runtime)]);
    assert_eq!(r.code, 0, "{}{}", r.out, r.err);
    assert!(
        r.out
            .contains(&format!("active runtime: {runtime} (XR_RUNTIME_JSON)")),
        "{}",
        r.out
    );
    assert!(r.out.contains("test runtime, library"), "{}", r.out);
    assert!(
        r.out.contains(&format!(
            "{}: {FOVEA}, library {}",
            path.display(),
            sb.library().display()
        )),
        "{}",
        r.out
    );
    assert!(r.out.contains("fovea: found, not enabled"), "{}", r.out);

    let r = sb.doctor(&[
        ("XR_RUNTIME_JSON", &runtime),
        ("XR_ENABLE_API_LAYERS", FOVEA),
    ]);
    assert_eq!(r.code, 0, "{}{}", r.out, r.err);
    assert!(r.problems().is_empty(), "{}", r.out);
    assert!(
        r.out.contains(&format!(
            "  1. {FOVEA} (XR_ENABLE_API_LAYERS) {}",
            path.display()
        )),
        "{}",
        r.out
    );
    assert!(r.out.contains("fovea: enabled, layer 1 of 1"), "{}", r.out);
}

#[test]
fn doctor_orders_implicit_layers_by_directory_and_reads_the_user_runtime() {
    let sb = Sandbox::new("doctor-implicit");
    sb.install(&["install", "--implicit"]);
    // Another implicit layer in XDG_DATA_DIRS, searched before XDG_DATA_HOME.
    let other = sb.system_layers("implicit");
    std::fs::create_dir_all(&other).unwrap();
    std::fs::write(
        other.join("other.json"),
        format!(
            r#"{{"file_format_version": "1.0.0", "api_layer": {{"name": "XR_APILAYER_TEST_other",
            "library_path": "{}", "api_version": "1.0", "implementation_version": "1",
            "disable_environment": "NO_OTHER"}}}}"#,
            sb.library().display()
        ),
    )
    .unwrap();
    // The active runtime from XDG_CONFIG_HOME.
    let config = sb.dir.join("config/openxr/1");
    std::fs::create_dir_all(&config).unwrap();
    std::fs::copy(sb.runtime(), config.join("active_runtime.json")).unwrap();

    let r = sb.doctor(&[]);
    assert_eq!(r.code, 0, "{}{}", r.out, r.err);
    assert!(
        r.out.contains(&format!(
            "active runtime: {} (XDG_CONFIG_HOME)",
            config.join("active_runtime.json").display()
        )),
        "{}",
        r.out
    );
    assert!(
        r.out.contains("  1. XR_APILAYER_TEST_other (implicit)"),
        "{}",
        r.out
    );
    assert!(
        r.out.contains(&format!("  2. {FOVEA} (implicit)")),
        "{}",
        r.out
    );
    assert!(r.out.contains("fovea: enabled, layer 2 of 2"), "{}", r.out);
}

#[test]
fn doctor_names_a_missing_library_and_a_library_that_is_not_a_file() {
    let sb = Sandbox::new("doctor-library");
    let runtime = sb.runtime();
    sb.install(&["install"]);
    let path = sb.layers("explicit").join(FILE);
    std::fs::remove_file(sb.library()).unwrap();
    std::fs::write(sb.dir.join("lib/runtime.so"), "").unwrap();
    let rt = std::fs::read_to_string(&runtime)
        .unwrap()
        .replace("libfovea.so", "runtime.so");
    std::fs::write(&runtime, rt).unwrap();
    let r = sb.doctor(&[("XR_RUNTIME_JSON", &runtime)]);
    assert_eq!(r.code, 1, "{}", r.out);
    // The OpenXR manifest's, and the Vulkan manifest's (same library).
    assert_eq!(r.problems().len(), 2, "{}", r.out);
    assert!(r
        .problem(VK_FILE)
        .contains("is not a file, so the loader cannot load the Vulkan layer"));
    let p = r.problem("does not exist");
    assert!(
        p.starts_with(&format!(
            "{}: fovea's library_path {} does not exist",
            path.display(),
            sb.library().display()
        )),
        "{p}"
    );
    assert_eq!(r.err.trim(), "fovea doctor: 2 problems");

    // A directory where the library should be: the loader accepts the manifest, dlopen fails.
    std::fs::create_dir(sb.library()).unwrap();
    let r = sb.doctor(&[("XR_RUNTIME_JSON", &runtime)]);
    assert_eq!(r.code, 1);
    assert!(r
        .problem("fovea's library_path")
        .ends_with("is not a file: loading the layer fails"));
}

#[test]
fn doctor_names_an_implicit_manifest_without_disable_environment() {
    let sb = Sandbox::new("doctor-no-disable");
    let runtime = sb.runtime();
    sb.install(&["install", "--implicit"]);
    let path = sb.layers("implicit").join(FILE);
    let mut v = read(&path);
    v["api_layer"]
        .as_object_mut()
        .unwrap()
        .remove("disable_environment");
    std::fs::write(&path, v.to_string()).unwrap();
    let r = sb.doctor(&[("XR_RUNTIME_JSON", &runtime)]);
    assert_eq!(r.code, 1);
    assert_eq!(r.problems().len(), 1, "{}", r.out);
    assert!(r
        .problem("without disable_environment")
        .contains("the loader rejects it"));
    assert!(r.out.contains("follow):\n  (none)"), "{}", r.out);
    assert!(r.out.contains("fovea: found, not enabled"), "{}", r.out);
}

#[test]
fn doctor_names_fovea_disabled_by_fovea_disable() {
    let sb = Sandbox::new("doctor-disabled");
    let runtime = sb.runtime();
    sb.install(&["install", "--implicit"]);
    // Set but empty still counts: the loader tests presence.
    let r = sb.doctor(&[("XR_RUNTIME_JSON", &runtime), ("FOVEA_DISABLE", "")]);
    assert_eq!(r.code, 1);
    assert_eq!(r.problems().len(), 1, "{}", r.out);
    assert!(r
        .problem("disabled")
        .ends_with("the implicit fovea layer is disabled because FOVEA_DISABLE is set"));
    assert!(r.out.contains("load order (next to the application first; layers the application names follow):\n  (none)"), "{}", r.out);
}

#[test]
fn doctor_names_fovea_listed_twice() {
    let sb = Sandbox::new("doctor-twice");
    let runtime = sb.runtime();
    sb.install(&["install", "--implicit"]);
    // The same implicit manifest in a system directory too: both load.
    let system = sb.system_layers("implicit");
    std::fs::create_dir_all(&system).unwrap();
    std::fs::copy(sb.layers("implicit").join(FILE), system.join(FILE)).unwrap();
    let r = sb.doctor(&[("XR_RUNTIME_JSON", &runtime)]);
    assert_eq!(r.code, 1);
    assert_eq!(r.problems().len(), 1, "{}", r.out);
    assert!(r
        .problem("stacked on itself")
        .starts_with("fovea would be loaded 2 times"));
    assert!(
        r.out.contains("fovea: enabled, layer 1 and 2 of 2"),
        "{}",
        r.out
    );

    // Implicit once, and explicit requested by name as well: one copy on 1.1 loaders, two before 1.0.30.
    std::fs::remove_file(system.join(FILE)).unwrap();
    sb.install(&["install"]);
    let r = sb.doctor(&[
        ("XR_RUNTIME_JSON", &runtime),
        ("XR_ENABLE_API_LAYERS", FOVEA),
    ]);
    assert_eq!(r.code, 1);
    assert_eq!(r.problems().len(), 1, "{}", r.out);
    assert!(r
        .problem("before 1.0.30")
        .contains("load it twice, stacked on itself"));
    assert!(r.out.contains("fovea: enabled, layer 1 of 1"), "{}", r.out);
}

#[test]
fn doctor_names_a_runtime_manifest_in_an_api_layer_path_directory() {
    let sb = Sandbox::new("doctor-runtime-in-layers");
    let runtime = sb.runtime();
    sb.install(&["install"]);
    let dir = sb.dir.join("layers");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(sb.layers("explicit").join(FILE), dir.join(FILE)).unwrap();
    std::fs::copy(&runtime, dir.join("runtime.json")).unwrap();
    let env = [
        ("XR_RUNTIME_JSON", runtime.as_str()),
        ("XR_ENABLE_API_LAYERS", FOVEA),
        ("XR_API_LAYER_PATH", dir.to_str().unwrap()),
    ];
    let r = sb.doctor(&env);
    assert_eq!(r.code, 1);
    assert_eq!(r.problems().len(), 1, "{}", r.out);
    assert!(r.problem("runtime manifest").starts_with(&format!(
        "{} is a runtime manifest in an XR_API_LAYER_PATH directory",
        dir.join("runtime.json").display()
    )));
    // XR_API_LAYER_PATH replaces the standard directories: only this copy is found.
    assert!(
        r.out
            .contains("XR_API_LAYER_PATH replaces the standard directories"),
        "{}",
        r.out
    );
    assert!(
        r.out.contains(&format!(
            "  1. {FOVEA} (XR_ENABLE_API_LAYERS) {}",
            dir.join(FILE).display()
        )),
        "{}",
        r.out
    );

    // The checked-in manifest directory, as the README uses it, holds no runtime manifest.
    let manifest_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../manifest");
    let r = sb.doctor(&[
        ("XR_RUNTIME_JSON", runtime.as_str()),
        ("XR_API_LAYER_PATH", manifest_dir.to_str().unwrap()),
    ]);
    assert!(
        r.problems().iter().all(|p| !p.contains("runtime manifest")),
        "{}",
        r.out
    );
}

#[test]
fn doctor_names_fovea_requested_but_not_found() {
    let sb = Sandbox::new("doctor-not-found");
    let runtime = sb.runtime();
    let r = sb.doctor(&[
        ("XR_RUNTIME_JSON", &runtime),
        ("XR_ENABLE_API_LAYERS", FOVEA),
    ]);
    assert_eq!(r.code, 1);
    assert_eq!(r.problems().len(), 1, "{}", r.out);
    assert!(r
        .problem("XR_ENABLE_API_LAYERS names")
        .contains("no usable manifest provides it: xrCreateInstance fails with XR_ERROR_API_LAYER_NOT_PRESENT"));
    assert!(r.out.contains("fovea: no manifest found"), "{}", r.out);

    // And with no runtime at all, that is named too.
    let r = sb.doctor(&[]);
    assert_eq!(r.code, 1);
    assert!(r
        .problem("no active runtime")
        .contains("XR_ERROR_RUNTIME_UNAVAILABLE"));
}

/// The lines of doctor's Vulkan layer section.
fn vk_section(r: &Run) -> String {
    let start = r
        .out
        .find("Vulkan layer VK_LAYER_FOVEA_fragment_density_map:\n")
        .unwrap_or_else(|| panic!("no Vulkan layer section:\n{}", r.out));
    let rest = &r.out[start..];
    rest[..rest.find("GPUs").unwrap_or(rest.len())].to_owned()
}

#[test]
fn install_writes_the_implicit_vulkan_manifest_and_the_last_uninstall_removes_it() {
    let sb = Sandbox::new("vulkan-install");
    let r = sb.install(&["install"]);
    let path = sb.vk_manifest();
    assert!(
        r.out.contains(&format!("wrote {}", path.display())),
        "{}",
        r.out
    );
    let v = read(&path);
    let l = &v["layer"];
    assert_eq!(l["name"], fovea_abi::VK_LAYER_NAME);
    // The OpenXR manifest's library: both layers in one loaded library.
    assert_eq!(Path::new(l["library_path"].as_str().unwrap()), sb.library());
    assert_eq!(
        l["enable_environment"],
        serde_json::json!({ fovea_abi::env::VK_LAYER: "1" })
    );
    assert_eq!(
        l["disable_environment"],
        serde_json::json!({ fovea_abi::env::DISABLE_VK_LAYER: "1" })
    );
    assert_eq!(
        l["device_extensions"],
        serde_json::json!([{
            "name": fovea_abi::VK_FDM_EXTENSION,
            "spec_version": fovea_abi::VK_FDM_SPEC_VERSION.to_string()
        }])
    );
    // The checked-in implicit manifest, library path replaced.
    let mut expected = read(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../manifest/vulkan/implicit")
            .join(VK_FILE),
    );
    expected["layer"]["library_path"] = sb.library().to_str().unwrap().into();
    assert_eq!(v, expected);
    // --implicit writes the same file again; uninstalling one kind keeps it for the other.
    let r = sb.install(&["install", "--implicit"]);
    assert!(
        r.out.contains(&format!("replaced {}", path.display())),
        "{}",
        r.out
    );
    let r = sb.run(&["uninstall"], &[]);
    assert!(path.exists(), "{}", r.out);
    let r = sb.run(&["uninstall", "--implicit"], &[]);
    assert_eq!(r.code, 0, "{}{}", r.out, r.err);
    assert!(!path.exists(), "{}", r.out);
}

#[test]
fn doctor_says_the_vulkan_layer_is_installed_and_would_load() {
    let sb = Sandbox::new("vulkan-installed");
    let runtime = sb.runtime();
    sb.install(&["install"]);
    let r = sb.doctor(&[("XR_RUNTIME_JSON", &runtime)]);
    assert_eq!(r.code, 0, "{}{}", r.out, r.err);
    assert!(r.problems().is_empty(), "{}", r.out);
    let section = vk_section(&r);
    assert!(
        section.contains(&format!(
            "  {}, library {}: implicit; loads into processes with FOVEA_VK_LAYER=1",
            sb.vk_manifest().display(),
            sb.library().display()
        )),
        "{section}"
    );

    // Switched off by the user: named, with the fix.
    let r = sb.doctor(&[
        ("XR_RUNTIME_JSON", &runtime),
        ("DISABLE_FOVEA_VK_LAYER", "1"),
    ]);
    assert_eq!(r.code, 1, "{}", r.out);
    assert_eq!(r.problems().len(), 1, "{}", r.out);
    assert!(r
        .problem(VK_FILE)
        .contains("disabled because DISABLE_FOVEA_VK_LAYER is set; unset it"));
    let r = sb.doctor(&[("XR_RUNTIME_JSON", &runtime), ("FOVEA_VK_LAYER", "0")]);
    assert_eq!(r.problems().len(), 1, "{}", r.out);
    assert!(r
        .problem(VK_FILE)
        .contains("FOVEA_VK_LAYER=0 keeps the implicit Vulkan layer out"));
}

#[test]
fn doctor_names_a_missing_vulkan_layer() {
    let sb = Sandbox::new("vulkan-missing");
    let runtime = sb.runtime();
    sb.install(&["install"]);
    std::fs::remove_file(sb.vk_manifest()).unwrap();
    let r = sb.doctor(&[("XR_RUNTIME_JSON", &runtime)]);
    assert_eq!(r.code, 1, "{}", r.out);
    assert_eq!(r.problems().len(), 1, "{}", r.out);
    assert!(r
        .problem("is not installed")
        .ends_with("`fovea install` writes its manifest"));
    assert!(
        vk_section(&r).contains("  (no manifest found)"),
        "{}",
        r.out
    );
    // Found through VK_ADD_LAYER_PATH (the checked-in explicit manifest's folder, pointed at a
    // build): explicit, and fine.
    let dir = sb.dir.join("vklayers");
    std::fs::create_dir_all(&dir).unwrap();
    let mut m = read(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../manifest/vulkan")
            .join(VK_FILE),
    );
    m["layer"]["library_path"] = sb.library().to_str().unwrap().into();
    std::fs::write(dir.join(VK_FILE), m.to_string()).unwrap();
    let r = sb.doctor(&[
        ("XR_RUNTIME_JSON", &runtime),
        ("VK_ADD_LAYER_PATH", dir.to_str().unwrap()),
    ]);
    assert_eq!(r.code, 0, "{}", r.out);
    assert!(
        vk_section(&r).contains(": explicit; fovea adds it"),
        "{}",
        r.out
    );
}

#[test]
fn doctor_names_a_vulkan_layer_with_a_broken_library_path() {
    let sb = Sandbox::new("vulkan-broken");
    let runtime = sb.runtime();
    sb.install(&["install"]);
    let mut v = read(&sb.vk_manifest());
    let gone = sb.dir.join("lib/gone.so");
    v["layer"]["library_path"] = gone.to_str().unwrap().into();
    std::fs::write(sb.vk_manifest(), v.to_string()).unwrap();
    let r = sb.doctor(&[("XR_RUNTIME_JSON", &runtime)]);
    assert_eq!(r.code, 1, "{}", r.out);
    assert_eq!(r.problems().len(), 1, "{}", r.out);
    assert!(r.problem(VK_FILE).contains(&format!(
        "its library_path {} is not a file, so the loader cannot load the Vulkan layer",
        gone.display()
    )));
    // A file that is no layer library: named too.
    std::fs::write(&gone, "not a library").unwrap();
    let r = sb.doctor(&[("XR_RUNTIME_JSON", &runtime)]);
    assert_eq!(r.problems().len(), 1, "{}", r.out);
    assert!(r
        .problem(VK_FILE)
        .contains("cannot serve as the Vulkan layer"));
    // Without disable_environment the loader rejects an implicit manifest.
    v["layer"]["library_path"] = sb.library().to_str().unwrap().into();
    v["layer"]
        .as_object_mut()
        .unwrap()
        .remove("disable_environment");
    std::fs::write(sb.vk_manifest(), v.to_string()).unwrap();
    let r = sb.doctor(&[("XR_RUNTIME_JSON", &runtime)]);
    assert_eq!(r.problems().len(), 1, "{}", r.out);
    assert!(r
        .problem(VK_FILE)
        .contains("without disable_environment: the loader rejects it"));
}

/// Lavapipe's ICD manifest, for `VK_ICD_FILENAMES` (the sandbox hides the system's data folders).
fn lavapipe_icd() -> Option<PathBuf> {
    let found = std::fs::read_dir("/usr/share/vulkan/icd.d")
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("lvp_icd"))
        });
    if found.is_none() {
        fovea_harness::skip("lavapipe (mesa-vulkan-drivers) is not installed");
    }
    found
}

#[test]
fn doctor_says_lavapipe_has_no_density_maps() {
    let Some(icd) = lavapipe_icd() else { return };
    let sb = Sandbox::new("vulkan-lavapipe");
    let runtime = sb.runtime();
    sb.install(&["install"]);
    let r = sb.doctor(&[
        ("XR_RUNTIME_JSON", &runtime),
        ("VK_ICD_FILENAMES", icd.to_str().unwrap()),
    ]);
    assert_eq!(r.code, 0, "{}{}", r.out, r.err);
    let gpu = r
        .out
        .lines()
        .find(|l| l.contains("llvmpipe"))
        .unwrap_or_else(|| panic!("no lavapipe line:\n{}", r.out));
    assert!(gpu.contains("fragment density maps unavailable"), "{gpu}");
}

#[test]
fn doctor_says_a_shading_rate_gpu_gets_them_emulated() {
    let Some(icd) = lavapipe_icd() else { return };
    let double = match fovea_vkdouble::find_library()
        .or_else(|_| fovea_harness::artifact(fovea_vkdouble::LIBRARY_FILE))
    {
        Ok(l) => l,
        Err(e) => {
            fovea_harness::skip(&e);
            return;
        }
    };
    let sb = Sandbox::new("vulkan-double");
    let runtime = sb.runtime();
    sb.install(&["install"]);
    let dir = sb.dir.join("double");
    fovea_vkdouble::write_manifest(&dir, &double).unwrap();
    let double_name = fovea_vkdouble::LAYER_NAME.to_str().unwrap();
    let env = |profile| {
        sb.doctor(&[
            ("XR_RUNTIME_JSON", &runtime),
            ("VK_ICD_FILENAMES", icd.to_str().unwrap()),
            ("VK_ADD_LAYER_PATH", dir.to_str().unwrap()),
            ("VK_INSTANCE_LAYERS", double_name),
            (fovea_vkdouble::PROFILE_ENV, profile),
        ])
    };
    let r = env("nvidia");
    assert_eq!(r.code, 0, "{}{}", r.out, r.err);
    let gpu = r.out.lines().find(|l| l.contains("llvmpipe")).unwrap();
    assert!(
        gpu.ends_with("emulated by VK_LAYER_FOVEA_fragment_density_map on shading-rate attachments: texel 16×16, layered, up to 4×4"),
        "{gpu}"
    );
    let r = env("amd");
    let gpu = r.out.lines().find(|l| l.contains("llvmpipe")).unwrap();
    assert!(
        gpu.ends_with("texel 8×8, one layer for both eyes, up to 2×2"),
        "{gpu}"
    );
    // The layer missing where a GPU needs it: a problem with the fix.
    std::fs::remove_file(sb.vk_manifest()).unwrap();
    let r = env("nvidia");
    assert_eq!(r.code, 1, "{}", r.out);
    assert_eq!(r.problems().len(), 2, "{}", r.out);
    assert!(r
        .problem("needs fovea's Vulkan layer")
        .starts_with("llvmpipe"));
}

#[test]
fn doctor_says_whether_the_runtime_has_eye_gaze() {
    let sb = Sandbox::new("doctor-gaze");
    let sim = fovea_harness::artifact("libfovea_sim.so").expect("libfovea_sim.so: cargo build");
    let manifest = sb.dir.join("sim.json");
    std::fs::write(
        &manifest,
        format!(
            r#"{{"file_format_version": "1.0.0", "runtime": {{"name": "sim", "library_path": "{}"}}}}"#,
            sim.display()
        ),
    )
    .unwrap();
    let manifest = manifest.to_str().unwrap();
    for (tracker, want) in [
        (
            None,
            "eye gaze: the runtime does not offer XR_EXT_eye_gaze_interaction",
        ),
        (Some("unsupported"), "the system reports no eye tracker"),
        (Some("on"), "and the system has an eye tracker"),
    ] {
        let mut env = vec![("XR_RUNTIME_JSON", manifest)];
        env.extend(tracker.map(|t| ("FOVEA_SIM_EYE_GAZE", t)));
        let r = sb.doctor(&env);
        assert!(r.out.contains(want), "{tracker:?}: {}{}", r.out, r.err);
    }
    // A runtime manifest naming a library that is no runtime: said, and not a problem.
    let r = sb.doctor(&[("XR_RUNTIME_JSON", &sb.runtime())]);
    assert!(
        r.out.contains("eye gaze: cannot ask the runtime") && !r.out.contains("problem: eye"),
        "{}",
        r.out
    );
}
