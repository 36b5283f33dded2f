//! Headset presets and eye-buffer sizing.
//!
//! Numbers come from public runtime records (docs/headsets.md#presets): per-eye FOV tangents as the
//! runtimes report them (LibOVR `DefaultEyeFov`, OpenVR `GetProjectionRaw`) and pixels per unit
//! tangent at the centre. The sizing rule `alignUp16(round(ppt × (tanA + tanB)))` reproduces every
//! Oculus PC runtime record exactly (docs/headsets.md#records), so the simulated runtime and the
//! layer's tools both use it.
//!
//! Pure data and arithmetic: no OpenXR, no Vulkan.

use crate::fov::Fov;

/// One eye's FOV as four positive tangents, in LibOVR order: how the presets are recorded, and what
/// the sizing rule multiplies (in f64, so sizes match the runtimes' records exactly). Outside this
/// module every FOV is a [`Fov`].
#[derive(Clone, Copy, Debug, PartialEq)]
struct Tangents {
    left: f64,
    right: f64,
    down: f64,
    up: f64,
}

impl Tangents {
    fn fov(self) -> Fov {
        Fov::from_tangents(self.left, self.right, self.up, self.down)
    }
}

/// One headset as a runtime reports it.
#[derive(Clone, Copy, Debug)]
pub struct Headset {
    /// The name used on command lines and in `FOVEA_SIM_HEADSET`.
    pub id: &'static str,
    /// The product name.
    pub name: &'static str,
    /// Left and right eye.
    eyes: [Tangents; 2],
    /// Pixels per unit tangent at the centre, x and y (LibOVR `PixelsPerTanAngleAtCenter`).
    pub pixels_per_tangent: [f64; 2],
    /// Display refresh rate the record was taken at.
    pub refresh_hz: f32,
    /// Where the numbers come from.
    pub source: &'static str,
}

const fn oculus(left: f64, right: f64, down: f64, up: f64) -> [Tangents; 2] {
    [
        Tangents {
            left,
            right,
            down,
            up,
        },
        Tangents {
            left: right,
            right: left,
            down,
            up,
        },
    ]
}

/// Every preset, in the order the documentation lists them.
pub const HEADSETS: &[Headset] = &[
    Headset {
        id: "quest2",
        name: "Meta Quest 2",
        eyes: oculus(1.279942, 1.000000, 1.191754, 1.110613),
        pixels_per_tangent: [1029.04, 1026.28],
        refresh_hz: 90.0,
        source: "hmdgdb Quest2_Native_R72 (Link, runtime 1.53)",
    },
    Headset {
        id: "quest3",
        name: "Meta Quest 3",
        eyes: oculus(1.376382, 0.839100, 1.428148, 0.965689),
        pixels_per_tangent: [931.75, 933.94],
        refresh_hz: 90.0,
        source: "hmdgdb MetaQuest3_Native_R72 (Link, runtime 1.89)",
    },
    Headset {
        id: "quest-pro",
        name: "Meta Quest Pro",
        eyes: oculus(1.376382, 0.839100, 1.376382, 0.900404),
        pixels_per_tangent: [968.74, 971.56],
        refresh_hz: 90.0,
        source: "hmdgdb MetaQuestPro_Native_R72 (Link, runtime 1.78)",
    },
    Headset {
        id: "rift-cv1",
        name: "Oculus Rift CV1",
        eyes: oculus(0.964926, 0.715264, 1.110925, 0.889498),
        pixels_per_tangent: [792.76, 792.76],
        refresh_hz: 90.0,
        source: "hmdgdb OculusRiftCV1_Native_R90 (Oculus runtime 1.47)",
    },
    Headset {
        id: "rift-s",
        name: "Oculus Rift S",
        eyes: oculus(0.965689, 1.035530, 1.150368, 1.000000),
        pixels_per_tangent: [823.28, 823.28],
        refresh_hz: 80.0,
        source: "hmdgdb OculusRiftS_Native_R80 (Oculus runtime 1.82)",
    },
    Headset {
        id: "index",
        name: "Valve Index",
        eyes: [
            Tangents {
                left: 1.279120,
                right: 1.258676,
                down: 1.408557,
                up: 1.413973,
            },
            Tangents {
                left: 1.257541,
                right: 1.281748,
                down: 1.407222,
                up: 1.415720,
            },
        ],
        // Derived so that the sizing rule gives SteamVR's recommended 2468×2740 (SS-dependent).
        pixels_per_tangent: [972.49, 970.76],
        refresh_hz: 144.0,
        source: "hmdgdb Index_Native_R144 (OpenVR raw projection); ppt derived from 2468x2740",
    },
    Headset {
        id: "pico4",
        name: "Pico 4",
        eyes: oculus(1.279942, 1.279942, 1.279942, 1.279942),
        // Derived so that the sizing rule gives the recorded 2160×2160.
        pixels_per_tangent: [843.79, 843.79],
        refresh_hz: 90.0,
        source: "hmdgdb PICO4_Native_R90 (symmetric 52 deg); ppt derived from 2160x2160",
    },
];

/// The preset names, for help texts and error messages.
pub fn ids() -> impl Iterator<Item = &'static str> {
    HEADSETS.iter().map(|h| h.id)
}

/// Looks a preset up by its command-line name.
pub fn by_id(id: &str) -> Option<&'static Headset> {
    HEADSETS.iter().find(|h| h.id == id)
}

fn align_up_16(v: u32) -> u32 {
    v.div_ceil(16) * 16
}

/// The recommended eye-buffer size for one eye: pixels per tangent times the tangent span, rounded to
/// nearest, then up to a multiple of 16 (docs/headsets.md#sizing-rule).
fn recommended_size(t: Tangents, pixels_per_tangent: [f64; 2]) -> [u32; 2] {
    let w = (pixels_per_tangent[0] * (t.left + t.right)).round() as u32;
    let h = (pixels_per_tangent[1] * (t.up + t.down)).round() as u32;
    [align_up_16(w), align_up_16(h)]
}

/// One symmetric FOV that contains every given eye's FOV: the largest half-angle on each axis,
/// mirrored. This is Quest's "symmetric FOV" mode and Oculus' "symmetric" rendering
/// (docs/headsets.md#symmetric-fov).
fn symmetric(eyes: &[Tangents]) -> Tangents {
    let h = eyes.iter().fold(0.0f64, |m, t| m.max(t.left).max(t.right));
    let v = eyes.iter().fold(0.0f64, |m, t| m.max(t.up).max(t.down));
    Tangents {
        left: h,
        right: h,
        down: v,
        up: v,
    }
}

impl Headset {
    /// The left and right eye's FOV.
    pub fn fovs(&self) -> [Fov; 2] {
        self.eyes.map(Tangents::fov)
    }

    /// Recommended per-eye size with the runtime's own (asymmetric) FOVs: the larger of the two eyes.
    pub fn recommended_size(&self) -> [u32; 2] {
        let [a, b] = self
            .eyes
            .map(|t| recommended_size(t, self.pixels_per_tangent));
        [a[0].max(b[0]), a[1].max(b[1])]
    }

    /// Recommended per-eye size when both eyes render one shared symmetric FOV.
    pub fn symmetric_size(&self) -> [u32; 2] {
        recommended_size(symmetric(&self.eyes), self.pixels_per_tangent)
    }

    /// Fraction of pixels the asymmetric FOV saves against the symmetric one.
    pub fn symmetric_pixel_saving(&self) -> f64 {
        let [aw, ah] = self.recommended_size();
        let [sw, sh] = self.symmetric_size();
        1.0 - (f64::from(aw) * f64::from(ah)) / (f64::from(sw) * f64::from(sh))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The six Oculus PC runtime records that the sizing rule must reproduce
    /// (docs/headsets.md#records), of which the presets carry four, plus the symmetric CV1 size of
    /// Oculus' asymmetric FOV FAQ (docs/headsets.md#symmetric-fov).
    #[test]
    fn sizing_reproduces_runtime_records() {
        let expect = [
            ("quest2", [2352, 2368]),
            ("quest3", [2064, 2240]),
            ("quest-pro", [2160, 2224]),
            ("rift-cv1", [1344, 1600]),
            ("rift-s", [1648, 1776]),
            // SteamVR reports 2468×2740 unaligned; the Oculus rule rounds up to 16.
            ("index", [2480, 2752]),
            ("pico4", [2160, 2160]),
        ];
        for (id, size) in expect {
            assert_eq!(by_id(id).unwrap().recommended_size(), size, "{id}");
        }
        let cv1 = by_id("rift-cv1").unwrap();
        assert_eq!(cv1.symmetric_size(), [1536, 1776]);
        let saving = cv1.symmetric_pixel_saving();
        assert!((saving - 0.212).abs() < 0.001, "{saving}");
        assert_eq!(by_id("quest3").unwrap().symmetric_size(), [2576, 2672]);
    }

    #[test]
    fn fovs_are_the_recorded_tangents_and_mirror() {
        let q3 = by_id("quest3").unwrap();
        let [l, r] = q3.fovs();
        assert!((l.left - -0.942478).abs() < 1e-5);
        assert!((l.down - -0.959931).abs() < 1e-5);
        assert_eq!(r, l.mirrored());
        let deg = l.degrees();
        assert!((deg[0] - 54.0).abs() < 1e-3 && (deg[3] - 55.0).abs() < 1e-3);
    }

    #[test]
    fn every_id_resolves_and_is_unique() {
        let all: Vec<_> = ids().collect();
        assert_eq!(
            all,
            [
                "quest2",
                "quest3",
                "quest-pro",
                "rift-cv1",
                "rift-s",
                "index",
                "pico4"
            ]
        );
        assert!(by_id("quest4").is_none());
    }
}
