//! The real Khronos loader (libopenxr_loader.so.1, Debian 1.0.20) loading target/debug/libfovea_sim.so
//! through a runtime manifest named by XR_RUNTIME_JSON. One test, in a process of its own, because it
//! sets process-wide environment variables.

use std::ffi::{c_char, c_void, CStr, CString};
use std::path::PathBuf;
use std::ptr::{null, null_mut};

use openxr_sys as xr;
use openxr_sys::Handle;

use crate::process::in_own_process;

fn skip(reason: &str) {
    if std::env::var("FOVEA_REQUIRE_SYSTEM").as_deref() == Ok("1") {
        panic!("FOVEA_REQUIRE_SYSTEM=1 but {reason}");
    }
    eprintln!("skipping: {reason}");
}

/// target/debug/deps/<test> → target/debug/libfovea_sim.so
fn runtime_library() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    exe.parent()
        .unwrap()
        .parent()
        .unwrap()
        .join("libfovea_sim.so")
}

/// In a process of its own ([`crate::process::in_own_process`]): it sets process-wide environment variables.
#[test]
fn khronos_loader_creates_an_instance_and_a_headless_session() {
    in_own_process(
        module_path!(),
        "khronos_loader_creates_an_instance_and_a_headless_session",
        khronos_loader_creates_an_instance_and_a_headless_session_here,
    );
}

fn khronos_loader_creates_an_instance_and_a_headless_session_here() {
    let library = runtime_library();
    if !library.exists() {
        return skip(&format!("{} was not built", library.display()));
    }
    let loader = match unsafe { libloading::Library::new("libopenxr_loader.so.1") } {
        Ok(l) => l,
        Err(e) => return skip(&format!("the Khronos OpenXR loader is not installed ({e})")),
    };
    let dir = std::env::temp_dir().join(format!("fovea-sim-loader-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let manifest = dir.join("fovea_sim_runtime.json");
    let json = format!(
        r#"{{"file_format_version": "1.0.0", "runtime": {{"name": "fovea simulated headset", "library_path": "{}"}}}}"#,
        library.display()
    );
    std::fs::write(&manifest, json).unwrap();
    std::env::set_var("XR_RUNTIME_JSON", &manifest);
    std::env::set_var("FOVEA_SIM_HEADSET", "rift-cv1");

    unsafe {
        let gipa: libloading::Symbol<xr::pfn::GetInstanceProcAddr> =
            loader.get(b"xrGetInstanceProcAddr\0").unwrap();
        let load = |instance: xr::Instance, name: &str| {
            let c = CString::new(name).unwrap();
            let mut f = None;
            assert_eq!(
                gipa(instance, c.as_ptr(), &mut f),
                xr::Result::SUCCESS,
                "{name}"
            );
            f.unwrap()
        };
        let create: xr::pfn::CreateInstance =
            std::mem::transmute(load(xr::Instance::NULL, "xrCreateInstance"));
        let headless = c"XR_MND_headless";
        let exts = [headless.as_ptr()];
        let mut app = xr::ApplicationInfo {
            application_name: [0; xr::MAX_APPLICATION_NAME_SIZE],
            application_version: 1,
            engine_name: [0; xr::MAX_ENGINE_NAME_SIZE],
            engine_version: 1,
            // The Debian loader is 1.0.20 and rejects 1.1 applications.
            api_version: xr::Version::new(1, 0, 20),
        };
        for (d, s) in app.application_name.iter_mut().zip(b"loader test") {
            *d = *s as c_char;
        }
        let info = xr::InstanceCreateInfo {
            ty: xr::InstanceCreateInfo::TYPE,
            next: null(),
            create_flags: xr::InstanceCreateFlags::EMPTY,
            application_info: app,
            enabled_api_layer_count: 0,
            enabled_api_layer_names: null(),
            enabled_extension_count: 1,
            enabled_extension_names: exts.as_ptr(),
        };
        let mut instance = xr::Instance::NULL;
        assert_eq!(create(&info, &mut instance), xr::Result::SUCCESS);

        let props_fn: xr::pfn::GetInstanceProperties =
            std::mem::transmute(load(instance, "xrGetInstanceProperties"));
        let mut props = xr::InstanceProperties {
            ty: xr::InstanceProperties::TYPE,
            next: null_mut(),
            runtime_version: xr::Version::new(0, 0, 0),
            runtime_name: [0; xr::MAX_RUNTIME_NAME_SIZE],
        };
        assert_eq!(props_fn(instance, &mut props), xr::Result::SUCCESS);
        assert_eq!(
            CStr::from_ptr(props.runtime_name.as_ptr())
                .to_str()
                .unwrap(),
            "fovea simulated headset"
        );

        let get_system: xr::pfn::GetSystem = std::mem::transmute(load(instance, "xrGetSystem"));
        let gi = xr::SystemGetInfo {
            ty: xr::SystemGetInfo::TYPE,
            next: null(),
            form_factor: xr::FormFactor::HEAD_MOUNTED_DISPLAY,
        };
        let mut system = xr::SystemId::NULL;
        assert_eq!(get_system(instance, &gi, &mut system), xr::Result::SUCCESS);

        // The preset came from FOVEA_SIM_HEADSET through the environment.
        let views_fn: xr::pfn::EnumerateViewConfigurationViews =
            std::mem::transmute(load(instance, "xrEnumerateViewConfigurationViews"));
        let mut views = [xr::ViewConfigurationView {
            ty: xr::ViewConfigurationView::TYPE,
            next: null_mut(),
            recommended_image_rect_width: 0,
            max_image_rect_width: 0,
            recommended_image_rect_height: 0,
            max_image_rect_height: 0,
            recommended_swapchain_sample_count: 0,
            max_swapchain_sample_count: 0,
        }; 2];
        let mut count = 0;
        let stereo = xr::ViewConfigurationType::PRIMARY_STEREO;
        assert_eq!(
            views_fn(instance, system, stereo, 2, &mut count, views.as_mut_ptr()),
            xr::Result::SUCCESS
        );
        assert_eq!(
            (
                views[0].recommended_image_rect_width,
                views[0].recommended_image_rect_height
            ),
            (1344, 1600)
        );

        let create_session: xr::pfn::CreateSession =
            std::mem::transmute(load(instance, "xrCreateSession"));
        let si = xr::SessionCreateInfo {
            ty: xr::SessionCreateInfo::TYPE,
            next: null::<c_void>(),
            create_flags: xr::SessionCreateFlags::EMPTY,
            system_id: system,
        };
        let mut session = xr::Session::NULL;
        assert_eq!(
            create_session(instance, &si, &mut session),
            xr::Result::SUCCESS
        );

        let poll: xr::pfn::PollEvent = std::mem::transmute(load(instance, "xrPollEvent"));
        let mut states = Vec::new();
        loop {
            let mut buffer = xr::EventDataBuffer {
                ty: xr::EventDataBuffer::TYPE,
                next: null(),
                varying: [0; 4000],
            };
            if poll(instance, &mut buffer) != xr::Result::SUCCESS {
                break;
            }
            states.push((*(&buffer as *const _ as *const xr::EventDataSessionStateChanged)).state);
        }
        assert_eq!(states, [xr::SessionState::IDLE, xr::SessionState::READY]);

        let destroy_session: xr::pfn::DestroySession =
            std::mem::transmute(load(instance, "xrDestroySession"));
        assert_eq!(destroy_session(session), xr::Result::SUCCESS);
        let destroy: xr::pfn::DestroyInstance =
            std::mem::transmute(load(instance, "xrDestroyInstance"));
        assert_eq!(destroy(instance), xr::Result::SUCCESS);
    }
    let _ = std::fs::remove_dir_all(&dir);
}
