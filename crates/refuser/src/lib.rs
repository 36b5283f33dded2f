//! A test OpenXR API layer that stands between fovea and the runtime the way real layers do when
//! they do not help a layer above learn what lies below.
//!
//! One library, two layers, chosen by the name the loader negotiates it under (the manifest's
//! `name`, or `LayerSpec::name` in the harness):
//!
//! - [`REFUSE_NULL_LOOKUPS`]: every `xrGetInstanceProcAddr(XR_NULL_HANDLE, ...)` is answered with
//!   XR_ERROR_HANDLE_INVALID and a NULL function, `xrEnumerateInstanceExtensionProperties` included,
//!   as the CTS conformance layer (`XR_APILAYER_KHRONOS_runtime_conformance`) does. The spec's
//!   table says a NULL instance must yield the three global functions
//!   (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#xrGetInstanceProcAddr), but a
//!   layer has no next `xrGetInstanceProcAddr` to forward them to before its
//!   `xrCreateApiLayerInstance` runs, so layers in the wild refuse them.
//! - [`HIDE_EXTENSIONS`]: NULL-instance `xrEnumerateInstanceExtensionProperties` answers with an empty
//!   list (the extensions below are hidden), `xrEnumerateApiLayerProperties` names this layer, and
//!   every other NULL-instance name is XR_ERROR_HANDLE_INVALID.
//!
//! Both pass everything else through untouched: `xrCreateApiLayerInstance` advances the chain as
//! the loader interface requires
//! (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#api-layer-create-instance-process),
//! and a lookup on a live instance returns the next `xrGetInstanceProcAddr`'s pointer unchanged, so
//! the layer adds no code to any call made on the instance except `xrDestroyInstance` (to forget
//! the instance) and `xrGetInstanceProcAddr` itself.
//!
//! `fovea_refuser_stats` (exported, C ABI) tells a test what the layer saw: a test opens the same
//! library path again (the dynamic loader returns the already loaded copy) and reads it.
//!
//! `LayerSpec` is the harness's (crates/harness): `LayerSpec::refuse_null_lookups()` and
//! `LayerSpec::hide_extensions()`; `write_layer_manifest` writes a manifest for the Khronos loader.

use std::ffi::{c_char, CStr};
use std::panic::catch_unwind;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

use openxr_sys as xr;
use openxr_sys::Handle;

/// The layer that refuses every NULL-instance lookup.
pub const REFUSE_NULL_LOOKUPS: &str = "XR_APILAYER_FOVEA_test_refuse_null_lookups";
/// The layer that reports no instance extensions below it.
pub const HIDE_EXTENSIONS: &str = "XR_APILAYER_FOVEA_test_hide_extensions";

/// Loader interface version 1 is the only one that exists.
const INTERFACE_VERSION: u32 = 1;
/// The API version the layer reports (it passes through whatever the runtime implements).
const API_VERSION: xr::Version = xr::Version::new(1, 0, 0);

/// What the layer saw in this process, for tests (`fovea_refuser_stats`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RefuserStats {
    /// `xrGetInstanceProcAddr` calls with XR_NULL_HANDLE.
    pub null_lookups: u64,
    /// Of those, answered with an error and a NULL function.
    pub null_lookups_refused: u64,
    /// Calls of the hiding layer's own `xrEnumerateInstanceExtensionProperties`.
    pub hidden_enumerations: u64,
    /// Lookups on a live instance, forwarded to the next `xrGetInstanceProcAddr`.
    pub forwarded_lookups: u64,
    /// Successful `xrCreateApiLayerInstance` calls.
    pub instances_created: u64,
    /// `xrDestroyInstance` calls passed down.
    pub instances_destroyed: u64,
}

static NULL_LOOKUPS: AtomicU64 = AtomicU64::new(0);
static NULL_LOOKUPS_REFUSED: AtomicU64 = AtomicU64::new(0);
static HIDDEN_ENUMERATIONS: AtomicU64 = AtomicU64::new(0);
static FORWARDED_LOOKUPS: AtomicU64 = AtomicU64::new(0);
static INSTANCES_CREATED: AtomicU64 = AtomicU64::new(0);
static INSTANCES_DESTROYED: AtomicU64 = AtomicU64::new(0);

/// Each live instance's next `xrGetInstanceProcAddr` (several instances may live at once in the
/// harness, where tests run in parallel).
static INSTANCES: Mutex<Vec<(u64, xr::pfn::GetInstanceProcAddr)>> = Mutex::new(Vec::new());

fn count(counter: &AtomicU64) {
    counter.fetch_add(1, Ordering::Relaxed);
}

fn next_gipa(instance: xr::Instance) -> Option<xr::pfn::GetInstanceProcAddr> {
    let list = INSTANCES.lock().unwrap_or_else(|e| e.into_inner());
    list.iter()
        .find(|(i, _)| *i == instance.into_raw())
        .map(|(_, g)| *g)
}

/// Copies the layer's counters to `out` (ignored when NULL).
///
/// # Safety
/// `out` must be NULL or point to a writable `RefuserStats`.
#[no_mangle]
pub unsafe extern "C" fn fovea_refuser_stats(out: *mut RefuserStats) {
    if out.is_null() {
        return;
    }
    let load = |c: &AtomicU64| c.load(Ordering::Relaxed);
    out.write(RefuserStats {
        null_lookups: load(&NULL_LOOKUPS),
        null_lookups_refused: load(&NULL_LOOKUPS_REFUSED),
        hidden_enumerations: load(&HIDDEN_ENUMERATIONS),
        forwarded_lookups: load(&FORWARDED_LOOKUPS),
        instances_created: load(&INSTANCES_CREATED),
        instances_destroyed: load(&INSTANCES_DESTROYED),
    });
}

/// Which of the two layers a negotiation named.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Mode {
    Refuse,
    Hide,
}

/// The loader's entry point (spec "API Layer Interface Negotiation"): malformed structs or no
/// overlapping version are XR_ERROR_INITIALIZATION_FAILED; otherwise the entry points of the layer
/// `layer_name` names (the refusing one for any other name).
///
/// # Safety
/// The pointers must be NULL or point to the loader's structs and a NUL-terminated name.
#[no_mangle]
pub unsafe extern "system" fn xrNegotiateLoaderApiLayerInterface(
    loader_info: *const xr::NegotiateLoaderInfo,
    layer_name: *const c_char,
    request: *mut xr::NegotiateApiLayerRequest,
) -> xr::Result {
    catch_unwind(|| negotiate(loader_info, layer_name, request))
        .unwrap_or(xr::Result::ERROR_INITIALIZATION_FAILED)
}

unsafe fn negotiate(
    loader_info: *const xr::NegotiateLoaderInfo,
    layer_name: *const c_char,
    request: *mut xr::NegotiateApiLayerRequest,
) -> xr::Result {
    if loader_info.is_null() || request.is_null() {
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    }
    let info = &*loader_info;
    let req = &mut *request;
    let info_ok = info.struct_type == xr::NegotiateLoaderInfo::TYPE
        && info.struct_version == xr::NegotiateLoaderInfo::VERSION
        && info.struct_size == std::mem::size_of::<xr::NegotiateLoaderInfo>();
    let request_ok = req.struct_type == xr::NegotiateApiLayerRequest::TYPE
        && req.struct_version == xr::NegotiateApiLayerRequest::VERSION
        && req.struct_size == std::mem::size_of::<xr::NegotiateApiLayerRequest>();
    if !info_ok || !request_ok {
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    }
    if !(info.min_interface_version..=info.max_interface_version).contains(&INTERFACE_VERSION) {
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    }
    let mm = |v: xr::Version| (v.major(), v.minor());
    if !(mm(info.min_api_version)..=mm(info.max_api_version)).contains(&mm(API_VERSION)) {
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    }
    let mode = if !layer_name.is_null()
        && CStr::from_ptr(layer_name).to_bytes() == HIDE_EXTENSIONS.as_bytes()
    {
        Mode::Hide
    } else {
        Mode::Refuse
    };
    req.layer_interface_version = INTERFACE_VERSION;
    req.layer_api_version = API_VERSION;
    req.get_instance_proc_addr = Some(match mode {
        Mode::Refuse => refuse_gipa,
        Mode::Hide => hide_gipa,
    });
    req.create_api_layer_instance = Some(create_api_layer_instance);
    xr::Result::SUCCESS
}

/// `xrCreateApiLayerInstance`: copy the create info, step to the next layer, call down, and
/// remember the next `xrGetInstanceProcAddr` for the instance that came back.
unsafe extern "system" fn create_api_layer_instance(
    info: *const xr::InstanceCreateInfo,
    layer_info: *const xr::ApiLayerCreateInfo,
    instance: *mut xr::Instance,
) -> xr::Result {
    catch_unwind(|| {
        if layer_info.is_null() || instance.is_null() {
            return xr::Result::ERROR_INITIALIZATION_FAILED;
        }
        let next_info = (*layer_info).next_info;
        if next_info.is_null() {
            return xr::Result::ERROR_INITIALIZATION_FAILED;
        }
        let (Some(gipa), Some(create)) = (
            (*next_info).next_get_instance_proc_addr,
            (*next_info).next_create_api_layer_instance,
        ) else {
            return xr::Result::ERROR_INITIALIZATION_FAILED;
        };
        let mut copy = std::ptr::read(layer_info);
        copy.next_info = (*next_info).next;
        let r = create(info, &copy, instance);
        if r.into_raw() >= 0 {
            count(&INSTANCES_CREATED);
            INSTANCES
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .push(((*instance).into_raw(), gipa));
        }
        r
    })
    .unwrap_or(xr::Result::ERROR_RUNTIME_FAILURE)
}

/// `xrDestroyInstance`: passes down, then forgets the instance.
unsafe extern "system" fn destroy_instance(instance: xr::Instance) -> xr::Result {
    catch_unwind(|| {
        let Some(gipa) = next_gipa(instance) else {
            return xr::Result::ERROR_HANDLE_INVALID;
        };
        let mut f = None;
        let r = gipa(instance, c"xrDestroyInstance".as_ptr(), &mut f);
        let Some(f) = f.filter(|_| r == xr::Result::SUCCESS) else {
            return xr::Result::ERROR_RUNTIME_FAILURE;
        };
        let destroy: xr::pfn::DestroyInstance = std::mem::transmute(f);
        let r = destroy(instance);
        if r == xr::Result::SUCCESS {
            count(&INSTANCES_DESTROYED);
            INSTANCES
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .retain(|(i, _)| *i != instance.into_raw());
        }
        r
    })
    .unwrap_or(xr::Result::ERROR_RUNTIME_FAILURE)
}

/// A live instance's lookup: the layer's own two functions, everything else from below unchanged.
unsafe fn instance_lookup(
    own_gipa: xr::pfn::GetInstanceProcAddr,
    instance: xr::Instance,
    name: &CStr,
    function: *mut Option<xr::pfn::VoidFunction>,
) -> xr::Result {
    let Some(next) = next_gipa(instance) else {
        *function = None;
        return xr::Result::ERROR_HANDLE_INVALID;
    };
    let own: Option<xr::pfn::VoidFunction> = match name.to_bytes() {
        b"xrGetInstanceProcAddr" => Some(std::mem::transmute::<
            xr::pfn::GetInstanceProcAddr,
            xr::pfn::VoidFunction,
        >(own_gipa)),
        b"xrDestroyInstance" => Some(std::mem::transmute::<
            xr::pfn::DestroyInstance,
            xr::pfn::VoidFunction,
        >(destroy_instance)),
        _ => None,
    };
    if let Some(f) = own {
        *function = Some(f);
        return xr::Result::SUCCESS;
    }
    count(&FORWARDED_LOOKUPS);
    next(instance, name.as_ptr(), function)
}

/// The common part of both layers' `xrGetInstanceProcAddr`.
unsafe fn gipa(
    mode: Mode,
    instance: xr::Instance,
    name: *const c_char,
    function: *mut Option<xr::pfn::VoidFunction>,
) -> xr::Result {
    if function.is_null() || name.is_null() {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    let name = CStr::from_ptr(name);
    if instance != xr::Instance::NULL {
        let own = match mode {
            Mode::Refuse => refuse_gipa as xr::pfn::GetInstanceProcAddr,
            Mode::Hide => hide_gipa,
        };
        return instance_lookup(own, instance, name, function);
    }
    count(&NULL_LOOKUPS);
    let answer: Option<xr::pfn::VoidFunction> = match (mode, name.to_bytes()) {
        (Mode::Hide, b"xrEnumerateInstanceExtensionProperties") => {
            Some(std::mem::transmute::<
                xr::pfn::EnumerateInstanceExtensionProperties,
                xr::pfn::VoidFunction,
            >(hidden_extensions))
        }
        (Mode::Hide, b"xrEnumerateApiLayerProperties") => Some(std::mem::transmute::<
            xr::pfn::EnumerateApiLayerProperties,
            xr::pfn::VoidFunction,
        >(own_layer_properties)),
        _ => None,
    };
    match answer {
        Some(f) => {
            *function = Some(f);
            xr::Result::SUCCESS
        }
        None => {
            count(&NULL_LOOKUPS_REFUSED);
            *function = None;
            xr::Result::ERROR_HANDLE_INVALID
        }
    }
}

/// [`REFUSE_NULL_LOOKUPS`]'s `xrGetInstanceProcAddr`.
unsafe extern "system" fn refuse_gipa(
    instance: xr::Instance,
    name: *const c_char,
    function: *mut Option<xr::pfn::VoidFunction>,
) -> xr::Result {
    catch_unwind(|| gipa(Mode::Refuse, instance, name, function))
        .unwrap_or(xr::Result::ERROR_RUNTIME_FAILURE)
}

/// [`HIDE_EXTENSIONS`]'s `xrGetInstanceProcAddr`.
unsafe extern "system" fn hide_gipa(
    instance: xr::Instance,
    name: *const c_char,
    function: *mut Option<xr::pfn::VoidFunction>,
) -> xr::Result {
    catch_unwind(|| gipa(Mode::Hide, instance, name, function))
        .unwrap_or(xr::Result::ERROR_RUNTIME_FAILURE)
}

/// The hiding layer's `xrEnumerateInstanceExtensionProperties`: no extensions, for a NULL layer
/// name (what lies below) and for its own name (it offers none); any other layer name is not this
/// layer (XR_ERROR_API_LAYER_NOT_PRESENT).
unsafe extern "system" fn hidden_extensions(
    layer_name: *const c_char,
    _capacity: u32,
    count_out: *mut u32,
    _properties: *mut xr::ExtensionProperties,
) -> xr::Result {
    catch_unwind(|| {
        count(&HIDDEN_ENUMERATIONS);
        if !layer_name.is_null()
            && CStr::from_ptr(layer_name).to_bytes() != HIDE_EXTENSIONS.as_bytes()
        {
            return xr::Result::ERROR_API_LAYER_NOT_PRESENT;
        }
        if count_out.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        *count_out = 0;
        xr::Result::SUCCESS
    })
    .unwrap_or(xr::Result::ERROR_RUNTIME_FAILURE)
}

/// The hiding layer's `xrEnumerateApiLayerProperties`: this layer only (api_layer.adoc: a layer
/// reports itself).
unsafe extern "system" fn own_layer_properties(
    capacity: u32,
    count_out: *mut u32,
    properties: *mut xr::ApiLayerProperties,
) -> xr::Result {
    catch_unwind(|| {
        if count_out.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        *count_out = 1;
        if capacity == 0 {
            return xr::Result::SUCCESS;
        }
        if properties.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        let p = &mut *properties;
        if p.ty != xr::StructureType::API_LAYER_PROPERTIES {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        p.layer_name = [0; xr::MAX_API_LAYER_NAME_SIZE];
        for (d, s) in p.layer_name.iter_mut().zip(HIDE_EXTENSIONS.bytes()) {
            *d = s as c_char;
        }
        p.spec_version = API_VERSION;
        p.layer_version = 1;
        p.description = [0; xr::MAX_API_LAYER_DESCRIPTION_SIZE];
        for (d, s) in p
            .description
            .iter_mut()
            .zip(b"fovea test: hides extensions")
        {
            *d = *s as c_char;
        }
        xr::Result::SUCCESS
    })
    .unwrap_or(xr::Result::ERROR_RUNTIME_FAILURE)
}
