//! Settings read from the environment.
//!
//! Every variable the layer reads is listed here (and in the README's settings table and
//! include/fovea.h), so there is one place to look.

/// `FOVEA_SYMMETRIC_FOV=1`: report one shared symmetric FOV for both eyes (Quest's recommended mode,
/// fixed-foveated-rendering seed) and give pixels outside each eye's true FOV the lowest density.
pub const SYMMETRIC_FOV_ENV: &str = "FOVEA_SYMMETRIC_FOV";

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
        Settings { symmetric_fov: flag(get(SYMMETRIC_FOV_ENV).as_deref(), SYMMETRIC_FOV_ENV) }
    }
}

/// A 0/1 switch; anything else gets one warning naming the variable and is treated as off.
fn flag(v: Option<&str>, name: &str) -> bool {
    match v.map(str::trim) {
        None | Some("") | Some("0") => false,
        Some("1") => true,
        Some(other) => {
            tracing::warn!(variable = name, value = other, "accepted values are 0 and 1; ignored");
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symmetric_fov_switch() {
        let s = |v: Option<&str>| Settings::from_lookup(|k| (k == SYMMETRIC_FOV_ENV).then(|| v).flatten().map(String::from));
        assert!(s(Some("1")).symmetric_fov);
        assert!(!s(Some("0")).symmetric_fov);
        assert!(!s(Some("yes")).symmetric_fov);
        assert!(!s(None).symmetric_fov);
    }
}
