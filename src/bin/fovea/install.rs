//! `fovea install` / `fovea uninstall` (in progress).

use crate::args::Args;

pub fn install(_args: &Args) -> Result<(), String> {
    Err("not built yet".into())
}

pub fn uninstall(_args: &Args) -> Result<(), String> {
    Err("not built yet".into())
}
