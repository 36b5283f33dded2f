//! `fovea config [--app NAME] [--exe NAME] [--engine NAME] [--check]`: the settings fovea would use
//! for an application and where each value comes from (environment, a section of `fovea.toml`,
//! default), or, with `--check`, whether the file is valid (`problem:` lines, exit status 1).
//!
//! Resolution is `fovea_config`'s, the same code the layer runs.

use std::collections::BTreeMap;
use std::ffi::OsString;
use std::path::PathBuf;

use fovea_config::{Config, Fallback, Identity, Key, Source};

use crate::args::ConfigArgs;

/// The configuration file for `vars`, whether `FOVEA_CONFIG` chose it, and the file read (`None`:
/// missing; `Err`: unreadable).
pub struct Located {
    pub path: Option<PathBuf>,
    pub explicit: bool,
    pub file: Option<Result<Config, String>>,
}

/// Finds and reads the configuration file as the layer would under `vars`.
pub fn locate(vars: &BTreeMap<String, String>) -> Located {
    let get = |k: &str| vars.get(k).map(OsString::from);
    let path = fovea_config::config_path(get);
    let file = path.as_deref().and_then(|p| match Config::load(p) {
        Ok(c) => Some(Ok(c)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => Some(Err(format!("cannot read {}: {e}", p.display()))),
    });
    Located {
        path,
        explicit: vars.contains_key(fovea_config::env::CONFIG),
        file,
    }
}

/// What applies when nothing sets `key`: the table's default, with the log file's path as `vars`
/// make it.
fn default_of(key: Key, vars: &BTreeMap<String, String>) -> String {
    match key.default() {
        Fallback::LogPath => fovea_config::default_log_path(|k| vars.get(k).map(OsString::from))
            .map_or("none (no home folder)".into(), |p| {
                format!("{:?}", p.display().to_string())
            }),
        d => d.text(),
    }
}

/// The report for `id` under `vars`: the file, the sections that match, each key's value and source.
pub fn render(vars: &BTreeMap<String, String>, id: &Identity) -> String {
    let loc = locate(vars);
    let mut out = String::new();
    let mut line = |s: String| {
        out.push_str(&s);
        out.push('\n');
    };
    let config = match (&loc.path, &loc.file) {
        (None, _) => {
            line("configuration file: none (FOVEA_CONFIG is empty or no home folder)".into());
            None
        }
        (Some(p), None) => {
            line(format!(
                "configuration file: {} (not found: defaults apply)",
                p.display()
            ));
            None
        }
        (Some(_), Some(Err(e))) => {
            line(format!("configuration file: {e}"));
            None
        }
        (Some(p), Some(Ok(c))) => {
            line(format!(
                "configuration file: {} ({})",
                p.display(),
                match c.problems.len() {
                    0 => "valid".to_string(),
                    n => format!("{n} problems; `fovea config --check` lists them"),
                }
            ));
            Some(c)
        }
    };
    let who = [("app", &id.app), ("exe", &id.exe), ("engine", &id.engine)]
        .iter()
        .filter_map(|(k, v)| v.as_ref().map(|v| format!("{k} {v:?}")))
        .collect::<Vec<_>>();
    line(format!(
        "for: {}",
        if who.is_empty() {
            "any application (--app, --exe, --engine name one)".into()
        } else {
            who.join(", ")
        }
    ));
    if let Some(c) = config {
        let m: Vec<String> = c.matching(id).iter().map(|s| s.scope.header()).collect();
        line(format!(
            "matching sections, least specific first: {}",
            m.join(", ")
        ));
    }
    let (r, bad) = fovea_config::resolve(config, id, |k| vars.get(k).cloned());
    let width = Key::ALL.iter().map(|k| k.name().len()).max().unwrap_or(0);
    line(format!("{:<width$} {:<28} from", "setting", "value"));
    for key in Key::ALL {
        let value = r
            .get(key)
            .map_or_else(|| default_of(key, vars), ToString::to_string);
        let from = match r.source(key) {
            Source::Default => "default".to_string(),
            s => s.to_string(),
        };
        line(format!("{:<width$} {:<28} {from}", key.name(), value));
    }
    line(
        "precedence: environment and Quest debug properties > [app] > [exe] > [engine] > global \
         > the application's profile > defaults"
            .into(),
    );
    if let Some(forced) = vars.get(fovea_config::env::DEBUG_SUBSAMPLED) {
        line(format!(
            "{}={forced}: debug.oculus.foveation.subsampled wins over subsampled \
             (1 reconstructs every foveated swapchain, 0 none)",
            fovea_config::env::DEBUG_SUBSAMPLED
        ));
    }
    if let Some(props) = vars.get("FOVEA_PROPS") {
        line(format!(
            "FOVEA_PROPS={props}: its debug.oculus.foveation.* lines win over all of the above"
        ));
    }
    for (var, value, accepted) in bad {
        line(format!(
            "problem: {var}={value:?} is not valid ({accepted}); ignored"
        ));
    }
    out
}

/// The file's problems as `problem:` lines (empty: valid or absent).
pub fn check(vars: &BTreeMap<String, String>) -> (String, Vec<String>) {
    let loc = locate(vars);
    match (&loc.path, loc.file) {
        (None, _) => ("no configuration file\n".into(), Vec::new()),
        (Some(p), None) if loc.explicit => (
            String::new(),
            vec![format!(
                "FOVEA_CONFIG names {}, which does not exist: create it or unset FOVEA_CONFIG",
                p.display()
            )],
        ),
        (Some(p), None) => (
            format!("{} does not exist: defaults apply\n", p.display()),
            Vec::new(),
        ),
        (Some(_), Some(Err(e))) => (String::new(), vec![format!("{e}: fix its permissions")]),
        (Some(p), Some(Ok(c))) => (
            format!("{}: {} sections\n", p.display(), c.sections.len()),
            c.problems
                .iter()
                .map(|p| format!("{p}: fix or remove the line"))
                .collect(),
        ),
    }
}

pub fn run(args: &ConfigArgs) -> Result<(), String> {
    let vars = crate::discovery::process_vars();
    if args.check {
        let (text, problems) = check(&vars);
        print!("{text}");
        for p in &problems {
            println!("problem: {p}");
        }
        return match problems.len() {
            0 => {
                println!("ok");
                Ok(())
            }
            1 => Err("1 problem".into()),
            n => Err(format!("{n} problems")),
        };
    }
    let id = Identity {
        app: args.app.clone(),
        exe: args.exe.clone(),
        engine: args.engine.clone(),
    };
    print!("{}", render(&vars, &id));
    Ok(())
}
