//! The FFI panic guard: every entry point a loader or an application calls runs its body inside
//! [`guard`], so that a panic never unwinds into the caller (undefined behaviour across
//! `extern "system"`). A panic becomes the entry point's failure value and one error line naming
//! the function; the application goes on.

use std::panic::{catch_unwind, AssertUnwindSafe};

/// Runs an entry point's body; a panic becomes `fail` and the error line `line` naming `function`.
/// Inlined into each entry point (one call frame fewer on every call; the OpenXR frame loop makes
/// seven), with the rare path out of line.
#[inline(always)]
pub fn guard<R>(
    function: &'static str,
    line: &'static str,
    fail: R,
    body: impl FnOnce() -> R,
) -> R {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(result) => result,
        Err(payload) => caught(function, line, fail, payload),
    }
}

#[cold]
fn caught<R>(
    function: &'static str,
    line: &'static str,
    fail: R,
    payload: Box<dyn std::any::Any + Send>,
) -> R {
    let message = payload
        .downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "non-string panic payload".to_owned());
    tracing::error!(function, %message, "{line}");
    fail
}
