//! The FFI edge and what every floor above shares of the loader: the panic guard and the caller's
//! arrays, `pNext` chains, the loader's link structs, the one command list and the next layer's
//! tables.

pub mod chain;
pub mod commands;
pub mod ffi;
pub mod link;
pub mod next;
pub mod structs;
