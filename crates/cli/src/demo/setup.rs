//! What both ways of running the demo share: the command line, the output folder and the property
//! file ([`Setup`]), the load script, and building what the demo runs.

use std::path::PathBuf;

use fovea_model::headsets::Headset;

use crate::args::DemoArgs;

/// The load script, in frames at 90 Hz: light, then past the 11.1 ms budget, then light again.
pub(super) const LOAD: [(u64, f32); 3] = [(0, 6.0), (270, 14.0), (630, 6.0)];

/// [`LOAD`] for a display at `refresh_hz`: the same seconds and the same share of the frame
/// budget (frames scaled by `refresh_hz / 90`, milliseconds by `90 / refresh_hz`), so the dynamic
/// level tells the same story at any rate.
pub(super) fn load_at(refresh_hz: f32) -> Vec<(u64, f32)> {
    let k = refresh_hz / 90.0;
    LOAD.iter()
        .map(|&(f, ms)| ((f as f32 * k).round() as u64, ms / k))
        .collect()
}

/// Where the simulated eye tracker says the eye looks (`FOVEA_SIM_GAZE`, the grammar in
/// `crates/sim/src/gaze_script.rs`), a loop of about 4.7 s: a fixation ahead, a 40 ms saccade up and right
/// (saccades take 20–80 ms), a fixation there, smooth pursuit down and left at 20°/s (pursuit
/// reaches about 30°/s), a 300 ms blink (the fovea holds where it was), a fixation, and a saccade
/// back. 15° moves the fovea about a third of a Quest 3 or Rift CV1 view: several density-map
/// texels at any level.
pub(super) const GAZE: &str = "fix 0,0 for 1s; saccade 15,8 in 40ms; fix for 1s; \
     pursue -15,-6 at 20; blink 300ms; fix for 700ms; saccade 0,0 in 40ms; loop";

/// What the override writes, four fifths through.
const OVERRIDE: &str = "debug.oculus.foveation.level=2\ndebug.oculus.foveation.dynamic=0\n";

/// What both ways share: the command line, the output folder and the property file.
pub struct Setup {
    /// `--seconds`, when given.
    pub(super) seconds: Option<u64>,
    pub(super) out: PathBuf,
    pub(super) props: PathBuf,
    /// `FOVEA_LOG` for the layer: the caller's, else warnings and the stats lines.
    pub(super) log: String,
    /// `--headset`, when given.
    pub(super) headset: &'static Headset,
    pub(super) headset_given: bool,
    /// `--overlay`: the map sampled into the frames, not the frames foveated.
    pub(super) overlay: bool,
    /// `--compare`: blocky and reconstructed runs, side by side.
    pub(super) compare: bool,
}

impl Setup {
    pub(super) fn new(args: &DemoArgs) -> Result<Setup, String> {
        let out = &args.out;
        std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
        let out = std::fs::canonicalize(out).map_err(|e| format!("{}: {e}", out.display()))?;
        let props = out.join("foveation.props");
        let headset = args.headset.unwrap_or_else(|| {
            fovea_model::headsets::by_id("quest3").expect("quest3 preset exists")
        });
        let setup = Setup {
            seconds: args.seconds,
            out,
            props,
            log: std::env::var("FOVEA_LOG")
                .unwrap_or_else(|_| format!("warn,{}=info", fovea_abi::log_target::STATS)),
            headset,
            headset_given: args.headset.is_some(),
            overlay: args.overlay,
            compare: args.compare,
        };
        setup.reset_props()?;
        Ok(setup)
    }

    /// The property file as the run starts: no override yet (each run of `--compare` starts so).
    pub(super) fn reset_props(&self) -> Result<(), String> {
        std::fs::write(
            &self.props,
            "# Quest debug properties, re-read while the app runs\n",
        )
        .map_err(|e| format!("{}: {e}", self.props.display()))
    }

    pub(super) fn write_override(&self) -> Result<(), String> {
        std::fs::write(&self.props, OVERRIDE)
            .map_err(|e| format!("{}: {e}", self.props.display()))?;
        println!(
            "-- wrote debug.oculus.foveation.level=2, dynamic=0 to {}",
            self.props.display()
        );
        Ok(())
    }

    /// The run's length: `--seconds`, else `default`.
    pub(super) fn seconds_or(&self, default: u64) -> u64 {
        self.seconds.unwrap_or(default)
    }
}

/// The gaze script as the first lines print it.
pub(super) fn gaze_description() -> String {
    format!("FOVEA_SIM_GAZE=\"{GAZE}\"")
}

pub(super) fn load_description(load: &[(u64, f32)]) -> String {
    load.iter()
        .map(|(f, ms)| format!("{ms} ms from frame {f}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The folder the running `fovea` was built into (`target/release`, `target/debug`), where Cargo
/// also puts the libraries and examples the demo runs.
pub(super) fn build_dir() -> Result<PathBuf, String> {
    let exe = std::env::current_exe().map_err(|e| format!("current executable: {e}"))?;
    let exe = std::fs::canonicalize(&exe).unwrap_or(exe);
    exe.parent()
        .map(PathBuf::from)
        .ok_or_else(|| "the executable has no directory".into())
}

/// Builds `what` with the profile the running `fovea` was built with, when the demo was started by
/// Cargo (`$CARGO` is set): `cargo run` builds only what the binary links.
pub(super) fn cargo_build(what: &[&str]) -> Result<(), String> {
    let cargo = std::env::var_os("CARGO").ok_or("not started by cargo")?;
    let dir = build_dir()?;
    let profile = match dir.file_name().and_then(|n| n.to_str()) {
        Some("debug") | None => "dev".to_owned(),
        Some(p) => p.to_owned(),
    };
    let status = std::process::Command::new(cargo)
        .args(["build", "--quiet", "--profile", &profile])
        .args(what)
        .status()
        .map_err(|e| format!("cargo: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("cargo build {} failed: {status}", what.join(" ")))
    }
}
