//! A fake OpenXR loader.
//!
//! It loads API layer libraries the way the Khronos loader does (`dlopen` with
//! `RTLD_LAZY | RTLD_LOCAL`, `xrNegotiateLoaderApiLayerInterface` with the loader's own version
//! ranges, one `XrApiLayerNextInfo` per layer, the topmost `xrGetInstanceProcAddr` for everything
//! after creation; docs/openxr-layer.md#loader-negotiation, #creating-the-instance) and ends in the
//! simulated runtime, linked in-process, so a test can drive a layer and read exactly what reached
//! the runtime through [`fovea_sim::control`].
//!
//! Differences from the real loader, on purpose: several instances may live at once (tests run in
//! parallel), and layers are named by path rather than discovered from manifests (the system-loader
//! tests cover discovery).

use std::ffi::{c_char, CStr, CString};
use std::path::{Path, PathBuf};

use openxr_sys as xr;
use xr::Handle;

pub use fovea_sim as sim;

/// The Khronos loader's interface and API version ranges (identical in 1.0.20 and 1.1.x).
pub const LOADER_MIN_API: xr::Version = xr::Version::new(1, 0, 0);
pub const LOADER_MAX_API: xr::Version = xr::Version::new(1, 0x3ff, 0xfff);

/// The layer name fovea registers under.
pub const FOVEA_LAYER: &str = "XR_APILAYER_FOVEA_foveation";
/// The Khronos core validation layer's name and where Debian installs it.
pub const CORE_VALIDATION_LAYER: &str = "XR_APILAYER_LUNARG_core_validation";
pub const CORE_VALIDATION_PATH: &str =
    "/usr/lib/x86_64-linux-gnu/openxr/1/api_layers/libXrApiLayer_core_validation.so";

/// A layer to load: its library and the name the loader would hand it.
#[derive(Clone, Debug)]
pub struct LayerSpec {
    pub path: PathBuf,
    pub name: String,
}

impl LayerSpec {
    /// The fovea layer built in this workspace (`target/<profile>/libfovea.so`), or the library
    /// named by `FOVEA_LAYER_LIB`.
    pub fn fovea() -> Result<LayerSpec, String> {
        let path = match std::env::var_os("FOVEA_LAYER_LIB") {
            Some(p) => PathBuf::from(p),
            None => artifact("libfovea.so")?,
        };
        Ok(LayerSpec {
            path,
            name: FOVEA_LAYER.to_owned(),
        })
    }

    /// Debian's Khronos core validation layer (`openxr-layer-corevalidation`), if installed.
    pub fn core_validation() -> Option<LayerSpec> {
        Path::new(CORE_VALIDATION_PATH).exists().then(|| LayerSpec {
            path: CORE_VALIDATION_PATH.into(),
            name: CORE_VALIDATION_LAYER.to_owned(),
        })
    }
}

/// The test layer that refuses every `xrGetInstanceProcAddr(XR_NULL_HANDLE, ...)`, as the CTS
/// conformance layer does (crates/refuser).
pub const REFUSE_NULL_LOOKUPS_LAYER: &str = "XR_APILAYER_FOVEA_test_refuse_null_lookups";
/// The test layer that reports no instance extensions below it (crates/refuser).
pub const HIDE_EXTENSIONS_LAYER: &str = "XR_APILAYER_FOVEA_test_hide_extensions";

impl LayerSpec {
    /// crates/refuser's `libfovea_refuser.so` under [`REFUSE_NULL_LOOKUPS_LAYER`]: passes everything
    /// through except that every NULL-instance lookup is XR_ERROR_HANDLE_INVALID.
    pub fn refuse_null_lookups() -> Result<LayerSpec, String> {
        Ok(LayerSpec {
            path: artifact("libfovea_refuser.so")?,
            name: REFUSE_NULL_LOOKUPS_LAYER.to_owned(),
        })
    }

    /// The same library under [`HIDE_EXTENSIONS_LAYER`]: a NULL-instance
    /// `xrEnumerateInstanceExtensionProperties` lists nothing below it.
    pub fn hide_extensions() -> Result<LayerSpec, String> {
        Ok(LayerSpec {
            path: artifact("libfovea_refuser.so")?,
            name: HIDE_EXTENSIONS_LAYER.to_owned(),
        })
    }

    /// Writes an explicit-layer manifest for this layer into `dir` (file format 1.0.0; the keys the
    /// Khronos loader requires, see https://registry.khronos.org/OpenXR/specs/1.0/loader.html) and
    /// returns its path. Point `XR_API_LAYER_PATH` at `dir` and enable the layer by name.
    pub fn write_manifest(&self, dir: &Path) -> Result<PathBuf, String> {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let path = dir.join(format!("{}.json", self.name));
        let json = format!(
            r#"{{
  "file_format_version": "1.0.0",
  "api_layer": {{
    "name": "{}",
    "library_path": "{}",
    "api_version": "1.0",
    "implementation_version": "1",
    "description": "written by a fovea test"
  }}
}}
"#,
            self.name,
            self.path.display()
        );
        std::fs::write(&path, json).map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(path)
    }
}

/// What crates/refuser's layer saw in this process (its `fovea_refuser_stats`, same layout).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RefuserStats {
    pub null_lookups: u64,
    pub null_lookups_refused: u64,
    pub hidden_enumerations: u64,
    pub forwarded_lookups: u64,
    pub instances_created: u64,
    pub instances_destroyed: u64,
}

/// Reads the counters of the refuser library at `path` as loaded in this process (opening it again
/// returns the copy a loader already holds; a fresh copy reads all zeros).
pub fn refuser_stats(path: &Path) -> Result<RefuserStats, String> {
    let lib = open_library(path)?;
    // SAFETY: the symbol has this type in crates/refuser; the struct layouts are the same.
    unsafe {
        let f = lib
            .get::<unsafe extern "C" fn(*mut RefuserStats)>(b"fovea_refuser_stats\0")
            .map_err(|e| format!("no fovea_refuser_stats in {}: {e}", path.display()))?;
        let mut stats = RefuserStats::default();
        f(&mut stats);
        Ok(stats)
    }
}

/// A build artifact of this workspace, found next to the running executable: a test binary sits in
/// `target/<profile>/deps`, the `fovea` binary in `target/<profile>`.
///
/// `cargo test` links crates as rlibs and does not rebuild the cdylibs the harness loads, so a
/// library older than its sources is refused: testing yesterday's layer and passing would be worse
/// than failing.
pub fn artifact(file: &str) -> Result<PathBuf, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let mut dir = exe.parent();
    while let Some(d) = dir {
        let candidate = d.join(file);
        if candidate.exists() {
            check_fresh(&candidate, file)?;
            return Ok(candidate);
        }
        if d.file_name().is_some_and(|n| n == "target") {
            break;
        }
        dir = d.parent();
    }
    Err(format!(
        "{file} not found next to {}: run `cargo build` first",
        exe.display()
    ))
}

/// The source folders each library of this workspace is built from.
fn sources_of(file: &str) -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    match file {
        "libfovea.so" => vec![root.join("src"), root.join("crates/headsets/src")],
        "libfovea_sim.so" => vec![
            root.join("crates/sim/src"),
            root.join("crates/headsets/src"),
        ],
        "libfovea_refuser.so" => vec![root.join("crates/refuser/src")],
        _ => Vec::new(),
    }
}

fn newest(dir: &Path) -> Option<std::time::SystemTime> {
    let mut best = None;
    for entry in std::fs::read_dir(dir).ok()?.flatten() {
        let path = entry.path();
        let t = if path.is_dir() {
            newest(&path)
        } else {
            entry.metadata().ok()?.modified().ok()
        };
        best = best.max(t);
    }
    best
}

fn check_fresh(library: &Path, file: &str) -> Result<(), String> {
    let built = std::fs::metadata(library)
        .and_then(|m| m.modified())
        .map_err(|e| e.to_string())?;
    let source = sources_of(file).iter().filter_map(|d| newest(d)).max();
    match source {
        Some(s) if s > built => Err(format!(
            "{} is older than its sources: run `cargo build` first (cargo test does not rebuild it)",
            library.display()
        )),
        _ => Ok(()),
    }
}

/// The validation layer's features the tests' Vulkan instances turn on: synchronization validation
/// (hazards between commands and submissions,
/// <https://vulkan.lunarg.com/doc/sdk/latest/linux/synchronization_usage.html>), unless
/// `FOVEA_VK_SYNC_VALIDATION=0`. `.ci/valgrind` sets that: validation 1.3.239's synchronization
/// state for command buffers is lost under memcheck (its own leak, not the code under test), and
/// the suite runs with it on in both roots anyway.
pub fn validation_enables() -> &'static [ash::vk::ValidationFeatureEnableEXT] {
    const SYNC: [ash::vk::ValidationFeatureEnableEXT; 1] =
        [ash::vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
    if std::env::var("FOVEA_VK_SYNC_VALIDATION").is_ok_and(|v| v.trim() == "0") {
        &[]
    } else {
        &SYNC
    }
}

/// Whether tests that need a system component must fail rather than skip (`FOVEA_REQUIRE_SYSTEM=1`,
/// set by CI).
pub fn require_system() -> bool {
    std::env::var("FOVEA_REQUIRE_SYSTEM").is_ok_and(|v| v == "1")
}

/// Skips (prints why and returns `true`) or, under `FOVEA_REQUIRE_SYSTEM=1`, panics.
pub fn skip(reason: &str) -> bool {
    if require_system() {
        panic!("required system component missing: {reason}");
    }
    eprintln!("SKIPPED: {reason}");
    true
}

/// Checks that `checked_in` is the SPIR-V glslang builds from the GLSL file `source` with `defines`
/// (`-DNAME` arguments), as the shaders' `build.sh` scripts build it: a shader edited without
/// rebuilding its SPIR-V fails here. Skips ([`skip`]) where glslang-tools is not installed. The
/// bytes are the installed glslang's: other releases emit others (`.ci/run` skips these checks in
/// the Debian 13 root for that reason).
pub fn assert_spirv_built_from(source: &Path, defines: &[&str], checked_in: &[u8]) {
    let version = std::process::Command::new("glslangValidator")
        .arg("--version")
        .output();
    if version.is_err() {
        skip("glslangValidator is not installed (glslang-tools)");
        return;
    }
    let out = std::env::temp_dir().join(format!(
        "fovea-spirv-{}-{:?}.spv",
        std::process::id(),
        std::thread::current().id()
    ));
    let run = std::process::Command::new("glslangValidator")
        .args(["-V", "--target-env", "vulkan1.1", "-o"])
        .arg(&out)
        .args(defines)
        .arg(source)
        .output()
        .expect("glslangValidator runs");
    let built = std::fs::read(&out);
    let _ = std::fs::remove_file(&out);
    assert!(
        run.status.success(),
        "{} {defines:?} does not compile: {}",
        source.display(),
        String::from_utf8_lossy(&run.stdout)
    );
    assert!(
        built.expect("glslang's output") == checked_in,
        "{} {defines:?}: the checked-in SPIR-V is stale; run the build.sh beside it",
        source.display()
    );
}

/// One loaded, negotiated layer library.
pub struct LoadedLayer {
    pub spec: LayerSpec,
    name: CString,
    pub gipa: xr::pfn::GetInstanceProcAddr,
    pub create: xr::pfn::CreateApiLayerInstance,
    _lib: libloading::Library,
}

/// Opens a library as the loader does: `RTLD_LAZY | RTLD_LOCAL`.
pub fn open_library(path: &Path) -> Result<libloading::Library, String> {
    use libloading::os::unix::{Library, RTLD_LAZY, RTLD_LOCAL};
    // SAFETY: loading a layer runs its initialisers; that is what loading a layer means.
    unsafe { Library::open(Some(path), RTLD_LAZY | RTLD_LOCAL) }
        .map(Into::into)
        .map_err(|e| format!("dlopen {}: {e}", path.display()))
}

/// The loader's `XrNegotiateLoaderInfo`.
pub fn loader_info() -> xr::NegotiateLoaderInfo {
    xr::NegotiateLoaderInfo {
        struct_type: xr::NegotiateLoaderInfo::TYPE,
        struct_version: xr::NegotiateLoaderInfo::VERSION,
        struct_size: std::mem::size_of::<xr::NegotiateLoaderInfo>(),
        min_interface_version: 1,
        max_interface_version: 1,
        min_api_version: LOADER_MIN_API,
        max_api_version: LOADER_MAX_API,
    }
}

/// The loader's empty `XrNegotiateApiLayerRequest`.
pub fn layer_request() -> xr::NegotiateApiLayerRequest {
    xr::NegotiateApiLayerRequest {
        struct_type: xr::NegotiateApiLayerRequest::TYPE,
        struct_version: xr::NegotiateApiLayerRequest::VERSION,
        struct_size: std::mem::size_of::<xr::NegotiateApiLayerRequest>(),
        layer_interface_version: 0,
        layer_api_version: xr::Version::new(0, 0, 0),
        get_instance_proc_addr: None,
        create_api_layer_instance: None,
    }
}

impl LoadedLayer {
    /// Loads and negotiates a layer.
    pub fn load(spec: LayerSpec) -> Result<LoadedLayer, String> {
        let lib = open_library(&spec.path)?;
        let name = CString::new(spec.name.clone()).map_err(|e| e.to_string())?;
        let negotiate = negotiate_symbol(&lib)?;
        let info = loader_info();
        let mut request = layer_request();
        // SAFETY: both structs are valid and live across the call.
        let r = unsafe { negotiate(&info, name.as_ptr(), &mut request) };
        if r != xr::Result::SUCCESS {
            return Err(format!("{}: negotiation failed with {r:?}", spec.name));
        }
        match (
            request.get_instance_proc_addr,
            request.create_api_layer_instance,
        ) {
            (Some(gipa), Some(create)) => Ok(LoadedLayer {
                spec,
                name,
                gipa,
                create,
                _lib: lib,
            }),
            _ => Err(format!(
                "{}: negotiation returned NULL entry points",
                spec.name
            )),
        }
    }
}

/// A library's `xrNegotiateLoaderApiLayerInterface`.
pub fn negotiate_symbol(
    lib: &libloading::Library,
) -> Result<xr::pfn::NegotiateLoaderApiLayerInterface, String> {
    // SAFETY: the symbol's type is fixed by the loader interface.
    unsafe {
        lib.get::<xr::pfn::NegotiateLoaderApiLayerInterface>(
            b"xrNegotiateLoaderApiLayerInterface\0",
        )
        .map(|s| *s)
        .map_err(|e| format!("no xrNegotiateLoaderApiLayerInterface: {e}"))
    }
}

/// A stack of layers in front of the simulated runtime; index 0 is closest to the application.
pub struct Chain {
    pub layers: Vec<LoadedLayer>,
}

/// The terminator's `xrCreateApiLayerInstance`: ignores the layer info and calls the runtime's
/// `xrCreateInstance` with the create info it receives, as the Khronos loader's terminator does.
unsafe extern "system" fn terminator_create(
    info: *const xr::InstanceCreateInfo,
    _layer_info: *const xr::ApiLayerCreateInfo,
    instance: *mut xr::Instance,
) -> xr::Result {
    match runtime_fn::<xr::pfn::CreateInstance>(xr::Instance::NULL, c"xrCreateInstance") {
        Ok(create) => create(info, instance),
        Err(r) => r,
    }
}

/// The runtime's own `xrGetInstanceProcAddr`.
pub fn runtime_gipa() -> xr::pfn::GetInstanceProcAddr {
    fovea_sim::get_instance_proc_addr
}

/// A typed function from the runtime, bypassing every layer.
///
/// # Safety
/// `F` must be the function type the name implies.
pub unsafe fn runtime_fn<F: Copy>(instance: xr::Instance, name: &CStr) -> Result<F, xr::Result> {
    lookup(runtime_gipa(), instance, name)
}

/// A typed function through a `xrGetInstanceProcAddr`.
///
/// # Safety
/// `F` must be the function type the name implies (a function pointer).
pub unsafe fn lookup<F: Copy>(
    gipa: xr::pfn::GetInstanceProcAddr,
    instance: xr::Instance,
    name: &CStr,
) -> Result<F, xr::Result> {
    assert_eq!(
        std::mem::size_of::<F>(),
        std::mem::size_of::<xr::pfn::VoidFunction>()
    );
    let mut f = None;
    let r = gipa(instance, name.as_ptr(), &mut f);
    match (r, f) {
        (xr::Result::SUCCESS, Some(f)) => {
            Ok(std::mem::transmute_copy::<xr::pfn::VoidFunction, F>(&f))
        }
        (xr::Result::SUCCESS, None) => panic!("{name:?}: XR_SUCCESS with a NULL pointer"),
        (r, _) => Err(r),
    }
}

impl Chain {
    /// Loads and negotiates every layer, outermost first.
    pub fn new(specs: Vec<LayerSpec>) -> Result<Chain, String> {
        Ok(Chain {
            layers: specs
                .into_iter()
                .map(LoadedLayer::load)
                .collect::<Result<_, _>>()?,
        })
    }

    /// fovea alone in front of the runtime.
    pub fn fovea() -> Result<Chain, String> {
        Chain::new(vec![LayerSpec::fovea()?])
    }

    /// No layer: the application talks to the runtime directly (the baseline for comparisons).
    pub fn bare() -> Chain {
        Chain { layers: Vec::new() }
    }

    /// The `xrGetInstanceProcAddr` the application uses: the topmost layer's, or the runtime's.
    pub fn gipa(&self) -> xr::pfn::GetInstanceProcAddr {
        self.layers.first().map_or(runtime_gipa(), |l| l.gipa)
    }

    /// What the loader checks before any layer runs (docs/openxr-layer.md#enumerating-extensions):
    /// every enabled extension must come from the runtime or an enabled layer.
    pub fn available_extensions(&self) -> Vec<String> {
        let mut names = Vec::new();
        // SAFETY: the enumerate functions are called with valid buffers.
        unsafe {
            if let Ok(f) = runtime_fn::<xr::pfn::EnumerateInstanceExtensionProperties>(
                xr::Instance::NULL,
                c"xrEnumerateInstanceExtensionProperties",
            ) {
                names.extend(enumerate_extensions(f, std::ptr::null()));
            }
            for l in &self.layers {
                if let Ok(f) = lookup::<xr::pfn::EnumerateInstanceExtensionProperties>(
                    l.gipa,
                    xr::Instance::NULL,
                    c"xrEnumerateInstanceExtensionProperties",
                ) {
                    names.extend(enumerate_extensions(f, l.name.as_ptr()));
                }
            }
        }
        names
    }

    /// `xrCreateInstance` as the loader performs it: the pre-check, then one next-info per layer and
    /// the topmost layer's `xrCreateApiLayerInstance`.
    ///
    /// # Safety
    /// `info` must be a valid `XrInstanceCreateInfo`.
    pub unsafe fn create_instance(
        &self,
        info: *const xr::InstanceCreateInfo,
        instance: *mut xr::Instance,
    ) -> xr::Result {
        if !info.is_null() {
            let available = self.available_extensions();
            let i = &*info;
            for k in 0..i.enabled_extension_count as usize {
                let name = CStr::from_ptr(*i.enabled_extension_names.add(k)).to_string_lossy();
                if !available.iter().any(|a| *a == name) {
                    return xr::Result::ERROR_EXTENSION_NOT_PRESENT;
                }
            }
        }
        let Some(top) = self.layers.first() else {
            return terminator_create(info, std::ptr::null(), instance);
        };
        let n = self.layers.len();
        let mut infos: Vec<xr::ApiLayerNextInfo> =
            (0..n)
                .map(|k| {
                    let mut ni =
                        xr::ApiLayerNextInfo {
                            struct_type: xr::ApiLayerNextInfo::TYPE,
                            struct_version: xr::ApiLayerNextInfo::VERSION,
                            struct_size: std::mem::size_of::<xr::ApiLayerNextInfo>(),
                            layer_name: [0; xr::MAX_API_LAYER_NAME_SIZE],
                            next_get_instance_proc_addr: Some(
                                self.layers.get(k + 1).map_or(runtime_gipa(), |l| l.gipa),
                            ),
                            next_create_api_layer_instance: Some(self.layers.get(k + 1).map_or(
                                terminator_create as xr::pfn::CreateApiLayerInstance,
                                |l| l.create,
                            )),
                            next: std::ptr::null_mut(),
                        };
                    for (d, s) in ni.layer_name.iter_mut().zip(self.layers[k].name.as_bytes()) {
                        *d = *s as c_char;
                    }
                    ni
                })
                .collect();
        for k in (0..n.saturating_sub(1)).rev() {
            let next: *mut xr::ApiLayerNextInfo = &mut infos[k + 1];
            infos[k].next = next;
        }
        let create_info = xr::ApiLayerCreateInfo {
            struct_type: xr::ApiLayerCreateInfo::TYPE,
            struct_version: xr::ApiLayerCreateInfo::VERSION,
            struct_size: std::mem::size_of::<xr::ApiLayerCreateInfo>(),
            loader_instance: std::ptr::null_mut(),
            settings_file_location: [0; xr::API_LAYER_MAX_SETTINGS_PATH_SIZE],
            next_info: infos.as_mut_ptr(),
        };
        (top.create)(info, &create_info, instance)
    }
}

/// Extension names from an `xrEnumerateInstanceExtensionProperties`.
///
/// # Safety
/// `f` must be such a function; `layer` NULL or NUL-terminated.
pub unsafe fn enumerate_extensions(
    f: xr::pfn::EnumerateInstanceExtensionProperties,
    layer: *const c_char,
) -> Vec<String> {
    let mut n = 0;
    if f(layer, 0, &mut n, std::ptr::null_mut()) != xr::Result::SUCCESS {
        return Vec::new();
    }
    let empty = xr::ExtensionProperties {
        ty: xr::StructureType::EXTENSION_PROPERTIES,
        next: std::ptr::null_mut(),
        extension_name: [0; xr::MAX_EXTENSION_NAME_SIZE],
        extension_version: 0,
    };
    let mut props = vec![empty; n as usize];
    if f(layer, n, &mut n, props.as_mut_ptr()) != xr::Result::SUCCESS {
        return Vec::new();
    }
    props
        .iter()
        .take(n as usize)
        .map(|p| {
            CStr::from_ptr(p.extension_name.as_ptr())
                .to_string_lossy()
                .into_owned()
        })
        .collect()
}

pub mod app;
pub mod fns;
pub mod frame_loop;
pub mod vulkan;
pub use app::App;

/// Where a test process's `$XDG_CONFIG_HOME` and `$XDG_STATE_HOME` point ([`private_home!`]):
/// `fovea-test-home/` under the system's temporary folder, so tests never read the user's
/// `fovea.toml` nor append to their `fovea.log`.
pub fn private_home() -> PathBuf {
    std::env::temp_dir().join("fovea-test-home")
}

/// Sets `XDG_CONFIG_HOME` and `XDG_STATE_HOME` to [`private_home`]'s folders; what
/// [`private_home!`] runs before `main`.
pub fn use_private_home() {
    let home = private_home();
    std::env::set_var("XDG_CONFIG_HOME", home.join("config"));
    std::env::set_var("XDG_STATE_HOME", home.join("state"));
}

/// In a test binary that loads the layer: points the XDG folders the layer reads at
/// [`private_home`] before `main` runs, while the process has one thread (so setting the
/// environment races with nothing), and for every child the tests start. Tests that need other
/// folders set them in a process of their own.
#[macro_export]
macro_rules! private_home {
    () => {
        // Run by the dynamic loader with the other constructors of the executable, before `main`
        // (https://refspecs.linuxfoundation.org/LSB_5.0.0/LSB-Core-generic/LSB-Core-generic/specialsections.html).
        #[used]
        #[link_section = ".init_array"]
        static FOVEA_PRIVATE_HOME: extern "C" fn() = {
            extern "C" fn set() {
                $crate::use_private_home();
            }
            set
        };
    };
}
