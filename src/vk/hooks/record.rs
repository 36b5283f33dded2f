//! Command buffers on an emulating device: allocated, begun, freed and their pools destroyed with
//! a record each, and the application's compute bindings and conditional rendering noted, so that
//! a conversion at pass begin ([`crate::vk::convert`]) can give them back and run outside it.

use std::ffi::c_void;

use ash::vk;
use ash::vk::Handle as _;

use crate::vk::base::chain;
use crate::vk::base::ffi::{key, slice, Arr, Call, In};
use crate::vk::convert;
use crate::vk::own::bindings::{Bound, PushRange};
use crate::vk::registry::{
    self, command_pool_destroyed, forget_command_buffers, record_of, remember_command_buffer,
    with_record, CbRecord, Device,
};

hook! {
    /// `vkAllocateCommandBuffers`: each new command buffer gets its record, with its pool, and
    /// its queue family is noted for ownership transfers ([`registry::buffers_allocated`]).
    allocate_command_buffers = "vkAllocateCommandBuffers";
    on device_ref(device), next allocate_command_buffers,
    fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    allocate(
        device: val vk::Device,
        info: in vk::CommandBufferAllocateInfo<'_>,
        out: val *mut vk::CommandBuffer,
    ) -> vk::Result
}

fn allocate(
    c: Call<'_, Device, vk::PFN_vkAllocateCommandBuffers, impl Fn() -> vk::Result>,
    device: vk::Device,
    info: In<'_, vk::CommandBufferAllocateInfo<'_>>,
    out: *mut vk::CommandBuffer,
) -> vk::Result {
    let r = c.as_given();
    // SAFETY: a device the loader dispatched.
    let (Some(k), Some(i)) = (unsafe { key(device) }, info.get()) else {
        return r;
    };
    if r == vk::Result::SUCCESS && !out.is_null() {
        // SAFETY: on success the next layer wrote `commandBufferCount` handles to `out`, valid
        // for that many (the command's valid usage).
        let cbs = unsafe { slice(out, i.command_buffer_count) };
        let secondary = i.level == vk::CommandBufferLevel::SECONDARY;
        for &cb in cbs {
            let pool = i.command_pool.as_raw();
            remember_command_buffer(cb, CbRecord::new(c.dev, k, pool, secondary));
        }
    }
    r
}

hook! {
    /// `vkDestroyCommandPool`: its command buffers are freed with it, and their records go
    /// (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkDestroyCommandPool.html>),
    /// whether or not the layer knows the device.
    destroy_command_pool = "vkDestroyCommandPool"; raw, fails(());
    destroy_pool(
        device: val vk::Device,
        pool: val vk::CommandPool,
        alloc: val *const vk::AllocationCallbacks<'_>,
    ) -> ()
}

fn destroy_pool(
    device: vk::Device,
    pool: vk::CommandPool,
    alloc: *const vk::AllocationCallbacks<'_>,
) {
    // SAFETY: a device the loader dispatched (or NULL): its first word is its dispatch key; the
    // borrow ends with this call.
    let (dev, key) = unsafe { (registry::device_ref(device), key(device)) };
    if let (Some(d), Some(k), false) = (&dev, key, pool == vk::CommandPool::null()) {
        command_pool_destroyed(d, k, pool.as_raw());
    }
    if let Some(next) = dev.and_then(|d| d.next.destroy_command_pool) {
        // SAFETY: the next layer's function, with the application's arguments.
        unsafe { next(device, pool, alloc) };
    }
}

hook! {
    /// `vkBeginCommandBuffer`: the command buffer's bindings start empty
    /// (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkBeginCommandBuffer.html>);
    /// its record is made (once per command buffer) or cleared, and its conversion slots of
    /// destroyed maps go ([`convert::begun`]).
    begin_command_buffer = "vkBeginCommandBuffer";
    on device_ref(cb), next begin_command_buffer, fails(vk::Result::ERROR_INITIALIZATION_FAILED);
    begin(cb: val vk::CommandBuffer, info: in vk::CommandBufferBeginInfo<'_>) -> vk::Result
}

fn begin(
    c: Call<'_, Device, vk::PFN_vkBeginCommandBuffer, impl Fn() -> vk::Result>,
    cb: vk::CommandBuffer,
    info: In<'_, vk::CommandBufferBeginInfo<'_>>,
) -> vk::Result {
    let found = record_of(cb, |r| {
        // Its inheritance info is read for secondary command buffers only, as the
        // specification says.
        let inherits = r.secondary && inherits_conditional_rendering(info);
        {
            let mut b = r.bound.lock();
            *b = Bound {
                inherited_conditional: inherits,
                recording: b.recording + 1,
                ..Bound::default()
            };
        }
        convert::begun(r);
        // A pass left open by the previous recording ends nowhere.
        registry::take_plan(r);
    });
    if found.is_none() {
        // Allocated before the layer saw it (not expected on an emulating device): a primary's
        // record without a pool, dropped with the command buffer or its device.
        // SAFETY: a command buffer the loader dispatched: its first word is its dispatch key.
        let device = unsafe { key(cb) }.unwrap_or(0);
        remember_command_buffer(cb, CbRecord::new(c.dev, device, 0, false));
    }
    c.as_given()
}

hook! {
    /// `vkFreeCommandBuffers`: their records go, whether or not the layer knows the device.
    free_command_buffers = "vkFreeCommandBuffers"; raw, fails(());
    free(
        device: val vk::Device,
        pool: val vk::CommandPool,
        count: val u32,
        cbs: (array count) vk::CommandBuffer,
    ) -> ()
}

fn free(device: vk::Device, pool: vk::CommandPool, count: u32, cbs: Arr<'_, vk::CommandBuffer>) {
    forget_command_buffers(cbs.slice());
    // The leaf table, not the registry's ranked map: fovea's own uploads free their command
    // buffers through the layer under their submit lock (`crate::common::lock::Rank`).
    // SAFETY: a device the loader dispatched (or NULL); the borrow ends with this call.
    let dev = unsafe { registry::device_ref(device) };
    if let Some(next) = dev.and_then(|d| d.next.free_command_buffers) {
        // SAFETY: the next layer's function, with the application's arguments.
        unsafe { next(device, pool, count, cbs.raw()) };
    }
}

/// Whether a secondary command buffer's begin info makes it inherit conditional rendering.
fn inherits_conditional_rendering(info: In<'_, vk::CommandBufferBeginInfo<'_>>) -> bool {
    let Some(begin) = info.get() else {
        return false;
    };
    // SAFETY: the command's valid usage: a secondary's begin info has a valid inheritance info,
    // with a valid chain.
    let Some(inh) = (unsafe { begin.p_inheritance_info.as_ref() }) else {
        return false;
    };
    let ty = vk::StructureType::COMMAND_BUFFER_INHERITANCE_CONDITIONAL_RENDERING_INFO_EXT;
    // SAFETY: as above; found by its sType, read only.
    unsafe {
        chain::find::<vk::CommandBufferInheritanceConditionalRenderingInfoEXT<'_>>(inh.p_next, ty)
            .ok()
            .flatten()
            .is_some_and(|c| (*c).conditional_rendering_enable == vk::TRUE)
    }
}

hook! {
    /// `vkCmdBeginConditionalRenderingEXT`: the condition is noted, so a conversion can suspend
    /// it.
    cmd_begin_conditional_rendering = "vkCmdBeginConditionalRenderingEXT";
    on device_ref(cb), next cmd_begin_conditional_rendering_ext, fails(());
    begin_conditional(
        cb: val vk::CommandBuffer,
        info: in vk::ConditionalRenderingBeginInfoEXT<'_>,
    ) -> ()
}

fn begin_conditional(
    c: Call<'_, Device, vk::PFN_vkCmdBeginConditionalRenderingEXT, impl Fn()>,
    cb: vk::CommandBuffer,
    info: In<'_, vk::ConditionalRenderingBeginInfoEXT<'_>>,
) {
    if let Some(i) = info.get() {
        let condition = (i.buffer, i.offset, i.flags);
        with_record(cb, |b| b.conditional = Some(condition));
    }
    c.as_given()
}

hook! {
    /// `vkCmdEndConditionalRenderingEXT`: the condition is forgotten.
    cmd_end_conditional_rendering = "vkCmdEndConditionalRenderingEXT";
    on device_ref(cb), next cmd_end_conditional_rendering_ext, fails(());
    end_conditional(cb: val vk::CommandBuffer) -> ()
}

fn end_conditional(
    c: Call<'_, Device, vk::PFN_vkCmdEndConditionalRenderingEXT, impl Fn()>,
    cb: vk::CommandBuffer,
) {
    with_record(cb, |b| b.conditional = None);
    c.as_given()
}

hook! {
    /// `vkCmdBindPipeline`: a compute pipeline is noted.
    cmd_bind_pipeline = "vkCmdBindPipeline";
    on device_ref(cb), next cmd_bind_pipeline, fails(());
    bind_pipeline(
        cb: val vk::CommandBuffer,
        point: val vk::PipelineBindPoint,
        pipeline: val vk::Pipeline,
    ) -> ()
}

fn bind_pipeline(
    c: Call<'_, Device, vk::PFN_vkCmdBindPipeline, impl Fn()>,
    cb: vk::CommandBuffer,
    point: vk::PipelineBindPoint,
    pipeline: vk::Pipeline,
) {
    if point == vk::PipelineBindPoint::COMPUTE {
        with_record(cb, |b| b.pipeline = pipeline);
    }
    c.as_given()
}

hook! {
    /// `vkCmdBindDescriptorSets`: compute sets and their dynamic offsets are noted.
    cmd_bind_descriptor_sets = "vkCmdBindDescriptorSets";
    on device_ref(cb), next cmd_bind_descriptor_sets, fails(());
    bind_sets(
        cb: val vk::CommandBuffer,
        point: val vk::PipelineBindPoint,
        layout: val vk::PipelineLayout,
        first: val u32,
        set_count: val u32,
        sets: (array set_count) vk::DescriptorSet,
        dynamic_count: val u32,
        dynamic: (array dynamic_count) u32,
    ) -> ()
}

#[allow(clippy::too_many_arguments)]
fn bind_sets(
    c: Call<'_, Device, vk::PFN_vkCmdBindDescriptorSets, impl Fn()>,
    cb: vk::CommandBuffer,
    point: vk::PipelineBindPoint,
    layout: vk::PipelineLayout,
    first: u32,
    _set_count: u32,
    sets: Arr<'_, vk::DescriptorSet>,
    _dynamic_count: u32,
    dynamic: Arr<'_, u32>,
) {
    if point == vk::PipelineBindPoint::COMPUTE && !sets.raw().is_null() {
        let (s, dy) = (sets.slice(), dynamic.slice());
        with_record(cb, |b| {
            // Which sets take how many dynamic offsets is in their layouts, which the layer does
            // not look into: one set with all of them is exact; several sets with dynamic
            // offsets cannot be split, so the record gives up.
            if dy.is_empty() || s.len() == 1 {
                let n = dy.len() as u32;
                b.bind_sets(layout, first, s, dy, |_| Some(n));
            } else {
                b.lost = true;
            }
        });
    }
    c.as_given()
}

hook! {
    /// `vkCmdPushConstants`: the bytes and the range are noted where the conversion's compute
    /// dispatch would disturb them ([`Bound::push`]).
    cmd_push_constants = "vkCmdPushConstants";
    on device_ref(cb), next cmd_push_constants, fails(());
    push_constants(
        cb: val vk::CommandBuffer,
        layout: val vk::PipelineLayout,
        stages: val vk::ShaderStageFlags,
        offset: val u32,
        size: val u32,
        values: (bytes size) c_void,
    ) -> ()
}

fn push_constants(
    c: Call<'_, Device, vk::PFN_vkCmdPushConstants, impl Fn()>,
    cb: vk::CommandBuffer,
    layout: vk::PipelineLayout,
    stages: vk::ShaderStageFlags,
    offset: u32,
    size: u32,
    values: Arr<'_, u8>,
) {
    if !values.raw().is_null() {
        let range = PushRange {
            layout,
            stages,
            offset,
            size,
            seq: 0,
        };
        with_record(cb, |b| b.push(range, values.slice()));
    }
    c.as_given()
}

hook! {
    /// `vkCmdPushDescriptorSetKHR`: a compute push descriptor cannot be given back (its writes
    /// would have to be copied); the command buffer's maps are not converted from then on.
    cmd_push_descriptor_set_khr = "vkCmdPushDescriptorSetKHR";
    on device_ref(cb), next cmd_push_descriptor_set_khr, fails(());
    push_descriptor_set(
        cb: val vk::CommandBuffer,
        point: val vk::PipelineBindPoint,
        layout: val vk::PipelineLayout,
        set: val u32,
        count: val u32,
        writes: val *const vk::WriteDescriptorSet<'_>,
    ) -> ()
}

fn push_descriptor_set(
    c: Call<'_, Device, vk::PFN_vkCmdPushDescriptorSetKHR, impl Fn()>,
    cb: vk::CommandBuffer,
    point: vk::PipelineBindPoint,
    _layout: vk::PipelineLayout,
    _set: u32,
    _count: u32,
    _writes: *const vk::WriteDescriptorSet<'_>,
) {
    if point == vk::PipelineBindPoint::COMPUTE {
        with_record(cb, |b| b.lost = true);
    }
    c.as_given()
}

hook! {
    /// `vkCmdPushDescriptorSetWithTemplateKHR`: as [`cmd_push_descriptor_set_khr`] (the
    /// template's bind point is not looked up, so any use gives up).
    cmd_push_descriptor_set_with_template_khr = "vkCmdPushDescriptorSetWithTemplateKHR";
    on device_ref(cb), next cmd_push_descriptor_set_with_template_khr, fails(());
    push_with_template(
        cb: val vk::CommandBuffer,
        template: val vk::DescriptorUpdateTemplate,
        layout: val vk::PipelineLayout,
        set: val u32,
        data: val *const c_void,
    ) -> ()
}

fn push_with_template(
    c: Call<'_, Device, vk::PFN_vkCmdPushDescriptorSetWithTemplateKHR, impl Fn()>,
    cb: vk::CommandBuffer,
    _template: vk::DescriptorUpdateTemplate,
    _layout: vk::PipelineLayout,
    _set: u32,
    _data: *const c_void,
) {
    with_record(cb, |b| b.lost = true);
    c.as_given()
}
