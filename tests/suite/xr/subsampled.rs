//! Reconstruction's switches on the OpenXR side (docs/openxr-layer.md#subsampled-images): for each
//! input (the application's `VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT` in
//! `XrVulkanSwapchainCreateInfoMETA`, Quest's `debug.oculus.foveation.subsampled`, the `subsampled`
//! setting, who foveates the swapchain), what usage the simulated runtime's `xrCreateSwapchain` got
//! (its call journal) and what fovea published for the images the application enumerated (the
//! layer's log), on Vulkan sessions on lavapipe. An application that uses nothing of fovea's gets
//! its usage unchanged and nothing published, whatever forces reconstruction on. Under the Khronos
//! validation layer, a copy out of one of the runtime's images into another (what reconstruction
//! records) is valid exactly where fovea reconstructs, and invalid for the transfer usage the
//! application's own request lacks elsewhere.
//!
//! All cases run in one child process of their own: the switches are environment variables read
//! when each instance is created, and the log file is the process's.

use std::ffi::c_void;
use std::path::{Path, PathBuf};
use std::ptr::null_mut;

use ash::vk;
use fovea_harness::app::API_1_0;
use fovea_harness::sim::control::{self, Fault};
use fovea_harness::vulkan::{self, pick_lavapipe, take_messages, Vulkan};
use fovea_harness::{skip, App, Chain};
use openxr_sys as xr;
use xr::Handle;

use crate::both::fdm_vulkan::{func, running_session, swapchain_info, FDM_BIT};
use crate::support::device::{allocate, resettable_pool};
use crate::support::in_own_process;

/// `XrVulkanSwapchainCreateInfoMETA` as C lays it out (docs/openxr-layer.md: openxr-sys declares
/// its flags 64 bits wide).
#[repr(C)]
struct MetaCreateInfo {
    ty: xr::StructureType,
    next: *const c_void,
    additional_create_flags: u32,
    additional_usage_flags: u32,
}

/// `VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT`.
const SUBSAMPLED_BIT: u32 = 0x4000;
/// `XR_SWAPCHAIN_USAGE_TRANSFER_SRC_BIT | XR_SWAPCHAIN_USAGE_TRANSFER_DST_BIT`.
const TRANSFER: u64 = 0x8 | 0x10;
/// The usage of [`swapchain_info`]: colour attachment and sampled.
const APP_USAGE: u64 = 0x1 | 0x20;
/// A depth swapchain's: depth-stencil attachment.
const DEPTH_USAGE: u64 = 0x2;
/// `VK_FORMAT_D32_SFLOAT`.
const D32: i64 = 126;

/// What the application does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum AppKind {
    /// Enables nothing fovea provides: a colour swapchain, no chain.
    Bystander,
    /// XR_FB_foveation_vulkan: a FRAGMENT_DENSITY_MAP swapchain (fovea's density images).
    Profiles,
    /// As `Profiles`, with `VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT` in the META struct.
    ProfilesAsking,
    /// Enables nothing; a depth swapchain.
    BystanderDepth,
}

/// One case: the switches and what must come of them.
#[derive(Clone, Debug)]
struct Case {
    app: AppKind,
    /// `DEBUG_OCULUS_FOVEATION_SUBSAMPLED`.
    property: Option<&'static str>,
    /// `FOVEA_SUBSAMPLED`.
    setting: Option<&'static str>,
    /// `FOVEA_INJECT=1`.
    inject: bool,
    /// A `fovea.toml` for the process (`FOVEA_CONFIG`).
    config: Option<&'static str>,
    /// The runtime refuses the first xrCreateSwapchain with this.
    refuse: Option<xr::Result>,
    /// The application's VkDevice enables Vulkan 1.2's `imagelessFramebuffer`.
    imageless: bool,
    /// The usage the runtime's (last) xrCreateSwapchain got.
    usage: u64,
    /// What was published for the images: `None`, nothing.
    published: Option<bool>,
    /// A fragment of the one line the decision gets, where it gets one at info level.
    line: Option<&'static str>,
}

impl Case {
    fn new(app: AppKind, usage: u64, published: Option<bool>) -> Case {
        Case {
            app,
            property: None,
            setting: None,
            inject: false,
            config: None,
            refuse: None,
            imageless: false,
            usage,
            published,
            line: None,
        }
    }
}

const RECONSTRUCTED: &str = "coarse blocks reconstructed by fovea's Vulkan layer";
const NOT_RECONSTRUCTED: &str = "coarse blocks not reconstructed";
const PUBLISHED: &str = "reconstruction decision published for the swapchain's images";
const FORGOTTEN: &str = "reconstruction decision forgotten";

fn cases() -> Vec<Case> {
    use AppKind::*;
    let on = APP_USAGE | TRANSFER;
    let c = Case::new;
    vec![
        // Nothing of fovea's: nothing changes, whatever forces reconstruction on.
        c(Bystander, APP_USAGE, None),
        Case {
            property: Some("1"),
            setting: Some("1"),
            ..c(Bystander, APP_USAGE, None)
        },
        // The application foveates with profiles: as it asks.
        c(Profiles, APP_USAGE, Some(false)),
        Case {
            line: Some("the application asked for VK_IMAGE_CREATE_SUBSAMPLED_BIT_EXT"),
            ..c(ProfilesAsking, on, Some(true))
        },
        // The property forces either way, over everything.
        Case {
            property: Some("0"),
            line: Some("debug.oculus.foveation.subsampled=0"),
            ..c(ProfilesAsking, APP_USAGE, Some(false))
        },
        Case {
            property: Some("1"),
            line: Some("debug.oculus.foveation.subsampled=1"),
            ..c(Profiles, on, Some(true))
        },
        Case {
            property: Some("1"),
            setting: Some("0"),
            ..c(Profiles, on, Some(true))
        },
        // The setting over the request.
        Case {
            setting: Some("1"),
            line: Some("subsampled = on"),
            ..c(Profiles, on, Some(true))
        },
        Case {
            setting: Some("0"),
            line: Some("subsampled = off"),
            ..c(ProfilesAsking, APP_USAGE, Some(false))
        },
        // Per application, from the file.
        Case {
            config: Some("subsampled = \"off\"\n[app.\"fovea-harness\"]\nsubsampled = \"on\"\n"),
            line: Some("subsampled = on"),
            ..c(Profiles, on, Some(true))
        },
        Case {
            config: Some("[app.\"another app\"]\nsubsampled = \"on\"\n"),
            ..c(Profiles, APP_USAGE, Some(false))
        },
        // Injection: on by default, the setting and property switch it off.
        Case {
            inject: true,
            line: Some("fovea injects shading rates into it"),
            ..c(Bystander, on, Some(true))
        },
        Case {
            inject: true,
            setting: Some("0"),
            ..c(Bystander, APP_USAGE, Some(false))
        },
        Case {
            inject: true,
            property: Some("0"),
            setting: Some("1"),
            ..c(Bystander, APP_USAGE, Some(false))
        },
        // A depth swapchain is never reconstructed, injected or forced.
        Case {
            inject: true,
            property: Some("1"),
            ..c(BystanderDepth, DEPTH_USAGE, None)
        },
        // An application with imageless framebuffers names the usage it expects of its images:
        // nothing is added, whatever switches reconstruction on, and the line says why.
        Case {
            inject: true,
            imageless: true,
            line: Some("imagelessFramebuffer"),
            ..c(Bystander, APP_USAGE, Some(false))
        },
        Case {
            property: Some("1"),
            imageless: true,
            line: Some("VUID-VkRenderPassBeginInfo-framebuffer-04627"),
            ..c(ProfilesAsking, APP_USAGE, Some(false))
        },
        // A runtime that refuses the usage: the application's swapchain as it asked, no
        // reconstruction.
        Case {
            refuse: Some(xr::Result::ERROR_FEATURE_UNSUPPORTED),
            line: Some("the runtime refused the transfer usage it needs"),
            ..c(ProfilesAsking, APP_USAGE, Some(false))
        },
    ]
}

/// The extensions `kind` enables.
fn extensions(kind: AppKind) -> Vec<&'static str> {
    let mut e = vec!["XR_KHR_vulkan_enable2"];
    if matches!(kind, AppKind::Profiles | AppKind::ProfilesAsking) {
        e.extend([
            "XR_FB_swapchain_update_state",
            "XR_FB_foveation",
            "XR_FB_foveation_configuration",
            "XR_FB_foveation_vulkan",
        ]);
    }
    if kind == AppKind::ProfilesAsking {
        e.push("XR_META_vulkan_swapchain_create_info");
    }
    e
}

/// The log written since `from` bytes.
fn log_since(log: &Path, from: u64) -> String {
    let text = std::fs::read(log).unwrap_or_default();
    String::from_utf8_lossy(&text[(from as usize).min(text.len())..]).into_owned()
}

fn log_len(log: &Path) -> u64 {
    std::fs::metadata(log).map_or(0, |m| m.len())
}

/// The `images=[…]` of the first line holding `what`, and that line.
fn images_in(text: &str, what: &str) -> Option<(Vec<u64>, String)> {
    let line = text.lines().find(|l| l.contains(what))?;
    let list = line.split("images=[").nth(1)?.split(']').next()?;
    let images = list
        .split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|s| s.trim().parse().unwrap())
        .collect();
    Some((images, line.to_owned()))
}

/// Records (never submits) a copy from layer 0 of `src` to layer 0 of `dst`, as reconstruction
/// copies a pass's colour out and back: the validation messages that recording drew.
fn copy_messages(v: &Vulkan, src: u64, dst: u64) -> Vec<String> {
    use ash::vk::Handle as _;
    take_messages();
    let d = &v.device;
    let pool = resettable_pool(d, v.family);
    let cb = allocate(d, pool);
    let layer = vk::ImageSubresourceLayers::default()
        .aspect_mask(vk::ImageAspectFlags::COLOR)
        .layer_count(1);
    let region = vk::ImageCopy::default()
        .src_subresource(layer)
        .dst_subresource(layer)
        .extent(vk::Extent3D {
            width: 16,
            height: 16,
            depth: 1,
        });
    // SAFETY: the pool, the command buffer and the images are this device's and alive; the
    // command buffer is never submitted.
    unsafe {
        d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
            .unwrap();
        d.cmd_copy_image(
            cb,
            vk::Image::from_raw(src),
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            vk::Image::from_raw(dst),
            vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            &[region],
        );
        d.end_command_buffer(cb).unwrap();
        d.destroy_command_pool(pool, None);
    }
    take_messages()
}

/// How the case ends: the swapchain destroyed by itself, or with its instance.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Teardown {
    Swapchain,
    Instance,
}

/// Runs one case; `Err` with a reason to skip where the system has no lavapipe.
fn run(
    case: &Case,
    entry: &ash::Entry,
    dir: &Path,
    log: &Path,
    end: Teardown,
) -> Result<(), String> {
    for (var, value) in [
        ("DEBUG_OCULUS_FOVEATION_SUBSAMPLED", case.property),
        ("FOVEA_SUBSAMPLED", case.setting),
        ("FOVEA_INJECT", case.inject.then_some("1")),
    ] {
        match value {
            Some(v) => std::env::set_var(var, v),
            None => std::env::remove_var(var),
        }
    }
    let config: PathBuf = dir.join("fovea.toml");
    std::fs::write(&config, case.config.unwrap_or("")).unwrap();
    std::env::set_var("FOVEA_CONFIG", &config);
    control::set_thread_config(None);
    let from = log_len(log);
    let app = App::new(Chain::fovea().unwrap(), &extensions(case.app), API_1_0).unwrap();
    let sys = app.system();
    let features12 = vk::PhysicalDeviceVulkan12Features {
        imageless_framebuffer: vk::TRUE,
        ..Default::default()
    };
    let options = vulkan::Options {
        api_version: vk::API_VERSION_1_2,
        device_next: if case.imageless {
            &features12 as *const _ as *const c_void
        } else {
            std::ptr::null()
        },
        ..vulkan::Options::default()
    };
    let v = match Vulkan::through_xr_with(entry, app.chain.gipa(), app.instance, sys, &options) {
        Ok(v) => v,
        Err(why) => {
            assert_eq!(app.destroy(), xr::Result::SUCCESS);
            return Err(why);
        }
    };
    if let Some(result) = case.refuse {
        control::inject_fault(
            app.instance,
            Fault {
                function: "xrCreateSwapchain".into(),
                result,
                nth: 1,
            },
        );
    }
    let (session, _space) = running_session(&app, sys, &v);
    let fdm = xr::SwapchainCreateInfoFoveationFB {
        ty: xr::StructureType::SWAPCHAIN_CREATE_INFO_FOVEATION_FB,
        next: null_mut(),
        flags: xr::SwapchainCreateFoveationFlagsFB::from_raw(FDM_BIT),
    };
    let meta = MetaCreateInfo {
        ty: xr::StructureType::VULKAN_SWAPCHAIN_CREATE_INFO_META,
        next: &fdm as *const _ as *const c_void,
        additional_create_flags: SUBSAMPLED_BIT,
        additional_usage_flags: 0,
    };
    let mut info = match case.app {
        AppKind::Bystander | AppKind::BystanderDepth => swapchain_info(std::ptr::null()),
        AppKind::Profiles => swapchain_info(&fdm as *const _ as *const c_void),
        AppKind::ProfilesAsking => swapchain_info(&meta as *const _ as *const c_void),
    };
    if case.app == AppKind::BystanderDepth {
        info.usage_flags = xr::SwapchainUsageFlags::from_raw(DEPTH_USAGE);
        info.format = D32;
    }
    let before = info;
    let create: xr::pfn::CreateSwapchain = func(&app, "xrCreateSwapchain");
    let mut swapchain = xr::Swapchain::NULL;
    assert_eq!(
        unsafe { create(session, &info, &mut swapchain) },
        xr::Result::SUCCESS,
        "{case:?}"
    );
    // The application's struct is as it built it.
    assert_eq!(format!("{before:?}"), format!("{info:?}"));
    let journal = control::journal(app.instance);
    let creates: Vec<_> = journal
        .iter()
        .filter(|c| c.function == "xrCreateSwapchain")
        .collect();
    assert_eq!(
        creates.len(),
        if case.refuse.is_some() { 2 } else { 1 },
        "{case:?}: {creates:?}"
    );
    let last = creates.last().unwrap();
    assert_eq!(last.result, xr::Result::SUCCESS);
    assert!(
        last.detail.contains(&format!(" usage={:#x} ", case.usage)),
        "{case:?}: the runtime got {}",
        last.detail
    );
    // The application's images, as it enumerates them.
    let images_fn: xr::pfn::EnumerateSwapchainImages = func(&app, "xrEnumerateSwapchainImages");
    let mut count = 0;
    assert_eq!(
        unsafe { images_fn(swapchain, 0, &mut count, null_mut()) },
        xr::Result::SUCCESS
    );
    let mut images = vec![
        xr::SwapchainImageVulkanKHR {
            ty: xr::StructureType::SWAPCHAIN_IMAGE_VULKAN_KHR,
            next: null_mut(),
            image: 0,
        };
        count as usize
    ];
    assert_eq!(
        unsafe {
            images_fn(
                swapchain,
                count,
                &mut count,
                images.as_mut_ptr() as *mut xr::SwapchainImageBaseHeader,
            )
        },
        xr::Result::SUCCESS
    );
    let mut raw: Vec<u64> = images.iter().map(|i| i.image).collect();
    if case.app != AppKind::BystanderDepth {
        let messages = copy_messages(&v, raw[0], raw[1]);
        if case.usage & TRANSFER == TRANSFER {
            assert!(messages.is_empty(), "{case:?}: {messages:#?}");
        } else {
            // The check can fail: without the usage, the validation layer refuses the copy.
            assert!(
                messages.iter().any(|m| m.contains("TRANSFER_SRC")),
                "{case:?}: {messages:#?}"
            );
        }
    }
    raw.sort_unstable();
    let text = log_since(log, from);
    match (case.published, images_in(&text, PUBLISHED)) {
        (None, None) => {}
        (Some(want), Some((mut got, line))) => {
            got.sort_unstable();
            assert_eq!(got, raw, "{case:?}: {line}");
            assert!(
                line.contains(&format!("reconstruct={want}")),
                "{case:?}: {line}"
            );
        }
        (want, got) => panic!("{case:?}: published {got:?}, not {want:?}:\n{text}"),
    }
    let lines = text
        .lines()
        .filter(|l| {
            (l.contains(RECONSTRUCTED) || l.contains(NOT_RECONSTRUCTED)) && l.contains("INFO")
        })
        .collect::<Vec<_>>();
    match case.line {
        Some(why) => {
            assert_eq!(lines.len(), 1, "{case:?}: {lines:?}");
            assert!(lines[0].contains(why), "{case:?}: {lines:?}");
            let said = if case.published == Some(true) {
                RECONSTRUCTED
            } else {
                NOT_RECONSTRUCTED
            };
            assert!(lines[0].contains(said), "{case:?}: {lines:?}");
        }
        None if case.published.is_none() => {
            assert!(lines.is_empty(), "{case:?}: {lines:?}")
        }
        None => {}
    }
    // Where something was published, it is forgotten when the runtime destroys the images, by
    // xrDestroySwapchain or with the instance.
    let from = log_len(log);
    if end == Teardown::Swapchain {
        let destroy: xr::pfn::DestroySwapchain = func(&app, "xrDestroySwapchain");
        assert_eq!(unsafe { destroy(swapchain) }, xr::Result::SUCCESS);
    }
    assert_eq!(app.destroy(), xr::Result::SUCCESS);
    let text = log_since(log, from);
    match images_in(&text, FORGOTTEN) {
        Some((mut got, line)) => {
            assert!(case.published.is_some(), "{case:?}: {line}");
            got.sort_unstable();
            assert_eq!(got, raw, "{case:?}: {line}");
        }
        None => assert!(
            case.published.is_none(),
            "{case:?}: nothing forgotten:\n{text}"
        ),
    }
    v.destroy();
    let messages = take_messages();
    assert!(messages.is_empty(), "{case:?}: {messages:#?}");
    Ok(())
}

#[test]
fn each_switch_decides_the_usage_asked_of_the_runtime_and_what_is_published() {
    in_own_process(
        module_path!(),
        "each_switch_decides_the_usage_asked_of_the_runtime_and_what_is_published",
        || {
            pick_lavapipe();
            let entry = match vulkan::validated_entry() {
                Ok(e) => e,
                Err(why) => {
                    skip(&why);
                    return;
                }
            };
            let dir = std::env::temp_dir().join(format!("fovea-subsampled-{}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            let log = dir.join("fovea.log");
            std::env::set_var("FOVEA_LOG", "info,fovea=debug");
            std::env::set_var("FOVEA_LOG_FILE", &log);
            for (n, case) in cases().iter().enumerate() {
                let end = if n % 2 == 0 {
                    Teardown::Swapchain
                } else {
                    Teardown::Instance
                };
                if let Err(why) = run(case, &entry, &dir, &log, end) {
                    std::fs::remove_dir_all(&dir).ok();
                    skip(&why);
                    return;
                }
            }
            std::fs::remove_dir_all(&dir).ok();
        },
    );
}
