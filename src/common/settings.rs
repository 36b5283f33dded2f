//! Settings read from the environment.
//!
//! Every variable the layer reads is listed here (and in the README's settings table and
//! include/fovea.h), so there is one place to look.

use std::path::PathBuf;
use std::sync::atomic::{AtomicI64, Ordering};
use std::time::SystemTime;

use crate::common::lock::{Mutex, Rank};

use fovea_model::density::Level;

/// `FOVEA_SYMMETRIC_FOV=1`: report one shared symmetric FOV for both eyes (Quest's recommended mode,
/// docs/headsets.md#symmetric-fov) and give pixels outside each eye's true FOV the lowest density.
pub const SYMMETRIC_FOV_ENV: &str = "FOVEA_SYMMETRIC_FOV";

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

/// `FOVEA_PROPS`: a file of `debug.oculus.foveation.*=value` lines, re-read while the app runs.
pub const PROPS_ENV: &str = "FOVEA_PROPS";

/// The debug overrides in force. As on Quest: with dynamic on, the level is the maximum; with
/// dynamic off, it is the level; either applies to every foveated swapchain, above what the
/// application asked for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DebugProperties {
    pub level: Option<Level>,
    pub dynamic: Option<bool>,
    pub subsampled: Option<bool>,
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
        p
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

/// The debug properties of a running instance: the environment's, overlaid by the `FOVEA_PROPS`
/// file's, which is re-read when its modification time or size changes, so a property takes effect
/// without restarting the app (the desktop counterpart of `adb shell setprop`).
#[derive(Debug)]
pub struct Overrides {
    env: DebugProperties,
    file: Option<PathBuf>,
    state: Mutex<FileState>,
    next_poll_ns: AtomicI64,
}

#[derive(Debug, Default)]
struct FileState {
    stamp: Option<(SystemTime, u64)>,
    current: DebugProperties,
}

impl Overrides {
    pub fn from_env() -> Overrides {
        let get = |k: &str| std::env::var(k).ok();
        Overrides::new(
            DebugProperties::from_lookup(get),
            std::env::var_os(PROPS_ENV).map(PathBuf::from),
        )
    }

    pub fn new(env: DebugProperties, file: Option<PathBuf>) -> Overrides {
        let o = Overrides {
            env,
            file,
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
        if self.file.is_none() || display_ns < self.next_poll_ns.load(Ordering::Relaxed) {
            return false;
        }
        self.next_poll_ns
            .store(display_ns.saturating_add(PROPS_POLL_NS), Ordering::Relaxed);
        self.reload()
    }

    fn reload(&self) -> bool {
        let Some(path) = &self.file else {
            return false;
        };
        let stamp = std::fs::metadata(path)
            .ok()
            .map(|m| (m.modified().unwrap_or(SystemTime::UNIX_EPOCH), m.len()));
        let mut s = self.state.lock();
        if stamp == s.stamp {
            return false;
        }
        s.stamp = stamp;
        let from_file = match stamp.and_then(|_| std::fs::read_to_string(path).ok()) {
            Some(text) => DebugProperties::parse(&text, &path.display().to_string()),
            None => DebugProperties::default(),
        };
        let next = self.env.overlaid(from_file);
        let changed = next != s.current;
        if changed {
            tracing::info!(file = %path.display(), properties = ?next, "debug properties changed");
        }
        s.current = next;
        changed
    }
}

/// Settings fixed for an instance's life, read when it is created.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Settings {
    pub symmetric_fov: bool,
}

impl Settings {
    pub fn from_env() -> Settings {
        Settings::from_lookup(|k| std::env::var(k).ok())
    }

    /// From any key-value source, so tests need not touch the process environment.
    pub fn from_lookup(get: impl Fn(&str) -> Option<String>) -> Settings {
        Settings {
            symmetric_fov: flag(get(SYMMETRIC_FOV_ENV).as_deref(), SYMMETRIC_FOV_ENV),
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
