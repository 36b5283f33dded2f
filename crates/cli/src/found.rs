//! What the OpenXR loader would find on Linux: the active runtime, each layer manifest and what the
//! loader makes of it, and the order it loads layers in. `fovea doctor` reports it
//! ([`crate::doctor`], [`crate::doctor_settings`]).
//!
//! Where the loader looks is [`crate::discovery`], shared with `fovea install`; what it makes of
//! each file and in which order it loads layers follows its `api_layer_interface.cpp` (1.1.x;
//! <https://registry.khronos.org/OpenXR/specs/1.0/loader.html>). [`discover`] takes the environment
//! and the filesystem root as arguments, so tests drive it without the real home directory or
//! `/etc`.

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::discovery::{
    layer_dirs, runtime_candidates, Environment, Kind, MANIFEST_FILE, RUNTIME_JSON_VAR,
};

/// The active runtime, as far as the loader's discovery goes.
#[derive(Debug)]
pub struct Runtime {
    pub manifest: PathBuf,
    /// What chose it: `XR_RUNTIME_JSON`, `XDG_CONFIG_HOME`, ...
    pub source: &'static str,
    /// Its name and library, or why the loader cannot use it.
    pub read: Result<(String, PathBuf), String>,
}

fn read_json(path: &Path) -> Result<Value, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("cannot read it: {e}"))?;
    let v: Value = serde_json::from_str(&text).map_err(|e| format!("not valid JSON: {e}"))?;
    if !v.is_object() {
        return Err("not a JSON object".into());
    }
    if v["file_format_version"] != "1.0.0" {
        return Err("file_format_version is not the string \"1.0.0\"".into());
    }
    Ok(v)
}

/// A manifest's `library_path` as the loader resolves it: a bare file name goes to the dynamic
/// linker's search path (returned as is), anything else is absolute or relative to the manifest.
fn resolve_library(manifest: &Path, library: &str) -> PathBuf {
    let p = Path::new(library);
    if !library.contains('/') || p.is_absolute() {
        return p.to_path_buf();
    }
    let dir = manifest.parent().unwrap_or(Path::new("."));
    // Relative to the real manifest file, not to a symlink to it.
    let dir = std::fs::canonicalize(manifest)
        .ok()
        .and_then(|m| m.parent().map(Path::to_path_buf))
        .unwrap_or_else(|| dir.to_path_buf());
    dir.join(p)
}

fn find_runtime(env: &Environment) -> Option<Runtime> {
    let (manifest, source) = runtime_candidates(env).into_iter().find(|(p, why)| {
        // XR_RUNTIME_JSON is used whether or not the file exists.
        *why == RUNTIME_JSON_VAR || p.exists()
    })?;
    let read = read_json(&manifest).and_then(|v| {
        let rt = &v["runtime"];
        let library = rt["library_path"]
            .as_str()
            .ok_or("no \"runtime\" object with a string library_path")?;
        let name = rt["name"].as_str().unwrap_or("(no name)").to_owned();
        Ok((name, resolve_library(&manifest, library)))
    });
    Some(Runtime {
        manifest,
        source,
        read,
    })
}

/// One `*.json` file in a layer directory.
#[derive(Clone, Debug)]
pub struct Manifest {
    pub path: PathBuf,
    pub kind: Kind,
    /// The layer name, when the file has one.
    pub name: Option<String>,
    /// `library_path`, resolved.
    pub library: Option<PathBuf>,
    pub disable_environment: Option<String>,
    /// The file holds a runtime manifest, not a layer manifest.
    pub runtime_manifest: bool,
    /// `Ok` when the loader would use it; otherwise why it skips it.
    pub verdict: Result<(), Skip>,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Skip {
    /// An implicit layer switched off by the environment: the reason.
    Disabled(String),
    /// The loader rejects the file: the reason.
    Invalid(String),
}

impl Manifest {
    pub fn is_fovea(&self) -> bool {
        match &self.name {
            Some(n) => n == fovea_abi::LAYER_NAME,
            None => self.path.file_name().is_some_and(|f| f == MANIFEST_FILE),
        }
    }

    pub fn usable(&self) -> bool {
        self.verdict.is_ok()
    }
}

/// Reads one layer manifest the way the loader's `ApiLayerManifestFile::CreateIfValid` does.
pub fn read_layer(path: &Path, kind: Kind, env: &Environment) -> Manifest {
    let mut m = Manifest {
        path: path.to_path_buf(),
        kind,
        name: None,
        library: None,
        disable_environment: None,
        runtime_manifest: false,
        verdict: Ok(()),
    };
    let invalid = |why: &str| Err(Skip::Invalid(why.to_owned()));
    let v = match read_json(path) {
        Ok(v) => v,
        Err(e) => {
            m.verdict = invalid(&e);
            return m;
        }
    };
    let l = &v["api_layer"];
    m.runtime_manifest = l.is_null() && v["runtime"].is_object();
    m.name = l["name"].as_str().map(String::from);
    m.library = l["library_path"]
        .as_str()
        .map(|lib| resolve_library(path, lib));
    m.disable_environment = l["disable_environment"].as_str().map(String::from);
    if m.runtime_manifest {
        m.verdict = invalid("a runtime manifest, not a layer manifest");
        return m;
    }
    // Required fields must be strings: the loader drops numbers as "missing required fields".
    let required = [
        "name",
        "library_path",
        "api_version",
        "implementation_version",
    ];
    if let Some(k) = required.iter().find(|k| !l[**k].is_string()) {
        m.verdict = invalid(&format!("missing required field {k} (a string)"));
        return m;
    }
    if kind == Kind::Implicit {
        let Some(disable) = &m.disable_environment else {
            m.verdict = invalid("implicit layer without disable_environment");
            return m;
        };
        // disable wins over enable; "set" means present, even empty.
        if env.is_set(disable) {
            m.verdict = Err(Skip::Disabled(format!("{disable} is set")));
            return m;
        }
        if let Some(enable) = l["enable_environment"].as_str() {
            if !env.is_set(enable) {
                m.verdict = Err(Skip::Disabled(format!("{enable} is not set")));
                return m;
            }
        }
    }
    let api = l["api_version"].as_str().unwrap_or_default();
    let api_ok = api
        .split_once('.')
        .and_then(|(a, b)| Some((a.parse::<u32>().ok()?, b.parse::<u32>().ok()?)))
        .is_some_and(|(major, minor)| major <= 1 && (major, minor) != (0, 0));
    if !api_ok {
        m.verdict = invalid(&format!("api_version {api:?} is not 1.x"));
        return m;
    }
    if let Some(lib) = &m.library {
        if lib.is_absolute() && !lib.exists() {
            m.verdict = invalid(&format!("library {} does not exist", lib.display()));
        }
    }
    m
}

/// The `*.json` files of a directory. The loader takes them in `readdir` order, which no filesystem
/// promises; sorted here so the report is stable.
fn json_files(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "json") && p.is_file())
        .collect();
    files.sort();
    files
}

/// One layer the loader would load, in order.
#[derive(Clone, Debug)]
pub struct Load {
    /// Index into [`Discovery::implicit`] or [`Discovery::explicit`], by `kind`.
    pub kind: Kind,
    pub index: usize,
}

/// Everything the loader would find.
#[derive(Debug)]
pub struct Discovery {
    pub runtime: Option<Runtime>,
    pub explicit_dirs: Vec<PathBuf>,
    /// `XR_API_LAYER_PATH` replaced the standard explicit directories.
    pub explicit_override: bool,
    pub implicit_dirs: Vec<PathBuf>,
    pub explicit: Vec<Manifest>,
    pub implicit: Vec<Manifest>,
    /// `XR_ENABLE_API_LAYERS`, in order.
    pub requested: Vec<String>,
    /// What loads, next to the application first (before any layer the application names).
    pub order: Vec<Load>,
    /// Requested names no usable manifest provides.
    pub not_found: Vec<String>,
}

impl Discovery {
    pub fn manifest(&self, l: &Load) -> &Manifest {
        match l.kind {
            Kind::Explicit => &self.explicit[l.index],
            Kind::Implicit => &self.implicit[l.index],
        }
    }
}

/// Discovery and load order as the 1.1.x loader does it (`LoadApiLayers`): every usable implicit
/// manifest, in directory order; then, for each name in `XR_ENABLE_API_LAYERS` not already loaded,
/// every usable explicit manifest of that name.
pub fn discover(env: &Environment) -> Discovery {
    let (explicit_dirs, explicit_override) = layer_dirs(env, Kind::Explicit);
    let (implicit_dirs, _) = layer_dirs(env, Kind::Implicit);
    let read = |dirs: &[PathBuf], kind| -> Vec<Manifest> {
        dirs.iter()
            .flat_map(|d| json_files(d))
            .map(|p| read_layer(&p, kind, env))
            .collect()
    };
    let explicit = read(&explicit_dirs, Kind::Explicit);
    let implicit = read(&implicit_dirs, Kind::Implicit);
    let requested: Vec<String> = env
        .get("XR_ENABLE_API_LAYERS")
        .unwrap_or_default()
        .split(':')
        .filter(|n| !n.is_empty())
        .map(String::from)
        .collect();
    let mut order: Vec<Load> = (0..implicit.len())
        .filter(|&i| implicit[i].usable())
        .map(|index| Load {
            kind: Kind::Implicit,
            index,
        })
        .collect();
    let mut loaded: Vec<&str> = order
        .iter()
        .filter_map(|l| implicit[l.index].name.as_deref())
        .collect();
    let mut not_found = Vec::new();
    for name in &requested {
        if loaded.contains(&name.as_str()) {
            continue;
        }
        let matching: Vec<usize> = (0..explicit.len())
            .filter(|&i| explicit[i].usable() && explicit[i].name.as_deref() == Some(name))
            .collect();
        if matching.is_empty() {
            not_found.push(name.clone());
            continue;
        }
        loaded.push(name);
        order.extend(matching.into_iter().map(|index| Load {
            kind: Kind::Explicit,
            index,
        }));
    }
    Discovery {
        runtime: find_runtime(env),
        explicit_dirs,
        explicit_override,
        implicit_dirs,
        explicit,
        implicit,
        requested,
        order,
        not_found,
    }
}
