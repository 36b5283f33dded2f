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
//! `benches/vk_commands.rs`.
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
//! Run: `cargo build --release -p fovea -p fovea-vkdouble && cargo bench --bench vk_parallel --
//! --warm-up-time 1 --measurement-time 2` (needs the Vulkan loader and lavapipe; skips otherwise).

use std::ffi::{c_void, CStr};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Barrier, Mutex};
use std::time::{Duration, Instant};

use ash::vk;
use criterion::Criterion;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

extern "C" {
    fn __libc_malloc(size: usize) -> *mut c_void;
    fn __libc_calloc(n: usize, size: usize) -> *mut c_void;
    fn __libc_realloc(p: *mut c_void, size: usize) -> *mut c_void;
    fn __libc_memalign(align: usize, size: usize) -> *mut c_void;
    fn clock_gettime(clock: i32, out: *mut Timespec) -> i32;
}

/// # Safety
/// The C `malloc` contract.
#[no_mangle]
pub unsafe extern "C" fn malloc(size: usize) -> *mut c_void {
    ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    // SAFETY: glibc's own allocator, with the caller's arguments.
    unsafe { __libc_malloc(size) }
}

/// # Safety
/// The C `calloc` contract.
#[no_mangle]
pub unsafe extern "C" fn calloc(n: usize, size: usize) -> *mut c_void {
    ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    // SAFETY: as in malloc.
    unsafe { __libc_calloc(n, size) }
}

/// # Safety
/// The C `realloc` contract.
#[no_mangle]
pub unsafe extern "C" fn realloc(p: *mut c_void, size: usize) -> *mut c_void {
    ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    // SAFETY: as in malloc.
    unsafe { __libc_realloc(p, size) }
}

/// # Safety
/// The C `posix_memalign` contract.
#[no_mangle]
pub unsafe extern "C" fn posix_memalign(out: *mut *mut c_void, align: usize, size: usize) -> i32 {
    ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    // SAFETY: as in malloc.
    let p = unsafe { __libc_memalign(align, size) };
    if p.is_null() {
        return 12; // ENOMEM
    }
    // SAFETY: the caller's out pointer.
    unsafe { *out = p };
    0
}

/// # Safety
/// The C `aligned_alloc` contract.
#[no_mangle]
pub unsafe extern "C" fn aligned_alloc(align: usize, size: usize) -> *mut c_void {
    ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    // SAFETY: as in malloc.
    unsafe { __libc_memalign(align, size) }
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

const FOVEA: &CStr = c"VK_LAYER_FOVEA_fragment_density_map";
const FDM_EXT: &CStr = c"VK_EXT_fragment_density_map";
const THREADS: usize = 8;
const SIZE: u32 = 64;
/// Commands per round (each thread's command buffer is ended and reset between rounds, outside
/// the timed part). Long, so that waking the threads at each round's start weighs little in the
/// wall-clock figure; the double drops the commands, so the command buffers do not grow.
const ROUND: usize = 24_000;
/// The mix, in recording order.
const MIX: usize = 6;

/// One instance and device (bare or through fovea) with what every thread records into.
struct Side {
    instance: ash::Instance,
    device: ash::Device,
    color: (vk::Image, vk::DeviceMemory, vk::ImageView),
    pass: vk::RenderPass,
    framebuffer: vk::Framebuffer,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    /// One pool and command buffer per thread.
    buffers: Vec<(vk::CommandPool, vk::CommandBuffer)>,
}

impl Side {
    fn new(entry: &ash::Entry, with_fovea: bool) -> Result<Side, String> {
        let mut layers = vec![fovea_vkdouble::LAYER_NAME.as_ptr()];
        if with_fovea {
            layers.insert(0, FOVEA.as_ptr());
        }
        let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_3);
        let info = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layers);
        // SAFETY: every struct lives across its call; handles are used while alive.
        unsafe {
            let instance = entry
                .create_instance(&info, None)
                .map_err(|e| format!("vkCreateInstance: {e}"))?;
            let physical = instance
                .enumerate_physical_devices()
                .unwrap_or_default()
                .into_iter()
                .find(|&p| {
                    instance
                        .get_physical_device_properties(p)
                        .device_name_as_c_str()
                        .is_ok_and(|n| n.to_string_lossy().contains("llvmpipe"))
                })
                .ok_or("lavapipe (llvmpipe) is not installed")?;
            let prio = [1.0];
            let queues = [vk::DeviceQueueCreateInfo::default()
                .queue_family_index(0)
                .queue_priorities(&prio)];
            let exts = [FDM_EXT.as_ptr()];
            let mut fdm = vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default()
                .fragment_density_map(true)
                .fragment_density_map_non_subsampled_images(true);
            let mut v13 = vk::PhysicalDeviceVulkan13Features::default()
                .dynamic_rendering(true)
                .synchronization2(true);
            let mut dinfo = vk::DeviceCreateInfo::default()
                .queue_create_infos(&queues)
                .push_next(&mut v13);
            if with_fovea {
                dinfo = dinfo.enabled_extension_names(&exts).push_next(&mut fdm);
            }
            let device = instance
                .create_device(physical, &dinfo, None)
                .map_err(|e| format!("vkCreateDevice: {e}"))?;
            let color = color_target(&instance, physical, &device);
            let (pass, framebuffer) = pass_and_framebuffer(&device, color.2);
            let (layout, pipeline) = compute_pipeline(&device);
            let buffers = (0..THREADS)
                .map(|_| {
                    let pool = device
                        .create_command_pool(
                            &vk::CommandPoolCreateInfo::default()
                                .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER)
                                .queue_family_index(0),
                            None,
                        )
                        .expect("vkCreateCommandPool");
                    let cb = device
                        .allocate_command_buffers(
                            &vk::CommandBufferAllocateInfo::default()
                                .command_pool(pool)
                                .level(vk::CommandBufferLevel::PRIMARY)
                                .command_buffer_count(1),
                        )
                        .expect("vkAllocateCommandBuffers")[0];
                    (pool, cb)
                })
                .collect();
            Ok(Side {
                instance,
                device,
                color,
                pass,
                framebuffer,
                layout,
                pipeline,
                buffers,
            })
        }
    }

    /// Records command `i` of the mix into thread `t`'s command buffer.
    fn record(&self, t: usize, i: usize) {
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
            match i % MIX {
                0 => {
                    let barrier = [vk::ImageMemoryBarrier::default()
                        .src_access_mask(vk::AccessFlags::SHADER_READ)
                        .dst_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                        .old_layout(vk::ImageLayout::UNDEFINED)
                        .new_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                        .image(self.color.0)
                        .subresource_range(range())];
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
                        .image(self.color.0)
                        .subresource_range(range())];
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
                        .image_view(self.color.2)
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
            d.destroy_image_view(self.color.2, None);
            d.destroy_image(self.color.0, None);
            d.free_memory(self.color.1, None);
            d.destroy_device(None);
            self.instance.destroy_instance(None);
        }
    }
}

fn range() -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange::default()
        .aspect_mask(vk::ImageAspectFlags::COLOR)
        .level_count(1)
        .layer_count(1)
}

/// A 64×64 colour image with memory and a view.
///
/// # Safety
/// `device` must be live and made from `physical`.
unsafe fn color_target(
    instance: &ash::Instance,
    physical: vk::PhysicalDevice,
    device: &ash::Device,
) -> (vk::Image, vk::DeviceMemory, vk::ImageView) {
    let format = vk::Format::R8G8B8A8_UNORM;
    let info = vk::ImageCreateInfo::default()
        .image_type(vk::ImageType::TYPE_2D)
        .format(format)
        .extent(vk::Extent3D {
            width: SIZE,
            height: SIZE,
            depth: 1,
        })
        .mip_levels(1)
        .array_layers(1)
        .samples(vk::SampleCountFlags::TYPE_1)
        .tiling(vk::ImageTiling::OPTIMAL)
        .usage(vk::ImageUsageFlags::COLOR_ATTACHMENT);
    // SAFETY: as the caller promised; every struct lives across its call.
    unsafe {
        let image = device.create_image(&info, None).expect("vkCreateImage");
        let req = device.get_image_memory_requirements(image);
        let props = instance.get_physical_device_memory_properties(physical);
        let ty = (0..props.memory_type_count)
            .find(|i| req.memory_type_bits & (1 << i) != 0)
            .expect("a memory type");
        let memory = device
            .allocate_memory(
                &vk::MemoryAllocateInfo::default()
                    .allocation_size(req.size)
                    .memory_type_index(ty),
                None,
            )
            .expect("memory");
        device
            .bind_image_memory(image, memory, 0)
            .expect("vkBindImageMemory");
        let view = device
            .create_image_view(
                &vk::ImageViewCreateInfo::default()
                    .image(image)
                    .view_type(vk::ImageViewType::TYPE_2D)
                    .format(format)
                    .subresource_range(range()),
                None,
            )
            .expect("vkCreateImageView");
        (image, memory, view)
    }
}

/// A one-subpass pass without a density map, and its framebuffer.
///
/// # Safety
/// `device` must be live; `color` its view.
unsafe fn pass_and_framebuffer(
    device: &ash::Device,
    color: vk::ImageView,
) -> (vk::RenderPass, vk::Framebuffer) {
    let attachments = [vk::AttachmentDescription::default()
        .format(vk::Format::R8G8B8A8_UNORM)
        .samples(vk::SampleCountFlags::TYPE_1)
        .load_op(vk::AttachmentLoadOp::DONT_CARE)
        .store_op(vk::AttachmentStoreOp::STORE)
        .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
        .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
        .initial_layout(vk::ImageLayout::UNDEFINED)
        .final_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)];
    let refs = [vk::AttachmentReference::default()
        .attachment(0)
        .layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)];
    let subpasses = [vk::SubpassDescription::default()
        .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
        .color_attachments(&refs)];
    let views = [color];
    // SAFETY: as the caller promised; every struct lives across its call.
    unsafe {
        let pass = device
            .create_render_pass(
                &vk::RenderPassCreateInfo::default()
                    .attachments(&attachments)
                    .subpasses(&subpasses),
                None,
            )
            .expect("vkCreateRenderPass");
        let framebuffer = device
            .create_framebuffer(
                &vk::FramebufferCreateInfo::default()
                    .render_pass(pass)
                    .attachments(&views)
                    .width(SIZE)
                    .height(SIZE)
                    .layers(1),
                None,
            )
            .expect("vkCreateFramebuffer");
        (pass, framebuffer)
    }
}

/// A compute pipeline (`tests/suite/shaders/store.comp`) and its layout (one storage buffer,
/// eight bytes of push constants).
///
/// # Safety
/// `device` must be live.
unsafe fn compute_pipeline(device: &ash::Device) -> (vk::PipelineLayout, vk::Pipeline) {
    let code = ash::util::read_spv(&mut std::io::Cursor::new(
        &include_bytes!("../tests/suite/shaders/store.comp.spv")[..],
    ))
    .expect("SPIR-V");
    let bindings = [vk::DescriptorSetLayoutBinding::default()
        .binding(0)
        .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
        .descriptor_count(1)
        .stage_flags(vk::ShaderStageFlags::COMPUTE)];
    let ranges = [vk::PushConstantRange {
        stage_flags: vk::ShaderStageFlags::COMPUTE,
        offset: 0,
        size: 8,
    }];
    // SAFETY: as the caller promised; every struct lives across its call.
    unsafe {
        let set_layout = device
            .create_descriptor_set_layout(
                &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                None,
            )
            .expect("vkCreateDescriptorSetLayout");
        let set_layouts = [set_layout];
        let layout = device
            .create_pipeline_layout(
                &vk::PipelineLayoutCreateInfo::default()
                    .set_layouts(&set_layouts)
                    .push_constant_ranges(&ranges),
                None,
            )
            .expect("vkCreatePipelineLayout");
        device.destroy_descriptor_set_layout(set_layout, None);
        let module = device
            .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&code), None)
            .expect("vkCreateShaderModule");
        let info = [vk::ComputePipelineCreateInfo::default()
            .stage(
                vk::PipelineShaderStageCreateInfo::default()
                    .stage(vk::ShaderStageFlags::COMPUTE)
                    .module(module)
                    .name(c"main"),
            )
            .layout(layout)];
        let pipeline = device
            .create_compute_pipelines(vk::PipelineCache::null(), &info, None)
            .expect("vkCreateComputePipelines")[0];
        device.destroy_shader_module(module, None);
        (layout, pipeline)
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
                            job.side.record(t, i);
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
    fn run(&self, side: &Arc<Side>, threads: usize, per_thread: usize) -> Run {
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
        });
        for tx in &self.jobs[..threads] {
            tx.send(Some(Arc::clone(&job))).expect("worker");
        }
        let mut run = Run::default();
        let mut left = per_thread;
        while left > 0 {
            let n = left.min(ROUND);
            g.begun.wait();
            let a = ALLOCATIONS.load(Ordering::Relaxed);
            let t = Instant::now();
            g.go.wait();
            g.done.wait();
            run.wall += t.elapsed();
            run.allocations += ALLOCATIONS.load(Ordering::Relaxed) - a;
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

/// Both sides on the null bottom, or why not.
fn sides() -> Result<(Arc<Side>, Arc<Side>), String> {
    let fovea_lib = fovea_harness::artifact("libfovea.so")?
        .canonicalize()
        .map_err(|e| e.to_string())?;
    let double_lib = fovea_vkdouble::find_library()?;
    let dir = std::env::temp_dir().join(format!("fovea-vkparallel-{}", std::process::id()));
    fovea_vkdouble::write_manifest(&dir, &double_lib).map_err(|e| e.to_string())?;
    let checked_in = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("manifest/vulkan/VK_LAYER_FOVEA_fragment_density_map.json");
    let mut manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&checked_in).map_err(|e| e.to_string())?)
            .map_err(|e| e.to_string())?;
    manifest["layer"]["library_path"] = serde_json::json!(fovea_lib.to_string_lossy());
    std::fs::write(
        dir.join("VK_LAYER_FOVEA_fragment_density_map.json"),
        manifest.to_string(),
    )
    .map_err(|e| e.to_string())?;
    // Set before the loader first reads the environment, while nothing else runs.
    std::env::set_var("VK_ADD_LAYER_PATH", &dir);
    std::env::set_var(fovea_vkdouble::PROFILE_ENV, "nvidia");
    // Read by the double at vkCreateDevice.
    std::env::set_var(fovea_vkdouble::NULL_COMMANDS_ENV, "1");
    // SAFETY: loading libvulkan runs its initialisers, as any Vulkan application does.
    let entry = unsafe { ash::Entry::load() }.map_err(|e| format!("no Vulkan loader ({e})"))?;
    let bare = Side::new(&entry, false)?;
    let fovea = Side::new(&entry, true)?;
    // The entry (the loader library) must outlive every instance: keep it for the process.
    std::mem::forget(entry);
    Ok((Arc::new(bare), Arc::new(fovea)))
}

/// Criterion's time for `iters` commands per thread: the mean over threads of their CPU time.
fn timed(workers: &Workers, side: &Arc<Side>, threads: usize, iters: u64) -> Duration {
    workers.run(side, threads, iters as usize).cpu / threads as u32
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Per command, from interleaved runs: (CPU ns, scaled wall ns, allocations per command; fewest
/// in a run).
fn figures(workers: &Workers, side: &Arc<Side>, threads: usize, runs: usize) -> (f64, f64, f64) {
    let per_thread = ROUND;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let (mut cpu, mut wall, mut alloc) = (Vec::new(), Vec::new(), u64::MAX);
    for _ in 0..runs {
        let r = workers.run(side, threads, per_thread);
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

fn benches() {
    let (bare, fovea) = match sides() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("vk_parallel: skipped: {e}");
            return;
        }
    };
    let workers = Workers::new();
    // Warm up: every thread's command buffer reaches its steady size, the layer's scratch too.
    for side in [&bare, &fovea] {
        workers.run(side, THREADS, ROUND);
    }
    let mut c = Criterion::default()
        .sample_size(20)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .configure_from_args();
    let mut g = c.benchmark_group("vk_parallel/null");
    for threads in [1, THREADS] {
        for (label, side) in [("bare", &bare), ("fovea", &fovea)] {
            g.bench_function(format!("{threads} thread(s)/{label}"), |b| {
                b.iter_custom(|iters| timed(&workers, side, threads, iters))
            });
        }
    }
    g.finish();
    c.final_summary();

    const RUNS: usize = 60;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut rows = Vec::new();
    for _ in 0..RUNS / 10 {
        for threads in [1, THREADS] {
            for (i, side) in [&bare, &fovea].into_iter().enumerate() {
                rows.push((threads, i, figures(&workers, side, threads, 10)));
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
        "\nvk_parallel summary, null bottom, {cores} core(s): median ns per command (mix of \
         barrier, barrier2, compute bind, push constants, render pass begin+end, rendering \
         begin+end) over {RUNS} interleaved runs of {} commands per thread",
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
                    "{threads} thread(s): {av} allocations per command, {ab} without the layer"
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
    assert!(
        allocates.is_empty(),
        "the layer allocates while recording:\n{}",
        allocates.join("\n")
    );
    drop(workers);
}

fn main() {
    benches();
}
