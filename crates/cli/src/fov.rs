//! `fovea fov --headset NAME [--json]`: each eye's FOV and projection centre, and the recommended
//! eye-buffer size with the asymmetric FOVs against one shared symmetric FOV (asymmetric FOV FAQ).

use serde::Serialize;

use crate::args::FovArgs;
use crate::json::Fixed;

/// One eye's FOV in degrees, as the JSON outputs name the sides.
#[derive(Serialize)]
pub struct FovDeg {
    left: Fixed<4>,
    right: Fixed<4>,
    up: Fixed<4>,
    down: Fixed<4>,
}

impl FovDeg {
    pub fn new([l, r, u, d]: [f64; 4]) -> FovDeg {
        FovDeg {
            left: Fixed(l),
            right: Fixed(r),
            up: Fixed(u),
            down: Fixed(d),
        }
    }
}

#[derive(Serialize)]
struct EyeJson {
    eye: &'static str,
    fov_deg: FovDeg,
    projection_center_ndc: [Fixed<6>; 2],
}

#[derive(Serialize)]
struct Recommended {
    asymmetric: [u32; 2],
    symmetric: [u32; 2],
}

#[derive(Serialize)]
struct FovJson {
    headset: &'static str,
    eyes: Vec<EyeJson>,
    recommended: Recommended,
    symmetric_pixel_saving: Fixed<6>,
}

pub fn run(args: &FovArgs) -> Result<(), String> {
    let h = args.headset;
    let [aw, ah] = h.recommended_size();
    let [sw, sh] = h.symmetric_size();
    let saving = h.symmetric_pixel_saving();
    let eyes: Vec<(&str, [f64; 4], [f32; 2])> = ["left", "right"]
        .iter()
        .zip(h.fovs())
        .map(|(name, f)| (*name, f.degrees(), f.projection_center_ndc()))
        .collect();
    if args.json {
        let json = FovJson {
            headset: h.id,
            eyes: eyes
                .iter()
                .map(|&(eye, deg, [x, y])| EyeJson {
                    eye,
                    fov_deg: FovDeg::new(deg),
                    projection_center_ndc: [Fixed(f64::from(x)), Fixed(f64::from(y))],
                })
                .collect(),
            recommended: Recommended {
                asymmetric: [aw, ah],
                symmetric: [sw, sh],
            },
            symmetric_pixel_saving: Fixed(saving),
        };
        println!(
            "{}",
            serde_json::to_string(&json).map_err(|e| e.to_string())?
        );
        return Ok(());
    }
    println!("{} ({})", h.name, h.source);
    println!(
        "{:<6} {:>7} {:>7} {:>7} {:>7}   projection centre (NDC)",
        "eye", "left", "right", "up", "down"
    );
    for (name, [l, r, u, d], [x, y]) in &eyes {
        println!("{name:<6} {l:>6.2}° {r:>6.2}° {u:>6.2}° {d:>6.2}°   ({x:+.3}, {y:+.3})");
    }
    println!("recommended per eye: asymmetric {aw}x{ah}, symmetric {sw}x{sh}, asymmetric saves {:.1}% of pixels", saving * 100.0);
    Ok(())
}
