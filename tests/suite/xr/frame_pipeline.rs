//! The frame pipeline through the harness on the simulated Quest 3 with scripted GPU load: the
//! dynamic level rises under overload and falls back with headroom, the stats line comes once a
//! second of display time, and a FOVEA_PROPS override takes effect while the app runs. The layer's
//! log goes to a file (FOVEA_LOG_FILE), which is what the test reads; one test function, in a
//! process of its own, since the log is set up once per process from the environment it sets.

use std::path::Path;

use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::{HeadlessLoop, FOVEATION_EXTENSIONS};
use fovea_harness::{sim, App, Chain};
use openxr_sys as xr;

use crate::support::{foveated_loop, in_own_process};

fn running(load: &[(u64, f32)]) -> HeadlessLoop {
    let mut cfg =
        sim::control::SimConfig::for_headset(fovea_model::headsets::by_id("quest3").unwrap());
    cfg.journal = false;
    cfg.load = sim::control::Load {
        gpu_ms: load.to_vec(),
    };
    sim::control::set_thread_config(Some(cfg));
    let app = App::new(Chain::fovea().unwrap(), &FOVEATION_EXTENSIONS, API_1_0).unwrap();
    foveated_loop(app)
}

/// The log lines after `from` bytes.
fn lines_since(log: &Path, from: usize) -> Vec<String> {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    text[from.min(text.len())..]
        .lines()
        .map(String::from)
        .collect()
}

fn fov_values(lines: &[String]) -> Vec<String> {
    lines
        .iter()
        .filter(|l| l.contains(fovea_abi::log_target::STATS))
        .map(|l| {
            let at = l.find("Fov=").expect("Fov= in the stats line") + 4;
            l[at..].split(' ').next().unwrap().to_string()
        })
        .collect()
}

#[test]
fn dynamic_level_stats_and_live_overrides() {
    in_own_process(
        module_path!(),
        "dynamic_level_stats_and_live_overrides",
        dynamic_level_stats_and_live_overrides_here,
    );
}

fn dynamic_level_stats_and_live_overrides_here() {
    let dir = std::env::temp_dir().join(format!("fovea-pipeline-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join("fovea.log");
    let props = dir.join("foveation.props");
    std::fs::write(&props, "").unwrap();
    std::env::set_var(
        "FOVEA_LOG",
        format!(
            "warn,{}=info,{}=info",
            fovea_abi::log_target::STATS,
            fovea_abi::log_target::DYNAMIC
        ),
    );
    std::env::set_var("FOVEA_LOG_FILE", &log);
    std::env::set_var("FOVEA_PROPS", &props);

    // Phase 1: 6 ms per frame (headroom at 90 Hz), 14 ms from frame 200 (every frame misses a
    // period), 6 ms again from frame 600. 1500 frames of virtual time, no sleeping.
    let mut lp = running(&[(0, 6.0), (200, 14.0), (600, 6.0)]);
    lp.apply_profile(
        xr::FoveationLevelFB::HIGH,
        xr::FoveationDynamicFB::LEVEL_ENABLED,
    )
    .unwrap();
    for _ in 0..1500 {
        lp.frame().unwrap();
    }
    let lines = lines_since(&log, 0);
    let stats: Vec<&String> = lines
        .iter()
        .filter(|l| l.contains(fovea_abi::log_target::STATS))
        .collect();
    // 200 frames at 90 Hz, 400 at 45 Hz, 900 at 90 Hz: 2.2 + 8.9 + 10 s of display time.
    assert!(
        (19..=22).contains(&stats.len()),
        "{} stats lines",
        stats.len()
    );
    assert!(
        stats[0].contains("FPS=90/90") && stats[0].contains("Miss=0"),
        "{}",
        stats[0]
    );
    assert!(
        stats
            .iter()
            .any(|l| l.contains("FPS=45/90") && l.contains("Miss=45")),
        "overload shows in the stats"
    );
    let fov = fov_values(&lines);
    let changes: Vec<&String> = fov.iter().fold(Vec::new(), |mut v, f| {
        if v.last() != Some(&f) {
            v.push(f);
        }
        v
    });
    assert_eq!(
        changes,
        ["0D", "1D", "2D", "3D", "2D", "1D", "0D"],
        "the level rises to HIGH under overload, one step a second, and falls back: {fov:?}"
    );
    let steps: Vec<&String> = lines
        .iter()
        .filter(|l| l.contains("dynamic foveation"))
        .collect();
    assert_eq!(
        steps.len(),
        6,
        "exactly six changes, never two within the dwell"
    );

    // Phase 2: an override file written while the app runs, with one bad line.
    let mark = std::fs::read_to_string(&log).unwrap().len();
    std::fs::write(
        &props,
        "debug.oculus.foveation.level=2\ndebug.oculus.foveation.dynamic=0\n\
         debug.oculus.foveation.subsampled=maybe\n",
    )
    .unwrap();
    for _ in 0..300 {
        lp.frame().unwrap();
    }
    let lines = lines_since(&log, mark);
    let fov = fov_values(&lines);
    assert!(fov.len() >= 2);
    assert_eq!(
        fov.last().unwrap(),
        "2",
        "the override's level, not dynamic: {fov:?}"
    );
    let warnings: Vec<&String> = lines
        .iter()
        .filter(|l| l.contains("bad value for a debug property"))
        .collect();
    assert_eq!(
        warnings.len(),
        1,
        "one warning for the bad value: {lines:?}"
    );
    assert!(warnings[0].contains("debug.oculus.foveation.subsampled"));
    assert!(warnings[0].contains("0 or 1"));
    drop(lp);
    std::fs::remove_dir_all(&dir).ok();
}
