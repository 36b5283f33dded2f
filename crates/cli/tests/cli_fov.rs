//! `fovea fov`: the JSON keys and values the issue names, from the built binary.

use std::process::Command;

fn fovea(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_fovea"))
        .args(args)
        .output()
        .expect("run fovea");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn fov_json_for_the_rift_reproduces_the_asymmetric_fov_faq() {
    let (ok, out, _) = fovea(&["fov", "--headset", "rift-cv1", "--json"]);
    assert!(ok);
    for key in [
        "\"eyes\":[",
        "\"eye\":\"left\"",
        "\"fov_deg\":{\"left\":43.977",
        "\"projection_center_ndc\":[0.14",
        "\"symmetric_pixel_saving\":0.21",
    ] {
        assert!(out.contains(key), "{key} missing in {out}");
    }
    assert!(
        out.contains("\"recommended\":{\"asymmetric\":[1344,1600],\"symmetric\":[1536,1776]}"),
        "{out}"
    );
}

#[test]
fn fov_names_the_accepted_headsets_on_a_bad_name() {
    let (ok, _, err) = fovea(&["fov", "--headset", "quest9"]);
    assert!(!ok);
    assert!(
        err.contains("quest2, quest3, quest-pro, rift-cv1, rift-s, index, pico4"),
        "{err}"
    );
    let (ok, _, err) = fovea(&["fov"]);
    assert!(
        !ok && err
            .contains("the following required arguments were not provided:\n  --headset <NAME>"),
        "{err}"
    );
}
