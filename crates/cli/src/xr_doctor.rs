//! `fovea doctor`'s eye gaze line: whether the active runtime offers `XR_EXT_eye_gaze_interaction`
//! and whether its head-mounted system has an eye tracker (`supportsEyeGazeInteraction`), which is
//! what fovea's gaze source needs (docs/eye-tracking.md#where-gaze-comes-from).
//!
//! The runtime is asked directly, as the loader would (its library from the active runtime manifest,
//! `xrNegotiateLoaderRuntimeInterface`), so no layer (fovea's included) stands in between. Asking
//! whether the system has a tracker needs an instance of the runtime's: one is created with the
//! extension enabled and destroyed at once. Whether the gaze is then active depends on the session
//! (focus, the user's permission), which only a running application shows: fovea's stats line says
//! it (`Gaze=`).

use std::ffi::{c_char, CStr};
use std::path::Path;

use openxr_sys as xr;
use xr::Handle;

const EXTENSION: &CStr = c"XR_EXT_eye_gaze_interaction";

/// What the runtime said about eye gaze.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum EyeGaze {
    /// The runtime does not list the extension.
    NotOffered,
    /// It lists it, and its system has an eye tracker (`true`) or reports none (`false`).
    Offered(bool),
    /// It lists it, but the system could not be asked (no headset connected, or a refused call).
    OfferedUnknown(String),
}

impl EyeGaze {
    /// The doctor's line.
    pub fn describe(&self) -> String {
        match self {
            EyeGaze::NotOffered => "eye gaze: the runtime does not offer XR_EXT_eye_gaze_interaction: \
                 fixed foveation"
                .into(),
            EyeGaze::Offered(true) => "eye gaze: the runtime offers XR_EXT_eye_gaze_interaction and \
                 the system has an eye tracker: the fovea follows the eyes while the runtime reports \
                 the gaze active (the stats line's Gaze= says so)"
                .into(),
            EyeGaze::Offered(false) => "eye gaze: the runtime offers XR_EXT_eye_gaze_interaction, but \
                 the system reports no eye tracker (supportsEyeGazeInteraction is false): fixed \
                 foveation"
                .into(),
            EyeGaze::OfferedUnknown(why) => format!(
                "eye gaze: the runtime offers XR_EXT_eye_gaze_interaction; whether the system has an \
                 eye tracker is unknown ({why})"
            ),
        }
    }
}

/// A function of the runtime's, by name.
///
/// # Safety
/// `gipa` must be a runtime's `xrGetInstanceProcAddr` and `instance` NULL or its live instance;
/// `F` the function type the name implies.
unsafe fn func<F: Copy>(
    gipa: xr::pfn::GetInstanceProcAddr,
    instance: xr::Instance,
    name: &CStr,
) -> Result<F, String> {
    let mut f = None;
    // SAFETY: the caller's contract; `f` is a live local.
    let r = unsafe { gipa(instance, name.as_ptr(), &mut f) };
    match f {
        // SAFETY: the runtime answered for `name`, whose type the caller names as `F`.
        Some(f) if r.into_raw() >= 0 => Ok(unsafe { std::mem::transmute_copy(&f) }),
        _ => Err(format!("the runtime has no {name:?} ({r:?})")),
    }
}

/// Asks the runtime in `library` (the active runtime manifest's) about eye gaze.
pub fn eye_gaze(library: &Path) -> Result<EyeGaze, String> {
    // SAFETY: loading the runtime runs its initialisers, as the loader's loading does.
    let lib = unsafe { libloading::Library::new(library) }
        .map_err(|e| format!("cannot load {}: {e}", library.display()))?;
    // SAFETY: the symbol's type is fixed by the loader interface.
    let negotiate = unsafe {
        lib.get::<xr::pfn::NegotiateLoaderRuntimeInterface>(b"xrNegotiateLoaderRuntimeInterface\0")
    }
    .map_err(|_| format!("{} is not an OpenXR runtime", library.display()))?;
    let info = fovea_harness::loader_info();
    let mut request = xr::NegotiateRuntimeRequest {
        struct_type: xr::NegotiateRuntimeRequest::TYPE,
        struct_version: xr::NegotiateRuntimeRequest::VERSION,
        struct_size: std::mem::size_of::<xr::NegotiateRuntimeRequest>(),
        runtime_interface_version: 0,
        runtime_api_version: xr::Version::new(0, 0, 0),
        get_instance_proc_addr: None,
    };
    // SAFETY: both structs are valid and live across the call.
    let r = unsafe { negotiate(&info, &mut request) };
    let Some(gipa) = request.get_instance_proc_addr.filter(|_| r.into_raw() >= 0) else {
        return Err(format!("the runtime refused to negotiate ({r:?})"));
    };
    // SAFETY: for every call below: the runtime's own functions with valid, live arguments.
    unsafe {
        let enumerate: xr::pfn::EnumerateInstanceExtensionProperties = func(
            gipa,
            xr::Instance::NULL,
            c"xrEnumerateInstanceExtensionProperties",
        )?;
        let mut n = 0;
        enumerate(std::ptr::null(), 0, &mut n, std::ptr::null_mut());
        let empty = xr::ExtensionProperties {
            ty: xr::StructureType::EXTENSION_PROPERTIES,
            next: std::ptr::null_mut(),
            extension_name: [0; xr::MAX_EXTENSION_NAME_SIZE],
            extension_version: 0,
        };
        let mut props = vec![empty; n as usize];
        let r = enumerate(std::ptr::null(), n, &mut n, props.as_mut_ptr());
        if r.into_raw() < 0 {
            return Err(format!(
                "the runtime refused to list its extensions ({r:?})"
            ));
        }
        let offered = props
            .iter()
            .take(n as usize)
            .any(|p| CStr::from_ptr(p.extension_name.as_ptr()) == EXTENSION);
        if !offered {
            return Ok(EyeGaze::NotOffered);
        }
        Ok(match system_supports(gipa) {
            Ok(s) => EyeGaze::Offered(s),
            Err(why) => EyeGaze::OfferedUnknown(why),
        })
    }
}

/// `supportsEyeGazeInteraction` of the runtime's head-mounted system, through an instance of
/// doctor's own.
///
/// # Safety
/// `gipa` must be a runtime's `xrGetInstanceProcAddr`.
unsafe fn system_supports(gipa: xr::pfn::GetInstanceProcAddr) -> Result<bool, String> {
    // SAFETY: for every call below: the runtime's own functions with valid, live arguments.
    unsafe {
        let create: xr::pfn::CreateInstance = func(gipa, xr::Instance::NULL, c"xrCreateInstance")?;
        let mut app = xr::ApplicationInfo {
            application_name: [0; xr::MAX_APPLICATION_NAME_SIZE],
            application_version: 0,
            engine_name: [0; xr::MAX_ENGINE_NAME_SIZE],
            engine_version: 0,
            api_version: xr::Version::new(1, 0, 0),
        };
        for (d, s) in app.application_name.iter_mut().zip(b"fovea doctor") {
            *d = *s as c_char;
        }
        let names = [EXTENSION.as_ptr()];
        let info = xr::InstanceCreateInfo {
            ty: xr::StructureType::INSTANCE_CREATE_INFO,
            next: std::ptr::null(),
            create_flags: xr::InstanceCreateFlags::EMPTY,
            application_info: app,
            enabled_api_layer_count: 0,
            enabled_api_layer_names: std::ptr::null(),
            enabled_extension_count: 1,
            enabled_extension_names: names.as_ptr(),
        };
        let mut instance = xr::Instance::NULL;
        let r = create(&info, &mut instance);
        if r.into_raw() < 0 {
            return Err(format!("xrCreateInstance: {r:?}"));
        }
        let answer = ask_system(gipa, instance);
        if let Ok(destroy) = func::<xr::pfn::DestroyInstance>(gipa, instance, c"xrDestroyInstance")
        {
            destroy(instance);
        }
        answer
    }
}

/// # Safety
/// `gipa` must be a runtime's `xrGetInstanceProcAddr` and `instance` its live instance with the
/// eye gaze extension enabled.
unsafe fn ask_system(
    gipa: xr::pfn::GetInstanceProcAddr,
    instance: xr::Instance,
) -> Result<bool, String> {
    // SAFETY: for every call below: the runtime's own functions with valid, live arguments.
    unsafe {
        let get_system: xr::pfn::GetSystem = func(gipa, instance, c"xrGetSystem")?;
        let get_props: xr::pfn::GetSystemProperties =
            func(gipa, instance, c"xrGetSystemProperties")?;
        let info = xr::SystemGetInfo {
            ty: xr::StructureType::SYSTEM_GET_INFO,
            next: std::ptr::null(),
            form_factor: xr::FormFactor::HEAD_MOUNTED_DISPLAY,
        };
        let mut system = xr::SystemId::NULL;
        let r = get_system(instance, &info, &mut system);
        if r.into_raw() < 0 {
            return Err(format!("no headset: xrGetSystem {r:?}"));
        }
        let mut eye = xr::SystemEyeGazeInteractionPropertiesEXT {
            ty: xr::StructureType::SYSTEM_EYE_GAZE_INTERACTION_PROPERTIES_EXT,
            next: std::ptr::null_mut(),
            supports_eye_gaze_interaction: xr::FALSE,
        };
        let mut props = xr::SystemProperties {
            ty: xr::StructureType::SYSTEM_PROPERTIES,
            next: &mut eye as *mut _ as *mut _,
            system_id: xr::SystemId::NULL,
            vendor_id: 0,
            system_name: [0; xr::MAX_SYSTEM_NAME_SIZE],
            graphics_properties: xr::SystemGraphicsProperties {
                max_swapchain_image_height: 0,
                max_swapchain_image_width: 0,
                max_layer_count: 0,
            },
            tracking_properties: xr::SystemTrackingProperties {
                orientation_tracking: xr::FALSE,
                position_tracking: xr::FALSE,
            },
        };
        let r = get_props(instance, system, &mut props);
        if r.into_raw() < 0 {
            return Err(format!("xrGetSystemProperties {r:?}"));
        }
        Ok(eye.supports_eye_gaze_interaction != xr::FALSE)
    }
}
