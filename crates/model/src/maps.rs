//! What each layer of a density map holds: the views rendered into it, and the map filled from them.
//!
//! A swapchain image's density map has one layer per array layer of the image. Which views a layer
//! holds comes from what the application submitted into the swapchain in `xrEndFrame`
//! (`XrCompositionLayerProjectionView`: array index, rectangle, FOV); before its first submission,
//! layer `i` holds view `i` over the whole image, as last located.

use crate::density::{self, Grid, Pattern, Rect, View};
use crate::fov::Fov;
use crate::shift::Placed;

/// Most views a session has (quad views is the largest view configuration there is).
pub const MAX_VIEWS: usize = 4;

/// Framebuffer pixels per density texel on a device without VK_EXT_fragment_density_map: 32×32,
/// the size Adreno drivers report as their minimum, so maps look alike with and without FDM and a
/// 2k×2k eye buffer needs a 64×64 map.
pub const DEFAULT_TEXEL: [u32; 2] = [32, 32];

/// The FOV assumed for a view before the application first called xrLocateViews: 45° each way.
pub const FALLBACK_FOV: Fov = Fov {
    left: -std::f32::consts::FRAC_PI_4,
    right: std::f32::consts::FRAC_PI_4,
    up: std::f32::consts::FRAC_PI_4,
    down: -std::f32::consts::FRAC_PI_4,
};

/// Everything a density map depends on. Two fills with equal inputs give the same bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct Inputs {
    pub pattern: Pattern,
    /// The largest fragment the map may ask for, per axis (`max_fragment`: 1, 2 or 4; the grid's
    /// own limit applies too).
    pub max_fragment: u32,
    /// Per array layer, the views rendered into it (none: the layer is not shown).
    pub layers: Vec<Vec<View>>,
}

/// A view the application submitted in `xrEndFrame` (XrCompositionLayerProjectionView).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SubmittedView {
    /// Its index in the projection layer: the eye, for symmetric-FOV mode's true FOVs.
    pub eye: usize,
    /// `subImage.imageArrayIndex`.
    pub layer: u32,
    /// `subImage.imageRect`.
    pub rect: Rect,
    pub fov: Fov,
}

impl Inputs {
    /// The inputs for a swapchain of `extent` and `layers` layers, from the views the application
    /// last submitted into it where there are any; before the first submission, layer `i` holds
    /// view `i` as the application last located it ([`FALLBACK_FOV`] before that) over the whole
    /// extent. `visible` gives the eyes' true FOVs in symmetric-FOV mode.
    pub fn new(
        pattern: Pattern,
        extent: [u32; 2],
        layers: u32,
        submitted: &[Option<SubmittedView>; MAX_VIEWS],
        located: &[Option<Fov>; MAX_VIEWS],
        visible: Option<[Fov; 2]>,
    ) -> Inputs {
        let visible_for = |eye: usize| visible.and_then(|v| v.get(eye).copied());
        let mut out: Vec<Vec<View>> = vec![Vec::new(); layers as usize];
        if submitted.iter().any(Option::is_some) {
            for v in submitted.iter().flatten() {
                if let Some(views) = out.get_mut(v.layer as usize) {
                    views.push(View {
                        fov: v.fov,
                        rect: v.rect,
                        visible: visible_for(v.eye),
                    });
                }
            }
        } else {
            let rect = Rect {
                x: 0,
                y: 0,
                width: extent[0],
                height: extent[1],
            };
            for (i, views) in out.iter_mut().enumerate() {
                views.push(View {
                    fov: located.get(i).copied().flatten().unwrap_or(FALLBACK_FOV),
                    rect,
                    visible: visible_for(i),
                });
            }
        }
        Inputs {
            pattern,
            max_fragment: DEFAULT_MAX_FRAGMENT,
            layers: out,
        }
    }

    /// The same inputs under a `max_fragment` cap.
    pub fn capped(self, max_fragment: u32) -> Inputs {
        Inputs {
            max_fragment,
            ..self
        }
    }
}

/// Where each view (by its index in the projection layer, the eye) lies in the map
/// [`Inputs::new`] builds from the same arguments: the layer and the view there. A gaze moves each
/// view's fovea by its own shift ([`crate::shift::shift_layers`]).
pub fn placed(
    extent: [u32; 2],
    layers: u32,
    submitted: &[Option<SubmittedView>; MAX_VIEWS],
    located: &[Option<Fov>; MAX_VIEWS],
    visible: Option<[Fov; 2]>,
) -> [Option<Placed>; MAX_VIEWS] {
    let visible_for = |eye: usize| visible.and_then(|v| v.get(eye).copied());
    let mut out = [None; MAX_VIEWS];
    if submitted.iter().any(Option::is_some) {
        for v in submitted.iter().flatten() {
            if v.layer < layers && v.eye < MAX_VIEWS {
                out[v.eye] = Some(Placed {
                    layer: v.layer as usize,
                    view: View {
                        fov: v.fov,
                        rect: v.rect,
                        visible: visible_for(v.eye),
                    },
                });
            }
        }
    } else {
        let rect = Rect {
            x: 0,
            y: 0,
            width: extent[0],
            height: extent[1],
        };
        for (i, slot) in out.iter_mut().enumerate().take(layers as usize) {
            *slot = Some(Placed {
                layer: i,
                view: View {
                    fov: located.get(i).copied().flatten().unwrap_or(FALLBACK_FOV),
                    rect,
                    visible: visible_for(i),
                },
            });
        }
    }
    out
}

/// The largest fragment a map asks for unless capped lower: 4×4, as on Quest.
pub const DEFAULT_MAX_FRAGMENT: u32 = 4;

/// Fills every layer of a density image with its views' maps. A layer whose views mirror layer
/// 0's (headsets' eyes do) is [`density::mirror_into`]'s copy.
///
/// # Panics
/// If `out` is not `layers × map_extent` texels of two bytes.
pub fn fill_layers(grid: &Grid, inputs: &Inputs, out: &mut [u8]) {
    let grid = &grid.capped(inputs.max_fragment);
    let layers = inputs.layers.len();
    if layers == 0 {
        return;
    }
    let layer_len = out.len() / layers;
    let (first, rest) = out.split_at_mut(layer_len);
    let v0 = &inputs.layers[0];
    density::fill(grid, v0, inputs.pattern, first);
    for (vi, dst) in inputs.layers[1..]
        .iter()
        .zip(rest.chunks_exact_mut(layer_len))
    {
        if !v0.is_empty() && density::is_mirror(grid, v0, vi) {
            density::mirror_into(grid, first, dst);
        } else {
            density::fill(grid, vi, inputs.pattern, dst);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::density::Level;

    fn quest_like_fovs() -> (Fov, Fov) {
        let left = Fov {
            left: -0.94,
            right: 0.70,
            up: 0.77,
            down: -0.96,
        };
        let right = Fov {
            left: -left.right,
            right: -left.left,
            ..left
        };
        (left, right)
    }

    #[test]
    fn layers_match_the_model_mirrored_or_not() {
        let (l, r) = quest_like_fovs();
        for extent in [[640, 500], [600, 500]] {
            let grid = Grid::new(extent, [32, 32]);
            let [mw, mh] = grid.map_extent();
            let layer = (mw * mh * 2) as usize;
            for level in 0..=3 {
                let inputs = Inputs::new(
                    Pattern {
                        level: Level::from_index(level).unwrap(),
                        vertical_offset_deg: 3.0,
                    },
                    extent,
                    2,
                    &[None; MAX_VIEWS],
                    &[Some(l), Some(r), None, None],
                    None,
                );
                let mut out = vec![0u8; layer * 2];
                fill_layers(&grid, &inputs, &mut out);
                for (i, fov) in [l, r].into_iter().enumerate() {
                    let mut want = vec![0u8; layer];
                    let view = View {
                        fov,
                        rect: Rect {
                            x: 0,
                            y: 0,
                            width: extent[0],
                            height: extent[1],
                        },
                        visible: None,
                    };
                    density::fill(&grid, &[view], inputs.pattern, &mut want);
                    assert!(
                        out[i * layer..(i + 1) * layer] == want[..],
                        "extent {extent:?} level {level} layer {i}"
                    );
                }
            }
        }
    }

    /// `max_fragment` caps every texel of every layer; under the default cap the map is the
    /// uncapped model's.
    #[test]
    fn max_fragment_caps_every_texel() {
        let (l, r) = quest_like_fovs();
        let grid = Grid::new([640, 500], [32, 32]);
        let [mw, mh] = grid.map_extent();
        let high = Pattern {
            level: Level::High,
            vertical_offset_deg: 0.0,
        };
        let inputs = Inputs::new(
            high,
            [640, 500],
            2,
            &[None; MAX_VIEWS],
            &[Some(l), Some(r), None, None],
            None,
        );
        let fill = |inputs: &Inputs| {
            let mut out = vec![0u8; (mw * mh * 4) as usize];
            fill_layers(&grid, inputs, &mut out);
            out
        };
        let largest = |map: &[u8]| map.iter().map(|&b| density::decode(b)).max().unwrap();
        let default = fill(&inputs);
        assert_eq!(inputs.max_fragment, DEFAULT_MAX_FRAGMENT);
        assert_eq!(largest(&default), 4, "HIGH reaches 4x4 uncapped");
        assert_eq!(default, fill(&inputs.clone().capped(4)));
        let two = fill(&inputs.clone().capped(2));
        assert_eq!(largest(&two), 2);
        for (a, b) in default.iter().zip(&two) {
            let want = density::decode(*a).min(2);
            assert_eq!(
                density::decode(*b),
                want,
                "a cap only lowers what is above it"
            );
        }
        let one = fill(&inputs.capped(1));
        assert!(one.iter().all(|&b| density::decode(b) == 1), "1: full rate");
    }

    #[test]
    fn inputs_fall_back_to_a_symmetric_fov() {
        let (l, _) = quest_like_fovs();
        let none = Pattern {
            level: Level::None,
            vertical_offset_deg: 0.0,
        };
        let i = Inputs::new(
            none,
            [64, 32],
            3,
            &[None; MAX_VIEWS],
            &[Some(l), None, None, None],
            None,
        );
        let fovs: Vec<Fov> = i.layers.iter().map(|v| v[0].fov).collect();
        assert_eq!(fovs, [l, FALLBACK_FOV, FALLBACK_FOV]);
        assert!(i
            .layers
            .iter()
            .all(|v| v.len() == 1 && v[0].rect.width == 64));
    }

    /// Submitted views win over located ones: a double-wide swapchain gets both eyes' views side by
    /// side in layer 0, each with its own rectangle and (symmetric mode) its own true FOV, and the
    /// map equals the model's for exactly those views.
    #[test]
    fn submitted_views_place_each_eye_in_its_rectangle() {
        let (l, r) = quest_like_fovs();
        let rect = |x| Rect {
            x,
            y: 0,
            width: 320,
            height: 500,
        };
        let submitted = [
            Some(SubmittedView {
                eye: 0,
                layer: 0,
                rect: rect(0),
                fov: l,
            }),
            Some(SubmittedView {
                eye: 1,
                layer: 0,
                rect: rect(320),
                fov: r,
            }),
            None,
            None,
        ];
        let high = Pattern {
            level: Level::High,
            vertical_offset_deg: 0.0,
        };
        let grid = Grid::new([640, 500], [32, 32]);
        let visible = Some([l, r]);
        let i = Inputs::new(
            high,
            [640, 500],
            1,
            &submitted,
            &[Some(r), Some(l), None, None],
            visible,
        );
        assert_eq!(i.layers.len(), 1);
        assert_eq!(i.layers[0].len(), 2);
        assert_eq!(i.layers[0][1].rect.x, 320);
        assert_eq!(i.layers[0][1].visible, Some(r));
        let [mw, mh] = grid.map_extent();
        let mut out = vec![0u8; (mw * mh * 2) as usize];
        fill_layers(&grid, &i, &mut out);
        let mut want = vec![0u8; out.len()];
        density::fill(&grid, &i.layers[0], high, &mut want);
        assert_eq!(out, want);
        // The left half's fovea is not the right half's: the two halves differ.
        let row = (mh / 2 * mw * 2) as usize;
        let half = (mw as usize / 2) * 2;
        assert_ne!(out[row..row + half], out[row + half..row + 2 * half]);
        // Each eye is placed where its inputs draw it: both in layer 0, each in its half.
        let p = placed(
            [640, 500],
            1,
            &submitted,
            &[Some(r), Some(l), None, None],
            visible,
        );
        for (eye, v) in i.layers[0].iter().enumerate() {
            assert_eq!(
                p[eye].map(|p| (p.layer, p.view)),
                Some((0, *v)),
                "eye {eye}"
            );
        }
        assert_eq!(p[2], None);
        // Before any submission, layer i holds view i over the whole image.
        let p = placed(
            [64, 32],
            2,
            &[None; MAX_VIEWS],
            &[Some(l), None, None, None],
            None,
        );
        assert_eq!(
            p[0].map(|p| (p.layer, p.view.fov, p.view.rect.width)),
            Some((0, l, 64))
        );
        assert_eq!(p[1].map(|p| (p.layer, p.view.fov)), Some((1, FALLBACK_FOV)));
        assert_eq!(p[2], None, "only as many views as layers");
    }
}
