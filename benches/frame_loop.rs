//! The layer's added CPU per frame in steady state, and its heap allocations per frame.
//!
//! Both loops run in this process, through the fake loader harness, on the simulated runtime (Quest 3
//! preset, headless): `bare` calls the runtime directly, `fovea` goes through the layer with a
//! foveated multiview swapchain whose state asks for HIGH with dynamic foveation on. A frame is wait,
//! begin, locate views, one acquire/wait/release, end with one two-view projection layer.
//!
//! Allocations are counted by interposing `malloc` and friends in this executable: the layer is a
//! separately dlopened library with its own Rust runtime, so a `#[global_allocator]` here would not
//! see its allocations, but ELF symbol interposition routes its `malloc` calls through these.
//!
//! Besides criterion's own report, the run ends with a summary line: ns per frame for both loops from
//! interleaved timing rounds in the same run (the tenth percentile of 2,000 rounds of 250 frames: see
//! [`summary`]), the difference, the ratio, and allocations per frame.
//!
//! `FOVEA_BENCH_BASELINE=/path/to/libfovea.so` adds a third loop, `baseline`, through that library (an
//! older build of the layer, loaded beside this workspace's own: `dlopen` keeps the two apart), to both
//! criterion's report and the interleaved summary, so that a change is compared with the code it
//! replaces in the same run on the same machine state. `benches/compare-baseline.sh` builds the
//! baseline from a commit and runs this.

use std::time::Instant;

use criterion::{criterion_group, Criterion};
use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::{HeadlessLoop, SwapchainSpec, FOVEATION_EXTENSIONS};
use fovea_harness::{sim, App, Chain, LayerSpec, FOVEA_LAYER};
use openxr_sys as xr;
use xr::Handle;

#[path = "support/alloc.rs"]
mod alloc;

fn running_loop(chain: Chain) -> HeadlessLoop {
    let mut cfg = sim::control::SimConfig::from_env().expect("simulated runtime configuration");
    cfg.journal = false;
    sim::control::set_thread_config(Some(cfg));
    // The bare runtime offers none of the foveation extensions: its loop is the same without them.
    let layered = !chain.layers.is_empty();
    let extensions: &[&str] = if layered {
        &FOVEATION_EXTENSIONS
    } else {
        &["XR_MND_headless"]
    };
    let app = App::new(chain, extensions, API_1_0).expect("instance");
    let spec = SwapchainSpec {
        foveation: layered,
        array_size: 2,
    };
    let mut lp = HeadlessLoop::new(app, spec).expect("session");
    if layered {
        lp.apply_profile(
            xr::FoveationLevelFB::HIGH,
            xr::FoveationDynamicFB::LEVEL_ENABLED,
        )
        .expect("HIGH dynamic profile");
    }
    for _ in 0..300 {
        lp.frame().expect("warm-up frame");
    }
    lp
}

/// The environment variable naming a baseline build of the layer to compare with.
const BASELINE_ENV: &str = "FOVEA_BENCH_BASELINE";

/// The baseline layer named by [`BASELINE_ENV`], loaded as the loader would load fovea.
fn baseline_chain() -> Option<Chain> {
    let path = std::env::var_os(BASELINE_ENV)?;
    let spec = LayerSpec {
        path: path.into(),
        name: FOVEA_LAYER.to_owned(),
    };
    Some(Chain::new(vec![spec]).expect("the baseline layer loads"))
}

fn bench_frames(c: &mut Criterion) {
    let mut group = c.benchmark_group("frame");
    let mut bare = running_loop(Chain::bare());
    group.bench_function("bare", |b| b.iter(|| bare.frame().unwrap()));
    if let Some(chain) = baseline_chain() {
        let mut baseline = running_loop(chain);
        group.bench_function("baseline", |b| b.iter(|| baseline.frame().unwrap()));
    }
    let mut fovea = running_loop(Chain::fovea().expect("libfovea.so is built"));
    group.bench_function("fovea", |b| b.iter(|| fovea.frame().unwrap()));
    group.finish();
}

/// Mean ns per frame over `n` frames, and allocations per frame.
fn timed(lp: &mut HeadlessLoop, n: u32) -> (f64, f64) {
    let a0 = alloc::allocations();
    let t0 = Instant::now();
    for _ in 0..n {
        lp.frame().unwrap();
    }
    let ns = t0.elapsed().as_nanos() as f64 / f64::from(n);
    let allocs = (alloc::allocations() - a0) as f64 / f64::from(n);
    (ns, allocs)
}

/// The allocation counter must see allocations made inside the dlopened layer, or "zero added
/// allocations" would prove nothing: the layer's xrEnumerateInstanceExtensionProperties builds a Vec.
fn check_counter_sees_the_layer() {
    let chain = Chain::fovea().expect("libfovea.so is built");
    // SAFETY: the name's type matches; the count pointer is valid.
    let before = alloc::allocations();
    unsafe {
        let f: xr::pfn::EnumerateInstanceExtensionProperties = fovea_harness::lookup(
            chain.gipa(),
            xr::Instance::NULL,
            c"xrEnumerateInstanceExtensionProperties",
        )
        .unwrap();
        let mut n = 0;
        f(std::ptr::null(), 0, &mut n, std::ptr::null_mut());
    }
    let seen = alloc::allocations() - before;
    assert!(
        seen > 0,
        "the malloc interposer does not see the layer's allocations"
    );
}

/// Interleaved rounds of the loops in the same run (bare, the baseline when named, fovea); the tenth
/// percentile round of each. Many short rounds (2,000 of 250 frames, under a millisecond each) and a
/// low percentile rather than a few long rounds and their median: on a shared machine other work
/// only ever adds time, and lands in most rounds of ten milliseconds or more, so that the median of
/// long rounds measures the machine's load as much as the loop (ratios from 0.3 to 1.1 between the
/// same two builds in one afternoon); a low percentile of short rounds is what the loop costs when
/// nothing else interrupts it. Allocations per frame are the median round's.
fn summary() {
    let mut bare = running_loop(Chain::bare());
    let mut baseline = baseline_chain().map(running_loop);
    let mut fovea = running_loop(Chain::fovea().expect("libfovea.so is built"));
    let (mut b, mut o, mut f) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..ROUNDS {
        b.push(timed(&mut bare, ROUND_FRAMES));
        if let Some(lp) = &mut baseline {
            o.push(timed(lp, ROUND_FRAMES));
        }
        f.push(timed(&mut fovea, ROUND_FRAMES));
    }
    let median = |v: &mut Vec<(f64, f64)>| {
        v.sort_by(|x, y| x.0.total_cmp(&y.0));
        (v[v.len() / 10].0, v[v.len() / 2].1)
    };
    let (bare_ns, bare_allocs) = median(&mut b);
    let (fovea_ns, fovea_allocs) = median(&mut f);
    println!(
        "summary: bare {bare_ns:.0} ns/frame, fovea {fovea_ns:.0} ns/frame, added {:.0} ns/frame, ratio {:.3}; \
         heap allocations per frame: bare {bare_allocs:.2}, fovea {fovea_allocs:.2}, added by the layer {:.2}",
        fovea_ns - bare_ns,
        fovea_ns / bare_ns,
        fovea_allocs - bare_allocs,
    );
    if !o.is_empty() {
        let (base_ns, base_allocs) = median(&mut o);
        println!(
            "baseline: bare {bare_ns:.0} ns/frame, baseline {base_ns:.0} ns/frame, added {:.0} ns/frame, ratio {:.3}, \
             allocations added {:.2}; fovea's added cost is {:.2} of the baseline's",
            base_ns - bare_ns,
            base_ns / bare_ns,
            base_allocs - bare_allocs,
            (fovea_ns - bare_ns) / (base_ns - bare_ns),
        );
    }
}

/// Interleaved timing rounds in the summary, and frames per round.
const ROUNDS: usize = 2_000;
const ROUND_FRAMES: u32 = 250;

criterion_group!(benches, bench_frames);

fn main() {
    check_counter_sees_the_layer();
    benches();
    summary();
    Criterion::default().configure_from_args().final_summary();
}
