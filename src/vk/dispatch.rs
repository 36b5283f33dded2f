//! The hook tables that `vkGetInstanceProcAddr` and `vkGetDeviceProcAddr` answer from, expanded
//! from the one command list ([`crate::vk::base::commands`]) beside the next-layer tables
//! ([`crate::vk::base::next`]).

use std::ffi::CStr;

use crate::vk::base::commands::{command_list, When};
use crate::vk::base::ffi::pfn;
use crate::vk::base::next::{DeviceNext, InstanceNext};
use crate::vk::hooks::{
    barrier, device, image, instance, pass, physical, pipeline, record, submit,
};

/// An intercepted instance or physical-device command.
pub struct InstanceHook {
    pub name: &'static CStr,
    pub function: unsafe extern "system" fn(),
    /// Whether the next layer offers the command (the layer hooks only what exists below it).
    pub offered: fn(&InstanceNext) -> bool,
}

/// An intercepted device command.
pub struct DeviceHook {
    pub name: &'static CStr,
    pub function: unsafe extern "system" fn(),
    pub when: When,
    pub offered: fn(&DeviceNext) -> bool,
}

macro_rules! hook_tables {
    (
        instance { $($iname:literal => $ifield:ident: $ipfn:ident = $ihook:path;)* }
        device { $($dname:literal => $dfield:ident: $dpfn:ident = $dhook:path, $when:expr;)* }
    ) => {
        /// Every intercepted instance and physical-device command.
        pub static INSTANCE_HOOKS: &[InstanceHook] = &[
            $(InstanceHook {
                name: $iname,
                // SAFETY: function pointers share one representation; the caller casts it back to
                // the type the name implies, which the `as` checks here.
                function: unsafe {
                    std::mem::transmute::<pfn::$ipfn, unsafe extern "system" fn()>($ihook as pfn::$ipfn)
                },
                offered: |n: &InstanceNext| n.$ifield.is_some(),
            },)*
        ];

        /// Every intercepted device command.
        pub static DEVICE_HOOKS: &[DeviceHook] = &[
            $(DeviceHook {
                name: $dname,
                // SAFETY: as for INSTANCE_HOOKS.
                function: unsafe {
                    std::mem::transmute::<pfn::$dpfn, unsafe extern "system" fn()>($dhook as pfn::$dpfn)
                },
                when: $when,
                offered: |n: &DeviceNext| n.$dfield.is_some(),
            },)*
        ];
    };
}

command_list!(hook_tables);

/// The instance hook for `name`, if the layer intercepts it.
pub fn instance_hook(name: &CStr) -> Option<&'static InstanceHook> {
    INSTANCE_HOOKS.iter().find(|h| h.name == name)
}

/// The device hook for `name`, if the layer intercepts it.
pub fn device_hook(name: &CStr) -> Option<&'static DeviceHook> {
    DEVICE_HOOKS.iter().find(|h| h.name == name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_resolvable() {
        let names: Vec<&CStr> = INSTANCE_HOOKS
            .iter()
            .map(|h| h.name)
            .chain(DEVICE_HOOKS.iter().map(|h| h.name))
            .collect();
        for (i, n) in names.iter().enumerate() {
            assert!(!names[..i].contains(n), "{n:?} twice");
        }
        for h in INSTANCE_HOOKS {
            assert!(std::ptr::eq(instance_hook(h.name).unwrap(), h));
            assert!(!(h.offered)(&InstanceNext::default()));
        }
        for h in DEVICE_HOOKS {
            assert!(std::ptr::eq(device_hook(h.name).unwrap(), h));
        }
        assert!(device_hook(c"vkCmdDraw").is_none());
    }

    #[test]
    fn an_applications_own_rates_are_hooked_on_injecting_devices_only() {
        let h = device_hook(c"vkCmdSetFragmentShadingRateKHR").unwrap();
        assert_eq!(h.when, When::Injecting);
        assert!(h.when.applies(false, true));
        assert!(
            !h.when.applies(true, false),
            "an emulating device has no rates of the app's"
        );
        assert!(!h.when.applies(false, false));
    }
}
