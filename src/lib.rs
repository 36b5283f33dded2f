//! fovea
