//! The repository itself: house rules over the source tree, the checked-in manifests, the C header,
//! and the commands and links of the README and docs/.

pub mod c_header;
pub mod docs_commands;
pub mod manifests;
pub mod tidy;
