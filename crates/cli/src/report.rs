//! `fovea report (--headset NAME | --fov L,R,U,D [--fov-right L,R,U,D] [--size WxH]) [--texel N]
//! [--json]`: what each level costs and keeps, both eyes.

use fovea_model::density::{analyze, fill, Analysis, Level, Pattern};
use serde::Serialize;

use crate::args::ReportArgs;
use crate::fov::FovDeg;
use crate::json::Fixed;
use crate::target::{Sizing, Target};

/// The `max_fragment` caps the report compares (the setting's accepted values), largest first.
pub const CAPS: [u32; 3] = [4, 2, 1];

/// Both eyes of `target` at `texel` for one level with fragments up to `cap`, analysed together.
pub fn level_analysis(target: &Target, texel: u32, level: Level, cap: u32) -> Analysis {
    let pattern = Pattern {
        level,
        vertical_offset_deg: 0.0,
    };
    let parts: Vec<Analysis> = (0..2)
        .map(|eye| {
            let (grid, view) = target.eye_view(eye, texel);
            let grid = grid.capped(cap);
            let [w, hh] = grid.map_extent();
            let mut map = vec![0; w as usize * hh as usize * 2];
            fill(&grid, &[view], pattern, &mut map);
            analyze(&grid, &[view], pattern, &map)
        })
        .collect();
    Analysis::combine(&parts)
}

#[derive(Serialize)]
struct LevelJson {
    level: &'static str,
    shaded_fraction: Fixed<6>,
    full_rate_radius_deg: Option<Fixed<3>>,
    min_relative_ppd: Fixed<6>,
    min_relative_ppd_within_15deg: Fixed<6>,
    /// The shaded fraction under each `max_fragment` cap, keyed "4", "2", "1".
    shaded_by_max_fragment: std::collections::BTreeMap<&'static str, Fixed<6>>,
}

/// A command-line headset: what it was given as, so the JSON stands on its own.
#[derive(Serialize)]
struct CustomJson {
    fov_deg: [FovDeg; 2],
    size: [u32; 2],
    /// `"--size"`, or `"fov"` when sized from the FOV.
    size_from: &'static str,
    /// The pixels per unit tangent a size from the FOV used.
    #[serde(skip_serializing_if = "Option::is_none")]
    pixels_per_tangent: Option<f64>,
}

#[derive(Serialize)]
struct ReportJson {
    headset: &'static str,
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    custom: Option<CustomJson>,
    texel: u32,
    levels: Vec<LevelJson>,
}

pub fn run(args: &ReportArgs) -> Result<(), String> {
    let target = Target::from_args(&args.target);
    let texel = args.texel.value;
    let rows: Vec<(Level, Analysis, [f64; 3])> = Level::ALL
        .iter()
        .map(|&l| {
            let by_cap = CAPS.map(|c| level_analysis(&target, texel, l, c).shaded_fraction);
            (l, level_analysis(&target, texel, l, CAPS[0]), by_cap)
        })
        .collect();
    if args.json {
        let json = ReportJson {
            headset: target.id,
            custom: target.custom.map(|sizing| CustomJson {
                fov_deg: target.fovs.map(|f| FovDeg::new(f.degrees())),
                size: target.size,
                size_from: match sizing {
                    Sizing::Given => "--size",
                    Sizing::FromFov => "fov",
                },
                pixels_per_tangent: (sizing == Sizing::FromFov)
                    .then_some(crate::target::DEFAULT_PIXELS_PER_TANGENT),
            }),
            texel,
            levels: rows
                .iter()
                .map(|(l, a, by_cap)| LevelJson {
                    level: l.name(),
                    shaded_fraction: Fixed(a.shaded_fraction),
                    full_rate_radius_deg: a.full_rate_radius_deg.map(Fixed),
                    min_relative_ppd: Fixed(a.min_relative_ppd),
                    min_relative_ppd_within_15deg: Fixed(a.min_relative_ppd_within_15deg),
                    shaded_by_max_fragment: ["4", "2", "1"]
                        .into_iter()
                        .zip(by_cap.map(Fixed))
                        .collect(),
                })
                .collect(),
        };
        println!(
            "{}",
            serde_json::to_string(&json).map_err(|e| e.to_string())?
        );
        return Ok(());
    }
    let [w, hh] = target.size;
    println!(
        "{}: {w}x{hh} per eye, texel {texel}, fragments up to 4x4, both eyes",
        target.name
    );
    if let Some(note) = target.sizing_note() {
        println!("{note}");
    }
    println!(
        "{:<9} {:>8} {:>16} {:>17} {:>22}",
        "level", "shaded", "full-rate radius", "min relative ppd", "min rel. ppd within 15°"
    );
    for (l, a, _) in &rows {
        let radius = a
            .full_rate_radius_deg
            .map_or("whole view".to_string(), |r| format!("{r:.1}°"));
        println!(
            "{:<9} {:>8.3} {:>16} {:>17.3} {:>22.3}",
            l.name(),
            a.shaded_fraction,
            radius,
            a.min_relative_ppd,
            a.min_relative_ppd_within_15deg
        );
    }
    println!();
    println!("shaded under each max_fragment cap (the setting; 4 is the default):");
    println!("{:<9} {:>8} {:>8} {:>8}", "level", "4x4", "2x2", "1x1");
    for (l, _, by_cap) in &rows {
        println!(
            "{:<9} {:>8.3} {:>8.3} {:>8.3}",
            l.name(),
            by_cap[0],
            by_cap[1],
            by_cap[2]
        );
    }
    Ok(())
}
