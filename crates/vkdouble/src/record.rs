//! What the double saw, kept per process in the loaded library, and the profile it plays.

use std::sync::Mutex;

use serde_json::{json, Value};

use crate::Profile;

struct Records {
    events: Vec<Value>,
    errors: Vec<String>,
    /// Events left out to keep the records bounded ([`KEPT_EVENTS`]).
    dropped: u64,
    /// Errors past [`KEPT_EVENTS`], counted only.
    dropped_errors: u64,
}

static RECORDS: Mutex<Records> = Mutex::new(Records {
    events: Vec::new(),
    errors: Vec::new(),
    dropped: 0,
    dropped_errors: 0,
});

/// How many events the records keep at least: once twice as many have piled up, the oldest are
/// dropped down to this many (`instance` and `device` events excepted: there are few, and tests
/// read them long after). A process that records for hours through the double (the demo on
/// lavapipe, a benchmark recording millions of commands) then runs in bounded memory; a test,
/// which reads back far fewer, sees everything, and `dropped` in the snapshot says where it would
/// not.
pub const KEPT_EVENTS: usize = 1 << 15;

/// Whether an event is kept however old it is.
fn lasting(v: &Value) -> bool {
    matches!(v["kind"].as_str(), Some("instance" | "device"))
}

/// Set by [`crate::fovea_vkdouble_set_profile`]; overrides the environment.
static PROFILE: Mutex<Option<Profile>> = Mutex::new(None);

fn records() -> std::sync::MutexGuard<'static, Records> {
    RECORDS.lock().unwrap_or_else(|e| e.into_inner())
}

/// Appends one event (an object with a `kind`).
pub fn event(v: Value) {
    let mut r = records();
    r.events.push(v);
    if r.events.len() >= 2 * KEPT_EVENTS {
        let mut excess = r.events.len() - KEPT_EVENTS;
        let before = r.events.len();
        r.events.retain(|e| {
            if excess > 0 && !lasting(e) {
                excess -= 1;
                false
            } else {
                true
            }
        });
        r.dropped += (before - r.events.len()) as u64;
    }
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
