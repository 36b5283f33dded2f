//! Link flags for libfovea.so.
//!
//! `-z nodelete`: once loaded, the layer stays loaded for the life of the process. The Khronos loader
//! `dlclose`s layers when the last instance is destroyed and opens them again for the next one. fovea
//! keeps process-wide state in Rust statics (the handle registry, the `tracing` subscriber) that no
//! destructor runs for at unload, so every unload lost that memory (valgrind: ~35 KB per cycle), and
//! a thread-local destructor registered by the library would run after its code was unmapped. Kept
//! loaded, a new instance finds the same statics.
fn main() {
    println!("cargo:rustc-cdylib-link-arg=-Wl,-z,nodelete");
    println!("cargo:rerun-if-changed=build.rs");
}
