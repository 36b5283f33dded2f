//! Settings read from the environment and the configuration file.
//!
//! Every variable the layer reads is listed here or in `fovea_config` (and in docs/settings.md
//! and include/fovea.h), so there is one place to look. The file, `fovea.toml`, is
//! `fovea_config`'s; its values sit below the environment's and Quest's debug properties and above
//! the application's own profile (docs/settings.md).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicI64, Ordering};
use std::time::SystemTime;

use crate::common::lock::{Mutex, Rank};

use fovea_model::density::Level;
use fovea_model::gaze::GazeParams;

/// `FOVEA_SYMMETRIC_FOV=1`: report one shared symmetric FOV for both eyes (Quest's recommended mode,
/// docs/headsets.md#symmetric-fov) and give pixels outside each eye's true FOV the lowest density.
pub const SYMMETRIC_FOV_ENV: &str = fovea_abi::env::SYMMETRIC_FOV;

/// One of Quest's `debug.oculus.foveation.*` properties (docs/users.md#quest-debug-properties: set with
/// `adb shell setprop` on Quest); fovea reads it from an environment variable and from the
/// `FOVEA_PROPS` file.
#[derive(Debug)]
pub struct Property {
    pub name: &'static str,
    pub env: &'static str,
    pub accepted: &'static str,
}

pub const LEVEL: Property = Property {
    name: "debug.oculus.foveation.level",
    env: "DEBUG_OCULUS_FOVEATION_LEVEL",
    accepted: "0 (off), 1 (low), 2 (medium), 3 (high), 4 (high top)",
};
pub const DYNAMIC: Property = Property {
    name: "debug.oculus.foveation.dynamic",
    env: "DEBUG_OCULUS_FOVEATION_DYNAMIC",
    accepted: "0 or 1",
};
pub const SUBSAMPLED: Property = Property {
    name: "debug.oculus.foveation.subsampled",
    env: "DEBUG_OCULUS_FOVEATION_SUBSAMPLED",
    accepted: "0 or 1",
};
pub const PROPERTIES: [&Property; 3] = [&LEVEL, &DYNAMIC, &SUBSAMPLED];

/// `FOVEA_MAX_FRAGMENT`: the largest fragment any density map asks for (1, 2 or 4).
pub const MAX_FRAGMENT_ENV: &str = fovea_abi::env::MAX_FRAGMENT;

/// `FOVEA_PROPS`: a file of `debug.oculus.foveation.*=value` lines, re-read while the app runs.
pub const PROPS_ENV: &str = fovea_abi::env::PROPS;

/// The overrides in force: Quest's debug properties over the configuration file's values. As on
/// Quest: with dynamic on, the level is the maximum; with dynamic off, it is the level; either
/// applies to every foveated swapchain, above what the application asked for.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DebugProperties {
    pub level: Option<Level>,
    pub dynamic: Option<bool>,
    pub subsampled: Option<bool>,
    /// `vertical_offset` (file only): replaces the application's `verticalOffset`.
    pub vertical_offset_deg: Option<f32>,
    /// `max_fragment` (file or `FOVEA_MAX_FRAGMENT`): 1, 2 or 4.
    pub max_fragment: Option<u32>,
}

impl DebugProperties {
    /// From the environment variables (any key-value source, for tests).
    pub fn from_lookup(get: impl Fn(&str) -> Option<String>) -> DebugProperties {
        let mut p = DebugProperties::default();
        for prop in PROPERTIES {
            if let Some(v) = get(prop.env) {
                p.set(prop, &v, prop.env);
            }
        }
        if let Some(v) = get(MAX_FRAGMENT_ENV) {
            match fovea_config::parse_env(fovea_config::Key::MaxFragment, &v) {
                Some(fovea_config::Value::Fragment(n)) => p.max_fragment = Some(n),
                _ => tracing::warn!(
                    variable = MAX_FRAGMENT_ENV,
                    value = v.trim(),
                    accepted = fovea_config::Key::MaxFragment.accepted(),
                    "bad value; ignored"
                ),
            }
        }
        p
    }

    /// The file's values for the application `id`: the sections of `config` that match it.
    pub fn from_config(config: &fovea_config::Config, id: &fovea_config::Identity) -> Self {
        use fovea_config::Key;
        let (r, _) = fovea_config::resolve(Some(config), id, |_| None);
        DebugProperties {
            level: r.level(Key::Level),
            dynamic: r.flag(Key::Dynamic),
            subsampled: None,
            vertical_offset_deg: r.vertical_offset_deg(),
            max_fragment: r.get(Key::MaxFragment).is_some().then(|| r.max_fragment()),
        }
    }

    /// The largest fragment maps may ask for now.
    pub fn max_fragment(&self) -> u32 {
        self.max_fragment
            .unwrap_or(fovea_config::DEFAULT_MAX_FRAGMENT)
    }

    /// From a property file's text: `name=value` lines; blank lines and `#` comments are skipped, a
    /// later line wins, an unknown name gets a warning.
    pub fn parse(text: &str, origin: &str) -> DebugProperties {
        let mut p = DebugProperties::default();
        for line in text.lines().map(str::trim) {
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let (key, value) = line.split_once('=').unwrap_or((line, ""));
            match PROPERTIES.iter().find(|prop| prop.name == key.trim()) {
                Some(prop) => p.set(prop, value, origin),
                None => tracing::warn!(
                    file = origin,
                    line,
                    "not a debug.oculus.foveation property (level, dynamic, subsampled); ignored"
                ),
            }
        }
        p
    }

    /// Sets one property from text; a bad value gets one warning naming the property and its
    /// accepted values, and leaves the property as it was.
    fn set(&mut self, prop: &Property, value: &str, origin: &str) {
        let v = value.trim();
        let ok = match prop.name {
            n if n == LEVEL.name => v
                .parse::<u32>()
                .ok()
                .and_then(Level::from_index)
                .map(|l| self.level = Some(l)),
            n if n == DYNAMIC.name => bool01(v).map(|b| self.dynamic = Some(b)),
            _ => bool01(v).map(|b| self.subsampled = Some(b)),
        };
        if ok.is_none() {
            tracing::warn!(
                property = prop.name,
                from = origin,
                value = v,
                accepted = prop.accepted,
                "bad value for a debug property; ignored"
            );
        }
    }

    /// `over`'s properties where it sets them, else these.
    pub fn overlaid(self, over: DebugProperties) -> DebugProperties {
        DebugProperties {
            level: over.level.or(self.level),
            dynamic: over.dynamic.or(self.dynamic),
            subsampled: over.subsampled.or(self.subsampled),
            vertical_offset_deg: over.vertical_offset_deg.or(self.vertical_offset_deg),
            max_fragment: over.max_fragment.or(self.max_fragment),
        }
    }
}

fn bool01(v: &str) -> Option<bool> {
    match v.trim() {
        "0" => Some(false),
        "1" => Some(true),
        _ => None,
    }
}

/// How often, in display time, the property file's modification stamp is checked.
pub const PROPS_POLL_NS: i64 = 250_000_000;

/// The overrides of a running instance: the configuration file's sections for the application,
/// overlaid by the environment's debug properties, overlaid by the `FOVEA_PROPS` file's. Both files
/// are re-read when their modification time or size changes, so a change takes effect without
/// restarting the app (the desktop counterpart of `adb shell setprop`).
#[derive(Debug)]
pub struct Overrides {
    env: DebugProperties,
    file: Option<PathBuf>,
    config: Option<(PathBuf, fovea_config::Identity)>,
    state: Mutex<FileState>,
    next_poll_ns: AtomicI64,
}

/// A file's modification time and size: what tells a re-read is due.
type Stamp = Option<(SystemTime, u64)>;

#[derive(Debug, Default)]
struct FileState {
    /// `None` until first read.
    stamp: Option<Stamp>,
    from_props: DebugProperties,
    config_stamp: Option<Stamp>,
    from_config: DebugProperties,
    current: DebugProperties,
}

fn stamp_of(path: &Path) -> Stamp {
    std::fs::metadata(path)
        .ok()
        .map(|m| (m.modified().unwrap_or(SystemTime::UNIX_EPOCH), m.len()))
}

impl Overrides {
    /// For the application `id`: the environment, `FOVEA_PROPS` and the configuration file.
    pub fn from_env(config: Option<PathBuf>, id: fovea_config::Identity) -> Overrides {
        let get = |k: &str| std::env::var(k).ok();
        Overrides::with_config(
            DebugProperties::from_lookup(get),
            std::env::var_os(PROPS_ENV).map(PathBuf::from),
            config.map(|c| (c, id)),
        )
    }

    #[cfg(test)]
    pub fn new(env: DebugProperties, file: Option<PathBuf>) -> Overrides {
        Overrides::with_config(env, file, None)
    }

    /// With a configuration file and the application its sections are matched against.
    pub fn with_config(
        env: DebugProperties,
        file: Option<PathBuf>,
        config: Option<(PathBuf, fovea_config::Identity)>,
    ) -> Overrides {
        let o = Overrides {
            env,
            file,
            config,
            state: Mutex::ranked(
                Rank::Settings,
                "debug properties",
                FileState {
                    current: env,
                    ..FileState::default()
                },
            ),
            next_poll_ns: AtomicI64::new(0),
        };
        o.reload();
        o
    }

    /// The properties in force now.
    pub fn current(&self) -> DebugProperties {
        self.state.lock().current
    }

    /// Checks the file at most every [`PROPS_POLL_NS`] of display time; returns whether the
    /// properties changed. A `stat` when due, a read only when the file changed: no allocation
    /// otherwise.
    pub fn poll(&self, display_ns: i64) -> bool {
        // Lock-free on the frames in between: this runs in every xrEndFrame.
        if (self.file.is_none() && self.config.is_none())
            || display_ns < self.next_poll_ns.load(Ordering::Relaxed)
        {
            return false;
        }
        self.next_poll_ns
            .store(display_ns.saturating_add(PROPS_POLL_NS), Ordering::Relaxed);
        self.reload()
    }

    fn reload(&self) -> bool {
        let props_stamp = self.file.as_deref().map(stamp_of);
        let config_stamp = self.config.as_ref().map(|(p, _)| stamp_of(p));
        let mut s = self.state.lock();
        let mut read = false;
        if let (Some(path), Some(stamp)) = (&self.file, props_stamp) {
            if Some(stamp) != s.stamp {
                s.stamp = Some(stamp);
                s.from_props = match stamp.and_then(|_| std::fs::read_to_string(path).ok()) {
                    Some(text) => DebugProperties::parse(&text, &path.display().to_string()),
                    None => DebugProperties::default(),
                };
                read = true;
            }
        }
        if let (Some((path, id)), Some(stamp)) = (&self.config, config_stamp) {
            if Some(stamp) != s.config_stamp {
                s.config_stamp = Some(stamp);
                s.from_config = match stamp.and_then(|_| fovea_config::Config::load(path).ok()) {
                    Some(c) => {
                        warn_problems(&c);
                        DebugProperties::from_config(&c, id)
                    }
                    None => DebugProperties::default(),
                };
                read = true;
            }
        }
        if !read {
            return false;
        }
        let next = s.from_config.overlaid(self.env).overlaid(s.from_props);
        let changed = next != s.current;
        if changed {
            tracing::info!(properties = ?next, "overrides changed");
        }
        s.current = next;
        changed
    }
}

/// One warning per problem of a configuration file, each naming the file, line, key and the
/// accepted values.
pub fn warn_problems(c: &fovea_config::Config) {
    for p in &c.problems {
        tracing::warn!("configuration: {p}");
    }
}

/// Settings fixed for an instance's life, read when it is created.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Settings {
    pub symmetric_fov: bool,
    /// `inject` (or `FOVEA_INJECT`): foveate an application that never asks, by adding
    /// shading-rate attachments to its eye passes (docs/injection.md).
    pub inject: bool,
    /// `inject_level` (or `FOVEA_INJECT_LEVEL`): the level injection uses before Quest's debug
    /// properties apply on top; [`DEFAULT_INJECT_LEVEL`] when not given.
    pub inject_level: Option<Level>,
    /// `subsampled` (or `FOVEA_SUBSAMPLED`): reconstruct the coarse blocks of foveated swapchains
    /// (`Some(true)`) or not (`Some(false)`) whatever the application asks; `None`: as it asks,
    /// and on for injected swapchains (docs/openxr-layer.md#subsampled-images). Quest's
    /// `debug.oculus.foveation.subsampled` wins over it.
    pub subsampled: Option<bool>,
    /// The `log` filter from the file (`FOVEA_LOG` wins; the log is set up before the instance).
    pub log: Option<String>,
    /// The `log_file` from the file or `FOVEA_LOG_FILE`: `Some("")` turns the file off; `None`
    /// keeps the default.
    pub log_file: Option<String>,
    /// Who is running, as the file's sections are matched.
    pub identity: fovea_config::Identity,
    /// The configuration file, when there is one to watch.
    pub config: Option<PathBuf>,
    /// `eye_tracked_y_up` (or `FOVEA_EYE_TRACKED_Y_UP`): XR_META_foveation_eye_tracked's centres
    /// with y up instead of y down (docs/eye-tracking.md#xr_meta_foveation_eye_tracked).
    pub eye_tracked_y_up: bool,
    /// The gaze source (docs/eye-tracking.md#settings).
    pub gaze: GazeSettings,
}

/// What the gaze source does (`gaze`, `gaze_*` in `fovea.toml` or `FOVEA_GAZE*`:
/// docs/eye-tracking.md#settings), read when the instance is created.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GazeSettings {
    /// Use the runtime's eye gaze at all.
    pub on: bool,
    /// The filter, the hold and the fixation distance.
    pub params: GazeParams,
    /// Seconds of display time after the session's first frame before fovea attaches its set alone
    /// in a session whose application has not attached any; `None`: never.
    pub attach_after_s: Option<f32>,
}

impl GazeSettings {
    /// From the resolved keys: each one set replaces its default.
    fn from_resolved(r: &fovea_config::Resolved) -> GazeSettings {
        use fovea_config::Key;
        let d = GazeSettings::default();
        let n = |k: Key, default: f32| r.number(k).unwrap_or(default);
        GazeSettings {
            on: r.flag_or_default(Key::Gaze),
            params: GazeParams {
                min_cutoff_hz: n(Key::GazeMinCutoff, d.params.min_cutoff_hz),
                beta: n(Key::GazeBeta, d.params.beta),
                d_cutoff_hz: n(Key::GazeDCutoff, d.params.d_cutoff_hz),
                saccade_deg: n(Key::GazeSaccade, d.params.saccade_deg),
                hold_s: n(Key::GazeHold, d.params.hold_s),
                return_s: n(Key::GazeReturn, d.params.return_s),
                fixation_m: n(Key::GazeFixation, d.params.fixation_m),
            },
            attach_after_s: match r.get(Key::GazeAttachAfter) {
                Some(fovea_config::Value::Never) => None,
                Some(fovea_config::Value::Number(s)) => Some(*s),
                _ => d.attach_after_s,
            },
        }
    }
}

impl Default for GazeSettings {
    fn default() -> GazeSettings {
        GazeSettings {
            on: fovea_config::Key::Gaze.default_flag(),
            params: GazeParams::default(),
            attach_after_s: fovea_config::DEFAULT_GAZE_ATTACH_AFTER_S,
        }
    }
}

/// The level injection uses when `inject` is on and `inject_level` is not given (the table of keys'
/// default, [`fovea_config::DEFAULT_INJECT_LEVEL`]).
pub const DEFAULT_INJECT_LEVEL: Level = fovea_config::DEFAULT_INJECT_LEVEL;

/// Whether an instance's eye passes get injected shading rates (docs/injection.md#switching-it-on).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Injection {
    /// `inject` is off.
    Off,
    /// On, at this level (before the debug properties and the dynamic controller apply). An
    /// application that uses the FB foveation API gets it too: whether it foveates a swapchain
    /// itself is told per swapchain, by its density images (docs/injection.md#switching-it-on).
    On(Level),
}

impl Settings {
    /// Whether `inject` is on, and at which level.
    pub fn injection(&self) -> Injection {
        if self.inject {
            Injection::On(self.inject_level.unwrap_or(DEFAULT_INJECT_LEVEL))
        } else {
            Injection::Off
        }
    }

    /// For the application `id`: the environment over the configuration file's matching sections.
    pub fn from_env(id: fovea_config::Identity) -> Settings {
        let config = fovea_config::config_path(fovea_config::process_env);
        let file = config
            .as_deref()
            .and_then(|p| fovea_config::Config::load(p).ok());
        let mut s = Settings::resolve(file.as_ref(), &id, |k| std::env::var(k).ok());
        s.identity = id;
        s.config = config;
        s
    }

    /// From any key-value source, so tests need not touch the process environment.
    #[cfg(test)]
    pub fn from_lookup(get: impl Fn(&str) -> Option<String>) -> Settings {
        Settings::resolve(None, &fovea_config::Identity::default(), get)
    }

    fn resolve(
        file: Option<&fovea_config::Config>,
        id: &fovea_config::Identity,
        get: impl Fn(&str) -> Option<String>,
    ) -> Settings {
        use fovea_config::Key;
        // The symmetric-FOV switch keeps its own warning; the file's problems are warned about
        // once, by [`Overrides`].
        let env_symmetric = get(SYMMETRIC_FOV_ENV);
        let (r, _) = fovea_config::resolve(file, id, |k| {
            (k != SYMMETRIC_FOV_ENV && k != MAX_FRAGMENT_ENV)
                .then(|| get(k))
                .flatten()
        });
        let symmetric_fov = match env_symmetric {
            Some(v) => flag(Some(&v), SYMMETRIC_FOV_ENV),
            None => r.flag_or_default(Key::SymmetricFov),
        };
        Settings {
            symmetric_fov,
            inject: r.flag_or_default(Key::Inject),
            inject_level: r.level(Key::InjectLevel),
            subsampled: r.flag(Key::Subsampled),
            log: r.text(Key::Log).map(String::from),
            log_file: r.text(Key::LogFile).map(String::from),
            identity: id.clone(),
            config: None,
            eye_tracked_y_up: r.flag_or_default(Key::EyeTrackedYUp),
            gaze: GazeSettings::from_resolved(&r),
        }
    }
}

/// A 0/1 switch; anything else gets one warning naming the variable and is treated as off.
fn flag(v: Option<&str>, name: &str) -> bool {
    match v.map(str::trim) {
        None | Some("") | Some("0") => false,
        Some("1") => true,
        Some(other) => {
            tracing::warn!(
                variable = name,
                value = other,
                "accepted values are 0 and 1; ignored"
            );
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symmetric_fov_switch() {
        let s = |v: Option<&str>| {
            Settings::from_lookup(|k| {
                (k == SYMMETRIC_FOV_ENV)
                    .then_some(v)
                    .flatten()
                    .map(String::from)
            })
        };
        assert!(s(Some("1")).symmetric_fov);
        assert!(!s(Some("0")).symmetric_fov);
        assert!(!s(Some("yes")).symmetric_fov);
        assert!(!s(None).symmetric_fov);
    }

    #[test]
    fn gaze_settings_come_from_the_environment() {
        let s = |pairs: &'static [(&'static str, &'static str)]| {
            Settings::from_lookup(move |k| pairs.iter().find(|p| p.0 == k).map(|p| p.1.to_string()))
                .gaze
        };
        assert_eq!(s(&[]), GazeSettings::default());
        assert!(s(&[]).on, "on by default");
        assert!(!s(&[("FOVEA_GAZE", "0")]).on);
        let g = s(&[
            ("FOVEA_GAZE_MIN_CUTOFF_HZ", "2.5"),
            ("FOVEA_GAZE_BETA", "0.2"),
            ("FOVEA_GAZE_D_CUTOFF_HZ", "0.5"),
            ("FOVEA_GAZE_SACCADE_DEG", "6"),
            ("FOVEA_GAZE_HOLD_S", "0.1"),
            ("FOVEA_GAZE_RETURN_S", "0"),
            ("FOVEA_GAZE_FIXATION_M", "2"),
            ("FOVEA_GAZE_ATTACH_AFTER_S", "never"),
        ]);
        assert_eq!(
            g.params,
            GazeParams {
                min_cutoff_hz: 2.5,
                beta: 0.2,
                d_cutoff_hz: 0.5,
                saccade_deg: 6.0,
                hold_s: 0.1,
                return_s: 0.0,
                fixation_m: 2.0,
            }
        );
        assert_eq!(g.attach_after_s, None);
        assert_eq!(
            s(&[("FOVEA_GAZE_ATTACH_AFTER_S", "2")]).attach_after_s,
            Some(2.0)
        );
        let bad = s(&[
            ("FOVEA_GAZE_MIN_CUTOFF_HZ", "0"),
            ("FOVEA_GAZE_HOLD_S", "-1"),
        ]);
        assert_eq!(
            bad.params,
            GazeParams::default(),
            "out of range: the defaults"
        );
    }

    #[test]
    fn injection_is_off_by_default() {
        let s = |pairs: &'static [(&'static str, &'static str)]| {
            Settings::from_lookup(move |k| pairs.iter().find(|p| p.0 == k).map(|p| p.1.to_string()))
        };
        assert_eq!(s(&[]).injection(), Injection::Off);
        assert_eq!(
            s(&[("FOVEA_INJECT_LEVEL", "3")]).injection(),
            Injection::Off,
            "a level alone does not switch it on"
        );
        let on = s(&[("FOVEA_INJECT", "1")]);
        assert_eq!(on.injection(), Injection::On(DEFAULT_INJECT_LEVEL));
        let high = s(&[("FOVEA_INJECT", "1"), ("FOVEA_INJECT_LEVEL", "high")]);
        assert_eq!(high.injection(), Injection::On(Level::High));
        assert_eq!(
            s(&[("FOVEA_INJECT", "0"), ("FOVEA_INJECT_LEVEL", "2")]).injection(),
            Injection::Off
        );
    }

    /// `subsampled` is per application, like `inject`: unset by default, `on`/`off` from the
    /// matching section, `FOVEA_SUBSAMPLED` above the file.
    #[test]
    fn subsampled_comes_from_the_apps_section_and_the_environment() {
        let file = fovea_config::Config::parse(
            "subsampled = \"off\"\n[app.\"game\"]\nsubsampled = \"on\"\n",
            std::path::Path::new("fovea.toml"),
        );
        assert!(file.problems.is_empty(), "{:?}", file.problems);
        let id = |app: &str| fovea_config::Identity {
            app: Some(app.into()),
            ..Default::default()
        };
        assert_eq!(Settings::from_lookup(|_| None).subsampled, None);
        let game = Settings::resolve(Some(&file), &id("game"), |_| None);
        assert_eq!(game.subsampled, Some(true));
        let other = Settings::resolve(Some(&file), &id("other"), |_| None);
        assert_eq!(other.subsampled, Some(false));
        let env_wins = Settings::resolve(Some(&file), &id("game"), |k| {
            (k == "FOVEA_SUBSAMPLED").then(|| "0".to_string())
        });
        assert_eq!(env_wins.subsampled, Some(false));
    }

    #[test]
    fn injection_comes_from_the_apps_section_of_the_file() {
        let file = fovea_config::Config::parse(
            "inject = false\n[app.\"game\"]\ninject = true\ninject_level = \"low\"\n",
            std::path::Path::new("fovea.toml"),
        );
        let id = |app: &str| fovea_config::Identity {
            app: Some(app.into()),
            ..Default::default()
        };
        let game = Settings::resolve(Some(&file), &id("game"), |_| None);
        assert_eq!(game.injection(), Injection::On(Level::Low));
        let other = Settings::resolve(Some(&file), &id("other"), |_| None);
        assert_eq!(other.injection(), Injection::Off);
        let env_wins = Settings::resolve(Some(&file), &id("game"), |k| {
            (k == "FOVEA_INJECT_LEVEL").then(|| "4".to_string())
        });
        assert_eq!(env_wins.injection(), Injection::On(Level::HighTop));
    }

    #[test]
    fn subsampled_is_per_app_unset_by_default_and_the_variable_wins() {
        let file = fovea_config::Config::parse(
            "[app.\"game\"]\nsubsampled = \"off\"\n[app.\"other\"]\nsubsampled = \"maybe\"\n",
            std::path::Path::new("fovea.toml"),
        );
        let id = |app: &str| fovea_config::Identity {
            app: Some(app.into()),
            ..Default::default()
        };
        let no_env = |_: &str| None;
        assert_eq!(
            Settings::resolve(Some(&file), &id("game"), no_env).subsampled,
            Some(false)
        );
        assert_eq!(
            Settings::resolve(Some(&file), &id("other"), no_env).subsampled,
            None,
            "a bad value is dropped"
        );
        assert_eq!(
            Settings::resolve(None, &id("game"), no_env).subsampled,
            None
        );
        let on = |k: &str| (k == "FOVEA_SUBSAMPLED").then(|| "on".to_string());
        assert_eq!(
            Settings::resolve(Some(&file), &id("game"), on).subsampled,
            Some(true)
        );
    }

    #[test]
    fn debug_properties_from_env_and_file_with_quest_names() {
        let env = |pairs: &'static [(&'static str, &'static str)]| {
            DebugProperties::from_lookup(move |k| {
                pairs.iter().find(|p| p.0 == k).map(|p| p.1.to_string())
            })
        };
        let e = env(&[
            ("DEBUG_OCULUS_FOVEATION_LEVEL", "4"),
            ("DEBUG_OCULUS_FOVEATION_DYNAMIC", "1"),
        ]);
        assert_eq!(e.level, Some(Level::HighTop));
        assert_eq!(e.dynamic, Some(true));
        assert_eq!(e.subsampled, None);
        let bad = env(&[
            ("DEBUG_OCULUS_FOVEATION_LEVEL", "5"),
            ("DEBUG_OCULUS_FOVEATION_SUBSAMPLED", "yes"),
        ]);
        assert_eq!(bad, DebugProperties::default(), "bad values are ignored");
        let f = DebugProperties::parse(
            "# comment\n debug.oculus.foveation.level = 2\ndebug.oculus.foveation.subsampled=0\n\
             debug.oculus.foveation.level=x\nother=1\n",
            "test",
        );
        assert_eq!(
            f.level,
            Some(Level::Medium),
            "a bad later line keeps the earlier value"
        );
        assert_eq!(f.subsampled, Some(false));
        let merged = e.overlaid(f);
        assert_eq!(merged.level, Some(Level::Medium), "the file wins");
        assert_eq!(merged.dynamic, Some(true), "the environment fills in");
    }

    #[test]
    fn the_property_file_is_reread_when_it_changes() {
        let path = std::env::temp_dir().join(format!("fovea-props-{}", std::process::id()));
        std::fs::write(&path, "debug.oculus.foveation.level=1\n").unwrap();
        let o = Overrides::new(DebugProperties::default(), Some(path.clone()));
        assert_eq!(o.current().level, Some(Level::Low));
        assert!(!o.poll(0), "unchanged");
        std::fs::write(
            &path,
            "debug.oculus.foveation.level=3\ndebug.oculus.foveation.dynamic=1\n",
        )
        .unwrap();
        assert!(!o.poll(PROPS_POLL_NS / 2), "not due yet");
        assert!(o.poll(PROPS_POLL_NS), "due: the new size is seen");
        assert_eq!(o.current().level, Some(Level::High));
        assert_eq!(o.current().dynamic, Some(true));
        std::fs::remove_file(&path).unwrap();
        assert!(
            o.poll(2 * PROPS_POLL_NS),
            "a removed file drops its properties"
        );
        assert_eq!(o.current(), DebugProperties::default());
    }
}
