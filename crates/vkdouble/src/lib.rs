//! `VK_LAYER_FOVEA_shading_rate_double`: a test-only Vulkan layer that makes a device without
//! `VK_KHR_fragment_shading_rate` (Mesa's lavapipe) look like a desktop GPU with shading-rate
//! attachments, and records what it was asked to do.
//!
//! Why: fovea's Vulkan layer rewrites fragment-density-map calls into shading-rate-attachment
//! calls. CI has no GPU with that feature, but it has lavapipe and the Khronos validation layer.
//! With the double *below* validation, validation checks every call against a device that has the
//! feature, lavapipe renders real pixels (at 1×1, since the double strips the shading-rate parts
//! before lavapipe sees them), and tests read back what a real driver would have been told:
//! which attachment, which texel size, which pipeline state, which rate codes.
//!
//! Stack in tests: application → (fovea) → `VK_LAYER_KHRONOS_validation` → this double → lavapipe.
//! The first layer named in `ppEnabledLayerNames` or `VK_INSTANCE_LAYERS` sits closest to the
//! application (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderApplicationInterface.md>).
//!
//! The loader dlopens the manifest's `library_path` ([`LIBRARY_FILE`]); a test binary that links
//! this crate as an rlib has its own, separate copy of the statics. So the records are read
//! through the loaded copy: [`Loaded`] dlopens the same file (the dynamic linker hands back the
//! same instance) and calls its exported `fovea_vkdouble_*` functions.
//!
//! Handles in the records are the ones the double sees. The validation layer wraps non-dispatchable
//! handles by default, so a test that compares them with its own disables that with
//! `VkValidationFeaturesEXT { VK_VALIDATION_FEATURE_DISABLE_UNIQUE_HANDLES_EXT }`
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkValidationFeatureDisableEXT.html>);
//! dispatchable handles (command buffers) are never wrapped.
//!
//! Records (`kind` and fields): `instance` {profile}; `device` {extension, features, extensions (every name), chain (every sType)}; `image`
//! {image, format, extent, layers} and `image_view` {view, image, base_layer, layers} for
//! shading-rate images only; `render_pass` {render_pass, attachments, subpasses[{shading_rate:
//! null | {attachment, layout, texel}}]}; `framebuffer` {framebuffer, render_pass, attachments,
//! extent, layers}; `pipeline` {pipeline, render_pass, subpass, shading_rate_state: null |
//! {fragment_size, combiner_ops}, rendering_attachment_flag, dynamic_rate};
//! `begin_render_pass` {command_buffer, render_pass, framebuffer, shading_rate_views};
//! `begin_rendering` {command_buffer, shading_rate: null | {view, layout, texel}};
//! `set_fragment_shading_rate` {command_buffer, fragment_size, combiner_ops}; `barrier`
//! {command_buffer, stages, access, images[{image, layouts}]} as given, raw values (version 1: the
//! two stage masks; version 2: per memory and image barrier); `submit`
//! {command_buffers, shading_rate_images[{image, extent, layers, codes}]}, the codes read back
//! after the submit completed; `draw` {command_buffer, pass, rendering, subpass, draw,
//! pipeline_rate, views[{view, layer, columns, rows, codes}]}, one per draw of each submitted
//! command buffer ([`Loaded::draws`], [`Loaded::effective_rates`]); `poison` {command_buffer,
//! image, base_layer, layers}. With the `none` profile nothing but `instance` is recorded.
//!
//! Effects, not inputs: for every draw (`vkCmdDraw*`, indexed, indirect, indirect count) the
//! double computes the fragment size the device it plays would shade each shading-rate attachment
//! texel with, by the specification's combiner pipeline
//! (<https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#primsrast-fragment-shading-rate>):
//! the bound pipeline's `VkPipelineFragmentShadingRateStateCreateInfoKHR` (absent: 1×1 and
//! `{KEEP, KEEP}`, so the attachment is ignored) or, where the pipeline has that dynamic state, the
//! last `vkCmdSetFragmentShadingRateKHR`; a 1×1 primitive rate; the attachment's code at that texel
//! of layer `ViewIndex` (layered attachment under multiview) or 0; clamped to the largest listed
//! rate no wider and no taller (then the smallest aspect ratio; ties go to the wider). The
//! attachment's codes are those the pass reads: the double records, in the command buffer in front
//! of each pass instance or rendering, a copy of its attachment's layers into a host-visible
//! buffer of its own (these commands go straight to lavapipe, so validation above never sees
//! them), and evaluates after the submit completed. `codes` are one hex digit per texel in the
//! attachment's encoding, rows top to bottom, over the texels the render area covers; a pass
//! without an attachment gives one texel, `layer` null.
//!
//! Strictness, as a driver without fragment density maps (every desktop driver with shading-rate
//! attachments): `vkCreateDevice` with a density-map extension name fails with
//! `VK_ERROR_EXTENSION_NOT_PRESENT`, with a density-map features struct that enables anything with
//! `VK_ERROR_FEATURE_NOT_PRESENT`; density-map layouts, stages, access bits, usage, image, view,
//! sampler and pipeline flags, and density-map structs in any chain the double sees (render passes
//! v1 and v2 with their attachments, references, dependencies and a `VkMemoryBarrier2` chained to
//! one, renderings, barriers v1 and v2, events, timestamps, submits' wait stages) are recorded as
//! errors, as is a shading-rate attachment (image usage, render pass, rendering) on a device that
//! did not enable `attachmentFragmentShadingRate`.
//!
//! Drawing the effect (`coarsened` {image, layer} records): lavapipe shades every pixel, so the
//! double makes colour attachments look as a GPU with shading-rate attachments leaves them, where
//! a GPU leaves them: at the end of each pass instance (a suspended rendering's at its last
//! part), in the command buffer, so that every later command (a read-back recorded right after
//! the pass, a later pass, a layer's own work on the colour) sees it. For each layer of each
//! colour attachment (a 2D image with the colour-attachment usage, in an 8-, 16- or
//! 32-bit-per-channel RGBA or 32-bit packed format) of a pass with a draw that can shade coarser
//! than 1×1: per shading-rate attachment texel, the finest effective fragment size any of the
//! pass's draws got there; every block of that size (aligned to multiples of its size, as a
//! fragment's area is) gets one value: what its shader computes at the centre of the fragment
//! area, where a GPU evaluates a coarse fragment (inputs are interpolated "at the center of the
//! fragment area", Vulkan, "Interpolation Decorations",
//! <https://registry.khronos.org/vulkan/specs/latest/html/vkspec.html#shaders-interpolation-decorations>;
//! `FragCoord` is "the center of the fragment"). Lavapipe shaded each pixel at its own centre,
//! so the double takes the mean, in linear terms, of the pixels nearest the fragment's centre:
//! one for a size of 1, the middle two of 2 or 4, per axis (`layer/centre.rs`). The double
//! records after the pass copies of those layers into buffers of its own, an event it sets, a
//! wait on an event the host sets, and copies back; at submit a thread of the double coarsens
//! between the two events (`layer/coarse.rs`). Passes whose draws can only shade 1×1 get nothing
//! recorded. Approximations, where a GPU differs: the whole block is replaced, so edges of
//! geometry become blocky where a GPU keeps per-pixel coverage; the mean equals the value at the
//! centre where the shaded value varies linearly over the middle pixels, and mixes the two sides
//! where an edge the shader draws runs between them (a GPU gives one side); where the
//! framebuffer or render area cuts a fragment, a GPU still shades at the whole area's centre,
//! outside the pixels written, and the double takes the written pixels nearest it; pixels no
//! draw wrote (a cleared background, loaded contents) are coarsened too.
//! [`blocks::uniform_share`] measures the result from pixels read back.
//!
//! Strictness: after a render pass whose shading-rate attachment has `storeOp = DONT_CARE`, the
//! double overwrites the layers the pass used with [`POISON`] (4×4, the coarsest rate), as the
//! contents are undefined then
//! (<https://registry.khronos.org/vulkan/specs/latest/man/html/VkAttachmentStoreOp.html>): a later
//! pass that relies on them shades visibly wrong.
//!
//! Fault injection ([`fovea_vkdouble_fail`], [`Loaded::fail`]): any of [`FAULTABLE`] (and
//! `vkCreateDevice`) can be made to fail at its n-th call, whatever the profile; since the double
//! sits below validation, the calls fovea makes for itself (its shadows) are counted and failed too.

#![deny(unsafe_op_in_unsafe_fn)]

pub mod blocks;
mod chain;
mod ffi;
mod layer;
mod profile;
mod record;
mod shade;
mod strict;

use std::ffi::{c_char, CStr};
use std::path::{Path, PathBuf};

pub use layer::{COUNTED, FAULTABLE, POISON};
pub use profile::Profile;
pub use record::KEPT_EVENTS;
use serde_json::Value;

/// The layer's name, as in its manifest.
pub const LAYER_NAME: &CStr = c"VK_LAYER_FOVEA_shading_rate_double";
/// The shared library the manifest points at (`target/<profile>/libfovea_vkdouble.so`).
pub const LIBRARY_FILE: &str = "libfovea_vkdouble.so";
/// The environment variable that picks the profile: `nvidia` (default), `amd` or `none`.
pub const PROFILE_ENV: &str = "FOVEA_VKDOUBLE_PROFILE";
/// Set (to anything) when a device is created, the environment variable that makes that device's
/// barrier, render-pass, dynamic-rendering, shading-rate, compute-binding, dispatch and
/// buffer-image copy recording commands do nothing: the double hands out empty functions for
/// them instead of going down to the driver. A benchmark of the layers above then measures their
/// own cost per command, not the driver's (`benches/vk_commands.rs`; the density-map pass cases
/// include the conversion fovea records in front of them, the reconstructed ones the copies and the
/// dispatch it records after them).
pub const NULL_COMMANDS_ENV: &str = "FOVEA_VKDOUBLE_NULL_COMMANDS";
/// Set (to anything) when the shading-rate properties are queried, the environment variable that
/// makes either profile report `fragmentShadingRateNonTrivialCombinerOps` false: only `KEEP` and
/// `REPLACE` then, which validation above the double enforces. Both profiles report it true by
/// default, as NVIDIA's driver and RADV do; this is for testing what a layer above does on a
/// device without it.
pub const TRIVIAL_COMBINERS_ENV: &str = "FOVEA_VKDOUBLE_TRIVIAL_COMBINERS";
/// Where set, the path the double writes its records to (as [`fovea_vkdouble_records_json`]
/// gives them) each time a device or an instance is destroyed, and at exit: how a test reads what reached the driver in an
/// application it runs as a child process (`tests/suite/hello_xr.rs`).
pub const RECORDS_FILE_ENV: &str = "FOVEA_VKDOUBLE_RECORDS_FILE";

/// Copies the records (`{"events": [...], "errors": [...], "dropped": n, "dropped_errors": n}`, bounded as [`KEPT_EVENTS`] says, as UTF-8 JSON, no terminator) into
/// `buf`, at most `len` bytes, and returns the full length, so a caller can size its buffer.
///
/// # Safety
/// `buf` must be null or valid for `len` bytes.
#[no_mangle]
pub unsafe extern "C" fn fovea_vkdouble_records_json(buf: *mut u8, len: usize) -> usize {
    let text = std::panic::catch_unwind(|| record::snapshot().to_string()).unwrap_or_default();
    if !buf.is_null() {
        let n = len.min(text.len());
        // SAFETY: the caller promised `len` writable bytes at `buf`; `n` ≤ `len`.
        unsafe { std::ptr::copy_nonoverlapping(text.as_ptr(), buf, n) };
    }
    text.len()
}

/// Forgets every record.
#[no_mangle]
pub extern "C" fn fovea_vkdouble_clear() {
    let _ = std::panic::catch_unwind(record::clear);
}

/// Fault injection: makes the call number `nth` (0-based, counted since the last
/// [`fovea_vkdouble_clear`]) of the command `name` return `result` (a `VkResult`, e.g.
/// `VK_ERROR_OUT_OF_DEVICE_MEMORY` = -2) without reaching lavapipe; the fault fires once. `name` is
/// `vkCreateDevice` or one of [`FAULTABLE`]. Returns 0, or -1 for a null or unknown name.
///
/// # Safety
/// `name` must be null or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn fovea_vkdouble_fail(name: *const c_char, nth: u64, result: i32) -> i32 {
    if name.is_null() {
        return -1;
    }
    // SAFETY: the caller promised a NUL-terminated string.
    let name = unsafe { CStr::from_ptr(name) }.to_string_lossy();
    if name != "vkCreateDevice" && !FAULTABLE.contains(&&*name) {
        return -1;
    }
    let _ = std::panic::catch_unwind(|| record::arm(&name, nth, result));
    0
}

/// How often the command `name` reached the double since the last [`fovea_vkdouble_clear`]
/// (counted for `vkCreateDevice`, [`FAULTABLE`] and [`COUNTED`], and on the shading-rate profiles
/// for the destruction of images, views, render passes, pipelines and framebuffers).
///
/// # Safety
/// `name` must be null or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn fovea_vkdouble_calls(name: *const c_char) -> u64 {
    if name.is_null() {
        return 0;
    }
    // SAFETY: the caller promised a NUL-terminated string.
    let name = unsafe { CStr::from_ptr(name) }.to_string_lossy();
    std::panic::catch_unwind(|| record::calls(&name)).unwrap_or(0)
}

/// Sets how many queues family 0 offers the next devices where the driver has fewer (0 or 1: as
/// the driver says). The extra ones stand for the driver's queue 0 (`layer/queues.rs`).
#[no_mangle]
pub extern "C" fn fovea_vkdouble_set_queues(n: u32) {
    let _ = std::panic::catch_unwind(|| layer::set_queues(n));
}

/// Sets the profile the next VkInstance gets (`nvidia`, `amd`, `none`), overriding
/// [`PROFILE_ENV`]; null lifts the override. Returns 0, or -1 for an unknown name.
///
/// # Safety
/// `name` must be null or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn fovea_vkdouble_set_profile(name: *const c_char) -> i32 {
    if name.is_null() {
        record::set_profile(None);
        return 0;
    }
    // SAFETY: the caller promised a NUL-terminated string.
    let name = unsafe { CStr::from_ptr(name) }.to_string_lossy();
    match Profile::parse(&name) {
        Some(p) => {
            record::set_profile(Some(p));
            0
        }
        None => -1,
    }
}

/// The layer manifest for the library at `library` (an absolute path). It lists
/// `VK_KHR_fragment_shading_rate` under `device_extensions`: the loader refuses device extensions
/// that neither the driver nor an enabled layer's manifest names
/// (<https://github.com/KhronosGroup/Vulkan-Loader/blob/main/docs/LoaderLayerInterface.md>,
/// "Layer Manifest File Format").
pub fn manifest_json(library: &Path) -> String {
    serde_json::json!({
        "file_format_version": "1.1.2",
        "layer": {
            "name": LAYER_NAME.to_str().unwrap_or_default(),
            "type": "GLOBAL",
            "library_path": library.to_string_lossy(),
            // As fovea's own manifests: a loader skips a layer older than the application's
            // API version, and a meta-layer (the tests' validation-over-double) any component
            // older than itself.
            "api_version": "1.4.359",
            "implementation_version": "1",
            "description": "fovea test double: shading-rate attachments on a device without them",
            "device_extensions": [{
                "name": "VK_KHR_fragment_shading_rate",
                "spec_version": "2",
                "entrypoints": ["vkCmdSetFragmentShadingRateKHR"]
            }, {
                "name": "VK_EXT_load_store_op_none",
                "spec_version": "1"
            }]
        }
    })
    .to_string()
}

/// Writes `VkLayer_fovea_shading_rate_double.json` for `library` into `dir`, for `VK_LAYER_PATH`.
pub fn write_manifest(dir: &Path, library: &Path) -> std::io::Result<PathBuf> {
    std::fs::create_dir_all(dir)?;
    let path = dir.join("VkLayer_fovea_shading_rate_double.json");
    std::fs::write(&path, manifest_json(library))?;
    Ok(path)
}

/// This build's library, searched from the running executable's folder upwards to `target`.
/// `cargo test` builds the cdylib into `target/<profile>/deps` beside the rlib it links (it does
/// not copy it up to `target/<profile>`), so a test binary finds the library built with it first.
pub fn find_library() -> Result<PathBuf, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let mut dir = exe.parent();
    while let Some(d) = dir {
        let c = d.join(LIBRARY_FILE);
        if c.exists() {
            return c.canonicalize().map_err(|e| e.to_string());
        }
        if d.file_name().is_some_and(|n| n == "target") {
            break;
        }
        dir = d.parent();
    }
    Err(format!(
        "{LIBRARY_FILE} not found next to {} (cargo build -p fovea-vkdouble)",
        exe.display()
    ))
}

/// The effective fragment sizes one view of one draw got, per shading-rate attachment texel that
/// the render area covers (row-major, `columns` × `rows`; one texel, `layer` `None`, where the pass
/// had no attachment).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ViewRates {
    pub view: u32,
    pub layer: Option<u32>,
    pub columns: u32,
    pub rows: u32,
    /// Each texel's effective size in the attachment's encoding (`(log2 w << 2) | log2 h`).
    pub codes: Vec<u8>,
}

impl ViewRates {
    /// The effective sizes, `[width, height]` per texel.
    pub fn sizes(&self) -> Vec<[u32; 2]> {
        self.codes.iter().map(|&c| shade::decode(c)).collect()
    }
}

/// What one draw of a submitted command buffer shaded at (a `draw` record).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DrawRates {
    pub command_buffer: u64,
    /// The render pass instance or rendering, counted from 0 in the command buffer's recording
    /// (a secondary's renderings count where it is executed).
    pub pass: usize,
    pub rendering: bool,
    pub subpass: u32,
    /// The draw, counted from 0 in its pass.
    pub draw: usize,
    /// Per view (one where the pass has no view mask).
    pub views: Vec<ViewRates>,
}

impl DrawRates {
    fn from_json(e: &Value) -> Option<DrawRates> {
        let views = e["views"]
            .as_array()?
            .iter()
            .map(|v| {
                Some(ViewRates {
                    view: v["view"].as_u64()? as u32,
                    layer: v["layer"].as_u64().map(|l| l as u32),
                    columns: v["columns"].as_u64()? as u32,
                    rows: v["rows"].as_u64()? as u32,
                    codes: v["codes"]
                        .as_str()?
                        .chars()
                        .map(|c| c.to_digit(16).map(|d| d as u8))
                        .collect::<Option<Vec<u8>>>()?,
                })
            })
            .collect::<Option<Vec<_>>>()?;
        Some(DrawRates {
            command_buffer: e["command_buffer"].as_u64()?,
            pass: e["pass"].as_u64()? as usize,
            rendering: e["rendering"].as_bool()?,
            subpass: e["subpass"].as_u64()? as u32,
            draw: e["draw"].as_u64()? as usize,
            views,
        })
    }
}

/// The double's library as the loader loads it, for reading its records in-process.
pub struct Loaded {
    lib: libloading::Library,
}

impl Loaded {
    /// Opens the library at `path`. Open it by the same file the manifest names: the dynamic
    /// linker then returns the instance the loader uses (or will use). Open it before the first
    /// VkInstance and keep it: the loader closes the layer's library at vkDestroyInstance, and
    /// with the last reference gone the records would be unloaded with it.
    pub fn open(path: &Path) -> Result<Loaded, String> {
        // SAFETY: loading the double runs no initialisers beyond Rust's own.
        let lib = unsafe { libloading::Library::new(path) }
            .map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(Loaded { lib })
    }

    /// Everything recorded so far: `{"events": [...], "errors": [...]}`.
    pub fn records(&self) -> Value {
        // SAFETY: the symbol has this signature (defined above, exported by the library).
        let f = unsafe {
            self.lib
                .get::<unsafe extern "C" fn(*mut u8, usize) -> usize>(
                    b"fovea_vkdouble_records_json\0",
                )
                .expect("fovea_vkdouble_records_json")
        };
        let mut buf = Vec::new();
        loop {
            // SAFETY: `buf` is valid for its length.
            let n = unsafe { f(buf.as_mut_ptr(), buf.len()) };
            if n <= buf.len() {
                buf.truncate(n);
                break;
            }
            buf.resize(n, 0);
        }
        serde_json::from_slice(&buf).expect("records are JSON")
    }

    /// The events of one kind, in order.
    pub fn events(&self, kind: &str) -> Vec<Value> {
        self.records()["events"]
            .as_array()
            .map(|a| a.iter().filter(|e| e["kind"] == kind).cloned().collect())
            .unwrap_or_default()
    }

    /// Every draw of every submit since [`Loaded::clear`], in order: the effective fragment
    /// size each got per shading-rate attachment texel, as the device the double plays would
    /// shade it.
    pub fn draws(&self) -> Vec<DrawRates> {
        self.events("draw")
            .iter()
            .map(|e| DrawRates::from_json(e).expect("a draw record"))
            .collect()
    }

    /// The effective rates of draw `draw` of pass `pass` on command buffer `cb`, at its last
    /// submit.
    pub fn effective_rates(&self, cb: u64, pass: usize, draw: usize) -> Option<Vec<ViewRates>> {
        self.draws()
            .into_iter()
            .rev()
            .find(|d| d.command_buffer == cb && d.pass == pass && d.draw == draw)
            .map(|d| d.views)
    }

    /// The misuses recorded so far.
    pub fn errors(&self) -> Vec<String> {
        self.records()["errors"]
            .as_array()
            .map(|a| {
                a.iter()
                    .map(|e| e.as_str().unwrap_or_default().to_owned())
                    .collect()
            })
            .unwrap_or_default()
    }

    /// Forgets every record.
    pub fn clear(&self) {
        // SAFETY: the symbol has this signature.
        unsafe {
            let f = self
                .lib
                .get::<extern "C" fn()>(b"fovea_vkdouble_clear\0")
                .expect("fovea_vkdouble_clear");
            f()
        }
    }

    /// Makes call number `nth` of `name` (counted since [`Loaded::clear`]) return `result`; see
    /// [`fovea_vkdouble_fail`].
    pub fn fail(&self, name: &str, nth: u64, result: ash::vk::Result) {
        let name = std::ffi::CString::new(name).expect("no NUL");
        // SAFETY: the symbol has this signature; the name lives across the call.
        unsafe {
            let f = self
                .lib
                .get::<unsafe extern "C" fn(*const c_char, u64, i32) -> i32>(
                    b"fovea_vkdouble_fail\0",
                )
                .expect("fovea_vkdouble_fail");
            assert_eq!(
                f(name.as_ptr(), nth, result.as_raw()),
                0,
                "{name:?} cannot fail"
            );
        }
    }

    /// How often `name` reached the double since [`Loaded::clear`].
    pub fn calls(&self, name: &str) -> u64 {
        let name = std::ffi::CString::new(name).expect("no NUL");
        // SAFETY: the symbol has this signature; the name lives across the call.
        unsafe {
            let f = self
                .lib
                .get::<unsafe extern "C" fn(*const c_char) -> u64>(b"fovea_vkdouble_calls\0")
                .expect("fovea_vkdouble_calls");
            f(name.as_ptr())
        }
    }

    /// Offers `n` queues of family 0 to the next devices ([`fovea_vkdouble_set_queues`]).
    pub fn set_queues(&self, n: u32) {
        // SAFETY: the symbol has the signature declared here.
        unsafe {
            if let Ok(f) = self
                .lib
                .get::<extern "C" fn(u32)>(b"fovea_vkdouble_set_queues\0")
            {
                f(n);
            }
        }
    }

    /// Picks the profile for the next VkInstance; `None` goes back to [`PROFILE_ENV`].
    pub fn set_profile(&self, profile: Option<Profile>) {
        let name = profile.map(|p| std::ffi::CString::new(p.name()).expect("no NUL"));
        // SAFETY: the symbol has this signature; the name lives across the call.
        unsafe {
            let f = self
                .lib
                .get::<unsafe extern "C" fn(*const c_char) -> i32>(b"fovea_vkdouble_set_profile\0")
                .expect("fovea_vkdouble_set_profile");
            assert_eq!(f(name.as_ref().map_or(std::ptr::null(), |n| n.as_ptr())), 0);
        }
    }
}
