//! Fuzzed calls through fovea's Vulkan layer: structs it does not know in every chain it edits,
//! null handles where the specification allows them, and handles of a device it never saw.
//!
//! Stack as in `vk::layer`. Each case attaches a random chain of structs with sTypes no extension
//! has yet (a valid `VkBaseInStructure` header and a zeroed body) to one struct fovea rewrites:
//! device, image and image-view create infos, render pass v1 and v2 create infos, framebuffer
//! create info, render-pass begin info, rendering info, pipeline create info, image barriers and
//! dependency infos. Chains run up to past the layer's longest walk. The call must not crash,
//! must succeed as it does without the chain, and where the double records it, reach the driver
//! translated as without the chain. Validation's only complaints may be about those sTypes
//! (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#fundamentals-validusage-pNext>).
//!
//! A second test hands the intercepted commands null handles and handles fovea never saw (made on
//! another device), and unknown structs on the chains of the submit and event-set commands: fovea
//! must not crash and must pass the call down for validation to judge (it reports the bad handle,
//! or nothing where a null handle is allowed).
//!
//! `FOVEA_FUZZ_CASES=N` runs N cases instead of 64.

use std::ffi::c_void;

use ash::vk;
use fovea_vkdouble::Profile;
use proptest::prelude::*;

use crate::support::device::{env, fdm_features, take_real_messages, Vk, FDM};
use crate::support::vulkan::{
    allocate_info, attachments, attachments2, image_info, range, spv, stages, Fixed, COLOR,
    DENSITY, FDM_LAYOUT, FRAGMENT, SIZE, VERTEX,
};

/// What validation must say of a call with a bad handle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Expect {
    /// fovea passed the call down: validation reported the handle, or the call reached the double
    /// below it (validation does not tell every other device's handle from this device's).
    Down,
    /// A null handle the specification allows there: nothing to report.
    Silent,
    /// A null dispatchable handle: there is no next layer to pass it to; fovea must only not
    /// crash.
    Dropped,
}

/// A struct fovea cannot know: a header and a body nobody reads.
#[repr(C)]
struct Unknown {
    s_type: vk::StructureType,
    p_next: *const c_void,
    body: [u64; 8],
}

/// A chain of unknown structs, linked in order, `tail` at its end (the vector is never grown
/// after linking, so the links stay valid while it lives).
fn chain(types: &[i32], tail: *const c_void) -> Vec<Unknown> {
    let mut v: Vec<Unknown> = types
        .iter()
        .map(|&t| Unknown {
            s_type: vk::StructureType::from_raw(t),
            p_next: std::ptr::null(),
            body: [0; 8],
        })
        .collect();
    let mut next = tail;
    for s in v.iter_mut().rev() {
        s.p_next = next;
        next = s as *const Unknown as *const c_void;
    }
    v
}

fn chain_length(mut p: *const c_void) -> usize {
    let mut n = 0;
    while !p.is_null() {
        n += 1;
        // SAFETY: a chain made by [`chain`].
        p = unsafe { (*(p as *const Unknown)).p_next };
    }
    n
}

fn head(c: &[Unknown], tail: *const c_void) -> *const c_void {
    c.first()
        .map_or(tail, |s| s as *const Unknown as *const c_void)
}

/// Which struct the chain goes on.
#[derive(Clone, Copy, Debug)]
enum Target {
    Device,
    Image,
    ImageView,
    RenderPass1,
    RenderPass2,
    Framebuffer,
    BeginRenderPass,
    Rendering,
    Pipeline,
    Barrier1,
    Barrier2,
}

const TARGETS: [Target; 11] = [
    Target::Device,
    Target::Image,
    Target::ImageView,
    Target::RenderPass1,
    Target::RenderPass2,
    Target::Framebuffer,
    Target::BeginRenderPass,
    Target::Rendering,
    Target::Pipeline,
    Target::Barrier1,
    Target::Barrier2,
];

fn cases() -> u32 {
    std::env::var("FOVEA_FUZZ_CASES")
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(64)
}

/// sTypes of extension numbers 801–1000, which no extension has yet: never a struct fovea, the
/// validation layer or the driver reads.
fn unknown_stype() -> impl Strategy<Value = i32> {
    1_000_800_000i32..1_001_000_000
}

fn device(vk: &Vk, extra: *const c_void) -> Result<ash::Device, vk::Result> {
    let prio = [1.0];
    let queues = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(0)
        .queue_priorities(&prio)];
    let names = [FDM.as_ptr()];
    let mut v13 = vk::PhysicalDeviceVulkan13Features::default()
        .dynamic_rendering(true)
        .synchronization2(true);
    v13.p_next = extra as *mut c_void;
    let mut density = fdm_features();
    density.p_next = &mut v13 as *mut _ as *mut c_void;
    let mut info = vk::DeviceCreateInfo::default()
        .queue_create_infos(&queues)
        .enabled_extension_names(&names);
    info.p_next = &density as *const _ as *const c_void;
    // SAFETY: every struct lives across the call.
    unsafe { vk.instance.create_device(vk.physical, &info, None) }
}

/// The objects every case uses, on one FDM device.
struct Fixture {
    d: ash::Device,
    memory: vk::PhysicalDeviceMemoryProperties,
    images: Vec<(vk::Image, vk::DeviceMemory)>,
    color_view: vk::ImageView,
    density_view: vk::ImageView,
    pass: vk::RenderPass,
    layout: vk::PipelineLayout,
    modules: [vk::ShaderModule; 2],
    pool: vk::CommandPool,
}

impl Fixture {
    /// # Safety
    /// `vk` must outlive the fixture.
    unsafe fn new(vk: &Vk) -> Fixture {
        let d = device(vk, std::ptr::null()).expect("vkCreateDevice");
        // SAFETY: plain creations on the live device.
        unsafe {
            let memory = vk
                .instance
                .get_physical_device_memory_properties(vk.physical);
            let mut f = Fixture {
                d,
                memory,
                images: Vec::new(),
                color_view: vk::ImageView::null(),
                density_view: vk::ImageView::null(),
                pass: vk::RenderPass::null(),
                layout: vk::PipelineLayout::null(),
                modules: [vk::ShaderModule::null(); 2],
                pool: vk::CommandPool::null(),
            };
            let color = f
                .image(
                    COLOR,
                    SIZE,
                    vk::ImageUsageFlags::COLOR_ATTACHMENT,
                    std::ptr::null(),
                )
                .unwrap();
            let density = f
                .image(
                    DENSITY,
                    SIZE / 16,
                    vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT,
                    std::ptr::null(),
                )
                .unwrap();
            f.color_view = f.view(color, COLOR, std::ptr::null()).unwrap();
            f.density_view = f.view(density, DENSITY, std::ptr::null()).unwrap();
            f.pass = f.render_pass2(std::ptr::null()).unwrap();
            f.layout =
                f.d.create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default(), None)
                    .unwrap();
            for (i, bytes) in [VERTEX, FRAGMENT].into_iter().enumerate() {
                let words = spv(bytes);
                f.modules[i] = f
                    .d
                    .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
                    .unwrap();
            }
            f.pool =
                f.d.create_command_pool(
                    &vk::CommandPoolCreateInfo::default().queue_family_index(0),
                    None,
                )
                .unwrap();
            f
        }
    }

    /// # Safety
    /// `next` must be a valid chain.
    unsafe fn image(
        &mut self,
        format: vk::Format,
        size: u32,
        usage: vk::ImageUsageFlags,
        next: *const c_void,
    ) -> Result<vk::Image, vk::Result> {
        let mut info = image_info(format, size, 1, usage);
        info.p_next = next;
        // SAFETY: as the caller promised; the image gets memory before any use.
        unsafe {
            let image = self.d.create_image(&info, None)?;
            let req = self.d.get_image_memory_requirements(image);
            let any = vk::MemoryPropertyFlags::empty();
            let mem = self
                .d
                .allocate_memory(&allocate_info(&self.memory, req, any), None)
                .unwrap();
            self.d.bind_image_memory(image, mem, 0).unwrap();
            self.images.push((image, mem));
            Ok(image)
        }
    }

    /// # Safety
    /// `next` must be a valid chain.
    unsafe fn view(
        &self,
        image: vk::Image,
        format: vk::Format,
        next: *const c_void,
    ) -> Result<vk::ImageView, vk::Result> {
        let mut info = vk::ImageViewCreateInfo::default()
            .image(image)
            .view_type(vk::ImageViewType::TYPE_2D)
            .format(format)
            .subresource_range(range(0, 1));
        info.p_next = next;
        // SAFETY: as the caller promised.
        unsafe { self.d.create_image_view(&info, None) }
    }

    /// A colour + density pass, v2; `next` on the create info, after the density-map info.
    ///
    /// # Safety
    /// `next` must be a valid chain.
    unsafe fn render_pass2(&self, next: *const c_void) -> Result<vk::RenderPass, vk::Result> {
        let atts = attachments2(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL);
        let color = [vk::AttachmentReference2::default()
            .attachment(0)
            .layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)];
        let subpass = [vk::SubpassDescription2::default()
            .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
            .color_attachments(&color)];
        let mut fdm = vk::RenderPassFragmentDensityMapCreateInfoEXT::default()
            .fragment_density_map_attachment(vk::AttachmentReference {
                attachment: 1,
                layout: FDM_LAYOUT,
            });
        fdm.p_next = next;
        let mut info = vk::RenderPassCreateInfo2::default()
            .attachments(&atts)
            .subpasses(&subpass);
        info.p_next = &fdm as *const _ as *const c_void;
        // SAFETY: as the caller promised; the structs live across the call.
        unsafe { self.d.create_render_pass2(&info, None) }
    }

    /// # Safety
    /// `next` must be a valid chain.
    unsafe fn render_pass1(&self, next: *const c_void) -> Result<vk::RenderPass, vk::Result> {
        let atts = attachments(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL);
        let color = [vk::AttachmentReference {
            attachment: 0,
            layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
        }];
        let subpass = [vk::SubpassDescription::default()
            .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
            .color_attachments(&color)];
        let mut fdm = vk::RenderPassFragmentDensityMapCreateInfoEXT::default()
            .fragment_density_map_attachment(vk::AttachmentReference {
                attachment: 1,
                layout: FDM_LAYOUT,
            });
        // The unknown structs first, the density-map info after them.
        let mut info = vk::RenderPassCreateInfo::default()
            .attachments(&atts)
            .subpasses(&subpass);
        fdm.p_next = std::ptr::null();
        info.p_next = next;
        let tail = &fdm as *const _ as *const c_void;
        let mut last = next as *mut Unknown;
        if last.is_null() {
            info.p_next = tail;
        } else {
            // SAFETY: the chain is made of `Unknown`s (see `chain`).
            unsafe {
                while !(*last).p_next.is_null() {
                    last = (*last).p_next as *mut Unknown;
                }
                (*last).p_next = tail;
            }
        }
        // SAFETY: as the caller promised; the structs live across the call.
        let r = unsafe { self.d.create_render_pass(&info, None) };
        if !last.is_null() {
            // SAFETY: as above; the chain is unlinked from the local struct again.
            unsafe { (*last).p_next = std::ptr::null() };
        }
        r
    }

    /// One command buffer, `f` recording into it between begin and end; freed afterwards.
    ///
    /// # Safety
    /// What `f` records must be valid.
    unsafe fn record(&self, f: impl FnOnce(vk::CommandBuffer)) {
        // SAFETY: the pool is this fixture's; the buffer is never submitted.
        unsafe {
            let cb = self
                .d
                .allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default()
                        .command_pool(self.pool)
                        .command_buffer_count(1),
                )
                .unwrap()[0];
            self.d
                .begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
                .unwrap();
            f(cb);
            self.d.end_command_buffer(cb).unwrap();
            self.d.free_command_buffers(self.pool, &[cb]);
        }
    }

    /// # Safety
    /// Nothing made from the fixture may be in use.
    unsafe fn destroy(self) {
        // SAFETY: as the caller promised.
        unsafe {
            let d = &self.d;
            d.destroy_command_pool(self.pool, None);
            for m in self.modules {
                d.destroy_shader_module(m, None);
            }
            d.destroy_pipeline_layout(self.layout, None);
            d.destroy_render_pass(self.pass, None);
            d.destroy_image_view(self.color_view, None);
            d.destroy_image_view(self.density_view, None);
            for (i, m) in self.images {
                d.destroy_image(i, None);
                d.free_memory(m, None);
            }
            d.destroy_device(None);
        }
    }
}

/// Runs one case: `target` gets the chain; every object made is destroyed again.
///
/// # Safety
/// `f` and `vk` must be alive.
unsafe fn run(vk: &Vk, f: &mut Fixture, target: Target, next: *const c_void) {
    let d = f.d.clone();
    let area = vk::Rect2D {
        offset: vk::Offset2D { x: 0, y: 0 },
        extent: vk::Extent2D {
            width: SIZE,
            height: SIZE,
        },
    };
    // SAFETY: as the caller promised; every struct lives across its call.
    unsafe {
        match target {
            Target::Device => match device(vk, next) {
                Ok(dev) => dev.destroy_device(None),
                // Past the longest chain fovea walks it passes the create info through as it
                // is, density maps included, and the driver answers that it has none.
                Err(
                    vk::Result::ERROR_FEATURE_NOT_PRESENT | vk::Result::ERROR_EXTENSION_NOT_PRESENT,
                ) if chain_length(next) + 2 > fovea_abi::MAX_CHAIN_LENGTH => {}
                Err(e) => panic!("vkCreateDevice with unknown structs: {e}"),
            },
            Target::Image => {
                let n = f.images.len();
                f.image(
                    DENSITY,
                    4,
                    vk::ImageUsageFlags::FRAGMENT_DENSITY_MAP_EXT,
                    next,
                )
                .expect("vkCreateImage");
                let (i, m) = f.images.remove(n);
                d.destroy_image(i, None);
                d.free_memory(m, None);
            }
            Target::ImageView => {
                let image = f.images[1].0;
                let v = f.view(image, DENSITY, next).expect("vkCreateImageView");
                d.destroy_image_view(v, None);
            }
            Target::RenderPass1 => {
                let p = f.render_pass1(next).expect("vkCreateRenderPass");
                d.destroy_render_pass(p, None);
            }
            Target::RenderPass2 => {
                let p = f.render_pass2(next).expect("vkCreateRenderPass2");
                d.destroy_render_pass(p, None);
            }
            Target::Framebuffer | Target::BeginRenderPass => {
                let list = [f.color_view, f.density_view];
                let mut info = vk::FramebufferCreateInfo::default()
                    .render_pass(f.pass)
                    .attachments(&list)
                    .width(SIZE)
                    .height(SIZE)
                    .layers(1);
                if matches!(target, Target::Framebuffer) {
                    info.p_next = next;
                }
                let fb = d
                    .create_framebuffer(&info, None)
                    .expect("vkCreateFramebuffer");
                if matches!(target, Target::BeginRenderPass) {
                    let clear = [vk::ClearValue::default()];
                    let mut begin = vk::RenderPassBeginInfo::default()
                        .render_pass(f.pass)
                        .framebuffer(fb)
                        .render_area(area)
                        .clear_values(&clear);
                    begin.p_next = next;
                    f.record(|cb| {
                        d.cmd_begin_render_pass2(
                            cb,
                            &begin,
                            &vk::SubpassBeginInfo::default().contents(vk::SubpassContents::INLINE),
                        );
                        d.cmd_end_render_pass2(cb, &vk::SubpassEndInfo::default());
                    });
                }
                d.destroy_framebuffer(fb, None);
            }
            Target::Rendering => {
                let color = [vk::RenderingAttachmentInfo::default()
                    .image_view(f.color_view)
                    .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::STORE)];
                let mut density = vk::RenderingFragmentDensityMapAttachmentInfoEXT::default()
                    .image_view(f.density_view)
                    .image_layout(FDM_LAYOUT);
                density.p_next = next;
                let mut info = vk::RenderingInfo::default()
                    .render_area(area)
                    .layer_count(1)
                    .color_attachments(&color);
                info.p_next = &density as *const _ as *const c_void;
                f.record(|cb| {
                    d.cmd_begin_rendering(cb, &info);
                    d.cmd_end_rendering(cb);
                });
            }
            Target::Pipeline => {
                let stages = stages(f.modules);
                let fixed = Fixed::new();
                let mut info = fixed.info(&stages, f.layout).render_pass(f.pass).subpass(0);
                info.p_next = next;
                let p = d
                    .create_graphics_pipelines(vk::PipelineCache::null(), &[info], None)
                    .map_err(|e| e.1)
                    .expect("vkCreateGraphicsPipelines")[0];
                d.destroy_pipeline(p, None);
            }
            Target::Barrier1 => {
                let mut b = vk::ImageMemoryBarrier::default()
                    .image(f.images[1].0)
                    .subresource_range(range(0, 1))
                    .old_layout(vk::ImageLayout::UNDEFINED)
                    .new_layout(FDM_LAYOUT)
                    .dst_access_mask(vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT);
                b.p_next = next;
                f.record(|cb| {
                    d.cmd_pipeline_barrier(
                        cb,
                        vk::PipelineStageFlags::TOP_OF_PIPE,
                        vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
                        vk::DependencyFlags::empty(),
                        &[],
                        &[],
                        &[b],
                    )
                });
            }
            Target::Barrier2 => {
                let mut b = [vk::ImageMemoryBarrier2::default()
                    .image(f.images[1].0)
                    .subresource_range(range(0, 1))
                    .old_layout(vk::ImageLayout::UNDEFINED)
                    .new_layout(FDM_LAYOUT)
                    .dst_stage_mask(vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT)
                    .dst_access_mask(vk::AccessFlags2::FRAGMENT_DENSITY_MAP_READ_EXT)];
                b[0].p_next = next;
                let mut info = vk::DependencyInfo::default().image_memory_barriers(&b);
                info.p_next = next;
                f.record(|cb| d.cmd_pipeline_barrier2(cb, &info));
            }
        }
    }
}

/// Random chains of unknown structs on every struct fovea edits: no crash, the call succeeds, and
/// validation complains about nothing but the unknown structs.
#[test]
fn unknown_structs_in_every_edited_chain() {
    let Some((_serial, env)) = env() else { return };
    let vk = Vk::new(env, Profile::Nvidia, true).expect("an instance");
    // SAFETY: the instance outlives the fixture.
    let f = std::cell::RefCell::new(unsafe { Fixture::new(&vk) });
    let mut runner = proptest::test_runner::TestRunner::new(ProptestConfig {
        cases: cases(),
        failure_persistence: None,
        ..ProptestConfig::default()
    });
    let strategy = (
        0..TARGETS.len(),
        prop_oneof![
            proptest::collection::vec(unknown_stype(), 0..4),
            proptest::collection::vec(unknown_stype(), 60..70),
        ],
    );
    let n = std::cell::Cell::new(0);
    runner
        .run(&strategy, |(target, types)| {
            let target = TARGETS[target];
            let c = chain(&types, std::ptr::null());
            // SAFETY: the chain lives across the case.
            unsafe { run(&vk, &mut f.borrow_mut(), target, head(&c, std::ptr::null())) };
            let others: Vec<String> = take_real_messages()
                .into_iter()
                .filter(|m| !m.contains("pNext") && !m.contains("sType"))
                .collect();
            prop_assert!(
                others.is_empty(),
                "{target:?} with {} unknown structs: {others:#?}",
                types.len()
            );
            prop_assert!(env.double.errors().is_empty(), "{:?}", env.double.errors());
            n.set(n.get() + 1);
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{e}"));
    // SAFETY: nothing made from the fixture is in use.
    unsafe { f.into_inner().destroy() };
    drop(vk);
    let leaks: Vec<String> = take_real_messages()
        .into_iter()
        .filter(|m| !m.contains("pNext") && !m.contains("sType"))
        .collect();
    assert!(leaks.is_empty(), "at teardown: {leaks:#?}");
    eprintln!("vk_fuzz: {} cases", n.get());
}

/// Null and foreign handles (made on a second device, never seen by fovea's maps) in every kind of
/// command fovea intercepts, and unknown structs on the submit and event-set chains: no crash, and
/// each call reaches validation, which reports the bad handle (or nothing where the specification
/// allows a null handle).
#[test]
fn null_and_foreign_handles_go_down_for_validation_to_judge() {
    let Some((_serial, env)) = env() else { return };
    let vk = Vk::new(env, Profile::Nvidia, true).expect("an instance");
    // SAFETY: the instance outlives the fixture and the other device.
    let f = unsafe { Fixture::new(&vk) };
    let other = vk.device(&[], None).expect("a second device");
    let d = &f.d;
    // SAFETY: objects of the second device, destroyed at the end.
    let (foreign_image, foreign_memory, foreign_view, foreign_event, foreign_cb, other_pool) = unsafe {
        let image = other
            .create_image(
                &image_info(DENSITY, 4, 1, vk::ImageUsageFlags::SAMPLED),
                None,
            )
            .unwrap();
        let req = other.get_image_memory_requirements(image);
        let memory = other
            .allocate_memory(
                &allocate_info(&f.memory, req, vk::MemoryPropertyFlags::DEVICE_LOCAL),
                None,
            )
            .unwrap();
        other.bind_image_memory(image, memory, 0).unwrap();
        let view = other
            .create_image_view(
                &vk::ImageViewCreateInfo::default()
                    .image(image)
                    .view_type(vk::ImageViewType::TYPE_2D)
                    .format(DENSITY)
                    .subresource_range(range(0, 1)),
                None,
            )
            .unwrap();
        let event = other
            .create_event(&vk::EventCreateInfo::default(), None)
            .unwrap();
        let pool = other
            .create_command_pool(
                &vk::CommandPoolCreateInfo::default().queue_family_index(0),
                None,
            )
            .unwrap();
        let cb = other
            .allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool)
                    .command_buffer_count(1),
            )
            .unwrap()[0];
        other
            .begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
            .unwrap();
        (image, memory, view, event, cb, pool)
    };
    // SAFETY: a queue of the fixture's device.
    let queue = unsafe { d.get_device_queue(0, 0) };
    let barrier = |image| {
        vk::ImageMemoryBarrier::default()
            .image(image)
            .subresource_range(range(0, 1))
            .old_layout(vk::ImageLayout::UNDEFINED)
            .new_layout(FDM_LAYOUT)
            .dst_access_mask(vk::AccessFlags::FRAGMENT_DENSITY_MAP_READ_EXT)
    };
    let barrier2 = |image| {
        [vk::ImageMemoryBarrier2::default()
            .image(image)
            .subresource_range(range(0, 1))
            .old_layout(vk::ImageLayout::UNDEFINED)
            .new_layout(FDM_LAYOUT)
            .dst_stage_mask(vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT)
            .dst_access_mask(vk::AccessFlags2::FRAGMENT_DENSITY_MAP_READ_EXT)]
    };
    let unknown = chain(&[1_000_900_001, 1_000_900_002], std::ptr::null());
    let unknown = head(&unknown, std::ptr::null());
    let null_image = vk::Image::null();
    let rendering = |cb, view| {
        let mut density = vk::RenderingFragmentDensityMapAttachmentInfoEXT::default()
            .image_view(view)
            .image_layout(FDM_LAYOUT);
        let info = vk::RenderingInfo::default()
            .render_area(vk::Rect2D {
                offset: vk::Offset2D::default(),
                extent: vk::Extent2D {
                    width: SIZE,
                    height: SIZE,
                },
            })
            .layer_count(1)
            .push_next(&mut density);
        // SAFETY: `cb` is recording (or null / foreign, on purpose).
        unsafe {
            d.cmd_begin_rendering(cb, &info);
            // Not intercepted: it would go straight to validation, which takes NULL badly.
            if cb != vk::CommandBuffer::null() {
                d.cmd_end_rendering(cb);
            }
        }
    };
    type Case<'a> = (&'static str, Expect, Box<dyn Fn(vk::CommandBuffer) + 'a>);
    // SAFETY (every case): the calls are invalid on purpose where they must be; validation, below
    // fovea, reports and stops them before the driver.
    let cases: Vec<Case<'_>> = vec![
        (
            "barrier, null image",
            Expect::Down,
            Box::new(|cb| unsafe {
                d.cmd_pipeline_barrier(
                    cb,
                    vk::PipelineStageFlags::TOP_OF_PIPE,
                    vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[barrier(null_image)],
                );
            }),
        ),
        (
            "barrier, foreign image",
            Expect::Down,
            Box::new(|cb| unsafe {
                d.cmd_pipeline_barrier(
                    cb,
                    vk::PipelineStageFlags::TOP_OF_PIPE,
                    vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[barrier(foreign_image)],
                );
            }),
        ),
        (
            "barrier2, foreign image",
            Expect::Down,
            Box::new(|cb| unsafe {
                let b = barrier2(foreign_image);
                d.cmd_pipeline_barrier2(
                    cb,
                    &vk::DependencyInfo::default().image_memory_barriers(&b),
                );
            }),
        ),
        (
            "set event2, null event",
            Expect::Down,
            Box::new(|cb| unsafe {
                let b = barrier2(f.images[1].0);
                d.cmd_set_event2(
                    cb,
                    vk::Event::null(),
                    &vk::DependencyInfo::default().image_memory_barriers(&b),
                );
            }),
        ),
        (
            "set event2, foreign event, unknown chain",
            Expect::Down,
            Box::new(|cb| unsafe {
                let b = barrier2(f.images[1].0);
                let mut info = vk::DependencyInfo::default().image_memory_barriers(&b);
                info.p_next = unknown;
                d.cmd_set_event2(cb, foreign_event, &info);
            }),
        ),
        (
            "wait events, foreign event",
            Expect::Down,
            Box::new(|cb| unsafe {
                d.cmd_wait_events(
                    cb,
                    &[foreign_event],
                    vk::PipelineStageFlags::TOP_OF_PIPE,
                    vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
                    &[],
                    &[],
                    &[barrier(f.images[1].0)],
                );
            }),
        ),
        (
            "rendering, null density view",
            Expect::Silent,
            Box::new(|cb| rendering(cb, vk::ImageView::null())),
        ),
        (
            "rendering, foreign density view",
            Expect::Silent,
            Box::new(|cb| rendering(cb, foreign_view)),
        ),
        (
            "barrier, null command buffer",
            Expect::Dropped,
            Box::new(|_| unsafe {
                d.cmd_pipeline_barrier(
                    vk::CommandBuffer::null(),
                    vk::PipelineStageFlags::TOP_OF_PIPE,
                    vk::PipelineStageFlags::FRAGMENT_DENSITY_PROCESS_EXT,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[barrier(f.images[1].0)],
                );
            }),
        ),
        (
            "rendering, null command buffer",
            Expect::Dropped,
            Box::new(|_| rendering(vk::CommandBuffer::null(), f.density_view)),
        ),
        // A command buffer of the other device through this device's pointer: fovea finds the
        // device by the handle, and the other device's next layer gets it.
        (
            "barrier2, the other device's command buffer",
            Expect::Silent,
            Box::new(|_| unsafe {
                d.cmd_pipeline_barrier2(foreign_cb, &vk::DependencyInfo::default());
            }),
        ),
    ];
    let events = || {
        env.double.records()["events"]
            .as_array()
            .map_or(0, Vec::len)
    };
    let mut ran = 0;
    for (what, expect, case) in &cases {
        take_real_messages();
        let before = events();
        // SAFETY: see above; the command buffer is the fixture's, recording.
        unsafe { f.record(case) };
        let reached = events() > before;
        let messages: Vec<String> = take_real_messages()
            .into_iter()
            .filter(|m| !m.contains("pNext") && !m.contains("sType"))
            .collect();
        match expect {
            Expect::Down => assert!(
                !messages.is_empty() || reached,
                "{what}: neither validation nor the double saw it"
            ),
            Expect::Silent | Expect::Dropped => {
                assert!(messages.is_empty(), "{what}: {messages:#?}")
            }
        }
        ran += 1;
    }
    // Device-level calls. Only ones the stack below survives: validation 1.3.239 lets some null
    // handles through to lavapipe, which does not survive them (a null image in a view's create
    // info, a null framebuffer at a pass's begin).
    // SAFETY: the semaphore is destroyed at the end, when the queue is idle.
    let semaphore = unsafe { d.create_semaphore(&vk::SemaphoreCreateInfo::default(), None) }
        .expect("vkCreateSemaphore");
    type DeviceCase<'a> = (
        &'static str,
        Expect,
        Box<dyn Fn() -> Option<vk::Result> + 'a>,
    );
    let device_cases: Vec<DeviceCase<'_>> = vec![
        (
            "framebuffer with a foreign density view: the full-rate stand-in",
            Expect::Silent,
            Box::new(|| unsafe {
                let views = [f.color_view, foreign_view];
                let r = d.create_framebuffer(
                    &vk::FramebufferCreateInfo::default()
                        .render_pass(f.pass)
                        .attachments(&views)
                        .width(SIZE)
                        .height(SIZE)
                        .layers(1),
                    None,
                );
                r.map(|fb| d.destroy_framebuffer(fb, None)).err()
            }),
        ),
        (
            "destroy null image, view and pass",
            Expect::Silent,
            Box::new(|| unsafe {
                d.destroy_image(null_image, None);
                d.destroy_image_view(vk::ImageView::null(), None);
                d.destroy_render_pass(vk::RenderPass::null(), None);
                None
            }),
        ),
        (
            "submit nothing, null fence, unknown chain",
            Expect::Silent,
            Box::new(|| unsafe {
                let s = vk::SubmitInfo {
                    p_next: unknown,
                    ..Default::default()
                };
                d.queue_submit(queue, &[s], vk::Fence::null()).err()
            }),
        ),
        (
            "submit2 signalling at the density stage, unknown chains",
            Expect::Silent,
            Box::new(|| unsafe {
                let mut g = vk::SemaphoreSubmitInfo::default()
                    .semaphore(semaphore)
                    .stage_mask(vk::PipelineStageFlags2::FRAGMENT_DENSITY_PROCESS_EXT);
                g.p_next = unknown;
                let signals = [g];
                let mut s = vk::SubmitInfo2::default().signal_semaphore_infos(&signals);
                s.p_next = unknown;
                let r = d.queue_submit2(queue, &[s], vk::Fence::null()).err();
                // Unsignal it again for the next use.
                let waits = [vk::SemaphoreSubmitInfo::default()
                    .semaphore(semaphore)
                    .stage_mask(vk::PipelineStageFlags2::ALL_COMMANDS)];
                d.queue_submit2(
                    queue,
                    &[vk::SubmitInfo2::default().wait_semaphore_infos(&waits)],
                    vk::Fence::null(),
                )
                .expect("wait");
                r
            }),
        ),
        (
            "submit on a null queue",
            Expect::Dropped,
            Box::new(|| unsafe {
                d.queue_submit(vk::Queue::null(), &[], vk::Fence::null())
                    .err()
            }),
        ),
    ];
    for (what, expect, case) in &device_cases {
        take_real_messages();
        let before = events();
        let r = case();
        let reached = events() > before;
        // SAFETY: the queue is idle after it.
        unsafe { d.queue_wait_idle(queue).unwrap() };
        let messages: Vec<String> = take_real_messages()
            .into_iter()
            .filter(|m| !m.contains("pNext") && !m.contains("sType"))
            .collect();
        match expect {
            Expect::Down => assert!(
                !messages.is_empty() || reached,
                "{what}: neither validation nor the double saw it ({r:?})"
            ),
            Expect::Silent => {
                assert!(
                    messages.is_empty() && r.is_none(),
                    "{what}: {r:?} {messages:#?}"
                )
            }
            Expect::Dropped => assert!(r.is_some(), "{what}: no next layer, yet success"),
        }
        ran += 1;
    }
    assert!(env.double.errors().is_empty(), "{:?}", env.double.errors());
    drop(cases);
    drop(device_cases);
    // SAFETY: nothing made from the fixture or the other device is in use.
    unsafe {
        d.destroy_semaphore(semaphore, None);
        other.end_command_buffer(foreign_cb).unwrap();
        other.destroy_command_pool(other_pool, None);
        other.destroy_event(foreign_event, None);
        other.destroy_image_view(foreign_view, None);
        other.destroy_image(foreign_image, None);
        other.free_memory(foreign_memory, None);
        other.destroy_device(None);
        f.destroy();
    }
    drop(vk);
    take_real_messages();
    eprintln!("vk_fuzz: {ran} calls with null or foreign handles");
}
