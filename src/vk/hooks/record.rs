//! Command buffers on an emulating device: allocated, begun, freed and their pools destroyed with
//! a record each, and the application's compute bindings and conditional rendering noted, so that
//! a conversion at pass begin ([`crate::vk::convert`]) can give them back and run outside it.

use std::ffi::c_void;

use ash::vk;
use ash::vk::Handle as _;

use crate::vk::base::chain;
use crate::vk::base::ffi::{guard, key};
use crate::vk::convert;
use crate::vk::own::bindings::{Bound, PushRange};
use crate::vk::registry::{
    self, command_pool_destroyed, forget_command_buffers, record_of, remember_command_buffer,
    with_record, CbRecord,
};

/// `vkAllocateCommandBuffers`: each new command buffer gets its record, with its pool and its
/// pool's queue family, for ownership transfers ([`registry::is_release`]).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn allocate_command_buffers(
    device: vk::Device,
    info: *const vk::CommandBufferAllocateInfo<'_>,
    out: *mut vk::CommandBuffer,
) -> vk::Result {
    guard(
        "vkAllocateCommandBuffers",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let rec = unsafe { registry::recording(device) };
            let Some(next) = rec.and_then(|r| r.next.allocate_command_buffers) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            // SAFETY: the next layer's function, with the caller's arguments.
            let r = unsafe { next(device, info, out) };
            // SAFETY: as the caller promised.
            let (Some(k), Some(i)) = (unsafe { key(device) }, unsafe { info.as_ref() }) else {
                return r;
            };
            let Some(rec) = rec else {
                return r;
            };
            if r == vk::Result::SUCCESS && !out.is_null() {
                let n = i.command_buffer_count as usize;
                // SAFETY: the driver wrote `command_buffer_count` handles.
                let cbs = unsafe { std::slice::from_raw_parts(out, n) };
                let secondary = i.level == vk::CommandBufferLevel::SECONDARY;
                for &cb in cbs {
                    let pool = i.command_pool.as_raw();
                    remember_command_buffer(cb, CbRecord::new(rec.device, k, pool, secondary));
                }
            }
            r
        },
    )
}

/// `vkDestroyCommandPool`: its command buffers are freed with it, and their records go
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkDestroyCommandPool.html>).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn destroy_command_pool(
    device: vk::Device,
    pool: vk::CommandPool,
    alloc: *const vk::AllocationCallbacks<'_>,
) {
    guard("vkDestroyCommandPool", (), || {
        // SAFETY: as the caller promised.
        let (rec, key) = (unsafe { registry::recording(device) }, unsafe {
            key(device)
        });
        if let (Some(rec), Some(k), false) = (rec, key, pool == vk::CommandPool::null()) {
            command_pool_destroyed(rec.device, k, pool.as_raw());
        }
        let next = rec.and_then(|r| r.next.destroy_command_pool);
        if let Some(next) = next {
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { next(device, pool, alloc) };
        }
    })
}

/// `vkBeginCommandBuffer`: the command buffer's bindings start empty
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkBeginCommandBuffer.html>); its
/// record is made (once per command buffer) or cleared, and its conversion slots of destroyed
/// maps go ([`convert::begun`]).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn begin_command_buffer(
    cb: vk::CommandBuffer,
    info: *const vk::CommandBufferBeginInfo<'_>,
) -> vk::Result {
    guard(
        "vkBeginCommandBuffer",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: as the caller promised.
            let rec = unsafe { registry::recording(cb) };
            let Some(next) = rec.and_then(|r| r.next.begin_command_buffer) else {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            };
            let found = record_of(cb, |r| {
                // SAFETY: the caller's begin info, read only; its inheritance info is read for
                // secondary command buffers only, as the specification says.
                let inherits = r.secondary && unsafe { inherits_conditional_rendering(info) };
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
            if let (None, Some(rec)) = (found, rec) {
                // Allocated before the layer saw it (not expected on an emulating device): a
                // primary's record without a pool, dropped with the command buffer or its device.
                // SAFETY: as the caller promised.
                let device = unsafe { key(cb) }.unwrap_or(0);
                remember_command_buffer(cb, CbRecord::new(rec.device, device, 0, false));
            }
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { next(cb, info) }
        },
    )
}

/// `vkFreeCommandBuffers`: their records go.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn free_command_buffers(
    device: vk::Device,
    pool: vk::CommandPool,
    count: u32,
    cbs: *const vk::CommandBuffer,
) {
    guard("vkFreeCommandBuffers", (), || {
        if !cbs.is_null() {
            // SAFETY: the caller's array.
            forget_command_buffers(unsafe { std::slice::from_raw_parts(cbs, count as usize) });
        }
        // The leaf table, not the registry's ranked map: fovea's own uploads free their command
        // buffers through the layer under their submit lock (`crate::common::lock::Rank`).
        // SAFETY: as the caller promised.
        let next = unsafe { registry::recording(device) }.and_then(|r| r.next.free_command_buffers);
        if let Some(next) = next {
            // SAFETY: the next layer's function, with the caller's arguments.
            unsafe { next(device, pool, count, cbs) };
        }
    })
}

/// Whether a begin info's inheritance info makes the command buffer inherit conditional rendering.
///
/// # Safety
/// `info` must be NULL or a valid begin info of a secondary command buffer.
unsafe fn inherits_conditional_rendering(info: *const vk::CommandBufferBeginInfo<'_>) -> bool {
    // SAFETY: as the caller promised.
    let Some(begin) = (unsafe { info.as_ref() }) else {
        return false;
    };
    // SAFETY: as the caller promised: a secondary's begin info has a valid inheritance info.
    let Some(inh) = (unsafe { begin.p_inheritance_info.as_ref() }) else {
        return false;
    };
    let ty = vk::StructureType::COMMAND_BUFFER_INHERITANCE_CONDITIONAL_RENDERING_INFO_EXT;
    // SAFETY: the caller's chain, read only.
    let found = unsafe {
        chain::find::<vk::CommandBufferInheritanceConditionalRenderingInfoEXT<'_>>(inh.p_next, ty)
    };
    let Some(c) = found.ok().flatten() else {
        return false;
    };
    // SAFETY: found by its sType in a valid chain.
    unsafe { (*c).conditional_rendering_enable == vk::TRUE }
}

/// `vkCmdBeginConditionalRenderingEXT`: the condition is noted, so a conversion can suspend it.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_begin_conditional_rendering(
    cb: vk::CommandBuffer,
    info: *const vk::ConditionalRenderingBeginInfoEXT<'_>,
) {
    guard("vkCmdBeginConditionalRenderingEXT", (), || {
        // SAFETY: as the caller promised.
        let rec = unsafe { registry::recording(cb) };
        let Some(next) = rec.and_then(|r| r.next.cmd_begin_conditional_rendering_ext) else {
            return;
        };
        // SAFETY: as the caller promised.
        if let Some(i) = unsafe { info.as_ref() } {
            let c = (i.buffer, i.offset, i.flags);
            with_record(cb, |b| b.conditional = Some(c));
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { next(cb, info) }
    })
}

/// `vkCmdEndConditionalRenderingEXT`: the condition is forgotten.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_end_conditional_rendering(cb: vk::CommandBuffer) {
    guard("vkCmdEndConditionalRenderingEXT", (), || {
        // SAFETY: as the caller promised.
        let rec = unsafe { registry::recording(cb) };
        let Some(next) = rec.and_then(|r| r.next.cmd_end_conditional_rendering_ext) else {
            return;
        };
        with_record(cb, |b| b.conditional = None);
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { next(cb) }
    })
}

/// `vkCmdBindPipeline`: a compute pipeline is noted.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_bind_pipeline(
    cb: vk::CommandBuffer,
    point: vk::PipelineBindPoint,
    pipeline: vk::Pipeline,
) {
    guard("vkCmdBindPipeline", (), || {
        // SAFETY: as the caller promised.
        let rec = unsafe { registry::recording(cb) };
        let Some(next) = rec.and_then(|r| r.next.cmd_bind_pipeline) else {
            return;
        };
        if point == vk::PipelineBindPoint::COMPUTE {
            with_record(cb, |b| b.pipeline = pipeline);
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { next(cb, point, pipeline) }
    })
}

/// `vkCmdBindDescriptorSets`: compute sets and their dynamic offsets are noted.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
#[allow(clippy::too_many_arguments)]
pub unsafe extern "system" fn cmd_bind_descriptor_sets(
    cb: vk::CommandBuffer,
    point: vk::PipelineBindPoint,
    layout: vk::PipelineLayout,
    first: u32,
    set_count: u32,
    sets: *const vk::DescriptorSet,
    dynamic_count: u32,
    dynamic: *const u32,
) {
    guard("vkCmdBindDescriptorSets", (), || {
        // SAFETY: as the caller promised.
        let rec = unsafe { registry::recording(cb) };
        let Some(next) = rec.and_then(|r| r.next.cmd_bind_descriptor_sets) else {
            return;
        };
        if point == vk::PipelineBindPoint::COMPUTE && !sets.is_null() {
            // SAFETY: the caller's arrays.
            let s = unsafe { std::slice::from_raw_parts(sets, set_count as usize) };
            let dy = if dynamic.is_null() {
                &[][..]
            } else {
                // SAFETY: as above.
                unsafe { std::slice::from_raw_parts(dynamic, dynamic_count as usize) }
            };
            with_record(cb, |b| {
                // Which sets take how many dynamic offsets is in their layouts, which the layer
                // does not look into: one set with all of them is exact; several sets with dynamic
                // offsets cannot be split, so the record gives up.
                if dy.is_empty() || s.len() == 1 {
                    let n = dy.len() as u32;
                    b.bind_sets(layout, first, s, dy, |_| Some(n));
                } else {
                    b.lost = true;
                }
            });
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe {
            next(
                cb,
                point,
                layout,
                first,
                set_count,
                sets,
                dynamic_count,
                dynamic,
            )
        }
    })
}

/// `vkCmdPushConstants`: the bytes and the range are noted where the conversion's compute
/// dispatch would disturb them ([`Bound::push`]).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_push_constants(
    cb: vk::CommandBuffer,
    layout: vk::PipelineLayout,
    stages: vk::ShaderStageFlags,
    offset: u32,
    size: u32,
    values: *const c_void,
) {
    guard("vkCmdPushConstants", (), || {
        // SAFETY: as the caller promised.
        let rec = unsafe { registry::recording(cb) };
        let Some(next) = rec.and_then(|r| r.next.cmd_push_constants) else {
            return;
        };
        if !values.is_null() {
            // SAFETY: the caller's `size` bytes.
            let v = unsafe { std::slice::from_raw_parts(values as *const u8, size as usize) };
            let range = PushRange {
                layout,
                stages,
                offset,
                size,
                seq: 0,
            };
            with_record(cb, |b| b.push(range, v));
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { next(cb, layout, stages, offset, size, values) }
    })
}

/// `vkCmdPushDescriptorSetKHR`: a compute push descriptor cannot be given back (its writes would
/// have to be copied); the command buffer's maps are not converted from then on.
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_push_descriptor_set_khr(
    cb: vk::CommandBuffer,
    point: vk::PipelineBindPoint,
    layout: vk::PipelineLayout,
    set: u32,
    count: u32,
    writes: *const vk::WriteDescriptorSet<'_>,
) {
    guard("vkCmdPushDescriptorSetKHR", (), || {
        // SAFETY: as the caller promised.
        let rec = unsafe { registry::recording(cb) };
        let Some(next) = rec.and_then(|r| r.next.cmd_push_descriptor_set_khr) else {
            return;
        };
        if point == vk::PipelineBindPoint::COMPUTE {
            with_record(cb, |b| b.lost = true);
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { next(cb, point, layout, set, count, writes) }
    })
}

/// `vkCmdPushDescriptorSetWithTemplateKHR`: as [`cmd_push_descriptor_set_khr`] (the template's
/// bind point is not looked up, so any use gives up).
///
/// # Safety
/// The caller's arguments, valid as the command requires.
pub unsafe extern "system" fn cmd_push_descriptor_set_with_template_khr(
    cb: vk::CommandBuffer,
    template: vk::DescriptorUpdateTemplate,
    layout: vk::PipelineLayout,
    set: u32,
    data: *const c_void,
) {
    guard("vkCmdPushDescriptorSetWithTemplateKHR", (), || {
        // SAFETY: as the caller promised.
        let rec = unsafe { registry::recording(cb) };
        let Some(next) = rec.and_then(|r| r.next.cmd_push_descriptor_set_with_template_khr) else {
            return;
        };
        with_record(cb, |b| b.lost = true);
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { next(cb, template, layout, set, data) }
    })
}
