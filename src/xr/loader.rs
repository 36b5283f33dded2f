//! The loader interface: negotiation, `xrCreateApiLayerInstance`, `xrGetInstanceProcAddr` and the
//! layer's own `xrEnumerateInstanceExtensionProperties`.
//!
//! Follows the normative "API Layer Interface Negotiation" of api_initialization.adoc and the
//! loader's api_layer.adoc (docs/openxr-layer.md#loader-negotiation).

use std::ffi::{c_char, CStr};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use openxr_sys as xr;
use xr::Handle;

use crate::common::settings;
use crate::xr::below;
use crate::xr::dispatch::{self, Owner};
use crate::xr::extensions::{self, Ext, Extensions, EXTENSIONS};
use crate::xr::ffi::{self, shim, HookResult, In, Out, OutArray};
use crate::xr::gaze;
use crate::xr::next_layer::{self, Next};
use crate::xr::registry::{registry, Instance, InstanceFovs};
use crate::xr::symmetric;
use fovea_abi::LAYER_NAME;

/// The once-per-process line that the runtime offers no eye gaze was written.
static GAZE_ABSENT_SAID: AtomicBool = AtomicBool::new(false);

/// The interface version fovea speaks (the only one that exists).
const INTERFACE_VERSION: u32 = 1;

/// The API versions fovea supports: every 1.x. The Debian loader (1.0.20) offers 1.0.0 to 1.1023.4095
/// and only logs what the layer answers (docs/openxr-layer.md#loader-negotiation).
const MIN_API: xr::Version = xr::Version::new(1, 0, 0);
const MAX_API: xr::Version = xr::Version::new(1, 1023, 4095);

shim! {
    /// `xrNegotiateLoaderApiLayerInterface`: the only symbol the loader looks up
    /// (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#api-layer-interface-negotiation).
    #[no_mangle]
    pub fn xrNegotiateLoaderApiLayerInterface = c"xrNegotiateLoaderApiLayerInterface" => negotiate,
    (
        loader_info: in xr::NegotiateLoaderInfo,
        layer_name: (string) c_char,
        request: out xr::NegotiateApiLayerRequest,
    )
}

fn negotiate(
    info: In<xr::NegotiateLoaderInfo>,
    layer_name: Option<&CStr>,
    request: Out<xr::NegotiateApiLayerRequest>,
) -> HookResult<xr::Result> {
    crate::common::log::init();
    let failed = |why: &str| {
        tracing::error!(why, "negotiation refused");
        xr::Result::ERROR_INITIALIZATION_FAILED
    };
    let (Some(info), Some(req)) = (info.get_untyped(), request.into_mut()) else {
        return Ok(failed("NULL loader info or request"));
    };
    if info.struct_type != xr::NegotiateLoaderInfo::TYPE
        || info.struct_version != xr::NegotiateLoaderInfo::VERSION
        || info.struct_size != std::mem::size_of::<xr::NegotiateLoaderInfo>()
    {
        return Ok(failed(
            "XrNegotiateLoaderInfo has the wrong type, version or size",
        ));
    }
    if req.struct_type != xr::NegotiateApiLayerRequest::TYPE
        || req.struct_version != xr::NegotiateApiLayerRequest::VERSION
        || req.struct_size != std::mem::size_of::<xr::NegotiateApiLayerRequest>()
    {
        return Ok(failed(
            "XrNegotiateApiLayerRequest has the wrong type, version or size",
        ));
    }
    if !(info.min_interface_version..=info.max_interface_version).contains(&INTERFACE_VERSION) {
        return Ok(failed("no common loader interface version"));
    }
    // "Ignoring patch": compare major.minor only.
    let mm = |v: xr::Version| (v.major(), v.minor());
    if mm(info.max_api_version) < mm(MIN_API) || mm(info.min_api_version) > mm(MAX_API) {
        return Ok(failed("no common API version"));
    }
    if let Some(name) = layer_name {
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
    Ok(xr::Result::SUCCESS)
}

shim! {
    /// The layer's `xrCreateApiLayerInstance`
    /// (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#api-layer-create-instance-process).
    pub fn create_api_layer_instance = c"xrCreateApiLayerInstance" => create_instance,
    (
        info: in xr::InstanceCreateInfo,
        layer_info: in xr::ApiLayerCreateInfo,
        instance: out xr::Instance,
    )
}

fn create_instance(
    info: In<xr::InstanceCreateInfo>,
    layer_info: In<xr::ApiLayerCreateInfo>,
    instance: Out<xr::Instance>,
) -> HookResult<xr::Result> {
    Ok(create_instance_inner(info, layer_info, instance))
}

fn create_instance_inner(
    info: In<xr::InstanceCreateInfo>,
    layer_info: In<xr::ApiLayerCreateInfo>,
    instance: Out<xr::Instance>,
) -> xr::Result {
    crate::common::log::init();
    let (Some(app), false) = (info.get(), instance.is_null()) else {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    };
    let Some(li) = layer_info.get_untyped() else {
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    };
    if li.struct_type != xr::ApiLayerCreateInfo::TYPE
        || li.struct_version != xr::ApiLayerCreateInfo::VERSION
        || li.struct_size != std::mem::size_of::<xr::ApiLayerCreateInfo>()
        || li.next_info.is_null()
    {
        tracing::error!("XrApiLayerCreateInfo is malformed");
        return xr::Result::ERROR_INITIALIZATION_FAILED;
    }
    // SAFETY: checked non-NULL above; the loader's XrApiLayerCreateInfo points to its list of
    // next-layer entries, valid through the call
    // (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#api-layer-create-instance-process).
    let next_info = unsafe { &*li.next_info };
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

    if app.enabled_extension_count > 0 && app.enabled_extension_names.is_null() {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    let names: Vec<&CStr> = (0..app.enabled_extension_count as usize)
        // SAFETY: a valid XrInstanceCreateInfo (`In`) has `enabledExtensionCount` names, each NULL
        // or NUL-terminated
        // (https://registry.khronos.org/OpenXR/specs/1.0/man/html/XrInstanceCreateInfo.html).
        .map(|i| unsafe { ffi::cstr(*app.enabled_extension_names.add(i)) })
        .collect::<Option<_>>()
        .unwrap_or_default();
    if names.len() != app.enabled_extension_count as usize {
        return xr::Result::ERROR_VALIDATION_FAILURE;
    }
    // SAFETY: the next-info entry is fovea's own, validated above; its pointers are the loader's,
    // and `app`/`li` are the validated arguments of this call.
    let below = unsafe { below::extensions_below(next_gipa, next_info, next_create, app, li) };
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
    let id = identity(&app.application_info);
    let settings = settings::Settings::from_env(id.clone());
    crate::common::log::configure(settings.log.as_deref(), settings.log_file.as_deref());
    let epic = symmetric::enable_epic(settings.symmetric_fov, &names, &below, &mut kept);
    let gaze_settings = settings.gaze;
    let app_gaze = gaze::listed(names.iter().copied());
    // Gaze only where something of fovea's uses it (docs/eye-tracking.md#who-uses-the-gaze): an
    // application that enables nothing that follows the eyes gets no extension enabled below, no
    // action set and no input call from fovea.
    // `inject` on for this application; not the injection an FB application gets for the
    // profiles it applies (docs/injection.md#applications-that-apply-profiles): those profiles
    // are fixed, nothing of theirs follows the eyes.
    let injects = matches!(settings.injection(), settings::Injection::On(_));
    let gaze_used =
        gaze_settings.on && gaze::used(exts.provided(Ext::MetaFoveationEyeTracked), injects);
    let gaze_below = gaze_used && (app_gaze || gaze::listed(&below));
    if gaze_below && !app_gaze {
        kept.push(gaze::name_ptr());
    } else if gaze_used && !gaze_below && !GAZE_ABSENT_SAID.swap(true, Ordering::Relaxed) {
        tracing::info!(
            target: fovea_abi::log_target::GAZE,
            "the runtime does not offer XR_EXT_eye_gaze_interaction: fixed foveation (said once \
             for this process)"
        );
    }
    let mut down = *app;
    down.enabled_extension_count = kept.len() as u32;
    down.enabled_extension_names = if kept.is_empty() {
        std::ptr::null()
    } else {
        kept.as_ptr()
    };
    // Before the runtime below exists and starts threads: see the function's reasoning.
    crate::xr::hooks::vulkan_layer::request_for_process(exts.vulkan_enable || exts.vulkan_enable2);
    let mut next_layer_info = *li;
    next_layer_info.next_info = next_info.next;
    // SAFETY: the next layer's xrCreateApiLayerInstance, with copies of the application's and the
    // loader's structs whose pointers outlive the call, and the application's output pointer.
    let result = unsafe { next_create(&down, &next_layer_info, instance.raw()) };
    if result.into_raw() < 0 {
        return result;
    }
    let Some(handle) = instance.read() else {
        return result;
    };
    let gaze = gaze_below.then(|| {
        // SAFETY: the next layer's xrGetInstanceProcAddr and the instance it just created.
        unsafe { gaze::InstanceGaze::new(next_gipa, handle, gaze_settings, app_gaze) }
    });
    let gaze = match gaze {
        Some(Err(why)) => {
            tracing::warn!(target: fovea_abi::log_target::GAZE, why, "no eye gaze: fixed foveation");
            None
        }
        Some(Ok(g)) => Some(g),
        None => None,
    };
    let state = Instance {
        gaze,
        gaze_on: gaze_used,
        handle,
        next_gipa,
        // SAFETY: the next layer's xrGetInstanceProcAddr and the instance it just created.
        next: unsafe { Next::load(next_gipa, handle) },
        extensions: exts,
        symmetric_fov: settings.symmetric_fov,
        overrides: settings::Overrides::from_env(settings.config.clone(), id.clone()),
        stereo_fovs: Default::default(),
        fovs: InstanceFovs::new(epic),
        vulkan: Default::default(),
        lost: Default::default(),
        inject: injection(&settings, exts),
        subsampled: settings.subsampled,
        eye_tracked_y_up: settings.eye_tracked_y_up,
    };
    let provided: Vec<Ext> = exts.enabled.iter().filter(|e| exts.provided(*e)).collect();
    let native: Vec<Ext> = exts.native.iter().collect();
    // SAFETY: the next layer's xrGetInstanceProcAddr and the instance it just created.
    let runtime = unsafe { runtime_name(next_gipa, handle) };
    let config = settings
        .config
        .as_deref()
        .map_or("none".into(), |p| p.display().to_string());
    let opt = |s: &Option<String>| s.clone().unwrap_or_default();
    // The instance header: one line per run in the log file whatever the filter.
    crate::common::log::header(&format!(
        "fovea {} instance: app={:?} exe={:?} engine={:?} runtime={runtime:?} provided={provided:?} \
         native={native:?} symmetric_fov={} config={config:?} pid={}",
        fovea_abi::VERSION,
        opt(&id.app),
        opt(&id.exe),
        opt(&id.engine),
        settings.symmetric_fov,
        std::process::id(),
    ));
    tracing::info!(
        target: fovea_abi::log_target::INSTANCE,
        app = opt(&id.app),
        engine = opt(&id.engine),
        runtime,
        ?provided,
        ?native,
        "instance created"
    );
    registry()
        .instances
        .write()
        .insert(handle.into_raw(), Arc::new(state));
    result
}

/// Who is running, as the configuration file's sections are matched: the application and engine
/// names from `XrApplicationInfo`, and the executable's file name.
fn identity(info: &xr::ApplicationInfo) -> fovea_config::Identity {
    let name = |s: String| (!s.is_empty()).then_some(s);
    fovea_config::Identity {
        app: name(ffi::read_fixed(&info.application_name)),
        exe: fovea_config::Identity::current_exe(),
        engine: name(ffi::read_fixed(&info.engine_name)),
    }
}

/// The runtime's name and version from `xrGetInstanceProperties` through the next layer, for the
/// instance header; `unknown` when the call fails.
///
/// # Safety
/// `gipa` must be the next layer's `xrGetInstanceProcAddr` and `instance` its live instance.
unsafe fn runtime_name(gipa: xr::pfn::GetInstanceProcAddr, instance: xr::Instance) -> String {
    // SAFETY: the caller's contract.
    let Some(f) = (unsafe { next_layer::load(gipa, instance, c"xrGetInstanceProperties") }) else {
        return "unknown".into();
    };
    let f: xr::pfn::GetInstanceProperties =
        // SAFETY: the next layer answered for xrGetInstanceProperties, so the pointer has the
        // signature the spec gives that name, which is openxr-sys's.
        unsafe { std::mem::transmute::<xr::pfn::VoidFunction, xr::pfn::GetInstanceProperties>(f) };
    let mut props = xr::InstanceProperties {
        ty: xr::InstanceProperties::TYPE,
        next: std::ptr::null_mut(),
        runtime_version: xr::Version::new(0, 0, 0),
        runtime_name: [0; xr::MAX_RUNTIME_NAME_SIZE],
    };
    // SAFETY: a live instance and a properly typed output struct with a NULL `next`.
    if unsafe { f(instance, &mut props) }.into_raw() < 0 {
        return "unknown".into();
    }
    let v = props.runtime_version;
    format!(
        "{} {}.{}.{}",
        ffi::read_fixed(&props.runtime_name),
        v.major(),
        v.minor(),
        v.patch()
    )
}

shim! {
    /// The layer's `xrGetInstanceProcAddr`, following the spec's table
    /// (https://registry.khronos.org/OpenXR/specs/1.0/man/html/xrGetInstanceProcAddr.html): never
    /// `XR_SUCCESS` with a NULL pointer, which modern loaders treat as a broken layer.
    pub fn get_instance_proc_addr = c"xrGetInstanceProcAddr" => instance_proc_addr,
    (
        instance: val xr::Instance,
        name: (string) c_char,
        function: (required_out) Option<xr::pfn::VoidFunction>,
    )
}

fn instance_proc_addr(
    instance: xr::Instance,
    name: Option<&CStr>,
    function: &mut Option<xr::pfn::VoidFunction>,
) -> HookResult<xr::Result> {
    *function = None;
    let Some(name) = name else {
        return Ok(xr::Result::ERROR_VALIDATION_FAILURE);
    };
    let r = resolve(instance, name, function);
    if r == xr::Result::SUCCESS && function.is_none() {
        // Cannot happen by construction; the rule matters enough to hold it here too.
        return Ok(xr::Result::ERROR_FUNCTION_UNSUPPORTED);
    }
    Ok(r)
}

/// A function pointer of any signature as the `PFN_xrVoidFunction` `xrGetInstanceProcAddr` hands
/// out; the caller casts it back to the signature the name implies.
macro_rules! void_fn {
    ($pfn:ident, $f:expr) => {
        // SAFETY: function pointers of any signature have the same representation; `as` checks
        // `$f` against openxr-sys's type for the name it is handed out under.
        Some(unsafe {
            std::mem::transmute::<xr::pfn::$pfn, xr::pfn::VoidFunction>($f as xr::pfn::$pfn)
        })
    };
}

fn resolve(
    instance: xr::Instance,
    name: &CStr,
    out: &mut Option<xr::pfn::VoidFunction>,
) -> xr::Result {
    if name == c"xrGetInstanceProcAddr" {
        *out = void_fn!(GetInstanceProcAddr, get_instance_proc_addr);
        return xr::Result::SUCCESS;
    }
    if instance == xr::Instance::NULL {
        // Without an instance there is no next layer to ask: fovea answers the three functions the
        // table requires, and nothing else.
        return if name == c"xrEnumerateInstanceExtensionProperties" {
            *out = void_fn!(
                EnumerateInstanceExtensionProperties,
                enumerate_instance_extension_properties
            );
            xr::Result::SUCCESS
        } else if name == c"xrEnumerateApiLayerProperties" {
            *out = void_fn!(EnumerateApiLayerProperties, enumerate_api_layer_properties);
            xr::Result::SUCCESS
        } else if name == c"xrCreateInstance" {
            *out = void_fn!(CreateInstance, create_instance_direct);
            xr::Result::SUCCESS
        } else {
            xr::Result::ERROR_HANDLE_INVALID
        };
    }
    let Some(state) = registry().instance(instance) else {
        return xr::Result::ERROR_HANDLE_INVALID;
    };
    if name == c"xrEnumerateInstanceExtensionProperties" {
        *out = void_fn!(
            EnumerateInstanceExtensionProperties,
            enumerate_instance_extension_properties
        );
        return xr::Result::SUCCESS;
    }
    let exts = &state.extensions;
    let ours = match dispatch::hook(name) {
        None => false,
        Some(h) => match h.owner {
            Owner::Below => (h.offered_below)(&state.next),
            Owner::Gaze => state.gaze.is_some() && (h.offered_below)(&state.next),
            Owner::Layer(ext) if exts.provided(ext) => true,
            // The runtime has XR_FB_swapchain_update_state but not XR_FB_foveation: fovea handles the
            // foveation state type and passes every other one down.
            Owner::Layer(Ext::SwapchainUpdateState) if exts.provided(Ext::Foveation) => {
                (h.offered_below)(&state.next)
            }
            Owner::Layer(ext) if exts.enabled.contains(ext) => false,
            Owner::Layer(_) => return xr::Result::ERROR_FUNCTION_UNSUPPORTED,
        },
    };
    if let (true, Some(h)) = (ours, dispatch::hook(name)) {
        *out = Some(h.function);
        return xr::Result::SUCCESS;
    }
    // SAFETY: the next layer's xrGetInstanceProcAddr with its own instance, a NUL-terminated name
    // and a writable output.
    let r = unsafe { (state.next_gipa)(instance, name.as_ptr(), out) };
    if r == xr::Result::SUCCESS && out.is_none() {
        tracing::warn!(
            ?name,
            "the next layer answered XR_SUCCESS with a NULL pointer"
        );
        return xr::Result::ERROR_FUNCTION_UNSUPPORTED;
    }
    r
}

shim! {
    /// Layers are created through `xrCreateApiLayerInstance`; the spec's table still wants a
    /// pointer for `xrCreateInstance` with a NULL instance, so this one explains instead of
    /// crashing.
    fn create_instance_direct = c"xrCreateInstance" => refuse_create_instance,
    (info: in xr::InstanceCreateInfo, instance: out xr::Instance)
}

fn refuse_create_instance(
    _info: In<xr::InstanceCreateInfo>,
    _instance: Out<xr::Instance>,
) -> HookResult<xr::Result> {
    tracing::error!(
        "xrCreateInstance called on the layer directly; layers are created by the loader"
    );
    Ok(xr::Result::ERROR_INITIALIZATION_FAILED)
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

shim! {
    /// `xrEnumerateInstanceExtensionProperties` as a layer answers it
    /// (https://registry.khronos.org/OpenXR/specs/1.0/man/html/xrEnumerateInstanceExtensionProperties.html):
    /// with its own name, its own extensions; with NULL, its own too, since a layer above may
    /// resolve this function through fovea instead of the loader; with another name,
    /// XR_ERROR_API_LAYER_NOT_PRESENT.
    fn enumerate_instance_extension_properties =
        c"xrEnumerateInstanceExtensionProperties" => instance_extension_properties,
    (
        layer_name: (string) c_char,
        capacity: val u32,
        count_out: out u32,
        properties: (array capacity) xr::ExtensionProperties,
    )
}

fn instance_extension_properties(
    layer_name: Option<&CStr>,
    capacity: u32,
    count_out: Out<u32>,
    properties: OutArray<xr::ExtensionProperties>,
) -> HookResult<xr::Result> {
    if let Some(n) = layer_name {
        if n.to_bytes() != LAYER_NAME.as_bytes() {
            return Ok(xr::Result::ERROR_API_LAYER_NOT_PRESENT);
        }
    }
    let own = own_extensions();
    for i in 0..(capacity as usize).min(own.len()) {
        if properties
            .read(i)
            .is_some_and(|p| p.ty != xr::StructureType::EXTENSION_PROPERTIES)
        {
            return Ok(xr::Result::ERROR_VALIDATION_FAILURE);
        }
    }
    Ok(ffi::two_call(&own, count_out, properties))
}

shim! {
    /// `xrEnumerateApiLayerProperties` as a layer answers it: the layer itself.
    fn enumerate_api_layer_properties =
        c"xrEnumerateApiLayerProperties" => api_layer_properties,
    (
        capacity: val u32,
        count_out: out u32,
        properties: (array capacity) xr::ApiLayerProperties,
    )
}

fn api_layer_properties(
    capacity: u32,
    count_out: Out<u32>,
    properties: OutArray<xr::ApiLayerProperties>,
) -> HookResult<xr::Result> {
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
        && properties
            .read(0)
            .is_some_and(|p| p.ty != xr::StructureType::API_LAYER_PROPERTIES)
    {
        return Ok(xr::Result::ERROR_VALIDATION_FAILURE);
    }
    Ok(ffi::two_call(&[p], count_out, properties))
}

/// Whether injection applies to a new instance (docs/injection.md#switching-it-on), and at which
/// level for swapchains the application applies no profile to; if so, publishes it for the Vulkan
/// side before the application creates its `VkDevice`.
///
/// With `inject` on, every application. With it off, a Vulkan application that enabled
/// `XR_FB_foveation` where fovea provides it, at level `none`: the device must get the shading-rate
/// attachment feature at `vkCreateDevice`, before the application can apply a profile to a
/// swapchain without density images (Qt 6.8's Quick 3D XR does, docs/openxr-layer.md#swapchains-without-foveation-info),
/// and until it does, its passes get maps of rate 1×1 everywhere. Whether the application
/// foveates a swapchain itself is told per swapchain, by its density images.
fn injection(
    settings: &settings::Settings,
    exts: Extensions,
) -> Option<fovea_model::density::Level> {
    let asks = exts.enabled.contains(Ext::Foveation)
        && exts.provided(Ext::Foveation)
        && (exts.vulkan_enable || exts.vulkan_enable2);
    let every_app = matches!(settings.injection(), settings::Injection::On(_));
    let level = match settings.injection() {
        settings::Injection::On(level) => {
            tracing::info!(
                level = level.name(),
                "injecting shading rates into eye passes"
            );
            level
        }
        settings::Injection::Off if asks => {
            tracing::info!(
                "the application enabled XR_FB_foveation: swapchains it applies a profile to \
                 without density images are foveated by injecting shading rates into their eye \
                 passes"
            );
            fovea_model::density::Level::None
        }
        settings::Injection::Off => return None,
    };
    crate::bridge::inject::start(level, every_app);
    Some(level)
}
