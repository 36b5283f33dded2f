//! `fovea doctor`'s checks of where fovea is installed for Steam games, of the other layers it
//! shares applications with, and of the configuration file. Each takes the discovery and the
//! environment as arguments, so tests drive them with a constructed home and root.
//!
//! The Steam Linux Runtime container (pressure-vessel) sees only layers under the user's home and
//! drops `XR_API_LAYER_PATH` (docs/users.md#steam-linux-runtime). The loader calls layers in its
//! load order, the first nearest the application (docs/openxr-layer.md#discovery).

use std::path::{Path, PathBuf};

use fovea_config::Identity;

use crate::discovery::{Environment, LAYER_PATH_VAR};
use crate::found::{Discovery, Manifest};

/// The per-user data folder the container sees: `$XDG_DATA_HOME`, else `~/.local/share`.
fn user_data(env: &Environment) -> Option<PathBuf> {
    env.get("XDG_DATA_HOME")
        .map(PathBuf::from)
        .or_else(|| env.get("HOME").map(|h| Path::new(h).join(".local/share")))
}

fn under_home(env: &Environment, p: &Path) -> bool {
    env.get("HOME").is_some_and(|h| p.starts_with(h))
        || user_data(env).is_some_and(|d| p.starts_with(d))
}

fn from_layer_path(env: &Environment, p: &Path) -> bool {
    env.get(LAYER_PATH_VAR)
        .is_some_and(|v| v.split(':').any(|d| !d.is_empty() && p.starts_with(d)))
}

/// Steam games: fovea must be installed under the home folder, not only under `/usr` or `/etc`
/// (a problem), and not only through `XR_API_LAYER_PATH` (a note: it is how developers run a
/// build, and it works outside the container). Returns `(notes, problems)`.
pub fn container_findings(d: &Discovery, env: &Environment) -> (Vec<String>, Vec<String>) {
    let fovea: Vec<&Path> = d
        .explicit
        .iter()
        .chain(&d.implicit)
        .filter(|m| m.is_fovea() && m.usable())
        .map(|m| m.path.as_path())
        .collect();
    if fovea.is_empty()
        || fovea
            .iter()
            .any(|p| under_home(env, p) && !from_layer_path(env, p))
    {
        return (Vec::new(), Vec::new());
    }
    let target = user_data(env).map_or("~/.local/share".into(), |d| d.display().to_string());
    let mut notes = Vec::new();
    let mut out = Vec::new();
    if fovea.iter().any(|p| from_layer_path(env, p)) {
        notes.push(format!(
            "fovea is found through {LAYER_PATH_VAR}, which the Steam Linux Runtime container \
             (pressure-vessel) drops: Steam games will not load it; run `fovea install` to register \
             it in {target}/openxr/1/api_layers/"
        ));
    }
    let system: Vec<String> = fovea
        .iter()
        .filter(|p| !under_home(env, p) && !from_layer_path(env, p))
        .map(|p| p.display().to_string())
        .collect();
    if !system.is_empty() {
        out.push(format!(
            "fovea's manifest is only outside the home folder ({}): the Steam Linux Runtime \
             container (pressure-vessel) sees only layers under the home folder, so Steam games \
             will not load it; run `fovea install` (writes {target}/openxr/1/api_layers/ with an \
             absolute library path), or set PRESSURE_VESSEL_IMPORT_OPENXR_1_LAYERS=1 in the game's \
             launch options",
            system.join(", ")
        ));
    }
    (notes, out)
}

/// Words in a layer's name that mark it as foveating or drawing over the image.
const FOVEATING: [&str; 3] = ["foveat", "quad_views", "quadviews"];
const OVERLAYING: [&str; 4] = ["toolkit", "overlay", "motioncompensation", "mango"];

fn lower(name: &str) -> String {
    name.to_ascii_lowercase().replace('-', "_")
}

/// The other foveation or overlay layers installed, and the order the loader will call them in
/// with fovea: information lines, and a problem for each other foveation layer that loads with it.
pub fn order_findings(d: &Discovery) -> (Vec<String>, Vec<String>) {
    let mut lines = Vec::new();
    let mut problems = Vec::new();
    let kind = |k| match k {
        crate::discovery::Kind::Explicit => "explicit",
        crate::discovery::Kind::Implicit => "implicit",
    };
    let others: Vec<&Manifest> = d
        .explicit
        .iter()
        .chain(&d.implicit)
        .filter(|m| !m.is_fovea())
        .filter(|m| {
            m.name.as_deref().is_some_and(|n| {
                let n = lower(n);
                FOVEATING.iter().chain(&OVERLAYING).any(|w| n.contains(w))
            })
        })
        .collect();
    for m in &others {
        lines.push(format!(
            "other layer: {} ({}, {})",
            m.name.as_deref().unwrap_or("?"),
            kind(m.kind),
            m.path.display()
        ));
    }
    let order: Vec<&Manifest> = d.order.iter().map(|l| d.manifest(l)).collect();
    let Some(fovea_at) = order.iter().position(|m| m.is_fovea()) else {
        return (lines, problems);
    };
    if order.len() > 1 {
        let names: Vec<&str> = order
            .iter()
            .map(|m| m.name.as_deref().unwrap_or("?"))
            .collect();
        lines.push(format!(
            "call order, the application's side first: app -> {} -> runtime",
            names.join(" -> ")
        ));
    }
    for (i, m) in order.iter().enumerate() {
        let Some(name) = m.name.as_deref() else {
            continue;
        };
        let n = lower(name);
        if m.is_fovea() || !FOVEATING.iter().any(|w| n.contains(w)) {
            continue;
        }
        let side = if i < fovea_at {
            "above fovea (nearer the application)"
        } else {
            "below fovea (nearer the runtime)"
        };
        let off = m
            .disable_environment
            .as_deref()
            .map_or("remove its manifest".to_string(), |v| format!("set {v}=1"));
        problems.push(format!(
            "{name} also changes foveation and loads {side}: two foveation layers on one \
             application fight over the views and the swapchains; keep one per application \
             ({off} for it, or FOVEA_DISABLE=1 for fovea)"
        ));
    }
    (lines, problems)
}

/// The configuration file: found or not, valid or not, and which sections would match `app`.
pub fn config_findings(env: &Environment, app: Option<&str>) -> (Vec<String>, Vec<String>) {
    let loc = crate::config::locate(env.vars);
    let mut lines = Vec::new();
    let mut problems = Vec::new();
    match (&loc.path, &loc.file) {
        (None, _) => lines.push("configuration file: none".into()),
        (Some(p), None) => {
            lines.push(format!(
                "configuration file: {} (not found: defaults apply)",
                p.display()
            ));
            if loc.explicit {
                problems.push(format!(
                    "FOVEA_CONFIG names {}, which does not exist: create it or unset FOVEA_CONFIG",
                    p.display()
                ));
            }
        }
        (Some(_), Some(Err(e))) => problems.push(format!("{e}: fix its permissions")),
        (Some(p), Some(Ok(c))) => {
            lines.push(format!(
                "configuration file: {} ({} sections, {})",
                p.display(),
                c.sections.len(),
                if c.problems.is_empty() {
                    "valid"
                } else {
                    "with problems"
                }
            ));
            problems.extend(
                c.problems
                    .iter()
                    .map(|p| format!("{p}: fix or remove the line")),
            );
            if let Some(app) = app {
                let id = Identity {
                    app: Some(app.to_owned()),
                    exe: Some(app.to_owned()),
                    engine: None,
                };
                let m: Vec<String> = c.matching(&id).iter().map(|s| s.scope.header()).collect();
                lines.push(format!(
                    "sections matching {app:?} as application or executable name: {}",
                    m.join(", ")
                ));
            }
        }
    }
    (lines, problems)
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;
    use crate::found::discover;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("fovea-doctor-s-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn layer(dir: &Path, name: &str, disable: &str) {
        std::fs::create_dir_all(dir).unwrap();
        let lib = dir.join(format!("lib{name}.so"));
        std::fs::write(&lib, b"").unwrap();
        std::fs::write(
            dir.join(format!("{name}.json")),
            format!(
                r#"{{"file_format_version": "1.0.0", "api_layer": {{"name": "{name}",
                "library_path": "{}", "api_version": "1.0",
                "implementation_version": "1", "disable_environment": "{disable}"}}}}"#,
                lib.display()
            ),
        )
        .unwrap();
    }

    fn vars(pairs: &[(&str, String)]) -> BTreeMap<String, String> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect()
    }

    #[test]
    fn a_system_only_install_is_a_problem_for_steam_games() {
        let r = scratch("container");
        let home = r.join("home");
        layer(
            &r.join("usr/share/openxr/1/api_layers/implicit.d"),
            fovea_abi::LAYER_NAME,
            "FOVEA_DISABLE",
        );
        let v = vars(&[("HOME", home.display().to_string())]);
        let env = Environment { vars: &v, root: &r };
        let (_, p) = container_findings(&discover(&env), &env);
        assert_eq!(p.len(), 1, "{p:?}");
        assert!(
            p[0].contains("pressure-vessel") && p[0].contains("fovea install"),
            "{}",
            p[0]
        );
        assert!(p[0].contains(&home.join(".local/share").display().to_string()));
        // Installed for the user as well: nothing to say.
        layer(
            &home.join(".local/share/openxr/1/api_layers/implicit.d"),
            fovea_abi::LAYER_NAME,
            "FOVEA_DISABLE",
        );
        assert_eq!(container_findings(&discover(&env), &env), (vec![], vec![]));
    }

    #[test]
    fn a_layer_path_only_install_is_dropped_in_the_container() {
        let r = scratch("layerpath");
        let dev = r.join("dev");
        layer(&dev, fovea_abi::LAYER_NAME, "FOVEA_DISABLE");
        let v = vars(&[
            ("HOME", r.join("home").display().to_string()),
            ("XR_API_LAYER_PATH", dev.display().to_string()),
            ("XR_ENABLE_API_LAYERS", fovea_abi::LAYER_NAME.into()),
        ]);
        let env = Environment { vars: &v, root: &r };
        let (p, problems) = container_findings(&discover(&env), &env);
        assert!(problems.is_empty(), "a note, not a problem: {problems:?}");
        assert_eq!(p.len(), 1, "{p:?}");
        assert!(
            p[0].contains("XR_API_LAYER_PATH") && p[0].contains("drops"),
            "{}",
            p[0]
        );
    }

    #[test]
    fn other_foveation_layers_and_the_order() {
        let r = scratch("order");
        let home = r.join("home");
        let implicit = home.join(".local/share/openxr/1/api_layers/implicit.d");
        layer(
            &implicit,
            "XR_APILAYER_MBUCCHIA_quad_views_foveated",
            "DISABLE_QVF",
        );
        layer(&implicit, fovea_abi::LAYER_NAME, "FOVEA_DISABLE");
        layer(&implicit, "XR_APILAYER_NOVENDOR_toolkit", "DISABLE_TOOLKIT");
        layer(&implicit, "XR_APILAYER_other_thing", "X");
        let v = vars(&[("HOME", home.display().to_string())]);
        let env = Environment { vars: &v, root: &r };
        let (lines, problems) = order_findings(&discover(&env));
        let others: Vec<&String> = lines
            .iter()
            .filter(|l| l.starts_with("other layer:"))
            .collect();
        assert_eq!(others.len(), 2, "{lines:?}");
        assert!(lines
            .iter()
            .any(|l| l.starts_with("call order") && l.contains(fovea_abi::LAYER_NAME)));
        assert_eq!(problems.len(), 1, "{problems:?}");
        assert!(
            problems[0].contains("quad_views_foveated") && problems[0].contains("DISABLE_QVF=1")
        );
    }

    #[test]
    fn the_configuration_file_is_found_checked_and_matched() {
        let r = scratch("config");
        let cfg = r.join("config/fovea/fovea.toml");
        std::fs::create_dir_all(cfg.parent().unwrap()).unwrap();
        std::fs::write(
            &cfg,
            "level = 2\n[app.\"hello_xr\"]\nmax_fragment = 8\n[exe.\"x\"]\n",
        )
        .unwrap();
        let v = vars(&[("XDG_CONFIG_HOME", r.join("config").display().to_string())]);
        let env = Environment { vars: &v, root: &r };
        let (lines, problems) = config_findings(&env, Some("hello_xr"));
        assert_eq!(problems.len(), 1, "{problems:?}");
        assert!(problems[0].contains(&format!("{}:3: max_fragment", cfg.display())));
        assert!(
            lines
                .iter()
                .any(|l| l.contains("global, [app.\"hello_xr\"]")),
            "{lines:?}"
        );
        let v = vars(&[("FOVEA_CONFIG", r.join("missing.toml").display().to_string())]);
        let env = Environment { vars: &v, root: &r };
        let (_, problems) = config_findings(&env, None);
        assert!(problems[0].contains("does not exist"), "{problems:?}");
    }
}
