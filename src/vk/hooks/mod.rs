//! The intercepted commands, one file per kind of object. Each hook is declared with [`hook!`]:
//! the declaration says how its record is found, which next-layer function it goes down through
//! and what it returns where the layer cannot act, and the chassis emits the `extern "system"`
//! edge; the body is plain Rust on the record, the next function and typed arguments
//! (docs/ARCHITECTURE.md#how-a-hook-is-declared). A hook never imports another hook.

/// Declares a hook: emits its `extern "system"` function (and its aliases'), which runs inside
/// the layer's panic guard ([`crate::vk::base::ffi::guard`]), finds the record of its dispatchable
/// handle, picks the next layer's function from it, turns the application's pointers into typed
/// values and calls a plain Rust body.
///
/// ```text
/// hook! {
///     /// `vkQueueSubmit2`: …
///     queue_submit2 = "vkQueueSubmit2", queue_submit2_khr = "vkQueueSubmit2KHR";
///     on device_ref(queue), next queue_submit2 / queue_submit2_khr, fails(FAILED, panic OOM);
///     submit2(queue: val vk::Queue, count: val u32, submits: (array count) vk::SubmitInfo2<'_>,
///         fence: val vk::Fence) -> vk::Result
/// }
/// ```
///
/// - The names: the hook and the command it intercepts, then its aliases (`…KHR`, `…EXT`), which
///   share the body and pick their own next function.
/// - `on`: how the record is found from the handle argument: `device_ref` borrows the device's
///   record for the call without a lock or a reference count (recording commands, submits:
///   `crate::vk::registry::device_ref`), `device` takes its `Arc` from the map (creating and
///   destroying objects: `crate::vk::registry::device`), `instance` the instance of a physical
///   device. An unknown handle returns the failure value without a call down.
/// - `next f` picks the next layer's function from the record's table, and returns the failure
///   value where there is none; `maybe f` hands the body the `Option` (hooks that forget what
///   they kept whether or not the command goes down).
/// - `fails(v)`: returned for an unknown handle, a missing next function and a panic;
///   `fails(v, panic p)` returns `p` for a panic instead (`vkQueueSubmit` may not answer
///   `VK_ERROR_INITIALIZATION_FAILED`).
/// - The parameters, in the command's order, each with how the C value reaches the body: `val T`
///   as it is (handles, flags, counts, pointers passed down untouched); `in T`, a `const T*`, as
///   [`In<T>`](crate::vk::base::ffi::In); `out T`, a `T*`, as
///   [`Out<T>`](crate::vk::base::ffi::Out); `(array n) T`, a `const T*` of `n` elements, as
///   [`Arr<T>`](crate::vk::base::ffi::Arr); `(bytes n) c_void`, a `const void*` of `n` bytes, as
///   an `Arr<u8>`.
/// - The body gets a [`Call`](crate::vk::base::ffi::Call) (the command's name, the record, the
///   next function, and the call down with the application's arguments as they came,
///   `Call::as_given`, so that the path that changes nothing needs no `unsafe`) and the typed
///   parameters.
///
/// `raw` in place of `on …` declares a hook that finds its records itself (instance and device
/// creation and destruction, and the hooks that forget command buffers whether or not their
/// device is known): the body gets the typed parameters only.
macro_rules! hook {
    (
        $(#[$attr:meta])*
        $hook:ident = $name:literal $(, $alias:ident = $alias_name:literal)*;
        on $find:ident($handle:ident), $pick:ident $field:ident $(/ $alias_field:ident)*,
        fails $fails:tt;
        $body:ident $args:tt -> $ret:ty
    ) => {
        hook!(@edge [$(#[$attr])*] $hook $name $find $handle $pick $field $fails $body $args $ret);
        $(
            hook!(@edge
                [#[doc = concat!("`", $alias_name, "`: as [`", stringify!($hook), "`].")]]
                $alias $alias_name $find $handle $pick $alias_field $fails $body $args $ret);
        )*
    };
    (
        $(#[$attr:meta])*
        $hook:ident = $name:literal; raw, fails $fails:tt;
        $body:ident ($($arg:ident: $mode:tt $ty:ty),* $(,)?) -> $ret:ty
    ) => {
        $(#[$attr])*
        ///
        /// # Safety
        /// Called by the loader or the layer above with arguments valid as the command requires
        /// (its valid usage in the Vulkan specification): every pointer NULL or valid for the
        /// whole call.
        #[allow(clippy::too_many_arguments, clippy::unused_unit)]
        pub unsafe extern "system" fn $hook($($arg: hook!(@c $mode $ty)),*) -> $ret {
            $crate::vk::base::ffi::guard($name, hook!(@panic $fails), || {
                $(let $arg = hook!(@arg $mode $arg);)*
                $body($($arg),*)
            })
        }
    };
    (@edge [$(#[$attr:meta])*] $hook:ident $name:literal $find:ident $handle:ident $pick:ident
        $field:ident $fails:tt $body:ident ($($arg:ident: $mode:tt $ty:ty),* $(,)?) $ret:ty) => {
        $(#[$attr])*
        ///
        /// # Safety
        /// Called by the loader or the layer above with arguments valid as the command requires
        /// (its valid usage in the Vulkan specification): the handle one the loader dispatched,
        /// every pointer NULL or valid for the whole call.
        #[allow(clippy::too_many_arguments, clippy::unused_unit)]
        pub unsafe extern "system" fn $hook($($arg: hook!(@c $mode $ty)),*) -> $ret {
            $crate::vk::base::ffi::guard($name, hook!(@panic $fails), || {
                let Some(dev) = hook!(@find $find $handle) else {
                    return hook!(@fail $fails);
                };
                let next = hook!(@pick $pick dev $field $fails);
                let given = hook!(@given $pick next ($($arg),*));
                $(let $arg = hook!(@arg $mode $arg);)*
                let call = $crate::vk::base::ffi::Call { name: $name, dev: &*dev, next, given };
                $body(call, $($arg),*)
            })
        }
    };
    (@find device_ref $handle:ident) => {
        // SAFETY: the loader dispatched the command on `$handle` (or it is NULL), so it starts
        // with a dispatch key; the borrow is dropped when this call returns, before the
        // application may destroy the device (`device_ref`'s contract).
        unsafe { $crate::vk::registry::device_ref($handle) }
    };
    (@find device $handle:ident) => {
        // SAFETY: the loader dispatched the command on `$handle` (or it is NULL), so it starts
        // with a dispatch key.
        unsafe { $crate::vk::registry::device($handle) }
    };
    (@find instance $handle:ident) => {
        // SAFETY: the loader dispatched the command on `$handle`, a physical device (or NULL), so
        // it starts with its instance's dispatch key.
        unsafe { $crate::vk::registry::instance($handle) }
    };
    (@pick next $dev:ident $field:ident $fails:tt) => {
        match $dev.next.$field {
            Some(f) => f,
            None => return hook!(@fail $fails),
        }
    };
    (@pick maybe $dev:ident $field:ident $fails:tt) => {
        $dev.next.$field
    };
    (@given next $next:ident ($($arg:ident),*)) => {
        // SAFETY: the next layer's function, with the application's own arguments, unchanged:
        // what the caller promised of them holds for the call down.
        move || unsafe { $next($($arg),*) }
    };
    (@given maybe $next:ident ($($arg:ident),*)) => {
        move || {
            if let Some(f) = $next {
                // SAFETY: as for `next`.
                unsafe { f($($arg),*) }
            }
        }
    };
    (@fail ($fail:expr $(, panic $panic:expr)?)) => {
        $fail
    };
    (@panic ($fail:expr)) => {
        $fail
    };
    (@panic ($fail:expr, panic $panic:expr)) => {
        $panic
    };
    (@c val $ty:ty) => { $ty };
    (@c in $ty:ty) => { *const $ty };
    (@c out $ty:ty) => { *mut $ty };
    (@c (array $count:ident) $ty:ty) => { *const $ty };
    (@c (bytes $count:ident) $ty:ty) => { *const $ty };
    (@arg val $arg:ident) => {
        $arg
    };
    (@arg in $arg:ident) => {
        // SAFETY: the command's valid usage, which the caller promised: the struct is NULL or
        // valid, with a valid chain, and the application does not write it during the call.
        unsafe { $crate::vk::base::ffi::In::new($arg) }
    };
    (@arg out $arg:ident) => {
        // SAFETY: the command's valid usage: NULL or valid for the next layer to write, and
        // nothing else of the application's touches it during the call.
        unsafe { $crate::vk::base::ffi::Out::new($arg) }
    };
    (@arg (array $count:ident) $arg:ident) => {
        // SAFETY: the command's valid usage: NULL or valid for `$count` elements (a parameter
        // declared before it, so the application's own count, or the one struct a command
        // takes), unwritten during the call.
        unsafe { $crate::vk::base::ffi::Arr::new($arg, $count) }
    };
    (@arg (bytes $count:ident) $arg:ident) => {
        // SAFETY: the command's valid usage: NULL or valid for `$count` bytes, unwritten during
        // the call.
        unsafe { $crate::vk::base::ffi::Arr::new($arg.cast::<u8>(), $count) }
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
