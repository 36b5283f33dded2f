//! `fovea report` and `fovea maps` for a headset given by its FOVs (`--fov`, `--fov-right`,
//! `--size`) instead of a preset.

use serde_json::Value;

use crate::maps::read_png;
use crate::support::fovea;

fn report_json(args: &[&str]) -> Value {
    let mut argv = vec!["report", "--json"];
    argv.extend(args);
    let r = fovea(&argv);
    assert!(r.ok(), "{argv:?}: {}", r.text());
    serde_json::from_str(&r.out).expect("report --json is JSON")
}

/// LOW's row: `(shaded fraction, full-rate radius)`.
fn low(v: &Value) -> (f64, Option<f64>) {
    let l = &v["levels"][1];
    assert_eq!(l["level"], "low");
    (
        l["shaded_fraction"].as_f64().unwrap(),
        l["full_rate_radius_deg"].as_f64(),
    )
}

#[test]
fn a_preset_given_by_its_fovs_and_size_reports_as_the_preset() {
    // Quest 3's left eye is 54° left, 40° right, 44° up, 55° down; the right eye is its mirror.
    let custom = report_json(&["--fov", "54,40,44,55", "--size", "2064x2240"]);
    let preset = report_json(&["--headset", "quest3"]);
    assert_eq!(custom["levels"], preset["levels"]);
    assert_eq!(custom["headset"], "custom");
    assert_eq!(custom["size"], serde_json::json!([2064, 2240]));
    assert_eq!(custom["size_from"], "--size");
    assert_eq!(custom["fov_deg"][1]["left"], 40.0);
    assert_eq!(custom["fov_deg"][1]["right"], 54.0);
    // Both eyes given: the same figures when they are the mirror images.
    let both = report_json(&[
        "--fov",
        "54,40,44,55",
        "--fov-right",
        "40,54,44,55",
        "--size",
        "2064x2240",
    ]);
    assert_eq!(both["levels"], preset["levels"]);
}

#[test]
fn without_size_the_eye_buffer_is_sized_from_the_fov_and_the_output_says_so() {
    let v = report_json(&["--fov", "45,45,45,45"]);
    assert_eq!(v["size"], serde_json::json!([2000, 2000]));
    assert_eq!(v["size_from"], "fov");
    assert_eq!(v["pixels_per_tangent"], 1000.0);
    let r = fovea(&["report", "--fov", "45,45,45,45"]);
    assert!(r.ok(), "{}", r.text());
    let mut lines = r.out.lines();
    assert_eq!(
        lines.next(),
        Some(
            "--fov 45.0,45.0,45.0,45.0 (right eye mirrored): 2000x2000 per eye, texel 32, \
             fragments up to 4x4, both eyes"
        )
    );
    assert_eq!(
        lines.next(),
        Some(
            "2000x2000 per eye from the FOV at 1000 pixels per unit tangent (no --size given; \
             --size WxH sets it)"
        )
    );
}

/// On a symmetric 85–90° headset LOW costs nothing (its floor is full resolution everywhere) and
/// saves almost nothing: the planar projection oversamples only the far corners enough for LOW to
/// halve them. Up to 86° it shades every fragment; at 90° it halves the corners beyond about 49.5°
/// from the centre, under 1% of the fragments.
#[test]
fn on_85_to_90_degree_headsets_low_saves_at_most_one_percent() {
    for (fov, size) in [
        ("42.5,42.5,42.5,42.5", "1840x1840"),
        ("43,43,43,43", "1872x1872"),
    ] {
        let v = report_json(&["--fov", fov, "--size", size]);
        assert_eq!(low(&v), (1.0, None), "{fov}: everything at full rate");
    }
    let v = report_json(&["--fov", "45,45,45,45", "--size", "2000x2000"]);
    let (shaded, radius) = low(&v);
    assert_eq!(shaded, 0.9908, "{v}");
    assert_eq!(radius, Some(49.467), "{v}");
    for level in v["levels"].as_array().unwrap() {
        if level["level"] == "low" || level["level"] == "none" {
            // No angular resolution lost anywhere.
            assert_eq!(level["min_relative_ppd"], 1.0, "{level}");
        }
    }
    // Quest 3 for contrast: LOW saves 17% there.
    let (quest3, _) = low(&report_json(&["--headset", "quest3"]));
    assert!((quest3 - 0.826).abs() < 0.001, "{quest3}");
}

#[test]
fn maps_draw_a_headset_given_by_its_fovs() {
    let dir = std::env::temp_dir().join(format!("fovea-custom-maps-{}", std::process::id()));
    let r = fovea(&[
        "maps",
        "--fov",
        "50,45,45,50",
        "--level",
        "high",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(r.ok(), "{}", r.text());
    let lines: Vec<&str> = r.out.lines().collect();
    assert_eq!(lines.len(), 3, "{}", r.out);
    assert!(
        lines[0].starts_with("note: --fov 50.0,45.0,45.0,50.0 (right eye mirrored): ")
            && lines[0].contains("from the FOV at 1000 pixels per unit tangent"),
        "{}",
        lines[0]
    );
    for eye in ["left", "right"] {
        let path = dir.join(format!("custom_high_{eye}.png"));
        assert!(r.out.contains(path.to_str().unwrap()), "{}", r.out);
        // tan 50° + tan 45° = 2.19 at 1000 px per tangent, rounded up to a multiple of 16.
        let (w, h, _) = read_png(&path);
        assert_eq!(w, 2192);
        assert!(h > 2192, "legend below the eye buffer");
    }
    std::fs::remove_dir_all(&dir).ok();
}
