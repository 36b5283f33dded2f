//! Plumbing every side of the layer uses: the FFI edge (panic guard, next chains, the two-call
//! idiom), ranked locks, handle maps, logging and settings. Imports nothing else of the crate.

pub mod ffi;
pub mod lock;
pub mod log;
pub mod records;
pub mod settings;
