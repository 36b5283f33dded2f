//! fovea's Vulkan layer on pipelines, samplers, views, shaders and barriers: the same stack as
//! [`crate::support::device`] (this test → fovea → validation → the shading-rate double → lavapipe), on
//! both shading-rate profiles. Validation must stay silent; the double's records say what the
//! driver was told.
//!
//! The shaders are the GLSL files beside their SPIR-V in `tests/suite/shaders/`
//! (`glslangValidator -V --target-env vulkan1.1 -Os -g0`).

use ash::vk;
use fovea_vkdouble::Profile;
use serde_json::{json, Value};

use crate::support::device::{
    assert_no_messages, assert_only_stage_false_positives, env, fdm_image_info, take_messages, Env,
    Vk,
};
use crate::support::vulkan::{range, spv, stages, Fixed, COLOR};

const FDM_FLAG: vk::PipelineCreateFlags =
    vk::PipelineCreateFlags::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_EXT;

/// The shading-rate state fovea gives pipelines used with a density map: 1×1, {KEEP, REPLACE}.
fn injected() -> Value {
    json!({"fragment_size": [1, 1], "combiner_ops": [0, 1]})
}

/// A device with emulated density maps (and, with `gpl`, graphics pipeline libraries).
fn fdm_device(vk: &Vk, gpl: bool) -> ash::Device {
    let mut library = vk::PhysicalDeviceGraphicsPipelineLibraryFeaturesEXT::default()
        .graphics_pipeline_library(true);
    if gpl {
        let exts = [
            ash::khr::pipeline_library::NAME,
            ash::ext::graphics_pipeline_library::NAME,
        ];
        vk.fdm_device(&exts, Some(&mut library))
    } else {
        vk.fdm_device(&[], None)
    }
}

struct Objects {
    vert: vk::ShaderModule,
    frag: vk::ShaderModule,
    layout: vk::PipelineLayout,
}

impl Objects {
    fn new(d: &ash::Device) -> Objects {
        let vert = spv(include_bytes!("../shaders/triangle.vert.spv"));
        let frag = spv(include_bytes!("../shaders/white.frag.spv"));
        // SAFETY: create infos live across the calls.
        unsafe {
            Objects {
                vert: d
                    .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&vert), None)
                    .expect("vertex shader"),
                frag: d
                    .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&frag), None)
                    .expect("fragment shader"),
                layout: d
                    .create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default(), None)
                    .expect("layout"),
            }
        }
    }

    fn destroy(&self, d: &ash::Device) {
        // SAFETY: no pipeline creation is in flight.
        unsafe {
            d.destroy_shader_module(self.vert, None);
            d.destroy_shader_module(self.frag, None);
            d.destroy_pipeline_layout(self.layout, None);
        }
    }
}

/// Creates one graphics pipeline from `info` (whose pointers `fixed` and the caller keep alive).
fn create(d: &ash::Device, info: &vk::GraphicsPipelineCreateInfo<'_>) -> vk::Pipeline {
    // SAFETY: everything the create info points at lives across the call.
    unsafe {
        d.create_graphics_pipelines(vk::PipelineCache::null(), std::slice::from_ref(info), None)
    }
    .map(|p| p[0])
    .unwrap_or_else(|(_, e)| panic!("vkCreateGraphicsPipelines: {e}; {:?}", take_messages()))
}

/// Memory of the first type `image` allows, bound to it.
///
/// # Safety
/// `image` must be alive on `d` and without memory.
unsafe fn bound_memory(d: &ash::Device, image: vk::Image) -> vk::DeviceMemory {
    // SAFETY: the caller's promise; the struct lives across the call.
    unsafe {
        let req = d.get_image_memory_requirements(image);
        let memory = d
            .allocate_memory(
                &vk::MemoryAllocateInfo::default()
                    .allocation_size(req.size)
                    .memory_type_index(req.memory_type_bits.trailing_zeros()),
                None,
            )
            .expect("memory");
        d.bind_image_memory(image, memory, 0).expect("bind");
        memory
    }
}

/// The double's record of `pipeline`.
fn record(env: &Env, pipeline: vk::Pipeline) -> Value {
    use ash::vk::Handle as _;
    env.double
        .events("pipeline")
        .into_iter()
        .find(|e| e["pipeline"] == pipeline.as_raw())
        .unwrap_or_else(|| panic!("no record of {pipeline:?}"))
}

/// Runs `body` on each shading-rate profile with a density-map device (with graphics pipeline
/// libraries where `gpl`) and [`Objects`] on it, then destroys those and checks that neither the
/// double nor validation complained. `body` destroys what it made.
fn on_each_profile(gpl: bool, body: impl Fn(&Env, Profile, &ash::Device, &Objects)) {
    let Some((_serial, env)) = env() else { return };
    for profile in [Profile::Nvidia, Profile::Amd] {
        let Some(vk) = Vk::new(env, profile, true) else {
            return;
        };
        let d = fdm_device(&vk, gpl);
        let o = Objects::new(&d);
        body(env, profile, &d, &o);
        // SAFETY: nothing made from them is left.
        unsafe {
            o.destroy(&d);
            d.destroy_device(None);
        }
        assert_eq!(env.double.errors(), Vec::<String>::new());
        drop(vk);
        assert_no_messages();
    }
}

/// A pipeline for dynamic rendering with a density map reaches the driver with the shading-rate flag and
/// the state that lets the attachment decide; a pipeline for a render pass without a density map
/// is untouched. (The 64-bit flags in `VkPipelineCreateFlags2CreateInfoKHR` are unit-tested only:
/// the validation layer here, 1.3.239, predates that struct and reports it as unknown.)
#[test]
fn pipelines_used_with_density_maps_let_the_attachment_decide() {
    on_each_profile(false, |env, profile, d, o| {
        let f = Fixed::new();
        let stages = stages([o.vert, o.frag]);
        let base = f.info(&stages, o.layout);

        let mut rendering =
            vk::PipelineRenderingCreateInfo::default().color_attachment_formats(&[COLOR]);
        let with_flag = base.flags(FDM_FLAG).push_next(&mut rendering);
        let p_flag = create(d, &with_flag);

        let attachment = [vk::AttachmentDescription::default()
            .format(COLOR)
            .samples(vk::SampleCountFlags::TYPE_1)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::STORE)
            .initial_layout(vk::ImageLayout::UNDEFINED)
            .final_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)];
        let color_ref = [vk::AttachmentReference::default()
            .attachment(0)
            .layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)];
        let subpass = [vk::SubpassDescription::default().color_attachments(&color_ref)];
        // SAFETY: the create info lives across the call.
        let pass = unsafe {
            d.create_render_pass(
                &vk::RenderPassCreateInfo::default()
                    .attachments(&attachment)
                    .subpasses(&subpass),
                None,
            )
        }
        .expect("render pass");
        let p_plain = create(d, &base.render_pass(pass));

        let r = record(env, p_flag);
        assert_eq!(r["shading_rate_state"], injected(), "{profile:?}: {r}");
        assert_eq!(r["rendering_attachment_flag"], true, "{profile:?}");
        let r = record(env, p_plain);
        assert_eq!(r["shading_rate_state"], Value::Null, "{profile:?}: {r}");
        assert_eq!(r["rendering_attachment_flag"], false);
        assert_eq!(
            with_flag.flags, FDM_FLAG,
            "the application's create info is not written"
        );

        // SAFETY: nothing uses them any more.
        unsafe {
            for p in [p_flag, p_plain] {
                d.destroy_pipeline(p, None);
            }
            d.destroy_render_pass(pass, None);
        }
    });
}

/// Graphics pipeline libraries (lavapipe 22.3 offers VK_EXT_graphics_pipeline_library): the
/// pre-rasterisation and fragment-shader libraries of a density-map pipeline both carry the same
/// shading-rate state, the vertex-input and fragment-output ones none. (Linking them is not
/// checked here: validation 1.3.239 reports VUID-VkGraphicsPipelineCreateInfo-renderPass-06054 on
/// the link of dynamic-rendering libraries whatever fovea does.)
#[test]
fn pipeline_libraries_agree_on_the_shading_rate_state() {
    on_each_profile(true, |env, profile, d, o| {
        let f = Fixed::new();
        let [vert, frag] = stages([o.vert, o.frag]);
        let flags = FDM_FLAG | vk::PipelineCreateFlags::LIBRARY_KHR;
        type L = vk::GraphicsPipelineLibraryFlagsEXT;
        let library = |part: L, info: vk::GraphicsPipelineCreateInfo<'_>| {
            let mut gpl = vk::GraphicsPipelineLibraryCreateInfoEXT::default().flags(part);
            // Pre-rasterisation state reads only the view mask of it (validation 1.3.239 wants
            // colour blend state wherever it sees colour formats).
            let formats: &[vk::Format] = if part == L::PRE_RASTERIZATION_SHADERS {
                &[]
            } else {
                &[COLOR]
            };
            let mut rendering =
                vk::PipelineRenderingCreateInfo::default().color_attachment_formats(formats);
            let p = create(
                d,
                &info
                    .flags(flags)
                    .color_blend_state(&f.blend)
                    .push_next(&mut gpl)
                    .push_next(&mut rendering),
            );
            p
        };
        let base = vk::GraphicsPipelineCreateInfo::default();
        let vertex_input = library(
            L::VERTEX_INPUT_INTERFACE,
            base.vertex_input_state(&f.vertex)
                .input_assembly_state(&f.assembly),
        );
        let pre_raster = library(
            L::PRE_RASTERIZATION_SHADERS,
            base.stages(std::slice::from_ref(&vert))
                .viewport_state(&f.viewport)
                .rasterization_state(&f.raster)
                .dynamic_state(&f.dynamic)
                .layout(o.layout),
        );
        let fragment = library(
            L::FRAGMENT_SHADER,
            base.stages(std::slice::from_ref(&frag))
                .multisample_state(&f.multisample)
                .depth_stencil_state(&f.depth)
                .dynamic_state(&f.dynamic)
                .layout(o.layout),
        );
        let output = library(
            L::FRAGMENT_OUTPUT_INTERFACE,
            base.multisample_state(&f.multisample)
                .color_blend_state(&f.blend),
        );
        let libraries = [vertex_input, pre_raster, fragment, output];
        for (p, state) in [
            (vertex_input, Value::Null),
            (pre_raster, injected()),
            (fragment, injected()),
            (output, Value::Null),
        ] {
            let r = record(env, p);
            assert_eq!(r["shading_rate_state"], state, "{profile:?}: {r}");
            assert_eq!(r["rendering_attachment_flag"], true, "{profile:?}: {r}");
        }
        // SAFETY: nothing uses them any more.
        unsafe {
            for p in libraries {
                d.destroy_pipeline(p, None);
            }
        }
    });
}

/// Samplers with the subsampled flags and density-map views with the dynamic flag are created
/// (without those flags below), validation-clean; a shader reading `FragSizeEXT` is passed on
/// (the layer says once it cannot be emulated) without a crash.
#[test]
fn subsampled_samplers_dynamic_views_and_frag_size_shaders() {
    let Some((_serial, env)) = env() else { return };
    for profile in [Profile::Nvidia, Profile::Amd] {
        let Some(vk) = Vk::new(env, profile, true) else {
            return;
        };
        let d = fdm_device(&vk, false);
        // SAFETY: create infos live across the calls; objects are destroyed before the device.
        unsafe {
            let sampler = d
                .create_sampler(
                    &vk::SamplerCreateInfo::default().flags(
                        vk::SamplerCreateFlags::SUBSAMPLED_EXT
                            | vk::SamplerCreateFlags::SUBSAMPLED_COARSE_RECONSTRUCTION_EXT,
                    ),
                    None,
                )
                .expect("a subsampled sampler");
            let image = d
                .create_image(
                    &fdm_image_info().usage(
                        vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT
                            | vk::ImageUsageFlags::SAMPLED,
                    ),
                    None,
                )
                .expect("density image");
            let memory = bound_memory(&d, image);
            let view = d
                .create_image_view(
                    &vk::ImageViewCreateInfo::default()
                        .flags(vk::ImageViewCreateFlags::FRAGMENT_DENSITY_MAP_DYNAMIC_EXT)
                        .image(image)
                        .view_type(vk::ImageViewType::TYPE_2D_ARRAY)
                        .format(vk::Format::R8G8_UNORM)
                        .subresource_range(range(0, 2)),
                    None,
                )
                .expect("a dynamic density-map view");
            assert_eq!(env.double.errors(), Vec::<String>::new());
            assert_no_messages();

            let code = spv(include_bytes!("../shaders/frag_size.frag.spv"));
            let r =
                d.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&code), None);
            // The driver below has no density maps, so validation may refuse the capability; what
            // matters is that the call came back.
            let said = take_messages();
            assert!(
                said.iter().all(|m| m.contains("FragmentDensity")
                    || m.contains("08740")
                    || m.contains("08742")
                    || m.contains("Capability")),
                "{said:?}"
            );
            if let Ok(m) = r {
                d.destroy_shader_module(m, None);
            }
            d.destroy_image_view(view, None);
            d.destroy_image(image, None);
            d.free_memory(memory, None);
            d.destroy_sampler(sampler, None);
            d.destroy_device(None);
        }
        drop(vk);
        take_messages();
    }
}

/// Barriers and event waits that move a density map into its layout for the density stage reach
/// the driver without a density-map bit (the double sees the general layout and the shading-rate
/// stage and access), validation-clean through to the submit.
#[test]
fn barriers_lose_the_density_map_bits() {
    use ash::vk::Handle as _;
    let Some((_serial, env)) = env() else { return };
    for profile in [Profile::Nvidia, Profile::Amd] {
        let Some(vk) = Vk::new(env, profile, true) else {
            return;
        };
        let d = fdm_device(&vk, false);
        let range = range(0, 2);
        // SAFETY: create infos live across the calls; the submit is waited for before anything
        // it uses is destroyed.
        unsafe {
            let image = d
                .create_image(&fdm_image_info(), None)
                .expect("density image");
            let memory = bound_memory(&d, image);
            let pool = d
                .create_command_pool(&vk::CommandPoolCreateInfo::default(), None)
                .expect("pool");
            let cb = d
                .allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default()
                        .command_pool(pool)
                        .command_buffer_count(1),
                )
                .expect("command buffer")[0];
            let event = d
                .create_event(&vk::EventCreateInfo::default(), None)
                .expect("event");
            d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
                .expect("begin");
            let to_transfer = vk::ImageMemoryBarrier::default()
                .dst_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .old_layout(vk::ImageLayout::UNDEFINED)
                .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .image(image)
                .subresource_range(range);
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TOP_OF_PIPE,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[to_transfer],
            );
            d.cmd_clear_color_image(
                cb,
                image,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &vk::ClearColorValue::default(),
                &[range],
            );
            let to_density = to_transfer
                .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .dst_access_mask(vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT)
                .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .new_layout(vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT);
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[to_density],
            );
            let back = [vk::ImageMemoryBarrier2::default()
                .src_stage_mask(vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT)
                .src_access_mask(vk::AccessFlags2::FRAGMENT_DENSITY_MAP_READ_EXT)
                .dst_stage_mask(vk::PipelineStageFlags2::COPY)
                .dst_access_mask(vk::AccessFlags2::TRANSFER_WRITE)
                .old_layout(vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT)
                .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .image(image)
                .subresource_range(range)];
            d.cmd_pipeline_barrier2(
                cb,
                &vk::DependencyInfo::default().image_memory_barriers(&back),
            );
            d.cmd_set_event(cb, event, vk::PipelineStageFlags::TRANSFER);
            let memory_barrier = [vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .dst_access_mask(vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT)];
            d.cmd_wait_events(
                cb,
                &[event],
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
                &memory_barrier,
                &[],
                &[],
            );
            d.end_command_buffer(cb).expect("end");
            let queue = d.get_device_queue(0, 0);
            let cbs = [cb];
            d.queue_submit(
                queue,
                &[vk::SubmitInfo::default().command_buffers(&cbs)],
                vk::Fence::null(),
            )
            .expect("submit");
            d.queue_wait_idle(queue).expect("wait");

            // The app's own command buffer: the layer's one-time shadow clear records barriers too.
            let barriers: Vec<_> = env
                .double
                .events("barrier")
                .into_iter()
                .filter(|e| e["command_buffer"] == json!(cb.as_raw()))
                .collect();
            let general = vk::ImageLayout::GENERAL.as_raw();
            let fsr_stage = vk::PipelineStageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR.as_raw();
            let fsr_read = vk::AccessFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR.as_raw();
            assert_eq!(barriers.len(), 3, "{barriers:?}");
            assert_eq!(
                barriers[1]["stages"],
                json!([vk::PipelineStageFlags::TRANSFER.as_raw(), fsr_stage])
            );
            // The app's image stays GENERAL; a second barrier orders its shading-rate shadow, which
            // stays in the shading-rate layout on both sides.
            let read_after_write = json!([vk::AccessFlags::TRANSFER_WRITE.as_raw(), fsr_read]);
            assert_eq!(
                barriers[1]["access"],
                json!([read_after_write.clone(), read_after_write])
            );
            assert_eq!(
                barriers[1]["images"][0],
                json!({"image": image.as_raw(), "layouts": [vk::ImageLayout::TRANSFER_DST_OPTIMAL.as_raw(), general]})
            );
            let fsr_layout = vk::ImageLayout::FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR.as_raw();
            assert_ne!(barriers[1]["images"][1]["image"], json!(image.as_raw()));
            assert_eq!(
                barriers[1]["images"][1]["layouts"],
                json!([fsr_layout, fsr_layout])
            );
            let fsr_stage2 = vk::PipelineStageFlags2::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR.as_raw();
            assert_eq!(barriers[2]["stages"][0][0], fsr_stage2);
            assert_eq!(barriers[2]["images"][0]["layouts"][0], general);

            d.destroy_event(event, None);
            d.destroy_command_pool(pool, None);
            d.destroy_image(image, None);
            d.free_memory(memory, None);
            d.destroy_device(None);
        }
        assert_eq!(env.double.errors(), Vec::<String>::new());
        drop(vk);
        assert_only_stage_false_positives();
    }
}
