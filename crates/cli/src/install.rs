//! `fovea install [--implicit] [--system]` / `fovea uninstall [--implicit] [--system]`: write or
//! remove a layer manifest where the loader looks (openxr-layer-facts.md §2.7), pointing at this
//! build's `libfovea.so` by absolute path, so the manifest works from any directory.
//!
//! The manifest is the checked-in one with `library_path` replaced, so the extension list has one
//! source (tests/manifests.rs checks it against the layer's table).

use std::path::{Path, PathBuf};

use crate::args::Args;
use crate::doctor::{data_home, Kind, MANIFEST_FILE};

const EXPLICIT_MANIFEST: &str = include_str!("../../../manifest/XR_APILAYER_FOVEA_foveation.json");
const IMPLICIT_MANIFEST: &str =
    include_str!("../../../manifest/implicit/XR_APILAYER_FOVEA_foveation.json");

/// Overrides where the library is looked for: `cargo test` runs a `fovea` binary with no
/// `libfovea.so` beside it that is guaranteed fresh, and packagers may install the two apart.
pub const LIBRARY_ENV: &str = "FOVEA_LIBRARY";

/// `--system` writes here: `/usr/local/share` is in the loader's default `XDG_DATA_DIRS`, and it is
/// the place for files no package manager owns.
const SYSTEM_DATA_DIR: &str = "/usr/local/share";

fn kind(args: &Args) -> Kind {
    if args.switch("implicit") {
        Kind::Implicit
    } else {
        Kind::Explicit
    }
}

/// Where the manifest goes: `$XDG_DATA_HOME` (default `~/.local/share`), or `/usr/local/share`
/// with `--system`, then `openxr/1/api_layers/{explicit,implicit}.d/XR_APILAYER_FOVEA_foveation.json`.
pub fn manifest_path(
    kind: Kind,
    system: bool,
    get: impl Fn(&str) -> Option<String>,
) -> Result<PathBuf, String> {
    let base = if system {
        PathBuf::from(SYSTEM_DATA_DIR)
    } else {
        data_home(get).ok_or("neither XDG_DATA_HOME nor HOME is set")?
    };
    Ok(base.join(kind.relative_dir()).join(MANIFEST_FILE))
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

/// `template` with its `"library_path"` string replaced by `library`, JSON-escaped. Textual, so the
/// file keeps the checked-in layout.
pub fn with_library_path(template: &str, library: &str) -> Result<String, String> {
    const KEY: &str = "\"library_path\"";
    let at = template
        .find(KEY)
        .ok_or("no library_path in the manifest")?;
    if template[at + KEY.len()..].contains(KEY) {
        return Err("library_path appears twice in the manifest".into());
    }
    let after_key = at + KEY.len();
    let open = after_key
        + template[after_key..]
            .find('"')
            .ok_or("library_path has no string value")?;
    // The checked-in value is a plain path, but skip escapes anyway.
    let mut close = None;
    let mut escaped = false;
    for (i, c) in template[open + 1..].char_indices() {
        match (escaped, c) {
            (false, '\\') => escaped = true,
            (false, '"') => {
                close = Some(open + 1 + i);
                break;
            }
            _ => escaped = false,
        }
    }
    let close = close.ok_or("library_path's string is not closed")?;
    let value = serde_json::to_string(library).map_err(|e| e.to_string())?;
    Ok(format!(
        "{}{value}{}",
        &template[..open],
        &template[close + 1..]
    ))
}

/// The manifest text for `kind` with `library` as its absolute library path.
pub fn manifest_text(kind: Kind, library: &Path) -> Result<String, String> {
    let template = match kind {
        Kind::Explicit => EXPLICIT_MANIFEST,
        Kind::Implicit => IMPLICIT_MANIFEST,
    };
    // JSON strings are Unicode; a path that is not cannot be written into one.
    let library = library
        .to_str()
        .ok_or_else(|| format!("{} is not valid UTF-8", library.display()))?;
    with_library_path(template, library)
}

fn env(k: &str) -> Option<String> {
    std::env::var(k).ok()
}

fn io_error(what: &str, path: &Path, e: std::io::Error) -> String {
    let hint = if e.kind() == std::io::ErrorKind::PermissionDenied {
        " (--system needs root)"
    } else {
        ""
    };
    format!("{what} {}: {e}{hint}", path.display())
}

pub fn install(args: &Args) -> Result<(), String> {
    let kind = kind(args);
    let system = args.switch("system");
    let path = manifest_path(kind, system, env)?;
    let library = library()?;
    let text = manifest_text(kind, &library)?;
    let dir = path.parent().expect("manifest path has a directory");
    std::fs::create_dir_all(dir).map_err(|e| io_error("cannot create", dir, e))?;
    let replaced = path.exists();
    std::fs::write(&path, text).map_err(|e| io_error("cannot write", &path, e))?;
    println!(
        "{} {}",
        if replaced { "replaced" } else { "wrote" },
        path.display()
    );
    println!("  library_path: {}", library.display());
    match kind {
        Kind::Explicit => {
            println!(
                "  explicit layer: enable it with XR_ENABLE_API_LAYERS={}",
                fovea_abi::LAYER_NAME
            );
            // The override hides the standard directories this file went to.
            if env("XR_API_LAYER_PATH").is_some_and(|v| !v.is_empty()) {
                println!(
                    "note: XR_API_LAYER_PATH is set, so the loader will not look here while it is"
                );
            }
        }
        Kind::Implicit => println!(
            "  implicit layer: every OpenXR application loads it; FOVEA_DISABLE=1 switches it off"
        ),
    }
    if system {
        if let Some(dirs) = env("XDG_DATA_DIRS").filter(|v| !v.is_empty()) {
            if !dirs
                .split(':')
                .any(|d| Path::new(d) == Path::new(SYSTEM_DATA_DIR))
            {
                println!("note: XDG_DATA_DIRS is set without {SYSTEM_DATA_DIR}, so the loader will not look here while it is");
            }
        }
    }
    let other = match kind {
        Kind::Explicit => Kind::Implicit,
        Kind::Implicit => Kind::Explicit,
    };
    let other_path = manifest_path(other, system, env)?;
    if other_path.exists() {
        println!(
            "note: {} is installed too; `fovea doctor` shows whether fovea would load twice",
            other_path.display()
        );
    }
    Ok(())
}

pub fn uninstall(args: &Args) -> Result<(), String> {
    let path = manifest_path(kind(args), args.switch("system"), env)?;
    match std::fs::remove_file(&path) {
        Ok(()) => {
            println!("removed {}", path.display());
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            println!("nothing to remove: {} does not exist", path.display());
            Ok(())
        }
        Err(e) => Err(io_error("cannot remove", &path, e)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_per_kind_and_location() {
        let home = |k: &str| (k == "HOME").then(|| "/home/u".to_owned());
        assert_eq!(
            manifest_path(Kind::Explicit, false, home).unwrap(),
            Path::new(
                "/home/u/.local/share/openxr/1/api_layers/explicit.d/XR_APILAYER_FOVEA_foveation.json"
            )
        );
        let xdg = |k: &str| match k {
            "HOME" => Some("/home/u".to_owned()),
            "XDG_DATA_HOME" => Some("/data".to_owned()),
            _ => None,
        };
        assert_eq!(
            manifest_path(Kind::Implicit, false, xdg).unwrap(),
            Path::new("/data/openxr/1/api_layers/implicit.d/XR_APILAYER_FOVEA_foveation.json")
        );
        assert_eq!(
            manifest_path(Kind::Implicit, true, xdg).unwrap(),
            Path::new(
                "/usr/local/share/openxr/1/api_layers/implicit.d/XR_APILAYER_FOVEA_foveation.json"
            )
        );
        assert!(manifest_path(Kind::Explicit, false, |_| None).is_err());
    }

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
        assert!(with_library_path(r#"{"name": "x"}"#, "/l").is_err());
        assert!(with_library_path(r#"{"library_path": "a", "library_path": "b"}"#, "/l").is_err());
    }
}
