//! The `extern "system"` bodies of the intercepted commands, one file per kind of object: each
//! looks its device up, calls each mode in turn and calls down. A hook never imports another hook.

pub mod barrier;
pub mod device;
pub mod image;
pub mod instance;
pub mod pass;
pub mod physical;
pub mod pipeline;
pub mod record;
pub mod submit;
