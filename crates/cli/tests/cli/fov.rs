//! `fovea fov`: the JSON keys and values, and clear errors.

use crate::support::fovea;

#[test]
fn fov_json_for_the_rift_reproduces_the_asymmetric_fov_faq() {
    let r = fovea(&["fov", "--headset", "rift-cv1", "--json"]);
    assert!(r.ok(), "{}", r.err);
    let out = &r.out;
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
    let r = fovea(&["fov", "--headset", "quest9"]);
    assert_eq!(r.code, 2, "{}", r.err);
    assert!(
        r.err
            .contains("quest2, quest3, quest-pro, rift-cv1, rift-s, index, pico4"),
        "{}",
        r.err
    );
    let r = fovea(&["fov"]);
    let (ok, err) = (r.ok(), r.err);
    assert!(
        !ok && err
            .contains("the following required arguments were not provided:\n  --headset <NAME>"),
        "{err}"
    );
}
