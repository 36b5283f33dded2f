//! The next layer's table: its pointer for every function fovea intercepts, loaded once when the
//! instance is created ([`Next`], expanded from [`crate::xr::commands`]), how one function is asked
//! for ([`load`]), and how a hook takes its pointer to go down ([`next`]).

use std::ffi::CStr;

use openxr_sys as xr;

use crate::xr::ffi::HookResult;

macro_rules! next_table {
    ($($name:literal => $field:ident: $pfn:ident = $hook:path, $owner:expr,
        ($($arg:ident : $mode:tt $ty:ty),* $(,)?);)*) => {
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
                    $($field: {
                        // SAFETY: the caller's contract.
                        let f = unsafe { load(gipa, instance, $name) };
                        // SAFETY: the next layer answered for `$name`, so the pointer has the
                        // signature the spec gives that name, which is openxr-sys's `$pfn`.
                        f.map(|f| unsafe { std::mem::transmute::<xr::pfn::VoidFunction, xr::pfn::$pfn>(f) })
                    },)*
                }
            }
        }

    };
}

crate::xr::commands::with_commands!(next_table);

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
    // SAFETY: the caller's contract; the name is NUL-terminated and `f` a live local.
    let r = unsafe { gipa(instance, name.as_ptr(), &mut f) };
    if r.into_raw() < 0 {
        return None;
    }
    f
}

/// The next layer's pointer. A hook is only handed out where the next layer offers the function
/// (see `loader::resolve`), so `None` means the table was corrupted: report a runtime failure.
pub fn next<F>(f: Option<F>) -> HookResult<F> {
    crate::common::lock::assert_none_held("going down to the next layer");
    f.ok_or(xr::Result::ERROR_RUNTIME_FAILURE)
}
