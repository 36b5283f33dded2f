//! `fovea install [--implicit] [--system]` / `fovea uninstall [--implicit] [--system]`: write or
//! remove a layer manifest where the loader looks ([`crate::discovery`]), pointing at this build's
//! `libfovea.so` by absolute path, so the manifest works from any directory.
//!
//! Install writes the Vulkan layer's manifest too, always implicit, into the Vulkan loader's folder
//! (`$XDG_DATA_HOME/vulkan/implicit_layer.d`, or `/usr/local/share/vulkan/implicit_layer.d` with
//! `--system`), with the same library path: it loads only where `FOVEA_VK_LAYER=1`, which fovea's
//! OpenXR layer sets for OpenXR applications that use Vulkan (docs/vulkan-layer.md).
//!
//! Each manifest is the checked-in one with `library_path` replaced, so the extension list has one
//! source (tests/manifests.rs checks it against the layer's table).

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::args::InstallArgs;
use crate::discovery::{
    install_path, layer_dirs, process_vars, standard_layer_dirs, vk_install_path, vk_layer_dirs,
    Environment, Kind, LAYER_PATH_VAR, SYSTEM_DATA_DIR,
};

const EXPLICIT_MANIFEST: &str = include_str!("../../../manifest/XR_APILAYER_FOVEA_foveation.json");
const IMPLICIT_MANIFEST: &str =
    include_str!("../../../manifest/implicit/XR_APILAYER_FOVEA_foveation.json");
const VK_EXPLICIT_MANIFEST: &str =
    include_str!("../../../manifest/vulkan/VK_LAYER_FOVEA_fragment_density_map.json");
const VK_IMPLICIT_MANIFEST: &str =
    include_str!("../../../manifest/vulkan/implicit/VK_LAYER_FOVEA_fragment_density_map.json");

/// Overrides where the library is looked for: `cargo test` runs a `fovea` binary with no
/// `libfovea.so` beside it that is guaranteed fresh, and packagers may install the two apart.
pub const LIBRARY_ENV: &str = "FOVEA_LIBRARY";

fn kind(args: &InstallArgs) -> Kind {
    if args.implicit {
        Kind::Implicit
    } else {
        Kind::Explicit
    }
}

/// The layer library: `$FOVEA_LIBRARY`, else `libfovea.so` next to the running `fovea`; absolute
/// and canonical, since the loader resolves a relative `library_path` against the manifest's
/// directory.
fn library() -> Result<PathBuf, String> {
    let (path, origin) = match std::env::var_os(LIBRARY_ENV) {
        Some(p) => (PathBuf::from(p), format!("{LIBRARY_ENV} names")),
        None => {
            let exe = std::env::current_exe().map_err(|e| format!("current executable: {e}"))?;
            let exe = std::fs::canonicalize(&exe).unwrap_or(exe);
            let dir = exe.parent().ok_or("the executable has no directory")?;
            (dir.join("libfovea.so"), "expected".to_owned())
        }
    };
    match std::fs::canonicalize(&path) {
        Ok(p) if p.is_file() => Ok(p),
        Ok(_) => Err(format!("{origin} {}, which is not a file", path.display())),
        Err(_) if origin == "expected" => Err(format!(
            "no libfovea.so next to this fovea ({}): run `cargo build --release` and use \
             target/release/fovea, or set {LIBRARY_ENV}=/path/to/libfovea.so",
            path.display()
        )),
        Err(e) => Err(format!("{origin} {}: {e}", path.display())),
    }
}

/// `template` with `<layer>.library_path` set to `library` (`layer`: `api_layer` in OpenXR
/// manifests, `layer` in Vulkan ones). Edited as a JSON value, so escaping is serde_json's; written
/// with the template's key order and two-space indent, so the installed file reads like the
/// checked-in one.
pub fn with_library_path(template: &str, layer: &str, library: &str) -> Result<String, String> {
    let mut v: Value =
        serde_json::from_str(template).map_err(|e| format!("the manifest is not JSON: {e}"))?;
    let slot = v
        .get_mut(layer)
        .and_then(|l| l.get_mut("library_path"))
        .filter(|p| p.is_string())
        .ok_or_else(|| format!("no {layer}.library_path string in the manifest"))?;
    *slot = Value::from(library);
    let mut text = serde_json::to_string_pretty(&v).map_err(|e| e.to_string())?;
    text.push('\n');
    Ok(text)
}

/// The manifest text for `kind` with `library` as its absolute library path.
pub fn manifest_text(kind: Kind, library: &Path) -> Result<String, String> {
    let template = match kind {
        Kind::Explicit => EXPLICIT_MANIFEST,
        Kind::Implicit => IMPLICIT_MANIFEST,
    };
    with_library_path(template, "api_layer", utf8(library)?)
}

/// JSON strings are Unicode; a path that is not cannot be written into one.
fn utf8(library: &Path) -> Result<&str, String> {
    library
        .to_str()
        .ok_or_else(|| format!("{} is not valid UTF-8", library.display()))
}

/// The Vulkan layer's implicit manifest with `library` as its absolute library path.
pub fn vk_manifest_text(library: &Path) -> Result<String, String> {
    with_library_path(VK_IMPLICIT_MANIFEST, "layer", utf8(library)?)
}

/// The Vulkan layer's explicit manifest (the checked-in one) with `library` as its absolute library
/// path, for a folder named by `VK_ADD_LAYER_PATH`.
pub fn vk_explicit_manifest_text(library: &Path) -> Result<String, String> {
    with_library_path(VK_EXPLICIT_MANIFEST, "layer", utf8(library)?)
}

/// Writes `text` to `path`, creating its folder; whether a file was replaced.
fn write_file(path: &Path, text: &str) -> Result<bool, String> {
    let dir = path.parent().expect("manifest path has a directory");
    std::fs::create_dir_all(dir).map_err(|e| io_error("cannot create", dir, e))?;
    let replaced = path.exists();
    std::fs::write(path, text).map_err(|e| io_error("cannot write", path, e))?;
    Ok(replaced)
}

fn wrote(replaced: bool, path: &Path) {
    println!(
        "{} {}",
        if replaced { "replaced" } else { "wrote" },
        path.display()
    );
}

fn io_error(what: &str, path: &Path, e: std::io::Error) -> String {
    let hint = if e.kind() == std::io::ErrorKind::PermissionDenied {
        " (--system needs root)"
    } else {
        ""
    };
    format!("{what} {}: {e}{hint}", path.display())
}

pub fn install(args: &InstallArgs) -> Result<(), String> {
    let kind = kind(args);
    let vars = process_vars();
    let env = Environment {
        vars: &vars,
        root: Path::new("/"),
    };
    let path = install_path(&env, kind, args.system)?;
    let library = library()?;
    let text = manifest_text(kind, &library)?;
    let vk_path = vk_install_path(&env, args.system)?;
    let vk_text = vk_manifest_text(&library)?;
    wrote(write_file(&path, &text)?, &path);
    println!("  library_path: {}", library.display());
    match kind {
        Kind::Explicit => println!(
            "  explicit layer: enable it with XR_ENABLE_API_LAYERS={}",
            fovea_abi::LAYER_NAME
        ),
        Kind::Implicit => println!(
            "  implicit layer: every OpenXR application loads it; FOVEA_DISABLE=1 switches it off"
        ),
    }
    for note in search_notes(&env, kind, &path) {
        println!("note: {note}");
    }
    wrote(write_file(&vk_path, &vk_text)?, &vk_path);
    println!(
        "  Vulkan layer {}, implicit: loads where {}=1, which fovea sets for OpenXR applications \
         that use Vulkan; {}=1 switches it off",
        fovea_abi::VK_LAYER_NAME,
        fovea_abi::env::VK_LAYER,
        fovea_abi::env::DISABLE_VK_LAYER
    );
    if !vk_layer_dirs(&env, Kind::Implicit)
        .iter()
        .any(|d| Some(d.as_path()) == vk_path.parent())
    {
        println!(
            "note: VK_IMPLICIT_LAYER_PATH or XDG_DATA_DIRS is set so that the Vulkan loader will not \
             look there while it is"
        );
    }
    let other_path = install_path(&env, kind.other(), args.system)?;
    if other_path.exists() {
        println!(
            "note: {} is installed too; `fovea doctor` shows whether fovea would load twice",
            other_path.display()
        );
    }
    Ok(())
}

/// Why the loader, in this environment, would not look where `path` is: the search model says
/// whether it is among the directories searched, and these name the variable that moved them.
fn search_notes(env: &Environment, kind: Kind, path: &Path) -> Vec<String> {
    let mut notes = Vec::new();
    // The override hides the standard directories this file went to.
    if layer_dirs(env, kind).1 {
        notes.push(format!(
            "{LAYER_PATH_VAR} is set, so the loader will not look here while it is"
        ));
    }
    let searched = standard_layer_dirs(env, kind)
        .iter()
        .any(|d| Some(d.as_path()) == path.parent());
    if !searched {
        notes.push(format!(
            "XDG_DATA_DIRS is set without {SYSTEM_DATA_DIR}, so the loader will not look here while it is"
        ));
    }
    notes
}

pub fn uninstall(args: &InstallArgs) -> Result<(), String> {
    let vars = process_vars();
    let env = Environment {
        vars: &vars,
        root: Path::new("/"),
    };
    let kind = kind(args);
    let path = install_path(&env, kind, args.system)?;
    remove(&path)?;
    // The Vulkan manifest serves both OpenXR manifests of this scope: it goes with the last.
    let other = install_path(&env, kind.other(), args.system)?;
    let vk_path = vk_install_path(&env, args.system)?;
    if other.exists() {
        if vk_path.exists() {
            println!(
                "kept {} for {}; `fovea uninstall{}` removes both",
                vk_path.display(),
                other.display(),
                if kind == Kind::Explicit {
                    " --implicit"
                } else {
                    ""
                }
            );
        }
        return Ok(());
    }
    remove(&vk_path)
}

fn remove(path: &Path) -> Result<(), String> {
    match std::fs::remove_file(path) {
        Ok(()) => {
            println!("removed {}", path.display());
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            println!("nothing to remove: {} does not exist", path.display());
            Ok(())
        }
        Err(e) => Err(io_error("cannot remove", path, e)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn library_path_is_replaced_and_escaped() {
        let odd = r#"/opt/a "quoted" \dir/libfovea.so"#;
        for kind in [Kind::Explicit, Kind::Implicit] {
            let text = manifest_text(kind, Path::new(odd)).unwrap();
            let v: serde_json::Value = serde_json::from_str(&text).unwrap();
            assert_eq!(v["api_layer"]["library_path"], odd);
            assert_eq!(v["api_layer"]["name"], fovea_abi::LAYER_NAME);
            assert_eq!(
                v["api_layer"]["instance_extensions"]
                    .as_array()
                    .unwrap()
                    .len(),
                fovea_abi::EXTENSIONS.len()
            );
            assert_eq!(
                v["api_layer"]["disable_environment"].as_str(),
                (kind == Kind::Implicit).then_some("FOVEA_DISABLE")
            );
        }
        let l = "api_layer";
        assert!(with_library_path(r#"{"api_layer": {"name": "x"}}"#, l, "/l").is_err());
        // Only the layer's own library_path, never a key of that name elsewhere.
        assert!(with_library_path(r#"{"library_path": "a"}"#, l, "/l").is_err());
        assert!(with_library_path("not json", l, "/l").is_err());
        let vk: serde_json::Value =
            serde_json::from_str(&vk_manifest_text(Path::new(odd)).unwrap()).unwrap();
        assert_eq!(vk["layer"]["library_path"], odd);
        assert_eq!(vk["layer"]["name"], fovea_abi::VK_LAYER_NAME);
        assert_eq!(
            vk["layer"]["enable_environment"][fovea_abi::env::VK_LAYER],
            "1"
        );
        assert_eq!(
            vk["layer"]["disable_environment"][fovea_abi::env::DISABLE_VK_LAYER],
            "1"
        );
        assert_eq!(
            vk["layer"]["device_extensions"][0]["name"],
            fovea_abi::VK_FDM_EXTENSION
        );
    }

    #[test]
    fn notes_say_when_the_loader_would_not_look_there() {
        let vars = |pairs: &[(&str, &str)]| -> std::collections::BTreeMap<String, String> {
            pairs
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect()
        };
        let notes = |pairs: &[(&str, &str)], kind, system| {
            let v = vars(pairs);
            let env = Environment {
                vars: &v,
                root: Path::new("/"),
            };
            let path = install_path(&env, kind, system).unwrap();
            search_notes(&env, kind, &path)
        };
        let home = ("HOME", "/home/u");
        assert!(notes(&[home], Kind::Explicit, false).is_empty());
        assert!(notes(&[home], Kind::Implicit, true).is_empty());
        let layer_path = [home, ("XR_API_LAYER_PATH", "/x")];
        assert_eq!(
            notes(&layer_path, Kind::Explicit, false),
            ["XR_API_LAYER_PATH is set, so the loader will not look here while it is"]
        );
        assert!(notes(&layer_path, Kind::Implicit, false).is_empty());
        let data_dirs = [home, ("XDG_DATA_DIRS", "/usr/share")];
        assert!(notes(&data_dirs, Kind::Explicit, false).is_empty());
        assert_eq!(
            notes(&data_dirs, Kind::Implicit, true),
            ["XDG_DATA_DIRS is set without /usr/local/share, so the loader will not look here while it is"]
        );
        let with_it = [home, ("XDG_DATA_DIRS", "/usr/share:/usr/local/share/")];
        assert!(notes(&with_it, Kind::Implicit, true).is_empty());
    }

    #[test]
    fn the_installed_file_keeps_the_checked_in_layout() {
        // Only the library path differs from the checked-in file, line for line.
        let text = manifest_text(Kind::Explicit, Path::new("/opt/libfovea.so")).unwrap();
        let old: Vec<&str> = EXPLICIT_MANIFEST.lines().collect();
        let new: Vec<&str> = text.lines().collect();
        assert_eq!(old.len(), new.len(), "{text}");
        let differing: Vec<(&str, &str)> = old
            .iter()
            .zip(&new)
            .filter(|(a, b)| a != b)
            .map(|(a, b)| (*a, *b))
            .collect();
        assert_eq!(
            differing,
            [(
                r#"    "library_path": "../target/release/libfovea.so","#,
                r#"    "library_path": "/opt/libfovea.so","#
            )]
        );
    }
}
