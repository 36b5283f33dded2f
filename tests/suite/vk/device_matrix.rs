//! Device creation through fovea's Vulkan layer, whatever the application's create info holds.
//!
//! Stack (as in `vk::layer`): this test → fovea's layer → VK_LAYER_KHRONOS_validation → the
//! shading-rate double (`nvidia`, `amd`) → lavapipe. Each case is one `vkCreateDevice` with a
//! pNext chain and extension list of the kind real applications send: Godot's (both the
//! density-map and the shading-rate extension enabled, shading-rate features used), shading rates
//! only, density maps only, and density maps with the structs Vulkan 1.1 to 1.4 applications chain
//! (the core feature structs, `VkPhysicalDeviceMaintenance6Features`,
//! `VkPhysicalDeviceVulkan14Features`, a struct nobody knows) before and after the density-map
//! features. Lavapipe here has no maintenance6 and no Vulkan 1.4, so those structs are chained
//! with every feature false, which is legal: what is tested is that the layer walks and copies
//! the chain.
//!
//! The effects checked per case: the result the application gets; that the device works (an
//! empty command buffer submitted and waited for; a timeline semaphore where the application
//! enabled that feature in a copied Vulkan 1.2 struct, which validation refuses where the feature
//! did not reach it); what the driver was asked for (the double's `device` record: every extension
//! name, every sType in the chain, the shading-rate features), with no density-map name or struct
//! among them; no misuse recorded by the double; no validation message, except validation's note
//! that a struct is unknown to it, for the structs newer than the validation layer installed (the
//! layer cannot check what it does not know; its newer versions know them).
//!
//! A density-map features struct behind a struct of a type no registry knows cannot be left out
//! (the unknown struct's size is unknown, so it cannot be copied and relinked), and the driver
//! must never see density maps: `vkCreateDevice` answers `VK_ERROR_FEATURE_NOT_PRESENT` without
//! reaching the driver (docs/vulkan-fdm-on-fsr.md#device-creation).

use std::ffi::{c_void, CStr};

use ash::vk;
use fovea_vkdouble::Profile;
use serde_json::{json, Value};

use crate::support::device::{env, take_messages, Vk, FDM};

const FSR: &CStr = c"VK_KHR_fragment_shading_rate";
/// Density-map offsets under both names, which the layer offers with density maps.
const OFFSET_EXT: &CStr = c"VK_EXT_fragment_density_map_offset";
const OFFSET_QCOM: &CStr = c"VK_QCOM_fragment_density_map_offset";
/// An sType no registry has.
const UNKNOWN: i32 = 1_000_900_001;
/// `VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_MAINTENANCE_6_FEATURES` (vk.xml; newer than ash 0.38).
const MAINTENANCE6: i32 = 1_000_545_000;
/// `VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_4_FEATURES` (vk.xml; newer than ash 0.38).
const VULKAN14: i32 = 55;
/// The loader's own link structs, which every layer's create info carries.
const LOADER_DEVICE_CREATE_INFO: i32 = 48;

/// One struct of a case's chain.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Link {
    /// `fragmentDensityMap` and `…NonSubsampledImages` enabled.
    Fdm,
    /// `VkPhysicalDeviceFragmentDensityMap2FeaturesEXT`, nothing enabled (an extension neither
    /// the driver nor the layer offers; chained by engines that query every struct they know).
    Fdm2,
    /// `VkPhysicalDeviceFragmentDensityMapOffsetFeaturesEXT` (the QCOM struct's `sType`),
    /// `fragmentDensityMapOffset` enabled: offsets, which the layer offers with density maps.
    FdmOffset,
    /// The shading-rate features: pipeline rates as given, attachments enabled.
    Fsr {
        pipeline: bool,
    },
    Unknown,
    /// Every feature false (lavapipe here has neither).
    Maintenance6,
    Vulkan14,
    /// `storageBuffer16BitAccess` … left false, `multiview` enabled.
    Vulkan11,
    /// `timelineSemaphore` enabled.
    Vulkan12,
    /// `dynamicRendering` and `synchronization2` enabled.
    Vulkan13,
}

impl Link {
    fn stype(self) -> i32 {
        match self {
            Link::Fdm => vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_FEATURES_EXT,
            Link::Fdm2 => vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_2_FEATURES_EXT,
            Link::FdmOffset => {
                vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_OFFSET_FEATURES_QCOM
            }
            Link::Fsr { .. } => {
                vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_SHADING_RATE_FEATURES_KHR
            }
            Link::Unknown => vk::StructureType::from_raw(UNKNOWN),
            Link::Maintenance6 => vk::StructureType::from_raw(MAINTENANCE6),
            Link::Vulkan14 => vk::StructureType::from_raw(VULKAN14),
            Link::Vulkan11 => vk::StructureType::PHYSICAL_DEVICE_VULKAN_1_1_FEATURES,
            Link::Vulkan12 => vk::StructureType::PHYSICAL_DEVICE_VULKAN_1_2_FEATURES,
            Link::Vulkan13 => vk::StructureType::PHYSICAL_DEVICE_VULKAN_1_3_FEATURES,
        }
        .as_raw()
    }

    /// The struct's bytes, its `pNext` still null, in 8-byte words.
    fn words(self) -> Box<[u64]> {
        fn of<T>(s: T) -> Box<[u64]> {
            let mut w = vec![0u64; std::mem::size_of::<T>().div_ceil(8)].into_boxed_slice();
            // SAFETY: `w` holds at least size_of::<T>() bytes, 8-aligned, and `s` is plain data.
            unsafe {
                std::ptr::copy_nonoverlapping(
                    &s as *const T as *const u8,
                    w.as_mut_ptr() as *mut u8,
                    std::mem::size_of::<T>(),
                )
            };
            w
        }
        /// A header and `bools` all false: `size` bytes (from vk.xml).
        fn zeroed(stype: i32, size: usize) -> Box<[u64]> {
            let mut w = vec![0u64; size / 8].into_boxed_slice();
            w[0] = stype as u32 as u64;
            w
        }
        match self {
            Link::Fdm => of(vk::PhysicalDeviceFragmentDensityMapFeaturesEXT::default()
                .fragment_density_map(true)
                .fragment_density_map_non_subsampled_images(true)),
            Link::Fdm2 => of(vk::PhysicalDeviceFragmentDensityMap2FeaturesEXT::default()),
            Link::FdmOffset => of(
                vk::PhysicalDeviceFragmentDensityMapOffsetFeaturesQCOM::default()
                    .fragment_density_map_offset(true),
            ),
            Link::Fsr { pipeline } => {
                of(vk::PhysicalDeviceFragmentShadingRateFeaturesKHR::default()
                    .pipeline_fragment_shading_rate(pipeline)
                    .attachment_fragment_shading_rate(true))
            }
            // Four booleans' worth of body, as if it were some future feature struct.
            Link::Unknown => zeroed(UNKNOWN, 32),
            // One VkBool32 after the header, padded.
            Link::Maintenance6 => zeroed(MAINTENANCE6, 24),
            // 22 VkBool32 after the header.
            Link::Vulkan14 => zeroed(VULKAN14, 104),
            Link::Vulkan11 => of(vk::PhysicalDeviceVulkan11Features::default().multiview(true)),
            Link::Vulkan12 => {
                of(vk::PhysicalDeviceVulkan12Features::default().timeline_semaphore(true))
            }
            Link::Vulkan13 => of(vk::PhysicalDeviceVulkan13Features::default()
                .dynamic_rendering(true)
                .synchronization2(true)),
        }
    }

    /// Validation 1.3.239 (Debian 12's) predates these; it says so, and nothing else, about them.
    fn newer_than_validation(self) -> bool {
        matches!(self, Link::Unknown | Link::Maintenance6 | Link::Vulkan14)
    }
}

/// A chain of [`Link`]s in order, owning its structs (boxes do not move).
struct Chain(Vec<Box<[u64]>>);

impl Chain {
    fn new(links: &[Link]) -> Chain {
        let mut nodes: Vec<Box<[u64]>> = links.iter().map(|l| l.words()).collect();
        for i in (0..nodes.len().saturating_sub(1)).rev() {
            let next = nodes[i + 1].as_ptr() as u64;
            // Word 1 is pNext on 64-bit targets, the only ones the suite runs on.
            nodes[i][1] = next;
        }
        Chain(nodes)
    }

    fn head(&self) -> *const c_void {
        self.0
            .first()
            .map_or(std::ptr::null(), |n| n.as_ptr() as *const c_void)
    }
}

/// What a case must come to.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Expect {
    /// Density maps emulated: the driver gets the shading-rate extension and the attachment
    /// feature alone, everything else the application chained, density maps left out.
    Emulated,
    /// The application's own shading rates: the driver gets what it asked, less density maps.
    Own { pipeline: bool },
    /// Refused without reaching the driver.
    Refused(vk::Result),
}

struct Case {
    name: &'static str,
    exts: &'static [&'static CStr],
    links: &'static [Link],
    expect: Expect,
}

const CASES: &[Case] = &[
    Case {
        name: "Godot: both extensions, shading-rate features",
        exts: &[FDM, FSR],
        links: &[Link::Fsr { pipeline: true }],
        expect: Expect::Own { pipeline: true },
    },
    Case {
        name: "Godot with core features after its shading-rate struct",
        exts: &[FDM, FSR],
        links: &[
            Link::Fsr { pipeline: false },
            Link::Vulkan12,
            Link::Vulkan13,
        ],
        expect: Expect::Own { pipeline: false },
    },
    Case {
        name: "shading rates only",
        exts: &[FSR],
        links: &[Link::Fsr { pipeline: true }, Link::Vulkan13],
        expect: Expect::Own { pipeline: true },
    },
    Case {
        name: "density maps only",
        exts: &[FDM],
        links: &[Link::Fdm],
        expect: Expect::Emulated,
    },
    Case {
        name: "density-map extension without its features struct",
        exts: &[FDM],
        links: &[Link::Vulkan13],
        expect: Expect::Emulated,
    },
    Case {
        name: "Vulkan 1.1, 1.2 and 1.3 features before the density-map features",
        exts: &[FDM],
        links: &[Link::Vulkan11, Link::Vulkan12, Link::Vulkan13, Link::Fdm],
        expect: Expect::Emulated,
    },
    Case {
        name: "Vulkan 1.2 features after the density-map features",
        exts: &[FDM],
        links: &[Link::Fdm, Link::Vulkan12],
        expect: Expect::Emulated,
    },
    Case {
        name: "maintenance6 before the density-map features",
        exts: &[FDM],
        links: &[Link::Maintenance6, Link::Fdm, Link::Vulkan13],
        expect: Expect::Emulated,
    },
    Case {
        name: "maintenance6 after the density-map features",
        exts: &[FDM],
        links: &[Link::Fdm, Link::Maintenance6],
        expect: Expect::Emulated,
    },
    Case {
        name: "Vulkan14Features before the density-map features",
        exts: &[FDM],
        links: &[Link::Vulkan12, Link::Vulkan14, Link::Fdm],
        expect: Expect::Emulated,
    },
    Case {
        name: "Vulkan14Features after the density-map features",
        exts: &[FDM],
        links: &[Link::Fdm, Link::Vulkan14, Link::Vulkan12],
        expect: Expect::Emulated,
    },
    Case {
        name: "density-map 2 features beside the density-map features",
        exts: &[FDM],
        links: &[Link::Vulkan12, Link::Fdm, Link::Fdm2, Link::Vulkan13],
        expect: Expect::Emulated,
    },
    Case {
        name: "density maps with offsets under both names, their feature between core features",
        exts: &[FDM, OFFSET_EXT, OFFSET_QCOM],
        links: &[Link::Vulkan12, Link::Fdm, Link::FdmOffset, Link::Vulkan13],
        expect: Expect::Emulated,
    },
    Case {
        name: "Godot with the offset extension: shading rates of its own",
        exts: &[FDM, OFFSET_EXT, FSR],
        links: &[Link::Fsr { pipeline: true }, Link::FdmOffset],
        expect: Expect::Own { pipeline: true },
    },
    Case {
        name: "an unknown struct after the density-map features",
        exts: &[FDM],
        links: &[Link::Vulkan13, Link::Fdm, Link::Unknown],
        expect: Expect::Emulated,
    },
    Case {
        name: "an unknown struct before the density-map features",
        exts: &[FDM],
        links: &[Link::Unknown, Link::Fdm],
        expect: Expect::Refused(vk::Result::ERROR_FEATURE_NOT_PRESENT),
    },
];

/// The density-map family's feature structs: none may reach a driver without density maps.
fn density_map_structs() -> [i32; 4] {
    [
        vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_FEATURES_EXT.as_raw(),
        vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_2_FEATURES_EXT.as_raw(),
        vk::StructureType::PHYSICAL_DEVICE_FRAGMENT_DENSITY_MAP_OFFSET_FEATURES_QCOM.as_raw(),
        // VkPhysicalDeviceFragmentDensityMapLayeredFeaturesVALVE (vk.xml).
        1_000_611_000,
    ]
}

/// Creates the case's device, checks it, destroys it; the problems found.
fn run_case(env: &crate::support::device::Env, profile: Profile, case: &Case) -> Vec<String> {
    let Some(vk) = Vk::new(env, profile, true) else {
        return vec!["no instance".into()];
    };
    let mut problems = Vec::new();
    let chain = Chain::new(case.links);
    let prio = [1.0];
    let queues = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(0)
        .queue_priorities(&prio)];
    let names: Vec<_> = case.exts.iter().map(|e| e.as_ptr()).collect();
    let mut info = vk::DeviceCreateInfo::default()
        .queue_create_infos(&queues)
        .enabled_extension_names(&names);
    info.p_next = chain.head();
    let before: Vec<Box<[u64]>> = chain.0.clone();
    // SAFETY: every struct lives across the call.
    let created = unsafe { vk.instance.create_device(vk.physical, &info, None) };
    if chain.0 != before {
        problems.push("the application's chain was written".into());
    }
    let devices = env.double.events("device");
    match (case.expect, created) {
        (Expect::Refused(want), Err(got)) => {
            if got != want {
                problems.push(format!("refused with {got}, not {want}"));
            }
            if env.double.calls("vkCreateDevice") != 0 {
                problems.push(format!("the driver was asked: {devices:?}"));
            }
        }
        (Expect::Refused(want), Ok(device)) => {
            problems.push(format!("created, not refused with {want}: {devices:?}"));
            // SAFETY: nothing made from it.
            unsafe { device.destroy_device(None) };
        }
        (_, Err(e)) => problems.push(format!("vkCreateDevice: {e}; the driver got {devices:?}")),
        (expect, Ok(device)) => {
            problems.extend(driver_request(case, expect, &devices));
            // SAFETY: the device was just created; everything made on it is destroyed here.
            unsafe {
                works(&device, case.links.contains(&Link::Vulkan12));
                device.destroy_device(None);
            }
        }
    }
    let errors = env.double.errors();
    if !errors.is_empty() {
        problems.push(format!("the double recorded misuse: {errors:?}"));
    }
    drop(vk);
    let messages: Vec<String> = take_messages()
        .into_iter()
        .filter(|m| {
            // The loader's report of a failed vkCreateDevice, where the case is one that fails.
            !(matches!(case.expect, Expect::Refused(_))
                && m.contains("vkCreateDevice:  Failed to create device chain"))
        })
        .filter(|m| {
            // Validation's note that it does not know a struct newer than itself.
            !(m.contains("VUID-VkDeviceCreateInfo-pNext-pNext")
                && case
                    .links
                    .iter()
                    .any(|l| l.newer_than_validation() && m.contains(&l.stype().to_string())))
        })
        .collect();
    if !messages.is_empty() {
        problems.push(format!("validation: {messages:#?}"));
    }
    problems
}

/// What reached the driver, against what the case expects.
fn driver_request(case: &Case, expect: Expect, devices: &[Value]) -> Vec<String> {
    let mut problems = Vec::new();
    let [device] = devices else {
        return vec![format!("{} device records: {devices:?}", devices.len())];
    };
    let names: Vec<&str> = device["extensions"]
        .as_array()
        .map(|a| a.iter().filter_map(Value::as_str).collect())
        .unwrap_or_default();
    for n in [FDM, OFFSET_EXT, OFFSET_QCOM] {
        if names.contains(&n.to_str().unwrap()) {
            problems.push(format!("{n:?} reached the driver: {names:?}"));
        }
    }
    if !names.contains(&FSR.to_str().unwrap()) {
        problems.push(format!("no shading-rate extension: {names:?}"));
    }
    let chain: Vec<i32> = device["chain"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|v| v.as_i64())
                .map(|v| v as i32)
                .collect()
        })
        .unwrap_or_default();
    if chain.iter().any(|t| density_map_structs().contains(t)) {
        problems.push(format!(
            "a density-map struct reached the driver: {chain:?}"
        ));
    }
    // The application's structs, in its order, less density maps; the layer's shading-rate
    // struct where it adds one; the loader's link structs aside. A validation layer older than a
    // struct leaves it out of the create info it passes down (it copies the create info, and
    // copies only the structs it knows), so those are compared where they arrive only.
    let fsr = Link::Fsr { pipeline: false }.stype();
    let newer: Vec<i32> = case
        .links
        .iter()
        .filter(|l| l.newer_than_validation())
        .map(|l| l.stype())
        .collect();
    let got: Vec<i32> = chain
        .iter()
        .copied()
        .filter(|&t| t != LOADER_DEVICE_CREATE_INFO && t != fsr)
        .filter(|t| !newer.contains(t) || chain.contains(t))
        .collect();
    let want: Vec<i32> = case
        .links
        .iter()
        .filter(|l| {
            !matches!(
                l,
                Link::Fdm | Link::Fdm2 | Link::FdmOffset | Link::Fsr { .. }
            )
        })
        .map(|l| l.stype())
        .filter(|t| !newer.contains(t) || chain.contains(t))
        .collect();
    if got != want {
        problems.push(format!(
            "the driver's chain {chain:?} is not the application's {want:?}"
        ));
    }
    if chain.iter().filter(|&&t| t == fsr).count() != 1 {
        problems.push(format!("not one shading-rate features struct: {chain:?}"));
    }
    let features = match expect {
        Expect::Own { pipeline } => {
            json!({"pipeline": pipeline, "primitive": false, "attachment": true})
        }
        _ => json!({"pipeline": false, "primitive": false, "attachment": true}),
    };
    if device["features"] != features {
        problems.push(format!(
            "the driver's shading-rate features {} are not {features}",
            device["features"]
        ));
    }
    problems
}

/// An empty command buffer submitted and waited for; a timeline semaphore where the application
/// enabled them (validation refuses one where the feature did not reach the layers below).
///
/// # Safety
/// `d` must be a live device with queue family 0.
unsafe fn works(d: &ash::Device, timeline: bool) {
    // SAFETY: the caller's promise; everything made here is destroyed here.
    unsafe {
        let queue = d.get_device_queue(0, 0);
        let pool = d
            .create_command_pool(&vk::CommandPoolCreateInfo::default(), None)
            .expect("command pool");
        let cb = d
            .allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool)
                    .command_buffer_count(1),
            )
            .expect("command buffer")[0];
        d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default())
            .expect("begin");
        d.end_command_buffer(cb).expect("end");
        let fence = d
            .create_fence(&vk::FenceCreateInfo::default(), None)
            .expect("fence");
        let cbs = [cb];
        d.queue_submit(
            queue,
            &[vk::SubmitInfo::default().command_buffers(&cbs)],
            fence,
        )
        .expect("vkQueueSubmit");
        d.wait_for_fences(&[fence], true, u64::MAX)
            .expect("the submit completes");
        d.destroy_fence(fence, None);
        d.destroy_command_pool(pool, None);
        if timeline {
            let mut ty = vk::SemaphoreTypeCreateInfo::default()
                .semaphore_type(vk::SemaphoreType::TIMELINE)
                .initial_value(1);
            let s = d
                .create_semaphore(&vk::SemaphoreCreateInfo::default().push_next(&mut ty), None)
                .expect("a timeline semaphore");
            assert_eq!(d.get_semaphore_counter_value(s), Ok(1));
            d.destroy_semaphore(s, None);
        }
    }
}

/// Every case on both shading-rate profiles; all problems are listed before the test fails, so
/// one run shows the whole matrix.
#[test]
fn device_creation_matrix() {
    let Some((_serial, env)) = env() else { return };
    let mut failed = Vec::new();
    for profile in [Profile::Nvidia, Profile::Amd] {
        for case in CASES {
            let problems = run_case(env, profile, case);
            eprintln!(
                "{profile:?}: {}: {}",
                case.name,
                if problems.is_empty() { "ok" } else { "FAILED" }
            );
            if !problems.is_empty() {
                failed.push(format!(
                    "{profile:?}: {}:\n  {}",
                    case.name,
                    problems.join("\n  ")
                ));
            }
        }
    }
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}
