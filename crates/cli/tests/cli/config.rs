//! `fovea config`: the settings in force for an application and where each comes from, and
//! `--check`, which names each bad line of the file and exits with status 1.

use crate::support::{command, run};

fn with_file(name: &str, text: &str) -> (std::path::PathBuf, std::process::Command) {
    let dir = std::env::temp_dir().join(format!("fovea-cli-config-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let file = dir.join("fovea/fovea.toml");
    std::fs::create_dir_all(file.parent().unwrap()).unwrap();
    std::fs::write(&file, text).unwrap();
    let mut c = command();
    c.env("XDG_CONFIG_HOME", &dir)
        .env_remove("DEBUG_OCULUS_FOVEATION_LEVEL")
        .env_remove("DEBUG_OCULUS_FOVEATION_SUBSAMPLED")
        .env_remove("FOVEA_SUBSAMPLED")
        .env_remove("FOVEA_MAX_FRAGMENT")
        .env_remove("FOVEA_LOG");
    (file, c)
}

#[test]
fn config_shows_each_value_and_its_source() {
    let (file, mut c) = with_file(
        "show",
        "level = \"low\"\n[engine.\"Unity\"]\nmax_fragment = 2\n[app.\"hello_xr\"]\nlevel = \"high\"\n",
    );
    let r = run(c
        .args(["config", "--app", "hello_xr", "--engine", "Unity"])
        .env("FOVEA_LOG", "info"));
    assert!(r.ok(), "{}", r.text());
    let f = file.display().to_string();
    let line = |key: &str| {
        r.out
            .lines()
            .find(|l| l.starts_with(&format!("{key} ")))
            .unwrap_or_else(|| panic!("{key} in {}", r.out))
            .to_string()
    };
    assert!(
        line("level").contains("high")
            && line("level").contains(&format!("{f}:5 ([app.\"hello_xr\"])")),
        "{}",
        r.out
    );
    assert!(
        line("max_fragment").contains("2x2") && line("max_fragment").contains("[engine.\"Unity\"]")
    );
    assert!(line("log").contains("environment FOVEA_LOG"));
    assert!(line("symmetric_fov").contains("default"));
    assert!(r.out.contains("matching sections, least specific first: global, [engine.\"Unity\"], [app.\"hello_xr\"]"), "{}", r.out);
    // Another application gets the global section only.
    let (_, mut c) = with_file("other", "level = \"low\"\n[app.\"hello_xr\"]\nlevel = 3\n");
    let r = run(c.args(["config", "--app", "other"]));
    assert!(
        r.out
            .lines()
            .any(|l| l.starts_with("level ") && l.contains("low")),
        "{}",
        r.out
    );
}

/// `subsampled` is per application like `inject`; Quest's `debug.oculus.foveation.subsampled`
/// wins over it, and the output says so.
#[test]
fn config_shows_subsampled_per_app_and_the_property_over_it() {
    let (file, mut c) = with_file(
        "subsampled",
        "subsampled = \"off\"\n[app.\"game\"]\nsubsampled = \"on\"\n",
    );
    let row = |out: &str| {
        out.lines()
            .find(|l| l.starts_with("subsampled "))
            .unwrap_or_else(|| panic!("subsampled in {out}"))
            .to_string()
    };
    let value = |out: &str| row(out).split_whitespace().nth(1).unwrap().to_string();
    let r = run(c.args(["config", "--app", "game"]));
    assert!(r.ok(), "{}", r.text());
    let f = file.display().to_string();
    assert!(
        value(&r.out) == "on" && row(&r.out).contains(&format!("{f}:3 ([app.\"game\"])")),
        "{}",
        r.out
    );
    assert!(
        !r.out.contains("DEBUG_OCULUS_FOVEATION_SUBSAMPLED"),
        "{}",
        r.out
    );
    let (_, mut c) = with_file("subsampled-env", "");
    let r = run(c
        .args(["config", "--app", "game"])
        .env("FOVEA_SUBSAMPLED", "0")
        .env("DEBUG_OCULUS_FOVEATION_SUBSAMPLED", "1"));
    assert!(
        value(&r.out) == "off" && row(&r.out).contains("environment FOVEA_SUBSAMPLED"),
        "{}",
        r.out
    );
    assert!(
        r.out.contains(
            "DEBUG_OCULUS_FOVEATION_SUBSAMPLED=1: debug.oculus.foveation.subsampled wins over \
             subsampled"
        ),
        "{}",
        r.out
    );
    let (_, mut c) = with_file("subsampled-default", "");
    let r = run(c.args(["config"]));
    assert!(
        row(&r.out).contains("as the application asks; on for injected passes")
            && row(&r.out).contains("default"),
        "{}",
        r.out
    );
}

#[test]
fn config_check_names_file_line_key_and_accepted_values() {
    let (file, mut c) = with_file(
        "check",
        "level = 2\nmax_fragment = 3\nvertical_offset = 0,5\n",
    );
    let r = run(c.args(["config", "--check"]));
    assert_eq!(r.code, 1, "{}", r.text());
    let problems: Vec<&str> = r
        .out
        .lines()
        .filter(|l| l.starts_with("problem: "))
        .collect();
    assert_eq!(problems.len(), 2, "{}", r.out);
    let f = file.display().to_string();
    assert!(
        problems[0].contains(&format!("{f}:2: max_fragment")) && problems[0].contains("1, 2 or 4")
    );
    assert!(problems[1].contains(&format!("{f}:3: -: not TOML")));
    let (_, mut c) = with_file("good", "level = 2\n");
    let r = run(c.args(["config", "--check"]));
    assert!(r.ok(), "{}", r.text());
    assert!(r.out.contains("ok"));
}

#[test]
fn config_shows_the_gaze_settings_per_app() {
    let (file, mut c) = with_file(
        "gaze",
        "gaze_hold_s = 0.5\n[app.\"late\"]\ngaze_attach_after_s = \"never\"\ngaze_fixation_m = 0.05\n",
    );
    let r = run(c
        .args(["config", "--app", "late"])
        .env_remove("FOVEA_GAZE")
        .env("FOVEA_GAZE_BETA", "0.2"));
    let f = file.display().to_string();
    let line = |key: &str| {
        r.out
            .lines()
            .find(|l| l.starts_with(&format!("{key} ")))
            .unwrap_or_else(|| panic!("{key} in {}", r.out))
            .to_string()
    };
    assert!(
        line("gaze").contains("on") && line("gaze").contains("default"),
        "{}",
        r.out
    );
    assert!(line("gaze_hold_s").contains("0.5") && line("gaze_hold_s").contains(&format!("{f}:1")));
    assert!(
        line("gaze_attach_after_s").contains("never")
            && line("gaze_attach_after_s").contains("[app.\"late\"]"),
        "{}",
        r.out
    );
    assert!(
        line("gaze_beta").contains("0.2")
            && line("gaze_beta").contains("environment FOVEA_GAZE_BETA")
    );
    assert!(line("gaze_fixation_m").contains("1 ") && line("gaze_fixation_m").contains("default"));
    assert!(r.out.contains("(1 problems;"), "{}", r.out);
    let (_, mut c) = with_file(
        "gaze-check",
        "[app.\"late\"]\ngaze_attach_after_s = \"never\"\ngaze_fixation_m = 0.05\n",
    );
    let r = run(c.args(["config", "--check"]));
    assert!(!r.ok());
    assert!(
        r.text().contains("gaze_fixation_m") && r.text().contains("metres from 0.1 to 100"),
        "the bad value is named with what it accepts: {}",
        r.text()
    );
}
