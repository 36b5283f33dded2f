//! What lies below fovea: the instance extensions the layers and the runtime under it offer, learned
//! without depending on which layers are stacked, and without a call the runtime could refuse.
//!
//! The loader's way is `xrGetInstanceProcAddr(XR_NULL_HANDLE, "xrEnumerateInstanceExtensionProperties")`
//! through the next layer
//! (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#xrGetInstanceProcAddr). It creates
//! nothing below, so fovea asks that way at every `xrCreateInstance` and keeps nothing: the answer is
//! always fresh. Some layers refuse every lookup without an instance (the conformance suite's own
//! layer does), and a list of names to step past cannot keep up with every layer users stack. Where
//! that lookup is refused, fovea asks through an instance instead, where the lookup is legal for every
//! layer: a **probe**, an instance of its own created below, asked, and destroyed before the
//! application's instance is created. Two rules keep the probe out of the runtime's way (under the
//! conformance suite on Monado a probe per application instance made 646 runtime instances instead of
//! 323, and the runtime logged errors for create infos the suite had made invalid on purpose):
//!
//! - **Once per process and stack.** What a probe learned is kept for the process, keyed by the names
//!   of the layers below fovea (the loader's `XrApiLayerNextInfo` chain past fovea's entry): the same
//!   stack is never probed twice, a different one is asked again. libfovea.so stays loaded for the
//!   process (`-z nodelete`, build.rs), so the answer survives the loader's unloading between
//!   instances. The loader names no runtime before an instance exists, so a process that switches
//!   runtimes between instances (a changed `XR_RUNTIME_JSON`) under a refusing layer keeps the first
//!   runtime's answer. A probe the runtime could not create (no runtime running yet, an instance
//!   limit) teaches nothing and is not kept: the next application instance asks again.
//! - **Only with a create info fovea knows valid.** The probe never carries the application's strings,
//!   chain, layers or extensions: its application name is "fovea", its engine name empty, its API
//!   version 1.0 (`XR_API_VERSION_1_0`, which every 1.x runtime supports), no extension, no next
//!   chain; only the loader's layer chain past fovea goes with it, as for the application's instance.
//!   And where the application's own create info is one the spec obliges every runtime to refuse (an
//!   empty or unterminated application name: XR_ERROR_NAME_INVALID; an API version whose major is not
//!   1: XR_ERROR_API_VERSION_UNSUPPORTED; create flags, none of which are defined:
//!   XR_ERROR_VALIDATION_FAILURE;
//!   https://registry.khronos.org/OpenXR/specs/1.0/man/html/xrCreateInstance.html,
//!   XrApplicationInfo.html), fovea does not probe: that call can only fail, and it goes down as it
//!   is and fails on its own, so the runtime sees the application's call and nothing of fovea's. What
//!   the runtime refuses by its own state or offer (an extension it lacks, a version it does not
//!   implement) fovea cannot tell beforehand; the probe it may make first is valid and is refused
//!   nothing.
//!
//! The log says once per process that a probe was needed. Where the list cannot be learned at all,
//! fovea provides every extension of its own the application enabled, and says so once.

use std::ffi::CString;
use std::sync::atomic::{AtomicBool, Ordering};

use openxr_sys as xr;
use parking_lot::Mutex;
use xr::Handle;

use crate::xr::ffi;
use crate::xr::next_layer;

/// The once-per-process line about how the list was learned was written.
static SAID: AtomicBool = AtomicBool::new(false);

/// What probes learned, per stack below fovea (the layer names, outermost first): a handful of
/// entries per process, read and written at instance creation only. Held across a probe, so that two
/// threads creating instances at once under a stack not yet known make one probe between them.
static LEARNED: Mutex<Vec<(Vec<String>, Vec<CString>)>> = Mutex::new(Vec::new());

/// More entries than any loader's chain has: a malformed, cyclic list stops here.
const MAX_LAYERS: usize = 64;

/// Layers known to mishandle an `xrGetInstanceProcAddr` with XR_NULL_HANDLE and to provide no
/// instance extensions: Debian's core validation layer (1.0.20) prints "INTERNAL VALIDATION LAYER
/// ERROR: Null handle passed to HandleInfoBase::get()" and answers nothing. fovea asks the layer
/// below it instead, so a stack with core validation under fovea stays silent and still learns what
/// the runtime offers natively.
const NO_NULL_INSTANCE_LOOKUP: [&str; 1] = ["XR_APILAYER_LUNARG_core_validation"];

/// The extension names the layers and runtime below offer (see the module's text). Empty where
/// nothing can tell: fovea then provides every extension the application enabled.
///
/// # Safety
/// `ours` must be fovea's own, validated next-info entry; `app` and `layer_info` the create call's
/// validated arguments (`layer_info` still pointing at `ours`), with `next_create` the next layer's
/// `xrCreateApiLayerInstance`.
pub unsafe fn extensions_below(
    next_gipa: xr::pfn::GetInstanceProcAddr,
    ours: &xr::ApiLayerNextInfo,
    next_create: xr::pfn::CreateApiLayerInstance,
    app: &xr::InstanceCreateInfo,
    layer_info: &xr::ApiLayerCreateInfo,
) -> Vec<CString> {
    // SAFETY: the caller upholds this function's `# Safety` contract; the comments inside say
    // what each step relies on.
    unsafe {
        let gipa = enumeration_gipa(next_gipa, ours);
        if let Some(f) = next_layer::load(
            gipa,
            xr::Instance::NULL,
            c"xrEnumerateInstanceExtensionProperties",
        ) {
            // SAFETY: the name's signature is that of the pfn type.
            let enumerate: xr::pfn::EnumerateInstanceExtensionProperties = std::mem::transmute(f);
            if let Some(list) = enumerate_with(enumerate) {
                return list;
            }
        }
        let stack = stack_below(ours);
        let mut learned = LEARNED.lock();
        if let Some((_, list)) = learned.iter().find(|(s, _)| *s == stack) {
            return list.clone();
        }
        if let Some(why) = refused_by_every_runtime(app) {
            tracing::debug!(
                target: fovea_abi::log_target::BELOW,
                why,
                "no probe for a create info every runtime refuses"
            );
            return Vec::new();
        }
        let (list, keep) = match probe(next_gipa, next_create, layer_info) {
            Probe::Listed(list) => {
                if !SAID.swap(true, Ordering::Relaxed) {
                    tracing::info!(
                        target: fovea_abi::log_target::BELOW,
                        "a layer below fovea refuses lookups without an instance; fovea learns what \
                         the runtime offers through an instance of its own, once for each stack of \
                         layers (said once for this process)"
                    );
                }
                (list, true)
            }
            Probe::Unlisted => {
                if !SAID.swap(true, Ordering::Relaxed) {
                    tracing::warn!(
                        target: fovea_abi::log_target::BELOW,
                        "fovea cannot learn which extensions the runtime offers (the layers below \
                         refuse to list them, with and without an instance); it provides every \
                         extension of its own the application enables (said once for this process)"
                    );
                }
                (Vec::new(), true)
            }
            Probe::NoInstance(r) => {
                tracing::warn!(
                    target: fovea_abi::log_target::BELOW,
                    ?r,
                    "fovea cannot learn which extensions the runtime offers now (the layers below \
                     refuse to list them without an instance, and none could be created to ask); \
                     for this instance it provides every extension of its own the application \
                     enables, and asks again at the next"
                );
                (Vec::new(), false)
            }
        };
        if keep {
            learned.push((stack, list.clone()));
        }
        list
    }
}

/// The names of the layers below fovea, outermost first: what the loader's next-info list says
/// after fovea's own entry.
///
/// # Safety
/// `ours` must be fovea's own, validated next-info entry.
unsafe fn stack_below(ours: &xr::ApiLayerNextInfo) -> Vec<String> {
    let mut names = Vec::new();
    let mut below = ours.next;
    // SAFETY: the loader's next-info list is valid to its end; each entry's type is checked before
    // its fields are read.
    while let Some(entry) = unsafe { below.as_ref() } {
        if entry.struct_type != xr::ApiLayerNextInfo::TYPE || names.len() == MAX_LAYERS {
            break;
        }
        names.push(ffi::read_fixed(&entry.layer_name));
        below = entry.next;
    }
    names
}

/// Why every runtime must refuse `app` whatever it offers, if it must
/// (https://registry.khronos.org/OpenXR/specs/1.0/man/html/xrCreateInstance.html,
/// https://registry.khronos.org/OpenXR/specs/1.0/man/html/XrApplicationInfo.html): the checks a
/// runtime makes on the create info alone, without its state or its offer.
fn refused_by_every_runtime(app: &xr::InstanceCreateInfo) -> Option<&'static str> {
    let info = &app.application_info;
    let name = &info.application_name;
    if name.first().is_none_or(|c| *c == 0) || !name.contains(&0) {
        return Some("the application name is empty or unterminated (XR_ERROR_NAME_INVALID)");
    }
    if !info.engine_name.contains(&0) {
        return Some("the engine name is unterminated (XR_ERROR_VALIDATION_FAILURE)");
    }
    if info.api_version.major() != 1 {
        return Some("the API version's major is not 1 (XR_ERROR_API_VERSION_UNSUPPORTED)");
    }
    if app.create_flags != xr::InstanceCreateFlags::EMPTY {
        return Some("create flags are set, and none is defined (XR_ERROR_VALIDATION_FAILURE)");
    }
    None
}

/// The `xrGetInstanceProcAddr` to ask for the extensions below: the next layer's, or, past layers in
/// [`NO_NULL_INSTANCE_LOOKUP`], the first one below them (the runtime's at the end of the chain).
///
/// # Safety
/// `ours` must be fovea's own, validated next-info entry.
unsafe fn enumeration_gipa(
    next_gipa: xr::pfn::GetInstanceProcAddr,
    ours: &xr::ApiLayerNextInfo,
) -> xr::pfn::GetInstanceProcAddr {
    // SAFETY: the caller upholds this function's `# Safety` contract; the comments inside say
    // what each step relies on.
    unsafe {
        let mut gipa = next_gipa;
        let mut below = ours.next;
        // SAFETY: the loader's next-info list is valid to its end.
        while !below.is_null()
            && (*below).struct_type == xr::ApiLayerNextInfo::TYPE
            && NO_NULL_INSTANCE_LOOKUP.contains(&ffi::read_fixed(&(*below).layer_name).as_ref())
        {
            match (*below).next_get_instance_proc_addr {
                Some(g) => gipa = g,
                None => break,
            }
            below = (*below).next;
        }
        gipa
    }
}

/// What a probe taught.
enum Probe {
    /// The extensions below.
    Listed(Vec<CString>),
    /// An instance was created but the layers below would not list them on it: asking again with
    /// the same stack would get the same answer.
    Unlisted,
    /// No instance could be created (the runtime's state: not running, an instance limit), with the
    /// result: a later instance may ask again.
    NoInstance(xr::Result),
}

/// The create info of a probe: fovea's own, valid for every 1.x runtime (see the module's text).
fn probe_create_info() -> xr::InstanceCreateInfo {
    let mut application_info = xr::ApplicationInfo {
        application_name: [0; xr::MAX_APPLICATION_NAME_SIZE],
        application_version: 0,
        engine_name: [0; xr::MAX_ENGINE_NAME_SIZE],
        engine_version: 0,
        // XR_API_VERSION_1_0 as openxr.h defines it since 1.1: 1.0 with the headers' patch.
        api_version: xr::Version::new(1, 0, xr::CURRENT_API_VERSION.patch()),
    };
    ffi::write_fixed(&mut application_info.application_name, "fovea");
    xr::InstanceCreateInfo {
        ty: xr::StructureType::INSTANCE_CREATE_INFO,
        next: std::ptr::null(),
        create_flags: xr::InstanceCreateFlags::EMPTY,
        application_info,
        enabled_api_layer_count: 0,
        enabled_api_layer_names: std::ptr::null(),
        enabled_extension_count: 0,
        enabled_extension_names: std::ptr::null(),
    }
}

/// Creates an instance below with fovea's own create info, asks it for the extensions below, and
/// destroys it.
///
/// # Safety
/// As [`extensions_below`].
unsafe fn probe(
    next_gipa: xr::pfn::GetInstanceProcAddr,
    next_create: xr::pfn::CreateApiLayerInstance,
    layer_info: &xr::ApiLayerCreateInfo,
) -> Probe {
    // SAFETY: the caller upholds this function's `# Safety` contract; the comments inside say
    // what each step relies on.
    unsafe {
        let info = probe_create_info();
        // The next layer reads the loader's list from the entry after fovea's, as for the real instance.
        let mut down = *layer_info;
        // SAFETY: `next_info` is fovea's own entry, validated non-NULL by the caller.
        down.next_info = (*layer_info.next_info).next;
        let mut instance = xr::Instance::NULL;
        // SAFETY: fovea's own create info and a copy of the loader's layer info, pointing past fovea.
        let r = next_create(&info, &down, &mut instance);
        if r.into_raw() < 0 || instance == xr::Instance::NULL {
            return Probe::NoInstance(r);
        }
        let list = next_layer::load(
            next_gipa,
            instance,
            c"xrEnumerateInstanceExtensionProperties",
        )
        // SAFETY: the name's signature is that of the pfn type.
        .and_then(|f| {
            enumerate_with(std::mem::transmute::<
                xr::pfn::VoidFunction,
                xr::pfn::EnumerateInstanceExtensionProperties,
            >(f))
        });
        match next_layer::load(next_gipa, instance, c"xrDestroyInstance") {
            Some(f) => {
                // SAFETY: the name's signature is that of the pfn type; the instance is fovea's own.
                let destroy: xr::pfn::DestroyInstance = std::mem::transmute(f);
                destroy(instance);
            }
            None => {
                tracing::warn!(
                    target: fovea_abi::log_target::BELOW,
                    "the instance fovea created to ask what lies below cannot be destroyed"
                )
            }
        }
        list.map_or(Probe::Unlisted, Probe::Listed)
    }
}

/// Every extension `enumerate` lists (layer name NULL: the runtime's and the implicit layers'
/// below); `None` where it fails.
///
/// # Safety
/// `enumerate` must be a valid `xrEnumerateInstanceExtensionProperties`.
unsafe fn enumerate_with(
    enumerate: xr::pfn::EnumerateInstanceExtensionProperties,
) -> Option<Vec<CString>> {
    // SAFETY: the caller upholds this function's `# Safety` contract; the comments inside say
    // what each step relies on.
    unsafe {
        let mut count = 0;
        // SAFETY: the two-call idiom with fovea's own output.
        if enumerate(std::ptr::null(), 0, &mut count, std::ptr::null_mut()).into_raw() < 0 {
            return None;
        }
        let empty = xr::ExtensionProperties {
            ty: xr::StructureType::EXTENSION_PROPERTIES,
            next: std::ptr::null_mut(),
            extension_name: [0; xr::MAX_EXTENSION_NAME_SIZE],
            extension_version: 0,
        };
        let mut props = vec![empty; count as usize];
        // SAFETY: as above, `count` elements.
        if enumerate(std::ptr::null(), count, &mut count, props.as_mut_ptr()).into_raw() < 0 {
            return None;
        }
        props.truncate(count as usize);
        Some(
            props
                .iter()
                .filter_map(|p| CString::new(ffi::read_fixed(&p.extension_name)).ok())
                .collect(),
        )
    }
}
