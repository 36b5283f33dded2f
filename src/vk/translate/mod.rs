//! Pure struct translation, with no device call: render passes version 1 → version 2 and without
//! the density map, synchronisation's stages, accesses and layouts, pipelines' shading-rate state,
//! and formats.

pub mod formats;
pub mod rate_state;
pub mod render_pass;
pub mod render_pass_v1;
pub mod sync;
