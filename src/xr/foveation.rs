//! What a density map is made from, and the one rule for when a map is stale: the swapchain's
//! foveation state, the FOVs and submitted views the maps are drawn for, the pattern they hold
//! under Quest's debug overrides and the dynamic step ([`effective`]), and how a profile applied
//! for injection is kept in one atomic ([`pack_request`]).
//!
//! A density map depends on exactly the inputs named in [`MapKey`]: the swapchain's foveation state
//! (its last applied profile), the FOVs the session last located, the session's pattern (dynamic
//! step and debug overrides) and the views last submitted into the swapchain. Each input carries a
//! generation that its owner bumps when it changes; an image whose stored key differs from the
//! current one is stale and is rebuilt (only in `xrAcquireSwapchainImage`). Adding an input means
//! adding a field here and bumping it where it changes; nothing else decides staleness
//! (docs/ARCHITECTURE.md#one-staleness-rule-mapkey).
//!
//! Only the OpenXR side reads any of it; what the Vulkan side reads too is in [`crate::bridge`].
//! The session's use of it (which pattern its swapchains and injection use now) is
//! [`crate::xr::pattern`].

use fovea_model::density::{Level, Pattern};
use fovea_model::dynamic::level_at;
use fovea_model::maps::{Inputs, SubmittedView, MAX_VIEWS};
use fovea_model::Fov;
use openxr_sys as xr;

use crate::common::settings::DebugProperties;

/// Which state a density image holds: the generation of each input a map depends on, as it was when
/// the image was filled.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MapKey {
    /// [`FoveationState::generation`]: bumped by every `xrUpdateSwapchainFB`.
    pub foveation: u64,
    /// [`ViewFovs::generation`]: bumped when a located FOV changes.
    pub located: u64,
    /// The session's pattern generation: bumped when the dynamic step or the debug overrides change
    /// what the maps hold.
    pub pattern: u64,
    /// [`Submitted::generation`]: bumped when the views submitted into the swapchain change.
    pub submitted: u64,
}

/// What one swapchain image's map is computed from, read once per acquire.
#[derive(Clone, Copy, Debug)]
pub struct MapSources {
    pub foveation: FoveationState,
    pub located: ViewFovs,
    pub pattern_generation: u64,
    pub submitted: Submitted,
}

impl MapSources {
    /// The key a map filled from these sources holds.
    pub fn key(&self) -> MapKey {
        MapKey {
            foveation: self.foveation.generation,
            located: self.located.generation,
            pattern: self.pattern_generation,
            submitted: self.submitted.generation,
        }
    }

    /// The map's inputs for a swapchain of `extent` with `layers` array layers, under `pattern`;
    /// `visible` gives the eyes' true FOVs in symmetric-FOV mode. Called only for a stale image.
    pub fn inputs(
        &self,
        pattern: Pattern,
        extent: [u32; 2],
        layers: u32,
        visible: Option<[Fov; 2]>,
    ) -> Inputs {
        Inputs::new(
            pattern,
            extent,
            layers,
            &self.submitted.views,
            &self.located.fovs,
            visible,
        )
    }
}

/// The pattern for a swapchain state under debug overrides at a dynamic step. As on Quest: the
/// level property replaces the application's level (the maximum when dynamic), the dynamic property
/// replaces its dynamic flag.
pub fn effective(params: ProfileParams, over: DebugProperties, step: usize) -> (Pattern, bool) {
    let max = over.level.unwrap_or(params.level);
    let dynamic = over.dynamic.unwrap_or(params.dynamic);
    let level = if dynamic { level_at(step, max) } else { max };
    (
        Pattern {
            level,
            vertical_offset_deg: over
                .vertical_offset_deg
                .unwrap_or(params.vertical_offset_deg),
        },
        dynamic,
    )
}

/// The views' FOVs as the application last got them from xrLocateViews.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ViewFovs {
    pub fovs: [Option<Fov>; MAX_VIEWS],
    /// Bumped whenever a FOV changes, so density maps computed for older FOVs are refreshed.
    pub generation: u64,
}

impl ViewFovs {
    /// Records the FOVs of one xrLocateViews call; bumps the generation only when one changed.
    pub fn record(&mut self, fovs: impl IntoIterator<Item = Fov>) {
        let mut new = [None; MAX_VIEWS];
        for (slot, fov) in new.iter_mut().zip(fovs) {
            *slot = Some(fov);
        }
        if new != self.fovs {
            self.fovs = new;
            self.generation += 1;
        }
    }
}

/// The projection views one `xrEndFrame` put into a swapchain.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Submitted {
    pub views: [Option<SubmittedView>; MAX_VIEWS],
    /// Bumped when the views change (FOV, rectangle or array layer): the maps are rebuilt once.
    pub generation: u64,
}

/// What an `XrFoveationLevelProfileCreateInfoFB` asks for. A profile without one applies no
/// foveation (fb_foveation.adoc), which is level NONE (the default).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProfileParams {
    /// `XrFoveationLevelFB` as validated (NONE..HIGH, never High Top, which only the debug
    /// property asks for); the maximum when dynamic.
    pub level: Level,
    /// Degrees, positive up: where the centre of the pattern sits.
    pub vertical_offset_deg: f32,
    /// XR_FOVEATION_DYNAMIC_LEVEL_ENABLED_FB.
    pub dynamic: bool,
    /// The profile was created with `XrFoveationEyeTrackedProfileCreateInfoMETA`
    /// (XR_META_foveation_eye_tracked): its fovea follows the gaze where a gaze source exists.
    pub eye_tracked: bool,
}

impl Default for ProfileParams {
    fn default() -> ProfileParams {
        ProfileParams {
            level: Level::None,
            vertical_offset_deg: 0.0,
            dynamic: false,
            eye_tracked: false,
        }
    }
}

/// A profile applied for injection, kept in one atomic ([`crate::xr::registry::Session::inject_request`])
/// because the frame loop reads it every frame: bit 63 set, the level's index in bits 32–39,
/// dynamic in bit 40, eye-tracked in bit 41, the vertical offset's bits below; 0 before any.
pub fn pack_request(p: ProfileParams) -> u64 {
    1 << 63
        | (p.level as u64) << 32
        | u64::from(p.dynamic) << 40
        | u64::from(p.eye_tracked) << 41
        | u64::from(p.vertical_offset_deg.to_bits())
}

/// The parameters [`pack_request`] packed; `None` for 0.
pub fn unpack_request(v: u64) -> Option<ProfileParams> {
    (v >> 63 == 1).then(|| ProfileParams {
        level: Level::from_index((v >> 32 & 0xFF) as u32).unwrap_or(Level::None),
        vertical_offset_deg: f32::from_bits(v as u32),
        dynamic: v >> 40 & 1 == 1,
        eye_tracked: v >> 41 & 1 == 1,
    })
}

/// A foveated swapchain's current state: a copy of the last applied profile's parameters, so
/// destroying the profile afterwards changes nothing (fb_foveation.adoc).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FoveationState {
    pub params: ProfileParams,
    /// The profile last applied (XR_NULL_HANDLE before the first update).
    pub profile: xr::FoveationProfileFB,
    /// Bumped by every xrUpdateSwapchainFB: density images filled for an older state are dirty.
    pub generation: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Quest's semantics for the debug properties: the level property is the level, or the
    /// maximum when dynamic; the dynamic property overrides the application's flag.
    #[test]
    fn overrides_apply_above_the_application() {
        let app = ProfileParams {
            level: Level::Low,
            vertical_offset_deg: 5.0,
            dynamic: false,
            eye_tracked: false,
        };
        let none = DebugProperties::default();
        let level = |p: ProfileParams, o: DebugProperties, step| {
            let (pat, dynamic) = effective(p, o, step);
            (pat.level, dynamic)
        };
        assert_eq!(level(app, none, 0), (Level::Low, false));
        assert_eq!(effective(app, none, 0).0.vertical_offset_deg, 5.0);
        let high = DebugProperties {
            level: Some(Level::High),
            ..none
        };
        assert_eq!(
            level(app, high, 0),
            (Level::High, false),
            "the level, not dynamic"
        );
        let high_dynamic = DebugProperties {
            dynamic: Some(true),
            ..high
        };
        assert_eq!(level(app, high_dynamic, 0), (Level::None, true));
        assert_eq!(level(app, high_dynamic, 2), (Level::Medium, true));
        assert_eq!(
            level(app, high_dynamic, 3),
            (Level::High, true),
            "the maximum"
        );
        let app_dynamic = ProfileParams {
            dynamic: true,
            level: Level::High,
            ..app
        };
        let off = DebugProperties {
            dynamic: Some(false),
            ..none
        };
        assert_eq!(level(app_dynamic, off, 1), (Level::High, false));
        assert_eq!(level(app_dynamic, none, 1), (Level::Low, true));
        let top = DebugProperties {
            level: Some(Level::HighTop),
            ..none
        };
        assert_eq!(level(app, top, 0).0, Level::HighTop);
    }

    #[test]
    fn an_applied_profile_packs_and_unpacks_whole() {
        assert_eq!(unpack_request(0), None);
        for p in [
            ProfileParams::default(),
            ProfileParams {
                level: Level::High,
                vertical_offset_deg: -7.5,
                dynamic: true,
                eye_tracked: true,
            },
            ProfileParams {
                level: Level::Low,
                vertical_offset_deg: 0.25,
                dynamic: false,
                eye_tracked: true,
            },
        ] {
            assert_eq!(unpack_request(pack_request(p)), Some(p), "{p:?}");
        }
    }
}
