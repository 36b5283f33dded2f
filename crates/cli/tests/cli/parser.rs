//! The command line itself: misspelt and unknown flags are refused with a suggestion and exit
//! status 2 before anything runs, each command's `--help` lists its flags and the values they
//! accept, and failures of a command that did run keep exit status 1.

use crate::support::fovea;

#[test]
fn a_misspelt_flag_is_refused_with_a_suggestion_and_status_2() {
    let r = fovea(&["report", "--headset", "quest3", "--texl", "16"]);
    assert_eq!(r.code, 2, "{}", r.text());
    assert!(r.out.is_empty(), "nothing ran: {}", r.out);
    assert!(
        r.err.contains("unexpected argument '--texl' found"),
        "{}",
        r.err
    );
    assert!(
        r.err.contains("a similar argument exists: '--texel'"),
        "{}",
        r.err
    );
    // `fov` has no --texel: refused all the same, where the old parser ran without a word.
    let r = fovea(&["fov", "--headset", "quest3", "--texl", "16"]);
    assert_eq!(r.code, 2, "{}", r.text());
    assert!(r.out.is_empty(), "{}", r.out);
    assert!(r.err.contains("'--texl'"), "{}", r.err);
    // A misspelt value gets a suggestion too.
    let r = fovea(&[
        "maps",
        "--headset",
        "quest3",
        "--level",
        "medum",
        "--out",
        "/tmp/x",
    ]);
    assert_eq!(r.code, 2, "{}", r.text());
    assert!(
        r.err.contains("a similar value exists: 'medium'"),
        "{}",
        r.err
    );
}

#[test]
fn quiet_is_gone_and_stray_arguments_are_refused() {
    for args in [
        &["demo", "--quiet"][..],
        &["report", "--headset", "quest3", "--quiet"],
        &["doctor", "--json"],
        &["install", "stray"],
        &["frobnicate"],
    ] {
        let r = fovea(args);
        assert_eq!(r.code, 2, "{args:?}: {}", r.text());
        assert!(r.err.starts_with("error: "), "{args:?}: {}", r.err);
    }
}

#[test]
fn values_are_checked_and_the_accepted_ones_named() {
    for (args, needle) in [
        (
            &["demo", "--via", "bus"][..],
            "[possible values: loader, harness]",
        ),
        (&["demo", "--seconds", "0"], "0 is not in 1.."),
        (&["demo", "--headset", "vive"], "[possible values: quest2"),
        (
            &[
                "maps",
                "--headset",
                "quest3",
                "--level",
                "low",
                "--vertical-offset",
                "inf",
                "--out",
                "/tmp/x",
            ],
            "expected a finite number of degrees",
        ),
        (
            &["report", "--headset", "quest3", "--texel", "1025"],
            "1025 is not in 1..=1024",
        ),
        (
            &["report", "--fov", "45,45,45"],
            "expected four half-angles in degrees: left,right,up,down",
        ),
        (
            &["report", "--fov", "45,45,90,45"],
            "up 90°: expected a half-angle above 0° and below 90°",
        ),
        (
            &["report", "--fov", "45,45,45,45", "--size", "2000"],
            "expected WIDTHxHEIGHT in pixels",
        ),
        // One headset or the other, and --size only with --fov.
        (
            &["report", "--headset", "quest3", "--fov", "45,45,45,45"],
            "cannot be used with",
        ),
        (
            &[
                "maps",
                "--size",
                "2000x2000",
                "--level",
                "low",
                "--out",
                "/tmp/x",
            ],
            "--fov <L,R,U,D>",
        ),
        (&["report"], "--headset <NAME>"),
    ] {
        let r = fovea(args);
        assert_eq!(r.code, 2, "{args:?}: {}", r.text());
        assert!(r.out.is_empty(), "{args:?}: {}", r.out);
        assert!(r.err.contains(needle), "{args:?}: {}", r.err);
    }
    // Accepted spellings of the old parser still work: level indices and negative offsets.
    let dir = std::env::temp_dir().join(format!("fovea-parser-{}", std::process::id()));
    let r = fovea(&[
        "maps",
        "--headset",
        "rift-cv1",
        "--level",
        "4",
        "--vertical-offset",
        "-5",
        "--eye",
        "left",
        "--texel",
        "64",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(r.ok(), "{}", r.text());
    assert!(dir.join("rift-cv1_high-top_left.png").is_file());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn each_command_has_help_listing_its_flags() {
    for (command, flags) in [
        (
            "demo",
            &[
                "--via",
                "--seconds",
                "--headset",
                "--out",
                "- loader:",
                "- harness:",
            ][..],
        ),
        (
            "maps",
            &[
                "--headset",
                "--fov",
                "--fov-right",
                "--size",
                "--level",
                "--vertical-offset",
                "--eye",
                "--texel",
                "--out",
                "none, low, medium, high, high-top",
                "left, right, both",
                "quest2, quest3, quest-pro, rift-cv1, rift-s, index, pico4",
            ],
        ),
        (
            "report",
            &[
                "--headset",
                "--fov",
                "--fov-right",
                "--size",
                "--texel",
                "--json",
                "1000 pixels per unit tangent",
            ],
        ),
        ("fov", &["--headset", "--json"]),
        ("install", &["--implicit", "--system"]),
        ("uninstall", &["--implicit", "--system"]),
        ("doctor", &["Usage: fovea doctor"]),
    ] {
        for help in [vec![command, "--help"], vec!["help", command]] {
            let r = fovea(&help);
            assert_eq!(r.code, 0, "{help:?}: {}", r.text());
            assert!(
                r.out.contains(&format!("Usage: fovea {command}")),
                "{help:?}: {}",
                r.out
            );
            for flag in flags {
                assert!(r.out.contains(flag), "{help:?} lacks {flag}:\n{}", r.out);
            }
        }
    }
}

#[test]
fn the_top_level_lists_the_commands() {
    let r = fovea(&["--help"]);
    assert_eq!(r.code, 0, "{}", r.text());
    for command in [
        "demo",
        "maps",
        "report",
        "fov",
        "install",
        "uninstall",
        "doctor",
    ] {
        assert!(r.out.contains(&format!("  {command} ")), "{}", r.out);
    }
    // No command at all: the same list on stderr, and a usage error.
    let r = fovea(&[]);
    assert_eq!(r.code, 2, "{}", r.text());
    assert!(r.err.contains("Usage: fovea <COMMAND>"), "{}", r.err);
}

/// `fovea report --json | head -c1`: a reader that closed its end is not an error of `fovea`'s,
/// and the command ends quietly as other Unix tools do, instead of panicking on the broken pipe.
/// The peer is closed before `fovea` starts, so its first write always meets a closed reader.
#[test]
fn output_into_a_closed_pipe_ends_quietly() {
    use std::os::unix::net::UnixStream;
    use std::os::unix::process::ExitStatusExt;
    use std::process::Stdio;

    let (ours, theirs) = UnixStream::pair().expect("socket pair");
    drop(ours);
    let out = crate::support::command()
        .args(["report", "--headset", "quest3", "--json"])
        .stdout(Stdio::from(std::os::fd::OwnedFd::from(theirs)))
        .stderr(Stdio::piped())
        .output()
        .expect("run fovea");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(
        out.status.signal(),
        Some(13),
        "ended by SIGPIPE: {:?} {err}",
        out.status
    );
}
