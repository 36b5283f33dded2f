//! `fovea demo`: an application applies a HIGH profile with dynamic foveation on the simulated
//! headset; the simulated GPU load rises past the frame budget and falls back (the dynamic level
//! follows), and four fifths through, a Quest debug property file fixes the level at MEDIUM while
//! the app runs. The simulated headset has an eye tracker whose scripted gaze ([`setup::GAZE`])
//! fixates, jumps, pursues and blinks, and the app's profile is eye-tracked
//! (`XR_META_foveation_eye_tracked`), so the fovea follows the eye. The layer's once-a-second stats
//! lines (target `fovea_model::stats`) show what it does, the gaze in their `Gaze=` field.
//!
//! Where the system's Khronos loader is installed and Vulkan has a device, the application is
//! `examples/foveated_vulkan` drawing its room (`--scene room`) through that loader, fovea and the
//! simulated runtime, and the density maps and frames it reads back from the GPU are written as
//! PNGs ([`loader`]), with a line per frame on where the gaze was and how coarse each zone is
//! ([`frames`]). On a device without shading-rate attachments (lavapipe) it renders on the
//! simulated desktop GPU (fovea's Vulkan layer over the shading-rate double, `crates/vkdouble`), so
//! the frames show foveation as a headset would; `--overlay` draws the stripes at full rate with
//! the maps in a debug overlay instead, and `--compare` runs twice, coarse blocks as shaded and
//! reconstructed (`FOVEA_SUBSAMPLED`), side by side. Otherwise it is a headless frame loop through
//! fovea's fake loader harness ([`harness`]). `--via loader` or `--via harness` chooses instead.

mod frames;
mod harness;
mod loader;
mod setup;

use crate::args::{DemoArgs, Via};

pub fn run(args: &DemoArgs) -> Result<(), String> {
    let setup = setup::Setup::new(args)?;
    match args.via {
        Some(Via::Harness) => harness::run(&setup),
        Some(Via::Loader) => loader::run(&setup, loader::System::find()?),
        None => match loader::System::find() {
            Ok(system) => loader::run(&setup, system),
            Err(why) => {
                println!("fovea demo: {why}; running through fovea's fake loader harness instead");
                harness::run(&setup)
            }
        },
    }
}
