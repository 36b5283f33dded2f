//! Which swapchain images get their coarse blocks reconstructed (docs/reconstruction.md): the
//! OpenXR side decides per swapchain, from the application's subsampled request
//! (`XrVulkanSwapchainCreateInfoMETA`), Quest's `debug.oculus.foveation.subsampled` and the
//! application's `subsampled` setting, and publishes the decision for the swapchain's `VkImage`s;
//! the Vulkan side reads it when it creates the records it keeps per image (views, framebuffers),
//! never per pass.
//!
//! An image nobody published is not a swapchain image the OpenXR side knows of; the Vulkan side
//! decides for it itself (an application's own image created with `VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT`).
//!
//! The lock is a leaf, like injection's: taken for a look-up or an edit, nothing is called while it
//! is held.

use std::collections::HashMap;

use crate::common::lock::SharedRwLock;

static IMAGES: SharedRwLock<Option<HashMap<u64, bool>>> = SharedRwLock::new(None);

/// The OpenXR side's decision for a swapchain's `VkImage`s (raw handles): `true` reconstructs.
/// Published when the application enumerates the images, before it can create views of them.
pub fn publish(images: &[u64], reconstruct: bool) {
    let mut map = IMAGES.write();
    let map = map.get_or_insert_with(HashMap::new);
    for &i in images {
        map.insert(i, reconstruct);
    }
}

/// A swapchain's images went away with it. Drivers reuse handles: an image created later with one
/// of these handles is not a swapchain image until published again.
pub fn forget(images: &[u64]) {
    if let Some(map) = IMAGES.write().as_mut() {
        for i in images {
            map.remove(i);
        }
    }
}

/// The decision published for `image`, `None` where none was (not a swapchain image the OpenXR
/// side foveates or injects into). For creation-time look-ups only.
pub fn published(image: u64) -> Option<bool> {
    IMAGES.read().as_ref()?.get(&image).copied()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_decision_lives_from_publish_to_forget() {
        // Handles of this test only: the table is process-wide and tests run in parallel.
        let (a, b) = (0xfeed_0001, 0xfeed_0002);
        assert_eq!(published(a), None);
        publish(&[a, b], true);
        assert_eq!(published(a), Some(true));
        publish(&[b], false);
        assert_eq!(published(b), Some(false));
        forget(&[a, b]);
        assert_eq!((published(a), published(b)), (None, None));
    }
}
