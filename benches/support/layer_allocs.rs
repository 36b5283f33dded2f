//! The check that the `malloc` interposer (`alloc.rs`, the bench's `alloc` module) sees
//! allocations made inside the dlopened layer: without it, "no allocation added by the layer"
//! would prove nothing.

use fovea_harness::Chain;
use openxr_sys as xr;
use xr::Handle;

/// Panics unless the counter sees the layer's xrEnumerateInstanceExtensionProperties, which
/// builds a Vec, allocate.
pub fn check_counter_sees_the_layer(chain: &Chain) {
    let before = crate::alloc::allocations();
    // SAFETY: the name's type matches; the count pointer is valid.
    unsafe {
        let f: xr::pfn::EnumerateInstanceExtensionProperties = fovea_harness::lookup(
            chain.gipa(),
            xr::Instance::NULL,
            c"xrEnumerateInstanceExtensionProperties",
        )
        .unwrap();
        let mut n = 0;
        f(std::ptr::null(), 0, &mut n, std::ptr::null_mut());
    }
    assert!(
        crate::alloc::allocations() > before,
        "the malloc interposer does not see the layer's allocations"
    );
}
