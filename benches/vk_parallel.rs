//! Recording through fovea's Vulkan layer on one thread and on eight at once, in the same run:
//! per-command cost, its ratio, and heap allocations per command.
//!
//! Engines record command buffers on 8–16 threads. A hook that takes a process-wide lock, counts a
//! reference on a shared record or writes a shared cache line per command gets slower per command
//! as threads are added; one that only reads shared state does not. This bench records the same
//! mix of the commands the layer intercepts on every emulating device (`vkCmdPipelineBarrier` and
//! `vkCmdPipelineBarrier2` with one image barrier, `vkCmdBindPipeline` of a compute pipeline,
//! `vkCmdPushConstants`, `vkCmdBeginRenderPass` + End on a pass without a density map,
//! `vkCmdBeginRendering` + End without one; a begin/end pair counts as one command) on 1 and on
//! [`THREADS`] threads, each thread with its own command pool and command buffer, through two
//! devices: `bare` (the shading-rate test double only) and `fovea` (fovea's layer above it,
//! emulating density maps). The double drops the commands ([`fovea_vkdouble::NULL_COMMANDS_ENV`]),
//! so `bare` costs a call into an empty function and `fovea - bare` is the layer's own cost, as in
//! `benches/vk_commands.rs`. A second comparison records only `vkCmdBeginRendering` + End into an
//! eye target, on the bare device and on a third, injecting one (docs/injection.md), made through
//! `xrCreateVulkanDeviceKHR` of an OpenXR instance with `FOVEA_INJECT=1` on the simulated runtime
//! with its eye swapchain published, as `benches/vk_commands.rs` makes its injecting side: fovea's
//! map is chained onto each such begin, the hot path of DXVK and vkd3d-proton, which render with
//! dynamic rendering only. The run fails where that device does not inject.
//!
//! **What the figure is.** Each thread's recording loop is timed with its own CPU clock
//! (`CLOCK_THREAD_CPUTIME_ID`), and criterion's time per iteration is the mean over threads of CPU
//! time per command. On a machine with at least eight free cores that is the per-command cost each
//! recording thread sees. On fewer cores (this project's machines have two, shared) eight threads
//! cannot run at once: wall time would measure the scheduler (about four times the one-thread
//! figure on two cores with no contention at all), so it is not the figure. Per-thread CPU time
//! still shows what contention costs while threads do run at once (two at a time on two cores):
//! cache lines bouncing between cores, atomic read-modify-writes on shared words, spinning on a
//! lock. It does not show time a thread spends blocked on a lock (that is not CPU time), so the
//! summary also prints the wall-clock figure scaled to the cores the threads could use
//! (wall × min(threads, cores) / commands), which does include it, and whose ratio stays near 1
//! only where no thread waits and every core is free; on a shared machine the bare side's own
//! 8-thread slowdown shows how many were, and the line "relative to the bare side" divides it out.
//! Context switches of eight threads on two cores add a little to both.
//!
//! The summary (interleaved rounds, medians) prints per command: bare and fovea on one thread and
//! on eight, the layer's added cost, the ratio 8 threads / 1 thread, and allocations per command.
//! The run fails where the layer allocates per command; the targets (eight threads at most 1.5×
//! one thread's figure, at most 30 ns added on one thread) are reported, not asserted: timings on
//! a shared machine are not pass/fail.
//!
//! Run: `cargo build --release --workspace && cargo bench --bench vk_parallel -- --warm-up-time 1
//! --measurement-time 2` (needs the Vulkan loader and lavapipe; skips otherwise).

use std::sync::{Arc, Barrier, Mutex};
use std::time::{Duration, Instant};

use ash::vk;
use criterion::Criterion;

#[path = "support/vulkan.rs"]
mod vulkan;
use vulkan::{colour_range, compute_pipeline, median, pass_and_framebuffer, Target};

#[path = "support/alloc.rs"]
mod alloc;

#[path = "support/xr_inject.rs"]
mod xr_inject;
use xr_inject::{injects, Xr};

extern "C" {
    fn clock_gettime(clock: i32, out: *mut Timespec) -> i32;
}

#[repr(C)]
struct Timespec {
    sec: i64,
    nsec: i64,
}

/// Linux's `CLOCK_THREAD_CPUTIME_ID`.
const THREAD_CPU: i32 = 3;

/// This thread's CPU time.
fn thread_cpu() -> Duration {
    let mut t = Timespec { sec: 0, nsec: 0 };
    // SAFETY: a plain query into a struct on the stack.
    unsafe { clock_gettime(THREAD_CPU, &mut t) };
    Duration::new(t.sec as u64, t.nsec as u32)
}

const THREADS: usize = 8;
const SIZE: u32 = 64;
/// Commands per round (each thread's command buffer is ended and reset between rounds, outside
/// the timed part). Long, so that waking the threads at each round's start weighs little in the
/// wall-clock figure; the double drops the commands, so the command buffers do not grow.
const ROUND: usize = 24_000;
/// The mix, in recording order.
const MIX: usize = 6;
/// The eye swapchain's size, and the injecting side's colour target's (an eye-shaped target).
const EYE: [u32; 2] = [640, 500];

/// What a run records.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mix {
    /// The [`MIX`] commands in turn.
    All,
    /// `vkCmdBeginRendering` + `vkCmdEndRendering` into the side's colour target only: on the
    /// injecting side an eye target, whose rendering gets fovea's map chained on, the hot path of
    /// DXVK and vkd3d-proton, which render with dynamic rendering only.
    Rendering,
}

/// One instance and device (bare or through fovea) with what every thread records into.
struct Side {
    instance: ash::Instance,
    device: ash::Device,
    color: Target,
    pass: vk::RenderPass,
    framebuffer: vk::Framebuffer,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    /// One pool and command buffer per thread.
    buffers: Vec<(vk::CommandPool, vk::CommandBuffer)>,
    /// Whether the side destroys its device and instance (not where they were made through
    /// OpenXR: the injecting side's go with their [`fovea_harness::vulkan::Vulkan`]).
    owned: bool,
}

impl Side {
    fn new(entry: &ash::Entry, with_fovea: bool) -> Result<Side, String> {
        let (instance, physical) = vulkan::instance_on_lavapipe(entry, with_fovea)?;
        // SAFETY: `physical` is the instance's.
        let device = unsafe { vulkan::device(&instance, physical, with_fovea, false) }?;
        // SAFETY: the device is the instance's and the side's alone.
        Ok(unsafe { Side::on(instance, physical, device, [SIZE, SIZE], true) })
    }

    /// The injecting side: its instance and device made through OpenXR
    /// ([`xr_inject::Xr::vulkan`]), the session on it and its eye swapchain published, and a
    /// colour target of the eye's size; with what destroys its device and instance after it.
    fn injecting(
        entry: &ash::Entry,
        xr: &Xr,
    ) -> Result<(Side, fovea_harness::vulkan::Vulkan), String> {
        let v = xr.vulkan(entry)?;
        xr.publish_eye(&v, EYE)?;
        let (instance, physical, device) =
            (v.instance.clone(), v.physical_device, v.device.clone());
        // SAFETY: the device is the instance's and the side's alone; `v` destroys both.
        Ok((
            unsafe { Side::on(instance, physical, device, EYE, false) },
            v,
        ))
    }

    /// What a side records with, made on `device`, its colour target of `extent`.
    ///
    /// # Safety
    /// `device` must be live and made from `instance`'s `physical`; the side destroys both where
    /// `owned`.
    unsafe fn on(
        instance: ash::Instance,
        physical: vk::PhysicalDevice,
        device: ash::Device,
        extent: [u32; 2],
        owned: bool,
    ) -> Side {
        // SAFETY: as the caller promised; every struct lives across its call; handles are used
        // while alive.
        unsafe {
            let color = Target::new(
                &instance,
                physical,
                &device,
                vk::Format::R8G8B8A8_UNORM,
                extent,
                vk::ImageUsageFlags::COLOR_ATTACHMENT,
            );
            let (pass, framebuffer) = pass_and_framebuffer(&device, color.view, None, SIZE);
            let (layout, pipeline) = compute_pipeline(&device);
            let buffers = (0..THREADS)
                .map(|_| vulkan::command_buffer(&device))
                .collect();
            Side {
                instance,
                device,
                color,
                pass,
                framebuffer,
                layout,
                pipeline,
                buffers,
                owned,
            }
        }
    }

    /// Records command `i` of `mix` into thread `t`'s command buffer.
    fn record(&self, t: usize, i: usize, mix: Mix) {
        let d = &self.device;
        let cb = self.buffers[t].1;
        let whole = vk::Rect2D {
            offset: vk::Offset2D::default(),
            extent: vk::Extent2D {
                width: SIZE,
                height: SIZE,
            },
        };
        // SAFETY: thread `t`'s own command buffer, recording; every struct lives across its call.
        unsafe {
            let which = match mix {
                Mix::All => i % MIX,
                Mix::Rendering => MIX - 1,
            };
            match which {
                0 => {
                    let barrier = [vk::ImageMemoryBarrier::default()
                        .src_access_mask(vk::AccessFlags::SHADER_READ)
                        .dst_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                        .old_layout(vk::ImageLayout::UNDEFINED)
                        .new_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                        .image(self.color.image)
                        .subresource_range(colour_range())];
                    d.cmd_pipeline_barrier(
                        cb,
                        vk::PipelineStageFlags::FRAGMENT_SHADER,
                        vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                        vk::DependencyFlags::empty(),
                        &[],
                        &[],
                        &barrier,
                    );
                }
                1 => {
                    let barrier = [vk::ImageMemoryBarrier2::default()
                        .src_stage_mask(vk::PipelineStageFlags2::FRAGMENT_SHADER)
                        .src_access_mask(vk::AccessFlags2::SHADER_READ)
                        .dst_stage_mask(vk::PipelineStageFlags2::COLOR_ATTACHMENT_OUTPUT)
                        .dst_access_mask(vk::AccessFlags2::COLOR_ATTACHMENT_WRITE)
                        .old_layout(vk::ImageLayout::UNDEFINED)
                        .new_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                        .image(self.color.image)
                        .subresource_range(colour_range())];
                    d.cmd_pipeline_barrier2(
                        cb,
                        &vk::DependencyInfo::default().image_memory_barriers(&barrier),
                    );
                }
                2 => d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, self.pipeline),
                3 => d.cmd_push_constants(
                    cb,
                    self.layout,
                    vk::ShaderStageFlags::COMPUTE,
                    0,
                    &(i as u64).to_le_bytes(),
                ),
                4 => {
                    let begin = vk::RenderPassBeginInfo::default()
                        .render_pass(self.pass)
                        .framebuffer(self.framebuffer)
                        .render_area(whole);
                    d.cmd_begin_render_pass(cb, &begin, vk::SubpassContents::INLINE);
                    d.cmd_end_render_pass(cb);
                }
                _ => {
                    let colors = [vk::RenderingAttachmentInfo::default()
                        .image_view(self.color.view)
                        .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                        .load_op(vk::AttachmentLoadOp::DONT_CARE)
                        .store_op(vk::AttachmentStoreOp::STORE)];
                    let info = vk::RenderingInfo::default()
                        .render_area(whole)
                        .layer_count(1)
                        .color_attachments(&colors);
                    d.cmd_begin_rendering(cb, &info);
                    d.cmd_end_rendering(cb);
                }
            }
        }
    }

    fn begin(&self, t: usize) {
        // SAFETY: thread `t`'s own command buffer, not recording.
        unsafe {
            self.device
                .begin_command_buffer(self.buffers[t].1, &vk::CommandBufferBeginInfo::default())
                .expect("vkBeginCommandBuffer");
        }
    }

    fn end_and_reset(&self, t: usize) {
        let cb = self.buffers[t].1;
        // SAFETY: thread `t`'s own command buffer, recording and never submitted.
        unsafe {
            self.device
                .end_command_buffer(cb)
                .expect("vkEndCommandBuffer");
            self.device
                .reset_command_buffer(cb, vk::CommandBufferResetFlags::RELEASE_RESOURCES)
                .expect("vkResetCommandBuffer");
        }
    }
}

impl Drop for Side {
    fn drop(&mut self) {
        // SAFETY: nothing made from these handles outlives them; each is destroyed once.
        unsafe {
            let d = &self.device;
            for &(pool, _) in &self.buffers {
                d.destroy_command_pool(pool, None);
            }
            d.destroy_pipeline(self.pipeline, None);
            d.destroy_pipeline_layout(self.layout, None);
            d.destroy_framebuffer(self.framebuffer, None);
            d.destroy_render_pass(self.pass, None);
            self.color.destroy(d);
            if self.owned {
                d.destroy_device(None);
                self.instance.destroy_instance(None);
            }
        }
    }
}

/// What one run of the threads measured.
#[derive(Clone, Copy, Default)]
struct Run {
    /// Sum over threads of the CPU time of their recording loops.
    cpu: Duration,
    /// Wall time from the start barrier until the last thread finished recording.
    wall: Duration,
    /// Allocations made (by any thread) while the threads recorded.
    allocations: u64,
}

/// A job for the workers taking part in a run: record `per_thread` commands into `side`.
struct Job {
    side: Arc<Side>,
    per_thread: usize,
    mix: Mix,
}

/// Where every thread of a run (the workers and the caller) meets, per round: every command buffer
/// begun (the caller reads the allocation count), go, every recording done (the caller reads the
/// count again), counted; and once at the end of the run. So the count covers the recording loops
/// and nothing else.
struct Gates {
    begun: Barrier,
    go: Barrier,
    done: Barrier,
    counted: Barrier,
    end: Barrier,
}

/// [`THREADS`] threads that record on demand; each owns command buffer `t` of every side.
struct Workers {
    jobs: Vec<std::sync::mpsc::Sender<Option<Arc<Job>>>>,
    /// The current run's gates, for the workers taking part.
    gates: Arc<Mutex<Option<Arc<Gates>>>>,
    /// Each worker's CPU time of its recording loops in the current run.
    results: Arc<Mutex<Vec<Duration>>>,
    handles: Vec<std::thread::JoinHandle<()>>,
}

impl Workers {
    fn new() -> Workers {
        let results = Arc::new(Mutex::new(Vec::new()));
        let gates: Arc<Mutex<Option<Arc<Gates>>>> = Arc::new(Mutex::new(None));
        let mut jobs = Vec::new();
        let mut handles = Vec::new();
        for t in 0..THREADS {
            let (tx, rx) = std::sync::mpsc::channel::<Option<Arc<Job>>>();
            let results = Arc::clone(&results);
            let gates = Arc::clone(&gates);
            jobs.push(tx);
            handles.push(std::thread::spawn(move || {
                while let Ok(Some(job)) = rx.recv() {
                    let g = gates.lock().expect("gates").clone().expect("set");
                    let mut cpu = Duration::ZERO;
                    let mut left = job.per_thread;
                    while left > 0 {
                        let n = left.min(ROUND);
                        job.side.begin(t);
                        g.begun.wait();
                        g.go.wait();
                        let c = thread_cpu();
                        for i in 0..n {
                            job.side.record(t, i, job.mix);
                        }
                        cpu += thread_cpu() - c;
                        g.done.wait();
                        g.counted.wait();
                        job.side.end_and_reset(t);
                        left -= n;
                    }
                    results.lock().expect("results").push(cpu);
                    g.end.wait();
                }
            }));
        }
        Workers {
            jobs,
            gates,
            results,
            handles,
        }
    }

    /// Records `per_thread` commands on each of `threads` workers into `side`.
    fn run(&self, side: &Arc<Side>, threads: usize, per_thread: usize, mix: Mix) -> Run {
        let g = Arc::new(Gates {
            begun: Barrier::new(threads + 1),
            go: Barrier::new(threads + 1),
            done: Barrier::new(threads + 1),
            counted: Barrier::new(threads + 1),
            end: Barrier::new(threads + 1),
        });
        *self.gates.lock().expect("gates") = Some(Arc::clone(&g));
        self.results.lock().expect("results").clear();
        let job = Arc::new(Job {
            side: Arc::clone(side),
            per_thread,
            mix,
        });
        for tx in &self.jobs[..threads] {
            tx.send(Some(Arc::clone(&job))).expect("worker");
        }
        let mut run = Run::default();
        let mut left = per_thread;
        while left > 0 {
            let n = left.min(ROUND);
            g.begun.wait();
            let a = alloc::allocations();
            let t = Instant::now();
            g.go.wait();
            g.done.wait();
            run.wall += t.elapsed();
            run.allocations += alloc::allocations() - a;
            g.counted.wait();
            left -= n;
        }
        g.end.wait();
        run.cpu = self.results.lock().expect("results").iter().sum();
        run
    }
}

impl Drop for Workers {
    fn drop(&mut self) {
        for tx in &self.jobs {
            let _ = tx.send(None);
        }
        for h in self.handles.drain(..) {
            let _ = h.join();
        }
    }
}

/// The bare, emulating and injecting sides on the null bottom, what keeps injection on (dropped
/// after the sides: the session's swapchain images live on the injecting device), or why not.
/// Panics where the injecting side does not inject: its rows would measure nothing.
#[allow(clippy::type_complexity)]
fn sides() -> Result<
    (
        Arc<Side>,
        Arc<Side>,
        Arc<Side>,
        fovea_harness::vulkan::Vulkan,
        Xr,
    ),
    String,
> {
    let double_lib = vulkan::layers_on_search_path("vkparallel")?;
    let double = fovea_vkdouble::Loaded::open(&double_lib)?;
    // Read by the double at vkCreateDevice.
    std::env::set_var(fovea_vkdouble::NULL_COMMANDS_ENV, "1");
    // SAFETY: loading libvulkan runs its initialisers, as any Vulkan application does.
    let entry = unsafe { ash::Entry::load() }.map_err(|e| format!("no Vulkan loader ({e})"))?;
    let bare = Side::new(&entry, false)?;
    let fovea = Side::new(&entry, true)?;
    let xr = Xr::new()?;
    double.clear();
    let (inject, v) = Side::injecting(&entry, &xr)?;
    if let Err(e) = injects(&double, ash::vk::Handle::as_raw(inject.framebuffer), EYE) {
        panic!(
            "vk_parallel: the injecting device does not inject, so its rows would say nothing: {e}"
        );
    }
    // The entry (the loader library) must outlive every instance: keep it for the process; the
    // double's too (its records live there).
    std::mem::forget(entry);
    std::mem::forget(double);
    Ok((Arc::new(bare), Arc::new(fovea), Arc::new(inject), v, xr))
}

/// Criterion's time for `iters` commands per thread: the mean over threads of their CPU time.
fn timed(workers: &Workers, side: &Arc<Side>, threads: usize, iters: u64, mix: Mix) -> Duration {
    workers.run(side, threads, iters as usize, mix).cpu / threads as u32
}

/// Per command, from interleaved runs: (CPU ns, scaled wall ns, allocations per command; fewest
/// in a run).
fn figures(
    workers: &Workers,
    side: &Arc<Side>,
    threads: usize,
    runs: usize,
    mix: Mix,
) -> (f64, f64, f64) {
    let per_thread = ROUND;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let (mut cpu, mut wall, mut alloc) = (Vec::new(), Vec::new(), u64::MAX);
    for _ in 0..runs {
        let r = workers.run(side, threads, per_thread, mix);
        let commands = (threads * per_thread) as f64;
        cpu.push(r.cpu.as_nanos() as f64 / commands);
        wall.push(r.wall.as_nanos() as f64 * threads.min(cores) as f64 / commands);
        alloc = alloc.min(r.allocations);
    }
    (
        median(cpu),
        median(wall),
        alloc as f64 / (threads * per_thread) as f64,
    )
}

/// The summary of one comparison (`what`: the commands `mix` records, on `bare` and through
/// fovea on `fovea`) from interleaved runs; where the layer allocates, why.
fn summary(
    workers: &Workers,
    what: &str,
    mix: Mix,
    bare: &Arc<Side>,
    fovea: &Arc<Side>,
) -> Vec<String> {
    const RUNS: usize = 60;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut rows = Vec::new();
    for _ in 0..RUNS / 10 {
        for threads in [1, THREADS] {
            for (i, side) in [bare, fovea].into_iter().enumerate() {
                rows.push((threads, i, figures(workers, side, threads, 10, mix)));
            }
        }
    }
    let pick = |threads: usize, i: usize, f: fn(&(f64, f64, f64)) -> f64| {
        median(
            rows.iter()
                .filter(|r| r.0 == threads && r.1 == i)
                .map(|r| f(&r.2))
                .collect(),
        )
    };
    println!(
        "\nvk_parallel summary, null bottom, {cores} core(s): median ns per command ({what}) over \
         {RUNS} interleaved runs of {} commands per thread",
        ROUND
    );
    println!(
        "{:<34} {:>9} {:>9} {:>9} {:>11}",
        "figure", "bare", "fovea", "added", "fovea alloc"
    );
    let mut allocates = Vec::new();
    for (name, f) in [
        (
            "CPU ns per command",
            (|x: &(f64, f64, f64)| x.0) as fn(&_) -> f64,
        ),
        ("wall ns × min(threads, cores)", |x| x.1),
    ] {
        for threads in [1, THREADS] {
            let (b, v) = (pick(threads, 0, f), pick(threads, 1, f));
            let (ab, av) = (pick(threads, 0, |x| x.2), pick(threads, 1, |x| x.2));
            println!(
                "{:<34} {:>9.1} {:>9.1} {:>9.1} {:>11.3}",
                format!("{name}, {threads} thread(s)"),
                b,
                v,
                v - b,
                av
            );
            if av > ab {
                allocates.push(format!(
                    "{what}, {threads} thread(s): {av} allocations per command, {ab} without the \
                     layer"
                ));
            }
        }
        let (one, eight) = (pick(1, 1, f), pick(THREADS, 1, f));
        let (one_added, eight_added) = (one - pick(1, 0, f), eight - pick(THREADS, 0, f));
        println!(
            "{:<34} {:>9} {:>9.3} {:>9.3}   (target: fovea ≤ 1.5)",
            format!("{name}, ratio {THREADS} / 1"),
            "",
            eight / one,
            eight_added / one_added
        );
    }
    // Where fewer cores are free than the machine has (other work on a shared machine), the bare
    // side slows down on eight threads as much as fovea's: fovea's slowdown over the bare side's
    // is what the layer adds.
    let wall = |threads, i| pick(threads, i, |x| x.1);
    println!(
        "{:<34} {:>9} {:>9.3}             (fovea's 8 / 1 over bare's 8 / 1)",
        "wall, relative to the bare side",
        "",
        (wall(THREADS, 1) / wall(1, 1)) / (wall(THREADS, 0) / wall(1, 0)),
    );
    allocates
}

fn benches() {
    let (bare, fovea, inject, v, xr) = match sides() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("vk_parallel: skipped: {e}");
            return;
        }
    };
    let workers = Workers::new();
    let comparisons = [
        (
            "vk_parallel/null",
            "mix of barrier, barrier2, compute bind, push constants, render pass begin+end, \
             rendering begin+end",
            Mix::All,
            &bare,
            &fovea,
        ),
        (
            "vk_parallel/null/injected eye rendering",
            "vkCmdBeginRendering+End into an eye target, fovea's map chained on, on the \
             injecting device",
            Mix::Rendering,
            &bare,
            &inject,
        ),
    ];
    // Warm up: every thread's command buffer reaches its steady size, the layer's scratch and
    // every thread's look-ups too.
    for (_, _, mix, b, f) in comparisons {
        for side in [b, f] {
            workers.run(side, THREADS, ROUND, mix);
        }
    }
    let mut c = Criterion::default()
        .sample_size(20)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .configure_from_args();
    for (group, _, mix, b, f) in comparisons {
        let mut g = c.benchmark_group(group);
        for threads in [1, THREADS] {
            for (label, side) in [("bare", b), ("fovea", f)] {
                g.bench_function(format!("{threads} thread(s)/{label}"), |bench| {
                    bench.iter_custom(|iters| timed(&workers, side, threads, iters, mix))
                });
            }
        }
        g.finish();
    }
    c.final_summary();
    let mut allocates = Vec::new();
    for (_, what, mix, b, f) in comparisons {
        allocates.extend(summary(&workers, what, mix, b, f));
    }
    assert!(
        allocates.is_empty(),
        "the layer allocates while recording:\n{}",
        allocates.join("\n")
    );
    drop(workers);
    // The session's swapchain images are on the injecting device: the session goes first.
    drop(xr);
    drop((bare, fovea, inject));
    v.destroy();
}

fn main() {
    benches();
}
