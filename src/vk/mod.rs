//! The Vulkan side: `VK_LAYER_FOVEA_fragment_density_map`, a Vulkan layer in the same library as
//! the OpenXR layer, that offers `VK_EXT_fragment_density_map` on devices that have shading-rate
//! attachments (`VK_KHR_fragment_shading_rate`) and no density maps of their own, so that an
//! application's fragment-density-map code path shades fewer fragments on a desktop GPU.
//!
//! This folder never imports the OpenXR side; both meet in [`crate::bridge`].
//!
//! - [`loader`]: the loader interface (negotiation, `vkGetInstanceProcAddr`,
//!   `vkGetDeviceProcAddr`), instance creation, and the panic guard;
//! - [`dispatch`]: the one list of intercepted commands;
//! - [`registry`]: per-instance and per-device state, keyed by the loader's dispatch pointer;
//! - [`physical`]: the per-physical-device decision and what the application sees of a device;
//! - [`device`]: device creation (density maps stripped, shading-rate attachments enabled) and the
//!   device commands;
//! - [`pipeline`]: graphics pipelines get the shading-rate state, shader modules that read the
//!   fragment size are detected, subsampled sampler and dynamic view flags are left out;
//! - [`barrier`]: barriers, event sets and waits without the density-map layout, stage and access bits;
//! - [`image`]: the layer-owned shading-rate shadows of density-map images and views;
//! - [`inject`]: injection's own shading-rate maps for eye passes, and the colour images and views
//!   tracked to find them (docs/injection.md);
//! - [`pass`]: render passes, framebuffers and dynamic rendering, rewritten to name the shadows;
//! - [`convert`]: density maps the application writes, converted into their shadows at pass
//!   begin, with the application's compute bindings given back;
//! - [`submit`]: new shadows' clears ahead of the application's next submit, and semaphore wait
//!   stages without the density-map stage;
//! - [`chain`], [`link`], [`structs`]: `pNext` chains, the loader's link structs, and the size of
//!   every struct a device create info may chain.
//!
//! Per physical device: native density maps → everything passes through untouched;
//! `attachmentFragmentShadingRate` without them → emulate; neither → pass through. Fail open:
//! where the layer cannot do its part, the application's calls go down untouched and the log says
//! why, once.

#![deny(unsafe_op_in_unsafe_fn)]

/// A command's hook and its KHR alias's: two `extern "system"` functions that hand their arguments
/// to one shared body, `$shared(name, pick, arguments…)`, where `pick` takes the next layer's
/// function of the hook's own name from the device (or recording) state.
macro_rules! hook_and_khr_alias {
    (
        $(#[$doc:meta])*
        $hook:ident, $khr:ident = $shared:ident($name:literal)
        ($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)?
    ) => {
        $(#[$doc])*
        ///
        /// # Safety
        /// The caller's arguments, valid as the command requires.
        pub unsafe extern "system" fn $hook($($arg: $ty),*) $(-> $ret)? {
            // SAFETY: the caller's arguments.
            unsafe { $shared($name, |d| d.next.$hook, $($arg),*) }
        }

        #[doc = concat!("`", $name, "KHR`: as [`", stringify!($hook), "`].")]
        ///
        /// # Safety
        /// The caller's arguments, valid as the command requires.
        pub unsafe extern "system" fn $khr($($arg: $ty),*) $(-> $ret)? {
            // SAFETY: the caller's arguments.
            unsafe { $shared(concat!($name, "KHR"), |d| d.next.$khr, $($arg),*) }
        }
    };
}

mod base;
mod convert;
mod decide;
mod dispatch;
mod emulation;
mod hooks;
mod injection;
mod loader;
mod own;
mod registry;
mod translate;
