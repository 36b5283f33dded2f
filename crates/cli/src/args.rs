//! The command line, declared once with clap: each command's flags, what each accepts and its help
//! text. clap rejects an unknown or misspelt flag with a suggestion, names the accepted values of a
//! wrong one, and exits with status 2 on any usage error, so a typo can no longer run a command
//! with a default the user meant to change.

use std::path::PathBuf;

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use clap::{Args, Parser, Subcommand, ValueEnum};
use fovea_model::density::Level;
use fovea_model::headsets::{by_id, ids, Headset};
use fovea_model::Fov;

#[derive(Debug, Parser)]
#[command(
    name = "fovea",
    version,
    about = "fovea's command-line companion: the demo, density maps and reports, install, doctor",
    arg_required_else_help = true,
    after_help = "`fovea <command> --help` lists a command's options."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// An app on the simulated headset through the layer: the example app through the system
    /// loader where it and Vulkan are there, else a headless loop through the fake loader harness
    Demo(DemoArgs),
    /// Write PNGs of the resolution multiplier maps
    Maps(MapsArgs),
    /// Per level: shaded fraction, full-rate radius, relative pixel density
    Report(ReportArgs),
    /// Per-eye FOV, projection centre, asymmetric vs symmetric sizes
    Fov(FovArgs),
    /// Write a layer manifest with an absolute library path (libfovea.so next to this binary, or
    /// the file FOVEA_LIBRARY names) to $XDG_DATA_HOME (default ~/.local/share), or
    /// /usr/local/share with --system, under openxr/1/api_layers/{explicit,implicit}.d
    Install(InstallArgs),
    /// Remove what install wrote
    Uninstall(InstallArgs),
    /// Show what the OpenXR loader would find and name misconfigurations (exit status 1 when
    /// there are any)
    Doctor(DoctorArgs),
    /// Show the settings in force for an application and where each comes from; --check
    /// validates fovea.toml (exit status 1 on problems)
    Config(ConfigArgs),
}

#[derive(Debug, Args)]
pub struct DoctorArgs {
    /// Also say which sections of fovea.toml match this application or executable name
    #[arg(long, value_name = "NAME")]
    pub app: Option<String>,
}

#[derive(Debug, Args)]
pub struct ConfigArgs {
    /// XrApplicationInfo::applicationName to resolve for
    #[arg(long, value_name = "NAME")]
    pub app: Option<String>,
    /// The executable's file name to resolve for
    #[arg(long, value_name = "NAME")]
    pub exe: Option<String>,
    /// XrApplicationInfo::engineName to resolve for
    #[arg(long, value_name = "NAME")]
    pub engine: Option<String>,
    /// Validate the file: one `problem:` line per error, exit status 1 when there are any
    #[arg(long, conflicts_with_all = ["app", "exe", "engine"])]
    pub check: bool,
}

impl Command {
    /// The command's name, for the `fovea <command>: <error>` line.
    pub fn name(&self) -> &'static str {
        match self {
            Command::Demo(_) => "demo",
            Command::Maps(_) => "maps",
            Command::Report(_) => "report",
            Command::Fov(_) => "fov",
            Command::Install(_) => "install",
            Command::Uninstall(_) => "uninstall",
            Command::Doctor(_) => "doctor",
            Command::Config(_) => "config",
        }
    }
}

/// How `fovea demo` runs the application.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Via {
    /// examples/foveated_vulkan through the system's Khronos loader
    Loader,
    /// a headless frame loop through fovea's fake loader harness
    Harness,
}

#[derive(Debug, Args)]
pub struct DemoArgs {
    /// How to run the app [default: the loader where it and Vulkan are there, else the harness]
    #[arg(long)]
    pub via: Option<Via>,
    /// How long to run [default: 20, or 10 on a CPU renderer, 8 (at 30 Hz) on the simulated
    /// desktop GPU]
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub seconds: Option<u64>,
    /// The simulated headset [default: quest3, or rift-cv1 on a CPU renderer]
    #[arg(long, value_name = "NAME", value_parser = headset_parser())]
    pub headset: Option<&'static Headset>,
    /// Where the property file and the PNGs go
    #[arg(long, value_name = "DIR", default_value = "target/demo")]
    pub out: PathBuf,
    /// Through the loader on a device without shading-rate attachments: draw the stripes at full
    /// rate with the density maps sampled into a debug overlay, instead of foveating the room on
    /// the simulated desktop GPU
    #[arg(long)]
    pub overlay: bool,
    /// Through the loader: run twice, the periphery's coarse blocks as they are
    /// (FOVEA_SUBSAMPLED=off) and reconstructed (FOVEA_SUBSAMPLED=on), and write each frame side
    /// by side
    #[arg(long, conflicts_with = "overlay")]
    pub compare: bool,
}

/// Which eye's map `fovea maps` draws.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Eye {
    Left,
    Right,
    Both,
}

/// The headset a map or report is for: a preset, or FOVs and a size from the command line.
#[derive(Debug, Args)]
pub struct TargetArgs {
    /// A headset preset
    #[arg(
        long,
        value_name = "NAME",
        value_parser = headset_parser(),
        required_unless_present = "fov",
        conflicts_with_all = ["fov", "fov_right", "size"]
    )]
    pub headset: Option<&'static Headset>,
    /// Instead of --headset: the left eye's half-angles in degrees, each above 0 and below 90, as
    /// the runtime reports them (left,right,up,down); the right eye is its mirror image unless
    /// --fov-right gives it
    #[arg(long, value_name = "L,R,U,D", value_parser = parse_fov, allow_hyphen_values = true)]
    pub fov: Option<Fov>,
    /// The right eye's half-angles in degrees (left,right,up,down), for a headset whose eyes are
    /// not mirror images
    #[arg(
        long,
        value_name = "L,R,U,D",
        value_parser = parse_fov,
        allow_hyphen_values = true,
        requires = "fov"
    )]
    pub fov_right: Option<Fov>,
    /// With --fov: the per-eye eye-buffer size in pixels [default: from the FOV at 1000 pixels per
    /// unit tangent]
    #[arg(long, value_name = "WxH", value_parser = parse_size, requires = "fov")]
    pub size: Option<[u32; 2]>,
}

#[derive(Debug, Args)]
pub struct MapsArgs {
    #[command(flatten)]
    pub target: TargetArgs,
    /// The foveation level (also 0-4)
    #[arg(long, value_parser = level_parser(), ignore_case = true)]
    pub level: Level,
    /// Moves the fovea up (positive) or down, in degrees, as XrFoveationLevelProfileCreateInfoFB's
    /// verticalOffset does
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 0.0,
        value_parser = parse_finite_degrees,
        allow_negative_numbers = true
    )]
    pub vertical_offset: f32,
    /// Which eye's map to draw
    #[arg(long, value_enum, default_value_t = Eye::Both)]
    pub eye: Eye,
    #[command(flatten)]
    pub texel: TexelArg,
    /// The folder the PNGs are written to (created if missing)
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

/// `--texel`, shared by `maps` and `report`.
#[derive(Debug, Args)]
pub struct TexelArg {
    /// The density map's texel size in pixels (1-1024)
    #[arg(
        long = "texel",
        value_name = "N",
        default_value_t = 32,
        value_parser = clap::value_parser!(u32).range(1..=1024)
    )]
    pub value: u32,
}

#[derive(Debug, Args)]
pub struct ReportArgs {
    #[command(flatten)]
    pub target: TargetArgs,
    #[command(flatten)]
    pub texel: TexelArg,
    /// Print one JSON object instead of the table
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct FovArgs {
    /// A headset preset
    #[arg(long, value_name = "NAME", value_parser = headset_parser())]
    pub headset: &'static Headset,
    /// Print one JSON object instead of the table
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct InstallArgs {
    /// An implicit layer, loaded by every OpenXR application (FOVEA_DISABLE=1 switches it off),
    /// instead of an explicit one enabled by name
    #[arg(long)]
    pub implicit: bool,
    /// System-wide, under /usr/local/share (needs root), instead of for this user
    #[arg(long)]
    pub system: bool,
}

/// `--headset`: one of the presets, which `--help` and errors list.
fn headset_parser() -> impl TypedValueParser<Value = &'static Headset> {
    PossibleValuesParser::new(ids()).map(|id| by_id(&id).expect("a possible value is a preset"))
}

/// `--level`: the level names, which `--help` and errors list; the indices and the spellings
/// `Level`'s parser also takes are accepted as hidden aliases.
fn level_parser() -> impl TypedValueParser<Value = Level> {
    let values = Level::ALL.map(|level| {
        let aliases: &[&'static str] = match level {
            Level::None => &["0", "off"],
            Level::Low => &["1"],
            Level::Medium => &["2"],
            Level::High => &["3"],
            Level::HighTop => &["4", "hightop", "high_top"],
        };
        PossibleValue::new(level.name()).aliases(aliases.iter().copied())
    });
    PossibleValuesParser::new(values).map(|s| {
        s.parse()
            .expect("every possible value and alias names a level")
    })
}

/// `--vertical-offset`: any finite number of degrees.
fn parse_finite_degrees(s: &str) -> Result<f32, String> {
    let v: f32 = s
        .trim()
        .parse()
        .map_err(|_| "expected a number of degrees".to_owned())?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err("expected a finite number of degrees".into())
    }
}

/// `--fov L,R,U,D`: four half-angles in degrees, each in (0, 90): a view must contain the direction
/// straight ahead (where the fovea is), and 90° would put an edge at infinity on the image plane.
pub fn parse_fov(s: &str) -> Result<Fov, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [l, r, u, d] = parts[..] else {
        return Err("expected four half-angles in degrees: left,right,up,down".into());
    };
    let mut tangents = [0.0f64; 4];
    for ((side, text), t) in ["left", "right", "up", "down"]
        .iter()
        .zip([l, r, u, d])
        .zip(&mut tangents)
    {
        let deg: f64 = text
            .parse()
            .map_err(|_| format!("{side} '{text}' is not a number of degrees"))?;
        if !(deg > 0.0 && deg < 90.0) {
            return Err(format!(
                "{side} {deg}°: expected a half-angle above 0° and below 90°"
            ));
        }
        *t = deg.to_radians().tan();
    }
    let [l, r, u, d] = tangents;
    Ok(Fov::from_tangents(l, r, u, d))
}

/// `--size WxH`: each side 16 to 16384 pixels, what Vulkan implementations allow for an image.
pub fn parse_size(s: &str) -> Result<[u32; 2], String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or("expected WIDTHxHEIGHT in pixels, e.g. 2000x2000")?;
    let side = |v: &str| -> Result<u32, String> {
        let n: u32 = v
            .trim()
            .parse()
            .map_err(|_| format!("'{v}' is not a whole number of pixels"))?;
        if (16..=16384).contains(&n) {
            Ok(n)
        } else {
            Err(format!("{n}: expected 16 to 16384 pixels"))
        }
    };
    Ok([side(w)?, side(h)?])
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_declaration_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn fov_and_size_parse_and_refuse_what_cannot_be_a_view() {
        let f = parse_fov("54,40,44,55").unwrap();
        let [l, r, u, d] = f.degrees();
        assert!((l - 54.0).abs() < 1e-4 && (r - 40.0).abs() < 1e-4);
        assert!((u - 44.0).abs() < 1e-4 && (d - 55.0).abs() < 1e-4);
        assert!(f.left < 0.0 && f.down < 0.0);
        for bad in [
            "45,45,45",
            "45,45,45,90",
            "0,45,45,45",
            "a,45,45,45",
            "-5,45,45,45",
        ] {
            assert!(parse_fov(bad).is_err(), "{bad}");
        }
        assert_eq!(parse_size("2000x1800").unwrap(), [2000, 1800]);
        for bad in ["2000", "2000x", "8x8", "20000x100", "axb"] {
            assert!(parse_size(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn levels_keep_their_indices_and_spellings() {
        let parse = |args: &[&str]| {
            let mut argv = vec!["fovea", "maps", "--headset", "quest3", "--out", "x"];
            argv.extend(args);
            Cli::try_parse_from(argv)
        };
        for (given, want) in [
            ("2", Level::Medium),
            ("HIGH", Level::High),
            ("hightop", Level::HighTop),
            ("high-top", Level::HighTop),
            ("off", Level::None),
        ] {
            let Command::Maps(m) = parse(&["--level", given]).unwrap().command else {
                panic!("maps");
            };
            assert_eq!(m.level, want, "{given}");
        }
        let Command::Maps(m) = parse(&["--level", "low", "--vertical-offset", "-5"])
            .unwrap()
            .command
        else {
            panic!("maps");
        };
        assert_eq!(m.vertical_offset, -5.0);
        assert!(parse(&["--level", "5"]).is_err());
    }
}
