//! The one way these tests run `fovea`: the binary Cargo built for this test run, its exit status
//! and both streams as text.

use std::process::Command;

/// What one run of `fovea` did.
pub struct Run {
    /// The exit status: 0 done, 1 the command failed, 2 a usage error.
    pub code: i32,
    pub out: String,
    pub err: String,
}

impl Run {
    pub fn ok(&self) -> bool {
        self.code == 0
    }

    /// Both streams, for assertion messages.
    pub fn text(&self) -> String {
        format!("{}{}", self.out, self.err)
    }
}

/// A `fovea` command to add arguments and environment to. Its XDG configuration and state folders
/// are a private folder, so no test reads the user's `fovea.toml` or writes to their log.
pub fn command() -> Command {
    let home = fovea_harness::private_home();
    let mut c = Command::new(env!("CARGO_BIN_EXE_fovea"));
    c.env("XDG_CONFIG_HOME", home.join("config"))
        .env("XDG_STATE_HOME", home.join("state"))
        .env_remove("FOVEA_CONFIG");
    c
}

/// Runs a prepared command.
pub fn run(cmd: &mut Command) -> Run {
    let out = cmd.output().expect("run fovea");
    Run {
        code: out
            .status
            .code()
            .expect("fovea exited, not killed by a signal"),
        out: String::from_utf8_lossy(&out.stdout).into_owned(),
        err: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// `fovea args...` in the test's environment.
pub fn fovea(args: &[&str]) -> Run {
    run(command().args(args))
}
