//! What the Vulkan benches need for a device that injects (docs/injection.md): an OpenXR
//! instance with `FOVEA_INJECT=1` through fovea's OpenXR layer on the simulated runtime, whose
//! `xrCreateVulkanDeviceKHR` makes the device, as an `XR_KHR_vulkan_enable2` application makes
//! its session's, and the check, from what reached the test double, that injection is on for it.

use std::ffi::c_void;

use ash::vk;
use openxr_sys::Handle as _;
use serde_json::Value;

use crate::vulkan;

/// What keeps injection on: an OpenXR instance with `FOVEA_INJECT=1` through fovea's OpenXR layer
/// and the simulated runtime, whose `xrCreateVulkanDeviceKHR` makes the injecting sides' devices,
/// and a session on the first of them with a colour swapchain, which fovea publishes as
/// the left eye's (docs/injection.md#which-passes). Destroy it before the sides: the swapchain's
/// images are on the first injecting device.
pub struct Xr {
    app: fovea_harness::App,
    sys: openxr_sys::SystemId,
    /// The session, once the first injecting device exists.
    session: std::cell::Cell<openxr_sys::Session>,
}

impl Xr {
    /// Starts injection for the devices made through it, or why not.
    pub fn new() -> Result<Xr, String> {
        std::env::set_var("FOVEA_INJECT", "1");
        std::env::set_var("FOVEA_SIM_VK_DEVICE", "llvmpipe");
        let app = fovea_harness::App::new(
            fovea_harness::Chain::fovea()?,
            &["XR_KHR_vulkan_enable2"],
            fovea_harness::app::API_1_0,
        )
        .map_err(|r| format!("xrCreateInstance: {r:?}"))?;
        let sys = app.system();
        Ok(Xr {
            app,
            sys,
            session: std::cell::Cell::new(openxr_sys::Session::NULL),
        })
    }

    /// An instance and device made through the runtime, with fovea's Vulkan layer above the
    /// double, Vulkan 1.3's dynamic rendering and synchronization2, and
    /// `VK_KHR_fragment_shading_rate`'s pipeline rates (no attachments), as vkd3d-proton enables
    /// them: the bare side's device, asked for the same way.
    pub fn vulkan(&self, entry: &ash::Entry) -> Result<fovea_harness::vulkan::Vulkan, String> {
        let layers = [vulkan::FOVEA, fovea_vkdouble::LAYER_NAME];
        let extensions = [ash::khr::fragment_shading_rate::NAME];
        let rates = vk::PhysicalDeviceFragmentShadingRateFeaturesKHR::default()
            .pipeline_fragment_shading_rate(true);
        let options = fovea_harness::vulkan::Options {
            layers: &layers,
            api_version: vk::API_VERSION_1_3,
            multiview: false,
            dynamic_rendering: true,
            device_extensions: &extensions,
            device_next: &rates as *const _ as *const c_void,
            queues: 1,
        };
        fovea_harness::vulkan::Vulkan::through_xr_with(
            entry,
            self.app.chain.gipa(),
            self.app.instance,
            self.sys,
            &options,
        )
    }

    /// Makes the session on `v`'s device and its eye swapchain of `eye` pixels, where there is
    /// none yet.
    pub fn publish_eye(
        &self,
        v: &fovea_harness::vulkan::Vulkan,
        eye: [u32; 2],
    ) -> Result<(), String> {
        use openxr_sys as xr;
        if self.session.get() != xr::Session::NULL {
            return Ok(());
        }
        let binding = v.binding();
        // SAFETY: each function is looked up as the type its name implies; every struct lives
        // across its call.
        unsafe {
            let create_session: xr::pfn::CreateSession = self.app.func(c"xrCreateSession");
            let create_swapchain: xr::pfn::CreateSwapchain = self.app.func(c"xrCreateSwapchain");
            let info = xr::SessionCreateInfo {
                ty: xr::StructureType::SESSION_CREATE_INFO,
                next: &binding as *const _ as *const c_void,
                create_flags: xr::SessionCreateFlags::EMPTY,
                system_id: self.sys,
            };
            let mut session = xr::Session::NULL;
            let r = create_session(self.app.instance, &info, &mut session);
            if r != xr::Result::SUCCESS {
                return Err(format!("xrCreateSession: {r:?}"));
            }
            self.session.set(session);
            let info = xr::SwapchainCreateInfo {
                ty: xr::StructureType::SWAPCHAIN_CREATE_INFO,
                next: std::ptr::null(),
                create_flags: xr::SwapchainCreateFlags::EMPTY,
                usage_flags: xr::SwapchainUsageFlags::COLOR_ATTACHMENT,
                format: vk::Format::R8G8B8A8_SRGB.as_raw() as i64,
                sample_count: 1,
                width: eye[0],
                height: eye[1],
                face_count: 1,
                array_size: 1,
                mip_count: 1,
            };
            let mut swapchain = xr::Swapchain::NULL;
            let r = create_swapchain(session, &info, &mut swapchain);
            if r != xr::Result::SUCCESS {
                return Err(format!("xrCreateSwapchain: {r:?}"));
            }
        }
        Ok(())
    }
}

/// The handle a double's record names under `key`.
pub fn handle(e: &Value, key: &str) -> u64 {
    e[key].as_u64().unwrap_or(0)
}

/// The extent of the image `view` shows, as the double recorded them.
pub fn extent_of(events: &[Value], view: u64) -> Option<Value> {
    let image = events
        .iter()
        .find(|e| e["kind"] == "image_view" && handle(e, "view") == view)
        .map(|e| handle(e, "image"))?;
    events
        .iter()
        .find(|e| e["kind"] == "image" && handle(e, "image") == image)
        .map(|e| e["extent"].clone())
}

/// That injection is on for a device just made, from what reached the double since its records
/// were cleared in front of it: the device with the shading-rate attachment feature (asked for
/// pipeline rates only) and the framebuffer `fb` with a second attachment, fovea's map for an
/// eye-shaped target of `eye` pixels (its extent over the profile's texel: a full-rate map would
/// cover the framebuffer only). Returns that map's view and its extent as the double records it.
pub fn injects(
    double: &fovea_vkdouble::Loaded,
    fb: u64,
    eye: [u32; 2],
) -> Result<(u64, Value), String> {
    let texel = fovea_vkdouble::Profile::Nvidia.texel();
    let eye_map = serde_json::json!([eye[0].div_ceil(texel.width), eye[1].div_ceil(texel.height)]);
    let events = double.records()["events"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    let of = |kind: &str| -> Vec<&Value> { events.iter().filter(|e| e["kind"] == kind).collect() };
    let devices = of("device");
    match devices.as_slice() {
        [d] if d["features"]["attachment"] == true => {}
        _ => {
            return Err(format!(
                "the device reached the driver without the shading-rate attachment feature: \
                 {devices:?}"
            ))
        }
    }
    let made = of("framebuffer");
    let map = made
        .iter()
        .find(|e| handle(e, "framebuffer") == fb)
        .and_then(|e| e["attachments"].as_array()?.get(1)?.as_u64());
    let Some(map) = map else {
        return Err(format!(
            "its framebuffer reached the driver without a shading-rate attachment: {made:?}"
        ));
    };
    let extent = extent_of(&events, map);
    if extent.as_ref() != Some(&eye_map) {
        return Err(format!(
            "its framebuffer's map is {extent:?}, not the eye target's {eye_map}"
        ));
    }
    Ok((map, eye_map))
}
