//! The one field-of-view type: a view's four half-angles in radians, with `XrFovf`'s signs.
//!
//! OpenXR reports each view's FOV as angles (`XrFovf`,
//! https://registry.khronos.org/OpenXR/specs/1.0/man/html/XrFovf.html); LibOVR and OpenVR report
//! positive tangents. Everything in fovea converts to this type at its edge (the layer from
//! `XrFovf`, the headset presets from tangents) and computes with it.

/// A view's field of view in radians, with `XrFovf`'s signs (left and down negative).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fov {
    pub left: f32,
    pub right: f32,
    pub up: f32,
    pub down: f32,
}

impl Fov {
    /// From four positive tangents, the way LibOVR (`ovrFovPort`) and OpenVR
    /// (`GetProjectionRaw`, negated where negative) give them.
    pub fn from_tangents(left: f64, right: f64, up: f64, down: f64) -> Fov {
        Fov {
            left: -(left.atan() as f32),
            right: right.atan() as f32,
            up: up.atan() as f32,
            down: -(down.atan() as f32),
        }
    }

    /// The four positive tangents `[left, right, up, down]`.
    pub fn tangents(&self) -> [f64; 4] {
        [-self.left, self.right, self.up, -self.down].map(|a| f64::from(a).tan())
    }

    /// The four half-angles in degrees, `[left, right, up, down]`, all positive.
    pub fn degrees(&self) -> [f64; 4] {
        [-self.left, self.right, self.up, -self.down].map(|a| f64::from(a).to_degrees())
    }

    /// The horizontal mirror image: what the other eye of a symmetric headset sees.
    pub fn mirrored(&self) -> Fov {
        Fov {
            left: -self.right,
            right: -self.left,
            ..*self
        }
    }

    /// Where the straight-ahead direction lands in normalised device coordinates (y up): the
    /// projection centre, where fovea puts the fovea.
    ///
    /// Oculus' asymmetric FOV FAQ (docs/density-model.md#fovea-placement) computes it as
    /// `ProjectionMatrix × (0, 0, −near, 1)`; for an off-centre frustum with positive tangents
    /// `l, r, u, d` that is `((l−r)/(l+r), (d−u)/(d+u))`
    /// after the divide by w (checked against a projection matrix in [`crate::projection`]'s
    /// tests). For Quest 3's left eye (54° left, 40° right) it is at x ≈ +0.24: right of the image
    /// centre. This is the only place fovea computes it.
    pub fn projection_center_ndc(&self) -> [f32; 2] {
        let [l, r, u, d] = self.tangents();
        [((l - r) / (l + r)) as f32, ((d - u) / (d + u)) as f32]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tangents_round_trip_and_mirror() {
        let f = Fov::from_tangents(1.376382, 0.839100, 0.965689, 1.428148);
        assert!((f.left - -0.942478).abs() < 1e-5);
        assert!((f.down - -0.959931).abs() < 1e-5);
        let [l, r, u, d] = f.tangents();
        assert!((l - 1.376382).abs() < 1e-5 && (r - 0.8391).abs() < 1e-5);
        assert!((u - 0.965689).abs() < 1e-5 && (d - 1.428148).abs() < 1e-5);
        let deg = f.degrees();
        assert!((deg[0] - 54.0).abs() < 1e-3 && (deg[3] - 55.0).abs() < 1e-3);
        let m = f.mirrored();
        assert_eq!((m.left, m.right, m.up), (-f.right, -f.left, f.up));
        assert_eq!(m.mirrored(), f);
    }

    #[test]
    fn projection_centre_of_off_centre_and_centred_fovs() {
        // Quest 3 left eye: more FOV outward (left) and down, so straight ahead sits right of and
        // above the image centre.
        let [x, y] =
            Fov::from_tangents(1.376382, 0.839100, 0.965689, 1.428148).projection_center_ndc();
        assert!((x - 0.2424).abs() < 1e-3, "{x}");
        assert!((y - 0.1932).abs() < 1e-3, "{y}");
        let t = 1.279942;
        assert_eq!(
            Fov::from_tangents(t, t, t, t).projection_center_ndc(),
            [0.0, 0.0]
        );
    }
}
