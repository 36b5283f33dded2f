//! `fovea report` and `fovea maps` for the presets: the JSON figures, the PNGs' size, colours and
//! legend, and clear errors.

use crate::support::fovea;

#[test]
fn report_json_lists_every_level_with_its_figures() {
    let r = fovea(&["report", "--headset", "quest3", "--texel", "32", "--json"]);
    assert!(r.ok(), "{}", r.err);
    let v: serde_json::Value = serde_json::from_str(&r.out).expect("report --json is JSON");
    assert_eq!(v["headset"], "quest3");
    assert_eq!(v["texel"], 32);
    let levels = v["levels"].as_array().expect("levels");
    let names: Vec<&str> = levels
        .iter()
        .map(|l| l["level"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["none", "low", "medium", "high", "high-top"]);
    let shaded: Vec<f64> = levels
        .iter()
        .map(|l| l["shaded_fraction"].as_f64().unwrap())
        .collect();
    assert_eq!(shaded[0], 1.0);
    assert!(shaded[0] > shaded[1] && shaded[1] > shaded[2] && shaded[2] > shaded[3]);
    // The reference figures for Quest 3 at texel 32.
    for (i, want) in [(1, 0.83), (2, 0.28), (3, 0.14)] {
        assert!(
            (shaded[i] - want).abs() < 0.03,
            "{}: {}",
            names[i],
            shaded[i]
        );
    }
    assert!(levels[0]["full_rate_radius_deg"].is_null());
    let radius = |i: usize| levels[i]["full_rate_radius_deg"].as_f64().unwrap();
    assert!((radius(2) - 20.0).abs() < 1.0 && (radius(3) - 15.0).abs() < 1.0);
    for l in levels {
        assert!(l["min_relative_ppd"].as_f64().unwrap() > 0.0);
        assert!(l["min_relative_ppd_within_15deg"].as_f64().unwrap() >= 1.0 - 1e-9);
    }
}

pub fn read_png(path: &std::path::Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::fs::File::open(path).expect("png written"));
    let mut reader = decoder.read_info().expect("png header");
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).expect("png data");
    assert_eq!(info.color_type, png::ColorType::Rgb);
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

#[test]
fn maps_draw_each_level_in_metas_colours() {
    let dir = std::env::temp_dir().join(format!("fovea-maps-{}", std::process::id()));
    let out = dir.to_str().unwrap();
    for (level, centre, corner) in [
        ("none", [255, 255, 255], [255, 255, 255]),
        // MEDIUM's floor beyond 20° is 1/2 per axis, and the planar projection oversamples Quest 3's
        // corners by more than 2× per axis, so they reach 4×4 too.
        ("medium", [255, 255, 255], [220, 40, 220]),
        ("high", [255, 255, 255], [220, 40, 220]),
    ] {
        let r = fovea(&[
            "maps",
            "--headset",
            "quest3",
            "--level",
            level,
            "--eye",
            "both",
            "--out",
            out,
        ]);
        assert!(r.ok(), "{}", r.err);
        assert_eq!(r.out.lines().count(), 2, "{}", r.out);
        for eye in ["left", "right"] {
            let (w, h, rgb) = read_png(&dir.join(format!("quest3_{level}_{eye}.png")));
            assert_eq!(w, 2064, "recommended width");
            assert!(h > 2240, "legend below the 2240-row eye buffer");
            let px = |x: u32, y: u32| rgb[((y * w + x) * 3) as usize..][..3].to_vec();
            // Quest 3's left eye sees 54° left and 40° right: its projection centre is right of
            // the image centre (x = 0.58 w), the right eye's mirrored. 60 px beside it (the cross).
            let cx = if eye == "left" {
                w * 58 / 100
            } else {
                w * 42 / 100
            };
            assert_eq!(
                px(cx + 60, 2240 * 45 / 100),
                centre,
                "{level} {eye} near the fovea"
            );
            // The temporal top corner: top-left for the left eye, top-right for the right.
            let temporal = if eye == "left" { 4 } else { w - 5 };
            assert_eq!(px(temporal, 4), corner, "{level} {eye} temporal top corner");
            // Legend: the last cell is black ("not shown"), the first white.
            assert_eq!(px(4, h - 2), [255, 255, 255]);
            assert_eq!(px(w - 2, h - 2), [0, 0, 0]);
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn maps_and_report_reject_bad_arguments_clearly() {
    for (args, needle) in [
        (
            &[
                "maps",
                "--headset",
                "quest3",
                "--level",
                "ultra",
                "--out",
                "/tmp/x",
            ][..],
            "invalid value 'ultra' for '--level <LEVEL>'\n  [possible values: none, low, medium, high, high-top]",
        ),
        (
            &[
                "maps",
                "--headset",
                "quest3",
                "--level",
                "low",
                "--eye",
                "middle",
                "--out",
                "/tmp/x",
            ],
            "invalid value 'middle' for '--eye <EYE>'\n  [possible values: left, right, both]",
        ),
        (
            &["maps", "--headset", "quest3", "--level", "low"],
            "not provided:\n  --out <DIR>",
        ),
        (
            &["report", "--headset", "quest3", "--texel", "0"],
            "invalid value '0' for '--texel <N>': 0 is not in 1..=1024",
        ),
        (
            &["report", "--headset", "vive"],
            "[possible values: quest2, quest3, quest-pro, rift-cv1, rift-s, index, pico4]",
        ),
    ] {
        let r = fovea(args);
        assert_eq!(r.code, 2, "{args:?}: a usage error\n{}", r.text());
        assert!(r.out.is_empty(), "{args:?}: {}", r.out);
        assert!(r.err.contains(needle), "{args:?}: {}", r.err);
    }
}

/// What each level shades under each `max_fragment` cap on Quest 3 at texel 32 (the README's
/// table): 4 is the default and gives the figures above, 2 is Quest 3's own palette (full rate and
/// 2×2), 1 turns foveation off.
#[test]
fn report_pins_what_each_level_shades_under_each_max_fragment() {
    let r = fovea(&["report", "--headset", "quest3", "--texel", "32", "--json"]);
    assert!(r.ok(), "{}", r.err);
    let v: serde_json::Value = serde_json::from_str(&r.out).unwrap();
    let got: Vec<[f64; 3]> = v["levels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| ["4", "2", "1"].map(|c| l["shaded_by_max_fragment"][c].as_f64().unwrap()))
        .collect();
    let want = [
        [1.0, 1.0, 1.0],
        [0.826, 0.826, 1.0],
        [0.273, 0.316, 1.0],
        [0.140, 0.287, 1.0],
        [0.144, 0.289, 1.0],
    ];
    for (g, w) in got.iter().zip(want) {
        for (a, b) in g.iter().zip(w) {
            assert!((a - b).abs() < 0.0005, "{got:?}");
        }
    }
    let text = fovea(&["report", "--headset", "quest3"]);
    assert!(
        text.out.contains("shaded under each max_fragment cap"),
        "{}",
        text.out
    );
    assert!(
        text.out.contains("high         0.140    0.287    1.000"),
        "{}",
        text.out
    );
}
