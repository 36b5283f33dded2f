//! The extensions fovea implements, their dependencies, and which of them the layer provides for a
//! given instance (the app enabled it and nothing below implements it natively).
//!
//! Versions and dependencies are the registry's (docs/openxr-layer.md#extensions).

use std::ffi::CStr;

pub use fovea_abi::{Ext, EXTENSIONS, VULKAN_ENABLE};

/// The bit of `ext` in an [`ExtSet`].
fn bit(ext: Ext) -> u8 {
    1 << ext as u8
}

/// A set of [`Ext`], as a bit set (one bit each: at most eight extensions).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ExtSet(u8);

impl ExtSet {
    pub fn contains(self, ext: Ext) -> bool {
        self.0 & bit(ext) != 0
    }

    pub fn insert(&mut self, ext: Ext) {
        self.0 |= bit(ext);
    }

    pub fn iter(self) -> impl Iterator<Item = Ext> {
        EXTENSIONS
            .iter()
            .map(|e| e.ext)
            .filter(move |e| self.contains(*e))
    }
}

/// Which of fovea's extensions an instance uses and who implements each.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Extensions {
    /// Enabled by the application.
    pub enabled: ExtSet,
    /// Implemented by a layer below or the runtime: fovea passes their calls through untouched.
    pub native: ExtSet,
    /// The application enabled XR_KHR_vulkan_enable.
    pub vulkan_enable: bool,
    /// The application enabled XR_KHR_vulkan_enable2.
    pub vulkan_enable2: bool,
}

impl Extensions {
    /// Enabled and not native: fovea implements it for this instance.
    pub fn provided(&self, ext: Ext) -> bool {
        self.enabled.contains(ext) && !self.native.contains(ext)
    }
}

/// A dependency the application left out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MissingDependency {
    pub ext: Ext,
    pub needs: &'static str,
}

/// The first dependency of an enabled extension that the application did not enable.
/// `other_enabled` answers for extensions outside fovea's set (the Vulkan enable extensions).
pub fn missing_dependency(
    enabled: ExtSet,
    other_enabled: impl Fn(&CStr) -> bool,
) -> Option<MissingDependency> {
    for e in EXTENSIONS.iter().filter(|e| enabled.contains(e.ext)) {
        if let Some(d) = e.depends.iter().find(|d| !enabled.contains(**d)) {
            return Some(MissingDependency {
                ext: e.ext,
                needs: d.info().name.to_str().unwrap_or_default(),
            });
        }
        if e.ext == Ext::MetaVulkanSwapchainCreateInfo
            && !VULKAN_ENABLE.iter().any(|v| other_enabled(v))
        {
            return Some(MissingDependency {
                ext: e.ext,
                needs: "XR_KHR_vulkan_enable or XR_KHR_vulkan_enable2",
            });
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_is_indexed_by_enum() {
        for (i, e) in EXTENSIONS.iter().enumerate() {
            assert_eq!(e.ext as usize, i);
            assert_eq!(Ext::by_name(e.name), Some(e.ext));
        }
        assert_eq!(Ext::SwapchainUpdateState.info().version, 3);
        assert_eq!(Ext::by_name(c"XR_FB_foveation_vulkan2"), None);
    }

    #[test]
    fn provided_means_enabled_and_not_native() {
        let mut x = Extensions::default();
        x.enabled.insert(Ext::Foveation);
        x.enabled.insert(Ext::SwapchainUpdateState);
        x.native.insert(Ext::SwapchainUpdateState);
        assert!(x.provided(Ext::Foveation));
        assert!(!x.provided(Ext::SwapchainUpdateState));
        assert!(!x.provided(Ext::FoveationVulkan));
        assert_eq!(
            x.enabled.iter().collect::<Vec<_>>(),
            [Ext::SwapchainUpdateState, Ext::Foveation]
        );
    }

    #[test]
    fn dependencies() {
        let mut s = ExtSet::default();
        s.insert(Ext::FoveationConfiguration);
        let m = missing_dependency(s, |_| false).unwrap();
        assert_eq!(
            (m.ext, m.needs),
            (Ext::FoveationConfiguration, "XR_FB_foveation")
        );
        s.insert(Ext::Foveation);
        assert_eq!(
            missing_dependency(s, |_| false).unwrap().needs,
            "XR_FB_swapchain_update_state"
        );
        s.insert(Ext::SwapchainUpdateState);
        assert_eq!(missing_dependency(s, |_| false), None);
        s.insert(Ext::MetaVulkanSwapchainCreateInfo);
        assert!(missing_dependency(s, |_| false).is_some());
        assert_eq!(
            missing_dependency(s, |n| n == c"XR_KHR_vulkan_enable2"),
            None
        );
    }
}
