//! Where the Khronos OpenXR loader looks for manifests on Linux, as data: one model that `fovea
//! install` (where to write so the loader finds it) and `fovea doctor` (what the loader will find)
//! both read, so the two cannot disagree.
//!
//! The order follows the loader's `manifest_file.cpp` (1.1.x), described in the loader
//! documentation: <https://registry.khronos.org/OpenXR/specs/1.0/loader.html>.
//! Everything here takes the environment and the filesystem root as arguments, so tests drive it
//! without the real home directory or `/etc`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// fovea's manifest file name, as `fovea install` writes it.
pub const MANIFEST_FILE: &str = "XR_APILAYER_FOVEA_foveation.json";

/// Replaces the whole explicit-layer search with its ':'-separated directories.
pub const LAYER_PATH_VAR: &str = "XR_API_LAYER_PATH";

/// Names the runtime manifest file, ending the runtime search.
pub const RUNTIME_JSON_VAR: &str = "XR_RUNTIME_JSON";

/// Explicit layers load only when named (`XR_ENABLE_API_LAYERS` or the application); implicit ones
/// load for every application unless their `disable_environment` variable is set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Explicit,
    Implicit,
}

impl Kind {
    /// The directory under each base directory: `openxr/1/api_layers/{explicit,implicit}.d`.
    pub fn relative_dir(self) -> &'static str {
        match self {
            Kind::Explicit => "openxr/1/api_layers/explicit.d",
            Kind::Implicit => "openxr/1/api_layers/implicit.d",
        }
    }

    /// The other kind: an install of one kind notes a manifest of the other.
    pub fn other(self) -> Kind {
        match self {
            Kind::Explicit => Kind::Implicit,
            Kind::Implicit => Kind::Explicit,
        }
    }
}

/// One step of a search: where its base directories come from.
#[derive(Clone, Copy, Debug)]
pub enum Base {
    /// A ':'-separated list in a variable, or the built-in `default` when it is unset or empty.
    List {
        var: &'static str,
        default: &'static [&'static str],
    },
    /// A directory compiled into the loader (its `SYSCONFDIR`, `/etc` in Debian's build).
    Fixed(&'static str),
    /// One per-user directory in a variable, or `$HOME/<home>` when it is unset or empty.
    User {
        var: &'static str,
        home: &'static str,
    },
}

/// The base directories of layer manifests, both kinds, in the loader's order; each is followed
/// by [`Kind::relative_dir`]. The user's data home comes last, so a system-wide layer of the same
/// name is found first.
pub const LAYER_SEARCH: &[Base] = &[
    Base::List {
        var: "XDG_CONFIG_DIRS",
        default: &["/etc/xdg"],
    },
    Base::Fixed("/etc"),
    Base::List {
        var: "XDG_DATA_DIRS",
        default: &["/usr/local/share", "/usr/share"],
    },
    USER_DATA,
];

/// Where per-user layer manifests go, and where `fovea install` writes without `--system`.
pub const USER_DATA: Base = Base::User {
    var: "XDG_DATA_HOME",
    home: ".local/share",
};

/// Where `fovea install --system` writes: a default of `XDG_DATA_DIRS`, and the place for files no
/// package manager owns.
pub const SYSTEM_DATA_DIR: &str = "/usr/local/share";

/// The base directories of the active runtime manifest, in the loader's order: the user's
/// configuration first. Each is followed by `openxr/1/active_runtime[.<abi>].json`.
pub const RUNTIME_SEARCH: &[Base] = &[
    Base::User {
        var: "XDG_CONFIG_HOME",
        home: ".config",
    },
    Base::List {
        var: "XDG_CONFIG_DIRS",
        default: &["/etc/xdg"],
    },
    Base::Fixed("/etc"),
];

/// What the loader reads: the process environment, and where the fixed directories are.
pub struct Environment<'a> {
    pub vars: &'a BTreeMap<String, String>,
    /// Prefix of the loader's built-in directories (`/etc/xdg`, `/etc`, `/usr/local/share`,
    /// `/usr/share`): `/` for the real system. Directories named by variables are taken as they are.
    pub root: &'a Path,
}

/// This process's environment as text (the loader reads it as bytes; a non-UTF-8 value cannot name
/// a path fovea writes into JSON anyway).
pub fn process_vars() -> BTreeMap<String, String> {
    std::env::vars_os()
        .map(|(k, v)| {
            (
                k.to_string_lossy().into_owned(),
                v.to_string_lossy().into_owned(),
            )
        })
        .collect()
}

impl Environment<'_> {
    /// A variable's value; the loader treats an empty one as unset.
    pub fn get(&self, name: &str) -> Option<&str> {
        self.vars
            .get(name)
            .map(String::as_str)
            .filter(|v| !v.is_empty())
    }

    /// Whether a variable is present, even empty: the test for `disable_environment`.
    pub fn is_set(&self, name: &str) -> bool {
        self.vars.contains_key(name)
    }

    fn fixed(&self, path: &str) -> PathBuf {
        self.root.join(path.trim_start_matches('/'))
    }

    /// The directories one step of a search yields, in order; none for a per-user step without
    /// `HOME`.
    pub fn bases(&self, base: Base) -> Vec<PathBuf> {
        match base {
            Base::List { var, default } => match self.get(var) {
                Some(v) => v
                    .split(':')
                    .filter(|d| !d.is_empty())
                    .map(PathBuf::from)
                    .collect(),
                None => default.iter().map(|d| self.fixed(d)).collect(),
            },
            Base::Fixed(path) => vec![self.fixed(path)],
            Base::User { var, home } => self
                .get(var)
                .map(PathBuf::from)
                .or_else(|| self.get("HOME").map(|h| Path::new(h).join(home)))
                .into_iter()
                .collect(),
        }
    }
}

/// The directories the loader reads layer manifests of one kind from when `XR_API_LAYER_PATH`
/// does not replace them.
pub fn standard_layer_dirs(env: &Environment, kind: Kind) -> Vec<PathBuf> {
    LAYER_SEARCH
        .iter()
        .flat_map(|&b| env.bases(b))
        .map(|b| b.join(kind.relative_dir()))
        .collect()
}

/// The directories the loader reads layer manifests of one kind from, in its order, and whether
/// `XR_API_LAYER_PATH` replaced them (explicit layers only).
pub fn layer_dirs(env: &Environment, kind: Kind) -> (Vec<PathBuf>, bool) {
    if kind == Kind::Explicit {
        if let Some(p) = env.get(LAYER_PATH_VAR) {
            let dirs = p.split(':').filter(|d| !d.is_empty()).map(PathBuf::from);
            return (dirs.collect(), true);
        }
    }
    (standard_layer_dirs(env, kind), false)
}

/// Where `fovea install` puts fovea's manifest: the user's data home, or [`SYSTEM_DATA_DIR`] with
/// `--system`, then the kind's directory.
pub fn install_path(env: &Environment, kind: Kind, system: bool) -> Result<PathBuf, String> {
    let base = if system {
        PathBuf::from(SYSTEM_DATA_DIR)
    } else {
        env.bases(USER_DATA)
            .pop()
            .ok_or("neither XDG_DATA_HOME nor HOME is set")?
    };
    Ok(base.join(kind.relative_dir()).join(MANIFEST_FILE))
}

/// The Vulkan layer's implicit manifest file name, as `fovea install` writes it.
pub const VK_MANIFEST_FILE: &str = "VK_LAYER_FOVEA_fragment_density_map.json";

/// The Vulkan loader's folder for implicit layer manifests under each base directory.
pub const VK_IMPLICIT_DIR: &str = "vulkan/implicit_layer.d";
/// The Vulkan loader's folder for explicit layer manifests under each base directory.
pub const VK_EXPLICIT_DIR: &str = "vulkan/explicit_layer.d";

/// The base directories the Vulkan loader reads layer manifests from on Linux, in its order; each
/// is followed by [`VK_IMPLICIT_DIR`] or [`VK_EXPLICIT_DIR`]
/// (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>, "Linux
/// Layer Discovery"). Debian's loader has `/etc` as both its SYSCONFDIR and EXTRASYSCONFDIR.
pub const VK_LAYER_SEARCH: &[Base] = &[
    Base::User {
        var: "XDG_CONFIG_HOME",
        home: ".config",
    },
    Base::List {
        var: "XDG_CONFIG_DIRS",
        default: &["/etc/xdg"],
    },
    Base::Fixed("/etc"),
    USER_DATA,
    Base::List {
        var: "XDG_DATA_DIRS",
        default: &["/usr/local/share", "/usr/share"],
    },
];

/// Variables that name folders of Vulkan layer manifests: the explicit ones add to
/// (`VK_ADD_LAYER_PATH`) or replace (`VK_LAYER_PATH`) the explicit search, the implicit ones the
/// implicit search (loaders 1.3.234 and later).
pub const VK_ADD_LAYER_PATH: &str = "VK_ADD_LAYER_PATH";
pub const VK_LAYER_PATH: &str = "VK_LAYER_PATH";
pub const VK_ADD_IMPLICIT_LAYER_PATH: &str = "VK_ADD_IMPLICIT_LAYER_PATH";
pub const VK_IMPLICIT_LAYER_PATH: &str = "VK_IMPLICIT_LAYER_PATH";

/// The folders the Vulkan loader reads layer manifests of one kind from, in its order.
pub fn vk_layer_dirs(env: &Environment, kind: Kind) -> Vec<PathBuf> {
    let (add, replace, rel) = match kind {
        Kind::Explicit => (VK_ADD_LAYER_PATH, VK_LAYER_PATH, VK_EXPLICIT_DIR),
        Kind::Implicit => (
            VK_ADD_IMPLICIT_LAYER_PATH,
            VK_IMPLICIT_LAYER_PATH,
            VK_IMPLICIT_DIR,
        ),
    };
    let split = |v: &str| -> Vec<PathBuf> {
        v.split(':')
            .filter(|d| !d.is_empty())
            .map(PathBuf::from)
            .collect()
    };
    if let Some(p) = env.get(replace) {
        return split(p);
    }
    let mut dirs = env.get(add).map(split).unwrap_or_default();
    dirs.extend(
        VK_LAYER_SEARCH
            .iter()
            .flat_map(|&b| env.bases(b))
            .map(|b| b.join(rel)),
    );
    dirs
}

/// Where `fovea install` puts the Vulkan layer's implicit manifest: the user's data home, or
/// [`SYSTEM_DATA_DIR`] with `--system`, then [`VK_IMPLICIT_DIR`].
pub fn vk_install_path(env: &Environment, system: bool) -> Result<PathBuf, String> {
    let base = if system {
        PathBuf::from(SYSTEM_DATA_DIR)
    } else {
        env.bases(USER_DATA)
            .pop()
            .ok_or("neither XDG_DATA_HOME nor HOME is set")?
    };
    Ok(base.join(VK_IMPLICIT_DIR).join(VK_MANIFEST_FILE))
}

/// `XR_ARCH_ABI` as the loader spells it, for `active_runtime.<abi>.json`.
pub fn arch_abi() -> &'static str {
    match std::env::consts::ARCH {
        "x86" => "i686",
        "arm" => "armv7a-vfp",
        other => other,
    }
}

/// Names the step of [`RUNTIME_SEARCH`] a runtime manifest came from, for the report.
fn runtime_source(base: Base) -> &'static str {
    match base {
        Base::List { var, .. } | Base::User { var, .. } => var,
        Base::Fixed(_) => "the loader's SYSCONFDIR",
    }
}

/// The runtime manifest paths the loader tries, in order, and what chose them; the first that
/// exists wins (`XR_RUNTIME_JSON` is taken whether or not it does). Newer loaders try
/// `active_runtime.<abi>.json` before `active_runtime.json` in each directory.
pub fn runtime_candidates(env: &Environment) -> Vec<(PathBuf, &'static str)> {
    if let Some(p) = env.get(RUNTIME_JSON_VAR) {
        return vec![(PathBuf::from(p), RUNTIME_JSON_VAR)];
    }
    let decorated = format!("active_runtime.{}.json", arch_abi());
    RUNTIME_SEARCH
        .iter()
        .flat_map(|&step| env.bases(step).into_iter().map(move |b| (b, step)))
        .flat_map(|(b, step)| {
            let dir = b.join("openxr/1");
            let why = runtime_source(step);
            [
                (dir.join(&decorated), why),
                (dir.join("active_runtime.json"), why),
            ]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vars(pairs: &[(&str, &str)]) -> BTreeMap<String, String> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    #[test]
    fn layer_search_order_follows_the_loader() {
        let r = Path::new("/root");
        let v = vars(&[("HOME", "/home/u")]);
        let env = Environment { vars: &v, root: r };
        let (dirs, over) = layer_dirs(&env, Kind::Implicit);
        assert!(!over);
        let rel = "openxr/1/api_layers/implicit.d";
        assert_eq!(
            dirs,
            [
                r.join("etc/xdg").join(rel),
                r.join("etc").join(rel),
                r.join("usr/local/share").join(rel),
                r.join("usr/share").join(rel),
                PathBuf::from("/home/u/.local/share").join(rel),
            ]
        );
        // XR_API_LAYER_PATH replaces the explicit search and leaves the implicit one alone; an
        // empty variable counts as unset.
        let v = vars(&[
            ("XR_API_LAYER_PATH", "/a::/b"),
            ("XDG_DATA_DIRS", "/d"),
            ("XDG_DATA_HOME", ""),
            ("HOME", "/h"),
        ]);
        let env = Environment { vars: &v, root: r };
        assert_eq!(
            layer_dirs(&env, Kind::Explicit),
            (vec![PathBuf::from("/a"), PathBuf::from("/b")], true)
        );
        let (dirs, _) = layer_dirs(&env, Kind::Implicit);
        assert_eq!(dirs[2], Path::new("/d").join(rel));
        assert_eq!(dirs[3], Path::new("/h/.local/share").join(rel));
        assert_eq!(dirs.len(), 4);
    }

    #[test]
    fn install_paths_are_in_the_search() {
        let r = Path::new("/");
        let home = vars(&[("HOME", "/home/u")]);
        let env = Environment {
            vars: &home,
            root: r,
        };
        assert_eq!(
            install_path(&env, Kind::Explicit, false).unwrap(),
            Path::new(
                "/home/u/.local/share/openxr/1/api_layers/explicit.d/XR_APILAYER_FOVEA_foveation.json"
            )
        );
        let xdg = vars(&[("HOME", "/home/u"), ("XDG_DATA_HOME", "/data")]);
        let env = Environment {
            vars: &xdg,
            root: r,
        };
        assert_eq!(
            install_path(&env, Kind::Implicit, false).unwrap(),
            Path::new("/data/openxr/1/api_layers/implicit.d/XR_APILAYER_FOVEA_foveation.json")
        );
        let system = install_path(&env, Kind::Implicit, true).unwrap();
        assert_eq!(
            system,
            Path::new(
                "/usr/local/share/openxr/1/api_layers/implicit.d/XR_APILAYER_FOVEA_foveation.json"
            )
        );
        // Both places are searched with the default environment.
        for kind in [Kind::Explicit, Kind::Implicit] {
            let dirs = standard_layer_dirs(&env, kind);
            for system in [false, true] {
                let p = install_path(&env, kind, system).unwrap();
                assert!(dirs.iter().any(|d| Some(d.as_path()) == p.parent()));
            }
        }
        let none = vars(&[]);
        let env = Environment {
            vars: &none,
            root: r,
        };
        assert!(install_path(&env, Kind::Explicit, false).is_err());
    }

    #[test]
    fn vulkan_layer_search_and_install_paths() {
        let r = Path::new("/root");
        let v = vars(&[("HOME", "/h"), ("XDG_DATA_HOME", "/data")]);
        let env = Environment { vars: &v, root: r };
        let dirs = vk_layer_dirs(&env, Kind::Implicit);
        assert_eq!(dirs[0], Path::new("/h/.config/vulkan/implicit_layer.d"));
        assert_eq!(dirs[3], Path::new("/data/vulkan/implicit_layer.d"));
        assert_eq!(dirs.len(), 6);
        let user = vk_install_path(&env, false).unwrap();
        assert_eq!(
            user,
            Path::new("/data/vulkan/implicit_layer.d/VK_LAYER_FOVEA_fragment_density_map.json")
        );
        assert!(dirs.iter().any(|d| Some(d.as_path()) == user.parent()));
        let system = vk_install_path(&env, true).unwrap();
        assert!(dirs.contains(&r.join("usr/local/share").join(VK_IMPLICIT_DIR)));
        assert_eq!(
            system.parent().unwrap(),
            Path::new("/usr/local/share/vulkan/implicit_layer.d")
        );
        let v = vars(&[("HOME", "/h"), ("VK_ADD_LAYER_PATH", "/a:/b")]);
        let env = Environment { vars: &v, root: r };
        let dirs = vk_layer_dirs(&env, Kind::Explicit);
        assert_eq!(dirs[..2], [PathBuf::from("/a"), PathBuf::from("/b")]);
        assert_eq!(dirs.len(), 8);
        let v = vars(&[("VK_ADD_LAYER_PATH", "/a"), ("VK_LAYER_PATH", "/c")]);
        let env = Environment { vars: &v, root: r };
        assert_eq!(vk_layer_dirs(&env, Kind::Explicit), [PathBuf::from("/c")]);
    }

    #[test]
    fn runtime_search_starts_with_the_user_config() {
        let r = Path::new("/root");
        let v = vars(&[("HOME", "/home/u")]);
        let env = Environment { vars: &v, root: r };
        let c = runtime_candidates(&env);
        let decorated = format!("active_runtime.{}.json", arch_abi());
        assert_eq!(
            c[0],
            (
                PathBuf::from("/home/u/.config/openxr/1").join(&decorated),
                "XDG_CONFIG_HOME"
            )
        );
        assert_eq!(c[3].1, "XDG_CONFIG_DIRS");
        assert_eq!(
            c[5],
            (
                r.join("etc/openxr/1/active_runtime.json"),
                "the loader's SYSCONFDIR"
            )
        );
        assert_eq!(c.len(), 6);
        let v = vars(&[("XR_RUNTIME_JSON", "/rt.json"), ("HOME", "/home/u")]);
        let env = Environment { vars: &v, root: r };
        assert_eq!(
            runtime_candidates(&env),
            [(PathBuf::from("/rt.json"), "XR_RUNTIME_JSON")]
        );
    }
}
