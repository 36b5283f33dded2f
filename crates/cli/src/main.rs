//! `fovea`: the layer's command-line companion.
//!
//! [`args`] declares the command line; each subcommand lives in its own module and exposes a `run`
//! taking its parsed arguments. Usage errors exit with status 2 (clap's convention), failures of a
//! command that ran with status 1.
//!
//! The files stand in floors: each imports only files on floors below its own.
//!
//! | floor | path | job |
//! |---|---|---|
//! | 1 | `args.rs` | the command line, declared once with clap |
//! | 1 | `discovery.rs` | where the OpenXR and Vulkan loaders look for manifests on Linux, as data (`install` and `doctor` both read it) |
//! | 1 | `json.rs` | numbers for the JSON outputs |
//! | 2 | `target.rs` | the headset `maps` and `report` describe: a preset, or FOVs and a size |
//! | 2 | `fov.rs` | `fovea fov` |
//! | 2 | `config.rs` | `fovea config` |
//! | 2 | `install.rs` | `fovea install`, `fovea uninstall` |
//! | 2 | `found.rs` | what the OpenXR loader would find: the active runtime, each layer manifest, the load order |
//! | 2 | `vk_doctor.rs` | `fovea doctor`'s Vulkan half: each GPU, and where the Vulkan layer is installed |
//! | 2 | `xr_doctor.rs` | `fovea doctor`'s eye gaze line: whether the runtime offers eye gaze and its system has an eye tracker |
//! | 2 | `demo/setup.rs` | what both ways of running the demo share |
//! | 2 | `demo/frames.rs` | what the demo says about the frames it read back, and `--compare`'s pairs |
//! | 3 | `maps.rs` | `fovea maps` |
//! | 3 | `report.rs` | `fovea report` |
//! | 3 | `doctor_settings.rs` | `fovea doctor`'s checks of Steam installs, other layers and the configuration file |
//! | 4 | `doctor.rs` | `fovea doctor` |
//! | 4 | `demo/harness.rs` | the demo through fovea's fake loader harness |
//! | 4 | `demo/loader.rs` | the demo through the system's Khronos loader |
//! | 5 | `demo/mod.rs` | `fovea demo`: chooses the way and runs it |
//! | 6 | `main.rs` | parses the command line and runs the command |

mod args;
mod config;
mod demo;
mod discovery;
mod doctor;
mod doctor_settings;
mod found;
mod fov;
mod install;
mod json;
mod maps;
mod report;
mod target;
mod vk_doctor;
mod xr_doctor;

use clap::Parser;

use args::{Cli, Command};

/// Rust starts programs with SIGPIPE ignored, so a write into a pipe whose reader has gone
/// (`fovea report --json | head -c1`) fails and `println!` panics. The default disposition ends
/// `fovea` quietly there, as it ends `cat` and other tools (signal(7)).
fn end_quietly_on_a_closed_pipe() {
    extern "C" {
        /// signal(2), from the C library the standard library links.
        fn signal(signum: i32, handler: usize) -> usize;
    }
    const SIGPIPE: i32 = 13;
    const SIG_DFL: usize = 0;
    // SAFETY: sets one signal's disposition to its default before any other thread exists; no
    // handler of ours is installed.
    unsafe { signal(SIGPIPE, SIG_DFL) };
}

fn main() {
    end_quietly_on_a_closed_pipe();
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Demo(a) => demo::run(a),
        Command::Maps(a) => maps::run(a),
        Command::Report(a) => report::run(a),
        Command::Fov(a) => fov::run(a),
        Command::Install(a) => install::install(a),
        Command::Uninstall(a) => install::uninstall(a),
        Command::Doctor(a) => doctor::run(a),
        Command::Config(a) => config::run(a),
    };
    if let Err(e) = result {
        eprintln!("fovea {}: {e}", cli.command.name());
        std::process::exit(1);
    }
}
