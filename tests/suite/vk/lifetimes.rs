//! What long-running applications do to the objects fovea's Vulkan layer keeps state for: density
//! maps the application writes recreated (a resolution change, a session restart, a swapchain
//! recreation) while the command buffer that converted them lives on and is recorded again, their
//! views, render passes and framebuffers recreated with them, and the command buffer reset in every
//! way the specification allows (implicitly at `vkBeginCommandBuffer`, `vkResetCommandBuffer`,
//! `vkResetCommandPool`, freed and allocated again).
//!
//! Stack as in [`crate::support::device`] (this test → fovea → validation with unique handles off,
//! so that validation sees the driver's own handles, which lavapipe reuses → the double → lavapipe).
//! Checked per cycle: the shading rates the double reads back from the shadow at the submit are the
//! model's for the bytes the application wrote into this cycle's map (never a destroyed map's, and
//! never a conversion sized for another map); validation says nothing but its 1.3.239 stage false
//! positives; the double records no misuse. Over the cycles: the buffers, memory objects and image
//! views alive below the layers (the double counts their creation and destruction,
//! [`fovea_vkdouble::COUNTED`]) do not grow, so the layer keeps no conversion objects of dead maps,
//! and the process's resident memory stays put.

use ash::vk;
use ash::vk::Handle as _;
use fovea_vkdouble::Profile;

use crate::support::device::{allocate, env, resettable_pool, take_real_messages, Env, Vk};
use crate::support::vulkan::{
    begin_pass, cleared_color, density_pass, draw_fullscreen, framebuffer, spv, stages,
    to_color_attachment, Fixed, AREA, COLOR, DENSITY, FDM_LAYOUT, FRAGMENT, SIZE, VERTEX,
};
use crate::vk::convert::{codes_of, converting_device, model_codes, read_at_submit};

/// How a cycle begins recording the command buffer again.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reset {
    /// `vkBeginCommandBuffer` on a command buffer that was recorded (the pool allows it).
    Implicit,
    /// `vkResetCommandBuffer`, releasing its resources.
    Buffer,
    /// `vkResetCommandPool`.
    Pool,
    /// `vkFreeCommandBuffers`, then a new one (the driver may hand back the same handle).
    Reallocate,
}

const RESETS: [Reset; 4] = [
    Reset::Implicit,
    Reset::Buffer,
    Reset::Pool,
    Reset::Reallocate,
];

/// How a cycle's pass reads its map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Pass {
    /// `vkCmdBeginRendering` with `VkRenderingFragmentDensityMapAttachmentInfoEXT`.
    Rendering,
    /// `vkCmdBeginRenderPass2` with a render pass and framebuffer made for this cycle's map.
    RenderPass,
}

/// Objects alive below the layers, as the double counted their creation and destruction.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Alive {
    buffers: i64,
    memory: i64,
    views: i64,
}

/// Command buffers allocated below the layers (the application's and fovea's own), which the
/// double counts.
fn allocations(env: &Env) -> u64 {
    env.double.calls("vkAllocateCommandBuffers")
}

impl Alive {
    /// What the double counted since its records were last cleared, added to `self`.
    fn add_counted(&mut self, env: &Env) {
        let n = |name: &str| env.double.calls(name) as i64;
        self.buffers += n("vkCreateBuffer") - n("vkDestroyBuffer");
        self.memory += n("vkAllocateMemory") - n("vkFreeMemory");
        self.views += n("vkCreateImageView") - n("vkDestroyImageView");
    }
}

/// The process's resident memory in bytes (`/proc/self/statm`), where the system tells.
fn resident() -> Option<u64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4096)
}

/// The application's bytes for a `side`×`side` R8G8 map in `cycle`: every texel different from the
/// previous cycle's, so a conversion of a stale map shows.
fn bytes(side: u32, cycle: u32) -> Vec<u8> {
    const LEVELS: [u8; 5] = [0, 30, 100, 160, 255];
    (0..side * side)
        .flat_map(|t| {
            [
                LEVELS[((t * 3 + cycle) % 5) as usize],
                LEVELS[((t + cycle * 2 + 1) % 5) as usize],
            ]
        })
        .collect()
}

/// What a run of [`cycles`] saw.
struct Seen {
    /// Objects alive below the layers after each cycle.
    alive: Vec<Alive>,
    /// Command buffers allocated below the layers by the end of each cycle.
    allocated: Vec<u64>,
    /// Resident memory after each cycle.
    resident: Vec<Option<u64>>,
    /// Cycles whose map had the handle of an earlier cycle's destroyed map.
    reused: usize,
}

/// `n` cycles on a converting device: each creates a density map (twice as wide every other
/// cycle, so a conversion sized for the previous map would write past its buffer), its view and,
/// for [`Pass::RenderPass`], a render pass and framebuffer; records into the one command buffer
/// (begun again as `resets` says) an upload of the cycle's bytes and a pass that reads the map;
/// submits and waits; checks the rates the pass got; destroys the map, its view, and the pass and
/// framebuffer. The double's records are read and cleared each cycle, so the run's cost does not
/// grow with its length.
fn cycles(env: &Env, vk: &Vk, profile: Profile, n: u32, passes: &[Pass], resets: &[Reset]) -> Seen {
    let dev = converting_device(vk, false);
    let d = &dev.d;
    let side = SIZE / profile.texel().width;
    let staging = dev.buffer(
        u64::from(4 * side * side * 2),
        vk::BufferUsageFlags::TRANSFER_SRC,
    );
    let (color, color_memory, color_view) =
        dev.image(COLOR, SIZE, 1, vk::ImageUsageFlags::COLOR_ATTACHMENT);
    let pool = resettable_pool(d, 0);
    let mut cb = allocate(d, pool);
    let mut alive = Alive::default();
    alive.add_counted(env);
    env.double.clear();
    let mut allocated = 0;
    let mut seen = Seen {
        alive: Vec::new(),
        allocated: Vec::new(),
        resident: Vec::new(),
        reused: 0,
    };
    let mut handles = std::collections::HashSet::new();
    for cycle in 0..n {
        let pass = passes[cycle as usize % passes.len()];
        let reset = resets[cycle as usize % resets.len()];
        // Every other cycle destroys the map before its view.
        let image_first = cycle % 2 == 1;
        let what = format!("{profile:?} cycle {cycle} ({pass:?}, {reset:?})");
        let map_side = side * (1 + cycle / 2 % 2);
        let (map, map_memory, map_view) = dev.image(
            DENSITY,
            map_side,
            1,
            vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT | vk::ImageUsageFlags::TRANSFER_DST,
        );
        if !handles.insert(map.as_raw()) {
            seen.reused += 1;
        }
        let bytes = bytes(map_side, cycle);
        dev.write(&staging, &bytes);
        // SAFETY: the command buffer is not pending (every cycle waits for the queue); every
        // struct lives across its call.
        unsafe {
            match reset {
                Reset::Implicit => {}
                Reset::Buffer => d
                    .reset_command_buffer(cb, vk::CommandBufferResetFlags::RELEASE_RESOURCES)
                    .expect("vkResetCommandBuffer"),
                Reset::Pool => d
                    .reset_command_pool(pool, vk::CommandPoolResetFlags::empty())
                    .expect("vkResetCommandPool"),
                Reset::Reallocate => {
                    d.free_command_buffers(pool, &[cb]);
                    cb = allocate(d, pool);
                }
            }
            d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
                .expect("vkBeginCommandBuffer");
            dev.upload(cb, &staging, map, map_side, 1);
            to_color_attachment(d, cb, &[color], 1);
        }
        let made = match pass {
            Pass::Rendering => {
                let color_att = [cleared_color(color_view)];
                let mut density = vk::RenderingFragmentDensityMapAttachmentInfoEXT::default()
                    .image_view(map_view)
                    .image_layout(FDM_LAYOUT);
                let info = vk::RenderingInfo::default()
                    .render_area(AREA)
                    .layer_count(1)
                    .color_attachments(&color_att)
                    .push_next(&mut density);
                // SAFETY: recording; the structs live across the calls.
                unsafe {
                    d.cmd_begin_rendering(cb, &info);
                    d.cmd_end_rendering(cb);
                }
                None
            }
            Pass::RenderPass => {
                // SAFETY: the device is alive; the structs live across the calls.
                unsafe {
                    let rp = density_pass(d, vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL, FDM_LAYOUT)
                        .expect("vkCreateRenderPass2");
                    let fb = framebuffer(d, rp, &[color_view, map_view], SIZE);
                    begin_pass(d, cb, rp, fb);
                    d.cmd_end_render_pass2(cb, &vk::SubpassEndInfo::default());
                    Some((rp, fb))
                }
            }
        };
        dev.submit(cb);
        let got = codes_of(&read_at_submit(env, cb), &what);
        let want = model_codes(profile, &bytes, (map_side * map_side) as usize, 1);
        assert!(
            want.iter().any(|&c| c != 0),
            "{what}: a map that tests nothing"
        );
        assert!(got == want, "{what}: shadow codes {got:?}, want {want:?}");
        // SAFETY: the queue is idle; each object destroyed once, the map's users first.
        unsafe {
            if let Some((rp, fb)) = made {
                d.destroy_framebuffer(fb, None);
                d.destroy_render_pass(rp, None);
            }
            if image_first {
                // Valid: nothing requires a view to go before its image, only that no pending
                // command uses either (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkDestroyImage.html>).
                d.destroy_image(map, None);
                d.free_memory(map_memory, None);
                d.destroy_image_view(map_view, None);
            } else {
                d.destroy_image_view(map_view, None);
                d.destroy_image(map, None);
                d.free_memory(map_memory, None);
            }
        }
        let messages = take_real_messages();
        assert!(
            messages.is_empty(),
            "{what}: validation reported {messages:#?}"
        );
        let errors = env.double.errors();
        assert!(errors.is_empty(), "{what}: the double refused {errors:#?}");
        alive.add_counted(env);
        allocated += allocations(env);
        env.double.clear();
        seen.alive.push(alive);
        seen.allocated.push(allocated);
        seen.resident.push(resident());
    }
    // SAFETY: the queue is idle; everything else made from the device is gone with these.
    unsafe {
        d.destroy_command_pool(pool, None);
        d.destroy_image_view(color_view, None);
        d.destroy_image(color, None);
        d.free_memory(color_memory, None);
    }
    dev.free(staging);
    dev.destroy();
    assert!(
        take_real_messages().is_empty(),
        "{profile:?}: at vkDestroyDevice"
    );
    seen
}

/// An application that records a dynamic-rendering pass with its own density map into one command
/// buffer, and recreates the map each cycle: every cycle's pass shades with that cycle's map,
/// though lavapipe hands the destroyed map's image and the layer's view of it the same handles
/// again, and though every other map is twice as large. Before the layer matched a command
/// buffer's conversion objects to their map by its generation, the second cycle bound a descriptor
/// set naming a destroyed view (VUID-vkCmdDispatch-None-02699) and wrote past the code buffer.
#[test]
fn a_recreated_map_is_converted_with_objects_of_its_own() {
    let Some((_serial, env)) = env() else { return };
    for profile in [Profile::Nvidia, Profile::Amd] {
        let Some(vk) = Vk::new(env, profile, true) else {
            return;
        };
        let seen = cycles(
            env,
            &vk,
            profile,
            100,
            &[Pass::Rendering],
            &[Reset::Implicit],
        );
        assert!(
            seen.reused > 0,
            "{profile:?}: the driver never reused a map's handle, so this tests nothing"
        );
        drop(vk);
        assert!(take_real_messages().is_empty(), "{profile:?}");
    }
}

/// A thousand cycles of recreated maps, views, render passes and framebuffers under one command
/// buffer, alternating dynamic rendering and render passes and every way of resetting it, on both
/// profiles: every pass shades with its own cycle's map, and after the first cycles nothing grows,
/// neither the objects alive below the layers (the layer keeps one set of conversion objects per
/// live map and command buffer) nor the process's resident memory.
///
/// It runs in a process of its own, so that no other test's allocations land in the resident
/// memory it measures.
#[test]
fn a_thousand_recreations_under_a_live_command_buffer_leave_nothing_behind() {
    crate::support::in_own_process(
        module_path!(),
        "a_thousand_recreations_under_a_live_command_buffer_leave_nothing_behind",
        thousand_recreations,
    );
}

fn thousand_recreations() {
    let Some((_serial, env)) = env() else { return };
    for profile in [Profile::Nvidia, Profile::Amd] {
        let Some(vk) = Vk::new(env, profile, true) else {
            return;
        };
        let n = 1000;
        let seen = cycles(
            env,
            &vk,
            profile,
            n,
            &[Pass::Rendering, Pass::RenderPass],
            &RESETS,
        );
        // After the first cycles every cycle ends with what was alive before it: the device's own
        // objects and the application's staging, target and pool; nothing per map.
        let settled = seen.alive[8];
        for (i, a) in seen.alive.iter().enumerate().skip(8) {
            assert_eq!(
                *a, settled,
                "{profile:?}: objects alive below the layers after cycle {i}, against cycle 8"
            );
        }
        // Resident memory, from the hundredth cycle to the last. Debian 12's validation layer
        // (1.3.239) keeps about 4 KiB for each command buffer fovea allocates for the shadow
        // clears of a new map (heaptrack: allocated in the validation layer under
        // `Clears::flush`'s vkAllocateCommandBuffers, never freed before vkDestroyDevice), about
        // 5 KiB a cycle here, so there the bound is three times that, which a leak of the layer's
        // own per recreation (a record, a map entry, a descriptor pool) would still pass through
        // quickly; with validation 1.4 (Debian 13: under 200 B a cycle) it is 1 KiB.
        let per_cycle_bound: u64 = if validation_version(env) >= vk::make_api_version(0, 1, 4, 0) {
            1 << 10
        } else {
            16 << 10
        };
        let last = n as usize - 1;
        if let (Some(a), Some(b)) = (seen.resident[100], seen.resident[last]) {
            let grown = b.saturating_sub(a);
            let cycles = (last - 100) as u64;
            let allocated = seen.allocated[last] - seen.allocated[100];
            eprintln!(
                "{profile:?}: resident {} KiB at cycle 100, {} KiB at cycle {last}: +{} B a \
                 cycle; {allocated} command buffers allocated meanwhile; {} maps had a \
                 destroyed one's handle",
                a / 1024,
                b / 1024,
                grown / cycles,
                seen.reused
            );
            assert!(
                grown / cycles < per_cycle_bound,
                "{profile:?}: resident memory grew by {} KiB over {cycles} cycles",
                grown / 1024
            );
        }
        drop(vk);
        assert!(take_real_messages().is_empty(), "{profile:?}");
    }
}

/// A long run keeps what the double knows of every object still alive: a render pass, its
/// framebuffer, a pipeline, the map's shadow and its view, made before more than twice as many
/// commands as the double keeps events for were recorded, still have their records afterwards,
/// and a draw recorded then gets its effective rates (the model's for the application's map);
/// a render pass destroyed before the run has none left, so what the double keeps stays bounded
/// by what the application keeps alive.
#[test]
fn definitions_outlive_a_long_run() {
    let Some((_serial, env)) = env() else { return };
    let profile = Profile::Nvidia;
    let Some(vk) = Vk::new(env, profile, true) else {
        return;
    };
    let dev = converting_device(&vk, false);
    let d = &dev.d;
    let side = SIZE / profile.texel().width;
    let bytes = bytes(side, 3);
    let staging = dev.buffer(bytes.len() as u64, vk::BufferUsageFlags::TRANSFER_SRC);
    dev.write(&staging, &bytes);
    let (map, map_memory, map_view) = dev.image(
        DENSITY,
        side,
        1,
        vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT | vk::ImageUsageFlags::TRANSFER_DST,
    );
    let (color, color_memory, color_view) =
        dev.image(COLOR, SIZE, 1, vk::ImageUsageFlags::COLOR_ATTACHMENT);
    let kept = fovea_vkdouble::KEPT_EVENTS;
    // SAFETY: the device is alive; every struct lives across its call; every object is
    // destroyed once, after the queue is idle.
    unsafe {
        let gone = density_pass(d, vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL, FDM_LAYOUT)
            .expect("vkCreateRenderPass2");
        d.destroy_render_pass(gone, None);
        let rp = density_pass(d, vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL, FDM_LAYOUT)
            .expect("vkCreateRenderPass2");
        let fb = framebuffer(d, rp, &[color_view, map_view], SIZE);
        let layout = d
            .create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default(), None)
            .expect("vkCreatePipelineLayout");
        let module = |code: &[u8]| {
            d.create_shader_module(
                &vk::ShaderModuleCreateInfo::default().code(&spv(code)),
                None,
            )
            .expect("vkCreateShaderModule")
        };
        let modules = [module(VERTEX), module(FRAGMENT)];
        let stages = stages(modules);
        let fixed = Fixed::new();
        let pipeline = d
            .create_graphics_pipelines(
                vk::PipelineCache::null(),
                &[fixed.info(&stages, layout).render_pass(rp).subpass(0)],
                None,
            )
            .expect("vkCreateGraphicsPipelines")[0];
        for m in modules {
            d.destroy_shader_module(m, None);
        }

        // The long run: more barriers than twice the events the double keeps (it trims them
        // once there are twice as many).
        let pool = resettable_pool(d, 0);
        let cb = allocate(d, pool);
        let barrier = [vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE)
            .dst_access_mask(vk::AccessFlags::SHADER_READ)];
        for _ in 0..2 {
            d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
                .expect("vkBeginCommandBuffer");
            for _ in 0..kept + 64 {
                d.cmd_pipeline_barrier(
                    cb,
                    vk::PipelineStageFlags::COMPUTE_SHADER,
                    vk::PipelineStageFlags::FRAGMENT_SHADER,
                    vk::DependencyFlags::empty(),
                    &barrier,
                    &[],
                    &[],
                );
            }
            d.end_command_buffer(cb).expect("vkEndCommandBuffer");
        }

        // Then a frame that draws with the map.
        d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
            .expect("vkBeginCommandBuffer");
        dev.upload(cb, &staging, map, side, 1);
        to_color_attachment(d, cb, &[color], 1);
        begin_pass(d, cb, rp, fb);
        draw_fullscreen(d, cb, pipeline);
        d.cmd_end_render_pass2(cb, &vk::SubpassEndInfo::default());
        dev.submit(cb);

        let records = env.double.records();
        assert!(
            records["dropped"].as_u64().unwrap_or(0) >= kept as u64,
            "the run went past the bound: {}",
            records["dropped"]
        );
        let events = records["events"].as_array().expect("events");
        assert!(events.len() < 2 * kept, "{} events kept", events.len());
        let defined = |kind: &str, field: &str, handle: u64| {
            events
                .iter()
                .filter(|e| e["kind"] == kind && e[field].as_u64() == Some(handle))
                .count()
        };
        assert_eq!(defined("render_pass", "render_pass", rp.as_raw()), 1);
        assert_eq!(defined("framebuffer", "framebuffer", fb.as_raw()), 1);
        assert_eq!(defined("pipeline", "pipeline", pipeline.as_raw()), 1);
        let pipeline_record = events
            .iter()
            .find(|e| e["kind"] == "pipeline" && e["pipeline"].as_u64() == Some(pipeline.as_raw()))
            .expect("the pipeline's record");
        assert_ne!(
            pipeline_record["shading_rate_state"],
            serde_json::Value::Null,
            "the pipeline lets the attachment decide"
        );
        let shadows: Vec<_> = events.iter().filter(|e| e["kind"] == "image").collect();
        assert_eq!(shadows.len(), 1, "the map's shadow: {shadows:?}");
        assert!(
            events
                .iter()
                .any(|e| e["kind"] == "image_view" && e["image"] == shadows[0]["image"]),
            "the shadow's view"
        );
        if gone != rp {
            assert_eq!(
                defined("render_pass", "render_pass", gone.as_raw()),
                0,
                "a render pass destroyed before the run is not kept"
            );
        }
        // What the draw shaded with: the model's rates for the application's map.
        let rates = env
            .double
            .effective_rates(cb.as_raw(), 0, 0)
            .expect("the draw's effective rates");
        let want = model_codes(profile, &bytes, (side * side) as usize, 1);
        assert_eq!(rates.len(), 1);
        assert_eq!(rates[0].codes, want, "the draw's effective rates");

        d.destroy_command_pool(pool, None);
        d.destroy_pipeline(pipeline, None);
        d.destroy_pipeline_layout(layout, None);
        d.destroy_framebuffer(fb, None);
        d.destroy_render_pass(rp, None);
        d.destroy_image_view(map_view, None);
        d.destroy_image(map, None);
        d.free_memory(map_memory, None);
        d.destroy_image_view(color_view, None);
        d.destroy_image(color, None);
        d.free_memory(color_memory, None);
    }
    dev.free(staging);
    dev.finish(env, vk);
}

/// The installed validation layer's specification version.
fn validation_version(env: &Env) -> u32 {
    // SAFETY: a plain query.
    unsafe { env.entry.enumerate_instance_layer_properties() }
        .unwrap_or_default()
        .iter()
        .find(|l| l.layer_name_as_c_str() == Ok(c"VK_LAYER_KHRONOS_validation"))
        .map_or(0, |l| l.spec_version)
}
