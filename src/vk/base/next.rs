//! The next layer's pointers for every intercepted command, expanded from the one command list
//! ([`crate::vk::base::commands`]).

use ash::vk;

use crate::vk::base::commands::command_list;
use crate::vk::base::ffi::pfn;

macro_rules! next_tables {
    (
        instance { $($iname:literal => $ifield:ident: $ipfn:ident = $ihook:path;)* }
        device { $($dname:literal => $dfield:ident: $dpfn:ident = $dhook:path, $when:expr;)* }
    ) => {
        /// The next layer's pointer for every intercepted instance command (`None` where it has
        /// none), loaded once at `vkCreateInstance`.
        #[derive(Clone, Copy, Default)]
        pub struct InstanceNext {
            $(pub $ifield: Option<pfn::$ipfn>,)*
        }

        impl InstanceNext {
            /// Asks the next layer for every intercepted instance command.
            ///
            /// # Safety
            /// `gipa` must be the next layer's `vkGetInstanceProcAddr`, `instance` its instance.
            pub unsafe fn load(gipa: vk::PFN_vkGetInstanceProcAddr, instance: vk::Instance) -> Self {
                InstanceNext {
                    // SAFETY: the next layer returns a pointer of the type the name implies.
                    $($ifield: unsafe { gipa(instance, $iname.as_ptr()) }
                        .map(|f| {
                            // SAFETY: function pointers share one representation; the name
                            // implies this type.
                            unsafe { std::mem::transmute::<unsafe extern "system" fn(), pfn::$ipfn>(f) }
                        }),)*
                }
            }
        }

        /// The next layer's pointer for every intercepted device command, loaded at
        /// `vkCreateDevice`.
        #[derive(Clone, Copy, Default)]
        pub struct DeviceNext {
            $(pub $dfield: Option<pfn::$dpfn>,)*
        }

        impl DeviceNext {
            /// Asks the next layer for every intercepted device command.
            ///
            /// # Safety
            /// `gdpa` must be the next layer's `vkGetDeviceProcAddr`, `device` its device.
            pub unsafe fn load(gdpa: vk::PFN_vkGetDeviceProcAddr, device: vk::Device) -> Self {
                DeviceNext {
                    // SAFETY: as in InstanceNext::load.
                    $($dfield: unsafe { gdpa(device, $dname.as_ptr()) }
                        .map(|f| {
                            // SAFETY: function pointers share one representation; the name
                            // implies this type.
                            unsafe { std::mem::transmute::<unsafe extern "system" fn(), pfn::$dpfn>(f) }
                        }),)*
                }
            }
        }

    };
}

command_list!(next_tables);
