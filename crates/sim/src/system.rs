//! The one system: a head-mounted display with a primary stereo view configuration (spec chapters
//! "System", "View Configurations"). Sizes and FOVs come from the configured headset preset.

use openxr_sys as xr;

use crate::extensions::{
    EPIC_VIEW_CONFIGURATION_FOV, EXT_EYE_GAZE_INTERACTION, META_FOVEATION_EYE_TRACKED,
};
use crate::ffi;
use crate::state::{entry, world};

pub(crate) const SYSTEM_ID: u64 = 0x5157_0001;
const VENDOR_ID: u32 = 0xF0FE;
pub(crate) const MAX_IMAGE_SIZE: u32 = 8192;
pub(crate) const MAX_LAYER_COUNT: u32 = 16;
pub(crate) const VIEW_COUNT: usize = 2;

/// Validates an `XrSystemId` against the only system the runtime has.
pub(crate) fn check_system(system: xr::SystemId) -> Result<(), xr::Result> {
    if system.into_raw() == SYSTEM_ID {
        Ok(())
    } else {
        Err(xr::Result::ERROR_SYSTEM_INVALID)
    }
}

pub(crate) unsafe extern "system" fn get_system(
    instance: xr::Instance,
    get_info: *const xr::SystemGetInfo,
    system_id: *mut xr::SystemId,
) -> xr::Result {
    entry("xrGetSystem", |ctx| {
        let mut w = world();
        w.enter_instance(ctx, instance)?;
        let info = ffi::input(get_info, xr::StructureType::SYSTEM_GET_INFO)?;
        ffi::non_null(system_id)?;
        // The simulated system is a headset; any other form factor, a handheld display or a value
        // this runtime does not know (XR_FORM_FACTOR_MAX_ENUM in the CTS's xrGetSystem case), is
        // XR_ERROR_FORM_FACTOR_UNSUPPORTED, as the conformance suite requires.
        if info.form_factor != xr::FormFactor::HEAD_MOUNTED_DISPLAY {
            return Err(xr::Result::ERROR_FORM_FACTOR_UNSUPPORTED);
        }
        *system_id = xr::SystemId::from_raw(SYSTEM_ID);
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn get_system_properties(
    instance: xr::Instance,
    system_id: xr::SystemId,
    properties: *mut xr::SystemProperties,
) -> xr::Result {
    entry("xrGetSystemProperties", |ctx| {
        let mut w = world();
        let id = w.enter_instance(ctx, instance)?;
        check_system(system_id)?;
        let p = ffi::output(properties, xr::StructureType::SYSTEM_PROPERTIES)?;
        ctx.next_types = ffi::chain_types((*p).next);
        (*p).system_id = xr::SystemId::from_raw(SYSTEM_ID);
        (*p).vendor_id = VENDOR_ID;
        let name = format!("fovea simulated {}", w.instances[&id].config.headset.name);
        ffi::copy_str(&mut (*p).system_name, &name);
        (*p).graphics_properties = xr::SystemGraphicsProperties {
            max_swapchain_image_height: MAX_IMAGE_SIZE,
            max_swapchain_image_width: MAX_IMAGE_SIZE,
            max_layer_count: MAX_LAYER_COUNT,
        };
        (*p).tracking_properties = xr::SystemTrackingProperties {
            orientation_tracking: xr::TRUE,
            position_tracking: xr::TRUE,
        };
        let inst = &w.instances[&id];
        if inst.has_extension(EXT_EYE_GAZE_INTERACTION) {
            let ty = xr::StructureType::SYSTEM_EYE_GAZE_INTERACTION_PROPERTIES_EXT;
            if let Some(e) = ffi::find_in_chain((*p).next, ty) {
                let e = e as *mut xr::SystemEyeGazeInteractionPropertiesEXT;
                let supported = inst.config.eye_gaze.as_ref().is_some_and(|g| g.supported);
                (*e).supports_eye_gaze_interaction = supported.into();
            }
        }
        if inst.has_extension(META_FOVEATION_EYE_TRACKED) {
            let ty = xr::StructureType::SYSTEM_FOVEATION_EYE_TRACKED_PROPERTIES_META;
            if let Some(e) = ffi::find_in_chain((*p).next, ty) {
                let e = e as *mut xr::SystemFoveationEyeTrackedPropertiesMETA;
                (*e).supports_foveation_eye_tracked = xr::TRUE;
            }
        }
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) fn check_view_configuration(ty: xr::ViewConfigurationType) -> Result<(), xr::Result> {
    match ty {
        xr::ViewConfigurationType::PRIMARY_STEREO => Ok(()),
        _ => Err(xr::Result::ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED),
    }
}

pub(crate) unsafe extern "system" fn enumerate_environment_blend_modes(
    instance: xr::Instance,
    system_id: xr::SystemId,
    view_configuration_type: xr::ViewConfigurationType,
    capacity: u32,
    count_out: *mut u32,
    modes: *mut xr::EnvironmentBlendMode,
) -> xr::Result {
    entry("xrEnumerateEnvironmentBlendModes", |ctx| {
        let mut w = world();
        w.enter_instance(ctx, instance)?;
        check_system(system_id)?;
        check_view_configuration(view_configuration_type)?;
        ffi::two_call(capacity, count_out, modes, 1, |_, p| {
            *p = xr::EnvironmentBlendMode::OPAQUE;
            Ok(())
        })?;
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn enumerate_view_configurations(
    instance: xr::Instance,
    system_id: xr::SystemId,
    capacity: u32,
    count_out: *mut u32,
    types: *mut xr::ViewConfigurationType,
) -> xr::Result {
    entry("xrEnumerateViewConfigurations", |ctx| {
        let mut w = world();
        w.enter_instance(ctx, instance)?;
        check_system(system_id)?;
        ffi::two_call(capacity, count_out, types, 1, |_, p| {
            *p = xr::ViewConfigurationType::PRIMARY_STEREO;
            Ok(())
        })?;
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn get_view_configuration_properties(
    instance: xr::Instance,
    system_id: xr::SystemId,
    view_configuration_type: xr::ViewConfigurationType,
    properties: *mut xr::ViewConfigurationProperties,
) -> xr::Result {
    entry("xrGetViewConfigurationProperties", |ctx| {
        let mut w = world();
        w.enter_instance(ctx, instance)?;
        check_system(system_id)?;
        check_view_configuration(view_configuration_type)?;
        let p = ffi::output(properties, xr::StructureType::VIEW_CONFIGURATION_PROPERTIES)?;
        (*p).view_configuration_type = view_configuration_type;
        (*p).fov_mutable = xr::TRUE;
        Ok(xr::Result::SUCCESS)
    })
}

pub(crate) unsafe extern "system" fn enumerate_view_configuration_views(
    instance: xr::Instance,
    system_id: xr::SystemId,
    view_configuration_type: xr::ViewConfigurationType,
    capacity: u32,
    count_out: *mut u32,
    views: *mut xr::ViewConfigurationView,
) -> xr::Result {
    entry("xrEnumerateViewConfigurationViews", |ctx| {
        let mut w = world();
        let id = w.enter_instance(ctx, instance)?;
        check_system(system_id)?;
        check_view_configuration(view_configuration_type)?;
        let inst = &w.instances[&id];
        let [width, height] = inst.config.headset.recommended_size();
        let fovs = inst.config.headset.fovs();
        // A struct of an extension the instance did not enable is not recognised, and runtimes
        // ignore structs they do not recognise: it is left as it came.
        let epic = inst.has_extension(EPIC_VIEW_CONFIGURATION_FOV);
        ffi::two_call(capacity, count_out, views, VIEW_COUNT, |i, p| {
            let p = ffi::output(p, xr::StructureType::VIEW_CONFIGURATION_VIEW)?;
            if epic {
                fill_view_fov_epic((*p).next, fovs[i]);
            }
            (*p).recommended_image_rect_width = width;
            (*p).max_image_rect_width = MAX_IMAGE_SIZE;
            (*p).recommended_image_rect_height = height;
            (*p).max_image_rect_height = MAX_IMAGE_SIZE;
            (*p).recommended_swapchain_sample_count = 1;
            (*p).max_swapchain_sample_count = 4;
            Ok(())
        })?;
        Ok(xr::Result::SUCCESS)
    })
}

/// XR_EPIC_view_configuration_fov: the first `XrViewConfigurationViewFovEPIC` in a view's `next`
/// chain receives the eye's FOV as recommended and as the widest allowed (the simulated headset's
/// FOVs are fixed; https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#XrViewConfigurationViewFovEPIC).
///
/// # Safety
/// `next` must be NULL or a valid, writable chain.
unsafe fn fill_view_fov_epic(next: *mut std::ffi::c_void, fov: fovea_model::Fov) {
    let mut p = next as *mut xr::BaseOutStructure;
    let mut hops = 0;
    // A bound guards against cyclic chains from broken callers.
    while !p.is_null() && hops < 64 {
        if (*p).ty == xr::StructureType::VIEW_CONFIGURATION_VIEW_FOV_EPIC {
            let e = p.cast::<xr::ViewConfigurationViewFovEPIC>();
            let f = xr::Fovf {
                angle_left: fov.left,
                angle_right: fov.right,
                angle_up: fov.up,
                angle_down: fov.down,
            };
            (*e).recommended_fov = f;
            (*e).max_mutable_fov = f;
            return;
        }
        p = (*p).next;
        hops += 1;
    }
}
