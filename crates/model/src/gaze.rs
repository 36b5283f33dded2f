//! Gaze fit to render with: the eye tracker's samples filtered, held through blinks, eased back to
//! fixed foveation when lost, and projected into each eye's own asymmetric FOV.
//!
//! Runtimes report gaze as a pose in VIEW space (`XR_EXT_eye_gaze_interaction`: +Y up, −Z forward,
//! <https://registry.khronos.org/OpenXR/specs/1.1/html/xrspec.html#XR_EXT_eye_gaze_interaction>),
//! a sample at a time, noisy while the eye fixates and jumping during saccades. Rendering wants a
//! fovea that sits still while the eye does and arrives at once when it jumps, so
//! (docs/eye-tracking.md):
//! - a one-euro filter (Casiez et al., CHI 2012): a low-pass whose cutoff rises with the gaze's
//!   speed, smoothing fixation noise without lagging smooth pursuit much;
//! - a reset on saccades: a sample farther than [`GazeParams::saccade_deg`] from the filtered gaze
//!   is taken as it is (Visual Pinball resets at about 4.5°);
//! - a hold of the last good gaze while samples are invalid (blinks: tools hold 100 ms to 1 s),
//!   then an eased return to fixed foveation, so a lost tracker leaves the fovea where fixed
//!   foveation puts it, not wherever the eye last was;
//! - the gaze ray meets a fixation plane ([`GazeParams::fixation_m`] ahead, 1 m as WiVRn and Visual
//!   Pinball use) and that point is projected into each eye, whose views are offset from VIEW
//!   space and may be rotated (canted displays); the centre is kept inside the view.
//!
//! Everything is a function of the samples' times, so it is deterministic under the simulated
//! runtime's clock. Angles are in degrees: yaw positive to the right, pitch positive up.

use glam::{Quat, Vec3};

use crate::fov::Fov;

/// What the filter and the hold do; every field is a setting (`fovea.toml`, the environment).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GazeParams {
    /// The one-euro filter's cutoff at rest, in Hz: lower smooths fixation noise more.
    pub min_cutoff_hz: f32,
    /// How fast the cutoff rises with the gaze's speed, in Hz per degree per second: higher lags
    /// pursuit less.
    pub beta: f32,
    /// The cutoff of the speed estimate the filter steers by, in Hz.
    pub d_cutoff_hz: f32,
    /// A sample at least this far (degrees) from the filtered gaze is a saccade: taken as it is.
    pub saccade_deg: f32,
    /// How long the last good gaze is held while samples are invalid, in seconds.
    pub hold_s: f32,
    /// How long the fovea then takes to ease back to fixed foveation, in seconds.
    pub return_s: f32,
    /// Distance of the fixation plane the gaze ray meets, in metres.
    pub fixation_m: f32,
}

impl GazeParams {
    /// Defaults chosen by the figures in this module's tests (docs/eye-tracking.md#defaults):
    /// pursuit at 30°/s lags under 1.5°, fixation noise of 0.5° shrinks to under a third, a blink
    /// of 150 ms is held through, a lost tracker is back at fixed foveation within 0.6 s. A
    /// constant, so `fovea-config`'s table of keys can name each as its key's default.
    pub const DEFAULT: GazeParams = GazeParams {
        min_cutoff_hz: 1.0,
        beta: 0.1,
        d_cutoff_hz: 1.0,
        saccade_deg: 4.5,
        hold_s: 0.3,
        return_s: 0.3,
        fixation_m: 1.0,
    };
}

impl Default for GazeParams {
    fn default() -> GazeParams {
        GazeParams::DEFAULT
    }
}

/// One sample from the tracker: where the eye looks, in VIEW space, at `time_ns`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    pub time_ns: i64,
    /// A direction in VIEW space (need not be normalised; zero or non-finite is no sample).
    pub direction: Vec3,
}

/// How much the gaze can be trusted now.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tracking {
    /// Fresh samples: the fovea follows them.
    Tracked,
    /// Samples invalid for less than the hold: the last good gaze stands.
    Held,
    /// Held too long: the fovea eases back to fixed foveation.
    Returning,
    /// No gaze (never had one, or lost and back): fixed foveation.
    Fixed,
}

/// The filter's answer for one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gaze {
    /// Yaw and pitch in degrees (right and up positive) of the filtered gaze.
    pub angles: [f32; 2],
    /// How far the fovea follows the gaze: 1 follows it, 0 is fixed foveation.
    pub weight: f32,
    pub tracking: Tracking,
}

impl Gaze {
    /// Fixed foveation: no gaze.
    pub const FIXED: Gaze = Gaze {
        angles: [0.0, 0.0],
        weight: 0.0,
        tracking: Tracking::Fixed,
    };

    /// The gaze direction in VIEW space (unit length).
    pub fn direction(&self) -> Vec3 {
        let [yaw, pitch] = self.angles.map(f32::to_radians);
        Vec3::new(
            pitch.cos() * yaw.sin(),
            pitch.sin(),
            -pitch.cos() * yaw.cos(),
        )
    }
}

/// Yaw and pitch (degrees) of a VIEW-space direction; `None` for zero or non-finite ones, and for
/// directions that point backwards (no eye looks there).
pub fn angles_of(direction: Vec3) -> Option<[f32; 2]> {
    let d = direction.try_normalize()?;
    if d.z >= 0.0 {
        return None;
    }
    let yaw = d.x.atan2(-d.z).to_degrees();
    let pitch = d.y.atan2(d.x.hypot(d.z)).to_degrees();
    Some([yaw, pitch])
}

/// A first-order low-pass smoothing factor for a cutoff and a step (seconds).
fn alpha(cutoff_hz: f32, dt: f32) -> f32 {
    let tau = 1.0 / (std::f32::consts::TAU * cutoff_hz.max(1e-6));
    1.0 / (1.0 + tau / dt)
}

/// The one-euro filter on yaw and pitch together: one cutoff from the speed of both, so the
/// direction of a movement is kept.
#[derive(Clone, Copy, Debug, PartialEq)]
struct OneEuro {
    time_ns: i64,
    value: [f32; 2],
    speed: [f32; 2],
}

impl OneEuro {
    fn start(time_ns: i64, value: [f32; 2]) -> OneEuro {
        OneEuro {
            time_ns,
            value,
            speed: [0.0; 2],
        }
    }

    fn step(&mut self, p: &GazeParams, time_ns: i64, x: [f32; 2]) {
        let dt = (time_ns - self.time_ns) as f32 * 1e-9;
        if dt <= 0.0 {
            // A repeated or older sample: nothing new to learn from.
            return;
        }
        let raw_speed = [0, 1].map(|i| (x[i] - self.value[i]) / dt);
        let a_d = alpha(p.d_cutoff_hz, dt);
        self.speed = [0, 1].map(|i| self.speed[i] + a_d * (raw_speed[i] - self.speed[i]));
        let cutoff = p.min_cutoff_hz + p.beta * self.speed[0].hypot(self.speed[1]);
        let a = alpha(cutoff, dt);
        self.value = [0, 1].map(|i| self.value[i] + a * (x[i] - self.value[i]));
        self.time_ns = time_ns;
    }
}

/// Smoothstep: eases in and out, so the fovea neither jumps nor stops abruptly.
fn ease(t: f32) -> f32 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The gaze filter of one session: fed a sample (or none) per frame, it answers where the fovea
/// goes. Plain data, no allocation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GazeFilter {
    params: GazeParams,
    filter: Option<OneEuro>,
    /// The time of the last valid sample and the gaze answered then.
    last_good: Option<(i64, [f32; 2])>,
}

impl GazeFilter {
    pub fn new(params: GazeParams) -> GazeFilter {
        GazeFilter {
            params,
            filter: None,
            last_good: None,
        }
    }

    pub fn params(&self) -> &GazeParams {
        &self.params
    }

    /// Takes this frame's sample (`None` where the runtime gave no valid gaze) at `now_ns` and
    /// answers where the fovea goes.
    pub fn update(&mut self, sample: Option<Sample>, now_ns: i64) -> Gaze {
        let p = self.params;
        if let Some((s, angles)) = sample.and_then(|s| Some((s, angles_of(s.direction)?))) {
            let saccade = |f: &OneEuro| {
                let d = [angles[0] - f.value[0], angles[1] - f.value[1]];
                d[0].hypot(d[1]) >= p.saccade_deg
            };
            // After a loss the filter starts afresh: the eye has moved on.
            let lost = self.last_good.is_none();
            match &mut self.filter {
                Some(f) if !lost && !saccade(f) => f.step(&p, s.time_ns, angles),
                _ => self.filter = Some(OneEuro::start(s.time_ns, angles)),
            }
            let value = self.filter.map_or(angles, |f| f.value);
            self.last_good = Some((s.time_ns, value));
            return Gaze {
                angles: value,
                weight: 1.0,
                tracking: Tracking::Tracked,
            };
        }
        let Some((t, angles)) = self.last_good else {
            return Gaze::FIXED;
        };
        let since = (now_ns - t).max(0) as f32 * 1e-9;
        if since < p.hold_s {
            return Gaze {
                angles,
                weight: 1.0,
                tracking: Tracking::Held,
            };
        }
        let back = since - p.hold_s;
        if back < p.return_s {
            return Gaze {
                angles,
                weight: 1.0 - ease(back / p.return_s),
                tracking: Tracking::Returning,
            };
        }
        self.last_good = None;
        self.filter = None;
        Gaze::FIXED
    }
}

/// One eye's view as the runtime locates it in VIEW space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EyeView {
    pub fov: Fov,
    /// The eye's position in VIEW space, metres.
    pub position: Vec3,
    /// The eye's orientation in VIEW space (identity for parallel displays).
    pub orientation: Quat,
}

/// What projecting into one eye takes, computed once for a located view rather than every frame:
/// the inverse of its orientation, its position, its FOV's tangents and its projection centre (a
/// view's tangents cost eight `tan` a frame otherwise).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EyeProjection {
    inverse: Quat,
    position: Vec3,
    /// left, right, up, down.
    tangents: [f32; 4],
    fixed: [f32; 2],
}

impl EyeView {
    /// The view's projection, for [`centre_in`].
    pub fn projection(&self) -> EyeProjection {
        EyeProjection {
            inverse: self.orientation.inverse(),
            position: self.position,
            tangents: self.fov.tangents().map(|t| t as f32),
            fixed: self.fov.projection_center_ndc(),
        }
    }
}

/// Where a VIEW-space point lands in the eye's normalised device coordinates (y up), unclamped;
/// `None` for points at or behind the eye.
fn ndc_in(point: Vec3, eye: &EyeProjection) -> Option<[f32; 2]> {
    let p = eye.inverse * (point - eye.position);
    if p.z >= -1e-6 {
        return None;
    }
    let (tx, ty) = (p.x / -p.z, p.y / -p.z);
    let [l, r, u, d] = eye.tangents;
    Some([
        (2.0 * tx - (r - l)) / (l + r),
        (2.0 * ty - (u - d)) / (u + d),
    ])
}

/// Where the fovea goes in `eye`'s normalised device coordinates (y up, kept inside the view):
/// where the gaze meets the fixation plane, as that eye sees it, blended towards the projection
/// centre (fixed foveation's fovea) as the gaze's weight falls.
pub fn eye_centre(gaze: &Gaze, eye: &EyeView, fixation_m: f32) -> [f32; 2] {
    centre_in(gaze, &eye.projection(), fixation_m)
}

/// [`eye_centre`] with the view's projection computed beforehand ([`EyeView::projection`]): what
/// a frame loop calls, the same answer to the bit.
pub fn centre_in(gaze: &Gaze, eye: &EyeProjection, fixation_m: f32) -> [f32; 2] {
    let fixed = eye.fixed;
    if gaze.weight <= 0.0 {
        return fixed;
    }
    let point = gaze.direction() * fixation_m.max(0.01);
    let Some(g) = ndc_in(point, eye) else {
        return fixed;
    };
    let w = gaze.weight.min(1.0);
    [0, 1].map(|i| (fixed[i] + w * (g[i] - fixed[i])).clamp(-1.0, 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: i64 = 1_000_000;

    fn quest3_left() -> EyeView {
        EyeView {
            fov: Fov::from_tangents(1.376382, 0.839100, 0.965689, 1.428148),
            position: Vec3::new(-0.032, 0.0, 0.0),
            orientation: Quat::IDENTITY,
        }
    }

    fn dir(yaw: f32, pitch: f32) -> Vec3 {
        Gaze {
            angles: [yaw, pitch],
            weight: 1.0,
            tracking: Tracking::Tracked,
        }
        .direction()
    }

    fn sample(ms: i64, yaw: f32, pitch: f32) -> Option<Sample> {
        Some(Sample {
            time_ns: ms * MS,
            direction: dir(yaw, pitch),
        })
    }

    /// A deterministic noise source in [-1, 1] (a linear congruential generator).
    struct Noise(u64);
    impl Noise {
        fn next(&mut self) -> f32 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((self.0 >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        }
    }

    #[test]
    fn angles_round_trip_and_refuse_nonsense() {
        for (y, p) in [(0.0, 0.0), (20.0, -10.0), (-35.0, 25.0)] {
            let a = angles_of(dir(y, p)).unwrap();
            assert!((a[0] - y).abs() < 1e-4 && (a[1] - p).abs() < 1e-4, "{a:?}");
        }
        assert_eq!(angles_of(Vec3::ZERO), None);
        assert_eq!(angles_of(Vec3::new(f32::NAN, 0.0, -1.0)), None);
        assert_eq!(angles_of(Vec3::new(0.0, 0.0, 1.0)), None);
    }

    #[test]
    fn straight_ahead_at_infinity_is_the_projection_centre() {
        let eye = EyeView {
            position: Vec3::ZERO,
            ..quest3_left()
        };
        let g = Gaze {
            angles: [0.0, 0.0],
            weight: 1.0,
            tracking: Tracking::Tracked,
        };
        let c = eye_centre(&g, &eye, 1.0);
        let f = eye.fov.projection_center_ndc();
        assert!((c[0] - f[0]).abs() < 1e-5 && (c[1] - f[1]).abs() < 1e-5);
    }

    #[test]
    fn the_left_eye_sees_a_near_fixation_to_its_right() {
        // At 1 m, a point straight ahead of the head is 32 mm right of the left eye: parallax
        // moves that eye's fovea right of its projection centre, and the right eye's left.
        let g = Gaze {
            angles: [0.0, 0.0],
            weight: 1.0,
            tracking: Tracking::Tracked,
        };
        let left = quest3_left();
        let right = EyeView {
            fov: left.fov.mirrored(),
            position: Vec3::new(0.032, 0.0, 0.0),
            orientation: Quat::IDENTITY,
        };
        let (cl, cr) = (eye_centre(&g, &left, 1.0), eye_centre(&g, &right, 1.0));
        let (fl, fr) = (
            left.fov.projection_center_ndc(),
            right.fov.projection_center_ndc(),
        );
        assert!(cl[0] > fl[0] + 0.02, "{cl:?} {fl:?}");
        assert!(cr[0] < fr[0] - 0.02, "{cr:?} {fr:?}");
        // Farther fixation, less parallax.
        let far = eye_centre(&g, &left, 10.0);
        assert!(far[0] < cl[0] && far[0] > fl[0]);
    }

    #[test]
    fn looking_right_and_up_moves_the_fovea_right_and_up_and_stays_in_view() {
        let g = |yaw, pitch| Gaze {
            angles: [yaw, pitch],
            weight: 1.0,
            tracking: Tracking::Tracked,
        };
        let eye = quest3_left();
        let a = eye_centre(&g(0.0, 0.0), &eye, 1.0);
        let b = eye_centre(&g(15.0, 10.0), &eye, 1.0);
        assert!(b[0] > a[0] + 0.2 && b[1] > a[1] + 0.1, "{a:?} {b:?}");
        // Beyond the FOV's edge: clamped to it.
        let c = eye_centre(&g(80.0, -80.0), &eye, 1.0);
        assert_eq!(c, [1.0, -1.0]);
    }

    #[test]
    fn a_canted_display_sees_the_gaze_in_its_own_frame() {
        // A display turned 10° outwards (left eye: to the left): straight ahead of the head lands
        // right of where it would on a parallel display.
        let parallel = quest3_left();
        let canted = EyeView {
            orientation: Quat::from_rotation_y(10f32.to_radians()),
            ..parallel
        };
        let g = Gaze {
            angles: [0.0, 0.0],
            weight: 1.0,
            tracking: Tracking::Tracked,
        };
        let (p, c) = (eye_centre(&g, &parallel, 1.0), eye_centre(&g, &canted, 1.0));
        assert!(c[0] > p[0] + 0.1, "{p:?} {c:?}");
    }

    #[test]
    fn fixation_noise_is_smoothed() {
        // 0.5° of jitter at 120 Hz around a fixation: the filtered gaze moves far less.
        let mut f = GazeFilter::new(GazeParams::default());
        let mut noise = Noise(7);
        let (mut raw_sq, mut out_sq, mut n) = (0.0f64, 0.0f64, 0);
        for i in 0..1200 {
            let t = i * 1_000 / 120;
            let (dy, dp) = (0.5 * noise.next(), 0.5 * noise.next());
            let g = f.update(sample(t, 10.0 + dy, -5.0 + dp), t * MS);
            assert_eq!(g.tracking, Tracking::Tracked);
            if i >= 120 {
                raw_sq += f64::from(dy * dy + dp * dp);
                let (ey, ep) = (g.angles[0] - 10.0, g.angles[1] + 5.0);
                out_sq += f64::from(ey * ey + ep * ep);
                n += 1;
            }
        }
        let (raw, out) = ((raw_sq / n as f64).sqrt(), (out_sq / n as f64).sqrt());
        eprintln!("gaze filter: fixation jitter {raw:.3}° rms in, {out:.3}° rms out");
        assert!(out < raw / 3.0, "{raw} {out}");
    }

    #[test]
    fn smooth_pursuit_lags_little() {
        // 30°/s of smooth pursuit, sampled at 120 Hz, once the filter has settled.
        let mut f = GazeFilter::new(GazeParams::default());
        let mut lag: f32 = 0.0;
        for i in 0..120 {
            let t = i * 1_000 / 120;
            let yaw = -15.0 + 30.0 * t as f32 / 1000.0;
            let g = f.update(sample(t, yaw, 0.0), t * MS);
            if i >= 60 {
                lag = lag.max(yaw - g.angles[0]);
            }
        }
        eprintln!("gaze filter: pursuit at 30°/s lags {lag:.2}°");
        assert!(lag > 0.0 && lag < 1.5, "{lag}");
    }

    #[test]
    fn a_saccade_arrives_at_once() {
        let mut f = GazeFilter::new(GazeParams::default());
        for i in 0..60 {
            f.update(sample(i * 8, 0.0, 0.0), i * 8 * MS);
        }
        let g = f.update(sample(480, 12.0, 4.0), 480 * MS);
        assert!((g.angles[0] - 12.0).abs() < 1e-4 && (g.angles[1] - 4.0).abs() < 1e-4);
        // A small step is smoothed instead.
        let h = f.update(sample(488, 13.0, 4.0), 488 * MS);
        assert!(h.angles[0] > 12.0 && h.angles[0] < 13.0, "{h:?}");
    }

    #[test]
    fn a_blink_is_held_then_a_loss_eases_back_to_fixed() {
        let p = GazeParams::default();
        let mut f = GazeFilter::new(p);
        for i in 0..30 {
            f.update(sample(i * 10, 20.0, 10.0), i * 10 * MS);
        }
        // A 150 ms blink: held, then tracked again without a jump.
        for t in (300..450).step_by(10) {
            let g = f.update(None, t * MS);
            assert_eq!((g.tracking, g.weight), (Tracking::Held, 1.0));
            assert!((g.angles[0] - 20.0).abs() < 0.01);
        }
        assert_eq!(
            f.update(sample(450, 20.0, 10.0), 450 * MS).tracking,
            Tracking::Tracked
        );
        // Lost for good: held for hold_s, eased back over return_s, then fixed.
        let start = 450;
        let mut last_weight = 1.0;
        // Off the 10 ms grid, so no step lands on a boundary.
        let mut t = start + 5;
        let end = start + ((p.hold_s + p.return_s) * 1000.0) as i64 + 20;
        while t <= end {
            let g = f.update(None, t * MS);
            assert!(g.weight <= last_weight, "{g:?}");
            last_weight = g.weight;
            let since = (t - start) as f32 / 1000.0;
            let want = if since < p.hold_s {
                Tracking::Held
            } else if since < p.hold_s + p.return_s {
                Tracking::Returning
            } else {
                Tracking::Fixed
            };
            assert_eq!(g.tracking, want, "at {since} s");
            t += 10;
        }
        assert_eq!(f.update(None, (end + 1000) * MS), Gaze::FIXED);
        // Back from a loss: taken as it is, not smoothed from where it was.
        let g = f.update(sample(end + 1010, -5.0, 0.0), (end + 1010) * MS);
        assert_eq!(g.tracking, Tracking::Tracked);
        assert!((g.angles[0] + 5.0).abs() < 1e-4 && g.angles[1].abs() < 1e-4);
    }

    #[test]
    fn the_return_blends_the_fovea_towards_the_projection_centre() {
        let eye = quest3_left();
        let g = |weight| Gaze {
            angles: [20.0, 0.0],
            weight,
            tracking: Tracking::Returning,
        };
        let full = eye_centre(&g(1.0), &eye, 1.0);
        let half = eye_centre(&g(0.5), &eye, 1.0);
        let none = eye_centre(&g(0.0), &eye, 1.0);
        assert_eq!(none, eye.fov.projection_center_ndc());
        assert!((half[0] - (full[0] + none[0]) / 2.0).abs() < 1e-5);
    }

    #[test]
    fn no_sample_ever_is_fixed_foveation() {
        let mut f = GazeFilter::new(GazeParams::default());
        assert_eq!(f.update(None, 0), Gaze::FIXED);
        let bad = Sample {
            time_ns: 1,
            direction: Vec3::ZERO,
        };
        assert_eq!(f.update(Some(bad), 1), Gaze::FIXED);
    }

    #[test]
    fn repeated_samples_change_nothing() {
        let mut f = GazeFilter::new(GazeParams::default());
        f.update(sample(0, 0.0, 0.0), 0);
        let a = f.update(sample(10, 2.0, 0.0), 10 * MS);
        let b = f.update(sample(10, 2.0, 0.0), 11 * MS);
        assert_eq!(a.angles, b.angles);
    }
}
