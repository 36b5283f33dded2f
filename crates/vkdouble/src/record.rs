//! What the double saw, kept per process in the loaded library, and the profile it plays.

use std::sync::Mutex;

use serde_json::{json, Value};

use crate::Profile;

struct Records {
    events: Vec<Value>,
    errors: Vec<String>,
}

static RECORDS: Mutex<Records> = Mutex::new(Records {
    events: Vec::new(),
    errors: Vec::new(),
});

/// Set by [`crate::fovea_vkdouble_set_profile`]; overrides the environment.
static PROFILE: Mutex<Option<Profile>> = Mutex::new(None);

fn records() -> std::sync::MutexGuard<'static, Records> {
    RECORDS.lock().unwrap_or_else(|e| e.into_inner())
}

/// Appends one event (an object with a `kind`).
pub fn event(v: Value) {
    records().events.push(v);
}

/// Appends a misuse a driver with shading-rate attachments would refuse.
pub fn error(message: String) {
    records().errors.push(message);
}

/// `{"events": [...], "errors": [...]}`.
pub fn snapshot() -> Value {
    let r = records();
    json!({ "events": r.events, "errors": r.errors })
}

/// Forgets every event and error.
pub fn clear() {
    let mut r = records();
    r.events.clear();
    r.errors.clear();
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
