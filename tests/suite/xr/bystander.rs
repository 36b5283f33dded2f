//! Do no harm: an application that enables nothing fovea provides sees the same runtime with fovea
//! as without it (docs/eye-tracking.md#who-uses-the-gaze). On the simulated runtime with its eye
//! tracker on, hello_xr-like applications (no input; their own controller set; their own eye gaze
//! binding with `XR_EXT_eye_gaze_interaction` enabled by themselves) run the same frames with and
//! without fovea, and the runtime's call journals are identical, call for call, apart from the calls
//! the docs list ([`LISTED`]).

use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::{HeadlessLoop, SwapchainSpec};
use fovea_harness::{sim, App, Chain};
use openxr_sys as xr;

use crate::support::actions::{attach_set, declare, sync_set};
use crate::support::in_own_process;

/// The calls fovea makes below in an instance that uses nothing of its own, as
/// docs/eye-tracking.md#who-uses-the-gaze lists them: `xrGetInstanceProperties`, once, for the
/// runtime's name in the log's instance header.
const LISTED: [&str; 1] = ["xrGetInstanceProperties"];

/// What an application does besides its frames.
#[derive(Clone, Copy, Debug)]
enum Input {
    /// No input at all.
    None,
    /// Its own action set bound to a controller, attached and synced every frame.
    Controller,
    /// `XR_EXT_eye_gaze_interaction` enabled by itself, its own action bound to the gaze.
    OwnGaze,
}

/// One journal entry as compared: the command, its result, its chain and its details.
type Entry = (&'static str, xr::Result, Vec<xr::StructureType>, String);

/// Runs the application through `chain` for 120 frames on the simulated Quest 3 with an eye
/// tracker, polling events every frame as applications do; the runtime's journal of its instance.
fn journal(chain: Chain, input: Input) -> Vec<Entry> {
    let mut cfg =
        sim::control::SimConfig::for_headset(fovea_model::headsets::by_id("quest3").unwrap());
    cfg.eye_gaze = Some(sim::control::EyeGaze {
        supported: true,
        space_after_attach: false,
        script: sim::gaze_script::GazeScript::parse("fix 5,5 for 10s").unwrap(),
    });
    sim::control::set_thread_config(Some(cfg));
    let mut exts = vec!["XR_MND_headless"];
    if matches!(input, Input::OwnGaze) {
        exts.push("XR_EXT_eye_gaze_interaction");
    }
    let app = App::new(chain, &exts, API_1_0).unwrap();
    let declared = match input {
        Input::None => None,
        Input::Controller => Some(declare(&app, false)),
        Input::OwnGaze => Some(declare(&app, true)),
    };
    let mut lp = HeadlessLoop::new(
        app,
        SwapchainSpec {
            foveation: false,
            array_size: 2,
        },
    )
    .unwrap();
    // SAFETY: the type matches the name.
    let sync: xr::pfn::SyncActions = unsafe { lp.func(c"xrSyncActions") };
    if let Some((set, _)) = declared {
        attach_set(&lp, set);
    }
    for _ in 0..120 {
        lp.poll_events();
        if let Some((set, _)) = declared {
            sync_set(&lp, sync, set);
        }
        lp.frame().unwrap();
    }
    let instance = lp.app.instance;
    drop(lp);
    sim::control::journal(instance)
        .into_iter()
        .filter(|c| !LISTED.contains(&c.function))
        .map(|c| (c.function, c.result, c.next_types, normalise(&c.detail)))
        .collect()
}

/// A detail with the runtime's handle values (`0x…`, counting up across the process) blanked.
fn normalise(detail: &str) -> String {
    let mut out = String::with_capacity(detail.len());
    let mut rest = detail;
    while let Some(i) = rest.find("0x") {
        out.push_str(&rest[..i]);
        out.push_str("0x#");
        rest = rest[i + 2..].trim_start_matches(|c: char| c.is_ascii_hexdigit());
    }
    out.push_str(rest);
    out
}

fn same_journal(input: Input) {
    let bare = journal(Chain::bare(), input);
    let fovea = journal(Chain::fovea().unwrap(), input);
    let first = bare.iter().zip(&fovea).position(|(a, b)| a != b);
    assert!(
        bare.len() == fovea.len() && first.is_none(),
        "{input:?}: the runtime saw {} calls without fovea, {} with; first difference at {:?}:\n\
         without: {:?}\nwith:    {:?}\nfovea's calls named nowhere: {:?}",
        bare.len(),
        fovea.len(),
        first,
        first.and_then(|i| bare.get(i)),
        first.and_then(|i| fovea.get(i)),
        fovea
            .iter()
            .filter(|c| !bare.iter().any(|b| b.0 == c.0))
            .map(|c| c.0)
            .collect::<std::collections::BTreeSet<_>>(),
    );
    assert!(bare.iter().filter(|c| c.0 == "xrEndFrame").count() == 120);
}

#[test]
fn an_app_without_input_sees_the_same_runtime() {
    in_own_process(
        module_path!(),
        "an_app_without_input_sees_the_same_runtime",
        || same_journal(Input::None),
    );
}

#[test]
fn an_app_with_its_own_controller_set_sees_the_same_runtime() {
    in_own_process(
        module_path!(),
        "an_app_with_its_own_controller_set_sees_the_same_runtime",
        || same_journal(Input::Controller),
    );
}

#[test]
fn an_app_with_its_own_eye_gaze_sees_the_same_runtime() {
    in_own_process(
        module_path!(),
        "an_app_with_its_own_eye_gaze_sees_the_same_runtime",
        || same_journal(Input::OwnGaze),
    );
}

#[test]
fn the_listed_calls_are_fovea_s_only_difference() {
    // The list is not a blanket: each listed call is one fovea makes at most once per instance.
    in_own_process(
        module_path!(),
        "the_listed_calls_are_fovea_s_only_difference",
        || {
            sim::control::set_thread_config(None);
            let app = App::new(Chain::fovea().unwrap(), &["XR_MND_headless"], API_1_0).unwrap();
            let instance = app.instance;
            drop(app);
            let listed = sim::control::journal(instance)
                .iter()
                .filter(|c| LISTED.contains(&c.function))
                .count();
            assert_eq!(listed, 1);
        },
    );
}
