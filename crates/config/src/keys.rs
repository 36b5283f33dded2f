//! The one table of settings: each key of `fovea.toml` declared once, with its environment
//! variable, what it accepts, its default and its doc line. Parsing ([`crate::Config::parse`],
//! [`crate::resolve`]), `fovea config`'s report, the layer's defaults and the table in
//! docs/settings.md (checked against [`markdown_table`] by this crate's tests) all come from here.
//!
//! Adding a key is one row of [`keys!`] below, the field that reads it (src/common/settings.rs) and
//! the row the docs test prints for docs/settings.md; a variable the layer reads also goes into
//! include/fovea.h, whose test lists every variable in the sources.

use fovea_model::density::{Level, MAX_VERTICAL_OFFSET_DEG};
use fovea_model::gaze::GazeParams;

use crate::{env, Value};

/// The largest fragment a map may ask for when nothing says otherwise: 4×4, as fovea always did.
pub const DEFAULT_MAX_FRAGMENT: u32 = 4;

/// The level injection uses when `inject` is on and `inject_level` is not given: medium, a level
/// whose full-rate centre covers what the eye resolves sharply (docs/density-model.md#floors), so
/// switching injection on alone changes something visible without being drastic.
pub const DEFAULT_INJECT_LEVEL: Level = Level::Medium;

/// Seconds of display time before fovea attaches its own eye gaze action set in a session whose
/// application attached none (`gaze_attach_after_s`; docs/eye-tracking.md#applications-that-do-not-cooperate):
/// never by default. A session's sets attach once, so an attach of fovea's alone makes every later
/// attach of the application fail (`XR_ERROR_ACTIONSETS_ALREADY_ATTACHED`); an application that sets
/// up its input after a long loading screen must not pay for an opt-in it never made.
pub const DEFAULT_GAZE_ATTACH_AFTER_S: Option<f32> = None;

/// The log filter when neither `FOVEA_LOG` nor `log` gives one: warnings.
pub const DEFAULT_LOG: &str = "warn";

/// How a key's value is read.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    /// A level name or its index, 0-4.
    Level,
    /// `true`/`false`, `"on"`/`"off"`, `1`/`0`.
    Switch,
    /// Degrees, at most `max` either way.
    Degrees { max: f32 },
    /// A fragment size: 1, 2 or 4.
    Fragment,
    /// A number from `low` to `high` (`low` itself refused where `open`); where `never`, also the
    /// word `"never"`.
    Number {
        low: f32,
        high: f32,
        open: bool,
        never: bool,
    },
    /// Any string.
    Text,
}

/// What applies when nothing sets a key.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Fallback {
    /// No value of fovea's: what applies instead, in words.
    Unset(&'static str),
    Level(Level),
    Switch(bool),
    Fragment(u32),
    Number(f32),
    /// `"never"`.
    Never,
    Text(&'static str),
    /// The default log file, which depends on `XDG_STATE_HOME` and `HOME`
    /// ([`crate::default_log_path`]).
    LogPath,
}

impl Fallback {
    /// The default as a value, where it is one.
    pub fn value(self) -> Option<Value> {
        Some(match self {
            Fallback::Level(l) => Value::Level(l),
            Fallback::Switch(b) => Value::Bool(b),
            Fallback::Fragment(n) => Value::Fragment(n),
            Fallback::Number(n) => Value::Number(n),
            Fallback::Never => Value::Never,
            Fallback::Text(t) => Value::Text(t.to_owned()),
            Fallback::Unset(_) | Fallback::LogPath => return None,
        })
    }

    /// The default as `fovea config` and docs/settings.md write it.
    pub fn text(self) -> String {
        match (self, self.value()) {
            (Fallback::Unset(words), _) => words.to_owned(),
            (Fallback::LogPath, _) => "`$XDG_STATE_HOME/fovea/fovea.log`".to_owned(),
            (_, Some(v)) => v.to_string(),
            (_, None) => unreachable!("every other default is a value"),
        }
    }
}

/// One row of the table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spec {
    pub key: Key,
    /// The key as written in the file.
    pub name: &'static str,
    /// The environment variable that wins over the file, if any.
    pub env: Option<&'static str>,
    pub kind: Kind,
    /// What the key accepts, for problem lines and the docs.
    pub accepted: &'static str,
    pub default: Fallback,
    /// What the key does: its doc comment, and its line in docs/settings.md (Markdown, links
    /// relative to `docs/`).
    pub doc: &'static str,
}

/// Declares the keys: the enum, [`Key::ALL`], [`KEYS`] and [`TABLE`] come from one list, so a key
/// cannot be missing from any of them.
macro_rules! keys {
    ($($variant:ident {
        name: $name:literal,
        env: $env:expr,
        kind: $kind:expr,
        accepted: $accepted:expr,
        default: $default:expr,
        doc: $doc:literal $(,)?
    }),* $(,)?) => {
        /// The file's keys.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum Key {
            $(#[doc = $doc] $variant,)*
        }

        /// How many keys there are.
        pub const KEYS: usize = [$(Key::$variant),*].len();

        /// Every key's row, in [`Key`] order.
        pub const TABLE: [Spec; KEYS] = [$(Spec {
            key: Key::$variant,
            name: $name,
            env: $env,
            kind: $kind,
            accepted: $accepted,
            default: $default,
            doc: $doc,
        }),*];

        impl Key {
            pub const ALL: [Key; KEYS] = [$(Key::$variant),*];
        }
    };
}

const SWITCH: &str = "true or false (also \"on\"/\"off\", 1/0)";

keys! {
    Level {
        name: "level",
        env: Some(env::LEVEL),
        kind: Kind::Level,
        accepted: "\"none\", \"low\", \"medium\", \"high\", \"high-top\" or 0-4",
        default: Fallback::Unset("the application's profile"),
        doc: "the level of every foveated swapchain, as Quest's `debug.oculus.foveation.level` (the maximum when dynamic)",
    },
    Dynamic {
        name: "dynamic",
        env: Some(env::DYNAMIC),
        kind: Kind::Switch,
        accepted: SWITCH,
        default: Fallback::Unset("the application's profile"),
        doc: "dynamic foveation on or off",
    },
    VerticalOffset {
        name: "vertical_offset",
        env: None,
        kind: Kind::Degrees { max: MAX_VERTICAL_OFFSET_DEG },
        accepted: "degrees from -55 to 55, e.g. -5.5",
        default: Fallback::Unset("the application's profile"),
        doc: "where the fovea sits, positive up (the profile's `verticalOffset`)",
    },
    SymmetricFov {
        name: "symmetric_fov",
        env: Some(env::SYMMETRIC_FOV),
        kind: Kind::Switch,
        accepted: SWITCH,
        default: Fallback::Switch(false),
        doc: "one shared symmetric FOV for both eyes from `xrLocateViews`, recommended sizes enlarged to match, pixels outside each eye's own FOV at the lowest density (Quest's recommended mode); its variable takes `0` or `1` only",
    },
    MaxFragment {
        name: "max_fragment",
        env: Some(env::MAX_FRAGMENT),
        kind: Kind::Fragment,
        accepted: "1, 2 or 4",
        default: Fallback::Fragment(DEFAULT_MAX_FRAGMENT),
        doc: "the largest fragment any map asks for, pixels per axis: `2` is Quest 3's own palette (full rate and 2×2), `1` turns foveation off ([below](#what-each-level-shades-under-each-max_fragment))",
    },
    Inject {
        name: "inject",
        env: Some(env::INJECT),
        kind: Kind::Switch,
        accepted: SWITCH,
        default: Fallback::Switch(false),
        doc: "injection: foveate an app that never asks by adding shading rates to its eye passes ([injection.md](injection.md)); never into swapchains with density images of the app's own (an app that enables `XR_FB_foveation` and applies a profile to a swapchain without them gets injection at that profile's level, on or off: [injection.md](injection.md#applications-that-apply-profiles)), nor into passes that name a shading-rate attachment of the app's own (an app that sets rates per pipeline or per draw is injected into, its rates combined with the maps by `MAX`). Eye passes (dynamic rendering, render passes) get fovea's shading-rate maps; other passes render at full rate",
    },
    InjectLevel {
        name: "inject_level",
        env: Some(env::INJECT_LEVEL),
        kind: Kind::Level,
        accepted: "\"none\", \"low\", \"medium\", \"high\", \"high-top\" or 0-4",
        default: Fallback::Level(DEFAULT_INJECT_LEVEL),
        doc: "the injected level; Quest's debug properties apply on top (level replaced, the maximum when dynamic)",
    },
    Log {
        name: "log",
        env: Some(env::LOG),
        kind: Kind::Text,
        accepted: "a tracing filter string, e.g. \"info\" or \"warn,fovea::stats=info\"",
        default: Fallback::Text(DEFAULT_LOG),
        doc: "what the layer logs ([the log](#the-log))",
    },
    LogFile {
        name: "log_file",
        env: Some(env::LOG_FILE),
        kind: Kind::Text,
        accepted: "a path in a string, \"\" for no log file",
        default: Fallback::LogPath,
        doc: "the log file ([the log](#the-log))",
    },
    Gaze {
        name: "gaze",
        env: Some(env::GAZE),
        kind: Kind::Switch,
        accepted: SWITCH,
        default: Fallback::Switch(true),
        doc: "the fovea follows the eyes where the runtime has eye gaze (`XR_EXT_eye_gaze_interaction` and a tracker) and something in the app uses it (`XR_META_foveation_eye_tracked`, injection; elsewhere fovea touches no eye gaze at all); off leaves fixed foveation and enables nothing ([eye-tracking.md](eye-tracking.md#who-uses-the-gaze))",
    },
    GazeMinCutoff {
        name: "gaze_min_cutoff_hz",
        env: Some(env::GAZE_MIN_CUTOFF_HZ),
        kind: Kind::Number { low: 0.0, high: 100.0, open: true, never: false },
        accepted: "hertz above 0, at most 100, e.g. 1.0",
        default: Fallback::Number(GazeParams::DEFAULT.min_cutoff_hz),
        doc: "the gaze filter's cutoff at rest ([eye-tracking.md](eye-tracking.md#settings))",
    },
    GazeBeta {
        name: "gaze_beta",
        env: Some(env::GAZE_BETA),
        kind: Kind::Number { low: 0.0, high: 10.0, open: false, never: false },
        accepted: "a number from 0 to 10, e.g. 0.1",
        default: Fallback::Number(GazeParams::DEFAULT.beta),
        doc: "how fast the filter's cutoff rises with the gaze's speed",
    },
    GazeDCutoff {
        name: "gaze_d_cutoff_hz",
        env: Some(env::GAZE_D_CUTOFF_HZ),
        kind: Kind::Number { low: 0.0, high: 100.0, open: true, never: false },
        accepted: "hertz above 0, at most 100, e.g. 1.0",
        default: Fallback::Number(GazeParams::DEFAULT.d_cutoff_hz),
        doc: "the cutoff of the filter's speed estimate",
    },
    GazeSaccade {
        name: "gaze_saccade_deg",
        env: Some(env::GAZE_SACCADE_DEG),
        kind: Kind::Number { low: 0.0, high: 90.0, open: true, never: false },
        accepted: "degrees above 0, at most 90, e.g. 4.5",
        default: Fallback::Number(GazeParams::DEFAULT.saccade_deg),
        doc: "a jump of at least this many degrees is a saccade, taken as it is",
    },
    GazeHold {
        name: "gaze_hold_s",
        env: Some(env::GAZE_HOLD_S),
        kind: Kind::Number { low: 0.0, high: 10.0, open: false, never: false },
        accepted: "seconds from 0 to 10, e.g. 0.3",
        default: Fallback::Number(GazeParams::DEFAULT.hold_s),
        doc: "how long the last good gaze is held while the gaze is invalid (a blink)",
    },
    GazeReturn {
        name: "gaze_return_s",
        env: Some(env::GAZE_RETURN_S),
        kind: Kind::Number { low: 0.0, high: 10.0, open: false, never: false },
        accepted: "seconds from 0 to 10, e.g. 0.3",
        default: Fallback::Number(GazeParams::DEFAULT.return_s),
        doc: "how long the fovea then eases back to fixed foveation",
    },
    GazeFixation {
        name: "gaze_fixation_m",
        env: Some(env::GAZE_FIXATION_M),
        kind: Kind::Number { low: 0.1, high: 100.0, open: false, never: false },
        accepted: "metres from 0.1 to 100, e.g. 1.0",
        default: Fallback::Number(GazeParams::DEFAULT.fixation_m),
        doc: "the distance of the fixation plane the gaze ray meets",
    },
    GazeAttachAfter {
        name: "gaze_attach_after_s",
        env: Some(env::GAZE_ATTACH_AFTER_S),
        kind: Kind::Number { low: 0.0, high: 3600.0, open: false, never: true },
        accepted: "seconds from 0 to 3600, or \"never\"",
        default: match DEFAULT_GAZE_ATTACH_AFTER_S {
            Some(s) => Fallback::Number(s),
            None => Fallback::Never,
        },
        doc: "an opt-in for apps that never attach an action set: fovea attaches its gaze action set alone in a session whose app has attached none after this much display time; an app that attaches later then fails to ([eye-tracking.md](eye-tracking.md#applications-that-do-not-cooperate))",
    },
    // XR_META_foveation_eye_tracked.
    EyeTrackedYUp {
        name: "eye_tracked_y_up",
        env: Some(env::EYE_TRACKED_Y_UP),
        kind: Kind::Switch,
        accepted: SWITCH,
        default: Fallback::Switch(false),
        doc: "the direction of y in the centres `xrGetFoveationEyeTrackedStateMETA` returns: off is y down, as Quest's runtime answers and Godot reads; on is y up, OpenXR's NDC, for an app that reads them that way ([eye-tracking.md](eye-tracking.md#xr_meta_foveation_eye_tracked))",
    },
    Subsampled {
        name: "subsampled",
        env: Some(env::SUBSAMPLED),
        kind: Kind::Switch,
        accepted: SWITCH,
        default: Fallback::Unset("as the application asks; on for injected passes"),
        doc: "force the reconstruction of coarse blocks on or off for this application: on, they are smoothed as a subsampled image sampled bilinearly shows them (what an app asks for with `VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT`), and the swapchain is created with transfer usage added; off, the blocks stay. Below Quest's `debug.oculus.foveation.subsampled`; a swapchain nobody foveates is never touched ([openxr-layer.md](openxr-layer.md#subsampled-images))",
    },
}

impl Key {
    /// The key's row.
    pub fn spec(self) -> &'static Spec {
        &TABLE[self as usize]
    }

    /// The key as written in the file.
    pub fn name(self) -> &'static str {
        self.spec().name
    }

    /// The range a numeric key accepts (inclusive; a lower bound of 0 for the cutoffs and the
    /// saccade threshold is exclusive).
    pub fn range(self) -> Option<(f32, f32)> {
        match self.spec().kind {
            Kind::Number { low, high, .. } => Some((low, high)),
            _ => None,
        }
    }

    /// What the key accepts, for problem lines.
    pub fn accepted(self) -> &'static str {
        self.spec().accepted
    }

    /// The environment variable that wins over the file, if any.
    pub fn env(self) -> Option<&'static str> {
        self.spec().env
    }

    /// What applies when nothing sets the key.
    pub fn default(self) -> Fallback {
        self.spec().default
    }

    /// A switch's default (off for a key whose default is no switch).
    pub fn default_flag(self) -> bool {
        matches!(self.default(), Fallback::Switch(true))
    }

    pub(crate) fn by_name(name: &str) -> Option<Key> {
        Key::ALL.into_iter().find(|k| k.name() == name)
    }
}

/// A scalar as the file or the environment wrote it.
pub(crate) enum Raw<'a> {
    Str(&'a str),
    Int(&'a str),
    Float(&'a str),
    Bool(bool),
    Other,
}

/// Parses a value for `key`; `None` when it is not one `key` accepts.
pub(crate) fn parse_value(key: Key, raw: Raw<'_>) -> Option<Value> {
    match key.spec().kind {
        Kind::Level => match raw {
            Raw::Str(s) | Raw::Int(s) => s.parse::<Level>().ok().map(Value::Level),
            _ => None,
        },
        Kind::Number { never: true, .. } if matches!(raw, Raw::Str(s) if s.trim().eq_ignore_ascii_case("never")) => {
            Some(Value::Never)
        }
        Kind::Number {
            low, high, open, ..
        } => match raw {
            Raw::Int(s) | Raw::Float(s) | Raw::Str(s) => s
                .trim()
                .replace('_', "")
                .parse::<f32>()
                .ok()
                .filter(|v| v.is_finite() && *v <= high && (*v > low || (!open && *v == low)))
                .map(Value::Number),
            _ => None,
        },
        Kind::Switch => match raw {
            Raw::Bool(b) => Some(Value::Bool(b)),
            Raw::Int("0") => Some(Value::Bool(false)),
            Raw::Int("1") => Some(Value::Bool(true)),
            Raw::Str(s) => match s.trim().to_ascii_lowercase().as_str() {
                "on" | "true" | "1" => Some(Value::Bool(true)),
                "off" | "false" | "0" => Some(Value::Bool(false)),
                _ => None,
            },
            _ => None,
        },
        Kind::Degrees { max } => match raw {
            Raw::Int(s) | Raw::Float(s) | Raw::Str(s) => s
                .trim()
                .replace('_', "")
                .parse::<f32>()
                .ok()
                .filter(|d| d.is_finite() && d.abs() <= max)
                .map(Value::Degrees),
            _ => None,
        },
        Kind::Fragment => match raw {
            Raw::Int(s) | Raw::Str(s) => match s.trim() {
                "1" => Some(Value::Fragment(1)),
                "2" => Some(Value::Fragment(2)),
                "4" => Some(Value::Fragment(4)),
                _ => None,
            },
            _ => None,
        },
        Kind::Text => match raw {
            Raw::Str(s) => Some(Value::Text(s.to_owned())),
            _ => None,
        },
    }
}

/// Parses an environment variable's value for `key` (text, as the file's strings).
pub fn parse_env(key: Key, text: &str) -> Option<Value> {
    parse_value(key, Raw::Str(text))
}

/// The table as docs/settings.md holds it: one row per key, in [`Key`] order.
pub fn markdown_table() -> String {
    let mut out =
        String::from("| key | variable | values | default | meaning |\n|---|---|---|---|---|\n");
    for s in &TABLE {
        let env = s
            .env
            .map_or_else(|| "none".to_owned(), |v| format!("`{v}`"));
        out.push_str(&format!(
            "| `{}` | {env} | {} | {} | {} |\n",
            s.name,
            s.accepted,
            s.default.text(),
            s.doc
        ));
    }
    out
}
