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
//! With the decision goes the usage the OpenXR side added to the images for it (`TRANSFER_SRC`,
//! `TRANSFER_DST` where the application did not ask for them): the Vulkan side hides it from the
//! application's views of them, whose usage an imageless framebuffer names
//! (docs/reconstruction.md#usage-the-application-does-not-see). And the Vulkan side publishes the
//! devices on which it does so, so the OpenXR side knows when an application's imageless
//! framebuffers rule the added usage out.
//!
//! The locks are leaves, like injection's: taken for a look-up or an edit, nothing is called while
//! one is held.

use std::collections::HashMap;

use ash::vk;

use crate::common::lock::SharedRwLock;

static IMAGES: SharedRwLock<Option<HashMap<u64, (bool, vk::ImageUsageFlags)>>> =
    SharedRwLock::new(None);

/// Devices (raw `VkDevice`s) whose views of images with added usage the Vulkan side gives the
/// application's usage only ([`set_hides_usage`]).
static HIDING: SharedRwLock<Vec<u64>> = SharedRwLock::new(Vec::new());

/// The OpenXR side's decision for a swapchain's `VkImage`s (raw handles): `true` reconstructs;
/// `added`: the Vulkan usage it had the runtime add to them that the application did not ask for.
/// Published when the application enumerates the images, before it can create views of them.
pub fn publish(images: &[u64], reconstruct: bool, added: vk::ImageUsageFlags) {
    let mut map = IMAGES.write();
    let map = map.get_or_insert_with(HashMap::new);
    for &i in images {
        map.insert(i, (reconstruct, added));
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
    IMAGES.read().as_ref()?.get(&image).map(|p| p.0)
}

/// The usage the OpenXR side added to `image` that its application did not ask for (empty for an
/// image nobody published). For view creation only.
pub fn added_usage(image: u64) -> vk::ImageUsageFlags {
    IMAGES
        .read()
        .as_ref()
        .and_then(|m| m.get(&image))
        .map_or(vk::ImageUsageFlags::empty(), |p| p.1)
}

/// The Vulkan side gives the views of `device` (raw) the application's usage only, hiding the
/// usage added for reconstruction (`true`, at device creation), or the device is gone (`false`).
pub fn set_hides_usage(device: u64, hides: bool) {
    let mut v = HIDING.write();
    v.retain(|d| *d != device);
    if hides {
        v.push(device);
    }
}

/// Whether the Vulkan side hides added usage from the application's views on `device` (raw): an
/// application's imageless framebuffers then name the usage it asked for, as they must.
pub fn hides_usage(device: u64) -> bool {
    device != 0 && HIDING.read().contains(&device)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_decision_lives_from_publish_to_forget() {
        // Handles of this test only: the table is process-wide and tests run in parallel.
        let (a, b) = (0xfeed_0001, 0xfeed_0002);
        let t = vk::ImageUsageFlags::TRANSFER_SRC;
        assert_eq!(published(a), None);
        publish(&[a, b], true, t);
        assert_eq!(published(a), Some(true));
        assert_eq!(added_usage(a), t);
        publish(&[b], false, vk::ImageUsageFlags::empty());
        assert_eq!(published(b), Some(false));
        assert_eq!(added_usage(b), vk::ImageUsageFlags::empty());
        forget(&[a, b]);
        assert_eq!((published(a), published(b)), (None, None));
        assert_eq!(added_usage(a), vk::ImageUsageFlags::empty());
    }

    #[test]
    fn a_device_hides_usage_from_set_to_unset() {
        let d = 0xfeed_0d01;
        assert!(!hides_usage(d));
        set_hides_usage(d, true);
        set_hides_usage(d, true);
        assert!(hides_usage(d));
        set_hides_usage(d, false);
        assert!(!hides_usage(d));
        assert!(!hides_usage(0));
    }
}
