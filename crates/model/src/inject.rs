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
    let out_layers = if merge { 1 } else { layers.len().max(1) };
    let mut out = vec![0u8; texels * out_layers];
    shading_rate::fill_codes(
        &density_bytes,
        texels,
        merge,
        device.max_fragment,
        &device.rates,
        &mut out,
    );
    ([mw, mh], out_layers as u32, out)
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
