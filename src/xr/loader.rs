//! The loader interface: negotiation, `xrCreateApiLayerInstance`, `xrGetInstanceProcAddr` and the
//! layer's own `xrEnumerateInstanceExtensionProperties`.
//!
//! Follows the normative "API Layer Interface Negotiation" of api_initialization.adoc and the
//! loader's api_layer.adoc (openxr-layer-facts.md §2).

use std::ffi::{c_char, CStr};
use std::sync::Arc;

use openxr_sys as xr;
use xr::Handle;

use crate::common::ffi::{self, guard};
use crate::common::settings;
use crate::xr::below;
use crate::xr::dispatch::{self, Next, Owner};
use crate::xr::extensions::{self, Ext, Extensions, EXTENSIONS};
use crate::xr::registry::{registry, Instance};
use crate::xr::symmetric;
use fovea_abi::LAYER_NAME;

/// The interface version fovea speaks (the only one that exists).
const INTERFACE_VERSION: u32 = 1;

/// The API versions fovea supports: every 1.x. The Debian loader (1.0.20) offers 1.0.0 to 1.1023.4095
/// and only logs what the layer answers (openxr-layer-facts.md §2.2).
const MIN_API: xr::Version = xr::Version::new(1, 0, 0);
const MAX_API: xr::Version = xr::Version::new(1, 0x3ff, 0xfff);

/// `xrNegotiateLoaderApiLayerInterface`: the only symbol the loader looks up.
///
/// # Safety
/// Called by the loader with pointers it owns; every one is checked before use.
#[no_mangle]
pub unsafe extern "system" fn xrNegotiateLoaderApiLayerInterface(
    loader_info: *const xr::NegotiateLoaderInfo,
    layer_name: *const c_char,
    request: *mut xr::NegotiateApiLayerRequest,
) -> xr::Result {
    guard("xrNegotiateLoaderApiLayerInterface", || {
        negotiate(loader_info, layer_name, request)
    })
}

unsafe fn negotiate(
    info: *const xr::NegotiateLoaderInfo,
    layer_name: *const c_char,
    request: *mut xr::NegotiateApiLayerRequest,
) -> xr::Result {
    crate::common::log::init();
    let failed = |why: &str| {
        tracing::error!(why, "negotiation refused");
        xr::Result::ERROR_INITIALIZATION_FAILED
    };
    if info.is_null() || request.is_null() {
        return failed("NULL loader info or request");
    }
    let info = &*info;
    if info.struct_type != xr::NegotiateLoaderInfo::TYPE
        || info.struct_version != xr::NegotiateLoaderInfo::VERSION
        || info.struct_size != std::mem::size_of::<xr::NegotiateLoaderInfo>()
    {
        return failed("XrNegotiateLoaderInfo has the wrong type, version or size");
    }
    let req = &mut *request;
    if req.struct_type != xr::NegotiateApiLayerRequest::TYPE
        || req.struct_version != xr::NegotiateApiLayerRequest::VERSION
        || req.struct_size != std::mem::size_of::<xr::NegotiateApiLayerRequest>()
    {
        return failed("XrNegotiateApiLayerRequest has the wrong type, version or size");
    }
    if !(info.min_interface_version..=info.max_interface_version).contains(&INTERFACE_VERSION) {
        return failed("no common loader interface version");
    }
    // "Ignoring patch": compare major.minor only.
    let mm = |v: xr::Version| (v.major(), v.minor());
    if mm(info.max_api_version) < mm(MIN_API) || mm(info.min_api_version) > mm(MAX_API) {
        return failed("no common API version");
    }
    if let Some(name) = ffi::cstr(layer_name) {
        if name.to_bytes() != LAYER_NAME.as_bytes() {
            tracing::warn!(
                ?name,
                "loaded under another layer name; answering as {LAYER_NAME}"
            );
        }
    }
    req.layer_interface_version = INTERFACE_VERSION;
    req.layer_api_version = if mm(info.max_api_version) >= (1, 1) {
        xr::Version::new(1, 1, 0)
    } else {
        MIN_API
    };
    req.get_instance_proc_addr = Some(get_instance_proc_addr);
    req.create_api_layer_instance = Some(create_api_layer_instance);
    xr::Result::SUCCESS
}

/// The layer's `xrCreateApiLayerInstance` (api_initialization.adoc; openxr-layer-facts.md §2.3, §3).
///
/// # Safety
/// Called by the loader or the layer above with its own pointers; every one is checked.
pub unsafe extern "system" fn create_api_layer_instance(
    info: *const xr::InstanceCreateInfo,
    layer_info: *const xr::ApiLayerCreateInfo,
    instance: *mut xr::Instance,
) -> xr::Result {
    guard("xrCreateApiLayerInstance", || {
        create_instance(info, layer_info, instance)
    })
}

unsafe fn create_instance(
    info: *const xr::InstanceCreateInfo,
    layer_info: *const xr::ApiLayerCreateInfo,
    instance: *mut xr::Instance,
) -> xr::Result {
    crate::common::log::init();
    if info.is_null() || instance.is_null() || (*info).ty != xr::StructureType::INSTANCE_CREATE_INFO
    {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    if layer_info.is_null() {
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    }
    let li = &*layer_info;
    if li.struct_type != xr::ApiLayerCreateInfo::TYPE
        || li.struct_version != xr::ApiLayerCreateInfo::VERSION
        || li.struct_size != std::mem::size_of::<xr::ApiLayerCreateInfo>()
        || li.next_info.is_null()
    {
        tracing::error!("XrApiLayerCreateInfo is malformed");
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    }
    let next_info = &*li.next_info;
    if next_info.struct_type != xr::ApiLayerNextInfo::TYPE
        || next_info.struct_version != xr::ApiLayerNextInfo::VERSION
        || next_info.struct_size != std::mem::size_of::<xr::ApiLayerNextInfo>()
    {
        tracing::error!("XrApiLayerNextInfo is malformed");
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    }
    let next_name = ffi::read_fixed(&next_info.layer_name);
    if next_name != LAYER_NAME {
        tracing::error!(
            next_name,
            "the loader's next-info entry belongs to another layer"
        );
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    }
    let (Some(next_gipa), Some(next_create)) = (
        next_info.next_get_instance_proc_addr,
        next_info.next_create_api_layer_instance,
    ) else {
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    };

    let app = &*info;
    if app.enabled_extension_count > 0 && app.enabled_extension_names.is_null() {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    let names: Vec<&CStr> = (0..app.enabled_extension_count as usize)
        .map(|i| *app.enabled_extension_names.add(i))
        .map(|p| ffi::cstr(p))
        .collect::<Option<_>>()
        .unwrap_or_default();
    if names.len() != app.enabled_extension_count as usize {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    let below = below::extensions_below(next_gipa, next_info, next_create, app, li);
    let mut exts = Extensions::default();
    for n in &names {
        if let Some(e) = Ext::by_name(n) {
            exts.enabled.insert(e);
            if below.iter().any(|b| b.as_c_str() == *n) {
                exts.native.insert(e);
            }
        }
    }
    exts.vulkan_enable = names.contains(&c"XR_KHR_vulkan_enable");
    exts.vulkan_enable2 = names.contains(&c"XR_KHR_vulkan_enable2");
    let api_version = app.application_info.api_version;
    // XR_ERROR_EXTENSION_DEPENDENCY_NOT_ENABLED is a 1.1 result; 1.0 apps never see it.
    if (api_version.major(), api_version.minor()) >= (1, 1) {
        if let Some(m) = extensions::missing_dependency(exts.enabled, |n| names.contains(&n)) {
            tracing::warn!(extension = ?m.ext.info().name, needs = m.needs, "extension dependency not enabled");
            return xr::Result::ERROR_EXTENSION_DEPENDENCY_NOT_ENABLED;
        }
    }

    // Down goes a copy of the create info without the extensions fovea provides itself (and, in
    // symmetric-FOV mode, with the one that reports the FOVs where the runtime offers it).
    let mut kept: Vec<*const c_char> = names
        .iter()
        .filter(|n| Ext::by_name(n).is_none_or(|e| !exts.provided(e)))
        .map(|n| n.as_ptr())
        .collect();
    let settings = settings::Settings::from_env();
    let epic = symmetric::enable_epic(settings.symmetric_fov, &names, &below, &mut kept);
    let mut down = *app;
    down.enabled_extension_count = kept.len() as u32;
    down.enabled_extension_names = if kept.is_empty() {
        std::ptr::null()
    } else {
        kept.as_ptr()
    };
    let mut next_layer_info = *li;
    next_layer_info.next_info = next_info.next;
    let result = next_create(&down, &next_layer_info, instance);
    if result.into_raw() < 0 {
        return result;
    }

    let handle = *instance;
    let state = Instance {
        handle,
        next_gipa,
        next: Next::load(next_gipa, handle),
        extensions: exts,
        symmetric_fov: settings.symmetric_fov,
        overrides: settings::Overrides::from_env(),
        stereo_fovs: crate::common::lock::Mutex::new(None),
        fovs: symmetric::InstanceFovs::new(epic),
        vulkan: Default::default(),
        lost: Default::default(),
    };
    tracing::info!(
        provided = ?exts.enabled.iter().filter(|e| exts.provided(*e)).collect::<Vec<_>>(),
        native = ?exts.native.iter().collect::<Vec<_>>(),
        "instance created"
    );
    registry()
        .instances
        .write()
        .insert(handle.into_raw(), Arc::new(state));
    result
}

/// The layer's `xrGetInstanceProcAddr`, following the spec's table (api_initialization.adoc):
/// never `XR_SUCCESS` with a NULL pointer, which modern loaders treat as a broken layer.
///
/// # Safety
/// `name` NUL-terminated or NULL; `function` writable or NULL.
pub unsafe extern "system" fn get_instance_proc_addr(
    instance: xr::Instance,
    name: *const c_char,
    function: *mut Option<xr::pfn::VoidFunction>,
) -> xr::Result {
    guard("xrGetInstanceProcAddr", || {
        if function.is_null() {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        *function = None;
        let Some(name) = dispatch::name(name) else {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        };
        resolve(instance, name, &mut *function)
    })
}

unsafe fn resolve(
    instance: xr::Instance,
    name: &CStr,
    out: &mut Option<xr::pfn::VoidFunction>,
) -> xr::Result {
    if name == c"xrGetInstanceProcAddr" {
        *out = Some(std::mem::transmute::<
            xr::pfn::GetInstanceProcAddr,
            xr::pfn::VoidFunction,
        >(get_instance_proc_addr));
        return xr::Result::SUCCESS;
    }
    if instance == xr::Instance::NULL {
        // Without an instance there is no next layer to ask: fovea answers the three functions the
        // table requires, and nothing else.
        return if name == c"xrEnumerateInstanceExtensionProperties" {
            *out = Some(std::mem::transmute::<
                xr::pfn::EnumerateInstanceExtensionProperties,
                xr::pfn::VoidFunction,
            >(enumerate_instance_extension_properties));
            xr::Result::SUCCESS
        } else if name == c"xrEnumerateApiLayerProperties" {
            *out = Some(std::mem::transmute::<
                xr::pfn::EnumerateApiLayerProperties,
                xr::pfn::VoidFunction,
            >(enumerate_api_layer_properties));
            xr::Result::SUCCESS
        } else if name == c"xrCreateInstance" {
            *out = Some(std::mem::transmute::<
                xr::pfn::CreateInstance,
                xr::pfn::VoidFunction,
            >(create_instance_direct));
            xr::Result::SUCCESS
        } else {
            xr::Result::ERROR_HANDLE_INVALID
        };
    }
    let Some(state) = registry().instance(instance) else {
        return xr::Result::ERROR_HANDLE_INVALID;
    };
    if name == c"xrEnumerateInstanceExtensionProperties" {
        *out = Some(std::mem::transmute::<
            xr::pfn::EnumerateInstanceExtensionProperties,
            xr::pfn::VoidFunction,
        >(enumerate_instance_extension_properties));
        return xr::Result::SUCCESS;
    }
    let exts = &state.extensions;
    let ours = match dispatch::hook(name) {
        None => false,
        Some(h) => match h.owner {
            Owner::Below => (h.offered_below)(&state.next),
            Owner::Layer(ext) if exts.provided(ext) => true,
            // The runtime has XR_FB_swapchain_update_state but not XR_FB_foveation: fovea handles the
            // foveation state type and passes every other one down.
            Owner::Layer(Ext::SwapchainUpdateState) if exts.provided(Ext::Foveation) => {
                (dispatch::hook(name).unwrap().offered_below)(&state.next)
            }
            Owner::Layer(ext) if exts.enabled.contains(ext) => false,
            Owner::Layer(_) => return xr::Result::ERROR_FUNCTION_UNSUPPORTED,
        },
    };
    if ours {
        *out = Some(dispatch::hook(name).unwrap().function);
        return xr::Result::SUCCESS;
    }
    let r = (state.next_gipa)(instance, name.as_ptr(), out);
    if r == xr::Result::SUCCESS && out.is_none() {
        tracing::warn!(
            ?name,
            "the next layer answered XR_SUCCESS with a NULL pointer"
        );
        return xr::Result::ERROR_FUNCTION_UNSUPPORTED;
    }
    r
}

/// Layers are created through `xrCreateApiLayerInstance`; the spec's table still wants a pointer for
/// `xrCreateInstance` with a NULL instance, so this one explains instead of crashing.
unsafe extern "system" fn create_instance_direct(
    _info: *const xr::InstanceCreateInfo,
    _instance: *mut xr::Instance,
) -> xr::Result {
    tracing::error!(
        "xrCreateInstance called on the layer directly; layers are created by the loader"
    );
    xr::Result::ERROR_INITIALIZATION_FAILED
}

/// The layer's own extension list, as `XrExtensionProperties`.
fn own_extensions() -> Vec<xr::ExtensionProperties> {
    EXTENSIONS
        .iter()
        .map(|e| {
            let mut p = xr::ExtensionProperties {
                ty: xr::StructureType::EXTENSION_PROPERTIES,
                next: std::ptr::null_mut(),
                extension_name: [0; xr::MAX_EXTENSION_NAME_SIZE],
                extension_version: e.version,
            };
            ffi::write_fixed(&mut p.extension_name, e.name.to_str().unwrap_or_default());
            p
        })
        .collect()
}

/// `xrEnumerateInstanceExtensionProperties` as a layer answers it (api_layer.adoc): with its own name,
/// its own extensions; with NULL, its own too, since a layer above may resolve this function through
/// fovea instead of the loader (prior-art.md, OpenXR-Layer-Template 71c35a1); with another name,
/// XR_ERROR_API_LAYER_NOT_PRESENT.
unsafe extern "system" fn enumerate_instance_extension_properties(
    layer_name: *const c_char,
    capacity: u32,
    count_out: *mut u32,
    properties: *mut xr::ExtensionProperties,
) -> xr::Result {
    guard("xrEnumerateInstanceExtensionProperties", || {
        if let Some(n) = ffi::cstr(layer_name) {
            if n.to_bytes() != LAYER_NAME.as_bytes() {
                return xr::Result::ERROR_API_LAYER_NOT_PRESENT;
            }
        }
        let own = own_extensions();
        if capacity > 0 && !properties.is_null() {
            for i in 0..(capacity as usize).min(own.len()) {
                if (*properties.add(i)).ty != xr::StructureType::EXTENSION_PROPERTIES {
                    return xr::Result::ERROR_VALIDATION_FAILURE;
                }
            }
        }
        ffi::two_call(&own, capacity, count_out, properties)
    })
}

/// `xrEnumerateApiLayerProperties` as a layer answers it: the layer itself.
unsafe extern "system" fn enumerate_api_layer_properties(
    capacity: u32,
    count_out: *mut u32,
    properties: *mut xr::ApiLayerProperties,
) -> xr::Result {
    guard("xrEnumerateApiLayerProperties", || {
        let mut p = xr::ApiLayerProperties {
            ty: xr::StructureType::API_LAYER_PROPERTIES,
            next: std::ptr::null_mut(),
            layer_name: [0; xr::MAX_API_LAYER_NAME_SIZE],
            spec_version: xr::Version::new(1, 0, 0),
            layer_version: 1,
            description: [0; xr::MAX_API_LAYER_DESCRIPTION_SIZE],
        };
        ffi::write_fixed(&mut p.layer_name, LAYER_NAME);
        ffi::write_fixed(
            &mut p.description,
            "fovea: fixed foveated rendering (XR_FB_foveation) for Vulkan",
        );
        if capacity > 0
            && !properties.is_null()
            && (*properties).ty != xr::StructureType::API_LAYER_PROPERTIES
        {
            return xr::Result::ERROR_VALIDATION_FAILURE;
        }
        ffi::two_call(&[p], capacity, count_out, properties)
    })
}
