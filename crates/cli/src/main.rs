//! `fovea`: the layer's command-line companion.
//!
//! [`args`] declares the command line; each subcommand lives in its own module and exposes a `run`
//! taking its parsed arguments. Usage errors exit with status 2 (clap's convention), failures of a
//! command that ran with status 1.

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

use clap::Parser;

use args::{Cli, Command};

fn main() {
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
