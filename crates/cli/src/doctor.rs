//! `fovea doctor`: what the Khronos loader would find on Linux ([`crate::found`]: the active runtime,
//! the explicit and implicit layer manifests, which layers it enables and in which order) and the
//! misconfigurations that keep fovea from loading or load it twice; whether the runtime has eye
//! gaze ([`crate::xr_doctor`]); then what [`crate::vk_doctor`] finds of the Vulkan layer and each
//! GPU.
//!
//! [`problems`] takes what was found as an argument, so tests drive it without the real home
//! directory or `/etc`.

use std::path::{Path, PathBuf};

use crate::discovery::{process_vars, Environment, Kind};
use crate::found::{discover, Discovery, Manifest, Skip};
use crate::vk_doctor;
use crate::xr_doctor;

/// The misconfigurations, one line each.
pub fn problems(d: &Discovery) -> Vec<String> {
    let mut out = Vec::new();
    match &d.runtime {
        None => out.push(
            "no active runtime: neither XR_RUNTIME_JSON nor an active_runtime.json; \
             xrCreateInstance fails with XR_ERROR_RUNTIME_UNAVAILABLE"
                .to_owned(),
        ),
        Some(rt) => match &rt.read {
            Err(e) => out.push(format!("runtime manifest {}: {e}", rt.manifest.display())),
            Ok((_, lib)) if lib.is_absolute() && !lib.is_file() => out.push(format!(
                "runtime manifest {}: library {} is not a file",
                rt.manifest.display(),
                lib.display()
            )),
            Ok(_) => {}
        },
    }
    if d.explicit_override {
        for dir in &d.explicit_dirs {
            if dir.is_file() {
                out.push(format!(
                    "XR_API_LAYER_PATH names the file {}: it lists directories, and the loader reads \
                     every *.json in each",
                    dir.display()
                ));
            }
        }
        for m in d.explicit.iter().filter(|m| m.runtime_manifest) {
            out.push(format!(
                "{} is a runtime manifest in an XR_API_LAYER_PATH directory: the loader reads every \
                 *.json there as a layer manifest and logs \"missing required fields\" on every \
                 enumeration; move it out",
                m.path.display()
            ));
        }
    }
    let fovea: Vec<&Manifest> = d
        .implicit
        .iter()
        .chain(&d.explicit)
        .filter(|m| m.is_fovea())
        .collect();
    for m in &fovea {
        let path = m.path.display();
        let before = out.len();
        match &m.library {
            Some(lib) if lib.is_absolute() && !lib.exists() => out.push(format!(
                "{path}: fovea's library_path {} does not exist, so the loader ignores this manifest \
                 (`cargo build --release` builds it; `fovea install` points a manifest at a build)",
                lib.display()
            )),
            Some(lib) if lib.is_absolute() && !lib.is_file() => out.push(format!(
                "{path}: fovea's library_path {} is not a file: loading the layer fails",
                lib.display()
            )),
            _ => {}
        }
        if m.kind == Kind::Implicit && m.name.is_some() && m.disable_environment.is_none() {
            out.push(format!(
                "{path}: implicit fovea manifest without disable_environment: the loader rejects it \
                 (`fovea install --implicit` writes FOVEA_DISABLE)"
            ));
        }
        match &m.verdict {
            Err(Skip::Disabled(why)) => out.push(format!(
                "{path}: the implicit fovea layer is disabled because {why}"
            )),
            // Anything not named above.
            Err(Skip::Invalid(why)) if out.len() == before => out.push(format!(
                "{path}: the loader skips this fovea manifest: {why}"
            )),
            _ => {}
        }
    }
    let loads: Vec<&Manifest> = d
        .order
        .iter()
        .map(|l| d.manifest(l))
        .filter(|m| m.is_fovea())
        .collect();
    if loads.len() > 1 {
        out.push(format!(
            "fovea would be loaded {} times, stacked on itself: {}; keep one manifest",
            loads.len(),
            loads
                .iter()
                .map(|m| m.path.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    let implicit_fovea = d
        .order
        .iter()
        .any(|l| l.kind == Kind::Implicit && d.manifest(l).is_fovea());
    if implicit_fovea && d.requested.iter().any(|n| n == fovea_abi::LAYER_NAME) {
        let explicit: Vec<String> = d
            .explicit
            .iter()
            .filter(|m| m.is_fovea() && m.usable())
            .map(|m| m.path.display().to_string())
            .collect();
        let consequence = if explicit.is_empty() {
            "fail with XR_ERROR_API_LAYER_NOT_PRESENT".to_owned()
        } else {
            format!(
                "load it twice, stacked on itself (also from {})",
                explicit.join(", ")
            )
        };
        out.push(format!(
            "fovea is implicit and also named in XR_ENABLE_API_LAYERS: loaders before 1.0.30 \
             (Debian 12 ships 1.0.20) {consequence}; drop it from XR_ENABLE_API_LAYERS"
        ));
    }
    for name in &d.not_found {
        let hint = if name == fovea_abi::LAYER_NAME {
            " (`fovea install` writes one)"
        } else {
            ""
        };
        out.push(format!(
            "XR_ENABLE_API_LAYERS names {name} but no usable manifest provides it: xrCreateInstance \
             fails with XR_ERROR_API_LAYER_NOT_PRESENT{hint}"
        ));
    }
    out
}

fn describe(m: &Manifest) -> String {
    let name = m.name.as_deref().unwrap_or("(no name)");
    match &m.verdict {
        Ok(()) => match &m.library {
            Some(lib) => format!("{name}, library {}", lib.display()),
            None => name.to_owned(),
        },
        Err(Skip::Disabled(why)) => format!("{name}, disabled: {why}"),
        Err(Skip::Invalid(why)) => format!("skipped: {why}"),
    }
}

fn join(dirs: &[PathBuf]) -> String {
    let s: Vec<String> = dirs.iter().map(|d| d.display().to_string()).collect();
    s.join(", ")
}

/// The report, `extra` lines before the problems, problems last.
pub fn render(d: &Discovery, extra: &[String], problems: &[String]) -> String {
    let mut out = String::new();
    let mut line = |s: String| {
        out.push_str(&s);
        out.push('\n');
    };
    match &d.runtime {
        None => line("active runtime: none found".into()),
        Some(rt) => {
            line(format!(
                "active runtime: {} ({})",
                rt.manifest.display(),
                rt.source
            ));
            match &rt.read {
                Ok((name, lib)) => line(format!("  {name}, library {}", lib.display())),
                Err(e) => line(format!("  unusable: {e}")),
            }
        }
    }
    let sections = [
        (
            if d.explicit_override {
                "explicit layers (XR_API_LAYER_PATH replaces the standard directories):"
            } else {
                "explicit layers:"
            },
            &d.explicit_dirs,
            &d.explicit,
        ),
        ("implicit layers:", &d.implicit_dirs, &d.implicit),
    ];
    for (title, dirs, manifests) in sections {
        line(title.into());
        line(format!("  searched: {}", join(dirs)));
        if manifests.is_empty() {
            line("  (no manifests)".into());
        }
        for m in manifests {
            line(format!("  {}: {}", m.path.display(), describe(m)));
        }
    }
    if !d.requested.is_empty() {
        line(format!("XR_ENABLE_API_LAYERS: {}", d.requested.join(":")));
    }
    line("load order (next to the application first; layers the application names follow):".into());
    if d.order.is_empty() {
        line("  (none)".into());
    }
    for (i, l) in d.order.iter().enumerate() {
        let m = d.manifest(l);
        let how = match l.kind {
            Kind::Implicit => "implicit",
            Kind::Explicit => "XR_ENABLE_API_LAYERS",
        };
        line(format!(
            "  {}. {} ({how}) {}",
            i + 1,
            m.name.as_deref().unwrap_or_default(),
            m.path.display()
        ));
    }
    let positions: Vec<String> = d
        .order
        .iter()
        .enumerate()
        .filter(|(_, l)| d.manifest(l).is_fovea())
        .map(|(i, _)| (i + 1).to_string())
        .collect();
    let found = d.implicit.iter().chain(&d.explicit).any(Manifest::is_fovea);
    line(if !positions.is_empty() {
        format!(
            "fovea: enabled, layer {} of {}",
            positions.join(" and "),
            d.order.len()
        )
    } else if found {
        format!(
            "fovea: found, not enabled (an application enables it by name, or XR_ENABLE_API_LAYERS={})",
            fovea_abi::LAYER_NAME
        )
    } else {
        "fovea: no manifest found (`fovea install` writes one)".into()
    });
    for l in extra {
        line(l.clone());
    }
    for p in problems {
        line(format!("problem: {p}"));
    }
    out
}

pub fn run(args: &crate::args::DoctorArgs) -> Result<(), String> {
    let vars = process_vars();
    let env = Environment {
        vars: &vars,
        root: Path::new("/"),
    };
    let d = discover(&env);
    let mut found = problems(&d);
    // Steam's container, the other layers, the configuration file (doctor_settings.rs).
    let (order, order_problems) = crate::doctor_settings::order_findings(&d);
    let (config, config_problems) =
        crate::doctor_settings::config_findings(&env, args.app.as_deref());
    let (container, container_problems) = crate::doctor_settings::container_findings(&d, &env);
    found.extend(container_problems);
    found.extend(order_problems);
    found.extend(config_problems);
    for l in order.iter().chain(&config) {
        println!("{l}");
    }
    for n in &container {
        println!("note: {n}");
    }
    // The runtime's eye gaze: information, never a problem (fixed foveation works everywhere).
    let gaze = match d.runtime.as_ref().map(|rt| &rt.read) {
        Some(Ok((_, library))) => match xr_doctor::eye_gaze(library) {
            Ok(g) => g.describe(),
            Err(e) => format!("eye gaze: cannot ask the runtime ({e})"),
        },
        _ => "eye gaze: no usable runtime to ask".into(),
    };
    let mut vk = vk_doctor::Report::default();
    vk.lines.push(gaze);
    vk.lines
        .push(format!("Vulkan layer {}:", fovea_abi::VK_LAYER_NAME));
    let openxr_found = d.implicit.iter().chain(&d.explicit).any(Manifest::is_fovea);
    let usable = vk_doctor::layer_report(&env, openxr_found, &mut vk);
    // The user's environment is read above; from here on the GPUs are asked without the layer.
    vk_doctor::keep_layer_out();
    vk_doctor::gpu_report(usable, &mut vk);
    found.extend(vk.problems);
    print!("{}", render(&d, &vk.lines, &found));
    match found.len() {
        0 => Ok(()),
        1 => Err("1 problem".into()),
        n => Err(format!("{n} problems")),
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;
    use crate::discovery::{arch_abi, MANIFEST_FILE};
    use crate::found::read_layer;

    /// A scratch directory standing in for `/`.
    fn root(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("fovea-doctor-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn vars(pairs: &[(&str, &str)]) -> BTreeMap<String, String> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect()
    }

    fn layer(dir: &Path, file: &str, name: &str, library: &Path, disable: Option<&str>) {
        std::fs::create_dir_all(dir).unwrap();
        let disable = disable
            .map(|d| format!(r#", "disable_environment": "{d}""#))
            .unwrap_or_default();
        std::fs::write(
            dir.join(file),
            format!(
                r#"{{"file_format_version": "1.0.0", "api_layer": {{"name": "{name}",
                "library_path": "{}", "api_version": "1.0", "implementation_version": "1"{disable}}}}}"#,
                library.display()
            ),
        )
        .unwrap();
    }

    #[test]
    fn runtime_from_the_first_existing_config_dir() {
        let r = root("runtime");
        let v = vars(&[("HOME", r.join("home").to_str().unwrap())]);
        let env = Environment { vars: &v, root: &r };
        assert!(discover(&env).runtime.is_none());
        let etc = r.join("etc/openxr/1");
        std::fs::create_dir_all(&etc).unwrap();
        std::fs::write(
            etc.join("active_runtime.json"),
            r#"{"file_format_version": "1.0.0", "runtime": {"name": "sys", "library_path": "./librt.so"}}"#,
        )
        .unwrap();
        let rt = discover(&env).runtime.unwrap();
        assert_eq!(rt.source, "the loader's SYSCONFDIR");
        let (name, lib) = rt.read.unwrap();
        assert_eq!(name, "sys");
        assert_eq!(lib, std::fs::canonicalize(&etc).unwrap().join("./librt.so"));
        // A user's runtime wins over the system's.
        let user = r.join("home/.config/openxr/1");
        std::fs::create_dir_all(&user).unwrap();
        let decorated = format!("active_runtime.{}.json", arch_abi());
        std::fs::write(user.join(&decorated), "{}").unwrap();
        let rt = discover(&env).runtime.unwrap();
        assert_eq!(rt.manifest, user.join(&decorated));
        assert_eq!(rt.source, "XDG_CONFIG_HOME");
        assert!(rt.read.unwrap_err().contains("file_format_version"));
    }

    #[test]
    fn implicit_layers_first_then_requested_explicit_ones_once_each() {
        let r = root("load");
        let lib = r.join("lib.so");
        std::fs::write(&lib, "").unwrap();
        let sys = r.join("etc/xdg/openxr/1/api_layers/implicit.d");
        layer(
            &sys,
            "other.json",
            "XR_APILAYER_OTHER",
            &lib,
            Some("NO_OTHER"),
        );
        layer(&sys, "off.json", "XR_APILAYER_OFF", &lib, Some("NO_OFF"));
        let user = r.join("home/.local/share/openxr/1/api_layers/explicit.d");
        layer(&user, MANIFEST_FILE, fovea_abi::LAYER_NAME, &lib, None);
        layer(&user, "b.json", "XR_APILAYER_B", &lib, None);
        let v = vars(&[
            ("HOME", r.join("home").to_str().unwrap()),
            ("NO_OFF", ""),
            (
                "XR_ENABLE_API_LAYERS",
                "XR_APILAYER_B:XR_APILAYER_OTHER:XR_APILAYER_FOVEA_foveation:XR_APILAYER_B",
            ),
        ]);
        let env = Environment { vars: &v, root: &r };
        let d = discover(&env);
        let names: Vec<&str> = d
            .order
            .iter()
            .map(|l| d.manifest(l).name.as_deref().unwrap())
            .collect();
        // An empty disable variable still disables; a layer already loaded implicitly is not
        // loaded again; a name given twice loads once.
        assert_eq!(
            names,
            ["XR_APILAYER_OTHER", "XR_APILAYER_B", fovea_abi::LAYER_NAME]
        );
        assert_eq!(
            d.implicit[0].verdict,
            Err(Skip::Disabled("NO_OFF is set".into()))
        );
        let p = problems(&d);
        // Only the missing runtime.
        assert_eq!(p.len(), 1, "{p:?}");
        assert!(p[0].starts_with("no active runtime"), "{p:?}");
        let text = render(&d, &[], &p);
        assert!(text.contains("fovea: enabled, layer 3 of 3"), "{text}");
    }

    #[test]
    fn relative_library_paths_resolve_against_the_manifest_directory() {
        let r = root("relative");
        std::fs::create_dir_all(r.join("lib")).unwrap();
        std::fs::write(r.join("lib/libfovea.so"), "").unwrap();
        let dir = r.join("layers");
        layer(&dir, "a.json", "A", Path::new("../lib/libfovea.so"), None);
        layer(&dir, "b.json", "B", Path::new("../lib/missing.so"), None);
        layer(&dir, "c.json", "C", Path::new("libbare.so"), None);
        let v = vars(&[]);
        let env = Environment { vars: &v, root: &r };
        let a = read_layer(&dir.join("a.json"), Kind::Explicit, &env);
        assert!(a.usable(), "{a:?}");
        assert!(a.library.unwrap().is_file());
        let b = read_layer(&dir.join("b.json"), Kind::Explicit, &env);
        assert!(matches!(b.verdict, Err(Skip::Invalid(ref w)) if w.contains("does not exist")));
        // A bare file name is left to the dynamic linker.
        let c = read_layer(&dir.join("c.json"), Kind::Explicit, &env);
        assert!(c.usable());
        assert_eq!(c.library.unwrap(), Path::new("libbare.so"));
    }
}
