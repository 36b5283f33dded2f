//! The shading-rate test double's integration tests, in one test binary: the double on lavapipe
//! under the Khronos validation layer ([`lavapipe`]), and enabled through the loader's environment
//! variables in a child process of this binary ([`env_layers`]).

#[path = "../../../../tests/suite/support/process.rs"]
mod process;

mod env_layers;
mod lavapipe;

/// Skips a test whose system component (loader, lavapipe, validation layer, the built library)
/// is missing, saying why; fails it under `FOVEA_REQUIRE_SYSTEM=1`.
fn skip(reason: &str) {
    if std::env::var("FOVEA_REQUIRE_SYSTEM").is_ok_and(|v| v == "1") {
        panic!("required system component missing: {reason}");
    }
    eprintln!("SKIPPED: {reason}");
}
