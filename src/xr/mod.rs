//! The OpenXR side: the loader interface, the hooks on the functions fovea intercepts, what the
//! layer knows of each handle, and fovea's own density images on the application's device.
//!
//! Its files stand in floors: each file imports only files on floors below its own (never one on
//! its own floor or above), so a reader can start at the bottom and a change reaches upward only.
//! Outside this folder it imports the bridge and the shared plumbing only (`crate::bridge`,
//! `crate::common`); it never imports the Vulkan side.
//!
//! `tests/suite/meta/tidy.rs` holds the same table (`XR_FLOORS`) and fails on any import that runs
//! up or sideways; docs/ARCHITECTURE.md#floors draws both sides.
//!
//! | floor | path | job |
//! |---|---|---|
//! | 0 | `mod.rs` | this table and the module list; imports nothing |
//! | 1 | `ffi.rs` | the FFI edge: the entry shims (`shim!`) and the hook runner inside the panic guard ([`crate::common::guard`]), typed views of the application's pointers, next-chain walking and copying, C strings, the two-call idiom |
//! | 1 | `commands.rs` | the one list of intercepted functions, expanded into both tables ([`next_layer`], [`dispatch`]) |
//! | 1 | `extensions.rs` | the extensions fovea provides and which of them an instance has |
//! | 1 | `records.rs` | handle maps with a per-thread cache: per-frame look-ups without atomics |
//! | 1 | `session_gpu.rs` | what fovea keeps of a session's Vulkan device: the binding, the loader's entry points, FDM support, the queue, pool and fence it uploads with |
//! | 1 | `eye_centres.rs` | where each view's fovea is this frame: what the gaze source leaves for the maps, injection and `XR_META_foveation_eye_tracked` |
//! | 1 | `values.rs` | value conversions: OpenXR's result codes and FOVs as plain values and back |
//! | 1 | `foveation.rs` | what a density map is made from (the swapchain's foveation state, the located FOVs, the submitted views, the pattern under the debug overrides) and [`foveation::MapKey`], the one rule for when a map is stale |
//! | 2 | `density_images.rs` | fovea's own Vulkan objects: density images on the application's device, filled from the model |
//! | 2 | `gaze_sampling.rs` | fovea's own gaze source, per session: the attach state, the syncs alone, the gaze located after each `xrWaitFrame`, the filter; where each view's fovea is, once a frame |
//! | 2 | `gaze.rs` | fovea's own gaze source, per instance (above `gaze_sampling.rs`, whose sessions it makes): who uses it, the eye gaze action set, fovea's binding merged into the application's suggestions, the attach with the application's sets or alone |
//! | 2 | `next_layer.rs` | the next layer's table (expanded from the command list) and its loading; how a hook goes down |
//! | 3 | `registry.rs` | per-instance, per-session, per-swapchain and per-profile records (the FOV records among them), their look-ups and the losses the runtime reported; records only, no policy |
//! | 4 | `below.rs` | what lies below: the instance extensions the layers and runtime under fovea offer |
//! | 4 | `symmetric.rs` | symmetric-FOV mode: learning each eye's FOV and enlarging the recommended sizes |
//! | 4 | `pattern.rs` | the session's pattern policy: which pattern its swapchains' maps and injection use now, how far the dynamic controller may step, what injection publishes for the Vulkan side |
//! | 5 | `hooks/` (mod, actions, eye_tracked, foveation, frame, instance, session, swapchain, vulkan_enable, vulkan_layer) | the hook bodies, one file per function group: look up, do the layer's work, go down. A hook never imports another hook; `mod.rs` only lists them |
//! | 6 | `dispatch.rs` | the exported entry points and the hook table `xrGetInstanceProcAddr` answers from, expanded from the command list |
//! | 7 | `loader.rs` | negotiation, `xrCreateApiLayerInstance`, `xrGetInstanceProcAddr`, the layer's own enumerations |

pub mod below;
pub mod commands;
pub mod density_images;
pub mod dispatch;
pub mod extensions;
pub mod eye_centres;
pub mod ffi;
pub mod foveation;
pub mod gaze;
pub mod gaze_sampling;
pub mod hooks;
pub mod loader;
pub mod next_layer;
pub mod pattern;
pub mod records;
pub mod registry;
pub mod session_gpu;
pub mod symmetric;
pub mod values;
