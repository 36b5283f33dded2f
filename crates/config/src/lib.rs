//! `fovea.toml`: fovea's configuration file, shared by the layer (read at `xrCreateInstance`, re-read
//! while the app runs) and the `fovea` tool (`fovea config`, `fovea doctor`).
//!
//! # The file
//!
//! `$XDG_CONFIG_HOME/fovea/fovea.toml` (default `~/.config/fovea/fovea.toml`), or the file
//! `FOVEA_CONFIG` names. Keys at the top level are the global section; tables name the applications
//! a section is for (docs/users.md#per-app-conventions):
//!
//! ```toml
//! level = "medium"            # global
//! [app."hello_xr"]            # XrApplicationInfo::applicationName, exactly
//! level = "high"
//! [exe."hello_xr"]            # the executable's file name (/proc/self/exe)
//! [engine."Unity"]            # XrApplicationInfo::engineName, exactly
//! ```
//!
//! Every section that matches applies, the most specific last: global, then engine, then exe,
//! then app. Above all of them come the environment and Quest's debug properties
//! ([`effective`]).
//!
//! # Errors
//!
//! A bad file never stops anything. Each problem is a [`Problem`] naming the file, the line, the key
//! and the accepted values; the bad line or value is dropped and the rest applies (a TOML syntax
//! error drops its line and the file is parsed again without it).
//!
//! Numbers are parsed by Rust's `str::parse`, which knows no locale: `0.5` is one half under
//! every `LC_NUMERIC`, and `0,5` is an error everywhere.
#![forbid(unsafe_code)]

use std::ffi::OsString;
use std::fmt;
use std::path::{Path, PathBuf};

use fovea_model::density::Level;
use toml::de::{DeTable, DeValue};

mod keys;
pub use keys::{
    markdown_table, parse_env, Fallback, Key, Kind, Spec, DEFAULT_GAZE_ATTACH_AFTER_S,
    DEFAULT_INJECT_LEVEL, DEFAULT_LOG, DEFAULT_MAX_FRAGMENT, KEYS, TABLE,
};
use keys::{parse_value, Raw};

/// Environment variables this crate reads.
pub mod env {
    pub use fovea_abi::env::EYE_TRACKED_Y_UP;
    pub use fovea_abi::env::{
        CONFIG, GAZE, GAZE_ATTACH_AFTER_S, GAZE_BETA, GAZE_D_CUTOFF_HZ, GAZE_FIXATION_M,
        GAZE_HOLD_S, GAZE_MIN_CUTOFF_HZ, GAZE_RETURN_S, GAZE_SACCADE_DEG, INJECT, INJECT_LEVEL,
        LOG, LOG_FILE, MAX_FRAGMENT, SUBSAMPLED, SYMMETRIC_FOV,
    };
    /// Quest's `debug.oculus.foveation.level` as a variable.
    pub const LEVEL: &str = "DEBUG_OCULUS_FOVEATION_LEVEL";
    /// Quest's `debug.oculus.foveation.dynamic` as a variable.
    pub const DYNAMIC: &str = "DEBUG_OCULUS_FOVEATION_DYNAMIC";
    /// Quest's `debug.oculus.foveation.subsampled` as a variable: not the `subsampled` key's own
    /// variable (`FOVEA_SUBSAMPLED`), but a debug override above it, as on Quest.
    pub const DEBUG_SUBSAMPLED: &str = "DEBUG_OCULUS_FOVEATION_SUBSAMPLED";
    /// The XDG base directory for configuration (default `~/.config`).
    pub const XDG_CONFIG_HOME: &str = "XDG_CONFIG_HOME";
    /// The XDG base directory for state such as logs (default `~/.local/state`).
    pub const XDG_STATE_HOME: &str = "XDG_STATE_HOME";
}

/// The log file is renamed to `fovea.log.1` (replacing the previous one) once it reaches this size.
pub const LOG_ROTATE_BYTES: u64 = 1 << 20;

/// A key's value.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Level(Level),
    Bool(bool),
    Degrees(f32),
    Fragment(u32),
    /// A gaze parameter, in the unit its key names.
    Number(f32),
    /// `gaze_attach_after_s = "never"`.
    Never,
    Text(String),
}

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Level(l) => f.write_str(l.name()),
            Value::Bool(b) => f.write_str(if *b { "on" } else { "off" }),
            Value::Degrees(d) => write!(f, "{d}°"),
            Value::Fragment(n) => write!(f, "{n}x{n}"),
            Value::Number(n) => write!(f, "{n}"),
            Value::Never => f.write_str("never"),
            Value::Text(t) => write!(f, "{t:?}"),
        }
    }
}

/// Which applications a section is for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Scope {
    Global,
    /// `[engine."NAME"]`: `XrApplicationInfo::engineName`.
    Engine(String),
    /// `[exe."NAME"]`: the executable's file name.
    Exe(String),
    /// `[app."NAME"]`: `XrApplicationInfo::applicationName`.
    App(String),
}

impl Scope {
    /// How the section is written: `global` or its table header.
    pub fn header(&self) -> String {
        match self {
            Scope::Global => "global".into(),
            Scope::Engine(n) => format!("[engine.{n:?}]"),
            Scope::Exe(n) => format!("[exe.{n:?}]"),
            Scope::App(n) => format!("[app.{n:?}]"),
        }
    }

    /// Higher wins.
    fn rank(&self) -> u8 {
        match self {
            Scope::Global => 0,
            Scope::Engine(_) => 1,
            Scope::Exe(_) => 2,
            Scope::App(_) => 3,
        }
    }

    fn matches(&self, id: &Identity) -> bool {
        let is = |want: &Option<String>, n: &String| want.as_deref() == Some(n.as_str());
        match self {
            Scope::Global => true,
            Scope::Engine(n) => is(&id.engine, n),
            Scope::Exe(n) => is(&id.exe, n),
            Scope::App(n) => is(&id.app, n),
        }
    }
}

/// Who is running: what a section is matched on.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Identity {
    /// `XrApplicationInfo::applicationName`.
    pub app: Option<String>,
    /// The executable's file name (`/proc/self/exe`).
    pub exe: Option<String>,
    /// `XrApplicationInfo::engineName`.
    pub engine: Option<String>,
}

impl Identity {
    /// This process's executable file name.
    pub fn current_exe() -> Option<String> {
        std::env::current_exe()
            .ok()?
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
    }
}

/// One key's value in a section and the line it is on (1-based).
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    pub key: Key,
    pub value: Value,
    pub line: usize,
}

/// A section of the file.
#[derive(Clone, Debug, PartialEq)]
pub struct Section {
    pub scope: Scope,
    /// The header's line (1 for the global section).
    pub line: usize,
    pub entries: Vec<Entry>,
}

impl Section {
    pub fn get(&self, key: Key) -> Option<&Entry> {
        self.entries.iter().rev().find(|e| e.key == key)
    }
}

/// Something wrong in the file: its line, the key, what is wrong and what is accepted.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Problem {
    pub file: String,
    pub line: usize,
    /// The key (or table) concerned, `-` for a syntax error.
    pub key: String,
    pub message: String,
    pub accepted: String,
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}:{}: {}: {}; accepted: {}; ignored, the rest of the file applies",
            self.file, self.line, self.key, self.message, self.accepted
        )
    }
}

/// A parsed file: its sections in file order, and its problems.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Config {
    pub path: PathBuf,
    pub sections: Vec<Section>,
    pub problems: Vec<Problem>,
}

/// Most syntax errors one parse recovers from (one line dropped each).
const MAX_SYNTAX_ERRORS: usize = 32;

const SECTION_KINDS: &str =
    "keys at the top level, [app.\"NAME\"], [exe.\"NAME\"] or [engine.\"NAME\"] tables";

impl Config {
    /// Reads the file at `path`. `Err` when it cannot be read (a missing file is `NotFound`).
    pub fn load(path: &Path) -> std::io::Result<Config> {
        let bytes = std::fs::read(path)?;
        let text = String::from_utf8_lossy(&bytes);
        Ok(Config::parse(&text, path))
    }

    /// Parses `text`, read from `path`.
    pub fn parse(text: &str, path: &Path) -> Config {
        let file = path.display().to_string();
        let mut out = Config {
            path: path.to_path_buf(),
            ..Config::default()
        };
        let mut text = text.to_owned();
        let table = loop {
            match DeTable::parse(&text) {
                Ok(t) => break Some(t.into_inner()),
                Err(e) if out.problems.len() < MAX_SYNTAX_ERRORS => {
                    let at = e.span().map_or(0, |s| s.start).min(text.len());
                    let line = line_of(&text, at);
                    out.problems.push(Problem {
                        file: file.clone(),
                        line,
                        key: "-".into(),
                        message: format!("not TOML: {}", e.message().trim()),
                        accepted: "TOML 1.0 (https://toml.io)".into(),
                    });
                    blank_line(&mut text, at);
                }
                Err(_) => break None,
            }
        };
        let Some(table) = table else {
            return out;
        };
        let mut global = Section {
            scope: Scope::Global,
            line: 1,
            entries: Vec::new(),
        };
        let problem = |line: usize, key: &str, message: String, accepted: &str| Problem {
            file: file.clone(),
            line,
            key: key.to_owned(),
            message,
            accepted: accepted.to_owned(),
        };
        let mut sections = Vec::new();
        let mut problems = Vec::new();
        for (k, v) in table.iter() {
            let name = k.get_ref().as_ref();
            let line = line_of(&text, k.span().start);
            match (name, v.get_ref()) {
                ("app" | "exe" | "engine", DeValue::Table(apps)) => {
                    for (app, body) in apps.iter() {
                        let app_name = app.get_ref().to_string();
                        let scope = match name {
                            "app" => Scope::App(app_name),
                            "exe" => Scope::Exe(app_name),
                            _ => Scope::Engine(app_name),
                        };
                        let line = line_of(&text, app.span().start);
                        let DeValue::Table(body) = body.get_ref() else {
                            problems.push(problem(
                                line,
                                &format!("{name}.{}", app.get_ref()),
                                "not a table".into(),
                                SECTION_KINDS,
                            ));
                            continue;
                        };
                        let mut section = Section {
                            scope,
                            line,
                            entries: Vec::new(),
                        };
                        for (k, v) in body.iter() {
                            read_entry(&text, k, v, &mut section, &mut problems, &problem);
                        }
                        sections.push(section);
                    }
                }
                (_, DeValue::Table(_)) => problems.push(problem(
                    line,
                    name,
                    "not a section fovea knows".into(),
                    SECTION_KINDS,
                )),
                _ => read_entry(&text, k, v, &mut global, &mut problems, &problem),
            }
        }
        problems.sort_by_key(|p| p.line);
        sections.sort_by_key(|s| s.line);
        global.entries.sort_by_key(|e| e.line);
        out.problems.extend(problems);
        out.problems.sort_by_key(|p| p.line);
        out.sections.push(global);
        out.sections.extend(sections);
        out
    }

    /// The sections that apply to `id`, least specific first (global, engine, exe, app; file order
    /// within a kind).
    pub fn matching(&self, id: &Identity) -> Vec<&Section> {
        let mut m: Vec<&Section> = self
            .sections
            .iter()
            .filter(|s| s.scope.matches(id))
            .collect();
        m.sort_by_key(|s| s.scope.rank());
        m
    }
}

type Spanned<T> = toml::Spanned<T>;

fn read_entry(
    text: &str,
    k: &Spanned<std::borrow::Cow<'_, str>>,
    v: &Spanned<DeValue<'_>>,
    section: &mut Section,
    problems: &mut Vec<Problem>,
    problem: &dyn Fn(usize, &str, String, &str) -> Problem,
) {
    let name = k.get_ref().as_ref();
    let line = line_of(text, k.span().start);
    let Some(key) = Key::by_name(name) else {
        let keys: Vec<&str> = Key::ALL.iter().map(|k| k.name()).collect();
        problems.push(problem(line, name, "unknown key".into(), &keys.join(", ")));
        return;
    };
    let raw = match v.get_ref() {
        DeValue::String(s) => Raw::Str(s.as_ref()),
        DeValue::Integer(i) => Raw::Int(i.as_str()),
        DeValue::Float(f) => Raw::Float(f.as_str()),
        DeValue::Boolean(b) => Raw::Bool(*b),
        _ => Raw::Other,
    };
    match parse_value(key, raw) {
        Some(value) => section.entries.push(Entry { key, value, line }),
        None => problems.push(problem(
            line,
            name,
            format!("bad value {}", text[v.span()].trim()),
            key.accepted(),
        )),
    }
}

/// 1-based line of byte `at`.
fn line_of(text: &str, at: usize) -> usize {
    text.as_bytes()[..at.min(text.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// Replaces the line holding byte `at` with spaces, so every other line keeps its number.
fn blank_line(text: &mut String, at: usize) {
    let start = text[..at].rfind('\n').map_or(0, |i| i + 1);
    let end = text[at..].find('\n').map_or(text.len(), |i| at + i);
    let blank = " ".repeat(text[start..end].chars().count());
    text.replace_range(start..end, &blank);
}

/// Where a value in force came from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Source {
    /// fovea's default (or, for what a profile sets, the application's own profile).
    Default,
    /// An environment variable.
    Env(&'static str),
    /// A section of the configuration file.
    File {
        path: String,
        section: String,
        line: usize,
    },
}

impl fmt::Display for Source {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Source::Default => f.write_str("default"),
            Source::Env(v) => write!(f, "environment {v}"),
            Source::File {
                path,
                section,
                line,
            } => write!(f, "{path}:{line} ({section})"),
        }
    }
}

/// Every key's value in force (`None`: not set, the application's profile or fovea's default
/// applies) and where it came from.
#[derive(Clone, Debug, PartialEq)]
pub struct Resolved {
    pub values: [Option<Value>; KEYS],
    pub sources: [Source; KEYS],
}

impl Resolved {
    pub fn get(&self, key: Key) -> Option<&Value> {
        self.values[key as usize].as_ref()
    }

    pub fn source(&self, key: Key) -> &Source {
        &self.sources[key as usize]
    }

    pub fn level(&self, key: Key) -> Option<Level> {
        match self.get(key) {
            Some(Value::Level(l)) => Some(*l),
            _ => None,
        }
    }

    pub fn flag(&self, key: Key) -> Option<bool> {
        match self.get(key) {
            Some(Value::Bool(b)) => Some(*b),
            _ => None,
        }
    }

    /// A switch in force: set, else the table's default (off for a switch without one).
    pub fn flag_or_default(&self, key: Key) -> bool {
        self.flag(key).unwrap_or(key.default_flag())
    }

    pub fn vertical_offset_deg(&self) -> Option<f32> {
        match self.get(Key::VerticalOffset) {
            Some(Value::Degrees(d)) => Some(*d),
            _ => None,
        }
    }

    /// The cap in force: 1, 2 or 4.
    pub fn max_fragment(&self) -> u32 {
        match self.get(Key::MaxFragment) {
            Some(Value::Fragment(n)) => *n,
            _ => DEFAULT_MAX_FRAGMENT,
        }
    }

    /// A gaze parameter's value, where set.
    pub fn number(&self, key: Key) -> Option<f32> {
        match self.get(key) {
            Some(Value::Number(n)) => Some(*n),
            _ => None,
        }
    }

    pub fn text(&self, key: Key) -> Option<&str> {
        match self.get(key) {
            Some(Value::Text(t)) => Some(t),
            _ => None,
        }
    }
}

/// The settings in force for `id`: the matching sections of `file` (least specific first), then
/// the environment (`env`) over them. Quest's property file, which fovea re-reads on its own, is
/// not included here. A bad environment value is skipped and returned in the second list as
/// `(variable, value, accepted)`.
pub fn resolve(
    file: Option<&Config>,
    id: &Identity,
    env: impl Fn(&str) -> Option<String>,
) -> (Resolved, Vec<(&'static str, String, &'static str)>) {
    let mut r = Resolved {
        values: Default::default(),
        sources: std::array::from_fn(|_| Source::Default),
    };
    if let Some(c) = file {
        let path = c.path.display().to_string();
        for s in c.matching(id) {
            for e in &s.entries {
                r.values[e.key as usize] = Some(e.value.clone());
                r.sources[e.key as usize] = Source::File {
                    path: path.clone(),
                    section: s.scope.header(),
                    line: e.line,
                };
            }
        }
    }
    let mut bad = Vec::new();
    for key in Key::ALL {
        let Some(var) = key.env() else { continue };
        let Some(text) = env(var) else { continue };
        match parse_env(key, &text) {
            Some(v) => {
                r.values[key as usize] = Some(v);
                r.sources[key as usize] = Source::Env(var);
            }
            None => bad.push((var, text, key.accepted())),
        }
    }
    (r, bad)
}

/// The configuration file: `FOVEA_CONFIG`, else `$XDG_CONFIG_HOME/fovea/fovea.toml`, else
/// `~/.config/fovea/fovea.toml`. `None` when `FOVEA_CONFIG` is empty (no file) or no home is known.
pub fn config_path(get: impl Fn(&str) -> Option<OsString>) -> Option<PathBuf> {
    if let Some(p) = get(env::CONFIG) {
        return (!p.is_empty()).then(|| PathBuf::from(p));
    }
    base_dir(&get, env::XDG_CONFIG_HOME, ".config").map(|d| d.join("fovea").join("fovea.toml"))
}

/// The default log file: `$XDG_STATE_HOME/fovea/fovea.log`, else `~/.local/state/fovea/fovea.log`.
pub fn default_log_path(get: impl Fn(&str) -> Option<OsString>) -> Option<PathBuf> {
    base_dir(&get, env::XDG_STATE_HOME, ".local/state").map(|d| d.join("fovea").join("fovea.log"))
}

/// An XDG base directory: the variable when it holds an absolute path (the spec ignores relative
/// ones, https://specifications.freedesktop.org/basedir-spec/latest/), else `$HOME/<fallback>`.
fn base_dir(get: &impl Fn(&str) -> Option<OsString>, var: &str, fallback: &str) -> Option<PathBuf> {
    if let Some(d) = get(var).map(PathBuf::from).filter(|d| d.is_absolute()) {
        return Some(d);
    }
    get("HOME")
        .filter(|h| !h.is_empty())
        .map(|h| PathBuf::from(h).join(fallback))
}

/// The process environment as [`config_path`] and [`default_log_path`] take it.
pub fn process_env(name: &str) -> Option<OsString> {
    std::env::var_os(name)
}

#[cfg(test)]
mod tests;
