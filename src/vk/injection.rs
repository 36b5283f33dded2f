//! Injection's modes (docs/injection.md#how-the-attachment-gets-in): on an injecting device, render
//! passes and framebuffers get a shading-rate attachment of the layer's own after the
//! application's, and an eye pass's begin names the injected map ([`crate::vk::own::injector`]).

use std::ffi::c_void;

use ash::vk;
use ash::vk::Handle as _;

use crate::vk::base::chain::{self, ChainCopy};
use crate::vk::base::ffi::{raw, slice};
use crate::vk::own::reconstructor::{rate_layers, Colour, Plan};
use crate::vk::registry::{self, Device};
use crate::vk::translate::formats::{SHADOW_FORMAT, SHADOW_LAYOUT, SHADOW_USAGE};
use crate::vk::translate::render_pass::{
    add_shading_rate, pass_colours, rate_store_op, rendering_target, too_many_targets, Pass2,
    MAX_TARGETS,
};

/// On an injecting device (docs/injection.md#how-the-attachment-gets-in): creates `pass` below with
/// a shading-rate attachment added after the application's, named by every subpass; whether a
/// framebuffer's pass is an eye pass is not known yet, and compatibility of render passes would
/// not let a framebuffer or pipeline made for one pass serve the other
/// (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#renderpass-compatibility>).
/// Where the driver refuses the rewritten pass, the application's goes down as it came (fail
/// open: its framebuffers are then left alone).
///
/// # Safety
/// As `create_rewritten` in [`crate::vk::hooks::pass`].
#[allow(clippy::too_many_arguments)]
pub unsafe fn create_injected(
    dev: &Device,
    inj: &crate::vk::own::injector::Injector,
    create2: vk::PFN_vkCreateRenderPass2,
    mut pass: Pass2,
    flags: vk::RenderPassCreateFlags,
    p_next: *const c_void,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::RenderPass,
) -> vk::Result {
    let (first, view_mask) = match pass.subpasses.first() {
        Some(s) => (
            // SAFETY: the application's array, as the caller promised, alive across the call.
            unsafe { slice(s.p_color_attachments, s.color_attachment_count) }
                .first()
                .map(|r| r.attachment)
                .filter(|&a| a != vk::ATTACHMENT_UNUSED),
            s.view_mask,
        ),
        None => (None, 0),
    };
    // SAFETY: the application's subpass chains, alive across the call, as the caller promised.
    if let Err(e) = unsafe { pass.without_apps_rate_infos() } {
        tracing::warn!(
            error = ?e,
            "a subpass pNext chain the layer cannot copy; the render pass is created as it came, \
             at full rate"
        );
        let info = pass.info(flags, p_next);
        // SAFETY: the application's pass, its arrays alive across the call.
        return unsafe { create2(dev.handle, &info, alloc, out) };
    }
    let targets = pass_colours(&pass);
    let rate = pass.attachments.len() as u32;
    pass.attachments.push(vk::AttachmentDescription2::default());
    add_shading_rate(&mut pass, rate, inj.texel(), rate_store_op(dev.api_version));
    let info = pass.info(flags, p_next);
    // SAFETY: the copy and everything it points at live across the call.
    let r = unsafe { create2(dev.handle, &info, alloc, out) };
    if !matches!(
        r,
        vk::Result::SUCCESS
            | vk::Result::ERROR_OUT_OF_HOST_MEMORY
            | vk::Result::ERROR_OUT_OF_DEVICE_MEMORY
    ) {
        tracing::warn!(
            result = ?r,
            "a render pass with an injected shading-rate attachment was refused; the \
             application's pass is created as it came, at full rate"
        );
        // The application's pass: its attachments and its subpasses' own chains.
        pass.attachments.pop();
        for (s, f) in pass.subpasses.iter_mut().zip(&pass.rate_infos) {
            s.p_next = f.p_next;
        }
        let info = pass.info(flags, p_next);
        // SAFETY: as above.
        return unsafe { create2(dev.handle, &info, alloc, out) };
    }
    if r == vk::Result::SUCCESS {
        // SAFETY: just created.
        let handle = unsafe { *out };
        inj.pass_created(
            handle,
            crate::vk::own::injector::InjectedPass {
                rate,
                colour: first,
                view_mask,
                targets,
            },
        );
        tracing::debug!(
            render_pass = raw(handle),
            rate,
            "render pass: a shading-rate attachment added for injection"
        );
    }
    r
}

/// `vkCreateFramebuffer` of a pass with an injected shading-rate attachment
/// (docs/injection.md#how-the-attachment-gets-in): the framebuffer gets that attachment after the
/// application's, the eye map where its colour target is an eye target, otherwise a full-rate map
/// covering it ([`crate::vk::own::injector::Injector::neutral`]). An imageless framebuffer describes a
/// one-layer map of exactly `ceil(size / texel)` texels, which each begin names
/// ([`begin_injected_pass`]).
///
/// # Safety
/// The caller's arguments, valid as the command requires; `own` must be `inj`'s device's.
#[allow(clippy::too_many_arguments)]
pub unsafe fn create_injected_framebuffer(
    inj: &crate::vk::own::injector::Injector,
    own: &crate::vk::own::calls::Own,
    p: crate::vk::own::injector::InjectedPass,
    next: vk::PFN_vkCreateFramebuffer,
    device: vk::Device,
    ci: &vk::FramebufferCreateInfo<'_>,
    alloc: *const vk::AllocationCallbacks<'_>,
    out: *mut vk::Framebuffer,
) -> vk::Result {
    let extent = [ci.width, ci.height];
    let texels = inj.texels_for(extent);
    let mut copy = *ci;
    let mut targets = [None; MAX_TARGETS];
    let colour_view = if ci.flags.contains(vk::FramebufferCreateFlags::IMAGELESS) {
        None
    } else {
        // SAFETY: the caller's array.
        let views = unsafe { slice(ci.p_attachments, ci.attachment_count) };
        for (out, t) in targets.iter_mut().zip(&p.targets) {
            *out = t.and_then(|(i, _)| views.get(i as usize)).copied();
        }
        p.colour.and_then(|c| views.get(c as usize)).copied()
    };
    let fb_layers = if p.view_mask != 0 {
        crate::vk::own::injector::rendered_layers(p.view_mask, 0).unwrap_or(1)
    } else {
        ci.layers.max(1)
    };
    let record = |eye: Option<([u32; 2], fovea_model::inject::Views)>, imageless: bool| {
        // SAFETY: just created.
        let fb = unsafe { *out };
        inj.framebuffer_created(
            fb,
            crate::vk::own::injector::InjectedFramebuffer {
                pass: p,
                extent,
                imageless,
                eye,
                colour: colour_view,
                targets,
                layers: fb_layers,
            },
        );
        tracing::debug!(
            framebuffer = raw(fb),
            eye = eye.is_some(),
            imageless,
            "framebuffer: injected shading-rate attachment"
        );
    };
    if ci.flags.contains(vk::FramebufferCreateFlags::IMAGELESS) {
        let ty = vk::StructureType::FRAMEBUFFER_ATTACHMENTS_CREATE_INFO;
        // SAFETY: the caller's chain, read only.
        let found = unsafe { chain::find::<vk::FramebufferAttachmentsCreateInfo>(ci.p_next, ty) };
        // SAFETY: as above.
        let rest = unsafe { ChainCopy::without(ci.p_next, |t| t == ty) };
        let (Ok(Some(found)), Ok(rest)) = (found, rest) else {
            tracing::warn!(
                "vkCreateFramebuffer: an imageless framebuffer of an injected pass the layer \
                 cannot extend; passed on as is"
            );
            // SAFETY: the next layer's function, with the caller's arguments.
            return unsafe { next(device, ci, alloc, out) };
        };
        // SAFETY: found by its sType in a valid chain.
        let found = unsafe { &*found };
        // SAFETY: the caller's array.
        let mut infos: Vec<vk::FramebufferAttachmentImageInfo<'_>> = unsafe {
            slice(
                found.p_attachment_image_infos,
                found.attachment_image_info_count,
            )
        }
        .to_vec();
        let formats = [SHADOW_FORMAT];
        infos.push(vk::FramebufferAttachmentImageInfo {
            usage: SHADOW_USAGE,
            width: texels[0],
            height: texels[1],
            layer_count: 1,
            view_format_count: 1,
            p_view_formats: formats.as_ptr(),
            ..Default::default()
        });
        let mut attachments = *found;
        attachments.p_next = rest.head();
        attachments.attachment_image_info_count = infos.len() as u32;
        attachments.p_attachment_image_infos = infos.as_ptr();
        copy.p_next = &attachments as *const _ as *const c_void;
        copy.attachment_count = ci.attachment_count + 1;
        // SAFETY: the copies live across the call.
        let r = unsafe { next(device, &copy, alloc, out) };
        if r == vk::Result::SUCCESS {
            record(None, true);
        }
        return r;
    }
    let mut views: Vec<vk::ImageView> =
        // SAFETY: the caller's array.
        unsafe { slice(ci.p_attachments, ci.attachment_count) }.to_vec();
    let colour = p.colour.and_then(|c| views.get(c as usize).copied());
    let layers = if p.view_mask != 0 {
        crate::vk::own::injector::rendered_layers(p.view_mask, 0)
    } else {
        Some(ci.layers)
    };
    let eye = match (colour, crate::bridge::inject::current()) {
        // SAFETY: `own` is the device's, as the caller promised.
        (Some(v), Some(state)) => unsafe { inj.eye_map(own, &state, v, layers) },
        _ => None,
    };
    let rate = eye.map(|e| e.0).or_else(|| {
        // SAFETY: as above.
        unsafe { inj.neutral(own, texels) }
    });
    let Some(rate) = rate else {
        // The pass names an attachment the framebuffer cannot fill: the driver's answer for
        // memory it cannot get (logged by `neutral`).
        return vk::Result::ERROR_OUT_OF_DEVICE_MEMORY;
    };
    views.push(rate);
    copy.attachment_count = views.len() as u32;
    copy.p_attachments = views.as_ptr();
    // SAFETY: the copy and the views live across the call.
    let r = unsafe { next(device, &copy, alloc, out) };
    if r == vk::Result::SUCCESS {
        record(eye.map(|(_, e, v)| (e, v)), false);
    }
    r
}

/// A begin's decision on an injecting device, as one thread made it: for `injector` (its
/// address), what kind of begin (`kind`) naming `what` and `extra`, made when the published
/// state's generation was `state` and the injectors' tables' was `tables`: `out`.
#[derive(Clone, Copy)]
struct Decided {
    injector: usize,
    kind: u8,
    what: u64,
    extra: u64,
    state: u64,
    tables: u64,
    out: (u64, bool),
}

/// Decisions a thread keeps: the few targets and framebuffers of the passes it records.
const DECIDED: usize = 8;

thread_local! {
    static DECISIONS: std::cell::Cell<[Option<Decided>; DECIDED]> =
        const { std::cell::Cell::new([None; DECIDED]) };
}

/// Kinds of [`Decided`]: a dynamic rendering's colour view (with its rendered layers), a
/// framebuffer, an imageless framebuffer's colour view.
const RENDERING: u8 = 1;
const FRAMEBUFFER: u8 = 2;
const IMAGELESS: u8 = 3;

/// What a begin on an injecting device decides (whether its target is an eye target, which map it
/// gets) depends only on the published state ([`crate::bridge::inject::generation`]) and the
/// injectors' tables ([`crate::vk::own::injector::tables_generation`]), which change at object
/// creation, never per command. So each thread keeps its latest decisions and makes one again
/// only when either generation moved: in steady state a begin takes no lock, per-device or
/// process-wide, and counts no reference (docs/ARCHITECTURE.md#recording-without-locks), where
/// it used to take the published state's lock and two or three of the device's. A miss runs
/// `decide`, which may take them and refill a map whose published key moved.
fn decided(
    inj: &crate::vk::own::injector::Injector,
    kind: u8,
    what: u64,
    extra: u64,
    decide: impl FnOnce() -> (u64, bool),
) -> (u64, bool) {
    let state = crate::bridge::inject::generation();
    let tables = crate::vk::own::injector::tables_generation();
    let injector = inj as *const _ as usize;
    let hit = |d: &Decided| {
        (d.injector, d.kind, d.what, d.extra, d.state, d.tables)
            == (injector, kind, what, extra, state, tables)
    };
    let cached = DECISIONS
        .try_with(|c| c.get().iter().flatten().find(|d| hit(d)).map(|d| d.out))
        .ok()
        .flatten();
    if let Some(out) = cached {
        return out;
    }
    let out = decide();
    let _ = DECISIONS.try_with(|c| {
        let mut v = c.get();
        v.rotate_right(1);
        v[0] = Some(Decided {
            injector,
            kind,
            what,
            extra,
            state,
            tables,
            out,
        });
        c.set(v);
    });
    out
}

/// Views a begin names inline, before a longer list takes the heap.
pub const INLINE_VIEWS: usize = 16;

/// A begin of a render pass on an injecting device: the eye map a framebuffer names is refilled
/// where the published maps moved on, and the pass is counted; for an imageless framebuffer, a copy
/// of `begin` whose `VkRenderPassAttachmentBeginInfo` adds the map of this begin's colour view (or
/// the full-rate one of the framebuffer's size). No allocation for up to [`INLINE_VIEWS`] views.
///
/// # Safety
/// `begin` must be NULL or valid; `own` must be `inj`'s device's.
pub unsafe fn begin_injected_pass(
    inj: &crate::vk::own::injector::Injector,
    own: &crate::vk::own::calls::Own,
    cb: vk::CommandBuffer,
    begin: *const vk::RenderPassBeginInfo<'_>,
    f: impl FnOnce(*const vk::RenderPassBeginInfo<'_>),
) {
    // SAFETY: as the caller promised.
    let Some(b) = (unsafe { begin.as_ref() }) else {
        return f(begin);
    };
    // What the framebuffer is: 0 not one of an injected pass, 1 with views of its own, 2 with an
    // eye map of its own (refilled here where the published maps moved on), 3 + the colour
    // attachment's index + 1 imageless.
    let (class, _) = decided(inj, FRAMEBUFFER, b.framebuffer.as_raw(), 0, || {
        let Some(fb) = inj.framebuffer(b.framebuffer) else {
            return (0, false);
        };
        if fb.imageless {
            return (3 + fb.pass.colour.map_or(0, |c| u64::from(c) + 1), false);
        }
        let Some((extent, views)) = fb.eye else {
            return (1, false);
        };
        crate::bridge::inject::with_current(|state| {
            if let Some(state) = state {
                // SAFETY: as the caller promised.
                unsafe { inj.refresh(own, state, extent, views) };
            }
        });
        (2, false)
    });
    if class < 3 {
        crate::bridge::inject::count_pass(class == 2);
        if class == 2 && inj.reconstructs() {
            plan_render_pass(inj, cb, b);
        }
        return f(begin);
    }
    let ty = vk::StructureType::RENDER_PASS_ATTACHMENT_BEGIN_INFO;
    let Ok(Some(found)) =
        // SAFETY: the caller's chain, read only.
        (unsafe { chain::find::<vk::RenderPassAttachmentBeginInfo>(b.p_next, ty) })
    else {
        return f(begin);
    };
    // SAFETY: found by its sType in a valid chain.
    let found = unsafe { &*found };
    // SAFETY: the caller's array.
    let app = unsafe { slice(found.p_attachments, found.attachment_count) };
    let colour = (class - 3)
        .checked_sub(1)
        .and_then(|c| app.get(c as usize).copied());
    // The map this begin's colour view gets (0: none), and whether it is an eye map.
    let (rate, eye) = decided(
        inj,
        IMAGELESS,
        b.framebuffer.as_raw(),
        colour.map_or(0, |v| v.as_raw()),
        || {
            let Some(fb) = inj.framebuffer(b.framebuffer) else {
                return (0, false);
            };
            let texels = inj.texels_for(fb.extent);
            let layers = if fb.pass.view_mask != 0 {
                crate::vk::own::injector::rendered_layers(fb.pass.view_mask, 0)
            } else {
                None
            };
            let eye = colour
                .and_then(|v| {
                    crate::bridge::inject::with_current(|state| {
                        // SAFETY: as the caller promised.
                        state.and_then(|state| unsafe { inj.eye_map(own, state, v, layers) })
                    })
                })
                // The framebuffer describes a one-layer map of exactly its texels.
                .filter(|&(_, e, v)| inj.map_size(e, v) == Some((texels, 1)));
            if let Some((v, _, _)) = eye {
                return (v.as_raw(), true);
            }
            // SAFETY: as the caller promised.
            let neutral = unsafe { inj.neutral(own, texels) };
            (neutral.map_or(0, |v| v.as_raw()), false)
        },
    );
    if rate == 0 {
        return f(begin);
    }
    let rate = vk::ImageView::from_raw(rate);
    crate::bridge::inject::count_pass(eye);
    if eye && inj.reconstructs() {
        plan_imageless_pass(inj, cb, b, app, rate);
    }
    let mut inline = [vk::ImageView::null(); INLINE_VIEWS];
    let heap: Vec<vk::ImageView>;
    let views: &[vk::ImageView] = if app.len() < INLINE_VIEWS {
        inline[..app.len()].copy_from_slice(app);
        inline[app.len()] = rate;
        &inline[..=app.len()]
    } else {
        heap = app.iter().copied().chain([rate]).collect();
        &heap
    };
    // SAFETY: the caller's chain, read only; the copy lives across `f`.
    unsafe {
        chain::with_removed(
            b.p_next,
            |t| t == ty,
            |rest| {
                let Ok(rest) = rest else {
                    tracing::warn!(
                        "vkCmdBeginRenderPass: a pNext chain the layer cannot copy; passed on as is"
                    );
                    return f(begin);
                };
                let mut attachments = *found;
                attachments.p_next = rest;
                attachments.attachment_count = views.len() as u32;
                attachments.p_attachments = views.as_ptr();
                let mut copy = *b;
                copy.p_next = &attachments as *const _ as *const c_void;
                f(&copy)
            },
        )
    }
}

/// `vkCmdBeginRendering` on an injecting device (docs/injection.md#how-the-attachment-gets-in): where
/// the first colour attachment's view is an eye target, a copy of the begin info goes down with a
/// `VkRenderingFragmentShadingRateAttachmentInfoKHR` naming the map for its shape in front of the
/// application's chain (on the stack: no allocation per command); any other rendering goes down
/// untouched. Either is counted for the stats line's `Inj=`.
///
/// An application's own `VkRenderingFragmentShadingRateAttachmentInfoKHR` with a view wins: the
/// rendering goes down as it came. One with a null view (vkd3d-proton chains one into every
/// rendering, docs/injection.md#apps-that-set-rates) names no attachment; in an eye pass it is
/// left out of the copy's chain (built in per-thread scratch storage, no allocation per command)
/// and fovea's takes its place, since a struct may appear only once in a chain
/// (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#fundamentals-validusage-pNext>).
///
/// The attachment's layer count is 1 (merged, or one view) or the rendered views', as
/// <https://registry.khronos.org/vulkan/specs/latest/man/html/VkRenderingFragmentShadingRateAttachmentInfoKHR.html>
/// asks of a multiview rendering; its extent covers the whole colour target.
///
/// # Safety
/// The caller's arguments, valid as the command requires; `own` must be `inj`'s device's.
pub unsafe fn begin_injected(
    inj: &crate::vk::own::injector::Injector,
    own: &crate::vk::own::calls::Own,
    next: vk::PFN_vkCmdBeginRendering,
    cb: vk::CommandBuffer,
    info: *const vk::RenderingInfo<'_>,
) {
    // SAFETY: the caller's rendering info, read only.
    let ri = unsafe { info.as_ref() };
    // Injection switched off (its instance gone): the rendering goes down as it came. A
    // thread-local look, no lock (`with_current`).
    let Some(ri) = ri.filter(|_| crate::bridge::inject::with_current(|s| s.is_some())) else {
        // SAFETY: the next layer's function, with the caller's arguments.
        return unsafe { next(cb, info) };
    };
    let rate_ty = vk::StructureType::RENDERING_FRAGMENT_SHADING_RATE_ATTACHMENT_INFO_KHR;
    // SAFETY: the caller's chain, read only; found by its sType.
    let apps = match unsafe {
        chain::find::<vk::RenderingFragmentShadingRateAttachmentInfoKHR<'_>>(ri.p_next, rate_ty)
    } {
        // SAFETY: found by its sType in the caller's chain.
        Ok(found) => found.map(|f| unsafe { (*f).image_view }),
        Err(_) => {
            crate::bridge::inject::count_pass(false);
            // SAFETY: the next layer's function, with the caller's arguments.
            return unsafe { next(cb, info) };
        }
    };
    if apps.is_some_and(|v| v != vk::ImageView::null()) {
        inj.apps_own_attachment("vkCmdBeginRendering");
        crate::bridge::inject::count_pass(false);
        // SAFETY: the next layer's function, with the caller's arguments.
        return unsafe { next(cb, info) };
    }
    // SAFETY: the caller's colour attachments, `colorAttachmentCount` of them.
    let colour = unsafe { slice(ri.p_color_attachments, ri.color_attachment_count) }
        .first()
        .map(|a| a.image_view)
        .filter(|v| *v != vk::ImageView::null());
    let layers = crate::vk::own::injector::rendered_layers(ri.view_mask, ri.layer_count);
    let map = colour.and_then(|v| {
        let (map, _) = decided(
            inj,
            RENDERING,
            v.as_raw(),
            layers.map_or(0, |l| u64::from(l) + 1),
            || {
                crate::bridge::inject::with_current(|state| {
                    // SAFETY: `own` is the device's, as the caller promised.
                    let map = state.and_then(|s| unsafe { inj.eye_view(own, s, v, layers) });
                    (map.map_or(0, |m| m.as_raw()), false)
                })
            },
        );
        (map != 0).then(|| vk::ImageView::from_raw(map))
    });
    crate::bridge::inject::count_pass(map.is_some());
    if inj.reconstructs() {
        plan_rendering(inj, cb, ri, map);
    }
    let Some(map) = map else {
        // SAFETY: the next layer's function, with the caller's arguments.
        return unsafe { next(cb, info) };
    };
    let begin = |rest: *const c_void| {
        let mut rate = vk::RenderingFragmentShadingRateAttachmentInfoKHR::default()
            .image_view(map)
            .image_layout(SHADOW_LAYOUT)
            .shading_rate_attachment_texel_size(inj.texel());
        rate.p_next = rest;
        let mut copy = *ri;
        copy.p_next = &rate as *const _ as *const c_void;
        // SAFETY: the copy and the struct in front of the chain live across the call.
        unsafe { next(cb, &copy) }
    };
    if apps.is_none() {
        return begin(ri.p_next);
    }
    // SAFETY: the caller's chain, read only; the copy lives across `begin`.
    unsafe {
        chain::with_removed(
            ri.p_next,
            |t| t == rate_ty,
            |rest| match rest {
                Ok(rest) => begin(rest),
                Err(e) => {
                    tracing::warn!(
                        error = ?e,
                        "vkCmdBeginRendering: a pNext chain the layer cannot copy; passed on as \
                         is, at full rate"
                    );
                    next(cb, info)
                }
            },
        )
    }
}

/// Notes in `cb`'s record what the end of the eye pass just begun with the map `map` reconstructs
/// (docs/reconstruction.md): each of `targets` (a view the pass leaves what it renders in, with
/// the layout it leaves it in, rendering `layers` of it) whose image is reconstructed (decided
/// when the view was made), where the device has a reconstructor. The eye pass is judged by its
/// first colour attachment (which in a multisampled pass is the multisampled image), the targets
/// by their own images: a resolve target is reconstructed where its image is.
fn plan(
    inj: &crate::vk::own::injector::Injector,
    cb: vk::CommandBuffer,
    targets: impl Iterator<Item = (vk::ImageView, vk::ImageLayout)>,
    map: vk::ImageView,
    layers: u32,
    area: vk::Rect2D,
    suspending: bool,
) {
    let mut found = [None; MAX_TARGETS];
    let mut n = 0;
    for (view, layout) in targets {
        let Some(v) = inj.view(view).filter(|v| v.reconstruct) else {
            continue;
        };
        if n == MAX_TARGETS {
            too_many_targets();
            break;
        }
        found[n] = Some((v, layout));
        n += 1;
    }
    if n == 0 {
        return;
    }
    let Some((rate_image, rate_extent, map_layers)) = inj.map_image(map) else {
        return;
    };
    registry::record_of(cb, |r| {
        let Some(rc) = r.reconstructor.as_deref() else {
            return;
        };
        let mut p = Plan::new(area, rate_image, rate_extent, 0, suspending);
        for (v, layout) in found.into_iter().flatten() {
            let Some(kind) = rc.handles(v.format) else {
                continue;
            };
            let layers = layers.min(v.layers).max(1);
            p.push(Colour {
                image: vk::Image::from_raw(v.image),
                base_layer: v.base_layer,
                layers,
                layout,
                kind,
                rate_layers: rate_layers(map_layers, layers),
            });
        }
        if !p.is_empty() {
            registry::set_plan(r, p);
        }
    });
}

/// [`plan`] for a render pass begun on a framebuffer with an eye map of its own.
fn plan_render_pass(
    inj: &crate::vk::own::injector::Injector,
    cb: vk::CommandBuffer,
    b: &vk::RenderPassBeginInfo<'_>,
) {
    let Some(fb) = inj.framebuffer(b.framebuffer) else {
        return;
    };
    let Some((extent, views)) = fb.eye else {
        return;
    };
    let Some(map) = inj.map_view(extent, views) else {
        return;
    };
    let targets = fb
        .targets
        .into_iter()
        .zip(fb.pass.targets)
        .filter_map(|(v, t)| Some((v?, t?.1)));
    plan(inj, cb, targets, map, fb.layers, b.render_area, false);
}

/// [`plan`] for a render pass begun on an imageless framebuffer whose colour view got the eye map
/// `map`: the pass's targets are the views this begin names (`views`, the application's) at the
/// pass's target attachments.
fn plan_imageless_pass(
    inj: &crate::vk::own::injector::Injector,
    cb: vk::CommandBuffer,
    b: &vk::RenderPassBeginInfo<'_>,
    views: &[vk::ImageView],
    map: vk::ImageView,
) {
    let Some(fb) = inj.framebuffer(b.framebuffer) else {
        return;
    };
    let targets = fb.pass.targets.into_iter().filter_map(|t| {
        let (i, layout) = t?;
        Some((*views.get(i as usize)?, layout))
    });
    plan(inj, cb, targets, map, fb.layers, b.render_area, false);
}

/// [`plan`] for a dynamic rendering whose first colour attachment got an eye map: each colour
/// attachment's view, or its resolve view where it is multisampled; a resuming rendering keeps
/// the plan of the instance it continues.
fn plan_rendering(
    inj: &crate::vk::own::injector::Injector,
    cb: vk::CommandBuffer,
    ri: &vk::RenderingInfo<'_>,
    map: Option<vk::ImageView>,
) {
    let suspending = ri.flags.contains(vk::RenderingFlags::SUSPENDING);
    if ri.flags.contains(vk::RenderingFlags::RESUMING) {
        registry::record_of(cb, |r| {
            if let Some(p) = r.plan.lock().as_mut() {
                p.suspending = suspending;
            }
        });
        return;
    }
    let Some(map) = map else {
        return;
    };
    // SAFETY: the caller's colour attachments, `colorAttachmentCount` of them.
    let colours = unsafe { slice(ri.p_color_attachments, ri.color_attachment_count) };
    let layers =
        crate::vk::own::injector::rendered_layers(ri.view_mask, ri.layer_count).unwrap_or(1);
    plan(
        inj,
        cb,
        colours.iter().filter_map(rendering_target),
        map,
        layers,
        ri.render_area,
        suspending,
    );
}
