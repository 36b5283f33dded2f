//! A minimal OpenXR application for tests: an instance through a [`Chain`], typed function lookup,
//! and the few calls every test needs. It owns its chain, so the layer libraries stay loaded while the
//! instance lives, and destroys the instance when dropped.

use std::ffi::{CStr, CString};

use openxr_sys as xr;
use xr::Handle;

use crate::{lookup, Chain};

/// An application instance.
pub struct App {
    pub chain: Chain,
    pub instance: xr::Instance,
    destroyed: bool,
}

/// Builds an `XrInstanceCreateInfo` for `extensions` and calls `f` with it.
pub fn with_create_info<R>(
    extensions: &[&str],
    api: xr::Version,
    f: impl FnOnce(&xr::InstanceCreateInfo) -> R,
) -> R {
    let names: Vec<CString> = extensions
        .iter()
        .map(|e| CString::new(*e).unwrap())
        .collect();
    let ptrs: Vec<*const std::ffi::c_char> = names.iter().map(|n| n.as_ptr()).collect();
    let mut app_info = xr::ApplicationInfo {
        application_name: [0; xr::MAX_APPLICATION_NAME_SIZE],
        application_version: 1,
        engine_name: [0; xr::MAX_ENGINE_NAME_SIZE],
        engine_version: 0,
        api_version: api,
    };
    for (d, s) in app_info.application_name.iter_mut().zip(b"fovea-harness") {
        *d = *s as std::ffi::c_char;
    }
    let info = xr::InstanceCreateInfo {
        ty: xr::StructureType::INSTANCE_CREATE_INFO,
        next: std::ptr::null(),
        create_flags: xr::InstanceCreateFlags::EMPTY,
        application_info: app_info,
        enabled_api_layer_count: 0,
        enabled_api_layer_names: std::ptr::null(),
        enabled_extension_count: ptrs.len() as u32,
        enabled_extension_names: if ptrs.is_empty() {
            std::ptr::null()
        } else {
            ptrs.as_ptr()
        },
    };
    f(&info)
}

/// The API version the Debian loader accepts (1.0.20 refuses 1.1 apps).
pub const API_1_0: xr::Version = xr::Version::new(1, 0, 0);
/// A 1.1 application, for the results only 1.1 defines.
pub const API_1_1: xr::Version = xr::Version::new(1, 1, 0);

impl App {
    /// Creates an instance through `chain` with these extensions.
    pub fn new(chain: Chain, extensions: &[&str], api: xr::Version) -> Result<App, xr::Result> {
        let mut instance = xr::Instance::NULL;
        // SAFETY: the create info and its strings live across the call.
        let r = with_create_info(extensions, api, |info| unsafe {
            chain.create_instance(info, &mut instance)
        });
        if r != xr::Result::SUCCESS {
            return Err(r);
        }
        Ok(App {
            chain,
            instance,
            destroyed: false,
        })
    }

    /// A function through the topmost `xrGetInstanceProcAddr`.
    ///
    /// # Safety
    /// `F` must be the function type the name implies.
    pub unsafe fn try_fn<F: Copy>(&self, name: &CStr) -> Result<F, xr::Result> {
        lookup(self.chain.gipa(), self.instance, name)
    }

    /// As [`App::try_fn`], panicking with the name when the lookup fails.
    ///
    /// # Safety
    /// As [`App::try_fn`].
    pub unsafe fn func<F: Copy>(&self, name: &CStr) -> F {
        self.try_fn(name)
            .unwrap_or_else(|r| panic!("{name:?}: {r:?}"))
    }

    /// The head-mounted display system.
    pub fn system(&self) -> xr::SystemId {
        let info = xr::SystemGetInfo {
            ty: xr::StructureType::SYSTEM_GET_INFO,
            next: std::ptr::null(),
            form_factor: xr::FormFactor::HEAD_MOUNTED_DISPLAY,
        };
        let mut system = xr::SystemId::NULL;
        // SAFETY: valid pointers; the type matches the name.
        let r = unsafe {
            self.func::<xr::pfn::GetSystem>(c"xrGetSystem")(self.instance, &info, &mut system)
        };
        assert_eq!(r, xr::Result::SUCCESS, "xrGetSystem");
        system
    }

    /// A session without graphics (XR_MND_headless must be enabled).
    pub fn headless_session(&self) -> Result<xr::Session, xr::Result> {
        let info = xr::SessionCreateInfo {
            ty: xr::StructureType::SESSION_CREATE_INFO,
            next: std::ptr::null(),
            create_flags: xr::SessionCreateFlags::EMPTY,
            system_id: self.system(),
        };
        let mut session = xr::Session::NULL;
        // SAFETY: valid pointers; the type matches the name.
        let r = unsafe {
            self.func::<xr::pfn::CreateSession>(c"xrCreateSession")(
                self.instance,
                &info,
                &mut session,
            )
        };
        if r == xr::Result::SUCCESS {
            Ok(session)
        } else {
            Err(r)
        }
    }

    /// Destroys the instance now and returns the result.
    pub fn destroy(mut self) -> xr::Result {
        self.destroy_instance()
    }

    fn destroy_instance(&mut self) -> xr::Result {
        if self.destroyed {
            return xr::Result::SUCCESS;
        }
        self.destroyed = true;
        // SAFETY: the instance is live and the type matches the name.
        unsafe {
            match self.try_fn::<xr::pfn::DestroyInstance>(c"xrDestroyInstance") {
                Ok(f) => f(self.instance),
                Err(r) => r,
            }
        }
    }
}

impl Drop for App {
    fn drop(&mut self) {
        self.destroy_instance();
    }
}
