//! crates/refuser's layer through the real Khronos loader (libopenxr_loader.so.1), found through a
//! manifest this test writes (`XR_API_LAYER_PATH`) and enabled by name, over libfovea_sim.so
//! (`XR_RUNTIME_JSON`) offering XR_FB_swapchain_update_state natively. One test, in a process
//! of its own, because it sets process-wide environment variables and the loader allows one instance.
//!
//! 1. The refusing layer alone: an instance, a headless session that begins, and located views pass
//!    through it to the runtime, and the loader never asks it a NULL-instance lookup (the loader
//!    answers those itself).
//! 2. fovea above it (fovea → refuser → runtime): whatever NULL-instance lookup a layer above makes
//!    is refused, the instance still works, and fovea still learns what the runtime offers (through
//!    an instance of its own): the runtime's native XR_FB_swapchain_update_state passes through, no
//!    per-instance warning, one line for the process.

use std::ffi::{c_char, CStr, CString};
use std::ptr::{null, null_mut};

// The layer reads no fovea.toml and writes no log file in the user's home during tests.
fovea_harness::private_home!();

use fovea_harness::{artifact, open_library, refuser_stats, skip, LayerSpec};
use openxr_sys as xr;
use openxr_sys::Handle;

use crate::process::in_own_process;

struct Loader {
    gipa: xr::pfn::GetInstanceProcAddr,
    _lib: libloading::Library,
}

impl Loader {
    unsafe fn load<F: Copy>(&self, instance: xr::Instance, name: &str) -> F {
        let c = CString::new(name).unwrap();
        let mut f = None;
        assert_eq!(
            (self.gipa)(instance, c.as_ptr(), &mut f),
            xr::Result::SUCCESS,
            "{name}"
        );
        std::mem::transmute_copy(&f.unwrap())
    }

    /// xrCreateInstance with these API layers enabled, XR_MND_headless and `extra` extensions.
    unsafe fn create_instance(
        &self,
        layers: &[&str],
        extra: &[&CStr],
    ) -> Result<xr::Instance, xr::Result> {
        let create: xr::pfn::CreateInstance = self.load(xr::Instance::NULL, "xrCreateInstance");
        let names: Vec<CString> = layers.iter().map(|l| CString::new(*l).unwrap()).collect();
        let layer_ptrs: Vec<*const c_char> = names.iter().map(|n| n.as_ptr()).collect();
        let exts: Vec<*const c_char> = std::iter::once(c"XR_MND_headless")
            .chain(extra.iter().copied())
            .map(CStr::as_ptr)
            .collect();
        let mut app = xr::ApplicationInfo {
            application_name: [0; xr::MAX_APPLICATION_NAME_SIZE],
            application_version: 1,
            engine_name: [0; xr::MAX_ENGINE_NAME_SIZE],
            engine_version: 1,
            // The Debian loader is 1.0.20 and rejects 1.1 applications.
            api_version: xr::Version::new(1, 0, 20),
        };
        for (d, s) in app.application_name.iter_mut().zip(b"refuser loader test") {
            *d = *s as c_char;
        }
        let info = xr::InstanceCreateInfo {
            ty: xr::InstanceCreateInfo::TYPE,
            next: null(),
            create_flags: xr::InstanceCreateFlags::EMPTY,
            application_info: app,
            enabled_api_layer_count: layer_ptrs.len() as u32,
            enabled_api_layer_names: layer_ptrs.as_ptr(),
            enabled_extension_count: exts.len() as u32,
            enabled_extension_names: exts.as_ptr(),
        };
        let mut instance = xr::Instance::NULL;
        match create(&info, &mut instance) {
            xr::Result::SUCCESS => Ok(instance),
            e => Err(e),
        }
    }

    /// The runtime's name, a headless session that begins, and two located views: the calls a
    /// pass-through layer must not disturb.
    unsafe fn exercise(&self, instance: xr::Instance) {
        let props_fn: xr::pfn::GetInstanceProperties =
            self.load(instance, "xrGetInstanceProperties");
        let mut props = xr::InstanceProperties {
            ty: xr::InstanceProperties::TYPE,
            next: null_mut(),
            runtime_version: xr::Version::new(0, 0, 0),
            runtime_name: [0; xr::MAX_RUNTIME_NAME_SIZE],
        };
        assert_eq!(props_fn(instance, &mut props), xr::Result::SUCCESS);
        assert_eq!(
            CStr::from_ptr(props.runtime_name.as_ptr()).to_str(),
            Ok("fovea simulated headset")
        );
        let get_system: xr::pfn::GetSystem = self.load(instance, "xrGetSystem");
        let gi = xr::SystemGetInfo {
            ty: xr::SystemGetInfo::TYPE,
            next: null(),
            form_factor: xr::FormFactor::HEAD_MOUNTED_DISPLAY,
        };
        let mut system = xr::SystemId::NULL;
        assert_eq!(get_system(instance, &gi, &mut system), xr::Result::SUCCESS);
        let create_session: xr::pfn::CreateSession = self.load(instance, "xrCreateSession");
        let si = xr::SessionCreateInfo {
            ty: xr::SessionCreateInfo::TYPE,
            next: null(),
            create_flags: xr::SessionCreateFlags::EMPTY,
            system_id: system,
        };
        let mut session = xr::Session::NULL;
        assert_eq!(
            create_session(instance, &si, &mut session),
            xr::Result::SUCCESS
        );
        let begin: xr::pfn::BeginSession = self.load(instance, "xrBeginSession");
        let bi = xr::SessionBeginInfo {
            ty: xr::SessionBeginInfo::TYPE,
            next: null(),
            primary_view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
        };
        assert_eq!(begin(session, &bi), xr::Result::SUCCESS);
        let create_space: xr::pfn::CreateReferenceSpace =
            self.load(instance, "xrCreateReferenceSpace");
        let space_info = xr::ReferenceSpaceCreateInfo {
            ty: xr::ReferenceSpaceCreateInfo::TYPE,
            next: null(),
            reference_space_type: xr::ReferenceSpaceType::LOCAL,
            pose_in_reference_space: xr::Posef::IDENTITY,
        };
        let mut space = xr::Space::NULL;
        assert_eq!(
            create_space(session, &space_info, &mut space),
            xr::Result::SUCCESS
        );
        let locate: xr::pfn::LocateViews = self.load(instance, "xrLocateViews");
        let li = xr::ViewLocateInfo {
            ty: xr::ViewLocateInfo::TYPE,
            next: null(),
            view_configuration_type: xr::ViewConfigurationType::PRIMARY_STEREO,
            display_time: xr::Time::from_nanos(1_000_000_000_000),
            space,
        };
        let mut vs = xr::ViewState {
            ty: xr::ViewState::TYPE,
            next: null_mut(),
            view_state_flags: xr::ViewStateFlags::EMPTY,
        };
        let blank = xr::View {
            ty: xr::View::TYPE,
            next: null_mut(),
            pose: xr::Posef::IDENTITY,
            fov: xr::Fovf::default(),
        };
        let mut views = [blank; 2];
        let mut n = 0;
        assert_eq!(
            locate(session, &li, &mut vs, 2, &mut n, views.as_mut_ptr()),
            xr::Result::SUCCESS
        );
        assert_eq!(n, 2);
        assert!(views[0].fov.angle_left < 0.0 && views[0].fov.angle_right > 0.0);
        let destroy_session: xr::pfn::DestroySession = self.load(instance, "xrDestroySession");
        assert_eq!(destroy_session(session), xr::Result::SUCCESS);
    }
}

/// In a process of its own ([`crate::process::in_own_process`]): it sets process-wide environment variables and the loader allows one instance.
#[test]
fn the_refusing_layer_through_the_khronos_loader() {
    in_own_process(
        module_path!(),
        "the_refusing_layer_through_the_khronos_loader",
        the_refusing_layer_through_the_khronos_loader_here,
    );
}

fn the_refusing_layer_through_the_khronos_loader_here() {
    let (Ok(runtime), Ok(refuser), Ok(fovea)) = (
        artifact("libfovea_sim.so"),
        LayerSpec::refuse_null_lookups(),
        LayerSpec::fovea(),
    ) else {
        skip("libfovea_sim.so, libfovea_refuser.so or libfovea.so was not built");
        return;
    };
    let lib = match unsafe { libloading::Library::new("libopenxr_loader.so.1") } {
        Ok(l) => l,
        Err(e) => {
            skip(&format!("the Khronos OpenXR loader is not installed ({e})"));
            return;
        }
    };
    let dir = std::env::temp_dir().join(format!("fovea-refuser-loader-{}", std::process::id()));
    let layers = dir.join("layers");
    refuser.write_manifest(&layers).unwrap();
    fovea.write_manifest(&layers).unwrap();
    let runtime_json = dir.join("fovea_sim_runtime.json");
    std::fs::write(
        &runtime_json,
        format!(
            r#"{{"file_format_version": "1.0.0", "runtime": {{"name": "fovea simulated headset", "library_path": "{}"}}}}"#,
            runtime.display()
        ),
    )
    .unwrap();
    std::env::set_var("XR_RUNTIME_JSON", &runtime_json);
    std::env::set_var("XR_API_LAYER_PATH", &layers);
    // fovea's log, read at the end (fovea is loaded by the loader, after these are set).
    let log = dir.join("fovea.log");
    std::env::set_var(
        "FOVEA_LOG",
        format!(
            "warn,{}=info,{}=info",
            fovea_abi::log_target::BELOW,
            fovea_abi::log_target::INSTANCE
        ),
    );
    std::env::set_var("FOVEA_LOG_FILE", &log);
    // A runtime with native FB support below the refuser: what it hides from a layer above.
    std::env::set_var("FOVEA_SIM_NATIVE_UPDATE_STATE", "1");
    // Holds the refuser loaded across the loader's dlclose at xrDestroyInstance, so its counters
    // are read from one copy.
    let _keep = open_library(&refuser.path).unwrap();
    let loader = Loader {
        gipa: unsafe {
            *lib.get::<xr::pfn::GetInstanceProcAddr>(b"xrGetInstanceProcAddr\0")
                .unwrap()
        },
        _lib: lib,
    };

    unsafe {
        // 1. The refuser alone.
        let before = refuser_stats(&refuser.path).unwrap();
        let instance = loader.create_instance(&[&refuser.name], &[]).unwrap();
        loader.exercise(instance);
        let destroy: xr::pfn::DestroyInstance = loader.load(instance, "xrDestroyInstance");
        assert_eq!(destroy(instance), xr::Result::SUCCESS);
        let alone = refuser_stats(&refuser.path).unwrap();
        assert_eq!(alone.instances_created - before.instances_created, 1);
        assert_eq!(alone.instances_destroyed - before.instances_destroyed, 1);
        // The loader fills its dispatch table through the topmost xrGetInstanceProcAddr.
        assert!(alone.forwarded_lookups > before.forwarded_lookups);
        assert_eq!(
            alone.null_lookups, before.null_lookups,
            "the loader answers NULL-instance lookups itself"
        );

        // 2. fovea above the refuser: every NULL-instance lookup fovea makes is refused, and the
        // instance works regardless.
        let instance = loader
            .create_instance(
                &[&fovea.name, &refuser.name],
                &[c"XR_FB_swapchain_update_state"],
            )
            .unwrap();
        let stacked = refuser_stats(&refuser.path).unwrap();
        let asked = stacked.null_lookups - alone.null_lookups;
        let refused = stacked.null_lookups_refused - alone.null_lookups_refused;
        eprintln!("fovea asked the refuser {asked} NULL-instance lookups; {refused} refused");
        assert_eq!(asked, refused);
        // fovea asks what lies below through an instance of its own, destroyed before the
        // application's is created.
        assert_eq!(stacked.instances_created - alone.instances_created, 2);
        assert_eq!(stacked.instances_destroyed - alone.instances_destroyed, 1);
        loader.exercise(instance);
        let destroy: xr::pfn::DestroyInstance = loader.load(instance, "xrDestroyInstance");
        assert_eq!(destroy(instance), xr::Result::SUCCESS);
        // A second instance: the same, and still no warning.
        let instance = loader
            .create_instance(
                &[&fovea.name, &refuser.name],
                &[c"XR_FB_swapchain_update_state"],
            )
            .unwrap();
        loader.exercise(instance);
        let destroy: xr::pfn::DestroyInstance = loader.load(instance, "xrDestroyInstance");
        assert_eq!(destroy(instance), xr::Result::SUCCESS);
    }
    // fovea learned that the runtime offers XR_FB_swapchain_update_state natively and passed it
    // through (its "instance created" line lists it as native), said how once, and never warned.
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(
        !text.contains("does not offer xrEnumerateInstanceExtensionProperties"),
        "{text}"
    );
    assert_eq!(
        text.matches("refuses lookups without an instance").count(),
        1,
        "{text}"
    );
    let created: Vec<&str> = text
        .lines()
        .filter(|l| l.contains("instance created"))
        .collect();
    assert_eq!(created.len(), 2, "{text}");
    for line in created {
        assert!(line.contains("native=[SwapchainUpdateState]"), "{line}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
