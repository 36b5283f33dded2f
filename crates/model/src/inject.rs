//! Injection: which of an application's passes are eye passes, which view each part of one holds,
//! and the shading-rate codes fovea gives it (docs/injection.md).
//!
//! An application that never asks for foveation still renders its eyes into the swapchains the
//! OpenXR side knows, either directly or through an intermediate target of the same shape. A pass
//! is an **eye pass** when its colour target
//!
//! 1. is a swapchain image that holds views (per-eye swapchains, an array of views, a double-wide
//!    image); the view follows from the swapchain (its eye, the array layer, the half), or
//! 2. has the shape of one: the aspect of one view, or of two side by side, within
//!    [`ASPECT_TOLERANCE`], at [`MIN_SCALE`] to [`MAX_SCALE`] times a view's width (the
//!    OpenXR-Toolkit rule, see docs/injection.md#which-passes). A multi-layer target holds view `i`
//!    in its layer `i`; a one-layer slice of an array image holds the view of its layer; a one-layer
//!    target of its own is an eye whose side cannot be told, and gets the finer rate of every view
//!    ([`Views::Merged`]), which is never coarser than either eye's map.
//!
//! Everything else (depth-only passes, shadow maps, UI, small or odd-shaped targets, mirror windows)
//! renders at full rate. The caller passes only passes with a colour target.

use crate::density::{self, Grid, Pattern, Rect, View};
use crate::fov::Fov;
use crate::maps::{FALLBACK_FOV, MAX_VIEWS};
use crate::shading_rate;
use crate::shift::{self, Placed};

/// How far a target's aspect ratio (width / height) may be from a view's, relative: 1 %.
pub const ASPECT_TOLERANCE: f64 = 0.01;

/// The narrowest eye-shaped target that counts, as a fraction of a view's width. Below it sit the
/// inputs of upscalers (0.5–0.67 of the output), mirror and preview windows, and bloom and blur
/// chains, none of which should be foveated.
pub const MIN_SCALE: f64 = 0.75;

/// The widest eye-shaped target that counts, as a multiple of a view's width: supersampled eye
/// buffers, but not the square 2× targets (shadow maps, probes) of an app with square eyes.
pub const MAX_SCALE: f64 = 1.5;

/// What a swapchain's images hold, as the OpenXR side learned it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Holds {
    /// One view: the swapchain is that view's (one swapchain per eye).
    View(u8),
    /// Array layer `i` holds view `i` (an array of two for stereo).
    Layers,
    /// One double-wide image: view 0 in the left half, view 1 in the right half.
    Halves,
}

/// A swapchain whose images hold views.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Swapchain {
    /// Width and height in pixels.
    pub extent: [u32; 2],
    /// Array layers.
    pub layers: u32,
    pub holds: Holds,
}

impl Swapchain {
    /// The size of one view in this swapchain's images.
    pub fn view_extent(&self) -> [u32; 2] {
        match self.holds {
            Holds::Halves => [self.extent[0] / 2, self.extent[1]],
            Holds::View(_) | Holds::Layers => self.extent,
        }
    }
}

/// A pass's colour target.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Target {
    /// The target's width and height in pixels (the attachment's, the framebuffer's).
    pub extent: [u32; 2],
    /// The first array layer of the image the pass renders.
    pub base_layer: u32,
    /// Layers rendered: the view's layer count, or the views of a multiview pass.
    pub layers: u32,
    /// Array layers of the whole image.
    pub image_layers: u32,
    /// Which of the swapchains the image is one of, if it is a swapchain image.
    pub swapchain: Option<usize>,
}

/// Which view each part of an eye pass holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Views {
    /// Rendered layer `i` (0-based from the first rendered layer) holds view `first + i`, over
    /// the whole target.
    Layers { first: u8, count: u8 },
    /// One layer: view 0 in the left half, view 1 in the right half.
    Halves,
    /// One layer whose view cannot be told: each texel gets the finer rate of every view.
    Merged,
}

/// What a pass is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Pass {
    /// Renders one or more views: foveate it.
    Eye(Views),
    /// Anything else: full rate.
    Other,
}

/// Whether `a`'s aspect is within [`ASPECT_TOLERANCE`] of `ratio` times `b`'s.
fn aspect_matches(a: [u32; 2], b: [u32; 2], ratio: f64) -> bool {
    if a[1] == 0 || b[1] == 0 || b[0] == 0 {
        return false;
    }
    let want = ratio * f64::from(b[0]) / f64::from(b[1]);
    let got = f64::from(a[0]) / f64::from(a[1]);
    (got - want).abs() <= ASPECT_TOLERANCE * want
}

/// Whether a target `width` wide is within the scale range of views `per_view` wide, `count` of
/// them side by side.
fn scale_matches(width: u32, per_view: u32, count: u32) -> bool {
    let full = f64::from(per_view) * f64::from(count);
    if full == 0.0 {
        return false;
    }
    let s = f64::from(width) / full;
    (MIN_SCALE..=MAX_SCALE).contains(&s)
}

/// Decides whether `target` is an eye pass, given the swapchains holding `views` views (2 for
/// stereo; at most [`MAX_VIEWS`]). Pure arithmetic over at most a few swapchains: cheap enough to
/// run when a pass begins, though callers cache it per target.
pub fn classify(swapchains: &[Swapchain], views: u8, target: &Target) -> Pass {
    let views = views.min(MAX_VIEWS as u8);
    if views == 0 || target.layers == 0 || target.extent[0] == 0 || target.extent[1] == 0 {
        return Pass::Other;
    }
    if let Some(i) = target.swapchain {
        let Some(sc) = swapchains.get(i) else {
            return Pass::Other;
        };
        return match sc.holds {
            Holds::View(v) if v < views && target.layers == 1 => {
                Pass::Eye(Views::Layers { first: v, count: 1 })
            }
            Holds::View(_) => Pass::Other,
            Holds::Layers => {
                let end = target.base_layer.saturating_add(target.layers);
                if end <= u32::from(views) && end <= sc.layers {
                    Pass::Eye(Views::Layers {
                        first: target.base_layer as u8,
                        count: target.layers as u8,
                    })
                } else {
                    Pass::Other
                }
            }
            Holds::Halves if target.layers == 1 && views >= 2 => Pass::Eye(Views::Halves),
            Holds::Halves => Pass::Other,
        };
    }
    for sc in swapchains {
        let view = sc.view_extent();
        if aspect_matches(target.extent, view, 1.0) && scale_matches(target.extent[0], view[0], 1) {
            let end = target.base_layer.saturating_add(target.layers);
            return if target.layers > 1 {
                if target.base_layer == 0 && target.layers <= u32::from(views) {
                    Pass::Eye(Views::Layers {
                        first: 0,
                        count: target.layers as u8,
                    })
                } else {
                    Pass::Other
                }
            } else if target.image_layers > 1 && end <= u32::from(views) {
                // One slice of an array of views, rendered a layer at a time.
                Pass::Eye(Views::Layers {
                    first: target.base_layer as u8,
                    count: 1,
                })
            } else if target.image_layers > 1 {
                Pass::Other
            } else {
                Pass::Eye(Views::Merged)
            };
        }
        if views >= 2
            && target.layers == 1
            && aspect_matches(target.extent, view, 2.0)
            && scale_matches(target.extent[0], view[0], 2)
        {
            return Pass::Eye(Views::Halves);
        }
    }
    Pass::Other
}

/// The density-model layers of an injected map over a target of `extent`: per output layer, the
/// views drawn into it (with their FOVs, [`FALLBACK_FOV`] where a view's is not known yet), and
/// whether the layers are to be merged into one (finer rate per texel).
pub fn map_layers(
    views: Views,
    extent: [u32; 2],
    fovs: &[Option<Fov>; MAX_VIEWS],
) -> (Vec<Vec<View>>, bool) {
    let fov = |v: usize| fovs.get(v).copied().flatten().unwrap_or(FALLBACK_FOV);
    let whole = Rect {
        x: 0,
        y: 0,
        width: extent[0],
        height: extent[1],
    };
    let view = |v: usize, rect: Rect| View {
        fov: fov(v),
        rect,
        visible: None,
    };
    match views {
        Views::Layers { first, count } => (
            (0..usize::from(count))
                .map(|i| vec![view(usize::from(first) + i, whole)])
                .collect(),
            false,
        ),
        Views::Halves => {
            let half = extent[0] / 2;
            let left = Rect {
                width: half,
                ..whole
            };
            let right = Rect {
                x: half as i32,
                width: extent[0] - half,
                ..whole
            };
            (vec![vec![view(0, left), view(1, right)]], false)
        }
        Views::Merged => {
            let mut out: Vec<Vec<View>> = (0..MAX_VIEWS)
                .filter(|&v| fovs[v].is_some())
                .map(|v| vec![view(v, whole)])
                .collect();
            if out.is_empty() {
                out.push(vec![view(0, whole)]);
            }
            (out, true)
        }
    }
}

/// What a device's shading-rate attachments allow, as the Vulkan side learned at `vkCreateDevice`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Device {
    /// The attachment texel in pixels.
    pub texel: [u32; 2],
    /// `layeredShadingRateAttachments`: one rate layer per view, else one merged layer.
    pub layered: bool,
    /// `maxFragmentSize`.
    pub max_fragment: [u32; 2],
    /// The fragment sizes the device lists for one sample.
    pub rates: Vec<[u32; 2]>,
}

/// The shading-rate codes (R8_UINT, one per texel, layer after layer) of the map an eye pass with
/// `views` over a target of `extent` gets on `device`, at `pattern` and capped at `max_fragment`:
/// the density model's map for each view's FOV, exactly as a foveated swapchain's, converted to
/// codes. Returns the map's extent in texels, its layer count and the codes.
pub fn codes(
    device: &Device,
    views: Views,
    extent: [u32; 2],
    fovs: &[Option<Fov>; MAX_VIEWS],
    pattern: Pattern,
    max_fragment: u32,
) -> ([u32; 2], u32, Vec<u8>) {
    let fixed = FixedCodes::new(device, views, extent, fovs, pattern, max_fragment);
    let mut out = Vec::new();
    fixed.codes_into(&[None; MAX_VIEWS], &mut Vec::new(), &mut out);
    (fixed.texels, fixed.out_layers(), out)
}

/// An injected map's fixed codes, kept so that a gaze moves its views' foveas by shifting them
/// (docs/eye-tracking.md#moving-the-fovea-one-shift-for-every-path): one layer of codes per view
/// layer of [`map_layers`], not merged yet, and where each view lies.
#[derive(Clone, Debug, PartialEq)]
pub struct FixedCodes {
    pub grid: Grid,
    /// The map's extent in texels.
    pub texels: [u32; 2],
    /// One layer per layer of [`map_layers`], each `texels` codes.
    pub codes: Vec<u8>,
    /// Whether the output is those layers merged into one (finer rate per texel).
    pub merge: bool,
    /// Per view (by index), its layer and place.
    pub placed: [Option<Placed>; MAX_VIEWS],
    supported: Vec<[u32; 2]>,
}

impl FixedCodes {
    /// The fixed map's codes, as [`codes`] describes.
    pub fn new(
        device: &Device,
        views: Views,
        extent: [u32; 2],
        fovs: &[Option<Fov>; MAX_VIEWS],
        pattern: Pattern,
        max_fragment: u32,
    ) -> FixedCodes {
        let grid = Grid::new(extent, device.texel).capped(max_fragment);
        let [mw, mh] = grid.map_extent();
        let texels = (mw * mh) as usize;
        let (layers, merged) = map_layers(views, extent, fovs);
        let merge = merged || (!device.layered && layers.len() > 1);
        let mut density_bytes = vec![0u8; texels * 2 * layers.len()];
        for (views, out) in layers
            .iter()
            .zip(density_bytes.chunks_exact_mut(texels * 2))
        {
            density::fill(&grid, views, pattern, out);
        }
        let mut codes = vec![0u8; texels * layers.len()];
        shading_rate::fill_codes(
            &density_bytes,
            texels,
            false,
            device.max_fragment,
            &device.rates,
            &mut codes,
        );
        FixedCodes {
            grid,
            texels: [mw, mh],
            codes,
            merge,
            placed: placed(views, extent, fovs),
            supported: device.rates.clone(),
        }
    }

    /// The output's layers: 1 where merged.
    pub fn out_layers(&self) -> u32 {
        let n = self.codes.len() / self.texel_count().max(1);
        if self.merge {
            1
        } else {
            n.max(1) as u32
        }
    }

    fn texel_count(&self) -> usize {
        (self.texels[0] * self.texels[1]) as usize
    }

    /// The codes with each view's fovea at `centres` (NDC of its own FOV, y up; `None`: the fixed
    /// map's) in `out`, as many layers as [`FixedCodes::out_layers`]: each view's codes shifted
    /// ([`crate::shift::shift_layers`], no map evaluation), then merged where the output is one
    /// layer. `scratch` and `out` are resized, and keep their allocation from one call to the next.
    pub fn codes_into(
        &self,
        centres: &[Option<[f32; 2]>; MAX_VIEWS],
        scratch: &mut Vec<u8>,
        out: &mut Vec<u8>,
    ) {
        let mut shifts = [None; MAX_VIEWS];
        for ((s, c), p) in shifts.iter_mut().zip(centres).zip(&self.placed) {
            if let (Some(c), Some(p)) = (c, p) {
                *s = Some(shift::texel_shift(&self.grid, &p.view, *c));
            }
        }
        let texels = self.texel_count();
        let moved: &[u8] = if shifts.iter().any(|s| s.is_some_and(|s| s != [0, 0])) {
            scratch.resize(self.codes.len(), 0);
            shift::shift_layers::<1>(&self.grid, &self.placed, &shifts, &self.codes, scratch);
            scratch
        } else {
            &self.codes
        };
        if self.merge {
            out.resize(texels, 0);
            shading_rate::merge_codes(moved, texels, &self.supported, out);
        } else {
            out.resize(moved.len().max(texels), 0);
            out[..moved.len()].copy_from_slice(moved);
        }
    }
}

/// Where each view of [`map_layers`]'s layers lies: the layer (of the unmerged layers) and its
/// place there, by view index.
pub fn placed(
    views: Views,
    extent: [u32; 2],
    fovs: &[Option<Fov>; MAX_VIEWS],
) -> [Option<Placed>; MAX_VIEWS] {
    let (layers, _) = map_layers(views, extent, fovs);
    let mut out = [None; MAX_VIEWS];
    let mut put = |v: usize, layer: usize, view: View| {
        if let Some(slot) = out.get_mut(v) {
            *slot = Some(Placed { layer, view });
        }
    };
    match views {
        Views::Layers { first, .. } => {
            for (i, l) in layers.iter().enumerate() {
                put(usize::from(first) + i, i, l[0]);
            }
        }
        Views::Halves => {
            for (v, view) in layers[0].iter().enumerate() {
                put(v, 0, *view);
            }
        }
        Views::Merged => {
            let known: Vec<usize> = (0..MAX_VIEWS).filter(|&v| fovs[v].is_some()).collect();
            if known.is_empty() {
                put(0, 0, layers[0][0]);
            }
            for (i, v) in known.into_iter().enumerate() {
                put(v, i, layers[i][0]);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::density::Level;

    /// Index-like eyes: 1440×1600 (not square), two per-eye swapchains.
    fn per_eye() -> Vec<Swapchain> {
        (0..2)
            .map(|v| Swapchain {
                extent: [1440, 1600],
                layers: 1,
                holds: Holds::View(v),
            })
            .collect()
    }

    fn target(extent: [u32; 2]) -> Target {
        Target {
            extent,
            base_layer: 0,
            layers: 1,
            image_layers: 1,
            swapchain: None,
        }
    }

    #[test]
    fn swapchain_images_name_their_view() {
        let sc = per_eye();
        for v in 0..2u8 {
            let t = Target {
                swapchain: Some(usize::from(v)),
                ..target([1440, 1600])
            };
            assert_eq!(
                classify(&sc, 2, &t),
                Pass::Eye(Views::Layers { first: v, count: 1 })
            );
        }
        let array = [Swapchain {
            extent: [1440, 1600],
            layers: 2,
            holds: Holds::Layers,
        }];
        let multiview = Target {
            layers: 2,
            image_layers: 2,
            swapchain: Some(0),
            ..target([1440, 1600])
        };
        assert_eq!(
            classify(&array, 2, &multiview),
            Pass::Eye(Views::Layers { first: 0, count: 2 })
        );
        let second = Target {
            base_layer: 1,
            layers: 1,
            ..multiview
        };
        assert_eq!(
            classify(&array, 2, &second),
            Pass::Eye(Views::Layers { first: 1, count: 1 }),
            "one layer at a time: the layer is the view"
        );
        let beyond = Target {
            base_layer: 2,
            ..second
        };
        assert_eq!(classify(&array, 2, &beyond), Pass::Other);
        let wide = [Swapchain {
            extent: [2880, 1600],
            layers: 1,
            holds: Holds::Halves,
        }];
        let t = Target {
            swapchain: Some(0),
            ..target([2880, 1600])
        };
        assert_eq!(classify(&wide, 2, &t), Pass::Eye(Views::Halves));
        assert_eq!(
            classify(
                &wide,
                2,
                &Target {
                    swapchain: Some(5),
                    ..t
                }
            ),
            Pass::Other,
            "an unknown swapchain index is no eye"
        );
    }

    #[test]
    fn eye_shaped_targets_are_eye_passes() {
        let sc = per_eye();
        assert_eq!(
            classify(&sc, 2, &target([1440, 1600])),
            Pass::Eye(Views::Merged),
            "a one-layer target of its own: the side is unknown"
        );
        // Supersampled at 1.4, a little off by rounding.
        assert_eq!(
            classify(&sc, 2, &target([2016, 2241])),
            Pass::Eye(Views::Merged)
        );
        let array = Target {
            layers: 2,
            image_layers: 2,
            ..target([1440, 1600])
        };
        assert_eq!(
            classify(&sc, 2, &array),
            Pass::Eye(Views::Layers { first: 0, count: 2 }),
            "an array of two"
        );
        let slice = Target {
            base_layer: 1,
            layers: 1,
            ..array
        };
        assert_eq!(
            classify(&sc, 2, &slice),
            Pass::Eye(Views::Layers { first: 1, count: 1 })
        );
        assert_eq!(
            classify(&sc, 2, &target([2880, 1600])),
            Pass::Eye(Views::Halves),
            "double-wide"
        );
        let wide = [Swapchain {
            extent: [2880, 1600],
            layers: 1,
            holds: Holds::Halves,
        }];
        assert_eq!(
            classify(&wide, 2, &target([1440, 1600])),
            Pass::Eye(Views::Merged),
            "one eye's half of a double-wide swapchain, rendered on its own"
        );
        assert_eq!(
            classify(&wide, 2, &target([2880, 1600])),
            Pass::Eye(Views::Halves)
        );
    }

    #[test]
    fn other_targets_render_at_full_rate() {
        let sc = per_eye();
        for (extent, what) in [
            ([2048, 2048], "a square shadow map"),
            ([4096, 4096], "a large square shadow map"),
            ([256, 256], "a small offscreen target"),
            ([720, 800], "an upscaler's half-size input"),
            ([1000, 1111], "a mirror at the eye's aspect, too small"),
            ([1920, 1080], "a 16:9 mirror window"),
            ([3000, 3333], "more than 1.5 times the eye"),
            ([1440, 1500], "the eye's width, another aspect"),
        ] {
            assert_eq!(classify(&sc, 2, &target(extent)), Pass::Other, "{what}");
        }
        // Square eyes: a square target twice their size is not one.
        let square = [Swapchain {
            extent: [1024, 1024],
            layers: 1,
            holds: Holds::View(0),
        }];
        assert_eq!(classify(&square, 2, &target([2048, 2048])), Pass::Other);
        assert_eq!(
            classify(&square, 2, &target([1024, 1024])),
            Pass::Eye(Views::Merged)
        );
        assert_eq!(classify(&[], 2, &target([1440, 1600])), Pass::Other);
        assert_eq!(classify(&sc, 0, &target([1440, 1600])), Pass::Other);
        assert_eq!(classify(&sc, 2, &target([0, 0])), Pass::Other);
        let six = Target {
            layers: 6,
            image_layers: 6,
            ..target([1440, 1600])
        };
        assert_eq!(classify(&sc, 2, &six), Pass::Other, "a cube map");
        let face = Target {
            base_layer: 4,
            layers: 1,
            ..six
        };
        assert_eq!(classify(&sc, 2, &face), Pass::Other, "a cube map's face");
    }

    fn fovs() -> [Option<Fov>; MAX_VIEWS] {
        let left = Fov {
            left: -0.94,
            right: 0.70,
            up: 0.77,
            down: -0.96,
        };
        [Some(left), Some(left.mirrored()), None, None]
    }

    fn nvidia() -> Device {
        let mut rates = Vec::new();
        for w in [1u32, 2, 4] {
            for h in [1u32, 2, 4] {
                if w <= 2 * h && h <= 2 * w {
                    rates.push([w, h]);
                }
            }
        }
        Device {
            texel: [16, 16],
            layered: true,
            max_fragment: [4, 4],
            rates,
        }
    }

    /// The codes are the density model's map for each view's FOV, converted per texel: for one
    /// view, exactly what `density::fill` and `shading_rate::fsr_code` give.
    #[test]
    fn codes_follow_the_model_per_view() {
        let dev = nvidia();
        let extent = [1440, 1600];
        let pattern = Pattern {
            level: Level::High,
            vertical_offset_deg: 0.0,
        };
        let (map, layers, got) = codes(
            &dev,
            Views::Layers { first: 0, count: 2 },
            extent,
            &fovs(),
            pattern,
            4,
        );
        assert_eq!(map, [90, 100]);
        assert_eq!(layers, 2);
        let texels = 90 * 100;
        let grid = Grid::new(extent, dev.texel);
        for v in 0..2 {
            let mut d = vec![0u8; texels * 2];
            let view = View {
                fov: fovs()[v].unwrap(),
                rect: Rect {
                    x: 0,
                    y: 0,
                    width: extent[0],
                    height: extent[1],
                },
                visible: None,
            };
            density::fill(&grid, &[view], pattern, &mut d);
            let want: Vec<u8> = d
                .chunks_exact(2)
                .map(|t| shading_rate::fsr_code([t[0], t[1]], [4, 4], &dev.rates))
                .collect();
            assert_eq!(got[v * texels..(v + 1) * texels], want[..], "view {v}");
        }
        assert!(got.iter().any(|&c| c != 0), "high foveates somewhere");
        assert_ne!(
            got[..texels],
            got[texels..],
            "the eyes' maps are mirror images, not equal"
        );
        // Level none: full rate everywhere.
        let (_, _, none) = codes(
            &dev,
            Views::Layers { first: 1, count: 1 },
            extent,
            &fovs(),
            Pattern {
                level: Level::None,
                ..pattern
            },
            4,
        );
        assert!(none.iter().all(|&c| c == 0));
    }

    #[test]
    fn merged_and_halves() {
        let mut dev = nvidia();
        let extent = [1440, 1600];
        let pattern = Pattern {
            level: Level::Medium,
            vertical_offset_deg: 0.0,
        };
        let (_, _, both) = codes(
            &dev,
            Views::Layers { first: 0, count: 2 },
            extent,
            &fovs(),
            pattern,
            4,
        );
        let (_, layers, merged) = codes(&dev, Views::Merged, extent, &fovs(), pattern, 4);
        assert_eq!(layers, 1);
        let texels = merged.len();
        for (i, &m) in merged.iter().enumerate() {
            assert_eq!(
                m,
                shading_rate::finer(both[i], both[texels + i], &dev.rates),
                "texel {i}"
            );
        }
        dev.layered = false;
        let (_, layers, unlayered) = codes(
            &dev,
            Views::Layers { first: 0, count: 2 },
            extent,
            &fovs(),
            pattern,
            4,
        );
        assert_eq!(layers, 1, "one merged layer without layered attachments");
        assert_eq!(unlayered, merged);

        // Double-wide: each half is that eye's map.
        let (map, layers, wide) =
            codes(&nvidia(), Views::Halves, [2880, 1600], &fovs(), pattern, 4);
        assert_eq!((map, layers), ([180, 100], 1));
        for row in 0..100usize {
            assert_eq!(
                wide[row * 180..row * 180 + 90],
                both[row * 90..row * 90 + 90],
                "left half, row {row}"
            );
            assert_eq!(
                wide[row * 180 + 90..row * 180 + 180],
                both[texels + row * 90..texels + row * 90 + 90],
                "right half, row {row}"
            );
        }
    }

    /// The centre, in texels, of the full-rate codes of `layer` in `map` (`mw` texels wide), over
    /// columns `cols`.
    fn full_rate_centre(map: &[u8], mw: usize, cols: std::ops::Range<usize>) -> [f32; 2] {
        let (mut sum, mut n) = ([0.0f32; 2], 0.0f32);
        for (i, &c) in map.iter().enumerate() {
            if c == 0 && cols.contains(&(i % mw)) {
                sum[0] += (i % mw) as f32 + 0.5;
                sum[1] += (i / mw) as f32 + 0.5;
                n += 1.0;
            }
        }
        assert!(n > 0.0, "no full-rate texel");
        sum.map(|s| s / n)
    }

    /// A gaze moves each view's codes by that view's whole-texel shift, as the FB path moves its
    /// density: per eye layer, each half of a double-wide map, and both eyes before they merge.
    #[test]
    fn a_gaze_shifts_each_views_codes() {
        let dev = nvidia();
        let pattern = Pattern {
            level: Level::High,
            vertical_offset_deg: 0.0,
        };
        let extent = [1440, 1600];
        let mut scratch = Vec::new();
        let mut out = Vec::new();
        // The right eye's swapchain: view 1 moves, view 0's centre means nothing here.
        let right = FixedCodes::new(
            &dev,
            Views::Layers { first: 1, count: 1 },
            extent,
            &fovs(),
            pattern,
            4,
        );
        let fixed = codes(
            &dev,
            Views::Layers { first: 1, count: 1 },
            extent,
            &fovs(),
            pattern,
            4,
        )
        .2;
        right.codes_into(&[None; MAX_VIEWS], &mut scratch, &mut out);
        assert_eq!(out, fixed, "no gaze: the fixed codes");
        right.codes_into(
            &[Some([0.9, 0.9]), None, None, None],
            &mut scratch,
            &mut out,
        );
        assert_eq!(out, fixed, "another view's gaze moves nothing");
        let centre = [-0.3, 0.25];
        right.codes_into(&[None, Some(centre), None, None], &mut scratch, &mut out);
        let p = right.placed[1].expect("view 1 placed");
        assert_eq!(p.layer, 0);
        let s = shift::texel_shift(&right.grid, &p.view, centre);
        assert!(s[0] < 0 && s[1] < 0, "left and up: {s:?}");
        let (a, b) = (
            full_rate_centre(&fixed, 90, 0..90),
            full_rate_centre(&out, 90, 0..90),
        );
        for i in 0..2 {
            assert!(
                (b[i] - a[i] - s[i] as f32).abs() < 1e-3,
                "{a:?} → {b:?} by {s:?}"
            );
        }
        // Double-wide: only the left half moves for view 0.
        let wide = FixedCodes::new(&dev, Views::Halves, [2880, 1600], &fovs(), pattern, 4);
        let before = codes(&dev, Views::Halves, [2880, 1600], &fovs(), pattern, 4).2;
        wide.codes_into(&[Some(centre), None, None, None], &mut scratch, &mut out);
        for row in 0..100usize {
            assert_eq!(
                out[row * 180 + 90..(row + 1) * 180],
                before[row * 180 + 90..(row + 1) * 180]
            );
        }
        assert_ne!(out, before);
        // Merged: each eye's layer moves, then the finer rate of both.
        let merged = FixedCodes::new(&dev, Views::Merged, extent, &fovs(), pattern, 4);
        merged.codes_into(
            &[Some(centre), Some(centre), None, None],
            &mut scratch,
            &mut out,
        );
        assert_eq!(out.len(), 90 * 100);
        let layer = |v: usize| {
            let f = FixedCodes::new(
                &dev,
                Views::Layers {
                    first: v as u8,
                    count: 1,
                },
                extent,
                &fovs(),
                pattern,
                4,
            );
            let mut o = Vec::new();
            let mut c = [None; MAX_VIEWS];
            c[v] = Some(centre);
            f.codes_into(&c, &mut Vec::new(), &mut o);
            o
        };
        let (l, r) = (layer(0), layer(1));
        for i in 0..out.len() {
            assert_eq!(
                out[i],
                shading_rate::finer(l[i], r[i], &dev.rates),
                "texel {i}"
            );
        }
    }

    #[test]
    fn capped_fragments() {
        let dev = nvidia();
        let pattern = Pattern {
            level: Level::High,
            vertical_offset_deg: 0.0,
        };
        let (_, _, c) = codes(&dev, Views::Merged, [1440, 1600], &fovs(), pattern, 2);
        assert!(c.iter().all(|&c| {
            let [w, h] = shading_rate::decode(c);
            w <= 2 && h <= 2
        }));
        assert!(c.iter().any(|&c| c != 0));
    }
}
