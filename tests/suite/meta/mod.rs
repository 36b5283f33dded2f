//! The repository itself: house rules over the source tree, the checked-in manifests, the C header.

pub mod c_header;
pub mod manifests;
pub mod tidy;
