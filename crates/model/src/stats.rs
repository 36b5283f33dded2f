//! Once a second, what the layer does: a line through `tracing` (target `fovea::stats`, level info)
//! in the spirit of Quest's VrApi logcat line, e.g.
//!
//! ```text
//! FPS=45/90 App=6.02ms Int=22.22ms Miss=45 Fov=3D Maps=2/4 Cpu=0.41us
//! ```
//!
//! `FPS` frames ended in the last second against the display's refresh rate; `App` the mean time from
//! `xrBeginFrame` to `xrEndFrame`; `Int` the mean interval between predicted display times; `Miss`
//! display periods missed; `Fov` the highest effective level of the session's foveated swapchains,
//! `D` when dynamic; `Maps` density maps built and uploaded; `Cpu` the layer's own time per frame
//! in its frame hooks. Windows are measured in display time, so the simulated runtime's virtual
//! clock gives the same lines on every run.

use std::fmt;

use crate::density::Level;
use crate::gaze::Tracking;

/// One window of display time between two lines.
pub const WINDOW_NS: i64 = 1_000_000_000;
/// Display times are whole nanoseconds, so 90 periods of 11 111 111 ns fall 10 ns short of a
/// second: a window closes this much early so that it holds 90 frames at 90 Hz, not 91.
const SLACK_NS: i64 = 1_000_000;

/// Accumulates one window; no allocation.
#[derive(Clone, Debug, Default)]
pub struct Stats {
    window_start: Option<i64>,
    frames: u32,
    app_ns: u64,
    app_frames: u32,
    interval_ns: i64,
    intervals: u32,
    missed: u32,
    own_ns: u64,
    own_frames: u32,
}

/// A finished window's figures, without the session-wide fields the line adds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Window {
    pub frames: u32,
    pub app_ms: f64,
    pub interval_ms: f64,
    pub missed: u32,
    pub cpu_us: f64,
}

impl Stats {
    /// `intervals` `xrWaitFrame` calls: the sum of the intervals between their predicted display
    /// times and the periods they skipped.
    pub fn waited(&mut self, interval_ns: i64, intervals: u32, missed: u32) {
        self.interval_ns += interval_ns;
        self.intervals += intervals;
        self.missed += missed;
    }

    /// An `xrEndFrame` for the frame displayed at `display_ns`, `app_ns` after its `xrBeginFrame`,
    /// with `own_ns` spent in the layer. Returns the window when a second of display time is full.
    /// Either time is `None` for a frame that was not timed (the layer reads the clock only while
    /// the line is logged); the means are over the frames that were.
    pub fn ended(
        &mut self,
        display_ns: i64,
        app_ns: Option<u64>,
        own_ns: Option<u64>,
    ) -> Option<Window> {
        let start = *self.window_start.get_or_insert(display_ns);
        let mut finished = None;
        if display_ns - start >= WINDOW_NS - SLACK_NS {
            // This frame opens the next window.
            let mean = |sum: f64, n: u32| if n == 0 { 0.0 } else { sum / f64::from(n) };
            finished = Some(Window {
                frames: self.frames,
                app_ms: mean(self.app_ns as f64, self.app_frames) / 1e6,
                interval_ms: mean(self.interval_ns as f64, self.intervals) / 1e6,
                missed: self.missed,
                cpu_us: mean(self.own_ns as f64, self.own_frames) / 1e3,
            });
            *self = Stats {
                window_start: Some(display_ns),
                ..Stats::default()
            };
        }
        self.frames += 1;
        if let Some(a) = app_ns {
            self.app_ns += a;
            self.app_frames += 1;
        }
        if let Some(o) = own_ns {
            self.own_ns += o;
            self.own_frames += 1;
        }
        finished
    }
}

/// The whole line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Line {
    pub window: Window,
    pub refresh_hz: u32,
    /// The highest effective level, and whether it is dynamic; `None` without foveated swapchains.
    pub level: Option<(Level, bool)>,
    pub maps_built: u64,
    pub maps_uploaded: u64,
    /// In injection mode (docs/injection.md#stats): the passes per frame that got injected shading
    /// rates, and all passes begun per frame, as means over the window rounded to whole passes.
    pub injected: Option<(u64, u64)>,
    /// Where the gaze puts the fovea now (docs/eye-tracking.md#stats).
    pub gaze: GazeShown,
}

/// The gaze as the stats line shows it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GazeShown {
    /// Gaze is switched off: fixed foveation by choice (`Gaze=off`).
    Off,
    /// No gaze (none on this runtime or system, never active, or lost and back): fixed foveation
    /// (`Gaze=fixed`).
    Fixed,
    /// The fovea follows the gaze: how far it is trusted, and the centre of the first two views in
    /// normalised device coordinates, y up (`Gaze=tracked@-0.12,+0.30/+0.05,+0.30`).
    Follows {
        tracking: Tracking,
        ndc: [[f32; 2]; 2],
        views: u8,
    },
}

impl fmt::Display for GazeShown {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            GazeShown::Off => write!(f, "off"),
            GazeShown::Follows {
                tracking,
                ndc,
                views,
            } if tracking != Tracking::Fixed && views > 0 => {
                let name = match tracking {
                    Tracking::Tracked => "tracked",
                    Tracking::Held => "held",
                    _ => "returning",
                };
                write!(f, "{name}@")?;
                for (i, [x, y]) in ndc.iter().take(usize::from(views)).enumerate() {
                    let sep = if i == 0 { "" } else { "/" };
                    write!(f, "{sep}{x:+.2},{y:+.2}")?;
                }
                Ok(())
            }
            _ => write!(f, "fixed"),
        }
    }
}

impl Line {
    /// The per-frame means of `eye` injected and `all` passes counted over `frames` frames.
    pub fn per_frame(eye: u64, all: u64, frames: u32) -> (u64, u64) {
        let f = u64::from(frames.max(1));
        ((eye + f / 2) / f, (all + f / 2) / f)
    }
}

impl fmt::Display for Line {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let w = &self.window;
        write!(
            f,
            "FPS={}/{} App={:.2}ms Int={:.2}ms Miss={} Fov=",
            w.frames, self.refresh_hz, w.app_ms, w.interval_ms, w.missed
        )?;
        match self.level {
            Some((level, dynamic)) => {
                write!(f, "{}{}", level as u32, if dynamic { "D" } else { "" })?
            }
            None => write!(f, "-")?,
        }
        if let Some((eye, all)) = self.injected {
            write!(f, " Inj={eye}/{all}")?;
        }
        write!(
            f,
            " Gaze={} Maps={}/{} Cpu={:.2}us",
            self.gaze, self.maps_built, self.maps_uploaded, w.cpu_us
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_closes_after_a_second_of_display_time_with_its_means() {
        let mut s = Stats::default();
        let period = 11_111_111;
        let mut t = 0;
        let mut windows = Vec::new();
        for i in 0..200 {
            let missed = u32::from(i % 2 == 0);
            t += period * (1 + i64::from(missed));
            s.waited(period * (1 + i64::from(missed)), 1, missed);
            if let Some(w) = s.ended(t, Some(6_000_000), Some(400)) {
                windows.push(w);
            }
        }
        assert_eq!(windows.len(), 3, "3.3 s of display time");
        let w = windows[0];
        assert!((60..=61).contains(&w.frames), "{w:?}");
        let mut steady = Stats::default();
        let full: Vec<Window> = (1..=300)
            .filter_map(|i| steady.ended(i * period, None, None))
            .collect();
        assert!(
            full.iter().all(|w| w.frames == 90),
            "90 Hz gives 90 frames a line: {full:?}"
        );
        assert!((w.app_ms - 6.0).abs() < 1e-9);
        assert!((w.interval_ms - 16.67).abs() < 0.2, "{w:?}");
        assert!(w.missed.abs_diff(w.frames / 2) <= 1);
        assert!((w.cpu_us - 0.4).abs() < 1e-9);
        assert!(full.iter().all(|w| w.app_ms == 0.0 && w.cpu_us == 0.0));
        // Timing switched on mid-window: the means are over the timed frames only.
        let mut half = Stats::default();
        let some = (1..=200)
            .filter_map(|i| {
                let timed = (i % 90 > 45).then_some(1_000);
                half.ended(i * period, timed.map(|t| t * 2), timed)
            })
            .next()
            .unwrap();
        assert!((some.cpu_us - 1.0).abs() < 1e-9, "{some:?}");
        assert!((some.app_ms - 0.002).abs() < 1e-9, "{some:?}");
        let line = Line {
            window: w,
            refresh_hz: 90,
            level: Some((Level::High, true)),
            maps_built: 2,
            maps_uploaded: 4,
            injected: None,
            gaze: GazeShown::Off,
        };
        let text = line.to_string();
        assert!(
            text.starts_with(&format!("FPS={}/90 App=6.00ms Int=", w.frames)),
            "{text}"
        );
        assert!(
            text.ends_with("Fov=3D Gaze=off Maps=2/4 Cpu=0.40us"),
            "{text}"
        );
        let follows = |tracking, views| {
            Line {
                gaze: GazeShown::Follows {
                    tracking,
                    ndc: [[-0.121, 0.3], [0.05, 0.3]],
                    views,
                },
                ..line
            }
            .to_string()
        };
        assert!(
            follows(Tracking::Tracked, 2).contains(" Gaze=tracked@-0.12,+0.30/+0.05,+0.30 "),
            "{}",
            follows(Tracking::Tracked, 2)
        );
        assert!(follows(Tracking::Held, 1).contains(" Gaze=held@-0.12,+0.30 "));
        assert!(follows(Tracking::Returning, 2).contains(" Gaze=returning@"));
        assert!(follows(Tracking::Fixed, 2).contains(" Gaze=fixed "));
        assert!(follows(Tracking::Tracked, 0).contains(" Gaze=fixed "));
        let fixed = Line {
            gaze: GazeShown::Fixed,
            ..line
        };
        assert!(fixed.to_string().contains(" Gaze=fixed "), "{fixed}");
        let none = Line {
            level: None,
            ..line
        }
        .to_string();
        assert!(none.contains("Fov=- "), "{none}");
        let injected = Line {
            level: Some((Level::Medium, false)),
            injected: Some(Line::per_frame(181, 540, 90)),
            ..line
        }
        .to_string();
        assert!(
            injected.contains("Fov=2 Inj=2/6 Gaze=off Maps="),
            "{injected}"
        );
        assert_eq!(Line::per_frame(5, 9, 0), (5, 9), "no frames: the counts");
    }
}
