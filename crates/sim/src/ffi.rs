//! Small helpers for the C side of entry points: next chains, the two-call idiom, strings.

use std::ffi::{c_char, c_void, CStr};

use openxr_sys as xr;

/// Spec "Valid Usage" for XrPosef inputs: the orientation must be a unit quaternion (runtimes accept
/// about 1% deviation), otherwise XR_ERROR_POSE_INVALID.
pub(crate) fn check_pose(p: &xr::Posef) -> Result<(), xr::Result> {
    let q = p.orientation;
    let norm = (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w).sqrt();
    let finite = [q.x, q.y, q.z, q.w, p.position.x, p.position.y, p.position.z]
        .iter()
        .all(|v| v.is_finite());
    if finite && (norm - 1.0).abs() <= 0.01 {
        Ok(())
    } else {
        Err(xr::Result::ERROR_POSE_INVALID)
    }
}

/// Fails with XR_ERROR_VALIDATION_FAILURE when a required pointer is NULL (implicit valid usage:
/// "must be a pointer to a valid ...").
pub(crate) fn non_null<T>(p: *const T) -> Result<(), xr::Result> {
    if p.is_null() {
        Err(xr::Result::ERROR_VALIDATION_FAILURE)
    } else {
        Ok(())
    }
}

/// Reads the `type` of a struct the application passed and checks it (implicit valid usage: "type
/// must be XR_TYPE_..."), returning a reference to it.
///
/// # Safety
/// `p` must be NULL or point to a readable `T` whose first member is an `XrStructureType`.
pub(crate) unsafe fn input<'a, T>(p: *const T, ty: xr::StructureType) -> Result<&'a T, xr::Result> {
    non_null(p)?;
    if *(p as *const xr::StructureType) != ty {
        return Err(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    Ok(&*p)
}

/// Checks the `type` of an output struct and returns a mutable pointer to it.
///
/// # Safety
/// As [`input`], writable.
pub(crate) unsafe fn output<T>(p: *mut T, ty: xr::StructureType) -> Result<*mut T, xr::Result> {
    input(p as *const T, ty)?;
    Ok(p)
}

/// The structure types found along a `next` chain, in order. Unknown structs are never interpreted
/// beyond their header (spec: runtimes must ignore unrecognised structs).
///
/// # Safety
/// `next` must be NULL or a valid chain.
pub(crate) unsafe fn chain_types(next: *const c_void) -> Vec<xr::StructureType> {
    let mut types = Vec::new();
    let mut p = next as *const xr::BaseInStructure;
    // A bound guards against cyclic chains from broken callers.
    while !p.is_null() && types.len() < 64 {
        types.push((*p).ty);
        p = (*p).next;
    }
    types
}

/// The first struct of `ty` in a chain (spec, "Next Chain Structure Uniqueness": only the first
/// counts).
///
/// # Safety
/// As [`chain_types`].
pub(crate) unsafe fn find_in_chain(
    next: *const c_void,
    ty: xr::StructureType,
) -> Option<*const c_void> {
    let mut p = next as *const xr::BaseInStructure;
    let mut steps = 0;
    while !p.is_null() && steps < 64 {
        if (*p).ty == ty {
            return Some(p as *const c_void);
        }
        p = (*p).next;
        steps += 1;
    }
    None
}

/// The two-call idiom ("Buffer Size Parameters"): capacity 0 asks for the count; a non-zero capacity
/// smaller than the count is XR_ERROR_SIZE_INSUFFICIENT with the count still written. `fill` writes
/// element `i` and may reject it (e.g. a wrong `type` in an application-provided array).
///
/// # Safety
/// `count_out` must be NULL or writable; `out` must hold `capacity` elements when `capacity > 0`.
pub(crate) unsafe fn two_call<T>(
    capacity: u32,
    count_out: *mut u32,
    out: *mut T,
    count: usize,
    mut fill: impl FnMut(usize, *mut T) -> Result<(), xr::Result>,
) -> Result<(), xr::Result> {
    non_null(count_out)?;
    let count32 = u32::try_from(count).map_err(|_| xr::Result::ERROR_RUNTIME_FAILURE)?;
    *count_out = count32;
    if capacity == 0 {
        return Ok(());
    }
    if capacity < count32 {
        return Err(xr::Result::ERROR_SIZE_INSUFFICIENT);
    }
    non_null(out)?;
    for i in 0..count {
        fill(i, out.add(i))?;
    }
    Ok(())
}

/// Two-call idiom for a string; counts include the terminating NUL.
///
/// # Safety
/// As [`two_call`].
pub(crate) unsafe fn two_call_str(
    capacity: u32,
    count_out: *mut u32,
    buffer: *mut c_char,
    s: &str,
) -> Result<(), xr::Result> {
    let bytes: Vec<u8> = s.bytes().chain(std::iter::once(0)).collect();
    two_call(capacity, count_out, buffer, bytes.len(), |i, p| {
        *p = bytes[i] as c_char;
        Ok(())
    })
}

/// Copies `s` into a fixed-size C string field, truncating and always NUL-terminating.
pub(crate) fn copy_str(dst: &mut [c_char], s: &str) {
    let n = s.len().min(dst.len().saturating_sub(1));
    for (d, b) in dst.iter_mut().zip(s.bytes().take(n)) {
        *d = b as c_char;
    }
    if let Some(end) = dst.get_mut(n) {
        *end = 0;
    }
}

/// A C string from the application, or `None` when NULL or not UTF-8.
///
/// # Safety
/// `p` must be NULL or a NUL-terminated string.
pub(crate) unsafe fn c_str<'a>(p: *const c_char) -> Option<&'a str> {
    if p.is_null() {
        return None;
    }
    CStr::from_ptr(p).to_str().ok()
}

/// A fixed-size C string field, which must be NUL-terminated within its size.
pub(crate) fn fixed_str(field: &[c_char]) -> Option<&str> {
    let bytes: &[u8] =
        unsafe { std::slice::from_raw_parts(field.as_ptr() as *const u8, field.len()) };
    let end = bytes.iter().position(|&b| b == 0)?;
    std::str::from_utf8(&bytes[..end]).ok()
}
