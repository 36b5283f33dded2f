//! The extensions the runtime knows: their names, and which of them it offers under a
//! configuration.

use crate::config::SimConfig;

pub(crate) const KHR_VULKAN_ENABLE: &str = "XR_KHR_vulkan_enable";
pub(crate) const KHR_VULKAN_ENABLE2: &str = "XR_KHR_vulkan_enable2";
pub(crate) const MND_HEADLESS: &str = "XR_MND_headless";
pub(crate) const FB_SWAPCHAIN_UPDATE_STATE: &str = "XR_FB_swapchain_update_state";
pub(crate) const FB_FOVEATION: &str = "XR_FB_foveation";
pub(crate) const EXT_EYE_GAZE_INTERACTION: &str = "XR_EXT_eye_gaze_interaction";
pub(crate) const FB_FOVEATION_CONFIGURATION: &str = "XR_FB_foveation_configuration";
pub(crate) const META_FOVEATION_EYE_TRACKED: &str = "XR_META_foveation_eye_tracked";
pub(crate) const EPIC_VIEW_CONFIGURATION_FOV: &str = "XR_EPIC_view_configuration_fov";
pub(crate) const KHR_BINDING_MODIFICATION: &str = "XR_KHR_binding_modification";
pub(crate) const EXT_ACTIVE_ACTION_SET_PRIORITY: &str = "XR_EXT_active_action_set_priority";

/// The extensions this runtime offers under `cfg`, with their spec versions.
pub(crate) fn extensions(cfg: &SimConfig) -> Vec<(&'static str, u32)> {
    let mut list = vec![
        (KHR_VULKAN_ENABLE, 8),
        (KHR_VULKAN_ENABLE2, 2),
        (MND_HEADLESS, 2),
    ];
    // XR_FB_foveation depends on XR_FB_swapchain_update_state (its xrUpdateSwapchainFB applies
    // profiles), so native foveation brings it along.
    if cfg.native_swapchain_update_state || cfg.native_foveation {
        list.push((FB_SWAPCHAIN_UPDATE_STATE, 3));
    }
    if cfg.native_foveation {
        list.push((FB_FOVEATION, 1));
        list.push((FB_FOVEATION_CONFIGURATION, 1));
        if cfg.native_meta_eye_tracked {
            list.push((META_FOVEATION_EYE_TRACKED, 1));
        }
    }
    if cfg.view_configuration_fov {
        list.push((EPIC_VIEW_CONFIGURATION_FOV, 2));
    }
    if cfg.eye_gaze.is_some() {
        list.push((EXT_EYE_GAZE_INTERACTION, 2));
        // With the one input device, the input extensions Monado offers: suggestions may chain
        // XrBindingModificationsKHR (the journal records it), a sync may override the active
        // sets' priorities.
        list.push((KHR_BINDING_MODIFICATION, 1));
        list.push((EXT_ACTIVE_ACTION_SET_PRIORITY, 1));
    }
    list
}
