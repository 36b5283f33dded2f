//! Injection on the Vulkan side (docs/injection.md): fovea's own shading-rate maps for the eye
//! passes of an application that never asked for foveation, and what the layer tracks to tell an
//! eye pass when it begins.
//!
//! - **Tracking.** A pass is judged by its first colour attachment
//!   (docs/injection.md#which-passes), which a begin names by view only. So at `vkCreateImage` the
//!   layer notes each colour-attachment image's extent and layers, and at `vkCreateImageView` each
//!   view's image, base layer and layer count: at creation, once, on injecting devices only. A view
//!   of an image the layer did not see made (a runtime's swapchain image made below the layer) is
//!   described from the published swapchain it belongs to, if any.
//! - **Maps.** Per target shape (extent, the views it holds) one `R8_UINT` image with the
//!   `FRAGMENT_SHADING_RATE_ATTACHMENT` usage and a view of it, filled with
//!   [`fovea_model::inject::codes`] for the published pattern and FOVs. The bytes reach the image
//!   through the pending uploads of [`crate::vk::own::calls::Clears`], in front of the application's next
//!   submit on a graphics queue: the layer uses a queue only inside a call the application made on
//!   it (<https://registry.khronos.org/vulkan/specs/latest/man/html/vkQueueSubmit.html>, "Host
//!   Synchronization"). A map is made the first time a pass of its shape begins and filled again
//!   only when the published maps' key moves ([`crate::bridge::inject::Injection::key`]), in place:
//!   a pass already recorded with it reads the newer map, which is what it would have got had it
//!   been recorded later. Maps live until the device is destroyed.
//!
//! Fail open: a map that cannot be made leaves the passes of its shape at full rate, and one log
//! line says why.
//!
//! Locks: the maps' and the tracking tables' are leaves outside
//! [`crate::common::lock::Rank`]'s order, like [`crate::vk::own::calls::Clears`]': under them the layer calls
//! only the next layer's commands on its own objects, which never call back into fovea.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use ash::vk;
use ash::vk::Handle as _;

use crate::bridge::inject::Injection;
use crate::bridge::FdmEmulation;
use crate::vk::own::calls::Own;
use crate::vk::translate::formats::SHADOW_FORMAT;
use crate::vk::translate::render_pass::MAX_TARGETS;
use fovea_model::inject::{FixedCodes, Pass, Views};

/// Advanced by every change to what a pass begin's decision on any injecting device reads (a view
/// or framebuffer noted or forgotten, a map made) and by every injector made or destroyed: a
/// decision a thread made after loading this value stays good while it is unchanged
/// ([`crate::vk::injection`] caches them per thread). All of these happen at object creation and
/// destruction, never per command.
static TABLES: AtomicU64 = AtomicU64::new(0);

/// The generation of every injector's tables (see [`TABLES`]).
pub fn tables_generation() -> u64 {
    TABLES.load(Ordering::Acquire)
}

fn tables_changed() {
    TABLES.fetch_add(1, Ordering::AcqRel);
}

/// What the layer knows of a colour image: its extent and array layers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct ImageFacts {
    extent: [u32; 2],
    layers: u32,
}

/// What the layer knows of a view of a colour image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ViewFacts {
    pub image: u64,
    pub extent: [u32; 2],
    pub base_layer: u32,
    pub layers: u32,
    pub image_layers: u32,
    /// The view's format, and whether its image's coarse blocks are reconstructed after the eye
    /// passes that render it (`crate::bridge::subsampled`, read when the view is created;
    /// docs/reconstruction.md).
    pub format: vk::Format,
    pub reconstruct: bool,
}

/// One injected map: the shape it is for, the key it was filled for, and the layer's objects.
struct Map {
    extent: [u32; 2],
    views: Views,
    key: u64,
    /// `None` where it could not be made: the shape renders at full rate, not retried.
    objects: Option<InjectedMap>,
    /// The fixed map's codes, per view layer, and the published fixed-map generation they were
    /// computed for ([`Injection::fixed`]): a gaze shifts them, and only a new pattern or FOV
    /// computes them again (docs/eye-tracking.md#what-moves-when).
    fixed: Option<(u64, FixedCodes)>,
    /// Scratch for the shifted per-view codes, kept between refills.
    scratch: Vec<u8>,
    /// The codes of the latest refill, kept between refills: a moving gaze refills the map every
    /// frame, and this keeps that from allocating.
    codes: Vec<u8>,
}

#[derive(Clone, Copy)]
struct InjectedMap {
    image: vk::Image,
    memory: vk::DeviceMemory,
    view: vk::ImageView,
    /// The map's extent in texels and layers (what [`fovea_model::inject::codes`] returned).
    texels: [u32; 2],
    layers: u32,
}

/// A render pass the layer gave a shading-rate attachment.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InjectedPass {
    /// The index of the added shading-rate attachment (the last one).
    pub rate: u32,
    /// The first subpass's first colour attachment, the pass's colour target.
    pub colour: Option<u32>,
    /// The first subpass's view mask.
    pub view_mask: u32,
    /// The attachments reconstructed after an eye pass where their images are
    /// (docs/reconstruction.md): each stored single-sample colour attachment and each stored
    /// resolve attachment of a multisampled one, with its `finalLayout`
    /// ([`crate::vk::translate::render_pass::pass_colours`]).
    pub targets: [Option<(u32, vk::ImageLayout)>; MAX_TARGETS],
}

/// What a framebuffer of an injected pass got.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InjectedFramebuffer {
    pub pass: InjectedPass,
    /// Width and height.
    pub extent: [u32; 2],
    /// Imageless: the shading-rate view is chosen at each begin.
    pub imageless: bool,
    /// The eye map it names (target extent and views), refreshed at each begin.
    pub eye: Option<([u32; 2], Views)>,
    /// Its colour target's view (`None` for an imageless framebuffer).
    pub colour: Option<vk::ImageView>,
    /// The views of its pass's [`InjectedPass::targets`], entry for entry (`None` for an
    /// imageless framebuffer).
    pub targets: [Option<vk::ImageView>; MAX_TARGETS],
    /// The layers it renders (its `layers`, or the views of a multiview pass).
    pub layers: u32,
}

/// One injecting device's state.
pub struct Injector {
    /// The device's shading-rate attachment facts.
    pub fdm: FdmEmulation,
    model: fovea_model::inject::Device,
    images: parking_lot::Mutex<HashMap<u64, ImageFacts>>,
    views: parking_lot::Mutex<HashMap<u64, ViewFacts>>,
    maps: parking_lot::Mutex<Vec<Map>>,
    /// Full-rate (code 0) maps by exact extent in texels, for passes that are not eye passes.
    neutral: parking_lot::Mutex<Vec<([u32; 2], Option<InjectedMap>)>>,
    passes: parking_lot::Mutex<HashMap<u64, InjectedPass>>,
    framebuffers: parking_lot::Mutex<HashMap<u64, InjectedFramebuffer>>,
    /// Set once the log has said that a map could not be made.
    failure_logged: AtomicBool,
    /// The application's render passes with shading-rate attachments of their own, created as
    /// they came (docs/injection.md#switching-it-on): their pipelines get nothing injected.
    apps_passes: parking_lot::Mutex<std::collections::HashSet<u64>>,
    /// Set once the log has said that the application uses attachments of its own.
    own_logged: AtomicBool,
    /// Set once a view whose image is reconstructed was noted: until then a begin looks no
    /// further for a reconstruction (docs/reconstruction.md).
    reconstructs: AtomicBool,
}

impl Injector {
    /// Nothing tracked yet, on a device with `fdm`'s shading-rate attachments.
    pub fn new(fdm: FdmEmulation) -> Injector {
        crate::bridge::inject::set_texel(fdm.texel);
        tables_changed();
        let model = fovea_model::inject::Device {
            texel: fdm.texel,
            layered: fdm.layered,
            max_fragment: fdm.max_fragment,
            rates: fdm.rates.clone(),
        };
        Injector {
            fdm,
            model,
            images: parking_lot::Mutex::new(HashMap::new()),
            views: parking_lot::Mutex::new(HashMap::new()),
            maps: parking_lot::Mutex::new(Vec::new()),
            neutral: parking_lot::Mutex::new(Vec::new()),
            passes: parking_lot::Mutex::new(HashMap::new()),
            framebuffers: parking_lot::Mutex::new(HashMap::new()),
            failure_logged: AtomicBool::new(false),
            apps_passes: parking_lot::Mutex::new(std::collections::HashSet::new()),
            own_logged: AtomicBool::new(false),
            reconstructs: AtomicBool::new(false),
        }
    }

    /// Notes a pass that names a shading-rate attachment of the application's own, which wins over
    /// fovea's map there (docs/injection.md#switching-it-on); the log says so the first time on
    /// this device.
    pub fn apps_own_attachment(&self, what: &str) {
        if !self.own_logged.swap(true, Ordering::Relaxed) {
            tracing::warn!(
                what,
                "the application uses a shading-rate attachment of its own; its passes with one \
                 are left alone, fovea's maps go into its other eye passes"
            );
        }
    }

    /// Records a render pass the application gave a shading-rate attachment of its own.
    pub fn apps_pass_created(&self, pass: vk::RenderPass) {
        self.apps_passes.lock().insert(pass.as_raw());
    }

    /// Whether `pass` is a render pass with the application's own shading-rate attachment.
    pub fn is_apps_pass(&self, pass: vk::RenderPass) -> bool {
        pass != vk::RenderPass::null() && self.apps_passes.lock().contains(&pass.as_raw())
    }

    /// The attachment texel, as the begin info's `shadingRateAttachmentTexelSize`.
    pub fn texel(&self) -> vk::Extent2D {
        vk::Extent2D {
            width: self.fdm.texel[0],
            height: self.fdm.texel[1],
        }
    }

    /// Notes a new image (from its create info) that may be a pass's colour target.
    pub fn image_created(&self, image: vk::Image, ci: &vk::ImageCreateInfo<'_>) {
        if !ci.usage.contains(vk::ImageUsageFlags::COLOR_ATTACHMENT)
            || ci.image_type != vk::ImageType::TYPE_2D
        {
            return;
        }
        self.images.lock().insert(
            image.as_raw(),
            ImageFacts {
                extent: [ci.extent.width, ci.extent.height],
                layers: ci.array_layers.max(1),
            },
        );
    }

    /// Forgets a destroyed image.
    pub fn image_destroyed(&self, image: vk::Image) {
        self.images.lock().remove(&image.as_raw());
    }

    /// Notes a new view (from its create info) of a colour image the layer knows, or of a
    /// published swapchain's image.
    pub fn view_created(&self, view: vk::ImageView, ci: &vk::ImageViewCreateInfo<'_>) {
        let image = ci.image.as_raw();
        let known = self.images.lock().get(&image).copied().or_else(|| {
            let state = crate::bridge::inject::current()?;
            let i = state.swapchain_of(image)?;
            let shape = state.swapchains.get(i)?.shape;
            Some(ImageFacts {
                extent: shape.extent,
                layers: shape.layers.max(1),
            })
        });
        let Some(facts) = known else {
            return;
        };
        if let Some(mut v) = view_facts(image, facts.extent, facts.layers, &ci.subresource_range) {
            v.format = ci.format;
            v.reconstruct = crate::bridge::subsampled::published(image) == Some(true);
            if v.reconstruct {
                self.reconstructs.store(true, Ordering::Release);
            }
            self.views.lock().insert(view.as_raw(), v);
            tables_changed();
        }
    }

    /// Forgets a destroyed view.
    pub fn view_destroyed(&self, view: vk::ImageView) {
        if self.views.lock().remove(&view.as_raw()).is_some() {
            tables_changed();
        }
    }

    /// Whether any view of this device renders an image that is reconstructed.
    pub fn reconstructs(&self) -> bool {
        self.reconstructs.load(Ordering::Acquire)
    }

    /// The image behind the map view `view` (made by this injector), its extent in texels and its
    /// layers.
    pub fn map_image(&self, view: vk::ImageView) -> Option<(vk::Image, [u32; 2], u32)> {
        self.maps
            .lock()
            .iter()
            .filter_map(|m| m.objects)
            .find(|o| o.view == view)
            .map(|o| (o.image, o.texels, o.layers))
    }

    /// The map view a target of `extent` holding `views` has, where it exists.
    pub fn map_view(&self, extent: [u32; 2], views: Views) -> Option<vk::ImageView> {
        self.maps
            .lock()
            .iter()
            .find(|m| m.extent == extent && m.views == views)
            .and_then(|m| m.objects)
            .map(|o| o.view)
    }

    /// What the layer knows of `view`.
    pub fn view(&self, view: vk::ImageView) -> Option<ViewFacts> {
        self.views.lock().get(&view.as_raw()).copied()
    }

    /// The shading-rate view an eye pass with colour target `view` gets, rendering `layers` layers
    /// (the view's, or the views of a multiview pass); `None` for any other pass, or where its map
    /// could not be made. No allocation once the shape's map exists and is current.
    ///
    /// # Safety
    /// `own` must belong to this injector's live device.
    pub unsafe fn eye_view(
        &self,
        own: &Own,
        state: &Injection,
        view: vk::ImageView,
        layers: Option<u32>,
    ) -> Option<vk::ImageView> {
        // SAFETY: as the caller promised.
        unsafe { self.eye_map(own, state, view, layers) }.map(|(v, _, _)| v)
    }

    /// As [`Injector::eye_view`], with the map's shape: the target extent and the views.
    ///
    /// # Safety
    /// `own` must belong to this injector's live device.
    pub unsafe fn eye_map(
        &self,
        own: &Own,
        state: &Injection,
        view: vk::ImageView,
        layers: Option<u32>,
    ) -> Option<(vk::ImageView, [u32; 2], Views)> {
        let v = self.view(view)?;
        let layers = layers.unwrap_or(v.layers);
        let Pass::Eye(views) =
            state.classify(v.image, v.extent, v.base_layer, layers, v.image_layers)
        else {
            return None;
        };
        // SAFETY: as the caller promised.
        unsafe { self.map(own, state, v.extent, views) }.map(|m| (m, v.extent, views))
    }

    /// The map's extent in texels and layers, where it exists.
    pub fn map_size(&self, extent: [u32; 2], views: Views) -> Option<([u32; 2], u32)> {
        self.maps
            .lock()
            .iter()
            .find(|m| m.extent == extent && m.views == views)
            .and_then(|m| m.objects)
            .map(|o| (o.texels, o.layers))
    }

    /// A full-rate map of exactly `texels` (one layer, rate code 0 everywhere, cleared ahead of the
    /// next submit), made once per extent: the shading-rate attachment of a pass that is not an
    /// eye pass (docs/injection.md#how-the-attachment-gets-in).
    ///
    /// # Safety
    /// `own` must belong to this injector's live device.
    pub unsafe fn neutral(&self, own: &Own, texels: [u32; 2]) -> Option<vk::ImageView> {
        let mut list = self.neutral.lock();
        if let Some((_, o)) = list.iter().find(|(t, _)| *t == texels) {
            return o.map(|o| o.view);
        }
        // SAFETY: as the caller promised.
        let made = match unsafe { make(own, texels, 1) } {
            Ok(o) => {
                own.clears.add(o.image, 1);
                Some(o)
            }
            Err(e) => {
                if !self.failure_logged.swap(true, Ordering::Relaxed) {
                    tracing::warn!(
                        result = ?e,
                        "cannot make a full-rate shading-rate map: framebuffers of passes that \
                         need one are passed on as the application made them"
                    );
                }
                None
            }
        };
        list.push((texels, made));
        tables_changed();
        made.map(|o| o.view)
    }

    /// The texels a framebuffer of `extent` needs: `ceil(extent / texel)`
    /// (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkFramebufferCreateInfo.html>,
    /// VUID-VkFramebufferCreateInfo-flags-04539).
    pub fn texels_for(&self, extent: [u32; 2]) -> [u32; 2] {
        [
            extent[0].div_ceil(self.fdm.texel[0].max(1)).max(1),
            extent[1].div_ceil(self.fdm.texel[1].max(1)).max(1),
        ]
    }

    /// Notes a render pass the layer gave a shading-rate attachment.
    pub fn pass_created(&self, pass: vk::RenderPass, p: InjectedPass) {
        self.passes.lock().insert(pass.as_raw(), p);
    }

    /// The injected pass `pass`, if it is one.
    pub fn pass(&self, pass: vk::RenderPass) -> Option<InjectedPass> {
        self.passes.lock().get(&pass.as_raw()).copied()
    }

    /// Forgets a destroyed render pass.
    pub fn pass_destroyed(&self, pass: vk::RenderPass) {
        self.passes.lock().remove(&pass.as_raw());
        self.apps_passes.lock().remove(&pass.as_raw());
    }

    /// Notes a framebuffer of an injected pass.
    pub fn framebuffer_created(&self, fb: vk::Framebuffer, f: InjectedFramebuffer) {
        self.framebuffers.lock().insert(fb.as_raw(), f);
        tables_changed();
    }

    /// The framebuffer `fb` of an injected pass, if it is one.
    pub fn framebuffer(&self, fb: vk::Framebuffer) -> Option<InjectedFramebuffer> {
        self.framebuffers.lock().get(&fb.as_raw()).copied()
    }

    /// Forgets a destroyed framebuffer.
    pub fn framebuffer_destroyed(&self, fb: vk::Framebuffer) {
        if self.framebuffers.lock().remove(&fb.as_raw()).is_some() {
            tables_changed();
        }
    }

    /// The map for a target of `extent` holding `views`, refilled where the published maps moved
    /// on: at each begin of a framebuffer that names it.
    ///
    /// # Safety
    /// `own` must belong to this injector's live device.
    pub unsafe fn refresh(&self, own: &Own, state: &Injection, extent: [u32; 2], views: Views) {
        // SAFETY: as the caller promised.
        unsafe { self.map(own, state, extent, views) };
    }

    /// The view of the map for a target of `extent` holding `views`, made or refilled where it is
    /// missing or stale.
    ///
    /// # Safety
    /// `own` must belong to this injector's live device.
    unsafe fn map(
        &self,
        own: &Own,
        state: &Injection,
        extent: [u32; 2],
        views: Views,
    ) -> Option<vk::ImageView> {
        let key = state.key();
        let mut maps = self.maps.lock();
        if let Some(m) = maps
            .iter_mut()
            .find(|m| m.extent == extent && m.views == views)
        {
            let o = m.objects?;
            if m.key != key {
                // Whatever happens below, not again for this key: nothing per command.
                m.key = key;
                let refilled = m.fixed.as_ref().is_none_or(|(f, _)| *f != state.fixed);
                if refilled {
                    m.fixed = Some((state.fixed, self.fixed_codes(state, extent, views)));
                }
                let Some((_, fixed)) = &m.fixed else {
                    return Some(o.view);
                };
                fixed.codes_into(&state.centres(), &mut m.scratch, &mut m.codes);
                // A shape's texels and layers follow from its extent, views and the device alone,
                // so the image always fits; checked all the same, never written past.
                if fixed.texels == o.texels && fixed.out_layers() == o.layers {
                    own.clears.upload(o.image, o.texels, o.layers, &m.codes);
                    if refilled {
                        tracing::info!(
                            width = extent[0],
                            height = extent[1],
                            ?views,
                            level = state.pattern.level.name(),
                            "injected shading-rate map refilled"
                        );
                    } else {
                        tracing::debug!(
                            width = extent[0],
                            height = extent[1],
                            ?views,
                            centres = ?state.centres(),
                            "injected shading-rate map's fovea moved"
                        );
                    }
                }
            }
            return Some(o.view);
        }
        let fixed = self.fixed_codes(state, extent, views);
        let (texels, layers) = (fixed.texels, fixed.out_layers());
        let mut scratch = Vec::new();
        let mut codes = Vec::new();
        fixed.codes_into(&state.centres(), &mut scratch, &mut codes);
        // SAFETY: as the caller promised.
        let made = unsafe { make(own, texels, layers) };
        let objects = match made {
            Ok(o) => {
                own.clears.upload(o.image, texels, layers, &codes);
                tracing::info!(
                    width = extent[0],
                    height = extent[1],
                    ?views,
                    texels = ?texels,
                    layers,
                    level = state.pattern.level.name(),
                    "injected shading-rate map made"
                );
                Some(o)
            }
            Err(e) => {
                if !self.failure_logged.swap(true, Ordering::Relaxed) {
                    tracing::warn!(
                        result = ?e,
                        width = extent[0],
                        height = extent[1],
                        "cannot make an injected shading-rate map: passes of this shape render \
                         at full rate"
                    );
                }
                None
            }
        };
        maps.push(Map {
            extent,
            views,
            key,
            objects,
            fixed: Some((state.fixed, fixed)),
            scratch,
            codes,
        });
        tables_changed();
        objects.map(|o| o.view)
    }

    /// The fixed map's codes (no gaze) for a target of `extent` holding `views`.
    fn fixed_codes(&self, state: &Injection, extent: [u32; 2], views: Views) -> FixedCodes {
        FixedCodes::new(
            &self.model,
            views,
            extent,
            &state.fovs,
            state.pattern,
            state.max_fragment,
        )
    }

    /// Enters a made, current map of a shape (and a full-rate map of `texels`) with the view
    /// `view`, as the first begin of that shape would have made it: for tests that drive the begin
    /// hooks on a device without a driver.
    #[cfg(test)]
    pub fn seed(
        &self,
        state: &Injection,
        extent: [u32; 2],
        views: Views,
        view: vk::ImageView,
        texels: [u32; 2],
    ) {
        let objects = Some(InjectedMap {
            image: vk::Image::null(),
            memory: vk::DeviceMemory::null(),
            view,
            texels,
            layers: 1,
        });
        self.maps.lock().push(Map {
            extent,
            views,
            key: state.key(),
            objects,
            fixed: None,
            scratch: Vec::new(),
            codes: Vec::new(),
        });
        self.neutral.lock().push((texels, objects));
        tables_changed();
    }

    /// Destroys every map of a device about to be destroyed.
    ///
    /// # Safety
    /// `own` must belong to this injector's live device, idle, its uploads done or dropped.
    pub unsafe fn destroy(&self, own: &Own) {
        tables_changed();
        let maps: Vec<Map> = self.maps.lock().drain(..).collect();
        let neutral: Vec<InjectedMap> = self
            .neutral
            .lock()
            .drain(..)
            .filter_map(|(_, o)| o)
            .collect();
        for o in maps.into_iter().filter_map(|m| m.objects).chain(neutral) {
            // SAFETY: as the caller promised; the layer's own objects.
            unsafe {
                own.clears.forget_upload(&own.fns, o.image);
                own.fns.destroy_image_view(o.view, None);
                own.fns.destroy_image(o.image, None);
                own.fns.free_memory(o.memory, None);
            }
        }
    }
}

/// A view's facts from its subresource range over an image of `extent` and `image_layers`
/// layers; `None` for a range that names no layer.
fn view_facts(
    image: u64,
    extent: [u32; 2],
    image_layers: u32,
    r: &vk::ImageSubresourceRange,
) -> Option<ViewFacts> {
    let layers = if r.layer_count == vk::REMAINING_ARRAY_LAYERS {
        image_layers.checked_sub(r.base_array_layer)?
    } else {
        r.layer_count
    };
    // A view of a lower mip level renders a smaller target.
    let mip = r.base_mip_level.min(31);
    (layers > 0).then_some(ViewFacts {
        image,
        extent: [(extent[0] >> mip).max(1), (extent[1] >> mip).max(1)],
        base_layer: r.base_array_layer,
        layers,
        image_layers,
        format: vk::Format::UNDEFINED,
        reconstruct: false,
    })
}

/// Makes a map image of `texels` × `layers` in device-local memory and its view (2D for one
/// layer, 2D-array otherwise, as shading-rate attachment views must be).
///
/// # Safety
/// `own` must belong to a live device.
unsafe fn make(own: &Own, texels: [u32; 2], layers: u32) -> Result<InjectedMap, vk::Result> {
    let d = &own.fns;
    // SAFETY: as the caller promised; the image and memory are destroyed again on failure.
    unsafe {
        let (image, memory) = own.shading_rate_image(texels, layers)?;
        let view_type = if layers > 1 {
            vk::ImageViewType::TYPE_2D_ARRAY
        } else {
            vk::ImageViewType::TYPE_2D
        };
        let view = d.create_image_view(
            &vk::ImageViewCreateInfo::default()
                .image(image)
                .view_type(view_type)
                .format(SHADOW_FORMAT)
                .subresource_range(vk::ImageSubresourceRange {
                    aspect_mask: vk::ImageAspectFlags::COLOR,
                    base_mip_level: 0,
                    level_count: 1,
                    base_array_layer: 0,
                    layer_count: layers,
                }),
            None,
        );
        match view {
            Ok(view) => Ok(InjectedMap {
                image,
                memory,
                view,
                texels,
                layers,
            }),
            Err(e) => {
                d.destroy_image(image, None);
                d.free_memory(memory, None);
                Err(e)
            }
        }
    }
}

/// The layers a dynamic rendering renders: the highest view of its view mask plus one, or its
/// layer count (`None` where it names none, and the view's count applies).
pub fn rendered_layers(view_mask: u32, layer_count: u32) -> Option<u32> {
    if view_mask != 0 {
        Some(32 - view_mask.leading_zeros())
    } else {
        (layer_count > 0).then_some(layer_count)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::common::alloc_count::allocations;

    fn range(base_mip: u32, base: u32, count: u32) -> vk::ImageSubresourceRange {
        vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: base_mip,
            level_count: 1,
            base_array_layer: base,
            layer_count: count,
        }
    }

    #[test]
    fn view_facts_resolve_remaining_layers_and_mips() {
        let v = view_facts(7, [1440, 1600], 2, &range(0, 1, vk::REMAINING_ARRAY_LAYERS)).unwrap();
        assert_eq!((v.base_layer, v.layers, v.image_layers), (1, 1, 2));
        assert_eq!(v.extent, [1440, 1600]);
        let mip = view_facts(7, [1440, 1600], 1, &range(1, 0, 1)).unwrap();
        assert_eq!(
            mip.extent,
            [720, 800],
            "a lower mip level is a smaller target"
        );
        assert!(view_facts(7, [8, 8], 1, &range(0, 2, vk::REMAINING_ARRAY_LAYERS)).is_none());
        assert!(view_facts(7, [8, 8], 1, &range(0, 0, 0)).is_none());
    }

    #[test]
    fn rendered_layers_follow_the_view_mask() {
        assert_eq!(rendered_layers(0b11, 1), Some(2));
        assert_eq!(rendered_layers(0b10, 1), Some(2));
        assert_eq!(rendered_layers(0, 1), Some(1));
        assert_eq!(rendered_layers(0, 0), None);
    }

    /// A gaze that moves every frame refills an eye map at every move: in steady state the refill
    /// (the shifted codes, and their bytes handed to the next submit's upload) allocates nothing,
    /// and what the upload will copy is the map for the newest gaze.
    #[test]
    fn refills_for_a_moving_gaze_allocate_nothing() {
        use crate::bridge::inject;
        let _one = inject::tests::STATE_TESTS.lock();
        inject::tests::start_high_square();
        let inj = Injector::new(FdmEmulation::nvidia_like());
        let device = vk::Device::from_raw(0x7711);
        // SAFETY: a table of functions that are never called: the map exists, so nothing is made.
        let fns = unsafe { ash::Device::load_with(|_| std::ptr::null(), device) };
        unsafe extern "system" fn loader_data(
            _: vk::Device,
            _: *mut std::ffi::c_void,
        ) -> vk::Result {
            vk::Result::SUCCESS
        }
        let own = Own {
            fns,
            memory: vk::PhysicalDeviceMemoryProperties::default(),
            set_loader_data: loader_data,
            clears: crate::vk::own::calls::Clears::new(Vec::new()),
            fallbacks: crate::common::lock::Mutex::new(Vec::new()),
        };
        let (extent, views) = ([512, 512], Views::Layers { first: 0, count: 1 });
        let image = vk::Image::from_raw(0x1a6e);
        inject::with_current(|s| {
            inj.seed(
                s.unwrap(),
                extent,
                views,
                vk::ImageView::from_raw(0x1a6f),
                [32, 32],
            );
        });
        inj.maps.lock()[0].objects.as_mut().unwrap().image = image;
        let mut counts = Vec::new();
        for frame in 0..40u32 {
            // Smooth pursuit across the view, far enough each frame to be published.
            let x = (frame as f32 * 0.05).sin() * 0.6;
            let mut centres = [None; fovea_model::maps::MAX_VIEWS];
            centres[0] = Some([x, 0.1]);
            inject::set_centres(&centres);
            let before = allocations();
            inject::with_current(|s| {
                // SAFETY: the map exists, so no call reaches the (absent) driver.
                unsafe { inj.refresh(&own, s.unwrap(), extent, views) };
            });
            counts.push(allocations() - before);
            let want = inject::with_current(|s| {
                let s = s.unwrap();
                let mut scratch = Vec::new();
                let mut codes = Vec::new();
                inj.fixed_codes(s, extent, views).codes_into(
                    &s.centres(),
                    &mut scratch,
                    &mut codes,
                );
                codes
            });
            let st = own.clears.state.lock();
            let u = st
                .uploads
                .iter()
                .find(|u| u.image == image)
                .expect("staged");
            assert!(
                u.dirty && u.bytes == want,
                "frame {frame}: the newest gaze's map"
            );
        }
        // SAFETY: nothing is in flight.
        unsafe { own.clears.destroy(&own.fns) };
        inject::stop();
        assert!(
            counts[..2].iter().any(|&n| n > 0),
            "the first refills allocate: {counts:?}"
        );
        assert_eq!(
            &counts[2..],
            &[0; 38],
            "allocations per move in steady state"
        );
    }

    #[test]
    fn only_colour_attachment_images_are_tracked() {
        let inj = Injector::new(FdmEmulation {
            texel: [16, 16],
            layered: true,
            max_fragment: [4, 4],
            rates: Vec::new(),
            non_trivial_combiners: true,
        });
        let colour = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .extent(vk::Extent3D {
                width: 64,
                height: 32,
                depth: 1,
            })
            .array_layers(2)
            .usage(vk::ImageUsageFlags::COLOR_ATTACHMENT);
        inj.image_created(vk::Image::from_raw(1), &colour);
        inj.image_created(
            vk::Image::from_raw(2),
            &colour.usage(vk::ImageUsageFlags::SAMPLED),
        );
        let view = |image| {
            vk::ImageViewCreateInfo::default()
                .image(vk::Image::from_raw(image))
                .subresource_range(range(0, 0, 2))
        };
        inj.view_created(vk::ImageView::from_raw(10), &view(1));
        inj.view_created(vk::ImageView::from_raw(20), &view(2));
        let v = inj.view(vk::ImageView::from_raw(10)).unwrap();
        assert_eq!((v.image, v.extent, v.layers), (1, [64, 32], 2));
        assert!(inj.view(vk::ImageView::from_raw(20)).is_none());
        inj.view_destroyed(vk::ImageView::from_raw(10));
        assert!(inj.view(vk::ImageView::from_raw(10)).is_none());
        inj.image_destroyed(vk::Image::from_raw(1));
        inj.view_created(vk::ImageView::from_raw(11), &view(1));
        assert!(inj.view(vk::ImageView::from_raw(11)).is_none());
    }
}
