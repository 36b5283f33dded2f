//! Drawing the effect of coarse fragments where a GPU leaves it: at the end of each pass instance,
//! in the command buffer, so that every later command (a read-back in the same command buffer, a
//! later pass, a layer's own pass that post-processes the colour) sees the blocks.
//!
//! Lavapipe shades every pixel. A GPU with shading-rate attachments shades one value per
//! fragment and writes it to every covered pixel of the fragment, so when the pass instance ends
//! its colour attachments hold blocks, and so do the resolve targets of its multisampled ones
//! (every sample of a fragment's pixels got the fragment's colour); the multisampled images
//! themselves are not coarsened here (a buffer copy cannot read them). The double cannot shade coarsely, and the rates each texel
//! gets depend on the shading-rate attachment's contents, which the command buffer may write
//! itself before the pass (a layer's converter does), so they are known only when the commands
//! run. So after each pass instance that could shade coarsely the double records, in the
//! application's command buffer and straight to lavapipe (validation above never sees it):
//! copies of the pass's colour layers into buffers of its own, `vkCmdSetEvent(ready)`,
//! `vkCmdWaitEvents(done)` with the host as source, and copies back. At submit a thread of the
//! double waits for each `ready` in execution order, computes from the attachment's snapshot
//! (copied in front of the pass, [`super::snapshot`]) the finest fragment size any draw of the
//! pass got per texel, gives each block the value its fragment's shader computes at the
//! fragment's centre ([`super::centre`]) in the buffer, and sets `done` (the host may signal an
//! event a command buffer waits on after the submit, outside a render pass: "vkCmdWaitEvents",
//! VUID-vkCmdWaitEvents-pEvents-01163,
//! <https://registry.khronos.org/vulkan/specs/latest/man/html/vkCmdWaitEvents.html>). Lavapipe
//! executes a command buffer's commands in order on the CPU, so the copy back runs after the host
//! finished.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use ash::vk::{self, Handle as _};
use serde_json::json;

use super::centre::{self, Codec};
use super::{
    full_barrier, host_buffer, lock, pixel_bytes, subresource, view_rates, Codes, ColourTarget,
    DeviceData, PassRec, Snapshot,
};
use crate::record::{error, event};

/// What the double recorded after one pass instance.
pub(super) struct PassEnd {
    /// Set by the command buffer once the colour layers are in the buffers.
    ready: vk::Event,
    /// Set by the host once they are coarsened; the command buffer waits for it.
    done: vk::Event,
    /// The pass instance whose draws decide (a suspended rendering's parts merged in).
    pass: PassRec,
    /// Per colour layer: the target, the layer, the view whose rates decide it, its buffer.
    layers: Vec<(ColourTarget, u32, u32, Snapshot)>,
}

/// One entry of a recording's pass ends, in recording order.
pub(super) enum End {
    Own(PassEnd),
    /// `vkCmdExecuteCommands` of this secondary: its own ends run here.
    Secondary(u64),
}

/// Frees what a pass end owns.
///
/// # Safety
/// Its command buffer must not be pending.
pub(super) unsafe fn free(d: &DeviceData, e: PassEnd) {
    // SAFETY: the double's own objects, no longer in use (the caller's promise).
    unsafe {
        d.fns.destroy_event(e.ready, None);
        d.fns.destroy_event(e.done, None);
        for (_, _, _, b) in e.layers {
            d.fns.destroy_buffer(b.buffer, None);
            d.fns.free_memory(b.memory, None);
        }
    }
}

/// The views a pass's subpasses render (view 0 without multiview).
fn views_of(pass: &PassRec) -> Vec<u32> {
    let mask = pass.subpasses.iter().fold(0, |m, s| m | s.1);
    if mask == 0 {
        vec![0]
    } else {
        (0..32).filter(|v| mask & (1 << v) != 0).collect()
    }
}

/// Records, after the pass instance `pass` just ended on `cb`, the round trip that leaves its
/// colour coarse; `None` where no draw of it can shade coarser than 1×1 (nothing recorded, so a
/// pass without foveation costs nothing) or no colour layer has a format the double handles.
///
/// # Safety
/// `cb` must be recording outside a pass, on `d`.
pub(super) unsafe fn end_pass(
    d: &DeviceData,
    cb: vk::CommandBuffer,
    pass: PassRec,
) -> Option<PassEnd> {
    let rates = d.instance.profile.fragment_sizes();
    let coarse = pass.draws.iter().any(|dr| {
        pass.subpasses
            .get(dr.subpass as usize)
            .is_some_and(|s| s.0.is_some())
            && (0..16u8).any(|c| dr.rate.effective(crate::shade::decode(c), &rates) != [1, 1])
    });
    if !coarse {
        return None;
    }
    let mask = pass.subpasses.iter().fold(0, |m, s| m | s.1);
    let mut layers = Vec::new();
    for target in &pass.colours {
        let Some(bpp) = pixel_bytes(target.format) else {
            continue;
        };
        for v in views_of(&pass) {
            let layer = target.base_layer + if mask == 0 { 0 } else { v };
            let e = target.extent;
            let size = e.width as u64 * e.height as u64 * bpp;
            let usage = vk::BufferUsageFlags::TRANSFER_SRC | vk::BufferUsageFlags::TRANSFER_DST;
            // SAFETY: `d` is live.
            match unsafe { host_buffer(d, size, usage) } {
                Ok(b) => layers.push((*target, layer, v, b)),
                Err(e) => error(format!("coarse shading: no buffer: {e:?}")),
            }
        }
    }
    let event_info = vk::EventCreateInfo::default();
    // SAFETY: plain creations on a live device.
    let events = unsafe {
        d.fns.create_event(&event_info, None).and_then(|a| {
            match d.fns.create_event(&event_info, None) {
                Ok(b) => Ok((a, b)),
                Err(e) => {
                    d.fns.destroy_event(a, None);
                    Err(e)
                }
            }
        })
    };
    let (ready, done) = match events {
        Ok(ev) if !layers.is_empty() => ev,
        other => {
            if let Err(e) = other {
                error(format!("coarse shading: no event: {e:?}"));
            }
            let end = PassEnd {
                ready: other.map_or(vk::Event::null(), |e| e.0),
                done: other.map_or(vk::Event::null(), |e| e.1),
                pass,
                layers,
            };
            // SAFETY: nothing recorded uses them.
            unsafe { free(d, end) };
            return None;
        }
    };
    let region = |e: vk::Extent2D, layer: u32| {
        vk::BufferImageCopy::default()
            .image_subresource(subresource(layer, 1))
            .image_extent(vk::Extent3D {
                width: e.width,
                height: e.height,
                depth: 1,
            })
    };
    let f = d.fns.fp_v1_0();
    // SAFETY: the caller's promise; the images got TRANSFER_SRC and TRANSFER_DST when the double
    // created them; lavapipe ignores layouts.
    unsafe {
        full_barrier(d, cb);
        for (t, layer, _, b) in &layers {
            (f.cmd_copy_image_to_buffer)(
                cb,
                vk::Image::from_raw(t.image),
                vk::ImageLayout::GENERAL,
                b.buffer,
                1,
                &region(t.extent, *layer),
            );
        }
        full_barrier(d, cb);
        (f.cmd_set_event)(cb, ready, vk::PipelineStageFlags::ALL_COMMANDS);
        let host = vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::HOST_WRITE)
            .dst_access_mask(vk::AccessFlags::TRANSFER_READ);
        (f.cmd_wait_events)(
            cb,
            1,
            &done,
            vk::PipelineStageFlags::HOST,
            vk::PipelineStageFlags::ALL_COMMANDS,
            1,
            &host,
            0,
            std::ptr::null(),
            0,
            std::ptr::null(),
        );
        for (t, layer, _, b) in &layers {
            (f.cmd_copy_buffer_to_image)(
                cb,
                b.buffer,
                vk::Image::from_raw(t.image),
                vk::ImageLayout::GENERAL,
                1,
                &region(t.extent, *layer),
            );
        }
        full_barrier(d, cb);
    }
    Some(PassEnd {
        ready,
        done,
        pass,
        layers,
    })
}

/// One pass end as the worker handles it.
struct Job {
    ready: vk::Event,
    done: vk::Event,
    pass: PassRec,
    layers: Vec<(ColourTarget, u32, u32, Snapshot)>,
}

/// The pass ends of `cbs` in execution order, secondaries' where they are executed.
fn jobs_of(d: &DeviceData, cbs: &[u64]) -> Vec<Job> {
    fn walk(st: &super::DeviceState, cb: u64, depth: u32, out: &mut Vec<Job>) {
        let Some(r) = st.recordings.get(&cb) else {
            return;
        };
        for e in &r.ends {
            match e {
                End::Own(p) => out.push(Job {
                    ready: p.ready,
                    done: p.done,
                    pass: p.pass.clone(),
                    layers: p.layers.clone(),
                }),
                End::Secondary(s) if depth == 0 => walk(st, *s, 1, out),
                End::Secondary(_) => {}
            }
        }
    }
    let st = lock(&d.state);
    let mut out = Vec::new();
    for &cb in cbs {
        walk(&st, cb, 0, &mut out);
    }
    out
}

/// The worker of one submit, joined after the submit went down.
pub(super) struct Worker {
    thread: std::thread::JoinHandle<()>,
    abort: Arc<AtomicBool>,
}

/// Before a submit of `cbs` goes down: resets their pass ends' events and starts the thread that
/// coarsens between them; `None` where they have none.
///
/// # Safety
/// The command buffers' earlier submits must have completed (the double waits for every submit
/// with draws).
pub(super) unsafe fn start(d: &Arc<DeviceData>, cbs: &[u64]) -> Option<Worker> {
    let jobs = jobs_of(d, cbs);
    if jobs.is_empty() {
        return None;
    }
    for j in &jobs {
        // SAFETY: the double's own events, not in use (the caller's promise).
        let r = unsafe {
            d.fns
                .reset_event(j.ready)
                .and_then(|()| d.fns.reset_event(j.done))
        };
        if let Err(e) = r {
            error(format!("coarse shading: resetting an event failed: {e:?}"));
        }
    }
    let abort = Arc::new(AtomicBool::new(false));
    let (dd, flag) = (Arc::clone(d), Arc::clone(&abort));
    let thread = std::thread::Builder::new()
        .name("vkdouble-coarse".into())
        .spawn(move || {
            // SAFETY: the jobs' objects live until their command buffers are recorded anew,
            // which waits for this submit.
            let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| unsafe {
                work(&dd, &jobs, &flag)
            }));
            // Whatever happened, no command buffer may wait forever.
            for j in &jobs {
                // SAFETY: as above.
                let _ = unsafe { dd.fns.set_event(j.done) };
            }
        });
    match thread {
        Ok(thread) => Some(Worker { thread, abort }),
        Err(e) => {
            error(format!("coarse shading: no thread: {e}"));
            None
        }
    }
}

/// After the submit went down (`ok`: it was accepted): waits for the worker.
pub(super) fn finish(w: Worker, ok: bool) {
    if !ok {
        w.abort.store(true, Ordering::Relaxed);
    }
    if w.thread.join().is_err() {
        error("coarse shading: the worker panicked".into());
    }
}

/// How long the worker waits for one pass end to be reached.
const PATIENCE: Duration = Duration::from_secs(120);

/// # Safety
/// As [`start`]'s thread.
unsafe fn work(d: &DeviceData, jobs: &[Job], abort: &AtomicBool) {
    let rates = d.instance.profile.fragment_sizes();
    for j in jobs {
        let since = Instant::now();
        loop {
            // SAFETY: the double's own event.
            match unsafe { d.fns.get_event_status(j.ready) } {
                Ok(true) => break,
                Ok(false) if abort.load(Ordering::Relaxed) => return,
                Ok(false) if since.elapsed() > PATIENCE => {
                    error("coarse shading: a pass end was never reached".into());
                    return;
                }
                Ok(false) => std::thread::sleep(Duration::from_micros(50)),
                Err(e) => {
                    error(format!("coarse shading: event status: {e:?}"));
                    return;
                }
            }
        }
        // SAFETY: the copies out completed before `ready` was set.
        unsafe { coarsen_job(d, j, &rates) };
        // SAFETY: the double's own event.
        if let Err(e) = unsafe { d.fns.set_event(j.done) } {
            error(format!("coarse shading: setting an event failed: {e:?}"));
        }
    }
}

/// Per view of a pass: the attachment texel size, the columns of the grid and, per texel, the
/// finest effective size any of its draws got.
type Finest = (vk::Extent2D, u32, Vec<u8>);

/// The finest effective size per texel of view `v` over the draws of `pass`, from the
/// attachments' snapshots; `None` where no draw of that view had an attachment.
///
/// # Safety
/// The snapshots' copies must have completed.
unsafe fn finest(
    d: &DeviceData,
    pass: &PassRec,
    v: u32,
    rates: &[[u32; 2]],
    read: &mut BTreeMap<u64, Vec<u8>>,
) -> Option<Finest> {
    let mut out: Option<Finest> = None;
    for draw in &pass.draws {
        let Some(&(Some(a), mask)) = pass.subpasses.get(draw.subpass as usize) else {
            continue;
        };
        if (mask == 0 && v != 0) || (mask != 0 && mask & (1 << v) == 0) {
            continue;
        }
        let Some(s) = a.snapshot else { continue };
        // SAFETY: the caller's promise.
        let bytes = read
            .entry(s.buffer.as_raw())
            .or_insert_with(|| unsafe { super::read_snapshot(d, s) });
        let layer = if a.layers > 1 && mask != 0 { v } else { 0 };
        let texels = (a.extent.width * a.extent.height) as usize;
        let start = (layer.min(a.layers - 1) as usize) * texels;
        let codes = Codes {
            bytes: bytes.get(start..start + texels).unwrap_or(&[]),
            extent: a.extent,
        };
        let (columns, _, grid) = view_rates(&codes, a.texel, pass.area, draw.rate, rates);
        let f = out.get_or_insert_with(|| (a.texel, columns, grid.clone()));
        for (o, &g) in f.2.iter_mut().zip(&grid) {
            let (oa, ga) = (crate::shade::decode(*o), crate::shade::decode(g));
            if ga[0] * ga[1] < oa[0] * oa[1] {
                *o = g;
            }
        }
    }
    out
}

/// Coarsens one pass end's buffers.
///
/// # Safety
/// Its copies out and the snapshots' copies must have completed.
unsafe fn coarsen_job(d: &DeviceData, j: &Job, rates: &[[u32; 2]]) {
    let mut read = BTreeMap::new();
    for (target, layer, v, b) in &j.layers {
        // SAFETY: the caller's promise.
        let Some((texel, columns, codes)) = (unsafe { finest(d, &j.pass, *v, rates, &mut read) })
        else {
            continue;
        };
        if !codes.iter().any(|&c| c != 0) {
            continue;
        }
        let Some(codec) = Codec::of(target.format) else {
            continue;
        };
        // SAFETY: the double's own host-visible memory, not in use by the device now.
        unsafe {
            match d
                .fns
                .map_memory(b.memory, 0, b.size, vk::MemoryMapFlags::empty())
            {
                Ok(p) => {
                    let pixels = std::slice::from_raw_parts_mut(p as *mut u8, b.size as usize);
                    coarsen(
                        target.extent,
                        j.pass.area,
                        texel,
                        columns,
                        &codes,
                        pixels,
                        codec,
                    );
                    d.fns.unmap_memory(b.memory);
                }
                Err(e) => {
                    error(format!("coarse shading: mapping failed: {e:?}"));
                    continue;
                }
            }
        }
        event(json!({
            "kind": "coarsened",
            "image": target.image,
            "layer": layer,
        }));
    }
}

/// Gives every block the value its fragment's shader computes at the fragment's centre
/// ([`centre`]: the mean of the pixels nearest it), per attachment texel: the block is the
/// finest fragment size at that texel (`codes`, `columns` texels a row), within the render
/// area.
fn coarsen(
    e: vk::Extent2D,
    area: vk::Extent2D,
    texel: vk::Extent2D,
    columns: u32,
    codes: &[u8],
    pixels: &mut [u8],
    codec: Codec,
) {
    let bpp = codec.bytes();
    let right = area.width.min(e.width);
    let bottom = area.height.min(e.height);
    let row = e.width as usize * bpp;
    for (i, &code) in codes.iter().enumerate() {
        if code == 0 {
            continue;
        }
        let [w, h] = crate::shade::decode(code);
        let (tx, ty) = (i as u32 % columns, i as u32 / columns);
        let x0 = tx * texel.width;
        let y0 = ty * texel.height;
        let x1 = (x0 + texel.width).min(right);
        let y1 = (y0 + texel.height).min(bottom);
        for by in (y0..y1).step_by(h as usize) {
            let (bh, ys) = (
                (by + h).min(y1) - by,
                centre::middle(h, (by + h).min(y1) - by),
            );
            for bx in (x0..x1).step_by(w as usize) {
                let (bw, xs) = (
                    (bx + w).min(x1) - bx,
                    centre::middle(w, (bx + w).min(x1) - bx),
                );
                let mut value = [0u8; 16];
                let mut at = [0usize; 4];
                let mut n = 0;
                for &y in &ys[..1 + usize::from(ys[0] != ys[1])] {
                    for &x in &xs[..1 + usize::from(xs[0] != xs[1])] {
                        at[n] = (by + y) as usize * row + (bx + x) as usize * bpp;
                        n += 1;
                    }
                }
                codec.mean_at(pixels, &at[..n], &mut value);
                for y in by..by + bh {
                    for x in bx..bx + bw {
                        let at = y as usize * row + x as usize * bpp;
                        pixels[at..at + bpp].copy_from_slice(&value[..bpp]);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 6×5 image, red = 10 x, green = 10 y, in one 8×8 shading-rate texel of `code`.
    fn coarsened(code: u8) -> Vec<[u8; 4]> {
        let (w, h) = (6u32, 5u32);
        let mut pixels: Vec<u8> = (0..w * h)
            .flat_map(|i| [(i % w * 10) as u8, (i / w * 10) as u8, 7, 255])
            .collect();
        let e = vk::Extent2D {
            width: w,
            height: h,
        };
        let texel = vk::Extent2D {
            width: 8,
            height: 8,
        };
        let codec = Codec::of(vk::Format::R8G8B8A8_UNORM).unwrap();
        coarsen(e, e, texel, 1, &[code], &mut pixels, codec);
        pixels.chunks(4).map(|p| [p[0], p[1], p[2], p[3]]).collect()
    }

    #[test]
    fn a_block_gets_the_value_at_its_centre_and_a_cut_block_that_of_its_written_pixels_nearest_it()
    {
        let px = coarsened(0b1010); // 4×4
        let at = |x: usize, y: usize| px[y * 6 + x];
        for y in 0..5 {
            for x in 0..6 {
                // Whole block (0..4): the mean of columns and rows 1 and 2, i.e. 15 (the value at
                // 2.0, its centre; its top-left pixel has 0). Cut blocks (columns 4..6, row 4):
                // the written pixel nearest the centre (column 5, row 4).
                let r = if x < 4 { 15 } else { 50 };
                let g = if y < 4 { 15 } else { 40 };
                assert_eq!(at(x, y), [r, g, 7, 255], "({x},{y})");
            }
        }
        let px = coarsened(0b0100); // 2×1
        for y in 0..5 {
            for x in 0..6 {
                let r = (x / 2 * 20 + 5) as u8;
                assert_eq!(px[y * 6 + x], [r, (y * 10) as u8, 7, 255], "({x},{y})");
            }
        }
    }
}
