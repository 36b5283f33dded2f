//! Applications that ask for foveation as Qt 6.8's Quick 3D XR does: the FB foveation extensions
//! without `XR_FB_foveation_vulkan`, a swapchain without `XrSwapchainCreateInfoFoveationFB`, a
//! HIGH profile applied with `xrUpdateSwapchainFB` (docs/injection.md#applications-that-apply-profiles).
//! Their eye passes are foveated by injection at the profile's level, with `inject` off and on.

use fovea_model::density::Level;
use fovea_vkdouble::Profile;

use crate::support::in_own_process;

use super::app::*;
use super::outcome::*;

/// fovea's line when it takes a profile for a swapchain without density images.
const ACCEPTED: &str = "a foveation profile applied to a swapchain without density images: its \
                        eye passes are foveated by injection at its level level=3";

/// `xrUpdateSwapchainFB` succeeds (the application asserts it), and what reaches the driver is
/// what injection at HIGH gives a multiview application ([`assert_outcome`]): the device with the
/// attachment feature, both views of the swapchain's rendering and of the eye-shaped target of
/// its own shading at the model's HIGH codes, texel for texel, the small target at full rate;
/// with injection off, and on at `low` (the application's HIGH wins), on both driver profiles.
#[test]
fn a_profile_applied_to_a_swapchain_without_foveation_info_is_injected_at_its_level() {
    in_own_process(
        module_path!(),
        "a_profile_applied_to_a_swapchain_without_foveation_info_is_injected_at_its_level",
        || {
            let mut first = true;
            for inject in [None, Some(Level::Low)] {
                for profile in [Profile::Nvidia, Profile::Amd] {
                    let setup = Setup::Toolkit(inject);
                    let dir = set_up(&format!("toolkit-{inject:?}-{profile:?}"), setup);
                    let Some(out) = run(profile, setup, Api::Multiview, &dir) else {
                        return;
                    };
                    assert_outcome(profile, setup, Api::Multiview, &out);
                    if first {
                        // The process's log file is the first run's.
                        assert_eq!(out.log.matches(ACCEPTED).count(), 1, "{}", out.log);
                        assert!(!out.log.contains("not injecting"), "{}", out.log);
                        first = false;
                    }
                }
            }
        },
    );
}

/// On a device without shading-rate attachments (the double's `none` profile) the profile is still
/// accepted, but nothing can foveate it: one info line says so, once however often it happens,
/// the device reaches the driver as the application asked, no map is made, and the Vulkan side's
/// line for `inject = true` ("injection is on, but ...") is not written, since it is
/// not on.
#[test]
fn a_profile_no_device_can_take_is_said_once() {
    in_own_process(
        module_path!(),
        "a_profile_no_device_can_take_is_said_once",
        || {
            let setup = Setup::Toolkit(None);
            let said = "a foveation profile applied to a swapchain without density images, but no \
                        Vulkan device of this process takes injected shading-rate maps";
            let dir = set_up("toolkit-no-device", setup);
            for run_ in 0..2 {
                let Some(out) = run(Profile::None, setup, Api::Multiview, &dir) else {
                    return;
                };
                // (The double records a device only where shading rates are in play.)
                for d in out.of("device") {
                    assert_ne!(d["features"]["attachment"], true, "{d}");
                }
                assert!(
                    !out.log.contains("injected shading-rate map made"),
                    "{}",
                    out.log
                );
                // Both runs log into the process's one file.
                assert_eq!(out.log.matches(said).count(), 1, "{run_}:\n{}", out.log);
                assert_eq!(out.log.matches(ACCEPTED).count(), run_ + 1, "{}", out.log);
                assert!(
                    !out.log
                        .contains("injection is on, but this device cannot take"),
                    "{}",
                    out.log
                );
            }
        },
    );
}

/// Quest's debug properties apply to the applied profile as to any: `debug.oculus.foveation.level`
/// written to the property file while the application runs replaces its HIGH, and the map is
/// refilled in place, once, with the new level's codes.
#[test]
fn the_debug_level_replaces_the_applied_profiles_level() {
    in_own_process(
        module_path!(),
        "the_debug_level_replaces_the_applied_profiles_level",
        || {
            let then = Level::Low;
            let profile = Profile::Nvidia;
            let setup = Setup::Toolkit(None);
            let dir = set_up("toolkit-props", setup);
            let Some(out) = run_with(profile, setup, Api::Dynamic, &dir, Some(then)) else {
                return;
            };
            assert_outcome(profile, setup, Api::Dynamic, &out);
            let cb2 = out.second.expect("a second command buffer");
            let view = out.rates(Api::Dynamic)[0]["view"].clone();
            let image = out.image_of(&view);
            let views = fovea_model::inject::Views::Layers { first: 0, count: 1 };
            let new = out.codes_in(cb2, &image);
            assert!(
                new.2 == expected(profile, views, out.fovs, then).2,
                "the property's level"
            );
            assert!(
                out.codes_of(&image).2 == expected(profile, views, out.fovs, TOOLKIT_LEVEL).2,
                "the profile's level before"
            );
            assert_eq!(
                out.log
                    .matches("injected shading-rate map refilled")
                    .count(),
                1,
                "{}",
                out.log
            );
        },
    );
}
