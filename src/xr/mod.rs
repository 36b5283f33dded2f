//! The OpenXR side: the loader interface ([`loader`]), the one list of intercepted functions
//! ([`dispatch`]), what the layer knows of each handle ([`registry`]), the extensions it provides
//! ([`extensions`]) and the hooks, one module per function group ([`hooks`]); how symmetric-FOV mode learns the FOVs
//! ([`symmetric`]).

pub mod below;
pub mod dispatch;
pub mod extensions;
pub mod hooks;
pub mod loader;
pub mod registry;
pub mod symmetric;
