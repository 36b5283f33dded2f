//! Settings read from the environment.
//!
//! Every variable the layer reads is listed here (and in the README's settings table and
//! include/fovea.h), so there is one place to look.

/// `FOVEA_SYMMETRIC_FOV=1`: report one shared symmetric FOV for both eyes (Quest's recommended mode,
/// fixed-foveated-rendering seed) and give pixels outside each eye's true FOV the lowest density.
pub const SYMMETRIC_FOV_ENV: &str = "FOVEA_SYMMETRIC_FOV";

/// Quest's `debug.oculus.foveation.*` properties (fixed-foveated-rendering seed), as environment
/// variables: `DEBUG_OCULUS_FOVEATION_LEVEL` (0 off, 1 low, 2 medium, 3 high, 4 high top),
/// `DEBUG_OCULUS_FOVEATION_DYNAMIC` (0/1), `DEBUG_OCULUS_FOVEATION_SUBSAMPLED` (0/1).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DebugProperties {
    pub level: Option<u32>,
    pub dynamic: Option<bool>,
    pub subsampled: Option<bool>,
}

/// The debug properties in force now.
pub fn debug_properties() -> DebugProperties {
    let get = |k: &str| std::env::var(k).ok();
    DebugProperties {
        level: get("DEBUG_OCULUS_FOVEATION_LEVEL")
            .and_then(|v| v.trim().parse().ok())
            .filter(|l| *l <= 4),
        dynamic: get("DEBUG_OCULUS_FOVEATION_DYNAMIC").and_then(|v| bool01(&v)),
        subsampled: get("DEBUG_OCULUS_FOVEATION_SUBSAMPLED").and_then(|v| bool01(&v)),
    }
}

fn bool01(v: &str) -> Option<bool> {
    match v.trim() {
        "0" => Some(false),
        "1" => Some(true),
        _ => None,
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
}
