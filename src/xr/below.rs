//! What lies below fovea: the instance extensions the layers and the runtime under it offer, learned
//! without depending on which layers are stacked.
//!
//! The loader's way is `xrGetInstanceProcAddr(XR_NULL_HANDLE, "xrEnumerateInstanceExtensionProperties")`
//! through the next layer
//! (https://registry.khronos.org/OpenXR/specs/1.0/html/xrspec.html#xrGetInstanceProcAddr). Some
//! layers refuse every lookup without an instance (the conformance suite's own layer does), and a
//! list of names to step past cannot keep up with every layer users stack. Where that lookup is
//! refused, fovea asks through an instance instead, where the lookup is legal for every layer: it
//! creates one instance below with the application's create info and no extensions (which every
//! conformant runtime accepts), asks it, and destroys it before the application's instance is
//! created. That is done for each instance the application creates (the layers enabled may differ
//! from one to the next), and the log says so once per process. Where even that fails, fovea cannot know and provides every
//! extension the application enabled itself, and says so once.

use std::ffi::CString;
use std::sync::atomic::{AtomicBool, Ordering};

use openxr_sys as xr;
use xr::Handle;

use crate::xr::ffi;
use crate::xr::next_layer;

/// The once-per-process line about how the list was learned was written.
static SAID: AtomicBool = AtomicBool::new(false);

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
        match probe(next_gipa, next_create, app, layer_info) {
            Some(list) => {
                if !SAID.swap(true, Ordering::Relaxed) {
                    tracing::info!(
                        target: fovea_abi::log_target::BELOW,
                        "a layer below fovea refuses lookups without an instance; fovea learns what \
                         the runtime offers through an instance of its own (said once for this process)"
                    );
                }
                list
            }
            None => {
                if !SAID.swap(true, Ordering::Relaxed) {
                    tracing::warn!(
                        target: fovea_abi::log_target::BELOW,
                        "fovea cannot learn which extensions the runtime offers (the layers below \
                         refuse to list them, with and without an instance); it provides every \
                         extension of its own the application enables (said once for this process)"
                    );
                }
                Vec::new()
            }
        }
    }
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

/// Creates an instance below with the application's create info and no extensions, asks it for the
/// extensions below, and destroys it.
///
/// # Safety
/// As [`extensions_below`].
unsafe fn probe(
    next_gipa: xr::pfn::GetInstanceProcAddr,
    next_create: xr::pfn::CreateApiLayerInstance,
    app: &xr::InstanceCreateInfo,
    layer_info: &xr::ApiLayerCreateInfo,
) -> Option<Vec<CString>> {
    // SAFETY: the caller upholds this function's `# Safety` contract; the comments inside say
    // what each step relies on.
    unsafe {
        let mut info = *app;
        info.enabled_extension_count = 0;
        info.enabled_extension_names = std::ptr::null();
        // The next layer reads the loader's list from the entry after fovea's, as for the real instance.
        let mut down = *layer_info;
        // SAFETY: `next_info` is fovea's own entry, validated non-NULL by the caller.
        down.next_info = (*layer_info.next_info).next;
        let mut instance = xr::Instance::NULL;
        // SAFETY: copies of the application's create info (its chain is read-only to layers) and of the
        // loader's layer info, pointing past fovea.
        let r = next_create(&info, &down, &mut instance);
        if r.into_raw() < 0 || instance == xr::Instance::NULL {
            tracing::debug!(?r, "no instance below to ask for its extensions");
            return None;
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
        list
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
