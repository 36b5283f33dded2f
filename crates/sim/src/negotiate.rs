//! Loader ↔ runtime negotiation (spec api_initialization.adoc, "Runtime Interface Negotiation").
//!
//! The loader fills an XrNegotiateLoaderInfo with the interface and API version ranges it supports;
//! the runtime answers in XrNegotiateRuntimeRequest with the versions it picked and its
//! xrGetInstanceProcAddr. Any malformed struct or empty overlap is XR_ERROR_INITIALIZATION_FAILED.

use std::mem::size_of;

use openxr_sys as xr;

use crate::dispatch::get_instance_proc_addr;

/// Loader interface version 1 is the only one that exists.
const INTERFACE_VERSION: u32 = 1;
/// The newest API version the runtime implements. Apps asking for 1.0.x or 1.1.x are accepted at
/// xrCreateInstance.
const API_VERSION: xr::Version = xr::Version::new(1, 1, 0);

/// Versions compare without the patch number ("ignoring patch", api_initialization.adoc).
fn major_minor(v: xr::Version) -> (u16, u16) {
    (v.major(), v.minor())
}

pub(crate) unsafe fn negotiate(
    loader_info: *const xr::NegotiateLoaderInfo,
    request: *mut xr::NegotiateRuntimeRequest,
) -> xr::Result {
    if loader_info.is_null() || request.is_null() {
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    }
    let info = &*loader_info;
    let req = &mut *request;
    let info_ok = info.struct_type == xr::NegotiateLoaderInfo::TYPE
        && info.struct_version == xr::NegotiateLoaderInfo::VERSION
        && info.struct_size == size_of::<xr::NegotiateLoaderInfo>();
    let request_ok = req.struct_type == xr::NegotiateRuntimeRequest::TYPE
        && req.struct_version == xr::NegotiateRuntimeRequest::VERSION
        && req.struct_size == size_of::<xr::NegotiateRuntimeRequest>();
    if !info_ok || !request_ok {
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    }
    if !(info.min_interface_version..=info.max_interface_version).contains(&INTERFACE_VERSION) {
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    }
    let ours = major_minor(API_VERSION);
    let (min, max) = (
        major_minor(info.min_api_version),
        major_minor(info.max_api_version),
    );
    // Prefer our newest version; a loader capped at 1.0 gets 1.0.
    let api = if (min..=max).contains(&ours) {
        API_VERSION
    } else if (min..=max).contains(&(1, 0)) {
        xr::Version::new(1, 0, 0)
    } else {
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    };
    req.runtime_interface_version = INTERFACE_VERSION;
    req.runtime_api_version = api;
    req.get_instance_proc_addr = Some(get_instance_proc_addr);
    xr::Result::SUCCESS
}

#[cfg(test)]
mod tests {
    use super::*;

    fn loader_info() -> xr::NegotiateLoaderInfo {
        xr::NegotiateLoaderInfo {
            struct_type: xr::NegotiateLoaderInfo::TYPE,
            struct_version: 1,
            struct_size: size_of::<xr::NegotiateLoaderInfo>(),
            min_interface_version: 1,
            max_interface_version: 1,
            min_api_version: xr::Version::new(1, 0, 0),
            max_api_version: xr::Version::new(1, 0x3ff, 0xfff),
        }
    }

    fn request() -> xr::NegotiateRuntimeRequest {
        xr::NegotiateRuntimeRequest {
            struct_type: xr::NegotiateRuntimeRequest::TYPE,
            struct_version: 1,
            struct_size: size_of::<xr::NegotiateRuntimeRequest>(),
            runtime_interface_version: 0,
            runtime_api_version: xr::Version::new(0, 0, 0),
            get_instance_proc_addr: None,
        }
    }

    #[test]
    fn accepts_what_the_khronos_loader_sends() {
        let mut req = request();
        assert_eq!(
            unsafe { negotiate(&loader_info(), &mut req) },
            xr::Result::SUCCESS
        );
        assert_eq!(req.runtime_interface_version, 1);
        assert_eq!(req.runtime_api_version, API_VERSION);
        assert!(req.get_instance_proc_addr.is_some());
    }

    #[test]
    fn rejects_malformed_structs_and_empty_ranges() {
        let bad_infos = [
            xr::NegotiateLoaderInfo {
                struct_type: xr::LoaderInterfaceStructs::RUNTIME_REQUEST,
                ..loader_info()
            },
            xr::NegotiateLoaderInfo {
                struct_version: 2,
                ..loader_info()
            },
            xr::NegotiateLoaderInfo {
                struct_size: 8,
                ..loader_info()
            },
            xr::NegotiateLoaderInfo {
                min_interface_version: 2,
                max_interface_version: 3,
                ..loader_info()
            },
            xr::NegotiateLoaderInfo {
                min_api_version: xr::Version::new(2, 0, 0),
                max_api_version: xr::Version::new(2, 1, 0),
                ..loader_info()
            },
        ];
        for info in bad_infos {
            let mut req = request();
            assert_eq!(
                unsafe { negotiate(&info, &mut req) },
                xr::Result::ERROR_INITIALIZATION_FAILED
            );
        }
        let mut req = xr::NegotiateRuntimeRequest {
            struct_size: 4,
            ..request()
        };
        assert_eq!(
            unsafe { negotiate(&loader_info(), &mut req) },
            xr::Result::ERROR_INITIALIZATION_FAILED
        );
        assert_eq!(
            unsafe { negotiate(std::ptr::null(), &mut request()) },
            xr::Result::ERROR_INITIALIZATION_FAILED
        );
        // A 1.0-only loader gets 1.0.
        let info = xr::NegotiateLoaderInfo {
            max_api_version: xr::Version::new(1, 0, 20),
            ..loader_info()
        };
        let mut req = request();
        assert_eq!(unsafe { negotiate(&info, &mut req) }, xr::Result::SUCCESS);
        assert_eq!(req.runtime_api_version, xr::Version::new(1, 0, 0));
    }
}
