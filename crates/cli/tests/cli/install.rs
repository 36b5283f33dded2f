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
        // A stand-in for libfovea.so: install and doctor only check that it is a file.
        std::fs::write(dir.join("lib/libfovea.so"), "").unwrap();
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
    assert_eq!(r.out.trim(), format!("removed {}", implicit.display()));
    assert!(!implicit.exists() && neighbour.exists() && explicit.exists());

    let r = sb.run(&["uninstall", "--implicit"], &[]);
    assert_eq!(r.code, 0, "{}{}", r.out, r.err);
    assert!(r.out.contains("nothing to remove"), "{}", r.out);

    let r = sb.run(&["uninstall"], &[]);
    assert_eq!(r.code, 0);
    assert!(!explicit.exists());
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
    assert_eq!(r.problems().len(), 1, "{}", r.out);
    let p = r.problem("does not exist");
    assert!(
        p.starts_with(&format!(
            "{}: fovea's library_path {} does not exist",
            path.display(),
            sb.library().display()
        )),
        "{p}"
    );
    assert_eq!(r.err.trim(), "fovea doctor: 1 problem");

    // A directory where the library should be: the loader accepts the manifest, dlopen fails.
    std::fs::create_dir(sb.library()).unwrap();
    let r = sb.doctor(&[("XR_RUNTIME_JSON", &runtime)]);
    assert_eq!(r.code, 1);
    assert!(r
        .problem("library_path")
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
