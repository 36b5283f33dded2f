//! Off-centre projection matrices and the projection centre.
//!
//! An asymmetric FOV needs an off-centre frustum: four independent tangents instead of a vertical FOV
//! and an aspect ratio (Oculus' asymmetric FOV FAQ,
//! <https://developer.oculus.com/documentation/unity/latest/concepts/unity-asymmetric-fov-faq/>). The
//! straight-ahead direction then lands off the image centre, at `ProjectionMatrix × (0, 0, −near, 1)`
//! (same FAQ, OpenGL form), which is where the density model puts the fovea
//! ([`crate::Fov::projection_center_ndc`]; docs/density-model.md#fovea-placement).
//!
//! Depth: the third row must map the near plane to the start of the depth range and the far plane to
//! its end (−1 and 1 in OpenGL, 0 and 1 in Direct3D/Vulkan). The Rift SDK documentation's matrix had
//! `f/(n−f)` and `fn/(n−f)` there, which puts the nominal near plane at 0 instead of −1 in OpenGL,
//! wasting half the depth range and clipping at the wrong distance; the correction is
//! `(n+f)/(n−f)` and `2fn/(n−f)` (Oliver Kreylos, "Small Correction to Rift's Projection Matrix",
//! <http://doc-ok.org/?p=804>). The tests pin every convention below.
//!
//! View space is right-handed, looking down −z, y up (OpenXR).

use glam::{Mat4, Vec4};

use crate::fov::Fov;

/// The clip-space convention a graphics API expects.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ClipSpace {
    /// z in −1..1, y up.
    OpenGl,
    /// z in 0..1, y up.
    Direct3D,
    /// z in 0..1, y down (Vulkan's clip space flips y relative to OpenGL).
    Vulkan,
}

/// How depth maps into the clip volume.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Depth {
    /// Near plane distance (> 0).
    pub near: f32,
    /// Far plane distance; `None` for an infinite far plane.
    pub far: Option<f32>,
    /// Reversed-Z: near maps to the far end of the range (1), far to the near end (−1 or 0), which
    /// spreads float precision evenly over distance.
    pub reversed: bool,
}

/// The projection matrix for `fov` (`XrFovf` angles) in the given convention.
pub fn projection(fov: Fov, clip: ClipSpace, depth: Depth) -> Mat4 {
    let (l, r) = (f64::from(fov.left).tan(), f64::from(fov.right).tan());
    let (d, u) = (f64::from(fov.down).tan(), f64::from(fov.up).tan());
    let (sx, ox) = (2.0 / (r - l), (r + l) / (r - l));
    let (mut sy, mut oy) = (2.0 / (u - d), (u + d) / (u - d));
    if clip == ClipSpace::Vulkan {
        sy = -sy;
        oy = -oy;
    }
    let n = f64::from(depth.near);
    // z_ndc = (a·z + b) / −z.
    let (a, b) = match (
        clip == ClipSpace::OpenGl,
        depth.far.map(f64::from),
        depth.reversed,
    ) {
        (true, Some(f), false) => (-(f + n) / (f - n), -2.0 * f * n / (f - n)),
        (true, Some(f), true) => ((f + n) / (f - n), 2.0 * f * n / (f - n)),
        (true, None, false) => (-1.0, -2.0 * n),
        (true, None, true) => (1.0, 2.0 * n),
        (false, Some(f), false) => (-f / (f - n), -f * n / (f - n)),
        (false, Some(f), true) => (n / (f - n), f * n / (f - n)),
        (false, None, false) => (-1.0, -n),
        (false, None, true) => (0.0, n),
    };
    Mat4::from_cols(
        Vec4::new(sx as f32, 0.0, 0.0, 0.0),
        Vec4::new(0.0, sy as f32, 0.0, 0.0),
        Vec4::new(ox as f32, oy as f32, a as f32, -1.0),
        Vec4::new(0.0, 0.0, b as f32, 0.0),
    )
}

/// The projection centre in the matrix's NDC: `P × (0, 0, −near, 1)` divided by w (Oculus'
/// asymmetric FOV FAQ, docs/density-model.md#fovea-placement). For OpenGL and Direct3D it equals [`Fov::projection_center_ndc`]; Vulkan's y is flipped.
pub fn projection_center_ndc(m: &Mat4, near: f32) -> [f32; 2] {
    let c = *m * Vec4::new(0.0, 0.0, -near, 1.0);
    [c.x / c.w, c.y / c.w]
}

/// NDC depth of a point at distance `dist` in front of the eye.
pub fn ndc_depth(m: &Mat4, dist: f32) -> f32 {
    let c = *m * Vec4::new(0.0, 0.0, -dist, 1.0);
    c.z / c.w
}

/// One symmetric FOV containing every given FOV: the largest half-angle on each axis, mirrored.
/// Quest's symmetric-FOV mode renders both eyes with it (docs/headsets.md#symmetric-fov); the pixels
/// outside an eye's own FOV are never shown. `None` for no FOVs.
pub fn symmetric_fov(fovs: &[Fov]) -> Option<Fov> {
    let h = fovs
        .iter()
        .map(|f| (-f.left).max(f.right))
        .reduce(f32::max)?;
    let v = fovs.iter().map(|f| f.up.max(-f.down)).reduce(f32::max)?;
    Some(Fov {
        left: -h,
        right: h,
        up: v,
        down: -v,
    })
}

/// The image size that keeps `size`'s pixels per tangent when the FOV grows from `from` to `to`:
/// rounded to nearest, then up to a multiple of 16 (the sizing rule, docs/headsets.md#sizing-rule).
pub fn rescaled_size(size: [u32; 2], from: Fov, to: Fov) -> [u32; 2] {
    let span = |a: f32, b: f32| f64::from(b).tan() - f64::from(a).tan();
    let scale = |px: u32, old: f64, new: f64| {
        if !(old > 0.0 && new.is_finite()) {
            return px;
        }
        let n = (f64::from(px) * new / old)
            .round()
            .clamp(1.0, f64::from(u32::MAX - 15)) as u32;
        n.div_ceil(16) * 16
    };
    [
        scale(
            size[0],
            span(from.left, from.right),
            span(to.left, to.right),
        ),
        scale(size[1], span(from.down, from.up), span(to.down, to.up)),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::headsets::by_id;

    fn quest3_left() -> Fov {
        by_id("quest3").unwrap().fovs()[0]
    }

    fn close(a: f32, b: f32, eps: f32) -> bool {
        (a - b).abs() <= eps
    }

    #[test]
    fn depth_maps_near_and_far_to_the_range_ends() {
        let fov = quest3_left();
        let (n, f) = (0.05, 100.0);
        let cases = [
            (ClipSpace::OpenGl, false, -1.0, 1.0),
            (ClipSpace::OpenGl, true, 1.0, -1.0),
            (ClipSpace::Direct3D, false, 0.0, 1.0),
            (ClipSpace::Direct3D, true, 1.0, 0.0),
            (ClipSpace::Vulkan, false, 0.0, 1.0),
            (ClipSpace::Vulkan, true, 1.0, 0.0),
        ];
        for (clip, reversed, at_near, at_far) in cases {
            let m = projection(
                fov,
                clip,
                Depth {
                    near: n,
                    far: Some(f),
                    reversed,
                },
            );
            assert!(
                close(ndc_depth(&m, n), at_near, 1e-5),
                "{clip:?} rev={reversed} near"
            );
            assert!(
                close(ndc_depth(&m, f), at_far, 1e-4),
                "{clip:?} rev={reversed} far"
            );
            let inf = projection(
                fov,
                clip,
                Depth {
                    near: n,
                    far: None,
                    reversed,
                },
            );
            assert!(
                close(ndc_depth(&inf, n), at_near, 1e-5),
                "{clip:?} rev={reversed} inf near"
            );
            assert!(
                close(ndc_depth(&inf, 1.0e7), at_far, 1e-4),
                "{clip:?} rev={reversed} inf far"
            );
        }
    }

    /// The Rift SDK documentation's third row (<http://doc-ok.org/?p=804>) puts the near plane at 0
    /// in OpenGL's −1..1; the corrected one puts it at −1.
    #[test]
    fn corrected_third_row_differs_from_the_documented_one() {
        let (n, f) = (0.1f32, 10.0f32);
        let documented = |z: f32| ((f / (n - f)) * z + (f * n / (n - f))) / -z;
        assert!(close(documented(-n), 0.0, 1e-6));
        let m = projection(
            quest3_left(),
            ClipSpace::OpenGl,
            Depth {
                near: n,
                far: Some(f),
                reversed: false,
            },
        );
        assert!(close(ndc_depth(&m, n), -1.0, 1e-6));
        assert!(close(m.z_axis.z, (n + f) / (n - f), 1e-6));
        assert!(close(m.w_axis.z, 2.0 * f * n / (n - f), 1e-6));
    }

    #[test]
    fn frustum_edges_land_on_the_ndc_edges() {
        let fov = quest3_left();
        let m = projection(
            fov,
            ClipSpace::OpenGl,
            Depth {
                near: 0.1,
                far: Some(10.0),
                reversed: false,
            },
        );
        let edge = |tx: f32, ty: f32| {
            let c = m * Vec4::new(tx * 2.0, ty * 2.0, -2.0, 1.0);
            [c.x / c.w, c.y / c.w]
        };
        let [l, r, u, d] = [fov.left, fov.right, fov.up, fov.down].map(f32::tan);
        assert!(close(edge(l, 0.0)[0], -1.0, 1e-5) && close(edge(r, 0.0)[0], 1.0, 1e-5));
        assert!(close(edge(0.0, d)[1], -1.0, 1e-5) && close(edge(0.0, u)[1], 1.0, 1e-5));
        let vk = projection(
            fov,
            ClipSpace::Vulkan,
            Depth {
                near: 0.1,
                far: Some(10.0),
                reversed: false,
            },
        );
        let c = vk * Vec4::new(0.0, u * 2.0, -2.0, 1.0);
        assert!(close(c.y / c.w, -1.0, 1e-5), "Vulkan y points down");
    }

    #[test]
    fn projection_centre_matches_the_faq_formula() {
        let fov = quest3_left();
        let want = fov.projection_center_ndc();
        // Quest 3 left eye: 54° left, 40° right, 44° up, 55° down: straight ahead is right of and
        // above the image centre.
        assert!(
            close(want[0], 0.2425, 1e-3) && close(want[1], 0.1929, 1e-3),
            "{want:?}"
        );
        for clip in [ClipSpace::OpenGl, ClipSpace::Direct3D] {
            let m = projection(
                fov,
                clip,
                Depth {
                    near: 0.05,
                    far: None,
                    reversed: true,
                },
            );
            let got = projection_center_ndc(&m, 0.05);
            assert!(
                close(got[0], want[0], 1e-5) && close(got[1], want[1], 1e-5),
                "{clip:?} {got:?}"
            );
        }
        let vk = projection(
            fov,
            ClipSpace::Vulkan,
            Depth {
                near: 0.05,
                far: Some(1.0),
                reversed: false,
            },
        );
        let got = projection_center_ndc(&vk, 0.05);
        assert!(close(got[0], want[0], 1e-5) && close(got[1], -want[1], 1e-5));
        let sym = Fov {
            left: -0.8,
            right: 0.8,
            up: 0.7,
            down: -0.7,
        };
        assert_eq!(sym.projection_center_ndc(), [0.0, 0.0]);
    }

    #[test]
    fn symmetric_fov_contains_both_eyes_and_sizes_follow_it() {
        let q3 = by_id("quest3").unwrap();
        let eyes = q3.fovs();
        let shared = symmetric_fov(&eyes).unwrap();
        assert_eq!(shared.left, -shared.right);
        assert_eq!(shared.up, -shared.down);
        for e in eyes {
            assert!(shared.left <= e.left && shared.right >= e.right);
            assert!(shared.down <= e.down && shared.up >= e.up);
        }
        assert_eq!(
            shared.right, -eyes[0].left,
            "Quest 3's widest half-angle is 54° outward"
        );
        // From the runtime's recommended size to the symmetric one, as the preset computes it
        // from pixels per tangent (the recommended size was already rounded up, hence ±16).
        let got = rescaled_size(q3.recommended_size(), eyes[0], shared);
        let want = q3.symmetric_size();
        for axis in 0..2 {
            assert_eq!(got[axis] % 16, 0);
            assert!(got[axis].abs_diff(want[axis]) <= 16, "{got:?} vs {want:?}");
        }
        assert_eq!(rescaled_size([1000, 1000], eyes[0], eyes[0]), [1008, 1008]);
        assert!(symmetric_fov(&[]).is_none());
    }
}
