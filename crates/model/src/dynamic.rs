//! Dynamic foveation: the level follows the application's headroom (XR_FOVEATION_DYNAMIC_LEVEL_ENABLED_FB).
//!
//! The only headroom signal every runtime gives a layer is the frame timing it already reports:
//! `xrWaitFrame`'s predicted display times advance by more than one `predictedDisplayPeriod` when the
//! previous frame missed the compositor's deadline. So the controller counts frames that missed a
//! period over half-second windows of display time: when at least a tenth of a window's frames miss,
//! the level goes up one step; when no frame has missed for a calm period, it comes down one step.
//!
//! Level jumps are visible (Meta advises against frequent changes within a scene,
//! docs/density-model.md#level-changes), so:
//! - no two changes within [`DWELL_NS`] (1 s) of display time;
//! - hysteresis: going up needs misses now, coming down needs a calm period (2 s at first) without
//!   any, and a step down that brings misses back within 2 s doubles the calm period needed next
//!   time (up to 16 s), so an application at the edge settles instead of oscillating.
//!
//! Everything is a function of display times, so it is deterministic under the simulated runtime's
//! virtual clock and scripted load.

use crate::density::Level;

/// Least display time between two level changes.
pub const DWELL_NS: i64 = 1_000_000_000;
/// Display time over which missed frames are counted.
pub const WINDOW_NS: i64 = 500_000_000;
/// The calm period needed before the first step down, and its cap.
pub const CALM_NS: i64 = 2_000_000_000;
pub const MAX_CALM_NS: i64 = 16_000_000_000;

/// The steps dynamic foveation moves through, lowest first.
pub const LADDER: [Level; 4] = [Level::None, Level::Low, Level::Medium, Level::High];

/// Where `max` sits on the ladder (High Top counts as High's step).
pub fn step_of(max: Level) -> usize {
    match max {
        Level::None => 0,
        Level::Low => 1,
        Level::Medium => 2,
        Level::High | Level::HighTop => 3,
    }
}

/// The level at `step` for a swapchain whose maximum is `max`.
pub fn level_at(step: usize, max: Level) -> Level {
    if step >= step_of(max) {
        max
    } else {
        LADDER[step]
    }
}

/// The controller of one session.
#[derive(Clone, Debug)]
pub struct Controller {
    step: usize,
    last_change: Option<i64>,
    last_fall: Option<i64>,
    window_start: Option<i64>,
    window_frames: u32,
    window_missed: u32,
    calm_since: Option<i64>,
    calm_needed: i64,
}

impl Default for Controller {
    fn default() -> Self {
        Controller {
            step: 0,
            last_change: None,
            last_fall: None,
            window_start: None,
            window_frames: 0,
            window_missed: 0,
            calm_since: None,
            calm_needed: CALM_NS,
        }
    }
}

impl Controller {
    /// The current step on [`LADDER`].
    pub fn step(&self) -> usize {
        self.step
    }

    /// One frame: its predicted display time, how many display periods it missed, and the highest
    /// step any dynamic swapchain allows. Returns whether the step changed.
    pub fn frame(&mut self, display_ns: i64, missed: u32, max_step: usize) -> bool {
        let start = *self.window_start.get_or_insert(display_ns);
        self.window_frames += 1;
        if missed > 0 {
            self.window_missed += 1;
            self.calm_since = None;
        } else if self.calm_since.is_none() {
            self.calm_since = Some(display_ns);
        }
        if self.step > max_step {
            // The application or an override lowered the maximum: follow at once.
            self.step = max_step;
            self.last_change = Some(display_ns);
            return true;
        }
        let settled = self.last_change.is_none_or(|t| display_ns - t >= DWELL_NS);
        if display_ns - start >= WINDOW_NS {
            let overloaded = self.window_missed * 10 >= self.window_frames;
            self.window_start = Some(display_ns);
            self.window_frames = 0;
            self.window_missed = 0;
            if overloaded && settled && self.step < max_step {
                if self.last_fall.is_some_and(|t| display_ns - t < CALM_NS) {
                    self.calm_needed = (self.calm_needed * 2).min(MAX_CALM_NS);
                }
                self.step += 1;
                self.last_change = Some(display_ns);
                return true;
            }
        }
        let calm = self
            .calm_since
            .is_some_and(|t| display_ns - t >= self.calm_needed);
        if calm && settled && self.step > 0 {
            self.step -= 1;
            self.last_change = Some(display_ns);
            self.last_fall = Some(display_ns);
            self.calm_since = Some(display_ns);
            return true;
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PERIOD: i64 = 11_111_111;

    /// Runs `frames` frames of `missed` periods each from `t`, returning the new time and every
    /// (time, step) change.
    fn run(
        c: &mut Controller,
        t: &mut i64,
        frames: u32,
        missed: u32,
        max: usize,
    ) -> Vec<(i64, usize)> {
        let mut changes = Vec::new();
        for _ in 0..frames {
            *t += PERIOD * (1 + i64::from(missed));
            if c.frame(*t, missed, max) {
                changes.push((*t, c.step()));
            }
        }
        changes
    }

    #[test]
    fn rises_under_overload_within_bounded_time_and_never_past_the_maximum() {
        let mut c = Controller::default();
        let mut t = 0;
        let changes = run(&mut c, &mut t, 400, 1, 3);
        assert_eq!(changes.iter().map(|c| c.1).collect::<Vec<_>>(), [1, 2, 3]);
        // First rise once the half-second window opened by the first frame (at 2 periods) is full,
        // within one more frame; then one per dwell.
        let first_frame = 2 * PERIOD;
        assert!(
            changes[0].0 - first_frame <= WINDOW_NS + 2 * PERIOD,
            "{changes:?}"
        );
        for w in changes.windows(2) {
            assert!(w[1].0 - w[0].0 >= DWELL_NS);
        }
        assert_eq!(c.step(), 3);
        let mut capped = Controller::default();
        run(&mut capped, &mut 0, 400, 1, 2);
        assert_eq!(capped.step(), 2, "never above the maximum");
    }

    #[test]
    fn falls_back_when_headroom_returns_and_never_changes_twice_within_the_dwell() {
        let mut c = Controller::default();
        let mut t = 0;
        let mut changes = run(&mut c, &mut t, 300, 1, 3);
        let overload_end = t;
        changes.extend(run(&mut c, &mut t, 90 * 12, 0, 3));
        assert_eq!(c.step(), 0, "back to NONE: {changes:?}");
        let falls: Vec<_> = changes.iter().filter(|c| c.0 > overload_end).collect();
        assert_eq!(falls.len(), 3);
        assert!(falls[0].0 - overload_end >= CALM_NS);
        for w in changes.windows(2) {
            assert!(w[1].0 - w[0].0 >= DWELL_NS, "{changes:?}");
        }
    }

    #[test]
    fn an_application_at_the_edge_settles_instead_of_oscillating() {
        // Misses whenever the step is below 2, none at 2 or above: each fall from 2 brings misses
        // back, so the calm period needed doubles and the changes thin out.
        let mut c = Controller::default();
        let mut t = 0;
        let mut changes = Vec::new();
        for _ in 0..90 * 120 {
            let missed = u32::from(c.step() < 2);
            t += PERIOD * (1 + i64::from(missed));
            if c.frame(t, missed, 3) {
                changes.push((t, c.step()));
            }
        }
        let late = changes.iter().filter(|c| c.0 > 60 * 1_000_000_000).count();
        let early = changes.iter().filter(|c| c.0 <= 60 * 1_000_000_000).count();
        assert!(late < early, "{changes:?}");
        assert!(c.step() >= 1);
    }

    #[test]
    fn lowering_the_maximum_applies_at_once() {
        let mut c = Controller::default();
        let mut t = 0;
        run(&mut c, &mut t, 400, 1, 3);
        assert_eq!(c.step(), 3);
        t += PERIOD;
        assert!(c.frame(t, 1, 1));
        assert_eq!(c.step(), 1);
        assert_eq!(level_at(1, Level::High), Level::Low);
        assert_eq!(level_at(3, Level::HighTop), Level::HighTop);
        assert_eq!(level_at(5, Level::Medium), Level::Medium);
    }
}
