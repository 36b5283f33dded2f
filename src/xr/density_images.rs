//! The Vulkan image work behind XR_FB_foveation_vulkan: fragment density map (FDM) images on the
//! application's device, filled from the density model.
//!
//! fb_foveation_vulkan.adoc: a swapchain created with
//! XR_SWAPCHAIN_CREATE_FOVEATION_FRAGMENT_DENSITY_MAP_BIT_FB hands out, through
//! XrSwapchainImageFoveationVulkanFB, one density image per swapchain image. Runtimes that
//! implement it allocate those images themselves; fovea does the same on the device of the
//! session's XrGraphicsBindingVulkanKHR:
//!
//! * one image per swapchain image, `VK_FORMAT_R8G8_UNORM` (the one format Vulkan requires to
//!   support FDM, docs/openxr-layer.md#fdm-image), 2D, `arrayLayers` = the swapchain's `arraySize` (with
//!   multiview, layer = view index), extent = `ceil(swapchain extent / texel size)`;
//! * usage FRAGMENT_DENSITY_MAP where the device has VK_EXT_fragment_density_map enabled, plus
//!   SAMPLED, STORAGE, TRANSFER_SRC and TRANSFER_DST where the format supports them: engines wrap
//!   the images in their own views, and on drivers without FDM convert them into shading-rate
//!   images;
//! * filled only inside xrAcquireSwapchainImage (one of the four calls where the spec lets the
//!   runtime use the application's queue, XR_KHR_vulkan_enable "Concurrency"), through a persistent
//!   staging buffer and one command buffer per image, and finished (fence) before the acquire
//!   returns: by default the map is read by the host when the application *records* its render pass
//!   (docs/openxr-layer.md#fdm-read-timing).
//!
//! The device, what it supports and the queue the uploads go through are
//! [`crate::xr::session_gpu`]'s.
//!
//! Fail open: where any Vulkan step fails, a warning is logged and the swapchain goes on without
//! density images (XrSwapchainImageFoveationVulkanFB stays as the application passed it).

use std::sync::Arc;

use crate::common::lock::{Mutex, Rank};
use ash::vk;
use ash::vk::Handle as _;

use fovea_model::density::Grid;
use fovea_model::maps::{fill_layers, Inputs, MAX_VIEWS};
use fovea_model::shading_rate;
use fovea_model::shift::{self, Filled, Placed};

use crate::xr::foveation::MapKey;
use crate::xr::session_gpu::{final_layout, memory_type, step, SessionGpu, VkError, FORMAT};

/// What a refresh did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refreshed {
    /// The image already held its key's map.
    Nothing,
    /// Uploaded from the cached map (its inputs had not changed).
    Uploaded,
    /// Computed anew and uploaded.
    Built,
}

/// What one image holds: the key of its map's inputs, and per view whether its fovea was moved
/// to a gaze and where (docs/eye-tracking.md#moving-the-fovea-one-shift-for-every-path).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Held {
    key: MapKey,
    foveas: [Option<Filled>; MAX_VIEWS],
}

/// Where the fovea of each view of a swapchain's maps is to be: per view its centre in NDC of its
/// own FOV (`None`: the fixed map's, the projection centre), and where each view lies in the map.
#[derive(Clone, Copy, Debug)]
pub struct Foveas {
    pub centres: [Option<[f32; 2]>; MAX_VIEWS],
    pub placed: [Option<Placed>; MAX_VIEWS],
}

impl Foveas {
    /// Fixed foveation: every view's fovea at its projection centre.
    pub const FIXED: Foveas = Foveas {
        centres: [None; MAX_VIEWS],
        placed: [None; MAX_VIEWS],
    };

    /// Per view, where its fovea is (pixels) and the shift that puts it there.
    fn filled(&self, grid: &Grid) -> [Option<Filled>; MAX_VIEWS] {
        let mut out = [None; MAX_VIEWS];
        for ((o, c), p) in out.iter_mut().zip(&self.centres).zip(&self.placed) {
            if let (Some(c), Some(p)) = (c, p) {
                *o = Some(Filled {
                    at: shift::pixel_of(&p.view, *c),
                    shift: shift::texel_shift(grid, &p.view, *c),
                });
            }
        }
        out
    }
}

/// A persistently mapped host pointer. It is only used under the `Fill` mutex.
struct Mapped(*mut u8);

// SAFETY: the pointer is into device memory mapped for the record's lifetime; access is serialised
// by the mutex that owns it.
unsafe impl Send for Mapped {}

/// The mutable half of [`DensityImages`].
struct Fill {
    /// Per image: what it was last filled with (`None`: never, its contents are undefined).
    filled: Vec<Option<Held>>,
    /// The inputs of the bytes in `bytes` (and in the staging buffer), once computed.
    cached: Option<Inputs>,
    /// The last computed map, all layers: the cache, so images with unchanged inputs are only
    /// re-uploaded. Allocated once.
    bytes: Vec<u8>,
    /// The shading-rate codes of `bytes` for the images' shadows (empty where there are none),
    /// computed with the map. Allocated once.
    codes: Vec<u8>,
    /// Where the codes are merged into one layer: the fixed map's codes one layer per density
    /// layer, so each view's can move alone before they are merged again; computed at the first
    /// move after a build (`layer_codes_current`). Allocated once, at the first move.
    layer_codes: Vec<u8>,
    layer_codes_current: bool,
    /// The cached map with its views' foveas moved, and its codes (and, merged, its codes per
    /// layer): the scratch a move is written into. Allocated once, at the first move.
    moved: Vec<u8>,
    moved_codes: Vec<u8>,
    moved_layer_codes: Vec<u8>,
    /// The per-view shifts of the map in the staging buffer (all `None`: the fixed map); `None`
    /// while it holds no map of the cached inputs.
    staged: Option<[Option<[i32; 2]>; MAX_VIEWS]>,
    mapped: Mapped,
}

impl Fill {
    /// Nothing filled yet for `count` images; the map's bytes (`density_bytes`) allocated once.
    fn new(count: usize, density_bytes: usize) -> Fill {
        Fill {
            filled: vec![None; count],
            cached: None,
            bytes: vec![0; density_bytes],
            codes: Vec::new(),
            layer_codes: Vec::new(),
            layer_codes_current: false,
            moved: Vec::new(),
            moved_codes: Vec::new(),
            moved_layer_codes: Vec::new(),
            staged: None,
            mapped: Mapped(std::ptr::null_mut()),
        }
    }
}

/// Whether the device makes density images of `extent` texels and `layers` layers with the
/// session's usage and `flags`.
///
/// # Safety
/// The session's instance and physical device must be live.
unsafe fn check_size(
    gpu: &SessionGpu,
    [mw, mh]: [u32; 2],
    layers: u32,
    flags: vk::ImageCreateFlags,
) -> Result<(), VkError> {
    // SAFETY: as the caller promised.
    let props = unsafe {
        gpu.instance.get_physical_device_image_format_properties(
            gpu.physical_device,
            FORMAT,
            vk::ImageType::TYPE_2D,
            vk::ImageTiling::OPTIMAL,
            gpu.usage,
            flags,
        )
    }
    .map_err(step("vkGetPhysicalDeviceImageFormatProperties"))?;
    let fits = props.max_extent.width >= mw
        && props.max_extent.height >= mh
        && props.max_array_layers >= layers;
    if !fits || mw == 0 || mh == 0 {
        return Err(VkError {
            step: "density image size",
            result: vk::Result::ERROR_FORMAT_NOT_SUPPORTED,
        });
    }
    Ok(())
}

/// How fovea's density maps become shading-rate codes on a device that emulates fragment density
/// maps on shading-rate attachments (docs/vulkan-fdm-on-fsr.md#rate-encoding).
#[derive(Clone, Debug)]
struct Rates {
    /// The shadows' layers: the density images', or 1 where the device merges all views into one
    /// layer holding the finer rate (docs/vulkan-fdm-on-fsr.md#multiview).
    layers: u32,
    max_fragment: [u32; 2],
    /// The fragment sizes the device lists.
    supported: Vec<[u32; 2]>,
    /// Where the codes start in the staging buffer (after the density bytes, 4-aligned).
    offset: u64,
}

impl Rates {
    /// The rates for shadows of `layers`-layer images of `extent` texels on `fdm`'s device.
    fn new(fdm: &crate::bridge::FdmEmulation, layers: u32, density_bytes: u64) -> Rates {
        Rates {
            layers: if fdm.layered { layers } else { 1 },
            max_fragment: fdm.max_fragment,
            supported: fdm.rates.clone(),
            offset: density_bytes.next_multiple_of(4),
        }
    }

    /// Whether `shadow` is one these rates can fill: the density image's extent, the expected
    /// layers.
    fn fits(&self, shadow: &crate::bridge::Shadow, extent: [u32; 2]) -> bool {
        shadow.extent == extent && shadow.layers == self.layers
    }
}

/// One swapchain's density images, their staging buffer and command buffers.
pub struct DensityImages {
    gpu: Arc<SessionGpu>,
    /// The density map size in texels (XrSwapchainImageFoveationVulkanFB width and height).
    pub extent: [u32; 2],
    pub layers: u32,
    pub grid: Grid,
    images: Vec<(vk::Image, vk::DeviceMemory)>,
    /// Per image, its shading-rate shadow where the application's device emulates fragment
    /// density maps (docs/vulkan-fdm-on-fsr.md#shadows): uploads write the rate codes into it.
    shadows: Vec<Option<vk::Image>>,
    /// How the shadows' codes are computed, where any image has a shadow.
    rates: Option<Rates>,
    staging: (vk::Buffer, vk::DeviceMemory),
    command_buffers: Vec<vk::CommandBuffer>,
    fill: Mutex<Fill>,
}

impl DensityImages {
    /// Creates `count` density images for a swapchain of `extent` pixels and `layers` array
    /// layers, with device-local memory, the staging buffer (host-visible and coherent, mapped for
    /// good) and a command buffer per image. On error, whatever was made is destroyed. `flags`:
    /// the images' create flags (`VK_IMAGE_CREATE_FRAGMENT_DENSITY_MAP_OFFSET_BIT_EXT` where the
    /// application applies density-map offsets to them, docs/eye-tracking.md#what-moves-when).
    ///
    /// # Safety
    /// The session's device must be live.
    pub unsafe fn new(
        gpu: &Arc<SessionGpu>,
        extent: [u32; 2],
        layers: u32,
        count: u32,
        flags: vk::ImageCreateFlags,
    ) -> Result<DensityImages, VkError> {
        let grid = Grid::new(extent, gpu.texel);
        let [mw, mh] = grid.map_extent();
        let layers = layers.max(1);
        // SAFETY: as the caller promised.
        unsafe { check_size(gpu, [mw, mh], layers, flags) }?;
        let density_bytes = u64::from(mw) * u64::from(mh) * 2 * u64::from(layers);
        let rates = crate::bridge::device_fdm(gpu.device.handle())
            .map(|fdm| Rates::new(&fdm, layers, density_bytes));
        let size = match &rates {
            Some(r) => r.offset + u64::from(mw) * u64::from(mh) * u64::from(r.layers),
            None => density_bytes,
        };
        let fill = Fill::new(count as usize, density_bytes as usize);
        let mut out = DensityImages {
            gpu: gpu.clone(),
            extent: [mw, mh],
            layers,
            grid,
            images: Vec::new(),
            shadows: Vec::new(),
            rates,
            staging: (vk::Buffer::null(), vk::DeviceMemory::null()),
            command_buffers: Vec::new(),
            fill: Mutex::ranked(Rank::DensityFill, "density fill", fill),
        };
        // From here on, an early return drops `out`, which destroys what exists so far: every
        // object made below is fovea's own and recorded in `out` as soon as it exists.
        for _ in 0..count {
            // SAFETY: as the caller promised.
            unsafe { out.push_image(flags) }?;
        }
        out.rates_from_shadows();
        // SAFETY: as the caller promised.
        unsafe {
            out.make_staging(size)?;
            out.allocate_command_buffers(count)?;
        }
        Ok(out)
    }

    /// Makes one density image with device-local memory, through the application's device, and
    /// notes its shading-rate shadow where it has one the rates fit.
    ///
    /// # Safety
    /// As [`DensityImages::new`].
    unsafe fn push_image(&mut self, flags: vk::ImageCreateFlags) -> Result<(), VkError> {
        let gpu = &*self.gpu;
        let d = &gpu.device;
        let [mw, mh] = self.extent;
        let create = vk::ImageCreateInfo::default()
            .flags(flags)
            .image_type(vk::ImageType::TYPE_2D)
            .format(FORMAT)
            .extent(vk::Extent3D {
                width: mw,
                height: mh,
                depth: 1,
            })
            .mip_levels(1)
            .array_layers(self.layers)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(gpu.usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        // SAFETY: the session's live device (as the caller promised); the image is destroyed
        // again where its memory is not made, and recorded once it is.
        unsafe {
            // Through the application's device: on a device that emulates density maps the
            // Vulkan layer gives the image its shadow, and learns that fovea writes its rates.
            let image = crate::bridge::own_density_images(|| d.create_image(&create, None))
                .map_err(step("vkCreateImage"))?;
            let req = d.get_image_memory_requirements(image);
            let memory = memory_type(
                &gpu.memory,
                req.memory_type_bits,
                vk::MemoryPropertyFlags::DEVICE_LOCAL,
                true,
            )
            .ok_or(vk::Result::ERROR_OUT_OF_DEVICE_MEMORY)
            .and_then(|i| {
                d.allocate_memory(
                    &vk::MemoryAllocateInfo::default()
                        .allocation_size(req.size)
                        .memory_type_index(i),
                    None,
                )
            });
            let memory = match memory {
                Ok(m) => m,
                Err(e) => {
                    d.destroy_image(image, None);
                    return Err(step("vkAllocateMemory (image)")(e));
                }
            };
            self.images.push((image, memory));
            d.bind_image_memory(image, memory, 0)
                .map_err(step("vkBindImageMemory"))?;
            let shadow = crate::bridge::shadow_of(image);
            let fits = |s: &crate::bridge::Shadow| {
                self.rates.as_ref().is_some_and(|r| r.fits(s, [mw, mh]))
            };
            self.shadows.push(shadow.filter(fits).map(|s| s.image));
            if shadow.is_some() && self.shadows.last() == Some(&None) {
                tracing::warn!(
                    ?shadow,
                    "a density image's shading-rate shadow does not match it; that image renders \
                     at full rate"
                );
            }
        }
        Ok(())
    }

    /// Where no image got a shadow, nothing computes codes; else their buffer is made once.
    fn rates_from_shadows(&mut self) {
        if self.shadows.iter().all(Option::is_none) {
            self.rates = None;
        }
        if let Some(r) = &self.rates {
            let [mw, mh] = self.extent;
            self.fill.get_mut().codes = vec![0; (mw * mh * r.layers) as usize];
            tracing::info!(
                layers = r.layers,
                max_fragment = ?r.max_fragment,
                "density images carry their shading rates"
            );
        }
    }

    /// The staging buffer of `size` bytes: host-visible and coherent, mapped for good.
    ///
    /// # Safety
    /// As [`DensityImages::new`].
    unsafe fn make_staging(&mut self, size: u64) -> Result<(), VkError> {
        let gpu = &*self.gpu;
        let d = &gpu.device;
        // SAFETY: the session's live device (as the caller promised); each object is recorded
        // in `self` as soon as it exists, so Drop destroys it on a later failure.
        unsafe {
            let buffer = d
                .create_buffer(
                    &vk::BufferCreateInfo::default()
                        .size(size)
                        .usage(vk::BufferUsageFlags::TRANSFER_SRC)
                        .sharing_mode(vk::SharingMode::EXCLUSIVE),
                    None,
                )
                .map_err(step("vkCreateBuffer"))?;
            self.staging.0 = buffer;
            let req = d.get_buffer_memory_requirements(buffer);
            // Vulkan guarantees a HOST_VISIBLE | HOST_COHERENT type for buffers ("Memory Types").
            let index = memory_type(
                &gpu.memory,
                req.memory_type_bits,
                vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
                false,
            )
            .ok_or(VkError {
                step: "a host-coherent memory type",
                result: vk::Result::ERROR_OUT_OF_HOST_MEMORY,
            })?;
            self.staging.1 = d
                .allocate_memory(
                    &vk::MemoryAllocateInfo::default()
                        .allocation_size(req.size)
                        .memory_type_index(index),
                    None,
                )
                .map_err(step("vkAllocateMemory (staging)"))?;
            d.bind_buffer_memory(buffer, self.staging.1, 0)
                .map_err(step("vkBindBufferMemory"))?;
            let flags = vk::MemoryMapFlags::empty();
            let mapped = d
                .map_memory(self.staging.1, 0, vk::WHOLE_SIZE, flags)
                .map_err(step("vkMapMemory"))?;
            self.fill.get_mut().mapped = Mapped(mapped as *mut u8);
        }
        Ok(())
    }

    /// A command buffer per image, from the session's pool under its mutex.
    ///
    /// # Safety
    /// As [`DensityImages::new`].
    unsafe fn allocate_command_buffers(&mut self, count: u32) -> Result<(), VkError> {
        let gpu = &*self.gpu;
        let s = gpu.submit.lock();
        let info = vk::CommandBufferAllocateInfo::default()
            .command_pool(s.pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(count);
        // SAFETY: the session's live device and pool, used under its mutex.
        self.command_buffers = unsafe { gpu.device.allocate_command_buffers(&info) }
            .map_err(step("vkAllocateCommandBuffers"))?;
        Ok(())
    }

    /// The VkImage of swapchain image `i`, as XrSwapchainImageFoveationVulkanFB wants it.
    pub fn image(&self, i: usize) -> Option<u64> {
        self.images.get(i).map(|(image, _)| image.as_raw())
    }

    /// How many images there are (the swapchain's image count).
    pub fn count(&self) -> usize {
        self.images.len()
    }

    /// Makes image `index` hold the map for `key` with each view's fovea where `foveas` puts it:
    /// nothing when it already does (a fovea that moved by less than half a texel since the image
    /// was filled counts as there, `shift::must_refill`); otherwise the fixed map is computed from
    /// `inputs()` (unless the cached map has the same inputs), shifted per view where a fovea
    /// follows a gaze (`shift::shift_layers`: a clamped copy, no map evaluation; on an emulating
    /// device the codes move the same way) and uploaded on the binding's queue, waited for before
    /// returning. A fovea that moved by half a texel onto the same whole-texel shift is recorded
    /// without an upload.
    ///
    /// # Safety
    /// Call only where the spec lets the runtime use the binding's queue (the application
    /// synchronises it there), e.g. inside xrAcquireSwapchainImage.
    pub unsafe fn refresh(
        &self,
        index: u32,
        key: MapKey,
        foveas: &Foveas,
        inputs: impl FnOnce() -> Inputs,
    ) -> Result<Refreshed, VkError> {
        let mut fill = self.fill.lock();
        let i = index as usize;
        if i >= self.images.len() {
            return Ok(Refreshed::Nothing);
        }
        let held = fill.filled[i];
        let same_key = held.is_some_and(|h| h.key == key);
        let at = |f: &[Option<Filled>; MAX_VIEWS]| f.map(|f| f.map(|f| f.at));
        let filled = foveas.filled(&self.grid);
        if same_key {
            let h = held.map(|h| h.foveas).unwrap_or_default();
            if !shift::must_refill(&self.grid, &h, &at(&filled)) {
                return Ok(Refreshed::Nothing);
            }
            if h.iter()
                .map(shift::held_shift)
                .eq(filled.iter().map(shift::held_shift))
            {
                // Moved by half a texel onto the same whole-texel shift: the image already holds
                // that map; only where it was filled moves on.
                fill.filled[i] = Some(Held {
                    key,
                    foveas: filled,
                });
                return Ok(Refreshed::Nothing);
            }
        }
        let mut done = Refreshed::Uploaded;
        if !same_key {
            let inputs = inputs();
            if fill.cached.as_ref() != Some(&inputs) {
                done = Refreshed::Built;
                let f = &mut *fill;
                fill_layers(&self.grid, &inputs, &mut f.bytes);
                if let Some(r) = &self.rates {
                    let texels = (self.extent[0] * self.extent[1]) as usize;
                    let merged = r.layers < self.layers;
                    shading_rate::fill_codes(
                        &f.bytes,
                        texels,
                        merged,
                        r.max_fragment,
                        &r.supported,
                        &mut f.codes,
                    );
                }
                f.cached = Some(inputs);
                f.layer_codes_current = false;
                f.staged = None;
            }
        }
        let shifts = filled.map(|f| shift::held_shift(&f));
        self.stage(&mut fill, &foveas.placed, shifts);
        // Until the upload succeeds the image counts as undefined.
        fill.filled[i] = None;
        // SAFETY: the caller's contract: the binding's queue may be used here.
        unsafe { self.upload(i)? };
        fill.filled[i] = Some(Held {
            key,
            foveas: filled,
        });
        Ok(done)
    }

    /// Makes the staging buffer hold the cached map with each view shifted by `shifts` (all
    /// `None`: the fixed map itself), and its codes where the images have shadows; nothing when it
    /// already does. The scratch buffers are allocated at the first move and reused.
    fn stage(
        &self,
        f: &mut Fill,
        placed: &[Option<Placed>; MAX_VIEWS],
        shifts: [Option<[i32; 2]>; MAX_VIEWS],
    ) {
        if f.staged == Some(shifts) {
            return;
        }
        let texels = (self.extent[0] * self.extent[1]) as usize;
        let fixed = shifts.iter().all(Option::is_none);
        if !fixed {
            f.moved.resize(f.bytes.len(), 0);
            shift::shift_layers::<2>(&self.grid, placed, &shifts, &f.bytes, &mut f.moved);
            if let Some(r) = &self.rates {
                f.moved_codes.resize(f.codes.len(), 0);
                if r.layers < self.layers {
                    // One merged layer holds every view: each view's codes move in their own
                    // layer, which are then merged again.
                    let n = texels * self.layers as usize;
                    if !f.layer_codes_current {
                        f.layer_codes.resize(n, 0);
                        shading_rate::fill_codes(
                            &f.bytes,
                            texels,
                            false,
                            r.max_fragment,
                            &r.supported,
                            &mut f.layer_codes,
                        );
                        f.layer_codes_current = true;
                    }
                    f.moved_layer_codes.resize(n, 0);
                    shift::shift_layers::<1>(
                        &self.grid,
                        placed,
                        &shifts,
                        &f.layer_codes,
                        &mut f.moved_layer_codes,
                    );
                    shading_rate::merge_codes(
                        &f.moved_layer_codes,
                        texels,
                        &r.supported,
                        &mut f.moved_codes,
                    );
                } else {
                    shift::shift_layers::<1>(
                        &self.grid,
                        placed,
                        &shifts,
                        &f.codes,
                        &mut f.moved_codes,
                    );
                }
            }
        }
        let (bytes, codes) = if fixed {
            (&f.bytes, &f.codes)
        } else {
            (&f.moved, &f.moved_codes)
        };
        // SAFETY: the staging memory is mapped for the record's lifetime and is as large as the
        // density bytes (both sized from the map extent and layers); the fill lock serialises
        // writes, and the GPU last read it in an upload that was waited for.
        unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), f.mapped.0, bytes.len()) };
        if let Some(r) = &self.rates {
            // SAFETY: as above; the staging buffer was sized for the codes at `offset`, after the
            // density bytes (`codes` holds texels × the shadows' layers).
            unsafe {
                std::ptr::copy_nonoverlapping(
                    codes.as_ptr(),
                    f.mapped.0.add(r.offset as usize),
                    codes.len(),
                )
            };
        }
        f.staged = Some(shifts);
    }

    /// Records and submits the staging buffer's copy into image `i` and waits for it.
    ///
    /// # Safety
    /// As [`DensityImages::refresh`]; `i` is within the images.
    unsafe fn upload(&self, i: usize) -> Result<(), VkError> {
        let d = &self.gpu.device;
        let cb = self.command_buffers[i];
        let image = self.images[i].0;
        let range = vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: 0,
            layer_count: self.layers,
        };
        let (layout, read) = final_layout(self.gpu.usage);
        // The whole image is overwritten, so its old contents may be discarded (UNDEFINED). The
        // source scope (all commands) orders the write after the application's earlier reads on
        // this queue, e.g. of the frame that last used this image. The fence wait therefore also
        // waits for the GPU work already queued: only when a map changed.
        let to_transfer = vk::ImageMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::empty())
            .dst_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .old_layout(vk::ImageLayout::UNDEFINED)
            .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(image)
            .subresource_range(range);
        let to_final = to_transfer
            .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(read)
            .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
            .new_layout(layout);
        let region = vk::BufferImageCopy {
            buffer_offset: 0,
            buffer_row_length: 0,
            buffer_image_height: 0,
            image_subresource: vk::ImageSubresourceLayers {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                mip_level: 0,
                base_array_layer: 0,
                layer_count: self.layers,
            },
            image_offset: vk::Offset3D::default(),
            image_extent: vk::Extent3D {
                width: self.extent[0],
                height: self.extent[1],
                depth: 1,
            },
        };
        // The shadow, where there is one, gets the codes from the same staging buffer. Every
        // layer is overwritten, so it too starts from UNDEFINED: the Vulkan layer gives the
        // shadows of fovea's own density images no clear of their own (`src/vk/own/calls.rs`), and
        // the first upload is what makes them valid. It ends in the shading-rate layout
        // (docs/vulkan-fdm-on-fsr.md#shadows) before the density image's own final barrier, to
        // which the Vulkan layer adds an ordering barrier on the shadow in that layout.
        let shadow = self.shadows[i].zip(self.rates.as_ref()).map(|(shadow, r)| {
            let fsr = vk::ImageLayout::FRAGMENT_SHADING_RATE_ATTACHMENT_OPTIMAL_KHR;
            let to_transfer =
                to_transfer
                    .image(shadow)
                    .subresource_range(vk::ImageSubresourceRange {
                        layer_count: r.layers,
                        ..range
                    });
            let back = to_transfer
                .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .dst_access_mask(vk::AccessFlags::FRAGMENT_SHADING_RATE_ATTACHMENT_READ_KHR)
                .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .new_layout(fsr);
            let region = vk::BufferImageCopy {
                buffer_offset: r.offset,
                image_subresource: vk::ImageSubresourceLayers {
                    layer_count: r.layers,
                    ..region.image_subresource
                },
                ..region
            };
            (shadow, to_transfer, back, region)
        });
        let mut first = [to_transfer; 2];
        let first: &[vk::ImageMemoryBarrier<'_>] = match &shadow {
            Some((_, b, ..)) => {
                first[1] = *b;
                &first
            }
            None => &first[..1],
        };
        // SAFETY: the caller's contract: the application synchronises the queue for the runtime here.
        // The command buffer is this image's own, not in flight (every submission is waited for before
        // returning), and recorded and submitted under the session's submit lock, which guards the
        // queue, pool and fence (Vulkan "Threading Behavior").
        unsafe {
            let s = self.gpu.submit.lock();
            d.begin_command_buffer(
                cb,
                &vk::CommandBufferBeginInfo::default()
                    .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
            )
            .map_err(step("vkBeginCommandBuffer"))?;
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                first,
            );
            d.cmd_copy_buffer_to_image(
                cb,
                self.staging.0,
                image,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &[region],
            );
            if let Some((shadow, _, back, region)) = shadow {
                d.cmd_copy_buffer_to_image(
                    cb,
                    self.staging.0,
                    shadow,
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                    &[region],
                );
                d.cmd_pipeline_barrier(
                    cb,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::PipelineStageFlags::ALL_COMMANDS,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[back],
                );
            }
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[to_final],
            );
            d.end_command_buffer(cb)
                .map_err(step("vkEndCommandBuffer"))?;
            let cbs = [cb];
            d.queue_submit(
                s.queue,
                &[vk::SubmitInfo::default().command_buffers(&cbs)],
                s.fence,
            )
            .map_err(step("vkQueueSubmit"))?;
            let waited = d.wait_for_fences(&[s.fence], true, u64::MAX);
            let reset = d.reset_fences(&[s.fence]);
            waited.map_err(step("vkWaitForFences"))?;
            reset.map_err(step("vkResetFences"))?;
            Ok(())
        }
    }
}

impl Drop for DensityImages {
    fn drop(&mut self) {
        let d = &self.gpu.device;
        // SAFETY: fovea's own submissions were all waited on before their calls returned. The
        // application must not use a destroyed swapchain's images (spec); fovea cannot wait for the
        // queue here, because xrDestroySwapchain and xrDestroySession are not among the calls where
        // the application synchronises the queue for the runtime (XR_KHR_vulkan_enable).
        unsafe {
            if !self.command_buffers.is_empty() {
                let s = self.gpu.submit.lock();
                d.free_command_buffers(s.pool, &self.command_buffers);
            }
            if !self.fill.get_mut().mapped.0.is_null() {
                d.unmap_memory(self.staging.1);
            }
            if self.staging.0 != vk::Buffer::null() {
                d.destroy_buffer(self.staging.0, None);
            }
            if self.staging.1 != vk::DeviceMemory::null() {
                d.free_memory(self.staging.1, None);
            }
            for (image, memory) in self.images.drain(..) {
                d.destroy_image(image, None);
                d.free_memory(memory, None);
            }
        }
    }
}
