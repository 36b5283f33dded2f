//! `fovea report --headset NAME [--texel N] [--json]`: what each level costs and keeps, both eyes.

use fovea_model::density::{analyze, fill, Analysis, Level, Pattern};

use crate::args::Args;
use crate::fov::{eye_view, headset, texel};

/// Both eyes of `h` at `texel` for one level, analysed together.
pub fn level_analysis(h: &fovea_model::headsets::Headset, texel: u32, level: Level) -> Analysis {
    let pattern = Pattern {
        level,
        vertical_offset_deg: 0.0,
    };
    let parts: Vec<Analysis> = (0..2)
        .map(|eye| {
            let (grid, view) = eye_view(h, eye, texel);
            let [w, hh] = grid.map_extent();
            let mut map = vec![0; w as usize * hh as usize * 2];
            fill(&grid, &[view], pattern, &mut map);
            analyze(&grid, &[view], pattern, &map)
        })
        .collect();
    Analysis::combine(&parts)
}

pub fn run(args: &Args) -> Result<(), String> {
    let h = headset(args)?;
    let texel = texel(args)?;
    let rows: Vec<(Level, Analysis)> = Level::ALL
        .iter()
        .map(|&l| (l, level_analysis(h, texel, l)))
        .collect();
    if args.switch("json") {
        let levels: Vec<String> = rows
            .iter()
            .map(|(l, a)| {
                let radius = a
                    .full_rate_radius_deg
                    .map_or("null".to_string(), |r| format!("{r:.3}"));
                format!(
                    "{{\"level\":\"{}\",\"shaded_fraction\":{:.6},\"full_rate_radius_deg\":{radius},\
                     \"min_relative_ppd\":{:.6},\"min_relative_ppd_within_15deg\":{:.6}}}",
                    l.name(),
                    a.shaded_fraction,
                    a.min_relative_ppd,
                    a.min_relative_ppd_within_15deg
                )
            })
            .collect();
        println!(
            "{{\"headset\":\"{}\",\"texel\":{texel},\"levels\":[{}]}}",
            h.id,
            levels.join(",")
        );
        return Ok(());
    }
    let [w, hh] = h.recommended_size();
    println!(
        "{}: {w}x{hh} per eye, texel {texel}, fragments up to 4x4, both eyes",
        h.name
    );
    println!(
        "{:<9} {:>8} {:>16} {:>17} {:>22}",
        "level", "shaded", "full-rate radius", "min relative ppd", "min rel. ppd within 15°"
    );
    for (l, a) in rows {
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
    Ok(())
}
