//! Plumbing both sides of the layer use: the FFI panic guard, ranked locks, logging and settings.
//! Imports nothing else of the crate.

#[cfg(test)]
pub mod alloc_count;
pub mod guard;
pub mod lock;
pub mod log;
pub mod settings;
