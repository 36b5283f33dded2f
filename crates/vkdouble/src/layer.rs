//! The layer: loader plumbing, dispatch, and the intercepted commands.
//!
//! Plumbing follows the Vulkan-Loader's LoaderLayerInterface
//! (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>):
//! `vkNegotiateLoaderLayerInterfaceVersion` hands the loader our `vkGetInstanceProcAddr` and
//! `vkGetDeviceProcAddr`; at `vkCreateInstance`/`vkCreateDevice` the layer takes the next layer's
//! proc-addr functions from the `VK_LAYER_LINK_INFO` element the loader chained in, and advances
//! that element's `pLayerInfo` for the layer below (the loader owns that struct and expects the
//! write). Per-object data is keyed by a dispatchable handle's first pointer word, the loader's
//! dispatch table, which an instance shares with its physical devices and a device with its queues
//! and command buffers.
//!
//! The application's structs are never written: each rewrite works on a copy.

use std::collections::BTreeMap;
use std::ffi::{c_char, c_void, CStr};
use std::panic::AssertUnwindSafe;
use std::sync::{Arc, Mutex};

use ash::vk::{self, Handle as _};
use serde_json::{json, Value};

use crate::chain::{self, find};
use crate::ffi;
use crate::record::{self, error, event};
use crate::shade::PipelineRate;
use crate::Profile;

mod centre;
mod coarse;
mod queues;

pub use queues::set_wanted as set_queues;
use queues::Down as _;

type Key = usize;

/// The loader's dispatch pointer in a dispatchable handle.
///
/// # Safety
/// `raw` must be a live dispatchable handle.
unsafe fn key(raw: u64) -> Key {
    // SAFETY: dispatchable handles point at an object whose first word is the dispatch pointer.
    unsafe { *(raw as usize as *const usize) }
}

struct InstanceData {
    handle: vk::Instance,
    gipa: vk::PFN_vkGetInstanceProcAddr,
    fns: ash::Instance,
    profile: Profile,
}

struct DeviceData {
    handle: vk::Device,
    physical: vk::PhysicalDevice,
    instance: Arc<InstanceData>,
    gdpa: vk::PFN_vkGetDeviceProcAddr,
    fns: ash::Device,
    set_loader_data: Option<ffi::PfnSetDeviceLoaderData>,
    /// [`crate::NULL_COMMANDS_ENV`] was set when the device was created.
    null_commands: bool,
    /// `attachmentFragmentShadingRate` was enabled: without it, no shading-rate attachment.
    attachment_feature: bool,
    state: Mutex<DeviceState>,
}

#[derive(Clone, Copy)]
struct ImageInfo {
    extent: vk::Extent3D,
    layers: u32,
}

/// A view of a shading-rate image: which image, which layers.
#[derive(Clone, Copy)]
struct ViewInfo {
    image: u64,
    base_layer: u32,
    layers: u32,
}

/// One subpass of a render pass: its shading-rate attachment (index, texel size), view mask and
/// colour attachments.
#[derive(Clone)]
struct SubpassInfo {
    rate: Option<(u32, vk::Extent2D)>,
    view_mask: u32,
    colors: Vec<u32>,
}

/// A colour attachment's image as the double coarsens it: format, size, the first layer a view
/// names.
#[derive(Clone, Copy)]
struct ColourTarget {
    image: u64,
    base_layer: u32,
    format: vk::Format,
    extent: vk::Extent2D,
}

/// What the double keeps of a render pass.
struct PassInfo {
    subpasses: Vec<SubpassInfo>,
    /// Per attachment: its load and store operations.
    ops: Vec<(vk::AttachmentLoadOp, vk::AttachmentStoreOp)>,
}

impl PassInfo {
    fn rates(&self) -> impl Iterator<Item = (u32, vk::Extent2D)> + '_ {
        self.subpasses.iter().filter_map(|s| s.rate)
    }
}

#[derive(Default)]
struct DeviceState {
    /// Images created with the shading-rate usage.
    images: BTreeMap<u64, ImageInfo>,
    /// Views of those images.
    views: BTreeMap<u64, ViewInfo>,
    /// Render passes.
    passes: BTreeMap<u64, PassInfo>,
    /// Images with the colour-attachment usage (`base_layer` 0).
    colour_images: BTreeMap<u64, ColourTarget>,
    /// Views of those.
    colour_views: BTreeMap<u64, ColourTarget>,
    /// Graphics pipelines: their rate state, and whether it is dynamic.
    pipelines: BTreeMap<u64, (PipelineRate, bool)>,
    /// Per command buffer: what its recording does to the rates of its draws.
    recordings: BTreeMap<u64, Recording>,
    /// Framebuffer → its attachments' views.
    framebuffers: BTreeMap<u64, Vec<u64>>,
    /// Command buffer → shading-rate images its render passes read.
    commands: BTreeMap<u64, Vec<u64>>,
    /// Queue → family.
    queues: BTreeMap<u64, u32>,
    /// The layer's own command pools for read-backs, per family.
    pools: BTreeMap<u32, vk::CommandPool>,
}

static INSTANCES: Mutex<BTreeMap<Key, Arc<InstanceData>>> = Mutex::new(BTreeMap::new());
static DEVICES: Mutex<BTreeMap<Key, Arc<DeviceData>>> = Mutex::new(BTreeMap::new());

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The data of the instance (or physical device) `raw`.
///
/// # Safety
/// `raw` must be a live instance or physical device.
unsafe fn instance_of(raw: u64) -> Option<Arc<InstanceData>> {
    // SAFETY: forwarded from the caller.
    let k = unsafe { key(raw) };
    lock(&INSTANCES).get(&k).cloned()
}

/// The data of the device (or queue, or command buffer) `raw`; panics (caught by [`guard`]) for a
/// handle the double never saw.
///
/// # Safety
/// `raw` must be a live device, queue or command buffer.
unsafe fn device_of(raw: u64) -> Arc<DeviceData> {
    // SAFETY: forwarded from the caller.
    let k = unsafe { key(raw) };
    lock(&DEVICES)
        .get(&k)
        .cloned()
        .expect("a device the double created")
}

/// Runs `f`, turning a panic into `fail` and a recorded error: no panic crosses the C ABI.
fn guard<R>(what: &str, fail: R, f: impl FnOnce() -> R) -> R {
    match std::panic::catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(p) => {
            let why = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            error(format!("{what}: internal failure: {why}"));
            fail
        }
    }
}

/// A slice from a Vulkan (pointer, count) pair; empty for null.
///
/// # Safety
/// `p` must be null or valid for `n` elements.
pub(crate) unsafe fn slice<'a, T>(p: *const T, n: u32) -> &'a [T] {
    if p.is_null() || n == 0 {
        &[]
    } else {
        // SAFETY: the caller's promise.
        unsafe { std::slice::from_raw_parts(p, n as usize) }
    }
}

/// The two-call idiom: count only when `out` is null, else fill and report `VK_INCOMPLETE` when
/// the array was short
/// (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#fundamentals-commandsyntax>).
///
/// # Safety
/// `count` must be valid; `out` null or valid for `*count` elements.
unsafe fn two_call<T: Copy>(items: &[T], count: *mut u32, out: *mut T) -> vk::Result {
    // SAFETY: the caller's promise.
    unsafe {
        if out.is_null() {
            *count = items.len() as u32;
            return vk::Result::SUCCESS;
        }
        let n = (*count as usize).min(items.len());
        std::ptr::copy_nonoverlapping(items.as_ptr(), out, n);
        *count = n as u32;
        if n < items.len() {
            vk::Result::INCOMPLETE
        } else {
            vk::Result::SUCCESS
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Rewrites lavapipe needs: the shading-rate layout, stage and access bits become ones it knows.

const FSR_USAGE: vk::ImageUsageFlags = vk::ImageUsageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR;
const FSR_LAYOUT: vk::ImageLayout = vk::ImageLayout::FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR;
const FSR_EXT: &CStr = c"VK_KHR_fragment_shading_rate";
/// Offered as the desktop drivers the double plays offer it (NVIDIA's and RADV list it): `NONE`
/// load and store operations. lavapipe 22.3 has the store operation (core in Vulkan 1.3) but not
/// the extension; the double strips the name and hands lavapipe `LOAD` for a `NONE` load, which
/// keeps the contents as `NONE` does
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkAttachmentLoadOp.html>).
const LOAD_STORE_NONE_EXT: &CStr = c"VK_EXT_load_store_op_none";

/// The load operation lavapipe gets.
fn fix_load(op: vk::AttachmentLoadOp) -> vk::AttachmentLoadOp {
    if op == vk::AttachmentLoadOp::NONE_EXT {
        vk::AttachmentLoadOp::LOAD
    } else {
        op
    }
}

fn fix_layout(l: vk::ImageLayout) -> vk::ImageLayout {
    if l == FSR_LAYOUT {
        vk::ImageLayout::GENERAL
    } else {
        l
    }
}

fn fix_stage(s: vk::PipelineStageFlags) -> vk::PipelineStageFlags {
    let fsr = vk::PipelineStageFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR;
    if s.contains(fsr) {
        (s & !fsr) | vk::PipelineStageFlags::FRAGMENT_SHADER
    } else {
        s
    }
}

fn fix_access(a: vk::AccessFlags) -> vk::AccessFlags {
    let fsr = vk::AccessFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR;
    if a.contains(fsr) {
        (a & !fsr) | vk::AccessFlags::SHADER_READ
    } else {
        a
    }
}

fn fix_stage2(s: vk::PipelineStageFlags2) -> vk::PipelineStageFlags2 {
    let fsr = vk::PipelineStageFlags2::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR;
    if s.contains(fsr) {
        (s & !fsr) | vk::PipelineStageFlags2::FRAGMENT_SHADER
    } else {
        s
    }
}

fn fix_access2(a: vk::AccessFlags2) -> vk::AccessFlags2 {
    let fsr = vk::AccessFlags2::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR;
    if a.contains(fsr) {
        (a & !fsr) | vk::AccessFlags2::SHADER_READ
    } else {
        a
    }
}

fn pair(e: vk::Extent2D) -> Value {
    json!([e.width, e.height])
}

// ---------------------------------------------------------------------------------------------
// Dispatch tables: each intercepted command is named once; the proc-addr lookups derive from them.

macro_rules! table {
    ($lookup:ident: $($name:literal => $f:ident as $pfn:ident),* $(,)?) => {
        fn $lookup(name: &[u8]) -> vk::PFN_vkVoidFunction {
            match name {
                $($name => {
                    let f: vk::$pfn = $f;
                    // SAFETY: the loader's generic function pointer type; the caller casts it back
                    // to the type its name implies, which is `$pfn`.
                    Some(unsafe { std::mem::transmute::<vk::$pfn, unsafe extern "system" fn()>(f) })
                })*
                _ => None,
            }
        }
    };
}

// Intercepted whatever the profile: without them the layer could not stay in the chain.
table! { lifecycle:
    b"vkGetInstanceProcAddr" => get_instance_proc_addr as PFN_vkGetInstanceProcAddr,
    b"vkCreateInstance" => create_instance as PFN_vkCreateInstance,
    b"vkDestroyInstance" => destroy_instance as PFN_vkDestroyInstance,
    b"vkCreateDevice" => create_device as PFN_vkCreateDevice,
    b"vkGetDeviceProcAddr" => get_device_proc_addr as PFN_vkGetDeviceProcAddr,
    b"vkDestroyDevice" => destroy_device as PFN_vkDestroyDevice,
}

// Physical-device queries the double answers for a profile that offers shading rates.
table! { instance_commands:
    b"vkGetPhysicalDeviceQueueFamilyProperties" => get_queue_family_properties as PFN_vkGetPhysicalDeviceQueueFamilyProperties,
    b"vkGetPhysicalDeviceQueueFamilyProperties2" => get_queue_family_properties2 as PFN_vkGetPhysicalDeviceQueueFamilyProperties2,
    b"vkGetPhysicalDeviceQueueFamilyProperties2KHR" => get_queue_family_properties2 as PFN_vkGetPhysicalDeviceQueueFamilyProperties2,
    b"vkEnumerateDeviceExtensionProperties" => enumerate_device_extension_properties as PFN_vkEnumerateDeviceExtensionProperties,
    b"vkGetPhysicalDeviceFeatures2" => get_features2 as PFN_vkGetPhysicalDeviceFeatures2,
    b"vkGetPhysicalDeviceFeatures2KHR" => get_features2 as PFN_vkGetPhysicalDeviceFeatures2,
    b"vkGetPhysicalDeviceProperties2" => get_properties2 as PFN_vkGetPhysicalDeviceProperties2,
    b"vkGetPhysicalDeviceProperties2KHR" => get_properties2 as PFN_vkGetPhysicalDeviceProperties2,
    b"vkGetPhysicalDeviceFragmentShadingRatesKHR" => get_fragment_shading_rates as PFN_vkGetPhysicalDeviceFragmentShadingRatesKHR,
    b"vkGetPhysicalDeviceFormatProperties" => get_format_properties as PFN_vkGetPhysicalDeviceFormatProperties,
    b"vkGetPhysicalDeviceFormatProperties2" => get_format_properties2 as PFN_vkGetPhysicalDeviceFormatProperties2,
    b"vkGetPhysicalDeviceFormatProperties2KHR" => get_format_properties2 as PFN_vkGetPhysicalDeviceFormatProperties2,
    b"vkGetPhysicalDeviceImageFormatProperties" => get_image_format_properties as PFN_vkGetPhysicalDeviceImageFormatProperties,
    b"vkGetPhysicalDeviceImageFormatProperties2" => get_image_format_properties2 as PFN_vkGetPhysicalDeviceImageFormatProperties2,
    b"vkGetPhysicalDeviceImageFormatProperties2KHR" => get_image_format_properties2 as PFN_vkGetPhysicalDeviceImageFormatProperties2,
}

// Device commands the double rewrites or records for a profile that offers shading rates.
table! { device_commands:
    b"vkGetDeviceQueue" => get_device_queue as PFN_vkGetDeviceQueue,
    b"vkGetDeviceQueue2" => get_device_queue2 as PFN_vkGetDeviceQueue2,
    b"vkQueueBindSparse" => queue_bind_sparse as PFN_vkQueueBindSparse,
    b"vkDeviceWaitIdle" => device_wait_idle as PFN_vkDeviceWaitIdle,
    b"vkGetFenceStatus" => get_fence_status as PFN_vkGetFenceStatus,
    b"vkWaitSemaphores" => wait_semaphores as PFN_vkWaitSemaphores,
    b"vkWaitSemaphoresKHR" => wait_semaphores as PFN_vkWaitSemaphores,
    b"vkGetSemaphoreCounterValue" => get_semaphore_counter_value as PFN_vkGetSemaphoreCounterValue,
    b"vkGetSemaphoreCounterValueKHR" => get_semaphore_counter_value as PFN_vkGetSemaphoreCounterValue,
    b"vkCreateImage" => create_image as PFN_vkCreateImage,
    b"vkDestroyImage" => destroy_image as PFN_vkDestroyImage,
    b"vkDestroyImageView" => destroy_image_view as PFN_vkDestroyImageView,
    b"vkDestroyRenderPass" => destroy_render_pass as PFN_vkDestroyRenderPass,
    b"vkDestroyFramebuffer" => destroy_framebuffer as PFN_vkDestroyFramebuffer,
    b"vkCreateImageView" => create_image_view as PFN_vkCreateImageView,
    b"vkCreateRenderPass2" => create_render_pass2 as PFN_vkCreateRenderPass2,
    b"vkCreateRenderPass2KHR" => create_render_pass2 as PFN_vkCreateRenderPass2,
    b"vkCreateFramebuffer" => create_framebuffer as PFN_vkCreateFramebuffer,
    b"vkCreateGraphicsPipelines" => create_graphics_pipelines as PFN_vkCreateGraphicsPipelines,
    b"vkBeginCommandBuffer" => begin_command_buffer as PFN_vkBeginCommandBuffer,
    b"vkCmdBeginRenderPass" => cmd_begin_render_pass as PFN_vkCmdBeginRenderPass,
    b"vkCmdBeginRenderPass2" => cmd_begin_render_pass2 as PFN_vkCmdBeginRenderPass2,
    b"vkCmdBeginRenderPass2KHR" => cmd_begin_render_pass2 as PFN_vkCmdBeginRenderPass2,
    b"vkCmdBeginRendering" => cmd_begin_rendering as PFN_vkCmdBeginRendering,
    b"vkCmdBeginRenderingKHR" => cmd_begin_rendering as PFN_vkCmdBeginRendering,
    b"vkCmdPipelineBarrier" => cmd_pipeline_barrier as PFN_vkCmdPipelineBarrier,
    b"vkCmdPipelineBarrier2" => cmd_pipeline_barrier2 as PFN_vkCmdPipelineBarrier2,
    b"vkCmdPipelineBarrier2KHR" => cmd_pipeline_barrier2 as PFN_vkCmdPipelineBarrier2,
    b"vkCmdSetFragmentShadingRateKHR" => cmd_set_fragment_shading_rate as PFN_vkCmdSetFragmentShadingRateKHR,
    b"vkCmdExecuteCommands" => cmd_execute_commands as PFN_vkCmdExecuteCommands,
    b"vkDestroyPipeline" => destroy_pipeline as PFN_vkDestroyPipeline,
    b"vkCreateRenderPass" => create_render_pass as PFN_vkCreateRenderPass,
    b"vkCreateSampler" => create_sampler as PFN_vkCreateSampler,
    b"vkCmdSetEvent" => cmd_set_event as PFN_vkCmdSetEvent,
    b"vkCmdResetEvent" => cmd_reset_event as PFN_vkCmdResetEvent,
    b"vkCmdWriteTimestamp" => cmd_write_timestamp as PFN_vkCmdWriteTimestamp,
    b"vkCmdWaitEvents" => cmd_wait_events as PFN_vkCmdWaitEvents,
    b"vkCmdSetEvent2" => cmd_set_event2 as PFN_vkCmdSetEvent2,
    b"vkCmdSetEvent2KHR" => cmd_set_event2 as PFN_vkCmdSetEvent2,
    b"vkCmdResetEvent2" => cmd_reset_event2 as PFN_vkCmdResetEvent2,
    b"vkCmdResetEvent2KHR" => cmd_reset_event2 as PFN_vkCmdResetEvent2,
    b"vkCmdWriteTimestamp2" => cmd_write_timestamp2 as PFN_vkCmdWriteTimestamp2,
    b"vkCmdWriteTimestamp2KHR" => cmd_write_timestamp2 as PFN_vkCmdWriteTimestamp2,
    b"vkCmdWaitEvents2" => cmd_wait_events2 as PFN_vkCmdWaitEvents2,
    b"vkCmdWaitEvents2KHR" => cmd_wait_events2 as PFN_vkCmdWaitEvents2,
    b"vkCmdBindPipeline" => cmd_bind_pipeline as PFN_vkCmdBindPipeline,
    b"vkCmdNextSubpass" => cmd_next_subpass as PFN_vkCmdNextSubpass,
    b"vkCmdNextSubpass2" => cmd_next_subpass2 as PFN_vkCmdNextSubpass2,
    b"vkCmdNextSubpass2KHR" => cmd_next_subpass2 as PFN_vkCmdNextSubpass2,
    b"vkCmdEndRenderPass" => cmd_end_render_pass as PFN_vkCmdEndRenderPass,
    b"vkCmdEndRenderPass2" => cmd_end_render_pass2 as PFN_vkCmdEndRenderPass2,
    b"vkCmdEndRenderPass2KHR" => cmd_end_render_pass2 as PFN_vkCmdEndRenderPass2,
    b"vkCmdEndRendering" => cmd_end_rendering as PFN_vkCmdEndRendering,
    b"vkCmdEndRenderingKHR" => cmd_end_rendering as PFN_vkCmdEndRendering,
    b"vkCmdDraw" => cmd_draw as PFN_vkCmdDraw,
    b"vkCmdDrawIndexed" => cmd_draw_indexed as PFN_vkCmdDrawIndexed,
    b"vkCmdDrawIndirect" => cmd_draw_indirect as PFN_vkCmdDrawIndirect,
    b"vkCmdDrawIndexedIndirect" => cmd_draw_indexed_indirect as PFN_vkCmdDrawIndexedIndirect,
    b"vkCmdDrawIndirectCount" => cmd_draw_indirect_count as PFN_vkCmdDrawIndirectCount,
    b"vkCmdDrawIndirectCountKHR" => cmd_draw_indirect_count as PFN_vkCmdDrawIndirectCount,
    b"vkCmdDrawIndexedIndirectCount" => cmd_draw_indexed_indirect_count as PFN_vkCmdDrawIndexedIndirectCount,
    b"vkCmdDrawIndexedIndirectCountKHR" => cmd_draw_indexed_indirect_count as PFN_vkCmdDrawIndexedIndirectCount,
    b"vkQueueSubmit" => queue_submit as PFN_vkQueueSubmit,
    b"vkQueueSubmit2" => queue_submit2 as PFN_vkQueueSubmit2,
    b"vkQueueSubmit2KHR" => queue_submit2 as PFN_vkQueueSubmit2,
}

// With `NULL_COMMANDS_ENV` set at device creation: recording commands that do nothing.
table! { null_commands:
    b"vkCmdPipelineBarrier" => null_pipeline_barrier as PFN_vkCmdPipelineBarrier,
    b"vkCmdPipelineBarrier2" => null_pipeline_barrier2 as PFN_vkCmdPipelineBarrier2,
    b"vkCmdPipelineBarrier2KHR" => null_pipeline_barrier2 as PFN_vkCmdPipelineBarrier2,
    b"vkCmdBeginRenderPass" => null_begin_render_pass as PFN_vkCmdBeginRenderPass,
    b"vkCmdBeginRenderPass2" => null_begin_render_pass2 as PFN_vkCmdBeginRenderPass2,
    b"vkCmdBeginRenderPass2KHR" => null_begin_render_pass2 as PFN_vkCmdBeginRenderPass2,
    b"vkCmdEndRenderPass" => null_end as PFN_vkCmdEndRenderPass,
    b"vkCmdEndRenderPass2" => null_end2 as PFN_vkCmdEndRenderPass2,
    b"vkCmdEndRenderPass2KHR" => null_end2 as PFN_vkCmdEndRenderPass2,
    b"vkCmdBeginRendering" => null_begin_rendering as PFN_vkCmdBeginRendering,
    b"vkCmdBeginRenderingKHR" => null_begin_rendering as PFN_vkCmdBeginRendering,
    b"vkCmdEndRendering" => null_end as PFN_vkCmdEndRendering,
    b"vkCmdEndRenderingKHR" => null_end as PFN_vkCmdEndRendering,
    b"vkCmdSetFragmentShadingRateKHR" => null_set_fragment_shading_rate
        as PFN_vkCmdSetFragmentShadingRateKHR,
    b"vkCmdBindPipeline" => null_bind_pipeline as PFN_vkCmdBindPipeline,
    b"vkCmdBindDescriptorSets" => null_bind_descriptor_sets as PFN_vkCmdBindDescriptorSets,
    b"vkCmdPushConstants" => null_push_constants as PFN_vkCmdPushConstants,
    b"vkCmdDispatch" => null_dispatch as PFN_vkCmdDispatch,
    b"vkCmdCopyBufferToImage" => null_copy_buffer_to_image as PFN_vkCmdCopyBufferToImage,
    b"vkCmdCopyImageToBuffer" => null_copy_image_to_buffer as PFN_vkCmdCopyImageToBuffer,
}

#[allow(clippy::too_many_arguments)]
unsafe extern "system" fn null_pipeline_barrier(
    _: vk::CommandBuffer,
    _: vk::PipelineStageFlags,
    _: vk::PipelineStageFlags,
    _: vk::DependencyFlags,
    _: u32,
    _: *const vk::MemoryBarrier<'_>,
    _: u32,
    _: *const vk::BufferMemoryBarrier<'_>,
    _: u32,
    _: *const vk::ImageMemoryBarrier<'_>,
) {
}

unsafe extern "system" fn null_pipeline_barrier2(
    _: vk::CommandBuffer,
    _: *const vk::DependencyInfo<'_>,
) {
}

unsafe extern "system" fn null_begin_render_pass(
    _: vk::CommandBuffer,
    _: *const vk::RenderPassBeginInfo<'_>,
    _: vk::SubpassContents,
) {
}

unsafe extern "system" fn null_begin_render_pass2(
    _: vk::CommandBuffer,
    _: *const vk::RenderPassBeginInfo<'_>,
    _: *const vk::SubpassBeginInfo<'_>,
) {
}

unsafe extern "system" fn null_begin_rendering(
    _: vk::CommandBuffer,
    _: *const vk::RenderingInfo<'_>,
) {
}

unsafe extern "system" fn null_end(_: vk::CommandBuffer) {}

unsafe extern "system" fn null_end2(_: vk::CommandBuffer, _: *const vk::SubpassEndInfo<'_>) {}

unsafe extern "system" fn null_set_fragment_shading_rate(
    _: vk::CommandBuffer,
    _: *const vk::Extent2D,
    _: *const [vk::FragmentShadingRateCombinerOpKHR; 2],
) {
}

unsafe extern "system" fn null_bind_pipeline(
    _: vk::CommandBuffer,
    _: vk::PipelineBindPoint,
    _: vk::Pipeline,
) {
}

#[allow(clippy::too_many_arguments)]
unsafe extern "system" fn null_bind_descriptor_sets(
    _: vk::CommandBuffer,
    _: vk::PipelineBindPoint,
    _: vk::PipelineLayout,
    _: u32,
    _: u32,
    _: *const vk::DescriptorSet,
    _: u32,
    _: *const u32,
) {
}

unsafe extern "system" fn null_push_constants(
    _: vk::CommandBuffer,
    _: vk::PipelineLayout,
    _: vk::ShaderStageFlags,
    _: u32,
    _: u32,
    _: *const std::ffi::c_void,
) {
}

unsafe extern "system" fn null_dispatch(_: vk::CommandBuffer, _: u32, _: u32, _: u32) {}

unsafe extern "system" fn null_copy_buffer_to_image(
    _: vk::CommandBuffer,
    _: vk::Buffer,
    _: vk::Image,
    _: vk::ImageLayout,
    _: u32,
    _: *const vk::BufferImageCopy,
) {
}

unsafe extern "system" fn null_copy_image_to_buffer(
    _: vk::CommandBuffer,
    _: vk::Image,
    _: vk::ImageLayout,
    _: vk::Buffer,
    _: u32,
    _: *const vk::BufferImageCopy,
) {
}

/// The loader's entry: agree on interface version 2, which hands over both proc-addr functions.
///
/// # Safety
/// `p` must point at the loader's `VkNegotiateLayerInterface`.
#[no_mangle]
pub unsafe extern "system" fn vkNegotiateLoaderLayerInterfaceVersion(
    p: *mut ffi::NegotiateLayerInterface,
) -> vk::Result {
    guard(
        "vkNegotiateLoaderLayerInterfaceVersion",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: the loader passes a valid struct it owns, for us to fill.
            let n = unsafe { &mut *p };
            if n.s_type != ffi::NEGOTIATE_INTERFACE_STRUCT || n.loader_layer_interface_version < 2 {
                return vk::Result::ERROR_INITIALIZATION_FAILED;
            }
            n.loader_layer_interface_version = 2;
            n.pfn_get_instance_proc_addr = Some(get_instance_proc_addr);
            n.pfn_get_device_proc_addr = Some(get_device_proc_addr);
            n.pfn_get_physical_device_proc_addr = None;
            vk::Result::SUCCESS
        },
    )
}

unsafe extern "system" fn get_instance_proc_addr(
    instance: vk::Instance,
    name: *const c_char,
) -> vk::PFN_vkVoidFunction {
    guard("vkGetInstanceProcAddr", None, || {
        if name.is_null() {
            return None;
        }
        // SAFETY: the loader passes a NUL-terminated name.
        let n = unsafe { CStr::from_ptr(name) }.to_bytes();
        if let Some(f) = lifecycle(n) {
            return Some(f);
        }
        if instance == vk::Instance::null() {
            return None;
        }
        // SAFETY: a live instance (the loader asks only about instances it created through us).
        let data = unsafe { instance_of(instance.as_raw()) }?;
        if data.profile.offers_fsr() {
            if let Some(f) = instance_commands(n).or_else(|| device_commands(n)) {
                return Some(f);
            }
        }
        if let Some(f) = faultable_commands(n).or_else(|| counted_commands(n)) {
            return Some(f);
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { (data.gipa)(instance, name) }
    })
}

unsafe extern "system" fn get_device_proc_addr(
    device: vk::Device,
    name: *const c_char,
) -> vk::PFN_vkVoidFunction {
    guard("vkGetDeviceProcAddr", None, || {
        if name.is_null() || device == vk::Device::null() {
            return None;
        }
        // SAFETY: the loader passes a NUL-terminated name and a device made through us.
        let (n, data) = unsafe { (CStr::from_ptr(name).to_bytes(), device_of(device.as_raw())) };
        if n == b"vkGetDeviceProcAddr" || n == b"vkDestroyDevice" {
            return lifecycle(n);
        }
        if data.null_commands {
            if let Some(f) = null_commands(n) {
                return Some(f);
            }
        }
        if data.instance.profile.offers_fsr() {
            if let Some(f) = device_commands(n) {
                return Some(f);
            }
        }
        if let Some(f) = faultable_commands(n).or_else(|| counted_commands(n)) {
            return Some(f);
        }
        // SAFETY: the next layer's function, with the caller's arguments.
        unsafe { (data.gdpa)(device, name) }
    })
}

unsafe extern "system" fn create_instance(
    info: *const vk::InstanceCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Instance,
) -> vk::Result {
    guard(
        "vkCreateInstance",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            // SAFETY: the loader's create info carries its link info; advancing `pLayerInfo` in
            // it is the documented protocol (the struct is the loader's, not the application's).
            // The next layer's functions get the caller's arguments.
            unsafe {
                let links = chain::find_all(
                    (*info).p_next,
                    vk::StructureType::LOADER_INSTANCE_CREATE_INFO,
                );
                let Some(link) = links
                    .into_iter()
                    .map(|l| l as *mut ffi::LayerInstanceCreateInfo)
                    .find(|&l| (*l).function == ffi::LAYER_LINK_INFO)
                else {
                    return vk::Result::ERROR_INITIALIZATION_FAILED;
                };
                let layer = (*link).u[0] as *mut ffi::LayerInstanceLink;
                if layer.is_null() {
                    return vk::Result::ERROR_INITIALIZATION_FAILED;
                }
                let gipa = (*layer).pfn_next_get_instance_proc_addr;
                (*link).u[0] = (*layer).p_next as *mut c_void;
                let Some(create) = gipa(vk::Instance::null(), c"vkCreateInstance".as_ptr()) else {
                    return vk::Result::ERROR_INITIALIZATION_FAILED;
                };
                let create: vk::PFN_vkCreateInstance = std::mem::transmute(create);
                let r = create(info, alloc, out);
                if r != vk::Result::SUCCESS {
                    return r;
                }
                let handle = *out;
                let fns = ash::Instance::load_with(
                    |n| std::mem::transmute(gipa(handle, n.as_ptr())),
                    handle,
                );
                let profile = record::profile();
                event(json!({"kind": "instance", "profile": profile.name()}));
                write_records_at_exit();
                lock(&INSTANCES).insert(
                    key(handle.as_raw()),
                    Arc::new(InstanceData {
                        handle,
                        gipa,
                        fns,
                        profile,
                    }),
                );
                r
            }
        },
    )
}

unsafe extern "system" fn destroy_instance(
    instance: vk::Instance,
    alloc: *const vk::AllocationCallbacks<'_>,
) {
    guard("vkDestroyInstance", (), || {
        if instance == vk::Instance::null() {
            return;
        }
        // SAFETY: a live instance made through us; the next layer gets the caller's arguments.
        unsafe {
            let k = key(instance.as_raw());
            let data = lock(&INSTANCES).remove(&k);
            if let Some(d) = data {
                (d.fns.fp_v1_0().destroy_instance)(instance, alloc);
            }
        }
        write_records();
    })
}

extern "C" {
    /// C's `atexit`: the handler runs when the process exits, or when this library is unloaded
    /// (glibc ties a shared library's handlers to it).
    fn atexit(handler: extern "C" fn()) -> std::ffi::c_int;
}

extern "C" fn write_records_now() {
    // No panic may leave a C callback.
    let _ = std::panic::catch_unwind(write_records);
}

/// Where [`crate::RECORDS_FILE_ENV`] names a file, makes sure the records reach it at exit too:
/// applications that exit without destroying their device and instance (hello_xr) are read so.
fn write_records_at_exit() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    if std::env::var_os(crate::RECORDS_FILE_ENV).is_some() {
        // SAFETY: registers a plain function that takes and returns nothing.
        ONCE.call_once(|| unsafe {
            atexit(write_records_now);
        });
    }
}

/// Writes the records where [`crate::RECORDS_FILE_ENV`] names a file.
fn write_records() {
    if let Some(path) = std::env::var_os(crate::RECORDS_FILE_ENV) {
        if let Err(e) = std::fs::write(&path, crate::record::snapshot().to_string()) {
            crate::record::error(format!("{}: {e}", crate::RECORDS_FILE_ENV));
        }
    }
}

unsafe extern "system" fn create_device(
    physical: vk::PhysicalDevice,
    info: *const vk::DeviceCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Device,
) -> vk::Result {
    guard(
        "vkCreateDevice",
        vk::Result::ERROR_INITIALIZATION_FAILED,
        || {
            if let Some(r) = record::fault("vkCreateDevice") {
                return r;
            }
            // SAFETY: as in create_instance: the loader's link info is advanced in place; the
            // application's create info is read only, its rewrite is a copy that lives across the
            // call.
            unsafe {
                let Some(inst) = instance_of(physical.as_raw()) else {
                    return vk::Result::ERROR_INITIALIZATION_FAILED;
                };
                let ci = &*info;
                let links =
                    chain::find_all(ci.p_next, vk::StructureType::LOADER_DEVICE_CREATE_INFO)
                        .into_iter()
                        .map(|l| l as *mut ffi::LayerDeviceCreateInfo)
                        .collect::<Vec<_>>();
                let Some(&link) = links
                    .iter()
                    .find(|&&l| (*l).function == ffi::LAYER_LINK_INFO)
                else {
                    return vk::Result::ERROR_INITIALIZATION_FAILED;
                };
                let set_loader_data = links
                    .iter()
                    .find(|&&l| (*l).function == ffi::LOADER_DATA_CALLBACK)
                    .map(|&l| {
                        std::mem::transmute::<*mut c_void, ffi::PfnSetDeviceLoaderData>((*l).u)
                    });
                let layer = (*link).u as *mut ffi::LayerDeviceLink;
                if layer.is_null() {
                    return vk::Result::ERROR_INITIALIZATION_FAILED;
                }
                let gipa = (*layer).pfn_next_get_instance_proc_addr;
                let gdpa = (*layer).pfn_next_get_device_proc_addr;
                (*link).u = (*layer).p_next as *mut c_void;
                let Some(create) = gipa(inst.handle, c"vkCreateDevice".as_ptr()) else {
                    return vk::Result::ERROR_INITIALIZATION_FAILED;
                };
                let create: vk::PFN_vkCreateDevice = std::mem::transmute(create);
                if let Some(r) = crate::strict::device(ci) {
                    return r;
                }
                let attachment_feature =
                    find::<vk::PhysicalDeviceFragmentShadingRateFeaturesKHR>(ci.p_next)
                        .is_some_and(|f| (*f).attachment_fragment_shading_rate != 0);

                let mut copy = *ci;
                let exts: Vec<*const c_char>;
                let stripped;
                if inst.profile.offers_fsr() {
                    let names = slice(ci.pp_enabled_extension_names, ci.enabled_extension_count);
                    let asked = names.iter().any(|&n| CStr::from_ptr(n) == FSR_EXT);
                    // lavapipe 22.3 has neither (a driver that has the second keeps it).
                    let native_none = inst
                        .fns
                        .enumerate_device_extension_properties(physical)
                        .unwrap_or_default()
                        .iter()
                        .any(|e| e.extension_name_as_c_str() == Ok(LOAD_STORE_NONE_EXT));
                    exts = names
                        .iter()
                        .copied()
                        .filter(|&n| CStr::from_ptr(n) != FSR_EXT)
                        .filter(|&n| native_none || CStr::from_ptr(n) != LOAD_STORE_NONE_EXT)
                        .collect();
                    let features = find::<vk::PhysicalDeviceFragmentShadingRateFeaturesKHR>(
                        ci.p_next,
                    )
                    .map(|f| {
                        json!({
                            "pipeline": (*f).pipeline_fragment_shading_rate != 0,
                            "primitive": (*f).primitive_fragment_shading_rate != 0,
                            "attachment": (*f).attachment_fragment_shading_rate != 0,
                        })
                    });
                    if let Some(f) =
                        find::<vk::PhysicalDeviceFragmentShadingRateFeaturesKHR>(ci.p_next)
                    {
                        if (*f).primitive_fragment_shading_rate != 0 {
                            error(
                                "vkCreateDevice: primitiveFragmentShadingRate is not offered"
                                    .into(),
                            );
                        }
                    }
                    // Every name and chained sType, as they reached the driver: what a test
                    // checks that no density-map name or struct got through.
                    let extensions: Vec<String> = names
                        .iter()
                        .map(|&n| CStr::from_ptr(n).to_string_lossy().into_owned())
                        .collect();
                    let mut chain_types = Vec::new();
                    let mut node = ci.p_next as *const vk::BaseInStructure<'static>;
                    while !node.is_null() && chain_types.len() < 64 {
                        chain_types.push((*node).s_type.as_raw());
                        node = (*node).p_next;
                    }
                    event(
                        json!({"kind": "device", "extension": asked, "features": features,
                        "extensions": extensions, "chain": chain_types}),
                    );
                    stripped = match chain::strip(
                        ci.p_next,
                        &[vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_SHADING_RATE_FEATURES_KHR],
                    ) {
                        Ok(s) => s,
                        Err(s) => {
                            error(format!("vkCreateDevice: cannot copy a {s:?} in the chain"));
                            return vk::Result::ERROR_INITIALIZATION_FAILED;
                        }
                    };
                    copy.p_next = stripped.head;
                    copy.enabled_extension_count = exts.len() as u32;
                    copy.pp_enabled_extension_names = exts.as_ptr();
                }
                // The extra queues of family 0 are the double's: the driver gets its own count.
                let driver = inst
                    .fns
                    .get_physical_device_queue_family_properties(physical)
                    .first()
                    .map_or(0, |f| f.queue_count);
                let cut = queues::cut(ci, driver);
                if let Some(c) = &cut {
                    copy.p_queue_create_infos = c.as_ptr();
                }
                let r = create(physical, &copy, alloc, out);
                if r != vk::Result::SUCCESS {
                    return r;
                }
                let handle = *out;
                if cut.is_some() {
                    queues::device_created(key(handle.as_raw()), driver);
                }
                // A core command the device's version lacks (render pass 2 below Vulkan 1.2,
                // say) falls back to its KHR alias, which an application (or fovea) enables.
                let fns = ash::Device::load_with(
                    |n| {
                        let f = gdpa(handle, n.as_ptr()).or_else(|| {
                            let mut khr = n.to_bytes().to_vec();
                            khr.extend_from_slice(b"KHR\0");
                            gdpa(handle, khr.as_ptr() as *const c_char)
                        });
                        std::mem::transmute(f)
                    },
                    handle,
                );
                lock(&DEVICES).insert(
                    key(handle.as_raw()),
                    Arc::new(DeviceData {
                        handle,
                        physical,
                        instance: inst,
                        gdpa,
                        fns,
                        set_loader_data,
                        null_commands: std::env::var_os(crate::NULL_COMMANDS_ENV).is_some(),
                        attachment_feature,
                        state: Mutex::new(DeviceState::default()),
                    }),
                );
                r
            }
        },
    )
}

unsafe extern "system" fn destroy_device(
    device: vk::Device,
    alloc: *const vk::AllocationCallbacks<'_>,
) {
    guard("vkDestroyDevice", (), || {
        if device == vk::Device::null() {
            return;
        }
        // SAFETY: a live device made through us; the pools are ours.
        unsafe {
            let k = key(device.as_raw());
            if let Some(d) = lock(&DEVICES).get(&k).cloned() {
                queues::catch_up(&d);
            }
            queues::device_destroyed(k);
            let data = lock(&DEVICES).remove(&k);
            if let Some(d) = data {
                for (_, pool) in std::mem::take(&mut lock(&d.state).pools) {
                    d.fns.destroy_command_pool(pool, None);
                }
                for (_, r) in std::mem::take(&mut lock(&d.state).recordings) {
                    drop_recording(&d, r);
                }
                (d.fns.fp_v1_0().destroy_device)(device, alloc);
            }
        }
        write_records();
    })
}

// ---------------------------------------------------------------------------------------------
// Physical-device queries.

unsafe extern "system" fn enumerate_device_extension_properties(
    physical: vk::PhysicalDevice,
    layer: *const c_char,
    count: *mut u32,
    out: *mut vk::ExtensionProperties,
) -> vk::Result {
    guard(
        "vkEnumerateDeviceExtensionProperties",
        vk::Result::ERROR_UNKNOWN,
        || {
            // SAFETY: the caller's arguments, forwarded or filled per the two-call idiom.
            unsafe {
                let inst = instance_of(physical.as_raw()).expect("instance");
                let next = inst.fns.fp_v1_0().enumerate_device_extension_properties;
                let fsr = vk::ExtensionProperties {
                    spec_version: 2,
                    ..Default::default()
                }
                .extension_name(FSR_EXT)
                .expect("a short name");
                let none = vk::ExtensionProperties {
                    spec_version: 1,
                    ..Default::default()
                }
                .extension_name(LOAD_STORE_NONE_EXT)
                .expect("a short name");
                if !layer.is_null() {
                    if CStr::from_ptr(layer) == crate::LAYER_NAME {
                        return two_call(&[fsr, none], count, out);
                    }
                    return next(physical, layer, count, out);
                }
                let mut n = 0;
                let r = next(physical, layer, &mut n, std::ptr::null_mut());
                if r != vk::Result::SUCCESS {
                    return r;
                }
                let mut all = vec![vk::ExtensionProperties::default(); n as usize];
                let r = next(physical, layer, &mut n, all.as_mut_ptr());
                if r != vk::Result::SUCCESS {
                    return r;
                }
                all.truncate(n as usize);
                if !all
                    .iter()
                    .any(|e| e.extension_name_as_c_str() == Ok(FSR_EXT))
                {
                    all.push(fsr);
                }
                if !all
                    .iter()
                    .any(|e| e.extension_name_as_c_str() == Ok(LOAD_STORE_NONE_EXT))
                {
                    all.push(none);
                }
                two_call(&all, count, out)
            }
        },
    )
}

unsafe extern "system" fn get_features2(
    physical: vk::PhysicalDevice,
    out: *mut vk::PhysicalDeviceFeatures2<'_>,
) {
    guard("vkGetPhysicalDeviceFeatures2", (), || {
        // SAFETY: the caller's output chain, which a query may fill.
        unsafe {
            let inst = instance_of(physical.as_raw()).expect("instance");
            (inst.fns.fp_v1_1().get_physical_device_features2)(physical, out);
            if let Some(f) = chain::find_raw(
                (*out).p_next,
                vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_SHADING_RATE_FEATURES_KHR,
            ) {
                let f = &mut *(f as *mut vk::PhysicalDeviceFragmentShadingRateFeaturesKHR<'_>);
                f.pipeline_fragment_shading_rate = vk::TRUE;
                f.primitive_fragment_shading_rate = vk::FALSE;
                f.attachment_fragment_shading_rate = vk::TRUE;
            }
        }
    })
}

unsafe extern "system" fn get_properties2(
    physical: vk::PhysicalDevice,
    out: *mut vk::PhysicalDeviceProperties2<'_>,
) {
    guard("vkGetPhysicalDeviceProperties2", (), || {
        // SAFETY: the caller's output chain, which a query may fill.
        unsafe {
            let inst = instance_of(physical.as_raw()).expect("instance");
            (inst.fns.fp_v1_1().get_physical_device_properties2)(physical, out);
            if let Some(p) = chain::find_raw(
                (*out).p_next,
                vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_SHADING_RATE_PROPERTIES_KHR,
            ) {
                let p = &mut *(p as *mut vk::PhysicalDeviceFragmentShadingRatePropertiesKHR<'_>);
                inst.profile.fill_properties(p);
                if std::env::var_os(crate::TRIVIAL_COMBINERS_ENV).is_some() {
                    p.fragment_shading_rate_non_trivial_combiner_ops = vk::FALSE;
                }
            }
        }
    })
}

unsafe extern "system" fn get_fragment_shading_rates(
    physical: vk::PhysicalDevice,
    count: *mut u32,
    out: *mut vk::PhysicalDeviceFragmentShadingRateKHR<'_>,
) -> vk::Result {
    guard(
        "vkGetPhysicalDeviceFragmentShadingRatesKHR",
        vk::Result::ERROR_UNKNOWN,
        || {
            // SAFETY: the caller's output array per the two-call idiom; each element's sType and
            // pNext are the caller's and stay.
            unsafe {
                let inst = instance_of(physical.as_raw()).expect("instance");
                let rates = inst.profile.rates();
                if out.is_null() {
                    *count = rates.len() as u32;
                    return vk::Result::SUCCESS;
                }
                let n = (*count as usize).min(rates.len());
                for (i, (size, samples)) in rates.iter().take(n).enumerate() {
                    let o = &mut *out.add(i);
                    o.fragment_size = *size;
                    o.sample_counts = *samples;
                }
                *count = n as u32;
                if n < rates.len() {
                    vk::Result::INCOMPLETE
                } else {
                    vk::Result::SUCCESS
                }
            }
        },
    )
}

/// Only R8_UINT gets the attachment bit: the spec makes it the one mandatory shading-rate format
/// (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkFormatFeatureFlagBits.html>).
const FSR_FORMAT: vk::Format = vk::Format::R8_UINT;

unsafe extern "system" fn get_format_properties(
    physical: vk::PhysicalDevice,
    format: vk::Format,
    out: *mut vk::FormatProperties,
) {
    guard("vkGetPhysicalDeviceFormatProperties", (), || {
        // SAFETY: the caller's output struct.
        unsafe {
            let inst = instance_of(physical.as_raw()).expect("instance");
            (inst.fns.fp_v1_0().get_physical_device_format_properties)(physical, format, out);
            if format == FSR_FORMAT {
                (*out).optimal_tiling_features |=
                    vk::FormatFeatureFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR;
            }
        }
    })
}

unsafe extern "system" fn get_format_properties2(
    physical: vk::PhysicalDevice,
    format: vk::Format,
    out: *mut vk::FormatProperties2<'_>,
) {
    guard("vkGetPhysicalDeviceFormatProperties2", (), || {
        // SAFETY: the caller's output chain.
        unsafe {
            let inst = instance_of(physical.as_raw()).expect("instance");
            (inst.fns.fp_v1_1().get_physical_device_format_properties2)(physical, format, out);
            if format == FSR_FORMAT {
                (*out).format_properties.optimal_tiling_features |=
                    vk::FormatFeatureFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR;
                if let Some(p3) =
                    chain::find_raw((*out).p_next, vk::StructureType::FORMAT_PROPERTIES_3)
                {
                    let p3 = &mut *(p3 as *mut vk::FormatProperties3<'_>);
                    p3.optimal_tiling_features |=
                        vk::FormatFeatureFlags2::FRAGMENT_SHADING_RATE_ATTACHMENT_KHR;
                }
            }
        }
    })
}

/// Whether a shading-rate image of this shape exists on the impersonated device: R8_UINT, 2D,
/// optimal tiling (VUID-VkImageCreateInfo-imageType-02082 and the format feature).
fn fsr_image_possible(format: vk::Format, ty: vk::ImageType, tiling: vk::ImageTiling) -> bool {
    format == FSR_FORMAT && ty == vk::ImageType::TYPE_2D && tiling == vk::ImageTiling::OPTIMAL
}

/// The usage lavapipe is asked about instead: without the shading-rate bit, never empty.
fn lavapipe_usage(usage: vk::ImageUsageFlags) -> vk::ImageUsageFlags {
    let rest = usage & !FSR_USAGE;
    if rest.is_empty() {
        vk::ImageUsageFlags::SAMPLED | vk::ImageUsageFlags::TRANSFER_DST
    } else {
        rest
    }
}

unsafe extern "system" fn get_image_format_properties(
    physical: vk::PhysicalDevice,
    format: vk::Format,
    ty: vk::ImageType,
    tiling: vk::ImageTiling,
    usage: vk::ImageUsageFlags,
    flags: vk::ImageCreateFlags,
    out: *mut vk::ImageFormatProperties,
) -> vk::Result {
    guard(
        "vkGetPhysicalDeviceImageFormatProperties",
        vk::Result::ERROR_UNKNOWN,
        || {
            // SAFETY: the caller's output struct.
            unsafe {
                let inst = instance_of(physical.as_raw()).expect("instance");
                let next = inst
                    .fns
                    .fp_v1_0()
                    .get_physical_device_image_format_properties;
                if !usage.contains(FSR_USAGE) {
                    return next(physical, format, ty, tiling, usage, flags, out);
                }
                if !fsr_image_possible(format, ty, tiling) {
                    return vk::Result::ERROR_FORMAT_NOT_SUPPORTED;
                }
                let r = next(
                    physical,
                    format,
                    ty,
                    tiling,
                    lavapipe_usage(usage),
                    flags,
                    out,
                );
                if r == vk::Result::SUCCESS {
                    (*out).sample_counts = vk::SampleCountFlags::TYPE_1;
                }
                r
            }
        },
    )
}

unsafe extern "system" fn get_image_format_properties2(
    physical: vk::PhysicalDevice,
    info: *const vk::PhysicalDeviceImageFormatInfo2<'_>,
    out: *mut vk::ImageFormatProperties2<'_>,
) -> vk::Result {
    guard(
        "vkGetPhysicalDeviceImageFormatProperties2",
        vk::Result::ERROR_UNKNOWN,
        || {
            // SAFETY: the caller's input is read (its rewrite is a local copy), its output filled.
            unsafe {
                let inst = instance_of(physical.as_raw()).expect("instance");
                let next = inst
                    .fns
                    .fp_v1_1()
                    .get_physical_device_image_format_properties2;
                let i = &*info;
                if !i.usage.contains(FSR_USAGE) {
                    return next(physical, info, out);
                }
                if !fsr_image_possible(i.format, i.ty, i.tiling) {
                    return vk::Result::ERROR_FORMAT_NOT_SUPPORTED;
                }
                let mut copy = *i;
                copy.usage = lavapipe_usage(i.usage);
                let r = next(physical, &copy, out);
                if r == vk::Result::SUCCESS {
                    (*out).image_format_properties.sample_counts = vk::SampleCountFlags::TYPE_1;
                }
                r
            }
        },
    )
}

unsafe extern "system" fn get_queue_family_properties(
    physical: vk::PhysicalDevice,
    n: *mut u32,
    out: *mut vk::QueueFamilyProperties,
) {
    guard("vkGetPhysicalDeviceQueueFamilyProperties", (), || {
        // SAFETY: the caller's arguments, forwarded; the output the driver filled is adjusted.
        unsafe {
            let inst = instance_of(physical.as_raw()).expect("instance");
            (inst
                .fns
                .fp_v1_0()
                .get_physical_device_queue_family_properties)(physical, n, out);
            if !n.is_null() {
                queues::fix_counts(out, *n);
            }
        }
    })
}

unsafe extern "system" fn get_queue_family_properties2(
    physical: vk::PhysicalDevice,
    n: *mut u32,
    out: *mut vk::QueueFamilyProperties2<'_>,
) {
    guard("vkGetPhysicalDeviceQueueFamilyProperties2", (), || {
        // SAFETY: as above.
        unsafe {
            let inst = instance_of(physical.as_raw()).expect("instance");
            (inst
                .fns
                .fp_v1_1()
                .get_physical_device_queue_family_properties2)(physical, n, out);
            if !n.is_null() && *n > 0 && !out.is_null() {
                queues::fix_counts(&mut (*out).queue_family_properties, 1);
            }
        }
    })
}

// ---------------------------------------------------------------------------------------------
// Device commands.

unsafe extern "system" fn device_wait_idle(device: vk::Device) -> vk::Result {
    guard("vkDeviceWaitIdle", vk::Result::ERROR_UNKNOWN, || {
        // SAFETY: the caller's argument, forwarded after the extra queues' deferred work.
        unsafe {
            let d = device_of(device.as_raw());
            queues::catch_up(&d);
            let _shared = queues::device_serial(&d);
            (d.fns.fp_v1_0().device_wait_idle)(device)
        }
    })
}

unsafe extern "system" fn get_fence_status(device: vk::Device, fence: vk::Fence) -> vk::Result {
    guard("vkGetFenceStatus", vk::Result::ERROR_UNKNOWN, || {
        // SAFETY: as above.
        unsafe {
            let d = device_of(device.as_raw());
            queues::catch_up(&d);
            (d.fns.fp_v1_0().get_fence_status)(device, fence)
        }
    })
}

unsafe extern "system" fn wait_semaphores(
    device: vk::Device,
    info: *const vk::SemaphoreWaitInfo<'_>,
    timeout: u64,
) -> vk::Result {
    guard("vkWaitSemaphores", vk::Result::ERROR_UNKNOWN, || {
        // SAFETY: as above.
        unsafe {
            let d = device_of(device.as_raw());
            queues::catch_up(&d);
            (d.fns.fp_v1_2().wait_semaphores)(device, info, timeout)
        }
    })
}

unsafe extern "system" fn get_semaphore_counter_value(
    device: vk::Device,
    semaphore: vk::Semaphore,
    out: *mut u64,
) -> vk::Result {
    guard(
        "vkGetSemaphoreCounterValue",
        vk::Result::ERROR_UNKNOWN,
        || {
            // SAFETY: as above.
            unsafe {
                let d = device_of(device.as_raw());
                queues::catch_up(&d);
                (d.fns.fp_v1_2().get_semaphore_counter_value)(device, semaphore, out)
            }
        },
    )
}

unsafe extern "system" fn queue_bind_sparse(
    queue: vk::Queue,
    count: u32,
    info: *const vk::BindSparseInfo<'_>,
    fence: vk::Fence,
) -> vk::Result {
    guard("vkQueueBindSparse", vk::Result::ERROR_UNKNOWN, || {
        // SAFETY: the caller's arguments, forwarded (an extra queue as the driver's).
        unsafe {
            let d = device_of(queue.as_raw());
            queues::catch_up(&d);
            let _shared = queue.serial();
            (d.fns.fp_v1_0().queue_bind_sparse)(queue.down(), count, info, fence)
        }
    })
}

unsafe extern "system" fn get_device_queue(
    device: vk::Device,
    family: u32,
    index: u32,
    out: *mut vk::Queue,
) {
    guard("vkGetDeviceQueue", (), || {
        // SAFETY: the caller's arguments, forwarded.
        unsafe {
            let d = device_of(device.as_raw());
            let k = key(device.as_raw());
            match queues::driver_count(k) {
                Some(driver) if family == 0 && index >= driver => {
                    let mut real = vk::Queue::null();
                    (d.fns.fp_v1_0().get_device_queue)(device, 0, 0, &mut real);
                    lock(&d.state).queues.insert(real.as_raw(), 0);
                    *out = queues::extra(k, k, index + 1 - driver, real);
                }
                _ => (d.fns.fp_v1_0().get_device_queue)(device, family, index, out),
            }
            lock(&d.state).queues.insert((*out).as_raw(), family);
        }
    })
}

unsafe extern "system" fn get_device_queue2(
    device: vk::Device,
    info: *const vk::DeviceQueueInfo2<'_>,
    out: *mut vk::Queue,
) {
    guard("vkGetDeviceQueue2", (), || {
        // SAFETY: the caller's arguments, forwarded.
        unsafe {
            let d = device_of(device.as_raw());
            let i = &*info;
            if i.flags.is_empty()
                && i.queue_family_index == 0
                && queues::driver_count(key(device.as_raw())).is_some_and(|n| i.queue_index >= n)
            {
                get_device_queue(device, 0, i.queue_index, out);
                return;
            }
            (d.fns.fp_v1_1().get_device_queue2)(device, info, out);
            if !(*out).is_null() {
                lock(&d.state)
                    .queues
                    .insert((*out).as_raw(), (*info).queue_family_index);
            }
        }
    })
}

macro_rules! forgetting_destroy {
    ($f:ident, $name:literal, $kind:literal, $handle:ty, $next:ident, $($map:ident),+) => {
        /// Forgets the object before the driver frees it: drivers reuse addresses as handles, so a
        /// stale entry would make a later, unrelated object look like a shading-rate one. Its
        /// definition record may go once it is old ([`record::destroyed`]); the call is counted
        /// ([`record::count`]).
        unsafe extern "system" fn $f(
            device: vk::Device,
            handle: $handle,
            alloc: *const vk::AllocationCallbacks<'_>,
        ) {
            guard($name, (), || {
                record::count($name);
                if handle.as_raw() != 0 {
                    record::destroyed($kind, handle.as_raw());
                }
                // SAFETY: the caller's arguments, forwarded unchanged.
                unsafe {
                    let d = device_of(device.as_raw());
                    {
                        let mut st = lock(&d.state);
                        $(st.$map.remove(&handle.as_raw());)+
                    }
                    (d.fns.fp_v1_0().$next)(device, handle, alloc);
                }
            })
        }
    };
}

forgetting_destroy!(
    destroy_image,
    "vkDestroyImage",
    "image",
    vk::Image,
    destroy_image,
    images,
    colour_images
);
forgetting_destroy!(
    destroy_image_view,
    "vkDestroyImageView",
    "image_view",
    vk::ImageView,
    destroy_image_view,
    views,
    colour_views
);
forgetting_destroy!(
    destroy_render_pass,
    "vkDestroyRenderPass",
    "render_pass",
    vk::RenderPass,
    destroy_render_pass,
    passes
);
forgetting_destroy!(
    destroy_pipeline,
    "vkDestroyPipeline",
    "pipeline",
    vk::Pipeline,
    destroy_pipeline,
    pipelines
);
forgetting_destroy!(
    destroy_framebuffer,
    "vkDestroyFramebuffer",
    "framebuffer",
    vk::Framebuffer,
    destroy_framebuffer,
    framebuffers
);

unsafe extern "system" fn create_image(
    device: vk::Device,
    info: *const vk::ImageCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Image,
) -> vk::Result {
    guard("vkCreateImage", vk::Result::ERROR_UNKNOWN, || {
        if let Some(r) = record::fault("vkCreateImage") {
            return r;
        }
        // SAFETY: the caller's create info is read; lavapipe gets a copy.
        unsafe {
            let d = device_of(device.as_raw());
            let ci = &*info;
            let next = d.fns.fp_v1_0().create_image;
            crate::strict::chain("vkCreateImage", ci.p_next);
            crate::strict::usage("vkCreateImage", ci.usage);
            crate::strict::flag(
                "vkCreateImage",
                ci.flags.intersects(
                    vk::ImageCreateFlags::SUBSAMPLED_EXT
                        | vk::ImageCreateFlags::FRAGMENT_DENSITY_MAP_OFFSET_QCOM,
                ),
                "a subsampled or density-map-offset image",
            );
            crate::strict::layout("vkCreateImage", ci.initial_layout);
            if !ci.usage.contains(FSR_USAGE) {
                if !ci.usage.contains(vk::ImageUsageFlags::COLOR_ATTACHMENT) {
                    return next(device, info, alloc, out);
                }
                // The double draws coarse fragments into colour attachments
                // ([`coarsen`]): it copies them out and back.
                let mut copy = *ci;
                copy.usage |= vk::ImageUsageFlags::TRANSFER_SRC | vk::ImageUsageFlags::TRANSFER_DST;
                let r = next(device, &copy, alloc, out);
                if r == vk::Result::SUCCESS
                    && ci.image_type == vk::ImageType::TYPE_2D
                    && ci.samples == vk::SampleCountFlags::TYPE_1
                {
                    lock(&d.state).colour_images.insert(
                        (*out).as_raw(),
                        ColourTarget {
                            image: (*out).as_raw(),
                            base_layer: 0,
                            format: ci.format,
                            extent: vk::Extent2D {
                                width: ci.extent.width,
                                height: ci.extent.height,
                            },
                        },
                    );
                }
                return r;
            }
            if !d.attachment_feature {
                error(
                    "vkCreateImage: shading-rate usage without the attachmentFragmentShadingRate \
                     feature"
                        .into(),
                );
            }
            if !fsr_image_possible(ci.format, ci.image_type, ci.tiling) {
                error(format!(
                    "vkCreateImage: shading-rate usage on {:?} {:?} {:?} (only R8_UINT 2D optimal)",
                    ci.format, ci.image_type, ci.tiling
                ));
            }
            if ci.samples != vk::SampleCountFlags::TYPE_1 {
                error(format!(
                    "vkCreateImage: shading-rate usage with {:?} samples",
                    ci.samples
                ));
            }
            let mut copy = *ci;
            // TRANSFER_SRC lets the double copy the rates a pass reads; TRANSFER_DST lets it poison
            // an attachment a pass left undefined.
            copy.usage = lavapipe_usage(ci.usage)
                | vk::ImageUsageFlags::TRANSFER_SRC
                | vk::ImageUsageFlags::TRANSFER_DST;
            let r = next(device, &copy, alloc, out);
            if r == vk::Result::SUCCESS {
                let image = (*out).as_raw();
                lock(&d.state).images.insert(
                    image,
                    ImageInfo {
                        extent: ci.extent,
                        layers: ci.array_layers,
                    },
                );
                event(json!({
                    "kind": "image",
                    "image": image,
                    "format": ci.format.as_raw(),
                    "extent": [ci.extent.width, ci.extent.height],
                    "layers": ci.array_layers,
                }));
            }
            r
        }
    })
}

unsafe extern "system" fn create_image_view(
    device: vk::Device,
    info: *const vk::ImageViewCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::ImageView,
) -> vk::Result {
    guard("vkCreateImageView", vk::Result::ERROR_UNKNOWN, || {
        if let Some(r) = record::fault("vkCreateImageView") {
            return r;
        }
        // SAFETY: the caller's arguments, forwarded unchanged.
        unsafe {
            let d = device_of(device.as_raw());
            let ci = &*info;
            crate::strict::chain("vkCreateImageView", ci.p_next);
            crate::strict::flag(
                "vkCreateImageView",
                ci.flags.intersects(
                    vk::ImageViewCreateFlags::FRAGMENT_DENSITY_MAP_DYNAMIC_EXT
                        | vk::ImageViewCreateFlags::FRAGMENT_DENSITY_MAP_DEFERRED_EXT,
                ),
                "a dynamic or deferred density-map view",
            );
            let r = (d.fns.fp_v1_0().create_image_view)(device, info, alloc, out);
            let image = ci.image.as_raw();
            if r == vk::Result::SUCCESS {
                let mut st = lock(&d.state);
                if let Some(c) = st.colour_images.get(&image).copied() {
                    st.colour_views.insert(
                        (*out).as_raw(),
                        ColourTarget {
                            base_layer: ci.subresource_range.base_array_layer,
                            ..c
                        },
                    );
                }
            }
            if r == vk::Result::SUCCESS && lock(&d.state).images.contains_key(&image) {
                let layers = ci.subresource_range.layer_count;
                if layers != 1 && !d.instance.profile.layered() {
                    error(format!(
                        "vkCreateImageView: {layers} layers of a shading-rate image, but \
                         layeredShadingRateAttachments is FALSE"
                    ));
                }
                lock(&d.state).views.insert(
                    (*out).as_raw(),
                    ViewInfo {
                        image,
                        base_layer: ci.subresource_range.base_array_layer,
                        layers,
                    },
                );
                event(json!({
                    "kind": "image_view",
                    "view": (*out).as_raw(),
                    "image": image,
                    "base_layer": ci.subresource_range.base_array_layer,
                    "layers": layers,
                }));
            }
            r
        }
    })
}

unsafe extern "system" fn create_render_pass2(
    device: vk::Device,
    info: *const vk::RenderPassCreateInfo2<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::RenderPass,
) -> vk::Result {
    guard("vkCreateRenderPass2", vk::Result::ERROR_UNKNOWN, || {
        if let Some(r) = record::fault("vkCreateRenderPass2") {
            return r;
        }
        // SAFETY: the caller's create info is read; lavapipe gets copies that live across the
        // call.
        unsafe {
            let d = device_of(device.as_raw());
            let profile = d.instance.profile;
            let ci = &*info;
            check_render_pass2(&d, ci);
            let attachments_in = slice(ci.p_attachments, ci.attachment_count);
            let attachments: Vec<vk::AttachmentDescription2<'_>> = attachments_in
                .iter()
                .map(|a| {
                    let mut a = *a;
                    a.initial_layout = fix_layout(a.initial_layout);
                    a.final_layout = fix_layout(a.final_layout);
                    a.load_op = fix_load(a.load_op);
                    a.stencil_load_op = fix_load(a.stencil_load_op);
                    a
                })
                .collect();
            let mut refs: Vec<Vec<vk::AttachmentReference2<'_>>> = Vec::new();
            let mut chains = Vec::new();
            let mut subpasses = Vec::new();
            let mut per_subpass = Vec::new();
            let mut record_subpasses = Vec::new();
            for (i, s) in slice(ci.p_subpasses, ci.subpass_count).iter().enumerate() {
                let mut c = *s;
                let mut fsr = None;
                if let Some(f) = find::<vk::FragmentShadingRateAttachmentInfoKHR>(s.p_next) {
                    let f = &*f;
                    let texel = f.shading_rate_attachment_texel_size;
                    if let Some(r) = f.p_fragment_shading_rate_attachment.as_ref() {
                        if r.attachment != vk::ATTACHMENT_UNUSED {
                            fsr = Some((r.attachment, r.layout, texel));
                        }
                    }
                }
                match fsr {
                    Some((a, layout, texel)) => {
                        check_pass_attachment(profile, i, a, layout, texel, attachments_in);
                        per_subpass.push(SubpassInfo {
                            rate: Some((a, texel)),
                            view_mask: s.view_mask,
                            colors: colors_of(s),
                        });
                        record_subpasses.push(json!({"shading_rate": {
                            "attachment": a,
                            "layout": layout.as_raw(),
                            "texel": pair(texel),
                        }}));
                    }
                    None => {
                        per_subpass.push(SubpassInfo {
                            rate: None,
                            view_mask: s.view_mask,
                            colors: colors_of(s),
                        });
                        record_subpasses.push(json!({"shading_rate": null}));
                    }
                }
                let stripped = match chain::strip(
                    s.p_next,
                    &[vk::StructureType::FRAGMENT_SHADING_RATE_ATTACHMENT_INFO_KHR],
                ) {
                    Ok(st) => st,
                    Err(st) => {
                        error(format!("vkCreateRenderPass2: cannot copy a {st:?}"));
                        return vk::Result::ERROR_UNKNOWN;
                    }
                };
                c.p_next = stripped.head;
                chains.push(stripped);
                c.p_input_attachments =
                    fix_refs(&mut refs, s.p_input_attachments, s.input_attachment_count);
                c.p_color_attachments =
                    fix_refs(&mut refs, s.p_color_attachments, s.color_attachment_count);
                c.p_resolve_attachments =
                    fix_refs(&mut refs, s.p_resolve_attachments, s.color_attachment_count);
                c.p_depth_stencil_attachment = fix_refs(&mut refs, s.p_depth_stencil_attachment, 1);
                subpasses.push(c);
            }
            let dependencies: Vec<vk::SubpassDependency2<'_>> =
                slice(ci.p_dependencies, ci.dependency_count)
                    .iter()
                    .map(|dep| {
                        let mut dep = *dep;
                        dep.src_stage_mask = fix_stage(dep.src_stage_mask);
                        dep.dst_stage_mask = fix_stage(dep.dst_stage_mask);
                        dep.src_access_mask = fix_access(dep.src_access_mask);
                        dep.dst_access_mask = fix_access(dep.dst_access_mask);
                        dep
                    })
                    .collect();
            let mut copy = *ci;
            copy.p_attachments = attachments.as_ptr();
            copy.p_subpasses = subpasses.as_ptr();
            copy.p_dependencies = dependencies.as_ptr();
            let r = (d.fns.fp_v1_2().create_render_pass2)(device, &copy, alloc, out);
            if r == vk::Result::SUCCESS {
                let pass = (*out).as_raw();
                lock(&d.state).passes.insert(
                    pass,
                    PassInfo {
                        subpasses: per_subpass,
                        ops: attachments_in
                            .iter()
                            .map(|a| (a.load_op, a.store_op))
                            .collect(),
                    },
                );
                event(json!({
                    "kind": "render_pass",
                    "render_pass": pass,
                    "attachments": attachments_in.iter().map(|a| json!({
                        "format": a.format.as_raw(),
                        "load_op": a.load_op.as_raw(),
                        "samples": a.samples.as_raw(),
                    })).collect::<Vec<_>>(),
                    "subpasses": record_subpasses,
                }));
            }
            r
        }
    })
}

/// Copies `n` attachment references into `refs` with the shading-rate layout made GENERAL; null
/// stays null.
///
/// # Safety
/// `p` must be null or valid for `n` elements.
unsafe fn fix_refs<'a>(
    refs: &mut Vec<Vec<vk::AttachmentReference2<'a>>>,
    p: *const vk::AttachmentReference2<'a>,
    n: u32,
) -> *const vk::AttachmentReference2<'a> {
    if p.is_null() {
        return p;
    }
    // SAFETY: the caller's promise.
    let v: Vec<_> = unsafe { slice(p, n) }
        .iter()
        .map(|r| {
            let mut r = *r;
            r.layout = fix_layout(r.layout);
            r
        })
        .collect();
    let ptr = v.as_ptr();
    refs.push(v);
    ptr
}

/// What a driver with shading-rate attachments refuses in a subpass's attachment: a texel size the
/// device does not have (VUID-VkFragmentShadingRateAttachmentInfoKHR-pFragmentShadingRateAttachment-04525..04532),
/// a format without the feature (VUID-VkRenderPassCreateInfo2-pAttachments-04586), a cleared load
/// (VUID-VkRenderPassCreateInfo2-pAttachments-09387), more than one sample, a wrong layout (04524).
fn check_pass_attachment(
    profile: Profile,
    subpass: usize,
    index: u32,
    layout: vk::ImageLayout,
    texel: vk::Extent2D,
    attachments: &[vk::AttachmentDescription2<'_>],
) {
    let t = profile.texel();
    if texel != t {
        error(format!(
            "vkCreateRenderPass2: subpass {subpass}: shading-rate texel {}x{} is not the device's {}x{}",
            texel.width, texel.height, t.width, t.height
        ));
    }
    if layout != FSR_LAYOUT && layout != vk::ImageLayout::GENERAL {
        error(format!(
            "vkCreateRenderPass2: subpass {subpass}: shading-rate attachment layout {layout:?}"
        ));
    }
    let Some(a) = attachments.get(index as usize) else {
        error(format!(
            "vkCreateRenderPass2: subpass {subpass}: shading-rate attachment {index} does not exist"
        ));
        return;
    };
    if a.format != FSR_FORMAT {
        error(format!(
            "vkCreateRenderPass2: attachment {index}: shading-rate attachment format {:?}",
            a.format
        ));
    }
    if a.load_op == vk::AttachmentLoadOp::CLEAR {
        error(format!(
            "vkCreateRenderPass2: attachment {index}: shading-rate attachment with loadOp CLEAR"
        ));
    }
    if a.samples != vk::SampleCountFlags::TYPE_1 {
        error(format!(
            "vkCreateRenderPass2: attachment {index}: shading-rate attachment with {:?} samples",
            a.samples
        ));
    }
}

/// Whether the attachment's image covers `extent` at `texel` per texel
/// (VUID-VkFramebufferCreateInfo-flags-04539/04540, VUID-VkRenderingInfo-pNext-06119/06121).
fn check_covers(what: &str, image: ImageInfo, extent: vk::Extent2D, texel: vk::Extent2D) {
    let need_w = extent.width.div_ceil(texel.width.max(1));
    let need_h = extent.height.div_ceil(texel.height.max(1));
    if image.extent.width < need_w || image.extent.height < need_h {
        error(format!(
            "{what}: shading-rate image {}x{} does not cover {}x{} at {}x{} texels",
            image.extent.width,
            image.extent.height,
            extent.width,
            extent.height,
            texel.width,
            texel.height
        ));
    }
}

unsafe extern "system" fn create_framebuffer(
    device: vk::Device,
    info: *const vk::FramebufferCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Framebuffer,
) -> vk::Result {
    guard("vkCreateFramebuffer", vk::Result::ERROR_UNKNOWN, || {
        if let Some(r) = record::fault("vkCreateFramebuffer") {
            return r;
        }
        // SAFETY: the caller's arguments, forwarded unchanged.
        unsafe {
            let d = device_of(device.as_raw());
            let r = (d.fns.fp_v1_0().create_framebuffer)(device, info, alloc, out);
            if r != vk::Result::SUCCESS {
                return r;
            }
            let ci = &*info;
            let views: Vec<u64> = if ci.flags.contains(vk::FramebufferCreateFlags::IMAGELESS) {
                Vec::new()
            } else {
                slice(ci.p_attachments, ci.attachment_count)
                    .iter()
                    .map(|v| v.as_raw())
                    .collect()
            };
            let mut st = lock(&d.state);
            let pass = ci.render_pass.as_raw();
            let extent = vk::Extent2D {
                width: ci.width,
                height: ci.height,
            };
            for (a, texel) in st.passes.get(&pass).into_iter().flat_map(PassInfo::rates) {
                let image = views
                    .get(a as usize)
                    .and_then(|v| st.views.get(v))
                    .and_then(|v| st.images.get(&v.image));
                if let Some(image) = image {
                    check_covers("vkCreateFramebuffer", *image, extent, texel);
                }
            }
            st.framebuffers.insert((*out).as_raw(), views.clone());
            event(json!({
                "kind": "framebuffer",
                "framebuffer": (*out).as_raw(),
                "render_pass": pass,
                "attachments": views,
                "extent": [ci.width, ci.height],
                "layers": ci.layers,
            }));
            r
        }
    })
}

unsafe extern "system" fn create_graphics_pipelines(
    device: vk::Device,
    cache: vk::PipelineCache,
    count: u32,
    infos: *const vk::GraphicsPipelineCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Pipeline,
) -> vk::Result {
    guard(
        "vkCreateGraphicsPipelines",
        vk::Result::ERROR_UNKNOWN,
        || {
            if let Some(r) = record::fault("vkCreateGraphicsPipelines") {
                // SAFETY: `out` has `count` elements.
                unsafe { null_outputs(out, count) };
                return r;
            }
            // SAFETY: the caller's create infos are read; lavapipe gets copies that live across the
            // call; `out` has `count` elements.
            unsafe {
                let d = device_of(device.as_raw());
                let max = d.instance.profile.max_fragment();
                let flag = vk::PipelineCreateFlags::RENDERING_FRAGMENT_SHADING_RATE_ATTACHMENT_KHR;
                let mut copies = Vec::new();
                let mut chains = Vec::new();
                let mut dynamic_lists: Vec<Vec<vk::DynamicState>> = Vec::new();
                let mut dynamic_infos: Vec<Box<vk::PipelineDynamicStateCreateInfo<'_>>> =
                    Vec::new();
                let mut records = Vec::new();
                let mut rates = Vec::new();
                for ci in slice(infos, count) {
                    crate::strict::chain("vkCreateGraphicsPipelines", ci.p_next);
                    crate::strict::flag(
                        "vkCreateGraphicsPipelines",
                        ci.flags.contains(
                            vk::PipelineCreateFlags::RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_EXT,
                        ),
                        "flag RENDERING_FRAGMENT_DENSITY_MAP_ATTACHMENT_EXT",
                    );
                    let mut c = *ci;
                    let state =
                        find::<vk::PipelineFragmentShadingRateStateCreateInfoKHR>(ci.p_next)
                            .map(|s| *s);
                    if let Some(s) = &state {
                        if s.fragment_size.width > max || s.fragment_size.height > max {
                            error(format!(
                            "vkCreateGraphicsPipelines: fragment size {}x{} above the device's {max}x{max}",
                            s.fragment_size.width, s.fragment_size.height
                        ));
                        }
                    }
                    let stripped = match chain::strip(
                        ci.p_next,
                        &[vk::StructureType::PIPELINE_FRAGMENT_SHADING_RATE_STATE_CREATE_INFO_KHR],
                    ) {
                        Ok(s) => s,
                        Err(s) => {
                            error(format!("vkCreateGraphicsPipelines: cannot copy a {s:?}"));
                            return vk::Result::ERROR_UNKNOWN;
                        }
                    };
                    c.p_next = stripped.head;
                    chains.push(stripped);
                    c.flags &= !flag;
                    let mut dynamic_rate = false;
                    if let Some(ds) = ci.p_dynamic_state.as_ref() {
                        let list = slice(ds.p_dynamic_states, ds.dynamic_state_count);
                        dynamic_rate = list.contains(&vk::DynamicState::FRAGMENT_SHADING_RATE_KHR);
                        if dynamic_rate {
                            let kept: Vec<vk::DynamicState> = list
                                .iter()
                                .copied()
                                .filter(|&s| s != vk::DynamicState::FRAGMENT_SHADING_RATE_KHR)
                                .collect();
                            let mut dc = Box::new(*ds);
                            dc.dynamic_state_count = kept.len() as u32;
                            dc.p_dynamic_states = kept.as_ptr();
                            c.p_dynamic_state = &*dc;
                            dynamic_lists.push(kept);
                            dynamic_infos.push(dc);
                        }
                    }
                    rates.push((
                        state.map_or(PipelineRate::NONE, |s| PipelineRate {
                            size: [s.fragment_size.width, s.fragment_size.height],
                            ops: s.combiner_ops,
                        }),
                        dynamic_rate,
                    ));
                    records.push(json!({
                    "kind": "pipeline",
                    "render_pass": ci.render_pass.as_raw(),
                    "subpass": ci.subpass,
                    "shading_rate_state": state.map(|s| json!({
                        "fragment_size": pair(s.fragment_size),
                        "combiner_ops": [s.combiner_ops[0].as_raw(), s.combiner_ops[1].as_raw()],
                    })),
                    "rendering_attachment_flag": ci.flags.contains(flag),
                    "dynamic_rate": dynamic_rate,
                }));
                    copies.push(c);
                }
                let r = (d.fns.fp_v1_0().create_graphics_pipelines)(
                    device,
                    cache,
                    count,
                    copies.as_ptr(),
                    alloc,
                    out,
                );
                for (i, mut rec) in records.into_iter().enumerate() {
                    let p = *out.add(i);
                    if p != vk::Pipeline::null() {
                        lock(&d.state).pipelines.insert(p.as_raw(), rates[i]);
                        rec["pipeline"] = json!(p.as_raw());
                        event(rec);
                    }
                }
                r
            }
        },
    )
}

unsafe extern "system" fn begin_command_buffer(
    cb: vk::CommandBuffer,
    info: *const vk::CommandBufferBeginInfo<'_>,
) -> vk::Result {
    guard("vkBeginCommandBuffer", vk::Result::ERROR_UNKNOWN, || {
        if let Some(r) = record::fault("vkBeginCommandBuffer") {
            return r;
        }
        // SAFETY: the caller's arguments, forwarded unchanged.
        unsafe {
            let d = device_of(cb.as_raw());
            let old = {
                let mut st = lock(&d.state);
                st.commands.insert(cb.as_raw(), Vec::new());
                st.recordings.remove(&cb.as_raw())
            };
            if let Some(old) = old {
                // The application waited for the command buffer before recording it anew.
                drop_recording(&d, old);
            }
            (d.fns.fp_v1_0().begin_command_buffer)(cb, info)
        }
    })
}

/// Records a render-pass begin and notes the shading-rate images its subpasses read.
///
/// # Safety
/// `info` must be a valid begin info.
unsafe fn note_begin_render_pass(
    d: &DeviceData,
    cb: vk::CommandBuffer,
    info: &vk::RenderPassBeginInfo<'_>,
) -> PassRec {
    let mut st = lock(&d.state);
    let pass = info.render_pass.as_raw();
    let fb = info.framebuffer.as_raw();
    // Imageless framebuffers name their views at begin.
    // SAFETY: the begin info's chain is valid (the caller's promise).
    let views: Vec<u64> = match unsafe { find::<vk::RenderPassAttachmentBeginInfo>(info.p_next) } {
        // SAFETY: as above.
        Some(b) => unsafe { slice((*b).p_attachments, (*b).attachment_count) }
            .iter()
            .map(|v| v.as_raw())
            .collect(),
        None => st.framebuffers.get(&fb).cloned().unwrap_or_default(),
    };
    let mut used = Vec::new();
    for (a, _) in st.passes.get(&pass).into_iter().flat_map(PassInfo::rates) {
        if let Some(&v) = views.get(a as usize) {
            used.push(v);
        }
    }
    let images: Vec<u64> = used
        .iter()
        .filter_map(|v| st.views.get(v).map(|v| v.image))
        .collect();
    let list = st.commands.entry(cb.as_raw()).or_default();
    for i in images {
        if !list.contains(&i) {
            list.push(i);
        }
    }
    used.dedup();
    event(json!({
        "kind": "begin_render_pass",
        "command_buffer": cb.as_raw(),
        "render_pass": pass,
        "framebuffer": fb,
        "shading_rate_views": used,
    }));
    let a = info.render_area;
    let subpasses = match st.passes.get(&pass) {
        Some(p) => p
            .subpasses
            .iter()
            .map(|s| {
                let attach = s.rate.and_then(|(i, texel)| {
                    let view = *views.get(i as usize)?;
                    let dont_care = p
                        .ops
                        .get(i as usize)
                        .is_some_and(|o| o.1 == vk::AttachmentStoreOp::DONT_CARE);
                    attach_of(&st, view, texel, dont_care)
                });
                (attach, s.view_mask)
            })
            .collect(),
        None => vec![(None, 0)],
    };
    let mut colours: Vec<ColourTarget> = Vec::new();
    for s in st
        .passes
        .get(&pass)
        .map(|p| &p.subpasses[..])
        .unwrap_or(&[])
    {
        for &c in &s.colors {
            let target = views.get(c as usize).and_then(|v| st.colour_views.get(v));
            if let Some(t) = target {
                if !colours
                    .iter()
                    .any(|o| (o.image, o.base_layer) == (t.image, t.base_layer))
                {
                    colours.push(*t);
                }
            }
        }
    }
    PassRec {
        colours,
        suspending: false,
        rendering: false,
        area: vk::Extent2D {
            width: a.offset.x.max(0) as u32 + a.extent.width,
            height: a.offset.y.max(0) as u32 + a.extent.height,
        },
        subpasses,
        draws: Vec::new(),
    }
}

unsafe extern "system" fn cmd_begin_render_pass(
    cb: vk::CommandBuffer,
    info: *const vk::RenderPassBeginInfo<'_>,
    contents: vk::SubpassContents,
) {
    guard("vkCmdBeginRenderPass", (), || {
        // SAFETY: the caller's arguments, forwarded unchanged.
        unsafe {
            let d = device_of(cb.as_raw());
            crate::strict::chain("vkCmdBeginRenderPass", (*info).p_next);
            let pass = note_begin_render_pass(&d, cb, &*info);
            open_pass(&d, cb, pass, false);
            (d.fns.fp_v1_0().cmd_begin_render_pass)(cb, info, contents);
        }
    })
}

unsafe extern "system" fn cmd_begin_render_pass2(
    cb: vk::CommandBuffer,
    info: *const vk::RenderPassBeginInfo<'_>,
    subpass: *const vk::SubpassBeginInfo<'_>,
) {
    guard("vkCmdBeginRenderPass2", (), || {
        // SAFETY: the caller's arguments, forwarded unchanged.
        unsafe {
            let d = device_of(cb.as_raw());
            crate::strict::chain("vkCmdBeginRenderPass2", (*info).p_next);
            let pass = note_begin_render_pass(&d, cb, &*info);
            open_pass(&d, cb, pass, false);
            (d.fns.fp_v1_2().cmd_begin_render_pass2)(cb, info, subpass);
        }
    })
}

unsafe extern "system" fn cmd_begin_rendering(
    cb: vk::CommandBuffer,
    info: *const vk::RenderingInfo<'_>,
) {
    guard("vkCmdBeginRendering", (), || {
        // SAFETY: the caller's rendering info is read; lavapipe gets a copy that lives across
        // the call.
        unsafe {
            let d = device_of(cb.as_raw());
            let ri = &*info;
            let what = "vkCmdBeginRendering";
            crate::strict::chain(what, ri.p_next);
            for a in slice(ri.p_color_attachments, ri.color_attachment_count)
                .iter()
                .chain(ri.p_depth_attachment.as_ref())
                .chain(ri.p_stencil_attachment.as_ref())
            {
                crate::strict::layout(what, a.image_layout);
                crate::strict::layout(what, a.resolve_image_layout);
            }
            let fsr = find::<vk::RenderingFragmentShadingRateAttachmentInfoKHR>(ri.p_next)
                .map(|f| *f)
                .filter(|f| f.image_view != vk::ImageView::null());
            let rec = match &fsr {
                Some(f) => {
                    if !d.attachment_feature {
                        error(format!(
                            "{what}: a shading-rate attachment without the \
                             attachmentFragmentShadingRate feature"
                        ));
                    }
                    let t = d.instance.profile.texel();
                    let texel = f.shading_rate_attachment_texel_size;
                    if texel != t {
                        error(format!(
                            "vkCmdBeginRendering: shading-rate texel {}x{} is not the device's {}x{}",
                            texel.width, texel.height, t.width, t.height
                        ));
                    }
                    if f.image_layout != FSR_LAYOUT && f.image_layout != vk::ImageLayout::GENERAL {
                        error(format!(
                            "vkCmdBeginRendering: shading-rate attachment layout {:?}",
                            f.image_layout
                        ));
                    }
                    let mut st = lock(&d.state);
                    let view = f.image_view.as_raw();
                    let image = st.views.get(&view).map(|v| v.image);
                    if let Some(image) = image {
                        if let Some(info) = st.images.get(&image) {
                            let a = ri.render_area;
                            let extent = vk::Extent2D {
                                width: (a.offset.x.max(0) as u32) + a.extent.width,
                                height: (a.offset.y.max(0) as u32) + a.extent.height,
                            };
                            check_covers("vkCmdBeginRendering", *info, extent, texel);
                        }
                        let list = st.commands.entry(cb.as_raw()).or_default();
                        if !list.contains(&image) {
                            list.push(image);
                        }
                    } else {
                        error("vkCmdBeginRendering: shading-rate view of an image without the shading-rate usage".into());
                    }
                    json!({
                        "view": view,
                        "layout": f.image_layout.as_raw(),
                        "texel": pair(texel),
                    })
                }
                None => Value::Null,
            };
            // How many shading-rate structs the chain holds (one at most is valid).
            let mut structs = 0;
            let mut node = ri.p_next as *const vk::BaseInStructure<'_>;
            while !node.is_null() {
                if (*node).s_type
                    == vk::StructureType::RENDERING_FRAGMENT_SHADING_RATE_ATTACHMENT_INFO_KHR
                {
                    structs += 1;
                }
                node = (*node).p_next;
            }
            event(json!({
                "kind": "begin_rendering",
                "command_buffer": cb.as_raw(),
                "shading_rate": rec,
                "shading_rate_structs": structs,
            }));
            let stripped = match chain::strip(
                ri.p_next,
                &[vk::StructureType::RENDERING_FRAGMENT_SHADING_RATE_ATTACHMENT_INFO_KHR],
            ) {
                Ok(s) => s,
                Err(s) => {
                    error(format!("vkCmdBeginRendering: cannot copy a {s:?}"));
                    return;
                }
            };
            let attach = fsr.and_then(|f| {
                attach_of(
                    &lock(&d.state),
                    f.image_view.as_raw(),
                    f.shading_rate_attachment_texel_size,
                    false,
                )
            });
            let a = ri.render_area;
            let colours: Vec<ColourTarget> = {
                let st = lock(&d.state);
                let attachments = slice(ri.p_color_attachments, ri.color_attachment_count);
                let resolves = attachments
                    .iter()
                    .filter(|c| c.resolve_mode != vk::ResolveModeFlags::NONE)
                    .map(|c| c.resolve_image_view);
                attachments
                    .iter()
                    .map(|c| c.image_view)
                    .chain(resolves)
                    .filter_map(|v| st.colour_views.get(&v.as_raw()).copied())
                    .collect()
            };
            open_pass(
                &d,
                cb,
                PassRec {
                    colours,
                    suspending: ri.flags.contains(vk::RenderingFlags::SUSPENDING),
                    rendering: true,
                    area: vk::Extent2D {
                        width: a.offset.x.max(0) as u32 + a.extent.width,
                        height: a.offset.y.max(0) as u32 + a.extent.height,
                    },
                    subpasses: vec![(attach, ri.view_mask)],
                    draws: Vec::new(),
                },
                ri.flags.contains(vk::RenderingFlags::RESUMING),
            );
            fn fixed<'a>(a: &vk::RenderingAttachmentInfo<'a>) -> vk::RenderingAttachmentInfo<'a> {
                let mut a = *a;
                a.load_op = fix_load(a.load_op);
                a
            }
            let colors: Vec<vk::RenderingAttachmentInfo<'_>> =
                slice(ri.p_color_attachments, ri.color_attachment_count)
                    .iter()
                    .map(fixed)
                    .collect();
            let depth = ri.p_depth_attachment.as_ref().map(fixed);
            let stencil = ri.p_stencil_attachment.as_ref().map(fixed);
            let mut copy = *ri;
            copy.p_next = stripped.head;
            if !ri.p_color_attachments.is_null() {
                copy.p_color_attachments = colors.as_ptr();
            }
            if let Some(a) = &depth {
                copy.p_depth_attachment = a;
            }
            if let Some(a) = &stencil {
                copy.p_stencil_attachment = a;
            }
            (d.fns.fp_v1_3().cmd_begin_rendering)(cb, &copy);
        }
    })
}

#[allow(clippy::too_many_arguments)]
unsafe extern "system" fn cmd_pipeline_barrier(
    cb: vk::CommandBuffer,
    src: vk::PipelineStageFlags,
    dst: vk::PipelineStageFlags,
    flags: vk::DependencyFlags,
    memory_count: u32,
    memory: *const vk::MemoryBarrier<'_>,
    buffer_count: u32,
    buffers: *const vk::BufferMemoryBarrier<'_>,
    image_count: u32,
    images: *const vk::ImageMemoryBarrier<'_>,
) {
    guard("vkCmdPipelineBarrier", (), || {
        // SAFETY: the caller's arrays are read; lavapipe gets copies that live across the call.
        unsafe {
            let d = device_of(cb.as_raw());
            let what = "vkCmdPipelineBarrier";
            crate::strict::stage(what, src.as_raw() as u64);
            crate::strict::stage(what, dst.as_raw() as u64);
            for b in slice(memory, memory_count) {
                crate::strict::access(what, b.src_access_mask.as_raw() as u64);
                crate::strict::access(what, b.dst_access_mask.as_raw() as u64);
            }
            for b in slice(buffers, buffer_count) {
                crate::strict::access(what, b.src_access_mask.as_raw() as u64);
                crate::strict::access(what, b.dst_access_mask.as_raw() as u64);
            }
            for b in slice(images, image_count) {
                crate::strict::access(what, b.src_access_mask.as_raw() as u64);
                crate::strict::access(what, b.dst_access_mask.as_raw() as u64);
                crate::strict::layout(what, b.old_layout);
                crate::strict::layout(what, b.new_layout);
            }
            let m: Vec<_> = slice(memory, memory_count)
                .iter()
                .map(|b| {
                    let mut b = *b;
                    b.src_access_mask = fix_access(b.src_access_mask);
                    b.dst_access_mask = fix_access(b.dst_access_mask);
                    b
                })
                .collect();
            let bu: Vec<_> = slice(buffers, buffer_count)
                .iter()
                .map(|b| {
                    let mut b = *b;
                    b.src_access_mask = fix_access(b.src_access_mask);
                    b.dst_access_mask = fix_access(b.dst_access_mask);
                    b
                })
                .collect();
            let im: Vec<_> = slice(images, image_count)
                .iter()
                .map(|b| {
                    let mut b = *b;
                    b.src_access_mask = fix_access(b.src_access_mask);
                    b.dst_access_mask = fix_access(b.dst_access_mask);
                    b.old_layout = fix_layout(b.old_layout);
                    b.new_layout = fix_layout(b.new_layout);
                    b
                })
                .collect();
            event(json!({
                "kind": "barrier",
                "command_buffer": cb.as_raw(),
                "stages": [src.as_raw(), dst.as_raw()],
                "access": m.iter().map(|b| [b.src_access_mask.as_raw(), b.dst_access_mask.as_raw()])
                    .chain(slice(images, image_count).iter()
                        .map(|b| [b.src_access_mask.as_raw(), b.dst_access_mask.as_raw()]))
                    .collect::<Vec<_>>(),
                "images": slice(images, image_count).iter()
                    .map(|b| json!({"image": b.image.as_raw(), "layouts": [b.old_layout.as_raw(), b.new_layout.as_raw()]}))
                    .collect::<Vec<_>>(),
            }));
            (d.fns.fp_v1_0().cmd_pipeline_barrier)(
                cb,
                fix_stage(src),
                fix_stage(dst),
                flags,
                memory_count,
                m.as_ptr(),
                buffer_count,
                bu.as_ptr(),
                image_count,
                im.as_ptr(),
            );
        }
    })
}

unsafe extern "system" fn cmd_pipeline_barrier2(
    cb: vk::CommandBuffer,
    info: *const vk::DependencyInfo<'_>,
) {
    guard("vkCmdPipelineBarrier2", (), || {
        // SAFETY: the caller's dependency info is read; lavapipe gets copies that live across
        // the call.
        unsafe {
            let d = device_of(cb.as_raw());
            let di = &*info;
            crate::strict::dependency("vkCmdPipelineBarrier2", di);
            let m: Vec<_> = slice(di.p_memory_barriers, di.memory_barrier_count)
                .iter()
                .map(|b| {
                    let mut b = *b;
                    b.src_stage_mask = fix_stage2(b.src_stage_mask);
                    b.dst_stage_mask = fix_stage2(b.dst_stage_mask);
                    b.src_access_mask = fix_access2(b.src_access_mask);
                    b.dst_access_mask = fix_access2(b.dst_access_mask);
                    b
                })
                .collect();
            let bu: Vec<_> = slice(di.p_buffer_memory_barriers, di.buffer_memory_barrier_count)
                .iter()
                .map(|b| {
                    let mut b = *b;
                    b.src_stage_mask = fix_stage2(b.src_stage_mask);
                    b.dst_stage_mask = fix_stage2(b.dst_stage_mask);
                    b.src_access_mask = fix_access2(b.src_access_mask);
                    b.dst_access_mask = fix_access2(b.dst_access_mask);
                    b
                })
                .collect();
            let im: Vec<_> = slice(di.p_image_memory_barriers, di.image_memory_barrier_count)
                .iter()
                .map(|b| {
                    let mut b = *b;
                    b.src_stage_mask = fix_stage2(b.src_stage_mask);
                    b.dst_stage_mask = fix_stage2(b.dst_stage_mask);
                    b.src_access_mask = fix_access2(b.src_access_mask);
                    b.dst_access_mask = fix_access2(b.dst_access_mask);
                    b.old_layout = fix_layout(b.old_layout);
                    b.new_layout = fix_layout(b.new_layout);
                    b
                })
                .collect();
            let given = slice(di.p_image_memory_barriers, di.image_memory_barrier_count);
            event(json!({
                "kind": "barrier",
                "command_buffer": cb.as_raw(),
                "stages": slice(di.p_memory_barriers, di.memory_barrier_count).iter()
                    .map(|b| [b.src_stage_mask.as_raw(), b.dst_stage_mask.as_raw()])
                    .chain(given.iter().map(|b| [b.src_stage_mask.as_raw(), b.dst_stage_mask.as_raw()]))
                    .collect::<Vec<_>>(),
                "access": slice(di.p_memory_barriers, di.memory_barrier_count).iter()
                    .map(|b| [b.src_access_mask.as_raw(), b.dst_access_mask.as_raw()])
                    .chain(given.iter().map(|b| [b.src_access_mask.as_raw(), b.dst_access_mask.as_raw()]))
                    .collect::<Vec<_>>(),
                "images": given.iter()
                    .map(|b| json!({"image": b.image.as_raw(), "layouts": [b.old_layout.as_raw(), b.new_layout.as_raw()]}))
                    .collect::<Vec<_>>(),
            }));
            let mut copy = *di;
            copy.p_memory_barriers = m.as_ptr();
            copy.p_buffer_memory_barriers = bu.as_ptr();
            copy.p_image_memory_barriers = im.as_ptr();
            (d.fns.fp_v1_3().cmd_pipeline_barrier2)(cb, &copy);
        }
    })
}

unsafe extern "system" fn cmd_set_fragment_shading_rate(
    cb: vk::CommandBuffer,
    size: *const vk::Extent2D,
    ops: *const [vk::FragmentShadingRateCombinerOpKHR; 2],
) {
    guard("vkCmdSetFragmentShadingRateKHR", (), || {
        // SAFETY: the caller's arguments; nothing reaches lavapipe, which lacks the command.
        unsafe {
            let (s, o) = (*size, *ops);
            let d = device_of(cb.as_raw());
            lock(&d.state)
                .recordings
                .entry(cb.as_raw())
                .or_default()
                .dynamic = Some(PipelineRate {
                size: [s.width, s.height],
                ops: o,
            });
            event(json!({
                "kind": "set_fragment_shading_rate",
                "command_buffer": cb.as_raw(),
                "fragment_size": pair(s),
                "combiner_ops": [o[0].as_raw(), o[1].as_raw()],
            }));
        }
    })
}

unsafe extern "system" fn cmd_execute_commands(
    cb: vk::CommandBuffer,
    count: u32,
    secondaries: *const vk::CommandBuffer,
) {
    guard("vkCmdExecuteCommands", (), || {
        // SAFETY: the caller's arguments, forwarded unchanged.
        unsafe {
            let d = device_of(cb.as_raw());
            {
                // A secondary's shading-rate images are read when its primary is submitted.
                let mut st = lock(&d.state);
                let mut images: Vec<u64> = Vec::new();
                for s in slice(secondaries, count) {
                    images.extend(st.commands.get(&s.as_raw()).into_iter().flatten());
                }
                let list = st.commands.entry(cb.as_raw()).or_default();
                for i in images {
                    if !list.contains(&i) {
                        list.push(i);
                    }
                }
                // A secondary's draws outside its own passes run in the primary's pass; its own
                // renderings are the primary's too.
                let mut loose = Vec::new();
                let mut passes = Vec::new();
                for s in slice(secondaries, count) {
                    if let Some(r) = st.recordings.get(&s.as_raw()) {
                        loose.extend(r.loose.iter().copied());
                        passes.extend(r.passes.iter().cloned());
                    }
                }
                let r = st.recordings.entry(cb.as_raw()).or_default();
                let subpass = r.subpass;
                if let Some(open) = r.open {
                    r.passes[open]
                        .draws
                        .extend(loose.into_iter().map(|dr| Draw { subpass, ..dr }));
                }
                r.passes.extend(passes);
                r.ends.extend(
                    slice(secondaries, count)
                        .iter()
                        .map(|s| coarse::End::Secondary(s.as_raw())),
                );
            }
            (d.fns.fp_v1_0().cmd_execute_commands)(cb, count, secondaries);
        }
    })
}

/// After a submit that read shading-rate images: waits for the queue and copies each image to the
/// host with the layer's own command buffer, so tests see the rate codes the GPU would have used.
///
/// # Safety
/// `queue` must belong to `d` and be externally synchronised by the current call.
unsafe fn read_back(d: &DeviceData, queue: vk::Queue, images: &[u64]) -> Value {
    let mut out = Vec::new();
    for &image in images {
        let info = lock(&d.state).images.get(&image).copied();
        let Some(info) = info else { continue };
        // SAFETY: the caller's promise; every object below is the layer's own and freed here.
        let codes = unsafe { copy_image(d, queue, image, info) };
        out.push(match codes {
            Ok(c) => json!({
                "image": image,
                "extent": [info.extent.width, info.extent.height],
                "layers": info.layers,
                "codes": c,
            }),
            Err(e) => {
                error(format!("read-back of shading-rate image failed: {e:?}"));
                json!({"image": image, "codes": null})
            }
        });
    }
    Value::Array(out)
}

/// # Safety
/// As [`read_back`].
unsafe fn copy_image(
    d: &DeviceData,
    queue: vk::Queue,
    image: u64,
    info: ImageInfo,
) -> Result<Vec<u8>, vk::Result> {
    let f = &d.fns;
    let family = lock(&d.state)
        .queues
        .get(&queue.as_raw())
        .copied()
        .unwrap_or(0);
    // SAFETY: the caller's promise; these are plain Vulkan calls on the layer's own objects.
    unsafe {
        f.queue_wait_idle(queue)?;
        let pool = {
            let existing = lock(&d.state).pools.get(&family).copied();
            match existing {
                Some(p) => p,
                None => {
                    let p = f.create_command_pool(
                        &vk::CommandPoolCreateInfo::default()
                            .queue_family_index(family)
                            .flags(vk::CommandPoolCreateFlags::TRANSIENT),
                        None,
                    )?;
                    lock(&d.state).pools.insert(family, p);
                    p
                }
            }
        };
        let size = info.extent.width as u64 * info.extent.height as u64 * info.layers as u64;
        let buffer = f.create_buffer(
            &vk::BufferCreateInfo::default()
                .size(size)
                .usage(vk::BufferUsageFlags::TRANSFER_DST),
            None,
        )?;
        let req = f.get_buffer_memory_requirements(buffer);
        let props = d
            .instance
            .fns
            .get_physical_device_memory_properties(d.physical);
        let want = vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
        let Some(ty) = (0..props.memory_type_count).find(|&i| {
            req.memory_type_bits & (1 << i) != 0
                && props.memory_types[i as usize].property_flags.contains(want)
        }) else {
            f.destroy_buffer(buffer, None);
            return Err(vk::Result::ERROR_FEATURE_NOT_PRESENT);
        };
        let memory = f.allocate_memory(
            &vk::MemoryAllocateInfo::default()
                .allocation_size(req.size)
                .memory_type_index(ty),
            None,
        )?;
        f.bind_buffer_memory(buffer, memory, 0)?;
        let cbs = f.allocate_command_buffers(
            &vk::CommandBufferAllocateInfo::default()
                .command_pool(pool)
                .level(vk::CommandBufferLevel::PRIMARY)
                .command_buffer_count(1),
        )?;
        let cb = cbs[0];
        if let Some(set) = d.set_loader_data {
            set(d.handle, cb.as_raw() as usize as *mut c_void).result()?;
        }
        f.begin_command_buffer(
            cb,
            &vk::CommandBufferBeginInfo::default()
                .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
        )?;
        // lavapipe ignores layouts; the application's own layout tracking (above the double) is
        // untouched, since these commands never pass the validation layer.
        f.cmd_copy_image_to_buffer(
            cb,
            vk::Image::from_raw(image),
            vk::ImageLayout::GENERAL,
            buffer,
            &[vk::BufferImageCopy::default()
                .image_subresource(vk::ImageSubresourceLayers {
                    aspect_mask: vk::ImageAspectFlags::COLOR,
                    mip_level: 0,
                    base_array_layer: 0,
                    layer_count: info.layers,
                })
                .image_extent(vk::Extent3D {
                    width: info.extent.width,
                    height: info.extent.height,
                    depth: 1,
                })],
        );
        f.end_command_buffer(cb)?;
        f.queue_submit(
            queue,
            &[vk::SubmitInfo::default().command_buffers(&cbs)],
            vk::Fence::null(),
        )?;
        f.queue_wait_idle(queue)?;
        let p = f.map_memory(memory, 0, size, vk::MemoryMapFlags::empty())?;
        let codes = std::slice::from_raw_parts(p as *const u8, size as usize).to_vec();
        f.unmap_memory(memory);
        f.free_command_buffers(pool, &cbs);
        f.destroy_buffer(buffer, None);
        f.free_memory(memory, None);
        Ok(codes)
    }
}

/// Records a submit and, where it read shading-rate images, their contents.
///
/// # Safety
/// As [`read_back`].
unsafe fn note_submit(d: &DeviceData, queue: vk::Queue, cbs: Vec<u64>) {
    let mut images = Vec::new();
    {
        let st = lock(&d.state);
        for cb in &cbs {
            for i in st.commands.get(cb).into_iter().flatten() {
                if !images.contains(i) {
                    images.push(*i);
                }
            }
        }
    }
    let read = if images.is_empty() {
        Value::Array(Vec::new())
    } else {
        // SAFETY: the caller's promise.
        unsafe { read_back(d, queue, &images) }
    };
    let draws = {
        let st = lock(&d.state);
        cbs.iter().any(|cb| {
            st.recordings
                .get(cb)
                .is_some_and(|r| r.passes.iter().any(|p| !p.draws.is_empty()))
        })
    };
    if draws {
        // SAFETY: the caller's promise: the queue is ours to wait on.
        match unsafe { d.fns.queue_wait_idle(queue) } {
            // SAFETY: the submit's work is complete.
            Ok(()) => unsafe { report_draws(d, &cbs) },
            Err(e) => error(format!("waiting for a submit failed: {e:?}")),
        }
    }
    event(json!({
        "kind": "submit",
        "command_buffers": cbs,
        "shading_rate_images": read,
    }));
}

unsafe extern "system" fn queue_submit(
    queue: vk::Queue,
    count: u32,
    submits: *const vk::SubmitInfo<'_>,
    fence: vk::Fence,
) -> vk::Result {
    guard("vkQueueSubmit", vk::Result::ERROR_UNKNOWN, || {
        if let Some(r) = record::fault("vkQueueSubmit") {
            return r;
        }
        // SAFETY: the caller's submits are read; wait-stage masks are rewritten in copies that
        // live across the call.
        unsafe {
            let d = device_of(queue.as_raw());
            let subs = slice(submits, count);
            for s in subs {
                crate::strict::chain("vkQueueSubmit", s.p_next);
                for m in slice(s.p_wait_dst_stage_mask, s.wait_semaphore_count) {
                    crate::strict::stage("vkQueueSubmit", m.as_raw() as u64);
                }
            }
            let masks: Vec<Vec<vk::PipelineStageFlags>> = subs
                .iter()
                .map(|s| {
                    slice(s.p_wait_dst_stage_mask, s.wait_semaphore_count)
                        .iter()
                        .map(|&m| fix_stage(m))
                        .collect()
                })
                .collect();
            let copies: Vec<vk::SubmitInfo<'_>> = subs
                .iter()
                .zip(&masks)
                .map(|(s, m)| {
                    let mut c = *s;
                    if !s.p_wait_dst_stage_mask.is_null() {
                        c.p_wait_dst_stage_mask = m.as_ptr();
                    }
                    c
                })
                .collect();
            let cbs: Vec<u64> = subs
                .iter()
                .flat_map(|s| slice(s.p_command_buffers, s.command_buffer_count))
                .map(|c| c.as_raw())
                .collect();
            let waits = subs.iter().any(|s| s.wait_semaphore_count > 0);
            if queues::defer1(&d, queue, &copies, fence, &cbs) {
                return vk::Result::SUCCESS;
            }
            // Held-back work goes first where this depends on it, and always on its own queue.
            if waits || queues::real(queue) != queue {
                queues::catch_up(&d);
            }
            execute1(&d, queue, &copies, fence, cbs)
        }
    })
}

/// Submits `copies` (the application's batches, rewritten) on `queue` (an extra one as the
/// driver's queue it stands for) and notes what they read.
///
/// # Safety
/// `queue` must be `d`'s and externally synchronised by the current call; `copies` valid.
unsafe fn execute1(
    d: &Arc<DeviceData>,
    queue: vk::Queue,
    copies: &[vk::SubmitInfo<'_>],
    fence: vk::Fence,
    cbs: Vec<u64>,
) -> vk::Result {
    // SAFETY: as the caller promised.
    unsafe {
        let worker = coarse::start(d, &cbs);
        let _shared = queue.serial();
        let queue = queue.down();
        let r = (d.fns.fp_v1_0().queue_submit)(queue, copies.len() as u32, copies.as_ptr(), fence);
        if let Some(w) = worker {
            coarse::finish(w, r == vk::Result::SUCCESS);
        }
        if r == vk::Result::SUCCESS {
            note_submit(d, queue, cbs);
        }
        r
    }
}

/// [`execute1`] for `vkQueueSubmit2`.
///
/// # Safety
/// As [`execute1`].
unsafe fn execute2(
    d: &Arc<DeviceData>,
    queue: vk::Queue,
    copies: &[vk::SubmitInfo2<'_>],
    fence: vk::Fence,
    cbs: Vec<u64>,
) -> vk::Result {
    // SAFETY: as the caller promised.
    unsafe {
        let worker = coarse::start(d, &cbs);
        let _shared = queue.serial();
        let queue = queue.down();
        let r = (d.fns.fp_v1_3().queue_submit2)(queue, copies.len() as u32, copies.as_ptr(), fence);
        if let Some(w) = worker {
            coarse::finish(w, r == vk::Result::SUCCESS);
        }
        if r == vk::Result::SUCCESS {
            note_submit(d, queue, cbs);
        }
        r
    }
}

/// Copies semaphore infos with shading-rate stage bits made fragment-shader bits.
///
/// # Safety
/// `p` must be null or valid for `n` elements.
unsafe fn fix_semaphores<'a>(
    p: *const vk::SemaphoreSubmitInfo<'a>,
    n: u32,
) -> Vec<vk::SemaphoreSubmitInfo<'a>> {
    // SAFETY: the caller's promise.
    unsafe { slice(p, n) }
        .iter()
        .map(|i| {
            let mut i = *i;
            i.stage_mask = fix_stage2(i.stage_mask);
            i
        })
        .collect()
}

unsafe extern "system" fn queue_submit2(
    queue: vk::Queue,
    count: u32,
    submits: *const vk::SubmitInfo2<'_>,
    fence: vk::Fence,
) -> vk::Result {
    guard("vkQueueSubmit2", vk::Result::ERROR_UNKNOWN, || {
        if let Some(r) = record::fault("vkQueueSubmit2") {
            return r;
        }
        // SAFETY: the caller's submits are read; semaphore stage masks are rewritten in copies
        // that live across the call.
        unsafe {
            let d = device_of(queue.as_raw());
            let subs = slice(submits, count);
            for s in subs {
                crate::strict::chain("vkQueueSubmit2", s.p_next);
                for i in slice(s.p_wait_semaphore_infos, s.wait_semaphore_info_count)
                    .iter()
                    .chain(slice(
                        s.p_signal_semaphore_infos,
                        s.signal_semaphore_info_count,
                    ))
                {
                    crate::strict::stage("vkQueueSubmit2", i.stage_mask.as_raw());
                }
            }
            let waits: Vec<_> = subs
                .iter()
                .map(|s| fix_semaphores(s.p_wait_semaphore_infos, s.wait_semaphore_info_count))
                .collect();
            let signals: Vec<_> = subs
                .iter()
                .map(|s| fix_semaphores(s.p_signal_semaphore_infos, s.signal_semaphore_info_count))
                .collect();
            let copies: Vec<vk::SubmitInfo2<'_>> = subs
                .iter()
                .zip(waits.iter().zip(&signals))
                .map(|(s, (w, g))| {
                    let mut c = *s;
                    c.p_wait_semaphore_infos = w.as_ptr();
                    c.p_signal_semaphore_infos = g.as_ptr();
                    c
                })
                .collect();
            let cbs: Vec<u64> = slice(submits, count)
                .iter()
                .flat_map(|s| slice(s.p_command_buffer_infos, s.command_buffer_info_count))
                .map(|c| c.command_buffer.as_raw())
                .collect();
            let waits = subs.iter().any(|s| s.wait_semaphore_info_count > 0);
            if queues::defer2(&d, queue, &copies, fence, &cbs) {
                return vk::Result::SUCCESS;
            }
            // Held-back work goes first where this depends on it, and always on its own queue.
            if waits || queues::real(queue) != queue {
                queues::catch_up(&d);
            }
            execute2(&d, queue, &copies, fence, cbs)
        }
    })
}

// ---------------------------------------------------------------------------------------------
// Fault injection: commands that can be made to fail (`fovea_vkdouble_fail`), intercepted whatever
// the profile. Each counts its calls and, at the armed one, returns the armed result without
// calling lavapipe; outputs a failed command must leave null
// (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#fundamentals-errorcodes>)
// are nulled. The commands the profile path rewrites check for their fault themselves.

macro_rules! faultable {
    ($($name:literal => $f:ident as $pfn:ident = $table:ident . $field:ident
        ($first:ident: $ft:ty $(, $a:ident: $t:ty)*) $(, on_fault $clear:expr)?;)*) => {
        $(
            unsafe extern "system" fn $f($first: $ft $(, $a: $t)*) -> vk::Result {
                guard($name, vk::Result::ERROR_UNKNOWN, || {
                    if let Some(r) = record::fault($name) {
                        $(
                            // SAFETY: the caller's output array, valid for the counts it gave.
                            unsafe { $clear };
                        )?
                        return r;
                    }
                    // SAFETY: the caller's arguments, forwarded unchanged to the next layer (an
                    // extra queue as the driver's queue it stands for).
                    unsafe {
                        let d = device_of($first.as_raw());
                        queues::catch_up(&d);
                        let _shared = $first.serial();
                        (d.fns.$table().$field)($first.down() $(, $a)*)
                    }
                })
            }
        )*

        /// The fault-injection wrapper for `name`.
        fn faultable_commands(name: &[u8]) -> vk::PFN_vkVoidFunction {
            $(
                if name == $name.as_bytes() {
                    let f: vk::$pfn = $f;
                    // SAFETY: the loader's generic function pointer type; the caller casts it back
                    // to the type its name implies, which is `$pfn`.
                    return Some(unsafe {
                        std::mem::transmute::<vk::$pfn, unsafe extern "system" fn()>(f)
                    });
                }
            )*
            None
        }

        /// Every command that can be made to fail (besides `vkCreateDevice`).
        pub const FAULTABLE: &[&str] = &[$($name),*];
    };
}

faultable! {
    "vkCreateImage" => fault_create_image as PFN_vkCreateImage = fp_v1_0.create_image
        (device: vk::Device, info: *const vk::ImageCreateInfo<'_>,
         alloc: *const vk::AllocationCallbacks<'_>, out: *mut vk::Image);
    "vkCreateBuffer" => fault_create_buffer as PFN_vkCreateBuffer = fp_v1_0.create_buffer
        (device: vk::Device, info: *const vk::BufferCreateInfo<'_>,
         alloc: *const vk::AllocationCallbacks<'_>, out: *mut vk::Buffer);
    "vkAllocateMemory" => fault_allocate_memory as PFN_vkAllocateMemory = fp_v1_0.allocate_memory
        (device: vk::Device, info: *const vk::MemoryAllocateInfo<'_>,
         alloc: *const vk::AllocationCallbacks<'_>, out: *mut vk::DeviceMemory);
    "vkBindImageMemory" => fault_bind_image_memory as PFN_vkBindImageMemory =
        fp_v1_0.bind_image_memory
        (device: vk::Device, image: vk::Image, memory: vk::DeviceMemory, offset: vk::DeviceSize);
    "vkBindBufferMemory" => fault_bind_buffer_memory as PFN_vkBindBufferMemory =
        fp_v1_0.bind_buffer_memory
        (device: vk::Device, buffer: vk::Buffer, memory: vk::DeviceMemory, offset: vk::DeviceSize);
    "vkMapMemory" => fault_map_memory as PFN_vkMapMemory = fp_v1_0.map_memory
        (device: vk::Device, memory: vk::DeviceMemory, offset: vk::DeviceSize,
         size: vk::DeviceSize, flags: vk::MemoryMapFlags, out: *mut *mut c_void);
    "vkCreateImageView" => fault_create_image_view as PFN_vkCreateImageView =
        fp_v1_0.create_image_view
        (device: vk::Device, info: *const vk::ImageViewCreateInfo<'_>,
         alloc: *const vk::AllocationCallbacks<'_>, out: *mut vk::ImageView);
    "vkCreateRenderPass" => fault_create_render_pass as PFN_vkCreateRenderPass =
        fp_v1_0.create_render_pass
        (device: vk::Device, info: *const vk::RenderPassCreateInfo<'_>,
         alloc: *const vk::AllocationCallbacks<'_>, out: *mut vk::RenderPass);
    "vkCreateRenderPass2" => fault_create_render_pass2 as PFN_vkCreateRenderPass2 =
        fp_v1_2.create_render_pass2
        (device: vk::Device, info: *const vk::RenderPassCreateInfo2<'_>,
         alloc: *const vk::AllocationCallbacks<'_>, out: *mut vk::RenderPass);
    "vkCreateFramebuffer" => fault_create_framebuffer as PFN_vkCreateFramebuffer =
        fp_v1_0.create_framebuffer
        (device: vk::Device, info: *const vk::FramebufferCreateInfo<'_>,
         alloc: *const vk::AllocationCallbacks<'_>, out: *mut vk::Framebuffer);
    "vkCreatePipelineLayout" => fault_create_pipeline_layout as PFN_vkCreatePipelineLayout =
        fp_v1_0.create_pipeline_layout
        (device: vk::Device, info: *const vk::PipelineLayoutCreateInfo<'_>,
         alloc: *const vk::AllocationCallbacks<'_>, out: *mut vk::PipelineLayout);
    "vkCreateGraphicsPipelines" => fault_create_graphics_pipelines
        as PFN_vkCreateGraphicsPipelines = fp_v1_0.create_graphics_pipelines
        (device: vk::Device, cache: vk::PipelineCache, count: u32,
         infos: *const vk::GraphicsPipelineCreateInfo<'_>,
         alloc: *const vk::AllocationCallbacks<'_>, out: *mut vk::Pipeline),
        on_fault null_outputs(out, count);
    "vkCreateShaderModule" => fault_create_shader_module as PFN_vkCreateShaderModule =
        fp_v1_0.create_shader_module
        (device: vk::Device, info: *const vk::ShaderModuleCreateInfo<'_>,
         alloc: *const vk::AllocationCallbacks<'_>, out: *mut vk::ShaderModule);
    "vkCreateSampler" => fault_create_sampler as PFN_vkCreateSampler = fp_v1_0.create_sampler
        (device: vk::Device, info: *const vk::SamplerCreateInfo<'_>,
         alloc: *const vk::AllocationCallbacks<'_>, out: *mut vk::Sampler);
    "vkCreateCommandPool" => fault_create_command_pool as PFN_vkCreateCommandPool =
        fp_v1_0.create_command_pool
        (device: vk::Device, info: *const vk::CommandPoolCreateInfo<'_>,
         alloc: *const vk::AllocationCallbacks<'_>, out: *mut vk::CommandPool);
    "vkAllocateCommandBuffers" => fault_allocate_command_buffers
        as PFN_vkAllocateCommandBuffers = fp_v1_0.allocate_command_buffers
        (device: vk::Device, info: *const vk::CommandBufferAllocateInfo<'_>,
         out: *mut vk::CommandBuffer),
        on_fault null_outputs(out, (*info).command_buffer_count);
    "vkBeginCommandBuffer" => fault_begin_command_buffer as PFN_vkBeginCommandBuffer =
        fp_v1_0.begin_command_buffer
        (cb: vk::CommandBuffer, info: *const vk::CommandBufferBeginInfo<'_>);
    "vkEndCommandBuffer" => fault_end_command_buffer as PFN_vkEndCommandBuffer =
        fp_v1_0.end_command_buffer (cb: vk::CommandBuffer);
    "vkQueueSubmit" => fault_queue_submit as PFN_vkQueueSubmit = fp_v1_0.queue_submit
        (queue: vk::Queue, count: u32, submits: *const vk::SubmitInfo<'_>, fence: vk::Fence);
    "vkQueueSubmit2" => fault_queue_submit2 as PFN_vkQueueSubmit2 = fp_v1_3.queue_submit2
        (queue: vk::Queue, count: u32, submits: *const vk::SubmitInfo2<'_>, fence: vk::Fence);
    "vkQueueWaitIdle" => fault_queue_wait_idle as PFN_vkQueueWaitIdle =
        fp_v1_0.queue_wait_idle (queue: vk::Queue);
    "vkCreateFence" => fault_create_fence as PFN_vkCreateFence = fp_v1_0.create_fence
        (device: vk::Device, info: *const vk::FenceCreateInfo<'_>,
         alloc: *const vk::AllocationCallbacks<'_>, out: *mut vk::Fence);
    "vkWaitForFences" => fault_wait_for_fences as PFN_vkWaitForFences = fp_v1_0.wait_for_fences
        (device: vk::Device, count: u32, fences: *const vk::Fence, all: vk::Bool32,
         timeout: u64);
    "vkResetFences" => fault_reset_fences as PFN_vkResetFences = fp_v1_0.reset_fences
        (device: vk::Device, count: u32, fences: *const vk::Fence);
}

macro_rules! counted {
    ($($name:literal => $f:ident as $pfn:ident = $table:ident . $field:ident
        ($first:ident: $ft:ty $(, $a:ident: $t:ty)*);)*) => {
        $(
            unsafe extern "system" fn $f($first: $ft $(, $a: $t)*) {
                guard($name, (), || {
                    record::count($name);
                    // SAFETY: the caller's arguments, forwarded unchanged to the next layer.
                    unsafe {
                        let d = device_of($first.as_raw());
                        (d.fns.$table().$field)($first $(, $a)*)
                    }
                })
            }
        )*

        /// The counting wrapper for `name`.
        fn counted_commands(name: &[u8]) -> vk::PFN_vkVoidFunction {
            $(
                if name == $name.as_bytes() {
                    let f: vk::$pfn = $f;
                    // SAFETY: the loader's generic function pointer type; the caller casts it back
                    // to the type its name implies, which is `$pfn`.
                    return Some(unsafe {
                        std::mem::transmute::<vk::$pfn, unsafe extern "system" fn()>(f)
                    });
                }
            )*
            None
        }

        /// Commands that free what [`FAULTABLE`] ones made, counted whatever the profile, so that
        /// a test can tell how many buffers and memory objects are alive below the layers above
        /// (`vkCreateBuffer` − `vkDestroyBuffer`): a layer that leaks per recreation shows. With
        /// `vkDestroyImageView` (counted on the shading-rate profiles), [`fovea_vkdouble_calls`]
        /// counts them.
        pub const COUNTED: &[&str] = &[$($name),*];
    };
}

counted! {
    "vkDestroyBuffer" => counted_destroy_buffer as PFN_vkDestroyBuffer = fp_v1_0.destroy_buffer
        (device: vk::Device, buffer: vk::Buffer, alloc: *const vk::AllocationCallbacks<'_>);
    "vkFreeMemory" => counted_free_memory as PFN_vkFreeMemory = fp_v1_0.free_memory
        (device: vk::Device, memory: vk::DeviceMemory, alloc: *const vk::AllocationCallbacks<'_>);
}

/// Nulls `n` output handles.
///
/// # Safety
/// `out` must be null or valid for `n` writes.
unsafe fn null_outputs<T: vk::Handle>(out: *mut T, n: u32) {
    if out.is_null() {
        return;
    }
    for i in 0..n as usize {
        // SAFETY: as the caller promised.
        unsafe { out.add(i).write(T::from_raw(0)) };
    }
}

// ---------------------------------------------------------------------------------------------
// Effects: the fragment size each draw gets, as the GPU the double plays would shade it.
//
// Per command buffer the double follows the bound pipeline's rate state, the dynamic rate, and the
// render pass instances (or renderings) with their shading-rate attachments. A pass cannot change
// its attachment while it runs, so the attachment's codes as the pass sees them are copied, in the
// command buffer, just before the pass begins, into a buffer the double owns; after the submit
// completed, each draw's effective size per attachment texel is computed from that copy.

/// A buffer of the double's own, host visible, that a pass's attachment is copied into.
#[derive(Clone, Copy)]
struct Snapshot {
    buffer: vk::Buffer,
    memory: vk::DeviceMemory,
    size: u64,
}

/// A pass's shading-rate attachment: the layers of the image its view names.
#[derive(Clone, Copy)]
struct Attach {
    image: u64,
    base_layer: u32,
    layers: u32,
    extent: vk::Extent2D,
    texel: vk::Extent2D,
    snapshot: Option<Snapshot>,
    /// `storeOp = DONT_CARE`: the contents are undefined after the pass.
    dont_care: bool,
}

#[derive(Clone, Copy)]
struct Draw {
    subpass: u32,
    rate: PipelineRate,
}

/// One render pass instance or rendering.
#[derive(Clone)]
struct PassRec {
    rendering: bool,
    /// The render area's far corner: the framebuffer region the draws can touch.
    area: vk::Extent2D,
    /// Per subpass (one for a rendering): the attachment and the view mask.
    subpasses: Vec<(Option<Attach>, u32)>,
    draws: Vec<Draw>,
    /// The colour attachments its subpasses write.
    colours: Vec<ColourTarget>,
    /// A rendering with `VK_RENDERING_SUSPENDING_BIT`: its pass instance goes on in the next.
    suspending: bool,
}

#[derive(Default)]
struct Recording {
    /// The bound graphics pipeline's rate state and whether it is dynamic.
    bound: Option<(PipelineRate, bool)>,
    /// The last `vkCmdSetFragmentShadingRateKHR`.
    dynamic: Option<PipelineRate>,
    passes: Vec<PassRec>,
    /// The pass being recorded, an index into `passes`.
    open: Option<usize>,
    subpass: u32,
    /// Draws outside any pass of this command buffer: a secondary's, which run in the pass of
    /// the primary that executes it.
    loose: Vec<Draw>,
    /// The snapshots this recording owns (freed when it is recorded anew).
    snapshots: Vec<Snapshot>,
    /// What the double recorded after each pass instance to leave its colour coarse, and the
    /// secondaries executed, in order ([`coarse`]).
    ends: Vec<coarse::End>,
}

/// What poisons a shading-rate attachment after `storeOp = DONT_CARE`: the code of 4×4, the
/// coarsest rate (clamped to what the device lists), so a later pass that relies on the old
/// contents shades visibly wrong.
pub const POISON: u8 = 0b1010;

/// Forgets a recording and frees what it owned.
///
/// # Safety
/// The snapshots' command buffer must not be pending.
unsafe fn drop_recording(d: &DeviceData, r: Recording) {
    for e in r.ends {
        if let coarse::End::Own(e) = e {
            // SAFETY: the caller's promise.
            unsafe { coarse::free(d, e) };
        }
    }
    for s in r.snapshots {
        // SAFETY: the double's own objects, no longer in use (the caller's promise).
        unsafe {
            d.fns.destroy_buffer(s.buffer, None);
            d.fns.free_memory(s.memory, None);
        }
    }
}

/// A host-visible, coherent buffer of `size` bytes.
///
/// # Safety
/// `d` must be live.
unsafe fn host_buffer(
    d: &DeviceData,
    size: u64,
    usage: vk::BufferUsageFlags,
) -> Result<Snapshot, vk::Result> {
    let f = &d.fns;
    // SAFETY: plain Vulkan calls on the double's own objects.
    unsafe {
        let buffer = f.create_buffer(
            &vk::BufferCreateInfo::default()
                .size(size.max(1))
                .usage(usage),
            None,
        )?;
        let req = f.get_buffer_memory_requirements(buffer);
        let props = d
            .instance
            .fns
            .get_physical_device_memory_properties(d.physical);
        let want = vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
        let Some(ty) = (0..props.memory_type_count).find(|&i| {
            req.memory_type_bits & (1 << i) != 0
                && props.memory_types[i as usize].property_flags.contains(want)
        }) else {
            f.destroy_buffer(buffer, None);
            return Err(vk::Result::ERROR_FEATURE_NOT_PRESENT);
        };
        let memory = match f.allocate_memory(
            &vk::MemoryAllocateInfo::default()
                .allocation_size(req.size)
                .memory_type_index(ty),
            None,
        ) {
            Ok(m) => m,
            Err(e) => {
                f.destroy_buffer(buffer, None);
                return Err(e);
            }
        };
        if let Err(e) = f.bind_buffer_memory(buffer, memory, 0) {
            f.destroy_buffer(buffer, None);
            f.free_memory(memory, None);
            return Err(e);
        }
        Ok(Snapshot {
            buffer,
            memory,
            size,
        })
    }
}

/// A global barrier between everything before and everything after, for the double's own copies
/// and clears (lavapipe ignores layouts; these commands never pass the validation layer).
///
/// # Safety
/// `cb` must be recording outside a pass.
unsafe fn full_barrier(d: &DeviceData, cb: vk::CommandBuffer) {
    let all = vk::AccessFlags::MEMORY_READ | vk::AccessFlags::MEMORY_WRITE;
    // SAFETY: the caller's promise.
    unsafe {
        (d.fns.fp_v1_0().cmd_pipeline_barrier)(
            cb,
            vk::PipelineStageFlags::ALL_COMMANDS,
            vk::PipelineStageFlags::ALL_COMMANDS | vk::PipelineStageFlags::HOST,
            vk::DependencyFlags::empty(),
            1,
            &vk::MemoryBarrier::default()
                .src_access_mask(all)
                .dst_access_mask(all | vk::AccessFlags::HOST_READ),
            0,
            std::ptr::null(),
            0,
            std::ptr::null(),
        );
    }
}

fn subresource(base: u32, layers: u32) -> vk::ImageSubresourceLayers {
    vk::ImageSubresourceLayers {
        aspect_mask: vk::ImageAspectFlags::COLOR,
        mip_level: 0,
        base_array_layer: base,
        layer_count: layers,
    }
}

/// Records, in front of a pass, the copy of its attachment's layers into a new snapshot.
///
/// # Safety
/// `cb` must be recording outside a pass, on `d`.
unsafe fn snapshot(d: &DeviceData, cb: vk::CommandBuffer, a: &Attach) -> Option<Snapshot> {
    let size = a.extent.width as u64 * a.extent.height as u64 * a.layers as u64;
    // SAFETY: the caller's promise.
    let s = match unsafe { host_buffer(d, size, vk::BufferUsageFlags::TRANSFER_DST) } {
        Ok(s) => s,
        Err(e) => {
            error(format!(
                "snapshot of a shading-rate attachment failed: {e:?}"
            ));
            return None;
        }
    };
    // SAFETY: the caller's promise; the image is a live shading-rate image the pass reads.
    unsafe {
        full_barrier(d, cb);
        (d.fns.fp_v1_0().cmd_copy_image_to_buffer)(
            cb,
            vk::Image::from_raw(a.image),
            vk::ImageLayout::GENERAL,
            s.buffer,
            1,
            &vk::BufferImageCopy::default()
                .image_subresource(subresource(a.base_layer, a.layers))
                .image_extent(vk::Extent3D {
                    width: a.extent.width,
                    height: a.extent.height,
                    depth: 1,
                }),
        );
        full_barrier(d, cb);
    }
    Some(s)
}

/// Records, after a pass, the poisoning of an attachment it stored with `DONT_CARE`.
///
/// # Safety
/// `cb` must be recording outside a pass, on `d`.
unsafe fn poison(d: &DeviceData, cb: vk::CommandBuffer, a: &Attach) {
    let value = vk::ClearColorValue {
        uint32: [POISON as u32; 4],
    };
    let range = vk::ImageSubresourceRange {
        aspect_mask: vk::ImageAspectFlags::COLOR,
        base_mip_level: 0,
        level_count: 1,
        base_array_layer: a.base_layer,
        layer_count: a.layers,
    };
    // SAFETY: the caller's promise; the image got TRANSFER_DST when the double created it.
    unsafe {
        full_barrier(d, cb);
        (d.fns.fp_v1_0().cmd_clear_color_image)(
            cb,
            vk::Image::from_raw(a.image),
            vk::ImageLayout::GENERAL,
            &value,
            1,
            &range,
        );
        full_barrier(d, cb);
    }
    event(json!({
        "kind": "poison",
        "command_buffer": cb.as_raw(),
        "image": a.image,
        "base_layer": a.base_layer,
        "layers": a.layers,
    }));
}

/// The attachment a view names, as a pass uses it.
fn attach_of(st: &DeviceState, view: u64, texel: vk::Extent2D, dont_care: bool) -> Option<Attach> {
    let v = st.views.get(&view)?;
    let image = st.images.get(&v.image)?;
    Some(Attach {
        image: v.image,
        base_layer: v.base_layer,
        layers: v.layers,
        extent: vk::Extent2D {
            width: image.extent.width,
            height: image.extent.height,
        },
        texel,
        snapshot: None,
        dont_care,
    })
}

/// Opens a pass in `cb`'s recording, with snapshots of its attachments recorded in front of it.
///
/// # Safety
/// `cb` must be recording outside a pass, on `d`; the begin is forwarded after this returns.
unsafe fn open_pass(d: &DeviceData, cb: vk::CommandBuffer, mut pass: PassRec, resuming: bool) {
    let mut taken: Vec<(u64, u32, u32, Snapshot)> = Vec::new();
    if resuming {
        // A resumed rendering continues the suspended one: nothing may come between them.
        let st = lock(&d.state);
        if let Some(prev) = st
            .recordings
            .get(&cb.as_raw())
            .and_then(|r| r.passes.last())
        {
            for (a, _) in pass.subpasses.iter_mut() {
                if let (Some(a), Some((Some(p), _))) = (a.as_mut(), prev.subpasses.first()) {
                    if p.image == a.image {
                        a.snapshot = p.snapshot;
                    }
                }
            }
        }
    } else {
        for (a, _) in pass.subpasses.iter_mut() {
            let Some(a) = a.as_mut() else { continue };
            if let Some(&(_, _, _, s)) = taken
                .iter()
                .find(|t| (t.0, t.1, t.2) == (a.image, a.base_layer, a.layers))
            {
                a.snapshot = Some(s);
                continue;
            }
            // SAFETY: the caller's promise.
            a.snapshot = unsafe { snapshot(d, cb, a) };
            if let Some(s) = a.snapshot {
                taken.push((a.image, a.base_layer, a.layers, s));
            }
        }
    }
    let mut st = lock(&d.state);
    let r = st.recordings.entry(cb.as_raw()).or_default();
    r.snapshots.extend(taken.iter().map(|t| t.3));
    r.passes.push(pass);
    r.open = Some(r.passes.len() - 1);
    r.subpass = 0;
}

/// Closes the open pass; poisons what it left undefined; leaves its colour as coarse fragments
/// shade it ([`coarse`]).
///
/// # Safety
/// `cb` must be recording on `d`, the pass's end just forwarded.
unsafe fn close_pass(d: &DeviceData, cb: vk::CommandBuffer) {
    let mut ended: Option<PassRec> = None;
    let poisoned: Vec<Attach> = {
        let mut st = lock(&d.state);
        let Some(r) = st.recordings.get_mut(&cb.as_raw()) else {
            return;
        };
        let Some(open) = r.open.take() else { return };
        r.subpass = 0;
        if !r.passes[open].suspending {
            // A pass instance ends here; a rendering it resumed adds its suspended parts' draws.
            let mut whole = r.passes[open].clone();
            let mut k = open;
            while k > 0 && r.passes[k].rendering && r.passes[k - 1].suspending {
                k -= 1;
                whole.draws.extend(r.passes[k].draws.iter().copied());
            }
            ended = Some(whole);
        }
        let mut out: Vec<Attach> = Vec::new();
        for (a, _) in &r.passes[open].subpasses {
            if let Some(a) = a.filter(|a| a.dont_care) {
                if !out
                    .iter()
                    .any(|o| (o.image, o.base_layer) == (a.image, a.base_layer))
                {
                    out.push(a);
                }
            }
        }
        out
    };
    for a in &poisoned {
        // SAFETY: the caller's promise.
        unsafe { poison(d, cb, a) };
    }
    // SAFETY: the caller's promise.
    if let Some(end) = ended.and_then(|p| unsafe { coarse::end_pass(d, cb, p) }) {
        let mut st = lock(&d.state);
        let r = st.recordings.entry(cb.as_raw()).or_default();
        r.ends.push(coarse::End::Own(end));
    }
}

/// Notes a draw with the state bound now.
fn note_draw(d: &DeviceData, cb: vk::CommandBuffer) {
    let mut st = lock(&d.state);
    let r = st.recordings.entry(cb.as_raw()).or_default();
    let rate = match r.bound {
        Some((rate, false)) => rate,
        Some((_, true)) => r.dynamic.unwrap_or_else(|| {
            error(
                "draw with a dynamic fragment shading rate that was never set \
                 (VUID-vkCmdDraw-None-08608)"
                    .into(),
            );
            PipelineRate::NONE
        }),
        None => PipelineRate::NONE,
    };
    let draw = Draw {
        subpass: r.subpass,
        rate,
    };
    match r.open {
        Some(i) => r.passes[i].draws.push(draw),
        None => r.loose.push(draw),
    }
}

/// The attachment's codes per texel of one layer, from a snapshot read back.
struct Codes<'a> {
    bytes: &'a [u8],
    extent: vk::Extent2D,
}

/// After a submit completed: the effective rates of every draw of the submitted command buffers.
///
/// # Safety
/// The submit's work must be complete.
unsafe fn report_draws(d: &DeviceData, cbs: &[u64]) {
    let rates = d.instance.profile.fragment_sizes();
    let st = lock(&d.state);
    let mut read: BTreeMap<u64, Vec<u8>> = BTreeMap::new();
    for &cb in cbs {
        let Some(r) = st.recordings.get(&cb) else {
            continue;
        };
        for (pi, pass) in r.passes.iter().enumerate() {
            for (k, draw) in pass.draws.iter().enumerate() {
                let (attach, mask) = pass
                    .subpasses
                    .get(draw.subpass as usize)
                    .copied()
                    .unwrap_or((None, 0));
                let bytes = attach.and_then(|a| a.snapshot).map(|s| {
                    read.entry(s.buffer.as_raw())
                        // SAFETY: the double's own memory; the copy into it completed.
                        .or_insert_with(|| unsafe { read_snapshot(d, s) })
                        .clone()
                });
                let views: Vec<u32> = if mask == 0 {
                    vec![0]
                } else {
                    (0..32).filter(|v| mask & (1 << v) != 0).collect()
                };
                let mut out = Vec::new();
                for v in views {
                    out.push(match (attach, &bytes) {
                        (Some(a), Some(b)) => {
                            // Layered attachment with multiview: layer = ViewIndex; else layer 0
                            // ("Attachment Fragment Shading Rate").
                            let layer = if a.layers > 1 && mask != 0 { v } else { 0 };
                            if layer >= a.layers {
                                error(format!(
                                    "view {v} reads layer {layer} of a {}-layer shading-rate view",
                                    a.layers
                                ));
                            }
                            let texels = (a.extent.width * a.extent.height) as usize;
                            let start = (layer.min(a.layers - 1) as usize) * texels;
                            let codes = Codes {
                                bytes: b.get(start..start + texels).unwrap_or(&[]),
                                extent: a.extent,
                            };
                            let (columns, rows, grid) =
                                view_rates(&codes, a.texel, pass.area, draw.rate, &rates);
                            json!({
                                "view": v,
                                "layer": layer,
                                "columns": columns,
                                "rows": rows,
                                "codes": hex(&grid),
                            })
                        }
                        _ => {
                            let e = draw.rate.effective([1, 1], &rates);
                            json!({
                                "view": v,
                                "layer": null,
                                "columns": 1,
                                "rows": 1,
                                "codes": format!("{:x}", crate::shade::encode(e)),
                            })
                        }
                    });
                }
                event(json!({
                    "kind": "draw",
                    "command_buffer": cb,
                    "pass": pi,
                    "rendering": pass.rendering,
                    "subpass": draw.subpass,
                    "draw": k,
                    "pipeline_rate": {
                        "fragment_size": draw.rate.size,
                        "combiner_ops": [draw.rate.ops[0].as_raw(), draw.rate.ops[1].as_raw()],
                    },
                    "views": out,
                }));
            }
        }
    }
}

/// A snapshot's bytes.
///
/// # Safety
/// The copy into it must have completed.
unsafe fn read_snapshot(d: &DeviceData, s: Snapshot) -> Vec<u8> {
    // SAFETY: the double's own memory (the caller's promise).
    unsafe {
        match d
            .fns
            .map_memory(s.memory, 0, s.size, vk::MemoryMapFlags::empty())
        {
            Ok(p) => {
                let v = std::slice::from_raw_parts(p as *const u8, s.size as usize).to_vec();
                d.fns.unmap_memory(s.memory);
                v
            }
            Err(e) => {
                error(format!("mapping a snapshot failed: {e:?}"));
                Vec::new()
            }
        }
    }
}

/// One view's effective sizes over the attachment texels the render area covers, as codes in
/// the attachment's encoding, rows top to bottom: (columns, rows, codes).
fn view_rates(
    codes: &Codes<'_>,
    texel: vk::Extent2D,
    area: vk::Extent2D,
    rate: PipelineRate,
    rates: &[[u32; 2]],
) -> (u32, u32, Vec<u8>) {
    let columns = area
        .width
        .div_ceil(texel.width.max(1))
        .min(codes.extent.width);
    let rows = area
        .height
        .div_ceil(texel.height.max(1))
        .min(codes.extent.height);
    let mut out = Vec::with_capacity((columns * rows) as usize);
    for y in 0..rows {
        for x in 0..columns {
            let at = (y * codes.extent.width + x) as usize;
            let code = codes.bytes.get(at).copied().unwrap_or(0);
            out.push(crate::shade::encode(
                rate.effective(crate::shade::decode(code), rates),
            ));
        }
    }
    (columns, rows, out)
}

/// Codes as the `draw` record gives them: one hex digit per texel.
fn hex(codes: &[u8]) -> String {
    codes
        .iter()
        .map(|&c| char::from_digit(c as u32, 16).unwrap_or('0'))
        .collect()
}

/// The pixel size of the colour formats the double coarsens (8-bit and 16-bit RGBA, 32-bit
/// packed, 32-bit float RGBA); others are left alone.
fn pixel_bytes(format: vk::Format) -> Option<u64> {
    use vk::Format as F;
    match format {
        F::R8G8B8A8_UNORM
        | F::R8G8B8A8_SRGB
        | F::B8G8R8A8_UNORM
        | F::B8G8R8A8_SRGB
        | F::A2B10G10R10_UNORM_PACK32
        | F::A2R10G10B10_UNORM_PACK32
        | F::B10G11R11_UFLOAT_PACK32 => Some(4),
        F::R16G16B16A16_SFLOAT | F::R16G16B16A16_UNORM => Some(8),
        F::R32G32B32A32_SFLOAT => Some(16),
        _ => None,
    }
}

/// The colour and resolve attachment indices of a subpass: a GPU's coarse fragments leave blocks
/// in a multisampled attachment's resolve as in a single-sample attachment (every sample of a
/// fragment's pixels gets its colour, so the pixels resolve alike). Multisampled images are not
/// coarsened themselves (the double does not track them as colour targets, [`ColourTarget`]).
///
/// # Safety
/// `s` must be valid.
unsafe fn colors_of(s: &vk::SubpassDescription2<'_>) -> Vec<u32> {
    // SAFETY: the caller's promise.
    let resolves = if s.p_resolve_attachments.is_null() {
        &[][..]
    } else {
        // SAFETY: as above: one per colour attachment.
        unsafe { slice(s.p_resolve_attachments, s.color_attachment_count) }
    };
    // SAFETY: the caller's promise.
    unsafe { slice(s.p_color_attachments, s.color_attachment_count) }
        .iter()
        .chain(resolves)
        .map(|r| r.attachment)
        .filter(|&a| a != vk::ATTACHMENT_UNUSED)
        .collect()
}

unsafe extern "system" fn cmd_bind_pipeline(
    cb: vk::CommandBuffer,
    point: vk::PipelineBindPoint,
    pipeline: vk::Pipeline,
) {
    guard("vkCmdBindPipeline", (), || {
        // SAFETY: the caller's arguments, forwarded unchanged.
        unsafe {
            let d = device_of(cb.as_raw());
            if point == vk::PipelineBindPoint::GRAPHICS {
                let mut st = lock(&d.state);
                let rate = st
                    .pipelines
                    .get(&pipeline.as_raw())
                    .copied()
                    .unwrap_or((PipelineRate::NONE, false));
                st.recordings.entry(cb.as_raw()).or_default().bound = Some(rate);
            }
            (d.fns.fp_v1_0().cmd_bind_pipeline)(cb, point, pipeline);
        }
    })
}

fn next_subpass(d: &DeviceData, cb: vk::CommandBuffer) {
    lock(&d.state)
        .recordings
        .entry(cb.as_raw())
        .or_default()
        .subpass += 1;
}

unsafe extern "system" fn cmd_next_subpass(cb: vk::CommandBuffer, contents: vk::SubpassContents) {
    guard("vkCmdNextSubpass", (), || {
        // SAFETY: the caller's arguments, forwarded unchanged.
        unsafe {
            let d = device_of(cb.as_raw());
            next_subpass(&d, cb);
            (d.fns.fp_v1_0().cmd_next_subpass)(cb, contents);
        }
    })
}

unsafe extern "system" fn cmd_next_subpass2(
    cb: vk::CommandBuffer,
    begin: *const vk::SubpassBeginInfo<'_>,
    end: *const vk::SubpassEndInfo<'_>,
) {
    guard("vkCmdNextSubpass2", (), || {
        // SAFETY: the caller's arguments, forwarded unchanged.
        unsafe {
            let d = device_of(cb.as_raw());
            if let Some(e) = end.as_ref() {
                crate::strict::chain("vkCmdNextSubpass2", e.p_next);
            }
            next_subpass(&d, cb);
            (d.fns.fp_v1_2().cmd_next_subpass2)(cb, begin, end);
        }
    })
}

unsafe extern "system" fn cmd_end_render_pass(cb: vk::CommandBuffer) {
    guard("vkCmdEndRenderPass", (), || {
        // SAFETY: the caller's arguments, forwarded unchanged; the double's own commands follow.
        unsafe {
            let d = device_of(cb.as_raw());
            (d.fns.fp_v1_0().cmd_end_render_pass)(cb);
            close_pass(&d, cb);
        }
    })
}

unsafe extern "system" fn cmd_end_render_pass2(
    cb: vk::CommandBuffer,
    end: *const vk::SubpassEndInfo<'_>,
) {
    guard("vkCmdEndRenderPass2", (), || {
        // SAFETY: the caller's arguments, forwarded unchanged; the double's own commands follow.
        unsafe {
            let d = device_of(cb.as_raw());
            if let Some(e) = end.as_ref() {
                crate::strict::chain("vkCmdEndRenderPass2", e.p_next);
            }
            (d.fns.fp_v1_2().cmd_end_render_pass2)(cb, end);
            close_pass(&d, cb);
        }
    })
}

unsafe extern "system" fn cmd_end_rendering(cb: vk::CommandBuffer) {
    guard("vkCmdEndRendering", (), || {
        // SAFETY: the caller's arguments, forwarded unchanged.
        unsafe {
            let d = device_of(cb.as_raw());
            (d.fns.fp_v1_3().cmd_end_rendering)(cb);
            close_pass(&d, cb);
        }
    })
}

macro_rules! draw_hook {
    ($f:ident, $name:literal, $table:ident . $field:ident ($($a:ident: $t:ty),*)) => {
        unsafe extern "system" fn $f(cb: vk::CommandBuffer $(, $a: $t)*) {
            guard($name, (), || {
                // SAFETY: the caller's arguments, forwarded unchanged.
                unsafe {
                    let d = device_of(cb.as_raw());
                    note_draw(&d, cb);
                    (d.fns.$table().$field)(cb $(, $a)*);
                }
            })
        }
    };
}

draw_hook!(cmd_draw, "vkCmdDraw", fp_v1_0.cmd_draw(
    vertices: u32, instances: u32, first_vertex: u32, first_instance: u32));
draw_hook!(cmd_draw_indexed, "vkCmdDrawIndexed", fp_v1_0.cmd_draw_indexed(
    indices: u32, instances: u32, first_index: u32, offset: i32, first_instance: u32));
draw_hook!(cmd_draw_indirect, "vkCmdDrawIndirect", fp_v1_0.cmd_draw_indirect(
    buffer: vk::Buffer, offset: vk::DeviceSize, count: u32, stride: u32));
draw_hook!(cmd_draw_indexed_indirect, "vkCmdDrawIndexedIndirect",
    fp_v1_0.cmd_draw_indexed_indirect(
    buffer: vk::Buffer, offset: vk::DeviceSize, count: u32, stride: u32));
draw_hook!(cmd_draw_indirect_count, "vkCmdDrawIndirectCount", fp_v1_2.cmd_draw_indirect_count(
    buffer: vk::Buffer, offset: vk::DeviceSize, count_buffer: vk::Buffer,
    count_offset: vk::DeviceSize, max: u32, stride: u32));
draw_hook!(cmd_draw_indexed_indirect_count, "vkCmdDrawIndexedIndirectCount",
    fp_v1_2.cmd_draw_indexed_indirect_count(
    buffer: vk::Buffer, offset: vk::DeviceSize, count_buffer: vk::Buffer,
    count_offset: vk::DeviceSize, max: u32, stride: u32));

// ---------------------------------------------------------------------------------------------
// Strictness: what a driver without fragment density maps refuses (`crate::strict`).

/// A render pass 2's density-map enums and structs, and a shading-rate attachment without the
/// feature.
///
/// # Safety
/// `ci` must be valid.
unsafe fn check_render_pass2(d: &DeviceData, ci: &vk::RenderPassCreateInfo2<'_>) {
    let what = "vkCreateRenderPass2";
    // SAFETY: the caller's promise.
    unsafe {
        crate::strict::chain(what, ci.p_next);
        for a in slice(ci.p_attachments, ci.attachment_count) {
            crate::strict::chain(what, a.p_next);
            crate::strict::layout(what, a.initial_layout);
            crate::strict::layout(what, a.final_layout);
        }
        for s in slice(ci.p_subpasses, ci.subpass_count) {
            crate::strict::chain(what, s.p_next);
            let refs = slice(s.p_input_attachments, s.input_attachment_count)
                .iter()
                .chain(slice(s.p_color_attachments, s.color_attachment_count))
                .chain(if s.p_resolve_attachments.is_null() {
                    &[][..]
                } else {
                    slice(s.p_resolve_attachments, s.color_attachment_count)
                })
                .chain(s.p_depth_stencil_attachment.as_ref());
            for r in refs {
                crate::strict::layout(what, r.layout);
            }
            let fsr = find::<vk::FragmentShadingRateAttachmentInfoKHR>(s.p_next)
                .and_then(|f| (*f).p_fragment_shading_rate_attachment.as_ref())
                .filter(|r| r.attachment != vk::ATTACHMENT_UNUSED);
            if fsr.is_some() && !d.attachment_feature {
                error(format!(
                    "{what}: a shading-rate attachment without the attachmentFragmentShadingRate \
                     feature"
                ));
            }
        }
        for dep in slice(ci.p_dependencies, ci.dependency_count) {
            crate::strict::barrier(
                what,
                [
                    dep.src_stage_mask.as_raw() as u64,
                    dep.dst_stage_mask.as_raw() as u64,
                ],
                [
                    dep.src_access_mask.as_raw() as u64,
                    dep.dst_access_mask.as_raw() as u64,
                ],
            );
            // A VkMemoryBarrier2 chained to the dependency replaces its masks
            // (VK_KHR_synchronization2).
            if let Some(m) = find::<vk::MemoryBarrier2>(dep.p_next) {
                let m = &*m;
                crate::strict::barrier(
                    what,
                    [m.src_stage_mask.as_raw(), m.dst_stage_mask.as_raw()],
                    [m.src_access_mask.as_raw(), m.dst_access_mask.as_raw()],
                );
            }
        }
    }
}

unsafe extern "system" fn create_render_pass(
    device: vk::Device,
    info: *const vk::RenderPassCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::RenderPass,
) -> vk::Result {
    guard("vkCreateRenderPass", vk::Result::ERROR_UNKNOWN, || {
        if let Some(r) = record::fault("vkCreateRenderPass") {
            return r;
        }
        // SAFETY: the caller's create info is read and forwarded unchanged.
        unsafe {
            let d = device_of(device.as_raw());
            let ci = &*info;
            let what = "vkCreateRenderPass";
            crate::strict::chain(what, ci.p_next);
            for a in slice(ci.p_attachments, ci.attachment_count) {
                crate::strict::layout(what, a.initial_layout);
                crate::strict::layout(what, a.final_layout);
            }
            for s in slice(ci.p_subpasses, ci.subpass_count) {
                let refs = slice(s.p_input_attachments, s.input_attachment_count)
                    .iter()
                    .chain(slice(s.p_color_attachments, s.color_attachment_count))
                    .chain(if s.p_resolve_attachments.is_null() {
                        &[][..]
                    } else {
                        slice(s.p_resolve_attachments, s.color_attachment_count)
                    })
                    .chain(s.p_depth_stencil_attachment.as_ref());
                for r in refs {
                    crate::strict::layout(what, r.layout);
                }
            }
            for dep in slice(ci.p_dependencies, ci.dependency_count) {
                crate::strict::barrier(
                    what,
                    [
                        dep.src_stage_mask.as_raw() as u64,
                        dep.dst_stage_mask.as_raw() as u64,
                    ],
                    [
                        dep.src_access_mask.as_raw() as u64,
                        dep.dst_access_mask.as_raw() as u64,
                    ],
                );
            }
            let attachments: Vec<vk::AttachmentDescription> =
                slice(ci.p_attachments, ci.attachment_count)
                    .iter()
                    .map(|a| {
                        let mut a = *a;
                        a.load_op = fix_load(a.load_op);
                        a.stencil_load_op = fix_load(a.stencil_load_op);
                        a
                    })
                    .collect();
            let mut copy = *ci;
            if !ci.p_attachments.is_null() {
                copy.p_attachments = attachments.as_ptr();
            }
            (d.fns.fp_v1_0().create_render_pass)(device, &copy, alloc, out)
        }
    })
}

unsafe extern "system" fn create_sampler(
    device: vk::Device,
    info: *const vk::SamplerCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Sampler,
) -> vk::Result {
    guard("vkCreateSampler", vk::Result::ERROR_UNKNOWN, || {
        if let Some(r) = record::fault("vkCreateSampler") {
            return r;
        }
        // SAFETY: the caller's create info is read and forwarded unchanged.
        unsafe {
            let d = device_of(device.as_raw());
            let ci = &*info;
            crate::strict::chain("vkCreateSampler", ci.p_next);
            crate::strict::flag(
                "vkCreateSampler",
                ci.flags.intersects(
                    vk::SamplerCreateFlags::SUBSAMPLED_EXT
                        | vk::SamplerCreateFlags::SUBSAMPLED_COARSE_RECONSTRUCTION_EXT,
                ),
                "a subsampled sampler",
            );
            (d.fns.fp_v1_0().create_sampler)(device, info, alloc, out)
        }
    })
}

unsafe extern "system" fn cmd_set_event(
    cb: vk::CommandBuffer,
    event_: vk::Event,
    stage: vk::PipelineStageFlags,
) {
    guard("vkCmdSetEvent", (), || {
        crate::strict::stage("vkCmdSetEvent", stage.as_raw() as u64);
        // SAFETY: the caller's arguments, forwarded unchanged.
        unsafe {
            let d = device_of(cb.as_raw());
            (d.fns.fp_v1_0().cmd_set_event)(cb, event_, stage);
        }
    })
}

unsafe extern "system" fn cmd_reset_event(
    cb: vk::CommandBuffer,
    event_: vk::Event,
    stage: vk::PipelineStageFlags,
) {
    guard("vkCmdResetEvent", (), || {
        crate::strict::stage("vkCmdResetEvent", stage.as_raw() as u64);
        // SAFETY: the caller's arguments, forwarded unchanged.
        unsafe {
            let d = device_of(cb.as_raw());
            (d.fns.fp_v1_0().cmd_reset_event)(cb, event_, stage);
        }
    })
}

unsafe extern "system" fn cmd_write_timestamp(
    cb: vk::CommandBuffer,
    stage: vk::PipelineStageFlags,
    pool: vk::QueryPool,
    query: u32,
) {
    guard("vkCmdWriteTimestamp", (), || {
        crate::strict::stage("vkCmdWriteTimestamp", stage.as_raw() as u64);
        // SAFETY: the caller's arguments, forwarded unchanged.
        unsafe {
            let d = device_of(cb.as_raw());
            (d.fns.fp_v1_0().cmd_write_timestamp)(cb, stage, pool, query);
        }
    })
}

#[allow(clippy::too_many_arguments)]
unsafe extern "system" fn cmd_wait_events(
    cb: vk::CommandBuffer,
    count: u32,
    events: *const vk::Event,
    src: vk::PipelineStageFlags,
    dst: vk::PipelineStageFlags,
    memory_count: u32,
    memory: *const vk::MemoryBarrier<'_>,
    buffer_count: u32,
    buffers: *const vk::BufferMemoryBarrier<'_>,
    image_count: u32,
    images: *const vk::ImageMemoryBarrier<'_>,
) {
    guard("vkCmdWaitEvents", (), || {
        // SAFETY: the caller's arguments, read and forwarded unchanged.
        unsafe {
            let what = "vkCmdWaitEvents";
            crate::strict::stage(what, src.as_raw() as u64);
            crate::strict::stage(what, dst.as_raw() as u64);
            for b in slice(memory, memory_count) {
                crate::strict::access(what, b.src_access_mask.as_raw() as u64);
                crate::strict::access(what, b.dst_access_mask.as_raw() as u64);
            }
            for b in slice(buffers, buffer_count) {
                crate::strict::access(what, b.src_access_mask.as_raw() as u64);
                crate::strict::access(what, b.dst_access_mask.as_raw() as u64);
            }
            for b in slice(images, image_count) {
                crate::strict::access(what, b.src_access_mask.as_raw() as u64);
                crate::strict::access(what, b.dst_access_mask.as_raw() as u64);
                crate::strict::layout(what, b.old_layout);
                crate::strict::layout(what, b.new_layout);
            }
            let d = device_of(cb.as_raw());
            (d.fns.fp_v1_0().cmd_wait_events)(
                cb,
                count,
                events,
                src,
                dst,
                memory_count,
                memory,
                buffer_count,
                buffers,
                image_count,
                images,
            );
        }
    })
}

unsafe extern "system" fn cmd_set_event2(
    cb: vk::CommandBuffer,
    event_: vk::Event,
    info: *const vk::DependencyInfo<'_>,
) {
    guard("vkCmdSetEvent2", (), || {
        // SAFETY: the caller's arguments, read and forwarded unchanged.
        unsafe {
            crate::strict::dependency("vkCmdSetEvent2", &*info);
            let d = device_of(cb.as_raw());
            (d.fns.fp_v1_3().cmd_set_event2)(cb, event_, info);
        }
    })
}

unsafe extern "system" fn cmd_reset_event2(
    cb: vk::CommandBuffer,
    event_: vk::Event,
    stage: vk::PipelineStageFlags2,
) {
    guard("vkCmdResetEvent2", (), || {
        crate::strict::stage("vkCmdResetEvent2", stage.as_raw());
        // SAFETY: the caller's arguments, forwarded unchanged.
        unsafe {
            let d = device_of(cb.as_raw());
            (d.fns.fp_v1_3().cmd_reset_event2)(cb, event_, stage);
        }
    })
}

unsafe extern "system" fn cmd_write_timestamp2(
    cb: vk::CommandBuffer,
    stage: vk::PipelineStageFlags2,
    pool: vk::QueryPool,
    query: u32,
) {
    guard("vkCmdWriteTimestamp2", (), || {
        crate::strict::stage("vkCmdWriteTimestamp2", stage.as_raw());
        // SAFETY: the caller's arguments, forwarded unchanged.
        unsafe {
            let d = device_of(cb.as_raw());
            (d.fns.fp_v1_3().cmd_write_timestamp2)(cb, stage, pool, query);
        }
    })
}

unsafe extern "system" fn cmd_wait_events2(
    cb: vk::CommandBuffer,
    count: u32,
    events: *const vk::Event,
    infos: *const vk::DependencyInfo<'_>,
) {
    guard("vkCmdWaitEvents2", (), || {
        // SAFETY: the caller's arguments, read and forwarded unchanged.
        unsafe {
            for i in slice(infos, count) {
                crate::strict::dependency("vkCmdWaitEvents2", i);
            }
            let d = device_of(cb.as_raw());
            (d.fns.fp_v1_3().cmd_wait_events2)(cb, count, events, infos);
        }
    })
}
