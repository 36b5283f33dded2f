//! Injection into eye passes and others, at every level and through every API, and nothing with
//! injection off.

use fovea_model::density::Level;
use fovea_model::inject::Views;
use fovea_vkdouble::Profile;
use serde_json::{json, Value};

use crate::support::in_own_process;

use super::app::*;
use super::outcome::*;

#[test]
fn injected_eye_passes_carry_the_models_codes_at_every_level() {
    check(
        module_path!(),
        "injected_eye_passes_carry_the_models_codes_at_every_level",
        Setup::Inject(Level::None),
        Api::Dynamic,
        &Level::ALL,
    );
}

#[test]
fn multiview_renderings_into_an_array_of_views_get_a_layered_or_merged_map() {
    check(
        module_path!(),
        "multiview_renderings_into_an_array_of_views_get_a_layered_or_merged_map",
        Setup::Inject(Level::None),
        Api::Multiview,
        &[Level::High],
    );
}

#[test]
fn render_pass_eye_passes_get_the_eye_map_and_others_the_full_rate_map() {
    check(
        module_path!(),
        "render_pass_eye_passes_get_the_eye_map_and_others_the_full_rate_map",
        Setup::Inject(Level::None),
        Api::RenderPass,
        &[Level::None, Level::High],
    );
}

#[test]
fn imageless_framebuffers_get_their_map_at_each_begin() {
    check(
        module_path!(),
        "imageless_framebuffers_get_their_map_at_each_begin",
        Setup::Inject(Level::None),
        Api::Imageless,
        &[Level::Medium],
    );
}

/// A map is refilled in place, once, when the published maps' key moves (here the level, through
/// the debug property file while the application runs), and the passes after it read the new
/// codes; nothing is refilled per pass.
#[test]
fn a_changed_level_refills_the_map_in_place_once() {
    in_own_process(
        module_path!(),
        "a_changed_level_refills_the_map_in_place_once",
        || {
            let (first, then) = (Level::Low, Level::High);
            for profile in [Profile::Nvidia, Profile::Amd] {
                let setup = Setup::Inject(first);
                let dir = set_up(&format!("refresh-{profile:?}"), setup);
                let Some(out) = run_with(profile, setup, Api::Dynamic, &dir, Some(then)) else {
                    return;
                };
                let what = format!("{profile:?}");
                assert_outcome(profile, setup, Api::Dynamic, &out);
                let cb2 = out.second.expect("a second command buffer");
                let before = out.rates(Api::Dynamic)[0]["view"].clone();
                let after: Vec<&Value> = out
                    .of("begin_rendering")
                    .into_iter()
                    .filter(|b| b["command_buffer"] == json!(cb2))
                    .collect();
                assert_eq!(after.len(), 2, "{what}: {after:?}");
                for b in &after {
                    assert_eq!(b["shading_rate"]["view"], before, "{what}: the same map");
                }
                let image = out.image_of(&before);
                let views = Views::Layers { first: 0, count: 1 };
                let old = out.codes_in(out.command_buffer, &image);
                let new = out.codes_in(cb2, &image);
                assert!(
                    old.2 == expected(profile, views, out.fovs, first).2,
                    "{what}"
                );
                assert!(
                    new.2 == expected(profile, views, out.fovs, then).2,
                    "{what}"
                );
                assert!(old.2 != new.2, "{what}: {first:?} and {then:?} differ");
                let refills = out
                    .log
                    .matches("injected shading-rate map refilled")
                    .count();
                assert_eq!(refills, 1, "{what}: one refill\n{}", out.log);
            }
        },
    );
}

#[test]
fn without_injection_nothing_reaches_the_driver() {
    check(
        module_path!(),
        "without_injection_nothing_reaches_the_driver",
        Setup::Off,
        Api::Dynamic,
        &[],
    );
}

#[test]
fn without_injection_render_passes_reach_the_driver_unchanged() {
    check(
        module_path!(),
        "without_injection_render_passes_reach_the_driver_unchanged",
        Setup::Off,
        Api::RenderPass,
        &[],
    );
}
