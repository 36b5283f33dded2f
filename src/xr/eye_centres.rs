//! Where each view's fovea is now: what the gaze source leaves once per frame for everything that
//! follows the eyes (the maps fovea fills, injected maps, `xrGetFoveationEyeTrackedStateMETA`, the
//! stats line). docs/eye-tracking.md says where the gaze comes from and how it is filtered.
//!
//! One value per session, written by the gaze source after it located the gaze for a frame and
//! read by the consumers; a copy is a few dozen bytes, so readers take it whole under the
//! session's record lock and never hold the lock while they work.

use fovea_model::gaze::Tracking;
use fovea_model::maps::MAX_VIEWS;

/// The fovea of each view for one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EyeCentres {
    /// Per view, the fovea's centre in normalised device coordinates of that view's own FOV (y up,
    /// OpenXR's convention), already kept inside the view; only the first `views` entries hold.
    pub ndc: [[f32; 2]; MAX_VIEWS],
    /// How many views `ndc` holds (0 before the first located gaze).
    pub views: u8,
    /// How far the gaze is trusted. `Fixed`: there is no gaze and consumers use fixed foveation
    /// (the projection centres), whatever `ndc` holds.
    pub tracking: Tracking,
    /// The predicted display time (ns) the gaze was located for.
    pub time_ns: i64,
}

impl EyeCentres {
    /// No gaze: fixed foveation.
    pub const FIXED: EyeCentres = EyeCentres {
        ndc: [[0.0, 0.0]; MAX_VIEWS],
        views: 0,
        tracking: Tracking::Fixed,
        time_ns: 0,
    };

    /// Whether consumers should move the fovea to `ndc` (tracked, held or returning gaze), rather
    /// than keep fixed foveation.
    pub fn follows(&self) -> bool {
        self.tracking != Tracking::Fixed && self.views > 0
    }

    /// The centre of view `i` while the fovea follows the gaze.
    pub fn of(&self, i: usize) -> Option<[f32; 2]> {
        (self.follows() && i < usize::from(self.views)).then(|| self.ndc[i])
    }
}

impl Default for EyeCentres {
    fn default() -> EyeCentres {
        EyeCentres::FIXED
    }
}
