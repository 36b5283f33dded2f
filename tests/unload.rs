//! The loader unloads layers when the last instance is destroyed and loads them again for the next
//! one. libfovea.so is linked with `-z nodelete` (build.rs) so that a cycle loses nothing: its
//! statics (the handle registry, the log subscriber) have no destructors to run at unload.
//!
//! A test binary of its own, not a module of the suite (tests/suite): the test needs a process in
//! which libfovea.so was never loaded and no other test holds it open, and the suite's process loads
//! it for its other tests.

use fovea_harness::app::API_1_0;
use fovea_harness::{open_library, App, Chain, LayerSpec};

// The layer reads no fovea.toml and writes no log file in the user's home during tests.
fovea_harness::private_home!();

#[test]
fn the_layer_stays_loaded_once_the_loader_lets_go() {
    use libloading::os::unix::{Library, RTLD_LAZY};
    /// glibc's RTLD_NOLOAD: succeed only if the library is already loaded.
    const RTLD_NOLOAD: std::ffi::c_int = 4;
    let path = LayerSpec::fovea().unwrap().path;
    let loaded = || unsafe { Library::open(Some(&path), RTLD_LAZY | RTLD_NOLOAD) }.is_ok();
    assert!(!loaded(), "loaded before the test opened it");
    // A whole instance cycle, the way the loader runs it, then the last handle closed. On a thread
    // of its own: glibc does not unload a library while a live thread holds its thread-local
    // destructors, which would hide an unload.
    let p = path.clone();
    std::thread::spawn(move || {
        let app = App::new(Chain::fovea().unwrap(), &["XR_MND_headless"], API_1_0).unwrap();
        assert!(app.headless_session().is_ok());
        drop(app);
        drop(open_library(&p).unwrap());
    })
    .join()
    .unwrap();
    // glibc defers an unload that thread-local destructors held up to the next dlclose.
    drop(open_library(&path).unwrap());
    assert!(
        loaded(),
        "libfovea.so was unloaded: its statics are lost at every instance cycle"
    );
}
