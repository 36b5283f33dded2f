//! The `fovea` binary from the outside: every command run as a user runs it, in one test binary
//! (one link, one process per test run) with one runner in [`support`].

mod config;
mod custom_headset;
mod demo;
mod fov;
mod install;
mod maps;
mod parser;
mod support;
