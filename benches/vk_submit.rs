//! The cost fovea's Vulkan layer adds to `vkQueueSubmit`, with and without the ordering of its
//! uploads across several graphics queues (docs/vulkan-layer.md#uploads-and-several-queues), in
//! the same run, and the heap allocations it adds per submit.
//!
//! Three devices on lavapipe under the test double (`crates/vkdouble`, NVIDIA-like), each
//! submitting one batch of one empty command buffer on queue 0, no fence, many times (the queue is
//! waited for between rounds, outside the timed part):
//! - `bare`: the double alone, two queues of family 0 (the double offers the second);
//! - `fovea 1 queue`: fovea above it, emulating density maps, one queue: no ordering, the path
//!   every device with one graphics queue keeps;
//! - `fovea 2 queues`: the same with two queues: each submit goes down between fovea's batches
//!   (here only the signal of the queue's timeline: nothing is uploaded in steady state).
//!
//! The table at the end gives the median ns per submit over interleaved rounds, the ratio against
//! `bare`, and allocations per submit in the whole process (fewest in a round: lavapipe's queue
//! thread allocates too, and more for the extra batch fovea adds, so this column cannot single
//! out fovea's; `vk::own::order::tests` counts fovea's own, 0 per submit). lavapipe's own submit
//! (a hand-off to its queue thread) dominates every row: the difference is fovea's and the
//! driver's work for the added batch.
//!
//! Run: `cargo bench --bench vk_submit` (needs the Vulkan loader and lavapipe; skips otherwise).

use std::time::{Duration, Instant};

use ash::vk;
use criterion::Criterion;

// Shared with vk_commands and vk_parallel, which use the rest of it.
#[allow(dead_code)]
#[path = "support/vulkan.rs"]
mod vulkan;
use vulkan::median;

#[path = "support/alloc.rs"]
mod alloc;

/// Submits per round (the queue is waited for between rounds).
const ROUND: usize = 64;

/// One device submitting an empty command buffer on its queue 0.
struct Side {
    name: &'static str,
    instance: ash::Instance,
    device: ash::Device,
    queue: vk::Queue,
    pool: vk::CommandPool,
    cb: vk::CommandBuffer,
}

impl Side {
    fn new(
        entry: &ash::Entry,
        name: &'static str,
        fovea: bool,
        queues: u32,
    ) -> Result<Side, String> {
        let (instance, physical) = vulkan::instance_on_lavapipe(entry, fovea)?;
        // SAFETY: `physical` is the instance's; every object is the side's own.
        unsafe {
            let device = vulkan::device_queues(&instance, physical, fovea, !fovea, queues)?;
            let (pool, cb) = vulkan::command_buffer(&device);
            device
                .begin_command_buffer(
                    cb,
                    &vk::CommandBufferBeginInfo::default()
                        .flags(vk::CommandBufferUsageFlags::SIMULTANEOUS_USE),
                )
                .map_err(|e| format!("vkBeginCommandBuffer: {e}"))?;
            device
                .end_command_buffer(cb)
                .map_err(|e| format!("vkEndCommandBuffer: {e}"))?;
            let queue = device.get_device_queue(0, 0);
            Ok(Side {
                name,
                instance,
                device,
                queue,
                pool,
                cb,
            })
        }
    }

    /// `n` submits, timed, then a wait for the queue (not timed); the time and the allocations.
    fn round(&self, n: usize) -> (Duration, u64) {
        let cbs = [self.cb];
        let batch = [vk::SubmitInfo::default().command_buffers(&cbs)];
        let a = alloc::allocations();
        let t = Instant::now();
        for _ in 0..n {
            // SAFETY: the side's own executable command buffer (simultaneous use: it may be
            // pending several times), on its own queue.
            unsafe {
                self.device
                    .queue_submit(self.queue, &batch, vk::Fence::null())
                    .expect("vkQueueSubmit");
            }
        }
        let time = t.elapsed();
        let allocs = alloc::allocations() - a;
        // SAFETY: the side's own queue.
        unsafe { self.device.queue_wait_idle(self.queue) }.expect("vkQueueWaitIdle");
        (time, allocs)
    }
}

impl Drop for Side {
    fn drop(&mut self) {
        // SAFETY: the queue is idle after each round; each object is destroyed once.
        unsafe {
            let _ = self.device.device_wait_idle();
            self.device.destroy_command_pool(self.pool, None);
            self.device.destroy_device(None);
            self.instance.destroy_instance(None);
        }
    }
}

fn main() {
    let sides = match sides() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("vk_submit: skipped: {e}");
            return;
        }
    };
    for s in &sides {
        for _ in 0..8 {
            s.round(ROUND);
        }
    }
    let mut c = Criterion::default()
        .sample_size(20)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1))
        .configure_from_args();
    let mut g = c.benchmark_group("vk_submit");
    for s in &sides {
        g.bench_function(s.name, |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                let mut left = iters as usize;
                while left > 0 {
                    let n = left.min(ROUND);
                    total += s.round(n).0;
                    left -= n;
                }
                total
            })
        });
    }
    g.finish();
    c.final_summary();
    const ROUNDS: usize = 100;
    println!(
        "\nvk_submit summary: median ns per vkQueueSubmit over {ROUNDS} interleaved rounds of \
         {ROUND}; allocations per submit (fewest in a round)"
    );
    println!(
        "{:<16} {:>9} {:>9} {:>7} {:>7}",
        "device", "ns", "added ns", "ratio", "alloc"
    );
    let mut times = vec![Vec::new(); sides.len()];
    let mut allocs = vec![u64::MAX; sides.len()];
    for _ in 0..ROUNDS {
        for (i, s) in sides.iter().enumerate() {
            let (t, a) = s.round(ROUND);
            times[i].push(t.as_nanos() as f64 / ROUND as f64);
            allocs[i] = allocs[i].min(a);
        }
    }
    let medians: Vec<f64> = times.into_iter().map(median).collect();
    for (i, s) in sides.iter().enumerate() {
        println!(
            "{:<16} {:>9.1} {:>9.1} {:>7.3} {:>7.2}",
            s.name,
            medians[i],
            medians[i] - medians[0],
            medians[i] / medians[0],
            allocs[i] as f64 / ROUND as f64
        );
    }
}

/// The bare device, fovea's with one queue, fovea's with two.
fn sides() -> Result<Vec<Side>, String> {
    let double_lib = vulkan::layers_on_search_path("vksubmit")?;
    let double = fovea_vkdouble::Loaded::open(&double_lib)?;
    // SAFETY: loading libvulkan runs its initialisers, as any Vulkan application does.
    let entry = unsafe { ash::Entry::load() }.map_err(|e| format!("no Vulkan loader ({e})"))?;
    double.set_queues(2);
    let bare = Side::new(&entry, "bare", false, 2)?;
    let one = Side::new(&entry, "fovea 1 queue", true, 1)?;
    let two = Side::new(&entry, "fovea 2 queues", true, 2)?;
    // The double and the loader must outlive every instance: keep them for the process.
    std::mem::forget(double);
    std::mem::forget(entry);
    Ok(vec![bare, one, two])
}
