//! Dispatch: the one list of functions fovea intercepts.
//!
//! Each line names the OpenXR function, the field that holds the next layer's pointer, its
//! openxr-sys signature, the hook, and who owns the function. From that list the macro derives the
//! table of next-layer pointers ([`Next`]) and the hook table [`HOOKS`] that `xrGetInstanceProcAddr`
//! answers from, so a function is declared in exactly one place and its hook's signature is checked
//! against openxr-sys by the compiler.

use std::ffi::{c_char, CStr};

use openxr_sys as xr;

use crate::xr::extensions::Ext;
use crate::xr::hooks;

/// Who implements an intercepted function.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Owner {
    /// Core OpenXR or a runtime extension: the layer watches the call and passes it on. It hooks it
    /// only where the next layer offers it.
    Below,
    /// One of the extensions fovea provides.
    Layer(Ext),
}

/// One intercepted function.
pub struct Hook {
    pub name: &'static CStr,
    pub function: xr::pfn::VoidFunction,
    pub owner: Owner,
    /// Whether the next layer offers this function for an instance.
    pub offered_below: fn(&Next) -> bool,
}

macro_rules! hooks {
    ($($name:literal => $field:ident: $pfn:ident = $hook:path, $owner:expr;)*) => {
        /// The next layer's (or the runtime's) pointer for every intercepted function, loaded once
        /// when the instance is created. `None` where the next layer does not offer it.
        #[derive(Clone, Copy, Default)]
        pub struct Next {
            $(pub $field: Option<xr::pfn::$pfn>,)*
        }

        impl Next {
            /// Asks the next layer for every intercepted function.
            ///
            /// # Safety
            /// `gipa` must be the next layer's `xrGetInstanceProcAddr` and `instance` its instance.
            pub unsafe fn load(gipa: xr::pfn::GetInstanceProcAddr, instance: xr::Instance) -> Next {
                Next {
                    $($field: load(gipa, instance, $name)
                        .map(|f| std::mem::transmute::<xr::pfn::VoidFunction, xr::pfn::$pfn>(f)),)*
                }
            }
        }

        /// Every intercepted function, answered by `xrGetInstanceProcAddr`.
        pub static HOOKS: &[Hook] = &[
            $(Hook {
                name: $name,
                // SAFETY: function pointers of any signature have the same representation; the
                // loader casts it back to the type the name implies, which `as` checked here.
                function: unsafe {
                    std::mem::transmute::<xr::pfn::$pfn, xr::pfn::VoidFunction>($hook as xr::pfn::$pfn)
                },
                owner: $owner,
                offered_below: |next: &Next| next.$field.is_some(),
            },)*
        ];
    };
}

hooks! {
    c"xrDestroyInstance" => destroy_instance: DestroyInstance = hooks::instance::destroy_instance, Owner::Below;
    c"xrCreateSession" => create_session: CreateSession = hooks::session::create_session, Owner::Below;
    c"xrDestroySession" => destroy_session: DestroySession = hooks::session::destroy_session, Owner::Below;
    c"xrBeginSession" => begin_session: BeginSession = hooks::session::begin_session, Owner::Below;
    c"xrEndSession" => end_session: EndSession = hooks::session::end_session, Owner::Below;
    c"xrEnumerateViewConfigurationViews" => enumerate_view_configuration_views: EnumerateViewConfigurationViews =
        hooks::session::enumerate_view_configuration_views, Owner::Below;
    c"xrLocateViews" => locate_views: LocateViews = hooks::frame::locate_views, Owner::Below;
    c"xrWaitFrame" => wait_frame: WaitFrame = hooks::frame::wait_frame, Owner::Below;
    c"xrBeginFrame" => begin_frame: BeginFrame = hooks::frame::begin_frame, Owner::Below;
    c"xrEndFrame" => end_frame: EndFrame = hooks::frame::end_frame, Owner::Below;
    c"xrCreateSwapchain" => create_swapchain: CreateSwapchain = hooks::swapchain::create_swapchain, Owner::Below;
    c"xrDestroySwapchain" => destroy_swapchain: DestroySwapchain = hooks::swapchain::destroy_swapchain, Owner::Below;
    c"xrEnumerateSwapchainImages" => enumerate_swapchain_images: EnumerateSwapchainImages =
        hooks::swapchain::enumerate_swapchain_images, Owner::Below;
    c"xrAcquireSwapchainImage" => acquire_swapchain_image: AcquireSwapchainImage =
        hooks::swapchain::acquire_swapchain_image, Owner::Below;
    c"xrWaitSwapchainImage" => wait_swapchain_image: WaitSwapchainImage =
        hooks::swapchain::wait_swapchain_image, Owner::Below;
    c"xrReleaseSwapchainImage" => release_swapchain_image: ReleaseSwapchainImage =
        hooks::swapchain::release_swapchain_image, Owner::Below;
    c"xrGetVulkanDeviceExtensionsKHR" => get_vulkan_device_extensions: GetVulkanDeviceExtensionsKHR =
        hooks::vulkan_enable::get_vulkan_device_extensions, Owner::Below;
    c"xrCreateVulkanDeviceKHR" => create_vulkan_device: CreateVulkanDeviceKHR =
        hooks::vulkan_enable::create_vulkan_device, Owner::Below;
    c"xrGetVulkanGraphicsDeviceKHR" => get_vulkan_graphics_device: GetVulkanGraphicsDeviceKHR =
        hooks::vulkan_enable::get_vulkan_graphics_device, Owner::Below;
    c"xrGetVulkanGraphicsDevice2KHR" => get_vulkan_graphics_device2: GetVulkanGraphicsDevice2KHR =
        hooks::vulkan_enable::get_vulkan_graphics_device2, Owner::Below;
    c"xrUpdateSwapchainFB" => update_swapchain: UpdateSwapchainFB =
        hooks::foveation::update_swapchain, Owner::Layer(Ext::SwapchainUpdateState);
    c"xrGetSwapchainStateFB" => get_swapchain_state: GetSwapchainStateFB =
        hooks::foveation::get_swapchain_state, Owner::Layer(Ext::SwapchainUpdateState);
    c"xrCreateFoveationProfileFB" => create_foveation_profile: CreateFoveationProfileFB =
        hooks::foveation::create_profile, Owner::Layer(Ext::Foveation);
    c"xrDestroyFoveationProfileFB" => destroy_foveation_profile: DestroyFoveationProfileFB =
        hooks::foveation::destroy_profile, Owner::Layer(Ext::Foveation);
}

/// Asks `gipa` for one function; `None` where it answers with an error or a NULL pointer.
///
/// # Safety
/// As [`Next::load`].
pub unsafe fn load(
    gipa: xr::pfn::GetInstanceProcAddr,
    instance: xr::Instance,
    name: &CStr,
) -> Option<xr::pfn::VoidFunction> {
    let mut f = None;
    let r = gipa(instance, name.as_ptr(), &mut f);
    if r.into_raw() < 0 {
        return None;
    }
    f
}

/// The hook for `name`, if fovea intercepts it.
pub fn hook(name: &CStr) -> Option<&'static Hook> {
    HOOKS.iter().find(|h| h.name == name)
}

/// Reads a function name handed to `xrGetInstanceProcAddr`.
///
/// # Safety
/// `name` must be NULL or NUL-terminated.
pub unsafe fn name<'a>(name: *const c_char) -> Option<&'a CStr> {
    crate::common::ffi::cstr(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_resolvable() {
        for (i, h) in HOOKS.iter().enumerate() {
            assert!(
                HOOKS[..i].iter().all(|o| o.name != h.name),
                "{:?} twice",
                h.name
            );
            assert!(std::ptr::eq(hook(h.name).unwrap(), h));
        }
        assert!(hook(c"xrPollEvent").is_none());
        assert!(!(HOOKS[0].offered_below)(&Next::default()));
    }
}
