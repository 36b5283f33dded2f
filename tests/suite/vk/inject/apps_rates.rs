//! Injection into applications that set shading rates of their own (vkd3d-proton's way, and as
//! it really is) or name shading-rate attachments of their own.

use fovea_model::density::Level;
use fovea_vkdouble::Profile;

use crate::support::in_own_process;

use super::app::*;
use super::outcome::*;

/// vkd3d-proton's way: pipeline rates enabled without attachments, every pipeline with the dynamic
/// shading-rate state, 1×1 and {KEEP, KEEP} set before each draw. Its eye passes get the injected
/// map all the same, and its rates combine with it by MAX, in dynamic renderings and render passes.
#[test]
fn an_application_that_sets_rates_without_attachments_is_injected_into() {
    check(
        module_path!(),
        "an_application_that_sets_rates_without_attachments_is_injected_into",
        Setup::SetsRates(Some(Level::None)),
        Api::Dynamic,
        &[Level::High],
    );
}

/// As [`an_application_that_sets_rates_without_attachments_is_injected_into`], in render passes:
/// the full-rate map of the small target's pass leaves its rates as they were (MAX with 1×1).
#[test]
fn an_application_that_sets_rates_without_attachments_is_injected_into_passes() {
    check(
        module_path!(),
        "an_application_that_sets_rates_without_attachments_is_injected_into_passes",
        Setup::SetsRates(Some(Level::None)),
        Api::RenderPass,
        &[Level::Medium],
    );
}

/// On a device with only `KEEP` and `REPLACE` (the double told to report
/// `fragmentShadingRateNonTrivialCombinerOps` false, which validation then enforces): the
/// application's 1×1 calls get `REPLACE` (the map's rate, as `MAX` would give), its pipeline's own
/// 2×2 keeps `KEEP` and so its rate.
#[test]
fn without_non_trivial_combiners_replace_stands_in_where_the_rate_is_1x1() {
    in_own_process(
        module_path!(),
        "without_non_trivial_combiners_replace_stands_in_where_the_rate_is_1x1",
        || {
            std::env::set_var(fovea_vkdouble::TRIVIAL_COMBINERS_ENV, "1");
            for profile in [Profile::Nvidia, Profile::Amd] {
                let setup = Setup::SetsRates(Some(Level::High));
                let dir = set_up(&format!("trivial-{profile:?}"), setup);
                let Some(out) = run(profile, setup, Api::Dynamic, &dir) else {
                    return;
                };
                assert_outcome(profile, setup, Api::Dynamic, &out);
            }
        },
    );
}

#[test]
fn without_injection_an_applications_rates_reach_the_driver_unchanged() {
    check(
        module_path!(),
        "without_injection_an_applications_rates_reach_the_driver_unchanged",
        Setup::SetsRates(None),
        Api::Dynamic,
        &[],
    );
}

/// An application that names a shading-rate view of its own in a rendering of an eye target: that
/// view reaches the driver, fovea's map only the eye rendering that names none.
#[test]
fn an_applications_own_shading_rate_attachment_is_left_alone() {
    check(
        module_path!(),
        "an_applications_own_shading_rate_attachment_is_left_alone",
        Setup::AppRates,
        Api::Dynamic,
        &[],
    );
}

/// An application whose render pass references a shading-rate attachment of its own: the pass,
/// its framebuffers and its pipeline reach the driver as it made them, its view in every begin.
#[test]
fn an_applications_render_pass_with_its_own_attachment_is_left_alone() {
    check(
        module_path!(),
        "an_applications_render_pass_with_its_own_attachment_is_left_alone",
        Setup::AppRates,
        Api::Imageless,
        &[],
    );
}

/// vkd3d-proton as it is: the attachment feature enabled, a null-view shading-rate struct in every
/// rendering, shading-rate images it never attaches, its own rates. Its eye renderings reach the
/// driver with fovea's map (the model's codes) in place of its null-view struct, one struct in
/// the chain; its other rendering unchanged.
#[test]
fn a_vkd3d_like_application_is_injected_into() {
    check(
        module_path!(),
        "a_vkd3d_like_application_is_injected_into",
        Setup::Vkd3d(Some(Level::None)),
        Api::Dynamic,
        &[Level::High],
    );
}

#[test]
fn without_injection_a_vkd3d_like_application_reaches_the_driver_unchanged() {
    check(
        module_path!(),
        "without_injection_a_vkd3d_like_application_reaches_the_driver_unchanged",
        Setup::Vkd3d(None),
        Api::Dynamic,
        &[],
    );
}
