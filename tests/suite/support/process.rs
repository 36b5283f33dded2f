//! Running a test in a process of its own: a child process of the test binary that runs only
//! that test. Shared by the suite and by the simulator's and the test double's tests
//! (crates/sim/tests/sim, crates/vkdouble/tests/vkdouble: a `#[path]` module each), so it needs
//! nothing but the standard library.

use std::process::{Command, Output};

/// Set in a child process of the test binary: the one test it runs.
const CHILD: &str = "FOVEA_SUITE_CHILD";

/// Runs a test that needs a process of its own: one that sets environment variables the layer or a
/// loader reads (the layer reads some once per process, and changing the environment while other
/// tests' threads read it is a data race in C's `getenv`), or that asserts on the simulated
/// runtime's process-wide object count, which the suite's other tests change at the same time.
///
/// In the test process this runs the test `name` of module `module` (pass `module_path!()`) again
/// in a child process of this binary and returns the child's output once it passed; in that child,
/// it runs `body` and returns `None`.
pub fn in_own_process(module: &str, name: &str, body: impl FnOnce()) -> Option<Output> {
    // `module_path!()` starts with the crate's name, which test names leave out.
    let test = match module.split_once("::") {
        Some((_, path)) => format!("{path}::{name}"),
        None => name.to_owned(),
    };
    if std::env::var_os(CHILD).is_some_and(|v| v == test.as_str()) {
        body();
        return None;
    }
    let out = Command::new(std::env::current_exe().unwrap())
        .args([&test, "--exact", "--nocapture", "--test-threads=1"])
        .env(CHILD, &test)
        .output()
        .expect("run the test in a child process");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "{test} failed in its own process ({}):\n{stdout}\n{stderr}",
        out.status
    );
    // A misspelt name would run nothing and pass.
    assert!(
        stdout.contains("test result: ok. 1 passed"),
        "{test} did not run in its own process:\n{stdout}\n{stderr}"
    );
    print!("{stdout}");
    eprint!("{stderr}");
    Some(out)
}
