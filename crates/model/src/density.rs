//! The density model: what fragment size each texel of a fragment density map (FDM) gets.
//!
//! Pure arithmetic on FOV tangents, no Vulkan and no OpenXR types, so that the layer, the CLI and
//! the tests share one model.
//!
//! # The model
//!
//! * **Angles, not pixels.** A planar (pinhole) projection puts a ray at tangent `(x, y)` from the
//!   optical axis, so relative to the view centre its pixels per radian are, per axis,
//!   `Dx = (1+x²+y²)/sqrt(1+y²)` horizontally and `Dy = (1+x²+y²)/sqrt(1+x²)` vertically
//!   (docs/density-model.md#planar-projection: a degree at the edge of a wide view covers far more
//!   of the screen than one at the centre). A level is a *floor* `F(θ)` on that relative angular
//!   resolution as a function of the angle `θ` from the fovea, so a level means the same foveal size
//!   in degrees on every headset and at every resolution. A fragment of `s` pixels along an axis divides the
//!   resolution by `s`, so the map spends the projection's peripheral surplus first: LOW (floor 1)
//!   only takes back that surplus.
//! * **The fovea** is the straight-ahead direction, i.e. the projection centre, which an off-centre
//!   (asymmetric) projection does not put at the image centre
//!   (docs/density-model.md#fovea-placement). `verticalOffset` turns it up (positive) or down by
//!   that many degrees (XrFoveationLevelProfileCreateInfoFB). Both are defined per view by its FOV,
//!   so a mirrored FOV gets the mirrored map.
//! * **Cheapest map meeting the floor.** Per texel and axis the fragment size is the largest power of
//!   two (up to `Grid::max_fragment`) for which the floor holds at *every* point of the texel, not
//!   just its centre. Per-axis densities are independent, so this also minimises the shaded area.
//! * **Encoding** follows the Vulkan rule (docs/openxr-layer.md#fdm-encoding): fragment area =
//!   1/density per axis, rounded down to a supported size; 128/255 would give 1.99, so 2× needs
//!   ≤127, 4× ≤63. Density 0 is undefined, so regions nobody sees get the *lowest* density, never 0.
//!
//! # Evaluating a texel
//!
//! A texel is a rectangle of tangents (clipped to its view and to the visible FOV). Per texel row,
//! everything is a step function of the texel's smallest `x²`: which ring of the floor it touches
//! (a ring `θ ≤ R` is an ellipse in the tangent plane whose widest point over the row is
//! closed-form) and, per ring zone, from which `x²` the lowest resolution over the texel reaches
//! twice, four times… the floor (closed-form inverses of `Dx` and `Dy`). [`RowFloors`] computes
//! those thresholds once per row; fragments never shrink away from the optical axis, so [`fill`]
//! writes runs, finding where each ends by searching from where it ended in the row above.
//! [`fill_reference`] evaluates every texel instead; the tests check the floors independently, by
//! sampling ray directions inside every texel.

use std::cell::Cell;
use std::str::FromStr;

use crate::fov::Fov;

/// A FOV as signed tangents (left and down negative), in f64 for the geometry.
#[derive(Clone, Copy, Debug)]
struct TanBox {
    left: f64,
    right: f64,
    up: f64,
    down: f64,
}

impl TanBox {
    fn of(f: Fov) -> TanBox {
        TanBox {
            left: f64::from(f.left).tan(),
            right: f64::from(f.right).tan(),
            up: f64::from(f.up).tan(),
            down: f64::from(f.down).tan(),
        }
    }
}

/// Foveation levels, numbered as `XrFoveationLevelFB` and Quest's `debug.oculus.foveation.level`
/// (docs/density-model.md#floors, docs/users.md#quest-debug-properties).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Level {
    None = 0,
    Low = 1,
    Medium = 2,
    High = 3,
    /// Quest's debug-only "High Top": HIGH with the fovea [`HIGH_TOP_OFFSET_DEG`] lower.
    HighTop = 4,
}

impl Level {
    /// Every level, in index order.
    pub const ALL: [Level; 5] = [
        Level::None,
        Level::Low,
        Level::Medium,
        Level::High,
        Level::HighTop,
    ];

    /// The level with that index (`XrFoveationLevelFB`, plus 4 for High Top as in the debug property).
    pub fn from_index(i: u32) -> Option<Level> {
        Level::ALL.get(i as usize).copied()
    }

    /// The name used on command lines and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Level::None => "none",
            Level::Low => "low",
            Level::Medium => "medium",
            Level::High => "high",
            Level::HighTop => "high-top",
        }
    }

    /// The quality floor: `(radius in degrees, floor)` rings from the inside out, and the floor
    /// beyond the last ring. `None` for NONE, which is full rate everywhere.
    fn floors(self) -> Option<(&'static [(f64, f64)], f64)> {
        match self {
            Level::None => None,
            Level::Low => Some((&[], 1.0)),
            Level::Medium => Some((&[(20.0, 1.0)], 0.5)),
            Level::High | Level::HighTop => Some((&[(15.0, 1.0), (30.0, 0.5)], 0.25)),
        }
    }
}

impl FromStr for Level {
    type Err = String;

    /// Accepts the names of [`Level::name`] (also `hightop`/`high_top`) and the indices 0–4.
    fn from_str(s: &str) -> Result<Level, String> {
        let l = s.trim().to_ascii_lowercase();
        if let Ok(i) = l.parse::<u32>() {
            return Level::from_index(i).ok_or_else(|| format!("no foveation level {i} (0-4)"));
        }
        match l.as_str() {
            "none" | "off" => Ok(Level::None),
            "low" => Ok(Level::Low),
            "medium" => Ok(Level::Medium),
            "high" => Ok(Level::High),
            "high-top" | "hightop" | "high_top" => Ok(Level::HighTop),
            _ => Err(format!(
                "unknown foveation level '{s}' (none, low, medium, high, high-top)"
            )),
        }
    }
}

/// How far High Top moves the fovea, as a `verticalOffset` in degrees (negative: down).
///
/// Meta describes High Top as "High foveation setting with more detail toward the bottom of the view
/// and more foveation near the top" and says OpenXR apps get it from `verticalOffset` on HIGH, but
/// publishes no number (docs/density-model.md#high-top). We use −10°: the eyes' resting line of
/// sight (the "normal line of sight" of display ergonomics) lies about 10–15° below the horizontal,
/// and on Quest 3 the image centre is already 5.5° below the projection centre (44° up, 55° down),
/// so 10° puts the fovea where content below eye level is looked at without leaving HIGH's 15°
/// full-rate disc far from straight ahead (the straight-ahead point stays inside it).
pub const HIGH_TOP_OFFSET_DEG: f32 = -10.0;

/// `verticalOffset` is clamped to ±this many degrees. The ring geometry needs `|offset| + 30° < 90°`,
/// and beyond 55° the fovea has left every preset's FOV anyway (the largest is Index's 54.7° up).
pub const MAX_VERTICAL_OFFSET_DEG: f32 = 55.0;

/// A foveation profile: an `XrFoveationLevelProfileCreateInfoFB` without the dynamic flag.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pattern {
    pub level: Level,
    /// Degrees, positive up.
    pub vertical_offset_deg: f32,
}

impl Pattern {
    /// The offset the model uses: the app's, plus High Top's, clamped (NaN counts as 0).
    pub fn effective_offset_deg(&self) -> f32 {
        let base = if self.vertical_offset_deg.is_nan() {
            0.0
        } else {
            self.vertical_offset_deg
        };
        let extra = if self.level == Level::HighTop {
            HIGH_TOP_OFFSET_DEG
        } else {
            0.0
        };
        (base + extra).clamp(-MAX_VERTICAL_OFFSET_DEG, MAX_VERTICAL_OFFSET_DEG)
    }
}

/// Pixels of the framebuffer (y down: row 0 is the top, i.e. `angle_up`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Rect {
    pub x: i32,
    pub y: i32,
    pub width: u32,
    pub height: u32,
}

/// One view drawn into the framebuffer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// The FOV the view was rendered with.
    pub fov: Fov,
    /// Where it was rendered.
    pub rect: Rect,
    /// The true FOV when narrower (Quest's symmetric-FOV mode, docs/headsets.md#symmetric-fov):
    /// pixels outside it are never shown and get the lowest density.
    pub visible: Option<Fov>,
}

/// The framebuffer and the density map's texel grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Grid {
    /// Framebuffer size in pixels.
    pub extent: [u32; 2],
    /// Framebuffer pixels per map texel (the device's fragment density texel size).
    pub texel: [u32; 2],
    /// Largest fragment size per axis the map asks for (rounded down to a power of two, ≤ 16: the
    /// levels' lowest floor, 1/4, never allows more than 8 even in the corners of the widest preset).
    pub max_fragment: [u32; 2],
}

impl Grid {
    /// A grid with Quest's default largest fragment, 4×4.
    pub fn new(extent: [u32; 2], texel: [u32; 2]) -> Grid {
        Grid {
            extent,
            texel,
            max_fragment: [4, 4],
        }
    }

    /// The same grid with its largest fragment capped at `max` per axis (the `max_fragment` setting:
    /// 1, 2 or 4). A cap never raises the grid's own largest fragment.
    pub fn capped(self, max: u32) -> Grid {
        Grid {
            max_fragment: self.max_fragment.map(|m| m.min(max.max(1))),
            ..self
        }
    }

    /// Map size in texels: `ceil(extent / texel)` (docs/openxr-layer.md#fdm-texel-size).
    pub fn map_extent(&self) -> [u32; 2] {
        [
            self.extent[0].div_ceil(self.texel[0].max(1)),
            self.extent[1].div_ceil(self.texel[1].max(1)),
        ]
    }

    fn max_fragment_pow2(&self) -> [u32; 2] {
        self.max_fragment.map(|m| {
            if m <= 1 {
                1
            } else {
                1 << (31 - m.min(16).leading_zeros())
            }
        })
    }
}

/// The R8G8_UNORM byte for a fragment size: `255 / fragment`, never 0. For powers of two this is the
/// largest byte whose Vulkan fragment size (see [`decode`]) is exactly `fragment`.
pub fn encode(fragment: u32) -> u8 {
    let f = fragment.max(1);
    let d = if f.is_power_of_two() {
        255 >> f.trailing_zeros()
    } else {
        255 / f
    };
    d.max(1) as u8
}

/// The fragment size the Vulkan rule gives for a byte: `1/density = 255/byte`, rounded down to a
/// power of two. 0 means undefined (density 0 is invalid, docs/openxr-layer.md#fdm-encoding).
pub fn decode(byte: u8) -> u32 {
    if byte == 0 {
        return 0;
    }
    let area = 255 / u32::from(byte);
    1 << (31 - area.leading_zeros())
}

// ---------------------------------------------------------------------------------------------
// Geometry. Tangents are in f64: the closed forms subtract nearly equal numbers near the rings.

/// `min over u in [lo, hi] of u + t²/u`: the smallest relative angular resolution along one axis
/// over a texel, where `t` is the texel's smallest `|tangent|` on that axis and `u = sqrt(1+s²)` runs
/// over the other axis (`u + t²/u` is `(1+t²+s²)/sqrt(1+s²)`, smallest at `u = t`).
fn min_resolution(t: f64, lo: f64, hi: f64) -> f64 {
    let u = t.max(lo).min(hi);
    u + t * t / u
}

fn sec(t: f64) -> f64 {
    (1.0 + t * t).sqrt()
}

/// Smallest and largest `|t|` over the tangent interval `[a, b]`.
fn abs_range(a: f64, b: f64) -> (f64, f64) {
    let near = if a <= 0.0 && b >= 0.0 {
        0.0
    } else {
        a.abs().min(b.abs())
    };
    (near, a.abs().max(b.abs()))
}

/// A ring of a level's floor around the fovea, in the tangent plane.
///
/// The cone `θ ≤ R` around the fovea direction `(0, t0, 1)` meets the plane `z = 1` in an ellipse:
/// `x² ≤ w(y) = (y·t0 + 1)²/k − 1 − y²` with `k = cos²R·(1+t0²)`. `w` is a concave parabola as long
/// as `R + |verticalOffset| < 90°` (guaranteed by [`MAX_VERTICAL_OFFSET_DEG`]), with its top at
/// `y = t0/(k − t0²)`, so the widest point of the ellipse over a row of texels is closed-form.
#[derive(Clone, Copy, Debug)]
struct Ring {
    inv_k: f64,
    apex: f64,
    floor: f64,
}

impl Ring {
    fn new(t0: f64, radius_deg: f64, floor: f64) -> Ring {
        let c = radius_deg.to_radians().cos();
        let k = c * c * (1.0 + t0 * t0);
        Ring {
            inv_k: 1.0 / k,
            apex: t0 / (k - t0 * t0),
            floor,
        }
    }

    /// The ellipse's largest `x²` over `y` in `[lo, hi]`; negative when the row misses the ring.
    fn half_width_sq(&self, t0: f64, lo: f64, hi: f64) -> f64 {
        let y = self.apex.max(lo).min(hi);
        let a = y * t0 + 1.0;
        a * a * self.inv_k - 1.0 - y * y
    }
}

/// What a level asks of one view: its rings (inside out) and the floor beyond them.
#[derive(Clone, Copy, Debug)]
struct Floors {
    t0: f64,
    rings: [Ring; 2],
    ring_count: usize,
    beyond: f64,
    max: [u32; 2],
    /// `log2(max)` per axis: how many doublings a fragment can take.
    steps: [usize; 2],
}

impl Floors {
    /// `None` for NONE: full rate everywhere, nothing to compute.
    fn new(pattern: Pattern, grid: &Grid) -> Option<Floors> {
        let (rings, beyond) = pattern.level.floors()?;
        let t0 = f64::from(pattern.effective_offset_deg()).to_radians().tan();
        let mut out = [Ring::new(t0, 90.0, 1.0); 2];
        for (slot, &(r, f)) in out.iter_mut().zip(rings) {
            *slot = Ring::new(t0, r, f);
        }
        Some(Floors {
            t0,
            rings: out,
            ring_count: rings.len(),
            beyond,
            max: grid.max_fragment_pow2(),
            steps: grid
                .max_fragment_pow2()
                .map(|m| (m.trailing_zeros() as usize).min(MAX_STEPS)),
        })
    }
}

/// A view's covered pixels (rect ∩ framebuffer ∩ visible FOV) and its pixel-to-tangent mapping.
#[derive(Clone, Copy, Debug)]
struct Placement {
    /// Covered pixel box, `[x0, x1) × [y0, y1)`, y down.
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
    /// `tan_x = ax + bx·px`, `tan_y = ay + by·py` (`by < 0`: row 0 is the top, `angle_up`).
    ax: f64,
    bx: f64,
    ay: f64,
    by: f64,
    /// Texel columns and rows touched.
    cols: (usize, usize),
    rows: (usize, usize),
    /// `1 + x²` at the covered box's farthest column from the optical axis.
    vfar2: f64,
}

impl Placement {
    fn new(grid: &Grid, view: &View) -> Option<Placement> {
        let t = TanBox::of(view.fov);
        let r = view.rect;
        if !(t.left < t.right && t.down < t.up) || r.width == 0 || r.height == 0 {
            return None;
        }
        let bx = (t.right - t.left) / f64::from(r.width);
        let ax = t.left - bx * f64::from(r.x);
        let by = -(t.up - t.down) / f64::from(r.height);
        let ay = t.up - by * f64::from(r.y);
        let v = TanBox::of(view.visible.unwrap_or(view.fov));
        let (mut x0, mut x1) = (f64::from(r.x), f64::from(r.x) + f64::from(r.width));
        let (mut y0, mut y1) = (f64::from(r.y), f64::from(r.y) + f64::from(r.height));
        x0 = x0.max(0.0).max((v.left - ax) / bx);
        x1 = x1.min(f64::from(grid.extent[0])).min((v.right - ax) / bx);
        y0 = y0.max(0.0).max((v.up - ay) / by);
        y1 = y1.min(f64::from(grid.extent[1])).min((v.down - ay) / by);
        // Also rejects NaN from a degenerate visible FOV.
        if !(x0 < x1 && y0 < y1) {
            return None;
        }
        let [tw, th] = grid.texel.map(|t| f64::from(t.max(1)));
        let span = |a: f64, b: f64, t: f64| ((a / t).floor() as usize, (b / t).ceil() as usize);
        let far = (ax + bx * x0).abs().max((ax + bx * x1).abs());
        Some(Placement {
            x0,
            x1,
            y0,
            y1,
            ax,
            bx,
            ay,
            by,
            cols: span(x0, x1, tw),
            rows: span(y0, y1, th),
            vfar2: 1.0 + far * far,
        })
    }

    /// Tangent interval of texel column `c` (clipped to the covered box).
    fn column(&self, c: usize, texel: f64) -> (f64, f64) {
        let a = (c as f64 * texel).max(self.x0);
        let b = ((c + 1) as f64 * texel).min(self.x1);
        (self.ax + self.bx * a, self.ax + self.bx * b)
    }

    /// Tangent interval of texel row `r`, lowest first.
    fn row(&self, r: usize, texel: f64) -> (f64, f64) {
        let a = (r as f64 * texel).max(self.y0);
        let b = ((r + 1) as f64 * texel).min(self.y1);
        (self.ay + self.by * b, self.ay + self.by * a)
    }

    /// The column holding the optical axis (`tan_x = 0`), clamped to the touched columns.
    fn axis_column(&self, texel: f64) -> usize {
        let p = -self.ax / self.bx;
        let c = (p / texel).floor().max(self.cols.0 as f64) as usize;
        c.min(self.cols.1 - 1)
    }
}

/// Most fragment doublings per axis (fragments up to 16, see [`Grid::max_fragment`]).
const MAX_STEPS: usize = 4;

/// One texel row's fragment sizes as step functions of a texel's smallest `x²` (`x = tan_x`).
///
/// Within a ring zone, the fragment along an axis is `2^k` for the largest `k` with
/// `D ≥ 2^k · floor`, where `D` is the axis's lowest relative resolution over the texel. Both `D`s
/// grow with `x²` (see below), so each `k` is reached at a threshold on `x²`, computed here once per
/// row in closed form; a texel then costs a few comparisons, and [`fill`] finds where runs end.
///
/// Conservative: a texel's floor is the highest of any ring it touches and its resolution the lowest
/// anywhere in it. Horizontally that lowest resolution, `Dx = min over the row of u + x²/u` with
/// `u = sqrt(1+y²)`, is exact. Vertically, `Dy = v + y²/v` with `v = sqrt(1+x²)` is taken over the
/// texel's row from the texel outward to the view's farthest column, which equals the texel's own
/// minimum except in rows more than 45° off-axis (where `Dy` dips slightly away from the axis, to
/// 2|y| from 1+y²); that makes `Dy` non-decreasing outward, so runs exist.
#[derive(Clone, Copy, Debug)]
struct RowFloors {
    /// Per ring, the largest `x²` of the ring inside the row (negative: not reached).
    reach: [f64; 2],
    /// Per zone (rings inside out, then beyond) and axis, the `x²` from which the fragment is at
    /// least `2^(k+1)`.
    steps: [[[f64; MAX_STEPS]; 2]; 3],
}

impl RowFloors {
    fn new(floors: &Floors, lo: f64, hi: f64, vfar2: f64) -> RowFloors {
        let (ym, yfar) = abs_range(lo, hi);
        let (ulo, uhi, ym2) = (sec(ym), sec(yfar), ym * ym);
        let mut row = RowFloors {
            reach: [-1.0; 2],
            steps: [[[f64::INFINITY; MAX_STEPS]; 2]; 3],
        };
        let rings = &floors.rings[..floors.ring_count];
        for (slot, ring) in row.reach.iter_mut().zip(rings) {
            *slot = ring.half_width_sq(floors.t0, lo, hi);
        }
        for zone in 0..=floors.ring_count {
            // A ring the row misses has no texels in its zone here.
            if row.reach.get(zone).is_some_and(|&r| r < 0.0) && zone < floors.ring_count {
                continue;
            }
            let floor = rings.get(zone).map_or(floors.beyond, |r| r.floor);
            let [x, y] = &mut row.steps[zone];
            let mut s = floor;
            for k in 0..floors.steps[0].max(floors.steps[1]) {
                s *= 2.0;
                x[k] = x_threshold(s, ulo, uhi);
                y[k] = y_threshold(s, ym2, vfar2);
            }
        }
        row
    }

    /// Fragment sizes of a texel whose smallest `|tan_x|` squared is `x2`.
    fn fragments(&self, floors: &Floors, x2: f64) -> [u32; 2] {
        let zone = self.reach[..floors.ring_count]
            .iter()
            .position(|&r| x2 <= r)
            .unwrap_or(floors.ring_count);
        let [x, y] = &self.steps[zone];
        let count = |t: &[f64]| t.iter().take_while(|&&t| x2 >= t).count() as u32;
        [
            1 << count(&x[..floors.steps[0]]),
            1 << count(&y[..floors.steps[1]]),
        ]
    }
}

/// Smallest `x²` where `Dx = min over u in [ulo, uhi] of u + x²/u` reaches `s`. `Dx` is
/// `ulo + x²/ulo` up to `x = ulo`, then `2x` up to `uhi`, then `uhi + x²/uhi`.
fn x_threshold(s: f64, ulo: f64, uhi: f64) -> f64 {
    if s <= 2.0 * ulo {
        ((s - ulo) * ulo).max(0.0)
    } else if s <= 2.0 * uhi {
        s * s / 4.0
    } else {
        (s - uhi) * uhi
    }
}

/// Smallest `x²` where `Dy = v + y²/v`, `v² = clamp(y², 1+x², vfar²)`, reaches `s` (∞: never in
/// the view). Where `y² ≥ vfar²` it is constant; otherwise it is `v + y²/v` at `v² = max(y², 1+x²)`,
/// increasing, and reaches `s` at `v = (s + sqrt(s² − 4y²))/2`.
fn y_threshold(s: f64, ym2: f64, vfar2: f64) -> f64 {
    let meets = |v2: f64| (v2 + ym2) * (v2 + ym2) >= s * s * v2;
    if ym2 >= vfar2 {
        return if meets(vfar2) { 0.0 } else { f64::INFINITY };
    }
    if meets(ym2.max(1.0)) {
        return 0.0;
    }
    let v = (s + (s * s - 4.0 * ym2).max(0.0).sqrt()) / 2.0;
    v * v - 1.0
}

/// First index in `[lo, hi)` where the monotone predicate `pred` holds (`hi` if none), searched
/// outward from `guess` (the previous row's answer, usually right or off by one).
fn first_true(lo: usize, hi: usize, guess: usize, pred: impl Fn(usize) -> bool) -> usize {
    if lo >= hi {
        return hi;
    }
    let g = guess.clamp(lo, hi - 1);
    let (mut a, mut b) = (lo, hi);
    if pred(g) {
        b = g;
        let mut step = 1;
        while a < b {
            let probe = b.saturating_sub(step).max(a);
            if pred(probe) {
                b = probe;
                step *= 2;
            } else {
                a = probe + 1;
                break;
            }
        }
    } else {
        a = g + 1;
        let mut step = 1;
        while a < b {
            let probe = (a + step - 1).min(b - 1);
            if pred(probe) {
                b = probe;
                break;
            }
            a = probe + 1;
            step *= 2;
        }
    }
    while a < b {
        let mid = a + (b - a) / 2;
        if pred(mid) {
            b = mid;
        } else {
            a = mid + 1;
        }
    }
    a
}

/// Raises `dst`'s densities to at least `[r, g]` (views sharing a texel get the finer of the two).
/// In 16-byte blocks so that it compiles to vector maxima: this is most of a map's cost.
fn raise(dst: &mut [u8], [r, g]: [u8; 2]) {
    let pattern: [u8; 16] = std::array::from_fn(|i| if i % 2 == 0 { r } else { g });
    let mut blocks = dst.chunks_exact_mut(16);
    for block in &mut blocks {
        for (b, p) in block.iter_mut().zip(pattern) {
            *b = (*b).max(p);
        }
    }
    for (b, p) in blocks.into_remainder().iter_mut().zip(pattern) {
        *b = (*b).max(p);
    }
}

/// Most runs one side of one row can have: every fragment size on each axis.
const MAX_RUNS: usize = 16;

/// Fills one layer of a density map: R8G8 texels, row-major, row 0 at the top, for the `views`
/// rendered into that layer (one per layer for a multiview array, two for a double-wide image).
///
/// Texels no view covers get the lowest density (never 0). Where views share a texel it gets the
/// finer density of the two. Cost: per texel row, a handful of texel evaluations found by searching
/// outward from the previous row's run boundaries, then plain stores; no allocation.
///
/// # Panics
/// If `out` is not `map_extent` texels of two bytes.
pub fn fill(grid: &Grid, views: &[View], pattern: Pattern, out: &mut [u8]) {
    fill_with(grid, views, pattern, out, true);
}

/// The same map evaluated texel by texel, without runs: the reference [`fill`] is tested against.
pub fn fill_reference(grid: &Grid, views: &[View], pattern: Pattern, out: &mut [u8]) {
    fill_with(grid, views, pattern, out, false);
}

fn fill_with(grid: &Grid, views: &[View], pattern: Pattern, out: &mut [u8], runs: bool) {
    let [mw, mh] = grid.map_extent().map(|v| v as usize);
    assert_eq!(
        out.len(),
        mw * mh * 2,
        "density map layer is {mw}x{mh} texels, 2 bytes each"
    );
    let Some(floors) = Floors::new(pattern, grid) else {
        out.fill(255);
        return;
    };
    out.fill(0);
    raise(out, floors.max.map(encode));
    let [tw, th] = grid.texel.map(|t| f64::from(t.max(1)));
    for view in views {
        let Some(p) = Placement::new(grid, view) else {
            continue;
        };
        let axis = p.axis_column(tw);
        // A texel's smallest |tan_x| is at its edge nearer the axis, affine in the outward index
        // (the right side's first column may start at the covered box's edge or straddle the axis).
        let first_right = (p.ax + p.bx * (axis as f64 * tw).max(p.x0)).max(0.0);
        let sides = [
            Side {
                first: axis,
                len: p.cols.1.min(mw) - axis,
                right: true,
                first_xm: first_right,
                base: p.ax + p.bx * tw * axis as f64,
                step: p.bx * tw,
            },
            Side {
                first: axis.wrapping_sub(1),
                len: axis - p.cols.0,
                right: false,
                first_xm: -(p.ax + p.bx * tw * axis as f64),
                base: -(p.ax + p.bx * tw * axis as f64),
                step: p.bx * tw,
            },
        ];
        let mut guesses = [[0usize; MAX_RUNS]; 2];
        for r in p.rows.0..p.rows.1.min(mh) {
            let (lo, hi) = p.row(r, th);
            let row = RowFloors::new(&floors, lo, hi, p.vfar2);
            let line = &mut out[r * mw * 2..(r + 1) * mw * 2];
            for (side, guesses) in sides.iter().zip(&mut guesses) {
                let value = |i: usize| {
                    let xm = side.nearest_tangent(i);
                    row.fragments(&floors, xm * xm)
                };
                if runs {
                    side.runs(line, value, guesses);
                } else {
                    for i in 0..side.len {
                        side.write(line, i, i + 1, value(i));
                    }
                }
            }
        }
    }
}

/// Whether the layer drawn with views `b` is the horizontal mirror of the one drawn with `a` on this
/// grid: each view's FOV and rect mirrored, and the texel grid symmetric (width a whole number of
/// texels). Headsets' eyes mirror each other, so the second eye's map can be [`mirror_into`]'s copy.
pub fn is_mirror(grid: &Grid, a: &[View], b: &[View]) -> bool {
    let w = grid.extent[0];
    let flip = |f: Fov| Fov {
        left: -f.right,
        right: -f.left,
        ..f
    };
    grid.extent[0] % grid.texel[0].max(1) == 0
        && a.len() == b.len()
        && a.iter().zip(b).all(|(a, b)| {
            b.fov == flip(a.fov)
                && b.visible == a.visible.map(flip)
                && b.rect.y == a.rect.y
                && (b.rect.width, b.rect.height) == (a.rect.width, a.rect.height)
                && i64::from(b.rect.x)
                    == i64::from(w) - i64::from(a.rect.x) - i64::from(a.rect.width)
        })
}

/// Writes `src`'s layer mirrored left to right into `dst` (see [`is_mirror`]).
pub fn mirror_into(grid: &Grid, src: &[u8], dst: &mut [u8]) {
    let row = grid.map_extent()[0] as usize * 2;
    for (s, d) in src.chunks_exact(row).zip(dst.chunks_exact_mut(row)) {
        for (s, d) in s.chunks_exact(2).zip(d.chunks_exact_mut(2).rev()) {
            d.copy_from_slice(s);
        }
    }
}

/// One side of a texel row, columns counted outward from the optical axis.
struct Side {
    first: usize,
    len: usize,
    right: bool,
    /// Smallest |tan_x| of the first texel, then `base + step·i` for the others.
    first_xm: f64,
    base: f64,
    step: f64,
}

impl Side {
    fn nearest_tangent(&self, i: usize) -> f64 {
        if i == 0 {
            self.first_xm
        } else {
            (self.base + self.step * f64::from(i as u32)).max(0.0)
        }
    }

    fn column(&self, i: usize) -> usize {
        if self.right {
            self.first + i
        } else {
            self.first - i
        }
    }

    /// Writes fragments `v` over outward indices `i..j` (a contiguous column range either way).
    fn write(&self, line: &mut [u8], i: usize, j: usize, v: [u32; 2]) {
        let (a, b) = (self.column(i), self.column(j - 1));
        let (a, b) = (a.min(b), a.max(b));
        raise(&mut line[a * 2..(b + 1) * 2], v.map(encode));
    }

    /// Runs of equal fragments: fragments never shrink outward ([`RowFloors`]), so each run
    /// ends where a monotone predicate turns true, found from the previous row's run ends.
    fn runs(
        &self,
        line: &mut [u8],
        value: impl Fn(usize) -> [u32; 2],
        guesses: &mut [usize; MAX_RUNS],
    ) {
        if self.len == 0 {
            return;
        }
        let mut i = 0;
        let mut v = value(0);
        let mut run = 0;
        while i < self.len {
            // The search's last `true` evaluation is at the index it returns: keep its value.
            let next = Cell::new(v);
            let j = first_true(i + 1, self.len, guesses[run.min(MAX_RUNS - 1)], |k| {
                let w = value(k);
                let differs = w != v;
                if differs {
                    next.set(w);
                }
                differs
            });
            if run < MAX_RUNS {
                guesses[run] = j;
            }
            self.write(line, i, j, v);
            run += 1;
            i = j;
            v = next.get();
        }
    }
}

/// What a map gives, measured over one layer's views.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Analysis {
    /// Fragments shaded relative to full rate, over every pixel of every view's rect.
    pub shaded_fraction: f64,
    /// Angular radius (degrees) of the largest disc around the fovea in which every shown pixel is
    /// shaded at full rate; `None` when the whole view is.
    pub full_rate_radius_deg: Option<f64>,
    /// Smallest per-axis angular resolution relative to the view centre's, over every shown point.
    pub min_relative_ppd: f64,
    /// The same over the shown texels within 15° of the fovea (HIGH's full-rate floor).
    pub min_relative_ppd_within_15deg: f64,
    /// The sums behind `shaded_fraction`, for combining layers: fragments shaded, pixels.
    pub shaded_pixels: f64,
    pub view_pixels: f64,
}

impl Analysis {
    /// Several layers (the two eyes) as one.
    pub fn combine(parts: &[Analysis]) -> Analysis {
        let shaded: f64 = parts.iter().map(|a| a.shaded_pixels).sum();
        let pixels: f64 = parts.iter().map(|a| a.view_pixels).sum();
        let min = |f: fn(&Analysis) -> f64| parts.iter().map(f).fold(f64::INFINITY, f64::min);
        Analysis {
            shaded_fraction: if pixels > 0.0 { shaded / pixels } else { 0.0 },
            full_rate_radius_deg: parts
                .iter()
                .filter_map(|a| a.full_rate_radius_deg)
                .reduce(f64::min),
            min_relative_ppd: min(|a| a.min_relative_ppd),
            min_relative_ppd_within_15deg: min(|a| a.min_relative_ppd_within_15deg),
            shaded_pixels: shaded,
            view_pixels: pixels,
        }
    }
}

/// Angle in degrees between the fovea `(0, t0, 1)` and the nearest point of a tangent rectangle:
/// `x` nearest the axis, `y` where `(y·t0 + 1)/sqrt(1+x²+y²)` peaks, `y = t0(1+x²)`.
fn nearest_angle_deg(t0: f64, (xm, _): (f64, f64), (lo, hi): (f64, f64)) -> f64 {
    let a = 1.0 + xm * xm;
    let y = (t0 * a).max(lo).min(hi);
    let cos = (y * t0 + 1.0) / ((1.0 + t0 * t0) * (a + y * y)).sqrt();
    cos.clamp(-1.0, 1.0).acos().to_degrees()
}

/// Measures a map layer filled for `views` (see [`Analysis`]), with the fragment sizes the Vulkan
/// rule gives for its bytes ([`decode`]) and each texel's exact worst point (not the fill's bound).
pub fn analyze(grid: &Grid, views: &[View], pattern: Pattern, map: &[u8]) -> Analysis {
    let [mw, mh] = grid.map_extent().map(|v| v as usize);
    let [tw, th] = grid.texel.map(|t| f64::from(t.max(1)));
    let t0 = f64::from(pattern.effective_offset_deg()).to_radians().tan();
    let mut a = Analysis {
        shaded_fraction: 0.0,
        full_rate_radius_deg: None,
        min_relative_ppd: f64::INFINITY,
        min_relative_ppd_within_15deg: f64::INFINITY,
        shaded_pixels: 0.0,
        view_pixels: 0.0,
    };
    let overlap = |a: f64, b: f64, lo: f64, hi: f64| (b.min(hi) - a.max(lo)).max(0.0);
    for view in views {
        // Shaded fraction over the whole rect inside the framebuffer, shown or not.
        let r = view.rect;
        let (rx0, ry0) = (f64::from(r.x).max(0.0), f64::from(r.y).max(0.0));
        let rx1 = (f64::from(r.x) + f64::from(r.width)).min(f64::from(grid.extent[0]));
        let ry1 = (f64::from(r.y) + f64::from(r.height)).min(f64::from(grid.extent[1]));
        for ty in 0..mh {
            let h = overlap(ty as f64 * th, (ty + 1) as f64 * th, ry0, ry1);
            for tx in 0..mw {
                let w = overlap(tx as f64 * tw, (tx + 1) as f64 * tw, rx0, rx1);
                let i = (ty * mw + tx) * 2;
                let area = f64::from(decode(map[i]).max(1) * decode(map[i + 1]).max(1));
                a.shaded_pixels += w * h / area;
                a.view_pixels += w * h;
            }
        }
        let Some(p) = Placement::new(grid, view) else {
            continue;
        };
        for ty in p.rows.0..p.rows.1.min(mh) {
            let ys = p.row(ty, th);
            let (ym, yfar) = abs_range(ys.0, ys.1);
            for tx in p.cols.0..p.cols.1.min(mw) {
                let xs = p.column(tx, tw);
                let (xm, xfar) = abs_range(xs.0, xs.1);
                let i = (ty * mw + tx) * 2;
                let f = [decode(map[i]).max(1), decode(map[i + 1]).max(1)].map(f64::from);
                let angle = nearest_angle_deg(t0, (xm, xfar), ys);
                if f != [1.0, 1.0] {
                    let radius = a.full_rate_radius_deg.get_or_insert(angle);
                    *radius = radius.min(angle);
                }
                let ppd = (min_resolution(xm, sec(ym), sec(yfar)) / f[0])
                    .min(min_resolution(ym, sec(xm), sec(xfar)) / f[1]);
                a.min_relative_ppd = a.min_relative_ppd.min(ppd);
                if angle <= 15.0 {
                    a.min_relative_ppd_within_15deg = a.min_relative_ppd_within_15deg.min(ppd);
                }
            }
        }
    }
    if a.view_pixels > 0.0 {
        a.shaded_fraction = a.shaded_pixels / a.view_pixels;
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::headsets::{by_id, HEADSETS};
    use proptest::prelude::*;

    fn layer(grid: &Grid) -> Vec<u8> {
        let [w, h] = grid.map_extent();
        vec![0; w as usize * h as usize * 2]
    }

    fn filled(grid: &Grid, views: &[View], pattern: Pattern) -> Vec<u8> {
        let mut out = layer(grid);
        fill(grid, views, pattern, &mut out);
        out
    }

    fn pattern(level: Level) -> Pattern {
        Pattern {
            level,
            vertical_offset_deg: 0.0,
        }
    }

    fn full_view(fov: Fov, size: [u32; 2]) -> View {
        View {
            fov,
            rect: Rect {
                x: 0,
                y: 0,
                width: size[0],
                height: size[1],
            },
            visible: None,
        }
    }

    /// One eye of a preset at its recommended size.
    fn eye(id: &str, eye: usize, texel: u32) -> (Grid, View) {
        let h = by_id(id).unwrap();
        let size = h.recommended_size();
        let view = full_view(h.fovs()[eye], size);
        (Grid::new(size, [texel, texel]), view)
    }

    /// The floor straight from the table, at `deg` from the fovea.
    fn floor_at(level: Level, deg: f64) -> f64 {
        match level {
            Level::None | Level::Low => 1.0,
            Level::Medium if deg <= 20.0 => 1.0,
            Level::Medium => 0.5,
            Level::High | Level::HighTop if deg <= 15.0 => 1.0,
            Level::High | Level::HighTop if deg <= 30.0 => 0.5,
            Level::High | Level::HighTop => 0.25,
        }
    }

    fn angle(a: [f64; 3], b: [f64; 3]) -> f64 {
        let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let c = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt().atan2(dot)
    }

    /// Relative angular resolution at tangent `(x, y)` per axis, from ray directions rather than
    /// the closed form the model uses: the angle a small tangent step subtends, against the centre.
    fn resolution(x: f64, y: f64) -> [f64; 2] {
        let h = 1e-5;
        let p = [x, y, 1.0];
        [h / angle(p, [x + h, y, 1.0]), h / angle(p, [x, y + h, 1.0])]
    }

    /// Samples a 5×5 lattice (corners and edges included) of the shown part of texel `(tx, ty)` and
    /// checks each point's resolution over fragment `f` against the floor at the point's angle.
    fn check_texel(
        grid: &Grid,
        p: &Placement,
        pat: Pattern,
        at: [usize; 2],
        f: [u32; 2],
    ) -> Result<(), String> {
        let t0 = f64::from(pat.effective_offset_deg()).to_radians().tan();
        let [tw, th] = grid.texel.map(f64::from);
        let (ya, yb) = p.row(at[1], th);
        let (xa, xb) = p.column(at[0], tw);
        for sy in 0..5 {
            for sx in 0..5 {
                let x = xa + (xb - xa) * f64::from(sx) / 4.0;
                let y = ya + (yb - ya) * f64::from(sy) / 4.0;
                let deg = angle([0.0, t0, 1.0], [x, y, 1.0]).to_degrees();
                let need = floor_at(pat.level, deg);
                let res = resolution(x, y);
                for axis in 0..2 {
                    let got = res[axis] / f64::from(f[axis]);
                    if got < need * (1.0 - 1e-6) {
                        return Err(format!(
                            "texel {at:?} axis {axis}: fragment {} gives {got:.4} at \
                             ({x:.4},{y:.4}), {deg:.2}° from the fovea, floor {need}",
                            f[axis]
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// [`check_texel`] over every texel each view covers, with the map's decoded fragments.
    fn check_floors(grid: &Grid, views: &[View], pat: Pattern, map: &[u8]) -> Result<(), String> {
        let [mw, mh] = grid.map_extent().map(|v| v as usize);
        for view in views {
            let Some(p) = Placement::new(grid, view) else {
                continue;
            };
            for ty in p.rows.0..p.rows.1.min(mh) {
                for tx in p.cols.0..p.cols.1.min(mw) {
                    let i = (ty * mw + tx) * 2;
                    let f = [decode(map[i]), decode(map[i + 1])];
                    if f.contains(&0) {
                        return Err(format!("zero density at texel {tx},{ty}"));
                    }
                    check_texel(grid, &p, pat, [tx, ty], f)?;
                }
            }
        }
        Ok(())
    }

    #[test]
    fn encoding_follows_the_vulkan_rule() {
        for f in [2, 4, 8, 16, 32, 64, 128] {
            assert_eq!(decode(encode(f)), f, "fragment {f}");
            assert_eq!(decode(encode(f) + 1), f / 2, "one above {f}'s byte");
        }
        assert_eq!(encode(1), 255);
        assert_eq!(encode(2), 127);
        assert_eq!(encode(4), 63);
        assert_eq!(decode(128), 1, "128/255 gives 1.99, so 1×1");
        assert_eq!(decode(0), 0);
        assert!((1..=4096).all(|f| encode(f) != 0));
    }

    #[test]
    fn first_true_finds_the_boundary_from_any_guess() {
        for len in 0..40usize {
            for edge in 0..=len {
                for guess in 0..=len + 2 {
                    assert_eq!(first_true(0, len, guess, |k| k >= edge), edge);
                }
            }
        }
    }

    /// The reference figures for Quest 3 at texel 32 with up to 4×4 fragments: about 0.83
    /// (LOW), 0.28 (MEDIUM), 0.14 (HIGH) of the full-rate fragments, both eyes.
    #[test]
    fn quest3_shades_the_published_fractions() {
        let expect = [
            (Level::None, 1.0),
            (Level::Low, 0.83),
            (Level::Medium, 0.28),
            (Level::High, 0.14),
        ];
        for (level, want) in expect {
            let parts: Vec<Analysis> = (0..2)
                .map(|e| {
                    let (grid, view) = eye("quest3", e, 32);
                    let map = filled(&grid, &[view], pattern(level));
                    analyze(&grid, &[view], pattern(level), &map)
                })
                .collect();
            let got = Analysis::combine(&parts).shaded_fraction;
            assert!(
                (got - want).abs() <= 0.03,
                "{level:?}: shaded {got:.3}, expected about {want}"
            );
        }
    }

    #[test]
    fn floors_hold_on_every_preset_and_level() {
        for h in HEADSETS {
            for e in 0..2 {
                let (grid, view) = eye(h.id, e, 32);
                for level in Level::ALL {
                    let map = filled(&grid, &[view], pattern(level));
                    check_floors(&grid, &[view], pattern(level), &map)
                        .unwrap_or_else(|m| panic!("{} eye {e} {level:?}: {m}", h.id));
                }
            }
        }
    }

    /// The fill is the cheapest map meeting the floor up to its conservative bound: against the
    /// largest fragments that pass a dense point sample of each texel, it shades at most 2% more.
    #[test]
    fn fill_is_close_to_the_sampled_optimum() {
        let (grid, view) = eye("quest3", 0, 32);
        let p = Placement::new(&grid, &view).unwrap();
        let [mw, mh] = grid.map_extent().map(|v| v as usize);
        for level in [Level::Low, Level::Medium, Level::High] {
            let pat = pattern(level);
            let map = filled(&grid, &[view], pat);
            let mut best = map.clone();
            for ty in 0..mh {
                for tx in 0..mw {
                    let i = (ty * mw + tx) * 2;
                    for axis in 0..2 {
                        let mut f = [decode(best[i]), decode(best[i + 1])];
                        while f[axis] < 4 {
                            f[axis] *= 2;
                            if check_texel(&grid, &p, pat, [tx, ty], f).is_err() {
                                f[axis] /= 2;
                                break;
                            }
                        }
                        best[i + axis] = encode(f[axis]);
                    }
                }
            }
            let ours = analyze(&grid, &[view], pat, &map).shaded_fraction;
            let opt = analyze(&grid, &[view], pat, &best).shaded_fraction;
            assert!(ours >= opt - 1e-12);
            assert!(
                ours <= opt * 1.02,
                "{level:?}: fill shades {ours:.4}, sampled optimum {opt:.4}"
            );
        }
    }

    fn arb_fov() -> impl Strategy<Value = Fov> {
        // Up to 60° each way, the projection centre anywhere inside the view.
        (0.1f32..1.05, 0.1f32..1.05, 0.1f32..1.05, 0.1f32..1.05).prop_map(|(l, r, u, d)| Fov {
            left: -l,
            right: r,
            up: u,
            down: -d,
        })
    }

    fn arb_level() -> impl Strategy<Value = Level> {
        (0u32..5).prop_map(|i| Level::from_index(i).unwrap())
    }

    prop_compose! {
        /// A grid with one or two views somewhere on it (double-wide, offset, overhanging).
        fn arb_case()(
            fovs in (arb_fov(), arb_fov()),
            size in (16u32..300, 16u32..300),
            texel in prop::sample::select(vec![8u32, 16, 32, 64]),
            max in prop::sample::select(vec![1u32, 2, 4, 8, 16]),
            origin in (-20i32..20, -20i32..20),
            two in any::<bool>(),
            level in arb_level(),
            offset in -30f32..30.0,
        ) -> (Grid, Vec<View>, Pattern) {
            let first = View {
                fov: fovs.0,
                rect: Rect { x: origin.0, y: origin.1, width: size.0, height: size.1 },
                visible: None,
            };
            let mut views = vec![first];
            let mut extent = [size.0, size.1];
            if two {
                let mut second = first;
                second.fov = fovs.1;
                second.rect.x = origin.0 + size.0 as i32;
                views.push(second);
                extent[0] += size.0;
            }
            let grid = Grid { extent, texel: [texel, texel], max_fragment: [max, max] };
            (grid, views, Pattern { level, vertical_offset_deg: offset })
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

        #[test]
        fn runs_equal_the_texel_by_texel_reference((grid, views, pat) in arb_case()) {
            let mut reference = layer(&grid);
            fill_reference(&grid, &views, pat, &mut reference);
            prop_assert_eq!(filled(&grid, &views, pat), reference);
        }

        #[test]
        fn floors_hold_and_no_density_is_zero((grid, views, pat) in arb_case()) {
            let map = filled(&grid, &views, pat);
            prop_assert!(map.iter().all(|&b| b != 0));
            let max = grid.max_fragment_pow2();
            prop_assert!(map.chunks_exact(2).all(|t| decode(t[0]) <= max[0] && decode(t[1]) <= max[1]));
            if let Err(m) = check_floors(&grid, &views, pat, &map) {
                return Err(TestCaseError::fail(m));
            }
        }

        #[test]
        fn levels_are_monotone((grid, views, pat) in arb_case()) {
            let maps: Vec<Vec<u8>> = [Level::None, Level::Low, Level::Medium, Level::High]
                .iter()
                .map(|&level| filled(&grid, &views, Pattern { level, ..pat }))
                .collect();
            for pair in maps.windows(2) {
                prop_assert!(pair[0].iter().zip(&pair[1]).all(|(a, b)| a >= b));
            }
        }

        /// A view whose FOV mirrors another's, on a texel-aligned rect, gets the mirrored map.
        #[test]
        fn mirrored_fov_gives_the_mirrored_map(
            fov in arb_fov(),
            cols in 1u32..12,
            rows in 1u32..12,
            texel in prop::sample::select(vec![8u32, 16, 32]),
            level in arb_level(),
            offset in -20f32..20.0,
        ) {
            let size = [cols * texel, rows * texel];
            let grid = Grid::new(size, [texel, texel]);
            let pat = Pattern { level, vertical_offset_deg: offset };
            let mirror = Fov { left: -fov.right, right: -fov.left, ..fov };
            let a = filled(&grid, &[full_view(fov, size)], pat);
            let b = filled(&grid, &[full_view(mirror, size)], pat);
            for (ra, rb) in a.chunks_exact(cols as usize * 2).zip(b.chunks_exact(cols as usize * 2)) {
                let flipped: Vec<u8> = rb.chunks_exact(2).rev().flatten().copied().collect();
                prop_assert_eq!(ra, &flipped[..]);
            }
        }

        /// The full-rate region of HIGH is the 15° disc around the fovea (beyond it the floor is
        /// 1/2, which every point of a planar projection meets at 2×), so its vertical middle on
        /// the axis column is the verticalOffset, to within a texel.
        #[test]
        fn vertical_offset_moves_the_fovea(offset in -25f32..25.0) {
            let fov = Fov { left: -0.9, right: 0.9, up: 0.9, down: -0.9 };
            let size = [256, 1024];
            let grid = Grid::new(size, [8, 8]);
            let pat = Pattern { level: Level::High, vertical_offset_deg: offset };
            let map = filled(&grid, &[full_view(fov, size)], pat);
            let [mw, mh] = grid.map_extent().map(|v| v as usize);
            let col = mw / 2;
            let full: Vec<usize> = (0..mh).filter(|&r| map[(r * mw + col) * 2..][..2] == [255, 255]).collect();
            let p = Placement::new(&grid, &full_view(fov, size)).unwrap();
            let top = p.row(full[0], 8.0).1.atan().to_degrees();
            let bottom = p.row(*full.last().unwrap(), 8.0).0.atan().to_degrees();
            let per_texel = (0.9f64.tan() * 2.0 / 128.0).atan().to_degrees();
            prop_assert!((top - f64::from(offset) - 15.0).abs() <= per_texel + 1e-6, "top {}", top);
            prop_assert!((f64::from(offset) - bottom - 15.0).abs() <= per_texel + 1e-6, "bottom {}", bottom);
        }
    }

    /// Symmetric-FOV mode: the eye renders with a wider shared FOV; pixels outside its true FOV get
    /// the lowest density and the rest the same map as far as the floors go.
    #[test]
    fn pixels_outside_the_visible_fov_get_the_lowest_density() {
        let h = by_id("quest3").unwrap();
        let shared = crate::projection::symmetric_fov(&h.fovs()).unwrap();
        let size = h.symmetric_size();
        let grid = Grid::new(size, [32, 32]);
        let view = View {
            visible: Some(h.fovs()[0]),
            ..full_view(shared, size)
        };
        for level in Level::ALL.into_iter().skip(1) {
            let map = filled(&grid, &[view], pattern(level));
            check_floors(&grid, &[view], pattern(level), &map).unwrap();
            let p = Placement::new(&grid, &view).unwrap();
            let [mw, mh] = grid.map_extent().map(|v| v as usize);
            let mut hidden = 0;
            for ty in 0..mh {
                for tx in 0..mw {
                    let inside =
                        (p.cols.0..p.cols.1).contains(&tx) && (p.rows.0..p.rows.1).contains(&ty);
                    let t = &map[(ty * mw + tx) * 2..][..2];
                    if !inside {
                        hidden += 1;
                        assert_eq!(t, [63, 63], "texel {tx},{ty}");
                    }
                }
            }
            // Quest 3's left eye is 54° left but 40° right, so the shared FOV hides columns on the right.
            assert!(hidden >= mh, "{hidden} hidden texels");
        }
    }

    #[test]
    fn mirrored_eyes_are_detected_and_copied() {
        for h in HEADSETS {
            for texel in [16, 32] {
                let (grid, left) = eye(h.id, 0, texel);
                let (_, right) = eye(h.id, 1, texel);
                let pat = pattern(Level::High);
                // Index's measured eyes are not exact mirrors of each other.
                let symmetric_grid =
                    grid.extent[0] % texel == 0 && h.fovs()[1] == h.fovs()[0].mirrored();
                assert_eq!(
                    is_mirror(&grid, &[left], &[right]),
                    symmetric_grid,
                    "{}",
                    h.id
                );
                assert!(!is_mirror(&grid, &[left], &[left]) || left.fov == right.fov);
                if symmetric_grid {
                    let mut copied = layer(&grid);
                    mirror_into(&grid, &filled(&grid, &[left], pat), &mut copied);
                    assert_eq!(
                        copied,
                        filled(&grid, &[right], pat),
                        "{} texel {texel}",
                        h.id
                    );
                }
            }
        }
    }

    /// Why fragments stop at 16: with room for 16×16, no level asks for more than 8 on any preset.
    #[test]
    fn no_level_asks_for_more_than_8() {
        for h in HEADSETS {
            for e in 0..2 {
                let (mut grid, view) = eye(h.id, e, 32);
                grid.max_fragment = [128, 128];
                for level in Level::ALL {
                    let map = filled(&grid, &[view], pattern(level));
                    let most = map.iter().map(|&b| decode(b)).max().unwrap();
                    assert!(most <= 8, "{} {level:?}: {most}", h.id);
                }
            }
        }
    }
}
