//! What one run of the injection tests' application left ([`Outcome`]), what fovea's model gives
//! ([`expected`]) and what must reach the driver ([`assert_outcome`]).

use ash::vk;
use fovea_model::density::{Level, Pattern};
use fovea_model::inject::Views;
use fovea_model::maps::MAX_VIEWS;
use fovea_model::Fov;
use fovea_vkdouble::Profile;
use serde_json::{json, Value};

use crate::support::device::inject_device;
use crate::support::in_own_process;

use super::app::*;

/// What one run left behind.
pub(super) struct Outcome {
    pub(super) events: Vec<Value>,
    pub(super) command_buffer: u64,
    /// With a refresh: the command buffer recorded after the level changed.
    pub(super) second: Option<u64>,
    pub(super) fovs: [Fov; 2],
    pub(super) log: String,
    /// [`Setup::AppRates`]: the application's own shading-rate view.
    pub(super) apps_view: Option<u64>,
}

impl Outcome {
    pub(super) fn of(&self, kind: &str) -> Vec<&Value> {
        self.events.iter().filter(|e| e["kind"] == kind).collect()
    }

    /// The shading-rate view of each of the test's three renderings or passes as the driver got
    /// them, in order (`Null` for none).
    pub(super) fn rates(&self, api: Api) -> Vec<Value> {
        let kind = if api.dynamic() {
            "begin_rendering"
        } else {
            "begin_render_pass"
        };
        let r: Vec<Value> = self
            .of(kind)
            .into_iter()
            .filter(|b| b["command_buffer"] == json!(self.command_buffer))
            .map(|b| {
                if api.dynamic() {
                    b["shading_rate"].clone()
                } else {
                    let v = b["shading_rate_views"]
                        .as_array()
                        .cloned()
                        .unwrap_or_default();
                    assert!(v.len() <= 1, "{b}");
                    v.first().cloned().unwrap_or(Value::Null)
                }
            })
            .collect();
        assert_eq!(r.len(), 3, "{r:?}");
        r
    }

    /// How many `VkRenderingFragmentShadingRateAttachmentInfoKHR`s the driver got in each of the
    /// test's three renderings.
    pub(super) fn rate_structs(&self) -> Vec<u64> {
        self.of("begin_rendering")
            .into_iter()
            .filter(|b| b["command_buffer"] == json!(self.command_buffer))
            .map(|b| b["shading_rate_structs"].as_u64().unwrap())
            .collect()
    }

    /// What the submit of the test's command buffer read of `image`: (extent, layers, codes).
    pub(super) fn codes_of(&self, image: &Value) -> ([u32; 2], u32, Vec<u8>) {
        self.codes_in(self.command_buffer, image)
    }

    /// What the submit of command buffer `cb` read of `image`.
    pub(super) fn codes_in(&self, cb: u64, image: &Value) -> ([u32; 2], u32, Vec<u8>) {
        let submits: Vec<&Value> = self
            .of("submit")
            .into_iter()
            .filter(|s| {
                s["command_buffers"]
                    .as_array()
                    .unwrap()
                    .contains(&json!(cb))
            })
            .collect();
        assert_eq!(submits.len(), 1, "{submits:?}");
        let read = submits[0]["shading_rate_images"].as_array().unwrap();
        let r = read
            .iter()
            .find(|r| &r["image"] == image)
            .unwrap_or_else(|| panic!("{image} not read at submit: {read:?}"));
        let e = r["extent"].as_array().unwrap();
        (
            [e[0].as_u64().unwrap() as u32, e[1].as_u64().unwrap() as u32],
            r["layers"].as_u64().unwrap() as u32,
            r["codes"]
                .as_array()
                .unwrap()
                .iter()
                .map(|c| c.as_u64().unwrap() as u8)
                .collect(),
        )
    }

    /// What each draw of the test's `pass`-th pass or rendering shaded at, per view: its
    /// effective fragment size per shading-rate attachment texel, as the GPU the double plays
    /// computes it.
    pub(super) fn effective(&self, pass: usize) -> Vec<Vec<fovea_vkdouble::ViewRates>> {
        let draws: Vec<Vec<fovea_vkdouble::ViewRates>> = self
            .of("draw")
            .into_iter()
            .filter(|d| d["command_buffer"] == json!(self.command_buffer) && d["pass"] == pass)
            .map(|d| {
                d["views"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|v| fovea_vkdouble::ViewRates {
                        view: v["view"].as_u64().unwrap() as u32,
                        layer: v["layer"].as_u64().map(|l| l as u32),
                        columns: v["columns"].as_u64().unwrap() as u32,
                        rows: v["rows"].as_u64().unwrap() as u32,
                        codes: v["codes"]
                            .as_str()
                            .unwrap()
                            .chars()
                            .map(|c| c.to_digit(16).unwrap() as u8)
                            .collect(),
                    })
                    .collect()
            })
            .collect();
        assert!(!draws.is_empty(), "no draw in pass {pass}");
        draws
    }

    /// The shading-rate image a view the double saw made is of.
    pub(super) fn image_of(&self, view: &Value) -> Value {
        self.of("image_view")
            .into_iter()
            .find(|v| &v["view"] == view)
            .unwrap_or_else(|| panic!("no shading-rate view {view}"))["image"]
            .clone()
    }
}

/// What fovea's model gives a map for `views` over a 640×500 target on `profile`.
pub(super) fn expected(
    profile: Profile,
    views: Views,
    fovs: [Fov; 2],
    level: Level,
) -> ([u32; 2], u32, Vec<u8>) {
    let device = inject_device(profile);
    let mut all = [None; MAX_VIEWS];
    all[0] = Some(fovs[0]);
    all[1] = Some(fovs[1]);
    fovea_model::inject::codes(
        &device,
        views,
        [WIDTH, HEIGHT],
        &all,
        Pattern {
            level,
            vertical_offset_deg: 0.0,
        },
        fovea_model::maps::DEFAULT_MAX_FRAGMENT,
    )
}

/// Runs `setup` with `api` on both profiles in a child process of its own (the test `test` of
/// `module`, its `module_path!()`) and checks the outcome.
pub(super) fn check(module: &str, test: &str, setup: Setup, api: Api, levels: &[Level]) {
    in_own_process(module, test, || {
        for profile in [Profile::Nvidia, Profile::Amd] {
            let setups: Vec<Setup> = match setup {
                Setup::Inject(_) | Setup::SetsRates(Some(_)) => {
                    levels.iter().map(|&l| setup.at(l)).collect()
                }
                s => vec![s],
            };
            for s in setups {
                let dir = set_up(&format!("{test}-{profile:?}"), s);
                let Some(out) = run(profile, s, api, &dir) else {
                    return;
                };
                assert_outcome(profile, s, api, &out);
            }
        }
    });
}

pub(super) fn assert_outcome(profile: Profile, setup: Setup, api: Api, out: &Outcome) {
    let what = format!("{profile:?} {setup:?} {api:?}");
    let devices = out.of("device");
    assert_eq!(devices.len(), 1, "{what}: {devices:?}");
    let pipelines = out.of("pipeline");
    assert_eq!(pipelines.len(), 1, "{what}: {pipelines:?}");
    let passes = out.of("render_pass");
    let sets_rates = matches!(setup, Setup::SetsRates(_) | Setup::Vkd3d(_));
    let vkd3d = matches!(setup, Setup::Vkd3d(_));
    // The application's own rates: the pipeline's dynamic state and, per pass, its 1×1.
    let sets: Vec<&Value> = out
        .of("set_fragment_shading_rate")
        .into_iter()
        .filter(|s| s["command_buffer"] == json!(out.command_buffer))
        .collect();
    assert_eq!(sets.len(), if sets_rates { 3 } else { 0 }, "{what}");
    assert_eq!(pipelines[0]["dynamic_rate"], sets_rates, "{what}");
    let ops = |o: [vk::FragmentShadingRateCombinerOpKHR; 2]| json!([o[0].as_raw(), o[1].as_raw()]);
    let Some(level) = setup.level() else {
        // Nothing of fovea's: no shading rates added to the device, no flag or state on the
        // pipeline, no attachment in any pass or rendering; an application's own rates as it set
        // them.
        let enabled = vkd3d;
        assert_eq!(
            devices[0]["features"]["attachment"]
                .as_bool()
                .unwrap_or(false),
            enabled,
            "{what}: {}",
            devices[0]
        );
        assert_eq!(
            devices[0]["features"]["pipeline"]
                .as_bool()
                .unwrap_or(false),
            sets_rates,
            "{what}: {}",
            devices[0]
        );
        assert_eq!(
            pipelines[0]["rendering_attachment_flag"],
            vkd3d && api.dynamic(),
            "{what}"
        );
        let own = sets_rates.then(|| json!({"fragment_size": [2, 2], "combiner_ops": ops(KEEP)}));
        assert_eq!(
            pipelines[0]["shading_rate_state"],
            own.unwrap_or(Value::Null),
            "{what}"
        );
        for s in &sets {
            assert_eq!(s["fragment_size"], json!([1, 1]), "{what}: {s}");
            assert_eq!(s["combiner_ops"], ops(KEEP), "{what}: {s}");
        }
        // (The double records passes and begins only where shading rates are in play.)
        for p in &passes {
            assert_eq!(p["attachments"].as_array().unwrap().len(), 1, "{what}: {p}");
            assert_eq!(
                p["subpasses"][0]["shading_rate"],
                Value::Null,
                "{what}: {p}"
            );
        }
        for b in out.of("begin_rendering") {
            assert_eq!(b["shading_rate"], Value::Null, "{what}: {b}");
        }
        for b in out.of("begin_render_pass") {
            assert_eq!(b["shading_rate_views"], json!([]), "{what}: {b}");
        }
        if api.dynamic() {
            assert_eq!(out.rates(api), vec![Value::Null; 3], "{what}");
            assert_eq!(out.rate_structs(), vec![u64::from(vkd3d); 3], "{what}");
        }
        assert!(
            !out.log.contains("injected shading-rate map"),
            "{what}: {}",
            out.log
        );
        // What the GPU shades: full rate everywhere, unless the application asked otherwise.
        if !sets_rates {
            for pass in 0..3 {
                for draw in out.effective(pass) {
                    for v in &draw {
                        assert!(
                            v.codes.iter().all(|&c| c == 0),
                            "{what}: pass {pass} shades at full rate: {v:?}"
                        );
                    }
                }
            }
        }
        return;
    };
    if setup == Setup::AppRates {
        return assert_apps_own(profile, api, out, level);
    }
    assert_eq!(
        passes.len(),
        usize::from(!api.dynamic()),
        "{what}: {passes:?}"
    );
    let rates = out.rates(api);
    let texel = profile.texel();
    // The attachment feature added; an application's own features kept.
    assert_eq!(
        devices[0]["features"],
        json!({"pipeline": sets_rates, "primitive": false, "attachment": true}),
        "{what}: {}",
        devices[0]
    );
    // The flag is for dynamic rendering; a render pass carries its attachment itself.
    assert_eq!(
        pipelines[0]["rendering_attachment_flag"],
        api.dynamic(),
        "{what}"
    );
    // An application's own rate and first combiner stay, and the attachment applies on top: MAX,
    // both profiles reporting fragmentShadingRateNonTrivialCombinerOps as the drivers they stand
    // for do. Without it, REPLACE where the application's rate is 1×1 (its calls), and its own
    // KEEP where it asked for coarser (its pipeline's 2×2).
    let trivial = std::env::var_os(fovea_vkdouble::TRIVIAL_COMBINERS_ENV).is_some();
    let (own_op, max) = if trivial {
        (
            vk::FragmentShadingRateCombinerOpKHR::KEEP,
            vk::FragmentShadingRateCombinerOpKHR::REPLACE,
        )
    } else {
        (
            vk::FragmentShadingRateCombinerOpKHR::MAX,
            vk::FragmentShadingRateCombinerOpKHR::MAX,
        )
    };
    let state = if sets_rates {
        json!({"fragment_size": [2, 2], "combiner_ops": ops([KEEP[0], own_op])})
    } else {
        json!({"fragment_size": [1, 1], "combiner_ops": ops([
            vk::FragmentShadingRateCombinerOpKHR::KEEP,
            vk::FragmentShadingRateCombinerOpKHR::REPLACE,
        ])})
    };
    assert_eq!(pipelines[0]["shading_rate_state"], state, "{what}");
    for s in &sets {
        assert_eq!(s["fragment_size"], json!([1, 1]), "{what}: its rate: {s}");
        assert_eq!(s["combiner_ops"], ops([KEEP[0], max]), "{what}: {s}");
    }
    if sets_rates {
        assert!(
            out.log.contains(&format!(
                "the application sets shading rates per pipeline or per draw: injected maps are \
                 combined with its rates non_trivial_combiners={}",
                !trivial
            )),
            "{what}: {}",
            out.log
        );
    }
    for p in &passes {
        let atts = p["attachments"].as_array().unwrap();
        assert_eq!(atts.len(), 2, "{what}: {p}");
        assert_eq!(atts[1]["format"], vk::Format::R8_UINT.as_raw(), "{what}");
        assert_eq!(
            p["subpasses"][0]["shading_rate"],
            json!({"attachment": 1, "layout": FSR_LAYOUT.as_raw(),
                   "texel": [texel.width, texel.height]}),
            "{what}: {p}"
        );
    }
    if api.dynamic() {
        for r in [&rates[0], &rates[2]] {
            assert_eq!(r["layout"], FSR_LAYOUT.as_raw(), "{what}: {r}");
            assert_eq!(r["texel"], json!([texel.width, texel.height]), "{what}");
        }
        // One struct in each eye rendering (vkd3d-proton's null-view one replaced by fovea's);
        // the small target's as the application chained it.
        assert_eq!(out.rate_structs(), vec![1, u64::from(vkd3d), 1], "{what}");
    }
    assert!(
        !out.log.contains("a shading-rate attachment of its own"),
        "{what}: {}",
        out.log
    );
    let view_of = |r: &Value| {
        if api.dynamic() {
            r["view"].clone()
        } else {
            r.clone()
        }
    };
    // The swapchain image (view 0) and the eye-shaped target of the application's own (both
    // eyes merged) get maps; in a multiview rendering both hold both views, layer by layer (on
    // `amd`, without layered attachments, merged into one).
    let (swapchain_views, own_views) = if api == Api::Multiview {
        let both = Views::Layers { first: 0, count: 2 };
        (both, both)
    } else {
        (Views::Layers { first: 0, count: 1 }, Views::Merged)
    };
    for (r, views) in [(&rates[0], swapchain_views), (&rates[2], own_views)] {
        let image = out.image_of(&view_of(r));
        let got = out.codes_of(&image);
        let want = expected(profile, views, out.fovs, level);
        assert_eq!(
            (got.0, got.1),
            (want.0, want.1),
            "{what} {views:?}: extent, layers"
        );
        let texels = (want.0[0] * want.0[1]) as usize;
        if level == Level::None {
            assert!(
                want.2.iter().all(|&c| c == 0),
                "{what}: level none is full rate"
            );
        } else {
            assert!(
                want.2.iter().any(|&c| c != 0),
                "{what}: {level:?} coarsens somewhere"
            );
        }
        // What the GPU shades: every draw of the pass, every view (its layer of the map where the
        // map is layered, else the one layer), the model's rates texel for texel.
        let pass = if std::ptr::eq(r, &rates[0]) { 0 } else { 2 };
        for draw in out.effective(pass) {
            let view_count = if api == Api::Multiview { 2 } else { 1 };
            assert_eq!(draw.len(), view_count, "{what}: pass {pass}: {draw:?}");
            for v in &draw {
                let layer = if want.1 > 1 { v.view as usize } else { 0 };
                assert_eq!([v.columns, v.rows], want.0, "{what}: pass {pass}");
                assert!(
                    v.codes[..] == want.2[layer * texels..(layer + 1) * texels],
                    "{what} {views:?}: pass {pass} view {}: the effective rates differ from \
                     the model",
                    v.view
                );
            }
        }
    }
    // Off the eyes, full rate: every draw of the small target's pass, everywhere.
    for draw in out.effective(1) {
        for v in &draw {
            assert!(
                v.codes.iter().all(|&c| c == 0),
                "{what}: the small target shades at full rate: {v:?}"
            );
        }
    }
    if api == Api::Multiview {
        assert_eq!(
            view_of(&rates[0]),
            view_of(&rates[2]),
            "{what}: one map per shape and views"
        );
        let (_, layers, _) = out.codes_of(&out.image_of(&view_of(&rates[0])));
        assert_eq!(layers, if profile.layered() { 2 } else { 1 }, "{what}");
    } else {
        assert_ne!(
            view_of(&rates[0]),
            view_of(&rates[2]),
            "{what}: one map per shape and views"
        );
    }
    // The small target: no attachment in a rendering; a full-rate map covering it in a pass.
    if api.dynamic() {
        assert_eq!(rates[1], Value::Null, "{what}: small target");
    } else {
        let (extent, layers, codes) = out.codes_of(&out.image_of(&rates[1]));
        let n = [SMALL.div_ceil(texel.width), SMALL.div_ceil(texel.height)];
        assert_eq!((extent, layers), (n, 1), "{what}: the full-rate map");
        assert!(codes.iter().all(|&c| c == 0), "{what}: full rate");
    }
}

/// [`Setup::AppRates`]: the application's own view reaches the driver in the swapchain's
/// rendering, fovea's map in the eye-shaped target's (which names none), and the log says once
/// that the application's own attachment wins.
pub(super) fn assert_apps_own(profile: Profile, api: Api, out: &Outcome, level: Level) {
    let what = format!("{profile:?} AppRates {api:?}");
    let devices = out.of("device");
    assert_eq!(
        devices[0]["features"],
        json!({"pipeline": false, "primitive": false, "attachment": true}),
        "{what}: {}",
        devices[0]
    );
    let pipelines = out.of("pipeline");
    let apps = json!(out.apps_view.expect("the application's view"));
    let once = || {
        assert_eq!(
            out.log
                .matches("the application uses a shading-rate attachment of its own")
                .count(),
            1,
            "{what}: {}",
            out.log
        )
    };
    if api == Api::Imageless {
        // The application's render pass names its own attachment: the pass, its framebuffers'
        // attachments and its pipeline (no shading-rate state: the application's attachment is
        // not applied, as it chose) as it made them.
        let passes = out.of("render_pass");
        assert_eq!(passes.len(), 1, "{what}: {passes:?}");
        let texel = profile.texel();
        assert_eq!(
            passes[0]["attachments"].as_array().unwrap().len(),
            2,
            "{what}: {}",
            passes[0]
        );
        assert_eq!(
            passes[0]["subpasses"][0]["shading_rate"],
            json!({"attachment": 1, "layout": FSR_LAYOUT.as_raw(),
                   "texel": [texel.width, texel.height]}),
            "{what}: {}",
            passes[0]
        );
        assert_eq!(pipelines[0]["rendering_attachment_flag"], false, "{what}");
        assert_eq!(pipelines[0]["shading_rate_state"], Value::Null, "{what}");
        assert_eq!(out.rates(api), vec![apps.clone(); 3], "{what}");
        return once();
    }
    assert_eq!(pipelines[0]["rendering_attachment_flag"], true, "{what}");
    // The application's own state, which lets its attachment decide: kept.
    assert_eq!(
        pipelines[0]["shading_rate_state"],
        json!({"fragment_size": [1, 1], "combiner_ops": [
            vk::FragmentShadingRateCombinerOpKHR::KEEP.as_raw(),
            vk::FragmentShadingRateCombinerOpKHR::REPLACE.as_raw(),
        ]}),
        "{what}"
    );
    let rates = out.rates(api);
    assert_eq!(rates[0]["view"], apps, "{what}: the application's own view");
    assert_eq!(rates[1], Value::Null, "{what}: small target");
    assert_ne!(rates[2]["view"], apps, "{what}");
    let got = out.codes_of(&out.image_of(&rates[2]["view"]));
    let want = expected(profile, Views::Merged, out.fovs, level);
    assert!(
        got == want,
        "{what}: the eye-shaped target gets fovea's map"
    );
    assert_eq!(out.rate_structs(), vec![1, 0, 1], "{what}");
    once();
}
