/*
 * fovea.h: for C and C++ code that works with the fovea OpenXR API layer (libfovea.so).
 *
 * Applications need no header to use fovea: they enable the layer (XR_ENABLE_API_LAYERS, an
 * implicit manifest, or XrInstanceCreateInfo::enabledApiLayerNames) and its extensions through
 * the OpenXR headers. This header names the layer (and the Vulkan layer in the same library), the
 * environment variables they read and the extensions the OpenXR layer provides, and declares its
 * negotiation symbol, for code that configures, checks or loads the layer itself.
 *
 * It needs no OpenXR headers. When <openxr/openxr_loader_negotiation.h> is available it is
 * included and the declaration uses its types; define FOVEA_NO_OPENXR_HEADERS to keep it out.
 *
 * tests/c_header.rs compiles it as C99 and C++ and checks it against the layer's sources.
 */
#ifndef FOVEA_H_
#define FOVEA_H_ 1

/* The layer's name, as in its manifests, XR_ENABLE_API_LAYERS and enabledApiLayerNames. */
#define FOVEA_LAYER_NAME "XR_APILAYER_FOVEA_foveation"

/*
 * The Vulkan layer in the same library (docs/vulkan-layer.md): VK_EXT_fragment_density_map on
 * devices with VK_KHR_fragment_shading_rate attachments. Its name, as in its manifests,
 * VK_INSTANCE_LAYERS and ppEnabledLayerNames.
 */
#define FOVEA_VK_LAYER_NAME "VK_LAYER_FOVEA_fragment_density_map"

/*
 * Environment variables fovea reads (docs/settings.md). FOVEA_DISABLE is read by the OpenXR
 * loader: it is the implicit manifest's disable_environment.
 */
#define FOVEA_ENV_LOG "FOVEA_LOG"                   /* a tracing filter, e.g. "info"; default "warn" */
#define FOVEA_ENV_LOG_FILE "FOVEA_LOG_FILE"         /* a path: also append every log line there */
#define FOVEA_ENV_DISABLE "FOVEA_DISABLE"           /* set (any value): the loader skips implicit fovea */
#define FOVEA_ENV_SYMMETRIC_FOV "FOVEA_SYMMETRIC_FOV" /* 0/1: one shared symmetric FOV for both eyes */
#define FOVEA_ENV_INJECT_PANIC "FOVEA_INJECT_PANIC" /* testing aid: that hook panics */
#define FOVEA_ENV_PROPS "FOVEA_PROPS"               /* a file of debug.oculus.foveation.*=value lines, re-read live */
/* Read by the Vulkan loader for the implicit Vulkan layer manifest `fovea install` writes. */
#define FOVEA_ENV_VK_LAYER "FOVEA_VK_LAYER" /* 1: load the Vulkan layer (fovea sets it for XR Vulkan apps) */
#define FOVEA_ENV_DISABLE_FOVEA_VK_LAYER "DISABLE_FOVEA_VK_LAYER" /* set: never load it */
#define FOVEA_ENV_CONFIG "FOVEA_CONFIG"             /* the fovea.toml to read instead of $XDG_CONFIG_HOME's; "" none */
#define FOVEA_ENV_MAX_FRAGMENT "FOVEA_MAX_FRAGMENT" /* 1, 2 or 4: the largest fragment a map asks for */
#define FOVEA_ENV_INJECT "FOVEA_INJECT"             /* 0/1: foveate apps that never ask (shading rates in eye passes) */
#define FOVEA_ENV_INJECT_LEVEL "FOVEA_INJECT_LEVEL" /* 0-4 or a level name: the level injection uses */
#define FOVEA_ENV_SUBSAMPLED "FOVEA_SUBSAMPLED"     /* 0/1: reconstruct coarse blocks as subsampled images look */
/* The gaze source (docs/eye-tracking.md#settings); each also a fovea.toml key in lower case without FOVEA_. */
#define FOVEA_ENV_GAZE "FOVEA_GAZE"                 /* 0/1: follow the eyes where the runtime has eye gaze (default 1) */
#define FOVEA_ENV_GAZE_MIN_CUTOFF_HZ "FOVEA_GAZE_MIN_CUTOFF_HZ" /* the one-euro filter's cutoff at rest, Hz */
#define FOVEA_ENV_GAZE_BETA "FOVEA_GAZE_BETA"       /* how fast the cutoff rises with the gaze's speed */
#define FOVEA_ENV_GAZE_D_CUTOFF_HZ "FOVEA_GAZE_D_CUTOFF_HZ" /* the cutoff of the speed estimate, Hz */
#define FOVEA_ENV_GAZE_SACCADE_DEG "FOVEA_GAZE_SACCADE_DEG" /* a jump of this many degrees resets the filter */
#define FOVEA_ENV_GAZE_HOLD_S "FOVEA_GAZE_HOLD_S"   /* seconds the last good gaze is held */
#define FOVEA_ENV_GAZE_RETURN_S "FOVEA_GAZE_RETURN_S" /* seconds of easing back to fixed foveation */
#define FOVEA_ENV_GAZE_FIXATION_M "FOVEA_GAZE_FIXATION_M" /* metres to the plane the gaze ray meets */
#define FOVEA_ENV_GAZE_ATTACH_AFTER_S "FOVEA_GAZE_ATTACH_AFTER_S" /* seconds, or "never": attach alone for apps that never attach */
/* XR_META_foveation_eye_tracked. */
#define FOVEA_ENV_EYE_TRACKED_Y_UP "FOVEA_EYE_TRACKED_Y_UP" /* 0/1: the eye-tracked centres with y up (default y down) */
/* Where fovea.toml (XDG_CONFIG_HOME/fovea) and the log (XDG_STATE_HOME/fovea) are by default. */
#define FOVEA_ENV_XDG_CONFIG_HOME "XDG_CONFIG_HOME"
#define FOVEA_ENV_XDG_STATE_HOME "XDG_STATE_HOME"
/* Quest's debug.oculus.foveation.* properties: level 0-4, dynamic 0/1, subsampled 0/1. */
#define FOVEA_ENV_DEBUG_OCULUS_FOVEATION_LEVEL "DEBUG_OCULUS_FOVEATION_LEVEL"
#define FOVEA_ENV_DEBUG_OCULUS_FOVEATION_DYNAMIC "DEBUG_OCULUS_FOVEATION_DYNAMIC"
#define FOVEA_ENV_DEBUG_OCULUS_FOVEATION_SUBSAMPLED "DEBUG_OCULUS_FOVEATION_SUBSAMPLED"

/* All of them, for X-macros: X(name). */
#define FOVEA_ENV_VARS(X)                        \
    X(FOVEA_ENV_LOG)                             \
    X(FOVEA_ENV_LOG_FILE)                        \
    X(FOVEA_ENV_DISABLE)                         \
    X(FOVEA_ENV_SYMMETRIC_FOV)                   \
    X(FOVEA_ENV_INJECT_PANIC)                    \
    X(FOVEA_ENV_PROPS)                           \
    X(FOVEA_ENV_VK_LAYER)                        \
    X(FOVEA_ENV_DISABLE_FOVEA_VK_LAYER)          \
    X(FOVEA_ENV_CONFIG)                          \
    X(FOVEA_ENV_MAX_FRAGMENT)                    \
    X(FOVEA_ENV_INJECT)                          \
    X(FOVEA_ENV_INJECT_LEVEL)                    \
    X(FOVEA_ENV_SUBSAMPLED)                      \
    X(FOVEA_ENV_GAZE)                            \
    X(FOVEA_ENV_GAZE_MIN_CUTOFF_HZ)              \
    X(FOVEA_ENV_GAZE_BETA)                       \
    X(FOVEA_ENV_GAZE_D_CUTOFF_HZ)                \
    X(FOVEA_ENV_GAZE_SACCADE_DEG)                \
    X(FOVEA_ENV_GAZE_HOLD_S)                     \
    X(FOVEA_ENV_GAZE_RETURN_S)                   \
    X(FOVEA_ENV_GAZE_FIXATION_M)                 \
    X(FOVEA_ENV_GAZE_ATTACH_AFTER_S)             \
    X(FOVEA_ENV_EYE_TRACKED_Y_UP)                \
    X(FOVEA_ENV_XDG_CONFIG_HOME)                 \
    X(FOVEA_ENV_XDG_STATE_HOME)                  \
    X(FOVEA_ENV_DEBUG_OCULUS_FOVEATION_LEVEL)    \
    X(FOVEA_ENV_DEBUG_OCULUS_FOVEATION_DYNAMIC)  \
    X(FOVEA_ENV_DEBUG_OCULUS_FOVEATION_SUBSAMPLED)

/*
 * The instance extensions fovea provides, at the versions it reports, in registry order. Prefixed,
 * so they never clash with openxr.h's XR_*_SPEC_VERSION and XR_*_EXTENSION_NAME.
 */
#define FOVEA_EXTENSION_COUNT 6
#define FOVEA_EXT_FB_SWAPCHAIN_UPDATE_STATE_NAME "XR_FB_swapchain_update_state"
#define FOVEA_EXT_FB_SWAPCHAIN_UPDATE_STATE_VERSION 3
#define FOVEA_EXT_FB_FOVEATION_NAME "XR_FB_foveation"
#define FOVEA_EXT_FB_FOVEATION_VERSION 1
#define FOVEA_EXT_FB_FOVEATION_CONFIGURATION_NAME "XR_FB_foveation_configuration"
#define FOVEA_EXT_FB_FOVEATION_CONFIGURATION_VERSION 1
#define FOVEA_EXT_FB_FOVEATION_VULKAN_NAME "XR_FB_foveation_vulkan"
#define FOVEA_EXT_FB_FOVEATION_VULKAN_VERSION 1
#define FOVEA_EXT_META_FOVEATION_EYE_TRACKED_NAME "XR_META_foveation_eye_tracked"
#define FOVEA_EXT_META_FOVEATION_EYE_TRACKED_VERSION 1
#define FOVEA_EXT_META_VULKAN_SWAPCHAIN_CREATE_INFO_NAME "XR_META_vulkan_swapchain_create_info"
#define FOVEA_EXT_META_VULKAN_SWAPCHAIN_CREATE_INFO_VERSION 1

/* All of them, for X-macros: X(name, version). */
#define FOVEA_EXTENSIONS(X)                                                                    \
    X(FOVEA_EXT_FB_SWAPCHAIN_UPDATE_STATE_NAME, FOVEA_EXT_FB_SWAPCHAIN_UPDATE_STATE_VERSION)   \
    X(FOVEA_EXT_FB_FOVEATION_NAME, FOVEA_EXT_FB_FOVEATION_VERSION)                             \
    X(FOVEA_EXT_FB_FOVEATION_CONFIGURATION_NAME, FOVEA_EXT_FB_FOVEATION_CONFIGURATION_VERSION) \
    X(FOVEA_EXT_FB_FOVEATION_VULKAN_NAME, FOVEA_EXT_FB_FOVEATION_VULKAN_VERSION)               \
    X(FOVEA_EXT_META_FOVEATION_EYE_TRACKED_NAME, FOVEA_EXT_META_FOVEATION_EYE_TRACKED_VERSION) \
    X(FOVEA_EXT_META_VULKAN_SWAPCHAIN_CREATE_INFO_NAME,                                        \
      FOVEA_EXT_META_VULKAN_SWAPCHAIN_CREATE_INFO_VERSION)

/* The loader negotiation types: the OpenXR SDK's when it is there (1.0.33 and later). */
#if !defined(FOVEA_NO_OPENXR_HEADERS) && !defined(XR_LOADER_VERSION_1_0) && defined(__has_include)
#if __has_include(<openxr/openxr_loader_negotiation.h>)
#include <openxr/openxr_loader_negotiation.h>
#endif
#endif

#if defined(XR_LOADER_VERSION_1_0)
#define FOVEA_XRAPI_ATTR XRAPI_ATTR
#define FOVEA_XRAPI_CALL XRAPI_CALL
#else
#include <stdint.h>
#define FOVEA_XRAPI_ATTR
#if defined(_WIN32)
#define FOVEA_XRAPI_CALL __stdcall
#else
#define FOVEA_XRAPI_CALL
#endif
#endif

#ifdef __cplusplus
extern "C" {
#endif

#if defined(XR_LOADER_VERSION_1_0)
typedef XrResult fovea_xr_result;
#else
/* XrResult: 0 is XR_SUCCESS, negative values are errors. */
typedef int32_t fovea_xr_result;
/* Complete in <openxr/openxr_loader_negotiation.h>; the same struct tags, so the two mix. */
struct XrNegotiateLoaderInfo;
struct XrNegotiateApiLayerRequest;
#endif

/*
 * The only symbol libfovea.so exports, which the OpenXR loader calls first (OpenXR spec, "API Layer
 * Interface Negotiation"). Code that dlopen()s the library looks it up by this name.
 */
FOVEA_XRAPI_ATTR fovea_xr_result FOVEA_XRAPI_CALL xrNegotiateLoaderApiLayerInterface(
    const struct XrNegotiateLoaderInfo *loaderInfo, const char *layerName,
    struct XrNegotiateApiLayerRequest *apiLayerRequest);

/* Its type, for the pointer dlsym() returns. */
typedef fovea_xr_result (FOVEA_XRAPI_CALL *fovea_pfn_negotiate)(
    const struct XrNegotiateLoaderInfo *loaderInfo, const char *layerName,
    struct XrNegotiateApiLayerRequest *apiLayerRequest);

#ifdef __cplusplus
}
#endif

#endif /* FOVEA_H_ */
