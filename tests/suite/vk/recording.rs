//! Recording through fovea's Vulkan layer for a long time, and the commands whose density-map bits
//! the layer translates besides barriers: the same stack as [`crate::support::device`] (this test →
//! fovea → validation → the shading-rate double → lavapipe), on the `nvidia` profile.

use ash::vk;
use fovea_vkdouble::Profile;

use crate::support::device::{
    allocate, assert_only_stage_false_positives, resettable_pool, take_messages, with_fovea,
};

const FDM_STAGE: vk::PipelineStageFlags = vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT;
const FSR_STAGE: vk::PipelineStageFlags =
    vk::PipelineStageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR;

/// A resettable pool on queue family 0 and one primary command buffer from it.
fn pool_and_buffer(d: &ash::Device) -> (vk::CommandPool, vk::CommandBuffer) {
    let pool = resettable_pool(d, 0);
    (pool, allocate(d, pool))
}

/// An application that records for hours, resetting its command buffer between frames, runs in
/// bounded memory through the layer and the double: after more barriers than the double keeps
/// (each becomes one of its `barrier` records), the records stay under their bound, say how many
/// were left out, and the newest are there, with the density-map stage translated.
#[test]
fn recording_for_long_keeps_the_records_bounded() {
    let Some((_serial, env, vk)) = with_fovea(Profile::Nvidia) else {
        return;
    };
    let d = vk.fdm_device(&[], None);
    let (pool, cb) = pool_and_buffer(&d);
    let kept = fovea_vkdouble::KEPT_EVENTS;
    let frames = 5;
    let per_frame = kept / 2 + 1;
    let plain = [vk::MemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::SHADER_WRITE)
        .dst_access_mask(vk::AccessFlags::SHADER_READ)];
    let density = [vk::MemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::SHADER_WRITE)
        .dst_access_mask(vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT)];
    // SAFETY: the test's own command buffer; arrays live across the calls.
    unsafe {
        for frame in 0..frames {
            d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
                .expect("vkBeginCommandBuffer");
            for i in 0..per_frame {
                // The last frame's last barrier waits on the density-map stage.
                let (dst, memory) = if frame == frames - 1 && i == per_frame - 1 {
                    (FDM_STAGE, &density)
                } else {
                    (vk::PipelineStageFlags::FRAGMENT_SHADER, &plain)
                };
                d.cmd_pipeline_barrier(
                    cb,
                    vk::PipelineStageFlags::COMPUTE_SHADER,
                    dst,
                    vk::DependencyFlags::empty(),
                    memory,
                    &[],
                    &[],
                );
            }
            d.end_command_buffer(cb).expect("vkEndCommandBuffer");
            d.reset_command_buffer(cb, vk::CommandBufferResetFlags::RELEASE_RESOURCES)
                .expect("vkResetCommandBuffer");
        }
    }
    let records = env.double.records();
    let events = records["events"].as_array().expect("events");
    let barriers: Vec<_> = events.iter().filter(|e| e["kind"] == "barrier").collect();
    let recorded = frames * per_frame;
    assert!(recorded > 2 * kept, "the test records past the bound");
    assert!(
        events.len() < 2 * kept,
        "{} records after {recorded} barriers: they grow with what is recorded",
        events.len()
    );
    assert_eq!(
        records["dropped"].as_u64(),
        Some((recorded - barriers.len()) as u64),
        "every barrier is either kept or counted as left out"
    );
    assert!(barriers.len() >= kept, "the newest {kept} are kept");
    assert!(
        events.iter().any(|e| e["kind"] == "device"),
        "the device's record is kept"
    );
    let last = barriers.last().expect("a barrier");
    assert_eq!(last["command_buffer"], ash::vk::Handle::as_raw(cb));
    assert_eq!(
        last["stages"][1].as_u64(),
        Some(u64::from(FSR_STAGE.as_raw())),
        "the newest barrier reached the driver, translated"
    );
    assert!(env.double.errors().is_empty(), "{:?}", env.double.errors());
    // SAFETY: nothing is pending on the device.
    unsafe {
        d.destroy_command_pool(pool, None);
        d.destroy_device(None);
    }
    assert_only_stage_false_positives();
}

/// Event sets and resets and timestamp writes name pipeline stages too: the density-map stage is
/// invalid on the driver's device, which never has the density-map feature (VUID-vkCmdSetEvent-
/// stageMask-04095 and the like, <https://registry.khronos.org/vulkan/specs/latest/man/html/vkCmdSetEvent.html>),
/// so it reaches the driver as the shading-rate attachment stage. Validation, which sees the
/// driver's device, reports any density-map stage that gets through.
#[test]
fn event_and_timestamp_stages_are_translated() {
    let Some((_serial, _env, vk)) = with_fovea(Profile::Nvidia) else {
        return;
    };
    let d = vk.fdm_device(&[], None);
    let (pool, cb) = pool_and_buffer(&d);
    let stage2 = vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT;
    // SAFETY: the test's own objects; create infos live across the calls.
    unsafe {
        let event = d
            .create_event(&vk::EventCreateInfo::default(), None)
            .expect("vkCreateEvent");
        let queries = d
            .create_query_pool(
                &vk::QueryPoolCreateInfo::default()
                    .query_type(vk::QueryType::TIMESTAMP)
                    .query_count(2),
                None,
            )
            .expect("vkCreateQueryPool");
        d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
            .expect("vkBeginCommandBuffer");
        d.cmd_reset_query_pool(cb, queries, 0, 2);
        d.cmd_set_event(cb, event, FDM_STAGE | vk::PipelineStageFlags::TRANSFER);
        // A reset right after a set races with it without an execution barrier between
        // (synchronization validation reports it).
        d.cmd_pipeline_barrier(
            cb,
            vk::PipelineStageFlags::ALL_COMMANDS,
            vk::PipelineStageFlags::ALL_COMMANDS,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[],
        );
        d.cmd_reset_event(cb, event, FDM_STAGE);
        d.cmd_reset_event2(cb, event, stage2);
        d.cmd_write_timestamp(cb, FDM_STAGE, queries, 0);
        d.cmd_write_timestamp2(cb, stage2, queries, 1);
        d.end_command_buffer(cb).expect("vkEndCommandBuffer");
        let messages = crate::support::device::take_real_messages();
        assert!(
            messages.is_empty(),
            "the density-map stage reached the driver: {messages:#?}"
        );
        d.destroy_query_pool(queries, None);
        d.destroy_event(event, None);
        d.destroy_command_pool(pool, None);
        d.destroy_device(None);
    }
    assert_only_stage_false_positives();
}

/// A `vkCreateGraphicsPipelines` batch in which one create info has a chain the layer cannot copy
/// (a struct of a size it does not know before the `VkPipelineCreateFlags2CreateInfoKHR` it would
/// rewrite): that pipeline alone falls back, and still gets the shading-rate state in front of its
/// chain; the other pipeline of the batch is rewritten in full. Before, the whole batch went down
/// untouched and every pipeline in it ignored the shading-rate attachment.
#[test]
fn an_uncopyable_chain_falls_back_for_its_pipeline_only() {
    use crate::support::vulkan::{spv, stages, Fixed, COLOR};
    use ash::vk::Handle as _;
    let Some((_serial, env, vk)) = with_fovea(Profile::Nvidia) else {
        return;
    };
    let d = vk.fdm_device(&[], None);
    let vert = spv(include_bytes!("../shaders/triangle.vert.spv"));
    let frag = spv(include_bytes!("../shaders/white.frag.spv"));
    // SAFETY: create infos live across the calls; the objects are destroyed at the end.
    unsafe {
        let modules = [
            d.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&vert), None)
                .expect("vertex shader"),
            d.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&frag), None)
                .expect("fragment shader"),
        ];
        let layout = d
            .create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default(), None)
            .expect("layout");
        let fixed = Fixed::new();
        let stages = stages(modules);
        let formats = [COLOR];
        let mut rendering0 =
            vk::PipelineRenderingCreateInfo::default().color_attachment_formats(&formats);
        let mut rendering1 =
            vk::PipelineRenderingCreateInfo::default().color_attachment_formats(&formats);
        // A struct whose size the layer's chain copier does not know, in front of the 64-bit
        // flags it would have to rewrite.
        let mut flags2 = vk::PipelineCreateFlags2CreateInfoKHR::default()
            .flags(vk::PipelineCreateFlags2KHR::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_EXT);
        let mut unknown = vk::PipelineRepresentativeFragmentTestStateCreateInfoNV::default();
        let uncopyable = fixed
            .info(&stages, layout)
            .push_next(&mut rendering0)
            .push_next(&mut flags2)
            .push_next(&mut unknown);
        let plain = fixed
            .info(&stages, layout)
            .flags(vk::PipelineCreateFlags::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_EXT)
            .push_next(&mut rendering1);
        let pipelines = d
            .create_graphics_pipelines(vk::PipelineCache::null(), &[uncopyable, plain], None)
            .unwrap_or_else(|(_, e)| panic!("vkCreateGraphicsPipelines: {e}"));
        // Validation reports the deliberately odd chain of the first create info; nothing else.
        let others: Vec<String> = crate::support::device::take_real_messages()
            .into_iter()
            .filter(|m| !m.contains("pCreateInfos[0]"))
            .collect();
        assert!(others.is_empty(), "{others:#?}");
        let state = serde_json::json!({"fragment_size": [1, 1], "combiner_ops": [0, 1]});
        let record = |p: vk::Pipeline| {
            env.double
                .events("pipeline")
                .into_iter()
                .find(|e| e["pipeline"] == p.as_raw())
                .unwrap_or_else(|| panic!("no record of {p:?}"))
        };
        let r = record(pipelines[1]);
        assert_eq!(
            r["shading_rate_state"], state,
            "the pipeline beside the uncopyable one lets the attachment decide: {r}"
        );
        assert_eq!(r["rendering_attachment_flag"], true, "{r}");
        let r = record(pipelines[0]);
        assert_eq!(
            r["shading_rate_state"], state,
            "the uncopyable one gets the state in front of its chain: {r}"
        );
        for p in pipelines {
            d.destroy_pipeline(p, None);
        }
        d.destroy_pipeline_layout(layout, None);
        for m in modules {
            d.destroy_shader_module(m, None);
        }
        d.destroy_device(None);
    }
    let _ = take_messages();
}

/// A render pass 2 dependency may chain a `VkMemoryBarrier2`, whose masks then replace the
/// dependency's own (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkSubpassDependency2.html>):
/// its density-map stage and access reach the driver as the shading-rate attachment's, on a
/// copy, and the application's struct is not written.
#[test]
fn a_dependencys_chained_memory_barrier_is_translated() {
    use crate::support::vulkan::attachments2;
    let Some((_serial, _env, vk)) = with_fovea(Profile::Nvidia) else {
        return;
    };
    let d = vk.fdm_device(&[], None);
    let atts = attachments2(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL);
    let color = [vk::AttachmentReference2::default()
        .attachment(0)
        .layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)];
    let subpass = [vk::SubpassDescription2::default()
        .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
        .color_attachments(&color)];
    let mut barrier = vk::MemoryBarrier2::default()
        .src_stage_mask(vk::PipelineStageFlags2::COMPUTE_SHADER)
        .src_access_mask(vk::AccessFlags2::SHADER_WRITE)
        .dst_stage_mask(vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT)
        .dst_access_mask(vk::AccessFlags2::FRAGMENT_DENSITY_MAP_READ_EXT);
    let deps = [vk::SubpassDependency2::default()
        .src_subpass(vk::SUBPASS_EXTERNAL)
        .dst_subpass(0)
        .push_next(&mut barrier)];
    let mut fdm_info = vk::RenderPassFragmentDensityMapCreateInfoEXT::default()
        .fragment_density_map_attachment(
            vk::AttachmentReference::default()
                .attachment(1)
                .layout(vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT),
        );
    let info = vk::RenderPassCreateInfo2::default()
        .attachments(&atts)
        .subpasses(&subpass)
        .dependencies(&deps)
        .push_next(&mut fdm_info);
    // SAFETY: the create info lives across the call.
    let pass = unsafe { d.create_render_pass2(&info, None) }
        .unwrap_or_else(|e| panic!("vkCreateRenderPass2: {e}; {:?}", take_messages()));
    let messages = crate::support::device::take_real_messages();
    assert!(
        messages.is_empty(),
        "the density-map stage or access reached the driver: {messages:#?}"
    );
    assert_eq!(
        barrier.dst_stage_mask,
        vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT,
        "the application's barrier is not written"
    );
    // SAFETY: nothing uses it.
    unsafe {
        d.destroy_render_pass(pass, None);
        d.destroy_device(None);
    }
    assert_only_stage_false_positives();
}

/// A queue family ownership transfer of a density image into the density-map layout: the release
/// half (recorded on the source family's queue, its destination masks ignored by the
/// specification) reaches the driver as the application wrote it, translated, with no barrier of
/// the layer's added; the acquire half still orders the image's shading-rate shadow. Checked
/// between the device's family and `VK_QUEUE_FAMILY_EXTERNAL` (lavapipe has one family), for
/// both barrier commands, on the double's `barrier` records.
#[test]
fn queue_family_release_halves_are_left_alone() {
    use ash::vk::Handle as _;
    let Some((_serial, env, vk)) = with_fovea(Profile::Nvidia) else {
        return;
    };
    let d = vk.fdm_device(&[], None);
    let (pool, cb) = pool_and_buffer(&d);
    let range = crate::support::vulkan::range(0, 2);
    // SAFETY: the test's own objects; structs live across the calls.
    unsafe {
        let image = d
            .create_image(&crate::support::device::fdm_image_info(), None)
            .expect("vkCreateImage");
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
        let fdm = vk::ImageLayout::FRAGMENT_DENSITY_MAP_OPTIMAL_EXT;
        let transfer = |src: u32, dst: u32| {
            vk::ImageMemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .dst_access_mask(vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT)
                .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .new_layout(fdm)
                .src_queue_family_index(src)
                .dst_queue_family_index(dst)
                .image(image)
                .subresource_range(range)
        };
        let transfer2 = |src: u32, dst: u32| {
            vk::ImageMemoryBarrier2::default()
                .src_stage_mask(vk::PipelineStageFlags2::COPY)
                .src_access_mask(vk::AccessFlags2::TRANSFER_WRITE)
                .dst_stage_mask(vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT)
                .dst_access_mask(vk::AccessFlags2::FRAGMENT_DENSITY_MAP_READ_EXT)
                // Where the first pair left it.
                .old_layout(fdm)
                .new_layout(fdm)
                .src_queue_family_index(src)
                .dst_queue_family_index(dst)
                .image(image)
                .subresource_range(range)
        };
        let external = vk::QUEUE_FAMILY_EXTERNAL;
        env.double.clear();
        d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
            .expect("vkBeginCommandBuffer");
        for (src, dst) in [(0, external), (external, 0)] {
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TRANSFER,
                FDM_STAGE,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[transfer(src, dst)],
            );
        }
        for (src, dst) in [(0, external), (external, 0)] {
            d.cmd_pipeline_barrier2(
                cb,
                &vk::DependencyInfo::default().image_memory_barriers(&[transfer2(src, dst)]),
            );
        }
        d.end_command_buffer(cb).expect("vkEndCommandBuffer");
        let images = |e: &serde_json::Value| -> Vec<u64> {
            e["images"]
                .as_array()
                .expect("images")
                .iter()
                .map(|i| i["image"].as_u64().expect("handle"))
                .collect()
        };
        let barriers: Vec<Vec<u64>> = env
            .double
            .events("barrier")
            .iter()
            .filter(|e| e["command_buffer"] == cb.as_raw())
            .map(images)
            .collect();
        assert_eq!(barriers.len(), 4, "{barriers:?}");
        for (n, b) in barriers.iter().enumerate() {
            let release = n % 2 == 0;
            assert_eq!(b[0], image.as_raw(), "the application's barrier first");
            assert_eq!(
                b.len(),
                if release { 1 } else { 2 },
                "barrier {n} ({}): {b:?}",
                if release { "release" } else { "acquire" }
            );
        }
        assert_eq!(env.double.errors(), Vec::<String>::new());
        d.destroy_command_pool(pool, None);
        d.destroy_image(image, None);
        d.free_memory(memory, None);
        d.destroy_device(None);
    }
    assert_only_stage_false_positives();
}
