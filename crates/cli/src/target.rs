//! The headset `fovea maps` and `fovea report` describe: a preset, or the headset a user actually
//! has, given as per-eye FOVs (and optionally a size) on the command line. Both become the same two
//! views, so the maps and figures come from one code path.

use fovea_model::density::{Grid, Rect, View};
use fovea_model::headsets::Headset;
use fovea_model::Fov;

use crate::args::TargetArgs;

/// Pixels per unit tangent used to size an eye buffer when `--fov` comes without `--size`. The
/// presets' runtimes recommend 790 to 1030 (Rift CV1 to Quest 2) at the centre; 1000 is a round
/// figure within that range, so the derived size is what such a runtime would roughly recommend.
pub const DEFAULT_PIXELS_PER_TANGENT: f64 = 1000.0;

/// What the model sees of a headset: each eye's FOV and the per-eye eye-buffer size.
#[derive(Clone, Debug)]
pub struct Target {
    /// The preset id, or `custom`: the JSON's `headset` and the PNG file names.
    pub id: &'static str,
    /// The product name, or what the command line gave.
    pub name: String,
    /// Left and right eye.
    pub fovs: [Fov; 2],
    /// Per-eye eye-buffer size.
    pub size: [u32; 2],
    /// How a command-line FOV was sized; `None` for a preset.
    pub custom: Option<Sizing>,
}

/// Where a command-line headset's size came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sizing {
    /// `--size WxH`.
    Given,
    /// From the FOV at [`DEFAULT_PIXELS_PER_TANGENT`].
    FromFov,
}

impl Target {
    /// A preset at its recommended size.
    pub fn preset(h: &'static Headset) -> Target {
        Target {
            id: h.id,
            name: h.name.to_owned(),
            fovs: h.fovs(),
            size: h.recommended_size(),
            custom: None,
        }
    }

    /// FOVs from the command line. `right` defaults to the mirror image of `left`: headsets are
    /// built symmetric about the nose, and runtimes report them so.
    pub fn custom(left: Fov, right: Option<Fov>, size: Option<[u32; 2]>) -> Target {
        let right_given = right.is_some();
        let fovs = [left, right.unwrap_or_else(|| left.mirrored())];
        let (size, sizing) = match size {
            Some(s) => (s, Sizing::Given),
            None => (size_from_fov(&fovs), Sizing::FromFov),
        };
        let deg = |f: &Fov| {
            let [l, r, u, d] = f.degrees();
            format!("{l:.1},{r:.1},{u:.1},{d:.1}")
        };
        let name = if right_given {
            format!("--fov {} --fov-right {}", deg(&fovs[0]), deg(&fovs[1]))
        } else {
            format!("--fov {} (right eye mirrored)", deg(&fovs[0]))
        };
        Target {
            id: "custom",
            name,
            fovs,
            size,
            custom: Some(sizing),
        }
    }

    /// From `--headset` or `--fov`/`--fov-right`/`--size`; clap has made sure one of them is there.
    pub fn from_args(args: &TargetArgs) -> Target {
        match (args.headset, args.fov) {
            (Some(h), _) => Target::preset(h),
            (None, Some(left)) => Target::custom(left, args.fov_right, args.size),
            (None, None) => unreachable!("clap requires --headset or --fov"),
        }
    }

    /// One line saying how a command-line headset was sized, for the outputs; `None` for presets.
    pub fn sizing_note(&self) -> Option<String> {
        let [w, h] = self.size;
        match self.custom? {
            Sizing::Given => None,
            Sizing::FromFov => Some(format!(
                "{w}x{h} per eye from the FOV at {DEFAULT_PIXELS_PER_TANGENT} pixels per unit \
                 tangent (no --size given; --size WxH sets it)"
            )),
        }
    }

    /// One eye at the target's size, as the density model sees it.
    pub fn eye_view(&self, eye: usize, texel: u32) -> (Grid, View) {
        let [w, h] = self.size;
        let view = View {
            fov: self.fovs[eye],
            rect: Rect {
                x: 0,
                y: 0,
                width: w,
                height: h,
            },
            visible: None,
        };
        (Grid::new([w, h], [texel, texel]), view)
    }
}

/// The runtimes' sizing rule (pixels per tangent times the tangent span, rounded, then up to a
/// multiple of 16) at [`DEFAULT_PIXELS_PER_TANGENT`]; the larger of the two eyes on each axis.
fn size_from_fov(fovs: &[Fov; 2]) -> [u32; 2] {
    let side = |a: f64, b: f64| -> u32 {
        let px = (DEFAULT_PIXELS_PER_TANGENT * (a + b)).round() as u32;
        px.div_ceil(16) * 16
    };
    fovs.iter()
        .map(|f| {
            let [l, r, u, d] = f.tangents();
            [side(l, r), side(u, d)]
        })
        .fold([0, 0], |[w, h], [a, b]| [w.max(a), h.max(b)])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::args::parse_fov;

    #[test]
    fn custom_fovs_mirror_and_size() {
        let t = Target::custom(parse_fov("45,45,45,45").unwrap(), None, None);
        assert_eq!(t.size, [2000, 2000]);
        assert_eq!(t.fovs[1], t.fovs[0].mirrored());
        assert!(t
            .sizing_note()
            .unwrap()
            .contains("1000 pixels per unit tangent"));
        // Quest 3's left eye: the mirrored right eye is Quest 3's right eye.
        let q3 = Target::preset(fovea_model::headsets::by_id("quest3").unwrap());
        let t = Target::custom(parse_fov("54,40,44,55").unwrap(), None, Some([2064, 2240]));
        for (a, b) in t.fovs.iter().zip(&q3.fovs) {
            for (x, y) in a.degrees().iter().zip(b.degrees()) {
                assert!((x - y).abs() < 1e-3, "{a:?} {b:?}");
            }
        }
        assert_eq!(t.sizing_note(), None);
        let right = parse_fov("40,50,44,55").unwrap();
        let t = Target::custom(parse_fov("54,40,44,55").unwrap(), Some(right), None);
        assert_eq!(t.fovs[1], right);
        assert!(t.name.contains("--fov-right"), "{}", t.name);
    }
}
