//! The layer's own device objects: its calls on a device with the clears and uploads ahead of the
//! application's submits, shadows, the GPU converter of application-written maps with its shader
//! and the bindings it gives back, injection's maps, the ordering of the layer's uploads against
//! the application's other queues, and the reconstruction of coarse blocks with its shader.

pub mod bindings;
pub mod calls;
pub mod convert_shader;
pub mod converter;
pub mod injector;
pub mod order;
pub mod recon_shader;
pub mod reconstructor;
pub mod shadows;
