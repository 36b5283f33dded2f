//! The Vulkan side: `VK_LAYER_FOVEA_fragment_density_map`, a Vulkan layer in the same library as
//! the OpenXR layer, that offers `VK_EXT_fragment_density_map` on devices that have shading-rate
//! attachments (`VK_KHR_fragment_shading_rate`) and no density maps of their own, so that an
//! application's fragment-density-map code path shades fewer fragments on a desktop GPU.
//!
//! This folder never imports the OpenXR side; both meet in [`crate::bridge`].
//!
//! The files stand on floors, each importing only files on floors below it (and, inside `base/`,
//! `own/` and `translate/`, files of its own folder, never in a circle); a hook never imports
//! another hook, and the modes never import each other:
//!
//! `tests/suite/meta/tidy.rs` holds the same table (`VK_FLOORS`) and fails on any import that runs
//! up or sideways; docs/ARCHITECTURE.md#floors draws both sides.
//!
//! | floor | path | job |
//! |---|---|---|
//! | 9 | `mod.rs` | this table and the module declarations |
//! | 8 | `loader.rs` | the loader interface: negotiation, `vkGetInstanceProcAddr`, `vkGetDeviceProcAddr` |
//! | 7 | `dispatch.rs` | the hook tables, expanded from the one command list |
//! | 6 | `hooks/` (`mod.rs`, `instance.rs`, `physical.rs`, `device.rs`, `image.rs`, `pass.rs`, `pipeline.rs`, `barrier.rs`, `record.rs`, `submit.rs`) | the hooks, one file per kind of object, each declared once with the chassis (`hook!` in `hooks/mod.rs`: guard, look-up, next pick, failure value, typed arguments) beside its plain Rust body: call each mode in turn, call down; create and destroy of a thing side by side |
//! | 5 | `decide.rs` | the mode per physical device: native, emulate or pass through |
//! | 5 | `emulation.rs` | emulation's shadows made and destroyed with density maps, and the render pass begins that name them |
//! | 5 | `convert.rs` | density maps the application writes, converted at pass begin |
//! | 5 | `injection.rs` | injection's render passes, framebuffers and eye-pass begins |
//! | 5 | `reconstruct.rs` | reconstruction of coarse blocks at the end of eye passes (docs/reconstruction.md) |
//! | 4 | `registry.rs` | per-instance and per-device records (each device's holding every mode's state: its own calls, emulation's shadows and converter, injection's maps, the reconstructor, its command pools' queue families), the lock-free device table, and command buffers' records (docs/ARCHITECTURE.md#who-owns-what) |
//! | 3 | `own/` (`mod.rs`, `calls.rs`, `shadows.rs`, `converter.rs`, `convert_shader.rs`, `bindings.rs`, `injector.rs`, `order.rs`, `recon_shader.rs`, `reconstructor.rs`), `shaders/` | the layer's own device objects: its calls on a device with the clears and uploads ahead of the application's submits (ordered against its other graphics queues by `order.rs`), shadows and their views, the GPU converter with its shader, each command buffer's conversion slots and the compute bindings it gives back, injection's maps and tracking, the reconstruction of coarse blocks with its shader |
//! | 2 | `translate/` (`mod.rs`, `render_pass.rs`, `render_pass_v1.rs`, `sync.rs`, `rate_state.rs`, `formats.rs`) | pure struct translation, no device calls: render passes v1 → v2 and without the density map, sync stages, accesses and layouts, pipelines' rate state, formats |
//! | 1 | `base/` (`mod.rs`, `ffi.rs`, `chain.rs`, `structs.rs`, `link.rs`, `commands.rs`, `next.rs`) | the FFI edge (guard, names, slices, typed views of the application's pointers and what a hook body gets, two-call, handle keys), `pNext` chains (read through the typed views too) and the size of every struct a device create info may chain, the loader's link structs, the one command list, the next-layer tables |
//!
//! Inside a folder: `base/chain.rs` uses `base/link.rs` and `base/structs.rs`, `base/next.rs` uses
//! `base/commands.rs` and `base/ffi.rs`; `own/calls.rs` uses `own/shadows.rs` and `own/order.rs`, `own/converter.rs` uses
//! `own/bindings.rs`, `own/calls.rs`, `own/convert_shader.rs` and `own/shadows.rs`, `own/reconstructor.rs` uses
//! `own/calls.rs`, `own/bindings.rs` and `own/recon_shader.rs`,
//! `own/injector.rs` uses `own/calls.rs`; `translate/render_pass.rs` uses `translate/formats.rs`
//! and `translate/sync.rs`, `translate/render_pass_v1.rs` uses `translate/render_pass.rs` and
//! `translate/formats.rs`.
//!
//! Per physical device: native density maps → everything passes through untouched;
//! `attachmentFragmentShadingRate` without them → emulate; neither → pass through. Fail open:
//! where the layer cannot do its part, the application's calls go down untouched and the log says
//! why, once.

#![deny(unsafe_op_in_unsafe_fn)]

mod base;
mod convert;
mod decide;
mod dispatch;
mod emulation;
mod hooks;
mod injection;
mod loader;
mod own;
mod reconstruct;
mod registry;
mod translate;
