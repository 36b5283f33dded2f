//! The simulated eye tracker's script: where the eye looks over time, as fixations, saccades,
//! smooth pursuit, blinks and spans where the tracker has nothing, sampled at the tracker's rate
//! and reported late by its latency.
//!
//! A script is one line (`FOVEA_SIM_GAZE`), steps separated by `;`. Angles are degrees, yaw right
//! and pitch up positive, in VIEW space; times take `ms` or `s`:
//! - `fix Y,P for T`: look at (Y, P) for T (`fix for T` stays where the eye is);
//! - `saccade Y,P in T`: move there in T, valid throughout (saccades take 20–80 ms);
//! - `pursue Y,P at V`: move there at V degrees per second (smooth pursuit is up to about 30°/s);
//! - `blink T`, `lost T`: no valid gaze for T, the eye where it was;
//! - `loop`: as the last step, start again from the first;
//! - settings anywhere: `hz=N` (sample rate, default 120), `latency=T` (default 0), `noise=D`
//!   (uniform jitter of ±D degrees per sample, deterministic, default 0), `tracked=no` (every
//!   sample sub-nominal: orientation VALID without TRACKED, as trackers report a degraded fix),
//!   `permission=T` (the user grants eye tracking T after the session starts: until then the gaze
//!   action stays inactive, as on runtimes that ask for the permission), `head=V` (the head turns
//!   right at V degrees per second from the session's start, and the script's angles are then
//!   directions in LOCAL space: the eye holds its target in the world while the head turns, as the
//!   vestibulo-ocular reflex does, so in VIEW space the gaze turns the other way at V, and a gaze
//!   located for the wrong time is off by V times the error).
//!
//! Example: `hz=120; latency=20ms; fix 0,0 for 500ms; saccade 12,4 in 40ms; fix for 300ms;
//! pursue -10,4 at 30; blink 150ms; lost 1s; loop`. Before the first step and after the last (no
//! `loop`) the eye stays where the script starts or ends.

/// One step of a script.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Step {
    /// Look at a point (or stay, `None`) for a time.
    Fix(Option<[f32; 2]>, i64),
    /// Move to a point over a time.
    Move([f32; 2], i64),
    /// Move to a point at a speed (degrees per second).
    Pursue([f32; 2], f32),
    /// No valid gaze for a time.
    Invalid(i64),
}

/// A parsed script, its steps laid on a timeline.
#[derive(Clone, Debug, PartialEq)]
pub struct GazeScript {
    /// (start, end, from, to, valid) per step, in ns from the script's start.
    spans: Vec<Span>,
    looped: bool,
    hz: f32,
    latency_ns: i64,
    noise_deg: f32,
    /// Samples are VALID without TRACKED (`tracked=no`).
    pub sub_nominal: bool,
    /// Time from the session's start until eye tracking is permitted (`permission=T`).
    pub permission_ns: i64,
    /// How fast the head turns right, degrees per second (`head=V`).
    pub head_deg_per_s: f32,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Span {
    start: i64,
    end: i64,
    from: [f32; 2],
    to: [f32; 2],
    valid: bool,
}

fn time_ns(s: &str) -> Result<i64, String> {
    let (num, scale) = if let Some(n) = s.strip_suffix("ms") {
        (n, 1e6)
    } else if let Some(n) = s.strip_suffix('s') {
        (n, 1e9)
    } else {
        return Err(format!("a time needs `ms` or `s`: {s:?}"));
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("not a time: {s:?}"))?;
    if !(v.is_finite() && v >= 0.0) {
        return Err(format!("not a time: {s:?}"));
    }
    Ok((v * scale).round() as i64)
}

fn point(s: &str) -> Result<[f32; 2], String> {
    let (y, p) = s
        .split_once(',')
        .ok_or_else(|| format!("a point is YAW,PITCH: {s:?}"))?;
    let f = |v: &str| -> Result<f32, String> {
        let v: f32 = v
            .trim()
            .parse()
            .map_err(|_| format!("not an angle: {v:?}"))?;
        if v.is_finite() && v.abs() < 90.0 {
            Ok(v)
        } else {
            Err(format!("an angle must be within ±90°: {v}"))
        }
    };
    Ok([f(y)?, f(p)?])
}

impl GazeScript {
    /// Parses a script; the error says which step is wrong.
    pub fn parse(text: &str) -> Result<GazeScript, String> {
        let mut steps = Vec::new();
        let (mut hz, mut latency_ns, mut noise_deg, mut looped) = (120.0f32, 0i64, 0.0f32, false);
        let (mut sub_nominal, mut permission_ns, mut head_deg_per_s) = (false, 0i64, 0.0f32);
        let parts: Vec<&str> = text
            .split(';')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .collect();
        for (i, part) in parts.iter().enumerate() {
            let words: Vec<&str> = part.split_whitespace().collect();
            let bad = || format!("gaze script step {}: {part:?}", i + 1);
            if let Some((key, value)) = part.split_once('=') {
                match key.trim() {
                    "hz" => {
                        hz = value.trim().parse().map_err(|_| bad())?;
                        if !(hz.is_finite() && hz > 0.0) {
                            return Err(bad());
                        }
                    }
                    "latency" => {
                        latency_ns = time_ns(value.trim()).map_err(|e| bad() + ": " + &e)?
                    }
                    "noise" => {
                        noise_deg = value.trim().parse().map_err(|_| bad())?;
                        if !(noise_deg.is_finite() && noise_deg >= 0.0) {
                            return Err(bad());
                        }
                    }
                    "tracked" => {
                        sub_nominal = match value.trim() {
                            "yes" => false,
                            "no" => true,
                            _ => return Err(bad() + ": tracked is yes or no"),
                        }
                    }
                    "head" => {
                        head_deg_per_s = value.trim().parse().map_err(|_| bad())?;
                        if !head_deg_per_s.is_finite() {
                            return Err(bad());
                        }
                    }
                    "permission" => {
                        permission_ns = time_ns(value.trim()).map_err(|e| bad() + ": " + &e)?
                    }
                    _ => return Err(bad() + ": unknown setting"),
                }
                continue;
            }
            let err = |e: String| bad() + ": " + &e;
            let step = match words.as_slice() {
                ["fix", "for", t] => Step::Fix(None, time_ns(t).map_err(err)?),
                ["fix", p, "for", t] => {
                    Step::Fix(Some(point(p).map_err(err)?), time_ns(t).map_err(err)?)
                }
                ["saccade", p, "in", t] => {
                    Step::Move(point(p).map_err(err)?, time_ns(t).map_err(err)?)
                }
                ["pursue", p, "at", v] => {
                    let v: f32 = v.parse().map_err(|_| bad())?;
                    if !(v.is_finite() && v > 0.0) {
                        return Err(bad() + ": a speed must be positive");
                    }
                    Step::Pursue(point(p).map_err(err)?, v)
                }
                ["blink", t] | ["lost", t] => Step::Invalid(time_ns(t).map_err(err)?),
                ["loop"] if i + 1 == parts.len() => {
                    looped = true;
                    continue;
                }
                _ => return Err(bad() + ": unknown step"),
            };
            steps.push(step);
        }
        let mut spans = Vec::with_capacity(steps.len());
        let (mut t, mut at) = (0i64, [0.0f32; 2]);
        for s in steps {
            let (to, duration, valid) = match s {
                Step::Fix(p, d) => (p.unwrap_or(at), d, true),
                Step::Move(p, d) => (p, d, true),
                Step::Pursue(p, v) => {
                    let dist = (p[0] - at[0]).hypot(p[1] - at[1]);
                    (p, (f64::from(dist / v) * 1e9).round() as i64, true)
                }
                Step::Invalid(d) => (at, d, false),
            };
            let from = if matches!(s, Step::Fix(..)) { to } else { at };
            spans.push(Span {
                start: t,
                end: t + duration,
                from,
                to,
                valid,
            });
            t += duration;
            at = to;
        }
        if looped && t == 0 {
            return Err("a looping gaze script needs steps that take time".to_owned());
        }
        Ok(GazeScript {
            spans,
            looped,
            hz,
            latency_ns,
            noise_deg,
            sub_nominal,
            permission_ns,
            head_deg_per_s,
        })
    }

    /// How long one pass of the script takes.
    pub fn duration_ns(&self) -> i64 {
        self.spans.last().map_or(0, |s| s.end)
    }

    /// Where the eye truly is `t_ns` after the script's start (`None` while it gives no gaze).
    pub fn eye_at(&self, t_ns: i64) -> Option<[f32; 2]> {
        let total = self.duration_ns();
        let t = if self.looped && total > 0 {
            t_ns.rem_euclid(total)
        } else {
            t_ns.clamp(0, total)
        };
        let Some(span) = self.spans.iter().find(|s| t < s.end).or(self.spans.last()) else {
            return Some([0.0, 0.0]);
        };
        if !span.valid {
            return None;
        }
        let len = (span.end - span.start).max(1) as f32;
        let k = ((t - span.start) as f32 / len).clamp(0.0, 1.0);
        Some([0, 1].map(|i| span.from[i] + k * (span.to[i] - span.from[i])))
    }

    /// What the tracker reports at `t_ns`: its latest sample (taken at the sample rate) of where the
    /// eye was `latency` earlier, with the script's jitter, and that sample's time.
    pub fn sample_at(&self, t_ns: i64) -> Option<([f32; 2], i64)> {
        let period = (1e9 / f64::from(self.hz)).round().max(1.0) as i64;
        let index = (t_ns - self.latency_ns).div_euclid(period);
        let taken = index * period;
        let eye = self.eye_at(taken)?;
        let jitter = |salt: u64| {
            let mut x = (index as u64) ^ salt;
            x = x.wrapping_mul(0x9E37_79B9_7F4A_7C15);
            x ^= x >> 31;
            x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
            x ^= x >> 29;
            ((x >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0) * self.noise_deg
        };
        Some((
            [eye[0] + jitter(1), eye[1] + jitter(2)],
            taken + self.latency_ns,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tracker_settings() {
        let s = GazeScript::parse("tracked=no; permission=2s; head=60; fix 1,2 for 1s").unwrap();
        assert!(s.sub_nominal);
        assert_eq!(s.permission_ns, 2_000_000_000);
        assert_eq!(s.head_deg_per_s, 60.0);
        let d = GazeScript::parse("fix 1,2 for 1s").unwrap();
        assert!(!d.sub_nominal && d.permission_ns == 0 && d.head_deg_per_s == 0.0);
        assert!(!GazeScript::parse("tracked=yes").unwrap().sub_nominal);
        for bad in ["tracked=maybe", "permission=2", "head=fast", "head=inf"] {
            assert!(GazeScript::parse(bad).is_err(), "{bad}");
        }
    }

    const MS: i64 = 1_000_000;

    #[test]
    fn fixations_saccades_and_pursuit() {
        let s = GazeScript::parse(
            "fix 0,0 for 100ms; saccade 10,0 in 40ms; fix for 60ms; pursue 10,15 at 30; fix 0,0 for 1s",
        )
        .unwrap();
        assert_eq!(s.eye_at(50 * MS), Some([0.0, 0.0]));
        assert_eq!(s.eye_at(120 * MS), Some([5.0, 0.0]));
        assert_eq!(s.eye_at(170 * MS), Some([10.0, 0.0]));
        // 15° at 30°/s: half a second, half way at 250 ms in.
        let p = s.eye_at(450 * MS).unwrap();
        assert!((p[1] - 7.5).abs() < 1e-3, "{p:?}");
        assert_eq!(s.duration_ns(), 1700 * MS);
        assert_eq!(s.eye_at(5_000 * MS), Some([0.0, 0.0]));
    }

    #[test]
    fn blinks_and_losses_give_no_gaze_and_loops_repeat() {
        let s = GazeScript::parse("fix 5,5 for 100ms; blink 150ms; fix for 100ms; loop").unwrap();
        assert_eq!(s.eye_at(50 * MS), Some([5.0, 5.0]));
        assert_eq!(s.eye_at(150 * MS), None);
        assert_eq!(s.eye_at(300 * MS), Some([5.0, 5.0]));
        assert_eq!(s.eye_at(350 * MS + 150 * MS), None);
    }

    #[test]
    fn samples_come_at_the_rate_and_late_by_the_latency() {
        let s = GazeScript::parse(
            "hz=100; latency=20ms; fix 0,0 for 100ms; saccade 10,0 in 10ms; fix for 1s",
        )
        .unwrap();
        // At 115 ms the tracker reports the sample taken at 90 ms of the eye (still at 0,0),
        // stamped with its report time.
        let (at, when) = s.sample_at(115 * MS).unwrap();
        assert_eq!((at, when), ([0.0, 0.0], 110 * MS));
        let (at, _) = s.sample_at(131 * MS).unwrap();
        assert_eq!(at, [10.0, 0.0]);
    }

    #[test]
    fn noise_is_bounded_and_repeatable() {
        let s = GazeScript::parse("noise=0.5; fix 3,3 for 10s").unwrap();
        let a: Vec<_> = (0..200)
            .map(|i| s.sample_at(i * 8 * MS).unwrap().0)
            .collect();
        let b: Vec<_> = (0..200)
            .map(|i| s.sample_at(i * 8 * MS).unwrap().0)
            .collect();
        assert_eq!(a, b);
        assert!(a
            .iter()
            .all(|p| (p[0] - 3.0).abs() <= 0.5 && (p[1] - 3.0).abs() <= 0.5));
        assert!(a.iter().any(|p| p[0] != 3.0));
    }

    #[test]
    fn bad_scripts_say_which_step() {
        for (text, what) in [
            ("fix 0,0 for 10", "step 1"),
            ("fix 0,0 for 1s; saccade 100,0 in 1ms", "step 2"),
            ("hz=0", "step 1"),
            ("pursue 1,1 at 0", "step 1"),
            ("dance 1s", "step 1"),
            ("loop; fix for 1s", "step 1"),
            ("loop", "needs steps"),
            ("colour=red", "unknown setting"),
        ] {
            let e = GazeScript::parse(text).unwrap_err();
            assert!(e.contains(what), "{text:?}: {e}");
        }
        assert_eq!(GazeScript::parse("").unwrap().eye_at(0), Some([0.0, 0.0]));
    }
}
