//! OpenXR's values as the layer's plain ones and back, in one place: result codes and FOVs.

use openxr_sys as xr;

use fovea_model::Fov;

/// Whether a result is a success code (XR_SUCCEEDED).
pub fn succeeded(r: xr::Result) -> bool {
    r.into_raw() >= 0
}

/// An `XrFovf` as the density model's FOV.
pub fn fov_from_xr(f: xr::Fovf) -> Fov {
    Fov {
        left: f.angle_left,
        right: f.angle_right,
        up: f.angle_up,
        down: f.angle_down,
    }
}

/// The density model's FOV as an `XrFovf`.
pub fn fov_to_xr(f: Fov) -> xr::Fovf {
    xr::Fovf {
        angle_left: f.left,
        angle_right: f.right,
        angle_up: f.up,
        angle_down: f.down,
    }
}
