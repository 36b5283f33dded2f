use super::*;

const EXAMPLE: &str = r#"
# global
level = "low"
max_fragment = 4
log = "warn"

[engine."Unity"]
level = "medium"
vertical_offset = -5.5

[exe."hello_xr"]
level = 3
dynamic = true

[app."hello_xr"]
level = "high-top"
symmetric_fov = "on"
inject = true
inject_level = "medium"
max_fragment = 2
"#;

fn id(app: Option<&str>, exe: Option<&str>, engine: Option<&str>) -> Identity {
    Identity {
        app: app.map(String::from),
        exe: exe.map(String::from),
        engine: engine.map(String::from),
    }
}

fn no_env(_: &str) -> Option<String> {
    None
}

fn parsed(text: &str) -> Config {
    Config::parse(text, Path::new("/cfg/fovea.toml"))
}

#[test]
fn sections_parse_with_lines() {
    let c = parsed(EXAMPLE);
    assert!(c.problems.is_empty(), "{:?}", c.problems);
    let scopes: Vec<String> = c.sections.iter().map(|s| s.scope.header()).collect();
    assert_eq!(
        scopes,
        [
            "global",
            "[engine.\"Unity\"]",
            "[exe.\"hello_xr\"]",
            "[app.\"hello_xr\"]"
        ]
    );
    let g = &c.sections[0];
    assert_eq!(g.get(Key::Level).unwrap().value, Value::Level(Level::Low));
    assert_eq!(g.get(Key::Level).unwrap().line, 3);
    let unity = &c.sections[1];
    assert_eq!(
        unity.get(Key::VerticalOffset).unwrap().value,
        Value::Degrees(-5.5)
    );
    assert_eq!(unity.get(Key::VerticalOffset).unwrap().line, 9);
}

#[test]
fn the_most_specific_section_wins() {
    let c = parsed(EXAMPLE);
    // Global only.
    let (r, _) = resolve(Some(&c), &id(Some("other"), Some("x"), None), no_env);
    assert_eq!(r.level(Key::Level), Some(Level::Low));
    assert_eq!(r.max_fragment(), 4);
    assert_eq!(r.vertical_offset_deg(), None);
    // Engine over global.
    let (r, _) = resolve(Some(&c), &id(Some("game"), None, Some("Unity")), no_env);
    assert_eq!(r.level(Key::Level), Some(Level::Medium));
    assert_eq!(r.vertical_offset_deg(), Some(-5.5));
    assert_eq!(
        r.source(Key::Level),
        &Source::File {
            path: "/cfg/fovea.toml".into(),
            section: "[engine.\"Unity\"]".into(),
            line: 8
        }
    );
    // Executable over engine; the engine still fills in what the exe does not set.
    let (r, _) = resolve(
        Some(&c),
        &id(Some("game"), Some("hello_xr"), Some("Unity")),
        no_env,
    );
    assert_eq!(r.level(Key::Level), Some(Level::High));
    assert_eq!(r.flag(Key::Dynamic), Some(true));
    assert_eq!(r.vertical_offset_deg(), Some(-5.5));
    // Application name over everything.
    let (r, _) = resolve(
        Some(&c),
        &id(Some("hello_xr"), Some("hello_xr"), Some("Unity")),
        no_env,
    );
    assert_eq!(r.level(Key::Level), Some(Level::HighTop));
    assert_eq!(r.flag(Key::SymmetricFov), Some(true));
    assert_eq!(r.flag(Key::Inject), Some(true));
    assert_eq!(r.level(Key::InjectLevel), Some(Level::Medium));
    assert_eq!(r.max_fragment(), 2);
    assert_eq!(r.flag(Key::Dynamic), Some(true), "from the exe section");
    assert_eq!(r.text(Key::Log), Some("warn"), "from the global section");
    // Names match exactly.
    let (r, _) = resolve(Some(&c), &id(Some("Hello_XR"), None, Some("unity")), no_env);
    assert_eq!(r.level(Key::Level), Some(Level::Low));
}

#[test]
fn the_environment_wins_over_the_file() {
    let c = parsed(EXAMPLE);
    let env = |k: &str| match k {
        "DEBUG_OCULUS_FOVEATION_LEVEL" => Some("1".to_string()),
        "FOVEA_MAX_FRAGMENT" => Some("1".to_string()),
        "FOVEA_LOG_FILE" => Some(String::new()),
        "FOVEA_SYMMETRIC_FOV" => Some("perhaps".to_string()),
        _ => None,
    };
    let (r, bad) = resolve(Some(&c), &id(Some("hello_xr"), None, None), env);
    assert_eq!(r.level(Key::Level), Some(Level::Low));
    assert_eq!(
        r.source(Key::Level),
        &Source::Env("DEBUG_OCULUS_FOVEATION_LEVEL")
    );
    assert_eq!(r.max_fragment(), 1);
    assert_eq!(
        r.text(Key::LogFile),
        Some(""),
        "an empty variable turns the file off"
    );
    assert_eq!(
        r.flag(Key::SymmetricFov),
        Some(true),
        "a bad variable leaves the file's"
    );
    assert_eq!(bad.len(), 1);
    assert_eq!(bad[0].0, "FOVEA_SYMMETRIC_FOV");
}

#[test]
fn defaults_without_a_file() {
    let (r, bad) = resolve(None, &Identity::default(), no_env);
    assert!(bad.is_empty());
    assert_eq!(r.max_fragment(), DEFAULT_MAX_FRAGMENT);
    assert!(Key::ALL.iter().all(|k| r.get(*k).is_none()));
    assert!(Key::ALL.iter().all(|k| *r.source(*k) == Source::Default));
}

#[test]
fn bad_values_name_file_line_key_and_accepted_values_and_the_rest_applies() {
    let text = "level = \"ultra\"\nmax_fragment = 3\ndynamic = true\nvertical_offset = \"0,5\"\n\
                colour = 1\n[app.\"a\"]\nlevel = 2\ninject_level = 9\n[games.\"x\"]\nlevel = 1\n";
    let c = parsed(text);
    let lines: Vec<String> = c.problems.iter().map(ToString::to_string).collect();
    assert_eq!(c.problems.len(), 6, "{lines:#?}");
    let want = [
        (1, "level", "high-top"),
        (2, "max_fragment", "1, 2 or 4"),
        (4, "vertical_offset", "degrees"),
        (5, "colour", "max_fragment"),
        (8, "inject_level", "medium"),
        (9, "games", "[app."),
    ];
    for ((line, key, accepted), p) in want.iter().zip(&c.problems) {
        assert_eq!((p.line, p.key.as_str()), (*line, *key), "{p}");
        assert!(p.accepted.contains(accepted), "{p}");
        let s = p.to_string();
        assert!(
            s.starts_with(&format!("/cfg/fovea.toml:{line}: {key}: ")),
            "{s}"
        );
    }
    let (r, _) = resolve(Some(&c), &id(Some("a"), None, None), no_env);
    assert_eq!(r.flag(Key::Dynamic), Some(true), "the good lines apply");
    assert_eq!(r.level(Key::Level), Some(Level::Medium));
    assert_eq!(r.max_fragment(), DEFAULT_MAX_FRAGMENT);
}

#[test]
fn a_syntax_error_drops_its_line_only() {
    // `0,5` with a decimal comma, an unquoted string and a duplicate key: three broken lines.
    let text = "level = 2\nvertical_offset = 0,5\nlog = info\ndynamic = true\nlevel = 3\n\
                [app.\"b\"]\nmax_fragment = 2\n";
    let c = parsed(text);
    let lines: Vec<usize> = c.problems.iter().map(|p| p.line).collect();
    assert_eq!(lines, [2, 3, 5], "{:#?}", c.problems);
    assert!(c
        .problems
        .iter()
        .all(|p| p.key == "-" && p.message.starts_with("not TOML")));
    let (r, _) = resolve(Some(&c), &id(Some("b"), None, None), no_env);
    assert_eq!(r.level(Key::Level), Some(Level::Medium));
    assert_eq!(r.flag(Key::Dynamic), Some(true));
    assert_eq!(r.max_fragment(), 2);
    assert_eq!(r.vertical_offset_deg(), None);
}

#[test]
fn numbers_are_locale_free() {
    // Rust's float parsing reads only `.`; this is what a German LC_NUMERIC would print.
    let c = parsed("vertical_offset = 2.5\n[app.\"x\"]\nvertical_offset = -1e1\n");
    assert!(c.problems.is_empty());
    let (r, _) = resolve(Some(&c), &Identity::default(), no_env);
    assert_eq!(r.vertical_offset_deg(), Some(2.5));
    let (r, _) = resolve(Some(&c), &id(Some("x"), None, None), no_env);
    assert_eq!(r.vertical_offset_deg(), Some(-10.0));
    assert_eq!(parse_env(Key::VerticalOffset, "2,5"), None);
}

#[test]
fn paths_follow_xdg() {
    let env = |pairs: &'static [(&'static str, &'static str)]| {
        move |k: &str| pairs.iter().find(|p| p.0 == k).map(|p| OsString::from(p.1))
    };
    assert_eq!(
        config_path(env(&[("HOME", "/h")])),
        Some(PathBuf::from("/h/.config/fovea/fovea.toml"))
    );
    assert_eq!(
        config_path(env(&[("HOME", "/h"), ("XDG_CONFIG_HOME", "/c")])),
        Some(PathBuf::from("/c/fovea/fovea.toml"))
    );
    assert_eq!(
        config_path(env(&[("XDG_CONFIG_HOME", "rel"), ("HOME", "/h")])),
        Some(PathBuf::from("/h/.config/fovea/fovea.toml")),
        "a relative XDG path is ignored"
    );
    assert_eq!(
        config_path(env(&[("FOVEA_CONFIG", "/x.toml"), ("HOME", "/h")])),
        Some(PathBuf::from("/x.toml"))
    );
    assert_eq!(
        config_path(env(&[("FOVEA_CONFIG", ""), ("HOME", "/h")])),
        None
    );
    assert_eq!(
        default_log_path(env(&[("HOME", "/h")])),
        Some(PathBuf::from("/h/.local/state/fovea/fovea.log"))
    );
    assert_eq!(
        default_log_path(env(&[("XDG_STATE_HOME", "/s")])),
        Some(PathBuf::from("/s/fovea/fovea.log"))
    );
}

#[test]
fn gaze_keys_parse_per_app_with_their_ranges() {
    let c = parsed(
        r#"
gaze = false
gaze_hold_s = 0.5
[app."hello_xr"]
gaze = "on"
gaze_min_cutoff_hz = 2
gaze_beta = 0.05
gaze_d_cutoff_hz = 1.5
gaze_saccade_deg = 5.0
gaze_return_s = 0
gaze_fixation_m = 2.5
gaze_attach_after_s = "never"
[app."other"]
gaze_attach_after_s = 5
gaze_min_cutoff_hz = 0
gaze_fixation_m = 0.05
gaze_hold_s = "long"
"#,
    );
    let (r, _) = resolve(Some(&c), &id(Some("hello_xr"), None, None), no_env);
    assert_eq!(r.flag(Key::Gaze), Some(true));
    assert_eq!(r.number(Key::GazeMinCutoff), Some(2.0));
    assert_eq!(r.number(Key::GazeBeta), Some(0.05));
    assert_eq!(r.number(Key::GazeDCutoff), Some(1.5));
    assert_eq!(r.number(Key::GazeSaccade), Some(5.0));
    assert_eq!(
        r.number(Key::GazeHold),
        Some(0.5),
        "from the global section"
    );
    assert_eq!(r.number(Key::GazeReturn), Some(0.0));
    assert_eq!(r.number(Key::GazeFixation), Some(2.5));
    assert_eq!(r.get(Key::GazeAttachAfter), Some(&Value::Never));
    let (o, _) = resolve(Some(&c), &id(Some("other"), None, None), no_env);
    assert_eq!(o.flag(Key::Gaze), Some(false));
    assert_eq!(o.number(Key::GazeAttachAfter), Some(5.0));
    assert_eq!(o.number(Key::GazeMinCutoff), None, "0 Hz is refused");
    assert_eq!(o.number(Key::GazeFixation), None, "below 0.1 m is refused");
    let bad: Vec<&str> = c.problems.iter().map(|p| p.key.as_str()).collect();
    assert_eq!(
        bad,
        ["gaze_min_cutoff_hz", "gaze_fixation_m", "gaze_hold_s"],
        "{:?}",
        c.problems
    );
    let (e, wrong) = resolve(None, &id(None, None, None), |k| {
        (k == "FOVEA_GAZE_BETA").then(|| "-1".to_string())
    });
    assert_eq!(e.number(Key::GazeBeta), None);
    assert_eq!(wrong.len(), 1, "a bad variable is reported");
}

/// The table of keys in docs/settings.md: the lines from its header row to the first line that is
/// not a table row.
fn docs_table() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/settings.md");
    let md = std::fs::read_to_string(&path).unwrap();
    let start = md
        .find("| key | variable |")
        .expect("docs/settings.md has the table of keys");
    md[start..]
        .lines()
        .take_while(|l| l.starts_with('|'))
        .map(|l| format!("{l}\n"))
        .collect()
}

#[test]
fn the_docs_table_of_keys_is_the_table() {
    let want = markdown_table();
    assert!(
        docs_table() == want,
        "docs/settings.md's table of keys differs from crates/config/src/keys.rs; it should read:\n\n{want}"
    );
}

#[test]
fn every_key_has_one_row_and_its_default_is_a_value_it_accepts() {
    let mut names = std::collections::BTreeSet::new();
    let mut vars = std::collections::BTreeSet::new();
    for (i, key) in Key::ALL.into_iter().enumerate() {
        let s = key.spec();
        assert_eq!((key as usize, s.key), (i, key), "{}", s.name);
        assert!(names.insert(s.name), "{} twice", s.name);
        assert_eq!(Key::by_name(s.name), Some(key));
        assert!(
            s.name
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_'),
            "{}",
            s.name
        );
        if let Some(v) = s.env {
            assert!(vars.insert(v), "{v} twice");
        }
        assert!(!s.doc.is_empty() && !s.accepted.is_empty(), "{}", s.name);
        // A default that is a value reads back as itself: the table cannot default outside its
        // own range.
        if let Some(v) = s.default.value() {
            let text = match &v {
                Value::Text(t) => t.clone(),
                Value::Fragment(n) => n.to_string(),
                Value::Degrees(d) => d.to_string(),
                Value::Level(l) => l.name().to_owned(),
                other => other.to_string(),
            };
            assert_eq!(parse_env(key, &text), Some(v), "{}'s default", s.name);
        }
    }
    assert_eq!(names.len(), KEYS);
}

/// `subsampled` reads like the other switches, per section, with `FOVEA_SUBSAMPLED` above the file;
/// Quest's `DEBUG_OCULUS_FOVEATION_SUBSAMPLED` is not this key's variable (it is a debug override
/// the layer applies above the key).
#[test]
fn subsampled_is_a_switch_per_app_below_its_variable() {
    for (text, want) in [
        ("\"on\"", true),
        ("\"off\"", false),
        ("true", true),
        ("0", false),
    ] {
        let c = parsed(&format!("[app.\"game\"]\nsubsampled = {text}\n"));
        assert!(c.problems.is_empty(), "{text}: {:?}", c.problems);
        let (r, _) = resolve(Some(&c), &id(Some("game"), None, None), no_env);
        assert_eq!(r.flag(Key::Subsampled), Some(want), "{text}");
        let (r, _) = resolve(Some(&c), &id(Some("other"), None, None), no_env);
        assert_eq!(r.flag(Key::Subsampled), None, "{text}");
    }
    let c = parsed("subsampled = \"maybe\"\n");
    assert_eq!(c.problems.len(), 1);
    assert_eq!(c.problems[0].key, "subsampled");
    let c = parsed("subsampled = true\n");
    let env = |k: &str| (k == "FOVEA_SUBSAMPLED").then(|| "0".to_string());
    let (r, _) = resolve(Some(&c), &id(None, None, None), env);
    assert_eq!(r.flag(Key::Subsampled), Some(false));
    let debug = |k: &str| (k == env::DEBUG_SUBSAMPLED).then(|| "0".to_string());
    let (r, _) = resolve(Some(&c), &id(None, None, None), debug);
    assert_eq!(r.flag(Key::Subsampled), Some(true));
}
