//! The `extern "system"` bodies of the intercepted commands, one file per kind of object: each
//! looks its device up, calls each mode in turn and calls down. A hook never imports another hook.

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

pub mod barrier;
pub mod device;
pub mod image;
pub mod instance;
pub mod pass;
pub mod physical;
pub mod pipeline;
pub mod record;
pub mod submit;
