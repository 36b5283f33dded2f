//! What the simulated headset is: preset, refresh rate, optional extensions, faults and load.
//!
//! A configuration is fixed when an instance is created. Tests pick one per thread with
//! [`set_thread_config`] (the fake loader calls down synchronously on the test's thread); everything
//! else, including the Khronos loader path, reads the `FOVEA_SIM_*` environment variables.

use std::cell::RefCell;

use fovea_model::headsets::Headset;
use openxr_sys as xr;

use crate::gaze_script::GazeScript;

/// The simulated runtime's settings, fixed for an instance at xrCreateInstance.
#[derive(Clone, Debug)]
pub struct SimConfig {
    /// Which headset the runtime pretends to be (FOVs and recommended sizes).
    pub headset: &'static Headset,
    /// Display refresh rate; the predicted display period is `1e9 / refresh_hz` ns.
    pub refresh_hz: f32,
    /// Offer XR_FB_swapchain_update_state (v3) without any state types of its own, so the layer's
    /// pass-through path for non-foveation states can be tested.
    pub native_swapchain_update_state: bool,
    /// Offer XR_FB_foveation (v1) and XR_FB_foveation_configuration (v1), with
    /// XR_FB_swapchain_update_state, natively, as a headset runtime does: profiles are created and
    /// applied with the spec's checks and recorded per swapchain (nothing renders differently). A
    /// layer above must pass them through, not shadow them.
    pub native_foveation: bool,
    /// With [`SimConfig::native_foveation`], also offer XR_META_foveation_eye_tracked (v1) natively
    /// (`FOVEA_SIM_META_EYE_TRACKED=1`): the system reports `supportsFoveationEyeTracked`, profiles
    /// accept `XrFoveationEyeTrackedProfileCreateInfoMETA`, and `xrGetFoveationEyeTrackedStateMETA`
    /// answers [`META_NATIVE_CENTRES`], VALID: an answer no layer computes, so a test sees whose
    /// answer reached the application.
    pub native_meta_eye_tracked: bool,
    /// Offer XR_EPIC_view_configuration_fov (v2), as Monado does: xrEnumerateViewConfigurationViews
    /// fills an `XrViewConfigurationViewFovEPIC` chained to each view with the headset's FOVs,
    /// without a session, where the instance enabled the extension
    /// (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#XR_EPIC_view_configuration_fov).
    pub view_configuration_fov: bool,
    /// xrWaitFrame also sleeps in real time until the frame should start (demo, real apps).
    pub realtime: bool,
    /// The runtime requests exit by itself after this many xrEndFrame calls.
    pub exit_after_frames: Option<u64>,
    /// How long an xrWaitFrame blocks on a previous waited frame that no xrBeginFrame has begun
    /// before it is refused with XR_ERROR_CALL_ORDER_INVALID (`FOVEA_SIM_WAIT_BLOCK_MS`, default
    /// 5000). The spec makes it block until the begin; a real runtime would block forever, which
    /// a single-threaded caller never escapes, so the simulation gives up instead. Random call
    /// sequences set it short.
    pub wait_block_ms: u64,
    /// Calls that fail on purpose.
    pub faults: Vec<Fault>,
    /// The application's simulated GPU time per frame.
    pub load: Load,
    /// Keep the call journal and the submitted views (`FOVEA_SIM_JOURNAL=0` turns it off): tests read
    /// it, but a benchmark running millions of frames must not grow memory without bound.
    pub journal: bool,
    /// Print one `fovea-sim: summary frames=N errors=M ...` line to stderr when the instance is
    /// destroyed (`FOVEA_SIM_SUMMARY=1`): an application run as a child process (hello_xr) has no
    /// other way to tell a test how many frames reached the runtime and which calls failed.
    pub summary: bool,
    /// Print one `fovea-sim: refused xrFoo: XR_ERROR_... (why)` line to stderr for every call the
    /// runtime refuses by its own rules (`FOVEA_SIM_LOG_REFUSALS=1`), as a real runtime such as
    /// Monado prints an error line: it shows, in any test's output, which component made a call a
    /// strict runtime refuses.
    pub log_refusals: bool,
    /// An eye tracker behind `XR_EXT_eye_gaze_interaction` (`FOVEA_SIM_EYE_GAZE`); `None` offers
    /// no such extension.
    pub eye_gaze: Option<EyeGaze>,
}

/// The foveation centres (left, right; NDC) the native XR_META_foveation_eye_tracked answers
/// ([`SimConfig::native_meta_eye_tracked`]).
pub const META_NATIVE_CENTRES: [[f32; 2]; 2] = [[0.125, -0.375], [-0.125, -0.375]];

/// The simulated eye tracker: what the runtime says of it and where the eye looks.
#[derive(Clone, Debug, PartialEq)]
pub struct EyeGaze {
    /// `XrSystemEyeGazeInteractionPropertiesEXT::supportsEyeGazeInteraction`. `false` is what
    /// Monado's simulated headset reports: the extension listed, no tracker behind it, the action
    /// never active.
    pub supported: bool,
    /// Refuse a gaze action space before the application attached its set (some runtimes, VDXR
    /// among them, cannot make one earlier): `FOVEA_SIM_GAZE_SPACE_AFTER_ATTACH=1`.
    pub space_after_attach: bool,
    /// Where the eye looks (`FOVEA_SIM_GAZE`; empty: straight ahead), from session creation on.
    pub script: GazeScript,
}

/// A call that fails on purpose: `function` returns `result` without doing anything.
#[derive(Clone, Debug, PartialEq)]
pub struct Fault {
    /// The OpenXR command name, e.g. `xrCreateSwapchain`.
    pub function: String,
    /// The result to return.
    pub result: xr::Result,
    /// 1-based count of calls to `function` in the instance that fails; 0 fails every call.
    pub nth: u32,
}

/// The app's GPU time per frame, piecewise constant: `(first_frame, ms)` pairs, sorted or not; frame
/// `n` uses the entry with the largest `first_frame <= n`. Frames before the first entry take no time.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Load {
    pub gpu_ms: Vec<(u64, f32)>,
}

impl Load {
    /// A constant load from frame 0 on.
    pub fn constant(ms: f32) -> Load {
        Load {
            gpu_ms: vec![(0, ms)],
        }
    }

    /// The GPU time of frame `frame` (0-based, counted by xrWaitFrame) in milliseconds.
    pub fn gpu_ms_at(&self, frame: u64) -> f32 {
        self.gpu_ms
            .iter()
            .filter(|(first, _)| *first <= frame)
            .max_by_key(|(first, _)| *first)
            .map_or(0.0, |(_, ms)| *ms)
    }
}

impl Default for SimConfig {
    fn default() -> Self {
        let headset = fovea_model::headsets::by_id("quest3").expect("quest3 preset exists");
        SimConfig {
            headset,
            refresh_hz: headset.refresh_hz,
            native_swapchain_update_state: false,
            native_foveation: false,
            native_meta_eye_tracked: false,
            view_configuration_fov: false,
            realtime: false,
            exit_after_frames: None,
            wait_block_ms: 5000,
            faults: Vec::new(),
            load: Load::default(),
            journal: true,
            summary: false,
            log_refusals: false,
            eye_gaze: None,
        }
    }
}

impl SimConfig {
    /// The configuration for a headset preset with its own refresh rate and nothing else set.
    pub fn for_headset(headset: &'static Headset) -> SimConfig {
        SimConfig {
            headset,
            refresh_hz: headset.refresh_hz,
            ..SimConfig::default()
        }
    }

    /// Reads `FOVEA_SIM_HEADSET`, `FOVEA_SIM_REFRESH_HZ`, `FOVEA_SIM_NATIVE_UPDATE_STATE`,
    /// `FOVEA_SIM_NATIVE_FOVEATION`, `FOVEA_SIM_META_EYE_TRACKED`, `FOVEA_SIM_VIEW_CONFIGURATION_FOV`,
    /// `FOVEA_SIM_REALTIME`, `FOVEA_SIM_JOURNAL`, `FOVEA_SIM_SUMMARY`, `FOVEA_SIM_LOG_REFUSALS`,
    /// `FOVEA_SIM_EXIT_AFTER_FRAMES`, `FOVEA_SIM_WAIT_BLOCK_MS`,
    /// `FOVEA_SIM_FAULT`, `FOVEA_SIM_LOAD`, and the eye tracker's `FOVEA_SIM_EYE_GAZE` (`on`,
    /// `unsupported` or `off`), `FOVEA_SIM_GAZE` (a script, [`GazeScript`]) and
    /// `FOVEA_SIM_GAZE_SPACE_AFTER_ATTACH`.
    /// The error names the variable and what it accepts.
    pub fn from_env() -> Result<SimConfig, String> {
        Self::from_vars(|name| std::env::var(name).ok())
    }

    /// [`SimConfig::from_env`] over any variable source (unit tests do not touch the process
    /// environment).
    pub fn from_vars(var: impl Fn(&str) -> Option<String>) -> Result<SimConfig, String> {
        let mut cfg = SimConfig::default();
        if let Some(id) = var("FOVEA_SIM_HEADSET") {
            cfg = SimConfig::for_headset(fovea_model::headsets::by_id(id.trim()).ok_or_else(
                || {
                    let ids: Vec<_> = fovea_model::headsets::ids().collect();
                    format!(
                        "FOVEA_SIM_HEADSET={id:?}: unknown headset; accepted: {}",
                        ids.join(", ")
                    )
                },
            )?);
        }
        if let Some(v) = var("FOVEA_SIM_REFRESH_HZ") {
            cfg.refresh_hz = v
                .trim()
                .parse::<f32>()
                .ok()
                .filter(|hz| hz.is_finite() && (1.0..=1000.0).contains(hz))
                .ok_or_else(|| {
                    format!("FOVEA_SIM_REFRESH_HZ={v:?}: expected a number of Hz in 1..=1000")
                })?;
        }
        cfg.native_swapchain_update_state = flag(&var, "FOVEA_SIM_NATIVE_UPDATE_STATE")?;
        cfg.native_foveation = flag(&var, "FOVEA_SIM_NATIVE_FOVEATION")?;
        cfg.native_meta_eye_tracked = flag(&var, "FOVEA_SIM_META_EYE_TRACKED")?;
        cfg.view_configuration_fov = flag(&var, "FOVEA_SIM_VIEW_CONFIGURATION_FOV")?;
        cfg.realtime = flag(&var, "FOVEA_SIM_REALTIME")?;
        cfg.summary = flag(&var, "FOVEA_SIM_SUMMARY")?;
        cfg.log_refusals = flag(&var, "FOVEA_SIM_LOG_REFUSALS")?;
        if var("FOVEA_SIM_JOURNAL").is_some() {
            cfg.journal = flag(&var, "FOVEA_SIM_JOURNAL")?;
        }
        if let Some(v) = var("FOVEA_SIM_EXIT_AFTER_FRAMES") {
            cfg.exit_after_frames = Some(v.trim().parse::<u64>().map_err(|_| {
                format!(
                    "FOVEA_SIM_EXIT_AFTER_FRAMES={v:?}: expected a frame count (unsigned integer)"
                )
            })?);
        }
        if let Some(v) = var("FOVEA_SIM_WAIT_BLOCK_MS") {
            cfg.wait_block_ms = v.trim().parse::<u64>().map_err(|_| {
                format!("FOVEA_SIM_WAIT_BLOCK_MS={v:?}: expected milliseconds (unsigned integer)")
            })?;
        }
        if let Some(v) = var("FOVEA_SIM_FAULT") {
            cfg.faults = parse_faults(&v).map_err(|e| format!("FOVEA_SIM_FAULT={v:?}: {e}"))?;
        }
        if let Some(v) = var("FOVEA_SIM_LOAD") {
            cfg.load = parse_load(&v).map_err(|e| format!("FOVEA_SIM_LOAD={v:?}: {e}"))?;
        }
        let supported = match var("FOVEA_SIM_EYE_GAZE").as_deref().map(str::trim) {
            None | Some("" | "off") => None,
            Some("on") => Some(true),
            Some("unsupported") => Some(false),
            Some(other) => {
                return Err(format!(
                    "FOVEA_SIM_EYE_GAZE={other:?}: expected on, unsupported or off"
                ))
            }
        };
        if let Some(supported) = supported {
            let text = var("FOVEA_SIM_GAZE").unwrap_or_default();
            cfg.eye_gaze = Some(EyeGaze {
                supported,
                space_after_attach: flag(&var, "FOVEA_SIM_GAZE_SPACE_AFTER_ATTACH")?,
                script: GazeScript::parse(&text)
                    .map_err(|e| format!("FOVEA_SIM_GAZE={text:?}: {e}"))?,
            });
        }
        Ok(cfg)
    }

    /// The predicted display period in nanoseconds.
    pub fn period_ns(&self) -> i64 {
        (1e9 / f64::from(self.refresh_hz)).round() as i64
    }
}

fn flag(var: &impl Fn(&str) -> Option<String>, name: &str) -> Result<bool, String> {
    match var(name).as_deref().map(str::trim) {
        None | Some("" | "0") => Ok(false),
        Some("1") => Ok(true),
        Some(other) => Err(format!("{name}={other:?}: expected 0 or 1")),
    }
}

/// `function:result[@nth]`, comma-separated; `result` is a signed XrResult number.
fn parse_faults(s: &str) -> Result<Vec<Fault>, String> {
    const FORM: &str =
        "expected a comma-separated list of function:result[@nth], e.g. xrCreateSwapchain:-2@1";
    s.split(',')
        .filter(|item| !item.trim().is_empty())
        .map(|item| {
            let (function, rest) = item.trim().split_once(':').ok_or(FORM)?;
            let (result, nth) = match rest.split_once('@') {
                Some((r, n)) => (r, n.trim().parse::<u32>().map_err(|_| FORM)?),
                None => (rest, 0),
            };
            let result = result.trim().parse::<i32>().map_err(|_| FORM)?;
            if !function.starts_with("xr") {
                return Err(FORM.to_string());
            }
            Ok(Fault {
                function: function.trim().to_string(),
                result: xr::Result::from_raw(result),
                nth,
            })
        })
        .collect()
}

/// `gpu_ms@first_frame`, comma-separated.
fn parse_load(s: &str) -> Result<Load, String> {
    const FORM: &str = "expected a comma-separated list of gpu_ms@first_frame, e.g. 8@0,14@100";
    let gpu_ms = s
        .split(',')
        .filter(|item| !item.trim().is_empty())
        .map(|item| {
            let (ms, frame) = item.trim().split_once('@').ok_or(FORM)?;
            let ms = ms
                .trim()
                .parse::<f32>()
                .ok()
                .filter(|m| m.is_finite() && *m >= 0.0)
                .ok_or(FORM)?;
            let frame = frame.trim().parse::<u64>().map_err(|_| FORM)?;
            Ok((frame, ms))
        })
        .collect::<Result<Vec<_>, String>>()?;
    Ok(Load { gpu_ms })
}

thread_local! {
    static THREAD_CONFIG: RefCell<Option<SimConfig>> = const { RefCell::new(None) };
}

/// Sets the configuration that instances created (and extension lists enumerated) on this thread use;
/// `None` goes back to [`SimConfig::from_env`].
pub fn set_thread_config(cfg: Option<SimConfig>) {
    THREAD_CONFIG.with(|c| *c.borrow_mut() = cfg);
}

/// The configuration in force on this thread. A bad environment is reported on stderr and replaced
/// by the defaults: a runtime has no other channel before an instance exists.
pub(crate) fn current() -> SimConfig {
    if let Some(mut cfg) = THREAD_CONFIG.with(|c| c.borrow().clone()) {
        // A diagnostic, not a property of the headset: the environment turns it on for tests
        // that pick their configuration in code too.
        cfg.log_refusals |= std::env::var("FOVEA_SIM_LOG_REFUSALS").is_ok_and(|v| v.trim() == "1");
        return cfg;
    }
    SimConfig::from_env().unwrap_or_else(|e| {
        eprintln!("fovea-sim: {e}; using the defaults");
        SimConfig::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vars<'a>(list: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |name| {
            list.iter()
                .find(|(k, _)| *k == name)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn defaults_are_quest3_at_its_rate() {
        let cfg = SimConfig::from_vars(|_| None).unwrap();
        assert_eq!(cfg.headset.id, "quest3");
        assert_eq!(cfg.refresh_hz, 90.0);
        assert_eq!(cfg.period_ns(), 11_111_111);
        assert!(!cfg.native_swapchain_update_state && !cfg.realtime);
    }

    #[test]
    fn parses_every_variable() {
        let cfg = SimConfig::from_vars(vars(&[
            ("FOVEA_SIM_HEADSET", "rift-s"),
            ("FOVEA_SIM_REFRESH_HZ", "120"),
            ("FOVEA_SIM_NATIVE_UPDATE_STATE", "1"),
            ("FOVEA_SIM_NATIVE_FOVEATION", "1"),
            ("FOVEA_SIM_REALTIME", "1"),
            ("FOVEA_SIM_SUMMARY", "1"),
            ("FOVEA_SIM_LOG_REFUSALS", "1"),
            ("FOVEA_SIM_EXIT_AFTER_FRAMES", "30"),
            ("FOVEA_SIM_WAIT_BLOCK_MS", "7"),
            ("FOVEA_SIM_FAULT", "xrCreateSwapchain:-2@2, xrEndFrame:-17"),
            ("FOVEA_SIM_LOAD", "8@0,14@100"),
            ("FOVEA_SIM_EYE_GAZE", "on"),
            ("FOVEA_SIM_GAZE", "fix 10,5 for 1s"),
            ("FOVEA_SIM_GAZE_SPACE_AFTER_ATTACH", "1"),
        ]))
        .unwrap();
        assert_eq!(cfg.headset.id, "rift-s");
        assert_eq!(cfg.refresh_hz, 120.0);
        assert!(cfg.native_swapchain_update_state && cfg.realtime && cfg.summary);
        assert!(cfg.log_refusals && cfg.native_foveation);
        assert_eq!(cfg.exit_after_frames, Some(30));
        assert_eq!(cfg.wait_block_ms, 7);
        assert_eq!(
            cfg.faults,
            [
                Fault {
                    function: "xrCreateSwapchain".into(),
                    result: xr::Result::ERROR_RUNTIME_FAILURE,
                    nth: 2
                },
                Fault {
                    function: "xrEndFrame".into(),
                    result: xr::Result::ERROR_SESSION_LOST,
                    nth: 0
                },
            ]
        );
        assert_eq!(cfg.load.gpu_ms_at(0), 8.0);
        assert_eq!(cfg.load.gpu_ms_at(99), 8.0);
        assert_eq!(cfg.load.gpu_ms_at(100), 14.0);
        let gaze = cfg.eye_gaze.unwrap();
        assert!(gaze.supported && gaze.space_after_attach);
        assert_eq!(gaze.script.eye_at(0), Some([10.0, 5.0]));
        let listed = SimConfig::from_vars(vars(&[("FOVEA_SIM_EYE_GAZE", "unsupported")])).unwrap();
        assert_eq!(listed.eye_gaze.map(|g| g.supported), Some(false));
    }

    #[test]
    fn errors_name_the_variable_and_the_accepted_values() {
        let e = SimConfig::from_vars(vars(&[("FOVEA_SIM_HEADSET", "quest9")])).unwrap_err();
        assert!(
            e.contains("FOVEA_SIM_HEADSET") && e.contains("quest3") && e.contains("pico4"),
            "{e}"
        );
        for (name, bad) in [
            ("FOVEA_SIM_REFRESH_HZ", "fast"),
            ("FOVEA_SIM_REALTIME", "yes"),
            ("FOVEA_SIM_EXIT_AFTER_FRAMES", "-1"),
            ("FOVEA_SIM_FAULT", "xrEndFrame"),
            ("FOVEA_SIM_LOAD", "8"),
            ("FOVEA_SIM_EYE_GAZE", "yes"),
        ] {
            let e = SimConfig::from_vars(vars(&[(name, bad)])).unwrap_err();
            assert!(e.starts_with(name), "{e}");
        }
        let e = SimConfig::from_vars(vars(&[
            ("FOVEA_SIM_EYE_GAZE", "on"),
            ("FOVEA_SIM_GAZE", "wink 1s"),
        ]))
        .unwrap_err();
        assert!(
            e.starts_with("FOVEA_SIM_GAZE=") && e.contains("step 1"),
            "{e}"
        );
    }

    #[test]
    fn thread_config_overrides_and_resets() {
        let mut cfg = SimConfig::for_headset(fovea_model::headsets::by_id("index").unwrap());
        cfg.native_swapchain_update_state = true;
        set_thread_config(Some(cfg));
        assert_eq!(current().headset.id, "index");
        set_thread_config(None);
        let from_env = SimConfig::from_env().map_or("quest3", |c| c.headset.id);
        assert_eq!(current().headset.id, from_env);
    }
}
