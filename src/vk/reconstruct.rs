//! Reconstruction of coarse blocks (docs/reconstruction.md): after an eye pass on a device with
//! shading-rate attachments from fovea, each coarse block of its colour target becomes what a
//! compositor's bilinear sample of a subsampled image gives, and full-rate texels stay as they
//! are. Where the pass begins, `crate::vk::injection` notes what its end reconstructs in the
//! command buffer's record ([`Plan`](crate::vk::own::reconstructor::Plan)); the end hooks call
//! [`ended`] after the end went down, which records the copies and the dispatch
//! ([`Reconstructor::record`]).
//!
//! Objects: the pipeline and layouts at device creation ([`device_created`]); scratch buffers at
//! the first pass of a target size, kept with the device. Per end of a pass that reconstructs
//! nothing: the command buffer's record (this thread's cache) and one uncontended lock of its
//! own; no allocation and no process-wide lock.

use std::sync::Arc;

use ash::vk;

use crate::vk::base::ffi::{key, raw};
use crate::vk::own::reconstructor::Reconstructor;
use crate::vk::registry::{self, record_of, RECONSTRUCTORS};

/// Sets up reconstruction on a device just recorded in the registry that injects shading-rate
/// maps, or logs why not. `why_not`: why the device cannot record compute dispatches into the
/// application's command buffers and give its bindings back, as the converter found.
///
/// # Safety
/// `handle` must be a live device just recorded.
pub unsafe fn device_created(handle: vk::Device, why_not: Option<String>) {
    // SAFETY: as the caller promised.
    let Some(dev) = (unsafe { registry::device(handle) }) else {
        return;
    };
    let (Some(inj), Some(own)) = (&dev.inject, &dev.attachments.own) else {
        return;
    };
    if let Some(why) = why_not {
        tracing::info!(
            device = raw(handle),
            why = why.as_str(),
            "coarse blocks are not reconstructed on this device"
        );
        return;
    }
    // SAFETY: the layer's own objects on a live device.
    match unsafe { Reconstructor::new(Arc::clone(own), &inj.fdm) } {
        Ok(r) => {
            // SAFETY: as the caller promised.
            let Some(k) = (unsafe { key(handle) }) else {
                // SAFETY: made on this live device, used by nothing yet.
                unsafe { r.destroy() };
                return;
            };
            let mut v = RECONSTRUCTORS.write();
            v.retain(|(key, _)| *key != k);
            v.push((k, Arc::new(r)));
        }
        Err(e) => tracing::warn!(
            device = raw(handle),
            result = ?e,
            "coarse blocks are not reconstructed on this device: its objects could not be made"
        ),
    }
}

/// Destroys a device's reconstruction objects; the device is about to be destroyed, and its
/// command buffers' records are gone.
///
/// # Safety
/// `handle` must be live and idle.
pub unsafe fn device_destroyed(handle: vk::Device) {
    // SAFETY: as the caller promised.
    let Some(k) = (unsafe { key(handle) }) else {
        return;
    };
    let r = {
        let mut v = RECONSTRUCTORS.write();
        let at = v.iter().position(|(key, _)| *key == k);
        at.map(|i| v.swap_remove(i).1)
    };
    if let Some(r) = r {
        // SAFETY: as the caller promised.
        unsafe { r.destroy() };
    }
}

/// What the layer kept for a device gone without `vkDestroyDevice` is dropped without a call.
pub fn device_key_reused(k: crate::vk::base::ffi::Key) {
    RECONSTRUCTORS.write().retain(|(key, _)| *key != k);
}

/// The end of a render pass instance just went down in `cb` (`vkCmdEndRenderPass(2)`,
/// `vkCmdEndRendering(2)`): where its begin planned a reconstruction and the end is not a
/// suspending one, it is recorded now.
pub fn ended(cb: vk::CommandBuffer) {
    record_of(cb, |r| {
        let Some(rc) = r.reconstructor.as_deref() else {
            return;
        };
        let plan = {
            let mut p = r.plan.lock();
            match *p {
                Some(plan) if !plan.suspending => {
                    *p = None;
                    plan
                }
                _ => return,
            }
        };
        let bound = Some(*r.bound.lock()).filter(|b| !b.lost);
        // SAFETY: `cb` is recording outside a render pass (its instance just ended), on the
        // reconstructor's device; `bound` is its bindings.
        unsafe { rc.record(cb, &plan, bound.as_ref()) };
    });
}
