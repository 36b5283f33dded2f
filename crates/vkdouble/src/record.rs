//! What the double saw, kept per process in the loaded library, and the profile it plays.

use std::sync::Mutex;

use serde_json::{json, Value};

use crate::Profile;

struct Records {
    events: Vec<Value>,
    /// Definitions ([`definition`]) whose object was destroyed since the records were last
    /// trimmed: a definition of one of them may go once it is old.
    destroyed: Vec<(&'static str, u64)>,
    errors: Vec<String>,
    /// Events left out to keep the records bounded ([`KEPT_EVENTS`]).
    dropped: u64,
    /// Errors past [`KEPT_EVENTS`], counted only.
    dropped_errors: u64,
}

static RECORDS: Mutex<Records> = Mutex::new(Records {
    events: Vec::new(),
    destroyed: Vec::new(),
    errors: Vec::new(),
    dropped: 0,
    dropped_errors: 0,
});

/// How many events the records keep at least: once twice as many have piled up, the oldest are
/// dropped down to this many. Kept however old they are: `instance` and `device` events (few, and
/// tests read them long after), and the definition of every object still alive ([`definition`]:
/// images, views, render passes, framebuffers, pipelines), which the checks of what a draw shades
/// read back whenever the draw was recorded; only per-command events (barriers, begins, submits,
/// draws) and the definitions of destroyed objects are bounded. A process that records for hours
/// through the double (the demo on lavapipe, a benchmark recording millions of commands) then runs
/// in memory bounded by what it keeps alive; a test, which reads back far fewer, sees everything,
/// and `dropped` in the snapshot says where it would not.
pub const KEPT_EVENTS: usize = 1 << 15;

/// Whether an event is kept however old it is, besides live definitions.
fn lasting(v: &Value) -> bool {
    matches!(v["kind"].as_str(), Some("instance" | "device"))
}

/// The kinds of definition events, with the field that holds the object's handle.
const DEFINITIONS: [(&str, &str); 5] = [
    ("image", "image"),
    ("image_view", "view"),
    ("render_pass", "render_pass"),
    ("framebuffer", "framebuffer"),
    ("pipeline", "pipeline"),
];

/// The kind and handle of a definition event.
fn definition(v: &Value) -> Option<(&'static str, u64)> {
    let kind = v["kind"].as_str()?;
    let (k, field) = DEFINITIONS.iter().find(|(k, _)| *k == kind)?;
    Some((k, v[*field].as_u64()?))
}

/// Notes that the object `handle` of a definition kind (`image`, `image_view`, `render_pass`,
/// `framebuffer`, `pipeline`) was destroyed: its definition is no longer kept past the bound.
pub fn destroyed(kind: &'static str, handle: u64) {
    let mut r = records();
    // A handle reused before the next trim is alive again; its newest definition stands.
    if !r.destroyed.contains(&(kind, handle)) {
        r.destroyed.push((kind, handle));
    }
}

/// Set by [`crate::fovea_vkdouble_set_profile`]; overrides the environment.
static PROFILE: Mutex<Option<Profile>> = Mutex::new(None);

fn records() -> std::sync::MutexGuard<'static, Records> {
    RECORDS.lock().unwrap_or_else(|e| e.into_inner())
}

/// Appends one event (an object with a `kind`).
pub fn event(v: Value) {
    let mut r = records();
    if let Some(d) = definition(&v) {
        // A new object with a destroyed one's handle (drivers reuse them).
        r.destroyed.retain(|x| *x != d);
    }
    r.events.push(v);
    if r.events.len() >= 2 * KEPT_EVENTS {
        trim(&mut r);
    }
}

/// Drops the oldest events down to [`KEPT_EVENTS`], keeping the [`lasting`] ones and each live
/// object's newest definition.
fn trim(r: &mut Records) {
    let Records {
        events, destroyed, ..
    } = r;
    let mut newest = std::collections::HashSet::new();
    let keep: Vec<bool> = events
        .iter()
        .rev()
        .map(|e| {
            lasting(e) || definition(e).is_some_and(|d| !destroyed.contains(&d) && newest.insert(d))
        })
        .collect::<Vec<_>>()
        .into_iter()
        .rev()
        .collect();
    let mut excess = events.len().saturating_sub(KEPT_EVENTS);
    let before = events.len();
    let mut i = 0;
    events.retain(|_| {
        let k = keep[i];
        i += 1;
        if excess > 0 && !k {
            excess -= 1;
            false
        } else {
            true
        }
    });
    // Destroyed objects whose definitions are all gone need no note any more.
    let left: std::collections::HashSet<_> = events.iter().filter_map(definition).collect();
    destroyed.retain(|d| left.contains(d));
    r.dropped += (before - r.events.len()) as u64;
}

/// Counts one call of `name` ([`calls`]) that cannot be made to fail.
pub fn count(name: &str) {
    let mut f = faults();
    *f.calls.entry(name.to_owned()).or_insert(0) += 1;
}

/// Appends a misuse a driver with shading-rate attachments would refuse (the first
/// [`KEPT_EVENTS`]; later ones are counted).
pub fn error(message: String) {
    let mut r = records();
    if r.errors.len() < KEPT_EVENTS {
        r.errors.push(message);
    } else {
        r.dropped_errors += 1;
    }
}

/// `{"events": [...], "errors": [...], "dropped": n, "dropped_errors": n}`.
pub fn snapshot() -> Value {
    let r = records();
    json!({
        "events": r.events,
        "errors": r.errors,
        "dropped": r.dropped,
        "dropped_errors": r.dropped_errors,
    })
}

/// Forgets every event and error.
pub fn clear() {
    let mut r = records();
    r.events.clear();
    r.destroyed.clear();
    r.errors.clear();
    r.dropped = 0;
    r.dropped_errors = 0;
    drop(r);
    clear_faults();
}

/// Sets (or, with `None`, lifts) the profile override.
pub fn set_profile(p: Option<Profile>) {
    *PROFILE.lock().unwrap_or_else(|e| e.into_inner()) = p;
}

/// The profile a new VkInstance gets: the override, else `FOVEA_VKDOUBLE_PROFILE`, else NVIDIA.
pub fn profile() -> Profile {
    if let Some(p) = *PROFILE.lock().unwrap_or_else(|e| e.into_inner()) {
        return p;
    }
    match std::env::var(crate::PROFILE_ENV) {
        Ok(v) => Profile::parse(&v).unwrap_or_else(|| {
            error(format!(
                "{}={v:?} is not nvidia, amd or none",
                crate::PROFILE_ENV
            ));
            Profile::Nvidia
        }),
        Err(_) => Profile::Nvidia,
    }
}

/// Fault injection: how often each intercepted command was called since [`clear`], and the one
/// armed failure per command (the call index at which it fails, and the result it returns).
struct Faults {
    calls: std::collections::BTreeMap<String, u64>,
    armed: std::collections::BTreeMap<String, (u64, i32)>,
}

static FAULTS: Mutex<Faults> = Mutex::new(Faults {
    calls: std::collections::BTreeMap::new(),
    armed: std::collections::BTreeMap::new(),
});

fn faults() -> std::sync::MutexGuard<'static, Faults> {
    FAULTS.lock().unwrap_or_else(|e| e.into_inner())
}

/// Counts one call of `name`; the armed result where this is the call it was armed for (the fault
/// fires once, then disarms).
pub fn fault(name: &str) -> Option<ash::vk::Result> {
    let mut f = faults();
    let calls = f.calls.entry(name.to_owned()).or_insert(0);
    let index = *calls;
    *calls += 1;
    match f.armed.get(name) {
        Some(&(nth, result)) if nth == index => {
            f.armed.remove(name);
            Some(ash::vk::Result::from_raw(result))
        }
        _ => None,
    }
}

/// Arms `name` to return `result` at its call number `nth` (0-based, counted since [`clear`]).
pub fn arm(name: &str, nth: u64, result: i32) {
    faults().armed.insert(name.to_owned(), (nth, result));
}

/// How often `name` was called since [`clear`].
pub fn calls(name: &str) -> u64 {
    faults().calls.get(name).copied().unwrap_or(0)
}

/// Forgets the counts and disarms every fault.
pub fn clear_faults() {
    let mut f = faults();
    f.calls.clear();
    f.armed.clear();
}
