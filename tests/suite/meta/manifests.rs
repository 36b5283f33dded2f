//! The checked-in manifests follow the loader's rules (docs/openxr-layer.md#manifests, docs/openxr-layer.md#discovery) and list
//! exactly the extensions the layer implements, at the versions it reports.

use std::path::{Path, PathBuf};

use fovea_abi::EXTENSIONS;
use serde_json::Value;

use crate::support::root;

fn read(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn check_layer(path: &Path, implicit: bool) {
    let m = read(path);
    assert_eq!(m["file_format_version"], "1.0.0");
    let l = &m["api_layer"];
    assert_eq!(l["name"], fovea_abi::LAYER_NAME);
    // Required fields must be strings: the loader drops numbers as "missing required fields".
    for key in [
        "name",
        "library_path",
        "api_version",
        "implementation_version",
    ] {
        assert!(
            l[key].is_string(),
            "{}: {key} must be a string",
            path.display()
        );
    }
    assert_eq!(l["api_version"], "1.0");
    let library = path
        .parent()
        .unwrap()
        .join(l["library_path"].as_str().unwrap());
    let normalised: PathBuf = library.components().fold(PathBuf::new(), |mut p, c| {
        if c.as_os_str() == ".." {
            p.pop();
        } else {
            p.push(c);
        }
        p
    });
    assert_eq!(
        normalised,
        root().join("target/release/libfovea.so"),
        "{}",
        path.display()
    );
    // `extension_version`, not `spec_version`: the loader silently drops entries without it.
    let listed: Vec<(String, String)> = l["instance_extensions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            (
                e["name"].as_str().unwrap().to_owned(),
                e["extension_version"].as_str().unwrap().to_owned(),
            )
        })
        .collect();
    let expected: Vec<(String, String)> = EXTENSIONS
        .iter()
        .map(|e| (e.name.to_str().unwrap().to_owned(), e.version.to_string()))
        .collect();
    assert_eq!(listed, expected, "{}", path.display());
    // An implicit layer without disable_environment is refused by the loader.
    assert_eq!(
        l["disable_environment"].as_str(),
        implicit.then_some("FOVEA_DISABLE"),
        "{}",
        path.display()
    );
}

#[test]
fn explicit_and_implicit_layer_manifests() {
    check_layer(
        &root().join("manifest/XR_APILAYER_FOVEA_foveation.json"),
        false,
    );
    check_layer(
        &root().join("manifest/implicit/XR_APILAYER_FOVEA_foveation.json"),
        true,
    );
}

/// `XR_API_LAYER_PATH=manifest` reads every *.json there as an explicit layer manifest: exactly one
/// fovea manifest (two would stack the layer on itself) and no runtime manifest.
#[test]
fn the_manifest_directory_holds_exactly_one_layer_manifest() {
    let jsons: Vec<PathBuf> = std::fs::read_dir(root().join("manifest"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    assert_eq!(jsons.len(), 1, "{jsons:?}");
    assert!(read(&jsons[0]).get("api_layer").is_some());
}

#[test]
fn runtime_manifest_points_at_the_simulated_runtime() {
    let m = read(&root().join("manifest/runtime/fovea_sim_runtime.json"));
    assert_eq!(m["file_format_version"], "1.0.0");
    assert_eq!(
        m["runtime"]["library_path"],
        "../../target/release/libfovea_sim.so"
    );
}
