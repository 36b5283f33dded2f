//! `fovea`: the layer's command-line companion.
//!
//! Each subcommand lives in its own module and exposes `run(&Args) -> Result<(), String>`.

mod args;
mod demo;
mod doctor;
mod fov;
mod install;
mod maps;
mod report;

use args::Args;

const USAGE: &str = "\
usage: fovea <command> [options]

commands:
  demo    [--via loader|harness] [--seconds N] [--headset NAME] [--out DIR]
                            an app on the simulated headset through the layer: the example app
                            through the system loader where it and Vulkan are there, else a
                            headless loop through the fake loader harness
  maps    --headset NAME --level none|low|medium|high|high-top [--vertical-offset DEG]
          [--eye left|right|both] [--texel N] --out DIR
                            write PNGs of the resolution multiplier maps
  report  --headset NAME [--texel N] [--json]
                            per level: shaded fraction, full-rate radius, relative pixel density
  fov     --headset NAME [--json]
                            per-eye FOV, projection centre, asymmetric vs symmetric sizes
  install [--implicit] [--system]
                            write a layer manifest with an absolute library path (libfovea.so
                            next to this binary, or the file FOVEA_LIBRARY names) to
                            $XDG_DATA_HOME (default ~/.local/share), or /usr/local/share with
                            --system, under openxr/1/api_layers/{explicit,implicit}.d
  uninstall [--implicit] [--system]
                            remove what install wrote
  doctor                    show what the OpenXR loader would find and name misconfigurations
                            (exit status 1 when there are any)

headsets: quest2, quest3, quest-pro, rift-cv1, rift-s, index, pico4";

fn main() {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    let Some((command, rest)) = argv.split_first() else {
        eprintln!("{USAGE}");
        std::process::exit(2);
    };
    let args = match Args::parse(rest) {
        Ok(a) => a,
        Err(e) => {
            eprintln!("fovea {command}: {e}\n\n{USAGE}");
            std::process::exit(2);
        }
    };
    let result = match command.as_str() {
        "demo" => demo::run(&args),
        "maps" => maps::run(&args),
        "report" => report::run(&args),
        "fov" => fov::run(&args),
        "install" => install::install(&args),
        "uninstall" => install::uninstall(&args),
        "doctor" => doctor::run(&args),
        "help" | "--help" | "-h" => {
            println!("{USAGE}");
            Ok(())
        }
        other => Err(format!("unknown command '{other}'")),
    };
    if let Err(e) = result {
        eprintln!("fovea {command}: {e}");
        std::process::exit(1);
    }
}
