//! `fovea doctor` (in progress).

use crate::args::Args;

pub fn run(_args: &Args) -> Result<(), String> {
    Err("not built yet".into())
}
