//! Injection (docs/injection.md) end to end on lavapipe: an application that never asks for
//! foveation, its eye passes foveated by fovea all the same.
//!
//! Stack: this test as an OpenXR application → fovea's OpenXR layer → the simulated runtime; its
//! VkInstance and VkDevice made through XR_KHR_vulkan_enable2 with the layers fovea's Vulkan layer →
//! VK_LAYER_KHRONOS_validation → the shading-rate double (`nvidia`: 16×16 texels, layered; `amd`:
//! 8×8) → lavapipe, validation's handle wrapping off so the double's records name the test's
//! handles. Each run is a child process of its own: `FOVEA_INJECT` and `FOVEA_INJECT_LEVEL` are read
//! from the environment at `xrCreateInstance`.
//!
//! One frame: a per-eye swapchain of 640×500 (so the left eye's: fovea guesses view 0 from the
//! first of its size), the views located, then three passes with one pipeline: into the acquired
//! swapchain image, into a 256×256 image of the application's own, and into an eye-shaped 640×500
//! image of its own; as dynamic renderings, as version-1 render passes with a framebuffer each, or
//! as version-2 passes with imageless framebuffers; or, multiview (view mask 0b11), into two-layer
//! targets with a swapchain that is an array of both views. What must reach the driver, per profile
//! and level:
//!
//! - injection on: the device with `VK_KHR_fragment_shading_rate`'s attachment feature; the pipeline
//!   with the state {1×1, {KEEP, REPLACE}} (and, for dynamic rendering, the shading-rate flag);
//!   render passes with a shading-rate attachment after the colour one in their subpass; the
//!   swapchain pass with a shading-rate attachment of the device's texel whose draws shade (the
//!   double's effective rates per view and texel) exactly at `fovea_model::inject::codes` for
//!   view 0 at the located FOVs and the level, and off-eye passes at full rate everywhere; the
//!   eye-shaped one with the merged map of both eyes; the small one with none (dynamic rendering)
//!   or a full-rate map covering it (render passes); multiview, one map of both views for both
//!   two-layer targets, two layers on `nvidia` and one merged layer on `amd`; a level changed while
//!   the application runs refills the map in place, once;
//! - injection off: none of it, the double sees the application's calls as they were;
//! - an application that names a shading-rate view of its own in the swapchain's rendering: that
//!   view reaches the driver there, fovea's map in the eye-shaped target's; one whose render pass
//!   references its own attachment: the pass, its framebuffers and pipeline as it made them; the
//!   log says so once;
//! - a vkd3d-like application (the attachment feature enabled, a null-view shading-rate struct in
//!   every rendering): its eye renderings with fovea's map in place of that struct, one in the chain;
//!
//! and in every case validation says nothing and the double records no misuse.
//!
//! The application is [`app`], what it left and what must reach the driver [`outcome`]; the
//! tests are by subject: [`eye_passes`] (what eye and other passes get, at each level, and with
//! injection off), [`apps_rates`] (applications that set shading rates or attachments of their
//! own), [`devices`] (only the session's device is injected into), [`toolkit`] (an
//! application that applies a profile to a swapchain without foveation info, as Qt does) and
//! [`resolve`] (a multisampled eye pass resolved into a swapchain image published for
//! reconstruction: the resolve target's coarse blocks are reconstructed).

mod app;
mod apps_rates;
mod devices;
mod eye_passes;
mod outcome;
mod resolve;
mod toolkit;
