//! Building a density map: both layers of a Quest 3 multiview swapchain (one view per layer, the
//! preset's asymmetric FOVs, recommended size) at texel 16 and 32, HIGH with up to 4×4 fragments.
//!
//! The baseline is a trivial fill of the same buffer (every texel set to one constant), measured in
//! the same run, so the ratio says what the model costs beyond touching the memory. The run ends with
//! a summary line per texel size from interleaved timing rounds: µs per 2-layer map, the baseline,
//! the ratio; and for scale, both layers filled without the mirror shortcut and texel by texel.
//!
//! `gaze_refill` is what a gaze move costs on devices whose maps are filled on the CPU: both
//! layers written again from the fixed map, shifted to the fovea's new place
//! (`fovea_model::shift`); the target is no more than `fovea_fill`, the fixed map's build.

use std::hint::black_box;
use std::time::Instant;

use criterion::{criterion_group, Criterion};
use fovea_model::density::{
    fill, fill_reference, is_mirror, mirror_into, Grid, Level, Pattern, Rect, View,
};
use fovea_model::shift::{shift_into, texel_shift};

struct Case {
    grid: Grid,
    views: [View; 2],
    pattern: Pattern,
    layers: [Vec<u8>; 2],
    /// Each eye's fixed map, for the gaze refill.
    fixed: [Vec<u8>; 2],
    /// Each eye's fovea after a gaze move, NDC.
    gaze: [[f32; 2]; 2],
}

impl Case {
    fn quest3(texel: u32) -> Case {
        let h = fovea_model::headsets::by_id("quest3").expect("quest3 preset");
        let [w, hh] = h.recommended_size();
        let view = |eye: usize| View {
            fov: h.fovs()[eye],
            rect: Rect {
                x: 0,
                y: 0,
                width: w,
                height: hh,
            },
            visible: None,
        };
        let grid = Grid::new([w, hh], [texel, texel]);
        let [mw, mh] = grid.map_extent();
        let len = mw as usize * mh as usize * 2;
        let mut case = Case {
            grid,
            views: [view(0), view(1)],
            pattern: Pattern {
                level: Level::High,
                vertical_offset_deg: 0.0,
            },
            layers: [vec![0; len], vec![0; len]],
            fixed: [vec![0; len], vec![0; len]],
            gaze: [[0.31, -0.22], [0.12, -0.22]],
        };
        case.unmirrored();
        case.fixed = case.layers.clone();
        case
    }

    /// A gaze move: each layer written again from its fixed map, shifted to the new fovea.
    fn gaze_refill(&mut self) {
        for eye in 0..2 {
            let view = black_box(&self.views[eye]);
            let shift = texel_shift(&self.grid, view, black_box(self.gaze[eye]));
            shift_into(
                &self.grid,
                view,
                shift,
                &self.fixed[eye],
                &mut self.layers[eye],
            );
        }
        black_box(&self.layers);
    }

    /// What the layer does: the left eye's layer, then the right eye's as its mirror when the
    /// preset's eyes mirror each other (they do on Quest 3), else filled on its own.
    fn model(&mut self) {
        let [left, right] = &mut self.layers;
        let views = black_box(&self.views);
        fill(&self.grid, &views[..1], self.pattern, left);
        if is_mirror(&self.grid, &views[..1], &views[1..]) {
            mirror_into(&self.grid, left, right);
        } else {
            fill(&self.grid, &views[1..], self.pattern, right);
        }
        black_box(&self.layers);
    }

    /// Both layers filled on their own, without the mirror shortcut.
    fn unmirrored(&mut self) {
        for (layer, view) in self.layers.iter_mut().zip(&self.views) {
            fill(
                &self.grid,
                black_box(std::slice::from_ref(view)),
                self.pattern,
                layer,
            );
        }
        black_box(&self.layers);
    }

    fn reference(&mut self) {
        for (layer, view) in self.layers.iter_mut().zip(&self.views) {
            fill_reference(
                &self.grid,
                black_box(std::slice::from_ref(view)),
                self.pattern,
                layer,
            );
        }
        black_box(&self.layers);
    }

    fn trivial(&mut self) {
        for layer in &mut self.layers {
            black_box(&mut layer[..]).fill(black_box(127));
        }
        black_box(&self.layers);
    }
}

fn bench_maps(c: &mut Criterion) {
    for texel in [16, 32] {
        let mut case = Case::quest3(texel);
        let mut group = c.benchmark_group(format!("density_quest3_2layer_texel{texel}"));
        group.bench_function("trivial_fill", |b| b.iter(|| case.trivial()));
        group.bench_function("fovea_fill", |b| b.iter(|| case.model()));
        group.bench_function("fovea_fill_unmirrored", |b| b.iter(|| case.unmirrored()));
        group.bench_function("gaze_refill", |b| b.iter(|| case.gaze_refill()));
        group.finish();
    }
}

/// Mean µs per call over interleaved rounds, so both sides see the same machine state.
fn summary() {
    for texel in [16, 32] {
        let mut case = Case::quest3(texel);
        let [mw, mh] = case.grid.map_extent();
        let time = |case: &mut Case, f: fn(&mut Case), n: u32| {
            let t = Instant::now();
            for _ in 0..n {
                f(case);
            }
            t.elapsed().as_secs_f64() * 1e6 / f64::from(n)
        };
        let (mut model, mut trivial, mut reference, mut unmirrored, mut refill) =
            (0.0, 0.0, 0.0, 0.0, 0.0);
        let rounds = 20;
        for _ in 0..rounds {
            model += time(&mut case, Case::model, 200);
            trivial += time(&mut case, Case::trivial, 200);
            reference += time(&mut case, Case::reference, 5);
            unmirrored += time(&mut case, Case::unmirrored, 100);
            refill += time(&mut case, Case::gaze_refill, 200);
        }
        let r = f64::from(rounds);
        let [model, trivial, reference, unmirrored, refill] =
            [model, trivial, reference, unmirrored, refill].map(|t| t / r);
        println!(
            "summary: quest3 2-layer {mw}x{mh} texels (texel {texel}), HIGH: fovea {model:.2} us, \
             trivial fill {trivial:.2} us, ratio {:.1}; both eyes filled {unmirrored:.2} us, \
             texel by texel {reference:.1} us; gaze refill {refill:.2} us, ratio to fovea {:.2} \
             (target <= 1)",
            model / trivial,
            refill / model
        );
    }
}

criterion_group!(benches, bench_maps);

fn main() {
    benches();
    Criterion::default().configure_from_args().final_summary();
    summary();
}
